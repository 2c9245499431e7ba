// The reflectivity basis assembled once per geometry (see bigusAssembledBasis.h).
#include "bigusAssembledBasis.h"

#include "bigusGaussianMath.h"
#include "bigusRasterGeometry.h"

#include "vtkSMPTools.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace bigus
{

namespace
{
constexpr std::int64_t GaussianChunk = 4096; // Gaussians per task of the assembly

/**
 * ForEachFootprintSpan for Gaussian @p i on slice @p s after the cheap test of OutOfReach and the set-up; false when
 * it is not visible there.
 */
template <typename F>
bool ForEachSpan(const FieldView& field, std::int64_t i, const Reach& reach, const PreparedSlice& s, double sigmaE,
  double cutoff, int box[4], F span)
{
  if (OutOfReach(reach, s, sigmaE, cutoff))
  {
    return false;
  }
  const GaussianParams g = LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, i);
  const Footprint f = SetupFootprint(g, s.Frame, sigmaE, cutoff, nullptr);
  return f.Visible && ForEachFootprintSpan(f, s, box, span);
}
}

std::int64_t AssembledBasis::Size::Bytes() const
{
  return this->Weights * std::int64_t(sizeof(float)) + this->Spans * std::int64_t(sizeof(Span)) +
    this->Footprints * std::int64_t(sizeof(FootprintEntry) + sizeof(double));
}

bool AssembledBasis::Measure(const FieldView& field, const SliceGeometry* slices, int count,
  const RenderOptions& options, Size& size, std::string* error)
{
  AssembledBasis counting;
  return counting.Build(field, slices, count, options, -1, &size, error, nullptr);
}

bool AssembledBasis::Assemble(const FieldView& field, const SliceGeometry* slices, int count,
  const RenderOptions& options, std::int64_t maximumBytes, std::string* error, bool* tooLarge)
{
  return this->Build(field, slices, count, options, maximumBytes, nullptr, error, tooLarge);
}

bool AssembledBasis::Build(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
  std::int64_t maximumBytes, Size* measured, std::string* error, bool* tooLarge)
{
  *this = AssembledBasis();
  if (tooLarge)
  {
    *tooLarge = false;
  }
  std::vector<PreparedSlice> prepared;
  if (!PrepareSlices(slices, count, options, prepared, error))
  {
    return false;
  }
  const double sigmaE = EffectiveElevationSigma(options);
  const std::int64_t n = field.Count;
  const std::int64_t chunks = (n + GaussianChunk - 1) / GaussianChunk;
  const std::int64_t tasks = count * chunks; // slice-major: task t is chunk t % chunks of slice t / chunks
  std::vector<std::int64_t> slicePixels(count + 1, 0);
  for (int j = 0; j < count; ++j)
  {
    slicePixels[j + 1] = slicePixels[j] + std::int64_t(prepared[j].Width) * prepared[j].Height;
  }
  std::vector<Reach> reach(n);
  vtkSMPTools::For(0, n, 4096, [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t i = begin; i < end; ++i)
    {
      reach[i] = ReachOf(field, i);
    }
  });
  // Pass 1 counts each task's footprints, spans and weights; pass 2 stores them at the prefix sums.
  std::vector<Size> at(tasks + 1);
  for (int pass = 0; pass < 2; ++pass)
  {
    vtkSMPTools::For(0, tasks, 1, [&](std::int64_t begin, std::int64_t end) {
      for (std::int64_t t = begin; t < end; ++t)
      {
        const int j = static_cast<int>(t / chunks);
        const PreparedSlice& s = prepared[j];
        Size cursor = pass == 0 ? Size() : at[t];
        for (std::int64_t i = (t % chunks) * GaussianChunk; i < std::min(n, (t % chunks + 1) * GaussianChunk); ++i)
        {
          int box[4];
          const Size first = cursor;
          const bool visible = ForEachSpan(
            field, i, reach[i], s, sigmaE, options.Cutoff, box, [&](int row, int a, int b, const auto& weight) {
              if (pass == 1)
              {
                this->Spans[cursor.Spans] = { slicePixels[j] + std::int64_t(row) * s.Width + box[0] + a, b - a };
                float* w = this->Weights.data() + cursor.Weights;
                for (int col = a; col < b; ++col)
                {
                  w[col - a] = weight(col);
                }
              }
              cursor.Spans += 1;
              cursor.Weights += b - a;
            });
          if (visible)
          {
            if (pass == 1)
            {
              this->Footprints[cursor.Footprints] = { i, first.Spans, first.Weights, cursor.Spans - first.Spans };
            }
            cursor.Footprints += 1;
          }
        }
        if (pass == 0)
        {
          at[t + 1] = cursor; // this task's counts, summed below
        }
      }
    });
    if (pass == 1)
    {
      break;
    }
    for (std::int64_t t = 0; t < tasks; ++t)
    {
      at[t + 1].Footprints += at[t].Footprints;
      at[t + 1].Spans += at[t].Spans;
      at[t + 1].Weights += at[t].Weights;
    }
    if (measured)
    {
      *measured = at[tasks];
    }
    if (maximumBytes < 0)
    {
      return true; // Measure
    }
    if (maximumBytes > 0 && at[tasks].Bytes() > maximumBytes)
    {
      if (tooLarge)
      {
        *tooLarge = true;
      }
      if (error)
      {
        char text[300];
        std::snprintf(text, sizeof(text),
          "the assembled reflectivity basis needs %.0f MB (%lld weights in %lld footprints of %lld Gaussians on %d "
          "slices) and %.0f MB are allowed",
          at[tasks].Bytes() / 1e6, static_cast<long long>(at[tasks].Weights),
          static_cast<long long>(at[tasks].Footprints), static_cast<long long>(n), count, maximumBytes / 1e6);
        *error = text;
      }
      return false;
    }
    this->Footprints.resize(at[tasks].Footprints);
    this->Spans.resize(at[tasks].Spans);
    this->Weights.resize(at[tasks].Weights);
  }
  this->Stored = at[tasks];
  this->Gaussians = n;
  this->Pixels = slicePixels[count];
  this->SlicePixels = slicePixels;
  this->SliceFootprints.resize(count + 1);
  for (int j = 0; j <= count; ++j)
  {
    this->SliceFootprints[j] = at[std::int64_t(j) * chunks].Footprints;
  }
  return true;
}

void AssembledBasis::Apply(const float* r, float* S) const
{
  const int count = static_cast<int>(this->SliceFootprints.size()) - 1;
  vtkSMPTools::For(0, count, 1, [&](int begin, int end) {
    for (int j = begin; j < end; ++j)
    {
      std::fill(S + this->SlicePixels[j], S + this->SlicePixels[j + 1], 0.0f);
      for (std::int64_t f = this->SliceFootprints[j]; f < this->SliceFootprints[j + 1]; ++f)
      {
        const FootprintEntry& e = this->Footprints[f];
        const float v = r[e.Gaussian];
        const float* w = this->Weights.data() + e.FirstWeight;
        for (std::int64_t k = e.FirstSpan; k < e.FirstSpan + e.SpanCount; ++k)
        {
          float* out = S + this->Spans[k].Pixel;
          const std::int64_t pixels = this->Spans[k].Count;
          for (std::int64_t q = 0; q < pixels; ++q)
          {
            out[q] += v * w[q];
          }
          w += pixels;
        }
      }
    }
  });
}

void AssembledBasis::ApplyTranspose(const float* y, double* out) const
{
  this->Transpose(y, false, out);
}

void AssembledBasis::Norms(const float* weights, double* out) const
{
  this->Transpose(weights, true, out);
}

void AssembledBasis::Transpose(const float* y, bool square, double* out) const
{
  const std::int64_t footprints = static_cast<std::int64_t>(this->Footprints.size());
  std::vector<double> dots(footprints);
  vtkSMPTools::For(0, footprints, 1024, [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t f = begin; f < end; ++f)
    {
      const FootprintEntry& e = this->Footprints[f];
      const float* w = this->Weights.data() + e.FirstWeight;
      double sum = 0;
      for (std::int64_t k = e.FirstSpan; k < e.FirstSpan + e.SpanCount; ++k)
      {
        const float* in = y + this->Spans[k].Pixel;
        const std::int64_t pixels = this->Spans[k].Count;
        for (std::int64_t q = 0; q < pixels; ++q)
        {
          sum += square ? double(in[q]) * w[q] * w[q] : double(in[q]) * w[q];
        }
        w += pixels;
      }
      dots[f] = sum;
    }
  });
  // Into each Gaussian in the footprints' order (slice by slice): the same sums for any number of threads.
  for (std::int64_t f = 0; f < footprints; ++f)
  {
    out[this->Footprints[f].Gaussian] += dots[f];
  }
}

} // namespace bigus
