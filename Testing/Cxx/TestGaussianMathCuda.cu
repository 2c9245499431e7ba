// Every BIGUS_HD function of bigusGaussianMath.h runs in a kernel and on the host on the same inputs,
// and the two agree to within what the device's math library changes. The file is compiled wherever
// nvcc is found, so the header is checked for device use on every such build; it exits 125 (skipped)
// where no usable GPU exists.
#include "bigusCudaDevice.h"
#include "bigusGaussianMath.h"
#include "bigusSliceFrame.h"

#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

namespace
{
using namespace bigus;

/// One set of inputs: a Gaussian (structure of arrays, as the renderers hold it), a slice, a pixel.
struct Case
{
  float Means[3], LogScales[3], Quaternions[4], Reflectivity; // [1, 3], [1, 3], [1, 4], [1]
  SliceFrameD Frame;
  double SigmaE, Cutoff;   // mm, standard deviations
  double FootprintSeed[6]; // dL/d(centre, conic, amp) fed to SetupFootprintBackward
  // Inputs of the per-pixel functions, from the host's footprint of this Gaussian (a random one where
  // it is culled), so that both sides evaluate them on the same numbers.
  double Conic[3], Axes[4], Amplitude;
  double Dx, Dy; // pixel offset from the footprint centre, mm
  double GS, S, Gamma, MeanIntensity;
};

constexpr int MaximumOutputs = 192;
// The kernel is compiled without fused multiply-adds (Testing/CMakeLists.txt), so host and device
// differ only by their math libraries (exp, log, sqrt, atan2, cos, sin: a few ulps on the device).
// Float: the per-pixel functions get the same inputs on both sides, so only std::exp(float) differs.
// Double: those ulps; the footprint gradient amplifies them by the Gaussian's squared scale ratio
// (needle and pancake cases: a host run with fused multiply-adds, a larger perturbation, moved its
// quaternion gradient by 2.2e-5 of its size at ratio e^12, where ConditionedTolerance gives 2.6e-3).
constexpr double DoubleTolerance = 1e-10;
constexpr double ConditionedTolerance = 1e-13; // times (largest / smallest scale)^2
constexpr double FloatTolerance = 1e-5;

/**
 * Appends outputs. On the host it also records each output's name and tolerance (relative to the
 * largest output of the same name in the case, so that a component that is small by cancellation is
 * judged against the size of its neighbours); the kernel passes no tables.
 */
struct Outputs
{
  double* Values;
  const char** Names;
  double* Tolerances;
  int Count;
  BIGUS_HD void Put(const char* name, double v, double tolerance = DoubleTolerance)
  {
    if (this->Count < MaximumOutputs)
    {
      if (this->Names)
      {
        this->Names[this->Count] = name;
        this->Tolerances[this->Count] = tolerance;
      }
      this->Values[this->Count] = v;
    }
    ++this->Count;
  }
};

template <typename T>
BIGUS_HD void PixelFunctions(const Case& k, Outputs& out)
{
  const double tolerance = sizeof(T) == sizeof(float) ? FloatTolerance : DoubleTolerance;
  const T a = T(k.Conic[0]), b = T(k.Conic[1]), c = T(k.Conic[2]), dx = T(k.Dx), dy = T(k.Dy);
  const T form = AxesForm(T(k.Axes[0]), T(k.Axes[1]), T(k.Axes[2]), T(k.Axes[3]), dx, dy);
  out.Put("ConicForm", ConicForm(a, b, c, dx, dy), tolerance);
  out.Put("AxesForm", form, tolerance);
  out.Put("PixelWeight", PixelWeight(T(k.Amplitude), a, b, c, dx, dy), tolerance);
  const T e = T(FastExp(float(-0.5 * form)));
  // Stride 2: the terms land in the even slots and the odd ones stay untouched.
  T sums[2 * 7] = {};
  PixelWeightBackward(T(k.GS), T(k.Reflectivity * k.Amplitude), e, a, b, c, dx, dy, sums, 2);
  const char* terms[7] = { "PixelWeightBackward dL/dc", "PixelWeightBackward dL/dc", "PixelWeightBackward dL/dconic",
    "PixelWeightBackward dL/dconic", "PixelWeightBackward dL/dconic", "PixelWeightBackward gS e",
    "PixelWeightBackward attribution" };
  for (int q = 0; q < 7; ++q)
  {
    out.Put(terms[q], sums[2 * q], tolerance);
    out.Put("PixelWeightBackward untouched slot", sums[2 * q + 1], 0.0);
  }
  out.Put("ImageFromScattering", ImageFromScattering(T(k.S), T(k.Gamma)), tolerance);
  out.Put("ImageFromScatteringDerivative", ImageFromScatteringDerivative(T(k.S), T(k.Gamma)), tolerance);
}

/// The same sequence of calls on the host and on the device.
BIGUS_HD void Evaluate(const Case& k, Outputs& out)
{
  const GaussianParams g = LoadGaussian(k.Means, k.LogScales, k.Quaternions, &k.Reflectivity, 0);
  const double md[3] = { k.Means[0], k.Means[1], k.Means[2] };
  const double ld[3] = { k.LogScales[0], k.LogScales[1], k.LogScales[2] };
  const double qd[4] = { k.Quaternions[0], k.Quaternions[1], k.Quaternions[2], k.Quaternions[3] };
  const double rd = k.Reflectivity;
  const GaussianParams gd = LoadGaussian(md, ld, qd, &rd, 0);
  const GaussianParams* loaded[2] = { &g, &gd };
  for (const GaussianParams* p : loaded)
  {
    for (int q = 0; q < 3; ++q)
    {
      out.Put("LoadGaussian Mean", p->Mean[q]);
      out.Put("LoadGaussian LogScale", p->LogScale[q]);
    }
    for (int q = 0; q < 4; ++q)
    {
      out.Put("LoadGaussian Quaternion", p->Quaternion[q]);
    }
    out.Put("LoadGaussian Reflectivity", p->Reflectivity);
  }

  double R[3][3], G[3][3], dq[4];
  QuaternionToMatrix(g.Quaternion, R);
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      out.Put("QuaternionToMatrix", R[i][j]);
      G[i][j] = 0.1 * (3 * i + j) - 0.4;
    }
  }
  QuaternionToMatrixBackward(g.Quaternion, G, dq);
  for (int q = 0; q < 4; ++q)
  {
    out.Put("QuaternionToMatrixBackward", dq[q]);
  }
  double qn[4];
  out.Put("NormalizeQuaternion |q|", NormalizeQuaternion(g.Quaternion, qn));
  for (int q = 0; q < 4; ++q)
  {
    out.Put("NormalizeQuaternion", qn[q]);
  }

  SetupCache cache;
  const Footprint f = SetupFootprint(g, k.Frame, k.SigmaE, k.Cutoff, &cache);
  out.Put("SetupFootprint Visible", f.Visible ? 1 : 0);
  out.Put("SetupFootprint Elevation", f.Elevation);
  out.Put("SetupFootprint ElevationVar", f.ElevationVar);
  if (f.Visible)
  {
    const double* fields[] = { f.Center, f.Conic, f.Axes, f.Cov };
    const int sizes[] = { 2, 3, 4, 3 };
    for (int s = 0; s < 4; ++s)
    {
      for (int q = 0; q < sizes[s]; ++q)
      {
        out.Put("SetupFootprint Center, Conic, Axes, Cov", fields[s][q]);
      }
    }
    out.Put("SetupFootprint Amplitude", f.Amplitude);
    out.Put("SetupFootprint CutoffSquared", f.CutoffSquared);

    double sums[7];
    for (int q = 0; q < 6; ++q)
    {
      sums[q] = k.FootprintSeed[q];
    }
    sums[6] = 0;
    const FootprintGrad gfp = FootprintGradFromSums(sums, g.Reflectivity);
    out.Put("FootprintGradFromSums Amplitude", gfp.Amplitude);
    GaussianGrad gg = {};
    SliceFrameGrad sg;
    SetupFootprintBackward(f, cache, k.Frame, k.SigmaE, gfp, gg, &sg);
    double smallest = cache.Scale[0], largest = cache.Scale[0];
    for (int q = 1; q < 3; ++q)
    {
      smallest = cache.Scale[q] < smallest ? cache.Scale[q] : smallest;
      largest = cache.Scale[q] > largest ? cache.Scale[q] : largest;
    }
    const double ratio = largest / smallest;
    const double tolerance = DoubleTolerance + ConditionedTolerance * ratio * ratio;
    for (int q = 0; q < 3; ++q)
    {
      out.Put("SetupFootprintBackward Mean", gg.Mean[q], tolerance);
      out.Put("SetupFootprintBackward LogScale", gg.LogScale[q], tolerance);
    }
    for (int q = 0; q < 4; ++q)
    {
      out.Put("SetupFootprintBackward Quaternion", gg.Quaternion[q], tolerance);
    }
    // Pose refinement: the gradient with respect to a correction of the slice's pose, and the corrected
    // frame (a correction of a few degrees and millimetres about the slice's point (10, 5) mm).
    const double pivot[3] = { 10, 5, 0 };
    double dxi[6] = { 0, 0, 0, 0, 0, 0 };
    SlicePoseBackward(cache, pivot, sg, dxi);
    for (int q = 0; q < 6; ++q)
    {
      out.Put("SlicePoseBackward", dxi[q], tolerance);
    }
  }
  const double pivot[3] = { 10, 5, 0 };
  const double xi[6] = { 0.02, -0.035, 0.05, 0.4, -0.7, 1.1 };
  SliceFrameD corrected;
  CorrectSliceFrame(k.Frame, pivot, xi, corrected);
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      out.Put("CorrectSliceFrame F", corrected.F[i][j]);
    }
    out.Put("CorrectSliceFrame Origin", corrected.Origin[i]);
  }
  PixelFunctions<double>(k, out);
  PixelFunctions<float>(k, out);
  out.Put("FastExp", FastExp(float(-30 * (k.Dx * k.Dx + k.Dy * k.Dy))), FloatTolerance); // reaches the clamp
  out.Put("GammaFromMeanIntensity", GammaFromMeanIntensity(k.MeanIntensity));
}

__global__ void EvaluateKernel(const Case* cases, int count, double* values, int* counts)
{
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < count)
  {
    Outputs out = { values + std::size_t(i) * MaximumOutputs, nullptr, nullptr, 0 };
    Evaluate(cases[i], out);
    counts[i] = out.Count;
  }
}

/// Deterministic inputs: random Gaussians around random oblique slices, plus the hard cases
/// (needle and pancake shapes past the aspect limit, a culled Gaussian, a NaN log-scale, a zero
/// quaternion, thin plane).
std::vector<Case> MakeCases()
{
  unsigned state = 12345u;
  auto uniform = [&state](double lo, double hi) {
    state = state * 1664525u + 1013904223u;
    return lo + (hi - lo) * ((state >> 8) / double(1u << 24));
  };
  std::vector<Case> cases;
  for (int n = 0; n < 256; ++n)
  {
    Case k = {};
    // Frame: rows of a rotation from a random unit quaternion.
    double q[4] = { uniform(-1, 1), uniform(-1, 1), uniform(-1, 1), uniform(-1, 1) };
    const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (double& v : q)
    {
      v /= norm;
    }
    QuaternionToMatrix(q, k.Frame.F);
    for (int i = 0; i < 3; ++i)
    {
      k.Frame.Origin[i] = uniform(-50, 50);
      k.Means[i] = static_cast<float>(k.Frame.Origin[i] + uniform(-2, 2));
      k.LogScales[i] = static_cast<float>(uniform(-2.5, 1));
    }
    for (int i = 0; i < 4; ++i)
    {
      k.Quaternions[i] = static_cast<float>(uniform(-1, 1));
    }
    k.Reflectivity = static_cast<float>(uniform(-1, 1));
    if (n % 3 == 1) // a pixel low-pass (SliceGeometry::PixelLowPass) through a sheared pixel
    {
      const double pixel[3] = { uniform(0.1, 0.6), uniform(-0.05, 0.05), uniform(0.1, 0.6) };
      PixelLowPassCovariance(pixel, uniform(0.02, 1), k.Frame.LowPass);
    }
    k.SigmaE = n % 7 == 0 ? 0.0 : uniform(0.1, 2);
    k.Cutoff = n % 5 == 0 ? std::numeric_limits<double>::infinity() : uniform(3, 6);
    for (double& v : k.FootprintSeed)
    {
      v = uniform(-2, 2);
    }
    k.Dx = uniform(-1.5, 1.5);
    k.Dy = uniform(-1.5, 1.5);
    k.GS = uniform(-1, 1);
    k.S = uniform(-0.5, 3);
    k.Gamma = uniform(0.2, 3);
    k.MeanIntensity = uniform(-0.1, 1.1);
    switch (n % 8)
    {
      case 1: // needle: scale ratio e^12 > MaximumFootprintAspect, widened
        k.LogScales[0] = -6;
        k.LogScales[1] = -6;
        k.LogScales[2] = 6;
        break;
      case 2: // pancake
        k.LogScales[0] = 4;
        k.LogScales[1] = 4;
        k.LogScales[2] = -7;
        break;
      case 3: // far from the plane: culled unless the cutoff is infinite
        for (int i = 0; i < 3; ++i)
        {
          k.Means[i] = static_cast<float>(k.Frame.Origin[i] + 40 * k.Frame.F[2][i]);
        }
        break;
      case 4:
        k.LogScales[1] = std::numeric_limits<float>::quiet_NaN();
        break;
      case 5:
        k.Quaternions[0] = k.Quaternions[1] = k.Quaternions[2] = k.Quaternions[3] = 0;
        break;
      default:
        break;
    }
    const Footprint f = SetupFootprint(
      LoadGaussian(k.Means, k.LogScales, k.Quaternions, &k.Reflectivity, 0), k.Frame, k.SigmaE, k.Cutoff, nullptr);
    if (f.Visible)
    {
      for (int i = 0; i < 3; ++i)
      {
        k.Conic[i] = f.Conic[i];
      }
      for (int i = 0; i < 4; ++i)
      {
        k.Axes[i] = f.Axes[i];
      }
      k.Amplitude = f.Amplitude;
    }
    else
    {
      const double angle = uniform(0, 3.14159), s1 = uniform(0.2, 1), s2 = uniform(0.2, 1);
      const double co = std::cos(angle), si = std::sin(angle);
      k.Conic[0] = co * co / (s1 * s1) + si * si / (s2 * s2);
      k.Conic[1] = co * si * (1 / (s1 * s1) - 1 / (s2 * s2));
      k.Conic[2] = si * si / (s1 * s1) + co * co / (s2 * s2);
      k.Axes[0] = co;
      k.Axes[1] = si;
      k.Axes[2] = 1 / s1;
      k.Axes[3] = 1 / s2;
      k.Amplitude = uniform(0, 1);
    }
    cases.push_back(k);
  }
  return cases;
}

bool Check(cudaError_t status, const char* what)
{
  if (status != cudaSuccess)
  {
    std::printf("FAIL: %s: %s\n", what, cudaGetErrorString(status));
    return false;
  }
  return true;
}

/// Host-device agreement of one output, given the largest host output of its name in the case.
bool Agree(double host, double device, double scale, double tolerance)
{
  if (std::isnan(host) || std::isnan(device))
  {
    return std::isnan(host) && std::isnan(device);
  }
  if (std::isinf(host) || std::isinf(device))
  {
    return host == device;
  }
  return std::abs(host - device) <= tolerance * scale;
}
}

int main()
{
  cuda::DeviceInfo info;
  std::string why;
  if (!cuda::QueryDevice(info, why))
  {
    std::printf("SKIP: no usable CUDA device (%s)\n", why.c_str());
    return 125;
  }
  std::printf("CUDA device: %s, sm_%d\n", info.Name.c_str(), info.ComputeCapability);

  const std::vector<Case> cases = MakeCases();
  const int count = static_cast<int>(cases.size());
  const std::size_t slots = std::size_t(count) * MaximumOutputs;
  std::vector<double> host(slots), device(slots), tolerances(slots);
  std::vector<const char*> names(slots, "");
  std::vector<int> hostCounts(count), deviceCounts(count);
  for (int i = 0; i < count; ++i)
  {
    const std::size_t first = std::size_t(i) * MaximumOutputs;
    Outputs out = { &host[first], &names[first], &tolerances[first], 0 };
    Evaluate(cases[i], out);
    hostCounts[i] = out.Count;
    if (out.Count > MaximumOutputs)
    {
      std::printf("FAIL: case %d writes %d outputs, more than MaximumOutputs = %d\n", i, out.Count, MaximumOutputs);
      return 1;
    }
  }

  Case* dCases = nullptr;
  double* dValues = nullptr;
  int* dCounts = nullptr;
  bool ok = Check(cudaMalloc(&dCases, sizeof(Case) * count), "cudaMalloc cases") &&
    Check(cudaMalloc(&dValues, sizeof(double) * device.size()), "cudaMalloc values") &&
    Check(cudaMalloc(&dCounts, sizeof(int) * count), "cudaMalloc counts") &&
    Check(cudaMemcpy(dCases, cases.data(), sizeof(Case) * count, cudaMemcpyHostToDevice), "cudaMemcpy cases");
  if (ok)
  {
    EvaluateKernel<<<(count + 63) / 64, 64>>>(dCases, count, dValues, dCounts);
    ok = Check(cudaGetLastError(), "kernel launch") && Check(cudaDeviceSynchronize(), "kernel") &&
      Check(cudaMemcpy(device.data(), dValues, sizeof(double) * device.size(), cudaMemcpyDeviceToHost),
        "cudaMemcpy values") &&
      Check(cudaMemcpy(deviceCounts.data(), dCounts, sizeof(int) * count, cudaMemcpyDeviceToHost), "cudaMemcpy counts");
  }
  cudaFree(dCases);
  cudaFree(dValues);
  cudaFree(dCounts);
  if (!ok)
  {
    return 1;
  }

  int failures = 0;
  std::size_t compared = 0;
  for (int i = 0; i < count; ++i)
  {
    if (deviceCounts[i] != hostCounts[i])
    {
      std::printf("FAIL: case %d: %d outputs on the device, %d on the host (the footprint's visibility differs)\n", i,
        deviceCounts[i], hostCounts[i]);
      ++failures;
      continue;
    }
    const std::size_t first = std::size_t(i) * MaximumOutputs;
    for (int q = 0; q < hostCounts[i]; ++q)
    {
      double scale = std::numeric_limits<double>::min();
      for (int p = 0; p < hostCounts[i]; ++p)
      {
        if (std::string(names[first + p]) == names[first + q] && std::isfinite(host[first + p]))
        {
          scale = std::max(scale, std::abs(host[first + p]));
        }
      }
      const double h = host[first + q], d = device[first + q];
      ++compared;
      if (!Agree(h, d, scale, tolerances[first + q]) && ++failures <= 20)
      {
        std::printf("FAIL: case %d output %d (%s): host %.17g, device %.17g\n", i, q, names[first + q], h, d);
      }
    }
  }
  if (failures)
  {
    std::printf("FAIL: %d of %zu outputs differ\n", failures, compared);
    return 1;
  }
  std::printf("PASS: %zu outputs of %d cases agree between host and device\n", compared, count);
  return 0;
}
