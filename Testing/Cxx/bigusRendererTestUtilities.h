// Test helpers of the renderer tests (TestCpuRenderer, TestCudaRenderer; TestResolutionSchedule for pose
// gradients): slice poses, central differences of a pose correction, random fields and their float copies. Header
// only.
#ifndef bigusRendererTestUtilities_h
#define bigusRendererTestUtilities_h

#include "bigusBackendCheck.h"
#include "bigusReferenceRenderer.h"
#include "bigusRenderer.h"

#include <cmath>
#include <random>
#include <vector>

namespace bigus
{
namespace test
{
/// A slice pose: rotation about the axis (ax, ay, az) by `degrees`, then translation; spacing in mm.
inline SliceGeometry MakeSlice(
  int w, int h, double spacing, double degrees, const double axis[3], const double origin[3])
{
  return RotatedSlice(w, h, spacing, degrees, axis, origin);
}

/// Central difference of @p loss (a function of a pose correction xi[6], as CorrectPose takes it) along component
/// @p k: steps of 1e-5 rad for the rotation, 1e-4 mm for the translation.
template <typename Loss>
double PoseCentralDifference(const Loss& loss, int k)
{
  const double h = k < 3 ? 1e-5 : 1e-4;
  double plus[6] = { 0, 0, 0, 0, 0, 0 }, minus[6] = { 0, 0, 0, 0, 0, 0 };
  plus[k] = h;
  minus[k] = -h;
  return (loss(plus) - loss(minus)) / (2 * h);
}

/// Random field around the slice centre: means in a cube of side `extent` mm, scales 0.3..2 mm,
/// random (unnormalised) quaternions, reflectivities N(mean, sd).
inline reference::FieldD RandomField(
  int n, const double centre[3], double extent, double meanR, double sdR, unsigned seed)
{
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0, 1);
  std::normal_distribution<double> normal(0, 1);
  reference::FieldD f;
  for (int i = 0; i < n; ++i)
  {
    for (int k = 0; k < 3; ++k)
    {
      f.Means.push_back(centre[k] + (u01(rng) - 0.5) * extent);
      f.LogScales.push_back(std::log(0.3 + 1.7 * u01(rng)));
    }
    for (int k = 0; k < 4; ++k)
    {
      f.Quaternions.push_back(normal(rng));
    }
    f.Reflectivities.push_back(meanR + sdR * normal(rng));
  }
  return f;
}

/// A float field on the host (the backend check's HostField).
using FieldF = HostField;

inline FieldF ToFloat(const reference::FieldD& d)
{
  FieldF f;
  f.Means.assign(d.Means.begin(), d.Means.end());
  f.LogScales.assign(d.LogScales.begin(), d.LogScales.end());
  f.Quaternions.assign(d.Quaternions.begin(), d.Quaternions.end());
  f.Reflectivities.assign(d.Reflectivities.begin(), d.Reflectivities.end());
  return f;
}

/// Same field rounded to float and back, so that the float and double renderers see one field.
inline reference::FieldD RoundedToFloat(const reference::FieldD& d)
{
  const FieldF f = ToFloat(d);
  reference::FieldD r;
  r.Means.assign(f.Means.begin(), f.Means.end());
  r.LogScales.assign(f.LogScales.begin(), f.LogScales.end());
  r.Quaternions.assign(f.Quaternions.begin(), f.Quaternions.end());
  r.Reflectivities.assign(f.Reflectivities.begin(), f.Reflectivities.end());
  return r;
}

} // namespace test
} // namespace bigus

#endif
