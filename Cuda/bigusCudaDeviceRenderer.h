/**
 * @file bigusCudaDeviceRenderer.h
 * @brief The CUDA renderer on device buffers (private to BIGUS::Cuda): the order of the kernels of one
 *        slice's forward and backward pass over a field that already lives on the device, with the
 *        binning's buffers, the CUB scan and sort, and the memory checks.
 *
 * Two users: bigus::cuda::CreateCudaRenderer (bigusCudaRenderer.cu), the Renderer interface on host
 * buffers, which uploads the field every call; and the device-resident training engine
 * (bigusCudaTrainingEngine.cu), which keeps the field, its Adam moments and its gradients on the device
 * and moves only images between host and device.
 */
#ifndef bigusCudaDeviceRenderer_h
#define bigusCudaDeviceRenderer_h

#include "bigusCudaKernels.h"
#include "bigusFieldLayout.h"

#include <cuda_runtime.h>

#include <cstdint>
#include <string>
#include <vector>

namespace bigus
{
namespace cuda
{

/// Device bytes of the work buffers: per Gaussian for the binning (footprint, tile count and its scan), per
/// Gaussian for the pose shares of a backward pass with pose gradients, per (tile, Gaussian) entry (keys and
/// values, unsorted and sorted; CUB's radix sort adds scratch space of about one key and value per entry).
constexpr std::int64_t BinningBytes = sizeof(Splat) + 2 * sizeof(unsigned long long);
constexpr std::int64_t PoseBytesPerGaussian = 6 * sizeof(double);
constexpr std::int64_t EntryBytes = 4 * sizeof(std::uint32_t);

/// The field at @p base on the device, in the packed layout of bigusFieldLayout.h (means [N, 3], log-scales
/// [N, 3], quaternions [N, 4] and reflectivities [N] one after the other).
inline DeviceField FieldAt(const float* base, std::int64_t n)
{
  return DeviceField{ base + FieldGroupFirst(MeanGroup) * n, base + FieldGroupFirst(LogScaleGroup) * n,
    base + FieldGroupFirst(QuaternionGroup) * n, base + FieldGroupFirst(ReflectivityGroup) * n, n };
}

/// The largest slice of a call, its tiles, and the call named for memory errors.
struct CallExtent
{
  std::int64_t Pixels = 1, Tiles = 1;
  std::string What; ///< "a field of N Gaussians and slices of P pixels"
};
CallExtent Extent(std::int64_t gaussians, const std::vector<PreparedSlice>& slices);

/// Queues on @p stream the copy of @p field's four host arrays to @p device, laid out as FieldAt reads them; false
/// with @p error when the copy cannot be queued.
bool UploadField(const FieldView& field, float* device, cudaStream_t stream, std::string* error);

/// True when a device can run the kernels (QueryDevice); otherwise false with @p error saying why.
bool DeviceUsable(std::string* error);

/// True for cudaSuccess; otherwise false with @p error "CUDA renderer: WHAT: the CUDA error".
bool Check(cudaError_t status, const char* what, std::string* error);

/// A device allocation that only grows; freed with its owner.
struct Buffer
{
  void* Data = nullptr;
  std::int64_t Bytes = 0;
  Buffer() = default;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  ~Buffer();
  /// At least @p bytes (contents lost when it grows); false with @p error naming @p what.
  bool Reserve(std::int64_t bytes, const char* what, std::string* error);
  template <typename T>
  T* As() const
  {
    return static_cast<T*>(this->Data);
  }
};

class DeviceRenderer
{
public:
  DeviceRenderer() = default;
  DeviceRenderer(const DeviceRenderer&) = delete;
  DeviceRenderer& operator=(const DeviceRenderer&) = delete;
  ~DeviceRenderer();

  /// Creates the stream every call runs on.
  bool Initialize(std::string* error);
  cudaStream_t GetStream() const { return this->Stream; }

  /**
   * Refuses, before allocating, @p bytes of new buffers when they do not fit: against the device's free
   * memory plus @p held, the bytes of the buffers they replace. The error names @p what and gives the
   * bytes needed, free and held.
   */
  bool Fits(std::int64_t bytes, std::int64_t held, const std::string& what, std::string* error) const;

  /**
   * Checks, then reserves, the work buffers of calls on a field of @p n Gaussians and slices of at most
   * @p tiles tiles: the binning for Forward, the pose shares for Backward with @p poses. @p ownBytes are
   * the caller's buffers for the same calls, of which it holds @p ownHeld already; the check counts them
   * too, so that nothing is allocated when the whole does not fit. @p what names the call in the error.
   */
  bool Reserve(bool backward, bool poses, std::int64_t n, std::int64_t tiles, std::int64_t ownBytes,
    std::int64_t ownHeld, const std::string& what, std::string* error);

  /**
   * S ([H, W], device) of slice @p s, and I when @p I (device) is not null. With @p stats (may be null) it
   * waits for the result and adds to them; without, the raster is only queued after the binning (which waits for
   * its entry count): work that follows on the stream sees S and I. The field is device memory ([N] per array,
   * DeviceField).
   */
  bool Forward(const DeviceField& field, const PreparedSlice& s, const RenderOptions& options, float* S, float* I,
    RenderStats* stats, std::string* error);

  /**
   * Adds slice @p s's gradients to @p out (device pointers, as FieldGradients; null entries are skipped)
   * from @p S and @p dL ([H, W], device; @p dL is dL/dS when @p withRespectToS, else dL/dI), with
   * @p scratch ([H, W], device) for dL/dS. With @p poseTotal (device, 6 doubles) adds the slice's pose
   * gradient there. Queued only: the caller synchronises the stream (Synchronize).
   */
  bool Backward(const DeviceField& field, const PreparedSlice& s, const RenderOptions& options, const float* S,
    const float* dL, bool withRespectToS, float* scratch, FieldGradients out, double* poseTotal, std::string* error);

  /// Waits for the work queued so far and adds the counters of the backward passes since the last call to
  /// @p stats (may be null).
  bool Synchronize(RenderStats* stats, const char* what, std::string* error);

private:
  /// Phase 1 and the binning of one slice: footprints, (tile, Gaussian) pairs sorted by tile, tile ranges.
  bool Bin(const DeviceField& field, const PreparedSlice& s, double sigmaE, const RenderOptions& options,
    std::int64_t& entries, std::string* error);
  bool ReadCounters(Counters& counters, const char* what, std::string* error);

  cudaStream_t Stream = nullptr;
  Buffer Splats;        // [N] Splat
  Buffer Touched;       // [2, N] unsigned long long: tiles touched, their inclusive scan
  Buffer TileStart;     // [tiles] int
  Buffer TileEnd;       // [tiles] int
  Buffer Partials;      // [RasterPieces, H, W] float: phase 2's partial sums of split tiles
  Buffer Keys;          // [E] tile id
  Buffer SortedKeys;    // [E]
  Buffer Values;        // [E] Gaussian index
  Buffer SortedValues;  // [E]
  Buffer Temporary;     // CUB's scratch space
  Buffer Count;         // Counters
  Buffer PoseShareData; // [N, 6] doubles: each Gaussian's share of one slice's pose gradient
};

} // namespace cuda
} // namespace bigus

#endif
