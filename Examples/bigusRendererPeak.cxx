// BenchmarkRenderer: the peak of phase 2's arithmetic, the inner loop of RasterSlice (bigusCpuRenderer.cxx) on a
// 16 x 64 accumulator and 64 splats, all in L1, on every core, for each ISA the CPU has.
#include "bigusRendererPeak.h"

#include "bigusGaussianMath.h"

#include "vtkSMPTools.h"

#include <benchmark/benchmark.h>

#include <cstdint>
#include <vector>

namespace bigus::rendererbenchmark
{
namespace
{
constexpr int PeakRows = 16, PeakCols = 64, PeakSplats = 64;

struct PeakSplat
{
  float A, B2, C, W, Dcx, Dcy;
};

__attribute__((always_inline)) inline void PeakBody(
  const PeakSplat* splats, const float* local, float* acc, int reps, float P1, float P2, float k2)
{
  for (int rep = 0; rep < reps; ++rep)
  {
    for (int s = 0; s < PeakSplats; ++s)
    {
      const float a = splats[s].A, b2 = splats[s].B2, c = splats[s].C, w = splats[s].W;
      const float dcx = splats[s].Dcx, dcy = splats[s].Dcy;
      for (int r = 0; r < PeakRows; ++r)
      {
        const float dy = r * P2 - dcy;
        const float xrow = r * P1 - dcx;
        const float cdy2 = c * dy * dy;
        const float bdy = b2 * dy;
        float* out = acc + r * PeakCols;
        for (int q = 0; q < PeakCols; ++q)
        {
          const float dx = local[q] + xrow;
          const float form = dx * (a * dx + bdy) + cdy2;
          const float value = w * bigus::FastExp(-0.5f * form);
          out[q] += form <= k2 ? value : 0.0f;
        }
      }
    }
  }
}

using PeakKernel = void (*)(const PeakSplat*, const float*, float*, int, float, float, float);

// The same ISAs as the library's clones (bigusCpuRenderer.cxx: target_clones "arch=x86-64-v3" and
// "default"), plus AVX-512 for the machine's own peak. This file is compiled with -fno-trapping-math
// like bigusCpuRenderer.cxx, so the selects are if-converted and the loop vectorises on every ISA.
__attribute__((noinline)) void PeakBaseline(
  const PeakSplat* s, const float* l, float* acc, int reps, float P1, float P2, float k2)
{
  PeakBody(s, l, acc, reps, P1, P2, k2);
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define BIGUS_PEAK_CLONES 1
__attribute__((noinline, target("arch=x86-64-v3"))) void PeakAvx2(
  const PeakSplat* s, const float* l, float* acc, int reps, float P1, float P2, float k2)
{
  PeakBody(s, l, acc, reps, P1, P2, k2);
}

__attribute__((noinline, target("arch=x86-64-v4,prefer-vector-width=512"))) void PeakAvx512(
  const PeakSplat* s, const float* l, float* acc, int reps, float P1, float P2, float k2)
{
  PeakBody(s, l, acc, reps, P1, P2, k2);
}
#endif

/// Evaluations per second of @p kernel on every core (best of three runs of about 0.25 s).
double MeasurePeak(PeakKernel kernel)
{
  const int threads = std::max(1, vtkSMPTools::GetEstimatedNumberOfThreads());
  const std::int64_t perRep = std::int64_t(PeakSplats) * PeakRows * PeakCols;
  std::vector<double> sink(1024, 0.0);
  auto run = [&](int chunks, int reps) {
    const double t0 = Now();
    vtkSMPTools::For(0, chunks, 1, [&](int begin, int end) {
      alignas(64) float acc[PeakRows * PeakCols];
      alignas(64) float local[PeakCols];
      PeakSplat splats[PeakSplats];
      for (int t = begin; t < end; ++t)
      {
        std::fill(acc, acc + PeakRows * PeakCols, 0.0f);
        for (int q = 0; q < PeakCols; ++q)
        {
          local[q] = 0.3f * q;
        }
        for (int s = 0; s < PeakSplats; ++s)
        {
          // Footprints a few mm wide centred in the block: forms from 0 to a few tens.
          splats[s] = {
            0.05f + 0.001f * s,
            0.01f,
            0.08f,
            0.1f,
            9.0f + 0.05f * s,
            2.4f,
          };
        }
        kernel(splats, local, acc, reps, 0.0f, 0.3f, 16.0f);
        double total = 0;
        for (float v : acc)
        {
          total += v;
        }
        sink[t % sink.size()] += total;
      }
    });
    return Now() - t0;
  };
  const int chunks = 8 * threads;
  int reps = 4;
  run(threads, reps); // warm-up
  double t = run(chunks, reps);
  while (t < 0.1)
  {
    reps *= 2;
    t = run(chunks, reps);
  }
  reps = std::max(1, static_cast<int>(reps * 0.25 / t));
  double best = 1e300;
  for (int k = 0; k < 3; ++k)
  {
    best = std::min(best, run(chunks, reps));
  }
  benchmark::DoNotOptimize(sink.data());
  return double(chunks) * reps * perRep / best;
}
}

Peak& GetPeak()
{
  static Peak peak = [] {
    Peak p;
    p.Baseline = MeasurePeak(PeakBaseline);
#ifdef BIGUS_PEAK_CLONES
    __builtin_cpu_init();
    if (__builtin_cpu_supports("x86-64-v3"))
    {
      p.Avx2 = MeasurePeak(PeakAvx2);
    }
    if (__builtin_cpu_supports("x86-64-v4"))
    {
      p.Avx512 = MeasurePeak(PeakAvx512);
    }
#endif
    return p;
  }();
  return peak;
}
}
