// `bigus benchmark`: held-out PSNR against Gaussians and time, the adaptive field against the regular grid
// (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"

#include "bigusSeeding.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

namespace bigus::benchmark
{
namespace
{
/// One run of the Pareto section: a trainer to a time budget, or the regular grid (no training).
struct ParetoRun
{
  std::string Method;
  double Budget = NaN;        ///< s: the trainer's time budget (NaN for the grid)
  std::int64_t Requested = 0; ///< the grid: the count asked for (the count an adaptive run ended with)
  AblationRun Run;
  bool CountFront = false; ///< no other run has at most its Gaussians and a higher held-out PSNR
  bool TimeFront = false;  ///< no other run took at most its time and has a higher held-out PSNR
  bool HighEnd = false;    ///< a grid of the high end (0.5 to 4 million Gaussians), not matched to an adaptive run
};

/// Marks the runs on the front of held-out PSNR against @p cost (lower cost, higher PSNR).
void MarkFront(std::vector<ParetoRun>& runs, double AblationRun::*cost, bool ParetoRun::*front)
{
  for (ParetoRun& a : runs)
  {
    a.*front = std::none_of(runs.begin(), runs.end(), [&](const ParetoRun& b) {
      return &a != &b && b.Run.*cost <= a.Run.*cost && b.Run.HeldOut.PSNR > a.Run.HeldOut.PSNR;
    });
  }
}
}

bool ParetoSection(BenchmarkContext& context, std::string* error)
{
  const std::vector<Sweep>& sweeps = context.Sweeps;
  const bool quick = context.Quick;
  VolumeProtocol vp;
  if (!MakeVolumeProtocol(context.Root, quick, vp, error))
  {
    return false;
  }
  Report& report = context.Report;
  // A solve passes over every training frame twice per iteration: --quick takes the 20 liver frames.
  const std::vector<AblationExperiment> experiments = { HoldOutExperiment(sweeps[quick ? 3 : 0], 0),
    HoldOutExperiment(sweeps[1], 0), VolumeExperiment(vp, 0) };
  const std::vector<double> budgets = quick ? std::vector<double>{ 3 } : std::vector<double>{ 30, 120 };
  const std::pair<std::string, bool> adaptive[] = { { "Adam alone (defaults)", false },
    { "variable projection", true } };
  const std::string grid = "regular grid + solve";

  std::ostringstream& md = report.Markdown;
  md << "\n## Held-out PSNR against Gaussians and time: the adaptive field and the regular grid\n\n"
     << "Trainer defaults (Adam alone) and variable projection (`--reflectivity-solve`: the reflectivities solved "
     << "by least squares after seeding and after every densification, Adam between) to time budgets of ";
  for (std::size_t b = 0; b < budgets.size(); ++b)
  {
    md << (b ? " and " : "") << Format("%.0f", budgets[b]);
  }
  md << " s, and a regular grid (`--dense-start`: Gaussians on the training frames' pixel grid, reflectivities "
     << "by the same solve, no training) at the count each adaptive run ended with (one grid for counts within "
     << "10 %), then grids of 0.5, 1, 2 and 4 million Gaussians where the training frames have that many fan pixels "
     << "(else one grid of every fan pixel) and the memory holds the grid with its solve (the assembled operator "
     << "where it fits the solve's memory share). Time includes seeding, the solves, the final prune and gap filling. "
     << "Held-out as in the ablations; "
     << "fit: every 4th training frame. *count front* / *time front*: no other run of the sweep has at most "
     << "its Gaussians / its time and a higher held-out PSNR.\n";
  nlohmann::json& json = report.Json["pareto"];
  for (const AblationExperiment& e : experiments)
  {
    std::vector<ParetoRun> runs;
    auto measure = [&](ParetoRun& p, const TrainerSettings& s, bool train) {
      if (!RunAblation(e, s, p.Run, error, train))
      {
        return Failed("Pareto " + e.Name + ", " + p.Method + ": " + *error, error);
      }
      std::printf("  pareto   %-16s %-24s %6.1f s  %6.0f steps  held-out %6.2f dB  fit %6.2f dB  %8.0f Gaussians\n",
        e.Name.substr(0, 16).c_str(), p.Method.c_str(), p.Run.Seconds, p.Run.Steps, p.Run.HeldOut.PSNR, p.Run.Fit,
        p.Run.Gaussians);
      std::fflush(stdout);
      runs.push_back(p);
      return true;
    };
    for (const auto& [name, solve] : adaptive)
    {
      for (double budget : budgets)
      {
        TrainerSettings s;
        s.Seeding.PixelGridFit = false; // the trainers themselves: the grid has its own rows
        s.Iterations = 0;
        s.TimeBudget = budget;
        s.ReflectivitySolve = solve;
        ParetoRun p;
        p.Method = name;
        p.Budget = budget;
        if (!measure(p, s, true))
        {
          return false;
        }
      }
    }
    const std::size_t adaptiveRuns = runs.size();
    for (std::size_t a = 0; a < adaptiveRuns; ++a)
    {
      const auto count = static_cast<std::int64_t>(runs[a].Run.Gaussians);
      if (std::any_of(runs.begin() + adaptiveRuns, runs.end(),
            [&](const ParetoRun& g) { return std::abs(double(g.Requested - count)) <= 0.1 * count; }))
      {
        continue;
      }
      TrainerSettings s;
      s.Seeding.DenseInitialisation = true;
      s.ReflectivitySolve = true;
      s.Seeding.InitialGaussians = count;
      ParetoRun p;
      p.Method = grid;
      p.Requested = count;
      if (!measure(p, s, false))
      {
        return false;
      }
    }
    // The high end: grids of 0.5, 1, 2 and 4 million Gaussians where the training frames have that many fan pixels
    // (else one grid of every fan pixel) and this machine's memory holds the grid with its solve.
    const std::size_t matchedGrids = runs.size();
    std::vector<std::string> notRun;
    {
      double gamma = 0;
      std::int64_t fanPixels = 0;
      std::string line;
      if (!GammaOfTrainingFrames(*e.Train, gamma, fanPixels, line, error))
      {
        return Failed("Pareto " + e.Name + ": " + *error, error);
      }
      // (--quick: one grid of 50,000, to run the same code in seconds.)
      const std::vector<std::int64_t> counts =
        quick ? std::vector<std::int64_t>{ 50000 } : std::vector<std::int64_t>{ 500000, 1000000, 2000000, 4000000 };
      for (std::int64_t count : counts)
      {
        const std::int64_t n = std::min(count, fanPixels);
        if (!TrainingFitsInMemory(*e.Train, n, true, false))
        {
          notRun.push_back(
            "a grid of " + std::to_string(n) + " Gaussians (with its solve, more than this machine's memory holds)");
          break;
        }
        TrainerSettings s;
        s.Seeding.DenseInitialisation = true;
        s.ReflectivitySolve = true;
        s.Seeding.InitialGaussians = n;
        s.MaximumGaussians = std::max(s.MaximumGaussians, n);
        ParetoRun p;
        p.Method = n == fanPixels ? "grid of every fan pixel + solve" : grid;
        p.Requested = n;
        p.HighEnd = true;
        if (!measure(p, s, false))
        {
          return false;
        }
        if (n == fanPixels)
        {
          break;
        }
      }
    }
    MarkFront(runs, &AblationRun::Gaussians, &ParetoRun::CountFront);
    MarkFront(runs, &AblationRun::Seconds, &ParetoRun::TimeFront);

    md << "\n### " << e.Name << "\n\n| method | budget (s) | time (s) | Gaussians | held-out PSNR (dB) | SSIM | "
       << "fit PSNR (dB) | steps | count front | time front |\n|---|---|---|---|---|---|---|---|---|---|\n";
    nlohmann::json je;
    PlotSpec byCount, byTime;
    byCount.Title = e.Name + ": held-out PSNR against Gaussians";
    byCount.XLabel = "Gaussians";
    byCount.LogX = true;
    byTime.Title = e.Name + ": held-out PSNR against time";
    byTime.XLabel = "time (s)";
    byCount.YLabel = byTime.YLabel = "held-out PSNR (dB)";
    for (const ParetoRun& p : runs)
    {
      const AblationRun& r = p.Run;
      md << "| " << p.Method << " | " << Format("%.0f", p.Budget) << " | " << Format("%.1f", r.Seconds) << " | "
         << Format("%.0f", r.Gaussians) << " | " << Format("%.2f", r.HeldOut.PSNR) << " | "
         << Format("%.4f", r.HeldOut.SSIM) << " | " << Format("%.2f", r.Fit) << " | " << Format("%.0f", r.Steps)
         << " | " << (p.CountFront ? "yes" : "") << " | " << (p.TimeFront ? "yes" : "") << " |\n";
      je["runs"].push_back({ { "method", p.Method },
        { "budget", std::isfinite(p.Budget) ? nlohmann::json(p.Budget) : nlohmann::json(nullptr) },
        { "requested", p.Requested }, { "seconds", r.Seconds }, { "gaussians", r.Gaussians }, { "seeds", r.Seeds },
        { "steps", r.Steps }, { "psnr", r.HeldOut.PSNR }, { "ssim", r.HeldOut.SSIM }, { "fit_psnr", r.Fit },
        { "count_front", p.CountFront }, { "time_front", p.TimeFront }, { "high_end", p.HighEnd } });
      for (PlotSpec* spec : { &byCount, &byTime })
      {
        auto series = std::find_if(
          spec->Series.begin(), spec->Series.end(), [&](const PlotSeries& s) { return s.Name == p.Method; });
        if (series == spec->Series.end())
        {
          series = spec->Series.insert(spec->Series.end(), PlotSeries{ p.Method, {} });
        }
        series->Points.emplace_back(spec == &byCount ? r.Gaussians : r.Seconds, r.HeldOut.PSNR);
      }
    }
    for (PlotSpec* spec : { &byCount, &byTime })
    {
      for (PlotSeries& s : spec->Series)
      {
        std::sort(s.Points.begin(), s.Points.end());
      }
    }
    // Each adaptive run against the grid made at (or within 10 % of) its count.
    md << "\n";
    for (std::size_t a = 0; a < adaptiveRuns; ++a)
    {
      const ParetoRun& p = runs[a];
      const auto g = std::min_element(
        runs.begin() + adaptiveRuns, runs.begin() + matchedGrids, [&](const ParetoRun& x, const ParetoRun& y) {
          return std::abs(x.Requested - p.Run.Gaussians) < std::abs(y.Requested - p.Run.Gaussians);
        });
      const double delta = p.Run.HeldOut.PSNR - g->Run.HeldOut.PSNR;
      const bool above = delta > 0;
      md << "- " << p.Method << ", " << Format("%.0f", p.Budget) << " s (" << Format("%.0f", p.Run.Gaussians)
         << " Gaussians): " << (above ? "above" : "below") << " the grid of " << Format("%.0f", g->Run.Gaussians)
         << " by " << Format("%.2f", std::abs(delta)) << " dB";
      if (!above)
      {
        md << "; fit of the training frames " << Format("%.2f", p.Run.Fit) << " dB against the grid's "
           << Format("%.2f", g->Run.Fit) << " ("
           << (p.Run.Fit < g->Run.Fit ? "the adaptive field fits less: "
                                        "its geometry is not yet where the budget's steps would take it"
                                      : "the adaptive field fits more "
                                        "and generalises less between frames")
           << ")";
      }
      md << ".\n";
      je["verdicts"].push_back({ { "method", p.Method }, { "budget", p.Budget }, { "grid_gaussians", g->Run.Gaussians },
        { "delta_psnr", delta }, { "above_grid", above } });
    }
    // Where each route wins: the best adaptive run against the best grid, at any count and time.
    auto best = [&](std::size_t from, std::size_t to) {
      return std::max_element(runs.begin() + from, runs.begin() + to,
        [](const ParetoRun& x, const ParetoRun& y) { return x.Run.HeldOut.PSNR < y.Run.HeldOut.PSNR; });
    };
    const auto a = best(0, adaptiveRuns), g = best(adaptiveRuns, runs.size());
    const bool gridWins = g->Run.HeldOut.PSNR > a->Run.HeldOut.PSNR;
    md << "- Where each route wins: the best grid (" << Format("%.0f", g->Run.Gaussians) << " Gaussians, "
       << Format("%.1f", g->Run.Seconds) << " s) " << Format("%.2f", g->Run.HeldOut.PSNR)
       << " dB, the best adaptive run (" << a->Method << ", " << Format("%.0f", a->Run.Gaussians) << " Gaussians, "
       << Format("%.1f", a->Run.Seconds) << " s) " << Format("%.2f", a->Run.HeldOut.PSNR)
       << " dB: " << (gridWins ? "the grid" : "the adaptive field") << " wins on this sweep by "
       << Format("%.2f", std::abs(g->Run.HeldOut.PSNR - a->Run.HeldOut.PSNR)) << " dB.\n";
    for (const std::string& what : notRun)
    {
      md << "- Not run: " << what << ".\n";
    }
    je["best"] = { { "grid_psnr", g->Run.HeldOut.PSNR }, { "grid_gaussians", g->Run.Gaussians },
      { "adaptive_psnr", a->Run.HeldOut.PSNR }, { "adaptive_method", a->Method }, { "grid_wins", gridWins } };
    const std::string tag = std::to_string(&e - experiments.data());
    if (!report.Plot(byCount, "pareto_gaussians_" + tag + ".png") ||
      !report.Plot(byTime, "pareto_time_" + tag + ".png"))
    {
      return Failed("cannot write the Pareto plots to " + report.PlotFolder, error);
    }
    json[e.Name] = je;
  }
  return true;
}
}
