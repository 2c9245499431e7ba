// A backend proves itself before "auto" picks it (bigusBackendCheck.h). Backends made here from the
// CPU renderer with one known fault each (images 0.1 % too bright; one Gaussian's dL/dr 1 % off where
// its own gradient is small) must fail the check, the CPU renderer itself must pass it exactly, and the
// registry must pass over a failing backend for "auto" with a notice while an explicit name still runs
// it with the warning.
#include "bigusBackend.h"
#include "bigusBackendCheck.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

using namespace bigus;

namespace
{
/// The CPU renderer under another name, with a fault applied to its outputs.
class FaultyRenderer : public Renderer
{
public:
  enum Fault
  {
    None,
    BrighterImage,               ///< I x (1 + 1e-3)
    OneSmallReflectivityGradient ///< dL/dr of Gaussian SmallGaussian x 1.01
  };
  FaultyRenderer(const char* name, Fault fault)
    : Name(name)
    , What(fault)
  {}
  const char* GetName() const override { return this->Name; }
  bool Forward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options, float* S,
    float* I, RenderStats* stats, std::string* error) override
  {
    if (!this->Cpu->Forward(field, slices, count, options, S, I, stats, error))
    {
      return false;
    }
    std::size_t pixels = 0;
    for (int k = 0; k < count; ++k)
    {
      pixels += std::size_t(slices[k].Width) * slices[k].Height;
    }
    for (std::size_t p = 0; I && this->What == BrighterImage && p < pixels; ++p)
    {
      I[p] *= 1.001f;
    }
    return true;
  }
  bool Backward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    const float* S, const float* dL, bool wrtS, FieldGradients& gradients, RenderStats* stats,
    std::string* error) override
  {
    const float before = gradients.Reflectivities ? gradients.Reflectivities[SmallGaussian] : 0.f;
    if (!this->Cpu->Backward(field, slices, count, options, S, dL, wrtS, gradients, stats, error))
    {
      return false;
    }
    if (this->What == OneSmallReflectivityGradient && gradients.Reflectivities)
    {
      float& g = gradients.Reflectivities[SmallGaussian];
      g = before + 1.01f * (g - before);
    }
    return true;
  }
  static std::int64_t SmallGaussian;

private:
  const char* Name;
  Fault What;
  std::unique_ptr<Renderer> Cpu = CreateCpuRenderer();
};
std::int64_t FaultyRenderer::SmallGaussian = 0;

std::unique_ptr<Renderer> MakeSound(std::string*)
{
  return std::make_unique<FaultyRenderer>("sound", FaultyRenderer::None);
}
std::unique_ptr<Renderer> MakeBright(std::string*)
{
  return std::make_unique<FaultyRenderer>("bright", FaultyRenderer::BrighterImage);
}

/// The Gaussian of the check whose |dL/dr| is the smallest above 1 % of the largest: a 1 % error there is
/// far below 1e-4 of the largest gradient, so only a per-Gaussian tolerance sees it.
std::int64_t SmallestVisibleReflectivityGradient()
{
  FaultyRenderer cpu("cpu", FaultyRenderer::None);
  const HostField field = HardCaseField(0.5, { 1.0, 10.0, 100.0 });
  SliceGeometry slices[2] = { HardCaseSlice(), HardCaseSlice(1.3) };
  slices[1].Width = 77;
  slices[1].Height = 45;
  const std::size_t pixels = std::size_t(slices[0].Width) * slices[0].Height + 77 * 45;
  std::vector<float> S(pixels), I(pixels), dL(pixels, 1.f), dr(field.Reflectivities.size(), 0.f);
  RenderOptions o;
  o.ElevationSigma = 0.5;
  std::string error;
  EXPECT_TRUE(cpu.Forward(field.View(), slices, 2, o, S.data(), I.data(), nullptr, &error)) << error;
  FieldGradients g;
  g.Reflectivities = dr.data();
  EXPECT_TRUE(cpu.Backward(field.View(), slices, 2, o, S.data(), dL.data(), false, g, nullptr, &error)) << error;
  double largest = 0;
  for (float v : dr)
  {
    largest = std::max(largest, double(std::abs(v)));
  }
  std::int64_t best = -1;
  for (std::size_t i = 0; i < dr.size(); ++i)
  {
    if (std::abs(dr[i]) > 0.01 * largest && (best < 0 || std::abs(dr[i]) < std::abs(dr[best])))
    {
      best = static_cast<std::int64_t>(i);
    }
  }
  return best;
}
}

TEST(BackendCheck, TheCpuRendererMatchesItselfExactly)
{
  FaultyRenderer cpu("cpu-copy", FaultyRenderer::None);
  const BackendCheck check = CheckRenderer(cpu);
  std::printf("%s\n", check.Detail.c_str());
  EXPECT_TRUE(check.Passed) << check.Detail;
  EXPECT_EQ(check.ImageDifference, 0.0);
  // The same errors against the reference as the CPU renderer's, and those are float rounding: the
  // reference is cut at the same footprints, so what is left is summation order and float products.
  EXPECT_EQ(check.GradientDifference, check.CpuGradientError);
  EXPECT_GT(check.CpuGradientError, 0.0);
  EXPECT_LT(check.CpuGradientError, 1e-2) << check.Detail;
  EXPECT_TRUE(CheckBackend("cpu").Passed);
}

TEST(BackendCheck, AnImageOffByATenthOfAPercentFails)
{
  FaultyRenderer bright("bright", FaultyRenderer::BrighterImage);
  const BackendCheck check = CheckRenderer(bright);
  EXPECT_FALSE(check.Passed);
  // I <= 1 - exp(-0.8) = 0.55 on this field, so the fault moves it by at most 5.5e-4, and by more than
  // the bound (1e-5) wherever I > 0.01.
  EXPECT_GT(check.ImageDifference, 1e-5);
  EXPECT_LT(check.ImageDifference, 6e-4);
  EXPECT_NE(check.Detail.find("max |delta I|"), std::string::npos) << check.Detail;
}

TEST(BackendCheck, OneSmallGaussiansGradientOffByOnePercentFails)
{
  FaultyRenderer::SmallGaussian = SmallestVisibleReflectivityGradient();
  ASSERT_GE(FaultyRenderer::SmallGaussian, 0);
  FaultyRenderer faulty("faulty", FaultyRenderer::OneSmallReflectivityGradient);
  const BackendCheck check = CheckRenderer(faulty);
  EXPECT_FALSE(check.Passed);
  EXPECT_NEAR(check.GradientDifference, 0.01, 2e-3) << check.Detail; // 1 % of the Gaussian's own gradient
  EXPECT_EQ(check.ImageDifference, 0.0);
  EXPECT_NE(check.Detail.find("dL/dr of Gaussian " + std::to_string(FaultyRenderer::SmallGaussian)), std::string::npos)
    << check.Detail;
}

TEST(BackendCheck, AutoTakesOnlyABackendThatPassed)
{
  // Above every real backend ("cuda" registers at 10 where a GPU is usable), so that the two decide "auto".
  RegisterBackend("sound", &MakeSound, 1000);
  RegisterBackend("bright", &MakeBright, 2000);
  EXPECT_EQ(ResolveBackend("auto", nullptr), "sound");
  std::string error, notice;
  std::unique_ptr<Renderer> automatic = CreateRenderer("auto", &error, &notice);
  ASSERT_TRUE(automatic) << error;
  EXPECT_STREQ(automatic->GetName(), "sound");
  EXPECT_NE(notice.find("backend 'bright' failed its self-check"), std::string::npos) << notice;
  EXPECT_NE(notice.find("using sound"), std::string::npos) << notice;
  // Asked for by name it still runs, with the same warning.
  notice.clear();
  std::unique_ptr<Renderer> named = CreateRenderer("bright", &error, &notice);
  ASSERT_TRUE(named) << error;
  EXPECT_STREQ(named->GetName(), "bright");
  EXPECT_NE(notice.find("failed its self-check"), std::string::npos) << notice;
  // A backend that passes gets no notice; the check ran once and is remembered.
  notice.clear();
  ASSERT_TRUE(CreateRenderer("sound", &error, &notice));
  EXPECT_TRUE(notice.empty()) << notice;
  EXPECT_TRUE(CheckBackend("sound").Passed);
  EXPECT_FALSE(CheckBackend("bright").Passed);
  EXPECT_FALSE(CheckBackend("no-such-backend").Passed);
}
