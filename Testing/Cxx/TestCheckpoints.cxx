// Checkpoints (bigus::TrainingState::Save, Load; Trainer::SaveCheckpoint, LoadCheckpoint): a resumed run is the
// run that went straight through, with its pose corrections, its parameter average and its time budget; the file holds
// the whole state; files of earlier formats load, bad and truncated ones are refused.
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

using namespace bigus;
using namespace bigus::synthetic;

TEST(Trainer, ResumingFromACheckpointGivesTheSameField)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 6), 0.5, heldOut);
  std::string error;
  Trainer straight(data, ShortSettings());
  ASSERT_TRUE(straight.Initialize(&error));
  ASSERT_TRUE(straight.Run(nullptr, nullptr, &error)) << error;
  ASSERT_GT(straight.GetReport().AverageSamples, 0);

  const std::string checkpoint = std::string(BIGUS_TEST_OUTPUT) + "/trainer.ckpt";
  // After the first densification, so that its state is in the file too; inside the parameter average (from the
  // window's close at step 150, a sample every 10 steps), so that the average is.
  for (const int at : { 110, 180 })
  {
    TrainerSettings s = ShortSettings();
    s.CheckpointFile = checkpoint;
    s.CheckpointInterval = at;
    Trainer first(data, s);
    ASSERT_TRUE(first.Initialize(&error));
    ASSERT_TRUE(first.Run(
      nullptr, [&]() { return first.GetIteration() >= at; }, &error))
      << error;
    EXPECT_EQ(first.GetReport().StopReason, "aborted");
    TrainingState saved;
    double gamma = 0;
    ASSERT_TRUE(saved.Load(checkpoint, gamma, &error)) << error;
    EXPECT_EQ(saved.AverageSamples, at == 180 ? 3 : 0);
    if (at == 180)
    {
      EXPECT_EQ(saved.AverageStart, 160);
      EXPECT_DOUBLE_EQ(saved.AverageFraction, 0.9);
      ASSERT_EQ(saved.AverageField.Count(), saved.Gaussians.Count());
      EXPECT_NE(saved.AverageField.Means, saved.Gaussians.Field.Means);
    }

    Trainer second(data, ShortSettings());
    ASSERT_TRUE(second.Initialize(&error));
    ASSERT_TRUE(second.LoadCheckpoint(checkpoint, &error)) << error;
    EXPECT_EQ(second.GetIteration(), at);
    ASSERT_TRUE(second.Run(nullptr, nullptr, &error)) << error;
    EXPECT_EQ(second.GetReport().AverageFrom, 160);
    ExpectSameField(straight.GetField(), second.GetField());
  }

  std::ofstream(checkpoint + ".bad") << "not a checkpoint";
  Trainer other(data, ShortSettings());
  ASSERT_TRUE(other.Initialize(&error));
  EXPECT_FALSE(other.LoadCheckpoint(checkpoint + ".bad", &error));
  EXPECT_NE(error.find("bad magic"), std::string::npos) << error;
}

TEST(Trainer, AResumeOnOtherDataOrWithOtherSettingsIsRefusedNamingWhatDiffers)
{
  // A checkpoint holds the digest of its run's data and the settings a resume must share: another sweep, or another
  // ElevationSigma, is refused with the reason; a longer schedule is accepted; a file of the format before them
  // ("BIGUSCK5") cannot be checked and is accepted.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 6), 0.5, heldOut);
  const TrainerSettings settings = ShortSettings();
  std::string error;
  Trainer first(data, settings);
  ASSERT_TRUE(first.Initialize(&error)) << error;
  ASSERT_TRUE(first.Train(
    nullptr, [&]() { return first.GetIteration() >= 50; }, &error))
    << error;
  const std::string file = std::string(BIGUS_TEST_OUTPUT) + "/identity.ckpt";
  ASSERT_TRUE(first.SaveCheckpoint(file, &error)) << error;
  EXPECT_EQ(first.GetState().DataDigest, TrainingDataDigest(data));

  TrainingData otherData = data;
  otherData.Frames[otherData.Frames.size() / 2] += 0.01f; // one pixel of one frame
  EXPECT_NE(TrainingDataDigest(otherData), TrainingDataDigest(data));
  Trainer other(otherData, settings);
  ASSERT_TRUE(other.Initialize(&error)) << error;
  EXPECT_FALSE(other.LoadCheckpoint(file, &error));
  EXPECT_NE(error.find("other training data"), std::string::npos) << error;

  TrainerSettings wider = settings;
  wider.ElevationSigma = 0.75;
  Trainer changed(data, wider);
  ASSERT_TRUE(changed.Initialize(&error)) << error;
  EXPECT_FALSE(changed.LoadCheckpoint(file, &error));
  EXPECT_NE(error.find("ElevationSigma: 0.5 in the checkpoint, 0.75 now"), std::string::npos) << error;

  TrainerSettings longer = settings;
  longer.Iterations = 400;
  Trainer resumed(data, longer);
  ASSERT_TRUE(resumed.Initialize(&error)) << error;
  EXPECT_TRUE(resumed.LoadCheckpoint(file, &error)) << error;
  EXPECT_EQ(resumed.GetIteration(), 50);

  // The same state in the previous format: the magic "BIGUSCK5" and no digest or settings at the end.
  std::ifstream in(file, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::size_t identity = 8 + 4 + first.GetState().RunSettings.size();
  ASSERT_GT(bytes.size(), identity);
  bytes = bytes.substr(0, bytes.size() - identity);
  bytes[7] = '5';
  std::ofstream(file + ".v5", std::ios::binary) << bytes;
  Trainer old(otherData, settings);
  ASSERT_TRUE(old.Initialize(&error)) << error;
  EXPECT_TRUE(old.LoadCheckpoint(file + ".v5", &error)) << error;
  EXPECT_EQ(old.GetIteration(), 50);
  std::remove(file.c_str());
  std::remove((file + ".v5").c_str());
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
  ASSERT_TRUE(first.Train(
    nullptr, [&]() { return first.GetIteration() >= 110; }, &error))
    << error;
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
  EXPECT_NE(error.find("RefinePoses: "), std::string::npos) << error; // the run settings differ
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
  s.Densification.End = -1;
  const std::string checkpoint = std::string(BIGUS_TEST_OUTPUT) + "/budget.ckpt";
  std::string error;
  Trainer first(data, s);
  ASSERT_TRUE(first.Initialize(&error)) << error;
  const auto start = std::chrono::steady_clock::now();
  auto since = [](std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
  };
  ASSERT_TRUE(first.Train(
    nullptr, [&]() { return since(start) >= 0.7 * s.TimeBudget + 0.05; }, &error))
    << error;
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
  ASSERT_EQ(bytes.compare(0, 8, "BIGUSCK8"), 0);
  // Version 6: no parameter average (the file ends with it: two counts, a fraction, the averaged field with its
  // count, no pose corrections with their count, 7 doubles); here it had started, the window having closed at 60 %.
  const std::int64_t averaged = first.GetState().AverageField.Count();
  ASSERT_GT(first.GetState().AverageSamples, 0);
  ASSERT_EQ(averaged, first.GetField().Count());
  // The file of an older format: its last @p cut bytes dropped from the last one's, the version set, written, loaded.
  auto older = [&](std::size_t cut, char version, TrainingState& state) {
    bytes = bytes.substr(0, bytes.size() - cut);
    bytes[7] = version;
    const std::string file = checkpoint + ".v" + version;
    std::ofstream(file, std::ios::binary) << bytes;
    double gamma = 0;
    const bool ok = state.Load(file, gamma, &error);
    std::remove(file.c_str());
    return ok;
  };
  // Version 7: no validation join or measured tail (the file ends with their steps, here none).
  TrainingState seven;
  ASSERT_TRUE(older(2 * sizeof(std::int32_t), '7', seven)) << error;
  EXPECT_EQ(seven.ValidationJoinedAt, -2) << "unknown in a file before the join was written";
  EXPECT_EQ(seven.MeasuredTailEnd, -1);
  EXPECT_EQ(seven.AverageSamples, first.GetState().AverageSamples);
  TrainingState six;
  ASSERT_TRUE(older(2 * sizeof(std::int32_t) + sizeof(double) + 2 * sizeof(std::int64_t) +
      static_cast<std::size_t>(averaged) * 11 * sizeof(float) + 7 * sizeof(double),
    '6', six))
    << error;
  EXPECT_EQ(six.TrainingSeconds, saved);
  EXPECT_EQ(six.AverageSamples, 0) << "a file before the average: it starts afresh";
  EXPECT_EQ(six.RunSettings, first.GetState().RunSettings);
  // Version 5: no data digest and run settings (the file ends with them).
  TrainingState five;
  ASSERT_TRUE(older(sizeof(std::uint64_t) + sizeof(std::uint32_t) + first.GetState().RunSettings.size(), '5', five))
    << error;
  EXPECT_EQ(five.TrainingSeconds, saved);
  EXPECT_EQ(five.DataDigest, 0u);
  TrainingState four;
  ASSERT_TRUE(older(28 * sizeof(double) + sizeof(std::int32_t) + sizeof(std::int64_t), '4', four)) << error;
  EXPECT_EQ(four.TrainingSeconds, saved);
  EXPECT_EQ(four.SharedPoseSteps, 0);
  TrainingState three;
  ASSERT_TRUE(older(sizeof(std::int64_t), '3', three)) << error;
  EXPECT_EQ(three.TrainingSeconds, saved);
  EXPECT_TRUE(three.PoseCorrections.empty());
  TrainingState two;
  ASSERT_TRUE(older(sizeof(double), '2', two)) << error;
  EXPECT_EQ(two.TrainingSeconds, 0);
  EXPECT_EQ(two.Iteration, iteration);
  std::remove(checkpoint.c_str());
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
  ASSERT_TRUE(trainer.Train(
    nullptr, [&]() { return trainer.GetIteration() >= 150; }, &error))
    << error;
  ASSERT_GT(trainer.GetState().SharedPoseSteps, 0);
  const std::string file = std::string(BIGUS_TEST_OUTPUT) + "/state.ckpt";
  ASSERT_TRUE(trainer.SaveCheckpoint(file, &error)) << error;
  const TrainingState& saved = trainer.GetState();
  ASSERT_GT(
    std::count_if(saved.Gaussians.SeenCount.begin(), saved.Gaussians.SeenCount.end(), [](int c) { return c > 0; }), 0)
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
  EXPECT_EQ(loaded.ValidationJoinedAt, saved.ValidationJoinedAt);
  EXPECT_EQ(loaded.MeasuredTailEnd, saved.MeasuredTailEnd);
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
  // Its last field, the measured tail's end step, cut short.
  std::ofstream(file + ".cut", std::ios::binary) << bytes.substr(0, bytes.size() - 2);
  EXPECT_FALSE(loaded.Load(file + ".cut", gamma, &error));
  EXPECT_NE(error.find("truncated or invalid validation join or measured tail"), std::string::npos) << error;
  std::remove(file.c_str());
  std::remove((file + ".cut").c_str());
}
