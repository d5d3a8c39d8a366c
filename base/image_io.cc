#include "base/image_io.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/io.h"

namespace procam {
namespace {

// An image's width and height as its file's header states them.
struct HeaderSize {
  int64_t width = 0, height = 0;
};

// `count` bytes at `at` as an unsigned integer, big- or little-endian; the caller checks bounds.
uint32_t Unsigned(const std::string& bytes, size_t at, int count, bool big_endian) {
  uint32_t value = 0;
  for (int k = 0; k < count; ++k) {
    const int byte = big_endian ? k : count - 1 - k;
    value = (value << 8) | static_cast<uint8_t>(bytes[at + byte]);
  }
  return value;
}

bool StartsWith(const std::string& bytes, const std::string& prefix) {
  return bytes.compare(0, prefix.size(), prefix) == 0;
}

std::optional<HeaderSize> PngSize(const std::string& bytes) {
  if (bytes.size() < 24 || !StartsWith(bytes, std::string("\x89PNG\r\n\x1a\n", 8))) return {};
  return HeaderSize{Unsigned(bytes, 16, 4, true), Unsigned(bytes, 20, 4, true)};
}

std::optional<HeaderSize> BmpSize(const std::string& bytes) {
  if (bytes.size() < 26 || !StartsWith(bytes, "BM")) return {};
  if (Unsigned(bytes, 14, 4, false) == 12) {  // OS/2 header: 16-bit sides
    return HeaderSize{Unsigned(bytes, 18, 2, false), Unsigned(bytes, 20, 2, false)};
  }
  // Signed sides; a negative height means top-down rows.
  const auto side = [&](size_t at) {
    return std::abs(int64_t{static_cast<int32_t>(Unsigned(bytes, at, 4, false))});
  };
  return HeaderSize{side(18), side(22)};
}

// The first start-of-frame segment (SOF0 to SOF15 but DHT, JPG and DAC) gives the size.
std::optional<HeaderSize> JpegSize(const std::string& bytes) {
  if (!StartsWith(bytes, "\xff\xd8")) return {};
  size_t at = 2;
  while (at + 4 <= bytes.size() && static_cast<uint8_t>(bytes[at]) == 0xff) {
    const uint8_t marker = static_cast<uint8_t>(bytes[at + 1]);
    if (marker == 0xff) {  // fill byte
      ++at;
    } else if (marker == 0x01 || (marker >= 0xd0 && marker <= 0xd9)) {  // no length
      at += 2;
    } else if (marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 &&
               marker != 0xcc) {
      if (at + 9 > bytes.size()) return {};
      return HeaderSize{Unsigned(bytes, at + 7, 2, true), Unsigned(bytes, at + 5, 2, true)};
    } else {
      at += 2 + Unsigned(bytes, at + 2, 2, true);
    }
  }
  return {};
}

// ImageWidth (256) and ImageLength (257) of the first directory, which is what OpenCV decodes.
std::optional<HeaderSize> TiffSize(const std::string& bytes) {
  const bool big_endian = StartsWith(bytes, std::string("MM\0*", 4));
  if (bytes.size() < 8 || !(big_endian || StartsWith(bytes, std::string("II*\0", 4)))) return {};
  const size_t directory = Unsigned(bytes, 4, 4, big_endian);
  if (directory + 2 > bytes.size()) return {};
  HeaderSize size;
  const size_t entries = Unsigned(bytes, directory, 2, big_endian);
  for (size_t k = 0; k < entries && directory + 2 + 12 * (k + 1) <= bytes.size(); ++k) {
    const size_t entry = directory + 2 + 12 * k;
    const uint32_t tag = Unsigned(bytes, entry, 2, big_endian);
    const bool is_short = Unsigned(bytes, entry + 2, 2, big_endian) == 3;
    const int64_t value = Unsigned(bytes, entry + 8, is_short ? 2 : 4, big_endian);
    if (tag == 256) size.width = value;
    if (tag == 257) size.height = value;
  }
  if (size.width == 0 || size.height == 0) return {};
  return size;
}

// Netpbm (P1 to P6): the magic, then width and height as decimal text, with whitespace and
// `#` comments between.
std::optional<HeaderSize> PnmSize(const std::string& bytes) {
  if (bytes.size() < 3 || bytes[0] != 'P' || bytes[1] < '1' || bytes[1] > '6') return {};
  size_t at = 2;
  int64_t sides[2] = {0, 0};
  for (int64_t& side : sides) {
    while (at < bytes.size() && (std::isspace(static_cast<unsigned char>(bytes[at])) || bytes[at] == '#')) {
      if (bytes[at] == '#') {
        while (at < bytes.size() && bytes[at] != '\n') ++at;
      } else {
        ++at;
      }
    }
    if (at >= bytes.size() || !std::isdigit(static_cast<unsigned char>(bytes[at]))) return {};
    while (at < bytes.size() && std::isdigit(static_cast<unsigned char>(bytes[at]))) {
      side = std::min<int64_t>(side * 10 + (bytes[at] - '0'), int64_t{1} << 40);
      ++at;
    }
  }
  return HeaderSize{sides[0], sides[1]};
}

// Refuses, before decoding, a file that is not PNG, JPEG, TIFF, BMP or Netpbm or whose header states a
// size beyond kMaxImagePixels: a few bytes must not make a decoder allocate gigabytes.
void CheckImageHeader(const std::filesystem::path& path, const std::string& bytes) {
  std::optional<HeaderSize> size = PngSize(bytes);
  for (const auto reader : {JpegSize, TiffSize, BmpSize, PnmSize}) {
    if (!size) size = reader(bytes);
  }
  if (!size) throw IoError(path.string() + ": not a readable image (PNG, JPEG, TIFF, BMP or PPM)");
  // Each side first: sides of up to 2^32 would overflow the product.
  if (size->width < 1 || size->height < 1 || size->width > kMaxImagePixels ||
      size->height > kMaxImagePixels || size->width * size->height > kMaxImagePixels) {
    throw IoError(path.string() + ": not a readable image: its header states " +
                  std::to_string(size->width) + "x" + std::to_string(size->height) +
                  " pixels (at most " + std::to_string(kMaxImagePixels) + ")");
  }
}

}  // namespace

void WritePng(const std::filesystem::path& path, const cv::Mat& image) {
  std::vector<uchar> bytes;
  if (image.empty() || !cv::imencode(".png", image, bytes)) {
    throw IoError(path.string() + ": cannot encode PNG");
  }
  WriteFileAtomically(path, std::string(bytes.begin(), bytes.end()));
}

cv::Mat DecodeImage(const std::filesystem::path& path, const std::string& bytes, int flags) {
  CheckImageHeader(path, bytes);
  const cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8U, const_cast<char*>(bytes.data()));
  cv::Mat image;
  {
    const SilencedStderr quiet;
    try {
      if (!bytes.empty()) image = cv::imdecode(buffer, flags);
    } catch (const cv::Exception&) {
      image.release();
    }
  }
  if (image.empty()) throw IoError(path.string() + ": not a readable image");
  return image;
}

cv::Mat ReadImage(const std::filesystem::path& path, int flags, uintmax_t max_bytes) {
  return DecodeImage(path, ReadFile(path, max_bytes), flags);
}

cv::Mat ReadImageChecked(const std::filesystem::path& path, int flags,
                         const std::string& checksum) {
  const std::string bytes = ReadFile(path, kMaxImageBytes);
  const std::string actual = ContentChecksum(bytes);
  if (actual != checksum) {
    throw IoError(path.string() + ": changed since it was recorded (checksum " + actual +
                  ", recorded " + checksum + ")");
  }
  return DecodeImage(path, bytes, flags);
}

}  // namespace procam
