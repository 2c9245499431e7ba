// diag(A^T W A) of the reflectivity basis on the CPU (see bigusBasisNorms.h).
#include "bigusBasisNorms.h"

#include "bigusGaussianMath.h"
#include "bigusRasterGeometry.h"

#include "vtkSMPTools.h"

#include <algorithm>
#include <vector>

namespace bigus
{

bool AccumulateBasisNorms(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
  const float* weights, double* norms, std::string* error)
{
  std::vector<PreparedSlice> prepared;
  if (!PrepareSlices(slices, count, options, prepared, error))
  {
    return false;
  }
  const double sigmaE = EffectiveElevationSigma(options);
  // Gaussian-parallel: each Gaussian sums its own slices and pixels in a fixed order.
  vtkSMPTools::For(0, field.Count, 256, [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t i = begin; i < end; ++i)
    {
      const GaussianParams g = LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, i);
      double total = 0;
      std::int64_t offset = 0;
      for (const PreparedSlice& s : prepared)
      {
        const float* W = weights + offset;
        offset += std::int64_t(s.Width) * s.Height;
        const Footprint f = SetupFootprint(g, s.Frame, sigmaE, options.Cutoff, nullptr);
        int box[4];
        if (!f.Visible)
        {
          continue;
        }
        ForEachFootprintSpan(f, s, box, [&](int row, int first, int last, const auto& weight) {
          const float* w = W + std::int64_t(row) * s.Width + box[0];
          for (int col = first; col < last; ++col)
          {
            const double value = weight(col);
            total += w[col] * value * value;
          }
        });
      }
      norms[i] += total;
    }
  });
  return true;
}

} // namespace bigus
