// `bigus benchmark`: speed against error.
//
// What it measures (issue 6), every number printed and written to BENCHMARKS.md as measured:
// - on each bundled real sweep (liver, spine phantom, N-wire) with the hold-out protocol (frames with
//   i mod 4 == 2 held out): held-out PSNR, SSIM, NCC and speckle score of BIGUS after several training
//   times, next to the classical baselines (nearest training frame by pose, blend of the bracketing
//   training frames, PLUS-style compounded volume resliced trilinearly) with their own times, and
//   the same on 20 frames of the liver (about 7 times the steps per training frame in the same time),
//   and where the held-out error comes from (training-frame PSNR, the blend of the field's own renders);
// - the volume protocol on the PLUS reconstruction of the spine phantom: train on parallel slices,
//   test on in-between, oblique and orthogonal slices;
// - quality against the number of Gaussians (capped runs against the adaptive stop);
// - render time per slice against the error from the naive double-precision renderer, per cutoff;
// - ablations: every switch (EA-D, Harris, beam integration, signed reflectivity, D-SSIM, FFL, capacity cap)
//   at equal iterations and at equal time, 3 seeds, on four sweeps;
// - held-out PSNR against the number of Gaussians and against time (a Pareto table): Adam alone, variable
//   projection and a regular grid with the same reflectivity solve;
// Times are wall-clock seconds on this machine; training time excludes the evaluations, which stop the
// clock, and the rows at the time marks are of the field as trained so far (no final prune).
//
// The driver: the sections run in the order of Sections() (Benchmark/bigusBenchmarkSections.h, one file
// each in Benchmark/), sharing the options, the report and their results through a BenchmarkContext.
#include "bigusBenchmark.h"

#include "Benchmark/bigusBenchmarkSections.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <functional>
#include <string>
#include <sys/stat.h>
#include <utility>
#include <vector>

namespace bigus
{
namespace
{
using benchmark::Format;
using benchmark::Now;

int Fail(const std::string& what)
{
  std::fprintf(stderr, "bigus: benchmark: %s\n", what.c_str());
  return 1;
}

bool MakeFolder(const std::string& path)
{
  return ::mkdir(path.c_str(), 0755) == 0 || errno == EEXIST;
}

/// One section of the report: its name (in the time per section and in results.json), the --section value
/// that runs it without the others ("main" for the hold-out sections and those that read their fields), and its
/// function.
struct Section
{
  std::string Name;
  const char* Alone;
  std::function<bool(benchmark::BenchmarkContext&, std::string*)> Run;
  bool InAll = true; ///< run by "all" too
};

/// Every section in the order they run: first the hold-out section of each of @p sweeps, whose results the
/// later sections read.
std::vector<Section> Sections(const std::vector<benchmark::Sweep>& sweeps)
{
  std::vector<Section> sections;
  for (std::size_t si = 0; si < sweeps.size(); ++si)
  {
    auto holdOut = [si](benchmark::BenchmarkContext& context, std::string* error) {
      return benchmark::HoldOutSection(context, si, error);
    };
    sections.push_back({ sweeps[si].Name, "main", holdOut });
  }
  sections.push_back({ "volume protocol", "volume", benchmark::VolumeProtocolSection });
  sections.push_back({ "capacity", "main", benchmark::CapacitySection });
  sections.push_back({ "render cutoffs", "main", benchmark::RenderSection });
  sections.push_back({ "ablations", "ablations", benchmark::AblationSection });
  sections.push_back({ "Pareto", "pareto", benchmark::ParetoSection });
  sections.push_back({ "defaults against hand-tuned", "defaults", benchmark::DefaultsSection });
  sections.push_back({ "block hold-outs", "blocks", benchmark::BlockHoldOutSection });
  sections.push_back({ "several sweeps", "sweeps", benchmark::SeveralSweepsSection });
  sections.push_back({ "backends", "gpu", benchmark::GpuSection, false });
  return sections;
}
}

int RunBenchmark(const BenchmarkOptions& options)
{
  const double started = Now();
  const bool quick = options.Quick;
  const std::string root = options.SourceDirectory;
  benchmark::Report report;
  report.PlotFolder = options.Output + "/benchmarks";
  report.PlotLink = "benchmarks";
  if (!MakeFolder(options.Output) || !MakeFolder(report.PlotFolder))
  {
    return Fail(options.Output + ": cannot create the output folder");
  }
  benchmark::BenchmarkContext context{ report, root, quick, benchmark::BundledSweeps(root, quick), {}, {} };
  const std::vector<Section> sections = Sections(context.Sweeps);
  const std::string& section = options.Section;
  const bool all = section == "all";
  if (!all &&
    std::none_of(sections.begin(), sections.end(), [&](const Section& s) { return s.Alone && section == s.Alone; }))
  {
    return Fail(
      "--section " + section + ": expected all, main, defaults, volume, blocks, ablations, pareto, sweeps or gpu");
  }
  std::string error;
  if (!bigus::CreateTrainingEngine(options.Backend, &error))
  {
    return Fail("--backend " + options.Backend + ": " + error);
  }
  benchmark::SetTrainingBackend(options.Backend);
  benchmark::Introduction(root, quick, options.Backend, report);
  // Each section's wall time, listed at the end of the report.
  std::vector<std::pair<std::string, double>> times;
  auto run = [&](const std::string& name, bool wanted, const std::function<bool()>& measure) {
    if (!wanted)
    {
      return true;
    }
    const double t0 = Now();
    const bool ok = measure();
    times.emplace_back(name, Now() - t0);
    report.Json["section_seconds"][name] = times.back().second;
    return ok;
  };
  bool ok = true;
  // A section alone loads the sweeps it reads; with every section or "main", their hold-out sections load them.
  for (std::size_t si = 0; ok && !all && si < context.Sweeps.size(); ++si)
  {
    if (section == "defaults" || (section == "blocks" && si == 0) || (section == "ablations" && si < 3) ||
      (section == "pareto" && si != 2))
    {
      ok = benchmark::Load(context.Sweeps[si], &error);
    }
  }
  for (const Section& s : sections)
  {
    ok = ok && run(s.Name, (all && s.InAll) || (s.Alone && section == s.Alone), [&] { return s.Run(context, &error); });
  }
  if (!ok)
  {
    return Fail(error);
  }
  report.Markdown << "\nTime per section:";
  for (std::size_t i = 0; i < times.size(); ++i)
  {
    report.Markdown << (i ? "; " : " ") << times[i].first << " " << Format("%.1f", times[i].second / 60) << " min";
  }
  report.Markdown << ".\n";
  const double total = Now() - started;
  if (!benchmark::WriteReport(options.Output, section, total, report, &error))
  {
    return Fail(error);
  }
  std::printf("benchmark done in %.1f minutes\n", total / 60);
  return 0;
}
}
