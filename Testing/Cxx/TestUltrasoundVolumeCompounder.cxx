// vtkUltrasoundVolumeCompounder against PLUS's own reconstructions of the spine-phantom sweep, against
// synthetic sweeps whose every pixel is a known function of its mm position, and on bad inputs.
#include "bigusTestUtilities.h"

#include "vtkCallbackCommand.h"
#include "vtkCommand.h"
#include "vtkExecutive.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkMetaImageReader.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkUltrasoundCalibration.h"
#include "vtkUltrasoundSequenceReader.h"
#include "vtkUltrasoundVolumeCompounder.h"
#include "vtkUnsignedIntArray.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

using bigus_test::DataPath;
using bigus_test::MessageCollector;
using bigus_test::Pose;

namespace
{
using Matrix = std::array<double, 16>;

/// Row-major pixel-to-mm pose: rotation about the unit axis (ax, ay, az) by angle (degrees), pixel
/// spacing s (mm) on both image axes, then translation t (mm).
Matrix MakePose(double ax, double ay, double az, double degrees, double s, double tx, double ty, double tz)
{
  const double n = std::sqrt(ax * ax + ay * ay + az * az);
  ax /= n;
  ay /= n;
  az /= n;
  const double a = degrees * M_PI / 180, c = std::cos(a), si = std::sin(a), C = 1 - c;
  const double R[3][3] = { { c + ax * ax * C, ax * ay * C - az * si, ax * az * C + ay * si },
    { ay * ax * C + az * si, c + ay * ay * C, ay * az * C - ax * si },
    { az * ax * C - ay * si, az * ay * C + ax * si, c + az * az * C } };
  const double t[3] = { tx, ty, tz };
  Matrix m{};
  for (int r = 0; r < 3; ++r)
  {
    m[4 * r] = R[r][0] * s;
    m[4 * r + 1] = R[r][1] * s;
    m[4 * r + 2] = R[r][2];
    m[4 * r + 3] = t[r];
  }
  m[15] = 1;
  return m;
}

std::array<double, 3> PixelToMm(const Matrix& m, double i, double j)
{
  return { m[0] * i + m[1] * j + m[3], m[4] * i + m[5] * j + m[7], m[8] * i + m[9] * j + m[11] };
}

/// A tracked sequence of W x H float frames 0.05 s apart: pixel (i, j) of frame k has
/// value(k, mm position of the pixel).
vtkSmartPointer<vtkImageData> Sequence(
  int w, int h, const std::vector<Matrix>& poses, const std::function<float(int, const std::array<double, 3>&)>& value)
{
  std::vector<double> times;
  for (std::size_t k = 0; k < poses.size(); ++k)
  {
    times.push_back(0.05 * k);
  }
  return bigus_test::TrackedSequence(
    w, h, poses, times, [&](int k, int i, int j) { return value(k, PixelToMm(poses[k], i, j)); });
}

const float* Values(vtkImageData* volume)
{
  return vtkFloatArray::SafeDownCast(volume->GetPointData()->GetArray("Intensity"))->GetPointer(0);
}

const unsigned int* Counts(vtkImageData* volume)
{
  return vtkUnsignedIntArray::SafeDownCast(volume->GetPointData()->GetArray("InsertedPixelCount"))->GetPointer(0);
}

double Pearson(const std::vector<double>& a, const std::vector<double>& b)
{
  const double n = static_cast<double>(a.size());
  double ma = 0, mb = 0;
  for (std::size_t k = 0; k < a.size(); ++k)
  {
    ma += a[k] / n;
    mb += b[k] / n;
  }
  double ab = 0, aa = 0, bb = 0;
  for (std::size_t k = 0; k < a.size(); ++k)
  {
    ab += (a[k] - ma) * (b[k] - mb);
    aa += (a[k] - ma) * (a[k] - ma);
    bb += (b[k] - mb) * (b[k] - mb);
  }
  return ab / std::sqrt(aa * bb);
}

// ---- The spine phantom and PLUS's reconstructions of it ----

const char* NearestMeanXml = "spine-phantom/PlusDeviceSet_VolumeReconstructionOnly_SpinePhantom_NN_MEAN.xml";

/// The spine-phantom sweep as PLUS reconstructs it (read once).
vtkImageData* SpineSweep()
{
  static vtkSmartPointer<vtkImageData> frames;
  if (!frames)
  {
    vtkNew<vtkUltrasoundSequenceReader> reader;
    reader->SetFileName(DataPath("spine-phantom/SpinePhantomFreehand.igs.mha").c_str());
    reader->SetCalibrationFileName(DataPath(NearestMeanXml).c_str());
    reader->Update();
    EXPECT_STREQ(reader->GetLastErrorText(), "");
    frames = reader->GetOutput();
  }
  return frames;
}

/// The compounder set up as the NN / MEAN PLUS configuration says: 0.5 mm, clip rectangle 820 x 616.
vtkSmartPointer<vtkUltrasoundVolumeCompounder> SpineCompounder(bool fillHoles)
{
  vtkNew<vtkUltrasoundCalibration> calibration;
  calibration->SetFileName(DataPath(NearestMeanXml).c_str());
  EXPECT_TRUE(calibration->Parse()) << calibration->GetErrorText();
  EXPECT_TRUE(calibration->GetHasClipRectangle());
  auto compounder = vtkSmartPointer<vtkUltrasoundVolumeCompounder>::New();
  compounder->SetInputData(SpineSweep());
  compounder->SetOutputSpacing(0.5, 0.5, 0.5);
  compounder->SetClipRectangleOrigin(calibration->GetClipRectangleOrigin());
  compounder->SetClipRectangleSize(calibration->GetClipRectangleSize());
  compounder->SetCompoundingModeToMean();
  compounder->SetFillHoles(fillHoles);
  const auto start = std::chrono::steady_clock::now();
  compounder->Update();
  std::cout << "[ measured ] spine phantom, 21 frames, 0.5 mm, hole filling " << (fillHoles ? "on" : "off") << ": "
            << std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() << " s (insertion "
            << compounder->GetInsertionSeconds() << " s, hole filling " << compounder->GetHoleFillingSeconds()
            << " s)\n";
  return compounder;
}

vtkSmartPointer<vtkImageData> ReadReference(const std::string& name)
{
  vtkNew<vtkMetaImageReader> reader;
  reader->SetFileName(DataPath("spine-phantom/" + name).c_str());
  reader->Update();
  vtkSmartPointer<vtkImageData> image = reader->GetOutput();
  EXPECT_EQ(image->GetScalarType(), VTK_UNSIGNED_CHAR);
  return image;
}

/// Voxel-wise comparison with a PLUS reconstruction on our grid (the reference may have more slices).
struct Agreement
{
  double Correlation = 0;   // Pearson over the voxels non-zero in both
  double FilledOrEmpty = 0; // fraction of voxels that agree on non-zero / zero
  vtkIdType BothNonZero = 0;
};

Agreement Compare(vtkImageData* ours, vtkImageData* reference)
{
  int dims[3], refDims[3];
  ours->GetDimensions(dims);
  reference->GetDimensions(refDims);
  EXPECT_EQ(dims[0], refDims[0]);
  EXPECT_EQ(dims[1], refDims[1]);
  EXPECT_LE(dims[2], refDims[2]);
  const float* v = Values(ours);
  const auto* r = static_cast<const unsigned char*>(reference->GetScalarPointer());
  std::vector<double> a, b;
  vtkIdType agree = 0;
  const vtkIdType voxels = vtkIdType(dims[0]) * dims[1] * dims[2];
  for (vtkIdType p = 0; p < voxels; ++p)
  {
    agree += (v[p] != 0) == (r[p] != 0);
    if (v[p] != 0 && r[p] != 0)
    {
      a.push_back(v[p]);
      b.push_back(r[p]);
    }
  }
  Agreement result;
  result.Correlation = Pearson(a, b);
  result.FilledOrEmpty = double(agree) / voxels;
  result.BothNonZero = static_cast<vtkIdType>(a.size());
  return result;
}
}

TEST(VolumeCompounder, SpinePhantomGridIsPlusGrid)
{
  auto compounder = SpineCompounder(true);
  vtkImageData* volume = compounder->GetOutput();
  double origin[3], spacing[3];
  int extent[6];
  volume->GetOrigin(origin);
  volume->GetSpacing(spacing);
  volume->GetExtent(extent);
  // SpinePhantomFreehandReconstructed.mha: PLUS's grid, extent = int(size / spacing). Its header
  // prints the origin with 6 significant digits: 1e-3 mm is its precision.
  vtkSmartPointer<vtkImageData> plus = ReadReference("SpinePhantomFreehandReconstructed.mha");
  for (int c = 0; c < 3; ++c)
  {
    EXPECT_NEAR(origin[c], plus->GetOrigin()[c], 1e-3) << "axis " << c;
    EXPECT_EQ(spacing[c], plus->GetSpacing()[c]);
    EXPECT_EQ(extent[2 * c], plus->GetExtent()[2 * c]) << "axis " << c;
    EXPECT_EQ(extent[2 * c + 1], plus->GetExtent()[2 * c + 1]) << "axis " << c;
  }
  // vtkVolumeReconstructorTestNNMEANvolumeRef.mha (PLUS's own test of this NN / MEAN configuration)
  // has the same origin and the same x and y extents, and one more z slice, which is empty: the box is
  // 103.85 voxels high, which that PLUS version rounded up (recent PLUS uses ceil on every axis, which
  // would also add an x and a y column; int() as above gives neither).
  vtkSmartPointer<vtkImageData> nearest = ReadReference("vtkVolumeReconstructorTestNNMEANvolumeRef.mha");
  int nearestDims[3];
  nearest->GetDimensions(nearestDims);
  for (int c = 0; c < 3; ++c)
  {
    EXPECT_NEAR(origin[c], nearest->GetOrigin()[c], 1e-3) << "axis " << c;
  }
  EXPECT_EQ(nearestDims[0], extent[1] + 1);
  EXPECT_EQ(nearestDims[1], extent[3] + 1);
  ASSERT_EQ(nearestDims[2], extent[5] + 2);
  const auto* last = static_cast<const unsigned char*>(nearest->GetScalarPointer()) +
    std::size_t(nearestDims[0]) * nearestDims[1] * (nearestDims[2] - 1);
  EXPECT_EQ(std::count(last, last + nearestDims[0] * nearestDims[1], 0), nearestDims[0] * nearestDims[1]);
  EXPECT_EQ(compounder->GetNumberOfInsertedFrames(), 21);
}

TEST(VolumeCompounder, SpinePhantomMatchesPlusNearestNeighbourMeanReconstruction)
{
  auto compounder = SpineCompounder(true);
  vtkImageData* volume = compounder->GetOutput();
  // PLUS's NN / MEAN reconstruction of this sweep, hole filled with STICK (length 9 voxels); ours
  // fills holes with the Gaussian kernels. Measured: correlation 0.9920 over the 404026 voxels
  // non-zero in both; 94.05 % of the 1620528 voxels agree on non-zero / zero (we fill 497674 voxels
  // non-zero, PLUS 406763: the Gaussian cubes fill some gaps that a 9-voxel stick does not span, and
  // one voxel beyond the outermost frames).
  const Agreement nearest = Compare(volume, ReadReference("vtkVolumeReconstructorTestNNMEANvolumeRef.mha"));
  std::cout << "[ measured ] vs PLUS NN/MEAN/STICK: correlation " << nearest.Correlation << " over "
            << nearest.BothNonZero << " voxels, filled/empty agreement " << nearest.FilledOrEmpty << "\n";
  EXPECT_GT(nearest.Correlation, 0.985);
  EXPECT_GT(nearest.FilledOrEmpty, 0.93);
  // SpinePhantomFreehandReconstructed.mha: PLUS with its LINEAR (trilinear splatting) configuration
  // (PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml). Measured: correlation 0.9898 over
  // 462902 voxels, 97.37 % agreement on non-zero / zero.
  const Agreement linear = Compare(volume, ReadReference("SpinePhantomFreehandReconstructed.mha"));
  std::cout << "[ measured ] vs PLUS LINEAR/MEAN/STICK: correlation " << linear.Correlation << " over "
            << linear.BothNonZero << " voxels, filled/empty agreement " << linear.FilledOrEmpty << "\n";
  EXPECT_GT(linear.Correlation, 0.98);
  EXPECT_GT(linear.FilledOrEmpty, 0.96);
}

TEST(VolumeCompounder, SpinePhantomInsertedVoxelsMatchPlusWithoutHoleFilling)
{
  auto unfilled = SpineCompounder(false);
  auto filled = SpineCompounder(true);
  vtkImageData* volume = unfilled->GetOutput();
  vtkSmartPointer<vtkImageData> plus = ReadReference("vtkVolumeReconstructorTestNNMEANvolumeRef.mha");
  const float* v = Values(volume);
  const unsigned int* n = Counts(volume);
  const float* vf = Values(filled->GetOutput());
  const unsigned int* nf = Counts(filled->GetOutput());
  const auto* r = static_cast<const unsigned char*>(plus->GetScalarPointer());
  const vtkIdType voxels = volume->GetNumberOfPoints();
  ASSERT_EQ(voxels, filled->GetOutput()->GetNumberOfPoints());
  // The voxels that a pixel landed in are those PLUS has without filling (the same nearest-neighbour
  // insertion): compare there. Measured: correlation 0.9987 over the 362093 hit voxels, mean absolute
  // difference 2.45 grey levels. The difference is PLUS's arithmetic, not the geometry: PLUS keeps
  // its running mean in unsigned char and truncates at every insertion (about (count + 1) / 4 grey
  // levels low after count pixels); replaying our pixel-to-voxel assignment with that truncation
  // reproduces 89.7 % of the reference's hit voxels exactly (mean absolute difference 0.26).
  std::vector<double> a, b;
  double absolute = 0;
  for (vtkIdType p = 0; p < voxels; ++p)
  {
    // Hole filling only touches voxels without pixels.
    ASSERT_EQ(n[p], nf[p]);
    if (n[p] > 0)
    {
      ASSERT_EQ(v[p], vf[p]);
      a.push_back(v[p]);
      b.push_back(r[p]);
      absolute += std::abs(v[p] - r[p]);
    }
    else
    {
      ASSERT_EQ(v[p], 0.0f);
    }
  }
  ASSERT_EQ(vtkIdType(a.size()), unfilled->GetNumberOfHitVoxels());
  const double correlation = Pearson(a, b);
  absolute /= a.size();
  std::cout << "[ measured ] hit voxels vs PLUS NN/MEAN: correlation " << correlation << " over " << a.size()
            << " voxels, mean absolute difference " << absolute << "\n";
  EXPECT_GT(correlation, 0.995);
  EXPECT_LT(absolute, 3.5);
  // PLUS's grid ends at int((max - min) / spacing): the pixels within the last half voxel below the
  // box's upper faces fall outside (measured: 260 of 10607520).
  EXPECT_GT(unfilled->GetNumberOfInsertedPixels(), vtkIdType(820) * 616 * 21 - 1000);
  EXPECT_EQ(unfilled->GetNumberOfFilledVoxels(), 0);
  EXPECT_GT(filled->GetNumberOfFilledVoxels(), 0);
}

// ---- Known geometry ----

TEST(VolumeCompounder, LinearFieldIsReproducedWithinHalfAVoxelGradient)
{
  // Every pixel holds f(x, y, z) = 3 + 0.7 x - 0.4 y + 1.1 z at its mm position; five crossing frames.
  const double g[3] = { 0.7, -0.4, 1.1 };
  auto f = [&](const std::array<double, 3>& p) { return 3 + g[0] * p[0] + g[1] * p[1] + g[2] * p[2]; };
  const std::vector<Matrix> poses = { MakePose(1, 0, 0, 90, 0.3, 0, 0, 0), MakePose(1, 0.2, 0, 70, 0.3, 1.5, -2, 1),
    MakePose(0, 1, 0, 40, 0.3, -3, 2, 4), MakePose(1, 1, 1, 100, 0.3, 2, 1, -1),
    MakePose(0, 0, 1, 15, 0.3, -1, -4, 3) };
  auto sweep = Sequence(60, 50, poses, [&](int, const std::array<double, 3>& p) { return float(f(p)); });
  vtkNew<vtkUltrasoundVolumeCompounder> compounder;
  compounder->SetInputData(sweep);
  compounder->FillHolesOff();
  compounder->Update();
  vtkImageData* volume = compounder->GetOutput();
  ASSERT_GT(volume->GetNumberOfPoints(), 0);

  // The automatic grid is the box of the frame corners: origin at its lower corner, int(size / 0.5).
  double lo[3] = { 1e9, 1e9, 1e9 }, hi[3] = { -1e9, -1e9, -1e9 };
  for (const Matrix& m : poses)
  {
    for (double i : { 0.0, 59.0 })
    {
      for (double j : { 0.0, 49.0 })
      {
        const auto p = PixelToMm(m, i, j);
        for (int c = 0; c < 3; ++c)
        {
          lo[c] = std::min(lo[c], p[c]);
          hi[c] = std::max(hi[c], p[c]);
        }
      }
    }
  }
  int extent[6];
  volume->GetExtent(extent);
  for (int c = 0; c < 3; ++c)
  {
    EXPECT_DOUBLE_EQ(volume->GetOrigin()[c], lo[c]);
    EXPECT_EQ(extent[2 * c], 0);
    EXPECT_EQ(extent[2 * c + 1], static_cast<int>((hi[c] - lo[c]) / 0.5));
  }

  // At a hit voxel every pixel lies within half a voxel of the centre on each axis, so the mean is
  // within sum |g_c| * 0.25 mm of f(centre).
  const double bound = (std::abs(g[0]) + std::abs(g[1]) + std::abs(g[2])) * 0.25 + 1e-4;
  const float* v = Values(volume);
  const unsigned int* n = Counts(volume);
  int dims[3];
  volume->GetDimensions(dims);
  vtkIdType hit = 0;
  double worst = 0;
  for (int k = 0; k < dims[2]; ++k)
  {
    for (int j = 0; j < dims[1]; ++j)
    {
      for (int i = 0; i < dims[0]; ++i)
      {
        const vtkIdType p = i + dims[0] * (j + vtkIdType(dims[1]) * k);
        if (n[p] == 0)
        {
          EXPECT_EQ(v[p], 0.0f);
          continue;
        }
        ++hit;
        const std::array<double, 3> centre = { lo[0] + 0.5 * i, lo[1] + 0.5 * j, lo[2] + 0.5 * k };
        worst = std::max(worst, std::abs(v[p] - f(centre)));
      }
    }
  }
  EXPECT_LE(worst, bound);
  EXPECT_EQ(hit, compounder->GetNumberOfHitVoxels());
  EXPECT_GT(hit, 5 * 1000); // five frames of 36 x 30 voxels, some shared

  // The pixels that land: those whose nearest voxel centre lies in the grid (the pixels within the
  // last half voxel below the box's upper faces do not, as in PLUS).
  vtkIdType landing = 0;
  for (const Matrix& m : poses)
  {
    for (int j = 0; j < 50; ++j)
    {
      for (int i = 0; i < 60; ++i)
      {
        const auto p = PixelToMm(m, i, j);
        bool inside = true;
        for (int c = 0; c < 3; ++c)
        {
          const double index = std::floor((p[c] - lo[c]) / 0.5 + 0.5);
          inside = inside && index >= 0 && index <= extent[2 * c + 1];
        }
        landing += inside;
      }
    }
  }
  EXPECT_EQ(compounder->GetNumberOfInsertedPixels(), landing);
  EXPECT_GT(landing, 5 * 60 * 50 - 100);
}

namespace
{
/// Two frames at the same pose, constants 10 (frame 0) and 30 (frame 1), 20 x 16 pixels of 0.2 mm.
vtkSmartPointer<vtkImageData> TwoConstantFrames()
{
  const Matrix pose = MakePose(0.3, 1, 0.2, 35, 0.2, 5, -3, 2);
  return Sequence(20, 16, { pose, pose }, [](int k, const std::array<double, 3>&) { return k == 0 ? 10.0f : 30.0f; });
}

/// The values of the hit voxels after compounding with the given setup; counts their pixels too.
std::vector<float> HitValues(
  vtkImageData* sweep, const std::function<void(vtkUltrasoundVolumeCompounder*)>& setup, vtkIdType* pixels = nullptr)
{
  vtkNew<vtkUltrasoundVolumeCompounder> compounder;
  compounder->SetInputData(sweep);
  compounder->FillHolesOff();
  // A grid with a margin around the frames, so that every pixel lands.
  compounder->SetOutputOrigin(-2, -10, -5);
  compounder->SetOutputExtent(0, 28, 0, 28, 0, 28);
  setup(compounder);
  compounder->Update();
  if (pixels)
  {
    *pixels = compounder->GetNumberOfInsertedPixels();
  }
  std::vector<float> values;
  vtkImageData* volume = compounder->GetOutput();
  const float* v = Values(volume);
  const unsigned int* n = Counts(volume);
  for (vtkIdType p = 0; p < volume->GetNumberOfPoints(); ++p)
  {
    if (n[p] > 0)
    {
      values.push_back(v[p]);
    }
  }
  return values;
}

void ExpectAll(const std::vector<float>& values, float expected)
{
  ASSERT_FALSE(values.empty());
  for (float v : values)
  {
    ASSERT_EQ(v, expected);
  }
}
}

TEST(VolumeCompounder, CompoundingModesOfTwoFramesAtOnePose)
{
  auto sweep = TwoConstantFrames();
  vtkIdType pixels = 0;
  ExpectAll(HitValues(
              sweep, [](vtkUltrasoundVolumeCompounder*) {}, &pixels),
    20.0f); // MEAN, exact
  EXPECT_EQ(pixels, 2 * 20 * 16);
  ExpectAll(HitValues(sweep, [](vtkUltrasoundVolumeCompounder* c) { c->SetCompoundingModeToMaximum(); }), 30.0f);
  ExpectAll(HitValues(sweep, [](vtkUltrasoundVolumeCompounder* c) { c->SetCompoundingModeToLatest(); }), 30.0f);
  // LATEST follows the frame list's order.
  ExpectAll(HitValues(sweep,
              [](vtkUltrasoundVolumeCompounder* c) {
                vtkNew<vtkIdList> frames;
                frames->InsertNextId(1);
                frames->InsertNextId(0);
                c->SetFrameList(frames);
                c->SetCompoundingModeToLatest();
              }),
    10.0f);
}

TEST(VolumeCompounder, FrameListMasksAndFrameValidKeepFramesOut)
{
  auto sweep = TwoConstantFrames();
  // Hold-out: only frame 0 is inserted.
  ExpectAll(HitValues(sweep,
              [](vtkUltrasoundVolumeCompounder* c) {
                vtkNew<vtkIdList> frames;
                frames->InsertNextId(0);
                c->SetFrameList(frames);
              }),
    10.0f);

  // A per-frame mask (W x H x N) that hides every pixel of frame 1.
  vtkNew<vtkImageData> perFrame;
  perFrame->SetDimensions(20, 16, 2);
  perFrame->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  auto* m = static_cast<unsigned char*>(perFrame->GetScalarPointer());
  std::fill(m, m + 20 * 16, 1);
  std::fill(m + 20 * 16, m + 2 * 20 * 16, 0);
  vtkIdType pixels = 0;
  ExpectAll(HitValues(
              sweep, [&](vtkUltrasoundVolumeCompounder* c) { c->SetFanMaskData(perFrame); }, &pixels),
    10.0f);
  EXPECT_EQ(pixels, 20 * 16);

  // One mask for every frame (W x H x 1): the left half of the image only.
  vtkNew<vtkImageData> shared;
  shared->SetDimensions(20, 16, 1);
  shared->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  auto* s = static_cast<unsigned char*>(shared->GetScalarPointer());
  for (int p = 0; p < 20 * 16; ++p)
  {
    s[p] = (p % 20) < 10 ? 255 : 0;
  }
  ExpectAll(HitValues(
              sweep, [&](vtkUltrasoundVolumeCompounder* c) { c->SetFanMaskData(shared); }, &pixels),
    20.0f);
  EXPECT_EQ(pixels, 2 * 10 * 16);

  // The clip rectangle, PLUS's convention: origin + size is included (columns 2..6, rows 3..8).
  HitValues(
    sweep,
    [](vtkUltrasoundVolumeCompounder* c) {
      c->SetClipRectangleOrigin(2, 3);
      c->SetClipRectangleSize(4, 5);
    },
    &pixels);
  EXPECT_EQ(pixels, 2 * 5 * 6);

  // FrameValid = 0: skipped with a warning.
  auto invalid = TwoConstantFrames();
  vtkDataArray::SafeDownCast(invalid->GetFieldData()->GetArray("FrameValid"))->SetTuple1(1, 0);
  vtkNew<MessageCollector> messages;
  ExpectAll(HitValues(invalid, [&](vtkUltrasoundVolumeCompounder* c) { messages->Watch(c); }), 10.0f);
  EXPECT_EQ(messages->Warnings.size(), 1u);
  EXPECT_TRUE(messages->Errors.empty());
}

TEST(VolumeCompounder, GaussianHoleFillingBridgesAGapAndBarelyGrowsTheSweep)
{
  // Two parallel frames of 0.25 mm pixels at z = 0 (value 10) and z = 1 mm (value 30): at 0.5 mm the
  // voxel slice z = 0.5 has no pixel. The grid is set to run from z = -1.5 to 3 mm.
  const Matrix a = MakePose(0, 0, 1, 0, 0.25, 0, 0, 0);
  Matrix b = a;
  b[11] = 1.0;
  auto sweep = Sequence(41, 41, { a, b }, [](int k, const std::array<double, 3>&) { return k == 0 ? 10.0f : 30.0f; });
  vtkNew<vtkUltrasoundVolumeCompounder> compounder;
  compounder->SetInputData(sweep);
  compounder->SetOutputOrigin(0, 0, 0);
  compounder->SetOutputExtent(-4, 24, -4, 24, -3, 6);
  compounder->Update();
  vtkImageData* volume = compounder->GetOutput();
  ASSERT_EQ(volume->GetNumberOfPoints(), 29 * 29 * 10);
  const float* v = Values(volume);
  const unsigned int* n = Counts(volume);
  auto at = [&](int i, int j, int k) { return (i + 4) + 29 * ((j + 4) + 29 * (k + 3)); };
  for (int j = 2; j <= 18; ++j)
  {
    for (int i = 2; i <= 18; ++i)
    {
      EXPECT_EQ(n[at(i, j, 0)], n[at(i, j, 2)]);
      EXPECT_GT(n[at(i, j, 0)], 0u);
      EXPECT_EQ(v[at(i, j, 0)], 10.0f);
      EXPECT_EQ(v[at(i, j, 2)], 30.0f);
      // The gap: symmetric neighbours, so the Gaussian-weighted mean is the plain mean.
      EXPECT_EQ(n[at(i, j, 1)], 0u);
      EXPECT_NEAR(v[at(i, j, 1)], 20.0f, 1e-4);
      // One voxel beyond each frame is filled (a 3^3 cube sees 9 / 27 > 0.25 inserted voxels)...
      EXPECT_NEAR(v[at(i, j, -1)], 10.0f, 1e-4);
      EXPECT_NEAR(v[at(i, j, 3)], 30.0f, 1e-4);
      // ... two voxels beyond is not (at most 1 / 5 of any cube).
      EXPECT_EQ(v[at(i, j, -2)], 0.0f);
      EXPECT_EQ(v[at(i, j, 4)], 0.0f);
    }
  }
  // Far from the frames in-plane nothing is filled either.
  EXPECT_EQ(v[at(-4, -4, 1)], 0.0f);
  EXPECT_EQ(compounder->GetNumberOfHitVoxels(), 2 * 21 * 21);

  compounder->FillHolesOff();
  compounder->Update();
  EXPECT_EQ(Values(compounder->GetOutput())[at(10, 10, 1)], 0.0f);
  EXPECT_EQ(compounder->GetNumberOfFilledVoxels(), 0);
}

TEST(VolumeCompounder, ExplicitOriginGetsAnExtentWhereEveryPixelLands)
{
  auto sweep = TwoConstantFrames();
  vtkNew<vtkUltrasoundVolumeCompounder> automatic;
  automatic->SetInputData(sweep);
  automatic->Update();
  double origin[3];
  automatic->GetOutput()->GetOrigin(origin);

  // The frames' box, as the class description defines the extent for an explicit origin.
  const Matrix pose = Pose(sweep, 0);
  double lo[3] = { 1e9, 1e9, 1e9 }, hi[3] = { -1e9, -1e9, -1e9 };
  for (double i : { 0.0, 19.0 })
  {
    for (double j : { 0.0, 15.0 })
    {
      const auto p = PixelToMm(pose, i, j);
      for (int c = 0; c < 3; ++c)
      {
        lo[c] = std::min(lo[c], p[c]);
        hi[c] = std::max(hi[c], p[c]);
      }
    }
  }
  const double chosen[3] = { origin[0] - 1.0, origin[1] + 1.5, origin[2] - 0.2 };
  vtkNew<vtkUltrasoundVolumeCompounder> shifted;
  shifted->SetInputData(sweep);
  shifted->SetOutputOrigin(chosen[0], chosen[1], chosen[2]);
  shifted->UpdateInformation();
  int info[6];
  shifted->GetOutputInformation(0)->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), info);
  shifted->Update();
  int got[6];
  shifted->GetOutput()->GetExtent(got);
  for (int c = 0; c < 3; ++c)
  {
    EXPECT_EQ(shifted->GetOutput()->GetOrigin()[c], chosen[c]);
    EXPECT_EQ(got[2 * c], static_cast<int>(std::floor((lo[c] - chosen[c]) / 0.5 + 0.5))) << "axis " << c;
    EXPECT_EQ(got[2 * c + 1], static_cast<int>(std::floor((hi[c] - chosen[c]) / 0.5 + 0.5))) << "axis " << c;
    EXPECT_EQ(info[2 * c], got[2 * c]);
    EXPECT_EQ(info[2 * c + 1], got[2 * c + 1]);
  }
  // The extent covers the frames: every pixel lands.
  EXPECT_EQ(shifted->GetNumberOfInsertedPixels(), 2 * 20 * 16);
  shifted->SetOutputOriginToDefault();
  shifted->Update();
  EXPECT_EQ(shifted->GetOutput()->GetOrigin()[0], origin[0]);
  EXPECT_EQ(shifted->GetOutput()->GetExtent()[0], 0);
}

TEST(VolumeCompounder, AbortStopsWithoutAVolume)
{
  vtkNew<vtkUltrasoundVolumeCompounder> compounder;
  compounder->SetInputData(TwoConstantFrames());
  vtkNew<vtkCallbackCommand> abort;
  abort->SetCallback(
    [](vtkObject* caller, unsigned long, void*, void*) { static_cast<vtkAlgorithm*>(caller)->AbortExecuteOn(); });
  compounder->AddObserver(vtkCommand::ProgressEvent, abort);
  vtkNew<MessageCollector> messages;
  messages->Watch(compounder->GetExecutive());
  compounder->Update();
  EXPECT_EQ(compounder->GetOutput()->GetNumberOfPoints(), 0);
}

// ---- Bad inputs ----

TEST(VolumeCompounder, BadInputsFailWithAnErrorAndNoVolume)
{
  struct Case
  {
    std::string Name;
    std::function<void(vtkImageData*, vtkUltrasoundVolumeCompounder*)> Break;
    std::string Expected; // part of the error text
  };
  const std::vector<Case> cases = {
    { "no ImageToReference",
      [](vtkImageData* s, vtkUltrasoundVolumeCompounder*) { s->GetFieldData()->RemoveArray("ImageToReference"); },
      "no ImageToReference" },
    { "one pose short",
      [](vtkImageData* s, vtkUltrasoundVolumeCompounder*) {
        s->GetFieldData()->GetArray("ImageToReference")->SetNumberOfTuples(1);
      },
      "must hold 2 tuples" },
    { "frame out of range",
      [](vtkImageData*, vtkUltrasoundVolumeCompounder* c) {
        vtkNew<vtkIdList> frames;
        frames->InsertNextId(0);
        frames->InsertNextId(2);
        c->SetFrameList(frames);
      },
      "frame 2 of the frame list is outside the 2 frames" },
    { "negative frame",
      [](vtkImageData*, vtkUltrasoundVolumeCompounder* c) {
        vtkNew<vtkIdList> frames;
        frames->InsertNextId(-1);
        c->SetFrameList(frames);
      },
      "outside" },
    { "singular pose",
      [](vtkImageData* s, vtkUltrasoundVolumeCompounder*) {
        double m[16];
        s->GetFieldData()->GetArray("ImageToReference")->GetTuple(1, m);
        m[0] = m[4] = m[8] = 0;
        s->GetFieldData()->GetArray("ImageToReference")->SetTuple(1, m);
      },
      "frame 1: ImageToReference has a singular" },
    { "parallel image axes",
      [](vtkImageData* s, vtkUltrasoundVolumeCompounder*) {
        double m[16];
        s->GetFieldData()->GetArray("ImageToReference")->GetTuple(0, m);
        m[1] = 2 * m[0];
        m[5] = 2 * m[4];
        m[9] = 2 * m[8];
        s->GetFieldData()->GetArray("ImageToReference")->SetTuple(0, m);
      },
      "singular" },
    { "NaN pose",
      [](vtkImageData* s, vtkUltrasoundVolumeCompounder*) {
        s->GetFieldData()->GetArray("ImageToReference")->SetComponent(0, 3, std::nan(""));
      },
      "non-finite" },
    { "projective pose",
      [](vtkImageData* s, vtkUltrasoundVolumeCompounder*) {
        s->GetFieldData()->GetArray("ImageToReference")->SetComponent(0, 12, 0.1);
      },
      "not affine" },
    { "every frame invalid",
      [](vtkImageData* s, vtkUltrasoundVolumeCompounder*) {
        s->GetFieldData()->GetArray("FrameValid")->SetTuple1(0, 0);
        s->GetFieldData()->GetArray("FrameValid")->SetTuple1(1, 0);
      },
      "no valid frame" },
    { "empty explicit grid",
      [](vtkImageData*, vtkUltrasoundVolumeCompounder* c) {
        c->SetOutputOrigin(0, 0, 0);
        c->SetOutputExtent(0, 10, 5, 4, 0, 10);
      },
      "empty" },
    { "grid over the voxel limit",
      [](vtkImageData*, vtkUltrasoundVolumeCompounder* c) { c->SetMaximumNumberOfVoxels(100); },
      "MaximumNumberOfVoxels = 100" },
    { "tiny spacing", [](vtkImageData*, vtkUltrasoundVolumeCompounder* c) { c->SetOutputSpacing(1e-4, 1e-4, 1e-4); },
      "MaximumNumberOfVoxels" },
    { "zero spacing", [](vtkImageData*, vtkUltrasoundVolumeCompounder* c) { c->SetOutputSpacing(0.5, 0, 0.5); },
      "OutputSpacing must be positive" },
    { "clip rectangle outside",
      [](vtkImageData*, vtkUltrasoundVolumeCompounder* c) {
        c->SetClipRectangleOrigin(100, 0);
        c->SetClipRectangleSize(10, 10);
      },
      "clip rectangle" },
    { "mask of the wrong size",
      [](vtkImageData*, vtkUltrasoundVolumeCompounder* c) {
        vtkNew<vtkImageData> mask;
        mask->SetDimensions(19, 16, 1);
        mask->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
        c->SetFanMaskData(mask);
      },
      "fan mask must be" },
    { "two-component frames",
      [](vtkImageData* s, vtkUltrasoundVolumeCompounder*) {
        vtkNew<vtkFloatArray> rgb;
        rgb->SetNumberOfComponents(2);
        rgb->SetNumberOfTuples(s->GetNumberOfPoints());
        s->GetPointData()->SetScalars(rgb);
      },
      "one-component" },
  };
  for (const Case& c : cases)
  {
    SCOPED_TRACE(c.Name);
    auto sweep = TwoConstantFrames();
    vtkNew<vtkUltrasoundVolumeCompounder> compounder;
    vtkNew<MessageCollector> messages, pipeline;
    messages->Watch(compounder);
    pipeline->Watch(compounder->GetExecutive());
    compounder->SetInputData(sweep);
    c.Break(sweep, compounder);
    compounder->Update();
    ASSERT_EQ(messages->Errors.size(), 1u);
    EXPECT_NE(messages->Errors[0].find(c.Expected), std::string::npos) << messages->Errors[0];
    EXPECT_EQ(compounder->GetOutput()->GetNumberOfPoints(), 0);
  }
}
