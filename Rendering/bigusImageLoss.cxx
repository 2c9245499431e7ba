// Losses between rendered and recorded frames (see bigusImageLoss.h). OpenCV does the filtering
// (separable Gaussian window) and the DFT; the gradients are derived below.
#include "bigusImageLoss.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>

namespace bigus
{

namespace
{
constexpr int Window = 11;
constexpr double WindowSigma = 1.5;
constexpr double C1 = 0.01 * 0.01;
constexpr double C2 = 0.03 * 0.03;

/// Gaussian window filter with zero padding: self-adjoint, so it is also its own gradient.
cv::Mat Filter(const cv::Mat& in)
{
  const cv::Mat kernel = cv::getGaussianKernel(Window, WindowSigma, in.depth());
  cv::Mat out;
  cv::sepFilter2D(in, out, in.depth(), kernel, kernel, cv::Point(-1, -1), 0, cv::BORDER_CONSTANT);
  return out;
}

template <typename T>
cv::Mat MaskOf(const unsigned char* mask, int width, int height)
{
  if (!mask)
  {
    return cv::Mat(height, width, cv::DataType<T>::depth, cv::Scalar(1.0));
  }
  cv::Mat m(height, width, CV_8U, const_cast<unsigned char*>(mask));
  cv::Mat nonZero = m != 0;
  cv::Mat out;
  nonZero.convertTo(out, cv::DataType<T>::depth, 1.0 / 255.0);
  return out;
}

template <typename T>
cv::Mat Image(const float* data, int width, int height)
{
  cv::Mat view(height, width, CV_32F, const_cast<float*>(data));
  cv::Mat out;
  view.convertTo(out, cv::DataType<T>::depth);
  return out;
}

/// SSIM map of X and Y and, if @p gradX is non-null, d(sum_p g(p) SSIM(p))/dX for the weights g.
/// SSIM(p) = A1 A2 / (B1 B2), A1 = 2 m1 m2 + C1, A2 = 2 (sxy - m1 m2) + C2, B1 = m1^2 + m2^2 + C1,
/// B2 = sxx - m1^2 + syy - m2^2 + C2 with m1 = G*X, m2 = G*Y, sxx = G*X^2, syy = G*Y^2, sxy = G*XY.
/// dSSIM/dm1 = 2 m2 (A2 - A1) / (B1 B2) - 2 m1 SSIM (1/B1 - 1/B2), dSSIM/dsxx = -SSIM / B2,
/// dSSIM/dsxy = 2 A1 / (B1 B2); then dX = G*(g dSSIM/dm1) + 2 X G*(g dSSIM/dsxx) + Y G*(g dSSIM/dsxy).
template <typename T>
cv::Mat SsimMap(const cv::Mat& X, const cv::Mat& Y, const cv::Mat& g, cv::Mat* gradX)
{
  const cv::Mat m1 = Filter(X), m2 = Filter(Y);
  const cv::Mat sxx = Filter(X.mul(X)), syy = Filter(Y.mul(Y)), sxy = Filter(X.mul(Y));
  const int depth = cv::DataType<T>::depth;
  cv::Mat map(X.size(), depth);
  cv::Mat dm1, dsxx, dsxy;
  if (gradX)
  {
    dm1.create(X.size(), depth);
    dsxx.create(X.size(), depth);
    dsxy.create(X.size(), depth);
  }
  for (int j = 0; j < X.rows; ++j)
  {
    const T* pm1 = m1.ptr<T>(j);
    const T* pm2 = m2.ptr<T>(j);
    const T* pxx = sxx.ptr<T>(j);
    const T* pyy = syy.ptr<T>(j);
    const T* pxy = sxy.ptr<T>(j);
    T* out = map.ptr<T>(j);
    const T* w = gradX ? g.ptr<T>(j) : nullptr;
    T* d1 = gradX ? dm1.ptr<T>(j) : nullptr;
    T* dxx = gradX ? dsxx.ptr<T>(j) : nullptr;
    T* dxy = gradX ? dsxy.ptr<T>(j) : nullptr;
    for (int i = 0; i < X.cols; ++i)
    {
      const double a = pm1[i], b = pm2[i];
      const double A1 = 2 * a * b + C1;
      const double A2 = 2 * (pxy[i] - a * b) + C2;
      const double B1 = a * a + b * b + C1;
      const double B2 = pxx[i] - a * a + pyy[i] - b * b + C2;
      const double s = A1 * A2 / (B1 * B2);
      out[i] = static_cast<T>(s);
      if (w)
      {
        d1[i] = static_cast<T>(w[i] * (2 * b * (A2 - A1) / (B1 * B2) - 2 * a * s * (1 / B1 - 1 / B2)));
        dxx[i] = static_cast<T>(w[i] * (-s / B2));
        dxy[i] = static_cast<T>(w[i] * (2 * A1 / (B1 * B2)));
      }
    }
  }
  if (gradX)
  {
    *gradX = Filter(dm1) + 2 * X.mul(Filter(dsxx)) + Y.mul(Filter(dsxy));
  }
  return map;
}

template <typename T>
ImageLossTerms Compute(const float* rendered, const float* target, const unsigned char* mask, int width, int height,
  const ImageLossWeights& weights, float* gradient)
{
  ImageLossTerms terms;
  const int depth = cv::DataType<T>::depth;
  const cv::Mat m = MaskOf<T>(mask, width, height);
  const cv::Mat x = Image<T>(rendered, width, height);
  const cv::Mat y = Image<T>(target, width, height);
  terms.MaskedPixels = static_cast<long>(cv::countNonZero(m));
  cv::Mat grad(height, width, depth, cv::Scalar(0.0));
  if (terms.MaskedPixels == 0)
  {
    if (gradient)
    {
      std::fill(gradient, gradient + std::size_t(width) * height, 0.0f);
    }
    return terms;
  }
  const double K = static_cast<double>(terms.MaskedPixels);

  if (weights.L1 != 0)
  {
    double sum = 0;
    const T step = static_cast<T>(weights.L1 / K);
    for (int j = 0; j < height; ++j)
    {
      const T* xr = x.ptr<T>(j);
      const T* yr = y.ptr<T>(j);
      const T* mr = m.ptr<T>(j);
      T* gr = grad.ptr<T>(j);
      for (int i = 0; i < width; ++i)
      {
        const T r = xr[i] - yr[i];
        sum += mr[i] * std::abs(double(r));
        gr[i] += mr[i] * step * static_cast<T>((r > 0) - (r < 0));
      }
    }
    terms.L1 = sum / K;
  }
  if (weights.DSSIM != 0)
  {
    const cv::Mat X = x.mul(m), Y = y.mul(m);
    const cv::Mat g = (-weights.DSSIM / K) * m; // d(total)/d(SSIM(p))
    cv::Mat dX;
    const cv::Mat map = SsimMap<T>(X, Y, g, gradient ? &dX : nullptr);
    terms.DSSIM = 1.0 - cv::sum(map.mul(m))[0] / K;
    if (gradient)
    {
      grad += dX.mul(m);
    }
  }
  if (weights.FFL != 0)
  {
    // Orthonormal DFT of the masked residual, zero-padded to OpenCV's next fast transform size
    // (frame sizes such as 820 = 4 x 5 x 41 are slow otherwise): F~ = F / sqrt(N), FFL = (1/N) sum w |F~|^2.
    const int pw = cv::getOptimalDFTSize(width), ph = cv::getOptimalDFTSize(height);
    const double N = double(pw) * ph;
    cv::Mat r;
    cv::copyMakeBorder((x - y).mul(m), r, 0, ph - height, 0, pw - width, cv::BORDER_CONSTANT, cv::Scalar(0));
    cv::Mat F;
    cv::dft(r, F, cv::DFT_COMPLEX_OUTPUT);
    cv::Mat planes[2];
    cv::split(F, planes);
    cv::Mat magnitude;
    cv::magnitude(planes[0], planes[1], magnitude);
    double largest = 0;
    cv::minMaxLoc(magnitude, nullptr, &largest);
    cv::Mat w;
    if (largest > 0)
    {
      cv::pow(magnitude / largest, weights.FFLAlpha, w);
    }
    else
    {
      w = cv::Mat::zeros(magnitude.size(), depth);
    }
    terms.FFL = cv::sum(w.mul(magnitude.mul(magnitude)))[0] / (N * N);
    if (gradient)
    {
      // d/dr of (1/N^2) sum_k w_k |F_k|^2 = (2/N^2) Re(unscaled inverse DFT of w F), w held constant.
      cv::Mat wF;
      cv::Mat weighted[2] = { planes[0].mul(w), planes[1].mul(w) };
      cv::merge(weighted, 2, wF);
      cv::Mat back;
      cv::dft(wF, back, cv::DFT_INVERSE | cv::DFT_COMPLEX_OUTPUT);
      cv::Mat parts[2];
      cv::split(back, parts);
      grad += (weights.FFL * 2.0 / (N * N)) * parts[0](cv::Rect(0, 0, width, height)).mul(m);
    }
  }
  terms.Total = weights.L1 * terms.L1 + weights.DSSIM * terms.DSSIM + weights.FFL * terms.FFL;
  if (gradient)
  {
    cv::Mat out(height, width, CV_32F, gradient);
    grad.convertTo(out, CV_32F);
  }
  return terms;
}
}

ImageLossTerms ComputeImageLoss(const float* rendered, const float* target, const unsigned char* mask, int width,
  int height, const ImageLossWeights& weights, float* gradient, bool doublePrecision)
{
  return doublePrecision ? Compute<double>(rendered, target, mask, width, height, weights, gradient)
                         : Compute<float>(rendered, target, mask, width, height, weights, gradient);
}

double MeanSSIM(const float* x, const float* y, const unsigned char* mask, int width, int height, bool maskImages)
{
  const cv::Mat m = MaskOf<double>(mask, width, height);
  const double K = cv::countNonZero(m);
  if (K == 0)
  {
    return 0;
  }
  cv::Mat X = Image<double>(x, width, height), Y = Image<double>(y, width, height);
  if (maskImages)
  {
    X = X.mul(m);
    Y = Y.mul(m);
  }
  const cv::Mat map = SsimMap<double>(X, Y, cv::Mat(), nullptr);
  return cv::sum(map.mul(m))[0] / K;
}

} // namespace bigus
