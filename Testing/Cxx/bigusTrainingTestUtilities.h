// Test helpers for the trainer's tests: a sweep rendered from a known field (header only, so that the
// tests that do not link BIGUS::Training keep bigusTestUtilities free of it), and in bigus::synthetic the
// synthetic sweep that the tests of the trainer and its stages share (TestTrainer, TestSeeding,
// TestDensification, TestCheckpoints, TestResolutionSchedule, TestDataParallel, TestGaussianFieldTrainer,
// TestPoseRefinement): a file that uses it says `using namespace bigus::synthetic;`.
#ifndef bigusTrainingTestUtilities_h
#define bigusTrainingTestUtilities_h

#include "bigusRenderer.h"
#include "bigusSliceFrame.h"
#include "bigusTrainer.h"
#include "bigusTrainingEngine.h"

#include <Eigen/Geometry>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace bigus
{
/// Frames of @p width x @p height pixels at @p poses, rendered from @p truth by the CPU renderer with
/// elevation sigma @p sigma (mm) and gamma 1, mask all ones; frames with k mod 4 == 2 go to @p heldOut,
/// the others to TrainFrames.
inline TrainingData RenderedSweep(const GaussianField& truth, const std::vector<std::array<double, 16>>& poses,
  int width, int height, double sigma, std::vector<int>& heldOut)
{
  TrainingData d;
  d.Width = width;
  d.Height = height;
  d.Mask.assign(std::size_t(width) * height, 1);
  d.Poses = poses;
  auto renderer = CreateCpuRenderer();
  RenderOptions o;
  o.ElevationSigma = sigma;
  o.Gamma = 1.0;
  std::vector<float> S(d.Mask.size()), I(d.Mask.size());
  for (int k = 0; k < d.Count(); ++k)
  {
    const SliceGeometry g = d.Slice(k);
    EXPECT_TRUE(renderer->Forward(truth.View(), &g, 1, o, S.data(), I.data(), nullptr, nullptr));
    d.Frames.insert(d.Frames.end(), I.begin(), I.end());
    (k % 4 == 2 ? heldOut : d.TrainFrames).push_back(k);
  }
  return d;
}

/// Appends a uniformly random unit quaternion (a normalised 4-vector of draws of the standard @p normal)
/// to @p field's rotations.
inline void AppendRandomRotation(GaussianField& field, std::mt19937_64& rng, std::normal_distribution<double>& normal)
{
  double q[4], n2 = 0;
  for (double& v : q)
  {
    v = normal(rng);
    n2 += v * v;
  }
  for (double v : q)
  {
    field.Quaternions.push_back(static_cast<float>(v / std::sqrt(n2)));
  }
}

/// PSNR (dB, peak 1) of @p n intensities @p a against @p b, every pixel counted.
inline double Psnr(const float* a, const float* b, std::size_t n)
{
  double mse = 0;
  for (std::size_t p = 0; p < n; ++p)
  {
    mse += (double(a[p]) - b[p]) * (double(a[p]) - b[p]);
  }
  return 10 * std::log10(1.0 / std::max(mse / n, 1e-20));
}

/// Every parameter of every Gaussian of @p a and @p b equal, bit for bit.
inline void ExpectSameField(const GaussianField& a, const GaussianField& b)
{
  ASSERT_EQ(a.Count(), b.Count());
  EXPECT_EQ(a.Means, b.Means);
  EXPECT_EQ(a.LogScales, b.LogScales);
  EXPECT_EQ(a.Quaternions, b.Quaternions);
  EXPECT_EQ(a.Reflectivities, b.Reflectivities);
}

/// @p truth (frames of @p width x @p height pixels) with the pose of each of @p frames moved by a rotation of
/// @p degrees about its centre pixel and a translation of @p mm, in random directions (uniform on the sphere;
/// generator seeded with @p seed).
inline TrainingData PerturbedPoses(const TrainingData& truth, const std::vector<int>& frames, double degrees, double mm,
  unsigned seed, int width, int height)
{
  TrainingData perturbed = truth;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0, 1);
  auto unit = [&](double* v, double length) {
    double n = 0;
    for (int k = 0; k < 3; ++k)
    {
      v[k] = normal(rng);
      n += v[k] * v[k];
    }
    for (int k = 0; k < 3; ++k)
    {
      v[k] *= length / std::sqrt(n);
    }
  };
  for (int f : frames)
  {
    double xi[6];
    unit(xi, degrees * M_PI / 180);
    unit(xi + 3, mm);
    EXPECT_EQ(CorrectPose(truth.Poses[f].data(), width, height, xi, perturbed.Poses[f].data()), PoseStatus::Ok);
  }
  return perturbed;
}

/// Mean distance (mm) of the four corner pixels of each of @p frames in @p d from where they lie in @p truth.
inline double CornerError(
  const TrainingData& d, const TrainingData& truth, const std::vector<int>& frames, int width, int height)
{
  double total = 0;
  for (int f : frames)
  {
    for (double i : { 0.0, width - 1.0 })
    {
      for (double j : { 0.0, height - 1.0 })
      {
        double d2 = 0;
        for (int k = 0; k < 3; ++k)
        {
          const double* a = d.Poses[f].data();
          const double* b = truth.Poses[f].data();
          const double e = (a[4 * k] - b[4 * k]) * i + (a[4 * k + 1] - b[4 * k + 1]) * j + a[4 * k + 3] - b[4 * k + 3];
          d2 += e * e;
        }
        total += std::sqrt(d2);
      }
    }
  }
  return total / (4.0 * frames.size());
}

/// CornerError after the rigid motion that best maps @p d's corners of @p frames onto @p truth's (Umeyama 1991,
/// no scaling): the part of the pose error that is not one motion of the whole sweep, which the frames of one
/// sweep cannot tell from a moved scene.
inline double AlignedCornerError(
  const TrainingData& d, const TrainingData& truth, const std::vector<int>& frames, int width, int height)
{
  Eigen::Matrix3Xd a(3, 4 * frames.size()), b(3, 4 * frames.size());
  Eigen::Index c = 0;
  for (int f : frames)
  {
    for (double i : { 0.0, width - 1.0 })
    {
      for (double j : { 0.0, height - 1.0 })
      {
        for (int k = 0; k < 3; ++k)
        {
          const double* p = d.Poses[f].data();
          const double* q = truth.Poses[f].data();
          a(k, c) = p[4 * k] * i + p[4 * k + 1] * j + p[4 * k + 3];
          b(k, c) = q[4 * k] * i + q[4 * k + 1] * j + q[4 * k + 3];
        }
        ++c;
      }
    }
  }
  const Eigen::Matrix4d T = Eigen::umeyama(a, b, false);
  const Eigen::Matrix3Xd moved = (T.topLeftCorner<3, 3>() * a).colwise() + T.topRightCorner<3, 1>();
  return (moved - b).colwise().norm().mean();
}

/// Mean PSNR (dB) of @p field rendered with @p options at @p data's poses of @p frames against @p data's frames.
inline double PsnrAt(
  const GaussianField& field, const RenderOptions& options, const TrainingData& data, const std::vector<int>& frames)
{
  auto renderer = CreateCpuRenderer();
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  std::vector<float> S(pixels), I(pixels);
  double total = 0;
  for (int f : frames)
  {
    const SliceGeometry g = data.Slice(f);
    EXPECT_TRUE(renderer->Forward(field.View(), &g, 1, options, S.data(), I.data(), nullptr, nullptr));
    total += Psnr(I.data(), &data.Frames[pixels * f], pixels);
  }
  return total / frames.size();
}

/**
 * The fair held-out score of a field trained on refined poses (docs/FINDINGS.md): PsnrAt with each of @p frames'
 * pose first refined from @p truth's with the field frozen (bigus::RefinePosesWithFieldFrozen, @p steps steps,
 * @p settings' pose rates and prior), as view-synthesis papers score test views.
 */
inline double FairPsnr(const GaussianField& field, const RenderOptions& options, const TrainingData& truth,
  const std::vector<int>& frames, const TrainerSettings& settings, int steps = 100)
{
  TrainingData scored = truth;
  std::vector<std::array<double, 6>> corrections;
  std::string error;
  EXPECT_TRUE(RefinePosesWithFieldFrozen(
    field, scored, frames, options, settings.Poses, settings.Loss, steps, "cpu", corrections, &error))
    << error;
  return PsnrAt(field, options, scored, frames);
}

/// The synthetic sweep of the trainer's tests: a known field of random Gaussians and 60 frames of W x H pixels
/// rendered from it, frames with k mod 4 == 2 held out.
namespace synthetic
{
constexpr int W = 64, H = 64;
constexpr double Spacing = 0.3;

/// Pose of frame k of a synthetic sweep: elevation steps of 0.2 mm with a slow +-4 degree rock.
inline std::array<double, 16> SweepPose(int k)
{
  const double tilt = 4.0 * std::sin(0.3 * k) * M_PI / 180.0;
  const double c = std::cos(tilt), s = std::sin(tilt);
  // Columns: u = x axis, v = (0, c, s) rotated about x, origin moving along z.
  return { Spacing, 0, 0, 0.0, 0, c * Spacing, 0, 0.0, 0, s * Spacing, 0, -6.0 + 0.2 * k, 0, 0, 0, 1 };
}

/// @p n random Gaussians (generator seeded with @p seed) in the box the sweep passes through: means in 19.2 x 19.2 x
/// 13 mm, scales 0.4 to 1.2 mm, random rotations, reflectivities 0.25 +- 0.2.
inline GaussianField KnownField(int n, unsigned seed)
{
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0, 1);
  std::normal_distribution<double> normal(0, 1);
  GaussianField f;
  for (int i = 0; i < n; ++i)
  {
    f.Means.push_back(static_cast<float>(19.2 * u01(rng)));
    f.Means.push_back(static_cast<float>(19.2 * u01(rng)));
    f.Means.push_back(static_cast<float>(-6.5 + 13.0 * u01(rng)));
    for (int k = 0; k < 3; ++k)
    {
      f.LogScales.push_back(static_cast<float>(std::log(0.4 + 0.8 * u01(rng))));
    }
    AppendRandomRotation(f, rng, normal);
    f.Reflectivities.push_back(static_cast<float>(0.25 + 0.2 * normal(rng)));
  }
  return f;
}

/// 60 frames rendered from the known field; frames with k mod 4 == 2 are held out.
inline TrainingData SyntheticSweep(const GaussianField& truth, double sigmaE, std::vector<int>& heldOut)
{
  std::vector<std::array<double, 16>> poses;
  for (int k = 0; k < 60; ++k)
  {
    poses.push_back(SweepPose(k));
  }
  return RenderedSweep(truth, poses, W, H, sigmaE, heldOut);
}

/// Mean PSNR (dB) of @p trainer's field rendered at its data's poses of @p heldOut against their frames.
inline double HeldOutPsnr(const Trainer& trainer, const std::vector<int>& heldOut)
{
  return PsnrAt(trainer.GetField(), trainer.Options(), trainer.GetData(), heldOut);
}

/// A short run on the synthetic sweep: sigma_E 0.5 mm, 800 seeds, 200 steps, one densification (step 100).
inline TrainerSettings ShortSettings()
{
  TrainerSettings s;
  s.ElevationSigma = 0.5;
  s.Seeding.InitialGaussians = 800;
  s.Iterations = 200;
  s.Densification.Start = 100;
  s.Densification.Interval = 100;
  s.Densification.End = 150;
  s.Poses.RefinePoses = PoseRefinement::Off; // exact synthetic poses: the tests of pose refinement switch it on
  return s;
}

/// The setting line of @p report that starts with "@p name = " ("" when it has none).
inline std::string SettingLine(const TrainerReport& report, const std::string& name)
{
  const auto line = std::find_if(report.Settings.begin(), report.Settings.end(),
    [&name](const std::string& l) { return l.rfind(name + " = ", 0) == 0; });
  return line == report.Settings.end() ? std::string() : *line;
}

/// Every parameter of @p f finite.
inline bool AllFinite(const GaussianField& f)
{
  for (const std::vector<float>* v : { &f.Means, &f.LogScales, &f.Quaternions, &f.Reflectivities })
  {
    for (float x : *v)
    {
      if (!std::isfinite(x))
      {
        return false;
      }
    }
  }
  return true;
}
} // namespace synthetic
}

#endif
