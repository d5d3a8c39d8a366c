#pragma once
// Wall-clock timing of stages, for their summaries and result.json (never asserted in tests).

#include <chrono>

namespace procam {

using Clock = std::chrono::steady_clock;

// Seconds from `start` to now.
inline double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace procam
