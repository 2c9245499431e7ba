// The CUDA backend's device code runs on this machine's GPU; exit 125 (skipped) where none is usable.
#include "bigusCudaDevice.h"

#include <cmath>
#include <cstdio>
#include <vector>

int main()
{
  bigus::cuda::DeviceInfo info;
  std::string why;
  if (!bigus::cuda::QueryDevice(info, why))
  {
    std::printf("SKIP: no usable CUDA device (%s)\n", why.c_str());
    return 125;
  }
  std::printf("CUDA device: %s, sm_%d, %.1f GiB\n", info.Name.c_str(), info.ComputeCapability, info.MemoryGiB);
  const int n = 100003; // not a multiple of the block size: the tail must be handled
  std::vector<float> x(n), y(n), out(n, -1.0f);
  for (int i = 0; i < n; ++i)
  {
    x[i] = 0.001f * i;
    y[i] = 1.0f - 0.5f * i;
  }
  if (!bigus::cuda::RunSelfTest(2.5f, x.data(), y.data(), out.data(), n, why))
  {
    std::printf("FAIL: %s\n", why.c_str());
    return 1;
  }
  for (int i = 0; i < n; ++i)
  {
    if (out[i] != std::fma(2.5f, x[i], y[i]))
    {
      std::printf("FAIL: element %d is %.9g, expected %.9g\n", i, out[i], std::fma(2.5f, x[i], y[i]));
      return 1;
    }
  }
  std::printf("PASS: %d elements match the host's fused multiply-add bit for bit\n", n);
  return 0;
}
