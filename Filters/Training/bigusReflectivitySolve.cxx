// The reflectivity solve: preconditioned CGLS over the engine's basis products (see bigusReflectivitySolve.h).
#include "bigusReflectivitySolve.h"

#include "bigusDensification.h"

#include "vtkSMPTools.h"
#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace bigus
{

namespace
{
constexpr std::int64_t Chunk = 1 << 16;

/// sum_k f(k) over [0, n) in fixed chunks summed in order: the same result for any thread count.
template <typename F>
double Sum(std::int64_t n, F f)
{
  std::vector<double> partial((n + Chunk - 1) / Chunk, 0.0);
  vtkSMPTools::For(0, static_cast<std::int64_t>(partial.size()), 1, [&](std::int64_t b, std::int64_t e) {
    for (std::int64_t c = b; c < e; ++c)
    {
      double s = 0;
      for (std::int64_t k = c * Chunk; k < std::min(n, (c + 1) * Chunk); ++k)
      {
        s += f(k);
      }
      partial[c] = s;
    }
  });
  double total = 0;
  for (double s : partial)
  {
    total += s;
  }
  return total;
}

/// f(k) for every k in [0, n), in parallel.
template <typename F>
void ForEach(std::int64_t n, F f)
{
  vtkSMPTools::For(0, n, Chunk, [&](std::int64_t b, std::int64_t e) {
    for (std::int64_t k = b; k < e; ++k)
    {
      f(k);
    }
  });
}

bool Fail(std::string* error, const std::string& message)
{
  if (error)
  {
    *error = message;
  }
  return false;
}
}

double ReflectivitySolveBytes(std::int64_t gaussians, std::int64_t pixels, bool l1, bool atField)
{
  // CGLS, per Gaussian: y, s, direction, ridge, the diagonal and P (double), the reflectivities applied (float);
  // per pixel: the residual and A p (float), and at the field its image S0. FISTA: y, z, the trial point, s at y and
  // at z, the diagonal and P; per pixel: the residuals at y, at z and at the trial point.
  return l1
    ? double(gaussians) * (7 * sizeof(double) + sizeof(float)) + double(pixels) * 3 * sizeof(float)
    : double(gaussians) * (6 * sizeof(double) + sizeof(float)) + double(pixels) * (atField ? 3 : 2) * sizeof(float);
}

bool SolveReflectivities(TrainingEngine& engine, const TrainingData& data, const std::vector<int>& allFrames,
  const RenderOptions& options, const ReflectivitySolveSettings& settings, std::vector<float>& reflectivities,
  ReflectivitySolveReport* report, std::string* error, ProcessReduction* reduction)
{
  const double start = SteadySeconds();
  reduction = reduction && reduction->Size() > 1 ? reduction : nullptr;
  if (allFrames.empty())
  {
    return Fail(error, "nothing to solve: no frame given");
  }
  // Data-parallel: this process's share of the frames; the sums over the data space are summed over processes.
  std::vector<int> frames;
  for (std::size_t k = 0; k < allFrames.size(); ++k)
  {
    if (!reduction || static_cast<int>(k % reduction->Size()) == reduction->Rank())
    {
      frames.push_back(allFrames[k]);
    }
  }
  bool communicated = true;
  auto total = [&](double local) {
    communicated = communicated && (!reduction || reduction->Sum(&local, 1, error));
    return local;
  };
  const std::int64_t n = static_cast<std::int64_t>(reflectivities.size());
  const std::int64_t pixels = std::int64_t(data.Width) * data.Height;
  const int count = static_cast<int>(frames.size());
  const std::int64_t m = pixels * count;
  // Refused before anything is allocated when its vectors alone would not fit in this machine's memory.
  const bool l1 = settings.L1 > 0;
  const bool atField = settings.LinearizeAtField && !l1;
  const double needed = ReflectivitySolveBytes(n, m, l1, atField);
  const double physical = PhysicalMemoryBytes();
  const bool fits = physical <= 0 || needed <= physical;
  if (reduction && !reduction->AllSucceeded(fits, error))
  {
    return fits ? false : Fail(error, "the reflectivity solve does not fit in memory on this process");
  }
  if (!fits)
  {
    char text[300];
    std::snprintf(text, sizeof(text),
      "the reflectivity solve needs %.0f MB (%d frames of %d x %d pixels, %lld Gaussians) and this machine has %.0f MB",
      needed / 1e6, count, data.Width, data.Height, static_cast<long long>(n), physical / 1e6);
    return Fail(error, text);
  }
  // Per pixel of the frames solved: sqrt(g) = gamma (1 - I) inside the fan, 0 outside, and the target t (or, at the
  // field, sqrt(g) = I'(c) and the residual I - I(c)).
  const double gamma = options.Gamma;
  std::vector<const float*> recorded(count);
  std::vector<const unsigned char*> masks(count);
  for (int k = 0; k < count; ++k)
  {
    recorded[k] = &data.Frames[pixels * frames[k]];
    masks[k] = data.MaskOf(frames[k]);
  }
  auto intensity = [&](std::int64_t k) {
    return std::min(std::max(double(recorded[k / pixels][k % pixels]), 0.0), settings.MaximumIntensity);
  };
  // LinearizeAtField: the field's image S0 per pixel (filled below before a weight is read), sqrt(g) = I'(c).
  std::vector<float> field(atField ? m : 0);
  auto root = [&](std::int64_t k) {
    return !masks[k / pixels][k % pixels] ? 0.0
      : atField                           ? gamma * std::exp(-gamma * std::max(double(field[k]), 0.0))
                                          : gamma * (1 - intensity(k));
  };
  const double imaged = total(Sum(m, [&](std::int64_t k) { return root(k) > 0 ? 1.0 : 0.0; }));
  if (!communicated)
  {
    return false;
  }
  if (imaged == 0)
  {
    return Fail(
      error, "nothing to solve: the fan masks of the " + std::to_string(allFrames.size()) + " frames are empty");
  }
  // The products over A assembled once for this solve where it fits beside the vectors.
  const double allowed = settings.AssembledMemoryShare * (physical > 0 ? physical : 0.0) - needed;
  engine.SetBasisMemoryLimit(settings.AssembledMemoryShare > 0 && physical <= 0
      ? std::numeric_limits<std::int64_t>::max()
      : static_cast<std::int64_t>(std::max(0.0, allowed)));
  // The matrix is this solve's: released when it returns, however it returns.
  struct Release
  {
    TrainingEngine& Engine;
    ~Release() { this->Engine.SetBasisMemoryLimit(0); }
  } release{ engine };
  // Data-space vectors: the residual rho and q (A p, the weights G, the input of A^T).
  std::vector<float> rho(m), q(m);
  std::vector<float> applied(n);
  if (atField)
  {
    ForEach(n, [&](std::int64_t i) { applied[i] = reflectivities[i]; });
    if (!engine.ApplyBasis(applied.data(), frames.data(), count, options, field.data(), error))
    {
      return false;
    }
  }
  // Jacobi preconditioner P = (diag(A^T G A) + lambda)^(-1/2).
  ForEach(m, [&](std::int64_t k) { q[k] = static_cast<float>(root(k) * root(k)); });
  std::vector<double> diagonal(n, 0.0);
  if (!engine.BasisNorms(q.data(), frames.data(), count, options, diagonal.data(), error))
  {
    return false;
  }
  std::int64_t seen = 0;
  double meanDiagonal = 0;
  for (double d : diagonal)
  {
    seen += d > 0 ? 1 : 0;
    meanDiagonal += d;
  }
  if (seen == 0)
  {
    return Fail(error,
      "nothing to solve: no Gaussian of the field reaches a pixel inside the fan masks of the " +
        std::to_string(allFrames.size()) + " frames");
  }
  const double lambda = settings.Ridge * meanDiagonal / seen;
  const double rootLambda = std::sqrt(lambda);
  std::vector<double> P(n);
  ForEach(n, [&](std::int64_t i) { P[i] = 1 / std::sqrt(diagonal[i] + lambda); });

  ReflectivitySolveReport local;
  ReflectivitySolveReport& r = report ? *report : local;
  r = ReflectivitySolveReport();
  r.Lambda = lambda;
  r.UnseenGaussians = n - seen;
  // The time limit: stop when one more iteration, as long as the last, would pass it (on the slowest clock).
  double iterationStart = SteadySeconds();
  auto outOfTime = [&]() {
    if (settings.TimeLimit <= 0)
    {
      return false;
    }
    const double now = SteadySeconds();
    double clock[2] = { now - start, now - iterationStart };
    iterationStart = now;
    communicated = communicated && (!reduction || reduction->Maximum(clock, 2, error));
    r.TimeLimitReached = clock[0] + clock[1] > settings.TimeLimit;
    return r.TimeLimitReached;
  };
  std::vector<double> y(n), s(n);
  if (l1)
  {
    // FISTA with backtracking (Beck and Teboulle, SIAM J. Imaging Sci. 2(1), 2009, section 4) on
    // F(y) = |b - B y|^2 + mu |y|_1, B and b as CGLS's below: the penalty weighs each Gaussian's |r_i| by its
    // basis norm 1 / P_i, and mu = L1 x 2 max_i |(B^T b)_i|, the smallest mu for which y = 0 is optimal. The
    // residuals and gradient of the momentum point z are combined from those of the last two iterates (B is
    // linear), so an iteration costs one A and one A^T, plus one A per doubling of the Lipschitz estimate L.
    std::vector<float> atZ(m); // rho: the data part of b - B y at y; q: at the trial point
    std::vector<double> z(n, 0.0), trial(n), sZ(n);
    // out = G^1/2 (t - A P v), the data part of b - B v.
    auto residual = [&](const std::vector<double>& v, std::vector<float>& out) {
      ForEach(n, [&](std::int64_t i) { applied[i] = static_cast<float>(P[i] * v[i]); });
      if (!engine.ApplyBasis(applied.data(), frames.data(), count, options, out.data(), error))
      {
        return false;
      }
      ForEach(m,
        [&](std::int64_t k) { out[k] = static_cast<float>(root(k) * (-std::log1p(-intensity(k)) / gamma - out[k])); });
      return true;
    };
    // g = B^T (b - B v) from the data part res at v (res is overwritten).
    auto gradient = [&](std::vector<float>& res, const std::vector<double>& v, std::vector<double>& g) {
      ForEach(m, [&](std::int64_t k) { res[k] = static_cast<float>(root(k) * res[k]); });
      std::fill(g.begin(), g.end(), 0.0);
      if (!engine.ApplyBasisTranspose(res.data(), frames.data(), count, options, g.data(), error))
      {
        return false;
      }
      ForEach(n, [&](std::int64_t i) { g[i] = P[i] * g[i] - lambda * P[i] * P[i] * v[i]; });
      return true;
    };
    // |b - B v|^2 from the data part at v.
    auto leastSquares = [&](const std::vector<float>& res, const std::vector<double>& v) {
      return total(Sum(m, [&](std::int64_t k) { return double(res[k]) * res[k]; })) +
        lambda * Sum(n, [&](std::int64_t i) { return P[i] * v[i] * P[i] * v[i]; });
    };
    if (!residual(z, atZ) || !gradient(atZ, z, sZ))
    {
      return false;
    }
    double largest = 0;
    for (double g : sZ)
    {
      largest = std::max(largest, std::abs(g));
    }
    const double mu = settings.L1 * 2 * largest;
    auto l1Norm = [&](const std::vector<double>& v) { return Sum(n, [&](std::int64_t i) { return std::abs(v[i]); }); };
    ForEach(n, [&](std::int64_t i) { y[i] = reflectivities[i] / P[i]; });
    if (!residual(y, rho))
    {
      return false;
    }
    double f = leastSquares(rho, y);
    r.Objective.push_back(f + mu * l1Norm(y));
    atZ = rho;
    if (!communicated || !gradient(atZ, y, s))
    {
      return false;
    }
    atZ = rho;
    z = y;
    sZ = s;
    double fZ = f, L = 2, momentum = 1; // B^T B has a unit diagonal, so L >= 2
    iterationStart = SteadySeconds();
    for (int it = 0; it < settings.MaximumIterations; ++it)
    {
      const bool stop = it > 0 && outOfTime();
      if (!communicated)
      {
        return false;
      }
      if (stop)
      {
        break;
      }
      // The proximal step from z, L doubled until the quadratic model at z bounds the least squares.
      double fTrial = 0, moved = 0;
      for (int doubling = 0;; ++doubling)
      {
        const double threshold = mu / L;
        ForEach(n, [&](std::int64_t i) {
          const double v = z[i] + 2 * sZ[i] / L;
          trial[i] = v > threshold ? v - threshold : v < -threshold ? v + threshold : 0.0;
        });
        if (!residual(trial, q))
        {
          return false;
        }
        fTrial = leastSquares(q, trial);
        double inner = 0;
        moved = 0;
        for (std::int64_t i = 0; i < n; ++i)
        {
          inner += sZ[i] * (trial[i] - z[i]);
          moved += (trial[i] - z[i]) * (trial[i] - z[i]);
        }
        if (!communicated)
        {
          return false;
        }
        // Float residuals: a bound met to their rounding is met.
        if (fTrial <= fZ - 2 * inner + 0.5 * L * moved + 1e-6 * fZ)
        {
          break;
        }
        if (doubling == 60 || !std::isfinite(fTrial))
        {
          return Fail(error, "the L1 reflectivity solve found no step at iteration " + std::to_string(it + 1));
        }
        L *= 2;
      }
      const double next = 0.5 * (1 + std::sqrt(1 + 4 * momentum * momentum));
      const double beta = (momentum - 1) / next;
      momentum = next;
      double change = 0, size = 0;
      for (std::int64_t i = 0; i < n; ++i)
      {
        change += (trial[i] - y[i]) * (trial[i] - y[i]);
        size += trial[i] * trial[i];
      }
      // z = y_new + beta (y_new - y), its residual and gradient likewise; then y = y_new.
      ForEach(m, [&](std::int64_t k) {
        atZ[k] = static_cast<float>(q[k] + beta * (double(q[k]) - rho[k]));
        rho[k] = q[k];
      });
      if (!gradient(q, trial, sZ)) // sZ holds the gradient at y_new for now
      {
        return false;
      }
      ForEach(n, [&](std::int64_t i) {
        const double g = sZ[i];
        sZ[i] = g + beta * (g - s[i]);
        s[i] = g;
        z[i] = trial[i] + beta * (trial[i] - y[i]);
        y[i] = trial[i];
      });
      fZ = leastSquares(atZ, z);
      r.Objective.push_back(fTrial + mu * l1Norm(y));
      r.Iterations = it + 1;
      if (!communicated)
      {
        return false;
      }
      if (change <= settings.Tolerance * settings.Tolerance * size)
      {
        break;
      }
    }
    r.L1Weight = mu;
  }
  else
  {
    // CGLS on B y = b, B = [G^1/2 A P; sqrt(lambda) P], b = [G^1/2 t; 0], r = P y.
    std::vector<double> direction(n), ridge(n);
    if (atField)
    {
      // rho = g^1/2 (t - S0) = I - I(c): the image's own residual, so that the objective starts at the field's
      // masked squared intensity error (plus the ridge).
      ForEach(m, [&](std::int64_t k) {
        const double c = std::max(double(field[k]), 0.0);
        const double recordedIntensity = std::min(std::max(double(recorded[k / pixels][k % pixels]), 0.0), 1.0);
        rho[k] = masks[k / pixels][k % pixels] ? static_cast<float>(recordedIntensity + std::expm1(-gamma * c)) : 0.f;
      });
    }
    else
    {
      ForEach(n, [&](std::int64_t i) { applied[i] = reflectivities[i]; });
      if (!engine.ApplyBasis(applied.data(), frames.data(), count, options, q.data(), error))
      {
        return false;
      }
      ForEach(m, [&](std::int64_t k) {
        const double target = -std::log1p(-intensity(k)) / gamma;
        rho[k] = static_cast<float>(root(k) * (target - q[k]));
      });
    }
    ForEach(n, [&](std::int64_t i) {
      y[i] = reflectivities[i] / P[i];
      ridge[i] = -rootLambda * reflectivities[i];
    });
    auto objective = [&]() {
      return total(Sum(m, [&](std::int64_t k) { return double(rho[k]) * rho[k]; })) +
        Sum(n, [&](std::int64_t i) { return ridge[i] * ridge[i]; });
    };
    // s = B^T residual; q is scratch here.
    auto transpose = [&]() {
      ForEach(m, [&](std::int64_t k) { q[k] = static_cast<float>(root(k) * rho[k]); });
      std::fill(s.begin(), s.end(), 0.0);
      if (!engine.ApplyBasisTranspose(q.data(), frames.data(), count, options, s.data(), error))
      {
        return false;
      }
      ForEach(n, [&](std::int64_t i) { s[i] = P[i] * (s[i] + rootLambda * ridge[i]); });
      return true;
    };
    r.Objective.push_back(objective());
    if (!communicated || !transpose())
    {
      return false;
    }
    direction = s;
    double norm = Sum(n, [&](std::int64_t i) { return s[i] * s[i]; });
    const double norm0 = norm;
    iterationStart = SteadySeconds();
    for (int it = 0;
         it < settings.MaximumIterations && norm > 0 && norm > settings.Tolerance * settings.Tolerance * norm0; ++it)
    {
      const bool stop = it > 0 && outOfTime();
      if (!communicated)
      {
        return false;
      }
      if (stop)
      {
        break;
      }
      ForEach(n, [&](std::int64_t i) { applied[i] = static_cast<float>(P[i] * direction[i]); });
      if (!engine.ApplyBasis(applied.data(), frames.data(), count, options, q.data(), error))
      {
        return false;
      }
      ForEach(m, [&](std::int64_t k) { q[k] = static_cast<float>(q[k] * root(k)); });
      const double delta = total(Sum(m, [&](std::int64_t k) { return double(q[k]) * q[k]; })) +
        lambda * Sum(n, [&](std::int64_t i) { return applied[i] * double(applied[i]); });
      if (!communicated)
      {
        return false;
      }
      const double alpha = norm / delta;
      if (!std::isfinite(alpha))
      {
        return Fail(error, "the reflectivity solve met a non-finite step at iteration " + std::to_string(it + 1));
      }
      ForEach(n, [&](std::int64_t i) {
        y[i] += alpha * direction[i];
        ridge[i] -= alpha * rootLambda * applied[i];
      });
      ForEach(m, [&](std::int64_t k) { rho[k] -= static_cast<float>(alpha * q[k]); });
      r.Objective.push_back(objective());
      r.Iterations = it + 1;
      if (!communicated)
      {
        return false;
      }
      if (!transpose())
      {
        return false;
      }
      const double next = Sum(n, [&](std::int64_t i) { return s[i] * s[i]; });
      const double beta = next / norm;
      norm = next;
      ForEach(n, [&](std::int64_t i) { direction[i] = s[i] + beta * direction[i]; });
    }
  }
  std::vector<float> solved(n);
  bool finite = true;
  for (std::int64_t i = 0; i < n; ++i)
  {
    solved[i] = static_cast<float>(P[i] * y[i]);
    finite = finite && std::isfinite(solved[i]);
  }
  if (!finite || !std::isfinite(r.Objective.back()))
  {
    return Fail(error, "the reflectivity solve produced a non-finite value");
  }
  reflectivities.swap(solved);
  r.Seconds = SteadySeconds() - start;
  r.Products = engine.DescribeBasisProducts();
  return true;
}

bool SolveFieldReflectivities(TrainingEngine& engine, const TrainingData& data, const RenderOptions& options,
  const ReflectivitySolveSettings& settings, const std::function<double()>& timeLimit, double gamma, OptimizerState& G,
  FieldSolveReport& report, std::string* error, ProcessReduction* reduction)
{
  const bool relaxed = settings.L1 > 0;
  for (int part = 0; part < (relaxed ? 2 : 1); ++part)
  {
    ReflectivitySolveSettings solve = settings;
    solve.L1 = part == 0 ? solve.L1 : 0.0;
    if (solve.TimeLimit <= 0 && timeLimit)
    {
      solve.TimeLimit = timeLimit();
    }
    std::vector<float> r = G.Field.Reflectivities;
    if (!SolveReflectivities(engine, data, data.TrainFrames, options, solve, r, &report.Last, error, reduction))
    {
      if (error)
      {
        *error = "reflectivity solve: " + *error;
      }
      return false;
    }
    G.Field.Reflectivities.swap(r);
    std::fill(G.FirstMoment.Reflectivities.begin(), G.FirstMoment.Reflectivities.end(), 0.f);
    std::fill(G.SecondMoment.Reflectivities.begin(), G.SecondMoment.Reflectivities.end(), 0.f);
    if (solve.L1 > 0)
    {
      report.L1Part = report.Last;
      report.L1Removed = FinalPrune(G, data, options, gamma, 0.0);
      if (!engine.Push(G, error)) // the refit solves the pruned field
      {
        return false;
      }
    }
  }
  report.Last.Seconds += relaxed ? report.L1Part.Seconds : 0.0;
  return true;
}

std::string DescribeReflectivitySolve(bool on, bool nonNegative, const ReflectivitySolveSettings& s, int interval)
{
  if (!on)
  {
    return "ReflectivitySolve = off (Adam alone)";
  }
  if (nonNegative)
  {
    return "ReflectivitySolve = off (NonNegativeReflectivity: the model is not linear in r)";
  }
  return vtkfmt::sprintf("ReflectivitySolve = on (%s, at most %d iterations, ridge %.3g, after seeding, after every "
                         "densification",
           s.L1 > 0 ? vtkfmt::sprintf("FISTA with L1 %.3g", s.L1) : std::string("CGLS"), s.MaximumIterations, s.Ridge) +
    (interval > 0 ? vtkfmt::sprintf(" and every %d steps)", interval) : std::string(")"));
}

} // namespace bigus
