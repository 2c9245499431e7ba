// A backend's self-check against the CPU renderer (see bigusBackendCheck.h).
#include "bigusBackendCheck.h"

#include "bigusGaussianMath.h"
#include "bigusReferenceRenderer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

namespace bigus
{
namespace
{
constexpr int GridColumns = 20, GridRows = 14; // cells of 4 mm on the 80 x 56 mm slice
constexpr double ImageTolerance = 1e-5, GradientTolerance = 1e-4;

}

FieldView HostField::View() const
{
  FieldView v;
  v.Count = static_cast<std::int64_t>(this->Reflectivities.size());
  v.Means = this->Means.data();
  v.LogScales = this->LogScales.data();
  v.Quaternions = this->Quaternions.data();
  v.Reflectivities = this->Reflectivities.data();
  return v;
}

bool RenderWithGradients(Renderer& renderer, const FieldView& field, const SliceGeometry* slices, int count,
  const RenderOptions& o, const std::vector<float>& dL, RenderedGradients& out, std::string* error)
{
  out.S.assign(dL.size(), 0.f);
  out.I.assign(dL.size(), 0.f);
  if (!renderer.Forward(field, slices, count, o, out.S.data(), out.I.data(), &out.Forward, error))
  {
    return false;
  }
  const std::size_t n = static_cast<std::size_t>(field.Count);
  out.Means.assign(3 * n, 0.f);
  out.LogScales.assign(3 * n, 0.f);
  out.Quaternions.assign(4 * n, 0.f);
  out.Reflectivities.assign(n, 0.f);
  out.Attribution.assign(n, 0.f);
  out.Visible.assign(n, 0);
  FieldGradients g;
  g.Means = out.Means.data();
  g.LogScales = out.LogScales.data();
  g.Quaternions = out.Quaternions.data();
  g.Reflectivities = out.Reflectivities.data();
  g.Attribution = out.Attribution.data();
  g.VisibleCount = out.Visible.data();
  return renderer.Backward(field, slices, count, o, out.S.data(), dL.data(), false, g, &out.Backward, error);
}

SliceGeometry RotatedSlice(int w, int h, double spacing, double degrees, const double axis[3], const double origin[3])
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

SliceGeometry HardCaseSlice(double shift)
{
  // 20 degrees about the axis (0.3, 0.2, 1): a generic orientation.
  const double axis[3] = { 0.3, 0.2, 1.0 };
  const double origin[3] = { 12.5, -31.25 + shift, 47.0 };
  return RotatedSlice(2 * 4 * GridColumns, 2 * 4 * GridRows, 0.5, 20, axis, origin);
}

HostField HardCaseField(double sigmaE, const std::vector<double>& ratios)
{
  const SliceGeometry slice = HardCaseSlice();
  double F[3][3]; // columns u, v, n of the slice
  for (int r = 0; r < 3; ++r)
  {
    F[r][0] = slice.ImageToReference[4 * r] / 0.5;
    F[r][1] = slice.ImageToReference[4 * r + 1] / 0.5;
  }
  F[0][2] = F[1][0] * F[2][1] - F[2][0] * F[1][1];
  F[1][2] = F[2][0] * F[0][1] - F[0][0] * F[2][1];
  F[2][2] = F[0][0] * F[1][1] - F[1][0] * F[0][1];
  HostField f;
  int cell = 0;
  const double azimuth = 37 * M_PI / 180;
  for (bool needle : { false, true })
  {
    for (double ratio : ratios)
    {
      for (double tiltDegrees : { 0.0, 1.0, 15.0, 45.0, 75.0, 89.0, 90.0 })
      {
        for (double offset : { 0.0, 0.5, 2.0, 4.0 })
        {
          const double s[3] = { needle ? 2.0 : 2.0 / ratio, needle ? 2.0 / ratio : 2.0, needle ? 2.0 / ratio : 2.0 };
          const double t = tiltDegrees * M_PI / 180;
          // Local rotation Rz(azimuth) Rx(tilt) in the slice frame, then into the reference frame.
          const double ca = std::cos(azimuth), sa = std::sin(azimuth), ct = std::cos(t), st = std::sin(t);
          const double L[3][3] = { { ca, -sa * ct, sa * st }, { sa, ca * ct, -ca * st }, { 0, st, ct } };
          double R[3][3];
          for (int i = 0; i < 3; ++i)
          {
            for (int j = 0; j < 3; ++j)
            {
              R[i][j] = F[i][0] * L[0][j] + F[i][1] * L[1][j] + F[i][2] * L[2][j];
            }
          }
          const double u[3] = { R[0][0], R[1][0], R[2][0] }, v[3] = { R[0][1], R[1][1], R[2][1] },
                       n[3] = { R[0][2], R[1][2], R[2][2] };
          double q[4];
          QuaternionFromAxes(u, v, n, q);
          // Its elevation standard deviation seen through the beam: sqrt(P2[z,z]) (bigusGaussianMath.h).
          const double elevation =
            offset * std::sqrt(std::pow(st * s[1], 2) + std::pow(ct * s[2], 2) + sigmaE * sigmaE);
          const double x = 2 + 4 * (cell % GridColumns), y = 2 + 4 * (cell / GridColumns);
          for (int k = 0; k < 3; ++k)
          {
            f.Means.push_back(
              float(slice.ImageToReference[4 * k + 3] + x * F[k][0] + y * F[k][1] + elevation * F[k][2]));
            f.LogScales.push_back(float(std::log(s[k])));
          }
          for (double c : q)
          {
            f.Quaternions.push_back(float(c));
          }
          f.Reflectivities.push_back(cell % 2 ? -0.5f : 0.8f);
          ++cell;
        }
      }
    }
  }
  return f;
}

BackendCheck CheckRenderer(Renderer& renderer)
{
  BackendCheck check;
  check.Backend = renderer.GetName();
  const HostField field = HardCaseField(0.5, { 1.0, 10.0, 100.0 });
  SliceGeometry slices[2] = { HardCaseSlice(), HardCaseSlice(1.3) };
  slices[1].Width = 77;
  slices[1].Height = 45;
  std::vector<float> dL(
    std::size_t(slices[0].Width) * slices[0].Height + std::size_t(slices[1].Width) * slices[1].Height);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (float& v : dL)
  {
    v = u(rng);
  }
  RenderOptions o;
  o.ElevationSigma = 0.5;
  RenderedGradients mine, cpu;
  std::string error;
  if (!RenderWithGradients(renderer, field.View(), slices, 2, o, dL, mine, &error))
  {
    check.Detail = "the hard-case field failed to render: " + error;
    return check;
  }
  const std::unique_ptr<Renderer> onCpu = CreateCpuRenderer();
  RenderedGradients exact;
  if (!RenderWithGradients(*onCpu, field.View(), slices, 2, o, dL, cpu, &error) ||
    !RenderReference(field.View(), slices, 2, o, dL, exact, &error))
  {
    check.Detail = "the CPU or the reference renderer failed on the hard-case field: " + error; // never expected
    return check;
  }
  check = CompareRenders(mine, cpu, exact, ImageTolerance, GradientTolerance);
  check.Backend = renderer.GetName();
  return check;
}

namespace
{
/// The largest error of a renderer's gradients against the reference's, and where it is.
struct GradientError
{
  double Worst = 0;       ///< relative to the Gaussian's own exact gradient in its group (NaN counts as infinite)
  const char* Group = ""; ///< "dL/dmean", ...
  std::size_t Gaussian = 0;
  bool Finite = true; ///< every gradient of the renderer finite
};

/// @p mine's gradients against @p exact's over the Gaussians and groups, each relative to the Gaussian's
/// own exact gradient in that group (floor: 1e-3 of the group's largest).
GradientError WorstGradientError(const RenderedGradients& mine, const RenderedGradients& exact)
{
  const struct
  {
    const char* Name;
    const std::vector<float>& Mine;
    const std::vector<float>& Exact;
    int Width;
  } groups[] = { { "dL/dmean", mine.Means, exact.Means, 3 }, { "dL/dlog-scale", mine.LogScales, exact.LogScales, 3 },
    { "dL/dq", mine.Quaternions, exact.Quaternions, 4 }, { "dL/dr", mine.Reflectivities, exact.Reflectivities, 1 },
    { "attribution", mine.Attribution, exact.Attribution, 1 } };
  GradientError e;
  for (const auto& g : groups)
  {
    double largest = 0;
    for (float v : g.Exact)
    {
      largest = std::max(largest, double(std::abs(v)));
    }
    for (std::size_t i = 0; i * g.Width < g.Exact.size(); ++i)
    {
      double own = 0, difference = 0;
      for (int c = 0; c < g.Width; ++c)
      {
        const std::size_t k = i * g.Width + c;
        e.Finite = e.Finite && std::isfinite(g.Mine[k]);
        own = std::max(own, double(std::abs(g.Exact[k])));
        difference = std::max(difference, std::abs(double(g.Mine[k]) - g.Exact[k]));
      }
      const double scale = std::max(own, 1e-3 * largest);
      const double relative = scale > 0 ? difference / scale : (difference > 0 ? HUGE_VAL : 0.0);
      if (!(relative <= e.Worst))
      {
        e.Worst = std::isnan(relative) ? HUGE_VAL : relative;
        e.Group = g.Name;
        e.Gaussian = i;
      }
    }
  }
  return e;
}
}

bool RenderReference(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& o,
  const std::vector<float>& dL, RenderedGradients& out, std::string* error)
{
  const reference::FieldD d = reference::FromView(field);
  reference::GradD grad(field.Count);
  out.S.clear();
  out.I.clear();
  std::size_t offset = 0;
  for (int k = 0; k < count; ++k)
  {
    const std::size_t pixels = std::size_t(slices[k].Width) * slices[k].Height;
    std::vector<double> S, I;
    const std::vector<double> gradient(dL.begin() + offset, dL.begin() + offset + pixels);
    if (!reference::Forward(d, slices[k], o, S, &I, true) ||
      !reference::Backward(d, slices[k], o, S, gradient, false, grad, true))
    {
      if (error)
      {
        *error = "the reference renderer rejected slice " + std::to_string(k) + "'s pose";
      }
      return false;
    }
    out.S.insert(out.S.end(), S.begin(), S.end());
    out.I.insert(out.I.end(), I.begin(), I.end());
    offset += pixels;
  }
  out.Means.assign(grad.Means.begin(), grad.Means.end());
  out.LogScales.assign(grad.LogScales.begin(), grad.LogScales.end());
  out.Quaternions.assign(grad.Quaternions.begin(), grad.Quaternions.end());
  out.Reflectivities.assign(grad.Reflectivities.begin(), grad.Reflectivities.end());
  out.Attribution.assign(grad.Attribution.begin(), grad.Attribution.end());
  out.Visible.clear();
  return true;
}

BackendCheck CompareRenders(const RenderedGradients& mine, const RenderedGradients& cpu, const RenderedGradients& exact,
  double imageTolerance, double gradientTolerance)
{
  BackendCheck check;
  bool finite = true;
  for (std::size_t p = 0; p < cpu.I.size(); ++p)
  {
    finite = finite && std::isfinite(mine.S[p]) && std::isfinite(mine.I[p]);
    check.ImageDifference = std::max(check.ImageDifference, double(std::abs(mine.I[p] - cpu.I[p])));
  }
  const GradientError error = WorstGradientError(mine, exact);
  finite = finite && error.Finite;
  check.GradientDifference = error.Worst;
  check.CpuGradientError = WorstGradientError(cpu, exact).Worst;
  const double bound = std::max(gradientTolerance, GradientErrorRatio * check.CpuGradientError);
  long long visible = 0, visibleCpu = 0;
  for (std::size_t i = 0; i < cpu.Visible.size(); ++i)
  {
    visible += mine.Visible[i];
    visibleCpu += cpu.Visible[i];
  }
  check.Passed =
    finite && check.ImageDifference <= imageTolerance && check.GradientDifference <= bound && visible == visibleCpu;
  char text[400];
  std::snprintf(text, sizeof(text),
    "max |delta I| %.3g (bound %.0e), max gradient error %.3g of the Gaussian's own against the double reference "
    "(the CPU's %.3g; bound %.3g; worst: %s of Gaussian %zu), visible %lld (CPU %lld)%s",
    check.ImageDifference, imageTolerance, check.GradientDifference, check.CpuGradientError, bound, error.Group,
    error.Gaussian, visible, visibleCpu, finite ? "" : ", non-finite values");
  check.Detail = text;
  return check;
}

} // namespace bigus
