// `bigus benchmark`: speed against error on the bundled sweeps, written to BENCHMARKS.md with plots.
#ifndef bigusBenchmark_h
#define bigusBenchmark_h

#include <string>

namespace bigus
{
struct BenchmarkOptions
{
  std::string Output = "docs"; ///< folder of BENCHMARKS.md; plots and results.json go to Output/benchmarks
  std::string SourceDirectory; ///< project root holding Examples/Data and Testing/Data
  bool Quick = false;          ///< a few minutes instead of about 3 hours (smoke test)
  /// "all" (written to Output/BENCHMARKS.md), or one section alone (Output/BENCHMARKS_<section>.md):
  /// "main" (the hold-out sections of the bundled sweeps, and the capacity and render-cutoff sections that
  /// read the liver's field), "defaults" (defaults against hand-tuned, without the fixed-schedule column),
  /// "volume" (the volume protocol), "blocks" (block hold-outs on the liver), "ablations" (every switch at
  /// equal iterations and equal time, 3 seeds), "pareto" (held-out PSNR against Gaussians and time: Adam alone,
  /// variable projection, the regular grid with the same solve) or "sweeps" (two sweeps of the volume protocol
  /// into one field). With "all", the defaults section also reads the hold-out sections' runs (its
  /// fixed-schedule column).
  std::string Section = "all";
  /// The training backend of every run (bigus::CreateTrainingEngine): "cpu" (default: the reports' numbers are the
  /// CPU's), "cuda" or "auto". The "gpu" section runs the main job on it and on the CPU. An unavailable backend fails
  /// the command before any section runs.
  std::string Backend = "cpu";
};

/// Runs every measurement and writes the report. Returns the process exit code (0, or 1 with a
/// one-line message on stderr when a data file cannot be read or an output cannot be written).
int RunBenchmark(const BenchmarkOptions& options);
}

#endif
