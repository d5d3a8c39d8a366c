#pragma once
// What the GPU tests share: their guard (without a usable CUDA device, as on CI and this machine,
// a test skips with "no CUDA device: skipped (why)" instead of failing), and the benchmarks'
// sizes from the environment.
#include <cstdlib>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include <gtest/gtest.h>

#include "compensation/solver.h"

#define SKIP_WITHOUT_CUDA_DEVICE()                                                      \
  do {                                                                                  \
    std::string why;                                                                    \
    if (!::procam::CudaAvailable(&why)) GTEST_SKIP() << "no CUDA device: skipped (" << why << ")"; \
  } while (0)

namespace procam::testing {

// The comma-separated numbers of environment variable `name` (PROCAM_BENCH_GRIDS=22,70), or
// `fallback` where it is not set.
template <typename T>
std::vector<T> ListFromEnvironment(const char* name, std::vector<T> fallback) {
  const char* text = std::getenv(name);
  if (text == nullptr) return fallback;
  std::vector<T> values;
  std::stringstream stream(text);
  for (std::string item; std::getline(stream, item, ',');) {
    if constexpr (std::is_integral_v<T>) {
      values.push_back(static_cast<T>(std::stol(item)));
    } else {
      values.push_back(static_cast<T>(std::stod(item)));
    }
  }
  return values;
}

}  // namespace procam::testing
