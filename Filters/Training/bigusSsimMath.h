/**
 * @file bigusSsimMath.h
 * @brief The per-pixel arithmetic of the D-SSIM loss term, for the host (bigusImageLoss.cxx) and the device
 *        (Cuda/bigusCudaImageLoss.cu): one definition of the window and of SSIM and its derivatives.
 *
 * SSIM (Wang et al. 2004, Eq. 13) of images X and Y at a pixel, from their window means m1 = G*X, m2 = G*Y and
 * second moments sxx = G*X^2, syy = G*Y^2, sxy = G*XY (G: the 11 x 11 Gaussian window of sigma 1.5 pixels,
 * zero padding outside the image):
 *   SSIM = A1 A2 / (B1 B2), A1 = 2 m1 m2 + C1, A2 = 2 (sxy - m1 m2) + C2, B1 = m1^2 + m2^2 + C1,
 *   B2 = sxx - m1^2 + syy - m2^2 + C2, C1 = 0.01^2, C2 = 0.03^2 (data range 1).
 * Its derivatives with respect to m1, sxx and sxy (the others are not needed for dSSIM/dX):
 *   dSSIM/dm1 = 2 m2 (A2 - A1) / (B1 B2) - 2 m1 SSIM (1/B1 - 1/B2), dSSIM/dsxx = -SSIM / B2,
 *   dSSIM/dsxy = 2 A1 / (B1 B2).
 * With the window self-adjoint, d(sum_p g(p) SSIM(p))/dX = G*D1 + 2 X G*Dxx + Y G*Dxy where D1, Dxx, Dxy are
 * g(p) times the three derivatives at p.
 *
 * Part of BIGUS::Training (public, not wrapped for Python); header only.
 */
#ifndef bigusSsimMath_h
#define bigusSsimMath_h

#include "bigusGaussianMath.h" // BIGUS_HD

#include <cmath>

namespace bigus
{

constexpr int SsimWindow = 11;          ///< pixels, the window's width and height
constexpr int SsimRadius = 5;           ///< pixels, (SsimWindow - 1) / 2
constexpr double SsimWindowSigma = 1.5; ///< pixels
constexpr double SsimC1 = 0.01 * 0.01;
constexpr double SsimC2 = 0.03 * 0.03;

/// SSIM at one pixel and its derivatives with respect to m1, sxx and sxy (see the file's documentation).
struct SsimPixel
{
  double Value, DMean, DSquare, DCross;
};

BIGUS_HD SsimPixel SsimAt(double m1, double m2, double sxx, double syy, double sxy)
{
  const double A1 = 2 * m1 * m2 + SsimC1;
  const double A2 = 2 * (sxy - m1 * m2) + SsimC2;
  const double B1 = m1 * m1 + m2 * m2 + SsimC1;
  const double B2 = sxx - m1 * m1 + syy - m2 * m2 + SsimC2;
  const double s = A1 * A2 / (B1 * B2);
  return { s, 2 * m2 * (A2 - A1) / (B1 * B2) - 2 * m1 * s * (1 / B1 - 1 / B2), -s / B2, 2 * A1 / (B1 * B2) };
}

/// The separable window's 1D weights, w[k] for offsets k - SsimRadius: exp(-x^2 / (2 sigma^2)) normalised to sum
/// 1, as cv::getGaussianKernel(SsimWindow, SsimWindowSigma, CV_64F) gives them.
inline void SsimWindowWeights(double w[SsimWindow])
{
  double sum = 0;
  for (int k = 0; k < SsimWindow; ++k)
  {
    const double x = k - SsimRadius;
    w[k] = std::exp(-x * x / (2 * SsimWindowSigma * SsimWindowSigma));
    sum += w[k];
  }
  for (int k = 0; k < SsimWindow; ++k)
  {
    w[k] /= sum;
  }
}

} // namespace bigus

#endif
