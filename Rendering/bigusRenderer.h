/**
 * @file bigusRenderer.h
 * @brief Backend-neutral interface of the beam-integrated Gaussian renderer (DESIGN sections 3 and 5).
 *
 * A renderer turns a Gaussian field and a batch of slice poses into the signed scattering field S and
 * the image I = 1 - exp(-gamma max(S, 0)), and turns dL/dI (or dL/dS) back into gradients of the
 * field's parameters plus the error-attribution score E_i = sum_p |dL/dS(p)| |r_i| w_i(p) that
 * densification uses. Buffers are host memory, structure of arrays, float; shapes in comments.
 *
 * Pixel (i, j) of a slice lies at ImageToReference * (i, j, 0, 1) (mm), i.e. columns along the first
 * column of the matrix; the slice's elevation axis is n = u x v. Output images are row-major
 * [H, W] per slice (pixel (i, j) at index j * W + i), slices one after the other.
 */
#ifndef bigusRenderer_h
#define bigusRenderer_h

#include "bigusRenderingModule.h" // For export macro

#include <cstdint>
#include <memory>
#include <string>

namespace bigus
{

/// Read-only view of a Gaussian field (host memory).
struct FieldView
{
  std::int64_t Count = 0;
  const float* Means = nullptr;          ///< [N, 3] mm, reference frame
  const float* LogScales = nullptr;      ///< [N, 3] ln(standard deviation in mm), local axes
  const float* Quaternions = nullptr;    ///< [N, 4] w, x, y, z; normalised on use
  const float* Reflectivities = nullptr; ///< [N] signed reflectivity r
};

/// Gradients of a field, accumulated (+=) by Backward. Any pointer may be null to skip that output.
struct FieldGradients
{
  float* Means = nullptr;          ///< [N, 3] dL/dmean, 1/mm
  float* LogScales = nullptr;      ///< [N, 3] dL/dlog-scale
  float* Quaternions = nullptr;    ///< [N, 4] dL/dq (through the normalisation)
  float* Reflectivities = nullptr; ///< [N] dL/dr
  float* Attribution = nullptr;    ///< [N] E_i = sum_p |dL/dS(p)| |r_i| w_i(p)
  int* VisibleCount = nullptr;     ///< [N] number of slices whose pixels the Gaussian's footprint touched
  /// [count, 6] (per slice of the call, not per Gaussian) dL/dxi of a rigid correction xi of each slice's
  /// pose at xi = 0: rotation vector (0..2, per rad) about the slice's centre pixel ((W - 1) / 2, (H - 1) / 2)
  /// and translation (3..5, per mm), both in the slice's own axes u, v, n (bigus::CorrectSliceFrame,
  /// SlicePoseBackward; SliceCorrectionMatrix gives the corrected ImageToReference). Pose refinement.
  double* SlicePoses = nullptr;
};

/// One slice: its pose and its pixel grid.
struct SliceGeometry
{
  double ImageToReference[16]; ///< row-major 4x4, pixel index -> mm (spacing inside)
  int Width = 0;               ///< pixels along the first matrix column
  int Height = 0;              ///< pixels along the second matrix column
  /// Variance (pixels^2, along each of the slice's pixel axes) of a Gaussian low-pass that every footprint is
  /// convolved with before it is sampled at the pixel centres: a pixel that stands for an area, not a point
  /// (Mip-Splatting's 2D filter; a box of w pixels has variance w^2 / 12). 0 (default): point samples. The
  /// resolution schedule's averaged coarse frames use 1/16 (bigus::DecimateFrames).
  double PixelLowPass = 0;
};

/**
 * Largest |90 deg - angle between the image axes| of a pose that the renderer accepts by default, and
 * the default limit of every reader and geometry check (vtkUltrasoundSequenceReader,
 * vtkUltrasoundSliceGeometry), so that a sweep read with the defaults is one the renderer and the
 * trainer accept. Real calibrations carry a few degrees of shear (the PLUS spine phantom about 2.8).
 */
constexpr double DefaultMaximumShearAngle = 5.0;

/// Rendering settings.
struct RenderOptions
{
  double ElevationSigma = 0.5;          ///< sigma_E, mm: standard deviation of the elevation beam profile
  double Gamma = 1.0;                   ///< gamma of I = 1 - exp(-gamma max(S, 0))
  double Cutoff = 5.0;                  ///< k: footprint extends k standard deviations (elevation and in plane);
                                        ///< 5 keeps the float error in I below 1e-5 (TestCpuRenderer)
  bool BeamIntegration = true;          ///< false: thin plane (sigma_E -> 0), the UltraGauss ablation
  bool NonNegativeReflectivity = false; ///< true: r is used as max(r, 0) (ablation)
  double MaximumShearAngle = DefaultMaximumShearAngle; ///< degrees; a pose sheared more is rejected
};

/// The sigma_E (mm) that the maths uses: ElevationSigma with beam integration, 0 (the thin plane) without.
inline double EffectiveElevationSigma(const RenderOptions& o)
{
  return o.BeamIntegration ? o.ElevationSigma : 0.0;
}

/// What one call did (summed over its slices).
struct RenderStats
{
  std::int64_t GaussiansVisible = 0; ///< Gaussians kept after elevation culling
  std::int64_t TileEntries = 0;      ///< (Gaussian, tile) pairs after binning
  std::int64_t PixelEvaluations = 0; ///< Gaussian-pixel pairs evaluated: forward, inside the bounding boxes;
                                     ///< backward, inside the row spans of the cutoff ellipses
  double SetupSeconds = 0;           ///< phase 1 (transform, cull, set up) and binning
  double RasterSeconds = 0;          ///< phase 2 (per-tile evaluation) and the image map, or the backward pass
};

class BIGUSRENDERING_EXPORT Renderer
{
public:
  virtual ~Renderer();
  virtual const char* GetName() const = 0;

  /**
   * Render @p count slices. @p S and @p I receive [count, H, W] floats each (@p I may be null).
   * Returns false with @p error set for a bad pose (NaN, singular, sheared beyond the limit) or a bad
   * grid; nothing is written then.
   */
  virtual bool Forward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    float* S, float* I, RenderStats* stats, std::string* error) = 0;

  /**
   * Accumulate gradients for @p count slices. @p S: the forward scattering field [count, H, W];
   * @p dL: dL/dI [count, H, W], or dL/dS when @p gradientIsWithRespectToS is true.
   */
  virtual bool Backward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    const float* S, const float* dL, bool gradientIsWithRespectToS, FieldGradients& gradients, RenderStats* stats,
    std::string* error) = 0;
};

/// The multi-threaded CPU backend (vtkSMPTools). Always available.
BIGUSRENDERING_EXPORT std::unique_ptr<Renderer> CreateCpuRenderer();

} // namespace bigus

#endif
