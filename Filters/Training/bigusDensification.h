/**
 * @file bigusDensification.h
 * @brief Error-attributed densification (EA-D) and pruning of a field while it trains, and the final
 *        prune at the end of a run (DESIGN section 4.5): free functions on the training state, which the
 *        trainer (bigus::Trainer) calls on its schedule.
 */
#ifndef bigusDensification_h
#define bigusDensification_h

#include "bigusSeeding.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <cstdint>
#include <string>

namespace bigus
{

/// Where DensificationSettings::End is -1, densification stops at this share of the schedule.
constexpr double DensifyEndFraction = 0.6;

/**
 * The densification stage's settings (TrainerSettings::Densification): EA-D every Interval steps from step Start
 * to End, growth stopped by the validation loss (UpdateGrowth). Why each default: docs/FINDINGS.md, "The
 * trainer's defaults, measured" and the sections it points to.
 */
struct DensificationSettings
{
  bool Enabled = true;     ///< EA-D on (off: the seeds are the field, the ablation)
  int Start = 200;         ///< first step that densifies
  int End = -1;            ///< last step that densifies; -1: DensifyEndFraction of the schedule
  int Interval = 200;      ///< steps between densifications (and validations)
  double Percentile = 5.0; ///< top share (%) of the attribution score densified each time
  /// New Gaussians where the residual is largest at each densification, as a share of those split or cloned
  /// (0 = off): seeds on ResidualSeedFrames training frames drawn at random, in proportion to |residual|, each
  /// taking the residual as its reflectivity (bigus::SeedResidual; Image-GS, Zhang et al. 2025).
  double ResidualSeedShare = 0;
  int ResidualSeedFrames = 4;
  double SplitScalePixels = 3.0;   ///< pixels: largest scale above which a Gaussian is split, not cloned
  double PruneReflectivity = 1e-3; ///< |r| below this is pruned (after the first densification)
  double GrowthMargin = 0.005;     ///< growth stops when the validation loss improves by less (relative) ...
  int GrowthPatience = 4;          ///< ... than the best so far over this many densification intervals in a row
};

/// The stage's `setting` line ("Densification = every 200 steps from step 200 to ...").
BIGUSTRAINING_EXPORT std::string DescribeDensification(
  const DensificationSettings& settings, std::int64_t maximumGaussians);

/**
 * Growth control, at a densification with validation loss @p validation: while @p state is Growing, a loss below
 * the best so far by more than GrowthMargin (relative) becomes the best, and GrowthPatience intervals in a row
 * without one stop growth (state.Growing false). Returns why growth stopped at this call, or "" (it goes on, or had
 * stopped before).
 */
BIGUSTRAINING_EXPORT std::string UpdateGrowth(
  TrainingState& state, double validation, const DensificationSettings& settings);

/**
 * EA-D densification of Gaussian @p i (DESIGN section 4): appends one child and returns its index.
 * Split when its largest scale s exceeds @p splitScale (mm), cloned otherwise. The pair sits at +-s/2
 * (split) or +-s/10 (clone) along the major axis,
 * with r / 2 each. A clone keeps the scales, so the pair renders as the parent did and the offset only
 * keeps the copies from getting identical gradients. A split divides every scale by 1.6, as 3D
 * Gaussian splatting does (Kerbl et al. 2023): smaller children resolve finer detail and render
 * faster; the render loses part of the parent's integral, which the next steps restore (a moment-matched
 * split keeps the render, but its larger children made steps slower: docs/FINDINGS.md, "The trainer's defaults,
 * measured").
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
 * The stage at a densification step, on @p state's host field: growth control (UpdateGrowth with @p validation);
 * Image-GS's residuals rendered by @p engine before the field changes (ResidualSeedShare, RenderResiduals); EA-D
 * (DensifyAndPrune, splitting above SplitScalePixels x @p shape's pixel spacing); the residual seeds in the room
 * left under @p maximumGaussians (SeedResiduals with @p shape); growth stopped when the maximum is reached.
 * @p growthStopReason receives why growth stopped at this call, and is left as it is otherwise; @p result (when not
 * null) what DensifyAndPrune split, cloned and pruned. Returns false with @p error when a residual cannot be rendered.
 */
BIGUSTRAINING_EXPORT bool DensifyField(TrainingEngine& engine, const TrainingData& data, const RenderOptions& options,
  double gamma, const SeedShape& shape, const DensificationSettings& settings, std::int64_t maximumGaussians,
  double validation, TrainingState& state, std::string& growthStopReason, std::string* error,
  DensificationResult* result = nullptr);

/**
 * The final prune: removes from @p G a set of Gaussians whose removal together changes no pixel inside the mask of a
 * training frame of @p data by more than @p tolerance in intensity. Removing Gaussian i changes S by r_i w_i (its
 * footprint's weight at the pixel, at most its peak amp: bigusGaussianMath.h SetupFootprint with @p options' beam and
 * cutoff) and I by at most gamma |r_i| w_i (dI/dS <= @p gamma); the candidates are the Gaussians whose own bound stays
 * within the tolerance on every training frame, and of those, every one that touches a training pixel where the
 * candidates' summed bound exceeds it is kept. Returns how many were removed.
 */
BIGUSTRAINING_EXPORT std::int64_t FinalPrune(
  OptimizerState& G, const TrainingData& data, const RenderOptions& options, double gamma, double tolerance);

} // namespace bigus

#endif
