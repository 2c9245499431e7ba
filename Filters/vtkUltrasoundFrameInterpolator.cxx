#include "vtkUltrasoundFrameInterpolator.h"

#include "bigusGaussianFieldData.h"
#include "bigusPipeline.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkFloatArray.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkIntArray.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkSMPTools.h"
#include "vtkStreamingDemandDrivenPipeline.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <set>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkUltrasoundFrameInterpolator);
vtkCxxSetObjectMacro(vtkUltrasoundFrameInterpolator, TrainingFrames, vtkIdList);
vtkCxxSetObjectMacro(vtkUltrasoundFrameInterpolator, TargetFrames, vtkIdList);

namespace
{
/// The target frames: the explicit list, or every frame of [0, frames) not in the training list.
std::vector<vtkIdType> Targets(vtkIdList* training, vtkIdList* targets, vtkIdType frames)
{
  std::vector<vtkIdType> out;
  if (targets && targets->GetNumberOfIds() > 0)
  {
    for (vtkIdType k = 0; k < targets->GetNumberOfIds(); ++k)
    {
      out.push_back(targets->GetId(k));
    }
    return out;
  }
  std::set<vtkIdType> used;
  for (vtkIdType k = 0; training && k < training->GetNumberOfIds(); ++k)
  {
    used.insert(training->GetId(k));
  }
  for (vtkIdType f = 0; f < frames; ++f)
  {
    if (!used.count(f))
    {
      out.push_back(f);
    }
  }
  return out;
}

/// One predicted frame: out = (1 - w) A + w B over the W x H pixels.
template <typename T>
void Blend(const T* a, const T* b, double w, vtkIdType pixels, float* out)
{
  const double wa = 1 - w;
  for (vtkIdType p = 0; p < pixels; ++p)
  {
    out[p] = static_cast<float>(w == 0 ? double(a[p]) : wa * double(a[p]) + w * double(b[p]));
  }
}
}

vtkUltrasoundFrameInterpolator::vtkUltrasoundFrameInterpolator() = default;

vtkUltrasoundFrameInterpolator::~vtkUltrasoundFrameInterpolator()
{
  this->SetTrainingFrames(nullptr);
  this->SetTargetFrames(nullptr);
}

vtkMTimeType vtkUltrasoundFrameInterpolator::GetMTime()
{
  vtkMTimeType time = this->Superclass::GetMTime();
  for (vtkIdList* list : { this->TrainingFrames, this->TargetFrames })
  {
    if (list)
    {
      time = std::max(time, list->GetMTime());
    }
  }
  return time;
}

const char* vtkUltrasoundFrameInterpolator::GetModeAsString()
{
  return this->Mode == TEMPORAL_BLEND ? "TemporalBlend" : "NearestPose";
}

int vtkUltrasoundFrameInterpolator::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkInformation* inInfo = inputVector[0]->GetInformationObject(0);
  int extent[6];
  inInfo->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent);
  const vtkIdType frames = extent[5] - extent[4] + 1;
  const vtkIdType targets = static_cast<vtkIdType>(Targets(this->TrainingFrames, this->TargetFrames, frames).size());
  extent[4] = 0;
  extent[5] = static_cast<int>(std::max<vtkIdType>(targets, 1)) - 1;
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent, 6);
  const double spacing[3] = { 1, 1, 1 }, origin[3] = { 0, 0, 0 };
  outInfo->Set(vtkDataObject::SPACING(), spacing, 3);
  outInfo->Set(vtkDataObject::ORIGIN(), origin, 3);
  vtkDataObject::SetPointDataActiveScalarInfo(outInfo, VTK_FLOAT, 1);
  return 1;
}

int vtkUltrasoundFrameInterpolator::RequestUpdateExtent(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector*)
{
  // Any frame may be a source, so the whole sequence is needed.
  bigus::RequestWholeExtent(inputVector[0]);
  return 1;
}

int vtkUltrasoundFrameInterpolator::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkImageData* input = vtkImageData::GetData(inputVector[0], 0);
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  vtkDataArray* scalars = input ? input->GetPointData()->GetScalars() : nullptr;
  if (!scalars || scalars->GetNumberOfTuples() == 0)
  {
    vtkErrorMacro("input must be a tracked frame sequence with pixels (W x H x N)");
    return 0;
  }
  if (scalars->GetNumberOfComponents() != 1)
  {
    vtkErrorMacro("the frames must have one-component scalars, not " << scalars->GetNumberOfComponents());
    return 0;
  }
  int dims[3];
  input->GetDimensions(dims);
  const vtkIdType frames = dims[2];
  vtkFieldData* fields = input->GetFieldData();
  vtkDataArray* poses = fields ? fields->GetArray("ImageToReference") : nullptr;
  if (!poses || poses->GetNumberOfComponents() != 16 || poses->GetNumberOfTuples() != frames)
  {
    vtkErrorMacro(
      "the sequence needs ImageToReference field data of " << frames << " x 16 values (one pose per frame)");
    return 0;
  }
  vtkDataArray* stamps = fields->GetArray("Timestamp");
  if (this->Mode == TEMPORAL_BLEND &&
    (!stamps || stamps->GetNumberOfComponents() != 1 || stamps->GetNumberOfTuples() != frames))
  {
    vtkErrorMacro("TemporalBlend needs Timestamp field data of " << frames << " values (one per frame)");
    return 0;
  }
  vtkDataArray* valid = fields->GetArray("FrameValid");
  if (valid && valid->GetNumberOfTuples() != frames)
  {
    valid = nullptr;
  }
  auto isValid = [&](vtkIdType f) { return !valid || valid->GetTuple1(f) != 0; };
  auto centre = [&](vtkIdType f, std::array<double, 3>& c) {
    double m[16];
    poses->GetTuple(f, m);
    const bool affine = m[12] == 0 && m[13] == 0 && m[14] == 0 && m[15] == 1;
    for (int r = 0; r < 3; ++r)
    {
      c[r] = m[4 * r] * 0.5 * dims[0] + m[4 * r + 1] * 0.5 * dims[1] + m[4 * r + 3];
    }
    return affine && std::isfinite(c[0]) && std::isfinite(c[1]) && std::isfinite(c[2]);
  };

  if (!this->TrainingFrames || this->TrainingFrames->GetNumberOfIds() == 0)
  {
    vtkErrorMacro("the training frame list is empty: set TrainingFrames");
    return 0;
  }
  std::vector<vtkIdType> training;
  for (vtkIdType k = 0; k < this->TrainingFrames->GetNumberOfIds(); ++k)
  {
    const vtkIdType f = this->TrainingFrames->GetId(k);
    if (f < 0 || f >= frames)
    {
      vtkErrorMacro("training frame " << f << " is outside the " << frames << " frames of the sequence");
      return 0;
    }
    if (!isValid(f))
    {
      vtkErrorMacro("training frame " << f << " has FrameValid = 0: its pose or image must not be used");
      return 0;
    }
    training.push_back(f);
  }
  const std::vector<vtkIdType> targets = Targets(this->TrainingFrames, this->TargetFrames, frames);
  if (targets.empty())
  {
    vtkErrorMacro("no target frame: every frame of the sequence is a training frame");
    return 0;
  }
  for (vtkIdType f : targets)
  {
    if (f < 0 || f >= frames)
    {
      vtkErrorMacro("target frame " << f << " is outside the " << frames << " frames of the sequence");
      return 0;
    }
  }

  // Sources A, B and the weight of B for every target (-1: an invalid target, predicted as zeros).
  const std::size_t count = targets.size();
  std::vector<std::array<vtkIdType, 2>> sources(count, { { -1, -1 } });
  std::vector<double> weights(count, 0.0);
  int invalidTargets = 0;
  if (this->Mode == NEAREST_POSE)
  {
    std::vector<std::array<double, 3>> centres(training.size());
    for (std::size_t k = 0; k < training.size(); ++k)
    {
      if (!centre(training[k], centres[k]))
      {
        vtkErrorMacro("training frame " << training[k] << ": ImageToReference is not a finite affine map");
        return 0;
      }
    }
    for (std::size_t m = 0; m < count; ++m)
    {
      if (!isValid(targets[m]))
      {
        ++invalidTargets;
        continue;
      }
      std::array<double, 3> c;
      if (!centre(targets[m], c))
      {
        vtkErrorMacro("target frame " << targets[m] << ": ImageToReference is not a finite affine map");
        return 0;
      }
      double best = VTK_DOUBLE_MAX;
      for (std::size_t k = 0; k < training.size(); ++k)
      {
        const double d = (c[0] - centres[k][0]) * (c[0] - centres[k][0]) +
          (c[1] - centres[k][1]) * (c[1] - centres[k][1]) + (c[2] - centres[k][2]) * (c[2] - centres[k][2]);
        if (d < best)
        {
          best = d;
          sources[m] = { { training[k], training[k] } };
        }
      }
    }
  }
  else
  {
    // Training frames in time order; the list order breaks ties so the result is deterministic.
    std::vector<std::size_t> order(training.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(),
      [&](std::size_t a, std::size_t b) { return stamps->GetTuple1(training[a]) < stamps->GetTuple1(training[b]); });
    std::vector<double> times(order.size());
    for (std::size_t k = 0; k < order.size(); ++k)
    {
      times[k] = stamps->GetTuple1(training[order[k]]);
      if (!std::isfinite(times[k]))
      {
        vtkErrorMacro("training frame " << training[order[k]] << " has a non-finite Timestamp");
        return 0;
      }
    }
    for (std::size_t m = 0; m < count; ++m)
    {
      if (!isValid(targets[m]))
      {
        ++invalidTargets;
        continue;
      }
      const double t = stamps->GetTuple1(targets[m]);
      if (!std::isfinite(t))
      {
        vtkErrorMacro("target frame " << targets[m] << " has a non-finite Timestamp");
        return 0;
      }
      // First training time strictly after t: B; the one before it: A.
      const std::size_t b = std::upper_bound(times.begin(), times.end(), t) - times.begin();
      if (b == 0 || b == times.size())
      {
        const vtkIdType end = training[order[b == 0 ? 0 : times.size() - 1]];
        sources[m] = { { end, end } };
        continue;
      }
      const std::size_t a = b - 1;
      const double span = times[b] - times[a];
      sources[m] = { { training[order[a]], training[order[b]] } };
      weights[m] = span > 0 ? (t - times[a]) / span : 0.0;
    }
  }
  if (invalidTargets > 0)
  {
    vtkWarningMacro(<< invalidTargets << " target frame(s) have FrameValid = 0: predicted as zeros");
  }

  // Pixels.
  const vtkIdType pixels = vtkIdType(dims[0]) * dims[1];
  vtkNew<vtkFloatArray> intensity;
  intensity->SetName("Intensity");
  intensity->SetNumberOfTuples(pixels * vtkIdType(count));
  float* out = intensity->GetPointer(0);
  void* in = input->GetScalarPointer();
  const int scalarType = input->GetScalarType();
  bool typeOk = true;
  vtkSMPTools::For(0, vtkIdType(count), 1, [&](vtkIdType begin, vtkIdType end) {
    for (vtkIdType m = begin; m < end; ++m)
    {
      float* frame = out + m * pixels;
      if (sources[m][0] < 0)
      {
        std::fill(frame, frame + pixels, 0.0f);
        continue;
      }
      switch (scalarType)
      {
        vtkTemplateMacro(Blend(static_cast<const VTK_TT*>(in) + sources[m][0] * pixels,
          static_cast<const VTK_TT*>(in) + sources[m][1] * pixels, weights[m], pixels, frame));
        default:
          typeOk = false;
          break;
      }
    }
  });
  if (!typeOk)
  {
    vtkErrorMacro("unsupported scalar type " << input->GetScalarTypeAsString());
    return 0;
  }

  output->SetExtent(0, dims[0] - 1, 0, dims[1] - 1, 0, static_cast<int>(count) - 1);
  output->SetSpacing(1, 1, 1);
  output->SetOrigin(0, 0, 0);
  output->GetPointData()->SetScalars(intensity);
  bigus::CopyFrameFieldData(fields, frames, targets, output->GetFieldData());
  vtkNew<vtkIntArray> used;
  used->SetName("SourceFrames");
  used->SetNumberOfComponents(2);
  used->SetNumberOfTuples(vtkIdType(count));
  vtkNew<vtkDoubleArray> blend;
  blend->SetName("BlendWeight");
  blend->SetNumberOfTuples(vtkIdType(count));
  for (std::size_t m = 0; m < count; ++m)
  {
    used->SetTypedComponent(vtkIdType(m), 0, static_cast<int>(sources[m][0]));
    used->SetTypedComponent(vtkIdType(m), 1, static_cast<int>(sources[m][1]));
    blend->SetValue(vtkIdType(m), weights[m]);
  }
  output->GetFieldData()->AddArray(used);
  output->GetFieldData()->AddArray(blend);
  return 1;
}

void vtkUltrasoundFrameInterpolator::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "TrainingFrames: " << (this->TrainingFrames ? this->TrainingFrames->GetNumberOfIds() : 0)
     << " frames\n";
  os << indent << "TargetFrames: ";
  if (this->TargetFrames && this->TargetFrames->GetNumberOfIds() > 0)
  {
    os << this->TargetFrames->GetNumberOfIds() << " frames\n";
  }
  else
  {
    os << "(every frame not in TrainingFrames)\n";
  }
  os << indent << "Mode: " << this->GetModeAsString() << "\n";
}
