// The device-resident training engine of the "cuda" backend (see bigusCudaTrainingEngine.h).
#include "bigusCudaTrainingEngine.h"

#include "bigusBasisNorms.h"
#include "bigusCudaAssembledBasis.h"
#include "bigusCudaDeviceRenderer.h"
#include "bigusFieldLayout.h"
#include "bigusImageLoss.h"
#include "bigusRasterGeometry.h"

#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <utility>
#include <vector>

namespace bigus
{
namespace cuda
{

namespace
{
// Per Gaussian: the field, m, v and their known-good copies (each FieldParameters floats, bigusFieldLayout.h);
// the step's gradients, E and seen count.
constexpr std::int64_t StateBytes = 6 * FieldParameters * sizeof(float);
constexpr std::int64_t StepBytes = FieldParameters * sizeof(float) + sizeof(float) + sizeof(int);
constexpr std::int64_t ImageBytes = 3 * sizeof(float);                  // per pixel: S, I (then dL/dI), dL/dS
constexpr std::int64_t SolveBytes = 2 * sizeof(float) + sizeof(double); // r or dL/dr of one frame, their sum

/// One Adam step's constants (StepRequest).
struct AdamStep
{
  AdamBias Bias;            // bias corrections 1 - beta^t
  double Rate[FieldGroups]; // learning rate of each group (StepRequest::Rate)
  float MinimumLogScale, MaximumLogScale;
  bool Sparse;
};

/**
 * Adam on Gaussian i (one thread each), as CpuTrainingEngine::Adam (AdamUpdate: the moments in double, stored as
 * float), the arrays in the field's packed layout (bigusFieldLayout.h),
 * the parameters kept in range (unit quaternion, clamped log-scales); @p nonFinite becomes 1 when a gradient or an
 * updated parameter is not finite.
 */
__global__ void AdamKernel(float* field, float* m, float* v, const float* g, std::int64_t n, AdamStep a, int* nonFinite)
{
  const std::int64_t i = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n)
  {
    return;
  }
  if (a.Sparse && !FieldGradientTouched(g, n, i))
  {
    return;
  }
  bool ok = true;
  for (int q = 0; q < FieldGroups; ++q)
  {
    for (int c = 0; c < FieldGroupWidth(q); ++c)
    {
      const std::int64_t k = FieldEntry(n, i, q, c);
      ok = ok && isfinite(g[k]);
      AdamUpdate(field[k], m[k], v[k], g[k], a.Rate[q], a.Bias);
    }
  }
  float* quaternion = field + FieldEntry(n, i, QuaternionGroup, 0);
  const float norm = sqrtf(quaternion[0] * quaternion[0] + quaternion[1] * quaternion[1] +
    quaternion[2] * quaternion[2] + quaternion[3] * quaternion[3]);
  if (norm > 1e-12f)
  {
    for (int c = 0; c < 4; ++c)
    {
      quaternion[c] /= norm;
      ok = ok && isfinite(quaternion[c]);
    }
  }
  for (int c = 0; c < 3; ++c)
  {
    float& l = field[FieldEntry(n, i, LogScaleGroup, c)];
    l = fminf(a.MaximumLogScale, fmaxf(a.MinimumLogScale, l));
    ok = ok && isfinite(field[FieldEntry(n, i, MeanGroup, c)]) && isfinite(l);
  }
  ok = ok && isfinite(quaternion[0]) && isfinite(quaternion[1]) && isfinite(quaternion[2]) && isfinite(quaternion[3]) &&
    isfinite(field[FieldEntry(n, i, ReflectivityGroup, 0)]);
  if (!ok)
  {
    *nonFinite = 1;
  }
}

/// @p sum [N] += @p values [N] (one frame's dL/dr into the solve's double sum).
__global__ void AddToSumKernel(const float* values, std::int64_t n, double* sum)
{
  const std::int64_t i = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i < n)
  {
    sum[i] += values[i];
  }
}

/// The prepared slices of @p count frames of @p data, checked before anything is rendered; false with @p error
/// naming the first frame the renderer refuses (TrainingFrameError).
bool PrepareFrames(const TrainingData& data, const int* frames, int count, const RenderOptions& options,
  std::vector<PreparedSlice>& prepared, std::string* error)
{
  prepared.resize(count);
  for (int k = 0; k < count; ++k)
  {
    if (!PrepareSlice(data.Slice(frames[k]), options, 0, prepared[k], error))
    {
      return TrainingFrameError(frames[k], error);
    }
  }
  return true;
}

class CudaTrainingEngine : public TrainingEngine
{
public:
  bool Initialize(std::string* error) { return this->Device.Initialize(error); }

  const char* GetName() const override { return "cuda"; }

  bool SetData(const TrainingData* data, std::string*) override
  {
    this->Data = data;
    this->Assembled.reset();
    this->Resident.clear();
    this->ResidencyDecided = false;
    return true;
  }

  bool Push(const OptimizerState& input, std::string* error) override;
  bool Pull(OptimizerState& state, std::string* error) override;
  bool PullField(GaussianField& field, std::string* error) override;
  void Snapshot() override;
  void Restore() override;
  StepStatus Step(const StepRequest& request, double* loss, std::string* error) override;
  bool Render(const SliceGeometry* slices, int count, const RenderOptions& options, float* S, float* I,
    std::string* error) override;
  bool ApplyBasis(
    const float* r, const int* frames, int count, const RenderOptions& options, float* S, std::string* error) override;
  bool ApplyBasisTranspose(const float* y, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) override;
  bool BasisNorms(const float* weights, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) override;
  void SetBasisMemoryLimit(std::int64_t bytes) override
  {
    this->BasisMemoryLimit = bytes;
    if (this->Assembled && this->Assembled->PersistentBytes() > std::max<std::int64_t>(0, bytes))
    {
      this->Assembled.reset();
    }
  }
  std::string DescribeBasisProducts() const override { return this->BasisProducts; }

private:
  /// The device field, or with @p reflectivities those in place of the field's.
  DeviceField Field(const float* reflectivities = nullptr) const
  {
    DeviceField field = FieldAt(this->State.As<float>(), this->N);
    field.Reflectivities = reflectivities ? reflectivities : field.Reflectivities;
    return field;
  }
  float* Moment(int which) const { return this->State.As<float>() + which * FieldParameters * this->N; }

  /// Checks the memory of a call on the @p prepared slices (forward, or backward with or without pose gradients)
  /// and reserves the image buffers and the renderer's work buffers.
  bool Reserve(const std::vector<PreparedSlice>& prepared, bool backward, bool poses, std::string* error);
  /// Queues the copy of the device field @p which (0 the field, 1 Adam m, 2 Adam v) into @p field, resized to N.
  bool DownloadField(int which, GaussianField& field, std::string* error);
  /// Reserves the solve's buffers (SolveBytes per Gaussian) before allocating.
  bool PrepareSolve(std::string* error);
  /**
   * Whether the basis products of @p frames with @p options run over A assembled on the device (DeviceBasis),
   * assembling it when the field, the frames or the options changed: true where BasisMemoryLimit allows one (above
   * 0) and it fits in both that limit and the device's free memory; false for the matrix-free products, and false
   * with @p ok false and @p error for a pose the renderer refuses or a CUDA error. BasisProducts says which.
   */
  bool UseAssembled(const int* frames, int count, const RenderOptions& options, bool& ok, std::string* error);
  /// A^T y (@p transpose true) or diag(A^T W A) over the assembled A, @p pixelValues the [count, H, W] y or W on the
  /// host: added to @p out [N].
  bool AssembledColumnProduct(const float* pixelValues, bool transpose, double* out, std::string* error);
  /// Puts the recorded frames and masks of the step's frames on the device (LossTargets, LossMasks; @p slots[b] is
  /// the place of the step's frame b there) and reserves the image loss's scratch, checked before allocating. The
  /// frames of the engine's own data (SetData) stay there once copied, where all of them take at most a quarter of
  /// the device's free memory; others (a coarse step's decimated frames) are copied for each step.
  bool StageLossTargets(
    const TrainingData& data, const StepRequest& request, std::vector<std::int64_t>& slots, std::string* error);
  /// Copies @p bytes from the device to the host and waits.
  bool Download(void* host, const void* device, std::size_t bytes, const char* what, std::string* error)
  {
    return Check(cudaMemcpyAsync(host, device, bytes, cudaMemcpyDeviceToHost, this->Device.GetStream()), what, error) &&
      Check(cudaStreamSynchronize(this->Device.GetStream()), what, error);
  }

  DeviceRenderer Device;
  const TrainingData* Data = nullptr;
  std::int64_t N = 0;
  Buffer State;       // [3, N, 11] floats: field, Adam m, Adam v, each laid out as the field (Field)
  Buffer Saved;       // [3, N, 11] floats: the last known-good State (Snapshot)
  Buffer Gradients;   // [N, 11] floats: the step's gradients, laid out as the field
  Buffer Attribution; // [N] float: the EA-D attribution since the last Push
  Buffer Seen;        // [N] int: the visible counts since the last Push
  Buffer Images;      // [3, H, W] floats: S, I (then dL/dI), dL/dS
  Buffer PoseTotals;  // [count, 6] doubles: a step's pose gradients
  Buffer NonFinite;   // int: 1 when Adam met a non-finite value
  Buffer SolveValues; // [N] float: the reflectivities of ApplyBasis, one frame's dL/dr in ApplyBasisTranspose
  Buffer SolveSum;    // [N] double: ApplyBasisTranspose's sum over frames
  Buffer LossTargets; // [count, H, W] floats: the step's recorded frames, or every frame of Data (Resident)
  Buffer LossMasks;   // [count, H, W] bytes: their masks
  std::vector<unsigned char> Resident; // per frame of Data: 1 when LossTargets holds it; empty: none is kept
  bool ResidencyDecided = false;       // whether the free memory was asked since SetData (once: not every step)
  Buffer LossScratch; // the image loss's work maps (ImageLossScratchBytes), then [count, 4] doubles: its terms
  // Host scratch, kept between steps (the host loss: steps with an FFL term)
  std::vector<float> I, LossGradient;
  ImageLossWorkspace LossWorkspace;
  GaussianField HostField; // BasisNorms's copy of the field
  // The basis products' A assembled on the device, for AssembledKey; dropped when the field changes (Push, Step,
  // Restore) or the data (SetData).
  std::unique_ptr<DeviceBasis> Assembled;
  BasisKey AssembledKey;
  std::int64_t BasisMemoryLimit = 0;
  std::string BasisProducts = "matrix free (no product run yet)";
};

bool CudaTrainingEngine::Push(const OptimizerState& input, std::string* error)
{
  this->Assembled.reset();
  OptimizerState state = input;
  state.ResizeToField();
  const std::int64_t n = state.Count();
  if (n >= (std::int64_t(1) << 31))
  {
    if (error)
    {
      *error = "CUDA training engine: " + std::to_string(n) + " Gaussians; at most 2^31 - 1 are supported";
    }
    return false;
  }
  const std::int64_t slots = std::max<std::int64_t>(1, n);
  const std::int64_t held =
    this->State.Bytes + this->Saved.Bytes + this->Gradients.Bytes + this->Attribution.Bytes + this->Seen.Bytes;
  if (!this->Device.Fits(
        n * TrainingBytesPerGaussian(), held, "the training state of " + std::to_string(n) + " Gaussians", error) ||
    !this->State.Reserve(slots * 3 * FieldParameters * sizeof(float), "allocating the training state", error) ||
    !this->Saved.Reserve(slots * 3 * FieldParameters * sizeof(float), "allocating the training state", error) ||
    !this->Gradients.Reserve(slots * FieldParameters * sizeof(float), "allocating gradients", error) ||
    !this->Attribution.Reserve(slots * sizeof(float), "allocating the attribution", error) ||
    !this->Seen.Reserve(slots * sizeof(int), "allocating visible counts", error) ||
    !this->NonFinite.Reserve(sizeof(int), "allocating a flag", error))
  {
    return false;
  }
  this->N = n;
  const cudaStream_t stream = this->Device.GetStream();
  const GaussianField* parts[3] = { &state.Field, &state.FirstMoment, &state.SecondMoment };
  for (int which = 0; which < 3; ++which)
  {
    if (!UploadField(parts[which]->View(), this->Moment(which), stream, error))
    {
      return false;
    }
  }
  if (n > 0 &&
    (!Check(cudaMemcpyAsync(
              this->Attribution.Data, state.Attribution.data(), sizeof(float) * n, cudaMemcpyHostToDevice, stream),
       "copying the attribution to the device", error) ||
      !Check(cudaMemcpyAsync(this->Seen.Data, state.SeenCount.data(), sizeof(int) * n, cudaMemcpyHostToDevice, stream),
        "copying visible counts to the device", error)))
  {
    return false;
  }
  this->Snapshot();
  return Check(cudaStreamSynchronize(stream), "copying the training state to the device", error);
}

bool CudaTrainingEngine::Pull(OptimizerState& state, std::string* error)
{
  const std::int64_t n = this->N;
  GaussianField* parts[3] = { &state.Field, &state.FirstMoment, &state.SecondMoment };
  for (int which = 0; which < 3; ++which)
  {
    if (!this->DownloadField(which, *parts[which], error))
    {
      return false;
    }
  }
  state.ResizeToField();
  const cudaStream_t stream = this->Device.GetStream();
  return n == 0 ||
    (Check(cudaMemcpyAsync(
             state.Attribution.data(), this->Attribution.Data, sizeof(float) * n, cudaMemcpyDeviceToHost, stream),
       "copying the attribution to the host", error) &&
      this->Download(
        state.SeenCount.data(), this->Seen.Data, sizeof(int) * n, "copying visible counts to the host", error));
}

bool CudaTrainingEngine::PullField(GaussianField& field, std::string* error)
{
  return this->DownloadField(0, field, error) &&
    Check(cudaStreamSynchronize(this->Device.GetStream()), "copying the field to the host", error);
}

bool CudaTrainingEngine::DownloadField(int which, GaussianField& field, std::string* error)
{
  const std::int64_t n = this->N;
  field.Resize(n);
  for (int q = 0; q < FieldGroups && n > 0; ++q)
  {
    if (!Check(cudaMemcpyAsync(field.Group(q).data(), this->Moment(which) + FieldGroupFirst(q) * n,
                 sizeof(float) * field.Group(q).size(), cudaMemcpyDeviceToHost, this->Device.GetStream()),
          "copying the training state to the host", error))
    {
      return false;
    }
  }
  return true;
}

void CudaTrainingEngine::Snapshot()
{
  // Stream-ordered after the work queued so far; a failure shows at the next call's check.
  cudaMemcpyAsync(this->Saved.Data, this->State.Data, sizeof(float) * 3 * FieldParameters * this->N,
    cudaMemcpyDeviceToDevice, this->Device.GetStream());
}

void CudaTrainingEngine::Restore()
{
  this->Assembled.reset();
  cudaMemcpyAsync(this->State.Data, this->Saved.Data, sizeof(float) * 3 * FieldParameters * this->N,
    cudaMemcpyDeviceToDevice, this->Device.GetStream());
}

bool CudaTrainingEngine::Reserve(
  const std::vector<PreparedSlice>& prepared, bool backward, bool poses, std::string* error)
{
  const CallExtent extent = Extent(this->N, prepared);
  const std::int64_t poseBytes = poses ? 6 * std::int64_t(sizeof(double)) * prepared.size() : 0;
  const std::int64_t own = extent.Pixels * ImageBytes + poseBytes;
  const std::int64_t held = this->Images.Bytes + (poses ? this->PoseTotals.Bytes : 0);
  return this->Device.Reserve(false, false, this->N, extent.Tiles, own, held, extent.What, error) &&
    (!backward || this->Device.Reserve(true, poses, this->N, extent.Tiles, own, held, extent.What, error)) &&
    this->Images.Reserve(extent.Pixels * ImageBytes, "allocating the image buffers", error) &&
    (!poses || this->PoseTotals.Reserve(poseBytes, "allocating pose gradients", error));
}

bool CudaTrainingEngine::PrepareSolve(std::string* error)
{
  const std::int64_t slots = std::max<std::int64_t>(1, this->N);
  return this->Device.Fits(this->N * SolveBytes, this->SolveValues.Bytes + this->SolveSum.Bytes,
           "the reflectivity solve's vectors for " + std::to_string(this->N) + " Gaussians", error) &&
    this->SolveValues.Reserve(slots * sizeof(float), "allocating the solve's vectors", error) &&
    this->SolveSum.Reserve(slots * sizeof(double), "allocating the solve's vectors", error);
}

bool CudaTrainingEngine::StageLossTargets(
  const TrainingData& data, const StepRequest& request, std::vector<std::int64_t>& slots, std::string* error)
{
  const std::int64_t pixels = std::int64_t(data.Width) * data.Height;
  const std::int64_t scratch =
    ImageLossScratchBytes(data.Width, data.Height) + 4 * std::int64_t(request.Count) * std::int64_t(sizeof(double));
  const std::int64_t held = this->LossTargets.Bytes + this->LossMasks.Bytes + this->LossScratch.Bytes;
  // The engine's own frames stay on the device when they take at most a quarter of its free memory (asked once
  // after SetData).
  const std::int64_t frames = pixels > 0 ? std::int64_t(data.Frames.size()) / pixels : 0;
  const bool own = &data == this->Data && frames > 0;
  if (own && !this->ResidencyDecided)
  {
    this->ResidencyDecided = true;
    std::size_t freeBytes = 0, totalBytes = 0;
    const std::int64_t all = frames * pixels * std::int64_t(sizeof(float) + 1);
    if (Check(cudaMemGetInfo(&freeBytes, &totalBytes), "cudaMemGetInfo", nullptr) &&
      all <= (held + std::int64_t(freeBytes)) / 4)
    {
      this->Resident.assign(std::size_t(frames), 0);
    }
  }
  const bool resident = own && !this->Resident.empty();
  if (!own)
  {
    std::fill(this->Resident.begin(), this->Resident.end(), 0); // this step's frames go where they were
  }
  const std::int64_t count = resident ? frames : request.Count;
  const std::int64_t bytes = count * pixels * std::int64_t(sizeof(float) + 1) + scratch;
  if (!this->Device.Fits(bytes, held,
        "the image loss of " + std::to_string(count) + " frames of " + std::to_string(pixels) + " pixels", error) ||
    !this->LossTargets.Reserve(
      std::max<std::int64_t>(1, count * pixels) * sizeof(float), "allocating the loss's frames", error) ||
    !this->LossMasks.Reserve(std::max<std::int64_t>(1, count * pixels), "allocating the loss's masks", error) ||
    !this->LossScratch.Reserve(scratch, "allocating the loss's scratch", error))
  {
    return false;
  }
  const cudaStream_t stream = this->Device.GetStream();
  slots.resize(std::size_t(request.Count));
  for (int b = 0; b < request.Count; ++b)
  {
    const int f = request.Frames[b];
    slots[b] = resident ? f : b;
    if (resident && this->Resident[f])
    {
      continue;
    }
    if (!Check(cudaMemcpyAsync(this->LossTargets.As<float>() + pixels * slots[b], &data.Frames[pixels * f],
                 sizeof(float) * pixels, cudaMemcpyHostToDevice, stream),
          "copying a recorded frame to the device", error) ||
      !Check(cudaMemcpyAsync(this->LossMasks.As<unsigned char>() + pixels * slots[b], data.MaskOf(f),
               std::size_t(pixels), cudaMemcpyHostToDevice, stream),
        "copying a mask to the device", error))
    {
      return TrainingFrameError(f, error);
    }
    if (resident)
    {
      this->Resident[f] = 1;
    }
  }
  return true;
}

StepStatus CudaTrainingEngine::Step(const StepRequest& request, double* loss, std::string* error)
{
  this->Assembled.reset(); // the step moves the geometry
  const TrainingData& data = request.Data ? *request.Data : *this->Data;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const std::int64_t n = this->N;
  const cudaStream_t stream = this->Device.GetStream();
  const bool poses = request.PoseGradients != nullptr;
  std::vector<PreparedSlice> prepared;
  if (!PrepareFrames(data, request.Frames, request.Count, request.Options, prepared, error) ||
    !this->Reserve(prepared, true, poses, error))
  {
    return StepStatus::Failed;
  }
  float* gradients = this->Gradients.As<float>();
  FieldGradients out = FieldGradientsAt(gradients, n); // device pointers, laid out as the field
  out.Attribution = this->Attribution.As<float>();
  out.VisibleCount = this->Seen.As<int>();
  if (!Check(cudaMemsetAsync(gradients, 0, sizeof(float) * FieldParameters * n, stream), "clearing gradients", error) ||
    (poses &&
      !Check(cudaMemsetAsync(this->PoseTotals.Data, 0, sizeof(double) * 6 * request.Count, stream),
        "clearing pose gradients", error)))
  {
    return StepStatus::Failed;
  }
  // The loss on the device unless it has an FFL term (an FFT, on the host): then I goes to the host and dL/dI back.
  const bool deviceLoss = request.Loss.FFL == 0;
  double* lossTerms = nullptr;     // [count, 4] on the device: each frame's terms (LaunchImageLoss)
  std::vector<std::int64_t> slots; // the place of each of the step's frames in LossTargets
  if (deviceLoss)
  {
    if (!this->StageLossTargets(data, request, slots, error))
    {
      return StepStatus::Failed;
    }
    lossTerms =
      this->LossScratch.As<double>() + ImageLossScratchBytes(data.Width, data.Height) / std::int64_t(sizeof(double));
  }
  else
  {
    this->I.resize(pixels);
    this->LossGradient.resize(pixels);
  }
  float* dS = this->Images.As<float>();
  float* dI = dS + pixels; // I, then dL/dI
  const DeviceField field = this->Field();
  double total = 0;
  for (int b = 0; b < request.Count; ++b)
  {
    const int f = request.Frames[b];
    if (!this->Device.Forward(field, prepared[b], request.Options, dS, dI, nullptr, error))
    {
      TrainingFrameError(f, error);
      return StepStatus::Failed;
    }
    bool ok = true;
    if (deviceLoss)
    {
      LaunchImageLoss(dI, this->LossTargets.As<float>() + pixels * slots[b],
        this->LossMasks.As<unsigned char>() + pixels * slots[b], data.Width, data.Height, request.Loss.L1,
        request.Loss.DSSIM, 1.0 / request.Count, dI, lossTerms + 4 * b, this->LossScratch.Data, stream);
      ok = Check(cudaGetLastError(), "image loss kernels", error);
    }
    else
    {
      ok = this->Download(this->I.data(), dI, sizeof(float) * pixels, "copying I to the host", error);
      total += ok ? FrameLoss(data, f, this->I.data(), request, this->LossGradient.data(), &this->LossWorkspace) : 0;
      ok = ok &&
        Check(cudaMemcpyAsync(dI, this->LossGradient.data(), sizeof(float) * pixels, cudaMemcpyHostToDevice, stream),
          "copying dL/dI to the device", error);
    }
    if (!ok ||
      !this->Device.Backward(field, prepared[b], request.Options, dS, dI, false, dI + pixels, out,
        poses ? this->PoseTotals.As<double>() + 6 * b : nullptr, error))
    {
      TrainingFrameError(f, error);
      return StepStatus::Failed;
    }
    // The next frame's work follows on the same stream: its forward pass overwrites S after this backward pass.
  }
  if (!this->Device.Synchronize(nullptr, "backward", error))
  {
    return StepStatus::Failed;
  }
  if (deviceLoss)
  {
    std::vector<double> terms(4 * std::size_t(request.Count));
    if (!this->Download(terms.data(), lossTerms, sizeof(double) * terms.size(), "copying the loss to the host", error))
    {
      return StepStatus::Failed;
    }
    for (int b = 0; b < request.Count; ++b)
    {
      total += terms[4 * b + 3]; // in frame order, as the host loss sums them
    }
  }
  if (poses &&
    !this->Download(request.PoseGradients, this->PoseTotals.Data, sizeof(double) * 6 * request.Count,
      "copying pose gradients to the host", error))
  {
    return StepStatus::Failed;
  }
  *loss = total / request.Count;
  if (!std::isfinite(*loss))
  {
    return StepStatus::NonFinite;
  }
  AdamStep a;
  a.Bias = AdamBiasAt(request.Iteration + 1);
  for (int q = 0; q < FieldGroups; ++q)
  {
    a.Rate[q] = request.Rate(q);
  }
  a.MinimumLogScale = static_cast<float>(request.MinimumLogScale);
  a.MaximumLogScale = static_cast<float>(request.MaximumLogScale);
  a.Sparse = request.SparseAdam;
  int nonFinite = 0;
  if (!Check(cudaMemsetAsync(this->NonFinite.Data, 0, sizeof(int), stream), "clearing a flag", error))
  {
    return StepStatus::Failed;
  }
  if (n > 0)
  {
    AdamKernel<<<Blocks(n, SetupBlock), SetupBlock, 0, stream>>>(
      this->Moment(0), this->Moment(1), this->Moment(2), gradients, n, a, this->NonFinite.As<int>());
  }
  if (!Check(cudaGetLastError(), "Adam kernel", error) ||
    !this->Download(&nonFinite, this->NonFinite.Data, sizeof(int), "Adam", error))
  {
    return StepStatus::Failed;
  }
  return nonFinite ? StepStatus::NonFinite : StepStatus::Done;
}

bool CudaTrainingEngine::Render(
  const SliceGeometry* slices, int count, const RenderOptions& options, float* S, float* I, std::string* error)
{
  std::vector<PreparedSlice> prepared;
  if (!PrepareSlices(slices, count, options, prepared, error) || !this->Reserve(prepared, false, false, error))
  {
    return false;
  }
  float* dS = this->Images.As<float>();
  std::int64_t offset = 0;
  for (const PreparedSlice& s : prepared)
  {
    const std::int64_t pixels = std::int64_t(s.Width) * s.Height;
    if (!this->Device.Forward(this->Field(), s, options, dS, I ? dS + pixels : nullptr, nullptr, error) ||
      !this->Download(S + offset, dS, sizeof(float) * pixels, "copying S to the host", error) ||
      (I && !this->Download(I + offset, dS + pixels, sizeof(float) * pixels, "copying I to the host", error)))
    {
      return false;
    }
    offset += pixels;
  }
  return true;
}

bool CudaTrainingEngine::ApplyBasis(
  const float* r, const int* frames, int count, const RenderOptions& options, float* S, std::string* error)
{
  const std::size_t pixels = std::size_t(this->Data->Width) * this->Data->Height;
  const RenderOptions linear = LinearBasisOptions(options);
  bool ok = true;
  const bool assembled = this->UseAssembled(frames, count, options, ok, error);
  if (!ok)
  {
    return false;
  }
  std::vector<PreparedSlice> prepared;
  if ((!assembled &&
        (!PrepareFrames(*this->Data, frames, count, linear, prepared, error) ||
          !this->Reserve(prepared, false, false, error))) ||
    !this->PrepareSolve(error) ||
    (this->N > 0 &&
      !Check(cudaMemcpyAsync(
               this->SolveValues.Data, r, sizeof(float) * this->N, cudaMemcpyHostToDevice, this->Device.GetStream()),
        "copying reflectivities to the device", error)))
  {
    return false;
  }
  if (assembled)
  {
    this->Assembled->Apply(this->SolveValues.As<float>(), this->Device.GetStream());
    return Check(cudaGetLastError(), "assembled product kernel", error) &&
      this->Download(S, this->Assembled->PixelVector(), sizeof(float) * pixels * count, "copying S to the host", error);
  }
  const DeviceField field = this->Field(this->SolveValues.As<float>());
  for (int k = 0; k < count; ++k)
  {
    if (!this->Device.Forward(field, prepared[k], linear, this->Images.As<float>(), nullptr, nullptr, error) ||
      !this->Download(S + pixels * k, this->Images.Data, sizeof(float) * pixels, "copying S to the host", error))
    {
      return TrainingFrameError(frames[k], error);
    }
  }
  return true;
}

bool CudaTrainingEngine::ApplyBasisTranspose(
  const float* y, const int* frames, int count, const RenderOptions& options, double* out, std::string* error)
{
  const std::int64_t n = this->N;
  const std::size_t pixels = std::size_t(this->Data->Width) * this->Data->Height;
  const RenderOptions linear = LinearBasisOptions(options);
  const cudaStream_t stream = this->Device.GetStream();
  bool ok = true;
  if (this->UseAssembled(frames, count, options, ok, error))
  {
    return this->AssembledColumnProduct(y, true, out, error);
  }
  std::vector<PreparedSlice> prepared;
  if (!ok || !PrepareFrames(*this->Data, frames, count, linear, prepared, error) ||
    !this->Reserve(prepared, true, false, error) || !this->PrepareSolve(error) ||
    !Check(cudaMemsetAsync(this->SolveSum.Data, 0, sizeof(double) * n, stream), "clearing the solve's sum", error))
  {
    return false;
  }
  // One frame at a time into float, summed over frames in double (as the CPU engine).
  FieldGradients gradient;
  gradient.Reflectivities = this->SolveValues.As<float>();
  float* dY = this->Images.As<float>();
  for (int k = 0; k < count; ++k)
  {
    // With the gradient taken with respect to S the forward S is not read; y stands in for it.
    if (!Check(cudaMemsetAsync(gradient.Reflectivities, 0, sizeof(float) * n, stream), "clearing dL/dr", error) ||
      !Check(cudaMemcpyAsync(dY, y + pixels * k, sizeof(float) * pixels, cudaMemcpyHostToDevice, stream),
        "copying y to the device", error) ||
      !this->Device.Backward(
        this->Field(), prepared[k], linear, dY, dY, true, dY + 2 * pixels, gradient, nullptr, error))
    {
      return TrainingFrameError(frames[k], error);
    }
    if (n > 0)
    {
      AddToSumKernel<<<Blocks(n, SetupBlock), SetupBlock, 0, stream>>>(
        gradient.Reflectivities, n, this->SolveSum.As<double>());
    }
    if (!Check(cudaGetLastError(), "sum kernel", error) || !this->Device.Synchronize(nullptr, "backward", error))
    {
      return TrainingFrameError(frames[k], error);
    }
  }
  std::vector<double> sum(n);
  if (n > 0 && !this->Download(sum.data(), this->SolveSum.Data, sizeof(double) * n, "copying A^T y to the host", error))
  {
    return false;
  }
  for (std::int64_t i = 0; i < n; ++i)
  {
    out[i] += sum[i];
  }
  return true;
}

bool CudaTrainingEngine::BasisNorms(
  const float* weights, const int* frames, int count, const RenderOptions& options, double* out, std::string* error)
{
  bool ok = true;
  if (this->UseAssembled(frames, count, options, ok, error))
  {
    return this->AssembledColumnProduct(weights, false, out, error);
  }
  // Matrix free: once per solve, on the host, over a copy of the field.
  if (!ok || !this->PullField(this->HostField, error))
  {
    return false;
  }
  const std::size_t pixels = std::size_t(this->Data->Width) * this->Data->Height;
  for (int k = 0; k < count; ++k)
  {
    const SliceGeometry slice = this->Data->Slice(frames[k]);
    if (!AccumulateBasisNorms(this->HostField.View(), &slice, 1, options, weights + pixels * k, out, error))
    {
      return TrainingFrameError(frames[k], error);
    }
  }
  return true;
}

bool CudaTrainingEngine::UseAssembled(
  const int* frames, int count, const RenderOptions& options, bool& ok, std::string* error)
{
  auto assemble = [&](DeviceBasis& basis, std::string& why, bool& tooLarge) {
    const RenderOptions linear = LinearBasisOptions(options);
    std::vector<PreparedSlice> prepared;
    // Refused before allocating its weights when it does not fit (matrix free then); a CUDA error fails the product.
    return PrepareFrames(*this->Data, frames, count, linear, prepared, &why) &&
      basis.Assemble(this->Field(), prepared, EffectiveElevationSigma(linear), linear.Cutoff, this->BasisMemoryLimit,
        this->Device, &why, &tooLarge);
  };
  auto describe = [](const DeviceBasis& basis, double seconds) {
    return AssembledBasisText(basis.GetEntries(), basis.PersistentBytes(), seconds, "on the device");
  };
  return UseAssembledBasis(this->Assembled, this->AssembledKey, BasisKey(frames, count, options),
    this->BasisMemoryLimit, this->BasisProducts, ok, error, assemble, describe);
}

bool CudaTrainingEngine::AssembledColumnProduct(
  const float* pixelValues, bool transpose, double* out, std::string* error)
{
  const std::int64_t n = this->N;
  const cudaStream_t stream = this->Device.GetStream();
  if (!this->PrepareSolve(error) ||
    !Check(cudaMemcpyAsync(this->Assembled->PixelVector(), pixelValues, sizeof(float) * this->Assembled->GetPixels(),
             cudaMemcpyHostToDevice, stream),
      "copying pixel values to the device", error))
  {
    return false;
  }
  if (transpose)
  {
    this->Assembled->ApplyTranspose(this->SolveSum.As<double>(), stream);
  }
  else
  {
    this->Assembled->Norms(this->SolveSum.As<double>(), stream);
  }
  std::vector<double> sum(n);
  if (!Check(cudaGetLastError(), "assembled product kernel", error) ||
    (n > 0 && !this->Download(sum.data(), this->SolveSum.Data, sizeof(double) * n, "copying A^T y to the host", error)))
  {
    return false;
  }
  for (std::int64_t i = 0; i < n; ++i)
  {
    out[i] += sum[i];
  }
  return true;
}

} // namespace

std::int64_t TrainingBytesPerGaussian()
{
  return StateBytes + StepBytes;
}

std::unique_ptr<TrainingEngine> CreateCudaTrainingEngine(std::string* error)
{
  if (!DeviceUsable(error))
  {
    return nullptr;
  }
  std::unique_ptr<CudaTrainingEngine> engine(new CudaTrainingEngine);
  if (!engine->Initialize(error))
  {
    return nullptr;
  }
  return engine;
}

} // namespace cuda
} // namespace bigus
