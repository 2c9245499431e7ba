// BenchmarkRenderer: the machine's peak for phase 2's arithmetic of the CPU renderer (bigusRendererPeak.cxx),
// the yardstick of its "fraction of the peak" columns.
#ifndef bigusRendererPeak_h
#define bigusRendererPeak_h

#include <algorithm>
#include <chrono>

namespace bigus::rendererbenchmark
{
/// Seconds on the steady clock (the differences are wall-clock times).
inline double Now()
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Evaluations per second of phase 2's inner loop on every core, per ISA (0: not measured, the CPU lacks it).
struct Peak
{
  double Baseline = 0, Avx2 = 0, Avx512 = 0;
  double Best() const { return std::max(this->Baseline, std::max(this->Avx2, this->Avx512)); }
  /// Peak for the clone that the library's dispatch picks here (x86-64-v3 when the CPU has it).
  double Library() const { return this->Avx2 > 0 ? this->Avx2 : this->Baseline; }
  const char* BestName() const
  {
    return this->Best() == this->Avx512 ? "x86-64-v4, AVX-512"
                                        : (this->Best() == this->Avx2 ? "x86-64-v3, AVX2+FMA" : "baseline SSE2");
  }
};

/// The peak, measured on the first call (a second or so per ISA).
Peak& GetPeak();
}

#endif
