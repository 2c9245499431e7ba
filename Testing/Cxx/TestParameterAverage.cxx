// The parameter average over the schedule's tail (bigusParameterAverage.h, TrainerSettings::ParameterAverage): the
// exponential moving average against its closed form, and a run's field against the average of the fields an
// observer reads from the same run without it (a resume inside the tail: TestCheckpoints).
#include "bigusParameterAverage.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

using namespace bigus;
using namespace bigus::synthetic;

namespace
{

/// A field of @p n Gaussians with parameters drawn from @p rng (quaternions normalised).
GaussianField RandomField(std::int64_t n, std::mt19937_64& rng)
{
  std::normal_distribution<float> normal;
  GaussianField f;
  f.Resize(n);
  for (int q = 0; q < 4; ++q)
  {
    for (float& x : f.Group(q))
    {
      x = normal(rng);
    }
  }
  for (std::int64_t i = 0; i < n; ++i)
  {
    float* p = &f.Quaternions[4 * i];
    const float norm = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]);
    std::transform(p, p + 4, p, [norm](float x) { return x / norm; });
  }
  return f;
}

/// The exponential moving average of samples mixed in with @p weights (w_0 = 1) written out: the weight of sample k in
/// the result, c_k = w_k prod_{j > k} (1 - w_j).
std::vector<double> ClosedFormWeights(const std::vector<double>& weights)
{
  std::vector<double> c(weights.size());
  for (std::size_t k = 0; k < weights.size(); ++k)
  {
    c[k] = k == 0 ? 1.0 : weights[k];
    for (std::size_t j = k + 1; j < weights.size(); ++j)
    {
      c[k] *= 1 - weights[j];
    }
  }
  return c;
}

/// Normalises each quaternion ([N,4]) of @p quaternions.
void NormaliseQuaternions(std::vector<double>& quaternions)
{
  for (std::size_t k = 0; k + 3 < quaternions.size(); k += 4)
  {
    const double n = std::sqrt(quaternions[k] * quaternions[k] + quaternions[k + 1] * quaternions[k + 1] +
      quaternions[k + 2] * quaternions[k + 2] + quaternions[k + 3] * quaternions[k + 3]);
    for (int c = 0; c < 4; ++c)
    {
      quaternions[k + c] /= n;
    }
  }
}

} // namespace

TEST(ParameterAverage, MixesEachSampleWithTheWeightOfItsScheduleFraction)
{
  EXPECT_NEAR(AverageWeight(0.05, 0.0625), 1 - std::exp(-0.8), 1e-15);
  EXPECT_EQ(AverageWeight(0, 0.1), 0.0);
  EXPECT_EQ(AverageWeight(-1, 0.1), 0.0) << "a sample at an earlier fraction adds nothing";
  EXPECT_NEAR(AverageWeight(100, 0.1), 1.0, 1e-15);

  // Samples at uneven schedule fractions (a time budget's steps are not evenly spaced): the average is the closed
  // form's weighted mean of the samples, and the pose corrections follow the same weights.
  std::mt19937_64 rng(7);
  const std::vector<double> fractions{ 0.60, 0.61, 0.625, 0.70, 0.71, 0.9 };
  const double tau = 0.0625;
  TrainingState state;
  state.PoseCorrections.assign(3, {});
  std::vector<GaussianField> fields;
  std::vector<double> weights, poses;
  for (std::size_t s = 0; s < fractions.size(); ++s)
  {
    fields.push_back(RandomField(40, rng));
    weights.push_back(s == 0 ? 1.0 : AverageWeight(fractions[s] - fractions[s - 1], tau));
    state.PoseCorrections[1][4] = 0.1 * double(s + 1);
    state.SharedPoseCorrection[6] = -0.01 * double(s + 1);
    poses.push_back(0.1 * double(s + 1));
    AccumulateParameterAverage(state, fields.back(), 100 + 10 * int(s), fractions[s], tau);
  }
  EXPECT_EQ(state.AverageSamples, 6);
  EXPECT_EQ(state.AverageStart, 100);
  EXPECT_EQ(state.AverageFraction, 0.9);
  const std::vector<double> c = ClosedFormWeights(weights);
  double expectedPose = 0;
  for (std::size_t k = 0; k < poses.size(); ++k)
  {
    expectedPose += c[k] * poses[k];
  }
  EXPECT_NEAR(state.AveragePoseCorrections[1][4], expectedPose, 1e-12);
  EXPECT_NEAR(state.AverageSharedPoseCorrection[6], -0.1 * expectedPose, 1e-12);
  // Means, log-scales and reflectivities are the closed form; the quaternions too, as long as no sample entered as
  // its antipode (random unit quaternions do, so they are checked below on their own).
  for (int q : { MeanGroup, LogScaleGroup, ReflectivityGroup })
  {
    const std::vector<float>& averaged = state.AverageField.Group(q);
    for (std::size_t k = 0; k < averaged.size(); ++k)
    {
      double expected = 0;
      for (std::size_t sample = 0; sample < fields.size(); ++sample)
      {
        expected += c[sample] * fields[sample].Group(q)[k];
      }
      ASSERT_NEAR(averaged[k], expected, 1e-5) << "group " << q << ", entry " << k;
    }
  }

  // Apply: the field is the average (quaternions normalised), the Adam moments zero, the pose corrections the
  // average's, the average cleared.
  state.Gaussians.Field = fields.back();
  state.Gaussians.ResizeToField();
  std::fill(state.Gaussians.FirstMoment.Means.begin(), state.Gaussians.FirstMoment.Means.end(), 1.0f);
  std::fill(
    state.Gaussians.SecondMoment.Reflectivities.begin(), state.Gaussians.SecondMoment.Reflectivities.end(), 1.0f);
  const GaussianField averaged = state.AverageField;
  ASSERT_TRUE(ApplyParameterAverage(state));
  EXPECT_EQ(state.Gaussians.Field.Means, averaged.Means);
  EXPECT_EQ(state.Gaussians.Field.Reflectivities, averaged.Reflectivities);
  for (std::size_t k = 0; k < averaged.Quaternions.size(); k += 4)
  {
    const float* p = &state.Gaussians.Field.Quaternions[k];
    EXPECT_NEAR(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3], 1.0f, 1e-6f);
  }
  EXPECT_TRUE(std::all_of(state.Gaussians.FirstMoment.Means.begin(), state.Gaussians.FirstMoment.Means.end(),
    [](float x) { return x == 0; }));
  EXPECT_TRUE(std::all_of(state.Gaussians.SecondMoment.Reflectivities.begin(),
    state.Gaussians.SecondMoment.Reflectivities.end(), [](float x) { return x == 0; }));
  EXPECT_NEAR(state.PoseCorrections[1][4], expectedPose, 1e-12);
  EXPECT_EQ(state.AverageSamples, 0);
  EXPECT_EQ(state.AverageField.Count(), 0);
  EXPECT_FALSE(ApplyParameterAverage(state)) << "no sample since: nothing to apply";
}

TEST(ParameterAverage, AQuaternionEntersOnTheAveragesSideAndAChangedFieldRestarts)
{
  // q and -q are one rotation: a sample that flipped sign must not cancel the average.
  GaussianField a, b;
  a.Resize(1);
  b.Resize(1);
  const double h = std::sqrt(0.5);
  a.Quaternions = { float(h), float(h), 0, 0 };
  b.Quaternions = { -float(h), -float(h), 0, 0 };
  TrainingState state;
  AccumulateParameterAverage(state, a, 0, 0.5, 0.0625);
  AccumulateParameterAverage(state, b, 10, 0.6, 0.0625);
  EXPECT_NEAR(state.AverageField.Quaternions[0], h, 1e-6);
  EXPECT_NEAR(state.AverageField.Quaternions[1], h, 1e-6);
  EXPECT_EQ(state.AverageSamples, 2);

  // A field of another size (its structure changed) restarts the average with its first sample.
  GaussianField c;
  c.Resize(2);
  c.Reflectivities = { 3, 4 };
  AccumulateParameterAverage(state, c, 20, 0.7, 0.0625);
  EXPECT_EQ(state.AverageSamples, 1);
  EXPECT_EQ(state.AverageStart, 20);
  EXPECT_EQ(state.AverageField.Reflectivities, c.Reflectivities);
}

// An average that scores worse on the validation frames than the last field they scored is replaced in Finish by that
// field (early stopping), and the ParameterAverage line says so: a time constant of 100 schedules keeps the average at
// its first sample, the field of step 160, while the field of step 200, validated at the densification interval, fits
// better. The run's field is then the plain run's, bit for bit.
TEST(ParameterAverage, AnAverageThatScoresWorseThanTheLastFieldIsReplacedAndTheLineSaysSo)
{
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 6), 0.5, heldOut);
  std::string error;
  TrainerSettings lagging = ShortSettings();
  lagging.ParameterAverage = 100;
  Trainer with(data, lagging);
  ASSERT_TRUE(with.Initialize(&error)) << error;
  ASSERT_TRUE(with.Run(nullptr, nullptr, &error)) << error;
  const TrainerReport& report = with.GetReport();
  EXPECT_EQ(report.AverageSamples, 5);
  EXPECT_TRUE(report.AverageReplaced);
  EXPECT_EQ(report.BestIteration, 200);
  EXPECT_LT(report.BestValidationLoss, report.LastValidationLoss) << "the average scored worse";
  const std::string line = SettingLine(report, "ParameterAverage");
  EXPECT_NE(line.find("made the field at step 200: 5 samples from step 160; early stopping then kept the field of "
                      "step 200 instead (validation loss "),
    std::string::npos)
    << line;

  TrainerSettings plain = lagging;
  plain.ParameterAverage = 0;
  Trainer without(data, plain);
  ASSERT_TRUE(without.Initialize(&error)) << error;
  ASSERT_TRUE(without.Run(nullptr, nullptr, &error)) << error;
  EXPECT_FALSE(without.GetReport().AverageReplaced);
  EXPECT_EQ(with.GetField().Means, without.GetField().Means);
  EXPECT_EQ(with.GetField().Reflectivities, without.GetField().Reflectivities);
}

TEST(ParameterAverage, TheRunsFieldIsTheAverageOfItsTailSteps)
{
  // Two runs of one schedule, one with the average (the default) and one without that an observer stops every
  // AverageInterval steps to read its field: the average does not change the steps, so the first run's field is the
  // observer's own average of the second run's fields from the window's close (step 150) to the end (step 200).
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(KnownField(200, 6), 0.5, heldOut);
  std::string error;
  const TrainerSettings averaged = ShortSettings();
  ASSERT_GT(averaged.ParameterAverage, 0) << "on by default";
  Trainer with(data, averaged);
  ASSERT_TRUE(with.Initialize(&error)) << error;
  ASSERT_TRUE(with.Train(nullptr, nullptr, &error)) << error;
  const TrainerReport& report = with.GetReport();
  EXPECT_EQ(report.AverageSamples, 5);
  EXPECT_EQ(report.AverageFrom, 160);
  EXPECT_EQ(report.AverageTo, 200);
  const std::string line = SettingLine(report, "ParameterAverage");
  ASSERT_FALSE(line.empty());
  EXPECT_NE(line.find("made the field at step 200: 5 samples from step 160"), std::string::npos) << line;

  TrainerSettings plain = averaged;
  plain.ParameterAverage = 0;
  Trainer without(data, plain);
  ASSERT_TRUE(without.Initialize(&error)) << error;
  std::vector<double> x;
  int samples = 0;
  double last = 0;
  while (without.GetIteration() < plain.Iterations)
  {
    const int target = without.GetIteration() + AverageInterval;
    ASSERT_TRUE(without.Train(
      nullptr, [&]() { return without.GetIteration() >= target; }, &error))
      << error;
    if (without.GetIteration() <= averaged.Densification.End)
    {
      continue;
    }
    const GaussianField& f = without.GetField();
    std::vector<double> sample;
    for (int q = 0; q < 4; ++q)
    {
      const std::vector<float>& v = const_cast<GaussianField&>(f).Group(q);
      sample.insert(sample.end(), v.begin(), v.end());
    }
    const double fraction = double(without.GetIteration()) / plain.Iterations;
    const double w = samples == 0 ? 1.0 : 1 - std::exp(-(fraction - last) / averaged.ParameterAverage);
    x.resize(sample.size());
    for (std::size_t k = 0; k < sample.size(); ++k)
    {
      x[k] = (1 - w) * x[k] + w * sample[k];
    }
    last = fraction;
    ++samples;
  }
  EXPECT_EQ(samples, 5);
  EXPECT_EQ(without.GetReport().AverageSamples, 0);
  const std::size_t n = static_cast<std::size_t>(without.GetField().Count());
  std::vector<double> quaternions(x.begin() + 6 * n, x.begin() + 10 * n);
  NormaliseQuaternions(quaternions);
  std::copy(quaternions.begin(), quaternions.end(), x.begin() + 6 * n);
  const GaussianField& delivered = with.GetField();
  ASSERT_EQ(delivered.Count(), static_cast<std::int64_t>(n));
  std::size_t k = 0;
  double largest = 0;
  for (int q = 0; q < 4; ++q)
  {
    for (float v : const_cast<GaussianField&>(delivered).Group(q))
    {
      largest = std::max(largest, std::abs(v - x[k]) / (1 + std::abs(x[k])));
      ++k;
    }
  }
  EXPECT_LT(largest, 1e-5);
  // And the average is not the last field: the test would pass for a run that ignored the setting otherwise.
  EXPECT_NE(delivered.Means, without.GetField().Means);
}
