#include "vtkGaussianFieldReslice.h"

#include "bigusGaussianFieldData.h"
#include "bigusRenderer.h"
#include "bigusTrainingEngine.h"

#include "vtkFloatArray.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkMatrix4x4.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkStreamingDemandDrivenPipeline.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

vtkStandardNewMacro(vtkGaussianFieldReslice);
vtkCxxSetObjectMacro(vtkGaussianFieldReslice, ResliceAxes, vtkMatrix4x4);
vtkCxxSetObjectMacro(vtkGaussianFieldReslice, InformationInput, vtkImageData);

namespace
{
constexpr double Unset = VTK_DOUBLE_MAX;
constexpr int UnsetExtent = VTK_INT_MIN;

/// An output grid in the reslice frame (mm, voxel indices); Unset / UnsetExtent where a default applies.
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

/// Whether a default that only the field can give (bounds, pixel spacing) is still unset.
bool NeedsField(const Grid& g, bool planar)
{
  return g.Spacing[0] == Unset || g.Spacing[1] == Unset || (!planar && g.Spacing[2] == Unset) || g.Origin[0] == Unset ||
    g.Origin[1] == Unset || (!planar && g.Origin[2] == Unset) || g.Extent[0] == UnsetExtent;
}

/**
 * The field's defaults for the unset parts of @p g: spacing = PixelSpacing or 0.5 mm; origin and extent
 * = the means' bounds padded by three times the largest scale, in the reslice frame of @p axes
 * (null = identity); a planar grid passes through the axes' origin (z = 0).
 */
void FillDefaults(Grid& g, const bigus::FieldCache& field, vtkMatrix4x4* axes, bool planar)
{
  const double step = field.GetModel().PixelSpacing > 0 ? field.GetModel().PixelSpacing : 0.5;
  for (int k = 0; k < 3; ++k)
  {
    g.Spacing[k] = g.Spacing[k] == Unset ? step : g.Spacing[k];
  }
  const double* world = field.GetBounds();
  const double pad = 3 * field.GetLargestScale();
  vtkNew<vtkMatrix4x4> inverse;
  if (axes)
  {
    vtkMatrix4x4::Invert(axes, inverse);
  }
  double lo[3] = { VTK_DOUBLE_MAX, VTK_DOUBLE_MAX, VTK_DOUBLE_MAX };
  double hi[3] = { -VTK_DOUBLE_MAX, -VTK_DOUBLE_MAX, -VTK_DOUBLE_MAX };
  for (int c = 0; c < 8; ++c)
  {
    double p[4] = { 0, 0, 0, 1 };
    for (int k = 0; k < 3; ++k)
    {
      const int upper = (c >> k) & 1;
      p[k] = world[2 * k + upper] + (upper ? pad : -pad);
    }
    double q[4];
    inverse->MultiplyPoint(p, q);
    for (int k = 0; k < 3; ++k)
    {
      lo[k] = std::min(lo[k], q[k]);
      hi[k] = std::max(hi[k], q[k]);
    }
  }
  for (int k = 0; k < 3; ++k)
  {
    if (g.Origin[k] == Unset)
    {
      g.Origin[k] = (planar && k == 2) ? 0.0 : lo[k];
    }
  }
  if (g.Extent[0] == UnsetExtent)
  {
    for (int k = 0; k < 3; ++k)
    {
      g.Extent[2 * k] = 0;
      // Held within int: a grid too large to render is refused by RequestData with the memory it needs.
      const double last = std::ceil((hi[k] - g.Origin[k]) / g.Spacing[k]);
      g.Extent[2 * k + 1] = last < VTK_INT_MAX - 1 ? static_cast<int>(last) : VTK_INT_MAX - 1;
    }
  }
}

/// Pose of slice k of @p extent: pixel (i, j) -> axes * (origin + (extent[0] + i, extent[2] + j,
/// extent[4] + k) * spacing), with the low-pass @p pixelLowPass (pixels^2).
bigus::SliceGeometry SliceAt(
  vtkMatrix4x4* axes, const double spacing[3], const double origin[3], const int extent[6], int k, double pixelLowPass)
{
  vtkNew<vtkMatrix4x4> grid, pose;
  grid->SetElement(0, 0, spacing[0]);
  grid->SetElement(1, 1, spacing[1]);
  grid->SetElement(0, 3, origin[0] + extent[0] * spacing[0]);
  grid->SetElement(1, 3, origin[1] + extent[2] * spacing[1]);
  grid->SetElement(2, 3, origin[2] + (extent[4] + k) * spacing[2]);
  vtkMatrix4x4::Multiply4x4(axes, grid, pose);
  bigus::SliceGeometry slice;
  std::copy(pose->GetData(), pose->GetData() + 16, slice.ImageToReference);
  slice.Width = extent[1] - extent[0] + 1;
  slice.Height = extent[3] - extent[2] + 1;
  slice.PixelLowPass = pixelLowPass;
  return slice;
}

/**
 * The output grid of @p self: its settings, an InformationInput's geometry over them, and for what is
 * still unset the defaults of the field @p input holds (converted into @p field only then). Returns
 * false when a default is needed and @p input holds no valid field.
 */
bool OutputGrid(vtkGaussianFieldReslice* self, bigus::FieldCache& field, vtkPolyData* input, Grid& g)
{
  const double* spacing = self->GetOutputSpacing();
  const double* origin = self->GetOutputOrigin();
  const int* extent = self->GetOutputExtent();
  std::copy(spacing, spacing + 3, g.Spacing);
  std::copy(origin, origin + 3, g.Origin);
  std::copy(extent, extent + 6, g.Extent);
  if (vtkImageData* reference = self->GetInformationInput())
  {
    reference->GetSpacing(g.Spacing);
    reference->GetOrigin(g.Origin);
    reference->GetExtent(g.Extent);
  }
  const bool planar = self->GetOutputDimensionality() == 2;
  if (NeedsField(g, planar))
  {
    if (!field.Update(input, nullptr))
    {
      return false;
    }
    FillDefaults(g, field, self->GetResliceAxes(), planar);
  }
  if (planar)
  {
    g.Extent[5] = g.Extent[4];
    g.Spacing[2] = g.Spacing[2] == Unset ? 1.0 : g.Spacing[2];
  }
  return true;
}
}

vtkGaussianFieldReslice::vtkGaussianFieldReslice()
{
  this->SetOutputSpacingToDefault();
  this->SetOutputOriginToDefault();
  this->SetOutputExtentToDefault();
}

vtkGaussianFieldReslice::~vtkGaussianFieldReslice()
{
  this->SetResliceAxes(nullptr);
  this->SetInformationInput(nullptr);
}

void vtkGaussianFieldReslice::SetOutputSpacingToDefault()
{
  this->SetOutputSpacing(Unset, Unset, Unset);
}

void vtkGaussianFieldReslice::SetOutputOriginToDefault()
{
  this->SetOutputOrigin(Unset, Unset, Unset);
}

void vtkGaussianFieldReslice::SetOutputExtentToDefault()
{
  this->SetOutputExtent(UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent, UnsetExtent);
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

vtkMTimeType vtkGaussianFieldReslice::GetMTime()
{
  vtkMTimeType t = this->Superclass::GetMTime();
  if (this->ResliceAxes)
  {
    t = std::max(t, this->ResliceAxes->GetMTime());
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
  // Metadata only: the input is never executed from here. A default grid uses the field the input
  // holds now (converted once and kept); RequestData corrects it if the field changes in this update.
  Grid grid;
  vtkInformation* outInfo = outputVector->GetInformationObject(0);
  vtkDataObject::SetPointDataActiveScalarInfo(outInfo, this->OutputScalarType, 1);
  if (!OutputGrid(this, this->GetFieldCache(), vtkPolyData::GetData(inputVector[0], 0), grid))
  {
    // No field yet (its producer has not run): nothing to announce until RequestData knows the grid.
    const int empty[6] = { 0, -1, 0, -1, 0, -1 };
    const double unit[3] = { 1, 1, 1 }, zero[3] = { 0, 0, 0 };
    outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), empty, 6);
    outInfo->Set(vtkDataObject::SPACING(), unit, 3);
    outInfo->Set(vtkDataObject::ORIGIN(), zero, 3);
    return 1;
  }
  if (grid.IsEmpty())
  {
    vtkErrorMacro("empty output extent " << grid.ExtentText());
    return 0;
  }
  outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), grid.Extent, 6);
  outInfo->Set(vtkDataObject::SPACING(), grid.Spacing, 3);
  outInfo->Set(vtkDataObject::ORIGIN(), grid.Origin, 3);
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
  OutputGrid(this, this->GetFieldCache(), vtkPolyData::GetData(inputVector[0], 0), grid);
  if (grid.IsEmpty())
  {
    vtkErrorMacro("empty output extent " << grid.ExtentText());
    return 0;
  }
  const bool planar = this->OutputDimensionality == 2;
  for (int k = 0; k < (planar ? 2 : 3); ++k)
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
    outInfo->Set(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), grid.Extent, 6);
    outInfo->Set(vtkDataObject::SPACING(), grid.Spacing, 3);
    outInfo->Set(vtkDataObject::ORIGIN(), grid.Origin, 3);
  }
  const int depth = extent[5] - extent[4] + 1;
  const std::size_t slicePixels = std::size_t(extent[1] - extent[0] + 1) * (extent[3] - extent[2] + 1);
  const std::size_t pixels = slicePixels * depth;

  vtkNew<vtkMatrix4x4> axes;
  if (this->ResliceAxes)
  {
    axes->DeepCopy(this->ResliceAxes);
  }
  // Refused before anything is allocated where the grid cannot be held: the float buffers below, the output's
  // scalars and arrays (each copied once), against this machine's memory.
  const double samples =
    double(extent[1] - extent[0] + 1) * double(extent[3] - extent[2] + 1) * double(extent[5] - extent[4] + 1);
  const double bytes = samples *
      (2 * sizeof(float) + (this->OutputScatteringField ? 2 * sizeof(float) : 0) + (coverage ? 2 * sizeof(float) : 0)) +
    samples / depth * sizeof(float);
  const double physical = bigus::PhysicalMemoryBytes();
  if (physical > 0 && bytes > physical)
  {
    vtkErrorMacro("the output grid " << grid.ExtentText() << " (" << samples << " samples) needs " << bytes / 1e6
                                     << " MB and this machine has " << physical / 1e6
                                     << " MB: choose a coarser OutputSpacing or a smaller OutputExtent");
    return 0;
  }
  const bigus::RenderOptions& options = render.Options;
  const bigus::FieldView view = render.Field->GetField().View();
  std::string error;
  // S is kept whole only when it is an output; otherwise one slice of scratch.
  std::vector<float> I(pixels), S(this->OutputScatteringField ? pixels : slicePixels), C(coverage ? pixels : 0);
  for (int k = 0; k < depth; ++k)
  {
    if (this->GetAbortExecute())
    {
      // The output stays empty, so the pipeline does not take it for the requested extent.
      return 1;
    }
    const bigus::SliceGeometry slice = SliceAt(axes, grid.Spacing, grid.Origin, extent, k, this->PixelLowPass);
    float* s = S.data() + (this->OutputScatteringField ? k * slicePixels : 0);
    if (!render.Backend->Forward(view, &slice, 1, options, s, I.data() + k * slicePixels, nullptr, &error))
    {
      vtkErrorMacro("ResliceAxes: " << error);
      return 0;
    }
    if (coverage)
    {
      coverage->Compute(slice, options.ElevationSigma, C.data() + k * slicePixels);
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
  return 1;
}

void vtkGaussianFieldReslice::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "ResliceAxes: " << (this->ResliceAxes ? "set" : "(identity)") << "\n";
  if (this->ResliceAxes)
  {
    this->ResliceAxes->PrintSelf(os, indent.GetNextIndent());
  }
  auto vec = [&](const char* name, const double* v) {
    os << indent << name << ": ";
    if (v[0] == Unset)
    {
      os << "(default)\n";
    }
    else
    {
      os << v[0] << " " << v[1] << " " << v[2] << "\n";
    }
  };
  vec("OutputSpacing", this->OutputSpacing);
  vec("OutputOrigin", this->OutputOrigin);
  os << indent << "OutputExtent: ";
  if (this->OutputExtent[0] == UnsetExtent)
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
  os << indent << "InformationInput: " << (this->InformationInput ? "set" : "(none)") << "\n";
  os << indent << "PixelLowPass: " << this->PixelLowPass << "\n";
  os << indent << "OutputScatteringField: " << this->OutputScatteringField << "\n";
}
