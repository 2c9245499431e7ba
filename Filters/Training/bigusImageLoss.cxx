// Losses between rendered and recorded frames (see bigusImageLoss.h). OpenCV does the filtering
// (separable Gaussian window) and the DFT; the gradients are derived below.
#include "bigusImageLoss.h"

#include "bigusSsimMath.h"

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "vtkSMPTools.h"
#include <vtk_fmt.h>
// clang-format off
#include VTK_FMT(fmt/printf.h)
// clang-format on

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <string>
#include <utility>
#include <vector>

namespace bigus
{

namespace
{
/// Gaussian window filter with zero padding: self-adjoint, so it is also its own gradient.
void Filter(const cv::Mat& in, cv::Mat& out)
{
  const cv::Mat kernel = cv::getGaussianKernel(SsimWindow, SsimWindowSigma, in.depth());
  cv::sepFilter2D(in, out, in.depth(), kernel, kernel, cv::Point(-1, -1), 0, cv::BORDER_CONSTANT);
}

/// Filters in[k] into out[k] for every k, the images on different threads (each filter is serial).
void FilterAll(std::initializer_list<std::pair<const cv::Mat*, cv::Mat*>> pairs)
{
  const std::vector<std::pair<const cv::Mat*, cv::Mat*>> list(pairs);
  vtkSMPTools::For(0, static_cast<int>(list.size()), 1, [&](int begin, int end) {
    for (int k = begin; k < end; ++k)
    {
      Filter(*list[k].first, *list[k].second);
    }
  });
}

/// The images of one evaluation, in T: masked inputs, their products, the filtered moments and the
/// gradient maps. Kept in an ImageLossWorkspace between calls.
template <typename T>
struct Scratch
{
  cv::Mat X, Y, XX, YY, XY, M1, M2, Sxx, Syy, Sxy, D1, Dxx, Dxy, F1, Fxx, Fxy, Grad;
  void Create(int width, int height)
  {
    for (cv::Mat* m : { &X, &Y, &XX, &YY, &XY, &M1, &M2, &Sxx, &Syy, &Sxy, &D1, &Dxx, &Dxy, &F1, &Fxx, &Fxy, &Grad })
    {
      m->create(height, width, cv::DataType<T>::depth); // reallocates only when the size changes
    }
  }
};

/// Sum over rows of per-row sums, in row order: the same result whatever the number of threads.
double SumRows(const std::vector<double>& rows)
{
  double total = 0;
  for (double v : rows)
  {
    total += v;
  }
  return total;
}

/**
 * SSIM map of w.X and w.Y (their products already in w.XX, w.YY, w.XY); returns its sum over the
 * masked pixels. With @p gradientWeight g != 0 it also fills w.D1, w.Dxx, w.Dxy so that
 * d(g sum_{p in mask} SSIM(p))/dX = G*D1 + 2 X G*Dxx + Y G*Dxy (SsimAt, bigusSsimMath.h).
 */
template <typename T>
double SsimSum(Scratch<T>& w, const unsigned char* mask, double gradientWeight)
{
  FilterAll({ { &w.X, &w.M1 }, { &w.Y, &w.M2 }, { &w.XX, &w.Sxx }, { &w.YY, &w.Syy }, { &w.XY, &w.Sxy } });
  const int width = w.X.cols;
  std::vector<double> rows(w.X.rows, 0.0);
  vtkSMPTools::For(0, w.X.rows, 16, [&](int first, int last) {
    for (int j = first; j < last; ++j)
    {
      const T* pm1 = w.M1.template ptr<T>(j);
      const T* pm2 = w.M2.template ptr<T>(j);
      const T* pxx = w.Sxx.template ptr<T>(j);
      const T* pyy = w.Syy.template ptr<T>(j);
      const T* pxy = w.Sxy.template ptr<T>(j);
      T* d1 = w.D1.template ptr<T>(j);
      T* dxx = w.Dxx.template ptr<T>(j);
      T* dxy = w.Dxy.template ptr<T>(j);
      const unsigned char* mr = mask ? mask + std::size_t(j) * width : nullptr;
      double sum = 0;
      for (int i = 0; i < width; ++i)
      {
        const SsimPixel s = SsimAt(pm1[i], pm2[i], pxx[i], pyy[i], pxy[i]);
        const double g = (!mr || mr[i]) ? gradientWeight : 0.0;
        sum += (!mr || mr[i]) ? s.Value : 0.0;
        if (gradientWeight != 0)
        {
          d1[i] = static_cast<T>(g * s.DMean);
          dxx[i] = static_cast<T>(g * s.DSquare);
          dxy[i] = static_cast<T>(g * s.DCross);
        }
      }
      rows[j] = sum;
    }
  });
  return SumRows(rows);
}

/// w.X = x, w.Y = y (each times the mask when @p maskImages) and their products; returns the number
/// of masked pixels.
template <typename T>
long Prepare(
  Scratch<T>& w, const float* x, const float* y, const unsigned char* mask, int width, int height, bool maskImages)
{
  w.Create(width, height);
  vtkSMPTools::For(0, height, 16, [&](int first, int last) {
    for (int j = first; j < last; ++j)
    {
      T* X = w.X.template ptr<T>(j);
      T* Y = w.Y.template ptr<T>(j);
      T* XX = w.XX.template ptr<T>(j);
      T* YY = w.YY.template ptr<T>(j);
      T* XY = w.XY.template ptr<T>(j);
      const std::size_t row = std::size_t(j) * width;
      for (int i = 0; i < width; ++i)
      {
        const T m = (!maskImages || !mask || mask[row + i]) ? T(1) : T(0);
        X[i] = m * static_cast<T>(x[row + i]);
        Y[i] = m * static_cast<T>(y[row + i]);
        XX[i] = X[i] * X[i];
        YY[i] = Y[i] * Y[i];
        XY[i] = X[i] * Y[i];
      }
    }
  });
  return mask ? static_cast<long>(cv::countNonZero(cv::Mat(height, width, CV_8U, const_cast<unsigned char*>(mask))))
              : long(width) * height;
}

template <typename T>
ImageLossTerms Compute(const float* rendered, const float* target, const unsigned char* mask, int width, int height,
  const ImageLossWeights& weights, float* gradient, Scratch<T>& w)
{
  ImageLossTerms terms;
  const int depth = cv::DataType<T>::depth;
  terms.MaskedPixels = Prepare(w, rendered, target, mask, width, height, true);
  if (terms.MaskedPixels == 0)
  {
    if (gradient)
    {
      std::fill(gradient, gradient + std::size_t(width) * height, 0.0f);
    }
    return terms;
  }
  const double K = static_cast<double>(terms.MaskedPixels);
  auto inMask = [mask, width](int j, int i) { return !mask || mask[std::size_t(j) * width + i]; };

  // L1 (sum and gradient) while the gradient image is initialised; X and Y are already masked.
  std::vector<double> rows(height, 0.0);
  const T step = static_cast<T>(weights.L1 / K);
  vtkSMPTools::For(0, height, 16, [&](int first, int last) {
    for (int j = first; j < last; ++j)
    {
      const T* X = w.X.template ptr<T>(j);
      const T* Y = w.Y.template ptr<T>(j);
      T* g = w.Grad.template ptr<T>(j);
      double sum = 0;
      for (int i = 0; i < width; ++i)
      {
        const T r = X[i] - Y[i];
        sum += std::abs(double(r));
        g[i] = (weights.L1 != 0 && inMask(j, i)) ? step * static_cast<T>((r > 0) - (r < 0)) : T(0);
      }
      rows[j] = sum;
    }
  });
  terms.L1 = weights.L1 != 0 ? SumRows(rows) / K : 0.0;
  if (weights.DSSIM != 0)
  {
    terms.DSSIM = 1.0 - SsimSum(w, mask, gradient ? -weights.DSSIM / K : 0.0) / K;
    if (gradient)
    {
      FilterAll({ { &w.D1, &w.F1 }, { &w.Dxx, &w.Fxx }, { &w.Dxy, &w.Fxy } });
      vtkSMPTools::For(0, height, 16, [&](int first, int last) {
        for (int j = first; j < last; ++j)
        {
          const T* X = w.X.template ptr<T>(j);
          const T* Y = w.Y.template ptr<T>(j);
          const T* f1 = w.F1.template ptr<T>(j);
          const T* fxx = w.Fxx.template ptr<T>(j);
          const T* fxy = w.Fxy.template ptr<T>(j);
          T* g = w.Grad.template ptr<T>(j);
          for (int i = 0; i < width; ++i)
          {
            g[i] += inMask(j, i) ? f1[i] + 2 * X[i] * fxx[i] + Y[i] * fxy[i] : T(0);
          }
        }
      });
    }
  }
  if (weights.FFL != 0)
  {
    // Orthonormal DFT of the masked residual, zero-padded to OpenCV's next fast transform size
    // (frame sizes such as 820 = 4 x 5 x 41 are slow otherwise): F~ = F / sqrt(N), FFL = (1/N) sum w |F~|^2.
    const int pw = cv::getOptimalDFTSize(width), ph = cv::getOptimalDFTSize(height);
    const double N = double(pw) * ph;
    cv::Mat r;
    cv::copyMakeBorder(w.X - w.Y, r, 0, ph - height, 0, pw - width, cv::BORDER_CONSTANT, cv::Scalar(0));
    cv::Mat F;
    cv::dft(r, F, cv::DFT_COMPLEX_OUTPUT);
    cv::Mat planes[2];
    cv::split(F, planes);
    cv::Mat magnitude;
    cv::magnitude(planes[0], planes[1], magnitude);
    double largest = 0;
    cv::minMaxLoc(magnitude, nullptr, &largest);
    cv::Mat fw;
    if (largest > 0)
    {
      cv::pow(magnitude / largest, weights.FFLAlpha, fw);
    }
    else
    {
      fw = cv::Mat::zeros(magnitude.size(), depth);
    }
    terms.FFL = cv::sum(fw.mul(magnitude.mul(magnitude)))[0] / (N * N);
    if (gradient)
    {
      // d/dr of (1/N^2) sum_k w_k |F_k|^2 = (2/N^2) Re(unscaled inverse DFT of w F), w held constant.
      cv::Mat wF;
      cv::Mat weighted[2] = { planes[0].mul(fw), planes[1].mul(fw) };
      cv::merge(weighted, 2, wF);
      cv::Mat back;
      cv::dft(wF, back, cv::DFT_INVERSE | cv::DFT_COMPLEX_OUTPUT);
      cv::Mat parts[2];
      cv::split(back, parts);
      const cv::Mat fflGradient = (weights.FFL * 2.0 / (N * N)) * parts[0](cv::Rect(0, 0, width, height));
      cv::add(w.Grad, fflGradient, w.Grad,
        mask ? cv::Mat(height, width, CV_8U, const_cast<unsigned char*>(mask)) : cv::noArray());
    }
  }
  terms.Total = weights.L1 * terms.L1 + weights.DSSIM * terms.DSSIM + weights.FFL * terms.FFL;
  if (gradient)
  {
    cv::Mat out(height, width, CV_32F, gradient);
    w.Grad.convertTo(out, CV_32F);
  }
  return terms;
}
}

bool CheckImageLossWeights(const ImageLossWeights& weights, std::string* error)
{
  const double w[3] = { weights.L1, weights.DSSIM, weights.FFL };
  const bool each = std::all_of(w, w + 3, [](double v) { return std::isfinite(v) && v >= 0; }) &&
    std::isfinite(weights.FFLAlpha) && weights.FFLAlpha >= 0;
  if (each && w[0] + w[1] + w[2] > 0)
  {
    return true;
  }
  if (error)
  {
    *error = vtkfmt::sprintf("the image loss's weights (L1 %g, D-SSIM %g, FFL %g, FFL alpha %g) %s", w[0], w[1], w[2],
      weights.FFLAlpha,
      each ? "are all 0: no step would move the field; give at least one of L1, D-SSIM and FFL a weight above 0"
           : "must each be a finite number >= 0");
  }
  return false;
}

struct ImageLossWorkspace::Internals
{
  Scratch<float> Float;
  Scratch<double> Double;
};

ImageLossWorkspace::ImageLossWorkspace()
  : Data(new Internals)
{}

ImageLossWorkspace::~ImageLossWorkspace() = default;
ImageLossWorkspace::ImageLossWorkspace(ImageLossWorkspace&&) noexcept = default;
ImageLossWorkspace& ImageLossWorkspace::operator=(ImageLossWorkspace&&) noexcept = default;

ImageLossTerms ComputeImageLoss(const float* rendered, const float* target, const unsigned char* mask, int width,
  int height, const ImageLossWeights& weights, float* gradient, bool doublePrecision, ImageLossWorkspace* workspace)
{
  ImageLossWorkspace local;
  ImageLossWorkspace::Internals& w = *(workspace ? workspace : &local)->Data;
  return doublePrecision ? Compute<double>(rendered, target, mask, width, height, weights, gradient, w.Double)
                         : Compute<float>(rendered, target, mask, width, height, weights, gradient, w.Float);
}

double MeanSSIM(const float* x, const float* y, const unsigned char* mask, int width, int height, bool maskImages)
{
  Scratch<double> w;
  const long K = Prepare(w, x, y, mask, width, height, maskImages);
  return K == 0 ? 0.0 : SsimSum(w, mask, 0.0) / K;
}

} // namespace bigus
