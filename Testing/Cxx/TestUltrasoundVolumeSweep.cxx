// vtkUltrasoundVolumeSweep: parallel sweeps with one frame per voxel plane reproduce the volume,
// Offset 0.5 slices lie midway, oblique poses are orthonormal, tilted at most MaximumTiltAngle and
// fixed by the seed, the orthogonal sweep steps along the next axis, every sampled pixel of a linear
// volume equals the function at its pose, the PLUS spine reconstruction gives the protocol's sweeps
// with sensible masks, and bad settings fail the request without a crash.
#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkExecutive.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkMetaImageReader.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundVolumeSweep.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <iostream>
#include <random>
#include <vector>

using bigus_test::DataPath;
using bigus_test::MessageCollector;
using bigus_test::Pose;

namespace
{
const int Dims[3] = { 9, 7, 6 };
const double Spacing[3] = { 0.5, 0.7, 0.9 };
const double Origin[3] = { 1.0, -2.0, 3.0 };

/// Float volume of random whole numbers in [1, 200] (non-zero: every voxel holds data).
vtkSmartPointer<vtkImageData> RandomVolume()
{
  auto volume = vtkSmartPointer<vtkImageData>::New();
  volume->SetDimensions(Dims[0], Dims[1], Dims[2]);
  volume->SetSpacing(Spacing[0], Spacing[1], Spacing[2]);
  volume->SetOrigin(Origin[0], Origin[1], Origin[2]);
  volume->AllocateScalars(VTK_FLOAT, 1);
  std::mt19937 rng(7);
  auto* v = static_cast<float*>(volume->GetScalarPointer());
  for (vtkIdType p = 0; p < volume->GetNumberOfPoints(); ++p)
  {
    v[p] = static_cast<float>(1 + rng() % 200);
  }
  return volume;
}

float Voxel(vtkImageData* volume, const int index[3])
{
  int ijk[3] = { index[0], index[1], index[2] };
  return static_cast<float>(volume->GetPointData()->GetScalars()->GetComponent(volume->ComputePointId(ijk), 0));
}

float At(vtkImageData* image, int i, int j, int k)
{
  int ijk[3] = { i, j, k };
  return static_cast<float>(image->GetPointData()->GetScalars()->GetComponent(image->ComputePointId(ijk), 0));
}

void Apply(const std::array<double, 16>& m, double i, double j, double p[3])
{
  for (int r = 0; r < 3; ++r)
  {
    p[r] = m[4 * r] * i + m[4 * r + 1] * j + m[4 * r + 3];
  }
}

double Column(const std::array<double, 16>& m, int c, int r)
{
  return m[4 * r + c];
}

double Norm(const std::array<double, 16>& m, int c)
{
  const double x = Column(m, c, 0), y = Column(m, c, 1), z = Column(m, c, 2);
  return std::sqrt(x * x + y * y + z * z);
}

bool Update(vtkUltrasoundVolumeSweep* sweep, std::vector<std::string>* errors = nullptr)
{
  vtkNew<MessageCollector> messages;
  messages->Watch(sweep);
  messages->Watch(sweep->GetExecutive());
  const bool ok = sweep->GetExecutive()->Update() != 0;
  if (errors)
  {
    *errors = messages->Errors;
  }
  return ok;
}

double MaskFraction(vtkImageData* mask)
{
  vtkDataArray* m = mask->GetPointData()->GetScalars();
  double sum = 0;
  for (vtkIdType p = 0; p < m->GetNumberOfTuples(); ++p)
  {
    sum += m->GetComponent(p, 0) != 0;
  }
  return sum / std::max<vtkIdType>(1, m->GetNumberOfTuples());
}
}

TEST(UltrasoundVolumeSweep, ParallelSweepWithOneFramePerVoxelPlaneReproducesTheVolume)
{
  vtkSmartPointer<vtkImageData> volume = RandomVolume();
  for (int axis = 0; axis < 3; ++axis)
  {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    vtkNew<vtkUltrasoundVolumeSweep> sweep;
    sweep->SetInputData(volume);
    sweep->SetSweepAxis(axis);
    sweep->SetNumberOfFrames(Dims[axis]);
    ASSERT_TRUE(Update(sweep));
    vtkImageData* out = sweep->GetOutput();
    int dims[3];
    out->GetDimensions(dims);
    ASSERT_EQ(dims[0], Dims[u]);
    ASSERT_EQ(dims[1], Dims[v]);
    ASSERT_EQ(dims[2], Dims[axis]);
    EXPECT_EQ(sweep->GetFrameSize()[0], Dims[u]);
    EXPECT_EQ(sweep->GetFrameSize()[1], Dims[v]);
    EXPECT_DOUBLE_EQ(sweep->GetSliceSpacing(), Spacing[axis]);
    EXPECT_EQ(MaskFraction(sweep->GetMaskOutput()), 1.0);
    for (int k = 0; k < dims[2]; ++k)
    {
      const std::array<double, 16> pose = Pose(out, k);
      for (int j = 0; j < dims[1]; ++j)
      {
        for (int i = 0; i < dims[0]; ++i)
        {
          int index[3];
          index[axis] = k;
          index[u] = i;
          index[v] = j;
          ASSERT_EQ(At(out, i, j, k), Voxel(volume, index)) << "axis " << axis << " frame " << k;
          double p[3];
          Apply(pose, i, j, p);
          for (int a = 0; a < 3; ++a)
          {
            ASSERT_NEAR(p[a], Origin[a] + index[a] * Spacing[a], 1e-12);
          }
        }
      }
    }
  }
}

TEST(UltrasoundVolumeSweep, SlicesFollowTheVolumesDirectionMatrix)
{
  // The volume's axes rotated by 30 degrees about z and 20 about x: frames still lie on its voxel planes.
  vtkSmartPointer<vtkImageData> volume = RandomVolume();
  const double a = M_PI / 6, b = M_PI / 9;
  const double Rz[3][3] = { { std::cos(a), -std::sin(a), 0 }, { std::sin(a), std::cos(a), 0 }, { 0, 0, 1 } };
  const double Rx[3][3] = { { 1, 0, 0 }, { 0, std::cos(b), -std::sin(b) }, { 0, std::sin(b), std::cos(b) } };
  double D[9];
  for (int r = 0; r < 3; ++r)
  {
    for (int c = 0; c < 3; ++c)
    {
      D[3 * r + c] = Rz[r][0] * Rx[0][c] + Rz[r][1] * Rx[1][c] + Rz[r][2] * Rx[2][c];
    }
  }
  volume->SetDirectionMatrix(D);
  vtkNew<vtkUltrasoundVolumeSweep> sweep;
  sweep->SetInputData(volume);
  sweep->SetNumberOfFrames(Dims[2]);
  ASSERT_TRUE(Update(sweep));
  vtkImageData* out = sweep->GetOutput();
  EXPECT_EQ(MaskFraction(sweep->GetMaskOutput()), 1.0);
  for (int k = 0; k < Dims[2]; ++k)
  {
    const std::array<double, 16> pose = Pose(out, k);
    for (int j = 0; j < Dims[1]; ++j)
    {
      for (int i = 0; i < Dims[0]; ++i)
      {
        const int index[3] = { i, j, k };
        ASSERT_EQ(At(out, i, j, k), Voxel(volume, index));
        double p[3], q[3];
        Apply(pose, i, j, p);
        volume->TransformIndexToPhysicalPoint(i, j, k, q);
        for (int c = 0; c < 3; ++c)
        {
          ASSERT_NEAR(p[c], q[c], 1e-12);
        }
      }
    }
  }
}

TEST(UltrasoundVolumeSweep, OffsetHalfSlicesLieMidwayBetweenOffsetZeroSlices)
{
  vtkSmartPointer<vtkImageData> volume = RandomVolume();
  // N = 3 slices of the 6 planes along z: Offset 0 reads planes 0, 2, 4 and Offset 0.5 planes 1, 3, 5.
  vtkNew<vtkUltrasoundVolumeSweep> train, test;
  for (vtkUltrasoundVolumeSweep* sweep : { train.Get(), test.Get() })
  {
    sweep->SetInputData(volume);
    sweep->SetNumberOfFrames(3);
    sweep->SetOffset(sweep == test.Get() ? 0.5 : 0.0);
    ASSERT_TRUE(Update(sweep));
    EXPECT_DOUBLE_EQ(sweep->GetSliceSpacing(), Dims[2] * Spacing[2] / 3);
  }
  const double delta = train->GetSliceSpacing();
  for (int k = 0; k < 3; ++k)
  {
    const std::array<double, 16> a = Pose(train->GetOutput(), k), b = Pose(test->GetOutput(), k);
    for (int r = 0; r < 3; ++r)
    {
      for (int c = 0; c < 3; ++c)
      {
        EXPECT_EQ(Column(a, c, r), Column(b, c, r));
      }
      // Half a slice spacing further along the normal (z)...
      EXPECT_NEAR(b[4 * r + 3] - a[4 * r + 3], r == 2 ? delta / 2 : 0.0, 1e-12);
      if (k + 1 < 3)
      {
        // ... which is the midpoint of this slice and the next.
        const std::array<double, 16> next = Pose(train->GetOutput(), k + 1);
        EXPECT_NEAR(b[4 * r + 3], (a[4 * r + 3] + next[4 * r + 3]) / 2, 1e-12);
      }
    }
    for (int j = 0; j < Dims[1]; ++j)
    {
      for (int i = 0; i < Dims[0]; ++i)
      {
        const int even[3] = { i, j, 2 * k }, odd[3] = { i, j, 2 * k + 1 };
        ASSERT_EQ(At(train->GetOutput(), i, j, k), Voxel(volume, even));
        ASSERT_EQ(At(test->GetOutput(), i, j, k), Voxel(volume, odd));
      }
    }
  }
}

TEST(UltrasoundVolumeSweep, ObliquePosesAreOrthonormalTiltedAtMostTheMaximumAndFixedBySeed)
{
  vtkSmartPointer<vtkImageData> volume = RandomVolume();
  const auto run = [&](unsigned int seed, double tilt, double offset) {
    auto sweep = vtkSmartPointer<vtkUltrasoundVolumeSweep>::New();
    sweep->SetInputData(volume);
    sweep->SetProtocolToOblique();
    sweep->SetNumberOfFrames(200);
    sweep->SetSeed(seed);
    sweep->SetMaximumTiltAngle(tilt);
    sweep->SetOffset(offset);
    EXPECT_TRUE(Update(sweep));
    return sweep;
  };
  vtkSmartPointer<vtkUltrasoundVolumeSweep> sweep = run(5, 30, 0);
  vtkImageData* out = sweep->GetOutput();
  const int W = Dims[0], H = Dims[1];
  ASSERT_EQ(out->GetDimensions()[0], W);
  ASSERT_EQ(out->GetDimensions()[1], H);
  ASSERT_EQ(out->GetDimensions()[2], 200);
  double largestTilt = 0, previousZ = -1e300;
  for (int k = 0; k < 200; ++k)
  {
    const std::array<double, 16> m = Pose(out, k);
    ASSERT_NEAR(Norm(m, 0), Spacing[0], 1e-12);
    ASSERT_NEAR(Norm(m, 1), Spacing[1], 1e-12);
    ASSERT_NEAR(Norm(m, 2), 1.0, 1e-12);
    double u[3], v[3], n[3];
    for (int r = 0; r < 3; ++r)
    {
      u[r] = Column(m, 0, r) / Spacing[0];
      v[r] = Column(m, 1, r) / Spacing[1];
      n[r] = Column(m, 2, r);
    }
    ASSERT_NEAR(u[0] * v[0] + u[1] * v[1] + u[2] * v[2], 0.0, 1e-12);
    // Right-handed: n = u x v.
    ASSERT_NEAR(n[0], u[1] * v[2] - u[2] * v[1], 1e-12);
    ASSERT_NEAR(n[1], u[2] * v[0] - u[0] * v[2], 1e-12);
    ASSERT_NEAR(n[2], u[0] * v[1] - u[1] * v[0], 1e-12);
    const double tilt = std::acos(std::min(1.0, n[2])) * 180 / M_PI;
    ASSERT_LE(tilt, 30.0 + 1e-9);
    largestTilt = std::max(largestTilt, tilt);
    // The frame centre lies on the sweep axis through the volume centre, within the voxel planes,
    // and the frames are ordered along it.
    double centre[3];
    Apply(m, (W - 1) / 2.0, (H - 1) / 2.0, centre);
    EXPECT_NEAR(centre[0], Origin[0] + (Dims[0] - 1) * Spacing[0] / 2, 1e-12);
    EXPECT_NEAR(centre[1], Origin[1] + (Dims[1] - 1) * Spacing[1] / 2, 1e-12);
    EXPECT_GE(centre[2], Origin[2]);
    EXPECT_LE(centre[2], Origin[2] + (Dims[2] - 1) * Spacing[2]);
    EXPECT_GE(centre[2], previousZ);
    previousZ = centre[2];
  }
  EXPECT_GT(largestTilt, 25.0);
  EXPECT_LT(MaskFraction(sweep->GetMaskOutput()), 1.0);
  EXPECT_GT(MaskFraction(sweep->GetMaskOutput()), 0.5);

  // The seed fixes the poses (Offset is not used); another seed gives other poses.
  vtkSmartPointer<vtkUltrasoundVolumeSweep> same = run(5, 30, 0.5), other = run(6, 30, 0);
  bool differs = false;
  for (int k = 0; k < 200; ++k)
  {
    const std::array<double, 16> a = Pose(out, k), b = Pose(same->GetOutput(), k), c = Pose(other->GetOutput(), k);
    for (int e = 0; e < 16; ++e)
    {
      ASSERT_EQ(a[e], b[e]);
      differs = differs || a[e] != c[e];
    }
  }
  EXPECT_TRUE(differs);

  // No tilt: every frame is a z plane.
  vtkSmartPointer<vtkUltrasoundVolumeSweep> flat = run(5, 0, 0);
  for (int k = 0; k < 200; ++k)
  {
    EXPECT_EQ(Pose(flat->GetOutput(), k)[10], 1.0);
  }
}

TEST(UltrasoundVolumeSweep, OrthogonalSweepStepsAlongTheNextAxis)
{
  vtkSmartPointer<vtkImageData> volume = RandomVolume();
  vtkNew<vtkUltrasoundVolumeSweep> sweep;
  sweep->SetInputData(volume);
  sweep->SetProtocolToOrthogonal();
  sweep->SetNumberOfFrames(Dims[0]);
  ASSERT_TRUE(Update(sweep));
  // SweepAxis 2 (default): slices step along x, columns along y, rows along z.
  vtkImageData* out = sweep->GetOutput();
  ASSERT_EQ(out->GetDimensions()[0], Dims[1]);
  ASSERT_EQ(out->GetDimensions()[1], Dims[2]);
  ASSERT_EQ(out->GetDimensions()[2], Dims[0]);
  for (int k = 0; k < Dims[0]; ++k)
  {
    const std::array<double, 16> m = Pose(out, k);
    EXPECT_EQ(Column(m, 2, 0), 1.0);
    for (int j = 0; j < Dims[2]; ++j)
    {
      for (int i = 0; i < Dims[1]; ++i)
      {
        const int index[3] = { k, i, j };
        ASSERT_EQ(At(out, i, j, k), Voxel(volume, index));
      }
    }
  }
}

TEST(UltrasoundVolumeSweep, TimestampsFieldDataAndPixelSpacing)
{
  vtkNew<vtkUltrasoundVolumeSweep> sweep;
  sweep->SetInputData(RandomVolume());
  sweep->SetNumberOfFrames(12);
  sweep->SetPixelSpacing(0.3);
  ASSERT_TRUE(Update(sweep));
  vtkImageData* out = sweep->GetOutput();
  // W = floor(8 * 0.5 / 0.3) + 1 = 14, H = floor(6 * 0.7 / 0.3) + 1 = 15.
  ASSERT_EQ(out->GetDimensions()[0], 14);
  ASSERT_EQ(out->GetDimensions()[1], 15);
  ASSERT_EQ(sweep->GetMaskOutput()->GetDimensions()[2], 12);
  vtkFieldData* fd = out->GetFieldData();
  for (int k = 0; k < 12; ++k)
  {
    EXPECT_DOUBLE_EQ(fd->GetArray("Timestamp")->GetTuple1(k), k * 0.05);
    EXPECT_EQ(fd->GetArray("FrameValid")->GetTuple1(k), 1);
    EXPECT_EQ(fd->GetArray("FrameIndex")->GetTuple1(k), k);
    const std::array<double, 16> m = Pose(out, k);
    EXPECT_NEAR(Norm(m, 0), 0.3, 1e-12);
    EXPECT_NEAR(Norm(m, 1), 0.3, 1e-12);
    // Centred on the cross-section.
    double centre[3];
    Apply(m, 6.5, 7, centre);
    EXPECT_NEAR(centre[0], Origin[0] + 2.0, 1e-12);
    EXPECT_NEAR(centre[1], Origin[1] + 2.1, 1e-12);
  }
}

TEST(UltrasoundVolumeSweep, EverySampleOfALinearVolumeEqualsTheFunctionAtItsPose)
{
  // 30 x 24 x 20 voxels, value 20 + x - 0.5 y + 0.25 z (mm; positive, so every voxel holds data):
  // trilinear sampling is exact.
  const int dims[3] = { 30, 24, 20 };
  const double spacing[3] = { 0.4, 0.5, 0.6 }, origin[3] = { -5, 4, 2 };
  auto volume = vtkSmartPointer<vtkImageData>::New();
  volume->SetDimensions(dims[0], dims[1], dims[2]);
  volume->SetSpacing(spacing[0], spacing[1], spacing[2]);
  volume->SetOrigin(origin[0], origin[1], origin[2]);
  volume->AllocateScalars(VTK_DOUBLE, 1);
  const auto f = [](const double p[3]) { return 20 + p[0] - 0.5 * p[1] + 0.25 * p[2]; };
  for (int z = 0; z < dims[2]; ++z)
  {
    for (int y = 0; y < dims[1]; ++y)
    {
      for (int x = 0; x < dims[0]; ++x)
      {
        const double p[3] = { origin[0] + x * spacing[0], origin[1] + y * spacing[1], origin[2] + z * spacing[2] };
        *static_cast<double*>(volume->GetScalarPointer(x, y, z)) = f(p);
      }
    }
  }
  for (int protocol : { vtkUltrasoundVolumeSweep::OBLIQUE, vtkUltrasoundVolumeSweep::PARALLEL })
  {
    vtkNew<vtkUltrasoundVolumeSweep> sweep;
    sweep->SetInputData(volume);
    sweep->SetProtocol(protocol);
    sweep->SetNumberOfFrames(25);
    sweep->SetPixelSpacing(0.35);
    sweep->SetOffset(0.3);
    ASSERT_TRUE(Update(sweep));
    vtkImageData* out = sweep->GetOutput();
    int W = out->GetDimensions()[0], H = out->GetDimensions()[1], inside = 0, outside = 0;
    for (int k = 0; k < 25; ++k)
    {
      const std::array<double, 16> m = Pose(out, k);
      for (int j = 0; j < H; ++j)
      {
        for (int i = 0; i < W; ++i)
        {
          double p[3], q[3];
          Apply(m, i, j, p);
          // Border: within half a voxel outside, the edge voxel's value (the function clamped).
          bool in = true, edge = false;
          for (int a = 0; a < 3; ++a)
          {
            const double c = (p[a] - origin[a]) / spacing[a];
            const double distance = std::min(c + 0.5, dims[a] - 0.5 - c);
            in = in && distance > 1e-6;
            edge = edge || std::abs(distance) <= 1e-6;
            q[a] = origin[a] + std::min(std::max(c, 0.0), dims[a] - 1.0) * spacing[a];
          }
          if (edge)
          {
            continue;
          }
          if (in)
          {
            ++inside;
            ASSERT_EQ(At(sweep->GetMaskOutput(), i, j, k), 1);
            ASSERT_NEAR(At(out, i, j, k), f(q), 2e-5 * std::abs(f(q)) + 1e-5);
          }
          else
          {
            ++outside;
            ASSERT_EQ(At(sweep->GetMaskOutput(), i, j, k), 0);
          }
        }
      }
    }
    EXPECT_GT(inside, 1000);
    if (protocol == vtkUltrasoundVolumeSweep::OBLIQUE)
    {
      EXPECT_GT(outside, 1000);
    }
  }
}

TEST(UltrasoundVolumeSweep, SpineReconstructionProtocol)
{
  vtkNew<vtkMetaImageReader> reader;
  reader->SetFileName(DataPath("spine-phantom/SpinePhantomFreehandReconstructed.mha").c_str());
  reader->Update();
  vtkImageData* volume = reader->GetOutput();
  int dims[3];
  volume->GetDimensions(dims);
  ASSERT_EQ(dims[2], 104);

  struct Case
  {
    const char* Name;
    int Protocol;
    double Offset;
    double MinimumMaskFraction;
  };
  // The reconstruction fills 29 % of its voxels (the rest is the bounding box around the sweep).
  // Mask fractions measured with 80 frames, trilinear: 0.282, 0.282, 0.279 (seed 1), 0.281; the
  // bounds leave some margin.
  const Case cases[] = { { "parallel", vtkUltrasoundVolumeSweep::PARALLEL, 0.0, 0.25 },
    { "in-between", vtkUltrasoundVolumeSweep::PARALLEL, 0.5, 0.25 },
    { "oblique", vtkUltrasoundVolumeSweep::OBLIQUE, 0.0, 0.25 },
    { "orthogonal", vtkUltrasoundVolumeSweep::ORTHOGONAL, 0.0, 0.25 } };
  for (const Case& c : cases)
  {
    vtkNew<vtkUltrasoundVolumeSweep> sweep;
    sweep->SetInputConnection(reader->GetOutputPort());
    sweep->SetProtocol(c.Protocol);
    sweep->SetOffset(c.Offset);
    sweep->SetNumberOfFrames(80);
    ASSERT_TRUE(Update(sweep)) << c.Name;
    vtkImageData* mask = sweep->GetMaskOutput();
    const double fraction = MaskFraction(mask);
    int emptyFrames = 0;
    const int W = mask->GetDimensions()[0], H = mask->GetDimensions()[1];
    for (int k = 0; k < 80; ++k)
    {
      int filled = 0;
      for (int j = 0; j < H; ++j)
      {
        for (int i = 0; i < W; ++i)
        {
          filled += At(mask, i, j, k) != 0;
        }
      }
      emptyFrames += filled == 0;
    }
    std::cout << c.Name << ": " << W << " x " << H << " x 80, mask fraction " << fraction << ", empty frames "
              << emptyFrames << ", " << sweep->GetSecondsToBuild() << " s\n";
    EXPECT_GT(fraction, c.MinimumMaskFraction) << c.Name;
    EXPECT_LT(fraction, 0.30) << c.Name;
  }

  // Every second voxel plane: Offset 0 gives the even planes and Offset 0.5 the odd ones, exactly.
  for (double offset : { 0.0, 0.5 })
  {
    vtkNew<vtkUltrasoundVolumeSweep> sweep;
    sweep->SetInputConnection(reader->GetOutputPort());
    sweep->SetNumberOfFrames(52);
    sweep->SetOffset(offset);
    ASSERT_TRUE(Update(sweep));
    vtkImageData* out = sweep->GetOutput();
    for (int k = 0; k < 52; ++k)
    {
      for (int j = 0; j < dims[1]; ++j)
      {
        for (int i = 0; i < dims[0]; ++i)
        {
          const int index[3] = { i, j, 2 * k + (offset > 0 ? 1 : 0) };
          ASSERT_EQ(At(out, i, j, k), static_cast<float>(Voxel(volume, index) / 255.0));
          ASSERT_EQ(At(sweep->GetMaskOutput(), i, j, k), Voxel(volume, index) != 0 ? 1 : 0);
        }
      }
    }
  }

  // Time to build the paper's 160-frame sweeps (printed, not asserted).
  for (int protocol : { vtkUltrasoundVolumeSweep::PARALLEL, vtkUltrasoundVolumeSweep::OBLIQUE })
  {
    vtkNew<vtkUltrasoundVolumeSweep> sweep;
    sweep->SetInputConnection(reader->GetOutputPort());
    sweep->SetProtocol(protocol);
    ASSERT_TRUE(Update(sweep));
    std::cout << (protocol == vtkUltrasoundVolumeSweep::PARALLEL ? "parallel" : "oblique")
              << " 160 frames: " << sweep->GetSecondsToBuild() << " s, mask fraction "
              << MaskFraction(sweep->GetMaskOutput()) << "\n";
  }
}

TEST(UltrasoundVolumeSweep, BadSettingsFailTheRequest)
{
  vtkSmartPointer<vtkImageData> volume = RandomVolume();
  const std::vector<std::pair<const char*, std::function<void(vtkUltrasoundVolumeSweep*)>>> bad = {
    { "zero frames", [](vtkUltrasoundVolumeSweep* s) { s->SetNumberOfFrames(0); } },
    { "offset 1", [](vtkUltrasoundVolumeSweep* s) { s->SetOffset(1.0); } },
    { "negative offset", [](vtkUltrasoundVolumeSweep* s) { s->SetOffset(-0.1); } },
    { "tilt 91",
      [](vtkUltrasoundVolumeSweep* s) {
        s->SetProtocolToOblique();
        s->SetMaximumTiltAngle(91);
      } },
    { "negative tilt", [](vtkUltrasoundVolumeSweep* s) { s->SetMaximumTiltAngle(-1); } },
    { "NaN tilt", [](vtkUltrasoundVolumeSweep* s) { s->SetMaximumTiltAngle(std::nan("")); } },
    { "sweep axis 3", [](vtkUltrasoundVolumeSweep* s) { s->SetSweepAxis(3); } },
    { "protocol 7", [](vtkUltrasoundVolumeSweep* s) { s->SetProtocol(7); } },
    { "negative pixel spacing", [](vtkUltrasoundVolumeSweep* s) { s->SetPixelSpacing(-1); } },
    { "tiny pixel spacing", [](vtkUltrasoundVolumeSweep* s) { s->SetPixelSpacing(1e-6); } },
    { "float output only", [](vtkUltrasoundVolumeSweep* s) { s->SetOutputScalarType(VTK_SHORT); } },
  };
  for (const auto& setting : bad)
  {
    vtkNew<vtkUltrasoundVolumeSweep> sweep;
    sweep->SetInputData(volume);
    setting.second(sweep);
    std::vector<std::string> errors;
    EXPECT_FALSE(Update(sweep, &errors)) << setting.first;
    EXPECT_FALSE(errors.empty()) << setting.first;
    EXPECT_EQ(sweep->GetOutput()->GetNumberOfPoints(), 0) << setting.first;
  }
  // Not a 3D volume, no scalars.
  auto flat = vtkSmartPointer<vtkImageData>::New();
  flat->SetDimensions(10, 10, 1);
  flat->AllocateScalars(VTK_FLOAT, 1);
  auto bare = vtkSmartPointer<vtkImageData>::New();
  bare->SetDimensions(10, 10, 10);
  for (vtkImageData* input : { flat.Get(), bare.Get() })
  {
    vtkNew<vtkUltrasoundVolumeSweep> sweep;
    sweep->SetInputData(input);
    std::vector<std::string> errors;
    EXPECT_FALSE(Update(sweep, &errors));
    EXPECT_FALSE(errors.empty());
  }
  // A failed request does not poison the filter: a valid setting works again.
  vtkNew<vtkUltrasoundVolumeSweep> sweep;
  sweep->SetInputData(volume);
  sweep->SetNumberOfFrames(0);
  EXPECT_FALSE(Update(sweep));
  sweep->SetNumberOfFrames(4);
  EXPECT_TRUE(Update(sweep));
  EXPECT_EQ(sweep->GetOutput()->GetDimensions()[2], 4);
}
