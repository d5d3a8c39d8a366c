#include "capture/pixel_format.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "base/io.h"

namespace procam {
namespace {

std::string Lower(std::string_view text) {
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return lower;
}

std::string SizeText(int width, int height) {
  return std::to_string(width) + "x" + std::to_string(height);
}

// OpenCV names a Bayer pattern by the second row's second and third pixels, so the GenICam
// (top-left 2×2) name RG corresponds to OpenCV's BG, and so on.
int DemosaicCode(PixelFormat format) {
  switch (format) {
    case PixelFormat::kBayerRG8:
      return cv::COLOR_BayerBG2BGR;
    case PixelFormat::kBayerBG8:
      return cv::COLOR_BayerRG2BGR;
    case PixelFormat::kBayerGR8:
      return cv::COLOR_BayerGB2BGR;
    case PixelFormat::kBayerGB8:
      return cv::COLOR_BayerGR2BGR;
    default:
      throw std::invalid_argument("not a Bayer format");
  }
}

// Channel (0 = B, 1 = G, 2 = R) of the mosaic at pixel (x, y), from the top-left 2×2 layout.
int BayerChannel(PixelFormat format, int x, int y) {
  const int cell = (y % 2) * 2 + (x % 2);  // 0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right
  static constexpr int kRG[4] = {2, 1, 1, 0};
  static constexpr int kBG[4] = {0, 1, 1, 2};
  static constexpr int kGR[4] = {1, 2, 0, 1};
  static constexpr int kGB[4] = {1, 0, 2, 1};
  switch (format) {
    case PixelFormat::kBayerRG8:
      return kRG[cell];
    case PixelFormat::kBayerBG8:
      return kBG[cell];
    case PixelFormat::kBayerGR8:
      return kGR[cell];
    case PixelFormat::kBayerGB8:
      return kGB[cell];
    default:
      throw std::invalid_argument("not a Bayer format");
  }
}

}  // namespace

const std::vector<PixelFormat>& AllPixelFormats() {
  static const std::vector<PixelFormat> kAll = {PixelFormat::kMono8,    PixelFormat::kMono16,
                                                PixelFormat::kBayerRG8, PixelFormat::kBayerBG8,
                                                PixelFormat::kBayerGR8, PixelFormat::kBayerGB8,
                                                PixelFormat::kRGB8,     PixelFormat::kBGR8,
                                                PixelFormat::kYUYV,     PixelFormat::kMJPEG};
  return kAll;
}

std::string PixelFormatName(PixelFormat format) {
  switch (format) {
    case PixelFormat::kMono8:
      return "Mono8";
    case PixelFormat::kMono16:
      return "Mono16";
    case PixelFormat::kBayerRG8:
      return "BayerRG8";
    case PixelFormat::kBayerBG8:
      return "BayerBG8";
    case PixelFormat::kBayerGR8:
      return "BayerGR8";
    case PixelFormat::kBayerGB8:
      return "BayerGB8";
    case PixelFormat::kRGB8:
      return "RGB8";
    case PixelFormat::kBGR8:
      return "BGR8";
    case PixelFormat::kYUYV:
      return "YUYV";
    case PixelFormat::kMJPEG:
      return "MJPEG";
  }
  return "unknown";
}

std::optional<PixelFormat> ParsePixelFormat(std::string_view name) {
  const std::string lower = Lower(name);
  for (PixelFormat format : AllPixelFormats()) {
    if (Lower(PixelFormatName(format)) == lower) return format;
  }
  if (lower == "grey" || lower == "gray8") return PixelFormat::kMono8;
  if (lower == "y16" || lower == "gray16") return PixelFormat::kMono16;
  if (lower == "rgb8packed" || lower == "rgb3" || lower == "rgb24") return PixelFormat::kRGB8;
  if (lower == "bgr8packed" || lower == "bgr3" || lower == "bgr24") return PixelFormat::kBGR8;
  if (lower == "yuv422_8" || lower == "yuv422_8_yuyv" || lower == "yuyv422")
    return PixelFormat::kYUYV;
  if (lower == "mjpg" || lower == "jpeg") return PixelFormat::kMJPEG;
  return std::nullopt;
}

bool IsBayer(PixelFormat format) {
  return format == PixelFormat::kBayerRG8 || format == PixelFormat::kBayerBG8 ||
         format == PixelFormat::kBayerGR8 || format == PixelFormat::kBayerGB8;
}

bool IsColour(PixelFormat format) {
  return format != PixelFormat::kMono8 && format != PixelFormat::kMono16;
}

int RawBytesPerPixel(PixelFormat format) {
  switch (format) {
    case PixelFormat::kMono16:
    case PixelFormat::kYUYV:
      return 2;
    case PixelFormat::kRGB8:
    case PixelFormat::kBGR8:
      return 3;
    case PixelFormat::kMJPEG:
      return 0;
    default:
      return 1;
  }
}

double FullScale(PixelFormat format) { return format == PixelFormat::kMono16 ? 65535.0 : 255.0; }

cv::Mat DecodeImage(const RawImage& raw) {
  const std::string what =
      PixelFormatName(raw.format) + " frame " + SizeText(raw.width, raw.height);
  if (raw.width <= 0 || raw.height <= 0) throw IoError(what + ": empty frame size");
  if (raw.data == nullptr || raw.size == 0) throw IoError(what + ": empty buffer");

  if (raw.format == PixelFormat::kMJPEG) {
    const cv::Mat bytes(1, static_cast<int>(raw.size), CV_8UC1, const_cast<uint8_t*>(raw.data));
    cv::Mat decoded = cv::imdecode(bytes, cv::IMREAD_COLOR);
    if (decoded.empty())
      throw IoError(what + ": JPEG data does not decode (" + std::to_string(raw.size) + " bytes)");
    if (decoded.cols != raw.width || decoded.rows != raw.height) {
      throw IoError(what + ": JPEG decodes to " + SizeText(decoded.cols, decoded.rows));
    }
    return decoded;
  }

  const size_t row_bytes = static_cast<size_t>(raw.width) * RawBytesPerPixel(raw.format);
  const size_t stride = raw.stride == 0 ? row_bytes : raw.stride;
  if (stride < row_bytes)
    throw IoError(what + ": row stride " + std::to_string(stride) + " < " +
                  std::to_string(row_bytes));
  const size_t needed = stride * static_cast<size_t>(raw.height - 1) + row_bytes;
  if (raw.size < needed) {
    throw IoError(what + " needs " + std::to_string(needed) + " bytes, buffer has " +
                  std::to_string(raw.size));
  }
  uint8_t* data = const_cast<uint8_t*>(raw.data);  // wrapped read-only: every branch copies
  switch (raw.format) {
    case PixelFormat::kMono8:
      return cv::Mat(raw.height, raw.width, CV_8UC1, data, stride).clone();
    case PixelFormat::kMono16: {
      cv::Mat image(raw.height, raw.width, CV_16UC1);
      for (int y = 0; y < raw.height; ++y) {
        const uint8_t* row = raw.data + stride * y;
        uint16_t* out = image.ptr<uint16_t>(y);
        for (int x = 0; x < raw.width; ++x)
          out[x] = static_cast<uint16_t>(row[2 * x] | (row[2 * x + 1] << 8));
      }
      return image;
    }
    case PixelFormat::kRGB8: {
      cv::Mat image;
      cv::cvtColor(cv::Mat(raw.height, raw.width, CV_8UC3, data, stride), image, cv::COLOR_RGB2BGR);
      return image;
    }
    case PixelFormat::kBGR8:
      return cv::Mat(raw.height, raw.width, CV_8UC3, data, stride).clone();
    case PixelFormat::kYUYV: {
      if (raw.width % 2 != 0) throw IoError(what + ": YUYV needs an even width");
      cv::Mat image;
      cv::cvtColor(cv::Mat(raw.height, raw.width, CV_8UC2, data, stride), image,
                   cv::COLOR_YUV2BGR_YUYV);
      return image;
    }
    case PixelFormat::kBayerRG8:
    case PixelFormat::kBayerBG8:
    case PixelFormat::kBayerGR8:
    case PixelFormat::kBayerGB8: {
      cv::Mat image;
      cv::cvtColor(cv::Mat(raw.height, raw.width, CV_8UC1, data, stride), image,
                   DemosaicCode(raw.format));
      return image;
    }
    case PixelFormat::kMJPEG:
      break;
  }
  throw IoError(what + ": unsupported pixel format");
}

std::vector<uint8_t> EncodeRaw(const cv::Mat& image, PixelFormat format) {
  const int expected_type = format == PixelFormat::kMono8    ? CV_8UC1
                            : format == PixelFormat::kMono16 ? CV_16UC1
                                                             : CV_8UC3;
  if (format == PixelFormat::kYUYV || format == PixelFormat::kMJPEG) {
    throw std::invalid_argument("EncodeRaw: " + PixelFormatName(format) +
                                " is not produced by simulated cameras");
  }
  if (image.type() != expected_type) {
    throw std::invalid_argument("EncodeRaw: " + PixelFormatName(format) +
                                " needs an image of type " + std::to_string(expected_type) +
                                ", got " + std::to_string(image.type()));
  }
  const int width = image.cols;
  const int height = image.rows;
  std::vector<uint8_t> raw(static_cast<size_t>(width) * height * RawBytesPerPixel(format));
  for (int y = 0; y < height; ++y) {
    uint8_t* out = raw.data() + static_cast<size_t>(y) * width * RawBytesPerPixel(format);
    switch (format) {
      case PixelFormat::kMono8:
        std::memcpy(out, image.ptr<uint8_t>(y), width);
        break;
      case PixelFormat::kMono16:
        for (int x = 0; x < width; ++x) {
          const uint16_t value = image.at<uint16_t>(y, x);
          out[2 * x] = static_cast<uint8_t>(value & 0xff);
          out[2 * x + 1] = static_cast<uint8_t>(value >> 8);
        }
        break;
      case PixelFormat::kRGB8:
        for (int x = 0; x < width; ++x) {
          const cv::Vec3b& bgr = image.at<cv::Vec3b>(y, x);
          out[3 * x] = bgr[2];
          out[3 * x + 1] = bgr[1];
          out[3 * x + 2] = bgr[0];
        }
        break;
      case PixelFormat::kBGR8:
        std::memcpy(out, image.ptr<uint8_t>(y), static_cast<size_t>(width) * 3);
        break;
      default:  // Bayer
        for (int x = 0; x < width; ++x)
          out[x] = image.at<cv::Vec3b>(y, x)[BayerChannel(format, x, y)];
        break;
    }
  }
  return raw;
}

}  // namespace procam
