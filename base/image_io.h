#pragma once
// Pictures procam writes (8-bit or 16-bit PNG through OpenCV, atomically, io.h) and reads.

#include <cstdint>
#include <filesystem>
#include <string>
#include <opencv2/core/mat.hpp>

namespace procam {

// Encodes `image` (8/16-bit, 1 or 3 channels, OpenCV's B, G, R order) as PNG and writes it
// through WriteFileAtomically. Throws IoError naming the file.
void WritePng(const std::filesystem::path& path, const cv::Mat& image);

// The largest image file ReadImage reads unless told otherwise: 1 GiB.
constexpr uintmax_t kMaxImageBytes = uintmax_t{1} << 30;

// The most pixels ReadImage decodes: 2^27 (e.g. 16384 x 8192), 1.6 GB as float RGB.
constexpr int64_t kMaxImagePixels = int64_t{1} << 27;

// Decodes a PNG, JPEG, TIFF, BMP or Netpbm (PPM, PGM, PBM) file as cv::imread does with `flags` (cv::ImreadModes), after
// checking that it is a regular file of at most `max_bytes` (io.h CheckRegularFile) and that the
// size its header states is at most kMaxImagePixels (so that a few bytes cannot make a decoder
// allocate gigabytes), with the decoders' own messages (libpng's, OpenCV's) silenced. Throws
// IoError naming the file: not found, not a regular file, too large, "not a readable image".
cv::Mat ReadImage(const std::filesystem::path& path, int flags,
                  uintmax_t max_bytes = kMaxImageBytes);

// Decodes `bytes`, the contents of `path` already read (ReadFile), with ReadImage's checks and
// messages: lets a caller checksum the same bytes it decodes.
cv::Mat DecodeImage(const std::filesystem::path& path, const std::string& bytes, int flags);

// ReadImage, after checking that the file's bytes still have the ContentChecksum recorded when
// it was written. Throws IoError naming the file when they do not ("changed since it was
// recorded"), or as ReadImage.
cv::Mat ReadImageChecked(const std::filesystem::path& path, int flags,
                         const std::string& checksum);

}  // namespace procam
