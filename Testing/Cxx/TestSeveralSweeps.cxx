// Several sweeps into one field (issue 33): two sweeps of one volume along different paths, with different
// frame sizes, trained into one field (vtkGaussianFieldTrainer with two input connections) and compounded into
// one volume (vtkUltrasoundVolumeCompounder); leave-one-sweep-out; the frames of different sizes as the
// trainer holds them; and each kind of sweep that cannot go with the others refused with an error that names it.
#include "bigusElevationSigma.h"
#include "bigusGapFilling.h"
#include "bigusGaussianFieldData.h"
#include "bigusSeeding.h"
#include "bigusTestUtilities.h"
#include "bigusTrainingEngine.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkGaussianFieldSequenceRenderer.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkIntArray.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkUltrasoundVolumeCompounder.h"
#include "vtkUltrasoundVolumeSweep.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

using namespace bigus;

namespace
{
constexpr int NP = 16, NO = 24; // frames of the parallel and the orthogonal sweep

/// A 48 x 40 x 32 volume of 0.5 mm voxels with structure at a few mm along every axis.
vtkSmartPointer<vtkImageData> Volume()
{
  auto volume = vtkSmartPointer<vtkImageData>::New();
  volume->SetDimensions(48, 40, 32);
  volume->SetSpacing(0.5, 0.5, 0.5);
  volume->AllocateScalars(VTK_FLOAT, 1);
  auto* v = static_cast<float*>(volume->GetScalarPointer());
  for (int k = 0; k < 32; ++k)
  {
    for (int j = 0; j < 40; ++j)
    {
      for (int i = 0; i < 48; ++i)
      {
        const double x = 0.5 * i, y = 0.5 * j, z = 0.5 * k;
        *v++ = static_cast<float>(
          0.45 + 0.2 * std::sin(0.9 * x + 0.4 * z) * std::cos(0.7 * y) + 0.15 * std::sin(1.1 * z + 0.3 * y));
      }
    }
  }
  return volume;
}

vtkSmartPointer<vtkUltrasoundVolumeSweep> Sweep(vtkImageData* volume, int protocol, int frames, double offset)
{
  auto sweep = vtkSmartPointer<vtkUltrasoundVolumeSweep>::New();
  sweep->SetInputData(volume);
  sweep->SetProtocol(protocol);
  sweep->SetNumberOfFrames(frames);
  sweep->SetOffset(offset);
  sweep->SetMaximumTiltAngle(30);
  sweep->SetSeed(3);
  sweep->Update();
  return sweep;
}

/// Masked PSNR (dB, peak 1) of @p field rendered at @p test's poses against its frames: every frame, or
/// those with index k mod 4 == 2 (the held-out frames of the trainers below).
double Psnr(vtkPolyData* field, vtkUltrasoundVolumeSweep* test, bool heldOutOnly)
{
  vtkNew<vtkIdList> frames;
  const int count = test->GetOutput()->GetDimensions()[2];
  for (int k = 0; k < count; ++k)
  {
    if (!heldOutOnly || k % 4 == 2)
    {
      frames->InsertNextId(k);
    }
  }
  vtkNew<vtkGaussianFieldSequenceRenderer> render;
  render->SetInputData(field);
  render->SetPoseConnection(test->GetOutputPort());
  render->SetFrameList(frames);
  render->SetBackend("cpu");
  render->Update();
  vtkDataArray* rendered = render->GetOutput()->GetPointData()->GetScalars();
  vtkDataArray* truth = test->GetOutput()->GetPointData()->GetScalars();
  vtkDataArray* mask = test->GetMaskOutput()->GetPointData()->GetScalars();
  const vtkIdType pixels = truth->GetNumberOfTuples() / count;
  if (!rendered || rendered->GetNumberOfTuples() != pixels * frames->GetNumberOfIds())
  {
    return -1;
  }
  double sum = 0;
  vtkIdType n = 0;
  for (vtkIdType m = 0; m < frames->GetNumberOfIds(); ++m)
  {
    for (vtkIdType p = 0; p < pixels; ++p)
    {
      const vtkIdType q = frames->GetId(m) * pixels + p;
      if (mask->GetTuple1(q) != 0)
      {
        const double d = rendered->GetTuple1(m * pixels + p) - truth->GetTuple1(q);
        sum += d * d;
        ++n;
      }
    }
  }
  return n ? 10 * std::log10(n / sum) : -1;
}

struct Sweeps
{
  vtkSmartPointer<vtkImageData> VolumeData = Volume();
  // Parallel along z: NP frames of 48 x 40, 1 mm apart; orthogonal along x: NO frames of 40 x 32, 1 mm apart,
  // between the voxel planes; oblique test slices of 48 x 40, tilted up to 30 degrees.
  vtkSmartPointer<vtkUltrasoundVolumeSweep> Parallel = Sweep(VolumeData, vtkUltrasoundVolumeSweep::PARALLEL, NP, 0);
  vtkSmartPointer<vtkUltrasoundVolumeSweep> Orthogonal =
    Sweep(VolumeData, vtkUltrasoundVolumeSweep::ORTHOGONAL, NO, 0.5);
  vtkSmartPointer<vtkUltrasoundVolumeSweep> Oblique = Sweep(VolumeData, vtkUltrasoundVolumeSweep::OBLIQUE, 10, 0);
};

/// A trainer on the given sweeps (and their masks) with the defaults (the pixel-grid fit applies: the sweeps are
/// small) and one elevation sigma for all (a smooth volume has no speckle to choose it from).
vtkSmartPointer<vtkGaussianFieldTrainer> MakeTrainer(const std::vector<vtkUltrasoundVolumeSweep*>& sweeps)
{
  auto trainer = vtkSmartPointer<vtkGaussianFieldTrainer>::New();
  for (vtkUltrasoundVolumeSweep* s : sweeps)
  {
    trainer->AddInputConnection(0, s->GetOutputPort());
    trainer->AddMaskConnection(s->GetMaskOutputPort());
  }
  trainer->SetBackend("cpu");
  trainer->SetElevationSigma(1.0);
  trainer->SetIterations(300);
  trainer->SetSeed(5);
  return trainer;
}

/// A copy of @p sequence with every ImageToReference changed by @p edit.
vtkSmartPointer<vtkImageData> EditPoses(vtkImageData* sequence, const std::function<void(double*)>& edit)
{
  auto copy = vtkSmartPointer<vtkImageData>::New();
  copy->DeepCopy(sequence);
  vtkDataArray* poses = copy->GetFieldData()->GetArray("ImageToReference");
  for (vtkIdType k = 0; k < poses->GetNumberOfTuples(); ++k)
  {
    double m[16];
    poses->GetTuple(k, m);
    edit(m);
    poses->SetTuple(k, m);
  }
  return copy;
}
}

TEST(SeveralSweeps, FramesOfDifferentSizesKeepTheirPixelsAndPosesAndThePaddingIsMaskedOut)
{
  Sweeps s;
  TrainingData data;
  std::string error;
  ASSERT_TRUE(TrainingDataFromSweeps({ { s.Parallel->GetOutput(), s.Parallel->GetMaskOutput(), "sweep 0" },
                                       { s.Orthogonal->GetOutput(), s.Orthogonal->GetMaskOutput(), "sweep 1" } },
    data, &error))
    << error;
  ASSERT_EQ(data.Width, 48);  // the larger of 48 and 40
  ASSERT_EQ(data.Height, 40); // the larger of 40 and 32
  ASSERT_EQ(data.Count(), NP + NO);
  ASSERT_EQ(data.Mask.size(), std::size_t(48) * 40 * (NP + NO)); // one mask per frame
  for (int f = 0; f < NP + NO; ++f)
  {
    EXPECT_EQ(data.SweepOf(f), f < NP ? 0 : 1);
  }
  // Frame NP + 3 is the orthogonal sweep's frame 3: its own 40 x 32 pixels and mask at their indices, its pose
  // as the sweep gave it, the rest of the 48 x 40 grid 0 and masked out.
  vtkImageData* orthogonal = s.Orthogonal->GetOutput();
  vtkDataArray* pixels = orthogonal->GetPointData()->GetScalars();
  vtkDataArray* mask = s.Orthogonal->GetMaskOutput()->GetPointData()->GetScalars();
  const std::array<double, 16> pose = bigus_test::Pose(orthogonal, 3);
  EXPECT_EQ(data.Poses[NP + 3], pose);
  const unsigned char* frameMask = data.MaskOf(NP + 3);
  int masked = 0;
  for (int j = 0; j < 40; ++j)
  {
    for (int i = 0; i < 48; ++i)
    {
      const std::size_t p = std::size_t(j) * 48 + i;
      const float value = data.Frames[std::size_t(NP + 3) * 48 * 40 + p];
      if (i < 40 && j < 32)
      {
        const vtkIdType q = vtkIdType(3) * 40 * 32 + vtkIdType(j) * 40 + i;
        ASSERT_FLOAT_EQ(value, static_cast<float>(pixels->GetTuple1(q))) << i << " " << j;
        ASSERT_EQ(frameMask[p], mask->GetTuple1(q) != 0 ? 1 : 0) << i << " " << j;
        masked += frameMask[p];
      }
      else
      {
        ASSERT_EQ(value, 0.0f);
        ASSERT_EQ(frameMask[p], 0);
      }
    }
  }
  EXPECT_GT(masked, 40 * 32 / 2);
}

TEST(SeveralSweeps, WhatDependsOnTheFrameSpacingIsMeasuredWithinEachSweep)
{
  // A parallel sweep 1 mm apart and an orthogonal one 4 mm apart (6 frames across 24 mm). Pooled, the dense
  // sweep's spacing would rule both: the sparse sweep's every pair would be a gap (over 3 x 1 mm) and its
  // Gaussians as thin as the dense sweep's planes.
  Sweeps s;
  auto sparse = Sweep(s.VolumeData, vtkUltrasoundVolumeSweep::ORTHOGONAL, 6, 0.5);
  const double spacing[2] = { s.Parallel->GetSliceSpacing(), sparse->GetSliceSpacing() };
  ASSERT_GT(spacing[1], 3.5 * spacing[0]);
  TrainingData both, dense;
  std::string error;
  ASSERT_TRUE(TrainingDataFromSweeps({ { s.Parallel->GetOutput(), s.Parallel->GetMaskOutput(), "sweep 0" },
                                       { sparse->GetOutput(), sparse->GetMaskOutput(), "sweep 1" } },
    both, &error))
    << error;
  ASSERT_TRUE(
    TrainingDataFromSweeps({ { s.Parallel->GetOutput(), s.Parallel->GetMaskOutput(), "sweep 0" } }, dense, &error))
    << error;
  for (TrainingData* d : { &both, &dense })
  {
    for (int k = 0; k < d->Count(); ++k)
    {
      d->TrainFrames.push_back(k);
    }
  }
  // The dense start's planes: each sweep's own spacing (the sweeps' slice spacing), and each plane's Gaussians
  // 0.45 of it thick across the plane.
  SeedShape shape;
  shape.PixelSpacing = 0.5;
  shape.ElevationSigma = 0.3;
  const GridPlanes planes = SelectGridPlanes(both, shape);
  ASSERT_EQ(planes.Frames.size(), std::size_t(NP + 6));
  ASSERT_EQ(planes.Spacing.size(), 2u);
  EXPECT_NEAR(planes.Spacing[0], spacing[0], 1e-6);
  EXPECT_NEAR(planes.Spacing[1], spacing[1], 1e-6);
  GaussianField field;
  SeedGrid(both, planes, planes.FanPixels, shape, field);
  ASSERT_EQ(field.Count(), planes.FanPixels);
  auto thickness = [&](std::int64_t g) {
    return std::exp(std::max({ field.LogScales[3 * g], field.LogScales[3 * g + 1], field.LogScales[3 * g + 2] }));
  };
  EXPECT_NEAR(thickness(0), 0.45 * spacing[0], 1e-5) << "the parallel sweep's first plane";
  EXPECT_NEAR(thickness(field.Count() - 1), 0.45 * spacing[1], 1e-5) << "the sparse sweep's last plane";
  // Gap filling: every pair of the sparse sweep is 1 of its own spacings apart, no gap.
  const GapFillingReport gaps = FillElevationGaps(field, both, 0.3, GapFillingSettings());
  EXPECT_EQ(gaps.Gaps, 0) << "typical spacing " << gaps.TypicalSpacing;
  // The elevation sigma: the dense sweep's choice (its frames lie closest), not the pooled pairs'.
  const ElevationSigmaChoice chosen = ChooseElevationSigma(both), alone = ChooseElevationSigma(dense);
  EXPECT_DOUBLE_EQ(chosen.Sigma, alone.Sigma) << chosen.Reason << " | " << alone.Reason;
  EXPECT_NE(chosen.Reason.find("sweep 0 of 2"), std::string::npos) << chosen.Reason;
}

TEST(SeveralSweeps, AFieldTrainedOnTwoSweepsRendersTheHeldOutFramesOfBoth)
{
  // Every 4th frame of each sweep held out (k mod 4 == 2, the index within the sweep): the field of both
  // sweeps renders the held-out frames of each about as well as that sweep's own field or better, far better
  // than the field of the other sweep, which never saw along that path, and oblique slices better than either.
  // Each field with the elevation sigma that suits it (measured, docs/FINDINGS.md "Two crossing sweeps and the
  // beam"): the frames are thin reslices of the volume, so the two sweeps together, which see each other's
  // elevation, want a narrow beam (0.5 mm); a sweep alone, 1 mm apart, a wide one (1 mm) to fill between its
  // planes. With 1 mm for both sweeps too, the joint field was 2 to 3 dB below each sweep's own.
  Sweeps s;
  auto both = MakeTrainer({ s.Parallel, s.Orthogonal });
  both->SetElevationSigma(0.5);
  auto parallel = MakeTrainer({ s.Parallel });
  auto orthogonal = MakeTrainer({ s.Orthogonal });
  for (vtkGaussianFieldTrainer* t : { both.Get(), parallel.Get(), orthogonal.Get() })
  {
    t->SetHoldOutEvery(4);
    t->SetHoldOutOffset(2);
  }
  bigus_test::MessageCollector* messages = bigus_test::MessageCollector::New();
  messages->Watch(both);
  both->Update();
  parallel->Update();
  orthogonal->Update();
  ASSERT_TRUE(messages->Errors.empty()) << messages->Errors.front();
  messages->Delete();
  ASSERT_GT(both->GetNumberOfGaussians(), 0);
  vtkFieldData* fd = both->GetOutput()->GetFieldData();
  // The training geometry on the shared grid, and which sweep each training frame came from.
  vtkDataArray* size = fd->GetArray("TrainingFrameSize");
  ASSERT_NE(size, nullptr);
  EXPECT_EQ(size->GetComponent(0, 0), 48);
  EXPECT_EQ(size->GetComponent(0, 1), 40);
  vtkDataArray* sweeps = fd->GetArray("TrainingSweeps");
  ASSERT_NE(sweeps, nullptr);
  ASSERT_EQ(sweeps->GetNumberOfTuples(), (NP + NO) * 3 / 4);
  EXPECT_EQ(sweeps->GetComponent(NP * 3 / 4 - 1, 0), 0);
  EXPECT_EQ(sweeps->GetComponent(NP * 3 / 4, 0), 1);
  EXPECT_EQ(sweeps->GetComponent(NP * 3 / 4, 1), 0); // the orthogonal sweep's first frame
  EXPECT_EQ(sweeps->GetComponent((NP + NO) * 3 / 4 - 1, 1), NO - 1);
  EXPECT_EQ(parallel->GetOutput()->GetFieldData()->GetArray("TrainingSweeps"), nullptr);

  const double onParallel[3] = { Psnr(both->GetOutput(), s.Parallel, true),
    Psnr(parallel->GetOutput(), s.Parallel, true), Psnr(orthogonal->GetOutput(), s.Parallel, true) };
  const double onOrthogonal[3] = { Psnr(both->GetOutput(), s.Orthogonal, true),
    Psnr(parallel->GetOutput(), s.Orthogonal, true), Psnr(orthogonal->GetOutput(), s.Orthogonal, true) };
  const double onOblique[3] = { Psnr(both->GetOutput(), s.Oblique, false),
    Psnr(parallel->GetOutput(), s.Oblique, false), Psnr(orthogonal->GetOutput(), s.Oblique, false) };
  std::printf("held-out frames of the parallel sweep: both sweeps' field %.2f dB, parallel's %.2f, orthogonal's %.2f\n",
    onParallel[0], onParallel[1], onParallel[2]);
  std::printf("held-out frames of the orthogonal sweep: both %.2f dB, parallel's %.2f, orthogonal's %.2f\n",
    onOrthogonal[0], onOrthogonal[1], onOrthogonal[2]);
  std::printf(
    "oblique slices: both %.2f dB, parallel's %.2f, orthogonal's %.2f\n", onOblique[0], onOblique[1], onOblique[2]);
  // Measured: 30.85 / 28.00 / 18.97, 30.76 / 16.86 / 31.05, 33.03 / 30.00 / 18.98 dB.
  EXPECT_GT(onParallel[0], onParallel[2] + 3);
  EXPECT_GT(onOrthogonal[0], onOrthogonal[1] + 3);
  EXPECT_GT(onParallel[0], onParallel[1] - 1);
  EXPECT_GT(onOrthogonal[0], onOrthogonal[2] - 1);
  EXPECT_GT(onOblique[0], std::max(onOblique[1], onOblique[2]) + 1);
}

TEST(SeveralSweeps, LeaveOneSweepOutTrainsOnTheOtherSweepsOnly)
{
  Sweeps s;
  auto trainer = MakeTrainer({ s.Parallel, s.Orthogonal });
  trainer->SetHoldOutSweep(1);
  trainer->SetHoldOutEvery(4); // applies within sweep 0, by the index there
  trainer->SetHoldOutOffset(2);
  trainer->Update();
  ASSERT_GT(trainer->GetNumberOfGaussians(), 0);
  vtkDataArray* frames = trainer->GetOutput()->GetFieldData()->GetArray("TrainingFrames");
  ASSERT_NE(frames, nullptr);
  std::vector<int> trained;
  for (vtkIdType k = 0; k < frames->GetNumberOfTuples(); ++k)
  {
    trained.push_back(static_cast<int>(frames->GetTuple1(k)));
  }
  std::vector<int> expected;
  for (int k = 0; k < NP; ++k)
  {
    if (k % 4 != 2)
    {
      expected.push_back(k);
    }
  }
  EXPECT_EQ(trained, expected);
  // Per sweep: holding out i mod 4 == 2 of each sweep's own indices.
  trainer->SetHoldOutSweep(-1);
  trainer->Update();
  frames = trainer->GetOutput()->GetFieldData()->GetArray("TrainingFrames");
  std::vector<int> perSweep;
  for (vtkIdType k = 0; k < frames->GetNumberOfTuples(); ++k)
  {
    perSweep.push_back(static_cast<int>(frames->GetTuple1(k)));
  }
  for (int k = 0; k < NO; ++k)
  {
    if (k % 4 != 2)
    {
      expected.push_back(NP + k);
    }
  }
  EXPECT_EQ(perSweep, expected);
  // A sweep that does not exist is an error.
  bigus_test::MessageCollector* messages = bigus_test::MessageCollector::New();
  messages->Watch(trainer);
  trainer->SetHoldOutSweep(2);
  trainer->Update();
  ASSERT_FALSE(messages->Errors.empty());
  EXPECT_NE(messages->Errors.back().find("HoldOutSweep 2"), std::string::npos) << messages->Errors.back();
  EXPECT_EQ(trainer->GetOutput()->GetNumberOfPoints(), 0);
  messages->Delete();
}

TEST(SeveralSweeps, SweepsThatCannotGoTogetherAreRefusedWithAnErrorNamingTheSweep)
{
  Sweeps s;
  struct Case
  {
    const char* What;
    vtkSmartPointer<vtkImageData> Second, SecondMask;
    const char* Expected;
  };
  // No common region: the orthogonal sweep moved 100 mm away.
  auto far = EditPoses(s.Orthogonal->GetOutput(), [](double* m) { m[3] += 100; });
  // Different units: the orthogonal sweep's poses in metres.
  auto metres = EditPoses(s.Orthogonal->GetOutput(), [](double* m) {
    for (int e = 0; e < 12; ++e)
    {
      m[e] *= 1e-3;
    }
  });
  // An empty fan mask.
  auto empty = vtkSmartPointer<vtkImageData>::New();
  empty->DeepCopy(s.Orthogonal->GetMaskOutput());
  empty->GetPointData()->GetScalars()->Fill(0);
  const Case cases[] = {
    { "no common region", far, s.Orthogonal->GetMaskOutput(), "share no region" },
    { "different units", metres, s.Orthogonal->GetMaskOutput(), "not in the same units" },
    { "empty mask", s.Orthogonal->GetOutput(), empty, "fan mask is empty" },
  };
  for (const Case& c : cases)
  {
    vtkNew<vtkGaussianFieldTrainer> trainer;
    trainer->AddInputConnection(0, s.Parallel->GetOutputPort());
    trainer->AddInputData(0, c.Second);
    trainer->AddMaskConnection(s.Parallel->GetMaskOutputPort());
    trainer->AddInputData(1, c.SecondMask);
    trainer->SetBackend("cpu");
    trainer->SetIterations(10);
    bigus_test::MessageCollector* messages = bigus_test::MessageCollector::New();
    messages->Watch(trainer);
    trainer->Update();
    ASSERT_EQ(messages->Errors.size(), 1u) << c.What;
    const std::string& e = messages->Errors.front();
    EXPECT_NE(e.find("sweep 1"), std::string::npos) << c.What << ": " << e;
    EXPECT_NE(e.find(c.Expected), std::string::npos) << c.What << ": " << e;
    EXPECT_EQ(trainer->GetOutput()->GetNumberOfPoints(), 0) << c.What;
    EXPECT_EQ(trainer->GetNumberOfGaussians(), 0) << c.What;
    messages->Delete();
  }
  // One mask for two sweeps: which sweep it belongs to is not known.
  vtkNew<vtkGaussianFieldTrainer> trainer;
  trainer->AddInputConnection(0, s.Parallel->GetOutputPort());
  trainer->AddInputConnection(0, s.Orthogonal->GetOutputPort());
  trainer->AddMaskConnection(s.Parallel->GetMaskOutputPort());
  bigus_test::MessageCollector* messages = bigus_test::MessageCollector::New();
  messages->Watch(trainer);
  trainer->Update();
  ASSERT_FALSE(messages->Errors.empty());
  EXPECT_NE(messages->Errors.front().find("1 fan masks for 2 sweeps"), std::string::npos) << messages->Errors.front();
  EXPECT_EQ(trainer->GetOutput()->GetNumberOfPoints(), 0);
  messages->Delete();
}

TEST(SeveralSweeps, CompoundingTwoSweepsIsTheMeanOfEveryPixelEitherSweepInserted)
{
  // On one explicit grid, the two sweeps' volume holds at each voxel the mean of the pixels of both: the
  // count-weighted mean of the two single-sweep volumes.
  Sweeps s;
  auto compound = [&](const std::vector<vtkUltrasoundVolumeSweep*>& sweeps, vtkIdList* frames) {
    auto c = vtkSmartPointer<vtkUltrasoundVolumeCompounder>::New();
    for (vtkUltrasoundVolumeSweep* sweep : sweeps)
    {
      c->AddInputConnection(0, sweep->GetOutputPort());
      c->AddInputConnection(1, sweep->GetMaskOutputPort());
    }
    c->SetOutputSpacing(1, 1, 1);
    c->SetOutputOrigin(0, 0, 0);
    c->SetOutputExtent(0, 23, 0, 19, 0, 15);
    c->FillHolesOff();
    c->SetFrameList(frames);
    c->Update();
    return c;
  };
  auto a = compound({ s.Parallel }, nullptr);
  auto b = compound({ s.Orthogonal }, nullptr);
  auto both = compound({ s.Parallel, s.Orthogonal }, nullptr);
  EXPECT_EQ(both->GetNumberOfInsertedFrames(), NP + NO);
  EXPECT_EQ(both->GetNumberOfInsertedPixels(), a->GetNumberOfInsertedPixels() + b->GetNumberOfInsertedPixels());
  vtkDataArray* va = a->GetOutput()->GetPointData()->GetArray("Intensity");
  vtkDataArray* vb = b->GetOutput()->GetPointData()->GetArray("Intensity");
  vtkDataArray* vab = both->GetOutput()->GetPointData()->GetArray("Intensity");
  vtkDataArray* ca = a->GetOutput()->GetPointData()->GetArray("InsertedPixelCount");
  vtkDataArray* cb = b->GetOutput()->GetPointData()->GetArray("InsertedPixelCount");
  vtkDataArray* cab = both->GetOutput()->GetPointData()->GetArray("InsertedPixelCount");
  vtkIdType shared = 0;
  for (vtkIdType v = 0; v < vab->GetNumberOfTuples(); ++v)
  {
    const double na = ca->GetTuple1(v), nb = cb->GetTuple1(v);
    ASSERT_EQ(cab->GetTuple1(v), na + nb) << v;
    if (na + nb > 0)
    {
      ASSERT_NEAR(vab->GetTuple1(v), (na * va->GetTuple1(v) + nb * vb->GetTuple1(v)) / (na + nb), 1e-5) << v;
    }
    shared += na > 0 && nb > 0;
  }
  EXPECT_GT(shared, 100); // the sweeps cross: voxels that both fill
  // The frame list counts the sweeps' frames in turn: frames NP to NP + NO - 1 are the orthogonal sweep's.
  vtkNew<vtkIdList> second;
  for (int f = NP; f < NP + NO; ++f)
  {
    second->InsertNextId(f);
  }
  auto onlyB = compound({ s.Parallel, s.Orthogonal }, second);
  EXPECT_EQ(onlyB->GetNumberOfInsertedPixels(), b->GetNumberOfInsertedPixels());
  // A frame beyond both sweeps is an error.
  second->InsertNextId(NP + NO);
  bigus_test::MessageCollector* messages = bigus_test::MessageCollector::New();
  vtkNew<vtkUltrasoundVolumeCompounder> c;
  messages->Watch(c);
  c->AddInputConnection(0, s.Parallel->GetOutputPort());
  c->AddInputConnection(0, s.Orthogonal->GetOutputPort());
  c->SetFrameList(second);
  c->Update();
  ASSERT_FALSE(messages->Errors.empty());
  EXPECT_NE(messages->Errors.front().find("frame " + std::to_string(NP + NO)), std::string::npos)
    << messages->Errors.front();
  messages->Delete();
}
