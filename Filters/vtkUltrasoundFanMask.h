/**
 * @class   vtkUltrasoundFanMask
 * @brief   Fan / field-of-view mask of a tracked ultrasound sweep: which pixels image tissue.
 *
 * Input: a tracked frame sequence (W x H x N `vtkImageData`, DESIGN section 2).
 * Output: a W x H x 1 `vtkImageData` of unsigned char scalars named "FanMask" (1 = imaged region,
 * 0 = background), spacing 1 1 1, origin 0 0 0. This image is how BIGUS keeps the fan mask everywhere:
 * filters that need it take it on an input port of its own beside the frames.
 *
 * Modes:
 * - Estimate (default): a pixel is a candidate when it exceeds BackgroundThreshold in any valid frame
 *   (FrameValid != 0); the candidates are opened morphologically (removes isolated speckle and thin
 *   overlay text; radius OpeningRadius pixels), the largest 8-connected component is kept, closed
 *   (radius ClosingRadius) and its holes filled (anechoic regions inside the fan stay inside).
 * - Calibration: the clip rectangle and/or fan of a PLUS configuration XML (CalibrationFileName),
 *   intersected. The fan is the set of pixels whose angle atan2(dx, dy) from FanOriginPixel (dx along
 *   columns, dy along rows, degrees) lies within FanAnglesDeg and whose distance lies within
 *   FanRadiusStartPixel..FanRadiusStopPixel (stop 0 = unlimited).
 *
 * Morphology and connected components use OpenCV (imgproc). Errors (no frames, a multi-component
 * input, a calibration without a clip rectangle or fan, a clip rectangle outside the image) fail the
 * request with vtkErrorMacro.
 */
#ifndef vtkUltrasoundFanMask_h
#define vtkUltrasoundFanMask_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkImageAlgorithm.h"

class BIGUSFILTERS_EXPORT vtkUltrasoundFanMask : public vtkImageAlgorithm
{
public:
  static vtkUltrasoundFanMask* New();
  vtkTypeMacro(vtkUltrasoundFanMask, vtkImageAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  enum Modes
  {
    ESTIMATE = 0,
    CALIBRATION = 1
  };
  vtkSetClampMacro(Mode, int, ESTIMATE, CALIBRATION);
  vtkGetMacro(Mode, int);
  void SetModeToEstimate() { this->SetMode(ESTIMATE); }
  void SetModeToCalibration() { this->SetMode(CALIBRATION); }

  /// Intensity at or below which a pixel is background (input units; default 0).
  vtkSetMacro(BackgroundThreshold, double);
  vtkGetMacro(BackgroundThreshold, double);

  /// Radius (pixels) of the opening that removes speckle and overlay text (default 2).
  vtkSetClampMacro(OpeningRadius, int, 0, 100);
  vtkGetMacro(OpeningRadius, int);

  /// Radius (pixels) of the closing that smooths the fan border (default 5).
  vtkSetClampMacro(ClosingRadius, int, 0, 100);
  vtkGetMacro(ClosingRadius, int);

  /// PLUS device-set configuration XML with ClipRectangle* and/or Fan* attributes (Calibration mode).
  vtkSetStringMacro(CalibrationFileName);
  vtkGetStringMacro(CalibrationFileName);

protected:
  vtkUltrasoundFanMask();
  ~vtkUltrasoundFanMask() override;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  int Mode = ESTIMATE;
  double BackgroundThreshold = 0.0;
  int OpeningRadius = 2;
  int ClosingRadius = 5;
  char* CalibrationFileName = nullptr;

private:
  vtkUltrasoundFanMask(const vtkUltrasoundFanMask&) = delete;
  void operator=(const vtkUltrasoundFanMask&) = delete;
};

#endif
