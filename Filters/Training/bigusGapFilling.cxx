#include "bigusGapFilling.h"

#include "bigusSliceFrame.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
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
bool InsideImage(const Plane& p, const Eigen::Vector3d& x, int width, int height)
{
  const double j = x[1] / p.PixelToPlane[2];
  const double i = (x[0] - j * p.PixelToPlane[1]) / p.PixelToPlane[0];
  return i >= -0.5 && i <= width - 0.5 && j >= -0.5 && j <= height - 0.5;
}
}

GapFillingReport FillElevationGaps(
  GaussianField& field, const TrainingData& data, double elevationSigma, const GapFillingSettings& settings)
{
  GapFillingReport report;
  std::vector<int> frames = data.TrainFrames;
  std::sort(frames.begin(), frames.end());
  std::vector<Plane> planes(frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k)
  {
    if (!MakePlane(data.Poses[frames[k]], data.Width, data.Height, planes[k]))
    {
      return report; // Initialize rejects such poses; nothing to bridge from
    }
  }
  if (frames.size() < 3)
  {
    return report;
  }
  // Distance between consecutive planes: each centre's elevation in the other's plane, averaged.
  std::vector<double> spacing(frames.size() - 1);
  for (std::size_t k = 0; k + 1 < frames.size(); ++k)
  {
    const Plane &a = planes[k], &b = planes[k + 1];
    spacing[k] = 0.5 * (std::abs(a.R.col(2).dot(b.Centre - a.Origin)) + std::abs(b.R.col(2).dot(a.Centre - b.Origin)));
  }
  std::vector<double> sorted = spacing;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  report.TypicalSpacing = sorted[sorted.size() / 2];
  std::vector<std::size_t> gaps;
  for (std::size_t k = 0; k + 1 < frames.size(); ++k)
  {
    if (spacing[k] > settings.MinimumGapSpacings * report.TypicalSpacing &&
      spacing[k] > 2 * settings.ClearanceSigmas * elevationSigma)
    {
      gaps.push_back(k);
    }
  }
  if (gaps.empty() || report.TypicalSpacing <= 0)
  {
    return report;
  }
  // Each Gaussian's nearest training plane, where its mean projects inside that frame.
  const std::int64_t n = field.Count();
  std::vector<int> owner(n, -1);
  for (std::int64_t i = 0; i < n; ++i)
  {
    const Eigen::Vector3d mu(field.Means[3 * i], field.Means[3 * i + 1], field.Means[3 * i + 2]);
    double nearest = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < planes.size(); ++k)
    {
      const double z = std::abs(planes[k].R.col(2).dot(mu - planes[k].Origin));
      if (z < nearest)
      {
        nearest = z;
        owner[i] = static_cast<int>(k);
      }
    }
    const Plane& p = planes[owner[i]];
    if (!InsideImage(p, p.R.transpose() * (mu - p.Origin), data.Width, data.Height))
    {
      owner[i] = -1;
    }
  }
  const double sigma2 = elevationSigma * elevationSigma;
  const double clearance2 = settings.ClearanceSigmas * settings.ClearanceSigmas;
  for (std::size_t k : gaps)
  {
    const Plane &a = planes[k], &b = planes[k + 1];
    const Eigen::Quaterniond qa(a.R), qb(b.R);
    const int steps = std::max(2, static_cast<int>(std::lround(spacing[k] / report.TypicalSpacing)));
    std::int64_t added = 0;
    for (int s = 1; s < steps; ++s)
    {
      const double t = double(s) / steps;
      const Eigen::Quaterniond qt = qa.slerp(t, qb);
      const Eigen::Matrix3d Rt = qt.toRotationMatrix();
      const Eigen::Vector3d ct = (1 - t) * a.Centre + t * b.Centre;
      for (int side = 0; side < 2; ++side)
      {
        const Plane& from = side == 0 ? a : b;
        const int fromIndex = static_cast<int>(side == 0 ? k : k + 1);
        const double weight = side == 0 ? 1 - t : t;
        const Eigen::Quaterniond turn = qt * (side == 0 ? qa : qb).conjugate();
        for (std::int64_t i = 0; i < n; ++i)
        {
          if (owner[i] != fromIndex)
          {
            continue;
          }
          const Eigen::Vector3d mu(field.Means[3 * i], field.Means[3 * i + 1], field.Means[3 * i + 2]);
          const Eigen::Vector3d copy = ct + Rt * (from.R.transpose() * (mu - from.Centre));
          Eigen::Quaterniond q(field.Quaternions[4 * i], field.Quaternions[4 * i + 1], field.Quaternions[4 * i + 2],
            field.Quaternions[4 * i + 3]);
          q = turn * q.normalized();
          // The copy's variance along each bracketing normal: sum_k (n . R(q) e_k)^2 s_k^2.
          const Eigen::Matrix3d Rq = q.toRotationMatrix();
          bool clear = true;
          for (const Plane* p : { &a, &b })
          {
            double variance = sigma2;
            for (int c = 0; c < 3; ++c)
            {
              const double s = std::exp(double(field.LogScales[3 * i + c]));
              const double along = p->R.col(2).dot(Rq.col(c));
              variance += along * along * s * s;
            }
            const double z = p->R.col(2).dot(copy - p->Origin);
            clear = clear && z * z >= clearance2 * variance;
          }
          if (!clear)
          {
            continue;
          }
          const std::int64_t j = field.Count();
          field.Resize(j + 1);
          field.CopyGaussian(i, j);
          for (int c = 0; c < 3; ++c)
          {
            field.Means[3 * j + c] = static_cast<float>(copy[c]);
          }
          field.Quaternions[4 * j] = static_cast<float>(q.w());
          field.Quaternions[4 * j + 1] = static_cast<float>(q.x());
          field.Quaternions[4 * j + 2] = static_cast<float>(q.y());
          field.Quaternions[4 * j + 3] = static_cast<float>(q.z());
          field.Reflectivities[j] = static_cast<float>(weight * field.Reflectivities[i]);
          ++added;
        }
      }
    }
    if (added > 0)
    {
      report.Gaps += 1;
      report.WidestGap = std::max(report.WidestGap, spacing[k]);
      report.Added += added;
    }
  }
  return report;
}

} // namespace bigus
