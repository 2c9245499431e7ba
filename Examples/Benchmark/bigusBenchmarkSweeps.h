// `bigus benchmark` (bigusBenchmark.h): the bundled sweeps with the hold-out protocol, the volume protocol's
// sweeps through the spine-phantom reconstruction, and the classical baselines of both.
#ifndef bigusBenchmarkSweeps_h
#define bigusBenchmarkSweeps_h

#include "bigusBenchmarkReport.h"
#include "bigusTrainer.h"

#include "vtkIdList.h"
#include "vtkImageData.h"
#include "vtkSmartPointer.h"
#include "vtkUltrasoundVolumeSweep.h"

#include <string>
#include <vector>

namespace bigus::benchmark
{
/// Mean metrics of predicted frames (M frames, [M, H, W], intensities times @p scale) against @p frames
/// of @p data, inside each frame's mask (bigus::MeanFrameMetrics).
ImageMetrics Score(const float* predicted, double scale, const TrainingData& data, const std::vector<int>& frames);

/// The frame indices @p frames as a vtkIdList (the filters' frame lists).
vtkSmartPointer<vtkIdList> IdList(const std::vector<int>& frames);

/// A tracked sweep with the hold-out protocol, in the two forms the methods need.
struct Sweep
{
  std::string Name, File, Calibration, Description;
  double ElevationSigma = 1.0;
  int Iterations = 3000;
  std::vector<int> FrameRange;          ///< empty, or the first and last frame read (inclusive)
  std::vector<double> Marks;            ///< training times (s) at which BIGUS is evaluated
  double DefaultsBudget = 60;           ///< time budget (s) of the defaults against hand-tuned runs
  vtkSmartPointer<vtkImageData> Frames; ///< the sequence as read
  vtkSmartPointer<vtkImageData> Mask;   ///< its fan mask (W x H x 1)
  double Scale = 1;                     ///< input units -> [0, 1]
  TrainingData Data;                    ///< Data.TrainFrames: valid frames with i mod 4 != 2
  std::vector<int> HeldOut;             ///< valid frames with i mod 4 == 2
};

/// Reads @p sweep (its File, Calibration and FrameRange) with its fan mask, splits its valid frames into
/// trained on and held out, and sets its Scale and Description; false with @p error when it cannot be read.
bool Load(Sweep& sweep, std::string* error);

/// The three classical baselines of a sweep, each with its own time.
std::vector<Row> Baselines(const Sweep& sweep);

/**
 * The bundled real sweeps, each with its training schedule and time marks (s): liver, spine phantom,
 * N-wire phantom, and 20 frames of the liver. The default run takes about 3 hours on 2 cores,
 * --quick a few minutes.
 */
std::vector<Sweep> BundledSweeps(const std::string& root, bool quick);

/// The volume protocol's sweeps: parallel training slices through the spine-phantom reconstruction and
/// three test sweeps (in-between parallel, oblique, orthogonal slices).
struct VolumeProtocol
{
  std::string File, Description;
  vtkSmartPointer<vtkImageData> Volume;
  vtkSmartPointer<vtkUltrasoundVolumeSweep> Train, Tests[3];
  TrainingData TrainData, TestData[3];
  std::vector<int> TestList[3];
  double SliceSpacing = 0;
  double ElevationSigma = 0; ///< hand-tuned: half the slice spacing
};

/// Reads the volume and makes the volume protocol's training and test sweeps (fewer frames with @p quick;
/// @p trainFrames > 0: that many parallel training slices, and as many in-between ones; the oblique and orthogonal
/// test slices do not depend on it); false with @p error when the volume cannot be read.
bool MakeVolumeProtocol(
  const std::string& root, bool quick, VolumeProtocol& vp, std::string* error, int trainFrames = 0);

/// The baseline of the volume protocol: the training slices compounded (0.5 mm, the volume's own grid
/// spacing) and resliced trilinearly at each test sweep's poses, into @p rows.
void CompoundVolume(const VolumeProtocol& vp, Row rows[3]);

/// The training slices stacked into a volume (the slice spacing between them, no compounding), resliced
/// trilinearly at each test sweep's poses (StackSlices).
struct StackedSlices
{
  Row AsRecorded[3];  ///< the slices as they are: also their pixels outside their masks (unreconstructed voxels)
  Row WithinMasks[3]; ///< each slice 0 outside its mask: only what the trainer is given
  /// Each test sweep with its masks narrowed to the pixels where every sample the trilinear reslice weighs lies
  /// within the training masks (where the two stacks above agree), the share of the scored pixels kept, and the
  /// stack's score there.
  TrainingData Covered[3];
  double CoveredShare[3] = {};
  ImageMetrics AsRecordedWhereCovered[3];
};

/// The other baselines: the training slices stacked (StackedSlices) and resliced at each test sweep's poses, into
/// @p out; false with @p error when the training slices are not parallel, axis-aligned and evenly spaced (the
/// parallel protocol's are).
bool StackSlices(const VolumeProtocol& vp, StackedSlices& out, std::string* error);
}

#endif
