// vtkUltrasoundFanMask against a known fan geometry (synthetic sweep drawn from the same fan
// parameters that the calibration mode rasterises) and on the real sweeps.
#include "bigusTestUtilities.h"

#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundSequenceReader.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

using bigus_test::DataPath;
using bigus_test::ExamplePath;
using bigus_test::OutputPath;

namespace
{
constexpr int W = 200, H = 150, N = 6;
constexpr double ApexX = 100, ApexY = -20, MinAngle = -35, MaxAngle = 35, R0 = 40, R1 = 165;

bool InFan(double i, double j)
{
  const double dx = i - ApexX, dy = j - ApexY;
  const double r = std::sqrt(dx * dx + dy * dy);
  const double a = std::atan2(dx, dy) * 180 / M_PI;
  return a >= MinAngle && a <= MaxAngle && r >= R0 && r <= R1;
}

/// A sweep whose speckle fills the fan (with dark speckle and an anechoic vessel that is black in
/// every frame), plus an overlay mark outside the fan that must not enter the mask.
vtkSmartPointer<vtkImageData> SyntheticSweep()
{
  auto image = vtkSmartPointer<vtkImageData>::New();
  image->SetDimensions(W, H, N);
  image->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  auto* p = static_cast<unsigned char*>(image->GetScalarPointer());
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> speckle(0, 255);
  for (int k = 0; k < N; ++k)
  {
    for (int j = 0; j < H; ++j)
    {
      for (int i = 0; i < W; ++i)
      {
        const bool vessel = std::hypot(i - 100.0, j - 90.0) < 12;
        const bool overlay = i >= 5 && i < 9 && j >= 5 && j < 12;
        unsigned char v = 0;
        if (InFan(i, j) && !vessel)
        {
          v = static_cast<unsigned char>(k == 0 ? 1 + speckle(rng) % 255 : speckle(rng));
        }
        if (overlay)
        {
          v = 255;
        }
        p[(std::size_t(k) * H + j) * W + i] = v;
      }
    }
  }
  vtkNew<vtkDoubleArray> valid;
  valid->SetName("FrameValid");
  for (int k = 0; k < N; ++k)
  {
    valid->InsertNextValue(1);
  }
  image->GetFieldData()->AddArray(valid);
  return image;
}

unsigned char MaskAt(vtkImageData* mask, int i, int j)
{
  return static_cast<unsigned char*>(mask->GetScalarPointer())[j * mask->GetDimensions()[0] + i];
}
}

TEST(FanMask, CalibrationModeRasterisesTheFanExactly)
{
  const std::string xml = OutputPath("fan_mask.xml");
  std::ofstream(xml) << "<PlusConfiguration><VolumeReconstruction FanAnglesDeg=\"" << MinAngle << " " << MaxAngle
                     << "\" FanOriginPixel=\"" << ApexX << " " << ApexY << "\" FanRadiusStartPixel=\"" << R0
                     << "\" FanRadiusStopPixel=\"" << R1 << "\"/></PlusConfiguration>\n";
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputData(SyntheticSweep());
  fan->SetModeToCalibration();
  fan->SetCalibrationFileName(xml.c_str());
  fan->Update();
  vtkImageData* mask = fan->GetOutput();
  ASSERT_EQ(mask->GetDimensions()[2], 1);
  EXPECT_STREQ(mask->GetPointData()->GetScalars()->GetName(), "FanMask");
  for (int j = 0; j < H; ++j)
  {
    for (int i = 0; i < W; ++i)
    {
      ASSERT_EQ(MaskAt(mask, i, j), InFan(i, j) ? 1 : 0) << i << ", " << j;
    }
  }
}

TEST(FanMask, EstimateRecoversTheFanWithItsVesselAndWithoutTheOverlay)
{
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputData(SyntheticSweep());
  fan->Update();
  vtkImageData* mask = fan->GetOutput();
  int wrong = 0, inside = 0, wrongAwayFromBorder = 0;
  for (int j = 0; j < H; ++j)
  {
    for (int i = 0; i < W; ++i)
    {
      inside += InFan(i, j);
      if (MaskAt(mask, i, j) != (InFan(i, j) ? 1 : 0))
      {
        ++wrong;
        // Away from the border means the fan test gives the same answer 2 pixels around.
        bool border = false;
        for (int dj = -2; dj <= 2; ++dj)
        {
          for (int di = -2; di <= 2; ++di)
          {
            border = border || InFan(i + di, j + dj) != InFan(i, j);
          }
        }
        wrongAwayFromBorder += !border;
      }
    }
  }
  EXPECT_EQ(wrongAwayFromBorder, 0) << "the vessel is filled and the overlay mark is dropped";
  EXPECT_LT(wrong, inside / 50) << wrong << " of " << inside;
  EXPECT_EQ(MaskAt(mask, 100, 90), 1) << "anechoic vessel centre";
  EXPECT_EQ(MaskAt(mask, 6, 8), 0) << "overlay mark";
}

TEST(FanMask, ClipRectangleFromThePlusXml)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(DataPath("nwire-phantom/NwirePhantomFreehand.igs.mha").c_str());
  reader->SetCalibrationFileName(
    DataPath("nwire-phantom/PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml").c_str());
  reader->SetFrameRange(0, 1);
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputConnection(reader->GetOutputPort());
  fan->SetModeToCalibration();
  fan->SetCalibrationFileName(reader->GetCalibrationFileName());
  fan->Update();
  vtkImageData* mask = fan->GetOutput();
  long count = 0;
  for (int j = 0; j < 616; ++j)
  {
    for (int i = 0; i < 820; ++i)
    {
      const bool inside = i >= 167 && i < 167 + 495 && j >= 62 && j < 62 + 488;
      ASSERT_EQ(MaskAt(mask, i, j), inside ? 1 : 0);
      count += inside;
    }
  }
  EXPECT_EQ(count, 495L * 488L);
}

TEST(FanMask, LiverEstimateHoldsEveryEchoOfTheSweep)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(ExamplePath("liver/liver_sweep.igs.mha").c_str());
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputConnection(reader->GetOutputPort());
  fan->Update();
  vtkImageData* mask = fan->GetOutput();
  vtkImageData* frames = reader->GetOutput();
  const auto* m = static_cast<unsigned char*>(mask->GetScalarPointer());
  const auto* f = static_cast<unsigned char*>(frames->GetScalarPointer());
  const std::size_t pixels = 739 * 593;
  std::size_t inside = 0;
  for (std::size_t p = 0; p < pixels; ++p)
  {
    inside += m[p];
  }
  // A convex-probe fan covers a good part of the frame, but not all of it.
  EXPECT_GT(inside, pixels / 3);
  EXPECT_LT(inside, pixels * 9 / 10);
  // Outside the fan the frames hold only isolated faint noise (values 1 to 3 of 255 from the
  // scanner); tissue echoes (above 10) lie inside the mask.
  std::size_t echoes = 0, echoesOutside = 0;
  for (int k = 0; k < 140; ++k)
  {
    for (std::size_t p = 0; p < pixels; ++p)
    {
      if (f[k * pixels + p] > 10)
      {
        ++echoes;
        echoesOutside += m[p] == 0;
      }
    }
  }
  EXPECT_LT(double(echoesOutside), 1e-4 * echoes) << echoesOutside << " echoes outside the mask";
}
