/**
 * @file bigusPoseRefinement.h
 * @brief The pose-refinement stage of training (DESIGN section 4, "Pose refinement"): a rigid correction of each
 *        training frame's tracked pose, a time offset and an ImageToProbe correction shared by every frame, moved
 *        by Adam on the gradient of the image loss with respect to the poses; the placing of the frames not
 *        trained on; and the refinement of held-out frames' poses with the field frozen (the fair score).
 *
 * bigus::PoseRefiner owns the tracked poses, the choices made for the run (which sweeps, from when) and every
 * update of the corrections; the corrections and their Adam moments live in the TrainingState, which the
 * checkpoint writes whole. The trainer calls it from Step, Finish and the checkpoint code.
 *
 * Part of BIGUS::Training (public, not wrapped for Python).
 */
#ifndef bigusPoseRefinement_h
#define bigusPoseRefinement_h

#include "bigusElevationSigma.h"
#include "bigusImageLoss.h"
#include "bigusPoseTimeline.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <array>
#include <functional>
#include <string>
#include <vector>

namespace bigus
{

/// Whether a trainer refines the tracked poses of the training frames (PoseRefinementSettings::RefinePoses).
enum class PoseRefinement : int
{
  Off = 0, ///< the tracked poses are trusted
  On = 1,  ///< every sweep's training frames are refined
  Auto = 2 ///< the sweeps whose neighbouring frames' speckle correlates (bigus::ChoosePoseRefinement)
};

/**
 * The pose-refinement stage's settings (TrainerSettings::Poses). A rigid correction per training frame (rotation
 * vector about the frame's centre pixel and translation, in its own axes: bigus::CorrectPose) is optimised with the
 * field by Adam on the gradient of the loss with respect to the frame's pose (FieldGradients::SlicePoses, taken at
 * the corrected pose), with the prior Prior / 2 (|omega|^2 / RotationSigma^2 + |t|^2 / TranslationSigma^2) per
 * frame. Held-out frames take the smooth part of their sweep's corrections at the end (CorrectUntrainedFrames).
 */
struct BIGUSTRAINING_EXPORT PoseRefinementSettings
{
  /// Off: the tracked poses are trusted. On: every sweep's training frames are refined. Auto (the default): the
  /// sweeps whose neighbouring frames' speckle correlates (bigus::ChoosePoseRefinement), resolved when the trainer is
  /// made (Trainer::GetSettings() then says On or Off, and PoseRefiner::IsSweepRefined which sweeps).
  PoseRefinement RefinePoses = PoseRefinement::Auto;
  /// Share of the schedule (0 to 1) trained on the tracked poses before the corrections move; negative (default):
  /// chosen when the trainer is made from the tracked path's jitter (bigus::ChoosePoseRefinementStart, the rule).
  double Start = -1;
  double RotationLearningRate = 1e-3;    ///< Adam's rate of the rotation vector, rad per step
  double TranslationLearningRate = 0.02; ///< Adam's rate of the translation, mm per step
  double RotationSigma = 0.0175;         ///< rad (1 degree): the prior's scale, a tracker's typical error
  double TranslationSigma = 1.0;         ///< mm
  double Prior = 1e-3;                   ///< weight of the prior against the image loss (0: none)
  /// The frames' own corrections: RotationSigma and TranslationSigma scaled on each sweep so that the prior's rms
  /// displacement of a frame's corners is PosePriorJitterRatio times its tracked path's jitter (bigus::PosePriorScale),
  /// as a tracker's noise shows in the path. Off: the sigmas as given on every sweep. The shared corrections (time
  /// offset, ImageToProbe) and the held-out poses' refinement (RefineHeldOutPoses) take the sigmas as given.
  bool PriorFromPath = true;
  /// Weight of the smoothness prior Smoothness / 2 sum |xi_f - xi_g|^2 (each component over its sigma squared) over
  /// consecutive training frames f, g of the sweep: a tracker's error drifts along a sweep, while a correction that
  /// jumps from frame to frame fits the image, not the pose (0: none).
  double Smoothness = 0;
  /// One time offset between tracker and video shared by every frame: frame f's pose is its tracked pose moved along
  /// the tracked path's velocity v_f for the offset (bigus::PoseTimeline; needs TrainingData::Timestamps), then its
  /// own correction (RefinePoses) and the ImageToProbe correction (RefineImageToProbe). Adam on sum_f g_f . v_f over
  /// the step's frames, g_f the frame's pose gradient, with the prior Prior / 2 (offset / TimeOffsetSigma)^2.
  /// Held-out frames take it too: it belongs to the system, not to a frame. From Start.
  bool RefineTimeOffset = false;
  double TimeOffsetLearningRate = 5e-4; ///< s per step (Adam's rate)
  double TimeOffsetSigma = 0.1;         ///< s: the prior's scale
  double TimeOffsetWindow = 0.25;       ///< s: the window of the path's velocity (PoseTimeline::Build)
  /// One rigid correction of ImageToProbe shared by every frame: the same correction (rotation vector about the
  /// centre pixel, translation; CorrectPose) of every frame in its own axes, composed last (ImageToReference =
  /// ProbeToReference ImageToProbe C), so its gradient is the sum of the frames' pose gradients. The rates, sigmas
  /// and prior of the per-frame corrections. Held-out frames take it too. From Start.
  bool RefineImageToProbe = false;
  /// Where every sweep's training frames are refined (RefinePoses On), the field and every pose are moved at the end
  /// by the rigid motion that best maps the refined training frames onto their tracked poses
  /// (PoseRefiner::AnchorToTrackedPoses): the images fix the refined poses only up to a motion of the whole scene,
  /// and a user renders the field at tracked poses. The training frames' renders are unchanged by it. Not where a
  /// shared correction is refined (RefineTimeOffset, RefineImageToProbe).
  bool AnchorToTrackedPoses = true;
  /// Auto, where the rule would refine: the choice is measured on the Adam route (Trainer::TryPoseRefinement). From
  /// the refinement's start, TrialSteps steps are taken on the tracked poses and TrialSteps steps with refinement
  /// from the same state, each scored on the held-out validation frames at their tracked poses (a user renders at
  /// tracked poses); the better one goes on. 0: the rule decides alone. The rule's sweeps refine alike on every
  /// route; where no validation frames can be held out, the rule decides and its line says so.
  int TrialSteps = 400;
  /// Whether any of the pose corrections is refined (RefinePoses not Off, RefineTimeOffset, RefineImageToProbe).
  bool Any() const
  {
    return this->RefinePoses != PoseRefinement::Off || this->RefineTimeOffset || this->RefineImageToProbe;
  }
};

/// One training frame's correction as reported (TrainerReport::PoseCorrections; field data PoseCorrections).
struct FramePoseCorrection
{
  int Frame = 0;
  std::array<double, 6> Xi{}; ///< rotation vector (rad) then translation (mm) in the frame's axes (CorrectPose)
};

/// What PoseRefiner::AnchorToTrackedPoses did (TrainerReport::PoseAnchor; its line in TrainerReport::Settings).
struct PoseAnchor
{
  bool Applied = false;         ///< the field and the poses were moved
  int Frames = 0;               ///< the refined training frames whose corners decided the motion
  double RotationDegrees = 0;   ///< the angle of the motion's rotation
  double MovedMillimetres = 0;  ///< rms distance the refined frames' corners moved
  double BeforeMillimetres = 0; ///< rms distance of the refined corners from the tracked ones, before
  double AfterMillimetres = 0;  ///< the same after: the part of the corrections that is not one rigid motion
  std::string Line;             ///< the `PoseAnchor = ...` line (why not, where not applied)
};

/**
 * The pose-refinement stage. Made by the trainer with its data (the poses it writes: TrainingData::Poses holds the
 * refined poses) and settings; Configure resolves the choices, then Step moves the corrections of a step's frames.
 */
class BIGUSTRAINING_EXPORT PoseRefiner
{
public:
  /**
   * Resolves RefinePoses Auto (sweep by sweep, from @p measured(): ChoosePoseRefinement) and a negative Start
   * (ChoosePoseRefinementStart), appends this stage's `setting` lines to @p lines, keeps the tracked poses of
   * @p data and sizes @p state's corrections. @p data must outlive the refiner; @p measured is called at most once.
   */
  void Configure(TrainingData* data, const PoseRefinementSettings& settings,
    const std::function<const std::vector<SweepDecorrelation>&()>& measured, TrainingState& state,
    std::vector<std::string>& lines);
  /// Builds the tracked path in time (RefineTimeOffset; false with @p error when the data have no timestamps).
  bool Prepare(std::string* error);
  /// No step will be taken (the pixel-grid fit): the per-frame corrections are turned off, and the `RefinePoses`
  /// line of @p lines says why (@p reason).
  void TurnOffCorrections(TrainingState& state, std::vector<std::string>& lines, const std::string& reason);

  /// The settings as resolved by Configure (RefinePoses On or Off, Start in [0, 1]).
  const PoseRefinementSettings& GetSettings() const { return this->Settings; }
  /// Whether a step at @p fraction of the schedule moves the corrections (never while Suspend holds them).
  bool RefinesAt(double fraction) const
  {
    return this->Settings.Any() && fraction >= this->Settings.Start && !this->Suspended;
  }
  /// While @p suspended, no step moves the corrections (the trusted branch of Trainer::TryPoseRefinement).
  void Suspend(bool suspended) { this->Suspended = suspended; }
  /// Whether RefinePoses Auto chose to refine and the choice is still to be measured (TrialSteps > 0); EndTrial
  /// clears it, whatever the trial found.
  bool IsTrialPending() const { return this->TrialPending; }
  void EndTrial() { this->TrialPending = false; }
  /**
   * Where RefinePoses Auto's trial cannot be run (@p why, "untested: ..."), the tracked path decides: where a refined
   * sweep's path jitters over PoseRefinementEarlyJitter (a tracker's noise shows in the path itself), refinement goes
   * on without the trial from Start (where chosen, the path's: ChoosePoseRefinementStart, 0), the
   * trial ends and the `RefinePoses = on (...)` line of @p lines says why; returns true. Elsewhere returns false and
   * changes nothing (the caller keeps the tracked poses, the simplest candidate). On a liver sweep whose training
   * poses were moved by 0.5 degrees and 0.5 mm, refinement from the first step scored higher than the tracked poses
   * at 60, 120 and 300 s on 2 cores, where the trial has no room (docs/FINDINGS.md, "Untested, the tracked path
   * decides").
   */
  bool RefineUntested(std::vector<std::string>& lines, const std::string& why);
  /// Adds what the trial found (@p how) to the `RefinePoses = on (...)` line of @p lines.
  void AnnotateChoice(std::vector<std::string>& lines, const std::string& how) const;
  /// The steps a trial needs left, in branches: 10 under a time budget (@p timeBudget; the branch it discards is lost
  /// to the run), 4 without one (there it costs time, not steps; docs/FINDINGS.md, "The pose trial's price at short
  /// budgets").
  static double TrialRoom(bool timeBudget) { return timeBudget ? 10.0 : 4.0; }
  /// The earliest share of the schedule a trial starts at where Start is chosen (negative): scored from the seeds'
  /// field, or from 20 %, the branches' 400 steps cannot show refinement's gain (its corrections first wander while
  /// the field forms); from 40 % they do, on a liver sweep whose training poses were moved by 0.5 degrees and 0.5 mm
  /// (docs/FINDINGS.md, "The pose trial from 40 % of the schedule").
  static constexpr double TrialStart = 0.4;
  /// The share of the schedule a pending trial runs at: Start, or TrialStart where the start is chosen and a refined
  /// sweep's path jitters over PoseRefinementEarlyJitter (the corrections then move from the path's start, 0, and
  /// the trial measures whether to keep them: docs/FINDINGS.md, "Untested, the tracked path decides").
  double GetTrialFraction() const { return this->TrialFraction; }
  /// Whether the corrections move before a pending trial (GetTrialFraction after Start): a checkpoint's moved
  /// corrections then do not say whether the trial ran (the trainer tells from its step).
  bool MovesBeforeTrial() const { return this->TrialFraction > this->Settings.Start; }
  /// Sets every per-frame correction of @p state, its Adam moments and step counts to zero and composes the poses
  /// again (the tracked poses); returns whether any had moved (nothing changes otherwise).
  bool ResetCorrections(TrainingState& state);
  /// What the `RefinePoses = on (...)` line said when Configure wrote it, without the brackets (empty where it
  /// wrote no such line): why the rule refines, kept for a line that later replaces it.
  const std::string& GetRuleText() const { return this->RuleText; }
  /// Whether the training frames of sweep @p sweep (TrainingData::Sweeps) have their poses refined.
  bool IsSweepRefined(int sweep) const
  {
    return sweep >= 0 && sweep < static_cast<int>(this->RefinedSweeps.size()) && this->RefinedSweeps[sweep] != 0;
  }
  /// The frames' poses as the trainer was given them (filled where Settings.Any()).
  const std::vector<std::array<double, 16>>& GetTrackedPoses() const { return this->TrackedPoses; }

  /**
   * Adam on the corrections of @p frames from their pose gradients @p gradients ([frames, 6], dL/dxi of
   * FieldGradients::SlicePoses) and the priors, at the rates times @p rateScale (the trainer's roll-back scale), and
   * on the shared corrections from their sum; the poses of the frames that moved are composed again. A frame whose
   * gradient is not finite keeps its correction.
   */
  void Step(
    const std::vector<int>& frames, const std::vector<double>& gradients, double rateScale, TrainingState& state);
  /// Every frame's pose composed from its tracked pose and @p state's corrections (after they were replaced).
  void ComposePoses(const TrainingState& state);
  /// The frames not trained on take the smooth part of their sweep's training corrections (CorrectUntrainedFrames)
  /// where RefinePoses is On; returns what was chosen (empty otherwise).
  UntrainedCorrection PlaceUntrainedFrames(TrainingState& state);
  /**
   * Moves @p field (means and rotations) and every pose by the rigid motion T that best maps the corners of the
   * refined training frames (their pixel-grid corners under the refined poses) onto the same corners under the
   * tracked poses (least squares, Umeyama, IEEE TPAMI 13(4), 1991, without scaling): the corrections keep what
   * distinguishes the frames and lose the motion of the whole scene, which no image fixes (docs/FINDINGS.md, "Pose
   * refinement on synthetic truth, scored fairly"). Each refined training frame's correction becomes the one that
   * puts it at T times its refined pose, so a training frame renders the moved field at its moved pose exactly as
   * before (rounding aside). Applied where RefinePoses is On, AnchorToTrackedPoses is set, every sweep is refined
   * (a trusted sweep anchors the scene already) and no shared correction (RefineTimeOffset, RefineImageToProbe) is:
   * those correct an error common to every tracked pose, which the anchor would put back. Call it before
   * PlaceUntrainedFrames.
   */
  PoseAnchor AnchorToTrackedPoses(TrainingState& state, GaussianField& field);
  /// The training frames' corrections, for the report (refined sweeps only).
  std::vector<FramePoseCorrection> Corrections(const TrainingState& state) const;
  /// Whether a checkpoint's state @p loaded holds the corrections this run refines (same settings, same sweep);
  /// false with @p error naming @p file otherwise.
  bool CheckCheckpoint(const TrainingState& loaded, const std::string& file, std::string* error) const;
  /**
   * A checkpoint's state @p loaded (from @p file) taken up. One written after the pose-refinement trial goes on with
   * its choice, read from its corrections: none, trusted (TurnOffCorrections, the RefinePoses line of @p lines says
   * so); one that moved, refined; @p trialDone says whether either applied (the checkpoint does not store the
   * outcome). Then CheckCheckpoint; false with its @p error.
   */
  bool Resume(TrainingState& loaded, std::vector<std::string>& lines, const std::string& file, bool& trialDone,
    std::string* error);

private:
  /// Frame @p frame's pose in the data: its tracked pose at its timestamp plus the time offset, then its own
  /// correction, then the ImageToProbe correction (each when refined).
  void ComposePose(int frame, const TrainingState& state);
  /// Frame @p frame's tracked pose at its timestamp plus the time offset: the pose its own correction moves.
  std::array<double, 16> UncorrectedPose(int frame, const TrainingState& state) const;

  TrainingData* Data = nullptr;
  PoseRefinementSettings Settings;
  std::vector<std::array<double, 16>> TrackedPoses;
  std::vector<bool> TrackedValid;  // the renderer accepts the tracked pose (others are never corrected)
  PoseTimeline Timeline;           // RefineTimeOffset
  std::vector<char> RefinedSweeps; // RefinePoses: 1 for each sweep whose training frames are refined
  std::vector<double> PriorScales; // [sweeps] the factor on the frames' prior sigmas (PriorFromPath; else 1)
  bool Suspended = false;
  bool TrialPending = false;
  double TrialFraction = 0;            // GetTrialFraction
  PoseRefinementStartChoice PathStart; // the tracked path's rule (where Start is chosen or a trial is pending)
  std::string RuleText;                // the `RefinePoses = on (...)` line's text as Configure wrote it
};

/**
 * The fair score of frames that were not trained on, when poses are imperfect: each of @p frames (indices into
 * @p data) has its pose refined with @p field frozen, as view-synthesis papers score held-out views under
 * pose error (Lin et al. 2021, BARF, section 4; Wang et al. 2021, NeRF--): @p steps Adam steps per frame
 * (@p settings' rates) on the gradient of the image loss (@p loss) with respect to a rigid correction of the
 * frame's pose about its centre pixel (FieldGradients::SlicePoses, bigus::CorrectPose), plus the training prior
 * Prior / 2 (|omega|^2 / RotationSigma^2 + |t|^2 / TranslationSigma^2). No smoothness term: the frames are scored
 * one by one. The field never moves (every learning rate of its parameters is 0). @p data's Poses of @p frames become
 * the refined poses; @p corrections ([frames.size()]: rotation vector, rad; translation, mm, in the frame's own axes)
 * what was applied. Rendering with @p options on the training engine of @p backend. Returns false with @p error when
 * the engine cannot be made or a pose is rejected.
 */
BIGUSTRAINING_EXPORT bool RefinePosesWithFieldFrozen(const GaussianField& field, TrainingData& data,
  const std::vector<int>& frames, const RenderOptions& options, const PoseRefinementSettings& settings,
  const ImageLossWeights& loss, int steps, const std::string& backend, std::vector<std::array<double, 6>>& corrections,
  std::string* error);

} // namespace bigus

#endif
