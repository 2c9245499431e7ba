// The CUDA renderer against the CPU renderer (itself checked against the naive double renderer, which
// TestGaussianFootprint checks against quadrature): forward and gradients on the hard-case grid and on
// a liver field, slice batches, bit-identical repeats, bad poses, a field too large for the device,
// pose gradients, and the registry choosing it. Exits 125 (skipped) where no usable GPU exists.
#include "bigusBackend.h"
#include "bigusBackendCheck.h"
#include "bigusCudaDevice.h"
#include "bigusCudaImageLoss.h"
#include "bigusCudaRenderer.h"
#include "bigusGaussianFieldData.h"
#include "bigusImageLoss.h"
#include "bigusRendererTestUtilities.h"
#include "bigusThreadReduction.h"
#include "bigusTrainer.h"

#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundSequenceReader.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

using namespace bigus;
using namespace bigus::test;

namespace
{
using Rendered = RenderedGradients;

Rendered Render(Renderer& renderer, const FieldView& field, const std::vector<SliceGeometry>& slices,
  const RenderOptions& o, const std::vector<float>& dL)
{
  Rendered out;
  std::string error;
  EXPECT_TRUE(RenderWithGradients(renderer, field, slices.data(), static_cast<int>(slices.size()), o, dL, out, &error))
    << error;
  return out;
}

/// dL/dI: uniform in [-1, 1], fixed seed.
std::vector<float> RandomGradient(std::size_t pixels, unsigned seed)
{
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<float> g(pixels);
  for (float& v : g)
  {
    v = u(rng);
  }
  return g;
}

/**
 * As the backend self-check compares (bigus::CompareRenders): max |delta I| <= @p imageTolerance (the
 * issue's bound: 1e-5); against @p exact (RenderReference, the double reference cut at the same
 * footprints), every Gaussian's gradient error relative to its own (floor: 1e-3 of the largest) at most
 * max(@p gradientTolerance, twice the CPU's); without @p exact (fields too large for the naive reference),
 * every Gaussian's gradients within @p gradientTolerance of the CPU's; visible entries equal in total (a
 * Gaussian at the cull's edge may tie differently under fused multiply-adds), nothing NaN or Inf.
 */
void ExpectSameAsCpu(const Rendered& gpu, const Rendered& cpu, const std::string& what, double imageTolerance = 1e-5,
  double gradientTolerance = 1e-4, const Rendered* exact = nullptr)
{
  ASSERT_EQ(gpu.I.size(), cpu.I.size()) << what;
  ASSERT_EQ(gpu.Reflectivities.size(), cpu.Reflectivities.size()) << what;
  const BackendCheck c = CompareRenders(gpu, cpu, exact ? *exact : cpu, imageTolerance, gradientTolerance);
  EXPECT_TRUE(c.Passed) << what << ": " << c.Detail;
  std::printf("%s: %s; forward %.3f ms (CPU %.3f), backward %.3f ms (CPU %.3f)\n", what.c_str(), c.Detail.c_str(),
    1e3 * (gpu.Forward.SetupSeconds + gpu.Forward.RasterSeconds),
    1e3 * (cpu.Forward.SetupSeconds + cpu.Forward.RasterSeconds), 1e3 * gpu.Backward.RasterSeconds,
    1e3 * cpu.Backward.RasterSeconds);
}

/// The double reference renderer's S, I and gradients for the same inputs (RenderReference).
Rendered Exact(const FieldView& field, const std::vector<SliceGeometry>& slices, const RenderOptions& o,
  const std::vector<float>& dL)
{
  Rendered out;
  std::string error;
  EXPECT_TRUE(RenderReference(field, slices.data(), static_cast<int>(slices.size()), o, dL, out, &error)) << error;
  return out;
}

std::unique_ptr<Renderer> Cuda()
{
  std::string error;
  std::unique_ptr<Renderer> r = cuda::CreateCudaRenderer(&error);
  EXPECT_TRUE(r) << error;
  return r;
}

/// The bundled liver sweep as training data, frames with k mod 4 == 2 held out.
TrainingData LiverData()
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName((std::string(BIGUS_EXAMPLE_DATA) + "/liver/liver_sweep.igs.mha").c_str());
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputConnection(reader->GetOutputPort());
  fan->Update();
  TrainingData d;
  std::string error;
  EXPECT_TRUE(TrainingDataFromSequence(reader->GetOutput(), fan->GetOutput(), d, &error)) << error;
  for (int k = 0; k < d.Count(); ++k)
  {
    if (k % 4 != 2)
    {
      d.TrainFrames.push_back(k);
    }
  }
  return d;
}
}

TEST(CudaRenderer, MatchesTheCpuOnTheHardCaseGrid)
{
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  auto cpu = CreateCpuRenderer();
  // Two slices in one call: the grid's own and one moved 1.3 mm along the reference y axis (partly out
  // of its plane), to check the batch.
  const std::vector<SliceGeometry> slices = { HardCaseSlice(), HardCaseSlice(1.3) };
  const std::vector<float> dL = RandomGradient(2 * 160 * 112, 5);
  // Images against the CPU's, gradients against the double reference as accurately as the CPU's (or
  // within the family's bound). Scale ratios up to 100 at the bounds. At 1e3 and 1e4 the footprint's minor-axis
  // term (cos dy - sin dx) / sigma_minor subtracts two products of a few mm, so one float rounding moves it by ~5e-7 mm
  // / sigma_minor (2e-4 mm and less): a backend that fuses multiply-adds differently (nvcc by default, GCC's AVX2
  // clone) moves I by up to ~1e-3 near the footprint's edge, as the CPU clones differ from each other
  // (TestGaussianFootprint bounds the weight by the same aspect-ratio growth).
  const struct
  {
    std::vector<double> Ratios;
    double Image, Gradient;
  } families[] = { { { 1.0, 10.0, 100.0 }, 1e-5, 1e-4 }, { { 1e3, 1e4 }, 5e-3, 2e-2 } };
  for (const auto& family : families)
  {
    for (double sigmaE : { 1e-4, 1e-2, 0.5, 5.0, 100.0 })
    {
      for (bool beam : { true, false })
      {
        const HostField field = HardCaseField(sigmaE, family.Ratios);
        RenderOptions o;
        o.ElevationSigma = sigmaE;
        o.BeamIntegration = beam;
        o.Cutoff = 5;
        const std::string what = "grid, ratios to " + std::to_string(family.Ratios.back()) + ", sigma_E " +
          std::to_string(sigmaE) + (beam ? "" : ", thin plane");
        const Rendered g = Render(*gpu, field.View(), slices, o, dL);
        const Rendered c = Render(*cpu, field.View(), slices, o, dL);
        const Rendered e = Exact(field.View(), slices, o, dL);
        ExpectSameAsCpu(g, c, what, family.Image, family.Gradient, &e);
        EXPECT_TRUE(std::any_of(c.S.begin(), c.S.end(), [](float v) { return v != 0; })) << what;
      }
    }
  }
}

TEST(CudaRenderer, MatchesTheCpuOnALiverField)
{
  TrainingData data = LiverData();
  ASSERT_GT(data.Count(), 100);
  TrainerSettings settings;
  settings.ElevationSigma = 0.3;
  settings.Seeding.InitialGaussians = 200000;
  Trainer trainer(data, settings);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  const FieldView field = trainer.GetField().View();
  std::printf("liver field: %lld Gaussians (Harris seeds)\n", static_cast<long long>(field.Count));
  RenderOptions o;
  o.ElevationSigma = 0.3;
  o.Gamma = trainer.GetReport().Gamma > 0 ? trainer.GetReport().Gamma : 1.0;
  o.Cutoff = 5;
  const std::vector<SliceGeometry> slices = { data.Slice(2), data.Slice(70) };
  const std::vector<float> dL = RandomGradient(2 * std::size_t(data.Width) * data.Height, 9);
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  auto cpu = CreateCpuRenderer();
  ExpectSameAsCpu(Render(*gpu, field, slices, o, dL), Render(*cpu, field, slices, o, dL), "liver frames 2 and 70");
}

TEST(CudaRenderer, RepeatedRunsAreBitIdentical)
{
  const double centre[3] = { 120.0, -40.0, 80.0 };
  const FieldF field = ToFloat(RandomField(20000, centre, 40.0, 0.05, 0.3, 3));
  const double axis[3] = { 0.2, 0.9, -0.3 };
  const double origin[3] = { centre[0] - 19.2, centre[1] - 19.2, centre[2] };
  const std::vector<SliceGeometry> slices = { MakeSlice(256, 192, 0.15, 35, axis, origin) };
  const std::vector<float> dL = RandomGradient(256 * 192, 2);
  RenderOptions o;
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  const Rendered first = Render(*gpu, field.View(), slices, o, dL);
  for (int run = 0; run < 3; ++run)
  {
    const Rendered again = Render(*gpu, field.View(), slices, o, dL);
    for (const auto& [a, b] : { std::make_pair(&first.S, &again.S), std::make_pair(&first.Means, &again.Means),
           std::make_pair(&first.LogScales, &again.LogScales), std::make_pair(&first.Quaternions, &again.Quaternions),
           std::make_pair(&first.Reflectivities, &again.Reflectivities),
           std::make_pair(&first.Attribution, &again.Attribution) })
    {
      ASSERT_EQ(a->size(), b->size());
      EXPECT_EQ(std::memcmp(a->data(), b->data(), sizeof(float) * a->size()), 0) << "run " << run;
    }
  }
}

TEST(CudaRenderer, BadPosesAreRejectedWithAReason)
{
  const HostField field = HardCaseField(0.5, { 1.0, 10.0 });
  std::vector<SliceGeometry> slices = { HardCaseSlice(), HardCaseSlice() };
  for (int k = 0; k < 3; ++k)
  {
    slices[1].ImageToReference[4 * k] = 0; // first image axis of length 0
  }
  std::vector<float> S(2 * 160 * 112, -7.f);
  std::string error;
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  RenderOptions o;
  EXPECT_FALSE(gpu->Forward(field.View(), slices.data(), 2, o, S.data(), nullptr, nullptr, &error));
  EXPECT_NE(error.find("slice 1"), std::string::npos) << error;
  EXPECT_NE(error.find("singular"), std::string::npos) << error;
  EXPECT_TRUE(std::all_of(S.begin(), S.end(), [](float v) { return v == -7.f; })) << "nothing written";
}

TEST(CudaRenderer, AFieldTooLargeForTheDeviceIsRefusedBeforeAllocating)
{
  cuda::DeviceInfo info;
  std::string why;
  ASSERT_TRUE(cuda::QueryDevice(info, why)) << why;
  // Twice what the whole device holds (or the most the backend indexes); the arrays behind the view
  // are small: a renderer that read them before refusing would fail here under the sanitizers.
  const double memory = info.MemoryGiB * 1073741824.0;
  const std::int64_t n = static_cast<std::int64_t>(std::min(2 * memory / cuda::DeviceBytesPerGaussian(), 2147483647.0));
  if (double(n) * cuda::DeviceBytesPerGaussian(true) <= memory) // Backward needs less than Forward
  {
    GTEST_SKIP() << "the device holds the largest field the backend indexes (2^31 - 1 Gaussians)";
  }
  const HostField small = HardCaseField(0.5, { 1.0, 10.0 });
  FieldView huge = small.View();
  huge.Count = n;
  const std::vector<SliceGeometry> slices = { HardCaseSlice() };
  std::vector<float> S(160 * 112, -7.f), dL(160 * 112, 1.f), gr(16, 0.f);
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  RenderOptions o;
  std::string error;
  EXPECT_FALSE(gpu->Forward(huge, slices.data(), 1, o, S.data(), nullptr, nullptr, &error));
  EXPECT_NE(error.find("MiB of device memory"), std::string::npos) << error;
  EXPECT_NE(error.find(std::to_string(n) + " Gaussians"), std::string::npos) << error;
  EXPECT_TRUE(std::all_of(S.begin(), S.end(), [](float v) { return v == -7.f; })) << "nothing written";
  FieldGradients grads;
  grads.Reflectivities = gr.data();
  error.clear();
  EXPECT_FALSE(gpu->Backward(huge, slices.data(), 1, o, S.data(), dL.data(), false, grads, nullptr, &error));
  EXPECT_NE(error.find("MiB of device memory"), std::string::npos) << error;
  // The renderer still works afterwards.
  const Rendered g = Render(*gpu, small.View(), slices, o, dL);
  const Rendered c = Render(*CreateCpuRenderer(), small.View(), slices, o, dL);
  const Rendered e = Exact(small.View(), slices, o, dL);
  ExpectSameAsCpu(g, c, "after a refused call", 1e-5, 1e-4, &e);
}

TEST(CudaRenderer, TheRegistryChoosesItForAuto)
{
  EXPECT_EQ(ResolveBackend("auto", nullptr), "cuda");
  std::string error, notice;
  std::unique_ptr<Renderer> r = CreateRenderer("auto", &error, &notice);
  ASSERT_TRUE(r) << error;
  EXPECT_STREQ(r->GetName(), "cuda");
  EXPECT_TRUE(notice.empty()) << notice;
}

TEST(CudaRenderer, EdgeTilesAndSlicesOfDifferentSizesInOneBatch)
{
  // Neither size a multiple of the 16-pixel tile, three sizes in one call (the last tile row and column
  // are partial on every slice).
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  auto cpu = CreateCpuRenderer();
  const HostField field = HardCaseField(0.5, { 1.0, 10.0 });
  std::vector<SliceGeometry> slices = { HardCaseSlice(), HardCaseSlice(0.7), HardCaseSlice(-0.4) };
  slices[0].Width = 161;
  slices[0].Height = 113;
  slices[1].Width = 77;
  slices[1].Height = 45;
  slices[2].Width = 17;
  slices[2].Height = 1;
  std::size_t pixels = 0;
  for (const SliceGeometry& g : slices)
  {
    pixels += std::size_t(g.Width) * g.Height;
  }
  const std::vector<float> dL = RandomGradient(pixels, 11);
  RenderOptions o;
  o.ElevationSigma = 0.5;
  ExpectSameAsCpu(Render(*gpu, field.View(), slices, o, dL), Render(*cpu, field.View(), slices, o, dL),
    "slices of 161 x 113, 77 x 45 and 17 x 1 in one batch");
}

TEST(CudaRenderer, ATileWithMoreFootprintsThanOneStagingPass)
{
  // Small Gaussians inside one 16 x 16 tile of a 48 x 48 slice: the raster kernel stages a block's footprints
  // RasterThreads (256) at a time, and splits a tile's list over up to RasterPieces (8) blocks of at least
  // RasterMinimumPiece (512) entries, whose partial sums are added in order. 700 footprints: 2 pieces; 6,000: 8
  // pieces of 768; the tiles around hold a few spilled footprints each (one piece).
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  auto cpu = CreateCpuRenderer();
  const double axis[3] = { 0, 0, 1 }, origin[3] = { 0, 0, 0 };
  const std::vector<SliceGeometry> slices = { MakeSlice(48, 48, 0.25, 0, axis, origin) };
  for (int count : { 700, 6000 })
  {
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> in(0.5, 3.5), off(-0.3, 0.3), r(-0.5, 1.0);
    FieldF field;
    for (int k = 0; k < count; ++k)
    {
      field.Means.insert(field.Means.end(), { float(in(rng)), float(in(rng)), float(off(rng)) });
      field.LogScales.insert(field.LogScales.end(), { std::log(0.2f), std::log(0.15f), std::log(0.3f) });
      field.Quaternions.insert(field.Quaternions.end(), { 1.f, 0.f, 0.f, 0.f });
      field.Reflectivities.push_back(float(r(rng)));
    }
    RenderOptions o;
    o.ElevationSigma = 0.4;
    const std::vector<float> dL = RandomGradient(48 * 48, 12);
    const std::string what = std::to_string(count) + " footprints in one tile";
    const Rendered g = Render(*gpu, field.View(), slices, o, dL);
    const Rendered c = Render(*cpu, field.View(), slices, o, dL);
    EXPECT_GT(g.Forward.TileEntries, count / 2) << what;
    ExpectSameAsCpu(g, c, what);
    const Rendered again = Render(*gpu, field.View(), slices, o, dL);
    EXPECT_EQ(g.S, again.S) << what << ": the split tile's sums repeat bit for bit";
    EXPECT_EQ(g.I, again.I) << what;
  }
}

TEST(CudaRenderer, NoImageOutputGradientsWithRespectToSAndNullGradientOutputs)
{
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  auto cpu = CreateCpuRenderer();
  const HostField field = HardCaseField(0.5, { 1.0, 10.0 });
  const SliceGeometry slice = HardCaseSlice();
  const std::size_t pixels = std::size_t(slice.Width) * slice.Height;
  RenderOptions o;
  o.ElevationSigma = 0.5;
  std::string error;
  // I == nullptr: S alone, the same as with I.
  std::vector<float> S(pixels, -1.f), Sc(pixels), Ic(pixels);
  ASSERT_TRUE(gpu->Forward(field.View(), &slice, 1, o, S.data(), nullptr, nullptr, &error)) << error;
  ASSERT_TRUE(cpu->Forward(field.View(), &slice, 1, o, Sc.data(), Ic.data(), nullptr, &error)) << error;
  double worst = 0;
  for (std::size_t p = 0; p < pixels; ++p)
  {
    worst = std::max(worst, double(std::abs(S[p] - Sc[p])));
  }
  EXPECT_LE(worst, 1e-5) << "S without an image output";
  // dL/dS given, and only the reflectivity gradient asked for (every other output null): as accurate as
  // the CPU's against the double reference (bigus::CompareRenders on that group alone).
  const std::vector<float> dS = RandomGradient(pixels, 13);
  Rendered only, onlyCpu, exact;
  only.Reflectivities.assign(field.Reflectivities.size(), 0.f);
  onlyCpu.Reflectivities.assign(field.Reflectivities.size(), 0.f);
  FieldGradients r, rc;
  r.Reflectivities = only.Reflectivities.data();
  rc.Reflectivities = onlyCpu.Reflectivities.data();
  ASSERT_TRUE(gpu->Backward(field.View(), &slice, 1, o, S.data(), dS.data(), true, r, nullptr, &error)) << error;
  ASSERT_TRUE(cpu->Backward(field.View(), &slice, 1, o, Sc.data(), dS.data(), true, rc, nullptr, &error)) << error;
  const reference::FieldD d = reference::FromView(field.View());
  reference::GradD g(d.Count());
  const std::vector<double> dSd(dS.begin(), dS.end());
  ASSERT_TRUE(reference::Backward(d, slice, o, {}, dSd, true, g, true));
  exact.Reflectivities.assign(g.Reflectivities.begin(), g.Reflectivities.end());
  ASSERT_TRUE(std::any_of(exact.Reflectivities.begin(), exact.Reflectivities.end(), [](float v) { return v != 0; }));
  const BackendCheck c = CompareRenders(only, onlyCpu, exact, 1e-5, 1e-4);
  EXPECT_TRUE(c.Passed) << c.Detail;
  std::printf("dL/dS given, dL/dr alone: %s\n", c.Detail.c_str());
}

// Pose refinement: the gradient with respect to each slice's pose correction (FieldGradients::SlicePoses)
// against the CPU backend's, which TestCpuRenderer checks against central differences of the double
// reference renderer; two slices in one call (one partly off the field), added (+=) to what the caller
// holds, the same on a repeat, and the field's gradients unchanged by asking for it.
TEST(CudaRenderer, PoseGradientsMatchTheCpu)
{
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  auto cpu = CreateCpuRenderer();
  const std::vector<SliceGeometry> slices = { HardCaseSlice(), HardCaseSlice(1.3) };
  const std::size_t pixels = 2 * std::size_t(slices[0].Width) * slices[0].Height;
  const std::vector<float> dL = RandomGradient(pixels, 21);
  for (double sigmaE : { 0.05, 0.5, 5.0 })
  {
    const HostField field = HardCaseField(sigmaE, { 1.0, 10.0, 100.0 });
    RenderOptions o;
    o.ElevationSigma = sigmaE;
    std::string error;
    std::vector<float> S(pixels), Sc(pixels);
    ASSERT_TRUE(gpu->Forward(field.View(), slices.data(), 2, o, S.data(), nullptr, nullptr, &error)) << error;
    ASSERT_TRUE(cpu->Forward(field.View(), slices.data(), 2, o, Sc.data(), nullptr, nullptr, &error)) << error;
    const std::size_t n = field.Reflectivities.size();
    std::vector<float> means(3 * n, 0.f), meansWithPoses(3 * n, 0.f);
    // Start from 1 in every component: the backends add to what the caller holds.
    double poses[12], again[12], cpuPoses[12];
    std::fill(poses, poses + 12, 1.0);
    std::fill(again, again + 12, 1.0);
    std::fill(cpuPoses, cpuPoses + 12, 1.0);
    FieldGradients plain, withPoses, repeat, onCpu;
    plain.Means = means.data();
    withPoses.Means = meansWithPoses.data();
    withPoses.SlicePoses = poses;
    repeat.SlicePoses = again;
    onCpu.SlicePoses = cpuPoses;
    ASSERT_TRUE(gpu->Backward(field.View(), slices.data(), 2, o, S.data(), dL.data(), false, plain, nullptr, &error))
      << error;
    ASSERT_TRUE(
      gpu->Backward(field.View(), slices.data(), 2, o, S.data(), dL.data(), false, withPoses, nullptr, &error))
      << error;
    ASSERT_TRUE(gpu->Backward(field.View(), slices.data(), 2, o, S.data(), dL.data(), false, repeat, nullptr, &error))
      << error;
    ASSERT_TRUE(cpu->Backward(field.View(), slices.data(), 2, o, Sc.data(), dL.data(), false, onCpu, nullptr, &error))
      << error;
    EXPECT_EQ(std::memcmp(means.data(), meansWithPoses.data(), sizeof(float) * means.size()), 0)
      << "sigma_E " << sigmaE << ": the mean gradients change when pose gradients are asked for";
    EXPECT_EQ(std::memcmp(poses, again, sizeof(poses)), 0) << "sigma_E " << sigmaE << ": a repeat differs";
    for (int k = 0; k < 2; ++k)
    {
      double largest = 0;
      for (int c = 0; c < 6; ++c)
      {
        largest = std::max(largest, std::abs(cpuPoses[6 * k + c] - 1));
      }
      ASSERT_GT(largest, 0) << "sigma_E " << sigmaE << ", slice " << k;
      for (int c = 0; c < 6; ++c)
      {
        std::printf("sigma_E %g, slice %d, xi[%d]: CUDA %.9g, CPU %.9g\n", sigmaE, k, c, poses[6 * k + c] - 1,
          cpuPoses[6 * k + c] - 1);
        EXPECT_NEAR(poses[6 * k + c], cpuPoses[6 * k + c], 1e-4 * largest)
          << "sigma_E " << sigmaE << ", slice " << k << ", component " << c;
      }
    }
  }
}

TEST(CudaRenderer, AnEmptyFieldAndASliceThatCullsEverything)
{
  auto gpu = Cuda();
  ASSERT_TRUE(gpu);
  const SliceGeometry slice = HardCaseSlice();
  const std::size_t pixels = std::size_t(slice.Width) * slice.Height;
  RenderOptions o;
  std::string error;
  std::vector<float> S(pixels, -1.f), I(pixels, -1.f), dL(pixels, 1.f);
  FieldF empty;
  ASSERT_TRUE(gpu->Forward(empty.View(), &slice, 1, o, S.data(), I.data(), nullptr, &error)) << error;
  EXPECT_TRUE(std::all_of(S.begin(), S.end(), [](float v) { return v == 0; }));
  EXPECT_TRUE(std::all_of(I.begin(), I.end(), [](float v) { return v == 0; }));
  FieldGradients none;
  EXPECT_TRUE(gpu->Backward(empty.View(), &slice, 1, o, S.data(), dL.data(), false, none, nullptr, &error)) << error;
  // The hard-case field 50 mm off its slice: every Gaussian is culled.
  const HostField field = HardCaseField(0.5, { 1.0 });
  const SliceGeometry far = HardCaseSlice(50.0);
  std::fill(S.begin(), S.end(), -1.f);
  RenderStats stats;
  ASSERT_TRUE(gpu->Forward(field.View(), &far, 1, o, S.data(), I.data(), &stats, &error)) << error;
  EXPECT_TRUE(std::all_of(S.begin(), S.end(), [](float v) { return v == 0; }));
  EXPECT_EQ(stats.GaussiansVisible, 0);
  std::vector<float> gr(field.Reflectivities.size(), 0.f);
  FieldGradients g;
  g.Reflectivities = gr.data();
  ASSERT_TRUE(gpu->Backward(field.View(), &far, 1, o, S.data(), dL.data(), false, g, nullptr, &error)) << error;
  EXPECT_TRUE(std::all_of(gr.begin(), gr.end(), [](float v) { return v == 0; }));
}

TEST(CudaRenderer, AWholeTrainingStepThroughTheCudaEngine)
{
  // One step through CreateTrainingEngine("cuda") against the same step through the CPU engine, with each
  // training frame's pose refined from the first step: the loss and every updated parameter and pose
  // correction agree to float rounding of the renders (Adam's first step moves each parameter by about
  // its learning rate whatever the gradient's size, so parameters are compared by the sign of their move).
  TrainingData data = LiverData();
  data.TrainFrames = { 0, 4, 8 };
  TrainerSettings settings;
  settings.Seeding.InitialGaussians = 3000;
  settings.Iterations = 1;
  settings.ElevationSigma = 0.3;
  settings.Poses.RefinePoses = bigus::PoseRefinement::On;
  settings.Poses.Start = 0;
  std::string error;
  std::unique_ptr<TrainingEngine> engines[2] = { CreateTrainingEngine("cuda", &error),
    CreateTrainingEngine("cpu", &error) };
  ASSERT_TRUE(engines[0] && engines[1]) << error;
  EXPECT_STREQ(engines[0]->GetName(), "cuda");
  OptimizerState after[2];
  std::vector<double> corrections[2];
  double loss[2] = { 0, 0 };
  for (int e = 0; e < 2; ++e)
  {
    Trainer trainer(data, settings, std::move(engines[e]));
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    const OptimizerState before = trainer.GetState().Gaussians;
    ASSERT_EQ(trainer.Step(&loss[e], &error), StepStatus::Done) << error;
    after[e] = trainer.GetState().Gaussians;
    ASSERT_EQ(after[e].Field.Count(), before.Field.Count());
    for (const auto& c : trainer.GetState().PoseCorrections)
    {
      corrections[e].insert(corrections[e].end(), c.begin(), c.end());
    }
  }
  EXPECT_NEAR(loss[0], loss[1], 1e-4 * std::abs(loss[1])) << "the batch loss";
  const std::vector<float>* params[2][2] = { { &after[0].Field.Reflectivities, &after[1].Field.Reflectivities },
    { &after[0].Field.Means, &after[1].Field.Means } };
  for (const auto& pair : params)
  {
    ASSERT_EQ(pair[0]->size(), pair[1]->size());
    std::size_t differ = 0;
    for (std::size_t k = 0; k < pair[0]->size(); ++k)
    {
      differ += std::abs((*pair[0])[k] - (*pair[1])[k]) > 1e-3f;
    }
    EXPECT_LE(differ, pair[0]->size() / 1000) << "parameters that moved differently";
  }
  // The frames of the step's batch moved (the others keep 0), by the same Adam step on both engines.
  ASSERT_EQ(corrections[0].size(), corrections[1].size());
  const auto moved = std::count_if(corrections[1].begin(), corrections[1].end(), [](double v) { return v != 0; });
  EXPECT_GE(moved, 6) << "the step refined no pose";
  for (std::size_t k = 0; k < corrections[0].size(); ++k)
  {
    EXPECT_NEAR(corrections[0][k], corrections[1][k], 1e-3 * std::abs(corrections[1][k])) << "component " << k;
  }
}

namespace
{
/// A liver training state (3,000 Harris seeds) with Adam moments and EA-D accumulators made non-zero, so that a
/// round trip through a device copies every array; and the training request of one step on frames 0 and 8.
struct EngineCase
{
  TrainingData Data = LiverData();
  OptimizerState State;
  StepRequest Request;
  std::vector<int> Frames = { 0, 8 };
  double Gamma = 1;

  EngineCase()
  {
    TrainerSettings settings;
    settings.Seeding.InitialGaussians = 3000;
    settings.ElevationSigma = 0.3;
    Trainer trainer(this->Data, settings);
    std::string error;
    EXPECT_TRUE(trainer.Initialize(&error)) << error;
    this->State = trainer.GetState().Gaussians;
    this->Gamma = trainer.GetGamma();
    EXPECT_GT(this->Gamma, 0);
    this->State.ResizeToField();
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.f, 1e-3f);
    for (GaussianField* f : { &this->State.FirstMoment, &this->State.SecondMoment })
    {
      for (std::vector<float>* a : { &f->Means, &f->LogScales, &f->Quaternions, &f->Reflectivities })
      {
        for (float& v : *a)
        {
          v = u(rng);
        }
      }
    }
    for (std::int64_t i = 0; i < this->State.Count(); ++i)
    {
      this->State.Attribution[i] = u(rng);
      this->State.SeenCount[i] = static_cast<int>(i % 7);
    }
    this->Request.Frames = this->Frames.data();
    this->Request.Count = static_cast<int>(this->Frames.size());
    this->Request.MeanRate = 1e-3;
    this->Request.LogScaleRate = 5e-3;
    this->Request.QuaternionRate = 1e-3;
    this->Request.ReflectivityRate = 1e-2;
    this->Request.MinimumLogScale = std::log(0.01);
    this->Request.MaximumLogScale = std::log(50.0);
    this->Request.Options.ElevationSigma = 0.3;
    this->Request.Options.Gamma = this->Gamma;
  }

  std::unique_ptr<TrainingEngine> Engine(const char* backend)
  {
    std::string error;
    std::unique_ptr<TrainingEngine> engine = CreateTrainingEngine(backend, &error);
    EXPECT_TRUE(engine) << error;
    if (engine)
    {
      EXPECT_TRUE(engine->SetData(&this->Data, &error)) << error;
      EXPECT_TRUE(engine->Push(this->State, &error)) << error;
    }
    return engine;
  }
};

void ExpectSameField(const GaussianField& a, const GaussianField& b, const std::string& what)
{
  EXPECT_EQ(a.Means, b.Means) << what;
  EXPECT_EQ(a.LogScales, b.LogScales) << what;
  EXPECT_EQ(a.Quaternions, b.Quaternions) << what;
  EXPECT_EQ(a.Reflectivities, b.Reflectivities) << what;
}

/// ||a - b|| / ||b||.
double RelativeDifference(const std::vector<double>& a, const std::vector<double>& b)
{
  double d = 0, n = 0;
  for (std::size_t k = 0; k < a.size(); ++k)
  {
    d += (a[k] - b[k]) * (a[k] - b[k]);
    n += b[k] * b[k];
  }
  return std::sqrt(d / std::max(n, 1e-300));
}
}

TEST(CudaTrainingEngine, IsTheCudaBackendsEngineAndKeepsTheStateOnTheDevice)
{
  // CreateTrainingEngine("cuda") is the device-resident engine (registered by the backend); Push then Pull
  // returns every array bit for bit; Restore returns the field and moments of the last Push or Snapshot and keeps
  // the accumulators of the steps since.
  EngineCase c;
  std::unique_ptr<TrainingEngine> engine = c.Engine("cuda");
  ASSERT_TRUE(engine);
  EXPECT_STREQ(engine->GetName(), "cuda");
  std::string error;
  OptimizerState back;
  ASSERT_TRUE(engine->Pull(back, &error)) << error;
  ExpectSameField(back.Field, c.State.Field, "field");
  ExpectSameField(back.FirstMoment, c.State.FirstMoment, "Adam m");
  ExpectSameField(back.SecondMoment, c.State.SecondMoment, "Adam v");
  EXPECT_EQ(back.Attribution, c.State.Attribution);
  EXPECT_EQ(back.SeenCount, c.State.SeenCount);
  GaussianField field;
  ASSERT_TRUE(engine->PullField(field, &error)) << error;
  ExpectSameField(field, c.State.Field, "PullField");
  double loss = 0;
  ASSERT_EQ(engine->Step(c.Request, &loss, &error), StepStatus::Done) << error;
  OptimizerState stepped;
  ASSERT_TRUE(engine->Pull(stepped, &error)) << error;
  EXPECT_NE(stepped.Field.Means, c.State.Field.Means) << "the step moved nothing";
  engine->Restore();
  OptimizerState restored;
  ASSERT_TRUE(engine->Pull(restored, &error)) << error;
  ExpectSameField(restored.Field, c.State.Field, "restored field");
  ExpectSameField(restored.SecondMoment, c.State.SecondMoment, "restored Adam v");
  EXPECT_EQ(restored.Attribution, stepped.Attribution) << "Restore keeps the accumulators";
  EXPECT_EQ(restored.SeenCount, stepped.SeenCount);
  EXPECT_NE(restored.SeenCount, c.State.SeenCount) << "the step counted no visible Gaussian";
  // Snapshot after a step: Restore comes back to it.
  ASSERT_EQ(engine->Step(c.Request, &loss, &error), StepStatus::Done) << error;
  engine->Snapshot();
  OptimizerState snapped;
  ASSERT_TRUE(engine->Pull(snapped, &error)) << error;
  ASSERT_EQ(engine->Step(c.Request, &loss, &error), StepStatus::Done) << error;
  engine->Restore();
  ASSERT_TRUE(engine->Pull(restored, &error)) << error;
  ExpectSameField(restored.Field, snapped.Field, "field restored to the snapshot");
  ExpectSameField(restored.FirstMoment, snapped.FirstMoment, "Adam m restored to the snapshot");
}

TEST(CudaTrainingEngine, StepsMatchTheCpuEngineAndRepeatBitForBit)
{
  // Five steps on frames 0 and 8 with pose gradients, and sparse Adam on the last two: the losses follow the CPU
  // engine's to float rounding of the renders, the pose gradients agree, and the same steps again on the device
  // give the same bits.
  EngineCase c;
  for (GaussianField* f : { &c.State.FirstMoment, &c.State.SecondMoment })
  {
    for (std::vector<float>* a : { &f->Means, &f->LogScales, &f->Quaternions, &f->Reflectivities })
    {
      std::fill(a->begin(), a->end(), 0.f); // a trainer's first step
    }
  }
  std::vector<double> losses[3], poses[3];
  OptimizerState after[3];
  const char* backends[3] = { "cuda", "cpu", "cuda" };
  for (int e = 0; e < 3; ++e)
  {
    std::unique_ptr<TrainingEngine> engine = c.Engine(backends[e]);
    ASSERT_TRUE(engine);
    std::string error;
    for (int step = 0; step < 5; ++step)
    {
      StepRequest request = c.Request;
      request.Iteration = step;
      request.SparseAdam = step >= 3;
      std::vector<double> pose(6 * request.Count, -1.0);
      request.PoseGradients = pose.data();
      double loss = 0;
      ASSERT_EQ(engine->Step(request, &loss, &error), StepStatus::Done) << backends[e] << ": " << error;
      losses[e].push_back(loss);
      poses[e].insert(poses[e].end(), pose.begin(), pose.end());
    }
    ASSERT_TRUE(engine->Pull(after[e], &error)) << error;
  }
  // Step 0 renders the same field on both; later steps the fields the engines' own Adam steps made, where a
  // gradient near 0 may change sign between float renderers and Adam moves it by its learning rate either way.
  for (int step = 0; step < 5; ++step)
  {
    EXPECT_NEAR(losses[0][step], losses[1][step], (step == 0 ? 1e-4 : 2e-3) * losses[1][step]) << "step " << step;
    std::printf("step %d: loss cuda %.9f, cpu %.9f\n", step, losses[0][step], losses[1][step]);
  }
  const std::size_t first = 6 * c.Frames.size();
  EXPECT_GT(std::count_if(poses[1].begin(), poses[1].end(), [](double v) { return v != 0; }), 6 * 5)
    << "pose gradients are zero";
  EXPECT_LT(losses[1][4], losses[1][0]) << "five steps did not lower the loss";
  EXPECT_LT(RelativeDifference(std::vector<double>(poses[0].begin(), poses[0].begin() + first),
              std::vector<double>(poses[1].begin(), poses[1].begin() + first)),
    1e-4)
    << "pose gradients of step 0";
  EXPECT_LT(RelativeDifference(poses[0], poses[1]), 1e-2) << "pose gradients of the five steps";
  EXPECT_EQ(losses[0], losses[2]);
  EXPECT_EQ(poses[0], poses[2]);
  ExpectSameField(after[0].Field, after[2].Field, "a repeated run");
  EXPECT_EQ(after[0].Attribution, after[2].Attribution);
  std::size_t counted = 0;
  for (std::size_t i = 0; i < after[0].SeenCount.size(); ++i)
  {
    counted += after[0].SeenCount[i] != after[1].SeenCount[i];
  }
  EXPECT_LE(counted, after[0].SeenCount.size() / 1000) << "visible counts unlike the CPU engine's";
  std::vector<double> r[2];
  for (int e = 0; e < 2; ++e)
  {
    r[e].assign(after[e].Field.Reflectivities.begin(), after[e].Field.Reflectivities.end());
  }
  EXPECT_LT(RelativeDifference(r[0], r[1]), 1e-2) << "reflectivities after five steps";
}

TEST(CudaTrainingEngine, ANonFiniteStepAndARefusedPoseAreReported)
{
  EngineCase c;
  std::unique_ptr<TrainingEngine> engine = c.Engine("cuda");
  ASSERT_TRUE(engine);
  std::string error;
  StepRequest request = c.Request;
  request.MeanRate = std::numeric_limits<double>::quiet_NaN();
  double loss = 0;
  EXPECT_EQ(engine->Step(request, &loss, &error), StepStatus::NonFinite);
  engine->Restore();
  GaussianField field;
  ASSERT_TRUE(engine->PullField(field, &error)) << error;
  ExpectSameField(field, c.State.Field, "after Restore");
  // A frame whose pose the renderer refuses: Failed, and the error names the training frame.
  std::array<double, 16>& pose = c.Data.Poses[8];
  std::fill(pose.begin(), pose.end(), 0.0);
  error.clear();
  EXPECT_EQ(engine->Step(c.Request, &loss, &error), StepStatus::Failed);
  EXPECT_NE(error.find("training frame 8"), std::string::npos) << error;
}

/// A frame pair for the image loss: speckle-like rendered and recorded images with saturated (0 and 1) patches, and
/// a fan-like mask (a disc sector) on [H, W].
struct LossImages
{
  int Width, Height;
  std::vector<float> X, Y;
  std::vector<unsigned char> Mask;
  LossImages(int width, int height, unsigned seed)
    : Width(width)
    , Height(height)
    , X(std::size_t(width) * height)
    , Y(X.size())
    , Mask(X.size())
  {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (int j = 0; j < height; ++j)
    {
      for (int i = 0; i < width; ++i)
      {
        const std::size_t p = std::size_t(j) * width + i;
        const double base = 0.5 + 0.4 * std::sin(0.07 * i) * std::cos(0.05 * j);
        this->Y[p] = static_cast<float>(std::clamp(base * (0.5 + u(rng)), 0.0, 1.0));
        this->X[p] = static_cast<float>(std::clamp(base + 0.2 * (u(rng) - 0.5), 0.0, 1.0));
        if (i < width / 5 && j < height / 3)
        {
          this->X[p] = 1.f; // saturated in both, and 0 in both
          this->Y[p] = (i + j) % 3 ? 1.f : 0.f;
        }
        const double dx = i - 0.5 * width, dy = j + 0.3 * height;
        const double r = std::hypot(dx, dy), angle = std::atan2(dx, dy);
        this->Mask[p] = (r > 0.35 * height && r < 1.25 * height && std::abs(angle) < 0.6) ? 1 : 0;
      }
    }
  }
};

TEST(CudaImageLoss, IsTheHostLossOnMaskedEmptyAndSaturatedFrames)
{
  // The device loss against ComputeImageLoss in double on the CPU (itself checked against finite differences in
  // TestImageLoss): the terms and dTotal/dx to 1e-6, on frames with a fan mask, without one, with an empty one,
  // of sizes that are not multiples of the kernels' 32 x 8 blocks (one smaller than the 11 x 11 window), and with
  // each term alone.
  struct Case
  {
    int Width, Height;
    const char* Mask; // "fan", "none", "empty"
    double L1, DSSIM;
  };
  const Case cases[] = { { 256, 200, "fan", 0.8, 0.2 }, { 333, 97, "fan", 0.8, 0.2 }, { 64, 48, "none", 0.8, 0.2 },
    { 9, 7, "none", 0.5, 0.5 }, { 120, 90, "empty", 0.8, 0.2 }, { 150, 111, "fan", 1.0, 0.0 },
    { 150, 111, "fan", 0.0, 1.0 } };
  for (const Case& k : cases)
  {
    const LossImages im(k.Width, k.Height, 7);
    std::vector<unsigned char> mask = im.Mask;
    if (std::string(k.Mask) == "empty")
    {
      std::fill(mask.begin(), mask.end(), 0);
    }
    const unsigned char* m = std::string(k.Mask) == "none" ? nullptr : mask.data();
    ImageLossWeights weights;
    weights.L1 = k.L1;
    weights.DSSIM = k.DSSIM;
    std::vector<float> host(im.X.size()), device(im.X.size(), -7.f);
    const ImageLossTerms expected =
      ComputeImageLoss(im.X.data(), im.Y.data(), m, k.Width, k.Height, weights, host.data(), true);
    ImageLossTerms got;
    std::string error;
    ASSERT_TRUE(cuda::ComputeImageLossOnDevice(
      im.X.data(), im.Y.data(), m, k.Width, k.Height, weights, device.data(), &got, &error))
      << error;
    const std::string name = std::to_string(k.Width) + " x " + std::to_string(k.Height) + ", mask " + k.Mask +
      ", weights " + std::to_string(k.L1) + " / " + std::to_string(k.DSSIM);
    EXPECT_EQ(got.MaskedPixels, expected.MaskedPixels) << name;
    EXPECT_NEAR(got.L1, expected.L1, 1e-6 * std::max(1e-3, expected.L1)) << name;
    EXPECT_NEAR(got.DSSIM, expected.DSSIM, 1e-6 * std::max(1e-3, expected.DSSIM)) << name;
    EXPECT_NEAR(got.Total, expected.Total, 1e-6 * std::max(1e-3, expected.Total)) << name;
    double largest = 0, worst = 0;
    for (std::size_t p = 0; p < host.size(); ++p)
    {
      largest = std::max(largest, std::abs(double(host[p])));
      worst = std::max(worst, std::abs(double(device[p]) - host[p]));
    }
    EXPECT_LE(worst, 1e-6 * largest) << name << ": the gradient";
    if (expected.MaskedPixels == 0)
    {
      EXPECT_EQ(got.Total, 0.0) << name;
      EXPECT_EQ(largest, 0.0) << name;
      EXPECT_EQ(*std::max_element(device.begin(), device.end()), 0.f) << name << ": a gradient on an empty mask";
    }
    std::printf("%s: total %.12f (host %.12f), gradient error %.3g of its largest %.3g\n", name.c_str(), got.Total,
      expected.Total, largest > 0 ? worst / largest : worst, largest);
  }
  // Without a gradient: the terms alone. With an FFL weight: refused, with the reason.
  const LossImages im(100, 80, 9);
  ImageLossTerms got;
  std::string error;
  ASSERT_TRUE(cuda::ComputeImageLossOnDevice(
    im.X.data(), im.Y.data(), im.Mask.data(), 100, 80, ImageLossWeights(), nullptr, &got, &error))
    << error;
  EXPECT_NEAR(got.Total,
    ComputeImageLoss(im.X.data(), im.Y.data(), im.Mask.data(), 100, 80, ImageLossWeights(), nullptr, true).Total,
    1e-6 * got.Total);
  ImageLossWeights ffl;
  ffl.FFL = 0.1;
  EXPECT_FALSE(
    cuda::ComputeImageLossOnDevice(im.X.data(), im.Y.data(), im.Mask.data(), 100, 80, ffl, nullptr, &got, &error));
  EXPECT_NE(error.find("FFL"), std::string::npos) << error;
}

TEST(CudaTrainingEngine, AStepWithAnFflTermTakesTheHostLossAndMatchesTheCpuEngine)
{
  // The device loss has no FFL term: such a step computes its loss on the host, and gives the CPU engine's.
  EngineCase c;
  c.Request.Loss.FFL = 0.5;
  double loss[2] = { 0, 0 };
  const char* backends[2] = { "cuda", "cpu" };
  for (int e = 0; e < 2; ++e)
  {
    std::unique_ptr<TrainingEngine> engine = c.Engine(backends[e]);
    ASSERT_TRUE(engine);
    std::string error;
    ASSERT_EQ(engine->Step(c.Request, &loss[e], &error), StepStatus::Done) << backends[e] << ": " << error;
  }
  EXPECT_NEAR(loss[0], loss[1], 1e-4 * loss[1]);
}

TEST(CudaTrainingEngine, ACoarseStepOfTheResolutionScheduleMatchesTheCpuEngine)
{
  // StepRequest::Data: a step on the decimated frames (DecimateFrames, TrainerSettings::CoarseFraction) instead of
  // the engine's own, with pose gradients: the same loss and pose gradients as the CPU engine's.
  EngineCase c;
  const TrainingData coarse = DecimateFrames(c.Data, c.Frames.data(), 2, 1, 0);
  double loss[2] = { 0, 0 };
  std::vector<double> poses[2];
  const char* backends[2] = { "cuda", "cpu" };
  for (int e = 0; e < 2; ++e)
  {
    std::unique_ptr<TrainingEngine> engine = c.Engine(backends[e]);
    ASSERT_TRUE(engine);
    StepRequest request = c.Request;
    request.Data = &coarse;
    request.Frames = coarse.TrainFrames.data();
    poses[e].assign(6 * request.Count, 0.0);
    request.PoseGradients = poses[e].data();
    std::string error;
    ASSERT_EQ(engine->Step(request, &loss[e], &error), StepStatus::Done) << backends[e] << ": " << error;
  }
  EXPECT_NEAR(loss[0], loss[1], 1e-4 * loss[1]);
  EXPECT_GT(std::count_if(poses[1].begin(), poses[1].end(), [](double v) { return v != 0; }), 6);
  EXPECT_LT(RelativeDifference(poses[0], poses[1]), 1e-4) << "pose gradients";
}

TEST(CudaTrainingEngine, TheSolveOperatorsMatchTheCpuEngineAndAreAdjoint)
{
  // A r, A^T y and diag(A^T W A) on frames 2 and 70 (bigusReflectivitySolve.h): against the CPU engine's, and
  // <A x, y> = <x, A^T y> on the device alone.
  EngineCase c;
  std::unique_ptr<TrainingEngine> engines[2] = { c.Engine("cuda"), c.Engine("cpu") };
  ASSERT_TRUE(engines[0] && engines[1]);
  const int frames[2] = { 2, 70 };
  const std::size_t pixels = std::size_t(c.Data.Width) * c.Data.Height;
  const std::int64_t n = c.State.Count();
  std::mt19937 rng(11);
  std::normal_distribution<float> normal(0.f, 1.f);
  std::vector<float> x(n), y(2 * pixels), weights(2 * pixels);
  for (float& v : x)
  {
    v = normal(rng);
  }
  for (std::size_t p = 0; p < y.size(); ++p)
  {
    y[p] = normal(rng);
    weights[p] = std::abs(normal(rng));
  }
  std::vector<float> Ax[2];
  std::vector<double> Aty[2], norms[2];
  std::string error;
  for (int e = 0; e < 2; ++e)
  {
    Ax[e].assign(2 * pixels, 0.f);
    Aty[e].assign(n, 0.5); // += semantics
    norms[e].assign(n, 0.0);
    // A^T y first, on an engine that has rendered nothing yet (its image buffers not yet allocated).
    ASSERT_TRUE(engines[e]->ApplyBasisTranspose(y.data(), frames, 2, c.Request.Options, Aty[e].data(), &error))
      << error;
    ASSERT_TRUE(engines[e]->ApplyBasis(x.data(), frames, 2, c.Request.Options, Ax[e].data(), &error)) << error;
    ASSERT_TRUE(engines[e]->BasisNorms(weights.data(), frames, 2, c.Request.Options, norms[e].data(), &error)) << error;
  }
  const std::vector<double> ax0(Ax[0].begin(), Ax[0].end()), ax1(Ax[1].begin(), Ax[1].end());
  EXPECT_LT(RelativeDifference(ax0, ax1), 1e-5) << "A x";
  EXPECT_LT(RelativeDifference(Aty[0], Aty[1]), 1e-4) << "A^T y";
  EXPECT_LT(RelativeDifference(norms[0], norms[1]), 1e-12) << "the basis norms (the same host code)";
  double left = 0, right = 0;
  for (std::size_t p = 0; p < y.size(); ++p)
  {
    left += double(Ax[0][p]) * y[p];
  }
  for (std::int64_t i = 0; i < n; ++i)
  {
    right += double(x[i]) * (Aty[0][i] - 0.5);
  }
  EXPECT_NEAR(left, right, 1e-5 * std::abs(right)) << "<A x, y> against <x, A^T y>";
}

TEST(CudaTrainingEngine, TheAssembledSolveProductsAreTheMatrixFreeOnesAndRepeatBitForBit)
{
  // The basis assembled on the device (DeviceBasis, allowed by SetBasisMemoryLimit) against the device's matrix-free
  // products (renders; the norms through the host's AccumulateBasisNorms) and the CPU engine's assembled basis, on
  // frames 2, 40 and 70: A x, A^T y and diag(A^T W A); repeated products and a second assembly give the same bits;
  // <A x, y> = <x, A^T y>; a limit too small for the matrix gives the matrix-free products; a moved field (Push) is
  // assembled again.
  EngineCase c;
  std::unique_ptr<TrainingEngine> engines[3] = { c.Engine("cuda"), c.Engine("cuda"), c.Engine("cpu") };
  ASSERT_TRUE(engines[0] && engines[1] && engines[2]);
  const std::int64_t unlimited = std::int64_t(1) << 40;
  engines[0]->SetBasisMemoryLimit(unlimited);
  engines[2]->SetBasisMemoryLimit(unlimited);
  const int frames[3] = { 2, 40, 70 };
  const std::size_t pixels = 3 * std::size_t(c.Data.Width) * c.Data.Height;
  const std::int64_t n = c.State.Count();
  std::mt19937 rng(12);
  std::normal_distribution<float> normal(0.f, 1.f);
  std::vector<float> x(n), y(pixels), weights(pixels);
  for (float& v : x)
  {
    v = normal(rng);
  }
  for (std::size_t p = 0; p < pixels; ++p)
  {
    y[p] = normal(rng);
    weights[p] = std::abs(normal(rng));
  }
  struct Products
  {
    std::vector<double> Ax, Aty, Norms;
  };
  auto products = [&](TrainingEngine& engine) {
    Products out;
    std::vector<float> ax(pixels, 0.f);
    out.Aty.assign(n, 0.25); // += semantics
    out.Norms.assign(n, 0.0);
    std::string error;
    EXPECT_TRUE(engine.ApplyBasisTranspose(y.data(), frames, 3, c.Request.Options, out.Aty.data(), &error)) << error;
    EXPECT_TRUE(engine.ApplyBasis(x.data(), frames, 3, c.Request.Options, ax.data(), &error)) << error;
    EXPECT_TRUE(engine.BasisNorms(weights.data(), frames, 3, c.Request.Options, out.Norms.data(), &error)) << error;
    out.Ax.assign(ax.begin(), ax.end());
    return out;
  };
  const Products assembled = products(*engines[0]);
  EXPECT_EQ(engines[0]->DescribeBasisProducts().rfind("assembled on the device (", 0), 0u)
    << engines[0]->DescribeBasisProducts();
  const Products free = products(*engines[1]);
  EXPECT_EQ(engines[1]->DescribeBasisProducts().rfind("matrix free", 0), 0u) << engines[1]->DescribeBasisProducts();
  const Products cpu = products(*engines[2]);
  EXPECT_EQ(engines[2]->DescribeBasisProducts().rfind("assembled (", 0), 0u) << engines[2]->DescribeBasisProducts();
  EXPECT_GT(std::count_if(assembled.Norms.begin(), assembled.Norms.end(), [](double v) { return v > 0; }), 20);
  EXPECT_LT(RelativeDifference(assembled.Ax, free.Ax), 1e-5) << "A x against the device's renders";
  EXPECT_LT(RelativeDifference(assembled.Aty, free.Aty), 1e-5) << "A^T y against the device's backward pass";
  EXPECT_LT(RelativeDifference(assembled.Norms, free.Norms), 1e-5) << "the norms against the host's";
  EXPECT_LT(RelativeDifference(assembled.Ax, cpu.Ax), 1e-5) << "A x against the CPU's assembled basis";
  EXPECT_LT(RelativeDifference(assembled.Aty, cpu.Aty), 1e-5) << "A^T y against the CPU's assembled basis";
  EXPECT_LT(RelativeDifference(assembled.Norms, cpu.Norms), 1e-5) << "the norms against the CPU's assembled basis";
  double left = 0, right = 0;
  for (std::size_t p = 0; p < pixels; ++p)
  {
    left += assembled.Ax[p] * y[p];
  }
  for (std::int64_t i = 0; i < n; ++i)
  {
    right += double(x[i]) * (assembled.Aty[i] - 0.25);
  }
  EXPECT_NEAR(left, right, 1e-5 * std::abs(right)) << "<A x, y> against <x, A^T y>";
  // The same products again (the basis kept), then after a Push of the same state (assembled anew): the same bits.
  const Products again = products(*engines[0]);
  std::string error;
  ASSERT_TRUE(engines[0]->Push(c.State, &error)) << error;
  const Products rebuilt = products(*engines[0]);
  for (const Products* p : { &again, &rebuilt })
  {
    EXPECT_EQ(p->Ax, assembled.Ax);
    EXPECT_EQ(p->Aty, assembled.Aty);
    EXPECT_EQ(p->Norms, assembled.Norms);
  }
  // A limit below the matrix's bytes: matrix free, the device's renders.
  engines[0]->SetBasisMemoryLimit(1000);
  const Products refused = products(*engines[0]);
  EXPECT_NE(engines[0]->DescribeBasisProducts().find("matrix free (the assembled basis of"), std::string::npos)
    << engines[0]->DescribeBasisProducts();
  EXPECT_LT(RelativeDifference(refused.Aty, free.Aty), 1e-12);
  // A moved field: assembled again for it, as the matrix-free products of an engine given the same field.
  engines[0]->SetBasisMemoryLimit(unlimited);
  OptimizerState moved = c.State;
  for (float& m : moved.Field.Means)
  {
    m += 0.3f;
  }
  ASSERT_TRUE(engines[0]->Push(moved, &error) && engines[1]->Push(moved, &error)) << error;
  const Products movedAssembled = products(*engines[0]), movedFree = products(*engines[1]);
  EXPECT_GT(RelativeDifference(movedAssembled.Aty, assembled.Aty), 1e-3) << "the field moved";
  EXPECT_LT(RelativeDifference(movedAssembled.Aty, movedFree.Aty), 1e-5);
  EXPECT_LT(RelativeDifference(movedAssembled.Ax, movedFree.Ax), 1e-5);
}

TEST(CudaTrainingEngine, DataParallelStepsOnTwoProcessesAreTheStepsOfOne)
{
  // Two processes on this GPU (threads with a ThreadReduction, as the ranks of mpirun): CreateTrainingEngine with
  // dataParallel gives the CPU engine's step over the CUDA renderer, which sums the halves of each step's frames
  // through the host. Three steps with pose gradients give both processes the same state, and that state is the
  // device-resident engine's steps on all the frames in one process, to float rounding; A^T y summed over the
  // processes' frames is one process's A^T y on all of them.
  EngineCase c;
  c.State.FirstMoment = GaussianField();
  c.State.SecondMoment = GaussianField();
  c.State.ResizeToField(); // zero moments: a trainer's first step
  const std::size_t pixels = std::size_t(c.Data.Width) * c.Data.Height;
  std::mt19937 rng(5);
  std::normal_distribution<float> normal(0.f, 1.f);
  std::vector<float> y(2 * pixels);
  for (float& v : y)
  {
    v = normal(rng);
  }
  std::vector<double> losses[3], poses[3], Aty[3];
  OptimizerState after[3];
  auto train = [&](ProcessReduction* reduction, int e) {
    std::string error;
    std::unique_ptr<TrainingEngine> engine = CreateTrainingEngine("cuda", &error, nullptr, reduction != nullptr);
    ASSERT_TRUE(engine) << error;
    ASSERT_TRUE(
      engine->SetData(&c.Data, &error) && engine->SetReduction(reduction, &error) && engine->Push(c.State, &error))
      << error;
    for (int step = 0; step < 3; ++step)
    {
      StepRequest request = c.Request;
      request.Iteration = step;
      std::vector<double> pose(6 * request.Count, 0.0);
      request.PoseGradients = pose.data();
      double loss = 0;
      EXPECT_EQ(engine->Step(request, &loss, &error), StepStatus::Done) << error;
      losses[e].push_back(loss);
      poses[e].insert(poses[e].end(), pose.begin(), pose.end());
    }
    EXPECT_TRUE(engine->Pull(after[e], &error)) << error;
    // The solve's split: each process applies A^T to its own frames' images.
    const int rank = reduction ? reduction->Rank() : 0, count = reduction ? 1 : 2;
    Aty[e].assign(c.State.Count(), 0.0);
    EXPECT_TRUE(engine->ApplyBasisTranspose(
      y.data() + rank * pixels, c.Frames.data() + rank, count, c.Request.Options, Aty[e].data(), &error))
      << error;
  };
  train(nullptr, 2);
  test::RunOnThreads(2, [&](int rank, ProcessReduction& reduction) { train(&reduction, rank); });
  EXPECT_EQ(losses[0], losses[1]);
  EXPECT_EQ(poses[0], poses[1]);
  ExpectSameField(after[0].Field, after[1].Field, "the two processes' fields");
  ExpectSameField(after[0].SecondMoment, after[1].SecondMoment, "the two processes' Adam v");
  EXPECT_EQ(after[0].Attribution, after[1].Attribution);
  EXPECT_EQ(Aty[0], Aty[1]);
  for (int step = 0; step < 3; ++step)
  {
    EXPECT_NEAR(losses[0][step], losses[2][step], (step == 0 ? 1e-6 : 2e-3) * losses[2][step]) << "step " << step;
    std::printf("step %d: loss of two processes %.9f, of one %.9f\n", step, losses[0][step], losses[2][step]);
  }
  const std::size_t first = 6 * c.Frames.size();
  EXPECT_LT(RelativeDifference(std::vector<double>(poses[0].begin(), poses[0].begin() + first),
              std::vector<double>(poses[2].begin(), poses[2].begin() + first)),
    1e-4)
    << "pose gradients of step 0";
  std::vector<double> r[2];
  for (int e = 0; e < 2; ++e)
  {
    r[e].assign(after[2 * e].Field.Reflectivities.begin(), after[2 * e].Field.Reflectivities.end());
  }
  EXPECT_LT(RelativeDifference(r[0], r[1]), 1e-2) << "reflectivities after three steps";
  EXPECT_LT(RelativeDifference(Aty[0], Aty[2]), 1e-5) << "A^T y";
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  bigus::cuda::DeviceInfo info;
  std::string why;
  if (!bigus::cuda::QueryDevice(info, why))
  {
    std::printf("SKIP: no usable CUDA device (%s)\n", why.c_str());
    return 125;
  }
  std::printf("CUDA device: %s, sm_%d, %.1f GiB; device bytes per Gaussian %lld (forward) and %lld (backward), "
              "per pixel %lld, per tile entry %lld\n",
    info.Name.c_str(), info.ComputeCapability, info.MemoryGiB,
    static_cast<long long>(bigus::cuda::DeviceBytesPerGaussian()),
    static_cast<long long>(bigus::cuda::DeviceBytesPerGaussian(true)),
    static_cast<long long>(bigus::cuda::DeviceBytesPerPixel()),
    static_cast<long long>(bigus::cuda::DeviceBytesPerTileEntry()));
  return RUN_ALL_TESTS();
}
