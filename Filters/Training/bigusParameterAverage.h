/**
 * @file bigusParameterAverage.h
 * @brief The average of the field's parameters over the schedule's tail (TrainerSettings::ParameterAverage):
 *        iterate averaging (B. T. Polyak and A. B. Juditsky, "Acceleration of stochastic approximation by
 *        averaging", SIAM J. Control Optim. 30(4), 1992) in its exponential form, as an exponential moving average
 *        of the weights is kept in stochastic-gradient training.
 *
 * Adam moves the log-scales, rotations and reflectivities at constant rates to the end (DESIGN section 4.3), so the
 * last field carries the noise of its last steps' frames; an average of the iterates keeps the part that the steps
 * agree on. The average starts once the field's structure is fixed (the densification window closed and the
 * validation frames joined the fit) and mixes a sample in every AverageInterval steps:
 *
 *     x <- (1 - w) x + w f,   w = 1 - exp(-df / tau),
 *
 * f the sample, df the schedule fraction since the previous sample and tau the time constant (a fraction of the
 * schedule, so that a run of many short steps and one of few long ones weigh the same share of their schedule).
 * The pose corrections of pose refinement are averaged with the field, so that the two stay registered.
 * docs/FINDINGS.md ("The parameter average") has the held-out measurements behind the default.
 *
 * Part of BIGUS::Training (public, not wrapped for Python).
 */
#ifndef bigusParameterAverage_h
#define bigusParameterAverage_h

#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

namespace bigus
{

/// Steps between two samples of the average.
constexpr int AverageInterval = 10;

/// The weight of a sample taken @p elapsed (a schedule fraction) after the previous one, for a time constant
/// @p timeConstant (a schedule fraction, > 0): 1 - exp(-elapsed / timeConstant), in [0, 1].
BIGUSTRAINING_EXPORT double AverageWeight(double elapsed, double timeConstant);

/**
 * Mixes @p field and @p state's pose corrections (PoseCorrections, SharedPoseCorrection) into @p state's average
 * (AverageField, AveragePoseCorrections, AverageSharedPoseCorrection) with the weight AverageWeight(fraction -
 * state.AverageFraction, timeConstant); the first sample, or one whose field or pose corrections differ in size from
 * the average's (a structure changed), restarts the average with weight 1. A quaternion whose dot product with the
 * average's is negative enters as its antipode (the same rotation). @p iteration and @p fraction (the schedule
 * fraction now) are recorded (AverageStart, AverageFraction, AverageSamples).
 */
BIGUSTRAINING_EXPORT void AccumulateParameterAverage(
  TrainingState& state, const GaussianField& field, int iteration, double fraction, double timeConstant);

/**
 * Makes the average @p state's field and pose corrections (quaternions normalised), the field's Adam moments zero,
 * and clears the average. False, and @p state unchanged, when it has no sample.
 */
BIGUSTRAINING_EXPORT bool ApplyParameterAverage(TrainingState& state);

/// Clears @p state's average (no sample: AverageSamples 0), leaving its field as it is.
BIGUSTRAINING_EXPORT void DropParameterAverage(TrainingState& state);

} // namespace bigus

#endif
