/**
 * @file bigusAdam.h
 * @brief Adam (Kingma and Ba 2015, algorithm 1): the one update of a parameter from its gradient, used by the CPU
 *        engine, the CUDA engine (the same function on the device) and the pose refiner (bigusPoseRefinement.h).
 *
 * Part of BIGUS::Training (public, not wrapped for Python); header only.
 */
#ifndef bigusAdam_h
#define bigusAdam_h

#include "bigusGaussianMath.h" // BIGUS_HD

#include <cmath>

namespace bigus
{

/// Adam's constants (Kingma and Ba 2015, section 2: beta_1, beta_2; epsilon smaller than theirs, 1e-8, so that
/// the small gradients of far-off Gaussians still move them).
constexpr double AdamBeta1 = 0.9;
constexpr double AdamBeta2 = 0.999;
constexpr double AdamEpsilon = 1e-12;

/// The bias corrections of step @p t (counting from 1): c1 = 1 - beta_1^t, c2 = 1 - beta_2^t.
struct AdamBias
{
  double C1 = 1, C2 = 1;
};
inline AdamBias AdamBiasAt(int t)
{
  return { 1 - std::pow(AdamBeta1, t), 1 - std::pow(AdamBeta2, t) };
}

/**
 * One Adam update of parameter @p x with gradient @p g (double), learning rate @p rate and the step's bias
 * corrections @p bias: m = beta_1 m + (1 - beta_1) g, v = beta_2 v + (1 - beta_2) g^2 (computed in double,
 * stored as @p Moment), x -= rate (m / c1) / (sqrt(v / c2) + epsilon), the step as @p Parameter. The field's
 * engines store parameters and moments as float, the pose refiner as double.
 */
template <typename Parameter, typename Moment>
BIGUS_HD void AdamUpdate(Parameter& x, Moment& m, Moment& v, double g, double rate, const AdamBias& bias)
{
  m = static_cast<Moment>(AdamBeta1 * m + (1 - AdamBeta1) * g);
  v = static_cast<Moment>(AdamBeta2 * v + (1 - AdamBeta2) * g * g);
  x -= static_cast<Parameter>(rate * (m / bias.C1) / (sqrt(v / bias.C2) + AdamEpsilon));
}

} // namespace bigus

#endif
