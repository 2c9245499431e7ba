// `bigus benchmark`: render speed against render error on the liver's field (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"

#include "bigusReferenceRenderer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

namespace bigus::benchmark
{
namespace
{
/// The naive double-precision renderer's image of a Width x Width crop at the centre of a frame.
struct CropReference
{
  SliceGeometry Slice;
  std::vector<double> I;
};

CropReference RenderReference(const GaussianField& field, const RenderOptions& o, const std::array<double, 16>& pose,
  int width, int height, int crop)
{
  CropReference ref;
  const double i0 = (width - crop) / 2, j0 = (height - crop) / 2;
  std::copy(pose.begin(), pose.end(), ref.Slice.ImageToReference);
  for (int r = 0; r < 3; ++r)
  {
    ref.Slice.ImageToReference[4 * r + 3] += pose[4 * r] * i0 + pose[4 * r + 1] * j0;
  }
  ref.Slice.Width = crop;
  ref.Slice.Height = crop;
  const reference::FieldD d = reference::FromView(field.View());
  std::vector<double> S;
  reference::Forward(d, ref.Slice, o, S, &ref.I);
  return ref;
}
}

bool RenderSection(BenchmarkContext& context, std::string* error)
{
  const Sweep& liver = context.Sweeps[0];
  const HoldOutResults& results = context.HoldOut;
  const bool quick = context.Quick;
  Report& report = context.Report;
  std::ostringstream& md = report.Markdown;
  const int crop = quick ? 32 : 128;
  const std::array<double, 16>& pose = liver.Data.Poses[liver.HeldOut[liver.HeldOut.size() / 2]];
  const int W = liver.Data.Width, H = liver.Data.Height;
  const double referenceStart = Now();
  RenderOptions exact = results.LiverOptions;
  const CropReference ref = RenderReference(results.LiverField, exact, pose, W, H, crop);
  const double referenceSeconds = Now() - referenceStart;
  auto cpu = CreateCpuRenderer();
  md << "\n## Render speed against render error (liver field, " << results.LiverField.Count() << " Gaussians)\n\n"
     << "Time per " << W << " x " << H << " slice at the held-out poses (CPU renderer, float) and the largest "
     << "and RMS difference in intensity from the naive double-precision renderer (no cutoff) on a " << crop << " x "
     << crop << " crop at the centre of a held-out frame (the naive renderer took " << Format("%.1f", referenceSeconds)
     << " s for that crop).\n\n"
     << "| cutoff k (standard deviations) | ms / slice | max abs error | RMS error | PSNR against naive (dB) |\n"
     << "|---|---|---|---|---|\n";
  PlotSpec spec;
  spec.Title = "render time per slice against error from the naive renderer (liver)";
  spec.XLabel = "ms per slice (log)";
  spec.YLabel = "-log10(max abs error)";
  spec.LogX = true;
  spec.Series.push_back({ "cutoff 3, 4, 5, 6", {} });
  std::vector<float> S(std::size_t(W) * H), I(S.size()), cropS(std::size_t(crop) * crop), cropI(cropS.size());
  for (double k : { 3.0, 4.0, 5.0, 6.0 })
  {
    RenderOptions o = results.LiverOptions;
    o.Cutoff = k;
    const int repeats = quick ? 2 : 10;
    const double start = Now();
    for (int n = 0; n < repeats; ++n)
    {
      SliceGeometry g;
      const auto& p = liver.Data.Poses[liver.HeldOut[n % liver.HeldOut.size()]];
      std::copy(p.begin(), p.end(), g.ImageToReference);
      g.Width = W;
      g.Height = H;
      cpu->Forward(results.LiverField.View(), &g, 1, o, S.data(), I.data(), nullptr, nullptr);
    }
    const double ms = 1e3 * (Now() - start) / repeats;
    cpu->Forward(results.LiverField.View(), &ref.Slice, 1, o, cropS.data(), cropI.data(), nullptr, nullptr);
    double maxError = 0, sum = 0;
    for (std::size_t p = 0; p < cropI.size(); ++p)
    {
      const double e = std::abs(cropI[p] - ref.I[p]);
      maxError = std::max(maxError, e);
      sum += e * e;
    }
    const double rms = std::sqrt(sum / cropI.size());
    md << "| " << Format("%.0f", k) << " | " << Format("%.2f", ms) << " | " << Format("%.2e", maxError) << " | "
       << Format("%.2e", rms) << " | " << Format("%.1f", -20 * std::log10(std::max(rms, 1e-12))) << " |\n";
    report.Json["render"].push_back(
      { { "cutoff", k }, { "ms_per_slice", ms }, { "max_error", maxError }, { "rms_error", rms } });
    std::printf("  render       cutoff %.0f: %.2f ms per slice, max |dI| %.2e, RMS %.2e\n", k, ms, maxError, rms);
    spec.Series[0].Points.emplace_back(ms, -std::log10(std::max(maxError, 1e-12)));
  }
  if (!report.Plot(spec, "render_speed_error.png"))
  {
    return Failed(report.PlotFolder + ": cannot write a plot", error);
  }
  return true;
}
}
