// `bigus train`: train a Gaussian scattering field from a tracked sweep.
#include "bigusCommandLine.h"
#include "bigusGapFilling.h"
#include "bigusGaussianFieldData.h"
#include "bigusPlot.h"
#include "bigusTrainer.h"
#include "bigusSliceFrame.h"
#include "vtkCallbackCommand.h"
#include "vtkCommand.h"
#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkGaussianFieldTrainer.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkMPIController.h"
#include "vtkMath.h"
#include "vtkNew.h"
#include "vtkSMPTools.h"
#include "vtkStringArray.h"
#include "vtkUltrasoundSequenceReader.h"
#include "vtkUltrasoundSequenceWriter.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mpi.h>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

namespace bigus::cli
{
namespace
{
struct TrainOptions
{
  std::vector<std::string> Sweeps, Calibrations, Masks; ///< one calibration / mask for all, or one per sweep
  std::string Chain;                                    ///< --transform, for every sweep
  std::string Output, Checkpoint, Resume, Backend = "auto";
  int CheckpointInterval = 200; ///< steps between checkpoints written to Checkpoint
  int HoldOutEvery = 0, HoldOutOffset = 0, HoldOutSweep = -1, Threads = 0;
  bool Distributed = false;
  std::vector<int> Frames; ///< explicit training frames (empty: the hold-out rule)
  double EvaluationInterval = 0;
  std::vector<std::string> RefinedPoses; ///< one per sweep
  std::vector<double> LossWeights;       ///< --loss-weights: L1, D-SSIM, FFL (empty: the trainer's)
  /// The trainer's settings, the options bound to them: their defaults are the trainer's own.
  TrainerSettings Settings;
};

/// The signal (SIGINT, SIGTERM) that asked the run to stop, 0 while none did; a second one ends the process at once.
volatile std::sig_atomic_t StopSignal = 0;
bool GracefulStop = true; // SetGracefulStop

void OnStopSignal(int signal)
{
  StopSignal = signal;
}

/// While it lives, SIGINT and SIGTERM ask the training to stop (StopSignal) instead of ending the process; the
/// handlers reset to the default after one signal (SA_RESETHAND), so a second one ends the process as before.
struct StopSignals
{
  struct sigaction Previous[2];
  bool Installed = false;
  StopSignals()
  {
    StopSignal = 0;
    this->Installed = GracefulStop;
    if (!this->Installed)
    {
      return;
    }
    struct sigaction action = {};
    action.sa_handler = OnStopSignal;
    action.sa_flags = SA_RESETHAND;
    sigemptyset(&action.sa_mask);
    sigaction(SIGINT, &action, &this->Previous[0]);
    sigaction(SIGTERM, &action, &this->Previous[1]);
  }
  ~StopSignals() { this->Restore(); }
  /// The handlers as they were before.
  void Restore()
  {
    if (!this->Installed)
    {
      return;
    }
    sigaction(SIGINT, &this->Previous[0], nullptr);
    sigaction(SIGTERM, &this->Previous[1], nullptr);
    this->Installed = false;
  }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;
};

/// The name of the field trained until a signal stopped the run: F.interrupted.vtp for F.vtp.
std::string InterruptedName(const std::string& output)
{
  const std::string stem = EndsWith(output, ".vtp") ? output.substr(0, output.size() - 4) : output;
  return stem + ".interrupted.vtp";
}

/// --distributed under mpirun: the MPI controller of the run (finalised when the command ends), this rank.
struct Processes
{
  vtkSmartPointer<vtkMPIController> Controller;
  int Rank = 0;
  ~Processes()
  {
    if (this->Controller)
    {
      this->Controller->Finalize();
    }
  }
  /**
   * The command's exit code @p code. A rank that fails with others running ends them all (MPI_Abort, after its
   * own message): they may be waiting for it in a sum it will never enter (its sweep could not be read, or it
   * failed outside the trainer's agreed checks).
   */
  int Exit(int code) const
  {
    if (code != 0 && this->Controller && this->Controller->GetNumberOfProcesses() > 1)
    {
      std::fflush(stdout);
      std::fflush(stderr);
      MPI_Abort(MPI_COMM_WORLD, code);
    }
    return code;
  }
};

int TrainOnThisProcess(const TrainOptions& o, Processes& processes);

int RunTrain(const TrainOptions& o)
{
  Processes processes;
  return processes.Exit(TrainOnThisProcess(o, processes));
}

int TrainOnThisProcess(const TrainOptions& o, Processes& processes)
{
  int threads = o.Threads;
  if (o.Distributed && LaunchedByMpi())
  {
    processes.Controller = vtkSmartPointer<vtkMPIController>::New();
    processes.Controller->Initialize(nullptr, nullptr);
    processes.Rank = processes.Controller->GetLocalProcessId();
    threads = threads > 0 ? threads : ThreadsPerRank();
    if (processes.Rank != 0)
    {
      // Rank 0 reports and writes; the others' errors still reach stderr.
      std::fflush(stdout);
      if (!std::freopen("/dev/null", "w", stdout))
      {
        return Fail("cannot silence the output of rank " + std::to_string(processes.Rank));
      }
    }
  }
  else if (o.Distributed)
  {
    std::printf("distributed    not started by mpirun: this process trains alone\n");
  }
  if (threads > 0)
  {
    vtkSMPTools::Initialize(threads);
  }
  const std::size_t count = o.Sweeps.size();
  for (const auto& [files, what] :
    { std::make_pair(&o.Calibrations, "--calibration"), std::make_pair(&o.Masks, "--mask") })
  {
    if (files->size() > 1 && files->size() != count)
    {
      std::fprintf(stderr,
        "bigus: %zu sweeps and %zu %s files: give one for every sweep, in the sweeps' order, or one for all\n", count,
        files->size(), what);
      return 2;
    }
  }
  const PoseRefinementSettings& poses = o.Settings.Poses;
  if (!o.RefinedPoses.empty() && poses.RefinePoses == PoseRefinement::Off && !poses.RefineTimeOffset &&
    !poses.RefineImageToProbe)
  {
    std::fprintf(
      stderr, "bigus: --refined-poses with --no-refine-poses needs --refine-time-offset or --refine-image-to-probe\n");
    return 2;
  }
  if (!o.RefinedPoses.empty() && o.RefinedPoses.size() != count)
  {
    std::fprintf(stderr, "bigus: %zu sweeps and %zu --refined-poses files: give one per sweep, in the sweeps' order\n",
      count, o.RefinedPoses.size());
    return 2;
  }
  std::string lossError;
  if (!o.LossWeights.empty() &&
    !bigus::CheckImageLossWeights({ o.LossWeights[0], o.LossWeights[1], o.LossWeights[2] }, &lossError))
  {
    std::fprintf(stderr, "bigus: --loss-weights: %s\n", lossError.c_str());
    return 2;
  }
  // Before any work: no output replaces an input, and every output can be written.
  // (The checkpoint may be the file a run resumes from.)
  std::vector<std::string> outputs = o.RefinedPoses, inputs = o.Sweeps;
  outputs.push_back(o.Output);
  inputs.insert(inputs.end(), o.Calibrations.begin(), o.Calibrations.end());
  inputs.insert(inputs.end(), o.Masks.begin(), o.Masks.end());
  std::vector<std::string> withCheckpoint = outputs;
  withCheckpoint.push_back(o.Checkpoint);
  if (CheckOutputs(withCheckpoint, inputs) != 0 || CheckOutputs(outputs, { o.Resume }) != 0)
  {
    return 1;
  }
  vtkNew<vtkGaussianFieldTrainer> trainer;
  std::vector<vtkSmartPointer<vtkUltrasoundSequenceReader>> readers;
  for (std::size_t k = 0; k < count; ++k)
  {
    auto pick = [k](const std::vector<std::string>& files) {
      return files.empty() ? std::string() : files[files.size() == 1 ? 0 : k];
    };
    SweepOptions sweep;
    sweep.Sweep = o.Sweeps[k];
    sweep.Calibration = pick(o.Calibrations);
    sweep.Chain = o.Chain;
    auto reader = ReadSweep(sweep);
    if (!reader)
    {
      return 1;
    }
    trainer->AddInputConnection(0, reader->GetOutputPort());
    if (!o.Masks.empty())
    {
      auto mask = ReadMask(pick(o.Masks), reader->GetOutput()->GetDimensions());
      if (!mask)
      {
        return 1;
      }
      trainer->AddInputData(1, mask);
    }
    readers.push_back(reader);
  }
  if (count > 1)
  {
    std::printf("sweeps         %zu, trained into one field (frame indices count them in turn):", count);
    int first = 0;
    for (std::size_t k = 0; k < count; ++k)
    {
      const int frames = readers[k]->GetOutput()->GetDimensions()[2];
      std::printf("%s %zu = %s (frames %d to %d)", k ? ";" : "", k, o.Sweeps[k].c_str(), first, first + frames - 1);
      first += frames;
    }
    std::printf("\n");
  }
  trainer->SetHoldOutEvery(o.HoldOutEvery);
  trainer->SetHoldOutOffset(o.HoldOutOffset);
  trainer->SetHoldOutSweep(o.HoldOutSweep);
  if (!o.Frames.empty())
  {
    vtkNew<vtkIdList> frames;
    for (int k : o.Frames)
    {
      frames->InsertUniqueId(k);
    }
    trainer->SetTrainingFrameList(frames);
  }
  TrainerSettings settings = o.Settings;
  if (!o.LossWeights.empty())
  {
    settings.Loss.L1 = o.LossWeights[0];
    settings.Loss.DSSIM = o.LossWeights[1];
    settings.Loss.FFL = o.LossWeights[2];
  }
  // Without --checkpoint, a run stopped by a signal still leaves one to resume from (only then is it written).
  settings.CheckpointFile = o.Checkpoint.empty() ? o.Output + ".checkpoint" : o.Checkpoint;
  settings.CheckpointInterval = o.Checkpoint.empty() ? 0 : o.CheckpointInterval;
  trainer->SetTrainerSettings(settings);
  trainer->SetController(processes.Controller);
  trainer->SetEvaluationInterval(o.EvaluationInterval);
  trainer->SetBackend(o.Backend.c_str());
  if (!o.Resume.empty())
  {
    trainer->SetResumeFile(o.Resume.c_str());
  }
  // Progress: a bar on a terminal, a line every 10 % otherwise.
  const bool terminal = ::isatty(STDOUT_FILENO);
  const auto start = std::chrono::steady_clock::now();
  int lastDecile = -1;
  vtkNew<vtkCallbackCommand> progress;
  struct Context
  {
    bool Terminal;
    std::chrono::steady_clock::time_point Start;
    int* LastDecile;
  } context{ terminal, start, &lastDecile };
  progress->SetClientData(&context);
  progress->SetCallback([](vtkObject* caller, unsigned long, void* client, void* data) {
    const Context& c = *static_cast<Context*>(client);
    const double fraction = *static_cast<double*>(data);
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - c.Start).count();
    const double eta = fraction > 0 ? elapsed * (1 - fraction) / fraction : 0;
    auto* t = static_cast<vtkGaussianFieldTrainer*>(caller);
    if (StopSignal)
    {
      t->SetAbortExecute(1); // the trainer stops at its next step, saves a checkpoint and outputs the field so far
    }
    if (t->GetCurrentIteration() == 0)
    {
      return; // the pipeline's own 0 % and 100 % events, also sent when training fails before a step
    }
    char state[160];
    std::snprintf(state, sizeof(state), "%3.0f%%  iteration %d  loss %.4f  Gaussians %lld  elapsed %.0f s  ETA %.0f s",
      100 * fraction, t->GetCurrentIteration(), t->GetCurrentLoss(),
      static_cast<long long>(t->GetCurrentNumberOfGaussians()), elapsed, eta);
    if (c.Terminal)
    {
      const int width = 24, filled = static_cast<int>(fraction * width);
      std::printf("\r[%s%s] %s   ", std::string(filled, '#').c_str(), std::string(width - filled, ' ').c_str(), state);
      std::fflush(stdout);
    }
    else if (static_cast<int>(fraction * 10) > *c.LastDecile)
    {
      *c.LastDecile = static_cast<int>(fraction * 10);
      std::printf("training %s\n", state);
      std::fflush(stdout);
    }
  });
  trainer->AddObserver(vtkCommand::ProgressEvent, progress);
  vtkNew<vtkCallbackCommand> chosen;
  chosen->SetCallback([](vtkObject* caller, unsigned long, void*, void*) {
    std::istringstream lines(static_cast<vtkGaussianFieldTrainer*>(caller)->GetSettingsText());
    for (std::string line; std::getline(lines, line);)
    {
      std::printf("setting        %s\n", line.c_str());
    }
    std::fflush(stdout);
  });
  trainer->AddObserver(vtkGaussianFieldTrainer::SettingsChosenEvent, chosen);
  FilterError error;
  error.Watch(trainer);
  StopSignals signals;
  trainer->Update();
  if (StopSignal && std::string(trainer->GetStopReason()) != "aborted")
  {
    // The signal came where no step could take it (reading, seeding, the pixel-grid fit, the end stages): it ends
    // the process as it would have without the handler, before any output is written.
    const int signal = StopSignal;
    signals.Restore();
    std::raise(signal);
  }
  if (terminal)
  {
    std::printf("\n");
  }
  if (StopSignal && trainer->GetNumberOfGaussians() > 0 && std::string(trainer->GetStopReason()) == "aborted")
  {
    // Stopped by a signal: the field so far under its own name (the output the user asked for is untouched), the
    // checkpoint, and how to go on.
    const int code = 128 + StopSignal;
    if (processes.Rank != 0)
    {
      return code;
    }
    const std::string interrupted = InterruptedName(o.Output);
    const std::string checkpoint = trainer->GetCheckpointFile() ? trainer->GetCheckpointFile() : "";
    if (WriteField(trainer->GetOutput(), interrupted) != 0)
    {
      return code;
    }
    // (Data-parallel runs write no checkpoint when stopped: vtkGaussianFieldTrainer's description.)
    const bool distributed = processes.Controller && processes.Controller->GetNumberOfProcesses() > 1;
    std::fprintf(stderr, "bigus: %s at iteration %d after %.1f s: the field trained so far is in %s; %s %s\n",
      StopSignal == SIGINT ? "interrupted (SIGINT)" : "terminated (SIGTERM)", trainer->GetCompletedIterations(),
      trainer->GetTrainingSeconds(), interrupted.c_str(),
      distributed ? "a data-parallel run saves no state when stopped; the last periodic checkpoint, if any, is"
                  : "the run's state is in",
      (checkpoint + (distributed ? "" : "; go on with the same command and --resume " + checkpoint)).c_str());
    return code;
  }
  if (trainer->GetNumberOfGaussians() == 0)
  {
    const int code = Fail((processes.Rank ? "rank " + std::to_string(processes.Rank) + ": " : std::string()) +
      "training failed: " + error.Or("no field"));
    if (processes.Controller && processes.Controller->GetNumberOfProcesses() > 1)
    {
      // The trainer's failures are agreed (every rank is here): each rank says why before any ends the job
      // (Processes::Exit aborts, which could cut off a rank that had not printed yet).
      std::fflush(stdout);
      std::fflush(stderr);
      processes.Controller->Barrier();
    }
    return code;
  }
  if (processes.Rank != 0)
  {
    return 0; // every rank holds the same field; rank 0 writes it
  }
  if (WriteField(trainer->GetOutput(), o.Output) != 0)
  {
    return 1;
  }
  vtkDataArray* seeds = trainer->GetOutput()->GetFieldData()->GetArray("InitialGaussians");
  std::printf(
    "field          %s: %lld Gaussians (from %lld seeds) after %d iterations in %.1f s (stop: %s; growth: %s)\n",
    o.Output.c_str(), static_cast<long long>(trainer->GetNumberOfGaussians()),
    seeds ? static_cast<long long>(seeds->GetTuple1(0)) : 0LL, trainer->GetCompletedIterations(),
    trainer->GetTrainingSeconds(), trainer->GetStopReason(), trainer->GetGrowthStopReason());
  vtkFieldData* fd = trainer->GetOutput()->GetFieldData();
  vtkDataArray* best = fd->GetArray("BestValidationLoss");
  vtkDataArray* last = fd->GetArray("LastValidationLoss");
  vtkDataArray* joined = fd->GetArray("ValidationJoinedAt");
  if (best && last && joined && joined->GetTuple1(0) >= 0)
  {
    std::printf("early stopping on the held-out validation frames: the field of iteration %.0f (validation loss %.5f) "
                "kept when they joined the fit at iteration %.0f; %.5f at the end, fitted since\n",
      fd->GetArray("BestIteration")->GetTuple1(0), best->GetTuple1(0), joined->GetTuple1(0), last->GetTuple1(0));
  }
  else if (best && last)
  {
    // Where the parameter average made the run's last field, the field early stopping kept replaced the average.
    bool averaged = false;
    if (vtkStringArray* lines = vtkStringArray::SafeDownCast(fd->GetAbstractArray("TrainingSettings")))
    {
      for (vtkIdType i = 0; i < lines->GetNumberOfValues(); ++i)
      {
        const std::string& line = lines->GetValue(i);
        averaged = averaged ||
          (line.rfind("ParameterAverage = ", 0) == 0 && line.find("; made the field at step ") != std::string::npos);
      }
    }
    if (averaged && best->GetTuple1(0) < last->GetTuple1(0))
    {
      std::printf("early stopping kept the field of iteration %.0f over the parameter average (validation loss %.5f "
                  "against the average's %.5f)\n",
        fd->GetArray("BestIteration")->GetTuple1(0), best->GetTuple1(0), last->GetTuple1(0));
    }
    else
    {
      std::printf("early stopping %s (validation loss %.5f at iteration %.0f, %.5f at the end)\n",
        best->GetTuple1(0) < last->GetTuple1(0) ? "kept an earlier field" : "kept the last field", best->GetTuple1(0),
        fd->GetArray("BestIteration")->GetTuple1(0), last->GetTuple1(0));
    }
  }
  if (vtkAbstractArray* gaps = fd->GetAbstractArray("GapFilling"))
  {
    std::printf("gap filling    %s\n", gaps->GetVariantValue(0).ToString().c_str());
  }
  if (vtkAbstractArray* merge = fd->GetAbstractArray("GaussianMerge"))
  {
    std::printf("merge          %s\n", merge->GetVariantValue(0).ToString().c_str());
  }
  if (vtkAbstractArray* solves = fd->GetAbstractArray("ReflectivitySolves"))
  {
    std::printf("solves         %s\n", solves->GetVariantValue(0).ToString().c_str());
  }
  const std::string curve = vtkGaussianFieldTrainer::DescribeHeldOutPSNR(fd->GetArray("HeldOutPSNR"));
  if (!curve.empty())
  {
    std::printf("held-out PSNR  %s\n", curve.c_str());
  }
  std::printf("backend        %s\n", trainer->GetBackendInUse());
  if (processes.Controller && processes.Controller->GetNumberOfProcesses() > 1)
  {
    const int steps = std::max(1, trainer->GetCompletedIterations());
    std::printf("distributed    %d ranks: %.1f s of %.1f s training in sums across ranks (AllReduce, waiting "
                "included) on rank 0; %.3f MB summed per step\n",
      processes.Controller->GetNumberOfProcesses(), trainer->GetReductionSeconds(), trainer->GetTrainingSeconds(),
      trainer->GetReductionBytes() / steps / 1e6);
  }
  if (vtkDataArray* corrections = fd->GetArray("PoseCorrections"))
  {
    // Per training frame: the rotation's angle (degrees) and the translation's length (mm).
    double sum[2] = { 0, 0 }, largest[2] = { 0, 0 };
    const vtkIdType n = corrections->GetNumberOfTuples();
    for (vtkIdType i = 0; i < n; ++i)
    {
      const double* c = corrections->GetTuple(i);
      const double size[2] = { std::sqrt(c[1] * c[1] + c[2] * c[2] + c[3] * c[3]),
        std::sqrt(c[4] * c[4] + c[5] * c[5] + c[6] * c[6]) };
      for (int k = 0; k < 2; ++k)
      {
        sum[k] += size[k];
        largest[k] = std::max(largest[k], size[k]);
      }
    }
    std::printf("poses          %lld training frames refined: rotation mean %.3f, largest %.3f degrees; translation "
                "mean %.3f, largest %.3f mm\n",
      static_cast<long long>(n), sum[0] / std::max<vtkIdType>(1, n), largest[0], sum[1] / std::max<vtkIdType>(1, n),
      largest[1]);
  }
  if (vtkStringArray* lines = vtkStringArray::SafeDownCast(fd->GetAbstractArray("TrainingSettings")))
  {
    for (vtkIdType i = 0; i < lines->GetNumberOfValues(); ++i)
    {
      // What the run decided after its settings were printed: the pose-refinement trial or why it was not run (and
      // when the frames it held out joined the fit), the anchor, the route
      // trial (and, where it took the grid, the grid's own choices), the steps the parameter average took.
      const std::string& line = lines->GetValue(i);
      const bool grid = trainer->GetStopReason() &&
        std::string(trainer->GetStopReason())
            .find("the pixel grid, "
                  "measured") == 0;
      if (line.rfind("PoseAnchor = ", 0) == 0 ||
        (line.rfind("ParameterAverage = ", 0) == 0 && line.find("; made the field") != std::string::npos) ||
        (line.rfind("RefinePoses = ", 0) == 0 &&
          (line.find("measured: ") != std::string::npos || line.find("untested: ") != std::string::npos)) ||
        (line.rfind("Validation = ", 0) == 0 && line.find("; in the fit from step ") != std::string::npos) ||
        (line.rfind("Route = ", 0) == 0 && line.find("(measured on ") != std::string::npos) ||
        (grid &&
          (line.rfind("ElevationSigma = ", 0) == 0 || line.rfind("Ridge = ", 0) == 0 ||
            line.rfind("FinalPrune = ", 0) == 0 || line.rfind("Merge = ", 0) == 0)))
      {
        std::printf("               %s\n", line.c_str());
      }
    }
  }
  if (vtkDataArray* untrained = fd->GetArray("UntrainedPoseCorrection"))
  {
    const double* u = untrained->GetTuple(0); // frames, bandwidth, leave-one-out error of none, of the chosen
    char smoothing[64] = "the whole sweep";
    if (!std::isinf(u[1]))
    {
      std::snprintf(smoothing, sizeof(smoothing), "%g training-frame intervals", u[1]);
    }
    if (u[1] == 0)
    {
      std::printf(
        "               frames not trained keep their tracked poses: no smoothing of the corrections predicts "
        "a training frame's better than none (leave-one-out error %.3f mm at the corners)\n",
        u[2]);
    }
    else if (u[0] > 0)
    {
      std::printf(
        "               %.0f frames not trained take their sweep's corrections smoothed over %s (leave-one-out "
        "error %.3f mm at the corners against %.3f for none)\n",
        u[0], smoothing, u[3], u[2]);
    }
  }
  if (vtkDataArray* offset = fd->GetArray("TimeOffset"))
  {
    std::printf("time offset    %.1f ms (added to every frame's timestamp to find its tracked pose)\n",
      1000 * offset->GetTuple1(0));
  }
  if (vtkDataArray* correction = fd->GetArray("ImageToProbeCorrection"))
  {
    const double* c = correction->GetTuple(0);
    std::printf("ImageToProbe   corrected by rotation %.3f %.3f %.3f degrees about u, v, n and translation %.3f %.3f "
                "%.3f mm (field data ImageToProbeCorrectionMatrix: ImageToProbe M)\n",
      c[0], c[1], c[2], c[3], c[4], c[5]);
  }
  vtkDataArray* all = fd->GetArray("RefinedPoses");
  if (!all && !o.RefinedPoses.empty())
  {
    std::printf("refined poses  not written: every sweep's tracked poses were trusted (the RefinePoses setting line "
                "says why)\n");
  }
  if (all)
  {
    // Each input sweep with every frame's ImageToReference as refined (RefinedPoses: the sweeps' frames in turn).
    vtkIdType first = 0; // index of the sweep's first frame among all sweeps' frames
    for (std::size_t k = 0; k < o.RefinedPoses.size(); ++k)
    {
      vtkImageData* input = readers[k]->GetOutput();
      vtkSmartPointer<vtkImageData> refined = WithOwnFieldData(input);
      vtkDataArray* poses = refined->GetFieldData()->GetArray("ImageToReference");
      const vtkIdType frames = input->GetDimensions()[2];
      for (vtkIdType f = 0; f < frames && first + f < all->GetNumberOfTuples(); ++f)
      {
        poses->SetTuple(f, all->GetTuple(first + f));
      }
      first += frames;
      vtkNew<vtkUltrasoundSequenceWriter> sequenceWriter; // under temporary names, then renamed
      sequenceWriter->SetInputData(refined);
      sequenceWriter->SetFileName(o.RefinedPoses[k].c_str());
      if (!sequenceWriter->Write())
      {
        return Fail(o.RefinedPoses[k] + ": cannot write the refined sequence");
      }
      std::printf("refined poses  %s: %s with its frames' ImageToReference as refined\n", o.RefinedPoses[k].c_str(),
        o.Sweeps[k].c_str());
    }
  }
  return 0;
}
}

void SetGracefulStop(bool graceful)
{
  GracefulStop = graceful;
}

Command AddTrainCommand(CLI::App& app)
{
  auto options = std::make_shared<TrainOptions>();
  TrainOptions& train = *options;
  CLI::App* trainCommand = app.add_subcommand("train", "Train a Gaussian scattering field from a tracked sweep");
  trainCommand
    ->add_option("SWEEP", train.Sweeps,
      "Sequence metafile; several: sweeps of one region along different paths, trained into one field")
    ->required()
    ->check(CLI::ExistingFile);
  trainCommand->add_option("-o,--output", train.Output, "Field to write (.vtp)")->required();
  trainCommand
    ->add_option("--calibration", train.Calibrations,
      "PLUS device-set configuration XML (ImageToProbe): one for every sweep, or one per sweep in their order "
      "(repeat the option)")
    ->allow_extra_args(false)
    ->check(CLI::ExistingFile);
  trainCommand->add_option("--transform", train.Chain,
    "Transform chain for ImageToReference of every sweep, e.g. \"inverse(ReferenceToTracker) * ProbeToTracker * "
    "ImageToProbe\"");
  trainCommand
    ->add_option("--mask", train.Masks,
      "Fan mask .mha (W x H x 1, or W x H x N per frame; default: estimated): one for every sweep, or one per sweep "
      "(repeat the option)")
    ->allow_extra_args(false);
  trainCommand
    ->add_option("--holdout-every", train.HoldOutEvery,
      "Hold out frames with index % K == J, the index within each sweep (0: none)")
    ->check(FiniteNonNegative());
  trainCommand->add_option("--holdout-offset", train.HoldOutOffset, "J of --holdout-every (0 to K - 1)")
    ->check(FiniteNonNegative());
  trainCommand
    ->add_option("--holdout-sweep", train.HoldOutSweep,
      "Hold out every frame of sweep K (0 = the first SWEEP): leave-one-sweep-out")
    ->check(FiniteNonNegative());
  trainCommand
    ->add_option("--frames", train.Frames,
      "Train on these frames only (indices, counting the sweeps' frames in turn); the others are held out")
    ->excludes("--holdout-every");
  TrainerSettings& settings = train.Settings;
  trainCommand
    ->add_option("--time-budget", settings.TimeBudget,
      "Wall-clock budget for training, seconds (0: none); alone, it is the whole schedule (learning-rate decay, "
      "densification window) and training runs until it; the end-of-run stages (final prune, gap filling, merge) "
      "follow its last step (on the liver's 300 s, 6 to 12 s more); at most 1e7 (116 days)")
    ->check(FiniteNonNegative(1e7));
  auto* iterations =
    trainCommand
      ->add_option("--iterations", settings.Iterations, "Optimisation steps (with --time-budget: whichever ends first)")
      ->capture_default_str()
      ->check(FiniteNonNegative());
  trainCommand
    ->add_option("--max-gaussians", settings.MaximumGaussians,
      "Maximum of Gaussians of Harris seeds and Adam (gap filling's copies included); the pixel grid "
      "takes every fan pixel where memory holds them, whatever this says (the InitialGaussians line)")
    ->capture_default_str()
    ->check(FinitePositive());
  trainCommand
    ->add_option("--initial-gaussians", settings.Seeding.InitialGaussians,
      "Seeds (0: chosen from the training frames' fan pixels; the InitialGaussians setting line says how)")
    ->capture_default_str()
    ->check(FiniteNonNegative());
  trainCommand
    ->add_option("--densify-percentile", settings.Densification.Percentile,
      "Top share (percent) of the attribution score split or cloned at each densification")
    ->capture_default_str()
    ->check(FiniteRange(0.0, 100.0));
  trainCommand
    ->add_option("--growth-margin", settings.Densification.GrowthMargin,
      "Growth stops when the validation loss improves by less than this (relative) on the best so far ...")
    ->capture_default_str()
    ->check(FiniteRange(0.0, 1.0));
  trainCommand
    ->add_option(
      "--growth-patience", settings.Densification.GrowthPatience, "... over this many densification intervals in a row")
    ->capture_default_str()
    ->check(FinitePositive());
  trainCommand
    ->add_option("--residual-seeds", settings.Densification.ResidualSeedShare,
      "New Gaussians where the residual is largest at each densification, as a share of those split or cloned, "
      "their reflectivity the residual (Image-GS; 0: off)")
    ->capture_default_str()
    ->check(FiniteRange(0.0, 100.0));
  trainCommand->add_flag("--reflectivity-solve", settings.ReflectivitySolve,
    "Variable projection: solve the reflectivities by least squares after seeding and after every densification, "
    "Adam between the solves (default: Adam alone)");
  trainCommand
    ->add_option("--solve-iterations", settings.Solve.MaximumIterations,
      "CGLS iterations of each reflectivity solve (each a forward and a backward pass over every training frame)")
    ->capture_default_str()
    ->check(FinitePositive());
  trainCommand->add_flag_callback(
    "--no-held-out-choices", [&settings] { settings.HeldOut.Enabled = false; },
    "Take the rules' values untested (default: where the fit is the pixel grid's solve, candidates are each fitted "
    "without every second training frame and scored on those: ElevationSigma by rule times 1/8, 1/4, 1/2, 1 and 2 "
    "(the narrowest within 0.05 dB of the best held-out PSNR is taken), then the solve's ridge times 1, 10 and 100 "
    "(the default's unless another is more than 0.05 dB better); the final prune and the merge are then kept only "
    "where they cost at most 0.05 dB on those frames; and with a time budget, where the grid of every fan pixel fits "
    "memory and half the budget, the route is measured on held-out frames: the grid against Harris seeds and Adam, "
    "the better takes the run (where the rule takes the grid, Adam must pass it within a quarter of the budget): the "
    "Route line)");
  auto* heldOutValidation = trainCommand->add_flag_callback(
    "--held-out-validation", [&settings] { settings.HeldOut.HoldOutValidationFrames = ValidationHoldOut::On; },
    "Validate on frames held out of the fit until the densification window closes (one in 8 training frames of a "
    "sweep, or one in 4 of a short one, 4 to 8 of them), then joined to it: growth stops and early stopping keeps a "
    "field on frames the fit has not seen (default: held out where the sweeps' neighbouring training frames share "
    "no speckle, as the Validation setting line says; on training frames elsewhere)");
  trainCommand
    ->add_flag_callback(
      "--no-held-out-validation", [&settings] { settings.HeldOut.HoldOutValidationFrames = ValidationHoldOut::Off; },
      "Validate on training frames whatever the speckle (see --held-out-validation)")
    ->excludes(heldOutValidation);
  trainCommand->add_flag_callback(
    "--no-measured-tail", [&settings] { settings.HeldOut.MeasuredTail = false; },
    "Go on to the schedule's end after held-out validation frames join the fit (default: where early stopping went "
    "back to an earlier field at the join, the run stops as many steps after it as the fit took to that field, its "
    "field the last step's; the spine phantom 21.32 dB at 3,000 steps against 21.14 going on)");
  trainCommand
    ->add_option("--solve-memory", settings.Solve.AssembledMemoryShare,
      "Share of this machine's memory that a reflectivity solve may hold as the assembled basis (its products then "
      "passes over stored weights instead of renders of every training frame; where it needs more, or with 0, the "
      "products are matrix free)")
    ->capture_default_str()
    ->check(FiniteRange(0.0, 1.0));
  trainCommand
    ->add_option("--solve-l1", settings.Solve.L1,
      "An L1 term in each reflectivity solve (the pixel-grid fit's, variable projection's), as a share of the weight "
      "that sets every reflectivity to 0 (FISTA; the Gaussians it zeroes are removed and the others refitted by "
      "least squares; default 0: none, CGLS)")
    ->capture_default_str()
    ->check(FiniteRange(0.0, 1.0));
  trainCommand->add_flag_callback(
    "--dense-adam", [&settings] { settings.SparseAdam = false; },
    "Adam moves every Gaussian every step on its momentum (the ablation; default: only the Gaussians a step "
    "touched, the others keep their parameters and moments)");
  trainCommand->add_flag("--dense-start", settings.Seeding.DenseInitialisation,
    "Start from Gaussians on the training frames' pixel grid (--initial-gaussians of them, default half of "
    "--max-gaussians) instead of Harris seeds");
  trainCommand->add_flag_callback(
    "--no-pixel-grid-fit", [&settings] { settings.Seeding.PixelGridFit = false; },
    "Train from Harris seeds even when the training frames hold at most twice --max-gaussians fan pixels (default: "
    "there, a pixel grid of every fan pixel where memory holds them, its reflectivities solved, and no geometry "
    "steps)");
  CLI::Option* refine = trainCommand->add_flag_callback(
    "--refine-poses", [&settings] { settings.Poses.RefinePoses = PoseRefinement::On; },
    "Refine the tracked pose of every sweep's training frames with the field (a rigid correction about its centre "
    "pixel, a prior towards the tracked pose; default: the sweeps whose neighbouring training frames' speckle "
    "correlates, the others trusted, as the RefinePoses setting line says)");
  trainCommand
    ->add_flag_callback(
      "--no-refine-poses", [&settings] { settings.Poses.RefinePoses = PoseRefinement::Off; },
      "Trust every tracked pose (see --refine-poses)")
    ->excludes(refine);
  trainCommand->add_flag("--refine-time-offset", settings.Poses.RefineTimeOffset,
    "Refine one time offset between tracker and video shared by every frame (needs the sweeps' timestamps; found "
    "from sweeps whose frames cross, not from one smooth sweep: docs/FINDINGS.md)");
  trainCommand->add_flag("--refine-image-to-probe", settings.Poses.RefineImageToProbe,
    "Refine one correction of ImageToProbe shared by every frame (printed, and in the field data)");
  trainCommand
    ->add_option("--pose-trial-steps", settings.Poses.TrialSteps,
      "Where the default (Auto) would refine the poses: steps taken each way (on the tracked poses, with refinement) "
      "from 40 % of the schedule where the refinement's start is chosen (the given start otherwise), scored on "
      "held-out frames at "
      "their tracked poses, the better going on; where the steps left after it are fewer than 10 x N under "
      "--time-budget (4 x N without), the choice is untested: refined from the first steps where the tracked path "
      "jitters over 0.35 mm from frame to frame, the tracked poses kept elsewhere (0: the speckle rule alone; the "
      "RefinePoses setting line says what each scored, or why untested)")
    ->capture_default_str()
    ->excludes("--no-refine-poses")
    ->excludes("--refine-poses")
    ->check(FiniteNonNegative(1e6));
  trainCommand
    ->add_flag_callback(
      "--no-pose-anchor", [&settings] { settings.Poses.AnchorToTrackedPoses = false; },
      "Where every sweep's poses are refined, leave the field where the refined poses put it (default: moved at the "
      "end with every pose by the rigid motion that best maps the refined training frames onto their tracked poses, "
      "as the PoseAnchor setting line says)")
    ->excludes("--no-refine-poses");
  trainCommand
    ->add_option("--refined-poses", train.RefinedPoses,
      "Write the sweep with its frames' ImageToReference as refined (.igs.mha; held-out "
      "frames take the shared corrections and the smooth part of their sweep's); one per sweep, in their order (repeat "
      "the option)")
    ->allow_extra_args(false);
  trainCommand
    ->add_option("--pose-smoothness", settings.Poses.Smoothness,
      "Where poses are refined: weight of the prior that keeps the corrections smooth along the sweep (0: none)")
    ->excludes("--no-refine-poses")
    ->check(FiniteNonNegative());
  trainCommand
    ->add_option("--pose-refinement-start", settings.Poses.Start,
      "Where poses are refined: the share of the schedule (0 to 1) trained on the tracked poses before the corrections "
      "move; -1: chosen from the tracked path's jitter (bigus::ChoosePoseRefinementStart: 0 where it jitters over 0.35 "
      "mm from frame to frame, else 20 %), and where the default (Auto) measures the choice on a path that does not "
      "jitter, 40 %, the trial's start (its setting line says why)")
    ->capture_default_str()
    ->excludes("--no-refine-poses")
    ->check(FiniteRange(-1.0, 1.0));
  trainCommand->add_flag_callback(
    "--no-fill-gaps", [&settings] { settings.FillGaps = false; },
    "Leave gaps between training frames wider than the beam empty (default: bridged, as bigus fill-gaps does)");
  trainCommand
    ->add_option("--merge-tolerance", settings.Merge.Tolerance,
      "Last, merge neighbouring Gaussians whose moment-matched merge has a relative integrated squared error "
      "below this (as bigus merge does); 0: off")
    ->capture_default_str()
    ->check(FiniteRange(0.0, 1.0));
  trainCommand
    ->add_option("--parameter-average", settings.ParameterAverage,
      "The run's field is an exponential moving average of its parameters over the schedule's tail (from the "
      "densification window's close) with this time constant, a fraction of the schedule; 0: off, the last step's "
      "field")
    ->capture_default_str()
    ->check(FiniteRange(0.0, 1.0));
  trainCommand
    ->add_option("--elevation-sigma", settings.ElevationSigma,
      "Elevation beam sigma, mm (FWHM / 2.355); 0: chosen from the sweep (bigus::ChooseElevationSigma; its setting "
      "line "
      "says why)")
    ->capture_default_str()
    ->check(FiniteNonNegative());
  trainCommand->add_option("--backend", train.Backend, "Training backend: auto, cpu or cuda (as registered)")
    ->capture_default_str();
  trainCommand
    ->add_option("--threads", train.Threads,
      "Threads (0: all cores; with --distributed, the cores divided among the ranks on each machine)")
    ->check(FiniteNonNegative());
  trainCommand
    ->add_option("--frames-per-step", settings.FramesPerStep,
      "Training frames rendered per step (per rank with --distributed); their losses are averaged")
    ->capture_default_str()
    ->check(FiniteRange(1, 4096));
  trainCommand
    ->add_option("--training-cutoff", settings.Cutoff,
      "Footprint cut-off of a training step, standard deviations, 2 to 5 (in plane and in elevation; the field is "
      "rendered and scored at the render filters' 5 whatever this is): smaller makes a step faster and fits the "
      "footprints' tails less well (3.5: 0.81 times the time of 4 on the liver, but refined poses and the pixel-grid "
      "fit lose; docs/FINDINGS.md). 0: automatic, 3.5 where Adam steps on trusted poses, 4 where poses are refined or "
      "reflectivities solved (validation and the final prune at 4)")
    ->capture_default_str()
    ->check(CLI::Validator(
      [range = FiniteRange(2, 5)](std::string& text) mutable -> std::string {
        const std::string refused = range(text);
        char* end = nullptr;
        const bool zero = !text.empty() && std::strtod(text.c_str(), &end) == 0 && *end == '\0';
        return refused.empty() || zero ? std::string() : refused + " (or 0: automatic)";
      },
      "0 or [2, 5]"));
  trainCommand
    ->add_option("--loss-weights", train.LossWeights,
      [&settings] {
        std::ostringstream text;
        text << "The image loss's weights of L1, D-SSIM and the focal frequency loss (three numbers; default "
             << settings.Loss.L1 << " " << settings.Loss.DSSIM << " " << settings.Loss.FFL
             << "; the FFL's two DFTs cost about as much as the rest of the loss)";
        return text.str();
      }())
    ->expected(3)
    ->check(FiniteNonNegative(100));
  trainCommand
    ->add_option("--coarse-fraction", settings.CoarseFraction,
      "The resolution schedule: the first fraction (0 to 1) of the schedule steps on every second pixel and row of "
      "its frames; 0: off")
    ->capture_default_str()
    ->check(FiniteRange(0.0, 1.0));
  trainCommand
    ->add_flag("--coarse-low-pass", settings.CoarseLowPass,
      "The coarse steps' frames as 2 x 2 averages, each Gaussian rendered through the pixel's low-pass, instead of "
      "point samples")
    ->capture_default_str();
  trainCommand->add_flag("--distributed", train.Distributed,
    "Under mpirun -n P: data-parallel training, each rank renders its share of every step's frames and the "
    "gradients are summed every step (MPI_Allreduce through vtkMPIController); rank 0 writes the field and "
    "checkpoints. Resume with the same P");
  trainCommand->add_option("--seed", settings.Seed, "Random seed")->capture_default_str();
  trainCommand->add_option("--checkpoint", train.Checkpoint,
    "Checkpoint file, written every --checkpoint-interval steps (and when SIGINT or SIGTERM stops the run; without "
    "this option that one goes to OUTPUT.checkpoint)");
  trainCommand
    ->add_option("--checkpoint-interval", train.CheckpointInterval, "Steps between checkpoints (0: only on a signal)")
    ->capture_default_str()
    ->needs("--checkpoint")
    ->check(FiniteNonNegative(1e9));
  trainCommand
    ->add_option("--resume", train.Resume,
      "Continue from this checkpoint (the same sweeps and settings, else refused naming the difference; a longer "
      "schedule is fine; the seconds trained before it count towards --time-budget)")
    ->check(CLI::ExistingFile);
  trainCommand
    ->add_option("--evaluate-every", train.EvaluationInterval,
      "Record the held-out PSNR every S seconds (field data HeldOutPSNR: seconds, dB, iteration; 0: never); the "
      "run's summary then says its best and last point, and whether more steps lowered it (overfitting)")
    ->check(FiniteNonNegative());
  return { trainCommand, [options, iterations] {
            TrainOptions& train = *options;
            if (iterations->count() == 0 && train.Settings.TimeBudget > 0)
            {
              train.Settings.Iterations = 0; // the budget alone is the schedule
            }
            return RunTrain(train);
          } };
}

} // namespace bigus::cli
