// Pattern generators and Gray-code decoding, checked against the coordinates they encode, and a
// full structured-light loop through the test camera whose pixel-to-projector map is known.
#include "capture/patterns.h"

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "capture/display.h"
#include "capture/sequencer.h"
#include "capture/test_camera.h"
#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

std::vector<cv::Mat> Images(const CaptureSequence& sequence) {
  std::vector<cv::Mat> images;
  for (const Pattern& pattern : sequence.patterns) images.push_back(pattern.image);
  return images;
}

TEST(GrayCode, SequenceHasWhiteBlackAndEachBitWithItsInverse) {
  EXPECT_EQ(GrayCodeBits(1024), 10);
  EXPECT_EQ(GrayCodeBits(1000), 10);
  EXPECT_EQ(GrayCodeBits(768), 10);
  EXPECT_EQ(GrayCodeBits(2), 1);
  GrayCodeOptions options;
  options.width = 100;
  options.height = 30;
  const CaptureSequence sequence = MakeGrayCodeSequence(options);
  EXPECT_EQ(sequence.kind, "graycode");
  ASSERT_EQ(sequence.patterns.size(), 2u + 2 * (7 + 5));
  EXPECT_EQ(sequence.patterns[0].name, "white");
  EXPECT_EQ(sequence.patterns[1].name, "black");
  EXPECT_EQ(sequence.patterns[2].name, "gray_col_b06");
  EXPECT_EQ(sequence.patterns[3].name, "gray_col_b06_inv");
  EXPECT_EQ(sequence.patterns.back().name, "gray_row_b00_inv");
  for (size_t i = 2; i < sequence.patterns.size(); i += 2) {
    cv::Mat sum;
    cv::add(sequence.patterns[i].image, sequence.patterns[i + 1].image, sum, cv::noArray(),
            CV_16UC3);
    EXPECT_EQ(cv::countNonZero(sum.reshape(1) != 255), 0) << "plane and inverse must add to white";
  }
  // Adjacent columns differ in exactly one column plane (the Gray code property).
  for (int u = 0; u + 1 < options.width; ++u) {
    int differing = 0;
    for (size_t i = 2; i < 2 + 2 * 7; i += 2) {
      differing += sequence.patterns[i].image.at<cv::Vec3b>(0, u) !=
                   sequence.patterns[i].image.at<cv::Vec3b>(0, u + 1);
    }
    EXPECT_EQ(differing, 1) << "u=" << u;
  }
}

TEST(GrayCode, DecodingThePatternsThemselvesGivesEveryCoordinate) {
  GrayCodeOptions options;
  options.width = 100;
  options.height = 37;
  const GrayCodeMap map = DecodeGrayCode(options, Images(MakeGrayCodeSequence(options)));
  for (int v = 0; v < options.height; ++v) {
    for (int u = 0; u < options.width; ++u) {
      ASSERT_EQ(map.column.at<int32_t>(v, u), u);
      ASSERT_EQ(map.row.at<int32_t>(v, u), v);
    }
  }
}

TEST(GrayCode, UnlitAndAmbiguousPixelsAreNotDecoded) {
  GrayCodeOptions options;
  options.width = 16;
  options.height = 8;
  options.rows = false;
  std::vector<cv::Mat> images = Images(MakeGrayCodeSequence(options));
  // Pixel (3, 2) is in shadow: it reads 20 in every image. Pixel (5, 1) has one ambiguous bit.
  for (cv::Mat& image : images) {
    image = image.clone();
    image.at<cv::Vec3b>(2, 3) = cv::Vec3b(20, 20, 20);
  }
  images[4].at<cv::Vec3b>(1, 5) = cv::Vec3b(128, 128, 128);
  images[5].at<cv::Vec3b>(1, 5) = cv::Vec3b(127, 127, 127);
  const GrayCodeMap map = DecodeGrayCode(options, images);
  EXPECT_EQ(map.column.at<int32_t>(2, 3), -1);
  EXPECT_EQ(map.column.at<int32_t>(1, 5), -1);
  EXPECT_EQ(map.column.at<int32_t>(1, 6), 6);
  EXPECT_EQ(map.row.at<int32_t>(0, 0), -1);  // rows not encoded
  images.pop_back();
  EXPECT_THROW(DecodeGrayCode(options, images), std::invalid_argument);
}

// Structured light end to end: the test camera at half the projector's resolution sees
// projector pixel (2x, 2y) at camera pixel (x, y), through read noise and a gamma-2.2 projector.
TEST(GrayCode, CapturedThroughTheTestCameraDecodesToTheKnownMap) {
  GrayCodeOptions options;
  options.width = 128;
  options.height = 96;
  const CaptureSequence sequence = MakeGrayCodeSequence(options);
  auto display = std::make_shared<MemoryDisplay>(cv::Size(options.width, options.height));
  LoopbackOptions loopback;
  loopback.projector_gamma = 2.2;
  loopback.ambient = 0.05;
  TestCameraOptions camera_options;
  camera_options.width = 64;
  camera_options.height = 48;
  camera_options.frame_rate = 500;
  camera_options.exposure_us = 1000;
  camera_options.reference_exposure_us = 1200;
  camera_options.noise_sigma = 4;
  TestCamera camera(camera_options, MakeLoopbackView(display, loopback));
  SequencerOptions sequencer_options;
  sequencer_options.settle_ms = 2;
  sequencer_options.frames_per_pattern = 2;
  PatternSequencer sequencer(sequencer_options, &camera, display.get());
  std::vector<cv::Mat> captured;
  for (const Pattern& pattern : sequence.patterns)
    captured.push_back(sequencer.Capture(pattern.image).exposures[0].mean);
  const GrayCodeMap map = DecodeGrayCode(options, captured);
  int wrong = 0;
  for (int y = 0; y < camera_options.height; ++y) {
    for (int x = 0; x < camera_options.width; ++x) {
      wrong += map.column.at<int32_t>(y, x) != 2 * x || map.row.at<int32_t>(y, x) != 2 * y;
    }
  }
  EXPECT_EQ(wrong, 0);
}

TEST(Photometric, FlatFieldsPerChannelAndLevel) {
  PhotometricOptions options;
  options.width = 8;
  options.height = 6;
  options.levels = {0, 100, 255};
  options.channels = "gw";
  const CaptureSequence sequence = MakePhotometricSequence(options);
  ASSERT_EQ(sequence.patterns.size(), 1u + 2 * 2);
  EXPECT_EQ(sequence.patterns[0].name, "black");
  EXPECT_EQ(sequence.patterns[1].name, "flat_g_100");
  EXPECT_EQ(sequence.patterns[1].image.at<cv::Vec3b>(5, 7), cv::Vec3b(0, 100, 0));
  EXPECT_EQ(sequence.patterns[4].name, "flat_w_255");
  EXPECT_EQ(sequence.patterns[4].image.at<cv::Vec3b>(0, 0), cv::Vec3b(255, 255, 255));
  EXPECT_EQ(sequence.patterns[4].info["level"], 255);
  std::string why;
  options.channels = "rx";
  EXPECT_FALSE(options.Check(&why));
  options.channels = "r";
  options.levels = {300};
  EXPECT_FALSE(options.Check(&why));
  EXPECT_NE(why.find("[0, 255]"), std::string::npos);
}

TEST(Verify, ImagesMustExistAndMatchTheProjector) {
  testing::TempDir dir;
  const cv::Mat good(6, 8, CV_8UC3, cv::Scalar(1, 2, 3));
  ASSERT_TRUE(cv::imwrite((dir / "a good one.png").string(), good));
  ASSERT_TRUE(cv::imwrite((dir / "small.png").string(), cv::Mat(3, 4, CV_8UC3, cv::Scalar(0))));
  const CaptureSequence sequence = MakeVerifySequence({dir / "a good one.png"}, cv::Size(8, 6));
  ASSERT_EQ(sequence.patterns.size(), 1u);
  EXPECT_EQ(sequence.patterns[0].name, "image_000_a_good_one");
  EXPECT_EQ(cv::norm(sequence.patterns[0].image, good, cv::NORM_INF), 0.0);
  try {
    MakeVerifySequence({dir / "a good one.png", dir / "small.png"}, cv::Size(8, 6));
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("small.png: image is 4x3, the projector is 8x6"),
              std::string::npos)
        << error.what();
  }
  EXPECT_THROW(MakeVerifySequence({dir / "missing.png"}, cv::Size(8, 6)), IoError);
}

TEST(Patterns, ChecksumsTellPatternsApart) {
  const cv::Mat a(4, 4, CV_8UC3, cv::Scalar(1, 2, 3));
  cv::Mat b = a.clone();
  EXPECT_EQ(PatternChecksum(a), PatternChecksum(b));
  b.at<cv::Vec3b>(3, 3)[2] = 4;
  EXPECT_NE(PatternChecksum(a), PatternChecksum(b));
  EXPECT_NE(PatternChecksum(cv::Mat(4, 8, CV_8UC3, cv::Scalar(0))),
            PatternChecksum(cv::Mat(8, 4, CV_8UC3, cv::Scalar(0))));
  EXPECT_EQ(PatternChecksum(a).size(), 16u);
}

}  // namespace
}  // namespace procam
