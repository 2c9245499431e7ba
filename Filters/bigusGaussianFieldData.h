/**
 * @file bigusGaussianFieldData.h
 * @brief Conversion between the Gaussian field's vtkPolyData form (DESIGN section 2) and the
 *        renderer's parameter arrays. Installed with BIGUS::Filters, not wrapped.
 *
 * vtkPolyData form: points = means (mm), one vertex per Gaussian, point data Scale (3, mm),
 * Rotation (4, unit quaternion w x y z), Reflectivity (1); field data ElevationSigma (mm), Gamma, and
 * from the trainer the training geometry (TrainingPoses, TrainingFrameSize, TrainingFanMask; see
 * TrainingGeometry) that the coverage image of a render (TrainingCoverage) is computed from.
 * Renderer form: log-scales, so Scale must be positive.
 */
#ifndef bigusGaussianFieldData_h
#define bigusGaussianFieldData_h

#include "bigusFiltersModule.h" // For export macro
#include "bigusRenderer.h"
#include "bigusTrainer.h"

#include "vtkSmartPointer.h"
#include "vtkType.h"
#include "vtkWeakPointer.h"

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

class vtkDataArray;
class vtkFieldData;
class vtkIdList;
class vtkInformation;
class vtkImageData;
class vtkPolyData;

namespace bigus
{

/// Model constants stored with a field.
struct FieldModel
{
  double ElevationSigma = 0.5; ///< mm
  double Gamma = 1.0;
  double PixelSpacing = 0.0; ///< mm, mean pixel spacing of the training frames (0 = unknown)
};

/**
 * Read a field. Returns false with @p error naming the missing or malformed array (no points, Scale
 * not 3 components, missing Rotation or Reflectivity) or the first bad Gaussian: a Scale not in (0, 1e6] mm, a
 * position not finite within 1e9 mm of the origin, a Rotation quaternion that is zero or not finite, a Reflectivity
 * that is not a finite float.
 */
BIGUSFILTERS_EXPORT bool FieldFromPolyData(
  vtkPolyData* data, GaussianField& field, FieldModel& model, std::string* error);

/**
 * The geometry of the frames a field was trained on, kept with the field as field data so that a
 * render can say which of its pixels training data supports (TrainingCoverage):
 * - "TrainingPoses": vtkDoubleArray, 16 components, one tuple per training frame (in the order of the
 *   trainer's "TrainingFrames"): ImageToReference, row-major, pixel (i, j, 0, 1) -> mm.
 * - "TrainingFrameSize": vtkIntArray, one tuple of 2 components: width, height (pixels).
 * - "TrainingFanMask": vtkUnsignedCharArray, width x height values, row-major [H, W] (pixel (i, j) at
 *   j * W + i), 1 where tissue was imaged: the mask used in training, or the union of the training
 *   frames' masks when each frame had its own.
 */
struct TrainingGeometry
{
  int Width = 0, Height = 0;                 ///< pixels
  std::vector<std::array<double, 16>> Poses; ///< [T] ImageToReference of the training frames, row-major
  std::vector<unsigned char> Mask;           ///< [H, W] 1 = imaged
};

/// The geometry of @p data's training frames (TrainFrames, in order); a per-frame mask becomes the union
/// of the training frames' masks. @p data as the trainer accepts it (a mask of either size).
BIGUSFILTERS_EXPORT TrainingGeometry TrainingGeometryOf(const TrainingData& data);

/// Adds @p geometry's three arrays to @p out (replacing arrays of the same names).
BIGUSFILTERS_EXPORT void TrainingGeometryToFieldData(const TrainingGeometry& geometry, vtkFieldData* out);

/**
 * Reads the training geometry. Field data with none of the three arrays (a field written before they
 * existed, a hand-made field) gives an empty geometry (no poses) and true. Returns false with @p error
 * naming the array when one of the three is missing while another is there, or is malformed:
 * TrainingPoses without tuples, not 16 components, or with a pose that is non-finite, not affine or
 * singular; TrainingFrameSize not 2 positive values; TrainingFanMask not one component with
 * width x height tuples.
 */
BIGUSFILTERS_EXPORT bool TrainingGeometryFromFieldData(
  vtkFieldData* in, TrainingGeometry& geometry, std::string* error);

/**
 * How much training data supports each pixel of a rendered slice (issue 19): for a pixel at x (mm,
 * reference frame),
 *
 *   Coverage(x) = sum over training frames t of [x projects inside t's fan mask] exp(-d_t(x)^2 / (2 sigma_E^2))
 *
 * with d_t(x) the distance (mm) from x to the plane of frame t and sigma_E the elevation beam sigma
 * (mm). The projection is the foot of the perpendicular from x on that plane in frame t's pixel
 * coordinates (a, b) (ImageToReference inverted on its plane, exact for a sheared pose); it is inside
 * when the nearest pixel (round(a), round(b)) lies in the frame and its fan mask is set. Coverage is
 * dimensionless: the elevation weights of the training frames, each at most 1. A pixel on a training
 * frame inside its fan gets 1 plus its neighbours' share; a pixel in a gap wider than the beam gets
 * about 0. The weight is the beam profile at unit peak (DESIGN section 3's beam, times
 * sqrt(2 pi) sigma_E). Frames further than CullSigmas sigma_E from a pixel are skipped (each adds less
 * than exp(-8) = 3.4e-4). sigma_E = 0 (a thin-plane field) is the limit: 1 from every frame whose
 * plane the pixel lies on (|d| <= 1e-6 mm), 0 from the others.
 */
class BIGUSFILTERS_EXPORT TrainingCoverage
{
public:
  /// Frames further than this many sigma_E are skipped.
  static constexpr double CullSigmas = 4.0;

  /// Prepares @p geometry (as TrainingGeometryFromFieldData accepts it): the inverse of every pose.
  explicit TrainingCoverage(const TrainingGeometry& geometry = TrainingGeometry());
  /// No training frames: there is no coverage to compute.
  bool IsEmpty() const { return this->Frames.empty(); }
  const TrainingGeometry& GetGeometry() const { return this->Geometry; }

  /**
   * Coverage of the pixels of @p slice into @p coverage ([H, W] floats of the slice, pixel (i, j) at
   * j * W + i), for elevation sigma @p elevationSigma (mm). Rows in parallel (vtkSMPTools); each pixel
   * sums its frames in their order, so the result does not depend on the thread count.
   */
  void Compute(const SliceGeometry& slice, double elevationSigma, float* coverage) const;

  /// Coverage at @p count scattered points ([count, 3] mm, reference frame) into @p coverage ([count]), as Compute
  /// at each (the samples of a reslice whose grid a non-linear transform bends). Points in parallel (vtkSMPTools).
  void ComputePoints(const double* points, std::int64_t count, double elevationSigma, float* coverage) const;

private:
  /// Frame t's pixel coordinates a, b and signed distance d (mm) of a point x: row r gives
  /// Rows[r][0..2] . x + Rows[r][3].
  struct Frame
  {
    double Rows[3][4];
  };
  TrainingGeometry Geometry;
  std::vector<Frame> Frames;
};

/**
 * A field converted from its vtkPolyData form once and kept, for a filter that renders its input on
 * every execute (vtkGaussianFieldReslice, vtkGaussianFieldSequenceRenderer): Update converts only
 * when @p data is not the object converted last time or has been modified since (its GetMTime covers
 * points, point data and field data), so an execute that follows a change of a filter setting alone
 * (a reslice matrix) reuses the conversion. A malformed field's error is kept the same way.
 */
class BIGUSFILTERS_EXPORT FieldCache
{
public:
  /// Brings the conversion up to date with @p data; false with @p error (FieldFromPolyData's) when
  /// @p data is null or not a valid field.
  bool Update(vtkPolyData* data, std::string* error);
  /// The last conversion (valid after Update returned true).
  const GaussianField& GetField() const { return this->Field; }
  const FieldModel& GetModel() const { return this->Model; }
  /// Bounds of the means (xmin, xmax, ymin, ymax, zmin, zmax; mm, reference frame).
  const double* GetBounds() const { return this->Bounds; }
  /// Largest standard deviation of any Gaussian along any of its axes (mm).
  double GetLargestScale() const { return this->LargestScale; }
  /**
   * The training coverage of the last converted field (empty when the field has no training
   * geometry); null with @p error (TrainingGeometryFromFieldData's) when its geometry is malformed.
   * Only a render that outputs coverage asks, so a malformed geometry fails only such a render.
   */
  const TrainingCoverage* GetCoverage(std::string* error) const;
  /**
   * The coverage a render filter outputs (its OutputCoverage flag @p wanted): @p coverage is null when
   * not wanted or when the field has no training geometry (no Coverage array then), else
   * GetCoverage's. Returns false with @p error when wanted and the geometry is malformed.
   */
  bool GetOutputCoverage(bool wanted, const TrainingCoverage*& coverage, std::string* error) const;

private:
  vtkWeakPointer<vtkPolyData> Source;
  vtkMTimeType SourceTime = 0;
  bool Valid = false;
  std::string Error;
  GaussianField Field;
  FieldModel Model;
  double Bounds[6] = { 0, 0, 0, 0, 0, 0 };
  double LargestScale = 0;
  TrainingCoverage Coverage;
  std::string CoverageError; ///< empty when the geometry is well-formed (or absent)
};

/**
 * The renderer a filter keeps between executes, created through the backend registry
 * (bigus::CreateRenderer, DESIGN section 5) and created again only when the backend name changes.
 */
class BIGUSFILTERS_EXPORT RendererCache
{
public:
  /**
   * The renderer of backend @p name ("auto", "cpu", "cuda"; empty = "auto"). Null with @p error
   * ("backend 'x' is not available in this build; available: auto, cpu") when that backend cannot
   * run here; @p notice says which backend "auto" skipped and why, on the call that created it.
   */
  Renderer* Get(const std::string& name, std::string* error, std::string* notice);

private:
  std::unique_ptr<Renderer> Held;
  std::string Name;
};

/// Rendering settings of a stored field: its gamma and elevation sigma (@p elevationSigma < 0 keeps
/// the field's), with footprint cutoff @p cutoff.
BIGUSFILTERS_EXPORT RenderOptions RenderOptionsFor(const FieldModel& model, double elevationSigma, double cutoff);

/// What a render filter has ready after the opening its renders share (vtkGaussianFieldRenderer::BeginRender).
struct RenderSetup
{
  const FieldCache* Field = nullptr;          ///< the up-to-date converted field
  Renderer* Backend = nullptr;                ///< the renderer of the filter's Backend
  const TrainingCoverage* Coverage = nullptr; ///< null: no Coverage array (not wanted, or no training geometry)
  RenderOptions Options;                      ///< RenderOptionsFor the field, ElevationSigma and Cutoff
};

/// The output unit of an intensity of @p scalarType: 1 for VTK_FLOAT and VTK_DOUBLE (I in [0, 1]), 255 for the
/// integer types (the gray levels of 8-bit ultrasound frames).
BIGUSFILTERS_EXPORT double IntensityUnit(int scalarType);

/// The rendered image I ([0, 1] floats) as point-data scalars "Intensity" of @p scalarType (IsIntensityScalarType):
/// I x IntensityUnit, for an integer type rounded to the nearest integer and clamped to the type's range (as
/// vtkImageReslice converts to its OutputScalarType).
BIGUSFILTERS_EXPORT vtkSmartPointer<vtkDataArray> IntensityArray(const std::vector<float>& I, int scalarType);

/// A coverage image (TrainingCoverage::Compute, slices one after the other) as point data "Coverage" (float).
BIGUSFILTERS_EXPORT vtkSmartPointer<vtkDataArray> CoverageArray(const std::vector<float>& coverage);

/// Whether IntensityArray produces @p scalarType: VTK_FLOAT, VTK_DOUBLE, VTK_CHAR, VTK_SIGNED_CHAR,
/// VTK_UNSIGNED_CHAR, VTK_SHORT, VTK_UNSIGNED_SHORT, VTK_INT or VTK_UNSIGNED_INT (vtkImageReslice's output types);
/// false with @p error naming the type and those accepted otherwise. The filters' OutputScalarType setters check it.
BIGUSFILTERS_EXPORT bool IsIntensityScalarType(int scalarType, std::string* error);

/// Write a field (points, vertices, Scale, Rotation normalised, Reflectivity, ElevationSigma, Gamma,
/// PixelSpacing).
BIGUSFILTERS_EXPORT void FieldToPolyData(const GaussianField& field, const FieldModel& model, vtkPolyData* data);

/**
 * Frames, poses and mask of a tracked frame sequence (DESIGN section 2) as training data: intensities
 * scaled to [0, 1] (unsigned char / 255, float clamped), ImageToReference per frame, the field data Timestamp (s) and
 * FrameValid when they have one per frame, and @p mask (a W x H x 1 fan mask or a W x H x N per-frame mask; non-zero =
 * imaged). TrainFrames is left empty. Returns false with @p error when the sequence is not W x H x N one-component
 * scalars with N ImageToReference tuples of 16, or the mask has neither size.
 */
BIGUSFILTERS_EXPORT bool TrainingDataFromSequence(
  vtkImageData* sequence, vtkImageData* mask, TrainingData& data, std::string* error);

/// One tracked sweep for TrainingDataFromSweeps.
struct SweepInput
{
  vtkImageData* Sequence = nullptr; ///< W x H x N tracked frames (DESIGN section 2)
  vtkImageData* Mask = nullptr;     ///< its fan mask, W x H x 1 or W x H x N
  std::string Name;                 ///< how errors name it (e.g. "sweep 1 (B.igs.mha)")
};

/**
 * Several tracked sweeps as one TrainingData, frames in the order of @p sweeps, each with its sweep's index
 * in TrainingData::Sweeps (filled only when there are two sweeps or more). Frames of different sizes share
 * the largest width and height, the rest masked (TrainingData); with several sweeps every frame has its
 * own mask. One sweep gives what TrainingDataFromSequence gives.
 *
 * Refused, with @p error naming the sweep and the reason (and @p data left empty):
 * - what TrainingDataFromSequence refuses;
 * - an empty fan mask (no imaged pixel);
 * - a pixel spacing (the median length of ImageToReference's first two columns over the valid frames)
 *   more than 10 times larger or smaller than the first sweep's: the sweeps are not in the same units
 *   (metres against millimetres), or a calibration does not belong to its sweep;
 * - bounds (the box around the corners of its valid frames, mm) that share no region with those of the
 *   other sweeps, directly or through a chain of sweeps: nothing ties that sweep's field to the others'.
 * Frames with FrameValid 0 are loaded but take no part in the checks.
 */
BIGUSFILTERS_EXPORT bool TrainingDataFromSweeps(
  const std::vector<SweepInput>& sweeps, TrainingData& data, std::string* error);

/**
 * The fan masks a filter with a repeatable sweep port takes on its mask port: none (every one estimated)
 * or one per sweep. Returns false with @p error ("input port 1: M fan masks for N sweeps; ...") otherwise.
 */
BIGUSFILTERS_EXPORT bool CheckMaskCount(int masks, int sweeps, std::string* error);

/**
 * The frames a sequence filter works on: those of @p list (indices into a sequence of @p frameCount
 * frames, in the list's order), or every frame when @p list is null or empty. Returns false with
 * @p error ("frame F is outside the N frames of the pose sequence") for an index out of range.
 */
BIGUSFILTERS_EXPORT bool ChosenFrames(
  vtkIdList* list, vtkIdType frameCount, std::vector<vtkIdType>& frames, std::string* error);

/**
 * Pipeline information of a sequence filter's output that has one frame per chosen frame of the pose
 * sequence described by @p poseInfo: W x H from the pose sequence, one slice per entry of @p list (all
 * frames when null or empty), spacing 1, origin 0, one-component scalars of @p scalarType.
 */
BIGUSFILTERS_EXPORT void SetFrameSequenceInformation(
  vtkInformation* poseInfo, vtkIdList* list, int scalarType, vtkInformation* outInfo);

/**
 * The per-frame field data of a tracked sequence for chosen frames, in their order: every named
 * array of @p in with @p frameCount tuples (ImageToReference, Timestamp, FrameValid, FrameIndex, ...)
 * is copied to @p out with tuple m = tuple frames[m]; FrameIndex (int, the frame's index in the input)
 * is added when @p in has none. Used by every filter that outputs one frame per chosen input frame.
 */
BIGUSFILTERS_EXPORT void CopyFrameFieldData(
  vtkFieldData* in, vtkIdType frameCount, const std::vector<vtkIdType>& frames, vtkFieldData* out);

} // namespace bigus

#endif
