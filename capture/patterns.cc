#include "capture/patterns.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <stdexcept>

#include "base/check.h"
#include "base/image_io.h"
#include "base/io.h"

namespace procam {
namespace {

void CheckOrThrow(bool ok, const std::string& what, const std::string& why) {
  if (!ok) throw std::invalid_argument(what + ": " + why);
}

std::string Padded(int value, int digits) {
  char text[16];
  std::snprintf(text, sizeof(text), "%0*d", digits, value);
  return text;
}

// Bit `bit` of the Gray code of every coordinate along one axis, as 0/255.
cv::Mat GrayPlane(int width, int height, bool along_columns, int bit, bool inverse) {
  cv::Mat plane(height, width, CV_8UC3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const int coordinate = along_columns ? x : y;
      const int gray = coordinate ^ (coordinate >> 1);
      const bool on = ((gray >> bit) & 1) != inverse;
      const uint8_t value = on ? 255 : 0;
      plane.at<cv::Vec3b>(y, x) = cv::Vec3b(value, value, value);
    }
  }
  return plane;
}

cv::Mat AsGreyFloat(const cv::Mat& image) {
  cv::Mat grey;
  if (image.channels() == 3) {
    cv::transform(image, grey, cv::Matx13f(1.0f / 3, 1.0f / 3, 1.0f / 3));
  } else if (image.channels() == 1) {
    grey = image;
  } else {
    throw std::invalid_argument("DecodeGrayCode: images must have one or three channels");
  }
  grey.convertTo(grey, CV_32F);
  return grey;
}

}  // namespace

bool GrayCodeOptions::Check(std::string* why) const {
  if (width < 2 || width > 16384 || height < 2 || height > 16384)
    return Fail(why, "projector size must be in [2, 16384]");
  if (!columns && !rows) return Fail(why, "encode at least one of columns and rows");
  return true;
}

int GrayCodeBits(int size) {
  int bits = 0;
  while ((1 << bits) < size) ++bits;
  return bits;
}

CaptureSequence MakeGrayCodeSequence(const GrayCodeOptions& options) {
  std::string why;
  CheckOrThrow(options.Check(&why), "GrayCodeOptions", why);
  CaptureSequence sequence;
  sequence.kind = "graycode";
  sequence.parameters = {{"width", options.width},
                         {"height", options.height},
                         {"columns", options.columns},
                         {"rows", options.rows},
                         {"code", "reflected binary, plane and inverse, MSB first"}};
  sequence.patterns.push_back(
      {"white",
       cv::Mat(options.height, options.width, CV_8UC3, cv::Scalar::all(255)),
       {{"kind", "white"}}});
  sequence.patterns.push_back(
      {"black", cv::Mat::zeros(options.height, options.width, CV_8UC3), {{"kind", "black"}}});
  for (const bool along_columns : {true, false}) {
    if (along_columns ? !options.columns : !options.rows) continue;
    const int bits = GrayCodeBits(along_columns ? options.width : options.height);
    for (int bit = bits - 1; bit >= 0; --bit) {
      for (const bool inverse : {false, true}) {
        Pattern pattern;
        pattern.name = std::string(along_columns ? "gray_col_b" : "gray_row_b") + Padded(bit, 2) +
                       (inverse ? "_inv" : "");
        pattern.image = GrayPlane(options.width, options.height, along_columns, bit, inverse);
        pattern.info = {{"kind", "graycode"},
                        {"axis", along_columns ? "column" : "row"},
                        {"bit", bit},
                        {"inverse", inverse}};
        sequence.patterns.push_back(std::move(pattern));
      }
    }
  }
  return sequence;
}

bool GrayCodeDecodeOptions::Check(std::string* why) const {
  if (!(min_contrast >= 0 && min_contrast < 1)) return Fail(why, "min_contrast must be in [0, 1)");
  if (!(min_bit_contrast >= 0 && min_bit_contrast < 1))
    return Fail(why, "min_bit_contrast must be in [0, 1)");
  return true;
}

GrayCodeMap DecodeGrayCode(const GrayCodeOptions& options, const std::vector<cv::Mat>& captured,
                           const GrayCodeDecodeOptions& decode_options) {
  std::string why;
  CheckOrThrow(options.Check(&why), "GrayCodeOptions", why);
  CheckOrThrow(decode_options.Check(&why), "GrayCodeDecodeOptions", why);
  const int column_bits = options.columns ? GrayCodeBits(options.width) : 0;
  const int row_bits = options.rows ? GrayCodeBits(options.height) : 0;
  const size_t expected = 2 + 2 * static_cast<size_t>(column_bits + row_bits);
  if (captured.size() != expected) {
    throw std::invalid_argument("DecodeGrayCode: expected " + std::to_string(expected) +
                                " images, got " + std::to_string(captured.size()));
  }
  const cv::Size size = captured[0].size();
  for (const cv::Mat& image : captured) {
    if (image.size() != size) throw std::invalid_argument("DecodeGrayCode: images differ in size");
  }
  const cv::Mat white = AsGreyFloat(captured[0]);
  const cv::Mat black = AsGreyFloat(captured[1]);
  const cv::Mat contrast = white - black;
  double max_contrast = 0.0;
  cv::minMaxLoc(contrast, nullptr, &max_contrast);
  const float lit_threshold = static_cast<float>(decode_options.min_contrast * max_contrast);

  GrayCodeMap map;
  map.column = cv::Mat(size, CV_32SC1, cv::Scalar(-1));
  map.row = cv::Mat(size, CV_32SC1, cv::Scalar(-1));
  size_t next = 2;
  for (const bool along_columns : {true, false}) {
    const int bits = along_columns ? column_bits : row_bits;
    if (bits == 0) continue;
    const int limit = along_columns ? options.width : options.height;
    cv::Mat gray(size, CV_32SC1, cv::Scalar(0));
    cv::Mat valid(size, CV_8UC1, cv::Scalar(1));
    for (int bit = bits - 1; bit >= 0; --bit) {
      const cv::Mat plane = AsGreyFloat(captured[next]);
      const cv::Mat inverse = AsGreyFloat(captured[next + 1]);
      next += 2;
      for (int y = 0; y < size.height; ++y) {
        for (int x = 0; x < size.width; ++x) {
          const float lit = contrast.at<float>(y, x);
          const float difference = plane.at<float>(y, x) - inverse.at<float>(y, x);
          if (lit <= lit_threshold ||
              std::abs(difference) <= decode_options.min_bit_contrast * lit) {
            valid.at<uint8_t>(y, x) = 0;
          }
          if (difference > 0) gray.at<int32_t>(y, x) |= 1 << bit;
        }
      }
    }
    cv::Mat& out = along_columns ? map.column : map.row;
    for (int y = 0; y < size.height; ++y) {
      for (int x = 0; x < size.width; ++x) {
        if (!valid.at<uint8_t>(y, x)) continue;
        int value = gray.at<int32_t>(y, x);  // Gray → binary: xor of all higher shifts
        for (int shift = value >> 1; shift != 0; shift >>= 1) value ^= shift;
        if (value < limit) out.at<int32_t>(y, x) = value;
      }
    }
  }
  return map;
}

bool PhotometricOptions::Check(std::string* why) const {
  if (width < 1 || width > 16384 || height < 1 || height > 16384)
    return Fail(why, "projector size must be in [1, 16384]");
  if (levels.empty()) return Fail(why, "give at least one level");
  for (int level : levels) {
    if (level < 0 || level > 255)
      return Fail(why, "levels must be in [0, 255], got " + std::to_string(level));
  }
  if (std::set<int>(levels.begin(), levels.end()).size() != levels.size())
    return Fail(why, "levels repeat");
  if (channels.empty()) return Fail(why, "give at least one channel");
  if (std::set<char>(channels.begin(), channels.end()).size() != channels.size())
    return Fail(why, "channels repeat");
  for (char channel : channels) {
    if (channel != 'r' && channel != 'g' && channel != 'b' && channel != 'w') {
      return Fail(why, std::string("channels are r, g, b, w; got '") + channel + "'");
    }
  }
  return true;
}

CaptureSequence MakePhotometricSequence(const PhotometricOptions& options) {
  std::string why;
  CheckOrThrow(options.Check(&why), "PhotometricOptions", why);
  CaptureSequence sequence;
  sequence.kind = "photometric";
  sequence.parameters = {{"width", options.width},
                         {"height", options.height},
                         {"levels", options.levels},
                         {"channels", options.channels}};
  sequence.patterns.push_back({"black",
                               cv::Mat::zeros(options.height, options.width, CV_8UC3),
                               {{"kind", "flat"}, {"channel", "w"}, {"level", 0}}});
  for (char channel : options.channels) {
    for (int level : options.levels) {
      if (level == 0) continue;
      cv::Scalar colour(0, 0, 0);
      if (channel == 'b' || channel == 'w') colour[0] = level;
      if (channel == 'g' || channel == 'w') colour[1] = level;
      if (channel == 'r' || channel == 'w') colour[2] = level;
      sequence.patterns.push_back(
          {std::string("flat_") + channel + "_" + Padded(level, 3),
           cv::Mat(options.height, options.width, CV_8UC3, colour),
           {{"kind", "flat"}, {"channel", std::string(1, channel)}, {"level", level}}});
    }
  }
  return sequence;
}

CaptureSequence MakeVerifySequence(const std::vector<std::filesystem::path>& images,
                                   cv::Size projector_size) {
  if (images.empty()) throw IoError("verify sequence: give at least one image");
  CaptureSequence sequence;
  sequence.kind = "verify";
  nlohmann::json files = nlohmann::json::array();
  for (size_t i = 0; i < images.size(); ++i) {
    const std::filesystem::path& path = images[i];
    cv::Mat image = ReadImage(path, cv::IMREAD_COLOR);
    if (image.size() != projector_size) {
      throw IoError(path.string() + ": image is " + std::to_string(image.cols) + "x" +
                    std::to_string(image.rows) + ", the projector is " +
                    std::to_string(projector_size.width) + "x" +
                    std::to_string(projector_size.height));
    }
    std::string stem = path.stem().string();
    for (char& c : stem) {
      if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
    }
    const std::string name = "image_" + Padded(static_cast<int>(i), 3) + "_" + stem;
    files.push_back(std::filesystem::absolute(path).string());
    sequence.patterns.push_back(
        {name, image, {{"kind", "image"}, {"source", std::filesystem::absolute(path).string()}}});
  }
  sequence.parameters = {
      {"width", projector_size.width}, {"height", projector_size.height}, {"images", files}};
  return sequence;
}

std::string PatternChecksum(const cv::Mat& image) {
  uint64_t hash = 1469598103934665603ull;
  auto mix = [&hash](uint8_t byte) {
    hash ^= byte;
    hash *= 1099511628211ull;
  };
  for (int shift = 0; shift < 32; shift += 8) {
    mix(static_cast<uint8_t>(image.cols >> shift));
    mix(static_cast<uint8_t>(image.rows >> shift));
    mix(static_cast<uint8_t>(image.type() >> shift));
  }
  const size_t row_bytes = static_cast<size_t>(image.cols) * image.elemSize();
  for (int y = 0; y < image.rows; ++y) {
    const uint8_t* row = image.ptr<uint8_t>(y);
    for (size_t i = 0; i < row_bytes; ++i) mix(row[i]);
  }
  char text[17];
  std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(hash));
  return text;
}

}  // namespace procam
