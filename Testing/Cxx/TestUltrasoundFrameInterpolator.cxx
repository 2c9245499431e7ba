// vtkUltrasoundFrameInterpolator: temporal blending on frames linear in time (exact), nearest pose on
// known poses, a hold-out on the real spine-phantom sweep, and bad inputs.
#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkExecutive.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundFrameInterpolator.h"
#include "vtkUltrasoundSequenceReader.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <initializer_list>
#include <iostream>
#include <string>
#include <vector>

using bigus_test::DataPath;
using bigus_test::MessageCollector;
using bigus_test::Pose;

namespace
{
using Matrix = std::array<double, 16>;

Matrix Translation(double tx, double ty, double tz)
{
  return { 1, 0, 0, tx, 0, 1, 0, ty, 0, 0, 1, tz, 0, 0, 0, 1 };
}

vtkSmartPointer<vtkIdList> Ids(std::initializer_list<vtkIdType> ids)
{
  auto list = vtkSmartPointer<vtkIdList>::New();
  for (vtkIdType id : ids)
  {
    list->InsertNextId(id);
  }
  return list;
}

const float* Pixels(vtkImageData* image)
{
  return vtkFloatArray::SafeDownCast(image->GetPointData()->GetScalars())->GetPointer(0);
}

double Field(vtkImageData* image, const char* name, int tuple, int component = 0)
{
  return image->GetFieldData()->GetArray(name)->GetComponent(tuple, component);
}

/// Nine frames, W x H = 12 x 10, each pixel linear in time: a(i, j) + b(i, j) t, unevenly timed.
const std::vector<double> Times = { 0, 0.1, 0.25, 0.3, 0.5, 0.55, 0.7, 0.9, 1.0 };
float LinearInTime(int k, int i, int j)
{
  return static_cast<float>((3 + i - 0.5 * j) + (20 - 2.0 * i + j) * Times[k]);
}

vtkSmartPointer<vtkImageData> LinearSweep()
{
  std::vector<Matrix> poses;
  for (int k = 0; k < 9; ++k)
  {
    poses.push_back(Translation(0, 0, 0.4 * k));
  }
  return bigus_test::TrackedSequence(12, 10, poses, Times, LinearInTime);
}
}

TEST(FrameInterpolator, TemporalBlendIsExactForFramesLinearInTime)
{
  auto sweep = LinearSweep();
  vtkNew<vtkUltrasoundFrameInterpolator> interpolator;
  interpolator->SetInputData(sweep);
  interpolator->SetTrainingFrames(Ids({ 8, 0, 5, 2 })); // any order: they are sorted by time
  interpolator->SetModeToTemporalBlend();
  interpolator->Update();
  vtkImageData* out = interpolator->GetOutput();
  int dims[3];
  out->GetDimensions(dims);
  ASSERT_EQ(dims[0], 12);
  ASSERT_EQ(dims[1], 10);
  ASSERT_EQ(dims[2], 5);
  const std::vector<int> targets = { 1, 3, 4, 6, 7 };
  const std::vector<std::array<int, 2>> brackets = { { { 0, 2 } }, { { 2, 5 } }, { { 2, 5 } }, { { 5, 8 } },
    { { 5, 8 } } };
  const float* p = Pixels(out);
  for (int m = 0; m < 5; ++m)
  {
    const int k = targets[m];
    EXPECT_EQ(Field(out, "FrameIndex", m), k);
    EXPECT_EQ(Field(out, "Timestamp", m), Times[k]);
    EXPECT_EQ(Field(out, "FrameValid", m), 1);
    EXPECT_EQ(Pose(out, m), Pose(sweep, k));
    EXPECT_EQ(Field(out, "SourceFrames", m, 0), brackets[m][0]);
    EXPECT_EQ(Field(out, "SourceFrames", m, 1), brackets[m][1]);
    const double ta = Times[brackets[m][0]], tb = Times[brackets[m][1]];
    EXPECT_NEAR(Field(out, "BlendWeight", m), (Times[k] - ta) / (tb - ta), 1e-15);
    for (int j = 0; j < 10; ++j)
    {
      for (int i = 0; i < 12; ++i)
      {
        ASSERT_NEAR(p[(m * 10 + j) * 12 + i], LinearInTime(k, i, j), 1e-4)
          << "frame " << k << " pixel " << i << ", " << j;
      }
    }
  }

  // Beyond the training frames' time span: the nearest one in time, unchanged.
  interpolator->SetTrainingFrames(Ids({ 2, 5 }));
  interpolator->SetTargetFrames(Ids({ 0, 8, 3 }));
  interpolator->Update();
  out = interpolator->GetOutput();
  ASSERT_EQ(out->GetDimensions()[2], 3);
  const int expected[2] = { 2, 5 };
  for (int m = 0; m < 2; ++m)
  {
    EXPECT_EQ(Field(out, "SourceFrames", m, 0), expected[m]);
    EXPECT_EQ(Field(out, "BlendWeight", m), 0);
    for (int q = 0; q < 120; ++q)
    {
      ASSERT_EQ(Pixels(out)[m * 120 + q], LinearInTime(expected[m], q % 12, q / 12));
    }
  }
  EXPECT_EQ(Field(out, "FrameIndex", 2), 3);
}

TEST(FrameInterpolator, NearestPoseUsesTheImageCentre)
{
  // W x H = 20 x 10 pixels of 1 mm; the image centre is pixel (10, 5). Each frame's pixels hold its
  // own index so the prediction names its source.
  Matrix flipped = Translation(21, 10, 1); // rotated 180 degrees about z: centre at (11, 5, 1)
  flipped[0] = -1;
  flipped[5] = -1;
  const std::vector<Matrix> poses = {
    Translation(0, 0, 0),   // 0: target, centre (10, 5, 0)
    Translation(3, 0, 0),   // 1: centre 3 mm away, origin 3 mm away
    flipped,                // 2: centre 1.41 mm away, origin 23 mm away
    Translation(0, 0, 2.5), // 3: target, centre (10, 5, 2.5): nearest is frame 4 (1.5 mm) over frame 2
    Translation(0, 0, 4),   // 4
    Translation(40, 0, 0),  // 5: target, nearest frame 1 (37 mm)
  };
  auto sweep =
    bigus_test::TrackedSequence(20, 10, poses, { 0, 1, 2, 3, 4, 5 }, [](int k, int, int) { return float(k); });
  vtkNew<vtkUltrasoundFrameInterpolator> interpolator;
  interpolator->SetInputData(sweep);
  interpolator->SetTrainingFrames(Ids({ 1, 2, 4 }));
  interpolator->Update();
  vtkImageData* out = interpolator->GetOutput();
  ASSERT_EQ(out->GetDimensions()[2], 3);
  const int targets[3] = { 0, 3, 5 }, nearest[3] = { 2, 4, 1 };
  for (int m = 0; m < 3; ++m)
  {
    EXPECT_EQ(Field(out, "FrameIndex", m), targets[m]);
    EXPECT_EQ(Field(out, "SourceFrames", m, 0), nearest[m]) << "target " << targets[m];
    EXPECT_EQ(Field(out, "SourceFrames", m, 1), nearest[m]);
    EXPECT_EQ(Pixels(out)[m * 200 + 77], float(nearest[m]));
    EXPECT_EQ(Pose(out, m), poses[targets[m]]);
  }
}

TEST(FrameInterpolator, InvalidTargetIsZerosAndKeepsFrameValidZero)
{
  auto sweep = LinearSweep();
  sweep->GetFieldData()->GetArray("FrameValid")->SetTuple1(4, 0);
  vtkNew<vtkUltrasoundFrameInterpolator> interpolator;
  vtkNew<MessageCollector> messages;
  messages->Watch(interpolator);
  interpolator->SetInputData(sweep);
  interpolator->SetTrainingFrames(Ids({ 0, 2, 6, 8 }));
  interpolator->SetTargetFrames(Ids({ 4, 5 }));
  interpolator->Update();
  EXPECT_TRUE(messages->Errors.empty());
  EXPECT_EQ(messages->Warnings.size(), 1u);
  vtkImageData* out = interpolator->GetOutput();
  EXPECT_EQ(Field(out, "FrameValid", 0), 0);
  EXPECT_EQ(Field(out, "SourceFrames", 0, 0), -1);
  EXPECT_EQ(Pixels(out)[37], 0.0f);
  EXPECT_EQ(Field(out, "FrameValid", 1), 1);
  EXPECT_EQ(Field(out, "SourceFrames", 1, 0), 6); // nearest pose: 0.4 mm steps along z
}

TEST(FrameInterpolator, SpinePhantomHoldOutKeepsShapesAndPoses)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(DataPath("spine-phantom/SpinePhantomFreehand.igs.mha").c_str());
  reader->SetCalibrationFileName(
    DataPath("spine-phantom/PlusDeviceSet_VolumeReconstructionOnly_SpinePhantom_NN_MEAN.xml").c_str());
  reader->Update();
  ASSERT_STREQ(reader->GetLastErrorText(), "");
  vtkImageData* sweep = reader->GetOutput();
  ASSERT_EQ(sweep->GetDimensions()[2], 21);
  vtkNew<vtkIdList> training;
  for (int k = 0; k < 21; k += 2)
  {
    training->InsertNextId(k);
  }
  const vtkIdType frame = 820 * 616;
  const auto* truth = static_cast<const unsigned char*>(sweep->GetScalarPointer());
  for (int mode : { vtkUltrasoundFrameInterpolator::NEAREST_POSE, vtkUltrasoundFrameInterpolator::TEMPORAL_BLEND })
  {
    vtkNew<vtkUltrasoundFrameInterpolator> interpolator;
    interpolator->SetInputConnection(reader->GetOutputPort());
    interpolator->SetTrainingFrames(training);
    interpolator->SetMode(mode);
    interpolator->Update();
    vtkImageData* out = interpolator->GetOutput();
    int dims[3];
    out->GetDimensions(dims);
    ASSERT_EQ(dims[0], 820);
    ASSERT_EQ(dims[1], 616);
    ASSERT_EQ(dims[2], 10);
    EXPECT_EQ(out->GetScalarType(), VTK_FLOAT);
    double error = 0;
    for (int m = 0; m < 10; ++m)
    {
      const int k = 2 * m + 1;
      EXPECT_EQ(Pose(out, m), Pose(sweep, k));
      EXPECT_EQ(Field(out, "FrameIndex", m), k);
      EXPECT_EQ(Field(out, "Timestamp", m), Field(sweep, "Timestamp", k));
      const int a = static_cast<int>(Field(out, "SourceFrames", m, 0));
      const int b = static_cast<int>(Field(out, "SourceFrames", m, 1));
      const double w = Field(out, "BlendWeight", m);
      if (mode == vtkUltrasoundFrameInterpolator::TEMPORAL_BLEND)
      {
        EXPECT_EQ(a, k - 1);
        EXPECT_EQ(b, k + 1);
        EXPECT_GT(w, 0.3); // about 0.5 at a steady frame rate
        EXPECT_LT(w, 0.7);
      }
      else
      {
        EXPECT_EQ(a, b);
        EXPECT_EQ(a % 2, 0);
        EXPECT_LE(std::abs(a - k), 3) << "a freehand sweep's nearest pose is a near neighbour in time";
      }
      const float* p = Pixels(out) + m * frame;
      for (vtkIdType q = 0; q < frame; q += 97)
      {
        const double expected = (1 - w) * truth[a * frame + q] + w * truth[b * frame + q];
        ASSERT_NEAR(p[q], expected, 1e-3);
        error += std::abs(p[q] - truth[k * frame + q]);
      }
    }
    std::cout << "[ measured ] spine hold-out (even frames train, odd frames predicted), "
              << interpolator->GetModeAsString() << ": mean absolute error " << error / (10.0 * ((frame + 96) / 97))
              << " grey levels (sampled pixels)\n";
  }
}

TEST(FrameInterpolator, BadListsAndInputsFailWithAnError)
{
  struct Case
  {
    std::string Name;
    std::function<void(vtkImageData*, vtkUltrasoundFrameInterpolator*)> Break;
    std::string Expected;
  };
  const std::vector<Case> cases = {
    { "no training list", [](vtkImageData*, vtkUltrasoundFrameInterpolator* f) { f->SetTrainingFrames(nullptr); },
      "training frame list is empty" },
    { "empty training list", [](vtkImageData*, vtkUltrasoundFrameInterpolator* f) { f->SetTrainingFrames(Ids({})); },
      "training frame list is empty" },
    { "training frame out of range",
      [](vtkImageData*, vtkUltrasoundFrameInterpolator* f) {
        f->SetTrainingFrames(Ids({ 0, 9 }));
      },
      "training frame 9 is outside the 9 frames" },
    { "negative training frame",
      [](vtkImageData*, vtkUltrasoundFrameInterpolator* f) { f->SetTrainingFrames(Ids({ -1 })); }, "outside" },
    { "target frame out of range",
      [](vtkImageData*, vtkUltrasoundFrameInterpolator* f) {
        f->SetTargetFrames(Ids({ 3, 12 }));
      },
      "target frame 12 is outside" },
    { "invalid training frame",
      [](vtkImageData* s, vtkUltrasoundFrameInterpolator*) {
        s->GetFieldData()->GetArray("FrameValid")->SetTuple1(2, 0);
      },
      "training frame 2 has FrameValid = 0" },
    { "every frame is a training frame",
      [](vtkImageData*, vtkUltrasoundFrameInterpolator* f) {
        f->SetTrainingFrames(Ids({ 0, 1, 2, 3, 4, 5, 6, 7, 8 }));
      },
      "no target frame" },
    { "no Timestamp for the blend",
      [](vtkImageData* s, vtkUltrasoundFrameInterpolator* f) {
        s->GetFieldData()->RemoveArray("Timestamp");
        f->SetModeToTemporalBlend();
      },
      "TemporalBlend needs Timestamp" },
    { "no ImageToReference",
      [](vtkImageData* s, vtkUltrasoundFrameInterpolator*) { s->GetFieldData()->RemoveArray("ImageToReference"); },
      "ImageToReference" },
    { "poses short",
      [](vtkImageData* s, vtkUltrasoundFrameInterpolator*) {
        s->GetFieldData()->GetArray("ImageToReference")->SetNumberOfTuples(4);
      },
      "ImageToReference" },
    { "NaN pose of a training frame",
      [](vtkImageData* s, vtkUltrasoundFrameInterpolator*) {
        s->GetFieldData()->GetArray("ImageToReference")->SetComponent(2, 3, std::nan(""));
      },
      "training frame 2: ImageToReference is not a finite affine map" },
    { "two-component frames",
      [](vtkImageData* s, vtkUltrasoundFrameInterpolator*) {
        vtkNew<vtkFloatArray> two;
        two->SetNumberOfComponents(2);
        two->SetNumberOfTuples(s->GetNumberOfPoints());
        s->GetPointData()->SetScalars(two);
      },
      "one-component" },
  };
  for (const Case& c : cases)
  {
    SCOPED_TRACE(c.Name);
    auto sweep = LinearSweep();
    vtkNew<vtkUltrasoundFrameInterpolator> interpolator;
    vtkNew<MessageCollector> messages, pipeline;
    messages->Watch(interpolator);
    pipeline->Watch(interpolator->GetExecutive());
    interpolator->SetInputData(sweep);
    interpolator->SetTrainingFrames(Ids({ 0, 2, 5, 8 }));
    c.Break(sweep, interpolator);
    interpolator->Update();
    ASSERT_EQ(messages->Errors.size(), 1u);
    EXPECT_NE(messages->Errors[0].find(c.Expected), std::string::npos) << messages->Errors[0];
    EXPECT_EQ(interpolator->GetOutput()->GetNumberOfPoints(), 0);
  }
}
