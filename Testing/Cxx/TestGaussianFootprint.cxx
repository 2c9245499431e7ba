// The closed-form beam-integrated footprint of bigusGaussianMath.h (DESIGN section 3) against an
// oracle that knows nothing of it: adaptive Gauss-Kronrod quadrature over elevation of the 3D Gaussian
// times the beam, with the Gaussian evaluated in its own principal frame (no matrix is inverted).
#include "bigusGaussianMath.h"
#include "bigusSliceFrame.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <limits>
#include <map>
#include <string>
#include <type_traits>
#include <vector>

namespace
{
using bigus::Footprint;
using bigus::GaussianParams;
using bigus::SliceFrameD;

constexpr double Pi = 3.14159265358979323846;

// ---------------------------------------------------------------------------------------------
// Quaternions (w, x, y, z), Hamilton product, so that R(a b) = R(a) R(b) with QuaternionToMatrix.

struct Quat
{
  double w, x, y, z;
};

Quat Mul(const Quat& a, const Quat& b)
{
  return { a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
    a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w };
}

Quat AxisAngle(int axis, double radians)
{
  Quat q{ std::cos(radians / 2), 0, 0, 0 };
  const double s = std::sin(radians / 2);
  (axis == 0 ? q.x : axis == 1 ? q.y : q.z) = s;
  return q;
}

double Radians(double degrees)
{
  return degrees * Pi / 180;
}

// A slice orientation with no special alignment to the reference axes, so that every entry of F and
// of R' is a full-precision number.
Quat GenericSliceRotation()
{
  return Mul(Mul(AxisAngle(2, 0.7), AxisAngle(0, -1.1)), AxisAngle(1, 0.4));
}

// ---------------------------------------------------------------------------------------------
// Test configurations, built in the slice frame and mapped back to the reference frame.

struct Case
{
  GaussianParams G;
  SliceFrameD Frame;
  double SigmaE;
};

/**
 * A Gaussian whose axis 0 (the long axis of a needle, the normal of a pancake) makes `tiltDeg` with the
 * slice plane, at in-plane azimuth `azimuthDeg` and rolled by `rollDeg` about itself, with mean m in
 * the slice frame. The slice has rotation `slice` (rows of F = columns of R(slice)) and origin `origin`.
 */
Case MakeCase(const double scales[3], double tiltDeg, double azimuthDeg, double rollDeg, const double m[3],
  const Quat& slice, const double origin[3], double sigmaE)
{
  Case c;
  double S[3][3];
  const double qs[4] = { slice.w, slice.x, slice.y, slice.z };
  bigus::QuaternionToMatrix(qs, S);
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      c.Frame.F[i][j] = S[j][i];
    }
    c.Frame.Origin[i] = origin[i];
  }
  // R' = F R = R(slice)^T R(slice * inSlice) = R(inSlice).
  const Quat inSlice =
    Mul(Mul(AxisAngle(2, Radians(azimuthDeg)), AxisAngle(1, -Radians(tiltDeg))), AxisAngle(0, Radians(rollDeg)));
  const Quat q = Mul(slice, inSlice);
  c.G.Quaternion[0] = q.w;
  c.G.Quaternion[1] = q.x;
  c.G.Quaternion[2] = q.y;
  c.G.Quaternion[3] = q.z;
  for (int k = 0; k < 3; ++k)
  {
    c.G.LogScale[k] = std::log(scales[k]);
    c.G.Mean[k] = origin[k] + c.Frame.F[0][k] * m[0] + c.Frame.F[1][k] * m[1] + c.Frame.F[2][k] * m[2];
  }
  c.G.Reflectivity = 1;
  c.SigmaE = sigmaE;
  return c;
}

// ---------------------------------------------------------------------------------------------
// The oracle. The inputs are taken through the same double steps as SetupFootprint up to R' = F R and
// m = F (mu - o) (so that both sides see the same Gaussian), then promoted to T.

template <typename T>
struct LocalGaussian
{
  T Rp[3][3]; // R': columns are the Gaussian's axes in the slice frame
  T s[3];     // standard deviations, mm
  T m[3];     // mean in the slice frame, mm

  /// The exponent q of G = exp(-q/2) at slice-frame point x: q = sum_k (y_k / s_k)^2, y = R'^T (x - m).
  T Exponent(T x0, T x1, T x2) const
  {
    const T d[3] = { x0 - this->m[0], x1 - this->m[1], x2 - this->m[2] };
    T q = 0;
    for (int k = 0; k < 3; ++k)
    {
      const T y = this->Rp[0][k] * d[0] + this->Rp[1][k] * d[1] + this->Rp[2][k] * d[2];
      q += (y / this->s[k]) * (y / this->s[k]);
    }
    return q;
  }
};

template <typename T>
LocalGaussian<T> MakeLocal(const GaussianParams& g, const SliceFrameD& frame)
{
  double qn[4];
  const double n = std::sqrt(g.Quaternion[0] * g.Quaternion[0] + g.Quaternion[1] * g.Quaternion[1] +
    g.Quaternion[2] * g.Quaternion[2] + g.Quaternion[3] * g.Quaternion[3]);
  for (int k = 0; k < 4; ++k)
  {
    qn[k] = g.Quaternion[k] / n;
  }
  double R[3][3];
  bigus::QuaternionToMatrix(qn, R);
  LocalGaussian<T> L;
  const double d[3] = { g.Mean[0] - frame.Origin[0], g.Mean[1] - frame.Origin[1], g.Mean[2] - frame.Origin[2] };
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      L.Rp[i][j] = T(frame.F[i][0] * R[0][j] + frame.F[i][1] * R[1][j] + frame.F[i][2] * R[2][j]);
    }
    L.m[i] = T(frame.F[i][0] * d[0] + frame.F[i][1] * d[1] + frame.F[i][2] * d[2]);
    L.s[i] = T(std::exp(g.LogScale[i]));
  }
  return L;
}

// 7-point Gauss / 15-point Kronrod nodes and weights on [-1, 1] (QUADPACK qk15), to long double digits.
const long double KronrodNodes[8] = { 0.991455371120812639206854697526329L, 0.949107912342758524526189684047851L,
  0.864864423359769072789712788640926L, 0.741531185599394439863864773280788L, 0.586087235467691130294144845693013L,
  0.405845151377397166906606412076961L, 0.207784955007898467600689403773245L, 0.0L };
const long double KronrodWeights[8] = { 0.022935322010529224963732008058970L, 0.063092092629978553290700663189204L,
  0.104790010322250183839876322541518L, 0.140653259715525918745189590510238L, 0.169004726639267902826583426598550L,
  0.190350578064785409913256402421014L, 0.204432940075298892414161999234649L, 0.209482141084727828012999174891714L };
const long double GaussWeights[4] = { 0.129484966168869693270611432679082L, 0.279705391489276667901467771423780L,
  0.381830050505118944950369775488975L, 0.417959183673469387755102040816327L };

/// K15 on [a, b], with QUADPACK's error estimate in *err and its rounding floor (50 eps |f|) in *floor.
template <typename T, typename F>
T Kronrod15(const F& f, T a, T b, T* err, T* floor = nullptr)
{
  const T h = (b - a) / 2, mid = (a + b) / 2;
  T values[15];
  values[7] = f(mid);
  for (int i = 0; i < 7; ++i)
  {
    const T x = h * T(KronrodNodes[i]);
    values[i] = f(mid - x);
    values[14 - i] = f(mid + x);
  }
  T kronrod = T(KronrodWeights[7]) * values[7], gauss = T(GaussWeights[3]) * values[7];
  T absolute = T(KronrodWeights[7]) * std::abs(values[7]);
  for (int i = 0; i < 7; ++i)
  {
    const T sum = values[i] + values[14 - i];
    kronrod += T(KronrodWeights[i]) * sum;
    absolute += T(KronrodWeights[i]) * (std::abs(values[i]) + std::abs(values[14 - i]));
    if (i % 2 == 1)
    {
      gauss += T(GaussWeights[i / 2]) * sum;
    }
  }
  const T mean = kronrod / 2;
  T spread = T(KronrodWeights[7]) * std::abs(values[7] - mean);
  for (int i = 0; i < 7; ++i)
  {
    spread += T(KronrodWeights[i]) * (std::abs(values[i] - mean) + std::abs(values[14 - i] - mean));
  }
  const T ah = std::abs(h);
  T e = std::abs((kronrod - gauss) * h);
  spread *= ah;
  if (spread > 0 && e > 0)
  {
    e = spread * std::min(T(1), std::pow(200 * e / spread, T(1.5)));
  }
  *err = e;
  if (floor)
  {
    *floor = 50 * std::numeric_limits<T>::epsilon() * absolute * ah;
  }
  return kronrod * h;
}

/// Bisects until the error estimate is below tol or down to rounding. Far from its centre a thin
/// Gaussian's exponent carries rounding noise of relative size eps |x - m| / s_min; the depth cap
/// stops the bisection from chasing it (at depth 8 a piece spans 1/170 of a width, where K15 is exact
/// to the last bit on the smooth part).
template <typename T, typename F>
T AdaptiveKronrod(const F& f, T a, T b, T tol, int depth)
{
  T err, floor;
  const T r = Kronrod15(f, a, b, &err, &floor);
  if (err <= tol || err <= floor || depth >= 8)
  {
    return r;
  }
  const T mid = (a + b) / 2;
  return AdaptiveKronrod(f, a, mid, tol / 2, depth + 1) + AdaptiveKronrod(f, mid, b, tol / 2, depth + 1);
}

/**
 * Integral over the real line of f, which is concentrated around `peak` with width `width`: +-60 widths
 * split at growing distances so that every piece is smooth on its own scale, each refined until its
 * error estimate is below relTol times the whole integral. The placement only needs to be roughly
 * right: a misplaced peak shows as missing mass, not as a wrong value, and the self-test checks it.
 */
template <typename T, typename F>
T IntegrateLine(const F& f, T peak, T width, T relTol)
{
  static const double breaks[] = { -60, -30, -16, -9, -5, -3, -1.5, 0, 1.5, 3, 5, 9, 16, 30, 60 };
  constexpr int pieces = sizeof(breaks) / sizeof(breaks[0]) - 1;
  T total = 0, err;
  for (int i = 0; i < pieces; ++i)
  {
    total += Kronrod15(f, peak + T(breaks[i]) * width, peak + T(breaks[i + 1]) * width, &err);
  }
  const T tol = relTol * std::abs(total) / pieces;
  T sum = 0;
  for (int i = 0; i < pieces; ++i)
  {
    sum += AdaptiveKronrod(f, peak + T(breaks[i]) * width, peak + T(breaks[i + 1]) * width, tol, 0);
  }
  return sum;
}

/**
 * Integral over z of G(p, z) N(z; 0, sigmaE^2) (sigmaE > 0), or of G(p, z) alone (sigmaE = 0 here means
 * no beam, i.e. the projection; not SetupFootprint's thin plane), optionally times z^2 (second moment). The exponent in
 * z is quadratic; its curvature and vertex place the quadrature pieces only.
 */
template <typename T>
T ElevationIntegral(const LocalGaussian<T>& L, T px, T py, T sigmaE, T relTol, bool timesZ2 = false)
{
  T a2 = sigmaE > 0 ? 1 / (sigmaE * sigmaE) : T(0), a1 = 0;
  for (int k = 0; k < 3; ++k)
  {
    const T r = L.Rp[2][k] / L.s[k];
    const T y0 = (L.Rp[0][k] * (px - L.m[0]) + L.Rp[1][k] * (py - L.m[1]) - L.Rp[2][k] * L.m[2]) / L.s[k];
    a2 += r * r;
    a1 += 2 * y0 * r;
  }
  const T peak = -a1 / (2 * a2), width = 1 / std::sqrt(a2);
  const T norm = sigmaE > 0 ? 1 / (sigmaE * std::sqrt(2 * T(Pi))) : T(1);
  const T lambdaE = sigmaE > 0 ? 1 / (sigmaE * sigmaE) : T(0);
  auto f = [&](T z) {
    const T v = norm * std::exp(T(-0.5) * (L.Exponent(px, py, z) + lambdaE * z * z));
    return timesZ2 ? v * z * z : v;
  };
  return IntegrateLine<T>(f, peak, width, relTol);
}

constexpr double OracleTolerance = 1e-14;

// ---------------------------------------------------------------------------------------------
// Points of a footprint: its centre and points along its principal axes.

struct Axes
{
  double Major[2], Minor[2]; // unit vectors
  double SigmaMajor, SigmaMinor;
};

// Both eigenvalues without cancellation: the larger from cov2, the smaller as 1 / the larger of the conic.
Axes FootprintAxes(const Footprint& f)
{
  const double a = f.Cov[0], b = f.Cov[1], c = f.Cov[2];
  const double big = (a + c) / 2 + std::hypot((a - c) / 2, b);
  const double ca = f.Conic[0], cb = f.Conic[1], cc = f.Conic[2];
  const double conicBig = (ca + cc) / 2 + std::hypot((ca - cc) / 2, cb);
  double v[2] = { a >= c ? big - c : b, a >= c ? b : big - a };
  double n = std::hypot(v[0], v[1]);
  if (!(n > 0))
  {
    v[0] = 1;
    v[1] = 0;
    n = 1;
  }
  Axes ax;
  ax.Major[0] = v[0] / n;
  ax.Major[1] = v[1] / n;
  ax.Minor[0] = -ax.Major[1];
  ax.Minor[1] = ax.Major[0];
  ax.SigmaMajor = std::sqrt(big);
  ax.SigmaMinor = 1 / std::sqrt(conicBig);
  return ax;
}

/// Offsets from the footprint centre: the centre, +-1, 2, 3 sigma on both axes, and (2, 2) sigma diagonals.
std::vector<std::array<double, 2>> FootprintOffsets(const Footprint& f, double maxSigma = 3)
{
  const Axes ax = FootprintAxes(f);
  std::vector<std::array<double, 2>> out{ { 0.0, 0.0 } };
  for (double k = 1; k <= maxSigma; ++k)
  {
    for (double sign : { -1.0, 1.0 })
    {
      const double a = sign * k * ax.SigmaMajor, b = sign * k * ax.SigmaMinor;
      out.push_back({ a * ax.Major[0], a * ax.Major[1] });
      out.push_back({ b * ax.Minor[0], b * ax.Minor[1] });
    }
  }
  const double d = 2 / std::sqrt(2.0);
  for (double sa : { -1.0, 1.0 })
  {
    for (double sb : { -1.0, 1.0 })
    {
      const double a = sa * d * ax.SigmaMajor, b = sb * d * ax.SigmaMinor;
      out.push_back({ a * ax.Major[0] + b * ax.Minor[0], a * ax.Major[1] + b * ax.Minor[1] });
    }
  }
  return out;
}

double ClosedFormWeight(const Footprint& f, double dx, double dy)
{
  return bigus::PixelWeight<double>(f.Amplitude, f.Conic[0], f.Conic[1], f.Conic[2], dx, dy);
}

// ---------------------------------------------------------------------------------------------
// The hard grid of the comparison: shape x scale ratio x tilt x elevation offset x beam width.

constexpr double BaseScale = 2.0; // mm: the long axis of a needle, the disc radius of a pancake
const double Ratios[] = { 1, 10, 100, 1e3, 1e4 };
const double Tilts[] = { 0, 1, 15, 45, 75, 89, 90 };
const double ElevationOffsets[] = { 0, 0.5, 2, 4 }; // in sqrt(P2[z,z])
const double BeamWidths[] = { 1e-4, 1e-2, 0.5, 5, 100 };

void ShapeScales(bool needle, double ratio, double s[3])
{
  s[0] = needle ? BaseScale : BaseScale / ratio;
  s[1] = s[2] = needle ? BaseScale / ratio : BaseScale;
}

/// The case with its mean placed `offset` elevation standard deviations (sqrt(P2[z,z])) off the plane.
Case MakeGridCase(bool needle, double ratio, double tilt, double offset, double sigmaE)
{
  double s[3];
  ShapeScales(needle, ratio, s);
  const double origin[3] = { 12.5, -31.25, 47.0 };
  const double m0[3] = { 0, 0, 0 };
  Case c = MakeCase(s, tilt, 37, 23, m0, GenericSliceRotation(), origin, sigmaE);
  // P2[z,z] from the case as built: the same numbers SetupFootprint will see.
  bigus::SetupCache cache;
  bigus::SetupFootprint(c.G, c.Frame, sigmaE, 1e3, &cache);
  const double m[3] = { 0.3 * BaseScale, -0.2 * BaseScale, offset * std::sqrt(cache.Pzz2) };
  return MakeCase(s, tilt, 37, 23, m, GenericSliceRotation(), origin, sigmaE);
}

std::string Describe(bool needle, double ratio, double tilt, double offset, double sigmaE)
{
  char text[160];
  std::snprintf(text, sizeof(text), "%s ratio %g tilt %g deg m_z %g sd sigma_E %g mm", needle ? "needle" : "pancake",
    ratio, tilt, offset, sigmaE);
  return text;
}

/// Worst relative error of a family and where it occurred.
struct Worst
{
  double Error = 0;
  std::string Where;
  void Add(double e, const std::string& where)
  {
    if (!(e <= this->Error)) // NaN counts as worst
    {
      this->Error = e;
      this->Where = where;
    }
  }
};

/**
 * Accuracy asked of w(p). 1e-9 relative, except where the footprint is so elongated in the plane that
 * the conic (a, b, c) itself cannot hold it: rounding a, b, c to double moves q by about
 * eps (|a| dx^2 + 2 |b dx dy| + |c| dy^2), which along the major axis is eps * aspect^2 * q (measured:
 * 6e-8 at aspect 1e4, where even the exact conic rounded to double gives 3e-8; see
 * ConicRoundingIsTheLimit). That allowance is granted only to the scale ratio 1e4, and is reported.
 */
double WeightTolerance(double ratio, const Footprint& f, double dx, double dy)
{
  if (ratio < 1e4)
  {
    return 1e-9;
  }
  const double magnitude =
    std::abs(f.Conic[0]) * dx * dx + 2 * std::abs(f.Conic[1] * dx * dy) + std::abs(f.Conic[2]) * dy * dy;
  return 1e-9 + 8 * std::numeric_limits<double>::epsilon() * magnitude;
}

std::string Family(bool needle, double ratio)
{
  char text[48];
  std::snprintf(text, sizeof(text), "%s ratio %g", needle ? "needle" : "pancake", ratio);
  return text;
}

std::string Where(const std::string& what, const std::array<double, 2>& d)
{
  char text[64];
  std::snprintf(text, sizeof(text), ", offset (%.4g, %.4g) mm", d[0], d[1]);
  return what + text;
}

void Report(const char* title, const std::vector<std::string>& order, std::map<std::string, Worst>& families)
{
  std::printf("%s\n", title);
  for (const auto& name : order)
  {
    std::printf("  %-20s %.3e  (%s)\n", name.c_str(), families[name].Error, families[name].Where.c_str());
    char value[32];
    std::snprintf(value, sizeof(value), "%.3e", families[name].Error);
    std::string key = name;
    std::replace(key.begin(), key.end(), ' ', '_');
    testing::Test::RecordProperty(key, value);
  }
}

/// Absolute elevation integral of one grid point, by quadrature in T.
template <typename T>
T OracleAt(const Case& c, double px, double py, double sigmaE)
{
  return ElevationIntegral<T>(MakeLocal<T>(c.G, c.Frame), T(px), T(py), T(sigmaE),
    std::is_same<T, double>::value ? T(OracleTolerance) : T(1e-17L));
}
} // namespace

// ---------------------------------------------------------------------------------------------

// The oracle's own accuracy, so that a disagreement below can be blamed on the closed form.
TEST(GaussianFootprint, OracleQuadratureIsExactOnKnownIntegrals)
{
  // K15 integrates polynomials up to degree 22 exactly.
  for (int degree = 0; degree <= 22; degree += 2)
  {
    long double err;
    const long double r = Kronrod15<long double>([&](long double x) { return std::pow(x, degree); }, -1.0L, 1.0L, &err);
    EXPECT_NEAR(static_cast<double>(r * (degree + 1) / 2), 1.0, 1e-17) << "degree " << degree;
  }
  // A Gaussian of any width and place integrates to sqrt(2 pi) sigma, even with a rough peak guess.
  for (double sigma : { 1e-6, 1e-2, 1.0, 1e4 })
  {
    for (double guess : { 0.0, 0.7, -3.0 })
    {
      const double mean = 0.37 * sigma;
      auto f = [&](double x) { return std::exp(-0.5 * ((x - mean) / sigma) * ((x - mean) / sigma)); };
      const double r = IntegrateLine<double>(f, mean + guess * sigma, sigma, OracleTolerance);
      EXPECT_NEAR(r / (std::sqrt(2 * Pi) * sigma), 1.0, 2e-15) << "sigma " << sigma << " guess " << guess;
    }
  }
}

// Item 1 of the brief: every hard case, every point within 3 footprint sigmas.
TEST(GaussianFootprint, ClosedFormMatchesElevationQuadrature)
{
  std::map<std::string, Worst> families;
  std::map<std::string, std::array<double, 7>> worstCase; // tilt, offset, sigmaE, dx, dy, needle, ratio
  std::vector<std::string> order;
  int compared = 0;
  for (bool needle : { true, false })
  {
    for (double ratio : Ratios)
    {
      const std::string family = Family(needle, ratio);
      order.push_back(family);
      for (double tilt : Tilts)
      {
        for (double offset : ElevationOffsets)
        {
          for (double sigmaE : BeamWidths)
          {
            const std::string what = Describe(needle, ratio, tilt, offset, sigmaE);
            const Case c = MakeGridCase(needle, ratio, tilt, offset, sigmaE);
            const Footprint f = bigus::SetupFootprint(c.G, c.Frame, sigmaE, 1e3, nullptr);
            ASSERT_TRUE(f.Visible) << what;
            for (const auto& d : FootprintOffsets(f))
            {
              const double px = f.Center[0] + d[0], py = f.Center[1] + d[1];
              const double dx = px - f.Center[0], dy = py - f.Center[1];
              const double oracle = OracleAt<double>(c, px, py, sigmaE);
              ASSERT_GE(oracle, 1e-6 * f.Amplitude) << Where(what, d); // 3 sigma: e^-4.5 of the peak
              const double w = ClosedFormWeight(f, dx, dy);
              const double e = std::abs(w - oracle) / oracle;
              EXPECT_LE(e, WeightTolerance(ratio, f, dx, dy)) << Where(what, d) << ": w " << w << " oracle " << oracle;
              if (!(e <= families[family].Error))
              {
                worstCase[family] = { tilt, offset, sigmaE, d[0], d[1], needle ? 1.0 : 0.0, ratio };
              }
              families[family].Add(e, Where(what, d));
              ++compared;
            }
          }
        }
      }
    }
  }
  std::printf("%d points compared.\n", compared);
  Report("Closed form vs elevation quadrature, worst relative error per family:", order, families);

  // At each family's worst point the double oracle must agree with a long double one far below the
  // error it reports, or that error would belong to the quadrature.
  std::printf("Oracle check at those points (|double oracle - long double oracle| / w):\n");
  for (const auto& name : order)
  {
    const auto& k = worstCase[name];
    const Case c = MakeGridCase(k[5] > 0, k[6], k[0], k[1], k[2]);
    const Footprint f = bigus::SetupFootprint(c.G, c.Frame, k[2], 1e3, nullptr);
    const double px = f.Center[0] + k[3], py = f.Center[1] + k[4];
    const long double precise = OracleAt<long double>(c, px, py, k[2]);
    const double rough = OracleAt<double>(c, px, py, k[2]);
    const double oracleError = static_cast<double>(std::abs((rough - precise) / precise));
    std::printf("  %-20s %.2e\n", name.c_str(), oracleError);
    EXPECT_LE(oracleError, 1e-10) << name;
  }
}

// Why the ratio-1e4 families fall short of 1e-9. The exact conic (the paper's Schur complement, in long
// double from the scales) evaluated in long double meets the oracle; the same conic merely rounded to
// three doubles misses it by as much as SetupFootprint's does. So the loss (eps * aspect^2 along one
// axis) belongs to the (a, b, c) representation, not to the closed form's arithmetic.
TEST(GaussianFootprint, ConicRoundingIsTheLimit)
{
  using LD = long double;
  if (std::numeric_limits<LD>::digits <= std::numeric_limits<double>::digits)
  {
    GTEST_SKIP() << "long double is no wider than double here";
  }
  for (bool needle : { true, false })
  {
    double exactError = 0, roundedError = 0, closedFormError = 0, roundedDoubleError = 0;
    for (double tilt : Tilts)
    {
      for (double offset : ElevationOffsets)
      {
        for (double sigmaE : { 1e-4, 0.5, 100.0 })
        {
          const Case c = MakeGridCase(needle, 1e4, tilt, offset, sigmaE);
          const Footprint f = bigus::SetupFootprint(c.G, c.Frame, sigmaE, 1e3, nullptr);
          const LocalGaussian<LD> L = MakeLocal<LD>(c.G, c.Frame);
          LD Lambda[3][3];
          for (int i = 0; i < 3; ++i)
          {
            for (int j = 0; j < 3; ++j)
            {
              Lambda[i][j] = 0;
              for (int k = 0; k < 3; ++k)
              {
                Lambda[i][j] += L.Rp[i][k] * L.Rp[j][k] / (L.s[k] * L.s[k]);
              }
            }
          }
          const LD denominator = Lambda[2][2] + 1 / (LD(sigmaE) * sigmaE);
          const LD exact[3] = { Lambda[0][0] - Lambda[0][2] * Lambda[0][2] / denominator,
            Lambda[0][1] - Lambda[0][2] * Lambda[1][2] / denominator,
            Lambda[1][1] - Lambda[1][2] * Lambda[1][2] / denominator };
          const LD rounded[3] = { LD(double(exact[0])), LD(double(exact[1])), LD(double(exact[2])) };
          for (const auto& d : FootprintOffsets(f))
          {
            const double px = f.Center[0] + d[0], py = f.Center[1] + d[1];
            const LD dx = px - f.Center[0], dy = py - f.Center[1];
            const LD oracle = OracleAt<LD>(c, px, py, sigmaE);
            auto weight = [&](const LD conic[3]) {
              return f.Amplitude * std::exp(-(conic[0] * dx * dx + 2 * conic[1] * dx * dy + conic[2] * dy * dy) / 2);
            };
            exactError = std::max(exactError, double(std::abs(weight(exact) / oracle - 1)));
            roundedError = std::max(roundedError, double(std::abs(weight(rounded) / oracle - 1)));
            const LD closedForm = ClosedFormWeight(f, double(dx), double(dy));
            const LD roundedDouble = bigus::PixelWeight<double>(
              f.Amplitude, double(exact[0]), double(exact[1]), double(exact[2]), double(dx), double(dy));
            roundedDoubleError = std::max(roundedDoubleError, double(std::abs(roundedDouble / oracle - 1)));
            closedFormError = std::max(closedFormError, double(std::abs(closedForm / oracle - 1)));
          }
        }
      }
    }
    std::printf("%s ratio 1e4, worst relative error of w with: exact conic %.2e, exact conic rounded to double "
                "%.2e, exact conic rounded and evaluated in double %.2e, SetupFootprint's conic %.2e\n",
      needle ? "needle" : "pancake", exactError, roundedError, roundedDoubleError, closedFormError);
    EXPECT_LE(exactError, 1e-10);
    EXPECT_GT(roundedError, 1e-9); // the representation's own limit; if this fails, retighten the grid test
    EXPECT_LE(closedFormError, 4 * roundedDoubleError); // within a small factor of the best (a, b, c) can do
  }
}

// Item 2a: a vanishing beam samples the 3D Gaussian on the plane (the UltraGauss ablation).
TEST(GaussianFootprint, ThinBeamGivesTheGaussianOnThePlane)
{
  std::map<std::string, Worst> families;
  std::vector<std::string> order;
  // sigma_E = 1e-6 mm differs from the plane by O(sigma_E^2 Lambda_zz) = 2.5e-11 at s_min = 0.2 mm;
  // sigma_E = 0 is the plane exactly, so it takes the whole hard grid.
  for (double sigmaE : { 1e-6, 0.0 })
  {
    for (bool needle : { true, false })
    {
      for (double ratio : Ratios)
      {
        if (sigmaE > 0 && ratio > 10)
        {
          continue;
        }
        const std::string family = Family(needle, ratio) + (sigmaE > 0 ? " sE 1e-6" : " sE 0");
        order.push_back(family);
        for (double tilt : Tilts)
        {
          for (double offset : ElevationOffsets)
          {
            const std::string what = Describe(needle, ratio, tilt, offset, sigmaE);
            const Case c = MakeGridCase(needle, ratio, tilt, offset, sigmaE);
            const Footprint f = bigus::SetupFootprint(c.G, c.Frame, sigmaE, 1e3, nullptr);
            ASSERT_TRUE(f.Visible) << what;
            const LocalGaussian<double> L = MakeLocal<double>(c.G, c.Frame);
            for (const auto& d : FootprintOffsets(f))
            {
              const double px = f.Center[0] + d[0], py = f.Center[1] + d[1];
              const double dx = px - f.Center[0], dy = py - f.Center[1];
              const double plane = std::exp(-0.5 * L.Exponent(px, py, 0));
              const double w = ClosedFormWeight(f, dx, dy);
              const double e = std::abs(w - plane) / plane;
              EXPECT_LE(e, WeightTolerance(ratio, f, dx, dy)) << Where(what, d);
              families[family].Add(e, Where(what, d));
            }
          }
        }
      }
    }
  }
  Report("Thin beam vs the 3D Gaussian at z = 0, worst relative error per family:", order, families);
}

// Item 2b: a very wide beam sees the projection of the Gaussian along the elevation, times the beam's
// density at the plane: sigma_E sqrt(2 pi) w(p) = integral of G(p, z) exp(-z^2 / 2 sigma_E^2) dz, which
// falls short of the projection by a fraction in [0, E[z^2] / (2 sigma_E^2)] (E over G(p, .)).
TEST(GaussianFootprint, WideBeamGivesTheProjection)
{
  const double sigmaE = 1e4;
  std::map<std::string, Worst> families;
  std::vector<std::string> order;
  double largestShortfall = 0;
  for (bool needle : { true, false })
  {
    for (double ratio : Ratios)
    {
      const std::string family = Family(needle, ratio);
      order.push_back(family);
      for (double tilt : Tilts)
      {
        const std::string what = Describe(needle, ratio, tilt, 0, sigmaE);
        const Case c = MakeGridCase(needle, ratio, tilt, 0, sigmaE);
        const Footprint f = bigus::SetupFootprint(c.G, c.Frame, sigmaE, 1e3, nullptr);
        ASSERT_TRUE(f.Visible) << what;
        const LocalGaussian<double> L = MakeLocal<double>(c.G, c.Frame);
        for (const auto& d : FootprintOffsets(f))
        {
          const double px = f.Center[0] + d[0], py = f.Center[1] + d[1];
          const double dx = px - f.Center[0], dy = py - f.Center[1];
          const double projection = ElevationIntegral<double>(L, px, py, 0.0, OracleTolerance);
          const double z2 = ElevationIntegral<double>(L, px, py, 0.0, OracleTolerance, true) / projection;
          const double bound = z2 / (2 * sigmaE * sigmaE);
          const double ratioToProjection = sigmaE * std::sqrt(2 * Pi) * ClosedFormWeight(f, dx, dy) / projection;
          const double tol = WeightTolerance(ratio, f, dx, dy);
          EXPECT_LE(ratioToProjection, 1 + tol) << Where(what, d);
          EXPECT_GE(ratioToProjection, 1 - bound - tol) << Where(what, d);
          largestShortfall = std::max(largestShortfall, 1 - ratioToProjection);
          // Error beyond what the finite beam explains.
          const double e = std::max(ratioToProjection - 1, 1 - bound - ratioToProjection);
          families[family].Add(std::max(e, 0.0), Where(what, d));
        }
      }
    }
  }
  Report("Wide beam (1e4 mm) vs projection, worst relative error beyond the finite-beam bound:", order, families);
  std::printf("  largest shortfall of sigma_E sqrt(2 pi) w below the projection: %.3e\n", largestShortfall);
}

// Item 3: the paper's Eq. 8-11 (Schur complement of the precision matrix, parallax vector), times the
// beam normalisation sqrt(lambda_E / 2 pi). Lambda comes from the scales, never from inverting P.
TEST(GaussianFootprint, ClosedFormEqualsThePapersSchurComplementForm)
{
  double worstConic = 0, worstCentre = 0, worstAmp = 0, worstWeight = 0;
  for (bool needle : { true, false })
  {
    for (double ratio : { 1.0, 10.0, 100.0 })
    {
      for (double tilt : Tilts)
      {
        for (double offset : ElevationOffsets)
        {
          for (double sigmaE : BeamWidths)
          {
            const std::string what = Describe(needle, ratio, tilt, offset, sigmaE);
            const Case c = MakeGridCase(needle, ratio, tilt, offset, sigmaE);
            const Footprint f = bigus::SetupFootprint(c.G, c.Frame, sigmaE, 1e3, nullptr);
            ASSERT_TRUE(f.Visible) << what;
            const LocalGaussian<double> L = MakeLocal<double>(c.G, c.Frame);
            double Lambda[3][3];
            for (int i = 0; i < 3; ++i)
            {
              for (int j = 0; j < 3; ++j)
              {
                Lambda[i][j] = 0;
                for (int k = 0; k < 3; ++k)
                {
                  Lambda[i][j] += L.Rp[i][k] * L.Rp[j][k] / (L.s[k] * L.s[k]);
                }
              }
            }
            const double b[2] = { Lambda[0][2], Lambda[1][2] }, cz = Lambda[2][2];
            const double lambdaE = 1 / (sigmaE * sigmaE);
            const double denominator = cz + lambdaE;
            // Schur complement S = A - b b^T / (c + lambda_E).
            const double S[3] = { Lambda[0][0] - b[0] * b[0] / denominator, Lambda[0][1] - b[0] * b[1] / denominator,
              Lambda[1][1] - b[1] * b[1] / denominator };
            const double detS = S[0] * S[2] - S[1] * S[1];
            // Completing the square in p: parallax e = lambda_E m_z S^-1 b / (c + lambda_E).
            const double k = lambdaE * L.m[2] / denominator;
            const double e[2] = { k * (S[2] * b[0] - S[1] * b[1]) / detS, k * (S[0] * b[1] - S[1] * b[0]) / detS };
            const double centre[2] = { L.m[0] + e[0], L.m[1] + e[1] };
            // The integral before completing the square, so the amplitude is not borrowed from the centre.
            auto paper = [&](double px, double py) {
              const double d0 = px - L.m[0], d1 = py - L.m[1];
              const double exponent = S[0] * d0 * d0 + 2 * S[1] * d0 * d1 + S[2] * d1 * d1 -
                2 * k * (b[0] * d0 + b[1] * d1) + lambdaE * cz * L.m[2] * L.m[2] / denominator;
              return std::sqrt(lambdaE / denominator) * std::exp(-0.5 * exponent);
            };
            for (int i = 0; i < 3; ++i)
            {
              const double scale = std::sqrt(std::abs(S[i == 2 ? 2 : 0] * S[i == 0 ? 0 : 2]));
              const double err = std::abs(f.Conic[i] - S[i]) / scale;
              worstConic = std::max(worstConic, err);
              EXPECT_LE(err, 1e-10) << what << " conic " << i;
            }
            // Centre error measured in footprint standard deviations.
            const double dc[2] = { f.Center[0] - centre[0], f.Center[1] - centre[1] };
            const double centreError =
              std::sqrt(std::abs(S[0] * dc[0] * dc[0] + 2 * S[1] * dc[0] * dc[1] + S[2] * dc[1] * dc[1]));
            worstCentre = std::max(worstCentre, centreError);
            EXPECT_LE(centreError, 1e-10) << what;
            const double ampError = std::abs(f.Amplitude - paper(centre[0], centre[1])) / f.Amplitude;
            worstAmp = std::max(worstAmp, ampError);
            EXPECT_LE(ampError, 1e-10) << what;
            for (const auto& d : FootprintOffsets(f))
            {
              const double px = f.Center[0] + d[0], py = f.Center[1] + d[1];
              const double reference = paper(px, py);
              const double err =
                std::abs(ClosedFormWeight(f, px - f.Center[0], py - f.Center[1]) - reference) / reference;
              worstWeight = std::max(worstWeight, err);
              EXPECT_LE(err, 1e-10) << Where(what, d);
            }
          }
        }
      }
    }
  }
  std::printf("Paper form (ratios <= 100): conic %.2e, centre %.2e sd, amp %.2e, w %.2e\n", worstConic, worstCentre,
    worstAmp, worstWeight);
}

namespace
{
/// Largest minus smallest log-scale as SetupFootprint uses them (clamped, NaN as 0).
double ClampedLogScaleGap(const GaussianParams& g)
{
  double lo = 1e300, hi = -1e300;
  for (double l : g.LogScale)
  {
    const double c = l == l ? std::min(std::max(l, bigus::MinimumLogScale), bigus::MaximumLogScale) : 0.0;
    lo = std::min(lo, c);
    hi = std::max(hi, c);
  }
  return hi - lo;
}

bool Finite(const Footprint& f)
{
  const double v[] = { f.Center[0], f.Center[1], f.Conic[0], f.Conic[1], f.Conic[2], f.Cov[0], f.Cov[1], f.Cov[2],
    f.Amplitude, f.Elevation, f.ElevationVar };
  return std::all_of(std::begin(v), std::end(v), [](double x) { return std::isfinite(x); });
}
}

// Item 4: whatever the parameters (an optimiser will try them all), no NaN or Inf leaves the setup or
// the pixel weight, and what lies far off the plane vanishes.
TEST(GaussianFootprint, NoNaNOrInfOnExtremeParameters)
{
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double logScales[] = { -40, -25, -3, 0, 2, 25, 40, nan };
  const double quaternionNorms[] = { 1, 1e-12, 1e-3, 1e3, 1e12, 0 };
  const double beams[] = { 0, 1e-4, 100 };
  const double origins[2][3] = { { 0, 0, 0 }, { 577.35, -577.35, 577.35 } }; // the second 1 m out
  const double elevations[] = { 0, 0.05, 3, 1e3 };                           // mm off the plane
  int setups = 0, visible = 0, weights = 0, farVisible = 0, aboveAmplitude = 0, nonFinite = 0, nanOrNegative = 0;
  std::string firstNonFinite, firstNanOrNegative;
  double smallestBadGap = std::numeric_limits<double>::infinity();
  double worstExcess = 0;
  std::string worstExcessWhere;
  for (const auto& origin : origins)
  {
    for (double l0 : logScales)
    {
      for (double l1 : logScales)
      {
        for (double l2 : { -25.0, 0.0, 40.0, nan })
        {
          for (double norm : quaternionNorms)
          {
            for (double tilt : { 0.0, 30.0, 90.0 })
            {
              for (double mz : elevations)
              {
                for (double sigmaE : beams)
                {
                  const double s[3] = { 1, 1, 1 };
                  const double m[3] = { 0.4, -0.7, mz };
                  Case c = MakeCase(s, tilt, 37, 23, m, GenericSliceRotation(), origin, sigmaE);
                  c.G.LogScale[0] = l0;
                  c.G.LogScale[1] = l1;
                  c.G.LogScale[2] = l2;
                  for (double& q : c.G.Quaternion)
                  {
                    q *= norm;
                  }
                  for (double cutoff : { 3.0, 1e200 })
                  {
                    const Footprint f = bigus::SetupFootprint(c.G, c.Frame, sigmaE, cutoff, nullptr);
                    ++setups;
                    char what[200];
                    std::snprintf(what, sizeof(what),
                      "log-scales (%g, %g, %g) |q| %g tilt %g m_z %g sigma_E %g origin %g cutoff %g", l0, l1, l2, norm,
                      tilt, mz, sigmaE, origin[0], cutoff);
                    EXPECT_TRUE(std::isfinite(f.Elevation) && !std::isnan(f.ElevationVar)) << what;
                    if (!f.Visible)
                    {
                      continue;
                    }
                    ++visible;
                    ASSERT_TRUE(Finite(f)) << what;
                    EXPECT_GE(f.Amplitude, 0) << what;
                    EXPECT_LE(f.Amplitude, 1) << what;
                    // Far: exp(-m_z^2 / 2 P2[z,z]) below the smallest double (e^-745).
                    if (mz * mz > 1500 * f.ElevationVar && f.Amplitude > 0)
                    {
                      ++farVisible;
                    }
                    const Axes ax = FootprintAxes(f);
                    for (double k : { 0.0, 1.0, 3.0, 10.0 })
                    {
                      for (int axis = 0; axis < 2; ++axis)
                      {
                        const double* u = axis == 0 ? ax.Major : ax.Minor;
                        const double r = k * (axis == 0 ? ax.SigmaMajor : ax.SigmaMinor);
                        const double w = ClosedFormWeight(f, r * u[0], r * u[1]);
                        ++weights;
                        // NaN, Inf or a weight above the peak all come from an indefinite conic (see
                        // ExtremeAnisotropyKeepsTheWeightBounded; NaN is 0 amp times an infinite
                        // exponential): counted, one example of each kept, asserted below.
                        if (std::isnan(w) || !(w <= f.Amplitude * (1 + 1e-12)))
                        {
                          smallestBadGap = std::min(smallestBadGap, ClampedLogScaleGap(c.G));
                        }
                        const std::string at =
                          std::string(what) + ", " + std::to_string(k) + " sigma on axis " + std::to_string(axis);
                        if (std::isnan(w) || w < 0)
                        {
                          if (nanOrNegative++ == 0)
                          {
                            firstNanOrNegative = at;
                          }
                        }
                        else if (!std::isfinite(w))
                        {
                          if (nonFinite++ == 0)
                          {
                            firstNonFinite = at;
                          }
                        }
                        else if (w > f.Amplitude * (1 + 1e-12))
                        {
                          ++aboveAmplitude;
                          if (w / f.Amplitude > worstExcess)
                          {
                            worstExcess = w / f.Amplitude;
                            worstExcessWhere = at;
                          }
                        }
                      }
                    }
                  }
                }
              }
            }
          }
        }
      }
    }
  }
  std::printf(
    "%d setups, %d visible, %d weights; amp > 0 beyond 38.7 elevation sd: %d\n", setups, visible, weights, farVisible);
  std::printf("weights above the amplitude: %d (worst w / amp = %.3e: %s)\n", aboveAmplitude, worstExcess,
    worstExcessWhere.c_str());
  std::printf("smallest log-scale gap (after clamping) with a bad weight: %g\n", smallestBadGap);
  std::printf("NaN or negative weights: %d (first: %s)\n", nanOrNegative, firstNanOrNegative.c_str());
  std::printf("infinite weights: %d (first: %s)\n", nonFinite, firstNonFinite.c_str());
  EXPECT_EQ(farVisible, 0);
  EXPECT_EQ(nanOrNegative, 0) << "first: " << firstNanOrNegative;
  EXPECT_EQ(nonFinite, 0) << "first: " << firstNonFinite;
  EXPECT_EQ(aboveAmplitude, 0) << "worst w / amp " << worstExcess << ": " << worstExcessWhere;
}

// The smallest reproduction of what the grid above finds. A needle lying in the plane with its thin
// axes e^-gap of its long one: the log-scale clamp (+-25) lets the gap reach 50, but cov2 = B B^T rounded
// to double stops being positive definite near aspect 1 / sqrt(eps) ~ 1e8 (gap ~ 19), and its adjugate,
// the conic, turns indefinite. No three doubles hold such an ellipse exactly; what is asked here is only
// that the weight stays finite and at most the peak.
TEST(GaussianFootprint, AQuaternionIsNormalisedAndACollapsedOneIsTheIdentity)
{
  // (0, 3, 0, 4) has length 5; a zero, denormal-small or non-finite quaternion is the identity rotation, so the
  // renderer, densification and the merge turn such a Gaussian alike.
  const double q[4] = { 0, 3, 0, 4 };
  double qn[4];
  EXPECT_DOUBLE_EQ(bigus::NormalizeQuaternion(q, qn), 5.0);
  EXPECT_DOUBLE_EQ(qn[0], 0.0);
  EXPECT_DOUBLE_EQ(qn[1], 0.6);
  EXPECT_DOUBLE_EQ(qn[2], 0.0);
  EXPECT_DOUBLE_EQ(qn[3], 0.8);
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  const double collapsed[4][4] = { { 0, 0, 0, 0 }, { 1e-20, 0, 0, 0 }, { nan, 0, 0, 1 }, { inf, 1, 0, 0 } };
  for (const auto& c : collapsed)
  {
    double in[4] = { c[0], c[1], c[2], c[3] };
    EXPECT_EQ(bigus::NormalizeQuaternion(in, in), 0.0);
    EXPECT_EQ(in[0], 1.0);
    EXPECT_EQ(in[1], 0.0);
    EXPECT_EQ(in[2], 0.0);
    EXPECT_EQ(in[3], 0.0);
  }
}

TEST(GaussianFootprint, ExtremeAnisotropyKeepsTheWeightBounded)
{
  int bad = 0;
  std::string table;
  for (double gap = 10; gap <= 50; gap += 1)
  {
    GaussianParams g{};
    SliceFrameD frame{};
    for (int i = 0; i < 3; ++i)
    {
      frame.F[i][i] = 1;
    }
    g.Mean[0] = 0.4;
    g.Mean[1] = -0.7;
    g.LogScale[1] = g.LogScale[2] = -gap;
    g.Quaternion[0] = std::cos(Radians(15)); // long axis at 30 degrees in the plane
    g.Quaternion[3] = std::sin(Radians(15));
    const Footprint f = bigus::SetupFootprint(g, frame, 1e-4, 3, nullptr);
    ASSERT_TRUE(f.Visible);
    const double c = std::cos(Radians(30)), s = std::sin(Radians(30));
    const double one = ClosedFormWeight(f, c, s) / f.Amplitude;
    char row[96];
    std::snprintf(row, sizeof(row), "  gap %2g: w(1 sd on the long axis) / amp = %.6g\n", gap, one);
    table += row;
    for (double k : { 1.0, 3.0, 10.0 })
    {
      const double w = ClosedFormWeight(f, k * c, k * s) / f.Amplitude;
      if (!(w <= 1) && bad++ < 3) // catches Inf and NaN too
      {
        ADD_FAILURE() << "log-scales (0, " << -gap << ", " << -gap << "), sigma_E 1e-4: conic (" << f.Conic[0] << ", "
                      << f.Conic[1] << ", " << f.Conic[2] << "), w(" << k << " sd on the long axis) / amp = " << w
                      << " (exact " << std::exp(-0.5 * k * k) << ")";
      }
    }
  }
  std::printf("exact e^-1/2 = %.6g\n%s", std::exp(-0.5), table.c_str());
  EXPECT_EQ(bad, 0) << "weights above the peak or not finite, for log-scale gaps 10 to 50";
}

// Item 5: the slice origin comes off first, so 1 m from the reference origin costs nothing.
TEST(GaussianFootprint, LargeCoordinatesLoseNoPrecision)
{
  const double T[3] = { 1000, 1000, 1000 };
  double worst = 0;
  for (double scale : { 1e-3, 0.5, 20.0 })
  {
    for (double sigmaE : { 0.0, 1e-4, 0.5, 100.0 })
    {
      const double s[3] = { scale, 0.3 * scale, 0.05 * scale };
      // The slice origin 0.3 mm from the Gaussian, mostly in the plane: the Gaussian sits half an
      // elevation sd (at most 0.1 mm) off it, so that even the 1 um one is seen.
      const double zero[3] = { 0, 0, 0 };
      bigus::SetupCache cache;
      const Case probe = MakeCase(s, 30, 37, 23, zero, GenericSliceRotation(), zero, sigmaE);
      bigus::SetupFootprint(probe.G, probe.Frame, sigmaE, 1e3, &cache);
      const double mz = std::min(0.5 * std::sqrt(cache.Pzz2), 0.1);
      const double m[3] = { 0.24, -std::sqrt(0.3 * 0.3 - 0.24 * 0.24 - mz * mz), mz };
      // Far: the Gaussian at T. Near: the same pair moved by -T, which is exact (Sterbenz), so both
      // describe the same geometry to the last bit.
      double farOrigin[3], nearOrigin[3];
      for (int k = 0; k < 3; ++k)
      {
        farOrigin[k] = T[k] - (probe.Frame.F[0][k] * m[0] + probe.Frame.F[1][k] * m[1] + probe.Frame.F[2][k] * m[2]);
        nearOrigin[k] = farOrigin[k] - T[k];
      }
      Case far = MakeCase(s, 30, 37, 23, zero, GenericSliceRotation(), farOrigin, sigmaE);
      Case near = MakeCase(s, 30, 37, 23, zero, GenericSliceRotation(), nearOrigin, sigmaE);
      for (int k = 0; k < 3; ++k)
      {
        far.G.Mean[k] = T[k];
        near.G.Mean[k] = 0;
      }
      const Footprint a = bigus::SetupFootprint(far.G, far.Frame, sigmaE, 1e3, nullptr);
      const Footprint b = bigus::SetupFootprint(near.G, near.Frame, sigmaE, 1e3, nullptr);
      ASSERT_TRUE(a.Visible && b.Visible) << "scale " << scale << " sigma_E " << sigmaE;
      ASSERT_GT(b.Amplitude, 0) << "scale " << scale << " sigma_E " << sigmaE;
      // Centres relative to their distance from the slice origin, or to the footprint's width if
      // that is larger; conic entries relative to sqrt(a c).
      const double width = std::sqrt(std::max(b.Cov[0], b.Cov[2]));
      const double conicScale = std::sqrt(b.Conic[0] * b.Conic[2]);
      const double errors[] = { std::abs(a.Center[0] - b.Center[0]) / std::max(std::abs(b.Center[0]), width),
        std::abs(a.Center[1] - b.Center[1]) / std::max(std::abs(b.Center[1]), width),
        std::abs(a.Conic[0] - b.Conic[0]) / conicScale, std::abs(a.Conic[1] - b.Conic[1]) / conicScale,
        std::abs(a.Conic[2] - b.Conic[2]) / conicScale, std::abs(a.Amplitude - b.Amplitude) / b.Amplitude,
        std::abs(a.Elevation - b.Elevation) / std::abs(b.Elevation) };
      for (double e : errors)
      {
        EXPECT_LE(e, 1e-12) << "scale " << scale << " sigma_E " << sigmaE;
        worst = std::max(worst, e);
      }
    }
  }
  std::printf("1 m from the origin vs at the origin: worst relative difference %.3e\n", worst);
}

// Item 6: the float exponential of the CPU backend's inner loop.
TEST(GaussianFootprint, FastExpMatchesStdExp)
{
  const int n = 1000000;
  double worst = 0, at = 0;
  for (int i = 0; i < n; ++i)
  {
    const float x = static_cast<float>(-87.0 * i / (n - 1));
    const double exact = std::exp(static_cast<double>(x));
    const double e = std::abs(static_cast<double>(bigus::FastExp(x)) - exact) / exact;
    if (!(e <= worst))
    {
      worst = e;
      at = x;
    }
  }
  std::printf("FastExp worst relative error on [-87, 0]: %.3e at x = %.7g\n", worst, at);
  EXPECT_LT(worst, 2.6e-7) << "at x = " << at;
}

// The header promises 2.6e-7 on [-87, 0]; a scan of every float there (18 s, so not repeated here)
// found its worst at this input. Kept apart so that the claim, not the grid above, is what fails.
TEST(GaussianFootprint, FastExpBoundHoldsAtTheWorstFloat)
{
  const float x = -26.6860046f;
  const double exact = std::exp(static_cast<double>(x));
  const double e = std::abs(static_cast<double>(bigus::FastExp(x)) - exact) / exact;
  std::printf("FastExp relative error at x = %.9g: %.4e\n", x, e);
  EXPECT_LT(e, 2.6e-7);
}

// ---------------------------------------------------------------------------------------------
// Pose refinement: the corrected slice frame against a known motion, and the gradient with respect to
// the correction against central differences of the footprint.

namespace
{
/// Reference position (mm) of slice point p (slice coordinates, mm) of @p frame: o + F^T p.
void SlicePoint(const SliceFrameD& frame, const double p[3], double x[3])
{
  for (int k = 0; k < 3; ++k)
  {
    x[k] = frame.Origin[k] + frame.F[0][k] * p[0] + frame.F[1][k] * p[1] + frame.F[2][k] * p[2];
  }
}
}

// A quarter turn about the slice normal through the pivot, then a shift: every point of the slice goes
// where the rigid motion p -> E (p - pivot) + pivot + t, written out by hand, takes it; F stays orthonormal.
TEST(SlicePose, ACorrectionMovesTheSliceRigidlyAboutItsPivot)
{
  const Case c = MakeGridCase(true, 1, 0, 0, 0.5);
  const double pivot[3] = { 20, 15, 0 };
  const double xi[6] = { 0, 0, Pi / 2, 1.0, -2.0, 0.5 };
  SliceFrameD moved;
  bigus::CorrectSliceFrame(c.Frame, pivot, xi, moved);
  const double points[3][3] = { { 0, 0, 0 }, { 20, 15, 0 }, { 33, 4, 0 } };
  for (const auto& p : points)
  {
    // A quarter turn about n: (x, y) -> (-y, x) about the pivot.
    const double expected[3] = { pivot[0] - (p[1] - pivot[1]) + xi[3], pivot[1] + (p[0] - pivot[0]) + xi[4],
      p[2] + xi[5] };
    double a[3], b[3];
    SlicePoint(moved, p, a);
    SlicePoint(c.Frame, expected, b);
    for (int k = 0; k < 3; ++k)
    {
      EXPECT_NEAR(a[k], b[k], 1e-12) << "point (" << p[0] << ", " << p[1] << "), axis " << k;
    }
  }
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      const double dot = moved.F[i][0] * moved.F[j][0] + moved.F[i][1] * moved.F[j][1] + moved.F[i][2] * moved.F[j][2];
      EXPECT_NEAR(dot, i == j ? 1.0 : 0.0, 1e-14);
    }
  }
  // No correction: the same frame, bit for bit.
  const double zero[6] = { 0, 0, 0, 0, 0, 0 };
  bigus::CorrectSliceFrame(c.Frame, pivot, zero, moved);
  EXPECT_EQ(std::memcmp(&moved, &c.Frame, sizeof(SliceFrameD)), 0);
}

// L = sum of random weights times the footprint's centre, conic and amplitude: dL/d(xi) from
// SetupFootprintBackward and SlicePoseBackward against a central difference of L over CorrectSliceFrame,
// on needles and pancakes, tilted, on and off the plane, with a pivot away from the Gaussian.
TEST(SlicePose, TheGradientWithRespectToTheCorrectionMatchesCentralDifferences)
{
  const double weights[6] = { 0.7, -1.3, 0.45, -0.8, 0.3, 1.9 }; // centre x, y, conic a, b, c, amplitude
  auto loss = [&](const Case& c, const SliceFrameD& frame) {
    const Footprint f = bigus::SetupFootprint(c.G, frame, c.SigmaE, 1e3, nullptr);
    return weights[0] * f.Center[0] + weights[1] * f.Center[1] + weights[2] * f.Conic[0] + weights[3] * f.Conic[1] +
      weights[4] * f.Conic[2] + weights[5] * f.Amplitude;
  };
  const double pivot[3] = { 7.5, -3.0, 0 };
  const double pixelToPlane[3] = { 0.6, 0.1, 0.55 }; // a sheared pixel, for the cases with a low-pass
  int cases = 0;
  for (bool needle : { true, false })
  {
    for (double ratio : { 1.0, 3.0 })
    {
      for (double tilt : { 0.0, 30.0, 75.0 })
      {
        for (double offset : { 0.0, 0.8 })
        {
          for (double lowPass : { 0.0, 0.5 })
          {
            Case c = MakeGridCase(needle, ratio, tilt, offset, 0.5);
            bigus::PixelLowPassCovariance(pixelToPlane, lowPass, c.Frame.LowPass);
            bigus::SetupCache cache;
            const Footprint f = bigus::SetupFootprint(c.G, c.Frame, c.SigmaE, 1e3, &cache);
            ASSERT_TRUE(f.Visible);
            bigus::FootprintGrad gf;
            gf.Center[0] = weights[0];
            gf.Center[1] = weights[1];
            // FootprintGrad's conic entries are dL/da, dL/db, dL/dc of q = a dx^2 + 2 b dx dy + c dy^2.
            gf.Conic[0] = weights[2];
            gf.Conic[1] = weights[3];
            gf.Conic[2] = weights[4];
            gf.Amplitude = weights[5];
            bigus::GaussianGrad gg{};
            bigus::SliceFrameGrad sg;
            bigus::SetupFootprintBackward(f, cache, c.Frame, c.SigmaE, gf, gg, &sg);
            double dxi[6] = { 0, 0, 0, 0, 0, 0 };
            bigus::SlicePoseBackward(cache, pivot, sg, dxi);
            double scale = 0;
            for (double v : dxi)
            {
              scale = std::max(scale, std::abs(v));
            }
            for (int k = 0; k < 6; ++k)
            {
              const double h = k < 3 ? 1e-6 : 1e-5; // rad, mm
              double xi[6] = { 0, 0, 0, 0, 0, 0 };
              SliceFrameD plus, minus;
              xi[k] = h;
              bigus::CorrectSliceFrame(c.Frame, pivot, xi, plus);
              xi[k] = -h;
              bigus::CorrectSliceFrame(c.Frame, pivot, xi, minus);
              const double numeric = (loss(c, plus) - loss(c, minus)) / (2 * h);
              EXPECT_NEAR(dxi[k], numeric, 1e-6 * std::max(1.0, scale))
                << Describe(needle, ratio, tilt, offset, c.SigmaE) << ", low-pass " << lowPass << ", component " << k;
            }
            ++cases;
          }
        }
      }
    }
  }
  EXPECT_EQ(cases, 48);
}

// The pixel low-pass (SliceFrameD::LowPass): the footprint's weight equals the point footprint's convolved with
// the normalised Gaussian kernel of covariance L, by quadrature over the kernel (the trapezoid rule on the
// whitened kernel's grid, spectrally accurate on a Gaussian integrand), on needles and pancakes, tilted, on and off
// the plane, through a sheared pixel; and the low-pass keeps the footprint's integral (its amplitude times
// 2 pi sqrt(det cov2)).
TEST(GaussianFootprint, ThePixelLowPassIsTheConvolutionWithItsKernel)
{
  const double pixelToPlane[3] = { 0.6, 0.1, 0.55 };
  double L[3];
  bigus::PixelLowPassCovariance(pixelToPlane, 0.5, L);
  EXPECT_NEAR(L[0], 0.5 * (0.36 + 0.01), 1e-15); // variance (a a^T + b b^T), a = (0.6, 0), b = (0.1, 0.55)
  EXPECT_NEAR(L[1], 0.5 * 0.055, 1e-15);
  EXPECT_NEAR(L[2], 0.5 * 0.3025, 1e-15);
  const double c00 = std::sqrt(L[0]), c10 = L[1] / c00, c11 = std::sqrt(L[2] - c10 * c10); // L = C C^T
  const double h = 0.04, reach = 9; // grid step and half-width in kernel standard deviations
  const int n = static_cast<int>(std::lround(reach / h));
  auto integral = [](const Footprint& f) {
    return f.Amplitude * 2 * Pi / std::sqrt(f.Conic[0] * f.Conic[2] - f.Conic[1] * f.Conic[1]);
  };
  int cases = 0;
  double worst = 0;
  for (bool needle : { true, false })
  {
    for (double ratio : { 1.0, 10.0 })
    {
      for (double tilt : { 0.0, 30.0, 75.0 })
      {
        for (double offset : { 0.0, 0.8 })
        {
          const Case c = MakeGridCase(needle, ratio, tilt, offset, 0.5);
          Case b = c;
          std::copy(L, L + 3, b.Frame.LowPass);
          const Footprint point = bigus::SetupFootprint(c.G, c.Frame, c.SigmaE, 1e3, nullptr);
          const Footprint blurred = bigus::SetupFootprint(b.G, b.Frame, b.SigmaE, 1e3, nullptr);
          ASSERT_TRUE(point.Visible && blurred.Visible);
          const std::string where = Describe(needle, ratio, tilt, offset, c.SigmaE);
          EXPECT_EQ(point.Center[0], blurred.Center[0]) << where;
          EXPECT_EQ(point.Center[1], blurred.Center[1]) << where;
          EXPECT_NEAR(integral(blurred), integral(point), 1e-12 * integral(point)) << where;
          for (const auto& d : FootprintOffsets(blurred, 3))
          {
            double sum = 0;
            for (int a = -n; a <= n; ++a)
            {
              for (int e = -n; e <= n; ++e)
              {
                const double za = a * h, ze = e * h;
                const double tx = c00 * za, ty = c10 * za + c11 * ze;
                sum += std::exp(-0.5 * (za * za + ze * ze)) * ClosedFormWeight(point, d[0] - tx, d[1] - ty);
              }
            }
            sum *= h * h / (2 * Pi);
            const double error = std::abs(ClosedFormWeight(blurred, d[0], d[1]) - sum) / point.Amplitude;
            worst = std::max(worst, error);
            EXPECT_LT(error, 1e-9) << where << Where("", d);
          }
          ++cases;
        }
      }
    }
  }
  EXPECT_EQ(cases, 24);
  std::printf("worst error of the low-passed weight against quadrature, relative to the amplitude: %.3g\n", worst);
}
