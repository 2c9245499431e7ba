#include "bigusGapFilling.h"

#include "bigusGaussianMath.h"
#include "bigusSliceFrame.h"

#include <Eigen/Geometry>
#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <vector>

namespace bigus
{
namespace
{
/// A training frame's plane: rotation from plane coordinates (u, v_perp, n) to the reference frame,
/// the image centre (mm), and the pixel -> plane map for the in-image test.
struct Plane
{
  Eigen::Matrix3d R; ///< columns u, v_perp, n
  Eigen::Vector3d Origin, Centre;
  double PixelToPlane[3];
};

bool MakePlane(const std::array<double, 16>& pose, int width, int height, Plane& p)
{
  double F[3][3];
  if (ComputeRenderingFrame(pose.data(), 90, F, p.Origin.data(), p.PixelToPlane) != PoseStatus::Ok)
  {
    return false;
  }
  for (int r = 0; r < 3; ++r)
  {
    for (int c = 0; c < 3; ++c)
    {
      p.R(c, r) = F[r][c];
    }
  }
  const double i = 0.5 * (width - 1), j = 0.5 * (height - 1);
  for (int r = 0; r < 3; ++r)
  {
    p.Centre[r] = pose[4 * r] * i + pose[4 * r + 1] * j + pose[4 * r + 3];
  }
  return true;
}

/// True when @p x (plane coordinates, mm) projects inside the frame's pixel grid.
/// Copies of one Gaussian lie this many of its beam widths sqrt(v) apart across a gap: Gaussian bumps
/// 1.5 widths apart sum to a constant within 3e-4 (the ripple of the sum is 2 exp(-2 pi^2 / 1.5^2)).
constexpr double LatticeSpacing = 1.5;

bool InsideImage(const Plane& p, const Eigen::Vector3d& x, int width, int height)
{
  const double j = x[1] / p.PixelToPlane[2];
  const double i = (x[0] - j * p.PixelToPlane[1]) / p.PixelToPlane[0];
  return i >= -0.5 && i <= width - 0.5 && j >= -0.5 && j <= height - 0.5;
}

/**
 * FillElevationGaps on @p field, into @p out when not null (then @p out is @p field), or, with @p out null, only the
 * count of the copies every gap would take with no maximum, into @p needed (nothing is changed).
 */
GapFillingReport BridgeGaps(const GaussianField& field, GaussianField* out, const TrainingData& data,
  const std::vector<int>& trainFrames, double elevationSigma, const GapFillingSettings& settings, std::int64_t& needed)
{
  GapFillingReport report;
  needed = 0;
  std::vector<int> frames = trainFrames;
  std::sort(frames.begin(), frames.end());
  std::vector<Plane> planes(frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k)
  {
    if (!MakePlane(data.Poses[frames[k]], data.Width, data.Height, planes[k]))
    {
      return report; // Initialize rejects such poses; nothing to bridge from
    }
  }
  if (frames.size() < 3 || !(elevationSigma > 0) || !std::isfinite(elevationSigma))
  {
    return report;
  }
  // Distance between consecutive planes of one sweep: each centre's elevation in the other's plane,
  // averaged (-1 between the last frame of a sweep and the first of the next: no gap there).
  std::vector<double> spacing(frames.size() - 1);
  std::map<int, std::vector<double>> sweepSpacings; // by sweep
  for (std::size_t k = 0; k + 1 < frames.size(); ++k)
  {
    const Plane &a = planes[k], &b = planes[k + 1];
    spacing[k] = data.SweepOf(frames[k]) != data.SweepOf(frames[k + 1])
      ? -1
      : 0.5 * (std::abs(a.R.col(2).dot(b.Centre - a.Origin)) + std::abs(b.R.col(2).dot(a.Centre - b.Origin)));
    if (spacing[k] >= 0)
    {
      sweepSpacings[data.SweepOf(frames[k])].push_back(spacing[k]);
    }
  }
  if (sweepSpacings.empty())
  {
    return report;
  }
  // A gap is wide against its own sweep's median spacing: sweeps may be sampled at different densities.
  std::map<int, double> typical;
  for (auto& [sweep, sorted] : sweepSpacings)
  {
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    typical[sweep] = sorted[sorted.size() / 2];
  }
  report.TypicalSpacing = typical.begin()->second;
  std::vector<std::size_t> gaps;
  for (std::size_t k = 0; k + 1 < frames.size(); ++k)
  {
    const double sweepTypical = spacing[k] >= 0 ? typical.at(data.SweepOf(frames[k])) : 0.0;
    if (sweepTypical > 0 && spacing[k] > settings.MinimumGapSpacings * sweepTypical &&
      spacing[k] > 2 * std::max(LatticeSpacing, settings.ClearanceSigmas) * elevationSigma &&
      spacing[k] <= settings.MaximumGapMm)
    {
      gaps.push_back(k);
    }
  }
  if (gaps.empty())
  {
    return report;
  }
  const double sigma2 = elevationSigma * elevationSigma;
  const std::int64_t n = field.Count();
  // What the copies add at the plane they were taken from, relative to what their Gaussian renders there:
  // taken off its reflectivity at the end, so that the bracketing frames render as before.
  std::vector<double> added(n, 0.0);
  for (std::size_t k : gaps)
  {
    const Plane &a = planes[k], &b = planes[k + 1];
    const Eigen::Quaterniond qa(a.R), qb(b.R);
    const Eigen::Vector3d middleNormal = qa.slerp(0.5, qb).toRotationMatrix().col(2);
    // The copies of Gaussian i across the gap from side 0 (frame a) or 1 (frame b): returns how many
    // there are, appends them to the field when @p emit, and sets @p strength to |r_i| exp(-z_i^2 / 2v),
    // what the Gaussian renders at its peak on that frame.
    auto bridge = [&](std::int64_t i, int side, bool emit, double& strength) -> int {
      const Plane& from = side == 0 ? a : b;
      const Eigen::Vector3d mu(field.Means[3 * i], field.Means[3 * i + 1], field.Means[3 * i + 2]);
      Eigen::Vector3d local = from.R.transpose() * (mu - from.Centre);
      // Out of reach whatever its rotation (a cheap test first): v below is at most sigma_E^2 plus its largest
      // variance.
      double largest = -std::numeric_limits<double>::infinity();
      for (int c = 0; c < 3; ++c)
      {
        const double l = field.LogScales[3 * i + c];
        largest = std::max(largest, std::isfinite(l) ? std::clamp(l, MinimumLogScale, MaximumLogScale) : 0.0);
      }
      if (local[2] * local[2] > settings.ReachSigmas * settings.ReachSigmas * (sigma2 + std::exp(2 * largest)))
      {
        return 0;
      }
      const Eigen::Quaterniond q0 = Eigen::Quaterniond(field.Quaternions[4 * i], field.Quaternions[4 * i + 1],
        field.Quaternions[4 * i + 2], field.Quaternions[4 * i + 3])
                                      .normalized();
      // Its profile across the frame seen through the beam: exp(-(z - z_i)^2 / (2 v)), v = sigma_E^2 +
      // its variance along the normal (bigusGaussianMath.h: P2[z,z]).
      const Eigen::Matrix3d R0 = from.R.transpose() * q0.toRotationMatrix();
      double v = sigma2;
      for (int c = 0; c < 3; ++c)
      {
        const double l = field.LogScales[3 * i + c];
        const double sc = std::exp(std::isfinite(l) ? std::clamp(l, MinimumLogScale, MaximumLogScale) : 0.0);
        v += R0(2, c) * R0(2, c) * sc * sc;
      }
      const double width = std::sqrt(v), zi = local[2];
      if (!std::isfinite(width) || !std::isfinite(zi) || std::abs(zi) > settings.ReachSigmas * width)
      {
        return 0; // out of the frame's reach (or a non-finite mean or rotation)
      }
      // Taken onto the frame's plane with what it renders there: the copies carry the frame as the
      // field renders it, from every Gaussian that contributes to it.
      local[2] = 0;
      if (!InsideImage(from, from.R.transpose() * (from.Centre - from.Origin) + local, data.Width, data.Height))
      {
        return 0;
      }
      const double atPlane = std::exp(-zi * zi / (2 * v));
      strength = std::abs(double(field.Reflectivities[i])) * atPlane;
      // The gap's length where this Gaussian crosses it (the frames need not be parallel): from its
      // place relative to the first frame to its place relative to the second, along the normal.
      const double gap = std::abs(middleNormal.dot(b.Centre + b.R * local - a.Centre - a.R * local));
      const double h = LatticeSpacing * width;
      if (!std::isfinite(gap) || gap > 2 * settings.MaximumGapMm)
      {
        return 0;
      }
      // Copies every h = 1.5 sqrt(v) with weight h / sqrt(2 pi v) sum to the profile's peak wherever the
      // lattice reaches (a partition of unity by Gaussian bumps).
      const int count = static_cast<int>(std::floor(gap / h));
      const double scale = h / std::sqrt(2 * M_PI * v);
      const double margin = std::min(settings.BlendMarginSigmas * width, 0.25 * gap);
      int copies = 0;
      for (int j = 1; j <= count; ++j)
      {
        const double z = j * h; // from its own frame, towards the other
        const double t = side == 0 ? z / gap : 1 - z / gap;
        // The share of its own frame: 1 within the margin of it, 0 within the margin of the other.
        const double own = 1 - std::clamp((z - margin) / (gap - 2 * margin), 0.0, 1.0);
        if (own <= 0 || z < settings.ClearanceSigmas * width || gap - z < settings.ClearanceSigmas * width)
        {
          continue;
        }
        ++copies;
        if (!emit)
        {
          continue;
        }
        const Eigen::Quaterniond qt = qa.slerp(t, qb);
        const Eigen::Vector3d copy = (1 - t) * a.Centre + t * b.Centre + qt.toRotationMatrix() * local;
        const Eigen::Quaterniond q = qt * (side == 0 ? qa : qb).conjugate() * q0;
        const std::int64_t c = out->Count();
        out->Resize(c + 1);
        out->CopyGaussian(i, c);
        for (int e = 0; e < 3; ++e)
        {
          out->Means[3 * c + e] = static_cast<float>(copy[e]);
        }
        out->Quaternions[4 * c] = static_cast<float>(q.w());
        out->Quaternions[4 * c + 1] = static_cast<float>(q.x());
        out->Quaternions[4 * c + 2] = static_cast<float>(q.y());
        out->Quaternions[4 * c + 3] = static_cast<float>(q.z());
        const double weight = own * scale;
        out->Reflectivities[c] = static_cast<float>(weight * atPlane * out->Reflectivities[i]);
        // At the plane the Gaussian renders r exp(-z_i^2 / 2v) and this copy r weight exp(-z_i^2 / 2v)
        // exp(-z^2 / 2v): relative to the Gaussian, weight exp(-z^2 / 2v), whatever z_i.
        added[i] += weight * std::exp(-z * z / (2 * v));
      }
      return copies;
    };
    // Which Gaussians are copied: all of them, or, when their copies would take the field past
    // MaximumGaussians, the strongest on either frame (by what they render there) whose copies fit.
    struct Candidate
    {
      std::int64_t Gaussian;
      int Side, Copies;
      double Strength;
    };
    std::vector<Candidate> candidates;
    std::int64_t total = 0;
    for (int side = 0; side < 2; ++side)
    {
      for (std::int64_t i = 0; i < n; ++i)
      {
        double strength = 0;
        const int copies = bridge(i, side, false, strength);
        if (copies > 0)
        {
          candidates.push_back({ i, side, copies, strength });
          total += copies;
        }
      }
    }
    needed += total;
    if (candidates.empty() || !out)
    {
      continue;
    }
    const std::int64_t room = settings.MaximumGaussians > 0 ? settings.MaximumGaussians - out->Count() : total;
    if (total > room)
    {
      std::stable_sort(candidates.begin(), candidates.end(),
        [](const Candidate& x, const Candidate& y) { return x.Strength > y.Strength; });
      std::int64_t kept = 0;
      std::vector<Candidate> fitting;
      for (const Candidate& c : candidates)
      {
        if (kept + c.Copies <= room)
        {
          kept += c.Copies;
          fitting.push_back(c);
        }
      }
      report.LeftOut += static_cast<std::int64_t>(candidates.size() - fitting.size());
      candidates.swap(fitting);
      // In the order of the unthinned field, so that a fill with room for everything is the same field.
      std::sort(candidates.begin(), candidates.end(), [](const Candidate& x, const Candidate& y) {
        return x.Side != y.Side ? x.Side < y.Side : x.Gaussian < y.Gaussian;
      });
      if (candidates.empty())
      {
        report.Skipped += 1;
        continue;
      }
      report.Thinned += 1;
    }
    const std::int64_t before = out->Count();
    for (const Candidate& c : candidates)
    {
      double strength = 0;
      bridge(c.Gaussian, c.Side, true, strength);
    }
    report.Gaps += 1;
    report.WidestGap = std::max(report.WidestGap, spacing[k]);
    report.Added += out->Count() - before;
  }
  for (std::int64_t i = 0; out && i < n; ++i)
  {
    out->Reflectivities[i] = static_cast<float>(out->Reflectivities[i] * std::max(0.0, 1 - added[i]));
  }
  return report;
}
}

GapFillingReport FillElevationGaps(
  GaussianField& field, const TrainingData& data, double elevationSigma, const GapFillingSettings& settings)
{
  std::int64_t needed = 0;
  return BridgeGaps(field, &field, data, data.TrainFrames, elevationSigma, settings, needed);
}

std::int64_t CountGapCopies(const GaussianField& field, const TrainingData& data, double elevationSigma,
  const GapFillingSettings& settings, const std::vector<int>* trainFrames)
{
  std::int64_t needed = 0;
  BridgeGaps(field, nullptr, data, trainFrames ? *trainFrames : data.TrainFrames, elevationSigma, settings, needed);
  return needed;
}

std::string DescribeGapFilling(const GapFillingReport& report, const GapFillingSettings& settings)
{
  char text[400];
  std::snprintf(text, sizeof(text),
    "%d gaps bridged (widest %.2f mm; typical spacing %.3f mm), %lld Gaussians added (a gap: over %.3g typical "
    "spacings; clearance %.3g beam widths; blend margin %.3g beam widths)",
    report.Gaps, report.WidestGap, report.TypicalSpacing, static_cast<long long>(report.Added),
    settings.MinimumGapSpacings, settings.ClearanceSigmas, settings.BlendMarginSigmas);
  std::string line = text;
  if (report.Thinned > 0)
  {
    std::snprintf(text, sizeof(text),
      "; %d gaps thinned: the copies of the %lld weakest Gaussians left out to stay within the maximum of %lld "
      "Gaussians",
      report.Thinned, static_cast<long long>(report.LeftOut), static_cast<long long>(settings.MaximumGaussians));
    line += text;
  }
  if (report.Skipped > 0)
  {
    std::snprintf(text, sizeof(text), "; %d gaps left empty: the field already holds the maximum of %lld Gaussians",
      report.Skipped, static_cast<long long>(settings.MaximumGaussians));
    line += text;
  }
  return line;
}

std::string DescribeGapFillingSettings(bool fill, bool beamIntegration, const GapFillingSettings& s)
{
  if (!fill)
  {
    return "FillGaps = off";
  }
  if (!beamIntegration)
  {
    return "FillGaps = off (BeamIntegration is off: the thin plane has no beam to bridge gaps with)";
  }
  return vtkfmt::sprintf("FillGaps = on (after training, gaps between training frames over %.3g typical spacings are "
                         "bridged by blended copies of the frames on either side as rendered, %.3g beam widths clear "
                         "of them, each frame alone within %.3g beam widths of it)",
    s.MinimumGapSpacings, s.ClearanceSigmas, s.BlendMarginSigmas);
}

} // namespace bigus
