// Merging of neighbouring Gaussians (see bigusGaussianMerging.h).
#include "bigusGaussianMerging.h"

#include "vtkIdList.h"
#include "vtkNew.h"
#include "vtkPoints.h"
#include "vtkPolyData.h"
#include "vtkSMPThreadLocalObject.h"
#include "vtkSMPTools.h"
#include "vtkStaticPointLocator.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <tuple>
#include <vector>

namespace bigus
{
namespace
{
using Matrix3 = Eigen::Matrix3d;
using Vector3 = Eigen::Vector3d;

constexpr double MinimumScale = 1e-6;                           // mm: a merged covariance's degenerate axis
constexpr double MinimumVariance = MinimumScale * MinimumScale; // mm^2

/// A Gaussian as its reflectivity, mean and covariance (mm^2).
struct Moments
{
  double R = 0;
  Vector3 Mu;
  Matrix3 Sigma;
  double Det = 0;         ///< det Sigma
  double Self = 0;        ///< <g, g> / (2 pi)^(3/2) = R^2 sqrt(det Sigma / 8) (the header's formula, Sigma + Sigma)
  double MinVariance = 0; ///< Sigma's smallest eigenvalue
};

double SelfOverlap(double r, double det)
{
  return r * r * std::sqrt(det / 8);
}

Moments ToMoments(const GaussianParams& g)
{
  double q[4];
  NormalizeQuaternion(g.Quaternion, q);
  double R[3][3];
  QuaternionToMatrix(q, R);
  Matrix3 rotation;
  Vector3 variance;
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      rotation(i, j) = R[i][j];
    }
    variance(i) = std::exp(2 * g.LogScale[i]);
  }
  Moments m;
  m.R = g.Reflectivity;
  m.Mu = Vector3(g.Mean[0], g.Mean[1], g.Mean[2]);
  m.Sigma = rotation * variance.asDiagonal() * rotation.transpose();
  m.Det = variance.prod();
  m.Self = SelfOverlap(m.R, m.Det);
  m.MinVariance = variance.minCoeff();
  return m;
}

/// The principal axes of @p sigma (columns, a rotation) and its variances along them, at least MinimumVariance.
bool Decompose(const Matrix3& sigma, Vector3& variance, Matrix3& axes)
{
  const Eigen::SelfAdjointEigenSolver<Matrix3> eigen(sigma);
  if (eigen.info() != Eigen::Success)
  {
    return false;
  }
  variance = eigen.eigenvalues().cwiseMax(MinimumVariance);
  axes = eigen.eigenvectors();
  if (axes.determinant() < 0)
  {
    axes.col(2) = -axes.col(2);
  }
  return true;
}

/// <g_a, g_b> / (2 pi)^(3/2) (the header's formula); false when Sigma_a + Sigma_b is not positive definite.
bool Overlap(const Moments& a, const Moments& b, double& value)
{
  const Eigen::LLT<Matrix3> llt(a.Sigma + b.Sigma);
  if (llt.info() != Eigen::Success)
  {
    return false;
  }
  const Matrix3& L = llt.matrixL();
  const double det = std::pow(L(0, 0) * L(1, 1) * L(2, 2), 2);
  const Vector3 d = a.Mu - b.Mu;
  const double mahalanobis = d.dot(llt.solve(d));
  value = a.R * b.R * std::sqrt(a.Det * b.Det / det) * std::exp(-0.5 * mahalanobis);
  return std::isfinite(value);
}

/// The moment-matched merge of a pair and its error (GaussianPairMerge), before it becomes a GaussianParams.
struct MomentMerge
{
  bool Merged = false; ///< false: the pair cannot merge (GaussianPairMerge::Error 1)
  Moments M;           ///< the merged Gaussian as the field will hold it
  double Error = 1;    ///< GaussianPairMerge::Error
};

/**
 * The merge of @p a and @p b (GaussianPairMerge's formulas) from their moments. The merged covariance is at least
 * the mass-weighted mean of the pair's (the spread of the means adds to it), so its variances are at least the
 * pair's smallest: only where one of the pair has a variance near MinimumVariance can the clamp of MergedParams
 * change it, and only there is it decomposed here (elsewhere only the merges applied are, by MergedParams).
 */
MomentMerge MergeMoments(const Moments& a, const Moments& b)
{
  MomentMerge result;
  if (!(a.R * b.R > 0) || !(a.Det > 0) || !(b.Det > 0))
  {
    return result;
  }
  const double massA = a.R * std::sqrt(a.Det), massB = b.R * std::sqrt(b.Det), mass = massA + massB;
  const double wa = massA / mass, wb = massB / mass; // both positive: same sign
  Moments& m = result.M;
  m.Mu = wa * a.Mu + wb * b.Mu;
  const Vector3 da = a.Mu - m.Mu, db = b.Mu - m.Mu;
  m.Sigma = wa * (a.Sigma + da * da.transpose()) + wb * (b.Sigma + db * db.transpose());
  m.Sigma = 0.5 * (m.Sigma + m.Sigma.transpose());
  if (std::min(a.MinVariance, b.MinVariance) < 2 * MinimumVariance)
  {
    // The merged Gaussian as stored (its covariance rebuilt from the clamped scales), so that the error is that
    // of the Gaussian the field will hold.
    Vector3 variance;
    Matrix3 axes;
    if (!Decompose(m.Sigma, variance, axes))
    {
      return result;
    }
    m.Sigma = axes * variance.asDiagonal() * axes.transpose();
  }
  m.Det = m.Sigma.determinant();
  if (!(m.Det > 0))
  {
    return result;
  }
  m.R = mass / std::sqrt(m.Det);
  m.Self = SelfOverlap(m.R, m.Det);
  double ab, am, bm;
  if (!Overlap(a, b, ab) || !Overlap(a, m, am) || !Overlap(b, m, bm))
  {
    return result;
  }
  const double norm = a.Self + b.Self + 2 * ab;
  const double error = (norm + m.Self - 2 * am - 2 * bm) / norm;
  if (!(norm > 0) || !std::isfinite(error))
  {
    return result;
  }
  result.Merged = true;
  result.Error = std::max(error, 0.0);
  return result;
}

/// The merged Gaussian of @p merge as the field stores it (its scales and rotation from its covariance's principal
/// axes); false where that covariance cannot be decomposed.
bool MergedParams(const MomentMerge& merge, GaussianParams& g)
{
  Vector3 variance;
  Matrix3 axes;
  if (!merge.Merged || !Decompose(merge.M.Sigma, variance, axes))
  {
    return false;
  }
  for (int k = 0; k < 3; ++k)
  {
    g.Mean[k] = merge.M.Mu(k);
    g.LogScale[k] = 0.5 * std::log(variance(k));
  }
  const double u[3] = { axes(0, 0), axes(1, 0), axes(2, 0) };
  const double v[3] = { axes(0, 1), axes(1, 1), axes(2, 1) };
  const double n[3] = { axes(0, 2), axes(1, 2), axes(2, 2) };
  QuaternionFromAxes(u, v, n, g.Quaternion);
  g.Reflectivity = merge.M.R;
  return true;
}

/// The merge of Gaussians @p i and @p j of a field from their moments, in index order (so that both of a pair
/// compute the same bits).
MomentMerge MergeOf(const std::vector<Moments>& moments, std::int64_t i, std::int64_t j)
{
  return i < j ? MergeMoments(moments[i], moments[j]) : MergeMoments(moments[j], moments[i]);
}
}

GaussianPairMerge MergeGaussianPair(const GaussianParams& ga, const GaussianParams& gb)
{
  GaussianPairMerge result;
  const MomentMerge merge = MergeMoments(ToMoments(ga), ToMoments(gb));
  if (MergedParams(merge, result.Merged))
  {
    result.Error = merge.Error;
  }
  return result;
}

GaussianMergeReport MergeGaussians(GaussianField& field, const GaussianMergeSettings& settings)
{
  const auto start = std::chrono::steady_clock::now();
  GaussianMergeReport report;
  report.Before = field.Count();
  while (settings.Tolerance > 0 && report.Passes < settings.MaximumPasses && field.Count() > 1)
  {
    const std::int64_t n = field.Count();
    vtkNew<vtkPoints> points;
    points->SetDataTypeToDouble();
    points->SetNumberOfPoints(n);
    for (std::int64_t i = 0; i < n; ++i)
    {
      points->SetPoint(i, field.Means[3 * i], field.Means[3 * i + 1], field.Means[3 * i + 2]);
    }
    vtkNew<vtkPolyData> cloud;
    cloud->SetPoints(points);
    vtkNew<vtkStaticPointLocator> locator;
    locator->SetDataSet(cloud);
    locator->BuildLocator();
    // Every Gaussian's moments once a pass; each Gaussian's best partner among its nearest neighbours (both of a
    // pair find it: kept once, i < j). Only the error is kept: the merges applied are computed again below.
    std::vector<Moments> moments(n);
    vtkSMPTools::For(0, n, 4096, [&](std::int64_t begin, std::int64_t end) {
      for (std::int64_t i = begin; i < end; ++i)
      {
        moments[i] = ToMoments(LoadGaussian(
          field.Means.data(), field.LogScales.data(), field.Quaternions.data(), field.Reflectivities.data(), i));
      }
    });
    std::vector<std::int64_t> partner(n, -1);
    std::vector<double> bestError(n, 1.0);
    vtkSMPThreadLocalObject<vtkIdList> neighbours;
    const int wanted = static_cast<int>(std::min<std::int64_t>(settings.Neighbours + 1, n));
    vtkSMPTools::For(0, n, 1024, [&](std::int64_t begin, std::int64_t end) {
      vtkIdList* ids = neighbours.Local();
      for (std::int64_t i = begin; i < end; ++i)
      {
        const double mean[3] = { moments[i].Mu(0), moments[i].Mu(1), moments[i].Mu(2) };
        locator->FindClosestNPoints(wanted, mean, ids);
        for (vtkIdType k = 0; k < ids->GetNumberOfIds(); ++k)
        {
          const std::int64_t j = ids->GetId(k);
          if (j == i)
          {
            continue;
          }
          const MomentMerge merge = MergeOf(moments, i, j);
          if (merge.Merged && merge.Error < settings.Tolerance && merge.Error < bestError[i])
          {
            bestError[i] = merge.Error;
            partner[i] = j;
          }
        }
      }
    });
    std::vector<std::int64_t> order;
    for (std::int64_t i = 0; i < n; ++i)
    {
      if (partner[i] >= 0 && (i < partner[i] || partner[partner[i]] != i))
      {
        order.push_back(i);
      }
    }
    std::sort(order.begin(), order.end(),
      [&](std::int64_t a, std::int64_t b) { return std::tie(bestError[a], a) < std::tie(bestError[b], b); });
    std::vector<unsigned char> used(n, 0), keep(n, 1);
    std::int64_t merged = 0;
    for (std::int64_t i : order)
    {
      const std::int64_t j = partner[i];
      GaussianParams g{};
      if (used[i] || used[j] || !MergedParams(MergeOf(moments, i, j), g))
      {
        continue;
      }
      used[i] = used[j] = 1;
      const std::int64_t to = std::min(i, j);
      for (int k = 0; k < 3; ++k)
      {
        field.Means[3 * to + k] = static_cast<float>(g.Mean[k]);
        field.LogScales[3 * to + k] = static_cast<float>(g.LogScale[k]);
      }
      for (int k = 0; k < 4; ++k)
      {
        field.Quaternions[4 * to + k] = static_cast<float>(g.Quaternion[k]);
      }
      field.Reflectivities[to] = static_cast<float>(g.Reflectivity);
      keep[std::max(i, j)] = 0;
      ++merged;
    }
    if (merged > 0)
    {
      field.Compact(keep);
    }
    report.Merged += merged;
    ++report.Passes;
    if (merged < n / 100 + 1)
    {
      break;
    }
  }
  report.Seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

std::string DescribeGaussianMerge(const GaussianMergeReport& report, const GaussianMergeSettings& settings)
{
  char text[300];
  std::snprintf(text, sizeof(text),
    "%lld pairs merged of %lld Gaussians in %d passes (relative error of a merge below %.3g; %d neighbours), %.2f s",
    static_cast<long long>(report.Merged), static_cast<long long>(report.Before), report.Passes, settings.Tolerance,
    settings.Neighbours, report.Seconds);
  return text;
}

std::string DescribeGaussianMergeSettings(const GaussianMergeSettings& settings)
{
  if (settings.Tolerance <= 0)
  {
    return "Merge = off";
  }
  char text[300];
  std::snprintf(text, sizeof(text),
    "Merge = on (last, neighbouring pairs whose moment-matched merge has a relative error below %.3g; %d neighbours, "
    "at most %d passes)",
    settings.Tolerance, settings.Neighbours, settings.MaximumPasses);
  return text;
}

GaussianMergeReport MergeGaussians(OptimizerState& G, const GaussianMergeSettings& settings)
{
  const GaussianMergeReport report = MergeGaussians(G.Field, settings);
  if (report.Merged > 0)
  {
    GaussianField field = std::move(G.Field);
    G = OptimizerState();
    G.Field = std::move(field);
    G.ResizeToField();
  }
  return report;
}

} // namespace bigus
