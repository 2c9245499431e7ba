/**
 * @file bigusBasisNorms.h
 * @brief The weighted squared norms of the reflectivity basis, diag(A^T W A) (DESIGN section 4).
 *
 * For a fixed geometry the scattering field is linear in the reflectivities, S = A r with column i of
 * A the beam-integrated weight w_i(p) of Gaussian i (DESIGN section 3). The reflectivity solve
 * (bigusReflectivitySolve.h) preconditions its Krylov iteration with the diagonal of the weighted
 * normal matrix, sum_p W(p) w_i(p)^2 (Jacobi). The sum runs over the same pixels, with the same cutoff
 * and the same float arithmetic, as the CPU renderer's phase 2, so it is exact for the operator that
 * Forward applies. Host memory; multi-threaded over Gaussians with vtkSMPTools; deterministic.
 */
#ifndef bigusBasisNorms_h
#define bigusBasisNorms_h

#include "bigusRenderer.h"
#include "bigusRenderingModule.h" // For export macro

#include <string>

namespace bigus
{

/**
 * Adds to @p norms ([N], double) sum over the @p count slices k and their pixels p of
 * weights_k(p) w_i(p)^2, w_i(p) the weight of Gaussian i at pixel p (reflectivity 1).
 * @p weights: [count, H, W] per-pixel weights of each slice (0 outside the fan mask).
 * RenderOptions::NonNegativeReflectivity does not enter (the basis has unit reflectivity).
 * Returns false with @p error, and adds nothing, for a bad pose or grid (as Renderer::Forward).
 */
BIGUSRENDERING_EXPORT bool AccumulateBasisNorms(const FieldView& field, const SliceGeometry* slices, int count,
  const RenderOptions& options, const float* weights, double* norms, std::string* error);

} // namespace bigus

#endif
