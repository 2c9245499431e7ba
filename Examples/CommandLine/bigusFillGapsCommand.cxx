// `bigus fill-gaps`: bridge the gaps between a field's training frames.
#include "bigusCommandLine.h"
#include "bigusGapFilling.h"
#include "bigusGaussianFieldData.h"
#include "bigusPlot.h"
#include "vtkFieldData.h"
#include "vtkNew.h"
#include "vtkPolyData.h"
#include "vtkStringArray.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <memory>
#include <numeric>
#include <string>

namespace bigus::cli
{
namespace
{
struct FillGapsOptions
{
  std::string Field, Output;
  bigus::GapFillingSettings Settings;
};

int RunFillGaps(const FillGapsOptions& o)
{
  vtkSmartPointer<vtkPolyData> input = ReadField(o.Field);
  if (!input)
  {
    return 1;
  }
  bigus::GaussianField field;
  bigus::FieldModel model;
  bigus::TrainingGeometry geometry;
  std::string error;
  if (!bigus::FieldFromPolyData(input, field, model, &error) ||
    !bigus::TrainingGeometryFromFieldData(input->GetFieldData(), geometry, &error))
  {
    return Fail(o.Field + ": " + error);
  }
  if (geometry.Poses.empty())
  {
    return Fail(o.Field +
      ": no field data TrainingPoses (a field trained before they were stored): the gaps "
      "between training frames are unknown");
  }
  bigus::TrainingData frames;
  frames.Width = geometry.Width;
  frames.Height = geometry.Height;
  frames.Poses = geometry.Poses;
  frames.TrainFrames.resize(geometry.Poses.size());
  std::iota(frames.TrainFrames.begin(), frames.TrainFrames.end(), 0);
  const std::int64_t before = field.Count();
  const bigus::GapFillingReport report = bigus::FillElevationGaps(field, frames, model.ElevationSigma, o.Settings);
  vtkNew<vtkPolyData> output;
  bigus::FieldToPolyData(field, model, output);
  output->GetFieldData()->PassData(input->GetFieldData());
  vtkNew<vtkStringArray> note;
  note->SetName("GapFilling");
  const std::string text = bigus::DescribeGapFilling(report, o.Settings);
  note->InsertNextValue(text);
  output->GetFieldData()->AddArray(note);
  if (WriteField(output, o.Output) != 0)
  {
    return 1;
  }
  std::printf(
    "%s: %lld Gaussians, %s\n", o.Output.c_str(), static_cast<long long>(before + report.Added), text.c_str());
  return 0;
}
}

Command AddFillGapsCommand(CLI::App& app)
{
  auto options = std::make_shared<FillGapsOptions>();
  FillGapsOptions& fillGaps = *options;
  CLI::App* fillGapsCommand = app.add_subcommand("fill-gaps",
    "Bridge the gaps between a field's training frames (wider than the beam) with copies of the Gaussians of the "
    "frames on either side, blended linearly across the gap");
  fillGapsCommand->add_option("FIELD", fillGaps.Field, "Gaussian field (.vtp) with its training geometry")
    ->required()
    ->check(CLI::ExistingFile);
  fillGapsCommand->add_option("-o,--output", fillGaps.Output, "Field to write (.vtp)")->required();
  fillGapsCommand
    ->add_option("--minimum-gap", fillGaps.Settings.MinimumGapSpacings,
      "A gap: consecutive training frames further apart than this many typical frame spacings")
    ->capture_default_str()
    ->check(FinitePositive());
  fillGapsCommand
    ->add_option("--clearance", fillGaps.Settings.ClearanceSigmas,
      "Copies stay this many beam widths away from the frames on either side")
    ->capture_default_str()
    ->check(FiniteNonNegative());
  fillGapsCommand
    ->add_option("--blend-margin", fillGaps.Settings.BlendMarginSigmas,
      "Within this many beam widths of a frame (at most a quarter of the gap) the copies carry that frame alone; "
      "between the margins the blend is linear")
    ->capture_default_str()
    ->check(FiniteNonNegative());
  fillGapsCommand
    ->add_option("--max-gaussians", fillGaps.Settings.MaximumGaussians,
      "The most Gaussians the filled field may hold (0: no limit); where a gap's copies would exceed it, only the "
      "strongest Gaussians of its two frames whose copies fit are copied")
    ->capture_default_str()
    ->check(FiniteNonNegative());
  return { fillGapsCommand, [options] {
            FillGapsOptions& fillGaps = *options;
            if (fillGaps.Output == fillGaps.Field)
            {
              return Fail(fillGaps.Output + ": the output would overwrite the input field");
            }
            return RunFillGaps(fillGaps);
          } };
}

} // namespace bigus::cli
