// Training losses: every gradient against central finite differences, FFL against a direct O(N^2)
// DFT, SSIM against known cases.
#include "bigusImageLoss.h"
#include "bigusSsimMath.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <random>
#include <vector>

using namespace bigus;

namespace
{
constexpr int W = 23, H = 19;

struct Images
{
  std::vector<float> X, Y;
  std::vector<unsigned char> Mask;
};

/// Random images whose residual stays away from 0 (L1 is not differentiable there), and an
/// elliptical mask that leaves a border outside.
Images MakeImages(unsigned seed)
{
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.1f, 0.9f);
  Images im;
  for (int p = 0; p < W * H; ++p)
  {
    const float y = u(rng);
    const float offset = 0.05f + 0.1f * u(rng);
    im.Y.push_back(y);
    im.X.push_back(p % 2 ? y + offset : y - offset);
    const int i = p % W, j = p / W;
    im.Mask.push_back(std::pow((i - 11.0) / 10.0, 2) + std::pow((j - 9.0) / 8.0, 2) <= 1.0 ? 1 : 0);
  }
  return im;
}

void CheckGradient(const ImageLossWeights& weights, double tolerance)
{
  Images im = MakeImages(4);
  std::vector<float> grad(W * H);
  ComputeImageLoss(im.X.data(), im.Y.data(), im.Mask.data(), W, H, weights, grad.data(), true);
  double largest = 0;
  for (float g : grad)
  {
    largest = std::max(largest, double(std::abs(g)));
  }
  ASSERT_GT(largest, 0);
  double worst = 0;
  for (int p = 0; p < W * H; ++p)
  {
    const float x = im.X[p];
    const float h = 1.0f / 1024; // exact in float, so the step is exactly what the loss sees
    im.X[p] = x + h;
    const double up = ComputeImageLoss(im.X.data(), im.Y.data(), im.Mask.data(), W, H, weights, nullptr, true).Total;
    im.X[p] = x - h;
    const double down = ComputeImageLoss(im.X.data(), im.Y.data(), im.Mask.data(), W, H, weights, nullptr, true).Total;
    im.X[p] = x;
    const double fd = (up - down) / (2.0 * h);
    const double err = std::abs(fd - grad[p]) / std::max({ std::abs(fd), double(std::abs(grad[p])), 1e-3 * largest });
    worst = std::max(worst, err);
    EXPECT_LE(err, tolerance) << "pixel " << p << ": finite difference " << fd << ", analytic " << grad[p];
    if (!im.Mask[p])
    {
      EXPECT_EQ(grad[p], 0.0f) << "no gradient outside the fan mask";
    }
  }
  std::printf("worst relative error %.3g\n", worst);
}
}

TEST(ImageLoss, L1GradientMatchesFiniteDifferences)
{
  ImageLossWeights w;
  w.L1 = 1;
  w.DSSIM = 0;
  w.FFL = 0;
  CheckGradient(w, 1e-5);
}

TEST(ImageLoss, DssimGradientMatchesFiniteDifferences)
{
  ImageLossWeights w;
  w.L1 = 0;
  w.DSSIM = 1;
  w.FFL = 0;
  // The gradient is exact; the tolerance covers the float rounding of the stored gradient and
  // the O(h^2) truncation of the central difference.
  CheckGradient(w, 2e-4);
}

TEST(ImageLoss, FflGradientMatchesFiniteDifferencesWithUniformWeights)
{
  ImageLossWeights w;
  w.L1 = 0;
  w.DSSIM = 0;
  w.FFL = 1;
  w.FFLAlpha = 0; // the spectrum weight is then constant, so finite differences see the same loss
  CheckGradient(w, 1e-4);
}

TEST(ImageLoss, FflMatchesADirectDftWithFocalWeights)
{
  const Images im = MakeImages(9);
  ImageLossWeights w;
  w.L1 = 0;
  w.DSSIM = 0;
  w.FFL = 1;
  w.FFLAlpha = 1;
  std::vector<float> grad(W * H);
  const ImageLossTerms t = ComputeImageLoss(im.X.data(), im.Y.data(), im.Mask.data(), W, H, w, grad.data(), true);
  // Direct DFT of the masked residual zero-padded to the next 5-smooth sizes (as documented: 24 x 20),
  // weights (|F| / max |F|), held constant for the gradient.
  constexpr int PW = 24, PH = 20;
  const double N = PW * PH;
  std::vector<std::complex<double>> F(PW * PH);
  for (int v = 0; v < PH; ++v)
  {
    for (int u = 0; u < PW; ++u)
    {
      std::complex<double> sum = 0;
      for (int j = 0; j < H; ++j)
      {
        for (int i = 0; i < W; ++i)
        {
          const int p = j * W + i;
          const double r = im.Mask[p] ? double(im.X[p]) - double(im.Y[p]) : 0.0;
          sum += r * std::polar(1.0, -2 * M_PI * (double(u) * i / PW + double(v) * j / PH));
        }
      }
      F[v * PW + u] = sum;
    }
  }
  double largest = 0;
  for (const auto& f : F)
  {
    largest = std::max(largest, std::abs(f));
  }
  double loss = 0;
  std::vector<double> weight(PW * PH);
  for (int k = 0; k < PW * PH; ++k)
  {
    weight[k] = std::abs(F[k]) / largest;
    loss += weight[k] * std::norm(F[k]) / (N * N);
  }
  EXPECT_NEAR(t.FFL, loss, 1e-12 * loss);
  for (int j = 0; j < H; ++j)
  {
    for (int i = 0; i < W; ++i)
    {
      const int p = j * W + i;
      double g = 0;
      for (int v = 0; v < PH; ++v)
      {
        for (int u = 0; u < PW; ++u)
        {
          g += 2 * weight[v * PW + u] *
            std::real(
              std::conj(F[v * PW + u]) * std::polar(1.0, -2 * M_PI * (double(u) * i / PW + double(v) * j / PH)));
        }
      }
      g = im.Mask[p] ? g / (N * N) : 0.0;
      EXPECT_NEAR(grad[p], g, 1e-6 * std::abs(g) + 1e-9) << "pixel " << p;
    }
  }
}

TEST(ImageLoss, SsimDerivativesOfOnePixelMatchFiniteDifferences)
{
  // SsimAt (bigusSsimMath.h, shared by this loss and the CUDA engine's): its three derivatives against central
  // differences of its own value, at moments of an ordinary window and of a nearly flat one (B2 near C2).
  const double cases[][5] = { { 0.4, 0.55, 0.2, 0.33, 0.24 }, { 0.9, 0.88, 0.8101, 0.7745, 0.7920 } };
  for (const auto& m : cases)
  {
    const SsimPixel s = SsimAt(m[0], m[1], m[2], m[3], m[4]);
    const double h = 1e-7; // the flat window's curvature is large: a small step, still far above rounding
    const double dMean =
      (SsimAt(m[0] + h, m[1], m[2], m[3], m[4]).Value - SsimAt(m[0] - h, m[1], m[2], m[3], m[4]).Value) / (2 * h);
    const double dSquare =
      (SsimAt(m[0], m[1], m[2] + h, m[3], m[4]).Value - SsimAt(m[0], m[1], m[2] - h, m[3], m[4]).Value) / (2 * h);
    const double dCross =
      (SsimAt(m[0], m[1], m[2], m[3], m[4] + h).Value - SsimAt(m[0], m[1], m[2], m[3], m[4] - h).Value) / (2 * h);
    EXPECT_NEAR(s.DMean, dMean, 1e-6 * std::max(1.0, std::abs(dMean)));
    EXPECT_NEAR(s.DSquare, dSquare, 1e-6 * std::max(1.0, std::abs(dSquare)));
    EXPECT_NEAR(s.DCross, dCross, 1e-6 * std::max(1.0, std::abs(dCross)));
  }
  double w[SsimWindow];
  SsimWindowWeights(w);
  double sum = 0;
  for (double v : w)
  {
    sum += v;
  }
  EXPECT_NEAR(sum, 1.0, 1e-15);
  EXPECT_NEAR(w[SsimRadius + 1] / w[SsimRadius], std::exp(-1.0 / (2 * 1.5 * 1.5)), 1e-15);
}

TEST(ImageLoss, SsimKnownCases)
{
  const Images im = MakeImages(2);
  EXPECT_NEAR(MeanSSIM(im.Y.data(), im.Y.data(), im.Mask.data(), W, H, false), 1.0, 1e-12) << "identical images";
  // A constant brightness offset keeps contrast and structure; SSIM drops by the luminance term only.
  std::vector<float> brighter(im.Y);
  for (float& v : brighter)
  {
    v += 0.2f;
  }
  const double shifted = MeanSSIM(im.Y.data(), brighter.data(), nullptr, W, H, false);
  EXPECT_GT(shifted, 0.5);
  EXPECT_LT(shifted, 0.999);
  // An inverted image is anti-correlated: SSIM below zero.
  std::vector<float> inverted(im.Y);
  for (float& v : inverted)
  {
    v = 1.0f - v;
  }
  EXPECT_LT(MeanSSIM(im.Y.data(), inverted.data(), nullptr, W, H, false), 0.0);
  ImageLossWeights w;
  const ImageLossTerms same = ComputeImageLoss(im.Y.data(), im.Y.data(), im.Mask.data(), W, H, w, nullptr);
  EXPECT_NEAR(same.Total, 0.0, 1e-12);
  EXPECT_EQ(same.MaskedPixels, std::count(im.Mask.begin(), im.Mask.end(), 1));
}

TEST(ImageLoss, FloatEvaluationAgreesWithDouble)
{
  const Images im = MakeImages(12);
  ImageLossWeights w; // every term on
  std::vector<float> gf(W * H), gd(W * H);
  const ImageLossTerms f = ComputeImageLoss(im.X.data(), im.Y.data(), im.Mask.data(), W, H, w, gf.data(), false);
  const ImageLossTerms d = ComputeImageLoss(im.X.data(), im.Y.data(), im.Mask.data(), W, H, w, gd.data(), true);
  EXPECT_NEAR(f.Total, d.Total, 1e-5 * d.Total);
  double largest = 0, worst = 0;
  for (int p = 0; p < W * H; ++p)
  {
    largest = std::max(largest, double(std::abs(gd[p])));
    worst = std::max(worst, double(std::abs(gf[p] - gd[p])));
  }
  EXPECT_LE(worst, 1e-4 * largest);
}
