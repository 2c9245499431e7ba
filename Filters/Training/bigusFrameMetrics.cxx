// Mean image metrics over the frames of a sweep (see bigusFrameMetrics.h).
#include "bigusFrameMetrics.h"

#include <algorithm>

namespace bigus
{

ImageMetrics MeanFrameMetrics(const TrainingData& data, const std::vector<int>& frames,
  const std::function<const float*(std::size_t, int)>& image, std::vector<std::optional<ImageMetrics>>* perFrame)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  ImageMetrics mean;
  int used = 0;
  if (perFrame)
  {
    perFrame->assign(frames.size(), std::nullopt);
  }
  for (std::size_t m = 0; m < frames.size(); ++m)
  {
    const int f = frames[m];
    const unsigned char* mask = data.MaskOf(f);
    if (std::none_of(mask, mask + pixels, [](unsigned char v) { return v != 0; }))
    {
      continue; // nothing of this frame is imaged (a per-frame mask outside the data)
    }
    const ImageMetrics q = CompareImages(image(m, f), &data.Frames[pixels * f], mask, data.Width, data.Height);
    if (perFrame)
    {
      (*perFrame)[m] = q;
    }
    mean.PSNR += q.PSNR;
    mean.SSIM += q.SSIM;
    mean.NCC += q.NCC;
    mean.Speckle += q.Speckle;
    mean.Patches += q.Patches;
    ++used;
  }
  const double n = std::max(1, used);
  mean.PSNR /= n;
  mean.SSIM /= n;
  mean.NCC /= n;
  mean.Speckle /= n;
  return mean;
}

bool RenderFrame(TrainingEngine& engine, const TrainingData& data, int frame, const RenderOptions& options,
  std::vector<float>& scratch, float* image, std::string* error)
{
  const SliceGeometry slice = data.Slice(frame);
  scratch.resize(std::size_t(data.Width) * data.Height);
  if (!engine.Render(&slice, 1, options, scratch.data(), image, error))
  {
    if (error)
    {
      *error = "frame " + std::to_string(frame) + ": " + *error;
    }
    return false;
  }
  return true;
}

bool EvaluateFrames(TrainingEngine& engine, const TrainingData& data, const std::vector<int>& frames,
  const RenderOptions& options, ImageMetrics& metrics, std::string* error, double* secondsPerFrame)
{
  std::vector<float> I(std::size_t(data.Width) * data.Height), S;
  double seconds = 0;
  int rendered = 0;
  bool ok = true;
  const ImageMetrics mean = MeanFrameMetrics(data, frames, [&](std::size_t, int f) {
    const double t0 = SteadySeconds();
    ok = ok && RenderFrame(engine, data, f, options, S, I.data(), error);
    seconds += SteadySeconds() - t0;
    ++rendered;
    return I.data();
  });
  if (!ok)
  {
    return false;
  }
  metrics = mean;
  if (secondsPerFrame)
  {
    *secondsPerFrame = rendered == 0 ? 0.0 : seconds / rendered;
  }
  return true;
}

} // namespace bigus
