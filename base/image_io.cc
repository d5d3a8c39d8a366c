#include "base/image_io.h"

#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "base/io.h"

namespace procam {

void WritePng(const std::filesystem::path& path, const cv::Mat& image) {
  std::vector<uchar> bytes;
  if (image.empty() || !cv::imencode(".png", image, bytes)) {
    throw IoError(path.string() + ": cannot encode PNG");
  }
  WriteFileAtomically(path, std::string(bytes.begin(), bytes.end()));
}

}  // namespace procam
