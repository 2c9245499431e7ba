// `bigus merge`: merge neighbouring Gaussians of a trained field (bigus::MergeGaussians).
#include "bigusCommandLine.h"
#include "bigusGaussianFieldData.h"
#include "bigusGaussianMerging.h"
#include "vtkFieldData.h"
#include "vtkNew.h"
#include "vtkPolyData.h"
#include "vtkStringArray.h"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>

namespace bigus::cli
{
namespace
{
struct MergeOptions
{
  std::string Field, Output;
  bigus::GaussianMergeSettings Settings;
};

int RunMerge(const MergeOptions& o)
{
  vtkSmartPointer<vtkPolyData> input = ReadField(o.Field);
  if (!input)
  {
    return 1;
  }
  bigus::GaussianField field;
  bigus::FieldModel model;
  std::string error;
  if (!bigus::FieldFromPolyData(input, field, model, &error))
  {
    return Fail(o.Field + ": " + error);
  }
  const bigus::GaussianMergeReport report = bigus::MergeGaussians(field, o.Settings);
  vtkNew<vtkPolyData> output;
  bigus::FieldToPolyData(field, model, output);
  output->GetFieldData()->PassData(input->GetFieldData());
  vtkNew<vtkStringArray> note;
  note->SetName("GaussianMerge");
  const std::string text = bigus::DescribeGaussianMerge(report, o.Settings);
  note->InsertNextValue(text);
  output->GetFieldData()->AddArray(note);
  if (WriteField(output, o.Output) != 0)
  {
    return 1;
  }
  std::printf("%s: %lld Gaussians, %s\n", o.Output.c_str(), static_cast<long long>(field.Count()), text.c_str());
  return 0;
}
}

Command AddMergeCommand(CLI::App& app)
{
  auto options = std::make_shared<MergeOptions>();
  MergeOptions& merge = *options;
  merge.Settings.Tolerance = 0.01;
  CLI::App* mergeCommand = app.add_subcommand("merge",
    "Merge neighbouring Gaussians of a field that one Gaussian represents (moment-matched pairs whose relative "
    "integrated squared error stays below the tolerance): a smaller field that renders nearly as before");
  mergeCommand->add_option("FIELD", merge.Field, "Gaussian field (.vtp)")->required()->check(CLI::ExistingFile);
  mergeCommand->add_option("-o,--output", merge.Output, "Field to write (.vtp)")->required();
  mergeCommand
    ->add_option("--tolerance", merge.Settings.Tolerance,
      "Largest relative integrated squared error of a merge, ||a + b - merged||^2 / ||a + b||^2 over 3D")
    ->capture_default_str()
    ->check(CLI::PositiveNumber);
  mergeCommand
    ->add_option("--neighbours", merge.Settings.Neighbours,
      "Candidates of each Gaussian: the Gaussians with the nearest centres")
    ->capture_default_str()
    ->check(CLI::PositiveNumber);
  mergeCommand
    ->add_option("--passes", merge.Settings.MaximumPasses,
      "Most passes over the field (each merges a Gaussian once); errors add up over passes")
    ->capture_default_str()
    ->check(CLI::PositiveNumber);
  return { mergeCommand, [options] {
    MergeOptions& merge = *options;
    if (merge.Output == merge.Field)
    {
      return Fail(merge.Output + ": the output would overwrite the input field");
    }
    return RunMerge(merge);
  } };
}

} // namespace bigus::cli
