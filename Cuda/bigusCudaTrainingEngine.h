/**
 * @file bigusCudaTrainingEngine.h
 * @brief The device-resident training engine of the "cuda" backend (DESIGN section 5), registered with
 *        bigus::RegisterTrainingEngine when the backend loads.
 *
 * The field, its Adam moments, the last known-good copy of both (Snapshot / Restore), the step's gradients
 * and the EA-D accumulators live on the device between steps. A step copies the batch's recorded frames and masks
 * to the device; for each frame of the batch: the forward pass, the image loss and its gradient dL/dI on the device
 * (bigusCudaImageLoss.h: ComputeImageLoss's masked L1 and D-SSIM, in double), the backward pass into the device's
 * gradients; only each frame's loss comes back. A loss with an FFL term takes the host instead: I ([H, W]) to the
 * host, ComputeImageLoss there, dL/dI back. Then Adam on the device (Kingma and Ba 2015, algorithm 1;
 * bigus::AdamUpdate, the CPU engine's function, per parameter, unit quaternions and clamped log-scales after
 * it, and a non-finite gradient or parameter reported as StepStatus::NonFinite). Pose gradients
 * (StepRequest::PoseGradients) are 6 doubles per frame copied back.
 *
 * The reflectivity solve's operators: ApplyBasis and ApplyBasisTranspose run on the device with the
 * reflectivities or images of the call uploaded; BasisNorms runs on the host over a copy of the field
 * (bigus::AccumulateBasisNorms), once per solve.
 *
 * Data-parallel runs do not use this engine: CreateTrainingEngine(..., dataParallel true) gives the CPU engine's
 * host-side step over the CUDA renderer, which sums gradients through the host; this engine refuses a reduction
 * of more than one process (TrainingEngine::SetReduction).
 *
 * Coarse steps (StepRequest::Data, the resolution schedule) render the request's frames instead of the
 * engine's own.
 *
 * Results differ from the CPU engine's by the renderers' float rounding only; repeated steps are
 * bit-identical (no float atomics).
 */
#ifndef bigusCudaTrainingEngine_h
#define bigusCudaTrainingEngine_h

#include "bigusCudaModule.h" // For export macro
#include "bigusTrainingEngine.h"

#include <cstdint>
#include <memory>
#include <string>

namespace bigus
{
namespace cuda
{

/**
 * Device bytes the engine holds per Gaussian between steps: the field, Adam's two moments and their
 * known-good copies (6 x 11 floats), the step's gradients (11 floats), the attribution (float) and the
 * visible count (int). A step adds the renderer's work buffers (DeviceBytesPerGaussian, per tile entry).
 */
BIGUSCUDA_EXPORT std::int64_t TrainingBytesPerGaussian();

/**
 * The engine on device 0, or null with @p error when no usable device exists. Push refuses, before
 * allocating, a state that does not fit in device memory, with an error that gives the bytes needed and free.
 */
BIGUSCUDA_EXPORT std::unique_ptr<TrainingEngine> CreateCudaTrainingEngine(std::string* error);

} // namespace cuda
} // namespace bigus

#endif
