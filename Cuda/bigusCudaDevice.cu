#include "bigusCudaDevice.h"

#include <cuda_runtime.h>

namespace bigus
{
namespace cuda
{

namespace
{
__global__ void SaxpyKernel(float a, const float* x, const float* y, float* out, int n)
{
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n)
  {
    out[i] = fmaf(a, x[i], y[i]);
  }
}

bool Check(cudaError_t status, const char* what, std::string& why)
{
  if (status != cudaSuccess)
  {
    why = std::string(what) + ": " + cudaGetErrorString(status);
    return false;
  }
  return true;
}
}

bool QueryDevice(DeviceInfo& info, std::string& why)
{
  info = DeviceInfo();
  cudaDriverGetVersion(&info.DriverVersion);
  cudaRuntimeGetVersion(&info.RuntimeVersion);
  if (!Check(cudaGetDeviceCount(&info.Count), "cudaGetDeviceCount", why))
  {
    info.Count = 0;
    return false;
  }
  if (info.Count == 0)
  {
    why = "no CUDA device is visible";
    return false;
  }
  cudaDeviceProp prop;
  if (!Check(cudaGetDeviceProperties(&prop, 0), "cudaGetDeviceProperties", why))
  {
    return false;
  }
  info.Name = prop.name;
  info.ComputeCapability = prop.major * 10 + prop.minor;
  info.MemoryGiB = prop.totalGlobalMem / double(1 << 30);
  if (info.ComputeCapability < 75)
  {
    why = "device " + info.Name + " is sm_" + std::to_string(info.ComputeCapability) + "; sm_75 or newer is needed";
    return false;
  }
  return true;
}

bool RunSelfTest(float a, const float* x, const float* y, float* out, int n, std::string& why)
{
  float* buffers = nullptr; // [3, n]: x, y, out
  const size_t bytes = sizeof(float) * size_t(n);
  if (!Check(cudaMalloc(&buffers, 3 * bytes), "cudaMalloc", why))
  {
    return false;
  }
  bool ok = Check(cudaMemcpy(buffers, x, bytes, cudaMemcpyHostToDevice), "cudaMemcpy x", why) &&
    Check(cudaMemcpy(buffers + n, y, bytes, cudaMemcpyHostToDevice), "cudaMemcpy y", why);
  if (ok)
  {
    SaxpyKernel<<<(n + 255) / 256, 256>>>(a, buffers, buffers + n, buffers + 2 * n, n);
    ok = Check(cudaGetLastError(), "kernel launch", why) &&
      Check(cudaMemcpy(out, buffers + 2 * n, bytes, cudaMemcpyDeviceToHost), "cudaMemcpy out", why);
  }
  cudaFree(buffers);
  return ok;
}

} // namespace cuda
} // namespace bigus
