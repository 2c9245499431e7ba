// `bigus benchmark` (bigusBenchmark.h): running the trainer for the sections: to time marks, to a time budget
// through Finish, and one run of an ablation or Pareto experiment.
#ifndef bigusBenchmarkRuns_h
#define bigusBenchmarkRuns_h

#include "bigusBenchmarkSweeps.h"
#include "bigusTrainer.h"

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace bigus::benchmark
{
/// The training backend of every run of this process (BenchmarkOptions::Backend; "cpu" until set).
void SetTrainingBackend(const std::string& name);
const std::string& TrainingBackend();

/// A trainer of @p data with @p settings on the engine of @p backend (CreateTrainingEngine); null with @p error where
/// that backend cannot run here.
std::unique_ptr<Trainer> MakeTrainer(const TrainingData& data, const TrainerSettings& settings, std::string* error,
  const std::string& backend = TrainingBackend());

/// Trains with @p settings, evaluating @p heldOut at each of @p marks (cumulative training seconds);
/// @p onMark is called with the mark, its row (measured time) and the trainer, and returns false (with
/// @p error) when its own measurement fails. The field is not pruned at the marks (Trainer::Train).
/// Returns false on a training error. On the engine of @p backend.
bool TrainWithMarks(const TrainingData& data, const TrainerSettings& settings, const std::vector<double>& marks,
  const std::vector<int>& heldOut, const std::string& method,
  const std::function<bool(double, const Row&, Trainer&)>& onMark, std::string* error,
  const std::string& backend = TrainingBackend());

/// Trains @p data with @p settings through Finish (early stopping, final prune, gap filling) and fills
/// @p row (method, time, Gaussians, peak memory, a note with the steps and the sigma used); then
/// @p evaluate scores the finished field into the row (and may copy it).
bool TrainToBudget(const TrainingData& data, const TrainerSettings& settings, const std::string& method, Row& row,
  const std::function<bool(Trainer&, Row&)>& evaluate, std::string* error);

/// TrainToBudget on a hold-out sweep, scored on its held-out frames.
bool TrainToBudget(
  const Sweep& sweep, const TrainerSettings& settings, const std::string& method, Row& row, std::string* error);

/// One sweep of the ablation section: where the field is trained and where it is scored.
struct AblationExperiment
{
  std::string Name;
  const TrainingData* Train = nullptr; ///< TrainFrames: the frames trained on
  const TrainingData* Test = nullptr;  ///< the held-out frames' data (Train itself for a hold-out sweep)
  std::vector<int> TestFrames;         ///< scored held out
  std::vector<int> FitFrames;          ///< training frames scored for the fit (every 4th)
  double Seconds = 60;                 ///< training time of the equal-time table
};

/// A bundled sweep with its hold-out protocol (frames i mod 4 == 2 scored).
AblationExperiment HoldOutExperiment(const Sweep& sweep, double seconds);

/// The volume protocol: trained on the parallel slices, scored on the in-between slices.
AblationExperiment VolumeExperiment(const VolumeProtocol& vp, double seconds);

/// One training run of the ablation section: the settings' schedule to its end, then the final prune.
struct AblationRun
{
  ImageMetrics HeldOut;
  double Fit = NaN; ///< PSNR of the training frames (dB)
  double Gaussians = 0;
  double Seeds = 0;
  double Steps = 0;
  double Seconds = 0; ///< wall clock: initialisation, training and final prune
};

/// @p train false: the seeded field (Initialize: seeds and their reflectivities) goes straight to Finish.
bool RunAblation(const AblationExperiment& e, const TrainerSettings& settings, AblationRun& run, std::string* error,
  bool train = true);
}

#endif
