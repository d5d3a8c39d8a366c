#pragma once
// Pictures procam writes: 8-bit or 16-bit PNG through OpenCV, atomically (io.h).

#include <filesystem>
#include <opencv2/core/mat.hpp>

namespace procam {

// Encodes `image` (8/16-bit, 1 or 3 channels, OpenCV's B, G, R order) as PNG and writes it
// through WriteFileAtomically. Throws IoError naming the file.
void WritePng(const std::filesystem::path& path, const cv::Mat& image);

}  // namespace procam
