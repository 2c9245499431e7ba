/**
 * @class   vtkGaussianFieldReslice
 * @brief   Renders ultrasound slices of a Gaussian scattering field at any plane, like vtkImageReslice.
 *
 * Input: a Gaussian field (vtkPolyData, DESIGN section 2; vtkGaussianFieldTrainer's output).
 * Output: vtkImageData in the coordinates of the reslice axes, with the vocabulary and meaning of
 * vtkImageReslice: output voxel (i, j, k) lies at ResliceAxes * (OutputOrigin + (i, j, k) * OutputSpacing, 1)
 * in the field's reference frame (mm). ResliceAxes columns are the x axis, the y axis, the normal and
 * the origin. OutputDimensionality 2 renders one slice (k = 0), 3 a stack of parallel slices: a volume
 * for vtkImageReslice or a volume mapper. SetInformationInput copies spacing, origin and extent from a
 * reference image.
 *
 * Point data (vtkGaussianFieldRenderer): scalars "Intensity", with OutputScatteringField on a second
 * array "ScatteringField" holding the signed scattering field S (float), and "Coverage" (OutputCoverage).
 *
 * Defaults when nothing is set: identity axes; spacing = the field's PixelSpacing (its training frames'
 * pixel spacing) or 0.5 mm; origin and extent = the field's bounds in the reslice frame (points, padded
 * by three times the largest scale); for OutputDimensionality 2 the slice passes through the axes'
 * origin (z = 0).
 *
 * Pipeline: RequestInformation never executes the input. With spacing, origin and extent all set (or
 * an InformationInput) the output grid is pure metadata. A default grid needs the field's bounds, which
 * are data, not pipeline information: RequestInformation takes them from the field the input holds at
 * that moment (exact for SetInputData and for an input that is already up to date), and RequestData
 * takes them from the up-to-date field; when the two differ (the field was not there yet, or changed
 * in this update) RequestData renders the grid of the up-to-date field and writes it into the output
 * information, as vtkGaussianSplatter does with its automatic bounds. A filter downstream that plans
 * from the whole extent during that same update saw the earlier grid (reader -> this filter with a
 * default grid -> vtkImageReslice, first Update): set the grid, or update this filter before the
 * downstream one.
 *
 * Interactive use: the renderer and the converted field are kept between executes
 * (vtkGaussianFieldRenderer), so moving the plane (ResliceAxes) re-renders without converting the
 * field again. A stack (OutputDimensionality 3) reports progress after every slice and stops at the
 * next slice when AbortExecute is set, leaving an empty output (the next Update renders again).
 *
 * Errors (those of vtkGaussianFieldRenderer, a singular or sheared ResliceAxes, an empty extent) fail
 * the request with vtkErrorMacro and leave the output empty.
 */
#ifndef vtkGaussianFieldReslice_h
#define vtkGaussianFieldReslice_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkGaussianFieldRenderer.h"

class vtkMatrix4x4;

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
  void SetResliceAxesDirectionCosines(
    double x0, double x1, double x2, double y0, double y1, double y2, double z0, double z1, double z2);
  void SetResliceAxesOrigin(double x, double y, double z);
  ///@}

  ///@{
  /**
   * Output grid in the reslice frame: spacing (mm), origin (mm) and extent (voxel indices);
   * OutputDimensionality 2 (default, one slice at z = OutputOrigin[2]) or 3 (a stack along the
   * normal). The ...ToDefault methods restore the defaults of the class description.
   */
  vtkSetVector3Macro(OutputSpacing, double);
  vtkGetVector3Macro(OutputSpacing, double);
  vtkSetVector3Macro(OutputOrigin, double);
  vtkGetVector3Macro(OutputOrigin, double);
  vtkSetVector6Macro(OutputExtent, int);
  vtkGetVector6Macro(OutputExtent, int);
  void SetOutputSpacingToDefault();
  void SetOutputOriginToDefault();
  void SetOutputExtentToDefault();
  vtkSetClampMacro(OutputDimensionality, int, 2, 3);
  vtkGetMacro(OutputDimensionality, int);
  ///@}

  ///@{
  /**
   * Copy spacing, origin and extent from this image (its data object, as vtkImageReslice does);
   * they take precedence over OutputSpacing, OutputOrigin and OutputExtent.
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

  /**
   * Includes the ResliceAxes matrix and the information input.
   */
  vtkMTimeType GetMTime() override;

protected:
  vtkGaussianFieldReslice();
  ~vtkGaussianFieldReslice() override;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  vtkMatrix4x4* ResliceAxes = nullptr;
  vtkImageData* InformationInput = nullptr;
  double OutputSpacing[3];
  double OutputOrigin[3];
  int OutputExtent[6];
  int OutputDimensionality = 2;
  double PixelLowPass = 0.0;
  bool OutputScatteringField = false;

private:
  vtkGaussianFieldReslice(const vtkGaussianFieldReslice&) = delete;
  void operator=(const vtkGaussianFieldReslice&) = delete;
};

#endif
