#include "vtkUltrasoundImageMetrics.h"

#include "bigusImageMetrics.h"
#include "bigusPipeline.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkIntArray.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkTable.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkUltrasoundImageMetrics);

namespace
{
constexpr double NaN = std::numeric_limits<double>::quiet_NaN();

std::string SizeText(const int dims[3])
{
  std::ostringstream text;
  text << dims[0] << " x " << dims[1] << " x " << dims[2];
  return text.str();
}

/// Frame @p k of one-component unsigned char, float or double scalars as [H, W] floats in [0, 1].
void ReadFrame(vtkDataArray* scalars, int k, std::size_t pixels, std::vector<float>& frame)
{
  frame.resize(pixels);
  const std::size_t offset = std::size_t(k) * pixels;
  switch (scalars->GetDataType())
  {
    case VTK_UNSIGNED_CHAR:
    {
      const auto* p = static_cast<const unsigned char*>(scalars->GetVoidPointer(0)) + offset;
      for (std::size_t i = 0; i < pixels; ++i)
      {
        frame[i] = p[i] / 255.0f;
      }
      break;
    }
    case VTK_FLOAT:
    {
      const auto* p = static_cast<const float*>(scalars->GetVoidPointer(0)) + offset;
      std::copy(p, p + pixels, frame.begin());
      break;
    }
    case VTK_DOUBLE:
    {
      const auto* p = static_cast<const double*>(scalars->GetVoidPointer(0)) + offset;
      for (std::size_t i = 0; i < pixels; ++i)
      {
        frame[i] = static_cast<float>(p[i]);
      }
      break;
    }
  }
}

/// The per-frame array @p name of the field data, when it has one value per frame.
vtkDataArray* FrameArray(vtkImageData* image, const char* name, int frames)
{
  vtkFieldData* fields = image->GetFieldData();
  vtkDataArray* array = fields ? fields->GetArray(name) : nullptr;
  return array && array->GetNumberOfTuples() == frames && array->GetNumberOfComponents() == 1 ? array : nullptr;
}

/// Mean of the values of @p column that are not NaN; NaN when there is none.
double MeanOfDefined(vtkDoubleArray* column)
{
  double sum = 0;
  int count = 0;
  for (vtkIdType r = 0; r < column->GetNumberOfTuples(); ++r)
  {
    const double v = column->GetValue(r);
    if (!std::isnan(v))
    {
      sum += v;
      ++count;
    }
  }
  return count > 0 ? sum / count : NaN;
}
}

vtkUltrasoundImageMetrics::vtkUltrasoundImageMetrics()
{
  this->SetNumberOfInputPorts(3);
  this->ResetMeans();
}

vtkUltrasoundImageMetrics::~vtkUltrasoundImageMetrics() = default;

void vtkUltrasoundImageMetrics::ResetMeans()
{
  this->MeanPSNR = this->MeanSSIM = this->MeanNCC = this->MeanSpeckle = NaN;
}

int vtkUltrasoundImageMetrics::FillInputPortInformation(int port, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkImageData");
  if (port == 2)
  {
    info->Set(vtkAlgorithm::INPUT_IS_OPTIONAL(), 1);
  }
  return 1;
}

int vtkUltrasoundImageMetrics::RequestUpdateExtent(
  vtkInformation* request, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  if (!this->Superclass::RequestUpdateExtent(request, inputVector, outputVector))
  {
    return 0;
  }
  // Every frame and the whole mask are compared, whatever part of the table is asked for.
  bigus::RequestWholeExtent(inputVector, this->GetNumberOfInputPorts());
  return 1;
}

int vtkUltrasoundImageMetrics::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkTable* output = vtkTable::GetData(outputVector, 0);
  output->Initialize();
  this->ResetMeans();

  vtkImageData* rendered = vtkImageData::GetData(inputVector[0], 0);
  vtkImageData* truth = vtkImageData::GetData(inputVector[1], 0);
  vtkImageData* maskImage = vtkImageData::GetData(inputVector[2], 0);
  if (!rendered || !truth)
  {
    vtkErrorMacro("rendered frames (port 0) and ground-truth frames (port 1) are both required");
    return 0;
  }
  int dims[3], truthDims[3];
  rendered->GetDimensions(dims);
  truth->GetDimensions(truthDims);
  if (dims[0] != truthDims[0] || dims[1] != truthDims[1] || dims[2] != truthDims[2])
  {
    vtkErrorMacro("rendered frames are " << SizeText(dims) << " but the ground-truth frames are " << SizeText(truthDims)
                                         << " (W x H x frames)");
    return 0;
  }
  vtkDataArray* scalars = rendered->GetPointData()->GetScalars();
  vtkDataArray* truthScalars = truth->GetPointData()->GetScalars();
  for (vtkDataArray* array : { scalars, truthScalars })
  {
    if (!array || array->GetNumberOfComponents() != 1)
    {
      vtkErrorMacro("rendered and ground-truth frames need one-component scalars; the "
        << (array == scalars ? "rendered" : "ground-truth") << " frames have "
        << (array ? array->GetNumberOfComponents() : 0));
      return 0;
    }
    const int type = array->GetDataType();
    if (type != VTK_UNSIGNED_CHAR && type != VTK_FLOAT && type != VTK_DOUBLE)
    {
      vtkErrorMacro("frame scalars must be unsigned char, float or double, not " << array->GetDataTypeAsString());
      return 0;
    }
  }
  const int width = dims[0], height = dims[1], frames = dims[2];
  const std::size_t pixels = std::size_t(width) * height;
  if (std::size_t(scalars->GetNumberOfTuples()) != pixels * frames ||
    std::size_t(truthScalars->GetNumberOfTuples()) != pixels * frames)
  {
    vtkErrorMacro("frame scalars hold " << scalars->GetNumberOfTuples() << " (rendered) and "
                                        << truthScalars->GetNumberOfTuples() << " (ground truth) values, "
                                        << SizeText(dims) << " expected");
    return 0;
  }

  // The mask: one W x H image for every frame, or one per frame (W x H x frames).
  std::vector<unsigned char> mask;
  std::size_t maskStride = 0; // 0: shared, pixels: per frame
  if (maskImage)
  {
    int maskDims[3];
    maskImage->GetDimensions(maskDims);
    vtkDataArray* maskScalars = maskImage->GetPointData()->GetScalars();
    if (maskDims[0] != width || maskDims[1] != height || (maskDims[2] != 1 && maskDims[2] != frames))
    {
      vtkErrorMacro("the mask is " << SizeText(maskDims) << " but the frames are " << SizeText(dims)
                                   << "; the mask must be " << width << " x " << height << " x 1 or " << width << " x "
                                   << height << " x " << frames);
      return 0;
    }
    if (!maskScalars || maskScalars->GetNumberOfComponents() != 1)
    {
      vtkErrorMacro("the mask needs one-component scalars");
      return 0;
    }
    maskStride = maskDims[2] == 1 ? 0 : pixels;
    mask.resize(pixels * maskDims[2]);
    bool any = false;
    for (std::size_t p = 0; p < mask.size(); ++p)
    {
      mask[p] = maskScalars->GetComponent(vtkIdType(p), 0) != 0;
      any = any || mask[p];
    }
    if (!any)
    {
      vtkErrorMacro("the mask has no imaged (non-zero) pixel");
      return 0;
    }
  }

  vtkDataArray* valid = this->FrameValidOnly ? FrameArray(truth, "FrameValid", frames) : nullptr;
  vtkDataArray* index = FrameArray(truth, "FrameIndex", frames);
  vtkNew<vtkIntArray> frameColumn;
  frameColumn->SetName("Frame");
  vtkNew<vtkDoubleArray> psnr, ssim, ncc, speckle;
  psnr->SetName("PSNR");
  ssim->SetName("SSIM");
  ncc->SetName("NCC");
  speckle->SetName("Speckle");
  std::vector<float> a, b;
  for (int k = 0; k < frames; ++k)
  {
    if (valid && valid->GetTuple1(k) == 0)
    {
      continue;
    }
    const unsigned char* frameMask = mask.empty() ? nullptr : mask.data() + maskStride * k;
    if (frameMask && std::none_of(frameMask, frameMask + pixels, [](unsigned char m) { return m != 0; }))
    {
      continue; // this frame's own mask is empty: nothing of it can be compared
    }
    ReadFrame(scalars, k, pixels, a);
    ReadFrame(truthScalars, k, pixels, b);
    const bigus::ImageMetrics m = bigus::CompareImages(a.data(), b.data(), frameMask, width, height);
    frameColumn->InsertNextValue(index ? static_cast<int>(index->GetTuple1(k)) : k);
    psnr->InsertNextValue(m.PSNR);
    ssim->InsertNextValue(m.SSIM);
    ncc->InsertNextValue(m.NCC);
    speckle->InsertNextValue(m.Patches > 0 ? m.Speckle : NaN);
    this->UpdateProgress(double(k + 1) / frames);
    if (this->AbortExecute)
    {
      return 0;
    }
  }
  if (frameColumn->GetNumberOfTuples() == 0)
  {
    vtkWarningMacro("every one of the " << frames << " frames has FrameValid 0: nothing was compared");
  }

  this->MeanPSNR = MeanOfDefined(psnr);
  this->MeanSSIM = MeanOfDefined(ssim);
  this->MeanNCC = MeanOfDefined(ncc);
  this->MeanSpeckle = MeanOfDefined(speckle);
  frameColumn->InsertNextValue(-1);
  psnr->InsertNextValue(this->MeanPSNR);
  ssim->InsertNextValue(this->MeanSSIM);
  ncc->InsertNextValue(this->MeanNCC);
  speckle->InsertNextValue(this->MeanSpeckle);
  output->AddColumn(frameColumn);
  output->AddColumn(psnr);
  output->AddColumn(ssim);
  output->AddColumn(ncc);
  output->AddColumn(speckle);
  return 1;
}

void vtkUltrasoundImageMetrics::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "FrameValidOnly: " << (this->FrameValidOnly ? "On" : "Off") << "\n";
  os << indent << "MeanPSNR: " << this->MeanPSNR << "\n";
  os << indent << "MeanSSIM: " << this->MeanSSIM << "\n";
  os << indent << "MeanNCC: " << this->MeanNCC << "\n";
  os << indent << "MeanSpeckle: " << this->MeanSpeckle << "\n";
}
