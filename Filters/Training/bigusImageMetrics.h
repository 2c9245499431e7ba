/**
 * @file bigusImageMetrics.h
 * @brief Quality of a rendered ultrasound image against a recorded frame (DESIGN section 9).
 *
 * Images are row-major [H, W] floats with intensities in [0, 1] (8-bit / 255); the fan mask is
 * [H, W] unsigned char (non-zero = imaged; null = every pixel). All metrics use the masked pixels.
 * - PSNR with data range 1: 10 log10(1 / MSE), dB, capped at 100 dB (identical images give 100).
 * - SSIM: mean of the SSIM map (11 x 11 Gaussian window, sigma 1.5, C1 = 0.01^2, C2 = 0.03^2) over the
 *   masked pixels (bigus::MeanSSIM; Wang et al. 2004); windows at the fan border also see the few
 *   pixels just outside it.
 * - NCC: Pearson correlation of the masked pixels (0 when either image is constant there).
 * - Speckle fidelity, the paper's Backscatter Fidelity Score BFS = 0.4 s_mu + 0.4 exp(-W1 / sigma_W)
 *   + 0.2 s_Ray, with the open choices fixed here: speckle contrast C = std / mean of 16 x 16 patches
 *   taken with stride 8 and lying wholly inside the mask where the truth's mean is positive (a black
 *   rendering there has contrast 0 and SNR 0, so it loses score);
 *   s_mu = max(0, 1 - |mean C_render - mean C_truth| / mean C_truth); W1 = the 1-D Wasserstein distance
 *   between the two contrast distributions (mean absolute difference of the sorted values);
 *   sigma_W = 0.1; s_Ray = max(0, 1 - |median SNR_render - median SNR_truth| / median SNR_truth) with
 *   SNR = mean / std per patch. Identical images score 1.
 */
#ifndef bigusImageMetrics_h
#define bigusImageMetrics_h

#include "bigusTrainingModule.h" // For export macro

namespace bigus
{

struct ImageMetrics
{
  double PSNR = 0;
  double SSIM = 0;
  double NCC = 0;
  double Speckle = 0; ///< BFS in [0, 1]
  long Patches = 0;   ///< patches used by the speckle score
};

/// sigma_W of the speckle score (contrast units).
constexpr double SpeckleWassersteinScale = 0.1;

/// All metrics of @p rendered against @p truth inside @p mask.
BIGUSTRAINING_EXPORT ImageMetrics CompareImages(
  const float* rendered, const float* truth, const unsigned char* mask, int width, int height);

} // namespace bigus

#endif
