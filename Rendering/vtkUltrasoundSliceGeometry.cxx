#include "vtkUltrasoundSliceGeometry.h"

#include "bigusRenderer.h"
#include "bigusSliceFrame.h"

#include "vtkMatrix4x4.h"
#include "vtkObjectFactory.h"

#include <algorithm>

vtkStandardNewMacro(vtkUltrasoundSliceGeometry);

vtkUltrasoundSliceGeometry::vtkUltrasoundSliceGeometry()
  : MaximumShearAngle(bigus::DefaultMaximumShearAngle)
{}

void vtkUltrasoundSliceGeometry::SetImageToReference(vtkMatrix4x4* imageToReference)
{
  if (!imageToReference)
  {
    vtkErrorMacro("SetImageToReference: null matrix");
    return;
  }
  bigus::SliceFrame frame{};
  const bigus::PoseStatus status =
    bigus::ComputeSliceFrame(imageToReference->GetData(), this->MaximumShearAngle, frame);
  this->Status = static_cast<int>(status);
  std::copy(frame.u, frame.u + 3, this->AxisU);
  std::copy(frame.v, frame.v + 3, this->AxisV);
  std::copy(frame.n, frame.n + 3, this->Normal);
  std::copy(frame.origin, frame.origin + 3, this->Origin);
  std::copy(frame.spacing, frame.spacing + 2, this->PixelSpacing);
  this->ShearAngle = frame.shearDegrees;
  this->Modified();
}

const char* vtkUltrasoundSliceGeometry::GetStatusText() const
{
  return bigus::PoseStatusText(static_cast<bigus::PoseStatus>(this->Status));
}

void vtkUltrasoundSliceGeometry::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "MaximumShearAngle: " << this->MaximumShearAngle << "\n";
  os << indent << "Status: " << this->Status << " (" << this->GetStatusText() << ")\n";
  os << indent << "AxisU: " << this->AxisU[0] << " " << this->AxisU[1] << " " << this->AxisU[2] << "\n";
  os << indent << "AxisV: " << this->AxisV[0] << " " << this->AxisV[1] << " " << this->AxisV[2] << "\n";
  os << indent << "Normal: " << this->Normal[0] << " " << this->Normal[1] << " " << this->Normal[2] << "\n";
  os << indent << "Origin: " << this->Origin[0] << " " << this->Origin[1] << " " << this->Origin[2] << "\n";
  os << indent << "PixelSpacing: " << this->PixelSpacing[0] << " " << this->PixelSpacing[1] << "\n";
  os << indent << "ShearAngle: " << this->ShearAngle << "\n";
}
