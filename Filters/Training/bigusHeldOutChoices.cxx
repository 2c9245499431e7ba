// The held-out choices (see bigusHeldOutChoices.h).
#include "bigusHeldOutChoices.h"

#include "bigusTrainer.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <map>
#include <memory>

namespace bigus
{

namespace
{
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
  std::vector<int> heldOut;
  for (auto& entry : sweeps)
  {
    std::vector<int>& frames = entry.second;
    std::sort(frames.begin(), frames.end());
    for (std::size_t k = stride / 2; k + 1 < frames.size(); k += stride)
    {
      heldOut.push_back(frames[k]); // between two training frames of its sweep (k >= 1 as stride >= 2)
    }
  }
  std::sort(heldOut.begin(), heldOut.end());
  if (maximum > 0 && static_cast<int>(heldOut.size()) > maximum)
  {
    // Spread evenly over them (the first and the last kept).
    std::vector<int> spread;
    for (int k = 0; k < maximum; ++k)
    {
      const std::size_t at = maximum == 1 ? 0 : (k * (heldOut.size() - 1) + (maximum - 1) / 2) / (maximum - 1);
      spread.push_back(heldOut[at]);
    }
    heldOut = spread;
  }
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
    return "untested on held-out frames: " + this->Untested;
  }
  const int last = this->Stride % 10;
  const char* ordinal = this->Stride % 100 / 10 == 1 ? "th"
    : last == 1                                      ? "st"
    : last == 2                                      ? "nd"
    : last == 3                                      ? "rd"
                                                     : "th";
  std::string text =
    vtkfmt::sprintf("chosen on %zu frames held out (every %d%s training frame, left out of every candidate's fit):",
      this->Frames.size(), this->Stride, ordinal);
  double seconds = 0;
  for (std::size_t k = 0; k < this->Candidates.size(); ++k)
  {
    const HeldOutCandidate& c = this->Candidates[k];
    text += vtkfmt::sprintf("%s %.3g %s %.2f dB", k == 0 ? "" : ",", c.Value, unit, c.PSNR);
    seconds += c.Seconds;
  }
  return text + vtkfmt::sprintf(" (%.1f s)", seconds);
}

void HeldOutChoice::RewriteSettingLine(std::vector<std::string>& lines, const char* name, const char* unit) const
{
  const std::string prefix = std::string(name) + " = ";
  for (std::string& ruleLine : lines)
  {
    const std::size_t open = ruleLine.find('('), close = ruleLine.rfind(')');
    if (ruleLine.rfind(prefix, 0) != 0)
    {
      continue;
    }
    if (this->Chosen < 0 || open == std::string::npos || close == std::string::npos || close < open)
    {
      ruleLine =
        (close == std::string::npos ? ruleLine : ruleLine.substr(0, close)) + "; " + this->Describe(unit) + ")";
      continue;
    }
    const double rule = std::atof(ruleLine.c_str() + prefix.size());
    ruleLine =
      vtkfmt::sprintf("%s = %.4g %s (%s; the rule's value %.4g %s, %s)", name, this->Candidates[this->Chosen].Value,
        unit, this->Describe(unit).c_str(), rule, unit, ruleLine.substr(open + 1, close - open - 1).c_str());
  }
}

bool ElevationSigmaOnHeldOutFrames(const TrainingData& data, const TrainerSettings& settings, bool pixelGrid,
  double ruleSigma, HeldOutChoice& choice, std::string* error)
{
  choice = HeldOutChoice();
  if (!settings.HeldOut.Enabled)
  {
    choice.Untested = "the held-out choices are off";
    return true;
  }
  if (!pixelGrid)
  {
    choice.Untested = "a candidate's fit on this route is an Adam run, which the budget does not repeat per candidate";
    return true;
  }
  return ChooseElevationSigmaOnHeldOutFrames(data, settings, ruleSigma, choice, error);
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
  choice.Stride = std::max(2, settings.HeldOut.Stride);
  // Every candidate is fitted without any held-out frame and scored on up to MaximumFrames of them.
  const std::vector<int> heldOut = HeldOutFrames(data, settings.HeldOut.Stride, 0);
  choice.Frames = HeldOutFrames(data, settings.HeldOut.Stride, settings.HeldOut.MaximumFrames);
  if (choice.Frames.size() < 2)
  {
    choice.Untested =
      vtkfmt::sprintf("%zu training frames leave fewer than 2 to hold out between them", data.TrainFrames.size());
    return true;
  }
  for (double factor : settings.HeldOut.ElevationSigmaFactors)
  {
    const double start = SteadySeconds();
    HeldOutCandidate c;
    c.Value = ruleSigma * factor;
    TrainerSettings s = settings;
    s.ElevationSigma = c.Value;
    const std::unique_ptr<Trainer> trainer = FitCandidate(data, heldOut, s, error);
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
    c.Seconds = SteadySeconds() - start;
    choice.Candidates.push_back(c);
  }
  // The narrowest beam within Tolerance of the best score: the held-out frames lie twice as far from the fitted
  // ones as the final field's in-between views from its frames, which favours a wider beam.
  double best = -std::numeric_limits<double>::infinity();
  for (const HeldOutCandidate& c : choice.Candidates)
  {
    best = std::max(best, c.PSNR);
  }
  for (std::size_t k = 0; k < choice.Candidates.size(); ++k)
  {
    const HeldOutCandidate& c = choice.Candidates[k];
    if (c.PSNR >= best - settings.HeldOut.Tolerance &&
      (choice.Chosen < 0 || c.Value < choice.Candidates[choice.Chosen].Value))
    {
      choice.Chosen = static_cast<int>(k);
    }
  }
  return true;
}

} // namespace bigus
