/**
 * @file bigusGapFilling.h
 * @brief What the field shows where no training frame is within reach of the beam: a gap in a sweep
 *        (frames dropped, the probe lifted, frames held out) bridged by the two frames on its sides.
 *
 * A trained field holds Gaussians only within a few elevation sigmas of its training frames: nothing
 * in the data asks for more. A plane in the middle of a gap wider than the beam therefore renders
 * almost nothing (issue 19: 13.9 dB on a brain sweep with 8 frames out, against 20 dB for the blend
 * of the bracketing frames). FillElevationGaps adds, between two consecutive training frames whose
 * planes are further apart than a few typical frame spacings, copies of the Gaussians that belong to
 * each of the two frames (those whose nearest training plane it is), carried along the sweep: a copy
 * at fraction t of the way keeps its position relative to its frame, in a frame interpolated between
 * the two poses (rotation by quaternion slerp, Eigen; centre linearly), and its reflectivity is scaled
 * by 1 - t (first frame) or t (second). Rendered at a pose in the gap, the copies give the linear
 * blend of the two frames' scattering, which is what the temporal blend baseline and compounding with
 * hole filling show there. Copies are placed at the sweep's typical frame spacing and only where they
 * stay ClearanceSigmas beam widths (sqrt(sigma_E^2 + the copy's variance along the normal)) from both
 * bracketing planes, so no training frame's render changes by more than exp(-C^2 / 2) of a copy's
 * weight.
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
  /// Copies nearer a bracketing plane than this many beam widths are left out.
  double ClearanceSigmas = 3.0;
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
 * @param elevationSigma  the beam sigma the field was trained with, mm.
 * @return what was done; no gap (or fewer than three training frames) adds nothing.
 */
BIGUSTRAINING_EXPORT GapFillingReport FillElevationGaps(GaussianField& field, const TrainingData& data,
  double elevationSigma, const GapFillingSettings& settings = GapFillingSettings());

} // namespace bigus

#endif
