// The elevation sigma chosen from a sweep (bigusElevationSigma.h), checked on synthetic sweeps rendered
// from known fields with a known beam sigma and frame spacing.
#include "bigusElevationSigma.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

using namespace bigus;

namespace
{
constexpr int W = 64, H = 64;
constexpr double Pixel = 0.3; // mm

/// A speckle-like field: many small Gaussians of signed reflectivity (in-plane scale 0.45 mm, 0.05 mm
/// along z) filling 19.2 x 19.2 x @p depth mm around z = 0.
GaussianField SpeckleField(int n, double depth, unsigned seed)
{
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0, 1);
  std::normal_distribution<double> normal(0, 1);
  GaussianField f;
  for (int i = 0; i < n; ++i)
  {
    f.Means.push_back(static_cast<float>(19.2 * u01(rng)));
    f.Means.push_back(static_cast<float>(19.2 * u01(rng)));
    f.Means.push_back(static_cast<float>(depth * (u01(rng) - 0.5)));
    f.LogScales.push_back(static_cast<float>(std::log(0.45)));
    f.LogScales.push_back(static_cast<float>(std::log(0.45)));
    f.LogScales.push_back(static_cast<float>(std::log(0.05)));
    f.Quaternions.insert(f.Quaternions.end(), { 1.f, 0.f, 0.f, 0.f });
    f.Reflectivities.push_back(static_cast<float>(0.3 + 0.5 * normal(rng)));
  }
  return f;
}

/// @p frames parallel frames @p spacing mm apart along z, centred on z = 0, rendered from @p truth
/// with elevation sigma @p sigma; every 4th frame (k mod 4 == 2) is held out.
TrainingData Sweep(const GaussianField& truth, double sigma, double spacing, int frames, std::vector<int>& heldOut)
{
  std::vector<std::array<double, 16>> poses;
  for (int k = 0; k < frames; ++k)
  {
    const double z = (k - 0.5 * (frames - 1)) * spacing;
    poses.push_back({ Pixel, 0, 0, 0, 0, Pixel, 0, 0, 0, 0, 0, z, 0, 0, 0, 1 });
  }
  return RenderedSweep(truth, poses, W, H, sigma, heldOut);
}

/// Mean PSNR of the held-out frames after training with @p sigma (fixed seed and steps).
double HeldOutPsnr(const TrainingData& data, const std::vector<int>& heldOut, double sigma)
{
  TrainerSettings s;
  s.ElevationSigma = sigma;
  s.InitialGaussians = 4000;
  s.Iterations = 1500;
  Trainer trainer(data, s);
  std::string error;
  EXPECT_TRUE(trainer.Initialize(&error)) << error;
  EXPECT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  ImageMetrics metrics;
  EXPECT_TRUE(trainer.Evaluate(heldOut, metrics, &error)) << error;
  return metrics.PSNR;
}
}

// Parallel frames through a speckle field: the measured correlation follows exp(-d^2 / (4 sigma_eff^2))
// with sigma_eff^2 = sigma^2 + 0.05^2 (the beam and the Gaussians' own extent along z), so the fit
// recovers the beam sigma.
TEST(ElevationSigma, DecorrelationOfASpeckleFieldGivesItsBeamSigma)
{
  for (double sigma : { 0.3, 0.6 })
  {
    const GaussianField truth = SpeckleField(20000, 8.0, 5);
    std::vector<int> heldOut;
    TrainingData data = Sweep(truth, sigma, 0.1, 40, heldOut);
    data.TrainFrames.clear();
    for (int k = 0; k < data.Count(); ++k)
    {
      data.TrainFrames.push_back(k);
    }
    ElevationDecorrelation m;
    std::string error;
    ASSERT_TRUE(MeasureElevationDecorrelation(data, ElevationDecorrelationSettings(), m, &error)) << error;
    const double expected = std::sqrt(sigma * sigma + 0.05 * 0.05);
    std::printf("beam sigma %.2f mm: decorrelation sigma %.3f mm (expected %.3f), neighbour spacing %.3f mm, "
                "correlation %.3f at %.2f mm\n",
      sigma, m.DecorrelationSigma, expected, m.NeighbourSpacing, m.Correlation.front(), m.Distance.front());
    EXPECT_NEAR(m.DecorrelationSigma, expected, 0.15 * expected);
    EXPECT_NEAR(m.NeighbourSpacing, 0.1, 1e-6);
  }
}

// The rule on two sweeps of known sigma and spacing: frames farther apart than the beam (sigma 0.3 mm,
// 0.6 mm apart) and frames closer than the beam (sigma 0.6 mm, 0.2 mm apart). Either way the chosen
// sigma trains a field whose held-out PSNR is within 0.3 dB of the one trained with the true sigma.
TEST(ElevationSigma, ChosenSigmaTrainsAsWellAsTheTrueOne)
{
  struct Case
  {
    double Sigma, Spacing;
    int Frames;
  };
  for (const Case c : { Case{ 0.3, 0.6, 24 }, Case{ 0.6, 0.2, 40 } })
  {
    const GaussianField truth = SpeckleField(6000, c.Spacing * c.Frames, 11);
    std::vector<int> heldOut;
    const TrainingData data = Sweep(truth, c.Sigma, c.Spacing, c.Frames, heldOut);
    const ElevationSigmaChoice choice = ChooseElevationSigma(data);
    const double chosen = HeldOutPsnr(data, heldOut, choice.Sigma);
    const double known = HeldOutPsnr(data, heldOut, c.Sigma);
    std::printf("true sigma %.2f mm, frames %.2f mm apart: chosen %.3f mm (%s); held-out PSNR %.2f dB against "
                "%.2f with the true sigma\n",
      c.Sigma, c.Spacing, choice.Sigma, choice.Reason.c_str(), chosen, known);
    EXPECT_GE(chosen, known - 0.3);
  }
}

TEST(ElevationSigma, FewerThanTwoTrainingFramesFallBackToTheFixedDefault)
{
  std::vector<int> heldOut;
  TrainingData data = Sweep(SpeckleField(100, 2.0, 1), 0.5, 0.2, 3, heldOut);
  data.TrainFrames = { 0 };
  const ElevationSigmaChoice choice = ChooseElevationSigma(data);
  EXPECT_EQ(choice.Sigma, 0.5);
  EXPECT_NE(choice.Reason.find("at least two training frames"), std::string::npos) << choice.Reason;
}

TEST(ElevationSigma, InconsistentDataIsAnErrorNotACrash)
{
  std::vector<int> heldOut;
  TrainingData data = Sweep(SpeckleField(100, 2.0, 1), 0.5, 0.2, 6, heldOut);
  data.Frames.resize(data.Frames.size() / 2); // fewer pixels than the poses announce
  ElevationDecorrelation m;
  std::string error;
  EXPECT_FALSE(MeasureElevationDecorrelation(data, ElevationDecorrelationSettings(), m, &error));
  EXPECT_NE(error.find("inconsistent sizes"), std::string::npos) << error;
  const ElevationSigmaChoice choice = ChooseElevationSigma(data);
  EXPECT_EQ(choice.Sigma, 0.5);
}
