// `bigus batch MANIFEST.json`: train and evaluate many jobs, on one process or on MPI ranks sharing a work
// queue held by rank 0; a summary of every job; a rerun skips the jobs whose outputs are complete.
#include "bigusBatchManifest.h"
#include "bigusCommandLine.h"
#include "bigusPlot.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkNew.h"
#include "vtkPolyData.h"
#include "vtkXMLPolyDataReader.h"

#include <CLI/CLI.hpp>
#include <mpi.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <new>
#include <sstream>
#include <string>
#include <sys/file.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace bigus::cli
{
namespace
{
namespace fs = std::filesystem;
using json = nlohmann::json;
/// Records are written with invalid UTF-8 (an error text may name a file in any bytes) replaced, not thrown on.
constexpr json::error_handler_t Utf8Replace = json::error_handler_t::replace;

struct BatchOptions
{
  std::string Manifest, Summary;
};

/// The job's record (job.json) when its outputs are complete and were made by these arguments: the field
/// reads back with the recorded count of Gaussians and metrics.json has its mean. Otherwise null.
json CompletedJob(const BatchJob& job)
{
  try
  {
    std::ifstream in(fs::path(job.Output) / "job.json");
    std::ifstream metricsFile(fs::path(job.Output) / "metrics.json");
    if (!in || !metricsFile)
    {
      return nullptr;
    }
    json record = json::parse(in);
    const json metrics = json::parse(metricsFile);
    if (record.value("status", "") != "done" || record.value("train", json()) != json(job.TrainArguments) ||
      record.value("evaluate", json()) != json(job.EvaluateArguments) || !metrics.contains("mean"))
    {
      return nullptr;
    }
    const std::string field = (fs::path(job.Output) / "field.vtp").string();
    if (!fs::exists(field))
    {
      return nullptr;
    }
    vtkNew<vtkXMLPolyDataReader> reader;
    reader->SetFileName(field.c_str());
    reader->Update();
    if (reader->GetErrorCode() != 0 || reader->GetOutput()->GetNumberOfPoints() != record.value("gaussians", -1LL))
    {
      return nullptr;
    }
    return record;
  }
  catch (const json::exception&)
  {
    return nullptr;
  }
}

/// The job's stdout and stderr go to its log.txt while it runs (this process runs one job at a time).
class LogRedirect
{
public:
  explicit LogRedirect(const std::string& path)
  {
    std::fflush(stdout);
    std::fflush(stderr);
    const int log = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (log < 0)
    {
      return;
    }
    this->Saved[0] = ::dup(STDOUT_FILENO);
    this->Saved[1] = ::dup(STDERR_FILENO);
    ::dup2(log, STDOUT_FILENO);
    ::dup2(log, STDERR_FILENO);
    ::close(log);
  }
  ~LogRedirect()
  {
    std::fflush(stdout);
    std::fflush(stderr);
    for (int k = 0; k < 2; ++k)
    {
      if (this->Saved[k] >= 0)
      {
        ::dup2(this->Saved[k], k ? STDERR_FILENO : STDOUT_FILENO);
        ::close(this->Saved[k]);
      }
    }
  }
  LogRedirect(const LogRedirect&) = delete;
  LogRedirect& operator=(const LogRedirect&) = delete;

private:
  int Saved[2] = { -1, -1 };
};

/// The last "bigus: ..." line of a job's log: the error its command reported.
std::string LastError(const std::string& log)
{
  std::ifstream in(log);
  std::string error;
  for (std::string line; std::getline(in, line);)
  {
    if (line.rfind("bigus: ", 0) == 0)
    {
      error = line.substr(7);
    }
  }
  return error;
}

/// Adds "--frames" and the frames of the scored sweep not in @p training to @p evaluate (the arguments of
/// `bigus evaluate`); returns 1 after a message when the sweep cannot be read.
int AddHeldOutFrames(const std::vector<int>& training, std::vector<std::string>& evaluate)
{
  SweepOptions sweep;
  sweep.Sweep = evaluate[2];
  for (std::size_t k = 3; k + 1 < evaluate.size(); ++k)
  {
    sweep.Calibration = evaluate[k] == "--calibration" ? evaluate[k + 1] : sweep.Calibration;
    sweep.Chain = evaluate[k] == "--transform" ? evaluate[k + 1] : sweep.Chain;
  }
  auto reader = ReadSweep(sweep);
  if (!reader)
  {
    return 1;
  }
  evaluate.push_back("--frames");
  for (int k = 0; k < reader->GetOutput()->GetDimensions()[2]; ++k)
  {
    if (std::find(training.begin(), training.end(), k) == training.end())
    {
      evaluate.push_back(std::to_string(k));
    }
  }
  return 0;
}

/// An exclusive lock on a job's folder while this process trains it: flock(2) on OUTPUT/.bigus-batch.lock, released
/// by the kernel when the process ends however it ends, so two batch runs of one manifest (on one machine, or on a
/// shared file system whose locks reach every client) never train one job at once.
class JobLock
{
public:
  explicit JobLock(const std::string& folder)
    : File(::open((fs::path(folder) / ".bigus-batch.lock").c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0644))
  {
    // A folder where no lock can be made is left to the job, which fails there with its own message.
    this->Busy = this->File >= 0 && ::flock(this->File, LOCK_EX | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  }
  ~JobLock()
  {
    if (this->File >= 0)
    {
      ::close(this->File);
    }
  }
  JobLock(const JobLock&) = delete;
  JobLock& operator=(const JobLock&) = delete;
  bool Busy = false; ///< another process holds the lock: it trains this job now

private:
  int File = -1;
};

/// Whether a job's record holds its metrics: trained by this run ("done") or complete before it ("kept"), not
/// "failed" nor left to another run ("busy").
bool Scored(const json& r)
{
  const std::string status = r.value("status", "");
  return status == "done" || status == "kept";
}

/// Trains and evaluates one job into its folder; returns its record (also written as job.json, last). A job another
/// batch run is training (JobLock) is left to it, untouched ("busy"); one completed since this run's queue was made
/// is kept.
json RunJob(const BatchJob& job, int rank, int threads)
{
  const auto start = std::chrono::steady_clock::now();
  json record = { { "name", job.Name }, { "output", job.Output }, { "train", job.TrainArguments },
    { "evaluate", job.EvaluateArguments }, { "rank", rank } };
  std::error_code made;
  fs::create_directories(job.Output, made);
  const JobLock lock(job.Output);
  if (lock.Busy)
  {
    record["status"] = "busy";
    record["error"] = "another batch run is training this job now (" + job.Output + "/.bigus-batch.lock is held)";
    return record;
  }
  json completed = CompletedJob(job);
  if (!completed.is_null())
  {
    completed["status"] = "kept";
    return completed;
  }
  fs::remove(fs::path(job.Output) / "job.json", made); // a rerun's outputs are not complete until it ends
  const std::string log = (fs::path(job.Output) / "log.txt").string();
  int code = 1;
  std::string error;
  {
    LogRedirect redirect(log);
    try
    {
      std::vector<std::string> train = job.TrainArguments;
      if (threads > 0 && std::find(train.begin(), train.end(), "--threads") == train.end())
      {
        train.insert(train.end(), { "--threads", std::to_string(threads) });
      }
      // A job stopped before its outputs were complete goes on from its checkpoint (the job's "checkpoint" key);
      // one the resume refuses (written with options the manifest has changed since, or broken) is trained afresh.
      const auto at = std::find(train.begin(), train.end(), "--checkpoint");
      bool resumed = false;
      if (at != train.end() && at + 1 != train.end() && fs::exists(*(at + 1)))
      {
        std::vector<std::string> resume = train;
        resume.insert(resume.end(), { "--resume", *(at + 1) });
        std::printf("batch: resuming from the checkpoint %s\n", (at + 1)->c_str());
        resumed = RunCommand(resume, false) == 0;
        if (!resumed)
        {
          std::printf(
            "batch: the checkpoint %s could not be resumed (above); training from the start\n", (at + 1)->c_str());
        }
      }
      std::vector<std::string> evaluate = job.EvaluateArguments;
      code = resumed ? 0 : RunCommand(train, false);
      code = code == 0 && !job.TrainingFrames.empty() ? AddHeldOutFrames(job.TrainingFrames, evaluate) : code;
      code = code == 0 ? RunCommand(evaluate, false) : code;
    }
    catch (const std::bad_alloc&)
    {
      error = "out of memory";
    }
    catch (const std::exception& e)
    {
      error = e.what();
    }
  }
  record["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (code == 0 && error.empty())
  {
    vtkNew<vtkXMLPolyDataReader> reader;
    const std::string field = (fs::path(job.Output) / "field.vtp").string();
    reader->SetFileName(field.c_str());
    reader->Update();
    std::ifstream metrics(fs::path(job.Output) / "metrics.json");
    try
    {
      record["metrics"] = json::parse(metrics).at("mean");
      record["gaussians"] = static_cast<long long>(reader->GetOutput()->GetNumberOfPoints());
      record["status"] = "done";
    }
    catch (const json::exception&)
    {
      error = "metrics.json unreadable after evaluate";
    }
  }
  if (!record.contains("status"))
  {
    record["status"] = "failed";
    record["error"] = error.empty() ? LastError(log) : error;
    if (record["error"].get<std::string>().empty())
    {
      record["error"] = "exit code " + std::to_string(code) + " (see " + log + ")";
    }
  }
  if (!WriteText((fs::path(job.Output) / "job.json").string(), record.dump(2, ' ', false, Utf8Replace) + "\n"))
  {
    record["status"] = "failed";
    record["error"] = job.Output + "/job.json: cannot write";
  }
  return record;
}

/// Mean, sample standard deviation, smallest and largest of @p values.
json Spread(const std::vector<double>& values)
{
  if (values.empty())
  {
    return nullptr;
  }
  double sum = 0, squares = 0;
  for (double v : values)
  {
    sum += v;
  }
  const double mean = sum / values.size();
  for (double v : values)
  {
    squares += (v - mean) * (v - mean);
  }
  return { { "mean", mean }, { "sd", values.size() > 1 ? std::sqrt(squares / (values.size() - 1)) : 0.0 },
    { "min", *std::min_element(values.begin(), values.end()) },
    { "max", *std::max_element(values.begin(), values.end()) }, { "jobs", values.size() } };
}

/// summary.json and summary.md in @p folder; false when they cannot be written.
bool WriteSummary(
  const std::string& folder, const std::string& manifest, const std::vector<json>& records, int ranks, double seconds)
{
  const char* metrics[] = { "psnr", "ssim", "ncc", "speckle" };
  std::map<std::string, std::vector<double>> values;
  int counts[4] = { 0, 0, 0, 0 }; // done now, kept (complete before this run), failed, busy (another run's)
  for (const json& r : records)
  {
    const std::string status = r.value("status", "");
    counts[status == "done" ? 0 : status == "kept" ? 1 : status == "busy" ? 3 : 2]++;
    if (!Scored(r))
    {
      continue;
    }
    for (const char* m : metrics)
    {
      values[m].push_back(r["metrics"].value(m, 0.0));
    }
    values["gaussians"].push_back(r.value("gaussians", 0.0));
    values["seconds"].push_back(r.value("seconds", 0.0));
  }
  json summary = { { "manifest", manifest }, { "ranks", ranks }, { "wall_seconds", seconds }, { "done", counts[0] },
    { "kept", counts[1] }, { "failed", counts[2] }, { "busy", counts[3] }, { "jobs", records } };
  for (const auto& [name, list] : values)
  {
    summary["statistics"][name] = Spread(list);
  }
  std::ostringstream md;
  char cell[256];
  md << "# bigus batch " << manifest << "\n\n"
     << records.size() << " jobs: " << counts[0] << " done, " << counts[1] << " kept (complete before this run), "
     << counts[2] << " failed, " << counts[3] << " left to another batch run training them; " << ranks
     << (ranks == 1 ? " process" : " MPI ranks") << ", " << std::lround(seconds) << " s wall-clock.\n\n"
     << "| job | status | rank | seconds | Gaussians | PSNR (dB) | SSIM | NCC | speckle | error |\n"
     << "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const json& r : records)
  {
    const bool scored = Scored(r);
    std::snprintf(cell, sizeof(cell), "| %s | %s | %d | %.1f | ", r.value("name", "").c_str(),
      r.value("status", "").c_str(), r.value("rank", 0), r.value("seconds", 0.0));
    md << cell;
    if (scored)
    {
      std::snprintf(cell, sizeof(cell), "%lld | %.2f | %.4f | %.4f | %.4f | |\n", r.value("gaussians", 0LL),
        r["metrics"].value("psnr", 0.0), r["metrics"].value("ssim", 0.0), r["metrics"].value("ncc", 0.0),
        r["metrics"].value("speckle", 0.0));
      md << cell;
    }
    else
    {
      md << "| | | | | " << r.value("error", "") << " |\n";
    }
  }
  if (!values.empty())
  {
    auto stat = [&](const char* name, const char* format) {
      const json& s = summary["statistics"][name];
      std::snprintf(cell, sizeof(cell), format, s["mean"].get<double>(), s["sd"].get<double>());
      return std::string(cell);
    };
    md << "| mean +- sd (" << values["seconds"].size() << " scored) | | | " << stat("seconds", "%.1f +- %.1f") << " | "
       << stat("gaussians", "%.0f +- %.0f") << " | " << stat("psnr", "%.2f +- %.2f") << " | "
       << stat("ssim", "%.4f +- %.4f") << " | " << stat("ncc", "%.4f +- %.4f") << " | "
       << stat("speckle", "%.4f +- %.4f") << " | |\n";
  }
  return WriteText(folder + "/summary.json", summary.dump(2, ' ', false, Utf8Replace) + "\n") &&
    WriteText(folder + "/summary.md", md.str());
}

constexpr int RequestTag = 1; ///< worker -> rank 0: the record of its last job (empty at first), and a request
constexpr int JobTag = 2;     ///< rank 0 -> worker: the index of its next job, -1 when none is left

int RunBatch(const BatchOptions& o)
{
  SetGracefulStop(false); // a signal ends the batch and its jobs; a rerun goes on with the queue
  const auto start = std::chrono::steady_clock::now();
  int rank = 0, ranks = 1, threads = 0;
  const bool mpi = LaunchedByMpi();
  if (mpi)
  {
    // Funneled: only the main thread calls MPI; on rank 0 a second thread trains while it serves the queue.
    int provided = 0;
    MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &ranks);
    if (provided < MPI_THREAD_FUNNELED)
    {
      if (rank == 0)
      {
        std::fprintf(stderr,
          "bigus: this MPI library does not allow threads (MPI_THREAD_FUNNELED), which rank 0 "
          "needs to train while it serves the queue\n");
      }
      MPI_Finalize();
      return 1;
    }
    threads = ThreadsPerRank();
  }
  auto finish = [&](int code) {
    if (mpi)
    {
      // Wait for every rank without spinning a core (a blocking barrier polls), then finalise.
      MPI_Request request;
      MPI_Ibarrier(MPI_COMM_WORLD, &request);
      for (int done = 0; !done;)
      {
        MPI_Test(&request, &done, MPI_STATUS_IGNORE);
        if (!done)
        {
          std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
      }
      MPI_Finalize();
    }
    return code;
  };
  std::vector<BatchJob> jobs;
  std::string error;
  bool read = false;
  try
  {
    read = ReadManifest(o.Manifest, jobs, error);
  }
  catch (const json::exception& e)
  {
    error = o.Manifest + ": " + e.what();
  }
  if (!read)
  {
    if (rank == 0)
    {
      std::fprintf(stderr, "bigus: %s\n", error.c_str());
    }
    return finish(2); // every rank read the same manifest and refused it
  }
  const std::string summaryFolder =
    o.Summary.empty() ? fs::absolute(fs::path(o.Manifest)).parent_path().string() : o.Summary;
  // Before any job runs: the summary can be written there.
  if (CheckOutputs({ summaryFolder + "/summary.json", summaryFolder + "/summary.md" }, { o.Manifest }) != 0)
  {
    return finish(2);
  }
  // The batch's own lines go to the terminal even while a job's output goes to its log.
  FILE* console = fdopen(::dup(STDOUT_FILENO), "w");
  std::mutex printing;
  auto report = [&](const json& r, std::size_t index) {
    std::lock_guard<std::mutex> lock(printing);
    if (!Scored(r))
    {
      std::fprintf(console, "job %zu/%zu %s: %s on rank %d after %.1f s: %s\n", index + 1, jobs.size(),
        r.value("name", "").c_str(), r.value("status", "") == "busy" ? "left to the run that holds it" : "failed",
        r.value("rank", 0), r.value("seconds", 0.0), r.value("error", "").c_str());
    }
    else
    {
      std::fprintf(console, "job %zu/%zu %s: %s on rank %d in %.1f s: %lld Gaussians, held-out PSNR %.2f dB\n",
        index + 1, jobs.size(), r.value("name", "").c_str(),
        r.value("status", "") == "kept" ? "kept (complete before this run), trained" : "done", r.value("rank", 0),
        r.value("seconds", 0.0), r.value("gaussians", 0LL), r["metrics"].value("psnr", 0.0));
    }
    std::fflush(console);
  };
  std::vector<json> records(jobs.size());
  if (rank != 0)
  {
    std::string last;
    for (;;)
    {
      MPI_Send(last.data(), static_cast<int>(last.size()), MPI_CHAR, 0, RequestTag, MPI_COMM_WORLD);
      int index = -1;
      MPI_Recv(&index, 1, MPI_INT, 0, JobTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      if (index < 0 || index >= static_cast<int>(jobs.size()))
      {
        break;
      }
      json r = RunJob(jobs[index], rank, threads);
      r["index"] = index;
      last = r.dump(-1, ' ', false, Utf8Replace);
    }
    std::fclose(console);
    return finish(0);
  }
  // Rank 0: the queue of the jobs not complete before this run.
  std::vector<int> pending;
  for (std::size_t j = 0; j < jobs.size(); ++j)
  {
    records[j] = CompletedJob(jobs[j]);
    if (records[j].is_null())
    {
      pending.push_back(static_cast<int>(j));
    }
    else
    {
      records[j]["status"] = "kept";
      report(records[j], j);
    }
  }
  std::fprintf(console, "batch          %zu jobs (%zu to run, %zu complete before this run) on %d %s\n", jobs.size(),
    pending.size(), jobs.size() - pending.size(), ranks, ranks == 1 ? "process" : "MPI ranks sharing a queue");
  std::fflush(console);
  std::atomic<std::size_t> next{ 0 };
  auto take = [&]() {
    const std::size_t k = next++;
    return k < pending.size() ? pending[k] : -1;
  };
  std::mutex recording;
  auto record = [&](json r, int index) {
    {
      std::lock_guard<std::mutex> lock(recording);
      records[index] = r;
    }
    report(r, index);
  };
  std::thread local([&] {
    for (int index; (index = take()) >= 0;)
    {
      record(RunJob(jobs[index], 0, threads), index);
    }
  });
  for (int active = ranks - 1; active > 0;)
  {
    int waiting = 0;
    MPI_Status status;
    MPI_Iprobe(MPI_ANY_SOURCE, RequestTag, MPI_COMM_WORLD, &waiting, &status);
    if (!waiting)
    {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      continue;
    }
    int length = 0;
    MPI_Get_count(&status, MPI_CHAR, &length);
    std::string message(length, '\0');
    MPI_Recv(message.data(), length, MPI_CHAR, status.MPI_SOURCE, RequestTag, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    if (!message.empty())
    {
      json r = json::parse(message);
      record(r, r["index"].get<int>());
    }
    int index = take();
    MPI_Send(&index, 1, MPI_INT, status.MPI_SOURCE, JobTag, MPI_COMM_WORLD);
    active -= index < 0;
  }
  local.join();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  int failed = 0;
  for (const json& r : records)
  {
    failed += r.value("status", "") == "failed";
  }
  if (!WriteSummary(summaryFolder, o.Manifest, records, ranks, seconds))
  {
    std::fclose(console);
    return finish(Fail(summaryFolder + ": cannot write summary.json / summary.md"));
  }
  std::fprintf(console, "summary        %s/summary.json, summary.md: %zu jobs, %d failed, %.1f s\n",
    summaryFolder.c_str(), jobs.size(), failed, seconds);
  std::fclose(console);
  return finish(failed ? 1 : 0);
}
}

Command AddBatchCommand(CLI::App& app)
{
  auto options = std::make_shared<BatchOptions>();
  CLI::App* batch = app.add_subcommand("batch",
    "Train and evaluate the jobs of a manifest (under mpirun -n P: P ranks share a work queue); a rerun skips "
    "completed jobs");
  batch
    ->add_option("MANIFEST", options->Manifest,
      "JSON: {\"defaults\": {...}, \"jobs\": [{\"sweep\": FILE or [FILES], \"output\": FOLDER, \"name\": ..., "
      "and any bigus train option without its dashes: \"calibration\", \"holdout-every\", \"time-budget\", ...}]}; "
      "paths relative to the manifest's folder")
    ->required()
    ->check(CLI::ExistingFile);
  batch->add_option(
    "--summary", options->Summary, "Folder for summary.json and summary.md (default: the manifest's folder)");
  return { batch, [options] { return RunBatch(*options); } };
}

} // namespace bigus::cli
