// `bigus benchmark --section gpu` (bigusBenchmarkSections.h): the main job's held-out PSNR against time on the
// training backend of --backend and on the CPU engine of the same machine, in one run (issue 58 item 4).
#include "bigusBenchmarkSections.h"

#include "bigusBackend.h"
#include "bigusBackendCheck.h"

#include <string>
#include <vector>

namespace bigus::benchmark
{

bool GpuSection(BenchmarkContext& context, std::string* error)
{
  Sweep& liver = context.Sweeps[0];
  if (liver.Data.TrainFrames.empty() && !Load(liver, error))
  {
    return false;
  }
  // The main job: the trainer's defaults with a time budget, scored on the held-out frames (i mod 4 == 2) at their
  // tracked poses at each mark.
  const std::vector<double> marks =
    context.Quick ? std::vector<double>{ 1, 2 } : std::vector<double>{ 10, 30, 60, 100 };
  TrainerSettings s;
  s.Iterations = 0;
  s.TimeBudget = marks.back();
  std::vector<std::string> backends{ TrainingBackend() };
  if (backends[0] != "cpu")
  {
    backends.push_back("cpu");
  }
  std::ostringstream& md = context.Report.Markdown;
  md << "\n## The main job on " << (backends.size() > 1 ? backends[0] + " and on the CPU" : "the CPU") << "\n\n"
     << "The liver's hold-out protocol (frames i mod 4 == 2 held out, scored at their tracked poses), the trainer's "
     << "defaults with a time budget of " << Format("%.0f", marks.back())
     << " s, scored at each mark (`bigus benchmark "
     << "--section gpu --backend " << backends[0] << "`). Training backends (`bigus info --backends`):\n\n";
  for (const std::string& name : backends)
  {
    const BackendCheck check = CheckBackend(name);
    const std::string runsOn = BackendDescription(name);
    md << "- `" << name << "` (" << (runsOn.empty() ? "the machine's processor, above" : runsOn)
       << "): " << (check.Passed ? "passed its self-check" : "FAILED its self-check") << ": " << check.Detail << "\n";
  }
  md << "\n" << TableHeader();
  std::vector<std::vector<Row>> rows(backends.size()); // each backend's, for the plot
  for (std::size_t b = 0; b < backends.size(); ++b)
  {
    const bool ok = TrainWithMarks(
      liver.Data, s, marks, liver.HeldOut, "BIGUS on " + backends[b],
      [&](double, const Row& r, Trainer&) {
        Print("gpu", r);
        rows[b].push_back(r);
        md << TableRow(r);
        context.Report.Json["gpu"][backends[b]].push_back(ToJson(r));
        return true;
      },
      error, backends[b]);
    if (!ok)
    {
      return false;
    }
  }
  // One curve per backend (TimePlot draws one BIGUS curve: the others' are added to it).
  PlotSpec plot = TimePlot("Liver: held-out PSNR against training time per backend", {}, rows[0]);
  plot.Series[0].Name = "BIGUS on " + backends[0];
  for (std::size_t b = 1; b < backends.size(); ++b)
  {
    plot.Series.push_back(TimePlot(plot.Title, {}, rows[b]).Series[0]);
    plot.Series.back().Name = "BIGUS on " + backends[b];
  }
  return context.Report.Plot(plot, "psnr_time_backends.png") ||
    Failed("cannot write the plot psnr_time_backends.png", error);
}

} // namespace bigus::benchmark
