/**
 * @file bigusBackendCheck.h
 * @brief A backend proves itself before "auto" picks it (bigusBackend.h): it renders and
 *        back-propagates a small fixed field of hard cases and must be as accurate as the CPU renderer.
 *
 * The field (HardCaseField) holds the footprint's hard cases on one slice of 160 x 112 pixels of 0.5 mm
 * in a generic orientation: needles and pancakes (long axis or disc radius 2 mm, scale ratios 1, 10 and
 * 100) tilted 0 to 90 degrees out of the plane, 0 to 4 elevation standard deviations off it, signed
 * reflectivities, each in a 4 mm cell of its own (168 Gaussians). The check renders it at that slice and
 * at a second one of another size (77 x 45 pixels: neither a multiple of the 16-pixel tile) moved 1.3 mm
 * off the plane, in one call, and back-propagates a fixed dL/dI. It passes when
 *   - max |I - I_cpu| <= ImageTolerance (1e-5: the CUDA parity test's bound at these ratios), and
 *   - its gradients are as accurate as the CPU renderer's: measured against the naive double reference
 *     renderer cut at the same footprints (RenderReference), the error of every Gaussian in every
 *     parameter group (mean, log-scale, rotation, reflectivity, attribution), max |g - g_exact| over
 *     max(|g_exact| of that Gaussian's group, 1e-3 x the largest |g_exact| of the group), is at most
 *     max(GradientTolerance (1e-4), GradientErrorRatio (2) x the CPU renderer's worst such error):
 *     relative to the Gaussian's own gradient, so a small Gaussian's wrong gradient is not hidden by a
 *     large one's. Not against the CPU itself: two float renderers that sum a footprint in different
 *     orders differ by both their errors, and where a gradient is small by cancellation (a log-scale
 *     gradient over a footprint of random dL/dI) float rounding of the per-pixel terms does not cancel
 *     and is a visible share of it on either (the errors measured: docs/FINDINGS.md,
 *     "The CUDA renderer on a GPU");
 *   - the visible counts agree in total (a Gaussian at the cull's edge may tie differently), and
 *     nothing is NaN or infinite.
 * It runs once per backend and process (CheckBackend caches it); its cost:
 * docs/FINDINGS.md, "The trainer's defaults, measured".
 */
#ifndef bigusBackendCheck_h
#define bigusBackendCheck_h

#include "bigusRenderer.h"
#include "bigusRenderingModule.h" // For export macro

#include <string>
#include <vector>

namespace bigus
{

/// What a backend's self-check found.
struct BackendCheck
{
  std::string Backend;
  bool Passed = false;
  double ImageDifference = 0;    ///< max |I - I_cpu| over the check's pixels
  double GradientDifference = 0; ///< the backend's worst gradient error against the reference (above)
  double CpuGradientError = 0;   ///< the CPU renderer's worst gradient error against the reference
  std::string Detail;            ///< one line: what was compared, or why the check could not run
};

/// A field of host arrays (structure of arrays, as FieldView).
struct BIGUSRENDERING_EXPORT HostField
{
  std::vector<float> Means, LogScales, Quaternions, Reflectivities; ///< [N,3] mm, [N,3], [N,4] w x y z, [N]
  FieldView View() const;
};

/// A slice of @p w x @p h pixels of @p spacing mm turned by @p degrees about @p axis (Rodrigues' formula),
/// its pixel (0, 0) at @p origin (mm).
BIGUSRENDERING_EXPORT SliceGeometry RotatedSlice(
  int w, int h, double spacing, double degrees, const double axis[3], const double origin[3]);

/// What a renderer gives for a field, a batch of slices and dL/dI: S, I, every gradient, the visible
/// counts and the calls' statistics.
struct RenderedGradients
{
  std::vector<float> S, I, Means, LogScales, Quaternions, Reflectivities, Attribution; ///< [pixels] and [N, ...]
  std::vector<int> Visible;                                                            ///< [N]
  RenderStats Forward, Backward;
};

/**
 * Forward then Backward of @p renderer for @p count @p slices with dL/dI = @p dL ([pixels of every
 * slice]); every gradient output is zeroed first. False with @p error when either call fails.
 */
BIGUSRENDERING_EXPORT bool RenderWithGradients(Renderer& renderer, const FieldView& field, const SliceGeometry* slices,
  int count, const RenderOptions& options, const std::vector<float>& dL, RenderedGradients& out, std::string* error);

/// The slice of the hard-case field: 160 x 112 pixels of 0.5 mm, moved @p shift mm along reference y.
BIGUSRENDERING_EXPORT SliceGeometry HardCaseSlice(double shift = 0);

/**
 * The hard cases above for beam @p sigmaE (mm; it sets the elevation offsets) and the scale ratios
 * @p ratios, on HardCaseSlice(); reflectivities 0.8 and -0.5 in turn.
 */
BIGUSRENDERING_EXPORT HostField HardCaseField(double sigmaE, const std::vector<double>& ratios);

/// How much larger than the CPU renderer's a backend's gradient error against the reference may be.
constexpr double GradientErrorRatio = 2.0;

/**
 * Compares @p renderer with the CPU renderer and the reference on the hard-case field (sigma_E 0.5 mm,
 * ratios 1 to 100) as above. Never throws; a renderer that fails a call fails the check with its error
 * in Detail.
 */
BIGUSRENDERING_EXPORT BackendCheck CheckRenderer(Renderer& renderer);

/**
 * What RenderWithGradients gives (S, I and every gradient; no visible counts), from the naive double
 * reference renderer (bigusReferenceRenderer.h) cut at the renderers' footprints (RenderOptions::Cutoff),
 * rounded to float. Costs every Gaussian at every pixel: for test-sized fields. False with @p error for a
 * pose the reference rejects.
 */
BIGUSRENDERING_EXPORT bool RenderReference(const FieldView& field, const SliceGeometry* slices, int count,
  const RenderOptions& options, const std::vector<float>& dL, RenderedGradients& out, std::string* error);

/**
 * @p mine against @p cpu and @p exact (RenderReference; the same field, slices, options and dL/dI) as the
 * check compares them: max |I - I_cpu| <= @p imageTolerance; the worst gradient error against @p exact
 * at most max(@p gradientTolerance, GradientErrorRatio x the CPU's); visible entries equal in total;
 * nothing NaN or infinite. Sizes must match (the same field and slices).
 */
BIGUSRENDERING_EXPORT BackendCheck CompareRenders(const RenderedGradients& mine, const RenderedGradients& cpu,
  const RenderedGradients& exact, double imageTolerance, double gradientTolerance);

/**
 * The self-check of registered backend @p name, run once per process (later calls return the first
 * result). "cpu" is the reference: it passes without running. An unknown or unusable backend fails
 * with the registry's reason.
 */
BIGUSRENDERING_EXPORT BackendCheck CheckBackend(const std::string& name);

} // namespace bigus

#endif
