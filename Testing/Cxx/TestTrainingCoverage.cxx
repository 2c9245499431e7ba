// The coverage image of vtkGaussianFieldReslice and vtkGaussianFieldSequenceRenderer (issue 19): the
// summed elevation weight of the training frames at each rendered pixel, checked against values worked
// out by hand for two parallel frames and against a brute-force projection for oblique, sheared frames;
// the training geometry a field carries (written by the trainer, through the XML format and back),
// malformed geometry as an error that names the array, and a field without geometry as before.
#include "bigusGaussianFieldData.h"
#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkGaussianFieldSequenceRenderer.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkImageData.h"
#include "vtkIntArray.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkSMPTools.h"
#include "vtkUnsignedCharArray.h"
#include "vtkXMLPolyDataReader.h"
#include "vtkXMLPolyDataWriter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using namespace bigus;

namespace
{
constexpr int FW = 40, FH = 30; // training frame size, pixels
constexpr double Pixel = 0.25;  // mm per pixel of the training frames
constexpr double Sigma = 1.0;   // the field's elevation sigma, mm
constexpr double Gap = 2.0;     // mm between the two parallel training frames

/// A fan: an annulus sector opening downwards from above the frame, the shape of a curvilinear probe's.
bool InFan(int i, int j)
{
  const double x = i - 19.5, y = j + 12.0;
  const double r = std::sqrt(x * x + y * y);
  return r >= 14 && r <= 40 && std::abs(x) <= 0.8 * y;
}

/// Frame poses: pixel (i, j) -> (i * Pixel, j * Pixel, z) mm.
std::array<double, 16> ParallelPose(double z)
{
  return { Pixel, 0, 0, 0, 0, Pixel, 0, 0, 0, 0, 1, z, 0, 0, 0, 1 };
}

TrainingGeometry Geometry(const std::vector<std::array<double, 16>>& poses)
{
  TrainingGeometry g;
  g.Width = FW;
  g.Height = FH;
  g.Poses = poses;
  g.Mask.resize(FW * FH);
  for (int j = 0; j < FH; ++j)
  {
    for (int i = 0; i < FW; ++i)
    {
      g.Mask[j * FW + i] = InFan(i, j) ? 1 : 0;
    }
  }
  return g;
}

/// A field of one Gaussian (what it renders does not matter here) with elevation sigma Sigma and, when
/// @p geometry has poses, that training geometry.
vtkSmartPointer<vtkPolyData> Field(const TrainingGeometry& geometry)
{
  GaussianField f;
  f.Means = { 5.0f, 4.0f, 1.0f };
  f.LogScales = { std::log(1.5f), std::log(1.0f), std::log(0.8f) };
  f.Quaternions = { 1, 0, 0, 0 };
  f.Reflectivities = { 1.0f };
  FieldModel model;
  model.ElevationSigma = Sigma;
  model.Gamma = 1.0;
  auto data = vtkSmartPointer<vtkPolyData>::New();
  FieldToPolyData(f, model, data);
  if (!geometry.Poses.empty())
  {
    TrainingGeometryToFieldData(geometry, data->GetFieldData());
  }
  return data;
}

/// The two parallel frames at z = 0 and z = Gap.
vtkSmartPointer<vtkPolyData> TwoFrameField()
{
  return Field(Geometry({ ParallelPose(0), ParallelPose(Gap) }));
}

/// A plane z = @p z, pixels a quarter pixel off the training frames' (no rounding ties): output pixel
/// (i, j) lies at ((i - 8.25) Pixel, (j - 8.25) Pixel, z), so it projects on frame pixel (i - 8, j - 8).
void AxialPlane(vtkGaussianFieldReslice* reslice, double z)
{
  reslice->SetResliceAxesOrigin(0, 0, z);
  reslice->SetOutputSpacing(Pixel, Pixel, 1);
  reslice->SetOutputOrigin(-8.25 * Pixel, -8.25 * Pixel, 0);
  reslice->SetOutputExtent(0, FW + 15, 0, FH + 15, 0, 0);
}

vtkFloatArray* CoverageOf(vtkImageData* image)
{
  return vtkFloatArray::SafeDownCast(image->GetPointData()->GetArray("Coverage"));
}

std::vector<float> Intensities(vtkImageData* image)
{
  vtkDataArray* scalars = image->GetPointData()->GetScalars();
  std::vector<float> v(scalars ? scalars->GetNumberOfTuples() : 0);
  for (std::size_t p = 0; p < v.size(); ++p)
  {
    v[p] = static_cast<float>(scalars->GetComponent(p, 0));
  }
  return v;
}

/// Checks an axial plane's coverage: @p inside where the pixel projects inside the fan, 0 elsewhere.
void ExpectAxialCoverage(vtkImageData* out, double inside, const char* what)
{
  vtkFloatArray* coverage = CoverageOf(out);
  ASSERT_NE(coverage, nullptr) << what;
  const int W = FW + 16, H = FH + 16;
  ASSERT_EQ(coverage->GetNumberOfTuples(), W * H) << what;
  int insideCount = 0;
  for (int j = 0; j < H; ++j)
  {
    for (int i = 0; i < W; ++i)
    {
      const int a = i - 8, b = j - 8;
      const bool in = a >= 0 && a < FW && b >= 0 && b < FH && InFan(a, b);
      insideCount += in;
      EXPECT_NEAR(coverage->GetValue(j * W + i), in ? inside : 0.0, 1e-5) << what << " at pixel " << i << ", " << j;
    }
  }
  EXPECT_GT(insideCount, 200) << "the fan covers part of the plane";
  EXPECT_LT(insideCount, FW * FH) << "and not all of it";
}
}

TEST(TrainingCoverage, HalfwayBetweenTwoFramesItIsTwiceTheBeamAtHalfTheGap)
{
  vtkNew<vtkGaussianFieldReslice> reslice;
  EXPECT_TRUE(reslice->GetOutputCoverage()) << "on by default";
  reslice->SetInputData(TwoFrameField());
  AxialPlane(reslice, Gap / 2);
  reslice->Update();
  // d = 1 mm from each frame: 2 exp(-1 / (2 sigma^2)).
  ExpectAxialCoverage(reslice->GetOutput(), 2 * std::exp(-1.0 / (2 * Sigma * Sigma)), "halfway");

  // The filter's ElevationSigma overrides the field's, as it does for the render.
  reslice->SetElevationSigma(0.8);
  reslice->Update();
  ExpectAxialCoverage(reslice->GetOutput(), 2 * std::exp(-1.0 / (2 * 0.64)), "halfway, sigma 0.8");
}

TEST(TrainingCoverage, OnATrainingFrameItIsOnePlusTheNeighboursShare)
{
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(TwoFrameField());
  AxialPlane(reslice, 0);
  reslice->Update();
  ExpectAxialCoverage(reslice->GetOutput(), 1 + std::exp(-Gap * Gap / (2 * Sigma * Sigma)), "on frame 0");

  // Beyond the beam of both frames (d >= 5 sigma_E) no training data supports the plane.
  AxialPlane(reslice, Gap + 5 * Sigma);
  reslice->Update();
  ExpectAxialCoverage(reslice->GetOutput(), 0, "5 sigma past frame 1");

  // The thin-plane limit (sigma_E = 0): 1 on a frame, 0 between frames.
  reslice->SetElevationSigma(0);
  AxialPlane(reslice, 0);
  reslice->Update();
  ExpectAxialCoverage(reslice->GetOutput(), 1, "on frame 0, sigma 0");
  AxialPlane(reslice, 0.01);
  reslice->Update();
  ExpectAxialCoverage(reslice->GetOutput(), 0, "0.01 mm off frame 0, sigma 0");
}

TEST(TrainingCoverage, APerpendicularSliceFollowsTheBeamProfileAcrossTheFrames)
{
  // The plane y = 3.0625 mm (frame row 12.25 -> 12), x along the frames' columns, y axis = elevation z.
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(TwoFrameField());
  reslice->SetResliceAxesDirectionCosines(1, 0, 0, 0, 0, 1, 0, -1, 0);
  reslice->SetResliceAxesOrigin(0, 12.25 * Pixel, 0);
  const double dz = 0.05;
  reslice->SetOutputSpacing(Pixel, dz, 1);
  reslice->SetOutputOrigin(-3.25 * Pixel, -5.0, 0);
  const int W = FW + 6, H = 241; // z from -5 to 7 mm
  reslice->SetOutputExtent(0, W - 1, 0, H - 1, 0, 0);
  reslice->Update();
  vtkFloatArray* coverage = CoverageOf(reslice->GetOutput());
  ASSERT_NE(coverage, nullptr);
  ASSERT_EQ(coverage->GetNumberOfTuples(), W * H);
  int columnsInside = 0;
  double largestError = 0;
  for (int i = 0; i < W; ++i)
  {
    const int a = i - 3;
    const bool in = a >= 0 && a < FW && InFan(a, 12);
    columnsInside += in;
    for (int j = 0; j < H; ++j)
    {
      const double z = -5.0 + j * dz;
      // The beam profile of each frame, without the 4-sigma cut (which leaves out at most exp(-8) per frame).
      const double truth =
        in ? std::exp(-z * z / (2 * Sigma * Sigma)) + std::exp(-(z - Gap) * (z - Gap) / (2 * Sigma * Sigma)) : 0.0;
      const bool bothWithinCut = std::abs(z) <= 4 * Sigma && std::abs(z - Gap) <= 4 * Sigma;
      const double c = coverage->GetValue(j * W + i);
      EXPECT_NEAR(c, truth, bothWithinCut ? 1e-5 : 2 * std::exp(-8.0)) << "column " << i << ", z " << z;
      largestError = std::max(largestError, std::abs(c - truth));
    }
  }
  EXPECT_GT(columnsInside, 5);
  EXPECT_LT(columnsInside, W);
  std::printf("largest |Coverage - beam profile| across the frames: %.2g\n", largestError);
}

namespace
{
/// Rotation by @p angle (radians) about the unit axis @p k.
void Rotation(const double k[3], double angle, double R[3][3])
{
  const double c = std::cos(angle), s = std::sin(angle), C = 1 - c;
  const double x = k[0], y = k[1], z = k[2];
  const double m[3][3] = { { c + x * x * C, x * y * C - z * s, x * z * C + y * s },
    { y * x * C + z * s, c + y * y * C, y * z * C - x * s }, { z * x * C - y * s, z * y * C + x * s, c + z * z * C } };
  for (int r = 0; r < 3; ++r)
  {
    for (int q = 0; q < 3; ++q)
    {
      R[r][q] = m[r][q];
    }
  }
}

/// A pose with pixel axes R e_x s0 and R (sin(shear) e_x + cos(shear) e_y) s1 (shear in radians) at @p origin.
std::array<double, 16> ObliquePose(
  const double axis[3], double angle, double shear, double s0, double s1, const double origin[3])
{
  double R[3][3];
  Rotation(axis, angle, R);
  std::array<double, 16> m{};
  for (int r = 0; r < 3; ++r)
  {
    m[4 * r + 0] = R[r][0] * s0;
    m[4 * r + 1] = (R[r][0] * std::sin(shear) + R[r][1] * std::cos(shear)) * s1;
    m[4 * r + 2] = R[r][2];
    m[4 * r + 3] = origin[r];
  }
  m[15] = 1;
  return m;
}

/**
 * The coverage formula by brute force: the foot of the perpendicular from x on frame t's plane by least
 * squares over the two pixel axes (normal equations), its nearest pixel, and the distance |x - foot|.
 * @p tie is set when a projection lies within 1e-6 pixel of a rounding boundary.
 */
double BruteForceCoverage(const TrainingGeometry& g, double sigma, const double x[3], bool& tie)
{
  double sum = 0;
  for (const auto& m : g.Poses)
  {
    const double c0[3] = { m[0], m[4], m[8] }, c1[3] = { m[1], m[5], m[9] };
    const double r[3] = { x[0] - m[3], x[1] - m[7], x[2] - m[11] };
    double g00 = 0, g01 = 0, g11 = 0, r0 = 0, r1 = 0;
    for (int k = 0; k < 3; ++k)
    {
      g00 += c0[k] * c0[k];
      g01 += c0[k] * c1[k];
      g11 += c1[k] * c1[k];
      r0 += c0[k] * r[k];
      r1 += c1[k] * r[k];
    }
    const double det = g00 * g11 - g01 * g01;
    const double a = (g11 * r0 - g01 * r1) / det, b = (g00 * r1 - g01 * r0) / det;
    double d2 = 0;
    for (int k = 0; k < 3; ++k)
    {
      const double e = r[k] - a * c0[k] - b * c1[k];
      d2 += e * e;
    }
    for (double v : { a, b })
    {
      tie = tie || std::abs(v - std::floor(v) - 0.5) < 1e-6;
    }
    const long ia = std::lround(a), ib = std::lround(b);
    if (ia >= 0 && ia < g.Width && ib >= 0 && ib < g.Height && g.Mask[ib * g.Width + ia])
    {
      sum += std::exp(-d2 / (2 * sigma * sigma));
    }
  }
  return sum;
}

/// Three oblique frames, two of them sheared (by 2.3 and 3.4 degrees), with unequal pixel spacings.
TrainingGeometry ObliqueGeometry()
{
  const double axis1[3] = { 0, 0.6, 0.8 }, axis2[3] = { 0.8, 0, 0.6 }, axis3[3] = { 0.48, 0.6, 0.64 };
  const double o1[3] = { -2, -1, 0.5 }, o2[3] = { 0, -3, 1.5 }, o3[3] = { 1, 0, -1 };
  return Geometry({ ObliquePose(axis1, 0.35, 0.04, 0.25, 0.3, o1), ObliquePose(axis2, -0.5, -0.06, 0.3, 0.25, o2),
    ObliquePose(axis3, 1.2, 0.0, 0.25, 0.25, o3) });
}
}

TEST(TrainingCoverage, ObliqueShearedFramesMatchABruteForceProjection)
{
  const TrainingGeometry geometry = ObliqueGeometry();
  const double sigma = 0.7;
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(Field(geometry));
  reslice->SetElevationSigma(sigma);
  // An oblique stack through the frames: rotation by 0.7 rad about (1, 1, 1) / sqrt 3.
  const double axis[3] = { 1 / std::sqrt(3.0), 1 / std::sqrt(3.0), 1 / std::sqrt(3.0) };
  double R[3][3];
  Rotation(axis, 0.7, R);
  reslice->SetResliceAxesDirectionCosines(
    R[0][0], R[1][0], R[2][0], R[0][1], R[1][1], R[2][1], R[0][2], R[1][2], R[2][2]);
  reslice->SetResliceAxesOrigin(2, 2, 1);
  reslice->SetOutputDimensionality(3);
  reslice->SetOutputSpacing(0.2, 0.2, 0.6);
  reslice->SetOutputOrigin(-8, -8, -3);
  reslice->SetOutputExtent(0, 79, 0, 79, 0, 10);
  reslice->Update();
  vtkImageData* out = reslice->GetOutput();
  vtkFloatArray* coverage = CoverageOf(out);
  ASSERT_NE(coverage, nullptr);
  ASSERT_EQ(coverage->GetNumberOfTuples(), 80 * 80 * 11);
  int compared = 0, ties = 0, supported = 0;
  double largestError = 0;
  for (int k = 0; k <= 10; ++k)
  {
    for (int j = 0; j < 80; ++j)
    {
      for (int i = 0; i < 80; ++i)
      {
        const double local[3] = { -8 + 0.2 * i, -8 + 0.2 * j, -3 + 0.6 * k };
        double x[3];
        for (int r = 0; r < 3; ++r)
        {
          x[r] = R[r][0] * local[0] + R[r][1] * local[1] + R[r][2] * local[2] + (r == 2 ? 1 : 2);
        }
        bool tie = false;
        const double truth = BruteForceCoverage(geometry, sigma, x, tie);
        if (tie)
        {
          ++ties;
          continue;
        }
        const double c = coverage->GetValue((k * 80 + j) * 80 + i);
        // Up to three frames each cut at 4 sigma (exp(-8) each) and float sums.
        EXPECT_NEAR(c, truth, 3 * std::exp(-8.0) + 1e-5) << "voxel " << i << ", " << j << ", " << k;
        largestError = std::max(largestError, std::abs(c - truth));
        supported += truth > 0.5;
        ++compared;
      }
    }
  }
  EXPECT_GT(supported, 2000) << "the stack cuts the frames' fans";
  EXPECT_LT(ties, compared / 100);
  std::printf("oblique stack: %d voxels compared (%d supported, %d rounding ties skipped), largest error %.2g\n",
    compared, supported, ties, largestError);
}

TEST(TrainingCoverage, TheResultDoesNotDependOnTheThreadCount)
{
  const TrainingGeometry geometry = ObliqueGeometry();
  const TrainingCoverage coverage(geometry);
  ASSERT_FALSE(coverage.IsEmpty());
  // The plane of the first frame at twice its resolution.
  SliceGeometry slice;
  std::copy(geometry.Poses[0].begin(), geometry.Poses[0].end(), slice.ImageToReference);
  for (int r = 0; r < 3; ++r)
  {
    slice.ImageToReference[4 * r] *= 0.5;
    slice.ImageToReference[4 * r + 1] *= 0.5;
  }
  slice.Width = 2 * FW;
  slice.Height = 2 * FH;
  std::vector<float> images[2];
  for (int threads : { 1, 2 })
  {
    vtkSMPTools::Initialize(threads);
    images[threads - 1].resize(4 * FW * FH);
    coverage.Compute(slice, 0.6, images[threads - 1].data());
  }
  vtkSMPTools::Initialize(0);
  EXPECT_GT(std::count_if(images[0].begin(), images[0].end(), [](float c) { return c > 0.5f; }), 500);
  EXPECT_EQ(images[0], images[1]);
}

TEST(TrainingCoverage, TheSequenceRendererOutputsCoverageAtEveryPose)
{
  // Poses: frame 0, halfway, and one outside both beams.
  const std::vector<std::array<double, 16>> poses = { ParallelPose(0), ParallelPose(Gap / 2),
    ParallelPose(Gap + 5 * Sigma) };
  vtkNew<vtkGaussianFieldSequenceRenderer> sequence;
  EXPECT_TRUE(sequence->GetOutputCoverage()) << "on by default";
  sequence->SetInputData(TwoFrameField());
  sequence->SetPoseData(bigus_test::TrackedSequence(FW, FH, poses, { 0, 0.1, 0.2 }, [](int, int, int) { return 0.f; }));
  sequence->Update();
  vtkImageData* out = sequence->GetOutput();
  vtkFloatArray* coverage = CoverageOf(out);
  ASSERT_NE(coverage, nullptr);
  ASSERT_EQ(coverage->GetNumberOfTuples(), FW * FH * 3);
  EXPECT_STREQ(out->GetPointData()->GetScalars()->GetName(), "Intensity") << "Coverage is not the scalars";
  const double expected[3] = { 1 + std::exp(-Gap * Gap / (2 * Sigma * Sigma)), 2 * std::exp(-1.0 / (2 * Sigma * Sigma)),
    0 };
  for (int k = 0; k < 3; ++k)
  {
    for (int p = 0; p < FW * FH; ++p)
    {
      EXPECT_NEAR(coverage->GetValue(k * FW * FH + p), InFan(p % FW, p / FW) ? expected[k] : 0.0, 1e-5)
        << "frame " << k << ", pixel " << p;
    }
  }

  // Off: no Coverage array, the same images.
  const std::vector<float> with = Intensities(out);
  sequence->OutputCoverageOff();
  sequence->Update();
  EXPECT_EQ(CoverageOf(sequence->GetOutput()), nullptr);
  EXPECT_EQ(Intensities(sequence->GetOutput()), with);
  std::ostringstream printed;
  sequence->Print(printed);
  EXPECT_NE(printed.str().find("OutputCoverage: 0"), std::string::npos) << printed.str();
}

TEST(TrainingCoverage, AFieldWithoutTrainingGeometryRendersAsBeforeWithoutCoverage)
{
  vtkSmartPointer<vtkPolyData> plain = Field(TrainingGeometry());
  vtkSmartPointer<vtkPolyData> trained = TwoFrameField();
  std::vector<float> images[3];
  int index = 0;
  vtkNew<bigus_test::MessageCollector> messages;
  for (auto [field, coverage] :
    { std::make_pair(plain.Get(), true), std::make_pair(trained.Get(), true), std::make_pair(trained.Get(), false) })
  {
    vtkNew<vtkGaussianFieldReslice> reslice;
    messages->Watch(reslice);
    reslice->SetInputData(field);
    reslice->SetOutputCoverage(coverage);
    AxialPlane(reslice, 1.0);
    reslice->Update();
    const bool expectCoverage = field == trained.Get() && coverage;
    EXPECT_EQ(CoverageOf(reslice->GetOutput()) != nullptr, expectCoverage) << "case " << index;
    EXPECT_EQ(reslice->GetOutput()->GetPointData()->GetNumberOfArrays(), expectCoverage ? 2 : 1) << "case " << index;
    images[index++] = Intensities(reslice->GetOutput());
  }
  EXPECT_TRUE(messages->Errors.empty());
  EXPECT_TRUE(messages->Warnings.empty()) << "a field without geometry is normal, not a warning";
  ASSERT_GT(images[0].size(), 0u);
  EXPECT_GT(*std::max_element(images[0].begin(), images[0].end()), 0.1f) << "the plane cuts the Gaussian";
  EXPECT_EQ(images[0], images[1]) << "the geometry does not change the rendering";
  EXPECT_EQ(images[0], images[2]);

  vtkNew<vtkGaussianFieldSequenceRenderer> sequence;
  sequence->SetInputData(plain);
  sequence->SetPoseData(
    bigus_test::TrackedSequence(FW, FH, { ParallelPose(1.0) }, { 0 }, [](int, int, int) { return 0.f; }));
  sequence->Update();
  EXPECT_EQ(sequence->GetOutput()->GetNumberOfPoints(), FW * FH);
  EXPECT_EQ(CoverageOf(sequence->GetOutput()), nullptr);
}

namespace
{
/// The two-frame field with its geometry spoiled by @p spoil.
vtkSmartPointer<vtkPolyData> Spoiled(const std::function<void(vtkFieldData*)>& spoil)
{
  vtkSmartPointer<vtkPolyData> field = TwoFrameField();
  spoil(field->GetFieldData());
  return field;
}
}

TEST(TrainingCoverage, MalformedTrainingGeometryIsAnErrorThatNamesTheArray)
{
  struct Case
  {
    const char* What;
    const char* Array;
    std::function<void(vtkFieldData*)> Spoil;
  };
  const std::vector<Case> cases = {
    { "9-component poses", "TrainingPoses",
      [](vtkFieldData* fd) {
        vtkNew<vtkDoubleArray> poses;
        poses->SetName("TrainingPoses");
        poses->SetNumberOfComponents(9);
        poses->SetNumberOfTuples(2);
        poses->Fill(0.5);
        fd->AddArray(poses);
      } },
    { "a NaN in a pose", "TrainingPoses",
      [](vtkFieldData* fd) { fd->GetArray("TrainingPoses")->SetComponent(1, 5, std::nan("")); } },
    { "a singular pose", "TrainingPoses",
      [](vtkFieldData* fd) {
        for (int c : { 0, 4, 8 })
        {
          fd->GetArray("TrainingPoses")->SetComponent(0, c, 0.0);
        }
      } },
    { "a mask of the wrong size", "TrainingFanMask",
      [](vtkFieldData* fd) { fd->GetArray("TrainingFanMask")->SetNumberOfTuples(FW * FH - 1); } },
    { "a frame size of 3 values", "TrainingFrameSize",
      [](vtkFieldData* fd) {
        vtkNew<vtkIntArray> size;
        size->SetName("TrainingFrameSize");
        size->SetNumberOfValues(3);
        size->Fill(10);
        fd->AddArray(size);
      } },
    { "a negative frame width", "TrainingFrameSize",
      [](vtkFieldData* fd) { fd->GetArray("TrainingFrameSize")->SetComponent(0, 0, -FW); } },
    { "no mask", "TrainingFanMask", [](vtkFieldData* fd) { fd->RemoveArray("TrainingFanMask"); } },
  };
  for (const Case& c : cases)
  {
    vtkSmartPointer<vtkPolyData> field = Spoiled(c.Spoil);
    vtkNew<vtkGaussianFieldReslice> reslice;
    vtkNew<vtkGaussianFieldSequenceRenderer> sequence;
    vtkNew<bigus_test::MessageCollector> messages;
    messages->Watch(reslice);
    messages->Watch(sequence);
    reslice->SetInputData(field);
    AxialPlane(reslice, 1.0);
    reslice->Update();
    EXPECT_EQ(reslice->GetOutput()->GetNumberOfPoints(), 0) << c.What;
    sequence->SetInputData(field);
    sequence->SetPoseData(
      bigus_test::TrackedSequence(FW, FH, { ParallelPose(1.0) }, { 0 }, [](int, int, int) { return 0.f; }));
    sequence->Update();
    EXPECT_EQ(sequence->GetOutput()->GetNumberOfPoints(), 0) << c.What;
    ASSERT_EQ(messages->Errors.size(), 2u) << c.What;
    for (const std::string& error : messages->Errors)
    {
      EXPECT_NE(error.find(c.Array), std::string::npos) << c.What << ": " << error;
    }

    // Without the coverage image the field renders.
    reslice->OutputCoverageOff();
    reslice->Update();
    sequence->OutputCoverageOff();
    sequence->Update();
    EXPECT_EQ(messages->Errors.size(), 2u) << c.What;
    EXPECT_GT(reslice->GetOutput()->GetNumberOfPoints(), 0) << c.What;
    EXPECT_EQ(CoverageOf(reslice->GetOutput()), nullptr) << c.What;
    EXPECT_EQ(sequence->GetOutput()->GetNumberOfPoints(), FW * FH) << c.What;
  }
}

TEST(TrainingCoverage, TheGeometryRoundTripsThroughTheXmlFormat)
{
  TrainingGeometry geometry = Geometry({ ParallelPose(0), ParallelPose(Gap) });
  const double axis[3] = { 0, 0.6, 0.8 }, origin[3] = { -2.5, 1.25, 3.125 };
  geometry.Poses.push_back(ObliquePose(axis, 0.3, 0.02, 0.123456789, 0.3, origin));
  vtkSmartPointer<vtkPolyData> field = Field(geometry);
  const std::string path = bigus_test::OutputPath("TrainingGeometry.vtp");
  vtkNew<vtkXMLPolyDataWriter> writer;
  writer->SetInputData(field);
  writer->SetFileName(path.c_str());
  writer->SetDataModeToAppended(); // binary: doubles exactly
  ASSERT_EQ(writer->Write(), 1);
  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(path.c_str());
  reader->Update();
  vtkFieldData* back = reader->GetOutput()->GetFieldData();
  EXPECT_TRUE(vtkDoubleArray::SafeDownCast(back->GetAbstractArray("TrainingPoses")));
  EXPECT_TRUE(vtkIntArray::SafeDownCast(back->GetAbstractArray("TrainingFrameSize")));
  EXPECT_TRUE(vtkUnsignedCharArray::SafeDownCast(back->GetAbstractArray("TrainingFanMask")));
  TrainingGeometry read;
  std::string error;
  ASSERT_TRUE(TrainingGeometryFromFieldData(back, read, &error)) << error;
  EXPECT_EQ(read.Width, FW);
  EXPECT_EQ(read.Height, FH);
  EXPECT_EQ(read.Poses, geometry.Poses);
  EXPECT_EQ(read.Mask, geometry.Mask);

  // And it renders the same coverage as the field it was written from.
  std::vector<float> coverage[2];
  for (int f = 0; f < 2; ++f)
  {
    vtkNew<vtkGaussianFieldReslice> reslice;
    reslice->SetInputData(f == 0 ? field.Get() : reader->GetOutput());
    AxialPlane(reslice, 1.0);
    reslice->Update();
    vtkFloatArray* c = CoverageOf(reslice->GetOutput());
    ASSERT_NE(c, nullptr);
    coverage[f].assign(c->GetPointer(0), c->GetPointer(0) + c->GetNumberOfTuples());
  }
  EXPECT_EQ(coverage[0], coverage[1]);
}

TEST(TrainingCoverage, TheGeometryOfTrainingDataIsItsTrainingFramesAndTheUnionOfTheirMasks)
{
  TrainingData data;
  data.Width = 4;
  data.Height = 2;
  for (int k = 0; k < 3; ++k)
  {
    data.Poses.push_back(ParallelPose(k));
  }
  data.Frames.assign(3 * 8, 0.5f);
  // Per-frame masks; frame 1 is held out, so its pixel 7 is not in the union.
  data.Mask = { 1, 0, 0, 0, 0, 0, 0, 0, /**/ 0, 0, 0, 0, 0, 0, 0, 1, /**/ 0, 0, 1, 0, 0, 1, 0, 0 };
  data.TrainFrames = { 0, 2 };
  TrainingGeometry g = TrainingGeometryOf(data);
  EXPECT_EQ(g.Width, 4);
  EXPECT_EQ(g.Height, 2);
  ASSERT_EQ(g.Poses.size(), 2u);
  EXPECT_EQ(g.Poses[0], data.Poses[0]);
  EXPECT_EQ(g.Poses[1], data.Poses[2]);
  EXPECT_EQ(g.Mask, (std::vector<unsigned char>{ 1, 0, 1, 0, 0, 1, 0, 0 }));
  // One shared mask is stored as it is.
  data.Mask = { 0, 1, 1, 1, 1, 1, 1, 0 };
  EXPECT_EQ(TrainingGeometryOf(data).Mask, data.Mask);
}

TEST(TrainingCoverage, TheTrainerWritesItsTrainingGeometry)
{
  constexpr int W = 32, H = 24, N = 6;
  std::vector<std::array<double, 16>> poses;
  for (int k = 0; k < N; ++k)
  {
    poses.push_back({ 0.3, 0, 0, 0, 0, 0.3, 0, 0, 0, 0, 1, 0.4 * k, 0, 0, 0, 1 });
  }
  vtkSmartPointer<vtkImageData> sequence = bigus_test::TrackedSequence(W, H, poses, { 0, 1, 2, 3, 4, 5 },
    [](int k, int i, int j) { return 0.4f + 0.3f * float(std::sin(0.7 * i + 0.3 * k) * std::cos(0.5 * j)); });
  // One mask per frame: frame k images columns from 4 + 2k on, above the last two rows; held-out frame 1
  // also column 0, which is therefore not in the union of the training frames' masks.
  vtkNew<vtkImageData> masks;
  masks->SetDimensions(W, H, N);
  masks->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  auto* m = static_cast<unsigned char*>(masks->GetScalarPointer());
  std::vector<unsigned char> trainingUnion(W * H);
  for (int k = 0; k < N; ++k)
  {
    for (int p = 0; p < W * H; ++p)
    {
      const int i = p % W, j = p / W;
      m[k * W * H + p] = j < H - 2 && (i >= 4 + 2 * k || (k == 1 && i == 0)) ? 1 : 0;
      trainingUnion[p] = j < H - 2 && i >= 4 ? 1 : 0; // frame 0's
    }
  }
  vtkNew<vtkGaussianFieldTrainer> trainer;
  vtkNew<bigus_test::MessageCollector> messages;
  messages->Watch(trainer);
  trainer->SetInputData(0, sequence);
  trainer->SetInputData(1, masks);
  trainer->SetIterations(3);
  trainer->SetInitialGaussians(50);
  trainer->SetHoldOutEvery(3);
  trainer->SetHoldOutOffset(1);
  // The tracked poses trusted, so that the poses written are the sequence's (a refined run writes its refined poses;
  // the rule reads this pattern's correlation between frames, which this test is not about).
  trainer->SetRefinePoses(vtkGaussianFieldTrainer::POSE_REFINEMENT_OFF);
  trainer->Update();
  vtkPolyData* field = trainer->GetOutput();
  EXPECT_TRUE(messages->Errors.empty());
  ASSERT_GT(field->GetNumberOfPoints(), 0);
  vtkDataArray* frames = field->GetFieldData()->GetArray("TrainingFrames");
  ASSERT_NE(frames, nullptr);
  TrainingGeometry g;
  std::string error;
  ASSERT_TRUE(TrainingGeometryFromFieldData(field->GetFieldData(), g, &error)) << error;
  EXPECT_EQ(g.Width, W);
  EXPECT_EQ(g.Height, H);
  ASSERT_EQ(vtkIdType(g.Poses.size()), frames->GetNumberOfTuples());
  EXPECT_EQ(g.Poses.size(), 4u) << "frames 1 and 4 are held out";
  for (std::size_t t = 0; t < g.Poses.size(); ++t)
  {
    EXPECT_EQ(g.Poses[t], poses[static_cast<int>(frames->GetTuple1(t))]) << "training frame " << t;
  }
  EXPECT_EQ(g.Mask, trainingUnion);

  // A render at a held-out pose (frame 1, 0.4 mm from frame 0 and 0.8 mm from frame 2) has coverage.
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(field);
  reslice->SetResliceAxesOrigin(0, 0, 0.4);
  reslice->SetOutputSpacing(0.3, 0.3, 1);
  reslice->SetOutputOrigin(0, 0, 0);
  reslice->SetOutputExtent(0, W - 1, 0, H - 1, 0, 0);
  reslice->Update();
  vtkFloatArray* coverage = CoverageOf(reslice->GetOutput());
  ASSERT_NE(coverage, nullptr);
  const double sigma = field->GetFieldData()->GetArray("ElevationSigma")->GetTuple1(0);
  double expected = 0;
  for (int k : { 0, 2, 3, 5 })
  {
    const double d = 0.4 * (k - 1);
    expected += std::abs(d) <= 4 * sigma ? std::exp(-d * d / (2 * sigma * sigma)) : 0.0;
  }
  // Pixel (10, 10) lies in the union (not in frame 5's own mask: the union is what is kept).
  EXPECT_NEAR(coverage->GetValue(10 * W + 10), expected, 1e-5);
  EXPECT_EQ(coverage->GetValue(10 * W + 1), 0.0f);
  EXPECT_EQ(coverage->GetValue(10 * W + 0), 0.0f) << "only the held-out frame imaged column 0";
}
