// The densification stage (bigusDensification.h): growth control (UpdateGrowth) on known sequences of validation
// losses, a Gaussian cloned or split, the compaction of the state that pruning does, growth stopped through the
// trainer, and residual seeds (bigus::SeedResidual), alone and in a densification.
#include "bigusDensification.h"
#include "bigusSeeding.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

using namespace bigus;
using namespace bigus::synthetic;

// Growth control (UpdateGrowth) on sequences of validation losses, one call per densification at iterations 100,
// 200, ..., with a margin of 10 % and a patience of 3: the truth is the rule counted by hand.
TEST(Densification, GrowthStopsAtTheCallThatCompletesThePatienceAndNamesItsIteration)
{
  // The first loss is the best (there is none before it); the next three are worse (1.2) or better by less than
  // 10 % (0.95, 0.91), so the fourth call, at iteration 400, stops growth; later calls, however good their loss,
  // change nothing.
  DensificationSettings s;
  s.GrowthMargin = 0.1;
  s.GrowthPatience = 3;
  TrainingState state;
  const double losses[6] = { 1.0, 1.2, 0.95, 0.91, 0.5, 0.4 };
  const int stalled[6] = { 0, 1, 2, 3, 3, 3 };
  for (int call = 0; call < 6; ++call)
  {
    state.Iteration = 100 * (call + 1);
    const std::string reason = UpdateGrowth(state, losses[call], s);
    if (call == 3)
    {
      EXPECT_NE(reason.find("over 3 densification intervals (iteration 400)"), std::string::npos) << reason;
      EXPECT_NE(reason.find("less than 10 %"), std::string::npos) << reason;
    }
    else
    {
      EXPECT_EQ(reason, "") << "call " << call;
    }
    EXPECT_EQ(state.Growing, call < 3) << "call " << call;
    EXPECT_EQ(state.BestValidationLoss, 1.0) << "call " << call;
    EXPECT_EQ(state.StalledGrowthSteps, stalled[call]) << "call " << call;
  }
}

TEST(Densification, ALossBetterThanTheBestByMoreThanTheMarginRestartsThePatience)
{
  // 0.85 is below the best (1.0) by more than 10 %: it becomes the best and the count of stalled intervals starts
  // again, so growth stops at the third interval after it (iteration 700), not at the fourth call.
  DensificationSettings s;
  s.GrowthMargin = 0.1;
  s.GrowthPatience = 3;
  TrainingState state;
  const double losses[7] = { 1.0, 0.95, 0.93, 0.85, 0.80, 0.79, 0.78 };
  const double best[7] = { 1.0, 1.0, 1.0, 0.85, 0.85, 0.85, 0.85 };
  const int stalled[7] = { 0, 1, 2, 0, 1, 2, 3 };
  for (int call = 0; call < 7; ++call)
  {
    state.Iteration = 100 * (call + 1);
    const std::string reason = UpdateGrowth(state, losses[call], s);
    EXPECT_EQ(state.BestValidationLoss, best[call]) << "call " << call;
    EXPECT_EQ(state.StalledGrowthSteps, stalled[call]) << "call " << call;
    EXPECT_EQ(state.Growing, call < 6) << "call " << call;
    if (call == 6)
    {
      EXPECT_NE(reason.find("over 3 densification intervals (iteration 700)"), std::string::npos) << reason;
    }
    else
    {
      EXPECT_EQ(reason, "") << "call " << call;
    }
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
    s.Densification.End = 800;
    s.Densification.GrowthMargin = 0.999;
    s.Densification.GrowthPatience = patience;
    Trainer trainer(data, s);
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    const TrainerReport& r = trainer.GetReport();
    const int stop = s.Densification.Start + patience * s.Densification.Interval;
    EXPECT_NE(r.GrowthStopReason.find("over " + std::to_string(patience) + " densification intervals (iteration " +
                std::to_string(stop) + ")"),
      std::string::npos)
      << r.GrowthStopReason;
    // One record per interval (measured before that interval's densification) and Finish's.
    const auto& h = r.ValidationHistory;
    ASSERT_EQ(h.size(), std::size_t(s.Iterations / s.Densification.Interval + 1));
    double best = h[0].Loss;
    for (std::size_t k = 0; k < h.size(); ++k)
    {
      EXPECT_EQ(h[k].Iteration, k + 1 < h.size() ? int(k + 1) * s.Densification.Interval : r.Iterations);
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
    v.Densification.ResidualSeedShare = k == 0 ? 0.0 : 0.5;
    v.Densification.ResidualSeedFrames = 2;
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
      onAFrame = onAFrame || (off < 1e-3 && pi > -0.5 && pi < data.Width - 0.5 && pj > -0.5 && pj < data.Height - 0.5);
    }
    EXPECT_TRUE(onAFrame) << "seed " << i << " lies on no training frame";
    EXPECT_NE(f.Reflectivities[i], 0.f) << "seed " << i;
  }
}

// The final prune's bound holds for everything it removes together: 50 Gaussians on one spot and 15 apart, each
// changing any pixel by at most half the tolerance alone (|r| = tolerance / 2, amp <= 1, gamma 1). Removing them all,
// as a bound per Gaussian would, changes the spot by about 25 tolerances; the prune removes the 15 apart and keeps
// what would exceed it. The truth is the render: no training pixel moves by more than the tolerance.
TEST(Densification, TheFinalPrunesBoundHoldsForWhatItRemovesTogether)
{
  TrainingData data;
  data.Width = W;
  data.Height = H;
  data.Mask.assign(std::size_t(W) * H, 1);
  for (int k = 0; k < 10; ++k)
  {
    data.Poses.push_back(SweepPose(k));
    data.TrainFrames.push_back(k);
  }
  data.Frames.assign(std::size_t(W) * H * data.Poses.size(), 0.f);
  const double tolerance = 1.0 / 512;
  GaussianField field;
  auto add = [&](double i, double j, double scale, double r) {
    const std::array<double, 16>& m = data.Poses[5]; // on frame 5's plane, at pixel (i, j)
    for (int a = 0; a < 3; ++a)
    {
      field.Means.push_back(static_cast<float>(m[4 * a] * i + m[4 * a + 1] * j + m[4 * a + 3]));
      field.LogScales.push_back(static_cast<float>(std::log(scale)));
    }
    field.Quaternions.insert(field.Quaternions.end(), { 1.f, 0.f, 0.f, 0.f });
    field.Reflectivities.push_back(static_cast<float>(r));
  };
  for (int k = 0; k < 50; ++k)
  {
    add(20, 20, 0.3, 0.5 * tolerance);
  }
  for (int a = 0; a < 5; ++a)
  {
    for (int b = 0; b < 3; ++b)
    {
      add(8 + 10 * a, 36 + 10 * b, 0.3, 0.5 * tolerance);
    }
  }
  add(32, 10, 1.0, 0.5); // a Gaussian no prune removes
  RenderOptions o;
  o.ElevationSigma = 0.5;
  o.Gamma = 1.0;
  auto render = [&](const GaussianField& f) {
    std::vector<float> I(data.Frames.size()), S(std::size_t(W) * H);
    auto renderer = CreateCpuRenderer();
    for (int k = 0; k < data.Count(); ++k)
    {
      const SliceGeometry g = data.Slice(k);
      EXPECT_TRUE(renderer->Forward(f.View(), &g, 1, o, S.data(), I.data() + std::size_t(W) * H * k, nullptr, nullptr));
    }
    return I;
  };
  const std::vector<float> before = render(field);
  OptimizerState G;
  G.Field = field;
  G.ResizeToField();
  const std::int64_t removed = FinalPrune(G, data, o, o.Gamma, tolerance);
  const std::vector<float> after = render(G.Field);
  double largest = 0;
  for (std::size_t p = 0; p < before.size(); ++p)
  {
    largest = std::max(largest, std::abs(double(after[p]) - before[p]));
  }
  std::printf("removed %lld of %lld; largest change of a training pixel %.3g (tolerance %.3g)\n",
    static_cast<long long>(removed), static_cast<long long>(field.Count()), largest, tolerance);
  EXPECT_LE(largest, tolerance * (1 + 1e-3));
  EXPECT_GE(removed, 15); // the Gaussians apart are removed ...
  EXPECT_LT(removed, 50); // ... and not the whole spot
  EXPECT_EQ(G.Field.Count(), field.Count() - removed);
}

// A caller that stops a run mid-schedule to score it (bigus benchmark's marks) waits for Trainer::IsSettled: after a
// densification that split or cloned, the step before the next densification, not the dip after one, where the
// field's split Gaussians have not yet recovered their fit; before the first densification, and from the step before
// where the next would come once the window has closed, every step.
TEST(Trainer, AStopThatWaitsForTheFieldToSettleEndsBeforeADensificationNotInItsDip)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.Iterations = 500;
  s.Densification.Start = 100;
  s.Densification.Interval = 100;
  s.Densification.End = 300;
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  auto psnr = [&]() {
    ImageMetrics metrics;
    EXPECT_TRUE(trainer.EvaluateOn(trainer.GetData(), trainer.GetData().TrainFrames, metrics, &error)) << error;
    return metrics.PSNR;
  };
  auto trainUntil = [&](int from, bool settled) {
    ASSERT_TRUE(trainer.Train(
      nullptr, [&]() { return trainer.GetIteration() >= from && (!settled || trainer.IsSettled()); }, &error))
      << error;
  };
  trainUntil(50, true);
  EXPECT_EQ(trainer.GetIteration(), 50) << "no densification yet: settled";
  trainUntil(100, true);
  EXPECT_EQ(trainer.GetIteration(), 199) << "the step before the densification of step 200";
  const double before = psnr();
  trainUntil(200, false);
  ASSERT_EQ(trainer.GetIteration(), 200);
  EXPECT_FALSE(trainer.IsSettled());
  const double after = psnr();
  trainUntil(200, true);
  EXPECT_EQ(trainer.GetIteration(), 299);
  const double recovered = psnr();
  std::printf("training frames: %.2f dB at step 199, %.2f right after the densification of step 200, %.2f at 299\n",
    before, after, recovered);
  EXPECT_LT(after, before - 1) << "the densification's dip, which the settled stops skip";
  EXPECT_GT(recovered, after + 1);
  trainUntil(305, true);
  EXPECT_EQ(trainer.GetIteration(), 399) << "the window's last densification, at step 300, split too";
  trainUntil(420, true);
  EXPECT_EQ(trainer.GetIteration(), 420) << "no densification since: settled";

  // A densification that only prunes (no room under the maximum) makes no dip: settled at every step.
  TrainerSettings full = s;
  full.MaximumGaussians = s.Seeding.InitialGaussians;
  Trainer capped(data, full);
  ASSERT_TRUE(capped.Initialize(&error)) << error;
  ASSERT_TRUE(capped.Train(
    nullptr, [&]() { return capped.GetIteration() >= 150 && capped.IsSettled(); }, &error))
    << error;
  EXPECT_EQ(capped.GetIteration(), 150);
  EXPECT_LE(capped.GetField().Count(), full.MaximumGaussians);
}
