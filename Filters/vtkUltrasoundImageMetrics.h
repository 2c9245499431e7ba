/**
 * @class   vtkUltrasoundImageMetrics
 * @brief   Image quality of rendered ultrasound frames against recorded ones: PSNR, SSIM, NCC and
 *          speckle score per frame, in a table.
 *
 * Inputs:
 * - port 0: the rendered frames, a W x H x N `vtkImageData` (frame k = slice k; N = 1 for one image);
 * - port 1: the ground-truth frames, W x H x N as well, usually a tracked frame sequence (DESIGN
 *   section 2) whose field data `FrameValid` and `FrameIndex` are used when present
 *   (SetTruthConnection / SetTruthData);
 * - port 2, optional: the fan mask, a W x H x 1 image such as vtkUltrasoundFanMask's `FanMask`, or one
 *   mask per frame, W x H x N (e.g. vtkUltrasoundSequenceReslice's port 1: where the volume has data)
 *   (SetMaskConnection / SetMaskData); non-zero = imaged pixel. Without it every pixel counts. A frame
 *   whose own mask is empty is left out of the table.
 * Scalars have one component: unsigned char (intensity / 255) or float / double already in [0, 1], so
 * that every metric uses data range 1.
 *
 * Output: a `vtkTable` with one row per compared frame, columns
 * - `Frame` (int): the truth's `FrameIndex` value of the frame when the truth carries that array
 *   (N values), otherwise the slice number k;
 * - `PSNR` (double, dB): 10 log10(1 / MSE) over the masked pixels, capped at 100 dB (identical frames);
 * - `SSIM` (double): mean over the masked pixels of the SSIM map (Wang et al., IEEE TIP 2004, Eq. 13;
 *   11 x 11 Gaussian window of sigma 1.5 pixels, C1 = 0.01^2, C2 = 0.03^2, zero padding at the image
 *   border). The images themselves are not masked, so the windows of masked pixels at the fan border
 *   also see the pixels up to 5 pixels outside the mask; PSNR, NCC and Speckle see masked pixels only;
 * - `NCC` (double): Pearson correlation of the masked pixels (undefined when either frame is constant
 *   there: then 0 or a rounding artefact);
 * - `Speckle` (double): the Backscatter Fidelity Score in [0, 1] from the speckle contrast of the
 *   16 x 16 patches (stride 8) that lie wholly inside the mask and have a positive mean in both frames;
 *   NaN when there is no such patch;
 * and, last, one summary row with `Frame` = -1 holding the mean of each column over the frame rows
 * (NaN entries left out of the mean; NaN when no frame row has a value). The PSNR mean is the mean of
 * the per-frame dB values. The formulas are those of bigus::CompareImages (bigusImageMetrics.h), which
 * is called once per frame; rendered and truth enter it in that order (the speckle score is not
 * symmetric: it is relative to the truth's speckle statistics).
 *
 * FrameValidOnly (default on) skips the frames whose truth `FrameValid` value is 0 (they get no row);
 * when every frame is skipped the table holds only the summary row (NaN means) and a warning is given.
 *
 * Errors fail the request with vtkErrorMacro, an empty table and NaN means: a missing input, rendered
 * and truth frames of different sizes or frame counts (the message gives both W x H x N), scalars with
 * more than one component or of another type, a mask whose size is not W x H x 1 (both sizes given)
 * and a mask without any imaged pixel.
 */
#ifndef vtkUltrasoundImageMetrics_h
#define vtkUltrasoundImageMetrics_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkTableAlgorithm.h"

class BIGUSFILTERS_EXPORT vtkUltrasoundImageMetrics : public vtkTableAlgorithm
{
public:
  static vtkUltrasoundImageMetrics* New();
  vtkTypeMacro(vtkUltrasoundImageMetrics, vtkTableAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// Ground-truth frames on input port 1.
  void SetTruthConnection(vtkAlgorithmOutput* output) { this->SetInputConnection(1, output); }
  void SetTruthData(vtkDataObject* truth) { this->SetInputData(1, truth); }

  /// Fan mask on the optional input port 2 (nullptr removes it: every pixel counts).
  void SetMaskConnection(vtkAlgorithmOutput* output) { this->SetInputConnection(2, output); }
  void SetMaskData(vtkDataObject* mask) { this->SetInputData(2, mask); }

  /// Skip the frames whose truth FrameValid value is 0 (default on; no effect without FrameValid).
  vtkSetMacro(FrameValidOnly, bool);
  vtkGetMacro(FrameValidOnly, bool);
  vtkBooleanMacro(FrameValidOnly, bool);

  ///@{
  /// Means over the frame rows of the last update (the summary row's values); NaN before an update,
  /// after an error, or when no frame was compared.
  vtkGetMacro(MeanPSNR, double);
  vtkGetMacro(MeanSSIM, double);
  vtkGetMacro(MeanNCC, double);
  vtkGetMacro(MeanSpeckle, double);
  ///@}

protected:
  vtkUltrasoundImageMetrics();
  ~vtkUltrasoundImageMetrics() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  bool FrameValidOnly = true;
  double MeanPSNR;
  double MeanSSIM;
  double MeanNCC;
  double MeanSpeckle;

private:
  vtkUltrasoundImageMetrics(const vtkUltrasoundImageMetrics&) = delete;
  void operator=(const vtkUltrasoundImageMetrics&) = delete;

  void ResetMeans();
};

#endif
