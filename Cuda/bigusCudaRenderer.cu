// CUDA backend of the beam-integrated Gaussian renderer (see bigusCudaRenderer.h), host side: device
// buffers, uploads and downloads, the CUB scan and sort, and the order of the kernels, which live one
// file per family behind launchers on device pointers (bigusCudaKernels.h: binning, forward, backward).
#include "bigusCudaRenderer.h"

#include "bigusBackend.h"
#include "bigusCudaDevice.h"
#include "bigusCudaKernels.h"
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
double Now()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

constexpr std::int64_t FieldBytes = 11 * sizeof(float);
constexpr std::int64_t GradientBytes = 12 * sizeof(float) + sizeof(int);
constexpr std::int64_t BinningBytes = sizeof(Splat) + 2 * sizeof(unsigned long long);
constexpr std::int64_t EntryBytes = 4 * sizeof(std::uint32_t); // keys and values, unsorted and sorted
constexpr std::int64_t PixelBytes = 3 * sizeof(float);          // forward S, I; backward S, dL, dL/dS
constexpr std::int64_t PoseBytesPerGaussian = 6 * sizeof(double); // backward with pose gradients: shares

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
      LaunchRaster(tiles, this->Splats.As<Splat>(), this->SortedValues.As<std::uint32_t>(), this->TileStart.As<int>(),
        this->TileEnd.As<int>(), s, static_cast<float>(options.Gamma), this->Image.As<float>(),
        I ? this->Image.As<float>() + pixels : nullptr, this->Count.As<Counters>(), this->Stream);
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
    const bool poses = gradients.SlicePoses != nullptr;
    if (!PrepareSlices(slices, count, options, prepared, error) ||
      !this->UploadField(field, true, prepared, error, poses ? count : 0))
    {
      return false;
    }
    const double t0 = Now();
    const std::int64_t n = field.Count;
    double* poseTotals = this->PoseTotalData.As<double>(); // [count, 6] the slices' pose gradients
    if (poses &&
      !Check(cudaMemsetAsync(poseTotals, 0, sizeof(double) * 6 * count, this->Stream), "clearing pose gradients", error))
    {
      return false;
    }
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
      LaunchScatteringGradient(dS, dG, pixels, gradientIsWithRespectToS, options.Gamma, dGS, this->Stream);
      PoseShares pose = { poses ? this->PoseShareData.As<double>() : nullptr, { 0, 0, 0 } };
      if (poses)
      {
        SliceCentre(s.PixelToPlane, s.Width, s.Height, pose.Pivot);
        if (!Check(cudaMemsetAsync(pose.Shares, 0, sizeof(double) * 6 * n, this->Stream), "clearing pose shares", error))
        {
          return false;
        }
      }
      if (n > 0)
      {
        LaunchBackward(this->Field(n), s, sigmaE, options.Cutoff, options.NonNegativeReflectivity, dGS, out, pose,
          this->Count.As<Counters>(), this->Stream);
        if (poses)
        {
          LaunchPoseShareSum(pose.Shares, n, poseTotals + 6 * k, this->Stream);
        }
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
    std::vector<double> poseGradients(poses ? 6 * std::size_t(count) : 0);
    if (poses &&
      !Check(cudaMemcpyAsync(poseGradients.data(), poseTotals, sizeof(double) * poseGradients.size(),
               cudaMemcpyDeviceToHost, this->Stream),
        "copying pose gradients to the host", error))
    {
      return false;
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
    for (std::size_t c = 0; c < poseGradients.size(); ++c)
    {
      gradients.SlicePoses[c] += poseGradients[c]; // after ReadCounters's synchronisation
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

  /// Checks the memory a call needs, then uploads the field; the counters are reset. A backward call with
  /// @p poseSlices > 0 also holds the pose gradient's buffers (PoseBytesPerGaussian, 6 doubles per slice).
  bool UploadField(const FieldView& field, bool backward, const std::vector<PreparedSlice>& slices, std::string* error,
    int poseSlices = 0)
  {
    const std::int64_t n = field.Count;
    std::int64_t pixels = 1, tiles = 1;
    for (const PreparedSlice& s : slices)
    {
      pixels = std::max(pixels, std::int64_t(s.Width) * s.Height);
      tiles = std::max(tiles, std::int64_t(s.TilesX) * s.TilesY);
    }
    const std::int64_t perGaussian = DeviceBytesPerGaussian(backward) + (poseSlices > 0 ? PoseBytesPerGaussian : 0);
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
    const std::int64_t poseTotalBytes = 6 * std::int64_t(sizeof(double)) * poseSlices;
    const std::int64_t held = this->FieldData.Bytes + this->Image.Bytes +
      (poseSlices > 0 ? this->PoseShareData.Bytes + this->PoseTotalData.Bytes : 0) +
      (backward ? this->Gradients.Bytes
                : this->Splats.Bytes + this->Touched.Bytes + this->TileStart.Bytes + this->TileEnd.Bytes);
    if (!this->Fits(n * perGaussian + pixels * PixelBytes + 2 * tiles * std::int64_t(sizeof(int)) + poseTotalBytes,
          held, what, error) ||
      !this->FieldData.Reserve(std::max<std::int64_t>(1, n) * FieldBytes, "allocating the field", error) ||
      !this->Image.Reserve(3 * pixels * std::int64_t(sizeof(float)), "allocating the image buffers", error) ||
      !this->Count.Reserve(sizeof(Counters), "allocating the counters", error) ||
      (backward && !this->Gradients.Reserve(std::max<std::int64_t>(1, n) * GradientBytes, "allocating gradients", error)) ||
      (poseSlices > 0 &&
        (!this->PoseShareData.Reserve(std::max<std::int64_t>(1, n) * PoseBytesPerGaussian, "allocating pose shares", error) ||
          !this->PoseTotalData.Reserve(poseTotalBytes, "allocating pose gradients", error))) ||
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
    LaunchSetup(this->Field(n), s, sigmaE, options.Cutoff, options.NonNegativeReflectivity, this->Splats.As<Splat>(),
      touched, this->Count.As<Counters>(), this->Stream);
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
    LaunchEmit(this->Splats.As<Splat>(), touched, inclusive, n, s.TilesX, this->Keys.As<std::uint32_t>(),
      this->Values.As<std::uint32_t>(), this->Stream);
    if (!Check(cudaGetLastError(), "binning kernel", error) ||
      !Check(cub::DeviceRadixSort::SortPairs(this->Temporary.Data, sortBytes, this->Keys.As<std::uint32_t>(),
               this->SortedKeys.As<std::uint32_t>(), this->Values.As<std::uint32_t>(),
               this->SortedValues.As<std::uint32_t>(), static_cast<int>(entries), 0, bits, this->Stream),
        "sort by tile", error))
    {
      return false;
    }
    LaunchTileRange(this->SortedKeys.As<std::uint32_t>(), entries, this->TileStart.As<int>(), this->TileEnd.As<int>(),
      this->Stream);
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
  Buffer PoseShareData;  // [N, 6] doubles: each Gaussian's share of one slice's pose gradient
  Buffer PoseTotalData;  // [count, 6] doubles: the slices' pose gradients
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
