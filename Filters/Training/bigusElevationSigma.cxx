#include "bigusElevationSigma.h"

#include "bigusSliceFrame.h"

#include "vtkSMPTools.h"

#include <opencv2/imgproc.hpp>
#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>

namespace bigus
{
namespace
{
/// Sums for the normalised cross-correlation of one distance bin.
struct CorrelationSums
{
  double X = 0, Y = 0, XX = 0, YY = 0, XY = 0;
  long N = 0;
  void Add(double x, double y)
  {
    this->X += x;
    this->Y += y;
    this->XX += x * x;
    this->YY += y * y;
    this->XY += x * y;
    ++this->N;
  }
  void Add(const CorrelationSums& o)
  {
    this->X += o.X;
    this->Y += o.Y;
    this->XX += o.XX;
    this->YY += o.YY;
    this->XY += o.XY;
    this->N += o.N;
  }
  double Correlation() const
  {
    const double mx = this->X / this->N, my = this->Y / this->N;
    const double vx = this->XX / this->N - mx * mx, vy = this->YY / this->N - my * my;
    return vx > 0 && vy > 0 ? (this->XY / this->N - mx * my) / std::sqrt(vx * vy) : 0.0;
  }
};

/// A training frame minus its masked local mean (Gaussian of @p sigmaPixels), 0 outside the mask.
cv::Mat HighPass(const TrainingData& data, int frame, double sigmaPixels)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  cv::Mat image(data.Height, data.Width, CV_32F, const_cast<float*>(&data.Frames[pixels * frame]));
  cv::Mat mask;
  cv::Mat imaged = cv::Mat(data.Height, data.Width, CV_8U, const_cast<unsigned char*>(data.MaskOf(frame))) != 0;
  imaged.convertTo(mask, CV_32F, 1.0 / 255);
  cv::Mat masked = image.mul(mask), meanImage, meanMask;
  cv::GaussianBlur(masked, meanImage, cv::Size(0, 0), sigmaPixels, sigmaPixels, cv::BORDER_CONSTANT);
  cv::GaussianBlur(mask, meanMask, cv::Size(0, 0), sigmaPixels, sigmaPixels, cv::BORDER_CONSTANT);
  cv::Mat out = masked - meanImage / cv::max(meanMask, 1e-6f);
  return out.mul(mask);
}

struct FramePlane
{
  double F[3][3], Origin[3], PixelToPlane[3];
};
}

bool MeasureElevationDecorrelation(const TrainingData& data, const ElevationDecorrelationSettings& settings,
  ElevationDecorrelation& result, std::string* error)
{
  result = ElevationDecorrelation();
  std::vector<int> frames;
  for (int f : data.TrainFrames)
  {
    if (settings.Sweep < 0 || (f >= 0 && f < data.Count() && data.SweepOf(f) == settings.Sweep))
    {
      frames.push_back(f);
    }
  }
  std::sort(frames.begin(), frames.end());
  if (frames.size() < 2)
  {
    if (error)
    {
      *error = "the elevation decorrelation needs at least two training frames" +
        (settings.Sweep >= 0 ? " in sweep " + std::to_string(settings.Sweep) : std::string());
    }
    return false;
  }
  const std::size_t framePixels = std::size_t(data.Width) * data.Height;
  if (framePixels == 0 || data.Frames.size() != framePixels * data.Poses.size() ||
    (data.Mask.size() != framePixels && data.Mask.size() != framePixels * data.Poses.size()) || frames.front() < 0 ||
    frames.back() >= data.Count())
  {
    if (error)
    {
      *error = "frames, poses, mask and training frames of inconsistent sizes";
    }
    return false;
  }
  std::vector<FramePlane> planes(frames.size());
  double spacing = 0;
  for (std::size_t k = 0; k < frames.size(); ++k)
  {
    FramePlane& p = planes[k];
    if (ComputeRenderingFrame(data.Poses[frames[k]].data(), 90, p.F, p.Origin, p.PixelToPlane) != PoseStatus::Ok)
    {
      if (error)
      {
        *error = "training frame " + std::to_string(frames[k]) + ": ImageToReference is singular or not finite";
      }
      return false;
    }
    spacing += 0.5 * (p.PixelToPlane[0] + p.PixelToPlane[2]) / frames.size();
  }
  const int bins = std::max(1, static_cast<int>(std::ceil(settings.MaximumDistanceMm / settings.BinWidthMm)));
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const int gaps = std::max(1, settings.MaximumPairGap);
  std::vector<CorrelationSums> total(bins);
  std::vector<double> neighbourDistances;
  // By position in frames, over the window [a, a + gaps]: each frame high-passed, and its sampled fan pixels in the
  // reference frame (x, y, z, high-passed value).
  std::map<int, cv::Mat> highPassed;
  std::map<int, std::vector<double>> sampled;
  auto sample = [&](std::size_t k) {
    const unsigned char* mask = data.MaskOf(frames[k]);
    const long inFan = std::count_if(mask, mask + pixels, [](unsigned char v) { return v != 0; });
    const long stride = std::max<long>(1, inFan / std::max<long>(1, settings.PixelsPerFrame));
    std::vector<double> points;
    long seen = 0;
    const FramePlane& A = planes[k];
    const cv::Mat& hp = highPassed.at(static_cast<int>(k));
    for (std::size_t p = 0; p < pixels; ++p)
    {
      if (!mask[p] || seen++ % stride != 0)
      {
        continue;
      }
      const double i = double(p % data.Width), j = double(p / data.Width);
      const double x = i * A.PixelToPlane[0] + j * A.PixelToPlane[1], y = j * A.PixelToPlane[2];
      for (int c = 0; c < 3; ++c)
      {
        points.push_back(A.Origin[c] + x * A.F[0][c] + y * A.F[1][c]);
      }
      points.push_back(hp.at<float>(static_cast<int>(j), static_cast<int>(i)));
    }
    return points;
  };
  // Frame from's sampled pixels against frame to, bilinear there, into sums by distance.
  auto correlate = [&](std::size_t from, std::size_t to, std::vector<CorrelationSums>& sums) {
    const std::vector<double>& points = sampled.at(static_cast<int>(from));
    const FramePlane& B = planes[to];
    const cv::Mat& hpB = highPassed.at(static_cast<int>(to));
    const unsigned char* maskB = data.MaskOf(frames[to]);
    for (std::size_t k = 0; k + 3 < points.size(); k += 4)
    {
      double r[3] = { 0, 0, 0 };
      for (int row = 0; row < 3; ++row)
      {
        for (int c = 0; c < 3; ++c)
        {
          r[row] += B.F[row][c] * (points[k + c] - B.Origin[c]);
        }
      }
      const double d = std::abs(r[2]);
      const int bin = static_cast<int>(d / settings.BinWidthMm);
      const double j = r[1] / B.PixelToPlane[2];
      const double i = (r[0] - j * B.PixelToPlane[1]) / B.PixelToPlane[0];
      const int i0 = static_cast<int>(std::floor(i)), j0 = static_cast<int>(std::floor(j));
      if (bin >= bins || i0 < 0 || j0 < 0 || i0 + 1 >= data.Width || j0 + 1 >= data.Height)
      {
        continue;
      }
      const std::size_t q = std::size_t(j0) * data.Width + i0;
      if (!maskB[q] || !maskB[q + 1] || !maskB[q + data.Width] || !maskB[q + data.Width + 1])
      {
        continue;
      }
      const double fi = i - i0, fj = j - j0;
      const double value = (1 - fj) * ((1 - fi) * hpB.at<float>(j0, i0) + fi * hpB.at<float>(j0, i0 + 1)) +
        fj * ((1 - fi) * hpB.at<float>(j0 + 1, i0) + fi * hpB.at<float>(j0 + 1, i0 + 1));
      sums[bin].Add(points[k + 3], value);
    }
  };
  // The distance of frame from's sampled pixels to frame to's plane.
  auto distances = [&](std::size_t from, std::size_t to) {
    const std::vector<double>& points = sampled.at(static_cast<int>(from));
    const FramePlane& B = planes[to];
    for (std::size_t k = 0; k + 3 < points.size(); k += 4)
    {
      double z = 0;
      for (int c = 0; c < 3; ++c)
      {
        z += B.F[2][c] * (points[k + c] - B.Origin[c]);
      }
      neighbourDistances.push_back(std::abs(z));
    }
  };
  for (std::size_t a = 0; a + 1 < frames.size(); ++a)
  {
    // Pairs within one sweep (the training frames are in order, a sweep's frames one after the other).
    std::size_t last = std::min(frames.size() - 1, a + gaps);
    while (last > a && data.SweepOf(frames[last]) != data.SweepOf(frames[a]))
    {
      --last;
    }
    if (last == a)
    {
      continue;
    }
    highPassed.erase(highPassed.begin(), highPassed.lower_bound(static_cast<int>(a)));
    sampled.erase(sampled.begin(), sampled.lower_bound(static_cast<int>(a)));
    std::vector<std::size_t> missing;
    for (std::size_t b = a; b <= last; ++b)
    {
      if (!highPassed.count(static_cast<int>(b)))
      {
        missing.push_back(b);
        highPassed[static_cast<int>(b)];
        sampled[static_cast<int>(b)];
      }
    }
    vtkSMPTools::For(0, static_cast<vtkIdType>(missing.size()), [&](vtkIdType b0, vtkIdType b1) {
      for (vtkIdType m = b0; m < b1; ++m)
      {
        const std::size_t b = missing[m];
        highPassed.at(static_cast<int>(b)) = HighPass(data, frames[b], settings.HighPassMm / spacing);
        sampled.at(static_cast<int>(b)) = sample(b);
      }
    });
    // Each pair both ways (frame a's sampled pixels against frame b, and b's against a), so that the measurement
    // does not depend on which of the two comes first: a sweep recorded in the other direction measures the same.
    std::vector<std::vector<CorrelationSums>> perGap(last - a, std::vector<CorrelationSums>(bins));
    vtkSMPTools::For(0, static_cast<vtkIdType>(last - a), [&](vtkIdType g0, vtkIdType g1) {
      for (vtkIdType g = g0; g < g1; ++g)
      {
        correlate(a, a + 1 + g, perGap[g]);
        correlate(a + 1 + g, a, perGap[g]);
      }
    });
    for (const auto& gap : perGap)
    {
      for (int bin = 0; bin < bins; ++bin)
      {
        total[bin].Add(gap[bin]);
      }
    }
    // Distance between neighbouring frames' planes, at every sampled pixel of either.
    distances(a, a + 1);
    distances(a + 1, a);
  }
  if (!neighbourDistances.empty())
  {
    auto middle = neighbourDistances.begin() + neighbourDistances.size() / 2;
    std::nth_element(neighbourDistances.begin(), middle, neighbourDistances.end());
    result.NeighbourSpacing = *middle;
  }
  for (int bin = 0; bin < bins; ++bin)
  {
    if (total[bin].N >= 1000)
    {
      result.Distance.push_back((bin + 0.5) * settings.BinWidthMm);
      result.Correlation.push_back(total[bin].Correlation());
      result.Samples.push_back(total[bin].N);
    }
  }
  if (result.Distance.empty())
  {
    if (error)
    {
      *error = "no two training frames overlap within " + std::to_string(settings.MaximumDistanceMm) +
        " mm along the elevation axis";
    }
    return false;
  }
  FitElevationDecorrelation(result);
  return true;
}

void FitElevationDecorrelation(ElevationDecorrelation& result)
{
  result.DecorrelationSigma = 0;
  result.ZeroDistanceCorrelation = 0;
  if (result.Correlation.empty() || result.Samples.size() != result.Correlation.size() ||
    result.Distance.size() != result.Correlation.size())
  {
    return;
  }
  // Weighted least squares of ln rho on d^2, down to half the first bin's correlation.
  const double half = 0.5 * result.Correlation.front();
  double sw = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t k = 0; k < result.Distance.size() && result.Correlation[k] >= half; ++k)
  {
    const double w = static_cast<double>(result.Samples[k]);
    const double x = result.Distance[k] * result.Distance[k], y = std::log(result.Correlation[k]);
    sw += w;
    sx += w * x;
    sy += w * y;
    sxx += w * x * x;
    sxy += w * x * y;
  }
  const double denominator = sw * sxx - sx * sx;
  const double slope = denominator > 0 ? (sw * sxy - sx * sy) / denominator : 0.0;
  result.DecorrelationSigma = slope < 0 ? std::sqrt(-1.0 / (4 * slope)) : 0.0;
  const double rho0 = denominator > 0 ? std::exp((sy - slope * sx) / sw) : 0.0;
  result.ZeroDistanceCorrelation = std::isfinite(rho0) ? rho0 : 0.0; // a first bin at or below 0 fits nothing
}

std::vector<SweepDecorrelation> MeasureSweeps(const TrainingData& data)
{
  const int sweeps = data.SweepCount();
  std::vector<SweepDecorrelation> out(sweeps); // SweepCount is at least 1
  for (std::size_t s = 0; s < out.size(); ++s)
  {
    ElevationDecorrelationSettings settings;
    settings.Sweep = sweeps > 1 ? static_cast<int>(s) : -1;
    out[s].Measured = MeasureElevationDecorrelation(data, settings, out[s].Measurement, &out[s].Error);
  }
  return out;
}

ElevationSigmaChoice ChooseElevationSigma(const TrainingData& data)
{
  return ChooseElevationSigma(MeasureSweeps(data));
}

ElevationSigmaChoice ChooseElevationSigma(const std::vector<SweepDecorrelation>& sweeps)
{
  ElevationSigmaChoice choice;
  std::string sweepText;
  if (sweeps.size() > 1)
  {
    // Each sweep alone; the one whose frames lie closest decides (see the header).
    std::string error;
    for (std::size_t s = 0; s < sweeps.size(); ++s)
    {
      const SweepDecorrelation& d = sweeps[s];
      if (d.Measured && d.Measurement.NeighbourSpacing > 0 &&
        (sweepText.empty() || d.Measurement.NeighbourSpacing < choice.Measurement.NeighbourSpacing))
      {
        choice.Measurement = d.Measurement;
        sweepText = "sweep " + std::to_string(s) + " of " + std::to_string(sweeps.size()) +
          ", the one whose frames lie closest: ";
      }
      else if (sweepText.empty() && error.empty())
      {
        error = d.Error;
      }
    }
    if (sweepText.empty())
    {
      choice.Reason = "0.5 mm, the fixed default: no sweep can be measured (" + error + ")";
      return choice;
    }
  }
  else if (sweeps.empty() || !sweeps[0].Measured)
  {
    choice.Reason = "0.5 mm, the fixed default: " +
      (sweeps.empty() ? std::string("no training frames were measured") : sweeps[0].Error);
    return choice;
  }
  else
  {
    choice.Measurement = sweeps[0].Measurement;
  }
  const ElevationDecorrelation& m = choice.Measurement;
  char text[256];
  int bins = 0;
  while (bins < static_cast<int>(m.Correlation.size()) && m.Correlation[bins] >= 0.5 * m.Correlation.front())
  {
    ++bins;
  }
  const bool correlated = m.DecorrelationSigma > 0 && m.ZeroDistanceCorrelation >= 0.3 && bins >= 3;
  if (correlated)
  {
    choice.Sigma = ElevationSigmaDecorrelationFactor * m.DecorrelationSigma;
    std::snprintf(text, sizeof(text),
      "%.2g x the speckle decorrelation sigma %.3g mm of the training frames (correlation %.2f at 0 mm by its fit), "
      "%.3g mm apart (median)",
      ElevationSigmaDecorrelationFactor, m.DecorrelationSigma, m.ZeroDistanceCorrelation, m.NeighbourSpacing);
  }
  else
  {
    choice.Sigma = ElevationSigmaSpacingFactor * m.NeighbourSpacing;
    std::snprintf(text, sizeof(text),
      "%.2g x the median spacing %.3g mm of neighbouring training frames, whose speckle does not correlate "
      "across it (correlation %.2f at 0 mm by the fit, %d bins before the first halves)",
      ElevationSigmaSpacingFactor, m.NeighbourSpacing, m.ZeroDistanceCorrelation, bins);
  }
  choice.Reason = sweepText + text;
  if (!(choice.Sigma > 0))
  {
    choice.Sigma = 0.5;
    choice.Reason = "0.5 mm, the fixed default: the training frames lie in one plane";
  }
  return choice;
}

double CorrelationAtNeighbourSpacing(const ElevationDecorrelation& m)
{
  const std::vector<double>& d = m.Distance;
  if (d.empty())
  {
    return 0;
  }
  if (m.NeighbourSpacing <= d.front())
  {
    return m.Correlation.front();
  }
  for (std::size_t k = 1; k < d.size(); ++k)
  {
    if (m.NeighbourSpacing <= d[k])
    {
      const double t = (m.NeighbourSpacing - d[k - 1]) / (d[k] - d[k - 1]);
      return (1 - t) * m.Correlation[k - 1] + t * m.Correlation[k];
    }
  }
  return 0;
}

bool PoseRefinementChoice::Any() const
{
  return std::any_of(this->Sweeps.begin(), this->Sweeps.end(), [](char on) { return on != 0; });
}

PoseRefinementChoice ChoosePoseRefinement(const TrainingData& data)
{
  return ChoosePoseRefinement(MeasureSweeps(data));
}

PoseRefinementChoice ChoosePoseRefinement(const std::vector<SweepDecorrelation>& sweepMeasurements)
{
  PoseRefinementChoice choice;
  const std::size_t sweeps = sweepMeasurements.size();
  char text[256];
  for (std::size_t s = 0; s < sweeps; ++s)
  {
    const ElevationDecorrelation& m = sweepMeasurements[s].Measurement;
    const std::string& error = sweepMeasurements[s].Error;
    const bool measured = sweepMeasurements[s].Measured && m.NeighbourSpacing > 0;
    const double rho = measured ? CorrelationAtNeighbourSpacing(m) : -1;
    const bool refined = measured && rho >= PoseRefinementMinimumCorrelation;
    choice.Sweeps.push_back(refined ? 1 : 0);
    choice.Correlation.push_back(rho);
    choice.Spacing.push_back(measured ? m.NeighbourSpacing : 0);
    const std::string name = sweeps > 1 ? "sweep " + std::to_string(s) : std::string("the sweep");
    if (measured)
    {
      std::snprintf(text, sizeof(text),
        "%s %s: speckle correlation %.2f at its training frames' spacing %.3g mm %s %.2g", name.c_str(),
        refined ? "refined" : "trusted", rho, m.NeighbourSpacing, refined ? ">=" : "<",
        PoseRefinementMinimumCorrelation);
    }
    else
    {
      std::snprintf(text, sizeof(text), "%s trusted: its frames cannot be measured (%s)", name.c_str(), error.c_str());
    }
    choice.Reason += (s > 0 ? "; " : "") + std::string(text);
  }
  return choice;
}

double ElevationSigmaSetting(double given, const std::function<const std::vector<SweepDecorrelation>&()>& sweeps,
  bool& byRule, std::string& line, double& spacing)
{
  spacing = 0;
  byRule = !(given > 0); // 0, negative or NaN: the rule
  if (!byRule)
  {
    line = vtkfmt::sprintf("ElevationSigma = %.4g mm (given)", given);
    return given;
  }
  const ElevationSigmaChoice choice = ChooseElevationSigma(sweeps());
  line = vtkfmt::sprintf("ElevationSigma = %.4g mm (chosen: ", choice.Sigma) + choice.Reason + ")";
  spacing = choice.Measurement.NeighbourSpacing;
  return choice.Sigma;
}

} // namespace bigus
