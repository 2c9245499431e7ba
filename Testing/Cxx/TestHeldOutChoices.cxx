// The held-out choices (bigusHeldOutChoices.h): which frames are held out, that a candidate's fit reads none of their
// pixels, and that the trainer takes the candidate with the best held-out score and says so.
#include "bigusHeldOutChoices.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

using namespace bigus;

namespace
{
/// The synthetic sweep's first 24 frames, all of them training frames (a pixel grid of 24 x 64 x 64 fan pixels).
/// The route trial's settings on the synthetic sweep: MaximumGaussians 20,000 (the rule takes Adam), exact poses,
/// @p iterations steps; the time budget (600 s, never reached) lets the trial plan its fits.
TrainerSettings RouteTrialSettings(int iterations)
{
  TrainerSettings settings;
  settings.ElevationSigma = 0.3;
  settings.MaximumGaussians = 20000;
  settings.Poses.RefinePoses = PoseRefinement::Off;
  settings.Iterations = iterations;
  settings.TimeBudget = 600;
  return settings;
}

TrainingData GridSweep()
{
  std::vector<int> unused;
  TrainingData data = synthetic::SyntheticSweep(synthetic::KnownField(300, 5), 0.3, unused);
  data.TrainFrames.clear();
  for (int k = 0; k < 24; ++k)
  {
    data.TrainFrames.push_back(k);
  }
  return data;
}
}

TEST(HeldOutChoices, FramesLieBetweenTrainingFramesOfEachSweepTakenInTurn)
{
  // Sweep 0: frames 0 to 19; sweep 1: frames 20 to 29, of which 25 is not a training frame; sweep 2: 30 and 31.
  TrainingData data;
  for (int f = 0; f < 32; ++f)
  {
    data.Sweeps.push_back(f < 20 ? 0 : f < 30 ? 1 : 2);
    if (f != 25)
    {
      data.TrainFrames.push_back(f);
    }
  }
  // Stride 8 from the 4th training frame of each sweep, never its last: sweep 0 positions 4 and 12 (frames 4, 12);
  // sweep 1's training frames 20 to 24 and 26 to 29, position 4 (frame 24); sweep 2 has none between two others.
  EXPECT_EQ(HeldOutFrames(data, 8, 12), (std::vector<int>{ 4, 12, 24 }));
  // At most 2: the sweeps' first shares in turn.
  EXPECT_EQ(HeldOutFrames(data, 8, 2), (std::vector<int>{ 4, 24 }));
  // Stride 4 from position 2: sweep 0 positions 2, 6, 10, 14, 18 (not 19, its last); sweep 1 positions 2, 6.
  EXPECT_EQ(HeldOutFrames(data, 4, 12), (std::vector<int>{ 2, 6, 10, 14, 18, 22, 27 }));
  const TrainingData fit = WithoutHeldOutFrames(data, { 4, 12, 24 });
  EXPECT_EQ(fit.TrainFrames.size(), data.TrainFrames.size() - 3);
  EXPECT_TRUE(std::none_of(fit.TrainFrames.begin(), fit.TrainFrames.end(), [](int f) { return f == 12; }));
  TrainingData two;
  two.TrainFrames = { 3, 4 };
  EXPECT_TRUE(HeldOutFrames(two, 8, 12).empty());
}

TEST(HeldOutChoices, ACandidatesFitReadsNoPixelOfAHeldOutFrame)
{
  // The held-out frames' pixels replaced by noise: the candidate's fit is the same to the bit. A training frame's
  // pixels changed the same way change it (the comparison can fail).
  const TrainingData data = GridSweep();
  const std::vector<int> heldOut = HeldOutFrames(data, 8, 12);
  ASSERT_EQ(heldOut, (std::vector<int>{ 4, 12, 20 }));
  TrainerSettings settings;
  settings.ElevationSigma = 0.3;
  settings.Poses.RefinePoses = PoseRefinement::Off;
  auto scrambled = [&](int frame) {
    TrainingData d = data;
    const std::size_t pixels = std::size_t(d.Width) * d.Height;
    std::mt19937 rng(frame);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::generate(d.Frames.begin() + pixels * frame, d.Frames.begin() + pixels * (frame + 1), [&] { return u(rng); });
    return d;
  };
  GaussianField fits[3];
  std::string error;
  ASSERT_TRUE(FitWithoutHeldOutFrames(data, heldOut, settings, fits[0], &error)) << error;
  ASSERT_TRUE(FitWithoutHeldOutFrames(scrambled(12), heldOut, settings, fits[1], &error)) << error;
  ASSERT_TRUE(FitWithoutHeldOutFrames(scrambled(13), heldOut, settings, fits[2], &error)) << error;
  EXPECT_GT(fits[0].Count(), 1000) << "the pixel-grid fit";
  ExpectSameField(fits[0], fits[1]);
  EXPECT_NE(fits[0].Reflectivities, fits[2].Reflectivities) << "a fitted frame's pixels must matter";
}

TEST(HeldOutChoices, TheChosenBeamRendersFramesNoChoiceSawAsWellAsTheBestCandidate)
{
  // The synthetic sweep (60 frames 0.2 mm apart, rendered with sigma_E 0.3 mm) less its own held-out frames
  // (k mod 4 == 2), which neither the choice nor any fit sees: the trainer measures ElevationSigma on its own
  // held-out frames (every 2nd training frame), chooses the narrowest candidate within 0.05 dB of the best and
  // takes it times ElevationSigmaScale; its field then renders the unseen frames within 0.5 dB of the best
  // candidate's field.
  std::vector<int> unseen;
  const TrainingData data = synthetic::SyntheticSweep(synthetic::KnownField(300, 5), 0.3, unseen);
  TrainerSettings settings;
  settings.Poses.RefinePoses = PoseRefinement::Off;
  Trainer trainer(data, settings);
  const double rule = trainer.GetReport().ElevationSigma;
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  const TrainerReport& report = trainer.GetReport();
  const HeldOutChoice& choice = report.HeldOut.ElevationSigma;
  ASSERT_EQ(choice.Candidates.size(), settings.HeldOut.ElevationSigmaFactors.size());
  ASSERT_GE(choice.Chosen, 0);
  double bestHeldOut = -1e300;
  for (std::size_t k = 0; k < choice.Candidates.size(); ++k)
  {
    EXPECT_NEAR(choice.Candidates[k].Value, rule * settings.HeldOut.ElevationSigmaFactors[k], 1e-12);
    bestHeldOut = std::max(bestHeldOut, choice.Candidates[k].PSNR);
  }
  const HeldOutCandidate& chosen = choice.Candidates[choice.Chosen];
  EXPECT_GE(chosen.PSNR, bestHeldOut - settings.HeldOut.Tolerance);
  for (const HeldOutCandidate& c : choice.Candidates)
  {
    EXPECT_FALSE(c.PSNR >= bestHeldOut - settings.HeldOut.Tolerance && c.Value < chosen.Value) << "a narrower one";
  }
  // Taken narrower for the fit on every frame (HeldOutChoiceSettings::ElevationSigmaScale).
  EXPECT_DOUBLE_EQ(report.ElevationSigma, chosen.Value * settings.HeldOut.ElevationSigmaScale);
  EXPECT_EQ(trainer.Options().ElevationSigma, report.ElevationSigma);
  const std::string line = synthetic::SettingLine(report, "ElevationSigma");
  ASSERT_FALSE(line.empty());
  std::printf("%s\n", line.c_str());
  EXPECT_NE(line.find("frames held out (every 2nd training frame"), std::string::npos) << line;
  EXPECT_NE(line.find("the rule's value"), std::string::npos) << line;
  EXPECT_NE(line.find("; taken x 0.707: "), std::string::npos) << line;
  // Each candidate given, fitted on every training frame, scored on the frames no choice saw; the run's own field
  // (the sigma taken) scores within 0.5 dB of the best of them.
  double best = -1e300;
  for (const HeldOutCandidate& c : choice.Candidates)
  {
    TrainerSettings given = settings;
    given.ElevationSigma = c.Value;
    Trainer fit(data, given);
    ASSERT_TRUE(fit.Initialize(&error)) << error;
    const double psnr = synthetic::HeldOutPsnr(fit, unseen);
    std::printf("sigma_E %.4g mm: %.2f dB on the unseen frames\n", c.Value, psnr);
    best = std::max(best, psnr);
  }
  const double taken = synthetic::HeldOutPsnr(trainer, unseen);
  std::printf("the run, sigma_E %.4g mm: %.2f dB on the unseen frames\n", report.ElevationSigma, taken);
  EXPECT_GE(taken, best - 0.5);
  // Off: the rule's value, untested.
  settings.HeldOut.Enabled = false;
  Trainer untested(data, settings);
  ASSERT_TRUE(untested.Initialize(&error)) << error;
  EXPECT_EQ(untested.GetReport().ElevationSigma, rule);
  EXPECT_EQ(untested.GetReport().HeldOut.ElevationSigma.Chosen, -1);
  const std::string ruleLine = synthetic::SettingLine(untested.GetReport(), "ElevationSigma");
  ASSERT_FALSE(ruleLine.empty());
  EXPECT_NE(ruleLine.find("(chosen: "), std::string::npos) << ruleLine;
  EXPECT_NE(ruleLine.find("; untested on held-out frames: the held-out choices are off)"), std::string::npos)
    << ruleLine;
}

TEST(HeldOutChoices, TheFinalPruneAndTheMergeAreKeptOnlyWhereHeldOutFramesSayTheyCostLittle)
{
  // The pixel grid of 24 frames with the beam given: the ridge and the reduction are still measured. With the default
  // tolerances both reductions are kept where they cost at most 0.05 dB on the held-out frames; a final prune of
  // 0.3 in intensity removes most of the field, costs far more and is dropped, so the run ends unpruned, while the
  // same prune taken untested removes Gaussians.
  const TrainingData data = GridSweep();
  TrainerSettings settings;
  settings.ElevationSigma = 0.3;
  settings.Poses.RefinePoses = PoseRefinement::Off;
  settings.FinalPruneTolerance = 0.3;
  std::string error;
  Trainer trainer(data, settings);
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  const HeldOutChoices& choices = trainer.GetReport().HeldOut;
  EXPECT_EQ(choices.ElevationSigma.Untested, "given");
  ASSERT_EQ(choices.Ridge.Candidates.size(), settings.HeldOut.RidgeFactors.size());
  EXPECT_EQ(choices.Ridge.Candidates[0].Value, settings.Solve.Ridge);
  ASSERT_GE(choices.Ridge.Chosen, 0);
  EXPECT_EQ(trainer.GetSettings().Solve.Ridge, choices.Ridge.Candidates[choices.Ridge.Chosen].Value);
  const HeldOutReduction& r = choices.Reduction;
  ASSERT_TRUE(r.Untested.empty()) << r.Untested;
  std::printf("whole %.2f dB (%lld), pruned %.2f dB (%lld), merged %.2f dB (%lld)\n", r.WholePSNR,
    static_cast<long long>(r.Whole), r.PrunedPSNR, static_cast<long long>(r.Pruned), r.MergedPSNR,
    static_cast<long long>(r.Merged));
  EXPECT_LT(r.Pruned, r.Whole / 2) << "a prune of 0.3 in intensity removes most of the grid";
  EXPECT_LT(r.PrunedPSNR, r.WholePSNR - settings.HeldOut.Tolerance);
  EXPECT_FALSE(r.KeepPrune);
  EXPECT_EQ(trainer.GetSettings().FinalPruneTolerance, 0.0);
  const std::string prune = synthetic::SettingLine(trainer.GetReport(), "FinalPrune");
  ASSERT_FALSE(prune.empty());
  std::printf("%s\n", prune.c_str());
  EXPECT_EQ(prune.rfind("FinalPrune = off (was: on", 0), 0u) << prune;
  EXPECT_NE(prune.find("dropped on " + std::to_string(r.Frames) + " held-out frames"), std::string::npos) << prune;
  ASSERT_TRUE(trainer.Finish(&error)) << error;
  EXPECT_EQ(trainer.GetReport().PrunedAtEnd, 0);

  settings.HeldOut.MeasureReduction = false;
  Trainer untested(data, settings);
  ASSERT_TRUE(untested.Initialize(&error) && untested.Finish(&error)) << error;
  EXPECT_GT(untested.GetReport().PrunedAtEnd, r.Whole / 4);

  // The default prune and merge cost nothing measurable here and are kept.
  settings = TrainerSettings();
  settings.ElevationSigma = 0.3;
  settings.Poses.RefinePoses = PoseRefinement::Off;
  Trainer defaults(data, settings);
  ASSERT_TRUE(defaults.Initialize(&error)) << error;
  const HeldOutReduction& kept = defaults.GetReport().HeldOut.Reduction;
  EXPECT_TRUE(kept.KeepPrune && kept.KeepMerge) << kept.WholePSNR << " " << kept.PrunedPSNR << " " << kept.MergedPSNR;
  EXPECT_TRUE(kept.MergeMeasured);
  EXPECT_EQ(defaults.GetSettings().FinalPruneTolerance, settings.FinalPruneTolerance);
  EXPECT_EQ(defaults.GetSettings().Merge.Tolerance, settings.Merge.Tolerance);
}

TEST(HeldOutChoices, TheRouteIsMeasuredWhereTheRuleTakesAdamAndTheBetterRouteTakesTheRun)
{
  // The synthetic sweep (45 training frames of 64 x 64 fan pixels, 0.2 mm apart, sigma_E 0.3 mm) with
  // MaximumGaussians 20,000: its grid's planes hold more than twice that many fan pixels, so the rule takes Harris
  // seeds and Adam. With a time budget the route trial fits the grid, holds its scored frames out of the Adam run,
  // and decides when they would join; the route it takes must render frames that neither route saw (k mod 4 == 2)
  // about as well as the better of the two routes run alone. The grid here has at most MaximumGaussians points (a
  // stride of about 2.2 pixels, GridCountByMemory off), so that Adam wins; every fan pixel's grid, with the gap at
  // each point as its elevation scale, renders this sweep's unseen frames better than Adam's 1000 steps (48.34
  // against 46.03 dB), which the next tests measure.
  std::vector<int> unseen;
  const TrainingData data = synthetic::SyntheticSweep(synthetic::KnownField(300, 5), 0.3, unseen);
  TrainerSettings settings = RouteTrialSettings(1000);
  settings.Seeding.GridCountByMemory = false;
  std::string error;
  Trainer trainer(data, settings);
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  const RouteTrial& route = trainer.GetReport().Route;
  ASSERT_TRUE(route.Untested.empty()) << route.Untested;
  ASSERT_TRUE(route.Pending);
  EXPECT_GT(route.FanPixels, 2 * settings.MaximumGaussians);
  EXPECT_GE(route.Frames.size(), 2u);
  EXPECT_EQ(trainer.GetReport().ValidationFrames, route.Frames) << "the Adam run is validated on the trial's frames";
  for (int f : route.Frames)
  {
    EXPECT_EQ(std::count(trainer.GetData().TrainFrames.begin(), trainer.GetData().TrainFrames.end(), f), 0)
      << "frame " << f << " is held out of the Adam run";
  }
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  ASSERT_GE(route.DecidedAt, 0);
  EXPECT_FALSE(route.GridChosen) << "Adam fits this field of Gaussians better than a grid of 20,000 points";
  const std::string line = synthetic::SettingLine(trainer.GetReport(), "Route");
  ASSERT_FALSE(line.empty());
  std::printf("%s\n", line.c_str());
  EXPECT_NE(line.find("measured on " + std::to_string(route.Frames.size()) + " held-out frames"), std::string::npos)
    << line;
  if (route.GridChosen)
  {
    EXPECT_EQ(trainer.GetIteration(), route.DecidedAt) << "the grid takes no step";
    EXPECT_GT(trainer.GetReport().InitialGaussians, settings.MaximumGaussians) << "every fan pixel: set by memory";
  }
  else
  {
    EXPECT_EQ(trainer.GetIteration(), settings.Iterations);
  }
  const double chosen = synthetic::HeldOutPsnr(trainer, unseen);

  // Each route alone, scored on the same unseen frames.
  TrainerSettings adam = settings;
  adam.HeldOut.MeasureRoute = false;
  Trainer adamAlone(data, adam);
  ASSERT_TRUE(adamAlone.Initialize(&error) && adamAlone.Run(nullptr, nullptr, &error)) << error;
  TrainerSettings grid = settings;
  grid.Seeding.PixelGridFanPixelsPerGaussian = 1e9;
  grid.HeldOut.MeasureRoute = false;
  Trainer gridAlone(data, grid);
  ASSERT_TRUE(gridAlone.Initialize(&error) && gridAlone.Run(nullptr, nullptr, &error)) << error;
  const double a = synthetic::HeldOutPsnr(adamAlone, unseen), g = synthetic::HeldOutPsnr(gridAlone, unseen);
  std::printf("unseen frames: the route taken %.2f dB; Harris seeds and Adam alone %.2f dB; the pixel grid alone %.2f "
              "dB\n",
    chosen, a, g);
  // Adam's runs differ by up to 0.8 dB between repeats (threads accumulate in any order) and the trial's Adam trains
  // without its 12 frames until the decision, so "about as well" is judged against the gap between the routes: the
  // route taken stays within a quarter of that gap of the better route (the worse one is 7 dB lower here).
  EXPECT_GE(chosen, std::max(a, g) - 0.25 * std::abs(a - g));
  EXPECT_EQ(adamAlone.GetReport().Route.Untested, "its measurement is off (MeasureRoute)");
  // The grid taken by the rule and not measured says so, and which routes it leaves untested.
  const std::string routeLine = synthetic::SettingLine(gridAlone.GetReport(), "Route");
  ASSERT_FALSE(routeLine.empty());
  EXPECT_EQ(
    routeLine.rfind("Route = the pixel grid (the rule: the " + std::to_string(gridAlone.GetReport().Route.FanPixels) +
        " fan pixels of the grid's planes are at most 1e+09 x MaximumGaussians; untested against Harris seeds "
        "and Adam: its measurement is off (MeasureRoute)",
      0),
    0u)
    << routeLine;
  EXPECT_NE(routeLine.find("variable projection and grids at a coarser stride untested"), std::string::npos)
    << routeLine;

  // The same grid taken by the rule (every fan pixel within it) is measured against the route it displaced: the run
  // starts as Adam's, with the trial's frames held out, and Adam, which scores above the grid on them before a quarter
  // of the schedule, takes the run (issue 54: a route is not switched by a pixel count).
  grid.HeldOut.MeasureRoute = true;
  Trainer probe(data, grid);
  ASSERT_TRUE(probe.Initialize(&error)) << error;
  const RouteTrial& probed = probe.GetReport().Route;
  ASSERT_TRUE(probed.Pending) << probed.Untested;
  EXPECT_TRUE(probed.GridByRule);
  EXPECT_TRUE(probed.AdamProbe);
  EXPECT_GE(probed.DecideBy, grid.HeldOut.RouteProbeFraction) << "from Adam's start, after the grid's side";
  EXPECT_LT(probed.DecideBy, grid.HeldOut.RouteProbeFraction + 0.1);
  EXPECT_LT(probe.GetReport().InitialGaussians, probed.GridGaussians) << "Harris seeds, not the grid";
  ASSERT_TRUE(probe.Run(nullptr, nullptr, &error)) << error;
  ASSERT_GE(probed.DecidedAt, 0);
  EXPECT_FALSE(probed.GridChosen);
  EXPECT_LE(probed.DecidedAt, grid.HeldOut.RouteProbeFraction * grid.Iterations + grid.Densification.Interval);
  EXPECT_EQ(probe.GetIteration(), grid.Iterations) << "Adam's steps go on";
  EXPECT_EQ(probe.GetData().TrainFrames, data.TrainFrames) << "the trial's frames joined the fit";
  EXPECT_EQ(probed.Line().rfind("Route = Harris seeds and Adam (measured on", 0), 0u) << probed.Line();
  EXPECT_NE(probed.Line().find("are at most 1e+09 x MaximumGaussians"), std::string::npos) << probed.Line();
  const double p = synthetic::HeldOutPsnr(probe, unseen);
  std::printf("%s\nunseen frames: the rule's grid measured against Adam %.2f dB\n", probed.Line().c_str(), p);
  EXPECT_GE(p, std::max(a, g) - 0.25 * std::abs(a - g));
  EXPECT_NE(
    synthetic::SettingLine(probe.GetReport(), "Validation")
      .find("; joined the fit at step " + std::to_string(probed.DecidedAt) + ", where the route trial took Adam"),
    std::string::npos)
    << synthetic::SettingLine(probe.GetReport(), "Validation");

  // Held out for their own sake too (HoldOutValidationFrames On, as the rule sets it where no sweep's frames share
  // speckle), the trial's frames stay out of the fit after Adam is taken mid-window, until the window's close, as their
  // Validation line says (docs/FINDINGS.md, "The route trial's frames": the spine phantom at 300 s scored 20.67 dB
  // when they joined at the decision, step 200, and 21.38 with them out to the window's close).
  TrainerSettings own = grid;
  own.HeldOut.HoldOutValidationFrames = ValidationHoldOut::On;
  Trainer ownFrames(data, own);
  ASSERT_TRUE(ownFrames.Initialize(&error) && ownFrames.Run(nullptr, nullptr, &error)) << error;
  const TrainerReport& o = ownFrames.GetReport();
  ASSERT_GE(o.Route.DecidedAt, 0);
  EXPECT_FALSE(o.Route.GridChosen);
  EXPECT_LE(o.Route.DecidedAt, own.HeldOut.RouteProbeFraction * own.Iterations + own.Densification.Interval);
  EXPECT_GE(o.ValidationJoinedAt, 0.6 * own.Iterations) << "joined at the window's close, not at the decision";
  EXPECT_EQ(ownFrames.GetData().TrainFrames, data.TrainFrames) << "then joined";
  EXPECT_EQ(synthetic::SettingLine(o, "Validation").find("where the route trial took Adam"), std::string::npos);

  // A run that ends before its frames would join (100 steps: no validation after the window's close) stays Adam's,
  // with every training frame back in the data and the line saying why the route is untested.
  settings.Iterations = 100;
  Trainer shortRun(data, settings);
  ASSERT_TRUE(shortRun.Initialize(&error)) << error;
  ASSERT_TRUE(shortRun.GetReport().Route.Pending);
  ASSERT_TRUE(shortRun.Run(nullptr, nullptr, &error)) << error;
  EXPECT_FALSE(shortRun.GetReport().Route.Pending);
  EXPECT_EQ(shortRun.GetIteration(), 100);
  EXPECT_EQ(shortRun.GetData().TrainFrames, data.TrainFrames);
  EXPECT_NE(
    shortRun.GetReport().Route.Line().find("the run ended before its frames would join the fit"), std::string::npos)
    << shortRun.GetReport().Route.Line();

  // Without a time budget nothing plans the trial: the rule's route, and its line says why.
  settings.TimeBudget = 0;
  settings.Iterations = 50;
  Trainer untested(data, settings);
  ASSERT_TRUE(untested.Initialize(&error)) << error;
  EXPECT_FALSE(untested.GetReport().Route.Pending);
  const std::vector<std::string>& l = untested.GetReport().Settings;
  EXPECT_NE(
    std::find(l.begin(), l.end(),
      "Route = Harris seeds and Adam (the rule: the " + std::to_string(untested.GetReport().Route.FanPixels) +
        " fan pixels of the grid's planes are more than 2 x MaximumGaussians; untested against the pixel "
        "grid: no time budget to plan the measurement in; variable projection and grids at a coarser stride untested: "
        "on the liver, the spine phantom and the volume protocol each scored below Adam alone or the grid of "
        "every fan pixel (docs/BENCHMARKS_pareto.md))"),
    l.end());
}

TEST(HeldOutChoices, AResumedRunHoldsOutTheRouteTrialsFramesWithoutFittingTheGridAgain)
{
  // The route test's sweep and settings: the trial is planned. A run stopped after its checkpoint at step 100, then
  // resumed (SetResuming before Initialize): the resumed run holds out the same frames as the checkpoint's run, does
  // not fit the grid again (no grid seconds), and LoadCheckpoint ends the trial with the reason in its line.
  std::vector<int> unseen;
  const TrainingData data = synthetic::SyntheticSweep(synthetic::KnownField(300, 5), 0.3, unseen);
  TrainerSettings settings = RouteTrialSettings(300);
  settings.CheckpointFile = std::string(BIGUS_TEST_OUTPUT) + "/route-trial.ckpt";
  settings.CheckpointInterval = 100;
  std::string error;
  Trainer first(data, settings);
  ASSERT_TRUE(first.Initialize(&error)) << error;
  ASSERT_TRUE(first.GetReport().Route.Pending) << first.GetReport().Route.Untested;
  EXPECT_GT(first.GetReport().Route.GridSeconds, 0) << "the grid's side was fitted";
  ASSERT_TRUE(first.Run(
    nullptr, [&]() { return first.GetIteration() >= 100; }, &error))
    << error;

  Trainer resumed(data, settings);
  resumed.SetResuming(true);
  ASSERT_TRUE(resumed.Initialize(&error)) << error;
  const RouteTrial& route = resumed.GetReport().Route;
  EXPECT_TRUE(route.Pending);
  EXPECT_EQ(route.GridSeconds, 0) << "the grid is not fitted again";
  EXPECT_EQ(route.Frames, first.GetReport().Route.Frames);
  EXPECT_EQ(resumed.GetReport().ValidationFrames, first.GetReport().ValidationFrames);
  for (int f : route.Frames)
  {
    EXPECT_EQ(std::count(resumed.GetData().TrainFrames.begin(), resumed.GetData().TrainFrames.end(), f), 0)
      << "frame " << f << " is held out of the resumed fit as of the checkpoint's";
  }
  ASSERT_TRUE(resumed.LoadCheckpoint(settings.CheckpointFile, &error)) << error;
  EXPECT_EQ(resumed.GetIteration(), 100);
  EXPECT_FALSE(route.Pending);
  EXPECT_NE(route.Line().find("the run resumed from the checkpoint"), std::string::npos) << route.Line();
  ASSERT_TRUE(resumed.Run(nullptr, nullptr, &error)) << error;
  EXPECT_EQ(resumed.GetIteration(), 300);
}

TEST(HeldOutChoices, TheGridsRouteFitOnMoreFramesScoresTheHeldOutFramesAtLeastAsWellAsItsChoicesFitOnFewer)
{
  // 60 parallel frames 0.2 mm apart through the synthetic field, every one a training frame and a thin beam (sigma_E
  // 0.05 mm): every frame is a plane of the grid. The grid's choices fit every second frame and score the frames
  // between; the route's fit leaves out only those scored frames, so each of them lies in a gap twice the spacing
  // around it. More frames must not score those frames lower (issue 54: more data is never worse): the planes beside a
  // gap take its width as their spacing (GridPlanes::PlaneSpacing). With the sweep's mean spacing they were too thin to
  // bridge it (on a volume sweep 0.217 mm apart: 35.06 dB against the choices' 47.34).
  std::vector<std::array<double, 16>> poses;
  for (int k = 0; k < 60; ++k)
  {
    std::array<double, 16> pose = synthetic::SweepPose(0); // without the rock: parallel frames
    pose[11] = -6.0 + 0.2 * k;
    poses.push_back(pose);
  }
  std::vector<int> unused;
  TrainingData data = RenderedSweep(synthetic::KnownField(300, 5), poses, synthetic::W, synthetic::H, 0.05, unused);
  data.TrainFrames.clear();
  for (int k = 0; k < 60; ++k)
  {
    data.TrainFrames.push_back(k);
  }
  TrainerSettings settings = RouteTrialSettings(1000);
  settings.ElevationSigma = 0.05;
  RouteTrial trial;
  std::string error;
  ASSERT_TRUE(MeasurePixelGridRoute(data, settings, false, trial, &error)) << error;
  ASSERT_TRUE(trial.Untested.empty()) << trial.Untested;
  const HeldOutChoice& ridge = trial.Grid.Ridge;
  ASSERT_GE(ridge.Chosen, 0);
  EXPECT_EQ(trial.Frames, ridge.Frames) << "the same frames scored";
  const double fewer = ridge.Candidates[ridge.Chosen].PSNR;
  std::printf("the grid on every second frame %.2f dB, on every frame but the %zu scored %.2f dB\n", fewer,
    trial.Frames.size(), trial.GridPSNR);
  EXPECT_GE(trial.GridPSNR, fewer - 0.1);
}

TEST(HeldOutChoices, TheGridsSideOfTheRouteTrialStopsWhereItsFitsLeftWouldPassHalfTheBudget)
{
  // Half a budget of 2 ms: the first candidate's fit is started (nothing was spent), none after it. The route is then
  // untested, says why, holds no frame out of the Adam run, and its time is counted.
  const TrainingData data = GridSweep();
  TrainerSettings settings = RouteTrialSettings(1000);
  settings.TimeBudget = 0.004;
  RouteTrial trial;
  std::string error;
  ASSERT_TRUE(MeasurePixelGridRoute(data, settings, true, trial, &error)) << error;
  std::printf("%s\n", trial.Line().c_str());
  EXPECT_NE(trial.Untested.find("its fits stopped after"), std::string::npos) << trial.Untested;
  EXPECT_NE(trial.Line().find("untested against the pixel grid: its fits stopped after"), std::string::npos);
  EXPECT_FALSE(trial.Pending);
  EXPECT_TRUE(trial.Frames.empty());
  EXPECT_GT(trial.GridSeconds, 0.002);
  EXPECT_EQ(trial.Grid.ElevationSigma.Chosen, -1) << "nothing measured is taken";
  EXPECT_EQ(trial.Grid.Ridge.Chosen, -1);
  EXPECT_EQ(trial.Grid.Reduction.Untested, trial.Untested);

  // Where the rule takes the grid (the plan's estimate made to pass), the same stop leaves nothing measured against
  // Adam, so the rule's grid stands: the run seeds every fan pixel and takes no step, and its line says why Adam went
  // untested.
  TrainerSettings byRule = settings;
  byRule.Seeding.PixelGridFanPixelsPerGaussian = 1e9;
  byRule.HeldOut.GridFitSecondsPerGaussian = 1e-12;
  Trainer grid(data, byRule);
  ASSERT_TRUE(grid.Initialize(&error)) << error;
  const RouteTrial& route = grid.GetReport().Route;
  EXPECT_FALSE(route.Pending);
  EXPECT_TRUE(route.GridByRule);
  EXPECT_FALSE(route.AdamProbe);
  EXPECT_EQ(grid.GetReport().InitialGaussians, route.FanPixels) << "the grid of every fan pixel";
  EXPECT_EQ(route.Line().rfind("Route = the pixel grid (the rule: the " + std::to_string(route.FanPixels) +
                " fan pixels of the grid's planes are at most 1e+09 x MaximumGaussians; untested against Harris "
                "seeds and Adam: its fits stopped after",
              0),
    0u)
    << route.Line();
  ASSERT_TRUE(grid.Run(nullptr, nullptr, &error)) << error;
  EXPECT_EQ(grid.GetIteration(), 0);
  EXPECT_EQ(grid.GetData().TrainFrames, data.TrainFrames);

  // The choices alone (a pixel-grid run given a limit): one fit, then every choice untested with the same reason.
  settings.HeldOut.MaximumSeconds = 0.002;
  HeldOutChoices choices;
  ASSERT_TRUE(ChooseOnHeldOutFrames(data, settings, true, true, choices, &error)) << error;
  EXPECT_NE(choices.ElevationSigma.Untested.find("its fits stopped after"), std::string::npos);
  EXPECT_EQ(choices.Ridge.Untested, choices.ElevationSigma.Untested);
  EXPECT_TRUE(choices.ElevationSigma.Candidates.empty());
}

TEST(HeldOutChoices, TheRouteTrialSwitchesToThePixelGridWhereItScoresHigher)
{
  // The same sweep with an Adam route that cannot win: MaximumGaussians 100 (50 seeds), no densification. The grid
  // stays ahead, so the run becomes the pixel grid when the trial's frames would join (the window's close): every
  // training frame at its tracked pose, the grid's own choices, no further step; it renders the unseen frames as the
  // grid alone does.
  std::vector<int> unseen;
  const TrainingData data = synthetic::SyntheticSweep(synthetic::KnownField(300, 5), 0.3, unseen);
  for (PoseRefinement refine : { PoseRefinement::Off, PoseRefinement::Auto })
  {
    TrainerSettings settings;
    settings.ElevationSigma = 0.3;
    settings.MaximumGaussians = 100;
    settings.Densification.Enabled = false;
    settings.Iterations = 1000;
    settings.TimeBudget = 600;
    settings.Poses.RefinePoses = refine; // Auto refines here before the switch, which must take the tracked poses
    std::string error;
    Trainer trainer(data, settings);
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    ASSERT_TRUE(trainer.GetReport().Route.Pending) << trainer.GetReport().Route.Untested;
    ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
    const TrainerReport& report = trainer.GetReport();
    const RouteTrial& route = report.Route;
    const std::string line = synthetic::SettingLine(report, "Route");
    ASSERT_FALSE(line.empty());
    std::printf("%s\n%s\n", line.c_str(), report.StopReason.c_str());
    ASSERT_TRUE(route.GridChosen) << "50 Gaussians without densification cannot fit this sweep";
    EXPECT_EQ(line.rfind("Route = the pixel grid (measured on", 0), 0u) << line;
    EXPECT_GE(route.DecidedAt, 600) << "the grid is taken only when the frames would join";
    EXPECT_EQ(trainer.GetIteration(), route.DecidedAt);
    EXPECT_EQ(trainer.GetData().TrainFrames, data.TrainFrames) << "every training frame in the grid's fit";
    EXPECT_EQ(trainer.GetData().Poses, data.Poses) << "at the tracked poses";
    EXPECT_GT(report.InitialGaussians, settings.MaximumGaussians);
    EXPECT_EQ(report.Solves, 1);

    TrainerSettings grid = settings;
    grid.Seeding.PixelGridFanPixelsPerGaussian = 1e9;
    grid.HeldOut.MeasureRoute = false;
    Trainer gridAlone(data, grid);
    ASSERT_TRUE(gridAlone.Initialize(&error) && gridAlone.Run(nullptr, nullptr, &error)) << error;
    const double switched = synthetic::HeldOutPsnr(trainer, unseen), alone = synthetic::HeldOutPsnr(gridAlone, unseen);
    std::printf("unseen frames: switched to the grid %.2f dB, the grid alone %.2f dB\n", switched, alone);
    EXPECT_NEAR(switched, alone, 0.1);

    // The rule taking the grid and measuring Adam against it: Adam stays below, so the grid is taken at the first
    // validation from a quarter of the schedule on (after the pose trial, where Auto holds one), not at the window's
    // close, and renders as the grid alone does.
    grid.HeldOut.MeasureRoute = true;
    Trainer probe(data, grid);
    ASSERT_TRUE(probe.Initialize(&error) && probe.Run(nullptr, nullptr, &error)) << error;
    const RouteTrial& probed = probe.GetReport().Route;
    std::printf("%s\n", probed.Line().c_str());
    ASSERT_TRUE(probed.GridChosen) << probed.Line();
    EXPECT_GE(probed.DecidedAt, grid.HeldOut.RouteProbeFraction * grid.Iterations);
    if (refine == PoseRefinement::Off)
    {
      EXPECT_EQ(probed.DecidedAt, 400) << "validations every 200 steps: the first from step 250 on";
    }
    EXPECT_LT(probed.DecidedAt, route.DecidedAt) << "before the window's close";
    EXPECT_EQ(probe.GetIteration(), probed.DecidedAt);
    EXPECT_EQ(probed.Line().rfind("Route = the pixel grid (measured on", 0), 0u) << probed.Line();
    EXPECT_NEAR(synthetic::HeldOutPsnr(probe, unseen), alone, 0.1);
  }
}
