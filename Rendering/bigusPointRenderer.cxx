// The beam-integrated field at scattered points (bigusPointRenderer.h): the Gaussians binned into a regular grid of
// cells over the samples, each sample summing the footprints of its cell's Gaussians on its own plane.
#include "bigusPointRenderer.h"

#include "bigusGaussianMath.h"
#include "bigusRasterGeometry.h"
#include "bigusSliceFrame.h"

#include "vtkSMPTools.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace bigus
{
namespace
{
/// The rendering frame of @p sample (origin at its position) with the low-pass of @p variance on its pixel axes;
/// false when the axes are zero or parallel.
bool SampleFrame(const PointSample& sample, double variance, SliceFrameD& frame)
{
  const double* a = sample.PixelAxes[0];
  const double* b = sample.PixelAxes[1];
  const double* x = sample.Position;
  const double m[16] = { a[0], b[0], 0, x[0], a[1], b[1], 0, x[1], a[2], b[2], 0, x[2], 0, 0, 0, 1 };
  double pixelToPlane[3];
  if (ComputeRenderingFrame(m, 90.0, frame.F, frame.Origin, pixelToPlane) != PoseStatus::Ok)
  {
    return false;
  }
  PixelLowPassCovariance(pixelToPlane, variance, frame.LowPass);
  return true;
}

/// The Gaussians of a field in a regular grid of cells (compressed rows: cell c holds Entries[Start[c] ..
/// Start[c + 1])), each in every cell its reach touches; Everywhere holds those whose reach spans too many cells.
struct CellGrid
{
  double Lo[3] = { 0, 0, 0 };
  double Cell = 1;
  int Dims[3] = { 1, 1, 1 };
  std::vector<std::int64_t> Start;
  std::vector<std::int64_t> Entries;
  std::vector<std::int64_t> Everywhere;
  std::vector<double> Reach; ///< [N] mm; a Gaussian further than this from a sample adds nothing to it

  std::int64_t CellOf(const double x[3]) const
  {
    std::int64_t index = 0;
    for (int k = 2; k >= 0; --k)
    {
      const double t = std::floor((x[k] - this->Lo[k]) / this->Cell);
      const int i = t < 0 ? 0 : (t > this->Dims[k] - 1 ? this->Dims[k] - 1 : static_cast<int>(t));
      index = index * this->Dims[k] + i;
    }
    return index;
  }
};

void BuildGrid(const FieldView& field, const PointSample* samples, std::int64_t count, double lowPassVariance,
  const RenderOptions& options, CellGrid& grid)
{
  double lo[3], hi[3];
  for (int k = 0; k < 3; ++k)
  {
    lo[k] = hi[k] = samples[0].Position[k];
  }
  for (std::int64_t s = 1; s < count; ++s)
  {
    for (int k = 0; k < 3; ++k)
    {
      lo[k] = std::min(lo[k], samples[s].Position[k]);
      hi[k] = std::max(hi[k], samples[s].Position[k]);
    }
  }
  // The footprint keeps the points within Cutoff of the mean in the Mahalanobis distance of the Gaussian convolved
  // with the beam and the low-pass, whose largest variance is at most s_max^2 + sigma_E^2 + the low-pass's.
  const double sigmaE = EffectiveElevationSigma(options);
  const double k = options.Cutoff;
  grid.Reach.assign(field.Count, -1.0);
  std::vector<double> reaches;
  for (std::int64_t g = 0; g < field.Count; ++g)
  {
    double largest = MinimumLogScale;
    for (int a = 0; a < 3; ++a)
    {
      const double l = field.LogScales[3 * g + a];
      largest = std::max(largest, l == l ? std::min(l, MaximumLogScale) : 0.0);
    }
    const double s = std::exp(largest);
    const double reach = 1.001 * k * std::sqrt(s * s + sigmaE * sigmaE + lowPassVariance) + 1e-9;
    bool touches = true;
    for (int a = 0; a < 3; ++a)
    {
      const double m = field.Means[3 * g + a];
      touches = touches && m + reach >= lo[a] && m - reach <= hi[a];
    }
    if (touches)
    {
      grid.Reach[g] = reach;
      reaches.push_back(reach);
    }
  }
  double cell = 1;
  if (!reaches.empty())
  {
    std::nth_element(reaches.begin(), reaches.begin() + reaches.size() / 2, reaches.end());
    cell = reaches[reaches.size() / 2];
  }
  // At most a million cells.
  double cells = 1;
  for (int a = 0; a < 3; ++a)
  {
    cells *= std::floor((hi[a] - lo[a]) / cell) + 1;
  }
  if (cells > 1e6)
  {
    cell *= std::cbrt(cells / 1e6) * 1.01;
  }
  std::copy(lo, lo + 3, grid.Lo);
  grid.Cell = cell;
  std::int64_t total = 1;
  for (int a = 0; a < 3; ++a)
  {
    grid.Dims[a] = static_cast<int>(std::floor((hi[a] - lo[a]) / cell)) + 1;
    total *= grid.Dims[a];
  }
  // Two passes over the Gaussians: count each cell's entries, then fill them in Gaussian order.
  auto cellRange = [&](std::int64_t g, int first[3], int last[3]) {
    std::int64_t n = 1;
    for (int a = 0; a < 3; ++a)
    {
      const double m = field.Means[3 * g + a], r = grid.Reach[g];
      first[a] = static_cast<int>(std::max(0.0, std::floor((m - r - lo[a]) / cell)));
      last[a] = static_cast<int>(std::min(grid.Dims[a] - 1.0, std::floor((m + r - lo[a]) / cell)));
      n *= std::max(0, last[a] - first[a] + 1);
    }
    return n;
  };
  const std::int64_t largest = 512; // cells; a Gaussian reaching more is checked by every sample
  grid.Start.assign(total + 1, 0);
  for (std::int64_t g = 0; g < field.Count; ++g)
  {
    int first[3], last[3];
    if (grid.Reach[g] < 0)
    {
      continue;
    }
    const std::int64_t n = cellRange(g, first, last);
    if (n > largest)
    {
      grid.Everywhere.push_back(g);
      continue;
    }
    for (int z = first[2]; z <= last[2]; ++z)
    {
      for (int y = first[1]; y <= last[1]; ++y)
      {
        for (int x = first[0]; x <= last[0]; ++x)
        {
          ++grid.Start[(std::int64_t(z) * grid.Dims[1] + y) * grid.Dims[0] + x + 1];
        }
      }
    }
  }
  for (std::int64_t c = 0; c < total; ++c)
  {
    grid.Start[c + 1] += grid.Start[c];
  }
  grid.Entries.resize(grid.Start[total]);
  std::vector<std::int64_t> next(grid.Start.begin(), grid.Start.end() - 1);
  for (std::int64_t g = 0; g < field.Count; ++g)
  {
    int first[3], last[3];
    if (grid.Reach[g] < 0 || cellRange(g, first, last) > largest)
    {
      continue;
    }
    for (int z = first[2]; z <= last[2]; ++z)
    {
      for (int y = first[1]; y <= last[1]; ++y)
      {
        for (int x = first[0]; x <= last[0]; ++x)
        {
          grid.Entries[next[(std::int64_t(z) * grid.Dims[1] + y) * grid.Dims[0] + x]++] = g;
        }
      }
    }
  }
}
}

bool RenderPoints(const FieldView& field, const PointSample* samples, std::int64_t count, double pixelLowPass,
  const RenderOptions& options, float* S, float* I, std::string* error)
{
  if (!(pixelLowPass >= 0) || !(pixelLowPass < 1e6))
  {
    if (error)
    {
      *error = "PixelLowPass " + std::to_string(pixelLowPass) + " is not a variance between 0 and 1e6 pixels^2";
    }
    return false;
  }
  double lowPassVariance = 0; // mm^2: the largest low-pass variance of any sample
  for (std::int64_t s = 0; s < count; ++s)
  {
    SliceFrameD frame;
    if (!SampleFrame(samples[s], pixelLowPass, frame))
    {
      if (error)
      {
        *error = "sample " + std::to_string(s) +
          ": its pixel axes are zero, parallel or not finite (a transform that folds the grid there)";
      }
      return false;
    }
    lowPassVariance = std::max(lowPassVariance, frame.LowPass[0] + frame.LowPass[2]);
  }
  if (count <= 0)
  {
    return true;
  }
  CellGrid grid;
  BuildGrid(field, samples, count, lowPassVariance, options, grid);
  const double sigmaE = EffectiveElevationSigma(options);
  const double gamma = options.Gamma;
  vtkSMPTools::For(0, count, 256, [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t s = begin; s < end; ++s)
    {
      const PointSample& sample = samples[s];
      SliceFrameD frame;
      SampleFrame(sample, pixelLowPass, frame);
      double sum = 0;
      auto add = [&](std::int64_t g) {
        const double* x = sample.Position;
        const float* m = field.Means + 3 * g;
        const double d2 = (m[0] - x[0]) * (m[0] - x[0]) + (m[1] - x[1]) * (m[1] - x[1]) + (m[2] - x[2]) * (m[2] - x[2]);
        if (d2 > grid.Reach[g] * grid.Reach[g])
        {
          return;
        }
        const GaussianParams p = LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, g);
        const Footprint f = SetupFootprint(p, frame, sigmaE, options.Cutoff, nullptr);
        if (!f.Visible)
        {
          return;
        }
        const double form = AxesForm(f.Axes[0], f.Axes[1], f.Axes[2], f.Axes[3], -f.Center[0], -f.Center[1]);
        if (form <= f.CutoffSquared)
        {
          sum += EffectiveReflectivity(p.Reflectivity, options.NonNegativeReflectivity) * f.Amplitude *
            std::exp(-0.5 * form);
        }
      };
      const std::int64_t c = grid.CellOf(sample.Position);
      for (std::int64_t e = grid.Start[c]; e < grid.Start[c + 1]; ++e)
      {
        add(grid.Entries[e]);
      }
      for (std::int64_t g : grid.Everywhere)
      {
        add(g);
      }
      S[s] = static_cast<float>(sum);
      if (I)
      {
        I[s] = static_cast<float>(ImageFromScattering(sum, gamma));
      }
    }
  });
  return true;
}

} // namespace bigus
