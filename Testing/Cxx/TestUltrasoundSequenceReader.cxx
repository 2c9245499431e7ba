// vtkUltrasoundSequenceReader on the real sweeps, against independent truth: the PLUS volume
// reconstructions of the same sweeps (their grid is the bounding box of all frame corners) and the
// known pixel spacing of the liver sweep.
#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkMatrix4x4.h"
#include "vtkMetaImageReader.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundCalibration.h"
#include "vtkUltrasoundSequenceReader.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

using bigus_test::DataPath;
using bigus_test::ExamplePath;
using bigus_test::Pose;

namespace
{
struct Box
{
  double Min[3] = { std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
    std::numeric_limits<double>::max() };
  double Max[3] = { -std::numeric_limits<double>::max(), -std::numeric_limits<double>::max(),
    -std::numeric_limits<double>::max() };
};

/// Bounding box (mm) of the corners of every valid frame, with PLUS's clip convention: the clipped
/// pixel range is [max(0, origin), min(size - 1, origin + clipSize)] (vtkPlusVolumeReconstructor).
Box FrameCornerBox(vtkImageData* sequence, const int clipOrigin[2], const int clipSize[2])
{
  int dims[3];
  sequence->GetDimensions(dims);
  const double x0 = std::max(0, clipOrigin[0]);
  const double y0 = std::max(0, clipOrigin[1]);
  const double x1 = std::min(dims[0] - 1, clipOrigin[0] + clipSize[0]);
  const double y1 = std::min(dims[1] - 1, clipOrigin[1] + clipSize[1]);
  vtkDataArray* valid = sequence->GetFieldData()->GetArray("FrameValid");
  Box box;
  for (int k = 0; k < dims[2]; ++k)
  {
    if (valid->GetTuple1(k) == 0)
    {
      continue;
    }
    const auto m = Pose(sequence, k);
    for (double x : { x0, x1 })
    {
      for (double y : { y0, y1 })
      {
        for (int c = 0; c < 3; ++c)
        {
          const double p = m[4 * c] * x + m[4 * c + 1] * y + m[4 * c + 3];
          box.Min[c] = std::min(box.Min[c], p);
          box.Max[c] = std::max(box.Max[c], p);
        }
      }
    }
  }
  return box;
}

/// The reconstruction grid must start at the box's lower corner and span it: PLUS sets
/// extent = int((max - min) / spacing) (vtkPlusVolumeReconstructor::SetOutputExtentFromFrameList).
void ExpectBoxMatchesReconstruction(const Box& box, const std::string& reconstruction, double originTolerance)
{
  vtkNew<vtkMetaImageReader> truth;
  truth->SetFileName(reconstruction.c_str());
  truth->UpdateInformation();
  double origin[3], spacing[3];
  int extent[6];
  truth->GetDataOrigin(origin);
  truth->GetDataSpacing(spacing);
  truth->GetDataExtent(extent);
  for (int c = 0; c < 3; ++c)
  {
    EXPECT_NEAR(box.Min[c], origin[c], originTolerance) << "axis " << c;
    EXPECT_EQ(static_cast<int>((box.Max[c] - box.Min[c]) / spacing[c]), extent[2 * c + 1] - extent[2 * c])
      << "axis " << c << ": box size " << box.Max[c] - box.Min[c] << " mm";
  }
}

vtkSmartPointer<vtkUltrasoundSequenceReader> Reader(const std::string& file, const std::string& xml = "")
{
  auto reader = vtkSmartPointer<vtkUltrasoundSequenceReader>::New();
  reader->SetFileName(file.c_str());
  if (!xml.empty())
  {
    reader->SetCalibrationFileName(xml.c_str());
  }
  return reader;
}
}

TEST(SequenceReader, SpinePhantomCornersMatchPlusReconstructionGrid)
{
  const std::string xml = DataPath("spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml");
  auto reader = Reader(DataPath("spine-phantom/SpinePhantomFreehand.igs.mha"), xml);
  reader->Update();
  ASSERT_STREQ(reader->GetLastErrorText(), "");
  vtkImageData* out = reader->GetOutput();
  int dims[3];
  out->GetDimensions(dims);
  EXPECT_EQ(dims[0], 820);
  EXPECT_EQ(dims[1], 616);
  EXPECT_EQ(dims[2], 21);
  EXPECT_STREQ(reader->GetTransformChainInUse(), "inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe");
  vtkNew<vtkUltrasoundCalibration> calibration;
  calibration->SetFileName(xml.c_str());
  ASSERT_TRUE(calibration->Parse()) << calibration->GetErrorText();
  const Box box = FrameCornerBox(out, calibration->GetClipRectangleOrigin(), calibration->GetClipRectangleSize());
  // The reference header prints the origin with 6 significant digits: 1e-3 mm is its precision.
  ExpectBoxMatchesReconstruction(box, DataPath("spine-phantom/SpinePhantomFreehandReconstructed.mha"), 1e-3);
}

TEST(SequenceReader, NwirePhantomCornersMatchPlusReconstructionGrid)
{
  const std::string xml = DataPath("nwire-phantom/PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml");
  auto reader = Reader(DataPath("nwire-phantom/NwirePhantomFreehand.igs.mha"), xml);
  reader->Update();
  ASSERT_STREQ(reader->GetLastErrorText(), "");
  vtkImageData* out = reader->GetOutput();
  EXPECT_EQ(out->GetDimensions()[2], 97);
  vtkNew<vtkUltrasoundCalibration> calibration;
  calibration->SetFileName(xml.c_str());
  ASSERT_TRUE(calibration->Parse()) << calibration->GetErrorText();
  ASSERT_TRUE(calibration->GetHasClipRectangle());
  const Box box = FrameCornerBox(out, calibration->GetClipRectangleOrigin(), calibration->GetClipRectangleSize());
  ExpectBoxMatchesReconstruction(box, DataPath("nwire-phantom/NwirePhantomFreehandReconstructed.mha"), 1e-3);
}

TEST(SequenceReader, LiverSweepHasItsPixelSpacingAndOrthonormalRotations)
{
  auto reader = Reader(ExamplePath("liver/liver_sweep.igs.mha"));
  reader->Update();
  ASSERT_STREQ(reader->GetLastErrorText(), "");
  vtkImageData* out = reader->GetOutput();
  int dims[3];
  out->GetDimensions(dims);
  EXPECT_EQ(dims[0], 739);
  EXPECT_EQ(dims[1], 593);
  EXPECT_EQ(dims[2], 140);
  EXPECT_EQ(out->GetScalarType(), VTK_UNSIGNED_CHAR);
  EXPECT_STREQ(reader->GetTransformChainInUse(), "ImageToReference");
  for (int k = 0; k < dims[2]; ++k)
  {
    const auto m = Pose(out, k);
    double norms[3];
    for (int c = 0; c < 3; ++c)
    {
      norms[c] = std::sqrt(m[c] * m[c] + m[4 + c] * m[4 + c] + m[8 + c] * m[8 + c]);
      EXPECT_NEAR(norms[c], 0.3148, 5e-5) << "frame " << k << " column " << c;
    }
    for (int a = 0; a < 3; ++a)
    {
      for (int b = 0; b < 3; ++b)
      {
        double dot = 0;
        for (int r = 0; r < 3; ++r)
        {
          dot += m[4 * r + a] * m[4 * r + b] / (norms[a] * norms[b]);
        }
        EXPECT_NEAR(dot, a == b ? 1.0 : 0.0, 1e-6) << "frame " << k << " columns " << a << ", " << b;
      }
    }
    EXPECT_EQ(out->GetFieldData()->GetArray("FrameValid")->GetTuple1(k), 1);
  }
  // Timestamps of a 23 fps sweep increase.
  vtkDataArray* stamps = out->GetFieldData()->GetArray("Timestamp");
  for (int k = 1; k < dims[2]; ++k)
  {
    EXPECT_GT(stamps->GetTuple1(k), stamps->GetTuple1(k - 1));
  }
}

TEST(SequenceReader, ExplicitChainAndStaticMatrixEqualTheAutomaticChain)
{
  const std::string file = DataPath("spine-phantom/SpinePhantomFreehand.igs.mha");
  const std::string xml = DataPath("spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml");
  auto automatic = Reader(file, xml);
  automatic->Update();

  // ImageToProbe given as a matrix instead of the XML, chain written with the other syntaxes.
  vtkNew<vtkUltrasoundCalibration> calibration;
  calibration->SetFileName(xml.c_str());
  ASSERT_TRUE(calibration->Parse());
  vtkNew<vtkMatrix4x4> imageToProbe;
  ASSERT_TRUE(calibration->GetTransform("Image", "Probe", imageToProbe));
  auto manual = Reader(file);
  manual->SetStaticTransform("ImageToProbe", imageToProbe);
  manual->SetTransformChain("ReferenceToTrackerTransform^-1 * ProbeToTracker * ImageToProbe");
  manual->Update();
  ASSERT_STREQ(manual->GetLastErrorText(), "");

  // Independent composition with vtkMatrix4x4 from the raw per-frame fields of frame 7.
  vtkImageData* a = automatic->GetOutput();
  vtkImageData* b = manual->GetOutput();
  for (int k = 0; k < 21; ++k)
  {
    EXPECT_EQ(Pose(a, k), Pose(b, k)) << "frame " << k;
  }
  const double probeToTracker[16] = { 0.229438, 0.950472, -0.209668, 174.425, -0.126821, -0.184385, -0.974638, -94.5085,
    -0.965026, 0.250209, 0.0782352, -21.6545, 0, 0, 0, 1 };
  const double referenceToTracker[16] = { 0.949522, -0.20838, 0.234489, 264.207, -0.195712, -0.977687, -0.0763249,
    93.8733, 0.245161, 0.0265799, -0.969118, 3.12539, 0, 0, 0, 1 };
  vtkNew<vtkMatrix4x4> trackerToReference, expected;
  vtkMatrix4x4::Invert(referenceToTracker, trackerToReference->GetData());
  vtkMatrix4x4::Multiply4x4(trackerToReference->GetData(), probeToTracker, expected->GetData());
  vtkMatrix4x4::Multiply4x4(expected, imageToProbe, expected);
  const auto frame3 = Pose(a, 3); // the values above are those of Seq_Frame0003
  for (int e = 0; e < 16; ++e)
  {
    EXPECT_NEAR(frame3[e], expected->GetData()[e], 1e-9) << "element " << e;
  }
}

TEST(SequenceReader, FrameRangeReadsTheSameFramesAndPoses)
{
  const std::string file = DataPath("spine-phantom/SpinePhantomFreehand.igs.mha");
  const std::string xml = DataPath("spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml");
  auto all = Reader(file, xml);
  all->Update();
  auto part = Reader(file, xml);
  part->SetFrameRange(5, 9);
  part->Update();
  ASSERT_STREQ(part->GetLastErrorText(), "");
  vtkImageData* a = all->GetOutput();
  vtkImageData* p = part->GetOutput();
  EXPECT_EQ(p->GetDimensions()[2], 5);
  EXPECT_EQ(part->GetNumberOfFramesInFile(), 21);
  const vtkIdType frame = 820 * 616;
  auto* pa = static_cast<unsigned char*>(a->GetScalarPointer());
  auto* pp = static_cast<unsigned char*>(p->GetScalarPointer());
  for (int k = 0; k < 5; ++k)
  {
    EXPECT_TRUE(std::equal(pp + k * frame, pp + (k + 1) * frame, pa + (k + 5) * frame)) << "frame " << k + 5;
    EXPECT_EQ(Pose(p, k), Pose(a, k + 5));
    EXPECT_EQ(p->GetFieldData()->GetArray("FrameIndex")->GetTuple1(k), k + 5);
  }
}

TEST(SequenceReader, LiverAlternativePoseDiffersByAConstantCalibrationRotation)
{
  // The liver file also carries ImageToReferenceFromTracking, which (per the data README) differs by
  // a near-constant rotation of about 14 degrees on the calibration side.
  auto direct = Reader(ExamplePath("liver/liver_sweep.igs.mha"));
  direct->Update();
  auto tracking = Reader(ExamplePath("liver/liver_sweep.igs.mha"));
  tracking->SetTransformChain("ImageToReferenceFromTracking");
  tracking->Update();
  ASSERT_STREQ(tracking->GetLastErrorText(), "");
  for (int k : { 0, 70, 139 })
  {
    const auto a = Pose(direct->GetOutput(), k);
    const auto b = Pose(tracking->GetOutput(), k);
    // Angle between the two rotations: cos = (trace(Ra^T Rb) - 1) / 2 with unit columns.
    double trace = 0;
    for (int c = 0; c < 3; ++c)
    {
      double na = 0, nb = 0, dot = 0;
      for (int r = 0; r < 3; ++r)
      {
        na += a[4 * r + c] * a[4 * r + c];
        nb += b[4 * r + c] * b[4 * r + c];
        dot += a[4 * r + c] * b[4 * r + c];
      }
      trace += dot / std::sqrt(na * nb);
    }
    const double degrees = std::acos(std::max(-1.0, std::min(1.0, (trace - 1) / 2))) * 180 / M_PI;
    EXPECT_NEAR(degrees, 14, 3) << "frame " << k;
  }
}
