// vtkGaussianFieldReslice: a Gaussian lands where geometry says, slices agree with the naive double
// renderer, a stack is a volume that vtkImageReslice can cut, and the matrix drives the pipeline.
// The backend comes from the registry (both field renderers), the renderer and the converted field are
// kept between executes, RequestInformation leaves the input alone, a stack reports progress and
// stops when aborted, and the announced scalar type is the produced one.
#include "bigusBackend.h"
#include "bigusGaussianFieldData.h"
#include "bigusReferenceRenderer.h"
#include "bigusTestUtilities.h"

#include "vtkCallbackCommand.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkGaussianFieldSequenceRenderer.h"
#include "vtkImageData.h"
#include "vtkImageReslice.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkPoints.h"
#include "vtkPolyData.h"
#include "vtkPolyDataAlgorithm.h"
#include "vtkStreamingDemandDrivenPipeline.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

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
  exact = reference::FromView(f.View());
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

// PixelLowPass 1/12 (a box of one output pixel) makes each pixel of a coarse slice the average over its area: the
// truth is the mean of a 4 x 4 grid of point samples inside each coarse pixel (a render at a quarter of the
// spacing); the low-passed slice must be much closer to it than the point-sampled one.
TEST(GaussianFieldReslice, APixelLowPassOfOneTwelfthAveragesEachPixelsArea)
{
  reference::FieldD exact;
  vtkSmartPointer<vtkPolyData> field = RandomField(300, 4, exact);
  vtkSmartPointer<vtkMatrix4x4> axes = Oblique(5, 5, 5);
  const double coarse = 0.8, fine = coarse / 4;
  auto render = [&](double spacing, double origin, int width, int height, double lowPass) {
    vtkNew<vtkGaussianFieldReslice> reslice;
    reslice->SetInputData(field);
    reslice->SetResliceAxes(axes);
    reslice->SetOutputSpacing(spacing, spacing, 1);
    reslice->SetOutputOrigin(origin, origin, 0);
    reslice->SetOutputExtent(0, width - 1, 0, height - 1, 0, 0);
    reslice->SetPixelLowPass(lowPass);
    reslice->OutputScatteringFieldOn();
    reslice->Update();
    vtkFloatArray* S = vtkFloatArray::SafeDownCast(reslice->GetOutput()->GetPointData()->GetArray("ScatteringField"));
    EXPECT_NE(S, nullptr);
    return std::vector<float>(S->GetPointer(0), S->GetPointer(0) + std::size_t(width) * height);
  };
  const int w = 16, h = 12;
  const std::vector<float> point = render(coarse, -6, w, h, 0);
  const std::vector<float> blurred = render(coarse, -6, w, h, 1.0 / 12);
  const std::vector<float> sub = render(fine, -6 - 1.5 * fine, 4 * w, 4 * h, 0);
  double pointError = 0, blurredError = 0;
  for (int j = 0; j < h; ++j)
  {
    for (int i = 0; i < w; ++i)
    {
      double mean = 0;
      for (int b = 0; b < 4; ++b)
      {
        for (int a = 0; a < 4; ++a)
        {
          mean += sub[std::size_t(4 * j + b) * 4 * w + 4 * i + a] / 16.0;
        }
      }
      pointError += (point[j * w + i] - mean) * (point[j * w + i] - mean);
      blurredError += (blurred[j * w + i] - mean) * (blurred[j * w + i] - mean);
    }
  }
  std::printf("RMS against the pixels' area means: low-pass %.3g, point samples %.3g\n",
    std::sqrt(blurredError / (w * h)), std::sqrt(pointError / (w * h)));
  EXPECT_GT(pointError, 0);
  EXPECT_LT(blurredError, 0.25 * pointError);
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
  // one-slice vtkGaussianFieldReslice renders on that plane (OutputDimensionality 3 with a z extent of one
  // slice: as in vtkImageReslice, dimensionality 2 would put the slice through the axes' origin).
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
  plane->SetOutputDimensionality(3);
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

namespace
{
/// A pipeline source of a Gaussian field that counts its executions (a reader or a trainer upstream).
class CountingFieldSource : public vtkPolyDataAlgorithm
{
public:
  static CountingFieldSource* New();
  vtkTypeMacro(CountingFieldSource, vtkPolyDataAlgorithm);
  void SetField(vtkPolyData* field)
  {
    this->Field = field;
    this->Modified();
  }
  int Executions = 0;

protected:
  CountingFieldSource() { this->SetNumberOfInputPorts(0); }
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector* outputVector) override
  {
    ++this->Executions;
    vtkPolyData::GetData(outputVector, 0)->ShallowCopy(this->Field);
    return 1;
  }
  vtkSmartPointer<vtkPolyData> Field;
};
vtkStandardNewMacro(CountingFieldSource);

/// The field moved by (dx, 0, 0) mm.
vtkSmartPointer<vtkPolyData> Shifted(vtkPolyData* field, double dx)
{
  auto moved = vtkSmartPointer<vtkPolyData>::New();
  moved->DeepCopy(field);
  for (vtkIdType i = 0; i < moved->GetNumberOfPoints(); ++i)
  {
    double p[3];
    moved->GetPoint(i, p);
    p[0] += dx;
    moved->GetPoints()->SetPoint(i, p);
  }
  moved->GetPoints()->Modified();
  return moved;
}

std::vector<float> Values(vtkImageData* image)
{
  vtkDataArray* scalars = image->GetPointData()->GetScalars();
  std::vector<float> v(scalars ? scalars->GetNumberOfTuples() : 0);
  for (std::size_t p = 0; p < v.size(); ++p)
  {
    v[p] = static_cast<float>(scalars->GetComponent(p, 0));
  }
  return v;
}

/// The scalar type the output information announces.
int AnnouncedScalarType(vtkAlgorithm* filter)
{
  vtkInformation* scalars = vtkDataObject::GetActiveFieldInformation(
    filter->GetOutputInformation(0), vtkDataObject::FIELD_ASSOCIATION_POINTS, vtkDataSetAttributes::SCALARS);
  return scalars ? scalars->Get(vtkDataObject::FIELD_ARRAY_TYPE()) : -1;
}

/// Poses of a small sweep through the random field (0.25 mm pixels, frames 1 mm apart along z).
vtkSmartPointer<vtkImageData> SweepThroughTheField()
{
  std::vector<std::array<double, 16>> poses;
  for (int k = 0; k < 3; ++k)
  {
    poses.push_back({ 0.25, 0, 0, 1, 0, 0.25, 0, 1, 0, 0, 1, 3.0 + k, 0, 0, 0, 1 });
  }
  return bigus_test::TrackedSequence(24, 20, poses, { 0, 0.1, 0.2 }, [](int, int, int) { return 0.f; });
}

/// How often the registry's "counting" backend (a CPU renderer) was created.
int CountingCreations = 0;
std::unique_ptr<Renderer> CountingFactory(std::string*)
{
  ++CountingCreations;
  return CreateCpuRenderer();
}
}

TEST(GaussianFieldReslice, AZeroOrNegativeOutputSpacingIsAnErrorThatNamesIt)
{
  // (It blamed "ImageToReference is singular" before: the spacing is what the caller set wrong.)
  reference::FieldD exact;
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(RandomField(50, 6, exact));
  reslice->SetOutputOrigin(0, 0, 5);
  reslice->SetOutputExtent(0, 19, 0, 19, 0, 0);
  vtkNew<bigus_test::MessageCollector> messages;
  messages->Watch(reslice);
  const double bad[3][3] = { { 0, 0.1, 0.1 }, { 0.1, -1, 0.1 }, { 0.1, 0.1, std::nan("") } };
  for (int c = 0; c < 3; ++c)
  {
    reslice->SetOutputDimensionality(c == 2 ? 3 : 2);
    reslice->SetOutputSpacing(bad[c][0], bad[c][1], bad[c][2]);
    reslice->Update();
    ASSERT_EQ(messages->Errors.size(), std::size_t(c + 1));
    EXPECT_NE(messages->Errors[c].find("OutputSpacing"), std::string::npos) << messages->Errors[c];
    EXPECT_EQ(messages->Errors[c].find("singular"), std::string::npos) << messages->Errors[c];
    EXPECT_EQ(reslice->GetOutput()->GetNumberOfPoints(), 0);
  }
  reslice->SetOutputDimensionality(2);
  reslice->SetOutputSpacing(0.5, 0.5, 1);
  reslice->Update();
  EXPECT_EQ(reslice->GetOutput()->GetNumberOfPoints(), 400);
}

TEST(GaussianFieldReslice, AnUnavailableBackendIsAnErrorThatNamesIt)
{
  reference::FieldD exact;
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(RandomField(50, 6, exact));
  reslice->SetOutputSpacing(0.5, 0.5, 1);
  reslice->SetOutputOrigin(0, 0, 5);
  reslice->SetOutputExtent(0, 19, 0, 19, 0, 0);
  EXPECT_STREQ(reslice->GetBackend(), "auto");
  reslice->SetBackend("nonexistent");
  vtkNew<bigus_test::MessageCollector> messages;
  messages->Watch(reslice);
  reslice->Update();
  ASSERT_EQ(messages->Errors.size(), 1u);
  EXPECT_NE(messages->Errors[0].find("'nonexistent'"), std::string::npos) << messages->Errors[0];
  EXPECT_NE(messages->Errors[0].find("available: auto, cpu"), std::string::npos) << messages->Errors[0];
  EXPECT_EQ(reslice->GetOutput()->GetNumberOfPoints(), 0);

  // Naming an available backend renders again.
  reslice->SetBackend("cpu");
  reslice->Update();
  EXPECT_EQ(reslice->GetOutput()->GetNumberOfPoints(), 400);

  vtkNew<vtkGaussianFieldSequenceRenderer> sequence;
  sequence->SetInputData(reslice->GetInput());
  sequence->SetPoseData(SweepThroughTheField());
  EXPECT_STREQ(sequence->GetBackend(), "auto");
  sequence->SetBackend("nonexistent");
  messages->Watch(sequence);
  sequence->Update();
  ASSERT_EQ(messages->Errors.size(), 2u);
  EXPECT_NE(messages->Errors[1].find("'nonexistent'"), std::string::npos) << messages->Errors[1];
  EXPECT_EQ(sequence->GetOutput()->GetNumberOfPoints(), 0);
}

TEST(GaussianFieldReslice, CpuAndAutoRenderTheSameImages)
{
  // "auto" is the CPU renderer unless a GPU backend registered; then the two agree to float rounding.
  const bool autoIsCpu = ResolveBackend("auto", nullptr) == "cpu";
  const double tolerance = autoIsCpu ? 0.0 : 1e-4;
  reference::FieldD exact;
  vtkSmartPointer<vtkPolyData> field = RandomField(300, 7, exact);
  std::vector<float> images[2][2];
  const char* names[2] = { "cpu", "auto" };
  for (int b = 0; b < 2; ++b)
  {
    vtkNew<vtkGaussianFieldReslice> reslice;
    reslice->SetInputData(field);
    reslice->SetResliceAxes(Oblique(5, 5, 5));
    reslice->SetOutputSpacing(0.25, 0.25, 0.5);
    reslice->SetOutputOrigin(-4, -4, -1);
    reslice->SetOutputExtent(0, 31, 0, 31, 0, 2);
    reslice->SetOutputDimensionality(3);
    reslice->SetBackend(names[b]);
    reslice->Update();
    images[0][b] = Values(reslice->GetOutput());

    vtkNew<vtkGaussianFieldSequenceRenderer> sequence;
    sequence->SetInputData(field);
    sequence->SetPoseData(SweepThroughTheField());
    sequence->SetBackend(names[b]);
    sequence->Update();
    images[1][b] = Values(sequence->GetOutput());
  }
  for (int f = 0; f < 2; ++f)
  {
    ASSERT_EQ(images[f][0].size(), f == 0 ? 32u * 32 * 3 : 24u * 20 * 3);
    ASSERT_EQ(images[f][1].size(), images[f][0].size());
    EXPECT_GT(*std::max_element(images[f][0].begin(), images[f][0].end()), 0.05f) << "the slices cut the field";
    double worst = 0;
    for (std::size_t p = 0; p < images[f][0].size(); ++p)
    {
      worst = std::max(worst, double(std::abs(images[f][0][p] - images[f][1][p])));
    }
    EXPECT_LE(worst, tolerance) << (f == 0 ? "reslice" : "sequence renderer");
  }
}

TEST(GaussianFieldReslice, TheRendererIsKeptUntilTheBackendChanges)
{
  RegisterBackend("counting", &CountingFactory, -100);
  const double centre[3] = { 0, 0, 0 };
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(OneGaussian(centre));
  reslice->SetBackend("counting");
  reslice->SetOutputSpacing(0.5, 0.5, 1);
  reslice->SetOutputOrigin(-2, -2, 0);
  reslice->SetOutputExtent(0, 8, 0, 8, 0, 0);
  CountingCreations = 0;
  for (int k = 0; k < 3; ++k)
  {
    reslice->SetResliceAxesOrigin(0, 0, 0.2 * k);
    reslice->Update();
  }
  EXPECT_EQ(CountingCreations, 1);
  reslice->SetBackend("cpu");
  reslice->Update();
  reslice->SetBackend("counting");
  reslice->Update();
  EXPECT_EQ(CountingCreations, 2);
}

TEST(GaussianFieldReslice, TheFieldIsConvertedAgainOnlyWhenTheInputIsModified)
{
  const double centre[3] = { 0, 0, 0 };
  vtkSmartPointer<vtkPolyData> field = OneGaussian(centre);
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(field);
  reslice->SetOutputSpacing(0.5, 0.5, 1);
  reslice->SetOutputOrigin(-2, -2, 0);
  reslice->SetOutputExtent(0, 8, 0, 8, 0, 0);
  reslice->SetResliceAxesOrigin(0, 0, 0);
  reslice->Update();
  const float first = static_cast<float>(reslice->GetOutput()->GetPointData()->GetScalars()->GetComponent(40, 0));
  ASSERT_GT(first, 0.5f);

  // Changed in place without Modified(): the pipeline cannot know, so the kept conversion is used.
  vtkDataArray* reflectivity = field->GetPointData()->GetArray("Reflectivity");
  reflectivity->SetComponent(0, 0, 0.0);
  reslice->SetResliceAxesOrigin(0, 0, 0.01);
  reslice->Update();
  const float moved = static_cast<float>(reslice->GetOutput()->GetPointData()->GetScalars()->GetComponent(40, 0));
  EXPECT_NEAR(moved, first, 1e-3) << "the plane moved 0.01 mm; the reflectivity change must not be seen yet";

  // Modified() (the VTK contract) brings the conversion up to date: reflectivity 0 renders nothing.
  reflectivity->Modified();
  reslice->Update();
  EXPECT_EQ(reslice->GetOutput()->GetPointData()->GetScalars()->GetComponent(40, 0), 0.0);
}

TEST(GaussianFieldReslice, TheFirstUpdateThroughAProducerNotYetRunHasTheFieldsGridDownstreamToo)
{
  // A default grid needs the field's bounds: on the first update through a producer that has not run (a reader),
  // RequestInformation runs it once, so that vtkImageReslice downstream plans from the field's grid (it got a
  // 2 x 2 x 2 image of zeros before), and the same as a filter given the field directly.
  reference::FieldD exact;
  vtkSmartPointer<vtkPolyData> field = RandomField(200, 8, exact);
  vtkNew<vtkGaussianFieldReslice> direct;
  direct->SetInputData(field);
  direct->SetOutputDimensionality(3);
  direct->SetOutputSpacing(1, 1, 1);
  direct->Update();
  for (bool downstream : { false, true })
  {
    vtkNew<CountingFieldSource> source;
    source->SetField(field);
    vtkNew<vtkGaussianFieldReslice> reslice;
    reslice->SetInputConnection(source->GetOutputPort());
    reslice->SetOutputDimensionality(3);
    reslice->SetOutputSpacing(1, 1, 1);
    vtkNew<vtkImageReslice> cut;
    cut->SetInputConnection(reslice->GetOutputPort());
    vtkAlgorithm* last = downstream ? static_cast<vtkAlgorithm*>(cut) : static_cast<vtkAlgorithm*>(reslice);
    last->Update();
    vtkImageData* out = vtkImageData::SafeDownCast(last->GetOutputDataObject(0));
    int extent[6], expected[6];
    out->GetExtent(extent);
    direct->GetOutput()->GetExtent(expected);
    for (int k = 0; k < 6; ++k)
    {
      EXPECT_EQ(extent[k], expected[k]) << (downstream ? "through vtkImageReslice" : "the filter") << ", k " << k;
    }
    EXPECT_EQ(Values(out), Values(direct->GetOutput())) << (downstream ? "through vtkImageReslice" : "the filter");
    EXPECT_EQ(source->Executions, 1);
  }
}

TEST(GaussianFieldReslice, TheDefaultGridFollowsTheFieldWhenItChanges)
{
  reference::FieldD exact;
  vtkSmartPointer<vtkPolyData> field = RandomField(200, 8, exact);
  vtkNew<CountingFieldSource> source;
  source->SetField(field);
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputConnection(source->GetOutputPort());
  reslice->SetOutputDimensionality(3);
  reslice->SetOutputSpacing(1, 1, 1);
  reslice->UpdateInformation();
  EXPECT_EQ(source->Executions, 1) << "the default grid needs the field: RequestInformation produces it once";

  for (double dx : { 0.0, 20.0 })
  {
    vtkSmartPointer<vtkPolyData> expected = dx == 0 ? field : Shifted(field, dx);
    if (dx != 0)
    {
      source->SetField(expected);
    }
    reslice->Update();
    // The same grid and image as a filter given that field directly (where RequestInformation sees it).
    vtkNew<vtkGaussianFieldReslice> direct;
    direct->SetInputData(expected);
    direct->SetOutputDimensionality(3);
    direct->SetOutputSpacing(1, 1, 1);
    direct->Update();
    vtkImageData* out = reslice->GetOutput();
    int extent[6], whole[6], directExtent[6];
    out->GetExtent(extent);
    direct->GetOutput()->GetExtent(directExtent);
    reslice->GetOutputInformation(0)->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), whole);
    for (int k = 0; k < 6; ++k)
    {
      EXPECT_EQ(extent[k], directExtent[k]) << "dx " << dx << ", k " << k;
      EXPECT_EQ(whole[k], extent[k]) << "the output information must describe the output";
    }
    for (int k = 0; k < 3; ++k)
    {
      EXPECT_DOUBLE_EQ(out->GetOrigin()[k], direct->GetOutput()->GetOrigin()[k]);
    }
    double bounds[6];
    out->GetBounds(bounds);
    EXPECT_LE(bounds[0], dx);
    EXPECT_GE(bounds[1], 10.0 + dx);
    EXPECT_EQ(Values(out), Values(direct->GetOutput()));
  }
  EXPECT_EQ(source->Executions, 2);
}

namespace
{
/// Progress events from inside RequestData (the executive adds 0 before and 1 after), and when to
/// abort: on the AbortAfter-th of them, or on the executive's 0 (AbortAtStart).
struct ProgressRecord
{
  std::vector<double> Progress;
  int AbortAfter = -1; // -1: never
  bool AbortAtStart = false;
};

void RecordProgress(vtkAlgorithm* filter, ProgressRecord& record)
{
  vtkNew<vtkCallbackCommand> observer;
  observer->SetClientData(&record);
  observer->SetCallback([](vtkObject* caller, unsigned long, void* clientData, void* callData) {
    auto* r = static_cast<ProgressRecord*>(clientData);
    const double p = *static_cast<double*>(callData);
    auto* algorithm = static_cast<vtkAlgorithm*>(caller);
    if (p == 0.0 && r->AbortAtStart)
    {
      algorithm->SetAbortExecute(1);
    }
    if (p > 0.0 && p < 1.0 + 1e-12 && !(p == 1.0 && algorithm->GetAbortExecute()))
    {
      r->Progress.push_back(p);
      if (int(r->Progress.size()) == r->AbortAfter)
      {
        algorithm->SetAbortExecute(1);
      }
    }
  });
  filter->AddObserver(vtkCommand::ProgressEvent, observer);
}
}

TEST(GaussianFieldReslice, AStackReportsProgressPerSliceAndStopsWhenAborted)
{
  reference::FieldD exact;
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(RandomField(100, 9, exact));
  reslice->SetOutputDimensionality(3);
  reslice->SetOutputSpacing(0.5, 0.5, 1.25);
  reslice->SetOutputOrigin(0, 0, 0);
  reslice->SetOutputExtent(0, 19, 0, 19, 0, 7);

  ProgressRecord record;
  RecordProgress(reslice, record);

  reslice->Update();
  // One event per slice, k / 8, then the executive's 1.
  ASSERT_EQ(record.Progress.size(), 9u);
  for (int k = 0; k < 8; ++k)
  {
    EXPECT_DOUBLE_EQ(record.Progress[k], (k + 1) / 8.0);
  }
  const std::vector<float> whole = Values(reslice->GetOutput());
  ASSERT_EQ(whole.size(), 20u * 20 * 8);

  // Aborted after the first slice: no further slice is rendered, the output is empty.
  record.Progress.clear();
  record.AbortAfter = 1;
  reslice->Modified();
  reslice->Update();
  EXPECT_EQ(record.Progress.size(), 1u) << "slices rendered after the abort";
  EXPECT_EQ(reslice->GetOutput()->GetNumberOfPoints(), 0);

  // Aborted on the first progress event (the executive's 0, before any slice): nothing rendered.
  record.Progress.clear();
  record.AbortAfter = -1;
  record.AbortAtStart = true;
  reslice->Modified();
  reslice->Update();
  EXPECT_TRUE(record.Progress.empty());
  EXPECT_EQ(reslice->GetOutput()->GetNumberOfPoints(), 0);

  // The empty output is not taken for the requested extent: the next Update renders it all.
  record.AbortAtStart = false;
  reslice->Update();
  EXPECT_EQ(Values(reslice->GetOutput()), whole);
}

TEST(GaussianFieldReslice, TheSequenceRendererReportsProgressPerFrameAndStopsWhenAborted)
{
  reference::FieldD exact;
  vtkNew<vtkGaussianFieldSequenceRenderer> sequence;
  sequence->SetInputData(RandomField(100, 9, exact));
  vtkSmartPointer<vtkImageData> poses = SweepThroughTheField();
  sequence->SetPoseData(poses);
  const int frames = poses->GetDimensions()[2];
  ASSERT_GT(frames, 2);
  ProgressRecord record;
  RecordProgress(sequence, record);

  sequence->Update();
  ASSERT_EQ(record.Progress.size(), std::size_t(frames) + 1) << "one event per frame, then the executive's 1";
  for (int k = 0; k < frames; ++k)
  {
    EXPECT_DOUBLE_EQ(record.Progress[k], double(k + 1) / frames);
  }
  const std::vector<float> whole = Values(sequence->GetOutput());

  // Aborted after the first frame: no further frame is rendered, the output is empty.
  record.Progress.clear();
  record.AbortAfter = 1;
  sequence->Modified();
  sequence->Update();
  EXPECT_EQ(record.Progress.size(), 1u) << "frames rendered after the abort";
  EXPECT_EQ(sequence->GetOutput()->GetNumberOfPoints(), 0);

  // The empty output is not taken for the requested frames: the next Update renders them all, the same.
  record.AbortAfter = -1;
  sequence->Update();
  EXPECT_EQ(Values(sequence->GetOutput()), whole);
}

TEST(GaussianFieldReslice, TheAnnouncedScalarTypeIsTheProducedOne)
{
  reference::FieldD exact;
  vtkSmartPointer<vtkPolyData> field = RandomField(50, 10, exact);
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(field);
  reslice->SetOutputSpacing(0.5, 0.5, 1);
  reslice->SetOutputOrigin(0, 0, 5);
  reslice->SetOutputExtent(0, 9, 0, 9, 0, 0);
  vtkNew<vtkGaussianFieldSequenceRenderer> sequence;
  sequence->SetInputData(field);
  sequence->SetPoseData(SweepThroughTheField());
  vtkNew<bigus_test::MessageCollector> messages;
  messages->Watch(reslice);
  messages->Watch(sequence);
  for (int type : { VTK_SHORT, VTK_LONG_LONG, VTK_DOUBLE, VTK_BIT, VTK_UNSIGNED_CHAR, VTK_FLOAT })
  {
    const std::size_t errors = messages->Errors.size();
    reslice->SetOutputScalarType(type);
    sequence->SetOutputScalarType(type);
    for (vtkImageAlgorithm* filter :
      { static_cast<vtkImageAlgorithm*>(reslice), static_cast<vtkImageAlgorithm*>(sequence) })
    {
      filter->UpdateInformation();
      const int announced = AnnouncedScalarType(filter);
      filter->Update();
      EXPECT_EQ(announced, filter->GetOutput()->GetScalarType())
        << filter->GetClassName() << " asked for " << vtkImageScalarTypeNameMacro(type);
    }
    // A type the filters cannot produce (not one of vtkImageReslice's output types) is refused, by name.
    const bool accepted = type != VTK_LONG_LONG && type != VTK_BIT;
    EXPECT_EQ(messages->Errors.size(), errors + (accepted ? 0 : 2)) << vtkImageScalarTypeNameMacro(type);
    if (!accepted && messages->Errors.size() > errors)
    {
      EXPECT_NE(messages->Errors.back().find(vtkImageScalarTypeNameMacro(type)), std::string::npos)
        << messages->Errors.back();
    }
  }
  EXPECT_EQ(reslice->GetOutput()->GetScalarType(), VTK_FLOAT);
  EXPECT_EQ(sequence->GetOutput()->GetScalarType(), VTK_FLOAT);
}
