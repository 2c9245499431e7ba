// The beam-integrated renderer: gradients of the shared formulas against central finite differences
// (double, through the quaternion normalisation and the rectifier), the float CPU backend against the
// naive double renderer, determinism across runs and thread counts, and bad poses.
#include "bigusReferenceRenderer.h"
#include "bigusRenderer.h"
#include "bigusRendererTestUtilities.h"

#include "vtkSMPTools.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

using namespace bigus;
using namespace bigus::test;

namespace
{
/// L = sum_p c_p X_p, X = I (or S).
double Loss(const reference::FieldD& field, const SliceGeometry& slice, const RenderOptions& o,
  const std::vector<double>& c, bool onS)
{
  std::vector<double> S, I;
  EXPECT_TRUE(reference::Forward(field, slice, o, S, &I));
  const std::vector<double>& X = onS ? S : I;
  double L = 0;
  for (std::size_t p = 0; p < X.size(); ++p)
  {
    L += c[p] * X[p];
  }
  return L;
}

/// Central differences of every parameter against the analytic reference backward.
void CheckGradients(
  reference::FieldD field, const SliceGeometry& slice, const RenderOptions& o, bool onS, double* worst)
{
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> c(std::size_t(slice.Width) * slice.Height);
  for (double& v : c)
  {
    v = u(rng);
  }
  std::vector<double> S, I;
  ASSERT_TRUE(reference::Forward(field, slice, o, S, &I));
  reference::GradD grad(field.Count());
  ASSERT_TRUE(reference::Backward(field, slice, o, S, c, onS, grad));

  struct Group
  {
    const char* Name;
    std::vector<double>* Values;
    const std::vector<double>* Grad;
  };
  Group groups[] = { { "mean", &field.Means, &grad.Means }, { "log-scale", &field.LogScales, &grad.LogScales },
    { "quaternion", &field.Quaternions, &grad.Quaternions },
    { "reflectivity", &field.Reflectivities, &grad.Reflectivities } };
  for (Group& g : groups)
  {
    double largest = 0;
    for (double v : *g.Grad)
    {
      largest = std::max(largest, std::abs(v));
    }
    ASSERT_GT(largest, 0) << g.Name << ": the case must exercise this gradient";
    for (std::size_t k = 0; k < g.Values->size(); ++k)
    {
      const double x = (*g.Values)[k];
      // Richardson-extrapolated central difference (error O(h^4)): a step large enough that
      // round-off in the loss stays near 1e-13 relative, small enough that truncation does too.
      const double h = 1e-4 * std::max(1.0, std::abs(x));
      auto at = [&](double v) {
        (*g.Values)[k] = v;
        return Loss(field, slice, o, c, onS);
      };
      const double d1 = at(x + h) - at(x - h);
      const double d2 = at(x + h / 2) - at(x - h / 2);
      (*g.Values)[k] = x;
      const double fd = (8 * d2 - d1) / (6 * h);
      const double an = (*g.Grad)[k];
      // Relative to the component, floored at 1e-6 of the group's largest so that components that
      // are zero up to round-off are compared absolutely.
      const double err = std::abs(fd - an) / std::max({ std::abs(fd), std::abs(an), 1e-6 * largest });
      *worst = std::max(*worst, err);
      EXPECT_LE(err, 1e-6) << g.Name << " [" << k << "]: finite difference " << fd << ", analytic " << an;
    }
  }
}

/// @p slice with its image's second axis tilted @p degrees towards the first, in the plane (a sheared pose).
SliceGeometry Sheared(SliceGeometry slice, double degrees)
{
  const double t = std::tan(degrees * M_PI / 180.0);
  for (int r = 0; r < 3; ++r)
  {
    slice.ImageToReference[4 * r + 1] += t * slice.ImageToReference[4 * r + 0];
  }
  return slice;
}

reference::FieldD GradientCaseField()
{
  // Five Gaussians near a tilted slice: anisotropic, off-plane, one with negative reflectivity and
  // unnormalised quaternions (norms 0.3 .. 2.5) so that the normalisation gradient is exercised.
  reference::FieldD f;
  f.Means = { 3.1, 2.4, 0.3, 5.2, 3.9, -0.6, 2.0, 5.1, 0.9, 6.3, 1.7, 0.1, 4.4, 4.6, -0.2 };
  f.LogScales = { std::log(1.2), std::log(0.5), std::log(0.8), std::log(2.0), std::log(0.4), std::log(0.6),
    std::log(0.7), std::log(0.7), std::log(1.5), std::log(0.3), std::log(1.9), std::log(0.9), std::log(1.0),
    std::log(0.8), std::log(0.35) };
  f.Quaternions = { 0.9, 0.3, -0.2, 0.1, 0.2, -0.1, 0.25, 0.05, 1.5, 1.1, 0.7, -1.2, -0.4, 0.8, 0.3, 0.6, 0.7, -0.2,
    0.1, 0.9 };
  f.Reflectivities = { 0.9, 0.6, -0.35, 0.8, 0.7 };
  return f;
}
}

TEST(RendererGradients, MatchFiniteDifferencesThroughTheRectifier)
{
  const double axis[3] = { 0.3, 1.0, 0.2 }, origin[3] = { 0.5, 0.2, 0.4 };
  const SliceGeometry slice = MakeSlice(22, 18, 0.4, 25, axis, origin);
  RenderOptions o;
  o.ElevationSigma = 0.8;
  o.Gamma = 1.3;
  double worst = 0;
  CheckGradients(GradientCaseField(), slice, o, false, &worst);
  std::printf("worst relative error, loss on I: %.3g\n", worst);
}

// The same through the pixel low-pass (SliceGeometry::PixelLowPass) on a sheared slice: the footprints' covariance
// and amplitude both carry it.
TEST(RendererGradients, MatchFiniteDifferencesThroughThePixelLowPass)
{
  const double axis[3] = { 0.3, 1.0, 0.2 }, origin[3] = { 0.5, 0.2, 0.4 };
  SliceGeometry slice = Sheared(MakeSlice(22, 18, 0.4, 25, axis, origin), 3);
  slice.PixelLowPass = 1.5;
  RenderOptions o;
  o.ElevationSigma = 0.8;
  o.Gamma = 1.3;
  double worst = 0;
  CheckGradients(GradientCaseField(), slice, o, false, &worst);
  std::printf("worst relative error, loss on I through the low-pass: %.3g\n", worst);
  // The low-pass changes the render (the case exercises it).
  std::vector<double> blurred, point;
  ASSERT_TRUE(reference::Forward(GradientCaseField(), slice, o, blurred, nullptr));
  slice.PixelLowPass = 0;
  ASSERT_TRUE(reference::Forward(GradientCaseField(), slice, o, point, nullptr));
  double change = 0;
  for (std::size_t p = 0; p < point.size(); ++p)
  {
    change = std::max(change, std::abs(blurred[p] - point[p]));
  }
  EXPECT_GT(change, 1e-2);
}

TEST(RendererGradients, MatchFiniteDifferencesOnTheScatteringField)
{
  const double axis[3] = { 1.0, -0.4, 0.5 }, origin[3] = { 0.2, 0.6, -0.3 };
  const SliceGeometry slice = MakeSlice(20, 20, 0.45, 60, axis, origin);
  double worst = 0;
  RenderOptions o;
  o.ElevationSigma = 0.3;
  CheckGradients(GradientCaseField(), slice, o, true, &worst);
  o.BeamIntegration = false; // thin plane
  CheckGradients(GradientCaseField(), slice, o, true, &worst);
  o.BeamIntegration = true;
  o.ElevationSigma = 5.0; // beam much thicker than the Gaussians
  CheckGradients(GradientCaseField(), slice, o, true, &worst);
  std::printf("worst relative error, loss on S: %.3g\n", worst);
}

TEST(RendererGradients, NonNegativeReflectivityPassesNoGradientToNegativeOnes)
{
  const double axis[3] = { 0.3, 1.0, 0.2 }, origin[3] = { 0.5, 0.2, 0.4 };
  const SliceGeometry slice = MakeSlice(22, 18, 0.4, 25, axis, origin);
  RenderOptions o;
  o.NonNegativeReflectivity = true;
  reference::FieldD f = GradientCaseField();
  std::vector<double> S, c(22 * 18, 1.0);
  ASSERT_TRUE(reference::Forward(f, slice, o, S));
  reference::GradD grad(f.Count());
  ASSERT_TRUE(reference::Backward(f, slice, o, S, c, true, grad));
  EXPECT_EQ(grad.Reflectivities[2], 0.0);
  EXPECT_EQ(grad.Means[6], 0.0) << "a Gaussian used as r = 0 has no footprint gradient either";
  EXPECT_NE(grad.Reflectivities[0], 0.0);
}

namespace
{
struct RealisticCase
{
  reference::FieldD Field;
  FieldF Float;
  SliceGeometry Slice;
};

RealisticCase MakeRealisticCase(int n, int pixels)
{
  // Gaussians in a 40 mm cube around an oblique 0.3 mm slice (38 mm field of view at 128 pixels),
  // scales 0.3..2 mm, signed reflectivities: the statistics of a trained liver field.
  RealisticCase c;
  const double centre[3] = { 120.0, -40.0, 80.0 };
  c.Field = RoundedToFloat(RandomField(n, centre, 40.0, 0.05, 0.3, 11));
  c.Float = ToFloat(c.Field);
  const double axis[3] = { 0.2, 0.9, -0.3 };
  const double spacing = 38.4 / pixels;
  const double origin[3] = { centre[0] - 19.2, centre[1] - 19.2, centre[2] };
  c.Slice = MakeSlice(pixels, pixels, spacing, 35, axis, origin);
  return c;
}
}

TEST(CpuRenderer, ForwardMatchesTheNaiveDoubleRenderer)
{
  const RealisticCase c = MakeRealisticCase(10000, 128);
  RenderOptions o;
  o.ElevationSigma = 0.5;
  o.Gamma = 1.0;
  std::vector<double> Sref, Iref;
  ASSERT_TRUE(reference::Forward(c.Field, c.Slice, o, Sref, &Iref));
  auto renderer = CreateCpuRenderer();
  const std::size_t pixels = Sref.size();
  std::vector<float> S(pixels), I(pixels);
  const double defaultCutoff = o.Cutoff;
  double errorAtDefault = 0;
  for (double cutoff : { 3.0, 4.0, 5.0, 6.0, defaultCutoff })
  {
    o.Cutoff = cutoff;
    RenderStats stats;
    std::string error;
    ASSERT_TRUE(renderer->Forward(c.Float.View(), &c.Slice, 1, o, S.data(), I.data(), &stats, &error)) << error;
    double maxI = 0, maxS = 0;
    for (std::size_t p = 0; p < pixels; ++p)
    {
      maxI = std::max(maxI, std::abs(I[p] - Iref[p]));
      maxS = std::max(maxS, std::abs(S[p] - Sref[p]));
    }
    std::printf("cutoff %.1f: max |I - I_ref| %.3g, max |S - S_ref| %.3g, %lld Gaussians kept, %lld evaluations\n",
      cutoff, maxI, maxS, static_cast<long long>(stats.GaussiansVisible),
      static_cast<long long>(stats.PixelEvaluations));
    if (cutoff == defaultCutoff)
    {
      errorAtDefault = maxI;
    }
  }
  // One 8-bit grey level is 3.9e-3: the default cutoff keeps the error more than 100 times below it.
  EXPECT_LT(errorAtDefault, 2e-5) << "default cutoff " << defaultCutoff;
}

TEST(CpuRenderer, FootprintKeepsThePixelsWithinTheCutoffIn3DMahalanobisDistance)
{
  // One isotropic Gaussian (s = 0.4 mm) 1 mm off the plane, beam sigma 0.3 mm: P2[z,z] = 0.25 mm^2, so
  // m_z^2 / P2[z,z] = 4 and, with k = 3, the footprint keeps |p - c|^2 / s^2 <= 9 - 4 = 5: a disc of
  // radius sqrt(5) 0.4 mm = 17.9 pixels of 0.05 mm, not the 3 s = 24 pixels of the in-plane cutoff alone.
  // The centre is off the pixel grid so that no pixel lies within 5e-3 of the disc's edge in the form:
  // float rounding cannot move a pixel across it in one pass and not in the other.
  const double s = 0.4, centre[2] = { 1.613, 1.571 };
  reference::FieldD field;
  field.Means = { centre[0], centre[1], 1.0 };
  field.LogScales = { std::log(s), std::log(s), std::log(s) };
  field.Quaternions = { 1, 0, 0, 0 };
  field.Reflectivities = { 1 };
  field = RoundedToFloat(field);
  const double axis[3] = { 0, 0, 1 }, origin[3] = { 0, 0, 0 };
  const SliceGeometry slice = MakeSlice(64, 64, 0.05, 0, axis, origin);
  RenderOptions o;
  o.ElevationSigma = 0.3;
  o.Cutoff = 3;
  std::vector<double> Sref;
  ASSERT_TRUE(reference::Forward(field, slice, o, Sref, nullptr));
  auto renderer = CreateCpuRenderer();
  const FieldF f = ToFloat(field);
  std::vector<float> S(Sref.size());
  ASSERT_TRUE(renderer->Forward(f.View(), &slice, 1, o, S.data(), nullptr, nullptr, nullptr));
  int inside = 0;
  double sum = 0;
  for (int j = 0; j < 64; ++j)
  {
    for (int i = 0; i < 64; ++i)
    {
      const std::size_t p = std::size_t(j) * 64 + i;
      const double dx = i * 0.05 - centre[0], dy = j * 0.05 - centre[1];
      const double form = (dx * dx + dy * dy) / (s * s);
      sum += S[p];
      if (form < 5 - 1e-3)
      {
        ++inside;
        EXPECT_NEAR(S[p], Sref[p], 1e-5 * Sref[p] + 1e-9) << "pixel " << i << ", " << j << " inside the disc";
      }
      else
      {
        ASSERT_GT(form, 5 + 1e-3) << "pixel " << i << ", " << j << " on the disc's edge";
        EXPECT_EQ(S[p], 0.f) << "pixel " << i << ", " << j << " outside the disc";
      }
    }
  }
  EXPECT_GT(inside, 900); // pi 17.9^2 = 1005 pixels
  // The backward pass sums over the same pixels: with dL/dS = 1, dL/dr = sum_p w(p) = sum_p S(p) / r.
  std::vector<float> ones(S.size(), 1.f), gr(1, 0.f);
  FieldGradients grads;
  grads.Reflectivities = gr.data();
  ASSERT_TRUE(renderer->Backward(f.View(), &slice, 1, o, S.data(), ones.data(), true, grads, nullptr, nullptr));
  EXPECT_NEAR(gr[0], sum, 1e-5 * sum);
}

TEST(CpuRenderer, BackwardMatchesTheNaiveDoubleRenderer)
{
  const RealisticCase c = MakeRealisticCase(600, 48);
  RenderOptions o;
  o.ElevationSigma = 0.5;
  std::vector<double> Sref, Iref;
  ASSERT_TRUE(reference::Forward(c.Field, c.Slice, o, Sref, &Iref));
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> dL(Sref.size());
  for (double& v : dL)
  {
    v = u(rng);
  }
  reference::GradD ref(c.Field.Count());
  ASSERT_TRUE(reference::Backward(c.Field, c.Slice, o, Sref, dL, false, ref));

  auto renderer = CreateCpuRenderer();
  std::vector<float> S(Sref.size()), dLf(dL.begin(), dL.end());
  ASSERT_TRUE(renderer->Forward(c.Float.View(), &c.Slice, 1, o, S.data(), nullptr, nullptr, nullptr));
  const std::int64_t n = c.Field.Count();
  std::vector<float> gm(3 * n, 0.f), gl(3 * n, 0.f), gq(4 * n, 0.f), gr(n, 0.f), ga(n, 0.f);
  FieldGradients grads;
  grads.Means = gm.data();
  grads.LogScales = gl.data();
  grads.Quaternions = gq.data();
  grads.Reflectivities = gr.data();
  grads.Attribution = ga.data();
  ASSERT_TRUE(renderer->Backward(c.Float.View(), &c.Slice, 1, o, S.data(), dLf.data(), false, grads, nullptr, nullptr));

  auto compare = [](const char* name, const std::vector<float>& cpu, const std::vector<double>& exact) {
    double largest = 0, worst = 0;
    for (double v : exact)
    {
      largest = std::max(largest, std::abs(v));
    }
    for (std::size_t k = 0; k < cpu.size(); ++k)
    {
      worst = std::max(worst, std::abs(cpu[k] - exact[k]));
    }
    std::printf("%-13s max |cpu - exact| = %.3g of largest %.3g\n", name, worst, largest);
    EXPECT_LE(worst, 1e-3 * largest) << name;
  };
  compare("mean", gm, ref.Means);
  compare("log-scale", gl, ref.LogScales);
  compare("quaternion", gq, ref.Quaternions);
  compare("reflectivity", gr, ref.Reflectivities);
  compare("attribution", ga, ref.Attribution);
}

TEST(CpuRenderer, ForwardIsBitwiseIdenticalAcrossRunsAndThreadCounts)
{
  const RealisticCase c = MakeRealisticCase(20000, 100);
  RenderOptions o;
  auto renderer = CreateCpuRenderer();
  const std::size_t pixels = 100 * 100;
  std::vector<float> first(pixels), again(pixels), single(pixels);
  vtkSMPTools::Initialize(2);
  ASSERT_TRUE(renderer->Forward(c.Float.View(), &c.Slice, 1, o, first.data(), nullptr, nullptr, nullptr));
  ASSERT_TRUE(renderer->Forward(c.Float.View(), &c.Slice, 1, o, again.data(), nullptr, nullptr, nullptr));
  vtkSMPTools::Initialize(1);
  ASSERT_TRUE(renderer->Forward(c.Float.View(), &c.Slice, 1, o, single.data(), nullptr, nullptr, nullptr));
  vtkSMPTools::Initialize(0);
  EXPECT_EQ(first, again);
  EXPECT_EQ(first, single);
  const double nonZero = static_cast<double>(std::count_if(first.begin(), first.end(), [](float v) { return v != 0; }));
  EXPECT_GT(nonZero, 0.9 * pixels) << "the case must cover the slice";
}

TEST(CpuRenderer, GradientsAreIdenticalAcrossRuns)
{
  const RealisticCase c = MakeRealisticCase(5000, 64);
  RenderOptions o;
  auto renderer = CreateCpuRenderer();
  std::vector<float> S(64 * 64), dL(64 * 64);
  for (std::size_t p = 0; p < dL.size(); ++p)
  {
    dL[p] = std::sin(0.37f * p);
  }
  ASSERT_TRUE(renderer->Forward(c.Float.View(), &c.Slice, 1, o, S.data(), nullptr, nullptr, nullptr));
  std::vector<float> runs[2];
  for (auto& g : runs)
  {
    g.assign(3 * 5000, 0.f);
    FieldGradients grads;
    grads.Means = g.data();
    ASSERT_TRUE(
      renderer->Backward(c.Float.View(), &c.Slice, 1, o, S.data(), dL.data(), false, grads, nullptr, nullptr));
  }
  EXPECT_EQ(runs[0], runs[1]);
}

TEST(CpuRenderer, BadPosesAndLowPassesAreRejectedWithAReason)
{
  const RealisticCase c = MakeRealisticCase(10, 16);
  SliceGeometry slices[2] = { c.Slice, c.Slice };
  slices[1].ImageToReference[1] = slices[1].ImageToReference[0]; // make the axes parallel
  slices[1].ImageToReference[5] = slices[1].ImageToReference[4];
  slices[1].ImageToReference[9] = slices[1].ImageToReference[8];
  auto renderer = CreateCpuRenderer();
  std::vector<float> S(2 * 16 * 16, -7.f);
  std::string error;
  RenderOptions o;
  EXPECT_FALSE(renderer->Forward(c.Float.View(), slices, 2, o, S.data(), nullptr, nullptr, &error));
  EXPECT_NE(error.find("slice 1"), std::string::npos) << error;
  EXPECT_NE(error.find("singular"), std::string::npos) << error;
  EXPECT_TRUE(std::all_of(S.begin(), S.end(), [](float v) { return v == -7.f; })) << "nothing written";
  // A pixel low-pass that is no variance.
  for (double lowPass : { -0.25, std::numeric_limits<double>::quiet_NaN(), 1e7 })
  {
    slices[1] = c.Slice;
    slices[1].PixelLowPass = lowPass;
    error.clear();
    EXPECT_FALSE(renderer->Forward(c.Float.View(), slices, 2, o, S.data(), nullptr, nullptr, &error));
    EXPECT_NE(error.find("slice 1: PixelLowPass"), std::string::npos) << error;
    EXPECT_TRUE(std::all_of(S.begin(), S.end(), [](float v) { return v == -7.f; })) << "nothing written";
  }
}

TEST(CpuRenderer, HardCasesGiveNoNaNOrInfInOutputsOrGradients)
{
  // Needles and pancakes (ratios to 1e4), extreme log-scales, tiny / huge / zero quaternions, all
  // tilts, near and far from a slice 1 m from the origin, for a thin and a thick beam.
  const double centre[3] = { 1000.0, -1000.0, 1000.0 };
  const double axis[3] = { 0.3, 0.2, 1.0 };
  const double origin[3] = { centre[0] - 4.8, centre[1] - 4.8, centre[2] };
  const SliceGeometry slice = MakeSlice(32, 32, 0.3, 20, axis, origin);
  reference::FieldD f;
  const double logScales[][3] = { { 0, 0, 0 }, { std::log(2.0), std::log(2e-4), std::log(2e-4) },
    { std::log(3.0), std::log(3.0), std::log(3e-4) }, { -40, 0, 0 }, { 40, -40, 0 }, { 25, 25, 25 },
    { -25, -25, -25 } };
  const double quaternions[][4] = { { 1, 0, 0, 0 }, { 1e-12, 1e-13, 0, 0 }, { 1e12, 3e11, -2e12, 0 }, { 0, 0, 0, 0 },
    { 0.7, 0.7, 0, 0 }, { 0.38, 0, 0.92, 0 } };
  for (const auto& l : logScales)
  {
    for (const auto& q : quaternions)
    {
      for (double offset : { 0.0, 0.4, 3.0, 1e3 })
      {
        for (int k = 0; k < 3; ++k)
        {
          f.Means.push_back(centre[k] + (k == 2 ? offset : 0.7 * k));
          f.LogScales.push_back(l[k]);
        }
        f.Quaternions.insert(f.Quaternions.end(), q, q + 4);
        f.Reflectivities.push_back(offset > 1 ? -0.5 : 0.8);
      }
    }
  }
  const FieldF field = ToFloat(f);
  auto renderer = CreateCpuRenderer();
  for (double sigmaE : { 0.0, 1e-4, 0.5, 100.0 })
  {
    RenderOptions o;
    o.ElevationSigma = sigmaE;
    std::vector<float> S(32 * 32), I(32 * 32), dL(32 * 32, 1.0f);
    std::string error;
    ASSERT_TRUE(renderer->Forward(field.View(), &slice, 1, o, S.data(), I.data(), nullptr, &error)) << error;
    const std::int64_t n = field.View().Count;
    std::vector<float> gm(3 * n), gl(3 * n), gq(4 * n), gr(n), ga(n);
    FieldGradients grads;
    grads.Means = gm.data();
    grads.LogScales = gl.data();
    grads.Quaternions = gq.data();
    grads.Reflectivities = gr.data();
    grads.Attribution = ga.data();
    ASSERT_TRUE(renderer->Backward(field.View(), &slice, 1, o, S.data(), dL.data(), false, grads, nullptr, &error));
    for (const std::vector<float>* v : { &S, &I, &gm, &gl, &gq, &gr, &ga })
    {
      for (float x : *v)
      {
        ASSERT_TRUE(std::isfinite(x)) << "sigma_E " << sigmaE;
      }
    }
    EXPECT_TRUE(std::any_of(S.begin(), S.end(), [](float v) { return v != 0; })) << "some case must be visible";
  }
}

// Pose refinement: CorrectPose moves a slice as the correction says (a known motion), and the CPU backend's
// gradient with respect to the correction (FieldGradients::SlicePoses) matches central differences of the
// double reference renderer's loss over corrected poses, on an oblique slice and on one with 3 degrees of
// shear and a pixel low-pass, two slices in one call.
TEST(CpuRenderer, ThePoseGradientMatchesCentralDifferencesOverCorrectedPoses)
{
  const RealisticCase c = MakeRealisticCase(600, 48);
  SliceGeometry sheared = Sheared(c.Slice, 3);
  sheared.PixelLowPass = 1.0 / 16; // and the coarse frames' low-pass (DecimateFrames with averages)
  const SliceGeometry slices[2] = { c.Slice, sheared };

  // A known motion: 1 mm along the normal moves every pixel by n; a quarter turn about n keeps the centre
  // pixel where it was.
  double F[3][3], o[3], p2p[3], moved[16];
  ASSERT_EQ(ComputeRenderingFrame(c.Slice.ImageToReference, 90, F, o, p2p), PoseStatus::Ok);
  auto pixel = [](
                 const double* m, double i, double j, int k) { return m[4 * k] * i + m[4 * k + 1] * j + m[4 * k + 3]; };
  const double shift[6] = { 0, 0, 0, 0, 0, 1 };
  ASSERT_EQ(CorrectPose(c.Slice.ImageToReference, 48, 48, shift, moved), PoseStatus::Ok);
  for (int k = 0; k < 3; ++k)
  {
    EXPECT_NEAR(pixel(moved, 7, 30, k), pixel(c.Slice.ImageToReference, 7, 30, k) + F[2][k], 1e-9);
  }
  const double turn[6] = { 0, 0, M_PI / 2, 0, 0, 0 };
  ASSERT_EQ(CorrectPose(c.Slice.ImageToReference, 48, 48, turn, moved), PoseStatus::Ok);
  for (int k = 0; k < 3; ++k)
  {
    EXPECT_NEAR(pixel(moved, 23.5, 23.5, k), pixel(c.Slice.ImageToReference, 23.5, 23.5, k), 1e-9);
    // Pixel (23.5 + 10, 23.5) moves to where pixel (23.5, 23.5 + 10) was (square pixels, no shear).
    EXPECT_NEAR(pixel(moved, 33.5, 23.5, k), pixel(c.Slice.ImageToReference, 23.5, 33.5, k), 1e-9);
  }

  RenderOptions options;
  options.ElevationSigma = 0.5;
  const std::size_t pixels = 48 * 48;
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> weights(2 * pixels);
  for (double& v : weights)
  {
    v = u(rng);
  }
  auto renderer = CreateCpuRenderer();
  std::vector<float> S(2 * pixels), dL(weights.begin(), weights.end());
  ASSERT_TRUE(renderer->Forward(c.Float.View(), slices, 2, options, S.data(), nullptr, nullptr, nullptr));
  double poses[12] = { 0 };
  FieldGradients grads;
  grads.SlicePoses = poses;
  ASSERT_TRUE(
    renderer->Backward(c.Float.View(), slices, 2, options, S.data(), dL.data(), false, grads, nullptr, nullptr));
  for (int s = 0; s < 2; ++s)
  {
    const std::vector<double> w(weights.begin() + s * pixels, weights.begin() + (s + 1) * pixels);
    auto loss = [&](const double xi[6]) {
      SliceGeometry g = slices[s];
      EXPECT_EQ(CorrectPose(slices[s].ImageToReference, 48, 48, xi, g.ImageToReference), PoseStatus::Ok);
      return Loss(c.Field, g, options, w, false);
    };
    double largest = 0;
    for (int k = 0; k < 6; ++k)
    {
      largest = std::max(largest, std::abs(poses[6 * s + k]));
    }
    ASSERT_GT(largest, 0);
    for (int k = 0; k < 6; ++k)
    {
      const double fd = test::PoseCentralDifference(loss, k);
      std::printf("slice %d, xi[%d]: finite difference %.6g, CPU backend %.6g\n", s, k, fd, poses[6 * s + k]);
      EXPECT_NEAR(poses[6 * s + k], fd, 1e-3 * largest) << "slice " << s << ", component " << k;
    }
  }

  // The same call twice gives the same sums (each Gaussian's share summed in index order).
  double again[12] = { 0 };
  grads.SlicePoses = again;
  ASSERT_TRUE(
    renderer->Backward(c.Float.View(), slices, 2, options, S.data(), dL.data(), false, grads, nullptr, nullptr));
  EXPECT_EQ(std::memcmp(poses, again, sizeof(poses)), 0);
}
