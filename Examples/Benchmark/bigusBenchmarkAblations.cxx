// `bigus benchmark`: every switch of the method against the full method at equal iterations and at equal
// time (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <numeric>
#include <sstream>

namespace bigus::benchmark
{
namespace
{
/// Settings of one ablation row: a name and what it changes.
struct Ablation
{
  std::string Name;
  /// Applies the switch; @p seeds is the mean seed count of the full method on the same sweep.
  std::function<void(TrainerSettings&, std::int64_t seeds)> Change;
  std::string PaperDirection; ///< what the paper's Tables 3 and 4 say removing / adding it does
  int PaperSign = -1;         ///< the sign of (variant - full method) in held-out PSNR that the paper reports
};

std::vector<Ablation> Ablations()
{
  return {
    { "no EA-D (no densification)", [](TrainerSettings& s, std::int64_t) { s.Densification.Enabled = false; },
      "lower (EA-D helps)" },
    { "random initialisation (not Harris)",
      [](TrainerSettings& s, std::int64_t) { s.Seeding.HarrisInitialisation = false; },
      "lower (Harris initialisation helps)" },
    { "thin plane (no beam integration, UltraGauss)",
      [](TrainerSettings& s, std::int64_t) { s.BeamIntegration = false; }, "lower (beam integration helps)" },
    { "non-negative reflectivity", [](TrainerSettings& s, std::int64_t) { s.NonNegativeReflectivity = true; },
      "lower (signed reflectivity helps)" },
    { "L1 only (no D-SSIM)", [](TrainerSettings& s, std::int64_t) { s.Loss.DSSIM = 0; },
      "lower (D-SSIM helps structure)" },
    { "L1 + D-SSIM + FFL (0.1)", [](TrainerSettings& s, std::int64_t) { s.Loss.FFL = 0.1; },
      "higher (FFL helps speckle)", +1 },
    { "capacity cap at the seed count",
      [](TrainerSettings& s, std::int64_t seeds) {
        s.Seeding.InitialGaussians = seeds;
        s.MaximumGaussians = seeds;
      },
      "lower (adaptive capacity helps)" },
    { "dense Adam (every Gaussian every step)", [](TrainerSettings& s, std::int64_t) { s.SparseAdam = false; },
      "not in the paper; lower at equal time (sparse Adam: Mallick et al. 2024, Taming 3DGS)" },
  };
}

/// Mean and spread (max - min) over seeds of one quantity.
struct Spread
{
  double Mean = NaN, Range = NaN;
  static Spread Of(const std::vector<double>& values)
  {
    Spread s;
    if (values.empty())
    {
      return s;
    }
    s.Mean = std::accumulate(values.begin(), values.end(), 0.0) / values.size();
    const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
    s.Range = *hi - *lo;
    return s;
  }
  std::string Text(const char* format) const
  {
    return Format(format, this->Mean) + " (" + Format(format, this->Range) + ")";
  }
};

/// Mean and spread of every column of a variant's runs over seeds.
struct AblationCell
{
  std::vector<AblationRun> Runs;
  Spread Get(const std::function<double(const AblationRun&)>& field) const
  {
    std::vector<double> v;
    for (const AblationRun& r : this->Runs)
    {
      v.push_back(field(r));
    }
    return Spread::Of(v);
  }
  Spread PSNR() const
  {
    return this->Get([](const AblationRun& r) { return r.HeldOut.PSNR; });
  }
  Spread Fit() const
  {
    return this->Get([](const AblationRun& r) { return r.Fit; });
  }
  Spread Steps() const
  {
    return this->Get([](const AblationRun& r) { return r.Steps; });
  }
  Spread Gaussians() const
  {
    return this->Get([](const AblationRun& r) { return r.Gaussians; });
  }
};

/**
 * The sentence under an ablation table for one component: whether the held-out PSNR moves the way the
 * paper says (@p paperSign: the sign of variant - full), against the noise (the larger of the two
 * spreads over seeds), and for a disagreement what was measured to differ: steps done, Gaussians at the
 * end, and the fit (training frames) against the held-out frames.
 */
std::string AblationVerdict(
  const Ablation& a, const AblationCell& full, const AblationCell& variant, std::string& verdict)
{
  const Spread f = full.PSNR(), v = variant.PSNR();
  const double delta = v.Mean - f.Mean, noise = std::max(f.Range, v.Range);
  std::ostringstream text;
  text << "**" << a.Name << "**: ";
  if (full.Runs.size() < 2 || variant.Runs.size() < 2)
  {
    verdict = "one seed";
    text << "one seed, so no spread to judge " << Format("%+.2f", delta) << " dB by.";
    return text.str();
  }
  if (!(std::abs(delta) > noise))
  {
    verdict = "within noise";
    text << "within noise (" << Format("%+.2f", delta) << " dB, spread " << Format("%.2f", noise) << ").";
    return text.str();
  }
  const bool agrees = (delta > 0) == (a.PaperSign > 0);
  verdict = agrees ? "agrees" : "disagrees";
  text << (agrees ? "agrees with" : "disagrees with") << " the paper (" << Format("%+.2f", delta) << " dB, spread "
       << Format("%.2f", noise) << ")";
  if (agrees)
  {
    text << ".";
    return text.str();
  }
  std::vector<std::string> reasons;
  const double steps = variant.Steps().Mean / full.Steps().Mean;
  if (std::abs(steps - 1) > 0.05)
  {
    reasons.push_back(Format("it did %.2f", steps) + " times the full method's steps (" +
      Format("%.0f", variant.Steps().Mean) + " against " + Format("%.0f", full.Steps().Mean) + ")");
  }
  const double gaussians = variant.Gaussians().Mean / full.Gaussians().Mean;
  if (std::abs(gaussians - 1) > 0.1)
  {
    reasons.push_back(Format("it ended with %.2f", gaussians) + " times the Gaussians (" +
      Format("%.0f", variant.Gaussians().Mean) + " against " + Format("%.0f", full.Gaussians().Mean) + ")");
  }
  const Spread vf = variant.Fit(), ff = full.Fit();
  const double fitDelta = vf.Mean - ff.Mean;
  const double gapFull = ff.Mean - f.Mean, gapVariant = vf.Mean - v.Mean;
  if (std::abs(fitDelta) > std::max(vf.Range, ff.Range))
  {
    reasons.push_back("its fit of the training frames is " + Format("%.2f", std::abs(fitDelta)) + " dB " +
      (fitDelta > 0 ? "higher" : "lower"));
  }
  else
  {
    reasons.push_back("its fit of the training frames is the same within noise (" + Format("%+.2f", fitDelta) + " dB)");
  }
  reasons.push_back("fit minus held-out: " + Format("%.2f", gapVariant) + " dB against " + Format("%.2f", gapFull) +
    " dB for the full method" + (gapFull > gapVariant + 0.5 ? " (the full method overfits more)" : ""));
  text << ": ";
  for (std::size_t i = 0; i < reasons.size(); ++i)
  {
    text << (i ? "; " : "") << reasons[i];
  }
  text << ".";
  return text.str();
}
}

bool AblationSection(BenchmarkContext& context, std::string* error)
{
  const std::vector<Sweep>& sweeps = context.Sweeps;
  const bool quick = context.Quick;
  Report& report = context.Report;
  VolumeProtocol vp;
  if (!MakeVolumeProtocol(context.Root, quick, vp, error))
  {
    return false;
  }
  std::vector<AblationExperiment> experiments;
  const double seconds[] = { 40, 20, 15 }; // liver, spine phantom, N-wire: about 100 minutes on 2 cores in all
  for (std::size_t si = 0; si < 3; ++si)
  {
    experiments.push_back(HoldOutExperiment(sweeps[si], quick ? 3 : seconds[si]));
  }
  experiments.push_back(VolumeExperiment(vp, quick ? 3 : 15));
  const std::vector<unsigned> seeds = quick ? std::vector<unsigned>{ 1 } : std::vector<unsigned>{ 1, 2, 3 };
  std::vector<Ablation> ablations = Ablations();
  if (quick)
  {
    ablations.resize(1);
  }

  std::ostringstream& md = report.Markdown;
  md << "\n## Ablations at equal iterations and at equal time\n\n"
     << "The paper's Tables 3 and 4 compare its components at equal iterations. Each switch below is trained "
     << "from the trainer's defaults (the full method) with that one change, with " << seeds.size() << " seed"
     << (seeds.size() > 1 ? "s" : "") << " per cell: **equal time**, the time budget as the "
     << "schedule, and **equal iterations**, the mean number of steps the full method did in that time as "
     << "the schedule. Each cell gives the mean over seeds and, in brackets, the spread (largest minus "
     << "smallest). A difference is called real only when it exceeds the larger of the two spreads. Held-out: "
     << "the sweep's held-out frames (i mod 4 == 2; the volume protocol's in-between slices); fit: every 4th "
     << "training frame. Time includes initialisation and the final prune. The capacity cap fixes the number "
     << "of Gaussians at the full method's seed count (densification only replaces what pruning removes).\n";
  nlohmann::json& json = report.Json["ablations"];
  for (const AblationExperiment& e : experiments)
  {
    const double started = Now();
    // The switches are those of training from Harris seeds: the pixel-grid fit, which the defaults take on
    // the volume protocol, takes no step (the volume section reports it).
    TrainerSettings timed;
    timed.Seeding.PixelGridFit = false;
    timed.Iterations = 0;
    timed.TimeBudget = e.Seconds;
    // The full method at equal time first: its steps set the equal-iteration schedule, its seeds the cap.
    auto runCell = [&](const TrainerSettings& base, const Ablation* a, std::int64_t seedCount, AblationCell& cell) {
      for (unsigned seed : seeds)
      {
        TrainerSettings s = base;
        s.Seed = seed;
        if (a)
        {
          a->Change(s, seedCount);
        }
        AblationRun run;
        if (!RunAblation(e, s, run, error))
        {
          return Failed(
            "ablation " + e.Name + ", " + (a ? a->Name : std::string("full method")) + ": " + *error, error);
        }
        std::printf(
          "  ablation %-16s %-44s seed %u  %6.1f s  %6.0f steps  held-out %6.2f dB  fit %6.2f dB  %8.0f Gaussians\n",
          e.Name.substr(0, 16).c_str(), a ? a->Name.c_str() : "full method", seed, run.Seconds, run.Steps,
          run.HeldOut.PSNR, run.Fit, run.Gaussians);
        std::fflush(stdout);
        cell.Runs.push_back(run);
      }
      return true;
    };
    AblationCell fullTimed, fullIterations;
    if (!runCell(timed, nullptr, 0, fullTimed))
    {
      return false;
    }
    TrainerSettings counted;
    counted.Seeding.PixelGridFit = false;
    counted.Iterations = std::max(1, static_cast<int>(std::lround(fullTimed.Steps().Mean)));
    if (!runCell(counted, nullptr, 0, fullIterations))
    {
      return false;
    }
    const std::int64_t seedCount = std::llround(fullTimed.Get([](const AblationRun& r) { return r.Seeds; }).Mean);
    md << "\n### " << e.Name << "\n";
    for (int table = 0; table < 2; ++table)
    {
      const bool equalTime = table == 0;
      const TrainerSettings& base = equalTime ? timed : counted;
      const AblationCell& full = equalTime ? fullTimed : fullIterations;
      std::vector<AblationCell> cells(ablations.size());
      for (std::size_t ai = 0; ai < ablations.size(); ++ai)
      {
        if (!runCell(base, &ablations[ai], seedCount, cells[ai]))
        {
          return false;
        }
      }
      md << "\n#### "
         << (equalTime ? "Equal time: " + Format("%.0f", e.Seconds) + " s"
                       : "Equal iterations: " + std::to_string(counted.Iterations) + " steps")
         << "\n\n| variant | held-out PSNR (dB) | SSIM | NCC | speckle | fit PSNR (dB) | Gaussians | steps | "
            "time (s) | paper | ours |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
      std::ostringstream sentences;
      nlohmann::json jt;
      jt["schedule"] = equalTime ? Format("%.0f s", e.Seconds) : std::to_string(counted.Iterations) + " steps";
      for (std::size_t ai = 0; ai <= ablations.size(); ++ai)
      {
        const AblationCell& cell = ai == 0 ? full : cells[ai - 1];
        std::string verdict;
        if (ai > 0)
        {
          sentences << "- " << AblationVerdict(ablations[ai - 1], full, cell, verdict) << "\n";
        }
        md << "| " << (ai == 0 ? std::string("full method (defaults)") : ablations[ai - 1].Name) << " | "
           << cell.PSNR().Text("%.2f") << " | "
           << cell.Get([](const AblationRun& r) { return r.HeldOut.SSIM; }).Text("%.4f") << " | "
           << cell.Get([](const AblationRun& r) { return r.HeldOut.NCC; }).Text("%.4f") << " | "
           << cell.Get([](const AblationRun& r) { return r.HeldOut.Speckle; }).Text("%.4f") << " | "
           << cell.Fit().Text("%.2f") << " | " << cell.Gaussians().Text("%.0f") << " | " << cell.Steps().Text("%.0f")
           << " | " << cell.Get([](const AblationRun& r) { return r.Seconds; }).Text("%.1f") << " | "
           << (ai == 0 ? "" : ablations[ai - 1].PaperDirection) << " | " << verdict << " |\n";
        nlohmann::json jc;
        jc["variant"] = ai == 0 ? std::string("full method") : ablations[ai - 1].Name;
        jc["verdict"] = verdict;
        for (const AblationRun& r : cell.Runs)
        {
          jc["runs"].push_back({ { "psnr", r.HeldOut.PSNR }, { "ssim", r.HeldOut.SSIM }, { "ncc", r.HeldOut.NCC },
            { "speckle", r.HeldOut.Speckle }, { "fit_psnr", r.Fit }, { "gaussians", r.Gaussians }, { "steps", r.Steps },
            { "seconds", r.Seconds } });
        }
        jt["cells"].push_back(jc);
      }
      md << "\n" << sentences.str();
      json[e.Name][equalTime ? "equal_time" : "equal_iterations"] = jt;
    }
    const double took = Now() - started;
    md << "\nThis sweep's ablations took " << Format("%.1f", took / 60) << " minutes.\n";
    json[e.Name]["seconds"] = took;
  }
  return true;
}
}
