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
 * Point data "Coverage" (float, OutputCoverage, default on): how much training data supports each
 * rendered pixel, the summed elevation weight sum_t [inside frame t's fan] exp(-d_t^2 / (2 sigma_E^2))
 * of the training frames t at distance d_t (mm), as vtkGaussianFieldReslice defines it (see there and
 * bigus::TrainingCoverage); about 1 on a training frame, about 0 in a gap wider than the beam. Only a
 * field that carries its training geometry (vtkGaussianFieldTrainer's output) has it; malformed
 * geometry fails the request with an error naming the array.
 * The renderer (Backend) and the field converted to the renderer's form are kept between executes and
 * rebuilt only when Backend or the field input (object or MTime) changes.
 * Frames are rendered one at a time: UpdateProgress after each, and AbortExecute stops before the
 * next (the output is then left empty, so the next Update renders every frame).
 * Errors (malformed field or sequence, malformed training geometry with OutputCoverage on, a frame
 * index outside the sequence, a bad pose, an unavailable backend) fail the request with vtkErrorMacro
 * and leave the output empty.
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

  ///@{
  /**
   * Elevation beam sigma (mm); negative (default) = the field's ElevationSigma.
   */
  vtkSetMacro(ElevationSigma, double);
  vtkGetMacro(ElevationSigma, double);
  ///@}

  ///@{
  /**
   * Footprint cutoff k (standard deviations, clamped to [1, 20]). Default 5 (float error in I below
   * 1e-5).
   */
  vtkSetClampMacro(Cutoff, double, 1.0, 20.0);
  vtkGetMacro(Cutoff, double);
  ///@}

  ///@{
  /**
   * Also output float point data "Coverage" (see the class description) when the field carries its
   * training geometry. Default on.
   */
  vtkSetMacro(OutputCoverage, bool);
  vtkGetMacro(OutputCoverage, bool);
  vtkBooleanMacro(OutputCoverage, bool);
  ///@}

  ///@{
  /**
   * Scalar type of "Intensity": VTK_FLOAT (default, I in [0, 1]) or VTK_UNSIGNED_CHAR
   * (round(255 I)). Any other type is refused with vtkErrorMacro and the previous type kept, so the
   * scalar type announced in the pipeline information is the one produced.
   */
  virtual void SetOutputScalarType(int type);
  vtkGetMacro(OutputScalarType, int);
  void SetOutputScalarTypeToFloat() { this->SetOutputScalarType(VTK_FLOAT); }
  void SetOutputScalarTypeToUnsignedChar() { this->SetOutputScalarType(VTK_UNSIGNED_CHAR); }
  ///@}

  ///@{
  /**
   * Rendering backend, by name in the backend registry (bigusBackend.h): "auto" (default: the
   * available backend of highest priority, CUDA where it is built and a device is usable, else the
   * CPU, with a warning that says why a backend was skipped), "cpu", "cuda". A backend that cannot
   * run here fails the request with an error naming it and the available ones; no silent fallback.
   * The renderer is kept between executes and created again only when this name changes.
   */
  vtkSetStringMacro(Backend);
  vtkGetStringMacro(Backend);
  ///@}

  /**
   * Seconds spent rendering in the last update, per frame (the renderer's time; the Coverage image is
   * not counted, so timings compare with renderers that have none).
   */
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
  bool OutputCoverage = true;
  int OutputScalarType = VTK_FLOAT;
  char* Backend = nullptr;
  double SecondsPerFrame = 0;

private:
  class vtkInternals;
  vtkInternals* Internals;

  vtkGaussianFieldSequenceRenderer(const vtkGaussianFieldSequenceRenderer&) = delete;
  void operator=(const vtkGaussianFieldSequenceRenderer&) = delete;
};

#endif
