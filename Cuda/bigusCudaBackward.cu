// CUDA renderer, backward: dL/dS, then one warp per Gaussian (see bigusCudaKernels.h). The maths is bigusGaussianMath.h
// and bigusRasterGeometry.h, as on the CPU.
#include "bigusCudaKernels.h"

#include "bigusGaussianMath.h"

namespace bigus
{
namespace cuda
{
namespace
{
/// dL/dS of every pixel: @p dL itself, or dL/dI times dI/dS (in double, as on the CPU).
__global__ void ScatteringGradientKernel(
  const float* S, const float* dL, std::int64_t pixels, bool withRespectToS, double gamma, float* gS)
{
  const std::int64_t p = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (p < pixels)
  {
    gS[p] = withRespectToS ? dL[p] : static_cast<float>(dL[p] * ImageFromScatteringDerivative<double>(S[p], gamma));
  }
}

/**
 * Backward, one warp per Gaussian: every lane sets the footprint up (the same double arithmetic), the
 * lanes share the pixels of its bounding box, each keeps float partial sums of PixelWeightBackward's
 * terms that it flushes into double every few pixels, and a fixed butterfly of shuffles reduces them;
 * lane 0 runs the setup's backward and adds to the Gaussian's gradients, which no other warp touches.
 */
__global__ void BackwardKernel(DeviceField field, PreparedSlice s, double sigmaE, double cutoff, bool nonNegative,
  const float* gS, FieldGradients out, PoseShares pose, Counters* counters)
{
  const std::int64_t i = (std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x) / WarpSize;
  const int lane = threadIdx.x & (WarpSize - 1);
  if (i >= field.Count)
  {
    return; // the whole warp: i is the same for its 32 lanes
  }
  const GaussianParams g = LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, i);
  const double r = EffectiveReflectivity(g.Reflectivity, nonNegative);
  SetupCache cache;
  const Footprint f = SetupFootprint(g, s.Frame, sigmaE, cutoff, &cache);
  int box[4];
  if (!f.Visible || !FootprintBox(f, s, box))
  {
    return;
  }
  const BoxFootprint fp = MakeBoxFootprint(f, s, box, r);
  const int boxWidth = box[1] - box[0] + 1;
  const std::int64_t boxPixels = std::int64_t(boxWidth) * (box[3] - box[2] + 1);
  double sum[7] = { 0, 0, 0, 0, 0, 0, 0 };
  float part[7] = { 0, 0, 0, 0, 0, 0, 0 };
  int pending = 0;
  for (std::int64_t k = lane; k < boxPixels; k += WarpSize)
  {
    const int row = static_cast<int>(k / boxWidth), col = static_cast<int>(k % boxWidth);
    const float dy = row * fp.P2 - fp.Dcy;
    const float dx = col * fp.P0 + (row * fp.P1 - fp.Dcx);
    const float form = AxesForm(fp.Axes[0], fp.Axes[1], fp.Axes[2], fp.Axes[3], dx, dy);
    if (form <= fp.CutoffSquared)
    {
      const float gv = gS[std::int64_t(box[2] + row) * s.Width + box[0] + col];
      PixelWeightBackward(gv, fp.Weight, FastExp(-0.5f * form), fp.A, fp.B, fp.C, dx, dy, part, 1);
      if (++pending == 8)
      {
        for (int t = 0; t < 7; ++t)
        {
          sum[t] += part[t];
          part[t] = 0;
        }
        pending = 0;
      }
    }
  }
  for (int t = 0; t < 7; ++t)
  {
    sum[t] += part[t];
    for (int offset = WarpSize / 2; offset > 0; offset /= 2)
    {
      sum[t] += __shfl_xor_sync(0xffffffffu, sum[t], offset);
    }
  }
  if (lane != 0)
  {
    return;
  }
  AddGaussianGradients(f, cache, s.Frame, sigmaE, sum, r, g.Reflectivity, nonNegative, out, i, pose.Pivot,
    pose.Shares ? pose.Shares + 6 * i : nullptr);
  if (out.VisibleCount)
  {
    out.VisibleCount[i] += 1;
  }
  atomicAdd(&counters->Visible, 1ull);
  atomicAdd(&counters->Evaluations, static_cast<unsigned long long>(boxPixels));
}

/**
 * The slice's pose gradient from the Gaussians' shares [N, 6]: block c sums component c, each thread a
 * fixed stride of Gaussians in index order, then a fixed tree in shared memory, so the sum is the same
 * on every run (the CPU sums in index order: the two differ by rounding).
 */
__global__ void PoseShareSumKernel(const double* shares, std::int64_t count, double* total)
{
  __shared__ double partial[PoseSumBlock];
  const int c = blockIdx.x;
  double sum = 0;
  for (std::int64_t i = threadIdx.x; i < count; i += PoseSumBlock)
  {
    sum += shares[6 * i + c];
  }
  partial[threadIdx.x] = sum;
  __syncthreads();
  for (int half = PoseSumBlock / 2; half > 0; half /= 2)
  {
    if (threadIdx.x < half)
    {
      partial[threadIdx.x] += partial[threadIdx.x + half];
    }
    __syncthreads();
  }
  if (threadIdx.x == 0)
  {
    total[c] += partial[0];
  }
}

}

void LaunchScatteringGradient(const float* S, const float* dL, std::int64_t pixels, bool withRespectToS, double gamma,
  float* gS, cudaStream_t stream)
{
  ScatteringGradientKernel<<<Blocks(pixels, SetupBlock), SetupBlock, 0, stream>>>(
    S, dL, pixels, withRespectToS, gamma, gS);
}

void LaunchBackward(const DeviceField& field, const PreparedSlice& s, double sigmaE, double cutoff, bool nonNegative,
  const float* gS, FieldGradients out, const PoseShares& pose, Counters* counters, cudaStream_t stream)
{
  BackwardKernel<<<Blocks(field.Count * WarpSize, BackwardBlock), BackwardBlock, 0, stream>>>(
    field, s, sigmaE, cutoff, nonNegative, gS, out, pose, counters);
}

void LaunchPoseShareSum(const double* shares, std::int64_t count, double* total, cudaStream_t stream)
{
  PoseShareSumKernel<<<6, PoseSumBlock, 0, stream>>>(shares, count, total);
}

} // namespace cuda
} // namespace bigus
