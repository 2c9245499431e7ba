// `bigus benchmark`: the hold-out section of each bundled sweep, and where its held-out error comes from
// (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"

#include "vtkFieldData.h"
#include "vtkNew.h"
#include "vtkUltrasoundFrameInterpolator.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

namespace bigus::benchmark
{
namespace
{
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
    // At the pose the field was trained at (refined, where the trainer refines the sweep's poses).
    if (!trainer.RenderFrame(trainer.GetData(), f, image + pixels * f, error))
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
  e.BlendedRenders = Score(static_cast<float*>(blend->GetOutput()->GetScalarPointer()), 1.0, data, sweep.HeldOut);
  return true;
}
}

bool HoldOutSection(BenchmarkContext& context, std::size_t si, std::string* error)
{
  Sweep& sweep = context.Sweeps[si];
  const std::string& root = context.Root;
  Report& report = context.Report;
  HoldOutResults& results = context.HoldOut;
  std::ostringstream& md = report.Markdown;
  const double capacitySeconds = CapacitySeconds(context.Quick);
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
  const bool ok = TrainWithMarks(
    sweep.Data, s, marks, sweep.HeldOut, "BIGUS",
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
  md << "\n## " << sweep.Name << "\n\n`" << sweep.File.substr(root.size() + 1) << "`: " << sweep.Description << ".\n\n"
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
    md << std::exchange(separator, ", ") << Format("%.2f", q.PSNR) << " dB (SSIM " << Format("%.3f", q.SSIM) << ") at "
       << Format("%.1f", sigma);
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
}
