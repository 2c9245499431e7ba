#include "vtkGaussianFieldMerge.h"

#include "bigusGaussianFieldData.h"
#include "bigusGaussianMerging.h"

#include "vtkFieldData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPolyData.h"
#include "vtkStringArray.h"

#include <string>

vtkStandardNewMacro(vtkGaussianFieldMerge);

vtkGaussianFieldMerge::vtkGaussianFieldMerge()
{
  const bigus::GaussianMergeSettings defaults;
  this->Neighbours = defaults.Neighbours;
  this->MaximumPasses = defaults.MaximumPasses;
}

int vtkGaussianFieldMerge::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkPolyData* input = vtkPolyData::GetData(inputVector[0], 0);
  vtkPolyData* output = vtkPolyData::GetData(outputVector, 0);
  this->MergedPairs = 0;
  bigus::GaussianField field;
  bigus::FieldModel model;
  std::string error;
  if (!bigus::FieldFromPolyData(input, field, model, &error))
  {
    vtkErrorMacro("The input is not a Gaussian field: " << error);
    return 0;
  }
  bigus::GaussianMergeSettings settings;
  settings.Tolerance = this->Tolerance;
  settings.Neighbours = this->Neighbours;
  settings.MaximumPasses = this->MaximumPasses;
  const bigus::GaussianMergeReport report = bigus::MergeGaussians(field, settings);
  this->MergedPairs = static_cast<vtkIdType>(report.Merged);
  bigus::FieldToPolyData(field, model, output);
  output->GetFieldData()->PassData(input->GetFieldData());
  vtkNew<vtkStringArray> note;
  note->SetName("GaussianMerge");
  note->InsertNextValue(bigus::DescribeGaussianMerge(report, settings));
  output->GetFieldData()->AddArray(note);
  return 1;
}

void vtkGaussianFieldMerge::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "Tolerance: " << this->Tolerance << "\n";
  os << indent << "Neighbours: " << this->Neighbours << "\n";
  os << indent << "MaximumPasses: " << this->MaximumPasses << "\n";
  os << indent << "MergedPairs: " << this->MergedPairs << "\n";
}
