// bigus: command-line front end of BIGUS-VTK.
//
//   bigus info SWEEP [--calibration XML] [--transform CHAIN] [--frames FIRST LAST]
//   bigus train SWEEP -o FIELD.vtp [--holdout-every K --holdout-offset J | --frames LIST] [--time-budget S]
//               [--iterations N] ...
//   bigus render FIELD.vtp --poses SWEEP [--frames LIST] -o OUT.igs.mha
//   bigus render FIELD.vtp --plane OX OY OZ NX NY NZ [--size W H] [--spacing MM] -o slice.png|.mha
//   bigus render FIELD.vtp --volume [--spacing MM] -o volume.mha|.vti
//   bigus evaluate FIELD.vtp SWEEP [--holdout-every K --holdout-offset J | --frames LIST] --report DIR
//   bigus sweep VOLUME -o SWEEP.igs.mha [--mask-output MASK.mha] [--protocol parallel|oblique|orthogonal] ...
//   bigus benchmark [--quick] [--section all|defaults|volume|blocks|ablations|pareto] [--output DIR]
//
// Exit codes: 0 success, 1 a bad file or a failed step (one line on stderr), 2 bad arguments.
// Outputs are written under a temporary name and renamed: an existing file is never left half-written.
#include "bigusBenchmark.h"
#include "bigusElevationSigma.h"
#include "bigusGapFilling.h"
#include "bigusGaussianFieldData.h"
#include "bigusImageMetrics.h"
#include "bigusPlot.h"
#include "bigusSliceFrame.h"
#include "vtkAlgorithm.h"
#include "vtkCallbackCommand.h"
#include "vtkCommand.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkGaussianFieldSequenceRenderer.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkLogger.h"
#include "vtkMatrix4x4.h"
#include "vtkMetaImageReader.h"
#include "vtkMetaImageWriter.h"
#include "vtkNIFTIImageReader.h"
#include "vtkNew.h"
#include "vtkOutputWindow.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkSMPTools.h"
#include "vtkStringArray.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundSequenceReader.h"
#include "vtkUltrasoundSequenceWriter.h"
#include "vtkUltrasoundVolumeSweep.h"
#include "vtkXMLImageDataReader.h"
#include "vtkXMLImageDataWriter.h"
#include "vtkXMLPolyDataReader.h"
#include "vtkXMLPolyDataWriter.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <numeric>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

using bigus::Publish;
using bigus::TemporaryName;

namespace
{
/// One-line failure with exit code 1.
int Fail(const std::string& what)
{
  std::fprintf(stderr, "bigus: %s\n", what.c_str());
  return 1;
}

/**
 * The last error a watched VTK object reported, on one line. VTK's output window is silenced (main),
 * so the command line reports a filter's own message ("ERROR: In <file>, line <n>\n<class>
 * (<address>): <message>\n\n" keeps <message>) instead of its own guess.
 */
class FilterError
{
public:
  FilterError()
  {
    this->Callback->SetClientData(&this->Text);
    this->Callback->SetCallback([](vtkObject*, unsigned long, void* client, void* data) {
      std::string text = static_cast<const char*>(data);
      const std::size_t start = text.rfind("): ");
      text = start == std::string::npos ? text : text.substr(start + 3);
      text.erase(std::remove(text.begin(), text.end(), '\n'), text.end());
      *static_cast<std::string*>(client) = text;
    });
  }
  FilterError(const FilterError&) = delete;
  FilterError& operator=(const FilterError&) = delete;
  void Watch(vtkObject* object) { object->AddObserver(vtkCommand::ErrorEvent, this->Callback); }
  /// The message, or @p fallback when none was reported.
  std::string Or(const std::string& fallback) const { return this->Text.empty() ? fallback : this->Text; }
  std::string Text;

private:
  vtkNew<vtkCallbackCommand> Callback;
};

bool EndsWith(const std::string& s, const std::string& suffix)
{
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

struct SweepOptions
{
  std::string Sweep, Calibration, Chain;
  std::vector<int> FrameRange; ///< empty, or first and last frame
};

/// Reads a sweep; on failure prints the reader's message and returns null.
vtkSmartPointer<vtkUltrasoundSequenceReader> ReadSweep(const SweepOptions& o)
{
  auto reader = vtkSmartPointer<vtkUltrasoundSequenceReader>::New();
  reader->SetFileName(o.Sweep.c_str());
  if (!o.Calibration.empty())
  {
    reader->SetCalibrationFileName(o.Calibration.c_str());
  }
  if (!o.Chain.empty())
  {
    reader->SetTransformChain(o.Chain.c_str());
  }
  if (o.FrameRange.size() == 2)
  {
    reader->SetFrameRange(o.FrameRange[0], o.FrameRange[1]);
  }
  reader->Update();
  if (*reader->GetLastErrorText())
  {
    Fail(reader->GetLastErrorText());
    return nullptr;
  }
  return reader;
}

vtkSmartPointer<vtkPolyData> ReadField(const std::string& file)
{
  std::ifstream probe(file);
  if (!probe)
  {
    Fail(file + ": cannot open the field file");
    return nullptr;
  }
  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(file.c_str());
  reader->Update();
  vtkPolyData* field = reader->GetOutput();
  if (!field || field->GetNumberOfPoints() == 0 || !field->GetPointData()->GetArray("Scale"))
  {
    Fail(file + ": not a Gaussian field (.vtp with point data Scale, Rotation, Reflectivity)");
    return nullptr;
  }
  auto copy = vtkSmartPointer<vtkPolyData>::New();
  copy->DeepCopy(field);
  return copy;
}

/**
 * Whether frame @p k of a sweep may be used: its FrameValid value is non-zero, or the sweep has no
 * FrameValid of one value per frame (every frame valid), as vtkGaussianFieldTrainer and
 * vtkUltrasoundVolumeCompounder read it.
 */
bool FrameIsValid(vtkImageData* sweep, int k)
{
  vtkDataArray* valid = sweep->GetFieldData()->GetArray("FrameValid");
  return !valid || valid->GetNumberOfTuples() != sweep->GetDimensions()[2] || valid->GetTuple1(k) != 0;
}

/// Frames with index k mod every == offset (every > 0), or the explicit list, or all.
std::vector<int> ChooseFrames(int count, int every, int offset, const std::vector<int>& list)
{
  std::vector<int> frames;
  for (int k = 0; k < count; ++k)
  {
    if (!list.empty() ? std::find(list.begin(), list.end(), k) != list.end() : (every <= 0 || k % every == offset))
    {
      frames.push_back(k);
    }
  }
  return frames;
}

/// Reads a fan mask (.mha/.mhd, W x H x 1, or W x H x N: one per frame) for a W x H x N sweep;
/// on failure prints what is wrong and returns null.
vtkSmartPointer<vtkImageData> ReadMask(const std::string& file, const int dims[3])
{
  std::ifstream probe(file);
  if (!probe)
  {
    Fail(file + ": cannot open the mask");
    return nullptr;
  }
  vtkNew<vtkMetaImageReader> reader;
  reader->SetFileName(file.c_str());
  reader->Update();
  vtkImageData* mask = reader->GetOutput();
  int size[3] = { 0, 0, 0 };
  mask->GetDimensions(size);
  if (!mask->GetPointData()->GetScalars() || mask->GetNumberOfScalarComponents() != 1 || size[0] != dims[0] ||
    size[1] != dims[1] || (size[2] != 1 && size[2] != dims[2]))
  {
    Fail(file + ": the mask must be one-component " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) +
      " x 1 or x " + std::to_string(dims[2]) + " (one per frame), not " + std::to_string(size[0]) + " x " +
      std::to_string(size[1]) + " x " + std::to_string(size[2]));
    return nullptr;
  }
  auto copy = vtkSmartPointer<vtkImageData>::New();
  copy->DeepCopy(mask);
  return copy;
}

// ---------------------------------------------------------------------------------------------
// info

struct InfoOptions
{
  SweepOptions Sweep;
};

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
    std::printf("pixel spacing  %.4f to %.4f mm (columns), %.4f to %.4f mm (rows); max shear %.2f deg\n",
      spacingMin[0], spacingMax[0], spacingMin[1], spacingMax[1], shearMax);
    std::printf("bounds (mm)    x %.2f .. %.2f, y %.2f .. %.2f, z %.2f .. %.2f\n", lo[0], hi[0], lo[1], hi[1],
      lo[2], hi[2]);
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
    const bigus::ElevationSigmaChoice choice = bigus::ChooseElevationSigma(data);
    const bigus::ElevationDecorrelation& decorrelation = choice.Measurement;
    if (!decorrelation.Distance.empty())
    {
      std::printf("frame spacing  %.3f mm between neighbouring frames along the elevation axis (median)\n",
        decorrelation.NeighbourSpacing);
      std::printf("speckle        decorrelation sigma %.3f mm; correlation at", decorrelation.DecorrelationSigma);
      for (std::size_t k = 0; k < decorrelation.Distance.size(); k += 2)
      {
        std::printf(" %.2f:%.3f", decorrelation.Distance[k], decorrelation.Correlation[k]);
      }
      std::printf(" (mm:NCC)\n");
    }
    std::printf("elevation sigma %.3f mm, as `bigus train` chooses it: %s\n", choice.Sigma, choice.Reason.c_str());
    return 0;
  }
  std::printf("elevation sigma not measured: %s\n", error.c_str());
  return 0;
}

// ---------------------------------------------------------------------------------------------
// train

struct TrainOptions
{
  SweepOptions Sweep;
  std::string Output, Checkpoint, Resume, Mask, Backend = "auto";
  int HoldOutEvery = 0, HoldOutOffset = 0, Iterations = 0, Threads = 0;
  std::vector<int> Frames; ///< explicit training frames (empty: the hold-out rule)
  double TimeBudget = 0, ElevationSigma = 0, EvaluationInterval = 0;
  long long MaxGaussians = 0, InitialGaussians = 0;
  double GrowthMargin = 0;
  int GrowthPatience = 0, SolveIterations = 0;
  bool NoFillGaps = false, ReflectivitySolve = false, DenseStart = false, DenseAdam = false;
  unsigned Seed = 0;

  /// The filter's own defaults, so that `bigus train` and vtkGaussianFieldTrainer agree.
  TrainOptions()
  {
    vtkNew<vtkGaussianFieldTrainer> defaults;
    this->Iterations = defaults->GetIterations();
    this->ElevationSigma = defaults->GetElevationSigma();
    this->MaxGaussians = defaults->GetMaximumGaussians();
    this->InitialGaussians = defaults->GetInitialGaussians();
    this->GrowthMargin = defaults->GetGrowthMargin();
    this->GrowthPatience = defaults->GetGrowthPatience();
    this->SolveIterations = defaults->GetSolveIterations();
    this->Seed = defaults->GetSeed();
  }
};

int RunTrain(const TrainOptions& o)
{
  if (o.Threads > 0)
  {
    vtkSMPTools::Initialize(o.Threads);
  }
  auto reader = ReadSweep(o.Sweep);
  if (!reader)
  {
    return 1;
  }
  vtkNew<vtkGaussianFieldTrainer> trainer;
  trainer->SetInputConnection(reader->GetOutputPort());
  if (!o.Mask.empty())
  {
    auto mask = ReadMask(o.Mask, reader->GetOutput()->GetDimensions());
    if (!mask)
    {
      return 1;
    }
    trainer->SetInputData(1, mask);
  }
  trainer->SetHoldOutEvery(o.HoldOutEvery);
  trainer->SetHoldOutOffset(o.HoldOutOffset);
  if (!o.Frames.empty())
  {
    vtkNew<vtkIdList> frames;
    for (int k : o.Frames)
    {
      frames->InsertUniqueId(k);
    }
    trainer->SetTrainingFrameList(frames);
  }
  trainer->SetIterations(o.Iterations);
  trainer->SetTimeBudget(o.TimeBudget);
  trainer->SetMaximumGaussians(o.MaxGaussians);
  trainer->SetInitialGaussians(o.InitialGaussians);
  trainer->SetGrowthMargin(o.GrowthMargin);
  trainer->SetGrowthPatience(o.GrowthPatience);
  trainer->SetFillGaps(!o.NoFillGaps);
  trainer->SetReflectivitySolve(o.ReflectivitySolve);
  trainer->SetSolveIterations(o.SolveIterations);
  trainer->SetDenseInitialisation(o.DenseStart);
  trainer->SetSparseAdam(!o.DenseAdam);
  trainer->SetElevationSigma(o.ElevationSigma);
  trainer->SetSeed(o.Seed);
  trainer->SetEvaluationInterval(o.EvaluationInterval);
  trainer->SetBackend(o.Backend.c_str());
  if (!o.Checkpoint.empty())
  {
    trainer->SetCheckpointFile(o.Checkpoint.c_str());
    trainer->SetCheckpointInterval(200);
  }
  if (!o.Resume.empty())
  {
    trainer->SetResumeFile(o.Resume.c_str());
  }
  // Progress: a bar on a terminal, a line every 10 % otherwise.
  const bool terminal = ::isatty(STDOUT_FILENO);
  const auto start = std::chrono::steady_clock::now();
  int lastDecile = -1;
  vtkNew<vtkCallbackCommand> progress;
  struct Context
  {
    bool Terminal;
    std::chrono::steady_clock::time_point Start;
    int* LastDecile;
  } context{ terminal, start, &lastDecile };
  progress->SetClientData(&context);
  progress->SetCallback([](vtkObject* caller, unsigned long, void* client, void* data) {
    const Context& c = *static_cast<Context*>(client);
    const double fraction = *static_cast<double*>(data);
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - c.Start).count();
    const double eta = fraction > 0 ? elapsed * (1 - fraction) / fraction : 0;
    auto* t = static_cast<vtkGaussianFieldTrainer*>(caller);
    if (t->GetCurrentIteration() == 0)
    {
      return; // the pipeline's own 0 % and 100 % events, also sent when training fails before a step
    }
    char state[160];
    std::snprintf(state, sizeof(state), "%3.0f%%  iteration %d  loss %.4f  Gaussians %lld  elapsed %.0f s  ETA %.0f s",
      100 * fraction, t->GetCurrentIteration(), t->GetCurrentLoss(),
      static_cast<long long>(t->GetCurrentNumberOfGaussians()), elapsed, eta);
    if (c.Terminal)
    {
      const int width = 24, filled = static_cast<int>(fraction * width);
      std::printf("\r[%s%s] %s   ", std::string(filled, '#').c_str(), std::string(width - filled, ' ').c_str(), state);
      std::fflush(stdout);
    }
    else if (static_cast<int>(fraction * 10) > *c.LastDecile)
    {
      *c.LastDecile = static_cast<int>(fraction * 10);
      std::printf("training %s\n", state);
      std::fflush(stdout);
    }
  });
  trainer->AddObserver(vtkCommand::ProgressEvent, progress);
  vtkNew<vtkCallbackCommand> chosen;
  chosen->SetCallback([](vtkObject* caller, unsigned long, void*, void*) {
    std::istringstream lines(static_cast<vtkGaussianFieldTrainer*>(caller)->GetSettingsText());
    for (std::string line; std::getline(lines, line);)
    {
      std::printf("setting        %s\n", line.c_str());
    }
    std::fflush(stdout);
  });
  trainer->AddObserver(vtkGaussianFieldTrainer::SettingsChosenEvent, chosen);
  FilterError error;
  error.Watch(trainer);
  trainer->Update();
  if (terminal)
  {
    std::printf("\n");
  }
  if (trainer->GetNumberOfGaussians() == 0)
  {
    return Fail("training failed: " + error.Or("no field"));
  }
  const std::string temporary = TemporaryName(o.Output);
  vtkNew<vtkXMLPolyDataWriter> writer;
  writer->SetInputConnection(trainer->GetOutputPort());
  writer->SetFileName(temporary.c_str());
  writer->SetDataModeToAppended();
  if (!writer->Write() || !Publish(temporary, o.Output))
  {
    std::remove(temporary.c_str());
    return Fail(o.Output + ": cannot write the field");
  }
  vtkDataArray* seeds = trainer->GetOutput()->GetFieldData()->GetArray("InitialGaussians");
  std::printf("field          %s: %lld Gaussians (from %lld seeds) after %d iterations in %.1f s (stop: %s; growth: %s)\n",
    o.Output.c_str(), static_cast<long long>(trainer->GetNumberOfGaussians()),
    seeds ? static_cast<long long>(seeds->GetTuple1(0)) : 0LL, trainer->GetCompletedIterations(),
    trainer->GetTrainingSeconds(), trainer->GetStopReason(), trainer->GetGrowthStopReason());
  vtkFieldData* fd = trainer->GetOutput()->GetFieldData();
  vtkDataArray* best = fd->GetArray("BestValidationLoss");
  vtkDataArray* last = fd->GetArray("LastValidationLoss");
  if (best && last)
  {
    std::printf("early stopping %s (validation loss %.5f at iteration %.0f, %.5f at the end)\n",
      best->GetTuple1(0) < last->GetTuple1(0) ? "kept an earlier field" : "kept the last field", best->GetTuple1(0),
      fd->GetArray("BestIteration")->GetTuple1(0), last->GetTuple1(0));
  }
  if (vtkAbstractArray* gaps = fd->GetAbstractArray("GapFilling"))
  {
    std::printf("gap filling    %s\n", gaps->GetVariantValue(0).ToString().c_str());
  }
  std::printf("backend        %s\n", trainer->GetBackendInUse());
  return 0;
}

// ---------------------------------------------------------------------------------------------
// fill-gaps

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
    return Fail(o.Field + ": no field data TrainingPoses (a field trained before they were stored): the gaps "
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
  const std::string temporary = TemporaryName(o.Output);
  vtkNew<vtkXMLPolyDataWriter> writer;
  writer->SetInputData(output);
  writer->SetFileName(temporary.c_str());
  writer->SetDataModeToAppended();
  if (!writer->Write() || !Publish(temporary, o.Output))
  {
    std::remove(temporary.c_str());
    return Fail(o.Output + ": cannot write the field");
  }
  std::printf("%s: %lld Gaussians, %s\n", o.Output.c_str(), static_cast<long long>(before + report.Added), text.c_str());
  return 0;
}

// ---------------------------------------------------------------------------------------------
// render

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

/// Writes an image: .png (8-bit, rows flipped so that row 0 is the top), .mha (MetaImage), .vti.
int WriteImage(vtkImageData* image, const std::string& path)
{
  const std::string temporary = TemporaryName(path);
  bool ok = false;
  if (EndsWith(path, ".png"))
  {
    int dims[3];
    image->GetDimensions(dims);
    vtkDataArray* values = image->GetPointData()->GetScalars();
    cv::Mat png(dims[1], dims[0], CV_8U);
    for (int j = 0; j < dims[1]; ++j)
    {
      for (int i = 0; i < dims[0]; ++i)
      {
        const double v = values->GetTuple1(vtkIdType(j) * dims[0] + i);
        png.at<unsigned char>(j, i) =
          static_cast<unsigned char>(std::lround(std::min(255.0, std::max(0.0, values->GetDataType() == VTK_FLOAT ? 255 * v : v))));
      }
    }
    ok = cv::imwrite(temporary, png);
  }
  else if (EndsWith(path, ".mha") || EndsWith(path, ".mhd"))
  {
    vtkNew<vtkMetaImageWriter> writer;
    writer->SetInputData(image);
    writer->SetFileName(temporary.c_str());
    writer->SetCompression(true);
    writer->Write();
    ok = writer->GetErrorCode() == 0;
  }
  else if (EndsWith(path, ".vti"))
  {
    vtkNew<vtkXMLImageDataWriter> writer;
    writer->SetInputData(image);
    writer->SetFileName(temporary.c_str());
    ok = writer->Write() != 0;
  }
  else
  {
    return Fail(path + ": unknown image format (use .png, .mha or .vti)");
  }
  if (!ok || !Publish(temporary, path))
  {
    std::remove(temporary.c_str());
    return Fail(path + ": cannot write the image");
  }
  return 0;
}

int RunRender(const RenderOptionsCli& o)
{
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

// ---------------------------------------------------------------------------------------------
// evaluate

struct EvaluateOptions
{
  std::string Field, Report, Mask, Backend = "auto";
  SweepOptions Sweep;
  int HoldOutEvery = 0, HoldOutOffset = 0;
  std::vector<int> Frames;
};

/// PNG plot of held-out PSNR (dB) against training time (s), from the field's HeldOutPSNR array.
bool PlotHistory(vtkDataArray* history, const std::string& path)
{
  bigus::PlotSpec spec;
  spec.Title = "held-out PSNR against training time";
  spec.XLabel = "training time (s)";
  spec.YLabel = "PSNR (dB)";
  spec.Series.push_back({ "BIGUS", {} });
  for (vtkIdType k = 0; k < history->GetNumberOfTuples(); ++k)
  {
    spec.Series[0].Points.emplace_back(history->GetComponent(k, 0), history->GetComponent(k, 1));
  }
  return bigus::WritePlot(spec, path);
}

/// Renders a slice through the centre of frame @p pose (W x H pixels at the frame's spacing) whose
/// in-plane axes are @p x and @p y (unit vectors), and writes it as PNG.
int WriteSliceThrough(vtkPolyData* field, const double pose[16], int width, int height, const double x[3],
  const double y[3], const std::string& backend, const std::string& path)
{
  bigus::SliceFrame frame;
  bigus::ComputeSliceFrame(pose, 90, frame);
  const double spacing = 0.5 * (frame.spacing[0] + frame.spacing[1]);
  double centre[3];
  for (int c = 0; c < 3; ++c)
  {
    centre[c] = pose[4 * c] * 0.5 * (width - 1) + pose[4 * c + 1] * 0.5 * (height - 1) + pose[4 * c + 3];
  }
  const double n[3] = { x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0] };
  vtkNew<vtkGaussianFieldReslice> reslice;
  reslice->SetInputData(field);
  reslice->SetBackend(backend.c_str());
  reslice->SetResliceAxesDirectionCosines(x[0], x[1], x[2], y[0], y[1], y[2], n[0], n[1], n[2]);
  reslice->SetResliceAxesOrigin(centre[0], centre[1], centre[2]);
  reslice->SetOutputSpacing(spacing, spacing, 1);
  reslice->SetOutputOrigin(-0.5 * spacing * (width - 1), -0.5 * spacing * (height - 1), 0);
  reslice->SetOutputExtent(0, width - 1, 0, height - 1, 0, 0);
  reslice->SetOutputScalarTypeToUnsignedChar();
  FilterError error;
  error.Watch(reslice);
  reslice->Update();
  if (reslice->GetOutput()->GetNumberOfPoints() == 0)
  {
    return Fail(path + ": rendering failed: " + error.Or("empty slice"));
  }
  return WriteImage(reslice->GetOutput(), path);
}

int RunEvaluate(const EvaluateOptions& o)
{
  auto field = ReadField(o.Field);
  auto reader = field ? ReadSweep(o.Sweep) : nullptr;
  if (!reader)
  {
    return 1;
  }
  vtkImageData* truth = reader->GetOutput();
  int dims[3];
  truth->GetDimensions(dims);
  for (int k : o.Frames)
  {
    if (k < 0 || k >= dims[2])
    {
      return Fail("--frames: frame " + std::to_string(k) + " is outside the " + std::to_string(dims[2]) +
        " frames of " + o.Sweep.Sweep);
    }
  }
  std::vector<int> frames = ChooseFrames(dims[2], o.HoldOutEvery, o.HoldOutOffset, o.Frames);
  frames.erase(std::remove_if(frames.begin(), frames.end(), [&](int k) { return !FrameIsValid(truth, k); }),
    frames.end());
  if (frames.empty())
  {
    return Fail("evaluate: no valid frame chosen");
  }
  vtkSmartPointer<vtkImageData> maskImage;
  if (!o.Mask.empty())
  {
    if (!(maskImage = ReadMask(o.Mask, dims)))
    {
      return 1;
    }
  }
  else
  {
    vtkNew<vtkUltrasoundFanMask> fan;
    fan->SetInputConnection(reader->GetOutputPort());
    fan->Update();
    maskImage = fan->GetOutput();
  }
  // The recorded frames and masks as the trainer sees them, so that the metrics are the trainer's own.
  bigus::TrainingData data;
  std::string message;
  if (!bigus::TrainingDataFromSequence(truth, maskImage, data, &message))
  {
    return Fail(o.Sweep.Sweep + ": " + message);
  }
  vtkNew<vtkGaussianFieldSequenceRenderer> renderer;
  renderer->SetInputData(field);
  renderer->SetPoseConnection(reader->GetOutputPort());
  renderer->SetBackend(o.Backend.c_str());
  vtkNew<vtkIdList> list;
  for (int k : frames)
  {
    list->InsertNextId(k);
  }
  renderer->SetFrameList(list);
  FilterError error;
  error.Watch(renderer);
  renderer->Update();
  vtkImageData* rendered = renderer->GetOutput();
  if (rendered->GetNumberOfPoints() == 0)
  {
    return Fail("rendering failed: " + error.Or("no frames"));
  }
  if (::mkdir(o.Report.c_str(), 0755) != 0 && errno != EEXIST)
  {
    return Fail(o.Report + ": cannot create the report folder");
  }
  const std::size_t pixels = std::size_t(dims[0]) * dims[1];
  const auto* renderedPixels = static_cast<float*>(rendered->GetScalarPointer());
  std::vector<std::optional<bigus::ImageMetrics>> perFrame;
  const bigus::ImageMetrics mean = bigus::MeanFrameMetrics(
    data, frames, [&](std::size_t m, int) { return renderedPixels + pixels * m; }, &perFrame);
  nlohmann::json report;
  report["field"] = o.Field;
  report["sweep"] = o.Sweep.Sweep;
  report["render_seconds_per_frame"] = renderer->GetSecondsPerFrame();
  std::size_t used = 0;
  std::printf("%6s %8s %8s %8s %8s\n", "frame", "PSNR", "SSIM", "NCC", "speckle");
  for (std::size_t n = 0; n < frames.size(); ++n)
  {
    const int k = frames[n];
    if (!perFrame[n])
    {
      report["frames"].push_back({ { "frame", k }, { "left_out", "empty mask" } });
      std::printf("%6d  left out of the mean: empty mask\n", k);
      continue;
    }
    const bigus::ImageMetrics& m = *perFrame[n];
    ++used;
    report["frames"].push_back(
      { { "frame", k }, { "psnr", m.PSNR }, { "ssim", m.SSIM }, { "ncc", m.NCC }, { "speckle", m.Speckle } });
    std::printf("%6d %8.2f %8.4f %8.4f %8.4f\n", k, m.PSNR, m.SSIM, m.NCC, m.Speckle);
    // Side by side for a few frames: truth | rendering | absolute error (x 4, so that it shows).
    if (n % std::max<std::size_t>(1, frames.size() / 4) == 0)
    {
      const float* image = renderedPixels + pixels * n;
      const float* recorded = &data.Frames[pixels * k];
      cv::Mat side(dims[1], 3 * dims[0], CV_8U);
      for (int j = 0; j < dims[1]; ++j)
      {
        for (int i = 0; i < dims[0]; ++i)
        {
          const std::size_t p = std::size_t(j) * dims[0] + i;
          side.at<unsigned char>(j, i) = cv::saturate_cast<unsigned char>(255 * recorded[p]);
          side.at<unsigned char>(j, dims[0] + i) = cv::saturate_cast<unsigned char>(255 * image[p]);
          side.at<unsigned char>(j, 2 * dims[0] + i) =
            cv::saturate_cast<unsigned char>(4 * 255 * std::abs(image[p] - recorded[p]));
        }
      }
      const std::string path = o.Report + "/frame_" + std::to_string(k) + "_truth_rendering_error.png";
      const std::string temporary = TemporaryName(path);
      if (!cv::imwrite(temporary, side) || !Publish(temporary, path))
      {
        return Fail(path + ": cannot write");
      }
    }
  }
  if (used == 0)
  {
    return Fail("evaluate: every chosen frame has an empty mask, so there is nothing to compare");
  }
  // Views that no frame saw, through the centre of the middle evaluated frame: the plane spanned by
  // depth and elevation (orthogonal to the frames), and one tilted 45 degrees between the two.
  const std::array<double, 16>& pose = data.Poses[frames[frames.size() / 2]];
  bigus::SliceFrame middle;
  bigus::ComputeSliceFrame(pose.data(), 90, middle);
  double tilted[3];
  for (int c = 0; c < 3; ++c)
  {
    tilted[c] = (middle.u[c] + middle.n[c]) / std::sqrt(2.0);
  }
  const double* matrix = pose.data();
  if (WriteSliceThrough(field, matrix, dims[0], dims[1], middle.n, middle.v, o.Backend,
        o.Report + "/slice_orthogonal.png") != 0 ||
    WriteSliceThrough(field, matrix, dims[0], dims[1], tilted, middle.v, o.Backend, o.Report + "/slice_oblique.png") != 0)
  {
    return 1;
  }
  if (vtkDataArray* history = field->GetFieldData()->GetArray("HeldOutPSNR"))
  {
    if (!PlotHistory(history, o.Report + "/psnr_against_time.png"))
    {
      return Fail(o.Report + "/psnr_against_time.png: cannot write");
    }
    for (vtkIdType k = 0; k < history->GetNumberOfTuples(); ++k)
    {
      report["held_out_psnr_against_time"].push_back(
        { { "seconds", history->GetComponent(k, 0) }, { "psnr", history->GetComponent(k, 1) } });
    }
  }
  report["mean"] = { { "psnr", mean.PSNR }, { "ssim", mean.SSIM }, { "ncc", mean.NCC }, { "speckle", mean.Speckle },
    { "frames", used } };
  std::printf("%6s %8.2f %8.4f %8.4f %8.4f  (%zu frames, %zu left out: empty mask; %.1f ms per rendered frame)\n",
    "mean", mean.PSNR, mean.SSIM, mean.NCC, mean.Speckle, used, frames.size() - used,
    1e3 * renderer->GetSecondsPerFrame());
  const std::string path = o.Report + "/metrics.json";
  const std::string temporary = TemporaryName(path);
  std::ofstream out(temporary);
  out << report.dump(2) << "\n";
  out.close();
  // A failed write (disk full) must not be published: the temporary goes, an existing file stays.
  if (!out)
  {
    std::remove(temporary.c_str());
    return Fail(path + ": cannot write");
  }
  if (!Publish(temporary, path))
  {
    return Fail(path + ": cannot write");
  }
  return 0;
}

// ---------------------------------------------------------------------------------------------
// sweep: the volume protocol

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
  const std::string temporary = TemporaryName(o.Output);
  vtkNew<vtkUltrasoundSequenceWriter> writer;
  writer->SetInputConnection(sweep->GetOutputPort());
  writer->SetFileName(temporary.c_str());
  if (!writer->Write() || !Publish(temporary, o.Output))
  {
    std::remove(temporary.c_str());
    return Fail(o.Output + ": cannot write the sweep");
  }
  if (!o.MaskOutput.empty())
  {
    const std::string maskTemporary = TemporaryName(o.MaskOutput);
    vtkNew<vtkMetaImageWriter> maskWriter;
    maskWriter->SetInputData(sweep->GetMaskOutput());
    maskWriter->SetFileName(maskTemporary.c_str());
    maskWriter->SetCompression(true);
    maskWriter->Write();
    if (maskWriter->GetErrorCode() != 0 || !Publish(maskTemporary, o.MaskOutput))
    {
      std::remove(maskTemporary.c_str());
      return Fail(o.MaskOutput + ": cannot write the mask");
    }
  }
  const int* size = sweep->GetFrameSize();
  std::printf("sweep          %s: %d %s frames of %d x %d pixels, %.4f mm apart (build %.2f s)%s%s\n", o.Output.c_str(),
    o.Frames, o.Protocol.c_str(), size[0], size[1], sweep->GetSliceSpacing(), sweep->GetSecondsToBuild(),
    o.MaskOutput.empty() ? "" : "; per-frame mask ", o.MaskOutput.c_str());
  return 0;
}

void AddSweepOptions(CLI::App* command, SweepOptions& o, const char* what)
{
  command->add_option("--calibration", o.Calibration, "PLUS device-set configuration XML (ImageToProbe)")
    ->check(CLI::ExistingFile);
  command->add_option("--transform", o.Chain,
    std::string("Transform chain for ImageToReference of the ") + what +
      ", e.g. \"inverse(ReferenceToTracker) * ProbeToTracker * ImageToProbe\"");
}
}

int main(int argc, char** argv)
{
  // Errors are reported once, on one line, by this program; VTK's own output would repeat them.
  vtkOutputWindow::GetInstance()->SetDisplayModeToNever();
  vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF);

  CLI::App app{ "BIGUS-VTK: beam-integrated Gaussian scattering for tracked freehand ultrasound" };
  app.require_subcommand(1);

  InfoOptions info;
  CLI::App* infoCommand = app.add_subcommand("info", "Summarise a tracked sweep (PLUS/IGSIO sequence metafile)");
  infoCommand->add_option("SWEEP", info.Sweep.Sweep, "Sequence metafile (.igs.mha, .seq.mha, .mha, .mhd)")
    ->required()
    ->check(CLI::ExistingFile);
  AddSweepOptions(infoCommand, info.Sweep, "sweep");
  infoCommand->add_option("--frames", info.Sweep.FrameRange, "First and last frame to read (inclusive)")->expected(2);

  TrainOptions train;
  CLI::App* trainCommand = app.add_subcommand("train", "Train a Gaussian scattering field from a tracked sweep");
  trainCommand->add_option("SWEEP", train.Sweep.Sweep, "Sequence metafile")->required()->check(CLI::ExistingFile);
  trainCommand->add_option("-o,--output", train.Output, "Field to write (.vtp)")->required();
  AddSweepOptions(trainCommand, train.Sweep, "sweep");
  trainCommand->add_option("--mask", train.Mask, "Fan mask .mha (W x H x 1, or W x H x N per frame; default: estimated)");
  trainCommand->add_option("--holdout-every", train.HoldOutEvery, "Hold out frames with index % K == J (0: none)");
  trainCommand->add_option("--holdout-offset", train.HoldOutOffset, "J of --holdout-every");
  trainCommand->add_option("--frames", train.Frames, "Train on these frames only (indices); the others are held out")
    ->excludes("--holdout-every");
  trainCommand->add_option("--time-budget", train.TimeBudget,
    "Wall-clock budget for training, seconds (0: none); alone, it is the whole schedule (learning-rate decay, "
    "densification window) and training runs until it");
  auto* iterations = trainCommand->add_option("--iterations", train.Iterations,
    "Optimisation steps (with --time-budget: whichever ends first)")->capture_default_str();
  trainCommand->add_option("--max-gaussians", train.MaxGaussians, "Hard maximum of Gaussians (gap filling's copies included)")->capture_default_str();
  trainCommand->add_option("--initial-gaussians", train.InitialGaussians,
    "Seeds (0: one per 200 fan pixels of the training frames, 20,000 to half the maximum)")
    ->capture_default_str()
    ->check(CLI::NonNegativeNumber);
  trainCommand->add_option("--growth-margin", train.GrowthMargin,
    "Growth stops when the validation loss improves by less than this (relative) on the best so far ...")
    ->capture_default_str()
    ->check(CLI::Range(0.0, 1.0));
  trainCommand->add_option("--growth-patience", train.GrowthPatience,
    "... over this many densification intervals in a row")
    ->capture_default_str()
    ->check(CLI::PositiveNumber);
  trainCommand->add_flag("--reflectivity-solve", train.ReflectivitySolve,
    "Variable projection: solve the reflectivities by least squares after seeding and after every densification, "
    "Adam between the solves (default: Adam alone)");
  trainCommand->add_option("--solve-iterations", train.SolveIterations,
    "CGLS iterations of each reflectivity solve (each a forward and a backward pass over every training frame)")
    ->capture_default_str()
    ->check(CLI::PositiveNumber);
  trainCommand->add_flag("--dense-adam", train.DenseAdam,
    "Adam moves every Gaussian every step on its momentum (the ablation; default: only the Gaussians a step "
    "touched, the others keep their parameters and moments)");
  trainCommand->add_flag("--dense-start", train.DenseStart,
    "Start from Gaussians on the training frames' pixel grid (--initial-gaussians of them, default half of "
    "--max-gaussians) instead of Harris seeds");
  trainCommand->add_flag("--no-fill-gaps", train.NoFillGaps,
    "Leave gaps between training frames wider than the beam empty (default: bridged, as bigus fill-gaps does)");
  trainCommand->add_option("--elevation-sigma", train.ElevationSigma, "Elevation beam sigma, mm (FWHM / 2.355); 0: chosen from the sweep (frame spacing, speckle decorrelation)")
    ->capture_default_str();
  trainCommand->add_option("--backend", train.Backend, "Training backend: auto, cpu or cuda (as registered)")
    ->capture_default_str();
  trainCommand->add_option("--threads", train.Threads, "Threads (0: all cores)");
  trainCommand->add_option("--seed", train.Seed, "Random seed")->capture_default_str();
  trainCommand->add_option("--checkpoint", train.Checkpoint, "Checkpoint file, written every 200 steps");
  trainCommand->add_option("--resume", train.Resume, "Continue from this checkpoint (same settings; the seconds trained before it count towards --time-budget)")
    ->check(CLI::ExistingFile);
  trainCommand->add_option("--evaluate-every", train.EvaluationInterval,
    "Record the held-out PSNR every S seconds (field data HeldOutPSNR)");

  RenderOptionsCli render;
  CLI::App* renderCommand = app.add_subcommand("render", "Render a field at sweep poses, a plane or a volume");
  renderCommand->add_option("FIELD", render.Field, "Gaussian field (.vtp)")->required()->check(CLI::ExistingFile);
  renderCommand->add_option("-o,--output", render.Output, "Output: .igs.mha (poses), .png/.mha (plane), .mha/.vti")
    ->required();
  renderCommand->add_option("--poses", render.Poses.Sweep, "Render at the poses of this sweep")
    ->check(CLI::ExistingFile);
  AddSweepOptions(renderCommand, render.Poses, "pose sweep");
  renderCommand->add_option("--frames", render.Frames, "Frames of the pose sweep (default: all)");
  renderCommand->add_option("--plane", render.Plane, "Plane origin and normal, mm: OX OY OZ NX NY NZ")->expected(6);
  renderCommand->add_option("--size", render.Size, "Plane size in pixels: W H")->expected(2);
  renderCommand->add_option("--spacing", render.Spacing, "Pixel spacing, mm");
  renderCommand->add_option("--backend", render.Backend, "Rendering backend: auto, cpu or cuda (as registered)");
  renderCommand->add_flag("--volume", render.Volume, "Render a stack of parallel slices covering the field");

  EvaluateOptions evaluate;
  CLI::App* evaluateCommand = app.add_subcommand("evaluate", "Render sweep frames and compare them with the recording");
  evaluateCommand->add_option("FIELD", evaluate.Field, "Gaussian field (.vtp)")->required()->check(CLI::ExistingFile);
  evaluateCommand->add_option("SWEEP", evaluate.Sweep.Sweep, "Sequence metafile")->required()->check(CLI::ExistingFile);
  AddSweepOptions(evaluateCommand, evaluate.Sweep, "sweep");
  evaluateCommand->add_option("--holdout-every", evaluate.HoldOutEvery, "Evaluate frames with index % K == J");
  evaluateCommand->add_option("--holdout-offset", evaluate.HoldOutOffset, "J of --holdout-every");
  evaluateCommand->add_option("--frames", evaluate.Frames, "Evaluate these frames");
  evaluateCommand->add_option("--mask", evaluate.Mask, "Fan mask .mha (W x H x 1, or W x H x N per frame; default: estimated)");
  evaluateCommand->add_option("--backend", evaluate.Backend, "Rendering backend: auto, cpu or cuda (as registered)");
  evaluateCommand->add_option("--report", evaluate.Report, "Folder for metrics.json and side-by-side PNGs")->required();

  SweepFromVolumeOptions sweep;
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
  sweepCommand->add_option("--frames", sweep.Frames, "Number of slices (the paper: 160 and 80)")->capture_default_str();
  sweepCommand->add_option("--axis", sweep.Axis, "Axis the parallel slices step along (0, 1, 2)")->capture_default_str();
  sweepCommand->add_option("--offset", sweep.Offset, "Shift in slice spacings, [0, 1): 0.5 = in-between slices")
    ->capture_default_str();
  sweepCommand->add_option("--tilt", sweep.Tilt, "Oblique: largest tilt, degrees")->capture_default_str();
  sweepCommand->add_option("--seed", sweep.Seed, "Oblique: random seed")->capture_default_str();
  sweepCommand->add_option("--spacing", sweep.Spacing, "Pixel spacing, mm (0: the volume's)")->capture_default_str();

  FillGapsOptions fillGaps;
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
    ->check(CLI::PositiveNumber);
  fillGapsCommand
    ->add_option("--clearance", fillGaps.Settings.ClearanceSigmas,
      "Copies stay this many beam widths away from the frames on either side")
    ->capture_default_str()
    ->check(CLI::NonNegativeNumber);
  fillGapsCommand
    ->add_option("--blend-margin", fillGaps.Settings.BlendMarginSigmas,
      "Within this many beam widths of a frame (at most a quarter of the gap) the copies carry that frame alone; "
      "between the margins the blend is linear")
    ->capture_default_str()
    ->check(CLI::NonNegativeNumber);
  fillGapsCommand
    ->add_option("--max-gaussians", fillGaps.Settings.MaximumGaussians,
      "The most Gaussians the filled field may hold (0: no limit); where a gap's copies would exceed it, only the "
      "strongest Gaussians of its two frames whose copies fit are copied")
    ->capture_default_str()
    ->check(CLI::NonNegativeNumber);

  bigus::BenchmarkOptions benchmark;
  benchmark.SourceDirectory = BIGUS_SOURCE_DIR;
  CLI::App* benchmarkCommand = app.add_subcommand("benchmark",
    "Speed against error on the bundled sweeps: baselines, volume protocol, capacity, render cutoffs, ablations, "
    "defaults against hand-tuned, block hold-outs; "
    "writes OUTPUT/BENCHMARKS.md and OUTPUT/benchmarks/ (about 3 hours on 2 cores)");
  benchmarkCommand->add_option("--output", benchmark.Output, "Folder for BENCHMARKS.md (default: docs)");
  benchmarkCommand->add_option("--data", benchmark.SourceDirectory, "Project folder holding Examples/Data and Testing/Data")
    ->check(CLI::ExistingDirectory);
  benchmarkCommand->add_flag("--quick", benchmark.Quick, "A few minutes: short training, small crops (smoke test)");
  benchmarkCommand
    ->add_option("--section", benchmark.Section,
      "all, or one section alone, written to BENCHMARKS_<section>.md: defaults (defaults against hand-tuned), "
      "volume (the volume protocol), blocks (block hold-outs on the liver) or ablations (every switch at equal "
      "iterations and equal time, 3 seeds; about 2 hours) or pareto (held-out PSNR against Gaussians and time: "
      "Adam alone, variable projection and the regular grid; about 30 minutes)")
    ->capture_default_str()
    ->check(CLI::IsMember({ "all", "defaults", "volume", "blocks", "ablations", "pareto" }));

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
  if (trainCommand->parsed())
  {
    if (iterations->count() == 0 && train.TimeBudget > 0)
    {
      train.Iterations = 0; // the budget alone is the schedule
    }
    return RunTrain(train);
  }
  if (renderCommand->parsed())
  {
    return RunRender(render);
  }
  if (evaluateCommand->parsed())
  {
    return RunEvaluate(evaluate);
  }
  if (sweepCommand->parsed())
  {
    return RunSweepFromVolume(sweep);
  }
  if (fillGapsCommand->parsed())
  {
    if (fillGaps.Output == fillGaps.Field)
    {
      return Fail(fillGaps.Output + ": the output would overwrite the input field");
    }
    return RunFillGaps(fillGaps);
  }
  if (benchmarkCommand->parsed())
  {
    return bigus::RunBenchmark(benchmark);
  }
  return 2;
}
