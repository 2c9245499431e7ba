// The BIGUS training loop (see bigusTrainer.h and DESIGN section 4).
#include "bigusTrainer.h"

#include "bigusGaussianMath.h"
#include "bigusSeeding.h"
#include "bigusSliceFrame.h"

#include "vtkSMPTools.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <numeric>
#include <sstream>

namespace bigus
{

namespace
{
constexpr int SnapshotInterval = 100;
constexpr int DefaultIterations = 3000; // the schedule when neither iterations nor a time budget is given
// Variable projection with a TimeBudget: a solve may take this share of the budget left when it starts. The
// liver, 30 s (docs/FINDINGS.md): the first solve took the whole budget before (0 steps, 18.04 dB held out);
// shares 0.25 / 0.1 / 0.03 gave 23.58 / 22.64 / 22.44 dB (a solve costs at least its setup and one iteration,
// so a smaller share leaves no more steps).
constexpr double SolveShareOfRemainingBudget = 0.25;
constexpr double MinimumScaleMm = 1e-3;
constexpr double MaximumScaleMm = 100.0;

}

// ------------------------------------------------------------------------------------------------

double PixelSpacingOf(const std::array<double, 16>& pose)
{
  SliceFrame frame;
  ComputeSliceFrame(pose.data(), 90, frame);
  return 0.5 * (frame.spacing[0] + frame.spacing[1]);
}

// ------------------------------------------------------------------------------------------------

Trainer::Trainer(TrainingData data, const TrainerSettings& settings, std::unique_ptr<TrainingEngine> engine)
  : Data(new TrainingData(std::move(data)))
  , Settings(settings)
  , Engine(engine ? std::move(engine) : CreateTrainingEngine("cpu", nullptr))
{
  this->State.Random.seed(settings.Seed);
  this->Settings.FramesPerStep = std::max(1, this->Settings.FramesPerStep);
  if (this->Settings.Iterations <= 0 && this->Settings.TimeBudget <= 0)
  {
    this->Settings.Iterations = DefaultIterations;
  }
  if (!this->Data->TrainFrames.empty())
  {
    double spacing = 0;
    for (int f : this->Data->TrainFrames)
    {
      spacing += PixelSpacingOf(this->Data->Poses[f]);
    }
    this->PixelSpacing = spacing / this->Data->TrainFrames.size();
  }
  // The speckle decorrelation of each sweep, measured once for the choices below that need it.
  std::vector<SweepDecorrelation> measured;
  auto measuredSweeps = [&]() -> const std::vector<SweepDecorrelation>& {
    if (measured.empty())
    {
      measured = MeasureSweeps(*this->Data);
    }
    return measured;
  };
  if (this->Settings.ElevationSigma > 0)
  {
    this->Report.Settings.push_back(vtkfmt::sprintf("ElevationSigma = %.4g mm (given)", this->Settings.ElevationSigma));
  }
  else
  {
    const ElevationSigmaChoice choice = ChooseElevationSigma(measuredSweeps());
    this->Settings.ElevationSigma = choice.Sigma;
    this->SigmaByRule = true;
    this->Report.Settings.push_back(
      vtkfmt::sprintf("ElevationSigma = %.4g mm (chosen: ", choice.Sigma) + choice.Reason + ")");
  }
  this->Report.ElevationSigma = this->Settings.ElevationSigma;
  const TrainerSettings& s = this->Settings;
  std::string schedule = s.Iterations > 0 ? vtkfmt::sprintf("Iterations = %d", s.Iterations) : "Iterations = no limit";
  if (s.TimeBudget > 0)
  {
    schedule += vtkfmt::sprintf(", TimeBudget = %.4g s (", s.TimeBudget) +
      (s.Iterations > 0 ? "whichever ends first; " : "") + "the schedule follows the one further along)";
  }
  this->Report.Settings.push_back(schedule);
  this->Report.Settings.push_back(DescribeDensification(s.Densification, s.MaximumGaussians));
  this->Report.Settings.push_back(DescribeGapFillingSettings(s.FillGaps, s.BeamIntegration, s.GapFilling));
  this->Report.Settings.push_back(DescribeGaussianMergeSettings(s.Merge));
  this->Report.Settings.push_back(
    DescribeReflectivitySolve(s.ReflectivitySolve, s.NonNegativeReflectivity, s.Solve, s.SolveInterval));
  this->Report.Settings.push_back(vtkfmt::sprintf("Seed = %u, FramesPerStep = %d, Cutoff = %.3g, SparseAdam = %s%s",
    s.Seed, s.FramesPerStep, s.Cutoff, s.SparseAdam ? "on" : "off",
    s.CoarseFraction > 0
      ? vtkfmt::sprintf(", CoarseFraction = %.3g (a quarter of the pixels per step until then, %s)", s.CoarseFraction,
          s.CoarseLowPass ? "2 x 2 averages through the pixel's low-pass" : "point samples")
          .c_str()
      : ""));
  this->Poses.Configure(this->Data.get(), s.Poses, measuredSweeps, this->State, this->Report.Settings);
  this->Settings.Poses = this->Poses.GetSettings();
  this->Engine->SetData(this->Data.get(), nullptr);
}

Trainer::~Trainer() = default;
Trainer::Trainer(Trainer&&) noexcept = default;
Trainer& Trainer::operator=(Trainer&&) noexcept = default;

RenderOptions Trainer::Options() const
{
  RenderOptions o;
  o.ElevationSigma = this->Settings.ElevationSigma;
  o.BeamIntegration = this->Settings.BeamIntegration;
  o.NonNegativeReflectivity = this->Settings.NonNegativeReflectivity;
  o.Cutoff = this->Settings.Cutoff;
  o.Gamma = this->Gamma;
  return o;
}

bool Trainer::PullState(std::string* error) const
{
  if (!this->HostCurrent && !this->Engine->Pull(this->State.Gaussians, error))
  {
    return false;
  }
  this->HostCurrent = true;
  return true;
}

bool Trainer::PushState(std::string* error)
{
  this->HostCurrent = true;
  return this->Engine->Push(this->State.Gaussians, error);
}

const GaussianField& Trainer::GetField() const
{
  return this->GetState().Gaussians.Field;
}

const TrainingState& Trainer::GetState() const
{
  std::string error;
  if (!this->PullState(&error))
  {
    // Only a device engine can fail here, and its last good host copy is the best answer left.
    std::fprintf(
      stderr, "bigus: cannot read the field back from the %s engine: %s\n", this->Engine->GetName(), error.c_str());
  }
  return this->State;
}

bool Trainer::Initialize(std::string* error)
{
  const bool prepared = this->PrepareInitialField(error);
  // Data-parallel: what PrepareInitialField checks is this process's own (its copy of the data, its machine's
  // memory), so every process learns of a failure here instead of waiting for the failed one in the first sum.
  return this->Agree(prepared, error) && this->FitInitialReflectivities(error);
}

bool Trainer::PrepareInitialField(std::string* error)
{
  const TrainingData& data = *this->Data;
  std::int64_t count = 0;
  if (!CheckTrainingData(data, error) || !this->Poses.Prepare(error))
  {
    return false;
  }
  const double mean = MeanFanIntensity(data, count);
  if (count == 0)
  {
    if (error)
    {
      *error = "the fan mask is empty";
    }
    return false;
  }
  this->Gamma = GammaFromMeanIntensity(mean);
  this->Report.Settings.push_back(
    vtkfmt::sprintf("Gamma = %.5g (from the mean fan intensity %.4f of the training frames)", this->Gamma, mean));
  const SeedShape shape = this->SeedShapeOf();
  SeedingPlan plan;
  if (!PlanSeeding(data, this->Settings.Seeding, this->Settings.MaximumGaussians,
        this->Settings.NonNegativeReflectivity, shape, count, plan, error))
  {
    return false;
  }
  if (this->SigmaByRule && !this->MeasureElevationSigma(count, plan, error))
  {
    return false;
  }
  this->PixelGrid = plan.PixelGrid;
  // A field that could not grow to MaximumGaussians in this machine's memory is refused before any seed is
  // made (the training frames are already held).
  const std::int64_t trainingPixels = std::int64_t(data.Width) * data.Height * std::int64_t(data.TrainFrames.size());
  const std::int64_t maximum = this->Settings.MaximumGaussians;
  if (!CheckTrainingMemory(
        maximum, this->SolvesReflectivities() ? ReflectivitySolveBytes(maximum, trainingPixels) : 0.0, error))
  {
    return false;
  }
  GaussianField& field = this->State.Gaussians.Field;
  this->Report.Settings.push_back(
    SeedField(data, plan, this->Settings.Seeding, shape, this->Settings.Seed, this->Settings.Solve.L1, field));
  this->Report.InitialGaussians =
    plan.PixelGrid || this->Settings.Seeding.DenseInitialisation ? field.Count() : plan.Count;
  if (plan.PixelGrid)
  {
    // No step, so no pose correction: the tracked poses stay, and the field says so (no RefinedPoses).
    this->Poses.TurnOffCorrections(
      this->State, this->Report.Settings, "the pixel-grid fit takes no step to refine the poses with");
    this->Settings.Poses = this->Poses.GetSettings();
  }
  return true;
}

bool Trainer::FitInitialReflectivities(std::string* error)
{
  if (!this->PushState(error))
  {
    return false;
  }
  if (!this->SolvesReflectivities())
  {
    return this->FitReflectivityScale(error);
  }
  // The first solve is training, not seeding: its time counts towards TimeBudget like the later ones.
  if (!this->SolveFieldReflectivities(error))
  {
    return false;
  }
  double seconds = this->Report.LastSolve.Seconds; // the slowest process's, so that every schedule agrees
  if (this->Reduction && !this->Reduction->Maximum(&seconds, 1, error))
  {
    return false;
  }
  this->State.TrainingSeconds += seconds;
  this->Report.Seconds += seconds;
  return true;
}

bool Trainer::Agree(bool ok, std::string* error)
{
  return this->Reduction ? this->Reduction->AllSucceeded(ok, error) : ok;
}

bool Trainer::SetProcessReduction(ProcessReduction* reduction, std::string* error)
{
  if (!this->Engine->SetReduction(reduction, error))
  {
    return false;
  }
  this->Reduction = reduction && reduction->Size() > 1 ? reduction : nullptr;
  if (this->Reduction)
  {
    this->Report.Settings.push_back(
      vtkfmt::sprintf("Processes = %d (data-parallel: each renders its share of the %d frames "
                      "of a step, FramesPerStep %d per process; gradients summed every step)",
        reduction->Size(), reduction->Size() * this->Settings.FramesPerStep, this->Settings.FramesPerStep));
  }
  return true;
}

bool Trainer::SolveFieldReflectivities(std::string* error)
{
  if (!this->PullState(error))
  {
    return false;
  }
  // With a TimeBudget: the pixel-grid fit is the whole run; variable projection leaves the rest to the steps
  // between solves.
  const auto timeLimit = [this]() {
    return this->Settings.TimeBudget <= 0 ? 0.0
                                          : (this->PixelGrid ? 1.0 : SolveShareOfRemainingBudget) *
        std::max(1e-3, this->Settings.TimeBudget - this->TrainingSeconds());
  };
  FieldSolveReport solved;
  TrainerReport& r = this->Report;
  solved.L1Part = r.LastL1Solve;
  solved.L1Removed = r.LastL1Removed;
  const bool ok = bigus::SolveFieldReflectivities(*this->Engine, *this->Data, this->Options(), this->Settings.Solve,
    timeLimit, this->Gamma, this->State.Gaussians, solved, error, this->Reduction);
  this->HostCurrent = true; // the engine holds the host's field, or the step that failed left nothing to pull
  if (!ok)
  {
    return false;
  }
  r.LastSolve = solved.Last;
  r.LastL1Solve = solved.L1Part;
  r.LastL1Removed = solved.L1Removed;
  r.SolveSeconds += solved.Last.Seconds;
  r.Solves += 1;
  return this->PushState(error);
}

bool Trainer::SetField(const GaussianField& field, std::string* error)
{
  this->State.Gaussians = OptimizerState();
  this->State.Gaussians.Field = field;
  this->State.Gaussians.ResizeToField();
  this->State.BestField = GaussianField();
  this->State.BestFieldLoss = -1;
  this->PixelGrid = false;
  return this->PushState(error);
}

SeedShape Trainer::SeedShapeOf() const
{
  SeedShape shape;
  shape.PixelSpacing = this->PixelSpacing;
  shape.InPlaneScale = this->Settings.Seeding.InitialScalePixels * this->PixelSpacing;
  shape.ElevationSigma = this->Settings.BeamIntegration ? this->Settings.ElevationSigma : 0.0;
  shape.ElevationScale = shape.ElevationSigma > 0 ? shape.ElevationSigma : this->PixelSpacing;
  shape.UniformShare = this->Settings.Seeding.UniformShare;
  shape.Gamma = this->Gamma;
  return shape;
}

bool Trainer::MeasureElevationSigma(std::int64_t fanPixels, SeedingPlan& plan, std::string* error)
{
  const double rule = this->Settings.ElevationSigma;
  HeldOutChoice& choice = this->Report.ElevationSigmaChoice;
  if (!ElevationSigmaOnHeldOutFrames(*this->Data, this->Settings, plan.PixelGrid, rule, choice, error))
  {
    return false;
  }
  const double sigma = choice.Chosen < 0 ? rule : choice.Candidates[choice.Chosen].Value;
  for (std::string& line : this->Report.Settings)
  {
    line = line.rfind("ElevationSigma = ", 0) == 0 ? choice.SettingLine(line, "ElevationSigma", "mm") : line;
  }
  if (sigma == rule)
  {
    return true;
  }
  // The seeding plan of the chosen sigma (the grid's elevation scale follows it).
  this->Settings.ElevationSigma = sigma;
  this->Report.ElevationSigma = sigma;
  return PlanSeeding(*this->Data, this->Settings.Seeding, this->Settings.MaximumGaussians,
    this->Settings.NonNegativeReflectivity, this->SeedShapeOf(), fanPixels, plan, error);
}

bool Trainer::FitReflectivityScale(std::string* error)
{
  bool scaled = false;
  return ScaleSeedReflectivities(
           *this->Engine, *this->Data, this->Options(), this->Gamma, this->State.Gaussians.Field, scaled, error) &&
    (!scaled || this->PushState(error));
}

double Trainer::TrainingSeconds() const
{
  return this->TrainStart > 0
    ? this->TrainedBefore + (this->Reduction ? this->AgreedElapsed : SteadySeconds() - this->TrainStart)
    : this->State.TrainingSeconds;
}

double Trainer::ScheduleFraction() const
{
  const TrainerSettings& s = this->Settings;
  double f = s.Iterations > 0 ? double(this->State.Iteration) / s.Iterations : 0.0;
  if (s.TimeBudget > 0)
  {
    f = std::max(f, this->TrainingSeconds() / s.TimeBudget);
  }
  return std::min(1.0, f);
}

double Trainer::MeanLearningRateAt(double fraction) const
{
  return this->Settings.MeanLearningRate *
    std::pow(this->Settings.MeanLearningRateFinal / this->Settings.MeanLearningRate, fraction);
}

bool Trainer::InDensificationWindow() const
{
  const TrainerSettings& s = this->Settings;
  return s.Densification.End >= 0 ? this->State.Iteration <= s.Densification.End
                                  : this->ScheduleFraction() <= DensifyEndFraction;
}

StepStatus Trainer::Step(double* loss, std::string* error)
{
  TrainingState& state = this->State;
  const std::vector<int>& train = this->Data->TrainFrames;
  std::vector<int> frames(this->Settings.FramesPerStep * (this->Reduction ? this->Reduction->Size() : 1));
  for (int& f : frames)
  {
    f = train[static_cast<std::size_t>(UniformDouble(state.Random) * train.size())];
  }
  StepRequest request;
  request.Frames = frames.data();
  request.Count = static_cast<int>(frames.size());
  request.Iteration = state.Iteration;
  const double scale = state.LearningRateScale;
  const double fraction = this->ScheduleFraction();
  request.MeanRate = scale * this->MeanLearningRateAt(fraction);
  request.LogScaleRate = scale * this->Settings.LogScaleLearningRate;
  request.QuaternionRate = scale * this->Settings.QuaternionLearningRate;
  request.ReflectivityRate = scale * this->Settings.ReflectivityLearningRate;
  request.MinimumLogScale = std::log(MinimumScaleMm);
  request.MaximumLogScale = std::log(MaximumScaleMm);
  request.Options = this->Options();
  request.Loss = this->Settings.Loss;
  request.SparseAdam = this->Settings.SparseAdam;
  // The resolution schedule's coarse steps: the frames on every second pixel and row, at a random phase (frames
  // narrower than 2 pixels, or 3 for averages, a whole 2 x 2 block at either phase, keep every pixel).
  const int smallest = this->Settings.CoarseLowPass ? 3 : 2;
  const bool coarse =
    fraction < this->Settings.CoarseFraction && this->Data->Width >= smallest && this->Data->Height >= smallest;
  TrainingData decimated;
  int phase = 0;
  if (coarse)
  {
    phase = static_cast<int>(UniformDouble(state.Random) * 4);
    decimated =
      DecimateFrames(*this->Data, frames.data(), request.Count, phase & 1, phase >> 1, this->Settings.CoarseLowPass);
    request.Data = &decimated;
    request.Frames = decimated.TrainFrames.data();
  }
  const bool refine = this->Poses.RefinesAt(fraction);
  std::vector<double> poseGradients(refine ? 6 * frames.size() : 0);
  request.PoseGradients = refine ? poseGradients.data() : nullptr;
  this->HostCurrent = false;
  const StepStatus status = this->Engine->Step(request, loss, error);
  if (status == StepStatus::Failed)
  {
    return status;
  }
  ++state.Iteration;
  if (status == StepStatus::NonFinite)
  {
    // Never keep a non-finite step in the field: back to the last good state, half the rates.
    this->Engine->Restore();
    state.LearningRateScale *= 0.5;
    state.RolledBackSteps += 1;
    *loss = std::numeric_limits<double>::quiet_NaN();
    return status;
  }
  if (state.Iteration % SnapshotInterval == 0)
  {
    this->Engine->Snapshot();
  }
  if (refine)
  {
    for (std::size_t k = 0; coarse && k < frames.size(); ++k)
    {
      DecimatedPoseGradientToSource(
        *this->Data, frames[k], phase & 1, phase >> 1, &poseGradients[6 * k], this->Settings.CoarseLowPass);
    }
    this->Poses.Step(frames, poseGradients, state.LearningRateScale, state);
  }
  state.LossHistory.push_back(*loss);
  return status;
}

bool Trainer::ValidationLoss(double& loss, std::string* error)
{
  return bigus::ValidationLoss(*this->Engine, *this->Data, ValidationFrames(*this->Data), this->Options(),
    this->Settings.Loss, this->Reduction, loss, error);
}

bool Trainer::CheckValidation(double& loss, std::string* error)
{
  if (!this->ValidationLoss(loss, error))
  {
    return false;
  }
  this->Report.ValidationHistory.push_back({ this->State.Iteration, loss, this->State.Gaussians.Count() });
  KeepIfBest(this->State, loss, this->GetField());
  return true;
}

bool Trainer::DensifyAndPrune(double validation, std::string* error)
{
  TrainingState& state = this->State;
  const DensificationSettings& d = this->Settings.Densification;
  const std::string stopped = UpdateGrowth(state, validation, d);
  if (!stopped.empty())
  {
    this->Report.GrowthStopReason = stopped;
  }
  if (!this->PullState(error))
  {
    return false;
  }
  // Image-GS's new Gaussians from the residual: rendered before densification changes the field.
  std::vector<int> residualFrames;
  std::vector<float> residuals;
  if (d.ResidualSeedShare > 0 && d.ResidualSeedFrames > 0 && state.Growing &&
    !RenderResiduals(*this->Engine, *this->Data, this->Options(), this->Gamma, d.ResidualSeedFrames, state.Random,
      residualFrames, residuals, error))
  {
    return false;
  }
  const DensificationResult result = bigus::DensifyAndPrune(state.Gaussians, state.Growing, d.Percentile,
    this->Settings.MaximumGaussians, d.SplitScalePixels * this->PixelSpacing, d.PruneReflectivity);
  if (!residualFrames.empty() && result.Added > 0)
  {
    const std::int64_t room = this->Settings.MaximumGaussians - state.Gaussians.Count();
    SeedResiduals(*this->Data, residualFrames, residuals,
      std::min<std::int64_t>(room, std::llround(d.ResidualSeedShare * result.Added)), state.Random, this->SeedShapeOf(),
      state.Gaussians.Field);
    state.Gaussians.ResizeToField();
  }
  if (state.Growing && result.MaximumReached)
  {
    state.Growing = false;
    this->Report.GrowthStopReason = "hard maximum of " + std::to_string(this->Settings.MaximumGaussians) +
      " Gaussians reached (iteration " + std::to_string(state.Iteration) + ")";
  }
  return this->PushState(error);
}

void Trainer::PlaceUntrainedFrames()
{
  this->Report.UntrainedCorrections = this->Poses.PlaceUntrainedFrames(this->State); // none unless RefinePoses On
}

bool Trainer::Evaluate(
  const std::vector<int>& frames, ImageMetrics& metrics, std::string* error, double* secondsPerFrame)
{
  // Mid-run too, the frames not trained on are scored where Finish will put them, among their refined neighbours.
  this->PlaceUntrainedFrames();
  return this->EvaluateOn(*this->Data, frames, metrics, error, secondsPerFrame);
}

bool Trainer::EvaluateOn(const TrainingData& data, const std::vector<int>& frames, ImageMetrics& metrics,
  std::string* error, double* secondsPerFrame)
{
  std::vector<float> I(std::size_t(data.Width) * data.Height);
  double seconds = 0;
  int rendered = 0;
  bool ok = true;
  const ImageMetrics mean = MeanFrameMetrics(data, frames, [&](std::size_t, int f) {
    const double t0 = SteadySeconds();
    ok = ok && this->RenderFrame(data, f, I.data(), error);
    seconds += SteadySeconds() - t0;
    ++rendered;
    return I.data();
  });
  if (!ok)
  {
    return false;
  }
  metrics = mean;
  if (secondsPerFrame)
  {
    *secondsPerFrame = rendered == 0 ? 0.0 : seconds / rendered;
  }
  return true;
}

bool Trainer::RenderFrame(const TrainingData& data, int frame, float* image, std::string* error)
{
  RenderOptions o = this->Options();
  o.Cutoff = RenderOptions().Cutoff;
  const SliceGeometry slice = data.Slice(frame);
  this->S.resize(std::size_t(data.Width) * data.Height);
  if (!this->Engine->Render(&slice, 1, o, this->S.data(), image, error))
  {
    if (error)
    {
      *error = "frame " + std::to_string(frame) + ": " + *error;
    }
    return false;
  }
  return true;
}

std::int64_t Trainer::FinalPrune(std::string* error)
{
  if (!this->PullState(error))
  {
    return -1;
  }
  const std::int64_t removed = bigus::FinalPrune(
    this->State.Gaussians, *this->Data, this->Options(), this->Gamma, this->Settings.FinalPruneTolerance);
  return removed > 0 && !this->PushState(error) ? -1 : removed;
}

bool Trainer::Train(const std::function<void(double, int, double, std::int64_t)>& progress,
  const std::function<bool()>& abort, std::string* error)
{
  if (this->GetField().Count() == 0)
  {
    if (error)
    {
      *error = "the field is empty: call Initialize() first";
    }
    return false;
  }
  const double start = SteadySeconds();
  this->TrainStart = start;
  this->TrainedBefore = this->State.TrainingSeconds;
  this->AgreedElapsed = 0;
  const TrainerSettings& s = this->Settings;
  const TrainingState& state = this->State;
  this->Report.StopReason = "iterations";
  if (this->PixelGrid)
  {
    // The solve was the fit (PixelGridFit): geometry steps would overfit data this few.
    this->Report.StopReason =
      "the pixel-grid fit (no geometry steps: a Gaussian per fan pixel, or a grid of MaximumGaussians)";
    this->Report.GrowthStopReason = "none (the pixel-grid fit)";
  }
  double recent = 0;
  int recentCount = 0;
  double previousWindow = -1;
  bool ok = true;
  while (!this->PixelGrid && (s.Iterations <= 0 || state.Iteration < s.Iterations))
  {
    bool aborted = abort && abort();
    if (this->Reduction)
    {
      // Every process stops at the same step: on the slowest clock, when any was asked to.
      double agreed[2] = { SteadySeconds() - start, aborted ? 1.0 : 0.0 };
      if (!this->Reduction->Maximum(agreed, 2, error))
      {
        ok = false;
        break;
      }
      this->AgreedElapsed = agreed[0];
      aborted = agreed[1] > 0;
    }
    if (aborted)
    {
      this->Report.StopReason = "aborted";
      break;
    }
    if (s.TimeBudget > 0 && this->TrainingSeconds() >= s.TimeBudget)
    {
      this->Report.StopReason = "time budget";
      break;
    }
    double loss = 0;
    if (this->Step(&loss, error) == StepStatus::Failed)
    {
      ok = false;
      break;
    }
    if (std::isfinite(loss))
    {
      recent += loss;
      ++recentCount;
    }
    if (state.LearningRateScale < 1e-6)
    {
      if (error)
      {
        *error = "every step produces NaN or Inf, even with learning rates divided by 1e6";
      }
      ok = false;
      break;
    }
    const int it = state.Iteration;
    double validation = 0;
    const DensificationSettings& d = s.Densification;
    if (it % d.Interval == 0 && !this->CheckValidation(validation, error))
    {
      ok = false;
      break;
    }
    const bool densify = d.Enabled && it >= d.Start && it % d.Interval == 0 && this->InDensificationWindow();
    if (densify && !this->DensifyAndPrune(validation, error))
    {
      ok = false;
      break;
    }
    if (this->SolvesReflectivities() && (densify || (s.SolveInterval > 0 && it % s.SolveInterval == 0)) &&
      !this->SolveFieldReflectivities(error))
    {
      ok = false;
      break;
    }
    if (s.ConvergenceTolerance > 0 && it % 200 == 0 && recentCount > 0)
    {
      const double window = recent / recentCount;
      if (previousWindow > 0 && (previousWindow - window) < s.ConvergenceTolerance * previousWindow)
      {
        this->Report.StopReason = "converged";
        break;
      }
      previousWindow = window;
      recent = 0;
      recentCount = 0;
    }
    if (s.CheckpointInterval > 0 && !s.CheckpointFile.empty() && it % s.CheckpointInterval == 0)
    {
      // Data-parallel: rank 0 writes, and the others learn whether it could.
      const bool saved =
        (this->Reduction && this->Reduction->Rank() != 0) || this->SaveCheckpoint(s.CheckpointFile, error);
      if (!this->Agree(saved, error))
      {
        ok = false;
        break;
      }
    }
    if (progress && (it % 10 == 0 || it == s.Iterations))
    {
      progress(this->ScheduleFraction(), it, std::isfinite(loss) ? loss : 0.0, state.Gaussians.Count());
    }
  }
  this->Report.Iterations = state.Iteration;
  this->Report.Seconds += SteadySeconds() - start;
  this->Report.Gamma = this->Gamma;
  const std::size_t h = state.LossHistory.size();
  double last = 0;
  for (std::size_t k = h - std::min<std::size_t>(h, 50); k < h; ++k)
  {
    last += state.LossHistory[k];
  }
  this->Report.LastLoss = h ? last / std::min<std::size_t>(h, 50) : 0;
  this->Report.Gaussians = this->GetField().Count();
  this->DensificationEnded = !this->InDensificationWindow();
  this->State.TrainingSeconds = this->TrainingSeconds();
  this->TrainStart = 0;
  return ok;
}

bool Trainer::Finish(std::string* error)
{
  const double start = SteadySeconds();
  const TrainerSettings& s = this->Settings;
  if (this->Report.GrowthStopReason.empty() && (!s.Densification.Enabled || this->DensificationEnded))
  {
    this->Report.GrowthStopReason = s.Densification.Enabled ? "densification schedule ended" : "densification off";
  }
  // Early stopping: keep the best field seen when the last one scores worse on the validation frames.
  double last = 0;
  if (!this->CheckValidation(last, error))
  {
    return false;
  }
  this->Report.LastValidationLoss = last;
  this->Report.BestValidationLoss = this->State.BestFieldLoss;
  this->Report.BestIteration = this->State.BestFieldIteration;
  if (RestoreBestField(this->State, last))
  {
    this->Poses.ComposePoses(this->State); // the best field's poses
    if (!this->PushState(error))
    {
      return false;
    }
  }
  // The frames not trained (held out) take the smooth part of their neighbours' corrections, if any.
  this->PlaceUntrainedFrames();
  this->Report.PoseCorrections = this->Poses.Corrections(this->State);
  const std::array<double, 7>& shared = this->State.SharedPoseCorrection;
  this->Report.TimeOffset = shared[6];
  std::copy_n(shared.begin(), 6, this->Report.ImageToProbeCorrection.begin());
  const std::int64_t pruned = this->FinalPrune(error);
  if (pruned < 0)
  {
    return false;
  }
  this->Report.PrunedAtEnd = pruned;
  if (s.FillGaps && s.BeamIntegration)
  {
    if (!this->PullState(error))
    {
      return false;
    }
    GapFillingSettings gaps = s.GapFilling;
    gaps.MaximumGaussians = s.MaximumGaussians;
    this->Report.GapFilling = FillElevationGaps(this->State.Gaussians.Field, *this->Data, s.ElevationSigma, gaps);
    if (this->Report.GapFilling.Added > 0)
    {
      this->State.Gaussians.ResizeToField();
      if (!this->PushState(error))
      {
        return false;
      }
    }
  }
  if (s.Merge.Tolerance > 0)
  {
    if (!this->PullState(error))
    {
      return false;
    }
    this->Report.Merge = MergeGaussians(this->State.Gaussians.Field, s.Merge);
    if (this->Report.Merge.Merged > 0)
    {
      // Fresh optimiser moments, as after SetField: a merged Gaussian is a new one.
      GaussianField field = std::move(this->State.Gaussians.Field);
      this->State.Gaussians = OptimizerState();
      this->State.Gaussians.Field = std::move(field);
      this->State.Gaussians.ResizeToField();
      if (!this->PushState(error))
      {
        return false;
      }
    }
  }
  this->Report.Gaussians = this->GetField().Count();
  this->Report.Seconds += SteadySeconds() - start;
  return true;
}

bool Trainer::Run(const std::function<void(double, int, double, std::int64_t)>& progress,
  const std::function<bool()>& abort, std::string* error)
{
  return this->Train(progress, abort, error) && this->Finish(error);
}

bool Trainer::SaveCheckpoint(const std::string& file, std::string* error)
{
  this->State.TrainingSeconds = this->TrainingSeconds();
  return this->PullState(error) && this->State.Save(file, this->Gamma, error);
}

bool Trainer::LoadCheckpoint(const std::string& file, std::string* error)
{
  // Data-parallel: every process reads the file (rank 0 wrote it); one that cannot fails them all here.
  const bool loaded = this->ReadCheckpoint(file, error);
  return this->Agree(loaded, error);
}

bool Trainer::ReadCheckpoint(const std::string& file, std::string* error)
{
  TrainingState loaded;
  double gamma = this->Gamma;
  if (!loaded.Load(file, gamma, error))
  {
    return false;
  }
  if (!this->Poses.CheckCheckpoint(loaded, file, error))
  {
    return false;
  }
  this->State = std::move(loaded);
  this->Poses.ComposePoses(
    this->State); // frames never corrected (held out, or before the corrections moved) stay as tracked
  this->Gamma = gamma;
  this->PixelGrid = false; // a checkpoint comes from a run that takes steps: it goes on with them
  return this->PushState(error);
}

} // namespace bigus
