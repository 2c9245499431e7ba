/**
 * @file bigusImageLoss.h
 * @brief Training losses between a rendered ultrasound image and a recorded frame, with gradients.
 *
 * All images are row-major [H, W] floats with intensities in [0, 1]; the fan mask is [H, W] unsigned
 * char (non-zero = imaged). Every term is evaluated on the masked pixels only:
 * - L1: mean over masked pixels of |x - y|.
 * - D-SSIM: 1 - mean over masked pixels of the SSIM map of (m x, m y) (Wang et al. 2004, Eq. 13), with
 *   an 11 x 11 Gaussian window of sigma 1.5 pixels, C1 = 0.01^2, C2 = 0.03^2 (data range 1) and zero
 *   padding outside the image (so that the window filter is self-adjoint and the gradient exact).
 * - FFL, the focal frequency loss (Jiang et al., ICCV 2021, Eq. 2-5): mean over frequencies of
 *   w(u, v) |F(u, v)|^2, F = DFT of the masked residual m (x - y), w = (|F| / max |F|)^alpha held
 *   constant (not differentiated, as in the paper).
 * Total = WeightL1 L1 + WeightDSSIM D-SSIM + WeightFFL FFL. The gradient dTotal/dx is exact for each
 * term (checked against finite differences in TestImageLoss).
 */
#ifndef bigusImageLoss_h
#define bigusImageLoss_h

#include "bigusTrainingModule.h" // For export macro

#include <memory>
#include <string>

namespace bigus
{

/// Weights of the loss terms. Defaults: see vtkGaussianFieldTrainer's documentation for the reasons.
struct ImageLossWeights
{
  double L1 = 0.8;
  double DSSIM = 0.2;
  double FFL = 0.0;
  double FFLAlpha = 1.0; ///< focusing exponent of the FFL spectrum weight
};

/**
 * Whether @p weights make a loss a step can descend: each of L1, DSSIM and FFL finite and >= 0, FFLAlpha finite and
 * >= 0, and at least one of the three weights > 0 (all three 0: every gradient is 0 and no step moves the field).
 * False with @p error (when not null) naming the weights and what is wrong.
 */
BIGUSTRAINING_EXPORT bool CheckImageLossWeights(const ImageLossWeights& weights, std::string* error);

/// The value of each term (unweighted) and the weighted total.
struct ImageLossTerms
{
  double L1 = 0, DSSIM = 0, FFL = 0, Total = 0;
  long MaskedPixels = 0;
};

/**
 * Scratch images that ComputeImageLoss reuses from one call to the next on frames of one size (a
 * training step evaluates such a frame again and again; fresh images cost page faults every call).
 * One workspace per thread.
 */
class BIGUSTRAINING_EXPORT ImageLossWorkspace
{
public:
  ImageLossWorkspace();
  ~ImageLossWorkspace();
  ImageLossWorkspace(const ImageLossWorkspace&) = delete;
  ImageLossWorkspace& operator=(const ImageLossWorkspace&) = delete;
  ImageLossWorkspace(ImageLossWorkspace&&) noexcept;
  ImageLossWorkspace& operator=(ImageLossWorkspace&&) noexcept;
  struct Internals;
  std::unique_ptr<Internals> Data;
};

/**
 * Evaluate the loss of @p rendered against @p target inside @p mask (may be null = every pixel).
 * @param gradient  if non-null, receives dTotal/d(rendered) [H, W] (zero outside the mask).
 * @param doublePrecision  evaluate in double (tests, metrics) instead of float (training: about twice
 *        as fast; sums are accumulated in double either way).
 * @param workspace  scratch kept between calls (null: allocated for this call).
 * Multi-threaded over rows (vtkSMPTools); the result does not depend on the number of threads.
 * @return the terms; Total is 0 with MaskedPixels 0 when the mask is empty.
 */
BIGUSTRAINING_EXPORT ImageLossTerms ComputeImageLoss(const float* rendered, const float* target,
  const unsigned char* mask, int width, int height, const ImageLossWeights& weights, float* gradient,
  bool doublePrecision = false, ImageLossWorkspace* workspace = nullptr);

/**
 * Mean SSIM over the masked pixels, in double (same definition as the D-SSIM term, without the mask
 * applied to the images when @p maskImages is false: the form used for evaluation metrics).
 */
BIGUSTRAINING_EXPORT double MeanSSIM(
  const float* x, const float* y, const unsigned char* mask, int width, int height, bool maskImages);

} // namespace bigus

#endif
