// `bigus benchmark`: several sweeps into one field (issue 33) on the volume protocol: the parallel training sweep
// and an orthogonal sweep of the spine-phantom reconstruction, scored on the oblique and in-between test slices
// against compounding both sweeps and against each single sweep's stack resliced (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"
#include "bigusGaussianFieldData.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkUltrasoundSequenceReslice.h"
#include "vtkUltrasoundVolumeCompounder.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace bigus::benchmark
{
namespace
{
/// The reslices of @p volume at the test sweeps @p tests (of @p vp) into @p rows (method, time given).
void ResliceAt(vtkImageData* volume, const VolumeProtocol& vp, const int tests[2], Row rows[2])
{
  for (int t = 0; t < 2; ++t)
  {
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputData(volume);
    reslice->SetPoseConnection(vp.Tests[tests[t]]->GetOutputPort());
    reslice->MaskEmptyVoxelsOff();
    const double t0 = Now();
    reslice->Update();
    rows[t].MsPerFrame = 1e3 * (Now() - t0) / vp.TestList[tests[t]].size();
    rows[t].Quality = Score(
      static_cast<float*>(reslice->GetOutput()->GetScalarPointer()), 1.0, vp.TestData[tests[t]], vp.TestList[tests[t]]);
  }
}

/**
 * A parallel sweep of vtkUltrasoundVolumeSweep (frames on the volume's axes, pixel centres on voxel centres)
 * as the volume it samples: compounded on its own grid (pixel spacing in plane, slice spacing across; one
 * pixel per voxel, no hole filling), so that reslicing it is the stacked slices resliced trilinearly.
 */
vtkSmartPointer<vtkImageData> Stack(vtkUltrasoundVolumeSweep* sweep)
{
  vtkImageData* frames = sweep->GetOutput();
  int dims[3];
  frames->GetDimensions(dims);
  double first[16], second[16];
  vtkDataArray* poses = frames->GetFieldData()->GetArray("ImageToReference");
  poses->GetTuple(0, first);
  poses->GetTuple(1, second);
  double spacing[3], origin[3];
  int extent[6];
  for (int c = 0; c < 3; ++c)
  {
    origin[c] = first[4 * c + 3];
    // Along the frames' columns, rows or normal: that axis's pixel spacing or the slice spacing.
    const double u = first[4 * c], v = first[4 * c + 1];
    const int size = std::abs(u) > 0 ? dims[0] : (std::abs(v) > 0 ? dims[1] : dims[2]);
    spacing[c] =
      std::abs(u) > 0 ? std::abs(u) : (std::abs(v) > 0 ? std::abs(v) : std::abs(second[4 * c + 3] - first[4 * c + 3]));
    extent[2 * c] = 0;
    extent[2 * c + 1] = size - 1;
  }
  vtkNew<vtkUltrasoundVolumeCompounder> stack;
  stack->SetInputConnection(sweep->GetOutputPort());
  stack->SetFanMaskConnection(sweep->GetMaskOutputPort());
  stack->SetOutputSpacing(spacing);
  stack->SetOutputOrigin(origin);
  stack->SetOutputExtent(extent);
  stack->FillHolesOff();
  stack->Update();
  vtkSmartPointer<vtkImageData> volume = stack->GetOutput();
  return volume;
}
}

bool SeveralSweepsSection(BenchmarkContext& context, std::string* error)
{
  const bool quick = context.Quick;
  Report& report = context.Report;
  std::ostringstream& md = report.Markdown;
  VolumeProtocol vp;
  if (!MakeVolumeProtocol(context.Root, quick, vp, error))
  {
    return false;
  }
  // The second sweep: orthogonal slices (along x) midway between the orthogonal test slices.
  auto orthogonal = vtkSmartPointer<vtkUltrasoundVolumeSweep>::New();
  orthogonal->SetInputData(vp.Volume);
  orthogonal->SetProtocolToOrthogonal();
  orthogonal->SetNumberOfFrames(quick ? 10 : 40);
  orthogonal->SetOffset(0.5);
  orthogonal->Update();
  TrainingData both;
  if (!TrainingDataFromSweeps({ { vp.Train->GetOutput(), vp.Train->GetMaskOutput(), "parallel sweep" },
                                { orthogonal->GetOutput(), orthogonal->GetMaskOutput(), "orthogonal sweep" } },
        both, error))
  {
    return Failed("several sweeps: " + *error, error);
  }
  for (int k = 0; k < both.Count(); ++k)
  {
    both.TrainFrames.push_back(k);
  }
  const int tests[2] = { 1, 0 }; // oblique, in-between parallel
  const char* testNames[2] = { "oblique slices (tilt up to 30 degrees)", "in-between parallel slices" };
  std::vector<Row> rows[2];
  auto add = [&](const Row pair[2]) {
    for (int t = 0; t < 2; ++t)
    {
      rows[t].push_back(pair[t]);
      Print(std::string("sweeps, ") + testNames[t], pair[t]);
    }
  };
  // Compounding: each sweep alone and both, at 0.5 mm with hole filling, resliced trilinearly.
  for (int which = 0; which < 3; ++which)
  {
    vtkNew<vtkUltrasoundVolumeCompounder> compound;
    if (which != 1)
    {
      compound->AddInputConnection(0, vp.Train->GetOutputPort());
      compound->AddInputConnection(1, vp.Train->GetMaskOutputPort());
    }
    if (which != 0)
    {
      compound->AddInputConnection(0, orthogonal->GetOutputPort());
      compound->AddInputConnection(1, orthogonal->GetMaskOutputPort());
    }
    compound->SetOutputSpacing(0.5, 0.5, 0.5);
    const double t0 = Now();
    compound->Update();
    Row pair[2];
    const char* names[3] = { "compounded, parallel sweep only", "compounded, orthogonal sweep only",
      "compounded, both sweeps" };
    for (Row& r : pair)
    {
      r.Method = std::string(names[which]) + " + trilinear reslice";
      r.Seconds = Now() - t0;
    }
    ResliceAt(compound->GetOutput(), vp, tests, pair);
    add(pair);
  }
  // Each sweep's own stack of slices, resliced.
  for (vtkUltrasoundVolumeSweep* sweep : { vp.Train.Get(), orthogonal.Get() })
  {
    const double t0 = Now();
    vtkSmartPointer<vtkImageData> stack = Stack(sweep);
    Row pair[2];
    for (Row& r : pair)
    {
      r.Method =
        std::string(sweep == vp.Train ? "parallel" : "orthogonal") + " sweep's slices stacked, trilinear reslice";
      r.Seconds = Now() - t0;
    }
    ResliceAt(stack, vp, tests, pair);
    add(pair);
  }
  // BIGUS on both sweeps: the defaults with a time budget, and training from Harris seeds scored at time marks.
  auto score = [&](Trainer& trainer, const Row& row) {
    Row pair[2] = { row, row };
    for (int t = 0; t < 2; ++t)
    {
      double secondsPerFrame = 0;
      if (!trainer.EvaluateOn(vp.TestData[tests[t]], vp.TestList[tests[t]], pair[t].Quality, error, &secondsPerFrame))
      {
        return false;
      }
      pair[t].MsPerFrame = 1e3 * secondsPerFrame;
    }
    add(pair);
    return true;
  };
  TrainerSettings defaults;
  defaults.Iterations = 0;
  defaults.TimeBudget = quick ? 4 : 120;
  Row row;
  if (!TrainToBudget(
        both, defaults, "BIGUS defaults on both sweeps, budget " + Format("%.0f", defaults.TimeBudget) + " s", row,
        [&](Trainer& trainer, Row& r) { return score(trainer, r); }, error))
  {
    return Failed("several sweeps: " + *error, error);
  }
  const std::vector<double> marks = quick ? std::vector<double>{ 4 } : std::vector<double>{ 60, 300, 600 };
  TrainerSettings adam;
  adam.Seeding.PixelGridFit = false;
  adam.Iterations = 0;
  adam.TimeBudget = marks.back();
  if (!TrainWithMarks(
        both, adam, marks, {}, "BIGUS on both sweeps, Harris seeds and Adam",
        [&](double, const Row& mark, Trainer& trainer) { return score(trainer, mark); }, error))
  {
    return Failed("several sweeps: " + *error, error);
  }
  md << "\n## Several sweeps into one field (volume protocol)\n\n"
     << "Two sweeps through the spine-phantom reconstruction along different paths: the volume protocol's "
     << vp.TrainData.Count() << " parallel training slices (frames of " << vp.TrainData.Width << " x "
     << vp.TrainData.Height << ") and " << orthogonal->GetNumberOfFrames()
     << " orthogonal slices along x midway between the orthogonal test slices (frames of "
     << orthogonal->GetOutput()->GetDimensions()[0] << " x " << orthogonal->GetOutput()->GetDimensions()[1]
     << "), trained into one field (`bigus train PARALLEL ORTHOGONAL`). Scored on test slices neither sweep "
     << "holds, against compounding both sweeps (and each alone) and against each sweep's own slices stacked "
     << "into a volume and resliced trilinearly. " << vp.Description
     << " Here BIGUS chooses its elevation sigma from the sweeps, as `bigus train` does (the note column).\n";
  nlohmann::json j;
  for (int t = 0; t < 2; ++t)
  {
    md << "\n### " << testNames[t] << "\n\n" << TableHeader();
    for (const Row& r : rows[t])
    {
      md << TableRow(r);
      j[testNames[t]].push_back(ToJson(r));
    }
  }
  report.Json["several_sweeps"] = j;
  return true;
}
}
