// Error-attributed densification and pruning (see bigusDensification.h and DESIGN section 4.5).
#include "bigusDensification.h"

#include "bigusGaussianMath.h"
#include "bigusRasterGeometry.h"
#include "bigusSliceFrame.h"

#include "vtkSMPTools.h"
#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

namespace bigus
{
namespace
{
constexpr double SplitShrink = 1.6; // every scale of a split Gaussian is divided by this
}

std::int64_t DensifyGaussian(GaussianField& field, std::int64_t i, double splitScale)
{
  const float* l = &field.LogScales[3 * i];
  const int major = static_cast<int>(std::max_element(l, l + 3) - l);
  const double s = std::exp(double(l[major]));
  const bool large = s > splitScale;
  double q[4] = { field.Quaternions[4 * i], field.Quaternions[4 * i + 1], field.Quaternions[4 * i + 2],
    field.Quaternions[4 * i + 3] };
  NormalizeQuaternion(q, q);
  double R[3][3];
  QuaternionToMatrix(q, R);
  // Split: children at +-s/2, every scale divided by 1.6 (as in 3D Gaussian splatting, Kerbl et al.
  // 2023): smaller Gaussians resolve finer detail and render faster. r / 2 each.
  const double offset = large ? 0.5 * s : 0.1 * s;
  const float reflectivity = 0.5f * field.Reflectivities[i];
  const std::int64_t child = field.Count();
  field.Resize(child + 1);
  for (int k = 0; large && k < 3; ++k)
  {
    field.LogScales[3 * i + k] -= static_cast<float>(std::log(SplitShrink));
  }
  field.CopyGaussian(i, child);
  for (int k = 0; k < 3; ++k)
  {
    const double axis = R[k][major];
    field.Means[3 * child + k] = static_cast<float>(field.Means[3 * i + k] - offset * axis);
    field.Means[3 * i + k] = static_cast<float>(field.Means[3 * i + k] + offset * axis);
  }
  field.Reflectivities[i] = reflectivity;
  field.Reflectivities[child] = reflectivity;
  return child;
}

DensificationResult DensifyAndPrune(OptimizerState& G, bool grow, double percentile, std::int64_t maximumGaussians,
  double splitScale, double pruneReflectivity)
{
  GaussianField& F = G.Field;
  const std::int64_t n = F.Count();
  std::vector<unsigned char> split(n, 0);
  std::int64_t added = 0;
  DensificationResult result;
  if (grow)
  {
    std::vector<std::int64_t> order(n);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(
      order.begin(), order.end(), [&](std::int64_t a, std::int64_t b) { return G.Attribution[a] > G.Attribution[b]; });
    const std::int64_t room = maximumGaussians - n;
    const std::int64_t wanted = static_cast<std::int64_t>(n * percentile / 100.0);
    added = std::max<std::int64_t>(0, std::min(room, wanted));
    for (std::int64_t k = 0; k < added; ++k)
    {
      if (G.Attribution[order[k]] <= 0)
      {
        added = k;
        break;
      }
      split[order[k]] = 1;
    }
    result.MaximumReached = room <= wanted;
  }
  for (std::int64_t i = 0; i < n; ++i)
  {
    if (split[i])
    {
      DensifyGaussian(F, i, splitScale);
    }
  }
  // Children and split parents start with fresh optimiser moments; the others keep theirs. Their
  // first steps are large (Adam with the global step's bias correction: 0.1 g / sqrt(0.001 g^2) = 3.2
  // learning rates, carried on by the first moment), which costs a dip in PSNR right after a
  // densification but lets the children move apart: inheriting the parent's second moment removed the
  // dip but ended lower (liver, 10 minutes: 37.1 against 37.5 dB held out, 37.4 against 39.0 trained).
  G.ResizeToField();
  for (std::int64_t i = 0; i < n; ++i)
  {
    if (split[i])
    {
      G.FirstMoment.ZeroGaussian(i);
      G.SecondMoment.ZeroGaussian(i);
    }
  }
  // Prune negligible and never-seen Gaussians (not the ones just made).
  std::vector<unsigned char> keep(F.Count(), 1);
  for (std::int64_t i = 0; i < n; ++i)
  {
    if (!split[i] && (std::abs(F.Reflectivities[i]) < pruneReflectivity || G.SeenCount[i] == 0))
    {
      keep[i] = 0;
    }
  }
  result.Added = added;
  if (std::count(keep.begin(), keep.end(), 1) > 0)
  {
    result.Pruned = F.Count() - std::count(keep.begin(), keep.end(), 1);
    G.Compact(keep);
  }
  G.Attribution.assign(F.Count(), 0.f);
  G.SeenCount.assign(F.Count(), 0);
  return result;
}

std::int64_t FinalPrune(
  OptimizerState& G, const TrainingData& data, const RenderOptions& o, double gamma, double tolerance)
{
  // Removing Gaussian i changes a pixel's scattering field by r_i w_i (its footprint's weight there, at most its peak
  // amp_i), hence its intensity by at most gamma |r_i| w_i (dI/dS <= gamma); removing a set, by at most the sum.
  const GaussianField& field = G.Field;
  const std::int64_t n = field.Count();
  const double sigmaE = EffectiveElevationSigma(o);
  std::vector<SliceGeometry> slices;
  for (int f : data.TrainFrames)
  {
    slices.push_back(data.Slice(f));
  }
  std::vector<PreparedSlice> prepared;
  RenderOptions frames = o;
  frames.MaximumShearAngle = 90; // every training pose passed Initialize's check; refined ones are rigid changes of it
  if (!PrepareSlices(slices.data(), static_cast<int>(slices.size()), frames, prepared, nullptr))
  {
    return 0; // no frame can be set up (an invalid pose): nothing is removed
  }
  auto reflectivity = [&](const GaussianParams& g) {
    return o.NonNegativeReflectivity ? std::max(g.Reflectivity, 0.0) : std::abs(g.Reflectivity);
  };
  auto load = [&](std::int64_t i) {
    return LoadGaussian(
      field.Means.data(), field.LogScales.data(), field.Quaternions.data(), field.Reflectivities.data(), i);
  };
  // The candidates: every Gaussian whose own change stays within the tolerance on every training frame.
  std::vector<unsigned char> keep(n, 0);
  vtkSMPTools::For(0, n, 256, [&](std::int64_t b, std::int64_t e) {
    for (std::int64_t i = b; i < e; ++i)
    {
      const GaussianParams g = load(i);
      const double r = reflectivity(g);
      for (const PreparedSlice& s : prepared)
      {
        const Footprint f = SetupFootprint(g, s.Frame, sigmaE, o.Cutoff, nullptr);
        if (f.Visible && gamma * r * f.Amplitude > tolerance)
        {
          keep[i] = 1;
          break;
        }
      }
    }
  });
  std::vector<std::int64_t> candidates;
  for (std::int64_t i = 0; i < n; ++i)
  {
    if (!keep[i])
    {
      candidates.push_back(i);
    }
  }
  // Together: on each training frame, the candidates' changes summed at every pixel; a candidate that touches a
  // masked pixel where the sum exceeds the tolerance is kept. What remains sums to at most the tolerance at every
  // training pixel (at a pixel over it, none remains; elsewhere a subset's sum is at most the whole set's).
  std::vector<std::vector<std::int64_t>> touching(prepared.size());
  vtkSMPTools::For(0, static_cast<std::int64_t>(prepared.size()), 1, [&](std::int64_t b, std::int64_t e) {
    for (std::int64_t k = b; k < e; ++k)
    {
      const PreparedSlice& s = prepared[k];
      const unsigned char* mask = data.MaskOf(data.TrainFrames[k]);
      std::vector<double> change(std::size_t(s.Width) * s.Height, 0.0);
      // Each candidate's spans on this frame: visit(i, pixel index, weight).
      auto walk = [&](const auto& visit) {
        for (std::int64_t i : candidates)
        {
          const GaussianParams g = load(i);
          const Footprint f = SetupFootprint(g, s.Frame, sigmaE, o.Cutoff, nullptr);
          int box[4];
          if (!f.Visible)
          {
            continue;
          }
          const double amount = gamma * reflectivity(g);
          ForEachFootprintSpan(f, s, box, [&](int row, int first, int last, const auto& weight) {
            const std::size_t pixel = std::size_t(row) * s.Width + box[0];
            for (int col = first; col < last; ++col)
            {
              visit(i, pixel + col, amount * weight(col));
            }
          });
        }
      };
      walk([&](std::int64_t, std::size_t p, double value) { change[p] += value; });
      std::int64_t last = -1;
      walk([&](std::int64_t i, std::size_t p, double value) {
        if (i != last && value > 0 && mask[p] && change[p] > tolerance)
        {
          touching[k].push_back(i);
          last = i;
        }
      });
    }
  });
  for (const std::vector<std::int64_t>& kept : touching)
  {
    for (std::int64_t i : kept)
    {
      keep[i] = 1;
    }
  }
  const std::int64_t removed = n - std::count(keep.begin(), keep.end(), 1);
  if (removed > 0)
  {
    G.Compact(keep);
  }
  return removed;
}

std::string DescribeDensification(const DensificationSettings& s, std::int64_t maximumGaussians)
{
  if (!s.Enabled)
  {
    return "Densification = off";
  }
  return vtkfmt::sprintf("Densification = every %d steps from step %d to ", s.Interval, s.Start) +
    (s.End >= 0 ? vtkfmt::sprintf("step %d", s.End)
                : vtkfmt::sprintf("%.0f %% of the schedule", 100 * DensifyEndFraction)) +
    vtkfmt::sprintf(", top %.3g %% by attribution", s.Percentile) +
    (s.ResidualSeedShare > 0 ? vtkfmt::sprintf(" and %.3g as many seeds where the residual of %d frames is largest",
                                 s.ResidualSeedShare, s.ResidualSeedFrames)
                             : std::string()) +
    vtkfmt::sprintf(", at most %lld Gaussians", static_cast<long long>(maximumGaussians)) +
    vtkfmt::sprintf("; growth stops when the validation loss improves by less than %.3g %%", 100 * s.GrowthMargin) +
    vtkfmt::sprintf(" over %d intervals", s.GrowthPatience);
}

std::string UpdateGrowth(TrainingState& state, double validation, const DensificationSettings& s)
{
  if (!state.Growing)
  {
    return std::string();
  }
  if (state.BestValidationLoss < 0 || validation < state.BestValidationLoss * (1 - s.GrowthMargin))
  {
    state.BestValidationLoss = validation;
    state.StalledGrowthSteps = 0;
    return std::string();
  }
  if (++state.StalledGrowthSteps < s.GrowthPatience)
  {
    return std::string();
  }
  state.Growing = false;
  return vtkfmt::sprintf("validation loss improved by less than %.2g %% over %d densification intervals (iteration %d)",
    100 * s.GrowthMargin, s.GrowthPatience, state.Iteration);
}

bool DensifyField(TrainingEngine& engine, const TrainingData& data, const RenderOptions& options, double gamma,
  const SeedShape& shape, const DensificationSettings& settings, std::int64_t maximumGaussians, double validation,
  TrainingState& state, std::string& growthStopReason, std::string* error, DensificationResult* densified)
{
  const DensificationSettings& d = settings;
  const std::string stopped = UpdateGrowth(state, validation, d);
  if (!stopped.empty())
  {
    growthStopReason = stopped;
  }
  // Image-GS's new Gaussians from the residual: rendered before densification changes the field.
  std::vector<int> residualFrames;
  std::vector<float> residuals;
  if (d.ResidualSeedShare > 0 && d.ResidualSeedFrames > 0 && state.Growing &&
    !RenderResiduals(
      engine, data, options, gamma, d.ResidualSeedFrames, state.Random, residualFrames, residuals, error))
  {
    return false;
  }
  const DensificationResult result = DensifyAndPrune(state.Gaussians, state.Growing, d.Percentile, maximumGaussians,
    d.SplitScalePixels * shape.PixelSpacing, d.PruneReflectivity);
  if (!residualFrames.empty() && result.Added > 0)
  {
    const std::int64_t room = maximumGaussians - state.Gaussians.Count();
    SeedResiduals(data, residualFrames, residuals,
      std::min<std::int64_t>(room, std::llround(d.ResidualSeedShare * result.Added)), state.Random, shape,
      state.Gaussians.Field);
    state.Gaussians.ResizeToField();
  }
  if (densified)
  {
    *densified = result;
  }
  if (state.Growing && result.MaximumReached)
  {
    state.Growing = false;
    growthStopReason = "hard maximum of " + std::to_string(maximumGaussians) + " Gaussians reached (iteration " +
      std::to_string(state.Iteration) + ")";
  }
  return true;
}

} // namespace bigus
