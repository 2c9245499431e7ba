#include "vtkUltrasoundVolumeSweep.h"

#include "bigusPipeline.h"
#include "bigusSeeding.h" // bigus::UniformDouble
#include "vtkUltrasoundSequenceReslice.h"

#include "vtkCallbackCommand.h"
#include "vtkDoubleArray.h"
#include "vtkExecutive.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkIntArray.h"
#include "vtkMatrix3x3.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkUnsignedCharArray.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <random>
#include <sstream>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkUltrasoundVolumeSweep);

namespace
{
/// Seconds between consecutive frames of a synthetic sweep (20 frames per second).
constexpr double FrameInterval = 0.05;
/// Largest frame side (pixels) that a PixelSpacing may ask for.
constexpr int MaximumFrameSide = 16384;

/// Frame layout of a sweep, from the volume's dimensions and spacing and the filter's settings.
struct SweepGeometry
{
  int Axis = 2;     // a: the slice normal is volume axis a
  int U = 0, V = 1; // volume axes of the frame's columns and rows
  int Width = 0, Height = 0;
  double PixelU = 0, PixelV = 0; // mm
  double Delta = 0;              // slice spacing (mm), Parallel and Orthogonal
};

/// Validates the settings and lays out the frames; an empty string on success, else the error.
std::string LayOut(const int dims[3], const double spacing[3], int protocol, int sweepAxis, int frames, double offset,
  double maximumTilt, double pixelSpacing, SweepGeometry& g)
{
  std::ostringstream error;
  if (dims[0] < 2 || dims[1] < 2 || dims[2] < 2)
  {
    error << "input must be a 3D volume with at least 2 voxels along every axis, not " << dims[0] << " x " << dims[1]
          << " x " << dims[2];
  }
  else if (!(spacing[0] > 0 && spacing[1] > 0 && spacing[2] > 0))
  {
    error << "the volume's spacing must be positive, not " << spacing[0] << " " << spacing[1] << " " << spacing[2];
  }
  else if (protocol < vtkUltrasoundVolumeSweep::PARALLEL || protocol > vtkUltrasoundVolumeSweep::ORTHOGONAL)
  {
    error << "Protocol must be Parallel (0), Oblique (1) or Orthogonal (2), not " << protocol;
  }
  else if (sweepAxis < 0 || sweepAxis > 2)
  {
    error << "SweepAxis must be 0, 1 or 2, not " << sweepAxis;
  }
  else if (frames < 1)
  {
    error << "NumberOfFrames must be at least 1, not " << frames;
  }
  else if (!(offset >= 0 && offset < 1))
  {
    error << "Offset must lie in [0, 1), not " << offset;
  }
  else if (!(maximumTilt >= 0 && maximumTilt <= 90))
  {
    error << "MaximumTiltAngle must lie in [0, 90] degrees, not " << maximumTilt;
  }
  else if (!(pixelSpacing >= 0) || !std::isfinite(pixelSpacing))
  {
    error << "PixelSpacing must be 0 (the volume's spacing) or positive, not " << pixelSpacing;
  }
  if (!error.str().empty())
  {
    return error.str();
  }
  g.Axis = protocol == vtkUltrasoundVolumeSweep::ORTHOGONAL ? (sweepAxis + 1) % 3 : sweepAxis;
  g.U = (g.Axis + 1) % 3;
  g.V = (g.Axis + 2) % 3;
  g.PixelU = pixelSpacing > 0 ? pixelSpacing : spacing[g.U];
  g.PixelV = pixelSpacing > 0 ? pixelSpacing : spacing[g.V];
  // The tolerance keeps a cross-section that is a whole number of pixels from losing its last one.
  const double columns = std::floor((dims[g.U] - 1) * spacing[g.U] / g.PixelU + 1e-6) + 1;
  const double rows = std::floor((dims[g.V] - 1) * spacing[g.V] / g.PixelV + 1e-6) + 1;
  if (columns > MaximumFrameSide || rows > MaximumFrameSide)
  {
    error << "PixelSpacing " << pixelSpacing << " mm would make " << columns << " x " << rows
          << " pixel frames (at most " << MaximumFrameSide << " a side)";
    return error.str();
  }
  g.Width = static_cast<int>(columns);
  g.Height = static_cast<int>(rows);
  g.Delta = protocol == vtkUltrasoundVolumeSweep::OBLIQUE ? 0.0 : dims[g.Axis] * spacing[g.Axis] / frames;
  return std::string();
}

/// Rotation by `angle` (radians) about the unit axis w (Rodrigues), row-major 3x3.
std::array<double, 9> Rotation(const double w[3], double angle)
{
  const double c = std::cos(angle), s = std::sin(angle), C = 1 - c;
  return { c + C * w[0] * w[0], C * w[0] * w[1] - s * w[2], C * w[0] * w[2] + s * w[1], C * w[1] * w[0] + s * w[2],
    c + C * w[1] * w[1], C * w[1] * w[2] - s * w[0], C * w[2] * w[0] - s * w[1], C * w[2] * w[1] + s * w[0],
    c + C * w[2] * w[2] };
}

/// Row-major ImageToReference of every frame (see the class description for the formula).
std::vector<std::array<double, 16>> Poses(vtkImageData* volume, const SweepGeometry& g, int protocol, int frames,
  double offset, double maximumTilt, unsigned int seed)
{
  int dims[3];
  volume->GetDimensions(dims);
  const double* spacing = volume->GetSpacing();
  const double* origin = volume->GetOrigin();
  const double* direction = volume->GetDirectionMatrix()->GetData();
  const double length = (dims[g.Axis] - 1) * spacing[g.Axis];

  // Position (mm from the first voxel plane) and rotation of each frame, in the volume's axes.
  struct Slice
  {
    double Z;
    std::array<double, 9> R;
  };
  std::vector<Slice> slices(frames);
  const std::array<double, 9> identity = { 1, 0, 0, 0, 1, 0, 0, 0, 1 };
  if (protocol == vtkUltrasoundVolumeSweep::OBLIQUE)
  {
    std::mt19937_64 rng(seed);
    for (Slice& slice : slices)
    {
      slice.Z = bigus::UniformDouble(rng) * length;
      const double phi = 2 * M_PI * bigus::UniformDouble(rng);
      const double theta = maximumTilt * M_PI / 180 * bigus::UniformDouble(rng);
      double w[3] = { 0, 0, 0 };
      w[g.U] = std::cos(phi);
      w[g.V] = std::sin(phi);
      slice.R = Rotation(w, theta);
    }
    std::stable_sort(slices.begin(), slices.end(), [](const Slice& a, const Slice& b) { return a.Z < b.Z; });
  }
  else
  {
    for (int k = 0; k < frames; ++k)
    {
      slices[k] = { (k + offset) * g.Delta, identity };
    }
  }

  std::vector<std::array<double, 16>> poses(frames);
  for (int k = 0; k < frames; ++k)
  {
    const std::array<double, 9>& R = slices[k].R;
    // Columns of the pose in the volume's axes: p_u R u, p_v R v, R n (u, v, n are unit axes).
    double columns[3][3];
    const int axes[3] = { g.U, g.V, g.Axis };
    const double scales[3] = { g.PixelU, g.PixelV, 1.0 };
    for (int c = 0; c < 3; ++c)
    {
      for (int r = 0; r < 3; ++r)
      {
        columns[c][r] = scales[c] * R[3 * r + axes[c]];
      }
    }
    // Translation: c + (z - L/2) n - R [(W-1)/2 p_u u + (H-1)/2 p_v v], centre c relative to o.
    double t[3];
    for (int r = 0; r < 3; ++r)
    {
      t[r] =
        (dims[r] - 1) * spacing[r] / 2 - (g.Width - 1) / 2.0 * columns[0][r] - (g.Height - 1) / 2.0 * columns[1][r];
    }
    t[g.Axis] += slices[k].Z - length / 2;
    // From the volume's axes to the reference frame: x = o + D q.
    std::array<double, 16>& pose = poses[k];
    for (int r = 0; r < 3; ++r)
    {
      for (int c = 0; c < 3; ++c)
      {
        pose[4 * r + c] = direction[3 * r] * columns[c][0] + direction[3 * r + 1] * columns[c][1] +
          direction[3 * r + 2] * columns[c][2];
      }
      pose[4 * r + 3] = origin[r] + direction[3 * r] * t[0] + direction[3 * r + 1] * t[1] + direction[3 * r + 2] * t[2];
    }
    pose[12] = pose[13] = pose[14] = 0;
    pose[15] = 1;
  }
  return poses;
}

/// The pose input of the internal reslice: a W x H x N image without pixels and the sweep's field data.
vtkSmartPointer<vtkImageData> PoseSequence(const std::vector<std::array<double, 16>>& poses, int width, int height)
{
  const int frames = static_cast<int>(poses.size());
  auto sequence = vtkSmartPointer<vtkImageData>::New();
  sequence->SetExtent(0, width - 1, 0, height - 1, 0, frames - 1);
  vtkNew<vtkDoubleArray> imageToReference;
  imageToReference->SetName("ImageToReference");
  imageToReference->SetNumberOfComponents(16);
  imageToReference->SetNumberOfTuples(frames);
  vtkNew<vtkDoubleArray> timestamp;
  timestamp->SetName("Timestamp");
  timestamp->SetNumberOfTuples(frames);
  vtkNew<vtkUnsignedCharArray> valid;
  valid->SetName("FrameValid");
  valid->SetNumberOfTuples(frames);
  vtkNew<vtkIntArray> index;
  index->SetName("FrameIndex");
  index->SetNumberOfTuples(frames);
  for (int k = 0; k < frames; ++k)
  {
    imageToReference->SetTypedTuple(k, poses[k].data());
    timestamp->SetValue(k, k * FrameInterval);
    valid->SetValue(k, 1);
    index->SetValue(k, k);
  }
  for (vtkDataArray* array : { static_cast<vtkDataArray*>(imageToReference), static_cast<vtkDataArray*>(timestamp),
         static_cast<vtkDataArray*>(valid), static_cast<vtkDataArray*>(index) })
  {
    sequence->GetFieldData()->AddArray(array);
  }
  return sequence;
}

void ForwardProgress(vtkObject*, unsigned long, void* clientData, void* callData)
{
  static_cast<vtkAlgorithm*>(clientData)->UpdateProgress(*static_cast<double*>(callData));
}

/// Keeps the first error message (the reslice's own; the executive's follow-up only repeats it).
void KeepError(vtkObject*, unsigned long, void* clientData, void* callData)
{
  std::string& message = *static_cast<std::string*>(clientData);
  if (message.empty())
  {
    message = callData ? static_cast<const char*>(callData) : "unknown error";
  }
}
}

vtkUltrasoundVolumeSweep::vtkUltrasoundVolumeSweep()
{
  this->SetNumberOfOutputPorts(2);
}

vtkUltrasoundVolumeSweep::~vtkUltrasoundVolumeSweep() = default;

vtkImageData* vtkUltrasoundVolumeSweep::GetMaskOutput()
{
  return vtkImageData::SafeDownCast(this->GetOutputDataObject(1));
}

int vtkUltrasoundVolumeSweep::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkInformation* inInfo = inputVector[0]->GetInformationObject(0);
  int extent[6];
  double spacing[3] = { 1, 1, 1 };
  inInfo->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent);
  if (inInfo->Has(vtkDataObject::SPACING()))
  {
    inInfo->Get(vtkDataObject::SPACING(), spacing);
  }
  const int dims[3] = { extent[1] - extent[0] + 1, extent[3] - extent[2] + 1, extent[5] - extent[4] + 1 };
  SweepGeometry g;
  const std::string error = LayOut(dims, spacing, this->Protocol, this->SweepAxis, this->NumberOfFrames, this->Offset,
    this->MaximumTiltAngle, this->PixelSpacing, g);
  if (!error.empty())
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  this->FrameSize[0] = g.Width;
  this->FrameSize[1] = g.Height;
  this->SliceSpacing = g.Delta;
  const int outExtent[6] = { 0, g.Width - 1, 0, g.Height - 1, 0, this->NumberOfFrames - 1 };
  const double unit[3] = { 1, 1, 1 }, zero[3] = { 0, 0, 0 };
  for (int port = 0; port < 2; ++port)
  {
    vtkInformation* outInfo = outputVector->GetInformationObject(port);
    outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), outExtent, 6);
    outInfo->Set(vtkDataObject::SPACING(), unit, 3);
    outInfo->Set(vtkDataObject::ORIGIN(), zero, 3);
    vtkDataObject::SetPointDataActiveScalarInfo(outInfo, port == 0 ? this->OutputScalarType : VTK_UNSIGNED_CHAR, 1);
  }
  return 1;
}

int vtkUltrasoundVolumeSweep::RequestUpdateExtent(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector*)
{
  // Every slice of the volume may be sampled, whatever part of the sweep is asked for.
  bigus::RequestWholeExtent(inputVector[0]);
  return 1;
}

int vtkUltrasoundVolumeSweep::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  const auto start = std::chrono::steady_clock::now();
  vtkImageData* input = vtkImageData::GetData(inputVector[0], 0);
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  vtkImageData* maskOutput = vtkImageData::GetData(outputVector, 1);
  int dims[3];
  input->GetDimensions(dims);
  SweepGeometry g;
  const std::string error = LayOut(dims, input->GetSpacing(), this->Protocol, this->SweepAxis, this->NumberOfFrames,
    this->Offset, this->MaximumTiltAngle, this->PixelSpacing, g);
  if (!error.empty())
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  const std::vector<std::array<double, 16>> poses =
    Poses(input, g, this->Protocol, this->NumberOfFrames, this->Offset, this->MaximumTiltAngle, this->Seed);

  vtkNew<vtkImageData> volume;
  volume->ShallowCopy(input);
  vtkNew<vtkUltrasoundSequenceReslice> reslice;
  reslice->SetInputData(volume);
  reslice->SetPoseData(PoseSequence(poses, g.Width, g.Height));
  reslice->SetInterpolationMode(this->InterpolationMode);
  reslice->SetMaskEmptyVoxels(this->MaskEmptyVoxels);
  reslice->SetOutputScalarType(this->OutputScalarType);
  reslice->BorderOn();
  std::string resliceError;
  vtkNew<vtkCallbackCommand> onError;
  onError->SetCallback(KeepError);
  onError->SetClientData(&resliceError);
  reslice->AddObserver(vtkCommand::ErrorEvent, onError);
  // The executive's "returned failure" would repeat the reslice's error; this filter reports it once.
  reslice->GetExecutive()->AddObserver(vtkCommand::ErrorEvent, onError);
  vtkNew<vtkCallbackCommand> onProgress;
  onProgress->SetCallback(ForwardProgress);
  onProgress->SetClientData(this);
  reslice->AddObserver(vtkCommand::ProgressEvent, onProgress);
  reslice->Update();
  if (!resliceError.empty())
  {
    vtkErrorMacro("sampling the volume failed: " << resliceError);
    return 0;
  }
  output->ShallowCopy(reslice->GetOutput());
  maskOutput->ShallowCopy(reslice->GetMaskOutput());
  this->SecondsToBuild = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return 1;
}

void vtkUltrasoundVolumeSweep::PrintSelf(ostream& os, vtkIndent indent)
{
  static const char* const protocols[] = { "Parallel", "Oblique", "Orthogonal" };
  this->Superclass::PrintSelf(os, indent);
  os << indent << "Protocol: "
     << (this->Protocol >= PARALLEL && this->Protocol <= ORTHOGONAL ? protocols[this->Protocol] : "(invalid)") << "\n";
  os << indent << "SweepAxis: " << this->SweepAxis << "\n";
  os << indent << "NumberOfFrames: " << this->NumberOfFrames << "\n";
  os << indent << "Offset: " << this->Offset << "\n";
  os << indent << "MaximumTiltAngle: " << this->MaximumTiltAngle << " degrees\n";
  os << indent << "Seed: " << this->Seed << "\n";
  os << indent << "PixelSpacing: " << this->PixelSpacing << (this->PixelSpacing > 0 ? " mm" : " (the volume's)")
     << "\n";
  os << indent << "InterpolationMode: " << (this->InterpolationMode == 1 ? "Linear" : "NearestNeighbor") << "\n";
  os << indent << "MaskEmptyVoxels: " << (this->MaskEmptyVoxels ? "On" : "Off") << "\n";
  os << indent << "OutputScalarType: " << vtkImageScalarTypeNameMacro(this->OutputScalarType) << "\n";
  os << indent << "FrameSize: " << this->FrameSize[0] << " x " << this->FrameSize[1] << " pixels\n";
  os << indent << "SliceSpacing: " << this->SliceSpacing << " mm\n";
  os << indent << "SecondsToBuild: " << this->SecondsToBuild << "\n";
}
