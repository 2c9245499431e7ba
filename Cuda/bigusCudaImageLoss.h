/**
 * @file bigusCudaImageLoss.h
 * @brief The training loss on the GPU: the masked L1 and D-SSIM terms of bigus::ComputeImageLoss
 *        (bigusImageLoss.h: the same definitions, window, constants and zero padding) and their exact gradient
 *        with respect to the rendered image, so that a training step keeps its images on the device.
 *
 * The kernels work in double (the window sums, SSIM and its derivatives; the gradient is stored as float), so
 * they agree with ComputeImageLoss(..., doublePrecision true) to rounding; sums over pixels are per-block trees
 * followed by one block in a fixed order: the same result on every run. The FFL term (an FFT) is not here: a
 * step with WeightFFL != 0 takes the host loss (CudaTrainingEngine).
 */
#ifndef bigusCudaImageLoss_h
#define bigusCudaImageLoss_h

#include "bigusCudaModule.h" // For export macro
#include "bigusImageLoss.h"

#include <string>

namespace bigus
{
namespace cuda
{

/**
 * ComputeImageLoss on the GPU for host images (tests and tools; the training engine calls the device-pointer
 * launcher of bigusCudaImageLossKernels, which this wraps): @p rendered, @p target [H, W] in [0, 1], @p mask
 * [H, W] (non-zero = imaged; null = every pixel), @p weights (FFL must be 0), @p gradient [H, W] receives
 * dTotal/d(rendered) when not null. Returns false with @p error on a CUDA error, a non-zero FFL weight or no
 * usable device.
 */
BIGUSCUDA_EXPORT bool ComputeImageLossOnDevice(const float* rendered, const float* target, const unsigned char* mask,
  int width, int height, const ImageLossWeights& weights, float* gradient, ImageLossTerms* terms, std::string* error);

} // namespace cuda
} // namespace bigus

#endif
