// The resolution schedule (TrainerSettings::CoarseFraction, CoarseLowPass): the decimated frames
// (bigus::DecimateFrames) against the source frames, point samples and 2 x 2 averages, the pose gradient of a
// decimated frame moved to its source frame, and a run whose first steps are on a quarter of the pixels.
#include "bigusRendererTestUtilities.h"
#include "bigusSliceFrame.h"
#include "bigusTrainer.h"
#include "bigusTrainingTestUtilities.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <vector>

using namespace bigus;
using namespace bigus::synthetic;

namespace
{
/// SyntheticSweep of @p truth (sigma_E 0.5 mm) with a shared fan mask that leaves out every 7th pixel in a slanted
/// pattern, for the decimation tests.
TrainingData SweepWithAMaskWithHoles(const GaussianField& truth)
{
  std::vector<int> heldOut;
  TrainingData data = SyntheticSweep(truth, 0.5, heldOut);
  data.Mask.assign(std::size_t(W) * H, 1);
  for (int j = 0; j < H; ++j)
  {
    for (int i = 0; i < W; ++i)
    {
      data.Mask[std::size_t(j) * W + i] = (i + 3 * j) % 7 != 0;
    }
  }
  return data;
}
}

TEST(Trainer, DecimatedFramesAreTheFramesPointSamplesAtTheSamePoints)
{
  // DecimateFrames (the resolution schedule's coarse frames) against the source frames: each pixel (i, j) is the
  // source's (ox + 2 i, oy + 2 j), in value, mask and position in mm, and a known field rendered at the decimated
  // pose gives the source render's pixels there.
  const GaussianField truth = KnownField(200, 5);
  TrainingData data = SweepWithAMaskWithHoles(truth);
  data.Sweeps.assign(data.Count(), 0);
  data.Sweeps[31] = 1;
  const int frames[2] = { 31, 7 };
  auto cpu = CreateCpuRenderer();
  RenderOptions o;
  o.ElevationSigma = 0.5;
  std::string error;
  for (const auto& [ox, oy] : { std::pair<int, int>{ 0, 0 }, { 1, 0 }, { 0, 1 }, { 1, 1 } })
  {
    const TrainingData d = DecimateFrames(data, frames, 2, ox, oy);
    ASSERT_EQ(d.Width, W / 2);
    ASSERT_EQ(d.Height, H / 2);
    ASSERT_EQ(d.Count(), 2);
    EXPECT_EQ(d.TrainFrames, (std::vector<int>{ 0, 1 }));
    EXPECT_EQ(d.SweepOf(0), 1);
    EXPECT_EQ(d.SweepOf(1), 0);
    for (int k = 0; k < 2; ++k)
    {
      const SliceGeometry coarse = d.Slice(k), full = data.Slice(frames[k]);
      std::vector<float> Sc(std::size_t(d.Width) * d.Height), Sf(std::size_t(W) * H);
      ASSERT_TRUE(cpu->Forward(truth.View(), &coarse, 1, o, Sc.data(), nullptr, nullptr, &error)) << error;
      ASSERT_TRUE(cpu->Forward(truth.View(), &full, 1, o, Sf.data(), nullptr, nullptr, &error)) << error;
      double worst = 0;
      for (int j = 0; j < d.Height; ++j)
      {
        for (int i = 0; i < d.Width; ++i)
        {
          const std::size_t c = std::size_t(j) * d.Width + i, f = std::size_t(oy + 2 * j) * W + ox + 2 * i;
          ASSERT_EQ(d.Frames[c + d.Width * d.Height * k], data.Frames[std::size_t(W) * H * frames[k] + f]);
          ASSERT_EQ(d.MaskOf(k)[c], data.Mask[f]);
          worst = std::max(worst, double(std::abs(Sc[c] - Sf[f])));
          for (int r = 0; r < 3; ++r)
          {
            const double* P = full.ImageToReference;
            const double* Q = coarse.ImageToReference;
            EXPECT_NEAR(Q[4 * r] * i + Q[4 * r + 1] * j + Q[4 * r + 3],
              P[4 * r] * (ox + 2 * i) + P[4 * r + 1] * (oy + 2 * j) + P[4 * r + 3], 1e-12);
          }
        }
      }
      EXPECT_LT(worst, 1e-5) << "the render at the decimated pose, offset " << ox << ", " << oy;
    }
  }
  // An odd size: the offset's row and column count.
  data.Width = W - 1; // frames read as 63 x 64 with the last column of each row moved on: sizes only
  const TrainingData odd = DecimateFrames(data, frames, 1, 0, 1);
  EXPECT_EQ(odd.Width, 32);
  EXPECT_EQ(odd.Height, 32);
  EXPECT_EQ((DecimateFrames(data, frames, 1, 1, 0).Width), 31);
}

TEST(Trainer, AveragedDecimatedFramesAreTheBlockMeansAndTheLowPassRendersThem)
{
  // DecimateFrames with averages (TrainerSettings::CoarseLowPass): pixel (i, j) is the mean of the source's 2 x 2
  // block from (ox + 2 i, oy + 2 j), imaged where all four are, placed at the block's centre, with the low-pass of
  // 1/16 decimated pixels^2; a known field rendered there through the low-pass is closer to the mean of the source
  // render over the block than the point sample at the block's centre is (the truth: the block mean of the
  // full-resolution render).
  const GaussianField truth = KnownField(200, 5);
  TrainingData data = SweepWithAMaskWithHoles(truth);
  const int frame = 31;
  auto cpu = CreateCpuRenderer();
  RenderOptions o;
  o.ElevationSigma = 0.5;
  std::string error;
  const SliceGeometry full = data.Slice(frame);
  std::vector<float> Sf(std::size_t(W) * H);
  ASSERT_TRUE(cpu->Forward(truth.View(), &full, 1, o, Sf.data(), nullptr, nullptr, &error)) << error;
  for (const auto& [ox, oy] : { std::pair<int, int>{ 0, 0 }, { 1, 0 }, { 0, 1 }, { 1, 1 } })
  {
    const TrainingData d = DecimateFrames(data, &frame, 1, ox, oy, true);
    ASSERT_EQ(d.Width, (W - ox) / 2);
    ASSERT_EQ(d.Height, (H - oy) / 2);
    EXPECT_EQ(d.PixelLowPass, 1.0 / 16);
    SliceGeometry coarse = d.Slice(0);
    EXPECT_EQ(coarse.PixelLowPass, 1.0 / 16);
    std::vector<float> blurred(std::size_t(d.Width) * d.Height), point(blurred.size());
    ASSERT_TRUE(cpu->Forward(truth.View(), &coarse, 1, o, blurred.data(), nullptr, nullptr, &error)) << error;
    coarse.PixelLowPass = 0;
    ASSERT_TRUE(cpu->Forward(truth.View(), &coarse, 1, o, point.data(), nullptr, nullptr, &error)) << error;
    const float* image = data.Frames.data() + std::size_t(W) * H * frame;
    double blurredError = 0, pointError = 0;
    for (int j = 0; j < d.Height; ++j)
    {
      for (int i = 0; i < d.Width; ++i)
      {
        const std::size_t c = std::size_t(j) * d.Width + i;
        const std::size_t top = std::size_t(oy + 2 * j) * W + ox + 2 * i;
        const std::size_t f[4] = { top, top + 1, top + W, top + W + 1 };
        ASSERT_FLOAT_EQ(d.Frames[c], 0.25f * (image[f[0]] + image[f[1]] + image[f[2]] + image[f[3]]));
        ASSERT_EQ(d.Mask[c], data.Mask[f[0]] && data.Mask[f[1]] && data.Mask[f[2]] && data.Mask[f[3]]);
        for (int r = 0; r < 3; ++r)
        {
          const double* P = full.ImageToReference;
          const double* Q = coarse.ImageToReference;
          EXPECT_NEAR(Q[4 * r] * i + Q[4 * r + 1] * j + Q[4 * r + 3],
            P[4 * r] * (ox + 2 * i + 0.5) + P[4 * r + 1] * (oy + 2 * j + 0.5) + P[4 * r + 3], 1e-12);
        }
        const double mean = 0.25 * (double(Sf[f[0]]) + Sf[f[1]] + Sf[f[2]] + Sf[f[3]]);
        blurredError += (blurred[c] - mean) * (blurred[c] - mean);
        pointError += (point[c] - mean) * (point[c] - mean);
      }
    }
    std::printf("offset %d %d: RMS against the block means, low-pass %.4g, point samples %.4g\n", ox, oy,
      std::sqrt(blurredError / blurred.size()), std::sqrt(pointError / point.size()));
    EXPECT_LT(blurredError, 0.5 * pointError) << "offset " << ox << ", " << oy;
  }
}

TEST(Trainer, ADecimatedFramesPoseGradientMovedToTheSourcePivotMatchesCentralDifferences)
{
  // A coarse step's pose gradient is taken about the decimated frame's centre pixel; DecimatedPoseGradientToSource
  // makes it the gradient of the source frame's correction (CorrectPose about the source's centre), which is what
  // the trainer moves. Truth: central differences of sum_p w(p) S(p) over the decimated pixels, rendered in double
  // (the reference renderer, every Gaussian at every pixel: where footprints are cut, their edges move with the pose
  // and the differences jump by up to 0.3 % of the gradient) at the decimated pose of the corrected source pose.
  const GaussianField truth = KnownField(300, 4);
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(truth, 0.5, heldOut);
  const reference::FieldD field = reference::FromView(truth.View());
  RenderOptions o;
  o.ElevationSigma = 0.5;
  const int frame = 23;
  auto cpu = CreateCpuRenderer();
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> w(std::size_t(W / 2) * (H / 2));
  for (double& v : w)
  {
    v = u(rng);
  }
  std::string error;
  for (bool average : { false, true }) // point samples; 2 x 2 averages at the blocks' centres, with the low-pass
  {
    for (const auto& [ox, oy] : { std::pair<int, int>{ 0, 0 }, { 1, 0 }, { 0, 1 }, { 1, 1 } })
    {
      const SliceGeometry coarse = DecimateFrames(data, &frame, 1, ox, oy, average).Slice(0);
      w.resize(std::size_t(coarse.Width) * coarse.Height);
      const std::vector<float> dL(w.begin(), w.end());
      std::vector<float> S(w.size());
      double pose[6] = { 0, 0, 0, 0, 0, 0 };
      FieldGradients g;
      g.SlicePoses = pose;
      ASSERT_TRUE(cpu->Forward(truth.View(), &coarse, 1, o, S.data(), nullptr, nullptr, &error)) << error;
      ASSERT_TRUE(cpu->Backward(truth.View(), &coarse, 1, o, S.data(), dL.data(), true, g, nullptr, &error)) << error;
      double moved[6];
      std::copy(pose, pose + 6, moved);
      DecimatedPoseGradientToSource(data, frame, ox, oy, moved, average);
      auto loss = [&](const double xi[6]) {
        TrainingData corrected = data;
        EXPECT_EQ(CorrectPose(data.Poses[frame].data(), W, H, xi, corrected.Poses[frame].data()), PoseStatus::Ok);
        std::vector<double> Sd;
        EXPECT_TRUE(reference::Forward(
          field, DecimateFrames(corrected, &frame, 1, ox, oy, average).Slice(0), o, Sd, nullptr, false));
        double sum = 0;
        for (std::size_t p = 0; p < Sd.size(); ++p)
        {
          sum += w[p] * Sd[p];
        }
        return sum;
      };
      double largest = 0;
      for (double v : moved)
      {
        largest = std::max(largest, std::abs(v));
      }
      ASSERT_GT(largest, 0);
      for (int k = 0; k < 6; ++k)
      {
        const double fd = test::PoseCentralDifference(loss, k);
        std::printf("%s, offset %d %d, xi[%d]: central difference %.6g, moved %.6g (about the decimated centre %.6g)\n",
          average ? "averages" : "point samples", ox, oy, k, fd, moved[k], pose[k]);
        EXPECT_NEAR(moved[k], fd, 1e-4 * largest)
          << (average ? "averages" : "point samples") << ", offset " << ox << ", " << oy << ", component " << k;
      }
    }
  }
}

namespace
{
/// The CPU engine, recording the frame size of every step (the resolution schedule's coarse steps).
class SizeRecordingEngine : public TrainingEngine
{
public:
  std::vector<int> StepWidths;
  std::vector<double> StepLowPass; // TrainingData::PixelLowPass of each step's frames
  std::vector<bool> PoseGradients;

  const char* GetName() const override { return "cpu"; }
  bool SetData(const TrainingData* data, std::string* error) override
  {
    this->Data = data;
    return this->Cpu->SetData(data, error);
  }
  bool Push(const OptimizerState& state, std::string* error) override { return this->Cpu->Push(state, error); }
  bool Pull(OptimizerState& state, std::string* error) override { return this->Cpu->Pull(state, error); }
  bool PullField(GaussianField& field, std::string* error) override { return this->Cpu->PullField(field, error); }
  StepStatus Step(const StepRequest& request, double* loss, std::string* error) override
  {
    this->StepWidths.push_back((request.Data ? request.Data : this->Data)->Width);
    this->StepLowPass.push_back((request.Data ? request.Data : this->Data)->PixelLowPass);
    this->PoseGradients.push_back(request.PoseGradients != nullptr);
    return this->Cpu->Step(request, loss, error);
  }
  void Snapshot() override { this->Cpu->Snapshot(); }
  void Restore() override { this->Cpu->Restore(); }
  bool Render(const SliceGeometry* slices, int count, const RenderOptions& options, float* S, float* I,
    std::string* error) override
  {
    return this->Cpu->Render(slices, count, options, S, I, error);
  }
  bool ApplyBasis(
    const float* r, const int* frames, int count, const RenderOptions& options, float* S, std::string* error) override
  {
    return this->Cpu->ApplyBasis(r, frames, count, options, S, error);
  }
  bool ApplyBasisTranspose(const float* y, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) override
  {
    return this->Cpu->ApplyBasisTranspose(y, frames, count, options, out, error);
  }
  bool BasisNorms(const float* weights, const int* frames, int count, const RenderOptions& options, double* out,
    std::string* error) override
  {
    return this->Cpu->BasisNorms(weights, frames, count, options, out, error);
  }

private:
  const TrainingData* Data = nullptr;
  std::unique_ptr<TrainingEngine> Cpu = CreateTrainingEngine("cpu", nullptr);
};
}

TEST(Trainer, TheResolutionScheduleStepsOnAQuarterOfThePixelsFirstAndLearnsThere)
{
  // CoarseFraction 0.5 of 400 steps: steps 0 to 199 on 32 x 32 decimated frames (point samples; with CoarseLowPass
  // 2 x 2 averages, 32 or 31 pixels wide by their phase, through the low-pass of 1/16 pixels^2), the rest on the
  // 64 x 64 frames, all with pose gradients; the coarse steps alone lower the full-resolution held-out error.
  const GaussianField truth = KnownField(400, 3);
  std::vector<int> heldOut;
  const TrainingData data = SyntheticSweep(truth, 0.5, heldOut);
  for (bool lowPass : { false, true })
  {
    TrainerSettings s;
    s.ElevationSigma = 0.5;
    s.Seeding.InitialGaussians = 3000;
    s.Iterations = 400;
    s.CoarseFraction = 0.5;
    s.CoarseLowPass = lowPass;
    s.Poses.RefinePoses = PoseRefinement::On;
    s.Poses.Start = 0;
    auto owned = std::make_unique<SizeRecordingEngine>();
    SizeRecordingEngine* engine = owned.get();
    Trainer trainer(data, s, std::move(owned));
    std::string error;
    ASSERT_TRUE(trainer.Initialize(&error)) << error;
    const double before = HeldOutPsnr(trainer, heldOut);
    ASSERT_TRUE(trainer.Train(
      nullptr, [&] { return engine->StepWidths.size() >= 200; }, &error))
      << error;
    ASSERT_LE(engine->StepWidths.size(), 200u);
    const double coarse = HeldOutPsnr(trainer, heldOut);
    ASSERT_TRUE(trainer.Train(nullptr, nullptr, &error)) << error;
    ASSERT_EQ(engine->StepWidths.size(), 400u);
    for (std::size_t k = 0; k < 400; ++k)
    {
      if (k < 200 && lowPass)
      {
        ASSERT_TRUE(engine->StepWidths[k] == W / 2 || engine->StepWidths[k] == W / 2 - 1) << "step " << k;
      }
      else
      {
        ASSERT_EQ(engine->StepWidths[k], k < 200 ? W / 2 : W) << "step " << k;
      }
      ASSERT_EQ(engine->StepLowPass[k], k < 200 && lowPass ? 1.0 / 16 : 0.0) << "step " << k;
      ASSERT_TRUE(engine->PoseGradients[k]) << "step " << k;
    }
    std::printf("%s: held-out PSNR %.2f dB at the start, %.2f after 200 coarse steps\n",
      lowPass ? "averages through the low-pass" : "point samples", before, coarse);
    EXPECT_GT(coarse, before + 3.0);
  }
}
