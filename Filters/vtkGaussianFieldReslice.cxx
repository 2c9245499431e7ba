#include "vtkGaussianFieldReslice.h"

#include "bigusGaussianFieldData.h"
#include "bigusRenderer.h"

#include "vtkAlgorithmOutput.h"
#include "vtkFloatArray.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkStreamingDemandDrivenPipeline.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkGaussianFieldReslice);
vtkCxxSetObjectMacro(vtkGaussianFieldReslice, ResliceAxes, vtkMatrix4x4);
vtkCxxSetObjectMacro(vtkGaussianFieldReslice, InformationInput, vtkImageData);

namespace
{
constexpr double Unset = VTK_DOUBLE_MAX;
constexpr int UnsetExtent = VTK_INT_MIN;
}

vtkGaussianFieldReslice::vtkGaussianFieldReslice()
{
  this->SetOutputSpacingToDefault();
  this->SetOutputOriginToDefault();
  this->SetOutputExtentToDefault();
  this->SetBackend("cpu");
}

vtkGaussianFieldReslice::~vtkGaussianFieldReslice()
{
  this->SetResliceAxes(nullptr);
  this->SetInformationInput(nullptr);
  this->SetBackend(nullptr);
}

void vtkGaussianFieldReslice::SetOutputSpacingToDefault()
{
  this->SetOutputSpacing(Unset, Unset, Unset);
}

void vtkGaussianFieldReslice::SetOutputOriginToDefault()
{
  this->SetOutputOrigin(Unset, Unset, Unset);
}

void vtkGaussianFieldReslice::SetOutputExtentToDefault()
{
  this->SetOutputExtent(UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent);
}

void vtkGaussianFieldReslice::SetResliceAxesDirectionCosines(
  double x0, double x1, double x2, double y0, double y1, double y2, double z0, double z1, double z2)
{
  if (!this->ResliceAxes)
  {
    vtkNew<vtkMatrix4x4> axes;
    this->SetResliceAxes(axes);
  }
  const double columns[3][3] = { { x0, x1, x2 }, { y0, y1, y2 }, { z0, z1, z2 } };
  for (int c = 0; c < 3; ++c)
  {
    for (int r = 0; r < 3; ++r)
    {
      this->ResliceAxes->SetElement(r, c, columns[c][r]);
    }
  }
  this->Modified();
}

void vtkGaussianFieldReslice::SetResliceAxesOrigin(double x, double y, double z)
{
  if (!this->ResliceAxes)
  {
    vtkNew<vtkMatrix4x4> axes;
    this->SetResliceAxes(axes);
  }
  this->ResliceAxes->SetElement(0, 3, x);
  this->ResliceAxes->SetElement(1, 3, y);
  this->ResliceAxes->SetElement(2, 3, z);
  this->Modified();
}

vtkMTimeType vtkGaussianFieldReslice::GetMTime()
{
  vtkMTimeType t = this->Superclass::GetMTime();
  if (this->ResliceAxes)
  {
    t = std::max(t, this->ResliceAxes->GetMTime());
  }
  if (this->InformationInput)
  {
    t = std::max(t, this->InformationInput->GetMTime());
  }
  return t;
}

int vtkGaussianFieldReslice::FillInputPortInformation(int, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkPolyData");
  return 1;
}

int vtkGaussianFieldReslice::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  double spacing[3], origin[3];
  int extent[6];
  std::copy(this->OutputSpacing, this->OutputSpacing + 3, spacing);
  std::copy(this->OutputOrigin, this->OutputOrigin + 3, origin);
  std::copy(this->OutputExtent, this->OutputExtent + 6, extent);
  if (this->InformationInput)
  {
    this->InformationInput->GetSpacing(spacing);
    this->InformationInput->GetOrigin(origin);
    this->InformationInput->GetExtent(extent);
  }
  const bool planar = this->OutputDimensionality == 2;
  const bool needField = spacing[0] == Unset || spacing[1] == Unset || (!planar && spacing[2] == Unset) ||
    origin[0] == Unset || origin[1] == Unset || (!planar && origin[2] == Unset) || extent[0] == UnsetExtent;
  if (needField)
  {
    // The defaults come from the field itself (bounds, pixel spacing): bring it up to date now.
    if (vtkAlgorithmOutput* connection = this->GetInputConnection(0, 0))
    {
      connection->GetProducer()->UpdatePiece(0, 1, 0);
    }
    vtkPolyData* input = vtkPolyData::GetData(inputVector[0], 0);
    bigus::GaussianField field;
    bigus::FieldModel model;
    std::string error;
    if (!bigus::FieldFromPolyData(input, field, model, &error))
    {
      vtkErrorMacro(<< error);
      return 0;
    }
    const double step = model.PixelSpacing > 0 ? model.PixelSpacing : 0.5;
    for (int k = 0; k < 3; ++k)
    {
      spacing[k] = spacing[k] == Unset ? step : spacing[k];
    }
    // Field bounds padded by three times the largest scale, expressed in the reslice frame.
    double lo[3] = { VTK_DOUBLE_MAX, VTK_DOUBLE_MAX, VTK_DOUBLE_MAX }, hi[3] = { -VTK_DOUBLE_MAX, -VTK_DOUBLE_MAX,
      -VTK_DOUBLE_MAX };
    double largest = 0;
    for (float l : field.LogScales)
    {
      largest = std::max(largest, std::exp(double(l)));
    }
    double world[6];
    input->GetBounds(world);
    vtkNew<vtkMatrix4x4> inverse;
    if (this->ResliceAxes)
    {
      vtkMatrix4x4::Invert(this->ResliceAxes, inverse);
    }
    for (int c = 0; c < 8; ++c)
    {
      const double p[4] = { world[c & 1] + (c & 1 ? 3 : -3) * largest, world[2 + ((c >> 1) & 1)] + ((c >> 1) & 1 ? 3 : -3) * largest,
        world[4 + ((c >> 2) & 1)] + ((c >> 2) & 1 ? 3 : -3) * largest, 1 };
      double q[4];
      inverse->MultiplyPoint(p, q);
      for (int k = 0; k < 3; ++k)
      {
        lo[k] = std::min(lo[k], q[k]);
        hi[k] = std::max(hi[k], q[k]);
      }
    }
    for (int k = 0; k < 3; ++k)
    {
      if (origin[k] == Unset)
      {
        origin[k] = (planar && k == 2) ? 0.0 : lo[k];
      }
    }
    if (extent[0] == UnsetExtent)
    {
      for (int k = 0; k < 3; ++k)
      {
        extent[2 * k] = 0;
        extent[2 * k + 1] = static_cast<int>(std::ceil((hi[k] - origin[k]) / spacing[k]));
      }
    }
  }
  if (planar)
  {
    extent[5] = extent[4];
    spacing[2] = spacing[2] == Unset ? 1.0 : spacing[2];
  }
  if (extent[1] < extent[0] || extent[3] < extent[2] || extent[5] < extent[4])
  {
    vtkErrorMacro("empty output extent " << extent[0] << " " << extent[1] << " " << extent[2] << " " << extent[3] << " "
                                         << extent[4] << " " << extent[5]);
    return 0;
  }
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent, 6);
  outInfo->Set(vtkDataObject::SPACING(), spacing, 3);
  outInfo->Set(vtkDataObject::ORIGIN(), origin, 3);
  vtkDataObject::SetPointDataActiveScalarInfo(outInfo, this->OutputScalarType, 1);
  return 1;
}

int vtkGaussianFieldReslice::RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*)
{
  return 1; // the whole field is needed for any part of the output
}

int vtkGaussianFieldReslice::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  vtkPolyData* input = vtkPolyData::GetData(inputVector[0], 0);
  const std::string backend = this->Backend ? this->Backend : "cpu";
  if (backend != "cpu" && backend != "auto")
  {
    vtkErrorMacro("Backend '" << backend << "' is not one of: cpu, auto");
    return 0;
  }
  bigus::GaussianField field;
  bigus::FieldModel model;
  std::string error;
  if (!bigus::FieldFromPolyData(input, field, model, &error))
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  int extent[6];
  double spacing[3], origin[3];
  outInfo->Get(vtkStreamingDemandDrivenPipeline::UPDATE_EXTENT(), extent);
  outInfo->Get(vtkDataObject::SPACING(), spacing);
  outInfo->Get(vtkDataObject::ORIGIN(), origin);
  output->SetExtent(extent);
  output->SetSpacing(spacing);
  output->SetOrigin(origin);
  const int width = extent[1] - extent[0] + 1, height = extent[3] - extent[2] + 1, depth = extent[5] - extent[4] + 1;

  // Slice k: pixel (i, j) -> ResliceAxes * (origin + (extent[0] + i, extent[2] + j, extent[4] + k) * spacing).
  vtkNew<vtkMatrix4x4> axes;
  if (this->ResliceAxes)
  {
    axes->DeepCopy(this->ResliceAxes);
  }
  std::vector<bigus::SliceGeometry> slices(depth);
  for (int k = 0; k < depth; ++k)
  {
    vtkNew<vtkMatrix4x4> grid, pose;
    grid->SetElement(0, 0, spacing[0]);
    grid->SetElement(1, 1, spacing[1]);
    grid->SetElement(0, 3, origin[0] + extent[0] * spacing[0]);
    grid->SetElement(1, 3, origin[1] + extent[2] * spacing[1]);
    grid->SetElement(2, 3, origin[2] + (extent[4] + k) * spacing[2]);
    vtkMatrix4x4::Multiply4x4(axes, grid, pose);
    std::copy(pose->GetData(), pose->GetData() + 16, slices[k].ImageToReference);
    slices[k].Width = width;
    slices[k].Height = height;
  }
  const bigus::RenderOptions options = bigus::RenderOptionsFor(model, this->ElevationSigma, this->Cutoff);
  const std::size_t pixels = std::size_t(width) * height * depth;
  std::vector<float> S(pixels), I(pixels);
  auto renderer = bigus::CreateCpuRenderer();
  if (!renderer->Forward(field.View(), slices.data(), depth, options, S.data(), I.data(), nullptr, &error))
  {
    vtkErrorMacro("ResliceAxes: " << error);
    return 0;
  }
  output->GetPointData()->SetScalars(bigus::IntensityArray(I, this->OutputScalarType));
  if (this->OutputScatteringField)
  {
    vtkNew<vtkFloatArray> scattering;
    scattering->SetName("ScatteringField");
    scattering->SetNumberOfTuples(static_cast<vtkIdType>(pixels));
    std::copy(S.begin(), S.end(), scattering->GetPointer(0));
    output->GetPointData()->AddArray(scattering);
  }
  return 1;
}

void vtkGaussianFieldReslice::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "ResliceAxes: " << (this->ResliceAxes ? "set" : "(identity)") << "\n";
  if (this->ResliceAxes)
  {
    this->ResliceAxes->PrintSelf(os, indent.GetNextIndent());
  }
  auto vec = [&](const char* name, const double* v) {
    os << indent << name << ": ";
    if (v[0] == Unset)
    {
      os << "(default)\n";
    }
    else
    {
      os << v[0] << " " << v[1] << " " << v[2] << "\n";
    }
  };
  vec("OutputSpacing", this->OutputSpacing);
  vec("OutputOrigin", this->OutputOrigin);
  os << indent << "OutputExtent: ";
  if (this->OutputExtent[0] == UnsetExtent)
  {
    os << "(default)\n";
  }
  else
  {
    for (int k = 0; k < 6; ++k)
    {
      os << this->OutputExtent[k] << (k < 5 ? " " : "\n");
    }
  }
  os << indent << "OutputDimensionality: " << this->OutputDimensionality << "\n";
  os << indent << "InformationInput: " << (this->InformationInput ? "set" : "(none)") << "\n";
  os << indent << "ElevationSigma: " << this->ElevationSigma << (this->ElevationSigma < 0 ? " (the field's)" : "")
     << "\n";
  os << indent << "Cutoff: " << this->Cutoff << "\n";
  os << indent << "OutputScatteringField: " << this->OutputScatteringField << "\n";
  os << indent << "OutputScalarType: " << vtkImageScalarTypeNameMacro(this->OutputScalarType) << "\n";
  os << indent << "Backend: " << (this->Backend ? this->Backend : "(none)") << "\n";
}
