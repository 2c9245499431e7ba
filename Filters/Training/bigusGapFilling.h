/**
 * @file bigusGapFilling.h
 * @brief What the field shows where no training frame is within reach of the beam: a gap in a sweep
 *        (frames dropped, the probe lifted, frames held out) bridged by the two frames on its sides.
 *
 * A trained field holds Gaussians only within a few elevation sigmas of its training frames: nothing
 * in the data asks for more. A plane in the middle of a gap wider than the beam therefore renders
 * almost nothing, less than the blend of the bracketing frames (issue 19). FillElevationGaps extrudes,
 * across each gap between two consecutive training frames whose planes lie further apart than a few typical
 * frame spacings, each of the two frames as the field renders it, and blends them linearly. Seen through the
 * beam, a Gaussian's profile across a frame is exp(-(z - z_i)^2 / (2 v)), z_i its mean's distance from the
 * plane (mm), v = sigma_E^2 + its variance along the normal (P2[z,z] of bigusGaussianMath.h). Every Gaussian within
 * ReachSigmas sqrt(v) of the frame's plane (not only those nearest to it: the Gaussians between frames
 * render in both) is taken onto the plane (z_i = 0) with reflectivity r exp(-z_i^2 / (2 v)), what it
 * renders there, and copied across the gap: copies 1.5 sqrt(v) apart, each with weight 1.5 / sqrt(2 pi),
 * sum to the profile's peak (a partition of unity by Gaussian bumps). A copy at fraction t of the way
 * keeps its position and orientation relative to its frame, in a frame interpolated between the two
 * poses (rotation by quaternion slerp, Eigen; centre linearly), and its weight is scaled by 1 - t
 * (first frame) or t (second), except near the frames: within BlendMarginSigmas sqrt(v) of its own
 * frame a copy carries that frame alone, and within that margin of the other frame it is left out,
 * the share falling linearly in between, so that the copies of one frame do not spill onto the other
 * (a linear blend leaves the copies nearest the far frame a share d / gap at distance d, which renders
 * onto that frame and makes it too bright).
 * Rendered in the gap, the field then shows the linear blend of the two
 * frames' scattering, which is what the temporal blend baseline and compounding with hole filling show
 * there. What the copies add at the frame they were taken from (relative to their Gaussian's own
 * contribution there, the sum of weight x exp(-z^2 / (2 v)) over the copies, whatever z_i) is taken off
 * that Gaussian's reflectivity, so that the frame renders as before to first order.
 * Why every Gaussian within reach and not only the nearest plane's, and why the blend margin: docs/FINDINGS.md,
 * "The trainer's defaults, measured" (FillGaps, and the paragraph bigusGapFilling.h below the table).
 */
#ifndef bigusGapFilling_h
#define bigusGapFilling_h

#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <cstdint>
#include <string>
#include <vector>

namespace bigus
{

struct GapFillingSettings
{
  /// A gap: two consecutive training frames (by index) whose image centres lie further apart along
  /// their normals than this many times the sweep's typical spacing (the median over consecutive pairs).
  double MinimumGapSpacings = 3.0;
  /// Gaps wider than this (mm) are left empty: a linear blend across them would be a guess (two sweeps,
  /// the probe moved elsewhere).
  double MaximumGapMm = 25.0;
  /// Copies nearer a bracketing plane than this many of their beam widths sqrt(v) are left out.
  double ClearanceSigmas = 0.0;
  /// The blend across a gap: within this many beam widths sqrt(v) of a bracketing frame (at most a quarter
  /// of the gap) the copies carry that frame alone, and in between its share falls linearly to 0, so that
  /// the copies of one frame do not spill onto the other (0: linear across the whole gap).
  double BlendMarginSigmas = 2.0;
  /// The Gaussians copied from a bracketing frame: those within this many of their beam widths sqrt(v)
  /// of its plane (their profile there is above exp(-ReachSigmas^2 / 2): 1 % at 3).
  double ReachSigmas = 3.0;
  /// The most Gaussians the filled field may hold (0: no limit). When a gap's copies would take the field
  /// past it, only the strongest Gaussians of its two frames (by |r| exp(-z_i^2 / 2v), what each renders
  /// at its peak there) whose copies fit are copied (GapFillingReport::Thinned, LeftOut); a gap is left
  /// empty (Skipped) only when the field already holds the maximum. Gaps are taken in sweep order.
  std::int64_t MaximumGaussians = 0;
};

struct GapFillingReport
{
  double TypicalSpacing = 0; ///< mm, median distance between consecutive training frames (of the first sweep
                             ///< that has two; each sweep's gaps are judged against its own median)
  int Gaps = 0;              ///< gaps bridged
  double WidestGap = 0;      ///< mm, the widest of them (0 when none)
  std::int64_t Added = 0;    ///< Gaussians added
  int Thinned = 0;           ///< gaps bridged by only the strongest Gaussians: all copies exceed MaximumGaussians
  std::int64_t LeftOut = 0;  ///< Gaussians of the thinned gaps' frames whose copies were left out
  int Skipped = 0;           ///< gaps left empty: no room at all under MaximumGaussians
};

/**
 * Adds the bridging copies to @p field (appended after its Gaussians; the existing ones are unchanged).
 * @param data            the training frames (TrainFrames, Poses, Width, Height).
 * @param elevationSigma  the beam sigma the field was trained with, mm (> 0; otherwise nothing is done).
 * @return what was done; no gap (or fewer than three training frames, or a Gaussian with a non-finite
 *         mean, which is skipped) adds nothing.
 */
BIGUSTRAINING_EXPORT GapFillingReport FillElevationGaps(GaussianField& field, const TrainingData& data,
  double elevationSigma, const GapFillingSettings& settings = GapFillingSettings());

/**
 * The Gaussians FillElevationGaps(@p field, @p data, @p elevationSigma, @p settings) would add with no maximum:
 * the room its gaps need (@p field is not changed), with @p trainFrames (indices into @p data) as the training
 * frames when not null (the frames the fill at the end will see: a run's validation frames held out of the fit
 * join it before the fill, and would otherwise make gaps that are not there). Densification keeps this room under
 * the trainer's MaximumGaussians, which counts gap filling's copies, so that a field grown to the maximum is not
 * bridged by only its strongest Gaussians.
 */
BIGUSTRAINING_EXPORT std::int64_t CountGapCopies(const GaussianField& field, const TrainingData& data,
  double elevationSigma, const GapFillingSettings& settings = GapFillingSettings(),
  const std::vector<int>* trainFrames = nullptr);

/// One line: "2 gaps bridged (widest 4.51 mm; typical spacing 0.645 mm), 31210 Gaussians added (...)", and
/// the gaps thinned or left empty by the maximum of Gaussians, if any.
BIGUSTRAINING_EXPORT std::string DescribeGapFilling(const GapFillingReport& report, const GapFillingSettings& settings);
/// The gap-filling stage's `setting` line: on (@p fill) with @p settings, or off and why (no beam without
/// @p beamIntegration).
BIGUSTRAINING_EXPORT std::string DescribeGapFillingSettings(
  bool fill, bool beamIntegration, const GapFillingSettings& settings);

} // namespace bigus

#endif
