#include "projection/test_pattern.h"

#include <array>

namespace procam {

const char* TestPatternName(TestPattern pattern) {
  switch (pattern) {
    case TestPattern::kGrid:
      return "grid";
    case TestPattern::kBars:
      return "bars";
    case TestPattern::kWhite:
      return "white";
    case TestPattern::kBlack:
      return "black";
  }
  return "?";
}

bool ParseTestPattern(const std::string& name, TestPattern* pattern) {
  for (const TestPattern p :
       {TestPattern::kGrid, TestPattern::kBars, TestPattern::kWhite, TestPattern::kBlack}) {
    if (name == TestPatternName(p)) {
      *pattern = p;
      return true;
    }
  }
  return false;
}

ProjectorImage MakeTestPattern(TestPattern pattern, cv::Size size) {
  ProjectorImage image;
  image.bits = 8;
  image.codes = cv::Mat(size, CV_16UC3, cv::Scalar::all(0));
  const int width = size.width, height = size.height;
  const cv::Vec3w white(255, 255, 255);
  switch (pattern) {
    case TestPattern::kBlack:
      break;
    case TestPattern::kWhite:
      image.codes.setTo(cv::Scalar::all(255));
      break;
    case TestPattern::kBars: {
      const std::array<cv::Vec3w, 8> bars = {cv::Vec3w(255, 255, 255), cv::Vec3w(255, 255, 0),
                                             cv::Vec3w(0, 255, 255),   cv::Vec3w(0, 255, 0),
                                             cv::Vec3w(255, 0, 255),   cv::Vec3w(255, 0, 0),
                                             cv::Vec3w(0, 0, 255),     cv::Vec3w(0, 0, 0)};
      for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) image.codes.at<cv::Vec3w>(y, x) = bars[(8 * x) / width];
      }
      break;
    }
    case TestPattern::kGrid: {
      for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
          const bool line = x % 64 == 0 || y % 64 == 0 || x == width - 1 || y == height - 1 ||
                            x == width / 2 || y == height / 2;
          if (line) image.codes.at<cv::Vec3w>(y, x) = white;
        }
      }
      image.codes.at<cv::Vec3w>(0, 0) = cv::Vec3w(255, 0, 0);
      image.codes.at<cv::Vec3w>(0, width - 1) = cv::Vec3w(0, 255, 0);
      image.codes.at<cv::Vec3w>(height - 1, width - 1) = cv::Vec3w(0, 0, 255);
      image.codes.at<cv::Vec3w>(height - 1, 0) = cv::Vec3w(255, 255, 0);
      break;
    }
  }
  return image;
}

}  // namespace procam
