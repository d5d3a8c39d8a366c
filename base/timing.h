#pragma once
// Wall-clock timing of stages, for their summaries and result.json (never asserted in tests).

#include <algorithm>
#include <chrono>
#include <vector>

namespace procam {

using Clock = std::chrono::steady_clock;

// Seconds from `start` to now.
inline double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Milliseconds from `start` to now.
inline double MsSince(Clock::time_point start) { return 1e3 * SecondsSince(start); }

// The median of timings (the upper one of an even count); 0 for none.
inline double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

}  // namespace procam
