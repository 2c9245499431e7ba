/**
 * @file bigusSeeding.h
 * @brief The first field of a run (DESIGN section 4): seeds drawn from the training frames' Harris
 *        response, uniform seeds (the ablation), or the dense start on the frames' pixel grid.
 *
 * Every seed is a Gaussian lying in a training frame (its axes the frame's u, v, n), placed at a
 * pixel, with in-plane scale SeedShape::InPlaneScale and the reflectivity that renders that pixel's
 * intensity alone, S = -ln(1 - I) / gamma (ScatteringOfIntensity); the trainer then scales or solves
 * the reflectivities of the whole field (bigus::Trainer::Initialize).
 */
#ifndef bigusSeeding_h
#define bigusSeeding_h

#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace bigus
{

/**
 * The seeding stage's settings (TrainerSettings::Seeding): which first field a run starts from. Why each default:
 * docs/FINDINGS.md, "The trainer's defaults, measured".
 */
struct SeedingSettings
{
  /// Harris seeds (false: uniform random in the sweep's bounding box, the ablation).
  bool HarrisInitialisation = true;
  /// Seeds; 0 = chosen (PlanSeeding): one per 200 masked pixels of the training frames, at least 20,000 and at most
  /// half of MaximumGaussians.
  std::int64_t InitialGaussians = 0;
  /// A dense start instead of Harris seeds: Gaussians on the pixel grid of the training frames (every frame at least
  /// sigma_E from the previous one kept) at the real-valued stride that gives at most InitialGaussians, short of it
  /// by less than a row and a column of the grid (0 = half of MaximumGaussians), in-plane scale 0.6 strides,
  /// elevation scale 0.45 of each plane's own spacing (SeedGrid).
  bool DenseInitialisation = false;
  /// The fit when the data are few: when the dense start's planes (SelectGridPlanes) hold at most
  /// PixelGridFanPixelsPerGaussian x MaximumGaussians fan pixels, the field is a pixel grid (SeedGrid: every fan
  /// pixel where this machine's memory holds them, TrainingBytesPerGaussian each and the solve's
  /// ReflectivitySolveBytes; else MaximumGaussians of them at a stride of up to 1.41) with its reflectivities
  /// solved, and no geometry step follows, whatever Iterations and TimeBudget: 11 parameters per Gaussian would
  /// outnumber the pixels, and Adam overfits them. With a time budget the rule is measured (the route trial,
  /// bigusHeldOutChoices.h): the run starts as Harris seeds and Adam, which take it only if they score above the grid
  /// on held-out frames. Applies with the default start only (Harris seeding, InitialGaussians 0, no
  /// DenseInitialisation, signed reflectivities).
  bool PixelGridFit = true;
  /// The pixel-grid fit applies while the dense start's planes hold at most this many fan pixels per Gaussian of
  /// MaximumGaussians (the route's rule): every fan pixel where memory holds them (the count is set by memory),
  /// otherwise a grid of MaximumGaussians points (a stride of up to sqrt(2) pixels; the grid loses to Adam from a
  /// stride of about 1.45: docs/FINDINGS.md, "Several sweeps into one field"). Above it the route is Harris seeds and
  /// Adam unless the held-out route trial measures the grid better (bigusHeldOutChoices.h, RouteTrial).
  double PixelGridFanPixelsPerGaussian = 2.0;
  /// The grid's count follows this machine's memory (every fan pixel where it holds them); false: at most
  /// MaximumGaussians (a data-parallel run, whose processes must seed the same grid).
  bool GridCountByMemory = true;
  double UniformShare = 0.1;       ///< share of Harris seeds drawn uniformly inside the mask
  double InitialScalePixels = 1.5; ///< pixels: in-plane standard deviation of a Harris or uniform seed
  /**
   * Harris and residual seeds' scale across their frame (SeedShape::ElevationScale): the beam
   * (TrainerSettings::ElevationSigma), or this times the training frames' median spacing where that is wider and
   * the beam rule measured the spacing (ElevationSigma 0: the ElevationSigma line's "mm apart"). A seed then reaches
   * the view midway to the next frame at one scale, where a beam narrower than the gaps (a sparse sweep whose speckle
   * still correlates) leaves the views between frames empty until Adam stretches the seeds that far: the liver's
   * training frames taken one in 3 (2.29 mm apart, beam 0.319 mm) scored 34.41 dB on 35 test frames at 3,000 steps
   * against 33.87 with seeds at the beam, one in 4 (3.03 mm, 0.284 mm) 33.86 against 32.75 (docs/FINDINGS.md, "Seeds
   * across a sparse sweep's gaps"). Where the beam is half the spacing or wider (every bundled sweep whole) nothing
   * changes. 0: the beam.
   */
  double ElevationSpacingFactor = 0.5;
};

/**
 * Whether this machine's memory holds the training state of @p gaussians (CheckTrainingMemory:
 * TrainingBytesPerGaussian each) and, where @p solve, the reflectivity solve over @p data's training frames
 * (ReflectivitySolveBytes, with the L1 term's vectors where @p l1). Where not, @p error (may be null) says what
 * does not fit.
 */
BIGUSTRAINING_EXPORT bool TrainingFitsInMemory(
  const TrainingData& data, std::int64_t gaussians, bool solve, bool l1, std::string* error = nullptr);

/**
 * The intensity map's exponent for @p data (GammaFromMeanIntensity of the training frames' mean intensity inside
 * their masks) and its `setting` line; @p fanPixels receives how many training pixels are inside the masks. False
 * with @p error when none is.
 */
BIGUSTRAINING_EXPORT bool GammaOfTrainingFrames(
  const TrainingData& data, double& gamma, std::int64_t& fanPixels, std::string& line, std::string* error);

/// Uniform double in [0, 1) from the generator's raw output (identical on every platform).
BIGUSTRAINING_EXPORT double UniformDouble(std::mt19937_64& rng);

/// How seeds are shaped.
struct SeedShape
{
  double PixelSpacing = 1; ///< mm, the training frames' mean in-plane pixel spacing
  double InPlaneScale = 1; ///< mm, Harris and uniform seeds' scale (InitialScalePixels x PixelSpacing)
  /// mm, Harris and residual seeds' scale across their frame: sigma_E (or a pixel without the beam), or
  /// SeedingSettings::ElevationSpacingFactor x FrameSpacing where that is wider
  double ElevationScale = 1;
  double FrameSpacing = 0;   ///< mm, the training frames' spacing ElevationScale was widened for (0: not widened)
  double ElevationSigma = 0; ///< mm, the beam the field renders with (0: the thin plane); the dense start's planes
  double UniformShare = 0.2; ///< Harris seeding: share of the seeds spread uniformly over the fan
  double Gamma = 1;          ///< of I = 1 - exp(-gamma max(S, 0))
};

/// The scattering field that gives intensity @p intensity alone: S = -ln(1 - min(I, 0.95)) / gamma.
double ScatteringOfIntensity(double intensity, double gamma);

/**
 * @p total seeds into @p field (replaced), in proportion to the positive Harris response (OpenCV
 * cornerHarris, block 3, aperture 3, k 0.04) of each training frame inside its mask, plus the uniform
 * share; an even share of @p total per frame, pixel positions jittered within the pixel by @p rng.
 */
void SeedHarris(
  const TrainingData& data, std::int64_t total, std::mt19937_64& rng, const SeedShape& shape, GaussianField& field);

/**
 * Appends to @p field @p count seeds on frame @p frame of @p data where its residual is largest: pixels
 * inside the frame's mask drawn in proportion to |@p residual| ([H, W], the target scattering field minus the
 * rendered one, S-space), each seed with the residual at its pixel as reflectivity (new Gaussians taking their
 * reflectivity from the residual, as Image-GS does: Zhang et al., SIGGRAPH 2025), shaped as Harris seeds.
 * Returns how many it added: @p count, or 0 when the residual is 0 everywhere in the mask.
 */
std::int64_t SeedResidual(const TrainingData& data, int frame, const float* residual, std::int64_t count,
  std::mt19937_64& rng, const SeedShape& shape, GaussianField& field);

/// The ablation: @p total seeds uniform in the bounding box of the training frames' corners, random rotations.
void SeedUniform(
  const TrainingData& data, std::int64_t total, std::mt19937_64& rng, const SeedShape& shape, GaussianField& field);

/// The planes of the dense start.
struct GridPlanes
{
  std::vector<int> Frames;     ///< training frames kept: the first of each sweep, and each other at least sigma_E
                               ///< (or a pixel) from the last one kept in its sweep
  std::vector<double> Spacing; ///< [sweeps] mm, the mean spacing of each sweep's planes along their normals
                               ///< (sigma_E or a pixel for a sweep of one plane)
  std::int64_t FanPixels = 0;  ///< pixels inside the fan masks of the frames kept (the grid's count at stride 1)
  /// [Frames] mm, each plane's own spacing: the larger of its gaps (along the normal of the plane before) to the
  /// planes kept beside it in its sweep (the sweep's Spacing for a sweep of one plane)
  std::vector<double> PlaneSpacing;
};
GridPlanes SelectGridPlanes(const TrainingData& data, const SeedShape& shape);

/**
 * The dense start: Gaussians on the pixel grid of the planes SelectGridPlanes keeps, about @p total of
 * them (never more), in-plane scale 0.6 stride, elevation scale 0.45 of the gap at the point (chosen on the volume
 * protocol: docs/FINDINGS.md, "The dense start's elevation scale"): the larger of the plane's own spacing
 * (GridPlanes::PlaneSpacing) and the point's distances to the planes beside it in its sweep (wider on one side of a
 * tilted neighbour). Returns one line that says what was made.
 */
std::string SeedGrid(const TrainingData& data, std::int64_t total, const SeedShape& shape, GaussianField& field);
/// The same on planes already selected (SelectGridPlanes of the same data and shape).
std::string SeedGrid(
  const TrainingData& data, const GridPlanes& planes, std::int64_t total, const SeedShape& shape, GaussianField& field);

/// What the seeding stage will make (PlanSeeding), decided before any seed is: the route and the count.
struct SeedingPlan
{
  bool PixelGrid = false;     ///< the pixel-grid fit (SeedingSettings::PixelGridFit): no geometry step follows
  std::int64_t Count = 0;     ///< seeds (Harris, uniform), points wanted (dense start) or grid points (pixel grid)
  GridPlanes Planes;          ///< the pixel grid's planes
  std::int64_t FanPixels = 0; ///< masked pixels of the training frames (given to PlanSeeding)
};

/**
 * The seeding stage's choices for @p data: the pixel-grid fit where it applies (the default start, signed
 * reflectivities: @p nonNegative false) and the planes hold at most @p s.PixelGridFanPixelsPerGaussian x
 * @p maximumGaussians fan pixels, else the count of seeds (InitialGaussians, or one per 200 of the training frames'
 * @p fanPixels, 20,000 to half of @p maximumGaussians). The grid's count is every fan pixel of its planes where this
 * machine holds their training state and the reflectivity solve's vectors (TrainingFitsInMemory; with the solve's
 * L1 term, @p solveL1, its larger vectors), else @p maximumGaussians of them. False with @p error when
 * InitialGaussians exceeds @p maximumGaussians.
 */
BIGUSTRAINING_EXPORT bool PlanSeeding(const TrainingData& data, const SeedingSettings& settings,
  std::int64_t maximumGaussians, bool nonNegative, bool solveL1, const SeedShape& shape, std::int64_t fanPixels,
  SeedingPlan& plan, std::string* error);

/**
 * Seeds @p field (replaced) as @p plan says, drawing with a generator seeded from @p seed; returns the stage's
 * `setting` line ("InitialGaussians = ... (why)"). @p solveL1 > 0 is said on the pixel grid's line.
 */
BIGUSTRAINING_EXPORT std::string SeedField(const TrainingData& data, const SeedingPlan& plan,
  const SeedingSettings& settings, const SeedShape& shape, unsigned seed, double solveL1, GaussianField& field);

/**
 * Overlapping seeds add up: one least-squares factor c on every reflectivity of @p field makes the scattering field
 * rendered by @p engine (which holds @p field) match -ln(1 - I) / gamma on up to 5 training frames spread over
 * @p data. @p field's reflectivities are multiplied by c where c is finite and positive (@p scaled then true).
 * False with @p error when a frame cannot be rendered.
 */
BIGUSTRAINING_EXPORT bool ScaleSeedReflectivities(TrainingEngine& engine, const TrainingData& data,
  const RenderOptions& options, double gamma, GaussianField& field, bool& scaled, std::string* error);

/**
 * The S-space residuals t - S ([count, H, W]) of @p count training frames drawn with @p rng (their indices into
 * @p frames), rendered by @p engine: the targets of SeedResidual (DensificationSettings::ResidualSeedShare).
 */
BIGUSTRAINING_EXPORT bool RenderResiduals(TrainingEngine& engine, const TrainingData& data,
  const RenderOptions& options, double gamma, int count, std::mt19937_64& rng, std::vector<int>& frames,
  std::vector<float>& residuals, std::string* error);

/// SeedResidual on each of @p frames with its residual ([frames, H, W], RenderResiduals'), @p count seeds shared
/// evenly among them (the first count % frames one more).
BIGUSTRAINING_EXPORT void SeedResiduals(const TrainingData& data, const std::vector<int>& frames,
  const std::vector<float>& residuals, std::int64_t count, std::mt19937_64& rng, const SeedShape& shape,
  GaussianField& field);

} // namespace bigus

#endif
