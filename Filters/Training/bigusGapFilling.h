/**
 * @file bigusGapFilling.h
 * @brief What the field shows where no training frame is within reach of the beam: a gap in a sweep
 *        (frames dropped, the probe lifted, frames held out) bridged by the two frames on its sides.
 *
 * A trained field holds Gaussians only within a few elevation sigmas of its training frames: nothing
 * in the data asks for more. A plane in the middle of a gap wider than the beam therefore renders
 * almost nothing (issue 19: 13.9 dB on a brain sweep with 8 frames out, against 20 dB for the blend
 * of the bracketing frames). FillElevationGaps extrudes, across each gap between two consecutive
 * training frames whose planes lie further apart than a few typical frame spacings, the Gaussians
 * that belong to each of the two frames (those whose nearest training plane it is) and blends them
 * linearly: a copy at fraction t of the way keeps its position and orientation relative to its frame,
 * in a frame interpolated between the two poses (rotation by quaternion slerp, Eigen; centre
 * linearly), and its reflectivity is scaled by 1 - t (first frame) or t (second). Seen through the
 * beam, a Gaussian's profile across its frame is exp(-z^2 / (2 v)) with v = sigma_E^2 + its variance
 * along the normal (P2[z,z] of bigusGaussianMath.h); its copies lie 1.5 sqrt(v) apart, each with
 * weight 1.5 / sqrt(2 pi), so that they sum to the profile's peak along the gap (a partition of unity
 * by Gaussian bumps). Rendered in the gap, the field then shows the linear blend of the two frames'
 * scattering, which is what the temporal blend baseline and compounding with hole filling show there.
 * Copies start ClearanceSigmas sqrt(v) away from both bracketing planes, and what they add at their
 * Gaussian's own plane (sum of weight x exp(-z^2 / (2 v)) over its copies) is taken off that
 * Gaussian's reflectivity, so that its frame renders as before to first order.
 * Measured (docs/FINDINGS.md; liver, 3,600 steps, frames 66 to 73 held out, a 3.8 mm gap): the frames in
 * the gap 28.62 dB without, 30.50 with clearance 1.5, 30.71 with 1.0; the two bracketing training
 * frames lost 0.27 and 0.20 dB at 1.5 (0.53 and 0.50 at 1.0). Frames 60 to 79 held out (8.3 mm): 21.46
 * against 24.84 dB at 1.5.
 */
#ifndef bigusGapFilling_h
#define bigusGapFilling_h

#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <cstdint>
#include <string>

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
  double ClearanceSigmas = 1.5;
};

struct GapFillingReport
{
  double TypicalSpacing = 0; ///< mm, median distance between consecutive training frames
  int Gaps = 0;              ///< gaps bridged
  double WidestGap = 0;      ///< mm, the widest of them (0 when none)
  std::int64_t Added = 0;    ///< Gaussians added
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

/// One line: "2 gaps bridged (widest 4.51 mm; typical spacing 0.645 mm), 31210 Gaussians added (...)".
BIGUSTRAINING_EXPORT std::string DescribeGapFilling(const GapFillingReport& report, const GapFillingSettings& settings);

} // namespace bigus

#endif
