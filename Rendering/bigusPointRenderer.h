/**
 * @file bigusPointRenderer.h
 * @brief The beam-integrated field at scattered points, each with its own local plane: the renderer of a
 *        vtkGaussianFieldReslice whose sampling grid a non-linear or perspective transform bends.
 *
 * A sample is a point x (mm, reference frame) with the two pixel axes a and b of its output grid there (mm per
 * output pixel: the derivatives of x along the output's i and j, i.e. the transform's Jacobian applied to the
 * grid's axes). Its value is what a slice through x with those axes renders at x (DESIGN section 3): each
 * Gaussian's footprint on the plane through x spanned by a and b (rendering frame u = a / |a|, v_perp, n = u x v),
 * the elevation beam along n, the pixel low-pass on a and b, evaluated at x. The footprints are the renderer's
 * (bigus::SetupFootprint, its cutoff); the sum is in double and std::exp, so a sample agrees with a slice rendered
 * through it by the tiled renderers to their float error (1e-5 in I, TestCpuRenderer's bound).
 *
 * Cost: the Gaussians are binned once per call into a regular grid of cells over the samples' bounds (each in the
 * cells its reach k sqrt(s_max^2 + sigma_E^2 + low-pass) touches); each sample then sets up the footprint of every
 * Gaussian of its cell: about (Gaussians per cell) x 100 flops per sample, against a slice's per-pixel cost of the
 * Gaussians that overlap it. Multi-threaded over the samples (vtkSMPTools); the result does not depend on the
 * thread count (each sample sums its Gaussians in index order).
 */
#ifndef bigusPointRenderer_h
#define bigusPointRenderer_h

#include "bigusRenderer.h"
#include "bigusRenderingModule.h" // For export macro

#include <string>
#include <vector>

namespace bigus
{

/// One sample: its position and the output grid's two pixel axes there.
struct PointSample
{
  double Position[3];     ///< mm, reference frame
  double PixelAxes[2][3]; ///< a, b: mm per output pixel along i and along j (not parallel; any shear)
};

/**
 * Renders @p count samples: @p S and @p I receive [count] floats (S the signed scattering field, I = 1 -
 * exp(-gamma max(S, 0)); @p I may be null). @p pixelLowPass: variance (output pixels^2, along a and b) of the
 * low-pass of SliceGeometry::PixelLowPass. Returns false with @p error ("sample 12: its pixel axes are parallel
 * or zero (a transform that folds the grid there)") when a sample has no plane, or a bad @p pixelLowPass; nothing is
 * written then.
 */
BIGUSRENDERING_EXPORT bool RenderPoints(const FieldView& field, const PointSample* samples, std::int64_t count,
  double pixelLowPass, const RenderOptions& options, float* S, float* I, std::string* error);

} // namespace bigus

#endif
