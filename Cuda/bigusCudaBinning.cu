// CUDA renderer, binning: phase 1 footprints, (tile, Gaussian) entries, tile ranges (see bigusCudaKernels.h). The maths
// is bigusGaussianMath.h and bigusRasterGeometry.h, as on the CPU.
#include "bigusCudaKernels.h"

#include "bigusGaussianMath.h"

namespace bigus
{
namespace cuda
{
namespace
{
/// Phase 1: footprint and number of tiles touched of Gaussian i (0 when culled).
__global__ void SetupKernel(DeviceField field, PreparedSlice s, double sigmaE, double cutoff, bool nonNegative,
  Splat* splats, unsigned long long* touched, Counters* counters)
{
  const std::int64_t i = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= field.Count)
  {
    return;
  }
  unsigned long long tiles = 0;
  const GaussianParams g = LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, i);
  const double r = EffectiveReflectivity(g.Reflectivity, nonNegative);
  if (r != 0)
  {
    const Footprint f = SetupFootprint(g, s.Frame, sigmaE, cutoff, nullptr);
    int box[4];
    if (f.Visible && FootprintBox(f, s, box))
    {
      splats[i] = MakeSplat(f, r, box);
      tiles = static_cast<unsigned long long>(box[1] / TileSize - box[0] / TileSize + 1) *
        static_cast<unsigned long long>(box[3] / TileSize - box[2] / TileSize + 1);
      atomicAdd(&counters->Visible, 1ull);
    }
  }
  touched[i] = tiles;
}

/// Binning: Gaussian i writes (tile, i) for every tile it touches, at its offset of the inclusive scan.
__global__ void EmitKernel(const Splat* splats, const unsigned long long* touched, const unsigned long long* inclusive,
  std::int64_t count, int tilesX, std::uint32_t* keys, std::uint32_t* values)
{
  const std::int64_t i = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= count || touched[i] == 0)
  {
    return;
  }
  const Splat sp = splats[i];
  unsigned long long next = inclusive[i] - touched[i];
  for (int ty = sp.Y0 / TileSize; ty <= sp.Y1 / TileSize; ++ty)
  {
    for (int tx = sp.X0 / TileSize; tx <= sp.X1 / TileSize; ++tx)
    {
      keys[next] = static_cast<std::uint32_t>(ty * tilesX + tx);
      values[next] = static_cast<std::uint32_t>(i);
      ++next;
    }
  }
}

/// Tile t's entries are [start[t], end[t]) of the sorted lists (both zero for an empty tile).
__global__ void TileRangeKernel(const std::uint32_t* keys, std::int64_t entries, int* start, int* end)
{
  const std::int64_t e = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (e >= entries)
  {
    return;
  }
  const std::uint32_t t = keys[e];
  if (e == 0 || keys[e - 1] != t)
  {
    start[t] = static_cast<int>(e);
  }
  if (e == entries - 1 || keys[e + 1] != t)
  {
    end[t] = static_cast<int>(e + 1);
  }
}

}

void LaunchSetup(const DeviceField& field, const PreparedSlice& s, double sigmaE, double cutoff, bool nonNegative,
  Splat* splats, unsigned long long* touched, Counters* counters, cudaStream_t stream)
{
  SetupKernel<<<Blocks(field.Count, SetupBlock), SetupBlock, 0, stream>>>(
    field, s, sigmaE, cutoff, nonNegative, splats, touched, counters);
}

void LaunchEmit(const Splat* splats, const unsigned long long* touched, const unsigned long long* inclusive,
  std::int64_t count, int tilesX, std::uint32_t* keys, std::uint32_t* values, cudaStream_t stream)
{
  EmitKernel<<<Blocks(count, SetupBlock), SetupBlock, 0, stream>>>(
    splats, touched, inclusive, count, tilesX, keys, values);
}

void LaunchTileRange(const std::uint32_t* keys, std::int64_t entries, int* start, int* end, cudaStream_t stream)
{
  TileRangeKernel<<<Blocks(entries, SetupBlock), SetupBlock, 0, stream>>>(keys, entries, start, end);
}

} // namespace cuda
} // namespace bigus
