/**
 * @file bigusCudaDevice.h
 * @brief Run-time discovery of the CUDA backend (DESIGN section 5).
 *
 * The CUDA backend is optional twice: at build time (this module exists only when nvcc was found)
 * and at run time (a machine without a usable GPU falls back to the CPU with a clear message).
 * The renderer kernels arrive with the renderer issue; this file is the boundary they plug into.
 */
#ifndef bigusCudaDevice_h
#define bigusCudaDevice_h

#include "bigusCudaModule.h" // For export macro

#include <string>

namespace bigus
{
namespace cuda
{

/// Description of the GPU the backend would use.
struct DeviceInfo
{
  int Count = 0;             ///< number of CUDA devices visible
  std::string Name;          ///< name of device 0
  int ComputeCapability = 0; ///< e.g. 90 for sm_90
  double MemoryGiB = 0;      ///< global memory of device 0
  int DriverVersion = 0;     ///< the CUDA version the driver supports, e.g. 13000 for 13.0 (cudaDriverGetVersion)
  int RuntimeVersion = 0;    ///< of the CUDA runtime this build links (cudaRuntimeGetVersion)
};

/**
 * Query the CUDA runtime. Returns true when at least one device can run our kernels; otherwise false
 * with @p why saying what is missing (no driver, no device, a device older than sm_75).
 */
BIGUSCUDA_EXPORT bool QueryDevice(DeviceInfo& info, std::string& why);

/**
 * Launch a kernel that computes out[i] = a * x[i] + y[i] for n elements on device 0 and copy the
 * result back: proves that the build's device code runs on this GPU. Returns false with @p why on
 * any CUDA error.
 */
BIGUSCUDA_EXPORT bool RunSelfTest(float a, const float* x, const float* y, float* out, int n, std::string& why);

} // namespace cuda
} // namespace bigus

#endif
