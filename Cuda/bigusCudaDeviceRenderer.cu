// The CUDA renderer on device buffers (see bigusCudaDeviceRenderer.h): binning with CUB, the order of
// the kernels of a slice's forward and backward pass, and the device memory checks.
#include "bigusCudaDeviceRenderer.h"

#include "bigusCudaDevice.h"
#include "bigusRasterGeometry.h"

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <chrono>
#include <cstdio>

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
}

bool DeviceUsable(std::string* error)
{
  DeviceInfo info;
  std::string why;
  if (QueryDevice(info, why))
  {
    return true;
  }
  if (error)
  {
    *error = why;
  }
  return false;
}

CallExtent Extent(std::int64_t gaussians, const std::vector<PreparedSlice>& slices)
{
  CallExtent e;
  for (const PreparedSlice& s : slices)
  {
    e.Pixels = std::max(e.Pixels, std::int64_t(s.Width) * s.Height);
    e.Tiles = std::max(e.Tiles, std::int64_t(s.TilesX) * s.TilesY);
  }
  e.What =
    "a field of " + std::to_string(gaussians) + " Gaussians and slices of " + std::to_string(e.Pixels) + " pixels";
  return e;
}

bool UploadField(const FieldView& field, float* device, cudaStream_t stream, std::string* error)
{
  const std::int64_t n = field.Count;
  const float* arrays[FieldGroups] = { field.Means, field.LogScales, field.Quaternions, field.Reflectivities };
  for (int q = 0; q < FieldGroups && n > 0; ++q)
  {
    if (!Check(cudaMemcpyAsync(device + FieldGroupFirst(q) * n, arrays[q], sizeof(float) * FieldGroupWidth(q) * n,
                 cudaMemcpyHostToDevice, stream),
          "copying the field to the device", error))
    {
      return false;
    }
  }
  return true;
}

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

Buffer::~Buffer()
{
  cudaFree(this->Data);
}

bool Buffer::Reserve(std::int64_t bytes, const char* what, std::string* error)
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

DeviceRenderer::~DeviceRenderer()
{
  if (this->Stream)
  {
    cudaStreamDestroy(this->Stream);
  }
}

bool DeviceRenderer::Initialize(std::string* error)
{
  return Check(cudaStreamCreate(&this->Stream), "cudaStreamCreate", error) &&
    this->Count.Reserve(2 * sizeof(Counters), "allocating the counters", error) &&
    Check(cudaMemsetAsync(this->Count.Data, 0, 2 * sizeof(Counters), this->Stream), "clearing counters", error);
}

bool DeviceRenderer::Fits(std::int64_t bytes, std::int64_t held, const std::string& what, std::string* error) const
{
  if (bytes <= held)
  {
    return true; // what is held already covers it: no query of the device (a training step asks several times)
  }
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

bool DeviceRenderer::Reserve(bool backward, bool poses, std::int64_t n, std::int64_t tiles, std::int64_t ownBytes,
  std::int64_t ownHeld, const std::string& what, std::string* error)
{
  const std::int64_t slots = std::max<std::int64_t>(1, n);
  // Phase 2's partial sums: RasterPieces floats per pixel of the slice's tiles.
  const std::int64_t partialBytes = tiles * std::int64_t(RasterPieces) * RasterThreads * std::int64_t(sizeof(float));
  const std::int64_t bytes = backward ? (poses ? n * PoseBytesPerGaussian : 0)
                                      : n * BinningBytes + 2 * tiles * std::int64_t(sizeof(int)) + partialBytes;
  const std::int64_t held = backward
    ? (poses ? this->PoseShareData.Bytes : 0)
    : this->Splats.Bytes + this->Touched.Bytes + this->TileStart.Bytes + this->TileEnd.Bytes + this->Partials.Bytes;
  if (!this->Fits(ownBytes + bytes, ownHeld + held, what, error))
  {
    return false;
  }
  if (backward)
  {
    return !poses || this->PoseShareData.Reserve(slots * PoseBytesPerGaussian, "allocating pose shares", error);
  }
  return this->Splats.Reserve(slots * std::int64_t(sizeof(Splat)), "allocating footprints", error) &&
    this->Touched.Reserve(2 * slots * std::int64_t(sizeof(unsigned long long)), "allocating tile counts", error) &&
    this->TileStart.Reserve(tiles * std::int64_t(sizeof(int)), "allocating tile ranges", error) &&
    this->TileEnd.Reserve(tiles * std::int64_t(sizeof(int)), "allocating tile ranges", error) &&
    this->Partials.Reserve(partialBytes, "allocating the raster's partial sums", error);
}

bool DeviceRenderer::ReadCounters(Counters& counters, const char* what, std::string* error)
{
  return Check(cudaMemcpyAsync(&counters, this->Count.Data, sizeof(Counters), cudaMemcpyDeviceToHost, this->Stream),
           "copying the counters", error) &&
    Check(cudaStreamSynchronize(this->Stream), what, error);
}

bool DeviceRenderer::Forward(const DeviceField& field, const PreparedSlice& s, const RenderOptions& options, float* S,
  float* I, RenderStats* stats, std::string* error)
{
  const double t0 = Now();
  std::int64_t entries = 0;
  if (!this->Bin(field, s, EffectiveElevationSigma(options), options, entries, error))
  {
    return false;
  }
  const double t1 = Now();
  LaunchRaster(s.TilesX * s.TilesY, this->Splats.As<Splat>(), this->SortedValues.As<std::uint32_t>(),
    this->TileStart.As<int>(), this->TileEnd.As<int>(), s, static_cast<float>(options.Gamma), S, I,
    this->Partials.As<float>(), this->Count.As<Counters>(), this->Stream);
  if (!Check(cudaGetLastError(), "raster kernel", error))
  {
    return false;
  }
  // The counters are read (a wait for the stream) only for statistics: a training step's or a solve's next work
  // follows on the same stream, and their copies to the host wait for it there.
  if (stats)
  {
    Counters counters;
    if (!this->ReadCounters(counters, "raster", error))
    {
      return false;
    }
    stats->GaussiansVisible += static_cast<std::int64_t>(counters.Visible);
    stats->TileEntries += entries;
    stats->PixelEvaluations += static_cast<std::int64_t>(counters.Evaluations);
    stats->SetupSeconds += t1 - t0;
    stats->RasterSeconds += Now() - t1;
  }
  return true;
}

bool DeviceRenderer::Backward(const DeviceField& field, const PreparedSlice& s, const RenderOptions& options,
  const float* S, const float* dL, bool withRespectToS, float* scratch, FieldGradients out, double* poseTotal,
  std::string* error)
{
  const std::int64_t n = field.Count;
  LaunchScatteringGradient(
    S, dL, std::int64_t(s.Width) * s.Height, withRespectToS, options.Gamma, scratch, this->Stream);
  PoseShares pose = { poseTotal ? this->PoseShareData.As<double>() : nullptr, { 0, 0, 0 } };
  if (poseTotal)
  {
    SliceCentre(s.PixelToPlane, s.Width, s.Height, pose.Pivot);
    if (!Check(cudaMemsetAsync(pose.Shares, 0, sizeof(double) * 6 * n, this->Stream), "clearing pose shares", error))
    {
      return false;
    }
  }
  if (n > 0)
  {
    LaunchBackward(field, s, EffectiveElevationSigma(options), options.Cutoff, options.NonNegativeReflectivity, scratch,
      out, pose, this->Count.As<Counters>() + 1, this->Stream);
    if (poseTotal)
    {
      LaunchPoseShareSum(pose.Shares, n, poseTotal, this->Stream);
    }
  }
  return Check(cudaGetLastError(), "backward kernel", error);
}

bool DeviceRenderer::Synchronize(RenderStats* stats, const char* what, std::string* error)
{
  Counters counters;
  Counters* backward = this->Count.As<Counters>() + 1;
  if (!Check(cudaMemcpyAsync(&counters, backward, sizeof(Counters), cudaMemcpyDeviceToHost, this->Stream),
        "copying the counters", error) ||
    !Check(cudaMemsetAsync(backward, 0, sizeof(Counters), this->Stream), "clearing counters", error) ||
    !Check(cudaStreamSynchronize(this->Stream), what, error))
  {
    return false;
  }
  if (stats)
  {
    stats->GaussiansVisible += static_cast<std::int64_t>(counters.Visible);
    stats->PixelEvaluations += static_cast<std::int64_t>(counters.Evaluations);
  }
  return true;
}

bool DeviceRenderer::Bin(const DeviceField& field, const PreparedSlice& s, double sigmaE, const RenderOptions& options,
  std::int64_t& entries, std::string* error)
{
  const std::int64_t n = field.Count;
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
  LaunchSetup(field, s, sigmaE, options.Cutoff, options.NonNegativeReflectivity, this->Splats.As<Splat>(), touched,
    this->Count.As<Counters>(), this->Stream);
  std::size_t scanBytes = 0;
  if (!Check(cudaGetLastError(), "setup kernel", error) ||
    !Check(
      cub::DeviceScan::InclusiveSum(nullptr, scanBytes, touched, inclusive, n, this->Stream), "scan size", error) ||
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
  LaunchTileRange(
    this->SortedKeys.As<std::uint32_t>(), entries, this->TileStart.As<int>(), this->TileEnd.As<int>(), this->Stream);
  return Check(cudaGetLastError(), "tile range kernel", error);
}

} // namespace cuda
} // namespace bigus
