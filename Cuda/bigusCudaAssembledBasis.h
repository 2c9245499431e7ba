/**
 * @file bigusCudaAssembledBasis.h
 * @brief The reflectivity basis A assembled on the device (private to BIGUS::Cuda): the GPU twin of
 *        bigus::AssembledBasis (bigusAssembledBasis.h), so that the CUDA engine's solve products are passes over
 *        stored weights instead of renders (DESIGN section 4, "Solve what is linear").
 *
 * Column i of A is Gaussian i's beam-integrated weight w_i(p) at reflectivity 1 on every pixel p of the slices. The
 * assembly is two passes of one warp per Gaussian over the slices (the cheap elevation test OutOfReach, then the
 * set-up and the pixels of the footprint's box, as the backward kernel of bigusCudaBackward.cu takes them): the first
 * counts each column's and each pixel's entries, the second writes each column's (pixel, weight) entries at the
 * offsets of the counts' scan, slice by slice and row by row. A stable radix sort of the entries by pixel (CUB) gives
 * the rows (Gaussian, weight) in Gaussian order. Only pixels inside the cut-off ellipse are stored.
 *
 * Products: A r one thread per pixel, A^T y and diag(A^T W A) one warp per Gaussian; each sums in double in a fixed
 * order, so a product gives the same result on every run.
 *
 * Storage (PersistentBytes): 16 bytes per entry (the column's pixel and weight, the row's Gaussian and weight), 8 per
 * Gaussian and per pixel (offsets, the pixel vector of a product); while it is built, 16 bytes per entry and 4 per
 * pixel more (the sort's second buffers, the pixels' counts) and CUB's scratch.
 */
#ifndef bigusCudaAssembledBasis_h
#define bigusCudaAssembledBasis_h

#include "bigusCudaDeviceRenderer.h"

#include <cstdint>
#include <string>
#include <vector>

namespace bigus
{
namespace cuda
{

class DeviceBasis
{
public:
  /**
   * Builds A for @p field (device) on the @p slices, all of one size (pixel k of slice j is row j H W + k), with
   * elevation sigma @p sigmaE (mm) and cut-off @p cutoff, on @p device's stream. Counts first; when the matrix and its
   * build need more than @p maximumBytes (0: no limit) or more than the device has free, or its entries or pixels do
   * not fit 32-bit indices, refuses before allocating the entries: false, @p tooLarge true and @p error giving the
   * bytes it needed. False with @p error for a CUDA error.
   */
  bool Assemble(const DeviceField& field, const std::vector<PreparedSlice>& slices, double sigmaE, double cutoff,
    std::int64_t maximumBytes, const DeviceRenderer& device, std::string* error, bool* tooLarge);

  /// The [pixels] floats on the device that a product reads (y, W) or writes (A r).
  float* PixelVector() const { return this->Vector.As<float>(); }
  /// Queues A r into PixelVector(), @p r [N] on the device.
  void Apply(const float* r, cudaStream_t stream) const;
  /// Queues A^T y into @p out [N] doubles on the device (overwritten), y in PixelVector().
  void ApplyTranspose(double* out, cudaStream_t stream) const;
  /// Queues diag(A^T W A) = sum_p W(p) w_i(p)^2 into @p out [N] doubles on the device (overwritten), W in
  /// PixelVector().
  void Norms(double* out, cudaStream_t stream) const;

  std::int64_t GetEntries() const { return this->Entries; }
  std::int64_t GetPixels() const { return this->Pixels; }
  /// Device bytes held after the build.
  std::int64_t PersistentBytes() const;

private:
  std::int64_t Gaussians = 0, Pixels = 0, Entries = 0;
  Buffer ColumnOffsets; // [N + 1] unsigned long long: column i's entries are [offset i, offset i + 1)
  Buffer ColumnPixels;  // [E] unsigned int: the pixel of each entry, in column order
  Buffer ColumnWeights; // [E] float
  Buffer RowOffsets;    // [P + 1] unsigned int
  Buffer RowEntries;    // [E] unsigned long long: Gaussian << 32 | the weight's float bits, in row order
  Buffer Vector;        // [P] float
};

} // namespace cuda
} // namespace bigus

#endif
