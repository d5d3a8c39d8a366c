// Pixel-format conversion against values computed independently: known mosaics, byte orders,
// the BT.601 limited-range YUV equations and JPEG round trips.
#include "capture/pixel_format.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "base/io.h"

namespace procam {
namespace {

RawImage Raw(const std::vector<uint8_t>& bytes, int width, int height, PixelFormat format,
             size_t stride = 0) {
  RawImage raw;
  raw.data = bytes.data();
  raw.size = bytes.size();
  raw.width = width;
  raw.height = height;
  raw.format = format;
  raw.stride = stride;
  return raw;
}

TEST(PixelFormat, NamesRoundTripAndAliasesParse) {
  for (PixelFormat format : AllPixelFormats()) {
    const auto parsed = ParsePixelFormat(PixelFormatName(format));
    ASSERT_TRUE(parsed.has_value()) << PixelFormatName(format);
    EXPECT_EQ(*parsed, format);
  }
  EXPECT_EQ(ParsePixelFormat("mono8"), PixelFormat::kMono8);
  EXPECT_EQ(ParsePixelFormat("GREY"), PixelFormat::kMono8);
  EXPECT_EQ(ParsePixelFormat("Y16"), PixelFormat::kMono16);
  EXPECT_EQ(ParsePixelFormat("RGB8Packed"), PixelFormat::kRGB8);
  EXPECT_EQ(ParsePixelFormat("YUV422_8"), PixelFormat::kYUYV);
  EXPECT_EQ(ParsePixelFormat("MJPG"), PixelFormat::kMJPEG);
  EXPECT_FALSE(ParsePixelFormat("Mono12Packed").has_value());
}

TEST(PixelFormat, Mono16IsLittleEndian) {
  const std::vector<uint8_t> bytes = {0x34, 0x12, 0xff, 0x00, 0x00, 0xff, 0x01, 0x80};
  const cv::Mat image = DecodeImage(Raw(bytes, 2, 2, PixelFormat::kMono16));
  ASSERT_EQ(image.type(), CV_16UC1);
  EXPECT_EQ(image.at<uint16_t>(0, 0), 0x1234);
  EXPECT_EQ(image.at<uint16_t>(0, 1), 0x00ff);
  EXPECT_EQ(image.at<uint16_t>(1, 0), 0xff00);
  EXPECT_EQ(image.at<uint16_t>(1, 1), 0x8001);
}

TEST(PixelFormat, Rgb8BytesBecomeBgrPixels) {
  const std::vector<uint8_t> bytes = {10, 20, 30, 40, 50, 60};  // two pixels R G B
  const cv::Mat image = DecodeImage(Raw(bytes, 2, 1, PixelFormat::kRGB8));
  ASSERT_EQ(image.type(), CV_8UC3);
  EXPECT_EQ(image.at<cv::Vec3b>(0, 0), cv::Vec3b(30, 20, 10));
  EXPECT_EQ(image.at<cv::Vec3b>(0, 1), cv::Vec3b(60, 50, 40));
  const cv::Mat bgr = DecodeImage(Raw(bytes, 2, 1, PixelFormat::kBGR8));
  EXPECT_EQ(bgr.at<cv::Vec3b>(0, 0), cv::Vec3b(10, 20, 30));
}

// A uniform colour mosaicked in each of the four layouts must demosaic back to that colour.
TEST(PixelFormat, BayerMosaicsOfAUniformColourDemosaicToIt) {
  const cv::Vec3b colour(50, 100, 200);  // B, G, R
  for (PixelFormat format : {PixelFormat::kBayerRG8, PixelFormat::kBayerBG8, PixelFormat::kBayerGR8,
                             PixelFormat::kBayerGB8}) {
    // Mosaic written by hand from the layout's name (the top-left 2×2 cell): the first row is
    // the name, the second its complement (RG → GB, BG → GR, GR → BG, GB → RG).
    const std::string name = PixelFormatName(format);
    const std::string first = name.substr(5, 2);
    const std::string second = first == "RG"   ? "GB"
                               : first == "BG" ? "GR"
                               : first == "GR" ? "BG"
                                               : "RG";
    auto value_of = [](char channel) -> uint8_t {
      return channel == 'R' ? 200 : channel == 'G' ? 100 : 50;
    };
    std::vector<uint8_t> bytes(8 * 8);
    for (int y = 0; y < 8; ++y) {
      for (int x = 0; x < 8; ++x) bytes[y * 8 + x] = value_of((y % 2 == 0 ? first : second)[x % 2]);
    }
    const cv::Mat image = DecodeImage(Raw(bytes, 8, 8, format));
    ASSERT_EQ(image.type(), CV_8UC3);
    for (int y = 2; y < 6; ++y) {
      for (int x = 2; x < 6; ++x)
        EXPECT_EQ(image.at<cv::Vec3b>(y, x), colour) << name << " at " << x << "," << y;
    }
    // EncodeRaw writes the same mosaic.
    const std::vector<uint8_t> encoded =
        EncodeRaw(cv::Mat(8, 8, CV_8UC3, cv::Scalar(50, 100, 200)), format);
    EXPECT_EQ(encoded, bytes) << name;
  }
}

// BT.601 limited range: R = 1.164 (Y − 16) + 1.596 (V − 128), G = 1.164 (Y − 16) − 0.391 (U − 128)
// − 0.813 (V − 128), B = 1.164 (Y − 16) + 2.018 (U − 128).
TEST(PixelFormat, YuyvFollowsBt601LimitedRange) {
  struct Sample {
    int y, u, v;
  };
  for (const Sample& s : {Sample{16, 128, 128}, Sample{235, 128, 128}, Sample{81, 90, 240},
                          Sample{145, 54, 34}, Sample{41, 240, 110}, Sample{120, 160, 100}}) {
    const std::vector<uint8_t> bytes = {static_cast<uint8_t>(s.y), static_cast<uint8_t>(s.u),
                                        static_cast<uint8_t>(s.y), static_cast<uint8_t>(s.v)};
    const cv::Mat image = DecodeImage(Raw(bytes, 2, 1, PixelFormat::kYUYV));
    const double luma = 1.164 * (s.y - 16);
    const double expected[3] = {luma + 2.018 * (s.u - 128),
                                luma - 0.391 * (s.u - 128) - 0.813 * (s.v - 128),
                                luma + 1.596 * (s.v - 128)};
    for (int x = 0; x < 2; ++x) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(image.at<cv::Vec3b>(0, x)[c], std::clamp(expected[c], 0.0, 255.0), 2.0)
            << "Y=" << s.y << " U=" << s.u << " V=" << s.v << " channel " << c;
      }
    }
  }
}

TEST(PixelFormat, RowStrideSkipsPadding) {
  // 3×2 Mono8 rows padded to 8 bytes, as V4L2 drivers report bytesperline.
  const std::vector<uint8_t> bytes = {1, 2, 3, 99, 99, 99, 99, 99, 4, 5, 6};
  const cv::Mat image = DecodeImage(Raw(bytes, 3, 2, PixelFormat::kMono8, 8));
  EXPECT_EQ(image.at<uint8_t>(1, 0), 4);
  EXPECT_EQ(image.at<uint8_t>(1, 2), 6);
  EXPECT_EQ(cv::countNonZero(image == 99), 0);
}

TEST(PixelFormat, MjpegDecodesToTheEncodedImage) {
  cv::Mat image(48, 64, CV_8UC3);
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) image.at<cv::Vec3b>(y, x) = cv::Vec3b(4 * x, 5 * y, 128);
  }
  std::vector<uint8_t> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, 100}));
  const cv::Mat decoded = DecodeImage(Raw(jpeg, 64, 48, PixelFormat::kMJPEG));
  ASSERT_EQ(decoded.type(), CV_8UC3);
  EXPECT_LT(cv::norm(decoded, image, cv::NORM_INF), 8.0);
  EXPECT_LT(cv::norm(decoded, image, cv::NORM_L1) / (image.total() * 3), 1.5);
  // A frame whose size disagrees with the negotiated one is an error, not a silent resize.
  EXPECT_THROW(DecodeImage(Raw(jpeg, 640, 480, PixelFormat::kMJPEG)), IoError);
}

TEST(PixelFormat, ShortOrCorruptBuffersNameTheFormatAndSize) {
  const std::vector<uint8_t> bytes(100, 0);
  try {
    DecodeImage(Raw(bytes, 640, 480, PixelFormat::kYUYV));
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_NE(
        std::string(error.what()).find("YUYV frame 640x480 needs 614400 bytes, buffer has 100"),
        std::string::npos)
        << error.what();
  }
  EXPECT_THROW(DecodeImage(Raw(bytes, 10, 10, PixelFormat::kMJPEG)), IoError);
}

TEST(PixelFormat, EncodeRawInvertsDecodeForSimulatedFormats) {
  cv::Mat mono8(5, 6, CV_8UC1), mono16(5, 6, CV_16UC1), colour(5, 6, CV_8UC3);
  cv::randu(mono8, 0, 256);
  cv::randu(mono16, 0, 65536);
  cv::randu(colour, 0, 256);
  auto round_trip = [](const cv::Mat& image, PixelFormat format) {
    const std::vector<uint8_t> raw = EncodeRaw(image, format);
    return DecodeImage(Raw(raw, image.cols, image.rows, format));
  };
  EXPECT_EQ(cv::norm(round_trip(mono8, PixelFormat::kMono8), mono8, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(round_trip(mono16, PixelFormat::kMono16), mono16, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(round_trip(colour, PixelFormat::kRGB8), colour, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(round_trip(colour, PixelFormat::kBGR8), colour, cv::NORM_INF), 0.0);
  EXPECT_THROW(EncodeRaw(colour, PixelFormat::kYUYV), std::invalid_argument);
  EXPECT_THROW(EncodeRaw(mono8, PixelFormat::kRGB8), std::invalid_argument);
}

}  // namespace
}  // namespace procam
