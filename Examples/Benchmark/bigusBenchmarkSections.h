// `bigus benchmark` (bigusBenchmark.h): the sections of the report, one file each, what they share through
// BenchmarkContext, and the helpers that more than one of them uses.
#ifndef bigusBenchmarkSections_h
#define bigusBenchmarkSections_h

#include "bigusBenchmarkRuns.h"

#include <cstddef>
#include <string>
#include <vector>

namespace bigus::benchmark
{
/// Where a trained field's held-out error comes from: its fit of the training frames, and its render at
/// a held-out pose against the blend of its own renders at the bracketing training frames.
struct ErrorSources
{
  double Seconds = NaN;
  ImageMetrics Training;       ///< renders at the training poses against the recorded frames
  ImageMetrics HeldOut;        ///< renders at the held-out poses (the BIGUS row)
  ImageMetrics BlendedRenders; ///< the blend baseline run on the field's renders instead of the recording
};

/// The report's account of where the held-out error comes from, one row per time mark, also added to
/// the sweep's JSON @p j; @p blend is the blend baseline's row on the recording.
std::string ErrorSourcesSection(const Row& blend, const std::vector<ErrorSources>& sources, nlohmann::json& j);

/// What the later sections take from the hold-out runs.
struct HoldOutResults
{
  GaussianField LiverField; ///< the liver's field at the end of its run (render speed against error)
  RenderOptions LiverOptions;
  Row LiverAtCapacityTime;             ///< the liver's default run at CapacitySeconds (the full method)
  std::vector<std::vector<Row>> Bigus; ///< per sweep, its BIGUS rows at the time marks
};

/// The volume protocol's runs that the defaults table reads (issue 19), per test sweep (in-between,
/// oblique, orthogonal): the compounded volume resliced, the trainer's defaults with only a time budget,
/// and the same budget with the hand-tuned sigma (VolumeProtocol::ElevationSigma).
struct VolumeBudgetResults
{
  double Budget = 0; ///< s; 0 until the runs are done
  Row Compounded[3], Defaults[3], Tuned[3];
  /// Where the defaults run's in-between error comes from (MeasureVolumeErrorSources), and the blend of
  /// the recorded training slices on each side of the in-between slices (the recording's interpolation).
  ErrorSources DefaultsSources;
  Row RecordedBlend;
  /// The same blend with each training slice used only where its mask says it holds data (what the trainer
  /// sees), and the pixels where both slices hold data: their share of the in-between slices' scored pixels
  /// and the defaults run's and the recorded blend's scores there.
  Row MaskedBlend;
  double BothHoldDataShare = 0;
  ImageMetrics DefaultsWhereBothHoldData, RecordedBlendWhereBothHoldData;
};

/// The volume protocol's compounded baseline and its defaults and hand-tuned runs at a time budget (600 s,
/// issue 19's 10 minutes; 4 s quick), each scored on the three test sweeps, into @p out.
bool VolumeBudgetRuns(const VolumeProtocol& vp, bool quick, VolumeBudgetResults& out, std::string* error);

/// Training time (s) of each capacity run, and the time mark of the liver's full method they are
/// compared with.
double CapacitySeconds(bool quick);

/// What the sections share: the options, the report they write to, the bundled sweeps and the results that
/// later sections read from earlier ones (none is kept anywhere else between sections).
struct BenchmarkContext
{
  benchmark::Report& Report;
  std::string Root; ///< project root holding Examples/Data and Testing/Data
  bool Quick = false;
  /// BundledSweeps: each loaded by its hold-out section, or before the sections when one runs alone.
  std::vector<Sweep> Sweeps;
  HoldOutResults HoldOut;     ///< filled by the hold-out sections (empty when they did not run)
  VolumeBudgetResults Volume; ///< filled by the volume protocol section, or by the defaults section
};

// The sections, in the order RunBenchmark runs them. Each writes its part of context.Report and returns
// false with @p error when a file cannot be read or written or a run fails.

/**
 * The section of sweep @p si of BundledSweeps (context.Sweeps) with the hold-out protocol: the baselines,
 * BIGUS at the sweep's time marks, the blurred truth for scale, where the held-out error comes from, and the
 * plot psnr_time_<si>.png. The liver (si 0) also runs to the capacity section's time and keeps its field
 * (context.HoldOut).
 */
bool HoldOutSection(BenchmarkContext& context, std::size_t si, std::string* error);

/// The volume protocol section: BIGUS (hand-tuned sigma, a fixed schedule) at time marks, then the
/// compounded baseline and the budget runs of VolumeBudgetRuns (kept in context.Volume for the defaults
/// table).
bool VolumeProtocolSection(BenchmarkContext& context, std::string* error);

/// Quality against the number of Gaussians on the liver: capped runs against the adaptive stop
/// (context.HoldOut.LiverAtCapacityTime, the default run at the capacity time).
bool CapacitySection(BenchmarkContext& context, std::string* error);

/// Render time per slice against the error from the naive double-precision renderer, per cutoff, for
/// the liver field at the end of its run (context.HoldOut).
bool RenderSection(BenchmarkContext& context, std::string* error);

/**
 * Issue 21: every switch of the method against the full method (the trainer's defaults) at equal
 * iterations and at equal wall time, on the liver, the spine phantom, the N-wire phantom and the volume
 * protocol, 3 seeds per cell (1 and one switch with --quick). Equal time: each run's time budget is the
 * schedule (TrainerSettings::TimeBudget). Equal iterations: the mean number of steps the full method did
 * in that time, as the schedule. Every run ends with the final prune; its time counts.
 */
bool AblationSection(BenchmarkContext& context, std::string* error);

/**
 * Issue 31, item 4: held-out PSNR against the number of Gaussians and against time, on the liver (20 of
 * its frames with --quick), the spine phantom and the volume protocol (in-between slices). Three methods:
 * the trainer's defaults (Adam alone, Harris seeds), variable projection (the same, with the reflectivities
 * solved after seeding and after every densification; TrainerSettings::ReflectivitySolve), each to time
 * budgets of 30 and 120 s; and the regular grid with the same solve and no training (DenseInitialisation:
 * Gaussians on the training frames' pixel grid) at the count each adaptive run ended with. Every run ends
 * with the final prune and gap filling, and its time counts them and the initialisation (seeding, solves).
 * The adaptive field should lie above the grid at every count; where it does not, the report says by how
 * much and compares the two fits of the training frames.
 */
bool ParetoSection(BenchmarkContext& context, std::string* error);

/**
 * Defaults against hand-tuned (issue 19's aims): per hold-out sweep, the trainer's defaults with only a
 * time budget (what `bigus train SWEEP --time-budget T` does) against the same budget with the
 * elevation sigma chosen by hand for that sweep, and against the hand-tuned fixed-schedule run of the
 * sweep's section at the same time (context.HoldOut, when it ran); then the volume protocol's in-between
 * and oblique test sweeps from context.Volume (its runs are made here when the volume section did not run).
 */
bool DefaultsSection(BenchmarkContext& context, std::string* error);

/**
 * Block hold-outs on the liver, context.Sweeps[0] (issue 19's gaps): 8 and 20 consecutive frames (--quick: 8)
 * in the middle of the sweep held out and every other valid frame trained on, so the held-out poses lie in a
 * gap wider than the beam. The baselines and BIGUS with its defaults at the sweep's DefaultsBudget. The sweep's
 * own frame lists are restored before returning.
 */
bool BlockHoldOutSection(BenchmarkContext& context, std::string* error);

/**
 * Issue 33, several sweeps: the volume protocol's parallel training sweep and an orthogonal sweep trained into
 * one field (bigus::TrainingDataFromSweeps), scored on the oblique and in-between test slices against
 * compounding both sweeps (and each alone) and each sweep's slices stacked and resliced: BIGUS's defaults with a
 * 120 s budget, and Harris seeds with Adam at 60, 300 and 600 s (4 s with --quick).
 */
bool SeveralSweepsSection(BenchmarkContext& context, std::string* error);

/**
 * Issue 58: the main job (the liver's hold-out protocol, the trainer's defaults with a time budget) scored at 10, 30,
 * 60 and 100 s (1 and 2 s with --quick) on the training backend of --backend (TrainingBackend) and, where that is not
 * the CPU, on the CPU engine of the same machine in the same run; each backend's self-check is printed with the
 * table. Run alone (`--section gpu`), not with "all".
 */
bool GpuSection(BenchmarkContext& context, std::string* error);
}

#endif
