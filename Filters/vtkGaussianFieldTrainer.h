/**
 * @class   vtkGaussianFieldTrainer
 * @brief   Trains a beam-integrated Gaussian scattering field from a tracked ultrasound sweep.
 *
 * Input port 0: a tracked frame sequence (DESIGN section 2; e.g. vtkUltrasoundSequenceReader), or several
 * (AddInputConnection, as vtkAppendFilter takes them): sweeps of one region along different paths, each with
 * its own frame size, pixel spacing and fan mask, trained into one field (bigus::TrainingDataFromSweeps).
 * Frame indices (TrainingFrameList, the output's TrainingFrames) count the sweeps' frames one sweep after
 * the other. Sweeps whose frames share no region, whose pixel spacings differ more than tenfold
 * (different units, or a calibration that belongs to another sweep), or with an empty fan mask are
 * refused with an error that names the sweep, and no field.
 * Input port 1 (optional): the fan mask (vtkUltrasoundFanMask's output, W x H x 1), or one mask per frame
 * (W x H x N, e.g. vtkUltrasoundVolumeSweep's port 1); estimated when absent. With several sweeps: none
 * (each estimated) or one connection per sweep, in the sweeps' order.
 * Output: the Gaussian field as vtkPolyData: one point (mean, mm) and one vertex per Gaussian, point
 * data `Scale` (3 floats, standard deviations in mm along the local axes), `Rotation` (4 floats, unit
 * quaternion w, x, y, z) and `Reflectivity` (signed); field data `ElevationSigma` (mm), `Gamma`,
 * `TrainingFrames` (frame indices), `InitialGaussians` (seeds), `Iterations`, `TrainingSeconds`,
 * `StopReason`, `GrowthStopReason`, with several sweeps `TrainingSweeps` (2 components per training frame:
 * Sweep, Frame within it), early stopping's `BestIteration`, `BestValidationLoss` and
 * `LastValidationLoss`, `ValidationHistory` (3 components per validation: Iteration, Loss, Gaussians),
 * `GapFilling` (string: what FillGaps added, or "off"), `GaussianMerge` (string: what the merge did, or "off"),
 * `ReflectivitySolves` (string, when the reflectivities were solved: how many solves, their seconds, the last one's
 * CGLS iterations and objective) (bigus::TrainerReport), the training geometry `TrainingPoses`, `TrainingFrameSize`,
 * `TrainingFanMask` (what the render filters' Coverage array is computed from), `TrainingSettings` (strings: every
 * setting the run chose or was given, "name = value (why)", as bigus::TrainerReport::Settings, plus the fan mask's
 * origin).
 *
 * Events: SettingsChosenEvent (vtkCommand::UserEvent + 1) is invoked once per run, before the first
 * step, when the settings are chosen (GetSettingsText() then holds them, one per line); `bigus train`
 * prints them.
 *
 * The method (BIGUS; DESIGN section 4): seeds from the Harris response of the training frames inside
 * the fan mask (or uniform random, for the ablation), gamma = -ln(1 - mean masked intensity), Adam on
 * means, log-scales, quaternions and reflectivities, loss = L1 + D-SSIM + focal frequency loss on the
 * masked pixels, error-attributed densification (the top DensifyPercentile of the attribution score
 * sum_p |dL/dS(p)| |r_i| w_i(p) is split or cloned (bigus::DensifyGaussian); negligible and never-seen
 * Gaussians pruned), growth that stops when a validation subset of the training frames stops
 * improving, and a final prune of every Gaussian whose removal changes no training pixel by more than
 * 1/512.
 *
 * Defaults: every setting's default, and the rule that chooses it from the data where it is chosen, is
 * bigus::TrainerSettings' (bigusTrainer.h and the stage headers it cites; the measurements behind them are in
 * docs/FINDINGS.md): the setters below write into one TrainerSettings, and a run's TrainingSettings says what
 * was chosen and why.
 *
 * What limits held-out quality: held-out error is close to the training-frame error plus the error
 * of blending the two bracketing recorded frames (the part of a held-out frame that no neighbour
 * holds): MSE_held-out ~ MSE_training + MSE_blend, so held-out PSNR stays below the blend of the
 * recorded frames however well the training frames are fitted, and training fit is bought with steps
 * per frame and capacity. `bigus benchmark` reports this split for every sweep.
 *
 * Stopping: Iterations, TimeBudget (s) or ConvergenceTolerance, whichever first; AbortExecute is
 * honoured and UpdateProgress called: set during a run (from a progress observer), it ends training at the next
 * step, writes a checkpoint to CheckpointFile if one is set (not data-parallel: a process that could not write it
 * would leave the others waiting), and outputs the field trained so far (StopReason "aborted"). Checkpoints
 * (CheckpointFile every CheckpointInterval steps) hold the field and the optimiser state; ResumeFile continues a
 * stopped run (same settings). Deterministic for a given Seed and thread count when scheduled by Iterations (a run
 * scheduled by TimeBudget depends on the machine's speed). Errors (no valid frames, empty mask, a training pose the
 * renderer rejects, an unavailable Backend, an unreadable checkpoint) fail the request with
 * vtkErrorMacro and an empty output.
 *
 * Setters: a value outside a setting's range is clamped to it (as vtkSetClampMacro does; the ParaView XML's range
 * domains are the same ranges); NaN, which no clamp moves, is refused with vtkErrorMacro and the setting kept.
 */
#ifndef vtkGaussianFieldTrainer_h
#define vtkGaussianFieldTrainer_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkCommand.h"         // For SettingsChosenEvent
#include "vtkPolyDataAlgorithm.h"

#include <memory> // For std::unique_ptr
#include <string> // For std::string

namespace bigus
{
struct TrainerSettings;
}

class vtkMultiProcessController;

class vtkDataArray;
class vtkIdList;

class BIGUSFILTERS_EXPORT vtkGaussianFieldTrainer : public vtkPolyDataAlgorithm
{
public:
  static vtkGaussianFieldTrainer* New();
  vtkTypeMacro(vtkGaussianFieldTrainer, vtkPolyDataAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// Connect the fan mask (W x H x 1 unsigned char, or W x H x N: one mask per frame) to port 1.
  void SetMaskConnection(vtkAlgorithmOutput* output) { this->SetInputConnection(1, output); }
  /// With several sweeps: the fan mask of the next sweep (one per sweep, in the order of port 0's connections).
  void AddMaskConnection(vtkAlgorithmOutput* output) { this->AddInputConnection(1, output); }
  /// Disconnect every sweep (port 0), or every fan mask (port 1): the ParaView proxy's clean commands.
  void RemoveAllSweepConnections() { this->RemoveAllInputConnections(0); }
  void RemoveAllMaskConnections() { this->RemoveAllInputConnections(1); }

  ///@{ Elevation beam standard deviation (mm). Default 0: chosen from the sweep (bigusElevationSigma.h).
  virtual void SetElevationSigma(double value);
  virtual double GetElevationSigma() const;
  ///@}
  ///@{ Ablations: beam integration off (thin plane), non-negative reflectivities, random initialisation,
  /// no densification.
  virtual void SetBeamIntegration(bool value);
  virtual bool GetBeamIntegration() const;
  virtual void SetNonNegativeReflectivity(bool value);
  virtual bool GetNonNegativeReflectivity() const;
  virtual void SetHarrisInitialisation(bool value);
  virtual bool GetHarrisInitialisation() const;
  virtual void SetDensify(bool value);
  virtual bool GetDensify() const;
  ///@}
  ///@{ Variable projection: the reflectivities solved by least squares after seeding and after every
  /// densification, Adam between the solves (default off: Adam alone scores better at equal time;
  /// docs/FINDINGS.md, "The trainer's defaults, measured"). See bigus::TrainerSettings::ReflectivitySolve.
  virtual void SetReflectivitySolve(bool value);
  virtual bool GetReflectivitySolve() const;
  vtkBooleanMacro(ReflectivitySolve, bool);
  ///@}
  ///@{ CGLS iterations of each reflectivity solve (default 12; each one a forward and a backward pass over
  /// every training frame). See bigus::ReflectivitySolveSettings::MaximumIterations.
  virtual void SetSolveIterations(int value);
  virtual int GetSolveIterations() const;
  ///@}
  ///@{ An L1 term in every reflectivity solve (default 0: none), as a share of the weight that would set every
  /// reflectivity to 0: FISTA, then the Gaussians it set to 0 are removed and the others refitted by CGLS
  /// (bigus::ReflectivitySolveSettings::L1; the relaxed lasso).
  virtual void SetSolveL1(double value);
  virtual double GetSolveL1() const;
  ///@}
  ///@{ Share of this machine's physical memory that a reflectivity solve may hold as the assembled basis (default
  /// 0.25; 0: the matrix-free products). See bigus::ReflectivitySolveSettings::AssembledMemoryShare.
  virtual void SetSolveMemoryShare(double value);
  virtual double GetSolveMemoryShare() const;
  ///@}
  ///@{ Choices measured on held-out frames (default on): with ElevationSigma 0 and the pixel-grid fit, five
  /// candidates around the rule's value are each fitted without every second training frame and scored on those
  /// (bigusHeldOutChoices.h; TrainingSettings prints the scores). Off: the rule, untested.
  virtual void SetHeldOutChoices(bool value);
  virtual bool GetHeldOutChoices() const;
  vtkBooleanMacro(HeldOutChoices, bool);
  ///@}
  ///@{ A dense start: Gaussians on the training frames' pixel grid instead of Harris seeds (default
  /// off; bigus::TrainerSettings::DenseInitialisation).
  virtual void SetDenseInitialisation(bool value);
  virtual bool GetDenseInitialisation() const;
  vtkBooleanMacro(DenseInitialisation, bool);
  ///@}
  ///@{ The fit when the data are few (default on): when the training planes hold at most twice
  /// MaximumGaussians fan pixels, the field is a pixel grid (every fan pixel, or MaximumGaussians of them)
  /// with solved reflectivities and no geometry step is taken (bigus::TrainerSettings::PixelGridFit). Applies
  /// with the default start only.
  virtual void SetPixelGridFit(bool value);
  virtual bool GetPixelGridFit() const;
  vtkBooleanMacro(PixelGridFit, bool);
  ///@}
  ///@{ The validation frames, on which growth stops and early stopping keeps a field
  /// (bigus::HeldOutChoiceSettings::HoldOutValidationFrames): HELD_OUT_VALIDATION_OFF (0, training frames),
  /// HELD_OUT_VALIDATION_ON (1, held out of the fit until the densification window closes, then joined to it) or
  /// HELD_OUT_VALIDATION_AUTO (2, the default: held out where no sweep's neighbouring training frames share speckle,
  /// bigus::HoldOutValidationByRule). TrainingSettings' Validation line says which frames decided and why.
  enum
  {
    HELD_OUT_VALIDATION_OFF = 0,
    HELD_OUT_VALIDATION_ON = 1,
    HELD_OUT_VALIDATION_AUTO = 2
  };
  virtual void SetHeldOutValidation(int value);
  virtual int GetHeldOutValidation() const;
  void SetHeldOutValidationToAuto() { this->SetHeldOutValidation(HELD_OUT_VALIDATION_AUTO); }
  ///@}
  ///@{ The measured tail (bigus::HeldOutChoiceSettings::MeasuredTail, default on): where the validation frames were
  /// held out of the fit and early stopping went back to an earlier field when they joined it, the run goes on as many
  /// steps after the join as the fit took to that field, then stops (StopReason "measured tail (...)"), its field the
  /// last step's. Off: the fit goes on to the schedule's end.
  virtual void SetMeasuredTail(bool value);
  virtual bool GetMeasuredTail() const;
  vtkBooleanMacro(MeasuredTail, bool);
  ///@}
  ///@{ Pose refinement: a rigid correction of each training frame's pose, optimised with the field
  /// (bigus::PoseRefinementSettings::RefinePoses): POSE_REFINEMENT_OFF (0, the tracked poses are trusted),
  /// POSE_REFINEMENT_ON (1, every sweep's training frames) or POSE_REFINEMENT_AUTO (2, the default: chosen sweep by
  /// sweep, bigus::ChoosePoseRefinement; TrainingSettings says what was chosen and why). Where poses are refined, the
  /// output's field data holds PoseCorrections, one tuple per refined training frame: Frame, rotation about the frame's
  /// u, v, n axes through its centre pixel (degrees), translation along u, v, n (mm) (bigus::CorrectPose),
  /// TrainingPoses are the refined poses, and RefinedPoses (16 components, one tuple per input frame, the sweeps'
  /// frames in turn) every frame's pose as refined, TrackedPoses the same frames' poses as given (RefinedPoses'
  /// matching key for bigus evaluate) (held-out frames take the shared corrections and the smooth part of their sweep's
  /// training corrections, bigus::CorrectUntrainedFrames), and UntrainedPoseCorrection (one tuple: the held-out frames
  /// so corrected, the kernel's width in training-frame intervals, 0 for none and infinity for the sweep's mean, and
  /// the leave-one-out errors in mm of no correction and of the chosen width).
  enum
  {
    POSE_REFINEMENT_OFF = 0,
    POSE_REFINEMENT_ON = 1,
    POSE_REFINEMENT_AUTO = 2
  };
  virtual void SetRefinePoses(int value);
  virtual int GetRefinePoses() const;
  vtkBooleanMacro(RefinePoses, int);
  void SetRefinePosesToAuto() { this->SetRefinePoses(POSE_REFINEMENT_AUTO); }
  ///@}
  ///@{ Refinement of one tracker-to-video time offset shared by every frame (default off;
  /// bigus::PoseRefinementSettings::RefineTimeOffset; needs the sweeps' Timestamp). The output's field data then holds
  /// TimeOffset (s, added to every frame's timestamp to find its tracked pose) and RefinedPoses.
  virtual void SetRefineTimeOffset(bool value);
  virtual bool GetRefineTimeOffset() const;
  vtkBooleanMacro(RefineTimeOffset, bool);
  ///@}
  ///@{ Refinement of one ImageToProbe correction shared by every frame (default off;
  /// bigus::PoseRefinementSettings::RefineImageToProbe). The output's field data then holds ImageToProbeCorrection
  /// (rotation about u, v, n through the centre pixel of the frame grid, degrees; translation along u, v, n,
  /// mm), ImageToProbeCorrectionMatrix (row-major 4x4 M in pixel indices: the corrected ImageToProbe is
  /// ImageToProbe M; M depends on the pixel spacing, and is the first training frame's sweep's when sweeps of
  /// other spacings are trained together) and RefinedPoses.
  virtual void SetRefineImageToProbe(bool value);
  virtual bool GetRefineImageToProbe() const;
  vtkBooleanMacro(RefineImageToProbe, bool);
  ///@}
  ///@{ Where every sweep's poses are refined, move the field and every pose at the end by the rigid motion that
  /// best maps the refined training frames onto their tracked poses (default on;
  /// bigus::PoseRefinementSettings::AnchorToTrackedPoses), so that the field renders at tracked poses where the
  /// refinement left the scene; the PoseAnchor line of TrainingSettings says by how much.
  virtual void SetAnchorPosesToTracked(bool value);
  virtual bool GetAnchorPosesToTracked() const;
  vtkBooleanMacro(AnchorPosesToTracked, bool);
  ///@}
  ///@{ RefinePoses Auto, where the speckle rule would refine: steps taken each way (on the tracked poses, with
  /// refinement) from 40 % of the schedule where the refinement's start is chosen (the given start otherwise:
  /// bigus::PoseRefiner::GetTrialFraction; where the tracked path jitters, the corrections move before it), scored on held-out frames at their tracked poses, the better going on (default
  /// 400; 0: the rule alone; bigus::PoseRefinementSettings::TrialSteps). Where the steps left after the start are
  /// fewer than 10 x these under a time budget (4 x without one) the trial is not run: the poses are refined from the
  /// first steps where the tracked path jitters over 0.35 mm from frame to frame, and kept elsewhere
  /// (bigus::PoseRefiner::RefineUntested).
  /// The TrainingSettings' RefinePoses line gives both scores, or why the choice is untested.
  virtual void SetPoseTrialSteps(int value);
  virtual int GetPoseTrialSteps() const;
  ///@}
  ///@{ Weight of the smoothness prior on the pose corrections along the sweep (default 0;
  /// bigus::PoseRefinementSettings::Smoothness).
  virtual void SetPoseSmoothness(double value);
  virtual double GetPoseSmoothness() const;
  ///@}
  ///@{ Where poses are refined: the share of the schedule (0 to 1) trained on the tracked poses before the
  /// corrections move; negative (default): chosen from the tracked path's jitter (bigus::ChoosePoseRefinementStart:
  /// 0 where it jitters over 0.35 mm, else 0.2), and where the choice is measured (PoseTrialSteps) on a path that
  /// does not jitter, 0.4, the trial's start (TrainingSettings says why).
  virtual void SetPoseRefinementStart(double value);
  virtual double GetPoseRefinementStart() const;
  ///@}
  ///@{ Adam over the Gaussians a step touched only (default on; off moves every Gaussian every step on its
  /// momentum, the ablation; bigus::TrainerSettings::SparseAdam).
  virtual void SetSparseAdam(bool value);
  virtual bool GetSparseAdam() const;
  vtkBooleanMacro(SparseAdam, bool);
  ///@}
  ///@{
  /**
   * Stopping and schedule: Iterations (steps), TimeBudget (wall-clock seconds, 0 = none),
   * ConvergenceTolerance (relative, 0 = off); whichever ends first. The mean learning rate decays and
   * the densification window (to 60 %) closes along the schedule, which is the larger of
   * steps / Iterations and seconds / TimeBudget: with Iterations 0 and a TimeBudget the budget alone is
   * the schedule and training runs until it (Iterations 0 without a budget means 3000). The end-of-run
   * stages (final prune, gap filling, merge) follow the budget's last step: on the liver's 300 s main job
   * on 2 cores they took 6 to 12 s more (docs/FINDINGS.md). A run scheduled by time is not reproducible
   * step for step; one scheduled by Iterations is.
   */
  virtual void SetIterations(int value);
  virtual int GetIterations() const;
  virtual void SetTimeBudget(double value);
  virtual double GetTimeBudget() const;
  virtual void SetConvergenceTolerance(double value);
  virtual double GetConvergenceTolerance() const;
  ///@}
  ///@{ Field size: seeds (0 = automatic, see above) and hard maximum (gap filling's copies included: a gap
  /// whose copies would exceed it is bridged by the strongest Gaussians only and field data `GapFilling` says so).
  virtual void SetInitialGaussians(vtkIdType value);
  virtual vtkIdType GetInitialGaussians() const;
  virtual void SetMaximumGaussians(vtkIdType value);
  virtual vtkIdType GetMaximumGaussians() const;
  ///@}
  ///@{ Loss weights (L1, D-SSIM, focal frequency loss): a negative one is taken as 0 and NaN leaves them as they
  /// were; all three 0 is refused by the next update (an error naming the weights, no output: no step would move
  /// the field).
  virtual void SetLossWeights(double l1, double dssim, double ffl);
  void SetLossWeights(const double weights[3]) { this->SetLossWeights(weights[0], weights[1], weights[2]); }
  void GetLossWeights(double weights[3]) const;
  ///@}
  ///@{ Densification schedule: first step, last step (-1: 60 % of the schedule), interval, top percentile.
  virtual void SetDensifyStart(int value);
  virtual int GetDensifyStart() const;
  virtual void SetDensifyEnd(int value);
  virtual int GetDensifyEnd() const;
  virtual void SetDensifyInterval(int value);
  virtual int GetDensifyInterval() const;
  virtual void SetDensifyPercentile(double value);
  virtual double GetDensifyPercentile() const;
  ///@}
  ///@{ New Gaussians where the residual is largest at each densification, as a share of those densified
  /// (default 0 = off): their reflectivity is the residual (Image-GS; bigus::TrainerSettings::ResidualSeedShare;
  /// why off: docs/FINDINGS.md, "The trainer's defaults, measured").
  virtual void SetResidualSeedShare(double value);
  virtual double GetResidualSeedShare() const;
  ///@}
  ///@{ Growth stops when the validation loss improves by less than GrowthMargin (relative) on the best
  /// so far over GrowthPatience densification intervals in a row (bigus::TrainerSettings).
  virtual void SetGrowthMargin(double value);
  virtual double GetGrowthMargin() const;
  virtual void SetGrowthPatience(int value);
  virtual int GetGrowthPatience() const;
  ///@}
  ///@{ After training, bridge the gaps between training frames that are wider than the beam
  /// (bigus::FillElevationGaps; default on). Field data `GapFilling` says what was added.
  virtual void SetFillGaps(bool value);
  virtual bool GetFillGaps() const;
  vtkBooleanMacro(FillGaps, bool);
  ///@}
  ///@{ Last, merge neighbouring Gaussians that one Gaussian represents: moment-matched pairs whose relative
  /// integrated squared error ||a + b - merged||^2 / ||a + b||^2 (over 3D) stays below MergeTolerance
  /// (bigus::MergeGaussians; default 0.001, 0 = off). Field data `GaussianMerge` says what was merged.
  virtual void SetMergeTolerance(double value);
  virtual double GetMergeTolerance() const;
  ///@}
  ///@{ The trained field is an exponential moving average of its parameters (and pose corrections) over the
  /// schedule's tail, from the densification window's close, with this time constant as a fraction of the schedule
  /// (Polyak averaging; bigusParameterAverage.h; default 0.0625, 0 = off: the last step's field). The setting line
  /// `ParameterAverage` in field data TrainingSettings says which steps it averaged.
  virtual void SetParameterAverage(double value);
  virtual double GetParameterAverage() const;
  ///@}
  ///@{ Which frames to train on: all valid frames except those with index % HoldOutEvery ==
  /// HoldOutOffset (HoldOutEvery 0 = none; the index within the frame's own sweep), or the explicit list
  /// when one is set (an index outside the input fails the request); with HoldOutSweep >= 0 (default -1,
  /// none), no frame of that sweep (leave-one-sweep-out: its frames were taken along another path than
  /// every training frame; a sweep that does not exist fails the request).
  vtkSetClampMacro(HoldOutEvery, int, 0, VTK_INT_MAX);
  vtkGetMacro(HoldOutEvery, int);
  vtkSetClampMacro(HoldOutOffset, int, 0, VTK_INT_MAX);
  vtkGetMacro(HoldOutOffset, int);
  vtkSetClampMacro(HoldOutSweep, int, -1, VTK_INT_MAX);
  vtkGetMacro(HoldOutSweep, int);
  void SetTrainingFrameList(vtkIdList* frames);
  ///@}
  ///@{ Every EvaluationInterval seconds of training (0 = never), render the held-out frames (valid
  /// frames not trained on) and record their mean masked PSNR: field data "HeldOutPSNR" of the output,
  /// tuples (seconds since the start, dB, iteration), the last one of the field after the end-of-run stages
  /// (DescribeHeldOutPSNR says what the curve shows). The evaluation time counts towards TimeBudget.
  vtkSetClampMacro(EvaluationInterval, double, 0.0, 1e9);
  vtkGetMacro(EvaluationInterval, double);
  ///@}

  /**
   * What a "HeldOutPSNR" array says (tuples seconds, dB[, iteration]; files written before the iteration column
   * have two components), in one line: the best mean PSNR of the held-out frames and when, and the last. Where the
   * last is more than HeldOutPSNRDropReported (0.1 dB) below the best, the line says that more steps lowered the
   * score on frames the fit did not see: the training frames were overfitted for these views (on the spine
   * phantom's 16 frames the best came at step 860 of a 3000-step schedule, and a 1200-step schedule scored 0.4 dB
   * above its end: docs/FINDINGS.md, "The spine phantom's held-out PSNR through a schedule"), and a shorter schedule
   * may score higher. Empty for a null or empty array, or one of fewer than 2 components. What the run decides is
   * unchanged: the held-out frames are the user's, and a choice made on them would leave them no test.
   */
  static std::string DescribeHeldOutPSNR(vtkDataArray* history);
  /// dB: DescribeHeldOutPSNR names a fall of the held-out PSNR from its best above this (the curve of one run moves
  /// by a few hundredths between measurements as Adam steps on single frames).
  static constexpr double HeldOutPSNRDropReported = 0.1;
  ///@{ Random seed.
  virtual void SetSeed(unsigned int value);
  virtual unsigned int GetSeed() const;
  ///@}
  ///@{
  /**
   * Backend that runs the training steps: "auto" (default: the fastest available, CUDA where it is
   * built and a device is usable, else the CPU), "cpu" or "cuda", chosen through the one backend
   * registry (bigus::CreateTrainingEngine). An unavailable backend fails the request with an error
   * that names it and the available ones. GetBackendInUse() says which one the last run used (also
   * stored as the output's field data `Backend`).
   */
  vtkSetStringMacro(Backend);
  vtkGetStringMacro(Backend);
  const char* GetBackendInUse() const { return this->BackendInUse.c_str(); }
  ///@}

#ifndef __VTK_WRAP__
  ///@{
  /**
   * The trainer's settings as one bigus::TrainerSettings (C++ only): what the setters above write into, for a
   * program that keeps its own (`bigus train` binds its options to one). What a run chose from the data is in
   * GetSettingsText(), not here.
   */
  const bigus::TrainerSettings& GetTrainerSettings() const
  {
    return *this->Settings;
  }
  void SetTrainerSettings(const bigus::TrainerSettings& settings);
  ///@}
#endif

  ///@{
  /**
   * Data-parallel training, as VTK's parallel filters take it: with a controller of more than one process
   * (vtkMPIController under mpirun; every process runs this filter on the same inputs and settings), each
   * process renders and differentiates its share of every step's frames, and the gradients, EA-D
   * accumulators and loss are summed over the processes every step (AllReduce), so that every process takes the
   * same Adam step and the same densification decisions and ends with the same field (bigus::ProcessReduction).
   * A step has FramesPerStep frames per process. Only process 0 writes checkpoints. Null (default) or one
   * process: training on this process alone. Backends: cpu, and cuda (trained through the CPU engine over the
   * CUDA renderer); an engine that cannot sum across processes fails the request with an error. Whether each
   * process could read its inputs and create its backend, the trainer's own checks and the checkpoint's read are
   * agreed across the processes, so a refusal on one fails the request on all ("another process failed (rank
   * R)"). A process whose pipeline fails before this filter runs (a reader's error) never reaches it: end every
   * process then (MPI_Abort), as `bigus train --distributed` does.
   */
  virtual void SetController(vtkMultiProcessController* controller);
  vtkGetObjectMacro(Controller, vtkMultiProcessController);
  ///@}
  ///@{ Training frames rendered per step (per process with a Controller); their losses are averaged.
  virtual void SetFramesPerStep(int value);
  virtual int GetFramesPerStep() const;
  ///@}
  ///@{ The renderer's footprint cut-off of a training step, in standard deviations (in plane and in elevation; 2 to
  /// 5, or 0: automatic, the default; bigus::TrainerSettings::Cutoff). Each Gaussian's dropped share of a pixel is
  /// below |r| exp(-k^2 / 2); the trained field is rendered and scored at the render filters' cut-off whatever this
  /// is. Smaller makes a step faster and fits the footprints' tails less well: 3.5 trains the liver's steps in 0.81
  /// of the time at 0.03 dB less held out, but loses where poses are refined and on the pixel-grid fit
  /// (docs/FINDINGS.md, "The training cut-off"), so the automatic choice is 3.5 where Adam steps on trusted poses and
  /// 4 elsewhere (bigus::Trainer::StepCutoff), validation and the final prune at 4. A value in (0, 2) is taken as 2,
  /// one below 0 as 0.
  virtual void SetTrainingCutoff(double value);
  virtual double GetTrainingCutoff() const;
  ///@}
  ///@{ The resolution schedule: the first CoarseFraction (0 to 1) of the schedule steps on every second pixel
  /// and row of its frames (a quarter of the pixels; bigus::TrainerSettings::CoarseFraction). Default 0.5; 0 = off.
  virtual void SetCoarseFraction(double value);
  virtual double GetCoarseFraction() const;
  ///@}
  ///@{ The coarse steps' frames as 2 x 2 averages, each Gaussian rendered through the pixel's low-pass, instead of
  /// point samples (bigus::TrainerSettings::CoarseLowPass). Default off.
  virtual void SetCoarseLowPass(bool value);
  virtual bool GetCoarseLowPass() const;
  vtkBooleanMacro(CoarseLowPass, bool);
  ///@}

  ///@{ Checkpoints: written every CheckpointInterval steps (0 = never) to CheckpointFile;
  /// ResumeFile continues from one, schedule included: the seconds trained before it count towards
  /// TimeBudget (a run stopped at 70 % of its budget and resumed trains for the remaining 30 %).
  virtual void SetCheckpointFile(const char* file);
  const char* GetCheckpointFile() const;
  virtual void SetCheckpointInterval(int value);
  virtual int GetCheckpointInterval() const;
  vtkSetStringMacro(ResumeFile);
  vtkGetStringMacro(ResumeFile);
  ///@}

  ///@{ State of the run in progress (read them in a ProgressEvent observer): step, loss of the last
  /// step, number of Gaussians.
  vtkGetMacro(CurrentIteration, int);
  vtkGetMacro(CurrentLoss, double);
  vtkGetMacro(CurrentNumberOfGaussians, vtkIdType);
  ///@}

  ///@{ Results of the last run.
  vtkGetMacro(NumberOfGaussians, vtkIdType);
  vtkGetMacro(TrainingSeconds, double);
  vtkGetMacro(CompletedIterations, int);
  vtkGetMacro(FinalLoss, double);
  /// With a Controller of several processes: seconds this process spent in the sums across processes
  /// (AllReduce, waiting for the slowest included) and the bytes it contributed to them; 0 alone.
  vtkGetMacro(ReductionSeconds, double);
  vtkGetMacro(ReductionBytes, double);
  vtkGetMacro(Gamma, double);
  const char* GetStopReason() const
  {
    return this->StopReason.c_str();
  }
  const char* GetGrowthStopReason() const
  {
    return this->GrowthStopReason.c_str();
  }
  /// The settings of the last run (chosen or given), one per line; set before its first step.
  const char* GetSettingsText() const
  {
    return this->SettingsText.c_str();
  }
  ///@}

  /// Invoked once per run when its settings are chosen, before the first step (see GetSettingsText).
  enum
  {
    SettingsChosenEvent = vtkCommand::UserEvent + 1
  };

protected:
  vtkGaussianFieldTrainer();
  ~vtkGaussianFieldTrainer() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  /// The field is point data: the sequence's whole extent, copied by default, is removed from it.
  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  /// Every frame of the sequence and the whole mask, whatever extent a consumer of the field asked for.
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  // The one copy of the trainer's settings (bigus::TrainerSettings): every setting's setter writes into it.
  std::unique_ptr<bigus::TrainerSettings> Settings;
  int HoldOutEvery = 0;
  int HoldOutOffset = 0;
  int HoldOutSweep = -1;
  vtkIdList* TrainingFrameList = nullptr;
  double EvaluationInterval = 0;
  char* ResumeFile = nullptr;
  char* Backend = nullptr;
  std::string BackendInUse;
  vtkMultiProcessController* Controller = nullptr;
  double ReductionSeconds = 0;
  double ReductionBytes = 0;

  int CurrentIteration = 0;
  double CurrentLoss = 0;
  vtkIdType CurrentNumberOfGaussians = 0;
  vtkIdType NumberOfGaussians = 0;
  double TrainingSeconds = 0;
  int CompletedIterations = 0;
  double FinalLoss = 0;
  double Gamma = 0;
  std::string StopReason;
  std::string GrowthStopReason;
  std::string SettingsText;

private:
  vtkGaussianFieldTrainer(const vtkGaussianFieldTrainer&) = delete;
  void operator=(const vtkGaussianFieldTrainer&) = delete;
};

#endif
