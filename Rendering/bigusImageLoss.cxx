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
  static const cv::Mat kernel = cv::getGaussianKernel(Window, WindowSigma, CV_64F);
  cv::Mat out;
  cv::sepFilter2D(in, out, CV_64F, kernel, kernel, cv::Point(-1, -1), 0, cv::BORDER_CONSTANT);
  return out;
}

cv::Mat MaskOf(const unsigned char* mask, int width, int height)
{
  if (!mask)
  {
    return cv::Mat(height, width, CV_64F, cv::Scalar(1.0));
  }
  cv::Mat m(height, width, CV_8U, const_cast<unsigned char*>(mask));
  cv::Mat out;
  cv::Mat nonZero = m != 0;
  nonZero.convertTo(out, CV_64F, 1.0 / 255.0);
  return out;
}

/// SSIM map of X and Y and, if @p gradX is non-null, d(sum_p g(p) SSIM(p))/dX for the weights g.
/// SSIM(p) = A1 A2 / (B1 B2), A1 = 2 m1 m2 + C1, A2 = 2 (sxy - m1 m2) + C2, B1 = m1^2 + m2^2 + C1,
/// B2 = sxx - m1^2 + syy - m2^2 + C2 with m1 = G*X, m2 = G*Y, sxx = G*X^2, syy = G*Y^2, sxy = G*XY.
/// dSSIM/dm1 = 2 m2 (A2 - A1) / (B1 B2) - 2 m1 SSIM (1/B1 - 1/B2), dSSIM/dsxx = -SSIM / B2,
/// dSSIM/dsxy = 2 A1 / (B1 B2); then dX = G*(g dSSIM/dm1) + 2 X G*(g dSSIM/dsxx) + Y G*(g dSSIM/dsxy).
cv::Mat SsimMap(const cv::Mat& X, const cv::Mat& Y, const cv::Mat& g, cv::Mat* gradX)
{
  const cv::Mat m1 = Filter(X), m2 = Filter(Y);
  const cv::Mat sxx = Filter(X.mul(X)), syy = Filter(Y.mul(Y)), sxy = Filter(X.mul(Y));
  cv::Mat map(X.size(), CV_64F);
  cv::Mat dm1, dsxx, dsxy;
  if (gradX)
  {
    dm1.create(X.size(), CV_64F);
    dsxx.create(X.size(), CV_64F);
    dsxy.create(X.size(), CV_64F);
  }
  for (int j = 0; j < X.rows; ++j)
  {
    for (int i = 0; i < X.cols; ++i)
    {
      const double a = m1.at<double>(j, i), b = m2.at<double>(j, i);
      const double A1 = 2 * a * b + C1;
      const double A2 = 2 * (sxy.at<double>(j, i) - a * b) + C2;
      const double B1 = a * a + b * b + C1;
      const double B2 = sxx.at<double>(j, i) - a * a + syy.at<double>(j, i) - b * b + C2;
      const double s = A1 * A2 / (B1 * B2);
      map.at<double>(j, i) = s;
      if (gradX)
      {
        const double w = g.at<double>(j, i);
        dm1.at<double>(j, i) = w * (2 * b * (A2 - A1) / (B1 * B2) - 2 * a * s * (1 / B1 - 1 / B2));
        dsxx.at<double>(j, i) = w * (-s / B2);
        dsxy.at<double>(j, i) = w * (2 * A1 / (B1 * B2));
      }
    }
  }
  if (gradX)
  {
    *gradX = Filter(dm1) + 2 * X.mul(Filter(dsxx)) + Y.mul(Filter(dsxy));
  }
  return map;
}
}

ImageLossTerms ComputeImageLoss(const float* rendered, const float* target, const unsigned char* mask, int width,
  int height, const ImageLossWeights& weights, float* gradient)
{
  ImageLossTerms terms;
  const cv::Mat m = MaskOf(mask, width, height);
  cv::Mat x, y;
  cv::Mat(height, width, CV_32F, const_cast<float*>(rendered)).convertTo(x, CV_64F);
  cv::Mat(height, width, CV_32F, const_cast<float*>(target)).convertTo(y, CV_64F);
  terms.MaskedPixels = static_cast<long>(cv::countNonZero(m));
  cv::Mat grad(height, width, CV_64F, cv::Scalar(0.0));
  if (terms.MaskedPixels == 0)
  {
    if (gradient)
    {
      std::fill(gradient, gradient + std::size_t(width) * height, 0.0f);
    }
    return terms;
  }
  const double K = static_cast<double>(terms.MaskedPixels);
  const cv::Mat residual = x - y;

  if (weights.L1 != 0)
  {
    terms.L1 = cv::sum(cv::abs(residual).mul(m))[0] / K;
    if (gradient)
    {
      cv::Mat sign(height, width, CV_64F);
      for (int j = 0; j < height; ++j)
      {
        for (int i = 0; i < width; ++i)
        {
          const double r = residual.at<double>(j, i);
          sign.at<double>(j, i) = (r > 0) - (r < 0);
        }
      }
      grad += (weights.L1 / K) * sign.mul(m);
    }
  }
  if (weights.DSSIM != 0)
  {
    const cv::Mat X = x.mul(m), Y = y.mul(m);
    const cv::Mat g = (-weights.DSSIM / K) * m; // d(total)/d(SSIM(p))
    cv::Mat dX;
    const cv::Mat map = SsimMap(X, Y, g, gradient ? &dX : nullptr);
    terms.DSSIM = 1.0 - cv::sum(map.mul(m))[0] / K;
    if (gradient)
    {
      grad += dX.mul(m);
    }
  }
  if (weights.FFL != 0)
  {
    // Orthonormal DFT of the masked residual: F~ = F / sqrt(N), FFL = (1/N) sum w |F~|^2.
    const double N = double(width) * height;
    const cv::Mat r = residual.mul(m);
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
      w = cv::Mat::zeros(magnitude.size(), CV_64F);
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
      grad += (weights.FFL * 2.0 / (N * N)) * parts[0].mul(m);
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

double MeanSSIM(const float* x, const float* y, const unsigned char* mask, int width, int height, bool maskImages)
{
  const cv::Mat m = MaskOf(mask, width, height);
  const double K = cv::countNonZero(m);
  if (K == 0)
  {
    return 0;
  }
  cv::Mat X, Y;
  cv::Mat(height, width, CV_32F, const_cast<float*>(x)).convertTo(X, CV_64F);
  cv::Mat(height, width, CV_32F, const_cast<float*>(y)).convertTo(Y, CV_64F);
  if (maskImages)
  {
    X = X.mul(m);
    Y = Y.mul(m);
  }
  const cv::Mat map = SsimMap(X, Y, cv::Mat(), nullptr);
  return cv::sum(map.mul(m))[0] / K;
}

} // namespace bigus
