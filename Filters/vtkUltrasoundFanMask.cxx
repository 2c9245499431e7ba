#include "vtkUltrasoundFanMask.h"

#include "bigusPipeline.h"
#include "vtkUltrasoundCalibration.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkUnsignedCharArray.h"

#include <opencv2/imgproc.hpp>

#include <cmath>

vtkStandardNewMacro(vtkUltrasoundFanMask);

vtkUltrasoundFanMask::vtkUltrasoundFanMask() = default;

vtkUltrasoundFanMask::~vtkUltrasoundFanMask()
{
  this->SetCalibrationFileName(nullptr);
}

int vtkUltrasoundFanMask::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkInformation* inInfo = inputVector[0]->GetInformationObject(0);
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  int extent[6];
  inInfo->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent);
  extent[4] = extent[5] = 0;
  outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent, 6);
  const double spacing[3] = { 1, 1, 1 };
  const double origin[3] = { 0, 0, 0 };
  outInfo->Set(vtkDataObject::SPACING(), spacing, 3);
  outInfo->Set(vtkDataObject::ORIGIN(), origin, 3);
  vtkDataObject::SetPointDataActiveScalarInfo(outInfo, VTK_UNSIGNED_CHAR, 1);
  return 1;
}

int vtkUltrasoundFanMask::RequestUpdateExtent(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector*)
{
  // Every frame contributes to the estimate, whatever part of the mask is asked for.
  bigus::RequestWholeExtent(inputVector[0]);
  return 1;
}

int vtkUltrasoundFanMask::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkImageData* input = vtkImageData::GetData(inputVector[0], 0);
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  vtkDataArray* scalars = input ? input->GetPointData()->GetScalars() : nullptr;
  if (!scalars || scalars->GetNumberOfTuples() == 0 || scalars->GetNumberOfComponents() != 1)
  {
    vtkErrorMacro("input must be a tracked frame sequence with one-component scalars");
    return 0;
  }
  int dims[3];
  input->GetDimensions(dims);
  const int width = dims[0];
  const int height = dims[1];
  cv::Mat mask(height, width, CV_8U, cv::Scalar(0));

  if (this->Mode == ESTIMATE)
  {
    vtkDataArray* valid = input->GetFieldData() ? input->GetFieldData()->GetArray("FrameValid") : nullptr;
    for (int k = 0; k < dims[2]; ++k)
    {
      if (valid && valid->GetNumberOfTuples() == dims[2] && valid->GetTuple1(k) == 0)
      {
        continue;
      }
      const vtkIdType base = vtkIdType(k) * width * height;
      for (int j = 0; j < height; ++j)
      {
        unsigned char* row = mask.ptr<unsigned char>(j);
        for (int i = 0; i < width; ++i)
        {
          if (scalars->GetComponent(base + vtkIdType(j) * width + i, 0) > this->BackgroundThreshold)
          {
            row[i] = 1;
          }
        }
      }
      this->UpdateProgress(0.8 * (k + 1) / dims[2]);
      if (this->AbortExecute)
      {
        return 0;
      }
    }
    auto disk = [](int r) { return cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1)); };
    if (this->OpeningRadius > 0)
    {
      cv::morphologyEx(mask, mask, cv::MORPH_OPEN, disk(this->OpeningRadius));
    }
    cv::Mat labels, stats, centroids;
    const int count = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
    int largest = 0;
    for (int c = 1; c < count; ++c)
    {
      if (largest == 0 || stats.at<int>(c, cv::CC_STAT_AREA) > stats.at<int>(largest, cv::CC_STAT_AREA))
      {
        largest = c;
      }
    }
    mask = largest > 0 ? (labels == largest) / 255 : cv::Mat(height, width, CV_8U, cv::Scalar(0));
    if (this->ClosingRadius > 0 && largest > 0)
    {
      // Pad so that the closing does not erode the fan where it touches the image border.
      const int r = this->ClosingRadius;
      cv::Mat padded;
      cv::copyMakeBorder(mask, padded, r, r, r, r, cv::BORDER_REPLICATE);
      cv::morphologyEx(padded, padded, cv::MORPH_CLOSE, disk(r));
      mask = padded(cv::Rect(r, r, width, height)).clone();
    }
    if (largest > 0)
    {
      // Fill holes: background not connected to the image border is inside the fan.
      cv::Mat outside;
      cv::copyMakeBorder(mask, outside, 1, 1, 1, 1, cv::BORDER_CONSTANT, cv::Scalar(0));
      cv::floodFill(outside, cv::Point(0, 0), cv::Scalar(2));
      mask = (outside(cv::Rect(1, 1, width, height)) != 2) / 255;
    }
  }
  else
  {
    vtkNew<vtkUltrasoundCalibration> calibration;
    calibration->SetFileName(this->CalibrationFileName);
    if (!calibration->Parse())
    {
      vtkErrorMacro(<< calibration->GetErrorText());
      return 0;
    }
    if (!calibration->GetHasClipRectangle() && !calibration->GetHasFan())
    {
      vtkErrorMacro(<< this->CalibrationFileName
                    << ": <VolumeReconstruction> gives neither a clip rectangle nor a fan");
      return 0;
    }
    int x0 = 0, y0 = 0, x1 = width, y1 = height;
    if (calibration->GetHasClipRectangle())
    {
      const int* o = calibration->GetClipRectangleOrigin();
      const int* s = calibration->GetClipRectangleSize();
      if (o[0] + s[0] > width || o[1] + s[1] > height)
      {
        vtkErrorMacro(<< this->CalibrationFileName << ": clip rectangle " << o[0] << " " << o[1] << " + " << s[0]
                      << " x " << s[1] << " lies outside the " << width << " x " << height << " frames");
        return 0;
      }
      x0 = o[0];
      y0 = o[1];
      x1 = o[0] + s[0];
      y1 = o[1] + s[1];
    }
    const bool fan = calibration->GetHasFan();
    const double* angles = calibration->GetFanAngles();
    const double* apex = calibration->GetFanOrigin();
    const double* radius = calibration->GetFanRadius();
    for (int j = y0; j < y1; ++j)
    {
      for (int i = x0; i < x1; ++i)
      {
        bool inside = true;
        if (fan)
        {
          const double dx = i - apex[0];
          const double dy = j - apex[1];
          const double r = std::sqrt(dx * dx + dy * dy);
          const double angle = std::atan2(dx, dy) * 180.0 / M_PI;
          inside = angle >= angles[0] && angle <= angles[1] && r >= radius[0] && (radius[1] <= 0 || r <= radius[1]);
        }
        mask.at<unsigned char>(j, i) = inside ? 1 : 0;
      }
    }
  }

  output->SetExtent(0, width - 1, 0, height - 1, 0, 0);
  output->SetSpacing(1, 1, 1);
  output->SetOrigin(0, 0, 0);
  vtkNew<vtkUnsignedCharArray> out;
  out->SetName("FanMask");
  out->SetNumberOfTuples(vtkIdType(width) * height);
  for (int j = 0; j < height; ++j)
  {
    std::copy(mask.ptr<unsigned char>(j), mask.ptr<unsigned char>(j) + width, out->GetPointer(vtkIdType(j) * width));
  }
  output->GetPointData()->SetScalars(out);
  this->UpdateProgress(1.0);
  return 1;
}

void vtkUltrasoundFanMask::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "Mode: " << (this->Mode == ESTIMATE ? "Estimate" : "Calibration") << "\n";
  os << indent << "BackgroundThreshold: " << this->BackgroundThreshold << "\n";
  os << indent << "OpeningRadius: " << this->OpeningRadius << "\n";
  os << indent << "ClosingRadius: " << this->ClosingRadius << "\n";
  os << indent << "CalibrationFileName: " << (this->CalibrationFileName ? this->CalibrationFileName : "(none)") << "\n";
}
