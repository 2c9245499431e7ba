/**
 * @class   vtkUltrasoundCalibration
 * @brief   Reads the calibration parts of a PLUS device-set configuration XML.
 *
 * PLUS (https://plustoolkit.github.io) keeps the probe calibration in a device-set configuration file:
 * `<CoordinateDefinitions><Transform From="Image" To="Probe" Matrix="16 numbers, row-major"/>` and
 * the imaged region in `<VolumeReconstruction ClipRectangleOrigin="x y" ClipRectangleSize="w h"
 * FanAnglesDeg="min max" FanOriginPixel="x y" FanRadiusStartPixel="r0" FanRadiusStopPixel="r1"/>`.
 * This class parses those with VTK's XML parser. Transforms can be asked for in either direction
 * (ProbeToImage is the inverse of a stored ImageToProbe).
 *
 * Errors (missing file, malformed XML, a Transform without From/To or with a Matrix that is not 16
 * finite numbers, a clip rectangle that is not two integers) make Parse() return false and fill
 * GetErrorText(), naming the file and the element.
 */
#ifndef vtkUltrasoundCalibration_h
#define vtkUltrasoundCalibration_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkObject.h"

#include <memory> // For std::unique_ptr

class vtkMatrix4x4;

class BIGUSFILTERS_EXPORT vtkUltrasoundCalibration : public vtkObject
{
public:
  static vtkUltrasoundCalibration* New();
  vtkTypeMacro(vtkUltrasoundCalibration, vtkObject);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// PLUS device-set configuration XML.
  vtkSetStringMacro(FileName);
  vtkGetStringMacro(FileName);

  /// Read FileName. Returns false (and sets ErrorText) on any problem; earlier results are cleared.
  bool Parse();

  /// Why the last Parse() failed (empty after success).
  const char* GetErrorText() const;

  /// Number of transforms read from CoordinateDefinitions.
  int GetNumberOfTransforms() const;
  /// Name of transform @p i as "<From>To<To>", e.g. "ImageToProbe".
  const char* GetTransformName(int i) const;

  /**
   * Copy the transform "<from>To<to>" into @p matrix (row-major semantics of vtkMatrix4x4: maps
   * points of frame @p from to frame @p to, mm). The inverse of a stored transform is found too.
   * Returns false when neither direction is stored.
   */
  bool GetTransform(const char* from, const char* to, vtkMatrix4x4* matrix) const;
  /// Same, with the name written as one word, e.g. "ImageToProbe".
  bool GetTransform(const char* name, vtkMatrix4x4* matrix) const;

  /// True when the VolumeReconstruction element gives ClipRectangleOrigin and ClipRectangleSize.
  vtkGetMacro(HasClipRectangle, bool);
  /// Clip rectangle in pixels: first column and row, then width and height.
  vtkGetVector2Macro(ClipRectangleOrigin, int);
  vtkGetVector2Macro(ClipRectangleSize, int);

  /// True when the VolumeReconstruction element describes a fan (FanAnglesDeg and FanOriginPixel).
  vtkGetMacro(HasFan, bool);
  /// Fan opening angles (degrees, from the image's +y axis, positive towards +x).
  vtkGetVector2Macro(FanAngles, double);
  /// Apex of the fan, pixels (column, row); may lie outside the image.
  vtkGetVector2Macro(FanOrigin, double);
  /// Inner and outer fan radius, pixels (outer 0 = unlimited).
  vtkGetVector2Macro(FanRadius, double);

protected:
  vtkUltrasoundCalibration();
  ~vtkUltrasoundCalibration() override;

  char* FileName = nullptr;
  bool HasClipRectangle = false;
  int ClipRectangleOrigin[2] = { 0, 0 };
  int ClipRectangleSize[2] = { 0, 0 };
  bool HasFan = false;
  double FanAngles[2] = { 0, 0 };
  double FanOrigin[2] = { 0, 0 };
  double FanRadius[2] = { 0, 0 };

private:
  vtkUltrasoundCalibration(const vtkUltrasoundCalibration&) = delete;
  void operator=(const vtkUltrasoundCalibration&) = delete;

  class vtkInternals;
  std::unique_ptr<vtkInternals> Internals;
};

#endif
