#include "base/parse.h"

#include <cmath>
#include <sstream>

#include "base/io.h"

namespace procam {

std::vector<double> ParseNumberList(const std::string& option, const std::string& text,
                                    const std::string& expected, size_t count) {
  const IoError error(option + ": expected " + expected + ", got '" + text + "'");
  std::vector<double> values;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    try {
      size_t used = 0;
      values.push_back(std::stod(item, &used));
      if (used != item.size() || !std::isfinite(values.back())) throw error;
    } catch (const std::exception&) {
      throw error;
    }
  }
  if (values.empty() || (count > 0 && values.size() != count)) throw error;
  return values;
}

std::vector<int> ParseIntegerList(const std::string& option, const std::string& text,
                                  const std::string& expected) {
  std::vector<int> integers;
  for (const double value : ParseNumberList(option, text, expected)) {
    if (value != std::floor(value) || std::abs(value) > 1e9) {
      throw IoError(option + ": expected " + expected + ", got '" + text + "'");
    }
    integers.push_back(static_cast<int>(value));
  }
  return integers;
}

std::array<int, 2> ParseSize(const std::string& option, const std::string& text,
                             const std::string& expected, int least, int most) {
  const IoError error(option + ": expected " + expected + ", each in [" + std::to_string(least) +
                      ", " + std::to_string(most) + "], got '" + text + "'");
  const size_t x = text.find('x');
  if (x == std::string::npos) throw error;
  std::array<int, 2> sides{};
  const std::string parts[2] = {text.substr(0, x), text.substr(x + 1)};
  for (int k = 0; k < 2; ++k) {
    const std::string& part = parts[k];
    if (part.empty() || part.size() > 9 ||
        part.find_first_not_of("0123456789") != std::string::npos) {
      throw error;
    }
    sides[k] = std::stoi(part);
    if (sides[k] < least || sides[k] > most) throw error;
  }
  return sides;
}

Eigen::Vector3d ParsePositiveRgb(const std::string& option, const std::string& text) {
  const std::string expected = "one positive number or three (R,G,B)";
  std::vector<double> values = ParseNumberList(option, text, expected);
  if (values.size() == 1) values = {values[0], values[0], values[0]};
  if (values.size() != 3 || !(values[0] > 0 && values[1] > 0 && values[2] > 0)) {
    throw IoError(option + ": expected " + expected + ", got '" + text + "'");
  }
  return {values[0], values[1], values[2]};
}

}  // namespace procam
