// Checkpoints of a run (see bigusTrainer.h and DESIGN section 4.7): methods of Trainer, as a resume replaces the
// whole training state the loop runs on.
#include "bigusTrainer.h"

namespace bigus
{

bool Trainer::SaveCheckpoint(const std::string& file, std::string* error)
{
  this->State.TrainingSeconds = this->TrainingSeconds();
  this->State.DataDigest = this->Digest;
  this->State.RunSettings = this->RunSettings;
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
  // Written for this run's data and settings (a file without them, from before "BIGUSCK6", cannot be checked).
  const std::string changed = ResumeSettingsDifference(loaded.RunSettings, this->RunSettings);
  if ((loaded.DataDigest != 0 && loaded.DataDigest != this->Digest) || !changed.empty())
  {
    if (error)
    {
      *error = file + ": the checkpoint was written by a run " +
        (changed.empty() ? std::string("on other training data (the frames, poses, masks, calibration or held-out "
                                       "frames differ); resume with the sweeps and options it was written with")
                         : "with other settings (" + changed + "); resume with the options it was written with");
    }
    return false;
  }
  // A pending route trial ends here (the checkpoint's run goes on with its steps), before the pose trial's frames
  // may join.
  if (!this->CancelRouteTrial("the run resumed from the checkpoint " + file + ", which goes on with its steps", error))
  {
    return false;
  }
  bool trialDone = false;
  if (!this->Poses.Resume(loaded, this->Report.Settings, file, trialDone, error))
  {
    return false;
  }
  this->Settings.Poses = this->Poses.GetSettings();
  this->State = std::move(loaded);
  this->Poses.ComposePoses(
    this->State); // frames never corrected (held out, or before the corrections moved) stay as tracked
  // Where the corrections move before the pose trial (PoseRefiner::GetTrialFraction), the checkpoint's step says
  // whether the trial ran (one that kept the tracked poses left no correction: PoseRefiner::Resume).
  if (this->Poses.IsTrialPending() && this->Poses.MovesBeforeTrial() &&
    this->ScheduleFraction() >= this->Poses.GetTrialFraction())
  {
    this->Poses.EndTrial();
    trialDone = true;
  }
  if (trialDone && !this->EndPoseTrial("before the checkpoint", error))
  {
    return false;
  }
  this->Gamma = gamma;
  this->PixelGrid = false; // a checkpoint comes from a run that takes steps: it goes on with them
  if (!this->PushState(error))
  {
    return false;
  }
  TrainingState& state = this->State;
  if (!this->MeasuresTail())
  {
    state.MeasuredTailEnd = -1; // asked off for the resumed run: the schedule ends it
  }
  // Frames the checkpoint's run had joined to its fit join it now (at the step they joined there); where its window
  // had closed but they had not joined yet, they join at the next validation, as they would have (Iterate).
  const int joinedAt = state.ValidationJoinedAt;
  if (this->InDensificationWindow() || joinedAt == -1)
  {
    return true;
  }
  if (!this->JoinValidationFrames(nullptr, error))
  {
    return false;
  }
  if (joinedAt >= 0)
  {
    state.ValidationJoinedAt = joinedAt;
    this->Report.ValidationJoinedAt = joinedAt;
  }
  return true;
}

} // namespace bigus
