// The slice frame of DESIGN section 3 against matrices with a known geometry.
#include "bigusSliceFrame.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkUltrasoundSliceGeometry.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace
{
// Rotation about z by `deg`, pixel spacing (sx, sy), origin (ox, oy, oz).
void MakePose(double m[16], double deg, double sx, double sy, double ox, double oy, double oz)
{
  const double c = std::cos(deg * M_PI / 180), s = std::sin(deg * M_PI / 180);
  const double r[16] = { c * sx, -s * sy, 0, ox, s * sx, c * sy, 0, oy, 0, 0, 0.5, oz, 0, 0, 0, 1 };
  std::copy(r, r + 16, m);
}
}

TEST(SliceGeometry, RotatedPoseGivesFrameSpacingAndNormal)
{
  double m[16];
  MakePose(m, 30, 0.2, 0.3, 10, -20, 1000);
  bigus::SliceFrame f;
  ASSERT_EQ(bigus::ComputeSliceFrame(m, 5, f), bigus::PoseStatus::Ok);
  EXPECT_NEAR(f.spacing[0], 0.2, 1e-15);
  EXPECT_NEAR(f.spacing[1], 0.3, 1e-15);
  EXPECT_NEAR(f.u[0], std::cos(M_PI / 6), 1e-15);
  EXPECT_NEAR(f.u[1], std::sin(M_PI / 6), 1e-15);
  EXPECT_NEAR(f.v[0], -std::sin(M_PI / 6), 1e-15);
  EXPECT_NEAR(f.n[2], 1.0, 1e-15);
  EXPECT_NEAR(f.shearDegrees, 0.0, 1e-12);
  EXPECT_EQ(f.origin[2], 1000);
  // Pixel (i, j) lands at origin + i su u + j sv v: check one against the matrix itself.
  const double i = 7, j = 11;
  for (int k = 0; k < 3; ++k)
  {
    EXPECT_NEAR(f.origin[k] + i * f.spacing[0] * f.u[k] + j * f.spacing[1] * f.v[k],
      m[4 * k] * i + m[4 * k + 1] * j + m[4 * k + 3], 1e-12);
  }
}

TEST(SliceGeometry, ShearIsMeasuredAndRejectedBeyondTolerance)
{
  // Second column tilted 3 degrees towards the first: 3 degrees of shear.
  const double t = 3 * M_PI / 180;
  double m[16] = { 1, std::sin(t), 0, 0, 0, std::cos(t), 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
  bigus::SliceFrame f;
  EXPECT_EQ(bigus::ComputeSliceFrame(m, 5, f), bigus::PoseStatus::Ok);
  EXPECT_NEAR(f.shearDegrees, 3.0, 1e-9);
  EXPECT_EQ(bigus::ComputeSliceFrame(m, 2, f), bigus::PoseStatus::Sheared);
}

TEST(SliceGeometry, DegeneratePosesAreReported)
{
  bigus::SliceFrame f;
  double zero[16] = { 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, 1 };
  EXPECT_EQ(bigus::ComputeSliceFrame(zero, 5, f), bigus::PoseStatus::Singular);
  double parallel[16] = { 1, 2, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
  EXPECT_EQ(bigus::ComputeSliceFrame(parallel, 90, f), bigus::PoseStatus::Singular);
  double nan[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, std::numeric_limits<double>::quiet_NaN(), 0, 0, 0, 1 };
  EXPECT_EQ(bigus::ComputeSliceFrame(nan, 5, f), bigus::PoseStatus::NotFinite);
  double projective[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0.1, 0, 0, 1 };
  EXPECT_EQ(bigus::ComputeSliceFrame(projective, 5, f), bigus::PoseStatus::NotAffine);
}

TEST(SliceGeometry, VtkClassExposesTheFrame)
{
  double m[16];
  MakePose(m, -45, 0.5, 0.5, 1, 2, 3);
  vtkNew<vtkMatrix4x4> matrix;
  matrix->DeepCopy(m);
  vtkNew<vtkUltrasoundSliceGeometry> geometry;
  geometry->SetImageToReference(matrix);
  EXPECT_EQ(geometry->GetStatus(), 0);
  EXPECT_NEAR(geometry->GetPixelSpacing()[0], 0.5, 1e-15);
  EXPECT_NEAR(geometry->GetNormal()[2], 1.0, 1e-15);
  EXPECT_NEAR(geometry->GetOrigin()[1], 2.0, 1e-15);
  matrix->SetElement(1, 1, matrix->GetElement(1, 0) * 2);
  matrix->SetElement(0, 1, matrix->GetElement(0, 0) * 2);
  geometry->SetImageToReference(matrix);
  EXPECT_EQ(geometry->GetStatus(), static_cast<int>(bigus::PoseStatus::Singular));
  EXPECT_NE(std::string(geometry->GetStatusText()).find("singular"), std::string::npos);
}
