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
        if (!f.Visible || !FootprintBox(f, s, box))
        {
          continue;
        }
        // The pixels and the float arithmetic of phase 2 (RasterTile), relative to the box's first pixel.
        const BoxFootprint fp = MakeBoxFootprint(f, s, box, 1.0);
        const float det = fp.A * fp.C - fp.B * fp.B;
        for (int row = box[2]; row <= box[3]; ++row)
        {
          const float dy = (row - box[2]) * fp.P2 - fp.Dcy;
          const float xrow = (row - box[2]) * fp.P1 - fp.Dcx;
          int first, last;
          RowSpan(fp.A, fp.B, det, fp.CutoffSquared, dy, xrow, fp.P0, 0, box[1] - box[0] + 1, first, last);
          const float* w = W + std::int64_t(row) * s.Width + box[0];
          for (int col = first; col < last; ++col)
          {
            const float dx = col * fp.P0 + xrow;
            const float form = AxesForm(fp.Axes[0], fp.Axes[1], fp.Axes[2], fp.Axes[3], dx, dy);
            if (form <= fp.CutoffSquared && w[col] != 0)
            {
              const double value = fp.Weight * FastExp(-0.5f * form);
              total += w[col] * value * value;
            }
          }
        }
      }
      norms[i] += total;
    }
  });
  return true;
}

} // namespace bigus
