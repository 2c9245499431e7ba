// The held-out choices (see bigusHeldOutChoices.h).
#include "bigusHeldOutChoices.h"

#include "bigusTrainer.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cstdlib>
#include <functional>
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
    text += vtkfmt::sprintf("%s %.3g%s%s %.2f dB", k == 0 ? "" : ",", c.Value, *unit ? " " : "", unit, c.PSNR);
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
    const std::string scaled =
      this->Scale == 1 ? std::string() : vtkfmt::sprintf("; taken x %.3g: %s", this->Scale, this->ScaleReason.c_str());
    ruleLine = vtkfmt::sprintf("%s = %.4g%s%s (%s%s; the rule's value %.4g%s%s, %s)", name, this->Taken(),
      *unit ? " " : "", unit, this->Describe(unit).c_str(), scaled.c_str(), rule, *unit ? " " : "", unit,
      ruleLine.substr(open + 1, close - open - 1).c_str());
  }
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

namespace
{
/// A candidate of @p settings fitted without @p heldOut (FitCandidate) and scored on @p scored: its PSNR into @p c
/// (and its Gaussians and seconds); the fit, or null with @p error prefixed by @p what.
std::unique_ptr<Trainer> FitAndScore(const TrainingData& data, const std::vector<int>& heldOut,
  const std::vector<int>& scored, const TrainerSettings& settings, const std::string& what, HeldOutCandidate& c,
  std::string* error)
{
  const double start = SteadySeconds();
  std::unique_ptr<Trainer> fit = FitCandidate(data, heldOut, settings, error);
  ImageMetrics metrics;
  if (!fit || !fit->EvaluateOn(data, scored, metrics, error))
  {
    if (error)
    {
      *error = what + ": " + *error;
    }
    return nullptr;
  }
  c.PSNR = metrics.PSNR;
  c.Count = fit->GetField().Count();
  c.Seconds = SteadySeconds() - start;
  return fit;
}

/// Why the held-out fits stopped @p elapsed seconds after they started: @p what (the fits still to come) would pass
/// the @p allowed seconds (HeldOutChoiceSettings::MaximumSeconds, which the route trial sets to half the budget).
std::string FitsStoppedForTime(double elapsed, const std::string& what, double allowed)
{
  return vtkfmt::sprintf(
    "its fits stopped after %.1f s, as %s would pass the %.3g s allowed (half the budget)", elapsed, what, allowed);
}

/// The index of the first candidate of @p candidates within @p tolerance dB of the best; -1 when there is none.
int FirstWithinTolerance(const std::vector<HeldOutCandidate>& candidates, double tolerance)
{
  double best = -std::numeric_limits<double>::infinity();
  for (const HeldOutCandidate& c : candidates)
  {
    best = std::max(best, c.PSNR);
  }
  for (std::size_t k = 0; k < candidates.size(); ++k)
  {
    if (candidates[k].PSNR >= best - tolerance)
    {
      return static_cast<int>(k);
    }
  }
  return -1;
}

/// What the candidates of one choice share: the data, the frames held out of their fits and those scored.
struct CandidateFits
{
  const TrainingData& Data;
  std::vector<int> HeldOut; ///< every frame left out of the fits
  std::vector<int> Scored;  ///< the held-out frames rendered and scored
  double Tolerance = 0;
  /// The fit of the candidate chosen so far, kept for the next choice and the reduction.
  std::unique_ptr<Trainer> Kept;
  double Start = SteadySeconds();
  double MaximumSeconds = 0; ///< HeldOutChoiceSettings::MaximumSeconds
  double LastFitSeconds = 0;
  int Planned = 0;       ///< the candidates' fits planned in all
  int Done = 0;          ///< of them, fitted
  std::string OutOfTime; ///< why the fits stopped before their last candidate (empty: they did not)

  /// Whether the fits still planned (at least one), each taken as long as the last, end within MaximumSeconds;
  /// OutOfTime says why not.
  bool HasTimeForAnotherFit()
  {
    const double elapsed = SteadySeconds() - this->Start;
    const int left = std::max(1, this->Planned - this->Done);
    if (this->MaximumSeconds > 0 && elapsed + left * this->LastFitSeconds > this->MaximumSeconds)
    {
      this->OutOfTime = FitsStoppedForTime(elapsed,
        vtkfmt::sprintf("the %d left after %d (the last took %.1f s)", left, this->Done, this->LastFitSeconds),
        this->MaximumSeconds);
      return false;
    }
    return true;
  }

  /**
   * Fits and scores a candidate of @p settings for each of @p values (@p apply sets one into the settings), after
   * @p choice's candidates already there, keeping the fit of the one chosen so far (the first within the tolerance
   * of the best); the one chosen at the end is refitted when an earlier best displaced it.
   */
  bool Measure(const TrainerSettings& settings, const std::vector<double>& values,
    const std::function<void(TrainerSettings&, double)>& apply, const char* name, HeldOutChoice& choice,
    std::string* error)
  {
    for (double value : values)
    {
      if (!this->HasTimeForAnotherFit())
      {
        return true;
      }
      TrainerSettings s = settings;
      apply(s, value);
      HeldOutCandidate c;
      c.Value = value;
      std::unique_ptr<Trainer> fit = FitAndScore(
        this->Data, this->HeldOut, this->Scored, s, vtkfmt::sprintf("%s candidate %.4g", name, value), c, error);
      if (!fit)
      {
        return false;
      }
      this->LastFitSeconds = c.Seconds;
      ++this->Done;
      const int before = choice.Chosen;
      choice.Candidates.push_back(c);
      choice.Chosen = FirstWithinTolerance(choice.Candidates, this->Tolerance);
      if (choice.Chosen == static_cast<int>(choice.Candidates.size()) - 1)
      {
        this->Kept = std::move(fit);
      }
      else if (choice.Chosen != before)
      {
        this->Kept.reset(); // an earlier candidate, whose fit was not kept, is chosen now
      }
    }
    if (choice.Candidates.empty())
    {
      choice.Untested = "no candidates";
      return true;
    }
    if (choice.Chosen < 0)
    {
      if (error)
      {
        *error = std::string(name) + ": no candidate scored a finite PSNR on the held-out frames";
      }
      return false;
    }
    if (!this->Kept)
    {
      if (!this->HasTimeForAnotherFit())
      {
        return true;
      }
      TrainerSettings s = settings;
      apply(s, choice.Candidates[choice.Chosen].Value);
      this->Kept = FitCandidate(this->Data, this->HeldOut, s, error);
    }
    return this->Kept != nullptr;
  }

  /// The final prune, then the merge, of the kept fit (its PSNR @p wholePSNR), scored on the held-out frames.
  bool MeasureReduction(const TrainerSettings& settings, double wholePSNR, HeldOutReduction& r, std::string* error)
  {
    const double start = SteadySeconds();
    Trainer& fit = *this->Kept;
    const GaussianField whole = fit.GetField();
    auto score = [&](const GaussianField& field, double& psnr) {
      ImageMetrics metrics;
      if (!fit.SetField(field, error) || !fit.EvaluateOn(this->Data, this->Scored, metrics, error))
      {
        return false;
      }
      psnr = metrics.PSNR;
      return true;
    };
    r.Frames = static_cast<int>(this->Scored.size());
    r.WholePSNR = wholePSNR;
    r.Whole = whole.Count();
    OptimizerState G;
    G.Field = whole;
    G.ResizeToField();
    r.PruneMeasured = settings.FinalPruneTolerance > 0;
    r.Pruned = r.Whole;
    r.PrunedPSNR = r.WholePSNR;
    if (r.PruneMeasured)
    {
      FinalPrune(G, fit.GetData(), fit.Options(), fit.GetGamma(), settings.FinalPruneTolerance);
      r.Pruned = G.Field.Count();
      if (!score(G.Field, r.PrunedPSNR))
      {
        return false;
      }
      r.KeepPrune = r.PrunedPSNR >= r.WholePSNR - this->Tolerance;
    }
    if (!r.KeepPrune)
    {
      G.Field = whole;
      G.ResizeToField();
    }
    r.MergeMeasured = settings.Merge.Tolerance > 0;
    if (r.MergeMeasured)
    {
      MergeGaussians(G, settings.Merge);
      r.Merged = G.Field.Count();
      if (!score(G.Field, r.MergedPSNR))
      {
        return false;
      }
      r.KeepMerge = r.MergedPSNR >= (r.KeepPrune ? r.PrunedPSNR : r.WholePSNR) - this->Tolerance;
    }
    r.Seconds = SteadySeconds() - start;
    return true;
  }
};
}

void HeldOutReduction::RewriteSettingLines(std::vector<std::string>& lines) const
{
  for (std::string& line : lines)
  {
    const bool prune = line.rfind("FinalPrune = ", 0) == 0 && (!this->Untested.empty() || this->PruneMeasured);
    const bool merge = line.rfind("Merge = ", 0) == 0 && (!this->Untested.empty() || this->MergeMeasured);
    if (!prune && !merge)
    {
      continue;
    }
    if (!this->Untested.empty())
    {
      line += "; untested on held-out frames: " + this->Untested;
      continue;
    }
    const bool keep = prune ? this->KeepPrune : this->KeepMerge;
    const double before = prune || !this->KeepPrune ? this->WholePSNR : this->PrunedPSNR;
    const double after = prune ? this->PrunedPSNR : this->MergedPSNR;
    const std::int64_t from = prune || !this->KeepPrune ? this->Whole : this->Pruned;
    const std::int64_t to = prune ? this->Pruned : this->Merged;
    if (!keep)
    {
      line = line.substr(0, line.find(" = ")) + " = off (was: " + line.substr(line.find(" = ") + 3) + ")";
    }
    line += vtkfmt::sprintf("; %s on %d held-out frames, the chosen candidate's fit: %.2f dB with %lld Gaussians, "
                            "%.2f dB with %lld after it (%.1f s)",
      keep ? "kept" : "dropped", this->Frames, before, static_cast<long long>(from), after, static_cast<long long>(to),
      this->Seconds);
  }
}

bool ChooseOnHeldOutFrames(const TrainingData& data, const TrainerSettings& settings, bool pixelGrid, bool sigmaByRule,
  HeldOutChoices& choices, std::string* error)
{
  choices = HeldOutChoices();
  const HeldOutChoiceSettings& h = settings.HeldOut;
  CandidateFits fits{ data, HeldOutFrames(data, h.Stride, 0), HeldOutFrames(data, h.Stride, h.MaximumFrames),
    h.Tolerance, nullptr };
  fits.MaximumSeconds = h.MaximumSeconds;
  // No candidate taken (empty @p why: none yet): every choice with its frames and why it is untested.
  auto untestedChoices = [&](const std::string& why) {
    choices = HeldOutChoices();
    for (HeldOutChoice* choice : { &choices.ElevationSigma, &choices.Ridge })
    {
      choice->Stride = std::max(2, h.Stride);
      choice->Frames = fits.Scored;
      choice->Untested = why;
    }
  };
  // Out of time: nothing measured is taken.
  auto outOfTime = [&]() {
    untestedChoices(fits.OutOfTime);
    choices.Reduction.Untested = fits.OutOfTime;
    return true;
  };
  std::string untested = !h.Enabled ? "the held-out choices are off"
    : !pixelGrid ? "a candidate's fit on this route is an Adam run, which the budget does not repeat per candidate"
    : fits.Scored.size() < 2
    ? vtkfmt::sprintf("%zu training frames leave fewer than 2 to hold out between them", data.TrainFrames.size())
    : std::string();
  untestedChoices(untested);
  choices.Reduction.Untested = h.Enabled && !pixelGrid
    ? "on this route no frame is held out at the end (the validation frames join the fit)"
    : !untested.empty()  ? untested
    : h.MeasureReduction ? std::string()
                         : "its measurement is off (MeasureReduction)";
  if (!untested.empty())
  {
    return true;
  }
  std::vector<double> sigmas{ settings.ElevationSigma };
  if (sigmaByRule && !h.ElevationSigmaFactors.empty())
  {
    sigmas.clear();
    for (double factor : h.ElevationSigmaFactors)
    {
      sigmas.push_back(settings.ElevationSigma * factor);
    }
  }
  fits.Planned = static_cast<int>(sigmas.size() + h.RidgeFactors.size()) -
    (!h.RidgeFactors.empty() && h.RidgeFactors.front() == 1.0 ? 1 : 0); // the first ridge's is sigma's fit
  HeldOutChoice& sigma = choices.ElevationSigma;
  if (!fits.Measure(
        settings, sigmas, [](TrainerSettings& s, double v) { s.ElevationSigma = v; }, "ElevationSigma", sigma, error))
  {
    return false;
  }
  if (!fits.OutOfTime.empty())
  {
    return outOfTime();
  }
  sigma.Scale = h.ElevationSigmaScale;
  sigma.ScaleReason = "the fit on every frame has its views half as far from its frames as the held-out frames lie "
                      "from the candidates' fits";
  TrainerSettings chosen = settings;
  chosen.ElevationSigma = sigma.Candidates[sigma.Chosen].Value;
  // The ridge's first candidate, the rule's ridge at the chosen sigma, is that sigma's fit, already scored (and kept).
  HeldOutChoice& ridge = choices.Ridge;
  HeldOutCandidate fitted = sigma.Candidates[sigma.Chosen];
  if (!sigmaByRule)
  {
    sigma = HeldOutChoice(); // given: measured only as the ridge's first candidate
    sigma.Untested = "given";
  }
  std::vector<double> ridges;
  for (double factor : h.RidgeFactors)
  {
    ridges.push_back(settings.Solve.Ridge * factor);
  }
  if (!ridges.empty() && h.RidgeFactors.front() == 1.0)
  {
    fitted.Value = ridges.front();
    fitted.Seconds = sigmaByRule ? 0.0 : fitted.Seconds; // counted in ElevationSigma's where that was measured
    ridge.Candidates.push_back(fitted);
    ridge.Chosen = 0;
    ridges.erase(ridges.begin());
  }
  if (!fits.Measure(
        chosen, ridges, [](TrainerSettings& s, double v) { s.Solve.Ridge = v; }, "Ridge", ridge, error))
  {
    return false;
  }
  if (!fits.OutOfTime.empty())
  {
    return outOfTime();
  }
  const HeldOutCandidate& fit = ridge.Chosen >= 0 ? ridge.Candidates[ridge.Chosen] : fitted;
  chosen.Solve.Ridge = ridge.Chosen >= 0 ? fit.Value : settings.Solve.Ridge;
  return !choices.Reduction.Untested.empty() || fits.MeasureReduction(chosen, fit.PSNR, choices.Reduction, error);
}

bool ApplyHeldOutChoices(
  const HeldOutChoices& choices, bool sigmaByRule, bool pixelGrid, TrainerSettings& s, std::vector<std::string>& lines)
{
  if (pixelGrid)
  {
    lines.push_back(
      vtkfmt::sprintf("Ridge = %.4g (the solve's: lambda as a share of the mean diag(A^T G A))", s.Solve.Ridge));
    choices.Ridge.RewriteSettingLine(lines, "Ridge", "");
  }
  choices.Reduction.RewriteSettingLines(lines);
  if (choices.Ridge.Chosen >= 0)
  {
    s.Solve.Ridge = choices.Ridge.Candidates[choices.Ridge.Chosen].Value;
  }
  s.FinalPruneTolerance = choices.Reduction.KeepPrune ? s.FinalPruneTolerance : 0.0;
  s.Merge.Tolerance = choices.Reduction.KeepMerge ? s.Merge.Tolerance : 0.0;
  if (!sigmaByRule)
  {
    return false;
  }
  const HeldOutChoice& sigma = choices.ElevationSigma;
  choices.ElevationSigma.RewriteSettingLine(lines, "ElevationSigma", "mm");
  const double chosen = sigma.Chosen < 0 ? s.ElevationSigma : sigma.Taken();
  const bool changed = chosen != s.ElevationSigma;
  s.ElevationSigma = chosen;
  return changed;
}

std::string RouteTrialUntested(
  const TrainingData& data, const TrainerSettings& settings, const SeedingPlan& plan, bool dataParallel)
{
  const HeldOutChoiceSettings& h = settings.HeldOut;
  const std::int64_t all = plan.Planes.FanPixels;
  const double seconds = 6.5 * h.GridFitSecondsPerGaussian * static_cast<double>(all);
  return !h.Enabled   ? "the held-out choices are off"
    : !h.MeasureRoute ? "its measurement is off (MeasureRoute)"
    : all <= 0        ? "the pixel-grid fit does not apply to these settings"
    : dataParallel    ? "a data-parallel run does not measure it"
    : settings.Poses.RefineTimeOffset || settings.Poses.RefineImageToProbe
    ? "a shared pose correction (time offset, ImageToProbe) is refined, which the grid's fit would not"
    : settings.TimeBudget <= 0 ? "no time budget to plan the measurement in"
    : !TrainingFitsInMemory(data, all, true, settings.Solve.L1 > 0)
    ? vtkfmt::sprintf(
        "a grid of every one of the %lld fan pixels does not fit this machine's memory", static_cast<long long>(all))
    : seconds > 0.5 * settings.TimeBudget
    ? vtkfmt::sprintf("the pixel grid's fits (about %.0f s for %lld Gaussians) would take more than half the budget",
        seconds, static_cast<long long>(all))
    : std::string();
}

bool MeasurePixelGridRoute(
  const TrainingData& data, const TrainerSettings& settings, bool sigmaByRule, RouteTrial& trial, std::string* error)
{
  const double start = SteadySeconds();
  TrainerSettings grid = settings;
  grid.Seeding.PixelGridFanPixelsPerGaussian = std::numeric_limits<double>::infinity();
  grid.HeldOut.MaximumSeconds = 0.5 * settings.TimeBudget;
  if (!ChooseOnHeldOutFrames(data, grid, true, sigmaByRule, trial.Grid, error))
  {
    return false;
  }
  trial.Frames = trial.Grid.Ridge.Frames;
  const double left = grid.HeldOut.MaximumSeconds - (SteadySeconds() - start);
  double last = 0; // the longest candidate's fit: the route's takes about as long
  for (const HeldOutChoice* choice : { &trial.Grid.ElevationSigma, &trial.Grid.Ridge })
  {
    for (const HeldOutCandidate& c : choice->Candidates)
    {
      last = std::max(last, c.Seconds);
    }
  }
  trial.Untested = trial.Frames.size() < 2 || !trial.Grid.Ridge.Untested.empty() ? trial.Grid.Ridge.Untested
    : last > left ? FitsStoppedForTime(SteadySeconds() - start, vtkfmt::sprintf("the route's fit (about %.1f s)", last),
                      grid.HeldOut.MaximumSeconds)
                  : std::string();
  if (!trial.Untested.empty())
  {
    trial.Frames.clear();
    trial.GridSeconds = SteadySeconds() - start;
    return true;
  }
  std::vector<std::string> lines;
  ApplyHeldOutChoices(trial.Grid, sigmaByRule, true, grid, lines);
  // Its frames lie a whole spacing from the fitted ones, as the choices' held-out frames do: the beam chosen for that
  // gap, not the narrower one taken for the fit on every frame (ElevationSigmaScale), which the switch takes.
  const HeldOutChoice& sigma = trial.Grid.ElevationSigma;
  grid.ElevationSigma = sigma.Chosen >= 0 ? sigma.Candidates[sigma.Chosen].Value : grid.ElevationSigma;
  HeldOutCandidate c;
  if (!FitAndScore(data, trial.Frames, trial.Frames, grid, "the pixel grid's fit for the route", c, error))
  {
    return false;
  }
  trial.GridPSNR = c.PSNR;
  trial.GridGaussians = c.Count;
  trial.GridSeconds = SteadySeconds() - start;
  trial.Pending = true;
  return true;
}

std::string RouteTrial::Line() const
{
  // The routes no run measures, and the report that measured them (item 5 of issue 54: the Pareto section).
  const std::string others = "; variable projection and grids at a coarser stride untested: on the liver, the spine "
                             "phantom and the volume protocol each scored below Adam alone or the grid of every fan "
                             "pixel (docs/BENCHMARKS_pareto.md)";
  const std::string rule =
    vtkfmt::sprintf("the rule: the %lld fan pixels of the grid's planes are %s %g x MaximumGaussians",
      static_cast<long long>(this->FanPixels), this->GridByRule ? "at most" : "more than", this->RulePixelsPerGaussian);
  const bool adamSide = !this->GridByRule || this->AdamProbe; // the run started as Adam's
  if (!this->Untested.empty() || (!this->Pending && this->DecidedAt < 0))
  {
    const std::string why = this->Untested.empty() ? std::string("not measured") : this->Untested;
    if (!adamSide) // the rule's grid, its fit with no step
    {
      return "Route = the pixel grid (" + rule + "; untested against Harris seeds and Adam: " + why + others + ")";
    }
    return "Route = Harris seeds and Adam (" + rule +
      (this->GridByRule ? "; the trial against the pixel grid ended untested: "
                        : "; untested against the pixel grid: ") +
      why + others + ")";
  }
  const std::string grid = vtkfmt::sprintf("the pixel grid of %lld Gaussians %.2f dB (its fits %.1f s)",
    static_cast<long long>(this->GridGaussians), this->GridPSNR, this->GridSeconds);
  if (this->DecidedAt < 0)
  {
    if (this->GridByRule)
    {
      return vtkfmt::sprintf("Route = the pixel grid unless Harris seeds and Adam score higher on %zu held-out frames "
                             "by %.0f %% of the schedule (",
               this->Frames.size(), 100 * this->DecideBy) +
        grid + "; " + rule + others + ")";
    }
    return vtkfmt::sprintf("Route = Harris seeds and Adam, measured against the pixel grid on %zu held-out frames "
                           "when they join the fit (",
             this->Frames.size()) +
      grid + "; " + rule + others + ")";
  }
  return vtkfmt::sprintf("Route = %s (measured on %zu held-out frames at their tracked poses, out of both fits: ",
           this->GridChosen ? "the pixel grid" : "Harris seeds and Adam", this->Frames.size()) +
    grid + vtkfmt::sprintf(", Harris seeds and Adam at step %d %.2f dB; ", this->DecidedAt, this->AdamPSNR) + rule +
    others + ")";
}

} // namespace bigus
