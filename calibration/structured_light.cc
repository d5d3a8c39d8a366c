#include "calibration/structured_light.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace procam {
namespace {

constexpr double kPi = 3.14159265358979323846;

bool IsPowerOfTwo(int value) { return value > 0 && (value & (value - 1)) == 0; }

int Log2(int power_of_two) {
  int bits = 0;
  while ((1 << bits) < power_of_two) ++bits;
  return bits;
}

std::string Name(const char* axis, const char* what, int index, bool inverse) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "sl_%s_%s%02d%s", axis, what, index, inverse ? "_inv" : "");
  return buffer;
}

// The shown value (0 or 1) of Gray plane `bit` at coordinate u.
int ShownBit(const StructuredLightOptions& options, int u, int bit) {
  const int gray = u ^ (u >> 1);
  const int finest = StructuredLightFinestBit(options);
  int value = (gray >> bit) & 1;
  if (options.xor_codes && bit > finest) value ^= (gray >> finest) & 1;
  return value;
}

uint8_t SinusoidValue(const StructuredLightOptions& options, int u, int step) {
  const double phase = 2.0 * kPi * u / options.phase_period - 2.0 * kPi * step / options.phase_steps;
  const double light = 0.5 + 0.5 * std::cos(phase);
  return static_cast<uint8_t>(std::lround(255.0 * std::pow(light, 1.0 / options.pattern_gamma)));
}

// A grey pattern, CV_8UC3, from a value per coordinate along `axis_is_column`.
cv::Mat AxisPattern(int width, int height, bool axis_is_column, const std::vector<uint8_t>& value) {
  cv::Mat image(height, width, CV_8UC3);
  for (int row = 0; row < height; ++row) {
    cv::Vec3b* out = image.ptr<cv::Vec3b>(row);
    for (int col = 0; col < width; ++col) {
      const uint8_t v = value[axis_is_column ? col : row];
      out[col] = cv::Vec3b(v, v, v);
    }
  }
  return image;
}

cv::Mat ToGrey(const cv::Mat& image) {
  cv::Mat grey;
  if (image.channels() == 3) {
    cv::Mat f;
    image.convertTo(f, CV_32F);
    cv::transform(f, grey, cv::Matx13f(1.0f / 3, 1.0f / 3, 1.0f / 3));
  } else if (image.channels() == 1) {
    image.convertTo(grey, CV_32F);
  } else {
    throw std::invalid_argument("structured light: images must have one or three channels, got " +
                                std::to_string(image.channels()));
  }
  return grey;
}

struct AxisLayout {
  bool is_column = true;
  int size = 0;
  int bits = 0;         // Gray bits of the full code
  int finest = 0;       // finest shown bit
  int first_index = 0;  // index of the most significant plane in the sequence
  int phase_index = 0;  // index of the first sinusoid
};

std::vector<AxisLayout> Layout(const StructuredLightOptions& options) {
  std::vector<AxisLayout> axes;
  int index = 2;  // after white and black
  for (int a = 0; a < 2; ++a) {
    const bool is_column = a == 0;
    if (is_column ? !options.columns : !options.rows) continue;
    AxisLayout axis;
    axis.is_column = is_column;
    axis.size = is_column ? options.width : options.height;
    axis.bits = GrayCodeBits(axis.size);
    axis.finest = StructuredLightFinestBit(options);
    axis.first_index = index;
    index += 2 * (axis.bits - axis.finest);
    axis.phase_index = index;
    if (options.phase_period > 0) index += options.phase_steps;
    axes.push_back(axis);
  }
  return axes;
}

}  // namespace

bool StructuredLightOptions::Check(std::string* why) const {
  auto fail = [&](const std::string& message) {
    if (why) *why = message;
    return false;
  };
  if (width < 4 || width > 16384 || height < 4 || height > 16384)
    return fail("projector size must be in [4, 16384], got " + std::to_string(width) + "x" +
                std::to_string(height));
  if (!columns && !rows) return fail("encode columns, rows or both");
  if (phase_period != 0) {
    if (!IsPowerOfTwo(phase_period) || phase_period < 4 || phase_period > 1024)
      return fail("phase_period must be 0 or a power of two in [4, 1024], got " +
                  std::to_string(phase_period));
    if ((columns && phase_period > width) || (rows && phase_period > height))
      return fail("phase_period " + std::to_string(phase_period) +
                  " is larger than an encoded projector side");
    if (phase_steps < 3 || phase_steps > 64)
      return fail("phase_steps must be in [3, 64], got " + std::to_string(phase_steps));
  }
  if (!(pattern_gamma > 0.0 && pattern_gamma <= 10.0))
    return fail("pattern_gamma must be in (0, 10], got " + std::to_string(pattern_gamma));
  return true;
}

bool StructuredLightDecodeOptions::Check(std::string* why) const {
  auto in_unit = [](double x) { return x >= 0.0 && x < 1.0; };
  if (!in_unit(min_contrast) || !in_unit(min_bit_contrast) || !in_unit(min_modulation)) {
    if (why) *why = "min_contrast, min_bit_contrast and min_modulation must be in [0, 1)";
    return false;
  }
  return true;
}

const char* BinarizationName(Binarization binarization) {
  switch (binarization) {
    case Binarization::kGlobalThreshold:
      return "global threshold";
    case Binarization::kPixelThreshold:
      return "per-pixel threshold";
    case Binarization::kComplementary:
      return "complementary";
  }
  return "?";
}

int StructuredLightFinestBit(const StructuredLightOptions& options) {
  return options.phase_period > 0 ? Log2(options.phase_period) - 2 : 0;
}

CaptureSequence MakeStructuredLightSequence(const StructuredLightOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("structured light: " + why);
  CaptureSequence sequence;
  sequence.kind = "structured_light";
  sequence.parameters = {{"width", options.width},
                         {"height", options.height},
                         {"columns", options.columns},
                         {"rows", options.rows},
                         {"phase_period", options.phase_period},
                         {"phase_steps", options.phase_steps},
                         {"xor_codes", options.xor_codes},
                         {"pattern_gamma", options.pattern_gamma}};
  const int width = options.width, height = options.height;
  sequence.patterns.push_back(
      {"white", cv::Mat(height, width, CV_8UC3, cv::Scalar::all(255)), {{"kind", "white"}}});
  sequence.patterns.push_back(
      {"black", cv::Mat(height, width, CV_8UC3, cv::Scalar::all(0)), {{"kind", "black"}}});
  for (const AxisLayout& axis : Layout(options)) {
    const char* axis_name = axis.is_column ? "col" : "row";
    std::vector<uint8_t> value(axis.size);
    for (int bit = axis.bits - 1; bit >= axis.finest; --bit) {
      for (int inverse = 0; inverse < 2; ++inverse) {
        for (int u = 0; u < axis.size; ++u)
          value[u] = (ShownBit(options, u, bit) ^ inverse) ? 255 : 0;
        sequence.patterns.push_back(
            {Name(axis_name, "b", bit, inverse), AxisPattern(width, height, axis.is_column, value),
             {{"kind", "graycode"},
              {"axis", axis.is_column ? "column" : "row"},
              {"bit", bit},
              {"inverse", inverse == 1},
              {"xor", options.xor_codes && bit > axis.finest}}});
      }
    }
    if (options.phase_period == 0) continue;
    for (int step = 0; step < options.phase_steps; ++step) {
      for (int u = 0; u < axis.size; ++u) value[u] = SinusoidValue(options, u, step);
      sequence.patterns.push_back({Name(axis_name, "phase", step, false),
                                   AxisPattern(width, height, axis.is_column, value),
                                   {{"kind", "phase"},
                                    {"axis", axis.is_column ? "column" : "row"},
                                    {"step", step},
                                    {"period", options.phase_period}}});
    }
  }
  return sequence;
}

StructuredLightMap DecodeStructuredLight(const StructuredLightOptions& options,
                                         const std::vector<cv::Mat>& captured,
                                         const StructuredLightDecodeOptions& decode_options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("structured light: " + why);
  if (!decode_options.Check(&why)) throw std::invalid_argument("structured light decode: " + why);
  const std::vector<AxisLayout> axes = Layout(options);
  const AxisLayout& last = axes.back();
  const size_t expected =
      last.phase_index + (options.phase_period > 0 ? options.phase_steps : 0);
  if (captured.size() != expected) {
    throw std::invalid_argument("structured light: " + std::to_string(captured.size()) +
                                " images for a sequence of " + std::to_string(expected));
  }
  const cv::Size size = captured[0].size();
  std::vector<cv::Mat> grey(captured.size());
  for (size_t i = 0; i < captured.size(); ++i) {
    if (captured[i].size() != size)
      throw std::invalid_argument("structured light: image " + std::to_string(i) +
                                  " differs in size from image 0");
    grey[i] = ToGrey(captured[i]);
  }
  const cv::Mat& white = grey[0];
  const cv::Mat& black = grey[1];
  const cv::Mat range = white - black;

  // Shadow test against a robust maximum of the contrast.
  std::vector<float> ranges(range.begin<float>(), range.end<float>());
  const size_t percentile = std::min(ranges.size() - 1, ranges.size() * 99 / 100);
  std::nth_element(ranges.begin(), ranges.begin() + percentile, ranges.end());
  const float contrast_floor =
      static_cast<float>(decode_options.min_contrast) * std::max(ranges[percentile], 0.0f);
  cv::Mat lit = (range > contrast_floor) & (range > 0.0f);

  double global_threshold = 0.0;
  if (decode_options.binarization == Binarization::kGlobalThreshold) {
    cv::Mat midpoint = 0.5 * (white + black);
    global_threshold = cv::mean(midpoint, lit)[0];
  }

  StructuredLightMap map;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  map.column = cv::Mat(size, CV_32FC1, cv::Scalar(nan));
  map.row = cv::Mat(size, CV_32FC1, cv::Scalar(nan));
  map.mask = cv::Mat(size, CV_8UC1, cv::Scalar(0));
  const bool phase = options.phase_period > 0;
  const int steps = options.phase_steps;
  std::vector<double> cosines(steps), sines(steps);
  for (int k = 0; k < steps; ++k) {
    cosines[k] = std::cos(2.0 * kPi * k / steps);
    sines[k] = std::sin(2.0 * kPi * k / steps);
  }
  const float bit_fraction = static_cast<float>(decode_options.min_bit_contrast);

  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      if (!lit.at<uint8_t>(y, x)) {
        ++map.shadowed;
        continue;
      }
      const float pixel_range = range.at<float>(y, x);
      const float threshold =
          decode_options.binarization == Binarization::kPixelThreshold
              ? 0.5f * (white.at<float>(y, x) + black.at<float>(y, x))
              : static_cast<float>(global_threshold);
      // Each axis decodes on its own (a grazed surface may crowd many projector columns into a
      // pixel and still resolve the rows); a pixel's first failing test is counted once.
      bool counted = false, all = true;
      const auto refuse = [&](long long* counter) {
        all = false;
        if (!counted) ++*counter;
        counted = true;
      };
      for (const AxisLayout& axis : axes) {
        // Shown bits, most significant first.
        int shown[32] = {0};
        bool ok = true;
        for (int bit = axis.bits - 1; bit >= axis.finest && ok; --bit) {
          const int index = axis.first_index + 2 * (axis.bits - 1 - bit);
          const float value = grey[index].at<float>(y, x);
          float difference;
          if (decode_options.binarization == Binarization::kComplementary) {
            difference = value - grey[index + 1].at<float>(y, x);
          } else {
            difference = 2.0f * (value - threshold);
          }
          ok = std::abs(difference) >= bit_fraction * pixel_range;
          shown[bit] = difference > 0.0f;
        }
        if (!ok) {
          refuse(&map.ambiguous);
          continue;
        }
        // Undo the XOR, then Gray → binary on the code truncated to the shown bits.
        int binary = 0, previous = 0;
        for (int bit = axis.bits - 1; bit >= axis.finest; --bit) {
          int gray = shown[bit];
          if (options.xor_codes && bit > axis.finest) gray ^= shown[axis.finest];
          previous ^= gray;
          binary |= previous << (bit - axis.finest);
        }
        double u;
        if (!phase) {
          u = binary;
        } else {
          double c = 0.0, s = 0.0;
          for (int k = 0; k < steps; ++k) {
            const float value = grey[axis.phase_index + k].at<float>(y, x);
            c += value * cosines[k];
            s += value * sines[k];
          }
          const double amplitude = 2.0 / steps * std::hypot(c, s);
          if (amplitude < decode_options.min_modulation * 0.5 * pixel_range) {
            refuse(&map.weak_phase);
            continue;
          }
          const double period = options.phase_period;
          double within = std::atan2(s, c) / (2.0 * kPi) * period;  // position within a period
          if (within < 0.0) within += period;
          const int step = 1 << axis.finest;
          const double coarse = binary * step + 0.5 * (step - 1);  // centre of the Gray cell
          u = within + period * std::round((coarse - within) / period);
        }
        if (u < -0.5 || u >= axis.size - 0.5) {
          refuse(&map.out_of_range);
          continue;
        }
        (axis.is_column ? map.column : map.row).at<float>(y, x) = static_cast<float>(u);
      }
      if (!all) continue;
      map.mask.at<uint8_t>(y, x) = 255;
    }
  }
  return map;
}

}  // namespace procam
