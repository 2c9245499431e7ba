/**
 * @class   vtkUltrasoundFrameInterpolator
 * @brief   The two frame baselines of view synthesis on a tracked sweep: predict each target frame
 *          from the training frames by nearest pose or by temporal blending.
 *
 * Input: a tracked frame sequence (DESIGN section 2): W x H x N `vtkImageData`, one-component scalars
 * (any type), field data `ImageToReference` (N x 16, row-major, pixel (column, row, 0, 1) -> mm),
 * `Timestamp` (N, seconds; needed by TemporalBlend) and, when present, `FrameValid`.
 *
 * Frames: TrainingFrames (indices into the sequence; required, every one valid) are the frames the
 * baseline may look at; TargetFrames (default: every frame not in TrainingFrames, in sequence order)
 * are the frames it predicts.
 *
 * Modes:
 * - NearestPose (default): the prediction is the training frame whose image centre, pixel
 *   (W / 2, H / 2) mapped to mm by its ImageToReference, is closest (Euclidean, mm) to the target's
 *   image centre; ties go to the training frame listed first.
 * - TemporalBlend: the training frames are ordered by Timestamp; the prediction is
 *   (1 - w) A + w B, w = (t - tA) / (tB - tA), of the two training frames A, B whose timestamps
 *   bracket the target's t (tA <= t <= tB); before the first or after the last training frame, the
 *   nearest one in time (w = 0). Equal timestamps give w = 0.
 *
 * Output: a tracked frame sequence, W x H x M (M = number of targets, frame m = target m), spacing 1,
 * origin 0, scalars "Intensity" (float, the input's intensity units), carrying the targets' per-frame
 * field data (every field array with N tuples, e.g. ImageToReference, Timestamp, FrameValid, and the
 * reader's FrameIndex; FrameIndex = the target's index into the sequence when the input has none),
 * like vtkGaussianFieldSequenceRenderer's output, so that vtkUltrasoundImageMetrics can compare it
 * with the same frames of the recorded sweep. Two more per-frame arrays say what was used:
 * `SourceFrames` (2 ints: the training frames A and B, equal for NearestPose) and `BlendWeight`
 * (double: w, the weight of B). A target whose FrameValid is 0 (its pose must not be used) is
 * predicted as zeros, keeps FrameValid = 0 and gets SourceFrames -1 -1; a warning says how many.
 *
 * Errors fail the request with vtkErrorMacro and an empty output: no input or pixels, scalars with
 * more than one component, no `ImageToReference` or one of the wrong size, no `Timestamp` (or one of
 * the wrong size) in TemporalBlend mode, an empty training list, a training or target index outside
 * the sequence, a training frame with FrameValid = 0, a non-finite or non-affine pose of a used frame,
 * or no target frame at all.
 */
#ifndef vtkUltrasoundFrameInterpolator_h
#define vtkUltrasoundFrameInterpolator_h

#include "bigusFiltersModule.h" // For export macro
#include "vtkImageAlgorithm.h"

class vtkIdList;

class BIGUSFILTERS_EXPORT vtkUltrasoundFrameInterpolator : public vtkImageAlgorithm
{
public:
  static vtkUltrasoundFrameInterpolator* New();
  vtkTypeMacro(vtkUltrasoundFrameInterpolator, vtkImageAlgorithm);
  void PrintSelf(ostream& os, vtkIndent indent) override;

  ///@{ Frames the baseline may use (indices into the sequence). Required.
  void SetTrainingFrames(vtkIdList* frames);
  vtkGetObjectMacro(TrainingFrames, vtkIdList);
  ///@}

  ///@{ Frames to predict (indices into the sequence); nullptr or empty = every frame not in
  /// TrainingFrames.
  void SetTargetFrames(vtkIdList* frames);
  vtkGetObjectMacro(TargetFrames, vtkIdList);
  ///@}

  enum Modes
  {
    NEAREST_POSE = 0,
    TEMPORAL_BLEND = 1
  };
  ///@{ NearestPose (default) or TemporalBlend, see the class description.
  vtkSetClampMacro(Mode, int, NEAREST_POSE, TEMPORAL_BLEND);
  vtkGetMacro(Mode, int);
  void SetModeToNearestPose() { this->SetMode(NEAREST_POSE); }
  void SetModeToTemporalBlend() { this->SetMode(TEMPORAL_BLEND); }
  const char* GetModeAsString();
  ///@}

  /// Includes the frame lists.
  vtkMTimeType GetMTime() override;

protected:
  vtkUltrasoundFrameInterpolator();
  ~vtkUltrasoundFrameInterpolator() override;

  int RequestInformation(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestUpdateExtent(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;
  int RequestData(vtkInformation*, vtkInformationVector**, vtkInformationVector*) override;

  vtkIdList* TrainingFrames = nullptr;
  vtkIdList* TargetFrames = nullptr;
  int Mode = NEAREST_POSE;

private:
  vtkUltrasoundFrameInterpolator(const vtkUltrasoundFrameInterpolator&) = delete;
  void operator=(const vtkUltrasoundFrameInterpolator&) = delete;
};

#endif
