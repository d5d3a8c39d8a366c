#pragma once
// Values people type into options and files beyond what JSON and the option parser check:
// comma-separated numbers, one or three positive numbers for R, G, B.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace procam {

// Comma-separated finite numbers, e.g. "0.5,-1.4,0.8". `count` > 0 demands exactly that many.
// Throws IoError "OPTION: expected EXPECTED, got 'TEXT'".
std::vector<double> ParseNumberList(const std::string& option, const std::string& text,
                                    const std::string& expected, size_t count = 0);

// Comma-separated whole numbers, e.g. "0,128,255" (at least one; "" is refused). Throws IoError
// "OPTION: expected EXPECTED, got 'TEXT'".
std::vector<int> ParseIntegerList(const std::string& option, const std::string& text,
                                  const std::string& expected);

// Two whole numbers WIDTHxHEIGHT (e.g. "1920x1080", "9x6"), each in [least, most]. Throws
// IoError "OPTION: expected EXPECTED, each in [LEAST, MOST], got 'TEXT'".
std::array<int, 2> ParseSize(const std::string& option, const std::string& text,
                             const std::string& expected, int least, int most);

// One positive number for every channel, or three (R, G, B). Throws IoError naming `option`.
Eigen::Vector3d ParsePositiveRgb(const std::string& option, const std::string& text);

}  // namespace procam
