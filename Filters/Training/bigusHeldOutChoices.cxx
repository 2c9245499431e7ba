// The held-out choices (see bigusHeldOutChoices.h).
#include "bigusHeldOutChoices.h"

#include "bigusTrainer.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>

namespace bigus
{

namespace
{
double Now()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// A trainer that has made the candidate's fit (Initialize) on the training frames other than @p heldOut.
std::unique_ptr<Trainer> FitCandidate(
  const TrainingData& data, const std::vector<int>& heldOut, const TrainerSettings& settings, std::string* error)
{
  TrainerSettings s = settings;
  s.HeldOut.Enabled = false;                 // no choice inside a choice
  s.Poses.RefinePoses = PoseRefinement::Off; // a candidate is scored at the tracked poses
  s.Poses.RefineTimeOffset = false;
  s.Poses.RefineImageToProbe = false;
  std::unique_ptr<Trainer> trainer(new Trainer(WithoutHeldOutFrames(data, heldOut), s));
  if (!trainer->Initialize(error))
  {
    return nullptr;
  }
  return trainer;
}
}

std::vector<int> HeldOutFrames(const TrainingData& data, int stride, int maximum)
{
  stride = std::max(2, stride);
  std::map<int, std::vector<int>> sweeps; // each sweep's training frames, in order
  for (int f : data.TrainFrames)
  {
    sweeps[data.SweepOf(f)].push_back(f);
  }
  std::vector<std::vector<int>> candidates;
  for (auto& entry : sweeps)
  {
    std::vector<int>& frames = entry.second;
    std::sort(frames.begin(), frames.end());
    std::vector<int> own;
    for (std::size_t k = stride / 2; k + 1 < frames.size(); k += stride)
    {
      if (k > 0)
      {
        own.push_back(frames[k]); // between two training frames of its sweep
      }
    }
    candidates.push_back(own);
  }
  // The sweeps' shares in turn, up to the maximum.
  std::vector<int> heldOut;
  for (std::size_t round = 0; static_cast<int>(heldOut.size()) < maximum; ++round)
  {
    bool any = false;
    for (const std::vector<int>& own : candidates)
    {
      if (round < own.size() && static_cast<int>(heldOut.size()) < maximum)
      {
        heldOut.push_back(own[round]);
        any = true;
      }
    }
    if (!any)
    {
      break;
    }
  }
  std::sort(heldOut.begin(), heldOut.end());
  return heldOut;
}

TrainingData WithoutHeldOutFrames(const TrainingData& data, const std::vector<int>& heldOut)
{
  TrainingData fit = data;
  fit.TrainFrames.clear();
  for (int f : data.TrainFrames)
  {
    if (std::find(heldOut.begin(), heldOut.end(), f) == heldOut.end())
    {
      fit.TrainFrames.push_back(f);
    }
  }
  return fit;
}

std::string HeldOutChoice::Describe(const char* unit) const
{
  if (this->Chosen < 0)
  {
    return "untested: " + this->Untested;
  }
  std::string text = vtkfmt::sprintf("chosen on %zu held-out frames:", this->Frames.size());
  double seconds = 0;
  for (std::size_t k = 0; k < this->Candidates.size(); ++k)
  {
    const HeldOutCandidate& c = this->Candidates[k];
    text += vtkfmt::sprintf("%s %.3g %s %.2f dB", k == 0 ? "" : ",", c.Value, unit, c.PSNR);
    seconds += c.Seconds;
  }
  return text + vtkfmt::sprintf(" (%.1f s)", seconds);
}

bool FitWithoutHeldOutFrames(const TrainingData& data, const std::vector<int>& heldOut, const TrainerSettings& settings,
  GaussianField& field, std::string* error)
{
  const std::unique_ptr<Trainer> trainer = FitCandidate(data, heldOut, settings, error);
  if (!trainer)
  {
    return false;
  }
  field = trainer->GetField();
  return true;
}

bool ChooseElevationSigmaOnHeldOutFrames(const TrainingData& data, const TrainerSettings& settings, double ruleSigma,
  HeldOutChoice& choice, std::string* error)
{
  choice = HeldOutChoice();
  choice.Frames = HeldOutFrames(data, settings.HeldOut.Stride, settings.HeldOut.MaximumFrames);
  if (choice.Frames.size() < 2)
  {
    choice.Untested =
      vtkfmt::sprintf("%zu training frames leave fewer than 2 to hold out between them", data.TrainFrames.size());
    return true;
  }
  for (double factor : settings.HeldOut.ElevationSigmaFactors)
  {
    const double start = Now();
    HeldOutCandidate c;
    c.Value = ruleSigma * factor;
    TrainerSettings s = settings;
    s.ElevationSigma = c.Value;
    const std::unique_ptr<Trainer> trainer = FitCandidate(data, choice.Frames, s, error);
    ImageMetrics metrics;
    if (!trainer || !trainer->EvaluateOn(data, choice.Frames, metrics, error))
    {
      if (error)
      {
        *error = vtkfmt::sprintf("ElevationSigma candidate %.4g mm: ", c.Value) + *error;
      }
      return false;
    }
    c.PSNR = metrics.PSNR;
    c.Count = trainer->GetField().Count();
    c.Seconds = Now() - start;
    choice.Candidates.push_back(c);
    if (choice.Chosen < 0 || c.PSNR > choice.Candidates[choice.Chosen].PSNR)
    {
      choice.Chosen = static_cast<int>(choice.Candidates.size()) - 1;
    }
  }
  return true;
}

} // namespace bigus
