// The trainer: self-consistency on a synthetic sweep rendered from a known field, determinism,
// checkpoint/resume, ablation switches, and a short run on the real spine-phantom sweep.
#include "bigusTestUtilities.h"
#include "bigusBackend.h"
#include "bigusElevationSigma.h"
#include "bigusSliceFrame.h"
#include "bigusRendererTestUtilities.h"
#include "bigusTrainer.h"
#include "bigusThreadReduction.h"
#include "bigusTrainingTestUtilities.h"

#include "vtkCallbackCommand.h"
#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkInformation.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkIdList.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkStringArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundSequenceReader.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <random>

using namespace bigus;

namespace
{
constexpr int W = 64, H = 64;
constexpr double Spacing = 0.3;

/// Pose of frame k of a synthetic sweep: elevation steps of 0.2 mm with a slow +-4 degree rock.
std::array<double, 16> SweepPose(int k)
{
  const double tilt = 4.0 * std::sin(0.3 * k) * M_PI / 180.0;
  const double c = std::cos(tilt), s = std::sin(tilt);
  // Columns: u = x axis, v = (0, c, s) rotated about x, origin moving along z.
  return { Spacing, 0, 0, 0.0, 0, c * Spacing, 0, 0.0, 0, s * Spacing, 0, -6.0 + 0.2 * k, 0, 0, 0, 1 };
}

GaussianField KnownField(int n, unsigned seed)
{
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0, 1);
  std::normal_distribution<double> normal(0, 1);
  GaussianField f;
  for (int i = 0; i < n; ++i)
  {
    f.Means.push_back(static_cast<float>(19.2 * u01(rng)));
    f.Means.push_back(static_cast<float>(19.2 * u01(rng)));
    f.Means.push_back(static_cast<float>(-6.5 + 13.0 * u01(rng)));
    for (int k = 0; k < 3; ++k)
    {
      f.LogScales.push_back(static_cast<float>(std::log(0.4 + 0.8 * u01(rng))));
    }
    AppendRandomRotation(f, rng, normal);
    f.Reflectivities.push_back(static_cast<float>(0.25 + 0.2 * normal(rng)));
  }
  return f;
}

/// 60 frames rendered from the known field; frames with k mod 4 == 2 are held out.
TrainingData SyntheticSweep(const GaussianField& truth, double sigmaE, std::vector<int>& heldOut)
{
  std::vector<std::array<double, 16>> poses;
  for (int k = 0; k < 60; ++k)
  {
    poses.push_back(SweepPose(k));
  }
  return RenderedSweep(truth, poses, W, H, sigmaE, heldOut);
}

double HeldOutPsnr(const Trainer& trainer, const std::vector<int>& heldOut)
{
  return PsnrAt(trainer.GetField(), trainer.Options(), trainer.GetData(), heldOut);
}
}

TEST(Trainer, LearnsAKnownFieldAndRendersHeldOutPosesAbove40dB)
{
  const GaussianField truth = KnownField(400, 3);
  std::vector<int> heldOut;
  TrainingData data = SyntheticSweep(truth, 0.5, heldOut);
  ASSERT_EQ(data.TrainFrames.size(), 45u);
  ASSERT_EQ(heldOut.size(), 15u);
  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.InitialGaussians = 3000;
  s.Iterations = 3000;
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  const double before = HeldOutPsnr(trainer, heldOut);
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const double after = HeldOutPsnr(trainer, heldOut);
  const TrainerReport& r = trainer.GetReport();
  std::printf("held-out PSNR %.2f dB -> %.2f dB; %lld Gaussians (%lld pruned at the end), %d steps in %.1f s; "
              "growth: %s\n",
    before, after, static_cast<long long>(r.Gaussians), static_cast<long long>(r.PrunedAtEnd), r.Iterations, r.Seconds,
    r.GrowthStopReason.c_str());
  EXPECT_GE(after, 40.0);
}

namespace
{
TrainerSettings ShortSettings()
{
  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.InitialGaussians = 800;
  s.Iterations = 200;
  s.DensifyStart = 100;
  s.DensifyInterval = 100;
  s.DensifyEnd = 150;
  s.Poses.RefinePoses = PoseRefinement::Off; // exact synthetic poses: the tests of pose refinement switch it on
  return s;
}

bool AllFinite(const GaussianField& f)
{
  for (const std::vector<float>* v : { &f.Means, &f.LogScales, &f.Quaternions, &f.Reflectivities })
  {
    for (float x : *v)
    {
      if (!std::isfinite(x))
      {
        return false;
      }
    }
  }
  return true;
}
}

namespace
{
/// Scattering field S of @p field on 60 parallel frames of W x H pixels, 0.2 mm apart along z (so that
/// the sum of S over them, times the voxel volume, approximates the field's 3D integral).
std::vector<float> RenderSweep(const GaussianField& field, double sigmaE)
{
  auto renderer = CreateCpuRenderer();
  RenderOptions o;
  o.ElevationSigma = sigmaE;
  o.Gamma = 1.0;
  std::vector<float> all, S(W * H);
  for (int k = 0; k < 60; ++k)
  {
    SliceGeometry g;
    const double pose[16] = { Spacing, 0, 0, 0, 0, Spacing, 0, 0, 0, 0, 0, -6.0 + 0.2 * k, 0, 0, 0, 1 };
    std::copy(pose, pose + 16, g.ImageToReference);
    g.Width = W;
    g.Height = H;
    EXPECT_TRUE(renderer->Forward(field.View(), &g, 1, o, S.data(), nullptr, nullptr, nullptr));
    all.insert(all.end(), S.begin(), S.end());
  }
  return all;
}
}

// Densification of one elongated, tilted Gaussian, checked on a rendered parallel sweep: a clone
// renders as its parent did; a split puts two children at +-s/2 along the parent's major axis (found
// here with Rodrigues' formula, not the trainer's quaternion code) whose sweep integral is the one of
// two Gaussians of r / 2 with every scale divided by 1.6 (the sweep sums S over 0.2 mm steps, so it
// approximates the 3D integral r s1 s2 s3 (2 pi)^(3/2), which the beam average keeps).
TEST(Trainer, DensifyingAGaussianClonesOrSplitsItAlongItsMajorAxis)
{
  const double angle = 0.6, c = std::cos(angle), sn = std::sin(angle), k = 1 / std::sqrt(3.0);
  // Rotation by angle about (1, 1, 1) / sqrt(3) applied to the x axis (the largest scale's).
  const double major[3] = { c + k * k * (1 - c), k * k * (1 - c) + k * sn, k * k * (1 - c) - k * sn };
  for (bool large : { true, false })
  {
    GaussianField field;
    field.Means = { 9.6f, 9.6f, 0.0f };
    field.LogScales = { std::log(2.0f), std::log(0.8f), std::log(1.0f) };
    field.Quaternions = { static_cast<float>(std::cos(angle / 2)), static_cast<float>(k * std::sin(angle / 2)),
      static_cast<float>(k * std::sin(angle / 2)), static_cast<float>(k * std::sin(angle / 2)) };
    field.Reflectivities = { 0.8f };
    const std::vector<float> before = RenderSweep(field, 0.5);
    GaussianField densified = field;
    EXPECT_EQ(DensifyGaussian(densified, 0, large ? 1.9 : 2.1), 1) << "the largest scale is 2 mm";
    ASSERT_EQ(densified.Count(), 2);
    const double offset = large ? 1.0 : 0.2;
    for (int q = 0; q < 3; ++q)
    {
      EXPECT_NEAR(densified.Means[q], field.Means[q] + offset * major[q], 1e-5) << "parent, axis " << q;
      EXPECT_NEAR(densified.Means[3 + q], field.Means[q] - offset * major[q], 1e-5) << "child, axis " << q;
    }
    const std::vector<float> after = RenderSweep(densified, 0.5);
    double peak = 0, largest = 0, sumBefore = 0, sumAfter = 0;
    for (std::size_t p = 0; p < before.size(); ++p)
    {
      peak = std::max(peak, std::abs(double(before[p])));
      largest = std::max(largest, std::abs(double(after[p]) - before[p]));
      sumBefore += before[p];
      sumAfter += after[p];
    }
    ASSERT_GT(peak, 0.3) << "the sweep passes through the Gaussian";
    if (large)
    {
      EXPECT_NEAR(sumAfter / sumBefore, 1 / (1.6 * 1.6 * 1.6), 0.01) << "split: two children of r / 2, scales / 1.6";
    }
    else
    {
      EXPECT_LT(largest, 0.01 * peak) << "clone: renders as the parent";
      EXPECT_NEAR(sumAfter, sumBefore, 1e-3 * sumBefore) << "clone: the integral is kept";
    }
  }
}

TEST(Trainer, SameSeedGivesTheSameField)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 5), 0.5, heldOut);
  GaussianField fields[2];
  for (GaussianField& f : fields)
  {
    Trainer trainer(data, ShortSettings());
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    f = trainer.GetField();
  }
  ExpectSameField(fields[0], fields[1]);
  TrainerSettings other = ShortSettings();
  other.Seed = 2;
  Trainer trainer(data, other);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error));
  EXPECT_NE(trainer.GetField().Means, fields[0].Means) << "another seed, other seeds";
}

TEST(Trainer, PerFrameMasksTrainOnEachFramesOwnPixels)
{
  std::vector<int> heldOut;
  TrainingData data = SyntheticSweep(KnownField(200, 5), 0.5, heldOut);
  auto train = [](const TrainingData& d) {
    Trainer trainer(d, ShortSettings());
    std::string error;
    EXPECT_TRUE(trainer.Initialize(&error)) << error;
    EXPECT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    return trainer;
  };
  // The same mask given once per frame is the shared mask.
  TrainingData perFrame = data;
  perFrame.Mask.assign(std::size_t(W) * H * data.Count(), 1);
  ExpectSameField(train(data).GetField(), train(perFrame).GetField());

  // Each training frame loses a different band of rows to saturation (as if an artefact covered it):
  // with the band masked out of that frame only, the held-out poses are rendered better than when the
  // corrupted pixels are trained on.
  TrainingData corrupted = data;
  for (int k : data.TrainFrames)
  {
    const int first = (k * 7) % (H - H / 4);
    for (int row = first; row < first + H / 4; ++row)
    {
      for (int col = 0; col < W; ++col)
      {
        const std::size_t p = std::size_t(row) * W + col;
        corrupted.Frames[std::size_t(W) * H * k + p] = 1.0f;
        perFrame.Mask[std::size_t(W) * H * k + p] = 0;
      }
    }
  }
  perFrame.Frames = corrupted.Frames;
  const double withMask = HeldOutPsnr(train(perFrame), heldOut);
  const double withoutMask = HeldOutPsnr(train(corrupted), heldOut);
  std::printf("held-out PSNR with the artefact bands masked per frame %.2f dB, trained on them %.2f dB\n", withMask,
    withoutMask);
  EXPECT_GT(withMask, withoutMask + 3);
}

TEST(Trainer, ResumingFromACheckpointGivesTheSameField)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 6), 0.5, heldOut);
  std::string error;
  Trainer straight(data, ShortSettings());
  ASSERT_TRUE(straight.Initialize(&error));
  ASSERT_TRUE(straight.Run(nullptr, nullptr, &error)) << error;

  const std::string checkpoint = std::string(BIGUS_TEST_OUTPUT) + "/trainer.ckpt";
  TrainerSettings s = ShortSettings();
  s.CheckpointFile = checkpoint;
  s.CheckpointInterval = 110; // after the first densification, so its state is in the file too
  Trainer first(data, s);
  ASSERT_TRUE(first.Initialize(&error));
  ASSERT_TRUE(first.Run(nullptr, [&]() { return first.GetIteration() >= 110; }, &error)) << error;
  EXPECT_EQ(first.GetReport().StopReason, "aborted");

  Trainer second(data, ShortSettings());
  ASSERT_TRUE(second.Initialize(&error));
  ASSERT_TRUE(second.LoadCheckpoint(checkpoint, &error)) << error;
  EXPECT_EQ(second.GetIteration(), 110);
  ASSERT_TRUE(second.Run(nullptr, nullptr, &error)) << error;
  ExpectSameField(straight.GetField(), second.GetField());

  std::ofstream(checkpoint + ".bad") << "not a checkpoint";
  EXPECT_FALSE(second.LoadCheckpoint(checkpoint + ".bad", &error));
  EXPECT_NE(error.find("bad magic"), std::string::npos) << error;
}

TEST(Trainer, AResumedRunGoesOnWithThePoseCorrectionsOfItsCheckpoint)
{
  // With pose refinement, the corrections and their Adam moments are part of the state: a run stopped at step
  // 110 and resumed ends with the field, the corrections and the corrected poses of the run that went straight
  // through. A checkpoint without corrections is refused by a run that refines poses, and the other way round.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 6), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.Poses.RefinePoses = PoseRefinement::On;
  s.Poses.Start = 0.25; // the corrections move from step 50, well before the checkpoint
  std::string error;
  Trainer straight(data, s);
  ASSERT_TRUE(straight.Initialize(&error));
  ASSERT_TRUE(straight.Run(nullptr, nullptr, &error)) << error;

  const std::string checkpoint = std::string(BIGUS_TEST_OUTPUT) + "/poses.ckpt";
  Trainer first(data, s);
  ASSERT_TRUE(first.Initialize(&error));
  ASSERT_TRUE(first.Train(nullptr, [&]() { return first.GetIteration() >= 110; }, &error)) << error;
  ASSERT_TRUE(first.SaveCheckpoint(checkpoint, &error)) << error;
  double moved = 0;
  for (const auto& xi : first.GetState().PoseCorrections)
  {
    for (double v : xi)
    {
      moved = std::max(moved, std::abs(v));
    }
  }
  EXPECT_GT(moved, 0) << "the corrections moved before the checkpoint";

  Trainer second(data, s);
  ASSERT_TRUE(second.Initialize(&error));
  ASSERT_TRUE(second.LoadCheckpoint(checkpoint, &error)) << error;
  EXPECT_EQ(second.GetData().Poses, first.GetData().Poses) << "the corrected poses are restored";
  ASSERT_TRUE(second.Run(nullptr, nullptr, &error)) << error;
  ExpectSameField(straight.GetField(), second.GetField());
  const auto& a = straight.GetReport().PoseCorrections;
  const auto& b = second.GetReport().PoseCorrections;
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k)
  {
    EXPECT_EQ(a[k].Frame, b[k].Frame);
    for (int c = 0; c < 6; ++c)
    {
      EXPECT_DOUBLE_EQ(a[k].Xi[c], b[k].Xi[c]) << "frame " << a[k].Frame << " component " << c;
    }
  }
  EXPECT_EQ(straight.GetData().Poses, second.GetData().Poses);

  TrainerSettings trusted = ShortSettings();
  Trainer other(data, trusted);
  ASSERT_TRUE(other.Initialize(&error));
  EXPECT_FALSE(other.LoadCheckpoint(checkpoint, &error));
  EXPECT_NE(error.find("pose corrections of"), std::string::npos) << error;
}

TEST(Trainer, AResumedRunCountsTheSecondsBeforeItsCheckpointTowardsItsTimeBudget)
{
  // The budget is the run's schedule: a run stopped at 70 % of it and resumed trains for the rest, with
  // the densification window (60 % of the schedule) already closed, instead of a fresh budget.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(150, 4), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.Iterations = 0;
  s.TimeBudget = 2.0;
  s.DensifyEnd = -1;
  const std::string checkpoint = std::string(BIGUS_TEST_OUTPUT) + "/budget.ckpt";
  std::string error;
  Trainer first(data, s);
  ASSERT_TRUE(first.Initialize(&error)) << error;
  const auto start = std::chrono::steady_clock::now();
  auto since = [](std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
  };
  ASSERT_TRUE(first.Train(nullptr, [&]() { return since(start) >= 0.7 * s.TimeBudget + 0.05; }, &error)) << error;
  ASSERT_TRUE(first.SaveCheckpoint(checkpoint, &error)) << error;
  const double saved = first.GetState().TrainingSeconds;
  EXPECT_GE(saved, 0.7 * s.TimeBudget);
  EXPECT_LT(saved, s.TimeBudget);

  Trainer second(data, s);
  ASSERT_TRUE(second.Initialize(&error)) << error;
  ASSERT_TRUE(second.LoadCheckpoint(checkpoint, &error)) << error;
  EXPECT_EQ(second.GetState().TrainingSeconds, saved);
  const std::int64_t loaded = second.GetField().Count();
  const int iteration = second.GetIteration();
  const auto resumed = std::chrono::steady_clock::now();
  ASSERT_TRUE(second.Train(nullptr, nullptr, &error)) << error;
  EXPECT_EQ(second.GetReport().StopReason, "time budget");
  EXPECT_GE(second.GetState().TrainingSeconds, s.TimeBudget);
  EXPECT_LT(since(resumed), s.TimeBudget - 0.25) << "the resumed run took a fresh budget";
  EXPECT_GT(second.GetIteration(), iteration);
  EXPECT_EQ(second.GetField().Count(), loaded) << "densified after the window had closed";

  // Checkpoints of the previous formats still load: version 4 (no shared pose correction: the file ends with
  // it, 3 x 7 doubles and a step count, then the best field's corrections, here a count 0 and 7 doubles),
  // version 3 (no pose corrections; this run has none, so its file then
  // ends with their count 0) with the training seconds, version 2 (no training seconds either) with none.
  std::ifstream in(checkpoint, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(bytes.compare(0, 8, "BIGUSCK5"), 0);
  bytes = bytes.substr(
    0, bytes.size() - 28 * sizeof(double) - sizeof(std::int32_t) - sizeof(std::int64_t));
  bytes[7] = '4';
  std::ofstream(checkpoint + ".v4", std::ios::binary) << bytes;
  TrainingState old;
  double gamma = 0;
  ASSERT_TRUE(old.Load(checkpoint + ".v4", gamma, &error)) << error;
  EXPECT_EQ(old.TrainingSeconds, saved);
  EXPECT_EQ(old.SharedPoseSteps, 0);
  bytes = bytes.substr(0, bytes.size() - sizeof(std::int64_t));
  bytes[7] = '3';
  std::ofstream(checkpoint + ".v3", std::ios::binary) << bytes;
  ASSERT_TRUE(old.Load(checkpoint + ".v3", gamma, &error)) << error;
  EXPECT_EQ(old.TrainingSeconds, saved);
  EXPECT_TRUE(old.PoseCorrections.empty());
  bytes[7] = '2';
  std::ofstream(checkpoint + ".v2", std::ios::binary) << bytes.substr(0, bytes.size() - sizeof(double));
  ASSERT_TRUE(old.Load(checkpoint + ".v2", gamma, &error)) << error;
  EXPECT_EQ(old.TrainingSeconds, 0);
  EXPECT_EQ(old.Iteration, iteration);
  std::remove(checkpoint.c_str());
  std::remove((checkpoint + ".v2").c_str());
  std::remove((checkpoint + ".v4").c_str());
}

TEST(Trainer, CheckpointHoldsTheWholeTrainingState)
{
  // Save and Load are inverse: every member of the state survives the file, bit for bit, and a
  // truncated file is refused without touching the state it was read into.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  TrainerSettings settings = ShortSettings();
  settings.Poses.RefineImageToProbe = true; // the shared pose correction moves from the start
  settings.Poses.Start = 0;
  Trainer trainer(data, settings);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Train(nullptr, [&]() { return trainer.GetIteration() >= 150; }, &error)) << error;
  ASSERT_GT(trainer.GetState().SharedPoseSteps, 0);
  const std::string file = std::string(BIGUS_TEST_OUTPUT) + "/state.ckpt";
  ASSERT_TRUE(trainer.SaveCheckpoint(file, &error)) << error;
  const TrainingState& saved = trainer.GetState();
  ASSERT_GT(std::count_if(saved.Gaussians.SeenCount.begin(), saved.Gaussians.SeenCount.end(), [](int c) { return c > 0; }), 0)
    << "the accumulators must hold something for the test to mean anything";

  TrainingState loaded;
  double gamma = 0;
  ASSERT_TRUE(loaded.Load(file, gamma, &error)) << error;
  EXPECT_EQ(gamma, trainer.GetGamma());
  EXPECT_EQ(loaded.Iteration, saved.Iteration);
  EXPECT_EQ(loaded.LearningRateScale, saved.LearningRateScale);
  EXPECT_EQ(loaded.Growing, saved.Growing);
  EXPECT_EQ(loaded.BestValidationLoss, saved.BestValidationLoss);
  EXPECT_EQ(loaded.StalledGrowthSteps, saved.StalledGrowthSteps);
  EXPECT_EQ(loaded.RolledBackSteps, saved.RolledBackSteps);
  EXPECT_EQ(loaded.LossHistory, saved.LossHistory);
  EXPECT_TRUE(loaded.Random == saved.Random);
  EXPECT_EQ(loaded.TrainingSeconds, saved.TrainingSeconds);
  EXPECT_GT(saved.TrainingSeconds, 0);
  for (const auto& pair : { std::make_pair(&loaded.Gaussians.Field, &saved.Gaussians.Field),
         std::make_pair(&loaded.Gaussians.FirstMoment, &saved.Gaussians.FirstMoment),
         std::make_pair(&loaded.Gaussians.SecondMoment, &saved.Gaussians.SecondMoment) })
  {
    ExpectSameField(*pair.first, *pair.second);
  }
  EXPECT_EQ(loaded.Gaussians.Attribution, saved.Gaussians.Attribution);
  EXPECT_EQ(loaded.Gaussians.SeenCount, saved.Gaussians.SeenCount);
  EXPECT_EQ(loaded.SharedPoseCorrection, saved.SharedPoseCorrection);
  EXPECT_EQ(loaded.SharedPoseFirstMoment, saved.SharedPoseFirstMoment);
  EXPECT_EQ(loaded.SharedPoseSecondMoment, saved.SharedPoseSecondMoment);
  EXPECT_EQ(loaded.SharedPoseSteps, saved.SharedPoseSteps);
  EXPECT_EQ(loaded.BestPoseCorrections, saved.BestPoseCorrections);
  EXPECT_EQ(loaded.BestSharedPoseCorrection, saved.BestSharedPoseCorrection);
  // A run with the same settings resumes at the same poses; one that does not refine the shared correction
  // refuses the checkpoint.
  Trainer resumed(data, settings);
  ASSERT_TRUE(resumed.Initialize(&error)) << error;
  ASSERT_TRUE(resumed.LoadCheckpoint(file, &error)) << error;
  EXPECT_EQ(resumed.GetData().Poses, trainer.GetData().Poses);
  EXPECT_NE(resumed.GetData().Poses, data.Poses) << "the shared correction moved the poses";
  Trainer without(data, ShortSettings());
  ASSERT_TRUE(without.Initialize(&error)) << error;
  EXPECT_FALSE(without.LoadCheckpoint(file, &error));
  EXPECT_NE(error.find("an ImageToProbe correction that this run does not refine"), std::string::npos) << error;

  // Truncated: refused, and the state read into stays as it was.
  std::ifstream in(file, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(file + ".cut", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  const int before = loaded.Iteration;
  EXPECT_FALSE(loaded.Load(file + ".cut", gamma, &error));
  EXPECT_NE(error.find("truncated"), std::string::npos) << error;
  EXPECT_EQ(loaded.Iteration, before);
  std::remove(file.c_str());
  std::remove((file + ".cut").c_str());
}

TEST(Trainer, CompactingTheStateKeepsEachGaussiansMomentsAndScoresWithIt)
{
  // Pruning (densification's and the final one) compacts the field, its Adam moments and the EA-D
  // accumulators together: tag every entry with its Gaussian's index and check the survivors.
  OptimizerState state;
  const int n = 10;
  state.Field.Resize(n);
  state.ResizeToField();
  for (int i = 0; i < n; ++i)
  {
    state.Field.Means[3 * i] = static_cast<float>(i);
    state.FirstMoment.Reflectivities[i] = static_cast<float>(10 * i);
    state.SecondMoment.Quaternions[4 * i + 3] = static_cast<float>(100 * i);
    state.Attribution[i] = static_cast<float>(1000 * i);
    state.SeenCount[i] = 7 * i;
  }
  std::vector<unsigned char> keep(n, 0);
  keep[1] = keep[4] = keep[9] = 1;
  state.Compact(keep);
  ASSERT_EQ(state.Count(), 3);
  const int kept[3] = { 1, 4, 9 };
  for (int j = 0; j < 3; ++j)
  {
    EXPECT_EQ(state.Field.Means[3 * j], kept[j]);
    EXPECT_EQ(state.FirstMoment.Reflectivities[j], 10 * kept[j]);
    EXPECT_EQ(state.SecondMoment.Quaternions[4 * j + 3], 100 * kept[j]);
    EXPECT_EQ(state.Attribution[j], 1000 * kept[j]);
    EXPECT_EQ(state.SeenCount[j], 7 * kept[j]);
  }
}

TEST(Trainer, TrainingInStagesEqualsOneRunAndOnlyFinishPrunes)
{
  // Train() stops at a condition without pruning, so a run trained in stages (the benchmark's time
  // marks) is the run trained at once, and Finish() alone removes Gaussians.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 6), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.FinalPruneTolerance = 0.02; // prunes a good share of this small field
  std::string error;
  Trainer once(data, s);
  ASSERT_TRUE(once.Initialize(&error)) << error;
  ASSERT_TRUE(once.Train(nullptr, nullptr, &error)) << error;
  Trainer staged(data, s);
  ASSERT_TRUE(staged.Initialize(&error)) << error;
  for (int stop : { 70, 150, 230 })
  {
    ASSERT_TRUE(staged.Train(nullptr, [&]() { return staged.GetIteration() >= stop; }, &error)) << error;
    EXPECT_EQ(staged.GetReport().PrunedAtEnd, 0);
  }
  ASSERT_TRUE(staged.Train(nullptr, nullptr, &error)) << error;
  ExpectSameField(once.GetField(), staged.GetField());
  const std::int64_t before = staged.GetField().Count();
  ASSERT_TRUE(staged.Finish(&error)) << error;
  EXPECT_GT(staged.GetReport().PrunedAtEnd, 0);
  const TrainerReport& r = staged.GetReport();
  EXPECT_EQ(staged.GetField().Count(), before - r.PrunedAtEnd + r.GapFilling.Added - r.Merge.Merged);
}

TEST(Trainer, ATimeBudgetAloneIsTheSchedule)
{
  // No step count chosen for another sweep: with Iterations 0 the run trains until the budget (before,
  // it took no step at all; the CLI stopped at its default 3000 steps whatever the budget).
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(150, 4), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.Iterations = 0;
  s.TimeBudget = 1.5;
  s.DensifyEnd = -1; // 60 % of the schedule
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const TrainerReport& r = trainer.GetReport();
  EXPECT_EQ(r.StopReason, "time budget");
  EXPECT_GE(r.Seconds, 1.5);
  EXPECT_GT(r.Iterations, 100);
}

TEST(Trainer, GrowthStopsAfterPatienceIntervalsWithoutImprovementAndTheHistoryRecordsIt)
{
  // A margin no interval can meet (99.9 %): the first densification sets the best validation loss and
  // each later one counts as stalled, so growth stops at DensifyStart + GrowthPatience intervals.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(150, 4), 0.5, heldOut);
  for (int patience : { 2, 4 })
  {
    TrainerSettings s = ShortSettings();
    s.Iterations = 800;
    s.DensifyEnd = 800;
    s.GrowthMargin = 0.999;
    s.GrowthPatience = patience;
    Trainer trainer(data, s);
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    const TrainerReport& r = trainer.GetReport();
    const int stop = s.DensifyStart + patience * s.DensifyInterval;
    EXPECT_NE(r.GrowthStopReason.find("over " + std::to_string(patience) + " densification intervals (iteration " +
                std::to_string(stop) + ")"),
      std::string::npos)
      << r.GrowthStopReason;
    // One record per interval (measured before that interval's densification) and Finish's.
    const auto& h = r.ValidationHistory;
    ASSERT_EQ(h.size(), std::size_t(s.Iterations / s.DensifyInterval + 1));
    double best = h[0].Loss;
    for (std::size_t k = 0; k < h.size(); ++k)
    {
      EXPECT_EQ(h[k].Iteration, k + 1 < h.size() ? int(k + 1) * s.DensifyInterval : r.Iterations);
      best = std::min(best, h[k].Loss);
      if (k > 0 && h[k - 1].Iteration < stop)
      {
        EXPECT_GT(h[k].Gaussians, h[k - 1].Gaussians) << "still growing at " << h[k - 1].Iteration;
      }
      else if (k > 0)
      {
        EXPECT_LE(h[k].Gaussians, h[k - 1].Gaussians) << "grew after the stop, at " << h[k - 1].Iteration;
      }
    }
    EXPECT_EQ(r.BestValidationLoss, best);
    EXPECT_EQ(r.LastValidationLoss, h.back().Loss);
  }
}

TEST(Trainer, FillingAGapBetweenTrainingFramesRendersTheFramesInsideItBetter)
{
  // 14 consecutive frames (2.8 mm, beam sigma 0.2 mm) held out of the known field's sweep: with
  // FillGaps the frames in the gap are rendered from the blended copies of the frames on either side.
  std::vector<int> unused;
  TrainingData data = SyntheticSweep(KnownField(400, 3), 0.2, unused);
  std::vector<int> gap;
  data.TrainFrames.clear();
  for (int k = 0; k < data.Count(); ++k)
  {
    (k >= 23 && k < 37 ? gap : data.TrainFrames).push_back(k);
  }
  TrainerSettings s;
  s.ElevationSigma = 0.2;
  s.InitialGaussians = 3000;
  s.Iterations = 1500;
  double psnr[2];
  for (int fill = 0; fill < 2; ++fill)
  {
    s.FillGaps = fill == 1;
    Trainer trainer(data, s);
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    psnr[fill] = HeldOutPsnr(trainer, gap);
    const GapFillingReport& g = trainer.GetReport().GapFilling;
    std::printf("FillGaps %s: frames in the gap %.2f dB; %s\n", fill ? "on" : "off", psnr[fill],
      DescribeGapFilling(g, s.GapFilling).c_str());
    EXPECT_EQ(g.Gaps, fill);
    EXPECT_EQ(g.Added > 0, fill == 1);
    EXPECT_EQ(trainer.GetField().Count(), trainer.GetReport().Gaussians);
  }
  EXPECT_GT(psnr[1], psnr[0] + 0.5); // measured: 20.24 -> 21.76 dB
}

TEST(Trainer, TheMergeAtTheEndIsMergeGaussiansOnTheTrainedFieldAndKeepsItsRender)
{
  // The same deterministic run with the merge off and on: the merged run's field is MergeGaussians on the
  // other's, it is smaller, and it renders the held-out frames within 0.05 dB of it.
  std::vector<int> heldOut;
  TrainingData data = SyntheticSweep(KnownField(400, 3), 0.5, heldOut);
  GaussianField fields[2];
  double psnr[2];
  for (int merge = 0; merge < 2; ++merge)
  {
    TrainerSettings s = ShortSettings();
    s.Merge.Tolerance = merge ? 1e-3 : 0;
    Trainer trainer(data, s);
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    fields[merge] = trainer.GetField();
    psnr[merge] = HeldOutPsnr(trainer, heldOut);
    const GaussianMergeReport& r = trainer.GetReport().Merge;
    std::printf("merge %s: %lld Gaussians, held out %.3f dB; %s\n", merge ? "on" : "off",
      static_cast<long long>(fields[merge].Count()), psnr[merge], DescribeGaussianMerge(r, s.Merge).c_str());
    EXPECT_EQ(r.Merged > 0, merge == 1);
    EXPECT_EQ(trainer.GetReport().Gaussians, fields[merge].Count());
  }
  GaussianField expected = fields[0];
  GaussianMergeSettings settings;
  settings.Tolerance = 1e-3;
  MergeGaussians(expected, settings);
  ExpectSameField(fields[1], expected);
  EXPECT_LT(fields[1].Count(), fields[0].Count());
  EXPECT_NEAR(psnr[1], psnr[0], 0.05);
}

TEST(Trainer, APoseTheRendererRejectsFailsTheRunWithItsMessage)
{
  // A sweep read with a looser shear limit than the renderer's (the reader's MaximumShearAngle at 10
  // degrees) used to train on the previous frame's buffers; now Initialize names the frame.
  std::vector<int> heldOut;
  TrainingData data = SyntheticSweep(KnownField(100, 5), 0.5, heldOut);
  const int bad = data.TrainFrames[3];
  const double shear = 8.0 * M_PI / 180.0; // the second image axis tilted 8 degrees towards the first
  std::array<double, 16>& m = data.Poses[bad];
  for (int r = 0; r < 3; ++r)
  {
    m[4 * r + 1] = std::cos(shear) * m[4 * r + 1] + std::sin(shear) * m[4 * r];
  }
  Trainer trainer(data, ShortSettings());
  std::string error;
  EXPECT_FALSE(trainer.Initialize(&error));
  EXPECT_NE(error.find("training frame " + std::to_string(bad)), std::string::npos) << error;
  EXPECT_NE(error.find("shear"), std::string::npos) << error;

  // The renderer's own refusal reaches Step's caller too (a field pushed past Initialize's check).
  TrainingData alone = data;
  alone.TrainFrames = { bad };
  Trainer direct(alone, ShortSettings());
  ASSERT_TRUE(direct.SetField(KnownField(50, 2), &error)) << error;
  double loss = 0;
  EXPECT_EQ(direct.Step(&loss, &error), StepStatus::Failed);
  EXPECT_NE(error.find("shear"), std::string::npos) << error;
}

TEST(Trainer, SparseAdamLeavesTheGaussiansAStepDidNotTouchAsTheyWere)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(50, 4), 0.5, heldOut);
  OptimizerState state;
  state.Field = KnownField(2, 11);
  // Gaussian 0 on frame 0's plane (z = -6 mm, the middle of the frame), Gaussian 1 100 mm off every frame.
  state.Field.Means = { 9.6f, 9.6f, -6.0f, 9.6f, 9.6f, 100.0f };
  state.ResizeToField();
  for (GaussianField* moment : { &state.FirstMoment, &state.SecondMoment })
  {
    const float value = moment == &state.FirstMoment ? 0.1f : 0.01f;
    for (std::vector<float>* v : { &moment->Means, &moment->LogScales, &moment->Quaternions, &moment->Reflectivities })
    {
      std::fill(v->begin(), v->end(), value);
    }
  }
  for (bool sparse : { true, false })
  {
    std::string error;
    auto engine = CreateTrainingEngine("cpu", &error);
    ASSERT_NE(engine, nullptr) << error;
    ASSERT_TRUE(engine->SetData(&data, &error) && engine->Push(state, &error)) << error;
    const int frame = 0;
    StepRequest request;
    request.Frames = &frame;
    request.Count = 1;
    request.Iteration = 5;
    request.MeanRate = request.LogScaleRate = request.QuaternionRate = request.ReflectivityRate = 0.01;
    request.MinimumLogScale = std::log(0.01);
    request.MaximumLogScale = std::log(100.0);
    request.SparseAdam = sparse;
    double loss = 0;
    ASSERT_EQ(engine->Step(request, &loss, &error), StepStatus::Done) << error;
    OptimizerState after;
    ASSERT_TRUE(engine->Pull(after, &error)) << error;
    EXPECT_NE(after.Field.Reflectivities[0], state.Field.Reflectivities[0]) << "the Gaussian on the frame moves";
    if (sparse)
    {
      for (const auto& [a, b] : { std::make_pair(&after.Field, &state.Field),
             std::make_pair(&after.FirstMoment, &state.FirstMoment), std::make_pair(&after.SecondMoment, &state.SecondMoment) })
      {
        EXPECT_TRUE(std::equal(a->Means.begin() + 3, a->Means.end(), b->Means.begin() + 3));
        EXPECT_TRUE(std::equal(a->LogScales.begin() + 3, a->LogScales.end(), b->LogScales.begin() + 3));
        EXPECT_TRUE(std::equal(a->Quaternions.begin() + 4, a->Quaternions.end(), b->Quaternions.begin() + 4));
        EXPECT_EQ(a->Reflectivities[1], b->Reflectivities[1]);
      }
    }
    else
    {
      // Dense Adam (Kingma and Ba, algorithm 1) with a zero gradient: m = beta1 m, and the parameter moves
      // on that momentum.
      EXPECT_FLOAT_EQ(after.FirstMoment.Reflectivities[1], 0.9f * 0.1f);
      EXPECT_NE(after.Field.Reflectivities[1], state.Field.Reflectivities[1]);
      EXPECT_NE(after.Field.Means[5], state.Field.Means[5]);
    }
  }
}

TEST(Trainer, ADataParallelStepOnTwoProcessesIsOneProcessesStepOnAllTheFrames)
{
  // Two processes (threads with a ThreadReduction, as the ranks of mpirun with vtkMPIController's AllReduce) each
  // render their share of a step's frames and sum: three steps give both the same field, moments and EA-D
  // accumulators, and they are one process's steps on all the frames to the float rounding of the sums' order.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(50, 4), 0.5, heldOut);
  OptimizerState state;
  state.Field = KnownField(300, 12);
  state.ResizeToField();
  const std::vector<int> frames = { 0, 5, 9, 14, 20 };
  StepRequest request;
  request.Frames = frames.data();
  request.Count = static_cast<int>(frames.size());
  request.MeanRate = request.LogScaleRate = request.QuaternionRate = request.ReflectivityRate = 0.01;
  request.MinimumLogScale = std::log(0.01);
  request.MaximumLogScale = std::log(100.0);
  auto train = [&](ProcessReduction* reduction, std::vector<double>& losses, OptimizerState& after) {
    std::string error;
    auto engine = CreateTrainingEngine("cpu", &error);
    ASSERT_NE(engine, nullptr) << error;
    ASSERT_TRUE(engine->SetData(&data, &error) && engine->SetReduction(reduction, &error) &&
      engine->Push(state, &error))
      << error;
    for (int step = 0; step < 3; ++step)
    {
      StepRequest r = request;
      r.Iteration = step;
      double loss = 0;
      EXPECT_EQ(engine->Step(r, &loss, &error), StepStatus::Done) << error;
      losses.push_back(loss);
    }
    EXPECT_TRUE(engine->Pull(after, &error)) << error;
  };
  std::vector<double> losses[3];
  OptimizerState after[3];
  train(nullptr, losses[2], after[2]);
  bigus::test::RunOnThreads(2, [&](int rank, ProcessReduction& reduction) {
    train(&reduction, losses[rank], after[rank]);
  });
  EXPECT_EQ(losses[0], losses[1]);
  ExpectSameField(after[0].Field, after[1].Field);
  ExpectSameField(after[0].SecondMoment, after[1].SecondMoment);
  EXPECT_EQ(after[0].Attribution, after[1].Attribution);
  EXPECT_EQ(after[0].SeenCount, after[1].SeenCount);
  EXPECT_EQ(after[0].SeenCount, after[2].SeenCount) << "the visible counts of all the frames";
  for (int step = 0; step < 3; ++step)
  {
    EXPECT_NEAR(losses[0][step], losses[2][step], 1e-6 * losses[2][step]) << "step " << step;
  }
  ASSERT_EQ(after[0].Field.Count(), after[2].Field.Count());
  double largest = 0, attribution = 0;
  for (std::size_t k = 0; k < after[0].Field.Means.size(); ++k)
  {
    largest = std::max(largest, static_cast<double>(std::abs(after[0].Field.Means[k] - after[2].Field.Means[k])));
  }
  for (std::size_t k = 0; k < after[0].Attribution.size(); ++k)
  {
    const double a = after[0].Attribution[k], b = after[2].Attribution[k];
    attribution = std::max(attribution, std::abs(a - b) / std::max(1e-12, std::abs(b)));
  }
  std::printf("two processes against one: means %.3g mm apart at most, attribution %.3g relative\n", largest,
    attribution);
  EXPECT_LT(largest, 1e-4) << "three steps of 0.01 mm each moved the means differently";
  EXPECT_LT(attribution, 1e-4);
}

namespace
{
/// The CPU renderer under the name of a test backend that brings its own training engine.
class EngineBackendRenderer : public Renderer
{
public:
  explicit EngineBackendRenderer(const char* name)
    : Name(name)
  {
  }
  const char* GetName() const override { return this->Name; }
  bool Forward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options, float* S,
    float* I, RenderStats* stats, std::string* error) override
  {
    return this->Cpu->Forward(field, slices, count, options, S, I, stats, error);
  }
  bool Backward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    const float* S, const float* dL, bool wrtS, FieldGradients& gradients, RenderStats* stats,
    std::string* error) override
  {
    return this->Cpu->Backward(field, slices, count, options, S, dL, wrtS, gradients, stats, error);
  }

private:
  const char* Name;
  std::unique_ptr<Renderer> Cpu = CreateCpuRenderer();
};

int EnginesMade = 0;
std::unique_ptr<Renderer> MakeOwnEngineRenderer(std::string*)
{
  return std::make_unique<EngineBackendRenderer>("own-engine");
}
std::unique_ptr<TrainingEngine> MakeOwnEngine(std::string*)
{
  ++EnginesMade;
  return CreateCpuTrainingEngine(CreateCpuRenderer());
}
std::unique_ptr<Renderer> MakeBrokenEngineRenderer(std::string*)
{
  return std::make_unique<EngineBackendRenderer>("broken-engine");
}
std::unique_ptr<TrainingEngine> MakeBrokenEngine(std::string* error)
{
  *error = "the device has no room for the training state";
  return nullptr;
}
}

namespace
{
/// SyntheticSweep of @p truth (sigma_E 0.5 mm) with a shared fan mask that leaves out every 7th pixel in a slanted
/// pattern, for the decimation tests.
TrainingData SweepWithAMaskWithHoles(const GaussianField& truth)
{
  std::vector<int> heldOut;
  TrainingData data = SyntheticSweep(truth, 0.5, heldOut);
  data.Mask.assign(std::size_t(W) * H, 1);
  for (int j = 0; j < H; ++j)
  {
    for (int i = 0; i < W; ++i)
    {
      data.Mask[std::size_t(j) * W + i] = (i + 3 * j) % 7 != 0;
    }
  }
  return data;
}
}

TEST(Trainer, DecimatedFramesAreTheFramesPointSamplesAtTheSamePoints)
{
  // DecimateFrames (the resolution schedule's coarse frames) against the source frames: each pixel (i, j) is the
  // source's (ox + 2 i, oy + 2 j), in value, mask and position in mm, and a known field rendered at the decimated
  // pose gives the source render's pixels there.
  const GaussianField truth = KnownField(200, 5);
  TrainingData data = SweepWithAMaskWithHoles(truth);
  data.Sweeps.assign(data.Count(), 0);
  data.Sweeps[31] = 1;
  const int frames[2] = { 31, 7 };
  auto cpu = CreateCpuRenderer();
  RenderOptions o;
  o.ElevationSigma = 0.5;
  std::string error;
  for (const auto& [ox, oy] : { std::pair<int, int>{ 0, 0 }, { 1, 0 }, { 0, 1 }, { 1, 1 } })
  {
    const TrainingData d = DecimateFrames(data, frames, 2, ox, oy);
    ASSERT_EQ(d.Width, W / 2);
    ASSERT_EQ(d.Height, H / 2);
    ASSERT_EQ(d.Count(), 2);
    EXPECT_EQ(d.TrainFrames, (std::vector<int>{ 0, 1 }));
    EXPECT_EQ(d.SweepOf(0), 1);
    EXPECT_EQ(d.SweepOf(1), 0);
    for (int k = 0; k < 2; ++k)
    {
      const SliceGeometry coarse = d.Slice(k), full = data.Slice(frames[k]);
      std::vector<float> Sc(std::size_t(d.Width) * d.Height), Sf(std::size_t(W) * H);
      ASSERT_TRUE(cpu->Forward(truth.View(), &coarse, 1, o, Sc.data(), nullptr, nullptr, &error)) << error;
      ASSERT_TRUE(cpu->Forward(truth.View(), &full, 1, o, Sf.data(), nullptr, nullptr, &error)) << error;
      double worst = 0;
      for (int j = 0; j < d.Height; ++j)
      {
        for (int i = 0; i < d.Width; ++i)
        {
          const std::size_t c = std::size_t(j) * d.Width + i, f = std::size_t(oy + 2 * j) * W + ox + 2 * i;
          ASSERT_EQ(d.Frames[c + d.Width * d.Height * k], data.Frames[std::size_t(W) * H * frames[k] + f]);
          ASSERT_EQ(d.MaskOf(k)[c], data.Mask[f]);
          worst = std::max(worst, double(std::abs(Sc[c] - Sf[f])));
          for (int r = 0; r < 3; ++r)
          {
            const double* P = full.ImageToReference;
            const double* Q = coarse.ImageToReference;
            EXPECT_NEAR(Q[4 * r] * i + Q[4 * r + 1] * j + Q[4 * r + 3],
              P[4 * r] * (ox + 2 * i) + P[4 * r + 1] * (oy + 2 * j) + P[4 * r + 3], 1e-12);
          }
        }
      }
      EXPECT_LT(worst, 1e-5) << "the render at the decimated pose, offset " << ox << ", " << oy;
    }
  }
  // An odd size: the offset's row and column count.
  data.Width = W - 1; // frames read as 63 x 64 with the last column of each row moved on: sizes only
  const TrainingData odd = DecimateFrames(data, frames, 1, 0, 1);
  EXPECT_EQ(odd.Width, 32);
  EXPECT_EQ(odd.Height, 32);
  EXPECT_EQ((DecimateFrames(data, frames, 1, 1, 0).Width), 31);
}

TEST(Trainer, AveragedDecimatedFramesAreTheBlockMeansAndTheLowPassRendersThem)
{
  // DecimateFrames with averages (TrainerSettings::CoarseLowPass): pixel (i, j) is the mean of the source's 2 x 2
  // block from (ox + 2 i, oy + 2 j), imaged where all four are, placed at the block's centre, with the low-pass of
  // 1/16 decimated pixels^2; a known field rendered there through the low-pass is closer to the mean of the source
  // render over the block than the point sample at the block's centre is (the truth: the block mean of the
  // full-resolution render).
  const GaussianField truth = KnownField(200, 5);
  TrainingData data = SweepWithAMaskWithHoles(truth);
  const int frame = 31;
  auto cpu = CreateCpuRenderer();
  RenderOptions o;
  o.ElevationSigma = 0.5;
  std::string error;
  const SliceGeometry full = data.Slice(frame);
  std::vector<float> Sf(std::size_t(W) * H);
  ASSERT_TRUE(cpu->Forward(truth.View(), &full, 1, o, Sf.data(), nullptr, nullptr, &error)) << error;
  for (const auto& [ox, oy] : { std::pair<int, int>{ 0, 0 }, { 1, 0 }, { 0, 1 }, { 1, 1 } })
  {
    const TrainingData d = DecimateFrames(data, &frame, 1, ox, oy, true);
    ASSERT_EQ(d.Width, (W - ox) / 2);
    ASSERT_EQ(d.Height, (H - oy) / 2);
    EXPECT_EQ(d.PixelLowPass, 1.0 / 16);
    SliceGeometry coarse = d.Slice(0);
    EXPECT_EQ(coarse.PixelLowPass, 1.0 / 16);
    std::vector<float> blurred(std::size_t(d.Width) * d.Height), point(blurred.size());
    ASSERT_TRUE(cpu->Forward(truth.View(), &coarse, 1, o, blurred.data(), nullptr, nullptr, &error)) << error;
    coarse.PixelLowPass = 0;
    ASSERT_TRUE(cpu->Forward(truth.View(), &coarse, 1, o, point.data(), nullptr, nullptr, &error)) << error;
    const float* image = data.Frames.data() + std::size_t(W) * H * frame;
    double blurredError = 0, pointError = 0;
    for (int j = 0; j < d.Height; ++j)
    {
      for (int i = 0; i < d.Width; ++i)
      {
        const std::size_t c = std::size_t(j) * d.Width + i;
        const std::size_t top = std::size_t(oy + 2 * j) * W + ox + 2 * i;
        const std::size_t f[4] = { top, top + 1, top + W, top + W + 1 };
        ASSERT_FLOAT_EQ(d.Frames[c], 0.25f * (image[f[0]] + image[f[1]] + image[f[2]] + image[f[3]]));
        ASSERT_EQ(d.Mask[c], data.Mask[f[0]] && data.Mask[f[1]] && data.Mask[f[2]] && data.Mask[f[3]]);
        for (int r = 0; r < 3; ++r)
        {
          const double* P = full.ImageToReference;
          const double* Q = coarse.ImageToReference;
          EXPECT_NEAR(Q[4 * r] * i + Q[4 * r + 1] * j + Q[4 * r + 3],
            P[4 * r] * (ox + 2 * i + 0.5) + P[4 * r + 1] * (oy + 2 * j + 0.5) + P[4 * r + 3], 1e-12);
        }
        const double mean = 0.25 * (double(Sf[f[0]]) + Sf[f[1]] + Sf[f[2]] + Sf[f[3]]);
        blurredError += (blurred[c] - mean) * (blurred[c] - mean);
        pointError += (point[c] - mean) * (point[c] - mean);
      }
    }
    std::printf("offset %d %d: RMS against the block means, low-pass %.4g, point samples %.4g\n", ox, oy,
      std::sqrt(blurredError / blurred.size()), std::sqrt(pointError / point.size()));
    EXPECT_LT(blurredError, 0.5 * pointError) << "offset " << ox << ", " << oy;
  }
}

TEST(Trainer, ADecimatedFramesPoseGradientMovedToTheSourcePivotMatchesCentralDifferences)
{
  // A coarse step's pose gradient is taken about the decimated frame's centre pixel; DecimatedPoseGradientToSource
  // makes it the gradient of the source frame's correction (CorrectPose about the source's centre), which is what
  // the trainer moves. Truth: central differences of sum_p w(p) S(p) over the decimated pixels, rendered in double
  // (the reference renderer, every Gaussian at every pixel: where footprints are cut, their edges move with the pose
  // and the differences jump by up to 0.3 % of the gradient) at the decimated pose of the corrected source pose.
  const GaussianField truth = KnownField(300, 4);
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(truth, 0.5, heldOut);
  const reference::FieldD field = reference::FromView(truth.View());
  RenderOptions o;
  o.ElevationSigma = 0.5;
  const int frame = 23;
  auto cpu = CreateCpuRenderer();
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> w(std::size_t(W / 2) * (H / 2));
  for (double& v : w)
  {
    v = u(rng);
  }
  std::string error;
  for (bool average : { false, true }) // point samples; 2 x 2 averages at the blocks' centres, with the low-pass
  {
    for (const auto& [ox, oy] : { std::pair<int, int>{ 0, 0 }, { 1, 0 }, { 0, 1 }, { 1, 1 } })
    {
      const SliceGeometry coarse = DecimateFrames(data, &frame, 1, ox, oy, average).Slice(0);
      w.resize(std::size_t(coarse.Width) * coarse.Height);
      const std::vector<float> dL(w.begin(), w.end());
      std::vector<float> S(w.size());
      double pose[6] = { 0, 0, 0, 0, 0, 0 };
      FieldGradients g;
      g.SlicePoses = pose;
      ASSERT_TRUE(cpu->Forward(truth.View(), &coarse, 1, o, S.data(), nullptr, nullptr, &error)) << error;
      ASSERT_TRUE(cpu->Backward(truth.View(), &coarse, 1, o, S.data(), dL.data(), true, g, nullptr, &error)) << error;
      double moved[6];
      std::copy(pose, pose + 6, moved);
      DecimatedPoseGradientToSource(data, frame, ox, oy, moved, average);
      auto loss = [&](const double xi[6]) {
        TrainingData corrected = data;
        EXPECT_EQ(CorrectPose(data.Poses[frame].data(), W, H, xi, corrected.Poses[frame].data()), PoseStatus::Ok);
        std::vector<double> Sd;
        EXPECT_TRUE(reference::Forward(
          field, DecimateFrames(corrected, &frame, 1, ox, oy, average).Slice(0), o, Sd, nullptr, false));
        double sum = 0;
        for (std::size_t p = 0; p < Sd.size(); ++p)
        {
          sum += w[p] * Sd[p];
        }
        return sum;
      };
      double largest = 0;
      for (double v : moved)
      {
        largest = std::max(largest, std::abs(v));
      }
      ASSERT_GT(largest, 0);
      for (int k = 0; k < 6; ++k)
      {
        const double fd = test::PoseCentralDifference(loss, k);
        std::printf("%s, offset %d %d, xi[%d]: central difference %.6g, moved %.6g (about the decimated centre %.6g)\n",
          average ? "averages" : "point samples", ox, oy, k, fd, moved[k], pose[k]);
        EXPECT_NEAR(moved[k], fd, 1e-4 * largest)
          << (average ? "averages" : "point samples") << ", offset " << ox << ", " << oy << ", component " << k;
      }
    }
  }
}

namespace
{
/// The CPU engine, recording the frame size of every step (the resolution schedule's coarse steps).
class SizeRecordingEngine : public TrainingEngine
{
public:
  std::vector<int> StepWidths;
  std::vector<double> StepLowPass; // TrainingData::PixelLowPass of each step's frames
  std::vector<bool> PoseGradients;

  const char* GetName() const override { return "cpu"; }
  bool SetData(const TrainingData* data, std::string* error) override
  {
    this->Data = data;
    return this->Cpu->SetData(data, error);
  }
  bool Push(const OptimizerState& state, std::string* error) override { return this->Cpu->Push(state, error); }
  bool Pull(OptimizerState& state, std::string* error) override { return this->Cpu->Pull(state, error); }
  bool PullField(GaussianField& field, std::string* error) override { return this->Cpu->PullField(field, error); }
  StepStatus Step(const StepRequest& request, double* loss, std::string* error) override
  {
    this->StepWidths.push_back((request.Data ? request.Data : this->Data)->Width);
    this->StepLowPass.push_back((request.Data ? request.Data : this->Data)->PixelLowPass);
    this->PoseGradients.push_back(request.PoseGradients != nullptr);
    return this->Cpu->Step(request, loss, error);
  }
  void Snapshot() override { this->Cpu->Snapshot(); }
  void Restore() override { this->Cpu->Restore(); }
  bool Render(const SliceGeometry* slices, int count, const RenderOptions& options, float* S, float* I,
    std::string* error) override
  {
    return this->Cpu->Render(slices, count, options, S, I, error);
  }
  bool ApplyBasis(const float* r, const int* frames, int count, const RenderOptions& options, float* S,
    std::string* error) override
  {
    return this->Cpu->ApplyBasis(r, frames, count, options, S, error);
  }
  bool ApplyBasisTranspose(const float* y, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) override
  {
    return this->Cpu->ApplyBasisTranspose(y, frames, count, options, out, error);
  }
  bool BasisNorms(const float* weights, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) override
  {
    return this->Cpu->BasisNorms(weights, frames, count, options, out, error);
  }

private:
  const TrainingData* Data = nullptr;
  std::unique_ptr<TrainingEngine> Cpu = CreateTrainingEngine("cpu", nullptr);
};
}

TEST(Trainer, TheResolutionScheduleStepsOnAQuarterOfThePixelsFirstAndLearnsThere)
{
  // CoarseFraction 0.5 of 400 steps: steps 0 to 199 on 32 x 32 decimated frames (point samples; with CoarseLowPass
  // 2 x 2 averages, 32 or 31 pixels wide by their phase, through the low-pass of 1/16 pixels^2), the rest on the
  // 64 x 64 frames, all with pose gradients; the coarse steps alone lower the full-resolution held-out error.
  const GaussianField truth = KnownField(400, 3);
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(truth, 0.5, heldOut);
  for (bool lowPass : { false, true })
  {
    TrainerSettings s;
    s.ElevationSigma = 0.5;
    s.InitialGaussians = 3000;
    s.Iterations = 400;
    s.CoarseFraction = 0.5;
    s.CoarseLowPass = lowPass;
    s.Poses.RefinePoses = PoseRefinement::On;
    s.Poses.Start = 0;
    auto owned = std::make_unique<SizeRecordingEngine>();
    SizeRecordingEngine* engine = owned.get();
    Trainer trainer(data, s, std::move(owned));
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    const double before = HeldOutPsnr(trainer, heldOut);
    ASSERT_TRUE(trainer.Train(nullptr, [&] { return engine->StepWidths.size() >= 200; }, &error)) << error;
    ASSERT_LE(engine->StepWidths.size(), 200u);
    const double coarse = HeldOutPsnr(trainer, heldOut);
    ASSERT_TRUE(trainer.Train(nullptr, nullptr, &error)) << error;
    ASSERT_EQ(engine->StepWidths.size(), 400u);
    for (std::size_t k = 0; k < 400; ++k)
    {
      if (k < 200 && lowPass)
      {
        ASSERT_TRUE(engine->StepWidths[k] == W / 2 || engine->StepWidths[k] == W / 2 - 1) << "step " << k;
      }
      else
      {
        ASSERT_EQ(engine->StepWidths[k], k < 200 ? W / 2 : W) << "step " << k;
      }
      ASSERT_EQ(engine->StepLowPass[k], k < 200 && lowPass ? 1.0 / 16 : 0.0) << "step " << k;
      ASSERT_TRUE(engine->PoseGradients[k]) << "step " << k;
    }
    std::printf("%s: held-out PSNR %.2f dB at the start, %.2f after 200 coarse steps\n",
      lowPass ? "averages through the low-pass" : "point samples", before, coarse);
    EXPECT_GT(coarse, before + 3.0);
  }
}

TEST(Trainer, ABackendBringsItsOwnTrainingEngine)
{
  // Registered engines are taken by name and by "auto"; "cpu" keeps the CPU engine. An engine that
  // cannot be made is an error when its backend is named, and "auto" then trains through the CPU
  // engine over that backend's renderer, saying so.
  RegisterBackend("own-engine", &MakeOwnEngineRenderer, 20);
  RegisterTrainingEngine("own-engine", &MakeOwnEngine);
  std::string error, notice;
  ASSERT_NE(CreateTrainingEngine("own-engine", &error), nullptr) << error;
  EXPECT_EQ(EnginesMade, 1);
  ASSERT_NE(CreateTrainingEngine("auto", &error), nullptr) << error;
  EXPECT_EQ(EnginesMade, 2);
  ASSERT_NE(CreateTrainingEngine("cpu", &error), nullptr) << error;
  EXPECT_EQ(EnginesMade, 2);

  RegisterBackend("broken-engine", &MakeBrokenEngineRenderer, 30);
  RegisterTrainingEngine("broken-engine", &MakeBrokenEngine);
  EXPECT_EQ(CreateTrainingEngine("broken-engine", &error), nullptr);
  EXPECT_NE(error.find("training engine of backend 'broken-engine' cannot be used: the device has no room"),
    std::string::npos)
    << error;
  std::unique_ptr<TrainingEngine> fallback = CreateTrainingEngine("auto", &error, &notice);
  ASSERT_NE(fallback, nullptr) << error;
  EXPECT_STREQ(fallback->GetName(), "broken-engine") << "the CPU engine over the backend's renderer";
  EXPECT_NE(notice.find("trains through the CPU engine"), std::string::npos) << notice;
}

TEST(Trainer, AnUnavailableBackendIsAClearError)
{
  std::string error;
  EXPECT_EQ(CreateTrainingEngine("no-such-backend", &error), nullptr);
  EXPECT_NE(error.find("no-such-backend"), std::string::npos) << error;
  EXPECT_NE(error.find("cpu"), std::string::npos) << "the message lists what is available: " << error;
  auto cpu = CreateTrainingEngine("cpu", &error);
  ASSERT_NE(cpu, nullptr) << error;
  EXPECT_STREQ(cpu->GetName(), "cpu");
  auto automatic = CreateTrainingEngine("auto", &error);
  ASSERT_NE(automatic, nullptr) << error;

  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(150, 9), 0.5, heldOut);
  vtkSmartPointer<vtkImageData> sequence = bigus_test::TrackedSequence(W, H, data.Poses,
    std::vector<double>(data.Count(), 0.0),
    [&](int k, int i, int j) { return data.Frames[(std::size_t(k) * H + j) * W + i]; });
  vtkNew<vtkGaussianFieldTrainer> filter;
  filter->SetInputData(sequence);
  filter->SetIterations(10);
  filter->SetBackend("no-such-backend");
  vtkNew<bigus_test::MessageCollector> messages;
  messages->Watch(filter);
  filter->Update();
  EXPECT_EQ(filter->GetOutput()->GetNumberOfPoints(), 0);
  ASSERT_EQ(messages->Errors.size(), 1u);
  EXPECT_NE(messages->Errors[0].find("'no-such-backend' is not available"), std::string::npos) << messages->Errors[0];
  filter->SetBackend("cpu");
  filter->Update();
  EXPECT_GT(filter->GetOutput()->GetNumberOfPoints(), 0);
  EXPECT_STREQ(filter->GetBackendInUse(), "cpu");
  vtkAbstractArray* used = filter->GetOutput()->GetFieldData()->GetAbstractArray("Backend");
  ASSERT_NE(used, nullptr);
  EXPECT_EQ(used->GetVariantValue(0).ToString(), "cpu");
}

TEST(Trainer, EveryAblationSwitchRuns)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  for (int variant = 0; variant < 6; ++variant)
  {
    TrainerSettings s = ShortSettings();
    s.Iterations = 120;
    const char* names[] = { "random initialisation", "no densification", "thin plane", "non-negative r", "L1 only",
      "no L1" };
    switch (variant)
    {
      case 0: s.HarrisInitialisation = false; break;
      case 1: s.Densify = false; break;
      case 2: s.BeamIntegration = false; break;
      case 3: s.NonNegativeReflectivity = true; break;
      case 4: s.Loss.DSSIM = 0; s.Loss.FFL = 0; break;
      case 5: s.Loss.L1 = 0; break;
    }
    Trainer trainer(data, s);
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << names[variant] << ": " << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << names[variant] << ": " << error;
    const std::vector<double>& h = trainer.GetState().LossHistory;
    ASSERT_GE(h.size(), 100u) << names[variant];
    double early = 0, late = 0;
    for (int k = 0; k < 20; ++k)
    {
      early += h[k];
      late += h[h.size() - 1 - k];
    }
    EXPECT_LT(late, early) << names[variant] << ": the loss must go down";
    EXPECT_TRUE(AllFinite(trainer.GetField())) << names[variant];
    // The settings lines say what Finish does: no gap filling without an elevation beam.
    const std::vector<std::string>& lines = trainer.GetReport().Settings;
    const bool fillsGaps = std::any_of(lines.begin(), lines.end(),
      [](const std::string& line) { return line.rfind("FillGaps = on", 0) == 0; });
    EXPECT_EQ(fillsGaps, s.BeamIntegration) << names[variant];
  }
}

TEST(Trainer, DivergingStepsAreRolledBackNeverWrittenIntoTheField)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(100, 8), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.Iterations = 60;
  s.Densify = false;
  s.MeanLearningRate = s.MeanLearningRateFinal = 1e39; // beyond float: the first update overflows to Inf
  s.ReflectivityLearningRate = 1e39;
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error));
  for (int k = 0; k < 60; ++k)
  {
    double loss = 0;
    ASSERT_NE(trainer.Step(&loss, &error), StepStatus::Failed) << error;
    ASSERT_TRUE(AllFinite(trainer.GetField())) << "step " << k;
  }
  EXPECT_GT(trainer.GetState().RolledBackSteps, 0);
}

namespace
{
/// The spine-phantom sweep as training data, frames with k mod 4 == 2 held out.
TrainingData SpineData(std::vector<int>& heldOut)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName((std::string(BIGUS_TEST_DATA) + "/spine-phantom/SpinePhantomFreehand.igs.mha").c_str());
  reader->SetCalibrationFileName(
    (std::string(BIGUS_TEST_DATA) + "/spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml").c_str());
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputConnection(reader->GetOutputPort());
  fan->Update();
  vtkImageData* frames = reader->GetOutput();
  int dims[3];
  frames->GetDimensions(dims);
  TrainingData d;
  d.Width = dims[0];
  d.Height = dims[1];
  const auto* pixels = static_cast<unsigned char*>(frames->GetScalarPointer());
  for (vtkIdType p = 0; p < vtkIdType(dims[0]) * dims[1] * dims[2]; ++p)
  {
    d.Frames.push_back(pixels[p] / 255.0f);
  }
  const auto* mask = static_cast<unsigned char*>(fan->GetOutput()->GetScalarPointer());
  d.Mask.assign(mask, mask + dims[0] * dims[1]);
  for (int k = 0; k < dims[2]; ++k)
  {
    std::array<double, 16> m;
    frames->GetFieldData()->GetArray("ImageToReference")->GetTuple(k, m.data());
    d.Poses.push_back(m);
    (k % 4 == 2 ? heldOut : d.TrainFrames).push_back(k);
  }
  return d;
}

double MaskedL1(const float* a, const float* b, const std::vector<unsigned char>& mask)
{
  double sum = 0;
  long n = 0;
  for (std::size_t p = 0; p < mask.size(); ++p)
  {
    if (mask[p])
    {
      sum += std::abs(double(a[p]) - b[p]);
      ++n;
    }
  }
  return sum / n;
}
}

namespace
{
/// The spine tests' settings: sigma 1.5 mm, 10,000 seeds, densification every 100 steps from 100.
TrainerSettings SpineSettings(int iterations)
{
  TrainerSettings s;
  s.ElevationSigma = 1.5;
  s.InitialGaussians = 10000;
  s.Iterations = iterations;
  s.DensifyStart = 100;
  s.DensifyInterval = 100;
  return s;
}
}

TEST(Trainer, SpinePhantomShortRunLearnsAndBeatsTheNearestFrameOnHeldOutFrames)
{
  std::vector<int> heldOut;
  const TrainingData data = SpineData(heldOut);
  // The phantom's frames lie about 1.5 mm apart: a beam of sigma 1.5 mm lets neighbouring frames
  // constrain the Gaussians between them (with 0.5 mm the held-out frames fall in the gaps).
  const TrainerSettings s = SpineSettings(300);
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const TrainerReport& r = trainer.GetReport();

  // The masked training loss goes down on average: the mean of the last fifth of the steps is below
  // the mean of the first fifth.
  const std::vector<double>& losses = trainer.GetState().LossHistory;
  const std::size_t fifth = losses.size() / 5;
  double first = 0, last = 0;
  for (std::size_t k = 0; k < fifth; ++k)
  {
    first += losses[k] / fifth;
    last += losses[losses.size() - 1 - k] / fifth;
  }
  EXPECT_LT(last, first);

  // Held-out frames: rendering versus the nearest training frame by the distance between frame centres.
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  auto renderer = CreateCpuRenderer();
  std::vector<float> S(pixels), I(pixels);
  double rendered = 0, nearest = 0;
  for (int k : heldOut)
  {
    const SliceGeometry g = trainer.Slice(k);
    ASSERT_TRUE(renderer->Forward(trainer.GetField().View(), &g, 1, trainer.Options(), S.data(), I.data(), nullptr, nullptr));
    const float* truth = &data.Frames[pixels * k];
    int best = data.TrainFrames.front();
    double bestDistance = 1e300;
    for (int t : data.TrainFrames)
    {
      double c[2][3];
      for (int r2 = 0; r2 < 3; ++r2)
      {
        c[0][r2] = data.Poses[k][4 * r2] * data.Width / 2 + data.Poses[k][4 * r2 + 1] * data.Height / 2 + data.Poses[k][4 * r2 + 3];
        c[1][r2] = data.Poses[t][4 * r2] * data.Width / 2 + data.Poses[t][4 * r2 + 1] * data.Height / 2 + data.Poses[t][4 * r2 + 3];
      }
      const double d = std::hypot(c[0][0] - c[1][0], c[0][1] - c[1][1], c[0][2] - c[1][2]);
      if (d < bestDistance)
      {
        bestDistance = d;
        best = t;
      }
    }
    rendered += MaskedL1(I.data(), truth, data.Mask) / heldOut.size();
    nearest += MaskedL1(&data.Frames[pixels * best], truth, data.Mask) / heldOut.size();
  }
  std::printf("spine: %d steps in %.1f s, %lld Gaussians; loss %.4f -> %.4f; held-out masked L1: BIGUS %.4f, "
              "nearest training frame %.4f\n",
    r.Iterations, r.Seconds, static_cast<long long>(r.Gaussians), first, last, rendered, nearest);
  EXPECT_LT(rendered, nearest);
}

// Early stopping: the field Finish keeps is the best the run passed through on the validation frames,
// so a run twice as long (same seed, its schedule stretched) never ends with a higher validation loss.
TEST(Trainer, ARunTwiceAsLongNeverEndsWorseOnTheValidationFrames)
{
  std::vector<int> heldOut;
  const TrainingData data = SpineData(heldOut);
  double validation[2] = { 0, 0 };
  for (int run = 0; run < 2; ++run)
  {
    const TrainerSettings s = SpineSettings(300 * (run + 1));
    Trainer trainer(data, s);
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    const TrainerReport& r = trainer.GetReport();
    std::printf("%d steps: validation loss %.5f at the end, best %.5f at iteration %d (kept)\n", r.Iterations,
      r.LastValidationLoss, r.BestValidationLoss, r.BestIteration);
    EXPECT_LE(r.BestValidationLoss, r.LastValidationLoss);
    EXPECT_GT(r.BestIteration, 0);
    EXPECT_LE(r.BestIteration, s.Iterations);
    validation[run] = r.BestValidationLoss;
  }
  EXPECT_LE(validation[1], validation[0]);
}

TEST(GaussianFieldTrainer, PipelineOutputsTheFieldOfTheDataModel)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(150, 9), 0.5, heldOut);
  // The synthetic sweep as a tracked frame sequence (unsigned char, as a reader gives it).
  vtkNew<vtkImageData> sequence;
  sequence->SetDimensions(W, H, data.Count());
  sequence->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  auto* pixels = static_cast<unsigned char*>(sequence->GetScalarPointer());
  for (std::size_t p = 0; p < data.Frames.size(); ++p)
  {
    pixels[p] = static_cast<unsigned char>(std::lround(255 * data.Frames[p]));
  }
  vtkNew<vtkDoubleArray> poses;
  poses->SetName("ImageToReference");
  poses->SetNumberOfComponents(16);
  for (const auto& m : data.Poses)
  {
    poses->InsertNextTuple(m.data());
  }
  sequence->GetFieldData()->AddArray(poses);

  vtkNew<vtkGaussianFieldTrainer> trainer;
  trainer->SetInputData(sequence);
  trainer->SetIterations(150);
  trainer->SetInitialGaussians(500);
  trainer->SetHoldOutEvery(4);
  trainer->SetHoldOutOffset(2);
  int progressEvents = 0;
  vtkNew<vtkCallbackCommand> counter;
  counter->SetClientData(&progressEvents);
  counter->SetCallback([](vtkObject*, unsigned long, void* client, void*) { ++*static_cast<int*>(client); });
  trainer->AddObserver(vtkCommand::ProgressEvent, counter);
  // The settings are announced once, before any step.
  struct Announced
  {
    int Count = 0, IterationThen = -1;
    std::string Text;
  } announced;
  vtkNew<vtkCallbackCommand> settingsObserver;
  settingsObserver->SetClientData(&announced);
  settingsObserver->SetCallback([](vtkObject* caller, unsigned long, void* client, void*) {
    auto* a = static_cast<Announced*>(client);
    auto* t = static_cast<vtkGaussianFieldTrainer*>(caller);
    ++a->Count;
    a->IterationThen = t->GetCurrentIteration();
    a->Text = t->GetSettingsText();
  });
  trainer->AddObserver(vtkGaussianFieldTrainer::SettingsChosenEvent, settingsObserver);
  trainer->Update();
  vtkPolyData* field = trainer->GetOutput();
  const vtkIdType n = field->GetNumberOfPoints();
  EXPECT_EQ(n, trainer->GetNumberOfGaussians());
  // The merge (on by default) says what it took: "M pairs merged of N Gaussians ...", N - M = n.
  auto* merge = vtkStringArray::SafeDownCast(field->GetFieldData()->GetAbstractArray("GaussianMerge"));
  ASSERT_NE(merge, nullptr);
  long long merged = -1, before = -1;
  ASSERT_EQ(std::sscanf(merge->GetValue(0).c_str(), "%lld pairs merged of %lld Gaussians", &merged, &before), 2)
    << merge->GetValue(0);
  EXPECT_EQ(before - merged, n);
  EXPECT_GT(before, 400);
  EXPECT_GT(n, 200);
  EXPECT_EQ(field->GetNumberOfVerts(), n) << "one vertex per Gaussian, so it shows as a point cloud";
  for (const char* name : { "Scale", "Rotation", "Reflectivity" })
  {
    ASSERT_NE(field->GetPointData()->GetArray(name), nullptr) << name;
  }
  vtkDataArray* rotation = field->GetPointData()->GetArray("Rotation");
  for (vtkIdType i = 0; i < n; i += 37)
  {
    double q[4];
    rotation->GetTuple(i, q);
    EXPECT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0, 1e-5);
  }
  // ElevationSigma 0 (the default): chosen from the frames, stored and reported with the rule used.
  TrainingData trained = data;
  trained.TrainFrames.clear();
  for (int k = 0; k < data.Count(); ++k)
  {
    if (k % 4 != 2)
    {
      trained.TrainFrames.push_back(k);
    }
  }
  const ElevationSigmaChoice chosen = ChooseElevationSigma(trained);
  // (the filter measures the 8-bit frames inside the estimated fan mask, this the float frames)
  EXPECT_NEAR(field->GetFieldData()->GetArray("ElevationSigma")->GetTuple1(0), chosen.Sigma, 0.01 * chosen.Sigma);
  EXPECT_EQ(announced.Count, 1);
  EXPECT_EQ(announced.IterationThen, 0);
  auto* settings = vtkStringArray::SafeDownCast(field->GetFieldData()->GetAbstractArray("TrainingSettings"));
  ASSERT_NE(settings, nullptr);
  std::string stored;
  for (vtkIdType k = 0; k < settings->GetNumberOfValues(); ++k)
  {
    stored += settings->GetValue(k) + "\n";
  }
  EXPECT_EQ(stored, announced.Text);
  for (const char* line : { "FanMask = estimated from the frames", "ElevationSigma = ", "(chosen: ", "Gamma = ",
         "InitialGaussians = 500 (given", "Iterations = 150", "Densification = every 200 steps" })
  {
    EXPECT_NE(stored.find(line), std::string::npos) << line << " not in\n" << stored;
  }
  vtkDataArray* frames = field->GetFieldData()->GetArray("TrainingFrames");
  ASSERT_NE(frames, nullptr);
  EXPECT_EQ(frames->GetNumberOfTuples(), 45);
  for (vtkIdType k = 0; k < frames->GetNumberOfTuples(); ++k)
  {
    EXPECT_NE(static_cast<int>(frames->GetTuple1(k)) % 4, 2) << "held-out frames are never trained on";
  }
  EXPECT_STREQ(trainer->GetStopReason(), "iterations");
  EXPECT_GT(progressEvents, 5);

  // AbortExecute stops a run early and still leaves a valid field.
  vtkNew<vtkGaussianFieldTrainer> aborted;
  aborted->SetInputData(sequence);
  aborted->SetIterations(100000);
  aborted->SetInitialGaussians(300);
  vtkNew<vtkCallbackCommand> stopper;
  stopper->SetCallback([](vtkObject* caller, unsigned long, void*, void*) {
    static_cast<vtkAlgorithm*>(caller)->SetAbortExecute(1);
  });
  aborted->AddObserver(vtkCommand::ProgressEvent, stopper);
  aborted->Update();
  EXPECT_STREQ(aborted->GetStopReason(), "aborted");
  EXPECT_LT(aborted->GetCompletedIterations(), 100);

  // An explicit frame list with a frame the input does not have fails the request and names the frame.
  vtkNew<vtkGaussianFieldTrainer> listed;
  listed->SetInputData(sequence);
  listed->SetIterations(5);
  vtkNew<vtkIdList> list;
  list->InsertNextId(0);
  list->InsertNextId(data.Count());
  listed->SetTrainingFrameList(list);
  vtkNew<bigus_test::MessageCollector> messages;
  messages->Watch(listed);
  listed->Update();
  EXPECT_EQ(listed->GetOutput()->GetNumberOfPoints(), 0);
  ASSERT_EQ(messages->Errors.size(), 1u);
  EXPECT_NE(messages->Errors[0].find("frame " + std::to_string(data.Count()) + " is outside"), std::string::npos)
    << messages->Errors[0];
}

// A slice downstream of the trainer asks for its own small extent: the reader still reads every frame,
// and the field, being points, does not carry the sequence's WHOLE_EXTENT (the executive copies it by
// default; an image filter after the field that fails its RequestInformation kept it, and ParaView then
// rendered the next valid slice on the sequence's 200 x 150 x 20 grid).
TEST(GaussianFieldTrainer, ASliceDownstreamDoesNotCropTheSequence)
{
  const std::string dir = std::string(BIGUS_TEST_DATA) + "/nwire-phantom/";
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName((dir + "NwirePhantomFreehandCropped.igs.mha").c_str());
  reader->SetCalibrationFileName((dir + "PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml").c_str());
  vtkNew<vtkGaussianFieldTrainer> trainer;
  trainer->SetInputConnection(reader->GetOutputPort());
  trainer->SetIterations(20);
  trainer->SetInitialGaussians(300);
  trainer->SetElevationSigma(0.5);
  trainer->SetHoldOutEvery(4);
  trainer->SetHoldOutOffset(2);
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputConnection(trainer->GetOutputPort());
  reslice->SetOutputSpacing(0.1, 0.1, 1);
  reslice->SetOutputOrigin(0, 0, 0);
  reslice->SetOutputExtent(0, 9, 0, 7, 0, 0);
  reslice->Update();

  int dims[3];
  reader->GetOutput()->GetDimensions(dims);
  EXPECT_EQ(dims[0], 200);
  EXPECT_EQ(dims[1], 150);
  EXPECT_EQ(dims[2], 20);
  vtkDataArray* poses = trainer->GetOutput()->GetFieldData()->GetArray("TrainingPoses");
  ASSERT_NE(poses, nullptr);
  EXPECT_EQ(poses->GetNumberOfTuples(), 15); // 20 frames, k mod 4 == 2 held out
  EXPECT_FALSE(trainer->GetOutputInformation(0)->Has(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT()));
  reslice->GetOutput()->GetDimensions(dims);
  EXPECT_EQ(dims[0], 10);
  EXPECT_EQ(dims[1], 8);
}

TEST(Trainer, VariableProjectionEndsWithALowerTrainingLossThanAdamAloneOnTheSpinePhantom)
{
  // The same seed and the same 300 steps (equal steps, not equal time: a test never depends on the
  // clock; the solves cost extra time, measured in the note), with and without the solve.
  std::vector<int> heldOut;
  const TrainingData data = SpineData(heldOut);
  double loss[2];
  for (int solve = 0; solve < 2; ++solve)
  {
    TrainerSettings s = SpineSettings(300);
    s.ReflectivitySolve = solve == 1;
    Trainer trainer(data, s);
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    EXPECT_EQ(trainer.GetReport().Solves > 0, solve == 1);
    loss[solve] = trainer.GetReport().LastValidationLoss; // the image loss on training frames (every 8th)
  }
  EXPECT_LT(loss[1], loss[0]);
}

// Data this few (the synthetic sweep's 45 training frames of 64 x 64 pixels): one Gaussian per fan pixel of
// the planes a beam width apart fits under MaximumGaussians, so the defaults fit that pixel grid, solve its
// reflectivities and take no geometry step; the held-out frames between the planes match the known
// field's renders to 44.53 dB (measured; Harris seeds and 200 Adam steps 38.19). Up to half the pixel count a
// coarser grid of MaximumGaussians; below it, or with a count given, the run trains from Harris seeds as before.
// The L1 term in the pixel-grid fit (ReflectivitySolveSettings::L1, the relaxed lasso): the FISTA solve sets some
// reflectivities to 0, those Gaussians are removed, and least squares refits the others, ending below the lasso's
// objective (the refit removes its shrinkage); the field is smaller and renders the held-out frames nearly as well.
TEST(Trainer, AnL1TermInThePixelGridFitKeepsFewerGaussiansAndRefitsThem)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.Iterations = 200;
  s.Solve.MaximumIterations = 20;
  Trainer plain(data, s);
  s.Solve.L1 = 0.002;
  Trainer sparse(data, s);
  std::string error;
  for (Trainer* t : { &plain, &sparse })
  {
    ASSERT_TRUE(t->Initialize(&error)) << error;
    ASSERT_TRUE(t->Run(nullptr, nullptr, &error)) << error;
    EXPECT_EQ(t->GetIteration(), 0) << "the pixel-grid fit";
  }
  const TrainerReport& r = sparse.GetReport();
  std::printf("pixel-grid fit: %lld Gaussians, held out %.2f dB; with L1 0.002: %lld removed by the lasso (%d FISTA "
              "iterations, objective %.4g), %lld Gaussians at the end, held out %.2f dB (refit objective %.4g)\n",
    static_cast<long long>(plain.GetField().Count()), HeldOutPsnr(plain, heldOut),
    static_cast<long long>(r.LastL1Removed), r.LastL1Solve.Iterations, r.LastL1Solve.Objective.back(),
    static_cast<long long>(sparse.GetField().Count()), HeldOutPsnr(sparse, heldOut), r.LastSolve.Objective.back());
  EXPECT_GT(r.LastL1Solve.L1Weight, 0);
  EXPECT_EQ(r.LastSolve.L1Weight, 0) << "the refit has no L1 term";
  EXPECT_EQ(r.Solves, 1);
  EXPECT_GT(r.LastL1Removed, 0);
  EXPECT_LT(sparse.GetField().Count(), plain.GetField().Count());
  EXPECT_LT(r.LastSolve.Objective.back(), r.LastL1Solve.Objective.back());
  EXPECT_GT(HeldOutPsnr(sparse, heldOut), HeldOutPsnr(plain, heldOut) - 1.0);
}

TEST(Trainer, WhenOneGaussianPerFanPixelFitsTheDefaultsFitThePixelGridAndTakeNoStep)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  SeedShape shape;
  shape.PixelSpacing = Spacing;
  shape.ElevationSigma = 0.5;
  const GridPlanes planes = SelectGridPlanes(data, shape);
  // The rule from the poses' formula: each training frame whose centre lies at least sigma_E (0.5 mm) from
  // the last kept plane along its normal is kept, the others skipped. The rock tilts frame k by t_k about
  // the x axis: normal (0, -sin t, cos t), centre = origin + 9.45 mm (u + v).
  auto distance = [](int from, int to) {
    const double a = 4.0 * std::sin(0.3 * from) * M_PI / 180.0, b = 4.0 * std::sin(0.3 * to) * M_PI / 180.0;
    const double half = Spacing * 0.5 * (W - 1);
    return -std::sin(a) * half * std::cos(b) + std::cos(a) * (0.2 * (to - from) + half * std::sin(b));
  };
  ASSERT_GE(planes.Frames.size(), 2u);
  ASSERT_EQ(planes.Frames.front(), data.TrainFrames.front());
  std::size_t next = 1;
  int last = planes.Frames.front();
  for (std::size_t t = 1; t < data.TrainFrames.size(); ++t)
  {
    const int f = data.TrainFrames[t];
    if (std::abs(distance(last, f)) >= 0.5)
    {
      ASSERT_LT(next, planes.Frames.size()) << "frame " << f << " is 0.5 mm from plane " << last;
      EXPECT_EQ(planes.Frames[next++], f);
      last = f;
    }
  }
  EXPECT_EQ(next, planes.Frames.size());
  EXPECT_EQ(planes.FanPixels, std::int64_t(planes.Frames.size()) * W * H) << "the mask is every pixel";

  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.Iterations = 200;
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  EXPECT_EQ(trainer.GetReport().InitialGaussians, planes.FanPixels);
  EXPECT_EQ(trainer.GetReport().Solves, 1);
  // No step, so nothing to refine the poses with, whatever the default (Auto) chose for this sweep.
  EXPECT_EQ(trainer.GetSettings().Poses.RefinePoses, PoseRefinement::Off);
  EXPECT_FALSE(trainer.GetPoseRefiner().IsSweepRefined(0));
  EXPECT_EQ(std::count_if(trainer.GetReport().Settings.begin(), trainer.GetReport().Settings.end(),
              [](const std::string& line) { return line.rfind("RefinePoses = off (", 0) == 0; }),
    1);
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  EXPECT_EQ(trainer.GetIteration(), 0);
  EXPECT_TRUE(trainer.GetReport().PoseCorrections.empty());
  EXPECT_EQ(trainer.GetData().Poses, data.Poses);
  EXPECT_NE(trainer.GetReport().StopReason.find("pixel-grid fit"), std::string::npos) << trainer.GetReport().StopReason;
  const double grid = HeldOutPsnr(trainer, heldOut);
  EXPECT_GT(grid, 43.0) << "held-out frames between the planes";

  // Up to twice as many fan pixels as MaximumGaussians: a coarser grid of at most that many, no step either.
  s.MaximumGaussians = planes.FanPixels / 2 + 1;
  Trainer coarse(data, s);
  ASSERT_TRUE(coarse.Initialize(&error)) << error;
  EXPECT_LE(coarse.GetReport().InitialGaussians, s.MaximumGaussians);
  EXPECT_GT(coarse.GetReport().InitialGaussians, s.MaximumGaussians * 9 / 10)
    << "short of it by less than a row and a column";
  ASSERT_TRUE(coarse.Run(nullptr, nullptr, &error)) << error;
  EXPECT_EQ(coarse.GetIteration(), 0);
  // One Gaussian fewer allowed than half the fan pixels: Harris seeds and Adam.
  s.MaximumGaussians = planes.FanPixels / 2 - 1;
  Trainer seeded(data, s);
  ASSERT_TRUE(seeded.Initialize(&error)) << error;
  EXPECT_LT(seeded.GetReport().InitialGaussians, planes.FanPixels);
  EXPECT_EQ(seeded.GetReport().Solves, 0);
  ASSERT_TRUE(seeded.Run(nullptr, nullptr, &error)) << error;
  EXPECT_EQ(seeded.GetIteration(), 200);
  std::printf("held-out PSNR: pixel-grid fit %.2f dB (%lld Gaussians), Harris seeds and 200 Adam steps %.2f dB\n", grid,
    static_cast<long long>(trainer.GetField().Count()), HeldOutPsnr(seeded, heldOut));
  // A count given, or the switch off: no pixel-grid fit either.
  s.MaximumGaussians = TrainerSettings().MaximumGaussians;
  s.Iterations = 5;
  for (int variant = 0; variant < 2; ++variant)
  {
    TrainerSettings v = s;
    if (variant == 0)
    {
      v.InitialGaussians = 1000;
    }
    else
    {
      v.PixelGridFit = false;
    }
    Trainer other(data, v);
    ASSERT_TRUE(other.Initialize(&error)) << error;
    ASSERT_TRUE(other.Run(nullptr, nullptr, &error)) << error;
    EXPECT_EQ(other.GetIteration(), 5) << "variant " << variant;
  }
}

TEST(Trainer, ResidualSeedsLieWhereTheResidualIsAndCarryIt)
{
  std::vector<int> heldOut;
  TrainingData data = SyntheticSweep(KnownField(50, 9), 0.5, heldOut);
  data.Mask[5 * W + 60] = 0; // a pixel outside the fan
  const int frame = data.TrainFrames[3];
  std::vector<float> residual(W * H, 0.f);
  SeedShape shape;
  shape.InPlaneScale = 0.45;
  shape.ElevationScale = 0.5;
  GaussianField field = KnownField(10, 1); // seeds are appended to what is there
  std::mt19937_64 rng(4);
  EXPECT_EQ(SeedResidual(data, frame, residual.data(), 100, rng, shape, field), 0) << "no residual, no seed";
  EXPECT_EQ(field.Count(), 10);
  residual[20 * W + 10] = 0.6f;  // pixel (i, j) = (10, 20)
  residual[40 * W + 30] = -0.2f; // (30, 40)
  residual[5 * W + 60] = 50.f;   // outside the mask: never seeded
  ASSERT_EQ(SeedResidual(data, frame, residual.data(), 1000, rng, shape, field), 1000);
  ASSERT_EQ(field.Count(), 1010);
  const std::array<double, 16>& m = data.Poses[frame];
  int positive = 0;
  for (std::int64_t i = 10; i < field.Count(); ++i)
  {
    const float r = field.Reflectivities[i];
    ASSERT_TRUE(r == 0.6f || r == -0.2f) << "seed " << i << ": r " << r;
    const double pi = r > 0 ? 10 : 30, pj = r > 0 ? 20 : 40;
    for (int k = 0; k < 3; ++k)
    {
      EXPECT_NEAR(field.Means[3 * i + k], m[4 * k] * pi + m[4 * k + 1] * pj + m[4 * k + 3], 1e-4) << "seed " << i;
    }
    EXPECT_NEAR(std::exp(field.LogScales[3 * i]), 0.45, 1e-6);
    EXPECT_NEAR(std::exp(field.LogScales[3 * i + 2]), 0.5, 1e-6);
    positive += r > 0 ? 1 : 0;
  }
  // Drawn in proportion to |residual|: 750 of the 1000 expected (binomial standard deviation 14).
  EXPECT_NEAR(positive, 750, 70);
}

// Through the trainer (ResidualSeedShare > 0): a densification adds, after what it splits and clones, new
// Gaussians on training frames' planes carrying the residual as their reflectivity, where the same run
// without adds none; the run goes on from them.
TEST(Trainer, ADensificationAddsResidualSeedsOnTrainingFrames)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.Iterations = 100; // the one densification (DensifyStart 100) ends the first call of Train
  std::int64_t counts[2] = { 0, 0 };
  GaussianField fields[2];
  std::string error;
  for (int k = 0; k < 2; ++k)
  {
    TrainerSettings v = s;
    v.ResidualSeedShare = k == 0 ? 0.0 : 0.5;
    v.ResidualSeedFrames = 2;
    Trainer trainer(data, v);
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Train(nullptr, nullptr, &error)) << error;
    ASSERT_EQ(trainer.GetIteration(), 100);
    fields[k] = trainer.GetField();
    counts[k] = fields[k].Count();
    if (k == 1)
    {
      // It trains on from the seeds.
      for (int step = 0; step < 50; ++step)
      {
        double loss = 0;
        ASSERT_EQ(trainer.Step(&loss, &error), StepStatus::Done) << error;
        EXPECT_TRUE(std::isfinite(loss));
      }
      EXPECT_TRUE(AllFinite(trainer.GetField()));
    }
  }
  const std::int64_t seeds = counts[1] - counts[0];
  std::printf("after the densification: %lld Gaussians without residual seeds, %lld with\n",
    static_cast<long long>(counts[0]), static_cast<long long>(counts[1]));
  ASSERT_GT(seeds, 0) << "the densification added no residual seed";
  EXPECT_LT(seeds, counts[0]) << "half of those split or cloned, at most";
  // The seeds are the last Gaussians: each lies on the plane of a training frame, inside its image, with a
  // non-zero reflectivity.
  const GaussianField& f = fields[1];
  for (std::int64_t i = counts[0]; i < counts[1]; ++i)
  {
    bool onAFrame = false;
    for (int t : data.TrainFrames)
    {
      const std::array<double, 16>& m = data.Poses[t];
      // Solve mean = m (pi, pj, 0, 1) for the pixel position in the frame's plane and its distance from it.
      double u[3], v[3], d[3];
      for (int r = 0; r < 3; ++r)
      {
        u[r] = m[4 * r];
        v[r] = m[4 * r + 1];
        d[r] = f.Means[3 * i + r] - m[4 * r + 3];
      }
      const double n[3] = { u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0] };
      const double nn = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      const double off = std::abs(n[0] * d[0] + n[1] * d[1] + n[2] * d[2]) / nn;
      const double uu = u[0] * u[0] + u[1] * u[1] + u[2] * u[2], vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
      const double pi = (u[0] * d[0] + u[1] * d[1] + u[2] * d[2]) / uu;
      const double pj = (v[0] * d[0] + v[1] * d[1] + v[2] * d[2]) / vv;
      onAFrame = onAFrame ||
        (off < 1e-3 && pi > -0.5 && pi < data.Width - 0.5 && pj > -0.5 && pj < data.Height - 0.5);
    }
    EXPECT_TRUE(onAFrame) << "seed " << i << " lies on no training frame";
    EXPECT_NE(f.Reflectivities[i], 0.f) << "seed " << i;
  }
}

TEST(Trainer, ADenseStartKeepsToItsCountAndSolvesTheReflectivities)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.DenseInitialisation = true;
  s.ReflectivitySolve = true;
  s.InitialGaussians = 6000;
  s.MaximumGaussians = 20000;
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  EXPECT_LE(trainer.GetField().Count(), 6000);
  // The real-valued stride lands within a row and a column of the grid (here about 20 x 20 per plane).
  EXPECT_GE(trainer.GetField().Count(), 5400);
  EXPECT_EQ(trainer.GetReport().Solves, 1);
  const std::vector<double>& objective = trainer.GetReport().LastSolve.Objective;
  ASSERT_GE(objective.size(), 2u);
  EXPECT_LT(objective.back(), 0.1 * objective.front()) << "the solve fits the frames from the seeds' guess";
  ImageMetrics m;
  ASSERT_TRUE(trainer.Evaluate(data.TrainFrames, m, &error)) << error;
  EXPECT_GT(m.PSNR, 35.0) << "training frames right after the dense start";
  EXPECT_FALSE(trainer.GetReport().LastSolve.TimeLimitReached) << "no TimeBudget, no limit";

  // With a TimeBudget the solve keeps to a share of it: a budget spent at once leaves it one iteration.
  TrainerSettings budgeted = s;
  budgeted.TimeBudget = 1e-6;
  Trainer hurried(data, budgeted);
  ASSERT_TRUE(hurried.Initialize(&error)) << error;
  EXPECT_TRUE(hurried.GetReport().LastSolve.TimeLimitReached);
  EXPECT_EQ(hurried.GetReport().LastSolve.Iterations, 1);
  EXPECT_GT(trainer.GetReport().LastSolve.Iterations, 1);

  // More seeds than the maximum is refused before any is made.
  s.InitialGaussians = 30000;
  Trainer refused(data, s);
  EXPECT_FALSE(refused.Initialize(&error));
  EXPECT_NE(error.find("InitialGaussians (30000) exceeds MaximumGaussians (20000)"), std::string::npos) << error;
  EXPECT_EQ(refused.GetField().Count(), 0);

  // A maximum whose training state cannot fit in this machine's memory is refused before any seed is made,
  // with what it needs: 10^12 Gaussians of TrainingBytesPerGaussian and the solve's 52 bytes each.
  s.InitialGaussians = 6000;
  s.MaximumGaussians = 1000000000000LL;
  Trainer tooLarge(data, s);
  EXPECT_FALSE(tooLarge.Initialize(&error));
  const double megabytes = 1e12 * (TrainingBytesPerGaussian + 52) / 1e6 +
    double(data.Width) * data.Height * data.TrainFrames.size() * 8 / 1e6;
  EXPECT_NE(error.find("MaximumGaussians (1000000000000) needs " + std::to_string(std::llround(megabytes)) + " MB"),
    std::string::npos) << error;
  EXPECT_NE(error.find("and this machine has"), std::string::npos) << error;
  EXPECT_EQ(tooLarge.GetField().Count(), 0);
}

// Pose refinement on synthetic truth: the known field rendered at the true poses, the training frames'
// poses then moved by a random rigid motion of 0.5 degrees and 0.5 mm each (about the frame's centre, in
// its own axes). Training with RefinePoses brings the poses back towards the truth: the mean distance of
// the frames' corners from where they truly lie falls by more than half (the error a tracker would leave
// in a volume), and the held-out frames (at their true poses, never refined) come out better.
TEST(Trainer, HeldOutPosesRefinedWithTheFieldFrozenComeBackToTheTruth)
{
  // The fair score of held-out frames: the known field that rendered the sweep, frozen; each held-out frame's
  // pose moved by 0.5 degrees and 0.5 mm at random, then refined against its recorded frame. The poses come back
  // towards the ones that rendered the frames (the truth), and the frames rendered at them match better.
  const GaussianField field = KnownField(200, 7);
  std::vector<int> heldOut;
  const TrainingData truth = SyntheticSweep(field, 0.5, heldOut);
  TrainingData data = PerturbedPoses(truth, heldOut, 0.5, 0.5, 5, W, H);
  RenderOptions options;
  options.ElevationSigma = 0.5;
  options.Gamma = 1.0;
  auto psnrAt = [&](const TrainingData& d) {
    auto renderer = CreateCpuRenderer();
    std::vector<float> S(W * H), I(W * H);
    double total = 0;
    for (int f : heldOut)
    {
      const SliceGeometry g = d.Slice(f);
      EXPECT_TRUE(renderer->Forward(field.View(), &g, 1, options, S.data(), I.data(), nullptr, nullptr));
      total += Psnr(I.data(), &truth.Frames[std::size_t(W) * H * f], W * H);
    }
    return total / heldOut.size();
  };
  const double before = CornerError(data, truth, heldOut, W, H), psnrBefore = psnrAt(data);
  TrainerSettings s;
  std::vector<std::array<double, 6>> corrections;
  std::string error;
  ASSERT_TRUE(RefinePosesWithFieldFrozen(field, data, heldOut, options, s.Poses, s.Loss, 100, "cpu", corrections, &error))
    << error;
  ASSERT_EQ(corrections.size(), heldOut.size());
  const double after = CornerError(data, truth, heldOut, W, H), psnrAfter = psnrAt(data);
  std::printf("held-out poses refined with the field frozen (100 steps): corner error %.3f -> %.3f mm, PSNR %.2f -> "
              "%.2f dB\n", before, after, psnrBefore, psnrAfter);
  EXPECT_LT(after, 0.5 * before);
  EXPECT_GT(psnrAfter, psnrBefore + 3.0);
  for (int f : truth.TrainFrames)
  {
    EXPECT_EQ(data.Poses[f], truth.Poses[f]) << "a frame not listed keeps its pose";
  }
}

TEST(Trainer, RefiningPosesBringsPerturbedTrainingPosesTowardsTheTruth)
{
  std::vector<int> heldOut;
  TrainingData truth = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  const TrainingData perturbed = PerturbedPoses(truth, truth.TrainFrames, 0.5, 0.5, 21, W, H);
  const double before = CornerError(perturbed, truth, truth.TrainFrames, W, H);
  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.PixelGridFit = false;
  s.InitialGaussians = 3000;
  s.Iterations = 1500;
  s.Poses.RefinePoses = PoseRefinement::On;
  Trainer trainer(perturbed, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const double after = CornerError(trainer.GetData(), truth, truth.TrainFrames, W, H);
  s.Poses.RefinePoses = PoseRefinement::Off;
  Trainer trusting(perturbed, s);
  ASSERT_TRUE(trusting.Initialize(&error)) << error;
  ASSERT_TRUE(trusting.Run(nullptr, nullptr, &error)) << error;
  Trainer onTruth(truth, s);
  ASSERT_TRUE(onTruth.Initialize(&error)) << error;
  ASSERT_TRUE(onTruth.Run(nullptr, nullptr, &error)) << error;
  std::printf("corner error: %.3f mm tracked, %.3f mm refined; held-out PSNR %.2f dB refined, %.2f dB trusting the "
              "tracked poses, %.2f dB on the true poses\n", before, after, HeldOutPsnr(trainer, heldOut),
    HeldOutPsnr(trusting, heldOut), HeldOutPsnr(onTruth, heldOut));
  ASSERT_EQ(trainer.GetReport().PoseCorrections.size(), truth.TrainFrames.size());
  // Measured: 0.505 -> 0.187 mm; held-out 38.80 dB refined, 34.89 trusting the tracked poses, 52.25 on the
  // true poses (scored at the true poses the aim of 0.5 dB from the true poses is far; fairly, below).
  EXPECT_LT(after, 0.5 * before) << "the pose error falls by at least half";
  EXPECT_GT(HeldOutPsnr(trainer, heldOut), HeldOutPsnr(trusting, heldOut) + 2.0);
  // The fair score: a field trained on refined poses lives in the sweep's refined frame, which one sweep fixes
  // only up to a motion of the whole sweep (and smooth warps along it), so its held-out frames are scored at
  // their true poses refined with the field frozen, as view-synthesis papers score test views.
  const double aligned = AlignedCornerError(trainer.GetData(), truth, truth.TrainFrames, W, H);
  const double fairRefined = FairPsnr(trainer.GetField(), trainer.Options(), truth, heldOut, s);
  const double fairTrusting = FairPsnr(trusting.GetField(), trusting.Options(), truth, heldOut, s);
  const double fairTruth = FairPsnr(onTruth.GetField(), onTruth.Options(), truth, heldOut, s);
  std::printf("aligned corner error %.3f mm; fair held-out PSNR %.2f dB refined, %.2f trusting, %.2f on the true "
              "poses\n", aligned, fairRefined, fairTrusting, fairTruth);
  // Measured: 0.161 mm; 48.00, 38.49, 52.44 dB (4,000 steps: 0.109 mm; 53.49 against 54.81).
  EXPECT_LT(aligned, 0.4 * before);
  EXPECT_GT(fairRefined, fairTrusting + 5.0);

  // The smoothness prior: the corrections of consecutive training frames differ less.
  auto roughness = [](const TrainerReport& report) {
    double sum = 0;
    for (std::size_t k = 1; k < report.PoseCorrections.size(); ++k)
    {
      for (int c = 0; c < 6; ++c)
      {
        const double d = report.PoseCorrections[k].Xi[c] - report.PoseCorrections[k - 1].Xi[c];
        sum += d * d * (c < 3 ? 1.0 / (0.0175 * 0.0175) : 1.0); // per degree-sized and mm-sized unit
      }
    }
    return std::sqrt(sum / (report.PoseCorrections.size() - 1));
  };
  s.Poses.RefinePoses = PoseRefinement::On;
  s.Poses.Smoothness = 10;
  Trainer smooth(perturbed, s);
  ASSERT_TRUE(smooth.Initialize(&error)) << error;
  ASSERT_TRUE(smooth.Train(nullptr, nullptr, &error)) << error;
  // Scored before Finish (bigus train --evaluate-every), the held-out frames are already placed among their
  // refined neighbours (Trainer::PlaceUntrainedFrames), as Finish places them.
  EXPECT_EQ(CornerError(smooth.GetData(), truth, heldOut, W, H), 0);
  ImageMetrics midRun;
  ASSERT_TRUE(smooth.Evaluate(heldOut, midRun, &error)) << error;
  EXPECT_GT(CornerError(smooth.GetData(), truth, heldOut, W, H), 0);
  EXPECT_EQ(smooth.GetReport().UntrainedCorrections.Frames, static_cast<int>(heldOut.size()));
  ASSERT_TRUE(smooth.Finish(&error)) << error;
  std::printf("roughness of the corrections along the sweep: %.4f without the smoothness prior, %.4f with\n",
    roughness(trainer.GetReport()), roughness(smooth.GetReport()));
  EXPECT_LT(roughness(smooth.GetReport()), 0.5 * roughness(trainer.GetReport()));
  // The held-out frames (at their true poses here): the training frames' corrections, independent from frame to
  // frame, predict none of them, so they stay (bigus::CorrectUntrainedFrames); the smoothed ones do, and move them
  // by little (measured: 0.049 mm at the corners, held out 34.97 dB at the moved poses, 34.87 at the true ones).
  EXPECT_EQ(trainer.GetReport().UntrainedCorrections.Bandwidth, 0);
  EXPECT_EQ(CornerError(trainer.GetData(), truth, heldOut, W, H), 0);
  EXPECT_GT(smooth.GetReport().UntrainedCorrections.Bandwidth, 0);
  EXPECT_EQ(smooth.GetReport().UntrainedCorrections.Frames, static_cast<int>(heldOut.size()));
}
