// The BIGUS training loop (see bigusTrainer.h and DESIGN section 4).
#include "bigusTrainer.h"

#include "bigusParameterAverage.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace bigus
{

namespace
{
constexpr int SnapshotInterval = 100;
// Variable projection with a TimeBudget: a solve may take this share of the budget left when it starts
// (docs/FINDINGS.md, "The trainer's defaults, measured").
constexpr double SolveShareOfRemainingBudget = 0.25;
}

Trainer::Trainer(TrainingData data, const TrainerSettings& settings, std::unique_ptr<TrainingEngine> engine)
  : Data(new TrainingData(std::move(data)))
  , Settings(ScheduledSettings(settings))
  , Engine(engine ? std::move(engine) : CreateTrainingEngine("cpu", nullptr))
  , RunSettings(ResumeSettings(settings))
  , Digest(TrainingDataDigest(*this->Data))
{
  this->State.Random.seed(settings.Seed);
  this->PixelSpacing = MeanTrainingPixelSpacing(*this->Data);
  // The speckle decorrelation of each sweep, measured once for the choices below that need it.
  std::vector<SweepDecorrelation> measured;
  auto measuredSweeps = [&]() -> const std::vector<SweepDecorrelation>& {
    if (measured.empty())
    {
      measured = MeasureSweeps(*this->Data);
    }
    return measured;
  };
  std::string sigmaLine;
  this->Settings.ElevationSigma = ElevationSigmaSetting(
    this->Settings.ElevationSigma, measuredSweeps, this->SigmaByRule, sigmaLine, this->FrameSpacing);
  this->Report.Settings.push_back(sigmaLine);
  this->Report.ElevationSigma = this->Settings.ElevationSigma;
  const std::vector<std::string> described = DescribeTrainerSettings(this->Settings);
  this->Report.Settings.insert(this->Report.Settings.end(), described.begin(), described.end());
  this->Poses.Configure(this->Data.get(), this->Settings.Poses, measuredSweeps, this->State, this->Report.Settings);
  this->Settings.Poses = this->Poses.GetSettings();
  // Auto resolved here, as RefinePoses is, from the same measurement (HoldOutValidationFrames writes its line).
  ValidationHoldOut& holdOut = this->Settings.HeldOut.HoldOutValidationFrames;
  if (holdOut == ValidationHoldOut::Auto)
  {
    holdOut =
      HoldOutValidationByRule(measuredSweeps(), this->ValidationRule) ? ValidationHoldOut::On : ValidationHoldOut::Off;
  }
  this->Engine->SetData(this->Data.get(), nullptr);
}

Trainer::~Trainer() = default;
Trainer::Trainer(Trainer&&) noexcept = default;
Trainer& Trainer::operator=(Trainer&&) noexcept = default;

RenderOptions Trainer::Options() const
{
  return RenderOptionsOf(this->Settings, this->Gamma);
}

double Trainer::StepCutoff() const
{
  return this->CutoffAt(this->ScheduleFraction());
}

double Trainer::CutoffAt(double fraction) const
{
  if (this->Settings.Cutoff > 0)
  {
    return this->Settings.Cutoff;
  }
  // Poses move only from the refinement's start: the steps before it are Adam's on trusted poses, and the trial's
  // two branches both step at the fine cut-off (what the refined one needs; the trusted one compared alike).
  const bool fine =
    this->PixelGrid || this->SolvesReflectivities() || this->InPoseTrial || this->Poses.RefinesAt(fraction);
  return fine ? FineTrainingCutoff : FastTrainingCutoff;
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
  std::string gammaLine;
  if (!CheckImageLossWeights(this->Settings.Loss, error) || !CheckTrainingData(data, error) ||
    !this->Poses.Prepare(error) || !GammaOfTrainingFrames(data, this->Gamma, count, gammaLine, error))
  {
    return false;
  }
  // Every process of a data-parallel run seeds the same grid: its count cannot follow each machine's memory.
  this->Settings.Seeding.GridCountByMemory = this->Settings.Seeding.GridCountByMemory && !this->Reduction;
  SeedingPlan plan;
  if (!PlanSeeding(data, this->Settings.Seeding, this->Settings.MaximumGaussians,
        this->Settings.NonNegativeReflectivity, this->Settings.Solve.L1 > 0, this->SeedShapeOf(), count, plan, error))
  {
    return false;
  }
  // The route measured where the rule takes Adam; the choices measured on the grid (or said untested on Adam).
  if (!this->PlanRouteTrial(plan, error) ||
    (!this->Report.Route.Pending && !this->MeasureOnHeldOutFrames(count, plan, error)))
  {
    return false;
  }
  this->PixelGrid = plan.PixelGrid;
  // A field that could not grow to MaximumGaussians in this machine's memory is refused before any seed is
  // made (the training frames are already held).
  const std::int64_t maximum = std::max(this->Settings.MaximumGaussians, plan.PixelGrid ? plan.Count : 0);
  if (!TrainingFitsInMemory(data, maximum, this->SolvesReflectivities(), this->Settings.Solve.L1 > 0, error))
  {
    return false;
  }
  if (!plan.PixelGrid)
  {
    // A schedule too short for the pose-refinement trial decides untested (no frame is held out for it; under a time
    // budget the steps left are judged from the rate, once there is one: Iterate).
    const std::string noRoom =
      this->Poses.IsTrialPending() && this->Settings.TimeBudget <= 0 ? this->PoseTrialWithoutRoom() : std::string();
    if (!noRoom.empty())
    {
      this->DecideUntestedTrial(noRoom);
    }
    // Before gamma and the seeds, which read only the fitted frames (the rules measured at construction, the seed
    // count and the pixel spacing read every training frame).
    this->HoldOutValidationFrames();
  }
  if (this->Report.ValidationHeldOut && !GammaOfTrainingFrames(data, this->Gamma, count, gammaLine, error))
  {
    return false;
  }
  this->Report.Settings.push_back(gammaLine);
  GaussianField& field = this->State.Gaussians.Field;
  this->Report.Settings.push_back(SeedField(
    data, plan, this->Settings.Seeding, this->SeedShapeOf(), this->Settings.Seed, this->Settings.Solve.L1, field));
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
  bool scaled = false;
  if (!this->SolvesReflectivities())
  {
    return ScaleSeedReflectivities(
             *this->Engine, *this->Data, this->Options(), this->Gamma, this->State.Gaussians.Field, scaled, error) &&
      (!scaled || this->PushState(error));
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
  return bigus::SeedShapeOf(this->Settings, this->PixelSpacing, this->Gamma, this->FrameSpacing);
}

void Trainer::AppendToSetting(const std::string& prefix, const std::string& text)
{
  std::vector<std::string>& lines = this->Report.Settings;
  const auto line =
    std::find_if(lines.begin(), lines.end(), [&](const std::string& l) { return l.rfind(prefix, 0) == 0; });
  if (line != lines.end())
  {
    *line += text;
  }
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

bool Trainer::InDensificationWindow() const
{
  const TrainerSettings& s = this->Settings;
  return s.Densification.End >= 0 ? this->State.Iteration <= s.Densification.End
                                  : this->ScheduleFraction() <= DensifyEndFraction;
}

bool Trainer::IsSettled() const
{
  // In the dip: from a densification that split or cloned to the step before the next one (a validation point).
  const int since = this->State.Iteration - this->LastSplit;
  return !this->InPoseTrial && (this->LastSplit < 0 || since < 0 || since >= this->Settings.Densification.Interval - 1);
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
  const double fraction = this->ScheduleFraction();
  RenderOptions options = this->Options();
  options.Cutoff = this->CutoffAt(fraction);
  StepRequest request = StepRequestAt(this->Settings, fraction, state.LearningRateScale, options);
  request.Frames = frames.data();
  request.Count = static_cast<int>(frames.size());
  request.Iteration = state.Iteration;
  TrainingData decimated;
  const bool lowPass = this->Settings.CoarseLowPass;
  const int phase = fraction < this->Settings.CoarseFraction
    ? DecimateStep(*this->Data, frames, lowPass, state.Random, decimated, request)
    : -1;
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
    for (std::size_t k = 0; phase >= 0 && k < frames.size(); ++k)
    {
      DecimatedPoseGradientToSource(*this->Data, frames[k], phase & 1, phase >> 1, &poseGradients[6 * k], lowPass);
    }
    this->Poses.Step(frames, poseGradients, state.LearningRateScale, state);
  }
  state.LossHistory.push_back(*loss);
  return status;
}

bool Trainer::DensifyAndPrune(double validation, std::string* error)
{
  if (!this->PullState(error))
  {
    return false;
  }
  // MaximumGaussians counts gap filling's copies: growth leaves them room, so that a field grown to the maximum is
  // not bridged by its strongest Gaussians alone (docs/FINDINGS.md, "Gap filling's room under the maximum"). The
  // copies grow with the field (they are copies of the Gaussians near the gaps' frames), so the field may grow to
  // the share of the maximum that leaves its copies in the same proportion room: m (1 + c / n) <= maximum for c
  // copies of a field of n Gaussians now.
  const TrainerSettings& s = this->Settings;
  const std::int64_t n = this->State.Gaussians.Count();
  std::int64_t copies = 0;
  if (s.FillGaps && s.BeamIntegration && this->State.Growing && n > 0)
  {
    // The frames the fill will see: the validation frames held out of the fit join it before then.
    std::vector<int> frames = this->Data->TrainFrames;
    frames.insert(frames.end(), this->HeldOutValidation.begin(), this->HeldOutValidation.end());
    copies = CountGapCopies(this->State.Gaussians.Field, *this->Data, s.ElevationSigma, s.GapFilling, &frames);
  }
  const std::int64_t maximum = copies > 0
    ? static_cast<std::int64_t>(std::floor(double(s.MaximumGaussians) * double(n) / double(n + copies)))
    : s.MaximumGaussians;
  const bool growing = this->State.Growing;
  DensificationResult densified;
  if (!DensifyField(*this->Engine, *this->Data, this->Options(), this->Gamma, this->SeedShapeOf(), s.Densification,
        maximum, validation, this->State, this->Report.GrowthStopReason, error, &densified))
  {
    return false;
  }
  this->LastSplit = densified.Added > 0 ? this->State.Iteration : this->LastSplit;
  if (growing && !this->State.Growing && copies > 0 && this->Report.GrowthStopReason.rfind("hard maximum", 0) == 0)
  {
    this->Report.GrowthStopReason += vtkfmt::sprintf("; MaximumGaussians %lld less room for the copies gap filling "
                                                     "will add (%lld for the %lld Gaussians before this densification)",
      static_cast<long long>(s.MaximumGaussians), static_cast<long long>(copies), static_cast<long long>(n));
  }
  return this->PushState(error);
}

bool Trainer::SampleParameterAverage(bool window, std::string* error)
{
  // The field's structure is fixed from the window's close on: no densification, the validation frames joined.
  const int it = this->State.Iteration;
  if (this->Settings.ParameterAverage <= 0 || window || it % AverageInterval != 0 || !this->HeldOutValidation.empty() ||
    this->Report.Route.Pending || this->InPoseTrial || this->Poses.IsTrialPending())
  {
    return true;
  }
  if (!this->HostCurrent && !this->Engine->PullField(this->AverageSample, error))
  {
    return false;
  }
  AccumulateParameterAverage(this->State, this->HostCurrent ? this->State.Gaussians.Field : this->AverageSample, it,
    this->ScheduleFraction(), this->Settings.ParameterAverage);
  return true;
}

bool Trainer::UseParameterAverage(std::string* error)
{
  if (this->State.AverageSamples == 0)
  {
    return true;
  }
  if (!this->PullState(error))
  {
    return false;
  }
  const int from = this->State.AverageStart, samples = this->State.AverageSamples;
  if (!ApplyParameterAverage(this->State))
  {
    return true;
  }
  this->Poses.ComposePoses(this->State);
  TrainerReport& r = this->Report;
  r.AverageSamples = samples;
  r.AverageFrom = from;
  r.AverageTo = this->State.Iteration;
  this->AppendToSetting("ParameterAverage = ",
    vtkfmt::sprintf("; made the field at step %d: %d samples from step %d", r.AverageTo, samples, from));
  return this->PushState(error);
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
  this->Recent = LossWindow();
  bool ok = true, stop = false;
  while (ok && !stop && !this->PixelGrid && (s.Iterations <= 0 || state.Iteration < s.Iterations))
  {
    ok = this->Iterate(start, progress, abort, stop, error);
  }
  // The schedule ended (not a stop asked for): the run's field is the average.
  ok = ok && (this->Report.StopReason == "aborted" || this->UseParameterAverage(error));
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

bool Trainer::Iterate(double start, const std::function<void(double, int, double, std::int64_t)>& progress,
  const std::function<bool()>& abort, bool& stop, std::string* error)
{
  const TrainerSettings& s = this->Settings;
  const TrainingState& state = this->State;
  bool aborted = abort && abort();
  if (this->Reduction)
  {
    // Every process stops at the same step: on the slowest clock, when any was asked to.
    double agreed[2] = { SteadySeconds() - start, aborted ? 1.0 : 0.0 };
    if (!this->Reduction->Maximum(agreed, 2, error))
    {
      return false;
    }
    this->AgreedElapsed = agreed[0];
    aborted = agreed[1] > 0;
  }
  stop = aborted || (s.TimeBudget > 0 && this->TrainingSeconds() >= s.TimeBudget);
  if (stop)
  {
    this->Report.StopReason = aborted ? "aborted" : "time budget";
    return true;
  }
  if (state.MeasuredTailEnd >= 0 && state.Iteration >= state.MeasuredTailEnd)
  {
    stop = true;
    this->EndMeasuredTail();
    return true;
  }
  // With a time budget the pose trial waits for the run's first steps: their rate (seeding and solves included) says
  // whether the budget leaves room for both branches (TryPoseRefinement). Before the trial's start it ends one
  // without room once the recent steps' rate says so (their frames then join the fit early).
  const bool rateKnown = s.TimeBudget <= 0 || state.Iteration >= 10;
  if (this->Poses.IsTrialPending() && !this->InPoseTrial && rateKnown)
  {
    bool recent = false;
    const bool due = this->ScheduleFraction() >= this->Poses.GetTrialFraction();
    if (due || (s.TimeBudget > 0 && !this->PoseTrialWithoutRoom(&recent).empty() && recent))
    {
      return this->TryPoseRefinement(start, progress, abort, stop, error);
    }
  }
  double loss = 0;
  if (this->Step(&loss, error) == StepStatus::Failed)
  {
    return false;
  }
  if (state.LearningRateScale < 1e-6)
  {
    if (error)
    {
      *error = "every step produces NaN or Inf, even with learning rates divided by 1e6";
    }
    return false;
  }
  LossWindow& recent = this->Recent;
  recent.Sum += std::isfinite(loss) ? loss : 0.0;
  recent.Count += std::isfinite(loss) ? 1 : 0;
  const int it = state.Iteration;
  double validation = 0;
  const DensificationSettings& d = s.Densification;
  if (it % d.Interval == 0)
  {
    this->RateMarkIteration = { this->RateMarkIteration[1], it };
    this->RateMarkSeconds = { this->RateMarkSeconds[1], this->TrainingSeconds() };
    if (!this->CheckValidation(validation, error))
    {
      return false;
    }
  }
  const bool window = this->InDensificationWindow();
  const bool densify = d.Enabled && it >= d.Start && it % d.Interval == 0 && window;
  if (window && this->Report.Route.Pending && !this->InPoseTrial && !this->Poses.IsTrialPending() &&
    it % d.Interval == 0 &&
    !this->DecideRoute(
      &validation, this->Report.Route.AdamProbe && this->ScheduleFraction() >= this->Report.Route.DecideBy, error))
  {
    return false;
  }
  // The choices made on the held-out frames end here: the fit goes on from the best field they scored, with them.
  if (!window && !this->InPoseTrial && !this->Poses.IsTrialPending() && it % d.Interval == 0 &&
    !this->JoinValidationFrames(&validation, error))
  {
    return false;
  }
  if (this->PixelGrid)
  {
    return true; // the route trial chose the pixel grid: its solve was the fit
  }
  if ((densify && !this->DensifyAndPrune(validation, error)) ||
    (this->SolvesReflectivities() && (densify || (s.SolveInterval > 0 && it % s.SolveInterval == 0)) &&
      !this->SolveFieldReflectivities(error)))
  {
    return false;
  }
  if (!this->SampleParameterAverage(window, error))
  {
    return false;
  }
  if (s.ConvergenceTolerance > 0 && it % 200 == 0 && recent.Count > 0)
  {
    const double mean = recent.Sum / recent.Count;
    stop = recent.Previous > 0 && (recent.Previous - mean) < s.ConvergenceTolerance * recent.Previous;
    if (stop)
    {
      this->Report.StopReason = "converged";
      return true;
    }
    recent = LossWindow{ 0.0, 0, mean };
  }
  // Data-parallel: rank 0 writes the checkpoint, and the others learn whether it could.
  if (s.CheckpointInterval > 0 && !s.CheckpointFile.empty() && it % s.CheckpointInterval == 0 && !this->InPoseTrial &&
    !this->Agree(
      (this->Reduction && this->Reduction->Rank() != 0) || this->SaveCheckpoint(s.CheckpointFile, error), error))
  {
    return false;
  }
  if (progress && (it % 10 == 0 || it == s.Iterations))
  {
    progress(this->ScheduleFraction(), it, std::isfinite(loss) ? loss : 0.0, state.Gaussians.Count());
  }
  return true;
}

bool Trainer::Finish(std::string* error)
{
  const double start = SteadySeconds();
  const TrainerSettings& s = this->Settings;
  if (this->Report.GrowthStopReason.empty() && (!s.Densification.Enabled || this->DensificationEnded))
  {
    this->Report.GrowthStopReason = s.Densification.Enabled ? "densification schedule ended" : "densification off";
  }
  // A run stopped before its schedule's end delivers the average too; early stopping then weighs it.
  if (!this->UseParameterAverage(error))
  {
    return false;
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
  if (this->Report.ValidationJoinedAt < 0 && RestoreBestField(this->State, last))
  {
    // Where the average made the field, it is the field it replaced that early stopping kept.
    this->Report.AverageReplaced = this->Report.AverageSamples > 0;
    if (this->Report.AverageReplaced)
    {
      this->AppendToSetting("ParameterAverage = ",
        vtkfmt::sprintf("; early stopping then kept the field of step %d instead (validation loss %.5f against the "
                        "average's %.5f)",
          this->State.BestFieldIteration, this->State.BestFieldLoss, last));
    }
    this->Poses.ComposePoses(this->State); // the best field's poses
    if (!this->PushState(error))
    {
      return false;
    }
  }
  if (!this->PullState(error))
  {
    return false;
  }
  // The stages that end a run, on the host field: the refined scene moved onto the tracked poses; the frames not
  // trained (held out, and validation frames that never joined) take the smooth part of their neighbours'
  // corrections, if any; the validation frames join, so that the final prune, gap filling and merge see them.
  OptimizerState& G = this->State.Gaussians;
  this->Report.Anchor = this->Poses.AnchorToTrackedPoses(this->State, G.Field);
  if (!this->Report.Anchor.Line.empty())
  {
    this->Report.Settings.push_back(this->Report.Anchor.Line);
  }
  this->Report.UntrainedCorrections = this->Poses.PlaceUntrainedFrames(this->State);
  if (!this->JoinValidationFrames(nullptr, error))
  {
    return false;
  }
  this->Report.PoseCorrections = this->Poses.Corrections(this->State);
  const std::array<double, 7>& shared = this->State.SharedPoseCorrection;
  this->Report.TimeOffset = shared[6];
  std::copy_n(shared.begin(), 6, this->Report.ImageToProbeCorrection.begin());
  this->Report.PrunedAtEnd = bigus::FinalPrune(G, *this->Data, this->Options(), this->Gamma, s.FinalPruneTolerance);
  if (s.FillGaps && s.BeamIntegration)
  {
    GapFillingSettings gaps = s.GapFilling;
    gaps.MaximumGaussians = s.MaximumGaussians;
    this->Report.GapFilling = FillElevationGaps(G.Field, *this->Data, s.ElevationSigma, gaps);
    G.ResizeToField();
  }
  if (s.Merge.Tolerance > 0)
  {
    this->Report.Merge = MergeGaussians(G, s.Merge);
  }
  if (!this->PushState(error))
  {
    return false;
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

} // namespace bigus
