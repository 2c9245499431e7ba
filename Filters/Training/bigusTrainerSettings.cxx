// The setting lines that a run's settings alone fix (see bigusTrainerSettings.h).
#include "bigusTrainerSettings.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

namespace bigus
{

std::string ResumeSettings(const TrainerSettings& s)
{
  std::string text;
  auto line = [&text](const char* name, double value) { text += vtkfmt::sprintf("%s = %.17g\n", name, value); };
  line("ElevationSigma", s.ElevationSigma);
  line("BeamIntegration", s.BeamIntegration);
  line("NonNegativeReflectivity", s.NonNegativeReflectivity);
  line("Cutoff", s.Cutoff);
  line("Seeding.HarrisInitialisation", s.Seeding.HarrisInitialisation);
  line("Seeding.InitialGaussians", static_cast<double>(s.Seeding.InitialGaussians));
  line("Seeding.DenseInitialisation", s.Seeding.DenseInitialisation);
  line("Seeding.PixelGridFit", s.Seeding.PixelGridFit);
  line("Seeding.ElevationSpacingFactor", s.Seeding.ElevationSpacingFactor);
  line("Loss.L1", s.Loss.L1);
  line("Loss.DSSIM", s.Loss.DSSIM);
  line("Loss.FFL", s.Loss.FFL);
  line("SparseAdam", s.SparseAdam);
  line("MaximumGaussians", static_cast<double>(s.MaximumGaussians));
  line("ReflectivitySolve", s.ReflectivitySolve);
  line("RefinePoses", static_cast<double>(s.Poses.RefinePoses));
  line("Seed", s.Seed);
  return text;
}

std::string ResumeSettingsDifference(const std::string& written, const std::string& current)
{
  auto lines = [](const std::string& text) {
    std::map<std::string, std::string> values;
    std::istringstream in(text);
    std::string row;
    while (std::getline(in, row))
    {
      const std::size_t at = row.find(" = ");
      if (at != std::string::npos)
      {
        values[row.substr(0, at)] = row.substr(at + 3);
      }
    }
    return values;
  };
  const std::map<std::string, std::string> then = lines(written), now = lines(current);
  std::string difference;
  for (const auto& entry : then)
  {
    const auto found = now.find(entry.first);
    const std::string value = found == now.end() ? "(none)" : found->second;
    if (value != entry.second)
    {
      difference +=
        (difference.empty() ? "" : "; ") + entry.first + ": " + entry.second + " in the checkpoint, " + value + " now";
    }
  }
  return difference;
}

std::vector<std::string> DescribeTrainerSettings(const TrainerSettings& s)
{
  std::string schedule = s.Iterations > 0 ? vtkfmt::sprintf("Iterations = %d", s.Iterations) : "Iterations = no limit";
  if (s.TimeBudget > 0)
  {
    schedule += vtkfmt::sprintf(", TimeBudget = %.4g s (", s.TimeBudget) +
      (s.Iterations > 0 ? "whichever ends first; " : "") + "the schedule follows the one further along)";
  }
  return { schedule, DescribeDensification(s.Densification, s.MaximumGaussians),
    s.FinalPruneTolerance > 0
      ? vtkfmt::sprintf("FinalPrune = on (at the end, the Gaussians whose removal together changes no training "
                        "pixel by more than %.3g in intensity)",
          s.FinalPruneTolerance)
      : std::string("FinalPrune = off"),
    DescribeGapFillingSettings(s.FillGaps, s.BeamIntegration, s.GapFilling), DescribeGaussianMergeSettings(s.Merge),
    DescribeReflectivitySolve(s.ReflectivitySolve, s.NonNegativeReflectivity, s.Solve, s.SolveInterval),
    s.ParameterAverage > 0
      ? vtkfmt::sprintf("ParameterAverage = %.4g (the run's field: an exponential moving average of the parameters "
                        "and pose corrections from the densification window's close, time constant %.4g of the "
                        "schedule; against the last field +0.46 dB on the liver's held-out frames at 600 s, "
                        "docs/FINDINGS.md)",
          s.ParameterAverage, s.ParameterAverage)
      : std::string("ParameterAverage = off (the run's field: the last step's)"),
    vtkfmt::sprintf("Seed = %u, FramesPerStep = %d, Loss = %.3g L1 + %.3g D-SSIM + %.3g FFL, Cutoff = %s, SparseAdam = "
                    "%s%s",
      s.Seed, s.FramesPerStep, s.Loss.L1, s.Loss.DSSIM, s.Loss.FFL,
      s.Cutoff > 0 ? vtkfmt::sprintf("%.3g", s.Cutoff)
                   : vtkfmt::sprintf(
                       "automatic (a step's: %.3g where Adam steps on trusted poses, %.3g while a pose is "
                       "refined, in the pose trial's branches and where reflectivities are solved; validation and "
                       "the final prune at %.3g; on the liver's held-out frames 3.5 scored +0.18 and +0.31 dB at 300 s "
                       "and, with refined poses, 4.2 dB lower fair on a synthetic path: docs/FINDINGS.md, \"The "
                       "automatic training cut-off\")",
                       FastTrainingCutoff, FineTrainingCutoff, FineTrainingCutoff),
      s.SparseAdam ? "on" : "off",
      s.CoarseFraction > 0
        ? vtkfmt::sprintf(", CoarseFraction = %.3g (a quarter of the pixels per step until then, %s)", s.CoarseFraction,
            s.CoarseLowPass ? "2 x 2 averages through the pixel's low-pass" : "point samples")
            .c_str()
        : "") };
}

TrainerSettings ScheduledSettings(TrainerSettings s)
{
  s.FramesPerStep = std::max(1, s.FramesPerStep);
  s.Iterations = s.Iterations <= 0 && s.TimeBudget <= 0 ? DefaultIterations : s.Iterations;
  return s;
}

SeedShape SeedShapeOf(const TrainerSettings& s, double pixelSpacing, double gamma, double frameSpacing)
{
  SeedShape shape;
  shape.PixelSpacing = pixelSpacing;
  shape.InPlaneScale = s.Seeding.InitialScalePixels * pixelSpacing;
  shape.ElevationSigma = s.BeamIntegration ? s.ElevationSigma : 0.0;
  shape.ElevationScale = shape.ElevationSigma > 0 ? shape.ElevationSigma : pixelSpacing;
  const double across = s.Seeding.ElevationSpacingFactor * frameSpacing;
  if (shape.ElevationSigma > 0 && across > shape.ElevationScale)
  {
    shape.ElevationScale = across;
    shape.FrameSpacing = frameSpacing;
  }
  shape.UniformShare = s.Seeding.UniformShare;
  shape.Gamma = gamma;
  return shape;
}

RenderOptions RenderOptionsOf(const TrainerSettings& s, double gamma)
{
  RenderOptions o;
  o.ElevationSigma = s.ElevationSigma;
  o.BeamIntegration = s.BeamIntegration;
  o.NonNegativeReflectivity = s.NonNegativeReflectivity;
  o.Cutoff = FixedTrainingCutoff(s);
  o.Gamma = gamma;
  return o;
}

StepRequest StepRequestAt(const TrainerSettings& s, double fraction, double rateScale, const RenderOptions& options)
{
  constexpr double MinimumScaleMm = 1e-3, MaximumScaleMm = 100.0;
  StepRequest request;
  request.MeanRate =
    rateScale * (s.MeanLearningRate * std::pow(s.MeanLearningRateFinal / s.MeanLearningRate, fraction));
  request.LogScaleRate = rateScale * s.LogScaleLearningRate;
  request.QuaternionRate = rateScale * s.QuaternionLearningRate;
  request.ReflectivityRate = rateScale * s.ReflectivityLearningRate;
  request.MinimumLogScale = std::log(MinimumScaleMm);
  request.MaximumLogScale = std::log(MaximumScaleMm);
  request.Options = options;
  request.Loss = s.Loss;
  request.SparseAdam = s.SparseAdam;
  return request;
}

int DecimateStep(const TrainingData& data, const std::vector<int>& frames, bool average, std::mt19937_64& rng,
  TrainingData& decimated, StepRequest& request)
{
  const int smallest = average ? 3 : 2;
  if (data.Width < smallest || data.Height < smallest)
  {
    return -1;
  }
  const int phase = static_cast<int>(UniformDouble(rng) * 4);
  decimated = DecimateFrames(data, frames.data(), static_cast<int>(frames.size()), phase & 1, phase >> 1, average);
  request.Data = &decimated;
  request.Frames = decimated.TrainFrames.data();
  return phase;
}

} // namespace bigus
