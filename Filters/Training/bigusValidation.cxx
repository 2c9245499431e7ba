// The validation stage (see bigusValidation.h).
#include "bigusValidation.h"

#include <algorithm>

namespace bigus
{

std::vector<int> ValidationFrames(const TrainingData& data)
{
  std::vector<int> frames;
  const int count = static_cast<int>(data.TrainFrames.size());
  const int stride = std::max(1, count / 8);
  for (int n = 0; n < count && frames.size() < 8; n += stride)
  {
    frames.push_back(data.TrainFrames[n]);
  }
  return frames;
}

bool ValidationLoss(TrainingEngine& engine, const TrainingData& data, const std::vector<int>& frames,
  const RenderOptions& options, const ImageLossWeights& weights, ProcessReduction* reduction, double& loss,
  std::string* error)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  std::vector<float> S(pixels), I(pixels);
  ImageLossWorkspace workspace;
  double total = 0;
  bool ok = true;
  for (std::size_t k = 0; k < frames.size() && ok; ++k)
  {
    if (reduction && static_cast<int>(k % reduction->Size()) != reduction->Rank())
    {
      continue;
    }
    const int f = frames[k];
    const SliceGeometry slice = data.Slice(f);
    ok = engine.Render(&slice, 1, options, S.data(), I.data(), error);
    if (ok)
    {
      total += ComputeImageLoss(I.data(), &data.Frames[pixels * f], data.MaskOf(f), data.Width, data.Height, weights,
        nullptr, false, &workspace)
                 .Total;
    }
  }
  if (reduction && (!reduction->AllSucceeded(ok, error) || !reduction->Sum(&total, 1, error)))
  {
    return false;
  }
  if (!ok)
  {
    return false;
  }
  loss = total / std::max<std::size_t>(1, frames.size());
  return true;
}

void KeepIfBest(TrainingState& state, double loss, const GaussianField& field)
{
  if (!(state.BestFieldLoss < 0 || loss < state.BestFieldLoss))
  {
    return; // not better (a NaN loss never is)
  }
  state.BestFieldLoss = loss;
  state.BestFieldIteration = state.Iteration;
  state.BestField = field;
  state.BestPoseCorrections = state.PoseCorrections;
  state.BestSharedPoseCorrection = state.SharedPoseCorrection;
}

bool RestoreBestField(TrainingState& state, double last)
{
  if (!(last > state.BestFieldLoss))
  {
    return false;
  }
  state.Gaussians = OptimizerState();
  state.Gaussians.Field = state.BestField;
  state.Gaussians.ResizeToField();
  if (state.BestPoseCorrections.size() == state.PoseCorrections.size())
  {
    state.PoseCorrections = state.BestPoseCorrections;
  }
  state.SharedPoseCorrection = state.BestSharedPoseCorrection;
  return true;
}

} // namespace bigus
