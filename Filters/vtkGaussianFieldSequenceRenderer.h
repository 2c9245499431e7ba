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
 * Scalars "Intensity": float in [0, 1] (default) or unsigned char; ElevationSigma < 0 uses the field's.
 * Errors (malformed field or sequence, a frame index outside the sequence, a bad pose) fail the request.
 */
#ifndef vtkGaussianFieldSequenceRenderer_h
#define vtkGaussianFieldSequenceRenderer_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkImageAlgorithm.h"

class vtkIdList;

class BIGUSFILTERS_EXPORT vtkGaussianFieldSequenceRenderer : public vtkImageAlgorithm
{
public:
  static vtkGaussianFieldSequenceRenderer* New();
  vtkTypeMacro(vtkGaussianFieldSequenceRenderer, vtkImageAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  /// The tracked sequence whose poses are rendered (port 1).
  void SetPoseConnection(vtkAlgorithmOutput* output) { this->SetInputConnection(1, output); }
  void SetPoseData(vtkDataObject* data) { this->SetInputData(1, data); }

  ///@{ Frames to render (indices into the pose sequence); empty = all.
  void SetFrameList(vtkIdList* frames);
  vtkGetObjectMacro(FrameList, vtkIdList);
  ///@}
  vtkSetMacro(ElevationSigma, double);
  vtkGetMacro(ElevationSigma, double);
  vtkSetClampMacro(Cutoff, double, 1.0, 20.0);
  vtkGetMacro(Cutoff, double);
  vtkSetMacro(OutputScalarType, int);
  vtkGetMacro(OutputScalarType, int);
  void SetOutputScalarTypeToFloat() { this->SetOutputScalarType(VTK_FLOAT); }
  void SetOutputScalarTypeToUnsignedChar() { this->SetOutputScalarType(VTK_UNSIGNED_CHAR); }

  /// Seconds spent rendering in the last update, per frame.
  vtkGetMacro(SecondsPerFrame, double);

protected:
  vtkGaussianFieldSequenceRenderer();
  ~vtkGaussianFieldSequenceRenderer() override;

  int FillInputPortInformation(int port, vtkInformation* info) override;
  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  vtkIdList* FrameList = nullptr;
  double ElevationSigma = -1;
  double Cutoff = 5.0;
  int OutputScalarType = VTK_FLOAT;
  double SecondsPerFrame = 0;

private:
  vtkGaussianFieldSequenceRenderer(const vtkGaussianFieldSequenceRenderer&) = delete;
  void operator=(const vtkGaussianFieldSequenceRenderer&) = delete;
};

#endif
