// bigus::RenderPoints (the renderer of bent reslice grids) against the naive double reference renderer: the samples of
// sheared, oblique slices with and without the pixel low-pass, scattered samples each with its own plane (a 1 x 1
// reference slice each), a Gaussian larger than the binning's cells, and the errors of a folded grid.
#include "bigusPointRenderer.h"
#include "bigusReferenceRenderer.h"
#include "bigusRendererTestUtilities.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

using namespace bigus;
using namespace bigus::test;

namespace
{
/// The samples of every pixel of @p slice: its point and the slice's two pixel axes.
std::vector<PointSample> SamplesOf(const SliceGeometry& slice)
{
  const double* m = slice.ImageToReference;
  std::vector<PointSample> samples;
  for (int j = 0; j < slice.Height; ++j)
  {
    for (int i = 0; i < slice.Width; ++i)
    {
      PointSample s;
      for (int r = 0; r < 3; ++r)
      {
        s.Position[r] = m[4 * r] * i + m[4 * r + 1] * j + m[4 * r + 3];
        s.PixelAxes[0][r] = m[4 * r];
        s.PixelAxes[1][r] = m[4 * r + 1];
      }
      samples.push_back(s);
    }
  }
  return samples;
}

/// A 1 x 1 slice at @p s (its pixel axes as the slice's columns).
SliceGeometry SliceAt(const PointSample& s, double lowPass)
{
  SliceGeometry slice;
  const double m[16] = { s.PixelAxes[0][0], s.PixelAxes[1][0], 0, s.Position[0], s.PixelAxes[0][1], s.PixelAxes[1][1],
    0, s.Position[1], s.PixelAxes[0][2], s.PixelAxes[1][2], 0, s.Position[2], 0, 0, 0, 1 };
  std::copy(m, m + 16, slice.ImageToReference);
  slice.Width = slice.Height = 1;
  slice.PixelLowPass = lowPass;
  return slice;
}

/// Largest |RenderPoints - reference| over the samples (S), the reference with the renderers' cutoff.
double WorstAgainstReference(const reference::FieldD& field, const std::vector<PointSample>& samples,
  const std::vector<SliceGeometry>& slices, double lowPass, const RenderOptions& options, double* largest)
{
  const FieldF f = ToFloat(field);
  std::vector<float> S(samples.size()), I(samples.size());
  std::string error;
  EXPECT_TRUE(RenderPoints(
    f.View(), samples.data(), static_cast<std::int64_t>(samples.size()), lowPass, options, S.data(), I.data(), &error))
    << error;
  const reference::FieldD rounded = RoundedToFloat(field);
  double worst = 0;
  *largest = 0;
  std::size_t offset = 0;
  for (const SliceGeometry& slice : slices)
  {
    std::vector<double> refS, refI;
    EXPECT_TRUE(reference::Forward(rounded, slice, options, refS, &refI, true));
    for (std::size_t p = 0; p < refS.size(); ++p, ++offset)
    {
      worst = std::max(worst, std::abs(S[offset] - refS[p]));
      worst = std::max(worst, std::abs(I[offset] - refI[p]));
      *largest = std::max(*largest, std::abs(refS[p]));
    }
  }
  EXPECT_EQ(offset, samples.size());
  return worst;
}
}

// Every pixel of a sheared oblique slice, as samples with the slice's axes, is the reference's pixel: with point
// samples, the low-pass of a pixel's box (1/12) and a wide one (1.5 pixels^2), beam or thin plane.
TEST(PointRenderer, SamplesOfASlicedPlaneAreTheSlicesPixels)
{
  const double centre[3] = { 2, -1, 3 };
  const reference::FieldD field = RandomField(300, centre, 12, 0.8, 0.5, 11);
  const double axis[3] = { 0.3, -0.5, 0.8 }, origin[3] = { -4, -5, 1 };
  SliceGeometry slice = MakeSlice(24, 20, 0.45, 35, axis, origin);
  // Shear the second pixel axis by 40 degrees within the plane.
  for (int r = 0; r < 3; ++r)
  {
    slice.ImageToReference[4 * r + 1] += 0.84 * slice.ImageToReference[4 * r];
  }
  for (double lowPass : { 0.0, 1.0 / 12, 1.5 })
  {
    for (bool beam : { true, false })
    {
      RenderOptions options;
      options.ElevationSigma = 0.8;
      options.BeamIntegration = beam;
      options.MaximumShearAngle = 90;
      slice.PixelLowPass = lowPass;
      double largest;
      const double worst = WorstAgainstReference(field, SamplesOf(slice), { slice }, lowPass, options, &largest);
      EXPECT_GT(largest, 0.5) << "the slice misses the field";
      EXPECT_LT(worst, 2e-6) << "low-pass " << lowPass << ", beam " << beam;
    }
  }
}

// Scattered samples, each with its own random plane, pixel spacing and shear: each is its own 1 x 1 reference slice
// (the beam along its own normal). One Gaussian of 40 mm spans more cells than the binning keeps per Gaussian (the
// samples spread over 120 mm) and is seen by every sample; one 200 mm away by none.
TEST(PointRenderer, ScatteredSamplesEachOnItsOwnPlane)
{
  const double centre[3] = { 0, 0, 0 };
  reference::FieldD field = RandomField(400, centre, 16, 0.5, 0.6, 5);
  const double big[3] = { 1, 2, -1 }, far[3] = { 200, 0, 0 };
  for (const double* mean : { big, far })
  {
    for (int k = 0; k < 3; ++k)
    {
      field.Means.push_back(mean[k]);
      field.LogScales.push_back(std::log(mean == big ? 40.0 : 1.0));
    }
    for (double q : { 0.9, 0.1, -0.3, 0.2 })
    {
      field.Quaternions.push_back(q);
    }
    field.Reflectivities.push_back(mean == big ? 0.05 : 5.0);
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<PointSample> samples;
  std::vector<SliceGeometry> slices;
  for (int s = 0; s < 220; ++s)
  {
    PointSample p;
    for (int r = 0; r < 3; ++r)
    {
      p.Position[r] = (s < 200 ? 9 : 60) * u(rng); // the last 20 spread the cells over 120 mm
      p.PixelAxes[0][r] = 0.5 * u(rng);
      p.PixelAxes[1][r] = 0.5 * u(rng);
    }
    samples.push_back(p);
    slices.push_back(SliceAt(p, 0.25));
  }
  RenderOptions options;
  options.ElevationSigma = 1.2;
  options.MaximumShearAngle = 90;
  double largest;
  const double worst = WorstAgainstReference(field, samples, slices, 0.25, options, &largest);
  EXPECT_GT(largest, 0.5);
  EXPECT_LT(worst, 2e-6);
}

// A sample whose pixel axes are parallel, zero or not finite (a transform that folds the grid), and a bad low-pass,
// are refused by name; nothing is written.
TEST(PointRenderer, RefusesAFoldedGridAndABadLowPass)
{
  const double centre[3] = { 0, 0, 0 };
  const FieldF field = ToFloat(RandomField(10, centre, 4, 1, 0, 1));
  std::vector<PointSample> samples(3);
  for (PointSample& s : samples)
  {
    s = PointSample{ { 0, 0, 0 }, { { 1, 0, 0 }, { 0, 1, 0 } } };
  }
  samples[2].PixelAxes[1][0] = 2; // (2, 1, 0) is fine
  samples[1].PixelAxes[1][0] = 1;
  samples[1].PixelAxes[1][1] = 0; // b = (1, 0, 0) parallel to a
  std::vector<float> S(3, -7.0f);
  std::string error;
  RenderOptions options;
  EXPECT_FALSE(RenderPoints(field.View(), samples.data(), 3, 0, options, S.data(), nullptr, &error));
  EXPECT_NE(error.find("sample 1:"), std::string::npos) << error;
  EXPECT_EQ(S[0], -7.0f);
  samples[1].PixelAxes[1][1] = 1;
  samples[1].Position[2] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(RenderPoints(field.View(), samples.data(), 3, 0, options, S.data(), nullptr, &error));
  EXPECT_NE(error.find("sample 1:"), std::string::npos) << error;
  samples[1].Position[2] = 0;
  EXPECT_FALSE(RenderPoints(field.View(), samples.data(), 3, -1, options, S.data(), nullptr, &error));
  EXPECT_NE(error.find("PixelLowPass"), std::string::npos) << error;
  EXPECT_TRUE(RenderPoints(field.View(), samples.data(), 3, 0, options, S.data(), nullptr, &error)) << error;
  EXPECT_NE(S[0], -7.0f);
}
