/**
 * @class   vtkGaussianFieldSequenceRenderer
 * @brief   Renders a Gaussian field at every frame pose of a tracked sequence (sibling of
 *          vtkGaussianFieldReslice).
 *
 * Input port 0: the Gaussian field (vtkPolyData). Input port 1: a tracked frame sequence (W x H x N,
 * field data ImageToReference; its pixels are not used). Output: a tracked frame sequence of the same
 * frame size with one rendered frame per chosen frame, in order, carrying the chosen frames'
 * ImageToReference, Timestamp, FrameValid and FrameIndex: it can be written with
 * vtkUltrasoundSequenceWriter and compared frame by frame (vtkUltrasoundImageMetrics).
 * Frames: all (default) or those of SetFrameList (indices into the sequence).
 * Point data (vtkGaussianFieldRenderer): scalars "Intensity" and "Coverage" (OutputCoverage).
 * The renderer and the converted field are kept between executes (vtkGaussianFieldRenderer).
 * Frames are rendered one at a time: UpdateProgress after each, and AbortExecute stops before the
 * next (the output is then left empty, so the next Update renders every frame).
 * Errors (those of vtkGaussianFieldRenderer, a malformed sequence, a frame index outside the
 * sequence, a bad pose) fail the request with vtkErrorMacro and leave the output empty.
 */
#ifndef vtkGaussianFieldSequenceRenderer_h
#define vtkGaussianFieldSequenceRenderer_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkGaussianFieldRenderer.h"

class vtkIdList;

class BIGUSFILTERS_EXPORT vtkGaussianFieldSequenceRenderer : public vtkGaussianFieldRenderer
{
public:
  static vtkGaussianFieldSequenceRenderer* New();
  vtkTypeMacro(vtkGaussianFieldSequenceRenderer, vtkGaussianFieldRenderer);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /**
   * The tracked sequence whose poses are rendered (port 1): W x H x N with field data
   * ImageToReference (N x 16, row-major, pixel -> mm).
   */
  void SetPoseConnection(vtkAlgorithmOutput* output) { this->SetInputConnection(1, output); }
  void SetPoseData(vtkDataObject* data) { this->SetInputData(1, data); }

  ///@{
  /**
   * Frames to render (indices into the pose sequence, in this order); null or empty = all. An index
   * outside the sequence fails the request.
   */
  void SetFrameList(vtkIdList* frames);
  vtkGetObjectMacro(FrameList, vtkIdList);
  ///@}

  /**
   * Seconds spent rendering in the last update, per frame (the renderer's time; the Coverage image is
   * not counted, so timings compare with renderers that have none).
   */
  vtkGetMacro(SecondsPerFrame, double);

protected:
  vtkGaussianFieldSequenceRenderer();
  ~vtkGaussianFieldSequenceRenderer() override;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  vtkIdList* FrameList = nullptr;
  double SecondsPerFrame = 0;

private:
  vtkGaussianFieldSequenceRenderer(const vtkGaussianFieldSequenceRenderer&) = delete;
  void operator=(const vtkGaussianFieldSequenceRenderer&) = delete;
};

#endif
