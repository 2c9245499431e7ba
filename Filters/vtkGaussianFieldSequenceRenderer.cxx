#include "vtkGaussianFieldSequenceRenderer.h"

#include "bigusGaussianFieldData.h"
#include "bigusRenderer.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"

#include <chrono>
#include <cmath>
#include <vector>

vtkStandardNewMacro(vtkGaussianFieldSequenceRenderer);
vtkCxxSetObjectMacro(vtkGaussianFieldSequenceRenderer, FrameList, vtkIdList);

vtkGaussianFieldSequenceRenderer::vtkGaussianFieldSequenceRenderer()
{
  this->SetNumberOfInputPorts(2);
}

vtkGaussianFieldSequenceRenderer::~vtkGaussianFieldSequenceRenderer()
{
  this->SetFrameList(nullptr);
}

int vtkGaussianFieldSequenceRenderer::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  bigus::SetFrameSequenceInformation(inputVector[1]->GetInformationObject(0), this->FrameList, this->OutputScalarType,
    outputVector->GetInformationObject(0));
  return 1;
}

int vtkGaussianFieldSequenceRenderer::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkImageData* sequence = vtkImageData::GetData(inputVector[1], 0);
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  bigus::RenderSetup render;
  if (!this->BeginRender(inputVector, render))
  {
    return 0;
  }
  const bigus::TrainingCoverage* coverage = render.Coverage;
  std::string error;
  int dims[3];
  sequence->GetDimensions(dims);
  vtkDataArray* poses = sequence->GetFieldData()->GetArray("ImageToReference");
  if (!poses || poses->GetNumberOfComponents() != 16 || poses->GetNumberOfTuples() != dims[2])
  {
    vtkErrorMacro("input 1 must be a tracked frame sequence with ImageToReference (" << dims[2] << " x 16)");
    return 0;
  }
  std::vector<vtkIdType> frames;
  if (!bigus::ChosenFrames(this->FrameList, dims[2], frames, &error))
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  const int count = static_cast<int>(frames.size());
  std::vector<bigus::SliceGeometry> slices(count);
  for (int k = 0; k < count; ++k)
  {
    poses->GetTuple(frames[k], slices[k].ImageToReference);
    slices[k].Width = dims[0];
    slices[k].Height = dims[1];
  }
  const bigus::RenderOptions& options = render.Options;
  const bigus::FieldView view = render.Field->GetField().View();
  const std::size_t framePixels = std::size_t(dims[0]) * dims[1];
  std::vector<float> S(framePixels), I(framePixels * count), C(coverage ? framePixels * count : 0);
  double renderSeconds = 0;
  for (int k = 0; k < count; ++k)
  {
    if (this->GetAbortExecute())
    {
      // The output stays empty, so the pipeline does not take it for the requested frames.
      return 1;
    }
    const auto start = std::chrono::steady_clock::now();
    if (!render.Backend->Forward(view, &slices[k], 1, options, S.data(), I.data() + k * framePixels, nullptr, &error))
    {
      vtkErrorMacro("frame " << frames[k] << ": " << error);
      return 0;
    }
    renderSeconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (coverage)
    {
      coverage->Compute(slices[k], options.ElevationSigma, C.data() + k * framePixels);
    }
    this->UpdateProgress(double(k + 1) / count);
  }
  this->SecondsPerFrame = renderSeconds / std::max(1, count);

  output->SetExtent(0, dims[0] - 1, 0, dims[1] - 1, 0, count - 1);
  output->SetSpacing(1, 1, 1);
  output->SetOrigin(0, 0, 0);
  output->GetPointData()->SetScalars(bigus::IntensityArray(I, this->OutputScalarType));
  if (coverage)
  {
    output->GetPointData()->AddArray(bigus::CoverageArray(C));
  }
  bigus::CopyFrameFieldData(sequence->GetFieldData(), dims[2], frames, output->GetFieldData());
  return 1;
}

void vtkGaussianFieldSequenceRenderer::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "FrameList: " << (this->FrameList ? this->FrameList->GetNumberOfIds() : 0) << " frames\n";
  os << indent << "SecondsPerFrame: " << this->SecondsPerFrame << "\n";
}
