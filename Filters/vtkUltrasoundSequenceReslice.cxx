#include "vtkUltrasoundSequenceReslice.h"

#include "bigusGaussianFieldData.h"
#include "bigusPipeline.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkMatrix3x3.h"
#include "vtkMatrix4x4.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkSMPTools.h"
#include "vtkUnsignedCharArray.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkUltrasoundSequenceReslice);
vtkCxxSetObjectMacro(vtkUltrasoundSequenceReslice, FrameList, vtkIdList);

namespace
{
/// Distance (voxels) within which a sample counts as lying on a voxel plane or on the bounds.
constexpr double SnapTolerance = 1e-6;
/// Frames sampled between two progress reports.
constexpr int FramesPerProgressStep = 8;

/// Trilinear support of a continuous index x along an axis of `dim` voxels: first voxel i0 and the
/// weight f of voxel i0 + 1 (f = 0: only i0 is read). x is clamped to the voxel centres, which
/// extends the edge voxels over the border.
inline void Support(double x, int dim, int& i0, double& f)
{
  x = std::min(std::max(x, 0.0), double(dim - 1));
  const double base = std::floor(x);
  i0 = static_cast<int>(base);
  f = x - base;
  if (f < SnapTolerance)
  {
    f = 0;
  }
  else if (f > 1 - SnapTolerance)
  {
    ++i0;
    f = 0;
  }
}

/// What the sampler needs besides the voxels (shared by every scalar type).
struct SamplerSettings
{
  const unsigned char* Filled; // [d2, d1, d0] non-zero = voxel holds data; null: non-zero scalars
  int Dims[3];                 // d0, d1, d2 voxels
  bool Linear;
  bool MaskEmpty;
  double Lower;                // lowest accepted continuous index (all axes)
  double Upper[3];             // highest accepted continuous index per axis
  double Scale;                // volume units -> intensity
  const double* Maps;          // [M, 3, 3] continuous index = map * (i, j, 1)
  const unsigned char* Usable; // [M] frame has a valid pose
  int Width, Height;
  float* Values;       // [M, H, W] intensities
  unsigned char* Mask; // [M, H, W] FanMask
};

/// Samples rows of frames; row r is row r % Height of output frame r / Height.
template <typename T>
struct FrameSampler : SamplerSettings
{
  const T* Scalars; // [d2, d1, d0] volume scalars

  void operator()(vtkIdType begin, vtkIdType end) const
  {
    for (vtkIdType row = begin; row < end; ++row)
    {
      const vtkIdType k = row / this->Height;
      const double j = static_cast<double>(row % this->Height);
      float* value = this->Values + row * this->Width;
      unsigned char* mask = this->Mask + row * this->Width;
      if (!this->Usable[k])
      {
        std::fill(value, value + this->Width, 0.0f);
        std::fill(mask, mask + this->Width, 0);
        continue;
      }
      const double* m = this->Maps + 9 * k;
      for (int i = 0; i < this->Width; ++i)
      {
        double x[3];
        bool inside = true;
        for (int a = 0; a < 3; ++a)
        {
          x[a] = m[3 * a] * i + m[3 * a + 1] * j + m[3 * a + 2];
          inside = inside && x[a] >= this->Lower - SnapTolerance && x[a] <= this->Upper[a] + SnapTolerance;
        }
        if (!inside)
        {
          value[i] = 0;
          mask[i] = 0;
          continue;
        }
        bool filled = true;
        const double sample = this->Linear ? this->Trilinear(x, filled) : this->Nearest(x, filled);
        value[i] = static_cast<float>(this->Scale * sample);
        mask[i] = (!this->MaskEmpty || filled) ? 1 : 0;
      }
    }
  }

  bool HasData(vtkIdType id, T v) const { return this->Filled ? this->Filled[id] != 0 : v != T(0); }

  double Nearest(const double x[3], bool& filled) const
  {
    vtkIdType id = 0, stride = 1;
    for (int a = 0; a < 3; ++a)
    {
      const int n = std::min(std::max(static_cast<int>(std::floor(x[a] + 0.5)), 0), this->Dims[a] - 1);
      id += n * stride;
      stride *= this->Dims[a];
    }
    const T v = this->Scalars[id];
    filled = this->HasData(id, v);
    return static_cast<double>(v);
  }

  double Trilinear(const double x[3], bool& filled) const
  {
    int i0[3];
    double f[3];
    for (int a = 0; a < 3; ++a)
    {
      Support(x[a], this->Dims[a], i0[a], f[a]);
    }
    const vtkIdType row = this->Dims[0], slice = vtkIdType(this->Dims[0]) * this->Dims[1];
    const vtkIdType base = i0[0] + i0[1] * row + i0[2] * slice;
    double sum = 0;
    // Only voxels with a non-zero weight are read, so a sample on a voxel plane sees that plane only.
    for (int c = 0; c < (f[2] > 0 ? 2 : 1); ++c)
    {
      const double wz = c ? f[2] : 1 - f[2];
      for (int b = 0; b < (f[1] > 0 ? 2 : 1); ++b)
      {
        const double wy = wz * (b ? f[1] : 1 - f[1]);
        for (int a = 0; a < (f[0] > 0 ? 2 : 1); ++a)
        {
          const vtkIdType id = base + a + b * row + c * slice;
          const T v = this->Scalars[id];
          sum += wy * (a ? f[0] : 1 - f[0]) * static_cast<double>(v);
          filled = filled && this->HasData(id, v);
        }
      }
    }
    return sum;
  }
};

/// Samples `count` frames of `height` rows, a few frames at a time so that progress is reported and
/// an abort is honoured between them.
template <typename T>
void SampleFrames(const SamplerSettings& settings, const T* scalars, int count, vtkAlgorithm* algorithm)
{
  FrameSampler<T> sampler;
  static_cast<SamplerSettings&>(sampler) = settings;
  sampler.Scalars = scalars;
  for (int first = 0; first < count && !algorithm->GetAbortExecute(); first += FramesPerProgressStep)
  {
    const int last = std::min(count, first + FramesPerProgressStep);
    vtkSMPTools::For(vtkIdType(first) * settings.Height, vtkIdType(last) * settings.Height, sampler);
    algorithm->UpdateProgress(double(last) / count);
  }
}

bool AllFinite(const double* values, int count)
{
  return std::all_of(values, values + count, [](double v) { return std::isfinite(v); });
}
}

vtkUltrasoundSequenceReslice::vtkUltrasoundSequenceReslice()
{
  this->SetNumberOfInputPorts(2);
  this->SetNumberOfOutputPorts(2);
}

vtkUltrasoundSequenceReslice::~vtkUltrasoundSequenceReslice()
{
  this->SetFrameList(nullptr);
  this->SetValidityArrayName(nullptr);
}

vtkImageData* vtkUltrasoundSequenceReslice::GetMaskOutput()
{
  return vtkImageData::SafeDownCast(this->GetOutputDataObject(1));
}

vtkMTimeType vtkUltrasoundSequenceReslice::GetMTime()
{
  const vtkMTimeType own = this->Superclass::GetMTime();
  return this->FrameList ? std::max(own, this->FrameList->GetMTime()) : own;
}

int vtkUltrasoundSequenceReslice::FillInputPortInformation(int, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkImageData");
  return 1;
}

int vtkUltrasoundSequenceReslice::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  for (int port = 0; port < 2; ++port)
  {
    bigus::SetFrameSequenceInformation(inputVector[1]->GetInformationObject(0), this->FrameList,
      port == 0 ? this->OutputScalarType : VTK_UNSIGNED_CHAR, outputVector->GetInformationObject(port));
  }
  return 1;
}

int vtkUltrasoundSequenceReslice::RequestUpdateExtent(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector*)
{
  // Any frame may reach any voxel; the poses come with the whole sequence.
  bigus::RequestWholeExtent(inputVector, 2);
  return 1;
}

int vtkUltrasoundSequenceReslice::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkImageData* volume = vtkImageData::GetData(inputVector[0], 0);
  vtkImageData* sequence = vtkImageData::GetData(inputVector[1], 0);
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  vtkImageData* maskOutput = vtkImageData::GetData(outputVector, 1);
  if (this->OutputScalarType != VTK_FLOAT && this->OutputScalarType != VTK_UNSIGNED_CHAR)
  {
    vtkErrorMacro("OutputScalarType must be VTK_FLOAT or VTK_UNSIGNED_CHAR, not " << this->OutputScalarType);
    return 0;
  }

  // The volume: 3D, one scalar component, an invertible index-to-physical map.
  int dims[3];
  volume->GetDimensions(dims);
  if (dims[0] < 2 || dims[1] < 2 || dims[2] < 2)
  {
    vtkErrorMacro("input 0 must be a 3D volume with at least 2 voxels along every axis, not "
      << dims[0] << " x " << dims[1] << " x " << dims[2]);
    return 0;
  }
  vtkDataArray* scalars = volume->GetPointData()->GetScalars();
  if (!scalars || scalars->GetNumberOfComponents() != 1 ||
    scalars->GetNumberOfTuples() != vtkIdType(dims[0]) * dims[1] * dims[2])
  {
    vtkErrorMacro("input 0 must have one-component point scalars for its " << dims[0] << " x " << dims[1] << " x "
                                                                           << dims[2] << " voxels");
    return 0;
  }
  double indexToPhysical[16], physicalToIndex[16];
  vtkImageData::ComputeIndexToPhysicalMatrix(
    volume->GetOrigin(), volume->GetSpacing(), volume->GetDirectionMatrix()->GetData(), indexToPhysical);
  const double determinant = vtkMatrix4x4::Determinant(indexToPhysical);
  if (!std::isfinite(determinant) || std::abs(determinant) < 1e-12 || !AllFinite(indexToPhysical, 16))
  {
    vtkErrorMacro("input 0 has a singular or non-finite geometry (spacing and direction matrix)");
    return 0;
  }
  vtkMatrix4x4::Invert(indexToPhysical, physicalToIndex);
  // The index of the first voxel is the extent's minimum, not 0.
  const int* volumeExtent = volume->GetExtent();
  for (int a = 0; a < 3; ++a)
  {
    physicalToIndex[4 * a + 3] -= volumeExtent[2 * a];
  }
  std::vector<unsigned char> filledCopy;
  const unsigned char* filled = nullptr;
  if (this->MaskEmptyVoxels && this->ValidityArrayName && *this->ValidityArrayName)
  {
    vtkDataArray* validity = volume->GetPointData()->GetArray(this->ValidityArrayName);
    if (!validity || validity->GetNumberOfTuples() != scalars->GetNumberOfTuples())
    {
      vtkErrorMacro("input 0 has no point-data array '" << this->ValidityArrayName << "' with one value per voxel");
      return 0;
    }
    filledCopy.resize(validity->GetNumberOfTuples());
    for (vtkIdType v = 0; v < validity->GetNumberOfTuples(); ++v)
    {
      filledCopy[v] = validity->GetComponent(v, 0) != 0;
    }
    filled = filledCopy.data();
  }

  // The poses.
  int poseDims[3];
  sequence->GetDimensions(poseDims);
  const int frameCount = sequence->GetNumberOfPoints() > 0 ? poseDims[2] : 0;
  vtkDataArray* poses = sequence->GetFieldData()->GetArray("ImageToReference");
  if (frameCount < 1)
  {
    vtkErrorMacro("input 1 (the pose sequence) has no frames");
    return 0;
  }
  if (!poses || poses->GetNumberOfComponents() != 16 || poses->GetNumberOfTuples() != frameCount)
  {
    vtkErrorMacro("input 1 must be a tracked frame sequence with ImageToReference (" << frameCount << " x 16)");
    return 0;
  }
  std::vector<vtkIdType> frames;
  std::string error;
  if (!bigus::ChosenFrames(this->FrameList, frameCount, frames, &error))
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  const int count = static_cast<int>(frames.size());
  vtkDataArray* frameValid = sequence->GetFieldData()->GetArray("FrameValid");
  if (frameValid && frameValid->GetNumberOfTuples() != frameCount)
  {
    frameValid = nullptr;
  }
  std::vector<double> maps(9 * std::size_t(count));
  std::vector<unsigned char> usable(count);
  for (int k = 0; k < count; ++k)
  {
    double pose[16], map[16];
    poses->GetTuple(frames[k], pose);
    usable[k] = !frameValid || frameValid->GetComponent(frames[k], 0) != 0;
    if (usable[k] && !AllFinite(pose, 16))
    {
      vtkErrorMacro("frame " << frames[k] << " has a non-finite ImageToReference");
      return 0;
    }
    // Continuous voxel index of pixel (i, j): rows of physicalToIndex * pose applied to (i, j, 0, 1).
    vtkMatrix4x4::Multiply4x4(physicalToIndex, pose, map);
    for (int a = 0; a < 3; ++a)
    {
      maps[9 * k + 3 * a] = map[4 * a];
      maps[9 * k + 3 * a + 1] = map[4 * a + 1];
      maps[9 * k + 3 * a + 2] = map[4 * a + 3];
    }
  }

  const int width = poseDims[0], height = poseDims[1];
  const std::size_t frameSize = std::size_t(width) * height;
  std::vector<float> values(frameSize * count);
  auto mask = vtkSmartPointer<vtkUnsignedCharArray>::New();
  mask->SetName("FanMask");
  mask->SetNumberOfTuples(static_cast<vtkIdType>(frameSize * count));
  const double border = this->Border ? 0.5 : 0.0;
  SamplerSettings settings;
  settings.Filled = filled;
  std::copy(dims, dims + 3, settings.Dims);
  settings.Linear = this->InterpolationMode == LINEAR;
  settings.MaskEmpty = this->MaskEmptyVoxels;
  settings.Lower = -border;
  for (int a = 0; a < 3; ++a)
  {
    settings.Upper[a] = dims[a] - 1 + border;
  }
  // The project's intensity convention: 8-bit intensities are v / 255 (DESIGN section 9).
  settings.Scale = scalars->GetDataType() == VTK_UNSIGNED_CHAR ? 1.0 / 255.0 : 1.0;
  settings.Maps = maps.data();
  settings.Usable = usable.data();
  settings.Width = width;
  settings.Height = height;
  settings.Values = values.data();
  settings.Mask = mask->GetPointer(0);
  bool sampled = false;
  switch (scalars->GetDataType())
  {
    vtkTemplateMacro(SampleFrames(settings, static_cast<const VTK_TT*>(scalars->GetVoidPointer(0)), count, this);
                     sampled = true);
  }
  if (!sampled)
  {
    vtkErrorMacro("input 0 has an unsupported scalar type " << scalars->GetDataTypeAsString());
    return 0;
  }

  for (vtkImageData* image : { output, maskOutput })
  {
    image->SetExtent(0, width - 1, 0, height - 1, 0, count - 1);
    image->SetSpacing(1, 1, 1);
    image->SetOrigin(0, 0, 0);
  }
  output->GetPointData()->SetScalars(bigus::IntensityArray(values, this->OutputScalarType));
  maskOutput->GetPointData()->SetScalars(mask);

  bigus::CopyFrameFieldData(sequence->GetFieldData(), frameCount, frames, output->GetFieldData());
  return 1;
}

void vtkUltrasoundSequenceReslice::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "FrameList: " << (this->FrameList ? this->FrameList->GetNumberOfIds() : 0) << " frames\n";
  os << indent << "InterpolationMode: " << (this->InterpolationMode == LINEAR ? "Linear" : "NearestNeighbor") << "\n";
  os << indent << "MaskEmptyVoxels: " << (this->MaskEmptyVoxels ? "On" : "Off") << "\n";
  os << indent << "ValidityArrayName: " << (this->ValidityArrayName ? this->ValidityArrayName : "(none)") << "\n";
  os << indent << "Border: " << (this->Border ? "On" : "Off") << "\n";
  os << indent << "OutputScalarType: " << vtkImageScalarTypeNameMacro(this->OutputScalarType) << "\n";
}
