// The pose-refinement stage (see bigusPoseRefinement.h and DESIGN section 4).
#include "bigusPoseRefinement.h"

#include "bigusAdam.h"
#include "bigusSliceFrame.h"

#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>

namespace bigus
{

namespace
{
/// One Adam step (t counts from 1) of @p count double parameters @p x with their moments.
void AdamSteps(int count, const double* g, const double* rate, int t, double* x, double* first, double* second)
{
  const AdamBias bias = AdamBiasAt(t);
  for (int k = 0; k < count; ++k)
  {
    AdamUpdate(x[k], first[k], second[k], g[k], rate[k], bias);
  }
}

/// Whether any per-frame correction of @p state took an Adam step.
bool AnyCorrectionMoved(const TrainingState& state)
{
  return std::any_of(state.PoseSteps.begin(), state.PoseSteps.end(), [](int steps) { return steps > 0; });
}

/// Drops every per-frame correction of @p state, its Adam moments and step counts, and the kept copies (the best
/// field's, the parameter average's): a checkpoint then holds no count of corrections the run does not have.
void ClearCorrections(TrainingState& state)
{
  for (auto* v : { &state.PoseCorrections, &state.PoseFirstMoment, &state.PoseSecondMoment, &state.BestPoseCorrections,
         &state.AveragePoseCorrections })
  {
    v->clear();
  }
  state.PoseSteps.clear();
}
}

void PoseRefiner::Configure(TrainingData* data, const PoseRefinementSettings& settings,
  const std::function<const std::vector<SweepDecorrelation>&()>& measured, TrainingState& state,
  std::vector<std::string>& lines)
{
  this->Data = data;
  this->Settings = settings;
  PoseRefinementSettings& s = this->Settings;
  // Auto is resolved here, sweep by sweep, from the speckle of neighbouring training frames.
  std::string refinedBy = "given";
  this->RefinedSweeps.assign(data->SweepCount(), s.RefinePoses == PoseRefinement::On ? 1 : 0);
  if (s.RefinePoses == PoseRefinement::Auto)
  {
    const PoseRefinementChoice choice = ChoosePoseRefinement(measured());
    this->RefinedSweeps = choice.Sweeps;
    s.RefinePoses = choice.Any() ? PoseRefinement::On : PoseRefinement::Off;
    refinedBy = "chosen: " + choice.Reason;
    // (Not with a shared correction refined: the branches would differ in it too, and the held-out frames are scored
    // at poses it moves.)
    this->TrialPending = choice.Any() && s.TrialSteps > 0 && !s.RefineTimeOffset && !s.RefineImageToProbe;
    if (!choice.Any())
    {
      lines.push_back("RefinePoses = off (" + refinedBy + ")");
    }
  }
  // The start of the corrections, where not given: from the jitter of the corrected sweeps' tracked paths (every
  // sweep where only the shared corrections are refined). A pending trial keeps the path's rule too: where the trial
  // cannot run, the path decides (RefineUntested).
  std::string startBy;
  this->TrialFraction = 0;
  const bool chosen = s.Start < 0;
  this->PathStart = PoseRefinementStartChoice();
  if (chosen || this->TrialPending)
  {
    this->PathStart =
      ChoosePoseRefinementStart(*data, s.RefinePoses == PoseRefinement::On ? this->RefinedSweeps : std::vector<char>());
  }
  if (chosen)
  {
    s.Start = this->PathStart.Start;
    startBy = this->PathStart.Reason;
    if (this->TrialPending && s.Start < TrialStart && this->PathStart.Jitters)
    {
      // The corrections move from the path's start and the trial, later, measures whether to keep them: a trial
      // that delayed them cost the jittered liver 0.34 dB at 3,000 steps.
      startBy += vtkfmt::sprintf("; the pose trial at %.0f %% of the schedule (refined on, or the tracked poses from "
                                 "there; from the seeds' field its branches score alike)",
        100 * TrialStart);
      this->TrialFraction = TrialStart;
    }
    else if (this->TrialPending && s.Start < TrialStart)
    {
      // Refinement comes only through the trial here, and a trial scored earlier keeps the tracked poses whatever
      // they are.
      startBy = vtkfmt::sprintf("chosen: the pose trial's start, %.0f %% (from the seeds' field or from 20 %% its "
                                "branches score alike); the path's jitter alone: %.0f %%, %s",
        100 * TrialStart, 100 * s.Start, startBy.substr(std::string("chosen: ").size()));
      s.Start = TrialStart;
    }
  }
  this->TrialFraction = std::max(this->TrialFraction, s.Start);
  if (s.RefinePoses == PoseRefinement::On)
  {
    // The frames' prior: a tracker's noise as each refined sweep's path shows it (PosePriorScale).
    this->PriorScales.assign(data->SweepCount(), 1.0);
    std::string prior;
    for (int sweep = 0; sweep < data->SweepCount(); ++sweep)
    {
      if (!this->IsSweepRefined(sweep))
      {
        continue;
      }
      const double jitter = s.PriorFromPath ? TrackedPathJitter(*data, sweep) : -1;
      const double k = this->PriorScales[sweep] =
        PosePriorScale(*data, sweep, PosePriorJitterRatio * jitter, s.RotationSigma, s.TranslationSigma);
      prior += (prior.empty() ? "" : ", ") +
        (data->SweepCount() > 1 ? vtkfmt::sprintf("sweep %d ", sweep) : std::string()) +
        vtkfmt::sprintf("%.3g degrees and %.3g mm", k * s.RotationSigma * 180 / M_PI, k * s.TranslationSigma) +
        (jitter >= 0
            ? vtkfmt::sprintf(" (%g x its tracked path's jitter, %.3f mm at the corners)", PosePriorJitterRatio, jitter)
            : "");
    }
    this->RuleText =
      vtkfmt::sprintf("from %.0f %% of the schedule, %sAdam %.3g rad and %.3g mm per step; prior %.3g at %s, "
                      "smoothness %.3g; ",
        100 * s.Start, startBy.empty() ? "" : startBy + "; ", s.RotationLearningRate, s.TranslationLearningRate,
        s.Prior, prior, s.Smoothness) +
      refinedBy;
    lines.push_back("RefinePoses = on (" + this->RuleText + ")");
    const std::size_t n = data->Poses.size();
    state.PoseCorrections.assign(n, {});
    state.PoseFirstMoment.assign(n, {});
    state.PoseSecondMoment.assign(n, {});
    state.PoseSteps.assign(n, 0);
  }
  else if (s.Any())
  {
    lines.push_back(vtkfmt::sprintf(
      "PoseRefinementStart = %.0f %% of the schedule (%s)", 100 * s.Start, startBy.empty() ? "given" : startBy));
  }
  // A change common to the frames of one smooth sweep is a warp of the scene the field takes up
  // (docs/FINDINGS.md, "Shared pose corrections"): said where it is switched on.
  const bool oneSweep = data->SweepCount() <= 1;
  const std::string caveat = oneSweep ? "; one sweep: not determined, sweeps whose frames cross are" : "";
  if (s.RefineTimeOffset)
  {
    lines.push_back(vtkfmt::sprintf("RefineTimeOffset = on (Adam %.3g s per step, prior %.3g at %.3g s",
                      s.TimeOffsetLearningRate, s.Prior, s.TimeOffsetSigma) +
      caveat + ")");
  }
  if (s.RefineImageToProbe)
  {
    lines.push_back(
      vtkfmt::sprintf("RefineImageToProbe = on (Adam %.3g rad and %.3g mm per step, prior %.3g at "
                      "%.3g degrees and %.3g mm",
        s.RotationLearningRate, s.TranslationLearningRate, s.Prior, s.RotationSigma * 180 / M_PI, s.TranslationSigma) +
      caveat + ")");
  }
  this->TrackedPoses.clear();
  this->TrackedValid.clear();
  if (s.Any())
  {
    this->TrackedPoses = data->Poses;
    for (const std::array<double, 16>& pose : this->TrackedPoses)
    {
      SliceFrame frame;
      const int f = static_cast<int>(this->TrackedValid.size());
      this->TrackedValid.push_back(data->IsValid(f) && ComputeSliceFrame(pose.data(), 90, frame) == PoseStatus::Ok);
    }
  }
}

bool PoseRefiner::Prepare(std::string* error)
{
  if (this->Settings.RefineTimeOffset && !this->Timeline.Build(*this->Data, this->Settings.TimeOffsetWindow, error))
  {
    if (error)
    {
      *error = "RefineTimeOffset: " + *error;
    }
    return false;
  }
  return true;
}

void PoseRefiner::TurnOffCorrections(TrainingState& state, std::vector<std::string>& lines, const std::string& reason)
{
  if (this->Settings.RefinePoses != PoseRefinement::On)
  {
    return;
  }
  // The field says so too: no RefinedPoses where no frame moved.
  this->Settings.RefinePoses = PoseRefinement::Off;
  this->TrialPending = false;
  std::fill(this->RefinedSweeps.begin(), this->RefinedSweeps.end(), 0);
  ClearCorrections(state);
  for (std::string& line : lines)
  {
    if (line.rfind("RefinePoses = ", 0) == 0)
    {
      line = "RefinePoses = off (" + reason + ")";
    }
  }
}

bool PoseRefiner::ResetCorrections(TrainingState& state)
{
  const bool moved = AnyCorrectionMoved(state);
  if (moved)
  {
    for (auto* v : { &state.PoseCorrections, &state.PoseFirstMoment, &state.PoseSecondMoment })
    {
      std::fill(v->begin(), v->end(), std::array<double, 6>{});
    }
    std::fill(state.PoseSteps.begin(), state.PoseSteps.end(), 0);
    this->ComposePoses(state);
  }
  return moved;
}

bool PoseRefiner::RefineUntested(std::vector<std::string>& lines, const std::string& why)
{
  if (this->Settings.RefinePoses != PoseRefinement::On || !this->PathStart.Jitters)
  {
    return false;
  }
  this->TrialPending = false; // from Start, which is the path's where it was chosen
  const std::string chosen = "chosen: ", &path = this->PathStart.Reason;
  const std::string said = why +
    vtkfmt::sprintf("; refined without it from %.0f %% of the schedule, as the tracked path says: %s; the rule alone: ",
      100 * this->Settings.Start, path.rfind(chosen, 0) == 0 ? path.substr(chosen.size()) : path) +
    this->RuleText;
  for (std::string& line : lines)
  {
    if (line.rfind("RefinePoses = on (", 0) == 0)
    {
      line = "RefinePoses = on (" + said + ")";
    }
  }
  return true;
}

void PoseRefiner::AnnotateChoice(std::vector<std::string>& lines, const std::string& how) const
{
  const std::string on = "RefinePoses = on (";
  for (std::string& line : lines)
  {
    if (line.rfind(on, 0) == 0)
    {
      line.insert(on.size(), how + "; ");
    }
  }
}

void PoseRefiner::Step(
  const std::vector<int>& frames, const std::vector<double>& gradients, double rateScale, TrainingState& state)
{
  const PoseRefinementSettings& s = this->Settings;
  // Constant rates: decaying them as the means' rate decays measured no better on TestPoseRefinement's case.
  const double rotation = s.RotationLearningRate * rateScale, translation = s.TranslationLearningRate * rateScale;
  const double rate[7] = { rotation, rotation, rotation, translation, translation, translation,
    s.TimeOffsetLearningRate * rateScale };
  const double sigma[7] = { s.RotationSigma, s.RotationSigma, s.RotationSigma, s.TranslationSigma, s.TranslationSigma,
    s.TranslationSigma, s.TimeOffsetSigma };
  const bool shared = s.RefineTimeOffset || s.RefineImageToProbe;
  if (shared)
  {
    // The shared corrections move every frame: their gradient is the sum over the batch of the frames' pose
    // gradients (ImageToProbe, composed last) and of their dot products with the tracked path's velocity (the
    // time offset).
    std::array<double, 7>& x = state.SharedPoseCorrection;
    double g[7] = { 0, 0, 0, 0, 0, 0, 0 };
    for (std::size_t b = 0; b < frames.size(); ++b)
    {
      const double* gb = &gradients[6 * b];
      if (!std::all_of(gb, gb + 6, [](double v) { return std::isfinite(v); }))
      {
        continue;
      }
      for (int k = 0; k < 6; ++k)
      {
        g[k] += gb[k];
        g[6] += s.RefineTimeOffset ? gb[k] * this->Timeline.Velocity(frames[b])[k] : 0.0;
      }
    }
    for (int k = 0; k < 7; ++k)
    {
      const bool refined = k < 6 ? s.RefineImageToProbe : s.RefineTimeOffset;
      g[k] = refined ? g[k] + s.Prior * x[k] / (sigma[k] * sigma[k]) : 0.0;
    }
    AdamSteps(7, g, rate, ++state.SharedPoseSteps, x.data(), state.SharedPoseFirstMoment.data(),
      state.SharedPoseSecondMoment.data());
  }
  const TrainingData& data = *this->Data;
  for (std::size_t b = 0; b < frames.size() && s.RefinePoses == PoseRefinement::On; ++b)
  {
    const int f = frames[b];
    const int sweep = data.SweepOf(f);
    if (!this->IsSweepRefined(sweep))
    {
      continue;
    }
    std::array<double, 6>& xi = state.PoseCorrections[f];
    // The neighbours along the sweep: the training frames before and after this one in its sweep
    // (TrainFrames in order; none where they are not).
    const std::vector<int>& train = data.TrainFrames;
    const auto at = std::lower_bound(train.begin(), train.end(), f);
    const bool found = at != train.end() && *at == f;
    const auto& corrections = state.PoseCorrections;
    const std::array<double, 6>* before =
      found && at != train.begin() && data.SweepOf(*(at - 1)) == sweep ? &corrections[*(at - 1)] : nullptr;
    const std::array<double, 6>* after =
      found && at + 1 != train.end() && data.SweepOf(*(at + 1)) == sweep ? &corrections[*(at + 1)] : nullptr;
    double g[6];
    bool finite = true;
    const double scale = this->PriorScales[sweep];
    for (int k = 0; k < 6; ++k)
    {
      double smooth = 0;
      for (const std::array<double, 6>* n : { before, after })
      {
        smooth += n ? xi[k] - (*n)[k] : 0.0;
      }
      g[k] = gradients[6 * b + k] + (s.Prior * xi[k] / (scale * scale) + s.Smoothness * smooth) / (sigma[k] * sigma[k]);
      finite = finite && std::isfinite(g[k]);
    }
    if (!finite)
    {
      continue; // a non-finite pose gradient moves none of the frame's correction
    }
    AdamSteps(
      6, g, rate, ++state.PoseSteps[f], xi.data(), state.PoseFirstMoment[f].data(), state.PoseSecondMoment[f].data());
  }
  if (shared)
  {
    this->ComposePoses(state);
    return;
  }
  for (int f : frames)
  {
    this->ComposePose(f, state);
  }
}

void PoseRefiner::ComposePoses(const TrainingState& state)
{
  for (int f = 0; f < this->Data->Count() && this->Settings.Any(); ++f)
  {
    this->ComposePose(f, state);
  }
}

void PoseRefiner::ComposePose(int frame, const TrainingState& state)
{
  const PoseRefinementSettings& s = this->Settings;
  if (!this->TrackedValid[frame])
  {
    return; // a pose the renderer rejects (an invalid frame) stays as it was recorded
  }
  const std::array<double, 7>& shared = state.SharedPoseCorrection;
  std::array<double, 16> pose = this->UncorrectedPose(frame, state);
  const int width = this->Data->Width, height = this->Data->Height;
  if (s.RefinePoses == PoseRefinement::On)
  {
    // The frame's own correction: stepped (a training frame) or set (a held-out one, CorrectUntrainedFrames).
    const std::array<double, 6>& xi = state.PoseCorrections[frame];
    if (state.PoseSteps[frame] > 0 || std::any_of(xi.begin(), xi.end(), [](double v) { return v != 0; }))
    {
      CorrectPose(pose.data(), width, height, xi.data(), pose.data());
    }
  }
  if (s.RefineImageToProbe)
  {
    CorrectPose(pose.data(), width, height, shared.data(), pose.data());
  }
  this->Data->Poses[frame] = pose;
}

std::array<double, 16> PoseRefiner::UncorrectedPose(int frame, const TrainingState& state) const
{
  std::array<double, 16> pose = this->TrackedPoses[frame];
  if (this->Settings.RefineTimeOffset)
  {
    this->Timeline.PoseAt(frame, state.SharedPoseCorrection[6], pose.data());
  }
  return pose;
}

PoseAnchor PoseRefiner::AnchorToTrackedPoses(TrainingState& state, GaussianField& field)
{
  PoseAnchor anchor;
  const PoseRefinementSettings& s = this->Settings;
  const TrainingData& data = *this->Data;
  if (s.RefinePoses != PoseRefinement::On)
  {
    return anchor;
  }
  if (!s.AnchorToTrackedPoses)
  {
    anchor.Line = "PoseAnchor = off (given: the field stays where the refined poses put it)";
    return anchor;
  }
  if (s.RefineTimeOffset || s.RefineImageToProbe)
  {
    // Refined to correct what the tracker gets wrong for every frame alike, the shared corrections move the scene on
    // purpose, and the per-frame corrections take part of it up (docs/FINDINGS.md, "Anchoring the refined scene").
    anchor.Line = "PoseAnchor = off (a shared correction is refined: the tracked poses are not where the scene lies)";
    return anchor;
  }
  std::vector<int> frames;
  for (int f : data.TrainFrames)
  {
    if (!this->IsSweepRefined(data.SweepOf(f)))
    {
      anchor.Line = "PoseAnchor = off (a sweep with trusted poses fixes where the scene lies)";
      return anchor;
    }
    if (this->TrackedValid[f])
    {
      frames.push_back(f);
    }
  }
  if (frames.empty())
  {
    return anchor;
  }
  // The four corners of every refined training frame, under its refined pose (a) and its tracked pose (b).
  const double width = data.Width - 1.0, height = data.Height - 1.0;
  Eigen::Matrix3Xd a(3, 4 * frames.size()), b(3, 4 * frames.size());
  Eigen::Index c = 0;
  for (int f : frames)
  {
    const double* p = data.Poses[f].data();
    const double* q = this->TrackedPoses[f].data();
    for (double i : { 0.0, width })
    {
      for (double j : { 0.0, height })
      {
        for (int k = 0; k < 3; ++k)
        {
          a(k, c) = p[4 * k] * i + p[4 * k + 1] * j + p[4 * k + 3];
          b(k, c) = q[4 * k] * i + q[4 * k + 1] * j + q[4 * k + 3];
        }
        ++c;
      }
    }
  }
  const Eigen::Matrix4d T = Eigen::umeyama(a, b, false);
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = T.topRightCorner<3, 1>();
  const Eigen::Matrix3Xd moved = (R * a).colwise() + t;
  auto rms = [&](const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& y) {
    return std::sqrt((x - y).colwise().squaredNorm().mean());
  };
  anchor.Frames = static_cast<int>(frames.size());
  anchor.BeforeMillimetres = rms(a, b);
  anchor.AfterMillimetres = rms(moved, b);
  anchor.MovedMillimetres = rms(moved, a);
  anchor.RotationDegrees = Eigen::AngleAxisd(R).angle() * 180 / M_PI;
  // Each refined training frame's correction puts it at T times its refined pose: CorrectPose moves a pose in its
  // own axes, so CorrectPose(T P, xi) = T CorrectPose(P, xi) and the ImageToProbe correction composed last follows.
  using RowMajor = Eigen::Matrix<double, 4, 4, Eigen::RowMajor>; // the poses' layout
  for (int f : frames)
  {
    const std::array<double, 16> from = this->UncorrectedPose(f, state);
    std::array<double, 16> corrected, target;
    CorrectPose(from.data(), data.Width, data.Height, state.PoseCorrections[f].data(), corrected.data());
    Eigen::Map<RowMajor>(target.data()) = T * Eigen::Map<const RowMajor>(corrected.data());
    PoseCorrectionBetween(from.data(), target.data(), data.Width, data.Height, state.PoseCorrections[f].data());
  }
  this->ComposePoses(state);
  // The field: mu' = R mu + t, each Gaussian's rotation R' = R R_i (quaternions as stored, w x y z, norm kept).
  const Eigen::Quaterniond rotation(R);
  for (std::int64_t i = 0; i < field.Count(); ++i)
  {
    float* mean = &field.Means[3 * i];
    const Eigen::Vector3d m = R * Eigen::Vector3d(mean[0], mean[1], mean[2]) + t;
    float* q = &field.Quaternions[4 * i];
    const Eigen::Quaterniond r = rotation * Eigen::Quaterniond(q[0], q[1], q[2], q[3]);
    for (int k = 0; k < 3; ++k)
    {
      mean[k] = static_cast<float>(m[k]);
    }
    q[0] = static_cast<float>(r.w());
    q[1] = static_cast<float>(r.x());
    q[2] = static_cast<float>(r.y());
    q[3] = static_cast<float>(r.z());
  }
  anchor.Applied = true;
  anchor.Line = vtkfmt::sprintf("PoseAnchor = on (the field and poses moved by %.3g degrees and %.3g mm rms onto "
                                "the tracked poses of %d refined training frames; their corners lay %.3g mm rms from "
                                "the tracked ones, %.3g mm after the motion)",
    anchor.RotationDegrees, anchor.MovedMillimetres, anchor.Frames, anchor.BeforeMillimetres, anchor.AfterMillimetres);
  return anchor;
}

UntrainedCorrection PoseRefiner::PlaceUntrainedFrames(TrainingState& state)
{
  if (this->Settings.RefinePoses != PoseRefinement::On)
  {
    return {};
  }
  const UntrainedCorrection placed = CorrectUntrainedFrames(*this->Data, state.PoseCorrections);
  this->ComposePoses(state);
  return placed;
}

std::vector<FramePoseCorrection> PoseRefiner::Corrections(const TrainingState& state) const
{
  std::vector<FramePoseCorrection> corrections;
  if (this->Settings.RefinePoses != PoseRefinement::On)
  {
    return corrections;
  }
  for (int f : this->Data->TrainFrames)
  {
    if (this->IsSweepRefined(this->Data->SweepOf(f)))
    {
      corrections.push_back({ f, state.PoseCorrections[f] });
    }
  }
  return corrections;
}

bool PoseRefiner::Resume(
  TrainingState& loaded, std::vector<std::string>& lines, const std::string& file, bool& trialDone, std::string* error)
{
  trialDone = false;
  // A checkpoint written before any correction moved holds the tracked poses alone: a run that keeps them (given, or
  // untested where its shorter schedule leaves no room for the trial) goes on from it without corrections.
  if (this->Settings.RefinePoses != PoseRefinement::On && !AnyCorrectionMoved(loaded))
  {
    ClearCorrections(loaded);
  }
  if (this->TrialPending && loaded.PoseCorrections.empty())
  {
    this->TurnOffCorrections(loaded, lines, "decided before the checkpoint " + file + " was written");
    trialDone = true;
  }
  else if (this->TrialPending && !this->MovesBeforeTrial() && AnyCorrectionMoved(loaded))
  {
    // Refined by the trial or untested (RefineUntested). Where they move before the trial, the trainer tells from
    // the checkpoint's step whether it ran.
    this->EndTrial();
    trialDone = true;
  }
  return this->CheckCheckpoint(loaded, file, error);
}

bool PoseRefiner::CheckCheckpoint(const TrainingState& loaded, const std::string& file, std::string* error) const
{
  const PoseRefinementSettings& s = this->Settings;
  auto fail = [&](const std::string& what) {
    if (error)
    {
      *error = file + ": " + what;
    }
    return false;
  };
  if (s.RefineTimeOffset && !this->Timeline.IsBuilt(this->Data->Count()))
  {
    return fail("a run that refines the time offset loads a checkpoint after Initialize");
  }
  // The pose corrections go on from where the checkpoint left them (the same settings, the same sweep).
  const bool refined = s.RefinePoses == PoseRefinement::On;
  const std::size_t frames = refined ? this->Data->Poses.size() : 0;
  if (loaded.PoseCorrections.size() != frames)
  {
    return fail("the checkpoint holds pose corrections of " + std::to_string(loaded.PoseCorrections.size()) +
      " frames and this run " + (refined ? "refines the poses of " : "refines the poses of none of ") +
      std::to_string(this->Data->Poses.size()) +
      " (resume with the settings and sweep the checkpoint was written with)");
  }
  const std::array<double, 7>& shared = loaded.SharedPoseCorrection;
  const bool imageToProbe = std::any_of(shared.begin(), shared.begin() + 6, [](double v) { return v != 0; });
  if ((imageToProbe && !s.RefineImageToProbe) || (shared[6] != 0 && !s.RefineTimeOffset))
  {
    return fail(std::string("the checkpoint holds ") + (imageToProbe ? "an ImageToProbe correction" : "a time offset") +
      " that this run does not refine (resume with the settings the checkpoint was written with)");
  }
  return true;
}

bool RefinePosesWithFieldFrozen(const GaussianField& field, TrainingData& data, const std::vector<int>& frames,
  const RenderOptions& options, const PoseRefinementSettings& settings, const ImageLossWeights& loss, int steps,
  const std::string& backend, std::vector<std::array<double, 6>>& corrections, std::string* error)
{
  std::unique_ptr<TrainingEngine> engine = CreateTrainingEngine(backend, error);
  OptimizerState frozen;
  frozen.Field = field;
  frozen.ResizeToField();
  if (!engine || !engine->SetData(&data, error) || !engine->Push(frozen, error))
  {
    return false;
  }
  // Every learning rate of the field 0: the engine's step gives the pose gradients and moves nothing.
  StepRequest request;
  request.Count = 1;
  request.Options = options;
  request.Loss = loss;
  request.MinimumLogScale = -1e30;
  request.MaximumLogScale = 1e30;
  double gradient[6];
  request.PoseGradients = gradient;
  const double rotation = settings.RotationLearningRate, translation = settings.TranslationLearningRate;
  const double rate[6] = { rotation, rotation, rotation, translation, translation, translation };
  const double sigma[2] = { settings.RotationSigma, settings.TranslationSigma };
  corrections.assign(frames.size(), {});
  std::vector<std::array<double, 6>> first(frames.size()), second(frames.size());
  std::vector<std::array<double, 16>> tracked;
  for (int f : frames)
  {
    tracked.push_back(data.Poses.at(f));
  }
  for (int t = 1; t <= steps; ++t)
  {
    for (std::size_t b = 0; b < frames.size(); ++b)
    {
      request.Frames = &frames[b];
      request.Iteration = t - 1;
      double value = 0;
      const StepStatus status = engine->Step(request, &value, error);
      if (status == StepStatus::Failed)
      {
        return false;
      }
      double g[6];
      bool finite = status == StepStatus::Done;
      for (int k = 0; k < 6 && finite; ++k)
      {
        g[k] = gradient[k] + settings.Prior * corrections[b][k] / (sigma[k / 3] * sigma[k / 3]);
        finite = std::isfinite(g[k]);
      }
      if (!finite)
      {
        engine->Restore();
        continue; // this frame's correction stays where it is for this step
      }
      AdamSteps(6, g, rate, t, corrections[b].data(), first[b].data(), second[b].data());
      CorrectPose(tracked[b].data(), data.Width, data.Height, corrections[b].data(), data.Poses[frames[b]].data());
    }
  }
  return true;
}

} // namespace bigus
