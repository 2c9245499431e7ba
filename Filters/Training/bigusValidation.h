/**
 * @file bigusValidation.h
 * @brief The validation stage of training (DESIGN section 4): the frames a run scores itself on while it trains, and
 *        their loss, which decides when growth stops (bigus::UpdateGrowth) and which field early stopping keeps.
 *
 * Part of BIGUS::Training (public, not wrapped for Python).
 */
#ifndef bigusValidation_h
#define bigusValidation_h

#include "bigusElevationSigma.h"
#include "bigusHeldOutChoices.h"
#include "bigusImageLoss.h"
#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <string>
#include <vector>

namespace bigus
{

/**
 * The validation frames of @p data: every max(1, n / 8)-th training frame from the first (n = TrainFrames.size()),
 * at most 8, so that a decision does not depend on one lucky frame. They are training frames: the field is fitted
 * to them too, and the end of a sweep is not always among them.
 */
BIGUSTRAINING_EXPORT std::vector<int> ValidationFrames(const TrainingData& data);

/**
 * The validation frames of a run that takes steps, by @p settings (TrainerSettings::HeldOut): @p given frames (the
 * route trial's, RouteTrial::Frames) where there are any, else with HoldOutValidationFrames On, HeldOutFrames(@p data,
 * ValidationStride, MaximumValidationFrames), or with SparseValidationStride where those are fewer than
 * MinimumValidationFrames, when there are at least MinimumValidationFrames (and 2) of them; either taken out of
 * @p data's TrainFrames (@p heldOut true); otherwise ValidationFrames(@p data), training frames (@p heldOut false).
 * @p line receives the stage's setting line ("Validation = ..."), which says that held-out frames are out of the
 * fit until @p until (when the trainer joins them).
 */
BIGUSTRAINING_EXPORT std::vector<int> ChooseValidationFrames(TrainingData& data, const HeldOutChoiceSettings& settings,
  const std::vector<int>& given, bool& heldOut, std::string& line,
  const std::string& until = "the densification window closes");

/**
 * ValidationHoldOut::Auto's rule: true where every sweep was measured (@p sweeps, MeasureSweeps) and no sweep's
 * speckle correlates across its training frames' spacing (CorrelationAtNeighbourSpacing below
 * PoseRefinementMinimumCorrelation, the pose rule's threshold: such a sweep's poses are trusted, and no
 * pose-refinement trial holds frames out). Neighbouring frames that share no speckle let a field fit each frame's
 * own speckle, which the training frames reward and a view between them does not: the spine phantom's held-out
 * PSNR peaked near a third of a 3,000-step schedule while its validation loss on training frames fell to the end
 * (docs/FINDINGS.md, "The spine phantom's held-out PSNR through a schedule"). @p reason receives the measurement,
 * "speckle correlation 0.05 at the training frames' spacing 1.85 mm < 0.3" (sweep by sweep where several).
 */
BIGUSTRAINING_EXPORT bool HoldOutValidationByRule(const std::vector<SweepDecorrelation>& sweeps, std::string& reason);

/// @p frames (held out by ChooseValidationFrames) back into @p data's TrainFrames, in order.
BIGUSTRAINING_EXPORT void JoinTrainingFrames(TrainingData& data, const std::vector<int>& frames);

/**
 * The mean image loss (@p weights; bigus::ComputeImageLoss inside each frame's mask) of @p engine's field on
 * @p frames of @p data, rendered with @p options, into @p loss. Data-parallel (@p reduction of several processes):
 * each process renders the frames k with k mod P == rank and the losses are summed, so that every process takes
 * its decisions from one agreed value. False with @p error when a frame cannot be rendered (on any process).
 */
BIGUSTRAINING_EXPORT bool ValidationLoss(TrainingEngine& engine, const TrainingData& data,
  const std::vector<int>& frames, const RenderOptions& options, const ImageLossWeights& weights,
  ProcessReduction* reduction, double& loss, std::string* error);

/**
 * Early stopping's record: when @p loss is the first validation loss of the run or below the best so far, @p state
 * keeps a copy of @p field (TrainingState::BestField), @p loss, its iteration and the pose corrections it was
 * measured at (BestPoseCorrections, BestSharedPoseCorrection).
 */
BIGUSTRAINING_EXPORT void KeepIfBest(TrainingState& state, double loss, const GaussianField& field);

/**
 * Early stopping at the end of a run: when the last validation loss @p last is above the best kept (KeepIfBest),
 * @p state's field becomes the best one with fresh optimiser moments (the record of the best stays) and its pose
 * corrections those kept with it. Returns whether it did (the frames' poses are then to be composed again,
 * PoseRefiner::ComposePoses).
 */
BIGUSTRAINING_EXPORT bool RestoreBestField(TrainingState& state, double last);

} // namespace bigus

#endif
