// `bigus sweep`: build a tracked sweep with exact poses from a 3D volume (the volume protocol).
#include "bigusCommandLine.h"
#include "bigusPlot.h"
#include "vtkAlgorithm.h"
#include "vtkDataArray.h"
#include "vtkImageData.h"
#include "vtkMetaImageReader.h"
#include "vtkNIFTIImageReader.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundSequenceWriter.h"
#include "vtkUltrasoundVolumeSweep.h"
#include "vtkXMLImageDataReader.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>

namespace bigus::cli
{
namespace
{
struct SweepFromVolumeOptions
{
  std::string Volume, Output, MaskOutput, Protocol = "parallel";
  int Frames = 160, Axis = 2;
  double Offset = 0, Tilt = 30, Spacing = 0;
  unsigned Seed = 1;
};

/// A 3D volume from .mha/.mhd (MetaIO), .nii/.nii.gz (NIfTI) or .vti (VTK XML); null after a message.
vtkSmartPointer<vtkImageData> ReadVolume(const std::string& file)
{
  std::ifstream probe(file);
  if (!probe)
  {
    Fail(file + ": cannot open the volume");
    return nullptr;
  }
  vtkSmartPointer<vtkAlgorithm> reader;
  if (EndsWith(file, ".mha") || EndsWith(file, ".mhd"))
  {
    auto r = vtkSmartPointer<vtkMetaImageReader>::New();
    r->SetFileName(file.c_str());
    reader = r;
  }
  else if (EndsWith(file, ".nii") || EndsWith(file, ".nii.gz"))
  {
    auto r = vtkSmartPointer<vtkNIFTIImageReader>::New();
    r->SetFileName(file.c_str());
    reader = r;
  }
  else if (EndsWith(file, ".vti"))
  {
    auto r = vtkSmartPointer<vtkXMLImageDataReader>::New();
    r->SetFileName(file.c_str());
    reader = r;
  }
  else
  {
    Fail(file + ": unknown volume format (expected .mha, .mhd, .nii, .nii.gz or .vti)");
    return nullptr;
  }
  reader->Update();
  vtkImageData* volume = vtkImageData::SafeDownCast(reader->GetOutputDataObject(0));
  int dims[3] = { 0, 0, 0 };
  if (volume)
  {
    volume->GetDimensions(dims);
  }
  if (!volume || !volume->GetPointData()->GetScalars() || dims[0] < 2 || dims[1] < 2 || dims[2] < 2)
  {
    Fail(file + ": not a 3D volume with scalars (at least 2 voxels along every axis)");
    return nullptr;
  }
  auto copy = vtkSmartPointer<vtkImageData>::New();
  copy->DeepCopy(volume);
  return copy;
}

int RunSweepFromVolume(const SweepFromVolumeOptions& o)
{
  auto volume = ReadVolume(o.Volume);
  if (!volume)
  {
    return 1;
  }
  vtkNew<vtkUltrasoundVolumeSweep> sweep;
  sweep->SetInputData(volume);
  sweep->SetProtocol(o.Protocol == "oblique" ? vtkUltrasoundVolumeSweep::OBLIQUE
      : o.Protocol == "orthogonal"           ? vtkUltrasoundVolumeSweep::ORTHOGONAL
                                             : vtkUltrasoundVolumeSweep::PARALLEL);
  sweep->SetSweepAxis(o.Axis);
  sweep->SetNumberOfFrames(o.Frames);
  sweep->SetOffset(o.Offset);
  sweep->SetMaximumTiltAngle(o.Tilt);
  sweep->SetSeed(o.Seed);
  sweep->SetPixelSpacing(o.Spacing);
  FilterError error;
  error.Watch(sweep);
  sweep->Update();
  if (!error.Text.empty() || sweep->GetOutput()->GetNumberOfPoints() == 0)
  {
    return Fail("sweep: " + error.Or("no frames"));
  }
  // The writer writes under temporary names and renames (a detached .mhd's data file too).
  vtkNew<vtkUltrasoundSequenceWriter> writer;
  writer->SetInputConnection(sweep->GetOutputPort());
  writer->SetFileName(o.Output.c_str());
  if (!writer->Write())
  {
    return Fail(o.Output + ": cannot write the sweep");
  }
  if (!o.MaskOutput.empty() && WriteImage(sweep->GetMaskOutput(), o.MaskOutput) != 0)
  {
    return 1;
  }
  const int* size = sweep->GetFrameSize();
  std::printf("sweep          %s: %d %s frames of %d x %d pixels, %.4f mm apart (build %.2f s)%s%s\n", o.Output.c_str(),
    o.Frames, o.Protocol.c_str(), size[0], size[1], sweep->GetSliceSpacing(), sweep->GetSecondsToBuild(),
    o.MaskOutput.empty() ? "" : "; per-frame mask ", o.MaskOutput.c_str());
  return 0;
}
}

Command AddSweepCommand(CLI::App& app)
{
  auto options = std::make_shared<SweepFromVolumeOptions>();
  SweepFromVolumeOptions& sweep = *options;
  CLI::App* sweepCommand =
    app.add_subcommand("sweep", "Build a tracked sweep with exact poses from a 3D volume (the volume protocol)");
  sweepCommand->add_option("VOLUME", sweep.Volume, "Volume: .mha, .mhd, .nii, .nii.gz or .vti")
    ->required()
    ->check(CLI::ExistingFile);
  sweepCommand->add_option("-o,--output", sweep.Output, "Sweep to write (.igs.mha)")->required();
  sweepCommand->add_option("--mask-output", sweep.MaskOutput, "Per-frame mask to write (.mha, W x H x N)");
  sweepCommand->add_option("--protocol", sweep.Protocol, "parallel, oblique or orthogonal")
    ->check(CLI::IsMember({ "parallel", "oblique", "orthogonal" }))
    ->capture_default_str();
  sweepCommand->add_option("--frames", sweep.Frames, "Number of slices (the paper: 160 and 80)")
    ->capture_default_str()
    ->check(FiniteRange(1, 100000));
  sweepCommand->add_option("--axis", sweep.Axis, "Axis the parallel slices step along (0, 1, 2)")
    ->capture_default_str()
    ->check(FiniteRange(0, 2));
  sweepCommand->add_option("--offset", sweep.Offset, "Shift in slice spacings, [0, 1): 0.5 = in-between slices")
    ->capture_default_str()
    ->check(FiniteRange(0, 1));
  sweepCommand->add_option("--tilt", sweep.Tilt, "Oblique: largest tilt, degrees (0 to 89)")
    ->capture_default_str()
    ->check(FiniteRange(0, 89));
  sweepCommand->add_option("--seed", sweep.Seed, "Oblique: random seed")->capture_default_str();
  sweepCommand->add_option("--spacing", sweep.Spacing, "Pixel spacing, mm (0: the volume's)")
    ->capture_default_str()
    ->check(FiniteNonNegative(1e6));
  return { sweepCommand, [options] {
            SweepFromVolumeOptions& sweep = *options;
            return RunSweepFromVolume(sweep);
          } };
}

} // namespace bigus::cli
