// The elevation sigma chosen from a sweep (bigusElevationSigma.h), checked on synthetic sweeps rendered
// from known fields with a known beam sigma and frame spacing.
#include "bigusElevationSigma.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"
#include "bigusValidation.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <algorithm>
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
  s.Poses.RefinePoses = PoseRefinement::Off; // exact poses: the sigma alone is compared
  s.Seeding.InitialGaussians = 4000;
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

// A fanning sweep (each frame tilted 0.4 degrees from the last about its top row, 0.06 mm further along z and shifted
// 0.037 mm sideways, so no pixel of one frame falls on a pixel of another) measures the same read in either order:
// every pair is sampled both ways, at one frame's pixels and bilinear in the other's. Sampled one way only (the first
// frame of each pair at its pixels), the liver read backwards measured 0.868 mm against 0.841 read forwards (`bigus
// info`; docs/FINDINGS.md, "The speckle measured both ways").
TEST(ElevationSigma, ASweepReadBackwardsOrMovedRigidlyMeasuresTheSame)
{
  const GaussianField truth = SpeckleField(20000, 8.0, 7);
  const int frames = 30;
  std::vector<std::array<double, 16>> poses;
  for (int k = 0; k < frames; ++k)
  {
    const double tilt = (k - 0.5 * (frames - 1)) * 0.4 * 3.141592653589793 / 180;
    poses.push_back({ Pixel, 0, 0, 0.037 * k, 0, Pixel * std::cos(tilt), 0, 0, 0, Pixel * std::sin(tilt), 0,
      0.06 * (k - 0.5 * (frames - 1)), 0, 0, 0, 1 });
  }
  std::vector<int> heldOut;
  TrainingData data = RenderedSweep(truth, poses, W, H, 0.4, heldOut);
  data.TrainFrames.clear();
  for (int k = 0; k < data.Count(); ++k)
  {
    data.TrainFrames.push_back(k);
  }
  // The same images and poses, last frame first.
  TrainingData backwards = data;
  const std::size_t pixels = std::size_t(W) * H;
  for (int k = 0; k < frames; ++k)
  {
    backwards.Poses[k] = data.Poses[frames - 1 - k];
    std::copy_n(data.Frames.begin() + pixels * (frames - 1 - k), pixels, backwards.Frames.begin() + pixels * k);
  }
  // Every bin, sample count, fit and spacing of @p b as of @p a (the spacing within @p spacingTolerance, mm).
  auto expectSame = [](const ElevationDecorrelation& a, const ElevationDecorrelation& b, double spacingTolerance) {
    ASSERT_EQ(a.Distance, b.Distance);
    EXPECT_EQ(a.Samples, b.Samples);
    for (std::size_t bin = 0; bin < a.Correlation.size(); ++bin)
    {
      EXPECT_NEAR(a.Correlation[bin], b.Correlation[bin], 1e-9) << "bin " << a.Distance[bin] << " mm";
    }
    EXPECT_NEAR(a.DecorrelationSigma, b.DecorrelationSigma, 1e-9);
    EXPECT_NEAR(a.NeighbourSpacing, b.NeighbourSpacing, spacingTolerance);
  };
  ElevationDecorrelation read[2];
  std::string error;
  ASSERT_TRUE(MeasureElevationDecorrelation(data, ElevationDecorrelationSettings(), read[0], &error)) << error;
  ASSERT_TRUE(MeasureElevationDecorrelation(backwards, ElevationDecorrelationSettings(), read[1], &error)) << error;
  std::printf("forwards: decorrelation sigma %.6f mm, spacing %.6f mm; backwards: %.6f mm, %.6f mm\n",
    read[0].DecorrelationSigma, read[0].NeighbourSpacing, read[1].DecorrelationSigma, read[1].NeighbourSpacing);
  expectSame(read[0], read[1], 0.0);
  EXPECT_NEAR(read[0].DecorrelationSigma, std::sqrt(0.4 * 0.4 + 0.05 * 0.05), 0.15 * 0.4); // and still the beam

  // The same frames in another reference frame (every pose turned 37 degrees about (3, -5, 8) and moved by (250, -120,
  // 400) mm, as another tracker's base would put them) measure the same: only distances between frames count.
  Eigen::Affine3d motion(Eigen::AngleAxisd(37 * 3.141592653589793 / 180, Eigen::Vector3d(0.3, -0.5, 0.8).normalized()));
  motion.translation() = Eigen::Vector3d(250, -120, 400);
  for (std::array<double, 16>& pose : data.Poses)
  {
    Eigen::Map<Eigen::Matrix<double, 4, 4, Eigen::RowMajor>> matrix(pose.data());
    matrix = (motion.matrix() * matrix).eval();
  }
  ElevationDecorrelation moved;
  ASSERT_TRUE(MeasureElevationDecorrelation(data, ElevationDecorrelationSettings(), moved, &error)) << error;
  expectSame(read[0], moved, 1e-9);
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

// Whether the speckle correlates is read from the fit's rho0, not from the first bin alone. In a sparse rocking sweep
// (the liver's training frames taken one in 3, 2.29 mm apart) the first bin holds only the few pixels where two tilted
// frames cross, whose speckle is turned in plane against each other: it correlates less than the bins after it, and a
// first bin just under 0.3 had switched the beam to the frame spacing, 2.29 mm for a beam near 0.3 mm (33.62 dB held
// out at 0.3 mm, 32.64 at the spacing; docs/FINDINGS.md, "A sparse sweep's beam"). Truth: rho0 exp(-d^2 / (4
// sigma^2)) with rho0 0.6 and sigma 0.8 mm, the first bin lowered to 0.28 with a twentieth of the others' pairs; and
// the spine phantom's measured curve (`bigus info SpinePhantomFreehand.igs.mha`: no speckle shared at any distance),
// which keeps the spacing.
TEST(ElevationSigma, AFirstBinOfCrossingFramesDoesNotDecideWhetherTheSpeckleCorrelates)
{
  SweepDecorrelation sparse;
  sparse.Measured = true;
  ElevationDecorrelation& m = sparse.Measurement;
  for (int k = 0; k < 20; ++k)
  {
    const double d = 0.05 + 0.1 * k;
    m.Distance.push_back(d);
    m.Correlation.push_back(k == 0 ? 0.28 : 0.6 * std::exp(-d * d / (4 * 0.8 * 0.8)));
    m.Samples.push_back(k == 0 ? 1000 : 20000);
  }
  m.NeighbourSpacing = 2.29;
  FitElevationDecorrelation(m);
  EXPECT_NEAR(m.DecorrelationSigma, 0.8, 0.04);
  EXPECT_NEAR(m.ZeroDistanceCorrelation, 0.6, 0.03);
  ElevationSigmaChoice choice = ChooseElevationSigma({ sparse });
  EXPECT_NEAR(choice.Sigma, ElevationSigmaDecorrelationFactor * m.DecorrelationSigma, 1e-12) << choice.Reason;
  EXPECT_NE(choice.Reason.find("(correlation 0.60 at 0 mm by its fit)"), std::string::npos) << choice.Reason;

  SweepDecorrelation spine;
  spine.Measured = true;
  ElevationDecorrelation& n = spine.Measurement;
  n.Distance = { 0.55, 0.75, 1.05, 1.25, 1.45, 1.65, 1.85, 2.05, 2.25 };
  n.Correlation = { 0.082, 0.166, 0.055, 0.167, 0.135, 0.073, 0.047, -0.018, -0.019 };
  n.Samples.assign(n.Distance.size(), 5000);
  n.NeighbourSpacing = 1.59;
  FitElevationDecorrelation(n);
  EXPECT_LT(n.ZeroDistanceCorrelation, 0.3);
  choice = ChooseElevationSigma({ spine });
  EXPECT_NEAR(choice.Sigma, ElevationSigmaSpacingFactor * 1.59, 1e-12) << choice.Reason;
  EXPECT_NE(choice.Reason.find("does not correlate across it (correlation 0."), std::string::npos) << choice.Reason;

  // Bins of unequal lengths, or none, fit nothing (no NaN).
  n.Samples.pop_back();
  FitElevationDecorrelation(n);
  EXPECT_EQ(n.DecorrelationSigma, 0.0);
  EXPECT_EQ(n.ZeroDistanceCorrelation, 0.0);
}

// CorrelationAtNeighbourSpacing on a measurement written by hand: linear between the bins around the spacing,
// the first bin's below it, 0 past the last bin.
TEST(PoseRefinementChoice, CorrelationAtTheNeighbourSpacingIsInterpolatedBetweenBins)
{
  ElevationDecorrelation m;
  m.Distance = { 0.15, 0.25, 0.35 };
  m.Correlation = { 0.9, 0.5, 0.2 };
  m.Samples = { 1000, 1000, 1000 };
  const double cases[][2] = { { 0.05, 0.9 }, { 0.15, 0.9 }, { 0.2, 0.7 }, { 0.325, 0.275 }, { 0.35, 0.2 }, { 0.5, 0 } };
  for (const auto& c : cases)
  {
    m.NeighbourSpacing = c[0];
    EXPECT_NEAR(CorrelationAtNeighbourSpacing(m), c[1], 1e-12) << "spacing " << c[0];
  }
  m.Distance.clear();
  m.Correlation.clear();
  EXPECT_EQ(CorrelationAtNeighbourSpacing(m), 0.0);
}

namespace
{
/// Sweep @p b's frames appended to sweep @p a's as a second sweep (the same frame size and mask).
TrainingData TwoSweeps(const TrainingData& a, const TrainingData& b)
{
  TrainingData d = a;
  d.Sweeps.assign(a.Count(), 0);
  d.Frames.insert(d.Frames.end(), b.Frames.begin(), b.Frames.end());
  d.Poses.insert(d.Poses.end(), b.Poses.begin(), b.Poses.end());
  d.Sweeps.insert(d.Sweeps.end(), b.Count(), 1);
  for (int f : b.TrainFrames)
  {
    d.TrainFrames.push_back(a.Count() + f);
  }
  return d;
}
}

// The rule on speckle sweeps of known beam and spacing: frames 0.2 mm apart under a 0.6 mm beam correlate as
// exp(-d^2 / (4 sigma_eff^2)) (about 0.96 at their training spacing) and are refined; frames 1.5 mm apart under a
// 0.3 mm beam share no speckle (exp(-6) at 1.5 mm) and are trusted. Two such sweeps together are decided sweep by
// sweep.
TEST(PoseRefinementChoice, SweepsAreRefinedWhereNeighbouringFramesCorrelate)
{
  const GaussianField truth = SpeckleField(12000, 10.0, 7);
  std::vector<int> heldOut;
  const TrainingData dense = Sweep(truth, 0.6, 0.2, 30, heldOut);
  const TrainingData sparse = Sweep(truth, 0.3, 1.5, 6, heldOut);
  struct Case
  {
    const TrainingData* Data;
    double Sigma;
    bool Refined;
  };
  for (const Case c : { Case{ &dense, 0.6, true }, Case{ &sparse, 0.3, false } })
  {
    const PoseRefinementChoice choice = ChoosePoseRefinement(*c.Data);
    ASSERT_EQ(choice.Sweeps.size(), 1u);
    const double spacing = choice.Spacing[0];
    const double sigma2 = c.Sigma * c.Sigma + 0.05 * 0.05;
    const double expected = std::exp(-spacing * spacing / (4 * sigma2));
    std::printf("beam %.2f mm, training frames %.3f mm apart: correlation %.3f (exp(-d^2 / 4 sigma^2) %.3f): %s\n",
      c.Sigma, spacing, choice.Correlation[0], expected, choice.Reason.c_str());
    EXPECT_NEAR(choice.Correlation[0], expected, 0.1);
    EXPECT_EQ(choice.Sweeps[0] != 0, c.Refined) << choice.Reason;
    EXPECT_EQ(choice.Any(), c.Refined);
  }
  const PoseRefinementChoice both = ChoosePoseRefinement(TwoSweeps(dense, sparse));
  ASSERT_EQ(both.Sweeps.size(), 2u);
  EXPECT_TRUE(both.Sweeps[0] != 0 && both.Sweeps[1] == 0) << both.Reason;
  EXPECT_NE(both.Reason.find("sweep 0 refined"), std::string::npos) << both.Reason;
  EXPECT_NE(both.Reason.find("sweep 1 trusted"), std::string::npos) << both.Reason;
  // A sweep that cannot be measured (one training frame) is trusted, and says why.
  TrainingData single = dense;
  single.TrainFrames = { 0 };
  const PoseRefinementChoice none = ChoosePoseRefinement(single);
  EXPECT_FALSE(none.Any());
  EXPECT_NE(none.Reason.find("cannot be measured"), std::string::npos) << none.Reason;
}

// The trainer's default (Auto) on the two sweeps: the dense sweep's training frames are refined, the sparse
// sweep's keep their tracked poses exactly, and the settings say so; Off and On override the rule.
TEST(PoseRefinementChoice, TheTrainerRefinesTheSweepsTheRuleChooses)
{
  const GaussianField truth = SpeckleField(12000, 10.0, 7);
  std::vector<int> heldOut;
  const TrainingData data = TwoSweeps(Sweep(truth, 0.6, 0.2, 30, heldOut), Sweep(truth, 0.3, 1.5, 6, heldOut));
  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.Seeding.PixelGridFit = false;
  s.Seeding.InitialGaussians = 2000;
  s.Iterations = 100;
  s.Poses.TrialSteps = 0; // the rule alone (its trial on held-out frames: the next test)
  ASSERT_EQ(s.Poses.RefinePoses, PoseRefinement::Auto);
  Trainer trainer(data, s);
  EXPECT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::On);
  EXPECT_TRUE(trainer.GetPoseRefiner().IsSweepRefined(0));
  EXPECT_FALSE(trainer.GetPoseRefiner().IsSweepRefined(1));
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const TrainerReport& report = trainer.GetReport();
  const std::string said = synthetic::SettingLine(report, "RefinePoses");
  EXPECT_TRUE(said.rfind("RefinePoses = on", 0) == 0 && said.find("sweep 1 trusted") != std::string::npos) << said;
  int moved = 0;
  for (const TrainerReport::PoseCorrection& p : report.PoseCorrections)
  {
    EXPECT_EQ(data.SweepOf(p.Frame), 0) << "frame " << p.Frame << " of the trusted sweep was refined";
    moved += std::any_of(p.Xi.begin(), p.Xi.end(), [](double v) { return v != 0; }) ? 1 : 0;
  }
  EXPECT_GT(moved, 0);
  for (int f = 0; f < data.Count(); ++f)
  {
    if (data.SweepOf(f) == 1)
    {
      EXPECT_EQ(trainer.GetData().Poses[f], data.Poses[f]) << "frame " << f;
    }
  }
  for (const PoseRefinement given : { PoseRefinement::Off, PoseRefinement::On })
  {
    s.Poses.RefinePoses = given;
    Trainer fixed(data, s);
    EXPECT_EQ(fixed.GetSettings().Poses.RefinePoses, given);
    EXPECT_EQ(fixed.GetPoseRefiner().IsSweepRefined(1), given == PoseRefinement::On);
  }
}

namespace
{
/// The pose trials' sweep (80 frames of a speckle field 0.2 mm apart, sigma_E 0.6 mm: the rule refines it) and
/// settings (3000 Harris seeds, no pixel grid; the refinement from 10 % of @p iterations, @p trialSteps each way).
TrainerSettings TrialSettings(int iterations, int trialSteps)
{
  TrainerSettings s;
  s.ElevationSigma = 0.6;
  s.Seeding.PixelGridFit = false;
  s.Seeding.InitialGaussians = 3000;
  s.Iterations = iterations;
  s.Poses.Start = 0.1; // the trial needs 4 x TrialSteps steps after the start
  s.Poses.TrialSteps = trialSteps;
  return s;
}

TrainingData TrialSweep()
{
  std::vector<int> heldOut;
  return Sweep(SpeckleField(12000, 20.0, 7), 0.6, 0.2, 80, heldOut);
}
}

// A run that stops in the trial's refined branch (here an abort 40 steps into it; on a short time budget, the budget)
// keeps the trusted branch, whose TrialSteps steps it would otherwise discard, and says so; the poses stay tracked.
TEST(PoseRefinementChoice, ARunStoppedInTheRefinedBranchKeepsTheTrustedBranchsSteps)
{
  const TrainerSettings s = TrialSettings(1000, 100); // the trial from step 100
  Trainer trainer(TrialSweep(), s);
  ASSERT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::On) << "the rule refines this sweep";
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  // One abort check per step: 100 before the trial, the one that starts it, 99 in the trusted branch (the branches
  // end just before the densification of step 200: Trainer::PoseTrialSteps), 40 refined.
  int checks = 0;
  ASSERT_TRUE(trainer.Run(
    nullptr, [&]() { return ++checks > 100 + 1 + 99 + 40; }, &error))
    << error;
  EXPECT_EQ(trainer.GetReport().StopReason, "aborted");
  EXPECT_EQ(trainer.GetIteration(), 199) << "the trusted branch's steps, not the refined branch's 139";
  EXPECT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::Off);
  const std::string said = synthetic::SettingLine(trainer.GetReport(), "RefinePoses");
  EXPECT_NE(said.find("RefinePoses = off (untested: the run stopped during the trial, 40 of its 99 steps with "
                      "refinement; the 99 on the tracked poses kept"),
    std::string::npos)
    << said;
  EXPECT_TRUE(trainer.GetReport().PoseCorrections.empty());
}

// Where the schedule leaves no room for the trial, Auto keeps the simplest candidate, the tracked poses, untested:
// without a time budget fewer than 4 x TrialSteps steps after the refinement's start (judged before any frame is held
// out), under one fewer than 10 x the branch's steps (its discarded branch would be lost to the run). The same sweep
// and settings without the budget run the trial (the next test). The line says why and what the rule would do; no
// pose moves.
TEST(PoseRefinementChoice, ATrialWithoutRoomKeepsTheTrackedPosesUntested)
{
  const TrainingData data = TrialSweep();
  TrainerSettings shortSchedule = TrialSettings(300, 100); // 270 steps after the start
  TrainerSettings budget = TrialSettings(2000, 150);       // the start at step 800, 1200 steps after it
  budget.Poses.Start = 0.4;
  budget.TimeBudget = 1e6; // seconds: the iterations bound the steps left
  for (const TrainerSettings* s : { &shortSchedule, &budget })
  {
    Trainer trainer(data, *s);
    ASSERT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::On) << "the rule refines this sweep";
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    int checks = 0; // the decision comes at step 30 or 400; 20 steps after it are enough
    ASSERT_TRUE(trainer.Run(
      nullptr, [&]() { return ++checks > (s == &budget ? 420 : 50); }, &error))
      << error;
    const std::string said = synthetic::SettingLine(trainer.GetReport(), "RefinePoses");
    const std::string why = s == &budget
      ? "the budget leaves about 1200 steps after the trial's start, fewer than 10 x 150"
      : "the schedule leaves 270 steps after the trial's start, fewer than 4 x 100";
    EXPECT_EQ(
      said.rfind("RefinePoses = off (untested: " + why + "; the tracked poses kept; the rule alone: on, ", 0), 0u)
      << said;
    EXPECT_NE(said.find("the sweep refined"), std::string::npos) << said;
    EXPECT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::Off);
    EXPECT_TRUE(trainer.GetReport().PoseCorrections.empty());
    EXPECT_EQ(trainer.GetData().Poses, data.Poses);
    EXPECT_GT(trainer.GetIteration(), s == &budget ? 400 : 30) << "the run went on past the decision";
    // The short schedule is judged before any frame is held out for the trial; under the budget the frames held out
    // for it join the fit at the decision: before the trial's start (800), at the first step the recent rate is
    // known (the end of the second densification interval, 400).
    const std::string validation = synthetic::SettingLine(trainer.GetReport(), "Validation");
    if (s == &budget)
    {
      EXPECT_NE(validation.find("; in the fit from step 400 (the trial made no choice)"), std::string::npos)
        << validation;
    }
    else
    {
      EXPECT_EQ(validation.find("until the pose-refinement trial ends"), std::string::npos) << validation;
    }
  }
}

// Where the trial cannot run and the tracked path jitters (its training poses moved by 0.5 degrees and 0.5 mm each at
// random: the path's rule reads over 0.35 mm from frame to frame), refinement goes on untested from the path's start,
// the first step (PoseRefiner::RefineUntested): the poses move towards the true ones. The same schedule on the straight
// path keeps the tracked poses (the test above).
TEST(PoseRefinementChoice, UntestedTheTrackedPathDecides)
{
  const TrainingData exact = TrialSweep();
  TrainerSettings s = TrialSettings(300, 100);
  s.Poses.Start = -1; // chosen: the trial at 40 %, 180 steps after it, fewer than 4 x 100
  const TrainingData perturbed = PerturbedPoses(exact, exact.TrainFrames, 0.5, 0.5, 21, W, H);
  Trainer trainer(perturbed, s);
  ASSERT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::On) << "the rule refines this sweep";
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  EXPECT_DOUBLE_EQ(trainer.GetSettings().Poses.Start, 0.0) << "decided before the first step";
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const std::string said = synthetic::SettingLine(trainer.GetReport(), "RefinePoses");
  EXPECT_EQ(
    said.rfind("RefinePoses = on (untested: the schedule leaves 180 steps after the trial's start, fewer than 4 "
               "x 100; refined without it from 0 % of the schedule, as the tracked path says: the tracked path "
               "jitters from frame to frame by ",
      0),
    0u)
    << said;
  EXPECT_NE(said.find("(over 0.35 mm); the rule alone: from 0 % of the schedule, chosen: the tracked path jitters"),
    std::string::npos)
    << said;
  EXPECT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::On);
  EXPECT_EQ(trainer.GetReport().PoseCorrections.size(), exact.TrainFrames.size());
  EXPECT_LT(CornerError(trainer.GetData(), exact, exact.TrainFrames, W, H),
    CornerError(perturbed, exact, exact.TrainFrames, W, H));
  // No frame was held out for a trial: the validation line holds none out for it.
  const std::string validation = synthetic::SettingLine(trainer.GetReport(), "Validation");
  EXPECT_EQ(validation.find("until the pose-refinement trial ends"), std::string::npos) << validation;
}

// Where the start is chosen and the tracked path jitters, the corrections move from the path's start (0) and the
// trial at 40 % of the schedule measures whether to keep them (PoseRefiner::GetTrialFraction): its trusted branch
// takes the tracked poses from there. A trial that delays them until 40 % cost the jittered liver 0.47 dB.
TEST(PoseRefinementChoice, WhereThePathJittersTheCorrectionsMoveBeforeTheTrial)
{
  const TrainingData exact = TrialSweep();
  TrainerSettings s = TrialSettings(1000, 100);
  s.Poses.Start = -1;
  const TrainingData perturbed = PerturbedPoses(exact, exact.TrainFrames, 0.5, 0.5, 21, W, H);
  Trainer trainer(perturbed, s);
  EXPECT_DOUBLE_EQ(trainer.GetSettings().Poses.Start, 0.0);
  EXPECT_DOUBLE_EQ(trainer.GetPoseRefiner().GetTrialFraction(), PoseRefiner::TrialStart);
  const std::string rule = synthetic::SettingLine(trainer.GetReport(), "RefinePoses");
  EXPECT_EQ(rule.rfind("RefinePoses = on (from 0 % of the schedule, chosen: the tracked path jitters", 0), 0u) << rule;
  EXPECT_NE(rule.find("; the pose trial at 40 % of the schedule (refined on, or the tracked poses from there"),
    std::string::npos)
    << rule;
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Train(
    nullptr, [&]() { return trainer.GetIteration() >= 300; }, &error))
    << error;
  EXPECT_LT(CornerError(trainer.GetData(), exact, exact.TrainFrames, W, H),
    CornerError(perturbed, exact, exact.TrainFrames, W, H))
    << "the corrections moved before the trial";
  // A checkpoint written here resumes with the trial still to come, though its corrections moved.
  const std::string checkpoint = std::string(BIGUS_TEST_OUTPUT) + "/jittered_path.ckpt";
  ASSERT_TRUE(trainer.SaveCheckpoint(checkpoint, &error)) << error;
  Trainer resumed(perturbed, s);
  ASSERT_TRUE(resumed.Initialize(&error)) << error;
  ASSERT_TRUE(resumed.LoadCheckpoint(checkpoint, &error)) << error;
  EXPECT_TRUE(resumed.GetPoseRefiner().IsTrialPending());
  for (Trainer* t : { &trainer, &resumed })
  {
    ASSERT_TRUE(t->Train(nullptr, nullptr, &error)) << error;
    const std::string said = synthetic::SettingLine(t->GetReport(), "RefinePoses");
    EXPECT_NE(said.find(" steps each way from step 400 "), std::string::npos) << said;
    EXPECT_EQ(t->GetSettings().Poses.RefinePoses, PoseRefinement::On) << said;
    EXPECT_LT(CornerError(t->GetData(), exact, exact.TrainFrames, W, H),
      CornerError(perturbed, exact, exact.TrainFrames, W, H));
  }
}

// A stop that waits for the field to settle (Trainer::IsSettled; bigus benchmark's marks) lets the trial run both
// branches and choose, where a plain abort inside it ends the trial untested (the test above).
TEST(PoseRefinementChoice, AStopThatWaitsForTheFieldToSettleLetsTheTrialChoose)
{
  Trainer trainer(TrialSweep(), TrialSettings(1000, 100)); // the trial from step 100
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  int checks = 0;
  ASSERT_TRUE(trainer.Train(
    nullptr, [&]() { return ++checks > 100 + 1 + 50 && trainer.IsSettled(); }, &error))
    << error;
  EXPECT_EQ(trainer.GetIteration(), 199) << "the branch kept: 99 steps from step 100";
  const std::string said = synthetic::SettingLine(trainer.GetReport(), "RefinePoses");
  EXPECT_NE(said.find("measured: 99 steps each way from step 100"), std::string::npos) << said;
  // The trial's held-out frames joined the fit at its end, not at the densification window's close, and the line
  // says so.
  const std::string validation = synthetic::SettingLine(trainer.GetReport(), "Validation");
  EXPECT_NE(validation.find("out of the fit until the pose-refinement trial ends, then in it"), std::string::npos)
    << validation;
  EXPECT_NE(validation.find("; in the fit from step 199"), std::string::npos) << validation;
  EXPECT_EQ(validation.find("densification window"), std::string::npos) << validation;
  EXPECT_FALSE(trainer.GetReport().ValidationHeldOut);
}

// Where the refinement's start is chosen (not given), a pending trial starts at 40 % of the schedule at the earliest
// (PoseRefiner::TrialStart): this sweep's straight path would start the corrections at 20 % (step 200), but a trial
// scored there cannot show refinement's gain. Without a trial (TrialSteps 0) the path's rule stands.
TEST(PoseRefinementChoice, ATrialStartsOnceTheFieldHasFormed)
{
  TrainerSettings s = TrialSettings(1000, 100);
  s.Poses.Start = -1;
  Trainer trainer(TrialSweep(), s);
  EXPECT_DOUBLE_EQ(trainer.GetSettings().Poses.Start, PoseRefiner::TrialStart);
  const std::string rule = synthetic::SettingLine(trainer.GetReport(), "RefinePoses");
  EXPECT_EQ(rule.rfind("RefinePoses = on (from 40 % of the schedule, chosen: the pose trial's start, 40 % (", 0), 0u)
    << rule;
  EXPECT_NE(rule.find("the path's jitter alone: 20 %, the tracked path jitters"), std::string::npos) << rule;
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  int checks = 0;
  ASSERT_TRUE(trainer.Train(
    nullptr, [&]() { return ++checks > 400 + 1 + 50 && trainer.IsSettled(); }, &error))
    << error;
  const std::string said = synthetic::SettingLine(trainer.GetReport(), "RefinePoses");
  EXPECT_NE(said.find(" steps each way from step 400 "), std::string::npos) << said;
  s.Poses.TrialSteps = 0;
  Trainer alone(TrialSweep(), s);
  EXPECT_DOUBLE_EQ(alone.GetSettings().Poses.Start, 0.2);
}

// Auto where the rule would refine (speckle correlates): the choice is measured, TrialSteps steps each way from the
// refinement's start, on held-out frames at their tracked poses (issue 54's tests). Exact poses: refinement ends off
// (or moves no pose by more than 0.02 mm). Training poses moved by 0.5 degrees and 0.5 mm each at random (the
// held-out frames' tracked poses exact): refinement stays on.
TEST(PoseRefinementChoice, AutoRefinementIsMeasuredOnHeldOutFramesAtTheirTrackedPoses)
{
  const TrainingData exact = TrialSweep();
  const TrainerSettings s = TrialSettings(1500, 300);
  // The frames the trainer will hold out for the trial (every 8th training frame), so that only the others err.
  TrainingData copy = exact;
  HeldOutChoiceSettings held = s.HeldOut;
  held.HoldOutValidationFrames = ValidationHoldOut::On;
  bool heldOutOk = false;
  std::string line;
  const std::vector<int> trial = ChooseValidationFrames(copy, held, {}, heldOutOk, line);
  ASSERT_TRUE(heldOutOk) << line;
  std::vector<int> fitted;
  for (int f : exact.TrainFrames)
  {
    if (!std::binary_search(trial.begin(), trial.end(), f))
    {
      fitted.push_back(f);
    }
  }
  const TrainingData perturbed = PerturbedPoses(exact, fitted, 0.5, 0.5, 21, W, H);
  for (const bool moved : { false, true })
  {
    Trainer trainer(moved ? perturbed : exact, s);
    ASSERT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::On) << "the rule refines this sweep";
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    const std::string said = synthetic::SettingLine(trainer.GetReport(), "RefinePoses");
    std::printf("%s poses: %s\n", moved ? "perturbed" : "exact", said.c_str());
    // 249 steps from step 150: the branches end at step 399, before the densification of step 400.
    EXPECT_NE(said.find("measured: 249 steps each way from step 150"), std::string::npos) << said;
    double largest = 0;
    for (const TrainerReport::PoseCorrection& p : trainer.GetReport().PoseCorrections)
    {
      const double r = std::sqrt(p.Xi[0] * p.Xi[0] + p.Xi[1] * p.Xi[1] + p.Xi[2] * p.Xi[2]);
      const double t = std::sqrt(p.Xi[3] * p.Xi[3] + p.Xi[4] * p.Xi[4] + p.Xi[5] * p.Xi[5]);
      largest = std::max(largest, t + r * 0.5 * W * Pixel); // the corners' displacement, at most
    }
    if (moved)
    {
      EXPECT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::On) << said;
      EXPECT_LT(CornerError(trainer.GetData(), exact, fitted, W, H), CornerError(perturbed, exact, fitted, W, H));
    }
    else
    {
      EXPECT_TRUE(trainer.GetSettings().Poses.RefinePoses == PoseRefinement::Off || largest < 0.02)
        << said << "; largest correction " << largest << " mm";
    }
    // The frames held out for the trial joined the fit afterwards.
    for (int f : trial)
    {
      EXPECT_TRUE(std::binary_search(trainer.GetData().TrainFrames.begin(), trainer.GetData().TrainFrames.end(), f));
    }
  }
}
