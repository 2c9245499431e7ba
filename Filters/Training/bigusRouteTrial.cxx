// The route trial (bigusHeldOutChoices.h, RouteTrial): methods of Trainer, as the trial's decision is taken inside
// the training loop (see bigusTrainer.h).
#include "bigusTrainer.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <limits>

namespace bigus
{

namespace
{
/// The index of the setting line that starts with @p prefix in @p lines, or lines.size().
std::size_t LineOf(const std::vector<std::string>& lines, const std::string& prefix)
{
  return static_cast<std::size_t>(
    std::find_if(lines.begin(), lines.end(), [&](const std::string& l) { return l.rfind(prefix, 0) == 0; }) -
    lines.begin());
}

/// The setting line that starts with @p prefix replaced by @p line (appended where there is none).
void ReplaceLine(std::vector<std::string>& lines, const std::string& prefix, const std::string& line)
{
  const std::size_t at = LineOf(lines, prefix);
  if (at < lines.size())
  {
    lines[at] = line;
  }
  else
  {
    lines.push_back(line);
  }
}
}

bool Trainer::PlanRouteTrial(SeedingPlan& plan, std::string* error)
{
  RouteTrial& trial = this->Report.Route;
  trial = RouteTrial();
  trial.FanPixels = plan.Planes.FanPixels;
  trial.RulePixelsPerGaussian = this->Settings.Seeding.PixelGridFanPixelsPerGaussian;
  trial.GridByRule = plan.PixelGrid;
  trial.Untested = RouteTrialUntested(*this->Data, this->Settings, plan, this->Reduction != nullptr);
  if (trial.Untested.empty() && this->Resuming)
  {
    // The frames the grid's side would score (its choices' held-out frames), held out of the fit as in the
    // checkpoint's run; the grid is not fitted (LoadCheckpoint cancels the trial).
    const HeldOutChoiceSettings& h = this->Settings.HeldOut;
    trial.Frames = HeldOutFrames(*this->Data, h.Stride, h.MaximumFrames);
    trial.Pending = trial.Frames.size() >= 2;
    trial.Untested = trial.Pending ? std::string() : "fewer than 2 training frames to hold out between them";
  }
  else if (trial.Untested.empty())
  {
    if (!MeasurePixelGridRoute(*this->Data, this->Settings, this->SigmaByRule, trial, error))
    {
      return false;
    }
    // The grid's side is training time: the budget pays for it.
    this->State.TrainingSeconds += trial.GridSeconds;
    this->Report.Seconds += trial.GridSeconds;
  }
  if (trial.GridByRule && trial.Pending)
  {
    // The rule's grid measured against the route it displaced (where nothing was measured it stands): the run starts
    // as Adam's, which has RouteProbeFraction of the schedule from its start, after the grid's side, to score above
    // the grid. The grid, if it stays ahead, is planned again when the run switches to it (SwitchToPixelGrid).
    SeedingSettings adam = this->Settings.Seeding;
    adam.PixelGridFit = false;
    const std::int64_t fanPixels = plan.FanPixels;
    if (!PlanSeeding(*this->Data, adam, this->Settings.MaximumGaussians, this->Settings.NonNegativeReflectivity,
          this->Settings.Solve.L1 > 0, this->SeedShapeOf(), fanPixels, plan, error))
    {
      return false;
    }
    trial.AdamProbe = true;
    trial.DecideBy = this->ScheduleFraction() + this->Settings.HeldOut.RouteProbeFraction;
  }
  if (trial.FanPixels > 0) // a route the rule chose (the grid's planes measured), not one the settings gave
  {
    this->Report.Settings.push_back(trial.Line());
  }
  return true;
}

bool Trainer::CancelRouteTrial(const std::string& why, std::string* error)
{
  RouteTrial& trial = this->Report.Route;
  if (!trial.Pending)
  {
    return true;
  }
  trial.Pending = false;
  trial.Untested = why;
  ReplaceLine(this->Report.Settings, "Route = ", trial.Line());
  SeedingPlan adam; // the Adam route's choices: said untested (no pixel-grid candidate is fitted)
  return this->MeasureOnHeldOutFrames(0, adam, error);
}

bool Trainer::DecideRoute(const double* last, bool closing, std::string* error)
{
  RouteTrial& trial = this->Report.Route;
  ImageMetrics metrics;
  // Scored as the grid was: the frames at their tracked poses (held out, they have no correction).
  if (!this->PullState(error) || !this->EvaluateOn(*this->Data, trial.Frames, metrics, error))
  {
    return false;
  }
  trial.AdamPSNR = metrics.PSNR;
  // Adam only gains from more steps and more frames: once it scores above the grid the route is decided; the grid
  // only when the frames would join anyway.
  if (!closing && trial.AdamPSNR <= trial.GridPSNR)
  {
    return true;
  }
  trial.Pending = false;
  trial.DecidedAt = this->State.Iteration;
  trial.GridChosen = trial.GridPSNR > trial.AdamPSNR;
  ReplaceLine(this->Report.Settings, "Route = ", trial.Line());
  if (trial.GridChosen)
  {
    return this->SwitchToPixelGrid(error);
  }
  SeedingPlan adam; // the Adam route's choices: said untested (no pixel-grid candidate is fitted)
  if (!this->MeasureOnHeldOutFrames(0, adam, error))
  {
    return false;
  }
  // Held out for their own sake too (HoldOutValidationFrames On: no sweep's frames share speckle), they stay out until
  // the window's close, as their Validation line says: growth and early stopping go on deciding on frames the fit has
  // not seen, and the measured tail follows their join (docs/FINDINGS.md, "The route trial's frames"). Held out for
  // the trial alone, they join now.
  const bool window = this->InDensificationWindow();
  if (window && this->Settings.HeldOut.HoldOutValidationFrames == ValidationHoldOut::On)
  {
    return true;
  }
  if (window)
  {
    this->AppendToSetting("Validation = ",
      vtkfmt::sprintf("; joined the fit at step %d, where the route trial took Adam", trial.DecidedAt));
  }
  return this->JoinValidationFrames(last, error);
}

bool Trainer::SwitchToPixelGrid(std::string* error)
{
  const RouteTrial& trial = this->Report.Route;
  TrainerSettings& s = this->Settings;
  std::vector<std::string>& lines = this->Report.Settings;
  // Every frame in the fit, at its tracked pose: the grid takes no step to refine one with.
  JoinTrainingFrames(*this->Data, this->HeldOutValidation);
  this->HeldOutValidation.clear();
  this->Poses.TurnOffCorrections(this->State, lines, "the route measured is the pixel grid, which takes no step");
  if (!this->Poses.GetTrackedPoses().empty()) // kept only where a pose was refined
  {
    this->Data->Poses = this->Poses.GetTrackedPoses();
  }
  s.Poses = this->Poses.GetSettings();
  s.Seeding.PixelGridFanPixelsPerGaussian = std::numeric_limits<double>::infinity();
  if (ApplyHeldOutChoices(trial.Grid, this->SigmaByRule, true, s, lines))
  {
    this->Report.ElevationSigma = s.ElevationSigma;
  }
  this->Report.HeldOut = trial.Grid;
  std::int64_t fanPixels = 0;
  std::string gammaLine;
  SeedingPlan plan;
  if (!this->Engine->SetData(this->Data.get(), error) ||
    !GammaOfTrainingFrames(*this->Data, this->Gamma, fanPixels, gammaLine, error) ||
    !PlanSeeding(*this->Data, s.Seeding, s.MaximumGaussians, s.NonNegativeReflectivity, s.Solve.L1 > 0,
      this->SeedShapeOf(), fanPixels, plan, error))
  {
    return false;
  }
  ReplaceLine(lines, "Gamma = ", gammaLine + " (of every training frame, for the pixel grid)");
  this->AppendToSetting("Validation = ",
    vtkfmt::sprintf("; joined the fit at step %d, where the route trial took the pixel grid", trial.DecidedAt));
  TrainingState& state = this->State;
  state.Gaussians = OptimizerState();
  // Adam's best field is no candidate: Finish's validation keeps the grid (early stopping has nothing earlier).
  state.BestField = GaussianField();
  state.BestFieldLoss = std::numeric_limits<double>::infinity();
  ReplaceLine(lines, "InitialGaussians = ",
    SeedField(*this->Data, plan, s.Seeding, this->SeedShapeOf(), s.Seed, s.Solve.L1, state.Gaussians.Field));
  state.Gaussians.ResizeToField();
  this->Report.InitialGaussians = state.Gaussians.Field.Count();
  this->PixelGrid = true;
  this->Report.StopReason = vtkfmt::sprintf(
    "the pixel grid, measured better than Adam on held-out frames at step %d (no geometry steps)", trial.DecidedAt);
  this->Report.GrowthStopReason = "none (the pixel grid)";
  return this->PushState(error) && this->SolveFieldReflectivities(error);
}

} // namespace bigus
