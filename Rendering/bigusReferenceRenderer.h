/**
 * @file bigusReferenceRenderer.h
 * @brief Naive double-precision renderer for tests and benchmarks only: every Gaussian at every pixel,
 *        no culling, no tiles, no threads. Built from the same formulas (bigusGaussianMath.h) as the
 *        backends, so that a finite-difference check of its backward validates those formulas, and the
 *        float backends are measured against it.
 */
#ifndef bigusReferenceRenderer_h
#define bigusReferenceRenderer_h

#include "bigusGaussianMath.h"
#include "bigusRenderer.h"
#include "bigusSliceFrame.h"

#include <limits>
#include <string>
#include <vector>

namespace bigus
{
namespace reference
{

/// A Gaussian field in double precision (same layout as FieldView).
struct FieldD
{
  std::vector<double> Means, LogScales, Quaternions, Reflectivities; // [N,3], [N,3], [N,4], [N]
  std::int64_t Count() const { return static_cast<std::int64_t>(this->Reflectivities.size()); }
  GaussianParams Get(std::int64_t i) const
  {
    return LoadGaussian(
      this->Means.data(), this->LogScales.data(), this->Quaternions.data(), this->Reflectivities.data(), i);
  }
};

/// The double copy of a float field (FieldView), to render it with the reference.
inline FieldD FromView(const FieldView& v)
{
  FieldD d;
  d.Means.assign(v.Means, v.Means + 3 * v.Count);
  d.LogScales.assign(v.LogScales, v.LogScales + 3 * v.Count);
  d.Quaternions.assign(v.Quaternions, v.Quaternions + 4 * v.Count);
  d.Reflectivities.assign(v.Reflectivities, v.Reflectivities + v.Count);
  return d;
}

/// Gradients in double, same layout.
struct GradD
{
  std::vector<double> Means, LogScales, Quaternions, Reflectivities, Attribution;
  explicit GradD(std::int64_t n = 0)
    : Means(3 * n, 0.0)
    , LogScales(3 * n, 0.0)
    , Quaternions(4 * n, 0.0)
    , Reflectivities(n, 0.0)
    , Attribution(n, 0.0)
  {}
};

inline bool Prepare(const SliceGeometry& slice, const RenderOptions& o, SliceFrameD& frame, double pixel[3])
{
  if (ComputeRenderingFrame(slice.ImageToReference, o.MaximumShearAngle, frame.F, frame.Origin, pixel) !=
    PoseStatus::Ok)
  {
    return false;
  }
  PixelLowPassCovariance(pixel, slice.PixelLowPass, frame.LowPass);
  return true;
}

inline double Reflectivity(double r, const RenderOptions& o)
{
  return o.NonNegativeReflectivity ? (r > 0 ? r : 0.0) : r;
}

/**
 * The cutoff of the reference: none (every Gaussian at every pixel) unless @p truncated, then the
 * renderers' RenderOptions::Cutoff, so that it sums over the footprints' pixels as they do and differs
 * from them by float rounding alone (bigusBackendCheck measures a backend's rounding against it).
 */
inline double ReferenceCutoff(const RenderOptions& o, bool truncated)
{
  return truncated ? o.Cutoff : std::numeric_limits<double>::infinity();
}

/// S (and I if non-null), [H, W], double. Returns false for a bad pose. @p truncated: ReferenceCutoff.
inline bool Forward(const FieldD& field, const SliceGeometry& slice, const RenderOptions& o, std::vector<double>& S,
  std::vector<double>* I = nullptr, bool truncated = false)
{
  SliceFrameD frame;
  double pixel[3];
  if (!Prepare(slice, o, frame, pixel))
  {
    return false;
  }
  const double sigmaE = EffectiveElevationSigma(o);
  S.assign(std::size_t(slice.Width) * slice.Height, 0.0);
  for (std::int64_t i = 0; i < field.Count(); ++i)
  {
    const GaussianParams g = field.Get(i);
    const Footprint f = SetupFootprint(g, frame, sigmaE, ReferenceCutoff(o, truncated), nullptr);
    if (!f.Visible)
    {
      continue;
    }
    const double r = Reflectivity(g.Reflectivity, o);
    for (int j = 0; j < slice.Height; ++j)
    {
      for (int k = 0; k < slice.Width; ++k)
      {
        const double dx = k * pixel[0] + j * pixel[1] - f.Center[0];
        const double dy = j * pixel[2] - f.Center[1];
        if (truncated && ConicForm(f.Conic[0], f.Conic[1], f.Conic[2], dx, dy) > f.CutoffSquared)
        {
          continue;
        }
        S[std::size_t(j) * slice.Width + k] += r * PixelWeight(f.Amplitude, f.Conic[0], f.Conic[1], f.Conic[2], dx, dy);
      }
    }
  }
  if (I)
  {
    I->resize(S.size());
    for (std::size_t p = 0; p < S.size(); ++p)
    {
      (*I)[p] = ImageFromScattering(S[p], o.Gamma);
    }
  }
  return true;
}

/// Gradients for dL/dS (or dL/dI with the forward S) on one slice, accumulated into @p grad.
/// @p truncated: ReferenceCutoff.
inline bool Backward(const FieldD& field, const SliceGeometry& slice, const RenderOptions& o,
  const std::vector<double>& S, const std::vector<double>& dL, bool gradientIsWithRespectToS, GradD& grad,
  bool truncated = false)
{
  SliceFrameD frame;
  double pixel[3];
  if (!Prepare(slice, o, frame, pixel))
  {
    return false;
  }
  const double sigmaE = EffectiveElevationSigma(o);
  std::vector<double> gS(dL.size());
  for (std::size_t p = 0; p < dL.size(); ++p)
  {
    gS[p] = gradientIsWithRespectToS ? dL[p] : dL[p] * ImageFromScatteringDerivative(S[p], o.Gamma);
  }
  for (std::int64_t i = 0; i < field.Count(); ++i)
  {
    const GaussianParams g = field.Get(i);
    SetupCache cache;
    const Footprint f = SetupFootprint(g, frame, sigmaE, ReferenceCutoff(o, truncated), &cache);
    if (!f.Visible)
    {
      continue;
    }
    const double r = Reflectivity(g.Reflectivity, o);
    double sums[7] = { 0, 0, 0, 0, 0, 0, 0 };
    for (int j = 0; j < slice.Height; ++j)
    {
      for (int k = 0; k < slice.Width; ++k)
      {
        const double dx = k * pixel[0] + j * pixel[1] - f.Center[0];
        const double dy = j * pixel[2] - f.Center[1];
        const double form = ConicForm(f.Conic[0], f.Conic[1], f.Conic[2], dx, dy);
        if (truncated && form > f.CutoffSquared)
        {
          continue;
        }
        const double e = std::exp(-0.5 * form);
        PixelWeightBackward(gS[std::size_t(j) * slice.Width + k], r * f.Amplitude, e, f.Conic[0], f.Conic[1],
          f.Conic[2], dx, dy, sums, 1);
      }
    }
    const FootprintGrad gf = FootprintGradFromSums(sums, r);
    GaussianGrad gg = {};
    SetupFootprintBackward(f, cache, frame, sigmaE, gf, gg);
    for (int q = 0; q < 3; ++q)
    {
      grad.Means[3 * i + q] += gg.Mean[q];
      grad.LogScales[3 * i + q] += gg.LogScale[q];
    }
    for (int q = 0; q < 4; ++q)
    {
      grad.Quaternions[4 * i + q] += gg.Quaternion[q];
    }
    grad.Reflectivities[i] += (o.NonNegativeReflectivity && g.Reflectivity <= 0) ? 0.0 : f.Amplitude * sums[5];
    grad.Attribution[i] += sums[6];
  }
  return true;
}

} // namespace reference
} // namespace bigus

#endif
