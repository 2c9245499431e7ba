// Pose refinement's shared corrections: the inverse of a pose correction, the tracked path's velocity
// (bigus::PoseTimeline), and a known field rendered at the liver sweep's tracked poses, recorded with a
// tracker-to-video time offset of 30 ms and a tracker error of 0.5 degrees and 0.5 mm per frame (issue 33).
// Per-frame refinement on the trainer's synthetic sweep (bigus::synthetic): held-out poses refined with the field
// frozen, and training poses perturbed at random brought back towards the truth.
#include "bigusPoseTimeline.h"
#include "bigusSliceFrame.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkUltrasoundSequenceReader.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <numeric>
#include <random>

using namespace bigus;
using namespace bigus::synthetic;

namespace
{
/// A pose of pixel spacing 0.3 mm: rotated about a tilted axis, away from the origin.
std::array<double, 16> TiltedPose()
{
  const double a = 0.4, b = -0.7;
  const double ca = std::cos(a), sa = std::sin(a), cb = std::cos(b), sb = std::sin(b);
  // Columns u, v (rotation about z by a, then about x by b), scaled by the spacing; origin (5, -3, 12).
  const double u[3] = { ca, sa * cb, sa * sb }, v[3] = { -sa, ca * cb, ca * sb };
  return { 0.3 * u[0], 0.3 * v[0], 0, 5.0, 0.3 * u[1], 0.3 * v[1], 0, -3.0, 0.3 * u[2], 0.3 * v[2], 0, 12.0, 0, 0, 0,
    1 };
}

void ExpectPosesNear(const double* a, const double* b, double tolerance)
{
  for (int k = 0; k < 16; ++k)
  {
    EXPECT_NEAR(a[k], b[k], tolerance) << "entry " << k;
  }
}

}

TEST(PoseTimeline, ThePoseCorrectionBetweenTwoPosesIsTheInverseOfCorrectPose)
{
  const std::array<double, 16> from = TiltedPose();
  const double xi[6] = { 0.21, -0.13, 0.35, 1.5, -2.25, 0.75 };
  double to[16], back[6];
  ASSERT_EQ(CorrectPose(from.data(), W, H, xi, to), PoseStatus::Ok);
  ASSERT_EQ(PoseCorrectionBetween(from.data(), to, W, H, back), PoseStatus::Ok);
  for (int k = 0; k < 6; ++k)
  {
    EXPECT_NEAR(back[k], xi[k], 1e-12) << "component " << k;
  }
  const double singular[16] = { 0.3, 0.3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1 }; // u parallel to v
  EXPECT_EQ(PoseCorrectionBetween(from.data(), singular, W, H, back), PoseStatus::Singular);
}

namespace
{
/// 60 frames in two sweeps (0 to 39, 40 to 59; 0.3 mm pixels of a W x H slice, timestamps 0.05 s apart with a
/// jitter), every 4th held out, frame 18 (held out) marked invalid.
TrainingData UntrainedCase()
{
  TrainingData d;
  d.Width = W;
  d.Height = H;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> jitter(-0.01, 0.01);
  for (int f = 0; f < 60; ++f)
  {
    d.Poses.push_back({ 0.3, 0, 0, 0, 0, 0.3, 0, 0, 0, 0, 0, 0.5 * f, 0, 0, 0, 1 });
    d.Timestamps.push_back(0.05 * (f % 40) + jitter(rng));
    d.Sweeps.push_back(f < 40 ? 0 : 1);
    d.Valid.push_back(f != 18);
    if (f % 4 != 2)
    {
      d.TrainFrames.push_back(f);
    }
  }
  return d;
}
}

TEST(PoseTimeline, UntrainedFramesTakeTheSmoothPartOfTheirSweepsCorrections)
{
  // Corrections that vary smoothly in time (a slow sine in the first sweep, a constant in the second), plus a
  // little noise: leave-one-out prediction chooses a kernel, and each held-out frame gets its sweep's smooth
  // correction at its time; the invalid frame and the training frames keep theirs.
  const TrainingData d = UntrainedCase();
  auto smooth = [&](int f) {
    const double t = d.Timestamps[f];
    return d.Sweeps[f] == 0 ? std::array<double, 6>{ 0.004 * std::sin(2.0 * t), -0.002 * std::cos(1.5 * t), 0.001,
      0.3 * std::sin(t), 0.1, -0.2 * t }
                            : std::array<double, 6>{ -0.003, 0.002, 0.004, 0.2, -0.1, 0.05 };
  };
  std::mt19937_64 rng(9);
  std::normal_distribution<double> noise(0, 1);
  const std::array<double, 6> unset = { 7, 7, 7, 7, 7, 7 };
  std::vector<std::array<double, 6>> xi(60, unset);
  for (int f : d.TrainFrames)
  {
    xi[f] = smooth(f);
    for (int c = 0; c < 6; ++c)
    {
      xi[f][c] += (c < 3 ? 1e-5 : 1e-3) * noise(rng);
    }
  }
  const std::vector<std::array<double, 6>> trained = xi;
  const UntrainedCorrection u = CorrectUntrainedFrames(d, xi);
  std::printf("smooth corrections: bandwidth %g intervals, leave-one-out %.4f mm against %.4f for none, %d frames\n",
    u.Bandwidth, u.ErrorChosen, u.ErrorNone, u.Frames);
  EXPECT_GT(u.Bandwidth, 0);
  EXPECT_LT(u.ErrorChosen, 0.1 * u.ErrorNone);
  EXPECT_EQ(u.Frames, 14) << "15 held-out frames but frame 18, which is invalid";
  for (int f = 0; f < 60; ++f)
  {
    const bool heldOut = f % 4 == 2 && f != 18;
    const std::array<double, 6>& expected = heldOut ? smooth(f) : (f == 18 ? unset : trained[f]);
    for (int c = 0; c < 6; ++c)
    {
      EXPECT_NEAR(xi[f][c], expected[c], heldOut ? (c < 3 ? 2e-4 : 0.02) : 0.0) << "frame " << f << ", component " << c;
    }
  }
}

TEST(PoseTimeline, UntrainedFramesKeepTheirPosesWhenTheCorrectionsAreIndependent)
{
  // Corrections drawn independently for every frame (a tracker's jitter): no kernel predicts a training frame's from
  // the others', so the held-out frames keep their tracked poses (their corrections as given), with or without
  // timestamps.
  for (bool timed : { true, false })
  {
    TrainingData d = UntrainedCase();
    if (!timed)
    {
      d.Timestamps.clear();
    }
    std::mt19937_64 rng(13);
    std::normal_distribution<double> normal(0, 1);
    std::vector<std::array<double, 6>> xi(60);
    for (int f : d.TrainFrames)
    {
      for (int c = 0; c < 6; ++c)
      {
        xi[f][c] = (c < 3 ? 0.008 : 0.5) * normal(rng);
      }
    }
    const std::vector<std::array<double, 6>> before = xi;
    const UntrainedCorrection u = CorrectUntrainedFrames(d, xi);
    EXPECT_EQ(u.Bandwidth, 0) << (timed ? "by time" : "by index");
    EXPECT_EQ(u.Frames, 0);
    EXPECT_EQ(u.ErrorChosen, u.ErrorNone);
    EXPECT_GT(u.ErrorNone, 0.5);
    EXPECT_EQ(xi, before);
  }
}

TEST(PoseTimeline, AFramesPoseMovesAlongThePathsVelocityOverTheWindow)
{
  // A constant motion in time: frame k at time t_k (unevenly spaced) has the pose CorrectPose(P0, t_k xi), a
  // rotation at constant angular velocity about the centre pixel while the centre moves at constant velocity.
  // Then a frame's pose at t_k + offset is CorrectPose(P0, (t_k + offset) xi).
  const std::array<double, 16> p0 = TiltedPose();
  const double xi[6] = { 0.05, -0.02, 0.08, 4.0, -1.0, 2.5 }; // per s
  TrainingData d;
  d.Width = W;
  d.Height = H;
  for (int k = 0; k < 12; ++k)
  {
    const double t = 0.04 * k + 0.002 * k * k;
    double step[6], pose[16];
    for (int c = 0; c < 6; ++c)
    {
      step[c] = t * xi[c];
    }
    ASSERT_EQ(CorrectPose(p0.data(), W, H, step, pose), PoseStatus::Ok);
    d.Poses.push_back({});
    std::copy(pose, pose + 16, d.Poses.back().begin());
    d.Timestamps.push_back(t);
  }
  PoseTimeline timeline;
  std::string error;
  ASSERT_TRUE(timeline.Build(d, 0.25, &error)) << error;
  for (int f : { 0, 5, 11 })
  {
    // Exactly: the rotation xi[0..2] and the centre's velocity xi[3..5] (P0's axes) in the frame's own axes,
    // what takes the frame to its pose a second later.
    double at[16], expected[16], step[6], velocity[6];
    for (int c = 0; c < 6; ++c)
    {
      step[c] = (d.Timestamps[f] + 1) * xi[c];
    }
    CorrectPose(p0.data(), W, H, step, expected);
    ASSERT_EQ(PoseCorrectionBetween(d.Poses[f].data(), expected, W, H, velocity), PoseStatus::Ok);
    for (int c = 0; c < 6; ++c)
    {
      EXPECT_NEAR(timeline.Velocity(f)[c], velocity[c], 1e-9 * (1 + std::abs(xi[c]))) << "frame " << f;
    }
    timeline.PoseAt(f, 0, at);
    EXPECT_EQ(std::vector<double>(at, at + 16), std::vector<double>(d.Poses[f].begin(), d.Poses[f].end()));
    for (int c = 0; c < 6; ++c)
    {
      step[c] = (d.Timestamps[f] + 0.03) * xi[c];
    }
    CorrectPose(p0.data(), W, H, step, expected);
    timeline.PoseAt(f, 0.03, at);
    ExpectPosesNear(at, expected, 1e-9);
  }

  // A frame the sweep marks invalid (its pose no tracked pose: here the first frame's) is left out of the path.
  TrainingData gap = d;
  gap.Valid.assign(12, 1);
  gap.Valid[6] = 0;
  gap.Poses[6] = p0;
  ASSERT_TRUE(timeline.Build(gap, 0.1, &error)) << error;
  for (int f : { 5, 7 })
  {
    for (int c = 0; c < 3; ++c)
    {
      EXPECT_NEAR(timeline.Velocity(f)[c], xi[c], 1e-9) << "frame " << f;
    }
  }
  EXPECT_EQ(timeline.Velocity(6), (std::array<double, 6>{})) << "no velocity of its own";

  // Each sweep has its own path: a second sweep standing still has velocity 0.
  TrainingData two = d;
  for (int k = 0; k < 12; ++k)
  {
    two.Poses.push_back(p0);
    two.Timestamps.push_back(0.05 * k);
  }
  two.Sweeps.assign(12, 0);
  two.Sweeps.insert(two.Sweeps.end(), 12, 1);
  ASSERT_TRUE(timeline.Build(two, 0.25, &error)) << error;
  EXPECT_NEAR(timeline.Velocity(3)[0], xi[0], 1e-9);
  EXPECT_NEAR(timeline.Velocity(15)[3], 0.0, 1e-12);

  // What cannot make a path: no timestamps, a non-finite one, a sweep whose frames share one timestamp.
  TrainingData bad = d;
  bad.Timestamps.clear();
  EXPECT_FALSE(timeline.Build(bad, 0.25, &error));
  EXPECT_NE(error.find("Timestamp"), std::string::npos) << error;
  bad = d;
  bad.Timestamps[3] = std::nan("");
  EXPECT_FALSE(timeline.Build(bad, 0.25, &error));
  EXPECT_NE(error.find("frame 3"), std::string::npos) << error;
  bad = two;
  std::fill(bad.Timestamps.begin() + 12, bad.Timestamps.end(), 1.0);
  EXPECT_FALSE(timeline.Build(bad, 0.25, &error));
  EXPECT_NE(error.find("sweep 1"), std::string::npos) << error;
}

namespace
{
/// The liver sweep's tracked poses (ImageToReference of a 64 x 64 window at the middle of its frames, its
/// pixel spacing 0.315 mm), every @p stride-th frame, and their timestamps.
bool LiverPath(int stride, std::vector<std::array<double, 16>>& poses, std::vector<double>& times)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(BIGUS_EXAMPLE_DATA "/liver/liver_sweep.igs.mha");
  reader->Update();
  vtkImageData* sweep = reader->GetOutput();
  vtkDataArray* matrices = sweep->GetFieldData()->GetArray("ImageToReference");
  vtkDataArray* stamps = sweep->GetFieldData()->GetArray("Timestamp");
  if (!matrices || !stamps)
  {
    return false;
  }
  const int i0 = sweep->GetDimensions()[0] / 2 - W / 2, j0 = sweep->GetDimensions()[1] / 2 - H / 2;
  for (vtkIdType f = 0; f < matrices->GetNumberOfTuples(); f += stride)
  {
    std::array<double, 16> m;
    matrices->GetTuple(f, m.data());
    for (int r = 0; r < 3; ++r)
    {
      m[4 * r + 3] += i0 * m[4 * r] + j0 * m[4 * r + 1];
    }
    poses.push_back(m);
    times.push_back(stamps->GetTuple1(f));
  }
  return !poses.empty();
}

/// Row-major pose @p m turned rigidly by @p R about @p centre (mm).
std::array<double, 16> Turned(const std::array<double, 16>& m, const Eigen::Matrix3d& R, const Eigen::Vector3d& centre)
{
  std::array<double, 16> out = m;
  for (int c = 0; c < 4; ++c)
  {
    const Eigen::Vector3d x(m[c], m[4 + c], m[8 + c]);
    const Eigen::Vector3d y = c == 3 ? Eigen::Vector3d(R * (x - centre) + centre) : Eigen::Vector3d(R * x);
    for (int r = 0; r < 3; ++r)
    {
      out[4 * r + c] = y[r];
    }
  }
  return out;
}

/// What LiverPathCase measured.
struct LiverPathResult
{
  double CornerErrorBefore = 0, CornerErrorAfter = 0;               ///< mm, training frames, against the true poses
  double TimeOffset = 0;                                            ///< s, refined
  std::array<double, 6> ImageToProbe{};                             ///< the refined ImageToProbe correction
  double Refined = 0, Trusting = 0, OnTruth = 0;                    ///< held-out PSNR at the true poses, dB
  double FairRefined = 0, FairTrusting = 0, FairOnTruth = 0;        ///< the fair score (FairPsnr), dB
  double AlignedCornerErrorBefore = 0, AlignedCornerErrorAfter = 0; ///< mm, after the best rigid motion of both sweeps
  double PoseRefinementStart = 0;                                   ///< the refined run's, as given or chosen
};

/**
 * Synthetic truth at the liver's path (issue 33), with the errors of @p e. Two sweeps along the liver's tracked path
 * (every @p stride-th frame): the path as recorded, and the path turned by 90 degrees about the frames' mean depth axis
 * through their mean centre, so that the second sweep's frames cross the first's. Frame k was imaged Offset (30 ms)
 * after its timestamp (a tracker whose poses arrive late): its true pose lies on the recorded path between the recorded
 * poses on either side (rotation about the centre pixel at constant angular velocity, the centre at constant velocity:
 * PoseCorrectionBetween, CorrectPose), not on PoseTimeline's first-order model. A known field (800 Gaussians at random
 * pixels of random true frames, within 1.5 mm of the plane) rendered there. The recorded poses: the path at the
 * timestamps, each moved by @p e's Degrees and Mm at random and then by its ImageToProbe correction. Three fields:
 * refining what @p e says, trusting the recorded poses, and trained on the true poses.
 */
struct LiverPathErrors
{
  int Stride = 1;                       ///< every Stride-th frame of the liver
  double Offset = 0.030;                ///< s: the frames were imaged this long after their timestamps
  double Degrees = 0, Mm = 0;           ///< each recorded pose moved this much at random
  std::array<double, 6> ImageToProbe{}; ///< every recorded pose moved by this correction (CorrectPose)
  bool PerFrame = false, TimeOffset = true, RefineImageToProbe = false; ///< what the refined run refines
  int Iterations = 2000;
  double PoseRefinementStart = TrainerSettings().Poses.Start; ///< of every run (the refined one's matters;
                                                              ///< default: chosen from the tracked path)
};

LiverPathResult LiverPathCase(const LiverPathErrors& e)
{
  LiverPathResult result;
  std::vector<std::array<double, 16>> recorded, truePoses;
  std::vector<double> times;
  EXPECT_TRUE(LiverPath(e.Stride, recorded, times));
  const double offset = e.Offset;
  const int n = static_cast<int>(recorded.size());
  for (int k = 0; k < n; ++k)
  {
    int from = k; // the last recorded pose at or before the shifted time (the last pair's first at the end)
    while (from + 2 < n && times[from + 1] <= times[k] + offset)
    {
      ++from;
    }
    from = std::min(from, n - 2);
    double xi[6];
    EXPECT_EQ(PoseCorrectionBetween(recorded[from].data(), recorded[from + 1].data(), W, H, xi), PoseStatus::Ok);
    const double s = (times[k] + offset - times[from]) / (times[from + 1] - times[from]);
    for (double& c : xi)
    {
      c *= s;
    }
    std::array<double, 16> pose;
    EXPECT_EQ(CorrectPose(recorded[from].data(), W, H, xi, pose.data()), PoseStatus::Ok);
    truePoses.push_back(pose);
  }
  Eigen::Vector3d axis = Eigen::Vector3d::Zero(), centre = Eigen::Vector3d::Zero();
  for (const std::array<double, 16>& m : recorded)
  {
    for (int r = 0; r < 3; ++r)
    {
      axis[r] += m[4 * r + 1];
      centre[r] += (m[4 * r + 3] + 0.5 * (W - 1) * m[4 * r] + 0.5 * (H - 1) * m[4 * r + 1]) / n;
    }
  }
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.5 * M_PI, axis.normalized()).toRotationMatrix();
  std::vector<int> sweeps(n, 0);
  for (int k = 0; k < n; ++k)
  {
    recorded.push_back(Turned(recorded[k], R, centre));
    truePoses.push_back(Turned(truePoses[k], R, centre));
    times.push_back(times[k]);
    sweeps.push_back(1);
  }
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u01(0, 1);
  std::normal_distribution<double> normal(0, 1);
  GaussianField field;
  for (int i = 0; i < 800; ++i)
  {
    const std::array<double, 16>& m = truePoses[static_cast<std::size_t>(u01(rng) * 2 * n) % (2 * n)];
    const double px = u01(rng) * (W - 1), py = u01(rng) * (H - 1), z = 3.0 * (u01(rng) - 0.5);
    const Eigen::Vector3d normalAxis =
      Eigen::Vector3d(m[0], m[4], m[8]).cross(Eigen::Vector3d(m[1], m[5], m[9])).normalized();
    for (int r = 0; r < 3; ++r)
    {
      field.Means.push_back(static_cast<float>(m[4 * r] * px + m[4 * r + 1] * py + m[4 * r + 3] + z * normalAxis[r]));
    }
    for (int k = 0; k < 3; ++k)
    {
      field.LogScales.push_back(static_cast<float>(std::log(0.4 + 0.8 * u01(rng))));
    }
    AppendRandomRotation(field, rng, normal);
    field.Reflectivities.push_back(static_cast<float>(0.25 + 0.2 * normal(rng)));
  }
  const double sigma = 0.5;
  std::vector<int> heldOut;
  TrainingData truth = RenderedSweep(field, truePoses, W, H, sigma, heldOut);
  truth.Timestamps = times;
  truth.Sweeps = sweeps;
  TrainingData tracked = truth;
  tracked.Poses = recorded;
  std::vector<int> every(2 * n);
  std::iota(every.begin(), every.end(), 0);
  tracked = PerturbedPoses(tracked, every, e.Degrees, e.Mm, 23, W, H);
  for (std::array<double, 16>& pose : tracked.Poses)
  {
    EXPECT_EQ(CorrectPose(pose.data(), W, H, e.ImageToProbe.data(), pose.data()), PoseStatus::Ok);
  }

  TrainerSettings s;
  s.ElevationSigma = sigma;
  s.Seeding.PixelGridFit = false;
  s.Seeding.InitialGaussians = 6000;
  s.Iterations = e.Iterations;
  s.Poses.Start = e.PoseRefinementStart;
  auto train = [&](const TrainingData& data, bool refine) {
    TrainerSettings settings = s;
    settings.Poses.RefinePoses = refine && e.PerFrame ? PoseRefinement::On : PoseRefinement::Off;
    settings.Poses.RefineTimeOffset = refine && e.TimeOffset;
    settings.Poses.RefineImageToProbe = refine && e.RefineImageToProbe;
    auto trainer = std::make_unique<Trainer>(data, settings);
    std::string error;
    EXPECT_TRUE(trainer->Initialize(&error)) << error;
    EXPECT_TRUE(trainer->Run(nullptr, nullptr, &error)) << error;
    return trainer;
  };
  const auto refined = train(tracked, true);
  const auto trusting = train(tracked, false);
  const auto onTruth = train(truth, false);
  result.CornerErrorBefore = CornerError(tracked, truth, truth.TrainFrames, W, H);
  result.CornerErrorAfter = CornerError(refined->GetData(), truth, truth.TrainFrames, W, H);
  result.TimeOffset = refined->GetReport().TimeOffset;
  result.PoseRefinementStart = refined->GetSettings().Poses.Start;
  result.ImageToProbe = refined->GetReport().ImageToProbeCorrection;
  result.Refined = PsnrAt(refined->GetField(), refined->Options(), truth, heldOut);
  result.Trusting = PsnrAt(trusting->GetField(), trusting->Options(), truth, heldOut);
  result.OnTruth = PsnrAt(onTruth->GetField(), onTruth->Options(), truth, heldOut);
  result.FairRefined = FairPsnr(refined->GetField(), refined->Options(), truth, heldOut, s);
  result.FairTrusting = FairPsnr(trusting->GetField(), trusting->Options(), truth, heldOut, s);
  result.FairOnTruth = FairPsnr(onTruth->GetField(), onTruth->Options(), truth, heldOut, s);
  result.AlignedCornerErrorBefore = AlignedCornerError(tracked, truth, truth.TrainFrames, W, H);
  result.AlignedCornerErrorAfter = AlignedCornerError(refined->GetData(), truth, truth.TrainFrames, W, H);
  std::printf("liver path, two crossing sweeps, %.0f ms late, %.2g degree and %.2g mm errors, %d steps (poses "
              "refined from %.0f %% of them): corner error %.3f -> %.3f mm; time offset %.1f ms; held-out PSNR at the "
              "true poses %.2f dB refined, %.2f trusting the recorded poses, %.2f trained on the true poses\n",
    1000 * e.Offset, e.Degrees, e.Mm, e.Iterations, 100 * result.PoseRefinementStart, result.CornerErrorBefore,
    result.CornerErrorAfter, 1000 * result.TimeOffset, result.Refined, result.Trusting, result.OnTruth);
  std::printf(
    "  aligned corner error %.3f -> %.3f mm; fair held-out PSNR (each frame's pose refined with the field frozen) "
    "%.2f dB refined, %.2f trusting, %.2f on the true poses\n",
    result.AlignedCornerErrorBefore, result.AlignedCornerErrorAfter, result.FairRefined, result.FairTrusting,
    result.FairOnTruth);
  std::printf("  the recorded paths jitter by %.3f and %.3f mm from frame to frame (TrackedPathJitter, sweeps 0, 1)\n",
    TrackedPathJitter(tracked, 0), TrackedPathJitter(tracked, 1));
  return result;
}
}

TEST(PoseRefinement, ATimeOffsetOnTheLiversPathIsFoundFromTwoCrossingSweeps)
{
  // The recorded poses exact but 30 ms early: refining the offset alone finds it. Measured: 25.6 ms, corner error
  // 0.384 -> 0.065 mm, held-out 44.31 dB against 36.84 trusting the recorded poses and 45.89 on the true poses
  // (27.6 ms, 0.041 mm, 44.58 dB before the resolution schedule became the default).
  // (With one sweep the offset is not found, -1.9 ms: a delay along a smooth path moves every frame along it,
  // a smooth warp of the scene that the field takes up; docs/FINDINGS.md.)
  const LiverPathResult r = LiverPathCase(LiverPathErrors());
  EXPECT_NEAR(r.TimeOffset, 0.030, 0.006);
  EXPECT_LT(r.CornerErrorAfter, 0.5 * r.CornerErrorBefore) << "the pose error falls by at least half";
  EXPECT_GT(r.Refined, r.Trusting + 4.0);
}

TEST(PoseRefinement, TrackerErrorsAndATimeOffsetOnTheLiversPathFallWithEachFramesCorrection)
{
  // The case: 0.5 degrees and 0.5 mm per frame at random, and 30 ms late; each frame's correction and the
  // offset refined, 16,000 steps, with the defaults: the recorded path jitters by more than 0.35 mm from frame to
  // frame, so the corrections move from the first step (PoseRefinementStart chosen 0; 0.2 trains the first fifth
  // on the recorded poses). The aims: the pose error falls by at least half, and held-out PSNR comes
  // within 0.5 dB of training on the true poses. Measured (every 2nd frame): corner error 0.597 -> 0.286 mm (52 %),
  // 0.538 -> 0.235 (56 %) after the rigid motion of the whole scene that no image tells; offset 13.3 ms (the
  // frames' own corrections take up part of it); held-out at the true poses 37.98 dB against 31.15 trusting the
  // recorded poses and 44.45 on the true poses; scored fairly (each held-out frame's pose refined with the field
  // frozen) 45.66 against 34.72 and 44.77. From 0.2 instead: 3,000 steps 0.291 aligned (46 %), fair 39.42
  // against 42.61 on the true poses; 8,000 steps 0.273 (49 %), 43.56 against 46.04 (docs/FINDINGS.md, "When
  // pose refinement starts").
  LiverPathErrors e;
  e.Stride = 2;
  e.Degrees = e.Mm = 0.5;
  e.PerFrame = true;
  e.Iterations = 16000;
  const LiverPathResult r = LiverPathCase(e);
  EXPECT_EQ(r.PoseRefinementStart, 0.0) << "chosen from the recorded path's jitter";
  EXPECT_LT(r.CornerErrorAfter, 0.5 * r.CornerErrorBefore) << "the pose error falls by at least half";
  EXPECT_LT(r.AlignedCornerErrorAfter, 0.5 * r.AlignedCornerErrorBefore);
  EXPECT_GT(r.TimeOffset, 0.005) << "the offset moves towards the truth";
  EXPECT_LT(r.TimeOffset, 0.045);
  EXPECT_GT(r.Refined, r.Trusting + 4.0);
  EXPECT_GT(r.FairRefined, r.FairOnTruth - 0.5) << "held out within 0.5 dB of training on the true poses";
  EXPECT_GT(r.FairRefined, r.FairTrusting + 8.0);
}

TEST(PoseRefinement, AnImageToProbeErrorSharedByEveryFrameIsFound)
{
  // Every recorded pose moved by one correction of ImageToProbe (0.55 degrees about a tilted axis, 0.53 mm across
  // the depth axis), no delay: refining the shared correction alone takes the poses back towards the truth. Not
  // along the depth axis: the two sweeps share it (the second is the first turned about it), so a shift along it
  // moves the whole scene, which no image tells (measured with 0.3 mm there: it stays, 0.006 mm found).
  LiverPathErrors e;
  e.Offset = 0;
  e.ImageToProbe = { 0.006, -0.004, 0.006, 0.4, 0, 0.35 };
  e.TimeOffset = false;
  e.RefineImageToProbe = true;
  const LiverPathResult r = LiverPathCase(e);
  std::printf("ImageToProbe correction found: %.4f %.4f %.4f rad, %.3f %.3f %.3f mm (the recorded poses' error: "
              "0.006 -0.004 0.006 rad, 0.4 0 0.35 mm, so the truth is about its opposite)\n",
    r.ImageToProbe[0], r.ImageToProbe[1], r.ImageToProbe[2], r.ImageToProbe[3], r.ImageToProbe[4], r.ImageToProbe[5]);
  // Measured: corner error 0.542 -> 0.076 mm, held-out 43.88 dB against 32.85 trusting the recorded poses and
  // 45.44 on the true poses (0.060 mm, 43.95 dB before the resolution schedule became the default).
  EXPECT_LT(r.CornerErrorAfter, 0.25 * r.CornerErrorBefore);
  EXPECT_GT(r.Refined, r.Trusting + 6.0);
}

namespace
{
/// A sweep of @p n frames of W x H pixels (0.3 mm) turning about an axis 20 mm from the image, @p degrees per
/// frame: every corner moves on a circle at constant speed.
TrainingData TurningSweep(int n, double degrees)
{
  TrainingData d;
  d.Width = W;
  d.Height = H;
  d.Frames.assign(std::size_t(n) * W * H, 0.f);
  d.Mask.assign(std::size_t(W) * H, 1);
  const std::array<double, 16> base = TiltedPose();
  for (int f = 0; f < n; ++f)
  {
    const Eigen::Matrix3d R = Eigen::AngleAxisd(f * degrees * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    std::array<double, 16> m = base;
    for (int c = 0; c < 4; ++c) // the linear part's columns and the translation, turned about the z axis
    {
      const Eigen::Vector3d v = R * Eigen::Vector3d(base[c], base[4 + c], base[8 + c] + (c == 3 ? 20.0 : 0.0));
      for (int r = 0; r < 3; ++r)
      {
        m[4 * r + c] = v[r];
      }
    }
    d.Poses.push_back(m);
    d.TrainFrames.push_back(f);
  }
  return d;
}

/// The four corners (mm) of pixel grid W x H under @p m.
std::array<Eigen::Vector3d, 4> Corners(const std::array<double, 16>& m)
{
  std::array<Eigen::Vector3d, 4> c;
  int k = 0;
  for (double j : { 0.0, H - 1.0 })
  {
    for (double i : { 0.0, W - 1.0 })
    {
      for (int r = 0; r < 3; ++r)
      {
        c[k][r] = m[4 * r] * i + m[4 * r + 1] * j + m[4 * r + 3];
      }
      ++k;
    }
  }
  return c;
}
}

TEST(PoseTimeline, TheTrackedPathsJitterIsTheRmsOfIndependentPoseErrorsAndNearZeroOnASmoothPath)
{
  // A smooth path: each corner at radius r_c turns by theta per frame, so its second difference is
  // r_c (1 - cos theta) exactly, and the jitter sqrt(mean_c (r_c (1 - cos theta))^2 / 1.5).
  const double theta = 0.4 * M_PI / 180;
  const TrainingData smooth = TurningSweep(200, 0.4);
  double expected = 0;
  for (const Eigen::Vector3d& c : Corners(smooth.Poses[0]))
  {
    const double r = std::hypot(c[0], c[1]); // distance from the z axis
    expected += std::pow(r * (1 - std::cos(theta)), 2) / 4;
  }
  expected = std::sqrt(expected / 1.5);
  EXPECT_NEAR(TrackedPathJitter(smooth, 0), expected, 1e-9 + 1e-6 * expected);
  EXPECT_LT(expected, 0.01) << "a smooth path barely jitters";

  // Independent errors of 0.5 degrees and 0.5 mm per frame: the jitter is the rms of their displacement at the
  // corners, within the sampling error of 200 frames.
  std::vector<int> every(smooth.Count());
  std::iota(every.begin(), every.end(), 0);
  const TrainingData jittered = PerturbedPoses(smooth, every, 0.5, 0.5, 7, W, H);
  double rms = 0;
  for (int f = 0; f < smooth.Count(); ++f)
  {
    const auto a = Corners(smooth.Poses[f]), b = Corners(jittered.Poses[f]);
    for (int k = 0; k < 4; ++k)
    {
      rms += (a[k] - b[k]).squaredNorm() / (4.0 * smooth.Count());
    }
  }
  rms = std::sqrt(rms);
  std::printf("jitter: smooth path %.5f mm (expected %.5f); independent errors of rms %.3f mm: %.3f mm\n",
    TrackedPathJitter(smooth, 0), expected, rms, TrackedPathJitter(jittered, 0));
  EXPECT_NEAR(TrackedPathJitter(jittered, 0), rms, 0.1 * rms);

  // Frames marked invalid are left out of the path; fewer than three usable frames measure nothing.
  TrainingData gaps = jittered;
  gaps.Valid.assign(gaps.Count(), 1);
  for (int f = 1; f < gaps.Count(); f += 2)
  {
    gaps.Valid[f] = 0;
    gaps.Poses[f][0] = NAN; // never read
  }
  EXPECT_GT(TrackedPathJitter(gaps, 0), 0.5 * rms);
  EXPECT_TRUE(std::isfinite(TrackedPathJitter(gaps, 0)));
  TrainingData two = TurningSweep(2, 0.4);
  EXPECT_EQ(TrackedPathJitter(two, 0), -1.0);
}

TEST(PoseTimeline, ThePosePriorsCornerDisplacementIsTheTrackedPathsJitter)
{
  // Independent truth: corrections drawn from the scaled prior (each component normal with the scaled sigma) and
  // applied by CorrectPose move the frame's corners by the jitter asked for, in root mean square (Monte Carlo,
  // 20,000 draws: a sampling error of about 0.5 %); a rotation prior alone and a translation prior alone check each
  // term of the formula.
  const TrainingData sweep = TurningSweep(10, 0.4);
  const double rotationSigma = 0.0175, translationSigma = 1.0;
  std::mt19937 random(3);
  std::normal_distribution<double> normal;
  const std::array<Eigen::Vector3d, 4> before = Corners(sweep.Poses[0]);
  for (const std::array<double, 2> sigmas : { std::array<double, 2>{ rotationSigma, translationSigma },
         std::array<double, 2>{ rotationSigma, 0.0 }, std::array<double, 2>{ 0.0, translationSigma } })
  {
    for (const double jitter : { 0.02, 0.313, 1.0 })
    {
      const double k = PosePriorScale(sweep, 0, jitter, sigmas[0], sigmas[1]);
      double squared = 0;
      const int draws = 20000;
      for (int d = 0; d < draws; ++d)
      {
        double xi[6];
        for (int c = 0; c < 6; ++c)
        {
          xi[c] = k * sigmas[c < 3 ? 0 : 1] * normal(random);
        }
        std::array<double, 16> moved;
        ASSERT_EQ(CorrectPose(sweep.Poses[0].data(), W, H, xi, moved.data()), PoseStatus::Ok);
        const std::array<Eigen::Vector3d, 4> after = Corners(moved);
        for (int c = 0; c < 4; ++c)
        {
          squared += (after[c] - before[c]).squaredNorm() / (4.0 * draws);
        }
      }
      std::printf("prior of %g rad and %g mm for a jitter of %.3f mm: sigmas x %.4f, corners moved %.4f mm rms\n",
        sigmas[0], sigmas[1], jitter, k, std::sqrt(squared));
      EXPECT_NEAR(std::sqrt(squared), jitter, 0.02 * jitter);
    }
  }
  EXPECT_EQ(PosePriorScale(sweep, 0, -1, rotationSigma, translationSigma), 1.0) << "nothing measured: as given";
  EXPECT_EQ(PosePriorScale(sweep, 0, 0, rotationSigma, translationSigma),
    PosePriorScale(sweep, 0, PosePriorLeastJitter, rotationSigma, translationSigma))
    << "a smooth path: the least jitter";
  EXPECT_EQ(PosePriorScale(sweep, 1, 0.5, rotationSigma, translationSigma), 1.0) << "no such sweep";

  // The trainer takes the prior from the corrected sweep's path, and says so; PriorFromPath off keeps the sigmas.
  std::vector<int> every(sweep.Count());
  std::iota(every.begin(), every.end(), 0);
  const TrainingData jittered = PerturbedPoses(TurningSweep(60, 0.4), every, 0.5, 0.5, 7, W, H);
  TrainerSettings s;
  s.Seeding.PixelGridFit = false;
  s.Seeding.InitialGaussians = 50;
  s.Iterations = 1;
  s.Poses.RefinePoses = PoseRefinement::On;
  const double k =
    PosePriorScale(jittered, 0, PosePriorJitterRatio * TrackedPathJitter(jittered, 0), rotationSigma, translationSigma);
  const auto line = [](const Trainer& t) {
    for (const std::string& l : t.GetReport().Settings)
    {
      if (l.rfind("RefinePoses = on", 0) == 0)
      {
        return l;
      }
    }
    return std::string();
  };
  const std::string fromPath = line(Trainer(jittered, s));
  char expected[128];
  std::snprintf(expected, sizeof(expected), "prior 0.001 at %.3g degrees and %.3g mm (2 x its tracked path's jitter, ",
    k * rotationSigma * 180 / M_PI, k * translationSigma);
  EXPECT_NE(fromPath.find(expected), std::string::npos) << fromPath << "\n" << expected;
  s.Poses.PriorFromPath = false;
  const std::string given = line(Trainer(jittered, s));
  EXPECT_NE(given.find("prior 0.001 at 1 degrees and 1 mm, smoothness"), std::string::npos) << given;
}

TEST(PoseTimeline, ThePoseRefinementStartsAtOnceWhereACorrectedSweepsPathJitters)
{
  // Two sweeps: a smooth one and one with 0.5 degrees and 0.5 mm of independent error per frame.
  const TrainingData smooth = TurningSweep(60, 0.4);
  std::vector<int> every(smooth.Count());
  std::iota(every.begin(), every.end(), 0);
  TrainingData both = smooth;
  const TrainingData jittered = PerturbedPoses(smooth, every, 0.5, 0.5, 7, W, H);
  both.Poses.insert(both.Poses.end(), jittered.Poses.begin(), jittered.Poses.end());
  both.Frames.resize(both.Frames.size() * 2, 0.f);
  both.Sweeps.assign(smooth.Count(), 0);
  both.Sweeps.resize(2 * smooth.Count(), 1);
  for (int f = 0; f < smooth.Count(); ++f)
  {
    both.TrainFrames.push_back(smooth.Count() + f);
  }
  EXPECT_EQ(ChoosePoseRefinementStart(smooth, {}).Start, 0.2);
  EXPECT_EQ(ChoosePoseRefinementStart(jittered, {}).Start, 0.0);
  EXPECT_EQ(ChoosePoseRefinementStart(both, {}).Start, 0.0) << "every sweep";
  EXPECT_EQ(ChoosePoseRefinementStart(both, { 1, 0 }).Start, 0.2) << "the jittering sweep is not corrected";
  const PoseRefinementStartChoice choice = ChoosePoseRefinementStart(both, { 0, 1 });
  EXPECT_EQ(choice.Start, 0.0);
  EXPECT_NE(choice.Reason.find("sweep 1"), std::string::npos) << choice.Reason;
  EXPECT_EQ(choice.Reason.find("sweep 0"), std::string::npos) << choice.Reason;

  // The trainer resolves a negative start (the default) and keeps one given.
  TrainerSettings s;
  s.Seeding.PixelGridFit = false;
  s.Seeding.InitialGaussians = 50;
  s.Iterations = 1;
  s.Poses.RefinePoses = PoseRefinement::On;
  EXPECT_EQ(Trainer(jittered, s).GetSettings().Poses.Start, 0.0);
  EXPECT_EQ(Trainer(smooth, s).GetSettings().Poses.Start, 0.2);
  s.Poses.Start = 0.5;
  EXPECT_EQ(Trainer(jittered, s).GetSettings().Poses.Start, 0.5);
}

TEST(Trainer, HeldOutPosesRefinedWithTheFieldFrozenComeBackToTheTruth)
{
  // The fair score of held-out frames: the known field that rendered the sweep, frozen; each held-out frame's
  // pose moved by 0.5 degrees and 0.5 mm at random, then refined against its recorded frame. The poses come back
  // towards the ones that rendered the frames (the truth), and the frames rendered at them match better.
  const GaussianField field = KnownField(200, 7);
  std::vector<int> heldOut;
  const TrainingData truth = SyntheticSweep(field, 0.5, heldOut);
  TrainingData data = PerturbedPoses(truth, heldOut, 0.5, 0.5, 5, W, H);
  RenderOptions options;
  options.ElevationSigma = 0.5;
  options.Gamma = 1.0;
  auto psnrAt = [&](const TrainingData& d) {
    auto renderer = CreateCpuRenderer();
    std::vector<float> S(W * H), I(W * H);
    double total = 0;
    for (int f : heldOut)
    {
      const SliceGeometry g = d.Slice(f);
      EXPECT_TRUE(renderer->Forward(field.View(), &g, 1, options, S.data(), I.data(), nullptr, nullptr));
      total += Psnr(I.data(), &truth.Frames[std::size_t(W) * H * f], W * H);
    }
    return total / heldOut.size();
  };
  const double before = CornerError(data, truth, heldOut, W, H), psnrBefore = psnrAt(data);
  TrainerSettings s;
  std::vector<std::array<double, 6>> corrections;
  std::string error;
  ASSERT_TRUE(
    RefinePosesWithFieldFrozen(field, data, heldOut, options, s.Poses, s.Loss, 100, "cpu", corrections, &error))
    << error;
  ASSERT_EQ(corrections.size(), heldOut.size());
  const double after = CornerError(data, truth, heldOut, W, H), psnrAfter = psnrAt(data);
  std::printf("held-out poses refined with the field frozen (100 steps): corner error %.3f -> %.3f mm, PSNR %.2f -> "
              "%.2f dB\n",
    before, after, psnrBefore, psnrAfter);
  EXPECT_LT(after, 0.5 * before);
  EXPECT_GT(psnrAfter, psnrBefore + 3.0);
  for (int f : truth.TrainFrames)
  {
    EXPECT_EQ(data.Poses[f], truth.Poses[f]) << "a frame not listed keeps its pose";
  }
}

// Pose refinement on synthetic truth: the known field rendered at the true poses, the training frames'
// poses then moved by a random rigid motion of 0.5 degrees and 0.5 mm each (about the frame's centre, in
// its own axes). Training with RefinePoses brings the poses back towards the truth: the mean distance of
// the frames' corners from where they truly lie falls by more than half (the error a tracker would leave
// in a volume), and the held-out frames (at their true poses, never refined) come out better.
TEST(Trainer, RefiningPosesBringsPerturbedTrainingPosesTowardsTheTruth)
{
  std::vector<int> heldOut;
  TrainingData truth = SyntheticSweep(KnownField(200, 7), 0.5, heldOut);
  const TrainingData perturbed = PerturbedPoses(truth, truth.TrainFrames, 0.5, 0.5, 21, W, H);
  const double before = CornerError(perturbed, truth, truth.TrainFrames, W, H);
  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.Seeding.PixelGridFit = false;
  s.Seeding.InitialGaussians = 3000;
  s.Iterations = 1500;
  s.Poses.RefinePoses = PoseRefinement::On;
  Trainer trainer(perturbed, s);
  std::string error;
  ASSERT_TRUE(trainer.Initialize(&error)) << error;
  ASSERT_TRUE(trainer.Run(nullptr, nullptr, &error)) << error;
  const double after = CornerError(trainer.GetData(), truth, truth.TrainFrames, W, H);
  s.Poses.RefinePoses = PoseRefinement::Off;
  Trainer trusting(perturbed, s);
  ASSERT_TRUE(trusting.Initialize(&error)) << error;
  ASSERT_TRUE(trusting.Run(nullptr, nullptr, &error)) << error;
  Trainer onTruth(truth, s);
  ASSERT_TRUE(onTruth.Initialize(&error)) << error;
  ASSERT_TRUE(onTruth.Run(nullptr, nullptr, &error)) << error;
  std::printf("corner error: %.3f mm tracked, %.3f mm refined; held-out PSNR %.2f dB refined, %.2f dB trusting the "
              "tracked poses, %.2f dB on the true poses\n",
    before, after, HeldOutPsnr(trainer, heldOut), HeldOutPsnr(trusting, heldOut), HeldOutPsnr(onTruth, heldOut));
  ASSERT_EQ(trainer.GetReport().PoseCorrections.size(), truth.TrainFrames.size());
  // Measured: 0.505 -> 0.187 mm; held-out 38.80 dB refined, 34.89 trusting the tracked poses, 52.25 on the
  // true poses (scored at the true poses the aim of 0.5 dB from the true poses is far; fairly, below).
  EXPECT_LT(after, 0.5 * before) << "the pose error falls by at least half";
  EXPECT_GT(HeldOutPsnr(trainer, heldOut), HeldOutPsnr(trusting, heldOut) + 2.0);
  // The fair score: a field trained on refined poses lives in the sweep's refined frame, which one sweep fixes
  // only up to a motion of the whole sweep (and smooth warps along it), so its held-out frames are scored at
  // their true poses refined with the field frozen, as view-synthesis papers score test views.
  const double aligned = AlignedCornerError(trainer.GetData(), truth, truth.TrainFrames, W, H);
  const double fairRefined = FairPsnr(trainer.GetField(), trainer.Options(), truth, heldOut, s);
  const double fairTrusting = FairPsnr(trusting.GetField(), trusting.Options(), truth, heldOut, s);
  const double fairTruth = FairPsnr(onTruth.GetField(), onTruth.Options(), truth, heldOut, s);
  std::printf("aligned corner error %.3f mm; fair held-out PSNR %.2f dB refined, %.2f trusting, %.2f on the true "
              "poses\n",
    aligned, fairRefined, fairTrusting, fairTruth);
  // Measured: 0.161 mm; 48.00, 38.49, 52.44 dB (4,000 steps: 0.109 mm; 53.49 against 54.81).
  EXPECT_LT(aligned, 0.4 * before);
  EXPECT_GT(fairRefined, fairTrusting + 5.0);

  // The smoothness prior: the corrections of consecutive training frames differ less.
  auto roughness = [](const TrainerReport& report) {
    double sum = 0;
    for (std::size_t k = 1; k < report.PoseCorrections.size(); ++k)
    {
      for (int c = 0; c < 6; ++c)
      {
        const double d = report.PoseCorrections[k].Xi[c] - report.PoseCorrections[k - 1].Xi[c];
        sum += d * d * (c < 3 ? 1.0 / (0.0175 * 0.0175) : 1.0); // per degree-sized and mm-sized unit
      }
    }
    return std::sqrt(sum / (report.PoseCorrections.size() - 1));
  };
  s.Poses.RefinePoses = PoseRefinement::On;
  s.Poses.Smoothness = 10;
  Trainer smooth(perturbed, s);
  ASSERT_TRUE(smooth.Initialize(&error)) << error;
  ASSERT_TRUE(smooth.Train(nullptr, nullptr, &error)) << error;
  // Scored before Finish (bigus train --evaluate-every), the held-out frames are already placed among their
  // refined neighbours (Trainer::PlaceUntrainedFrames), as Finish places them.
  EXPECT_EQ(CornerError(smooth.GetData(), truth, heldOut, W, H), 0);
  ImageMetrics midRun;
  ASSERT_TRUE(smooth.Evaluate(heldOut, midRun, &error)) << error;
  EXPECT_GT(CornerError(smooth.GetData(), truth, heldOut, W, H), 0);
  EXPECT_EQ(smooth.GetReport().UntrainedCorrections.Frames, static_cast<int>(heldOut.size()));
  ASSERT_TRUE(smooth.Finish(&error)) << error;
  std::printf("roughness of the corrections along the sweep: %.4f without the smoothness prior, %.4f with\n",
    roughness(trainer.GetReport()), roughness(smooth.GetReport()));
  EXPECT_LT(roughness(smooth.GetReport()), 0.5 * roughness(trainer.GetReport()));
  // The held-out frames (at their true poses here): the training frames' corrections, independent from frame to
  // frame, predict none of them, so they stay (bigus::CorrectUntrainedFrames); the smoothed ones do, and move them
  // by little (measured: 0.049 mm at the corners, held out 34.97 dB at the moved poses, 34.87 at the true ones).
  EXPECT_EQ(trainer.GetReport().UntrainedCorrections.Bandwidth, 0);
  EXPECT_EQ(CornerError(trainer.GetData(), truth, heldOut, W, H), 0);
  EXPECT_GT(smooth.GetReport().UntrainedCorrections.Bandwidth, 0);
  EXPECT_EQ(smooth.GetReport().UntrainedCorrections.Frames, static_cast<int>(heldOut.size()));
}

TEST(PoseRefinement, TheAnchorMovesTheRefinedSceneOntoTheTrackedPosesAndKeepsEveryTrainingRender)
{
  // A refinement that moved the whole scene: the field and every training pose moved by one rigid motion M (2
  // degrees, 1.4 mm), which no image can tell, plus (second case) an independent error per frame, which it can. The
  // anchor must take M away, so that the field lies where the tracked poses say, and render every training frame
  // as before.
  std::vector<int> heldOut;
  const GaussianField field = KnownField(200, 7);
  const TrainingData truth = SyntheticSweep(field, 0.5, heldOut);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2 * M_PI / 180, Eigen::Vector3d(1, 2, -1).normalized()).matrix();
  const Eigen::Vector3d t(1.0, -0.5, 0.8);
  auto moved = [&](const std::array<double, 16>& pose) {
    Eigen::Matrix4d P, M = Eigen::Matrix4d::Identity();
    for (int k = 0; k < 16; ++k)
    {
      P(k / 4, k % 4) = pose[k];
    }
    M.topLeftCorner<3, 3>() = R;
    M.topRightCorner<3, 1>() = t;
    const Eigen::Matrix4d out = M * P;
    std::array<double, 16> result;
    for (int k = 0; k < 16; ++k)
    {
      result[k] = out(k / 4, k % 4);
    }
    return result;
  };
  GaussianField movedField = field;
  const Eigen::Quaterniond rotation(R);
  for (std::int64_t i = 0; i < movedField.Count(); ++i)
  {
    float* m = &movedField.Means[3 * i];
    const Eigen::Vector3d p = R * Eigen::Vector3d(m[0], m[1], m[2]) + t;
    float* q = &movedField.Quaternions[4 * i];
    const Eigen::Quaterniond r = rotation * Eigen::Quaterniond(q[0], q[1], q[2], q[3]);
    const double values[7] = { p[0], p[1], p[2], r.w(), r.x(), r.y(), r.z() };
    std::copy_n(values, 3, m);
    std::copy_n(values + 3, 4, q);
  }
  RenderOptions o;
  o.ElevationSigma = 0.5;
  o.Gamma = 1;
  auto render = [&](const GaussianField& f, const TrainingData& d) {
    auto renderer = CreateCpuRenderer();
    const std::size_t pixels = std::size_t(W) * H;
    std::vector<float> all, S(pixels), I(pixels);
    for (int frame : d.TrainFrames)
    {
      const SliceGeometry g = d.Slice(frame);
      EXPECT_TRUE(renderer->Forward(f.View(), &g, 1, o, S.data(), I.data(), nullptr, nullptr));
      all.insert(all.end(), I.begin(), I.end());
    }
    return all;
  };
  for (const double noise : { 0.0, 0.3 })
  {
    TrainingData data = truth;
    PoseRefinementSettings settings;
    settings.RefinePoses = PoseRefinement::On;
    settings.Start = 0;
    PoseRefiner refiner;
    TrainingState state;
    std::vector<std::string> lines;
    refiner.Configure(&data, settings, nullptr, state, lines);
    // Each training frame's correction takes its tracked pose to M times its tracked pose, then errs by noise.
    std::mt19937_64 rng(5);
    std::normal_distribution<double> normal(0.0, 1.0);
    for (int f : data.TrainFrames)
    {
      const std::array<double, 16> target = moved(truth.Poses[f]);
      ASSERT_EQ(PoseCorrectionBetween(truth.Poses[f].data(), target.data(), W, H, state.PoseCorrections[f].data()),
        PoseStatus::Ok);
      for (int k = 0; k < 6; ++k)
      {
        state.PoseCorrections[f][k] += noise * normal(rng) * (k < 3 ? M_PI / 180 : 1.0);
      }
    }
    refiner.ComposePoses(state);
    GaussianField anchored = movedField;
    const std::vector<float> before = render(anchored, data);
    const PoseAnchor anchor = refiner.AnchorToTrackedPoses(state, anchored);
    ASSERT_TRUE(anchor.Applied) << anchor.Line;
    const std::vector<float> after = render(anchored, data);
    float largest = 0;
    for (std::size_t k = 0; k < before.size(); ++k)
    {
      largest = std::max(largest, std::abs(after[k] - before[k]));
    }
    const double error = CornerError(data, truth, data.TrainFrames, W, H);
    std::printf("noise %.1f: %s; training renders change by at most %.2g; corners %.4f mm from the tracked ones\n",
      noise, anchor.Line.c_str(), largest, error);
    EXPECT_LT(largest, 1e-4) << "a rigid motion of the scene and of every pose changes no render";
    EXPECT_NEAR(anchor.RotationDegrees, 2.0, noise > 0 ? 0.5 : 1e-9);
    if (noise == 0)
    {
      // M taken away exactly: the poses are the tracked ones, the field the one M moved.
      EXPECT_LT(anchor.AfterMillimetres, 1e-9);
      EXPECT_LT(error, 1e-9);
      for (std::int64_t i = 0; i < 3 * field.Count(); ++i)
      {
        ASSERT_NEAR(anchored.Means[i], field.Means[i], 1e-4) << "mean " << i / 3;
      }
    }
    else
    {
      // What is not one motion stays: the corrections keep what tells the frames apart.
      EXPECT_GT(anchor.AfterMillimetres, 0.1);
      EXPECT_LT(anchor.AfterMillimetres, anchor.BeforeMillimetres);
      EXPECT_NEAR(error, anchor.AfterMillimetres, 0.5 * anchor.AfterMillimetres);
    }
  }
}
