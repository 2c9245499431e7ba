#include "vtkPVUltrasoundFrameInterpolator.h"

#include "vtkIdList.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkStreamingDemandDrivenPipeline.h"

vtkStandardNewMacro(vtkPVUltrasoundFrameInterpolator);

namespace
{
bool SameIds(vtkIdList* a, vtkIdList* b)
{
  if (!a || a->GetNumberOfIds() != b->GetNumberOfIds())
  {
    return false;
  }
  for (vtkIdType i = 0; i < b->GetNumberOfIds(); ++i)
  {
    if (a->GetId(i) != b->GetId(i))
    {
      return false;
    }
  }
  return true;
}
}

int vtkPVUltrasoundFrameInterpolator::RequestInformation(
  vtkInformation* request, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkInformation* inInfo = inputVector[0]->GetInformationObject(0);
  int extent[6] = { 0, -1, 0, -1, 0, -1 };
  if (inInfo && inInfo->Has(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT()))
  {
    inInfo->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent);
  }
  vtkNew<vtkIdList> training, targets;
  for (int k = 0; k <= extent[5] - extent[4]; ++k)
  {
    const bool heldOut = this->HoldOutEvery > 1 && k % this->HoldOutEvery == this->HoldOutOffset;
    (heldOut ? targets : training)->InsertNextId(k);
  }
  // Set only what changed, so that a second update does not execute again.
  if (!SameIds(this->GetTrainingFrames(), training))
  {
    this->SetTrainingFrames(training);
  }
  if (!SameIds(this->GetTargetFrames(), targets))
  {
    this->SetTargetFrames(targets);
  }
  return this->Superclass::RequestInformation(request, inputVector, outputVector);
}

void vtkPVUltrasoundFrameInterpolator::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "HoldOutEvery: " << this->HoldOutEvery << "\n";
  os << indent << "HoldOutOffset: " << this->HoldOutOffset << "\n";
}
