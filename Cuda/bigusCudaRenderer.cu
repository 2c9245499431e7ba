// CUDA backend of the beam-integrated Gaussian renderer (see bigusCudaRenderer.h), the Renderer interface on
// host buffers: uploads and downloads around the DeviceRenderer (bigusCudaDeviceRenderer.h: binning, the
// order of the kernels, memory checks), whose kernels live one file per family (bigusCudaKernels.h).
#include "bigusCudaRenderer.h"

#include "bigusBackend.h"
#include "bigusCudaDevice.h"
#include "bigusCudaDeviceRenderer.h"
#include "bigusCudaKernels.h"
#include "bigusCudaTrainingEngine.h"
#include "bigusGaussianMath.h"
#include "bigusRasterGeometry.h"

#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdint>
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
constexpr std::int64_t PixelBytes = 3 * sizeof(float); // forward S, I; backward S, dL, dL/dS

/// The Renderer interface on host buffers: every call uploads the field (and in Backward the gradients it adds
/// to, S and dL), runs the DeviceRenderer and downloads the results.
class CudaRenderer : public Renderer
{
public:
  bool Initialize(std::string* error) { return this->Device.Initialize(error); }

  const char* GetName() const override { return "cuda"; }

  bool Forward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options, float* S,
    float* I, RenderStats* stats, std::string* error) override
  {
    std::vector<PreparedSlice> prepared;
    if (!PrepareSlices(slices, count, options, prepared, error) || !this->UploadField(field, false, prepared, error))
    {
      return false;
    }
    const cudaStream_t stream = this->Device.GetStream();
    const DeviceField device = this->Field(field.Count);
    std::int64_t offset = 0;
    for (const PreparedSlice& s : prepared)
    {
      const std::int64_t pixels = std::int64_t(s.Width) * s.Height;
      float* dS = this->Image.As<float>();
      if (!this->Device.Forward(device, s, options, dS, I ? dS + pixels : nullptr, stats, error) ||
        !Check(cudaMemcpyAsync(S + offset, dS, sizeof(float) * pixels, cudaMemcpyDeviceToHost, stream),
          "copying S to the host", error) ||
        (I &&
          !Check(cudaMemcpyAsync(I + offset, dS + pixels, sizeof(float) * pixels, cudaMemcpyDeviceToHost, stream),
            "copying I to the host", error)))
      {
        return false;
      }
      offset += pixels;
    }
    return Check(cudaStreamSynchronize(stream), "copying images to the host", error);
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
    const cudaStream_t stream = this->Device.GetStream();
    const std::int64_t n = field.Count;
    double* poseTotals = this->PoseTotalData.As<double>(); // [count, 6] the slices' pose gradients
    if (poses &&
      !Check(cudaMemsetAsync(poseTotals, 0, sizeof(double) * 6 * count, stream), "clearing pose gradients", error))
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
        if (!Check(cudaMemcpyAsync(
                     *outputs[k], slots[k].Host, sizeof(float) * slots[k].Width * n, cudaMemcpyHostToDevice, stream),
              "copying gradients to the device", error))
        {
          return false;
        }
      }
    }
    if (gradients.VisibleCount)
    {
      out.VisibleCount = reinterpret_cast<int*>(base + 12 * n);
      if (!Check(
            cudaMemcpyAsync(out.VisibleCount, gradients.VisibleCount, sizeof(int) * n, cudaMemcpyHostToDevice, stream),
            "copying visibility counts to the device", error))
      {
        return false;
      }
    }
    const DeviceField device = this->Field(n);
    std::int64_t offset = 0;
    for (int k = 0; k < count; ++k)
    {
      const PreparedSlice& s = prepared[k];
      const std::int64_t pixels = std::int64_t(s.Width) * s.Height;
      float* dS = this->Image.As<float>(); // [H, W] S of the slice
      float* dG = dS + pixels;             // [H, W] dL of the slice
      if (!Check(cudaMemcpyAsync(dS, S + offset, sizeof(float) * pixels, cudaMemcpyHostToDevice, stream),
            "copying S to the device", error) ||
        !Check(cudaMemcpyAsync(dG, dL + offset, sizeof(float) * pixels, cudaMemcpyHostToDevice, stream),
          "copying dL to the device", error) ||
        !this->Device.Backward(device, s, options, dS, dG, gradientIsWithRespectToS, dG + pixels, out,
          poses ? poseTotals + 6 * k : nullptr, error))
      {
        return false;
      }
      offset += pixels;
    }
    for (int k = 0; k < 5; ++k)
    {
      if (slots[k].Host &&
        !Check(cudaMemcpyAsync(
                 slots[k].Host, *outputs[k], sizeof(float) * slots[k].Width * n, cudaMemcpyDeviceToHost, stream),
          "copying gradients to the host", error))
      {
        return false;
      }
    }
    std::vector<double> poseGradients(poses ? 6 * std::size_t(count) : 0);
    if ((poses &&
          !Check(cudaMemcpyAsync(poseGradients.data(), poseTotals, sizeof(double) * poseGradients.size(),
                   cudaMemcpyDeviceToHost, stream),
            "copying pose gradients to the host", error)) ||
      (gradients.VisibleCount &&
        !Check(
          cudaMemcpyAsync(gradients.VisibleCount, out.VisibleCount, sizeof(int) * n, cudaMemcpyDeviceToHost, stream),
          "copying visibility counts to the host", error)) ||
      !this->Device.Synchronize(stats, "backward", error))
    {
      return false;
    }
    for (std::size_t c = 0; c < poseGradients.size(); ++c)
    {
      gradients.SlicePoses[c] += poseGradients[c]; // after the synchronisation
    }
    if (stats)
    {
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

  DeviceField Field(std::int64_t n) const { return FieldAt(this->FieldData.As<float>(), n); }

  /// Checks the memory a call needs (refused before allocating when it does not fit), then uploads the field. A
  /// backward call with @p poseSlices > 0 also holds the pose gradient's buffers (6 doubles per slice).
  bool UploadField(const FieldView& field, bool backward, const std::vector<PreparedSlice>& slices, std::string* error,
    int poseSlices = 0)
  {
    const std::int64_t n = field.Count;
    const CallExtent extent = Extent(n, slices);
    const std::int64_t pixels = extent.Pixels;
    if (n >= (std::int64_t(1) << 31))
    {
      if (error)
      {
        *error = "CUDA renderer: " + extent.What + ": at most 2^31 - 1 Gaussians are supported";
      }
      return false;
    }
    const std::int64_t slots = std::max<std::int64_t>(1, n);
    const std::int64_t poseTotalBytes = 6 * std::int64_t(sizeof(double)) * poseSlices;
    const std::int64_t own = n * (FieldBytes + (backward ? GradientBytes : 0)) + pixels * PixelBytes + poseTotalBytes;
    const std::int64_t held = this->FieldData.Bytes + this->Image.Bytes + (backward ? this->Gradients.Bytes : 0) +
      (poseSlices > 0 ? this->PoseTotalData.Bytes : 0);
    if (!this->Device.Reserve(backward, poseSlices > 0, n, extent.Tiles, own, held, extent.What, error) ||
      !this->FieldData.Reserve(slots * FieldBytes, "allocating the field", error) ||
      !this->Image.Reserve(pixels * PixelBytes, "allocating the image buffers", error) ||
      (backward && !this->Gradients.Reserve(slots * GradientBytes, "allocating gradients", error)) ||
      (poseSlices > 0 && !this->PoseTotalData.Reserve(poseTotalBytes, "allocating pose gradients", error)))
    {
      return false;
    }
    return cuda::UploadField(field, this->FieldData.As<float>(), this->Device.GetStream(), error);
  }

  DeviceRenderer Device;
  Buffer FieldData;     // [N, 11] floats: means [N, 3], log-scales [N, 3], quaternions [N, 4], reflectivities [N]
  Buffer Gradients;     // [N, 12] floats + [N] ints: as FieldData, then attribution [N], visible counts [N]
  Buffer Image;         // [3, H, W] floats: forward S, I; backward S, dL, dL/dS
  Buffer PoseTotalData; // [count, 6] doubles: the slices' pose gradients
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
  if (!DeviceUsable(error))
  {
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
 * above "cpu", with its device-resident training engine (bigusCudaTrainingEngine.h), where a usable device
 * exists, and otherwise records why not, so that asking for "cuda" says so and "auto" quietly stays on the CPU.
 */
extern "C" BIGUSCUDA_EXPORT void bigusCudaRegisterBackend()
{
  std::string why;
  if (bigus::cuda::DeviceUsable(&why))
  {
    bigus::RegisterBackend("cuda", &bigus::cuda::MakeCudaRenderer, 10);
    bigus::RegisterTrainingEngine("cuda", &bigus::cuda::CreateCudaTrainingEngine);
    bigus::cuda::DeviceInfo info;
    if (bigus::cuda::QueryDevice(info, why))
    {
      auto version = [](int v) { return std::to_string(v / 1000) + "." + std::to_string(v % 1000 / 10); };
      char memory[32];
      std::snprintf(memory, sizeof(memory), "%.1f", info.MemoryGiB);
      bigus::SetBackendDescription("cuda",
        info.Name + " (sm_" + std::to_string(info.ComputeCapability) + ", " + memory + " GiB; " +
          std::to_string(info.Count) + " device(s) visible, device 0 used), driver supports CUDA " +
          version(info.DriverVersion) + ", CUDA runtime " + version(info.RuntimeVersion));
    }
  }
  else
  {
    bigus::RegisterUnavailableBackend("cuda", why);
  }
}
