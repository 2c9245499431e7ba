// The training state, its checkpoint file, and the engine factory (see bigusTrainingEngine.h).
#include "bigusTrainingEngine.h"

#include "bigusReplaceFile.h"

#include "bigusBackend.h"
#include "bigusSliceFrame.h"

#include <vtksys/SystemInformation.hxx>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

#include <unistd.h>

namespace bigus
{

TrainingEngine::~TrainingEngine() = default;

void TrainingEngine::SetBasisMemoryLimit(std::int64_t)
{}

std::string TrainingEngine::DescribeBasisProducts() const
{
  return std::string("matrix free (the ") + this->GetName() + " engine renders every product)";
}

std::string AssembledBasisText(std::int64_t weights, std::int64_t bytes, double seconds, const char* where)
{
  char text[200];
  std::snprintf(text, sizeof(text), "assembled%s%s (%lld weights, %.0f MB, built in %.2f s)", where ? " " : "",
    where ? where : "", static_cast<long long>(weights), bytes / 1e6, seconds);
  return text;
}

bool TrainingEngine::SetReduction(ProcessReduction* reduction, std::string* error)
{
  if (reduction && reduction->Size() > 1)
  {
    if (error)
    {
      *error = std::string("the ") + this->GetName() + " training engine does not train data-parallel (sums across " +
        "processes); make the engine with CreateTrainingEngine(..., dataParallel true)";
    }
    return false;
  }
  return true;
}

double FrameLoss(const TrainingData& data, int frame, const float* I, const StepRequest& request, float* gradient,
  ImageLossWorkspace* workspace)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  const ImageLossTerms terms = ComputeImageLoss(I, &data.Frames[pixels * frame], data.MaskOf(frame), data.Width,
    data.Height, request.Loss, gradient, false, workspace);
  if (request.Count > 1)
  {
    for (std::size_t p = 0; p < pixels; ++p)
    {
      gradient[p] /= static_cast<float>(request.Count);
    }
  }
  return terms.Total;
}

ProcessReduction::~ProcessReduction() = default;

bool ProcessReduction::AllSucceeded(bool ok, std::string* error)
{
  // A failed process puts 1 in its own slot: the sum says whether any failed, and which.
  std::vector<double> failed(this->Size(), 0.0);
  failed[this->Rank()] = ok ? 0.0 : 1.0;
  std::string communication;
  if (!this->Sum(failed.data(), failed.size(), &communication))
  {
    if (error)
    {
      *error = communication;
    }
    return false;
  }
  for (int r = 0; r < this->Size(); ++r)
  {
    if (failed[r] != 0)
    {
      if (ok && error)
      {
        *error = "another process failed (rank " + std::to_string(r) + "; its own message is on its error output)";
      }
      return false;
    }
  }
  return true;
}

bool CheckTrainingData(const TrainingData& data, std::string* error)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  if (data.TrainFrames.empty() || pixels == 0 ||
    (data.Mask.size() != pixels && data.Mask.size() != pixels * data.Poses.size()) ||
    data.Frames.size() != pixels * data.Poses.size())
  {
    if (error)
    {
      *error = "no training frames, or frames, poses and mask of inconsistent sizes";
    }
    return false;
  }
  // Every training pose must be one the renderer accepts, or the run would stop at its first step.
  const double shearLimit = RenderOptions().MaximumShearAngle;
  for (int f : data.TrainFrames)
  {
    SliceFrame frame;
    const PoseStatus status = ComputeSliceFrame(data.Poses[f].data(), shearLimit, frame);
    if (status != PoseStatus::Ok)
    {
      if (error)
      {
        char detail[120] = "";
        if (status == PoseStatus::Sheared)
        {
          std::snprintf(detail, sizeof(detail), " by %.2f degrees; the renderer accepts at most %.2f",
            frame.shearDegrees, shearLimit);
        }
        *error = "training frame " + std::to_string(f) + ": ImageToReference " + PoseStatusText(status) + detail;
      }
      return false;
    }
  }
  return true;
}

bool CheckTrainingMemory(std::int64_t maximumGaussians, double solveBytes, std::string* error)
{
  const double needed = maximumGaussians * TrainingBytesPerGaussian + solveBytes;
  const double physical = PhysicalMemoryBytes();
  if (physical <= 0 || needed <= physical)
  {
    return true;
  }
  if (error)
  {
    char text[300];
    std::snprintf(text, sizeof(text),
      "MaximumGaussians (%lld) needs %.0f MB of training state (%.0f bytes per Gaussian%s) and this machine has %.0f "
      "MB",
      static_cast<long long>(maximumGaussians), needed / 1e6, TrainingBytesPerGaussian,
      solveBytes > 0 ? " and the reflectivity solve's vectors" : "", physical / 1e6);
    *error = text;
  }
  return false;
}

double MeanFanIntensity(const TrainingData& data, std::int64_t& fanPixels)
{
  const std::size_t pixels = std::size_t(data.Width) * data.Height;
  double sum = 0;
  fanPixels = 0;
  for (int f : data.TrainFrames)
  {
    const float* frame = &data.Frames[pixels * f];
    const unsigned char* mask = data.MaskOf(f);
    for (std::size_t p = 0; p < pixels; ++p)
    {
      if (mask[p])
      {
        sum += frame[p];
        ++fanPixels;
      }
    }
  }
  return fanPixels > 0 ? sum / fanPixels : 0.0;
}

double PixelSpacingOf(const std::array<double, 16>& pose)
{
  SliceFrame frame;
  ComputeSliceFrame(pose.data(), 90, frame);
  return 0.5 * (frame.spacing[0] + frame.spacing[1]);
}

double MeanTrainingPixelSpacing(const TrainingData& data)
{
  if (data.TrainFrames.empty())
  {
    return 1.0;
  }
  double spacing = 0;
  for (int f : data.TrainFrames)
  {
    spacing += PixelSpacingOf(data.Poses[f]);
  }
  return spacing / data.TrainFrames.size();
}

double PhysicalMemoryBytes()
{
  vtksys::SystemInformation info;
  info.RunMemoryCheck();
  return double(info.GetTotalPhysicalMemory()) * 1024.0 * 1024.0; // MiB
}

SliceGeometry TrainingData::Slice(int frame) const
{
  SliceGeometry g;
  std::copy(this->Poses[frame].begin(), this->Poses[frame].end(), g.ImageToReference);
  g.Width = this->Width;
  g.Height = this->Height;
  g.PixelLowPass = this->PixelLowPass;
  return g;
}

namespace
{
/// The grid of DecimateFrames: @p width x @p height pixels, pixel (i, j) at the source's pixel indices
/// (first[0] + 2 i, first[1] + 2 j).
void DecimatedGrid(
  const TrainingData& data, int offsetX, int offsetY, bool average, int& width, int& height, double first[2])
{
  const int partial = average ? 0 : 1; // a point sample needs one pixel of its block, an average all four
  width = (data.Width - offsetX + partial) / 2;
  height = (data.Height - offsetY + partial) / 2;
  first[0] = offsetX + (average ? 0.5 : 0.0);
  first[1] = offsetY + (average ? 0.5 : 0.0);
}
}

TrainingData DecimateFrames(
  const TrainingData& data, const int* frames, int count, int offsetX, int offsetY, bool average)
{
  TrainingData out;
  double first[2];
  DecimatedGrid(data, offsetX, offsetY, average, out.Width, out.Height, first);
  out.PixelLowPass = average ? data.PixelLowPass / 4 + 1.0 / 16 : data.PixelLowPass / 4;
  const std::size_t pixels = std::size_t(out.Width) * out.Height;
  const std::size_t sourcePixels = std::size_t(data.Width) * data.Height;
  out.Frames.resize(pixels * count);
  out.Mask.resize(pixels * count);
  out.Poses.resize(count);
  for (int k = 0; k < count; ++k)
  {
    const int f = frames[k];
    const float* image = data.Frames.data() + sourcePixels * f;
    const unsigned char* mask = data.MaskOf(f);
    for (int j = 0; j < out.Height; ++j)
    {
      for (int i = 0; i < out.Width; ++i)
      {
        const std::size_t from = std::size_t(offsetY + 2 * j) * data.Width + offsetX + 2 * i;
        const std::size_t to = pixels * k + std::size_t(j) * out.Width + i;
        if (average)
        {
          const std::size_t below = from + data.Width;
          out.Frames[to] = 0.25f * (image[from] + image[from + 1] + image[below] + image[below + 1]);
          out.Mask[to] = mask[from] && mask[from + 1] && mask[below] && mask[below + 1];
        }
        else
        {
          out.Frames[to] = image[from];
          out.Mask[to] = mask[from];
        }
      }
    }
    // ImageToReference times the map (i, j) -> (first[0] + 2 i, first[1] + 2 j), row-major.
    const std::array<double, 16>& P = data.Poses[f];
    std::array<double, 16>& Q = out.Poses[k];
    for (int r = 0; r < 4; ++r)
    {
      Q[4 * r + 0] = 2 * P[4 * r + 0];
      Q[4 * r + 1] = 2 * P[4 * r + 1];
      Q[4 * r + 2] = P[4 * r + 2];
      Q[4 * r + 3] = P[4 * r + 0] * first[0] + P[4 * r + 1] * first[1] + P[4 * r + 3];
    }
    if (!data.Sweeps.empty())
    {
      out.Sweeps.push_back(data.Sweeps[f]);
    }
    out.TrainFrames.push_back(k);
  }
  return out;
}

void DecimatedPoseGradientToSource(
  const TrainingData& data, int frame, int offsetX, int offsetY, double gradient[6], bool average)
{
  double F[3][3], origin[3], pixelToPlane[3];
  if (ComputeRenderingFrame(data.Poses[frame].data(), 90, F, origin, pixelToPlane) != PoseStatus::Ok)
  {
    return;
  }
  // The decimated frame's centre pixel in the source's pixel indices, then both centres in plane coordinates.
  int width, height;
  double first[2];
  DecimatedGrid(data, offsetX, offsetY, average, width, height, first);
  const double i = first[0] + (width - 1.0), j = first[1] + (height - 1.0);
  double centre[3];
  SliceCentre(pixelToPlane, data.Width, data.Height, centre);
  const double d[3] = { i * pixelToPlane[0] + j * pixelToPlane[1] - centre[0], j * pixelToPlane[2] - centre[1], 0 };
  const double* t = gradient + 3;
  gradient[0] += d[1] * t[2] - d[2] * t[1];
  gradient[1] += d[2] * t[0] - d[0] * t[2];
  gradient[2] += d[0] * t[1] - d[1] * t[0];
}

// ------------------------------------------------------------------------------------------------

namespace
{
/// Keeps the groups of @p stride entries of @p v (group i = Gaussian i) whose flag in @p keep is
/// non-zero, in order.
template <typename T>
void CompactVector(std::vector<T>& v, const std::vector<unsigned char>& keep, std::size_t stride = 1)
{
  std::size_t out = 0;
  for (std::size_t i = 0; i < v.size() / stride; ++i)
  {
    if (keep[i])
    {
      std::copy_n(&v[stride * i], stride, &v[stride * out++]);
    }
  }
  v.resize(stride * out);
}
}

FieldView GaussianField::View() const
{
  FieldView v;
  v.Count = this->Count();
  v.Means = this->Means.data();
  v.LogScales = this->LogScales.data();
  v.Quaternions = this->Quaternions.data();
  v.Reflectivities = this->Reflectivities.data();
  return v;
}

void GaussianField::Resize(std::int64_t n)
{
  this->Means.resize(3 * n, 0.f);
  this->LogScales.resize(3 * n, 0.f);
  this->Quaternions.resize(4 * n, 0.f);
  this->Reflectivities.resize(n, 0.f);
}

void GaussianField::Compact(const std::vector<unsigned char>& keep)
{
  CompactVector(this->Means, keep, 3);
  CompactVector(this->LogScales, keep, 3);
  CompactVector(this->Quaternions, keep, 4);
  CompactVector(this->Reflectivities, keep);
}

void GaussianField::CopyGaussian(std::int64_t from, std::int64_t to)
{
  std::copy_n(&this->Means[3 * from], 3, &this->Means[3 * to]);
  std::copy_n(&this->LogScales[3 * from], 3, &this->LogScales[3 * to]);
  std::copy_n(&this->Quaternions[4 * from], 4, &this->Quaternions[4 * to]);
  this->Reflectivities[to] = this->Reflectivities[from];
}

void GaussianField::ZeroGaussian(std::int64_t i)
{
  std::fill_n(&this->Means[3 * i], 3, 0.f);
  std::fill_n(&this->LogScales[3 * i], 3, 0.f);
  std::fill_n(&this->Quaternions[4 * i], 4, 0.f);
  this->Reflectivities[i] = 0.f;
}

void OptimizerState::ResizeToField()
{
  const std::int64_t n = this->Field.Count();
  this->FirstMoment.Resize(n);
  this->SecondMoment.Resize(n);
  this->Attribution.resize(n, 0.f);
  this->SeenCount.resize(n, 0);
}

void OptimizerState::Compact(const std::vector<unsigned char>& keep)
{
  this->Field.Compact(keep);
  this->FirstMoment.Compact(keep);
  this->SecondMoment.Compact(keep);
  CompactVector(this->Attribution, keep);
  CompactVector(this->SeenCount, keep);
}

// ------------------------------------------------------------------------------------------------
// Checkpoint file (format in bigusTrainingEngine.h).

namespace
{
template <typename T>
void Put(std::ostream& out, const T& value)
{
  out.write(reinterpret_cast<const char*>(&value), sizeof(T));
}
template <typename T>
void PutVector(std::ostream& out, const std::vector<T>& v)
{
  out.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(v.size() * sizeof(T)));
}
template <typename T>
bool Get(std::istream& in, T& value)
{
  return static_cast<bool>(in.read(reinterpret_cast<char*>(&value), sizeof(T)));
}
template <typename T>
bool GetVector(std::istream& in, std::vector<T>& v, std::size_t n)
{
  v.resize(n);
  return static_cast<bool>(in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T))));
}
/// Every entry of a shared pose correction (or one of its Adam moments) finite.
bool AllFinite(const std::array<double, 7>& v)
{
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}
/// The pose corrections of a field kept beside the run's (the best field's, the parameter average's): int64 P (0, or
/// the frames with a correction) + P x 6 float64, then the 7 float64 shared correction.
void WriteKeptCorrections(
  std::ostream& out, const std::vector<std::array<double, 6>>& frames, const std::array<double, 7>& shared)
{
  Put(out, std::int64_t(frames.size()));
  for (const std::array<double, 6>& xi : frames)
  {
    out.write(reinterpret_cast<const char*>(xi.data()), sizeof(double) * 6);
  }
  out.write(reinterpret_cast<const char*>(shared.data()), sizeof(double) * 7);
}
/// Reads what WriteKeptCorrections wrote; false when it is truncated, its count is neither 0 nor @p poses (the run's
/// frames with a correction) or its shared correction is not finite.
bool ReadKeptCorrections(
  std::istream& in, std::int64_t poses, std::vector<std::array<double, 6>>& frames, std::array<double, 7>& shared)
{
  std::int64_t count = 0;
  if (!Get(in, count) || (count != 0 && count != poses))
  {
    return false;
  }
  frames.resize(static_cast<std::size_t>(count));
  for (std::array<double, 6>& xi : frames)
  {
    if (!in.read(reinterpret_cast<char*>(xi.data()), sizeof(double) * 6))
    {
      return false;
    }
  }
  return in.read(reinterpret_cast<char*>(shared.data()), sizeof(double) * 7) && AllFinite(shared);
}
void WriteField(std::ostream& out, const GaussianField& f)
{
  PutVector(out, f.Means);
  PutVector(out, f.LogScales);
  PutVector(out, f.Quaternions);
  PutVector(out, f.Reflectivities);
}
bool ReadField(std::istream& in, GaussianField& f, std::int64_t n)
{
  return GetVector(in, f.Means, 3 * n) && GetVector(in, f.LogScales, 3 * n) && GetVector(in, f.Quaternions, 4 * n) &&
    GetVector(in, f.Reflectivities, n);
}
}

std::uint64_t TrainingDataDigest(const TrainingData& data)
{
  // FNV-1a over 64-bit words (the bytes of each array, padded with zeros to a whole word), each array preceded by
  // its length, so that moving bytes between arrays changes the digest.
  std::uint64_t h = 14695981039346656037ull;
  auto word = [&h](std::uint64_t w) {
    h ^= w;
    h *= 1099511628211ull;
  };
  auto bytes = [&](const void* data, std::size_t size) {
    word(size);
    const auto* b = static_cast<const unsigned char*>(data);
    std::size_t k = 0;
    for (; k + 8 <= size; k += 8)
    {
      std::uint64_t w;
      std::memcpy(&w, b + k, 8);
      word(w);
    }
    std::uint64_t last = 0;
    if (size > k) // (an empty array's data() may be null, which memcpy must not be given)
    {
      std::memcpy(&last, b + k, size - k);
    }
    word(last);
  };
  word(std::uint64_t(data.Width));
  word(std::uint64_t(data.Height));
  bytes(data.Frames.data(), data.Frames.size() * sizeof(float));
  bytes(data.Poses.data(), data.Poses.size() * sizeof(data.Poses[0]));
  bytes(data.Mask.data(), data.Mask.size());
  bytes(data.TrainFrames.data(), data.TrainFrames.size() * sizeof(int));
  bytes(data.Sweeps.data(), data.Sweeps.size() * sizeof(int));
  bytes(data.Timestamps.data(), data.Timestamps.size() * sizeof(double));
  bytes(data.Valid.data(), data.Valid.size());
  bytes(&data.PixelLowPass, sizeof(double));
  return h;
}

bool TrainingState::Save(const std::string& file, double gamma, std::string* error) const
{
  const std::string temporary = TemporaryName(file);
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out.write("BIGUSCK8", 8);
    Put(out, std::int32_t(this->Iteration));
    Put(out, this->LearningRateScale);
    Put(out, gamma);
    Put(out, std::int32_t(this->Growing));
    Put(out, this->BestValidationLoss);
    Put(out, std::int32_t(this->StalledGrowthSteps));
    Put(out, std::int32_t(this->RolledBackSteps));
    std::ostringstream state;
    state << this->Random;
    const std::string text = state.str();
    Put(out, std::uint32_t(text.size()));
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    const OptimizerState& g = this->Gaussians;
    Put(out, std::int64_t(g.Count()));
    WriteField(out, g.Field);
    WriteField(out, g.FirstMoment);
    WriteField(out, g.SecondMoment);
    PutVector(out, g.Attribution);
    PutVector(out, g.SeenCount);
    Put(out, std::int64_t(this->LossHistory.size()));
    PutVector(out, this->LossHistory);
    Put(out, this->BestFieldLoss);
    Put(out, std::int32_t(this->BestFieldIteration));
    Put(out, std::int64_t(this->BestField.Count()));
    WriteField(out, this->BestField);
    Put(out, this->TrainingSeconds);
    Put(out, std::int64_t(this->PoseCorrections.size()));
    for (std::size_t f = 0; f < this->PoseCorrections.size(); ++f)
    {
      for (const auto* v : { &this->PoseCorrections[f], &this->PoseFirstMoment[f], &this->PoseSecondMoment[f] })
      {
        out.write(reinterpret_cast<const char*>(v->data()), sizeof(double) * 6);
      }
      Put(out, std::int32_t(this->PoseSteps[f]));
    }
    for (const auto* v : { &this->SharedPoseCorrection, &this->SharedPoseFirstMoment, &this->SharedPoseSecondMoment })
    {
      out.write(reinterpret_cast<const char*>(v->data()), sizeof(double) * 7);
    }
    Put(out, std::int32_t(this->SharedPoseSteps));
    WriteKeptCorrections(out, this->BestPoseCorrections, this->BestSharedPoseCorrection);
    Put(out, this->DataDigest);
    Put(out, std::uint32_t(this->RunSettings.size()));
    out.write(this->RunSettings.data(), static_cast<std::streamsize>(this->RunSettings.size()));
    Put(out, std::int32_t(this->AverageSamples));
    Put(out, std::int32_t(this->AverageStart));
    Put(out, this->AverageFraction);
    Put(out, std::int64_t(this->AverageField.Count()));
    WriteField(out, this->AverageField);
    WriteKeptCorrections(out, this->AveragePoseCorrections, this->AverageSharedPoseCorrection);
    Put(out, std::int32_t(this->ValidationJoinedAt));
    Put(out, std::int32_t(this->MeasuredTailEnd));
    out.close();
    if (!out)
    {
      std::remove(temporary.c_str());
      if (error)
      {
        *error = file + ": cannot write the checkpoint";
      }
      return false;
    }
  }
  if (!Publish(temporary, file))
  {
    if (error)
    {
      *error = file + ": cannot replace the checkpoint";
    }
    return false;
  }
  return true;
}

bool TrainingState::Load(const std::string& file, double& gamma, std::string* error)
{
  std::ifstream in(file, std::ios::binary);
  auto fail = [&](const std::string& what) {
    if (error)
    {
      *error = file + ": " + what;
    }
    return false;
  };
  if (!in)
  {
    return fail("cannot open the checkpoint");
  }
  char magic[8];
  if (!in.read(magic, 8) || std::memcmp(magic, "BIGUSCK", 7) != 0 || magic[7] < '1' || magic[7] > '8')
  {
    return fail("not a BIGUS checkpoint (bad magic)");
  }
  const bool withBest = magic[7] >= '2', withSeconds = magic[7] >= '3', withPoses = magic[7] >= '4',
             withShared = magic[7] >= '5', withRun = magic[7] >= '6', withAverage = magic[7] >= '7',
             withTail = magic[7] >= '8';
  TrainingState s;
  std::int32_t iteration, growing, stalled, rolled;
  double storedGamma;
  std::uint32_t length;
  if (!Get(in, iteration) || !Get(in, s.LearningRateScale) || !Get(in, storedGamma) || !Get(in, growing) ||
    !Get(in, s.BestValidationLoss) || !Get(in, stalled) || !Get(in, rolled) || !Get(in, length) || length > (1u << 20))
  {
    return fail("truncated header");
  }
  std::string text(length, '\0');
  std::int64_t n = 0;
  if (!in.read(&text[0], length) || !Get(in, n) || n < 0 || n > (std::int64_t(1) << 32))
  {
    return fail("truncated header");
  }
  OptimizerState& g = s.Gaussians;
  std::int64_t history = 0;
  if (!ReadField(in, g.Field, n) || !ReadField(in, g.FirstMoment, n) || !ReadField(in, g.SecondMoment, n) ||
    !GetVector(in, g.Attribution, n) || !GetVector(in, g.SeenCount, n) || !Get(in, history) || history < 0 ||
    history > (std::int64_t(1) << 32) || !GetVector(in, s.LossHistory, static_cast<std::size_t>(history)))
  {
    return fail("truncated data (" + std::to_string(n) + " Gaussians announced)");
  }
  std::int32_t bestIteration = 0;
  std::int64_t best = 0;
  if (withBest &&
    (!Get(in, s.BestFieldLoss) || !Get(in, bestIteration) || !Get(in, best) || best < 0 ||
      best > (std::int64_t(1) << 32) || !ReadField(in, s.BestField, best)))
  {
    return fail("truncated best field");
  }
  if (withSeconds && (!Get(in, s.TrainingSeconds) || !(s.TrainingSeconds >= 0) || !std::isfinite(s.TrainingSeconds)))
  {
    return fail("truncated or invalid training seconds");
  }
  std::int64_t poses = 0;
  if (withPoses && (!Get(in, poses) || poses < 0 || poses > (std::int64_t(1) << 31)))
  {
    return fail("truncated pose corrections");
  }
  s.PoseCorrections.resize(poses);
  s.PoseFirstMoment.resize(poses);
  s.PoseSecondMoment.resize(poses);
  s.PoseSteps.resize(poses);
  for (std::int64_t f = 0; f < poses; ++f)
  {
    std::int32_t steps = 0;
    for (auto* v : { &s.PoseCorrections[f], &s.PoseFirstMoment[f], &s.PoseSecondMoment[f] })
    {
      if (!in.read(reinterpret_cast<char*>(v->data()), sizeof(double) * 6))
      {
        return fail("truncated pose corrections");
      }
    }
    if (!Get(in, steps) || steps < 0)
    {
      return fail("truncated pose corrections");
    }
    s.PoseSteps[f] = steps;
  }
  if (withShared)
  {
    std::int32_t steps = 0;
    for (auto* v : { &s.SharedPoseCorrection, &s.SharedPoseFirstMoment, &s.SharedPoseSecondMoment })
    {
      if (!in.read(reinterpret_cast<char*>(v->data()), sizeof(double) * 7))
      {
        return fail("truncated shared pose correction");
      }
    }
    if (!Get(in, steps) || steps < 0 || !AllFinite(s.SharedPoseCorrection) || !AllFinite(s.SharedPoseFirstMoment) ||
      !AllFinite(s.SharedPoseSecondMoment))
    {
      return fail("truncated or invalid shared pose correction");
    }
    s.SharedPoseSteps = steps;
    if (!ReadKeptCorrections(in, poses, s.BestPoseCorrections, s.BestSharedPoseCorrection))
    {
      return fail("truncated or invalid best field's pose corrections");
    }
  }
  std::uint32_t settingsLength = 0;
  if (withRun && (!Get(in, s.DataDigest) || !Get(in, settingsLength) || settingsLength > (1u << 20)))
  {
    return fail("truncated data digest or run settings");
  }
  s.RunSettings.assign(settingsLength, '\0');
  if (settingsLength > 0 && !in.read(&s.RunSettings[0], settingsLength))
  {
    return fail("truncated run settings");
  }
  if (withAverage)
  {
    std::int32_t samples = 0, start = 0;
    std::int64_t averaged = 0;
    if (!Get(in, samples) || !Get(in, start) || !Get(in, s.AverageFraction) || !Get(in, averaged) || samples < 0 ||
      start < 0 || !(s.AverageFraction >= 0 && s.AverageFraction <= 1) || (averaged != 0 && averaged != n) ||
      (samples > 0) != (averaged > 0) || !ReadField(in, s.AverageField, averaged))
    {
      return fail("truncated or invalid parameter average");
    }
    if (!ReadKeptCorrections(in, poses, s.AveragePoseCorrections, s.AverageSharedPoseCorrection))
    {
      return fail("truncated or invalid parameter average's pose corrections");
    }
    s.AverageSamples = samples;
    s.AverageStart = start;
  }
  std::int32_t joinedAt = -2, tailEnd = -1;
  if (withTail && (!Get(in, joinedAt) || !Get(in, tailEnd) || joinedAt < -1 || tailEnd < -1))
  {
    return fail("truncated or invalid validation join or measured tail");
  }
  s.ValidationJoinedAt = joinedAt;
  s.MeasuredTailEnd = tailEnd;
  s.BestFieldIteration = bestIteration;
  std::istringstream state(text);
  state >> s.Random;
  if (!state)
  {
    return fail("corrupt random state");
  }
  s.Iteration = iteration;
  s.Growing = growing != 0;
  s.StalledGrowthSteps = stalled;
  s.RolledBackSteps = rolled;
  *this = std::move(s);
  gamma = storedGamma;
  return true;
}

// ------------------------------------------------------------------------------------------------

namespace
{
/// The engines that backends registered, by backend name.
std::map<std::string, TrainingEngineFactory>& EngineFactories(std::unique_lock<std::mutex>& lock)
{
  static std::mutex mutex;
  static std::map<std::string, TrainingEngineFactory> factories;
  lock = std::unique_lock<std::mutex>(mutex);
  return factories;
}
}

void RegisterTrainingEngine(const std::string& name, TrainingEngineFactory factory)
{
  std::unique_lock<std::mutex> lock;
  EngineFactories(lock)[name] = factory;
}

std::unique_ptr<TrainingEngine> CreateTrainingEngine(
  const std::string& name, std::string* error, std::string* notice, bool dataParallel)
{
  // Every backend comes from the one registry; its renderer says which one "auto" chose.
  std::unique_ptr<Renderer> renderer = CreateRenderer(name, error, notice);
  if (!renderer)
  {
    return nullptr;
  }
  const std::string backend = renderer->GetName();
  TrainingEngineFactory factory = nullptr;
  if (!dataParallel) // data-parallel: the CPU engine's step, which sums through the host, over this renderer
  {
    std::unique_lock<std::mutex> lock;
    const auto& factories = EngineFactories(lock);
    const auto found = factories.find(backend);
    factory = found == factories.end() ? nullptr : found->second;
  }
  if (factory)
  {
    std::string why;
    std::unique_ptr<TrainingEngine> engine = factory(&why);
    if (engine)
    {
      return engine;
    }
    const std::string what = "the training engine of backend '" + backend + "' cannot be used: " + why;
    if (!(name.empty() || name == "auto"))
    {
      if (error)
      {
        *error = what;
      }
      return nullptr;
    }
    if (notice)
    {
      *notice = (notice->empty() ? "" : *notice + "; ") + what + "; its renderer trains through the CPU engine";
    }
  }
  // A backend without an engine of its own trains through the CPU engine's host-side step over its renderer.
  return CreateCpuTrainingEngine(std::move(renderer));
}

} // namespace bigus
