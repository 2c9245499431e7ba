// The frames a fit does not see (see bigusTrainer.h and DESIGN section 4.1): the held-out choices before the seeds,
// the validation frames held out of the Adam run and joined when the choices made on them end, the frames not trained
// placed among their refined neighbours, and the renders that score them. Methods of Trainer, as holding frames out
// and joining them changes the data the loop trains on.
#include "bigusTrainer.h"

#include "bigusParameterAverage.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <limits>

namespace bigus
{

bool Trainer::MeasureOnHeldOutFrames(std::int64_t fanPixels, SeedingPlan& plan, std::string* error)
{
  HeldOutChoices& choices = this->Report.HeldOut;
  if (!ChooseOnHeldOutFrames(*this->Data, this->Settings, plan.PixelGrid, this->SigmaByRule, choices, error))
  {
    return false;
  }
  if (!ApplyHeldOutChoices(choices, this->SigmaByRule, plan.PixelGrid, this->Settings, this->Report.Settings))
  {
    return true;
  }
  // The seeding plan of the chosen sigma (the grid's planes and elevation scale follow it), still the grid's.
  this->Report.ElevationSigma = this->Settings.ElevationSigma;
  SeedingSettings seeding = this->Settings.Seeding;
  seeding.PixelGridFanPixelsPerGaussian = std::numeric_limits<double>::infinity();
  return PlanSeeding(*this->Data, seeding, this->Settings.MaximumGaussians, this->Settings.NonNegativeReflectivity,
    this->Settings.Solve.L1 > 0, this->SeedShapeOf(), fanPixels, plan, error);
}

bool Trainer::CheckValidation(double& loss, std::string* error)
{
  TrainerReport& r = this->Report;
  if (r.ValidationFrames.empty())
  {
    r.ValidationFrames = ValidationFrames(*this->Data); // a field given (SetField): its training frames
  }
  if (!bigus::ValidationLoss(*this->Engine, *this->Data, r.ValidationFrames, this->Options(), this->Settings.Loss,
        this->Reduction, loss, error))
  {
    return false;
  }
  r.ValidationHistory.push_back({ this->State.Iteration, loss, this->State.Gaussians.Count() });
  if (r.ValidationJoinedAt < 0)
  {
    KeepIfBest(this->State, loss, this->GetField());
  }
  return true;
}

void Trainer::HoldOutValidationFrames()
{
  TrainerReport& r = this->Report;
  std::string line;
  // The pose-refinement trial scores on held-out frames too (TryPoseRefinement).
  HeldOutChoiceSettings held = this->Settings.HeldOut; // HoldOutValidationFrames On or Off (the constructor)
  const bool asked = held.HoldOutValidationFrames == ValidationHoldOut::On;
  held.HoldOutValidationFrames = asked || this->Poses.IsTrialPending() ? ValidationHoldOut::On : ValidationHoldOut::Off;
  // The route trial's frames, where it is pending: the pixel grid's fits never saw them.
  // Held out for the pose trial alone, they join the fit when it ends (EndPoseTrial), not at the window's close.
  const bool trialAlone = !asked && !this->Report.Route.Pending;
  r.ValidationFrames = ChooseValidationFrames(*this->Data, held,
    this->Report.Route.Pending ? this->Report.Route.Frames : std::vector<int>(), r.ValidationHeldOut, line,
    trialAlone ? "the pose-refinement trial ends" : "the densification window closes");
  // Where the rule decided (HoldOutValidationFrames Auto), what it measured.
  const std::string& rule = this->ValidationRule;
  const char* said = !asked ? "; the rule holds them out only where no sweep's training frames share speckle: "
    : r.ValidationHeldOut   ? "; held out by the rule, as no sweep's training frames share speckle: "
                            : "; the rule would hold them out, as no sweep's training frames share speckle: ";
  if (r.ValidationHeldOut && this->MeasuresTail())
  {
    line += "; where early stopping then goes back to an earlier field, the run stops as many steps after the join as "
            "the fit took to that field (measured tail)";
  }
  r.Settings.push_back(line + (rule.empty() ? std::string() : said + rule));
  if (r.ValidationHeldOut)
  {
    this->HeldOutValidation = r.ValidationFrames;
    this->Engine->SetData(this->Data.get(), nullptr);
  }
}

bool Trainer::JoinValidationFrames(const double* last, std::string* error)
{
  if (this->HeldOutValidation.empty())
  {
    return true;
  }
  if (this->Report.Route.Pending && last)
  {
    return this->DecideRoute(last, true, error);
  }
  // A run that ends before the window's close (a stop, a budget spent) stays Adam's.
  if (!this->CancelRouteTrial("the run ended before its frames would join the fit", error))
  {
    return false;
  }
  const bool restored = last && RestoreBestField(this->State, *last);
  if (restored)
  {
    this->Poses.ComposePoses(this->State); // the best field's poses
    if (!this->PushState(error))
    {
      return false;
    }
  }
  JoinTrainingFrames(*this->Data, this->HeldOutValidation);
  this->HeldOutValidation.clear();
  this->Recent = LossWindow(); // the joined frames' first losses are no sign of convergence
  TrainingState& state = this->State;
  state.ValidationJoinedAt = state.Iteration;
  this->Report.ValidationJoinedAt = state.Iteration;
  // The measured tail: the frames held out for their own sake measured that the steps after the field early stopping
  // went back to overfitted; the fit with them goes on as many steps as it took to that field. Only at the window's
  // close (a route trial that took Adam joins them earlier, while the field still grows).
  if (restored && this->MeasuresTail() && !this->InDensificationWindow())
  {
    state.MeasuredTailEnd = state.Iteration + state.BestFieldIteration;
  }
  return this->Engine->SetData(this->Data.get(), error);
}

bool Trainer::MeasuresTail() const
{
  const HeldOutChoiceSettings& held = this->Settings.HeldOut;
  return held.MeasuredTail && held.HoldOutValidationFrames == ValidationHoldOut::On;
}

void Trainer::EndMeasuredTail()
{
  TrainingState& state = this->State;
  const int joined = state.ValidationJoinedAt, tail = state.MeasuredTailEnd - joined;
  this->Report.StopReason = vtkfmt::sprintf("measured tail (%d steps after the held-out validation frames joined the "
                                            "fit at step %d, as many as the fit took to the field they scored best)",
    tail, joined);
  // Said once: a later Train call on the stopped run stops here again.
  const std::string said =
    vtkfmt::sprintf("; not taken: the run ended with its measured tail of %d steps from the join "
                    "at step %d, whose first steps fit the joined frames (the field is its last "
                    "step's)",
      tail, joined);
  const std::vector<std::string>& lines = this->Report.Settings;
  if (this->Settings.ParameterAverage > 0 &&
    std::none_of(lines.begin(), lines.end(), [&](const std::string& l) { return l.find(said) != std::string::npos; }))
  {
    this->AppendToSetting("ParameterAverage = ", said);
  }
  DropParameterAverage(state);
}

void Trainer::PlaceUntrainedFrames()
{
  this->Report.UntrainedCorrections = this->Poses.PlaceUntrainedFrames(this->State); // none unless RefinePoses On
  // Held-out validation frames stay at their tracked poses while they decide, as every validation scores them.
  if (!this->HeldOutValidation.empty() && !this->State.PoseCorrections.empty())
  {
    for (int f : this->HeldOutValidation)
    {
      this->State.PoseCorrections[f] = {};
    }
    this->Poses.ComposePoses(this->State);
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
  return EvaluateFrames(*this->Engine, data, frames, this->FilterRenderOptions(), metrics, error, secondsPerFrame);
}

bool Trainer::RenderFrame(const TrainingData& data, int frame, float* image, std::string* error)
{
  return bigus::RenderFrame(*this->Engine, data, frame, this->FilterRenderOptions(), this->S, image, error);
}

RenderOptions Trainer::FilterRenderOptions() const
{
  RenderOptions o = this->Options();
  o.Cutoff = RenderOptions().Cutoff;
  return o;
}

} // namespace bigus
