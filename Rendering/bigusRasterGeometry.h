/**
 * @file bigusRasterGeometry.h
 * @brief The slice and footprint geometry that every rasterizing backend shares (DESIGN section 3):
 *        a checked slice ready to render (orthonormal frame, pixel -> plane map, tile grid) and the
 *        pixel bounding box of a footprint's cutoff ellipse. Private to the backends (not installed):
 *        the CPU renderer and the CUDA renderer include it so that both cull and bin by the same rules.
 */
#ifndef bigusRasterGeometry_h
#define bigusRasterGeometry_h

#include "bigusGaussianMath.h"
#include "bigusRenderer.h"
#include "bigusSliceFrame.h"

#include <string>
#include <vector>

namespace bigus
{

/// Pixels per side of a raster tile (CPU: one work item; CUDA: one thread block of TileSize^2 threads).
constexpr int TileSize = 16;

/// A slice ready to render: orthonormal frame and the pixel -> plane map.
struct PreparedSlice
{
  SliceFrameD Frame;
  double PixelToPlane[3]; ///< x = i P0 + j P1, y = j P2 (mm)
  int Width, Height, TilesX, TilesY;
};

/**
 * Checks slice @p index of a call and prepares it. Returns false with @p error ("slice 3: grid 0 x 20
 * is not between 1 and 65536 pixels per side", "slice 1: ImageToReference contains NaN or Inf") for a
 * bad grid or pose.
 */
inline bool PrepareSlice(
  const SliceGeometry& g, const RenderOptions& o, int index, PreparedSlice& p, std::string* error)
{
  if (g.Width <= 0 || g.Height <= 0 || g.Width > 65536 || g.Height > 65536)
  {
    if (error)
    {
      *error = "slice " + std::to_string(index) + ": grid " + std::to_string(g.Width) + " x " +
        std::to_string(g.Height) + " is not between 1 and 65536 pixels per side";
    }
    return false;
  }
  const PoseStatus status =
    ComputeRenderingFrame(g.ImageToReference, o.MaximumShearAngle, p.Frame.F, p.Frame.Origin, p.PixelToPlane);
  if (status != PoseStatus::Ok)
  {
    if (error)
    {
      *error = "slice " + std::to_string(index) + ": ImageToReference " + PoseStatusText(status);
    }
    return false;
  }
  if (!(g.PixelLowPass >= 0) || !(g.PixelLowPass < 1e6))
  {
    if (error)
    {
      *error = "slice " + std::to_string(index) + ": PixelLowPass " + std::to_string(g.PixelLowPass) +
        " is not a variance between 0 and 1e6 pixels^2";
    }
    return false;
  }
  PixelLowPassCovariance(p.PixelToPlane, g.PixelLowPass, p.Frame.LowPass);
  p.Width = g.Width;
  p.Height = g.Height;
  p.TilesX = (g.Width + TileSize - 1) / TileSize;
  p.TilesY = (g.Height + TileSize - 1) / TileSize;
  return true;
}

/// Every slice of a call, checked before anything is written.
inline bool PrepareSlices(const SliceGeometry* slices, int count, const RenderOptions& o,
  std::vector<PreparedSlice>& prepared, std::string* error)
{
  prepared.resize(count);
  for (int k = 0; k < count; ++k)
  {
    if (!PrepareSlice(slices[k], o, k, prepared[k], error))
    {
      return false;
    }
  }
  return true;
}

/**
 * Pixel bounding box of the footprint's cutoff ellipse (columns box[0..1], rows box[2..3], inclusive,
 * clipped to the image); false when it misses the image.
 */
BIGUS_HD bool FootprintBox(const Footprint& f, const PreparedSlice& s, int box[4])
{
  const double cutoff = std::sqrt(std::fmax(f.CutoffSquared, 0.0));
  const double P0 = s.PixelToPlane[0], P1 = s.PixelToPlane[1], P2 = s.PixelToPlane[2];
  // pixel = K^-1 plane, K = [[P0, P1], [0, P2]].
  const double k00 = 1 / P0, k01 = -P1 / (P0 * P2), k11 = 1 / P2;
  const double ci = k00 * f.Center[0] + k01 * f.Center[1];
  const double cj = k11 * f.Center[1];
  const double vi = k00 * k00 * f.Cov[0] + 2 * k00 * k01 * f.Cov[1] + k01 * k01 * f.Cov[2];
  const double vj = k11 * k11 * f.Cov[2];
  const double hi = cutoff * std::sqrt(std::fmax(vi, 0.0));
  const double hj = cutoff * std::sqrt(std::fmax(vj, 0.0));
  const double lo[2] = { std::ceil(ci - hi), std::ceil(cj - hj) };
  const double up[2] = { std::floor(ci + hi), std::floor(cj + hj) };
  if (!(lo[0] <= s.Width - 1) || !(up[0] >= 0) || !(lo[1] <= s.Height - 1) || !(up[1] >= 0) || !(lo[0] <= up[0]) ||
    !(lo[1] <= up[1]))
  {
    return false;
  }
  box[0] = static_cast<int>(std::fmax(lo[0], 0.0));
  box[1] = static_cast<int>(std::fmin(up[0], s.Width - 1.0));
  box[2] = static_cast<int>(std::fmax(lo[1], 0.0));
  box[3] = static_cast<int>(std::fmin(up[1], s.Height - 1.0));
  return true;
}

/// A visible Gaussian's footprint as phase 2 uses it (float where the per-pixel arithmetic is float).
struct Splat
{
  double Cx, Cy;            ///< centre in the plane, mm
  float Cos, Sin;           ///< major axis of the footprint in the plane
  float InvMajor, InvMinor; ///< 1 / standard deviations along the axes, 1/mm
  float Weight;             ///< r_eff * amp
  float CutoffSquared;      ///< of the in-plane form (Footprint::CutoffSquared)
  int X0, X1, Y0, Y1;       ///< pixel bounding box (FootprintBox), inclusive, clipped to the image
};

/// The splat of the visible footprint @p f with effective reflectivity @p r and pixel box @p box.
BIGUS_HD Splat MakeSplat(const Footprint& f, double r, const int box[4])
{
  Splat sp;
  sp.Cx = f.Center[0];
  sp.Cy = f.Center[1];
  sp.Cos = static_cast<float>(f.Axes[0]);
  sp.Sin = static_cast<float>(f.Axes[1]);
  sp.InvMajor = static_cast<float>(f.Axes[2]);
  sp.InvMinor = static_cast<float>(f.Axes[3]);
  sp.Weight = static_cast<float>(r * f.Amplitude);
  sp.CutoffSquared = static_cast<float>(f.CutoffSquared);
  sp.X0 = box[0];
  sp.X1 = box[1];
  sp.Y0 = box[2];
  sp.Y1 = box[3];
  return sp;
}

/**
 * A footprint as the backward passes evaluate it: in float, with in-plane offsets relative to the first
 * pixel of its box (as phase 2 takes them relative to the tile), so that float keeps its precision
 * whatever the size of the image. Pixel (col, row) of the box lies at dx = col P0 + (row P1 - Dcx),
 * dy = row P2 - Dcy from the footprint's centre (mm).
 */
struct BoxFootprint
{
  float Dcx, Dcy;      ///< centre relative to the box's first pixel, mm
  float A, B, C;       ///< conic (Footprint::Conic), 1/mm^2
  float Axes[4];       ///< Footprint::Axes
  float Weight;        ///< r_eff * amp
  float CutoffSquared; ///< Footprint::CutoffSquared
  float P0, P1, P2;    ///< pixel -> plane map of the slice
};

BIGUS_HD BoxFootprint MakeBoxFootprint(const Footprint& f, const PreparedSlice& s, const int box[4], double r)
{
  const double X0 = box[0] * s.PixelToPlane[0] + box[2] * s.PixelToPlane[1];
  const double Y0 = box[2] * s.PixelToPlane[2];
  BoxFootprint b;
  b.Dcx = static_cast<float>(f.Center[0] - X0);
  b.Dcy = static_cast<float>(f.Center[1] - Y0);
  b.A = static_cast<float>(f.Conic[0]);
  b.B = static_cast<float>(f.Conic[1]);
  b.C = static_cast<float>(f.Conic[2]);
  for (int k = 0; k < 4; ++k)
  {
    b.Axes[k] = static_cast<float>(f.Axes[k]);
  }
  b.Weight = static_cast<float>(r * f.Amplitude);
  b.CutoffSquared = static_cast<float>(f.CutoffSquared);
  b.P0 = static_cast<float>(s.PixelToPlane[0]);
  b.P1 = static_cast<float>(s.PixelToPlane[1]);
  b.P2 = static_cast<float>(s.PixelToPlane[2]);
  return b;
}

/// The reflectivity the renderer uses: r, or max(r, 0) with RenderOptions::NonNegativeReflectivity.
BIGUS_HD double EffectiveReflectivity(double r, bool nonNegative)
{
  return nonNegative && r < 0 ? 0.0 : r;
}

/**
 * The columns of one pixel row that can lie inside a footprint's cutoff ellipse. With dx = q P0 + x0
 * the in-plane offset of column q and dy the row's, the form a dx^2 + 2 b dx dy + c dy^2 <= k2 holds
 * for dx between (-b dy -+ sqrt(a k2 - det dy^2)) / a (det = ac - b^2). The span is widened by a pixel
 * on each side and slightly in k2 so that float rounding never drops a pixel the exact test keeps;
 * the caller still tests every pixel. Returns [first, end) clipped to [lo, hi), empty when the row
 * misses the ellipse.
 */
BIGUS_HD void RowSpan(
  float a, float b, float det, float k2, float dy, float x0, float P0, int lo, int hi, int& first, int& end)
{
  const float disc = a * (k2 * 1.001f + 1e-6f) - det * dy * dy;
  if (!(disc >= 0))
  {
    first = end = lo;
    return;
  }
  const float root = std::sqrt(disc);
  const float q0 = ((-b * dy - root) / a - x0) / P0, q1 = ((-b * dy + root) / a - x0) / P0;
  // fmax / fmin also map a NaN bound (a degenerate conic) to the whole range.
  const int f = static_cast<int>(std::fmax(std::floor(q0), float(lo - 1))) - 1;
  const int e = static_cast<int>(std::fmin(std::ceil(q1), float(hi + 1))) + 2;
  first = f > lo ? f : lo;
  end = e < hi ? e : hi;
  end = end > first ? end : first;
}

/// What a cheap elevation test needs of a Gaussian: its mean and largest variance (mm^2); Known false for a
/// log-scale that is not finite (SetupFootprint decides those).
struct Reach
{
  double Mean[3];
  double LargestVariance;
  bool Known;
};

/// The Reach of Gaussian @p i of @p field (FieldView on the host, cuda::DeviceField on the device: Means [N, 3] and
/// LogScales [N, 3]).
template <typename Field>
BIGUS_HD Reach ReachOf(const Field& field, std::int64_t i)
{
  Reach r;
  double largest = MinimumLogScale;
  r.Known = true;
  for (int k = 0; k < 3; ++k)
  {
    r.Mean[k] = field.Means[3 * i + k];
    const double l = field.LogScales[3 * i + k];
    r.Known = r.Known && l - l == 0.0; // false for NaN and +-Inf
    const double held = l < MaximumLogScale ? l : MaximumLogScale;
    largest = largest < held ? held : largest;
  }
  r.LargestVariance = std::exp(2 * largest);
  return r;
}

/**
 * True when the Gaussian cannot reach slice @p s: its mean lies further from the plane than the cut-off times the
 * largest elevation standard deviation it can have (its largest scale, with the beam), so SetupFootprint would find
 * it invisible (its test with the actual elevation variance, which is at most this one). Saves the set-up of the
 * many (slice, Gaussian) pairs of a grid whose Gaussians each reach a few slices.
 */
BIGUS_HD bool OutOfReach(const Reach& g, const PreparedSlice& s, double sigmaE, double cutoff)
{
  if (!g.Known)
  {
    return false;
  }
  double m = 0, norm = 0;
  for (int k = 0; k < 3; ++k)
  {
    m += s.Frame.F[2][k] * (g.Mean[k] - s.Frame.Origin[k]);
    norm += s.Frame.F[2][k] * s.Frame.F[2][k];
  }
  return m * m > 1.0001 * cutoff * cutoff * (g.LargestVariance * norm + sigmaE * sigmaE);
}

/**
 * The pixels of the visible footprint @p f on slice @p s as the backward pass visits them (host): each row of its
 * box (FootprintBox, into @p box) that meets the cut-off ellipse (RowSpan) as @p span(row, first, last, weight),
 * columns [first, last) counted from box[0], where weight(col) is the pixel's float weight at reflectivity 1
 * (MakeBoxFootprint; 0 outside the cut-off). False when the box misses the slice. AccumulateBasisNorms and
 * AssembledBasis use it, so that both sum exactly the backward pass's pixels.
 */
template <typename Span>
inline bool ForEachFootprintSpan(const Footprint& f, const PreparedSlice& s, int box[4], Span span)
{
  if (!FootprintBox(f, s, box))
  {
    return false;
  }
  const BoxFootprint fp = MakeBoxFootprint(f, s, box, 1.0);
  const float det = fp.A * fp.C - fp.B * fp.B;
  for (int row = box[2]; row <= box[3]; ++row)
  {
    const float dy = (row - box[2]) * fp.P2 - fp.Dcy;
    const float xrow = (row - box[2]) * fp.P1 - fp.Dcx;
    int first, last;
    RowSpan(fp.A, fp.B, det, fp.CutoffSquared, dy, xrow, fp.P0, 0, box[1] - box[0] + 1, first, last);
    if (last > first)
    {
      span(row, first, last, [&](int col) {
        const float form = AxesForm(fp.Axes[0], fp.Axes[1], fp.Axes[2], fp.Axes[3], col * fp.P0 + xrow, dy);
        return form <= fp.CutoffSquared ? fp.Weight * FastExp(-0.5f * form) : 0.0f;
      });
    }
  }
  return true;
}

/**
 * The backward pass of Gaussian @p i on one slice from its pixel sums @p sums (PixelWeightBackward's
 * terms over its footprint): its mean, log-scale, quaternion and reflectivity gradients and its share
 * of the attribution, added to the non-null outputs of @p out (host or device pointers). @p r is the
 * effective reflectivity, @p reflectivity the stored one (no gradient reaches a clamped one). With @p dxi
 * (6 doubles), the Gaussian's share of the gradient with respect to the slice's pose correction about
 * @p pivot is added there too (SlicePoseBackward).
 */
BIGUS_HD void AddGaussianGradients(const Footprint& f, const SetupCache& cache, const SliceFrameD& frame, double sigmaE,
  const double sums[7], double r, double reflectivity, bool nonNegative, const FieldGradients& out, std::int64_t i,
  const double* pivot = nullptr, double* dxi = nullptr)
{
  GaussianGrad gg = {};
  SliceFrameGrad sg;
  SetupFootprintBackward(f, cache, frame, sigmaE, FootprintGradFromSums(sums, r), gg, dxi ? &sg : nullptr);
  if (dxi)
  {
    SlicePoseBackward(cache, pivot, sg, dxi);
  }
  gg.Reflectivity = (nonNegative && reflectivity <= 0) ? 0.0 : f.Amplitude * sums[5];
  for (int k = 0; k < 3; ++k)
  {
    if (out.Means)
    {
      out.Means[3 * i + k] += static_cast<float>(gg.Mean[k]);
    }
    if (out.LogScales)
    {
      out.LogScales[3 * i + k] += static_cast<float>(gg.LogScale[k]);
    }
  }
  if (out.Quaternions)
  {
    for (int k = 0; k < 4; ++k)
    {
      out.Quaternions[4 * i + k] += static_cast<float>(gg.Quaternion[k]);
    }
  }
  if (out.Reflectivities)
  {
    out.Reflectivities[i] += static_cast<float>(gg.Reflectivity);
  }
  if (out.Attribution)
  {
    out.Attribution[i] += static_cast<float>(sums[6]);
  }
}

} // namespace bigus

#endif
