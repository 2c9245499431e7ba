// The pose-refinement trial of the trainer (Trainer::TryPoseRefinement, bigusTrainer.h; DESIGN section 4.9): where
// RefinePoses Auto's rule would refine, both choices are tried from the refinement's start and scored on held-out
// frames at their tracked poses. A part of the trainer's schedule, kept beside it in its own file.
#include "bigusTrainer.h"

#include "bigusValidation.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <limits>

namespace bigus
{

bool Trainer::TryPoseRefinement(double start, const std::function<void(double, int, double, std::int64_t)>& progress,
  const std::function<bool()>& abort, bool& stop, std::string* error)
{
  this->Poses.EndTrial(); // one trial, whatever it finds
  const std::vector<int> frames = this->HeldOutValidation;
  const int from = this->State.Iteration, steps = this->PoseTrialSteps(from);
  const std::string noRoom = this->PoseTrialWithoutRoom();
  if (frames.empty() || this->Reduction || !noRoom.empty())
  {
    // Untested: the tracked path decides (DecideUntestedTrial).
    std::string why = "untested: too few training frames to hold any out for the trial";
    if (this->Reduction)
    {
      why = "untested: a data-parallel run cannot hold the trial";
    }
    else if (!frames.empty())
    {
      why = noRoom;
    }
    this->DecideUntestedTrial(why);
    return this->EndPoseTrial("", error);
  }
  // Both branches from the state at the refinement's start.
  if (!this->PullState(error))
  {
    return false;
  }
  const TrainingState initial = this->State;
  const TrainerReport report = this->Report;
  const LossWindow recent = this->Recent;
  this->InPoseTrial = true;
  auto branch = [&](double& psnr) {
    for (int k = 0; k < steps && !stop; ++k)
    {
      if (!this->Iterate(start, progress, abort, stop, error))
      {
        return false;
      }
    }
    ImageMetrics metrics;
    if (!this->EvaluateOn(*this->Data, frames, metrics, error) || !this->PullState(error))
    {
      return false;
    }
    psnr = metrics.PSNR;
    return true;
  };
  double trusted = 0, refined = 0;
  // Where the corrections moved before the trial (the path jitters: GetTrialFraction), the trusted branch takes the
  // tracked poses from here.
  this->Poses.Suspend(true);
  if (this->Poses.ResetCorrections(this->State) && !this->PushState(error))
  {
    this->Poses.Suspend(false);
    this->InPoseTrial = false;
    return false;
  }
  const bool ok = branch(trusted);
  this->Poses.Suspend(false);
  if (!ok)
  {
    this->InPoseTrial = false;
    return false;
  }
  // A run that stops inside a branch (budget, abort, convergence) ends in it: no choice is made, and its stop
  // reason stands.
  auto stopped = [&]() {
    this->InPoseTrial = false;
    this->KeepTrackedPoses("untested: the run stopped during the trial, in its branch on the tracked poses");
    return this->EndPoseTrial("", error);
  };
  if (stop)
  {
    return stopped();
  }
  TrainingState trustedState = this->State;
  TrainerReport trustedReport = this->Report;
  const LossWindow trustedRecent = this->Recent;
  this->State = initial;
  this->Report = report;
  this->Recent = recent;
  this->Poses.ComposePoses(this->State);
  if (!this->PushState(error))
  {
    this->InPoseTrial = false;
    return false;
  }
  this->Engine->Snapshot();
  if (!branch(refined))
  {
    this->InPoseTrial = false;
    return false;
  }
  this->InPoseTrial = false;
  // The trusted branch goes on: its state, report and poses (every correction 0: the tracked poses).
  auto keepTrusted = [&](const std::string& how) {
    const int refinedSteps = this->State.Iteration - from;
    const std::string stopReason = this->Report.StopReason; // the run's, where it stopped in the refined branch
    this->State = std::move(trustedState);
    this->Report = std::move(trustedReport);
    this->Report.StopReason = stop ? stopReason : this->Report.StopReason;
    this->Recent = trustedRecent;
    this->Poses.ComposePoses(this->State);
    if (!this->PushState(error))
    {
      return false;
    }
    this->Engine->Snapshot();
    const std::string said = !stop ? how
                                   : vtkfmt::sprintf("untested: the run stopped during the trial, %d of its %d steps "
                                                     "with refinement; the %d on the tracked poses kept",
                                       refinedSteps, steps, steps);
    this->KeepTrackedPoses(said);
    return this->EndPoseTrial(stop ? "" : how, error);
  };
  if (stop)
  {
    // The run ends in the refined branch, fewer steps along than the trusted one, which it would otherwise discard
    // (on a short budget the rate of the steps before the trial underestimates the steps to come).
    return keepTrusted("");
  }
  // As the held-out choices take the simplest candidate within their tolerance of the best, the tracked poses are
  // kept unless refinement scores more than that above them (on exact poses a refined branch scored 0.04 dB higher
  // and moved them by up to 0.38 mm: docs/FINDINGS.md, "The grid's elevation scale at a wider gap").
  const double tolerance = this->Settings.HeldOut.Tolerance;
  const std::string how = vtkfmt::sprintf("measured: %d steps each way from step %d on %zu held-out frames at "
                                          "their tracked poses, refined %.2f dB, trusted %.2f dB; refinement is "
                                          "taken only more than %.2g dB above",
    steps, from, frames.size(), refined, trusted, tolerance);
  if (refined > trusted + tolerance)
  {
    this->Poses.AnnotateChoice(this->Report.Settings, how);
    return this->EndPoseTrial(how, error);
  }
  return keepTrusted(how);
}

void Trainer::DecideUntestedTrial(const std::string& why)
{
  // Where the path jitters, refinement without the trial; elsewhere the simplest candidate (as the held-out choices
  // take): the tracked poses.
  if (this->Poses.RefineUntested(this->Report.Settings, why))
  {
    this->Settings.Poses = this->Poses.GetSettings();
    return;
  }
  this->KeepTrackedPoses(why + "; the tracked poses kept");
}

void Trainer::KeepTrackedPoses(const std::string& why)
{
  this->Poses.TurnOffCorrections(
    this->State, this->Report.Settings, why + "; the rule alone: on, " + this->Poses.GetRuleText());
  this->Settings.Poses = this->Poses.GetSettings();
}

double Trainer::StepsLeftAfter(double fraction, bool* recent) const
{
  const TrainerSettings& s = this->Settings;
  const int from = this->State.Iteration;
  double left = s.Iterations > 0 ? s.Iterations - std::max<double>(from, fraction * s.Iterations)
                                 : std::numeric_limits<double>::infinity();
  const double seconds = this->TrainingSeconds();
  // The steps slow as the run goes on (the field grows; from the refinement's start they take the fine cut-off, from
  // half the budget every pixel): on the liver at 300 s the mean rate of 3,615 steps promised about 5,400 more where
  // the budget held 2,054, and the recent rate still overstates (docs/FINDINGS.md, "The pose trial from 40 % of the
  // schedule", "Untested, the tracked path decides").
  const int mark = this->RateMarkIteration[0];
  const bool windowed = mark >= 0 && mark < from && this->RateMarkSeconds[0] < seconds;
  const double steps = windowed ? from - mark : from;
  const double stepping = windowed
    ? seconds - this->RateMarkSeconds[0]
    : seconds - this->Report.Route.GridSeconds; // the route trial's grid side took no step
  if (s.TimeBudget > 0 && stepping > 0 && steps > 0)
  {
    left = std::min(left, (s.TimeBudget - std::max(seconds, fraction * s.TimeBudget)) * steps / stepping);
  }
  if (recent)
  {
    *recent = windowed;
  }
  return left;
}

std::string Trainer::PoseTrialWithoutRoom(bool* recent) const
{
  // Under a time budget the branch the trial discards is steps the run loses: at 60 s on the liver 4 x cost 1.8 dB
  // held out for branches 0.4 dB apart (PoseRefiner::TrialRoom). The branch's steps are TrialSteps give or take the
  // half densification interval PoseTrialSteps moves its end by.
  const double left = this->StepsLeftAfter(this->Poses.GetTrialFraction(), recent);
  const bool budget = this->Settings.TimeBudget > 0;
  const double room = PoseRefiner::TrialRoom(budget);
  const int steps = this->Settings.Poses.TrialSteps;
  if (left >= room * steps)
  {
    return {};
  }
  return vtkfmt::sprintf("untested: the %s leaves %s%.0f steps after the trial's start, fewer than %.0f x %d",
    budget ? "budget" : "schedule", budget ? "about " : "", left, room, steps);
}

int Trainer::PoseTrialSteps(int from) const
{
  const int steps = this->Settings.Poses.TrialSteps, interval = this->Settings.Densification.Interval;
  if (!this->Settings.Densification.Enabled || interval <= 1 || !this->InDensificationWindow())
  {
    return steps;
  }
  // The step count nearest TrialSteps whose last step comes just before a densification: its splits take tens of
  // steps to recover from (docs/FINDINGS.md, "A densification's dip and the pose trial"), so a branch scored right
  // after one is scored in that dip.
  const int past = (from + steps + 1) % interval; // steps past the last step before a densification
  return past == 0 ? steps : (past <= interval / 2 && steps - past >= 1 ? steps - past : steps - past + interval);
}

bool Trainer::EndPoseTrial(const std::string& how, std::string* error)
{
  if (this->Settings.HeldOut.HoldOutValidationFrames == ValidationHoldOut::On || this->HeldOutValidation.empty() ||
    this->Report.Route.Pending)
  {
    return true; // held out for their own sake, or for the route trial, which decides when they join
  }
  // Held out for the trial alone: they join the fit, and validation goes on with them as training frames.
  JoinTrainingFrames(*this->Data, this->HeldOutValidation);
  this->HeldOutValidation.clear();
  this->Report.ValidationHeldOut = false;
  this->Recent = LossWindow(); // the joined frames' first losses are no sign of convergence
  this->AppendToSetting("Validation = ",
    vtkfmt::sprintf(
      "; in the fit from step %d%s", this->State.Iteration, how.empty() ? " (the trial made no choice)" : ""));
  return this->Engine->SetData(this->Data.get(), error);
}

} // namespace bigus
