// The reflectivity basis assembled on the device (see bigusCudaAssembledBasis.h).
#include "bigusCudaAssembledBasis.h"

#include "bigusGaussianMath.h"
#include "bigusRasterGeometry.h"

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <cstdio>
#include <utility>

namespace bigus
{
namespace cuda
{

namespace
{
constexpr int BasisBlock = 256;            // 8 warps: 8 Gaussians per block of the assembly and the column products
constexpr unsigned FullWarp = 0xffffffffu; // every lane of a warp
constexpr std::int64_t Limit32 = (std::int64_t(1) << 32) - 1;

/**
 * The assembly's two passes, one warp per Gaussian: each visible footprint's box pixels inside the cut-off ellipse in
 * slice, row and column order (the backward kernel's pixels and float weight at reflectivity 1). Counting
 * (@p Fill false): the column's entries into @p columnCounts [N] and each pixel's into @p pixelCounts [P] (integer
 * atomics: the same counts on every run). Filling: the entries at @p columnOffsets [N + 1], the column's (pixel,
 * weight) into @p pixels and @p weights, the sort's keys (the pixel) and values (Gaussian << 32 | weight bits) beside
 * them.
 */
template <bool Fill>
__global__ void FootprintEntriesKernel(DeviceField field, const PreparedSlice* slices, int count, double sigmaE,
  double cutoff, unsigned long long* columnCounts, unsigned* pixelCounts, const unsigned long long* columnOffsets,
  unsigned* pixels, float* weights, unsigned* keys, unsigned long long* values)
{
  const std::int64_t i = (std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x) / WarpSize;
  const int lane = threadIdx.x & (WarpSize - 1);
  if (i >= field.Count)
  {
    return; // the whole warp
  }
  const GaussianParams g = LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, i);
  const Reach reach = ReachOf(field, i);
  const unsigned below = (1u << lane) - 1; // the lanes before this one
  unsigned long long at = Fill ? columnOffsets[i] : 0;
  for (int j = 0; j < count; ++j)
  {
    const PreparedSlice& s = slices[j];
    if (OutOfReach(reach, s, sigmaE, cutoff))
    {
      continue;
    }
    const Footprint f = SetupFootprint(g, s.Frame, sigmaE, cutoff, nullptr);
    int box[4];
    if (!f.Visible || !FootprintBox(f, s, box))
    {
      continue;
    }
    const BoxFootprint fp = MakeBoxFootprint(f, s, box, 1.0);
    const int boxWidth = box[1] - box[0] + 1;
    const std::int64_t boxPixels = std::int64_t(boxWidth) * (box[3] - box[2] + 1);
    const unsigned first = static_cast<unsigned>(j) * static_cast<unsigned>(s.Width * s.Height);
    for (std::int64_t k0 = 0; k0 < boxPixels; k0 += WarpSize)
    {
      const std::int64_t k = k0 + lane;
      bool inside = false;
      float w = 0;
      unsigned pixel = 0;
      if (k < boxPixels)
      {
        const int row = static_cast<int>(k / boxWidth), col = static_cast<int>(k % boxWidth);
        const float dy = row * fp.P2 - fp.Dcy;
        const float dx = col * fp.P0 + (row * fp.P1 - fp.Dcx);
        const float form = AxesForm(fp.Axes[0], fp.Axes[1], fp.Axes[2], fp.Axes[3], dx, dy);
        inside = form <= fp.CutoffSquared;
        w = fp.Weight * FastExp(-0.5f * form);
        pixel = first + static_cast<unsigned>(box[2] + row) * static_cast<unsigned>(s.Width) +
          static_cast<unsigned>(box[0] + col);
      }
      const unsigned mask = __ballot_sync(FullWarp, inside);
      if (inside)
      {
        if (Fill)
        {
          const unsigned long long e = at + __popc(mask & below);
          pixels[e] = pixel;
          weights[e] = w;
          keys[e] = pixel;
          values[e] = (static_cast<unsigned long long>(i) << 32) | __float_as_uint(w);
        }
        else
        {
          atomicAdd(pixelCounts + pixel, 1u);
        }
      }
      at += __popc(mask);
    }
  }
  if (!Fill && lane == 0)
  {
    columnCounts[i] = at;
  }
}

/// A r: pixel p sums its row's weights times @p r in Gaussian order, in double.
__global__ void RowProductKernel(
  const unsigned* rowOffsets, const unsigned long long* rowEntries, std::int64_t pixels, const float* r, float* S)
{
  const std::int64_t p = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (p >= pixels)
  {
    return;
  }
  double sum = 0;
  for (unsigned e = rowOffsets[p]; e < rowOffsets[p + 1]; ++e)
  {
    const unsigned long long entry = rowEntries[e];
    sum += double(__uint_as_float(static_cast<unsigned>(entry))) * r[entry >> 32];
  }
  S[p] = static_cast<float>(sum);
}

/// A^T y (@p Squared false) or diag(A^T W A) (true), one warp per Gaussian: each lane a fixed stride of the column's
/// entries in double, then a fixed butterfly of shuffles; @p out [N] is overwritten.
template <bool Squared>
__global__ void ColumnProductKernel(const unsigned long long* columnOffsets, const unsigned* pixels,
  const float* weights, std::int64_t n, const float* y, double* out)
{
  const std::int64_t i = (std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x) / WarpSize;
  const int lane = threadIdx.x & (WarpSize - 1);
  if (i >= n)
  {
    return;
  }
  double sum = 0;
  for (unsigned long long e = columnOffsets[i] + lane; e < columnOffsets[i + 1]; e += WarpSize)
  {
    const double w = weights[e];
    sum += double(y[pixels[e]]) * (Squared ? w * w : w);
  }
  for (int offset = WarpSize / 2; offset > 0; offset /= 2)
  {
    sum += __shfl_xor_sync(FullWarp, sum, offset);
  }
  if (lane == 0)
  {
    out[i] = sum;
  }
}

void SwapBuffers(Buffer& a, Buffer& b)
{
  std::swap(a.Data, b.Data);
  std::swap(a.Bytes, b.Bytes);
}

bool TooLarge(const char* text, std::string* error, bool* tooLarge)
{
  *tooLarge = true;
  if (error)
  {
    *error = text;
  }
  return false;
}
}

std::int64_t DeviceBasis::PersistentBytes() const
{
  return this->ColumnOffsets.Bytes + this->ColumnPixels.Bytes + this->ColumnWeights.Bytes + this->RowOffsets.Bytes +
    this->RowEntries.Bytes + this->Vector.Bytes;
}

bool DeviceBasis::Assemble(const DeviceField& field, const std::vector<PreparedSlice>& slices, double sigmaE,
  double cutoff, std::int64_t maximumBytes, const DeviceRenderer& device, std::string* error, bool* tooLarge)
{
  *tooLarge = false;
  const cudaStream_t stream = device.GetStream();
  const std::int64_t n = field.Count;
  const int count = static_cast<int>(slices.size());
  const std::int64_t sliceSize = slices.empty() ? 0 : std::int64_t(slices[0].Width) * slices[0].Height;
  for (const PreparedSlice& s : slices)
  {
    if (std::int64_t(s.Width) * s.Height != sliceSize)
    {
      return TooLarge("slices of different sizes", error, tooLarge);
    }
  }
  const std::int64_t pixels = sliceSize * count;
  if (pixels > Limit32 || n > Limit32)
  {
    return TooLarge("more than 2^32 - 1 pixels", error, tooLarge);
  }
  // Counting: the columns' and the pixels' counts, then their scans.
  Buffer slicesOnDevice, columnCounts, pixelCounts, temporary;
  const std::int64_t countingBytes = count * std::int64_t(sizeof(PreparedSlice)) +
    (2 * n + 1) * std::int64_t(sizeof(unsigned long long)) + (2 * pixels + 1) * std::int64_t(sizeof(unsigned)) +
    pixels * std::int64_t(sizeof(float));
  std::size_t scanBytes = 0, rowScanBytes = 0;
  if (!Check(cub::DeviceScan::InclusiveSum(nullptr, scanBytes, static_cast<unsigned long long*>(nullptr),
               static_cast<unsigned long long*>(nullptr), n, stream),
        "scan size", error) ||
    !Check(cub::DeviceScan::InclusiveSum(
             nullptr, rowScanBytes, static_cast<unsigned*>(nullptr), static_cast<unsigned*>(nullptr), pixels, stream),
      "scan size", error) ||
    !device.Fits(countingBytes + std::int64_t(std::max(scanBytes, rowScanBytes)), 0,
      "the assembled basis's counts of " + std::to_string(pixels) + " pixels", error) ||
    !slicesOnDevice.Reserve(std::max(1, count) * std::int64_t(sizeof(PreparedSlice)), "allocating slices", error) ||
    !columnCounts.Reserve(std::max<std::int64_t>(1, n) * sizeof(unsigned long long), "allocating counts", error) ||
    !pixelCounts.Reserve(std::max<std::int64_t>(1, pixels) * sizeof(unsigned), "allocating counts", error) ||
    !temporary.Reserve(std::int64_t(std::max(scanBytes, rowScanBytes)), "allocating the scan", error) ||
    !this->ColumnOffsets.Reserve((n + 1) * sizeof(unsigned long long), "allocating column offsets", error) ||
    !this->RowOffsets.Reserve((pixels + 1) * sizeof(unsigned), "allocating row offsets", error) ||
    !this->Vector.Reserve(std::max<std::int64_t>(1, pixels) * sizeof(float), "allocating the pixel vector", error) ||
    !Check(cudaMemcpyAsync(
             slicesOnDevice.Data, slices.data(), count * sizeof(PreparedSlice), cudaMemcpyHostToDevice, stream),
      "copying slices to the device", error) ||
    !Check(cudaMemsetAsync(pixelCounts.Data, 0, std::max<std::int64_t>(1, pixels) * sizeof(unsigned), stream),
      "clearing counts", error) ||
    !Check(cudaMemsetAsync(this->ColumnOffsets.Data, 0, sizeof(unsigned long long), stream), "clearing", error) ||
    !Check(cudaMemsetAsync(this->RowOffsets.Data, 0, sizeof(unsigned), stream), "clearing", error))
  {
    return false;
  }
  const std::int64_t warpBlocks = Blocks(n * WarpSize, BasisBlock);
  if (n > 0)
  {
    FootprintEntriesKernel<false><<<warpBlocks, BasisBlock, 0, stream>>>(field, slicesOnDevice.As<PreparedSlice>(),
      count, sigmaE, cutoff, columnCounts.As<unsigned long long>(), pixelCounts.As<unsigned>(), nullptr, nullptr,
      nullptr, nullptr, nullptr);
    if (!Check(cudaGetLastError(), "assembly's count kernel", error) ||
      !Check(cub::DeviceScan::InclusiveSum(temporary.Data, scanBytes, columnCounts.As<unsigned long long>(),
               this->ColumnOffsets.As<unsigned long long>() + 1, n, stream),
        "column scan", error))
    {
      return false;
    }
  }
  if (pixels > 0 &&
    !Check(cub::DeviceScan::InclusiveSum(temporary.Data, rowScanBytes, pixelCounts.As<unsigned>(),
             this->RowOffsets.As<unsigned>() + 1, pixels, stream),
      "row scan", error))
  {
    return false;
  }
  unsigned long long entries = 0;
  if (!Check(cudaMemcpyAsync(&entries, this->ColumnOffsets.As<unsigned long long>() + n, sizeof(entries),
               cudaMemcpyDeviceToHost, stream),
        "copying the entry count", error) ||
    !Check(cudaStreamSynchronize(stream), "assembly's count", error))
  {
    return false;
  }
  const std::int64_t e = static_cast<std::int64_t>(entries);
  if (e > Limit32)
  {
    return TooLarge("more than 2^32 - 1 weights", error, tooLarge);
  }
  // The entries: columns, then the rows by a stable sort of the entries by pixel.
  int bits = 1;
  while ((std::int64_t(1) << bits) < pixels)
  {
    ++bits;
  }
  std::size_t sortBytes = 0;
  cub::DoubleBuffer<unsigned> sortKeys(nullptr, nullptr);
  cub::DoubleBuffer<unsigned long long> sortValues(nullptr, nullptr);
  if (!Check(cub::DeviceRadixSort::SortPairs(nullptr, sortBytes, sortKeys, sortValues, e, 0, bits, stream), "sort size",
        error))
  {
    return false;
  }
  // Columns 8 bytes an entry, keys 2 x 4, values 2 x 8; the counts' buffers are held until the end.
  const std::int64_t entryBytes = 32 * e + static_cast<std::int64_t>(sortBytes);
  const std::int64_t held = countingBytes + temporary.Bytes;
  if (maximumBytes > 0 && entryBytes + held > maximumBytes)
  {
    char text[200];
    std::snprintf(text, sizeof(text),
      "the assembled basis of %lld weights needs %.0f MB to build, above the %.0f MB allowed",
      static_cast<long long>(e), (entryBytes + held) / 1e6, maximumBytes / 1e6);
    return TooLarge(text, error, tooLarge);
  }
  std::string why;
  if (!device.Fits(entryBytes, 0, "the assembled basis's " + std::to_string(e) + " weights", &why))
  {
    return TooLarge(why.c_str(), error, tooLarge);
  }
  Buffer keys, keysSorted, valuesSorted;
  const std::int64_t slots = std::max<std::int64_t>(1, e);
  if (!this->ColumnPixels.Reserve(slots * sizeof(unsigned), "allocating the basis", error) ||
    !this->ColumnWeights.Reserve(slots * sizeof(float), "allocating the basis", error) ||
    !this->RowEntries.Reserve(slots * sizeof(unsigned long long), "allocating the basis", error) ||
    !keys.Reserve(slots * sizeof(unsigned), "allocating the basis's sort", error) ||
    !keysSorted.Reserve(slots * sizeof(unsigned), "allocating the basis's sort", error) ||
    !valuesSorted.Reserve(slots * sizeof(unsigned long long), "allocating the basis's sort", error) ||
    !temporary.Reserve(static_cast<std::int64_t>(sortBytes), "allocating the basis's sort", error))
  {
    return false;
  }
  if (n > 0)
  {
    FootprintEntriesKernel<true><<<warpBlocks, BasisBlock, 0, stream>>>(field, slicesOnDevice.As<PreparedSlice>(),
      count, sigmaE, cutoff, nullptr, nullptr, this->ColumnOffsets.As<unsigned long long>(),
      this->ColumnPixels.As<unsigned>(), this->ColumnWeights.As<float>(), keys.As<unsigned>(),
      this->RowEntries.As<unsigned long long>());
    if (!Check(cudaGetLastError(), "assembly's fill kernel", error))
    {
      return false;
    }
  }
  sortKeys = cub::DoubleBuffer<unsigned>(keys.As<unsigned>(), keysSorted.As<unsigned>());
  sortValues = cub::DoubleBuffer<unsigned long long>(
    this->RowEntries.As<unsigned long long>(), valuesSorted.As<unsigned long long>());
  if (e > 0 &&
    !Check(cub::DeviceRadixSort::SortPairs(temporary.Data, sortBytes, sortKeys, sortValues, e, 0, bits, stream),
      "sort by pixel", error))
  {
    return false;
  }
  if (sortValues.Current() != this->RowEntries.As<unsigned long long>())
  {
    SwapBuffers(this->RowEntries, valuesSorted);
  }
  if (!Check(cudaStreamSynchronize(stream), "assembling the basis", error))
  {
    return false;
  }
  this->Gaussians = n;
  this->Pixels = pixels;
  this->Entries = e;
  return true;
}

void DeviceBasis::Apply(const float* r, cudaStream_t stream) const
{
  if (this->Pixels > 0)
  {
    RowProductKernel<<<Blocks(this->Pixels, BasisBlock), BasisBlock, 0, stream>>>(this->RowOffsets.As<unsigned>(),
      this->RowEntries.As<unsigned long long>(), this->Pixels, r, this->Vector.As<float>());
  }
}

void DeviceBasis::ApplyTranspose(double* out, cudaStream_t stream) const
{
  if (this->Gaussians > 0)
  {
    ColumnProductKernel<false><<<Blocks(this->Gaussians * WarpSize, BasisBlock), BasisBlock, 0, stream>>>(
      this->ColumnOffsets.As<unsigned long long>(), this->ColumnPixels.As<unsigned>(), this->ColumnWeights.As<float>(),
      this->Gaussians, this->Vector.As<float>(), out);
  }
}

void DeviceBasis::Norms(double* out, cudaStream_t stream) const
{
  if (this->Gaussians > 0)
  {
    ColumnProductKernel<true><<<Blocks(this->Gaussians * WarpSize, BasisBlock), BasisBlock, 0, stream>>>(
      this->ColumnOffsets.As<unsigned long long>(), this->ColumnPixels.As<unsigned>(), this->ColumnWeights.As<float>(),
      this->Gaussians, this->Vector.As<float>(), out);
  }
}

} // namespace cuda
} // namespace bigus
