/**
 * @file bigusFrameMetrics.h
 * @brief The metrics of rendered frames against a sweep's recorded frames (DESIGN section 9), averaged
 *        over the frames: what the trainer's Evaluate, `bigus evaluate` and `bigus benchmark` report.
 */
#ifndef bigusFrameMetrics_h
#define bigusFrameMetrics_h

#include "bigusImageMetrics.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace bigus
{

/**
 * Mean metrics (bigus::CompareImages) of one [H, W] image per frame against @p frames of @p data, each
 * inside that frame's mask; frames whose mask is empty are left out of the means (and @p image is not
 * called for them). @p image(m, f) gives the image for the m-th entry f of @p frames. @p perFrame, if
 * non-null, receives one entry per entry of @p frames: that frame's metrics, or empty for a frame left out.
 */
BIGUSTRAINING_EXPORT ImageMetrics MeanFrameMetrics(const TrainingData& data, const std::vector<int>& frames,
  const std::function<const float*(std::size_t, int)>& image,
  std::vector<std::optional<ImageMetrics>>* perFrame = nullptr);

/**
 * Intensities in [0, 1] of @p engine's field rendered at the pose of frame @p frame of @p data with @p options into
 * @p image ([H, W] of @p data); @p scratch holds the scattering image S. Returns false with @p error ("frame F: ...")
 * for a pose the renderer rejects.
 */
BIGUSTRAINING_EXPORT bool RenderFrame(TrainingEngine& engine, const TrainingData& data, int frame,
  const RenderOptions& options, std::vector<float>& scratch, float* image, std::string* error);

/**
 * MeanFrameMetrics of @p engine's field rendered (RenderFrame) at @p frames of @p data. @p secondsPerFrame, if
 * non-null, receives the mean render time per frame (s). Returns false with @p error when a frame cannot be rendered.
 */
BIGUSTRAINING_EXPORT bool EvaluateFrames(TrainingEngine& engine, const TrainingData& data,
  const std::vector<int>& frames, const RenderOptions& options, ImageMetrics& metrics, std::string* error,
  double* secondsPerFrame = nullptr);

} // namespace bigus

#endif
