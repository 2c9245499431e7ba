/**
 * @file bigusTrainerSettings.h
 * @brief Every setting of a training run (TrainerSettings), one sub-struct per stage, and the `setting` lines of
 *        those that the settings alone fix (DescribeTrainerSettings). The one source of the defaults: the trainer,
 *        vtkGaussianFieldTrainer, `bigus train` and the ParaView plugin's XML (checked by Python.TestTrainerDefaults).
 *
 * Part of BIGUS::Training (public, not wrapped for Python).
 */
#ifndef bigusTrainerSettings_h
#define bigusTrainerSettings_h

#include "bigusTrainingModule.h" // For export macro
#include "bigusDensification.h"
#include "bigusGapFilling.h"
#include "bigusGaussianMerging.h"
#include "bigusHeldOutChoices.h"
#include "bigusImageLoss.h"
#include "bigusPoseRefinement.h"
#include "bigusReflectivitySolve.h"
#include "bigusSeeding.h"

#include <cstdint>
#include <string>
#include <vector>

namespace bigus
{

/// Steps of a run given neither Iterations nor a TimeBudget (a TimeBudget alone needs no step limit).
constexpr int DefaultIterations = 3000;

/**
 * Every setting of a run, one struct per stage where a stage has its own (Seeding, Solve, Densification, Poses,
 * GapFilling, Merge), the loop's and the schedule's here. The defaults are the project's (vtkGaussianFieldTrainer,
 * `bigus train` and the ParaView plugin take theirs from a default-constructed TrainerSettings); what each default
 * was measured against is in docs/FINDINGS.md, "The trainer's defaults, measured". A rule that chooses a setting
 * from the data lives in the stage that applies it, and the run's `setting` lines (TrainerReport::Settings) say
 * what it chose and why.
 */
struct TrainerSettings
{
  // Model
  /// mm; 0 = chosen from the training frames (bigus::ChooseElevationSigma, bigusElevationSigma.h)
  double ElevationSigma = 0;
  /// Beam integration (false: the thin plane, UltraGauss; the ablation).
  bool BeamIntegration = true;
  /// Signed reflectivity (true: clamped to >= 0; the ablation).
  bool NonNegativeReflectivity = false;
  /// Renderer cutoff k of a training step, standard deviations (Evaluate renders at the filters' 5): a smaller one
  /// makes a step faster and fits the footprints' tails less well. 0 (default): automatic, Trainer::StepCutoff:
  /// FastTrainingCutoff where Adam steps on trusted poses (before the pose refinement's start too), FineTrainingCutoff
  /// where a pose is refined, in both branches of the pose trial and where reflectivities are solved. The validation
  /// loss and the final prune take FixedTrainingCutoff (this, or FineTrainingCutoff where automatic), so that what
  /// they compare does not change with the step's.
  double Cutoff = 0;
  // The first field (bigusSeeding.h)
  SeedingSettings Seeding;
  // Variable projection (DESIGN section 4, "Solve what is linear"; bigusReflectivitySolve.h)
  /// On: the reflectivities are solved by least squares (bigus::SolveReflectivities over every training
  /// frame) after seeding, after every densification and every SolveInterval steps, and Adam moves every
  /// parameter between the solves. Off (default): one least-squares scale of the seeds' reflectivities
  /// (ScaleSeedReflectivities), then Adam alone. Ignored (off) with NonNegativeReflectivity, whose model is not
  /// linear in r. With a TimeBudget (and no Solve.TimeLimit given) each solve may take a quarter of the budget
  /// left when it starts, the pixel-grid fit's all of it (ReflectivitySolveSettings::TimeLimit).
  bool ReflectivitySolve = false;
  ReflectivitySolveSettings Solve;
  int SolveInterval = 0; ///< steps between solves besides those after densification; 0 = none
  // Optimisation
  /// Steps; 0 = no step limit when a TimeBudget is given (the budget is then the schedule), DefaultIterations
  /// when neither is. With both, whichever ends first, and the schedule follows the one further along.
  int Iterations = DefaultIterations;
  /// Seconds of training of the run, 0 = no limit: every Train call counts, and a run resumed from a
  /// checkpoint counts the seconds trained before it (TrainingState::TrainingSeconds). The end-of-run stages (final
  /// prune, gap filling, merge) follow the last step the budget allows (6 to 12 s after the liver's 300 s on 2 cores).
  double TimeBudget = 0;
  int FramesPerStep = 1; ///< training frames rendered per step (the batch); losses are averaged
  /// The resolution schedule: steps in the first CoarseFraction of the schedule see their frames on every second
  /// pixel and row, from a pixel drawn at random among the first 2 x 2 every step (DecimateFrames: a quarter of
  /// the pixels, point samples as the renderer's pixels are), later steps the whole frames; 0 = off. After
  /// DashGaussian's coarse-to-fine schedule (Chen et al. 2025); its low-pass images are CoarseLowPass. A coarse
  /// step's pose gradients are moved to the source frame's pivot (DecimatedPoseGradientToSource).
  double CoarseFraction = 0.5;
  /// The coarse steps' frames as 2 x 2 averages rendered through the pixel's low-pass (DecimateFrames with
  /// average, SliceGeometry::PixelLowPass: each footprint convolved with the 2 x 2 box's extra variance, as
  /// DashGaussian's and Mip-Splatting's low-pass filter does) instead of point samples. Off: a random phase makes the
  /// point samples an unbiased sample of the whole frame's loss, the averages a blurred one.
  bool CoarseLowPass = false;
  /// Adam over the Gaussians a step touched only (StepRequest::SparseAdam). Off: every Gaussian's moments decay and
  /// its parameters move every step (the ablation).
  bool SparseAdam = true;
  /// Adam's learning rates (per step; log-scale in log mm, reflectivity in intensity units). Twice the mean's or
  /// the log-scale's gained per step on the liver and lost or tied at the main job's 300 s (the larger Gaussians'
  /// slower steps): docs/FINDINGS.md, "Adam's learning rates, measured on held-out frames".
  double MeanLearningRate = 0.02;       ///< mm per step at the start ...
  double MeanLearningRateFinal = 0.002; ///< ... decaying exponentially to this at the end of the schedule
  double LogScaleLearningRate = 0.01;
  double QuaternionLearningRate = 0.005;
  double ReflectivityLearningRate = 0.01;
  /// The run's field is the average of its parameters (and pose corrections) over the schedule's tail: an
  /// exponential moving average with this time constant (a fraction of the schedule), sampled every AverageInterval
  /// steps from the densification window's close (once the validation frames joined the fit) and made the field when
  /// the schedule ends or Finish runs (bigusParameterAverage.h; docs/FINDINGS.md, "The parameter average"). 0: off,
  /// the last step's field.
  double ParameterAverage = 0.0625;
  /// L1 0.8 + D-SSIM 0.2 (3D Gaussian splatting's balance); the focal frequency loss off (its two DFTs cost about as
  /// much as the rest of the loss).
  ImageLossWeights Loss;
  double ConvergenceTolerance =
    0; ///< stop when the mean loss of the last 200 steps improved by less (relative); 0 = off
  // Densification (EA-D; bigusDensification.h)
  DensificationSettings Densification;
  /// Hard maximum, gap filling's copies included (GapFillingSettings): densification leaves them room in proportion
  /// to the field (CountGapCopies; DESIGN section 4.6). Room for a Gaussian per fan pixel of the volume protocol's
  /// two sweeps.
  std::int64_t MaximumGaussians = 500000;
  double FinalPruneTolerance = 1.0 / 512; ///< final prune: max change of any training pixel's I
  /// After the final prune, bridge gaps between training frames wider than the beam (FillElevationGaps).
  bool FillGaps = true;
  GapFillingSettings GapFilling;
  /// Last, merge neighbouring Gaussians that one Gaussian represents (bigus::MergeGaussians; Tolerance 0: off).
  GaussianMergeSettings Merge{ 1e-3 };
  // Pose refinement (bigusPoseRefinement.h)
  PoseRefinementSettings Poses;
  /// The choices measured on held-out frames (bigusHeldOutChoices.h): ElevationSigma on the pixel-grid route, and
  /// (HoldOutValidationFrames; Auto: where the training frames share no speckle) the Adam route's validation frames
  /// held out of the fit.
  HeldOutChoiceSettings HeldOut;
  // Run
  unsigned Seed = 1;
  int CheckpointInterval = 0; ///< steps between checkpoints (0 = none)
  std::string CheckpointFile;
};

/**
 * The `setting` lines (TrainerReport::Settings) that @p s alone fixes, in the report's order: the schedule
 * (Iterations, TimeBudget), densification, gap filling, merge, the reflectivity solve, the parameter average, and the
 * step's own (Seed, FramesPerStep, the loss's weights, Cutoff, SparseAdam, the resolution schedule). The lines of
 * choices made from the data (ElevationSigma, the poses, seeding, gamma) are written by the stages that make them.
 */
BIGUSTRAINING_EXPORT std::vector<std::string> DescribeTrainerSettings(const TrainerSettings& s);

/**
 * The settings a resumed run must share with the run that wrote its checkpoint (TrainingState::RunSettings), one
 * "name = value" line each, from the settings as requested (before the rules and measured choices): the rendering
 * model (ElevationSigma, BeamIntegration, NonNegativeReflectivity, Cutoff), the seeding, the loss, the optimiser's
 * form, MaximumGaussians, ReflectivitySolve, RefinePoses and Seed. Not the schedule's length (Iterations,
 * TimeBudget: a resume may train longer), nor FramesPerStep (a run on P processes takes P times each one's frames: a
 * checkpoint of one process resumes on two with half the frames each), nor checkpointing.
 */
BIGUSTRAINING_EXPORT std::string ResumeSettings(const TrainerSettings& s);

/**
 * The lines of @p written (ResumeSettings of a checkpoint) that @p current does not have, each as "NAME: VALUE in
 * the checkpoint, VALUE now"; empty when they agree.
 */
BIGUSTRAINING_EXPORT std::string ResumeSettingsDifference(const std::string& written, const std::string& current);

/// @p s as a run uses it: FramesPerStep at least 1, Iterations DefaultIterations when neither it nor a TimeBudget
/// is given.
BIGUSTRAINING_EXPORT TrainerSettings ScheduledSettings(TrainerSettings s);

/// The seeds' shape (bigusSeeding.h) of a run of @p s on frames of mean in-plane pixel spacing @p pixelSpacing (mm)
/// with intensity exponent @p gamma; @p frameSpacing (mm, 0 = unknown) is the training frames' median spacing, which
/// widens the seeds' elevation scale to SeedingSettings::ElevationSpacingFactor of it where that exceeds the beam.
BIGUSTRAINING_EXPORT SeedShape SeedShapeOf(
  const TrainerSettings& s, double pixelSpacing, double gamma, double frameSpacing = 0);

/**
 * The automatic training cut-offs (TrainerSettings::Cutoff 0), standard deviations. On the liver's main job 3.5
 * scored the same 8,000 steps within 0.03 dB of 4 in 0.81 times the time (+0.16 dB at 300 s), and within 0.08 dB on
 * the other sweeps of the main section; but refined poses lost 4 dB at 3.5 (a footprint's edge adds 2.2e-3 |r| at
 * once as a pose moves it across a pixel) and the 240-slice pixel-grid fit 0.8 dB (docs/FINDINGS.md, "The training
 * cut-off"); the automatic choice measured: "The automatic training cut-off".
 */
constexpr double FineTrainingCutoff = 4.0;
constexpr double FastTrainingCutoff = 3.5;

/// The cut-off of what must not change with a step's (the validation loss, the final prune, renders outside a run):
/// @p s's Cutoff, or FineTrainingCutoff where it is automatic (0).
inline double FixedTrainingCutoff(const TrainerSettings& s)
{
  return s.Cutoff > 0 ? s.Cutoff : FineTrainingCutoff;
}

/// The renderer's options of a run of @p s whose intensity map has exponent @p gamma (cutoff FixedTrainingCutoff).
BIGUSTRAINING_EXPORT RenderOptions RenderOptionsOf(const TrainerSettings& s, double gamma);

/**
 * The request of a step at @p fraction in [0, 1] of @p s's schedule: the mean learning rate MeanLearningRate decaying
 * exponentially to MeanLearningRateFinal along the schedule, the other rates constant, every rate times
 * @p rateScale (TrainingState::LearningRateScale, halved at each roll-back); log-scales bounded to [1e-3, 100] mm;
 * the loss and Adam's form. The caller sets the frames, the data and the pose gradients.
 */
BIGUSTRAINING_EXPORT StepRequest StepRequestAt(
  const TrainerSettings& s, double fraction, double rateScale, const RenderOptions& options);

/**
 * The resolution schedule's coarse step (TrainerSettings::CoarseFraction, CoarseLowPass): @p request, whose frames
 * are @p frames of @p data, moves onto @p decimated, those frames on every second pixel and row from a phase drawn
 * from @p rng (DecimateFrames), and the phase is returned (bit 0 the column offset, bit 1 the row's). Frames
 * narrower than 2 pixels, or 3 for averages (a whole 2 x 2 block at either phase), keep every pixel: -1, nothing
 * drawn, @p request unchanged. A coarse step's pose gradients go back to their source frames through
 * DecimatedPoseGradientToSource with the phase's offsets.
 */
BIGUSTRAINING_EXPORT int DecimateStep(const TrainingData& data, const std::vector<int>& frames, bool average,
  std::mt19937_64& rng, TrainingData& decimated, StepRequest& request);

} // namespace bigus

#endif
