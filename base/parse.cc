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
