// vtkGaussianFieldReslice: a Gaussian lands where geometry says, slices agree with the naive double
// renderer, a stack is a volume that vtkImageReslice can cut, and the matrix drives the pipeline.
#include "bigusGaussianFieldData.h"
#include "bigusReferenceRenderer.h"

#include "vtkFloatArray.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkImageData.h"
#include "vtkImageReslice.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

using namespace bigus;

namespace
{
/// One isotropic Gaussian of sigma 0.6 mm at `centre`, reflectivity 1.
vtkSmartPointer<vtkPolyData> OneGaussian(const double centre[3])
{
  GaussianField f;
  f.Means = { float(centre[0]), float(centre[1]), float(centre[2]) };
  f.LogScales = { std::log(0.6f), std::log(0.6f), std::log(0.6f) };
  f.Quaternions = { 1, 0, 0, 0 };
  f.Reflectivities = { 1.0f };
  FieldModel model;
  model.ElevationSigma = 0.4;
  model.Gamma = 1.5;
  model.PixelSpacing = 0.25;
  auto data = vtkSmartPointer<vtkPolyData>::New();
  FieldToPolyData(f, model, data);
  return data;
}

vtkSmartPointer<vtkPolyData> RandomField(int n, unsigned seed, reference::FieldD& exact)
{
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  GaussianField f;
  for (int i = 0; i < n; ++i)
  {
    for (int k = 0; k < 3; ++k)
    {
      f.Means.push_back(10 * u(rng));
      f.LogScales.push_back(std::log(0.3f + 0.7f * u(rng)));
    }
    float q[4], n2 = 0;
    for (float& v : q)
    {
      v = u(rng) - 0.5f;
      n2 += v * v;
    }
    for (float v : q)
    {
      f.Quaternions.push_back(v / std::sqrt(n2));
    }
    f.Reflectivities.push_back(0.4f * (u(rng) - 0.3f));
  }
  FieldModel model;
  model.ElevationSigma = 0.7;
  model.Gamma = 1.2;
  auto data = vtkSmartPointer<vtkPolyData>::New();
  FieldToPolyData(f, model, data);
  // What the filter reads back (scales through exp/log, quaternions normalised) is the exact field.
  FieldFromPolyData(data, f, model, nullptr);
  exact.Means.assign(f.Means.begin(), f.Means.end());
  exact.LogScales.assign(f.LogScales.begin(), f.LogScales.end());
  exact.Quaternions.assign(f.Quaternions.begin(), f.Quaternions.end());
  exact.Reflectivities.assign(f.Reflectivities.begin(), f.Reflectivities.end());
  return data;
}

/// An oblique reslice frame: rotation by 30 degrees about (1, 1, 0) / sqrt 2, origin o.
vtkSmartPointer<vtkMatrix4x4> Oblique(double ox, double oy, double oz)
{
  const double t = M_PI / 6, c = std::cos(t), s = std::sin(t), C = 1 - c, x = M_SQRT1_2, y = M_SQRT1_2;
  const double R[3][3] = { { c + x * x * C, x * y * C, y * s }, { y * x * C, c + y * y * C, -x * s },
    { -y * s, x * s, c } };
  auto m = vtkSmartPointer<vtkMatrix4x4>::New();
  for (int r = 0; r < 3; ++r)
  {
    for (int k = 0; k < 3; ++k)
    {
      m->SetElement(r, k, R[r][k]);
    }
  }
  m->SetElement(0, 3, ox);
  m->SetElement(1, 3, oy);
  m->SetElement(2, 3, oz);
  return m;
}
}

TEST(GaussianFieldReslice, AGaussianAppearsWhereTheResliceAxesPutIt)
{
  // A Gaussian at reslice-frame position (3.0, 2.0, 0) must peak at output voxel (3.0, 2.0) / spacing.
  vtkSmartPointer<vtkMatrix4x4> axes = Oblique(5, -2, 7);
  const double local[4] = { 3.0, 2.0, 0.0, 1.0 };
  double world[4];
  axes->MultiplyPoint(local, world);
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(OneGaussian(world));
  reslice->SetResliceAxes(axes);
  reslice->SetOutputSpacing(0.25, 0.25, 1);
  reslice->SetOutputOrigin(0, 0, 0);
  reslice->SetOutputExtent(0, 39, 0, 29, 0, 0);
  reslice->Update();
  vtkImageData* out = reslice->GetOutput();
  int dims[3];
  out->GetDimensions(dims);
  ASSERT_EQ(dims[0], 40);
  ASSERT_EQ(dims[1], 30);
  ASSERT_EQ(dims[2], 1);
  auto* I = static_cast<float*>(out->GetScalarPointer());
  const int best = static_cast<int>(std::max_element(I, I + 40 * 30) - I);
  EXPECT_EQ(best % 40, 12);
  EXPECT_EQ(best / 40, 8);
  // On the plane, the beam-integrated peak of a sigma-0.6 isotropic Gaussian with sigma_E 0.4 is
  // amp = 1 / sqrt(1 + 0.4^2 / 0.6^2); I = 1 - exp(-gamma amp).
  EXPECT_NEAR(I[best], 1 - std::exp(-1.5 / std::sqrt(1 + 0.16 / 0.36)), 1e-5);
}

TEST(GaussianFieldReslice, SlicesMatchTheNaiveDoubleRenderer)
{
  reference::FieldD exact;
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(RandomField(300, 4, exact));
  vtkSmartPointer<vtkMatrix4x4> axes = Oblique(5, 5, 5);
  reslice->SetResliceAxes(axes);
  reslice->SetOutputSpacing(0.2, 0.3, 0.5);
  reslice->SetOutputOrigin(-4, -3, -1);
  reslice->SetOutputExtent(0, 39, 0, 24, 0, 3);
  reslice->SetOutputDimensionality(3);
  reslice->OutputScatteringFieldOn();
  reslice->Update();
  vtkImageData* out = reslice->GetOutput();
  ASSERT_EQ(out->GetDimensions()[2], 4);
  auto* I = static_cast<float*>(out->GetScalarPointer());
  vtkFloatArray* S = vtkFloatArray::SafeDownCast(out->GetPointData()->GetArray("ScatteringField"));
  ASSERT_NE(S, nullptr);
  RenderOptions o;
  o.ElevationSigma = 0.7;
  o.Gamma = 1.2;
  double worst = 0;
  for (int k = 0; k < 4; ++k)
  {
    // Independent pose: ResliceAxes * (origin + index * spacing), written out by hand.
    SliceGeometry g;
    g.Width = 40;
    g.Height = 25;
    const double z = -1 + 0.5 * k;
    for (int r = 0; r < 3; ++r)
    {
      const double* a = &axes->Element[r][0];
      g.ImageToReference[4 * r + 0] = a[0] * 0.2;
      g.ImageToReference[4 * r + 1] = a[1] * 0.3;
      g.ImageToReference[4 * r + 2] = a[2];
      g.ImageToReference[4 * r + 3] = a[0] * -4 + a[1] * -3 + a[2] * z + a[3];
    }
    g.ImageToReference[12] = g.ImageToReference[13] = g.ImageToReference[14] = 0;
    g.ImageToReference[15] = 1;
    std::vector<double> Sref, Iref;
    ASSERT_TRUE(reference::Forward(exact, g, o, Sref, &Iref));
    for (int p = 0; p < 40 * 25; ++p)
    {
      worst = std::max(worst, std::abs(I[k * 1000 + p] - Iref[p]));
      EXPECT_NEAR(S->GetValue(k * 1000 + p), Sref[p], 2e-5);
    }
  }
  std::printf("max |I - I_naive| over the stack: %.3g\n", worst);
  EXPECT_LT(worst, 1e-5);
}

TEST(GaussianFieldReslice, DefaultsCoverTheFieldAndAStackIsAVolumeForImageReslice)
{
  reference::FieldD exact;
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(RandomField(200, 5, exact));
  reslice->SetOutputDimensionality(3);
  reslice->SetOutputScalarTypeToUnsignedChar();
  reslice->Update();
  vtkImageData* volume = reslice->GetOutput();
  double bounds[6];
  volume->GetBounds(bounds);
  // Means lie in [0, 10]^3; the default grid covers them (padded by three times the largest scale).
  for (int k = 0; k < 3; ++k)
  {
    EXPECT_LE(bounds[2 * k], 0.0);
    EXPECT_GE(bounds[2 * k + 1], 10.0);
  }
  EXPECT_EQ(volume->GetScalarType(), VTK_UNSIGNED_CHAR);
  EXPECT_DOUBLE_EQ(volume->GetSpacing()[0], 0.5) << "no PixelSpacing in this field: 0.5 mm";

  // vtkImageReslice takes it as any volume: cutting grid plane 10 of the stack gives exactly what a
  // 2D vtkGaussianFieldReslice renders on that plane.
  const double* origin = volume->GetOrigin();
  const int* extent = volume->GetExtent();
  const double z = origin[2] + 10 * 0.5;
  vtkNew<vtkImageReslice> cut;
  cut->SetInputData(volume);
  cut->SetInterpolationModeToNearestNeighbor();
  cut->SetOutputSpacing(0.5, 0.5, 0.5);
  cut->SetOutputOrigin(origin[0], origin[1], origin[2]);
  cut->SetOutputExtent(extent[0], extent[1], extent[2], extent[3], 10, 10);
  cut->Update();
  vtkNew<vtkGaussianFieldReslice> plane;
  plane->SetInputData(reslice->GetInput());
  plane->SetOutputScalarTypeToUnsignedChar();
  plane->SetOutputSpacing(0.5, 0.5, 0.5);
  plane->SetOutputOrigin(origin[0], origin[1], z);
  plane->SetOutputExtent(extent[0], extent[1], extent[2], extent[3], 0, 0);
  plane->Update();
  const vtkIdType n = plane->GetOutput()->GetNumberOfPoints();
  ASSERT_EQ(cut->GetOutput()->GetNumberOfPoints(), n);
  const auto* a = static_cast<unsigned char*>(cut->GetOutput()->GetScalarPointer());
  const auto* b = static_cast<unsigned char*>(plane->GetOutput()->GetScalarPointer());
  int mismatches = 0, largest = 0;
  for (vtkIdType p = 0; p < n; ++p)
  {
    mismatches += a[p] != b[p];
    largest = std::max(largest, std::abs(int(a[p]) - int(b[p])));
  }
  EXPECT_EQ(mismatches, 0) << "largest difference " << largest;
  EXPECT_GT(std::count_if(b, b + n, [](unsigned char v) { return v > 0; }), n / 10);
}

TEST(GaussianFieldReslice, ChangingTheMatrixReExecutes)
{
  const double centre[3] = { 0, 0, 0 };
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(OneGaussian(centre));
  vtkNew<vtkMatrix4x4> axes;
  reslice->SetResliceAxes(axes);
  reslice->SetOutputSpacing(0.5, 0.5, 1);
  reslice->SetOutputOrigin(-2, -2, 0);
  reslice->SetOutputExtent(0, 8, 0, 8, 0, 0);
  reslice->Update();
  const float before = static_cast<float*>(reslice->GetOutput()->GetScalarPointer())[4 * 9 + 4];
  axes->SetElement(2, 3, 1.5); // move the plane 1.5 mm off the Gaussian
  reslice->Update();
  const float after = static_cast<float*>(reslice->GetOutput()->GetScalarPointer())[4 * 9 + 4];
  EXPECT_GT(before, 0.5);
  EXPECT_LT(after, before * 0.5);
}
