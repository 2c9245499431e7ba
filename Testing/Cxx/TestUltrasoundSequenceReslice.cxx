// vtkUltrasoundSequenceReslice: a volume that is a linear function of position is sampled exactly
// (trilinear interpolation reproduces linear functions), samples outside the bounds or on empty
// voxels are masked, per-frame field data follows the frame list, the values agree with
// vtkImageReslice on the PLUS spine reconstruction, and bad input fails the request without a crash.
#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkExecutive.h"
#include "vtkFieldData.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkImageReslice.h"
#include "vtkMatrix4x4.h"
#include "vtkMetaImageReader.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundSequenceReslice.h"
#include "vtkUnsignedCharArray.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <vector>

using bigus_test::DataPath;
using bigus_test::MessageCollector;

namespace
{
using Pose = std::array<double, 16>;

const int Dims[3] = { 20, 16, 12 };
const double Spacing[3] = { 0.5, 0.6, 0.8 };
const double Origin[3] = { -3.0, 2.0, 5.0 };

/// The linear function (and the voxel values) of the test volume: positive everywhere in it.
double Linear(const double p[3])
{
  return 50 + 0.7 * p[0] - 0.3 * p[1] + 0.45 * p[2];
}

/// A double volume whose voxel value is Linear() at the voxel centre.
vtkSmartPointer<vtkImageData> LinearVolume()
{
  auto volume = vtkSmartPointer<vtkImageData>::New();
  volume->SetDimensions(Dims[0], Dims[1], Dims[2]);
  volume->SetSpacing(Spacing[0], Spacing[1], Spacing[2]);
  volume->SetOrigin(Origin[0], Origin[1], Origin[2]);
  volume->AllocateScalars(VTK_DOUBLE, 1);
  auto* v = static_cast<double*>(volume->GetScalarPointer());
  for (int z = 0; z < Dims[2]; ++z)
  {
    for (int y = 0; y < Dims[1]; ++y)
    {
      for (int x = 0; x < Dims[0]; ++x)
      {
        const double p[3] = { Origin[0] + x * Spacing[0], Origin[1] + y * Spacing[1], Origin[2] + z * Spacing[2] };
        *v++ = Linear(p);
      }
    }
  }
  return volume;
}

/// Pose with orthonormal axes from a rotation by `degrees` about `axis`, pixel spacings (su, sv) mm
/// and pixel (0, 0) at `origin`.
Pose Oblique(const double axis[3], double degrees, double su, double sv, const double origin[3])
{
  const double n = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  const double w[3] = { axis[0] / n, axis[1] / n, axis[2] / n };
  const double t = degrees * M_PI / 180, c = std::cos(t), s = std::sin(t), C = 1 - c;
  const double R[3][3] = { { c + C * w[0] * w[0], C * w[0] * w[1] - s * w[2], C * w[0] * w[2] + s * w[1] },
    { C * w[1] * w[0] + s * w[2], c + C * w[1] * w[1], C * w[1] * w[2] - s * w[0] },
    { C * w[2] * w[0] - s * w[1], C * w[2] * w[1] + s * w[0], c + C * w[2] * w[2] } };
  Pose m{};
  for (int r = 0; r < 3; ++r)
  {
    m[4 * r] = su * R[r][0];
    m[4 * r + 1] = sv * R[r][1];
    m[4 * r + 2] = R[r][2];
    m[4 * r + 3] = origin[r];
  }
  m[15] = 1;
  return m;
}

void Apply(const Pose& m, double i, double j, double p[3])
{
  for (int r = 0; r < 3; ++r)
  {
    p[r] = m[4 * r] * i + m[4 * r + 1] * j + m[4 * r + 3];
  }
}

/// A tracked sequence of W x H frames (pixels unused) with the given poses; FrameValid and Timestamp
/// when given.
vtkSmartPointer<vtkImageData> Sequence(const std::vector<Pose>& poses, int width, int height,
  const std::vector<unsigned char>& valid = {}, const std::vector<double>& timestamps = {})
{
  const int n = static_cast<int>(poses.size());
  auto sequence = vtkSmartPointer<vtkImageData>::New();
  sequence->SetDimensions(width, height, n);
  sequence->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  vtkNew<vtkDoubleArray> matrices;
  matrices->SetName("ImageToReference");
  matrices->SetNumberOfComponents(16);
  for (const Pose& p : poses)
  {
    matrices->InsertNextTuple(p.data());
  }
  sequence->GetFieldData()->AddArray(matrices);
  if (!valid.empty())
  {
    vtkNew<vtkUnsignedCharArray> flags;
    flags->SetName("FrameValid");
    for (unsigned char f : valid)
    {
      flags->InsertNextValue(f);
    }
    sequence->GetFieldData()->AddArray(flags);
  }
  if (!timestamps.empty())
  {
    vtkNew<vtkDoubleArray> times;
    times->SetName("Timestamp");
    for (double t : timestamps)
    {
      times->InsertNextValue(t);
    }
    sequence->GetFieldData()->AddArray(times);
  }
  return sequence;
}

/// Continuous voxel index of p in the test volume.
void Index(const double p[3], double c[3])
{
  for (int a = 0; a < 3; ++a)
  {
    c[a] = (p[a] - Origin[a]) / Spacing[a];
  }
}

/// -1: outside by more than tolerance, 1: inside by more than tolerance, 0: on the edge.
int Inside(const double c[3], double border, double tolerance = 1e-6)
{
  int result = 1;
  for (int a = 0; a < 3; ++a)
  {
    const double distance = std::min(c[a] + border, Dims[a] - 1 + border - c[a]);
    if (distance < -tolerance)
    {
      return -1;
    }
    if (distance < tolerance)
    {
      result = 0;
    }
  }
  return result;
}

std::vector<Pose> TestPoses()
{
  const double a1[3] = { 1, 2, 0.5 }, o1[3] = { -4.0, 1.0, 7.0 };
  const double a2[3] = { -0.3, 1, 1 }, o2[3] = { 0.5, 3.0, 4.0 };
  const double a3[3] = { 0, 0, 1 }, o3[3] = { -3.0, 2.0, 5.0 + 3 * 0.8 };
  return { Oblique(a1, 35, 0.37, 0.41, o1), Oblique(a2, -50, 0.29, 0.29, o2), Oblique(a3, 0, 0.5, 0.6, o3) };
}

float At(vtkImageData* image, int i, int j, int k)
{
  int ijk[3] = { i, j, k };
  return static_cast<float>(image->GetPointData()->GetScalars()->GetComponent(image->ComputePointId(ijk), 0));
}

struct Outcome
{
  bool Ok = false;
  std::vector<std::string> Errors;
};

Outcome Execute(vtkUltrasoundSequenceReslice* reslice)
{
  vtkNew<MessageCollector> messages;
  messages->Watch(reslice);
  messages->Watch(reslice->GetExecutive());
  Outcome outcome;
  outcome.Ok = reslice->GetExecutive()->Update() != 0;
  outcome.Errors = messages->Errors;
  return outcome;
}
}

TEST(UltrasoundSequenceReslice, LinearFunctionIsSampledExactlyInsideAndMaskedOutside)
{
  const std::vector<Pose> poses = TestPoses();
  const int W = 40, H = 30;
  for (bool border : { false, true })
  {
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(LinearVolume());
    reslice->SetPoseData(Sequence(poses, W, H));
    reslice->SetBorder(border);
    ASSERT_TRUE(Execute(reslice).Ok);
    vtkImageData* out = reslice->GetOutput();
    vtkImageData* mask = reslice->GetMaskOutput();
    int dims[3];
    out->GetDimensions(dims);
    ASSERT_EQ(dims[0], W);
    ASSERT_EQ(dims[1], H);
    ASSERT_EQ(dims[2], 3);
    ASSERT_EQ(out->GetScalarType(), VTK_FLOAT);
    ASSERT_STREQ(out->GetPointData()->GetScalars()->GetName(), "Intensity");
    ASSERT_STREQ(mask->GetPointData()->GetScalars()->GetName(), "FanMask");
    ASSERT_EQ(mask->GetScalarType(), VTK_UNSIGNED_CHAR);
    int inside = 0, outside = 0;
    for (int k = 0; k < 3; ++k)
    {
      for (int j = 0; j < H; ++j)
      {
        for (int i = 0; i < W; ++i)
        {
          double p[3], c[3];
          Apply(poses[k], i, j, p);
          Index(p, c);
          const int where = Inside(c, border ? 0.5 : 0.0);
          const float value = At(out, i, j, k), flag = At(mask, i, j, k);
          if (where > 0)
          {
            ++inside;
            ASSERT_EQ(flag, 1) << k << " " << i << " " << j;
            // In the border the edge voxel is extended: the function at the clamped position.
            double q[3];
            for (int a = 0; a < 3; ++a)
            {
              q[a] = Origin[a] + std::min(std::max(c[a], 0.0), Dims[a] - 1.0) * Spacing[a];
            }
            ASSERT_NEAR(value, Linear(q), 2e-5 * Linear(q)) << k << " " << i << " " << j;
          }
          else if (where < 0)
          {
            ++outside;
            ASSERT_EQ(flag, 0) << k << " " << i << " " << j;
            ASSERT_EQ(value, 0.0f);
          }
        }
      }
    }
    EXPECT_GT(inside, 1000);
    EXPECT_GT(outside, 500);
  }
}

TEST(UltrasoundSequenceReslice, AnExtentThatDoesNotStartAtZeroSamplesTheSamePositions)
{
  // The same voxels at the same millimetres, indexed from (3, -2, 5): the output must not change.
  vtkSmartPointer<vtkImageData> volume = LinearVolume();
  auto shifted = vtkSmartPointer<vtkImageData>::New();
  shifted->DeepCopy(volume);
  shifted->SetExtent(3, 3 + Dims[0] - 1, -2, -2 + Dims[1] - 1, 5, 5 + Dims[2] - 1);
  shifted->SetOrigin(Origin[0] - 3 * Spacing[0], Origin[1] + 2 * Spacing[1], Origin[2] - 5 * Spacing[2]);
  const std::vector<Pose> poses = TestPoses();
  vtkNew<vtkUltrasoundSequenceReslice> a, b;
  a->SetInputData(volume);
  b->SetInputData(shifted);
  for (vtkUltrasoundSequenceReslice* reslice : { a.Get(), b.Get() })
  {
    reslice->SetPoseData(Sequence(poses, 40, 30));
    ASSERT_TRUE(Execute(reslice).Ok);
  }
  for (int k = 0; k < 3; ++k)
  {
    for (int j = 0; j < 30; ++j)
    {
      for (int i = 0; i < 40; ++i)
      {
        ASSERT_NEAR(At(a->GetOutput(), i, j, k), At(b->GetOutput(), i, j, k), 1e-4);
        ASSERT_EQ(At(a->GetMaskOutput(), i, j, k), At(b->GetMaskOutput(), i, j, k));
      }
    }
  }
}

TEST(UltrasoundSequenceReslice, NearestReadsTheNearestVoxel)
{
  const std::vector<Pose> poses = TestPoses();
  const int W = 40, H = 30;
  vtkNew<vtkUltrasoundSequenceReslice> reslice;
  reslice->SetInputData(LinearVolume());
  reslice->SetPoseData(Sequence(poses, W, H));
  reslice->SetInterpolationModeToNearestNeighbor();
  reslice->BorderOff();
  ASSERT_TRUE(Execute(reslice).Ok);
  int checked = 0;
  for (int k = 0; k < 3; ++k)
  {
    for (int j = 0; j < H; ++j)
    {
      for (int i = 0; i < W; ++i)
      {
        double p[3], c[3], q[3];
        Apply(poses[k], i, j, p);
        Index(p, c);
        if (Inside(c, 0.0) <= 0)
        {
          continue;
        }
        bool tie = false;
        for (int a = 0; a < 3; ++a)
        {
          tie = tie || std::abs(c[a] - std::floor(c[a]) - 0.5) < 1e-6;
          q[a] = Origin[a] + std::floor(c[a] + 0.5) * Spacing[a];
        }
        if (!tie)
        {
          ++checked;
          ASSERT_NEAR(At(reslice->GetOutput(), i, j, k), Linear(q), 2e-5 * Linear(q));
          ASSERT_EQ(At(reslice->GetMaskOutput(), i, j, k), 1);
        }
      }
    }
  }
  EXPECT_GT(checked, 1000);
}

TEST(UltrasoundSequenceReslice, SamplesThatReadEmptyVoxelsAreMasked)
{
  // 10 x 10 x 10 voxels of 1 mm: value 2 everywhere except x index >= 5 and the plane z = 4 (0).
  auto volume = vtkSmartPointer<vtkImageData>::New();
  volume->SetDimensions(10, 10, 10);
  volume->AllocateScalars(VTK_FLOAT, 1);
  vtkNew<vtkUnsignedCharArray> filled;
  filled->SetName("Filled");
  filled->SetNumberOfTuples(1000);
  auto* v = static_cast<float*>(volume->GetScalarPointer());
  for (int z = 0; z < 10; ++z)
  {
    for (int y = 0; y < 10; ++y)
    {
      for (int x = 0; x < 10; ++x, ++v)
      {
        *v = (x >= 5 || z == 4) ? 0.0f : 2.0f;
        filled->SetValue(x + 10 * y + 100 * z, *v != 0);
      }
    }
  }
  // Frame on the voxel plane z = 3 (it must not see the empty plane z = 4), shifted half a voxel in x.
  const double axis[3] = { 0, 0, 1 }, origin[3] = { 0.5, 0, 3 };
  const Pose pose = Oblique(axis, 0, 1, 1, origin);
  const auto check = [](vtkUltrasoundSequenceReslice* reslice, bool maskEmpty) {
    ASSERT_TRUE(Execute(reslice).Ok);
    for (int j = 0; j < 10; ++j)
    {
      for (int i = 0; i < 9; ++i)
      {
        // Sample at x = i + 0.5 reads voxels i and i + 1.
        const float expected = i < 4 ? 2.0f : (i == 4 ? 1.0f : 0.0f);
        EXPECT_FLOAT_EQ(At(reslice->GetOutput(), i, j, 0), expected) << i << " " << j;
        EXPECT_EQ(At(reslice->GetMaskOutput(), i, j, 0), (!maskEmpty || i < 4) ? 1 : 0) << i << " " << j;
      }
    }
  };
  vtkNew<vtkUltrasoundSequenceReslice> reslice;
  reslice->SetInputData(volume);
  reslice->SetPoseData(Sequence({ pose }, 10, 10));
  check(reslice, true);
  reslice->MaskEmptyVoxelsOff();
  check(reslice, false);

  // A validity array decides instead of the scalars: make every scalar non-zero.
  auto painted = vtkSmartPointer<vtkImageData>::New();
  painted->DeepCopy(volume);
  auto* p = static_cast<float*>(painted->GetScalarPointer());
  for (int x = 0; x < 1000; ++x)
  {
    p[x] = p[x] == 0 ? 1e-3f : p[x];
  }
  painted->GetPointData()->AddArray(filled);
  vtkNew<vtkUltrasoundSequenceReslice> withValidity;
  withValidity->SetInputData(painted);
  withValidity->SetPoseData(Sequence({ pose }, 10, 10));
  withValidity->SetValidityArrayName("Filled");
  ASSERT_TRUE(Execute(withValidity).Ok);
  for (int i = 0; i < 9; ++i)
  {
    EXPECT_EQ(At(withValidity->GetMaskOutput(), i, 5, 0), i < 4 ? 1 : 0) << i;
  }
}

TEST(UltrasoundSequenceReslice, FrameListChoosesFramesAndCarriesTheirFieldData)
{
  std::vector<Pose> poses = TestPoses();
  vtkNew<vtkUltrasoundSequenceReslice> reslice;
  reslice->SetInputData(LinearVolume());
  reslice->SetPoseData(Sequence(poses, 40, 30, { 1, 0, 1 }, { 0.1, 0.2, 0.3 }));
  vtkNew<vtkIdList> frames;
  frames->InsertNextId(2);
  frames->InsertNextId(1);
  reslice->SetFrameList(frames);
  ASSERT_TRUE(Execute(reslice).Ok);
  vtkImageData* out = reslice->GetOutput();
  EXPECT_EQ(out->GetDimensions()[2], 2);
  EXPECT_EQ(reslice->GetMaskOutput()->GetDimensions()[2], 2);
  vtkFieldData* fd = out->GetFieldData();
  for (int k = 0; k < 2; ++k)
  {
    const int source = k == 0 ? 2 : 1;
    double m[16];
    fd->GetArray("ImageToReference")->GetTuple(k, m);
    for (int e = 0; e < 16; ++e)
    {
      EXPECT_EQ(m[e], poses[source][e]);
    }
    EXPECT_DOUBLE_EQ(fd->GetArray("Timestamp")->GetTuple1(k), 0.1 * (source + 1));
    EXPECT_EQ(fd->GetArray("FrameIndex")->GetTuple1(k), source);
    EXPECT_EQ(fd->GetArray("FrameValid")->GetTuple1(k), source == 2 ? 1 : 0);
  }
  // The invalid frame (1) has no usable pose: nothing is sampled.
  vtkDataArray* values = out->GetPointData()->GetScalars();
  vtkDataArray* mask = reslice->GetMaskOutput()->GetPointData()->GetScalars();
  double sum = 0, masked = 0;
  for (vtkIdType p = 40 * 30; p < 2 * 40 * 30; ++p)
  {
    sum += std::abs(values->GetComponent(p, 0));
    masked += mask->GetComponent(p, 0);
  }
  EXPECT_EQ(sum, 0);
  EXPECT_EQ(masked, 0);

  // Editing the held frame list (and marking it modified, as for any VTK data) re-executes the filter.
  frames->InsertNextId(0);
  frames->Modified();
  ASSERT_TRUE(Execute(reslice).Ok);
  EXPECT_EQ(reslice->GetOutput()->GetDimensions()[2], 3);
}

TEST(UltrasoundSequenceReslice, AgreesWithImageResliceOnTheSpineReconstruction)
{
  vtkNew<vtkMetaImageReader> reader;
  reader->SetFileName(DataPath("spine-phantom/SpinePhantomFreehandReconstructed.mha").c_str());
  reader->Update();
  vtkImageData* volume = reader->GetOutput();
  ASSERT_EQ(volume->GetScalarType(), VTK_UNSIGNED_CHAR);
  double centre[3];
  volume->GetCenter(centre);
  // Oblique planes through the centre, 120 x 90 pixels of 0.45 mm.
  const int W = 120, H = 90;
  const double su = 0.45, sv = 0.45;
  const double axes[3][3] = { { 1, 0.2, 0 }, { 0.3, -1, 0.6 }, { 0.1, 0.1, 1 } };
  const double angles[3] = { 25, 70, 10 };
  std::vector<Pose> poses;
  for (int f = 0; f < 3; ++f)
  {
    const double zero[3] = { 0, 0, 0 };
    Pose m = Oblique(axes[f], angles[f], su, sv, zero);
    for (int r = 0; r < 3; ++r)
    {
      m[4 * r + 3] = centre[r] - (W - 1) / 2.0 * m[4 * r] - (H - 1) / 2.0 * m[4 * r + 1];
    }
    poses.push_back(m);
  }
  for (int mode : { vtkUltrasoundSequenceReslice::LINEAR, vtkUltrasoundSequenceReslice::NEAREST })
  {
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputConnection(reader->GetOutputPort());
    reslice->SetPoseData(Sequence(poses, W, H));
    reslice->SetInterpolationMode(mode);
    ASSERT_TRUE(Execute(reslice).Ok);
    for (int f = 0; f < 3; ++f)
    {
      vtkNew<vtkMatrix4x4> axesMatrix;
      for (int r = 0; r < 3; ++r)
      {
        for (int c = 0; c < 3; ++c)
        {
          axesMatrix->SetElement(r, c, poses[f][4 * r + c] / (c == 0 ? su : c == 1 ? sv : 1.0));
        }
        axesMatrix->SetElement(r, 3, poses[f][4 * r + 3]);
      }
      vtkNew<vtkImageReslice> truth;
      truth->SetInputConnection(reader->GetOutputPort());
      truth->SetResliceAxes(axesMatrix);
      truth->SetOutputSpacing(su, sv, 1);
      truth->SetOutputOrigin(0, 0, 0);
      truth->SetOutputExtent(0, W - 1, 0, H - 1, 0, 0);
      truth->SetOutputScalarType(VTK_FLOAT);
      if (mode == vtkUltrasoundSequenceReslice::LINEAR)
      {
        truth->SetInterpolationModeToLinear();
      }
      else
      {
        truth->SetInterpolationModeToNearestNeighbor();
      }
      truth->Update();
      int compared = 0;
      for (int j = 0; j < H; ++j)
      {
        for (int i = 0; i < W; ++i)
        {
          if (At(reslice->GetMaskOutput(), i, j, f) == 0)
          {
            continue;
          }
          ++compared;
          ASSERT_NEAR(255.0 * At(reslice->GetOutput(), i, j, f), At(truth->GetOutput(), i, j, 0), 2e-3)
            << "mode " << mode << " frame " << f << " pixel " << i << " " << j;
        }
      }
      EXPECT_GT(compared, W * H / 4) << "frame " << f;
    }
  }
}

TEST(UltrasoundSequenceReslice, UnsignedCharOutputHoldsTheVoxelValues)
{
  auto volume = vtkSmartPointer<vtkImageData>::New();
  volume->SetDimensions(6, 5, 4);
  volume->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  auto* v = static_cast<unsigned char*>(volume->GetScalarPointer());
  for (int x = 0; x < 120; ++x)
  {
    v[x] = static_cast<unsigned char>(1 + (x * 37) % 250);
  }
  const double axis[3] = { 0, 0, 1 }, origin[3] = { 0, 0, 2 };
  vtkNew<vtkUltrasoundSequenceReslice> reslice;
  reslice->SetInputData(volume);
  reslice->SetPoseData(Sequence({ Oblique(axis, 0, 1, 1, origin) }, 6, 5));
  reslice->SetOutputScalarTypeToUnsignedChar();
  ASSERT_TRUE(Execute(reslice).Ok);
  ASSERT_EQ(reslice->GetOutput()->GetScalarType(), VTK_UNSIGNED_CHAR);
  for (int j = 0; j < 5; ++j)
  {
    for (int i = 0; i < 6; ++i)
    {
      EXPECT_EQ(At(reslice->GetOutput(), i, j, 0), v[i + 6 * j + 60]);
    }
  }
}

TEST(UltrasoundSequenceReslice, BadInputFailsTheRequest)
{
  const std::vector<Pose> poses = TestPoses();
  const auto expectFailure = [](vtkUltrasoundSequenceReslice* reslice, const char* what) {
    const Outcome outcome = Execute(reslice);
    EXPECT_FALSE(outcome.Ok) << what;
    EXPECT_FALSE(outcome.Errors.empty()) << what;
    EXPECT_EQ(reslice->GetOutput()->GetNumberOfPoints(), 0) << what;
  };
  {
    auto flat = vtkSmartPointer<vtkImageData>::New();
    flat->SetDimensions(10, 10, 1);
    flat->AllocateScalars(VTK_FLOAT, 1);
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(flat);
    reslice->SetPoseData(Sequence(poses, 8, 8));
    expectFailure(reslice, "2D volume");
  }
  {
    auto bare = vtkSmartPointer<vtkImageData>::New();
    bare->SetDimensions(10, 10, 10);
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(bare);
    reslice->SetPoseData(Sequence(poses, 8, 8));
    expectFailure(reslice, "volume without scalars");
  }
  {
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(LinearVolume());
    reslice->SetPoseData(Sequence({}, 8, 8));
    expectFailure(reslice, "no frames");
  }
  {
    auto noPoses = vtkSmartPointer<vtkImageData>::New();
    noPoses->SetDimensions(8, 8, 3);
    noPoses->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(LinearVolume());
    reslice->SetPoseData(noPoses);
    expectFailure(reslice, "no ImageToReference");
  }
  {
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(LinearVolume());
    reslice->SetPoseData(Sequence(poses, 8, 8));
    vtkNew<vtkIdList> frames;
    frames->InsertNextId(3);
    reslice->SetFrameList(frames);
    expectFailure(reslice, "frame outside the sequence");
  }
  {
    std::vector<Pose> broken = poses;
    broken[1][3] = std::nan("");
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(LinearVolume());
    reslice->SetPoseData(Sequence(broken, 8, 8));
    expectFailure(reslice, "NaN pose");
  }
  {
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(LinearVolume());
    reslice->SetPoseData(Sequence(poses, 8, 8));
    reslice->SetValidityArrayName("Missing");
    expectFailure(reslice, "missing validity array");
  }
}
