// The validation stage (bigusValidation.h): which training frames a run scores itself on while it trains.
#include "bigusValidation.h"

#include "bigusHeldOutChoices.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <random>
#include <vector>

using namespace bigus;

// ValidationFrames: every (n / 8)-th of the n training frames (every one while n < 16), at most 8, counted by hand.
// The training frames are 1, 4, 7, ... (3 m + 1 for the m-th), so that a position in TrainFrames is not taken for a
// frame.
TEST(Validation, EveryEighthOfTheTrainingFramesAtMostEight)
{
  struct Case
  {
    int Frames;
    std::vector<int> Expected;
  };
  const Case cases[] = {
    { 0, {} },                                       // no training frame, no validation frame
    { 5, { 1, 4, 7, 10, 13 } },                      // n / 8 = 0: every frame, 5 of them
    { 16, { 1, 7, 13, 19, 25, 31, 37, 43 } },        // every 2nd: positions 0, 2, ..., 14
    { 17, { 1, 7, 13, 19, 25, 31, 37, 43 } },        // every 2nd, the 9th (position 16) left out
    { 100, { 1, 37, 73, 109, 145, 181, 217, 253 } }, // every 12th: positions 0, 12, ..., 84 (96 left out)
  };
  for (const Case& c : cases)
  {
    TrainingData data;
    for (int m = 0; m < c.Frames; ++m)
    {
      data.TrainFrames.push_back(3 * m + 1);
    }
    EXPECT_EQ(ValidationFrames(data), c.Expected) << c.Frames << " training frames";
  }
}

// HoldOutValidationByRule: held out only where every sweep was measured and none correlates at its training frames'
// spacing below the pose rule's 0.3; the correlation there is the measured curve's, linear between its bins (by hand
// below: 0.6 at 1 mm, 0.2 at 2 mm, so 0.4 at 1.5 mm and 0.1 at 2.25 mm past a bin of 0 at 2.5 mm).
TEST(Validation, HeldOutWhereNoSweepsNeighbouringFramesShareSpeckle)
{
  auto sweep = [](double spacing) {
    SweepDecorrelation s;
    s.Measured = true;
    s.Measurement.Distance = { 1.0, 2.0, 2.5 };
    s.Measurement.Correlation = { 0.6, 0.2, 0.0 };
    s.Measurement.NeighbourSpacing = spacing;
    return s;
  };
  SweepDecorrelation unmeasured;
  unmeasured.Error = "fewer than two training frames";
  std::string reason;
  EXPECT_TRUE(HoldOutValidationByRule({ sweep(2.25) }, reason));
  EXPECT_EQ(reason, "speckle correlation 0.10 at the training frames' spacing 2.25 mm < 0.3");
  EXPECT_FALSE(HoldOutValidationByRule({ sweep(1.5) }, reason));
  EXPECT_EQ(reason, "speckle correlation 0.40 at the training frames' spacing 1.5 mm >= 0.3");
  EXPECT_TRUE(HoldOutValidationByRule({ sweep(2.25), sweep(3.0) }, reason)) << reason;
  EXPECT_FALSE(HoldOutValidationByRule({ sweep(2.25), sweep(1.5) }, reason));
  EXPECT_EQ(reason,
    "sweep 0: speckle correlation 0.10 at the training frames' spacing 2.25 mm < 0.3; sweep 1: "
    "speckle correlation 0.40 at the training frames' spacing 1.5 mm >= 0.3");
  // A measured correlation below 0 (the liver's training frames taken one in 4, 3 mm apart: -0.06) shares nothing:
  // held out, as any below 0.3; only a sweep that could not be measured keeps the training frames.
  SweepDecorrelation anticorrelated = sweep(2.5);
  anticorrelated.Measurement.Correlation.back() = -0.06;
  EXPECT_TRUE(HoldOutValidationByRule({ anticorrelated }, reason)) << reason;
  EXPECT_EQ(reason, "speckle correlation -0.06 at the training frames' spacing 2.5 mm < 0.3");
  EXPECT_FALSE(HoldOutValidationByRule({ sweep(2.25), unmeasured }, reason));
  EXPECT_NE(reason.find("sweep 1: its frames cannot be measured"), std::string::npos) << reason;
  EXPECT_FALSE(HoldOutValidationByRule({}, reason));
}

// Early stopping: KeepIfBest keeps the field of the lowest loss seen (not a later, worse one, nor a NaN), with its
// iteration and pose corrections; RestoreBestField brings it back, moments zeroed, only when the last loss is worse.
TEST(Validation, EarlyStoppingKeepsAndRestoresTheBestFieldWithItsPoses)
{
  auto fieldWith = [](float r) {
    GaussianField f;
    f.Means = { 0.f, 0.f, 0.f };
    f.LogScales = { 0.f, 0.f, 0.f };
    f.Quaternions = { 1.f, 0.f, 0.f, 0.f };
    f.Reflectivities = { r };
    return f;
  };
  TrainingState state;
  state.PoseCorrections.assign(2, {});
  const double losses[] = { 0.5, 0.3, 0.4, std::numeric_limits<double>::quiet_NaN(), 0.35 };
  for (int k = 0; k < 5; ++k)
  {
    state.Iteration = 100 * (k + 1);
    state.PoseCorrections[1][3] = 0.1 * (k + 1); // the corrections move with the field
    KeepIfBest(state, losses[k], fieldWith(float(k + 1)));
  }
  EXPECT_EQ(state.BestFieldLoss, 0.3);
  EXPECT_EQ(state.BestFieldIteration, 200);
  ASSERT_EQ(state.BestField.Reflectivities.size(), 1u);
  EXPECT_EQ(state.BestField.Reflectivities[0], 2.f);
  ASSERT_EQ(state.BestPoseCorrections.size(), 2u);
  EXPECT_DOUBLE_EQ(state.BestPoseCorrections[1][3], 0.2);

  state.Gaussians.Field = fieldWith(5.f);
  state.Gaussians.ResizeToField();
  state.Gaussians.FirstMoment.Reflectivities[0] = 7.f;
  EXPECT_FALSE(RestoreBestField(state, 0.3)) << "a last loss equal to the best keeps the last field";
  EXPECT_EQ(state.Gaussians.Field.Reflectivities[0], 5.f);
  EXPECT_TRUE(RestoreBestField(state, 0.35));
  EXPECT_EQ(state.Gaussians.Field.Reflectivities[0], 2.f);
  EXPECT_EQ(state.Gaussians.FirstMoment.Reflectivities[0], 0.f) << "fresh moments";
  EXPECT_DOUBLE_EQ(state.PoseCorrections[1][3], 0.2) << "the poses the best field was measured at";
  EXPECT_EQ(state.BestFieldLoss, 0.3) << "the record of the best stays";
}

// The Adam route's validation frames (HeldOutChoiceSettings::ValidationStride) are held out of the fit until the
// densification window closes. Two runs whose held-out frames differ (the second's replaced by noise) fit the same
// field, bit for bit, up to that point: gamma, the seeds and every step see only the fitted frames. A fitted frame
// changed the same way changes the field (the comparison can fail). After Finish the held-out frames are in the fit.
TEST(Validation, HeldOutFramesAreNotFittedBeforeTheyJoin)
{
  using namespace bigus::synthetic;
  const GaussianField truth = KnownField(400, 3);
  std::vector<int> testFrames;
  const TrainingData data = SyntheticSweep(truth, 0.5, testFrames);
  TrainerSettings s = ShortSettings(); // the window closes at step 150, the next validation (200) joins
  s.HeldOut.HoldOutValidationFrames = ValidationHoldOut::On;
  const std::vector<int> held = HeldOutFrames(data, s.HeldOut.ValidationStride, s.HeldOut.MaximumValidationFrames);
  ASSERT_GE(held.size(), 2u);
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  auto withNoiseOn = [&](int frame) {
    TrainingData changed = data;
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<float> uniform(0.f, 1.f);
    std::generate_n(changed.Frames.begin() + pixels * frame, pixels, [&]() { return uniform(rng); });
    return changed;
  };
  auto fieldAtStep150 = [&](const TrainingData& d, TrainerReport* report) {
    Trainer trainer(d, s);
    std::string error;
    EXPECT_TRUE(trainer.Initialize(&error)) << error;
    EXPECT_TRUE(trainer.Train(
      nullptr, [&]() { return trainer.GetIteration() >= 150; }, &error))
      << error;
    EXPECT_EQ(trainer.GetIteration(), 150);
    for (int f : held)
    {
      EXPECT_FALSE(std::binary_search(trainer.GetData().TrainFrames.begin(), trainer.GetData().TrainFrames.end(), f))
        << "validation frame " << f << " is fitted before the window closes";
    }
    if (report)
    {
      *report = trainer.GetReport();
    }
    return trainer.GetField();
  };
  TrainerReport report;
  const GaussianField reference = fieldAtStep150(data, &report);
  EXPECT_TRUE(report.ValidationHeldOut);
  EXPECT_EQ(report.ValidationFrames, held);
  EXPECT_EQ(report.ValidationJoinedAt, -1);
  TrainingData noisy = data;
  for (int f : held)
  {
    std::copy_n(withNoiseOn(f).Frames.begin() + pixels * f, pixels, noisy.Frames.begin() + pixels * f);
  }
  ExpectSameField(fieldAtStep150(noisy, nullptr), reference);
  // A fitted frame changed the same way changes the field.
  const GaussianField changed = fieldAtStep150(withNoiseOn(data.TrainFrames[1]), nullptr);
  EXPECT_NE(changed.Means, reference.Means);

  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error) && trainer.Run(nullptr, nullptr, &error)) << error;
  EXPECT_EQ(trainer.GetReport().ValidationJoinedAt, 200);
  EXPECT_EQ(trainer.GetData().TrainFrames, data.TrainFrames);
}

// With RefinePoses on, a mid-run Evaluate places the frames not trained among their refined neighbours, but the
// held-out validation frames stay at their tracked poses while they decide (every validation scores them there), so
// a run's decisions do not depend on when it was evaluated.
TEST(Validation, HeldOutFramesKeepTheirTrackedPosesThroughAMidRunEvaluation)
{
  using namespace bigus::synthetic;
  std::vector<int> testFrames;
  const TrainingData data = SyntheticSweep(KnownField(400, 3), 0.5, testFrames);
  TrainerSettings s = ShortSettings();
  s.HeldOut.HoldOutValidationFrames = ValidationHoldOut::On;
  s.Poses.RefinePoses = PoseRefinement::On;
  s.Poses.Start = 0;
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Train(
    nullptr, [&]() { return trainer.GetIteration() >= 120; }, &error))
    << error;
  ImageMetrics metrics;
  ASSERT_TRUE(trainer.Evaluate(testFrames, metrics, &error)) << error;
  const std::vector<std::array<double, 16>>& tracked = trainer.GetPoseRefiner().GetTrackedPoses();
  ASSERT_TRUE(trainer.GetReport().ValidationHeldOut);
  for (int f : trainer.GetReport().ValidationFrames)
  {
    EXPECT_EQ(trainer.GetData().Poses[f], tracked[f]) << "validation frame " << f;
  }
  int moved = 0; // the test frames were placed (the comparison can fail)
  for (int f : testFrames)
  {
    moved += trainer.GetData().Poses[f] != tracked[f];
  }
  EXPECT_GT(moved, 0);
}
