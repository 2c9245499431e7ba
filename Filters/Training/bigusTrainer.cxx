// The BIGUS training loop (see bigusTrainer.h and DESIGN section 4).
#include "bigusTrainer.h"

#include "bigusGaussianMath.h"
#include "bigusSeeding.h"
#include "bigusSliceFrame.h"

#include "vtkSMPTools.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
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
constexpr int DefaultIterations = 3000;         // the schedule when neither iterations nor a time budget is given
constexpr double DensifyEndFraction = 0.6;     // densification stops at this fraction of the schedule
// Variable projection with a TimeBudget: a solve may take this share of the budget left when it starts. The
// liver, 30 s (docs/FINDINGS.md): the first solve took the whole budget before (0 steps, 18.04 dB held out);
// shares 0.25 / 0.1 / 0.03 gave 23.58 / 22.64 / 22.44 dB (a solve costs at least its setup and one iteration,
// so a smaller share leaves no more steps).
constexpr double SolveShareOfRemainingBudget = 0.25;
constexpr double MinimumScaleMm = 1e-3;
constexpr double MaximumScaleMm = 100.0;

/// printf into a std::string.
template <typename... Args>
std::string Format(const char* format, Args... args)
{
  const int length = std::snprintf(nullptr, 0, format, args...);
  std::string text(static_cast<std::size_t>(std::max(length, 0)) + 1, '\0');
  std::snprintf(text.data(), text.size(), format, args...);
  text.resize(text.size() - 1);
  return text;
}

/// Uniform double in [0, 1) from the generator's raw output (identical on every platform).
double Uniform(std::mt19937_64& rng)
{
  return (rng() >> 11) * (1.0 / 9007199254740992.0);
}

double Seconds()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

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
    this->Report.Settings.push_back(Format("ElevationSigma = %.4g mm (given)", this->Settings.ElevationSigma));
  }
  else
  {
    const ElevationSigmaChoice choice = ChooseElevationSigma(measuredSweeps());
    this->Settings.ElevationSigma = choice.Sigma;
    this->Report.Settings.push_back(Format("ElevationSigma = %.4g mm (chosen: ", choice.Sigma) + choice.Reason + ")");
  }
  this->Report.ElevationSigma = this->Settings.ElevationSigma;
  const TrainerSettings& s = this->Settings;
  std::string schedule = s.Iterations > 0 ? Format("Iterations = %d", s.Iterations) : "Iterations = no limit";
  if (s.TimeBudget > 0)
  {
    schedule += Format(", TimeBudget = %.4g s (", s.TimeBudget) +
      (s.Iterations > 0 ? "whichever ends first; " : "") + "the schedule follows the one further along)";
  }
  this->Report.Settings.push_back(schedule);
  this->Report.Settings.push_back(s.Densify
      ? Format("Densification = every %d steps from step %d to ", s.DensifyInterval, s.DensifyStart) +
        (s.DensifyEnd >= 0 ? Format("step %d", s.DensifyEnd)
                           : Format("%.0f %% of the schedule", 100 * DensifyEndFraction)) +
        Format(", top %.3g %% by attribution", s.DensifyPercentile) +
        (s.ResidualSeedShare > 0 ? Format(" and %.3g as many seeds where the residual of %d frames is largest",
                                     s.ResidualSeedShare, s.ResidualSeedFrames)
                                 : std::string()) +
        Format(", at most %lld Gaussians", static_cast<long long>(s.MaximumGaussians)) +
        Format("; growth stops when the validation loss improves by less than %.3g %%", 100 * s.GrowthMargin) +
        Format(" over %d intervals", s.GrowthPatience)
      : "Densification = off");
  this->Report.Settings.push_back(s.FillGaps && s.BeamIntegration
      ? Format("FillGaps = on (after training, gaps between training frames over %.3g typical spacings ",
          s.GapFilling.MinimumGapSpacings) +
        Format("are bridged by blended copies of the frames on either side as rendered, %.3g beam widths clear of them, ",
          s.GapFilling.ClearanceSigmas) +
        Format("each frame alone within %.3g beam widths of it)", s.GapFilling.BlendMarginSigmas)
      : s.FillGaps ? "FillGaps = off (BeamIntegration is off: the thin plane has no beam to bridge gaps with)"
                   : "FillGaps = off");
  this->Report.Settings.push_back(!s.ReflectivitySolve ? "ReflectivitySolve = off (Adam alone)"
      : s.NonNegativeReflectivity
      ? "ReflectivitySolve = off (NonNegativeReflectivity: the model is not linear in r)"
      : Format("ReflectivitySolve = on (%s, at most %d iterations, ridge %.3g, after seeding, after every "
               "densification", s.Solve.L1 > 0 ? Format("FISTA with L1 %.3g", s.Solve.L1).c_str() : "CGLS",
          s.Solve.MaximumIterations, s.Solve.Ridge) +
        (s.SolveInterval > 0 ? Format(" and every %d steps)", s.SolveInterval) : std::string(")")));
  this->Report.Settings.push_back(Format("Seed = %u, FramesPerStep = %d, Cutoff = %.3g, SparseAdam = %s%s", s.Seed,
    s.FramesPerStep, s.Cutoff, s.SparseAdam ? "on" : "off",
    s.CoarseFraction > 0
      ? Format(", CoarseFraction = %.3g (a quarter of the pixels per step until then, %s)", s.CoarseFraction,
          s.CoarseLowPass ? "2 x 2 averages through the pixel's low-pass" : "point samples").c_str()
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
    std::fprintf(stderr, "bigus: cannot read the field back from the %s engine: %s\n", this->Engine->GetName(),
      error.c_str());
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
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  if (data.TrainFrames.empty() || pixels == 0 ||
    (data.Mask.size() != pixels && data.Mask.size() != pixels * data.Poses.size()) ||
    data.Frames.size() != pixels * data.Poses.size())
  {
    if (error)
    {
      *error = "no training frames, or frames, poses and mask of inconsistent sizes";
    }
    return false;
  }
  // Every training pose must be one the renderer accepts, or the run would stop at its first step.
  const double shearLimit = RenderOptions().MaximumShearAngle;
  for (int f : data.TrainFrames)
  {
    SliceFrame frame;
    const PoseStatus status = ComputeSliceFrame(data.Poses[f].data(), shearLimit, frame);
    if (status != PoseStatus::Ok)
    {
      if (error)
      {
        char detail[120] = "";
        if (status == PoseStatus::Sheared)
        {
          std::snprintf(detail, sizeof(detail), " by %.2f degrees; the renderer accepts at most %.2f",
            frame.shearDegrees, shearLimit);
        }
        *error = "training frame " + std::to_string(f) + ": ImageToReference " + PoseStatusText(status) + detail;
      }
      return false;
    }
  }
  if (!this->Poses.Prepare(error))
  {
    return false;
  }
  double sum = 0;
  long count = 0;
  for (int f : data.TrainFrames)
  {
    const float* frame = &data.Frames[pixels * f];
    const unsigned char* mask = data.MaskOf(f);
    for (std::size_t p = 0; p < pixels; ++p)
    {
      if (mask[p])
      {
        sum += frame[p];
        ++count;
      }
    }
  }
  if (count == 0)
  {
    if (error)
    {
      *error = "the fan mask is empty";
    }
    return false;
  }
  this->Gamma = GammaFromMeanIntensity(sum / count);
  this->Report.Settings.push_back(
    Format("Gamma = %.5g (from the mean fan intensity %.4f of the training frames)", this->Gamma, sum / count));
  // Capacity follows the data: more fan pixels to explain, more seeds (measured on the liver at 120 s
  // of training: 20k seeds 32.5 dB held-out PSNR, 60k 33.0, 100k 33.3, 200k 33.7).
  const std::int64_t seeds = this->Settings.InitialGaussians > 0
    ? this->Settings.InitialGaussians
    : std::max<std::int64_t>(std::min<std::int64_t>(20000, this->Settings.MaximumGaussians / 2),
        std::min<std::int64_t>(count / 200, this->Settings.MaximumGaussians / 2));
  if (this->Settings.InitialGaussians > this->Settings.MaximumGaussians)
  {
    if (error)
    {
      *error = Format("InitialGaussians (%lld) exceeds MaximumGaussians (%lld)",
        static_cast<long long>(this->Settings.InitialGaussians), static_cast<long long>(this->Settings.MaximumGaussians));
    }
    return false;
  }
  const SeedShape shape = this->SeedShapeOf();
  // The planes are selected (a pass over the training frames' masks) only where the pixel-grid fit may apply.
  const bool gridMayApply = this->Settings.PixelGridFit && !this->Settings.DenseInitialisation &&
    this->Settings.InitialGaussians <= 0 && this->Settings.HarrisInitialisation &&
    !this->Settings.NonNegativeReflectivity;
  const GridPlanes planes = gridMayApply ? SelectGridPlanes(data, shape) : GridPlanes();
  this->PixelGrid = gridMayApply &&
    planes.FanPixels <= PixelGridFanPixelsPerGaussian * this->Settings.MaximumGaussians;
  // A field that could not grow to MaximumGaussians in this machine's memory is refused before any seed is
  // made (the training frames are already held).
  const std::int64_t trainingPixels =
    std::int64_t(this->Data->Width) * this->Data->Height * std::int64_t(this->Data->TrainFrames.size());
  const double needed = this->Settings.MaximumGaussians * TrainingBytesPerGaussian +
    (this->SolvesReflectivities() ? ReflectivitySolveBytes(this->Settings.MaximumGaussians, trainingPixels) : 0.0);
  const double physical = PhysicalMemoryBytes();
  if (physical > 0 && needed > physical)
  {
    if (error)
    {
      *error = Format("MaximumGaussians (%lld) needs %.0f MB of training state (%.0f bytes per Gaussian%s) and this "
                      "machine has %.0f MB",
        static_cast<long long>(this->Settings.MaximumGaussians), needed / 1e6, TrainingBytesPerGaussian,
        this->SolvesReflectivities() ? " and the reflectivity solve's vectors" : "", physical / 1e6);
    }
    return false;
  }
  GaussianField& field = this->State.Gaussians.Field;
  if (this->PixelGrid)
  {
    const std::int64_t count = std::min<std::int64_t>(planes.FanPixels, this->Settings.MaximumGaussians);
    const std::string grid = SeedGrid(data, planes, count, shape, field);
    this->Report.InitialGaussians = field.Count();
    this->Report.Settings.push_back(Format("InitialGaussians = %lld (the pixel-grid fit: the %lld fan pixels of the "
                                           "dense start's planes %s; ",
                                      static_cast<long long>(field.Count()), static_cast<long long>(planes.FanPixels),
                                      count < planes.FanPixels
                                        ? "are at most twice MaximumGaussians, a grid of that many"
                                        : "fit under MaximumGaussians") +
      grid + "; reflectivities solved" +
      (this->Settings.Solve.L1 > 0 ? Format(" with an L1 term of %.3g (FISTA)", this->Settings.Solve.L1)
                                   : std::string()) +
      ", no geometry steps)");
    // No step, so no pose correction: the tracked poses stay, and the field says so (no RefinedPoses).
    this->Poses.TurnOffCorrections(
      this->State, this->Report.Settings, "the pixel-grid fit takes no step to refine the poses with");
    this->Settings.Poses = this->Poses.GetSettings();
    return true;
  }
  if (this->Settings.DenseInitialisation)
  {
    const std::int64_t wanted = this->Settings.InitialGaussians > 0 ? this->Settings.InitialGaussians
                                                                    : this->Settings.MaximumGaussians / 2;
    const std::string grid = SeedGrid(data, wanted, shape, field);
    this->Report.InitialGaussians = field.Count();
    this->Report.Settings.push_back(Format("InitialGaussians = %lld (dense start: ", static_cast<long long>(field.Count())) +
      grid + ")");
    return true;
  }
  this->Report.InitialGaussians = seeds;
  this->Report.Settings.push_back(Format("InitialGaussians = %lld (", static_cast<long long>(seeds)) +
    (this->Settings.InitialGaussians > 0
        ? std::string("given")
        : Format("chosen: one per 200 of the %ld fan pixels of the training frames, 20,000 to half the maximum", count)) +
    (this->Settings.HarrisInitialisation ? "; Harris seeding)" : "; uniform random seeding)"));
  std::mt19937_64 rng(this->Settings.Seed * 7919ULL + 17);
  if (this->Settings.HarrisInitialisation)
  {
    SeedHarris(data, seeds, rng, shape, field);
  }
  else
  {
    SeedUniform(data, seeds, rng, shape, field);
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
    this->Report.Settings.push_back(Format("Processes = %d (data-parallel: each renders its share of the %d frames "
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
  OptimizerState& G = this->State.Gaussians;
  // With an L1 term, one solve in two parts, the relaxed lasso (Meinshausen, Comput. Stat. Data Anal. 52(1), 2007):
  // the L1 solve chooses the Gaussians; the others (r = 0, and any no training pixel sees) are removed, and least
  // squares refits the kept ones' reflectivities without the L1 term's shrinkage. On the volume protocol the refit
  // gained 2.9 dB at L1 0.01 over the L1 solve alone (docs/FINDINGS.md, "An L1 term in the reflectivity solve").
  const bool relaxed = this->Settings.Solve.L1 > 0;
  for (int part = 0; part < (relaxed ? 2 : 1); ++part)
  {
    ReflectivitySolveSettings solve = this->Settings.Solve;
    solve.L1 = part == 0 ? solve.L1 : 0.0;
    if (this->Settings.TimeBudget > 0 && solve.TimeLimit <= 0)
    {
      // The pixel-grid fit is the whole run; variable projection leaves the rest to the steps between solves.
      solve.TimeLimit = (this->PixelGrid ? 1.0 : SolveShareOfRemainingBudget) *
        std::max(1e-3, this->Settings.TimeBudget - this->TrainingSeconds());
    }
    std::vector<float> r = G.Field.Reflectivities;
    if (!SolveReflectivities(*this->Engine, *this->Data, this->Data->TrainFrames, this->Options(), solve, r,
          &this->Report.LastSolve, error, this->Reduction))
    {
      if (error)
      {
        *error = "reflectivity solve: " + *error;
      }
      return false;
    }
    G.Field.Reflectivities.swap(r);
    std::fill(G.FirstMoment.Reflectivities.begin(), G.FirstMoment.Reflectivities.end(), 0.f);
    std::fill(G.SecondMoment.Reflectivities.begin(), G.SecondMoment.Reflectivities.end(), 0.f);
    this->Report.SolveSeconds += this->Report.LastSolve.Seconds;
    if (solve.L1 > 0)
    {
      this->Report.LastL1Solve = this->Report.LastSolve;
      this->Report.LastL1Removed = bigus::FinalPrune(G, *this->Data, this->Options(), this->Gamma, 0.0);
      if (!this->PushState(error)) // the refit solves the pruned field
      {
        return false;
      }
    }
  }
  this->Report.Solves += 1;
  this->Report.LastSolve.Seconds += relaxed ? this->Report.LastL1Solve.Seconds : 0.0;
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
  shape.InPlaneScale = this->Settings.InitialScalePixels * this->PixelSpacing;
  shape.ElevationSigma = this->Settings.BeamIntegration ? this->Settings.ElevationSigma : 0.0;
  shape.ElevationScale = shape.ElevationSigma > 0 ? shape.ElevationSigma : this->PixelSpacing;
  shape.UniformShare = this->Settings.UniformShare;
  shape.Gamma = this->Gamma;
  return shape;
}

bool Trainer::FitReflectivityScale(std::string* error)
{
  // Overlapping seeds add up: one least-squares factor c on every reflectivity makes the rendered
  // scattering field match -ln(1 - I) / gamma of a few training frames.
  const TrainingData& data = *this->Data;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const int frames = static_cast<int>(data.TrainFrames.size());
  const RenderOptions o = this->Options();
  std::vector<float> S(pixels);
  double num = 0, den = 0;
  for (int n = 0; n < std::min(frames, 5); ++n)
  {
    const int f = data.TrainFrames[(n * frames) / std::min(frames, 5)];
    const SliceGeometry slice = data.Slice(f);
    if (!this->Engine->Render(&slice, 1, o, S.data(), nullptr, error))
    {
      return false;
    }
    const float* frame = &data.Frames[pixels * f];
    const unsigned char* mask = data.MaskOf(f);
    for (std::size_t p = 0; p < pixels; ++p)
    {
      if (mask[p])
      {
        num += S[p] * ScatteringOfIntensity(frame[p], this->Gamma);
        den += double(S[p]) * S[p];
      }
    }
  }
  const double c = den > 0 ? num / den : 1.0;
  if (!std::isfinite(c) || c <= 0)
  {
    return true;
  }
  for (float& r : this->State.Gaussians.Field.Reflectivities)
  {
    r = static_cast<float>(r * c);
  }
  return this->PushState(error);
}

double Trainer::TrainingSeconds() const
{
  return this->TrainStart > 0
    ? this->TrainedBefore + (this->Reduction ? this->AgreedElapsed : Seconds() - this->TrainStart)
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
  return s.DensifyEnd >= 0 ? this->State.Iteration <= s.DensifyEnd : this->ScheduleFraction() <= DensifyEndFraction;
}

StepStatus Trainer::Step(double* loss, std::string* error)
{
  TrainingState& state = this->State;
  const std::vector<int>& train = this->Data->TrainFrames;
  std::vector<int> frames(this->Settings.FramesPerStep * (this->Reduction ? this->Reduction->Size() : 1));
  for (int& f : frames)
  {
    f = train[static_cast<std::size_t>(Uniform(state.Random) * train.size())];
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
  const bool coarse = fraction < this->Settings.CoarseFraction && this->Data->Width >= smallest &&
    this->Data->Height >= smallest;
  TrainingData decimated;
  int phase = 0;
  if (coarse)
  {
    phase = static_cast<int>(Uniform(state.Random) * 4);
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
  // Every 8th training frame (at most 8): the growth decision must not depend on one lucky frame.
  const TrainingData& data = *this->Data;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const RenderOptions o = this->Options();
  std::vector<float> S(pixels), I(pixels);
  ImageLossWorkspace workspace;
  double total = 0;
  int used = 0;
  bool ok = true;
  const int frames = static_cast<int>(data.TrainFrames.size());
  const int stride = std::max(1, frames / 8);
  for (int n = 0; n < frames && used < 8 && ok; n += stride, ++used)
  {
    // Data-parallel: each process renders its share of the frames, and the losses are summed, so that the
    // growth and early-stopping decisions are taken from one agreed value on every process.
    if (this->Reduction && used % this->Reduction->Size() != this->Reduction->Rank())
    {
      continue;
    }
    const int f = data.TrainFrames[n];
    const SliceGeometry slice = data.Slice(f);
    ok = this->Engine->Render(&slice, 1, o, S.data(), I.data(), error);
    if (ok)
    {
      total += ComputeImageLoss(I.data(), &data.Frames[pixels * f], data.MaskOf(f), data.Width, data.Height,
        this->Settings.Loss, nullptr, false, &workspace)
                 .Total;
    }
  }
  if (!this->Agree(ok, error) || (this->Reduction && !this->Reduction->Sum(&total, 1, error)))
  {
    return false;
  }
  loss = total / std::max(1, used);
  return true;
}

bool Trainer::CheckValidation(double& loss, std::string* error)
{
  if (!this->ValidationLoss(loss, error))
  {
    return false;
  }
  TrainingState& state = this->State;
  this->Report.ValidationHistory.push_back({ state.Iteration, loss, state.Gaussians.Count() });
  if (state.BestFieldLoss < 0 || loss < state.BestFieldLoss)
  {
    state.BestFieldLoss = loss;
    state.BestFieldIteration = state.Iteration;
    state.BestField = this->GetField();
    PoseRefiner::KeepBest(state);
  }
  return true;
}

bool Trainer::DensifyAndPrune(double validation, std::string* error)
{
  TrainingState& state = this->State;
  if (state.Growing)
  {
    if (state.BestValidationLoss < 0 || validation < state.BestValidationLoss * (1 - this->Settings.GrowthMargin))
    {
      state.BestValidationLoss = validation;
      state.StalledGrowthSteps = 0;
    }
    else if (++state.StalledGrowthSteps >= this->Settings.GrowthPatience)
    {
      state.Growing = false;
      char why[200];
      std::snprintf(why, sizeof(why),
        "validation loss improved by less than %.2g %% over %d densification intervals (iteration %d)",
        100 * this->Settings.GrowthMargin, this->Settings.GrowthPatience, state.Iteration);
      this->Report.GrowthStopReason = why;
    }
  }
  if (!this->PullState(error))
  {
    return false;
  }
  // Image-GS's new Gaussians from the residual: rendered before densification changes the field.
  const double residualShare = this->Settings.ResidualSeedShare;
  const int residualFrames = this->Settings.ResidualSeedFrames;
  std::vector<int> residualFrameList;
  std::vector<float> residuals;
  if (residualShare > 0 && residualFrames > 0 && state.Growing &&
    !this->RenderResiduals(residualFrames, residualFrameList, residuals, error))
  {
    return false;
  }
  const DensificationResult result = bigus::DensifyAndPrune(state.Gaussians, state.Growing,
    this->Settings.DensifyPercentile, this->Settings.MaximumGaussians,
    this->Settings.SplitScalePixels * this->PixelSpacing, this->Settings.PruneReflectivity);
  if (!residualFrameList.empty() && result.Added > 0)
  {
    const std::int64_t room = this->Settings.MaximumGaussians - state.Gaussians.Count();
    const std::int64_t count = std::min<std::int64_t>(room, std::llround(residualShare * result.Added));
    const SeedShape shape = this->SeedShapeOf();
    const std::size_t pixels = std::size_t(this->Data->Width) * this->Data->Height;
    for (std::size_t k = 0; k < residualFrameList.size(); ++k)
    {
      const std::int64_t share = count / residualFrames + (std::int64_t(k) < count % residualFrames ? 1 : 0);
      SeedResidual(*this->Data, residualFrameList[k], &residuals[pixels * k], share, state.Random, shape,
        state.Gaussians.Field);
    }
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

bool Trainer::RenderResiduals(int count, std::vector<int>& frames, std::vector<float>& residuals, std::string* error)
{
  const TrainingData& data = *this->Data;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const RenderOptions o = this->Options();
  residuals.resize(pixels * count);
  for (int k = 0; k < count; ++k)
  {
    const int f = data.TrainFrames[static_cast<std::size_t>(Uniform(this->State.Random) * data.TrainFrames.size())];
    frames.push_back(f);
    const SliceGeometry slice = data.Slice(f);
    float* S = &residuals[pixels * k];
    if (!this->Engine->Render(&slice, 1, o, S, nullptr, error))
    {
      return false;
    }
    const float* frame = &data.Frames[pixels * f];
    for (std::size_t p = 0; p < pixels; ++p)
    {
      S[p] = static_cast<float>(ScatteringOfIntensity(frame[p], this->Gamma) - S[p]);
    }
  }
  return true;
}

void Trainer::PlaceUntrainedFrames()
{
  if (this->Settings.Poses.RefinePoses == PoseRefinement::On)
  {
    this->Report.UntrainedCorrections = this->Poses.PlaceUntrainedFrames(this->State);
  }
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
    const double t0 = Seconds();
    ok = ok && this->RenderFrame(data, f, I.data(), error);
    seconds += Seconds() - t0;
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
  const double start = Seconds();
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
      double agreed[2] = { Seconds() - start, aborted ? 1.0 : 0.0 };
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
    if (it % s.DensifyInterval == 0 && !this->CheckValidation(validation, error))
    {
      ok = false;
      break;
    }
    const bool densify = s.Densify && it >= s.DensifyStart && it % s.DensifyInterval == 0 && this->InDensificationWindow();
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
      const bool saved = (this->Reduction && this->Reduction->Rank() != 0) || this->SaveCheckpoint(s.CheckpointFile, error);
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
  this->Report.Seconds += Seconds() - start;
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
  const double start = Seconds();
  const TrainerSettings& s = this->Settings;
  if (this->Report.GrowthStopReason.empty() && (!s.Densify || this->DensificationEnded))
  {
    this->Report.GrowthStopReason = s.Densify ? "densification schedule ended" : "densification off";
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
  if (last > this->State.BestFieldLoss)
  {
    // Fresh optimiser moments, as after SetField, but the record of the best field stays.
    this->State.Gaussians = OptimizerState();
    this->State.Gaussians.Field = this->State.BestField;
    this->State.Gaussians.ResizeToField();
    this->Poses.RestoreBest(this->State); // ... at the poses it was measured at
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
  this->Report.Seconds += Seconds() - start;
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
  this->Poses.ComposePoses(this->State); // frames never corrected (held out, or before the corrections moved) stay as tracked
  this->Gamma = gamma;
  this->PixelGrid = false; // a checkpoint comes from a run that takes steps: it goes on with them
  return this->PushState(error);
}

} // namespace bigus
