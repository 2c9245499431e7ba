#include "vtkGaussianFieldTrainer.h"

#include "bigusGaussianFieldData.h"
#include "bigusPipeline.h"
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

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
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
  {}
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
  if (holdOutEvery > 0 && holdOutOffset >= holdOutEvery && (!frameList || frameList->GetNumberOfIds() == 0))
  {
    error = "HoldOutOffset " + std::to_string(holdOutOffset) + " must be below HoldOutEvery " +
      std::to_string(holdOutEvery) + " (frames with index % HoldOutEvery == HoldOutOffset are held out: none would be)";
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
  : Settings(new bigus::TrainerSettings)
{
  this->SetNumberOfInputPorts(2);
  this->SetBackend("auto");
}

vtkGaussianFieldTrainer::~vtkGaussianFieldTrainer()
{
  this->SetTrainingFrameList(nullptr);
  this->SetResumeFile(nullptr);
  this->SetBackend(nullptr);
  this->SetController(nullptr);
}

// The settings' setters and getters: each reads and writes its field of the one bigus::TrainerSettings, whose
// defaults are the filter's (a clamped one keeps a value in [lo, hi], as vtkSetClampMacro does; NaN, which no clamp
// moves, is refused with an error and the setting kept).
namespace
{
/// @p member = @p value; whether it changed (the setter then calls Modified).
template <typename Member, typename Value>
bool Assign(Member& member, const Value& value)
{
  if (member == value)
  {
    return false;
  }
  member = value;
  return true;
}
}
#define bigusTrainerSettingMacro(name, type, member, lo, hi)                                                           \
  void vtkGaussianFieldTrainer::Set##name(type value)                                                                  \
  {                                                                                                                    \
    if (std::isnan(static_cast<double>(value)))                                                                        \
    {                                                                                                                  \
      vtkErrorMacro("Set" #name ": NaN is not a value; the setting stays " << this->Get##name());                      \
      return;                                                                                                          \
    }                                                                                                                  \
    if (Assign(this->Settings->member, std::min<type>(std::max<type>(value, lo), hi)))                                 \
    {                                                                                                                  \
      this->Modified();                                                                                                \
    }                                                                                                                  \
  }                                                                                                                    \
  type vtkGaussianFieldTrainer::Get##name() const                                                                      \
  {                                                                                                                    \
    return static_cast<type>(this->Settings->member);                                                                  \
  }
#define bigusAnyValue(type) std::numeric_limits<type>::lowest(), std::numeric_limits<type>::max()
// (expands bigusAnyValue before the setting macro counts its arguments)
#define bigusTrainerSetting(name, type, member, ...) bigusTrainerSettingMacro(name, type, member, __VA_ARGS__)
bigusTrainerSetting(ElevationSigma, double, ElevationSigma, 0.0, 1000.0)
bigusTrainerSetting(BeamIntegration, bool, BeamIntegration, bigusAnyValue(bool))
bigusTrainerSetting(NonNegativeReflectivity, bool, NonNegativeReflectivity, bigusAnyValue(bool))
bigusTrainerSetting(HarrisInitialisation, bool, Seeding.HarrisInitialisation, bigusAnyValue(bool))
bigusTrainerSetting(Densify, bool, Densification.Enabled, bigusAnyValue(bool))
bigusTrainerSetting(ReflectivitySolve, bool, ReflectivitySolve, bigusAnyValue(bool))
bigusTrainerSetting(SolveIterations, int, Solve.MaximumIterations, 1, 100000)
bigusTrainerSetting(SolveL1, double, Solve.L1, 0.0, 1.0)
bigusTrainerSetting(SolveMemoryShare, double, Solve.AssembledMemoryShare, 0.0, 1.0)
bigusTrainerSetting(HeldOutChoices, bool, HeldOut.Enabled, bigusAnyValue(bool))
bigusTrainerSetting(DenseInitialisation, bool, Seeding.DenseInitialisation, bigusAnyValue(bool))
bigusTrainerSetting(PixelGridFit, bool, Seeding.PixelGridFit, bigusAnyValue(bool))
bigusTrainerSetting(MeasuredTail, bool, HeldOut.MeasuredTail, bigusAnyValue(bool))
bigusTrainerSetting(PoseSmoothness, double, Poses.Smoothness, 0.0, 1e12)
bigusTrainerSetting(PoseTrialSteps, int, Poses.TrialSteps, 0, 1000000)
bigusTrainerSetting(PoseRefinementStart, double, Poses.Start, -1.0, 1.0)
bigusTrainerSetting(RefineTimeOffset, bool, Poses.RefineTimeOffset, bigusAnyValue(bool))
bigusTrainerSetting(RefineImageToProbe, bool, Poses.RefineImageToProbe, bigusAnyValue(bool))
bigusTrainerSetting(AnchorPosesToTracked, bool, Poses.AnchorToTrackedPoses, bigusAnyValue(bool))
bigusTrainerSetting(SparseAdam, bool, SparseAdam, bigusAnyValue(bool))
bigusTrainerSetting(Iterations, int, Iterations, 0, 100000000)
bigusTrainerSetting(TimeBudget, double, TimeBudget, 0.0, 1e9)
bigusTrainerSetting(ConvergenceTolerance, double, ConvergenceTolerance, 0.0, 1.0)
bigusTrainerSetting(InitialGaussians, vtkIdType, Seeding.InitialGaussians, 0, VTK_ID_MAX)
bigusTrainerSetting(MaximumGaussians, vtkIdType, MaximumGaussians, 1, VTK_ID_MAX)
bigusTrainerSetting(DensifyStart, int, Densification.Start, 0, VTK_INT_MAX)
bigusTrainerSetting(DensifyEnd, int, Densification.End, -1, VTK_INT_MAX)
bigusTrainerSetting(DensifyInterval, int, Densification.Interval, 1, VTK_INT_MAX)
bigusTrainerSetting(DensifyPercentile, double, Densification.Percentile, 0.0, 100.0)
bigusTrainerSetting(ResidualSeedShare, double, Densification.ResidualSeedShare, 0.0, 100.0)
bigusTrainerSetting(GrowthMargin, double, Densification.GrowthMargin, 0.0, 1.0)
bigusTrainerSetting(GrowthPatience, int, Densification.GrowthPatience, 1, VTK_INT_MAX)
bigusTrainerSetting(FillGaps, bool, FillGaps, bigusAnyValue(bool))
bigusTrainerSetting(MergeTolerance, double, Merge.Tolerance, 0.0, 1.0)
bigusTrainerSetting(ParameterAverage, double, ParameterAverage, 0.0, 1.0)
bigusTrainerSetting(Seed, unsigned int, Seed, bigusAnyValue(unsigned int))
bigusTrainerSetting(FramesPerStep, int, FramesPerStep, 1, 4096)
bigusTrainerSetting(CoarseFraction, double, CoarseFraction, 0.0, 1.0)
bigusTrainerSetting(CoarseLowPass, bool, CoarseLowPass, bigusAnyValue(bool))
bigusTrainerSetting(CheckpointInterval, int, CheckpointInterval, 0, VTK_INT_MAX)
#undef bigusTrainerSetting
#undef bigusTrainerSettingMacro
#undef bigusAnyValue

void vtkGaussianFieldTrainer::SetRefinePoses(int mode)
{
  if (Assign(this->Settings->Poses.RefinePoses, static_cast<bigus::PoseRefinement>(std::min(std::max(mode, 0), 2))))
  {
    this->Modified();
  }
}

int vtkGaussianFieldTrainer::GetRefinePoses() const
{
  return static_cast<int>(this->Settings->Poses.RefinePoses);
}

void vtkGaussianFieldTrainer::SetHeldOutValidation(int mode)
{
  if (Assign(this->Settings->HeldOut.HoldOutValidationFrames,
        static_cast<bigus::ValidationHoldOut>(std::min(std::max(mode, 0), 2))))
  {
    this->Modified();
  }
}

int vtkGaussianFieldTrainer::GetHeldOutValidation() const
{
  return static_cast<int>(this->Settings->HeldOut.HoldOutValidationFrames);
}

void vtkGaussianFieldTrainer::SetTrainingCutoff(double value)
{
  if (std::isnan(value))
  {
    vtkErrorMacro("SetTrainingCutoff: NaN is not a value; the setting stays " << this->GetTrainingCutoff());
    return;
  }
  // 0 or below: automatic; a given cut-off within [2, 5] (a render filter's own range ends at 5).
  if (Assign(this->Settings->Cutoff, value <= 0 ? 0.0 : std::min(std::max(value, 2.0), 5.0)))
  {
    this->Modified();
  }
}

double vtkGaussianFieldTrainer::GetTrainingCutoff() const
{
  return this->Settings->Cutoff;
}

void vtkGaussianFieldTrainer::SetLossWeights(double l1, double dssim, double ffl)
{
  bigus::ImageLossWeights& w = this->Settings->Loss;
  if (std::isnan(l1) || std::isnan(dssim) || std::isnan(ffl))
  {
    vtkErrorMacro("SetLossWeights: NaN is not a weight; the weights stay " << w.L1 << " " << w.DSSIM << " " << w.FFL);
    return;
  }
  // Clamped at 0, as the other settings are to their ranges: a negative weight would reward the error.
  if (Assign(w.L1, std::max(0.0, l1)) | Assign(w.DSSIM, std::max(0.0, dssim)) | Assign(w.FFL, std::max(0.0, ffl)))
  {
    this->Modified();
  }
}

void vtkGaussianFieldTrainer::GetLossWeights(double weights[3]) const
{
  const bigus::ImageLossWeights& w = this->Settings->Loss;
  weights[0] = w.L1;
  weights[1] = w.DSSIM;
  weights[2] = w.FFL;
}

void vtkGaussianFieldTrainer::SetCheckpointFile(const char* file)
{
  if (Assign(this->Settings->CheckpointFile, std::string(file ? file : "")))
  {
    this->Modified();
  }
}

const char* vtkGaussianFieldTrainer::GetCheckpointFile() const
{
  return this->Settings->CheckpointFile.empty() ? nullptr : this->Settings->CheckpointFile.c_str();
}

void vtkGaussianFieldTrainer::SetTrainerSettings(const bigus::TrainerSettings& settings)
{
  *this->Settings = settings;
  this->Modified();
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
  bigus::RequestWholeExtent(inputVector, 2);
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
  bool ready = ReadTrainerInputs(
    inputVector, this->HoldOutEvery, this->HoldOutOffset, this->HoldOutSweep, this->TrainingFrameList, in, error);
  bigus::TrainingData& data = in.Data;
  const int sweepCount = in.SweepCount, maskCount = in.MaskCount;

  const bigus::TrainerSettings& s = *this->Settings;

  std::string notice;
  std::unique_ptr<bigus::TrainingEngine> engine;
  if (ready)
  {
    // Data-parallel runs sum on the host: the factory gives the CPU engine over the backend's renderer.
    engine = bigus::CreateTrainingEngine(this->Backend ? this->Backend : "auto", &error, &notice,
      this->Controller && this->Controller->GetNumberOfProcesses() > 1);
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
  trainer.SetResuming(this->ResumeFile && *this->ResumeFile);
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
  // (Not the validation frames the trainer holds out of the fit for a while: they join it.)
  const std::vector<int>& validation = trainer.GetReport().ValidationFrames;
  for (int k = 0; k < trainer.GetData().Count(); ++k)
  {
    if (in.Valid[k] &&
      !std::binary_search(trainer.GetData().TrainFrames.begin(), trainer.GetData().TrainFrames.end(), k) &&
      !(trainer.GetReport().ValidationHeldOut && std::binary_search(validation.begin(), validation.end(), k)))
    {
      heldOut.push_back(k);
    }
  }
  vtkNew<vtkDoubleArray> history;
  history->SetName("HeldOutPSNR");
  history->SetNumberOfComponents(3);
  history->SetComponentName(0, "Seconds");
  history->SetComponentName(1, "PSNR");
  history->SetComponentName(2, "Iteration");
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
    const double row[3] = { seconds, metrics.PSNR, static_cast<double>(trainer.GetIteration()) };
    history->InsertNextTuple(row);
    return true;
  };
  const bool ok =
    trainer.Train(
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
      [&]() { return this->AbortExecute != 0 || !evaluationError.empty(); }, &error) &&
    // Stopped by AbortExecute (SIGINT in bigus train): the state so far is saved to resume from, before Finish
    // changes the field (data-parallel: rank 0 writes it, as the trainer's own checkpoints).
    // (Not data-parallel: a process that could not write it would leave the others waiting in Finish.)
    (!this->AbortExecute || s.CheckpointFile.empty() ||
      (this->Controller && this->Controller->GetNumberOfProcesses() > 1) ||
      trainer.SaveCheckpoint(s.CheckpointFile, &error)) &&
    trainer.Finish(&error);
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
  addValue("ValidationJoinedAt", report.ValidationJoinedAt);
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
  bigus::GapFillingSettings gaps = used.GapFilling;
  gaps.MaximumGaussians = used.MaximumGaussians;
  addText("GapFilling", used.FillGaps ? bigus::DescribeGapFilling(report.GapFilling, gaps) : std::string("off"));
  addText("GaussianMerge",
    used.Merge.Tolerance > 0 ? bigus::DescribeGaussianMerge(report.Merge, used.Merge) : std::string("off"));
  if (report.Solves > 0)
  {
    const bigus::ReflectivitySolveReport& last = report.LastSolve;
    char text[300];
    std::snprintf(text, sizeof(text), "%d in %.1f s; the last: %d CGLS iterations%s, objective %.4g -> %.4g",
      report.Solves, report.SolveSeconds, last.Iterations,
      last.TimeLimitReached ? " (ended by its share of the time budget)" : "",
      last.Objective.empty() ? 0.0 : last.Objective.front(), last.Objective.empty() ? 0.0 : last.Objective.back());
    std::string solves = text + ("; products " + last.Products);
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
  // The lines as the run left them (the pose-refinement trial rewrites RefinePoses; the end adds PoseAnchor), after
  // the fan mask's.
  settings.resize(1);
  settings.insert(settings.end(), report.Settings.begin(), report.Settings.end());
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
  if (used.Poses.RefinePoses == bigus::PoseRefinement::On)
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
  if (used.Poses.Any())
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
    for (const std::array<double, 16>& pose : trainer.GetPoseRefiner().GetTrackedPoses())
    {
      tracked->InsertNextTuple(pose.data());
    }
    output->GetFieldData()->AddArray(tracked);
  }
  if (used.Poses.RefineTimeOffset)
  {
    vtkNew<vtkDoubleArray> offset;
    offset->SetName("TimeOffset");
    offset->InsertNextValue(report.TimeOffset);
    output->GetFieldData()->AddArray(offset);
  }
  if (used.Poses.RefineImageToProbe)
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

std::string vtkGaussianFieldTrainer::DescribeHeldOutPSNR(vtkDataArray* history)
{
  if (!history || history->GetNumberOfTuples() == 0 || history->GetNumberOfComponents() < 2)
  {
    return {};
  }
  const bool iterations = history->GetNumberOfComponents() >= 3;
  const auto when = [&](vtkIdType k) {
    const double seconds = history->GetComponent(k, 0);
    return iterations ? vtkfmt::sprintf("iteration %.0f (%.0f s)", history->GetComponent(k, 2), seconds)
                      : vtkfmt::sprintf("%.0f s", seconds);
  };
  const vtkIdType n = history->GetNumberOfTuples();
  if (n == 1)
  {
    return vtkfmt::sprintf("1 measurement: %.2f dB at %s", history->GetComponent(0, 1), when(0));
  }
  vtkIdType best = 0;
  for (vtkIdType k = 1; k < n; ++k)
  {
    best = history->GetComponent(k, 1) > history->GetComponent(best, 1) ? k : best;
  }
  const double top = history->GetComponent(best, 1), last = history->GetComponent(n - 1, 1);
  std::string text = vtkfmt::sprintf("%lld measurements: best %.2f dB at %s; last %.2f dB at %s",
    static_cast<long long>(n), top, when(best), last, when(n - 1));
  if (top - last > HeldOutPSNRDropReported)
  {
    text += vtkfmt::sprintf(", %.2f dB below the best: more steps lowered the score on frames the fit did not see "
                            "(its training frames overfitted for these views); a shorter schedule may score higher",
      top - last);
  }
  return text;
}

void vtkGaussianFieldTrainer::PrintSelf(ostream& os, vtkIndent indent)
{
  this->Superclass::PrintSelf(os, indent);
  os << indent << "ElevationSigma: " << this->GetElevationSigma() << "\n";
  os << indent << "FramesPerStep: " << this->GetFramesPerStep() << "\n";
  os << indent << "TrainingCutoff: " << this->GetTrainingCutoff() << "\n";
  os << indent << "CoarseFraction: " << this->GetCoarseFraction() << "\n";
  os << indent << "CoarseLowPass: " << (this->GetCoarseLowPass() ? "On" : "Off") << "\n";
  os << indent << "Controller: " << this->Controller << "\n";
  os << indent << "BeamIntegration: " << this->GetBeamIntegration() << "\n";
  os << indent << "NonNegativeReflectivity: " << this->GetNonNegativeReflectivity() << "\n";
  os << indent << "HarrisInitialisation: " << this->GetHarrisInitialisation() << "\n";
  os << indent << "Densify: " << this->GetDensify() << "\n";
  os << indent << "ReflectivitySolve: " << this->GetReflectivitySolve() << "\n";
  os << indent << "SolveIterations: " << this->GetSolveIterations() << "\n";
  os << indent << "SolveL1: " << this->GetSolveL1() << "\n";
  os << indent << "DenseInitialisation: " << this->GetDenseInitialisation() << "\n";
  os << indent << "PixelGridFit: " << this->GetPixelGridFit() << "\n";
  os << indent << "HeldOutValidation: " << this->GetHeldOutValidation() << "\n";
  os << indent << "MeasuredTail: " << this->GetMeasuredTail() << "\n";
  os << indent << "RefinePoses: " << this->GetRefinePoses() << "\n";
  os << indent << "PoseSmoothness: " << this->GetPoseSmoothness() << "\n";
  os << indent << "PoseRefinementStart: " << this->GetPoseRefinementStart() << "\n";
  os << indent << "RefineTimeOffset: " << this->GetRefineTimeOffset() << "\n";
  os << indent << "RefineImageToProbe: " << this->GetRefineImageToProbe() << "\n";
  os << indent << "AnchorPosesToTracked: " << this->GetAnchorPosesToTracked() << "\n";
  os << indent << "PoseTrialSteps: " << this->GetPoseTrialSteps() << "\n";
  os << indent << "SparseAdam: " << this->GetSparseAdam() << "\n";
  os << indent << "Iterations: " << this->GetIterations() << "\n";
  os << indent << "TimeBudget: " << this->GetTimeBudget() << "\n";
  os << indent << "ConvergenceTolerance: " << this->GetConvergenceTolerance() << "\n";
  os << indent << "InitialGaussians: " << this->GetInitialGaussians() << "\n";
  os << indent << "MaximumGaussians: " << this->GetMaximumGaussians() << "\n";
  double weights[3];
  this->GetLossWeights(weights);
  os << indent << "LossWeights: " << weights[0] << " " << weights[1] << " " << weights[2] << "\n";
  os << indent << "Densify schedule: start " << this->GetDensifyStart() << ", end " << this->GetDensifyEnd()
     << ", interval " << this->GetDensifyInterval() << ", percentile " << this->GetDensifyPercentile()
     << ", residual seeds " << this->GetResidualSeedShare() << "\n";
  os << indent << "GrowthMargin: " << this->GetGrowthMargin() << ", GrowthPatience: " << this->GetGrowthPatience()
     << "\n";
  os << indent << "FillGaps: " << this->GetFillGaps() << "\n";
  os << indent << "MergeTolerance: " << this->GetMergeTolerance() << "\n";
  os << indent << "ParameterAverage: " << this->GetParameterAverage() << "\n";
  os << indent << "HoldOutEvery: " << this->HoldOutEvery << ", HoldOutOffset: " << this->HoldOutOffset
     << ", HoldOutSweep: " << this->HoldOutSweep << "\n";
  os << indent << "TrainingFrameList: " << (this->TrainingFrameList ? this->TrainingFrameList->GetNumberOfIds() : 0)
     << " frames\n";
  os << indent << "Seed: " << this->GetSeed() << "\n";
  os << indent << "EvaluationInterval: " << this->EvaluationInterval << "\n";
  os << indent << "CheckpointFile: " << (this->GetCheckpointFile() ? this->GetCheckpointFile() : "(none)") << " every "
     << this->GetCheckpointInterval() << " steps\n";
  os << indent << "ResumeFile: " << (this->ResumeFile ? this->ResumeFile : "(none)") << "\n";
  os << indent << "Backend: " << (this->Backend ? this->Backend : "(none)")
     << " (last run: " << (this->BackendInUse.empty() ? "none" : this->BackendInUse) << ")\n";
  os << indent << "NumberOfGaussians: " << this->NumberOfGaussians << ", StopReason: " << this->StopReason << "\n";
}
