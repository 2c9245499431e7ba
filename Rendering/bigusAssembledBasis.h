/**
 * @file bigusAssembledBasis.h
 * @brief The reflectivity basis A assembled once per geometry, so that the reflectivity solve's products are
 *        passes over stored weights instead of renders (DESIGN section 4, "Solve what is linear").
 *
 * For a fixed geometry S = A r (DESIGN section 3): column i of A is Gaussian i's beam-integrated weight w_i(p) at
 * reflectivity 1 on every pixel p of the slices. AssembledBasis stores each visible (slice, Gaussian) footprint as
 * the row spans of its bounding box that the cut-off ellipse covers (RowSpan) and the float weight of each pixel of
 * a span (0 where the pixel lies outside the cut-off): the same pixels, cut-off and float arithmetic as the CPU
 * renderer's backward pass and AccumulateBasisNorms, so A^T y and diag(A^T W A) are theirs to float rounding and
 * A r is Forward's (whose tiles evaluate the same footprint relative to another origin: a pixel on the cut-off
 * ellipse may fall on either side, a weight of at most exp(-cutoff^2 / 2) of the Gaussian's peak).
 *
 * Storage (Size): 4 bytes per stored weight, 16 per row span, 32 per footprint, 8 per footprint while a transpose
 * product runs. Measure counts them without storing anything, so a caller decides before allocating whether the
 * matrix fits (the solve falls back to the matrix-free products where it does not).
 *
 * Products: Apply is parallel over slices, ApplyTranspose and Norms over footprints, each with vtkSMPTools, and
 * sum in a fixed order: the same result for any number of threads. Host memory only.
 */
#ifndef bigusAssembledBasis_h
#define bigusAssembledBasis_h

#include "bigusRenderer.h"
#include "bigusRenderingModule.h" // For export macro

#include <cstdint>
#include <string>
#include <vector>

namespace bigus
{

class BIGUSRENDERING_EXPORT AssembledBasis
{
public:
  /// What a matrix stores.
  struct Size
  {
    std::int64_t Footprints = 0; ///< visible (slice, Gaussian) pairs
    std::int64_t Spans = 0;      ///< row spans of those footprints
    std::int64_t Weights = 0;    ///< stored weights (pixels of the spans)
    /// Bytes of the matrix and of a transpose product's scratch.
    std::int64_t Bytes() const;
  };

  /**
   * Counts what Assemble would store for @p field ([N]; all four arrays, the reflectivities unused) on the @p count
   * slices, with @p options' elevation sigma and cut-off, without storing it. Returns false with @p error, as
   * Renderer::Forward does, for a bad pose or grid.
   */
  static bool Measure(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    Size& size, std::string* error);

  /**
   * Builds A for @p field on the @p count slices (pixel k of slice j is row j H W + k for slices of one size; in
   * general the slices' pixels one slice after the other). Measures first and, when the matrix would need more than
   * @p maximumBytes (0: no limit), refuses before allocating: false with @p error giving the bytes it needed and
   * @p tooLarge (when not null) true. Returns false with @p error for a bad pose or grid too; the basis is then
   * empty.
   */
  bool Assemble(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    std::int64_t maximumBytes, std::string* error, bool* tooLarge = nullptr);

  /// S = A r: @p S [pixels of every slice] is overwritten; @p r [N].
  void Apply(const float* r, float* S) const;
  /// @p out [N] += A^T y, @p y [pixels of every slice].
  void ApplyTranspose(const float* y, double* out) const;
  /// @p out [N] += diag(A^T W A) = sum_p W(p) w_i(p)^2, @p weights W [pixels of every slice].
  void Norms(const float* weights, double* out) const;

  const Size& GetSize() const { return this->Stored; }
  std::int64_t GetGaussians() const { return this->Gaussians; }
  std::int64_t GetPixels() const { return this->Pixels; }

private:
  struct FootprintEntry
  {
    std::int64_t Gaussian;
    std::int64_t FirstSpan;
    std::int64_t FirstWeight;
    std::int64_t SpanCount;
  };
  struct Span
  {
    std::int64_t Pixel; ///< the first pixel's row of A
    std::int64_t Count; ///< pixels, consecutive along the image row
  };
  /// Measure (@p maximumBytes < 0: counts into @p measured only) and Assemble.
  bool Build(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    std::int64_t maximumBytes, Size* measured, std::string* error, bool* tooLarge);
  /// Dot products of each footprint's weights (squared, with @p square) with @p y, added to their Gaussians.
  void Transpose(const float* y, bool square, double* out) const;

  Size Stored;
  std::int64_t Gaussians = 0, Pixels = 0;
  std::vector<std::int64_t> SlicePixels;     ///< [count + 1]: slice j's rows of A are [j, j + 1)
  std::vector<std::int64_t> SliceFootprints; ///< [count + 1]: slice j's footprints are [j, j + 1)
  std::vector<FootprintEntry> Footprints;    ///< by slice, then by Gaussian
  std::vector<Span> Spans;
  std::vector<float> Weights;
};

} // namespace bigus

#endif
