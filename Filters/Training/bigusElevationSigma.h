/**
 * @file bigusElevationSigma.h
 * @brief The elevation beam sigma and the pose refinement chosen from a sweep: how fast the recorded
 *        speckle decorrelates with the distance between frames along the elevation axis.
 *
 * Part of BIGUS::Training (public, not wrapped for Python).
 */
#ifndef bigusElevationSigma_h
#define bigusElevationSigma_h

#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <functional>
#include <string>
#include <vector>

namespace bigus
{

/**
 * The correlation of the recorded speckle between pairs of training frames as a function of the
 * elevation distance between them, and the elevation sigma it implies.
 *
 * A slice through a field of scatterers weighted across the beam by exp(-z^2 / (2 sigma^2)) correlates
 * with a parallel slice d mm away as exp(-d^2 / (4 sigma^2)) (the overlap integral of the two beam
 * profiles; the same relation underlies speckle-decorrelation tracking: Chen et al., Ultrasound Med.
 * Biol. 23(2), 1997; Prager et al., Ultrasound Med. Biol. 29(3), 2003). The measurement pairs every
 * training frame with the next MaximumPairGap training frames: each sampled fan pixel of the first is
 * placed in the reference frame (its ImageToReference), its distance d to the second frame's plane is
 * taken and the second frame is sampled (bilinear) where the pixel projects onto it; and the same the other way
 * (the second frame's sampled pixels against the first), so that a sweep read in the other order measures the same
 * (docs/FINDINGS.md, "The speckle measured both ways"). Intensities are
 * high-passed first (minus a masked Gaussian mean of HighPassMm), so anatomy that persists across
 * frames does not count as correlation. Pixel pairs are binned by d; per bin the normalised cross
 * correlation is computed. DecorrelationSigma is the sigma of the least-squares fit of
 * ln rho = ln rho0 - d^2 / (4 sigma^2) over the bins down to half the first bin's correlation (rho0
 * absorbs the noise that decorrelates even at d = 0).
 */
struct BIGUSTRAINING_EXPORT ElevationDecorrelation
{
  std::vector<double> Distance;    ///< bin centres, mm
  std::vector<double> Correlation; ///< normalised cross-correlation of the high-passed intensities per bin
  std::vector<long> Samples;       ///< pixel pairs per bin (each pair of frames sampled both ways)
  double DecorrelationSigma = 0;   ///< mm; 0 when too few pairs overlap
  /// rho0 of the fit: the correlation it extrapolates to d = 0 (0 where there is no fit). Read instead of the first
  /// bin, which in a sparse sweep holds only the pixels where two tilted frames cross (their speckle turned in
  /// plane against each other, so it correlates less than the bins after it) and few of them.
  double ZeroDistanceCorrelation = 0;
  /// mm, median over the sampled fan pixels of neighbouring training frames of the distance to the other's plane
  double NeighbourSpacing = 0;
};

/**
 * The fit of @p m's bins (Distance, Correlation, Samples; filled by MeasureElevationDecorrelation): the least squares
 * of ln rho = ln rho0 - d^2 / (4 sigma^2), each bin weighted by its pixel pairs, over the bins from the first down to
 * half its correlation. Sets DecorrelationSigma (0 where the fitted slope is not negative) and
 * ZeroDistanceCorrelation (rho0; 0 where nothing fits); both 0 for bins of unequal lengths or none.
 */
BIGUSTRAINING_EXPORT void FitElevationDecorrelation(ElevationDecorrelation& m);

/// Settings of the measurement (defaults are the ones ChooseElevationSigma uses).
struct ElevationDecorrelationSettings
{
  int MaximumPairGap = 6;      ///< a frame is paired with the next this many training frames
  double HighPassMm = 1.0;     ///< sigma of the Gaussian mean removed from each frame, mm
  long PixelsPerFrame = 20000; ///< fan pixels sampled per frame (evenly strided)
  double BinWidthMm = 0.1;
  double MaximumDistanceMm = 4.0;
  int Sweep = -1; ///< only the training frames of this sweep (TrainingData::Sweeps); -1: all
};

/**
 * Measure @p data's training frames (at least two; poses the renderer accepts). Returns false with
 * @p error when there are fewer than two training frames, the data's sizes are inconsistent, a
 * training pose is singular, or no pair of frames overlaps within MaximumDistanceMm.
 */
BIGUSTRAINING_EXPORT bool MeasureElevationDecorrelation(const TrainingData& data,
  const ElevationDecorrelationSettings& settings, ElevationDecorrelation& result, std::string* error);

/// One sweep's training frames measured alone (MeasureElevationDecorrelation with the default settings).
struct BIGUSTRAINING_EXPORT SweepDecorrelation
{
  bool Measured = false; ///< whether the measurement succeeded
  ElevationDecorrelation Measurement;
  std::string Error; ///< why not, where it did not
};

/**
 * Each sweep of @p data measured alone ([TrainingData::SweepCount()]; with one sweep, all training frames),
 * what ChooseElevationSigma and ChoosePoseRefinement read, so that a trainer choosing both measures once.
 */
BIGUSTRAINING_EXPORT std::vector<SweepDecorrelation> MeasureSweeps(const TrainingData& data);

/// The elevation sigma a trainer uses when none is given, and why.
struct BIGUSTRAINING_EXPORT ElevationSigmaChoice
{
  double Sigma = 0.5; ///< mm
  std::string Reason; ///< one line: the rule and the measured values it used
  ElevationDecorrelation Measurement;
};

/**
 * The elevation sigma for @p data's training frames (TrainerSettings::ElevationSigma 0).
 * - Where the speckle of neighbouring frames still correlates (the fit's ZeroDistanceCorrelation is at
 *   least 0.3 and at least three bins fall before the first bin's correlation halves):
 *   sigma = ElevationSigmaDecorrelationFactor
 *   (0.4) x DecorrelationSigma. The measured decorrelation is that of the beam and of the scatterers' own
 *   extent along the elevation axis together (sigma_measured^2 = sigma^2 + s^2); a Gaussian field supplies
 *   the second through its scales, so the beam takes a sixth of the variance and the Gaussians keep the
 *   freedom to be thinner where the data changes faster (a beam thinner than the data's trains better than
 *   the true one).
 * - Otherwise (the frames are farther apart than the speckle's correlation length):
 *   sigma = ElevationSigmaSpacingFactor (1) x NeighbourSpacing, so that a frame rendered midway between two
 *   training frames still meets the Gaussians fitted to both (beam weight exp(-1/8) = 0.88 there).
 * The factors and the measurements behind them: docs/FINDINGS.md, "The trainer's defaults, measured"
 * (ElevationSigma).
 * Several sweeps (TrainingData::Sweeps): each sweep is measured alone and the choice is that of the sweep
 * whose neighbouring frames lie closest (the median NeighbourSpacing), among those that can be measured:
 * a beam is one probe's, and a sweep whose frames lie farther apart than its speckle's correlation length
 * cannot see it. Pooled, the pairs of a sparse sweep sit in the far bins of the dense one's curve and
 * flatten it (docs/FINDINGS.md, "What depends on the frame spacing, measured within each sweep").
 * Falls back to 0.5 mm, saying so in Reason, when the frames cannot be measured (fewer than two
 * training frames, or none overlapping).
 */
BIGUSTRAINING_EXPORT ElevationSigmaChoice ChooseElevationSigma(const TrainingData& data);
/// The same from measurements already taken (MeasureSweeps).
BIGUSTRAINING_EXPORT ElevationSigmaChoice ChooseElevationSigma(const std::vector<SweepDecorrelation>& sweeps);

/**
 * A run's ElevationSigma (mm) and its `setting` line: @p given (> 0) as it is, "(given)"; otherwise
 * ChooseElevationSigma of @p sweeps() (measured only then), "(chosen: the rule's reason)", and @p byRule true.
 * @p spacing receives the measured sweep's NeighbourSpacing (mm) where the rule measured one, else 0.
 */
BIGUSTRAINING_EXPORT double ElevationSigmaSetting(double given,
  const std::function<const std::vector<SweepDecorrelation>&()>& sweeps, bool& byRule, std::string& line,
  double& spacing);

/// The factors of ChooseElevationSigma's two rules.
constexpr double ElevationSigmaDecorrelationFactor = 0.4;
constexpr double ElevationSigmaSpacingFactor = 1.0;

/**
 * The correlation of @p m's speckle at its NeighbourSpacing (mm): linear between the bins around it, the first
 * bin's below it, 0 past the last bin (no pair of pixels that far apart correlates enough to be binned).
 */
BIGUSTRAINING_EXPORT double CorrelationAtNeighbourSpacing(const ElevationDecorrelation& m);

/// The correlation at the neighbour spacing from which a sweep's poses are refined (ChoosePoseRefinement).
constexpr double PoseRefinementMinimumCorrelation = 0.3;

/// Which sweeps' training frames a trainer refines the poses of (TrainerSettings::PoseRefinement::Auto), and why.
struct BIGUSTRAINING_EXPORT PoseRefinementChoice
{
  std::vector<char> Sweeps;        ///< [sweeps] 1 where the sweep's training frames are refined
  std::vector<double> Correlation; ///< [sweeps] CorrelationAtNeighbourSpacing (may be below 0); -1 where not measured
  std::vector<double> Spacing;     ///< [sweeps] NeighbourSpacing, mm; 0 where not measured (what tells it)
  std::string Reason;              ///< one line: the rule and the measured values, sweep by sweep
  bool Any() const;                ///< whether any sweep is refined
};

/**
 * The pose refinement a trainer uses by default: a sweep's training frames are refined where the speckle of
 * neighbouring training frames still correlates across their spacing (CorrelationAtNeighbourSpacing at least
 * PoseRefinementMinimumCorrelation; each sweep measured alone, MeasureElevationDecorrelation). A frame's pose
 * is found by what its image shares with its neighbours' through the field; frames farther apart than the
 * speckle's correlation length share nothing, and their corrections fit the field's error instead of the
 * tracker's. Refinement pays on the sweeps whose frames correlate and costs on those whose frames do not:
 * docs/FINDINGS.md, "Pose refinement where the frames correlate" and "Held-out frames between refined ones".
 * A sweep that cannot be measured (fewer than two training frames, none overlapping) is not refined.
 */
BIGUSTRAINING_EXPORT PoseRefinementChoice ChoosePoseRefinement(const TrainingData& data);
/// The same from measurements already taken (MeasureSweeps).
BIGUSTRAINING_EXPORT PoseRefinementChoice ChoosePoseRefinement(const std::vector<SweepDecorrelation>& sweeps);

} // namespace bigus

#endif
