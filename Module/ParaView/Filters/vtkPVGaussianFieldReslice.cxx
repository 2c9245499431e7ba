#include "vtkPVGaussianFieldReslice.h"

#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkMath.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkStreamingDemandDrivenPipeline.h"

#include <algorithm>
#include <cmath>
#include <sstream>

vtkStandardNewMacro(vtkPVGaussianFieldReslice);

vtkPVGaussianFieldReslice::vtkPVGaussianFieldReslice()
{
  // One port each in ParaView: the slice of a field (the stencil input and output are for VTK pipelines).
  this->SetNumberOfInputPorts(1);
  this->SetNumberOfOutputPorts(1);
  this->UpdateAxesAndGrid();
}

namespace
{
/// Copies (x, y, z) into @p member; false when it held them already.
template <typename T>
bool Assign(T (&member)[3], T x, T y, T z)
{
  const T value[3] = { x, y, z };
  if (std::equal(value, value + 3, member))
  {
    return false;
  }
  std::copy(value, value + 3, member);
  return true;
}
}

void vtkPVGaussianFieldReslice::SetSliceOrigin(double x, double y, double z)
{
  if (Assign(this->SliceOrigin, x, y, z))
  {
    this->UpdateAxesAndGrid();
    this->Modified();
  }
}

void vtkPVGaussianFieldReslice::SetSliceNormal(double x, double y, double z)
{
  if (Assign(this->SliceNormal, x, y, z))
  {
    this->UpdateAxesAndGrid();
    this->Modified();
  }
}

void vtkPVGaussianFieldReslice::SetSliceSpacing(double x, double y, double z)
{
  if (Assign(this->SliceSpacing, x, y, z))
  {
    this->UpdateAxesAndGrid();
    this->Modified();
  }
}

void vtkPVGaussianFieldReslice::SetSliceDimensions(int x, int y, int z)
{
  if (Assign(this->SliceDimensions, x, y, z))
  {
    this->UpdateAxesAndGrid();
    this->Modified();
  }
}

void vtkPVGaussianFieldReslice::UpdateAxesAndGrid()
{
  this->PlaneError.clear();
  double n[3] = { this->SliceNormal[0], this->SliceNormal[1], this->SliceNormal[2] };
  const double length = vtkMath::Norm(n);
  std::ostringstream error;
  if (!std::isfinite(length) || length < 1e-12)
  {
    error << "SliceNormal (" << n[0] << ", " << n[1] << ", " << n[2]
          << ") is not a plane normal: it must be finite and non-zero";
  }
  else if (!std::isfinite(this->SliceOrigin[0]) || !std::isfinite(this->SliceOrigin[1]) ||
    !std::isfinite(this->SliceOrigin[2]))
  {
    error << "SliceOrigin (" << this->SliceOrigin[0] << ", " << this->SliceOrigin[1] << ", " << this->SliceOrigin[2]
          << ") is not finite";
  }
  this->PlaneError = error.str();
  if (!this->PlaneError.empty())
  {
    return;
  }
  vtkMath::MultiplyScalar(n, 1.0 / length);

  // x axis: the world axis least aligned with n, projected onto the plane.
  int least = 0;
  for (int k = 1; k < 3; ++k)
  {
    if (std::abs(n[k]) < std::abs(n[least]))
    {
      least = k;
    }
  }
  double x[3] = { 0, 0, 0 };
  x[least] = 1;
  const double along = vtkMath::Dot(x, n);
  for (int k = 0; k < 3; ++k)
  {
    x[k] -= along * n[k];
  }
  vtkMath::Normalize(x);
  double y[3];
  vtkMath::Cross(n, x, y);

  vtkNew<vtkMatrix4x4> axes;
  for (int r = 0; r < 3; ++r)
  {
    axes->SetElement(r, 0, x[r]);
    axes->SetElement(r, 1, y[r]);
    axes->SetElement(r, 2, n[r]);
    axes->SetElement(r, 3, this->SliceOrigin[r]);
  }
  this->SetResliceAxes(axes);

  // The grid: centred on the origin when every needed spacing and size is given, else the default.
  const int used = this->GetOutputDimensionality() == 3 ? 3 : 2;
  bool explicitGrid = true;
  for (int k = 0; k < used; ++k)
  {
    explicitGrid = explicitGrid && this->SliceSpacing[k] > 0 && this->SliceDimensions[k] > 0;
  }
  if (explicitGrid)
  {
    double spacing[3] = { 1, 1, 1 }, origin[3] = { 0, 0, 0 };
    int extent[6] = { 0, 0, 0, 0, 0, 0 };
    for (int k = 0; k < used; ++k)
    {
      spacing[k] = this->SliceSpacing[k];
      origin[k] = -0.5 * (this->SliceDimensions[k] - 1) * spacing[k];
      extent[2 * k + 1] = this->SliceDimensions[k] - 1;
    }
    this->SetOutputSpacing(spacing);
    this->SetOutputOrigin(origin);
    this->SetOutputExtent(extent);
  }
  else
  {
    this->SetOutputOriginToDefault();
    this->SetOutputExtentToDefault();
    this->SetOutputSpacingComponents(this->SliceSpacing); // 0: the field's default on that axis
  }
}

void vtkPVGaussianFieldReslice::SetOutputDimensionality(int dimensionality)
{
  const int before = this->GetOutputDimensionality();
  this->Superclass::SetOutputDimensionality(dimensionality);
  if (this->GetOutputDimensionality() != before)
  {
    this->UpdateAxesAndGrid();
  }
}

bool vtkPVGaussianFieldReslice::CheckPlane()
{
  if (!this->PlaneError.empty())
  {
    vtkErrorMacro(<< this->PlaneError);
    return false;
  }
  return true;
}

int vtkPVGaussianFieldReslice::RequestInformation(
  vtkInformation* request, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  if (!this->CheckPlane())
  {
    // An empty extent, not one the executive copied from upstream, so that nothing stale is requested.
    const int empty[6] = { 0, -1, 0, -1, 0, -1 };
    outputVector->GetInformationObject(0)->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), empty, 6);
    return 0;
  }
  if (!this->Superclass::RequestInformation(request, inputVector, outputVector))
  {
    return 0;
  }
  outputVector->GetInformationObject(0)->Get(vtkDataObject::ORIGIN(), this->FrameOrigin);
  this->PlaceInWorld(outputVector->GetInformationObject(0), nullptr);
  return 1;
}

void vtkPVGaussianFieldReslice::PlaceInWorld(vtkInformation* outInfo, vtkImageData* output)
{
  // Voxel (0, 0, 0) sits at ResliceAxes * (origin, 1); the axes' columns are the direction matrix.
  vtkMatrix4x4* axes = this->GetResliceAxes();
  double origin[4] = { 0, 0, 0, 1 };
  if (output)
  {
    output->GetOrigin(origin);
  }
  else
  {
    outInfo->Get(vtkDataObject::ORIGIN(), origin);
  }
  double world[4];
  axes->MultiplyPoint(origin, world);
  double direction[9];
  for (int r = 0; r < 3; ++r)
  {
    for (int c = 0; c < 3; ++c)
    {
      direction[3 * r + c] = axes->GetElement(r, c);
    }
  }
  outInfo->Set(vtkDataObject::ORIGIN(), world, 3);
  outInfo->Set(vtkDataObject::DIRECTION(), direction, 9);
  if (output)
  {
    output->SetOrigin(world);
    output->SetDirectionMatrix(direction);
  }
}

int vtkPVGaussianFieldReslice::RequestData(
  vtkInformation* request, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  if (!this->CheckPlane())
  {
    vtkImageData::GetData(outputVector)->Initialize();
    return 0;
  }
  // The superclass compares the announced grid with its own, in the reslice frame.
  outputVector->GetInformationObject(0)->Set(vtkDataObject::ORIGIN(), this->FrameOrigin, 3);
  if (!this->Superclass::RequestData(request, inputVector, outputVector))
  {
    return 0;
  }
  this->PlaceInWorld(outputVector->GetInformationObject(0), vtkImageData::GetData(outputVector));
  return 1;
}

void vtkPVGaussianFieldReslice::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "SliceOrigin: " << this->SliceOrigin[0] << " " << this->SliceOrigin[1] << " " << this->SliceOrigin[2]
     << "\n";
  os << indent << "SliceNormal: " << this->SliceNormal[0] << " " << this->SliceNormal[1] << " " << this->SliceNormal[2]
     << "\n";
  os << indent << "SliceSpacing: " << this->SliceSpacing[0] << " " << this->SliceSpacing[1] << " "
     << this->SliceSpacing[2] << "\n";
  os << indent << "SliceDimensions: " << this->SliceDimensions[0] << " " << this->SliceDimensions[1] << " "
     << this->SliceDimensions[2] << "\n";
}
