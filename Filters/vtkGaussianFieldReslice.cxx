#include "vtkGaussianFieldReslice.h"

#include "bigusGaussianFieldData.h"
#include "bigusPointRenderer.h"
#include "bigusRenderer.h"
#include "bigusTrainingEngine.h"

#include "vtkAbstractImageInterpolator.h"
#include "vtkAbstractTransform.h"
#include "vtkExecutive.h"
#include "vtkFloatArray.h"
#include "vtkGeneralTransform.h"
#include "vtkHomogeneousTransform.h"
#include "vtkImageData.h"
#include "vtkImageStencilData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPerspectiveTransform.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkSMPTools.h"
#include "vtkStreamingDemandDrivenPipeline.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkGaussianFieldReslice);
vtkCxxSetObjectMacro(vtkGaussianFieldReslice, ResliceAxes, vtkMatrix4x4);
vtkCxxSetObjectMacro(vtkGaussianFieldReslice, InformationInput, vtkImageData);
vtkCxxSetObjectMacro(vtkGaussianFieldReslice, ResliceTransform, vtkAbstractTransform);
vtkCxxSetObjectMacro(vtkGaussianFieldReslice, Interpolator, vtkAbstractImageInterpolator);

namespace
{
/// An output grid in the reslice frame (mm, voxel indices).
struct Grid
{
  double Spacing[3];
  double Origin[3];
  int Extent[6];

  bool IsEmpty() const
  {
    return this->Extent[1] < this->Extent[0] || this->Extent[3] < this->Extent[2] || this->Extent[5] < this->Extent[4];
  }
  std::string ExtentText() const
  {
    std::string text;
    for (int k = 0; k < 6; ++k)
    {
      text += (k ? " " : "") + std::to_string(this->Extent[k]);
    }
    return text;
  }
};

/// Which parts of the grid take their default (vtkGaussianFieldReslice's Compute flags).
struct Computed
{
  bool Spacing[3], Origin, Extent;
  bool Any() const { return this->Spacing[0] || this->Spacing[1] || this->Spacing[2] || this->Origin || this->Extent; }
};

/// The voxel index @p index held within int (NaN as the largest): a grid too large to render is refused by RequestData
/// with the memory it needs, a bad spacing with its own error.
int HeldIndex(double index)
{
  const double largest = VTK_INT_MAX - 1;
  return index >= -largest && index <= largest ? static_cast<int>(index)
                                               : (index < 0 ? -VTK_INT_MAX + 1 : VTK_INT_MAX - 1);
}

/// @p axes (null: identity) as a matrix, and its inverse.
void AxesAndInverse(vtkMatrix4x4* axes, vtkMatrix4x4* matrix, vtkMatrix4x4* inverse)
{
  if (axes)
  {
    matrix->DeepCopy(axes);
  }
  vtkMatrix4x4::Invert(matrix, inverse);
}

/// The bounds in the reslice frame (inverse of the axes @p inverse) of the world box @p world.
void BoxInFrame(const double world[6], vtkMatrix4x4* inverse, double lo[3], double hi[3])
{
  for (int k = 0; k < 3; ++k)
  {
    lo[k] = VTK_DOUBLE_MAX;
    hi[k] = -VTK_DOUBLE_MAX;
  }
  for (int c = 0; c < 8; ++c)
  {
    double p[4] = { 0, 0, 0, 1 }, q[4];
    for (int k = 0; k < 3; ++k)
    {
      p[k] = world[2 * k + ((c >> k) & 1)];
    }
    inverse->MultiplyPoint(p, q);
    for (int k = 0; k < 3; ++k)
    {
      lo[k] = std::min(lo[k], q[k]);
      hi[k] = std::max(hi[k], q[k]);
    }
  }
}

/// The box that holds the field's footprint, as x0 x1 y0 y1 z0 z1 (mm): the means' bounds padded by three times the
/// largest scale. The field's default grid covers it; BackgroundColor fills the samples outside it.
void PaddedFieldBox(const bigus::FieldCache& field, double box[6])
{
  const double* bounds = field.GetBounds();
  const double pad = 3 * field.GetLargestScale();
  for (int k = 0; k < 6; ++k)
  {
    box[k] = bounds[k] + (k % 2 ? pad : -pad);
  }
}

/**
 * The field's defaults for the computed parts of @p g: spacing = PixelSpacing or 0.5 mm; origin and extent = the
 * means' bounds padded by three times the largest scale, in the reslice frame of @p axes (null = identity).
 */
void FieldDefaults(Grid& g, const Computed& computed, const bigus::FieldCache& field, vtkMatrix4x4* axes)
{
  const double step = field.GetModel().PixelSpacing > 0 ? field.GetModel().PixelSpacing : 0.5;
  double world[6];
  PaddedFieldBox(field, world);
  vtkNew<vtkMatrix4x4> matrix, inverse;
  AxesAndInverse(axes, matrix, inverse);
  double lo[3], hi[3];
  BoxInFrame(world, inverse, lo, hi);
  for (int k = 0; k < 3; ++k)
  {
    g.Spacing[k] = computed.Spacing[k] ? step : g.Spacing[k];
    g.Origin[k] = computed.Origin ? lo[k] : g.Origin[k];
    if (computed.Extent)
    {
      g.Extent[2 * k] = 0;
      g.Extent[2 * k + 1] = HeldIndex(std::ceil((hi[k] - g.Origin[k]) / g.Spacing[k]));
    }
  }
}

/**
 * vtkImageReslice's defaults for the computed parts of @p g with @p image as its input (its RequestInformation):
 * the image's spacing, extent and centre carried into the reslice frame of @p axes, each output axis taking the
 * input axes it is made of weighted by the squared direction cosines (TransformInputSampling; without it, the
 * image's own), the extent rounded from the first index's image and the length, the origin centring the extent on
 * the image's centre (without TransformInputSampling: the image's origin); with AutoCropOutput the extent and origin
 * cover the image's box in the frame.
 */
void ImageDefaults(
  Grid& g, const Computed& computed, vtkImageData* image, vtkMatrix4x4* axes, bool transformSampling, bool autoCrop)
{
  int inExtent[6];
  double inSpacing[3], inOrigin[3];
  image->GetExtent(inExtent);
  image->GetSpacing(inSpacing);
  image->GetOrigin(inOrigin);
  vtkNew<vtkMatrix4x4> matrix, inverse;
  AxesAndInverse(axes, matrix, inverse);
  double centre[4] = { 0, 0, 0, 1 }, world[6];
  for (int j = 0; j < 3; ++j)
  {
    const double a = inOrigin[j] + inExtent[2 * j] * inSpacing[j], b = inOrigin[j] + inExtent[2 * j + 1] * inSpacing[j];
    centre[j] = 0.5 * (a + b);
    world[2 * j] = std::min(a, b);
    world[2 * j + 1] = std::max(a, b);
  }
  double c[4], lo[3], hi[3];
  inverse->MultiplyPoint(centre, c);
  BoxInFrame(world, inverse, lo, hi);
  for (int i = 0; i < 3; ++i)
  {
    double s = inSpacing[i], d = (inExtent[2 * i + 1] - inExtent[2 * i]) * inSpacing[i], e = inExtent[2 * i];
    if (transformSampling)
    {
      double r = 0;
      s = d = e = 0;
      for (int j = 0; j < 3; ++j)
      {
        const double w = matrix->GetElement(j, i) * matrix->GetElement(j, i);
        s += w * std::fabs(inSpacing[j]);
        d += w * (inExtent[2 * j + 1] - inExtent[2 * j]) * std::fabs(inSpacing[j]);
        e += w * inExtent[2 * j];
        r += w;
      }
      s /= r;
      d /= r * std::sqrt(r);
      e /= r;
    }
    g.Spacing[i] = computed.Spacing[i] ? s : g.Spacing[i];
    if (computed.Extent)
    {
      d = autoCrop ? hi[i] - lo[i] : d;
      g.Extent[2 * i] = HeldIndex(std::floor(e + 0.5));
      g.Extent[2 * i + 1] = HeldIndex(std::floor(g.Extent[2 * i] + std::fabs(d / g.Spacing[i]) + 0.5));
    }
    if (computed.Origin)
    {
      g.Origin[i] = autoCrop ? lo[i] - g.Extent[2 * i] * g.Spacing[i]
        : transformSampling  ? c[i] - 0.5 * (g.Extent[2 * i] + g.Extent[2 * i + 1]) * g.Spacing[i]
                             : inOrigin[i];
    }
  }
}

/**
 * The matrix of the sampling grid's frame into @p frame: ResliceTransform's matrix times ResliceAxes. Returns whether
 * the grid stays planar: false for a transform that is not homogeneous, or a perspective bottom row (the samples are
 * then rendered point by point, and @p frame is not used).
 */
bool FrameMatrix(vtkMatrix4x4* axes, vtkAbstractTransform* transform, vtkMatrix4x4* frame)
{
  if (axes)
  {
    frame->DeepCopy(axes);
  }
  auto* linear = vtkHomogeneousTransform::SafeDownCast(transform);
  if (transform && !linear)
  {
    return false;
  }
  if (linear)
  {
    linear->Update();
    vtkMatrix4x4::Multiply4x4(linear->GetMatrix(), frame, frame);
  }
  const double* m = frame->GetData();
  return m[12] == 0 && m[13] == 0 && m[14] == 0 && m[15] == 1;
}

/**
 * The map of a bent grid from the output's (continuous) voxel index to mm: ResliceAxes (a 4x4 that may have a
 * perspective row) times the grid (origin + index x spacing), then ResliceTransform; updated, so that its
 * InternalTransformDerivative may run on many threads.
 */
vtkSmartPointer<vtkGeneralTransform> IndexToReference(
  vtkMatrix4x4* axes, vtkAbstractTransform* transform, const double spacing[3], const double origin[3])
{
  vtkNew<vtkMatrix4x4> grid, indexToWorld;
  for (int k = 0; k < 3; ++k)
  {
    grid->SetElement(k, k, spacing[k]);
    grid->SetElement(k, 3, origin[k]);
  }
  if (axes)
  {
    vtkMatrix4x4::Multiply4x4(axes, grid, indexToWorld);
  }
  else
  {
    indexToWorld->DeepCopy(grid);
  }
  vtkNew<vtkPerspectiveTransform> first;
  first->SetMatrix(indexToWorld);
  auto chain = vtkSmartPointer<vtkGeneralTransform>::New();
  chain->PostMultiply();
  chain->Concatenate(first);
  if (transform)
  {
    chain->Concatenate(transform);
  }
  chain->Update();
  return chain;
}

/// The samples of slice k of @p extent of a bent grid, @p offset voxels along the grid's z: each at its point with
/// the derivatives of the point along i and j as its pixel axes.
void BentSlice(vtkGeneralTransform* indexToReference, const int extent[6], int k, double offset,
  std::vector<bigus::PointSample>& samples)
{
  const int W = extent[1] - extent[0] + 1;
  samples.resize(std::size_t(W) * (extent[3] - extent[2] + 1));
  vtkSMPTools::For(0, static_cast<vtkIdType>(samples.size()), 1024, [&](vtkIdType begin, vtkIdType end) {
    for (vtkIdType p = begin; p < end; ++p)
    {
      const double index[3] = { double(extent[0] + p % W), double(extent[2] + p / W), extent[4] + k + offset };
      double J[3][3];
      bigus::PointSample& s = samples[p];
      indexToReference->InternalTransformDerivative(index, s.Position, J);
      for (int r = 0; r < 3; ++r)
      {
        s.PixelAxes[0][r] = J[r][0];
        s.PixelAxes[1][r] = J[r][1];
      }
    }
  });
}

/// The positions of @p samples into @p points ([n, 3] mm).
void PositionsOf(const std::vector<bigus::PointSample>& samples, std::vector<double>& points)
{
  points.resize(3 * samples.size());
  for (std::size_t p = 0; p < samples.size(); ++p)
  {
    std::copy(samples[p].Position, samples[p].Position + 3, &points[3 * p]);
  }
}

/// The points (mm) of the pixels of a planar @p slice into @p points ([H W, 3]).
void SlicePoints(const bigus::SliceGeometry& slice, std::vector<double>& points)
{
  points.resize(3 * std::size_t(slice.Width) * slice.Height);
  const double* m = slice.ImageToReference; // row-major: pixel (i, j) -> m (i, j, 0, 1)
  for (int j = 0; j < slice.Height; ++j)
  {
    for (int i = 0; i < slice.Width; ++i)
    {
      double* x = &points[3 * (std::size_t(j) * slice.Width + i)];
      for (int r = 0; r < 3; ++r)
      {
        x[r] = m[4 * r] * i + m[4 * r + 1] * j + m[4 * r + 3];
      }
    }
  }
}

/// Publishes the grid on both output ports (the image and the stencil output).
void Announce(vtkInformationVector* outputVector, const int extent[6], const double spacing[3], const double origin[3])
{
  for (int port = 0; port < outputVector->GetNumberOfInformationObjects(); ++port)
  {
    vtkInformation* info = outputVector->GetInformationObject(port);
    info->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), extent, 6);
    info->Set(vtkDataObject::SPACING(), spacing, 3);
    info->Set(vtkDataObject::ORIGIN(), origin, 3);
  }
}

/// Slice @p in of a slab, of weight @p w, into @p out ([n]) by SlabMode @p mode (@p first: the slab's first slice).
void CombineSlab(int mode, bool first, double w, const float* in, float* out, std::size_t n)
{
  for (std::size_t p = 0; p < n; ++p)
  {
    const float v = in[p];
    if (mode == VTK_IMAGE_SLAB_MIN)
    {
      out[p] = first ? v : std::min(out[p], v);
    }
    else if (mode == VTK_IMAGE_SLAB_MAX)
    {
      out[p] = first ? v : std::max(out[p], v);
    }
    else
    {
      out[p] = static_cast<float>((first ? 0.0 : out[p]) + w * v);
    }
  }
}

/// Whether each of the points @p points ([n, 3] mm) lies inside the field's PaddedFieldBox, into @p inside ([n]).
void InsideFieldBox(const bigus::FieldCache& field, const std::vector<double>& points, std::vector<char>& inside)
{
  double b[6];
  PaddedFieldBox(field, b);
  inside.resize(points.size() / 3);
  for (std::size_t p = 0; p < inside.size(); ++p)
  {
    const double* x = &points[3 * p];
    inside[p] = x[0] >= b[0] && x[0] <= b[1] && x[1] >= b[2] && x[1] <= b[3] && x[2] >= b[4] && x[2] <= b[5];
  }
}

/// The stencil of the samples of @p inside ([depth, H, W] of @p extent, 1 = inside) into @p stencil.
void StencilOf(const std::vector<char>& inside, const int extent[6], const double spacing[3], const double origin[3],
  vtkImageStencilData* stencil)
{
  stencil->SetExtent(extent);
  stencil->SetSpacing(spacing);
  stencil->SetOrigin(origin);
  stencil->AllocateExtents();
  const int W = extent[1] - extent[0] + 1;
  std::size_t p = 0;
  for (int z = extent[4]; z <= extent[5]; ++z)
  {
    for (int y = extent[2]; y <= extent[3]; ++y, p += W)
    {
      for (int i = 0; i < W; ++i)
      {
        if (inside[p + i] && (i == 0 || !inside[p + i - 1]))
        {
          int last = i;
          while (last + 1 < W && inside[p + last + 1])
          {
            ++last;
          }
          stencil->InsertNextExtent(extent[0] + i, extent[0] + last, y, z);
        }
      }
    }
  }
}

/// Pose of slice k of @p extent, @p offset mm along its normal: pixel (i, j) -> frame * (origin + (extent[0] + i,
/// extent[2] + j, extent[4] + k) * spacing + (0, 0, offset)), with the low-pass @p pixelLowPass (pixels^2).
bigus::SliceGeometry SliceAt(vtkMatrix4x4* frame, const double spacing[3], const double origin[3], const int extent[6],
  int k, double offset, double pixelLowPass)
{
  vtkNew<vtkMatrix4x4> grid, pose;
  grid->SetElement(0, 0, spacing[0]);
  grid->SetElement(1, 1, spacing[1]);
  grid->SetElement(0, 3, origin[0] + extent[0] * spacing[0]);
  grid->SetElement(1, 3, origin[1] + extent[2] * spacing[1]);
  grid->SetElement(2, 3, origin[2] + (extent[4] + k) * spacing[2] + offset);
  vtkMatrix4x4::Multiply4x4(frame, grid, pose);
  bigus::SliceGeometry slice;
  std::copy(pose->GetData(), pose->GetData() + 16, slice.ImageToReference);
  slice.Width = extent[1] - extent[0] + 1;
  slice.Height = extent[3] - extent[2] + 1;
  slice.PixelLowPass = pixelLowPass;
  return slice;
}
}

/**
 * The output grid of @p self: its settings where set, for the computed parts an InformationInput's defaults
 * (ImageDefaults) or the field's (FieldDefaults, the field @p input holds converted into @p field only then), and
 * OutputDimensionality's zeroed axes. Returns false when the field's defaults are needed and @p input holds no valid
 * field.
 */
bool vtkGaussianFieldReslice::ComputeOutputGrid(vtkPolyData* input, double spacing[3], double origin[3], int extent[6])
{
  bigus::FieldCache& field = this->GetFieldCache();
  Grid g;
  std::copy(this->OutputSpacing, this->OutputSpacing + 3, g.Spacing);
  std::copy(this->OutputOrigin, this->OutputOrigin + 3, g.Origin);
  std::copy(this->OutputExtent, this->OutputExtent + 6, g.Extent);
  const Computed computed{ { this->ComputeOutputSpacing[0], this->ComputeOutputSpacing[1],
                             this->ComputeOutputSpacing[2] },
    this->ComputeOutputOrigin, this->ComputeOutputExtent };
  if (this->InformationInput)
  {
    ImageDefaults(g, computed, this->InformationInput, this->ResliceAxes, this->TransformInputSampling != 0,
      this->AutoCropOutput != 0);
  }
  else if (computed.Any())
  {
    if (!field.Update(input, nullptr))
    {
      return false;
    }
    FieldDefaults(g, computed, field, this->ResliceAxes);
  }
  for (int i = std::max(0, this->OutputDimensionality); i < 3; ++i)
  {
    g.Extent[2 * i] = g.Extent[2 * i + 1] = 0;
    g.Origin[i] = 0;
  }
  std::copy(g.Spacing, g.Spacing + 3, spacing);
  std::copy(g.Origin, g.Origin + 3, origin);
  std::copy(g.Extent, g.Extent + 6, extent);
  return true;
}

vtkGaussianFieldReslice::vtkGaussianFieldReslice()
{
  this->SetNumberOfInputPorts(2);
  this->SetNumberOfOutputPorts(2);
  this->GetResliceAxesDirectionCosines(this->ResliceAxesDirectionCosines);
  this->GetResliceAxesOrigin(this->ResliceAxesOrigin);
}

vtkGaussianFieldReslice::~vtkGaussianFieldReslice()
{
  this->SetResliceAxes(nullptr);
  this->SetResliceTransform(nullptr);
  this->SetInformationInput(nullptr);
  this->SetInterpolator(nullptr);
}

void vtkGaussianFieldReslice::SetOutputSpacing(double x, double y, double z)
{
  const double v[3] = { x, y, z };
  const bool* computed = this->ComputeOutputSpacing;
  if (computed[0] || computed[1] || computed[2] || !std::equal(v, v + 3, this->OutputSpacing))
  {
    std::copy(v, v + 3, this->OutputSpacing);
    std::fill(this->ComputeOutputSpacing, this->ComputeOutputSpacing + 3, false);
    this->Modified();
  }
}

void vtkGaussianFieldReslice::SetOutputSpacingComponents(const double spacing[3])
{
  bool changed = false;
  for (int k = 0; k < 3; ++k)
  {
    const bool compute = !(spacing[k] > 0);
    const double value = compute ? 1.0 : spacing[k];
    changed = changed || compute != this->ComputeOutputSpacing[k] || value != this->OutputSpacing[k];
    this->ComputeOutputSpacing[k] = compute;
    this->OutputSpacing[k] = value;
  }
  if (changed)
  {
    this->Modified();
  }
}

void vtkGaussianFieldReslice::SetOutputOrigin(double x, double y, double z)
{
  const double v[3] = { x, y, z };
  if (this->ComputeOutputOrigin || !std::equal(v, v + 3, this->OutputOrigin))
  {
    std::copy(v, v + 3, this->OutputOrigin);
    this->ComputeOutputOrigin = false;
    this->Modified();
  }
}

void vtkGaussianFieldReslice::SetOutputExtent(int a, int b, int c, int d, int e, int f)
{
  const int v[6] = { a, b, c, d, e, f };
  if (this->ComputeOutputExtent || !std::equal(v, v + 6, this->OutputExtent))
  {
    std::copy(v, v + 6, this->OutputExtent);
    this->ComputeOutputExtent = false;
    this->Modified();
  }
}

void vtkGaussianFieldReslice::SetOutputSpacingToDefault()
{
  const double none[3] = { 0, 0, 0 };
  this->SetOutputSpacingComponents(none);
}

void vtkGaussianFieldReslice::SetOutputOriginToDefault()
{
  if (!this->ComputeOutputOrigin)
  {
    std::fill(this->OutputOrigin, this->OutputOrigin + 3, 0.0);
    this->ComputeOutputOrigin = true;
    this->Modified();
  }
}

void vtkGaussianFieldReslice::SetOutputExtentToDefault()
{
  if (!this->ComputeOutputExtent)
  {
    std::fill(this->OutputExtent, this->OutputExtent + 6, 0);
    this->ComputeOutputExtent = true;
    this->Modified();
  }
}

void vtkGaussianFieldReslice::SetResliceAxesDirectionCosines(
  double x0, double x1, double x2, double y0, double y1, double y2, double z0, double z1, double z2)
{
  if (!this->ResliceAxes)
  {
    vtkNew<vtkMatrix4x4> axes;
    this->SetResliceAxes(axes);
  }
  const double columns[3][3] = { { x0, x1, x2 }, { y0, y1, y2 }, { z0, z1, z2 } };
  for (int c = 0; c < 3; ++c)
  {
    for (int r = 0; r < 3; ++r)
    {
      this->ResliceAxes->SetElement(r, c, columns[c][r]);
    }
  }
  this->Modified();
}

void vtkGaussianFieldReslice::GetResliceAxesDirectionCosines(double x[3], double y[3], double z[3])
{
  double* columns[3] = { x, y, z };
  for (int c = 0; c < 3; ++c)
  {
    for (int r = 0; r < 3; ++r)
    {
      columns[c][r] = this->ResliceAxes ? this->ResliceAxes->GetElement(r, c) : (r == c ? 1.0 : 0.0);
    }
  }
}

void vtkGaussianFieldReslice::SetResliceAxesOrigin(double x, double y, double z)
{
  if (!this->ResliceAxes)
  {
    vtkNew<vtkMatrix4x4> axes;
    this->SetResliceAxes(axes);
  }
  this->ResliceAxes->SetElement(0, 3, x);
  this->ResliceAxes->SetElement(1, 3, y);
  this->ResliceAxes->SetElement(2, 3, z);
  this->Modified();
}

void vtkGaussianFieldReslice::GetResliceAxesOrigin(double xyz[3])
{
  for (int r = 0; r < 3; ++r)
  {
    xyz[r] = this->ResliceAxes ? this->ResliceAxes->GetElement(r, 3) : 0.0;
  }
}

const char* vtkGaussianFieldReslice::GetSlabModeAsString()
{
  switch (this->SlabMode)
  {
    case VTK_IMAGE_SLAB_MIN:
      return "Min";
    case VTK_IMAGE_SLAB_MAX:
      return "Max";
    case VTK_IMAGE_SLAB_SUM:
      return "Sum";
    default:
      return "Mean";
  }
}

vtkMTimeType vtkGaussianFieldReslice::GetMTime()
{
  vtkMTimeType t = this->Superclass::GetMTime();
  if (this->ResliceAxes)
  {
    t = std::max(t, this->ResliceAxes->GetMTime());
  }
  if (this->ResliceTransform)
  {
    t = std::max(t, this->ResliceTransform->GetMTime());
  }
  if (this->InformationInput)
  {
    t = std::max(t, this->InformationInput->GetMTime());
  }
  return t;
}

int vtkGaussianFieldReslice::RequestInformation(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  // A default grid uses the field the input holds now (converted once and kept); RequestData corrects it if
  // the field changes in this update. An input that holds no field yet is produced first (the class description).
  Grid grid;
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  vtkDataObject::SetPointDataActiveScalarInfo(outInfo, this->OutputScalarType, 1);
  bool known = this->ComputeOutputGrid(vtkPolyData::GetData(inputVector[0], 0), grid.Spacing, grid.Origin, grid.Extent);
  int producerPort = 0;
  vtkAlgorithm* producer = known ? nullptr : this->GetInputAlgorithm(0, 0, producerPort);
  if (producer)
  {
    producer->Update(producerPort);
    known = this->ComputeOutputGrid(vtkPolyData::GetData(inputVector[0], 0), grid.Spacing, grid.Origin, grid.Extent);
  }
  if (!known)
  {
    // No field (the producer gave none, or failed): nothing to announce; RequestData reports the error.
    const int empty[6] = { 0, -1, 0, -1, 0, -1 };
    const double unit[3] = { 1, 1, 1 }, zero[3] = { 0, 0, 0 };
    Announce(outputVector, empty, unit, zero);
    return 1;
  }
  if (grid.IsEmpty())
  {
    vtkErrorMacro("empty output extent " << grid.ExtentText());
    return 0;
  }
  Announce(outputVector, grid.Extent, grid.Spacing, grid.Origin);
  return 1;
}

int vtkGaussianFieldReslice::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  vtkImageData* output = vtkImageData::GetData(outputVector, 0);
  bigus::RenderSetup render;
  if (!this->BeginRender(inputVector, render))
  {
    return 0;
  }
  const bigus::TrainingCoverage* coverage = render.Coverage;

  Grid grid;
  this->ComputeOutputGrid(vtkPolyData::GetData(inputVector[0], 0), grid.Spacing, grid.Origin, grid.Extent);
  if (grid.IsEmpty())
  {
    vtkErrorMacro("empty output extent " << grid.ExtentText());
    return 0;
  }
  const int slab = this->SlabNumberOfSlices;
  for (int k = 0; k < (this->OutputDimensionality < 3 && slab == 1 ? 2 : 3); ++k)
  {
    if (!(grid.Spacing[k] > 0) || !std::isfinite(grid.Spacing[k]))
    {
      vtkErrorMacro("OutputSpacing " << grid.Spacing[0] << " " << grid.Spacing[1] << " " << grid.Spacing[2]
                                     << ": each must be a positive, finite number of mm");
      return 0;
    }
  }
  int extent[6], announced[6];
  double announcedSpacing[3], announcedOrigin[3];
  outInfo->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), announced);
  outInfo->Get(vtkDataObject::SPACING(), announcedSpacing);
  outInfo->Get(vtkDataObject::ORIGIN(), announcedOrigin);
  if (std::equal(announced, announced + 6, grid.Extent) &&
    std::equal(announcedSpacing, announcedSpacing + 3, grid.Spacing) &&
    std::equal(announcedOrigin, announcedOrigin + 3, grid.Origin))
  {
    outInfo->Get(vtkStreamingDemandDrivenPipeline::UPDATE_EXTENT(), extent);
  }
  else
  {
    // A default grid from a field that was not there yet, or changed, when RequestInformation ran:
    // render the up-to-date field's whole grid and publish it (see the class description).
    std::copy(grid.Extent, grid.Extent + 6, extent);
    Announce(outputVector, grid.Extent, grid.Spacing, grid.Origin);
  }
  const int depth = extent[5] - extent[4] + 1;
  const std::size_t slicePixels = std::size_t(extent[1] - extent[0] + 1) * (extent[3] - extent[2] + 1);
  const std::size_t pixels = slicePixels * depth;

  vtkNew<vtkMatrix4x4> frame;
  const bool planar = FrameMatrix(this->ResliceAxes, this->ResliceTransform, frame);
  vtkSmartPointer<vtkGeneralTransform> bent =
    planar ? nullptr : IndexToReference(this->ResliceAxes, this->ResliceTransform, grid.Spacing, grid.Origin);
  vtkImageStencilData* stencil =
    this->GetNumberOfInputPorts() > 1 ? vtkImageStencilData::GetData(inputVector[1], 0) : nullptr;
  std::string error;
  // The stencil output's coverage: the training coverage where the field has training geometry, else none (the
  // padded bounds then).
  const bigus::TrainingCoverage* stencilCoverage = nullptr;
  if (this->GenerateStencilOutput)
  {
    stencilCoverage = render.Field->GetCoverage(&error);
    if (!stencilCoverage)
    {
      vtkErrorMacro("GenerateStencilOutput: " << error);
      return 0;
    }
    stencilCoverage = stencilCoverage->IsEmpty() ? nullptr : stencilCoverage;
  }
  // Refused before anything is allocated where the grid cannot be held: the float buffers below, the output's
  // scalars and arrays (each copied once), a slice's points and samples, against this machine's memory.
  const double samples =
    double(extent[1] - extent[0] + 1) * double(extent[3] - extent[2] + 1) * double(extent[5] - extent[4] + 1);
  const double bytes = samples *
      (2 * sizeof(float) + (this->OutputScatteringField ? 2 * sizeof(float) : 0) + (coverage ? 2 * sizeof(float) : 0) +
        (this->GenerateStencilOutput ? 1 : 0)) +
    samples / depth * (2 * sizeof(float) + 3 * sizeof(double) + (planar ? 0 : sizeof(bigus::PointSample)));
  const double physical = bigus::PhysicalMemoryBytes();
  if (physical > 0 && bytes > physical)
  {
    vtkErrorMacro("the output grid " << grid.ExtentText() << " (" << samples << " samples) needs " << bytes / 1e6
                                     << " MB and this machine has " << physical / 1e6
                                     << " MB: choose a coarser OutputSpacing or a smaller OutputExtent");
    return 0;
  }
  // A planar grid may be sheared (any angle short of parallel axes): the renderers are exact for it.
  bigus::RenderOptions options = render.Options;
  options.MaximumShearAngle = 90;
  const bigus::FieldView view = render.Field->GetField().View();
  const double unit = bigus::IntensityUnit(this->OutputScalarType);
  // S is kept whole only when it is an output; otherwise one slice of scratch.
  std::vector<float> I(pixels), S(this->OutputScatteringField ? pixels : slicePixels), C(coverage ? pixels : 0);
  // A slab's slices, each rendered into scratch and combined (SlabMode) into the output slice.
  std::vector<float> slabI(slab > 1 ? slicePixels : 0), slabS(slabI.size()), slabC(coverage ? slabI.size() : 0);
  std::vector<bigus::PointSample> bentSamples;
  std::vector<double> points;          // the output slice's sample points (mm)
  std::vector<char> inside, outInside; // of the padded bounds; of the stencil output, [depth, H, W]
  std::vector<float> stencilScratch(stencilCoverage && !(coverage && slab == 1) ? slicePixels : 0);
  outInside.resize(this->GenerateStencilOutput ? pixels : 0);
  for (int k = 0; k < depth; ++k)
  {
    if (this->GetAbortExecute())
    {
      // The output stays empty, so the pipeline does not take it for the requested extent.
      return 1;
    }
    float* i = I.data() + k * slicePixels;
    float* s = S.data() + (this->OutputScatteringField ? k * slicePixels : 0);
    float* c = coverage ? C.data() + k * slicePixels : nullptr;
    double weights = 0;
    for (int t = 0; t < slab; ++t)
    {
      const double offset = (t - 0.5 * (slab - 1)) * this->SlabSliceSpacingFraction; // voxels along z
      float* ti = slab > 1 ? slabI.data() : i;
      float* ts = slab > 1 ? slabS.data() : s;
      float* tc = slab > 1 ? slabC.data() : c;
      bool rendered;
      if (planar)
      {
        const bigus::SliceGeometry slice =
          SliceAt(frame, grid.Spacing, grid.Origin, extent, k, offset * grid.Spacing[2], this->PixelLowPass);
        rendered = render.Backend->Forward(view, &slice, 1, options, ts, ti, nullptr, &error);
        if (rendered && coverage)
        {
          coverage->Compute(slice, options.ElevationSigma, tc);
        }
      }
      else
      {
        BentSlice(bent, extent, k, offset, bentSamples);
        rendered = bigus::RenderPoints(view, bentSamples.data(), static_cast<std::int64_t>(bentSamples.size()),
          this->PixelLowPass, options, ts, ti, &error);
        if (rendered && coverage)
        {
          PositionsOf(bentSamples, points);
          coverage->ComputePoints(
            points.data(), static_cast<std::int64_t>(bentSamples.size()), options.ElevationSigma, tc);
        }
      }
      if (!rendered)
      {
        vtkErrorMacro(<< (this->ResliceTransform ? "ResliceAxes and ResliceTransform: " : "ResliceAxes: ") << error);
        return 0;
      }
      if (slab > 1)
      {
        const double w = this->SlabTrapezoidIntegration && (t == 0 || t == slab - 1) ? 0.5 : 1.0;
        CombineSlab(this->SlabMode, t == 0, w, slabI.data(), i, slicePixels);
        CombineSlab(this->SlabMode, t == 0, w, slabS.data(), s, slicePixels);
        if (coverage)
        {
          CombineSlab(this->SlabMode, t == 0, w, slabC.data(), c, slicePixels);
        }
        weights += w;
      }
    }
    if (slab > 1 && this->SlabMode == VTK_IMAGE_SLAB_MEAN)
    {
      for (float* a : { i, s, c })
      {
        for (std::size_t p = 0; a && p < slicePixels; ++p)
        {
          a[p] = static_cast<float>(a[p] / weights);
        }
      }
    }
    if (this->ScalarShift != 0 || this->ScalarScale != 1)
    {
      // In the output's units, then back to I's: IntensityArray converts with the unit, rounds and clamps.
      for (std::size_t p = 0; p < slicePixels; ++p)
      {
        i[p] = static_cast<float>((unit * i[p] + this->ScalarShift) * this->ScalarScale / unit);
      }
    }
    // The output slice's own points (no slab offset), where the background outside the field's padded bounds or the
    // stencil output needs them. A background of 0 leaves the field's own samples beyond its padded bounds (below
    // exp(-4.5) of a Gaussian).
    const float background = static_cast<float>(this->BackgroundColor[0] / unit);
    if (background != 0 || this->GenerateStencilOutput)
    {
      if (planar)
      {
        SlicePoints(SliceAt(frame, grid.Spacing, grid.Origin, extent, k, 0, 0), points);
      }
      else
      {
        if (slab > 1) // else the samples rendered are the slice's own
        {
          BentSlice(bent, extent, k, 0, bentSamples);
        }
        PositionsOf(bentSamples, points);
      }
      InsideFieldBox(*render.Field, points, inside);
    }
    for (std::size_t p = 0; background != 0 && p < slicePixels; ++p)
    {
      i[p] = inside[p] ? i[p] : background;
    }
    if (stencil)
    {
      const int W = extent[1] - extent[0] + 1;
      for (std::size_t p = 0; p < slicePixels; ++p)
      {
        const int x = extent[0] + static_cast<int>(p % W), y = extent[2] + static_cast<int>(p / W);
        i[p] = stencil->IsInside(x, y, extent[4] + k) ? i[p] : background;
      }
    }
    if (this->GenerateStencilOutput)
    {
      char* out = outInside.data() + k * slicePixels;
      if (stencilCoverage)
      {
        // The coverage output's values where this slice has them (no slab: rendered at the same points).
        const float* at = c && slab == 1 ? c : stencilScratch.data();
        if (at != c)
        {
          stencilCoverage->ComputePoints(
            points.data(), static_cast<std::int64_t>(slicePixels), options.ElevationSigma, stencilScratch.data());
        }
        for (std::size_t p = 0; p < slicePixels; ++p)
        {
          out[p] = at[p] >= this->StencilCoverageThreshold;
        }
      }
      else
      {
        std::copy(inside.begin(), inside.end(), out);
      }
    }
    this->UpdateProgress(double(k + 1) / depth);
  }
  output->SetExtent(extent);
  output->SetSpacing(grid.Spacing);
  output->SetOrigin(grid.Origin);
  output->GetPointData()->SetScalars(bigus::IntensityArray(I, this->OutputScalarType));
  if (this->OutputScatteringField)
  {
    vtkNew<vtkFloatArray> scattering;
    scattering->SetName("ScatteringField");
    scattering->SetNumberOfTuples(static_cast<vtkIdType>(pixels));
    std::copy(S.begin(), S.end(), scattering->GetPointer(0));
    output->GetPointData()->AddArray(scattering);
  }
  if (coverage)
  {
    output->GetPointData()->AddArray(bigus::CoverageArray(C));
  }
  if (this->GenerateStencilOutput && this->GetNumberOfOutputPorts() > 1)
  {
    StencilOf(outInside, extent, grid.Spacing, grid.Origin, vtkImageStencilData::GetData(outputVector, 1));
  }
  return 1;
}

void vtkGaussianFieldReslice::SetStencilData(vtkImageStencilData* stencil)
{
  this->SetInputData(1, stencil);
}

vtkImageStencilData* vtkGaussianFieldReslice::GetStencil()
{
  return this->GetNumberOfInputConnections(1) < 1
    ? nullptr
    : vtkImageStencilData::SafeDownCast(this->GetExecutive()->GetInputData(1, 0));
}

void vtkGaussianFieldReslice::SetStencilOutput(vtkImageStencilData* stencil)
{
  this->GetExecutive()->SetOutputData(1, stencil);
}

const char* vtkGaussianFieldReslice::GetInterpolationModeAsString()
{
  switch (this->InterpolationMode)
  {
    case VTK_NEAREST_INTERPOLATION:
      return "NearestNeighbor";
    case VTK_CUBIC_INTERPOLATION:
      return "Cubic";
    default:
      return "Linear";
  }
}

vtkImageStencilData* vtkGaussianFieldReslice::GetStencilOutput()
{
  return vtkImageStencilData::SafeDownCast(this->GetOutputDataObject(1));
}

vtkTypeBool vtkGaussianFieldReslice::ProcessRequest(
  vtkInformation* request, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  // The stencil output is made here: VTK 9.1's vtkDataObjectTypes cannot make a vtkImageStencilData.
  if (request->Has(vtkDemandDrivenPipeline::REQUEST_DATA_OBJECT()) && outputVector->GetNumberOfInformationObjects() > 1)
  {
    vtkInformation* info = outputVector->GetInformationObject(1);
    if (!vtkImageStencilData::SafeDownCast(info->Get(vtkDataObject::DATA_OBJECT())))
    {
      vtkNew<vtkImageStencilData> stencil;
      info->Set(vtkDataObject::DATA_OBJECT(), stencil);
    }
  }
  return this->Superclass::ProcessRequest(request, inputVector, outputVector);
}

int vtkGaussianFieldReslice::FillInputPortInformation(int port, vtkInformation* info)
{
  if (port == 1)
  {
    info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkImageStencilData");
    info->Set(vtkAlgorithm::INPUT_IS_OPTIONAL(), 1);
    return 1;
  }
  return this->Superclass::FillInputPortInformation(port, info);
}

int vtkGaussianFieldReslice::FillOutputPortInformation(int port, vtkInformation* info)
{
  if (port == 1)
  {
    info->Set(vtkDataObject::DATA_TYPE_NAME(), "vtkImageStencilData");
    return 1;
  }
  return this->Superclass::FillOutputPortInformation(port, info);
}

void vtkGaussianFieldReslice::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "ResliceAxes: " << (this->ResliceAxes ? "set" : "(identity)") << "\n";
  if (this->ResliceAxes)
  {
    this->ResliceAxes->PrintSelf(os, indent.GetNextIndent());
  }
  auto vec = [&](const char* name, const double* v, bool computed) {
    os << indent << name << ": ";
    if (computed)
    {
      os << "(default)\n";
    }
    else
    {
      os << v[0] << " " << v[1] << " " << v[2] << "\n";
    }
  };
  const bool* spacing = this->ComputeOutputSpacing;
  os << indent << "OutputSpacing: ";
  for (int k = 0; k < 3; ++k)
  {
    os << (spacing[k] ? "(default)" : std::to_string(this->OutputSpacing[k])) << (k < 2 ? " " : "\n");
  }
  vec("OutputOrigin", this->OutputOrigin, this->ComputeOutputOrigin);
  os << indent << "OutputExtent: ";
  if (this->ComputeOutputExtent)
  {
    os << "(default)\n";
  }
  else
  {
    for (int k = 0; k < 6; ++k)
    {
      os << this->OutputExtent[k] << (k < 5 ? " " : "\n");
    }
  }
  os << indent << "OutputDimensionality: " << this->OutputDimensionality << "\n";
  os << indent << "ResliceTransform: " << (this->ResliceTransform ? this->ResliceTransform->GetClassName() : "(none)")
     << "\n";
  os << indent << "TransformInputSampling: " << this->TransformInputSampling << "\n";
  os << indent << "AutoCropOutput: " << this->AutoCropOutput << "\n";
  os << indent << "BackgroundColor: " << this->BackgroundColor[0] << " " << this->BackgroundColor[1] << " "
     << this->BackgroundColor[2] << " " << this->BackgroundColor[3] << "\n";
  os << indent << "SlabMode: " << this->GetSlabModeAsString() << "\n";
  os << indent << "SlabNumberOfSlices: " << this->SlabNumberOfSlices << "\n";
  os << indent << "SlabSliceSpacingFraction: " << this->SlabSliceSpacingFraction << "\n";
  os << indent << "SlabTrapezoidIntegration: " << this->SlabTrapezoidIntegration << "\n";
  os << indent << "InterpolationMode, Wrap, Mirror, Border, BorderThickness, Optimization (no effect on a field): "
     << this->InterpolationMode << " " << this->Wrap << " " << this->Mirror << " " << this->Border << " "
     << this->BorderThickness << " " << this->Optimization << "\n";
  os << indent << "InformationInput: " << (this->InformationInput ? "set" : "(none)") << "\n";
  os << indent << "PixelLowPass: " << this->PixelLowPass << "\n";
  os << indent << "OutputScatteringField: " << this->OutputScatteringField << "\n";
  os << indent << "ScalarShift: " << this->ScalarShift << "\n";
  os << indent << "ScalarScale: " << this->ScalarScale << "\n";
  os << indent << "Interpolator: " << this->Interpolator << "\n";
  os << indent << "GenerateStencilOutput: " << this->GenerateStencilOutput << "\n";
  os << indent << "StencilCoverageThreshold: " << this->StencilCoverageThreshold << "\n";
}
