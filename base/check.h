#pragma once
// How `Options::Check(std::string* why)` and the other checks that answer with a reason say no:
//   if (!(fps > 0)) return Fail(why, "fps must be > 0, got " + std::to_string(fps));

#include <string>

namespace procam {

// Sets *why to `message` (when `why` is given) and returns false.
inline bool Fail(std::string* why, const std::string& message) {
  if (why != nullptr) *why = message;
  return false;
}

}  // namespace procam
