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

} // namespace bigus

#endif
