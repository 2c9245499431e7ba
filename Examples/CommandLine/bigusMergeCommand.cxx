// `bigus merge`: merge neighbouring Gaussians of a trained field (vtkGaussianFieldMerge).
#include "bigusCommandLine.h"
#include "vtkAbstractArray.h"
#include "vtkFieldData.h"
#include "vtkGaussianFieldMerge.h"
#include "vtkNew.h"
#include "vtkPolyData.h"

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
  double Tolerance = 0;
  int Neighbours = 0, Passes = 0;

  /// The filter's own defaults, so that `bigus merge` and vtkGaussianFieldMerge agree.
  MergeOptions()
  {
    vtkNew<vtkGaussianFieldMerge> defaults;
    this->Tolerance = defaults->GetTolerance();
    this->Neighbours = defaults->GetNeighbours();
    this->Passes = defaults->GetMaximumPasses();
  }
};

int RunMerge(const MergeOptions& o)
{
  vtkSmartPointer<vtkPolyData> input = ReadField(o.Field);
  if (!input)
  {
    return 1;
  }
  vtkNew<vtkGaussianFieldMerge> merge;
  FilterError error;
  error.Watch(merge);
  merge->SetInputData(input);
  merge->SetTolerance(o.Tolerance);
  merge->SetNeighbours(o.Neighbours);
  merge->SetMaximumPasses(o.Passes);
  merge->Update();
  vtkPolyData* output = merge->GetOutput();
  vtkAbstractArray* note = output->GetFieldData()->GetAbstractArray("GaussianMerge");
  if (!note || output->GetNumberOfPoints() == 0)
  {
    return Fail(o.Field + ": " + error.Or("the merge failed"));
  }
  if (WriteField(output, o.Output) != 0)
  {
    return 1;
  }
  std::printf("%s: %lld Gaussians, %s\n", o.Output.c_str(), static_cast<long long>(output->GetNumberOfPoints()),
    note->GetVariantValue(0).ToString().c_str());
  return 0;
}
}

Command AddMergeCommand(CLI::App& app)
{
  auto options = std::make_shared<MergeOptions>();
  MergeOptions& merge = *options;
  CLI::App* mergeCommand = app.add_subcommand("merge",
    "Merge neighbouring Gaussians of a field that one Gaussian represents (moment-matched pairs whose relative "
    "integrated squared error stays below the tolerance): a smaller field that renders nearly as before");
  mergeCommand->add_option("FIELD", merge.Field, "Gaussian field (.vtp)")->required()->check(CLI::ExistingFile);
  mergeCommand->add_option("-o,--output", merge.Output, "Field to write (.vtp)")->required();
  mergeCommand
    ->add_option("--tolerance", merge.Tolerance,
      "Largest relative integrated squared error of a merge, ||a + b - merged||^2 / ||a + b||^2 over 3D")
    ->capture_default_str()
    ->check(FiniteRange(1e-12, 1.0));
  mergeCommand
    ->add_option(
      "--neighbours", merge.Neighbours, "Candidates of each Gaussian: the Gaussians with the nearest centres")
    ->capture_default_str()
    ->check(FiniteRange(1, 64));
  mergeCommand
    ->add_option(
      "--passes", merge.Passes, "Most passes over the field (each merges a Gaussian once); errors add up over passes")
    ->capture_default_str()
    ->check(FiniteRange(1, 100));
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
