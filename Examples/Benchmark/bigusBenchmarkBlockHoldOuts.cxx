// `bigus benchmark`: block hold-outs on the liver, consecutive frames held out (bigusBenchmarkSections.h).
#include "bigusBenchmarkSections.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace bigus::benchmark
{
bool BlockHoldOutSection(BenchmarkContext& context, std::string* error)
{
  Sweep& liver = context.Sweeps[0];
  const bool quick = context.Quick;
  Report& report = context.Report;
  std::ostringstream& md = report.Markdown;
  const std::vector<int> train = liver.Data.TrainFrames, heldOut = liver.HeldOut;
  std::vector<int> valid = train;
  valid.insert(valid.end(), heldOut.begin(), heldOut.end());
  std::sort(valid.begin(), valid.end());
  md << "\n## Block hold-outs (" << liver.Name << ")\n\n"
     << "Consecutive frames in the middle of the sweep held out, every other frame trained on: the held-out "
     << "poses lie in a gap much wider than the elevation beam, where no training frame holds their speckle. "
     << "BIGUS with its defaults and a time budget of " << Format("%.0f", liver.DefaultsBudget) << " s.\n";
  bool ok = true;
  for (int size : quick ? std::vector<int>{ 8 } : std::vector<int>{ 8, 20 })
  {
    const std::size_t first = valid.size() / 2 - size / 2;
    liver.HeldOut.assign(valid.begin() + first, valid.begin() + first + size);
    liver.Data.TrainFrames.assign(valid.begin(), valid.begin() + first);
    liver.Data.TrainFrames.insert(liver.Data.TrainFrames.end(), valid.begin() + first + size, valid.end());
    // The gap: from the last training frame before the block to the first after it (image centres, mm).
    auto centre = [&](int k) {
      const std::array<double, 16>& m = liver.Data.Poses[k];
      const double u = 0.5 * liver.Data.Width, v = 0.5 * liver.Data.Height;
      return std::array<double, 3>{ m[0] * u + m[1] * v + m[3], m[4] * u + m[5] * v + m[7],
        m[8] * u + m[9] * v + m[11] };
    };
    const auto a = centre(valid[first - 1]), c = centre(valid[first + size]);
    const double gap =
      std::sqrt((a[0] - c[0]) * (a[0] - c[0]) + (a[1] - c[1]) * (a[1] - c[1]) + (a[2] - c[2]) * (a[2] - c[2]));
    std::vector<Row> rows = Baselines(liver);
    TrainerSettings defaults;
    defaults.Iterations = 0;
    defaults.TimeBudget = liver.DefaultsBudget;
    rows.emplace_back();
    if (!TrainToBudget(liver, defaults, "BIGUS (defaults)", rows.back(), error))
    {
      ok = Failed("block hold-out: " + *error, error);
      break;
    }
    const std::string title = std::to_string(size) + " consecutive frames held out (frames " +
      std::to_string(liver.HeldOut.front()) + " to " + std::to_string(liver.HeldOut.back()) + ", " +
      Format("%.1f", gap) + " mm between the bracketing training frames)";
    md << "\n### " << title << "\n\n" << TableHeader();
    nlohmann::json j;
    j["frames"] = liver.HeldOut;
    j["gap_mm"] = gap;
    for (const Row& r : rows)
    {
      Print("block " + std::to_string(size), r);
      md << TableRow(r);
      j["rows"].push_back(ToJson(r));
    }
    report.Json["block_hold_outs"][std::to_string(size)] = j;
  }
  liver.Data.TrainFrames = train;
  liver.HeldOut = heldOut;
  return ok;
}
}
