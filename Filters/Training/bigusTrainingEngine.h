/**
 * @file bigusTrainingEngine.h
 * @brief The training state and the one interface a training step implements (DESIGN section 5).
 *
 * The trainer (bigus::Trainer) owns the schedule: which frames a step sees, learning rates,
 * densification, pruning, checkpoints, roll-back. A TrainingEngine owns the per-Gaussian state while
 * steps run (on the host for the CPU engine, on a device for a GPU engine, across ranks for a
 * distributed one) and does the step itself: forward, loss, backward and the Adam update for a batch
 * of frames. Between steps the trainer pulls the state to the host (Pull), edits it there
 * (densification, pruning, checkpoints) and pushes it back (Push). Every engine runs the same training
 * loop, so a new backend implements this interface and nothing else.
 */
#ifndef bigusTrainingEngine_h
#define bigusTrainingEngine_h

#include "bigusAdam.h"
#include "bigusFieldLayout.h"
#include "bigusImageLoss.h"
#include "bigusRenderer.h"
#include "bigusTrainingModule.h" // For export macro

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace bigus
{

/**
 * The frames a trainer learns from. Intensities in [0, 1].
 *
 * Several sweeps (bigus::TrainingDataFromSweeps) are held one after the other, each frame with the index
 * of its sweep in Sweeps. Frames of different sizes share one [H, W] grid, the largest width and height:
 * a frame's own w x h pixels keep their indices (i, j), so its ImageToReference (pixel index -> mm,
 * spacing inside) is unchanged, and the pixels beyond them are 0 and masked out (a per-frame mask). The
 * padding costs render time on the smaller frames and nothing else: no loss, gradient or seed comes from a
 * masked pixel.
 */
struct BIGUSTRAINING_EXPORT TrainingData
{
  int Width = 0, Height = 0;
  std::vector<float> Frames;                 ///< [N, H, W]
  std::vector<std::array<double, 16>> Poses; ///< [N] ImageToReference, row-major
  std::vector<unsigned char> Mask; ///< [H, W] fan mask shared by every frame, or [N, H, W] per frame (1 = imaged)
  std::vector<int> TrainFrames;    ///< indices into Frames used for training
  std::vector<int> Sweeps;         ///< [N] the sweep (0, 1, ...) each frame was recorded in; empty: one sweep
  /// [N] each frame's video timestamp (s, field data Timestamp); empty when unknown. Only the refinement of a
  /// tracker-to-video time offset reads them (bigus::PoseTimeline).
  std::vector<double> Timestamps;
  /// [N] 0 for a frame the sweep marks invalid (field data FrameValid 0: its pose is no tracked pose); empty:
  /// every frame valid. The tracked path in time (bigus::PoseTimeline) and the pose corrections skip them.
  std::vector<unsigned char> Valid;
  /// Variance (pixels^2) of the low-pass the frames' pixels stand for (SliceGeometry::PixelLowPass): 0 for
  /// recorded frames (point samples), 1/16 for the averaged coarse frames of DecimateFrames.
  double PixelLowPass = 0;
  bool IsValid(int frame) const { return this->Valid.empty() || this->Valid[frame] != 0; }
  int Count() const { return static_cast<int>(this->Poses.size()); }
  /// The sweep frame @p frame was recorded in (0 with a single sweep). Neighbours along a sweep (the
  /// elevation sigma's frame pairs, gap filling, the pose smoothness prior) are taken within one sweep.
  int SweepOf(int frame) const { return this->Sweeps.empty() ? 0 : this->Sweeps[frame]; }
  /// How many sweeps the frames come from (1 with a single sweep): the largest index in Sweeps, plus one.
  int SweepCount() const
  {
    return this->Sweeps.empty() ? 1 : *std::max_element(this->Sweeps.begin(), this->Sweeps.end()) + 1;
  }
  /// The [H, W] mask of frame @p frame (the shared one, or that frame's own).
  const unsigned char* MaskOf(int frame) const
  {
    const std::size_t pixels = std::size_t(this->Width) * this->Height;
    return this->Mask.data() + (this->Mask.size() == pixels ? 0 : pixels * frame);
  }
  /// The slice of frame @p frame: its pose and the frames' pixel grid.
  SliceGeometry Slice(int frame) const;
};

/**
 * Frames @p frames ([count] indices into @p data) on every second pixel and row from pixel (@p offsetX,
 * @p offsetY), @p offsetX, @p offsetY in {0, 1}: a quarter of the pixels. Frame k of the result is
 * @p frames[k]; sweeps carry over, TrainFrames lists every frame. The coarse steps of the resolution schedule
 * (TrainerSettings::CoarseFraction, CoarseLowPass).
 * - Point samples (@p average false): pixel (i, j) is the source's (offsetX + 2 i, offsetY + 2 j), its
 *   ImageToReference maps it to the same point (spacing doubled in plane), its mask is the source's there.
 * - Averages (@p average true): pixel (i, j) is the mean of the source's 2 x 2 block from (offsetX + 2 i,
 *   offsetY + 2 j) (whole blocks only), masked unless all four are imaged, placed at the block's centre; the
 *   result's PixelLowPass is data.PixelLowPass / 4 + 1/16 (decimated pixels^2: the 2 x 2 box's variance 1/12
 *   less the source pixel's 1/48), so that the renderer draws each Gaussian blurred as the average blurs it.
 */
BIGUSTRAINING_EXPORT TrainingData DecimateFrames(
  const TrainingData& data, const int* frames, int count, int offsetX, int offsetY, bool average = false);

/**
 * The pose gradient @p gradient (6 values, FieldGradients::SlicePoses) of a frame of DecimateFrames(@p data, ...,
 * @p offsetX, @p offsetY, @p average), made the gradient with respect to the correction of the source frame
 * @p frame: both are taken in the same axes, about the decimated and the source frame's centre pixel, so the
 * translation part is the same and the rotation part gains d x dL/dt, d the decimated centre minus the source
 * centre (mm, in plane). Unchanged when the source pose is not a valid frame.
 */
BIGUSTRAINING_EXPORT void DecimatedPoseGradientToSource(
  const TrainingData& data, int frame, int offsetX, int offsetY, double gradient[6], bool average = false);

/// A Gaussian field's parameters (float, structure of arrays).
struct BIGUSTRAINING_EXPORT GaussianField
{
  std::vector<float> Means, LogScales, Quaternions, Reflectivities; ///< [N,3] mm, [N,3], [N,4], [N]
  std::int64_t Count() const { return static_cast<std::int64_t>(this->Reflectivities.size()); }
  /// The array of parameter group @p q (bigusFieldLayout.h: MeanGroup, LogScaleGroup, ...).
  std::vector<float>& Group(int q)
  {
    return q == MeanGroup    ? this->Means
      : q == LogScaleGroup   ? this->LogScales
      : q == QuaternionGroup ? this->Quaternions
                             : this->Reflectivities;
  }
  FieldView View() const;
  void Resize(std::int64_t n);
  /// Keeps the Gaussians whose flag is non-zero, in order.
  void Compact(const std::vector<unsigned char>& keep);
  /// Gaussian @p to takes every parameter of Gaussian @p from.
  void CopyGaussian(std::int64_t from, std::int64_t to);
  /// Sets every parameter of Gaussian @p i to 0 (optimiser moments).
  void ZeroGaussian(std::int64_t i);
};

/// Everything a step reads and writes per Gaussian: the field, its Adam moments and the EA-D
/// accumulators since the last densification. Every vector has one entry (group) per Gaussian.
struct BIGUSTRAINING_EXPORT OptimizerState
{
  GaussianField Field;
  GaussianField FirstMoment, SecondMoment; ///< Adam m and v, laid out as the field
  std::vector<float> Attribution;          ///< [N] E_i = sum_p |dL/dS(p)| |r_i| w_i(p) (DESIGN section 4)
  std::vector<int> SeenCount;              ///< [N] training slices whose pixels the Gaussian touched
  std::int64_t Count() const { return this->Field.Count(); }
  /// Moments and accumulators sized to the field; new entries are zero.
  void ResizeToField();
  /// Keeps the Gaussians whose flag is non-zero, with their moments and accumulators, in order.
  void Compact(const std::vector<unsigned char>& keep);
};

/// The whole state of a training run: what a checkpoint stores and a resumed run continues from.
struct BIGUSTRAINING_EXPORT TrainingState
{
  OptimizerState Gaussians;
  // Schedule
  int Iteration = 0;
  double LearningRateScale = 1; ///< halved on every roll-back
  bool Growing = true;
  double BestValidationLoss = -1;
  int StalledGrowthSteps = 0;
  int RolledBackSteps = 0;
  std::vector<double> LossHistory; ///< loss of every completed step
  std::mt19937_64 Random;          ///< draws the frames of each step
  double TrainingSeconds =
    0; ///< seconds spent in Trainer::Train and the first reflectivity solve so far (TrainerSettings::TimeBudget)
  // Early stopping (bigus::Trainer::Finish)
  GaussianField BestField;    ///< the field with the lowest validation loss seen so far
  double BestFieldLoss = -1;  ///< its validation loss; -1: none measured yet
  int BestFieldIteration = 0; ///< the iteration it was measured at
  // Pose refinement (TrainerSettings::RefinePoses): per frame of the data, empty when off
  std::vector<std::array<double, 6>> PoseCorrections; ///< rotation vector (rad), translation (mm): CorrectPose
  std::vector<std::array<double, 6>> PoseFirstMoment; ///< Adam's moments of the corrections
  std::vector<std::array<double, 6>> PoseSecondMoment;
  std::vector<int> PoseSteps; ///< Adam steps each correction took
  /// The corrections shared by every frame (TrainerSettings::RefineImageToProbe, RefineTimeOffset): the ImageToProbe
  /// correction (rotation vector, rad; translation, mm: CorrectPose of every frame) then the time offset (s).
  std::array<double, 7> SharedPoseCorrection{};
  std::array<double, 7> SharedPoseFirstMoment{}, SharedPoseSecondMoment{}; ///< their Adam moments
  int SharedPoseSteps = 0;                                                 ///< Adam steps they took
  /// The corrections when BestField was measured (PoseCorrections, SharedPoseCorrection): early stopping keeps
  /// them with it. Empty / zero without pose refinement.
  std::vector<std::array<double, 6>> BestPoseCorrections;
  std::array<double, 7> BestSharedPoseCorrection{};
  // The parameter average over the schedule's tail (TrainerSettings::ParameterAverage, bigusParameterAverage.h)
  GaussianField AverageField;                                ///< empty until its first sample
  std::vector<std::array<double, 6>> AveragePoseCorrections; ///< the average of PoseCorrections
  std::array<double, 7> AverageSharedPoseCorrection{};       ///< the average of SharedPoseCorrection
  int AverageSamples = 0;                                    ///< samples mixed in; 0: no average
  int AverageStart = 0;                                      ///< the iteration of its first sample
  double AverageFraction = 0;                                ///< the schedule fraction of its last sample
  /// The step the held-out validation frames joined the fit (Trainer::JoinValidationFrames); -1: not yet, or none
  /// held out; -2: unknown (a checkpoint before "BIGUSCK8", whose frames join when it resumes past the window's close).
  int ValidationJoinedAt = -1;
  /// The step the run stops at after its held-out validation frames joined the fit (HeldOutChoiceSettings::
  /// MeasuredTail); -1: none, the schedule decides.
  int MeasuredTailEnd = -1;
  // What the state was trained on, so that a resume on other data or settings is refused (Trainer::LoadCheckpoint):
  std::uint64_t DataDigest = 0; ///< TrainingDataDigest of the run's data; 0: unknown (a file before "BIGUSCK6")
  std::string RunSettings;      ///< the settings a resume must share, "name = value" lines; empty: unknown

  /**
   * Writes the state to @p file (written to FILE.tmp, then renamed; the previous file survives a
   * failure). Little-endian binary, "BIGUSCK8" | int32 iteration | float64 learning-rate scale |
   * float64 gamma | int32 growing | float64 best validation loss | int32 stalled growth steps |
   * int32 rolled-back steps | uint32 length + text of the random engine state | int64 N | field, Adam
   * m, Adam v: each [N,3] means, [N,3] log-scales, [N,4] quaternions, [N] reflectivities as float32 |
   * [N] float32 attribution | [N] int32 seen counts | int64 H + H float64 loss history | float64 best
   * field's validation loss | int32 its iteration | int64 M | best field as above | float64 training
   * seconds | int64 P (frames with a pose correction; 0 without pose refinement) | P x (6 float64
   * correction, 6 float64 Adam m, 6 float64 Adam v, int32 steps) | 7 float64 shared correction, 7 Adam m,
   * 7 Adam v, int32 steps | int64 B + B x 6 float64 and 7 float64: the corrections of the best field | uint64 data
   * digest | uint32 length + text of the run settings | int32 average samples | int32 its first iteration | float64
   * its last schedule fraction | int64 A + the average field as above | int64 Q + Q x 6 float64 | 7 float64: the
   * average's pose corrections | int32 the step the validation frames joined (-1: not yet) | int32 the measured
   * tail's end (-1: none). Load also reads "BIGUSCK7" files (no measured tail: the schedule decides; the join step
   * unknown, -2), "BIGUSCK6" files (no parameter average: it starts afresh),
   * "BIGUSCK5" files (no data digest or run settings: a resume cannot check them), "BIGUSCK4" files (no shared
   * correction), "BIGUSCK3" files (no pose corrections), "BIGUSCK2" files (no training seconds either: a time budget
   * starts afresh) and "BIGUSCK1" files (neither those nor a best field: early stopping starts afresh too). Returns
   * false with @p error naming the file.
   */
  bool Save(const std::string& file, double gamma, std::string* error) const;
  /// Reads a state written by Save; on failure (@p error names the file and what is wrong: bad magic,
  /// truncated header or data, corrupt random state) this state and @p gamma are unchanged.
  bool Load(const std::string& file, double& gamma, std::string* error);
};

/// One training step's work.
struct StepRequest
{
  const int* Frames = nullptr; ///< [Count] indices into the engine's TrainingData.Frames
  int Count = 0;               ///< batch size; the loss and its gradient are the batch means
  int Iteration = 0;           ///< Adam's bias correction uses t = Iteration + 1
  double MeanRate = 0, LogScaleRate = 0, QuaternionRate = 0, ReflectivityRate = 0; ///< Adam learning rates
  /// The learning rate of parameter group @p q (bigusFieldLayout.h).
  double Rate(int q) const
  {
    return q == MeanGroup    ? this->MeanRate
      : q == LogScaleGroup   ? this->LogScaleRate
      : q == QuaternionGroup ? this->QuaternionRate
                             : this->ReflectivityRate;
  }
  double MinimumLogScale = 0, MaximumLogScale = 0; ///< log-scales are clamped to this range after the update
  /// Adam over the Gaussians the step touched only: one whose gradients are all zero keeps its parameters
  /// and moments (Mallick et al. 2024, Taming 3DGS; gsplat's sparse gradients). False: every Gaussian's
  /// moments decay and its parameters move on their momentum (Kingma and Ba 2015, algorithm 1).
  bool SparseAdam = false;
  RenderOptions Options; ///< rendering while training (cutoff, gamma, beam)
  ImageLossWeights Loss;
  /// Pose refinement: when not null, receives ([Count, 6], overwritten) the gradient of the batch's loss
  /// with respect to a rigid correction of each frame's pose at its current pose (FieldGradients::SlicePoses:
  /// rotation vector per rad, translation per mm, about the frame's centre pixel in its own axes). The
  /// trainer moves the poses (TrainingData::Poses) between steps; an engine reads them at every step.
  double* PoseGradients = nullptr;
  /// When not null, the step's frames come from this data instead of the engine's (SetData), and Frames index
  /// it: the trainer's decimated copies of the step's frames (DecimateFrames, TrainerSettings::CoarseFraction).
  const TrainingData* Data = nullptr;
};

/// For engines: the options of the reflectivity solve's linear map S = A r (reflectivities used as given,
/// NonNegativeReflectivity off).
inline RenderOptions LinearBasisOptions(RenderOptions options)
{
  options.NonNegativeReflectivity = false;
  return options;
}

/// For engines with an assembled basis: the frames, effective elevation sigma and cut-off that an assembled A was
/// built for; a product on the same ones reuses it.
struct BasisKey
{
  std::vector<int> Frames;
  double ElevationSigma = -1, Cutoff = -1;
  BasisKey() = default;
  BasisKey(const int* frames, int count, const RenderOptions& options)
    : Frames(frames, frames + count)
    , ElevationSigma(EffectiveElevationSigma(options))
    , Cutoff(options.Cutoff)
  {}
  bool operator==(const BasisKey& other) const
  {
    return this->Frames == other.Frames && this->ElevationSigma == other.ElevationSigma && this->Cutoff == other.Cutoff;
  }
};

/// For engines: DescribeBasisProducts's text for an assembled A of @p weights stored weights and @p bytes bytes built
/// in @p seconds: "assembled (W weights, B MB, built in S s)", with @p where ("on the device") after "assembled".
BIGUSTRAINING_EXPORT std::string AssembledBasisText(
  std::int64_t weights, std::int64_t bytes, double seconds, const char* where = nullptr);

/// For engines: @p error (the renderer's message for a call it refused) prefixed with "training frame F: ".
/// Returns false.
inline bool TrainingFrameError(int frame, std::string* error)
{
  if (error)
  {
    *error = "training frame " + std::to_string(frame) + ": " + *error;
  }
  return false;
}

/**
 * For engines: the image loss (ComputeImageLoss, inside the frame's mask) of @p I ([H, W]) rendered at frame
 * @p frame of @p data, returned undivided, and its gradient dL/dI into @p gradient ([H, W]) divided by the batch
 * size @p request.Count (a step's loss is the batch mean).
 */
BIGUSTRAINING_EXPORT double FrameLoss(const TrainingData& data, int frame, const float* I, const StepRequest& request,
  float* gradient, ImageLossWorkspace* workspace);

/// This machine's physical memory, bytes (vtksys::SystemInformation, to the MiB); 0 when unknown. Sizes are checked
/// against it before large allocations (the reflectivity solve, a trainer's MaximumGaussians).
BIGUSTRAINING_EXPORT double PhysicalMemoryBytes();

/**
 * Whether @p data can be trained on: training frames, frames, poses and mask of consistent sizes, and every training
 * pose one the renderer accepts (false with @p error: "training frame 12: ImageToReference is sheared ... by 7.20
 * degrees; the renderer accepts at most 5.00": bigus::DefaultMaximumShearAngle, also the reader's default limit).
 */
BIGUSTRAINING_EXPORT bool CheckTrainingData(const TrainingData& data, std::string* error);

/// The mean intensity of the training frames' pixels inside their masks; @p fanPixels receives how many (0: none,
/// and the mean is 0).
BIGUSTRAINING_EXPORT double MeanFanIntensity(const TrainingData& data, std::int64_t& fanPixels);

/// Mean in-plane pixel spacing (mm) of a pose (ImageToReference, row-major 4 x 4).
BIGUSTRAINING_EXPORT double PixelSpacingOf(const std::array<double, 16>& pose);

/// Mean in-plane pixel spacing (mm) of @p data's training frames; 1 when it has none.
BIGUSTRAINING_EXPORT double MeanTrainingPixelSpacing(const TrainingData& data);

/**
 * Host memory of a training run per Gaussian, bytes, with the CPU engine (the documented table is in
 * docs/FINDINGS.md, "Memory per Gaussian"): the trainer's optimiser state (the field 44: means, log-scales,
 * quaternions, reflectivity in float; Adam's two moments 88; attribution and visibility count 8), the
 * engine's copy of it (140), the engine's last known-good field and moments (132) and its gradients
 * (44), and the best field kept for early stopping (44). The reflectivity solve adds
 * ReflectivitySolveBytes while it runs. The training frames (4 bytes per pixel, 1 per mask pixel)
 * come on top.
 */
constexpr double TrainingBytesPerGaussian = 140 + 140 + 132 + 44 + 44;

/**
 * Whether a field of @p maximumGaussians Gaussians can be trained in this machine's memory (PhysicalMemoryBytes):
 * TrainingBytesPerGaussian each, plus @p solveBytes (the reflectivity solve's vectors, ReflectivitySolveBytes, where
 * the run solves). False with @p error naming the megabytes needed and present.
 */
BIGUSTRAINING_EXPORT bool CheckTrainingMemory(std::int64_t maximumGaussians, double solveBytes, std::string* error);

/**
 * Sums across the processes of a data-parallel run (one per MPI rank; DESIGN section 5). Each process renders
 * and differentiates its share of a step's frames (batch positions b with b mod Size() == Rank()) and the
 * sums give every process the same gradients, EA-D accumulators and loss, so that the same Adam update and the
 * same densification keep the processes' fields identical. Every call is collective: the trainer and the
 * engines make them in the same order on every process. vtkGaussianFieldTrainer implements it over a
 * vtkMultiProcessController (AllReduce; vtkMPIController under mpirun).
 */
class BIGUSTRAINING_EXPORT ProcessReduction
{
public:
  virtual ~ProcessReduction();
  virtual int Rank() const = 0; ///< this process, 0 to Size() - 1
  virtual int Size() const = 0; ///< processes in the run
  /// @p values ([count]) become their element-wise sum over the processes; false with @p error when the
  /// communication failed.
  virtual bool Sum(float* values, std::size_t count, std::string* error) = 0;
  virtual bool Sum(double* values, std::size_t count, std::string* error) = 0;
  /// @p values ([count]) become their element-wise maximum over the processes (the trainer's clock; with bytes,
  /// flags: which Gaussians any process's frames touched).
  virtual bool Maximum(double* values, std::size_t count, std::string* error) = 0;
  virtual bool Maximum(unsigned char* values, std::size_t count, std::string* error) = 0;
  /**
   * Collective agreement on success: true when @p ok on every process. Otherwise false, with @p error kept on
   * a process that failed and set to "another process failed (rank R)" on the others, so that no process
   * waits in a sum that a failed one never enters.
   */
  bool AllSucceeded(bool ok, std::string* error);
};

enum class StepStatus
{
  Done,      ///< the state took the step
  NonFinite, ///< the loss, a gradient or an updated parameter was NaN or Inf: call Restore()
  Failed     ///< the engine could not run (a rejected pose, device error): see the error text
};

class BIGUSTRAINING_EXPORT TrainingEngine
{
public:
  virtual ~TrainingEngine();
  /// The rendering backend the engine runs on ("cpu", "cuda").
  virtual const char* GetName() const = 0;

  /// The training frames, poses and masks; kept (by pointer) for the engine's lifetime.
  virtual bool SetData(const TrainingData* data, std::string* error) = 0;
  /// The engine's state becomes @p state (initial field, after densification or pruning, a loaded
  /// checkpoint); this is also the state Restore() returns to until the next Snapshot().
  virtual bool Push(const OptimizerState& state, std::string* error) = 0;
  /// Copies the engine's state into @p state.
  virtual bool Pull(OptimizerState& state, std::string* error) = 0;
  /// The field only, for rendering or writing on the host.
  virtual bool PullField(GaussianField& field, std::string* error) = 0;

  /**
   * One step: renders each frame of @p request, the image loss inside its mask, the gradients (and
   * the EA-D accumulators, which keep accumulating even when the step is not taken), then Adam.
   * @p loss receives the batch's mean loss (NaN when not finite).
   */
  virtual StepStatus Step(const StepRequest& request, double* loss, std::string* error) = 0;
  /// Remembers the field and moments as the last known-good state.
  virtual void Snapshot() = 0;
  /// Back to the last known-good field and moments (the accumulators are kept).
  virtual void Restore() = 0;

  /**
   * Data-parallel training (ProcessReduction): from now on Step renders this process's share of the request's
   * frames and sums the gradients over the processes; the operators of the solve take this process's frames
   * (the caller splits them: bigus::SolveReflectivities), ApplyBasis keeps their images here, and
   * ApplyBasisTranspose and BasisNorms sum their N-vectors over the processes; Render stays local. Every call
   * agrees on success first (ProcessReduction::AllSucceeded). Null: one process. The base class refuses (false
   * with @p error naming the engine) any reduction of more than one process; an engine that sums across processes
   * overrides it. The CPU engine does, over any backend's renderer: CreateTrainingEngine(..., dataParallel true)
   * gives it.
   */
  virtual bool SetReduction(ProcessReduction* reduction, std::string* error);

  /// Renders the engine's current field at @p count slices (bigus::Renderer::Forward).
  virtual bool Render(
    const SliceGeometry* slices, int count, const RenderOptions& options, float* S, float* I, std::string* error) = 0;

  // The reflectivity solve's operators (bigusReflectivitySolve.h, DESIGN section 4). For the engine's
  // current geometry the scattering field of a frame is linear in the reflectivities, S = A r, column i
  // of A being Gaussian i's beam-integrated weight w_i(p). A backend gives the solve these three products,
  // and nothing else: matrix free (each product renders) or over A assembled once per geometry and frame set
  // (the CPU engine: AssembledBasis, where it fits in SetBasisMemoryLimit). RenderOptions::NonNegativeReflectivity
  // does not enter (A is linear). Frames index the engine's TrainingData; each has that data's [H, W] grid.

  /**
   * The most memory (bytes) the basis products may hold as an assembled matrix; 0 or less: matrix free. An engine
   * without an assembled path ignores it (the CPU engine's default: 0; bigus::SolveReflectivities sets it from
   * ReflectivitySolveSettings::AssembledMemoryShare).
   */
  virtual void SetBasisMemoryLimit(std::int64_t bytes);
  /// How the last basis products ran, for reports: "assembled (...)" or "matrix free (...)".
  virtual std::string DescribeBasisProducts() const;

  /**
   * A r: with @p r ([N]) in place of the field's reflectivities, the scattering field S of each of the
   * @p count @p frames into @p S ([count, H, W]). False with @p error for a pose the renderer rejects.
   */
  virtual bool ApplyBasis(
    const float* r, const int* frames, int count, const RenderOptions& options, float* S, std::string* error) = 0;
  /**
   * A^T y: adds to @p out ([N]) sum over the @p count @p frames and their pixels p of y(p) w_i(p), for
   * @p y ([count, H, W]). False with @p error for a pose the renderer rejects.
   */
  virtual bool ApplyBasisTranspose(
    const float* y, const int* frames, int count, const RenderOptions& options, double* out, std::string* error) = 0;
  /**
   * diag(A^T W A): adds to @p out ([N]) sum over the @p count @p frames and their pixels p of
   * weights(p) w_i(p)^2, for @p weights ([count, H, W]; bigusBasisNorms.h).
   */
  virtual bool BasisNorms(const float* weights, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) = 0;
};

/**
 * A 64-bit digest of everything in @p data a training run reads (grid, frames, poses, masks, training frames,
 * sweeps, timestamps, validity, low-pass): two data give the same digest when they are the same, and different ones
 * with probability 1 - 2^-64. For checkpoints (TrainingState::DataDigest): one pass over the frames, 8 bytes at a
 * time (FNV-1a on 64-bit words).
 */
BIGUSTRAINING_EXPORT std::uint64_t TrainingDataDigest(const TrainingData& data);

/// Seconds on the monotonic clock (std::chrono::steady_clock): the durations the trainer and its stages report.
inline double SteadySeconds()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/**
 * For engines with an assembled basis (the CPU engine's AssembledBasis, the CUDA engine's device twin): whether the
 * products for @p key run on it. The cached @p assembled where @p assembledKey is @p key; otherwise one built by
 * @p assemble(Basis&, std::string& why, bool& tooLarge), which returns false with why when it cannot build: refused
 * before allocating (tooLarge, or @p memoryLimit <= 0), the products run matrix free and @p ok stays true; any other
 * failure sets @p ok false and @p error to why. @p products becomes DescribeBasisProducts's text: "matrix free (why)",
 * or @p describe(const Basis&, double seconds) of the new basis.
 */
template <class Basis, class Assemble, class Describe>
bool UseAssembledBasis(std::unique_ptr<Basis>& assembled, BasisKey& assembledKey, const BasisKey& key,
  std::int64_t memoryLimit, std::string& products, bool& ok, std::string* error, Assemble&& assemble,
  Describe&& describe)
{
  ok = true;
  if (memoryLimit <= 0)
  {
    products = "matrix free (no memory allowed for the assembled basis)";
    return false;
  }
  if (assembled && assembledKey == key)
  {
    return true;
  }
  assembled.reset();
  const double start = SteadySeconds();
  std::unique_ptr<Basis> basis(new Basis);
  std::string why;
  bool tooLarge = false;
  if (!assemble(*basis, why, tooLarge))
  {
    products = "matrix free (" + why + ")";
    ok = tooLarge;
    if (!ok && error)
    {
      *error = why;
    }
    return false;
  }
  assembled = std::move(basis);
  assembledKey = key;
  products = describe(*assembled, SteadySeconds() - start);
  return true;
}

/// The CPU engine over @p renderer (normally bigus::CreateRenderer("cpu", ...)).
BIGUSTRAINING_EXPORT std::unique_ptr<TrainingEngine> CreateCpuTrainingEngine(std::unique_ptr<Renderer> renderer);

/// Makes a backend's own training engine; null with @p error when it cannot run here.
using TrainingEngineFactory = std::unique_ptr<TrainingEngine> (*)(std::string* error);

/**
 * Registers (or replaces) the training engine of backend @p name (a renderer backend registered with
 * bigus::RegisterBackend): a backend that keeps the training state on its device, or across ranks,
 * brings its engine here, and CreateTrainingEngine takes it instead of the CPU engine over that
 * backend's renderer. Called once by the backend module when it is loaded.
 */
BIGUSTRAINING_EXPORT void RegisterTrainingEngine(const std::string& name, TrainingEngineFactory factory);

/**
 * The training engine of backend @p name ("auto", "cpu", "cuda"), chosen through the one backend
 * registry (bigus::CreateRenderer, so "auto" takes only a backend that passed its self-check): that
 * backend's registered engine (RegisterTrainingEngine), or else the CPU engine's host-side step over
 * the backend's renderer. Returns null with @p error when the backend is unknown, not built, cannot
 * run here, or its registered engine cannot be made (for an explicit name; "auto" then falls back to
 * the CPU engine over its renderer and says so in @p notice); @p notice as for CreateRenderer.
 * @p dataParallel (the engine will be given a reduction of several processes, SetReduction): the CPU engine,
 * which sums its gradients through the host, over the backend's renderer (the CUDA renderer for "cuda"),
 * never a registered engine.
 */
BIGUSTRAINING_EXPORT std::unique_ptr<TrainingEngine> CreateTrainingEngine(
  const std::string& name, std::string* error, std::string* notice = nullptr, bool dataParallel = false);

} // namespace bigus

#endif
