// CUDA renderer, forward: phase 2, one block per tile (see bigusCudaKernels.h). The maths is bigusGaussianMath.h and
// bigusRasterGeometry.h, as on the CPU.
#include "bigusCudaKernels.h"

#include "bigusGaussianMath.h"

namespace bigus
{
namespace cuda
{
namespace
{
/// Sum of @p v over the warp (integer: exact in any order).
__device__ unsigned long long WarpSum(unsigned long long v)
{
  for (int offset = WarpSize / 2; offset > 0; offset /= 2)
  {
    v += __shfl_down_sync(0xffffffffu, v, offset);
  }
  return v;
}

/// Entries per piece of a tile list of @p entries (RasterPieces): at least RasterMinimumPiece, whole staging
/// batches, at most RasterPieces pieces.
__device__ int PieceLength(int entries)
{
  const int batches = ((entries + RasterPieces - 1) / RasterPieces + RasterThreads - 1) / RasterThreads;
  return max(RasterMinimumPiece, batches * RasterThreads);
}

/// The pieces a tile list of @p entries is split into (1 for an empty list: its block writes the zeros).
__device__ int PieceCount(int entries)
{
  const int length = PieceLength(entries);
  return max(1, (entries + length - 1) / length);
}

/**
 * Phase 2: block (tile, piece) sums piece blockIdx.y of the tile's list (PieceCount), one thread per pixel. The
 * piece's footprints are staged in shared memory RasterThreads at a time and every pixel adds them in Gaussian
 * index order, as the CPU backend does, with offsets relative to the tile's first pixel. A tile of one piece writes
 * S and I; the pieces of a split tile write their partial sums, which CombinePiecesKernel adds.
 */
__global__ void RasterKernel(const Splat* splats, const std::uint32_t* values, const int* start, const int* end,
  PreparedSlice s, float gamma, float* S, float* I, float* partials, Counters* counters)
{
  __shared__ Splat staged[RasterThreads];
  const int tile = blockIdx.x, piece = blockIdx.y;
  const int entries = end[tile] - start[tile];
  const int pieces = PieceCount(entries);
  if (piece >= pieces)
  {
    return; // the whole block: no barrier is reached
  }
  const int q = threadIdx.x, r = threadIdx.y;
  const int I0 = (tile % s.TilesX) * TileSize, J0 = (tile / s.TilesX) * TileSize;
  const int i = I0 + q, j = J0 + r;
  const bool inside = i < s.Width && j < s.Height;
  const double X0 = I0 * s.PixelToPlane[0] + J0 * s.PixelToPlane[1];
  const double Y0 = J0 * s.PixelToPlane[2];
  const float P0 = static_cast<float>(s.PixelToPlane[0]);
  const float P1 = static_cast<float>(s.PixelToPlane[1]);
  const float P2 = static_cast<float>(s.PixelToPlane[2]);
  const float column = q * P0;
  float acc = 0;
  unsigned long long evaluations = 0;
  const int length = PieceLength(entries);
  const int first = start[tile] + piece * length, last = min(end[tile], first + length);
  for (int base = first; base < last; base += RasterThreads)
  {
    const int n = min(RasterThreads, last - base);
    const int t = r * TileSize + q;
    if (t < n)
    {
      staged[t] = splats[values[base + t]];
    }
    __syncthreads();
    if (inside)
    {
      for (int k = 0; k < n; ++k)
      {
        const Splat& sp = staged[k];
        if (i < sp.X0 || i > sp.X1 || j < sp.Y0 || j > sp.Y1)
        {
          continue;
        }
        const float dcx = static_cast<float>(sp.Cx - X0);
        const float dcy = static_cast<float>(sp.Cy - Y0);
        const float dy = r * P2 - dcy;
        const float dx = column + (r * P1 - dcx);
        const float form = AxesForm(sp.Cos, sp.Sin, sp.InvMajor, sp.InvMinor, dx, dy);
        const float value = sp.Weight * FastExp(-0.5f * form);
        acc += form <= sp.CutoffSquared ? value : 0.0f;
        ++evaluations;
      }
    }
    __syncthreads();
  }
  if (inside)
  {
    const std::int64_t p = std::int64_t(j) * s.Width + i;
    if (pieces > 1)
    {
      partials[piece * std::int64_t(s.Width) * s.Height + p] = acc;
    }
    else
    {
      S[p] = acc;
      if (I)
      {
        I[p] = ImageFromScattering(acc, gamma);
      }
    }
  }
  evaluations = WarpSum(evaluations);
  if (((r * TileSize + q) & (WarpSize - 1)) == 0 && evaluations)
  {
    atomicAdd(&counters->Evaluations, evaluations);
  }
}

/// S and I of the pixels of split tiles: their pieces' partial sums added in piece order.
__global__ void CombinePiecesKernel(
  const int* start, const int* end, PreparedSlice s, float gamma, const float* partials, float* S, float* I)
{
  const std::int64_t pixels = std::int64_t(s.Width) * s.Height;
  const std::int64_t p = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (p >= pixels)
  {
    return;
  }
  const int i = static_cast<int>(p % s.Width), j = static_cast<int>(p / s.Width);
  const int tile = (j / TileSize) * s.TilesX + i / TileSize;
  const int pieces = PieceCount(end[tile] - start[tile]);
  if (pieces == 1)
  {
    return;
  }
  float acc = 0;
  for (int k = 0; k < pieces; ++k)
  {
    acc += partials[k * pixels + p];
  }
  S[p] = acc;
  if (I)
  {
    I[p] = ImageFromScattering(acc, gamma);
  }
}
}

void LaunchRaster(int tiles, const Splat* splats, const std::uint32_t* values, const int* start, const int* end,
  const PreparedSlice& s, float gamma, float* S, float* I, float* partials, Counters* counters, cudaStream_t stream)
{
  RasterKernel<<<dim3(tiles, RasterPieces), dim3(TileSize, TileSize), 0, stream>>>(
    splats, values, start, end, s, gamma, S, I, partials, counters);
  constexpr int block = 256;
  CombinePiecesKernel<<<static_cast<unsigned>(Blocks(std::int64_t(s.Width) * s.Height, block)), block, 0, stream>>>(
    start, end, s, gamma, partials, S, I);
}

} // namespace cuda
} // namespace bigus
