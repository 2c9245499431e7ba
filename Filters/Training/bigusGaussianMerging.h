/**
 * @file bigusGaussianMerging.h
 * @brief The reduction of a trained field by merging neighbouring Gaussians that one Gaussian represents
 *        (issue 31, item 3): moment-matched pairs (A. R. Runnalls, "Kullback-Leibler approach to Gaussian
 *        mixture reduction", IEEE Trans. Aerospace and Electronic Systems 43(3), 2007) accepted by their
 *        integrated squared error (J. L. Williams and P. S. Maybeck, "Cost-function-based Gaussian mixture
 *        reduction for target tracking", Proc. FUSION 2003).
 *
 * The field is a sum of unnormalised 3D Gaussians g_i(x) = r_i exp(-1/2 (x - mu_i)^T Sigma_i^-1 (x - mu_i)),
 * Sigma_i = R(q_i) diag(s_i^2) R(q_i)^T (mm^2), and every slice renders a linear functional of that sum
 * (the beam integral, DESIGN section 3). A pair of the same sign is replaced by the Gaussian with the pair's
 * mass, centre of mass and second moment about it; the pair's error is the squared L2 distance in 3D between
 * the pair and its merge, relative to the pair's own squared norm, all in closed form:
 *
 *     <g_a, g_b> = r_a r_b (2 pi)^(3/2) sqrt(det Sigma_a det Sigma_b / det(Sigma_a + Sigma_b))
 *                  exp(-1/2 d^T (Sigma_a + Sigma_b)^-1 d),  d = mu_a - mu_b.
 */
#ifndef bigusGaussianMerging_h
#define bigusGaussianMerging_h

#include "bigusGaussianMath.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <cstdint>
#include <string>

namespace bigus
{

/// The merge of two Gaussians (MergeGaussianPair).
struct GaussianPairMerge
{
  /// The moment-matched Gaussian: with m_k = r_k sqrt(det Sigma_k) (its mass over (2 pi)^(3/2)) and
  /// M = m_a + m_b, mean mu = (m_a mu_a + m_b mu_b) / M, covariance sum_k m_k (Sigma_k + (mu_k - mu)(mu_k - mu)^T) / M,
  /// reflectivity M / sqrt(det Sigma); its scales the square roots of that covariance's eigenvalues (at least
  /// 1e-6 mm), its rotation (w, x, y, z) their eigenvectors.
  GaussianParams Merged{};
  /// ||g_a + g_b - g_merged||^2 / ||g_a + g_b||^2 over R^3 (0 for a pair of identical Gaussians); 1 when the pair
  /// cannot merge: reflectivities of opposite sign or zero, or a covariance that is not positive definite.
  double Error = 1;
};

/// Merges Gaussians @p a and @p b (GaussianPairMerge). Quaternions need not be normalised.
BIGUSTRAINING_EXPORT GaussianPairMerge MergeGaussianPair(const GaussianParams& a, const GaussianParams& b);

/// How MergeGaussians chooses its pairs.
struct GaussianMergeSettings
{
  /// The largest relative error (GaussianPairMerge::Error) of a merge; 0 merges nothing.
  double Tolerance = 0;
  int Neighbours = 8;    ///< candidates of each Gaussian: the Gaussians with the nearest means
  int MaximumPasses = 4; ///< passes over the field; each merges disjoint pairs, so a Gaussian merges once a pass
};

/// What MergeGaussians did.
struct GaussianMergeReport
{
  std::int64_t Before = 0; ///< Gaussians before
  std::int64_t Merged = 0; ///< pairs merged (the field lost as many Gaussians)
  int Passes = 0;
  double Seconds = 0;
};

/**
 * Merges pairs of neighbouring Gaussians of @p field while each pair's error stays below @p settings.Tolerance.
 * A pass finds each Gaussian's best partner among its Neighbours nearest means (vtkStaticPointLocator) and
 * merges the pairs in order of error, each Gaussian at most once (the merge takes the lower index, the order
 * of the field is kept otherwise); passes repeat while a pass merges at least 1 % of the field, up to
 * MaximumPasses. Deterministic. Errors accumulate over passes: a Gaussian merged in k passes may be off by
 * up to about k times the tolerance. Memory while it runs: about 140 bytes per Gaussian (its moments, its best
 * merge's error and partner) besides the locator's; its time on the README jobs' fields: docs/FINDINGS.md, "Merging".
 */
BIGUSTRAINING_EXPORT GaussianMergeReport MergeGaussians(GaussianField& field, const GaussianMergeSettings& settings);
/// The same on a training state's field: when any pair merged, every Gaussian starts with fresh optimiser moments and
/// accumulators, as after Trainer::SetField (a merged Gaussian is a new one).
BIGUSTRAINING_EXPORT GaussianMergeReport MergeGaussians(OptimizerState& G, const GaussianMergeSettings& settings);

/// One line for a report ("merged 1,234 pairs of 56,789 Gaussians in 2 passes (error below 0.01), 0.4 s").
BIGUSTRAINING_EXPORT std::string DescribeGaussianMerge(
  const GaussianMergeReport& report, const GaussianMergeSettings& settings);

/// The merge stage's `setting` line ("Merge = last, pairs whose merge errs by less than 0.001 ...", or off).
BIGUSTRAINING_EXPORT std::string DescribeGaussianMergeSettings(const GaussianMergeSettings& settings);

} // namespace bigus

#endif
