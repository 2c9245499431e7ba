// The CPU training engine: the step (forward, image loss, backward, Adam) on the host, multi-threaded
// with vtkSMPTools, over any renderer with host buffers. See bigusTrainingEngine.h.
#include "bigusTrainingEngine.h"

#include "bigusAssembledBasis.h"
#include "bigusBasisNorms.h"

#include "vtkSMPTools.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <utility>

namespace bigus
{

namespace
{

class CpuTrainingEngine : public TrainingEngine
{
public:
  explicit CpuTrainingEngine(std::unique_ptr<Renderer> renderer)
    : Backend(std::move(renderer))
  {}

  const char* GetName() const override { return this->Backend->GetName(); }

  bool SetData(const TrainingData* data, std::string*) override
  {
    this->Data = data;
    this->Assembled.reset();
    return true;
  }

  bool Push(const OptimizerState& state, std::string*) override
  {
    this->Assembled.reset();
    this->State = state;
    this->State.ResizeToField();
    this->Snapshot();
    return true;
  }

  bool Pull(OptimizerState& state, std::string*) override
  {
    state = this->State;
    return true;
  }

  bool PullField(GaussianField& field, std::string*) override
  {
    field = this->State.Field;
    return true;
  }

  void Snapshot() override
  {
    this->Saved = this->State.Field;
    this->SavedFirst = this->State.FirstMoment;
    this->SavedSecond = this->State.SecondMoment;
  }

  void Restore() override
  {
    this->Assembled.reset();
    this->State.Field = this->Saved;
    this->State.FirstMoment = this->SavedFirst;
    this->State.SecondMoment = this->SavedSecond;
    this->State.ResizeToField();
  }

  bool Render(const SliceGeometry* slices, int count, const RenderOptions& options, float* S, float* I,
    std::string* error) override
  {
    return this->Backend->Forward(this->State.Field.View(), slices, count, options, S, I, nullptr, error);
  }

  StepStatus Step(const StepRequest& request, double* loss, std::string* error) override;

  bool SetReduction(ProcessReduction* reduction, std::string*) override
  {
    this->Reduction = reduction && reduction->Size() > 1 ? reduction : nullptr;
    return true;
  }

  bool ApplyBasis(
    const float* r, const int* frames, int count, const RenderOptions& options, float* S, std::string* error) override
  {
    bool ok = true;
    if (this->UseAssembled(frames, count, options, ok, error))
    {
      this->Assembled->Apply(r, S);
      return this->Agree(true, error);
    }
    FieldView view = this->State.Field.View();
    view.Reflectivities = r;
    const RenderOptions linear = LinearBasisOptions(options);
    const std::size_t pixels = std::size_t(this->Data->Width) * this->Data->Height;
    for (int k = 0; k < count && ok; ++k)
    {
      const SliceGeometry slice = this->Data->Slice(frames[k]);
      if (!this->Backend->Forward(view, &slice, 1, linear, S + pixels * k, nullptr, nullptr, error))
      {
        ok = TrainingFrameError(frames[k], error);
      }
    }
    return this->Agree(ok, error); // data-parallel: this process's frames' images stay here
  }

  bool ApplyBasisTranspose(const float* y, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) override
  {
    // One frame at a time into float, summed over frames in double.
    const std::int64_t n = this->State.Count();
    const std::size_t pixels = std::size_t(this->Data->Width) * this->Data->Height;
    const RenderOptions linear = LinearBasisOptions(options);
    FieldGradients grads;
    // With several processes each sums its own frames into a vector of its own, then the vectors are summed.
    std::vector<double> own(this->Reduction ? n : 0, 0.0);
    double* sum = this->Reduction ? own.data() : out;
    bool ok = true;
    if (this->UseAssembled(frames, count, options, ok, error))
    {
      this->Assembled->ApplyTranspose(y, sum);
      return this->Agree(true, error) && this->AddSum(own, out, error);
    }
    for (int k = 0; k < count && ok; ++k)
    {
      this->Gradients.assign(n, 0.f);
      grads.Reflectivities = this->Gradients.data();
      const SliceGeometry slice = this->Data->Slice(frames[k]);
      // With the gradient taken with respect to S the forward S is not read; y stands in for it.
      if (!this->Backend->Backward(
            this->State.Field.View(), &slice, 1, linear, y + pixels * k, y + pixels * k, true, grads, nullptr, error))
      {
        ok = TrainingFrameError(frames[k], error);
        break;
      }
      vtkSMPTools::For(0, n, 8192, [&](std::int64_t b, std::int64_t e) {
        for (std::int64_t i = b; i < e; ++i)
        {
          sum[i] += this->Gradients[i];
        }
      });
    }
    return this->Agree(ok, error) && this->AddSum(own, out, error);
  }

  bool BasisNorms(const float* weights, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) override
  {
    const std::size_t pixels = std::size_t(this->Data->Width) * this->Data->Height;
    std::vector<double> own(this->Reduction ? this->State.Count() : 0, 0.0);
    double* sum = this->Reduction ? own.data() : out;
    bool ok = true;
    if (this->UseAssembled(frames, count, options, ok, error))
    {
      this->Assembled->Norms(weights, sum);
      return this->Agree(true, error) && this->AddSum(own, out, error);
    }
    for (int k = 0; k < count && ok; ++k)
    {
      const SliceGeometry slice = this->Data->Slice(frames[k]);
      if (!AccumulateBasisNorms(this->State.Field.View(), &slice, 1, options, weights + pixels * k, sum, error))
      {
        ok = TrainingFrameError(frames[k], error);
      }
    }
    return this->Agree(ok, error) && this->AddSum(own, out, error);
  }

  void SetBasisMemoryLimit(std::int64_t bytes) override
  {
    this->BasisMemoryLimit = bytes;
    if (this->Assembled && this->Assembled->GetSize().Bytes() > std::max<std::int64_t>(0, bytes))
    {
      this->Assembled.reset();
    }
  }

  std::string DescribeBasisProducts() const override { return this->BasisProducts; }

private:
  /// Adam (Kingma and Ba 2015, algorithm 1: bigus::AdamUpdate) on every Gaussian in one pass that also keeps each
  /// parameter in its meaningful range (unit quaternions, clamped log-scales); false when a gradient
  /// or an updated parameter is not finite.
  bool Adam(const StepRequest& request);
  /// Data-parallel step (Reduction): after this process's frames (@p ok: all rendered), the loss sum @p total,
  /// the pose gradients, the field's gradients and the EA-D accumulators summed over the processes.
  StepStatus Reduce(const StepRequest& request, double& total, bool ok, std::string* error);

  /**
   * Whether the basis products of @p frames with @p options run over the assembled A (AssembledBasis), assembling it
   * for the current geometry when the last one was for other frames or options (or the field changed since):
   * true where it fits in BasisMemoryLimit; false for the matrix-free products (it does not fit, or no limit is
   * set), and false with @p ok false and @p error for a pose the assembly refuses. BasisProducts says which.
   */
  bool UseAssembled(const int* frames, int count, const RenderOptions& options, bool& ok, std::string* error);

  /// Whether this process renders position @p k of a step's frames (all of them alone).
  bool Owns(int k) const { return !this->Reduction || k % this->Reduction->Size() == this->Reduction->Rank(); }
  /// With several processes, whether every one succeeded (ProcessReduction::AllSucceeded); alone, @p ok.
  bool Agree(bool ok, std::string* error) { return this->Reduction ? this->Reduction->AllSucceeded(ok, error) : ok; }
  /// With several processes: @p own (this process's sums) summed over the processes and added to @p out.
  bool AddSum(std::vector<double>& own, double* out, std::string* error)
  {
    if (!this->Reduction)
    {
      return true;
    }
    if (!this->Reduction->Sum(own.data(), own.size(), error))
    {
      return false;
    }
    for (std::size_t i = 0; i < own.size(); ++i)
    {
      out[i] += own[i];
    }
    return true;
  }

  std::unique_ptr<Renderer> Backend;
  ProcessReduction* Reduction = nullptr; // data-parallel: this process's share, summed (SetReduction)
  const TrainingData* Data = nullptr;
  OptimizerState State;
  GaussianField Saved, SavedFirst, SavedSecond; // last known-good field and moments
  // Scratch, kept between steps
  std::vector<float> S, I, LossGradient, Gradients;
  std::vector<int> Seen; // a data-parallel step's seen counts, before they are summed
  ImageLossWorkspace LossWorkspace;
  // The basis products' assembled A, for AssembledKey's frames, elevation sigma and cut-off, dropped
  // when the field changes (Push, Step, Restore) or the data (SetData).
  std::unique_ptr<AssembledBasis> Assembled;
  BasisKey AssembledKey;
  std::int64_t BasisMemoryLimit = 0;
  std::string BasisProducts = "matrix free (no product run yet)";
};

bool CpuTrainingEngine::UseAssembled(
  const int* frames, int count, const RenderOptions& options, bool& ok, std::string* error)
{
  auto assemble = [&](AssembledBasis& basis, std::string& why, bool& tooLarge) {
    std::vector<SliceGeometry> slices(count);
    for (int k = 0; k < count; ++k)
    {
      slices[k] = this->Data->Slice(frames[k]);
    }
    // Refused before allocating when it does not fit (matrix free then); a refused pose fails the product.
    return basis.Assemble(this->State.Field.View(), slices.data(), count, LinearBasisOptions(options),
      this->BasisMemoryLimit, &why, &tooLarge);
  };
  auto describe = [](const AssembledBasis& basis, double seconds) {
    return AssembledBasisText(basis.GetSize().Weights, basis.GetSize().Bytes(), seconds);
  };
  return UseAssembledBasis(this->Assembled, this->AssembledKey, BasisKey(frames, count, options),
    this->BasisMemoryLimit, this->BasisProducts, ok, error, assemble, describe);
}

StepStatus CpuTrainingEngine::Step(const StepRequest& request, double* loss, std::string* error)
{
  this->Assembled.reset(); // the step moves the geometry
  const TrainingData& data = request.Data ? *request.Data : *this->Data;
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const std::int64_t n = this->State.Count();
  this->S.resize(pixels);
  this->I.resize(pixels);
  this->LossGradient.resize(pixels);
  // The field's gradients in its packed layout (bigusFieldLayout.h); with several processes then this step's
  // attribution [N] and seen counts [N] (as float: exact to 2^24 frames), all summed in one reduction.
  this->Gradients.assign((this->Reduction ? FieldParameters + 2 : FieldParameters) * n, 0.f);
  FieldGradients grads = FieldGradientsAt(this->Gradients.data(), n);
  grads.Attribution = this->Reduction ? this->Gradients.data() + FieldParameters * n : this->State.Attribution.data();
  this->Seen.assign(this->Reduction ? n : 0, 0);
  grads.VisibleCount = this->Reduction ? this->Seen.data() : this->State.SeenCount.data();
  if (request.PoseGradients)
  {
    std::fill(request.PoseGradients, request.PoseGradients + 6 * request.Count, 0.0);
  }
  double total = 0;
  for (int b = 0; b < request.Count; ++b)
  {
    const int f = request.Frames[b];
    const SliceGeometry slice = data.Slice(f);
    if (!this->Owns(b))
    {
      continue;
    }
    if (!this->Backend->Forward(
          this->State.Field.View(), &slice, 1, request.Options, this->S.data(), this->I.data(), nullptr, error))
    {
      TrainingFrameError(f, error);
      return this->Reduction ? this->Reduce(request, total, false, error) : StepStatus::Failed;
    }
    total += FrameLoss(data, f, this->I.data(), request, this->LossGradient.data(), &this->LossWorkspace);
    if (request.PoseGradients)
    {
      grads.SlicePoses = request.PoseGradients + 6 * b;
    }
    if (!this->Backend->Backward(this->State.Field.View(), &slice, 1, request.Options, this->S.data(),
          this->LossGradient.data(), false, grads, nullptr, error))
    {
      TrainingFrameError(f, error);
      return this->Reduction ? this->Reduce(request, total, false, error) : StepStatus::Failed;
    }
  }
  if (this->Reduction && this->Reduce(request, total, true, error) == StepStatus::Failed)
  {
    return StepStatus::Failed;
  }
  *loss = total / request.Count;
  if (!std::isfinite(*loss))
  {
    return StepStatus::NonFinite;
  }
  return this->Adam(request) ? StepStatus::Done : StepStatus::NonFinite;
}

StepStatus CpuTrainingEngine::Reduce(const StepRequest& request, double& total, bool ok, std::string* error)
{
  // First whether every process rendered its frames, then one sum of the loss and pose gradients and one of
  // the field's gradients and EA-D accumulators.
  if (!this->Reduction->AllSucceeded(ok, error))
  {
    return StepStatus::Failed;
  }
  const std::int64_t n = this->State.Count();
  std::vector<double> small(1 + (request.PoseGradients ? 6 * request.Count : 0));
  small[0] = total;
  std::copy(request.PoseGradients, request.PoseGradients + (small.size() - 1), small.begin() + 1);
  float* seen = this->Gradients.data() + (FieldParameters + 1) * n;
  // A step's frames touch the Gaussians near their planes only, and every other entry is 0 on every process. So
  // first which Gaussians any process touched (one byte each, a maximum), then the 13 values of those alone: the
  // bytes summed follow the step's frames, not the field, and the sums are the same numbers (x + 0 = x).
  std::vector<unsigned char> touched(n);
  // Each block of the gradient buffer as (first entry in units of N, values per Gaussian): the field's groups,
  // then the attribution and the seen counts.
  std::array<std::pair<int, int>, FieldGroups + 2> blocks;
  for (int q = 0; q < FieldGroups; ++q)
  {
    blocks[q] = { FieldGroupFirst(q), FieldGroupWidth(q) };
  }
  blocks[FieldGroups] = { FieldParameters, 1 };
  blocks[FieldGroups + 1] = { FieldParameters + 1, 1 };
  for (std::int64_t i = 0; i < n; ++i)
  {
    seen[i] = static_cast<float>(this->Seen[i]);
    bool any = false;
    for (const auto& [first, width] : blocks)
    {
      for (int c = 0; c < width; ++c)
      {
        any = any || this->Gradients[first * n + width * i + c] != 0.f;
      }
    }
    touched[i] = any ? 1 : 0;
  }
  if (!this->Reduction->Sum(small.data(), small.size(), error) ||
    !this->Reduction->Maximum(touched.data(), touched.size(), error))
  {
    return StepStatus::Failed;
  }
  std::vector<std::int64_t> touchedIndices;
  for (std::int64_t i = 0; i < n; ++i)
  {
    if (touched[i])
    {
      touchedIndices.push_back(i);
    }
  }
  // [M, 13] per touched Gaussian: the field's 11 gradients (bigusFieldLayout.h), attribution 1, seen 1.
  constexpr int values = FieldParameters + 2;
  const std::size_t m = touchedIndices.size();
  std::vector<float> packed(values * m);
  auto packOrUnpack = [&](bool pack) {
    vtkSMPTools::For(0, static_cast<std::int64_t>(m), 8192, [&](std::int64_t begin, std::int64_t end) {
      for (std::int64_t k = begin; k < end; ++k)
      {
        const std::int64_t i = touchedIndices[k];
        float* entry = packed.data() + values * k;
        for (const auto& [first, width] : blocks)
        {
          for (int c = 0; c < width; ++c, ++entry)
          {
            float& value = this->Gradients[first * n + width * i + c];
            if (pack)
            {
              *entry = value;
            }
            else
            {
              value = *entry;
            }
          }
        }
      }
    });
  };
  packOrUnpack(true);
  if (!this->Reduction->Sum(packed.data(), packed.size(), error))
  {
    return StepStatus::Failed;
  }
  packOrUnpack(false);
  total = small[0];
  std::copy(small.begin() + 1, small.end(), request.PoseGradients);
  const float* attribution = this->Gradients.data() + FieldParameters * n;
  for (const std::int64_t i : touchedIndices)
  {
    this->State.Attribution[i] += attribution[i];
    this->State.SeenCount[i] += static_cast<int>(std::lround(seen[i]));
  }
  return StepStatus::Done;
}

bool CpuTrainingEngine::Adam(const StepRequest& request)
{
  const std::int64_t n = this->State.Count();
  const AdamBias bias = AdamBiasAt(request.Iteration + 1);
  const float lo = static_cast<float>(request.MinimumLogScale), hi = static_cast<float>(request.MaximumLogScale);
  const float* g = this->Gradients.data(); // the field's packed layout
  GaussianField& F = this->State.Field;
  float* p[FieldGroups];
  float* m[FieldGroups];
  float* v[FieldGroups];
  double rate[FieldGroups];
  for (int q = 0; q < FieldGroups; ++q)
  {
    p[q] = F.Group(q).data();
    m[q] = this->State.FirstMoment.Group(q).data();
    v[q] = this->State.SecondMoment.Group(q).data();
    rate[q] = request.Rate(q);
  }
  std::atomic<bool> finite(true);
  vtkSMPTools::For(0, n, 4096, [&](std::int64_t begin, std::int64_t end) {
    bool ok = true;
    for (std::int64_t i = begin; i < end; ++i)
    {
      if (request.SparseAdam && !FieldGradientTouched(g, n, i))
      {
        continue;
      }
      for (int q = 0; q < FieldGroups; ++q)
      {
        for (int c = 0, w = FieldGroupWidth(q); c < w; ++c)
        {
          const float gk = g[FieldEntry(n, i, q, c)];
          ok = ok && std::isfinite(gk);
          AdamUpdate(p[q][w * i + c], m[q][w * i + c], v[q][w * i + c], gk, rate[q], bias);
        }
      }
      float* q = &F.Quaternions[4 * i];
      const float norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      if (norm > 1e-12f)
      {
        for (int k = 0; k < 4; ++k)
        {
          q[k] /= norm;
        }
      }
      float* l = &F.LogScales[3 * i];
      const float* mean = &F.Means[3 * i];
      for (int k = 0; k < 3; ++k)
      {
        l[k] = std::min(hi, std::max(lo, l[k]));
        ok = ok && std::isfinite(mean[k]) && std::isfinite(l[k]);
      }
      ok = ok && std::isfinite(q[0]) && std::isfinite(q[1]) && std::isfinite(q[2]) && std::isfinite(q[3]) &&
        std::isfinite(F.Reflectivities[i]);
    }
    if (!ok)
    {
      finite.store(false, std::memory_order_relaxed);
    }
  });
  return finite.load();
}
}

std::unique_ptr<TrainingEngine> CreateCpuTrainingEngine(std::unique_ptr<Renderer> renderer)
{
  return std::unique_ptr<TrainingEngine>(new CpuTrainingEngine(std::move(renderer)));
}

} // namespace bigus
