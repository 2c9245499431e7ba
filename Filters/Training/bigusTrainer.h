/**
 * @file bigusTrainer.h
 * @brief The BIGUS training loop and its schedule (DESIGN section 4), independent of the VTK pipeline:
 *        settings chosen from the data, the steps, when to densify (bigusDensification.h) and to solve
 *        the reflectivities (bigusReflectivitySolve.h), adaptive growth stop, validation and early
 *        stopping, the final prune, NaN roll-back, checkpoints. The first field comes from
 *        bigusSeeding.h, frame metrics from bigusFrameMetrics.h. vtkGaussianFieldTrainer wraps it.
 *
 * Part of BIGUS::Training (public, not wrapped for Python). Deterministic for a given seed and thread
 * count on the CPU backend when scheduled by Iterations (TimeBudget alone follows the clock).
 */
#ifndef bigusTrainer_h
#define bigusTrainer_h

#include "bigusTrainingModule.h" // For export macro
#include "bigusElevationSigma.h"
#include "bigusFrameMetrics.h"
#include "bigusImageMetrics.h"
#include "bigusRenderer.h"
#include "bigusTrainerSettings.h"
#include "bigusTrainingEngine.h"
#include "bigusValidation.h"

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace bigus
{

/// What a run did.
struct TrainerReport
{
  int Iterations = 0;
  double Seconds = 0; ///< s: Train, Finish and the first reflectivity solve (not the seeding)
  std::string StopReason;
  std::string GrowthStopReason;
  std::int64_t InitialGaussians = 0; ///< seeds the run started from
  std::int64_t Gaussians = 0;
  std::int64_t PrunedAtEnd = 0;
  GapFillingReport GapFilling;       ///< what Finish's gap filling added (FillGaps)
  GaussianMergeReport Merge;         ///< what Finish's merge did (TrainerSettings::Merge)
  int Solves = 0;                    ///< reflectivity solves run (ReflectivitySolve)
  double SolveSeconds = 0;           ///< their time, s (all count towards TimeBudget, the first one's too)
  ReflectivitySolveReport LastSolve; ///< the last solve: iterations, objective per iteration
  /// With Solve.L1: the last solve's L1 part (FISTA), and how many Gaussians it set to 0 and removed before the
  /// least-squares refit that LastSolve describes (the relaxed lasso).
  ReflectivitySolveReport LastL1Solve;
  std::int64_t LastL1Removed = 0;
  double Gamma = 0;
  double LastLoss = 0;       ///< mean loss of the last 50 steps
  double ElevationSigma = 0; ///< mm, the sigma trained with (given or chosen)
  HeldOutChoices HeldOut;    ///< the choices measured on held-out frames (ChooseOnHeldOutFrames)
  RouteTrial Route;          ///< the route measured where the rule gives Harris seeds and Adam (RouteTrial)
  /// Early stopping: the iteration whose field Finish kept (the best on the validation frames; a field
  /// measured just before a densification carries that densification's iteration), the validation
  /// loss there and that of the last field (equal when the last was kept).
  int BestIteration = 0;
  double BestValidationLoss = 0, LastValidationLoss = 0;
  /// Every validation measurement of this run, in order: the field at Iteration (before that
  /// iteration's densification, if any) had Gaussians Gaussians and this mean loss on the validation
  /// frames. The last one is Finish's. Stored in the field data as ValidationHistory.
  struct ValidationRecord
  {
    int Iteration = 0;
    double Loss = 0;
    std::int64_t Gaussians = 0;
  };
  std::vector<ValidationRecord> ValidationHistory;
  /// The frames validation scores: held out of the fit (HeldOutChoiceSettings::ValidationStride) or, where too few
  /// are, training frames (ValidationFrames).
  std::vector<int> ValidationFrames;
  bool ValidationHeldOut = false; ///< whether ValidationFrames were held out of the fit
  /// The iteration at which the held-out validation frames joined the fit (the densification window closed, or
  /// Finish); -1 when none was held out. Early stopping and growth decide on the measurements before it.
  int ValidationJoinedAt = -1;
  /// Pose refinement (RefinePoses): each training frame's correction, rotation vector (rad) then
  /// translation (mm) in its own axes about its centre pixel (bigus::CorrectPose); empty when off.
  using PoseCorrection = FramePoseCorrection;
  std::vector<PoseCorrection> PoseCorrections;
  /// RefinePoses: how the frames not trained (held out) were placed among the refined ones
  /// (bigus::CorrectUntrainedFrames).
  UntrainedCorrection UntrainedCorrections;
  /// RefinePoses: the rigid motion that moved the field and the poses onto the tracked poses at the end
  /// (PoseRefiner::AnchorToTrackedPoses); its line is in Settings.
  PoseAnchor Anchor;
  /// ParameterAverage: the average made the field (when the schedule ended, or in Finish) of AverageSamples samples
  /// from step AverageFrom to AverageTo; 0 samples: the last step's field (off, or the run ended before the
  /// densification window closed).
  int AverageSamples = 0, AverageFrom = -1, AverageTo = -1;
  /// The average scored worse on the validation frames than a field early stopping had kept (BestIteration), which
  /// is the run's field instead (Finish); the ParameterAverage line says so.
  bool AverageReplaced = false;
  /// RefineTimeOffset: the offset (s) added to every frame's timestamp to find its tracked pose.
  double TimeOffset = 0;
  /// RefineImageToProbe: the correction of every frame (rotation vector, rad; translation, mm; CorrectPose).
  std::array<double, 6> ImageToProbeCorrection{};
  /// Every setting the run depends on that the trainer chose or was given, one line each
  /// ("ElevationSigma = 0.306 mm (chosen: ...)"), filled by the constructor and Initialize: printed by
  /// `bigus train` and stored in the field data (TrainingSettings) so that a run can be reproduced.
  std::vector<std::string> Settings;
};

/**
 * The training loop. It owns the schedule (frames drawn per step, learning rates, densification,
 * growth stop, roll-back, checkpoints, final prune) and keeps a host copy of the TrainingState; the
 * step itself runs in the TrainingEngine given to it, which owns the per-Gaussian state between
 * steps (bigusTrainingEngine.h). Host-side work pulls the state from the engine and pushes it back.
 */
class BIGUSTRAINING_EXPORT Trainer
{
public:
  /// @p engine runs the steps; null means the CPU engine (CreateTrainingEngine("cpu")).
  Trainer(TrainingData data, const TrainerSettings& settings, std::unique_ptr<TrainingEngine> engine = nullptr);
  ~Trainer();
  Trainer(Trainer&&) noexcept;
  Trainer& operator=(Trainer&&) noexcept;

  /**
   * Initial field (Harris or random) and gamma. Returns false with @p error on bad data: no training
   * frame, inconsistent sizes, an empty mask, or a training pose the renderer rejects ("training
   * frame 12: ImageToReference is sheared ... by 7.20 degrees; the renderer accepts at most 5.00":
   * bigus::DefaultMaximumShearAngle, also the reader's default limit). Data-parallel: a process that fails
   * these checks fails every process before the first sum ("another process failed (rank R)").
   */
  bool Initialize(std::string* error);
  /**
   * Call before Initialize when LoadCheckpoint follows: the route trial (RouteTrial) then holds out its frames as
   * the checkpoint's run did, without fitting the pixel grid again (LoadCheckpoint ends the trial: the checkpoint's
   * run goes on with its steps).
   */
  void SetResuming(bool resuming) { this->Resuming = resuming; }
  /**
   * Data-parallel training over the processes of @p reduction (null: this process alone); call before
   * Initialize, on every process with the same data and settings. Every process draws the same FramesPerStep x
   * Size() frames per step and renders its share, the engine sums gradients, EA-D accumulators and the loss
   * (TrainingEngine::SetReduction), so every process takes the same Adam step and the same densification and
   * pruning decisions: the fields stay identical. The clock of a time budget is the slowest process's; only
   * rank 0 writes checkpoints (a resumed run reads them on every process). False with @p error when the engine
   * cannot sum across processes.
   */
  bool SetProcessReduction(ProcessReduction* reduction, std::string* error);
  /// Start from a given field instead (gamma still from the data).
  bool SetField(const GaussianField& field, std::string* error);

  /**
   * Train until Iterations, TimeBudget (the run's training seconds, this call's included), convergence
   * or @p abort; the field is
   * not pruned (Finish does that), so training may go on with another call. @p progress(fraction,
   * iteration, loss, gaussians) is called every few steps. Returns false with @p error on an
   * unrecoverable problem (a step the renderer refuses, every step non-finite, a checkpoint not written).
   */
  bool Train(const std::function<void(double, int, double, std::int64_t)>& progress, const std::function<bool()>& abort,
    std::string* error);
  /**
   * Ends a run: early stopping, the final prune, gap filling, the merge and the report's totals. Early stopping:
   * the validation frames (TrainerReport::ValidationFrames: on the Adam route held out of the fit until the
   * densification window closes, HeldOutChoiceSettings::ValidationStride) are rendered every Densification.Interval
   * steps; when a field seen before they joined the fit scored a lower validation loss than the last one measured
   * before, that field is kept (fresh optimiser moments) and the report says so (BestIteration). Where they join
   * during Train, the choice is made there and training goes on from the kept field with them; otherwise it is made
   * here, and they join before the final prune. Returns false with @p error when the engine fails.
   */
  bool Finish(std::string* error);
  /// Train, then Finish.
  bool Run(const std::function<void(double, int, double, std::int64_t)>& progress, const std::function<bool()>& abort,
    std::string* error);
  /**
   * One optimisation step (no densification) on FramesPerStep frames drawn at random. @p loss receives
   * its loss (NaN when the step was rolled back: StepStatus::NonFinite). StepStatus::Failed, with
   * @p error, when the engine could not render or differentiate a frame.
   */
  StepStatus Step(double* loss, std::string* error);

  /// Checkpoint: the whole TrainingState and gamma (format in bigusTrainingEngine.h). Data-parallel: every
  /// process loads the file, and one that cannot fails every process (ProcessReduction::AllSucceeded).
  bool SaveCheckpoint(const std::string& file, std::string* error);
  bool LoadCheckpoint(const std::string& file, std::string* error);

  /**
   * Render @p frames at their poses (PlaceUntrainedFrames first) and compare them with the recorded frames inside
   * the mask (bigus::MeanFrameMetrics); @p metrics receives the mean of each metric. @p secondsPerFrame, if
   * non-null, receives the mean render time per frame (s). Returns false with @p error when a frame
   * cannot be rendered.
   */
  bool Evaluate(
    const std::vector<int>& frames, ImageMetrics& metrics, std::string* error, double* secondsPerFrame = nullptr);
  /// With RefinePoses, the frames not trained on take the smooth part of their sweep's training corrections
  /// (CorrectUntrainedFrames; report's UntrainedCorrections): Evaluate and Finish call it, so that a held-out
  /// frame is scored among its refined neighbours mid-run as at the end.
  void PlaceUntrainedFrames();
  /// The same for @p frames of other data (another frame size, e.g. a test sweep across the training
  /// frames). Frames whose mask is empty are left out of the means.
  bool EvaluateOn(const TrainingData& data, const std::vector<int>& frames, ImageMetrics& metrics, std::string* error,
    double* secondsPerFrame = nullptr);
  /// Intensities in [0, 1] of the field rendered at the pose of frame @p frame of @p data, at the render
  /// filters' cutoff whatever the training cutoff (the images a user gets), into @p image ([H, W] of
  /// @p data). Returns false with @p error for a pose the renderer rejects.
  bool RenderFrame(const TrainingData& data, int frame, float* image, std::string* error);

  /// The current field (pulled from the engine when steps ran since the last pull).
  const GaussianField& GetField() const;
  /// The whole training state, pulled likewise.
  const TrainingState& GetState() const;
  double GetGamma() const { return this->Gamma; }
  /// Mean in-plane pixel spacing of the training frames, mm.
  double GetPixelSpacing() const { return this->PixelSpacing; }
  const TrainerReport& GetReport() const { return this->Report; }
  /// The settings the run uses: those given, with what the trainer chose (ElevationSigma 0 replaced by the chosen
  /// sigma, RefinePoses Auto by On or Off).
  const TrainerSettings& GetSettings() const { return this->Settings; }
  /// The pose-refinement stage: the tracked poses (GetTrackedPoses; GetData() holds them as refined) and which
  /// sweeps are refined (IsSweepRefined).
  const PoseRefiner& GetPoseRefiner() const { return this->Poses; }
  int GetIteration() const { return this->State.Iteration; }
  /**
   * Whether the field, stopped now, is one the schedule would go on from without a pending repair: not inside the
   * pose-refinement trial (an abort there ends the trial untested), and not in the dip of a densification (its splits
   * cost the liver up to 10 dB held out for tens of steps; docs/FINDINGS.md, "A densification's dip and the pose
   * trial"): no densification has split or cloned a Gaussian in the last Interval - 1 steps (the step before the next
   * densification is settled). A caller that stops a run to score it mid-schedule (`bigus
   * benchmark`'s marks) waits for this.
   */
  bool IsSettled() const;
  const TrainingData& GetData() const { return *this->Data; }
  const TrainingEngine& GetEngine() const { return *this->Engine; }
  SliceGeometry Slice(int frame) const { return this->Data->Slice(frame); }
  /// The run's renderer options at its fixed cut-off (FixedTrainingCutoff): the validation loss, the final prune.
  RenderOptions Options() const;
  /**
   * The cut-off of the next step (standard deviations): TrainerSettings::Cutoff where given; where automatic (0)
   * FineTrainingCutoff on the pixel grid's route, where reflectivities are solved, while any pose is refined
   * (PoseRefinementSettings::Start on) and in both branches of the pose-refinement trial, else FastTrainingCutoff
   * (Adam on trusted poses, the steps before the refinement's start included: the liver's main job outside its
   * trial). Resolved at each step, so a checkpoint resumes to it.
   */
  double StepCutoff() const;

private:
  /// Options() at the render filters' cutoff whatever the training cutoff: the images a user gets.
  RenderOptions FilterRenderOptions() const;
  /// The seeds' shape for this run's data, settings and gamma (bigusSeeding.h).
  SeedShape SeedShapeOf() const;
  /// Initialize's part on this process alone: the data's checks, gamma, the memory check and the seeded field.
  bool PrepareInitialField(std::string* error);
  /// The choices measured on held-out frames (ChooseOnHeldOutFrames: on the pixel-grid route ElevationSigma where
  /// the rule gave it, the ridge, the final prune and the merge; elsewhere why they are untested), taken into the
  /// settings, @p plan made again for a sigma chosen (@p fanPixels: the training frames'), the setting lines
  /// rewritten.
  bool MeasureOnHeldOutFrames(std::int64_t fanPixels, SeedingPlan& plan, std::string* error);
  /// The engine takes the seeded field; its reflectivities are then solved (ReflectivitySolve) or scaled.
  bool FitInitialReflectivities(std::string* error);
  /// LoadCheckpoint's part on this process alone.
  bool ReadCheckpoint(const std::string& file, std::string* error);
  /// With several processes, whether every one succeeded (ProcessReduction::AllSucceeded, collective); alone, @p ok.
  bool Agree(bool ok, std::string* error);
  /// The reflectivities of the current geometry by least squares (ReflectivitySolve); fresh Adam
  /// moments for them.
  bool SolveFieldReflectivities(std::string* error);
  bool SolvesReflectivities() const
  {
    return (this->Settings.ReflectivitySolve || this->PixelGrid) && !this->Settings.NonNegativeReflectivity;
  }
  bool DensifyAndPrune(double validation, std::string* error);
  /// ParameterAverage: a sample of the field into the average every AverageInterval steps once the field's structure
  /// is fixed (out of the densification window, after the validation frames joined, no trial pending).
  bool SampleParameterAverage(bool window, std::string* error);
  /// The average made the field (ApplyParameterAverage), its poses composed, the report and setting line told.
  bool UseParameterAverage(std::string* error);
  /// The Adam route: the validation frames (HeldOutChoiceSettings::ValidationStride) taken out of the fit, and their
  /// setting line; too few, the training frames ValidationFrames chooses.
  void HoldOutValidationFrames();
  /**
   * The seeding @p plan made: the route trial's grid side where RouteTrialUntested allows it (MeasurePixelGridRoute,
   * its seconds counted as training), else the Route line says why not. Where the rule took the pixel grid and the
   * trial runs, @p plan becomes the Adam route's (Harris seeds), which must score above the grid by
   * RouteProbeFraction of the schedule (RouteTrial::DecideBy).
   */
  bool PlanRouteTrial(SeedingPlan& plan, std::string* error);
  /**
   * The route trial's decision: the Adam run's field scored on the trial's frames at their tracked poses against the
   * grid's score. Adam above it decides at once (more steps and frames only help it); the grid only when the frames
   * would join the fit (@p closing) or at RouteTrial::DecideBy of the schedule: it then becomes the pixel-grid fit on
   * every training frame with the grid's choices (SwitchToPixelGrid). Adam decided, the frames join
   * (JoinValidationFrames with @p last). The Route line says what each scored.
   */
  bool DecideRoute(const double* last, bool closing, std::string* error);
  /// A pending route trial ends untested (@p why): the run stays Adam's, its frames stay validation frames and the
  /// choices' lines say untested. False with @p error as MeasureOnHeldOutFrames.
  bool CancelRouteTrial(const std::string& why, std::string* error);
  /// The run from here the pixel grid's: the grid's choices in the settings, every frame in the fit at its tracked
  /// pose, the grid seeded and its reflectivities solved; Train takes no further step.
  bool SwitchToPixelGrid(std::string* error);
  /// The held-out validation frames join the fit (with RefinePoses, from their tracked poses, as they were scored),
  /// from the best field they scored when the @p last validation loss (if given) is worse (RestoreBestField); after
  /// this, a validation loss is recorded but no longer decides. Where it went back so at the window's close and the
  /// frames were held out for their own sake (MeasuresTail), the run ends BestFieldIteration steps later
  /// (TrainingState::MeasuredTailEnd).
  bool JoinValidationFrames(const double* last, std::string* error);
  /// Whether the held-out validation frames set a measured tail where early stopping goes back at their join
  /// (HeldOutChoiceSettings::MeasuredTail, with HoldOutValidationFrames On).
  bool MeasuresTail() const;
  /// The run stops at its measured tail's end (TrainingState::MeasuredTailEnd) with its last step's field: the stop
  /// reason says why, and the parameter average (whose samples from the join include the tail's first steps, before
  /// the joined frames fit) is dropped, as its line says.
  void EndMeasuredTail();
  /// One turn of Train's loop: the stop checks, a step, then what the schedule does at its iteration (validation,
  /// densification, solve, convergence, checkpoint, progress). @p stop: the run ends here (the report says why);
  /// false with @p error on an unrecoverable problem.
  bool Iterate(double start, const std::function<void(double, int, double, std::int64_t)>& progress,
    const std::function<bool()>& abort, bool& stop, std::string* error);
  /**
   * RefinePoses Auto, where the rule chose to refine, at the refinement's start (PoseRefinementSettings::TrialSteps;
   * PoseRefiner::TrialStart at the earliest where the start is chosen), or before it under a time budget where the
   * steps left will not hold the trial (PoseTrialWithoutRoom):
   * TrialSteps steps (PoseTrialSteps) on the tracked poses, then from the same state as many with refinement, each
   * scored by the PSNR of the held-out validation frames at their tracked poses; the better branch goes on (the other's
   * steps are spent time) and the RefinePoses line says what each scored. Without held-out frames, data-parallel,
   * or where the steps left are fewer than 10 x the branch's under a time budget (4 x without one), the trial is
   * not run and the choice is untested (DecideUntestedTrial), the line says so. The frames then join the fit unless
   * HoldOutValidationFrames keeps them out.
   */
  bool TryPoseRefinement(double start, const std::function<void(double, int, double, std::int64_t)>& progress,
    const std::function<bool()>& abort, bool& stop, std::string* error);
  /// The steps the schedule leaves after the share @p fraction of it (or after the current step, where later): at most
  /// Iterations', and under a time budget what its seconds allow at the rate of the recent steps (from the end of the
  /// densification interval before last, validations, densifications and solves included; before the second such
  /// end, of every step so far, the route trial's grid side excluded, which took none; unbounded before the first
  /// step). @p recent: whether that rate was the recent one.
  double StepsLeftAfter(double fraction, bool* recent = nullptr) const;
  /// Where the steps left after the pose refinement's start (StepsLeftAfter) are fewer than PoseRefiner::TrialRoom x
  /// TrialSteps: why, for the `RefinePoses` line (the trial is not run: DecideUntestedTrial); empty where they hold it.
  /// Judged at Initialize for an Iterations schedule without a time budget (before any frame is held out), and under
  /// a budget at the start and before it. @p recent: whether the steps were judged from the recent rate (before the
  /// start the trainer ends a trial without room only then: the first steps' rate counts the seeding).
  std::string PoseTrialWithoutRoom(bool* recent = nullptr) const;
  /// The steps of each of the trial's branches from step @p from: the count nearest TrialSteps whose last step comes
  /// just before a densification (where the densification window is open), so that no branch is scored in the dip
  /// of the densification its last step would have made.
  int PoseTrialSteps(int from) const;
  /// Ends RefinePoses Auto's choice with the tracked poses (PoseRefiner::TurnOffCorrections): the trial chose them or
  /// stopped in a branch, or could not be run (DecideUntestedTrial). The RefinePoses line says @p why and what the
  /// rule would have done.
  void KeepTrackedPoses(const std::string& why);
  /// Ends RefinePoses Auto's choice where its trial cannot be run (@p why): refinement without it where the tracked
  /// path jitters (PoseRefiner::RefineUntested), the tracked poses elsewhere (KeepTrackedPoses).
  void DecideUntestedTrial(const std::string& why);
  /// After the trial: the validation frames held out for it alone join the fit (validation goes on with them).
  bool EndPoseTrial(const std::string& how, std::string* error);
  /// Measures the validation loss; keeps a copy of the field when it is the best so far.
  bool CheckValidation(double& loss, std::string* error);
  /**
   * How far through its schedule the run is, in [0, 1]: the larger of iterations / Iterations and the
   * run's training seconds / TimeBudget; with a budget alone, the budget is the schedule. The mean
   * learning rate decays and the densification window closes along it.
   */
  double ScheduleFraction() const;
  /// StepCutoff's rule for a step at @p fraction of the schedule: Step resolves it at the fraction that also decides
  /// whether the step moves the poses, so the two never disagree across a clock read.
  double CutoffAt(double fraction) const;
  /// Appends @p text to the setting line (TrainerReport::Settings) that starts with @p prefix, where there is one:
  /// what the run decided after the line was written.
  void AppendToSetting(const std::string& prefix, const std::string& text);
  /// The run's seconds inside Train so far (TrainingState::TrainingSeconds, plus the call in progress).
  double TrainingSeconds() const;
  bool InDensificationWindow() const;
  /// The host state becomes the engine's (a no-op when nothing changed since the last pull).
  bool PullState(std::string* error) const;
  /// The engine takes the host state.
  bool PushState(std::string* error);

  std::unique_ptr<TrainingData> Data; // on the heap: the engine keeps a pointer to it
  TrainerSettings Settings;
  std::unique_ptr<TrainingEngine> Engine;
  std::string RunSettings;     // ResumeSettings of the settings as requested: what a checkpoint must share to resume
  std::uint64_t Digest = 0;    // TrainingDataDigest of the data as given (before held-out frames or pose corrections)
  mutable TrainingState State; // host copy, current when HostCurrent
  mutable bool HostCurrent = true;
  double Gamma = 1;
  double PixelSpacing = 1; // mean in-plane pixel spacing of the training frames, mm
  TrainerReport Report;
  ProcessReduction* Reduction = nullptr; // data-parallel training (SetProcessReduction), null alone
  double AgreedElapsed = 0;              // data-parallel: the slowest process's seconds in this Train call
  double TrainStart = 0;                 // Seconds() at the start of the Train call in progress, 0 outside
  double TrainedBefore = 0;              // the run's training seconds before that call
  struct LossWindow // ConvergenceTolerance: the finite losses since the last window, the last window's mean
  {
    double Sum = 0;
    int Count = 0;
    double Previous = -1;
  } Recent;
  bool DensificationEnded = false;    // the last Train call ended past the densification window
  bool PixelGrid = false;             // the field is the pixel-grid fit (PixelGridFit): Train takes no step
  std::vector<int> HeldOutValidation; // validation frames out of the fit until JoinValidationFrames; empty after
  std::string ValidationRule;         // HoldOutValidationFrames Auto: the rule's measurement, for the line; else empty
  bool Resuming = false;              // SetResuming
  bool SigmaByRule = false;           // ElevationSigma came from the rule (MeasureOnHeldOutFrames may measure it)
  double FrameSpacing = 0;            // mm, the training frames' median spacing the rule measured (seeds; 0: given)
  PoseRefiner Poses;
  bool InPoseTrial = false; // TryPoseRefinement is running its branches: no checkpoint, no join
  int LastSplit = -1;       // the iteration of the last densification that split or cloned (IsSettled)
  // The iteration and training seconds at the last two densification intervals' ends (-1: none yet), for the rate of
  // the recent steps (StepsLeftAfter).
  std::array<int, 2> RateMarkIteration{ { -1, -1 } };
  std::array<double, 2> RateMarkSeconds{};
  GaussianField AverageSample; // the engine's field, pulled for the parameter average
  std::vector<float> S;        // scratch for RenderFrame
};

} // namespace bigus

#endif
