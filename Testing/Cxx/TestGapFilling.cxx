// FillElevationGaps on a known geometry: two stacks of parallel frames 0.5 mm apart with a 4 mm gap
// between them, each frame holding its own Gaussians, up to about one beam width off its plane.
// Rendered in the gap, the filled field must show the blend of the two frames on either side as the
// field renders them (the scattering S of each, rendered by the CPU renderer at their own poses), and
// the training frames must render as before.
#include "bigusGapFilling.h"
#include "bigusRenderer.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

using namespace bigus;

namespace
{
constexpr int W = 48, H = 40;
constexpr double PixelSpacing = 0.3; // mm
constexpr double Sigma = 0.1;        // elevation beam, mm

/// ImageToReference of a frame whose image centre is at (0, 0, z), turned by @p degrees about the
/// image's x axis through that centre.
std::array<double, 16> Pose(double z, double degrees)
{
  const double a = degrees * M_PI / 180, c = std::cos(a), s = std::sin(a);
  const double u[3] = { 1, 0, 0 }, v[3] = { 0, c, s };
  const double i0 = 0.5 * (W - 1) * PixelSpacing, j0 = 0.5 * (H - 1) * PixelSpacing;
  std::array<double, 16> m{};
  for (int r = 0; r < 3; ++r)
  {
    m[4 * r] = u[r] * PixelSpacing;
    m[4 * r + 1] = v[r] * PixelSpacing;
    m[4 * r + 3] = (r == 2 ? z : 0.0) - u[r] * i0 - v[r] * j0;
  }
  m[15] = 1;
  return m;
}

SliceGeometry Slice(const std::array<double, 16>& pose)
{
  SliceGeometry g;
  std::copy(pose.begin(), pose.end(), g.ImageToReference);
  g.Width = W;
  g.Height = H;
  return g;
}

struct Sweep
{
  TrainingData Data;
  GaussianField Field;
  std::vector<int> Owner; ///< frame each Gaussian was placed on
};

/// Frames at z = 0, 0.5, ..., 2.0 (flat) and 6.0, ..., 8.0 (turned by @p degrees), 30 Gaussians near each
/// frame's plane (thin in elevation, inside the image, up to @p offset mm off the plane along its normal).
Sweep MakeSweep(double degrees, double offset = 0.1)
{
  Sweep s;
  s.Data.Width = W;
  s.Data.Height = H;
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> x(-5.5, 5.5), y(-4.5, 4.5), scale(0.25, 0.6), r(-0.8, 0.8),
    off(-offset, offset);
  for (int k = 0; k < 10; ++k)
  {
    const bool after = k >= 5;
    const std::array<double, 16> pose = Pose(after ? 6.0 + 0.5 * (k - 5) : 0.5 * k, after ? degrees : 0.0);
    s.Data.Poses.push_back(pose);
    s.Data.TrainFrames.push_back(k);
    const double a = after ? degrees * M_PI / 180 : 0.0;
    for (int g = 0; g < 30; ++g)
    {
      const double px = x(rng), py = y(rng), pz = off(rng);
      // Centre + px u + py v + pz n, v = (0, cos a, sin a), n = (0, -sin a, cos a).
      s.Field.Means.insert(s.Field.Means.end(),
        { float(px), float(py * std::cos(a) - pz * std::sin(a)),
          float(pose[11] + 0.5 * (H - 1) * PixelSpacing * std::sin(a) + py * std::sin(a) + pz * std::cos(a)) });
      s.Field.LogScales.insert(
        s.Field.LogScales.end(), { float(std::log(scale(rng))), float(std::log(scale(rng))), float(std::log(0.03)) });
      // Rotation about x by a, so the thin axis stays along the frame's normal.
      s.Field.Quaternions.insert(
        s.Field.Quaternions.end(), { float(std::cos(a / 2)), float(std::sin(a / 2)), 0.f, 0.f });
      s.Field.Reflectivities.push_back(float(r(rng)));
      s.Owner.push_back(k);
    }
  }
  return s;
}

std::vector<float> RenderS(const GaussianField& field, const std::array<double, 16>& pose)
{
  auto renderer = CreateCpuRenderer();
  RenderOptions o;
  o.ElevationSigma = Sigma;
  o.Gamma = 1;
  std::vector<float> S(W * H), I(W * H);
  const SliceGeometry g = Slice(pose);
  std::string error;
  EXPECT_TRUE(renderer->Forward(field.View(), &g, 1, o, S.data(), I.data(), nullptr, &error)) << error;
  return S;
}

double MaxAbs(const std::vector<float>& a)
{
  double m = 0;
  for (float v : a)
  {
    m = std::max(m, double(std::abs(v)));
  }
  return m;
}
}

TEST(GapFilling, InTheGapTheFieldShowsTheBlendOfTheFramesOnEitherSide)
{
  for (double degrees : { 0.0, 10.0 })
  {
    SCOPED_TRACE(degrees);
    Sweep s = MakeSweep(degrees);
    const GaussianField before = s.Field;
    const std::array<double, 16> a = s.Data.Poses[4], b = s.Data.Poses[5];
    // At fraction t of the way: the image centre moved linearly between the two frames' centres, turned
    // by t times the angle (the slerp of two turns about one axis).
    auto poseAt = [&](double t) {
      std::array<double, 16> m = Pose(0, t * degrees);
      for (int r = 0; r < 3; ++r)
      {
        auto centre = [&](const std::array<double, 16>& q) {
          return q[4 * r] * 0.5 * (W - 1) + q[4 * r + 1] * 0.5 * (H - 1) + q[4 * r + 3];
        };
        m[4 * r + 3] += (1 - t) * centre(a) + t * centre(b) - centre(m);
      }
      return m;
    };
    const std::array<double, 16> middle = poseAt(0.5);
    const std::vector<float> Sa = RenderS(before, a), Sb = RenderS(before, b);
    const double peak = std::max(MaxAbs(Sa), MaxAbs(Sb));
    ASSERT_GT(peak, 0.1);
    EXPECT_LT(MaxAbs(RenderS(before, middle)), 1e-6 * peak) << "the gap is empty before filling";

    const GapFillingReport report = FillElevationGaps(s.Field, s.Data, Sigma);
    EXPECT_NEAR(report.TypicalSpacing, 0.5, 1e-6);
    EXPECT_EQ(report.Gaps, 1);
    EXPECT_GT(report.WidestGap, 3.5);
    // Copies 1.5 beam widths (1.5 x 0.104 mm) apart along the 4 mm: 25 per Gaussian on parallel frames
    // 4 mm apart (the tilted gap's length differs a little). Only the Gaussians of the two bracketing
    // frames are within reach (3 widths, 0.31 mm) of their planes.
    EXPECT_GE(report.Added, 22 * 2 * 30);
    EXPECT_LE(report.Added, 27 * 2 * 30);
    ASSERT_EQ(s.Field.Count(), before.Count() + report.Added);
    // The Gaussians of the two bracketing frames give up what their copies add at their frame (the
    // nearest copy, 1.5 widths off at weight 0.6: about 0.6 exp(-1.125) = 0.19); no other one changes.
    for (std::int64_t i = 0; i < before.Count(); ++i)
    {
      const double ratio = s.Field.Reflectivities[i] / before.Reflectivities[i];
      if (s.Owner[i] == 4 || s.Owner[i] == 5)
      {
        ASSERT_GT(ratio, 0.7);
        ASSERT_LT(ratio, 0.9);
      }
      else
      {
        ASSERT_EQ(ratio, 1.0) << "Gaussian " << i << " of frame " << s.Owner[i] << " was changed";
      }
      for (int c = 0; c < 3; ++c)
      {
        ASSERT_EQ(s.Field.Means[3 * i + c], before.Means[3 * i + c]);
      }
    }

    // At t = 1/4, 1/2 and 0.6: the blend (1 - w) S_a + w S_b (the sum of the copies' profiles ripples
    // by 3e-4; the blend weight varies linearly under each copy's profile), w = t but for the margins of
    // BlendMarginSigmas (2) beam widths sqrt(0.1^2 + 0.03^2) = 0.104 mm at each end, where each frame
    // alone is carried: w = (t x gap - margin) / (gap - 2 margin), the gap 4 mm. The Gaussians up to
    // one beam width off their frame are carried with what they render there: copied at full weight
    // they would show up to exp(1/2) = 1.65 times too bright.
    const double margin = 2 * std::hypot(Sigma, 0.03), gap = report.WidestGap;
    for (double t : { 0.25, 0.5, 0.6 })
    {
      const std::vector<float> St = RenderS(s.Field, poseAt(t));
      const double w = (t * gap - margin) / (gap - 2 * margin);
      double worst = 0;
      for (int p = 0; p < W * H; ++p)
      {
        worst = std::max(worst, std::abs(St[p] - ((1 - w) * Sa[p] + w * Sb[p])));
      }
      EXPECT_LT(worst, 0.02 * peak) << "at t = " << t << ": not the blend of the bracketing frames";
    }
    // The training frames render almost as before: each copied Gaussian gave up what its copies add at
    // its frame (to first order: exactly at its centre; 19 % before that compensation).
    for (const auto& pose : { a, b, s.Data.Poses[0] })
    {
      const std::vector<float> S0 = RenderS(before, pose), S1 = RenderS(s.Field, pose);
      double change = 0;
      for (int p = 0; p < W * H; ++p)
      {
        change = std::max(change, double(std::abs(S1[p] - S0[p])));
      }
      EXPECT_LT(change, 0.02 * peak);
    }
  }
}

TEST(GapFilling, TheCopiesOfOneFrameStayOffTheOther)
{
  // Only the first frame's side carries scattering: what the filled field renders at the second
  // bracketing frame is what the first frame's copies spill onto it. Linear across the whole gap
  // (margin 0), the copies within a beam width of the second frame still carry a few % of the first
  // (share d / gap at distance d); with the margin of 2 beam widths they are left out and those beyond
  // carry (d - 2 widths) / gap at most exp(-2) of their peak there.
  Sweep s = MakeSweep(0);
  for (std::int64_t i = 0; i < s.Field.Count(); ++i)
  {
    if (s.Owner[i] >= 5)
    {
      s.Field.Reflectivities[i] = 0;
    }
  }
  const double peak = MaxAbs(RenderS(s.Field, s.Data.Poses[4]));
  double spill[2];
  for (int k = 0; k < 2; ++k)
  {
    GapFillingSettings settings;
    settings.BlendMarginSigmas = k == 0 ? 0.0 : GapFillingSettings().BlendMarginSigmas;
    GaussianField field = s.Field;
    ASSERT_GT(FillElevationGaps(field, s.Data, Sigma, settings).Added, 0);
    spill[k] = MaxAbs(RenderS(field, s.Data.Poses[5])) / peak;
  }
  std::printf("spill onto the second frame, relative to the first frame's peak: %.5f linear, %.5f with the margin\n",
    spill[0], spill[1]);
  EXPECT_GT(spill[0], 0.005) << "the linear blend spills";
  EXPECT_LT(spill[1], 0.25 * spill[0]);
  EXPECT_LT(spill[1], 0.002);
}

TEST(GapFilling, ASweepWithoutGapsOrTooFewFramesIsLeftAlone)
{
  Sweep s = MakeSweep(0);
  // The same frames without the gap: the second stack moved next to the first.
  for (int k = 5; k < 10; ++k)
  {
    s.Data.Poses[k] = Pose(0.5 * k, 0);
  }
  const std::int64_t n = s.Field.Count();
  EXPECT_EQ(FillElevationGaps(s.Field, s.Data, Sigma).Added, 0);
  // A gap narrower than two lattice steps of the beam alone (2 x 1.5 x sigma) is no gap.
  Sweep wide = MakeSweep(0);
  EXPECT_EQ(FillElevationGaps(wide.Field, wide.Data, 1.5).Added, 0);
  s.Data.TrainFrames = { 4, 5 };
  EXPECT_EQ(FillElevationGaps(s.Field, s.Data, Sigma).Added, 0);
  EXPECT_EQ(s.Field.Count(), n);
}

TEST(GapFilling, UnderTheMaximumOfGaussiansAGapIsBridgedByItsStrongestGaussians)
{
  // The maximum a user trains with holds for the filled field too. With room for half the copies the
  // gap is bridged by the strongest Gaussians of its two frames: rendered in the middle of the gap it
  // stays near the unlimited fill (|r| is uniform, so the stronger half of the Gaussians carries 7/8 of
  // the sum of r^2: a relative error near sqrt(1/8) = 0.35, where an unordered half would leave about
  // sqrt(1/2) = 0.71). With no room at all the gap is left empty and the field is as it was; with room for
  // every copy it is filled as without a maximum.
  const Sweep s = MakeSweep(0);
  const std::int64_t n = s.Field.Count();
  GaussianField unlimited = s.Field;
  const std::int64_t needed = FillElevationGaps(unlimited, s.Data, Sigma).Added;
  ASSERT_GT(needed, 0);
  // The room the trainer's densification keeps under its maximum is this count, taken without filling.
  EXPECT_EQ(CountGapCopies(s.Field, s.Data, Sigma), needed);
  std::array<double, 16> middle = s.Data.Poses[4];
  middle[11] = 0.5 * (s.Data.Poses[4][11] + s.Data.Poses[5][11]);
  const std::vector<float> full = RenderS(unlimited, middle);

  GapFillingSettings settings;
  settings.MaximumGaussians = n + needed / 2;
  GaussianField half = s.Field;
  const GapFillingReport report = FillElevationGaps(half, s.Data, Sigma, settings);
  EXPECT_EQ(report.Gaps, 1);
  EXPECT_EQ(report.Thinned, 1);
  EXPECT_EQ(report.Skipped, 0);
  EXPECT_GT(report.LeftOut, 0);
  EXPECT_LE(half.Count(), settings.MaximumGaussians);
  EXPECT_GT(report.Added, needed / 4);
  const std::vector<float> thinned = RenderS(half, middle);
  double error = 0, norm = 0;
  for (std::size_t p = 0; p < full.size(); ++p)
  {
    error += (thinned[p] - full[p]) * (thinned[p] - full[p]);
    norm += full[p] * full[p];
  }
  ASSERT_GT(norm, 0);
  std::printf(
    "half the copies, strongest first: relative error in the middle of the gap %.3f\n", std::sqrt(error / norm));
  EXPECT_LT(std::sqrt(error / norm), 0.5) << "the strongest half of the copies carries most of the gap";
  EXPECT_NE(DescribeGapFilling(report, settings).find("1 gaps thinned"), std::string::npos)
    << DescribeGapFilling(report, settings);

  settings.MaximumGaussians = n;
  GaussianField none = s.Field;
  const GapFillingReport empty = FillElevationGaps(none, s.Data, Sigma, settings);
  EXPECT_EQ(empty.Added, 0);
  EXPECT_EQ(empty.Skipped, 1);
  ExpectSameField(none, s.Field);
  EXPECT_NE(DescribeGapFilling(empty, settings).find("1 gaps left empty"), std::string::npos)
    << DescribeGapFilling(empty, settings);

  settings.MaximumGaussians = n + needed;
  GaussianField room = s.Field;
  EXPECT_EQ(FillElevationGaps(room, s.Data, Sigma, settings).Added, needed);
  ExpectSameField(room, unlimited);
}

TEST(GapFilling, TheCopiesAreCountedWithoutFillingOnTurnedFramesAndUnderTightMargins)
{
  // CountGapCopies against the copies FillElevationGaps adds with no maximum: frames turned by 0 and 25 degrees
  // across the gap, Gaussians up to 0.4 mm off their planes (some out of reach), clearance and margins changed.
  for (double degrees : { 0.0, 25.0 })
  {
    const Sweep s = MakeSweep(degrees, 0.4);
    for (double clearance : { 0.0, 1.5 })
    {
      GapFillingSettings settings;
      settings.ClearanceSigmas = clearance;
      settings.BlendMarginSigmas = clearance > 0 ? 0.5 : 2.0;
      GaussianField filled = s.Field;
      const std::int64_t added = FillElevationGaps(filled, s.Data, Sigma, settings).Added;
      EXPECT_GT(added, 0) << degrees << " degrees, clearance " << clearance;
      EXPECT_EQ(CountGapCopies(s.Field, s.Data, Sigma, settings), added)
        << degrees << " degrees, clearance " << clearance;
    }
  }
}

TEST(GapFilling, NonFiniteGaussiansAndAZeroBeamAddNothingAndNeverCrash)
{
  Sweep s = MakeSweep(0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  // Gaussian 120 sits on frame 4 (the first frame of the gap): a NaN mean, then a NaN scale and rotation.
  s.Field.Means[3 * 120] = nan;
  s.Field.LogScales[3 * 121] = nan;
  s.Field.Quaternions[4 * 122] = nan;
  const GaussianField before = s.Field;
  GaussianField field = s.Field;
  EXPECT_EQ(FillElevationGaps(field, s.Data, 0.0).Added, 0); // no beam: nothing to extrude
  EXPECT_EQ(field.Count(), before.Count());
  const std::int64_t counted = CountGapCopies(field, s.Data, Sigma);
  const GapFillingReport report = FillElevationGaps(field, s.Data, Sigma);
  EXPECT_EQ(report.Gaps, 1);
  EXPECT_EQ(counted, report.Added);
  // The Gaussians of the two frames, less the NaN mean and the NaN rotation (skipped); the NaN scale
  // counts as a scale of 1 mm, as the renderer takes it. Every copy is finite.
  EXPECT_GT(report.Added, 0);
  for (std::int64_t i = before.Count(); i < field.Count(); ++i)
  {
    for (int c = 0; c < 3; ++c)
    {
      ASSERT_TRUE(std::isfinite(field.Means[3 * i + c])) << "copy " << i;
    }
    ASSERT_TRUE(std::isfinite(field.Reflectivities[i])) << "copy " << i;
  }
}
