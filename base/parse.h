#pragma once
// Values people type into options and files beyond what JSON and the option parser check:
// comma-separated numbers, one or three positive numbers for R, G, B.

#include <Eigen/Core>
#include <cstddef>
#include <string>
#include <vector>

namespace procam {

// Comma-separated finite numbers, e.g. "0.5,-1.4,0.8". `count` > 0 demands exactly that many.
// Throws IoError "OPTION: expected EXPECTED, got 'TEXT'".
std::vector<double> ParseNumberList(const std::string& option, const std::string& text,
                                    const std::string& expected, size_t count = 0);

// One positive number for every channel, or three (R, G, B). Throws IoError naming `option`.
Eigen::Vector3d ParsePositiveRgb(const std::string& option, const std::string& text);

}  // namespace procam
