// `bigus render`: render a field at sweep poses, a plane or a volume.
#include "bigusCommandLine.h"
#include "bigusGaussianFieldData.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkGaussianFieldSequenceRenderer.h"
#include "vtkIdList.h"
#include "vtkNew.h"
#include "vtkUltrasoundSequenceWriter.h"

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace bigus::cli
{
namespace
{
struct RenderOptionsCli
{
  std::string Field, Output;
  SweepOptions Poses;
  std::vector<int> Frames;
  std::vector<double> Plane;
  std::vector<int> Size = { 512, 512 };
  double Spacing = 0;
  bool Volume = false;
  std::string Backend = "auto";
};

int RunRender(const RenderOptionsCli& o)
{
  if (CheckOutputs({ o.Output }, { o.Field, o.Poses.Sweep, o.Poses.Calibration }) != 0)
  {
    return 1;
  }
  auto field = ReadField(o.Field);
  if (!field)
  {
    return 1;
  }
  if (!o.Poses.Sweep.empty())
  {
    auto reader = ReadSweep(o.Poses);
    if (!reader)
    {
      return 1;
    }
    vtkNew<vtkGaussianFieldSequenceRenderer> renderer;
    renderer->SetInputData(field);
    renderer->SetPoseConnection(reader->GetOutputPort());
    renderer->SetBackend(o.Backend.c_str());
    renderer->SetOutputScalarTypeToUnsignedChar();
    vtkNew<vtkIdList> frames;
    for (int f : o.Frames)
    {
      frames->InsertNextId(f);
    }
    renderer->SetFrameList(frames);
    FilterError error;
    error.Watch(renderer);
    renderer->Update();
    if (renderer->GetOutput()->GetNumberOfPoints() == 0)
    {
      return Fail("rendering failed: " + error.Or("no frames"));
    }
    vtkNew<vtkUltrasoundSequenceWriter> writer;
    writer->SetInputConnection(renderer->GetOutputPort());
    writer->SetFileName(o.Output.c_str());
    writer->Write();
    if (*writer->GetLastErrorText())
    {
      return Fail(writer->GetLastErrorText());
    }
    std::printf("rendered %d frames (%.1f ms each) to %s\n", renderer->GetOutput()->GetDimensions()[2],
      1e3 * renderer->GetSecondsPerFrame(), o.Output.c_str());
    return 0;
  }
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(field);
  reslice->SetBackend(o.Backend.c_str());
  if (o.Spacing > 0)
  {
    reslice->SetOutputSpacing(o.Spacing, o.Spacing, o.Spacing);
  }
  if (o.Volume)
  {
    reslice->SetOutputDimensionality(3);
  }
  else
  {
    if (o.Plane.size() != 6)
    {
      return Fail("render: give --poses SWEEP, --plane OX OY OZ NX NY NZ, or --volume");
    }
    // Plane axes: the normal n; x = a unit vector perpendicular to n; y = n x x.
    double n[3] = { o.Plane[3], o.Plane[4], o.Plane[5] };
    const double nn = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(nn > 0))
    {
      return Fail("--plane: the normal must not be zero");
    }
    for (double& v : n)
    {
      v /= nn;
    }
    const double helper[3] = { std::abs(n[0]) < 0.9 ? 1.0 : 0.0, std::abs(n[0]) < 0.9 ? 0.0 : 1.0, 0.0 };
    double x[3] = { helper[1] * n[2] - helper[2] * n[1], helper[2] * n[0] - helper[0] * n[2],
      helper[0] * n[1] - helper[1] * n[0] };
    const double nx = std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    for (double& v : x)
    {
      v /= nx;
    }
    const double y[3] = { n[1] * x[2] - n[2] * x[1], n[2] * x[0] - n[0] * x[2], n[0] * x[1] - n[1] * x[0] };
    reslice->SetResliceAxesDirectionCosines(x[0], x[1], x[2], y[0], y[1], y[2], n[0], n[1], n[2]);
    reslice->SetResliceAxesOrigin(o.Plane[0], o.Plane[1], o.Plane[2]);
    const double spacing = o.Spacing > 0 ? o.Spacing : 0.25;
    reslice->SetOutputSpacing(spacing, spacing, 1);
    reslice->SetOutputOrigin(-0.5 * spacing * (o.Size[0] - 1), -0.5 * spacing * (o.Size[1] - 1), 0);
    reslice->SetOutputExtent(0, o.Size[0] - 1, 0, o.Size[1] - 1, 0, 0);
  }
  if (EndsWith(o.Output, ".png"))
  {
    reslice->SetOutputScalarTypeToUnsignedChar();
  }
  FilterError error;
  error.Watch(reslice);
  reslice->Update();
  if (reslice->GetOutput()->GetNumberOfPoints() == 0)
  {
    return Fail("rendering failed: " + error.Or("empty slice"));
  }
  if (WriteImage(reslice->GetOutput(), o.Output) != 0)
  {
    return 1;
  }
  int dims[3];
  reslice->GetOutput()->GetDimensions(dims);
  std::printf("rendered %d x %d x %d to %s\n", dims[0], dims[1], dims[2], o.Output.c_str());
  return 0;
}
}

Command AddRenderCommand(CLI::App& app)
{
  auto options = std::make_shared<RenderOptionsCli>();
  RenderOptionsCli& render = *options;
  CLI::App* renderCommand = app.add_subcommand("render", "Render a field at sweep poses, a plane or a volume");
  renderCommand->add_option("FIELD", render.Field, "Gaussian field (.vtp)")->required()->check(CLI::ExistingFile);
  renderCommand->add_option("-o,--output", render.Output, "Output: .igs.mha (poses), .png/.mha (plane), .mha/.vti")
    ->required();
  renderCommand->add_option("--poses", render.Poses.Sweep, "Render at the poses of this sweep")
    ->check(CLI::ExistingFile);
  AddSweepOptions(renderCommand, render.Poses, "pose sweep");
  renderCommand->add_option("--frames", render.Frames, "Frames of the pose sweep (default: all)");
  renderCommand->add_option("--plane", render.Plane, "Plane origin and normal, mm: OX OY OZ NX NY NZ")
    ->expected(6)
    ->check(FiniteRange(-1e9, 1e9));
  renderCommand->add_option("--size", render.Size, "Plane size in pixels: W H (1 to 65536 each)")
    ->expected(2)
    ->check(FiniteRange(1, 65536));
  renderCommand->add_option("--spacing", render.Spacing, "Pixel spacing, mm (default: the field's)")
    ->check(FinitePositive(1e6));
  renderCommand->add_option("--backend", render.Backend, "Rendering backend: auto, cpu or cuda (as registered)");
  renderCommand->add_flag("--volume", render.Volume, "Render a stack of parallel slices covering the field");
  return { renderCommand, [options] {
            RenderOptionsCli& render = *options;
            return RunRender(render);
          } };
}

} // namespace bigus::cli
