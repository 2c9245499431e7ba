// The first field of a run: Harris, uniform and dense seeding (see bigusSeeding.h and DESIGN section 4).
#include "bigusSeeding.h"

#include "bigusGaussianMath.h"
#include "bigusReflectivitySolve.h"
#include "bigusSliceFrame.h"

#include <opencv2/imgproc.hpp>
#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace bigus
{
namespace
{
/// A pixel drawn from @p cumulative, the running sum of per-pixel weights whose last entry is @p total (> 0).
std::size_t DrawPixel(const std::vector<double>& cumulative, double total, std::mt19937_64& rng)
{
  const double target = UniformDouble(rng) * total;
  const std::size_t p = std::upper_bound(cumulative.begin(), cumulative.end(), target) - cumulative.begin();
  return std::min(p, cumulative.size() - 1);
}

/// The point (mm) of pixel (i, j) of a frame with ImageToReference @p m.
void Apply(const std::array<double, 16>& m, double i, double j, double out[3])
{
  for (int r = 0; r < 3; ++r)
  {
    out[r] = m[4 * r] * i + m[4 * r + 1] * j + m[4 * r + 3];
  }
}
/// mm from @p plane to @p point (mm) along its normal.
double DistanceFromPlane(const SliceFrame& plane, const double point[3])
{
  double d = 0;
  for (int k = 0; k < 3; ++k)
  {
    d += plane.n[k] * (point[k] - plane.origin[k]);
  }
  return std::abs(d);
}

/// Appends one seed Gaussian lying in frame @p pose at pixel (i, j).
void AddSeed(GaussianField& field, const std::array<double, 16>& pose, double i, double j, double inPlaneScale,
  double elevationScale, double reflectivity)
{
  double p[3];
  Apply(pose, i, j, p);
  SliceFrame frame;
  ComputeSliceFrame(pose.data(), 90, frame);
  double q[4];
  QuaternionFromAxes(frame.u, frame.v, frame.n, q);
  for (int k = 0; k < 3; ++k)
  {
    field.Means.push_back(static_cast<float>(p[k]));
  }
  field.LogScales.push_back(static_cast<float>(std::log(inPlaneScale)));
  field.LogScales.push_back(static_cast<float>(std::log(inPlaneScale)));
  field.LogScales.push_back(static_cast<float>(std::log(elevationScale)));
  for (double v : q)
  {
    field.Quaternions.push_back(static_cast<float>(v));
  }
  field.Reflectivities.push_back(static_cast<float>(reflectivity));
}

}

double ScatteringOfIntensity(double intensity, double gamma)
{
  return -std::log(1.0 - std::min(intensity, 0.95)) / gamma;
}

void SeedHarris(
  const TrainingData& data, std::int64_t total, std::mt19937_64& rng, const SeedShape& shape, GaussianField& field)
{
  // Seeds in proportion to the positive Harris response inside the mask, plus a uniform share
  // (DESIGN section 4): structure (edges, corners, bright speckle) gets Gaussians first.
  const int W = data.Width, H = data.Height;
  const std::size_t pixels = std::size_t(W) * H;
  const int frames = static_cast<int>(data.TrainFrames.size());
  field = GaussianField();
  std::vector<double> cumulative(pixels);
  for (int n = 0; n < frames; ++n)
  {
    const int f = data.TrainFrames[n];
    const float* frame = &data.Frames[pixels * f];
    const unsigned char* mask = data.MaskOf(f);
    cv::Mat image(H, W, CV_32F, const_cast<float*>(frame));
    cv::Mat response;
    cv::cornerHarris(image, response, 3, 3, 0.04);
    double positive = 0, masked = 0;
    for (std::size_t p = 0; p < pixels; ++p)
    {
      if (mask[p])
      {
        positive += std::max(0.0f, response.at<float>(static_cast<int>(p)));
        masked += 1;
      }
    }
    if (masked == 0)
    {
      continue; // a frame that sees nothing of the scene (volume protocol: a slice outside the data)
    }
    const double share = shape.UniformShare;
    double running = 0;
    for (std::size_t p = 0; p < pixels; ++p)
    {
      if (mask[p])
      {
        const double harris = positive > 0 ? std::max(0.0f, response.at<float>(static_cast<int>(p))) / positive : 0;
        running += (1 - share) * harris + (positive > 0 ? share : 1.0) / masked;
      }
      cumulative[p] = running;
    }
    const std::int64_t seeds = total / frames + (n < total % frames ? 1 : 0);
    for (std::int64_t s = 0; s < seeds; ++s)
    {
      const std::size_t pixel = DrawPixel(cumulative, running, rng);
      const double i = double(pixel % W) + UniformDouble(rng) - 0.5;
      const double j = double(pixel / W) + UniformDouble(rng) - 0.5;
      AddSeed(field, data.Poses[f], i, j, shape.InPlaneScale, shape.ElevationScale,
        ScatteringOfIntensity(frame[pixel], shape.Gamma));
    }
  }
}

std::int64_t SeedResidual(const TrainingData& data, int f, const float* residual, std::int64_t count,
  std::mt19937_64& rng, const SeedShape& shape, GaussianField& field)
{
  const int W = data.Width;
  const std::size_t pixels = std::size_t(W) * data.Height;
  const unsigned char* mask = data.MaskOf(f);
  std::vector<double> cumulative(pixels);
  double running = 0;
  for (std::size_t p = 0; p < pixels; ++p)
  {
    running += mask[p] && std::isfinite(residual[p]) ? std::abs(double(residual[p])) : 0.0;
    cumulative[p] = running;
  }
  if (!(running > 0))
  {
    return 0;
  }
  for (std::int64_t s = 0; s < count; ++s)
  {
    const std::size_t pixel = DrawPixel(cumulative, running, rng);
    AddSeed(field, data.Poses[f], double(pixel % W), double(pixel / W), shape.InPlaneScale, shape.ElevationScale,
      residual[pixel]);
  }
  return count;
}

void SeedUniform(
  const TrainingData& data, std::int64_t total, std::mt19937_64& rng, const SeedShape& shape, GaussianField& field)
{
  // Ablation: seeds uniform in the bounding box of every training frame's corners.
  double lo[3] = { 1e300, 1e300, 1e300 }, hi[3] = { -1e300, -1e300, -1e300 };
  for (int f : data.TrainFrames)
  {
    for (double i : { 0.0, data.Width - 1.0 })
    {
      for (double j : { 0.0, data.Height - 1.0 })
      {
        double p[3];
        Apply(data.Poses[f], i, j, p);
        for (int k = 0; k < 3; ++k)
        {
          lo[k] = std::min(lo[k], p[k]);
          hi[k] = std::max(hi[k], p[k]);
        }
      }
    }
  }
  const double scale = shape.InPlaneScale;
  field = GaussianField();
  for (std::int64_t s = 0; s < total; ++s)
  {
    for (int k = 0; k < 3; ++k)
    {
      field.Means.push_back(static_cast<float>(lo[k] + (hi[k] - lo[k]) * UniformDouble(rng)));
      field.LogScales.push_back(static_cast<float>(std::log(scale)));
    }
    double q[4], n2 = 0;
    for (double& v : q)
    {
      v = UniformDouble(rng) - 0.5;
      n2 += v * v;
    }
    for (double v : q)
    {
      field.Quaternions.push_back(static_cast<float>(v / std::sqrt(n2)));
    }
    field.Reflectivities.push_back(static_cast<float>(ScatteringOfIntensity(0.5, shape.Gamma)));
  }
}

GridPlanes SelectGridPlanes(const TrainingData& data, const SeedShape& shape)
{
  // The training frames in order, each kept when its centre lies at least sigma_E (or 1 pixel without a
  // beam) from the plane of the last one kept, so that the planes' Gaussians do not repeat each other
  // within a beam width. Not a pixel with a beam: frames closer than a pixel still add views the beam
  // separates (volume protocol, 160 slices 0.325 mm apart, 0.5 mm pixels: every plane kept, oblique
  // 46.98 dB against 42.11 with every second; docs/FINDINGS.md, "The pixel grid's planes and count").
  GridPlanes result;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const double minimumGap = shape.ElevationSigma > 0 ? shape.ElevationSigma : shape.PixelSpacing;
  SliceFrame last;
  std::vector<double> gaps;
  std::vector<int> gapCount;
  std::vector<double> gapBefore; // [planes kept] mm to the previous plane kept in its sweep, -1 for a sweep's first
  int lastSweep = -1;
  for (int f : data.TrainFrames)
  {
    SliceFrame frame;
    ComputeSliceFrame(data.Poses[f].data(), 90, frame);
    double centre[3];
    Apply(data.Poses[f], 0.5 * (data.Width - 1), 0.5 * (data.Height - 1), centre);
    const int sweep = data.SweepOf(f);
    if (sweep >= static_cast<int>(gaps.size()))
    {
      gaps.resize(sweep + 1, 0.0);
      gapCount.resize(sweep + 1, 0);
    }
    if (sweep == lastSweep) // the first frame of a sweep is kept
    {
      const double d = DistanceFromPlane(last, centre);
      if (d < minimumGap)
      {
        continue;
      }
      gaps[sweep] += d;
      ++gapCount[sweep];
      gapBefore.push_back(d);
    }
    else
    {
      gapBefore.push_back(-1.0); // the first plane of its sweep
    }
    result.Frames.push_back(f);
    last = frame;
    lastSweep = sweep;
    const unsigned char* mask = data.MaskOf(f);
    result.FanPixels += std::count_if(mask, mask + pixels, [](unsigned char v) { return v != 0; });
  }
  for (std::size_t s = 0; s < gaps.size(); ++s)
  {
    result.Spacing.push_back(gapCount[s] > 0 ? gaps[s] / gapCount[s] : minimumGap);
  }
  for (std::size_t k = 0; k < result.Frames.size(); ++k)
  {
    const double after = k + 1 < result.Frames.size() ? gapBefore[k + 1] : -1.0;
    const double local = std::max(gapBefore[k], after);
    result.PlaneSpacing.push_back(local > 0 ? local : result.Spacing[data.SweepOf(result.Frames[k])]);
  }
  return result;
}

std::string SeedGrid(const TrainingData& data, std::int64_t total, const SeedShape& shape, GaussianField& field)
{
  return SeedGrid(data, SelectGridPlanes(data, shape), total, shape, field);
}

std::string SeedGrid(const TrainingData& data, const GridPlanes& selected, std::int64_t total, const SeedShape& shape,
  GaussianField& field)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const std::vector<int>& planes = selected.Frames;
  const std::vector<double>& planeSpacing = selected.Spacing;
  const double masked = static_cast<double>(selected.FanPixels);
  // Grid points at the centres of stride x stride blocks of pixels (pixel centres at integer indices:
  // (stride - 1)/2 + a stride), kept inside the fan mask. The stride is real-valued, so that the grid's
  // count falls short of the count wanted by less than a row and a column (an integer stride can land at
  // a quarter of it): widened from the estimate in steps of 1 % until the count stays within it.
  auto forEachPoint = [&](int f, double stride, const auto& visit) {
    const unsigned char* mask = data.MaskOf(f);
    for (double y = 0.5 * (stride - 1); y <= data.Height - 1; y += stride)
    {
      for (double x = 0.5 * (stride - 1); x <= data.Width - 1; x += stride)
      {
        const std::size_t p = std::size_t(std::lround(y)) * data.Width + std::size_t(std::lround(x));
        if (mask[p])
        {
          visit(x, y, p);
        }
      }
    }
  };
  auto gridCount = [&](double stride) {
    std::int64_t c = 0;
    for (int f : planes)
    {
      forEachPoint(f, stride, [&](double, double, std::size_t) { ++c; });
    }
    return c;
  };
  double stride = std::max(1.0, std::sqrt(masked / std::max<std::int64_t>(1, total)));
  while (gridCount(stride) > total)
  {
    stride *= 1.01;
  }
  const double inPlane = 0.6 * stride * shape.PixelSpacing;
  // Elevation scale 0.45 plane spacings, whatever the beam: measured on the volume protocol's in-between,
  // oblique and orthogonal slices (docs/FINDINGS.md, "The dense start's elevation scale"); a slice across
  // the planes sees this scale itself, not blurred by the beam. The spacing is the gap at the point, at least the
  // plane's own (the larger of its gaps to the planes beside it), so that the planes around a wider gap (a frame
  // held out, an irregular or rocking freehand step) bridge it: with the sweep's mean spacing the grid scored
  // 35.06 dB on frames held out of a sweep 0.217 mm apart, 48.04 with its own (docs/FINDINGS.md, "The grid's
  // elevation scale at a wider gap").
  field = GaussianField();
  for (std::size_t k = 0; k < planes.size(); ++k)
  {
    const int f = planes[k];
    const float* frame = &data.Frames[pixels * f];
    // The planes beside it in its sweep: where they are not parallel to it (a rocking or fanning probe) the gap at
    // a grid point is wider than at the frame's centre on one side.
    std::vector<SliceFrame> beside;
    for (std::size_t n : { k - 1, k + 1 })
    {
      if (n < planes.size() && data.SweepOf(planes[n]) == data.SweepOf(f))
      {
        beside.emplace_back();
        ComputeSliceFrame(data.Poses[planes[n]].data(), 90, beside.back());
      }
    }
    forEachPoint(f, stride, [&](double x, double y, std::size_t p) {
      double point[3];
      Apply(data.Poses[f], x, y, point);
      double gap = selected.PlaneSpacing.at(k);
      for (const SliceFrame& plane : beside)
      {
        gap = std::max(gap, DistanceFromPlane(plane, point));
      }
      AddSeed(field, data.Poses[f], x, y, inPlane, 0.45 * gap, ScatteringOfIntensity(frame[p], shape.Gamma));
    });
  }
  char text[200];
  std::string line = std::to_string(planes.size()) + " planes ";
  for (std::size_t s = 0; s < planeSpacing.size(); ++s)
  {
    std::snprintf(text, sizeof(text), "%s%.3g mm apart", s > 0 ? ", " : "", planeSpacing[s]);
    line += text + (planeSpacing.size() > 1 ? " in sweep " + std::to_string(s) : std::string());
  }
  std::snprintf(text, sizeof(text),
    ", every %.2f pixels, in-plane scale %.3g mm, elevation scale 0.45 x the gap to "
    "the planes beside each point",
    stride, inPlane);
  return line + text;
}
bool GammaOfTrainingFrames(
  const TrainingData& data, double& gamma, std::int64_t& fanPixels, std::string& line, std::string* error)
{
  const double mean = MeanFanIntensity(data, fanPixels);
  if (fanPixels == 0)
  {
    if (error)
    {
      *error = "the fan mask is empty";
    }
    return false;
  }
  gamma = GammaFromMeanIntensity(mean);
  line = vtkfmt::sprintf("Gamma = %.5g (from the mean fan intensity %.4f of the training frames)", gamma, mean);
  return true;
}

double UniformDouble(std::mt19937_64& rng)
{
  return (rng() >> 11) * (1.0 / 9007199254740992.0);
}

bool TrainingFitsInMemory(const TrainingData& data, std::int64_t gaussians, bool solve, bool l1, std::string* error)
{
  const std::int64_t trainingPixels =
    std::int64_t(data.Width) * data.Height * static_cast<std::int64_t>(data.TrainFrames.size());
  return CheckTrainingMemory(gaussians, solve ? ReflectivitySolveBytes(gaussians, trainingPixels, l1) : 0.0, error);
}

bool PlanSeeding(const TrainingData& data, const SeedingSettings& s, std::int64_t maximumGaussians, bool nonNegative,
  bool solveL1, const SeedShape& shape, std::int64_t fanPixels, SeedingPlan& plan, std::string* error)
{
  plan = SeedingPlan();
  plan.FanPixels = fanPixels;
  if (s.InitialGaussians > maximumGaussians)
  {
    if (error)
    {
      *error = vtkfmt::sprintf("InitialGaussians (%lld) exceeds MaximumGaussians (%lld)",
        static_cast<long long>(s.InitialGaussians), static_cast<long long>(maximumGaussians));
    }
    return false;
  }
  // The planes are selected (a pass over the training frames' masks) only where the pixel-grid fit may apply.
  const bool gridMayApply =
    s.PixelGridFit && !s.DenseInitialisation && s.InitialGaussians <= 0 && s.HarrisInitialisation && !nonNegative;
  if (gridMayApply)
  {
    plan.Planes = SelectGridPlanes(data, shape);
    plan.PixelGrid = plan.Planes.FanPixels <= s.PixelGridFanPixelsPerGaussian * maximumGaussians;
  }
  const std::int64_t half = std::max<std::int64_t>(1, maximumGaussians / 2); // at least one seed where the maximum is 1
  if (plan.PixelGrid)
  {
    // The grid's count is set by memory, not by MaximumGaussians (a grid is never densified): every fan pixel of the
    // planes where this machine holds their training state and solve, else MaximumGaussians of them.
    const std::int64_t all = plan.Planes.FanPixels;
    plan.Count = s.GridCountByMemory && TrainingFitsInMemory(data, all, true, solveL1)
      ? all
      : std::min<std::int64_t>(all, maximumGaussians);
  }
  else if (s.DenseInitialisation)
  {
    plan.Count = s.InitialGaussians > 0 ? s.InitialGaussians : half;
  }
  else
  {
    // Capacity follows the data: more fan pixels to explain, more seeds (docs/FINDINGS.md, "The trainer's defaults,
    // measured").
    plan.Count = s.InitialGaussians > 0
      ? s.InitialGaussians
      : std::max<std::int64_t>(std::min<std::int64_t>(20000, half), std::min<std::int64_t>(fanPixels / 200, half));
  }
  return true;
}

std::string SeedField(const TrainingData& data, const SeedingPlan& plan, const SeedingSettings& s,
  const SeedShape& shape, unsigned seed, double solveL1, GaussianField& field)
{
  const auto gaussians = [&]() { return static_cast<long long>(field.Count()); };
  if (plan.PixelGrid)
  {
    const std::string grid = SeedGrid(data, plan.Planes, plan.Count, shape, field);
    return vtkfmt::sprintf("InitialGaussians = %lld (the pixel-grid fit: %s the %lld fan pixels of the dense "
                           "start's planes; ",
             gaussians(),
             plan.Count < plan.Planes.FanPixels ? "MaximumGaussians points, as memory does not hold every one of"
                                                : "every one, as memory holds them, of",
             static_cast<long long>(plan.Planes.FanPixels)) +
      grid + "; reflectivities solved" +
      (solveL1 > 0 ? vtkfmt::sprintf(" with an L1 term of %.3g (FISTA)", solveL1) : std::string()) +
      ", no geometry steps)";
  }
  if (s.DenseInitialisation)
  {
    const std::string grid = SeedGrid(data, plan.Count, shape, field);
    return vtkfmt::sprintf("InitialGaussians = %lld (dense start: ", gaussians()) + grid + ")";
  }
  const std::string line = vtkfmt::sprintf("InitialGaussians = %lld (", static_cast<long long>(plan.Count)) +
    (s.InitialGaussians > 0
        ? std::string("given")
        : vtkfmt::sprintf("chosen: one per 200 of the %lld fan pixels of the training frames, 20,000 to half the "
                          "maximum",
            static_cast<long long>(plan.FanPixels))) +
    (s.HarrisInitialisation ? "; Harris seeding" : "; uniform random seeding") +
    (shape.FrameSpacing > 0
        ? vtkfmt::sprintf(", %.3g mm across their frame: %.2g x the training frames' spacing %.3g mm, wider than the "
                          "beam %.3g mm; on the liver's training frames one in 3 and one in 4, +0.54 and +1.11 dB on "
                          "frames the fit did not see: docs/FINDINGS.md, \"Seeds across a sparse sweep's gaps\")",
            shape.ElevationScale, s.ElevationSpacingFactor, shape.FrameSpacing, shape.ElevationSigma)
        : std::string(")"));
  std::mt19937_64 rng(seed * 7919ULL + 17);
  if (s.HarrisInitialisation)
  {
    SeedHarris(data, plan.Count, rng, shape, field);
  }
  else
  {
    SeedUniform(data, plan.Count, rng, shape, field);
  }
  return line;
}

bool ScaleSeedReflectivities(TrainingEngine& engine, const TrainingData& data, const RenderOptions& options,
  double gamma, GaussianField& field, bool& scaled, std::string* error)
{
  scaled = false;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const int frames = static_cast<int>(data.TrainFrames.size());
  std::vector<float> S(pixels);
  double num = 0, den = 0;
  for (int n = 0; n < std::min(frames, 5); ++n)
  {
    const int f = data.TrainFrames[(n * frames) / std::min(frames, 5)];
    const SliceGeometry slice = data.Slice(f);
    if (!engine.Render(&slice, 1, options, S.data(), nullptr, error))
    {
      return false;
    }
    const float* frame = &data.Frames[pixels * f];
    const unsigned char* mask = data.MaskOf(f);
    for (std::size_t p = 0; p < pixels; ++p)
    {
      if (mask[p])
      {
        num += S[p] * ScatteringOfIntensity(frame[p], gamma);
        den += double(S[p]) * S[p];
      }
    }
  }
  const double c = den > 0 ? num / den : 1.0;
  if (!std::isfinite(c) || c <= 0)
  {
    return true;
  }
  for (float& r : field.Reflectivities)
  {
    r = static_cast<float>(r * c);
  }
  scaled = true;
  return true;
}

bool RenderResiduals(TrainingEngine& engine, const TrainingData& data, const RenderOptions& options, double gamma,
  int count, std::mt19937_64& rng, std::vector<int>& frames, std::vector<float>& residuals, std::string* error)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  residuals.resize(pixels * count);
  for (int k = 0; k < count; ++k)
  {
    const int f = data.TrainFrames[static_cast<std::size_t>(UniformDouble(rng) * data.TrainFrames.size())];
    frames.push_back(f);
    const SliceGeometry slice = data.Slice(f);
    float* S = &residuals[pixels * k];
    if (!engine.Render(&slice, 1, options, S, nullptr, error))
    {
      return false;
    }
    const float* frame = &data.Frames[pixels * f];
    for (std::size_t p = 0; p < pixels; ++p)
    {
      S[p] = static_cast<float>(ScatteringOfIntensity(frame[p], gamma) - S[p]);
    }
  }
  return true;
}

void SeedResiduals(const TrainingData& data, const std::vector<int>& frames, const std::vector<float>& residuals,
  std::int64_t count, std::mt19937_64& rng, const SeedShape& shape, GaussianField& field)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const std::int64_t n = static_cast<std::int64_t>(frames.size());
  for (std::int64_t k = 0; k < n; ++k)
  {
    SeedResidual(data, frames[k], &residuals[pixels * k], count / n + (k < count % n ? 1 : 0), rng, shape, field);
  }
}

} // namespace bigus
