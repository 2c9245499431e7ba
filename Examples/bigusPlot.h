// Line plots as PNG (OpenCV drawing, VTK's PNG writer) for the command line's reports, and the file
// helpers the command-line tools share: write under a temporary name, then rename.
#ifndef bigusPlot_h
#define bigusPlot_h

#include <string>
#include <utility>
#include <vector>

namespace cv
{
class Mat;
}

namespace bigus
{
/// One curve: its points (x, y) are joined in order; a single point is drawn as a marker.
struct PlotSeries
{
  std::string Name;
  std::vector<std::pair<double, double>> Points;
};

struct PlotSpec
{
  std::string Title, XLabel, YLabel;
  bool LogX = false; ///< decades on the x axis (every x must be > 0)
  std::vector<PlotSeries> Series;
};

/// Draws @p spec (720 pixels wide, one colour and marker per series, legend below) and writes it as PNG to
/// @p path through a temporary file. Returns false when it cannot write.
bool WritePlot(const PlotSpec& spec, const std::string& path);

/**
 * Writes @p image (8-bit, 1 channel gray or 3 channels in OpenCV's B, G, R order; [rows, columns], row 0
 * at the top of the picture) as PNG to @p path through a temporary file (vtkPNGWriter). False when
 * the image is of another type or the file cannot be written; an existing @p path is then untouched.
 */
bool WritePng(const cv::Mat& image, const std::string& path);
}

#endif
