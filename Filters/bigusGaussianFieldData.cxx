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
#include "vtkUnsignedCharArray.h"

#include <algorithm>

#include <cmath>

namespace bigus
{

bool FieldFromPolyData(vtkPolyData* data, GaussianField& field, FieldModel& model, std::string* error)
{
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
      if (!(s > 0) || !std::isfinite(s) || !std::isfinite(p[k]))
      {
        return fail("point " + std::to_string(i) + " has a non-positive or non-finite Scale or position");
      }
      field.Means[3 * i + k] = static_cast<float>(p[k]);
      field.LogScales[3 * i + k] = static_cast<float>(std::log(s));
    }
    for (int k = 0; k < 4; ++k)
    {
      field.Quaternions[4 * i + k] = static_cast<float>(rotation->GetComponent(i, k));
    }
    field.Reflectivities[i] = static_cast<float>(reflectivity->GetComponent(i, 0));
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

vtkSmartPointer<vtkDataArray> IntensityArray(const std::vector<float>& I, int scalarType)
{
  vtkSmartPointer<vtkDataArray> scalars;
  if (scalarType == VTK_UNSIGNED_CHAR)
  {
    auto bytes = vtkSmartPointer<vtkUnsignedCharArray>::New();
    bytes->SetNumberOfTuples(static_cast<vtkIdType>(I.size()));
    for (std::size_t p = 0; p < I.size(); ++p)
    {
      bytes->SetValue(p, static_cast<unsigned char>(std::lround(255.0f * std::min(1.0f, std::max(0.0f, I[p])))));
    }
    scalars = bytes;
  }
  else
  {
    auto values = vtkSmartPointer<vtkFloatArray>::New();
    values->SetNumberOfTuples(static_cast<vtkIdType>(I.size()));
    std::copy(I.begin(), I.end(), values->GetPointer(0));
    scalars = values;
  }
  scalars->SetName("Intensity");
  return scalars;
}

bool IsIntensityScalarType(int scalarType, std::string* error)
{
  if (scalarType == VTK_FLOAT || scalarType == VTK_UNSIGNED_CHAR)
  {
    return true;
  }
  if (error)
  {
    *error = std::string("scalar type ") + vtkImageScalarTypeNameMacro(scalarType) + " (" + std::to_string(scalarType) +
      ") is not supported: use VTK_FLOAT or VTK_UNSIGNED_CHAR";
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
  for (const auto& entry : { std::make_pair("ElevationSigma", model.ElevationSigma), std::make_pair("Gamma", model.Gamma),
         std::make_pair("PixelSpacing", model.PixelSpacing) })
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
    *error = "the fan mask must be a " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) +
      " image or a " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) + " x " + std::to_string(dims[2]) +
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
  data.Mask.resize(maskPixels);
  for (vtkIdType p = 0; p < maskPixels; ++p)
  {
    data.Mask[p] = maskValues->GetComponent(p, 0) != 0 ? 1 : 0;
  }
  data.TrainFrames.clear();
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
      *error = "frame " + std::to_string(f) + " is outside the " + std::to_string(frameCount) +
        " frames of the pose sequence";
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
