// CPU backend of the beam-integrated Gaussian renderer: phase 1 (per Gaussian, double precision),
// deterministic tile binning, phase 2 (per tile, float, vectorisable), and a Gaussian-parallel
// backward pass without atomics. Multi-threaded with vtkSMPTools; results do not depend on the
// number of threads (every pixel sums its Gaussians in index order).
#include "bigusGaussianMath.h"
#include "bigusRasterGeometry.h"
#include "bigusRenderer.h"

#include "vtkSMPThreadLocal.h"
#include "vtkSMPTools.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <limits>
#include <cmath>
#include <vector>

// The inner loops are compiled twice, for AVX2 + FMA and for baseline x86-64, and the loader picks
// one per machine (GCC function multi-versioning), so one binary runs everywhere and fast where it can.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
#define BIGUS_TARGET_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define BIGUS_TARGET_CLONES
#endif

namespace bigus
{

Renderer::~Renderer() = default;

namespace
{
constexpr std::int64_t ChunkSize = 2048; // Gaussians per binning chunk (fixed: keeps binning deterministic)

double Now()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/**
 * Bound on every Gaussian's variance along any direction, exp(2 max_k l_k) (mm^2), computed once per
 * call. n^T Sigma n never exceeds it, so the elevation test below only keeps extra candidates, which
 * SetupFootprint's exact test then drops: a cheap, vectorisable first cull instead of a full setup.
 */
struct CullBounds
{
  std::vector<float> MaxVariance; // [N]

  void Compute(const FieldView& field)
  {
    this->MaxVariance.resize(field.Count);
    vtkSMPTools::For(0, field.Count, 8192, [&](std::int64_t begin, std::int64_t end) {
      for (std::int64_t i = begin; i < end; ++i)
      {
        const float* l = field.LogScales + 3 * i;
        const float m = std::max(std::max(l[0], l[1]), l[2]);
        // NaN or huge log-scales keep the Gaussian as a candidate; SetupFootprint clamps them.
        this->MaxVariance[i] = (m == m && m < 40.f) ? std::exp(2.f * std::min(m, float(MaximumLogScale)))
                                                    : std::numeric_limits<float>::infinity();
      }
    });
  }
};

/// First elevation cull: |m_z| <= k sqrt(max variance + sigma_E^2) with a small safety margin.
bool MayBeVisible(const FieldView& field, const CullBounds& bounds, std::int64_t i, const PreparedSlice& s,
  double sigmaE, double cutoff)
{
  const double* n = s.Frame.F[2];
  const double dz = n[0] * (field.Means[3 * i] - s.Frame.Origin[0]) +
    n[1] * (field.Means[3 * i + 1] - s.Frame.Origin[1]) + n[2] * (field.Means[3 * i + 2] - s.Frame.Origin[2]);
  const double k = cutoff * 1.001 + 1e-9;
  return dz * dz <= k * k * (double(bounds.MaxVariance[i]) * 1.001 + sigmaE * sigmaE);
}

/// Phase 1 for one slice: the visible splats, in Gaussian index order.
void SetupSlice(const FieldView& field, const CullBounds& bounds, const PreparedSlice& s, const RenderOptions& o,
  std::vector<std::vector<Splat>>& perChunk, std::vector<Splat>& splats)
{
  const double sigmaE = EffectiveElevationSigma(o);
  const std::int64_t chunks = (field.Count + ChunkSize - 1) / ChunkSize;
  perChunk.resize(chunks);
  vtkSMPTools::For(0, chunks, 1, [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t chunk = begin; chunk < end; ++chunk)
    {
      std::vector<Splat>& out = perChunk[chunk];
      out.clear();
      const std::int64_t last = std::min(field.Count, (chunk + 1) * ChunkSize);
      for (std::int64_t i = chunk * ChunkSize; i < last; ++i)
      {
        if (!MayBeVisible(field, bounds, i, s, sigmaE, o.Cutoff))
        {
          continue;
        }
        const GaussianParams g = LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, i);
        const double r = EffectiveReflectivity(g.Reflectivity, o.NonNegativeReflectivity);
        if (r == 0)
        {
          continue;
        }
        const Footprint f = SetupFootprint(g, s.Frame, sigmaE, o.Cutoff, nullptr);
        int box[4];
        if (!f.Visible || !FootprintBox(f, s, box))
        {
          continue;
        }
        out.push_back(MakeSplat(f, r, box));
      }
    }
  });
  splats.clear();
  for (std::int64_t chunk = 0; chunk < chunks; ++chunk)
  {
    splats.insert(splats.end(), perChunk[chunk].begin(), perChunk[chunk].end());
  }
}

/// Deterministic binning: per tile, the indices (into splats) of the splats that touch it, in order.
void BinSplats(const std::vector<Splat>& splats, const PreparedSlice& s, std::vector<std::int64_t>& tileStart,
  std::vector<std::int32_t>& entries)
{
  const int tiles = s.TilesX * s.TilesY;
  const std::int64_t count = static_cast<std::int64_t>(splats.size());
  const std::int64_t chunks = std::max<std::int64_t>(1, (count + ChunkSize - 1) / ChunkSize);
  std::vector<std::int64_t> counts(chunks * tiles, 0); // [chunk, tile]
  auto forTiles = [&](const Splat& sp, auto&& visit) {
    for (int ty = sp.Y0 / TileSize; ty <= sp.Y1 / TileSize; ++ty)
    {
      for (int tx = sp.X0 / TileSize; tx <= sp.X1 / TileSize; ++tx)
      {
        visit(ty * s.TilesX + tx);
      }
    }
  };
  vtkSMPTools::For(0, chunks, 1, [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t c = begin; c < end; ++c)
    {
      std::int64_t* row = &counts[c * tiles];
      for (std::int64_t k = c * ChunkSize; k < std::min(count, (c + 1) * ChunkSize); ++k)
      {
        forTiles(splats[k], [&](int t) { ++row[t]; });
      }
    }
  });
  tileStart.assign(tiles + 1, 0);
  std::vector<std::int64_t> offsets(chunks * tiles);
  std::int64_t total = 0;
  for (int t = 0; t < tiles; ++t)
  {
    tileStart[t] = total;
    for (std::int64_t c = 0; c < chunks; ++c)
    {
      offsets[c * tiles + t] = total;
      total += counts[c * tiles + t];
    }
  }
  tileStart[tiles] = total;
  entries.resize(total);
  vtkSMPTools::For(0, chunks, 1, [&](std::int64_t begin, std::int64_t end) {
    for (std::int64_t c = begin; c < end; ++c)
    {
      std::int64_t* next = &offsets[c * tiles];
      for (std::int64_t k = c * ChunkSize; k < std::min(count, (c + 1) * ChunkSize); ++k)
      {
        forTiles(splats[k], [&](int t) { entries[next[t]++] = static_cast<std::int32_t>(k); });
      }
    }
  });
}

/// Geometry of one tile: its pixel range and the plane offsets of its first pixel.
struct TileFrame
{
  int I0, J0, I1, J1; // pixel range [I0, I1) x [J0, J1)
  double X0, Y0;      // in-plane position of pixel (I0, J0), mm
  float P0, P1, P2;   // pixel -> plane map
};

/**
 * Phase 2 for one tile: adds every listed splat, in order, into the TileSize x TileSize accumulator.
 * Offsets are taken relative to the tile's first pixel so that float keeps its precision whatever the
 * size of the image. Returns the number of pixel evaluations. (Row spans, as in the backward pass,
 * cost more than they save on a 16-pixel tile row: measured 42 against 28 ms on a liver slice.)
 */
BIGUS_TARGET_CLONES std::int64_t RasterTile(
  const Splat* splats, const std::int32_t* entries, std::int64_t count, const TileFrame& t, float* acc)
{
  alignas(64) float column[TileSize];
  for (int k = 0; k < TileSize; ++k)
  {
    column[k] = k * t.P0;
  }
  std::int64_t evaluations = 0;
  for (std::int64_t e = 0; e < count; ++e)
  {
    const Splat& sp = splats[entries[e]];
    const float dcx = static_cast<float>(sp.Cx - t.X0);
    const float dcy = static_cast<float>(sp.Cy - t.Y0);
    const int cs = std::max(sp.X0, t.I0) - t.I0, ce = std::min(sp.X1 + 1, t.I1) - t.I0;
    const int rs = std::max(sp.Y0, t.J0) - t.J0, re = std::min(sp.Y1 + 1, t.J1) - t.J0;
    const float co = sp.Cos, si = sp.Sin, s1 = sp.InvMajor, s2 = sp.InvMinor, w = sp.Weight;
    const float cutoffSquared = sp.CutoffSquared;
    for (int r = rs; r < re; ++r)
    {
      const float dy = r * t.P2 - dcy;
      const float xrow = r * t.P1 - dcx;
      float* out = acc + r * TileSize;
      for (int q = cs; q < ce; ++q)
      {
        const float dx = column[q] + xrow;
        const float form = AxesForm(co, si, s1, s2, dx, dy);
        const float value = w * FastExp(-0.5f * form);
        out[q] += form <= cutoffSquared ? value : 0.0f;
      }
      evaluations += ce - cs;
    }
  }
  return evaluations;
}

/// Phase 2 for one slice: every tile sums its splats in order into S.
std::int64_t RasterSlice(const std::vector<Splat>& splats, const PreparedSlice& s,
  const std::vector<std::int64_t>& tileStart, const std::vector<std::int32_t>& entries, float* S)
{
  const int tiles = s.TilesX * s.TilesY;
  std::vector<std::int64_t> perTile(tiles, 0);
  vtkSMPTools::For(0, tiles, 1, [&](int begin, int end) {
    alignas(64) float acc[TileSize * TileSize];
    for (int k = begin; k < end; ++k)
    {
      TileFrame t;
      t.I0 = (k % s.TilesX) * TileSize;
      t.J0 = (k / s.TilesX) * TileSize;
      t.I1 = std::min(s.Width, t.I0 + TileSize);
      t.J1 = std::min(s.Height, t.J0 + TileSize);
      t.X0 = t.I0 * s.PixelToPlane[0] + t.J0 * s.PixelToPlane[1];
      t.Y0 = t.J0 * s.PixelToPlane[2];
      t.P0 = static_cast<float>(s.PixelToPlane[0]);
      t.P1 = static_cast<float>(s.PixelToPlane[1]);
      t.P2 = static_cast<float>(s.PixelToPlane[2]);
      std::fill(acc, acc + TileSize * TileSize, 0.0f);
      perTile[k] = RasterTile(splats.data(), entries.data() + tileStart[k], tileStart[k + 1] - tileStart[k], t, acc);
      for (int j = t.J0; j < t.J1; ++j)
      {
        std::copy(acc + (j - t.J0) * TileSize, acc + (j - t.J0) * TileSize + (t.I1 - t.I0),
          S + std::int64_t(j) * s.Width + t.I0);
      }
    }
  });
  std::int64_t total = 0;
  for (std::int64_t v : perTile)
  {
    total += v;
  }
  return total;
}

constexpr int Lanes = 8;

/**
 * The per-Gaussian pixel sums of the backward pass over the row spans (RowSpan) of its bounding box
 * @p box (columns box[0..1], rows box[2..3]); @p gS points at row box[2] of dL/dS; @p fp is the
 * footprint relative to the box (MakeBoxFootprint). sum[q] is the sum over those pixels of
 * PixelWeightBackward's term q, with e from the principal-axes form and the cutoff, as in phase 2. Columns are
 * processed in groups of Lanes with one partial sum per lane (vectorisable without reassociation, deterministic order).
 * Returns the number of pixels in the row spans (RenderStats::PixelEvaluations).
 */
BIGUS_TARGET_CLONES std::int64_t FootprintSums(
  const float* gS, int width, const int box[4], const BoxFootprint& fp, double sum[7])
{
  for (int q = 0; q < 7; ++q)
  {
    sum[q] = 0;
  }
  const float a = fp.A, b = fp.B, c = fp.C, w = fp.Weight, cutoffSquared = fp.CutoffSquared;
  const float P0 = fp.P0, P1 = fp.P1, P2 = fp.P2, dcx = fp.Dcx, dcy = fp.Dcy;
  const float axes[4] = { fp.Axes[0], fp.Axes[1], fp.Axes[2], fp.Axes[3] };
  const float det = a * c - b * b;
  std::int64_t evaluations = 0;
  for (int row = box[2]; row <= box[3]; ++row)
  {
    const float dy = (row - box[2]) * P2 - dcy;
    const float xrow = (row - box[2]) * P1 - dcx;
    int first, end; // columns relative to box[0], [first, end)
    RowSpan(a, b, det, cutoffSquared, dy, xrow, P0, 0, box[1] - box[0] + 1, first, end);
    const int last = end - 1;
    evaluations += end - first;
    const float* g = gS + std::int64_t(row - box[2]) * width + box[0];
    alignas(64) float part[7][Lanes] = {};
    for (int base = first; base <= last; base += Lanes)
    {
      for (int l = 0; l < Lanes; ++l)
      {
        const int col = base + l;
        const float inside = col <= last ? 1.0f : 0.0f;
        const float gv = g[col <= last ? col : last] * inside;
        const float dx = col * P0 + xrow;
        const float form = AxesForm(axes[0], axes[1], axes[2], axes[3], dx, dy);
        const float e = form <= cutoffSquared ? FastExp(-0.5f * form) : 0.0f;
        PixelWeightBackward(gv, w, e, a, b, c, dx, dy, &part[0][l], Lanes);
      }
    }
    for (int q = 0; q < 7; ++q)
    {
      for (int l = 0; l < Lanes; ++l)
      {
        sum[q] += part[q][l];
      }
    }
  }
  return evaluations;
}

class CpuRenderer : public Renderer
{
public:
  const char* GetName() const override { return "cpu"; }

  bool Forward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options, float* S,
    float* I, RenderStats* stats, std::string* error) override
  {
    std::vector<PreparedSlice> prepared;
    if (!PrepareSlices(slices, count, options, prepared, error))
    {
      return false;
    }
    const float gamma = static_cast<float>(options.Gamma);
    double t0 = Now();
    this->Bounds.Compute(field);
    std::int64_t offset = 0;
    for (int k = 0; k < count; ++k)
    {
      const PreparedSlice& s = prepared[k];
      SetupSlice(field, this->Bounds, s, options, this->ChunkSplats, this->Splats);
      BinSplats(this->Splats, s, this->TileStart, this->Entries);
      const double t1 = Now();
      const std::int64_t evals = RasterSlice(this->Splats, s, this->TileStart, this->Entries, S + offset);
      const std::int64_t pixels = std::int64_t(s.Width) * s.Height;
      if (I)
      {
        vtkSMPTools::For(0, pixels, 16384, [&](std::int64_t b, std::int64_t e) {
          for (std::int64_t p = b; p < e; ++p)
          {
            I[offset + p] = ImageFromScattering(S[offset + p], gamma);
          }
        });
      }
      const double t2 = Now();
      if (stats)
      {
        stats->GaussiansVisible += static_cast<std::int64_t>(this->Splats.size());
        stats->TileEntries += static_cast<std::int64_t>(this->Entries.size());
        stats->PixelEvaluations += evals;
        stats->SetupSeconds += t1 - t0;
        stats->RasterSeconds += t2 - t1;
      }
      t0 = t2;
      offset += pixels;
    }
    return true;
  }

  bool Backward(const FieldView& field, const SliceGeometry* slices, int count, const RenderOptions& options,
    const float* S, const float* dL, bool gradientIsWithRespectToS, FieldGradients& gradients, RenderStats* stats,
    std::string* error) override
  {
    std::vector<PreparedSlice> prepared;
    if (!PrepareSlices(slices, count, options, prepared, error))
    {
      return false;
    }
    const double t0 = Now();
    this->Bounds.Compute(field);
    const double sigmaE = EffectiveElevationSigma(options);
    std::int64_t offset = 0;
    std::vector<float>& gS = this->ScatteringGradient;
    for (int k = 0; k < count; ++k)
    {
      const PreparedSlice& s = prepared[k];
      const std::int64_t pixels = std::int64_t(s.Width) * s.Height;
      gS.resize(pixels);
      const double gamma = options.Gamma;
      vtkSMPTools::For(0, pixels, 16384, [&](std::int64_t b, std::int64_t e) {
        for (std::int64_t p = b; p < e; ++p)
        {
          gS[p] = gradientIsWithRespectToS
            ? dL[offset + p]
            : static_cast<float>(dL[offset + p] * ImageFromScatteringDerivative<double>(S[offset + p], gamma));
        }
      });
      vtkSMPThreadLocal<std::array<std::int64_t, 2>> counters(std::array<std::int64_t, 2>{ { 0, 0 } });
      // The slice's pose gradient: each Gaussian's share in its own slot, summed in index order below, so
      // that the sum does not depend on how the threads shared the Gaussians.
      std::vector<double>& shares = this->PoseShares;
      shares.assign(gradients.SlicePoses ? 6 * std::size_t(field.Count) : 0, 0.0);
      double pivot[3];
      SliceCentre(s.PixelToPlane, s.Width, s.Height, pivot);
      vtkSMPTools::For(0, field.Count, 256, [&](std::int64_t begin, std::int64_t end) {
        std::array<std::int64_t, 2>& counter = counters.Local(); // visible, pixel evaluations

        for (std::int64_t i = begin; i < end; ++i)
        {
          if (!MayBeVisible(field, this->Bounds, i, s, sigmaE, options.Cutoff))
          {
            continue;
          }
          const GaussianParams g =
            LoadGaussian(field.Means, field.LogScales, field.Quaternions, field.Reflectivities, i);
          const double r = EffectiveReflectivity(g.Reflectivity, options.NonNegativeReflectivity);
          SetupCache cache;
          const Footprint f = SetupFootprint(g, s.Frame, sigmaE, options.Cutoff, &cache);
          int box[4];
          if (!f.Visible || !FootprintBox(f, s, box))
          {
            continue;
          }
          double sum[7];
          counter[1] += FootprintSums(
            gS.data() + std::int64_t(box[2]) * s.Width, s.Width, box, MakeBoxFootprint(f, s, box, r), sum);
          counter[0] += 1;
          if (gradients.VisibleCount)
          {
            gradients.VisibleCount[i] += 1;
          }
          AddGaussianGradients(f, cache, s.Frame, sigmaE, sum, r, g.Reflectivity, options.NonNegativeReflectivity,
            gradients, i, pivot, gradients.SlicePoses ? &shares[6 * i] : nullptr);
        }
      });
      if (gradients.SlicePoses)
      {
        double total[6] = { 0, 0, 0, 0, 0, 0 };
        for (std::size_t i = 0; i < shares.size(); i += 6)
        {
          for (int c = 0; c < 6; ++c)
          {
            total[c] += shares[i + c];
          }
        }
        for (int c = 0; c < 6; ++c)
        {
          gradients.SlicePoses[6 * k + c] += total[c];
        }
      }
      for (const auto& counter : counters)
      {
        if (stats)
        {
          stats->GaussiansVisible += counter[0];
          stats->PixelEvaluations += counter[1];
        }
      }
      offset += pixels;
    }
    if (stats)
    {
      stats->RasterSeconds += Now() - t0;
    }
    return true;
  }

private:
  // Work buffers kept between calls (a training step renders and differentiates the same field size
  // again and again; fresh allocations cost page faults every step).
  CullBounds Bounds;
  std::vector<std::vector<Splat>> ChunkSplats;
  std::vector<Splat> Splats;
  std::vector<float> ScatteringGradient;
  std::vector<double> PoseShares; // [N, 6] each Gaussian's share of a slice's pose gradient (Backward)
  std::vector<std::int64_t> TileStart;
  std::vector<std::int32_t> Entries;
};
} // namespace

std::unique_ptr<Renderer> CreateCpuRenderer()
{
  return std::unique_ptr<Renderer>(new CpuRenderer);
}

} // namespace bigus
