/**
 * @class   vtkPVGaussianFieldReslice
 * @brief   vtkGaussianFieldReslice driven by a plane (origin and normal), for ParaView's plane widget.
 *
 * ParaView's interactive plane widget edits an origin and a normal; vtkGaussianFieldReslice takes
 * reslice axes (x axis, y axis, normal, origin). This subclass keeps the plane and sets the axes from
 * it: normal n = SliceNormal / |SliceNormal|, x axis = the world axis least aligned with n (X on a tie,
 * then Y) projected onto the plane and normalised, y axis = n x (x axis), origin = SliceOrigin (mm, in
 * the field's reference frame). So the default plane (normal 0 0 1) gives the identity axes, and the
 * rendered image's x and y follow the world's X and Y as closely as the plane allows.
 *
 * The grid: SliceSpacing (mm; a component <= 0 = the field's pixel spacing, the superclass default) and
 * SliceDimensions (pixels along x and y, and slices along the normal for OutputDimensionality 3).
 * With every needed spacing and dimension positive, the grid is centred on SliceOrigin: pixel (i, j, k)
 * at SliceOrigin + ((i - (nx - 1) / 2) sx) x_axis + ((j - (ny - 1) / 2) sy) y_axis
 * + ((k - (nz - 1) / 2) sz) n. Otherwise (any of them 0, the default) the superclass's default grid
 * applies: the field's bounds, padded, in the plane's frame, the slice through SliceOrigin.
 *
 * The output is placed in the world, where the plane is (unlike vtkGaussianFieldReslice, whose output
 * lies in the reslice frame, as vtkImageReslice's does): the same pixels, with origin
 * ResliceAxes * (OutputOrigin, 1) and the axes' rotation as the image's direction matrix (VTK 9.2's
 * oriented vtkImageData), so that ParaView draws the slice and the volume over the field, at the widget.
 *
 * Errors: a zero, non-finite or denormal normal, or a non-finite origin, fail the request with
 * vtkErrorMacro (ParaView shows it in its Output Messages) and leave the output empty; the plane is
 * kept as set, so that the next valid value renders again.
 */
#ifndef vtkPVGaussianFieldReslice_h
#define vtkPVGaussianFieldReslice_h

#include "bigusParaViewFiltersModule.h" // For export macro
#include "vtkGaussianFieldReslice.h"

#include <string> // For std::string

class vtkImageData;

class BIGUSPARAVIEWFILTERS_EXPORT vtkPVGaussianFieldReslice : public vtkGaussianFieldReslice
{
public:
  static vtkPVGaussianFieldReslice* New();
  vtkTypeMacro(vtkPVGaussianFieldReslice, vtkGaussianFieldReslice);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  ///@{
  /// The plane: a point on it (mm) and its normal (any length but zero). Defaults 0 0 0 and 0 0 1.
  void SetSliceOrigin(double x, double y, double z);
  vtkGetVector3Macro(SliceOrigin, double);
  void SetSliceNormal(double x, double y, double z);
  vtkGetVector3Macro(SliceNormal, double);
  ///@}

  ///@{
  /// Pixel spacing (mm) along x, y and the normal; <= 0 = the field's pixel spacing. Default 0 0 0.
  void SetSliceSpacing(double x, double y, double z);
  vtkGetVector3Macro(SliceSpacing, double);
  ///@}

  ///@{
  /// Pixels along x and y and slices along the normal (the third is used by OutputDimensionality 3);
  /// 0 = cover the field's bounds. Default 0 0 0.
  void SetSliceDimensions(int x, int y, int z);
  vtkGetVector3Macro(SliceDimensions, int);
  ///@}

  /// The grid depends on the dimensionality (the third spacing and size count only for a volume).
  void SetOutputDimensionality(int dimensionality) override;

protected:
  vtkPVGaussianFieldReslice();
  ~vtkPVGaussianFieldReslice() override = default;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

private:
  vtkPVGaussianFieldReslice(const vtkPVGaussianFieldReslice&) = delete;
  void operator=(const vtkPVGaussianFieldReslice&) = delete;

  /// Sets the superclass's axes and grid from the plane, or PlaneError (the reason) for an invalid plane.
  void UpdateAxesAndGrid();
  /// Reports an invalid plane with vtkErrorMacro; true when the plane is valid.
  bool CheckPlane();
  /// Moves the grid (origin in the reslice frame) to the world: origin and direction matrix, in the
  /// output information and, when given, on the output image.
  void PlaceInWorld(vtkInformation* outInfo, vtkImageData* output);

  double SliceOrigin[3] = { 0, 0, 0 };
  double SliceNormal[3] = { 0, 0, 1 };
  double SliceSpacing[3] = { 0, 0, 0 };
  int SliceDimensions[3] = { 0, 0, 0 };
  std::string PlaneError;
  double FrameOrigin[3] = { 0, 0, 0 }; // the announced grid origin in the reslice frame (mm)
};

#endif
