// The average of the field's parameters over the schedule's tail (see bigusParameterAverage.h).
#include "bigusParameterAverage.h"

#include <vtkSMPTools.h>

#include <algorithm>
#include <cmath>

namespace bigus
{

double AverageWeight(double elapsed, double timeConstant)
{
  return std::min(1.0, std::max(0.0, -std::expm1(-std::max(0.0, elapsed) / timeConstant)));
}

void AccumulateParameterAverage(
  TrainingState& state, const GaussianField& field, int iteration, double fraction, double timeConstant)
{
  const bool restart = state.AverageSamples == 0 || state.AverageField.Count() != field.Count() ||
    state.AveragePoseCorrections.size() != state.PoseCorrections.size();
  if (restart)
  {
    state.AverageField = field;
    state.AveragePoseCorrections = state.PoseCorrections;
    state.AverageSharedPoseCorrection = state.SharedPoseCorrection;
    state.AverageSamples = 1;
    state.AverageStart = iteration;
    state.AverageFraction = fraction;
    return;
  }
  const double weight = AverageWeight(fraction - state.AverageFraction, timeConstant);
  const float w = static_cast<float>(weight);
  GaussianField& a = state.AverageField;
  vtkSMPTools::For(0, field.Count(), [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t i = begin; i < end; ++i)
    {
      for (int c = 0; c < 3; ++c)
      {
        a.Means[3 * i + c] += w * (field.Means[3 * i + c] - a.Means[3 * i + c]);
        a.LogScales[3 * i + c] += w * (field.LogScales[3 * i + c] - a.LogScales[3 * i + c]);
      }
      const float* q = &field.Quaternions[4 * i];
      float* p = &a.Quaternions[4 * i];
      const float sign = p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3] < 0 ? -1.0f : 1.0f;
      for (int c = 0; c < 4; ++c)
      {
        p[c] += w * (sign * q[c] - p[c]);
      }
      a.Reflectivities[i] += w * (field.Reflectivities[i] - a.Reflectivities[i]);
    }
  });
  for (std::size_t f = 0; f < state.PoseCorrections.size(); ++f)
  {
    for (int c = 0; c < 6; ++c)
    {
      state.AveragePoseCorrections[f][c] += weight * (state.PoseCorrections[f][c] - state.AveragePoseCorrections[f][c]);
    }
  }
  for (int c = 0; c < 7; ++c)
  {
    state.AverageSharedPoseCorrection[c] +=
      weight * (state.SharedPoseCorrection[c] - state.AverageSharedPoseCorrection[c]);
  }
  state.AverageSamples += 1;
  state.AverageFraction = fraction;
}

bool ApplyParameterAverage(TrainingState& state)
{
  if (state.AverageSamples == 0 || state.AverageField.Count() != state.Gaussians.Count())
  {
    return false;
  }
  std::vector<float>& q = state.AverageField.Quaternions;
  for (std::size_t k = 0; k + 3 < q.size(); k += 4)
  {
    const double norm = std::sqrt(
      double(q[k]) * q[k] + double(q[k + 1]) * q[k + 1] + double(q[k + 2]) * q[k + 2] + double(q[k + 3]) * q[k + 3]);
    for (int c = 0; c < 4 && norm > 0; ++c)
    {
      q[k + c] = static_cast<float>(q[k + c] / norm);
    }
  }
  OptimizerState& g = state.Gaussians;
  g.Field = std::move(state.AverageField);
  for (GaussianField* moment : { &g.FirstMoment, &g.SecondMoment })
  {
    for (int group = 0; group < 4; ++group)
    {
      std::vector<float>& values = moment->Group(group);
      std::fill(values.begin(), values.end(), 0.0f);
    }
  }
  if (state.AveragePoseCorrections.size() == state.PoseCorrections.size())
  {
    state.PoseCorrections = state.AveragePoseCorrections;
    state.SharedPoseCorrection = state.AverageSharedPoseCorrection;
  }
  DropParameterAverage(state);
  return true;
}

void DropParameterAverage(TrainingState& state)
{
  state.AverageField = GaussianField();
  state.AveragePoseCorrections.clear();
  state.AverageSharedPoseCorrection = {};
  state.AverageSamples = 0;
}

} // namespace bigus
