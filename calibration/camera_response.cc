#include "calibration/camera_response.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include <opencv2/photo.hpp>

#include "base/check.h"
#include "base/io.h"

namespace procam {
namespace {

// About `count` pixels spread evenly over the codes of the middle exposure's green channel
// (strata of 8 codes, pixels within a stratum taken at an even stride).
std::vector<cv::Point> SpreadSamples(const std::vector<cv::Mat>& images, int count) {
  const cv::Mat& middle = images[images.size() / 2];
  constexpr int kStrata = 32;
  std::vector<std::vector<cv::Point>> strata(kStrata);
  for (int y = 0; y < middle.rows; ++y) {
    for (int x = 0; x < middle.cols; ++x) {
      strata[middle.at<cv::Vec3b>(y, x)[1] * kStrata / 256].push_back(cv::Point(x, y));
    }
  }
  int filled = 0;
  for (const auto& stratum : strata) filled += stratum.empty() ? 0 : 1;
  const size_t per_stratum = static_cast<size_t>(std::max(1, count / std::max(1, filled)));
  std::vector<cv::Point> picked;
  for (const auto& stratum : strata) {
    const size_t take = std::min(per_stratum, stratum.size());
    for (size_t k = 0; k < take; ++k) picked.push_back(stratum[k * stratum.size() / take]);
  }
  return picked;
}

}  // namespace

bool CameraResponseOptions::Check(std::string* why) const {
  if (samples < 10) return Fail(why, "samples must be >= 10");
  if (!(lambda > 0)) return Fail(why, "lambda must be > 0");
  if (!(min_code > 0 && min_code < max_code && max_code < 1))
    return Fail(why, "trusted codes must satisfy 0 < min_code < max_code < 1");
  return true;
}

bool CalibrateCameraResponse(const std::vector<cv::Mat>& images,
                             const std::vector<double>& exposures_us,
                             const CameraResponseOptions& options, CameraResponse* response,
                             std::string* why) {
  if (!options.Check(why)) return false;
  if (images.size() != exposures_us.size())
    return Fail(why, "need one image per exposure");
  if (images.size() < 3) return Fail(why, "need at least 3 exposures, got " +
                                          std::to_string(images.size()));
  std::set<double> distinct;
  for (size_t i = 0; i < images.size(); ++i) {
    if (images[i].type() != CV_8UC3) return Fail(why, "images must be 8-bit colour (CV_8UC3)");
    if (images[i].size() != images[0].size()) return Fail(why, "images differ in size");
    if (!(exposures_us[i] > 0)) return Fail(why, "exposures must be > 0");
    distinct.insert(exposures_us[i]);
  }
  if (distinct.size() != images.size()) return Fail(why, "exposures must all differ");

  std::vector<float> seconds;
  for (double us : exposures_us) seconds.push_back(static_cast<float>(us * 1e-6));
  cv::Mat curve;  // 256×1 CV_32FC3: g(z) per channel (B, G, R), arbitrary scale
  // Pixels whose codes cover the range (Debevec & Malik's advice; a regular grid over a room
  // photo samples mostly dark wall and leaves the top codes to the smoothness term), packed
  // into a k×k image per exposure so that OpenCV's regular sampling takes every one of them.
  const std::vector<cv::Point> picked = SpreadSamples(images, options.samples);
  const int side = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(picked.size()))));
  std::vector<cv::Mat> packed;
  for (const cv::Mat& image : images) {
    cv::Mat tile(side, side, CV_8UC3);
    for (int k = 0; k < side * side; ++k) {
      tile.at<cv::Vec3b>(k / side, k % side) = image.at<cv::Vec3b>(picked[k % picked.size()]);
    }
    packed.push_back(tile);
  }
  cv::createCalibrateDebevec(side * side, static_cast<float>(options.lambda), false)
      ->process(packed, curve, seconds);
  if (curve.rows != 256 || curve.type() != CV_32FC3) return Fail(why, "Debevec fit failed");

  response->inverse.assign(3, std::vector<double>(256, 0.0));
  response->pixels = images[0].rows * images[0].cols;
  for (int c = 0; c < 3; ++c) {
    const int channel = 2 - c;  // R, G, B out of B, G, R
    // Power law over the trusted codes: ln g = a + γ ln(z/255), least squares.
    double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (int z = 1; z < 256; ++z) {
      const double code = z / 255.0;
      if (code < options.min_code || code > options.max_code) continue;
      const double g = curve.at<cv::Vec3f>(z)[channel];
      if (!(g > 0)) return Fail(why, "Debevec fit gave a non-positive response");
      const double x = std::log(code), y = std::log(g);
      n += 1, sx += x, sy += y, sxx += x * x, sxy += x * y;
    }
    const double gamma = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    const double offset = (sy - gamma * sx) / n;
    if (!std::isfinite(gamma) || !(gamma > 0)) return Fail(why, "the response is not increasing");
    double squares = 0;
    for (int z = 1; z < 256; ++z) {
      const double code = z / 255.0;
      if (code < options.min_code || code > options.max_code) continue;
      const double residual =
          std::log(curve.at<cv::Vec3f>(z)[channel]) - (offset + gamma * std::log(code));
      squares += residual * residual;
    }
    response->gamma[c] = gamma;
    response->gamma_rms[c] = std::sqrt(squares / n);
    // Normalised table: g / e^offset, 0 at code 0, non-decreasing.
    std::vector<double>& table = response->inverse[c];
    const int top = static_cast<int>(std::floor(options.max_code * 255.0));
    for (int z = 1; z <= top; ++z) {
      table[z] = std::max(table[z - 1], curve.at<cv::Vec3f>(z)[channel] / std::exp(offset));
    }
    for (int z = top + 1; z < 256; ++z) {  // past the trusted codes: the power law, continued
      table[z] = std::max(table[z - 1], table[top] * std::pow(z / static_cast<double>(top), gamma));
    }
  }
  return true;
}

nlohmann::json CameraResponseJson(const CameraResponse& response) {
  return {{"format", "procam camera response"},
          {"codes", 256},
          {"gamma", {response.gamma[0], response.gamma[1], response.gamma[2]}},
          {"gamma_rms", {response.gamma_rms[0], response.gamma_rms[1], response.gamma_rms[2]}},
          {"inverse",
           {{"r", response.inverse[0]}, {"g", response.inverse[1]}, {"b", response.inverse[2]}}}};
}

std::vector<std::vector<double>> ReadInverseResponse(const std::filesystem::path& path,
                                                     int channels) {
  std::ifstream in(path);
  if (!in) throw IoError(path.string() + ": cannot open the camera response");
  std::stringstream text;
  text << in.rdbuf();
  const nlohmann::json file = nlohmann::json::parse(text.str(), nullptr, false);
  if (file.is_discarded() || !file.is_object()) throw IoError(path.string() + ": not a JSON object");
  if (!file.contains("inverse") || !file["inverse"].is_object())
    throw IoError(path.string() + ": inverse: missing (expected {\"r\", \"g\", \"b\"} tables)");
  const auto table = [&](const char* key) {
    const nlohmann::json& entry = file["inverse"].value(key, nlohmann::json());
    std::vector<double> values;
    if (entry.is_array()) {
      for (const nlohmann::json& value : entry) {
        if (!value.is_number()) break;
        values.push_back(value.get<double>());
      }
    }
    bool increasing = values.size() >= 2 && values.size() == entry.size();
    for (size_t k = 1; increasing && k < values.size(); ++k) increasing = values[k] >= values[k - 1];
    if (!increasing) {
      throw IoError(path.string() + ": inverse." + key +
                    ": expected at least 2 non-decreasing numbers");
    }
    return values;
  };
  if (channels == 1) return {table("g")};
  return {table("b"), table("g"), table("r")};
}

}  // namespace procam
