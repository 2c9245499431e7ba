#include "bigusPlot.h"
#include "bigusReplaceFile.h"

#include "vtkImageData.h"
#include "vtkNew.h"
#include "vtkPNGWriter.h"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace bigus
{

bool WritePng(const cv::Mat& image, const std::string& path)
{
  const int channels = image.channels();
  if (image.depth() != CV_8U || (channels != 1 && channels != 3) || image.empty())
  {
    return false;
  }
  // VTK's image rows run bottom-up and its PNG writer puts the last row at the top: row r of the picture
  // is VTK row rows - 1 - r. Colour goes from OpenCV's B, G, R to PNG's R, G, B.
  vtkNew<vtkImageData> vtkImage;
  vtkImage->SetDimensions(image.cols, image.rows, 1);
  vtkImage->AllocateScalars(VTK_UNSIGNED_CHAR, channels);
  auto* out = static_cast<unsigned char*>(vtkImage->GetScalarPointer());
  for (int r = 0; r < image.rows; ++r)
  {
    const unsigned char* row = image.ptr<unsigned char>(r);
    unsigned char* target = out + std::size_t(image.rows - 1 - r) * image.cols * channels;
    for (int c = 0; c < image.cols; ++c)
    {
      for (int k = 0; k < channels; ++k)
      {
        target[c * channels + k] = row[c * channels + (channels == 3 ? 2 - k : k)];
      }
    }
  }
  const std::string temporary = TemporaryName(path);
  vtkNew<vtkPNGWriter> writer;
  writer->SetInputData(vtkImage);
  writer->SetFileName(temporary.c_str());
  writer->Write();
  if (writer->GetErrorCode() != 0)
  {
    std::remove(temporary.c_str());
    return false;
  }
  return Publish(temporary, path);
}

namespace
{
/// A "nice" tick step (1, 2 or 5 times a power of ten) giving about @p count ticks over @p span.
double TickStep(double span, int count)
{
  const double raw = span / count;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : { 1.0, 2.0, 5.0 })
  {
    if (m * magnitude >= raw)
    {
      return m * magnitude;
    }
  }
  return 10 * magnitude;
}

std::string Number(double v)
{
  char text[32];
  std::snprintf(text, sizeof(text), "%g", v);
  return text;
}
}

bool WritePlot(const PlotSpec& spec, const std::string& path)
{
  // The legend sits below the axes, one row per series, so that it never hides a point.
  const int count = static_cast<int>(spec.Series.size());
  const int W = 720, left = 70, right = 20, top = 40, bottom = 60 + 18 * count, H = 400 + 18 * count;
  const cv::Scalar black(0, 0, 0), grey(225, 225, 225);
  // BGR, distinguishable in print.
  const cv::Scalar colours[] = { { 180, 90, 0 }, { 0, 120, 230 }, { 40, 160, 40 }, { 30, 30, 200 }, { 160, 60, 150 },
    { 60, 110, 140 }, { 190, 120, 220 }, { 120, 120, 120 }, { 20, 170, 190 }, { 200, 190, 20 } };
  cv::Mat plot(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  for (const PlotSeries& s : spec.Series)
  {
    for (const auto& p : s.Points)
    {
      if (!std::isfinite(p.first) || !std::isfinite(p.second) || (spec.LogX && p.first <= 0))
      {
        continue;
      }
      const double x = spec.LogX ? std::log10(p.first) : p.first;
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, p.second);
      y1 = std::max(y1, p.second);
    }
  }
  if (x0 > x1)
  {
    x0 = 0;
    x1 = 1;
    y0 = 0;
    y1 = 1;
  }
  if (spec.LogX)
  {
    x0 = std::floor(x0);
    x1 = std::max(std::ceil(x1), x0 + 1);
  }
  else if (x1 - x0 < 1e-12)
  {
    x1 = x0 + 1;
  }
  const double yStep = TickStep(std::max(y1 - y0, 1e-9), 5);
  y0 = std::floor(y0 / yStep) * yStep;
  y1 = std::max(std::ceil(y1 / yStep) * yStep, y0 + yStep);
  auto at = [&](double x, double y) {
    const double u = ((spec.LogX ? std::log10(x) : x) - x0) / (x1 - x0);
    return cv::Point(left + static_cast<int>((W - left - right) * u),
      H - bottom - static_cast<int>((H - top - bottom) * (y - y0) / (y1 - y0)));
  };
  const double xLow = spec.LogX ? std::pow(10.0, x0) : x0, xHigh = spec.LogX ? std::pow(10.0, x1) : x1;
  // Grid and ticks.
  for (double y = y0; y <= y1 + 1e-9 * yStep; y += yStep)
  {
    cv::line(plot, at(xLow, y), at(xHigh, y), grey);
    cv::putText(plot, Number(y), at(xLow, y) + cv::Point(-60, 5), cv::FONT_HERSHEY_SIMPLEX, 0.42, black);
  }
  std::vector<double> xTicks;
  if (spec.LogX)
  {
    for (double e = x0; e <= x1 + 1e-9; e += 1)
    {
      xTicks.push_back(std::pow(10.0, e));
    }
  }
  else
  {
    const double step = TickStep(x1 - x0, 5);
    for (double x = std::ceil(x0 / step) * step; x <= x1 + 1e-9 * step; x += step)
    {
      xTicks.push_back(x);
    }
  }
  for (double x : xTicks)
  {
    cv::line(plot, at(x, y0), at(x, y1), grey);
    cv::putText(plot, Number(x), at(x, y0) + cv::Point(-12, 20), cv::FONT_HERSHEY_SIMPLEX, 0.42, black);
  }
  cv::rectangle(plot, at(xLow, y1), at(xHigh, y0), black);
  cv::putText(plot, spec.Title, cv::Point(left, 25), cv::FONT_HERSHEY_SIMPLEX, 0.55, black);
  cv::putText(plot, spec.XLabel, cv::Point(left + (W - left - right) / 2 - 120, H - bottom + 38),
    cv::FONT_HERSHEY_SIMPLEX, 0.45, black);
  cv::putText(plot, spec.YLabel, cv::Point(5, top - 8), cv::FONT_HERSHEY_SIMPLEX, 0.42, black);
  // Curves, markers and the legend.
  for (std::size_t k = 0; k < spec.Series.size(); ++k)
  {
    const PlotSeries& s = spec.Series[k];
    const cv::Scalar colour = colours[k % (sizeof(colours) / sizeof(colours[0]))];
    std::vector<cv::Point> points;
    for (const auto& p : s.Points)
    {
      if (std::isfinite(p.first) && std::isfinite(p.second) && (!spec.LogX || p.first > 0))
      {
        points.push_back(at(p.first, p.second));
      }
    }
    for (std::size_t i = 1; i < points.size(); ++i)
    {
      cv::line(plot, points[i - 1], points[i], colour, 2, cv::LINE_AA);
    }
    for (const cv::Point& p : points)
    {
      if (k % 2 == 0)
      {
        cv::circle(plot, p, 4, colour, cv::FILLED, cv::LINE_AA);
      }
      else
      {
        cv::drawMarker(plot, p, colour, cv::MARKER_DIAMOND, 10, 2);
      }
    }
    const cv::Point key(left, H - bottom + 60 + 18 * static_cast<int>(k));
    cv::line(plot, key, key + cv::Point(22, 0), colour, 2);
    cv::putText(plot, s.Name, key + cv::Point(30, 5), cv::FONT_HERSHEY_SIMPLEX, 0.42, colour);
  }
  return WritePng(plot, path);
}
}
