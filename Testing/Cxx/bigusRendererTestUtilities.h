// Test helpers of the renderer tests (TestCpuRenderer, TestCudaRenderer): slice poses, random fields
// and their float copies. Header only.
#ifndef bigusRendererTestUtilities_h
#define bigusRendererTestUtilities_h

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
inline SliceGeometry MakeSlice(int w, int h, double spacing, double degrees, const double axis[3], const double origin[3])
{
  const double n = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  const double x = axis[0] / n, y = axis[1] / n, z = axis[2] / n;
  const double t = degrees * M_PI / 180, c = std::cos(t), s = std::sin(t), C = 1 - c;
  const double R[3][3] = { { c + x * x * C, x * y * C - z * s, x * z * C + y * s },
    { y * x * C + z * s, c + y * y * C, y * z * C - x * s }, { z * x * C - y * s, z * y * C + x * s, c + z * z * C } };
  SliceGeometry g;
  for (int r = 0; r < 3; ++r)
  {
    g.ImageToReference[4 * r + 0] = R[r][0] * spacing;
    g.ImageToReference[4 * r + 1] = R[r][1] * spacing;
    g.ImageToReference[4 * r + 2] = R[r][2] * spacing;
    g.ImageToReference[4 * r + 3] = origin[r];
  }
  g.ImageToReference[12] = g.ImageToReference[13] = g.ImageToReference[14] = 0;
  g.ImageToReference[15] = 1;
  g.Width = w;
  g.Height = h;
  return g;
}

/// Random field around the slice centre: means in a cube of side `extent` mm, scales 0.3..2 mm,
/// random (unnormalised) quaternions, reflectivities N(mean, sd).
inline reference::FieldD RandomField(int n, const double centre[3], double extent, double meanR, double sdR, unsigned seed)
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

struct FieldF
{
  std::vector<float> Means, LogScales, Quaternions, Reflectivities;
  FieldView View() const
  {
    FieldView v;
    v.Count = static_cast<std::int64_t>(this->Reflectivities.size());
    v.Means = this->Means.data();
    v.LogScales = this->LogScales.data();
    v.Quaternions = this->Quaternions.data();
    v.Reflectivities = this->Reflectivities.data();
    return v;
  }
};

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
