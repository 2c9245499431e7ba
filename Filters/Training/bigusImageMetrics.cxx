#include "bigusImageMetrics.h"

#include "bigusImageLoss.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace bigus
{

namespace
{
constexpr int Patch = 16;
constexpr int Stride = 8;

struct PatchStatistics
{
  std::vector<double> Contrast; // std / mean
  std::vector<double> SNR;      // mean / std
};

/// Contrast of the patches that lie wholly inside the mask and where the truth's mean is positive;
/// the two lists stay paired.
void SpecklePatches(const float* a, const float* b, const unsigned char* mask, int width, int height,
  PatchStatistics& pa, PatchStatistics& pb)
{
  for (int y = 0; y + Patch <= height; y += Stride)
  {
    for (int x = 0; x + Patch <= width; x += Stride)
    {
      bool inside = true;
      double s[2] = { 0, 0 }, s2[2] = { 0, 0 };
      for (int j = y; j < y + Patch && inside; ++j)
      {
        for (int i = x; i < x + Patch; ++i)
        {
          const std::size_t p = std::size_t(j) * width + i;
          if (mask && !mask[p])
          {
            inside = false;
            break;
          }
          s[0] += a[p];
          s2[0] += double(a[p]) * a[p];
          s[1] += b[p];
          s2[1] += double(b[p]) * b[p];
        }
      }
      if (!inside)
      {
        continue;
      }
      const double n = Patch * Patch;
      double mean[2], sd[2];
      for (int k = 0; k < 2; ++k)
      {
        mean[k] = s[k] / n;
        sd[k] = std::sqrt(std::max(0.0, s2[k] / n - mean[k] * mean[k]));
      }
      // Patches are chosen by the truth (b) alone: a rendering that is black where the truth has
      // speckle must lose score there (contrast 0, SNR 0), not have the patch dropped.
      if (mean[1] <= 0)
      {
        continue;
      }
      pa.Contrast.push_back(mean[0] > 0 ? sd[0] / mean[0] : 0.0);
      pb.Contrast.push_back(sd[1] / mean[1]);
      pa.SNR.push_back(sd[0] > 0 ? mean[0] / sd[0] : (mean[0] > 0 ? 1e6 : 0.0));
      pb.SNR.push_back(sd[1] > 0 ? mean[1] / sd[1] : 1e6);
    }
  }
}

double Median(std::vector<double> v)
{
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}
}

ImageMetrics CompareImages(const float* rendered, const float* truth, const unsigned char* mask, int width, int height)
{
  ImageMetrics m;
  const std::size_t pixels = std::size_t(width) * height;
  double se = 0, sa = 0, sb = 0;
  long n = 0;
  for (std::size_t p = 0; p < pixels; ++p)
  {
    if (mask && !mask[p])
    {
      continue;
    }
    const double a = rendered[p], b = truth[p];
    se += (a - b) * (a - b);
    sa += a;
    sb += b;
    ++n;
  }
  if (n == 0)
  {
    return m;
  }
  const double mse = se / n;
  m.PSNR = mse > 0 ? std::min(100.0, 10 * std::log10(1.0 / mse)) : 100.0;
  // Two passes (means first): a constant image has exactly zero variance, so NCC is 0 there.
  const double ma = sa / n, mb = sb / n;
  double va = 0, vb = 0, cov = 0;
  for (std::size_t p = 0; p < pixels; ++p)
  {
    if (mask && !mask[p])
    {
      continue;
    }
    const double a = rendered[p] - ma, b = truth[p] - mb;
    va += a * a;
    vb += b * b;
    cov += a * b;
  }
  m.NCC = va > 0 && vb > 0 ? cov / std::sqrt(va * vb) : 0.0;
  m.SSIM = MeanSSIM(rendered, truth, mask, width, height, false);

  PatchStatistics r, t;
  SpecklePatches(rendered, truth, mask, width, height, r, t);
  m.Patches = static_cast<long>(t.Contrast.size());
  if (m.Patches > 0)
  {
    double meanR = 0, meanT = 0;
    for (std::size_t k = 0; k < t.Contrast.size(); ++k)
    {
      meanR += r.Contrast[k] / m.Patches;
      meanT += t.Contrast[k] / m.Patches;
    }
    const double sMu = meanT > 0 ? std::max(0.0, 1 - std::abs(meanR - meanT) / meanT) : 0.0;
    std::vector<double> cr = r.Contrast, ct = t.Contrast;
    std::sort(cr.begin(), cr.end());
    std::sort(ct.begin(), ct.end());
    double w1 = 0;
    for (std::size_t k = 0; k < ct.size(); ++k)
    {
      w1 += std::abs(cr[k] - ct[k]) / m.Patches;
    }
    const double snrR = Median(r.SNR), snrT = Median(t.SNR);
    const double sRay = snrT > 0 ? std::max(0.0, 1 - std::abs(snrR - snrT) / snrT) : 0.0;
    m.Speckle = 0.4 * sMu + 0.4 * std::exp(-w1 / SpeckleWassersteinScale) + 0.2 * sRay;
  }
  return m;
}

} // namespace bigus
