// vtkUltrasoundCalibration against the PLUS configuration files we ship and against bad XML.
#include "bigusTestUtilities.h"

#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkUltrasoundCalibration.h"

#include <gtest/gtest.h>

#include <fstream>

using bigus_test::DataPath;
using bigus_test::OutputPath;

TEST(Calibration, NwireXmlGivesImageToProbeBothWaysAndTheClipRectangle)
{
  vtkNew<vtkUltrasoundCalibration> calibration;
  calibration->SetFileName(
    DataPath("nwire-phantom/PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml").c_str());
  ASSERT_TRUE(calibration->Parse()) << calibration->GetErrorText();
  EXPECT_EQ(calibration->GetNumberOfTransforms(), 2);
  vtkNew<vtkMatrix4x4> imageToProbe, probeToImage, product;
  ASSERT_TRUE(calibration->GetTransform("ImageToProbe", imageToProbe));
  EXPECT_DOUBLE_EQ(imageToProbe->GetElement(0, 0), -0.0094);
  EXPECT_DOUBLE_EQ(imageToProbe->GetElement(0, 3), -103.5322);
  EXPECT_DOUBLE_EQ(imageToProbe->GetElement(2, 2), 0.0760);
  ASSERT_TRUE(calibration->GetTransform("Probe", "Image", probeToImage));
  vtkMatrix4x4::Multiply4x4(imageToProbe, probeToImage, product);
  for (int r = 0; r < 4; ++r)
  {
    for (int c = 0; c < 4; ++c)
    {
      EXPECT_NEAR(product->GetElement(r, c), r == c ? 1.0 : 0.0, 1e-9);
    }
  }
  EXPECT_FALSE(calibration->GetTransform("ImageToTracker", product));
  ASSERT_TRUE(calibration->GetHasClipRectangle());
  EXPECT_EQ(calibration->GetClipRectangleOrigin()[0], 167);
  EXPECT_EQ(calibration->GetClipRectangleOrigin()[1], 62);
  EXPECT_EQ(calibration->GetClipRectangleSize()[0], 495);
  EXPECT_EQ(calibration->GetClipRectangleSize()[1], 488);
  EXPECT_FALSE(calibration->GetHasFan());
}

TEST(Calibration, FanParametersAreRead)
{
  const std::string file = OutputPath("fan.xml");
  std::ofstream(file) << "<PlusConfiguration><VolumeReconstruction FanAnglesDeg=\"-30 30\" "
                         "FanOriginPixel=\"320 -20\" FanRadiusStartPixel=\"40\" FanRadiusStopPixel=\"400\"/>"
                         "</PlusConfiguration>\n";
  vtkNew<vtkUltrasoundCalibration> calibration;
  calibration->SetFileName(file.c_str());
  ASSERT_TRUE(calibration->Parse()) << calibration->GetErrorText();
  ASSERT_TRUE(calibration->GetHasFan());
  EXPECT_EQ(calibration->GetFanAngles()[0], -30);
  EXPECT_EQ(calibration->GetFanOrigin()[1], -20);
  EXPECT_EQ(calibration->GetFanRadius()[1], 400);
  EXPECT_FALSE(calibration->GetHasClipRectangle());
}

TEST(Calibration, BadFilesGiveAClearError)
{
  struct Case
  {
    const char* Name;
    const char* Content;
    const char* Expected;
  };
  const Case cases[] = {
    { "truncated.xml", "<PlusConfiguration><CoordinateDefinitions><Transform From=\"Image\"", "malformed XML" },
    { "no_to.xml",
      "<A><CoordinateDefinitions><Transform From=\"Image\" Matrix=\"1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\"/>"
      "</CoordinateDefinitions></A>",
      "needs both From and To" },
    { "short_matrix.xml", "<A><Transform From=\"Image\" To=\"Probe\" Matrix=\"1 0 0 0 0 1 0 0 0 0 1 0\"/></A>",
      "16 numbers" },
    { "nan_matrix.xml", "<A><Transform From=\"Image\" To=\"Probe\" Matrix=\"1 0 0 0 0 1 0 0 0 0 1 nan 0 0 0 1\"/></A>",
      "NaN or Inf" },
    { "singular.xml", "<A><Transform From=\"Image\" To=\"Probe\" Matrix=\"0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 1\"/></A>",
      "singular" },
    { "bad_clip.xml", "<A><VolumeReconstruction ClipRectangleOrigin=\"1 2\" ClipRectangleSize=\"x 3\"/></A>",
      "ClipRectangle" },
  };
  for (const Case& c : cases)
  {
    const std::string file = OutputPath(c.Name);
    std::ofstream(file) << c.Content;
    vtkNew<vtkUltrasoundCalibration> calibration;
    calibration->SetFileName(file.c_str());
    EXPECT_FALSE(calibration->Parse()) << c.Name;
    const std::string error = calibration->GetErrorText();
    EXPECT_NE(error.find(file), std::string::npos) << error;
    EXPECT_NE(error.find(c.Expected), std::string::npos) << c.Name << ": " << error;
    EXPECT_EQ(calibration->GetNumberOfTransforms(), 0) << "nothing half-read is kept";
  }
  vtkNew<vtkUltrasoundCalibration> missing;
  missing->SetFileName(OutputPath("does_not_exist.xml").c_str());
  EXPECT_FALSE(missing->Parse());
  EXPECT_NE(std::string(missing->GetErrorText()).find("cannot open"), std::string::npos);
}
