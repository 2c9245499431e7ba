#include "vtkUltrasoundVolumeCompounder.h"

#include "bigusGaussianFieldData.h"
#include "bigusPipeline.h"
#include "bigusVolumeCompounding.h"

#include "vtkAlgorithmOutput.h"
#include "vtkDataArray.h"
#include "vtkFloatArray.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkSMPTools.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkUnsignedIntArray.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkUltrasoundVolumeCompounder);
vtkCxxSetObjectMacro(vtkUltrasoundVolumeCompounder, FrameList, vtkIdList);

namespace
{
using bigus::compounding::ComputeGrid;
using bigus::compounding::FramePlan;
using bigus::compounding::HoleFiller;
using bigus::compounding::MakePlans;
using bigus::compounding::Unset;
using bigus::compounding::UnsetExtent;

/// Running state of one voxel grid while frames are inserted.
struct Accumulator
{
  int Dims[3];
  int Start[3]; // extent lower bounds
  double Origin[3];
  double Spacing[3];
  int Mode;
  float* Value;        // [voxels] sum (MEAN), maximum or latest value
  unsigned int* Count; // [voxels] pixels inserted
  vtkIdType Inserted = 0;

  /// Voxel index (or -1) of every pixel of the clip rectangle of one frame, row-major; masked-out
  /// pixels get -1 too.
  void Locate(const std::array<double, 12>& m, const int clip[4], const unsigned char* mask, int width,
    std::vector<vtkIdType>& target) const
  {
    const int columns = clip[1] - clip[0] + 1;
    const int rows = clip[3] - clip[2] + 1;
    target.resize(std::size_t(columns) * rows);
    vtkSMPTools::For(0, rows, 16, [&](vtkIdType rowBegin, vtkIdType rowEnd) {
      for (vtkIdType r = rowBegin; r < rowEnd; ++r)
      {
        const int y = clip[2] + static_cast<int>(r);
        vtkIdType* out = target.data() + r * columns;
        // Continuous voxel coordinates of pixel (x, y): start + x * step.
        double start[3], step[3];
        for (int c = 0; c < 3; ++c)
        {
          start[c] = (m[4 * c + 1] * y + m[4 * c + 3] - this->Origin[c]) / this->Spacing[c] - this->Start[c];
          step[c] = m[4 * c] / this->Spacing[c];
        }
        const unsigned char* maskRow = mask ? mask + std::size_t(y) * width : nullptr;
        for (int i = 0; i < columns; ++i)
        {
          const int x = clip[0] + i;
          if (maskRow && !maskRow[x])
          {
            out[i] = -1;
            continue;
          }
          vtkIdType index[3];
          bool inside = true;
          for (int c = 0; c < 3; ++c)
          {
            // Nearest voxel centre (vtkPlusPasteSliceIntoVolume's nearest-neighbour rounding).
            const double f = std::floor(start[c] + step[c] * x + 0.5);
            inside = inside && f >= 0 && f < this->Dims[c];
            index[c] = inside ? static_cast<vtkIdType>(f) : 0;
          }
          out[i] = inside ? index[0] + this->Dims[0] * (index[1] + vtkIdType(this->Dims[1]) * index[2]) : -1;
        }
      }
    });
  }

  /// Insert the pixels of one frame (typed pointer to its first pixel) at their voxels. Serial: many
  /// pixels share a voxel (several per voxel along each image axis), and the order matters for LATEST.
  template <typename T>
  void Insert(const T* frame, const int clip[4], int width, const std::vector<vtkIdType>& target)
  {
    const int columns = clip[1] - clip[0] + 1;
    const int rows = clip[3] - clip[2] + 1;
    for (int r = 0; r < rows; ++r)
    {
      const T* row = frame + std::size_t(clip[2] + r) * width + clip[0];
      const vtkIdType* voxel = target.data() + std::size_t(r) * columns;
      for (int i = 0; i < columns; ++i)
      {
        const vtkIdType v = voxel[i];
        if (v < 0)
        {
          continue;
        }
        const float value = static_cast<float>(row[i]);
        switch (this->Mode)
        {
          case vtkUltrasoundVolumeCompounder::MEAN:
            this->Value[v] += value;
            break;
          case vtkUltrasoundVolumeCompounder::MAXIMUM:
            this->Value[v] = this->Count[v] == 0 ? value : std::max(this->Value[v], value);
            break;
          default:
            this->Value[v] = value;
            break;
        }
        ++this->Count[v];
        ++this->Inserted;
      }
    }
  }
};
}

vtkUltrasoundVolumeCompounder::vtkUltrasoundVolumeCompounder()
{
  this->SetNumberOfInputPorts(2);
  this->SetOutputOriginToDefault();
  this->SetOutputExtentToDefault();
}

vtkUltrasoundVolumeCompounder::~vtkUltrasoundVolumeCompounder()
{
  this->SetFrameList(nullptr);
}

vtkMTimeType vtkUltrasoundVolumeCompounder::GetMTime()
{
  vtkMTimeType time = this->Superclass::GetMTime();
  if (this->FrameList)
  {
    time = std::max(time, this->FrameList->GetMTime());
  }
  return time;
}

void vtkUltrasoundVolumeCompounder::SetOutputOriginToDefault()
{
  this->SetOutputOrigin(Unset, Unset, Unset);
}

void vtkUltrasoundVolumeCompounder::SetOutputExtentToDefault()
{
  this->SetOutputExtent(UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent);
}

const char* vtkUltrasoundVolumeCompounder::GetCompoundingModeAsString()
{
  switch (this->CompoundingMode)
  {
    case MAXIMUM:
      return "MAXIMUM";
    case LATEST:
      return "LATEST";
    default:
      return "MEAN";
  }
}

int vtkUltrasoundVolumeCompounder::FillInputPortInformation(int port, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkImageData");
  info->Set(vtkAlgorithm::INPUT_IS_REPEATABLE(), 1);
  if (port == 1)
  {
    info->Set(vtkAlgorithm::INPUT_IS_OPTIONAL(), 1);
  }
  return 1;
}

int vtkUltrasoundVolumeCompounder::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  const bool explicitGrid = this->OutputOrigin[0] != Unset && this->OutputOrigin[1] != Unset &&
    this->OutputOrigin[2] != Unset && this->OutputExtent[0] != UnsetExtent;
  std::vector<FramePlan> plans;
  std::string error;
  if (!explicitGrid)
  {
    // The automatic grid comes from the poses: bring the sequences up to date now.
    for (int k = 0; k < this->GetNumberOfInputConnections(0); ++k)
    {
      this->GetInputConnection(0, k)->GetProducer()->UpdatePiece(0, 1, 0);
    }
    if (!MakePlans(inputVector[0], this->FrameList, this->ClipRectangleOrigin, this->ClipRectangleSize, plans, error))
    {
      vtkErrorMacro(<< error);
      return 0;
    }
  }
  double origin[3];
  int extent[6];
  if (!ComputeGrid(explicitGrid ? nullptr : &plans, this->OutputSpacing, this->OutputOrigin, this->OutputExtent,
        this->MaximumNumberOfVoxels, origin, extent, error))
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent, 6);
  outInfo->Set(vtkDataObject::SPACING(), this->OutputSpacing, 3);
  outInfo->Set(vtkDataObject::ORIGIN(), origin, 3);
  vtkDataObject::SetPointDataActiveScalarInfo(outInfo, VTK_FLOAT, 1);
  return 1;
}

int vtkUltrasoundVolumeCompounder::RequestUpdateExtent(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector*)
{
  // Every frame and the whole mask are needed, whatever part of the volume is asked for.
  bigus::RequestWholeExtent(inputVector, 2);
  return 1;
}

int vtkUltrasoundVolumeCompounder::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  this->NumberOfInsertedFrames = 0;
  this->NumberOfInsertedPixels = 0;
  this->NumberOfHitVoxels = 0;
  this->NumberOfFilledVoxels = 0;
  this->InsertionSeconds = 0;
  this->HoleFillingSeconds = 0;

  std::vector<FramePlan> plans;
  std::string error;
  double origin[3];
  int extent[6];
  const int sweeps = inputVector[0]->GetNumberOfInformationObjects();
  const int maskCount = inputVector[1]->GetNumberOfInformationObjects();
  if (!bigus::CheckMaskCount(maskCount, sweeps, &error) ||
    !MakePlans(inputVector[0], this->FrameList, this->ClipRectangleOrigin, this->ClipRectangleSize, plans, error) ||
    !ComputeGrid(&plans, this->OutputSpacing, this->OutputOrigin, this->OutputExtent, this->MaximumNumberOfVoxels,
      origin, extent, error))
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  for (const FramePlan& plan : plans)
  {
    if (!plan.SkippedInvalid.empty())
    {
      vtkWarningMacro(<< (sweeps > 1 ? "sweep " + std::to_string(plan.Input) + ": " : std::string())
                      << plan.SkippedInvalid.size() << " listed frame(s) have FrameValid = 0 and are not inserted "
                      << "(first: frame " << plan.SkippedInvalid.front() << ")");
    }
  }

  output->SetExtent(extent);
  output->SetOrigin(origin);
  output->SetSpacing(this->OutputSpacing);
  const vtkIdType voxels =
    vtkIdType(extent[1] - extent[0] + 1) * (extent[3] - extent[2] + 1) * (extent[5] - extent[4] + 1);
  vtkNew<vtkFloatArray> values;
  values->SetName("Intensity");
  vtkNew<vtkUnsignedIntArray> counts;
  counts->SetName("InsertedPixelCount");
  values->SetNumberOfTuples(voxels);
  counts->SetNumberOfTuples(voxels);
  vtkSMPTools::Fill(values->GetPointer(0), values->GetPointer(0) + voxels, 0.0f);
  vtkSMPTools::Fill(counts->GetPointer(0), counts->GetPointer(0) + voxels, 0u);

  Accumulator acc;
  for (int c = 0; c < 3; ++c)
  {
    acc.Dims[c] = extent[2 * c + 1] - extent[2 * c] + 1;
    acc.Start[c] = extent[2 * c];
    acc.Origin[c] = origin[c];
    acc.Spacing[c] = this->OutputSpacing[c];
  }
  acc.Mode = this->CompoundingMode;
  acc.Value = values->GetPointer(0);
  acc.Count = counts->GetPointer(0);

  const auto start = std::chrono::steady_clock::now();
  const double insertionShare = this->FillHoles ? 0.5 : 1.0;
  std::size_t total = 0, done = 0;
  for (const FramePlan& plan : plans)
  {
    total += plan.Inserted.size();
  }
  std::vector<vtkIdType> target;
  for (const FramePlan& plan : plans)
  {
    vtkImageData* input = vtkImageData::GetData(inputVector[0], plan.Input);
    vtkImageData* maskImage = maskCount ? vtkImageData::GetData(inputVector[1], plan.Input) : nullptr;
    // The fan mask, as bytes: one W x H plane shared by every frame, or one per frame.
    const std::size_t framePixels = std::size_t(plan.Width) * plan.Height;
    std::vector<unsigned char> mask;
    bool maskPerFrame = false;
    if (maskImage)
    {
      int maskDims[3];
      maskImage->GetDimensions(maskDims);
      vtkDataArray* maskScalars = maskImage->GetPointData()->GetScalars();
      const bool sizeOk =
        maskDims[0] == plan.Width && maskDims[1] == plan.Height && (maskDims[2] == 1 || maskDims[2] == plan.Frames);
      if (!maskScalars || maskScalars->GetNumberOfComponents() != 1 || !sizeOk ||
        maskScalars->GetNumberOfTuples() != vtkIdType(framePixels) * maskDims[2])
      {
        vtkErrorMacro(<< (sweeps > 1 ? "sweep " + std::to_string(plan.Input) + ": " : std::string())
                      << "the fan mask must be a one-component W x H x 1 or W x H x N image for the " << plan.Width
                      << " x " << plan.Height << " x " << plan.Frames << " sequence, not " << maskDims[0] << " x "
                      << maskDims[1] << " x " << maskDims[2]);
        output->Initialize();
        return 0;
      }
      maskPerFrame = maskDims[2] > 1;
      mask.resize(maskScalars->GetNumberOfTuples());
      vtkSMPTools::For(0, maskScalars->GetNumberOfTuples(), 65536, [&](vtkIdType begin, vtkIdType end) {
        for (vtkIdType p = begin; p < end; ++p)
        {
          mask[p] = maskScalars->GetComponent(p, 0) != 0 ? 1 : 0;
        }
      });
    }
    void* pixels = input->GetScalarPointer();
    const int scalarType = input->GetScalarType();
    for (std::size_t k = 0; k < plan.Inserted.size(); ++k)
    {
      const vtkIdType f = plan.Inserted[k];
      const unsigned char* frameMask =
        mask.empty() ? nullptr : mask.data() + (maskPerFrame ? std::size_t(f) * framePixels : 0);
      acc.Locate(plan.Poses[k], plan.Clip, frameMask, plan.Width, target);
      switch (scalarType)
      {
        vtkTemplateMacro(
          acc.Insert(static_cast<const VTK_TT*>(pixels) + std::size_t(f) * framePixels, plan.Clip, plan.Width, target));
        default:
          vtkErrorMacro("unsupported scalar type " << input->GetScalarTypeAsString());
          output->Initialize();
          return 0;
      }
      this->UpdateProgress(insertionShare * ++done / total);
      if (this->AbortExecute)
      {
        output->Initialize();
        return 0;
      }
    }
  }
  float* value = acc.Value;
  const unsigned int* count = acc.Count;
  const bool mean = this->CompoundingMode == MEAN;
  std::vector<vtkIdType> hitPerChunk;
  {
    const vtkIdType chunk = 1 << 20;
    hitPerChunk.assign((voxels + chunk - 1) / chunk, 0);
    vtkSMPTools::For(0, vtkIdType(hitPerChunk.size()), 1, [&](vtkIdType begin, vtkIdType end) {
      for (vtkIdType c = begin; c < end; ++c)
      {
        vtkIdType hit = 0;
        for (vtkIdType v = c * chunk; v < std::min(voxels, (c + 1) * chunk); ++v)
        {
          if (count[v])
          {
            ++hit;
            if (mean)
            {
              value[v] /= count[v];
            }
          }
        }
        hitPerChunk[c] = hit;
      }
    });
  }
  for (vtkIdType hit : hitPerChunk)
  {
    this->NumberOfHitVoxels += hit;
  }
  this->NumberOfInsertedFrames = static_cast<int>(total);
  this->NumberOfInsertedPixels = acc.Inserted;
  const auto inserted = std::chrono::steady_clock::now();
  this->InsertionSeconds = std::chrono::duration<double>(inserted - start).count();

  if (this->FillHoles)
  {
    HoleFiller filler(acc.Dims, value, count);
    const int radii = (this->HoleFillingMaximumKernelSize - 1) / 2;
    for (int r = 1; r <= radii; ++r)
    {
      this->NumberOfFilledVoxels += filler.Pass(r, this->HoleFillingSigma * r, this->HoleFillingMinimumKnownRatio);
      this->UpdateProgress(insertionShare + (1 - insertionShare) * r / radii);
      if (this->AbortExecute)
      {
        output->Initialize();
        return 0;
      }
    }
    this->HoleFillingSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - inserted).count();
  }

  output->GetPointData()->SetScalars(values);
  output->GetPointData()->AddArray(counts);
  return 1;
}

void vtkUltrasoundVolumeCompounder::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "FrameList: ";
  if (this->FrameList && this->FrameList->GetNumberOfIds() > 0)
  {
    os << this->FrameList->GetNumberOfIds() << " frames\n";
  }
  else
  {
    os << "(all frames)\n";
  }
  os << indent << "OutputSpacing: " << this->OutputSpacing[0] << " " << this->OutputSpacing[1] << " "
     << this->OutputSpacing[2] << "\n";
  os << indent << "OutputOrigin: ";
  if (this->OutputOrigin[0] == Unset)
  {
    os << "(automatic)\n";
  }
  else
  {
    os << this->OutputOrigin[0] << " " << this->OutputOrigin[1] << " " << this->OutputOrigin[2] << "\n";
  }
  os << indent << "OutputExtent: ";
  if (this->OutputExtent[0] == UnsetExtent)
  {
    os << "(automatic)\n";
  }
  else
  {
    for (int e = 0; e < 6; ++e)
    {
      os << this->OutputExtent[e] << (e < 5 ? " " : "\n");
    }
  }
  os << indent << "ClipRectangleOrigin: " << this->ClipRectangleOrigin[0] << " " << this->ClipRectangleOrigin[1]
     << "\n";
  os << indent << "ClipRectangleSize: " << this->ClipRectangleSize[0] << " " << this->ClipRectangleSize[1] << "\n";
  os << indent << "CompoundingMode: " << this->GetCompoundingModeAsString() << "\n";
  os << indent << "FillHoles: " << (this->FillHoles ? "On" : "Off") << "\n";
  os << indent << "HoleFillingMaximumKernelSize: " << this->HoleFillingMaximumKernelSize << "\n";
  os << indent << "HoleFillingSigma: " << this->HoleFillingSigma << "\n";
  os << indent << "HoleFillingMinimumKnownRatio: " << this->HoleFillingMinimumKnownRatio << "\n";
  os << indent << "MaximumNumberOfVoxels: " << this->MaximumNumberOfVoxels << "\n";
  os << indent << "NumberOfInsertedFrames: " << this->NumberOfInsertedFrames << "\n";
  os << indent << "NumberOfInsertedPixels: " << this->NumberOfInsertedPixels << "\n";
  os << indent << "NumberOfHitVoxels: " << this->NumberOfHitVoxels << "\n";
  os << indent << "NumberOfFilledVoxels: " << this->NumberOfFilledVoxels << "\n";
  os << indent << "InsertionSeconds: " << this->InsertionSeconds << "\n";
  os << indent << "HoleFillingSeconds: " << this->HoleFillingSeconds << "\n";
}
