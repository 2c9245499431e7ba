// `bigus benchmark`: the volume protocol on the PLUS reconstruction of the spine phantom: train on parallel
// slices, test on in-between, oblique and orthogonal slices, against the compounded volume resliced
// (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"

#include <cstdio>

namespace bigus::benchmark
{
namespace
{
/**
 * The volume protocol's account of the in-between error (as MeasureErrorSources for a hold-out sweep): the
 * field's fit of the training slices, its renders at the in-between slices, and the blend of its own renders
 * at the training slices on each side. In-between slice k lies midway between training slices k and k + 1
 * (vtkUltrasoundVolumeSweep, Offset 0.5), so the blends use the in-between slices 0 to N - 2 and weights 1/2;
 * @p out's RecordedBlend receives the same blend of the recorded training slices. The recorded blend reads a
 * training slice's pixels also where its mask says it holds no data (a sample that reads an unreconstructed
 * voxel), which the trainer never sees; so @p out also receives the blend within the training masks (each slice
 * only where it holds data, the other alone where one does, 0 where neither does) and the defaults' and the
 * recorded blend's scores on the pixels where both slices hold data, with those pixels' share of the scored ones.
 */
bool MeasureVolumeErrorSources(
  const VolumeProtocol& vp, Trainer& trainer, const Row& row, VolumeBudgetResults& out, std::string* error)
{
  ErrorSources& e = out.DefaultsSources;
  const TrainingData& train = vp.TrainData;
  const std::size_t pixels = std::size_t(train.Width) * train.Height;
  std::vector<float> renders(pixels * train.Count());
  for (int f : train.TrainFrames)
  {
    if (!trainer.RenderFrame(train, f, renders.data() + pixels * f, error))
    {
      return false;
    }
  }
  const std::vector<int> between(vp.TestList[0].begin(), vp.TestList[0].end() - 1);
  std::vector<float> blend(pixels);
  auto blendOf = [&](const float* frames) {
    return [&, frames](std::size_t, int k) {
      for (std::size_t p = 0; p < pixels; ++p)
      {
        blend[p] = 0.5f * (frames[pixels * k + p] + frames[pixels * (k + 1) + p]);
      }
      return static_cast<const float*>(blend.data());
    };
  };
  e.Seconds = row.Seconds;
  e.Training = MeanFrameMetrics(train, train.TrainFrames, [&](std::size_t, int f) { return &renders[pixels * f]; });
  if (!trainer.EvaluateOn(vp.TestData[0], between, e.HeldOut, error))
  {
    return false;
  }
  e.BlendedRenders = MeanFrameMetrics(vp.TestData[0], between, blendOf(renders.data()));
  out.RecordedBlend.Method = "blend of the training slices on each side (recorded)";
  out.RecordedBlend.Quality = MeanFrameMetrics(vp.TestData[0], between, blendOf(train.Frames.data()));

  out.MaskedBlend.Method = "blend of the training slices on each side, each where its mask holds data";
  out.MaskedBlend.Quality = MeanFrameMetrics(vp.TestData[0], between, [&](std::size_t, int k) {
    const unsigned char* a = train.MaskOf(k);
    const unsigned char* b = train.MaskOf(k + 1);
    const float* frames = train.Frames.data();
    for (std::size_t p = 0; p < pixels; ++p)
    {
      const float va = frames[pixels * k + p], vb = frames[pixels * (k + 1) + p];
      blend[p] = a[p] && b[p] ? 0.5f * (va + vb) : a[p] ? va : b[p] ? vb : 0.f;
    }
    return static_cast<const float*>(blend.data());
  });
  // The in-between slices' masks narrowed to where both training slices on each side hold data.
  TrainingData both = vp.TestData[0];
  both.Mask.resize(pixels * both.Count());
  std::int64_t scored = 0, kept = 0;
  for (int k = 0; k < both.Count(); ++k)
  {
    std::copy_n(vp.TestData[0].MaskOf(k), pixels, both.Mask.data() + pixels * k);
  }
  for (int k : between)
  {
    unsigned char* mask = both.Mask.data() + pixels * k;
    const unsigned char* a = train.MaskOf(k);
    const unsigned char* b = train.MaskOf(k + 1);
    for (std::size_t p = 0; p < pixels; ++p)
    {
      scored += mask[p] != 0;
      mask[p] = mask[p] && a[p] && b[p];
      kept += mask[p] != 0;
    }
  }
  out.BothHoldDataShare = scored > 0 ? double(kept) / double(scored) : 0.0;
  out.RecordedBlendWhereBothHoldData = MeanFrameMetrics(both, between, blendOf(train.Frames.data()));
  return trainer.EvaluateOn(both, between, out.DefaultsWhereBothHoldData, error);
}

/// @p row (a run's time, Gaussians, note) scored with @p trainer's field on each of the volume protocol's
/// three test sweeps, into @p rows.
bool ScoreVolume(Trainer& trainer, const VolumeProtocol& vp, const Row& row, Row rows[3], std::string* error)
{
  for (int t = 0; t < 3; ++t)
  {
    rows[t] = row;
    double secondsPerFrame = 0;
    if (!trainer.EvaluateOn(vp.TestData[t], vp.TestList[t], rows[t].Quality, error, &secondsPerFrame))
    {
      return false;
    }
    rows[t].MsPerFrame = 1e3 * secondsPerFrame;
    Print("volume", rows[t]);
  }
  return true;
}
}

/**
 * "More data is never worse": the trainer's defaults on 40, 80, 160 and 240 parallel training slices of the volume
 * (quick: 20 and 40) at one time budget (240 slices hold more than twice MaximumGaussians fan pixels: the route's
 * rule takes Harris seeds and Adam there, and the route trial decides), each scored on its own in-between slices and on
 * the same oblique and orthogonal slices, beside the two baselines made from the same slices (compounded, and stacked
 * as they are); a table and a verdict in @p context's report.
 */
bool SliceCounts(BenchmarkContext& context, std::string* error)
{
  const bool quick = context.Quick;
  const std::vector<int> counts = quick ? std::vector<int>{ 20, 40 } : std::vector<int>{ 40, 80, 160, 240 };
  const double budget = quick ? 4 : 60;
  std::ostringstream& md = context.Report.Markdown;
  nlohmann::json& j = context.Report.Json["volume_slice_counts"];
  md << "\n### More slices of the same volume\n\nThe trainer's defaults with a time budget of "
     << Format("%.0f", budget) << " s on " << counts.size() << " training sweeps of the same volume that differ "
     << "only in their number of parallel slices; each is scored on its own in-between slices (offset half its "
     << "spacing) and on the same oblique and orthogonal slices as above, beside the compounded volume and the "
     << "training slices stacked (the slice spacing between them) as they are and within their masks (0 where a "
     << "slice holds no data: only what the trainer is given), each resliced trilinearly.\n\n"
     << "| slices | spacing (mm) | method | time (s) | in-between PSNR (dB) | oblique PSNR (dB) | orthogonal PSNR "
     << "(dB) | Gaussians | note |\n|---|---|---|---|---|---|---|---|---|\n";
  std::vector<Row> bigus;     // [count][test] flattened: the defaults' rows
  std::ostringstream covered; // the table of the pixels where the stack reads only the training masks' data
  nlohmann::json& jc = context.Report.Json["volume_slice_counts_where_the_stack_reads_masked_data"];
  for (int count : counts)
  {
    VolumeProtocol vp;
    StackedSlices stack;
    if (!MakeVolumeProtocol(context.Root, quick, vp, error, count) || !StackSlices(vp, stack, error))
    {
      return false;
    }
    Row methods[4][3];
    CompoundVolume(vp, methods[0]);
    std::copy_n(stack.AsRecorded, 3, methods[1]);
    std::copy_n(stack.WithinMasks, 3, methods[2]);
    TrainerSettings defaults;
    defaults.Iterations = 0;
    defaults.TimeBudget = budget;
    Row row;
    ImageMetrics bigusCovered[3];
    auto score = [&](Trainer& trainer, Row& r) {
      if (!ScoreVolume(trainer, vp, r, methods[3], error))
      {
        return false;
      }
      for (int t = 0; t < 3; ++t)
      {
        if (!trainer.EvaluateOn(stack.Covered[t], vp.TestList[t], bigusCovered[t], error))
        {
          return false;
        }
      }
      return true;
    };
    if (!TrainToBudget(vp.TrainData, defaults, "BIGUS defaults", row, score, error))
    {
      return Failed(Format("volume protocol, %.0f slices: ", count) + *error, error);
    }
    covered << "| " << count;
    nlohmann::json entry = { { "slices", count } };
    for (int t = 0; t < 3; ++t)
    {
      covered << " | " << Format("%.1f", 100 * stack.CoveredShare[t]) << " % | "
              << Format("%.2f", stack.AsRecordedWhereCovered[t].PSNR) << " / " << Format("%.2f", bigusCovered[t].PSNR);
      entry[t == 0 ? "in_between"
          : t == 1 ? "oblique"
                   : "orthogonal"] = { { "share", stack.CoveredShare[t] },
        { "stacked_psnr", stack.AsRecordedWhereCovered[t].PSNR }, { "bigus_psnr", bigusCovered[t].PSNR } };
    }
    covered << " |\n";
    jc.push_back(entry);
    for (const auto& rows : methods)
    {
      md << "| " << count << " | " << Format("%.3f", vp.SliceSpacing) << " | " << rows[0].Method << " | "
         << Format("%.1f", rows[0].Seconds) << " | " << Format("%.2f", rows[0].Quality.PSNR) << " | "
         << Format("%.2f", rows[1].Quality.PSNR) << " | " << Format("%.2f", rows[2].Quality.PSNR) << " | "
         << (rows[0].Gaussians >= 0 ? std::to_string(rows[0].Gaussians) : "-") << " | " << rows[0].Note << " |\n";
      nlohmann::json entry = { { "slices", count }, { "spacing_mm", vp.SliceSpacing } };
      for (int t = 0; t < 3; ++t)
      {
        entry[t == 0 ? "in_between" : t == 1 ? "oblique" : "orthogonal"] = ToJson(rows[t]);
      }
      j.push_back(entry);
    }
    bigus.insert(bigus.end(), methods[3], methods[3] + 3);
  }
  // The verdict: on the shared oblique and orthogonal slices, no sweep with more slices scores lower.
  std::string lower;
  for (std::size_t k = 1; k < counts.size(); ++k)
  {
    for (int t = 1; t < 3; ++t)
    {
      const double drop = bigus[3 * (k - 1) + t].Quality.PSNR - bigus[3 * k + t].Quality.PSNR;
      if (drop > 0)
      {
        lower += Format("; %.0f slices", counts[k]) + Format(" score %.2f dB below ", drop) +
          Format("%.0f on the ", counts[k - 1]) + (t == 1 ? "oblique" : "orthogonal") + " slices";
      }
    }
  }
  md << "\nMore slices never scored lower on the shared oblique and orthogonal slices: "
     << (lower.empty() ? std::string("yes.") : "no" + lower + ".") << "\n";
  md << "\nThe stack as it is reads each training slice also outside its mask (samples of unreconstructed voxels, "
     << "which the trainer is not given). Scored only on the test pixels where every sample its trilinear reslice "
     << "weighs lies within the training masks (there the two stacks agree; share of the scored pixels, then the "
     << "stack's and the BIGUS defaults' PSNR in dB):\n\n"
     << "| slices | in-between: share | stacked / BIGUS | oblique: share | stacked / BIGUS | orthogonal: share | "
     << "stacked / BIGUS |\n|---|---|---|---|---|---|---|\n"
     << covered.str();
  return true;
}

bool VolumeProtocolSection(BenchmarkContext& context, std::string* error)
{
  const std::string& root = context.Root;
  const bool quick = context.Quick;
  Report& report = context.Report;
  VolumeBudgetResults& budgetRuns = context.Volume;
  std::ostringstream& md = report.Markdown;
  const std::vector<double> marks = quick ? std::vector<double>{ 5 } : std::vector<double>{ 30, 60, 180 };
  VolumeProtocol vp;
  if (!MakeVolumeProtocol(root, quick, vp, error))
  {
    return false;
  }
  const char* testNames[] = { "in-between parallel slices", "oblique slices (tilt up to 30 degrees)",
    "orthogonal slices" };
  std::printf("volume protocol: %s\n", vp.Description.c_str());
  TrainerSettings s;
  s.ElevationSigma = vp.ElevationSigma;
  s.Seeding.PixelGridFit = false; // training from Harris seeds, measured along the way; the defaults' fit is below
  s.Iterations = quick ? 300 : 15000;
  std::vector<Row> bigusRows[3];
  const bool ok = TrainWithMarks(
    vp.TrainData, s, marks, {}, "BIGUS, Harris seeds and Adam",
    [&](double, const Row& mark, Trainer& trainer) {
      Row rows[3];
      if (!ScoreVolume(trainer, vp, mark, rows, error))
      {
        return false;
      }
      for (int t = 0; t < 3; ++t)
      {
        bigusRows[t].push_back(rows[t]);
      }
      return true;
    },
    error);
  if (!ok)
  {
    return Failed("volume protocol: " + *error, error);
  }
  if (!VolumeBudgetRuns(vp, quick, budgetRuns, error))
  {
    return false;
  }
  std::vector<Row> baselineRows[3];
  for (int t = 0; t < 3; ++t)
  {
    baselineRows[t].push_back(budgetRuns.Compounded[t]);
    Print("volume", budgetRuns.Compounded[t]);
  }
  md << "\n## Volume protocol (spine-phantom reconstruction)\n\n"
     << vp.Description << " The rows measured along "
     << "one run train from Harris seeds with Adam (`--no-pixel-grid-fit`). The last two rows "
     << "train with only a time budget of " << Format("%.0f", budgetRuns.Budget) << " s as the schedule (the "
     << "trainer's defaults, then the hand-tuned sigma) and include the final prune and gap filling; here the "
     << "defaults take the pixel-grid fit (one Gaussian per fan pixel of the training slices fits under "
     << "MaximumGaussians: reflectivities solved, no geometry step), so they end long before the budget.\n";
  for (int t = 0; t < 3; ++t)
  {
    md << "\n### " << testNames[t] << "\n\n" << TableHeader();
    nlohmann::json j;
    for (const Row& r : baselineRows[t])
    {
      md << TableRow(r);
      j["baselines"].push_back(ToJson(r));
    }
    for (const Row& r : bigusRows[t])
    {
      md << TableRow(r);
      j["bigus"].push_back(ToJson(r));
    }
    for (const Row* r : { &budgetRuns.Defaults[t], &budgetRuns.Tuned[t] })
    {
      md << TableRow(*r);
      j["budget_runs"].push_back(ToJson(*r));
    }
    if (t == 0)
    {
      // ErrorSourcesSection's "held-out pose" is here the in-between slice, its bracketing training frames
      // the training slices on each side.
      j["recorded_blend"] = ToJson(budgetRuns.RecordedBlend);
      md << ErrorSourcesSection(budgetRuns.RecordedBlend, { budgetRuns.DefaultsSources }, j)
         << "(The defaults run at the budget, in-between slices 0 to " << vp.TestList[0].size() - 2
         << ", each midway between two training slices: the held-out poses of the table above; the recorded "
         << "blend is that of the training slices on each side, which the compounded volume approximates.)\n";
      const VolumeBudgetResults& v = budgetRuns;
      j["masked_blend"] = ToJson(v.MaskedBlend);
      j["where_both_hold_data"] = { { "share", v.BothHoldDataShare },
        { "defaults_psnr", v.DefaultsWhereBothHoldData.PSNR },
        { "recorded_blend_psnr", v.RecordedBlendWhereBothHoldData.PSNR } };
      md << "\nThe recorded blend reads each training slice also where the slice's mask says it holds no data (its "
         << "samples there read unreconstructed voxels), pixels the trainer never sees. The blend within the "
         << "training masks (each slice only where it holds data, the other alone where one does, 0 where neither "
         << "does) scores " << Format("%.2f", v.MaskedBlend.Quality.PSNR) << " dB. On the pixels where both "
         << "training slices on each side hold data (" << Format("%.1f", 100 * v.BothHoldDataShare)
         << " % of the scored pixels) the defaults score " << Format("%.2f", v.DefaultsWhereBothHoldData.PSNR)
         << " dB and the recorded blend " << Format("%.2f", v.RecordedBlendWhereBothHoldData.PSNR) << " dB.\n";
    }
    report.Json["volume_protocol"][testNames[t]] = j;
  }
  if (!SliceCounts(context, error))
  {
    return false;
  }
  PlotSpec spec =
    TimePlot("volume protocol: PSNR of the in-between slices against time", baselineRows[0], bigusRows[0]);
  spec.Series.push_back({ "BIGUS, oblique slices", {} });
  spec.Series.push_back({ "BIGUS, orthogonal slices", {} });
  for (int t = 1; t < 3; ++t)
  {
    for (const Row& r : bigusRows[t])
    {
      spec.Series[spec.Series.size() - 3 + t].Points.emplace_back(r.Seconds, r.Quality.PSNR);
    }
  }
  if (!report.Plot(spec, "psnr_time_volume.png"))
  {
    return Failed(report.PlotFolder + ": cannot write a plot", error);
  }
  return true;
}

bool VolumeBudgetRuns(const VolumeProtocol& vp, bool quick, VolumeBudgetResults& out, std::string* error)
{
  CompoundVolume(vp, out.Compounded);
  const double budget = quick ? 4 : 600;
  TrainerSettings defaults;
  defaults.Iterations = 0;
  defaults.TimeBudget = budget;
  TrainerSettings tuned = defaults;
  tuned.ElevationSigma = vp.ElevationSigma;
  auto run = [&](const TrainerSettings& settings, const std::string& method, Row rows[3], bool measureSources) {
    Row row;
    return TrainToBudget(
      vp.TrainData, settings, method, row,
      [&](Trainer& trainer, Row& r) {
        return ScoreVolume(trainer, vp, r, rows, error) &&
          (!measureSources || MeasureVolumeErrorSources(vp, trainer, r, out, error));
      },
      error);
  };
  if (!run(defaults, "BIGUS defaults, time budget only", out.Defaults, true) ||
    !run(tuned, "BIGUS, same budget, hand-tuned sigma", out.Tuned, false))
  {
    return Failed("volume protocol at " + Format("%.0f", budget) + " s: " + *error, error);
  }
  out.Budget = budget;
  return true;
}
}
