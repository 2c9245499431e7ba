/**
 * @class   vtkGaussianFieldRenderer
 * @brief   Abstract superclass of the filters that render ultrasound images of a Gaussian scattering
 *          field: vtkGaussianFieldReslice (any plane or stack) and vtkGaussianFieldSequenceRenderer
 *          (every pose of a tracked sequence).
 *
 * Input port 0: a Gaussian field (vtkPolyData, DESIGN section 2; vtkGaussianFieldTrainer's output),
 * needed whole for any part of the output. Further input ports (a subclass's pose sequence) are
 * vtkImageData, requested whole (their poses come with the whole sequence).
 * Output: vtkImageData on a grid of the subclass's (a slice, a stack, a frame per pose), whose point
 * data the subclasses share:
 * - scalars "Intensity": I = 1 - exp(-gamma max(S, 0)), S the signed scattering field, as float in
 *   [0, 1] or unsigned char (x 255, rounded; OutputScalarType). ElevationSigma (mm) and gamma default
 *   to the field's (field data); Cutoff is the renderer's k.
 * - "Coverage" (float, dimensionless; OutputCoverage, default on) says how much training data
 *   supports each pixel (voxel of a stack), so that a viewer can tell data from interpolation: for a
 *   pixel at x (mm),
 *   Coverage(x) = sum over training frames t of [x projects inside t's fan mask] exp(-d_t(x)^2 / (2 sigma_E^2)),
 *   d_t(x) the distance (mm) from x to frame t's plane, the projection made with frame t's
 *   ImageToReference, sigma_E the ElevationSigma of the render (mm). A pixel on a training frame inside
 *   its fan has about 1 (plus its neighbours' share), a pixel in a gap wider than the beam about 0.
 *   Frames further than 4 sigma_E are left out (less than 3.4e-4 each); details in
 *   bigus::TrainingCoverage (bigusGaussianFieldData.h). It needs the field's training geometry (field
 *   data TrainingPoses, TrainingFrameSize, TrainingFanMask, written by vtkGaussianFieldTrainer): a
 *   field without those arrays (an older file, a hand-made field) renders with no Coverage array; a
 *   field whose arrays are malformed fails the request with an error naming the array (turn
 *   OutputCoverage off to render it without coverage).
 *
 * The renderer (Backend) and the field converted to the renderer's form are kept between executes,
 * rebuilt only when Backend or the field input (object or MTime) changes, so that a new pose
 * re-renders without converting the field again.
 *
 * A vtkThreadedImageAlgorithm, as vtkImageReslice is, so that a script's threading calls (NumberOfThreads,
 * EnableSMP, SplitMode, DesiredBytesPerPiece, MinimumPieceSize) are accepted; they are stored without effect: the
 * renderers run on vtkSMPTools' threads (VTK_SMP_MAX_THREADS / vtkSMPTools::Initialize), every output whole.
 *
 * Errors shared by the subclasses (no field or a malformed field, malformed training geometry with
 * OutputCoverage on, an unavailable backend) fail the request with vtkErrorMacro and leave the output
 * empty.
 */
#ifndef vtkGaussianFieldRenderer_h
#define vtkGaussianFieldRenderer_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkThreadedImageAlgorithm.h"

namespace bigus
{
class FieldCache;
struct RenderSetup;
}

class BIGUSFILTERS_EXPORT vtkGaussianFieldRenderer : public vtkThreadedImageAlgorithm
{
public:
  vtkAbstractTypeMacro(vtkGaussianFieldRenderer, vtkThreadedImageAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

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
   * Also output float point data "Coverage", the training data's support of each pixel (see the class
   * description), when the field carries its training geometry. Default on.
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

protected:
  vtkGaussianFieldRenderer();
  ~vtkGaussianFieldRenderer() override;

  /// Port 0 takes the field (vtkPolyData), any other port vtkImageData.
  int FillInputPortInformation(int port, vtkInformation* info) override;
  /// The field is needed whole (it has no extent); every other input port is asked for its whole extent.
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  /**
   * The field of input port 0 in the renderer's form, kept between executes (see the class
   * description); FieldCache::Update brings it up to date.
   */
  bigus::FieldCache& GetFieldCache();

  /**
   * The opening of every RequestData: brings the field of input port 0 up to date, gets the renderer of
   * Backend (a warning says which backend "auto" skipped and why), the field's training coverage when
   * OutputCoverage asks for it, and the render options (the field's gamma, ElevationSigma, Cutoff),
   * into @p setup. Returns false after vtkErrorMacro for the shared errors of the class description.
   */
  bool BeginRender(vtkInformationVector** inputVector, bigus::RenderSetup& setup);

  double ElevationSigma = -1;
  double Cutoff = 5.0;
  bool OutputCoverage = true;
  int OutputScalarType = VTK_FLOAT;
  char* Backend = nullptr;

private:
  class vtkInternals;
  vtkInternals* Internals;

  vtkGaussianFieldRenderer(const vtkGaussianFieldRenderer&) = delete;
  void operator=(const vtkGaussianFieldRenderer&) = delete;
};

#endif
