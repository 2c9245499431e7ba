/**
 * @class   vtkUltrasoundSliceGeometry
 * @brief   Geometry of one tracked ultrasound slice from its ImageToReference matrix.
 *
 * ImageToReference maps a pixel index (column, row, 0, 1) to millimetres in the reference frame
 * (the matrix carries the pixel spacing; PLUS's ElementSpacing is not used on top of it). This class
 * exposes the orthonormal probe frame of DESIGN section 3: unit axes U (columns) and V (rows),
 * normal N = U x V (the elevation direction of the beam), the origin (centre of pixel (0, 0), mm),
 * the pixel spacing (mm) and the shear angle between the two image axes (degrees).
 *
 * Status is 0 when the matrix is a usable pose; otherwise GetStatusText() says what is wrong
 * (NaN/Inf, bottom row not 0 0 0 1, singular, or sheared beyond MaximumShearAngle).
 */
#ifndef vtkUltrasoundSliceGeometry_h
#define vtkUltrasoundSliceGeometry_h

#include "bigusRenderingModule.h" // For export macro
#include "vtkObject.h"

class vtkMatrix4x4;

class BIGUSRENDERING_EXPORT vtkUltrasoundSliceGeometry : public vtkObject
{
public:
  static vtkUltrasoundSliceGeometry* New();
  vtkTypeMacro(vtkUltrasoundSliceGeometry, vtkObject);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /**
   * Largest accepted deviation of the angle between the image axes from 90 degrees.
   * Default 5 degrees (bigus::DefaultMaximumShearAngle, the renderer's limit): tracked calibrations
   * carry some shear (PLUS spine phantom: about 2.8).
   */
  vtkSetClampMacro(MaximumShearAngle, double, 0.0, 90.0);
  vtkGetMacro(MaximumShearAngle, double);

  /**
   * Set the pose (pixel index -> mm, 4x4) and recompute the frame. The matrix is copied.
   */
  void SetImageToReference(vtkMatrix4x4* imageToReference);

  /// 0 when the pose is usable; see GetStatusText().
  vtkGetMacro(Status, int);
  const char* GetStatusText() const;

  vtkGetVector3Macro(AxisU, double);
  vtkGetVector3Macro(AxisV, double);
  vtkGetVector3Macro(Normal, double);
  vtkGetVector3Macro(Origin, double);
  /// mm per pixel along the columns (x) and rows (y).
  vtkGetVector2Macro(PixelSpacing, double);
  /// |90 - angle between the image axes|, degrees.
  vtkGetMacro(ShearAngle, double);

protected:
  vtkUltrasoundSliceGeometry();
  ~vtkUltrasoundSliceGeometry() override = default;

  double MaximumShearAngle;
  int Status = 0;
  double AxisU[3] = { 1, 0, 0 };
  double AxisV[3] = { 0, 1, 0 };
  double Normal[3] = { 0, 0, 1 };
  double Origin[3] = { 0, 0, 0 };
  double PixelSpacing[2] = { 1, 1 };
  double ShearAngle = 0.0;

private:
  vtkUltrasoundSliceGeometry(const vtkUltrasoundSliceGeometry&) = delete;
  void operator=(const vtkUltrasoundSliceGeometry&) = delete;
};

#endif
