// Image metrics on cases with a known answer: identical images, a blurred copy, matching noise.
#include "bigusImageMetrics.h"

#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

using namespace bigus;

namespace
{
constexpr int W = 160, H = 128;

/// Fully developed speckle: Rayleigh-distributed amplitude (|complex Gaussian|), scaled into [0, 1].
std::vector<float> Speckle(unsigned seed)
{
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0, 1);
  std::vector<float> image(W * H);
  for (float& v : image)
  {
    v = static_cast<float>(std::min(1.0, 0.15 * std::hypot(normal(rng), normal(rng))));
  }
  return image;
}
}

TEST(ImageMetrics, IdenticalImagesScorePerfectly)
{
  const std::vector<float> a = Speckle(1);
  std::vector<unsigned char> mask(W * H, 1);
  const ImageMetrics m = CompareImages(a.data(), a.data(), mask.data(), W, H);
  EXPECT_EQ(m.PSNR, 100.0);
  EXPECT_NEAR(m.SSIM, 1.0, 1e-12);
  EXPECT_NEAR(m.NCC, 1.0, 1e-12);
  EXPECT_NEAR(m.Speckle, 1.0, 1e-12);
  EXPECT_EQ(m.Patches, ((W - 16) / 8 + 1) * ((H - 16) / 8 + 1));
}

TEST(ImageMetrics, PsnrAndNccOfAKnownDifference)
{
  const std::vector<float> a = Speckle(2);
  std::vector<float> b(a);
  for (float& v : b)
  {
    v += 0.01f; // MSE 1e-4: PSNR 40 dB, correlation unchanged
  }
  const ImageMetrics m = CompareImages(b.data(), a.data(), nullptr, W, H);
  EXPECT_NEAR(m.PSNR, 40.0, 1e-3);
  EXPECT_NEAR(m.NCC, 1.0, 1e-9);
}

TEST(ImageMetrics, SpeckleScoreDropsForSmoothedSpeckleAndStaysHighForMatchingNoise)
{
  const std::vector<float> truth = Speckle(3);
  std::vector<float> blurred(W * H);
  cv::GaussianBlur(cv::Mat(H, W, CV_32F, const_cast<float*>(truth.data())), cv::Mat(H, W, CV_32F, blurred.data()),
    cv::Size(0, 0), 2.0);
  const std::vector<float> other = Speckle(4); // same statistics, other realisation
  const ImageMetrics smooth = CompareImages(blurred.data(), truth.data(), nullptr, W, H);
  const ImageMetrics noise = CompareImages(other.data(), truth.data(), nullptr, W, H);
  std::printf("speckle score: blurred copy %.3f, independent speckle of the same statistics %.3f\n", smooth.Speckle,
    noise.Speckle);
  EXPECT_LT(smooth.Speckle, 0.6);
  EXPECT_GT(noise.Speckle, 0.9);
  // The pixel metrics rank them the other way round: that is why the speckle score exists.
  EXPECT_GT(smooth.PSNR, noise.PSNR);
}

TEST(ImageMetrics, OnlyMaskedPixelsCount)
{
  const std::vector<float> a = Speckle(5);
  std::vector<float> b(a);
  std::vector<unsigned char> mask(W * H, 1);
  for (int p = 0; p < W * 10; ++p)
  {
    b[p] = 1.0f - b[p]; // damage the first ten rows only ...
    mask[p] = 0;        // ... which the mask excludes
  }
  const ImageMetrics m = CompareImages(b.data(), a.data(), mask.data(), W, H);
  EXPECT_EQ(m.PSNR, 100.0);
  EXPECT_NEAR(m.Speckle, 1.0, 1e-12);
}
