// The trainer's loop: end-to-end learning of a known field from a synthetic sweep rendered from it, determinism,
// per-frame masks, training in stages, the time budget, Finish's gap filling and merge, refused poses, sparse Adam,
// backends and their training engines, ablation switches, roll-back, early stopping and short runs on the real
// spine-phantom sweep. The stages have their own files: TestSeeding, TestDensification, TestCheckpoints,
// TestResolutionSchedule, TestDataParallel, TestValidation, TestPoseRefinement, TestReflectivitySolve,
// TestGaussianMerging; the filter vtkGaussianFieldTrainer TestGaussianFieldTrainer.
#include "bigusTestUtilities.h"
#include "bigusBackend.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPolyData.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundSequenceReader.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <random>

using namespace bigus;
using namespace bigus::synthetic;

TEST(Trainer, LearnsAKnownFieldAndRendersHeldOutPosesAbove40dB)
{
  const GaussianField truth = KnownField(400, 3);
  std::vector<int> heldOut;
  TrainingData data = SyntheticSweep(truth, 0.5, heldOut);
  ASSERT_EQ(data.TrainFrames.size(), 45u);
  ASSERT_EQ(heldOut.size(), 15u);
  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.Seeding.InitialGaussians = 3000;
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
  std::printf(
    "held-out PSNR with the artefact bands masked per frame %.2f dB, trained on them %.2f dB\n", withMask, withoutMask);
  EXPECT_GT(withMask, withoutMask + 3);
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
    ASSERT_TRUE(staged.Train(
      nullptr, [&]() { return staged.GetIteration() >= stop; }, &error))
      << error;
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
  s.Densification.End = -1; // 60 % of the schedule
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const TrainerReport& r = trainer.GetReport();
  EXPECT_EQ(r.StopReason, "time budget");
  EXPECT_GE(r.Seconds, 1.5);
  EXPECT_GT(r.Iterations, 100);
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
  s.Seeding.InitialGaussians = 3000;
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

TEST(Trainer, GrowthLeavesRoomUnderTheMaximumForTheGapsCopies)
{
  // The gap of the test above, and a maximum the densification reaches. Growth stops short of it by room for the
  // copies gap filling will add (CountGapCopies, in proportion to the field), so that the gap is bridged by most of
  // them; without that room the field would reach the maximum and the gap be left empty. The copies the trained
  // field needs are counted on the field's first Gaussians (gap filling appends its copies and changes only the
  // reflectivities of the others, which the count does not read): the room is an estimate (the Gaussians near the
  // gap's frames densify faster than the field), so most, not all, are added.
  std::vector<int> unused;
  TrainingData data = SyntheticSweep(KnownField(400, 3), 0.2, unused);
  data.TrainFrames.clear();
  for (int k = 0; k < data.Count(); ++k)
  {
    if (k < 23 || k >= 37)
    {
      data.TrainFrames.push_back(k);
    }
  }
  TrainerSettings s;
  s.ElevationSigma = 0.2;
  s.Seeding.InitialGaussians = 3000;
  s.MaximumGaussians = 5000;
  s.Densification.Percentile = 10; // reaches it within the densification window
  s.Iterations = 1500;
  s.Merge.Tolerance = 0; // the count before the merge is the one the maximum holds
  Trainer trainer(data, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const TrainerReport& r = trainer.GetReport();
  GaussianField trained = trainer.GetField();
  trained.Resize(r.Gaussians - r.GapFilling.Added);
  const std::int64_t needed = CountGapCopies(trained, data, s.ElevationSigma, s.GapFilling);
  GapFillingSettings described = s.GapFilling;
  described.MaximumGaussians = s.MaximumGaussians;
  std::printf("growth: %s; gap filling: %s; %lld of the %lld copies the trained field needs\n",
    r.GrowthStopReason.c_str(), DescribeGapFilling(r.GapFilling, described).c_str(),
    static_cast<long long>(r.GapFilling.Added), static_cast<long long>(needed));
  EXPECT_EQ(r.GrowthStopReason.rfind("hard maximum", 0), 0u) << r.GrowthStopReason;
  EXPECT_NE(r.GrowthStopReason.find("room for the copies gap filling will add"), std::string::npos)
    << r.GrowthStopReason;
  EXPECT_LT(trained.Count(), s.MaximumGaussians - needed / 2) << "growth stopped short of the maximum";
  EXPECT_EQ(r.GapFilling.Gaps, 1);
  EXPECT_EQ(r.GapFilling.Skipped, 0);
  EXPECT_GE(r.GapFilling.Added, 0.6 * needed); // measured: 1519 of 1575
  EXPECT_LE(r.Gaussians, s.MaximumGaussians);
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

TEST(Trainer, ALossOfNoWeightOrANegativeOneIsRefusedBeforeAnySeed)
{
  // All three weights 0: every gradient is 0, so a run would spend its schedule moving nothing (it used to be
  // refused only by `bigus train`; the filter and ParaView took it).
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(100, 5), 0.5, heldOut);
  const struct
  {
    ImageLossWeights Weights;
    const char* Expected;
  } cases[] = { { { 0, 0, 0 }, "are all 0" }, { { 0.8, -0.2, 0 }, "D-SSIM -0.2" }, { { NAN, 0.2, 0 }, "L1 nan" },
    { { 0.8, 0.2, 0, INFINITY }, "FFL alpha inf" } };
  for (const auto& c : cases)
  {
    TrainerSettings s = ShortSettings();
    s.Loss = c.Weights;
    Trainer trainer(data, s);
    std::string error;
    EXPECT_FALSE(trainer.Initialize(&error)) << c.Expected;
    EXPECT_NE(error.find(c.Expected), std::string::npos) << error;
    EXPECT_NE(error.find("image loss"), std::string::npos) << error;
    EXPECT_EQ(trainer.GetState().Gaussians.Field.Count(), 0) << c.Expected;
  }
  // One weight above 0 is enough (D-SSIM alone, FFL alone).
  for (const ImageLossWeights w : { ImageLossWeights{ 0, 1, 0 }, ImageLossWeights{ 0, 0, 1 } })
  {
    std::string error;
    EXPECT_TRUE(CheckImageLossWeights(w, &error)) << error;
  }
}

TEST(Trainer, TheAutomaticCutoffStepsAt3Point5OnTrustedPosesAnd4WherePosesAreRefined)
{
  // The same field stepped from SetField (no seed scale, whose cut-off is the fixed one) for 30 steps: the automatic
  // cut-off's field is bit for bit the field of the cut-off it resolves to, and not the other's.
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(100, 5), 0.5, heldOut);
  const GaussianField start = KnownField(60, 2);
  auto stepped = [&](TrainerSettings s, double cutoff, double* resolved) {
    s.Cutoff = cutoff;
    Trainer trainer(data, s);
    std::string error;
    EXPECT_TRUE(trainer.SetField(start, &error)) << error;
    *resolved = trainer.StepCutoff();
    // Validation and the final prune keep one cut-off whatever the step's: the given one, else 4.
    EXPECT_EQ(trainer.Options().Cutoff, cutoff > 0 ? cutoff : FineTrainingCutoff);
    double loss = 0;
    for (int k = 0; k < 30; ++k)
    {
      EXPECT_EQ(trainer.Step(&loss, &error), StepStatus::Done) << error;
    }
    return trainer.GetField().Means;
  };
  TrainerSettings trusted = ShortSettings(); // RefinePoses Off, Adam alone
  TrainerSettings refined = ShortSettings();
  refined.Poses.RefinePoses = PoseRefinement::On;
  refined.Poses.Start = 0;
  TrainerSettings solved = ShortSettings();
  solved.ReflectivitySolve = true;
  double k = 0, given = 0;
  const std::vector<float> automatic = stepped(trusted, 0, &k);
  EXPECT_EQ(k, FastTrainingCutoff);
  EXPECT_EQ(automatic, stepped(trusted, FastTrainingCutoff, &given));
  EXPECT_NE(automatic, stepped(trusted, FineTrainingCutoff, &given));
  const std::vector<float> automaticRefined = stepped(refined, 0, &k);
  EXPECT_EQ(k, FineTrainingCutoff);
  EXPECT_EQ(automaticRefined, stepped(refined, FineTrainingCutoff, &given));
  EXPECT_NE(automaticRefined, stepped(refined, FastTrainingCutoff, &given));
  // Refined from half the schedule: no pose moves in the first 30 steps, which are the 3.5 field's; from step 100
  // the poses move and the cut-off is 4.
  TrainerSettings later = refined;
  later.Poses.Start = 0.5;
  const std::vector<float> automaticBefore = stepped(later, 0, &k);
  EXPECT_EQ(k, FastTrainingCutoff);
  EXPECT_EQ(automaticBefore, stepped(later, FastTrainingCutoff, &given));
  EXPECT_NE(automaticBefore, stepped(later, FineTrainingCutoff, &given));
  {
    Trainer trainer(data, later);
    std::string error;
    ASSERT_TRUE(trainer.SetField(start, &error)) << error;
    double loss = 0;
    while (trainer.GetState().Iteration < 100 && trainer.Step(&loss, &error) == StepStatus::Done)
    {
      EXPECT_EQ(trainer.StepCutoff(), trainer.GetState().Iteration < 100 ? FastTrainingCutoff : FineTrainingCutoff);
    }
    EXPECT_EQ(trainer.GetState().Iteration, 100) << error;
  }
  stepped(solved, 0, &k);
  EXPECT_EQ(k, FineTrainingCutoff);
  stepped(trusted, 4.5, &k); // a given cut-off is the step's
  EXPECT_EQ(k, 4.5);
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
      for (const auto& [a, b] :
        { std::make_pair(&after.Field, &state.Field), std::make_pair(&after.FirstMoment, &state.FirstMoment),
          std::make_pair(&after.SecondMoment, &state.SecondMoment) })
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

namespace
{
/// The CPU renderer under the name of a test backend that brings its own training engine.
class EngineBackendRenderer : public Renderer
{
public:
  explicit EngineBackendRenderer(const char* name)
    : Name(name)
  {}
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
  EXPECT_NE(
    error.find("training engine of backend 'broken-engine' cannot be used: the device has no room"), std::string::npos)
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
  vtkSmartPointer<vtkImageData> sequence =
    bigus_test::TrackedSequence(W, H, data.Poses, std::vector<double>(data.Count(), 0.0),
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
      case 0:
        s.Seeding.HarrisInitialisation = false;
        break;
      case 1:
        s.Densification.Enabled = false;
        break;
      case 2:
        s.BeamIntegration = false;
        break;
      case 3:
        s.NonNegativeReflectivity = true;
        break;
      case 4:
        s.Loss.DSSIM = 0;
        s.Loss.FFL = 0;
        break;
      case 5:
        s.Loss.L1 = 0;
        break;
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
    const bool fillsGaps = std::any_of(
      lines.begin(), lines.end(), [](const std::string& line) { return line.rfind("FillGaps = on", 0) == 0; });
    EXPECT_EQ(fillsGaps, s.BeamIntegration) << names[variant];
  }
}

TEST(Trainer, DivergingStepsAreRolledBackNeverWrittenIntoTheField)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(100, 8), 0.5, heldOut);
  TrainerSettings s = ShortSettings();
  s.Iterations = 60;
  s.Densification.Enabled = false;
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
  s.Seeding.InitialGaussians = 10000;
  s.Iterations = iterations;
  s.Densification.Start = 100;
  s.Densification.Interval = 100;
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
    ASSERT_TRUE(
      renderer->Forward(trainer.GetField().View(), &g, 1, trainer.Options(), S.data(), I.data(), nullptr, nullptr));
    const float* truth = &data.Frames[pixels * k];
    int best = data.TrainFrames.front();
    double bestDistance = 1e300;
    for (int t : data.TrainFrames)
    {
      double c[2][3];
      for (int r2 = 0; r2 < 3; ++r2)
      {
        c[0][r2] = data.Poses[k][4 * r2] * data.Width / 2 + data.Poses[k][4 * r2 + 1] * data.Height / 2 +
          data.Poses[k][4 * r2 + 3];
        c[1][r2] = data.Poses[t][4 * r2] * data.Width / 2 + data.Poses[t][4 * r2 + 1] * data.Height / 2 +
          data.Poses[t][4 * r2 + 3];
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

// The spine phantom's neighbouring training frames share no speckle (correlation 0.05 at their 1.85 mm): by
// default its validation frames are held out of the fit (HoldOutValidationByRule), one in 4 of its 16 training frames
// as one in 8 gives 2 (SparseValidationStride), and the Validation line says why. Asked for, training frames decide.
TEST(Trainer, TheSpinePhantomsUncorrelatedFramesAreValidatedOnFramesHeldOutOfTheFit)
{
  std::vector<int> heldOut;
  const TrainingData data = SpineData(heldOut);
  for (const ValidationHoldOut asked : { ValidationHoldOut::Auto, ValidationHoldOut::Off })
  {
    TrainerSettings s = SpineSettings(300);
    s.HeldOut.HoldOutValidationFrames = asked;
    Trainer trainer(data, s);
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    const TrainerReport& r = trainer.GetReport();
    const std::string line = SettingLine(r, "Validation");
    if (asked == ValidationHoldOut::Off)
    {
      EXPECT_FALSE(r.ValidationHeldOut) << line;
      EXPECT_EQ(trainer.GetData().TrainFrames, data.TrainFrames);
      EXPECT_EQ(line.find("the rule"), std::string::npos) << line;
      continue;
    }
    EXPECT_EQ(trainer.GetSettings().HeldOut.HoldOutValidationFrames, ValidationHoldOut::On);
    ASSERT_TRUE(r.ValidationHeldOut) << line;
    // Every 4th of the training frames from the 2nd, never the first or the last: the sweep's frames 3, 8, 13, 19.
    EXPECT_EQ(r.ValidationFrames,
      (std::vector<int>{ data.TrainFrames[2], data.TrainFrames[6], data.TrainFrames[10], data.TrainFrames[14] }));
    EXPECT_EQ(trainer.GetData().TrainFrames.size(), data.TrainFrames.size() - 4);
    for (const char* part : { "Validation = 4 held-out frames (one in 4 training frames of a sweep, at most 8)",
           "; held out by the rule, as no sweep's training frames share speckle: speckle correlation 0.0", " < 0.3" })
    {
      EXPECT_NE(line.find(part), std::string::npos) << part << " not in " << line;
    }
  }
  // Its first 8 training frames alone: one in 4 gives 2, too few; the training frames decide and the line says why.
  TrainingData few = data;
  few.TrainFrames.resize(8);
  Trainer trainer(few, SpineSettings(300));
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  const std::string line = SettingLine(trainer.GetReport(), "Validation");
  EXPECT_FALSE(trainer.GetReport().ValidationHeldOut) << line;
  EXPECT_EQ(line.rfind("Validation = 8 training frames (too few training frames to hold 4 out); the rule would hold "
                       "them out, as no sweep's training frames share speckle: speckle correlation ",
              0),
    0u)
    << line;
}

// The measured tail: on the spine phantom the held-out validation frames score step 600's field above step 700's (the
// steps after it overfit the 12 training frames), so when they join the fit at step 700 the run returns to that field
// and goes on as many steps as it took to it, then stops with the last step's field. A run resumed from a checkpoint
// written in the tail, or between the window's close and the join, stops where the straight run did, with the same
// field; off, the run goes on past the tail.
TEST(Trainer, WhereTheHeldOutFramesScoredAnEarlierFieldTheRunStopsAfterAsManyStepsAsItTook)
{
  std::vector<int> heldOut;
  const TrainingData data = SpineData(heldOut);
  TrainerSettings s = SpineSettings(1400);
  s.Densification.End = 650; // the frames join at the next validation, step 700
  std::string error;
  Trainer straight(data, s);
  ASSERT_TRUE(straight.Initialize(&error)) << error;
  ASSERT_TRUE(straight.GetReport().ValidationHeldOut);
  EXPECT_NE(SettingLine(straight.GetReport(), "Validation")
              .find("the run stops as many steps after the join as the fit took to that field (measured tail)"),
    std::string::npos);
  // Written after the window's close (650) before the join (700), and 20 steps into the tail; then on to its end.
  const std::string output = BIGUS_TEST_OUTPUT;
  const std::vector<std::pair<int, std::string>> checkpoints = { { 660, output + "/before_join.ckpt" },
    { 720, output + "/tail.ckpt" } };
  for (const auto& [at, file] : checkpoints)
  {
    ASSERT_TRUE(straight.Train(
      nullptr, [&, at = at]() { return straight.GetIteration() >= at; }, &error))
      << error;
    ASSERT_TRUE(straight.SaveCheckpoint(file, &error)) << error;
  }
  ASSERT_TRUE(straight.Run(nullptr, nullptr, &error)) << error;
  const TrainerReport& r = straight.GetReport();
  const int joined = r.ValidationJoinedAt, best = straight.GetState().BestFieldIteration;
  std::printf(
    "joined at %d, best field of step %d, stopped at %d: %s\n", joined, best, r.Iterations, r.StopReason.c_str());
  ASSERT_EQ(joined, 700);
  ASSERT_EQ(best, 600) << "the held-out frames' best field";
  EXPECT_EQ(straight.GetState().MeasuredTailEnd, 1300);
  EXPECT_EQ(r.Iterations, 1300);
  EXPECT_EQ(r.StopReason,
    "measured tail (600 steps after the held-out validation frames joined the fit at step 700, as many as the fit "
    "took to the field they scored best)");
  EXPECT_EQ(r.AverageSamples, 0) << "the tail's field is its last step's";
  EXPECT_NE(SettingLine(r, "ParameterAverage")
              .find("; not taken: the run ended with its measured tail of 600 steps from the join at step 700"),
    std::string::npos);

  for (const auto& [at, file] : checkpoints)
  {
    Trainer resumed(data, s);
    ASSERT_TRUE(resumed.Initialize(&error)) << error;
    ASSERT_TRUE(resumed.LoadCheckpoint(file, &error)) << error;
    EXPECT_EQ(resumed.GetState().MeasuredTailEnd, at < joined ? -1 : 1300) << at;
    EXPECT_EQ(resumed.GetReport().ValidationJoinedAt, at < joined ? -1 : joined) << at;
    ASSERT_TRUE(resumed.Run(nullptr, nullptr, &error)) << error;
    EXPECT_EQ(resumed.GetReport().Iterations, 1300) << at;
    EXPECT_EQ(resumed.GetReport().StopReason, r.StopReason) << at;
    EXPECT_EQ(resumed.GetReport().ValidationJoinedAt, joined) << at;
    ExpectSameField(resumed.GetField(), straight.GetField());
    if (at > joined)
    {
      // Trained again once stopped: it stops at once, and the ParameterAverage line says "not taken" once.
      ASSERT_TRUE(resumed.Train(nullptr, nullptr, &error)) << error;
      EXPECT_EQ(resumed.GetReport().Iterations, 1300);
      const std::string average = SettingLine(resumed.GetReport(), "ParameterAverage");
      EXPECT_EQ(average.find("not taken"), average.rfind("not taken")) << average;
      // A schedule that ends before the tail: the schedule ends the run, its field the parameter average, as before.
      TrainerSettings shorter = s;
      shorter.Iterations = 800;
      Trainer early(data, shorter);
      ASSERT_TRUE(early.Initialize(&error)) << error;
      ASSERT_TRUE(early.LoadCheckpoint(file, &error)) << error;
      ASSERT_TRUE(early.Run(nullptr, nullptr, &error)) << error;
      EXPECT_EQ(early.GetReport().StopReason, "iterations");
      EXPECT_EQ(early.GetReport().Iterations, 800);
      EXPECT_GT(early.GetReport().AverageSamples, 0) << SettingLine(early.GetReport(), "ParameterAverage");
      EXPECT_EQ(SettingLine(early.GetReport(), "ParameterAverage").find("not taken"), std::string::npos);
    }
    std::remove(file.c_str());
  }

  // Off: the same run returns to step 600's field at the join and sets no end (the schedule's decides).
  s.HeldOut.MeasuredTail = false;
  Trainer going(data, s);
  ASSERT_TRUE(going.Initialize(&error)) << error;
  ASSERT_TRUE(going.Train(
    nullptr, [&]() { return going.GetIteration() > joined; }, &error))
    << error;
  EXPECT_EQ(going.GetReport().ValidationJoinedAt, joined);
  EXPECT_EQ(going.GetState().BestFieldIteration, best);
  EXPECT_EQ(going.GetState().MeasuredTailEnd, -1);
  EXPECT_EQ(SettingLine(going.GetReport(), "Validation").find("measured tail"), std::string::npos);
}

// Early stopping: the field Finish keeps is the best the run passed through on the validation frames,
// so a run twice as long (same seed, its schedule stretched) never ends with a higher validation loss. On training
// frames (the spine's are held out by default, HoldOutValidationByRule, and measured after they join decide nothing).
TEST(Trainer, ARunTwiceAsLongNeverEndsWorseOnTheValidationFrames)
{
  std::vector<int> heldOut;
  const TrainingData data = SpineData(heldOut);
  double validation[2] = { 0, 0 };
  for (int run = 0; run < 2; ++run)
  {
    TrainerSettings s = SpineSettings(300 * (run + 1));
    s.HeldOut.HoldOutValidationFrames = ValidationHoldOut::Off;
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

TEST(Trainer, VariableProjectionEndsWithALowerTrainingLossThanAdamAloneOnTheSpinePhantom)
{
  // The same seed and the same 300 steps (equal steps, not equal time: a test never depends on the
  // clock; the solves cost extra time, measured in the note), with and without the solve, every training
  // frame fitted throughout (validation on training frames).
  std::vector<int> heldOut;
  const TrainingData data = SpineData(heldOut);
  double loss[2];
  for (int solve = 0; solve < 2; ++solve)
  {
    TrainerSettings s = SpineSettings(300);
    s.HeldOut.HoldOutValidationFrames = ValidationHoldOut::Off;
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
