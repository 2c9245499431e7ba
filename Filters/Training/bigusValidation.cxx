// The validation stage (see bigusValidation.h).
#include "bigusValidation.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

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

std::vector<int> ChooseValidationFrames(TrainingData& data, const HeldOutChoiceSettings& settings,
  const std::vector<int>& given, bool& heldOut, std::string& line, const std::string& until)
{
  const HeldOutChoiceSettings& h = settings;
  const bool holdOut = h.HoldOutValidationFrames == ValidationHoldOut::On || !given.empty();
  const int minimum = given.empty() ? std::max(2, h.MinimumValidationFrames) : 1;
  int stride = h.ValidationStride;
  std::vector<int> frames = !given.empty() ? given
    : holdOut                              ? HeldOutFrames(data, stride, h.MaximumValidationFrames)
                                           : std::vector<int>();
  if (holdOut && given.empty() && static_cast<int>(frames.size()) < minimum && h.SparseValidationStride < stride)
  {
    stride = std::max(2, h.SparseValidationStride);
    frames = HeldOutFrames(data, stride, h.MaximumValidationFrames);
  }
  heldOut = static_cast<int>(frames.size()) >= minimum;
  if (!heldOut)
  {
    frames = ValidationFrames(data);
    line = vtkfmt::sprintf("Validation = %d training frames (%s)", int(frames.size()),
      holdOut ? vtkfmt::sprintf("too few training frames to hold %d out", minimum).c_str()
              : "every (T / 8)-th of the T training frames: none is held out of the fit");
    return frames;
  }
  std::vector<int>& train = data.TrainFrames; // both in order
  train.erase(std::remove_if(
                train.begin(), train.end(), [&](int f) { return std::binary_search(frames.begin(), frames.end(), f); }),
    train.end());
  line = vtkfmt::sprintf("Validation = %d held-out frames (%s): out of the fit until %s, then in it; growth stops "
                         "and early stopping keeps a field on them",
    int(frames.size()),
    given.empty()
      ? vtkfmt::sprintf("one in %d training frames of a sweep, at most %d", stride, h.MaximumValidationFrames).c_str()
      : "the route trial's, which no fit of the pixel grid saw",
    until);
  return frames;
}

bool HoldOutValidationByRule(const std::vector<SweepDecorrelation>& sweeps, std::string& reason)
{
  const PoseRefinementChoice measured = ChoosePoseRefinement(sweeps);
  const std::size_t n = measured.Correlation.size();
  bool uncorrelated = n > 0;
  reason.clear();
  for (std::size_t s = 0; s < n; ++s)
  {
    // Spacing 0 says the sweep could not be measured; a measured correlation may be negative (speckle that shares
    // nothing at that spacing, minus the noise), and is below the threshold like any other.
    const bool wasMeasured = measured.Spacing[s] > 0;
    const double rho = measured.Correlation[s];
    const bool below = wasMeasured && rho < PoseRefinementMinimumCorrelation;
    uncorrelated = uncorrelated && below;
    reason += (s > 0 ? "; " : "") + (n > 1 ? vtkfmt::sprintf("sweep %zu: ", s) : std::string()) +
      (!wasMeasured ? std::string("its frames cannot be measured")
                    : vtkfmt::sprintf("speckle correlation %.2f at the training frames' spacing %.3g mm %s %.2g", rho,
                        measured.Spacing[s], below ? "<" : ">=", PoseRefinementMinimumCorrelation));
  }
  return uncorrelated;
}

void JoinTrainingFrames(TrainingData& data, const std::vector<int>& frames)
{
  std::vector<int>& train = data.TrainFrames;
  train.insert(train.end(), frames.begin(), frames.end());
  std::sort(train.begin(), train.end());
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
