// `bigus benchmark`: running the trainer for the sections (bigusBenchmarkRuns.h).
#include "bigusBenchmarkRuns.h"

namespace bigus::benchmark
{
namespace
{
std::string Backend = "cpu";

/// Every 4th training frame of @p e, scored for the fit.
void SetFitFrames(AblationExperiment& e)
{
  for (std::size_t k = 0; k < e.Train->TrainFrames.size(); k += 4)
  {
    e.FitFrames.push_back(e.Train->TrainFrames[k]);
  }
}
}

void SetTrainingBackend(const std::string& name)
{
  Backend = name;
}

const std::string& TrainingBackend()
{
  return Backend;
}

std::unique_ptr<Trainer> MakeTrainer(
  const TrainingData& data, const TrainerSettings& settings, std::string* error, const std::string& backend)
{
  std::unique_ptr<TrainingEngine> engine = CreateTrainingEngine(backend, error);
  if (!engine)
  {
    return nullptr;
  }
  return std::unique_ptr<Trainer>(new Trainer(data, settings, std::move(engine)));
}

bool TrainWithMarks(const TrainingData& data, const TrainerSettings& settings, const std::vector<double>& marks,
  const std::vector<int>& heldOut, const std::string& method,
  const std::function<bool(double, const Row&, Trainer&)>& onMark, std::string* error, const std::string& backend)
{
  ResetPeakMemory();
  std::unique_ptr<Trainer> made = MakeTrainer(data, settings, error, backend);
  if (!made)
  {
    return false;
  }
  Trainer& trainer = *made;
  double trained = 0;
  double t0 = Now();
  // Iterations 0: no step limit (TimeBudget is the schedule), the marks decide.
  auto scheduleLeft = [&]() { return settings.Iterations <= 0 || trainer.GetIteration() < settings.Iterations; };
  if (!trainer.Initialize(error))
  {
    return false;
  }
  trained += Now() - t0;
  for (double mark : marks)
  {
    const double start = Now();
    const double slice = mark - trained;
    // A mark waits for the field to settle (Trainer::IsSettled: out of the pose trial and of a densification's dip),
    // so that a row scores what the run goes on from; its time is the time it stopped.
    if (slice > 0 && scheduleLeft() &&
      !trainer.Train(
        nullptr, [&]() { return Now() - start >= slice && trainer.IsSettled(); }, error))
    {
      return false;
    }
    trained += Now() - start;
    Row r;
    r.Method = method;
    r.Seconds = trained;
    double secondsPerFrame = 0;
    if (!trainer.Evaluate(heldOut, r.Quality, error, &secondsPerFrame))
    {
      return false;
    }
    r.MsPerFrame = 1e3 * secondsPerFrame;
    r.Gaussians = trainer.GetField().Count();
    r.PeakMiB = PeakMemoryMiB();
    r.Note = std::to_string(trainer.GetIteration()) + " steps";
    if (!onMark(mark, r, trainer))
    {
      return false;
    }
    if (!scheduleLeft())
    {
      break; // the schedule ended before the later marks: they would repeat this row
    }
  }
  return true;
}

bool TrainToBudget(const TrainingData& data, const TrainerSettings& settings, const std::string& method, Row& row,
  const std::function<bool(Trainer&, Row&)>& evaluate, std::string* error)
{
  ResetPeakMemory();
  const double start = Now();
  std::unique_ptr<Trainer> made = MakeTrainer(data, settings, error);
  if (!made)
  {
    return false;
  }
  Trainer& trainer = *made;
  if (!trainer.Initialize(error) || !trainer.Train(nullptr, nullptr, error) || !trainer.Finish(error))
  {
    return false;
  }
  row.Method = method;
  row.Seconds = Now() - start;
  const TrainerReport& report = trainer.GetReport();
  row.Gaussians = trainer.GetField().Count();
  row.PeakMiB = PeakMemoryMiB();
  row.Note = std::to_string(report.Iterations) + " steps, sigma " + Format("%.3f", report.ElevationSigma) + " mm" +
    (report.BestIteration < report.Iterations ? ", field of step " + std::to_string(report.BestIteration) + " kept"
                                              : "");
  return evaluate(trainer, row);
}

bool TrainToBudget(
  const Sweep& sweep, const TrainerSettings& settings, const std::string& method, Row& row, std::string* error)
{
  return TrainToBudget(
    sweep.Data, settings, method, row,
    [&](Trainer& trainer, Row& r) {
      double secondsPerFrame = 0;
      const bool ok = trainer.Evaluate(sweep.HeldOut, r.Quality, error, &secondsPerFrame);
      r.MsPerFrame = 1e3 * secondsPerFrame;
      return ok;
    },
    error);
}

AblationExperiment HoldOutExperiment(const Sweep& sweep, double seconds)
{
  AblationExperiment e;
  e.Name = sweep.Name;
  e.Train = e.Test = &sweep.Data;
  e.TestFrames = sweep.HeldOut;
  e.Seconds = seconds;
  SetFitFrames(e);
  return e;
}

AblationExperiment VolumeExperiment(const VolumeProtocol& vp, double seconds)
{
  AblationExperiment e;
  e.Name = "volume protocol (in-between slices)";
  e.Train = &vp.TrainData;
  e.Test = &vp.TestData[0];
  e.TestFrames = vp.TestList[0];
  e.Seconds = seconds;
  SetFitFrames(e);
  return e;
}

bool RunAblation(
  const AblationExperiment& e, const TrainerSettings& settings, AblationRun& run, std::string* error, bool train)
{
  const double start = Now();
  std::unique_ptr<Trainer> made = MakeTrainer(*e.Train, settings, error);
  if (!made)
  {
    return false;
  }
  Trainer& trainer = *made;
  if (!trainer.Initialize(error) || (train && !trainer.Train(nullptr, nullptr, error)) || !trainer.Finish(error))
  {
    return false;
  }
  run.Seconds = Now() - start;
  ImageMetrics fit;
  if (!trainer.EvaluateOn(*e.Test, e.TestFrames, run.HeldOut, error) || !trainer.Evaluate(e.FitFrames, fit, error))
  {
    return false;
  }
  run.Fit = fit.PSNR;
  run.Gaussians = static_cast<double>(trainer.GetField().Count());
  run.Seeds = static_cast<double>(trainer.GetReport().InitialGaussians);
  run.Steps = trainer.GetReport().Iterations;
  return true;
}
}
