// vtkUltrasoundImageMetrics on frames of the real spine-phantom sweep, against answers computed
// independently here: PSNR from the MSE of a known offset, SSIM from a direct double-precision
// implementation (and OpenCV's quality module where it is installed), the effect of the fan mask.
#include "bigusTestUtilities.h"

#include "vtkDataArray.h"
#include "vtkExecutive.h"
#include "vtkFieldData.h"
#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPointData.h"
#include "vtkTable.h"
#include "vtkUltrasoundFanMask.h"
#include "vtkUltrasoundImageMetrics.h"
#include "vtkUltrasoundSequenceReader.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#ifdef BIGUS_HAVE_OPENCV_QUALITY
#include <opencv2/quality.hpp>
#endif

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

using bigus_test::DataPath;
using bigus_test::MessageCollector;

namespace
{
constexpr int W = 820, H = 616;
constexpr int FirstFrame = 5, LastFrame = 8, Frames = LastFrame - FirstFrame + 1;

/// Frames FirstFrame..LastFrame of the spine-phantom sweep (read once, copied for each use).
vtkSmartPointer<vtkImageData> SpineFrames()
{
  static vtkSmartPointer<vtkImageData> frames;
  if (!frames)
  {
    vtkNew<vtkUltrasoundSequenceReader> reader;
    reader->SetFileName(DataPath("spine-phantom/SpinePhantomFreehand.igs.mha").c_str());
    reader->SetCalibrationFileName(
      DataPath("spine-phantom/PlusDeviceSet_SpinePhantomFreehandReconstructionOnly.xml").c_str());
    reader->SetFrameRange(FirstFrame, LastFrame);
    reader->Update();
    EXPECT_STREQ(reader->GetLastErrorText(), "");
    frames = reader->GetOutput();
  }
  auto copy = vtkSmartPointer<vtkImageData>::New();
  copy->DeepCopy(frames);
  return copy;
}

/// The fan mask of the spine frames estimated by vtkUltrasoundFanMask (W x H x 1, 0 / 1).
vtkSmartPointer<vtkImageData> SpineMask()
{
  vtkNew<vtkUltrasoundFanMask> fan;
  fan->SetInputData(SpineFrames());
  fan->Update();
  auto mask = vtkSmartPointer<vtkImageData>::New();
  mask->DeepCopy(fan->GetOutput());
  return mask;
}

unsigned char* Bytes(vtkImageData* image)
{
  return static_cast<unsigned char*>(image->GetScalarPointer());
}

/// One W x H frame of floats as a W x H x 1 float image.
vtkSmartPointer<vtkImageData> FloatImage(const std::vector<float>& pixels)
{
  auto image = vtkSmartPointer<vtkImageData>::New();
  image->SetDimensions(W, H, 1);
  image->AllocateScalars(VTK_FLOAT, 1);
  std::copy(pixels.begin(), pixels.end(), static_cast<float*>(image->GetScalarPointer()));
  return image;
}

/// Frame k of a uchar sequence as floats in [0, 1], exactly as the filter converts it.
std::vector<float> Frame(vtkImageData* frames, int k)
{
  const unsigned char* p = Bytes(frames) + std::size_t(k) * W * H;
  std::vector<float> out(std::size_t(W) * H);
  for (std::size_t i = 0; i < out.size(); ++i)
  {
    out[i] = p[i] / 255.0f;
  }
  return out;
}

double Value(vtkTable* table, const char* column, vtkIdType row)
{
  return table->GetColumnByName(column)->GetVariantValue(row).ToDouble();
}

struct Result
{
  vtkSmartPointer<vtkTable> Table;
  double Mean[4];
};

Result Measure(vtkImageData* rendered, vtkImageData* truth, vtkImageData* mask = nullptr, bool validOnly = true)
{
  vtkNew<vtkUltrasoundImageMetrics> metrics;
  metrics->SetInputData(0, rendered);
  metrics->SetTruthData(truth);
  if (mask)
  {
    metrics->SetMaskData(mask);
  }
  metrics->SetFrameValidOnly(validOnly);
  metrics->Update();
  Result r;
  r.Table = metrics->GetOutput();
  r.Mean[0] = metrics->GetMeanPSNR();
  r.Mean[1] = metrics->GetMeanSSIM();
  r.Mean[2] = metrics->GetMeanNCC();
  r.Mean[3] = metrics->GetMeanSpeckle();
  return r;
}

/**
 * Reference SSIM written from Wang et al. 2004 without any filtering library: at each pixel the
 * 11 x 11 window of Gaussian weights (sigma 1.5, normalised to sum 1) gives the local means,
 * variances and covariance, with pixels outside the image counted as 0 (zero padding); the SSIM map
 * (Eq. 13, C1 = 0.01^2, C2 = 0.03^2) is averaged over the pixels where @p mask is non-zero.
 */
double ReferenceSSIM(const std::vector<float>& x, const std::vector<float>& y, const unsigned char* mask)
{
  constexpr int R = 5;
  constexpr double Sigma = 1.5, C1 = 0.01 * 0.01, C2 = 0.03 * 0.03;
  double g[2 * R + 1], total = 0;
  for (int u = -R; u <= R; ++u)
  {
    g[u + R] = std::exp(-u * u / (2 * Sigma * Sigma));
    total += g[u + R];
  }
  for (double& v : g)
  {
    v /= total;
  }
  double sum = 0;
  long count = 0;
  for (int j = 0; j < H; ++j)
  {
    for (int i = 0; i < W; ++i)
    {
      if (mask && !mask[j * W + i])
      {
        continue;
      }
      double mx = 0, my = 0, sxx = 0, syy = 0, sxy = 0;
      for (int v = -R; v <= R; ++v)
      {
        const int jj = j + v;
        if (jj < 0 || jj >= H)
        {
          continue;
        }
        for (int u = -R; u <= R; ++u)
        {
          const int ii = i + u;
          if (ii < 0 || ii >= W)
          {
            continue;
          }
          const double w = g[u + R] * g[v + R];
          const double a = x[jj * W + ii], b = y[jj * W + ii];
          mx += w * a;
          my += w * b;
          sxx += w * a * a;
          syy += w * b * b;
          sxy += w * a * b;
        }
      }
      const double vx = sxx - mx * mx, vy = syy - my * my, cxy = sxy - mx * my;
      sum += (2 * mx * my + C1) * (2 * cxy + C2) / ((mx * mx + my * my + C1) * (vx + vy + C2));
      ++count;
    }
  }
  return sum / count;
}

/// Gaussian blur (sigma 2 pixels) of one frame: smooth speckle, same anatomy.
std::vector<float> Blurred(const std::vector<float>& frame)
{
  std::vector<float> out(frame.size());
  cv::GaussianBlur(
    cv::Mat(H, W, CV_32F, const_cast<float*>(frame.data())), cv::Mat(H, W, CV_32F, out.data()), cv::Size(0, 0), 2.0);
  return out;
}

/// The spine frames, each blurred (Blurred) and rounded back to 8 bits.
vtkSmartPointer<vtkImageData> BlurredSpineFrames()
{
  vtkSmartPointer<vtkImageData> truth = SpineFrames();
  vtkSmartPointer<vtkImageData> blurred = SpineFrames();
  for (int k = 0; k < Frames; ++k)
  {
    const std::vector<float> b = Blurred(Frame(truth, k));
    unsigned char* p = Bytes(blurred) + std::size_t(k) * W * H;
    for (int q = 0; q < W * H; ++q)
    {
      p[q] = static_cast<unsigned char>(std::lround(b[q] * 255));
    }
  }
  return blurred;
}
}

TEST(UltrasoundImageMetrics, IdenticalSequencesScorePerfectly)
{
  vtkSmartPointer<vtkImageData> truth = SpineFrames();
  vtkSmartPointer<vtkImageData> mask = SpineMask();
  for (vtkImageData* m : { static_cast<vtkImageData*>(nullptr), mask.GetPointer() })
  {
    const Result r = Measure(SpineFrames(), truth, m);
    vtkTable* table = r.Table;
    ASSERT_EQ(table->GetNumberOfColumns(), 5);
    ASSERT_EQ(table->GetNumberOfRows(), Frames + 1);
    const char* names[] = { "Frame", "PSNR", "SSIM", "NCC", "Speckle" };
    for (int c = 0; c < 5; ++c)
    {
      EXPECT_STREQ(table->GetColumn(c)->GetName(), names[c]);
    }
    for (int row = 0; row <= Frames; ++row)
    {
      // Frame numbers are those of the file (FrameIndex), then -1 for the summary row.
      EXPECT_EQ(Value(table, "Frame", row), row < Frames ? FirstFrame + row : -1);
      EXPECT_EQ(Value(table, "PSNR", row), 100.0) << row;
      EXPECT_NEAR(Value(table, "SSIM", row), 1.0, 1e-12) << row;
      EXPECT_NEAR(Value(table, "NCC", row), 1.0, 1e-12) << row;
      EXPECT_NEAR(Value(table, "Speckle", row), 1.0, 1e-12) << row;
    }
    EXPECT_EQ(r.Mean[0], 100.0);
    for (int k = 1; k < 4; ++k)
    {
      EXPECT_NEAR(r.Mean[k], 1.0, 1e-12);
    }
  }
}

TEST(UltrasoundImageMetrics, PsnrOfAKnownOffsetMatchesTheMseComputedHere)
{
  vtkSmartPointer<vtkImageData> truth = SpineFrames();
  vtkSmartPointer<vtkImageData> rendered = SpineFrames();
  vtkSmartPointer<vtkImageData> mask = SpineMask();
  unsigned char* p = Bytes(rendered);
  const std::size_t n = std::size_t(W) * H * Frames;
  for (std::size_t i = 0; i < n; ++i)
  {
    p[i] = static_cast<unsigned char>(std::min(255, p[i] + 4));
  }
  for (vtkImageData* m : { static_cast<vtkImageData*>(nullptr), mask.GetPointer() })
  {
    const Result r = Measure(rendered, truth, m);
    ASSERT_EQ(r.Table->GetNumberOfRows(), Frames + 1);
    double meanPsnr = 0;
    for (int k = 0; k < Frames; ++k)
    {
      // Exact MSE of the clamped offset in 8-bit steps: saturated pixels differ by less than 4.
      const unsigned char* a = Bytes(rendered) + std::size_t(k) * W * H;
      const unsigned char* b = Bytes(truth) + std::size_t(k) * W * H;
      double squares = 0;
      long count = 0;
      for (int q = 0; q < W * H; ++q)
      {
        if (m && !Bytes(m)[q])
        {
          continue;
        }
        const double d = (double(a[q]) - double(b[q])) / 255.0;
        squares += d * d;
        ++count;
      }
      const double expected = 10 * std::log10(1.0 / (squares / count));
      EXPECT_NEAR(Value(r.Table, "PSNR", k), expected, 1e-4) << "frame " << k;
      EXPECT_GT(expected, 10 * std::log10(255.0 * 255.0 / 16.0) - 1e-9); // clamping only lowers the MSE
      meanPsnr += expected / Frames;
    }
    EXPECT_NEAR(Value(r.Table, "PSNR", Frames), meanPsnr, 1e-4);
    EXPECT_NEAR(r.Mean[0], meanPsnr, 1e-4);
    EXPECT_GT(r.Mean[2], 0.999); // a constant offset keeps the correlation, up to the clamping
  }
}

TEST(UltrasoundImageMetrics, SsimMatchesAnIndependentImplementation)
{
  vtkSmartPointer<vtkImageData> truthFrames = SpineFrames();
  vtkSmartPointer<vtkImageData> mask = SpineMask();
  const int k = 2;
  const std::vector<float> truth = Frame(truthFrames, k);
  const std::vector<float> blurred = Blurred(truth);
  auto truthImage = vtkSmartPointer<vtkImageData>::New();
  truthImage->SetDimensions(W, H, 1);
  truthImage->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  std::copy(
    Bytes(truthFrames) + std::size_t(k) * W * H, Bytes(truthFrames) + std::size_t(k + 1) * W * H, Bytes(truthImage));
  vtkSmartPointer<vtkImageData> renderedImage = FloatImage(blurred);

  const double whole = Value(Measure(renderedImage, truthImage).Table, "SSIM", 0);
  const double masked = Value(Measure(renderedImage, truthImage, mask).Table, "SSIM", 0);
  const double referenceWhole = ReferenceSSIM(blurred, truth, nullptr);
  const double referenceMasked = ReferenceSSIM(blurred, truth, Bytes(mask));
  std::printf("SSIM of a sigma-2 blurred frame: filter %.12f / reference %.12f (whole frame), "
              "filter %.12f / reference %.12f (fan mask)\n",
    whole, referenceWhole, masked, referenceMasked);
  // Same definition, both in double: only the order of the sums differs.
  EXPECT_NEAR(whole, referenceWhole, 1e-9);
  EXPECT_NEAR(masked, referenceMasked, 1e-9);
  EXPECT_LT(whole, 0.99);

#ifdef BIGUS_HAVE_OPENCV_QUALITY
  // OpenCV's QualitySSIM uses the same window and constants for data range 255 (SSIM does not
  // change when the data and sqrt(C1), sqrt(C2) are scaled together) but reflects the image at its
  // border instead of padding with zeros, and averages over the whole image. (1) On the pixels at
  // least 5 pixels from the border the 11 x 11 windows hold no padding, so there the two maps must
  // agree to rounding. (2) Over the whole image the means differ only through the 5-pixel border
  // band; SSIM lies in [-1, 1], so the difference is at most 2 x (band pixels / all pixels).
  cv::Mat x(H, W, CV_32F, const_cast<float*>(blurred.data())), y(H, W, CV_32F, const_cast<float*>(truth.data()));
  cv::Mat x255, y255;
  x.convertTo(x255, CV_64F, 255.0);
  y.convertTo(y255, CV_64F, 255.0);
  cv::UMat quality;
  const double opencvWhole = cv::quality::QualitySSIM::compute(x255, y255, quality)[0];
  const cv::Mat map = quality.getMat(cv::ACCESS_READ);
  ASSERT_EQ(map.type(), CV_64F);
  auto interior = vtkSmartPointer<vtkImageData>::New();
  interior->DeepCopy(mask);
  double mapSum = 0;
  long mapCount = 0;
  for (int j = 0; j < H; ++j)
  {
    for (int i = 0; i < W; ++i)
    {
      unsigned char& m = Bytes(interior)[j * W + i];
      m = m && i >= 5 && j >= 5 && i < W - 5 && j < H - 5;
      if (m)
      {
        mapSum += map.at<double>(j, i);
        ++mapCount;
      }
    }
  }
  const double interiorSSIM = Value(Measure(renderedImage, truthImage, interior).Table, "SSIM", 0);
  const double band = double(W) * H - double(W - 10) * (H - 10);
  std::printf("OpenCV QualitySSIM: %.12f (whole image, reflected border; filter %.12f, bound %.4f), "
              "%.12f vs filter %.12f (fan mask without the 5-pixel border band)\n",
    opencvWhole, whole, 2 * band / (double(W) * H), mapSum / mapCount, interiorSSIM);
  EXPECT_NEAR(interiorSSIM, mapSum / mapCount, 1e-9);
  EXPECT_NEAR(whole, opencvWhole, 2 * band / (double(W) * H));
#endif
}

TEST(UltrasoundImageMetrics, SpeckleScoreDropsForABlurredFrame)
{
  vtkSmartPointer<vtkImageData> truthFrames = SpineFrames();
  vtkSmartPointer<vtkImageData> mask = SpineMask();
  auto truthImage = FloatImage(Frame(truthFrames, 1));
  const Result same = Measure(FloatImage(Frame(truthFrames, 1)), truthImage, mask);
  const Result blurred = Measure(FloatImage(Blurred(Frame(truthFrames, 1))), truthImage, mask);
  const double s = Value(blurred.Table, "Speckle", 0);
  std::printf("speckle score of the spine frame: identical %.4f, sigma-2 blurred copy %.4f (PSNR %.2f dB)\n",
    Value(same.Table, "Speckle", 0), s, Value(blurred.Table, "PSNR", 0));
  EXPECT_NEAR(Value(same.Table, "Speckle", 0), 1.0, 1e-12);
  EXPECT_LT(s, 0.8);
  EXPECT_GE(s, 0.0);
}

TEST(UltrasoundImageMetrics, OnlyTheMaskedPixelsCount)
{
  vtkSmartPointer<vtkImageData> truth = SpineFrames();
  vtkSmartPointer<vtkImageData> mask = SpineMask();
  // Rendered = truth blurred, so that every metric is away from its perfect value.
  vtkSmartPointer<vtkImageData> rendered = BlurredSpineFrames();
  // Pixels outside the mask: "near" ones lie within the 11 x 11 SSIM window of a masked pixel.
  cv::Mat m(H, W, CV_8U, Bytes(mask)), reach;
  cv::dilate(m, reach, cv::Mat::ones(11, 11, CV_8U));
  long inside = cv::countNonZero(m), near = cv::countNonZero(reach) - inside;
  ASSERT_GT(inside, W * H / 4);
  ASSERT_GT(W * H - inside - near, W * H / 20) << "the spine frames' fan should leave a background";

  auto damage = [&](bool nearToo) {
    auto out = vtkSmartPointer<vtkImageData>::New();
    out->DeepCopy(rendered);
    for (int k = 0; k < Frames; ++k)
    {
      unsigned char* p = Bytes(out) + std::size_t(k) * W * H;
      for (int q = 0; q < W * H; ++q)
      {
        if (!m.data[q] && (nearToo || !reach.data[q]))
        {
          p[q] = static_cast<unsigned char>((q * 37 + k * 11) % 256);
        }
      }
    }
    return out;
  };
  const Result clean = Measure(rendered, truth, mask);
  const Result far = Measure(damage(false), truth, mask);
  const Result all = Measure(damage(true), truth, mask);
  const Result unmasked = Measure(damage(false), truth);
  EXPECT_LT(Value(clean.Table, "SSIM", 0), 0.99);
  for (int row = 0; row <= Frames; ++row)
  {
    for (const char* column : { "PSNR", "SSIM", "NCC", "Speckle" })
    {
      EXPECT_NEAR(Value(far.Table, column, row), Value(clean.Table, column, row), 1e-12) << column << row;
    }
    // Damage next to the fan changes only SSIM, whose windows reach 5 pixels past the mask.
    for (const char* column : { "PSNR", "NCC", "Speckle" })
    {
      EXPECT_EQ(Value(all.Table, column, row), Value(clean.Table, column, row)) << column << row;
    }
    EXPECT_LT(Value(unmasked.Table, "PSNR", row), Value(clean.Table, "PSNR", row) - 3) << row;
  }
  std::printf("SSIM of frame %d: %.6f clean, %.6f with the pixels next to the fan damaged\n", FirstFrame,
    Value(clean.Table, "SSIM", 0), Value(all.Table, "SSIM", 0));
  EXPECT_NE(Value(all.Table, "SSIM", 0), Value(clean.Table, "SSIM", 0));
}

TEST(UltrasoundImageMetrics, PerFrameMasksSelectEachFramesPixels)
{
  // A W x H x N mask: frame k is measured with its own mask, exactly as with a W x H x 1 mask equal to
  // that slice; a frame whose own mask is empty is left out.
  vtkSmartPointer<vtkImageData> truth = SpineFrames();
  vtkSmartPointer<vtkImageData> rendered = BlurredSpineFrames();
  vtkSmartPointer<vtkImageData> fan = SpineMask();
  vtkNew<vtkImageData> masks;
  masks->SetDimensions(W, H, Frames);
  masks->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  for (int k = 0; k < Frames; ++k)
  {
    // Frame k keeps the fan rows below a depth that grows with k; the last frame's mask is empty.
    for (int q = 0; q < W * H; ++q)
    {
      Bytes(masks)[std::size_t(k) * W * H + q] = k < Frames - 1 && q / W >= 100 * k ? Bytes(fan)[q] : 0;
    }
  }
  const Result perFrame = Measure(rendered, truth, masks);
  ASSERT_EQ(perFrame.Table->GetNumberOfRows(), Frames); // Frames - 1 rows and the mean
  for (int k = 0; k < Frames - 1; ++k)
  {
    vtkNew<vtkImageData> one;
    one->SetDimensions(W, H, 1);
    one->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
    std::copy_n(Bytes(masks) + std::size_t(k) * W * H, W * H, Bytes(one));
    const Result single = Measure(rendered, truth, one);
    EXPECT_EQ(Value(perFrame.Table, "Frame", k), FirstFrame + k);
    for (const char* column : { "PSNR", "SSIM", "NCC" })
    {
      EXPECT_EQ(Value(perFrame.Table, column, k), Value(single.Table, column, k)) << column << k;
    }
  }
  EXPECT_NE(Value(perFrame.Table, "PSNR", 0), Value(perFrame.Table, "PSNR", 2));
}

TEST(UltrasoundImageMetrics, FrameValidOnlySkipsInvalidTruthFrames)
{
  vtkSmartPointer<vtkImageData> truth = SpineFrames();
  vtkDataArray* valid = truth->GetFieldData()->GetArray("FrameValid");
  ASSERT_NE(valid, nullptr);
  valid->SetTuple1(1, 0);
  vtkSmartPointer<vtkImageData> rendered = SpineFrames();
  Bytes(rendered)[std::size_t(2) * W * H + W * H / 2] ^= 0x80; // one changed pixel in frame 2

  const Result skipped = Measure(rendered, truth);
  ASSERT_EQ(skipped.Table->GetNumberOfRows(), Frames);
  const int expectedFrames[] = { FirstFrame, FirstFrame + 2, FirstFrame + 3, -1 };
  for (int row = 0; row < Frames; ++row)
  {
    EXPECT_EQ(Value(skipped.Table, "Frame", row), expectedFrames[row]);
  }
  EXPECT_LT(Value(skipped.Table, "PSNR", 1), 100.0);
  EXPECT_NEAR(skipped.Mean[0], (2 * 100.0 + Value(skipped.Table, "PSNR", 1)) / 3, 1e-9);

  const Result everyFrame = Measure(rendered, truth, nullptr, false);
  EXPECT_EQ(everyFrame.Table->GetNumberOfRows(), Frames + 1);

  for (int k = 0; k < Frames; ++k)
  {
    valid->SetTuple1(k, 0);
  }
  vtkNew<MessageCollector> messages;
  vtkNew<vtkUltrasoundImageMetrics> metrics;
  messages->Watch(metrics);
  metrics->SetInputData(0, rendered);
  metrics->SetTruthData(truth);
  metrics->Update();
  EXPECT_EQ(messages->Warnings.size(), 1u);
  ASSERT_EQ(metrics->GetOutput()->GetNumberOfRows(), 1);
  EXPECT_EQ(Value(metrics->GetOutput(), "Frame", 0), -1);
  EXPECT_TRUE(std::isnan(metrics->GetMeanPSNR()));
}

TEST(UltrasoundImageMetrics, InconsistentInputsFailWithBothSizes)
{
  auto image = [](int w, int h, int n, int type, int components) {
    auto out = vtkSmartPointer<vtkImageData>::New();
    out->SetDimensions(w, h, n);
    out->AllocateScalars(type, components);
    std::fill_n(static_cast<unsigned char*>(out->GetScalarPointer()),
      std::size_t(w) * h * n * components * out->GetScalarSize(), 0x3f);
    return out;
  };
  struct Case
  {
    vtkSmartPointer<vtkImageData> Rendered, Truth, Mask;
    std::string Expected;
  };
  const Case cases[] = {
    { image(64, 48, 3, VTK_FLOAT, 1), image(64, 40, 3, VTK_FLOAT, 1), nullptr, "64 x 48 x 3" },
    { image(64, 48, 3, VTK_FLOAT, 1), image(64, 48, 4, VTK_UNSIGNED_CHAR, 1), nullptr, "64 x 48 x 4" },
    { image(64, 48, 2, VTK_UNSIGNED_CHAR, 3), image(64, 48, 2, VTK_UNSIGNED_CHAR, 3), nullptr, "one-component" },
    { image(64, 48, 2, VTK_SHORT, 1), image(64, 48, 2, VTK_SHORT, 1), nullptr, "unsigned char, float or double" },
    { image(64, 48, 2, VTK_FLOAT, 1), image(64, 48, 2, VTK_FLOAT, 1), image(48, 64, 1, VTK_UNSIGNED_CHAR, 1),
      "48 x 64 x 1" },
    { image(64, 48, 2, VTK_FLOAT, 1), image(64, 48, 2, VTK_FLOAT, 1), image(64, 48, 3, VTK_UNSIGNED_CHAR, 1),
      "64 x 48 x 3" },
    { image(64, 48, 2, VTK_FLOAT, 1), image(64, 48, 2, VTK_FLOAT, 1), image(64, 48, 1, VTK_DOUBLE, 1), "" },
  };
  for (const Case& c : cases)
  {
    vtkNew<vtkUltrasoundImageMetrics> metrics;
    vtkNew<MessageCollector> messages, pipeline;
    messages->Watch(metrics);
    pipeline->Watch(metrics->GetExecutive()); // "Algorithm ... returned failure for request"
    metrics->SetInputData(0, c.Rendered);
    metrics->SetTruthData(c.Truth);
    if (c.Mask)
    {
      metrics->SetMaskData(c.Mask);
    }
    EXPECT_EQ(metrics->GetExecutive()->Update(), c.Expected.empty() ? 1 : 0);
    if (c.Expected.empty())
    {
      // A double mask whose bytes are all 0x3f: non-zero everywhere, so it is accepted.
      EXPECT_TRUE(messages->Errors.empty());
      EXPECT_EQ(metrics->GetOutput()->GetNumberOfRows(), 3);
      continue;
    }
    ASSERT_FALSE(messages->Errors.empty()) << c.Expected;
    EXPECT_NE(messages->Errors[0].find(c.Expected), std::string::npos) << messages->Errors[0];
    EXPECT_EQ(metrics->GetOutput()->GetNumberOfRows(), 0);
    EXPECT_EQ(metrics->GetOutput()->GetNumberOfColumns(), 0);
    EXPECT_TRUE(std::isnan(metrics->GetMeanSSIM()));
  }
  // Both sizes are named when the frame sizes differ.
  vtkNew<vtkUltrasoundImageMetrics> metrics;
  vtkNew<MessageCollector> messages, pipeline;
  messages->Watch(metrics);
  pipeline->Watch(metrics->GetExecutive());
  metrics->SetInputData(0, image(64, 48, 3, VTK_FLOAT, 1));
  metrics->SetTruthData(image(64, 40, 3, VTK_FLOAT, 1));
  metrics->Update();
  ASSERT_EQ(messages->Errors.size(), 1u);
  EXPECT_NE(messages->Errors[0].find("64 x 48 x 3"), std::string::npos);
  EXPECT_NE(messages->Errors[0].find("64 x 40 x 3"), std::string::npos);

  // An all-zero mask and a previously failed run: the filter recovers once the inputs agree.
  auto empty = image(64, 48, 1, VTK_UNSIGNED_CHAR, 1);
  std::fill_n(Bytes(empty), 64 * 48, 0);
  metrics->SetTruthData(image(64, 48, 3, VTK_FLOAT, 1));
  metrics->SetMaskData(empty);
  metrics->Update();
  ASSERT_EQ(messages->Errors.size(), 2u);
  EXPECT_NE(messages->Errors[1].find("no imaged"), std::string::npos);
  metrics->SetMaskData(nullptr);
  metrics->Update();
  EXPECT_EQ(messages->Errors.size(), 2u);
  EXPECT_EQ(metrics->GetOutput()->GetNumberOfRows(), 4);
  EXPECT_EQ(metrics->GetMeanPSNR(), 100.0);
}
