// `bigus benchmark` (bigusBenchmark.h): the report, its rows and tables, the Markdown, JSON and plots it
// writes, the formatting helpers and the probes of this process.
#ifndef bigusBenchmarkReport_h
#define bigusBenchmarkReport_h

#include "bigusImageMetrics.h"
#include "bigusPlot.h"

#include <nlohmann/json.hpp>

#include <limits>
#include <sstream>
#include <string>
#include <vector>

namespace bigus::benchmark
{
const double NaN = std::numeric_limits<double>::quiet_NaN();

/// Seconds on the steady clock (the differences are wall-clock times).
double Now();

/// Peak resident memory of this process since the last ResetPeakMemory (MiB; Linux VmHWM).
double PeakMemoryMiB();

/// Resets VmHWM to the current resident size (Linux >= 4.0), so that each run reports its own peak.
void ResetPeakMemory();

/// @p value with the printf @p format, or "-" when it is not finite.
std::string Format(const char* format, double value);

/// One line of a results table.
struct Row
{
  std::string Method;
  double Seconds = NaN;    ///< training or preparation time (s)
  double MsPerFrame = NaN; ///< time to produce one frame once trained / compounded (ms)
  ImageMetrics Quality;
  long long Gaussians = -1;
  double PeakMiB = NaN;
  std::string Note;
};

nlohmann::json ToJson(const Row& r);

/// The header of a results table, and one row of it (Markdown).
std::string TableHeader();
std::string TableRow(const Row& r);

/// Prints @p r on one line of stdout, after @p where (the sweep or section).
void Print(const std::string& where, const Row& r);

/// PSNR against time (log axis) of every method of one experiment.
PlotSpec TimePlot(const std::string& title, const std::vector<Row>& baselines, const std::vector<Row>& bigus);

/// The report being written: its Markdown and JSON, and where its plots go.
struct Report
{
  std::ostringstream Markdown;
  nlohmann::json Json;
  std::string PlotFolder; ///< absolute or relative to the working directory
  std::string PlotLink;   ///< relative to BENCHMARKS.md
  bool Plot(const PlotSpec& spec, const std::string& name)
  {
    if (!WritePlot(spec, this->PlotFolder + "/" + name))
    {
      return false;
    }
    this->Markdown << "\n![" << spec.Title << "](" << this->PlotLink << "/" << name << ")\n";
    return true;
  }
};

/// Sets @p error to @p what and returns false: how a section fails (RunBenchmark reports it).
bool Failed(const std::string& what, std::string* error);

/// The report's title, the machine and commit, the training @p backend, and the conventions of every table (also in
/// @p report.Json).
void Introduction(const std::string& root, bool quick, const std::string& backend, Report& report);

/// Adds the total run time (@p seconds) and writes the report to @p output: BENCHMARKS.md for every
/// section, BENCHMARKS_<section>.md for one alone (so that it does not replace the full report), and
/// results[_<section>].json next to the plots.
bool WriteReport(
  const std::string& output, const std::string& section, double seconds, Report& report, std::string* error);
}

#endif
