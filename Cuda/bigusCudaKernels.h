/**
 * @file bigusCudaKernels.h
 * @brief The CUDA renderer's kernels, one file per family, behind host launchers that take device
 *        pointers and a stream (private to BIGUS::Cuda): binning (bigusCudaBinning.cu: phase 1's
 *        footprints, the (tile, Gaussian) entries, the tile ranges of the sorted entries), forward
 *        (bigusCudaForward.cu: phase 2, one block per tile) and backward (bigusCudaBackward.cu: dL/dS and
 *        one warp per Gaussian), and the image loss (bigusCudaImageLoss.cu). DeviceRenderer (bigusCudaDeviceRenderer.h)
 * owns the work buffers, the CUB scan and sort, and the order of the launches, for the renderer and the training engine
 * alike.
 *
 * A launcher only enqueues its kernel on @p stream (the caller checks cudaGetLastError). Every pointer is
 * device memory; shapes as in bigusRenderer.h.
 */
#ifndef bigusCudaKernels_h
#define bigusCudaKernels_h

#include "bigusRasterGeometry.h"
#include "bigusRenderer.h"

#include <cuda_runtime.h>

#include <cstdint>

namespace bigus
{
namespace cuda
{

constexpr int SetupBlock = 256;
constexpr int BackwardBlock = 256; // 8 warps: 8 Gaussians per block
constexpr int WarpSize = 32;
constexpr int RasterThreads = TileSize * TileSize;
/// Phase 2 splits a tile's footprint list over at most RasterPieces blocks, each of at least RasterMinimumPiece
/// entries (a whole number of staging batches), so that the longest lists no longer set a launch's time; the
/// pieces' partial sums are added in piece order (deterministic), a list of at most RasterMinimumPiece entries is
/// one piece summed as before.
constexpr int RasterPieces = 8;
constexpr int RasterMinimumPiece = 2 * RasterThreads;
constexpr int PoseSumBlock = 256;

/// The field on the device, structure of arrays as in FieldView.
struct DeviceField
{
  const float* Means;          // [N, 3] mm
  const float* LogScales;      // [N, 3] ln mm
  const float* Quaternions;    // [N, 4] w, x, y, z
  const float* Reflectivities; // [N]
  std::int64_t Count;
};

/// Running counters of a call: visible Gaussians, pixel evaluations.
struct Counters
{
  unsigned long long Visible;
  unsigned long long Evaluations;
};

/// Blocks of @p block threads that cover @p threads.
inline std::int64_t Blocks(std::int64_t threads, int block)
{
  return (threads + block - 1) / block;
}

// Binning (bigusCudaBinning.cu).

/// Phase 1 on slice @p s: Gaussian i's splat, and in @p touched [N] the number of tiles it touches (0 culled).
void LaunchSetup(const DeviceField& field, const PreparedSlice& s, double sigmaE, double cutoff, bool nonNegative,
  Splat* splats, unsigned long long* touched, Counters* counters, cudaStream_t stream);
/// Gaussian i writes (tile, i) for every tile it touches into @p keys / @p values at its offset of the
/// inclusive scan @p inclusive [N] of @p touched.
void LaunchEmit(const Splat* splats, const unsigned long long* touched, const unsigned long long* inclusive,
  std::int64_t count, int tilesX, std::uint32_t* keys, std::uint32_t* values, cudaStream_t stream);
/// Tile t's entries are [start[t], end[t]) of the @p entries sorted @p keys (@p start, @p end zeroed before).
void LaunchTileRange(const std::uint32_t* keys, std::int64_t entries, int* start, int* end, cudaStream_t stream);

// Forward (bigusCudaForward.cu).

/// Phase 2: S (and I = 1 - exp(-gamma max(S, 0)) when @p I is not null) of slice @p s, [H, W], from the
/// splats listed per tile by @p values, @p start and @p end; @p tiles = s.TilesX s.TilesY; @p partials
/// [RasterPieces, H, W] holds the partial sums of the tiles whose lists are split (RasterPieces).
void LaunchRaster(int tiles, const Splat* splats, const std::uint32_t* values, const int* start, const int* end,
  const PreparedSlice& s, float gamma, float* S, float* I, float* partials, Counters* counters, cudaStream_t stream);

// Backward (bigusCudaBackward.cu).

/// dL/dS of @p pixels pixels into @p gS: @p dL itself (@p withRespectToS) or dL/dI dI/dS.
void LaunchScatteringGradient(const float* S, const float* dL, std::int64_t pixels, bool withRespectToS, double gamma,
  float* gS, cudaStream_t stream);
/// Where the backward pass puts each Gaussian's share of a slice's pose gradient (FieldGradients::SlicePoses).
struct PoseShares
{
  double* Shares;  // [N, 6] dL/dxi of each Gaussian (zeroed before), or null: no pose gradient
  double Pivot[3]; // the pivot of the correction, the slice's centre pixel in its plane (SliceCentre), mm
};

/// Accumulates every Gaussian's gradients (and attribution, visible count) from @p gS of slice @p s, and
/// with @p pose.Shares its share of the slice's pose gradient.
void LaunchBackward(const DeviceField& field, const PreparedSlice& s, double sigmaE, double cutoff, bool nonNegative,
  const float* gS, FieldGradients out, const PoseShares& pose, Counters* counters, cudaStream_t stream);
/// Adds the sum over the @p count Gaussians of @p shares [N, 6] to @p total [6], in a fixed order.
void LaunchPoseShareSum(const double* shares, std::int64_t count, double* total, cudaStream_t stream);

// The image loss (bigusCudaImageLoss.cu; definitions as bigus::ComputeImageLoss without the FFL term).

/// Device bytes of LaunchImageLoss's @p scratch for [@p height, @p width] images (8 doubles a pixel and the
/// per-block sums).
std::int64_t ImageLossScratchBytes(int width, int height);
/// Queues the masked L1 and D-SSIM loss of @p rendered against @p target inside @p mask (null: every pixel), all
/// [H, W]: into @p terms (4 doubles) L1, D-SSIM, the masked pixels and weighted total (@p weightL1 L1 + @p weightDSSIM
/// D-SSIM, 0 for an empty mask); when @p gradient is not null, @p gradientScale times dTotal/d(rendered) into it
/// (it may be @p rendered itself). The same result on every run (sums in a fixed order).
void LaunchImageLoss(const float* rendered, const float* target, const unsigned char* mask, int width, int height,
  double weightL1, double weightDSSIM, double gradientScale, float* gradient, double* terms, void* scratch,
  cudaStream_t stream);

} // namespace cuda
} // namespace bigus

#endif
