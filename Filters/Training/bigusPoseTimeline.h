/**
 * @file bigusPoseTimeline.h
 * @brief The tracked path of a sweep in time, for the refinement of a tracker-to-video time offset.
 *
 * A tracked frame's ImageToReference is the tracker's pose at the frame's video timestamp. When the tracker's
 * clock and the video's are off by a constant delay (latency, a temporal calibration left undone), the pose
 * that truly belongs to frame f is the tracked pose at Timestamp[f] + offset. For offsets of the order of
 * tens of milliseconds PoseTimeline takes that pose to first order: frame f's tracked pose moved along the
 * path's velocity there,
 *
 *     P_f(offset) = CorrectPose(P_f, offset v_f),    v_f = (xi_fb - xi_fa) / (t_b - t_a),
 *
 * xi_fa and xi_fb the corrections (PoseCorrectionBetween) from frame f to the frames a and b of its sweep
 * about Window / 2 before and after it (the sweep's first and last frames at its ends; frames marked invalid
 * (TrainingData::Valid) or whose pose the renderer rejects left out), so d P_f / d offset = v_f exactly, and a
 * loss's gradient with respect to the offset is the pose gradient (FieldGradients::SlicePoses) dotted with v_f
 * (to first order when further corrections follow the offset, as in the trainer). Why not interpolate between the
 * tracked poses on either side of the shifted time: with a tracker's error in every pose, moving a frame
 * towards its neighbour's pose averages its own error away whatever the sign of the offset, so the offset
 * that fits best is biased towards half a frame interval; the velocity over a window is independent of the
 * frame's own error.
 */
#ifndef bigusPoseTimeline_h
#define bigusPoseTimeline_h

#include "bigusSliceFrame.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <array>
#include <string>
#include <vector>

namespace bigus
{

/**
 * The rigid correction @p xi (rotation vector, rad, about the centre pixel of a @p width x @p height slice;
 * translation, mm; both in @p from's rendering axes, as bigus::CorrectPose takes it) that moves the slice
 * of pose @p from onto the slice of pose @p to: CorrectPose(from, width, height, xi) = to when @p to is
 * @p from moved rigidly (pixel spacing and shear alike). The inverse of CorrectPose. Returns the status of
 * the first pose the renderer rejects (@p xi untouched then).
 */
BIGUSTRAINING_EXPORT PoseStatus PoseCorrectionBetween(
  const double from[16], const double to[16], int width, int height, double xi[6]);

/// What bigus::CorrectUntrainedFrames chose (TrainerReport; field data UntrainedPoseCorrection).
struct BIGUSTRAINING_EXPORT UntrainedCorrection
{
  int Frames = 0;         ///< the frames given a correction
  double Bandwidth = 0;   ///< the kernel's standard deviation in training-frame intervals; 0: none; infinity: the mean
  double ErrorNone = 0;   ///< leave-one-out rms error (mm at the slice's corners) of a zero correction
  double ErrorChosen = 0; ///< the same of the chosen kernel (ErrorNone when none)
};

/**
 * The pose corrections of the frames that were not trained (held out), from those of their sweep's training
 * frames: each valid frame of @p data outside TrainFrames takes the mean of its sweep's training frames'
 * corrections weighted by a Gaussian kernel in time (Nadaraya-Watson regression; time is the timestamp where @p data
 * has one per frame, else the frame index). The kernel's standard deviation is chosen by leave-one-out
 * prediction of the training frames' own corrections (each from the others of its sweep) among 0.5, 1, 2, 4, 8
 * and 16 times the sweep's median interval between training frames and the sweep's plain mean; where none
 * predicts better than no correction at all, none is applied (the frames keep @p corrections as given). The
 * error of a prediction is its displacement at the slice's corners: |translation|^2 + r^2 |rotation|^2, r half
 * the slice's diagonal (mm). @p corrections ([N]; rotation vector, rad, and translation, mm, each in its frame's
 * rendering axes as bigus::CorrectPose takes them; averaged as 6-vectors: neighbouring frames' axes nearly agree)
 * holds the training frames' on input. Frames marked invalid, and sweeps without a training frame, keep theirs.
 * Why: what refinement corrects along a tracked sweep (tracker drift, latency, the field's slow motion against
 * the tracked poses) varies smoothly, so a held-out frame is better placed with the smooth part of its
 * neighbours' corrections than at its tracked pose, while errors independent from frame to frame are left alone
 * because they predict nothing (docs/FINDINGS.md, "Held-out frames between refined ones").
 */
BIGUSTRAINING_EXPORT UntrainedCorrection CorrectUntrainedFrames(
  const TrainingData& data, std::vector<std::array<double, 6>>& corrections);

/**
 * How much a sweep's tracked path jitters from frame to frame (mm): the root mean square, over the valid frames of
 * sweep @p sweep of @p data (TrainingData::IsValid, with a pose the renderer accepts; every frame, trained on or not:
 * they share one tracker) in sequence order, of the distance of each of a frame's four corner pixels (those of the
 * frames' shared Width x Height grid) from the midpoint of the same corners of the frames before and after it (the
 * path's second difference), divided by sqrt(3/2). Independent errors of each frame's pose whose displacement at the
 * corners has root mean square e give e in expectation (the second difference of independent errors has variance
 * (1 + 1/4 + 1/4) e^2); motion smooth over three frames gives half the corners' acceleration times the frame interval
 * squared. Returns -1 where the sweep has fewer than three such frames. The bundled sweeps' and the synthetic
 * sweeps' values: docs/FINDINGS.md, "The pose refinement's start chosen from the tracked path".
 */
BIGUSTRAINING_EXPORT double TrackedPathJitter(const TrainingData& data, int sweep);

/// The tracked path's jitter below which PosePriorScale takes this (mm): a path without measurable jitter.
constexpr double PosePriorLeastJitter = 0.01;

/// The frames' pose prior moves their corners by this many times their sweep's tracked-path jitter (rms;
/// PoseRefinementSettings::PriorFromPath): 1 and 2 score alike on the jittered liver (within 0.03 dB at 0.1 and 0.5
/// degrees and mm), 1 misses the synthetic case's aims (corner error 0.597 -> 0.308 mm, fair PSNR 0.7 dB under the
/// true poses'), 2 meets them.
constexpr double PosePriorJitterRatio = 2;

/**
 * The factor on a pose prior's sigmas (@p rotationSigma, rad, and @p translationSigma, mm, per component of a
 * frame's correction) that makes the prior's root mean square displacement of the corners of sweep @p sweep's frames
 * equal to @p jitter (mm; the sweep's TrackedPathJitter, at least PosePriorLeastJitter): jitter / sqrt(3
 * translationSigma^2 + 2 rotationSigma^2 R^2), R^2 the mean squared distance of the four corner pixels from the centre
 * pixel (mm^2) on the sweep's first valid frame. With independent components, E|t|^2 = 3 sigma_t^2 and
 * E|omega x r|^2 = 2 sigma_r^2 |r|^2. The prior is then a tracker's noise as the path shows it: where poses are nearly
 * right it holds the corrections near them, where the path jitters it lets them move. Returns 1 where @p jitter is
 * negative (too few frames to measure) or the sweep has no valid frame. Measured on the liver with its training poses
 * moved by 0.1 to 0.5 degrees and mm: docs/FINDINGS.md, "The pose prior from the tracked path".
 */
BIGUSTRAINING_EXPORT double PosePriorScale(
  const TrainingData& data, int sweep, double jitter, double rotationSigma, double translationSigma);

/// When the pose corrections start to move (TrainerSettings::PoseRefinementStart negative), and why.
struct BIGUSTRAINING_EXPORT PoseRefinementStartChoice
{
  double Start = 0.2;   ///< share of the schedule trained on the tracked poses first
  std::string Reason;   ///< one line: the rule and each sweep's jitter
  bool Jitters = false; ///< a sweep's path jitters over PoseRefinementEarlyJitter (Start is then 0)
};

/// The tracked path's jitter (mm, TrackedPathJitter) above which the corrections move from the first step: about
/// the geometric mean of the real sweeps' 0.25 mm and the synthetic case's 0.48 (a margin of 1.4 to each).
constexpr double PoseRefinementEarlyJitter = 0.35;

/**
 * The pose refinement's start for @p data: 0 (the corrections move from the first step) where the tracked path of
 * a sweep in @p sweeps ([sweeps] 1 where the sweep's poses are corrected; empty: every sweep) jitters by more than
 * PoseRefinementEarlyJitter, else 0.2 (the first fifth of the schedule on the tracked poses).
 * Where the poses are far off, a field that takes shape on them fits their errors before the corrections move;
 * where they are nearly right, early corrections chase a field not yet formed. The bundled real sweeps jitter
 * alike whether an early start helps or costs them, so the rule keeps 0.2 for them (the larger effect is a
 * loss); the synthetic case starts at 0. The measurements: docs/FINDINGS.md, "When pose refinement starts"
 * and "The pose refinement's start chosen from the tracked path".
 */
BIGUSTRAINING_EXPORT PoseRefinementStartChoice ChoosePoseRefinementStart(
  const TrainingData& data, const std::vector<char>& sweeps);

class BIGUSTRAINING_EXPORT PoseTimeline
{
public:
  /**
   * The velocity of each frame's tracked path from @p data's Poses (the tracked ones: take them before any
   * correction), Timestamps (s) and Sweeps, over a window of @p window seconds. Returns false with @p error
   * when @p data has no timestamps (one per frame), a timestamp is not finite, or a sweep has no two frames
   * with a pose the renderer accepts and different timestamps.
   */
  bool Build(const TrainingData& data, double window, std::string* error);

  /// Frame @p frame's tracked pose ([16], row-major ImageToReference) at its timestamp plus @p offset (s),
  /// to first order; with @p offset 0 its own tracked pose, exactly.
  void PoseAt(int frame, double offset, double pose[16]) const;

  /// d xi / d offset of frame @p frame ([6]: rotation, rad/s; translation, mm/s; in its rendering axes about
  /// its centre pixel); zero for a frame left out of the path.
  const std::array<double, 6>& Velocity(int frame) const { return this->Velocities[frame]; }

  /// Whether Build succeeded for @p frames frames.
  bool IsBuilt(int frames) const { return static_cast<int>(this->Velocities.size()) == frames && frames > 0; }

private:
  int Width = 0, Height = 0;
  std::vector<std::array<double, 16>> Poses;     ///< [N] tracked
  std::vector<std::array<double, 6>> Velocities; ///< [N]
};

} // namespace bigus

#endif
