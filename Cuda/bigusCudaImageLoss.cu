// The image loss on the GPU (see bigusCudaImageLoss.h and LaunchImageLoss in bigusCudaKernels.h).
#include "bigusCudaImageLoss.h"

#include "bigusCudaDeviceRenderer.h" // Buffer, Check, DeviceUsable
#include "bigusCudaKernels.h"
#include "bigusSsimMath.h"

#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>

namespace bigus
{
namespace cuda
{

namespace
{
constexpr int LossBlockX = 32;
constexpr int LossBlockY = 8;
constexpr int LossThreads = LossBlockX * LossBlockY;
constexpr int LossSums = 3; // per block: SSIM over the mask, |X - Y|, masked pixels

/// The window's 1D weights, passed by value to the kernels.
struct Window
{
  double W[SsimWindow];
};

dim3 LossGrid(int width, int height)
{
  return dim3((width + LossBlockX - 1) / LossBlockX, (height + LossBlockY - 1) / LossBlockY);
}

__device__ __forceinline__ bool Imaged(const unsigned char* mask, std::int64_t p)
{
  return !mask || mask[p] != 0;
}

/// Sums @p v over the block's LossThreads threads (thread @p t) by a fixed tree; the totals end in shared[c][0].
__device__ void BlockTree(const double (&v)[LossSums], double (&shared)[LossSums][LossThreads], int t)
{
  for (int c = 0; c < LossSums; ++c)
  {
    shared[c][t] = v[c];
  }
  __syncthreads();
  for (int half = LossThreads / 2; half > 0; half /= 2)
  {
    if (t < half)
    {
      for (int c = 0; c < LossSums; ++c)
      {
        shared[c][t] += shared[c][t + half];
      }
    }
    __syncthreads();
  }
}

/// Pass 1: the window's row sums of X, Y, X^2, Y^2 and XY (X, Y: the images times the mask) into @p rows [5, H, W].
__global__ void MomentRowsKernel(
  const float* x, const float* y, const unsigned char* mask, int width, int height, Window w, double* rows)
{
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  const int j = blockIdx.y * blockDim.y + threadIdx.y;
  if (i >= width || j >= height)
  {
    return;
  }
  const std::int64_t pixels = std::int64_t(width) * height;
  const std::int64_t row = std::int64_t(j) * width;
  double s[5] = { 0, 0, 0, 0, 0 };
  for (int k = -SsimRadius; k <= SsimRadius; ++k)
  {
    const int c = i + k;
    if (c < 0 || c >= width)
    {
      continue; // zero padding
    }
    const std::int64_t p = row + c;
    const bool in = Imaged(mask, p);
    const double X = in ? double(x[p]) : 0.0;
    const double Y = in ? double(y[p]) : 0.0;
    const double g = w.W[k + SsimRadius];
    s[0] += g * X;
    s[1] += g * Y;
    s[2] += g * (X * X);
    s[3] += g * (Y * Y);
    s[4] += g * (X * Y);
  }
  for (int c = 0; c < 5; ++c)
  {
    rows[c * pixels + row + i] = s[c];
  }
}

/**
 * Pass 2: the column sums of @p rows (the window's moments), SSIM and its derivatives (SsimAt); into @p d [3, H, W]
 * (when not null) minus the derivatives inside the mask, 0 outside; into @p partials [blocks, 3] the block's sums
 * of SSIM inside the mask, |X - Y| and the masked pixels.
 */
__global__ void SsimKernel(const double* rows, const float* x, const float* y, const unsigned char* mask, int width,
  int height, Window w, double* d, double* partials)
{
  __shared__ double shared[LossSums][LossThreads];
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  const int j = blockIdx.y * blockDim.y + threadIdx.y;
  double sums[LossSums] = { 0, 0, 0 };
  if (i < width && j < height)
  {
    const std::int64_t pixels = std::int64_t(width) * height;
    double m[5] = { 0, 0, 0, 0, 0 };
    for (int k = -SsimRadius; k <= SsimRadius; ++k)
    {
      const int r = j + k;
      if (r < 0 || r >= height)
      {
        continue;
      }
      const double g = w.W[k + SsimRadius];
      const std::int64_t q = std::int64_t(r) * width + i;
      for (int c = 0; c < 5; ++c)
      {
        m[c] += g * rows[c * pixels + q];
      }
    }
    const SsimPixel s = SsimAt(m[0], m[1], m[2], m[3], m[4]);
    const std::int64_t p = std::int64_t(j) * width + i;
    const bool in = Imaged(mask, p);
    const double X = in ? double(x[p]) : 0.0;
    const double Y = in ? double(y[p]) : 0.0;
    sums[0] = in ? s.Value : 0.0;
    sums[1] = fabs(X - Y);
    sums[2] = in ? 1.0 : 0.0;
    if (d)
    {
      d[p] = in ? -s.DMean : 0.0;
      d[pixels + p] = in ? -s.DSquare : 0.0;
      d[2 * pixels + p] = in ? -s.DCross : 0.0;
    }
  }
  const int t = threadIdx.y * blockDim.x + threadIdx.x;
  BlockTree(sums, shared, t);
  if (t == 0)
  {
    const std::int64_t block = std::int64_t(blockIdx.y) * gridDim.x + blockIdx.x;
    for (int c = 0; c < LossSums; ++c)
    {
      partials[LossSums * block + c] = shared[c][0];
    }
  }
}

/**
 * One block: the sums of @p partials [blocks, 3] in a fixed order, then @p terms = (L1, D-SSIM, masked pixels,
 * weighted total) as ComputeImageLoss gives them, and @p scales = the gradient's factors of the L1 sign and of the
 * D-SSIM maps (each term's weight / masked pixels, times @p gradientScale).
 */
__global__ void LossTermsKernel(const double* partials, std::int64_t blocks, double weightL1, double weightDSSIM,
  double gradientScale, double* terms, double* scales)
{
  __shared__ double shared[LossSums][LossThreads];
  const int t = threadIdx.x;
  double v[LossSums] = { 0, 0, 0 };
  for (std::int64_t b = t; b < blocks; b += LossThreads)
  {
    for (int c = 0; c < LossSums; ++c)
    {
      v[c] += partials[LossSums * b + c];
    }
  }
  BlockTree(v, shared, t);
  if (t == 0)
  {
    const double K = shared[2][0];
    const double l1 = (weightL1 != 0 && K > 0) ? shared[1][0] / K : 0.0;
    const double dssim = (weightDSSIM != 0 && K > 0) ? 1.0 - shared[0][0] / K : 0.0;
    terms[0] = l1;
    terms[1] = dssim;
    terms[2] = K;
    terms[3] = weightL1 * l1 + weightDSSIM * dssim;
    scales[0] = K > 0 ? weightL1 * gradientScale / K : 0.0;
    scales[1] = K > 0 ? weightDSSIM * gradientScale / K : 0.0;
  }
}

/// Pass 3: the window's row sums of the three maps @p d [3, H, W] into @p out [3, H, W].
__global__ void GradientRowsKernel(const double* d, int width, int height, Window w, double* out)
{
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  const int j = blockIdx.y * blockDim.y + threadIdx.y;
  if (i >= width || j >= height)
  {
    return;
  }
  const std::int64_t pixels = std::int64_t(width) * height;
  const std::int64_t row = std::int64_t(j) * width;
  double s[3] = { 0, 0, 0 };
  for (int k = -SsimRadius; k <= SsimRadius; ++k)
  {
    const int c = i + k;
    if (c < 0 || c >= width)
    {
      continue;
    }
    const double g = w.W[k + SsimRadius];
    for (int m = 0; m < 3; ++m)
    {
      s[m] += g * d[m * pixels + row + c];
    }
  }
  for (int m = 0; m < 3; ++m)
  {
    out[m * pixels + row + i] = s[m];
  }
}

/**
 * Pass 4: dTotal/dx at each pixel into @p gradient (which may be @p x itself: each thread reads only its own pixel
 * of x): inside the mask scales[0] sign(X - Y) (with @p l1) plus scales[1] (G*D1 + 2 X G*Dxx + Y G*Dxy) (with
 * @p dssim; the column sums of @p rows, pass 3's output); 0 outside.
 */
__global__ void GradientKernel(const double* rows, const float* x, const float* y, const unsigned char* mask, int width,
  int height, Window w, const double* scales, bool l1, bool dssim, float* gradient)
{
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  const int j = blockIdx.y * blockDim.y + threadIdx.y;
  if (i >= width || j >= height)
  {
    return;
  }
  const std::int64_t pixels = std::int64_t(width) * height;
  const std::int64_t p = std::int64_t(j) * width + i;
  if (!Imaged(mask, p))
  {
    gradient[p] = 0.0f;
    return;
  }
  const double X = x[p];
  const double Y = y[p];
  double g = 0;
  if (l1)
  {
    const double r = X - Y;
    g += scales[0] * double((r > 0) - (r < 0));
  }
  if (dssim)
  {
    double f[3] = { 0, 0, 0 };
    for (int k = -SsimRadius; k <= SsimRadius; ++k)
    {
      const int r = j + k;
      if (r < 0 || r >= height)
      {
        continue;
      }
      const double c = w.W[k + SsimRadius];
      const std::int64_t q = std::int64_t(r) * width + i;
      for (int m = 0; m < 3; ++m)
      {
        f[m] += c * rows[m * pixels + q];
      }
    }
    g += scales[1] * (f[0] + 2 * X * f[1] + Y * f[2]);
  }
  gradient[p] = static_cast<float>(g);
}
}

std::int64_t ImageLossScratchBytes(int width, int height)
{
  const dim3 grid = LossGrid(width, height);
  const std::int64_t pixels = std::int64_t(width) * height;
  return (8 * pixels + LossSums * std::int64_t(grid.x) * grid.y + 2) * std::int64_t(sizeof(double));
}

void LaunchImageLoss(const float* rendered, const float* target, const unsigned char* mask, int width, int height,
  double weightL1, double weightDSSIM, double gradientScale, float* gradient, double* terms, void* scratch,
  cudaStream_t stream)
{
  Window w;
  SsimWindowWeights(w.W);
  const dim3 block(LossBlockX, LossBlockY);
  const dim3 grid = LossGrid(width, height);
  const std::int64_t pixels = std::int64_t(width) * height;
  const std::int64_t blocks = pixels > 0 ? std::int64_t(grid.x) * grid.y : 0;
  double* rows = static_cast<double*>(scratch); // [5, H, W], then pass 3's [3, H, W]
  double* d = rows + 5 * pixels;                // [3, H, W]
  double* partials = d + 3 * pixels;            // [blocks, 3]
  double* scales = partials + LossSums * blocks;
  if (pixels > 0)
  {
    MomentRowsKernel<<<grid, block, 0, stream>>>(rendered, target, mask, width, height, w, rows);
    SsimKernel<<<grid, block, 0, stream>>>(
      rows, rendered, target, mask, width, height, w, gradient ? d : nullptr, partials);
  }
  LossTermsKernel<<<1, LossThreads, 0, stream>>>(partials, blocks, weightL1, weightDSSIM, gradientScale, terms, scales);
  if (gradient && pixels > 0)
  {
    if (weightDSSIM != 0)
    {
      GradientRowsKernel<<<grid, block, 0, stream>>>(d, width, height, w, rows);
    }
    GradientKernel<<<grid, block, 0, stream>>>(
      rows, rendered, target, mask, width, height, w, scales, weightL1 != 0, weightDSSIM != 0, gradient);
  }
}

bool ComputeImageLossOnDevice(const float* rendered, const float* target, const unsigned char* mask, int width,
  int height, const ImageLossWeights& weights, float* gradient, ImageLossTerms* terms, std::string* error)
{
  if (weights.FFL != 0)
  {
    if (error)
    {
      *error = "ComputeImageLossOnDevice: the FFL term is computed on the host only (WeightFFL must be 0)";
    }
    return false;
  }
  if (!DeviceUsable(error))
  {
    return false;
  }
  const std::int64_t pixels = std::int64_t(width) * height;
  const std::size_t imageBytes = sizeof(float) * std::size_t(pixels);
  Buffer images, masks, scratch, results; // images: [2, H, W] x (then the gradient), y
  double values[4] = { 0, 0, 0, 0 };
  const bool ok = images.Reserve(2 * std::max<std::int64_t>(1, pixels) * sizeof(float), "allocating images", error) &&
    masks.Reserve(std::max<std::int64_t>(1, pixels), "allocating the mask", error) &&
    scratch.Reserve(ImageLossScratchBytes(width, height), "allocating the loss's scratch", error) &&
    results.Reserve(4 * sizeof(double), "allocating the loss's terms", error) &&
    Check(cudaMemcpy(images.Data, rendered, imageBytes, cudaMemcpyHostToDevice), "copying images", error) &&
    Check(
      cudaMemcpy(images.As<float>() + pixels, target, imageBytes, cudaMemcpyHostToDevice), "copying images", error) &&
    (!mask ||
      Check(cudaMemcpy(masks.Data, mask, std::size_t(pixels), cudaMemcpyHostToDevice), "copying the mask", error));
  if (!ok)
  {
    return false;
  }
  LaunchImageLoss(images.As<float>(), images.As<float>() + pixels, mask ? masks.As<unsigned char>() : nullptr, width,
    height, weights.L1, weights.DSSIM, 1.0, gradient ? images.As<float>() : nullptr, results.As<double>(), scratch.Data,
    nullptr);
  if (!Check(cudaGetLastError(), "image loss kernels", error) ||
    !Check(cudaMemcpy(values, results.Data, sizeof(values), cudaMemcpyDeviceToHost), "copying the loss", error) ||
    (gradient &&
      !Check(cudaMemcpy(gradient, images.Data, imageBytes, cudaMemcpyDeviceToHost), "copying the gradient", error)))
  {
    return false;
  }
  if (terms)
  {
    *terms = ImageLossTerms();
    terms->L1 = values[0];
    terms->DSSIM = values[1];
    terms->MaskedPixels = static_cast<long>(values[2]);
    terms->Total = values[3];
  }
  return true;
}

} // namespace cuda
} // namespace bigus
