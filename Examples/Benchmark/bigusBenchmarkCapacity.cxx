// `bigus benchmark`: quality against the number of Gaussians on the liver (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"

namespace bigus::benchmark
{
bool CapacitySection(BenchmarkContext& context, std::string* error)
{
  const Sweep& liver = context.Sweeps[0];
  const Row& full = context.HoldOut.LiverAtCapacityTime;
  const bool quick = context.Quick;
  Report& report = context.Report;
  std::ostringstream& md = report.Markdown;
  const double capacitySeconds = CapacitySeconds(quick);
  const std::vector<long long> caps =
    quick ? std::vector<long long>{ 2000, 4000 } : std::vector<long long>{ 10000, 40000, 160000 };
  const TrainerSettings defaults;
  std::vector<Row> rows;
  for (long long cap : caps)
  {
    TrainerSettings s;
    s.ElevationSigma = liver.ElevationSigma;
    s.Iterations = liver.Iterations;
    s.Seeding.InitialGaussians = cap / 2;
    s.MaximumGaussians = cap;
    s.Densification.GrowthMargin = 0; // grow while it improves at all, up to the cap
    const bool ok = TrainWithMarks(
      liver.Data, s, { capacitySeconds }, liver.HeldOut,
      "cap " + std::to_string(cap) + " (start at " + std::to_string(cap / 2) + ")",
      [&](double, const Row& r, Trainer&) {
        rows.push_back(r);
        Print("capacity", r);
        return true;
      },
      error);
    if (!ok)
    {
      return Failed("capacity: " + *error, error);
    }
  }
  Row adaptive = full;
  adaptive.Method = "adaptive stop (default: automatic seeds, margin " +
    Format("%.1f", 100 * defaults.Densification.GrowthMargin) + " %, cap " + std::to_string(defaults.MaximumGaussians) +
    ")";
  rows.push_back(adaptive);
  md << "\n## Quality against the number of Gaussians (liver, " << Format("%.0f", capacitySeconds)
     << " s of training each)\n\n"
     << "A capped run starts at half its cap and densifies until the cap (growth margin 0); the adaptive run is "
     << "the default trainer, whose growth stops when a validation subset of the training frames stops "
     << "improving by the margin.\n\n"
     << TableHeader();
  PlotSpec spec;
  spec.Title = "liver: held-out PSNR against the number of Gaussians";
  spec.XLabel = "Gaussians at the end (log)";
  spec.YLabel = "PSNR (dB)";
  spec.LogX = true;
  spec.Series.push_back({ "capped", {} });
  for (const Row& r : rows)
  {
    md << TableRow(r);
    report.Json["capacity"].push_back(ToJson(r));
    if (&r != &rows.back())
    {
      spec.Series[0].Points.emplace_back(static_cast<double>(r.Gaussians), r.Quality.PSNR);
    }
  }
  spec.Series.push_back({ "adaptive", { { static_cast<double>(adaptive.Gaussians), adaptive.Quality.PSNR } } });
  if (!report.Plot(spec, "psnr_gaussians_liver.png"))
  {
    return Failed(report.PlotFolder + ": cannot write a plot", error);
  }
  return true;
}

double CapacitySeconds(bool quick)
{
  return quick ? 4 : 60;
}
}
