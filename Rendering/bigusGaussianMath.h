/**
 * @file bigusGaussianMath.h
 * @brief Every per-Gaussian and per-pixel formula of the beam-integrated renderer, with its gradient
 *        twin. Plain structs, no Eigen, no VTK: included by the CPU backend and the CUDA backend, so
 *        the CPU tests check the arithmetic that the GPU runs.
 *
 * The model (DESIGN section 3; BIGUS paper Eq. 8-11). A Gaussian with mean mu (mm), log-scales l
 * (standard deviations s = exp(l), mm) and quaternion q (w, x, y, z, normalised on use) is moved into
 * the orthonormal frame of a slice (rows u, v, n of F; origin o):
 *
 *     m = F (mu - o)            R' = F R(q)            M = R' diag(s)        P = M M^T
 *
 * The elevation beam is a unit-area Gaussian of standard deviation sigma_E across the plane. Its
 * integral with the 3D Gaussian is a 2D Gaussian in the in-plane position p (mm):
 *
 *     P2    = P + sigma_E^2 e_z e_z^T
 *     cov2  = P2[xy,xy] - P2[xy,z] P2[xy,z]^T / P2[z,z]   (conditional covariance; conic = cov2^-1)
 *     delta = -m_z P2[xy,z] / P2[z,z]                       (parallax shift of the in-plane peak)
 *     amp   = exp(-m_z^2 / (2 P2[z,z])) / sqrt(1 + sigma_E^2 Lambda_zz),  Lambda = P^-1
 *     w(p)  = amp exp(-1/2 (p - c)^T conic (p - c)),  c = m_xy + delta
 *
 * Image formation: S(p) = sum_i r_i w_i(p);  I(p) = 1 - exp(-gamma max(S, 0)).
 *
 * Numerics. The setup (phase 1) runs in double: cov2 is formed as B B^T, with B the in-plane rows of
 * [M | sigma_E e_z] projected orthogonally to its elevation row, and det(cov2) by the Cauchy-Binet sum
 * of squared 2x2 minors, so that a needle or pancake Gaussian (scale ratios up to 1e4) loses no digits
 * to cancellation. Lambda_zz = sum_k R'_zk^2 / s_k^2 comes from the scales; no near-singular matrix is
 * ever inverted. The slice origin is subtracted before anything else, so a slice 1 m from the origin
 * costs no precision. Phase 2 (per pixel) evaluates the 2D Gaussian relative to its own centre.
 */
#ifndef bigusGaussianMath_h
#define bigusGaussianMath_h

#include <cmath>
#include <cstdint>
#include <cstring>

#if defined(__CUDACC__)
#define BIGUS_HD __host__ __device__ __forceinline__
#else
#define BIGUS_HD inline
#endif

namespace bigus
{

/// Limits on the log-scale (ln mm) applied on use: exp(-25) = 1.4e-11 mm .. exp(25) = 7.2e10 mm.
/// Outside, the scale is held at the limit and its gradient is zero, so no overflow reaches the maths.
constexpr double MinimumLogScale = -25.0;
constexpr double MaximumLogScale = 25.0;
/// Largest in-plane aspect ratio (major / minor standard deviation) of a footprint; see SetupFootprint.
constexpr double MaximumFootprintAspect = 1e4;
/// A quaternion with squared norm below this is taken as the identity rotation (zero gradient).
constexpr double MinimumQuaternionNorm2 = 1e-30;

struct Vec3
{
  double x, y, z;
};

struct Mat3
{
  double m[3][3];
};

/// Slice frame: rows u, v, n of F, origin o (mm). Pixel (i, j) lies at p = (i su, j sv) in the plane.
struct SliceFrameD
{
  double F[3][3];
  double Origin[3];
  /// In-plane covariance L (xx, xy, yy; mm^2, along u and v) of a Gaussian low-pass that every footprint is
  /// convolved with before it is sampled (SliceGeometry::PixelLowPass, PixelLowPassCovariance); 0: point samples.
  double LowPass[3] = { 0, 0, 0 };
};

/// One Gaussian's parameters (double, for the setup).
struct GaussianParams
{
  double Mean[3];
  double LogScale[3];
  double Quaternion[4]; ///< w, x, y, z; need not be normalised
  double Reflectivity;
};

/**
 * Gaussian @p i of a field held as structure of arrays (float or double): @p means [N, 3] mm (reference
 * frame), @p logScales [N, 3] ln mm, @p quaternions [N, 4] w, x, y, z, @p reflectivities [N] signed.
 */
template <typename T>
BIGUS_HD GaussianParams LoadGaussian(
  const T* means, const T* logScales, const T* quaternions, const T* reflectivities, std::int64_t i)
{
  GaussianParams g;
  for (int k = 0; k < 3; ++k)
  {
    g.Mean[k] = means[3 * i + k];
    g.LogScale[k] = logScales[3 * i + k];
  }
  for (int k = 0; k < 4; ++k)
  {
    g.Quaternion[k] = quaternions[4 * i + k];
  }
  g.Reflectivity = reflectivities[i];
  return g;
}

/// Result of phase 1 for one Gaussian and one slice: the 2D footprint.
struct Footprint
{
  double Center[2];     ///< c = m_xy + delta, mm in the slice plane
  double Conic[3];      ///< inverse of cov2: a, b, c of q = a dx^2 + 2 b dx dy + c dy^2 (1/mm^2)
  double Axes[4];       ///< cos, sin of the major axis; 1/sigma along the major and minor axes (1/mm):
                        ///< q = ((cos dx + sin dy) / s1)^2 + ((cos dy - sin dx) / s2)^2, never negative
  double Cov[3];        ///< cov2 (+ the slice's LowPass): xx, xy, yy (mm^2), for the footprint's extent
  double Amplitude;     ///< amp (unitless, <= 1; times the low-pass's sqrt(det cov2 / det(cov2 + L)))
  double Elevation;     ///< m_z, mm
  double ElevationVar;  ///< P2[z,z], mm^2
  double CutoffSquared; ///< k^2 - m_z^2 / P2[z,z]: the footprint keeps the pixels p with
                        ///< (p - c)^T conic (p - c) <= CutoffSquared, i.e. within k of the centre in the
                        ///< 3D Mahalanobis distance of the beam-convolved Gaussian (DESIGN section 3)
  bool Visible;         ///< false when culled in elevation or degenerate
};

/// Intermediate values of the setup that the backward pass needs.
struct SetupCache
{
  double Scale[3]; ///< s_k = exp(clamped l_k)
  bool ScaleClamped[3];
  double Qn[4];    ///< normalised quaternion
  double QNorm;    ///< |q| (0 when treated as identity)
  double Rp[3][3]; ///< R' = F R
  double M[3][3];  ///< R' diag(s)
  double m[3];     ///< mean in the slice frame
  double P[3][3];  ///< P = M M^T (without the beam)
  double Pzz2;     ///< P[z,z] + sigma_E^2
  double LambdaZZ; ///< (P^-1)[z,z]
};

// ---------------------------------------------------------------------------------------------
// Rotation from a quaternion, and its gradient twin.

/// R(q) for a unit quaternion (w, x, y, z).
BIGUS_HD void QuaternionToMatrix(const double q[4], double R[3][3])
{
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  R[0][0] = 1 - 2 * (y * y + z * z);
  R[0][1] = 2 * (x * y - w * z);
  R[0][2] = 2 * (x * z + w * y);
  R[1][0] = 2 * (x * y + w * z);
  R[1][1] = 1 - 2 * (x * x + z * z);
  R[1][2] = 2 * (y * z - w * x);
  R[2][0] = 2 * (x * z - w * y);
  R[2][1] = 2 * (y * z + w * x);
  R[2][2] = 1 - 2 * (x * x + y * y);
}

/**
 * @p q (w, x, y, z; any length) scaled to the unit quaternion @p qn; one of squared length below
 * MinimumQuaternionNorm2, or not finite, becomes the identity (1, 0, 0, 0): the rotation every part of BIGUS
 * (renderer, densification, merge) gives a Gaussian whose quaternion has collapsed. Returns |q|, 0 for those.
 * @p qn may be @p q.
 */
BIGUS_HD double NormalizeQuaternion(const double q[4], double qn[4])
{
  const double n2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
  if (n2 >= MinimumQuaternionNorm2 && n2 < 1e300)
  {
    const double n = std::sqrt(n2);
    for (int k = 0; k < 4; ++k)
    {
      qn[k] = q[k] / n;
    }
    return n;
  }
  qn[0] = 1;
  qn[1] = qn[2] = qn[3] = 0;
  return 0;
}

/**
 * The unit quaternion (w, x, y, z) of the rotation whose columns are the orthonormal vectors u, v, n: the
 * inverse of QuaternionToMatrix. Shepperd's method: the largest of the four pivots keeps it stable
 * (S. W. Shepperd, "Quaternion from rotation matrix", J. Guidance and Control 1(3), 1978). Host only.
 */
inline void QuaternionFromAxes(const double u[3], const double v[3], const double n[3], double q[4])
{
  const double m00 = u[0], m11 = v[1], m22 = n[2];
  const double trace = m00 + m11 + m22;
  if (trace > 0)
  {
    const double s = 2 * std::sqrt(1 + trace);
    q[0] = 0.25 * s, q[1] = (v[2] - n[1]) / s, q[2] = (n[0] - u[2]) / s, q[3] = (u[1] - v[0]) / s;
  }
  else if (m00 > m11 && m00 > m22)
  {
    const double s = 2 * std::sqrt(1 + m00 - m11 - m22);
    q[0] = (v[2] - n[1]) / s, q[1] = 0.25 * s, q[2] = (v[0] + u[1]) / s, q[3] = (n[0] + u[2]) / s;
  }
  else if (m11 > m22)
  {
    const double s = 2 * std::sqrt(1 + m11 - m00 - m22);
    q[0] = (n[0] - u[2]) / s, q[1] = (v[0] + u[1]) / s, q[2] = 0.25 * s, q[3] = (n[1] + v[2]) / s;
  }
  else
  {
    const double s = 2 * std::sqrt(1 + m22 - m00 - m11);
    q[0] = (u[1] - v[0]) / s, q[1] = (n[0] + u[2]) / s, q[2] = (n[1] + v[2]) / s, q[3] = 0.25 * s;
  }
}

/// dL/dq of R(q) given dL/dR, for the unit quaternion q (entry-wise derivative of the formula above).
BIGUS_HD void QuaternionToMatrixBackward(const double q[4], const double G[3][3], double dq[4])
{
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  dq[0] = 2 * (-z * G[0][1] + y * G[0][2] + z * G[1][0] - x * G[1][2] - y * G[2][0] + x * G[2][1]);
  dq[1] = 2 *
    (y * G[0][1] + z * G[0][2] + y * G[1][0] - 2 * x * G[1][1] - w * G[1][2] + z * G[2][0] + w * G[2][1] -
      2 * x * G[2][2]);
  dq[2] = 2 *
    (-2 * y * G[0][0] + x * G[0][1] + w * G[0][2] + x * G[1][0] + z * G[1][2] - w * G[2][0] + z * G[2][1] -
      2 * y * G[2][2]);
  dq[3] = 2 *
    (-2 * z * G[0][0] - w * G[0][1] + x * G[0][2] + w * G[1][0] - 2 * z * G[1][1] + y * G[1][2] + x * G[2][0] +
      y * G[2][1]);
}

// ---------------------------------------------------------------------------------------------
// A rigid correction of a slice's pose (pose refinement), and its gradient twin (SlicePoseBackward).

/**
 * The slice frame moved by the rigid correction @p xi = (omega, t), both in the slice's own axes u, v, n:
 * the rotation vector omega (rad) about the pivot @p pivot (slice coordinates, mm, e.g. the image centre),
 * then the translation t (mm). Every point p of the slice (slice coordinates) moves to
 * E (p - pivot) + pivot + t, E = exp([omega]_x) (Rodrigues' formula), so
 *
 *     F' = E^T F,    o' = o + F^T (pivot + t - E pivot),    and a Gaussian's m' = E^T (m - pivot - t) + pivot.
 *
 * The pixel grid in the plane is unchanged: the correction moves the whole slice.
 */
BIGUS_HD void CorrectSliceFrame(const SliceFrameD& frame, const double pivot[3], const double xi[6], SliceFrameD& out)
{
  const double angle = std::sqrt(xi[0] * xi[0] + xi[1] * xi[1] + xi[2] * xi[2]);
  // sin(a)/a and (1 - cos a)/a^2, by their series below 1e-4 rad (no division by a small angle).
  const double a2 = angle * angle;
  const double sa = angle < 1e-4 ? 1 - a2 / 6 : std::sin(angle) / angle;
  const double ca = angle < 1e-4 ? 0.5 - a2 / 24 : (1 - std::cos(angle)) / a2;
  const double K[3][3] = { { 0, -xi[2], xi[1] }, { xi[2], 0, -xi[0] }, { -xi[1], xi[0], 0 } };
  double E[3][3];
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      const double KK = K[i][0] * K[0][j] + K[i][1] * K[1][j] + K[i][2] * K[2][j];
      E[i][j] = (i == j ? 1.0 : 0.0) + sa * K[i][j] + ca * KK;
    }
  }
  double shift[3]; // pivot + t - E pivot, slice coordinates
  for (int i = 0; i < 3; ++i)
  {
    shift[i] = pivot[i] + xi[3 + i] - (E[i][0] * pivot[0] + E[i][1] * pivot[1] + E[i][2] * pivot[2]);
  }
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      out.F[i][j] = E[0][i] * frame.F[0][j] + E[1][i] * frame.F[1][j] + E[2][i] * frame.F[2][j];
    }
    out.Origin[i] = frame.Origin[i] + frame.F[0][i] * shift[0] + frame.F[1][i] * shift[1] + frame.F[2][i] * shift[2];
    out.LowPass[i] = frame.LowPass[i]; // in-plane: a rigid motion of the slice keeps it
  }
}

/// Gradients of the loss with respect to a Gaussian's mean and rotation in the slice frame, m and R' = F R
/// (SetupFootprintBackward's intermediate values): what a slice's pose changes.
struct SliceFrameGrad
{
  double Mean[3];
  double Rotation[3][3];
};

/**
 * dL/d(xi) of CorrectSliceFrame at xi = 0, accumulated into @p dxi (omega 0..2, per rad; t 3..5, per mm),
 * from one Gaussian's SliceFrameGrad @p g and its SetupCache @p c (m and R'). With E^T = I - [omega]_x to
 * first order, m' = m - t - omega x (m - pivot) and R'' = R' - [omega]_x R', so
 *
 *     dL/dt = -G_m,    dL/domega = G_m x (m - pivot) - (A_12 - A_21, A_20 - A_02, A_01 - A_10),  A = R' G_R'^T.
 *
 * A refinement that keeps a correction xi per frame composes it into the pose and takes this gradient at
 * the corrected pose (the left-trivialised gradient on SE(3)); it equals d/dxi to first order in |omega|.
 */
BIGUS_HD void SlicePoseBackward(const SetupCache& c, const double pivot[3], const SliceFrameGrad& g, double dxi[6])
{
  const double d[3] = { c.m[0] - pivot[0], c.m[1] - pivot[1], c.m[2] - pivot[2] };
  double A[3][3];
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      A[i][j] = c.Rp[i][0] * g.Rotation[j][0] + c.Rp[i][1] * g.Rotation[j][1] + c.Rp[i][2] * g.Rotation[j][2];
    }
  }
  dxi[0] += g.Mean[1] * d[2] - g.Mean[2] * d[1] - (A[1][2] - A[2][1]);
  dxi[1] += g.Mean[2] * d[0] - g.Mean[0] * d[2] - (A[2][0] - A[0][2]);
  dxi[2] += g.Mean[0] * d[1] - g.Mean[1] * d[0] - (A[0][1] - A[1][0]);
  for (int k = 0; k < 3; ++k)
  {
    dxi[3 + k] -= g.Mean[k];
  }
}

// ---------------------------------------------------------------------------------------------
// Phase 1: transform, cull and set up one Gaussian for one slice.

/**
 * Beam-integrated footprint of Gaussian @p g on the slice @p frame (DESIGN section 3).
 * @param sigmaE  elevation beam standard deviation, mm (0 = thin plane, the UltraGauss ablation).
 * @param cutoff  k: culled when |m_z| > k sqrt(P2[z,z]); a visible footprint keeps the pixels within k
 *                of the beam-convolved Gaussian's centre in 3D Mahalanobis distance (CutoffSquared), so a
 *                Gaussian far from the plane covers a smaller disc: every dropped contribution is at most
 *                |r| exp(-k^2 / 2), the bound the elevation cull alone gives.
 * @param cache   filled with what the backward pass needs (may be null).
 */
BIGUS_HD Footprint SetupFootprint(
  const GaussianParams& g, const SliceFrameD& frame, double sigmaE, double cutoff, SetupCache* cache)
{
  SetupCache local;
  SetupCache& c = cache ? *cache : local;
  Footprint f;
  f.Visible = false;

  for (int k = 0; k < 3; ++k)
  {
    const double l = g.LogScale[k];
    const bool finite = l == l; // NaN test that survives fast-math
    const double lc =
      !finite ? 0.0 : (l < MinimumLogScale ? MinimumLogScale : (l > MaximumLogScale ? MaximumLogScale : l));
    c.ScaleClamped[k] = !finite || l < MinimumLogScale || l > MaximumLogScale;
    c.Scale[k] = std::exp(lc);
  }
  c.QNorm = NormalizeQuaternion(g.Quaternion, c.Qn);
  double R[3][3];
  QuaternionToMatrix(c.Qn, R);
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      c.Rp[i][j] = frame.F[i][0] * R[0][j] + frame.F[i][1] * R[1][j] + frame.F[i][2] * R[2][j];
      c.M[i][j] = 0;
    }
  }
  const double d[3] = { g.Mean[0] - frame.Origin[0], g.Mean[1] - frame.Origin[1], g.Mean[2] - frame.Origin[2] };
  for (int i = 0; i < 3; ++i)
  {
    c.m[i] = frame.F[i][0] * d[0] + frame.F[i][1] * d[1] + frame.F[i][2] * d[2];
    for (int k = 0; k < 3; ++k)
    {
      c.M[i][k] = c.Rp[i][k] * c.Scale[k];
    }
  }
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      c.P[i][j] = c.M[i][0] * c.M[j][0] + c.M[i][1] * c.M[j][1] + c.M[i][2] * c.M[j][2];
    }
  }
  const double s2 = sigmaE * sigmaE;
  c.Pzz2 = c.P[2][2] + s2;
  c.LambdaZZ = 0;
  for (int k = 0; k < 3; ++k)
  {
    const double t = c.Rp[2][k] / c.Scale[k];
    c.LambdaZZ += t * t;
  }

  f.Elevation = c.m[2];
  f.ElevationVar = c.Pzz2;
  if (!(c.Pzz2 > 0) || !(c.m[2] * c.m[2] <= cutoff * cutoff * c.Pzz2))
  {
    return f;
  }

  // cov2 = B B^T: rows x, y of A = [M | sigma_E e_z] minus their projection on the elevation row a_z.
  const double az[4] = { c.M[2][0], c.M[2][1], c.M[2][2], sigmaE };
  double B[2][4];
  for (int r = 0; r < 2; ++r)
  {
    const double a[4] = { c.M[r][0], c.M[r][1], c.M[r][2], 0.0 };
    const double t = (a[0] * az[0] + a[1] * az[1] + a[2] * az[2]) / c.Pzz2;
    for (int k = 0; k < 4; ++k)
    {
      B[r][k] = a[k] - t * az[k];
    }
  }
  f.Cov[0] = B[0][0] * B[0][0] + B[0][1] * B[0][1] + B[0][2] * B[0][2] + B[0][3] * B[0][3];
  f.Cov[1] = B[0][0] * B[1][0] + B[0][1] * B[1][1] + B[0][2] * B[1][2] + B[0][3] * B[1][3];
  f.Cov[2] = B[1][0] * B[1][0] + B[1][1] * B[1][1] + B[1][2] * B[1][2] + B[1][3] * B[1][3];
  double det = 0; // Cauchy-Binet: det(B B^T) = sum over column pairs of squared 2x2 minors
  for (int i = 0; i < 4; ++i)
  {
    for (int j = i + 1; j < 4; ++j)
    {
      const double minor = B[0][i] * B[1][j] - B[0][j] * B[1][i];
      det += minor * minor;
    }
  }
  if (!(det > 0) || !(det < 1e300))
  {
    return f;
  }
  // Principal axes of cov2; the smaller variance comes from det / larger (no cancellation).
  const double half = 0.5 * (f.Cov[0] - f.Cov[2]);
  double large = 0.5 * (f.Cov[0] + f.Cov[2]) + std::sqrt(half * half + f.Cov[1] * f.Cov[1]);
  double small = det / large;
  // In-plane aspect ratios above MaximumFootprintAspect (scale ratio) are numerically meaningless (no
  // three doubles hold such an ellipse: the conic turns indefinite near 1e8) and thinner than any
  // pixel: such a footprint is widened to that aspect. Its gradient then ignores the widening.
  const double floor = large / (MaximumFootprintAspect * MaximumFootprintAspect);
  if (small < floor)
  {
    const double widen = (floor - small) / (1.0 - 1.0 / (MaximumFootprintAspect * MaximumFootprintAspect));
    f.Cov[0] += widen;
    f.Cov[2] += widen;
    large += widen;
    small += widen;
    det = large * small;
  }
  // The slice's low-pass: cov2 + L, the amplitude times sqrt(det cov2 / det(cov2 + L)), the footprint convolved
  // with a normalised Gaussian kernel of covariance L (its integral kept; Mip-Splatting's 2D filter, Yu et al.
  // 2024, eq. 9). det(cov2 + L) = det cov2 + tr(adj(cov2) L) + det L: a sum of non-negative terms.
  double lowPassFactor = 1;
  const double* L = frame.LowPass;
  if (L[0] != 0 || L[1] != 0 || L[2] != 0)
  {
    const double blurredDet =
      det + f.Cov[2] * L[0] - 2 * f.Cov[1] * L[1] + f.Cov[0] * L[2] + (L[0] * L[2] - L[1] * L[1]);
    lowPassFactor = std::sqrt(det / blurredDet);
    f.Cov[0] += L[0];
    f.Cov[1] += L[1];
    f.Cov[2] += L[2];
    det = blurredDet;
    const double blurredHalf = 0.5 * (f.Cov[0] - f.Cov[2]);
    large = 0.5 * (f.Cov[0] + f.Cov[2]) + std::sqrt(blurredHalf * blurredHalf + f.Cov[1] * f.Cov[1]);
    small = det / large;
  }
  f.Conic[0] = f.Cov[2] / det;
  f.Conic[1] = -f.Cov[1] / det;
  f.Conic[2] = f.Cov[0] / det;
  const double angle = 0.5 * std::atan2(2 * f.Cov[1], f.Cov[0] - f.Cov[2]);
  f.Axes[0] = std::cos(angle);
  f.Axes[1] = std::sin(angle);
  f.Axes[2] = 1 / std::sqrt(large);
  f.Axes[3] = 1 / std::sqrt(small);
  const double shift = -c.m[2] / c.Pzz2;
  f.Center[0] = c.m[0] + shift * c.P[0][2];
  f.Center[1] = c.m[1] + shift * c.P[1][2];
  const double elevationForm = c.m[2] * c.m[2] / c.Pzz2;
  f.Amplitude = lowPassFactor * std::exp(-0.5 * elevationForm) / std::sqrt(1.0 + s2 * c.LambdaZZ);
  f.CutoffSquared = cutoff * cutoff - elevationForm;
  f.Visible = true;
  return f;
}

/// Gradients of the loss with respect to a footprint's parameters (accumulated over pixels).
struct FootprintGrad
{
  double Center[2];
  double Conic[3]; ///< dL/da, dL/db, dL/dc for q = a dx^2 + 2 b dx dy + c dy^2
  double Amplitude;
};

/// Gradients with respect to one Gaussian's parameters.
struct GaussianGrad
{
  double Mean[3];
  double LogScale[3];
  double Quaternion[4];
  double Reflectivity;
};

/**
 * Backward of SetupFootprint: from dL/d(footprint) to dL/d(mean, log-scale, quaternion), through the
 * conic inverse, the conditional covariance, the parallax shift, the amplitude, P = M M^T, the
 * rotation into the slice frame and the quaternion normalisation. Accumulates into @p out.
 *
 * Derivation (symmetric matrices, G_X = dL/dX):
 *   conic = cov2^-1:          G_cov2 = -conic G_conic conic, with G_conic = [[Ga, Gb/2], [Gb/2, Gc]]
 *   with the slice's low-pass L (cov2 + L in the conic, amp times sqrt(det cov2 / det(cov2 + L))):
 *                             G_cov2 += G_amp amp (cov2^-1 - (cov2 + L)^-1) / 2
 *   cov2 = P_xy - b b^T / Pzz2 (b = P[xy,z]):  G_Pxy += G_cov2,  G_b += -2 G_cov2 b / Pzz2,
 *                                              G_Pzz2 += b^T G_cov2 b / Pzz2^2
 *   c = m_xy - m_z b / Pzz2:  G_mxy += G_c,  G_mz += -G_c.b / Pzz2,  G_b += -m_z G_c / Pzz2,
 *                             G_Pzz2 += m_z G_c.b / Pzz2^2
 *   amp = exp(-m_z^2 / 2 Pzz2) / sqrt(1 + s^2 Lzz):  G_mz += -G_amp amp m_z / Pzz2,
 *        G_Pzz2 += G_amp amp m_z^2 / (2 Pzz2^2),  G_Lzz = -G_amp amp s^2 / (2 (1 + s^2 Lzz))
 *   P = M M^T:  G_M = (G_P + G_P^T) M;   Lzz = sum_k R'_zk^2 / s_k^2;   M = R' diag(s)
 *   R' = F R:   G_R = F^T G_R';   q_n = q / |q|:  G_q = (G_qn - q_n (q_n . G_qn)) / |q|
 *   m = F (mu - o):  G_mu = F^T G_m
 * @p slice, if not null, receives G_m and G_R' (overwritten; zero when the footprint is not visible) for
 * the gradient with respect to the slice's pose (SlicePoseBackward).
 */
BIGUS_HD void SetupFootprintBackward(const Footprint& f, const SetupCache& c, const SliceFrameD& frame, double sigmaE,
  const FootprintGrad& gf, GaussianGrad& out, SliceFrameGrad* slice = nullptr)
{
  if (slice)
  {
    for (int i = 0; i < 3; ++i)
    {
      slice->Mean[i] = 0;
      slice->Rotation[i][0] = slice->Rotation[i][1] = slice->Rotation[i][2] = 0;
    }
  }
  if (!f.Visible)
  {
    return;
  }
  const double s2 = sigmaE * sigmaE;
  const double a = f.Conic[0], b = f.Conic[1], cc = f.Conic[2];
  const double g00 = gf.Conic[0], g01 = 0.5 * gf.Conic[1], g11 = gf.Conic[2];
  // G_cov2 = -C G C for C = [[a, b], [b, cc]].
  const double t00 = g00 * a + g01 * b, t01 = g00 * b + g01 * cc;
  const double t10 = g01 * a + g11 * b, t11 = g01 * b + g11 * cc;
  double gc00 = -(a * t00 + b * t10);
  double gc01 = -(a * t01 + b * t11);
  double gc11 = -(b * t01 + cc * t11);
  const double ga = gf.Amplitude * f.Amplitude;
  const double* L = frame.LowPass;
  if (L[0] != 0 || L[1] != 0 || L[2] != 0)
  {
    // amp ~ sqrt(det cov2 / det(cov2 + L)): G_cov2 += ga (cov2^-1 - (cov2 + L)^-1) / 2, with cov2 = f.Cov - L
    // and (cov2 + L)^-1 the conic; the conic's own gradient above is taken at cov2 + L, which moves with cov2.
    const double x = f.Cov[0] - L[0], y = f.Cov[1] - L[1], z = f.Cov[2] - L[2];
    const double det = x * z - y * y;
    if (det > 0)
    {
      gc00 += 0.5 * ga * (z / det - a);
      gc01 += 0.5 * ga * (-y / det - b);
      gc11 += 0.5 * ga * (x / det - cc);
    }
  }

  const double bx = c.P[0][2], by = c.P[1][2];
  const double mz = c.m[2];
  const double Pzz2 = c.Pzz2;
  double GP[3][3] = { { gc00, gc01, 0 }, { gc01, gc11, 0 }, { 0, 0, 0 } };
  double Gb[2] = { -2 * (gc00 * bx + gc01 * by) / Pzz2, -2 * (gc01 * bx + gc11 * by) / Pzz2 };
  double GPzz2 = (bx * (gc00 * bx + gc01 * by) + by * (gc01 * bx + gc11 * by)) / (Pzz2 * Pzz2);
  double Gm[3] = { gf.Center[0], gf.Center[1], 0 };
  const double gcb = gf.Center[0] * bx + gf.Center[1] * by;
  Gm[2] += -gcb / Pzz2;
  Gb[0] += -mz * gf.Center[0] / Pzz2;
  Gb[1] += -mz * gf.Center[1] / Pzz2;
  GPzz2 += mz * gcb / (Pzz2 * Pzz2);
  Gm[2] += -ga * mz / Pzz2;
  GPzz2 += ga * mz * mz / (2 * Pzz2 * Pzz2);
  const double GLzz = -ga * s2 / (2 * (1 + s2 * c.LambdaZZ));
  GP[0][2] = GP[2][0] = 0.5 * Gb[0];
  GP[1][2] = GP[2][1] = 0.5 * Gb[1];
  GP[2][2] = GPzz2;

  // P = M M^T -> G_M = 2 GP M (GP symmetric).
  double GRp[3][3];
  double Gs[3] = { 0, 0, 0 };
  for (int i = 0; i < 3; ++i)
  {
    for (int k = 0; k < 3; ++k)
    {
      const double gM = 2 * (GP[i][0] * c.M[0][k] + GP[i][1] * c.M[1][k] + GP[i][2] * c.M[2][k]);
      GRp[i][k] = gM * c.Scale[k];
      Gs[k] += gM * c.Rp[i][k];
    }
  }
  for (int k = 0; k < 3; ++k)
  {
    const double inv = 1.0 / c.Scale[k];
    GRp[2][k] += GLzz * 2 * c.Rp[2][k] * inv * inv;
    Gs[k] += GLzz * (-2 * c.Rp[2][k] * c.Rp[2][k] * inv * inv * inv);
    out.LogScale[k] += c.ScaleClamped[k] ? 0.0 : Gs[k] * c.Scale[k];
  }
  if (slice)
  {
    for (int i = 0; i < 3; ++i)
    {
      slice->Mean[i] = Gm[i];
      for (int j = 0; j < 3; ++j)
      {
        slice->Rotation[i][j] = GRp[i][j];
      }
    }
  }
  double GR[3][3];
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      GR[i][j] = frame.F[0][i] * GRp[0][j] + frame.F[1][i] * GRp[1][j] + frame.F[2][i] * GRp[2][j];
    }
  }
  double Gqn[4];
  QuaternionToMatrixBackward(c.Qn, GR, Gqn);
  if (c.QNorm > 0)
  {
    const double dot = c.Qn[0] * Gqn[0] + c.Qn[1] * Gqn[1] + c.Qn[2] * Gqn[2] + c.Qn[3] * Gqn[3];
    for (int k = 0; k < 4; ++k)
    {
      out.Quaternion[k] += (Gqn[k] - c.Qn[k] * dot) / c.QNorm;
    }
  }
  for (int k = 0; k < 3; ++k)
  {
    out.Mean[k] += frame.F[0][k] * Gm[0] + frame.F[1][k] * Gm[1] + frame.F[2][k] * Gm[2];
  }
}

/**
 * The footprint gradient from the per-pixel sums of PixelWeightBackward (sums[0..4]: centre and
 * conic terms; sums[5]: sum dL/dS e; sums[6], the attribution, is not used here) for a Gaussian of
 * effective reflectivity @p r: dL/d(amp) = r sums[5].
 */
BIGUS_HD FootprintGrad FootprintGradFromSums(const double sums[7], double r)
{
  FootprintGrad gf;
  gf.Center[0] = sums[0];
  gf.Center[1] = sums[1];
  gf.Conic[0] = sums[2];
  gf.Conic[1] = sums[3];
  gf.Conic[2] = sums[4];
  gf.Amplitude = r * sums[5];
  return gf;
}

// ---------------------------------------------------------------------------------------------
// Phase 2: per-pixel evaluation and its gradient twin.

/// Exponent q = d^T conic d of the 2D Gaussian at offset (dx, dy) = p - c, mm.
template <typename T>
BIGUS_HD T ConicForm(T a, T b, T c, T dx, T dy)
{
  return a * dx * dx + T(2) * b * dx * dy + c * dy * dy;
}

/// Exponent q from the principal-axes form (Footprint::Axes): rounding errors grow with the aspect
/// ratio, not its square as in the conic form, and q is never negative.
template <typename T>
BIGUS_HD T AxesForm(T cosine, T sine, T inverseMajor, T inverseMinor, T dx, T dy)
{
  const T u = (cosine * dx + sine * dy) * inverseMajor;
  const T v = (cosine * dy - sine * dx) * inverseMinor;
  return u * u + v * v;
}

/// Pixel weight w = amp exp(-q / 2).
template <typename T>
BIGUS_HD T PixelWeight(T amp, T a, T b, T c, T dx, T dy)
{
  return amp * std::exp(T(-0.5) * ConicForm(a, b, c, dx, dy));
}

/**
 * Accumulates one pixel's terms of the backward pass: dL/dS = @p gS at the offset (dx, dy) = p - c (mm)
 * from a footprint with conic (a, b, c), signed peak @p ra = r amp (r the effective reflectivity) and
 * @p e = exp(-q / 2) at that pixel (0 outside the footprint). The caller evaluates e, so that the float
 * backends use FastExp, AxesForm and their cutoff while the double reference uses std::exp, ConicForm.
 * With the Gaussian's share S(p) = r amp e, q = d^T conic d and d = p - c:
 *   dS/dc = r amp e conic d  (dq/dc = -2 conic d);   dS/d(a, b, c) = -r amp e (dx^2 / 2, dx dy, dy^2 / 2);
 *   dS/d(amp) = r e;   dS/dr = amp e.
 * sums[k * stride] += term k: k = 0, 1: dL/dc; 2..4: dL/d(a, b, c); 5: gS e (times r: dL/d(amp); times
 * amp: dL/dr); 6: |gS| |r amp| e, the pixel's share of the error attribution E_i (bigusRenderer.h).
 * @p stride is 1 for one running sum per term; the CPU backend passes its lane count to keep one partial
 * sum per vector lane (sums = &part[0][lane] of part[7][lanes]), which vectorises without reassociation.
 */
template <typename T>
BIGUS_HD void PixelWeightBackward(T gS, T ra, T e, T a, T b, T c, T dx, T dy, T* sums, int stride)
{
  const T ge = gS * e;
  const T gw = ge * ra;
  sums[0 * stride] += gw * (a * dx + b * dy);
  sums[1 * stride] += gw * (b * dx + c * dy);
  sums[2 * stride] += T(-0.5) * gw * dx * dx;
  sums[3 * stride] += -gw * dx * dy;
  sums[4 * stride] += T(-0.5) * gw * dy * dy;
  sums[5 * stride] += ge;
  sums[6 * stride] += std::abs(gS) * std::abs(ra) * e;
}

/**
 * exp(x) for float, as a branch-free polynomial that compilers vectorise (std::exp does not vectorise
 * without -ffast-math). Range reduction x = k ln2 + f, |f| <= ln2 / 2 (k rounded to nearest), then a
 * degree-6 Taylor
 * polynomial; relative error below 2.6e-7 on [-87, 0] (a scan of every float: worst 2.54e-7 at
 * -26.686; TestGaussianFootprint). Inputs are clamped
 * to [-87, 88].
 */
BIGUS_HD float FastExp(float x)
{
  x = x < -87.0f ? -87.0f : x;
  x = x > 88.0f ? 88.0f : x;
  // Round x / ln2 to the nearest integer without a call: adding 1.5 * 2^23 leaves no fraction bits.
  const float k = (x * 1.44269504f + 12582912.0f) - 12582912.0f;
  const float f = x - k * 0.693145751953125f - k * 1.428606765330187e-06f; // ln2 split for exact k ln2
  float p = 1.0f / 720.0f;
  p = p * f + 1.0f / 120.0f;
  p = p * f + 1.0f / 24.0f;
  p = p * f + 1.0f / 6.0f;
  p = p * f + 0.5f;
  p = p * f + 1.0f;
  p = p * f + 1.0f;
  const std::int32_t bits = (static_cast<std::int32_t>(k) + 127) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof(scale));
  return p * scale;
}

/// Image map I = 1 - exp(-gamma max(S, 0)) (envelope rectifier, then log-compression-like map).
template <typename T>
BIGUS_HD T ImageFromScattering(T S, T gamma)
{
  return S > T(0) ? T(1) - std::exp(-gamma * S) : T(0);
}

/// dI/dS = gamma exp(-gamma S) where S > 0, else 0 (the rectifier passes no gradient).
template <typename T>
BIGUS_HD T ImageFromScatteringDerivative(T S, T gamma)
{
  return S > T(0) ? gamma * std::exp(-gamma * S) : T(0);
}

/// gamma = -ln(1 - mean ground-truth intensity over the masked training pixels) (DESIGN section 3).
BIGUS_HD double GammaFromMeanIntensity(double meanIntensity)
{
  const double m = meanIntensity < 0 ? 0 : (meanIntensity > 0.999 ? 0.999 : meanIntensity);
  return -std::log(1.0 - m);
}

} // namespace bigus

#endif
