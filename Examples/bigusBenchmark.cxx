// `bigus benchmark`: speed against error.
//
// What it measures (issue 6), every number printed and written to BENCHMARKS.md as measured:
// - on each bundled real sweep (liver, spine phantom, N-wire) with the hold-out protocol (frames with
//   i mod 4 == 2 held out): held-out PSNR, SSIM, NCC and speckle score of BIGUS after several training
//   times, next to the classical baselines (nearest training frame by pose, blend of the bracketing
//   training frames, PLUS-style compounded volume resliced trilinearly) with their own times, and
//   the same on 20 frames of the liver (about 7 times the steps per training frame in the same time),
//   and where the held-out error comes from (training-frame PSNR, the blend of the field's own renders);
// - the volume protocol on the PLUS reconstruction of the spine phantom: train on parallel slices,
//   test on in-between, oblique and orthogonal slices;
// - quality against the number of Gaussians (capped runs against the adaptive stop);
// - render time per slice against the error from the naive double-precision renderer, per cutoff;
// - ablations: every switch (EA-D, Harris, beam integration, signed reflectivity, D-SSIM, FFL, capacity cap)
//   at equal iterations and at equal time, 3 seeds, on four sweeps;
// - held-out PSNR against the number of Gaussians and against time (a Pareto table): Adam alone, variable
//   projection and a regular grid with the same reflectivity solve;
// Times are wall-clock seconds on this machine; training time excludes the evaluations, which stop the
// clock, and the rows at the time marks are of the field as trained so far (no final prune).
#include "bigusBenchmark.h"

#include "bigusGaussianFieldData.h"
#include "bigusImageMetrics.h"
#include "bigusPlot.h"
#include "bigusReferenceRenderer.h"
#include "bigusTrainer.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkMetaImageReader.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkSMPTools.h"
#include "vtkSmartPointer.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundFrameInterpolator.h"
#include "vtkUltrasoundSequenceReader.h"
#include "vtkUltrasoundSequenceReslice.h"
#include "vtkUltrasoundVolumeCompounder.h"
#include "vtkUltrasoundVolumeSweep.h"

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <functional>
#include <limits>
#include <numeric>
#include <sstream>
#include <string>
#include <sys/stat.h>
#include <thread>
#include <utility>
#include <vector>

namespace bigus
{
namespace
{
const double NaN = std::numeric_limits<double>::quiet_NaN();

double Now()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Peak resident memory of this process since the last ResetPeakMemory (MiB; Linux VmHWM).
double PeakMemoryMiB()
{
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
  {
    if (line.rfind("VmHWM:", 0) == 0)
    {
      return std::stod(line.substr(6)) / 1024.0;
    }
  }
  return NaN;
}

/// Resets VmHWM to the current resident size (Linux >= 4.0), so that each run reports its own peak.
void ResetPeakMemory()
{
  std::ofstream("/proc/self/clear_refs") << "5";
}

std::string CommandOutput(const std::string& command)
{
  std::string out;
  if (FILE* pipe = ::popen(command.c_str(), "r"))
  {
    char buffer[256];
    while (std::fgets(buffer, sizeof(buffer), pipe))
    {
      out += buffer;
    }
    ::pclose(pipe);
  }
  while (!out.empty() && (out.back() == '\n' || out.back() == ' '))
  {
    out.pop_back();
  }
  return out;
}

std::string CpuModel()
{
  std::ifstream cpu("/proc/cpuinfo");
  std::string line;
  while (std::getline(cpu, line))
  {
    if (line.rfind("model name", 0) == 0)
    {
      return line.substr(line.find(':') + 2);
    }
  }
  return "unknown";
}

std::string Format(const char* format, double value)
{
  if (!std::isfinite(value))
  {
    return "-";
  }
  char text[64];
  std::snprintf(text, sizeof(text), format, value);
  return text;
}

/// One line of a results table.
struct Row
{
  std::string Method;
  double Seconds = NaN;       ///< training or preparation time (s)
  double MsPerFrame = NaN;    ///< time to produce one frame once trained / compounded (ms)
  ImageMetrics Quality;
  long long Gaussians = -1;
  double PeakMiB = NaN;
  std::string Note;
};

nlohmann::json ToJson(const Row& r)
{
  auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return { { "method", r.Method }, { "seconds", number(r.Seconds) }, { "ms_per_frame", number(r.MsPerFrame) },
    { "psnr", number(r.Quality.PSNR) }, { "ssim", number(r.Quality.SSIM) }, { "ncc", number(r.Quality.NCC) },
    { "speckle", number(r.Quality.Speckle) }, { "gaussians", r.Gaussians }, { "peak_mib", number(r.PeakMiB) },
    { "note", r.Note } };
}

std::string TableHeader()
{
  return "| method | time (s) | ms / frame | PSNR (dB) | SSIM | NCC | speckle | Gaussians | peak MiB | note |\n"
         "|---|---|---|---|---|---|---|---|---|---|\n";
}

std::string TableRow(const Row& r)
{
  std::ostringstream s;
  s << "| " << r.Method << " | " << Format("%.1f", r.Seconds) << " | " << Format("%.1f", r.MsPerFrame) << " | "
    << Format("%.2f", r.Quality.PSNR) << " | " << Format("%.4f", r.Quality.SSIM) << " | "
    << Format("%.4f", r.Quality.NCC) << " | " << Format("%.4f", r.Quality.Speckle) << " | "
    << (r.Gaussians >= 0 ? std::to_string(r.Gaussians) : "-") << " | " << Format("%.0f", r.PeakMiB) << " | "
    << r.Note << " |\n";
  return s.str();
}

void Print(const std::string& where, const Row& r)
{
  std::printf("  %-12s %-44s %8s s %8s ms/frame  PSNR %6s  SSIM %6s  NCC %6s  speckle %6s  %s Gaussians\n",
    where.c_str(), r.Method.c_str(), Format("%.1f", r.Seconds).c_str(), Format("%.1f", r.MsPerFrame).c_str(),
    Format("%.2f", r.Quality.PSNR).c_str(), Format("%.4f", r.Quality.SSIM).c_str(),
    Format("%.4f", r.Quality.NCC).c_str(), Format("%.4f", r.Quality.Speckle).c_str(),
    r.Gaussians >= 0 ? std::to_string(r.Gaussians).c_str() : "-");
  std::fflush(stdout);
}

/// Mean metrics of predicted frames (M frames, [M, H, W], intensities times @p scale) against @p frames
/// of @p data, inside each frame's mask (bigus::MeanFrameMetrics).
ImageMetrics Score(const float* predicted, double scale, const TrainingData& data, const std::vector<int>& frames)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  std::vector<float> image(pixels);
  return MeanFrameMetrics(data, frames, [&](std::size_t m, int) {
    for (std::size_t p = 0; p < pixels; ++p)
    {
      image[p] = static_cast<float>(predicted[pixels * m + p] * scale);
    }
    return image.data();
  });
}

vtkSmartPointer<vtkIdList> IdList(const std::vector<int>& frames)
{
  auto list = vtkSmartPointer<vtkIdList>::New();
  for (int k : frames)
  {
    list->InsertNextId(k);
  }
  return list;
}

/// A tracked sweep with the hold-out protocol, in the two forms the methods need.
struct Sweep
{
  std::string Name, File, Calibration, Description;
  double ElevationSigma = 1.0;
  int Iterations = 3000;
  std::vector<int> FrameRange;          ///< empty, or the first and last frame read (inclusive)
  std::vector<double> Marks;            ///< training times (s) at which BIGUS is evaluated
  double DefaultsBudget = 60;           ///< time budget (s) of the defaults against hand-tuned runs
  vtkSmartPointer<vtkImageData> Frames; ///< the sequence as read
  vtkSmartPointer<vtkImageData> Mask;   ///< its fan mask (W x H x 1)
  double Scale = 1;                     ///< input units -> [0, 1]
  TrainingData Data;                    ///< Data.TrainFrames: valid frames with i mod 4 != 2
  std::vector<int> HeldOut;             ///< valid frames with i mod 4 == 2
};

bool Load(Sweep& sweep, std::string* error)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(sweep.File.c_str());
  if (!sweep.Calibration.empty())
  {
    reader->SetCalibrationFileName(sweep.Calibration.c_str());
  }
  if (sweep.FrameRange.size() == 2)
  {
    reader->SetFrameRange(sweep.FrameRange[0], sweep.FrameRange[1]);
  }
  reader->Update();
  if (*reader->GetLastErrorText())
  {
    *error = reader->GetLastErrorText();
    return false;
  }
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputConnection(reader->GetOutputPort());
  fan->Update();
  sweep.Frames = reader->GetOutput();
  sweep.Mask = fan->GetOutput();
  sweep.Scale = sweep.Frames->GetPointData()->GetScalars()->GetDataType() == VTK_UNSIGNED_CHAR ? 1.0 / 255 : 1.0;
  if (!TrainingDataFromSequence(sweep.Frames, sweep.Mask, sweep.Data, error))
  {
    *error = sweep.File + ": " + *error;
    return false;
  }
  vtkDataArray* valid = sweep.Frames->GetFieldData()->GetArray("FrameValid");
  for (int k = 0; k < sweep.Data.Count(); ++k)
  {
    if (!valid || valid->GetTuple1(k) != 0)
    {
      (k % 4 == 2 ? sweep.HeldOut : sweep.Data.TrainFrames).push_back(k);
    }
  }
  int dims[3];
  sweep.Frames->GetDimensions(dims);
  std::ostringstream d;
  if (sweep.FrameRange.size() == 2)
  {
    d << "frames " << sweep.FrameRange[0] << " to " << sweep.FrameRange[1] << ": ";
  }
  d << dims[2] << " frames of " << dims[0] << " x " << dims[1] << " pixels ("
    << Format("%.4f", PixelSpacingOf(sweep.Data.Poses[0])) << " mm), " << sweep.Data.TrainFrames.size()
    << " trained on, " << sweep.HeldOut.size() << " held out (i mod 4 == 2); elevation sigma "
    << Format("%.2f", sweep.ElevationSigma) << " mm, schedule of " << sweep.Iterations << " iterations";
  sweep.Description = d.str();
  return true;
}

/// The three classical baselines of a sweep, each with its own time.
std::vector<Row> Baselines(const Sweep& sweep)
{
  std::vector<Row> rows;
  const double n = static_cast<double>(sweep.HeldOut.size());
  for (int mode : { vtkUltrasoundFrameInterpolator::NEAREST_POSE, vtkUltrasoundFrameInterpolator::TEMPORAL_BLEND })
  {
    vtkNew<vtkUltrasoundFrameInterpolator> predict;
    predict->SetInputData(sweep.Frames);
    predict->SetTrainingFrames(IdList(sweep.Data.TrainFrames));
    predict->SetTargetFrames(IdList(sweep.HeldOut));
    predict->SetMode(mode);
    const double t0 = Now();
    predict->Update();
    Row r;
    r.MsPerFrame = 1e3 * (Now() - t0) / n;
    r.Seconds = 0;
    r.Method = mode == vtkUltrasoundFrameInterpolator::NEAREST_POSE ? "nearest training frame (pose)"
                                                                    : "blend of bracketing training frames (time)";
    r.Quality = Score(static_cast<float*>(predict->GetOutput()->GetScalarPointer()), sweep.Scale, sweep.Data,
      sweep.HeldOut);
    rows.push_back(r);
  }
  // PLUS-style compounding of the training frames with PLUS's settings for the bundled phantoms
  // (0.5 mm voxels). Without the held-out frames the gaps between training frames reach 2 to 4.6 mm
  // (spine), so holes are filled with cubes of up to 11 voxels that need 10 % known voxels (two frame
  // planes in an 11^3 cube are 18 %).
  const double voxel = 0.5;
  vtkNew<vtkUltrasoundVolumeCompounder> compound;
  compound->SetInputData(sweep.Frames);
  compound->SetFanMaskData(sweep.Mask);
  compound->SetFrameList(IdList(sweep.Data.TrainFrames));
  compound->SetOutputSpacing(voxel, voxel, voxel);
  compound->SetHoleFillingMaximumKernelSize(11);
  compound->SetHoleFillingMinimumKnownRatio(0.1);
  double t0 = Now();
  compound->Update();
  const double compoundSeconds = Now() - t0;
  vtkNew<vtkUltrasoundSequenceReslice> reslice;
  reslice->SetInputConnection(compound->GetOutputPort());
  reslice->SetPoseData(sweep.Frames);
  reslice->SetFrameList(IdList(sweep.HeldOut));
  reslice->MaskEmptyVoxelsOff();
  t0 = Now();
  reslice->Update();
  Row r;
  r.Method = "compounded volume (NN, MEAN, hole filling) + trilinear reslice";
  r.Seconds = compoundSeconds;
  r.MsPerFrame = 1e3 * (Now() - t0) / n;
  int dims[3];
  compound->GetOutput()->GetDimensions(dims);
  r.Note = Format("%.1f", voxel) + " mm voxels, holes filled up to 11^3, " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) +
    " x " + std::to_string(dims[2]);
  // The compounded volume holds the input's units (0-255 for 8-bit frames) as float, which the reslice
  // passes through unscaled.
  r.Quality =
    Score(static_cast<float*>(reslice->GetOutput()->GetScalarPointer()), sweep.Scale, sweep.Data, sweep.HeldOut);
  rows.push_back(r);
  return rows;
}

/**
 * For scale, not a predictor: the held-out frames themselves, blurred in plane by a Gaussian of
 * @p sigmas (pixels; OpenCV GaussianBlur, reflected borders). It tells how much fine detail (speckle)
 * a method must reproduce to reach a given PSNR, since no prediction from other frames can beat the
 * truth at the resolution it resolves.
 */
std::vector<std::pair<double, ImageMetrics>> BlurredTruth(const Sweep& sweep, const std::vector<double>& sigmas)
{
  const TrainingData& data = sweep.Data;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  std::vector<float> blurred(pixels);
  std::vector<std::pair<double, ImageMetrics>> out;
  for (double sigma : sigmas)
  {
    out.emplace_back(sigma, MeanFrameMetrics(data, sweep.HeldOut, [&](std::size_t, int f) {
      const cv::Mat truth(data.Height, data.Width, CV_32F, const_cast<float*>(&data.Frames[pixels * f]));
      cv::Mat result(data.Height, data.Width, CV_32F, blurred.data());
      cv::GaussianBlur(truth, result, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
      return static_cast<const float*>(blurred.data());
    }));
  }
  return out;
}

/// Where a trained field's held-out error comes from: its fit of the training frames, and its render at
/// a held-out pose against the blend of its own renders at the bracketing training frames.
struct ErrorSources
{
  double Seconds = NaN;
  ImageMetrics Training;       ///< renders at the training poses against the recorded frames
  ImageMetrics HeldOut;        ///< renders at the held-out poses (the BIGUS row)
  ImageMetrics BlendedRenders; ///< the blend baseline run on the field's renders instead of the recording
};

/// PSNR (dB, data range 1) of the sum of the mean squared errors of two predictions given by their PSNR.
double PsnrOfSummedErrors(double psnrA, double psnrB)
{
  return -10 * std::log10(std::pow(10.0, -psnrA / 10) + std::pow(10.0, -psnrB / 10));
}

/// Fills @p e; false with @p error when the field cannot be rendered at a training pose.
bool MeasureErrorSources(const Sweep& sweep, Trainer& trainer, const Row& bigusRow, ErrorSources& e, std::string* error)
{
  const TrainingData& data = sweep.Data;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  // The renders at every training pose in a float copy of the sweep (same poses and timestamps), so
  // that vtkUltrasoundFrameInterpolator blends them exactly as it blends the recording for the baseline.
  vtkNew<vtkImageData> renders;
  renders->SetDimensions(sweep.Frames->GetDimensions());
  renders->AllocateScalars(VTK_FLOAT, 1);
  renders->GetFieldData()->ShallowCopy(sweep.Frames->GetFieldData());
  float* image = static_cast<float*>(renders->GetScalarPointer());
  std::fill_n(image, pixels * data.Count(), 0.f);
  for (int f : data.TrainFrames)
  {
    if (!trainer.RenderFrame(data, f, image + pixels * f, error))
    {
      return false;
    }
  }
  e.Seconds = bigusRow.Seconds;
  e.HeldOut = bigusRow.Quality;
  e.Training = MeanFrameMetrics(data, data.TrainFrames, [&](std::size_t, int f) { return image + pixels * f; });
  vtkNew<vtkUltrasoundFrameInterpolator> blend;
  blend->SetInputData(renders);
  blend->SetTrainingFrames(IdList(data.TrainFrames));
  blend->SetTargetFrames(IdList(sweep.HeldOut));
  blend->SetModeToTemporalBlend();
  blend->Update();
  e.BlendedRenders =
    Score(static_cast<float*>(blend->GetOutput()->GetScalarPointer()), 1.0, data, sweep.HeldOut);
  return true;
}

/// The report's account of where the held-out error comes from, one row per time mark, also added to
/// the sweep's JSON @p j; @p blend is the blend baseline's row on the recording.
std::string ErrorSourcesSection(const Row& blend, const std::vector<ErrorSources>& sources, nlohmann::json& j)
{
  std::ostringstream md;
  md << "\nWhere the held-out error comes from (see the conventions above; the blend of the recorded frames "
     << "scores " << Format("%.2f", blend.Quality.PSNR) << " dB):\n\n"
     << "| time (s) | training frames PSNR (dB) | held-out PSNR (dB) | blended renders PSNR (dB) | fit + blend (dB) |\n"
     << "|---|---|---|---|---|\n";
  double estimate = NaN;
  for (const ErrorSources& e : sources)
  {
    estimate = PsnrOfSummedErrors(e.Training.PSNR, blend.Quality.PSNR);
    md << "| " << Format("%.1f", e.Seconds) << " | " << Format("%.2f", e.Training.PSNR) << " | "
       << Format("%.2f", e.HeldOut.PSNR) << " | " << Format("%.2f", e.BlendedRenders.PSNR) << " | "
       << Format("%.2f", estimate) << " |\n";
    j["error_sources"].push_back({ { "seconds", e.Seconds }, { "training_psnr", e.Training.PSNR },
      { "training_ssim", e.Training.SSIM }, { "held_out_psnr", e.HeldOut.PSNR },
      { "blended_renders_psnr", e.BlendedRenders.PSNR }, { "fit_plus_blend_psnr", estimate } });
  }
  const ErrorSources& last = sources.back();
  const double gain = last.HeldOut.PSNR - last.BlendedRenders.PSNR;
  md << "\nAfter " << Format("%.0f", last.Seconds) << " s, rendering the held-out pose scores "
     << Format("%.2f", std::abs(gain)) << " dB " << (gain >= 0 ? "above" : "below")
     << " blending the field's own renders at the bracketing training frames, and the held-out PSNR is "
     << Format("%.2f", std::abs(last.HeldOut.PSNR - estimate)) << " dB from the fit + blend estimate.\n";
  return md.str();
}

/// Trains with @p settings, evaluating @p heldOut at each of @p marks (cumulative training seconds);
/// @p onMark is called with the mark, its row (measured time) and the trainer, and returns false (with
/// @p error) when its own measurement fails. The field is not pruned at the marks (Trainer::Train).
/// Returns false on a
/// training error.
bool TrainWithMarks(const TrainingData& data, const TrainerSettings& settings, const std::vector<double>& marks,
  const std::vector<int>& heldOut, const std::string& method,
  const std::function<bool(double, const Row&, Trainer&)>& onMark, std::string* error)
{
  ResetPeakMemory();
  Trainer trainer(data, settings);
  double trained = 0;
  double t0 = Now();
  if (!trainer.Initialize(error))
  {
    return false;
  }
  trained += Now() - t0;
  for (double mark : marks)
  {
    const double start = Now();
    const double slice = mark - trained;
    if (slice > 0 && trainer.GetIteration() < settings.Iterations &&
      !trainer.Train(nullptr, [&]() { return Now() - start >= slice; }, error))
    {
      return false;
    }
    trained += Now() - start;
    Row r;
    r.Method = method;
    r.Seconds = trained;
    double secondsPerFrame = 0;
    if (!trainer.Evaluate(heldOut, r.Quality, error, &secondsPerFrame))
    {
      return false;
    }
    r.MsPerFrame = 1e3 * secondsPerFrame;
    r.Gaussians = trainer.GetField().Count();
    r.PeakMiB = PeakMemoryMiB();
    r.Note = std::to_string(trainer.GetIteration()) + " steps";
    if (!onMark(mark, r, trainer))
    {
      return false;
    }
    if (trainer.GetIteration() >= settings.Iterations)
    {
      break; // the schedule ended before the later marks: they would repeat this row
    }
  }
  return true;
}

/// PSNR against time (log axis) of every method of one experiment.
PlotSpec TimePlot(const std::string& title, const std::vector<Row>& baselines, const std::vector<Row>& bigus)
{
  PlotSpec spec;
  spec.Title = title;
  spec.XLabel = "time (s, log): training, or compounding + one frame";
  spec.YLabel = "PSNR (dB)";
  spec.LogX = true;
  PlotSeries curve{ "BIGUS (training time)", {} };
  for (const Row& r : bigus)
  {
    curve.Points.emplace_back(r.Seconds, r.Quality.PSNR);
  }
  spec.Series.push_back(curve);
  for (const Row& r : baselines)
  {
    // A baseline's own time: its preparation plus producing one frame (at least 1 ms to fit the axis).
    const double t = std::max(1e-3, (std::isfinite(r.Seconds) ? r.Seconds : 0) + 1e-3 * r.MsPerFrame);
    spec.Series.push_back({ r.Method, { { t, r.Quality.PSNR } } });
  }
  return spec;
}

/// The naive double-precision renderer's image of a Width x Width crop at the centre of a frame.
struct CropReference
{
  SliceGeometry Slice;
  std::vector<double> I;
};

CropReference RenderReference(const GaussianField& field, const RenderOptions& o, const std::array<double, 16>& pose,
  int width, int height, int crop)
{
  CropReference ref;
  const double i0 = (width - crop) / 2, j0 = (height - crop) / 2;
  std::copy(pose.begin(), pose.end(), ref.Slice.ImageToReference);
  for (int r = 0; r < 3; ++r)
  {
    ref.Slice.ImageToReference[4 * r + 3] += pose[4 * r] * i0 + pose[4 * r + 1] * j0;
  }
  ref.Slice.Width = crop;
  ref.Slice.Height = crop;
  reference::FieldD d;
  d.Means.assign(field.Means.begin(), field.Means.end());
  d.LogScales.assign(field.LogScales.begin(), field.LogScales.end());
  d.Quaternions.assign(field.Quaternions.begin(), field.Quaternions.end());
  d.Reflectivities.assign(field.Reflectivities.begin(), field.Reflectivities.end());
  std::vector<double> S;
  reference::Forward(d, ref.Slice, o, S, &ref.I);
  return ref;
}

/// Settings of one ablation row: a name and what it changes.
struct Ablation
{
  std::string Name;
  /// Applies the switch; @p seeds is the mean seed count of the full method on the same sweep.
  std::function<void(TrainerSettings&, std::int64_t seeds)> Change;
  std::string PaperDirection; ///< what the paper's Tables 3 and 4 say removing / adding it does
  int PaperSign = -1;         ///< the sign of (variant - full method) in held-out PSNR that the paper reports
};

std::vector<Ablation> Ablations()
{
  return {
    { "no EA-D (no densification)", [](TrainerSettings& s, std::int64_t) { s.Densify = false; }, "lower (EA-D helps)" },
    { "random initialisation (not Harris)", [](TrainerSettings& s, std::int64_t) { s.HarrisInitialisation = false; },
      "lower (Harris initialisation helps)" },
    { "thin plane (no beam integration, UltraGauss)", [](TrainerSettings& s, std::int64_t) { s.BeamIntegration = false; },
      "lower (beam integration helps)" },
    { "non-negative reflectivity", [](TrainerSettings& s, std::int64_t) { s.NonNegativeReflectivity = true; },
      "lower (signed reflectivity helps)" },
    { "L1 only (no D-SSIM)", [](TrainerSettings& s, std::int64_t) { s.Loss.DSSIM = 0; },
      "lower (D-SSIM helps structure)" },
    { "L1 + D-SSIM + FFL (0.1)", [](TrainerSettings& s, std::int64_t) { s.Loss.FFL = 0.1; }, "higher (FFL helps speckle)",
      +1 },
    { "capacity cap at the seed count", [](TrainerSettings& s, std::int64_t seeds) {
        s.InitialGaussians = seeds;
        s.MaximumGaussians = seeds;
      },
      "lower (adaptive capacity helps)" },
    { "dense Adam (every Gaussian every step)", [](TrainerSettings& s, std::int64_t) { s.SparseAdam = false; },
      "not in the paper; lower at equal time (sparse Adam: Mallick et al. 2024, Taming 3DGS)" },
  };
}

struct Report
{
  std::ostringstream Markdown;
  nlohmann::json Json;
  std::string PlotFolder; ///< absolute or relative to the working directory
  std::string PlotLink;   ///< relative to BENCHMARKS.md
  bool Plot(const PlotSpec& spec, const std::string& name)
  {
    if (!WritePlot(spec, this->PlotFolder + "/" + name))
    {
      return false;
    }
    this->Markdown << "\n![" << spec.Title << "](" << this->PlotLink << "/" << name << ")\n";
    return true;
  }
};

int Fail(const std::string& what)
{
  std::fprintf(stderr, "bigus: benchmark: %s\n", what.c_str());
  return 1;
}

bool MakeFolder(const std::string& path)
{
  return ::mkdir(path.c_str(), 0755) == 0 || errno == EEXIST;
}

/// Sets @p error to @p what and returns false: how a section fails (RunBenchmark reports it).
bool Failed(const std::string& what, std::string* error)
{
  *error = what;
  return false;
}

/// Training time (s) of each capacity run, and the time mark of the liver's full method they are
/// compared with.
double CapacitySeconds(bool quick)
{
  return quick ? 4 : 60;
}

/**
 * The bundled real sweeps, each with its training schedule and time marks (s): liver, spine phantom,
 * N-wire phantom, and 20 frames of the liver. The default run takes about 3 hours on 2 cores,
 * --quick a few minutes.
 */
std::vector<Sweep> BundledSweeps(const std::string& root, bool quick)
{
  std::vector<Sweep> sweeps(4);
  sweeps[0].Name = "liver";
  sweeps[0].File = root + "/Examples/Data/liver/liver_sweep.igs.mha";
  // The liver's frames decorrelate within a few tenths of a millimetre (vtkGaussianFieldTrainer.h): held-out
  // PSNR after 10 minutes on 2 cores was 37.6 dB at sigma 0.3 mm, 36.3 at 0.5 and 35.6 at 1.0.
  sweeps[0].ElevationSigma = 0.3;
  sweeps[0].Iterations = quick ? 300 : 8000; // at 10 minutes on 2 cores 7,703 steps are done
  sweeps[0].Marks = quick ? std::vector<double>{ 4, 8 } : std::vector<double>{ 30, 60, 120, 300, 600 };
  sweeps[0].DefaultsBudget = quick ? 4 : 300; // the main job's budget
  sweeps[1].Name = "spine phantom";
  sweeps[1].File = root + "/Testing/Data/spine-phantom/SpinePhantomFreehand.igs.mha";
  sweeps[1].Calibration = root + "/Testing/Data/spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml";
  sweeps[1].ElevationSigma = 1.5;
  sweeps[1].Iterations = quick ? 300 : 3000;
  sweeps[1].Marks = quick ? std::vector<double>{ 4, 8 } : std::vector<double>{ 30, 60, 120, 300 };
  sweeps[1].DefaultsBudget = quick ? 4 : 300;
  sweeps[2].Name = "N-wire phantom";
  sweeps[2].File = root + "/Testing/Data/nwire-phantom/NwirePhantomFreehand.igs.mha";
  sweeps[2].Calibration =
    root + "/Testing/Data/nwire-phantom/PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml";
  sweeps[2].ElevationSigma = 1.0;
  sweeps[2].Iterations = quick ? 300 : 1200;
  sweeps[2].Marks = quick ? std::vector<double>{ 4 } : std::vector<double>{ 30, 60, 120 };
  sweeps[2].DefaultsBudget = quick ? 4 : 60;
  // The same liver settings on 20 of its 140 frames: in the same time every training frame is visited
  // about 7 times as often, which shows what more steps (a faster backend) would buy on the full sweep.
  sweeps[3] = sweeps[0];
  sweeps[3].Name = "liver, frames 40 to 59";
  sweeps[3].FrameRange = { 40, 59 };
  sweeps[3].DefaultsBudget = quick ? 4 : 120;
  return sweeps;
}

/// The report's title, the machine and commit, and the conventions of every table (also in @p report.Json).
void Introduction(const std::string& root, bool quick, Report& report)
{
  const std::string commit = CommandOutput("git -C '" + root + "' rev-parse --short HEAD 2>/dev/null");
  const bool dirty = !CommandOutput("git -C '" + root + "' status --porcelain --untracked-files=no 2>/dev/null").empty();
  char date[64];
  const std::time_t now = std::time(nullptr);
  std::strftime(date, sizeof(date), "%Y-%m-%d %H:%M %Z", std::localtime(&now));
  const std::string machine = CpuModel() + ", " + std::to_string(std::thread::hardware_concurrency()) +
    " logical cores, " + std::to_string(vtkSMPTools::GetEstimatedNumberOfThreads()) + " threads (" +
    vtkSMPTools::GetBackend() + ")";
  std::printf("bigus benchmark%s: %s\n", quick ? " --quick" : "", machine.c_str());

  std::ostringstream& md = report.Markdown;
  md << "# Benchmarks: speed against error\n\n"
     << "Produced by `bigus benchmark" << (quick ? " --quick" : "") << "` on " << date << " at commit `" << commit
     << (dirty ? " (with uncommitted changes)" : "") << "`.\n"
     << "Machine: " << machine << "; no GPU was used (CPU backend).\n"
     << "Every number below is the one this command printed; rerun it to reproduce them (timings vary "
     << "between runs on a shared machine: compare within one report). The hand-run measurements behind "
     << "the trainer's defaults are in docs/FINDINGS.md.\n\n"
     << "Conventions: metrics inside the fan mask of the recorded frame (DESIGN section 9; speckle = "
     << "Backscatter Fidelity Score). Training time is wall-clock and "
     << "stops while held-out frames are evaluated; each row is the field as trained until then, without the "
     << "final prune (which changes no training pixel by more than 1/512). A baseline's time is its preparation (compounding) "
     << "and its ms per frame is the time to produce one held-out frame; BIGUS's ms per frame is the render "
     << "time of one held-out frame. Peak MiB is the process's peak resident memory during that run "
     << "(frames of every sweep included).\n\n"
     << "Where the held-out error comes from (a table per sweep): the field rendered at its training poses "
     << "(training frames) and at the held-out poses (held-out) against the recording, and the blend baseline "
     << "run on the field's renders instead of the recording (blended renders: its renders at the two bracketing "
     << "training frames, blended in time). If the field's views between training frames were as good an "
     << "interpolation as blending the recorded frames, its held-out error would be its training error plus the "
     << "blend's error: fit + blend adds the two mean squared errors (MSE = 10^(-PSNR / 10), from mean PSNRs, so "
     << "approximate).\n";
  report.Json["date"] = date;
  report.Json["commit"] = commit + (dirty ? "+dirty" : "");
  report.Json["machine"] = machine;
  report.Json["quick"] = quick;
}

/// What the later sections take from the hold-out runs.
struct HoldOutResults
{
  GaussianField LiverField; ///< the liver's field at the end of its run (render speed against error)
  RenderOptions LiverOptions;
  Row LiverAtCapacityTime; ///< the liver's default run at CapacitySeconds (the full method)
  std::vector<std::vector<Row>> Bigus; ///< per sweep, its BIGUS rows at the time marks
};

/**
 * The section of sweep @p si of BundledSweeps with the hold-out protocol: the baselines, BIGUS at the
 * sweep's time marks, the blurred truth for scale, where the held-out error comes from, and the plot
 * psnr_time_<si>.png. The liver (si 0) also runs to the capacity section's time and keeps its field.
 */
bool HoldOutSection(Sweep& sweep, std::size_t si, const std::string& root, bool quick, Report& report,
  HoldOutResults& results, std::string* error)
{
  std::ostringstream& md = report.Markdown;
  const double capacitySeconds = CapacitySeconds(quick);
  if (!Load(sweep, error))
  {
    return false;
  }
  std::printf("%s: %s\n", sweep.Name.c_str(), sweep.Description.c_str());
  const std::vector<Row> baselines = Baselines(sweep);
  for (const Row& r : baselines)
  {
    Print(sweep.Name, r);
  }
  TrainerSettings s;
  s.ElevationSigma = sweep.ElevationSigma;
  s.Iterations = sweep.Iterations;
  std::vector<double> marks = sweep.Marks;
  if (si == 0 && std::find(marks.begin(), marks.end(), capacitySeconds) == marks.end())
  {
    marks.push_back(capacitySeconds);
    std::sort(marks.begin(), marks.end());
  }
  std::vector<Row> bigus;
  std::vector<ErrorSources> sources;
  const bool ok = TrainWithMarks(sweep.Data, s, marks, sweep.HeldOut, "BIGUS",
    [&](double mark, const Row& r, Trainer& trainer) {
      Print(sweep.Name, r);
      if (std::find(sweep.Marks.begin(), sweep.Marks.end(), mark) != sweep.Marks.end())
      {
        bigus.push_back(r);
        sources.emplace_back();
        if (!MeasureErrorSources(sweep, trainer, r, sources.back(), error))
        {
          return false;
        }
        // Its renders are freed again: the next row's peak memory is the training's own.
        ResetPeakMemory();
      }
      if (si == 0)
      {
        if (mark == capacitySeconds)
        {
          results.LiverAtCapacityTime = r;
        }
        results.LiverField = trainer.GetField();
        results.LiverOptions = trainer.Options();
      }
      return true;
    },
    error);
  if (!ok)
  {
    return Failed(sweep.Name + ": " + *error, error);
  }
  results.Bigus.resize(std::max(results.Bigus.size(), si + 1));
  results.Bigus[si] = bigus;
  if (si == 0 && !std::isfinite(results.LiverAtCapacityTime.Seconds))
  {
    results.LiverAtCapacityTime = bigus.back(); // the schedule ended before the capacity time
  }
  md << "\n## " << sweep.Name << "\n\n`" << sweep.File.substr(root.size() + 1) << "`: " << sweep.Description
     << ".\n\n"
     << TableHeader();
  nlohmann::json j;
  j["description"] = sweep.Description;
  for (const Row& r : baselines)
  {
    md << TableRow(r);
    j["baselines"].push_back(ToJson(r));
  }
  for (const Row& r : bigus)
  {
    md << TableRow(r);
    j["bigus"].push_back(ToJson(r));
  }
  const Row* best = &baselines[0];
  for (const Row& r : baselines)
  {
    best = r.Quality.PSNR > best->Quality.PSNR ? &r : best;
  }
  const Row& last = bigus.back();
  md << "\nAfter " << Format("%.0f", last.Seconds) << " s BIGUS is at " << Format("%.2f", last.Quality.PSNR)
     << " dB; the best baseline, " << best->Method << ", at " << Format("%.2f", best->Quality.PSNR) << " dB ("
     << (last.Quality.PSNR > best->Quality.PSNR ? "BIGUS ahead by " : "BIGUS behind by ")
     << Format("%.2f", std::abs(last.Quality.PSNR - best->Quality.PSNR)) << " dB).\n";
  md << "\nFor scale, the held-out frames themselves blurred in plane (Gaussian, sigma in pixels) score";
  const char* separator = " ";
  for (const auto& [sigma, q] : BlurredTruth(sweep, { 0.5, 1.0, 1.5, 2.0 }))
  {
    md << std::exchange(separator, ", ") << Format("%.2f", q.PSNR) << " dB (SSIM " << Format("%.3f", q.SSIM)
       << ") at " << Format("%.1f", sigma);
    j["blurred_truth"].push_back({ { "sigma_pixels", sigma }, { "psnr", q.PSNR }, { "ssim", q.SSIM } });
  }
  md << ": a prediction at one of these scores is as close to the recording as the recording blurred that much.\n";
  md << ErrorSourcesSection(baselines[1], sources, j); // Baselines(): nearest, blend, compounded
  report.Json["sweeps"][sweep.Name] = j;
  if (!report.Plot(TimePlot(sweep.Name + ": held-out PSNR against time", baselines, bigus),
        "psnr_time_" + std::to_string(si) + ".png"))
  {
    return Failed(report.PlotFolder + ": cannot write a plot", error);
  }
  return true;
}

/// Trains @p data with @p settings through Finish (early stopping, final prune, gap filling) and fills
/// @p row (method, time, Gaussians, peak memory, a note with the steps and the sigma used); then
/// @p evaluate scores the finished field into the row (and may copy it).
bool TrainToBudget(const TrainingData& data, const TrainerSettings& settings, const std::string& method, Row& row,
  const std::function<bool(Trainer&, Row&)>& evaluate, std::string* error)
{
  ResetPeakMemory();
  const double start = Now();
  Trainer trainer(data, settings);
  if (!trainer.Initialize(error) || !trainer.Train(nullptr, nullptr, error) || !trainer.Finish(error))
  {
    return false;
  }
  row.Method = method;
  row.Seconds = Now() - start;
  const TrainerReport& report = trainer.GetReport();
  row.Gaussians = trainer.GetField().Count();
  row.PeakMiB = PeakMemoryMiB();
  row.Note = std::to_string(report.Iterations) + " steps, sigma " + Format("%.3f", report.ElevationSigma) + " mm" +
    (report.BestIteration < report.Iterations ? ", field of step " + std::to_string(report.BestIteration) + " kept"
                                              : "");
  return evaluate(trainer, row);
}

/// TrainToBudget on a hold-out sweep, scored on its held-out frames.
bool TrainToBudget(const Sweep& sweep, const TrainerSettings& settings, const std::string& method, Row& row,
  std::string* error)
{
  return TrainToBudget(sweep.Data, settings, method, row,
    [&](Trainer& trainer, Row& r) {
      double secondsPerFrame = 0;
      const bool ok = trainer.Evaluate(sweep.HeldOut, r.Quality, error, &secondsPerFrame);
      r.MsPerFrame = 1e3 * secondsPerFrame;
      return ok;
    },
    error);
}

/// The volume protocol on the PLUS reconstruction of the spine phantom: train on parallel slices, test
/// on in-between, oblique and orthogonal slices, against the compounded volume resliced.
/// The volume protocol's sweeps: parallel training slices through the spine-phantom reconstruction and
/// three test sweeps (in-between parallel, oblique, orthogonal slices).
struct VolumeProtocol
{
  std::string File, Description;
  vtkSmartPointer<vtkImageData> Volume;
  vtkSmartPointer<vtkUltrasoundVolumeSweep> Train, Tests[3];
  TrainingData TrainData, TestData[3];
  std::vector<int> TestList[3];
  double SliceSpacing = 0;
  double ElevationSigma = 0; ///< hand-tuned: half the slice spacing
};

/// The volume protocol's runs that the defaults table reads (issue 19), per test sweep (in-between,
/// oblique, orthogonal): the compounded volume resliced, the trainer's defaults with only a time budget,
/// and the same budget with the hand-tuned sigma (VolumeProtocol::ElevationSigma).
struct VolumeBudgetResults
{
  double Budget = 0; ///< s; 0 until the runs are done
  Row Compounded[3], Defaults[3], Tuned[3];
  /// Where the defaults run's in-between error comes from (MeasureVolumeErrorSources), and the blend of
  /// the recorded training slices on each side of the in-between slices (the recording's interpolation).
  ErrorSources DefaultsSources;
  Row RecordedBlend;
};

bool MakeVolumeProtocol(const std::string& root, bool quick, VolumeProtocol& vp, std::string* error)
{
  vp.File = root + "/Testing/Data/spine-phantom/SpinePhantomFreehandReconstructed.mha";
  vtkNew<vtkMetaImageReader> volumeReader;
  volumeReader->SetFileName(vp.File.c_str());
  volumeReader->Update();
  vp.Volume = volumeReader->GetOutput();
  int vdims[3];
  vp.Volume->GetDimensions(vdims);
  if (vdims[0] < 2 || vdims[1] < 2 || vdims[2] < 2)
  {
    return Failed(vp.File + ": cannot read the volume", error);
  }
  const int trainFrames = quick ? 40 : 80;
  const int testFrames = quick ? 10 : 40;
  auto makeSweep = [&](int protocol, int frames, double offset) {
    auto sweep = vtkSmartPointer<vtkUltrasoundVolumeSweep>::New();
    sweep->SetInputData(vp.Volume);
    sweep->SetProtocol(protocol);
    sweep->SetNumberOfFrames(frames);
    sweep->SetOffset(offset);
    sweep->SetMaximumTiltAngle(30);
    sweep->SetSeed(1);
    sweep->Update();
    return sweep;
  };
  vp.Train = makeSweep(vtkUltrasoundVolumeSweep::PARALLEL, trainFrames, 0);
  vp.Tests[0] = makeSweep(vtkUltrasoundVolumeSweep::PARALLEL, trainFrames, 0.5);
  vp.Tests[1] = makeSweep(vtkUltrasoundVolumeSweep::OBLIQUE, testFrames, 0);
  vp.Tests[2] = makeSweep(vtkUltrasoundVolumeSweep::ORTHOGONAL, testFrames, 0);
  if (!TrainingDataFromSequence(vp.Train->GetOutput(), vp.Train->GetMaskOutput(), vp.TrainData, error))
  {
    return Failed("volume protocol: " + *error, error);
  }
  for (int k = 0; k < vp.TrainData.Count(); ++k)
  {
    vp.TrainData.TrainFrames.push_back(k);
  }
  for (int t = 0; t < 3; ++t)
  {
    if (!TrainingDataFromSequence(vp.Tests[t]->GetOutput(), vp.Tests[t]->GetMaskOutput(), vp.TestData[t], error))
    {
      return Failed("volume protocol: " + *error, error);
    }
    for (int k = 0; k < vp.TestData[t].Count(); ++k)
    {
      vp.TestList[t].push_back(k);
    }
  }
  vp.SliceSpacing = vp.Train->GetSliceSpacing();
  vp.ElevationSigma = 0.5 * vp.SliceSpacing;
  std::ostringstream d;
  d << "`" << vp.File.substr(root.size() + 1) << "` (" << vdims[0] << " x " << vdims[1] << " x " << vdims[2]
    << " voxels of 0.5 mm). Training sweep: " << trainFrames << " parallel slices along z, "
    << Format("%.3f", vp.SliceSpacing) << " mm apart, frames of " << vp.TrainData.Width << " x " << vp.TrainData.Height
    << " pixels; per-frame masks of where the volume has data (PLUS leaves unreconstructed voxels at 0). "
    << "Test sweeps: " << trainFrames << " in-between parallel slices (offset half a slice), " << testFrames
    << " oblique slices (random tilt up to 30 degrees, seed 1) and " << testFrames
    << " orthogonal slices (along x). BIGUS elevation sigma = half the slice spacing.";
  vp.Description = d.str();
  return true;
}

/// The baseline of the volume protocol: the training slices compounded (0.5 mm, the volume's own grid
/// spacing) and resliced trilinearly at each test sweep's poses, into @p rows.
void CompoundVolume(const VolumeProtocol& vp, Row rows[3])
{
  vtkNew<vtkUltrasoundVolumeCompounder> compound;
  compound->SetInputConnection(vp.Train->GetOutputPort());
  compound->SetFanMaskConnection(vp.Train->GetMaskOutputPort());
  compound->SetOutputSpacing(0.5, 0.5, 0.5);
  double t0 = Now();
  compound->Update();
  const double compoundSeconds = Now() - t0;
  for (int t = 0; t < 3; ++t)
  {
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    reslice->SetInputConnection(compound->GetOutputPort());
    reslice->SetPoseConnection(vp.Tests[t]->GetOutputPort());
    reslice->MaskEmptyVoxelsOff();
    t0 = Now();
    reslice->Update();
    Row& r = rows[t];
    r.Method = "compounded volume + trilinear reslice";
    r.Seconds = compoundSeconds;
    r.MsPerFrame = 1e3 * (Now() - t0) / vp.TestList[t].size();
    r.Quality = Score(static_cast<float*>(reslice->GetOutput()->GetScalarPointer()), 1.0, vp.TestData[t], vp.TestList[t]);
  }
}

/**
 * The volume protocol's account of the in-between error (as MeasureErrorSources for a hold-out sweep): the
 * field's fit of the training slices, its renders at the in-between slices, and the blend of its own renders
 * at the training slices on each side. In-between slice k lies midway between training slices k and k + 1
 * (vtkUltrasoundVolumeSweep, Offset 0.5), so the blends use the in-between slices 0 to N - 2 and weights 1/2;
 * @p recordedBlend receives the same blend of the recorded training slices.
 */
bool MeasureVolumeErrorSources(const VolumeProtocol& vp, Trainer& trainer, const Row& row, ErrorSources& e,
  Row& recordedBlend, std::string* error)
{
  const TrainingData& train = vp.TrainData;
  const std::size_t pixels = std::size_t(train.Width) * train.Height;
  std::vector<float> renders(pixels * train.Count());
  for (int f : train.TrainFrames)
  {
    if (!trainer.RenderFrame(train, f, renders.data() + pixels * f, error))
    {
      return false;
    }
  }
  const std::vector<int> between(vp.TestList[0].begin(), vp.TestList[0].end() - 1);
  std::vector<float> blend(pixels);
  auto blendOf = [&](const float* frames) {
    return [&, frames](std::size_t, int k) {
      for (std::size_t p = 0; p < pixels; ++p)
      {
        blend[p] = 0.5f * (frames[pixels * k + p] + frames[pixels * (k + 1) + p]);
      }
      return static_cast<const float*>(blend.data());
    };
  };
  e.Seconds = row.Seconds;
  e.Training = MeanFrameMetrics(train, train.TrainFrames, [&](std::size_t, int f) { return &renders[pixels * f]; });
  if (!trainer.EvaluateOn(vp.TestData[0], between, e.HeldOut, error))
  {
    return false;
  }
  e.BlendedRenders = MeanFrameMetrics(vp.TestData[0], between, blendOf(renders.data()));
  recordedBlend.Method = "blend of the training slices on each side (recorded)";
  recordedBlend.Quality = MeanFrameMetrics(vp.TestData[0], between, blendOf(train.Frames.data()));
  return true;
}

/// @p row (a run's time, Gaussians, note) scored with @p trainer's field on each of the volume protocol's
/// three test sweeps, into @p rows.
bool ScoreVolume(Trainer& trainer, const VolumeProtocol& vp, const Row& row, Row rows[3], std::string* error)
{
  for (int t = 0; t < 3; ++t)
  {
    rows[t] = row;
    double secondsPerFrame = 0;
    if (!trainer.EvaluateOn(vp.TestData[t], vp.TestList[t], rows[t].Quality, error, &secondsPerFrame))
    {
      return false;
    }
    rows[t].MsPerFrame = 1e3 * secondsPerFrame;
    Print("volume", rows[t]);
  }
  return true;
}

/// The volume protocol's compounded baseline and its defaults and hand-tuned runs at a time budget (600 s,
/// issue 19's 10 minutes; 4 s quick), each scored on the three test sweeps, into @p out.
bool VolumeBudgetRuns(const VolumeProtocol& vp, bool quick, VolumeBudgetResults& out, std::string* error)
{
  CompoundVolume(vp, out.Compounded);
  const double budget = quick ? 4 : 600;
  TrainerSettings defaults;
  defaults.Iterations = 0;
  defaults.TimeBudget = budget;
  TrainerSettings tuned = defaults;
  tuned.ElevationSigma = vp.ElevationSigma;
  auto run = [&](const TrainerSettings& settings, const std::string& method, Row rows[3], ErrorSources* sources) {
    Row row;
    return TrainToBudget(vp.TrainData, settings, method, row,
      [&](Trainer& trainer, Row& r) {
        return ScoreVolume(trainer, vp, r, rows, error) &&
          (!sources || MeasureVolumeErrorSources(vp, trainer, r, *sources, out.RecordedBlend, error));
      },
      error);
  };
  if (!run(defaults, "BIGUS defaults, time budget only", out.Defaults, &out.DefaultsSources) ||
    !run(tuned, "BIGUS, same budget, hand-tuned sigma", out.Tuned, nullptr))
  {
    return Failed("volume protocol at " + Format("%.0f", budget) + " s: " + *error, error);
  }
  out.Budget = budget;
  return true;
}

/// The volume protocol section: BIGUS (hand-tuned sigma, a fixed schedule) at time marks, then the
/// compounded baseline and the budget runs of VolumeBudgetRuns (kept in @p budgetRuns for the defaults
/// table).
bool VolumeProtocolSection(const std::string& root, bool quick, Report& report, VolumeBudgetResults& budgetRuns,
  std::string* error)
{
  std::ostringstream& md = report.Markdown;
  const std::vector<double> marks = quick ? std::vector<double>{ 5 } : std::vector<double>{ 30, 60, 180 };
  VolumeProtocol vp;
  if (!MakeVolumeProtocol(root, quick, vp, error))
  {
    return false;
  }
  const char* testNames[] = { "in-between parallel slices", "oblique slices (tilt up to 30 degrees)",
    "orthogonal slices" };
  std::printf("volume protocol: %s\n", vp.Description.c_str());
  TrainerSettings s;
  s.ElevationSigma = vp.ElevationSigma;
  s.Iterations = quick ? 300 : 15000;
  std::vector<Row> bigusRows[3];
  const bool ok = TrainWithMarks(vp.TrainData, s, marks, {}, "BIGUS",
    [&](double, const Row& mark, Trainer& trainer) {
      Row rows[3];
      if (!ScoreVolume(trainer, vp, mark, rows, error))
      {
        return false;
      }
      for (int t = 0; t < 3; ++t)
      {
        bigusRows[t].push_back(rows[t]);
      }
      return true;
    },
    error);
  if (!ok)
  {
    return Failed("volume protocol: " + *error, error);
  }
  if (!VolumeBudgetRuns(vp, quick, budgetRuns, error))
  {
    return false;
  }
  std::vector<Row> baselineRows[3];
  for (int t = 0; t < 3; ++t)
  {
    baselineRows[t].push_back(budgetRuns.Compounded[t]);
    Print("volume", budgetRuns.Compounded[t]);
  }
  md << "\n## Volume protocol (spine-phantom reconstruction)\n\n" << vp.Description << " The last two rows "
     << "train with only a time budget of " << Format("%.0f", budgetRuns.Budget) << " s as the schedule (the "
     << "trainer's defaults, then the hand-tuned sigma) and include the final prune and gap filling.\n";
  for (int t = 0; t < 3; ++t)
  {
    md << "\n### " << testNames[t] << "\n\n" << TableHeader();
    nlohmann::json j;
    for (const Row& r : baselineRows[t])
    {
      md << TableRow(r);
      j["baselines"].push_back(ToJson(r));
    }
    for (const Row& r : bigusRows[t])
    {
      md << TableRow(r);
      j["bigus"].push_back(ToJson(r));
    }
    for (const Row* r : { &budgetRuns.Defaults[t], &budgetRuns.Tuned[t] })
    {
      md << TableRow(*r);
      j["budget_runs"].push_back(ToJson(*r));
    }
    if (t == 0)
    {
      // ErrorSourcesSection's "held-out pose" is here the in-between slice, its bracketing training frames
      // the training slices on each side.
      j["recorded_blend"] = ToJson(budgetRuns.RecordedBlend);
      md << ErrorSourcesSection(budgetRuns.RecordedBlend, { budgetRuns.DefaultsSources }, j)
         << "(The defaults run at the budget, in-between slices 0 to " << vp.TestList[0].size() - 2
         << ", each midway between two training slices: the held-out poses of the table above; the recorded "
         << "blend is that of the training slices on each side, which the compounded volume approximates.)\n";
    }
    report.Json["volume_protocol"][testNames[t]] = j;
  }
  PlotSpec spec = TimePlot("volume protocol: PSNR of the in-between slices against time", baselineRows[0], bigusRows[0]);
  spec.Series.push_back({ "BIGUS, oblique slices", {} });
  spec.Series.push_back({ "BIGUS, orthogonal slices", {} });
  for (int t = 1; t < 3; ++t)
  {
    for (const Row& r : bigusRows[t])
    {
      spec.Series[spec.Series.size() - 3 + t].Points.emplace_back(r.Seconds, r.Quality.PSNR);
    }
  }
  if (!report.Plot(spec, "psnr_time_volume.png"))
  {
    return Failed(report.PlotFolder + ": cannot write a plot", error);
  }
  return true;
}

/// Quality against the number of Gaussians on the liver: capped runs against the adaptive stop
/// (@p full, the default run at the capacity time).
bool CapacitySection(const Sweep& liver, const Row& full, bool quick, Report& report, std::string* error)
{
  std::ostringstream& md = report.Markdown;
  const double capacitySeconds = CapacitySeconds(quick);
  const std::vector<long long> caps = quick ? std::vector<long long>{ 2000, 4000 }
                                            : std::vector<long long>{ 10000, 40000, 160000 };
  const TrainerSettings defaults;
  std::vector<Row> rows;
  for (long long cap : caps)
  {
    TrainerSettings s;
    s.ElevationSigma = liver.ElevationSigma;
    s.Iterations = liver.Iterations;
    s.InitialGaussians = cap / 2;
    s.MaximumGaussians = cap;
    s.GrowthMargin = 0; // grow while it improves at all, up to the cap
    const bool ok = TrainWithMarks(liver.Data, s, { capacitySeconds }, liver.HeldOut,
      "cap " + std::to_string(cap) + " (start at " + std::to_string(cap / 2) + ")",
      [&](double, const Row& r, Trainer&) {
        rows.push_back(r);
        Print("capacity", r);
        return true;
      },
      error);
    if (!ok)
    {
      return Failed("capacity: " + *error, error);
    }
  }
  Row adaptive = full;
  adaptive.Method = "adaptive stop (default: automatic seeds, margin " + Format("%.1f", 100 * defaults.GrowthMargin) +
    " %, cap " + std::to_string(defaults.MaximumGaussians) + ")";
  rows.push_back(adaptive);
  md << "\n## Quality against the number of Gaussians (liver, " << Format("%.0f", capacitySeconds)
     << " s of training each)\n\n"
     << "A capped run starts at half its cap and densifies until the cap (growth margin 0); the adaptive run is "
     << "the default trainer, whose growth stops when a validation subset of the training frames stops "
     << "improving by the margin.\n\n"
     << TableHeader();
  PlotSpec spec;
  spec.Title = "liver: held-out PSNR against the number of Gaussians";
  spec.XLabel = "Gaussians at the end (log)";
  spec.YLabel = "PSNR (dB)";
  spec.LogX = true;
  spec.Series.push_back({ "capped", {} });
  for (const Row& r : rows)
  {
    md << TableRow(r);
    report.Json["capacity"].push_back(ToJson(r));
    if (&r != &rows.back())
    {
      spec.Series[0].Points.emplace_back(static_cast<double>(r.Gaussians), r.Quality.PSNR);
    }
  }
  spec.Series.push_back({ "adaptive", { { static_cast<double>(adaptive.Gaussians), adaptive.Quality.PSNR } } });
  if (!report.Plot(spec, "psnr_gaussians_liver.png"))
  {
    return Failed(report.PlotFolder + ": cannot write a plot", error);
  }
  return true;
}

/// Render time per slice against the error from the naive double-precision renderer, per cutoff, for
/// the liver field at the end of its run.
bool RenderSection(const Sweep& liver, const HoldOutResults& results, bool quick, Report& report, std::string* error)
{
  std::ostringstream& md = report.Markdown;
  const int crop = quick ? 32 : 128;
  const std::array<double, 16>& pose = liver.Data.Poses[liver.HeldOut[liver.HeldOut.size() / 2]];
  const int W = liver.Data.Width, H = liver.Data.Height;
  const double referenceStart = Now();
  RenderOptions exact = results.LiverOptions;
  const CropReference ref = RenderReference(results.LiverField, exact, pose, W, H, crop);
  const double referenceSeconds = Now() - referenceStart;
  auto cpu = CreateCpuRenderer();
  md << "\n## Render speed against render error (liver field, " << results.LiverField.Count() << " Gaussians)\n\n"
     << "Time per " << W << " x " << H << " slice at the held-out poses (CPU renderer, float) and the largest "
     << "and RMS difference in intensity from the naive double-precision renderer (no cutoff) on a " << crop << " x "
     << crop << " crop at the centre of a held-out frame (the naive renderer took "
     << Format("%.1f", referenceSeconds) << " s for that crop).\n\n"
     << "| cutoff k (standard deviations) | ms / slice | max abs error | RMS error | PSNR against naive (dB) |\n"
     << "|---|---|---|---|---|\n";
  PlotSpec spec;
  spec.Title = "render time per slice against error from the naive renderer (liver)";
  spec.XLabel = "ms per slice (log)";
  spec.YLabel = "-log10(max abs error)";
  spec.LogX = true;
  spec.Series.push_back({ "cutoff 3, 4, 5, 6", {} });
  std::vector<float> S(std::size_t(W) * H), I(S.size()), cropS(std::size_t(crop) * crop), cropI(cropS.size());
  for (double k : { 3.0, 4.0, 5.0, 6.0 })
  {
    RenderOptions o = results.LiverOptions;
    o.Cutoff = k;
    const int repeats = quick ? 2 : 10;
    const double start = Now();
    for (int n = 0; n < repeats; ++n)
    {
      SliceGeometry g;
      const auto& p = liver.Data.Poses[liver.HeldOut[n % liver.HeldOut.size()]];
      std::copy(p.begin(), p.end(), g.ImageToReference);
      g.Width = W;
      g.Height = H;
      cpu->Forward(results.LiverField.View(), &g, 1, o, S.data(), I.data(), nullptr, nullptr);
    }
    const double ms = 1e3 * (Now() - start) / repeats;
    cpu->Forward(results.LiverField.View(), &ref.Slice, 1, o, cropS.data(), cropI.data(), nullptr, nullptr);
    double maxError = 0, sum = 0;
    for (std::size_t p = 0; p < cropI.size(); ++p)
    {
      const double e = std::abs(cropI[p] - ref.I[p]);
      maxError = std::max(maxError, e);
      sum += e * e;
    }
    const double rms = std::sqrt(sum / cropI.size());
    md << "| " << Format("%.0f", k) << " | " << Format("%.2f", ms) << " | " << Format("%.2e", maxError) << " | "
       << Format("%.2e", rms) << " | " << Format("%.1f", -20 * std::log10(std::max(rms, 1e-12))) << " |\n";
    report.Json["render"].push_back(
      { { "cutoff", k }, { "ms_per_slice", ms }, { "max_error", maxError }, { "rms_error", rms } });
    std::printf("  render       cutoff %.0f: %.2f ms per slice, max |dI| %.2e, RMS %.2e\n", k, ms, maxError, rms);
    spec.Series[0].Points.emplace_back(ms, -std::log10(std::max(maxError, 1e-12)));
  }
  if (!report.Plot(spec, "render_speed_error.png"))
  {
    return Failed(report.PlotFolder + ": cannot write a plot", error);
  }
  return true;
}

/**
 * Defaults against hand-tuned (issue 19's aims): per hold-out sweep, the trainer's defaults with only a
 * time budget (what `bigus train SWEEP --time-budget T` does) against the same budget with the
 * elevation sigma chosen by hand for that sweep, and against the hand-tuned fixed-schedule run of the
 * sweep's section at the same time (@p results, when it ran); then the volume protocol's in-between and
 * oblique test sweeps from @p volume (its runs are made here when the volume section did not run).
 */
bool DefaultsSection(const std::vector<Sweep>& sweeps, const HoldOutResults& results, const std::string& root,
  bool quick, VolumeBudgetResults& volume, Report& report, std::string* error)
{
  std::ostringstream& md = report.Markdown;
  md << "\n## Defaults against hand-tuned\n\n"
     << "Defaults: `TrainerSettings` with only a time budget, which is then the whole schedule (elevation sigma "
     << "chosen from the sweep, seeds, growth and early stopping as the trainer decides). Hand-tuned: the same "
     << "budget with the elevation sigma chosen by hand for the sweep, and the sweep's own fixed-schedule run "
     << "above, read at the same time (mid-schedule, not pruned). Held-out PSNR; difference = defaults minus the "
     << "better hand-tuned run.\n\n"
     << "| sweep | budget (s) | defaults PSNR (dB) | defaults | hand-tuned PSNR (dB) | hand-tuned | fixed schedule "
     << "PSNR (dB) | difference (dB) |\n|---|---|---|---|---|---|---|---|\n";
  auto addRow = [&](const std::string& name, double budget, const Row& d, const Row& t, double fixed) {
    const double best = std::isfinite(fixed) ? std::max(t.Quality.PSNR, fixed) : t.Quality.PSNR;
    md << "| " << name << " | " << Format("%.0f", budget) << " | " << Format("%.2f", d.Quality.PSNR) << " | " << d.Note
       << ", " << d.Gaussians << " Gaussians | " << Format("%.2f", t.Quality.PSNR) << " | " << t.Note << ", "
       << t.Gaussians << " Gaussians | " << Format("%.2f", fixed) << " | " << Format("%+.2f", d.Quality.PSNR - best)
       << " |\n";
    nlohmann::json j;
    j["budget_seconds"] = budget;
    j["defaults"] = ToJson(d);
    j["hand_tuned"] = ToJson(t);
    j["fixed_schedule_psnr"] = std::isfinite(fixed) ? nlohmann::json(fixed) : nlohmann::json(nullptr);
    j["difference_db"] = d.Quality.PSNR - best;
    report.Json["defaults_against_hand_tuned"][name] = j;
  };
  for (std::size_t si = 0; si < sweeps.size(); ++si)
  {
    const Sweep& sweep = sweeps[si];
    TrainerSettings defaults;
    defaults.Iterations = 0;
    defaults.TimeBudget = sweep.DefaultsBudget;
    TrainerSettings tuned = defaults;
    tuned.ElevationSigma = sweep.ElevationSigma;
    Row d, t;
    if (!TrainToBudget(sweep, defaults, "defaults", d, error) || !TrainToBudget(sweep, tuned, "hand-tuned sigma", t, error))
    {
      return Failed(sweep.Name + " (defaults against hand-tuned): " + *error, error);
    }
    Print(sweep.Name, d);
    Print(sweep.Name, t);
    double fixed = NaN;
    if (si < results.Bigus.size())
    {
      for (const Row& r : results.Bigus[si])
      {
        if (r.Seconds <= sweep.DefaultsBudget * 1.01)
        {
          fixed = r.Quality.PSNR; // the last mark within the budget
        }
      }
    }
    addRow(sweep.Name, sweep.DefaultsBudget, d, t, fixed);
  }
  if (!(volume.Budget > 0))
  {
    VolumeProtocol vp;
    if (!MakeVolumeProtocol(root, quick, vp, error) || !VolumeBudgetRuns(vp, quick, volume, error))
    {
      return false;
    }
  }
  // The volume protocol's fixed schedule is read at marks below its budget: no column.
  addRow("volume protocol, in-between slices", volume.Budget, volume.Defaults[0], volume.Tuned[0], NaN);
  addRow("volume protocol, oblique slices", volume.Budget, volume.Defaults[1], volume.Tuned[1], NaN);
  md << "\nThe volume protocol's baseline, the compounded volume resliced: " << Format("%.2f", volume.Compounded[0].Quality.PSNR)
     << " dB on the in-between slices, " << Format("%.2f", volume.Compounded[1].Quality.PSNR) << " dB on the oblique.\n";
  report.Json["defaults_against_hand_tuned_volume_compounded_psnr"] = { volume.Compounded[0].Quality.PSNR,
    volume.Compounded[1].Quality.PSNR };
  return true;
}

/**
 * Block hold-outs on @p liver (issue 19's gaps): @p blocks consecutive frames in the middle of the sweep
 * held out and every other valid frame trained on, so the held-out poses lie in a gap wider than the
 * beam. The baselines and BIGUS with its defaults at the sweep's DefaultsBudget. The sweep's own frame
 * lists are restored before returning.
 */
bool BlockHoldOutSection(Sweep& liver, bool quick, Report& report, std::string* error)
{
  std::ostringstream& md = report.Markdown;
  const std::vector<int> train = liver.Data.TrainFrames, heldOut = liver.HeldOut;
  std::vector<int> valid = train;
  valid.insert(valid.end(), heldOut.begin(), heldOut.end());
  std::sort(valid.begin(), valid.end());
  md << "\n## Block hold-outs (" << liver.Name << ")\n\n"
     << "Consecutive frames in the middle of the sweep held out, every other frame trained on: the held-out "
     << "poses lie in a gap much wider than the elevation beam, where no training frame holds their speckle. "
     << "BIGUS with its defaults and a time budget of " << Format("%.0f", liver.DefaultsBudget) << " s.\n";
  bool ok = true;
  for (int size : quick ? std::vector<int>{ 8 } : std::vector<int>{ 8, 20 })
  {
    const std::size_t first = valid.size() / 2 - size / 2;
    liver.HeldOut.assign(valid.begin() + first, valid.begin() + first + size);
    liver.Data.TrainFrames.assign(valid.begin(), valid.begin() + first);
    liver.Data.TrainFrames.insert(liver.Data.TrainFrames.end(), valid.begin() + first + size, valid.end());
    // The gap: from the last training frame before the block to the first after it (image centres, mm).
    auto centre = [&](int k) {
      const std::array<double, 16>& m = liver.Data.Poses[k];
      const double u = 0.5 * liver.Data.Width, v = 0.5 * liver.Data.Height;
      return std::array<double, 3>{ m[0] * u + m[1] * v + m[3], m[4] * u + m[5] * v + m[7], m[8] * u + m[9] * v + m[11] };
    };
    const auto a = centre(valid[first - 1]), c = centre(valid[first + size]);
    const double gap = std::sqrt((a[0] - c[0]) * (a[0] - c[0]) + (a[1] - c[1]) * (a[1] - c[1]) + (a[2] - c[2]) * (a[2] - c[2]));
    std::vector<Row> rows = Baselines(liver);
    TrainerSettings defaults;
    defaults.Iterations = 0;
    defaults.TimeBudget = liver.DefaultsBudget;
    rows.emplace_back();
    if (!TrainToBudget(liver, defaults, "BIGUS (defaults)", rows.back(), error))
    {
      ok = Failed("block hold-out: " + *error, error);
      break;
    }
    const std::string title = std::to_string(size) + " consecutive frames held out (frames " +
      std::to_string(liver.HeldOut.front()) + " to " + std::to_string(liver.HeldOut.back()) + ", " +
      Format("%.1f", gap) + " mm between the bracketing training frames)";
    md << "\n### " << title << "\n\n" << TableHeader();
    nlohmann::json j;
    j["frames"] = liver.HeldOut;
    j["gap_mm"] = gap;
    for (const Row& r : rows)
    {
      Print("block " + std::to_string(size), r);
      md << TableRow(r);
      j["rows"].push_back(ToJson(r));
    }
    report.Json["block_hold_outs"][std::to_string(size)] = j;
  }
  liver.Data.TrainFrames = train;
  liver.HeldOut = heldOut;
  return ok;
}

/// One sweep of the ablation section: where the field is trained and where it is scored.
struct AblationExperiment
{
  std::string Name;
  const TrainingData* Train = nullptr; ///< TrainFrames: the frames trained on
  const TrainingData* Test = nullptr;  ///< the held-out frames' data (Train itself for a hold-out sweep)
  std::vector<int> TestFrames;         ///< scored held out
  std::vector<int> FitFrames;          ///< training frames scored for the fit (every 4th)
  double Seconds = 60;                 ///< training time of the equal-time table
};

/// Every 4th training frame of @p e, scored for the fit.
void SetFitFrames(AblationExperiment& e)
{
  for (std::size_t k = 0; k < e.Train->TrainFrames.size(); k += 4)
  {
    e.FitFrames.push_back(e.Train->TrainFrames[k]);
  }
}

/// A bundled sweep with its hold-out protocol (frames i mod 4 == 2 scored).
AblationExperiment HoldOutExperiment(const Sweep& sweep, double seconds)
{
  AblationExperiment e;
  e.Name = sweep.Name;
  e.Train = e.Test = &sweep.Data;
  e.TestFrames = sweep.HeldOut;
  e.Seconds = seconds;
  SetFitFrames(e);
  return e;
}

/// The volume protocol: trained on the parallel slices, scored on the in-between slices.
AblationExperiment VolumeExperiment(const VolumeProtocol& vp, double seconds)
{
  AblationExperiment e;
  e.Name = "volume protocol (in-between slices)";
  e.Train = &vp.TrainData;
  e.Test = &vp.TestData[0];
  e.TestFrames = vp.TestList[0];
  e.Seconds = seconds;
  SetFitFrames(e);
  return e;
}

/// One training run of the ablation section: the settings' schedule to its end, then the final prune.
struct AblationRun
{
  ImageMetrics HeldOut;
  double Fit = NaN;     ///< PSNR of the training frames (dB)
  double Gaussians = 0;
  double Seeds = 0;
  double Steps = 0;
  double Seconds = 0;   ///< wall clock: initialisation, training and final prune
};

/// @p train false: the seeded field (Initialize: seeds and their reflectivities) goes straight to Finish.
bool RunAblation(const AblationExperiment& e, const TrainerSettings& settings, AblationRun& run, std::string* error,
  bool train = true)
{
  const double start = Now();
  Trainer trainer(*e.Train, settings);
  if (!trainer.Initialize(error) || (train && !trainer.Train(nullptr, nullptr, error)) || !trainer.Finish(error))
  {
    return false;
  }
  run.Seconds = Now() - start;
  ImageMetrics fit;
  if (!trainer.EvaluateOn(*e.Test, e.TestFrames, run.HeldOut, error) || !trainer.Evaluate(e.FitFrames, fit, error))
  {
    return false;
  }
  run.Fit = fit.PSNR;
  run.Gaussians = static_cast<double>(trainer.GetField().Count());
  run.Seeds = static_cast<double>(trainer.GetReport().InitialGaussians);
  run.Steps = trainer.GetReport().Iterations;
  return true;
}

/// Mean and spread (max - min) over seeds of one quantity.
struct Spread
{
  double Mean = NaN, Range = NaN;
  static Spread Of(const std::vector<double>& values)
  {
    Spread s;
    if (values.empty())
    {
      return s;
    }
    s.Mean = std::accumulate(values.begin(), values.end(), 0.0) / values.size();
    const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
    s.Range = *hi - *lo;
    return s;
  }
  std::string Text(const char* format) const
  {
    return Format(format, this->Mean) + " (" + Format(format, this->Range) + ")";
  }
};

/// Mean and spread of every column of a variant's runs over seeds.
struct AblationCell
{
  std::vector<AblationRun> Runs;
  Spread Get(const std::function<double(const AblationRun&)>& field) const
  {
    std::vector<double> v;
    for (const AblationRun& r : this->Runs)
    {
      v.push_back(field(r));
    }
    return Spread::Of(v);
  }
  Spread PSNR() const { return this->Get([](const AblationRun& r) { return r.HeldOut.PSNR; }); }
  Spread Fit() const { return this->Get([](const AblationRun& r) { return r.Fit; }); }
  Spread Steps() const { return this->Get([](const AblationRun& r) { return r.Steps; }); }
  Spread Gaussians() const { return this->Get([](const AblationRun& r) { return r.Gaussians; }); }
};

/**
 * The sentence under an ablation table for one component: whether the held-out PSNR moves the way the
 * paper says (@p paperSign: the sign of variant - full), against the noise (the larger of the two
 * spreads over seeds), and for a disagreement what was measured to differ: steps done, Gaussians at the
 * end, and the fit (training frames) against the held-out frames.
 */
std::string AblationVerdict(const Ablation& a, const AblationCell& full, const AblationCell& variant, std::string& verdict)
{
  const Spread f = full.PSNR(), v = variant.PSNR();
  const double delta = v.Mean - f.Mean, noise = std::max(f.Range, v.Range);
  std::ostringstream text;
  text << "**" << a.Name << "**: ";
  if (full.Runs.size() < 2 || variant.Runs.size() < 2)
  {
    verdict = "one seed";
    text << "one seed, so no spread to judge " << Format("%+.2f", delta) << " dB by.";
    return text.str();
  }
  if (!(std::abs(delta) > noise))
  {
    verdict = "within noise";
    text << "within noise (" << Format("%+.2f", delta) << " dB, spread " << Format("%.2f", noise) << ").";
    return text.str();
  }
  const bool agrees = (delta > 0) == (a.PaperSign > 0);
  verdict = agrees ? "agrees" : "disagrees";
  text << (agrees ? "agrees with" : "disagrees with") << " the paper (" << Format("%+.2f", delta) << " dB, spread "
       << Format("%.2f", noise) << ")";
  if (agrees)
  {
    text << ".";
    return text.str();
  }
  std::vector<std::string> reasons;
  const double steps = variant.Steps().Mean / full.Steps().Mean;
  if (std::abs(steps - 1) > 0.05)
  {
    reasons.push_back(Format("it did %.2f", steps) + " times the full method's steps (" +
      Format("%.0f", variant.Steps().Mean) + " against " + Format("%.0f", full.Steps().Mean) + ")");
  }
  const double gaussians = variant.Gaussians().Mean / full.Gaussians().Mean;
  if (std::abs(gaussians - 1) > 0.1)
  {
    reasons.push_back(Format("it ended with %.2f", gaussians) + " times the Gaussians (" +
      Format("%.0f", variant.Gaussians().Mean) + " against " + Format("%.0f", full.Gaussians().Mean) + ")");
  }
  const Spread vf = variant.Fit(), ff = full.Fit();
  const double fitDelta = vf.Mean - ff.Mean;
  const double gapFull = ff.Mean - f.Mean, gapVariant = vf.Mean - v.Mean;
  if (std::abs(fitDelta) > std::max(vf.Range, ff.Range))
  {
    reasons.push_back("its fit of the training frames is " + Format("%.2f", std::abs(fitDelta)) + " dB " +
      (fitDelta > 0 ? "higher" : "lower"));
  }
  else
  {
    reasons.push_back("its fit of the training frames is the same within noise (" + Format("%+.2f", fitDelta) + " dB)");
  }
  reasons.push_back("fit minus held-out: " + Format("%.2f", gapVariant) + " dB against " + Format("%.2f", gapFull) +
    " dB for the full method" + (gapFull > gapVariant + 0.5 ? " (the full method overfits more)" : ""));
  text << ": ";
  for (std::size_t i = 0; i < reasons.size(); ++i)
  {
    text << (i ? "; " : "") << reasons[i];
  }
  text << ".";
  return text.str();
}

/**
 * Issue 21: every switch of the method against the full method (the trainer's defaults) at equal
 * iterations and at equal wall time, on the liver, the spine phantom, the N-wire phantom and the volume
 * protocol, 3 seeds per cell (1 and one switch with --quick). Equal time: each run's time budget is the
 * schedule (TrainerSettings::TimeBudget). Equal iterations: the mean number of steps the full method did
 * in that time, as the schedule. Every run ends with the final prune; its time counts.
 */
bool AblationSection(const std::vector<Sweep>& sweeps, const std::string& root, bool quick, Report& report,
  std::string* error)
{
  VolumeProtocol vp;
  if (!MakeVolumeProtocol(root, quick, vp, error))
  {
    return false;
  }
  std::vector<AblationExperiment> experiments;
  const double seconds[] = { 40, 20, 15 }; // liver, spine phantom, N-wire: about 100 minutes on 2 cores in all
  for (std::size_t si = 0; si < 3; ++si)
  {
    experiments.push_back(HoldOutExperiment(sweeps[si], quick ? 3 : seconds[si]));
  }
  experiments.push_back(VolumeExperiment(vp, quick ? 3 : 15));
  const std::vector<unsigned> seeds = quick ? std::vector<unsigned>{ 1 } : std::vector<unsigned>{ 1, 2, 3 };
  std::vector<Ablation> ablations = Ablations();
  if (quick)
  {
    ablations.resize(1);
  }

  std::ostringstream& md = report.Markdown;
  md << "\n## Ablations at equal iterations and at equal time\n\n"
     << "The paper's Tables 3 and 4 compare its components at equal iterations. Each switch below is trained "
     << "from the trainer's defaults (the full method) with that one change, with " << seeds.size()
     << " seed" << (seeds.size() > 1 ? "s" : "") << " per cell: **equal time**, the time budget as the "
     << "schedule, and **equal iterations**, the mean number of steps the full method did in that time as "
     << "the schedule. Each cell gives the mean over seeds and, in brackets, the spread (largest minus "
     << "smallest). A difference is called real only when it exceeds the larger of the two spreads. Held-out: "
     << "the sweep's held-out frames (i mod 4 == 2; the volume protocol's in-between slices); fit: every 4th "
     << "training frame. Time includes initialisation and the final prune. The capacity cap fixes the number "
     << "of Gaussians at the full method's seed count (densification only replaces what pruning removes).\n";
  nlohmann::json& json = report.Json["ablations"];
  for (const AblationExperiment& e : experiments)
  {
    const double started = Now();
    TrainerSettings timed;
    timed.Iterations = 0;
    timed.TimeBudget = e.Seconds;
    // The full method at equal time first: its steps set the equal-iteration schedule, its seeds the cap.
    auto runCell = [&](const TrainerSettings& base, const Ablation* a, std::int64_t seedCount, AblationCell& cell) {
      for (unsigned seed : seeds)
      {
        TrainerSettings s = base;
        s.Seed = seed;
        if (a)
        {
          a->Change(s, seedCount);
        }
        AblationRun run;
        if (!RunAblation(e, s, run, error))
        {
          return Failed("ablation " + e.Name + ", " + (a ? a->Name : std::string("full method")) + ": " + *error, error);
        }
        std::printf("  ablation %-16s %-44s seed %u  %6.1f s  %6.0f steps  held-out %6.2f dB  fit %6.2f dB  %8.0f Gaussians\n",
          e.Name.substr(0, 16).c_str(), a ? a->Name.c_str() : "full method", seed, run.Seconds, run.Steps,
          run.HeldOut.PSNR, run.Fit, run.Gaussians);
        std::fflush(stdout);
        cell.Runs.push_back(run);
      }
      return true;
    };
    AblationCell fullTimed, fullIterations;
    if (!runCell(timed, nullptr, 0, fullTimed))
    {
      return false;
    }
    TrainerSettings counted;
    counted.Iterations = std::max(1, static_cast<int>(std::lround(fullTimed.Steps().Mean)));
    if (!runCell(counted, nullptr, 0, fullIterations))
    {
      return false;
    }
    const std::int64_t seedCount = std::llround(fullTimed.Get([](const AblationRun& r) { return r.Seeds; }).Mean);
    md << "\n### " << e.Name << "\n";
    for (int table = 0; table < 2; ++table)
    {
      const bool equalTime = table == 0;
      const TrainerSettings& base = equalTime ? timed : counted;
      const AblationCell& full = equalTime ? fullTimed : fullIterations;
      std::vector<AblationCell> cells(ablations.size());
      for (std::size_t ai = 0; ai < ablations.size(); ++ai)
      {
        if (!runCell(base, &ablations[ai], seedCount, cells[ai]))
        {
          return false;
        }
      }
      md << "\n#### " << (equalTime ? "Equal time: " + Format("%.0f", e.Seconds) + " s"
                                    : "Equal iterations: " + std::to_string(counted.Iterations) + " steps")
         << "\n\n| variant | held-out PSNR (dB) | SSIM | NCC | speckle | fit PSNR (dB) | Gaussians | steps | "
            "time (s) | paper | ours |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
      std::ostringstream sentences;
      nlohmann::json jt;
      jt["schedule"] = equalTime ? Format("%.0f s", e.Seconds) : std::to_string(counted.Iterations) + " steps";
      for (std::size_t ai = 0; ai <= ablations.size(); ++ai)
      {
        const AblationCell& cell = ai == 0 ? full : cells[ai - 1];
        std::string verdict;
        if (ai > 0)
        {
          sentences << "- " << AblationVerdict(ablations[ai - 1], full, cell, verdict) << "\n";
        }
        md << "| " << (ai == 0 ? std::string("full method (defaults)") : ablations[ai - 1].Name) << " | "
           << cell.PSNR().Text("%.2f") << " | "
           << cell.Get([](const AblationRun& r) { return r.HeldOut.SSIM; }).Text("%.4f") << " | "
           << cell.Get([](const AblationRun& r) { return r.HeldOut.NCC; }).Text("%.4f") << " | "
           << cell.Get([](const AblationRun& r) { return r.HeldOut.Speckle; }).Text("%.4f") << " | "
           << cell.Fit().Text("%.2f") << " | " << cell.Gaussians().Text("%.0f") << " | " << cell.Steps().Text("%.0f")
           << " | " << cell.Get([](const AblationRun& r) { return r.Seconds; }).Text("%.1f") << " | "
           << (ai == 0 ? "" : ablations[ai - 1].PaperDirection) << " | " << verdict << " |\n";
        nlohmann::json jc;
        jc["variant"] = ai == 0 ? std::string("full method") : ablations[ai - 1].Name;
        jc["verdict"] = verdict;
        for (const AblationRun& r : cell.Runs)
        {
          jc["runs"].push_back({ { "psnr", r.HeldOut.PSNR }, { "ssim", r.HeldOut.SSIM }, { "ncc", r.HeldOut.NCC },
            { "speckle", r.HeldOut.Speckle }, { "fit_psnr", r.Fit }, { "gaussians", r.Gaussians },
            { "steps", r.Steps }, { "seconds", r.Seconds } });
        }
        jt["cells"].push_back(jc);
      }
      md << "\n" << sentences.str();
      json[e.Name][equalTime ? "equal_time" : "equal_iterations"] = jt;
    }
    const double took = Now() - started;
    md << "\nThis sweep's ablations took " << Format("%.1f", took / 60) << " minutes.\n";
    json[e.Name]["seconds"] = took;
  }
  return true;
}

/// One run of the Pareto section: a trainer to a time budget, or the regular grid (no training).
struct ParetoRun
{
  std::string Method;
  double Budget = NaN;         ///< s: the trainer's time budget (NaN for the grid)
  std::int64_t Requested = 0;  ///< the grid: the count asked for (the count an adaptive run ended with)
  AblationRun Run;
  bool CountFront = false;     ///< no other run has at most its Gaussians and a higher held-out PSNR
  bool TimeFront = false;      ///< no other run took at most its time and has a higher held-out PSNR
};

/// Marks the runs on the front of held-out PSNR against @p cost (lower cost, higher PSNR).
void MarkFront(std::vector<ParetoRun>& runs, double AblationRun::*cost, bool ParetoRun::*front)
{
  for (ParetoRun& a : runs)
  {
    a.*front = std::none_of(runs.begin(), runs.end(), [&](const ParetoRun& b) {
      return &a != &b && b.Run.*cost <= a.Run.*cost && b.Run.HeldOut.PSNR > a.Run.HeldOut.PSNR;
    });
  }
}

/**
 * Issue 31, item 4: held-out PSNR against the number of Gaussians and against time, on the liver (20 of
 * its frames with --quick), the spine phantom and the volume protocol (in-between slices). Three methods:
 * the trainer's defaults (Adam alone, Harris seeds), variable projection (the same, with the reflectivities
 * solved after seeding and after every densification; TrainerSettings::ReflectivitySolve), each to time
 * budgets of 30 and 120 s; and the regular grid with the same solve and no training (DenseInitialisation:
 * Gaussians on the training frames' pixel grid) at the count each adaptive run ended with. Every run ends
 * with the final prune and gap filling, and its time counts them and the initialisation (seeding, solves).
 * The adaptive field should lie above the grid at every count; where it does not, the report says by how
 * much and compares the two fits of the training frames.
 */
bool ParetoSection(const std::vector<Sweep>& sweeps, const std::string& root, bool quick, Report& report,
  std::string* error)
{
  VolumeProtocol vp;
  if (!MakeVolumeProtocol(root, quick, vp, error))
  {
    return false;
  }
  // A solve passes over every training frame twice per iteration: --quick takes the 20 liver frames.
  const std::vector<AblationExperiment> experiments = { HoldOutExperiment(sweeps[quick ? 3 : 0], 0),
    HoldOutExperiment(sweeps[1], 0), VolumeExperiment(vp, 0) };
  const std::vector<double> budgets = quick ? std::vector<double>{ 3 } : std::vector<double>{ 30, 120 };
  const std::pair<std::string, bool> adaptive[] = { { "Adam alone (defaults)", false },
    { "variable projection", true } };
  const std::string grid = "regular grid + solve";

  std::ostringstream& md = report.Markdown;
  md << "\n## Held-out PSNR against Gaussians and time: the adaptive field and the regular grid\n\n"
     << "Trainer defaults (Adam alone) and variable projection (`--reflectivity-solve`: the reflectivities solved "
     << "by least squares after seeding and after every densification, Adam between) to time budgets of ";
  for (std::size_t b = 0; b < budgets.size(); ++b)
  {
    md << (b ? " and " : "") << Format("%.0f", budgets[b]);
  }
  md << " s, and a regular grid (`--dense-start`: Gaussians on the training frames' pixel grid, reflectivities "
     << "by the same solve, no training) at the count each adaptive run ended with (one grid for counts within "
     << "10 %). Time includes seeding, the solves, the final prune and gap filling. Held-out as in the ablations; "
     << "fit: every 4th training frame. *count front* / *time front*: no other run of the sweep has at most "
     << "its Gaussians / its time and a higher held-out PSNR.\n";
  nlohmann::json& json = report.Json["pareto"];
  for (const AblationExperiment& e : experiments)
  {
    std::vector<ParetoRun> runs;
    auto measure = [&](ParetoRun& p, const TrainerSettings& s, bool train) {
      if (!RunAblation(e, s, p.Run, error, train))
      {
        return Failed("Pareto " + e.Name + ", " + p.Method + ": " + *error, error);
      }
      std::printf("  pareto   %-16s %-24s %6.1f s  %6.0f steps  held-out %6.2f dB  fit %6.2f dB  %8.0f Gaussians\n",
        e.Name.substr(0, 16).c_str(), p.Method.c_str(), p.Run.Seconds, p.Run.Steps, p.Run.HeldOut.PSNR, p.Run.Fit,
        p.Run.Gaussians);
      std::fflush(stdout);
      runs.push_back(p);
      return true;
    };
    for (const auto& [name, solve] : adaptive)
    {
      for (double budget : budgets)
      {
        TrainerSettings s;
        s.Iterations = 0;
        s.TimeBudget = budget;
        s.ReflectivitySolve = solve;
        ParetoRun p;
        p.Method = name;
        p.Budget = budget;
        if (!measure(p, s, true))
        {
          return false;
        }
      }
    }
    const std::size_t adaptiveRuns = runs.size();
    for (std::size_t a = 0; a < adaptiveRuns; ++a)
    {
      const auto count = static_cast<std::int64_t>(runs[a].Run.Gaussians);
      if (std::any_of(runs.begin() + adaptiveRuns, runs.end(),
            [&](const ParetoRun& g) { return std::abs(double(g.Requested - count)) <= 0.1 * count; }))
      {
        continue;
      }
      TrainerSettings s;
      s.DenseInitialisation = true;
      s.ReflectivitySolve = true;
      s.InitialGaussians = count;
      ParetoRun p;
      p.Method = grid;
      p.Requested = count;
      if (!measure(p, s, false))
      {
        return false;
      }
    }
    MarkFront(runs, &AblationRun::Gaussians, &ParetoRun::CountFront);
    MarkFront(runs, &AblationRun::Seconds, &ParetoRun::TimeFront);

    md << "\n### " << e.Name << "\n\n| method | budget (s) | time (s) | Gaussians | held-out PSNR (dB) | SSIM | "
       << "fit PSNR (dB) | steps | count front | time front |\n|---|---|---|---|---|---|---|---|---|---|\n";
    nlohmann::json je;
    PlotSpec byCount, byTime;
    byCount.Title = e.Name + ": held-out PSNR against Gaussians";
    byCount.XLabel = "Gaussians";
    byCount.LogX = true;
    byTime.Title = e.Name + ": held-out PSNR against time";
    byTime.XLabel = "time (s)";
    byCount.YLabel = byTime.YLabel = "held-out PSNR (dB)";
    for (const ParetoRun& p : runs)
    {
      const AblationRun& r = p.Run;
      md << "| " << p.Method << " | " << Format("%.0f", p.Budget) << " | " << Format("%.1f", r.Seconds) << " | "
         << Format("%.0f", r.Gaussians) << " | " << Format("%.2f", r.HeldOut.PSNR) << " | "
         << Format("%.4f", r.HeldOut.SSIM) << " | " << Format("%.2f", r.Fit) << " | " << Format("%.0f", r.Steps)
         << " | " << (p.CountFront ? "yes" : "") << " | " << (p.TimeFront ? "yes" : "") << " |\n";
      je["runs"].push_back({ { "method", p.Method }, { "budget", std::isfinite(p.Budget) ? nlohmann::json(p.Budget) : nlohmann::json(nullptr) },
        { "requested", p.Requested }, { "seconds", r.Seconds }, { "gaussians", r.Gaussians }, { "seeds", r.Seeds },
        { "steps", r.Steps }, { "psnr", r.HeldOut.PSNR }, { "ssim", r.HeldOut.SSIM }, { "fit_psnr", r.Fit },
        { "count_front", p.CountFront }, { "time_front", p.TimeFront } });
      for (PlotSpec* spec : { &byCount, &byTime })
      {
        auto series = std::find_if(spec->Series.begin(), spec->Series.end(),
          [&](const PlotSeries& s) { return s.Name == p.Method; });
        if (series == spec->Series.end())
        {
          series = spec->Series.insert(spec->Series.end(), PlotSeries{ p.Method, {} });
        }
        series->Points.emplace_back(spec == &byCount ? r.Gaussians : r.Seconds, r.HeldOut.PSNR);
      }
    }
    for (PlotSpec* spec : { &byCount, &byTime })
    {
      for (PlotSeries& s : spec->Series)
      {
        std::sort(s.Points.begin(), s.Points.end());
      }
    }
    // Each adaptive run against the grid made at (or within 10 % of) its count.
    md << "\n";
    for (std::size_t a = 0; a < adaptiveRuns; ++a)
    {
      const ParetoRun& p = runs[a];
      const auto g = std::min_element(runs.begin() + adaptiveRuns, runs.end(), [&](const ParetoRun& x, const ParetoRun& y) {
        return std::abs(x.Requested - p.Run.Gaussians) < std::abs(y.Requested - p.Run.Gaussians);
      });
      const double delta = p.Run.HeldOut.PSNR - g->Run.HeldOut.PSNR;
      const bool above = delta > 0;
      md << "- " << p.Method << ", " << Format("%.0f", p.Budget) << " s (" << Format("%.0f", p.Run.Gaussians)
         << " Gaussians): " << (above ? "above" : "below") << " the grid of " << Format("%.0f", g->Run.Gaussians)
         << " by " << Format("%.2f", std::abs(delta)) << " dB";
      if (!above)
      {
        md << "; fit of the training frames " << Format("%.2f", p.Run.Fit) << " dB against the grid's "
           << Format("%.2f", g->Run.Fit) << " (" << (p.Run.Fit < g->Run.Fit ? "the adaptive field fits less: "
              "its geometry is not yet where the budget's steps would take it" : "the adaptive field fits more "
              "and generalises less between frames") << ")";
      }
      md << ".\n";
      je["verdicts"].push_back({ { "method", p.Method }, { "budget", p.Budget }, { "grid_gaussians", g->Run.Gaussians },
        { "delta_psnr", delta }, { "above_grid", above } });
    }
    const std::string tag = std::to_string(&e - experiments.data());
    if (!report.Plot(byCount, "pareto_gaussians_" + tag + ".png") || !report.Plot(byTime, "pareto_time_" + tag + ".png"))
    {
      return Failed("cannot write the Pareto plots to " + report.PlotFolder, error);
    }
    json[e.Name] = je;
  }
  return true;
}

/// Adds the total run time (@p seconds) and writes the report to @p output: BENCHMARKS.md for every
/// section, BENCHMARKS_<section>.md for one alone (so that it does not replace the full report), and
/// results[_<section>].json next to the plots.
bool WriteReport(const std::string& output, const std::string& section, double seconds, Report& report,
  std::string* error)
{
  report.Markdown << "\nTotal run time of the command: " << Format("%.1f", seconds / 60) << " minutes.\n";
  report.Json["total_seconds"] = seconds;
  const std::string suffix = section == "all" ? "" : "_" + section;
  const std::string markdown = output + "/BENCHMARKS" + suffix + ".md";
  const std::string json = report.PlotFolder + "/results" + suffix + ".json";
  for (const auto& [path, text] :
    { std::pair<std::string, std::string>{ markdown, report.Markdown.str() }, { json, report.Json.dump(2) + "\n" } })
  {
    const std::string temporary = TemporaryName(path);
    std::ofstream out(temporary);
    out << text;
    out.close();
    if (!out || !Publish(temporary, path))
    {
      std::remove(temporary.c_str());
      return Failed(path + ": cannot write", error);
    }
  }
  std::printf("wrote %s and %s\n", markdown.c_str(), json.c_str());
  return true;
}
}

int RunBenchmark(const BenchmarkOptions& options)
{
  const double started = Now();
  const bool quick = options.Quick;
  const std::string root = options.SourceDirectory;
  Report report;
  report.PlotFolder = options.Output + "/benchmarks";
  report.PlotLink = "benchmarks";
  if (!MakeFolder(options.Output) || !MakeFolder(report.PlotFolder))
  {
    return Fail(options.Output + ": cannot create the output folder");
  }
  const std::string& section = options.Section;
  if (section != "all" && section != "defaults" && section != "volume" && section != "blocks" && section != "ablations" &&
    section != "pareto")
  {
    return Fail("--section " + section + ": expected all, defaults, volume, blocks, ablations or pareto");
  }
  Introduction(root, quick, report);
  std::vector<Sweep> sweeps = BundledSweeps(root, quick);
  std::string error;
  HoldOutResults results;
  const bool all = section == "all";
  // Each section's wall time, listed at the end of the report.
  std::vector<std::pair<std::string, double>> times;
  auto run = [&](const std::string& name, bool wanted, const std::function<bool()>& measure) {
    if (!wanted)
    {
      return true;
    }
    const double t0 = Now();
    const bool ok = measure();
    times.emplace_back(name, Now() - t0);
    report.Json["section_seconds"][name] = times.back().second;
    return ok;
  };
  bool ok = true;
  for (std::size_t si = 0; ok && si < sweeps.size(); ++si)
  {
    if (all)
    {
      ok = run(sweeps[si].Name, true, [&] { return HoldOutSection(sweeps[si], si, root, quick, report, results, &error); });
    }
    else if (section == "defaults" || (section == "blocks" && si == 0) || (section == "ablations" && si < 3) ||
      (section == "pareto" && si != 2))
    {
      ok = Load(sweeps[si], &error);
    }
  }
  VolumeBudgetResults volume;
  ok = ok && run("volume protocol", all || section == "volume",
               [&] { return VolumeProtocolSection(root, quick, report, volume, &error); });
  ok = ok && run("capacity", all, [&] { return CapacitySection(sweeps[0], results.LiverAtCapacityTime, quick, report, &error); });
  ok = ok && run("render cutoffs", all, [&] { return RenderSection(sweeps[0], results, quick, report, &error); });
  ok = ok && run("ablations", all || section == "ablations", [&] { return AblationSection(sweeps, root, quick, report, &error); });
  ok = ok && run("Pareto", all || section == "pareto", [&] { return ParetoSection(sweeps, root, quick, report, &error); });
  ok = ok && run("defaults against hand-tuned", all || section == "defaults",
               [&] { return DefaultsSection(sweeps, results, root, quick, volume, report, &error); });
  ok = ok && run("block hold-outs", all || section == "blocks", [&] { return BlockHoldOutSection(sweeps[0], quick, report, &error); });
  if (!ok)
  {
    return Fail(error);
  }
  report.Markdown << "\nTime per section:";
  for (std::size_t i = 0; i < times.size(); ++i)
  {
    report.Markdown << (i ? "; " : " ") << times[i].first << " " << Format("%.1f", times[i].second / 60) << " min";
  }
  report.Markdown << ".\n";
  const double total = Now() - started;
  if (!WriteReport(options.Output, section, total, report, &error))
  {
    return Fail(error);
  }
  std::printf("benchmark done in %.1f minutes\n", total / 60);
  return 0;
}
}
