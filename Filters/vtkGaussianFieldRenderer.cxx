#include "vtkGaussianFieldRenderer.h"

#include "bigusGaussianFieldData.h"
#include "bigusPipeline.h"

#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkPolyData.h"

#include <string>

/// What the filter keeps between executes (see the class description).
class vtkGaussianFieldRenderer::vtkInternals
{
public:
  bigus::FieldCache Field;
  bigus::RendererCache Renderer;
};

vtkGaussianFieldRenderer::vtkGaussianFieldRenderer()
  : Internals(new vtkInternals)
{
  this->SetBackend("auto");
}

vtkGaussianFieldRenderer::~vtkGaussianFieldRenderer()
{
  this->SetBackend(nullptr);
  delete this->Internals;
}

void vtkGaussianFieldRenderer::SetOutputScalarType(int type)
{
  std::string error;
  if (!bigus::IsIntensityScalarType(type, &error))
  {
    vtkErrorMacro("OutputScalarType: " << error << "; keeping " << vtkImageScalarTypeNameMacro(this->OutputScalarType));
    return;
  }
  if (type != this->OutputScalarType)
  {
    this->OutputScalarType = type;
    this->Modified();
  }
}

int vtkGaussianFieldRenderer::FillInputPortInformation(int port, vtkInformation* info)
{
  if (port == 0)
  {
    info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkPolyData");
    return 1;
  }
  return this->Superclass::FillInputPortInformation(port, info);
}

int vtkGaussianFieldRenderer::RequestUpdateExtent(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector*)
{
  for (int port = 1; port < this->GetNumberOfInputPorts(); ++port)
  {
    bigus::RequestWholeExtent(inputVector[port]);
  }
  return 1;
}

bigus::FieldCache& vtkGaussianFieldRenderer::GetFieldCache()
{
  return this->Internals->Field;
}

bool vtkGaussianFieldRenderer::BeginRender(vtkInformationVector** inputVector, bigus::RenderSetup& setup)
{
  bigus::FieldCache& field = this->Internals->Field;
  std::string error, notice;
  if (!field.Update(vtkPolyData::GetData(inputVector[0], 0), &error))
  {
    vtkErrorMacro(<< error);
    return false;
  }
  setup.Field = &field;
  setup.Backend = this->Internals->Renderer.Get(this->Backend ? this->Backend : "auto", &error, &notice);
  if (!setup.Backend)
  {
    vtkErrorMacro("Backend: " << error);
    return false;
  }
  if (!notice.empty())
  {
    vtkWarningMacro("Backend: " << notice);
  }
  if (!field.GetOutputCoverage(this->OutputCoverage, setup.Coverage, &error))
  {
    vtkErrorMacro(<< error << " (OutputCoverage off renders without the coverage image)");
    return false;
  }
  setup.Options = bigus::RenderOptionsFor(field.GetModel(), this->ElevationSigma, this->Cutoff);
  return true;
}

void vtkGaussianFieldRenderer::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "ElevationSigma: " << this->ElevationSigma << (this->ElevationSigma < 0 ? " (the field's)" : "")
     << "\n";
  os << indent << "Cutoff: " << this->Cutoff << "\n";
  os << indent << "OutputCoverage: " << this->OutputCoverage << "\n";
  os << indent << "OutputScalarType: " << vtkImageScalarTypeNameMacro(this->OutputScalarType) << "\n";
  os << indent << "Backend: " << (this->Backend ? this->Backend : "auto") << "\n";
}
