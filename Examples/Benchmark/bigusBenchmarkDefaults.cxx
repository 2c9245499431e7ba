// `bigus benchmark`: the trainer's defaults against hand-tuned settings (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"

#include <algorithm>
#include <cmath>

namespace bigus::benchmark
{
bool DefaultsSection(BenchmarkContext& context, std::string* error)
{
  const std::vector<Sweep>& sweeps = context.Sweeps;
  const HoldOutResults& results = context.HoldOut;
  const std::string& root = context.Root;
  const bool quick = context.Quick;
  VolumeBudgetResults& volume = context.Volume;
  Report& report = context.Report;
  std::ostringstream& md = report.Markdown;
  md << "\n## Defaults against hand-tuned\n\n"
     << "Defaults: `TrainerSettings` with only a time budget, which is then the whole schedule (elevation sigma "
     << "chosen from the sweep, seeds, growth and early stopping as the trainer decides). Hand-tuned: the same "
     << "budget with the elevation sigma chosen by hand for the sweep, and the sweep's own fixed-schedule run "
     << "above, read at the same time (mid-schedule, not pruned). Held-out PSNR; difference = defaults minus the "
     << "better hand-tuned run.\n\n"
     << "| sweep | budget (s) | defaults PSNR (dB) | defaults | hand-tuned PSNR (dB) | hand-tuned | fixed schedule "
     << "PSNR (dB) | difference (dB) |\n|---|---|---|---|---|---|---|---|\n";
  auto addRow = [&](const std::string& name, double budget, const Row& d, const Row& t, double fixed) {
    const double best = std::isfinite(fixed) ? std::max(t.Quality.PSNR, fixed) : t.Quality.PSNR;
    md << "| " << name << " | " << Format("%.0f", budget) << " | " << Format("%.2f", d.Quality.PSNR) << " | " << d.Note
       << ", " << d.Gaussians << " Gaussians | " << Format("%.2f", t.Quality.PSNR) << " | " << t.Note << ", "
       << t.Gaussians << " Gaussians | " << Format("%.2f", fixed) << " | " << Format("%+.2f", d.Quality.PSNR - best)
       << " |\n";
    nlohmann::json j;
    j["budget_seconds"] = budget;
    j["defaults"] = ToJson(d);
    j["hand_tuned"] = ToJson(t);
    j["fixed_schedule_psnr"] = std::isfinite(fixed) ? nlohmann::json(fixed) : nlohmann::json(nullptr);
    j["difference_db"] = d.Quality.PSNR - best;
    report.Json["defaults_against_hand_tuned"][name] = j;
  };
  for (std::size_t si = 0; si < sweeps.size(); ++si)
  {
    const Sweep& sweep = sweeps[si];
    TrainerSettings defaults;
    defaults.Iterations = 0;
    defaults.TimeBudget = sweep.DefaultsBudget;
    TrainerSettings tuned = defaults;
    tuned.ElevationSigma = sweep.ElevationSigma;
    Row d, t;
    if (!TrainToBudget(sweep, defaults, "defaults", d, error) ||
      !TrainToBudget(sweep, tuned, "hand-tuned sigma", t, error))
    {
      return Failed(sweep.Name + " (defaults against hand-tuned): " + *error, error);
    }
    Print(sweep.Name, d);
    Print(sweep.Name, t);
    double fixed = NaN;
    if (si < results.Bigus.size())
    {
      for (const Row& r : results.Bigus[si])
      {
        if (r.Seconds <= sweep.DefaultsBudget * 1.01)
        {
          fixed = r.Quality.PSNR; // the last mark within the budget
        }
      }
    }
    addRow(sweep.Name, sweep.DefaultsBudget, d, t, fixed);
  }
  if (!(volume.Budget > 0))
  {
    VolumeProtocol vp;
    if (!MakeVolumeProtocol(root, quick, vp, error) || !VolumeBudgetRuns(vp, quick, volume, error))
    {
      return false;
    }
  }
  // The volume protocol's fixed schedule is read at marks below its budget: no column.
  addRow("volume protocol, in-between slices", volume.Budget, volume.Defaults[0], volume.Tuned[0], NaN);
  addRow("volume protocol, oblique slices", volume.Budget, volume.Defaults[1], volume.Tuned[1], NaN);
  md << "\nThe volume protocol's baseline, the compounded volume resliced: "
     << Format("%.2f", volume.Compounded[0].Quality.PSNR) << " dB on the in-between slices, "
     << Format("%.2f", volume.Compounded[1].Quality.PSNR) << " dB on the oblique.\n";
  report.Json["defaults_against_hand_tuned_volume_compounded_psnr"] = { volume.Compounded[0].Quality.PSNR,
    volume.Compounded[1].Quality.PSNR };
  return true;
}
}
