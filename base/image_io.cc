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

cv::Mat ReadImage(const std::filesystem::path& path, int flags, uintmax_t max_bytes) {
  const std::string bytes = ReadFile(path, max_bytes);
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

}  // namespace procam
