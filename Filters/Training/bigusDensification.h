/**
 * @file bigusDensification.h
 * @brief Error-attributed densification (EA-D) and pruning of a field while it trains, and the final
 *        prune at the end of a run (DESIGN section 4.5): free functions on the training state, which the
 *        trainer (bigus::Trainer) calls on its schedule.
 */
#ifndef bigusDensification_h
#define bigusDensification_h

#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <cstdint>

namespace bigus
{

/**
 * EA-D densification of Gaussian @p i (DESIGN section 4): appends one child and returns its index.
 * Split when its largest scale s exceeds @p splitScale (mm), cloned otherwise. The pair sits at +-s/2
 * (split) or +-s/10 (clone) along the major axis,
 * with r / 2 each. A clone keeps the scales, so the pair renders as the parent did and the offset only
 * keeps the copies from getting identical gradients. A split divides every scale by 1.6, as 3D
 * Gaussian splatting does (Kerbl et al. 2023): smaller children resolve finer detail and render
 * faster; the render loses part of the parent's integral, which the next steps restore. (A
 * moment-matched split, r / sqrt(3) each and only the major scale times sqrt(3/4), keeps the render
 * but gave 37.3 against 37.6 dB held-out PSNR after 10 minutes on the liver sweep, one run each: its
 * larger children made steps 10 % slower.)
 */
BIGUSTRAINING_EXPORT std::int64_t DensifyGaussian(GaussianField& field, std::int64_t i, double splitScale);

/// What one densification did.
struct DensificationResult
{
  std::int64_t Added = 0;      ///< Gaussians split or cloned (one child each)
  std::int64_t Pruned = 0;     ///< Gaussians removed
  bool MaximumReached = false; ///< the percentile did not fit under the maximum: growth should stop
};

/**
 * One EA-D step on @p G: when @p grow, the top @p percentile % of the Gaussians by attribution score
 * (G.Attribution; a score of 0 is never densified), at most up to @p maximumGaussians, are densified
 * (DensifyGaussian with @p splitScale, mm) and they and their children start with zero Adam moments; then
 * the Gaussians with |r| < @p pruneReflectivity or never seen since the last densification (G.SeenCount
 * 0), other than those just densified, are removed (never all of them). The attribution scores and seen
 * counts restart at 0.
 */
BIGUSTRAINING_EXPORT DensificationResult DensifyAndPrune(OptimizerState& G, bool grow, double percentile,
  std::int64_t maximumGaussians, double splitScale, double pruneReflectivity);

/**
 * The final prune: removes from @p G every Gaussian whose removal changes no pixel of a training frame
 * of @p data by more than @p tolerance in intensity: it changes S by at most |r| amp (its footprint's
 * peak, bigusGaussianMath.h SetupFootprint with @p options' beam and cutoff) and I by at most gamma |r|
 * amp (dI/dS <= @p gamma). Returns how many were removed.
 */
BIGUSTRAINING_EXPORT std::int64_t FinalPrune(OptimizerState& G, const TrainingData& data,
  const RenderOptions& options, double gamma, double tolerance);

} // namespace bigus

#endif
