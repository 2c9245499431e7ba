// `bigus benchmark`: the report and the probes of the machine and of this process (bigusBenchmarkReport.h).
#include "bigusBenchmarkReport.h"
#include "bigusReplaceFile.h"

#include "vtkSMPTools.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <thread>
#include <utility>

namespace bigus::benchmark
{
namespace
{
std::string CommandOutput(const std::string& command)
{
  std::string out;
  if (FILE* pipe = ::popen(command.c_str(), "r"))
  {
    char buffer[256];
    while (std::fgets(buffer, sizeof(buffer), pipe))
    {
      out += buffer;
    }
    ::pclose(pipe);
  }
  while (!out.empty() && (out.back() == '\n' || out.back() == ' '))
  {
    out.pop_back();
  }
  return out;
}

std::string CpuModel()
{
  std::ifstream cpu("/proc/cpuinfo");
  std::string line;
  while (std::getline(cpu, line))
  {
    if (line.rfind("model name", 0) == 0)
    {
      return line.substr(line.find(':') + 2);
    }
  }
  return "unknown";
}
}

double Now()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

double PeakMemoryMiB()
{
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
  {
    if (line.rfind("VmHWM:", 0) == 0)
    {
      return std::stod(line.substr(6)) / 1024.0;
    }
  }
  return NaN;
}

void ResetPeakMemory()
{
  std::ofstream("/proc/self/clear_refs") << "5";
}

std::string Format(const char* format, double value)
{
  if (!std::isfinite(value))
  {
    return "-";
  }
  return vtkfmt::sprintf(format, value);
}

nlohmann::json ToJson(const Row& r)
{
  auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return { { "method", r.Method }, { "seconds", number(r.Seconds) }, { "ms_per_frame", number(r.MsPerFrame) },
    { "psnr", number(r.Quality.PSNR) }, { "ssim", number(r.Quality.SSIM) }, { "ncc", number(r.Quality.NCC) },
    { "speckle", number(r.Quality.Speckle) }, { "gaussians", r.Gaussians }, { "peak_mib", number(r.PeakMiB) },
    { "note", r.Note } };
}

std::string TableHeader()
{
  return "| method | time (s) | ms / frame | PSNR (dB) | SSIM | NCC | speckle | Gaussians | peak MiB | note |\n"
         "|---|---|---|---|---|---|---|---|---|---|\n";
}

std::string TableRow(const Row& r)
{
  std::ostringstream s;
  s << "| " << r.Method << " | " << Format("%.1f", r.Seconds) << " | " << Format("%.1f", r.MsPerFrame) << " | "
    << Format("%.2f", r.Quality.PSNR) << " | " << Format("%.4f", r.Quality.SSIM) << " | "
    << Format("%.4f", r.Quality.NCC) << " | " << Format("%.4f", r.Quality.Speckle) << " | "
    << (r.Gaussians >= 0 ? std::to_string(r.Gaussians) : "-") << " | " << Format("%.0f", r.PeakMiB) << " | " << r.Note
    << " |\n";
  return s.str();
}

void Print(const std::string& where, const Row& r)
{
  std::printf("  %-12s %-44s %8s s %8s ms/frame  PSNR %6s  SSIM %6s  NCC %6s  speckle %6s  %s Gaussians\n",
    where.c_str(), r.Method.c_str(), Format("%.1f", r.Seconds).c_str(), Format("%.1f", r.MsPerFrame).c_str(),
    Format("%.2f", r.Quality.PSNR).c_str(), Format("%.4f", r.Quality.SSIM).c_str(),
    Format("%.4f", r.Quality.NCC).c_str(), Format("%.4f", r.Quality.Speckle).c_str(),
    r.Gaussians >= 0 ? std::to_string(r.Gaussians).c_str() : "-");
  std::fflush(stdout);
}

PlotSpec TimePlot(const std::string& title, const std::vector<Row>& baselines, const std::vector<Row>& bigus)
{
  PlotSpec spec;
  spec.Title = title;
  spec.XLabel = "time (s, log): training, or compounding + one frame";
  spec.YLabel = "PSNR (dB)";
  spec.LogX = true;
  PlotSeries curve{ "BIGUS (training time)", {} };
  for (const Row& r : bigus)
  {
    curve.Points.emplace_back(r.Seconds, r.Quality.PSNR);
  }
  spec.Series.push_back(curve);
  for (const Row& r : baselines)
  {
    // A baseline's own time: its preparation plus producing one frame (at least 1 ms to fit the axis).
    const double t = std::max(1e-3, (std::isfinite(r.Seconds) ? r.Seconds : 0) + 1e-3 * r.MsPerFrame);
    spec.Series.push_back({ r.Method, { { t, r.Quality.PSNR } } });
  }
  return spec;
}

bool Failed(const std::string& what, std::string* error)
{
  *error = what;
  return false;
}

void Introduction(const std::string& root, bool quick, const std::string& backend, Report& report)
{
  const std::string commit = CommandOutput("git -C '" + root + "' rev-parse --short HEAD 2>/dev/null");
  const bool dirty =
    !CommandOutput("git -C '" + root + "' status --porcelain --untracked-files=no 2>/dev/null").empty();
  char date[64];
  const std::time_t now = std::time(nullptr);
  std::strftime(date, sizeof(date), "%Y-%m-%d %H:%M %Z", std::localtime(&now));
  const std::string machine = CpuModel() + ", " + std::to_string(std::thread::hardware_concurrency()) +
    " logical cores, " + std::to_string(vtkSMPTools::GetEstimatedNumberOfThreads()) + " threads (" +
    vtkSMPTools::GetBackend() + ")";
  std::printf("bigus benchmark%s: %s\n", quick ? " --quick" : "", machine.c_str());

  std::ostringstream& md = report.Markdown;
  md << "# Benchmarks: speed against error\n\n"
     << "Produced by `bigus benchmark" << (quick ? " --quick" : "") << (backend != "cpu" ? " --backend " + backend : "")
     << "` on " << date << " at commit `" << commit << (dirty ? " (with uncommitted changes)" : "") << "`.\n"
     << "Machine: " << machine << "; training backend `" << backend
     << (backend == "cpu" ? "` (no GPU was used)" : "` (the render cutoffs section measures the CPU renderer)") << ".\n"
     << "Every number below is the one this command printed; rerun it to reproduce them (timings vary "
     << "between runs on a shared machine: compare within one report). The hand-run measurements behind "
     << "the trainer's defaults are in docs/FINDINGS.md; the MPI measurements (bigus batch on 1 and 2 ranks, "
     << "data-parallel training and its model at 8 to 512 ranks) in docs/BENCHMARKS_mpi.md "
     << "(Examples/benchmark_mpi.py: mpirun runs this program, not the other way round).\n\n"
     << "Conventions: metrics inside the fan mask of the recorded frame (DESIGN section 9; speckle = "
     << "Backscatter Fidelity Score). Training time is wall-clock and "
     << "stops while held-out frames are evaluated; each row is the field as trained until then (a mark waits "
     << "for the first step out of the pose trial and of a densification's dip: Trainer::IsSettled), without the "
     << "final prune (which changes no training pixel by more than 1/512). A baseline's time is its preparation "
        "(compounding) "
     << "and its ms per frame is the time to produce one held-out frame; BIGUS's ms per frame is the render "
     << "time of one held-out frame. Peak MiB is the process's peak resident memory during that run "
     << "(frames of every sweep included).\n\n"
     << "Where the held-out error comes from (a table per sweep): the field rendered at its training poses "
     << "(training frames) and at the held-out poses (held-out) against the recording, and the blend baseline "
     << "run on the field's renders instead of the recording (blended renders: its renders at the two bracketing "
     << "training frames, blended in time). If the field's views between training frames were as good an "
     << "interpolation as blending the recorded frames, its held-out error would be its training error plus the "
     << "blend's error: fit + blend adds the two mean squared errors (MSE = 10^(-PSNR / 10), from mean PSNRs, so "
     << "approximate).\n";
  report.Json["date"] = date;
  report.Json["commit"] = commit + (dirty ? "+dirty" : "");
  report.Json["machine"] = machine;
  report.Json["quick"] = quick;
  report.Json["backend"] = backend;
}

bool WriteReport(
  const std::string& output, const std::string& section, double seconds, Report& report, std::string* error)
{
  report.Markdown << "\nTotal run time of the command: " << Format("%.1f", seconds / 60) << " minutes.\n";
  report.Json["total_seconds"] = seconds;
  const std::string suffix = section == "all" ? "" : "_" + section;
  const std::string markdown = output + "/BENCHMARKS" + suffix + ".md";
  const std::string json = report.PlotFolder + "/results" + suffix + ".json";
  for (const auto& [path, text] :
    { std::pair<std::string, std::string>{ markdown, report.Markdown.str() }, { json, report.Json.dump(2) + "\n" } })
  {
    const std::string temporary = TemporaryName(path);
    std::ofstream out(temporary);
    out << text;
    out.close();
    if (!out || !Publish(temporary, path))
    {
      std::remove(temporary.c_str());
      return Failed(path + ": cannot write", error);
    }
  }
  std::printf("wrote %s and %s\n", markdown.c_str(), json.c_str());
  return true;
}
}
