#pragma once
// The GPU tests' guard: without a usable CUDA device (CI, this machine) a test skips with
// "no CUDA device: skipped (why)" instead of failing.
#include <string>

#include <gtest/gtest.h>

#include "compensation/solver.h"

#define SKIP_WITHOUT_CUDA_DEVICE()                                                      \
  do {                                                                                  \
    std::string why;                                                                    \
    if (!::procam::CudaAvailable(&why)) GTEST_SKIP() << "no CUDA device: skipped (" << why << ")"; \
  } while (0)
