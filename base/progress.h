#pragma once
// Progress of a long stage, as lines for people ("form factors:  40%"). Every stage's Options
// carries one; the command line logs the lines (spdlog), a program may show or drop them. Called
// on the stage's own thread; empty = silent.

#include <functional>
#include <string>

namespace procam {

using ProgressCallback = std::function<void(const std::string& line)>;

// Calls `progress` with `line` when it is set.
inline void Report(const ProgressCallback& progress, const std::string& line) {
  if (progress) progress(line);
}

}  // namespace procam
