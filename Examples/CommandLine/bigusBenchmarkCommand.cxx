// `bigus benchmark`: speed against error on the bundled sweeps (bigusBenchmark.h).
#include "bigusBenchmark.h"
#include "bigusCommandLine.h"

#include <CLI/CLI.hpp>
#include <memory>

namespace bigus::cli
{
Command AddBenchmarkCommand(CLI::App& app, const std::string& sourceDirectory)
{
  auto options = std::make_shared<bigus::BenchmarkOptions>();
  bigus::BenchmarkOptions& benchmark = *options;
  benchmark.SourceDirectory = sourceDirectory;
  CLI::App* benchmarkCommand = app.add_subcommand("benchmark",
    "Speed against error on the bundled sweeps: baselines, volume protocol, capacity, render cutoffs, ablations, "
    "defaults against hand-tuned, block hold-outs; "
    "writes OUTPUT/BENCHMARKS.md and OUTPUT/benchmarks/ (about 3 hours on 2 cores)");
  benchmarkCommand->add_option("--output", benchmark.Output, "Folder for BENCHMARKS.md (default: docs)");
  benchmarkCommand
    ->add_option("--data", benchmark.SourceDirectory, "Project folder holding Examples/Data and Testing/Data")
    ->check(CLI::ExistingDirectory);
  benchmarkCommand->add_flag("--quick", benchmark.Quick, "A few minutes: short training, small crops (smoke test)");
  benchmarkCommand
    ->add_option("--section", benchmark.Section,
      "all, or one section alone, written to BENCHMARKS_<section>.md: main (the hold-out sections of the four "
      "sweeps against the baselines, quality against the number of Gaussians, render cutoffs; about 25 minutes), "
      "defaults (defaults against hand-tuned), "
      "volume (the volume protocol), blocks (block hold-outs on the liver) or ablations (every switch at equal "
      "iterations and equal time, 3 seeds; about 2 hours) or pareto (held-out PSNR against Gaussians and time: "
      "Adam alone, variable projection and the regular grid, up to 4 million Gaussians; about 45 minutes) or sweeps "
      "(two sweeps of the volume "
      "protocol into one field against compounding both; about 15 minutes) or gpu (the main job at 10, 30, 60 and 100 "
      "s "
      "on --backend and on the CPU; about 4 minutes per backend; not part of all)")
    ->capture_default_str()
    ->check(CLI::IsMember({ "all", "main", "defaults", "volume", "blocks", "ablations", "pareto", "sweeps", "gpu" }));
  benchmarkCommand
    ->add_option("--backend", benchmark.Backend,
      "Training backend of every run: cpu (the reports' numbers), cuda or auto (as registered; `bigus info "
      "--backends`)")
    ->capture_default_str();
  return { benchmarkCommand, [options] {
            bigus::BenchmarkOptions& benchmark = *options;
            return bigus::RunBenchmark(benchmark);
          } };
}

} // namespace bigus::cli
