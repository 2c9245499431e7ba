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

} // namespace bigus
