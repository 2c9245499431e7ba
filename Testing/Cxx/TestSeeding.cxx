// The seeding stage (bigusSeeding.h): the plan (PlanSeeding) against its documented rules on a small synthetic
// sweep, and through the trainer the pixel-grid fit (with and without its L1 term) and the dense start.
#include "bigusSeeding.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

using namespace bigus;
using namespace bigus::synthetic;

namespace
{
/// @p count parallel frames of @p width x @p height pixels (0.3 mm) 1 mm apart along z, every one a training frame,
/// with a shared fan mask of their first @p columns columns: the dense start's planes (each at least sigma_E, 0.5 mm,
/// from the last one kept) are all the frames, and they hold count x columns x height fan pixels.
TrainingData ParallelFrames(int count, int width, int height, int columns)
{
  TrainingData d;
  d.Width = width;
  d.Height = height;
  d.Frames.assign(std::size_t(count) * width * height, 0.5f);
  d.Mask.assign(std::size_t(width) * height, 0);
  for (int j = 0; j < height; ++j)
  {
    std::fill_n(d.Mask.begin() + std::size_t(j) * width, columns, 1);
  }
  for (int k = 0; k < count; ++k)
  {
    d.Poses.push_back({ Spacing, 0, 0, 0.0, 0, Spacing, 0, 0.0, 0, 0, 0, 1.0 * k, 0, 0, 0, 1 });
    d.TrainFrames.push_back(k);
  }
  return d;
}

/// The seeds' shape for ParallelFrames: 0.3 mm pixels, sigma_E 0.5 mm.
SeedShape ParallelShape()
{
  SeedShape shape;
  shape.PixelSpacing = Spacing;
  shape.ElevationSigma = 0.5;
  return shape;
}
}

// PlanSeeding with the default settings on 12 frames of 48 x 64 fan pixels each, 36,864 in all: up to twice
// MaximumGaussians of them the plan is the pixel grid of every fan pixel (its count is set by memory, which holds
// these easily, not by the maximum); one Gaussian fewer allowed and the plan is Harris seeds (half the maximum here).
TEST(Seeding, FanPixelsUpToTwiceMaximumGaussiansGiveThePixelGrid)
{
  const TrainingData data = ParallelFrames(12, W, H, 48);
  const std::int64_t fanPixels = 12 * 48 * H;
  ASSERT_EQ(fanPixels, 36864);
  const SeedingSettings settings;
  // MaximumGaussians, then the grid's count.
  const std::int64_t cases[4][2] = { { 1000000, 36864 }, { 36864, 36864 }, { 20000, 36864 }, { 18432, 36864 } };
  for (const auto& c : cases)
  {
    SeedingPlan plan;
    std::string error;
    ASSERT_TRUE(PlanSeeding(data, settings, c[0], false, false, ParallelShape(), fanPixels, plan, &error)) << error;
    EXPECT_TRUE(plan.PixelGrid) << "MaximumGaussians " << c[0];
    EXPECT_EQ(plan.Count, c[1]) << "MaximumGaussians " << c[0];
    EXPECT_EQ(plan.Planes.Frames, data.TrainFrames) << "frames 1 mm apart, sigma_E 0.5 mm: every one a plane";
    EXPECT_EQ(plan.Planes.FanPixels, fanPixels);
    EXPECT_EQ(plan.FanPixels, fanPixels);
  }
  SeedingPlan plan;
  std::string error;
  ASSERT_TRUE(PlanSeeding(data, settings, 18431, false, false, ParallelShape(), fanPixels, plan, &error)) << error;
  EXPECT_FALSE(plan.PixelGrid);
  EXPECT_EQ(plan.Count, 18431 / 2) << "at most half the maximum (one per 200 fan pixels would be 184)";
  // Non-negative reflectivities: never the pixel grid.
  ASSERT_TRUE(PlanSeeding(data, settings, 1000000, true, false, ParallelShape(), fanPixels, plan, &error)) << error;
  EXPECT_FALSE(plan.PixelGrid);
  EXPECT_EQ(plan.Count, 20000);
}

// The count of Harris seeds when none is given (SeedingSettings::InitialGaussians 0): one per 200 fan pixels of the
// training frames, at least min(20,000, MaximumGaussians / 2), at most MaximumGaussians / 2. Frames of 512 x 512
// pixels, every one in the fan, always more than twice MaximumGaussians of them: Harris seeds.
// The dense start's planes each take their own spacing, the larger of the gaps to the planes beside them: 12
// parallel frames 1 mm apart with frame 5 left out give the planes beside the gap (4 and 6) a 2 mm spacing, the
// others 1 mm, and the grid's Gaussians elevation scales of 0.45 times that.
TEST(Seeding, TheGridsPlanesBesideAWiderGapTakeItsWidthAsTheirSpacing)
{
  TrainingData data = ParallelFrames(12, W, H, 48);
  data.TrainFrames.erase(data.TrainFrames.begin() + 5);
  const GridPlanes planes = SelectGridPlanes(data, ParallelShape());
  ASSERT_EQ(planes.Frames, data.TrainFrames);
  ASSERT_EQ(planes.PlaneSpacing.size(), planes.Frames.size());
  ASSERT_EQ(planes.Spacing.size(), 1u);
  EXPECT_NEAR(planes.Spacing[0], 11.0 / 10.0, 1e-9) << "the sweep's mean: 11 mm over 10 gaps";
  for (std::size_t k = 0; k < planes.Frames.size(); ++k)
  {
    const int f = planes.Frames[k];
    EXPECT_NEAR(planes.PlaneSpacing[k], f == 4 || f == 6 ? 2.0 : 1.0, 1e-9) << "frame " << f;
  }
  GaussianField field;
  SeedGrid(data, planes, planes.FanPixels, ParallelShape(), field);
  ASSERT_EQ(field.Count(), planes.FanPixels) << "every fan pixel";
  for (std::int64_t g = 0; g < field.Count(); ++g)
  {
    const int f = static_cast<int>(std::lround(field.Means[3 * g + 2])); // plane k lies at z = k mm
    ASSERT_NEAR(std::exp(field.LogScales[3 * g + 2]), 0.45 * (f == 4 || f == 6 ? 2.0 : 1.0), 1e-5) << "plane " << f;
  }
}

// Where the plane beside it is tilted (a rocking probe), the gap at a grid point is its distance to that plane, which
// runs across the frame: plane 1 of three parallel frames 1 mm apart is turned 10 degrees about the x axis through
// its centre, so a Gaussian of plane 0 at row height y (mm) lies |sin t (y - c) + cos t| from it (c the centre's
// height), and takes 0.45 times that where it is wider than the 1 mm between the centres.
TEST(Seeding, AGridPointsElevationScaleFollowsItsDistanceToATiltedPlaneBesideIt)
{
  TrainingData data = ParallelFrames(3, W, H, 48);
  const double t = 10.0 * M_PI / 180.0, c = Spacing * 0.5 * (H - 1);
  // Plane 1: v = (0, cos t, sin t), centre pixel at (x, c, 1).
  std::array<double, 16>& tilted = data.Poses[1];
  tilted[5] = std::cos(t) * Spacing;
  tilted[9] = std::sin(t) * Spacing;
  tilted[7] = c - std::cos(t) * c;
  tilted[11] = 1.0 - std::sin(t) * c;
  const GridPlanes planes = SelectGridPlanes(data, ParallelShape());
  ASSERT_EQ(planes.Frames, data.TrainFrames);
  ASSERT_NEAR(planes.PlaneSpacing[0], 1.0, 1e-9) << "the centres' gap";
  GaussianField field;
  SeedGrid(data, planes, planes.FanPixels, ParallelShape(), field);
  int onPlane0 = 0, wider = 0;
  for (std::int64_t g = 0; g < field.Count(); ++g)
  {
    if (std::abs(field.Means[3 * g + 2]) > 1e-6)
    {
      continue; // not plane 0 (z = 0)
    }
    ++onPlane0;
    const double y = field.Means[3 * g + 1];
    const double gap = std::abs(std::sin(t) * (y - c) + std::cos(t));
    wider += gap > 1.0;
    ASSERT_NEAR(std::exp(field.LogScales[3 * g + 2]), 0.45 * std::max(1.0, gap), 1e-5) << "row at y = " << y << " mm";
  }
  EXPECT_EQ(onPlane0, 48 * H);
  EXPECT_GT(wider, 0);
  EXPECT_LT(wider, onPlane0);
}

TEST(Seeding, HarrisSeedsAreOnePer200FanPixelsBetweenTheirBounds)
{
  const TrainingData two = ParallelFrames(2, 512, 512, 512), twenty = ParallelFrames(20, 512, 512, 512);
  struct Case
  {
    const TrainingData* Data;
    std::int64_t FanPixels, Maximum, Count;
    const char* Why;
  };
  const Case cases[] = {
    { &two, 524288, 100000, 20000, "one per 200 would be 2,621: at least 20,000" },
    { &twenty, 5242880, 60000, 26214, "one per 200 fan pixels" },
    { &twenty, 5242880, 50000, 25000, "one per 200 would be 26,214: at most half the maximum" },
    { &twenty, 5242880, 30000, 15000, "one per 200 would be 26,214: at most half the maximum (below 20,000)" },
    { &two, 524288, 30000, 15000, "one per 200 would be 2,621: at least min(20,000, half the maximum)" },
  };
  const SeedingSettings settings;
  for (const Case& c : cases)
  {
    ASSERT_EQ(c.FanPixels, std::int64_t(c.Data->Count()) * 512 * 512);
    SeedingPlan plan;
    std::string error;
    ASSERT_TRUE(PlanSeeding(*c.Data, settings, c.Maximum, false, false, ParallelShape(), c.FanPixels, plan, &error))
      << error;
    EXPECT_FALSE(plan.PixelGrid) << c.Why;
    EXPECT_EQ(plan.Count, c.Count) << c.Why;
    EXPECT_EQ(plan.FanPixels, c.FanPixels);
  }
  // A count given is the count, and the pixel grid is the default start's only.
  SeedingSettings given;
  given.InitialGaussians = 1234;
  SeedingPlan plan;
  std::string error;
  ASSERT_TRUE(PlanSeeding(two, given, 100000000, false, false, ParallelShape(), 524288, plan, &error)) << error;
  EXPECT_FALSE(plan.PixelGrid);
  EXPECT_EQ(plan.Count, 1234);
}

// A seed's scale across its frame (SeedShapeOf): the beam, or half the training frames' spacing where that is wider
// (a sparse sweep whose speckle correlates: docs/FINDINGS.md, "Seeds across a sparse sweep's gaps"); a pixel without
// the beam; the beam where no spacing was measured (given) or the factor is 0.
TEST(Seeding, ASeedSpansHalfTheFramesSpacingWhereTheBeamIsNarrower)
{
  TrainerSettings s;
  s.ElevationSigma = 0.3;
  SeedShape shape = SeedShapeOf(s, 0.2, 1.0, 2.29);
  EXPECT_DOUBLE_EQ(shape.ElevationScale, 0.5 * 2.29);
  EXPECT_DOUBLE_EQ(shape.FrameSpacing, 2.29);
  EXPECT_DOUBLE_EQ(shape.ElevationSigma, 0.3); // the beam the field renders with is not widened
  shape = SeedShapeOf(s, 0.2, 1.0, 0.5);       // the beam is wider than half the spacing: the beam
  EXPECT_DOUBLE_EQ(shape.ElevationScale, 0.3);
  EXPECT_EQ(shape.FrameSpacing, 0.0);
  shape = SeedShapeOf(s, 0.2, 1.0); // no spacing measured (ElevationSigma given)
  EXPECT_DOUBLE_EQ(shape.ElevationScale, 0.3);
  s.Seeding.ElevationSpacingFactor = 0;
  EXPECT_DOUBLE_EQ(SeedShapeOf(s, 0.2, 1.0, 2.29).ElevationScale, 0.3);
  s.Seeding.ElevationSpacingFactor = 0.5;
  s.BeamIntegration = false; // the thin plane: a pixel across
  shape = SeedShapeOf(s, 0.2, 1.0, 2.29);
  EXPECT_DOUBLE_EQ(shape.ElevationScale, 0.2);
  EXPECT_EQ(shape.FrameSpacing, 0.0);
}

TEST(Seeding, MoreInitialGaussiansThanTheMaximumAreRefusedNamingBoth)
{
  const TrainingData data = ParallelFrames(12, W, H, 48);
  SeedingSettings settings;
  settings.InitialGaussians = 30001;
  SeedingPlan plan;
  std::string error;
  EXPECT_FALSE(PlanSeeding(data, settings, 30000, false, false, ParallelShape(), 36864, plan, &error));
  EXPECT_NE(error.find("InitialGaussians (30001)"), std::string::npos) << error;
  EXPECT_NE(error.find("MaximumGaussians (30000)"), std::string::npos) << error;
  // As many as the maximum: accepted, and that many seeds.
  settings.InitialGaussians = 30000;
  error.clear();
  ASSERT_TRUE(PlanSeeding(data, settings, 30000, false, false, ParallelShape(), 36864, plan, &error)) << error;
  EXPECT_EQ(plan.Count, 30000);
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

  // Up to twice as many fan pixels as MaximumGaussians: still every fan pixel (memory holds them), no step either.
  s.MaximumGaussians = planes.FanPixels / 2 + 1;
  Trainer coarse(data, s);
  ASSERT_TRUE(coarse.Initialize(&error)) << error;
  EXPECT_EQ(coarse.GetReport().InitialGaussians, planes.FanPixels) << "the grid's count is set by memory";
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
      v.Seeding.InitialGaussians = 1000;
    }
    else
    {
      v.Seeding.PixelGridFit = false;
    }
    Trainer other(data, v);
    ASSERT_TRUE(other.Initialize(&error)) << error;
    ASSERT_TRUE(other.Run(nullptr, nullptr, &error)) << error;
    EXPECT_EQ(other.GetIteration(), 5) << "variant " << variant;
  }
}

TEST(Trainer, ADenseStartKeepsToItsCountAndSolvesTheReflectivities)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.Seeding.DenseInitialisation = true;
  s.ReflectivitySolve = true;
  s.Seeding.InitialGaussians = 6000;
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
  s.Seeding.InitialGaussians = 30000;
  Trainer refused(data, s);
  EXPECT_FALSE(refused.Initialize(&error));
  EXPECT_NE(error.find("InitialGaussians (30000) exceeds MaximumGaussians (20000)"), std::string::npos) << error;
  EXPECT_EQ(refused.GetField().Count(), 0);

  // A maximum whose training state cannot fit in this machine's memory is refused before any seed is made,
  // with what it needs: 10^12 Gaussians of TrainingBytesPerGaussian and the solve's 52 bytes each.
  s.Seeding.InitialGaussians = 6000;
  s.MaximumGaussians = 1000000000000LL;
  Trainer tooLarge(data, s);
  EXPECT_FALSE(tooLarge.Initialize(&error));
  const double megabytes =
    1e12 * (TrainingBytesPerGaussian + 52) / 1e6 + double(data.Width) * data.Height * data.TrainFrames.size() * 8 / 1e6;
  EXPECT_NE(error.find("MaximumGaussians (1000000000000) needs " + std::to_string(std::llround(megabytes)) + " MB"),
    std::string::npos)
    << error;
  EXPECT_NE(error.find("and this machine has"), std::string::npos) << error;
  EXPECT_EQ(tooLarge.GetField().Count(), 0);
}
