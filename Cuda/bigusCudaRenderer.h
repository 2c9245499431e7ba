/**
 * @file bigusCudaRenderer.h
 * @brief The CUDA backend of bigus::Renderer (DESIGN section 5), registered as "cuda".
 *
 * Same formulas as the CPU backend: phase 1 and the backward pass call bigusGaussianMath.h
 * (BIGUS_HD) and bigusRasterGeometry.h on the device. Phase 1 runs one thread per Gaussian; tile
 * binning sorts (tile, Gaussian) pairs with CUB's radix sort on the tile id (stable, so every tile's
 * list stays in Gaussian index order); phase 2 runs one 16 x 16 thread block per tile with the
 * tile's footprints staged in shared memory; the backward pass runs one warp per Gaussian over the
 * pixels of its footprint's bounding box (those within the cutoff, the CPU's pixel set) and reduces the
 * warp's partial sums in a fixed order. RenderStats::PixelEvaluations of Backward counts the box's
 * pixels, not the CPU's row spans. Pose gradients (FieldGradients::SlicePoses, pose refinement): the
 * warp's lane 0 writes its Gaussian's share ([N, 6] doubles, 48 more device bytes per Gaussian), and
 * one block per component sums the shares in a fixed order.
 *
 * Deterministic by construction: every pixel sums its Gaussians in index order (as on the CPU) and
 * every Gaussian's gradient is summed by one warp in a fixed order; no float atomics are used, so
 * repeated runs are bit-identical and there is no separate deterministic mode. Results differ from
 * the CPU backend's by float rounding (fused multiply-adds, the device's exp).
 *
 * Buffers of the Renderer interface are host memory: each call uploads the field (and, in Backward,
 * S, dL/dI and the gradients it accumulates into) and downloads the results.
 */
#ifndef bigusCudaRenderer_h
#define bigusCudaRenderer_h

#include "bigusCudaModule.h" // For export macro
#include "bigusRenderer.h"

#include <cstdint>
#include <memory>
#include <string>

namespace bigus
{
namespace cuda
{

/// Device bytes a call needs for each Gaussian of the field: Forward (field, footprints, binning
/// counts) or Backward (field, gradients; 48 more with pose gradients).
BIGUSCUDA_EXPORT std::int64_t DeviceBytesPerGaussian(bool backward = false);
/// Device bytes a call needs for each pixel of the largest slice (S, I, dL, dL/dS, tile ranges).
BIGUSCUDA_EXPORT std::int64_t DeviceBytesPerPixel();
/// Device bytes of one (tile, Gaussian) entry of the binning: keys and values, unsorted and sorted
/// (CUB's radix sort adds scratch space of about one key and value per entry on top).
BIGUSCUDA_EXPORT std::int64_t DeviceBytesPerTileEntry();

/**
 * The CUDA renderer on device 0, or null with @p error when no usable device exists ("no CUDA device
 * is visible", "device X is sm_61; sm_75 or newer is needed"). Its Forward and Backward refuse, with
 * an error that gives the bytes needed and free and before allocating, a field or a slice batch that
 * does not fit in device memory.
 */
BIGUSCUDA_EXPORT std::unique_ptr<Renderer> CreateCudaRenderer(std::string* error);

} // namespace cuda
} // namespace bigus

#endif
