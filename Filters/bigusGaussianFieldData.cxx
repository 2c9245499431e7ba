#include "bigusGaussianFieldData.h"

#include "bigusBackend.h"

#include "vtkCellArray.h"
#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkIntArray.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkPoints.h"
#include "vtkPolyData.h"
#include "vtkStreamingDemandDrivenPipeline.h"

#include <algorithm>

#include <cmath>
#include <type_traits>
#include <limits>

namespace bigus
{

namespace
{
/**
 * Every valid frame's ImageToReference is an affine map whose pixel axes have the lengths of the sweep's (the median
 * over its valid frames, within 1 %): a tracked pose is rigid, and only the pixel spacing scales it. A frame whose
 * pose is not finite, not affine, or scaled (a ProbeToTracker that is not rigid) is refused with its index.
 */
bool CheckRigidPoses(const TrainingData& data, std::string* error)
{
  std::vector<double> lengths[2];
  auto length = [](const std::array<double, 16>& m, int column) {
    return std::sqrt(m[column] * m[column] + m[4 + column] * m[4 + column] + m[8 + column] * m[8 + column]);
  };
  for (int f = 0; f < data.Count(); ++f)
  {
    const std::array<double, 16>& m = data.Poses[f];
    if (!data.IsValid(f))
    {
      continue;
    }
    const bool finite = std::all_of(m.begin(), m.end(), [](double v) { return std::abs(v) <= 1e9; });
    if (!finite || m[12] != 0 || m[13] != 0 || m[14] != 0 || m[15] != 1)
    {
      *error = "frame " + std::to_string(f) + "'s ImageToReference " +
        (finite ? "is not affine (its last row is not 0 0 0 1)" : "is not finite within 1e9 mm") +
        " (mark the frame INVALID, or fix its transforms)";
      return false;
    }
    for (int c = 0; c < 2; ++c)
    {
      lengths[c].push_back(length(m, c));
    }
  }
  if (lengths[0].empty())
  {
    return true;
  }
  double median[2];
  for (int c = 0; c < 2; ++c)
  {
    std::vector<double> sorted = lengths[c];
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    median[c] = sorted[sorted.size() / 2];
  }
  for (int f = 0; f < data.Count(); ++f)
  {
    if (!data.IsValid(f))
    {
      continue;
    }
    for (int c = 0; c < 2; ++c)
    {
      const double l = length(data.Poses[f], c);
      if (!(l > 0) || std::abs(l - median[c]) > 0.01 * median[c])
      {
        *error = "frame " + std::to_string(f) + "'s ImageToReference is not rigid: its " + (c ? "row" : "column") +
          " axis is " + std::to_string(l) + " mm a pixel where the sweep's other frames have " +
          std::to_string(median[c]) + " (a ProbeToTracker or ImageToProbe that scales?)";
        return false;
      }
    }
  }
  return true;
}
}

bool FieldFromPolyData(vtkPolyData* data, GaussianField& field, FieldModel& model, std::string* error)
{
  // Bounds no ultrasound scene reaches, far inside float's range: a standard deviation of 1 km, a position 1000 km
  // from the origin (their squares and products stay finite in the renderers' float arithmetic).
  constexpr double MaximumScale = 1e6, MaximumCoordinate = 1e9;
  auto fail = [&](const std::string& why) {
    if (error)
    {
      *error = "Gaussian field: " + why;
    }
    return false;
  };
  if (!data || !data->GetPoints() || data->GetNumberOfPoints() == 0)
  {
    return fail("no points (one point per Gaussian expected)");
  }
  const vtkIdType n = data->GetNumberOfPoints();
  vtkDataArray* scale = data->GetPointData()->GetArray("Scale");
  vtkDataArray* rotation = data->GetPointData()->GetArray("Rotation");
  vtkDataArray* reflectivity = data->GetPointData()->GetArray("Reflectivity");
  if (!scale || scale->GetNumberOfComponents() != 3 || scale->GetNumberOfTuples() != n)
  {
    return fail("point data Scale must hold 3 standard deviations (mm) per point");
  }
  if (!rotation || rotation->GetNumberOfComponents() != 4 || rotation->GetNumberOfTuples() != n)
  {
    return fail("point data Rotation must hold a quaternion (w, x, y, z) per point");
  }
  if (!reflectivity || reflectivity->GetNumberOfComponents() != 1 || reflectivity->GetNumberOfTuples() != n)
  {
    return fail("point data Reflectivity must hold one value per point");
  }
  field = GaussianField();
  field.Resize(n);
  for (vtkIdType i = 0; i < n; ++i)
  {
    double p[3];
    data->GetPoint(i, p);
    for (int k = 0; k < 3; ++k)
    {
      const double s = scale->GetComponent(i, k);
      if (!(s > 0) || !(s <= MaximumScale) || !(std::abs(p[k]) <= MaximumCoordinate))
      {
        return fail("Gaussian " + std::to_string(i) + " (point " + std::to_string(i) +
          ") has a Scale that is not in (0, 1e6] mm or a position that is not finite within 1e9 mm");
      }
      field.Means[3 * i + k] = static_cast<float>(p[k]);
      field.LogScales[3 * i + k] = static_cast<float>(std::log(s));
    }
    double norm = 0;
    bool representable = true;
    for (int k = 0; k < 4; ++k)
    {
      const double q = rotation->GetComponent(i, k);
      norm += q * q;
      representable = representable && std::abs(q) <= VTK_FLOAT_MAX;
      field.Quaternions[4 * i + k] = representable ? static_cast<float>(q) : 0.f;
    }
    if (!(norm > 1e-12) || !std::isfinite(norm) || !representable)
    {
      return fail("Gaussian " + std::to_string(i) + " has a Rotation quaternion that is zero or not finite");
    }
    const double r = reflectivity->GetComponent(i, 0);
    if (!std::isfinite(r) || std::abs(r) > VTK_FLOAT_MAX)
    {
      return fail("Gaussian " + std::to_string(i) + " has a Reflectivity that is not a finite float");
    }
    field.Reflectivities[i] = static_cast<float>(r);
  }
  model = FieldModel();
  auto value = [&](const char* name, double& out) {
    vtkDataArray* a = data->GetFieldData() ? data->GetFieldData()->GetArray(name) : nullptr;
    if (a && a->GetNumberOfTuples() > 0 && std::isfinite(a->GetTuple1(0)))
    {
      out = a->GetTuple1(0);
    }
  };
  value("ElevationSigma", model.ElevationSigma);
  value("Gamma", model.Gamma);
  value("PixelSpacing", model.PixelSpacing);
  return true;
}

bool FieldCache::Update(vtkPolyData* data, std::string* error)
{
  if (data && data == this->Source.GetPointer() && data->GetMTime() == this->SourceTime)
  {
    if (!this->Valid && error)
    {
      *error = this->Error;
    }
    return this->Valid;
  }
  this->Source = data;
  this->SourceTime = data ? data->GetMTime() : 0;
  this->Error.clear();
  this->CoverageError.clear();
  this->Coverage = TrainingCoverage();
  this->Valid = FieldFromPolyData(data, this->Field, this->Model, &this->Error);
  if (!this->Valid)
  {
    this->Field = GaussianField();
    if (error)
    {
      *error = this->Error;
    }
    return false;
  }
  data->GetPoints()->GetBounds(this->Bounds);
  float largest = -VTK_FLOAT_MAX;
  for (float l : this->Field.LogScales)
  {
    largest = std::max(largest, l);
  }
  this->LargestScale = std::exp(double(largest));
  TrainingGeometry geometry;
  if (TrainingGeometryFromFieldData(data->GetFieldData(), geometry, &this->CoverageError))
  {
    this->Coverage = TrainingCoverage(geometry);
  }
  return true;
}

const TrainingCoverage* FieldCache::GetCoverage(std::string* error) const
{
  if (!this->Valid || !this->CoverageError.empty())
  {
    if (error)
    {
      *error = this->Valid ? this->CoverageError : this->Error;
    }
    return nullptr;
  }
  return &this->Coverage;
}

bool FieldCache::GetOutputCoverage(bool wanted, const TrainingCoverage*& coverage, std::string* error) const
{
  coverage = nullptr;
  if (!wanted)
  {
    return true;
  }
  const TrainingCoverage* c = this->GetCoverage(error);
  if (!c)
  {
    return false;
  }
  coverage = c->IsEmpty() ? nullptr : c;
  return true;
}

Renderer* RendererCache::Get(const std::string& name, std::string* error, std::string* notice)
{
  if (!this->Held || name != this->Name)
  {
    this->Held = CreateRenderer(name, error, notice);
    this->Name = name;
  }
  return this->Held.get();
}

RenderOptions RenderOptionsFor(const FieldModel& model, double elevationSigma, double cutoff)
{
  RenderOptions options;
  options.ElevationSigma = elevationSigma >= 0 ? elevationSigma : model.ElevationSigma;
  options.Gamma = model.Gamma;
  options.Cutoff = cutoff;
  return options;
}

double IntensityUnit(int scalarType)
{
  return scalarType == VTK_FLOAT || scalarType == VTK_DOUBLE ? 1.0 : 255.0;
}

namespace
{
template <typename T>
void FillIntensities(const std::vector<float>& I, double unit, T* out)
{
  const double lowest = static_cast<double>(std::numeric_limits<T>::lowest());
  const double highest = static_cast<double>(std::numeric_limits<T>::max());
  for (std::size_t p = 0; p < I.size(); ++p)
  {
    const double v = unit * I[p];
    if constexpr (std::is_integral<T>::value)
    {
      // NaN (no sample) becomes the lowest value, as a clamp of nothing would; others round half up, then clamp.
      out[p] = static_cast<T>(std::isnan(v) ? lowest : std::min(highest, std::max(lowest, std::floor(v + 0.5))));
    }
    else
    {
      out[p] = static_cast<T>(v);
    }
  }
}
}

vtkSmartPointer<vtkDataArray> IntensityArray(const std::vector<float>& I, int scalarType)
{
  vtkSmartPointer<vtkDataArray> scalars = vtk::TakeSmartPointer(vtkDataArray::CreateDataArray(scalarType));
  scalars->SetNumberOfTuples(static_cast<vtkIdType>(I.size()));
  const double unit = IntensityUnit(scalarType);
  switch (scalarType)
  {
    vtkTemplateMacro(FillIntensities(I, unit, static_cast<VTK_TT*>(scalars->GetVoidPointer(0))));
  }
  scalars->SetName("Intensity");
  return scalars;
}

vtkSmartPointer<vtkDataArray> CoverageArray(const std::vector<float>& coverage)
{
  auto values = vtkSmartPointer<vtkFloatArray>::New();
  values->SetName("Coverage");
  values->SetNumberOfTuples(static_cast<vtkIdType>(coverage.size()));
  std::copy(coverage.begin(), coverage.end(), values->GetPointer(0));
  return values;
}

bool IsIntensityScalarType(int scalarType, std::string* error)
{
  switch (scalarType)
  {
    case VTK_FLOAT:
    case VTK_DOUBLE:
    case VTK_CHAR:
    case VTK_SIGNED_CHAR:
    case VTK_UNSIGNED_CHAR:
    case VTK_SHORT:
    case VTK_UNSIGNED_SHORT:
    case VTK_INT:
    case VTK_UNSIGNED_INT:
      return true;
    default:
      break;
  }
  if (error)
  {
    *error = std::string("scalar type ") + vtkImageScalarTypeNameMacro(scalarType) + " (" + std::to_string(scalarType) +
      ") is not supported: use VTK_FLOAT, VTK_DOUBLE, VTK_CHAR, VTK_SIGNED_CHAR, VTK_UNSIGNED_CHAR, VTK_SHORT, "
      "VTK_UNSIGNED_SHORT, VTK_INT or VTK_UNSIGNED_INT";
  }
  return false;
}

void FieldToPolyData(const GaussianField& field, const FieldModel& model, vtkPolyData* data)
{
  const vtkIdType n = field.Count();
  vtkNew<vtkPoints> points;
  points->SetDataTypeToFloat();
  points->SetNumberOfPoints(n);
  vtkNew<vtkFloatArray> scales, rotations, reflectivities;
  scales->SetName("Scale");
  scales->SetNumberOfComponents(3);
  scales->SetNumberOfTuples(n);
  rotations->SetName("Rotation");
  rotations->SetNumberOfComponents(4);
  rotations->SetNumberOfTuples(n);
  reflectivities->SetName("Reflectivity");
  reflectivities->SetNumberOfTuples(n);
  vtkNew<vtkCellArray> vertices;
  for (vtkIdType i = 0; i < n; ++i)
  {
    points->SetPoint(i, field.Means[3 * i], field.Means[3 * i + 1], field.Means[3 * i + 2]);
    for (int k = 0; k < 3; ++k)
    {
      scales->SetTypedComponent(i, k, std::exp(field.LogScales[3 * i + k]));
    }
    const float* q = &field.Quaternions[4 * i];
    const float norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int k = 0; k < 4; ++k)
    {
      rotations->SetTypedComponent(i, k, norm > 0 ? q[k] / norm : (k == 0 ? 1.f : 0.f));
    }
    reflectivities->SetValue(i, field.Reflectivities[i]);
    vertices->InsertNextCell(1, &i);
  }
  data->Initialize();
  data->SetPoints(points);
  data->SetVerts(vertices);
  data->GetPointData()->AddArray(scales);
  data->GetPointData()->AddArray(rotations);
  data->GetPointData()->AddArray(reflectivities);
  data->GetPointData()->SetActiveScalars("Reflectivity");
  for (const auto& entry : { std::make_pair("ElevationSigma", model.ElevationSigma),
         std::make_pair("Gamma", model.Gamma), std::make_pair("PixelSpacing", model.PixelSpacing) })
  {
    vtkNew<vtkDoubleArray> a;
    a->SetName(entry.first);
    a->InsertNextValue(entry.second);
    data->GetFieldData()->AddArray(a);
  }
}

bool TrainingDataFromSequence(vtkImageData* sequence, vtkImageData* mask, TrainingData& data, std::string* error)
{
  vtkDataArray* pixels = sequence ? sequence->GetPointData()->GetScalars() : nullptr;
  vtkDataArray* poses = sequence ? sequence->GetFieldData()->GetArray("ImageToReference") : nullptr;
  int dims[3] = { 0, 0, 0 };
  if (sequence)
  {
    sequence->GetDimensions(dims);
  }
  if (!pixels || pixels->GetNumberOfComponents() != 1 || !poses || poses->GetNumberOfComponents() != 16 ||
    poses->GetNumberOfTuples() != dims[2])
  {
    *error = "a tracked frame sequence needs W x H x N one-component scalars and field data ImageToReference "
             "with N tuples of 16";
    return false;
  }
  const vtkIdType framePixels = vtkIdType(dims[0]) * dims[1];
  vtkDataArray* maskValues = mask ? mask->GetPointData()->GetScalars() : nullptr;
  const vtkIdType maskPixels = maskValues ? maskValues->GetNumberOfTuples() : 0;
  if (maskPixels != framePixels && maskPixels != framePixels * dims[2])
  {
    *error = "the fan mask must be a " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) + " image or a " +
      std::to_string(dims[0]) + " x " + std::to_string(dims[1]) + " x " + std::to_string(dims[2]) +
      " per-frame mask sequence";
    return false;
  }
  data.Width = dims[0];
  data.Height = dims[1];
  const double scale = pixels->GetDataType() == VTK_UNSIGNED_CHAR ? 1.0 / 255.0 : 1.0;
  data.Frames.resize(std::size_t(framePixels) * dims[2]);
  for (vtkIdType p = 0; p < framePixels * dims[2]; ++p)
  {
    data.Frames[p] = static_cast<float>(std::min(1.0, std::max(0.0, pixels->GetComponent(p, 0) * scale)));
  }
  data.Poses.resize(dims[2]);
  for (int k = 0; k < dims[2]; ++k)
  {
    poses->GetTuple(k, data.Poses[k].data());
  }
  data.Valid.clear();
  vtkDataArray* valid = sequence->GetFieldData()->GetArray("FrameValid");
  if (valid && valid->GetNumberOfTuples() == dims[2])
  {
    for (int k = 0; k < dims[2]; ++k)
    {
      data.Valid.push_back(valid->GetTuple1(k) != 0 ? 1 : 0);
    }
  }
  data.Timestamps.clear();
  vtkDataArray* stamps = sequence->GetFieldData()->GetArray("Timestamp");
  if (stamps && stamps->GetNumberOfComponents() == 1 && stamps->GetNumberOfTuples() == dims[2])
  {
    for (int k = 0; k < dims[2]; ++k)
    {
      data.Timestamps.push_back(stamps->GetTuple1(k));
    }
  }
  if (!CheckRigidPoses(data, error))
  {
    return false;
  }
  data.Mask.resize(maskPixels);
  for (vtkIdType p = 0; p < maskPixels; ++p)
  {
    const double value = maskValues->GetComponent(p, 0);
    if (!std::isfinite(value))
    {
      *error = "the fan mask is not finite at pixel " + std::to_string(p % dims[0]) + ", " +
        std::to_string(p / dims[0] % dims[1]) +
        (maskPixels > framePixels ? " of frame " + std::to_string(p / framePixels) : std::string()) +
        " (a mask is 0 outside the fan and non-zero inside)";
      return false;
    }
    data.Mask[p] = value != 0 ? 1 : 0;
  }
  data.TrainFrames.clear();
  return true;
}

bool CheckMaskCount(int masks, int sweeps, std::string* error)
{
  if (masks == 0 || masks == sweeps)
  {
    return true;
  }
  if (error)
  {
    *error = "input port 1: " + std::to_string(masks) + " fan masks for " + std::to_string(sweeps) +
      " sweeps; connect one mask per sweep, in the sweeps' order, or none";
  }
  return false;
}

bool TrainingDataFromSweeps(const std::vector<SweepInput>& sweeps, TrainingData& data, std::string* error)
{
  data = TrainingData();
  if (sweeps.empty())
  {
    *error = "no sweep";
    return false;
  }
  struct Loaded
  {
    TrainingData Data;
    double Spacing = 0;                      // mm per pixel
    double Bounds[6] = { 0, 0, 0, 0, 0, 0 }; // mm, the valid frames' corners
  };
  std::vector<Loaded> loaded(sweeps.size());
  for (std::size_t s = 0; s < sweeps.size(); ++s)
  {
    Loaded& l = loaded[s];
    if (!TrainingDataFromSequence(sweeps[s].Sequence, sweeps[s].Mask, l.Data, error))
    {
      *error = sweeps[s].Name + ": " + *error;
      return false;
    }
    // No valid frame first: then the estimated mask is empty too, and that is not the cause.
    bool anyValid = false;
    for (int f = 0; f < l.Data.Count() && !anyValid; ++f)
    {
      anyValid = l.Data.IsValid(f);
    }
    if (!anyValid)
    {
      *error = sweeps[s].Name + ": every one of its " + std::to_string(l.Data.Count()) +
        " frames is marked INVALID (FrameValid 0: a tracker or image status), so the sweep has nothing to train on";
      return false;
    }
    if (std::none_of(l.Data.Mask.begin(), l.Data.Mask.end(), [](unsigned char v) { return v != 0; }))
    {
      *error = sweeps[s].Name + ": the fan mask is empty (no imaged pixel), so the sweep has nothing to train on";
      return false;
    }
    vtkDataArray* valid = sweeps[s].Sequence->GetFieldData()->GetArray("FrameValid");
    if (valid && valid->GetNumberOfTuples() != l.Data.Count())
    {
      valid = nullptr;
    }
    std::vector<double> spacings;
    for (int r = 0; r < 3; ++r)
    {
      l.Bounds[2 * r] = std::numeric_limits<double>::infinity();
      l.Bounds[2 * r + 1] = -std::numeric_limits<double>::infinity();
    }
    for (int f = 0; f < l.Data.Count(); ++f)
    {
      const std::array<double, 16>& m = l.Data.Poses[f];
      if ((valid && valid->GetTuple1(f) == 0) ||
        !std::all_of(m.begin(), m.end(), [](double v) { return std::isfinite(v); }))
      {
        continue;
      }
      for (int c = 0; c < 2; ++c)
      {
        spacings.push_back(std::sqrt(m[c] * m[c] + m[4 + c] * m[4 + c] + m[8 + c] * m[8 + c]));
      }
      for (double i : { 0.0, l.Data.Width - 1.0 })
      {
        for (double j : { 0.0, l.Data.Height - 1.0 })
        {
          for (int r = 0; r < 3; ++r)
          {
            const double x = m[4 * r] * i + m[4 * r + 1] * j + m[4 * r + 3];
            l.Bounds[2 * r] = std::min(l.Bounds[2 * r], x);
            l.Bounds[2 * r + 1] = std::max(l.Bounds[2 * r + 1], x);
          }
        }
      }
    }
    if (spacings.empty())
    {
      *error = sweeps[s].Name + ": no valid frame with a finite ImageToReference";
      return false;
    }
    std::nth_element(spacings.begin(), spacings.begin() + spacings.size() / 2, spacings.end());
    l.Spacing = spacings[spacings.size() / 2];
    if (s > 0 && (l.Spacing > 10 * loaded[0].Spacing || loaded[0].Spacing > 10 * l.Spacing))
    {
      char text[300];
      std::snprintf(text, sizeof(text),
        ": pixel spacing %.4g mm against %.4g mm in %s: the sweeps are not in the same units (metres against "
        "millimetres?), or a calibration does not belong to its sweep",
        l.Spacing, loaded[0].Spacing, sweeps[0].Name.c_str());
      *error = sweeps[s].Name + text;
      return false;
    }
  }
  // Every sweep's bounds joined to the first sweep's through overlapping bounds.
  std::vector<bool> joined(sweeps.size(), false);
  joined[0] = true;
  for (bool grew = true; grew;)
  {
    grew = false;
    for (std::size_t a = 0; a < sweeps.size(); ++a)
    {
      for (std::size_t b = 0; b < sweeps.size() && !joined[a]; ++b)
      {
        bool overlap = joined[b];
        for (int r = 0; r < 3 && overlap; ++r)
        {
          overlap = loaded[a].Bounds[2 * r] <= loaded[b].Bounds[2 * r + 1] &&
            loaded[b].Bounds[2 * r] <= loaded[a].Bounds[2 * r + 1];
        }
        if (overlap)
        {
          joined[a] = grew = true;
        }
      }
    }
  }
  for (std::size_t s = 0; s < sweeps.size(); ++s)
  {
    if (!joined[s])
    {
      const double* b = loaded[s].Bounds;
      char text[300];
      std::snprintf(text, sizeof(text),
        ": its frames (x %.1f to %.1f, y %.1f to %.1f, z %.1f to %.1f mm) share no region with the other sweeps'", b[0],
        b[1], b[2], b[3], b[4], b[5]);
      *error = sweeps[s].Name + text;
      return false;
    }
  }
  if (sweeps.size() == 1)
  {
    data = std::move(loaded[0].Data);
    return true;
  }
  for (const Loaded& l : loaded)
  {
    data.Width = std::max(data.Width, l.Data.Width);
    data.Height = std::max(data.Height, l.Data.Height);
  }
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  for (std::size_t s = 0; s < loaded.size(); ++s)
  {
    const TrainingData& d = loaded[s].Data;
    const std::size_t first = data.Poses.size();
    data.Poses.insert(data.Poses.end(), d.Poses.begin(), d.Poses.end());
    data.Sweeps.insert(data.Sweeps.end(), d.Poses.size(), static_cast<int>(s));
    data.Timestamps.insert(data.Timestamps.end(), d.Timestamps.begin(), d.Timestamps.end());
    if (d.Valid.empty())
    {
      data.Valid.insert(data.Valid.end(), d.Poses.size(), 1);
    }
    else
    {
      data.Valid.insert(data.Valid.end(), d.Valid.begin(), d.Valid.end());
    }
    data.Frames.resize(pixels * data.Poses.size(), 0.0f);
    data.Mask.resize(pixels * data.Poses.size(), 0);
    for (int f = 0; f < d.Count(); ++f)
    {
      const unsigned char* mask = d.MaskOf(f);
      for (int j = 0; j < d.Height; ++j)
      {
        const std::size_t from = std::size_t(f) * d.Width * d.Height + std::size_t(j) * d.Width;
        const std::size_t to = (first + f) * pixels + std::size_t(j) * data.Width;
        std::copy_n(&d.Frames[from], d.Width, &data.Frames[to]);
        std::copy_n(mask + std::size_t(j) * d.Width, d.Width, &data.Mask[to]);
      }
    }
  }
  if (data.Timestamps.size() != data.Poses.size())
  {
    data.Timestamps.clear(); // a sweep without them: none known
  }
  return true;
}

bool ChosenFrames(vtkIdList* list, vtkIdType frameCount, std::vector<vtkIdType>& frames, std::string* error)
{
  frames.clear();
  if (!list || list->GetNumberOfIds() == 0)
  {
    for (vtkIdType f = 0; f < frameCount; ++f)
    {
      frames.push_back(f);
    }
    return true;
  }
  for (vtkIdType k = 0; k < list->GetNumberOfIds(); ++k)
  {
    const vtkIdType f = list->GetId(k);
    if (f < 0 || f >= frameCount)
    {
      *error =
        "frame " + std::to_string(f) + " is outside the " + std::to_string(frameCount) + " frames of the pose sequence";
      return false;
    }
    frames.push_back(f);
  }
  return true;
}

void SetFrameSequenceInformation(vtkInformation* poseInfo, vtkIdList* list, int scalarType, vtkInformation* outInfo)
{
  int extent[6];
  poseInfo->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent);
  if (list && list->GetNumberOfIds() > 0)
  {
    extent[4] = 0;
    extent[5] = static_cast<int>(list->GetNumberOfIds()) - 1;
  }
  const double spacing[3] = { 1, 1, 1 }, origin[3] = { 0, 0, 0 };
  outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent, 6);
  outInfo->Set(vtkDataObject::SPACING(), spacing, 3);
  outInfo->Set(vtkDataObject::ORIGIN(), origin, 3);
  vtkDataObject::SetPointDataActiveScalarInfo(outInfo, scalarType, 1);
}

void CopyFrameFieldData(vtkFieldData* in, vtkIdType frameCount, const std::vector<vtkIdType>& frames, vtkFieldData* out)
{
  const vtkIdType count = static_cast<vtkIdType>(frames.size());
  for (int a = 0; a < in->GetNumberOfArrays(); ++a)
  {
    vtkDataArray* source = in->GetArray(a);
    if (!source || !source->GetName() || source->GetNumberOfTuples() != frameCount)
    {
      continue;
    }
    vtkSmartPointer<vtkDataArray> copy = vtkSmartPointer<vtkDataArray>::Take(source->NewInstance());
    copy->SetName(source->GetName());
    copy->SetNumberOfComponents(source->GetNumberOfComponents());
    copy->SetNumberOfTuples(count);
    for (vtkIdType m = 0; m < count; ++m)
    {
      copy->SetTuple(m, frames[m], source);
    }
    out->AddArray(copy);
  }
  if (!out->GetArray("FrameIndex"))
  {
    vtkNew<vtkIntArray> index;
    index->SetName("FrameIndex");
    index->SetNumberOfTuples(count);
    for (vtkIdType m = 0; m < count; ++m)
    {
      index->SetValue(m, static_cast<int>(frames[m]));
    }
    out->AddArray(index);
  }
}

} // namespace bigus
