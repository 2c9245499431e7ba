// `bigus evaluate`: render sweep frames and compare them with the recording.
#include "bigusCommandLine.h"
#include "bigusGaussianFieldData.h"
#include "bigusImageMetrics.h"
#include "bigusPlot.h"
#include "bigusSliceFrame.h"
#include "bigusTrainer.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkGaussianFieldReslice.h"
#include "vtkGaussianFieldSequenceRenderer.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPolyData.h"
#include "vtkUltrasoundFanMask.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

namespace bigus::cli
{
namespace
{
struct EvaluateOptions
{
  std::string Field, Report, Mask, Backend = "auto";
  SweepOptions Sweep;
  int HoldOutEvery = 0, HoldOutOffset = 0;
  std::vector<int> Frames;
  bool RefinePoses = false, TrackedPoses = false;
  int RefineSteps = 50;
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

/**
 * PNG plot of the field's pose corrections (PoseCorrections: frame, rotation about u, v, n in degrees,
 * translation along u, v, n in mm; `bigus train --refine-poses`) along the sweep: per training frame, the
 * rotation's angle (degrees) and the translation's length (mm), and the same into @p report.
 */
bool PlotPoseCorrections(vtkDataArray* corrections, const std::string& path, nlohmann::json& report)
{
  bigus::PlotSpec spec;
  spec.Title = "pose corrections along the sweep";
  spec.XLabel = "training frame (the sweeps' frames counted in turn)";
  spec.YLabel = "correction (degrees, mm)";
  spec.Series = { { "rotation angle (degrees)", {} }, { "translation length (mm)", {} } };
  for (vtkIdType k = 0; k < corrections->GetNumberOfTuples(); ++k)
  {
    double c[7];
    corrections->GetTuple(k, c);
    const double angle = std::sqrt(c[1] * c[1] + c[2] * c[2] + c[3] * c[3]);
    const double length = std::sqrt(c[4] * c[4] + c[5] * c[5] + c[6] * c[6]);
    spec.Series[0].Points.emplace_back(c[0], angle);
    spec.Series[1].Points.emplace_back(c[0], length);
    report["pose_corrections"].push_back({ { "frame", static_cast<int>(c[0]) },
      { "rotation_degrees", { c[1], c[2], c[3] } }, { "translation_mm", { c[4], c[5], c[6] } } });
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

/// @p field rendered at @p frames of the poses of @p sequence (its ImageToReference); null with @p error when
/// nothing was rendered.
vtkSmartPointer<vtkGaussianFieldSequenceRenderer> RenderAt(vtkPolyData* field, vtkImageData* sequence,
  const std::vector<int>& frames, const std::string& backend, std::string* error)
{
  auto renderer = vtkSmartPointer<vtkGaussianFieldSequenceRenderer>::New();
  renderer->SetInputData(field);
  renderer->SetPoseData(sequence);
  renderer->SetBackend(backend.c_str());
  vtkNew<vtkIdList> list;
  for (int k : frames)
  {
    list->InsertNextId(k);
  }
  renderer->SetFrameList(list);
  FilterError messages;
  messages.Watch(renderer);
  renderer->Update();
  if (renderer->GetOutput()->GetNumberOfPoints() == 0 || !renderer->GetOutput()->GetScalarPointer())
  {
    *error = messages.Or("no frames");
    return nullptr;
  }
  return renderer;
}

/**
 * The fair score under pose error (`--refine-poses`): each of @p scored (frames with a non-empty mask) has its
 * pose in @p data refined with @p field frozen (bigus::RefinePosesWithFieldFrozen), the frames are rendered
 * again at the refined poses and scored with the same metrics; into @p report and stdout. Returns the exit code.
 */
int ScoreAtRefinedPoses(vtkPolyData* field, vtkImageData* truth, bigus::TrainingData& data,
  const std::vector<int>& scored, const EvaluateOptions& o, nlohmann::json& report)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  std::string message;
  bigus::GaussianField gaussians;
  bigus::FieldModel model;
  std::vector<std::array<double, 6>> corrections;
  const bigus::TrainerSettings settings;
  if (!bigus::FieldFromPolyData(field, gaussians, model, &message) ||
    !bigus::RefinePosesWithFieldFrozen(gaussians, data, scored,
      bigus::RenderOptionsFor(model, -1, bigus::FixedTrainingCutoff(settings)), settings.Poses, settings.Loss,
      o.RefineSteps, o.Backend, corrections, &message))
  {
    return Fail("--refine-poses: " + message);
  }
  vtkSmartPointer<vtkImageData> refined = WithOwnFieldData(truth);
  vtkDataArray* poses = refined->GetFieldData()->GetArray("ImageToReference");
  for (int k : scored)
  {
    poses->SetTuple(k, data.Poses[k].data());
  }
  auto again = RenderAt(field, refined, scored, o.Backend, &message);
  if (!again)
  {
    return Fail("rendering at the refined poses failed: " + message);
  }
  const auto* againPixels = static_cast<float*>(again->GetOutput()->GetScalarPointer());
  const bigus::ImageMetrics refinedMean =
    bigus::MeanFrameMetrics(data, scored, [&](std::size_t m, int) { return againPixels + pixels * m; });
  double angle = 0, length = 0;
  for (std::size_t n = 0; n < scored.size(); ++n)
  {
    const std::array<double, 6>& xi = corrections[n];
    const double a = std::sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2]) * 180 / M_PI;
    const double t = std::sqrt(xi[3] * xi[3] + xi[4] * xi[4] + xi[5] * xi[5]);
    angle += a / scored.size();
    length += t / scored.size();
    report["refined_poses"]["frames"].push_back(
      { { "frame", scored[n] }, { "rotation_degrees", { xi[0] * 180 / M_PI, xi[1] * 180 / M_PI, xi[2] * 180 / M_PI } },
        { "translation_mm", { xi[3], xi[4], xi[5] } } });
  }
  report["refined_poses"]["steps"] = o.RefineSteps;
  report["refined_poses"]["mean"] = { { "psnr", refinedMean.PSNR }, { "ssim", refinedMean.SSIM },
    { "ncc", refinedMean.NCC }, { "speckle", refinedMean.Speckle }, { "frames", scored.size() } };
  std::printf("%6s %8.2f %8.4f %8.4f %8.4f  (each frame's pose refined with the field frozen, %d steps: mean "
              "correction %.3f degrees, %.3f mm)\n",
    "refined", refinedMean.PSNR, refinedMean.SSIM, refinedMean.NCC, refinedMean.Speckle, o.RefineSteps, angle, length);
  return 0;
}

/**
 * Where @p sweep's frames lie in a field's RefinedPoses (every trained sweep's frames in turn): the
 * first block of as many consecutive poses whose frames' corners all lie within @p tolerance mm of the sweep's own
 * in @p poses (TrackedPoses, the same frames as tracked, where the field has them: 1e-3 mm; RefinedPoses itself in
 * older fields: 5 mm, pose corrections being of the order of a millimetre, which a sweep a fraction of a frame
 * spacing away matches too; frames marked invalid are not compared). -1 when none does: another sweep, or another
 * frame range.
 */
vtkIdType RefinedPosesOf(vtkImageData* sweep, vtkDataArray* poses, double tolerance)
{
  int dims[3];
  sweep->GetDimensions(dims);
  vtkDataArray* own = sweep->GetFieldData()->GetArray("ImageToReference");
  if (!own || poses->GetNumberOfComponents() != 16 || poses->GetNumberOfTuples() < dims[2])
  {
    return -1;
  }
  for (vtkIdType first = 0; first + dims[2] <= poses->GetNumberOfTuples(); ++first)
  {
    bool close = true;
    for (int k = 0; k < dims[2] && close; ++k)
    {
      if (!FrameIsValid(sweep, k))
      {
        continue;
      }
      double a[16], b[16];
      own->GetTuple(k, a);
      poses->GetTuple(first + k, b);
      for (double i : { 0.0, dims[0] - 1.0 })
      {
        for (double j : { 0.0, dims[1] - 1.0 })
        {
          double d2 = 0;
          for (int r = 0; r < 3; ++r)
          {
            const double d =
              (a[4 * r] - b[4 * r]) * i + (a[4 * r + 1] - b[4 * r + 1]) * j + a[4 * r + 3] - b[4 * r + 3];
            d2 += d * d;
          }
          close = close && d2 < tolerance * tolerance; // also false for a non-finite pose
        }
      }
    }
    if (close)
    {
      return first;
    }
  }
  return -1;
}

int EvaluateInto(const EvaluateOptions& o);

int RunEvaluate(const EvaluateOptions& o)
{
  // Before any work: the report folder exists or is made; a run that fails leaves no empty folder it made.
  const bool made = ::mkdir(o.Report.c_str(), 0755) == 0;
  if (!made && errno != EEXIST)
  {
    return Fail(o.Report + ": cannot create the report folder");
  }
  const int code = EvaluateInto(o);
  if (code != 0 && made)
  {
    ::rmdir(o.Report.c_str()); // only when empty
  }
  return code;
}

int EvaluateInto(const EvaluateOptions& o)
{
  // The report's files replace none of the inputs.
  if (CheckOutputs({ o.Report + "/metrics.json" }, { o.Field, o.Sweep.Sweep, o.Mask }) != 0)
  {
    return 1;
  }
  auto field = ReadField(o.Field);
  auto reader = field ? ReadSweep(o.Sweep) : nullptr;
  if (!reader)
  {
    return 1;
  }
  vtkImageData* truth = reader->GetOutput();
  int dims[3];
  truth->GetDimensions(dims);
  // A field trained with pose refinement: the frames at the poses it was trained with (RefinedPoses: the
  // training frames' own corrections, the smooth part of them on held-out frames (bigus::CorrectUntrainedFrames),
  // and the shared time offset and ImageToProbe correction on every frame), unless --tracked-poses.
  vtkSmartPointer<vtkImageData> atRefinedPoses;
  std::string posesUsed = "tracked";
  if (vtkDataArray* refined = field->GetFieldData()->GetArray("RefinedPoses"))
  {
    vtkDataArray* tracked = field->GetFieldData()->GetArray("TrackedPoses");
    if (o.TrackedPoses)
    {
      std::printf("poses          the sweep's own (--tracked-poses), not the field's RefinedPoses\n");
    }
    else if (const vtkIdType first = tracked && tracked->GetNumberOfTuples() == refined->GetNumberOfTuples()
               ? RefinedPosesOf(truth, tracked, 1e-3)
               : RefinedPosesOf(truth, refined, 5.0);
             first >= 0)
    {
      atRefinedPoses = WithOwnFieldData(truth);
      vtkDataArray* poses = atRefinedPoses->GetFieldData()->GetArray("ImageToReference");
      for (vtkIdType f = 0; f < dims[2]; ++f)
      {
        poses->SetTuple(f, refined->GetTuple(first + f));
      }
      truth = atRefinedPoses;
      posesUsed = "refined";
      std::printf("poses          the field's RefinedPoses (its training frames' corrections, their smooth part on "
                  "the frames it did not train; its shared time offset and ImageToProbe correction on every frame); "
                  "--tracked-poses: the sweep's own\n");
    }
    else
    {
      std::printf("poses          the sweep's own: none of the field's %s (%lld frames) match its %d frames "
                  "(another sweep or frame range)\n",
        tracked ? "TrackedPoses" : "RefinedPoses (within 5 mm)", static_cast<long long>(refined->GetNumberOfTuples()),
        dims[2]);
    }
  }
  for (int k : o.Frames)
  {
    if (k < 0 || k >= dims[2])
    {
      return Fail("--frames: frame " + std::to_string(k) + " is outside the " + std::to_string(dims[2]) +
        " frames of " + o.Sweep.Sweep);
    }
  }
  if (o.Frames.empty() && o.HoldOutEvery > 0 && o.HoldOutOffset >= o.HoldOutEvery)
  {
    return Fail("--holdout-offset " + std::to_string(o.HoldOutOffset) + " must be below --holdout-every " +
      std::to_string(o.HoldOutEvery) + ": no frame would be evaluated");
  }
  std::vector<int> frames = ChooseFrames(dims[2], o.HoldOutEvery, o.HoldOutOffset, o.Frames);
  frames.erase(
    std::remove_if(frames.begin(), frames.end(), [&](int k) { return !FrameIsValid(truth, k); }), frames.end());
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
  auto renderer = RenderAt(field, truth, frames, o.Backend, &message);
  if (!renderer)
  {
    return Fail("rendering failed: " + message);
  }
  vtkImageData* rendered = renderer->GetOutput();
  const std::size_t pixels = std::size_t(dims[0]) * dims[1];
  const auto* renderedPixels = static_cast<float*>(rendered->GetScalarPointer());
  std::vector<std::optional<bigus::ImageMetrics>> perFrame;
  const bigus::ImageMetrics mean = bigus::MeanFrameMetrics(
    data, frames, [&](std::size_t m, int) { return renderedPixels + pixels * m; }, &perFrame);
  nlohmann::json report;
  report["field"] = o.Field;
  report["sweep"] = o.Sweep.Sweep;
  report["poses"] = posesUsed;
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
      if (!WritePng(side, path))
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
  if (WriteSliceThrough(
        field, matrix, dims[0], dims[1], middle.n, middle.v, o.Backend, o.Report + "/slice_orthogonal.png") != 0 ||
    WriteSliceThrough(field, matrix, dims[0], dims[1], tilted, middle.v, o.Backend, o.Report + "/slice_oblique.png") !=
      0)
  {
    return 1;
  }
  if (o.RefinePoses)
  {
    std::vector<int> scored;
    for (std::size_t n = 0; n < frames.size(); ++n)
    {
      if (perFrame[n])
      {
        scored.push_back(frames[n]);
      }
    }
    if (const int code = ScoreAtRefinedPoses(field, truth, data, scored, o, report))
    {
      return code;
    }
  }
  if (vtkDataArray* history = field->GetFieldData()->GetArray("HeldOutPSNR"))
  {
    if (!PlotHistory(history, o.Report + "/psnr_against_time.png"))
    {
      return Fail(o.Report + "/psnr_against_time.png: cannot write");
    }
    for (vtkIdType k = 0; k < history->GetNumberOfTuples(); ++k)
    {
      nlohmann::json point = { { "seconds", history->GetComponent(k, 0) }, { "psnr", history->GetComponent(k, 1) } };
      if (history->GetNumberOfComponents() >= 3)
      {
        point["iteration"] = static_cast<int>(history->GetComponent(k, 2));
      }
      report["held_out_psnr_against_time"].push_back(point);
    }
    report["held_out_psnr_while_training"] = vtkGaussianFieldTrainer::DescribeHeldOutPSNR(history);
  }
  vtkDataArray* corrections = field->GetFieldData()->GetArray("PoseCorrections");
  if (corrections && corrections->GetNumberOfComponents() == 7 && corrections->GetNumberOfTuples() > 0 &&
    !PlotPoseCorrections(corrections, o.Report + "/pose_corrections.png", report))
  {
    return Fail(o.Report + "/pose_corrections.png: cannot write");
  }
  // The shared corrections of a field trained with them.
  vtkDataArray* offset = field->GetFieldData()->GetArray("TimeOffset");
  if (offset && offset->GetNumberOfTuples() > 0)
  {
    report["time_offset_ms"] = 1000 * offset->GetTuple1(0);
  }
  if (vtkDataArray* shared = field->GetFieldData()->GetArray("ImageToProbeCorrection"))
  {
    if (shared->GetNumberOfComponents() == 6 && shared->GetNumberOfTuples() > 0)
    {
      const double* c = shared->GetTuple(0);
      report["image_to_probe_correction"] = { { "rotation_degrees", { c[0], c[1], c[2] } },
        { "translation_mm", { c[3], c[4], c[5] } } };
    }
  }
  report["mean"] = { { "psnr", mean.PSNR }, { "ssim", mean.SSIM }, { "ncc", mean.NCC }, { "speckle", mean.Speckle },
    { "frames", used } };
  std::printf("%6s %8.2f %8.4f %8.4f %8.4f  (%zu frames, %zu left out: empty mask; %.1f ms per rendered frame)\n",
    "mean", mean.PSNR, mean.SSIM, mean.NCC, mean.Speckle, used, frames.size() - used,
    1e3 * renderer->GetSecondsPerFrame());
  if (report.contains("held_out_psnr_while_training"))
  {
    std::printf("while training (bigus train --evaluate-every), the frames it did not train on: %s\n",
      report["held_out_psnr_while_training"].get<std::string>().c_str());
  }
  const std::string path = o.Report + "/metrics.json";
  // A failed write (disk full) is not published: the temporary goes, an existing file stays.
  return WriteText(path, report.dump(2) + "\n") ? 0 : Fail(path + ": cannot write");
}
}

Command AddEvaluateCommand(CLI::App& app)
{
  auto options = std::make_shared<EvaluateOptions>();
  EvaluateOptions& evaluate = *options;
  CLI::App* evaluateCommand = app.add_subcommand("evaluate", "Render sweep frames and compare them with the recording");
  evaluateCommand->add_option("FIELD", evaluate.Field, "Gaussian field (.vtp)")->required()->check(CLI::ExistingFile);
  evaluateCommand->add_option("SWEEP", evaluate.Sweep.Sweep, "Sequence metafile")->required()->check(CLI::ExistingFile);
  AddSweepOptions(evaluateCommand, evaluate.Sweep, "sweep");
  evaluateCommand->add_option("--holdout-every", evaluate.HoldOutEvery, "Evaluate frames with index % K == J")
    ->check(FiniteNonNegative());
  evaluateCommand->add_option("--holdout-offset", evaluate.HoldOutOffset, "J of --holdout-every (0 to K - 1)")
    ->check(FiniteNonNegative());
  evaluateCommand->add_option("--frames", evaluate.Frames, "Evaluate these frames");
  evaluateCommand->add_option(
    "--mask", evaluate.Mask, "Fan mask .mha (W x H x 1, or W x H x N per frame; default: estimated)");
  evaluateCommand->add_option("--backend", evaluate.Backend, "Rendering backend: auto, cpu or cuda (as registered)");
  evaluateCommand->add_option("--report", evaluate.Report, "Folder for metrics.json and side-by-side PNGs")->required();
  evaluateCommand->add_flag("--refine-poses", evaluate.RefinePoses,
    "Score each frame also at its pose refined with the field frozen (the fair score of held-out frames whose tracked "
    "poses are imperfect, as view-synthesis papers report it); both scores are printed and in metrics.json");
  evaluateCommand->add_flag("--tracked-poses", evaluate.TrackedPoses,
    "Score at the sweep's own poses even when the field holds RefinedPoses (default: a field trained with pose "
    "refinement is scored at the poses it refined, held-out frames with its shared corrections and the smooth part of "
    "their sweep's)");
  evaluateCommand->add_option("--refine-steps", evaluate.RefineSteps, "Adam steps per frame of --refine-poses")
    ->check(FinitePositive())
    ->capture_default_str();
  return { evaluateCommand, [options] {
            EvaluateOptions& evaluate = *options;
            return RunEvaluate(evaluate);
          } };
}

} // namespace bigus::cli
