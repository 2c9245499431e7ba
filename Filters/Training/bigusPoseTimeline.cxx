#include "bigusPoseTimeline.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <utility>

namespace bigus
{
namespace
{
/// Whether frame @p f belongs to sweep @p sweep's tracked path: valid, with a pose the renderer accepts.
bool IsPathFrame(const TrainingData& data, int sweep, int f)
{
  SliceFrame frame;
  return data.SweepOf(f) == sweep && data.IsValid(f) &&
    ComputeSliceFrame(data.Poses[f].data(), 90, frame) == PoseStatus::Ok;
}
}

double TrackedPathJitter(const TrainingData& data, int sweep)
{
  // The four corner pixels of each usable frame of the sweep, in sequence order.
  std::vector<std::array<double, 12>> corners;
  for (int f = 0; f < data.Count(); ++f)
  {
    if (!IsPathFrame(data, sweep, f))
    {
      continue;
    }
    const double* m = data.Poses[f].data();
    std::array<double, 12> c;
    int k = 0;
    for (double j : { 0.0, data.Height - 1.0 })
    {
      for (double i : { 0.0, data.Width - 1.0 })
      {
        for (int r = 0; r < 3; ++r)
        {
          c[k++] = m[4 * r] * i + m[4 * r + 1] * j + m[4 * r + 3];
        }
      }
    }
    corners.push_back(c);
  }
  if (corners.size() < 3)
  {
    return -1;
  }
  double sum = 0;
  for (std::size_t f = 1; f + 1 < corners.size(); ++f)
  {
    for (int k = 0; k < 12; ++k)
    {
      const double d = corners[f][k] - 0.5 * (corners[f - 1][k] + corners[f + 1][k]);
      sum += d * d;
    }
  }
  const double meanSquare = sum / (4.0 * (corners.size() - 2)); // per corner
  return std::sqrt(meanSquare / 1.5);
}

double PosePriorScale(const TrainingData& data, int sweep, double jitter, double rotationSigma, double translationSigma)
{
  if (jitter < 0)
  {
    return 1;
  }
  for (int f = 0; f < data.Count(); ++f)
  {
    if (!IsPathFrame(data, sweep, f))
    {
      continue;
    }
    // The corners' offsets from the centre pixel are +-u +-v (u = (W - 1) / 2 column, v = (H - 1) / 2 row, mm):
    // their mean squared length is |u|^2 + |v|^2.
    const double* m = data.Poses[f].data();
    double radius2 = 0;
    for (int r = 0; r < 3; ++r)
    {
      const double u = 0.5 * (data.Width - 1) * m[4 * r], v = 0.5 * (data.Height - 1) * m[4 * r + 1];
      radius2 += u * u + v * v;
    }
    const double unit =
      std::sqrt(3 * translationSigma * translationSigma + 2 * rotationSigma * rotationSigma * radius2);
    return unit > 0 ? std::max(jitter, PosePriorLeastJitter) / unit : 1.0;
  }
  return 1;
}

PoseRefinementStartChoice ChoosePoseRefinementStart(const TrainingData& data, const std::vector<char>& sweeps)
{
  PoseRefinementStartChoice choice;
  std::string measured;
  double largest = -1;
  char text[96];
  for (int s = 0; s < data.SweepCount(); ++s)
  {
    if (!sweeps.empty() && (s >= static_cast<int>(sweeps.size()) || !sweeps[s]))
    {
      continue;
    }
    const double jitter = TrackedPathJitter(data, s);
    largest = std::max(largest, jitter);
    measured += measured.empty() ? "" : ",";
    measured += data.SweepCount() > 1 ? " sweep " + std::to_string(s) : std::string();
    std::snprintf(text, sizeof(text), " %.3f mm", jitter);
    measured += jitter < 0 ? std::string(" too few frames") : std::string(text);
  }
  const bool jitters = largest > PoseRefinementEarlyJitter;
  choice.Jitters = jitters;
  if (jitters)
  {
    choice.Start = 0; // else the struct's default, 0.2
  }
  std::snprintf(text, sizeof(text), " (%s %.3g mm)", jitters ? "over" : "not over", PoseRefinementEarlyJitter);
  choice.Reason = "chosen: the tracked path jitters from frame to frame by" +
    (measured.empty() ? std::string(" nothing measured") : measured) + text;
  return choice;
}

PoseStatus PoseCorrectionBetween(const double from[16], const double to[16], int width, int height, double xi[6])
{
  double Fa[3][3], Fb[3][3], oa[3], ob[3], planeA[3], planeB[3];
  PoseStatus status = ComputeRenderingFrame(from, 90, Fa, oa, planeA);
  if (status == PoseStatus::Ok)
  {
    status = ComputeRenderingFrame(to, 90, Fb, ob, planeB);
  }
  if (status != PoseStatus::Ok)
  {
    return status;
  }
  // CorrectSliceFrame: F' = E^T F and o' = o + F^T (pivot + t - E pivot), so E = F F'^T and
  // t = F (o' - o) - pivot + E pivot.
  Eigen::Matrix3d E;
  Eigen::Vector3d d;
  for (int i = 0; i < 3; ++i)
  {
    for (int j = 0; j < 3; ++j)
    {
      E(i, j) = Fa[i][0] * Fb[j][0] + Fa[i][1] * Fb[j][1] + Fa[i][2] * Fb[j][2];
    }
    d[i] = Fa[i][0] * (ob[0] - oa[0]) + Fa[i][1] * (ob[1] - oa[1]) + Fa[i][2] * (ob[2] - oa[2]);
  }
  const Eigen::AngleAxisd rotation(E);
  const Eigen::Vector3d omega = rotation.angle() * rotation.axis();
  double pivot[3];
  SliceCentre(planeA, width, height, pivot);
  const Eigen::Vector3d p(pivot[0], pivot[1], pivot[2]);
  const Eigen::Vector3d t = d - p + E * p;
  for (int k = 0; k < 3; ++k)
  {
    xi[k] = omega[k];
    xi[3 + k] = t[k];
  }
  return PoseStatus::Ok;
}

namespace
{
/// The kernel-weighted mean of @p frames' corrections at time @p t (bandwidth @p h; infinity: the plain mean),
/// leaving out frame @p skip; false when no frame is left.
bool KernelMean(const std::vector<int>& frames, const std::vector<double>& times, double t, double h, int skip,
  const std::vector<std::array<double, 6>>& corrections, double out[6])
{
  double sum[6] = {}, weights = 0;
  int nearest = -1;
  double nearestDistance = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < frames.size(); ++k)
  {
    if (frames[k] == skip)
    {
      continue;
    }
    const double d = std::abs(times[k] - t);
    const double w = std::isinf(h) ? 1.0 : std::exp(-0.5 * (d / h) * (d / h));
    for (int c = 0; c < 6; ++c)
    {
      sum[c] += w * corrections[frames[k]][c];
    }
    weights += w;
    if (d < nearestDistance)
    {
      nearestDistance = d;
      nearest = frames[k];
    }
  }
  if (nearest < 0)
  {
    return false;
  }
  for (int c = 0; c < 6; ++c)
  {
    out[c] = weights > 1e-300 ? sum[c] / weights : corrections[nearest][c]; // all far: the nearest frame's
  }
  return true;
}
}

UntrainedCorrection CorrectUntrainedFrames(const TrainingData& data, std::vector<std::array<double, 6>>& corrections)
{
  const int n = data.Count();
  const bool timed = static_cast<int>(data.Timestamps.size()) == n;
  std::vector<char> trained(n, 0);
  for (int f : data.TrainFrames)
  {
    trained[f] = data.IsValid(f);
  }
  // Each sweep's training frames and their times, in time order; the sweep's median interval between them.
  struct Sweep
  {
    std::vector<int> Frames;
    std::vector<double> Times;
    double Interval = 1;
  };
  std::vector<Sweep> sweeps;
  auto when = [&](int f) { return timed ? data.Timestamps[f] : static_cast<double>(f); };
  for (int f = 0; f < n; ++f)
  {
    const int sweep = data.SweepOf(f);
    if (sweep >= static_cast<int>(sweeps.size()))
    {
      sweeps.resize(sweep + 1);
    }
    if (trained[f])
    {
      sweeps[sweep].Frames.push_back(f);
    }
  }
  for (Sweep& sweep : sweeps)
  {
    std::stable_sort(sweep.Frames.begin(), sweep.Frames.end(), [&](int a, int b) { return when(a) < when(b); });
    std::vector<double> gaps;
    for (int f : sweep.Frames)
    {
      sweep.Times.push_back(when(f));
      if (sweep.Times.size() > 1 && sweep.Times.back() > sweep.Times[sweep.Times.size() - 2])
      {
        gaps.push_back(sweep.Times.back() - sweep.Times[sweep.Times.size() - 2]);
      }
    }
    if (!gaps.empty())
    {
      std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
      sweep.Interval = gaps[gaps.size() / 2];
    }
  }
  // A correction's displacement at the slice's corners, squared.
  auto displacement = [&](int f, const double* delta) {
    const double* m = data.Poses[f].data();
    const double su = std::sqrt(m[0] * m[0] + m[4] * m[4] + m[8] * m[8]);
    const double sv = std::sqrt(m[1] * m[1] + m[5] * m[5] + m[9] * m[9]);
    const double r2 = 0.25 * ((data.Width * su) * (data.Width * su) + (data.Height * sv) * (data.Height * sv));
    return r2 * (delta[0] * delta[0] + delta[1] * delta[1] + delta[2] * delta[2]) + delta[3] * delta[3] +
      delta[4] * delta[4] + delta[5] * delta[5];
  };
  // Every training frame of a sweep with others is predicted from them; no correction at all is the baseline.
  double none = 0;
  int predicted = 0;
  for (const Sweep& sweep : sweeps)
  {
    for (std::size_t k = 0; k < sweep.Frames.size() && sweep.Frames.size() > 1; ++k)
    {
      none += displacement(sweep.Frames[k], corrections[sweep.Frames[k]].data());
      ++predicted;
    }
  }
  UntrainedCorrection result;
  result.ErrorNone = predicted > 0 ? std::sqrt(none / predicted) : 0;
  result.ErrorChosen = result.ErrorNone;
  const double inf = std::numeric_limits<double>::infinity();
  const double bandwidths[] = { 0.5, 1, 2, 4, 8, 16, inf };
  double best = inf, chosen = 0;
  for (const double h : bandwidths)
  {
    double error = 0;
    for (const Sweep& sweep : sweeps)
    {
      for (std::size_t k = 0; k < sweep.Frames.size() && sweep.Frames.size() > 1; ++k)
      {
        const int f = sweep.Frames[k];
        double prediction[6], delta[6];
        KernelMean(sweep.Frames, sweep.Times, sweep.Times[k], h * sweep.Interval, f, corrections, prediction);
        for (int c = 0; c < 6; ++c)
        {
          delta[c] = prediction[c] - corrections[f][c];
        }
        error += displacement(f, delta);
      }
    }
    if (error < best)
    {
      best = error;
      chosen = h;
    }
  }
  if (predicted == 0 || !(best < none))
  {
    return result; // nothing predicts a training frame's correction better than none
  }
  result.Bandwidth = chosen;
  result.ErrorChosen = std::sqrt(best / predicted);
  for (int f = 0; f < n; ++f)
  {
    const Sweep& sweep = sweeps[data.SweepOf(f)];
    if (!trained[f] && data.IsValid(f) &&
      KernelMean(sweep.Frames, sweep.Times, when(f), chosen * sweep.Interval, -1, corrections, corrections[f].data()))
    {
      ++result.Frames;
    }
  }
  return result;
}

bool PoseTimeline::Build(const TrainingData& data, double window, std::string* error)
{
  const int n = data.Count();
  auto fail = [error](const std::string& what) {
    if (error)
    {
      *error = what;
    }
    return false;
  };
  if (static_cast<int>(data.Timestamps.size()) != n)
  {
    return fail("the frames have no timestamps (field data Timestamp, one per frame), so the time between "
                "tracker and video cannot be refined");
  }
  this->Width = data.Width;
  this->Height = data.Height;
  this->Poses = data.Poses;
  this->Velocities.assign(n, {});
  int sweeps = 0;
  for (int f = 0; f < n; ++f)
  {
    if (!std::isfinite(data.Timestamps[f]))
    {
      return fail("frame " + std::to_string(f) + ": its timestamp is not a finite number of seconds");
    }
    sweeps = std::max(sweeps, data.SweepOf(f) + 1);
  }
  for (int s = 0; s < sweeps; ++s)
  {
    // The sweep's valid frames with a pose the renderer accepts, in time order.
    std::vector<std::pair<double, int>> path;
    for (int f = 0; f < n; ++f)
    {
      SliceFrame frame;
      if (data.SweepOf(f) == s && data.IsValid(f) &&
        ComputeSliceFrame(data.Poses[f].data(), 90, frame) == PoseStatus::Ok)
      {
        path.emplace_back(data.Timestamps[f], f);
      }
    }
    std::stable_sort(path.begin(), path.end(),
      [](const std::pair<double, int>& a, const std::pair<double, int>& b) { return a.first < b.first; });
    if (path.size() < 2 || path.front().first == path.back().first)
    {
      return fail("sweep " + std::to_string(s) +
        ": no two frames with a valid pose and different timestamps, so it has no tracked path in time");
    }
    for (std::size_t k = 0; k < path.size(); ++k)
    {
      const double t = path[k].first;
      // a: the last frame at or before t - window / 2 (else the first); b: the first at or after t + window / 2
      // (else the last); further apart when they share a timestamp.
      std::size_t a = k, b = k;
      while (a > 0 && path[a].first > t - 0.5 * window)
      {
        --a;
      }
      while (b + 1 < path.size() && path[b].first < t + 0.5 * window)
      {
        ++b;
      }
      while (path[b].first == path[a].first)
      {
        a = a > 0 ? a - 1 : a;
        b = b + 1 < path.size() ? b + 1 : b;
      }
      const int f = path[k].second;
      double xa[6], xb[6];
      PoseCorrectionBetween(data.Poses[f].data(), data.Poses[path[a].second].data(), data.Width, data.Height, xa);
      PoseCorrectionBetween(data.Poses[f].data(), data.Poses[path[b].second].data(), data.Width, data.Height, xb);
      for (int c = 0; c < 6; ++c)
      {
        this->Velocities[f][c] = (xb[c] - xa[c]) / (path[b].first - path[a].first);
      }
    }
  }
  return true;
}

void PoseTimeline::PoseAt(int frame, double offset, double pose[16]) const
{
  if (offset == 0)
  {
    std::copy(this->Poses[frame].begin(), this->Poses[frame].end(), pose);
    return;
  }
  double xi[6];
  for (int k = 0; k < 6; ++k)
  {
    xi[k] = offset * this->Velocities[frame][k];
  }
  CorrectPose(this->Poses[frame].data(), this->Width, this->Height, xi, pose);
}

} // namespace bigus
