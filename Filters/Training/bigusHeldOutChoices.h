/**
 * @file bigusHeldOutChoices.h
 * @brief The held-out choices of training (DESIGN section 4, "Choices measured on held-out frames"): a setting the
 *        user left to the trainer is decided by fitting each candidate on the training frames less a few held out
 *        along each sweep, and scoring the candidates' fits on the frames they did not see; the final fit then uses
 *        every training frame with the candidate chosen.
 *
 * Measured this way on the pixel-grid route (bigusSeeding.h, PlanSeeding), where a candidate's whole fit is one
 * reflectivity solve (a second or two with the assembled basis, AssembledBasis): ElevationSigma (the rule of
 * bigusElevationSigma.h gives the centre of the candidates), the solve's ridge, and whether the final prune and the
 * merge are kept. Where a candidate's fit would be a whole Adam run (the Harris route), the rules' values are taken
 * untested and the setting lines say so.
 *
 * Part of BIGUS::Training (public, not wrapped for Python).
 */
#ifndef bigusHeldOutChoices_h
#define bigusHeldOutChoices_h

#include "bigusSeeding.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <string>
#include <vector>

namespace bigus
{

struct TrainerSettings;

/// Whether a run's validation frames are held out of the fit (HeldOutChoiceSettings::HoldOutValidationFrames).
enum class ValidationHoldOut : int
{
  Off = 0, ///< training frames decide (ValidationFrames)
  On = 1,  ///< held out until the densification window closes (ChooseValidationFrames)
  Auto = 2 ///< held out where no sweep's neighbouring training frames share speckle (HoldOutValidationByRule)
};

/// The held-out choices' settings (TrainerSettings::HeldOut).
struct HeldOutChoiceSettings
{
  /// Measure the choices that can be measured (false: the rules decide, untested).
  bool Enabled = true;
  /// Every Stride-th training frame of a sweep is left out of the candidates' fits (HeldOutFrames). With 2 the fits
  /// see every second frame and the held-out frames lie half the fits' spacing from them, as the final field's
  /// in-between views lie from its frames; with 8 a held-out frame lies a whole spacing from the nearest fitted one
  /// and the score favours the widest beam (docs/FINDINGS.md, "ElevationSigma measured on held-out frames").
  int Stride = 2;
  int MaximumFrames = 12; ///< of the held-out frames, at most this many spread over them are rendered and scored
  /// dB: of the candidates within this of the best held-out score, the simplest is taken (for ElevationSigma the
  /// narrowest beam: the held-out frames lie twice as far from the fitted ones as the final field's views from its
  /// frames, which favours a wider one).
  double Tolerance = 0.05;
  /// ElevationSigma's candidates: the rule's value times these (small ones included: a volume has no beam).
  std::vector<double> ElevationSigmaFactors = { 0.125, 0.25, 0.5, 1.0, 2.0 };
  /// The chosen candidate times this is the ElevationSigma of the fit on every frame: a held-out frame lies a whole
  /// spacing from the candidates' fits (every second frame out), the final field's in-between views half a spacing
  /// from its frames, and a beam that bridges the wider gap blurs every view across its elevation. 1/sqrt(2) scored
  /// higher than 1 on in-between, oblique and orthogonal slices of three volume sweeps (and 1/2 did not, on two of
  /// them): docs/FINDINGS.md, "ElevationSigma taken narrower than the held-out choice".
  double ElevationSigmaScale = 0.70710678118654752;
  /// The reflectivity solve's ridge candidates: ReflectivitySolveSettings::Ridge times these (the first, the
  /// default's own, is kept unless another scores more than Tolerance higher).
  std::vector<double> RidgeFactors = { 1.0, 10.0, 100.0 };
  /// Measure the final prune and the merge on held-out frames (HeldOutReduction) and keep each only where it costs
  /// at most Tolerance.
  bool MeasureReduction = true;
  /// Measure the route's rule (SeedingSettings::PixelGridFanPixelsPerGaussian) on held-out frames when the budget
  /// affords it (RouteTrial): where it gives Harris seeds and Adam, the pixel grid against it; where it gives the
  /// grid, Harris seeds and Adam against the grid for RouteProbeFraction of the schedule.
  bool MeasureRoute = true;
  /// Where the rule takes the pixel grid, Harris seeds and Adam are taken only if they score above it on the
  /// held-out frames within this share of the schedule from Adam's start (after the grid's side; the decision is
  /// taken at the first validation from then on, after any pose-refinement trial). Where Adam passed the grid on
  /// real sweeps it did so within 4 to 9 % of the budget from its start (the N-wire and spine-phantom sweeps at 120
  /// and 300 s: docs/FINDINGS.md, "The route measured where the rule takes the grid"); a run whose grid wins spends
  /// this share of its budget on Adam's steps.
  double RouteProbeFraction = 0.25;
  /// s per Gaussian of one pixel-grid fit (assembly, solve, scoring), to plan the route trial: 2.5e-6 to 3.5e-6
  /// measured on 2 cores (volume protocol, 160 to 240 slices). A grid whose Gaussians reach more frames (a real
  /// sweep's wider beam) takes longer: the trial's fits stop at MaximumSeconds, which it sets to half the budget.
  double GridFitSecondsPerGaussian = 3.5e-6;
  /// s: the choices fit no further candidate once the time they took, plus the fits still planned each taken as
  /// long as the last, would pass this (0: no limit); nothing measured is then taken, every choice is untested and
  /// says why. The route trial sets half the budget.
  double MaximumSeconds = 0;
  /**
   * The Adam route's validation frames held out of the fit (On), or training frames (Off; ValidationFrames); a
   * switch of its own, whatever Enabled says. Auto (the default): held out where no sweep's neighbouring training
   * frames share speckle (HoldOutValidationByRule), training frames elsewhere. Where the training frames' speckle
   * correlates (the liver, 0.68 at its spacing) the frames out of the fit cost more than the honest decisions gave
   * (docs/FINDINGS.md, "Validation frames held out of the fit"); where it does not (the spine phantom, 0.05), the
   * training frames cannot tell the field's fit of the scene from its fit of each frame's speckle, and held out they
   * scored 21.14 dB against 20.56 at 3,000 steps (docs/FINDINGS.md, "The spine phantom's held-out PSNR through a
   * schedule").
   */
  ValidationHoldOut HoldOutValidationFrames = ValidationHoldOut::Auto;
  /// The held-out validation frames, on which growth stops and early stopping keeps its field: every
  /// ValidationStride-th training frame of a sweep, at most MaximumValidationFrames spread over them (HeldOutFrames),
  /// held out of the fit until the densification window closes, when they join it (Trainer). Where that gives fewer
  /// than MinimumValidationFrames, every SparseValidationStride-th (a short sweep: the spine phantom's 16 training
  /// frames give 4); still fewer, the run validates on training frames (ValidationFrames): on the N-wire sweep's 2
  /// the decisions followed the noise of two frames (docs/FINDINGS.md, "Validation frames held out of the fit").
  int ValidationStride = 8;
  int SparseValidationStride = 4;
  int MaximumValidationFrames = 8;
  int MinimumValidationFrames = 4;
  /**
   * The measured tail. Where the validation frames were held out of the fit (HoldOutValidationFrames On, or Auto
   * resolved On) and, when they joined it, early stopping went back to an earlier field (the steps after it overfitted
   * the training frames for the views between them), the run goes on after the join for as many steps as the fit took
   * to that field (TrainingState::BestFieldIteration), then stops ("measured tail"; TrainingState::MeasuredTailEnd),
   * its field the last step's (the parameter average, whose samples include the tail's first steps, before the joined
   * frames fit, is dropped; where the schedule ends first, it ends the run as before). The spine
   * phantom (5 test frames, tracked poses): 21.32 dB at 3,000 steps (the tail from 2,000 to 2,600) against 21.14
   * going on to the schedule's end, 21.24 at 8,000 (5,000 to 5,600) against 20.73 (docs/FINDINGS.md, "The measured
   * tail"). false: the fit goes on to the schedule's end.
   */
  bool MeasuredTail = true;
};

/**
 * The frames held out for the choices: in each sweep, its training frames in order, every @p stride-th from the
 * (@p stride / 2)-th, never the sweep's first or last training frame (a held-out frame lies between frames the fit
 * sees); with @p maximum > 0, at most that many of them, spread evenly (the first and last kept). Empty when no
 * sweep has three training frames.
 */
BIGUSTRAINING_EXPORT std::vector<int> HeldOutFrames(const TrainingData& data, int stride, int maximum);

/// @p data with @p heldOut taken out of its TrainFrames: what a candidate is fitted on.
BIGUSTRAINING_EXPORT TrainingData WithoutHeldOutFrames(const TrainingData& data, const std::vector<int>& heldOut);

/// One candidate of a measured choice.
struct HeldOutCandidate
{
  double Value = 0;       ///< the setting's value (mm for ElevationSigma)
  double PSNR = 0;        ///< dB, the mean over the held-out frames of its fit's masked PSNR
  double Seconds = 0;     ///< its fit and scoring
  std::int64_t Count = 0; ///< Gaussians of its fit
};

/// What a measured choice did.
struct HeldOutChoice
{
  std::vector<int> Frames;                  ///< the held-out frames scored
  int Stride = 0;                           ///< every Stride-th training frame was left out of the fits
  std::vector<HeldOutCandidate> Candidates; ///< in the order tried
  int Chosen = -1;                          ///< index into Candidates; -1: untested
  std::string Untested;                     ///< why no candidate was measured (Chosen -1)
  double Scale = 1;                         ///< the value taken is the chosen candidate's times this (Taken)
  std::string ScaleReason;                  ///< why, where Scale is not 1
  /// The value the run takes: the chosen candidate's times Scale (Chosen >= 0).
  double Taken() const { return this->Candidates[this->Chosen].Value * this->Scale; }
  /// The setting line's parenthesis: "chosen on 9 held-out frames: 0.12 mm 40.6 dB, 0.25 mm 41.0, ... (s)".
  std::string Describe(const char* unit) const;
  /**
   * Rewrites the setting line of @p name in @p lines, the rule's ("NAME = V UNIT (the rule's reason)"): untested,
   * the rule's line with why appended; measured, the value taken (Taken), the candidates, then the rule's value and
   * reason.
   */
  void RewriteSettingLine(std::vector<std::string>& lines, const char* name, const char* unit) const;
};

/**
 * The pixel-grid fit of @p settings (ElevationSigma given, > 0) on @p data's training frames other than
 * @p heldOut, into @p field: a Trainer's Initialize on WithoutHeldOutFrames (no pose refinement, no held-out choice
 * of its own; CPU engine). It reads no pixel of a held-out frame. False with @p error as Trainer::Initialize.
 */
BIGUSTRAINING_EXPORT bool FitWithoutHeldOutFrames(const TrainingData& data, const std::vector<int>& heldOut,
  const TrainerSettings& settings, GaussianField& field, std::string* error);

/// The end-of-run reduction measured on held-out frames: the final prune, then the merge, applied to the chosen
/// candidate's fit as Trainer::Finish applies them, each kept only where it costs at most the tolerance there.
struct HeldOutReduction
{
  std::string Untested;       ///< why it was not measured (empty: measured)
  std::int64_t Whole = 0;     ///< Gaussians of the chosen candidate's fit
  std::int64_t Pruned = 0;    ///< after the final prune (FinalPruneTolerance)
  std::int64_t Merged = 0;    ///< after the merge too (Merge), on what the prune left where it is kept
  double WholePSNR = 0;       ///< dB, mean masked PSNR of the held-out frames
  double PrunedPSNR = 0;      ///< dB
  double MergedPSNR = 0;      ///< dB
  bool KeepPrune = true;      ///< the prune cost at most HeldOutChoiceSettings::Tolerance
  bool KeepMerge = true;      ///< the merge cost at most that on top of what was kept
  bool MergeMeasured = false; ///< the merge is on (Merge.Tolerance > 0) and was measured
  bool PruneMeasured = false; ///< the prune is on (FinalPruneTolerance > 0) and was measured
  double Seconds = 0;         ///< the prune, the merge and their scoring
  int Frames = 0;             ///< held-out frames scored
  /**
   * Appends the measurement to the `FinalPrune = ` and `Merge = ` lines of @p lines (each turned to "off" where
   * it was not kept), or why it is untested.
   */
  void RewriteSettingLines(std::vector<std::string>& lines) const;
};

/// The choices measured on held-out frames before the final fit (ChooseOnHeldOutFrames).
struct HeldOutChoices
{
  HeldOutChoice ElevationSigma; ///< mm; Chosen -1: untested (or given: no candidates)
  HeldOutChoice Ridge;          ///< ReflectivitySolveSettings::Ridge, a share of the mean basis norm
  HeldOutReduction Reduction;   ///< the final prune and the merge
};

/**
 * The route measured: where the rule gives Harris seeds and Adam but the pixel grid of every fan pixel fits this
 * machine's memory and its fits half the time budget, the grid (with its own held-out choices, ChooseOnHeldOutFrames)
 * is fitted on every training frame but Frames and scored on them; the Adam run then holds Frames out as its
 * validation frames, and when they would join its fit (the densification window's close) it is scored on them too:
 * the higher score takes the rest of the run (Trainer). Where the rule gives the grid, the same under the same
 * conditions, except that Adam must score above the grid by DecideBy of the schedule (RouteProbeFraction from its
 * start). The Route setting line says what each scored, or why the rule's route was taken untested.
 */
struct RouteTrial
{
  bool Pending = false;           ///< measured on the grid's side; the Adam run decides when its frames join
  HeldOutChoices Grid;            ///< the grid's own choices, on its own held-out frames (a superset of Frames)
  std::vector<int> Frames;        ///< scored for both routes, held out of both fits
  double GridPSNR = 0;            ///< dB, the grid with its choices fitted on every training frame but Frames
  std::int64_t GridGaussians = 0; ///< of that fit
  double GridSeconds = 0;         ///< the grid's side: its choices and that fit
  double AdamPSNR = 0;            ///< dB, the Adam run's field at the decision
  int DecidedAt = -1;             ///< the Adam run's iteration at the decision; -1 before
  bool GridChosen = false;
  std::int64_t FanPixels = 0;       ///< of the grid's planes
  double RulePixelsPerGaussian = 2; ///< SeedingSettings::PixelGridFanPixelsPerGaussian, for the line
  std::string Untested;             ///< why the rule's route was taken without the measurement
  bool GridByRule = false;          ///< the rule took the pixel grid (FanPixels within the rule)
  /// The rule took the grid and the run started as Harris seeds and Adam to measure it against the grid (the trial
  /// planned; it stays set where the trial ends untested, as the run is then Adam's)
  bool AdamProbe = false;
  /// AdamProbe: the schedule fraction by which Adam must score above the grid (the fraction at Adam's start plus
  /// RouteProbeFraction); otherwise unused, the densification window's close decides
  double DecideBy = 1;
  /// The "Route = ..." setting line.
  std::string Line() const;
};

/**
 * Why the route trial cannot run for @p settings with the seeding @p plan (either route) on @p data, alone or
 * @p dataParallel; empty where it can: the held-out choices and MeasureRoute on, the grid allowed
 * (SeedingPlan::Planes measured), a time budget, one process, every fan pixel of the planes within this machine's
 * memory (CheckTrainingMemory), and about 6.5 grid fits (GridFitSecondsPerGaussian) within half the budget.
 */
BIGUSTRAINING_EXPORT std::string RouteTrialUntested(
  const TrainingData& data, const TrainerSettings& settings, const SeedingPlan& plan, bool dataParallel);

/**
 * The grid's side of the route trial (RouteTrial): the grid's choices (ChooseOnHeldOutFrames with the grid forced),
 * then the grid with them fitted on every training frame but the frames they scored, and scored on those (at the
 * ElevationSigma candidate chosen, not scaled: those frames lie a whole spacing from the fitted ones). False
 * with @p error when a fit fails.
 */
BIGUSTRAINING_EXPORT bool MeasurePixelGridRoute(
  const TrainingData& data, const TrainerSettings& settings, bool sigmaByRule, RouteTrial& trial, std::string* error);

/**
 * @p choices taken into @p settings: the chosen ElevationSigma (where @p sigmaByRule and measured), ridge, and the
 * final prune and merge tolerances (0 where dropped); the setting lines of @p lines rewritten (a `Ridge = ` line
 * added where @p pixelGrid). Returns whether ElevationSigma changed.
 */
BIGUSTRAINING_EXPORT bool ApplyHeldOutChoices(const HeldOutChoices& choices, bool sigmaByRule, bool pixelGrid,
  TrainerSettings& settings, std::vector<std::string>& lines);

/**
 * The choices a pixel-grid run (@p pixelGrid) makes on held-out frames (HeldOutFrames(settings.HeldOut.Stride)):
 * each candidate is fitted by a Trainer's Initialize on the other training frames (FitWithoutHeldOutFrames) and
 * scored by the mean masked PSNR of up to MaximumFrames held-out frames; of the candidates within
 * HeldOut.Tolerance dB of the best, the first in its list is taken. In turn:
 * - ElevationSigma, where the rule gave it (@p sigmaByRule): settings.ElevationSigma times
 *   HeldOut.ElevationSigmaFactors (ascending: the narrowest beam within the tolerance);
 * - the solve's ridge: Solve.Ridge times HeldOut.RidgeFactors (the rule's first), at the sigma chosen;
 * - the reduction (HeldOutReduction): the final prune and then the merge of the chosen fit, each kept where it
 *   costs at most HeldOut.Tolerance.
 * Where the held-out choices are off, the route is Harris seeds and Adam (a candidate's fit would be a whole Adam
 * run) or fewer than 2 frames can be held out, nothing is measured and each Untested says why. False with
 * @p error when a candidate's fit fails.
 */
BIGUSTRAINING_EXPORT bool ChooseOnHeldOutFrames(const TrainingData& data, const TrainerSettings& settings,
  bool pixelGrid, bool sigmaByRule, HeldOutChoices& choices, std::string* error);

} // namespace bigus

#endif
