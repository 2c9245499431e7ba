// CUDA backend of the beam-integrated Gaussian renderer (see bigusCudaRenderer.h): phase 1 one thread
// per Gaussian, binning by CUB radix sort on the tile id, phase 2 one block per tile, backward one
// warp per Gaussian. The maths is bigusGaussianMath.h and bigusRasterGeometry.h, as on the CPU.
#include "bigusCudaRenderer.h"

#include "bigusBackend.h"
#include "bigusCudaDevice.h"
#include "bigusGaussianMath.h"
#include "bigusRasterGeometry.h"

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <vector>

namespace bigus
{
namespace cuda
{

namespace
{
constexpr int SetupBlock = 256;
constexpr int BackwardBlock = 256; // 8 warps: 8 Gaussians per block
constexpr int WarpSize = 32;
constexpr int RasterThreads = TileSize * TileSize;

double Now()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

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

constexpr std::int64_t FieldBytes = 11 * sizeof(float);
constexpr std::int64_t GradientBytes = 12 * sizeof(float) + sizeof(int);
constexpr std::int64_t BinningBytes = sizeof(Splat) + 2 * sizeof(unsigned long long);
constexpr std::int64_t EntryBytes = 4 * sizeof(std::uint32_t); // keys and values, unsorted and sorted
constexpr std::int64_t PixelBytes = 3 * sizeof(float);          // forward S, I; backward S, dL, dL/dS

// ------------------------------------------------------------------------------------------------
// Kernels.

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
__global__ void EmitKernel(const Splat* splats, const unsigned long long* touched,
  const unsigned long long* inclusive, std::int64_t count, int tilesX, std::uint32_t* keys, std::uint32_t* values)
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

/// Sum of @p v over the warp (integer: exact in any order).
__device__ unsigned long long WarpSum(unsigned long long v)
{
  for (int offset = WarpSize / 2; offset > 0; offset /= 2)
  {
    v += __shfl_down_sync(0xffffffffu, v, offset);
  }
  return v;
}

/**
 * Phase 2: one block per tile, one thread per pixel. The tile's footprints are staged in shared memory
 * RasterThreads at a time and every pixel adds them in Gaussian index order, as the CPU backend does,
 * with offsets relative to the tile's first pixel.
 */
__global__ void RasterKernel(const Splat* splats, const std::uint32_t* values, const int* start,
  const int* end, PreparedSlice s, float gamma, float* S, float* I, Counters* counters)
{
  __shared__ Splat staged[RasterThreads];
  const int tile = blockIdx.x;
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
  const int first = start[tile], last = end[tile];
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
    S[p] = acc;
    if (I)
    {
      I[p] = ImageFromScattering(acc, gamma);
    }
  }
  evaluations = WarpSum(evaluations);
  if (((r * TileSize + q) & (WarpSize - 1)) == 0 && evaluations)
  {
    atomicAdd(&counters->Evaluations, evaluations);
  }
}

/// dL/dS of every pixel: @p dL itself, or dL/dI times dI/dS (in double, as on the CPU).
__global__ void ScatteringGradientKernel(const float* S, const float* dL, std::int64_t pixels, bool withRespectToS,
  double gamma, float* gS)
{
  const std::int64_t p = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (p < pixels)
  {
    gS[p] = withRespectToS ? dL[p] : static_cast<float>(dL[p] * ImageFromScatteringDerivative<double>(S[p], gamma));
  }
}

/**
 * Backward, one warp per Gaussian: every lane sets the footprint up (the same double arithmetic), the
 * lanes share the pixels of its bounding box, each keeps float partial sums of PixelWeightBackward's
 * terms that it flushes into double every few pixels, and a fixed butterfly of shuffles reduces them;
 * lane 0 runs the setup's backward and adds to the Gaussian's gradients, which no other warp touches.
 */
__global__ void BackwardKernel(DeviceField field, PreparedSlice s, double sigmaE, double cutoff, bool nonNegative,
  const float* gS, FieldGradients out, Counters* counters)
{
  const std::int64_t i = (std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x) / WarpSize;
  const int lane = threadIdx.x & (WarpSize - 1);
  if (i >= field.Count)
  {
    return; // the whole warp: i is the same for its 32 lanes
  }
  const GaussianParams g = LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, i);
  const double r = EffectiveReflectivity(g.Reflectivity, nonNegative);
  SetupCache cache;
  const Footprint f = SetupFootprint(g, s.Frame, sigmaE, cutoff, &cache);
  int box[4];
  if (!f.Visible || !FootprintBox(f, s, box))
  {
    return;
  }
  const BoxFootprint fp = MakeBoxFootprint(f, s, box, r);
  const int boxWidth = box[1] - box[0] + 1;
  const std::int64_t boxPixels = std::int64_t(boxWidth) * (box[3] - box[2] + 1);
  double sum[7] = { 0, 0, 0, 0, 0, 0, 0 };
  float part[7] = { 0, 0, 0, 0, 0, 0, 0 };
  int pending = 0;
  for (std::int64_t k = lane; k < boxPixels; k += WarpSize)
  {
    const int row = static_cast<int>(k / boxWidth), col = static_cast<int>(k % boxWidth);
    const float dy = row * fp.P2 - fp.Dcy;
    const float dx = col * fp.P0 + (row * fp.P1 - fp.Dcx);
    const float form = AxesForm(fp.Axes[0], fp.Axes[1], fp.Axes[2], fp.Axes[3], dx, dy);
    if (form <= fp.CutoffSquared)
    {
      const float gv = gS[std::int64_t(box[2] + row) * s.Width + box[0] + col];
      PixelWeightBackward(gv, fp.Weight, FastExp(-0.5f * form), fp.A, fp.B, fp.C, dx, dy, part, 1);
      if (++pending == 8)
      {
        for (int t = 0; t < 7; ++t)
        {
          sum[t] += part[t];
          part[t] = 0;
        }
        pending = 0;
      }
    }
  }
  for (int t = 0; t < 7; ++t)
  {
    sum[t] += part[t];
    for (int offset = WarpSize / 2; offset > 0; offset /= 2)
    {
      sum[t] += __shfl_xor_sync(0xffffffffu, sum[t], offset);
    }
  }
  if (lane != 0)
  {
    return;
  }
  AddGaussianGradients(f, cache, s.Frame, sigmaE, sum, r, g.Reflectivity, nonNegative, out, i);
  if (out.VisibleCount)
  {
    out.VisibleCount[i] += 1;
  }
  atomicAdd(&counters->Visible, 1ull);
  atomicAdd(&counters->Evaluations, static_cast<unsigned long long>(boxPixels));
}

// ------------------------------------------------------------------------------------------------
// Host side.

bool Check(cudaError_t status, const char* what, std::string* error)
{
  if (status == cudaSuccess)
  {
    return true;
  }
  if (error)
  {
    *error = std::string("CUDA renderer: ") + what + ": " + cudaGetErrorString(status);
  }
  return false;
}

/// A device allocation that only grows; freed with the renderer.
struct Buffer
{
  void* Data = nullptr;
  std::int64_t Bytes = 0;
  Buffer() = default;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  ~Buffer() { cudaFree(this->Data); }
  bool Reserve(std::int64_t bytes, const char* what, std::string* error)
  {
    if (bytes <= this->Bytes)
    {
      return true;
    }
    cudaFree(this->Data);
    this->Data = nullptr;
    this->Bytes = 0;
    if (!Check(cudaMalloc(&this->Data, static_cast<std::size_t>(bytes)), what, error))
    {
      return false;
    }
    this->Bytes = bytes;
    return true;
  }
  template <typename T>
  T* As() const
  {
    return static_cast<T*>(this->Data);
  }
};

std::int64_t Blocks(std::int64_t threads, int block)
{
  return (threads + block - 1) / block;
}

class CudaRenderer : public Renderer
{
public:
  CudaRenderer() = default;
  ~CudaRenderer() override
  {
    if (this->Stream)
    {
      cudaStreamDestroy(this->Stream);
    }
  }

  bool Initialize(std::string* error) { return Check(cudaStreamCreate(&this->Stream), "cudaStreamCreate", error); }

  const char* GetName() const override { return "cuda"; }

  bool Forward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    float* S, float* I, RenderStats* stats, std::string* error) override
  {
    std::vector<PreparedSlice> prepared;
    if (!PrepareSlices(slices, count, options, prepared, error) || !this->UploadField(field, false, prepared, error))
    {
      return false;
    }
    const double sigmaE = EffectiveElevationSigma(options);
    std::int64_t offset = 0;
    for (int k = 0; k < count; ++k)
    {
      const PreparedSlice& s = prepared[k];
      const std::int64_t pixels = std::int64_t(s.Width) * s.Height;
      const double t0 = Now();
      std::int64_t entries = 0;
      if (!this->Bin(s, sigmaE, options, entries, error))
      {
        return false;
      }
      const double t1 = Now();
      const int tiles = s.TilesX * s.TilesY;
      RasterKernel<<<tiles, dim3(TileSize, TileSize), 0, this->Stream>>>(this->Splats.As<Splat>(),
        this->SortedValues.As<std::uint32_t>(), this->TileStart.As<int>(), this->TileEnd.As<int>(), s,
        static_cast<float>(options.Gamma), this->Image.As<float>(), I ? this->Image.As<float>() + pixels : nullptr,
        this->Count.As<Counters>());
      Counters counters;
      if (!Check(cudaGetLastError(), "raster kernel", error) ||
        !Check(cudaMemcpyAsync(S + offset, this->Image.Data, sizeof(float) * pixels, cudaMemcpyDeviceToHost,
                 this->Stream),
          "copying S to the host", error) ||
        (I &&
          !Check(cudaMemcpyAsync(I + offset, this->Image.As<float>() + pixels, sizeof(float) * pixels,
                   cudaMemcpyDeviceToHost, this->Stream),
            "copying I to the host", error)) ||
        !this->ReadCounters(counters, "raster", error))
      {
        return false;
      }
      if (stats)
      {
        stats->GaussiansVisible += static_cast<std::int64_t>(counters.Visible);
        stats->TileEntries += entries;
        stats->PixelEvaluations += static_cast<std::int64_t>(counters.Evaluations);
        stats->SetupSeconds += t1 - t0;
        stats->RasterSeconds += Now() - t1;
      }
      offset += pixels;
    }
    return true;
  }

  bool Backward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    const float* S, const float* dL, bool gradientIsWithRespectToS, FieldGradients& gradients, RenderStats* stats,
    std::string* error) override
  {
    std::vector<PreparedSlice> prepared;
    if (!PrepareSlices(slices, count, options, prepared, error) || !this->UploadField(field, true, prepared, error))
    {
      return false;
    }
    const double t0 = Now();
    const std::int64_t n = field.Count;
    // The gradients accumulate (+=) into what the caller holds, in the same order as on the CPU.
    float* base = this->Gradients.As<float>();
    const GradientSlot slots[] = { { gradients.Means, 3, 0 }, { gradients.LogScales, 3, 3 },
      { gradients.Quaternions, 4, 6 }, { gradients.Reflectivities, 1, 10 }, { gradients.Attribution, 1, 11 } };
    FieldGradients out; // device pointers: [N, 3] means, [N, 3] log-scales, [N, 4] quaternions, [N] r, E, counts
    float** outputs[] = { &out.Means, &out.LogScales, &out.Quaternions, &out.Reflectivities, &out.Attribution };
    for (int k = 0; k < 5; ++k)
    {
      if (slots[k].Host)
      {
        *outputs[k] = base + slots[k].Offset * n;
        if (!Check(cudaMemcpyAsync(*outputs[k], slots[k].Host, sizeof(float) * slots[k].Width * n,
                     cudaMemcpyHostToDevice, this->Stream),
              "copying gradients to the device", error))
        {
          return false;
        }
      }
    }
    if (gradients.VisibleCount)
    {
      out.VisibleCount = reinterpret_cast<int*>(base + 12 * n);
      if (!Check(cudaMemcpyAsync(out.VisibleCount, gradients.VisibleCount, sizeof(int) * n, cudaMemcpyHostToDevice,
                   this->Stream),
            "copying visibility counts to the device", error))
      {
        return false;
      }
    }
    const double sigmaE = EffectiveElevationSigma(options);
    std::int64_t offset = 0;
    for (int k = 0; k < count; ++k)
    {
      const PreparedSlice& s = prepared[k];
      const std::int64_t pixels = std::int64_t(s.Width) * s.Height;
      float* dS = this->Image.As<float>();   // [H, W] S of the slice
      float* dG = dS + pixels;               // [H, W] dL of the slice
      float* dGS = dS + 2 * pixels;          // [H, W] dL/dS
      if (!Check(cudaMemcpyAsync(dS, S + offset, sizeof(float) * pixels, cudaMemcpyHostToDevice, this->Stream),
            "copying S to the device", error) ||
        !Check(cudaMemcpyAsync(dG, dL + offset, sizeof(float) * pixels, cudaMemcpyHostToDevice, this->Stream),
          "copying dL to the device", error))
      {
        return false;
      }
      ScatteringGradientKernel<<<Blocks(pixels, SetupBlock), SetupBlock, 0, this->Stream>>>(
        dS, dG, pixels, gradientIsWithRespectToS, options.Gamma, dGS);
      if (n > 0)
      {
        BackwardKernel<<<Blocks(n * WarpSize, BackwardBlock), BackwardBlock, 0, this->Stream>>>(this->Field(n), s,
          sigmaE, options.Cutoff, options.NonNegativeReflectivity, dGS, out, this->Count.As<Counters>());
      }
      if (!Check(cudaGetLastError(), "backward kernel", error))
      {
        return false;
      }
      offset += pixels;
    }
    for (int k = 0; k < 5; ++k)
    {
      if (slots[k].Host &&
        !Check(cudaMemcpyAsync(slots[k].Host, *outputs[k], sizeof(float) * slots[k].Width * n, cudaMemcpyDeviceToHost,
                 this->Stream),
          "copying gradients to the host", error))
      {
        return false;
      }
    }
    Counters counters;
    if ((gradients.VisibleCount &&
          !Check(cudaMemcpyAsync(gradients.VisibleCount, out.VisibleCount, sizeof(int) * n, cudaMemcpyDeviceToHost,
                   this->Stream),
            "copying visibility counts to the host", error)) ||
      !this->ReadCounters(counters, "backward", error))
    {
      return false;
    }
    if (stats)
    {
      stats->GaussiansVisible += static_cast<std::int64_t>(counters.Visible);
      stats->PixelEvaluations += static_cast<std::int64_t>(counters.Evaluations);
      stats->RasterSeconds += Now() - t0;
    }
    return true;
  }

private:
  struct GradientSlot
  {
    float* Host;
    int Width;  // floats per Gaussian
    int Offset; // in units of N floats inside Gradients
  };

  DeviceField Field(std::int64_t n) const
  {
    const float* base = this->FieldData.As<float>();
    return DeviceField{ base, base + 3 * n, base + 6 * n, base + 10 * n, n };
  }

  /**
   * Refuses, before allocating, a call whose buffers do not fit: @p bytes in the buffers @p reused
   * (which hold @p held bytes already and are reallocated if too small) against those plus the
   * device's free memory.
   */
  bool Fits(std::int64_t bytes, std::int64_t held, const std::string& what, std::string* error) const
  {
    std::size_t freeBytes = 0, totalBytes = 0;
    if (!Check(cudaMemGetInfo(&freeBytes, &totalBytes), "cudaMemGetInfo", error))
    {
      return false;
    }
    if (bytes <= held + static_cast<std::int64_t>(freeBytes))
    {
      return true;
    }
    if (error)
    {
      const double MiB = 1024.0 * 1024.0;
      char text[320];
      std::snprintf(text, sizeof(text),
        "CUDA renderer: %s need %.1f MiB of device memory; the device has %.1f MiB free and this renderer holds "
        "%.1f MiB for them (of %.1f MiB in all); render fewer Gaussians or smaller slices, or use the cpu backend",
        what.c_str(), bytes / MiB, freeBytes / MiB, held / MiB, totalBytes / MiB);
      *error = text;
    }
    return false;
  }

  /// Checks the memory a call needs, then uploads the field; the counters are reset.
  bool UploadField(const FieldView& field, bool backward, const std::vector<PreparedSlice>& slices, std::string* error)
  {
    const std::int64_t n = field.Count;
    std::int64_t pixels = 1, tiles = 1;
    for (const PreparedSlice& s : slices)
    {
      pixels = std::max(pixels, std::int64_t(s.Width) * s.Height);
      tiles = std::max(tiles, std::int64_t(s.TilesX) * s.TilesY);
    }
    const std::int64_t perGaussian = DeviceBytesPerGaussian(backward);
    const std::string what = "a field of " + std::to_string(n) + " Gaussians and slices of " + std::to_string(pixels) +
      " pixels";
    if (n >= (std::int64_t(1) << 31))
    {
      if (error)
      {
        *error = "CUDA renderer: " + what + ": at most 2^31 - 1 Gaussians are supported";
      }
      return false;
    }
    const std::int64_t held = this->FieldData.Bytes + this->Image.Bytes +
      (backward ? this->Gradients.Bytes
                : this->Splats.Bytes + this->Touched.Bytes + this->TileStart.Bytes + this->TileEnd.Bytes);
    if (!this->Fits(n * perGaussian + pixels * PixelBytes + 2 * tiles * std::int64_t(sizeof(int)), held, what, error) ||
      !this->FieldData.Reserve(std::max<std::int64_t>(1, n) * FieldBytes, "allocating the field", error) ||
      !this->Image.Reserve(3 * pixels * std::int64_t(sizeof(float)), "allocating the image buffers", error) ||
      !this->Count.Reserve(sizeof(Counters), "allocating the counters", error) ||
      (backward && !this->Gradients.Reserve(std::max<std::int64_t>(1, n) * GradientBytes, "allocating gradients", error)) ||
      (!backward &&
        (!this->Splats.Reserve(std::max<std::int64_t>(1, n) * std::int64_t(sizeof(Splat)), "allocating footprints",
           error) ||
          !this->Touched.Reserve(2 * std::max<std::int64_t>(1, n) * std::int64_t(sizeof(unsigned long long)),
            "allocating tile counts", error) ||
          !this->TileStart.Reserve(tiles * std::int64_t(sizeof(int)), "allocating tile ranges", error) ||
          !this->TileEnd.Reserve(tiles * std::int64_t(sizeof(int)), "allocating tile ranges", error))))
    {
      return false;
    }
    this->FieldCount = n;
    float* base = this->FieldData.As<float>();
    const struct
    {
      const float* Host;
      std::int64_t Floats;
      std::int64_t Offset;
    } parts[] = { { field.Means, 3 * n, 0 }, { field.LogScales, 3 * n, 3 * n }, { field.Quaternions, 4 * n, 6 * n },
      { field.Reflectivities, n, 10 * n } };
    for (const auto& part : parts)
    {
      if (n > 0 &&
        !Check(cudaMemcpyAsync(base + part.Offset, part.Host, sizeof(float) * part.Floats, cudaMemcpyHostToDevice,
                 this->Stream),
          "copying the field to the device", error))
      {
        return false;
      }
    }
    return Check(cudaMemsetAsync(this->Count.Data, 0, sizeof(Counters), this->Stream), "clearing counters", error);
  }

  /// Copies the counters to the host after the work queued so far and waits for it (@p what names it).
  bool ReadCounters(Counters& counters, const char* what, std::string* error)
  {
    return Check(cudaMemcpyAsync(&counters, this->Count.Data, sizeof(Counters), cudaMemcpyDeviceToHost, this->Stream),
             "copying the counters", error) &&
      Check(cudaStreamSynchronize(this->Stream), what, error);
  }

  /// Phase 1 and the binning of one slice: footprints, (tile, Gaussian) pairs sorted by tile, tile ranges.
  bool Bin(const PreparedSlice& s, double sigmaE, const RenderOptions& options, std::int64_t& entries, std::string* error)
  {
    const std::int64_t n = this->FieldCount;
    const int tiles = s.TilesX * s.TilesY;
    unsigned long long* touched = this->Touched.As<unsigned long long>();
    unsigned long long* inclusive = touched + std::max<std::int64_t>(1, n);
    if (!Check(cudaMemsetAsync(this->Count.Data, 0, sizeof(Counters), this->Stream), "clearing counters", error) ||
      !Check(cudaMemsetAsync(this->TileStart.Data, 0, sizeof(int) * tiles, this->Stream), "clearing tiles", error) ||
      !Check(cudaMemsetAsync(this->TileEnd.Data, 0, sizeof(int) * tiles, this->Stream), "clearing tiles", error))
    {
      return false;
    }
    entries = 0;
    if (n == 0)
    {
      return true;
    }
    SetupKernel<<<Blocks(n, SetupBlock), SetupBlock, 0, this->Stream>>>(this->Field(n), s, sigmaE, options.Cutoff,
      options.NonNegativeReflectivity, this->Splats.As<Splat>(), touched, this->Count.As<Counters>());
    std::size_t scanBytes = 0;
    if (!Check(cudaGetLastError(), "setup kernel", error) ||
      !Check(cub::DeviceScan::InclusiveSum(nullptr, scanBytes, touched, inclusive, n, this->Stream), "scan size", error) ||
      !this->Temporary.Reserve(static_cast<std::int64_t>(scanBytes), "allocating the scan", error) ||
      !Check(cub::DeviceScan::InclusiveSum(this->Temporary.Data, scanBytes, touched, inclusive, n, this->Stream),
        "scan of tile counts", error))
    {
      return false;
    }
    unsigned long long total = 0;
    if (!Check(cudaMemcpyAsync(&total, inclusive + n - 1, sizeof(total), cudaMemcpyDeviceToHost, this->Stream),
          "copying the entry count", error) ||
      !Check(cudaStreamSynchronize(this->Stream), "setup", error))
    {
      return false;
    }
    entries = static_cast<std::int64_t>(total);
    if (entries == 0)
    {
      return true;
    }
    if (entries >= (std::int64_t(1) << 31))
    {
      if (error)
      {
        *error = "CUDA renderer: " + std::to_string(entries) + " (tile, Gaussian) entries on one slice; at most 2^31 - 1";
      }
      return false;
    }
    int bits = 1;
    while ((1 << bits) < tiles)
    {
      ++bits;
    }
    std::size_t sortBytes = 0;
    if (!Check(cub::DeviceRadixSort::SortPairs(nullptr, sortBytes, this->Keys.As<std::uint32_t>(),
                 this->SortedKeys.As<std::uint32_t>(), this->Values.As<std::uint32_t>(),
                 this->SortedValues.As<std::uint32_t>(), static_cast<int>(entries), 0, bits, this->Stream),
          "sort size", error) ||
      !this->Fits(entries * EntryBytes + static_cast<std::int64_t>(sortBytes),
        this->Keys.Bytes + this->SortedKeys.Bytes + this->Values.Bytes + this->SortedValues.Bytes + this->Temporary.Bytes,
        "the " + std::to_string(entries) + " (tile, Gaussian) entries of one slice", error))
    {
      return false;
    }
    const std::int64_t entryBytes = entries * std::int64_t(sizeof(std::uint32_t));
    if (!this->Keys.Reserve(entryBytes, "allocating tile entries", error) ||
      !this->SortedKeys.Reserve(entryBytes, "allocating tile entries", error) ||
      !this->Values.Reserve(entryBytes, "allocating tile entries", error) ||
      !this->SortedValues.Reserve(entryBytes, "allocating tile entries", error) ||
      !this->Temporary.Reserve(static_cast<std::int64_t>(sortBytes), "allocating the sort", error))
    {
      return false;
    }
    EmitKernel<<<Blocks(n, SetupBlock), SetupBlock, 0, this->Stream>>>(this->Splats.As<Splat>(), touched,
      inclusive, n, s.TilesX, this->Keys.As<std::uint32_t>(), this->Values.As<std::uint32_t>());
    if (!Check(cudaGetLastError(), "binning kernel", error) ||
      !Check(cub::DeviceRadixSort::SortPairs(this->Temporary.Data, sortBytes, this->Keys.As<std::uint32_t>(),
               this->SortedKeys.As<std::uint32_t>(), this->Values.As<std::uint32_t>(),
               this->SortedValues.As<std::uint32_t>(), static_cast<int>(entries), 0, bits, this->Stream),
        "sort by tile", error))
    {
      return false;
    }
    TileRangeKernel<<<Blocks(entries, SetupBlock), SetupBlock, 0, this->Stream>>>(
      this->SortedKeys.As<std::uint32_t>(), entries, this->TileStart.As<int>(), this->TileEnd.As<int>());
    return Check(cudaGetLastError(), "tile range kernel", error);
  }

  cudaStream_t Stream = nullptr;
  std::int64_t FieldCount = 0;
  Buffer FieldData;    // [N, 11] floats: means [N, 3], log-scales [N, 3], quaternions [N, 4], reflectivities [N]
  Buffer Gradients;    // [N, 12] floats + [N] ints: as FieldData, then attribution [N], visible counts [N]
  Buffer Splats;       // [N] Splat
  Buffer Touched;      // [2, N] unsigned long long: tiles touched, their inclusive scan
  Buffer Image;        // [3, H, W] floats: forward S, I; backward S, dL, dL/dS
  Buffer TileStart;    // [tiles] int
  Buffer TileEnd;      // [tiles] int
  Buffer Keys;         // [E] tile id
  Buffer SortedKeys;   // [E]
  Buffer Values;       // [E] Gaussian index
  Buffer SortedValues; // [E]
  Buffer Temporary;    // CUB's scratch space
  Buffer Count;        // Counters
};

std::unique_ptr<Renderer> MakeCudaRenderer(std::string* error)
{
  return CreateCudaRenderer(error);
}
} // namespace

std::int64_t DeviceBytesPerGaussian(bool backward)
{
  return FieldBytes + (backward ? GradientBytes : BinningBytes);
}

std::int64_t DeviceBytesPerPixel()
{
  return PixelBytes;
}

std::int64_t DeviceBytesPerTileEntry()
{
  return EntryBytes;
}

std::unique_ptr<Renderer> CreateCudaRenderer(std::string* error)
{
  DeviceInfo info;
  std::string why;
  if (!QueryDevice(info, why))
  {
    if (error)
    {
      *error = why;
    }
    return nullptr;
  }
  std::unique_ptr<CudaRenderer> renderer(new CudaRenderer);
  if (!renderer->Initialize(error))
  {
    return nullptr;
  }
  return renderer;
}
} // namespace cuda
} // namespace bigus

/**
 * Called once by the backend registry when it loads this library (bigusBackend.cxx): registers "cuda"
 * above "cpu" where a usable device exists, and otherwise records why not, so that asking for "cuda"
 * says so and "auto" quietly stays on the CPU. A device-resident training engine would register here too
 * (bigus::RegisterTrainingEngine("cuda", ...), bigusTrainingEngine.h); until one exists the CPU engine
 * trains over this renderer.
 */
extern "C" BIGUSCUDA_EXPORT void bigusCudaRegisterBackend()
{
  bigus::cuda::DeviceInfo info;
  std::string why;
  if (bigus::cuda::QueryDevice(info, why))
  {
    bigus::RegisterBackend("cuda", &bigus::cuda::MakeCudaRenderer, 10);
  }
  else
  {
    bigus::RegisterUnavailableBackend("cuda", why);
  }
}
