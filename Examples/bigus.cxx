// bigus: command-line front end of BIGUS-VTK.
//
//   bigus info SWEEP [--calibration XML] [--transform CHAIN] [--frames FIRST LAST]
//
// prints what a tracked sweep holds: frames, frame size, pixel spacing, pose ranges, timestamps,
// valid frames and the fan-mask coverage. Exit code 0 on success, 1 on a bad file, 2 on bad arguments.
#include "bigusSliceFrame.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkLogger.h"
#include "vtkNew.h"
#include "vtkOutputWindow.h"
#include "vtkPointData.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundSequenceReader.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

namespace
{
struct InfoOptions
{
  std::string Sweep;
  std::string Calibration;
  std::string Chain;
  std::vector<int> Frames;
};

int RunInfo(const InfoOptions& options)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(options.Sweep.c_str());
  if (!options.Calibration.empty())
  {
    reader->SetCalibrationFileName(options.Calibration.c_str());
  }
  if (!options.Chain.empty())
  {
    reader->SetTransformChain(options.Chain.c_str());
  }
  if (options.Frames.size() == 2)
  {
    reader->SetFrameRange(options.Frames[0], options.Frames[1]);
  }
  reader->Update();
  if (*reader->GetLastErrorText())
  {
    std::fprintf(stderr, "bigus info: %s\n", reader->GetLastErrorText());
    return 1;
  }
  vtkImageData* frames = reader->GetOutput();
  int dims[3];
  frames->GetDimensions(dims);
  vtkFieldData* fd = frames->GetFieldData();
  vtkDataArray* poses = fd->GetArray("ImageToReference");
  vtkDataArray* valid = fd->GetArray("FrameValid");
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
    if (valid->GetTuple1(k) == 0)
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
      const double d[3] = { m[3] - previous[0], m[7] - previous[1], m[11] - previous[2] };
      path += std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
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

  std::printf("sweep          %s\n", options.Sweep.c_str());
  std::printf("frames         %d (%d valid), file has %d\n", dims[2], validCount, reader->GetNumberOfFramesInFile());
  std::printf("frame size     %d x %d pixels, %s, orientation in file %s (read as MF)\n", dims[0], dims[1],
    frames->GetScalarTypeAsString(), reader->GetFileOrientation());
  std::printf("pose chain     ImageToReference = %s\n", reader->GetTransformChainInUse());
  if (validCount > 0)
  {
    std::printf("pixel spacing  %.4f to %.4f mm (columns), %.4f to %.4f mm (rows); max shear %.2f deg\n",
      spacingMin[0], spacingMax[0], spacingMin[1], spacingMax[1], shearMax);
    std::printf("bounds (mm)    x %.2f .. %.2f, y %.2f .. %.2f, z %.2f .. %.2f\n", lo[0], hi[0], lo[1], hi[1],
      lo[2], hi[2]);
    std::printf("probe path     %.1f mm (distance between consecutive frame origins, summed)\n", path);
  }
  std::printf("time           %.3f .. %.3f s\n", stamps->GetTuple1(0), stamps->GetTuple1(dims[2] - 1));
  std::printf("fan mask       %.1f %% of the frame (estimated from the frames)\n",
    100.0 * covered / std::max<vtkIdType>(1, mask->GetNumberOfTuples()));
  return 0;
}
}

int main(int argc, char** argv)
{
  // Errors are reported once, on one line, by this program; VTK's own window would repeat them.
  vtkOutputWindow::GetInstance()->SetDisplayModeToNever();
  vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF);

  CLI::App app{ "BIGUS-VTK: beam-integrated Gaussian scattering for tracked freehand ultrasound" };
  app.require_subcommand(1);

  InfoOptions info;
  CLI::App* infoCommand = app.add_subcommand("info", "Summarise a tracked sweep (PLUS/IGSIO sequence metafile)");
  infoCommand->add_option("SWEEP", info.Sweep, "Sequence metafile (.igs.mha, .seq.mha, .mha, .mhd)")
    ->required()
    ->check(CLI::ExistingFile);
  infoCommand->add_option("--calibration", info.Calibration, "PLUS device-set configuration XML (ImageToProbe)")
    ->check(CLI::ExistingFile);
  infoCommand->add_option("--transform", info.Chain,
    "Transform chain for ImageToReference, e.g. \"inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe\"");
  infoCommand->add_option("--frames", info.Frames, "First and last frame to read (inclusive)")->expected(2);

  try
  {
    app.parse(argc, argv);
  }
  catch (const CLI::ParseError& e)
  {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  if (infoCommand->parsed())
  {
    return RunInfo(info);
  }
  return 2;
}
