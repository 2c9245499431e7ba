// BenchmarkRenderer: Google Benchmark timings of the CPU backend of the beam-integrated Gaussian renderer,
// and of the CUDA backend wherever the registry offers it (a build with nvcc on a machine with a GPU):
// its rows, BM_Forward/cuda and BM_Backward/cuda, stand next to the CPU rows in Google Benchmark's table
// (the summary below is the CPU's).
//
// The scene is realistic in extent and pose: Gaussians spread uniformly over the bounding box of every
// frame corner of the liver sweep (Examples/Data/liver/liver_sweep.igs.mha), sliced with the pose of its
// frame 70, the pixel grid rescaled so that W x W pixels cover the 739 x 593 frame's field of view.
//
// Printed, besides Google Benchmark's own table:
//   - the machine's peak for phase 2's arithmetic (FastExp plus the conic form, vectorised, on every
//     core, data in L1), for the library's own compile flags and for the best ISA the CPU has;
//   - per case: ms per slice forward / backward, Gaussians kept, pixel evaluations, evaluations per
//     second, setup / raster split, fraction of the peak reached in phase 2;
//   - the speed-up over the naive double renderer (measured at 10k Gaussians, 256 x 256; extrapolated
//     linearly in N * pixels elsewhere);
//   - a cutoff sweep: forward time at 100k / 512 and max |I_cpu - I_naive| at 10k / 128.
//
// Usage: BenchmarkRenderer [--benchmark_filter=...] [other Google Benchmark flags]
#include "bigusBackend.h"
#include "bigusBackendCheck.h"
#include "bigusReferenceRenderer.h"
#include "bigusRenderer.h"
#include "bigusRendererPeak.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkSMPTools.h"
#include "vtkUltrasoundSequenceReader.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#ifndef BIGUS_EXAMPLE_DATA
#define BIGUS_EXAMPLE_DATA "Examples/Data"
#endif

namespace
{
using bigus::rendererbenchmark::GetPeak;
using bigus::rendererbenchmark::Now;
using bigus::rendererbenchmark::Peak;

[[noreturn]] void Die(const std::string& message)
{
  std::fprintf(stderr, "BenchmarkRenderer: %s\n", message.c_str());
  std::exit(1);
}

// ---------------------------------------------------------------------------------------------
// Scene: bounding box of the sweep and the pose of the middle frame.

constexpr int PoseFrame = 70;

struct Scene
{
  double BoxMin[3], BoxMax[3];
  double Pose[16]; // frame 70, row-major, pixel index -> mm
  int FrameWidth = 0, FrameHeight = 0, Frames = 0, ValidFrames = 0;
};

const Scene& GetScene()
{
  static const Scene scene = [] {
    Scene s;
    const std::string file = std::string(BIGUS_EXAMPLE_DATA) + "/liver/liver_sweep.igs.mha";
    vtkNew<vtkUltrasoundSequenceReader> reader;
    reader->SetFileName(file.c_str());
    reader->Update();
    if (*reader->GetLastErrorText())
    {
      Die(reader->GetLastErrorText());
    }
    vtkImageData* frames = reader->GetOutput();
    int dims[3];
    frames->GetDimensions(dims);
    s.FrameWidth = dims[0];
    s.FrameHeight = dims[1];
    s.Frames = dims[2];
    vtkDataArray* poses = frames->GetFieldData()->GetArray("ImageToReference");
    vtkDataArray* valid = frames->GetFieldData()->GetArray("FrameValid");
    if (!poses || poses->GetNumberOfComponents() != 16 || poses->GetNumberOfTuples() != dims[2] || !valid)
    {
      Die("no ImageToReference / FrameValid field data in " + file);
    }
    if (dims[2] <= PoseFrame || valid->GetTuple1(PoseFrame) == 0)
    {
      Die("frame 70 of " + file + " is missing or invalid");
    }
    for (int k = 0; k < 3; ++k)
    {
      s.BoxMin[k] = 1e300;
      s.BoxMax[k] = -1e300;
    }
    for (int f = 0; f < dims[2]; ++f)
    {
      if (valid->GetTuple1(f) == 0)
      {
        continue;
      }
      ++s.ValidFrames;
      double m[16];
      poses->GetTuple(f, m);
      const double corners[4][2] = { { 0, 0 }, { dims[0] - 1.0, 0 }, { 0, dims[1] - 1.0 },
        { dims[0] - 1.0, dims[1] - 1.0 } };
      for (const auto& c : corners)
      {
        for (int k = 0; k < 3; ++k)
        {
          const double x = m[4 * k] * c[0] + m[4 * k + 1] * c[1] + m[4 * k + 3];
          s.BoxMin[k] = std::min(s.BoxMin[k], x);
          s.BoxMax[k] = std::max(s.BoxMax[k], x);
        }
      }
    }
    poses->GetTuple(PoseFrame, s.Pose);
    return s;
  }();
  return scene;
}

/// The pose of frame 70 with a W x H grid over the frame's field of view.
bigus::SliceGeometry MakeSlice(int width, int height)
{
  const Scene& scene = GetScene();
  bigus::SliceGeometry g;
  std::copy(scene.Pose, scene.Pose + 16, g.ImageToReference);
  const double su = double(scene.FrameWidth) / width, sv = double(scene.FrameHeight) / height;
  for (int r = 0; r < 3; ++r)
  {
    g.ImageToReference[4 * r] *= su;
    g.ImageToReference[4 * r + 1] *= sv;
  }
  g.Width = width;
  g.Height = height;
  return g;
}

/// The same slice moved 1 m along its normal, away from every Gaussian: what a call costs when nothing
/// is visible (the per-call work over all N Gaussians that does not depend on visibility).
bigus::SliceGeometry MakeEmptySlice(int width, int height)
{
  bigus::SliceGeometry g = MakeSlice(width, height);
  const double* m = g.ImageToReference;
  double n[3] = { m[4] * m[9] - m[8] * m[5], m[8] * m[1] - m[0] * m[9], m[0] * m[5] - m[4] * m[1] };
  const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  for (int r = 0; r < 3; ++r)
  {
    g.ImageToReference[4 * r + 3] += 1000.0 * n[r] / length;
  }
  return g;
}

// ---------------------------------------------------------------------------------------------
// Random fields (fixed seed), cached per size.

using Field = bigus::HostField;

const Field& GetField(std::int64_t n)
{
  static std::map<std::int64_t, std::unique_ptr<Field>> cache;
  auto& slot = cache[n];
  if (!slot)
  {
    const Scene& scene = GetScene();
    slot.reset(new Field);
    Field& f = *slot;
    std::mt19937_64 rng(20240611ULL);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    std::uniform_real_distribution<double> scale(0.3, 2.0);
    std::normal_distribution<double> normal(0.0, 1.0);
    std::normal_distribution<double> reflectivity(0.05, 0.3);
    f.Means.resize(3 * n);
    f.LogScales.resize(3 * n);
    f.Quaternions.resize(4 * n);
    f.Reflectivities.resize(n);
    for (std::int64_t i = 0; i < n; ++i)
    {
      for (int k = 0; k < 3; ++k)
      {
        f.Means[3 * i + k] = static_cast<float>(scene.BoxMin[k] + unit(rng) * (scene.BoxMax[k] - scene.BoxMin[k]));
        f.LogScales[3 * i + k] = static_cast<float>(std::log(scale(rng)));
      }
      double q[4], norm2 = 0;
      do
      {
        norm2 = 0;
        for (double& c : q)
        {
          c = normal(rng);
          norm2 += c * c;
        }
      } while (norm2 < 1e-12);
      for (int k = 0; k < 4; ++k)
      {
        f.Quaternions[4 * i + k] = static_cast<float>(q[k] / std::sqrt(norm2));
      }
      f.Reflectivities[i] = static_cast<float>(reflectivity(rng));
    }
  }
  return *slot;
}

bigus::RenderOptions Options(double cutoff)
{
  bigus::RenderOptions o; // sigma_E = 0.5 mm, gamma = 1
  o.ElevationSigma = 0.5;
  o.Gamma = 1.0;
  o.Cutoff = cutoff;
  return o;
}

// ---------------------------------------------------------------------------------------------
// Results kept for the summary tables (the last run of each benchmark wins).

struct ForwardResult
{
  double Ms = 0, SetupMs = 0, RasterMs = 0;
  std::int64_t Kept = 0, Evals = 0, TileEntries = 0;
};
struct BackwardResult
{
  double Ms = 0;
  std::int64_t Kept = 0, Evals = 0;
};

std::map<std::tuple<std::int64_t, int, int>, ForwardResult> ForwardResults; // N, W, cutoff x 10
std::map<std::pair<std::int64_t, int>, BackwardResult> BackwardResults;     // N, W
std::map<std::int64_t, std::pair<double, double>> EmptyResults;             // N -> forward, backward ms

const std::vector<float>& GetGradientImage(int width, int height)
{
  static std::map<std::pair<int, int>, std::vector<float>> cache;
  auto& image = cache[{ width, height }];
  if (image.empty())
  {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    image.resize(std::size_t(width) * height);
    for (float& v : image)
    {
      v = u(rng);
    }
  }
  return image;
}

/// The renderer of @p backend, or null after marking @p state skipped with the registry's reason.
std::unique_ptr<bigus::Renderer> MakeRenderer(benchmark::State& state, const std::string& backend)
{
  std::string error;
  std::unique_ptr<bigus::Renderer> renderer = bigus::CreateRenderer(backend, &error);
  if (!renderer)
  {
    state.SkipWithError(error.c_str());
  }
  return renderer;
}

/// Forward timings of @p backend; the CPU's also feed the summary.
void RunForward(benchmark::State& state, const std::string& backend)
{
  const std::int64_t n = state.range(0);
  const int width = static_cast<int>(state.range(1));
  const int cutoff10 = static_cast<int>(state.range(2));
  const bigus::FieldView field = GetField(n).View();
  const bigus::SliceGeometry slice = MakeSlice(width, width);
  const bigus::RenderOptions options = Options(cutoff10 / 10.0);
  auto renderer = MakeRenderer(state, backend);
  if (!renderer)
  {
    return;
  }
  std::vector<float> S(std::size_t(width) * width), I(S.size());
  std::string error;
  if (!renderer->Forward(field, &slice, 1, options, S.data(), I.data(), nullptr, &error)) // warm-up
  {
    state.SkipWithError(error.c_str());
    return;
  }
  bigus::RenderStats total;
  double wall = 0;
  for (auto _ : state)
  {
    const double t0 = Now();
    renderer->Forward(field, &slice, 1, options, S.data(), I.data(), &total, &error);
    wall += Now() - t0;
    benchmark::ClobberMemory();
  }
  const double it = static_cast<double>(state.iterations());
  ForwardResult r;
  r.Ms = 1e3 * wall / it;
  r.SetupMs = 1e3 * total.SetupSeconds / it;
  r.RasterMs = 1e3 * total.RasterSeconds / it;
  r.Kept = static_cast<std::int64_t>(total.GaussiansVisible / it);
  r.Evals = static_cast<std::int64_t>(total.PixelEvaluations / it);
  r.TileEntries = static_cast<std::int64_t>(total.TileEntries / it);
  if (backend == "cpu")
  {
    ForwardResults[{ n, width, cutoff10 }] = r;
  }
  const double phase2 = r.Evals / (r.RasterMs * 1e-3);
  state.counters["ms/slice"] = r.Ms;
  state.counters["setup_ms"] = r.SetupMs;
  state.counters["raster_ms"] = r.RasterMs;
  state.counters["kept"] = static_cast<double>(r.Kept);
  state.counters["pix_evals"] = static_cast<double>(r.Evals);
  state.counters["evals/s"] = r.Evals / (r.Ms * 1e-3);
  state.counters["ph2_evals/s"] = phase2;
  state.counters["peak_frac"] = phase2 / GetPeak().Best();
  state.counters["lib_peak_frac"] = phase2 / GetPeak().Library();
}

void BM_Backward(benchmark::State& state, const std::string& backend)
{
  const std::int64_t n = state.range(0);
  const int width = static_cast<int>(state.range(1));
  const Field& host = GetField(n);
  const bigus::FieldView field = host.View();
  const bigus::SliceGeometry slice = MakeSlice(width, width);
  const bigus::RenderOptions options = Options(4.0);
  auto renderer = MakeRenderer(state, backend);
  if (!renderer)
  {
    return;
  }
  std::vector<float> S(std::size_t(width) * width), I(S.size());
  std::string error;
  bigus::RenderStats forward;
  if (!renderer->Forward(field, &slice, 1, options, S.data(), I.data(), &forward, &error))
  {
    state.SkipWithError(error.c_str());
    return;
  }
  const std::vector<float>& dL = GetGradientImage(width, width);
  std::vector<float> gMeans(3 * n), gLogScales(3 * n), gQuaternions(4 * n), gReflectivities(n), gAttribution(n);
  bigus::FieldGradients gradients;
  gradients.Means = gMeans.data();
  gradients.LogScales = gLogScales.data();
  gradients.Quaternions = gQuaternions.data();
  gradients.Reflectivities = gReflectivities.data();
  gradients.Attribution = gAttribution.data();
  renderer->Backward(field, &slice, 1, options, S.data(), dL.data(), false, gradients, nullptr, &error); // warm-up
  double wall = 0;
  for (auto _ : state)
  {
    const double t0 = Now();
    renderer->Backward(field, &slice, 1, options, S.data(), dL.data(), false, gradients, nullptr, &error);
    wall += Now() - t0;
    benchmark::ClobberMemory();
  }
  BackwardResult r;
  r.Ms = 1e3 * wall / static_cast<double>(state.iterations());
  r.Kept = forward.GaussiansVisible; // Backward's stats hold only the time; the work is forward's
  r.Evals = forward.PixelEvaluations;
  if (backend == "cpu")
  {
    BackwardResults[{ n, width }] = r;
  }
  state.counters["ms/slice"] = r.Ms;
  state.counters["kept"] = static_cast<double>(r.Kept);
  state.counters["pix_evals"] = static_cast<double>(r.Evals);
  state.counters["evals/s"] = r.Evals / (r.Ms * 1e-3);
}

/// Forward and backward on the slice that sees nothing (W = 256): the visibility-independent cost.
void BM_NothingVisible(benchmark::State& state)
{
  const std::int64_t n = state.range(0);
  const bigus::FieldView field = GetField(n).View();
  const bigus::SliceGeometry slice = MakeEmptySlice(256, 256);
  const bigus::RenderOptions options = Options(4.0);
  auto renderer = bigus::CreateCpuRenderer();
  std::vector<float> S(256 * 256), I(S.size()), dL(S.size(), 1.0f), gR(n);
  bigus::FieldGradients gradients;
  gradients.Reflectivities = gR.data();
  std::string error;
  bigus::RenderStats stats;
  renderer->Forward(field, &slice, 1, options, S.data(), I.data(), &stats, &error);
  renderer->Backward(field, &slice, 1, options, S.data(), dL.data(), false, gradients, nullptr, &error);
  if (stats.GaussiansVisible != 0)
  {
    state.SkipWithError("the far slice sees Gaussians");
    return;
  }
  double forward = 0, backward = 0;
  for (auto _ : state)
  {
    const double t0 = Now();
    renderer->Forward(field, &slice, 1, options, S.data(), I.data(), nullptr, &error);
    const double t1 = Now();
    renderer->Backward(field, &slice, 1, options, S.data(), dL.data(), false, gradients, nullptr, &error);
    forward += t1 - t0;
    backward += Now() - t1;
  }
  const double it = static_cast<double>(state.iterations());
  EmptyResults[n] = { 1e3 * forward / it, 1e3 * backward / it };
  state.counters["fwd_ms"] = 1e3 * forward / it;
  state.counters["bwd_ms"] = 1e3 * backward / it;
}

const std::vector<std::int64_t> Sizes = { 10000, 100000, 1000000 };
const std::vector<std::int64_t> Widths = { 256, 512 };
const std::vector<std::int64_t> Cutoffs10 = { 20, 30, 35, 40, 50, 60 };

void Register()
{
  const std::vector<std::string> names = bigus::AvailableBackends();
  const bool cuda = std::find(names.begin(), names.end(), "cuda") != names.end();
  for (const std::string backend : { "cpu", "cuda" })
  {
    if (backend == "cuda" && !cuda)
    {
      continue;
    }
    const std::string suffix = backend == "cpu" ? "" : "/" + backend;
    benchmark::RegisterBenchmark(("BM_Forward" + suffix).c_str(), RunForward, backend)
      ->ArgsProduct({ Sizes, Widths, { 40 } })
      ->ArgNames({ "N", "W", "k10" })
      ->UseRealTime()
      ->MinTime(0.5)
      ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("BM_Backward" + suffix).c_str(), BM_Backward, backend)
      ->ArgsProduct({ Sizes, Widths })
      ->ArgNames({ "N", "W" })
      ->UseRealTime()
      ->MinTime(0.5)
      ->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark("BM_ForwardCutoff", RunForward, std::string("cpu"))
    ->ArgsProduct({ { 100000 }, { 512 }, Cutoffs10 })
    ->ArgNames({ "N", "W", "k10" })
    ->UseRealTime()
    ->MinTime(0.3)
    ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("BM_NothingVisible", BM_NothingVisible)
    ->ArgsProduct({ { 100000, 1000000 } })
    ->ArgNames({ "N" })
    ->UseRealTime()
    ->MinTime(0.3)
    ->Unit(benchmark::kMillisecond);
}

// ---------------------------------------------------------------------------------------------
// Summary.

std::string Count(double v)
{
  char buffer[32];
  if (v >= 1e9)
    std::snprintf(buffer, sizeof(buffer), "%.2fG", v / 1e9);
  else if (v >= 1e6)
    std::snprintf(buffer, sizeof(buffer), "%.2fM", v / 1e6);
  else if (v >= 1e3)
    std::snprintf(buffer, sizeof(buffer), "%.1fk", v / 1e3);
  else
    std::snprintf(buffer, sizeof(buffer), "%.0f", v);
  return buffer;
}

/// Time of the naive double renderer on one slice.
double TimeNaive(const bigus::reference::FieldD& field, const bigus::SliceGeometry& slice, double cutoff,
  std::vector<double>& S, std::vector<double>& I)
{
  const double t0 = Now();
  if (!bigus::reference::Forward(field, slice, Options(cutoff), S, &I))
  {
    Die("the naive renderer rejected the slice");
  }
  return Now() - t0;
}

void PrintSummary()
{
  const Scene& scene = GetScene();
  const Peak& peak = GetPeak();
  std::printf("\n================ BIGUS CPU renderer benchmark summary ================\n");
  std::printf("Scene: liver sweep, %d frames (%d valid) of %d x %d; Gaussians uniform in the corner box\n",
    scene.Frames, scene.ValidFrames, scene.FrameWidth, scene.FrameHeight);
  std::printf("  [%.1f, %.1f] x [%.1f, %.1f] x [%.1f, %.1f] mm; slice = pose of frame %d, W x W pixels over the\n"
              "  frame's field of view; sigma_E 0.5 mm, gamma 1, scales U[0.3, 2] mm, r ~ N(0.05, 0.3^2)\n",
    scene.BoxMin[0], scene.BoxMax[0], scene.BoxMin[1], scene.BoxMax[1], scene.BoxMin[2], scene.BoxMax[2], PoseFrame);
  std::printf("Threads (vtkSMPTools %s): %d\n", vtkSMPTools::GetBackend(), vtkSMPTools::GetEstimatedNumberOfThreads());
  std::printf("\nPeak of phase 2's arithmetic (FastExp + conic form, L1-resident, all threads):\n");
  std::printf("  baseline x86-64 (SSE2, the library's 'default' clone): %s evals/s\n", Count(peak.Baseline).c_str());
  if (peak.Avx2 > 0)
    std::printf("  x86-64-v3, AVX2 + FMA (the library's fast clone):     %s evals/s\n", Count(peak.Avx2).c_str());
  if (peak.Avx512 > 0)
    std::printf("  x86-64-v4, AVX-512 (512-bit vectors):                 %s evals/s\n", Count(peak.Avx512).c_str());
  std::printf("  machine peak = %s (%s)\n", Count(peak.Best()).c_str(), peak.BestName());

  // Naive reference: 10k Gaussians at 256 x 256, once.
  double naive256 = 0;
  const bool haveForward = !ForwardResults.empty();
  if (haveForward)
  {
    std::printf("\nTiming the naive double renderer (bigus::reference::Forward) at 10k Gaussians, 256 x 256 ...\n");
    std::fflush(stdout);
    const bigus::reference::FieldD field = bigus::reference::FromView(GetField(10000).View());
    std::vector<double> S, I;
    naive256 = TimeNaive(field, MakeSlice(256, 256), 4.0, S, I);
    std::printf("  naive: %.1f ms (%s Gaussian-pixel evaluations/s, one thread, double)\n", 1e3 * naive256,
      Count(10000.0 * 256 * 256 / naive256).c_str());
  }

  std::printf("\nForward and backward, cutoff k = 4 (per slice):\n");
  std::printf("%8s %4s | %9s %8s %9s %8s %8s %10s %10s %7s %7s | %9s %9s %7s | %9s\n", "N", "W", "fwd ms", "setup",
    "raster", "kept", "kept%", "pix evals", "evals/s", "ph2 %pk", "%libpk", "bwd ms", "evals/s", "bwd/fwd", "vs naive");
  for (std::int64_t n : Sizes)
  {
    for (std::int64_t w : Widths)
    {
      const auto f = ForwardResults.find({ n, static_cast<int>(w), 40 });
      const auto b = BackwardResults.find({ n, static_cast<int>(w) });
      if (f == ForwardResults.end() && b == BackwardResults.end())
      {
        continue;
      }
      std::printf("%8s %4d |", Count(double(n)).c_str(), static_cast<int>(w));
      if (f != ForwardResults.end())
      {
        const ForwardResult& r = f->second;
        const double phase2 = r.Evals / (r.RasterMs * 1e-3);
        std::printf(" %9.3f %8.3f %9.3f %8s %7.2f%% %10s %10s %6.1f%% %6.1f%% |", r.Ms, r.SetupMs, r.RasterMs,
          Count(double(r.Kept)).c_str(), 100.0 * r.Kept / n, Count(double(r.Evals)).c_str(),
          Count(r.Evals / (r.Ms * 1e-3)).c_str(), 100.0 * phase2 / peak.Best(), 100.0 * phase2 / peak.Library());
      }
      else
      {
        std::printf(" %9s %8s %9s %8s %8s %10s %10s %7s %7s |", "-", "-", "-", "-", "-", "-", "-", "-", "-");
      }
      if (b != BackwardResults.end())
      {
        const BackwardResult& r = b->second;
        std::printf(" %9.3f %9s", r.Ms, Count(r.Evals / (r.Ms * 1e-3)).c_str());
        if (f != ForwardResults.end())
          std::printf(" %7.2f |", r.Ms / f->second.Ms);
        else
          std::printf(" %7s |", "-");
      }
      else
      {
        std::printf(" %9s %9s %7s |", "-", "-", "-");
      }
      if (f != ForwardResults.end() && naive256 > 0)
      {
        const double naive = naive256 * (double(n) * w * w) / (10000.0 * 256 * 256);
        std::printf(
          " %8.0fx%s", naive / (1e-3 * f->second.Ms), (n == 10000 && w == 256) ? " (measured)" : " (extrap.)");
      }
      std::printf("\n");
    }
  }
  std::printf("  kept = Gaussians left after culling (RenderStats.GaussiansVisible); pix evals = Gaussian-pixel pairs\n"
              "  evaluated; evals/s = pix evals / whole-slice time; ph2 %%pk = (pix evals / RasterSeconds) / machine\n"
              "  peak, %%libpk the same against the peak of the ISA the library runs here. Backward's kept / evals\n"
              "  are forward's (the backward pass evaluates the same boxes). 'vs naive' = naive time / CPU forward "
              "time; the naive time\n"
              "  is measured at 10k / 256 only and extrapolated linearly in N * pixels for the other cases.\n");

  if (!EmptyResults.empty())
  {
    std::printf("\nFixed per-call cost, slice moved 1 m away so that no Gaussian is visible (256 x 256):\n");
    for (const auto& e : EmptyResults)
    {
      std::printf("  N = %s: forward %.3f ms, backward %.3f ms (work over all N that does not depend on visibility)\n",
        Count(double(e.first)).c_str(), e.second.first, e.second.second);
    }
  }

  // Cutoff sweep.
  bool haveSweep = false;
  for (std::int64_t k : Cutoffs10)
  {
    haveSweep = haveSweep || ForwardResults.count({ 100000, 512, static_cast<int>(k) });
  }
  if (haveSweep)
  {
    std::printf("\nCutoff sweep: forward at 100k / 512; error at 10k / 128 against the naive double renderer\n");
    std::fflush(stdout);
    const Field& small = GetField(10000);
    const bigus::reference::FieldD fieldD = bigus::reference::FromView(small.View());
    const bigus::SliceGeometry slice128 = MakeSlice(128, 128);
    std::vector<double> naiveS, naiveI;
    const double naive128 = TimeNaive(fieldD, slice128, 4.0, naiveS, naiveI);
    double maxI = 0;
    for (double v : naiveI)
      maxI = std::max(maxI, std::abs(v));
    std::printf("  (naive 10k / 128: %.1f ms; max |I_naive| = %.3f)\n", 1e3 * naive128, maxI);
    std::printf("%6s | %9s %8s %9s %8s %10s | %14s %14s\n", "k", "fwd ms", "setup", "raster", "kept", "pix evals",
      "max|dI| 10k/128", "max|dS| 10k/128");
    auto renderer = bigus::CreateCpuRenderer();
    const bigus::FieldView view = small.View();
    for (std::int64_t k : Cutoffs10)
    {
      std::vector<float> S(128 * 128), I(128 * 128);
      std::string error;
      renderer->Forward(view, &slice128, 1, Options(k / 10.0), S.data(), I.data(), nullptr, &error);
      double errI = 0, errS = 0;
      for (std::size_t p = 0; p < S.size(); ++p)
      {
        errI = std::max(errI, std::abs(I[p] - naiveI[p]));
        errS = std::max(errS, std::abs(S[p] - naiveS[p]));
      }
      std::printf("%6.1f |", k / 10.0);
      const auto f = ForwardResults.find({ 100000, 512, static_cast<int>(k) });
      if (f != ForwardResults.end())
      {
        std::printf(" %9.3f %8.3f %9.3f %8s %10s |", f->second.Ms, f->second.SetupMs, f->second.RasterMs,
          Count(double(f->second.Kept)).c_str(), Count(double(f->second.Evals)).c_str());
      }
      else
      {
        std::printf(" %9s %8s %9s %8s %10s |", "-", "-", "-", "-", "-");
      }
      std::printf(" %14.3e %14.3e\n", errI, errS);
    }
  }
  std::printf("=======================================================================\n");
}
} // namespace

int main(int argc, char** argv)
{
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv))
  {
    return 1;
  }
  const double t0 = Now();
  const Scene& scene = GetScene();
  std::printf("Read the liver sweep (%d x %d x %d) in %.2f s; measuring the phase-2 peak ...\n", scene.FrameWidth,
    scene.FrameHeight, scene.Frames, Now() - t0);
  std::fflush(stdout);
  const Peak& peak = GetPeak();
  std::printf("Peak: baseline %s, AVX2 %s, AVX-512 %s evals/s\n", Count(peak.Baseline).c_str(),
    Count(peak.Avx2).c_str(), Count(peak.Avx512).c_str());
  std::fflush(stdout);
  Register();
  benchmark::RunSpecifiedBenchmarks();
  PrintSummary();
  benchmark::Shutdown();
  std::printf("Total run time %.1f s\n", Now() - t0);
  return 0;
}
