#include "vtkGaussianFieldTrainer.h"

#include "bigusGaussianFieldData.h"
#include "bigusTrainer.h"
#include "bigusTrainingEngine.h"
#include "vtkUltrasoundFanMask.h"

#include "vtkDataArray.h"
#include "vtkDoubleArray.h"
#include "vtkFieldData.h"
#include "vtkMath.h"
#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkInformation.h"
#include "vtkInformationVector.h"
#include "vtkIntArray.h"
#include "vtkMatrix4x4.h"
#include "vtkMultiProcessController.h"
#include "vtkNew.h"
#include "vtkObjectFactory.h"
#include "vtkPointData.h"
#include "vtkPolyData.h"
#include "vtkStreamingDemandDrivenPipeline.h"
#include "vtkStringArray.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

vtkStandardNewMacro(vtkGaussianFieldTrainer);
vtkCxxSetObjectMacro(vtkGaussianFieldTrainer, Controller, vtkMultiProcessController);

namespace
{
/// The sums of data-parallel training (bigus::ProcessReduction) over a VTK controller's processes.
class ControllerReduction : public bigus::ProcessReduction
{
public:
  explicit ControllerReduction(vtkMultiProcessController* controller)
    : Controller(controller)
  {
  }
  int Rank() const override { return this->Controller->GetLocalProcessId(); }
  int Size() const override { return this->Controller->GetNumberOfProcesses(); }
  bool Sum(float* values, std::size_t count, std::string* error) override
  {
    return this->Reduce(values, count, vtkCommunicator::SUM_OP, error);
  }
  bool Sum(double* values, std::size_t count, std::string* error) override
  {
    return this->Reduce(values, count, vtkCommunicator::SUM_OP, error);
  }
  bool Maximum(double* values, std::size_t count, std::string* error) override
  {
    return this->Reduce(values, count, vtkCommunicator::MAX_OP, error);
  }
  bool Maximum(unsigned char* values, std::size_t count, std::string* error) override
  {
    return this->Reduce(values, count, vtkCommunicator::MAX_OP, error);
  }
  double Seconds = 0; ///< wall-clock seconds inside AllReduce (waiting for the slowest process included)
  double Bytes = 0;   ///< bytes this process contributed to the sums

private:
  template <typename T>
  bool Reduce(T* values, std::size_t count, int operation, std::string* error)
  {
    const auto start = std::chrono::steady_clock::now();
    const std::vector<T> mine(values, values + count);
    const bool ok = this->Controller->AllReduce(mine.data(), values, static_cast<vtkIdType>(count), operation) != 0;
    this->Seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    this->Bytes += static_cast<double>(count * sizeof(T));
    if (!ok)
    {
      if (error)
      {
        *error = "the sum across processes (AllReduce of " + std::to_string(count) + " values) failed on rank " +
          std::to_string(this->Rank());
      }
      return false;
    }
    return true;
  }
  vtkMultiProcessController* Controller;
};

/// How the field data stores a pose correction (bigus::CorrectPose's xi: rotation vector, rad; translation, mm):
/// these six components, written by StoredCorrection.
const char* const CorrectionComponents[6] = { "RotationU (degrees)", "RotationV (degrees)", "RotationN (degrees)",
  "TranslationU (mm)", "TranslationV (mm)", "TranslationN (mm)" };

void StoredCorrection(const std::array<double, 6>& xi, double stored[6])
{
  const double degrees = 180.0 / vtkMath::Pi();
  for (int k = 0; k < 6; ++k)
  {
    stored[k] = k < 3 ? xi[k] * degrees : xi[k];
  }
}

/// What vtkGaussianFieldTrainer trains on, read from its input ports.
struct TrainerInputs
{
  bigus::TrainingData Data;      ///< every sweep's frames in turn, with the training frames chosen
  std::vector<bool> Valid;       ///< per frame of all sweeps: FrameValid
  std::vector<int> IndexInSweep; ///< per frame of all sweeps: its index in its own sweep
  int SweepCount = 0, MaskCount = 0;
};

/// The sweeps (port 0) and their fan masks (port 1) as training data, with the training frames that the hold-out
/// settings (or @p frameList) leave; false with @p error (the filter's message) when the inputs are refused.
bool ReadTrainerInputs(vtkInformationVector** inputVector, int holdOutEvery, int holdOutOffset, int holdOutSweep,
  vtkIdList* frameList, TrainerInputs& in, std::string& error)
{
  // The sweeps (port 0) and their fan masks (port 1: none, every one estimated, or one per sweep).
  const int sweepCount = in.SweepCount = inputVector[0]->GetNumberOfInformationObjects();
  const int maskCount = in.MaskCount = inputVector[1]->GetNumberOfInformationObjects();
  if (!bigus::CheckMaskCount(maskCount, sweepCount, &error))
  {
    return false;
  }
  std::vector<vtkSmartPointer<vtkImageData>> masks(sweepCount);
  std::vector<bigus::SweepInput> sweeps(sweepCount);
  for (int k = 0; k < sweepCount; ++k)
  {
    vtkImageData* sequence = vtkImageData::GetData(inputVector[0], k);
    masks[k] = maskCount ? vtkImageData::GetData(inputVector[1], k) : nullptr;
    if (!masks[k] && sequence)
    {
      vtkNew<vtkUltrasoundFanMask> estimate;
      estimate->SetInputData(sequence);
      estimate->Update();
      masks[k] = estimate->GetOutput();
    }
    sweeps[k] = { sequence, masks[k], sweepCount > 1 ? "sweep " + std::to_string(k) : std::string("input") };
    int dims[3] = { 0, 0, 0 };
    if (sequence)
    {
      sequence->GetDimensions(dims);
    }
    vtkDataArray* isValid = sequence ? sequence->GetFieldData()->GetArray("FrameValid") : nullptr;
    for (int f = 0; f < dims[2]; ++f)
    {
      in.Valid.push_back(!isValid || isValid->GetNumberOfTuples() != dims[2] || isValid->GetTuple1(f) != 0);
      in.IndexInSweep.push_back(f);
    }
  }
  bigus::TrainingData& data = in.Data;
  if (!bigus::TrainingDataFromSweeps(sweeps, data, &error))
  {
    return false;
  }
  if (holdOutSweep >= sweepCount)
  {
    error = "HoldOutSweep " + std::to_string(holdOutSweep) + ": there are " + std::to_string(sweepCount) +
      " sweeps (0 to " + std::to_string(sweepCount - 1) + ")";
    return false;
  }
  std::vector<vtkIdType> listed;
  if (!bigus::ChosenFrames(frameList, data.Count(), listed, &error))
  {
    error = "TrainingFrameList: " + error;
    return false;
  }
  for (int k = 0; k < data.Count(); ++k)
  {
    bool train = in.Valid[k] && data.SweepOf(k) != holdOutSweep;
    if (frameList && frameList->GetNumberOfIds() > 0)
    {
      train = train && frameList->IsId(k) >= 0;
    }
    else if (holdOutEvery > 0)
    {
      train = train && in.IndexInSweep[k] % holdOutEvery != holdOutOffset;
    }
    if (train)
    {
      data.TrainFrames.push_back(k);
    }
  }
  if (data.TrainFrames.empty())
  {
    error = "no valid training frames (" + std::to_string(data.Count()) + " frames in the input)";
    return false;
  }
  return true;
}
}
vtkCxxSetObjectMacro(vtkGaussianFieldTrainer, TrainingFrameList, vtkIdList);

vtkGaussianFieldTrainer::vtkGaussianFieldTrainer()
{
  this->SetNumberOfInputPorts(2);
  this->SetBackend("auto");
  // One place for the defaults: the trainer's own (RequestData hands these back to it).
  const bigus::TrainerSettings d;
  this->ElevationSigma = d.ElevationSigma;
  this->BeamIntegration = d.BeamIntegration;
  this->NonNegativeReflectivity = d.NonNegativeReflectivity;
  this->HarrisInitialisation = d.HarrisInitialisation;
  this->Densify = d.Densify;
  this->ReflectivitySolve = d.ReflectivitySolve;
  this->SolveIterations = d.Solve.MaximumIterations;
  this->SolveL1 = d.Solve.L1;
  this->DenseInitialisation = d.DenseInitialisation;
  this->PixelGridFit = d.PixelGridFit;
  this->RefinePoses = static_cast<int>(d.RefinePoses);
  this->PoseSmoothness = d.PoseSmoothness;
  this->PoseRefinementStart = d.PoseRefinementStart;
  this->RefineTimeOffset = d.RefineTimeOffset;
  this->RefineImageToProbe = d.RefineImageToProbe;
  this->SparseAdam = d.SparseAdam;
  this->Iterations = d.Iterations;
  this->TimeBudget = d.TimeBudget;
  this->ConvergenceTolerance = d.ConvergenceTolerance;
  this->InitialGaussians = d.InitialGaussians;
  this->MaximumGaussians = d.MaximumGaussians;
  this->LossWeights[0] = d.Loss.L1;
  this->LossWeights[1] = d.Loss.DSSIM;
  this->LossWeights[2] = d.Loss.FFL;
  this->DensifyStart = d.DensifyStart;
  this->DensifyEnd = d.DensifyEnd;
  this->DensifyInterval = d.DensifyInterval;
  this->DensifyPercentile = d.DensifyPercentile;
  this->ResidualSeedShare = d.ResidualSeedShare;
  this->CoarseFraction = d.CoarseFraction;
  this->CoarseLowPass = d.CoarseLowPass;
  this->GrowthMargin = d.GrowthMargin;
  this->GrowthPatience = d.GrowthPatience;
  this->FillGaps = d.FillGaps;
  this->MergeTolerance = d.Merge.Tolerance;
  this->Seed = d.Seed;
}

vtkGaussianFieldTrainer::~vtkGaussianFieldTrainer()
{
  this->SetTrainingFrameList(nullptr);
  this->SetCheckpointFile(nullptr);
  this->SetResumeFile(nullptr);
  this->SetBackend(nullptr);
  this->SetController(nullptr);
}

int vtkGaussianFieldTrainer::FillInputPortInformation(int port, vtkInformation* info)
{
  info->Set(vtkAlgorithm::INPUT_REQUIRED_DATA_TYPE(), "vtkImageData");
  info->Set(vtkAlgorithm::INPUT_IS_REPEATABLE(), 1);
  if (port == 1)
  {
    info->Set(vtkAlgorithm::INPUT_IS_OPTIONAL(), 1);
  }
  return 1;
}

int vtkGaussianFieldTrainer::RequestInformation(
  vtkInformation*, vtkInformationVector**, vtkInformationVector* outputVector)
{
  // The executive copies the input image's WHOLE_EXTENT to the output by default; a consumer of the
  // field (an image filter that fails its own RequestInformation) would otherwise inherit it.
  outputVector->GetInformationObject(0)->Remove(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT());
  return 1;
}

int vtkGaussianFieldTrainer::RequestUpdateExtent(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector*)
{
  // The trainer needs every frame whatever a consumer of the field asks for (as the other sequence
  // filters here do); the default would copy the output's update request upstream.
  for (int port = 0; port < 2; ++port)
  {
    for (int c = 0; c < inputVector[port]->GetNumberOfInformationObjects(); ++c)
    {
      vtkInformation* inInfo = inputVector[port]->GetInformationObject(c);
      if (inInfo->Has(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT()))
      {
        inInfo->Set(vtkStreamingDemandDrivenPipeline::UPDATE_EXTENT(),
          inInfo->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT()), 6);
      }
    }
  }
  return 1;
}

int vtkGaussianFieldTrainer::RequestData(
  vtkInformation*, vtkInformationVector** inputVector, vtkInformationVector* outputVector)
{
  vtkPolyData* output = vtkPolyData::GetData(outputVector, 0);
  this->StopReason.clear();
  this->GrowthStopReason.clear();
  this->SettingsText.clear();
  this->NumberOfGaussians = 0;
  this->BackendInUse.clear();

  // Data-parallel: a process whose inputs are refused, or that has no such backend, fails every process here
  // (ProcessReduction::AllSucceeded), before the trainer's first sum, instead of leaving them waiting for it.
  TrainerInputs in;
  std::string error;
  bool ready = ReadTrainerInputs(inputVector, this->HoldOutEvery, this->HoldOutOffset, this->HoldOutSweep,
    this->TrainingFrameList, in, error);
  bigus::TrainingData& data = in.Data;
  const int sweepCount = in.SweepCount, maskCount = in.MaskCount;

  bigus::TrainerSettings s;
  s.ElevationSigma = this->ElevationSigma;
  s.BeamIntegration = this->BeamIntegration;
  s.NonNegativeReflectivity = this->NonNegativeReflectivity;
  s.HarrisInitialisation = this->HarrisInitialisation;
  s.Densify = this->Densify;
  s.ReflectivitySolve = this->ReflectivitySolve;
  s.Solve.MaximumIterations = this->SolveIterations;
  s.Solve.L1 = this->SolveL1;
  s.DenseInitialisation = this->DenseInitialisation;
  s.PixelGridFit = this->PixelGridFit;
  s.RefinePoses = static_cast<bigus::PoseRefinement>(this->RefinePoses);
  s.PoseSmoothness = this->PoseSmoothness;
  s.PoseRefinementStart = this->PoseRefinementStart;
  s.RefineTimeOffset = this->RefineTimeOffset;
  s.RefineImageToProbe = this->RefineImageToProbe;
  s.SparseAdam = this->SparseAdam;
  s.InitialGaussians = this->InitialGaussians;
  s.MaximumGaussians = this->MaximumGaussians;
  s.Iterations = this->Iterations;
  s.TimeBudget = this->TimeBudget;
  s.ConvergenceTolerance = this->ConvergenceTolerance;
  s.Loss.L1 = this->LossWeights[0];
  s.Loss.DSSIM = this->LossWeights[1];
  s.Loss.FFL = this->LossWeights[2];
  s.DensifyStart = this->DensifyStart;
  s.DensifyEnd = this->DensifyEnd;
  s.DensifyInterval = this->DensifyInterval;
  s.DensifyPercentile = this->DensifyPercentile;
  s.ResidualSeedShare = this->ResidualSeedShare;
  s.GrowthMargin = this->GrowthMargin;
  s.GrowthPatience = this->GrowthPatience;
  s.FillGaps = this->FillGaps;
  s.Merge.Tolerance = this->MergeTolerance;
  s.Seed = this->Seed;
  s.FramesPerStep = this->FramesPerStep;
  s.CoarseFraction = this->CoarseFraction;
  s.CoarseLowPass = this->CoarseLowPass;
  s.CheckpointInterval = this->CheckpointInterval;
  s.CheckpointFile = this->CheckpointFile ? this->CheckpointFile : "";

  std::string notice;
  std::unique_ptr<bigus::TrainingEngine> engine;
  if (ready)
  {
    engine = bigus::CreateTrainingEngine(this->Backend ? this->Backend : "auto", &error, &notice);
    ready = engine != nullptr;
    error = ready ? error : "Backend: " + error;
  }
  ControllerReduction reduction(this->Controller);
  if (this->Controller && this->Controller->GetNumberOfProcesses() > 1)
  {
    ready = reduction.AllSucceeded(ready, &error);
  }
  if (!ready)
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  if (!notice.empty())
  {
    vtkWarningMacro("Backend auto: " << notice);
  }
  this->BackendInUse = engine->GetName();
  bigus::Trainer trainer(std::move(data), s, std::move(engine));
  if ((this->Controller && !trainer.SetProcessReduction(&reduction, &error)) || !trainer.Initialize(&error) ||
    (this->ResumeFile && *this->ResumeFile && !trainer.LoadCheckpoint(this->ResumeFile, &error)))
  {
    vtkErrorMacro(<< error);
    return 0;
  }
  std::vector<std::string> settings = trainer.GetReport().Settings;
  {
    const bigus::TrainingData& d = trainer.GetData();
    const double imaged =
      static_cast<double>(std::count_if(d.Mask.begin(), d.Mask.end(), [](unsigned char v) { return v != 0; }));
    char text[200];
    std::snprintf(text, sizeof(text), "FanMask = %s, %.1f %% of the frame%s",
      maskCount ? "given (input port 1)" : "estimated from the frames (vtkUltrasoundFanMask)",
      100 * imaged / std::max<std::size_t>(1, d.Mask.size()),
      d.Mask.size() == std::size_t(d.Width) * d.Height ? "" : " (one per frame, mean)");
    settings.insert(settings.begin(), text);
  }
  for (const std::string& line : settings)
  {
    this->SettingsText += line + "\n";
  }
  this->InvokeEvent(SettingsChosenEvent, nullptr);
  // Held-out frames for the evaluation: valid, not trained on.
  std::vector<int> heldOut;
  for (int k = 0; k < trainer.GetData().Count(); ++k)
  {
    if (in.Valid[k] && !std::binary_search(trainer.GetData().TrainFrames.begin(), trainer.GetData().TrainFrames.end(), k))
    {
      heldOut.push_back(k);
    }
  }
  vtkNew<vtkDoubleArray> history;
  history->SetName("HeldOutPSNR");
  history->SetNumberOfComponents(2);
  const auto start = std::chrono::steady_clock::now();
  double nextEvaluation = 0;
  std::string evaluationError; // a held-out frame the renderer refused stops the run
  auto evaluate = [&]() {
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    bigus::ImageMetrics metrics;
    if (!trainer.Evaluate(heldOut, metrics, &evaluationError))
    {
      evaluationError = "held-out evaluation: " + evaluationError;
      return false;
    }
    const double row[2] = { seconds, metrics.PSNR };
    history->InsertNextTuple(row);
    return true;
  };
  const bool ok = trainer.Run(
    [&](double fraction, int iteration, double loss, std::int64_t gaussians) {
      this->CurrentIteration = iteration;
      this->CurrentLoss = loss;
      this->CurrentNumberOfGaussians = gaussians;
      this->UpdateProgress(fraction);
      if (this->EvaluationInterval > 0 && !heldOut.empty() && evaluationError.empty() &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= nextEvaluation)
      {
        evaluate();
        nextEvaluation += this->EvaluationInterval;
      }
    },
    [&]() { return this->AbortExecute != 0 || !evaluationError.empty(); }, &error);
  if (ok && evaluationError.empty() && this->EvaluationInterval > 0 && !heldOut.empty())
  {
    evaluate();
  }
  if (!ok || !evaluationError.empty())
  {
    vtkErrorMacro(<< (ok ? evaluationError : error));
    return 0;
  }

  const bigus::TrainerReport& report = trainer.GetReport();
  const bigus::TrainerSettings& used = trainer.GetSettings(); // RefinePoses Auto resolved
  bigus::FieldModel model;
  model.ElevationSigma = bigus::EffectiveElevationSigma(trainer.Options());
  model.Gamma = trainer.GetGamma();
  model.PixelSpacing = trainer.GetPixelSpacing();
  bigus::FieldToPolyData(trainer.GetField(), model, output);
  bigus::TrainingGeometryToFieldData(bigus::TrainingGeometryOf(trainer.GetData()), output->GetFieldData());
  const vtkIdType n = trainer.GetField().Count();

  auto addValue = [&](const char* name, double value) {
    vtkNew<vtkDoubleArray> a;
    a->SetName(name);
    a->InsertNextValue(value);
    output->GetFieldData()->AddArray(a);
  };
  auto addText = [&](const char* name, const std::string& text) {
    vtkNew<vtkStringArray> a;
    a->SetName(name);
    a->InsertNextValue(text);
    output->GetFieldData()->AddArray(a);
  };
  addValue("InitialGaussians", static_cast<double>(report.InitialGaussians));
  addValue("Iterations", report.Iterations);
  addValue("TrainingSeconds", report.Seconds);
  addValue("BestIteration", report.BestIteration);
  addValue("BestValidationLoss", report.BestValidationLoss);
  addValue("LastValidationLoss", report.LastValidationLoss);
  vtkNew<vtkDoubleArray> validationHistory;
  validationHistory->SetName("ValidationHistory");
  validationHistory->SetNumberOfComponents(3);
  validationHistory->SetComponentName(0, "Iteration");
  validationHistory->SetComponentName(1, "Loss");
  validationHistory->SetComponentName(2, "Gaussians");
  for (const bigus::TrainerReport::ValidationRecord& v : report.ValidationHistory)
  {
    const double tuple[3] = { double(v.Iteration), v.Loss, double(v.Gaussians) };
    validationHistory->InsertNextTuple(tuple);
  }
  output->GetFieldData()->AddArray(validationHistory);
  bigus::GapFillingSettings gaps;
  gaps.MaximumGaussians = this->MaximumGaussians;
  addText("GapFilling", this->FillGaps ? bigus::DescribeGapFilling(report.GapFilling, gaps) : std::string("off"));
  bigus::GaussianMergeSettings merge;
  merge.Tolerance = this->MergeTolerance;
  addText("GaussianMerge", merge.Tolerance > 0 ? bigus::DescribeGaussianMerge(report.Merge, merge) : std::string("off"));
  if (report.Solves > 0)
  {
    const bigus::ReflectivitySolveReport& last = report.LastSolve;
    char text[300];
    std::snprintf(text, sizeof(text), "%d in %.1f s; the last: %d CGLS iterations%s, objective %.4g -> %.4g",
      report.Solves, report.SolveSeconds, last.Iterations,
      last.TimeLimitReached ? " (ended by its share of the time budget)" : "",
      last.Objective.empty() ? 0.0 : last.Objective.front(), last.Objective.empty() ? 0.0 : last.Objective.back());
    std::string solves = text;
    if (report.LastL1Solve.L1Weight > 0)
    {
      std::snprintf(text, sizeof(text),
        " (least squares on the Gaussians kept by FISTA with the L1 term: %d iterations, %lld Gaussians set to 0 and "
        "removed)",
        report.LastL1Solve.Iterations, static_cast<long long>(report.LastL1Removed));
      solves += text;
    }
    addText("ReflectivitySolves", solves);
  }
  addText("StopReason", report.StopReason);
  addText("GrowthStopReason", report.GrowthStopReason);
  addText("Backend", this->BackendInUse);
  vtkNew<vtkStringArray> settingsArray;
  settingsArray->SetName("TrainingSettings");
  for (const std::string& line : settings)
  {
    settingsArray->InsertNextValue(line);
  }
  output->GetFieldData()->AddArray(settingsArray);
  vtkNew<vtkIntArray> frames;
  frames->SetName("TrainingFrames");
  for (int f : trainer.GetData().TrainFrames)
  {
    frames->InsertNextValue(f);
  }
  output->GetFieldData()->AddArray(frames);
  if (sweepCount > 1)
  {
    // The sweep of each training frame and its index there (TrainingFrames counts the sweeps' frames in turn).
    vtkNew<vtkIntArray> trainingSweeps;
    trainingSweeps->SetName("TrainingSweeps");
    trainingSweeps->SetNumberOfComponents(2);
    trainingSweeps->SetComponentName(0, "Sweep");
    trainingSweeps->SetComponentName(1, "Frame");
    for (int f : trainer.GetData().TrainFrames)
    {
      const int tuple[2] = { trainer.GetData().SweepOf(f), in.IndexInSweep[f] };
      trainingSweeps->InsertNextTypedTuple(tuple);
    }
    output->GetFieldData()->AddArray(trainingSweeps);
  }
  if (!report.PoseCorrections.empty())
  {
    vtkNew<vtkDoubleArray> corrections;
    corrections->SetName("PoseCorrections");
    corrections->SetNumberOfComponents(7);
    corrections->SetComponentName(0, "Frame");
    for (int k = 0; k < 6; ++k)
    {
      corrections->SetComponentName(k + 1, CorrectionComponents[k]);
    }
    for (const bigus::TrainerReport::PoseCorrection& p : report.PoseCorrections)
    {
      double tuple[7] = { double(p.Frame) };
      StoredCorrection(p.Xi, tuple + 1);
      corrections->InsertNextTuple(tuple);
    }
    output->GetFieldData()->AddArray(corrections);
  }
  if (used.RefinePoses == bigus::PoseRefinement::On)
  {
    const bigus::UntrainedCorrection& u = report.UntrainedCorrections;
    vtkNew<vtkDoubleArray> untrained;
    untrained->SetName("UntrainedPoseCorrection");
    untrained->SetNumberOfComponents(4);
    const char* names[4] = { "Frames", "Bandwidth (training-frame intervals)", "LeaveOneOutErrorNone (mm)",
      "LeaveOneOutErrorChosen (mm)" };
    for (int k = 0; k < 4; ++k)
    {
      untrained->SetComponentName(k, names[k]);
    }
    const double tuple[4] = { double(u.Frames), u.Bandwidth, u.ErrorNone, u.ErrorChosen };
    untrained->InsertNextTuple(tuple);
    output->GetFieldData()->AddArray(untrained);
  }
  if (used.RefinesPoses())
  {
    // Every input frame's pose as refined, for a sequence written with them (bigus train --refined-poses).
    vtkNew<vtkDoubleArray> refined;
    refined->SetName("RefinedPoses");
    refined->SetNumberOfComponents(16);
    for (const std::array<double, 16>& pose : trainer.GetData().Poses)
    {
      refined->InsertNextTuple(pose.data());
    }
    output->GetFieldData()->AddArray(refined);
    // ... and as tracked, so that a sweep is matched to its block of RefinedPoses exactly (bigus evaluate).
    vtkNew<vtkDoubleArray> tracked;
    tracked->SetName("TrackedPoses");
    tracked->SetNumberOfComponents(16);
    for (const std::array<double, 16>& pose : trainer.GetTrackedPoses())
    {
      tracked->InsertNextTuple(pose.data());
    }
    output->GetFieldData()->AddArray(tracked);
  }
  if (used.RefineTimeOffset)
  {
    vtkNew<vtkDoubleArray> offset;
    offset->SetName("TimeOffset");
    offset->InsertNextValue(report.TimeOffset);
    output->GetFieldData()->AddArray(offset);
  }
  if (used.RefineImageToProbe)
  {
    const std::array<double, 6>& xi = report.ImageToProbeCorrection;
    vtkNew<vtkDoubleArray> correction;
    correction->SetName("ImageToProbeCorrection");
    correction->SetNumberOfComponents(6);
    for (int k = 0; k < 6; ++k)
    {
      correction->SetComponentName(k, CorrectionComponents[k]);
    }
    double tuple[6];
    StoredCorrection(xi, tuple);
    correction->InsertNextTuple(tuple);
    output->GetFieldData()->AddArray(correction);
    // M = P^-1 CorrectPose(P, xi): the correction acts in the image's own axes, so M is the same for every
    // pose P of the frame grid's pixel spacing (a training frame's).
    double pose[16], corrected[16];
    const std::array<double, 16>& P = trainer.GetData().Poses[trainer.GetData().TrainFrames.front()];
    std::copy(P.begin(), P.end(), pose);
    bigus::CorrectPose(pose, trainer.GetData().Width, trainer.GetData().Height, xi.data(), corrected);
    vtkNew<vtkMatrix4x4> inverse, after, m;
    inverse->DeepCopy(pose);
    inverse->Invert();
    after->DeepCopy(corrected);
    vtkMatrix4x4::Multiply4x4(inverse, after, m);
    vtkNew<vtkDoubleArray> matrix;
    matrix->SetName("ImageToProbeCorrectionMatrix");
    matrix->SetNumberOfComponents(16);
    matrix->InsertNextTuple(&m->GetData()[0]);
    output->GetFieldData()->AddArray(matrix);
  }
  if (history->GetNumberOfTuples() > 0)
  {
    output->GetFieldData()->AddArray(history);
  }

  this->NumberOfGaussians = n;
  this->TrainingSeconds = report.Seconds;
  this->CompletedIterations = report.Iterations;
  this->ReductionSeconds = reduction.Seconds;
  this->ReductionBytes = reduction.Bytes;
  this->FinalLoss = report.LastLoss;
  this->Gamma = trainer.GetGamma();
  this->StopReason = report.StopReason;
  this->GrowthStopReason = report.GrowthStopReason;
  return 1;
}

void vtkGaussianFieldTrainer::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "ElevationSigma: " << this->ElevationSigma << "\n";
  os << indent << "FramesPerStep: " << this->FramesPerStep << "\n";
  os << indent << "CoarseFraction: " << this->CoarseFraction << "\n";
  os << indent << "CoarseLowPass: " << (this->CoarseLowPass ? "On" : "Off") << "\n";
  os << indent << "Controller: " << this->Controller << "\n";
  os << indent << "BeamIntegration: " << this->BeamIntegration << "\n";
  os << indent << "NonNegativeReflectivity: " << this->NonNegativeReflectivity << "\n";
  os << indent << "HarrisInitialisation: " << this->HarrisInitialisation << "\n";
  os << indent << "Densify: " << this->Densify << "\n";
  os << indent << "ReflectivitySolve: " << this->ReflectivitySolve << "\n";
  os << indent << "SolveIterations: " << this->SolveIterations << "\n";
  os << indent << "SolveL1: " << this->SolveL1 << "\n";
  os << indent << "DenseInitialisation: " << this->DenseInitialisation << "\n";
  os << indent << "PixelGridFit: " << this->PixelGridFit << "\n";
  os << indent << "RefinePoses: " << this->RefinePoses << "\n";
  os << indent << "PoseSmoothness: " << this->PoseSmoothness << "\n";
  os << indent << "PoseRefinementStart: " << this->PoseRefinementStart << "\n";
  os << indent << "RefineTimeOffset: " << this->RefineTimeOffset << "\n";
  os << indent << "RefineImageToProbe: " << this->RefineImageToProbe << "\n";
  os << indent << "SparseAdam: " << this->SparseAdam << "\n";
  os << indent << "Iterations: " << this->Iterations << "\n";
  os << indent << "TimeBudget: " << this->TimeBudget << "\n";
  os << indent << "ConvergenceTolerance: " << this->ConvergenceTolerance << "\n";
  os << indent << "InitialGaussians: " << this->InitialGaussians << "\n";
  os << indent << "MaximumGaussians: " << this->MaximumGaussians << "\n";
  os << indent << "LossWeights: " << this->LossWeights[0] << " " << this->LossWeights[1] << " " << this->LossWeights[2]
     << "\n";
  os << indent << "Densify schedule: start " << this->DensifyStart << ", end " << this->DensifyEnd << ", interval "
     << this->DensifyInterval << ", percentile " << this->DensifyPercentile
     << ", residual seeds " << this->ResidualSeedShare << "\n";
  os << indent << "GrowthMargin: " << this->GrowthMargin << ", GrowthPatience: " << this->GrowthPatience << "\n";
  os << indent << "FillGaps: " << this->FillGaps << "\n";
  os << indent << "MergeTolerance: " << this->MergeTolerance << "\n";
  os << indent << "HoldOutEvery: " << this->HoldOutEvery << ", HoldOutOffset: " << this->HoldOutOffset
     << ", HoldOutSweep: " << this->HoldOutSweep << "\n";
  os << indent << "TrainingFrameList: " << (this->TrainingFrameList ? this->TrainingFrameList->GetNumberOfIds() : 0)
     << " frames\n";
  os << indent << "Seed: " << this->Seed << "\n";
  os << indent << "EvaluationInterval: " << this->EvaluationInterval << "\n";
  os << indent << "CheckpointFile: " << (this->CheckpointFile ? this->CheckpointFile : "(none)") << " every "
     << this->CheckpointInterval << " steps\n";
  os << indent << "ResumeFile: " << (this->ResumeFile ? this->ResumeFile : "(none)") << "\n";
  os << indent << "Backend: " << (this->Backend ? this->Backend : "(none)") << " (last run: "
     << (this->BackendInUse.empty() ? "none" : this->BackendInUse) << ")\n";
  os << indent << "NumberOfGaussians: " << this->NumberOfGaussians << ", StopReason: " << this->StopReason << "\n";
}
