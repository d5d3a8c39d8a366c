#include "calibration/structured_light.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <limits>
#include <numbers>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "base/option_table.h"

namespace procam {
namespace {

// At most this many Gray bits too faint to read are tried at both values (faint_bits): blur leaves
// a pixel unclear only in the planes with a stripe edge near it, one or two of a plain Gray code's;
// where more are unclear (every XOR-coded plane beside an edge of the finest plane, a dark pixel)
// no single coordinate is left to find, and each bit doubles the decodes tried.
constexpr int kMaxFaintBits = 4;

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
  const double phase = 2.0 * std::numbers::pi * u / options.phase_period - 2.0 * std::numbers::pi * step / options.phase_steps;
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

// The photos as the decoder reads them, one value per pixel as a float. A camera's own frames
// (one channel, all of one depth: 8- or 16-bit or float) are read where they are: converting 42
// photos of a megapixel to floats cost more than the decoding itself (allocating and touching
// 4 bytes per pixel of each); other images (colour, other depths) are converted to one float
// channel each, colour averaged.
class Photos {
 public:
  explicit Photos(const std::vector<cv::Mat>& captured) : images_(captured) {
    const int depth = captured.empty() ? CV_32F : captured[0].depth();
    const bool direct = (depth == CV_8U || depth == CV_16U || depth == CV_32F) &&
                        std::all_of(captured.begin(), captured.end(), [&](const cv::Mat& image) {
                          return image.channels() == 1 && image.depth() == depth;
                        });
    depth_ = direct ? depth : CV_32F;
    if (!direct) {
      cv::parallel_for_(cv::Range(0, static_cast<int>(captured.size())),
                        [&](const cv::Range& range) {
                          for (int i = range.start; i < range.end; ++i)
                            images_[i] = ToGrey(captured[i]);
                        });
    }
    for (const cv::Mat& image : images_) {
      data_.push_back(image.data);
      step_.push_back(image.step[0]);
    }
  }
  float at(int image, int y, int x) const {
    const uchar* row = data_[image] + static_cast<size_t>(y) * step_[image];
    switch (depth_) {
      case CV_8U:
        return row[x];
      case CV_16U:
        return reinterpret_cast<const uint16_t*>(row)[x];
      default:
        return reinterpret_cast<const float*>(row)[x];
    }
  }
  // One image as CV_32FC1.
  cv::Mat Float(int image) const {
    cv::Mat value;
    images_[image].convertTo(value, CV_32F);
    return value;
  }

 private:
  std::vector<cv::Mat> images_;
  std::vector<const uchar*> data_;
  std::vector<size_t> step_;
  int depth_ = CV_32F;
};

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

void StructuredLightDecodeOptions::Declare(OptionTable* table) {
  const OptionTable::Interval unit = OptionTable::Interval::BelowMax(0.0, 1.0);
  table
      ->Number("min-contrast", &min_contrast, unit, "",
               "shadow test: white - black at least this fraction of its 99th percentile")
      .Number("min-bit-contrast", &min_bit_contrast, unit, "",
              "a bit: |pattern - inverse| at least this fraction of white - black")
      .Number("min-modulation", &min_modulation, unit, "",
              "a phase: amplitude at least this fraction of (white - black)/2")
      .Number("noise-sigmas", &noise_sigmas, 0.0, 100.0, "",
              "every difference at least this many standard deviations of the photos' noise "
              "(estimated from them)")
      .Integer("faint-bits", &faint_bits, 0, kMaxFaintBits, "",
               "Gray bits per axis that may fail the bit test: tried at both values, the pixel "
               "decoded where the phase unwraps the same either way (defocus)");
}

bool StructuredLightDecodeOptions::Check(std::string* why) const {
  auto in_unit = [](double x) { return x >= 0.0 && x < 1.0; };
  if (!in_unit(min_contrast) || !in_unit(min_bit_contrast) || !in_unit(min_modulation)) {
    if (why) *why = "min_contrast, min_bit_contrast and min_modulation must be in [0, 1)";
    return false;
  }
  if (!(noise_sigmas >= 0.0 && noise_sigmas <= 100.0)) {
    if (why) *why = "noise_sigmas must be in [0, 100]";
    return false;
  }
  if (faint_bits < 0 || faint_bits > kMaxFaintBits) {
    if (why) *why = "faint_bits must be in [0, " + std::to_string(kMaxFaintBits) + "]";
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

StructuredLightLayout LayoutOf(const StructuredLightOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("structured light: " + why);
  StructuredLightLayout layout;
  layout.width = options.width;
  layout.height = options.height;
  layout.white = 0;
  layout.black = 1;
  const std::vector<AxisLayout> axes = Layout(options);
  for (const AxisLayout& axis : axes) {
    StructuredLightLayout::Gray gray;
    gray.column = axis.is_column;
    gray.bits = axis.bits;
    gray.finest_bit = axis.finest;
    gray.xor_codes = options.xor_codes;
    for (int bit = axis.bits - 1; bit >= axis.finest; --bit) {
      const int index = axis.first_index + 2 * (axis.bits - 1 - bit);
      gray.images.push_back(index);
      gray.inverse.push_back(index + 1);
    }
    layout.gray.push_back(gray);
    if (options.phase_period == 0) continue;
    StructuredLightLayout::Phase phase;
    phase.column = axis.is_column;
    phase.period = options.phase_period;
    for (int step = 0; step < options.phase_steps; ++step) {
      phase.shifts.push_back(-2.0 * std::numbers::pi * step / options.phase_steps);
      phase.images.push_back(axis.phase_index + step);
    }
    layout.phases.push_back(phase);
  }
  const AxisLayout& last = axes.back();
  layout.image_count = last.phase_index + (options.phase_period > 0 ? options.phase_steps : 0);
  return layout;
}

bool StructuredLightLayout::Check(std::string* why) const {
  auto fail = [&](const std::string& message) {
    if (why) *why = message;
    return false;
  };
  if (width < 2 || width > 16384 || height < 2 || height > 16384)
    return fail("projector size must be in [2, 16384], got " + std::to_string(width) + "x" +
                std::to_string(height));
  if (image_count < 3) return fail("fewer than three images");
  std::vector<int> uses(image_count, 0);
  auto use = [&](int index) {
    if (index < 0 || index >= image_count) return false;
    ++uses[index];
    return true;
  };
  if (!use(white)) return fail("no white image");
  if (!use(black)) return fail("no black image");
  if (gray.empty() && phases.empty()) return fail("neither a Gray code nor phases");
  for (const Gray& code : gray) {
    const int size = code.column ? width : height;
    if (code.cell < 1 || code.cell > size) return fail("Gray cell outside [1, projector size]");
    if (code.bits != GrayCodeBits((size + code.cell - 1) / code.cell))
      return fail("Gray code of " + std::to_string(code.bits) + " bits does not fit " +
                  std::to_string(size) + " pixels in cells of " + std::to_string(code.cell));
    if (code.finest_bit < 0 || code.finest_bit >= code.bits) return fail("finest Gray bit outside the code");
    const size_t shown = static_cast<size_t>(code.bits - code.finest_bit);
    if (code.images.size() != shown || code.inverse.size() != shown)
      return fail("Gray code images do not match its bits");
    for (size_t b = 0; b < shown; ++b) {
      if (!use(code.images[b])) return fail("a Gray bit image index outside the images");
      if (code.inverse[b] != -1 && !use(code.inverse[b]))
        return fail("a Gray inverse image index outside the images");
    }
  }
  for (bool column : {true, false}) {
    if (std::count_if(phases.begin(), phases.end(),
                      [&](const Phase& phase) { return phase.column == column; }) >
        kMaxPhasesPerAxis)
      return fail("more than " + std::to_string(kMaxPhasesPerAxis) + " phase sets on one axis");
  }
  for (const Phase& phase : phases) {
    if (!(phase.period > 1.0 && phase.period <= 65536.0))
      return fail("phase period must be in (1, 65536] projector pixels");
    if (!std::isfinite(phase.origin)) return fail("phase origin must be finite");
    if (phase.direction != 1 && phase.direction != -1) return fail("phase direction must be 1 or -1");
    if (phase.shifts.size() < 3 || phase.images.size() != phase.shifts.size())
      return fail("a phase set needs at least three images, one shift each");
    // The least-squares fit of offset, cosine and sine needs three independent shifts.
    Eigen::MatrixXd design(phase.shifts.size(), 3);
    for (size_t k = 0; k < phase.shifts.size(); ++k) {
      if (!std::isfinite(phase.shifts[k])) return fail("phase shifts must be finite");
      design.row(k) << 1.0, std::cos(phase.shifts[k]), -std::sin(phase.shifts[k]);
    }
    if (Eigen::FullPivLU<Eigen::MatrixXd>(design).rank() < 3)
      return fail("a phase set's shifts must hold three distinct phases");
    for (int index : phase.images)
      if (!use(index)) return fail("a phase image index outside the images");
  }
  for (int i = 0; i < image_count; ++i) {
    if (uses[i] != 1)
      return fail("image " + std::to_string(i) + (uses[i] ? " is used twice" : " is not used"));
  }
  return true;
}

bool StructuredLightLayout::Encodes(bool column) const {
  return std::any_of(gray.begin(), gray.end(), [&](const Gray& g) { return g.column == column; }) ||
         std::any_of(phases.begin(), phases.end(),
                     [&](const Phase& p) { return p.column == column; });
}

const char* DecodeRefusalName(DecodeRefusal refusal) {
  switch (refusal) {
    case DecodeRefusal::kDecoded:
      return "decoded";
    case DecodeRefusal::kShadowed:
      return "shadowed";
    case DecodeRefusal::kAmbiguous:
      return "ambiguous bit";
    case DecodeRefusal::kWeakPhase:
      return "weak phase";
    case DecodeRefusal::kOutOfRange:
      return "out of range";
    case DecodeRefusal::kUnwrap:
      return "not unwrapped";
  }
  return "?";
}

StructuredLightMap DecodeStructuredLight(const StructuredLightOptions& options,
                                         const std::vector<cv::Mat>& captured,
                                         const StructuredLightDecodeOptions& decode_options) {
  return DecodeStructuredLight(LayoutOf(options), captured, decode_options);
}

namespace {

// The median of |x − median x|, scaled to a normal distribution's standard deviation.
double RobustSigma(std::vector<float> values) {
  if (values.empty()) return 0.0;
  const size_t middle = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + middle, values.end());
  const float median = values[middle];
  for (float& v : values) v = std::abs(v - median);
  std::nth_element(values.begin(), values.begin() + middle, values.end());
  return 1.4826 * values[middle];
}

// One standard deviation of one image's noise (see StructuredLightMap::noise_sigma), from every
// fourth pixel of every fourth row that passes the shadow floor.
double EstimateNoise(const StructuredLightLayout& layout, const Photos& photos,
                     const cv::Mat& white, const cv::Mat& black, const cv::Mat& lit) {
  constexpr int kStride = 4;
  std::vector<float> residuals;
  for (const StructuredLightLayout::Gray& code : layout.gray) {
    for (size_t b = 0; b < code.images.size(); ++b) {
      if (code.inverse[b] < 0) continue;
      const int pattern = code.images[b], inverse = code.inverse[b];
      for (int y = 0; y < lit.rows; y += kStride) {
        for (int x = 0; x < lit.cols; x += kStride) {
          if (!lit.at<uint8_t>(y, x)) continue;
          residuals.push_back(photos.at(pattern, y, x) + photos.at(inverse, y, x) -
                              white.at<float>(y, x) - black.at<float>(y, x));
        }
      }
    }
  }
  // Four images' noise in each residual.
  if (residuals.size() >= 100) return RobustSigma(std::move(residuals)) / 2.0;
  residuals.clear();
  for (int y = 0; y < black.rows; y += kStride)
    for (int x = 0; x + 1 < black.cols; x += kStride)
      residuals.push_back(black.at<float>(y, x + 1) - black.at<float>(y, x));
  return RobustSigma(std::move(residuals)) / std::sqrt(2.0);
}

// A phase set's least-squares fit: for each image k, value = a + C cos(shift_k) − S sin(shift_k),
// so C = amplitude · cos θ and S = amplitude · sin θ for θ = direction · 2π (u − origin) / P.
struct PhaseFit {
  const StructuredLightLayout::Phase* phase = nullptr;
  Eigen::MatrixXd solve;  // 3 × N: (a, C, S) = solve · values
  double amplitude_noise = 0.0;  // standard deviation of C and S per unit image noise
};

PhaseFit FitPhase(const StructuredLightLayout::Phase& phase) {
  const int n = static_cast<int>(phase.shifts.size());
  Eigen::MatrixXd design(n, 3);
  for (int k = 0; k < n; ++k) design.row(k) << 1.0, std::cos(phase.shifts[k]), -std::sin(phase.shifts[k]);
  const Eigen::Matrix3d normal = design.transpose() * design;
  PhaseFit fit;
  fit.phase = &phase;
  fit.solve = normal.inverse() * design.transpose();
  fit.amplitude_noise = std::sqrt(0.5 * (normal.inverse()(1, 1) + normal.inverse()(2, 2)));
  return fit;
}

// x + P · round((estimate − x) / P): the one of x's P-periodic images nearest the estimate.
double Unwrap(double within, double period, double estimate) {
  return within + period * std::round((estimate - within) / period);
}

// Per axis: its Gray code (at most one) and its phase sets, coarsest period first.
struct Axis {
  bool column = true;
  int size = 0;
  const StructuredLightLayout::Gray* gray = nullptr;
  std::vector<PhaseFit> phases;
};

// One pixel's decode along one axis from the shown Gray bits `shown` (indexed by bit, before any
// XOR is undone) and the phases' positions within their periods `within` (coarsest first).
struct AxisDecode {
  DecodeRefusal refusal = DecodeRefusal::kDecoded;
  double coordinate = 0.0;  // projector pixels (kDecoded, or kOutOfRange after unwrapping)
  double gray_low = 0.0, gray_high = 0.0;  // the Gray cell's first and last pixel
  bool compared = false;                   // a Gray cell and unwrapped phases, to compare
};

AxisDecode DecodeAxis(const Axis& axis, const int* shown, const double* within) {
  AxisDecode result;
  double estimate = std::numeric_limits<double>::quiet_NaN();
  double bound = std::numeric_limits<double>::infinity();  // |estimate − truth| below this
  if (axis.gray) {
    const StructuredLightLayout::Gray& code = *axis.gray;
    // Undo the XOR, then Gray → binary on the code truncated to the shown bits.
    int binary = 0, previous = 0;
    for (int bit = code.bits - 1; bit >= code.finest_bit; --bit) {
      int gray = shown[bit];
      if (code.xor_codes && bit > code.finest_bit) gray ^= shown[code.finest_bit];
      previous ^= gray;
      binary |= previous << (bit - code.finest_bit);
    }
    const int cell = code.cell << code.finest_bit;
    result.gray_low = static_cast<double>(binary) * cell;
    if (result.gray_low >= axis.size) {
      result.refusal = DecodeRefusal::kOutOfRange;
      return result;
    }
    result.gray_high = std::min<double>(result.gray_low + cell, axis.size) - 1.0;
    estimate = 0.5 * (result.gray_low + result.gray_high);
    bound = 0.5 * cell;
  }
  // The phases, coarsest first; a set whose period the estimate cannot unwrap is first combined
  // with the next finer set into their beat.
  double phase_estimate = estimate;
  bool unwrapped = true;
  for (size_t k = 0; k < axis.phases.size() && unwrapped; ++k) {
    const double period = axis.phases[k].phase->period;
    if (bound < 0.5 * period) {
      phase_estimate = Unwrap(within[k], period, phase_estimate);
    } else if (std::isinf(bound) && period >= axis.size - 0.5) {
      phase_estimate = within[k];  // one period spans the axis
    } else if (k + 1 < axis.phases.size() &&
               period > axis.phases[k + 1].phase->period * (1.0 + 1e-9)) {
      // The beat of this set and the next finer one.
      const double finer = axis.phases[k + 1].phase->period;
      const double beat = period * finer / (period - finer);
      double w = within[k + 1] / finer - within[k] / period;
      w = (w - std::floor(w)) * beat;
      if (bound < 0.5 * beat) {
        phase_estimate = Unwrap(w, beat, phase_estimate);
      } else if (std::isinf(bound) && beat >= axis.size - 0.5) {
        phase_estimate = w;
      } else {
        unwrapped = false;
      }
      unwrapped = unwrapped && beat / 8.0 < 0.5 * period;
      if (unwrapped) phase_estimate = Unwrap(within[k], period, phase_estimate);
    } else {
      unwrapped = false;
    }
    bound = period / 8.0;
  }
  if (!unwrapped) {
    result.refusal = DecodeRefusal::kUnwrap;
    return result;
  }
  if (!axis.phases.empty()) estimate = phase_estimate;
  result.compared = axis.gray && !axis.phases.empty();
  result.coordinate = estimate;
  if (estimate < -0.5 || estimate >= axis.size - 0.5) result.refusal = DecodeRefusal::kOutOfRange;
  return result;
}

}  // namespace

StructuredLightMap DecodeStructuredLight(const StructuredLightLayout& layout,
                                         const std::vector<cv::Mat>& captured,
                                         const StructuredLightDecodeOptions& decode_options) {
  std::string why;
  if (!layout.Check(&why)) throw std::invalid_argument("structured light layout: " + why);
  if (!decode_options.Check(&why)) throw std::invalid_argument("structured light decode: " + why);
  if (captured.size() != static_cast<size_t>(layout.image_count)) {
    throw std::invalid_argument("structured light: " + std::to_string(captured.size()) +
                                " images for a sequence of " + std::to_string(layout.image_count));
  }
  const cv::Size size = captured[0].size();
  for (size_t i = 0; i < captured.size(); ++i) {
    if (captured[i].size() != size)
      throw std::invalid_argument("structured light: image " + std::to_string(i) +
                                  " differs in size from image 0");
  }
  const Photos photos(captured);
  const cv::Mat white = photos.Float(layout.white);
  const cv::Mat black = photos.Float(layout.black);
  const cv::Mat range = white - black;

  // Shadow test against a robust maximum of the contrast, then against the noise.
  std::vector<float> ranges(range.begin<float>(), range.end<float>());
  const size_t percentile = std::min(ranges.size() - 1, ranges.size() * 99 / 100);
  std::nth_element(ranges.begin(), ranges.begin() + percentile, ranges.end());
  const float relative_floor =
      static_cast<float>(decode_options.min_contrast) * std::max(ranges[percentile], 0.0f);
  StructuredLightMap map;
  map.noise_sigma =
      EstimateNoise(layout, photos, white, black, (range > relative_floor) & (range > 0.0f));
  const double sigmas = decode_options.noise_sigmas;
  const float difference_floor = static_cast<float>(sigmas * std::sqrt(2.0) * map.noise_sigma);
  const float contrast_floor = std::max(relative_floor, difference_floor);
  const cv::Mat lit = (range > contrast_floor) & (range > 0.0f);

  double global_threshold = 0.0;
  if (decode_options.binarization == Binarization::kGlobalThreshold) {
    cv::Mat midpoint = 0.5 * (white + black);
    global_threshold = cv::mean(midpoint, lit)[0];
  }

  const float nan = std::numeric_limits<float>::quiet_NaN();
  map.column = cv::Mat(size, CV_32FC1, cv::Scalar(nan));
  map.row = cv::Mat(size, CV_32FC1, cv::Scalar(nan));
  map.mask = cv::Mat(size, CV_8UC1, cv::Scalar(0));
  map.refused = cv::Mat(size, CV_8UC1, cv::Scalar(static_cast<int>(DecodeRefusal::kShadowed)));

  std::vector<Axis> axes;
  for (bool column : {true, false}) {
    Axis axis;
    axis.column = column;
    axis.size = column ? layout.width : layout.height;
    for (const auto& code : layout.gray)
      if (code.column == column && axis.gray == nullptr) axis.gray = &code;
    for (const auto& phase : layout.phases)
      if (phase.column == column) axis.phases.push_back(FitPhase(phase));
    std::sort(axis.phases.begin(), axis.phases.end(),
              [](const PhaseFit& a, const PhaseFit& b) { return a.phase->period > b.phase->period; });
    if (axis.gray || !axis.phases.empty()) axes.push_back(std::move(axis));
  }

  const float bit_fraction = static_cast<float>(decode_options.min_bit_contrast);
  std::vector<long long> agree(size.height, 0), disagree(size.height, 0);
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      for (int x = 0; x < size.width; ++x) {
        if (!lit.at<uint8_t>(y, x)) continue;
        const float pixel_range = range.at<float>(y, x);
        const float threshold =
            decode_options.binarization == Binarization::kPixelThreshold
                ? 0.5f * (white.at<float>(y, x) + black.at<float>(y, x))
                : static_cast<float>(global_threshold);
        const float bit_floor = std::max(bit_fraction * pixel_range, difference_floor);
        // Each axis decodes on its own; a pixel's first failing test is what it is refused for.
        DecodeRefusal refusal = DecodeRefusal::kDecoded;
        const auto refuse = [&](DecodeRefusal why_refused) {
          if (refusal == DecodeRefusal::kDecoded) refusal = why_refused;
        };
        for (const Axis& axis : axes) {
          // The Gray bits as shown (before any XOR is undone), and those too faint to read.
          int shown[32] = {0};
          int unclear[32];
          int unclear_count = 0;
          if (axis.gray) {
            const StructuredLightLayout::Gray& code = *axis.gray;
            for (size_t b = 0; b < code.images.size(); ++b) {
              const int bit = code.bits - 1 - static_cast<int>(b);
              const float value = photos.at(code.images[b], y, x);
              const bool complementary =
                  decode_options.binarization == Binarization::kComplementary && code.inverse[b] >= 0;
              const float threshold_here =
                  complementary ? 0.0f
                  : decode_options.binarization == Binarization::kComplementary
                      ? 0.5f * (white.at<float>(y, x) + black.at<float>(y, x))
                      : threshold;
              const float difference = complementary ? value - photos.at(code.inverse[b], y, x)
                                                     : 2.0f * (value - threshold_here);
              shown[bit] = difference > 0.0f;
              if (std::abs(difference) < bit_floor) unclear[unclear_count++] = bit;
            }
          }
          // Without phases every Gray bit is needed; with them, only the bits that change the
          // decode (below).
          if (unclear_count > 0 &&
              (axis.phases.empty() || unclear_count > decode_options.faint_bits)) {
            refuse(DecodeRefusal::kAmbiguous);
            continue;
          }
          bool phase_ok = true;
          double within[StructuredLightLayout::kMaxPhasesPerAxis];
          for (size_t k = 0; k < axis.phases.size() && phase_ok; ++k) {
            const PhaseFit& fit = axis.phases[k];
            const StructuredLightLayout::Phase& phase = *fit.phase;
            double abc[3] = {0.0, 0.0, 0.0};  // fit.solve · values, without allocating
            for (size_t i = 0; i < phase.images.size(); ++i) {
              const double value = photos.at(phase.images[i], y, x);
              for (int r = 0; r < 3; ++r) abc[r] += fit.solve(r, i) * value;
            }
            const double amplitude = std::hypot(abc[1], abc[2]);
            if (amplitude < decode_options.min_modulation * 0.5 * pixel_range ||
                amplitude < sigmas * fit.amplitude_noise * map.noise_sigma) {
              phase_ok = false;
              break;
            }
            const double turns = std::atan2(abc[2], abc[1]) / (2.0 * std::numbers::pi);
            double w = phase.origin + phase.direction * turns * phase.period;
            w -= phase.period * std::floor(w / phase.period);
            within[k] = w;
          }
          if (!phase_ok) {
            // The Gray test comes first: a pixel with unclear bits is refused for them.
            refuse(unclear_count > 0 ? DecodeRefusal::kAmbiguous : DecodeRefusal::kWeakPhase);
            continue;
          }
          AxisDecode decoded = DecodeAxis(axis, shown, within);
          if (unclear_count == 0) {
            if (decoded.compared) {
              ++((decoded.coordinate >= decoded.gray_low - 1.5 &&
                  decoded.coordinate <= decoded.gray_high + 1.5)
                     ? agree
                     : disagree)[y];
            }
          } else {
            // Unclear bits are tried at both values: the pixel decodes where every value that
            // leads to a coordinate at all leads to the same one, which is then the coordinate
            // the bits read right would give (the phases unwrap the same from either side of a
            // blurred stripe edge: the cells on its two sides are within half a period of the
            // pixel). Values that lead nowhere (a cell beyond the projector, a coordinate outside
            // it) cannot be the pixel's; where none is left, or two lead to different
            // coordinates, the bits matter and the pixel is refused as ambiguous.
            int tried[32];
            std::copy(std::begin(shown), std::end(shown), std::begin(tried));
            bool found = false, conflict = false;
            for (int values = 0; values < (1 << unclear_count) && !conflict; ++values) {
              for (int j = 0; j < unclear_count; ++j) tried[unclear[j]] = (values >> j) & 1;
              const AxisDecode candidate = DecodeAxis(axis, tried, within);
              if (candidate.refusal != DecodeRefusal::kDecoded) continue;
              if (!found) {
                decoded = candidate;
                found = true;
              } else if (std::abs(candidate.coordinate - decoded.coordinate) > 0.5) {
                conflict = true;  // distinct coordinates differ by a multiple of a period > 1
              }
            }
            if (!found || conflict) {
              refuse(DecodeRefusal::kAmbiguous);
              continue;
            }
          }
          if (decoded.refusal != DecodeRefusal::kDecoded) {
            refuse(decoded.refusal);
            continue;
          }
          (axis.column ? map.column : map.row).at<float>(y, x) =
              static_cast<float>(decoded.coordinate);
        }
        map.refused.at<uint8_t>(y, x) = static_cast<uint8_t>(refusal);
        if (refusal == DecodeRefusal::kDecoded) map.mask.at<uint8_t>(y, x) = 255;
      }
    }
  });
  for (int y = 0; y < size.height; ++y) {
    map.gray_phase_agree += agree[y];
    map.gray_phase_disagree += disagree[y];
    const uint8_t* reasons = map.refused.ptr<uint8_t>(y);
    for (int x = 0; x < size.width; ++x) {
      switch (static_cast<DecodeRefusal>(reasons[x])) {
        case DecodeRefusal::kShadowed: ++map.shadowed; break;
        case DecodeRefusal::kAmbiguous: ++map.ambiguous; break;
        case DecodeRefusal::kWeakPhase: ++map.weak_phase; break;
        case DecodeRefusal::kOutOfRange: ++map.out_of_range; break;
        case DecodeRefusal::kUnwrap: ++map.unwrap; break;
        case DecodeRefusal::kDecoded: break;
      }
    }
  }
  return map;
}

cv::Mat DecodePicture(const StructuredLightMap& map, int projector_width, int projector_height) {
  const cv::Size size = map.column.size();
  const double scale = std::min(1.0, 640.0 / std::max(1, size.width));
  const cv::Size panel(std::max(1, static_cast<int>(std::lround(size.width * scale))),
                       std::max(1, static_cast<int>(std::lround(size.height * scale))));
  constexpr int kTitle = 28, kLegend = 22;
  const int legend_rows = 6;
  cv::Mat picture(panel.height + kTitle + kLegend * legend_rows, 3 * panel.width,
                  CV_8UC3, cv::Scalar::all(255));
  const auto coordinate_panel = [&](const cv::Mat& coordinate, int extent) {
    cv::Mat level(size, CV_8UC1, cv::Scalar(0)), valid = coordinate == coordinate;  // not NaN
    coordinate.convertTo(level, CV_8U, 255.0 / std::max(1, extent - 1));
    cv::Mat colour;
    cv::applyColorMap(level, colour, cv::COLORMAP_TURBO);
    colour.setTo(cv::Scalar::all(0), ~valid);
    cv::Mat resized;
    cv::resize(colour, resized, panel, 0, 0, cv::INTER_NEAREST);
    return resized;
  };
  static const cv::Vec3b kColours[] = {{60, 170, 60},   {80, 80, 80},  {0, 140, 255},
                                       {230, 60, 160},  {40, 40, 220}, {200, 180, 0}};
  cv::Mat reasons(size, CV_8UC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      reasons.at<cv::Vec3b>(y, x) = kColours[std::min<int>(map.refused.at<uint8_t>(y, x), 5)];
  cv::Mat reasons_panel;
  cv::resize(reasons, reasons_panel, panel, 0, 0, cv::INTER_NEAREST);
  const cv::Mat panels[] = {coordinate_panel(map.column, projector_width),
                            coordinate_panel(map.row, projector_height), reasons_panel};
  const char* titles[] = {"projector column", "projector row", "why refused"};
  for (int k = 0; k < 3; ++k) {
    panels[k].copyTo(picture(cv::Rect(k * panel.width, kTitle, panel.width, panel.height)));
    cv::putText(picture, titles[k], cv::Point(k * panel.width + 6, 20), cv::FONT_HERSHEY_SIMPLEX,
                0.55, cv::Scalar::all(0), 1, cv::LINE_AA);
  }
  const long long counts[] = {cv::countNonZero(map.mask), map.shadowed, map.ambiguous,
                              map.weak_phase, map.out_of_range, map.unwrap};
  const double total = std::max(1, size.area());
  for (int k = 0; k < legend_rows; ++k) {
    const int top = kTitle + panel.height + k * kLegend + 4;
    const cv::Rect swatch(2 * panel.width + 6, top, 14, 14);
    picture(swatch).setTo(cv::Scalar(kColours[k][0], kColours[k][1], kColours[k][2]));
    char text[96];
    std::snprintf(text, sizeof(text), "%s: %lld (%.1f%%)",
                  DecodeRefusalName(static_cast<DecodeRefusal>(k)), counts[k],
                  100.0 * counts[k] / total);
    cv::putText(picture, text, cv::Point(swatch.x + 20, top + 12), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar::all(0), 1, cv::LINE_AA);
  }
  return picture;
}

}  // namespace procam
