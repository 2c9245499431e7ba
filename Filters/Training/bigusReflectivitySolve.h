/**
 * @file bigusReflectivitySolve.h
 * @brief The reflectivities of a fixed geometry by least squares (DESIGN section 4, "Solve what is
 *        linear").
 *
 * For a fixed geometry S(p) = sum_i r_i w_i(p) = (A r)(p) is linear in the reflectivities, and the image
 * map I = 1 - exp(-gamma max(S, 0)) is monotone. The solve inverts the map on each recorded pixel,
 * t(p) = -ln(1 - min(I(p), MaximumIntensity)) / gamma, and minimises the Gauss-Newton linearisation of
 * the squared intensity error,
 *
 *     sum_f sum_{p in fan_f} g(p) ((A r)(p) - t(p))^2 + lambda ||r||^2,   g(p) = (dI/dS at t)^2 = gamma^2 (1 - I)^2,
 *
 * with lambda = Ridge * mean_i diag(A^T G A) (Tikhonov). The solver is CGLS (Hestenes and Stiefel 1952;
 * Paige and Saunders 1982, section 7.1) on the column-scaled system, Jacobi-preconditioned with
 * diag(A^T G A) + lambda (BasisNorms), through the TrainingEngine's ApplyBasis (A) and ApplyBasisTranspose (A^T),
 * so a CUDA or distributed engine solves by implementing the same products. The CPU and CUDA engines assemble A
 * once per solve where it fits (AssembledBasis on the host, DeviceBasis on the device;
 * ReflectivitySolveSettings::AssembledMemoryShare), so that a product is a pass over stored weights; elsewhere every
 * product renders the frames (matrix free).
 * In exact arithmetic each iteration lowers the objective; it starts from the field's reflectivities.
 *
 * Linearised at the field instead (ReflectivitySolveSettings::LinearizeAtField, a Gauss-Newton step from the field's
 * image S0 = A r0): I(S) ~ I(S0) + I'(c) (S - S0) with c = max(S0, 0) and I'(c) = gamma exp(-gamma c) (the right
 * derivative where the field is rectified), that is g(p) = I'(c)^2 and t(p) = S0 + (I(p) - I(c)) / I'(c). The
 * objective then starts at the field's masked squared intensity error (plus the ridge). The targets at the
 * recorded intensities do not: where a trained field's S is below 0 (its image rectified to 0, which Adam uses
 * freely), they ask for S = t >= 0 and weigh the gap; on the liver's field after 2,000 steps that gap made the
 * objective 8 times the image's error, and a solve lowered it while the image's fit fell 0.7 dB (docs/FINDINGS.md,
 * "The reflectivity solve on a trained field"). The trainer's solves stay at the recorded intensities: after seeding
 * there is no fitted image to linearise at, and variable projection's solves after a densification (whose splits
 * leave the image far from its fit, where the Gauss-Newton weights I'(c)^2 all but ignore over-bright pixels)
 * measured worse at the field.
 *
 * With an L1 term (ReflectivitySolveSettings::L1) the objective gains mu sum_i |r_i| / P_i, a lasso whose
 * solution sets the reflectivities of the Gaussians the data do not need to exactly 0, and the solver is FISTA
 * with backtracking (Beck and Teboulle 2009) on the same scaled system and products.
 *
 * Eigen's iterative solvers were not used: their matrix-free path needs a wrapper type with Eigen's
 * traits and a custom preconditioner, while CGLS itself is a dozen lines here, keeps the residual in
 * data space (better conditioned than CG on the normal equations) and reports the objective per
 * iteration, which the trainer and the tests read.
 *
 * Memory: two float vectors over every pixel of the frames solved ([frames, H, W]: the residual and
 * A p; the liver's 105 training frames of 739 x 593: 368 MB; linearised at the field a third, its image S0) and
 * 52 bytes per Gaussian (six double vectors and one float vector). A solve that would need more than the machine's
 * physical memory is refused before it allocates, with a message that says how much it needed.
 */
#ifndef bigusReflectivitySolve_h
#define bigusReflectivitySolve_h

#include "bigusTrainingEngine.h"
#include "bigusTrainingModule.h" // For export macro

#include <string>
#include <functional>
#include <vector>

namespace bigus
{

struct ReflectivitySolveSettings
{
  int MaximumIterations = 12;     ///< CGLS iterations (each one A and one A^T over every frame)
  double Tolerance = 1e-3;        ///< stop when |A^T G residual| falls below this share of its start
  double Ridge = 1e-4;            ///< lambda as a share of the mean of diag(A^T G A) over the Gaussians
  double MaximumIntensity = 0.98; ///< recorded intensities are clamped to this before the map is inverted
  /// Seconds the solve may take (0 = no limit): it ends after the iteration past which one more iteration, as
  /// long as the last one took, would exceed the limit. At least one iteration is taken; each one lowers the
  /// objective, so a solve cut short is still no worse a fit than its starting point.
  double TimeLimit = 0;
  /// Weight of an L1 term mu sum_i |r_i| / P_i (each Gaussian's |r| times its basis norm sqrt(diag(A^T G A) +
  /// lambda)) as a share of the smallest mu that makes every reflectivity 0 (0: none, CGLS; in (0, 1): FISTA;
  /// the trainer then removes the Gaussians it set to exactly 0 and refits the others by CGLS, the relaxed lasso).
  /// Tolerance then bounds the relative change of the scaled reflectivities between iterations.
  double L1 = 0;
  /// Share of the machine's physical memory that the engine may hold as the assembled basis (AssembledBasis: A built
  /// once per geometry, each product then a pass over its weights instead of a render of every frame); where A needs
  /// more, or with 0, the products are matrix free. The CUDA engine holds its A on the device (DeviceBasis) within
  /// the same bytes and the device's free memory.
  double AssembledMemoryShare = 0.25;
  /// Where the image map is linearised: false, at the recorded intensities (the targets t above: the fit of a
  /// geometry whose reflectivities are not yet fitted, seeds); true, at the field's own image S0 = A r0 (a
  /// Gauss-Newton step: see the file's comment), for a field Adam has trained. CGLS only (FISTA ignores it).
  bool LinearizeAtField = false;
};

struct ReflectivitySolveReport
{
  int Iterations = 0;
  /// The objective (weighted squared error plus the ridge term) at the start and after every iteration.
  std::vector<double> Objective;
  double Lambda = 0;                ///< the ridge weight used
  std::int64_t UnseenGaussians = 0; ///< Gaussians that no pixel of the frames weighs (their r goes to 0)
  double Seconds = 0;
  bool TimeLimitReached = false; ///< it ended on settings.TimeLimit before MaximumIterations or Tolerance
  double L1Weight = 0;           ///< settings.L1: the weight mu used
  std::string Products;          ///< how the engine's products ran (TrainingEngine::DescribeBasisProducts)
};

/// Bytes a solve allocates for @p gaussians Gaussians over @p pixels pixels (frames x H x W): 52 per
/// Gaussian and 8 per pixel (12 linearised at the field, @p atField); with an L1 term (@p l1) 60 and 12.
BIGUSTRAINING_EXPORT double ReflectivitySolveBytes(
  std::int64_t gaussians, std::int64_t pixels, bool l1 = false, bool atField = false);

/**
 * Solves for the reflectivities of the @p engine's current field on @p frames of @p data (the data
 * the engine was given), and returns them in @p reflectivities ([N]; on entry the starting point, for
 * example the field's own). @p options: gamma, sigma_E, cutoff of the renderer.
 * Returns false with @p error when the engine fails (a rejected pose), when no frame is given or no
 * pixel of them is inside the fan mask ("nothing to solve: ..."), when its vectors would not fit in
 * memory, or when the solve meets a non-finite value; @p reflectivities are unchanged then.
 *
 * Data-parallel (@p reduction of several processes, the one the engine was given: every process calls this with
 * the same @p frames and field): each process keeps the residual of its share of @p frames (positions k with
 * k mod P == rank) and applies A and A^T to them only; A^T's N-vectors and the data-space inner products are
 * summed over the processes (ProcessReduction), so every process takes the same CGLS steps and returns the same
 * reflectivities; the time limit is judged on the slowest process's clock (a maximum over the processes).
 */
BIGUSTRAINING_EXPORT bool SolveReflectivities(TrainingEngine& engine, const TrainingData& data,
  const std::vector<int>& frames, const RenderOptions& options, const ReflectivitySolveSettings& settings,
  std::vector<float>& reflectivities, ReflectivitySolveReport* report, std::string* error,
  ProcessReduction* reduction = nullptr);

/// What SolveFieldReflectivities did.
struct FieldSolveReport
{
  ReflectivitySolveReport Last;   ///< the last solve (the refit with an L1 term); its Seconds cover both parts
  ReflectivitySolveReport L1Part; ///< with an L1 term: the L1 solve (FISTA)
  std::int64_t L1Removed = 0;     ///< with an L1 term: the Gaussians it set to 0, removed before the refit
};

/**
 * The solve stage: the reflectivities of @p G's field (which @p engine holds) by least squares on every training
 * frame of @p data (SolveReflectivities with @p settings), Adam's moments of the reflectivities reset. With an L1
 * term, one solve in two parts, the relaxed lasso (Meinshausen, Comput. Stat. Data Anal. 52(1), 2007): the L1 solve
 * chooses the Gaussians; the others (r = 0, and any no training pixel sees) are removed (FinalPrune with tolerance
 * 0; @p engine takes the pruned field) and least squares refits the kept ones' reflectivities without the L1 term's
 * shrinkage. @p timeLimit() gives each part's time limit (s; 0 or less: none), asked when the part starts, where
 * @p settings have none. Returns false with @p error ("reflectivity solve: ...") as SolveReflectivities does.
 */
BIGUSTRAINING_EXPORT bool SolveFieldReflectivities(TrainingEngine& engine, const TrainingData& data,
  const RenderOptions& options, const ReflectivitySolveSettings& settings, const std::function<double()>& timeLimit,
  double gamma, OptimizerState& G, FieldSolveReport& report, std::string* error, ProcessReduction* reduction);

/// The solve stage's `setting` line: variable projection @p on or off (and why: @p nonNegative), @p settings, and
/// the steps between solves (@p interval, 0: after seeding and densification only).
BIGUSTRAINING_EXPORT std::string DescribeReflectivitySolve(
  bool on, bool nonNegative, const ReflectivitySolveSettings& settings, int interval);

} // namespace bigus

#endif
