/**
 * @class   vtkGaussianFieldReslice
 * @brief   Renders ultrasound slices of a Gaussian scattering field at any plane, like vtkImageReslice.
 *
 * Input: a Gaussian field (vtkPolyData, DESIGN section 2; vtkGaussianFieldTrainer's output).
 * Output: vtkImageData in the coordinates of the reslice axes, with the vocabulary and meaning of
 * vtkImageReslice: output voxel (i, j, k) lies at ResliceTransform(ResliceAxes * (OutputOrigin + (i, j, k) *
 * OutputSpacing, 1)) in the field's reference frame (mm). ResliceAxes columns are the x axis, the y axis, the
 * normal and the origin. OutputDimensionality 2 renders one slice, 3 a stack of parallel slices: a volume for
 * vtkImageReslice or a volume mapper. As in vtkImageReslice, dimensionality 2 forces the output's z extent to
 * (0, 0) and its z origin to 0 (the slice passes through the axes' origin: move ResliceAxesOrigin to move it),
 * dimensionality 1 also the y extent and origin, 0 the x ones. The one difference: the default dimensionality is 2
 * (vtkImageReslice's is 3), because a field has no voxels and a default stack renders every slice of its bounds.
 * The API of vtkImageReslice and what each call does on a field: README, "vtkGaussianFieldReslice and
 * vtkImageReslice".
 *
 * Point data (vtkGaussianFieldRenderer): scalars "Intensity", with OutputScatteringField on a second
 * array "ScatteringField" holding the signed scattering field S (float), and "Coverage" (OutputCoverage).
 *
 * Defaults when nothing is set: identity axes; spacing = the field's PixelSpacing (its training frames'
 * pixel spacing) or 0.5 mm; origin and extent = the field's bounds in the reslice frame (points, padded
 * by three times the largest scale: vtkImageReslice's AutoCropOutput of a volume that holds the field).
 * With an InformationInput the defaults are vtkImageReslice's for that image as its input: its spacing, origin
 * and extent permuted through the ResliceAxes (TransformInputSampling, AutoCropOutput as there). Values set
 * with SetOutputSpacing, SetOutputOrigin and SetOutputExtent override either; the getters return them, or
 * vtkImageReslice's (1, 1, 1), (0, 0, 0) and (0, 0, 0, 0, 0, 0) while the default applies.
 *
 * OutputScalarType: any of vtkImageReslice's (bigus::IsIntensityScalarType), the intensity I in [0, 1] for float
 * and double, round(255 I) clamped to the type's range for the integer types; ScalarShift and ScalarScale as there.
 * BackgroundColor (its first component, BackgroundLevel, in the output's scalar units: [0, 1] for float and double,
 * 0 to 255 for the integer types) fills the samples outside the field's padded bounds, where vtkImageReslice fills the
 * samples outside its input volume; inside, a field renders 0 where it has no Gaussian. SlabMode (min, max,
 * mean, sum) combines SlabNumberOfSlices slices SlabSliceSpacingFraction x the output's z spacing apart,
 * centred on each output slice (SlabTrapezoidIntegration halves the two end slices' weights for mean and sum),
 * the intensity, the scattering field and the coverage alike.
 *
 * Accepted and stored, without effect on a field (it has no voxels to interpolate, wrap or mirror):
 * InterpolationMode (and Interpolate), Interpolator, Wrap, Mirror, Border, BorderThickness, Optimization.
 *
 * Sampling grids: sheared axes (the x and y direction cosines not perpendicular, short of parallel) are rendered
 * exactly, each slice a sheared pixel grid on its plane with the elevation beam along the plane's normal x cross y.
 * A ResliceTransform that is not linear (any vtkAbstractTransform other than a vtkHomogeneousTransform: thin-plate
 * spline, grid, general, spherical...) or a perspective bottom row (in ResliceAxes or a vtkHomogeneousTransform)
 * bends the grid: each output sample is then rendered at its own point, with the elevation beam along the local
 * normal (the cross product of the sample's derivatives along the output's i and j, from the transform's
 * TransformDerivative) and PixelLowPass on those local pixel axes (bigus::RenderPoints). Cost: every Gaussian near
 * a sample set up for that sample's own plane, about 50 times a plane's time (a 256 x 256 slice of the liver field of
 * 136,530 Gaussians: 0.28 s bent, 0.006 s planar, 2 cores). Always on the CPU (Backend applies to planar grids).
 *
 * Stencils, as vtkImageReslice's: SetStencilData (input port 1, a vtkImageStencilData on the output's grid) sets the
 * output's scalars outside the stencil to BackgroundLevel. GenerateStencilOutput makes output port 1 a
 * vtkImageStencilData on the output's grid (GetStencilOutput) marking the samples the field stands for: where the
 * training coverage (vtkGaussianFieldRenderer's Coverage, at each sample's own point) is at least
 * StencilCoverageThreshold; for a field without training geometry, the samples inside the field's padded bounds (the
 * samples BackgroundColor does not fill), as vtkImageReslice marks the samples inside its input volume.
 *
 * Pipeline: with spacing, origin and extent all set (or an InformationInput) the output grid is pure
 * metadata. A default grid needs the field's bounds, which are data, not pipeline information:
 * RequestInformation takes them from the field the input holds at that moment (exact for SetInputData and
 * for an input that is already up to date); when the input holds no field yet (its producer has not run,
 * as on the first update through a reader), RequestInformation runs the producer once, so that the grid a
 * downstream filter plans from is the field's. RequestData takes the bounds from the up-to-date field; when
 * they differ from those RequestInformation saw (the field changed in this update) it renders the grid of
 * the up-to-date field and writes it into the output information, as vtkGaussianSplatter does with its
 * automatic bounds (a downstream filter that planned from the earlier grid sees the new one at its next
 * update).
 *
 * Interactive use: the renderer and the converted field are kept between executes
 * (vtkGaussianFieldRenderer), so moving the plane (ResliceAxes) re-renders without converting the
 * field again. A stack (OutputDimensionality 3) reports progress after every slice and stops at the
 * next slice when AbortExecute is set, leaving an empty output (the next Update renders again).
 *
 * Errors (those of vtkGaussianFieldRenderer, a singular ResliceAxes or one a transform folds, an empty extent) fail
 * the request with vtkErrorMacro and leave the output empty.
 */
#ifndef vtkGaussianFieldReslice_h
#define vtkGaussianFieldReslice_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkGaussianFieldRenderer.h"

class vtkAbstractImageInterpolator;
class vtkAbstractTransform;
class vtkAlgorithmOutput;
class vtkImageStencilData;
class vtkMatrix4x4;
class vtkPolyData;

class BIGUSFILTERS_EXPORT vtkGaussianFieldReslice : public vtkGaussianFieldRenderer
{
public:
  static vtkGaussianFieldReslice* New();
  vtkTypeMacro(vtkGaussianFieldReslice, vtkGaussianFieldRenderer);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  ///@{
  /**
   * The reslice frame: a 4x4 matrix whose columns are the x axis, the y axis, the normal (unit
   * vectors) and the origin (mm) in the field's reference frame; null = identity. Held, not copied:
   * changing its elements re-executes the filter (GetMTime includes it).
   */
  virtual void SetResliceAxes(vtkMatrix4x4*);
  vtkGetObjectMacro(ResliceAxes, vtkMatrix4x4);
  ///@}

  ///@{
  /**
   * The axes' direction cosines (the first three elements of each of the first three columns) and origin (the
   * first three of the last), as vtkImageReslice's: setting them creates ResliceAxes if there is none; the
   * getters give the identity's without one.
   */
  void SetResliceAxesDirectionCosines(
    double x0, double x1, double x2, double y0, double y1, double y2, double z0, double z1, double z2);
  void SetResliceAxesDirectionCosines(const double x[3], const double y[3], const double z[3])
  {
    this->SetResliceAxesDirectionCosines(x[0], x[1], x[2], y[0], y[1], y[2], z[0], z[1], z[2]);
  }
  void SetResliceAxesDirectionCosines(const double xyz[9])
  {
    this->SetResliceAxesDirectionCosines(xyz[0], xyz[1], xyz[2], xyz[3], xyz[4], xyz[5], xyz[6], xyz[7], xyz[8]);
  }
  void GetResliceAxesDirectionCosines(double x[3], double y[3], double z[3]);
  void GetResliceAxesDirectionCosines(double xyz[9])
  {
    this->GetResliceAxesDirectionCosines(&xyz[0], &xyz[3], &xyz[6]);
  }
  double* GetResliceAxesDirectionCosines() VTK_SIZEHINT(9)
  {
    this->GetResliceAxesDirectionCosines(this->ResliceAxesDirectionCosines);
    return this->ResliceAxesDirectionCosines;
  }
  void SetResliceAxesOrigin(double x, double y, double z);
  void SetResliceAxesOrigin(const double xyz[3]) { this->SetResliceAxesOrigin(xyz[0], xyz[1], xyz[2]); }
  void GetResliceAxesOrigin(double xyz[3]);
  double* GetResliceAxesOrigin() VTK_SIZEHINT(3)
  {
    this->GetResliceAxesOrigin(this->ResliceAxesOrigin);
    return this->ResliceAxesOrigin;
  }
  ///@}

  ///@{
  /**
   * A transform applied to the sampling grid after ResliceAxes, as vtkImageReslice's: a linear one
   * (vtkLinearTransform, or a vtkHomogeneousTransform without perspective) is composed with the axes, so that
   * each slice is rendered in its transformed plane; any other (non-linear, perspective) renders each sample at its
   * transformed point with the beam along the local normal (the class description). Held: its changes re-execute
   * the filter.
   */
  virtual void SetResliceTransform(vtkAbstractTransform*);
  vtkGetObjectMacro(ResliceTransform, vtkAbstractTransform);
  ///@}

  ///@{
  /**
   * Output grid in the reslice frame: spacing (mm), origin (mm) and extent (voxel indices);
   * OutputDimensionality 2 (default, one slice at z = OutputOrigin[2]) or 3 (a stack along the
   * normal). The ...ToDefault methods restore the defaults of the class description.
   */
  virtual void SetOutputSpacing(double x, double y, double z);
  virtual void SetOutputSpacing(const double a[3]) { this->SetOutputSpacing(a[0], a[1], a[2]); }
  vtkGetVector3Macro(OutputSpacing, double);
  virtual void SetOutputOrigin(double x, double y, double z);
  virtual void SetOutputOrigin(const double a[3]) { this->SetOutputOrigin(a[0], a[1], a[2]); }
  vtkGetVector3Macro(OutputOrigin, double);
  virtual void SetOutputExtent(int a, int b, int c, int d, int e, int f);
  virtual void SetOutputExtent(const int a[6]) { this->SetOutputExtent(a[0], a[1], a[2], a[3], a[4], a[5]); }
  vtkGetVector6Macro(OutputExtent, int);
  void SetOutputSpacingToDefault();
  void SetOutputOriginToDefault();
  void SetOutputExtentToDefault();
  vtkSetClampMacro(OutputDimensionality, int, 0, 3);
  vtkGetMacro(OutputDimensionality, int);
  ///@}

  ///@{
  /**
   * With an InformationInput, as vtkImageReslice's: TransformInputSampling (default on) permutes and rotates the
   * image's spacing and extent into the reslice frame; AutoCropOutput (default off) makes the default extent and
   * origin cover the whole image in that frame. The field's own default grid is always its bounds in the frame.
   */
  vtkSetMacro(TransformInputSampling, vtkTypeBool);
  vtkGetMacro(TransformInputSampling, vtkTypeBool);
  vtkBooleanMacro(TransformInputSampling, vtkTypeBool);
  vtkSetMacro(AutoCropOutput, vtkTypeBool);
  vtkGetMacro(AutoCropOutput, vtkTypeBool);
  vtkBooleanMacro(AutoCropOutput, vtkTypeBool);
  ///@}

  ///@{
  /**
   * The value of the samples outside the field's padded bounds (see the class description), in the output's
   * scalar units; BackgroundLevel is BackgroundColor's first component. Default 0.
   */
  vtkSetVector4Macro(BackgroundColor, double);
  vtkGetVector4Macro(BackgroundColor, double);
  void SetBackgroundLevel(double v) { this->SetBackgroundColor(v, v, v, v); }
  double GetBackgroundLevel() { return this->BackgroundColor[0]; }
  ///@}

  ///@{
  /**
   * As vtkImageReslice's: each rendered sample v (the intensity in the output's scalar units, IntensityUnit: I for
   * float and double, 255 I for the integer types) becomes (v + ScalarShift) x ScalarScale before it is converted
   * to OutputScalarType (an integer type rounded and clamped to its range). The background (BackgroundColor) is not
   * shifted or scaled. Defaults 0 and 1.
   */
  vtkSetMacro(ScalarShift, double);
  vtkGetMacro(ScalarShift, double);
  vtkSetMacro(ScalarScale, double);
  vtkGetMacro(ScalarScale, double);
  ///@}

  ///@{
  /**
   * Slab rendering, as vtkImageReslice's (see the class description): SlabMode VTK_IMAGE_SLAB_MIN, _MAX, _MEAN
   * (default) or _SUM; SlabNumberOfSlices (default 1: no slab); SlabSliceSpacingFraction of the output's z
   * spacing between the slab's slices (default 1); SlabTrapezoidIntegration (default off).
   */
  vtkSetClampMacro(SlabMode, int, VTK_IMAGE_SLAB_MIN, VTK_IMAGE_SLAB_SUM);
  vtkGetMacro(SlabMode, int);
  void SetSlabModeToMin() { this->SetSlabMode(VTK_IMAGE_SLAB_MIN); }
  void SetSlabModeToMax() { this->SetSlabMode(VTK_IMAGE_SLAB_MAX); }
  void SetSlabModeToMean() { this->SetSlabMode(VTK_IMAGE_SLAB_MEAN); }
  void SetSlabModeToSum() { this->SetSlabMode(VTK_IMAGE_SLAB_SUM); }
  const char* GetSlabModeAsString();
  vtkSetClampMacro(SlabNumberOfSlices, int, 1, 1000);
  vtkGetMacro(SlabNumberOfSlices, int);
  vtkSetClampMacro(SlabSliceSpacingFraction, double, 1e-6, 1e6);
  vtkGetMacro(SlabSliceSpacingFraction, double);
  vtkSetMacro(SlabTrapezoidIntegration, vtkTypeBool);
  vtkGetMacro(SlabTrapezoidIntegration, vtkTypeBool);
  vtkBooleanMacro(SlabTrapezoidIntegration, vtkTypeBool);
  ///@}

  ///@{
  /**
   * Accepted for scripts written for vtkImageReslice and stored; no effect on a field (the class description).
   */
  vtkSetClampMacro(InterpolationMode, int, VTK_NEAREST_INTERPOLATION, VTK_CUBIC_INTERPOLATION);
  vtkGetMacro(InterpolationMode, int);
  void SetInterpolationModeToNearestNeighbor() { this->SetInterpolationMode(VTK_NEAREST_INTERPOLATION); }
  void SetInterpolationModeToLinear() { this->SetInterpolationMode(VTK_LINEAR_INTERPOLATION); }
  void SetInterpolationModeToCubic() { this->SetInterpolationMode(VTK_CUBIC_INTERPOLATION); }
  const char* GetInterpolationModeAsString();
  void SetInterpolate(int t) { this->SetInterpolationMode(t ? VTK_LINEAR_INTERPOLATION : VTK_NEAREST_INTERPOLATION); }
  void InterpolateOn() { this->SetInterpolate(1); }
  void InterpolateOff() { this->SetInterpolate(0); }
  int GetInterpolate() { return this->InterpolationMode != VTK_NEAREST_INTERPOLATION; }
  vtkSetMacro(Wrap, vtkTypeBool);
  vtkGetMacro(Wrap, vtkTypeBool);
  vtkBooleanMacro(Wrap, vtkTypeBool);
  vtkSetMacro(Mirror, vtkTypeBool);
  vtkGetMacro(Mirror, vtkTypeBool);
  vtkBooleanMacro(Mirror, vtkTypeBool);
  vtkSetMacro(Border, vtkTypeBool);
  vtkGetMacro(Border, vtkTypeBool);
  vtkBooleanMacro(Border, vtkTypeBool);
  vtkSetMacro(BorderThickness, double);
  vtkGetMacro(BorderThickness, double);
  vtkSetMacro(Optimization, vtkTypeBool);
  vtkGetMacro(Optimization, vtkTypeBool);
  vtkBooleanMacro(Optimization, vtkTypeBool);
  /// An interpolator (vtkImageInterpolator, vtkImageSincInterpolator, ...) as vtkImageReslice takes one: held and
  /// returned, no effect on a field.
  virtual void SetInterpolator(vtkAbstractImageInterpolator*);
  vtkGetObjectMacro(Interpolator, vtkAbstractImageInterpolator);
  ///@}

  ///@{
  /**
   * An image whose geometry gives the default spacing, origin and extent, as vtkImageReslice's (see the class
   * description): permuted through the ResliceAxes; values set with SetOutputSpacing, SetOutputOrigin and
   * SetOutputExtent override it.
   */
  virtual void SetInformationInput(vtkImageData*);
  vtkGetObjectMacro(InformationInput, vtkImageData);
  ///@}

  ///@{
  /**
   * Variance (output pixels^2, along each output axis; clamped to [0, 1e6]) of a Gaussian low-pass that every
   * Gaussian is convolved with before it is sampled at the output pixel centres (bigus::SliceGeometry::
   * PixelLowPass). 1/12 makes each pixel the average over its own area (the variance of a box of one pixel):
   * anti-aliasing where the output spacing is coarser than the field's detail, as vtkImageReslice's
   * antialiasing interpolators do. Default 0: point samples.
   */
  vtkSetClampMacro(PixelLowPass, double, 0.0, 1e6);
  vtkGetMacro(PixelLowPass, double);
  ///@}

  ///@{
  /**
   * Also output the signed scattering field S as float point data "ScatteringField". Default off.
   */
  vtkSetMacro(OutputScatteringField, bool);
  vtkGetMacro(OutputScatteringField, bool);
  vtkBooleanMacro(OutputScatteringField, bool);
  ///@}

  ///@{
  /**
   * A stencil on the output's grid, as vtkImageReslice's (input port 1): the output's scalars outside it are
   * BackgroundLevel (not shifted or scaled). Null (default): none.
   */
  void SetStencilData(vtkImageStencilData* stencil);
  vtkImageStencilData* GetStencil();
  ///@}

  ///@{
  /**
   * Output port 1 as a vtkImageStencilData of the samples the field stands for (the class description), as
   * vtkImageReslice's GenerateStencilOutput. Default off (the port's stencil is then empty).
   */
  vtkSetMacro(GenerateStencilOutput, vtkTypeBool);
  vtkGetMacro(GenerateStencilOutput, vtkTypeBool);
  vtkBooleanMacro(GenerateStencilOutput, vtkTypeBool);
  vtkAlgorithmOutput* GetStencilOutputPort() { return this->GetOutputPort(1); }
  vtkImageStencilData* GetStencilOutput();
  /// The data object of output port 1 (as vtkImageReslice's): the next update fills it when GenerateStencilOutput.
  void SetStencilOutput(vtkImageStencilData* stencil);
  ///@}

  ///@{
  /**
   * The training coverage (dimensionless: the elevation weights of the training frames at a sample, each at most 1;
   * bigus::TrainingCoverage) from which a sample is inside the stencil output. Default 0.5: within 1.18 sigma_E of a
   * training frame inside its fan (where one frame's beam is at half its peak), or between two frames' half weights.
   */
  vtkSetClampMacro(StencilCoverageThreshold, double, 0.0, 1e6);
  vtkGetMacro(StencilCoverageThreshold, double);
  ///@}

  /**
   * Includes the ResliceAxes matrix, the ResliceTransform and the information input.
   */
  vtkMTimeType GetMTime() override;

protected:
  vtkGaussianFieldReslice();
  ~vtkGaussianFieldReslice() override;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  /// Makes the stencil output (port 1) on REQUEST_DATA_OBJECT.
  vtkTypeBool ProcessRequest(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  /// Port 1: the optional stencil (vtkImageStencilData).
  int FillInputPortInformation(int port, vtkInformation* info) override;
  /// Port 1: the stencil output (vtkImageStencilData).
  int FillOutputPortInformation(int port, vtkInformation* info) override;

  /**
   * The output grid (spacing and origin in mm, extent): the settings where set; for the computed parts an
   * InformationInput's defaults or those of the field @p input holds (converted then); OutputDimensionality's
   * zeroed axes (the class description). Extents too large for int are held at VTK_INT_MAX - 1 (RequestData
   * refuses them with the memory they need). False when the field's defaults are needed and @p input holds no valid
   * field.
   */
  bool ComputeOutputGrid(vtkPolyData* input, double spacing[3], double origin[3], int extent[6]);

  /**
   * For subclasses (the ParaView filter, whose SliceSpacing 0 means "the default" per axis): the components of
   * @p spacing above 0 set, the others computed as by SetOutputSpacingToDefault. vtkImageReslice has no such call (its
   * spacing is set or computed whole).
   */
  void SetOutputSpacingComponents(const double spacing[3]);

  vtkMatrix4x4* ResliceAxes = nullptr;
  vtkAbstractTransform* ResliceTransform = nullptr;
  vtkImageData* InformationInput = nullptr;
  double ResliceAxesDirectionCosines[9];
  double ResliceAxesOrigin[3];
  double OutputSpacing[3] = { 1, 1, 1 };
  double OutputOrigin[3] = { 0, 0, 0 };
  int OutputExtent[6] = { 0, 0, 0, 0, 0, 0 };
  bool ComputeOutputSpacing[3] = { true, true, true };
  bool ComputeOutputOrigin = true;
  bool ComputeOutputExtent = true;
  int OutputDimensionality = 2;
  vtkTypeBool TransformInputSampling = 1;
  vtkTypeBool AutoCropOutput = 0;
  double BackgroundColor[4] = { 0, 0, 0, 0 };
  int SlabMode = VTK_IMAGE_SLAB_MEAN;
  int SlabNumberOfSlices = 1;
  double SlabSliceSpacingFraction = 1;
  vtkTypeBool SlabTrapezoidIntegration = 0;
  int InterpolationMode = VTK_NEAREST_INTERPOLATION;
  vtkTypeBool Wrap = 0;
  vtkTypeBool Mirror = 0;
  vtkTypeBool Border = 1;
  double BorderThickness = 0.5;
  vtkTypeBool Optimization = 1;
  vtkAbstractImageInterpolator* Interpolator = nullptr;
  double ScalarShift = 0.0;
  double ScalarScale = 1.0;
  double PixelLowPass = 0.0;
  bool OutputScatteringField = false;
  vtkTypeBool GenerateStencilOutput = 0;
  double StencilCoverageThreshold = 0.5;

private:
  vtkGaussianFieldReslice(const vtkGaussianFieldReslice&) = delete;
  void operator=(const vtkGaussianFieldReslice&) = delete;
};

#endif
