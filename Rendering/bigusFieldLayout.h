/**
 * @file bigusFieldLayout.h
 * @brief The one table of a Gaussian field's parameter groups (means 3, log-scales 3, quaternions 4,
 *        reflectivity 1) and of the packed layout that the engines and the CUDA backend give the field, its
 *        Adam moments and its gradients: the groups one after the other, [N, width] each, 11 floats per
 *        Gaussian in all.
 *
 * Part of BIGUS::Rendering (public, not wrapped for Python); header only, for the host and the device
 * (BIGUS_HD).
 */
#ifndef bigusFieldLayout_h
#define bigusFieldLayout_h

#include "bigusGaussianMath.h" // BIGUS_HD
#include "bigusRenderer.h"

#include <cstdint>

namespace bigus
{

/// The parameter groups of a Gaussian, in the order of FieldView's (and GaussianField's) arrays.
enum FieldGroup : int
{
  MeanGroup,
  LogScaleGroup,
  QuaternionGroup,
  ReflectivityGroup
};
constexpr int FieldGroups = 4;

/// Floats per Gaussian of group @p q: 3, 3, 4, 1.
BIGUS_HD constexpr int FieldGroupWidth(int q)
{
  return q == QuaternionGroup ? 4 : q == ReflectivityGroup ? 1 : 3;
}

/// Where group @p q starts in the packed layout, in units of N: 0, 3, 6, 10 (the widths before it).
BIGUS_HD constexpr int FieldGroupFirst(int q)
{
  return q == MeanGroup ? 0 : q == LogScaleGroup ? 3 : q == QuaternionGroup ? 6 : 10;
}

/// Floats per Gaussian of all groups: 11.
constexpr int FieldParameters = 11;

static_assert(FieldGroupFirst(LogScaleGroup) == FieldGroupFirst(MeanGroup) + FieldGroupWidth(MeanGroup) &&
    FieldGroupFirst(QuaternionGroup) == FieldGroupFirst(LogScaleGroup) + FieldGroupWidth(LogScaleGroup) &&
    FieldGroupFirst(ReflectivityGroup) == FieldGroupFirst(QuaternionGroup) + FieldGroupWidth(QuaternionGroup) &&
    FieldParameters == FieldGroupFirst(ReflectivityGroup) + FieldGroupWidth(ReflectivityGroup),
  "the groups lie one after the other");

/// Entry @p c of group @p q of Gaussian @p i in a packed array of @p n Gaussians.
BIGUS_HD constexpr std::int64_t FieldEntry(std::int64_t n, std::int64_t i, int q, int c)
{
  return FieldGroupFirst(q) * n + FieldGroupWidth(q) * i + c;
}

/// Whether any parameter of Gaussian @p i has a non-zero gradient in the packed array @p g of @p n Gaussians
/// (sparse Adam passes over the others: StepRequest::SparseAdam).
BIGUS_HD bool FieldGradientTouched(const float* g, std::int64_t n, std::int64_t i)
{
  bool touched = false;
  for (int q = 0; q < FieldGroups; ++q)
  {
    for (int c = 0; c < FieldGroupWidth(q); ++c)
    {
      touched = touched || g[FieldEntry(n, i, q, c)] != 0.f;
    }
  }
  return touched;
}

/// The gradients of the field's parameters as the packed array @p base of @p n Gaussians (the other outputs of
/// FieldGradients left null).
inline FieldGradients FieldGradientsAt(float* base, std::int64_t n)
{
  FieldGradients g;
  g.Means = base + FieldGroupFirst(MeanGroup) * n;
  g.LogScales = base + FieldGroupFirst(LogScaleGroup) * n;
  g.Quaternions = base + FieldGroupFirst(QuaternionGroup) * n;
  g.Reflectivities = base + FieldGroupFirst(ReflectivityGroup) * n;
  return g;
}

} // namespace bigus

#endif
