// `bigus info`: summarise a tracked sweep.
#include "bigusBackend.h"
#include "bigusBackendCheck.h"
#include "bigusCommandLine.h"
#include "bigusElevationSigma.h"
#include "bigusGaussianFieldData.h"
#include "bigusSliceFrame.h"
#include "bigusTrainerSettings.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundFanMask.h"

#include <CLI/CLI.hpp>
#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <string>

namespace bigus::cli
{
namespace
{
struct InfoOptions
{
  SweepOptions Sweep;
  bool Backends = false;
};

/// One line per registered backend and what its self-check found (bigusBackendCheck.h).
int PrintBackends()
{
  for (const std::string& name : bigus::AvailableBackends())
  {
    const bigus::BackendCheck check = bigus::CheckBackend(name);
    const std::string runsOn = bigus::BackendDescription(name);
    std::printf("backend %-6s %s: %s%s\n", name.c_str(),
      check.Passed ? "passed its self-check" : "FAILED its self-check", check.Detail.c_str(),
      runsOn.empty() ? "" : ("; runs on " + runsOn).c_str());
  }
  for (const auto& [name, why] : bigus::UnavailableBackends())
  {
    std::printf("backend %-6s built, cannot run here: %s\n", name.c_str(), why.c_str());
  }
  std::string error;
  std::printf("auto   -> %s\n", bigus::ResolveBackend("auto", &error).c_str());
  return 0;
}

int RunInfo(const InfoOptions& options)
{
  auto reader = ReadSweep(options.Sweep);
  if (!reader)
  {
    return 1;
  }
  vtkImageData* frames = reader->GetOutput();
  int dims[3];
  frames->GetDimensions(dims);
  vtkFieldData* fd = frames->GetFieldData();
  vtkDataArray* poses = fd->GetArray("ImageToReference");
  vtkDataArray* stamps = fd->GetArray("Timestamp");

  int validCount = 0;
  double lo[3] = { std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
    std::numeric_limits<double>::max() };
  double hi[3] = { -lo[0], -lo[1], -lo[2] };
  double spacingMin[2] = { lo[0], lo[0] }, spacingMax[2] = { 0, 0 }, shearMax = 0, path = 0;
  double previous[3] = { 0, 0, 0 };
  bool havePrevious = false;
  for (int k = 0; k < dims[2]; ++k)
  {
    if (!FrameIsValid(frames, k))
    {
      continue;
    }
    ++validCount;
    double m[16];
    poses->GetTuple(k, m);
    bigus::SliceFrame frame;
    bigus::ComputeSliceFrame(m, 90, frame);
    for (int s = 0; s < 2; ++s)
    {
      spacingMin[s] = std::min(spacingMin[s], frame.spacing[s]);
      spacingMax[s] = std::max(spacingMax[s], frame.spacing[s]);
    }
    shearMax = std::max(shearMax, frame.shearDegrees);
    for (double x : { 0.0, double(dims[0] - 1) })
    {
      for (double y : { 0.0, double(dims[1] - 1) })
      {
        for (int c = 0; c < 3; ++c)
        {
          const double p = m[4 * c] * x + m[4 * c + 1] * y + m[4 * c + 3];
          lo[c] = std::min(lo[c], p);
          hi[c] = std::max(hi[c], p);
        }
      }
    }
    if (havePrevious)
    {
      path += std::hypot(m[3] - previous[0], m[7] - previous[1], m[11] - previous[2]);
    }
    previous[0] = m[3];
    previous[1] = m[7];
    previous[2] = m[11];
    havePrevious = true;
  }

  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputData(frames);
  fan->Update();
  vtkDataArray* mask = fan->GetOutput()->GetPointData()->GetScalars();
  double covered = 0;
  for (vtkIdType p = 0; p < mask->GetNumberOfTuples(); ++p)
  {
    covered += mask->GetTuple1(p);
  }

  std::printf("sweep          %s\n", options.Sweep.Sweep.c_str());
  std::printf("frames         %d (%d valid), file has %d\n", dims[2], validCount, reader->GetNumberOfFramesInFile());
  std::printf("frame size     %d x %d pixels, %s, orientation in file %s (read as MF)\n", dims[0], dims[1],
    frames->GetScalarTypeAsString(), reader->GetFileOrientation());
  std::printf("pose chain     ImageToReference = %s\n", reader->GetTransformChainInUse());
  if (validCount > 0)
  {
    std::printf("pixel spacing  %.4f to %.4f mm (columns), %.4f to %.4f mm (rows); max shear %.2f deg\n", spacingMin[0],
      spacingMax[0], spacingMin[1], spacingMax[1], shearMax);
    std::printf(
      "bounds (mm)    x %.2f .. %.2f, y %.2f .. %.2f, z %.2f .. %.2f\n", lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]);
    std::printf("probe path     %.1f mm (distance between consecutive frame origins, summed)\n", path);
  }
  if (stamps && stamps->GetNumberOfTuples() == dims[2])
  {
    std::printf("time           %.3f .. %.3f s\n", stamps->GetTuple1(0), stamps->GetTuple1(dims[2] - 1));
  }
  std::printf("fan mask       %.1f %% of the frame (estimated from the frames)\n",
    100.0 * covered / std::max<vtkIdType>(1, mask->GetNumberOfTuples()));
  bigus::TrainingData data;
  std::string error;
  if (bigus::TrainingDataFromSequence(frames, fan->GetOutput(), data, &error))
  {
    for (int k = 0; k < dims[2]; ++k)
    {
      if (FrameIsValid(frames, k))
      {
        data.TrainFrames.push_back(k);
      }
    }
    const std::vector<bigus::SweepDecorrelation> measured = bigus::MeasureSweeps(data);
    const bigus::ElevationSigmaChoice choice = bigus::ChooseElevationSigma(measured);
    const bigus::ElevationDecorrelation& decorrelation = choice.Measurement;
    if (!decorrelation.Distance.empty())
    {
      std::printf("frame spacing  %.3f mm between neighbouring frames along the elevation axis (median)\n",
        decorrelation.NeighbourSpacing);
      std::printf("speckle        decorrelation sigma %.3f mm (its fit's correlation at 0 mm %.3f); correlation at",
        decorrelation.DecorrelationSigma, decorrelation.ZeroDistanceCorrelation);
      for (std::size_t k = 0; k < decorrelation.Distance.size(); k += 2)
      {
        std::printf(" %.2f:%.3f", decorrelation.Distance[k], decorrelation.Correlation[k]);
      }
      std::printf(" (mm:NCC)\n");
    }
    std::printf("elevation sigma %.3f mm, as `bigus train` chooses it: %s\n", choice.Sigma, choice.Reason.c_str());
    // The Harris seeds' scale across their frame, as `bigus train` sets it from the same measurement (SeedShapeOf).
    bigus::TrainerSettings seeding;
    seeding.ElevationSigma = choice.Sigma;
    const bigus::SeedShape shape = bigus::SeedShapeOf(seeding, 1.0, 1.0, decorrelation.NeighbourSpacing);
    const std::string why = shape.FrameSpacing > 0
      ? vtkfmt::sprintf("%.3g x the frame spacing, wider than the beam", seeding.Seeding.ElevationSpacingFactor)
      : std::string("the beam");
    std::printf("seeds          %.3f mm across their frame: %s\n", shape.ElevationScale, why.c_str());
    // With every frame trained on; a hold-out widens the training frames' spacing.
    const bigus::PoseRefinementChoice refine = bigus::ChoosePoseRefinement(measured);
    std::printf("pose refinement %s by default, every frame trained on: %s\n", refine.Any() ? "on" : "off",
      refine.Reason.c_str());
    return 0;
  }
  std::printf("elevation sigma not measured: %s\n", error.c_str());
  return 0;
}
}

Command AddInfoCommand(CLI::App& app)
{
  auto options = std::make_shared<InfoOptions>();
  InfoOptions& info = *options;
  CLI::App* infoCommand = app.add_subcommand("info", "Summarise a tracked sweep (PLUS/IGSIO sequence metafile)");
  infoCommand->add_option("SWEEP", info.Sweep.Sweep, "Sequence metafile (.igs.mha, .seq.mha, .mha, .mhd)")
    ->check(CLI::ExistingFile);
  infoCommand->add_flag("--backends", info.Backends,
    "List the rendering backends and what each one's self-check against the CPU renderer found (\"auto\" takes "
    "only one that passed)");
  AddSweepOptions(infoCommand, info.Sweep, "sweep");
  infoCommand->add_option("--frames", info.Sweep.FrameRange, "First and last frame to read (inclusive)")->expected(2);
  return { infoCommand, [options] {
            InfoOptions& info = *options;
            if (info.Sweep.Sweep.empty() && !info.Backends)
            {
              std::fprintf(stderr, "bigus info: give a SWEEP, or --backends\n");
              return 2;
            }
            const int backends = info.Backends ? PrintBackends() : 0;
            return info.Sweep.Sweep.empty() ? backends : RunInfo(info);
          } };
}

} // namespace bigus::cli
