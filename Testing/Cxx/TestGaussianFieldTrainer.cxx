// The filter vtkGaussianFieldTrainer: a tracked frame sequence in, the trained field of the data model out, with
// its settings, progress, abort and errors; and its place in a pipeline with a slice downstream.
#include "bigusElevationSigma.h"
#include "bigusGaussianFieldData.h"
#include "bigusTestUtilities.h"
#include "bigusTrainingTestUtilities.h"
#include "bigusValidation.h"

#include "vtkCallbackCommand.h"
#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkSmartPointer.h"
#include "vtkStringArray.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundSequenceReader.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

using namespace bigus;
using namespace bigus::synthetic;

namespace
{
/// @p data as a tracked frame sequence (unsigned char, as a reader gives it).
vtkSmartPointer<vtkImageData> TrackedSequence(const TrainingData& data)
{
  auto sequence = vtkSmartPointer<vtkImageData>::New();
  sequence->SetDimensions(W, H, data.Count());
  sequence->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  auto* pixels = static_cast<unsigned char*>(sequence->GetScalarPointer());
  for (std::size_t p = 0; p < data.Frames.size(); ++p)
  {
    pixels[p] = static_cast<unsigned char>(std::lround(255 * data.Frames[p]));
  }
  vtkNew<vtkDoubleArray> poses;
  poses->SetName("ImageToReference");
  poses->SetNumberOfComponents(16);
  for (const auto& m : data.Poses)
  {
    poses->InsertNextTuple(m.data());
  }
  sequence->GetFieldData()->AddArray(poses);
  return sequence;
}
} // namespace

TEST(GaussianFieldTrainer, PipelineOutputsTheFieldOfTheDataModel)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(150, 9), 0.5, heldOut);
  vtkSmartPointer<vtkImageData> sequence = TrackedSequence(data);

  vtkNew<vtkGaussianFieldTrainer> trainer;
  trainer->SetInputData(sequence);
  trainer->SetIterations(150);
  trainer->SetInitialGaussians(500);
  trainer->SetHoldOutEvery(4);
  trainer->SetHoldOutOffset(2);
  trainer->SetTrainingCutoff(4.5); // not the default (0, automatic): the setting line below shows it arrived
  int progressEvents = 0;
  vtkNew<vtkCallbackCommand> counter;
  counter->SetClientData(&progressEvents);
  counter->SetCallback([](vtkObject*, unsigned long, void* client, void*) { ++*static_cast<int*>(client); });
  trainer->AddObserver(vtkCommand::ProgressEvent, counter);
  // The settings are announced once, before any step.
  struct Announced
  {
    int Count = 0, IterationThen = -1;
    std::string Text;
  } announced;
  vtkNew<vtkCallbackCommand> settingsObserver;
  settingsObserver->SetClientData(&announced);
  settingsObserver->SetCallback([](vtkObject* caller, unsigned long, void* client, void*) {
    auto* a = static_cast<Announced*>(client);
    auto* t = static_cast<vtkGaussianFieldTrainer*>(caller);
    ++a->Count;
    a->IterationThen = t->GetCurrentIteration();
    a->Text = t->GetSettingsText();
  });
  trainer->AddObserver(vtkGaussianFieldTrainer::SettingsChosenEvent, settingsObserver);
  trainer->Update();
  vtkPolyData* field = trainer->GetOutput();
  const vtkIdType n = field->GetNumberOfPoints();
  EXPECT_EQ(n, trainer->GetNumberOfGaussians());
  // The merge (on by default) says what it took: "M pairs merged of N Gaussians ...", N - M = n.
  auto* merge = vtkStringArray::SafeDownCast(field->GetFieldData()->GetAbstractArray("GaussianMerge"));
  ASSERT_NE(merge, nullptr);
  long long merged = -1, before = -1;
  ASSERT_EQ(std::sscanf(merge->GetValue(0).c_str(), "%lld pairs merged of %lld Gaussians", &merged, &before), 2)
    << merge->GetValue(0);
  EXPECT_EQ(before - merged, n);
  EXPECT_GT(before, 400);
  EXPECT_GT(n, 200);
  EXPECT_EQ(field->GetNumberOfVerts(), n) << "one vertex per Gaussian, so it shows as a point cloud";
  for (const char* name : { "Scale", "Rotation", "Reflectivity" })
  {
    ASSERT_NE(field->GetPointData()->GetArray(name), nullptr) << name;
  }
  vtkDataArray* rotation = field->GetPointData()->GetArray("Rotation");
  for (vtkIdType i = 0; i < n; i += 37)
  {
    double q[4];
    rotation->GetTuple(i, q);
    EXPECT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0, 1e-5);
  }
  // ElevationSigma 0 (the default): chosen from the frames, stored and reported with the rule used.
  TrainingData trained = data;
  trained.TrainFrames.clear();
  for (int k = 0; k < data.Count(); ++k)
  {
    if (k % 4 != 2)
    {
      trained.TrainFrames.push_back(k);
    }
  }
  const ElevationSigmaChoice chosen = ChooseElevationSigma(trained);
  // (the filter measures the 8-bit frames inside the estimated fan mask, this the float frames)
  EXPECT_NEAR(field->GetFieldData()->GetArray("ElevationSigma")->GetTuple1(0), chosen.Sigma, 0.01 * chosen.Sigma);
  EXPECT_EQ(announced.Count, 1);
  EXPECT_EQ(announced.IterationThen, 0);
  auto* settings = vtkStringArray::SafeDownCast(field->GetFieldData()->GetAbstractArray("TrainingSettings"));
  ASSERT_NE(settings, nullptr);
  std::string stored;
  for (vtkIdType k = 0; k < settings->GetNumberOfValues(); ++k)
  {
    stored += settings->GetValue(k) + "\n";
  }
  // The lines announced before training, as stored: the run's later decisions rewrite the RefinePoses and
  // Validation lines (the pose-refinement trial) and the ParameterAverage line (which steps it averaged), and add
  // lines at the end (PoseAnchor).
  std::istringstream storedLines(stored), announcedLines(announced.Text);
  for (std::string said, kept; std::getline(announcedLines, said);)
  {
    ASSERT_TRUE(static_cast<bool>(std::getline(storedLines, kept))) << said;
    const std::string key = said.substr(0, said.find(" = ") + 3);
    EXPECT_TRUE(kept == said ||
      (kept.rfind(key, 0) == 0 && (key == "RefinePoses = " || key == "Validation = " || key == "ParameterAverage = ")))
      << "announced: " << said << "\nstored: " << kept;
  }
  for (const char* line : { "FanMask = estimated from the frames",
         "ElevationSigma = ", "(chosen: ", "Gamma = ", "InitialGaussians = 500 (given", "Iterations = 150",
         "Densification = every 200 steps", "Cutoff = 4.5,", "; made the field at step 150: " })
  {
    EXPECT_NE(stored.find(line), std::string::npos) << line << " not in\n" << stored;
  }
  vtkDataArray* frames = field->GetFieldData()->GetArray("TrainingFrames");
  ASSERT_NE(frames, nullptr);
  EXPECT_EQ(frames->GetNumberOfTuples(), 45);
  for (vtkIdType k = 0; k < frames->GetNumberOfTuples(); ++k)
  {
    EXPECT_NE(static_cast<int>(frames->GetTuple1(k)) % 4, 2) << "held-out frames are never trained on";
  }
  EXPECT_STREQ(trainer->GetStopReason(), "iterations");
  EXPECT_GT(progressEvents, 5);

  // AbortExecute stops a run early and still leaves a valid field.
  vtkNew<vtkGaussianFieldTrainer> aborted;
  aborted->SetInputData(sequence);
  aborted->SetIterations(100000);
  aborted->SetInitialGaussians(300);
  vtkNew<vtkCallbackCommand> stopper;
  stopper->SetCallback(
    [](vtkObject* caller, unsigned long, void*, void*) { static_cast<vtkAlgorithm*>(caller)->SetAbortExecute(1); });
  aborted->AddObserver(vtkCommand::ProgressEvent, stopper);
  aborted->Update();
  EXPECT_STREQ(aborted->GetStopReason(), "aborted");
  EXPECT_LT(aborted->GetCompletedIterations(), 100);

  // An explicit frame list with a frame the input does not have fails the request and names the frame.
  vtkNew<vtkGaussianFieldTrainer> listed;
  listed->SetInputData(sequence);
  listed->SetIterations(5);
  vtkNew<vtkIdList> list;
  list->InsertNextId(0);
  list->InsertNextId(data.Count());
  listed->SetTrainingFrameList(list);
  vtkNew<bigus_test::MessageCollector> messages;
  messages->Watch(listed);
  listed->Update();
  EXPECT_EQ(listed->GetOutput()->GetNumberOfPoints(), 0);
  ASSERT_EQ(messages->Errors.size(), 1u);
  EXPECT_NE(messages->Errors[0].find("frame " + std::to_string(data.Count()) + " is outside"), std::string::npos)
    << messages->Errors[0];
}

// EvaluationInterval's curve (HeldOutPSNR: seconds, dB, iteration) and what DescribeHeldOutPSNR reads in it: the
// best point and the last, and a fall from the best past 0.1 dB named as overfitting (the spine phantom's curve).
TEST(GaussianFieldTrainer, TheHeldOutCurveRecordsItsIterationsAndNamesAFallFromItsBest)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(150, 9), 0.5, heldOut);
  vtkNew<vtkGaussianFieldTrainer> trainer;
  trainer->SetInputData(TrackedSequence(data));
  trainer->SetIterations(60);
  trainer->SetInitialGaussians(300);
  trainer->SetHoldOutEvery(4);
  trainer->SetHoldOutOffset(2);
  trainer->SetEvaluationInterval(1e-9); // at every progress report (every 10 steps), and once after Finish
  trainer->Update();
  vtkDataArray* curve = trainer->GetOutput()->GetFieldData()->GetArray("HeldOutPSNR");
  ASSERT_NE(curve, nullptr);
  ASSERT_EQ(curve->GetNumberOfComponents(), 3);
  EXPECT_STREQ(curve->GetComponentName(2), "Iteration");
  const vtkIdType n = curve->GetNumberOfTuples();
  ASSERT_EQ(n, 7) << "steps 10 to 60, then the finished field";
  for (vtkIdType k = 0; k < n; ++k)
  {
    EXPECT_EQ(curve->GetComponent(k, 2), std::min<double>(10.0 * (k + 1), 60.0)) << k;
    EXPECT_GE(curve->GetComponent(k, 0), k > 0 ? curve->GetComponent(k - 1, 0) : 0.0) << k;
    EXPECT_TRUE(std::isfinite(curve->GetComponent(k, 1)) && curve->GetComponent(k, 1) > 0) << k;
  }
  EXPECT_NE(vtkGaussianFieldTrainer::DescribeHeldOutPSNR(curve).find("7 measurements: best "), std::string::npos);

  // The spine phantom's curve in short (docs/FINDINGS.md): best at step 860, 0.47 dB lower at the end.
  vtkNew<vtkDoubleArray> spine;
  spine->SetNumberOfComponents(3);
  for (const auto& row : std::vector<std::array<double, 3>>{
         { 0.1, 7.63, 10 }, { 16.0, 21.03, 860 }, { 70.0, 20.86, 1980 }, { 146.0, 20.56, 3000 } })
  {
    spine->InsertNextTuple(row.data());
  }
  const std::string said = vtkGaussianFieldTrainer::DescribeHeldOutPSNR(spine);
  for (const char* part : { "4 measurements: best 21.03 dB at iteration 860 (16 s); last 20.56 dB at iteration 3000 "
                            "(146 s), 0.47 dB below the best: more steps lowered the score",
         "a shorter schedule may score higher" })
  {
    EXPECT_NE(said.find(part), std::string::npos) << part << " not in " << said;
  }
  // Within 0.1 dB of the best, or rising to the end (the liver), no fall is named.
  spine->SetComponent(3, 1, 20.94);
  EXPECT_EQ(vtkGaussianFieldTrainer::DescribeHeldOutPSNR(spine).find("below the best"), std::string::npos);
  spine->SetComponent(3, 1, 21.50);
  EXPECT_NE(
    vtkGaussianFieldTrainer::DescribeHeldOutPSNR(spine).find("best 21.50 dB at iteration 3000"), std::string::npos);
  // A file written before the iteration column: seconds alone. No curve: nothing to say.
  vtkNew<vtkDoubleArray> old;
  old->SetNumberOfComponents(2);
  old->InsertNextTuple2(16.0, 21.03);
  old->InsertNextTuple2(146.0, 20.56);
  EXPECT_NE(vtkGaussianFieldTrainer::DescribeHeldOutPSNR(old).find("best 21.03 dB at 16 s; last 20.56 dB at 146 s, "
                                                                   "0.47 dB below"),
    std::string::npos)
    << vtkGaussianFieldTrainer::DescribeHeldOutPSNR(old);
  EXPECT_EQ(vtkGaussianFieldTrainer::DescribeHeldOutPSNR(nullptr), "");
  EXPECT_EQ(vtkGaussianFieldTrainer::DescribeHeldOutPSNR(vtkNew<vtkDoubleArray>()), "");
}

// HeldOutValidation reaches the run: On holds one in 8 of the 45 training frames out of the fit (the Validation line
// says so), Off validates on training frames; out of range is clamped to Auto.
TEST(GaussianFieldTrainer, HeldOutValidationDecidesWhichFramesValidate)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(150, 9), 0.5, heldOut);
  vtkSmartPointer<vtkImageData> sequence = TrackedSequence(data);
  // Held out with the measured tail (the default), held out without it, training frames.
  for (const auto& [mode, tail] : { std::make_pair(vtkGaussianFieldTrainer::HELD_OUT_VALIDATION_ON, true),
         std::make_pair(vtkGaussianFieldTrainer::HELD_OUT_VALIDATION_ON, false),
         std::make_pair(vtkGaussianFieldTrainer::HELD_OUT_VALIDATION_OFF, true) })
  {
    vtkNew<vtkGaussianFieldTrainer> trainer;
    EXPECT_TRUE(trainer->GetMeasuredTail());
    trainer->SetMeasuredTail(tail);
    trainer->SetInputData(sequence);
    trainer->SetIterations(20);
    trainer->SetInitialGaussians(300);
    trainer->SetHoldOutEvery(4);
    trainer->SetHoldOutOffset(2);
    trainer->SetHeldOutValidation(mode);
    trainer->Update();
    auto* settings =
      vtkStringArray::SafeDownCast(trainer->GetOutput()->GetFieldData()->GetAbstractArray("TrainingSettings"));
    ASSERT_NE(settings, nullptr);
    std::string line;
    for (vtkIdType k = 0; k < settings->GetNumberOfValues(); ++k)
    {
      line = settings->GetValue(k).rfind("Validation = ", 0) == 0 ? settings->GetValue(k) : line;
    }
    EXPECT_EQ(line.rfind(mode == vtkGaussianFieldTrainer::HELD_OUT_VALIDATION_ON
                  ? "Validation = 5 held-out frames (one in 8 training frames of a sweep"
                  : "Validation = 8 training frames",
                0),
      0u)
      << line;
    const bool said = line.find("the run stops as many steps after the join as the fit took to that field (measured "
                                "tail)") != std::string::npos;
    EXPECT_EQ(said, mode == vtkGaussianFieldTrainer::HELD_OUT_VALIDATION_ON && tail) << line;
  }
  vtkNew<vtkGaussianFieldTrainer> clamped;
  clamped->SetHeldOutValidation(7);
  EXPECT_EQ(clamped->GetHeldOutValidation(), vtkGaussianFieldTrainer::HELD_OUT_VALIDATION_AUTO);
}

// The rules on sparse real sweeps (docs/FINDINGS.md, "A sparse sweep's beam"): the liver's training frames (i mod 4
// != 2) taken one in 3 (2.29 mm apart) and one in 4 (3.03 mm), with the fan mask the trainer estimates. Their speckle
// decorrelates over the liver's beam (sigma about 0.8 mm, as every frame's) although the first bin, where tilted frames
// cross, lies lower than the next: the beam is the fit's (0.4 x its sigma), not the frame spacing, which scored 1.2 dB
// lower held out on both. Neither shares speckle at its spacing (the one in 4 measures below 0): the validation frames
// are held out of the fit. The seeds span half the frames' spacing across their frame, wider than that beam
// (SeedingSettings::ElevationSpacingFactor; docs/FINDINGS.md, "Seeds across a sparse sweep's gaps"): the spacing
// checked here from the poses alone.
TEST(GaussianFieldTrainer, ASparseSweepTakesTheBeamItsSpeckleMeasures)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(bigus_test::ExamplePath("liver/liver_sweep.igs.mha").c_str());
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputConnection(reader->GetOutputPort());
  fan->Update();
  TrainingData data;
  std::string error;
  ASSERT_TRUE(TrainingDataFromSequence(reader->GetOutput(), fan->GetOutput(), data, &error)) << error;
  std::vector<int> training;
  for (int i = 0; i < data.Count(); ++i)
  {
    if (i % 4 != 2)
    {
      training.push_back(i);
    }
  }
  for (const int stride : { 3, 4 })
  {
    data.TrainFrames.clear();
    for (std::size_t k = 0; k < training.size(); k += stride)
    {
      data.TrainFrames.push_back(training[k]);
    }
    const std::vector<SweepDecorrelation> measured = MeasureSweeps(data);
    ASSERT_TRUE(measured[0].Measured) << measured[0].Error;
    const ElevationDecorrelation& m = measured[0].Measurement;
    const ElevationSigmaChoice beam = ChooseElevationSigma(measured);
    std::printf("one in %d: %.3f mm apart, decorrelation sigma %.3f mm, fit's correlation at 0 mm %.3f, first bin "
                "%.3f at %.2f mm; %s\n",
      stride, m.NeighbourSpacing, m.DecorrelationSigma, m.ZeroDistanceCorrelation, m.Correlation.front(),
      m.Distance.front(), beam.Reason.c_str());
    EXPECT_GT(m.NeighbourSpacing, 2.0) << stride;
    EXPECT_GT(m.DecorrelationSigma, 0.6) << stride;
    EXPECT_LT(m.DecorrelationSigma, 1.0) << stride;
    EXPECT_GE(m.ZeroDistanceCorrelation, 0.4) << stride;
    EXPECT_NEAR(beam.Sigma, ElevationSigmaDecorrelationFactor * m.DecorrelationSigma, 1e-12) << beam.Reason;
    std::string reason;
    EXPECT_TRUE(HoldOutValidationByRule(measured, reason)) << reason;
    // The median over the fan pixels of consecutive training frames (every 8th column and row) of the distance from
    // either's pixel to the other's plane, from the poses alone.
    std::vector<double> gaps;
    auto addGaps = [&](int from, int to) {
      const std::array<double, 16>& a = data.Poses[from];
      const std::array<double, 16>& b = data.Poses[to];
      const double n[3] = { b[4] * b[9] - b[8] * b[5], b[8] * b[1] - b[0] * b[9], b[0] * b[5] - b[4] * b[1] };
      const double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      const unsigned char* mask = data.MaskOf(from);
      for (int j = 0; j < data.Height; j += 8)
      {
        for (int i = 0; i < data.Width; i += 8)
        {
          if (!mask[std::size_t(j) * data.Width + i])
          {
            continue;
          }
          double z = 0;
          for (int r = 0; r < 3; ++r)
          {
            z += (a[4 * r] * i + a[4 * r + 1] * j + a[4 * r + 3] - b[4 * r + 3]) * n[r] / length;
          }
          gaps.push_back(std::abs(z));
        }
      }
    };
    for (std::size_t k = 0; k + 1 < data.TrainFrames.size(); ++k)
    {
      addGaps(data.TrainFrames[k], data.TrainFrames[k + 1]);
      addGaps(data.TrainFrames[k + 1], data.TrainFrames[k]);
    }
    std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
    const double spacing = gaps[gaps.size() / 2];
    TrainerSettings settings;
    settings.Seeding.InitialGaussians = 2000;
    Trainer trainer(data, settings);
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    const GaussianField& seeds = trainer.GetField();
    ASSERT_EQ(seeds.Count(), 2000);
    for (std::int64_t i = 0; i < seeds.Count(); ++i)
    {
      ASSERT_NEAR(std::exp(seeds.LogScales[3 * i + 2]), 0.5 * spacing, 0.02 * spacing)
        << "seed " << i << "; spacing " << spacing << " mm from the poses, " << m.NeighbourSpacing << " measured";
    }
    const std::vector<std::string>& lines = trainer.GetReport().Settings;
    EXPECT_TRUE(std::any_of(lines.begin(), lines.end(), [](const std::string& l) {
      return l.rfind("InitialGaussians = 2000 (given; Harris seeding, ", 0) == 0 &&
        l.find("mm across their frame: 0.5 x the training frames' spacing") != std::string::npos;
    }));
  }
}

// A slice downstream of the trainer asks for its own small extent: the reader still reads every frame,
// and the field, being points, does not carry the sequence's WHOLE_EXTENT (the executive copies it by
// default; an image filter after the field that fails its RequestInformation kept it, and ParaView then
// rendered the next valid slice on the sequence's 200 x 150 x 20 grid).
TEST(GaussianFieldTrainer, ASliceDownstreamDoesNotCropTheSequence)
{
  const std::string dir = std::string(BIGUS_TEST_DATA) + "/nwire-phantom/";
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName((dir + "NwirePhantomFreehandCropped.igs.mha").c_str());
  reader->SetCalibrationFileName((dir + "PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml").c_str());
  vtkNew<vtkGaussianFieldTrainer> trainer;
  trainer->SetInputConnection(reader->GetOutputPort());
  trainer->SetIterations(20);
  trainer->SetInitialGaussians(300);
  trainer->SetElevationSigma(0.5);
  trainer->SetHoldOutEvery(4);
  trainer->SetHoldOutOffset(2);
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputConnection(trainer->GetOutputPort());
  reslice->SetOutputSpacing(0.1, 0.1, 1);
  reslice->SetOutputOrigin(0, 0, 0);
  reslice->SetOutputExtent(0, 9, 0, 7, 0, 0);
  reslice->Update();

  int dims[3];
  reader->GetOutput()->GetDimensions(dims);
  EXPECT_EQ(dims[0], 200);
  EXPECT_EQ(dims[1], 150);
  EXPECT_EQ(dims[2], 20);
  vtkDataArray* poses = trainer->GetOutput()->GetFieldData()->GetArray("TrainingPoses");
  ASSERT_NE(poses, nullptr);
  EXPECT_EQ(poses->GetNumberOfTuples(), 15); // 20 frames, k mod 4 == 2 held out
  EXPECT_FALSE(trainer->GetOutputInformation(0)->Has(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT()));
  reslice->GetOutput()->GetDimensions(dims);
  EXPECT_EQ(dims[0], 10);
  EXPECT_EQ(dims[1], 8);
}
