// `bigus benchmark`: the sweeps, the volume protocol and the classical baselines (bigusBenchmarkSweeps.h).
#include "bigusBenchmarkSweeps.h"

#include "bigusGaussianFieldData.h"

#include "vtkDataArray.h"
#include "vtkImageData.h"
#include "vtkFieldData.h"
#include "vtkMetaImageReader.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundFrameInterpolator.h"
#include "vtkUltrasoundSequenceReader.h"
#include "vtkUltrasoundSequenceReslice.h"
#include "vtkUltrasoundVolumeCompounder.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>

namespace bigus::benchmark
{
ImageMetrics Score(const float* predicted, double scale, const TrainingData& data, const std::vector<int>& frames)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  std::vector<float> image(pixels);
  return MeanFrameMetrics(data, frames, [&](std::size_t m, int) {
    for (std::size_t p = 0; p < pixels; ++p)
    {
      image[p] = static_cast<float>(predicted[pixels * m + p] * scale);
    }
    return image.data();
  });
}

vtkSmartPointer<vtkIdList> IdList(const std::vector<int>& frames)
{
  auto list = vtkSmartPointer<vtkIdList>::New();
  for (int k : frames)
  {
    list->InsertNextId(k);
  }
  return list;
}

bool Load(Sweep& sweep, std::string* error)
{
  vtkNew<vtkUltrasoundSequenceReader> reader;
  reader->SetFileName(sweep.File.c_str());
  if (!sweep.Calibration.empty())
  {
    reader->SetCalibrationFileName(sweep.Calibration.c_str());
  }
  if (sweep.FrameRange.size() == 2)
  {
    reader->SetFrameRange(sweep.FrameRange[0], sweep.FrameRange[1]);
  }
  reader->Update();
  if (*reader->GetLastErrorText())
  {
    *error = reader->GetLastErrorText();
    return false;
  }
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputConnection(reader->GetOutputPort());
  fan->Update();
  sweep.Frames = reader->GetOutput();
  sweep.Mask = fan->GetOutput();
  sweep.Scale = sweep.Frames->GetPointData()->GetScalars()->GetDataType() == VTK_UNSIGNED_CHAR ? 1.0 / 255 : 1.0;
  if (!TrainingDataFromSequence(sweep.Frames, sweep.Mask, sweep.Data, error))
  {
    *error = sweep.File + ": " + *error;
    return false;
  }
  vtkDataArray* valid = sweep.Frames->GetFieldData()->GetArray("FrameValid");
  for (int k = 0; k < sweep.Data.Count(); ++k)
  {
    if (!valid || valid->GetTuple1(k) != 0)
    {
      (k % 4 == 2 ? sweep.HeldOut : sweep.Data.TrainFrames).push_back(k);
    }
  }
  int dims[3];
  sweep.Frames->GetDimensions(dims);
  std::ostringstream d;
  if (sweep.FrameRange.size() == 2)
  {
    d << "frames " << sweep.FrameRange[0] << " to " << sweep.FrameRange[1] << ": ";
  }
  d << dims[2] << " frames of " << dims[0] << " x " << dims[1] << " pixels ("
    << Format("%.4f", PixelSpacingOf(sweep.Data.Poses[0])) << " mm), " << sweep.Data.TrainFrames.size()
    << " trained on, " << sweep.HeldOut.size() << " held out (i mod 4 == 2); elevation sigma "
    << Format("%.2f", sweep.ElevationSigma) << " mm, schedule of " << sweep.Iterations << " iterations";
  sweep.Description = d.str();
  return true;
}

std::vector<Row> Baselines(const Sweep& sweep)
{
  std::vector<Row> rows;
  const double n = static_cast<double>(sweep.HeldOut.size());
  for (int mode : { vtkUltrasoundFrameInterpolator::NEAREST_POSE, vtkUltrasoundFrameInterpolator::TEMPORAL_BLEND })
  {
    vtkNew<vtkUltrasoundFrameInterpolator> predict;
    predict->SetInputData(sweep.Frames);
    predict->SetTrainingFrames(IdList(sweep.Data.TrainFrames));
    predict->SetTargetFrames(IdList(sweep.HeldOut));
    predict->SetMode(mode);
    const double t0 = Now();
    predict->Update();
    Row r;
    r.MsPerFrame = 1e3 * (Now() - t0) / n;
    r.Seconds = 0;
    r.Method = mode == vtkUltrasoundFrameInterpolator::NEAREST_POSE ? "nearest training frame (pose)"
                                                                    : "blend of bracketing training frames (time)";
    r.Quality =
      Score(static_cast<float*>(predict->GetOutput()->GetScalarPointer()), sweep.Scale, sweep.Data, sweep.HeldOut);
    rows.push_back(r);
  }
  // PLUS-style compounding of the training frames with PLUS's settings for the bundled phantoms
  // (0.5 mm voxels). Without the held-out frames the gaps between training frames reach 2 to 4.6 mm
  // (spine), so holes are filled with cubes of up to 11 voxels that need 10 % known voxels (two frame
  // planes in an 11^3 cube are 18 %).
  const double voxel = 0.5;
  vtkNew<vtkUltrasoundVolumeCompounder> compound;
  compound->SetInputData(sweep.Frames);
  compound->SetFanMaskData(sweep.Mask);
  compound->SetFrameList(IdList(sweep.Data.TrainFrames));
  compound->SetOutputSpacing(voxel, voxel, voxel);
  compound->SetHoleFillingMaximumKernelSize(11);
  compound->SetHoleFillingMinimumKnownRatio(0.1);
  double t0 = Now();
  compound->Update();
  const double compoundSeconds = Now() - t0;
  vtkNew<vtkUltrasoundSequenceReslice> reslice;
  reslice->SetInputConnection(compound->GetOutputPort());
  reslice->SetPoseData(sweep.Frames);
  reslice->SetFrameList(IdList(sweep.HeldOut));
  reslice->MaskEmptyVoxelsOff();
  t0 = Now();
  reslice->Update();
  Row r;
  r.Method = "compounded volume (NN, MEAN, hole filling) + trilinear reslice";
  r.Seconds = compoundSeconds;
  r.MsPerFrame = 1e3 * (Now() - t0) / n;
  int dims[3];
  compound->GetOutput()->GetDimensions(dims);
  r.Note = Format("%.1f", voxel) + " mm voxels, holes filled up to 11^3, " + std::to_string(dims[0]) + " x " +
    std::to_string(dims[1]) + " x " + std::to_string(dims[2]);
  // The compounded volume holds the input's units (0-255 for 8-bit frames) as float, which the reslice
  // passes through unscaled.
  r.Quality =
    Score(static_cast<float*>(reslice->GetOutput()->GetScalarPointer()), sweep.Scale, sweep.Data, sweep.HeldOut);
  rows.push_back(r);
  return rows;
}

std::vector<Sweep> BundledSweeps(const std::string& root, bool quick)
{
  std::vector<Sweep> sweeps(4);
  sweeps[0].Name = "liver";
  sweeps[0].File = root + "/Examples/Data/liver/liver_sweep.igs.mha";
  // The liver's frames decorrelate within a few tenths of a millimetre (vtkGaussianFieldTrainer.h): held-out
  // PSNR after 10 minutes on 2 cores was 37.6 dB at sigma 0.3 mm, 36.3 at 0.5 and 35.6 at 1.0.
  sweeps[0].ElevationSigma = 0.3;
  sweeps[0].Iterations = quick ? 300 : 8000; // at 10 minutes on 2 cores 7,703 steps are done
  sweeps[0].Marks = quick ? std::vector<double>{ 4, 8 } : std::vector<double>{ 30, 60, 120, 300, 600 };
  sweeps[0].DefaultsBudget = quick ? 4 : 300; // the main job's budget
  sweeps[1].Name = "spine phantom";
  sweeps[1].File = root + "/Testing/Data/spine-phantom/SpinePhantomFreehand.igs.mha";
  sweeps[1].Calibration = root + "/Testing/Data/spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml";
  sweeps[1].ElevationSigma = 1.5;
  sweeps[1].Iterations = quick ? 300 : 3000;
  sweeps[1].Marks = quick ? std::vector<double>{ 4, 8 } : std::vector<double>{ 30, 60, 120, 300 };
  sweeps[1].DefaultsBudget = quick ? 4 : 300;
  sweeps[2].Name = "N-wire phantom";
  sweeps[2].File = root + "/Testing/Data/nwire-phantom/NwirePhantomFreehand.igs.mha";
  sweeps[2].Calibration =
    root + "/Testing/Data/nwire-phantom/PlusDeviceSet_NwirePhantomFreehand_vtkVolumeReconstructorTest2.xml";
  sweeps[2].ElevationSigma = 1.0;
  sweeps[2].Iterations = quick ? 300 : 1200;
  sweeps[2].Marks = quick ? std::vector<double>{ 4 } : std::vector<double>{ 30, 60, 120 };
  sweeps[2].DefaultsBudget = quick ? 4 : 60;
  // The same liver settings on 20 of its 140 frames: in the same time every training frame is visited
  // about 7 times as often, which shows what more steps (a faster backend) would buy on the full sweep.
  sweeps[3] = sweeps[0];
  sweeps[3].Name = "liver, frames 40 to 59";
  sweeps[3].FrameRange = { 40, 59 };
  sweeps[3].DefaultsBudget = quick ? 4 : 120;
  return sweeps;
}

bool MakeVolumeProtocol(const std::string& root, bool quick, VolumeProtocol& vp, std::string* error, int trainFrames)
{
  vp.File = root + "/Testing/Data/spine-phantom/SpinePhantomFreehandReconstructed.mha";
  vtkNew<vtkMetaImageReader> volumeReader;
  volumeReader->SetFileName(vp.File.c_str());
  volumeReader->Update();
  vp.Volume = volumeReader->GetOutput();
  int vdims[3];
  vp.Volume->GetDimensions(vdims);
  if (vdims[0] < 2 || vdims[1] < 2 || vdims[2] < 2)
  {
    return Failed(vp.File + ": cannot read the volume", error);
  }
  trainFrames = trainFrames > 0 ? trainFrames : quick ? 40 : 80;
  const int testFrames = quick ? 10 : 40;
  auto makeSweep = [&](int protocol, int frames, double offset) {
    auto sweep = vtkSmartPointer<vtkUltrasoundVolumeSweep>::New();
    sweep->SetInputData(vp.Volume);
    sweep->SetProtocol(protocol);
    sweep->SetNumberOfFrames(frames);
    sweep->SetOffset(offset);
    sweep->SetMaximumTiltAngle(30);
    sweep->SetSeed(1);
    sweep->Update();
    return sweep;
  };
  vp.Train = makeSweep(vtkUltrasoundVolumeSweep::PARALLEL, trainFrames, 0);
  vp.Tests[0] = makeSweep(vtkUltrasoundVolumeSweep::PARALLEL, trainFrames, 0.5);
  vp.Tests[1] = makeSweep(vtkUltrasoundVolumeSweep::OBLIQUE, testFrames, 0);
  vp.Tests[2] = makeSweep(vtkUltrasoundVolumeSweep::ORTHOGONAL, testFrames, 0);
  if (!TrainingDataFromSequence(vp.Train->GetOutput(), vp.Train->GetMaskOutput(), vp.TrainData, error))
  {
    return Failed("volume protocol: " + *error, error);
  }
  for (int k = 0; k < vp.TrainData.Count(); ++k)
  {
    vp.TrainData.TrainFrames.push_back(k);
  }
  for (int t = 0; t < 3; ++t)
  {
    if (!TrainingDataFromSequence(vp.Tests[t]->GetOutput(), vp.Tests[t]->GetMaskOutput(), vp.TestData[t], error))
    {
      return Failed("volume protocol: " + *error, error);
    }
    for (int k = 0; k < vp.TestData[t].Count(); ++k)
    {
      vp.TestList[t].push_back(k);
    }
  }
  vp.SliceSpacing = vp.Train->GetSliceSpacing();
  vp.ElevationSigma = 0.5 * vp.SliceSpacing;
  std::ostringstream d;
  d << "`" << vp.File.substr(root.size() + 1) << "` (" << vdims[0] << " x " << vdims[1] << " x " << vdims[2]
    << " voxels of 0.5 mm). Training sweep: " << trainFrames << " parallel slices along z, "
    << Format("%.3f", vp.SliceSpacing) << " mm apart, frames of " << vp.TrainData.Width << " x " << vp.TrainData.Height
    << " pixels; per-frame masks of where the volume has data (PLUS leaves unreconstructed voxels at 0). "
    << "Test sweeps: " << trainFrames << " in-between parallel slices (offset half a slice), " << testFrames
    << " oblique slices (random tilt up to 30 degrees, seed 1) and " << testFrames
    << " orthogonal slices (along x). BIGUS elevation sigma = half the slice spacing.";
  vp.Description = d.str();
  return true;
}

namespace
{
/// @p volume resliced trilinearly at each of @p vp's test sweeps' poses and scored, into @p rows (@p seconds: its
/// preparation); with @p resliced, [t] also receives test sweep t's resliced frames ([M, H, W]).
void ResliceAtTestPoses(const VolumeProtocol& vp, vtkAlgorithmOutput* volume, vtkImageData* volumeData,
  const std::string& method, double seconds, Row rows[3], std::vector<float>* resliced = nullptr)
{
  for (int t = 0; t < 3; ++t)
  {
    vtkNew<vtkUltrasoundSequenceReslice> reslice;
    if (volume)
    {
      reslice->SetInputConnection(volume);
    }
    else
    {
      reslice->SetInputData(volumeData);
    }
    reslice->SetPoseConnection(vp.Tests[t]->GetOutputPort());
    reslice->MaskEmptyVoxelsOff();
    const double t0 = Now();
    reslice->Update();
    Row& r = rows[t];
    r.Method = method;
    r.Seconds = seconds;
    r.MsPerFrame = 1e3 * (Now() - t0) / vp.TestList[t].size();
    const float* frames = static_cast<float*>(reslice->GetOutput()->GetScalarPointer());
    r.Quality = Score(frames, 1.0, vp.TestData[t], vp.TestList[t]);
    if (resliced)
    {
      resliced[t].assign(frames, frames + reslice->GetOutput()->GetNumberOfPoints());
    }
  }
}
}

bool StackSlices(const VolumeProtocol& vp, StackedSlices& out, std::string* error)
{
  const TrainingData& d = vp.TrainData;
  const int n = d.Count();
  if (n < 2)
  {
    return Failed("volume protocol: fewer than 2 training slices to stack", error);
  }
  // Pixel (i, j) of slice k lies at origin + i u + j v + k w: u, v along x and y, w along z, the same for every k.
  const std::array<double, 16>& first = d.Poses[0];
  const double step = d.Poses[1][11] - first[11];
  if (!(first[0] > 0 && first[5] > 0 && step > 0)) // vtkImageData's spacing: positive
  {
    return Failed("volume protocol: the training slices do not step along +x, +y and +z", error);
  }
  for (int k = 0; k < n; ++k)
  {
    const std::array<double, 16>& p = d.Poses[k];
    const double expected[12] = { first[0], 0, 0, first[3], 0, first[5], 0, first[7], 0, 0, 0, first[11] + k * step };
    for (int e = 0; e < 12; ++e)
    {
      if (e % 4 != 2 && std::abs(p[e] - expected[e]) > 1e-6 * (1 + std::abs(expected[e])))
      {
        return Failed("volume protocol: training slice " + std::to_string(k) +
            " is not on the axis-aligned, evenly spaced stack the first two define",
          error);
      }
    }
  }
  const std::size_t pixels = std::size_t(d.Width) * d.Height;
  // values(k, p): the value slice k's pixel p is stacked with.
  auto resliceStack = [&](const std::string& method, auto values, Row rows[3], std::vector<float>* resliced) {
    const double t0 = Now();
    vtkNew<vtkImageData> stack;
    stack->SetDimensions(d.Width, d.Height, n);
    stack->SetSpacing(first[0], first[5], step);
    stack->SetOrigin(first[3], first[7], first[11]);
    stack->AllocateScalars(VTK_FLOAT, 1);
    float* voxels = static_cast<float*>(stack->GetScalarPointer());
    for (int k = 0; k < n; ++k)
    {
      for (std::size_t p = 0; p < pixels; ++p)
      {
        voxels[pixels * k + p] = values(k, p);
      }
    }
    ResliceAtTestPoses(vp, nullptr, stack, method, Now() - t0, rows, resliced);
  };
  const float* frames = d.Frames.data();
  std::vector<float> recorded[3], coverage[3];
  resliceStack(
    "training slices stacked + trilinear reslice", [&](int k, std::size_t p) { return frames[pixels * k + p]; },
    out.AsRecorded, recorded);
  resliceStack(
    "training slices stacked within their masks + trilinear reslice",
    [&](int k, std::size_t p) { return d.MaskOf(k)[p] ? frames[pixels * k + p] : 0.f; }, out.WithinMasks, nullptr);
  // The masks stacked (1 where a slice holds data) and resliced: 1 where every sample the trilinear reslice
  // weighs lies within the training masks, below 1 where one reads a pixel the trainer is not given.
  Row unused[3];
  resliceStack(
    "training masks stacked", [&](int k, std::size_t p) { return d.MaskOf(k)[p] ? 1.f : 0.f; }, unused, coverage);
  for (int t = 0; t < 3; ++t)
  {
    const TrainingData& test = vp.TestData[t];
    const std::size_t testPixels = std::size_t(test.Width) * test.Height; // the orthogonal frames are smaller
    TrainingData& covered = out.Covered[t];
    covered = test;
    covered.Mask.resize(testPixels * test.Count());
    std::int64_t scored = 0, kept = 0;
    for (int k = 0; k < test.Count(); ++k)
    {
      const unsigned char* mask = test.MaskOf(k);
      unsigned char* narrowed = covered.Mask.data() + testPixels * k;
      for (std::size_t p = 0; p < testPixels; ++p)
      {
        narrowed[p] = mask[p] && coverage[t][testPixels * k + p] >= 1.f - 1e-4f;
      }
    }
    auto count = [&](const unsigned char* mask) {
      return std::count_if(mask, mask + testPixels, [](unsigned char m) { return m != 0; });
    };
    for (int k : vp.TestList[t])
    {
      scored += count(test.MaskOf(k));
      kept += count(covered.MaskOf(k));
    }
    out.CoveredShare[t] = scored > 0 ? double(kept) / double(scored) : 0.0;
    out.AsRecordedWhereCovered[t] = Score(recorded[t].data(), 1.0, covered, vp.TestList[t]);
  }
  return true;
}

void CompoundVolume(const VolumeProtocol& vp, Row rows[3])
{
  vtkNew<vtkUltrasoundVolumeCompounder> compound;
  compound->SetInputConnection(vp.Train->GetOutputPort());
  compound->SetFanMaskConnection(vp.Train->GetMaskOutputPort());
  compound->SetOutputSpacing(0.5, 0.5, 0.5);
  double t0 = Now();
  compound->Update();
  ResliceAtTestPoses(vp, compound->GetOutputPort(), nullptr, "compounded volume + trilinear reslice", Now() - t0, rows);
}
}
