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

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace bigus
{

/// How seeds are shaped.
struct SeedShape
{
  double PixelSpacing = 1;   ///< mm, the training frames' mean in-plane pixel spacing
  double InPlaneScale = 1;   ///< mm, Harris and uniform seeds' scale (InitialScalePixels x PixelSpacing)
  double ElevationScale = 1; ///< mm, Harris seeds' scale across their frame (sigma_E, or a pixel without the beam)
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
void SeedHarris(const TrainingData& data, std::int64_t total, std::mt19937_64& rng, const SeedShape& shape,
  GaussianField& field);

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
void SeedUniform(const TrainingData& data, std::int64_t total, std::mt19937_64& rng, const SeedShape& shape,
  GaussianField& field);

/// The planes of the dense start.
struct GridPlanes
{
  std::vector<int> Frames;     ///< training frames kept: the first of each sweep, and each other at least sigma_E
                               ///< (or a pixel) from the last one kept in its sweep
  std::vector<double> Spacing; ///< [sweeps] mm, the mean spacing of each sweep's planes along their normals
                               ///< (sigma_E or a pixel for a sweep of one plane)
  std::int64_t FanPixels = 0;  ///< pixels inside the fan masks of the frames kept (the grid's count at stride 1)
};
GridPlanes SelectGridPlanes(const TrainingData& data, const SeedShape& shape);

/**
 * The dense start: Gaussians on the pixel grid of the planes SelectGridPlanes keeps, about @p total of
 * them (never more), in-plane scale 0.6 stride, elevation scale 0.45 of the spacing of the plane's sweep's
 * planes (measured on the volume protocol: docs/FINDINGS.md). Returns one line that says what was made.
 */
std::string SeedGrid(const TrainingData& data, std::int64_t total, const SeedShape& shape, GaussianField& field);
/// The same on planes already selected (SelectGridPlanes of the same data and shape).
std::string SeedGrid(const TrainingData& data, const GridPlanes& planes, std::int64_t total, const SeedShape& shape,
  GaussianField& field);

} // namespace bigus

#endif
