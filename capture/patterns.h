#pragma once
// The pattern sequences procam captures: Gray-code structured light (geometric calibration),
// flat fields per channel and level (photometric calibration), and user images (verification).
// Each generator returns a CaptureSequence: the patterns in showing order plus the parameters
// that produced them, which a capture session records and compares when it resumes.
//
// Patterns are CV_8UC3 (B, G, R) at projector resolution; projector pixel (u, v) is column u,
// row v from the top left.

#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace procam {

struct Pattern {
  std::string name;     // unique within a sequence, usable in file names ("gray_col_b03_inv")
  cv::Mat image;        // CV_8UC3, projector resolution
  nlohmann::json info;  // what the pattern encodes ({"kind": "graycode", "axis": "column", ...})
};

struct CaptureSequence {
  std::string kind;           // "graycode", "photometric", "verify"
  nlohmann::json parameters;  // the generator's options; a resumed session must match them
  std::vector<Pattern> patterns;
};

// Gray-code structured light: a white and a black frame (the per-pixel thresholds), then for
// each axis and each bit, most significant first, the bit plane of the reflected binary code
// g(u) = u xor (u >> 1) and its inverse. Decoding compares each plane with its inverse, which
// is robust to albedo and ambient light.
struct GrayCodeOptions {
  int width = 1024;     // projector pixels, [2, 16384]
  int height = 768;     // projector pixels, [2, 16384]
  bool columns = true;  // encode the column u
  bool rows = true;     // encode the row v
  bool Check(std::string* why) const;
};

// Bits needed to code 0 .. size−1: ⌈log2 size⌉.
int GrayCodeBits(int size);
CaptureSequence MakeGrayCodeSequence(const GrayCodeOptions& options);

struct GrayCodeDecodeOptions {
  // A camera pixel is decoded only where white − black exceeds this fraction of the
  // brightest such difference in the image, [0, 1).
  double min_contrast = 0.1;
  // A bit is accepted only where |plane − inverse| exceeds this fraction of white − black,
  // [0, 1).
  double min_bit_contrast = 0.1;
  bool Check(std::string* why) const;
};

// Per camera pixel, the projector column and row it sees (CV_32SC1; −1 where the pixel is not
// lit enough or a bit is ambiguous). `captured` holds one image per pattern of
// MakeGrayCodeSequence(options), in order, any depth, one or three channels (three are
// averaged). Throws std::invalid_argument when the count or sizes do not match.
struct GrayCodeMap {
  cv::Mat column;
  cv::Mat row;
};
GrayCodeMap DecodeGrayCode(const GrayCodeOptions& options, const std::vector<cv::Mat>& captured,
                           const GrayCodeDecodeOptions& decode_options = {});

// Flat fields: black, then for each channel and each level > 0 the projector showing `level`
// on that channel ("w" = all three) and 0 on the others. Named "flat_<channel>_<level:03>".
struct PhotometricOptions {
  int width = 1024;  // projector pixels, [1, 16384]
  int height = 768;  // projector pixels, [1, 16384]
  std::vector<int> levels = {0, 32, 64, 96, 128, 160, 192, 224, 255};  // 8-bit values, [0, 255]
  std::string channels = "rgbw";  // any of r, g, b, w, each once
  bool Check(std::string* why) const;
};
CaptureSequence MakePhotometricSequence(const PhotometricOptions& options);

// Verification: the given images, in order, each exactly `projector_size` (they are meant to
// be a projector's computed output). Throws IoError naming the file that is missing,
// unreadable or of another size.
CaptureSequence MakeVerifySequence(const std::vector<std::filesystem::path>& images,
                                   cv::Size projector_size);

// FNV-1a over the pattern's pixels, as 16 hex digits: identifies a pattern in manifests.
std::string PatternChecksum(const cv::Mat& image);

}  // namespace procam
