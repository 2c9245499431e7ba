// The training geometry kept with a field (bigusGaussianFieldData.h: TrainingGeometry) and the coverage of a
// rendered slice computed from it (TrainingCoverage).
#include "bigusGaussianFieldData.h"

#include "bigusSliceFrame.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkIntArray.h"
#include "vtkMath.h"
#include "vtkNew.h"
#include "vtkSMPTools.h"
#include "vtkUnsignedCharArray.h"

#include <algorithm>
#include <cmath>

namespace bigus
{

TrainingGeometry TrainingGeometryOf(const TrainingData& data)
{
  TrainingGeometry geometry;
  geometry.Width = data.Width;
  geometry.Height = data.Height;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  geometry.Mask.assign(pixels, 0);
  for (int f : data.TrainFrames)
  {
    geometry.Poses.push_back(data.Poses[f]);
    const unsigned char* mask = data.MaskOf(f);
    for (std::size_t p = 0; p < pixels; ++p)
    {
      geometry.Mask[p] |= mask[p] != 0 ? 1 : 0;
    }
  }
  return geometry;
}

void TrainingGeometryToFieldData(const TrainingGeometry& geometry, vtkFieldData* out)
{
  vtkNew<vtkDoubleArray> poses;
  poses->SetName("TrainingPoses");
  poses->SetNumberOfComponents(16);
  poses->SetNumberOfTuples(static_cast<vtkIdType>(geometry.Poses.size()));
  for (std::size_t t = 0; t < geometry.Poses.size(); ++t)
  {
    poses->SetTypedTuple(static_cast<vtkIdType>(t), geometry.Poses[t].data());
  }
  vtkNew<vtkIntArray> size;
  size->SetName("TrainingFrameSize");
  size->SetNumberOfComponents(2);
  const int widthHeight[2] = { geometry.Width, geometry.Height };
  size->InsertNextTypedTuple(widthHeight);
  vtkNew<vtkUnsignedCharArray> mask;
  mask->SetName("TrainingFanMask");
  mask->SetNumberOfTuples(static_cast<vtkIdType>(geometry.Mask.size()));
  std::copy(geometry.Mask.begin(), geometry.Mask.end(), mask->GetPointer(0));
  out->AddArray(poses);
  out->AddArray(size);
  out->AddArray(mask);
}

bool TrainingGeometryFromFieldData(vtkFieldData* in, TrainingGeometry& geometry, std::string* error)
{
  auto fail = [&](const std::string& why) {
    if (error)
    {
      *error = "Gaussian field: field data " + why;
    }
    geometry = TrainingGeometry();
    return false;
  };
  geometry = TrainingGeometry();
  const char* names[3] = { "TrainingPoses", "TrainingFrameSize", "TrainingFanMask" };
  vtkAbstractArray* arrays[3];
  int present = 0;
  for (int a = 0; a < 3; ++a)
  {
    arrays[a] = in ? in->GetAbstractArray(names[a]) : nullptr;
    present += arrays[a] != nullptr;
  }
  if (present == 0)
  {
    return true;
  }
  for (int a = 0; a < 3; ++a)
  {
    if (!arrays[a])
    {
      return fail(
        std::string(names[a]) + " is missing (TrainingPoses, TrainingFrameSize and TrainingFanMask come together)");
    }
    if (!vtkDataArray::SafeDownCast(arrays[a]))
    {
      return fail(std::string(names[a]) + " must be a numeric array, not " + arrays[a]->GetClassName());
    }
  }
  auto* poses = vtkDataArray::SafeDownCast(arrays[0]);
  auto* size = vtkDataArray::SafeDownCast(arrays[1]);
  auto* mask = vtkDataArray::SafeDownCast(arrays[2]);
  if (poses->GetNumberOfComponents() != 16 || poses->GetNumberOfTuples() == 0)
  {
    return fail("TrainingPoses must hold one row-major 4x4 ImageToReference (16 components) per training frame; "
                "it has " +
      std::to_string(poses->GetNumberOfTuples()) + " tuples of " + std::to_string(poses->GetNumberOfComponents()) +
      " components");
  }
  const vtkIdType count = poses->GetNumberOfTuples();
  geometry.Poses.resize(count);
  for (vtkIdType t = 0; t < count; ++t)
  {
    poses->GetTuple(t, geometry.Poses[t].data());
    SliceFrame frame;
    // Any shear is accepted: the coverage inverts the pose exactly on its plane.
    const PoseStatus status = ComputeSliceFrame(geometry.Poses[t].data(), 90.0, frame);
    if (status != PoseStatus::Ok)
    {
      return fail("TrainingPoses: pose " + std::to_string(t) + " (ImageToReference) " + PoseStatusText(status));
    }
  }
  if (size->GetNumberOfValues() != 2)
  {
    return fail("TrainingFrameSize must hold 2 values (width, height in pixels); it has " +
      std::to_string(size->GetNumberOfValues()));
  }
  const int components = size->GetNumberOfComponents();
  double widthHeight[2];
  for (int v = 0; v < 2; ++v)
  {
    widthHeight[v] = size->GetComponent(v / components, v % components);
  }
  if (!(widthHeight[0] >= 1 && widthHeight[1] >= 1 && widthHeight[0] <= VTK_INT_MAX && widthHeight[1] <= VTK_INT_MAX &&
        widthHeight[0] == std::floor(widthHeight[0]) && widthHeight[1] == std::floor(widthHeight[1])))
  {
    return fail("TrainingFrameSize must be a positive whole width and height (pixels); it is " +
      std::to_string(widthHeight[0]) + " x " + std::to_string(widthHeight[1]));
  }
  geometry.Width = static_cast<int>(widthHeight[0]);
  geometry.Height = static_cast<int>(widthHeight[1]);
  const vtkIdType pixels = vtkIdType(geometry.Width) * geometry.Height;
  if (mask->GetNumberOfComponents() != 1 || mask->GetNumberOfTuples() != pixels)
  {
    return fail("TrainingFanMask must hold width x height = " + std::to_string(geometry.Width) + " x " +
      std::to_string(geometry.Height) + " one-component values; it has " + std::to_string(mask->GetNumberOfTuples()) +
      " tuples of " + std::to_string(mask->GetNumberOfComponents()) + " components");
  }
  geometry.Mask.resize(pixels);
  for (vtkIdType p = 0; p < pixels; ++p)
  {
    geometry.Mask[p] = mask->GetComponent(p, 0) != 0 ? 1 : 0;
  }
  return true;
}

TrainingCoverage::TrainingCoverage(const TrainingGeometry& geometry)
  : Geometry(geometry)
{
  if (this->Geometry.Mask.size() != std::size_t(this->Geometry.Width) * this->Geometry.Height)
  {
    return; // not a geometry TrainingGeometryFromFieldData accepts: nothing to cover with
  }
  for (const auto& pose : this->Geometry.Poses)
  {
    SliceFrame frame;
    if (ComputeSliceFrame(pose.data(), 90.0, frame) != PoseStatus::Ok)
    {
      continue;
    }
    // x = origin + a c0 + b c1 + d n with c0, c1 the pose's pixel axes (mm per pixel) and n their unit
    // normal: (a, b, d) = [c0 c1 n]^-1 (x - origin). The third row is n itself (n is orthogonal to the
    // other two columns), so d is the signed distance to the plane even when c0 and c1 are sheared.
    double columns[3][3], inverse[3][3];
    for (int r = 0; r < 3; ++r)
    {
      columns[r][0] = frame.u[r] * frame.spacing[0];
      columns[r][1] = frame.v[r] * frame.spacing[1];
      columns[r][2] = frame.n[r];
    }
    vtkMath::Invert3x3(columns, inverse);
    Frame f;
    for (int r = 0; r < 3; ++r)
    {
      f.Rows[r][3] = 0;
      for (int k = 0; k < 3; ++k)
      {
        f.Rows[r][k] = inverse[r][k];
        f.Rows[r][3] -= inverse[r][k] * frame.origin[k];
      }
    }
    this->Frames.push_back(f);
  }
}

namespace
{
/// Narrows [lo, hi] to the indices i where low <= c0 + c1 i <= high may hold, widened by one index on
/// each side (the caller checks every pixel exactly); false when none can.
bool NarrowRow(double c0, double c1, double low, double high, int& lo, int& hi)
{
  if (c1 == 0)
  {
    return c0 >= low && c0 <= high;
  }
  double t1 = (low - c0) / c1, t2 = (high - c0) / c1;
  if (t1 > t2)
  {
    std::swap(t1, t2);
  }
  lo = static_cast<int>(std::max(double(lo), std::floor(t1) - 1));
  hi = static_cast<int>(std::min(double(hi), std::ceil(t2) + 1));
  return lo <= hi;
}
}

void TrainingCoverage::Compute(const SliceGeometry& slice, double elevationSigma, float* coverage) const
{
  const int W = slice.Width, H = slice.Height;
  if (W <= 0 || H <= 0)
  {
    return;
  }
  std::fill(coverage, coverage + std::size_t(W) * H, 0.0f);
  // For each frame: a, b, d at the slice's pixel (0, 0) and their steps along i and along j.
  struct Map
  {
    double At[3], Di[3], Dj[3];
  };
  const double* m = slice.ImageToReference;
  const double origin[3] = { m[3], m[7], m[11] }, di[3] = { m[0], m[4], m[8] }, dj[3] = { m[1], m[5], m[9] };
  std::vector<Map> maps(this->Frames.size());
  for (std::size_t t = 0; t < this->Frames.size(); ++t)
  {
    for (int r = 0; r < 3; ++r)
    {
      const double* row = this->Frames[t].Rows[r];
      maps[t].At[r] = vtkMath::Dot(row, origin) + row[3];
      maps[t].Di[r] = vtkMath::Dot(row, di);
      maps[t].Dj[r] = vtkMath::Dot(row, dj);
    }
  }
  const double sigma = std::max(0.0, elevationSigma);
  const double reach = sigma > 0 ? CullSigmas * sigma : 1e-6;
  const double exponent = sigma > 0 ? -0.5 / (sigma * sigma) : 0.0;
  const int frameWidth = this->Geometry.Width, frameHeight = this->Geometry.Height;
  const unsigned char* mask = this->Geometry.Mask.data();
  vtkSMPTools::For(0, H, 8, [&](vtkIdType rowBegin, vtkIdType rowEnd) {
    for (vtkIdType j = rowBegin; j < rowEnd; ++j)
    {
      float* out = coverage + std::size_t(j) * W;
      for (const Map& map : maps)
      {
        double c[3];
        for (int r = 0; r < 3; ++r)
        {
          c[r] = map.At[r] + j * map.Dj[r];
        }
        // Only the pixels whose distance and projection qualify are visited: each of d, a, b is affine
        // along the row, so each constraint holds on an interval of i. NarrowRow brackets the
        // intersection; trimming its ends with the exact test leaves the pixels where all three hold
        // (the intersection of intervals is an interval; the rounded affine values are monotone in i).
        int lo = 0, hi = W - 1;
        if (!NarrowRow(c[2], map.Di[2], -reach, reach, lo, hi) ||
          !NarrowRow(c[0], map.Di[0], -0.5, frameWidth - 0.5, lo, hi) ||
          !NarrowRow(c[1], map.Di[1], -0.5, frameHeight - 0.5, lo, hi))
        {
          continue;
        }
        auto qualifies = [&](int i) {
          const double a = std::floor(c[0] + i * map.Di[0] + 0.5), b = std::floor(c[1] + i * map.Di[1] + 0.5);
          return std::abs(c[2] + i * map.Di[2]) <= reach && a >= 0 && a < frameWidth && b >= 0 && b < frameHeight;
        };
        while (lo <= hi && !qualifies(lo))
        {
          ++lo;
        }
        while (hi >= lo && !qualifies(hi))
        {
          --hi;
        }
        // exp(e d(i)^2) along the row without an exp per pixel: with d(i) = d0 + i s, the ratio of
        // neighbours is exp(e (2 d(i) s + s^2)), itself multiplied by exp(2 e s^2) per step. Every d is
        // within the reach, so neither factor over- or underflows, and in double the relative drift over
        // a row of a few thousand pixels stays below 1e-12.
        const double step = map.Di[2], d0 = c[2] + lo * step;
        double weight = std::exp(exponent * d0 * d0);
        double ratio = std::exp(exponent * (2 * d0 * step + step * step));
        const double ratioStep = std::exp(2 * exponent * step * step);
        for (int i = lo; i <= hi; ++i, weight *= ratio, ratio *= ratioStep)
        {
          // a + 0.5 >= 0 here, so truncation rounds like floor (and needs no libm call).
          const int a = static_cast<int>(c[0] + i * map.Di[0] + 0.5), b = static_cast<int>(c[1] + i * map.Di[1] + 0.5);
          if (mask[std::size_t(b) * frameWidth + a])
          {
            out[i] += static_cast<float>(weight);
          }
        }
      }
    }
  });
}

void TrainingCoverage::ComputePoints(
  const double* points, std::int64_t count, double elevationSigma, float* coverage) const
{
  const double sigma = std::max(0.0, elevationSigma);
  const double reach = sigma > 0 ? CullSigmas * sigma : 1e-6;
  const double exponent = sigma > 0 ? -0.5 / (sigma * sigma) : 0.0;
  const int frameWidth = this->Geometry.Width, frameHeight = this->Geometry.Height;
  const unsigned char* mask = this->Geometry.Mask.data();
  vtkSMPTools::For(0, count, 1024, [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t p = begin; p < end; ++p)
    {
      const double* x = points + 3 * p;
      double sum = 0;
      for (const Frame& frame : this->Frames)
      {
        double c[3];
        for (int r = 0; r < 3; ++r)
        {
          c[r] = vtkMath::Dot(frame.Rows[r], x) + frame.Rows[r][3];
        }
        const double a = std::floor(c[0] + 0.5), b = std::floor(c[1] + 0.5);
        if (std::abs(c[2]) <= reach && a >= 0 && a < frameWidth && b >= 0 && b < frameHeight &&
          mask[std::size_t(b) * frameWidth + std::size_t(a)])
        {
          sum += std::exp(exponent * c[2] * c[2]);
        }
      }
      coverage[p] = static_cast<float>(sum);
    }
  });
}

} // namespace bigus
