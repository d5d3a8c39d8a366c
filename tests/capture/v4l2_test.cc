// The device-independent half of the V4L2 backend: fourcc mapping, format negotiation and
// control mapping against hand-computed answers, and the conversion of synthetic driver buffers
// (with the row padding drivers add). This machine has no /dev/video*; see README for the check
// to run with a webcam.
#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include "capture/camera.h"
#include "capture/v4l2_camera.h"
#include "capture/v4l2_mapping.h"

namespace procam {
namespace {

TEST(V4l2Mapping, FourccsMapBothWays) {
  EXPECT_EQ(FourccFromPixelFormat(PixelFormat::kYUYV), V4L2_PIX_FMT_YUYV);
  EXPECT_EQ(FourccFromPixelFormat(PixelFormat::kMJPEG), V4L2_PIX_FMT_MJPEG);
  EXPECT_EQ(FourccFromPixelFormat(PixelFormat::kBayerBG8),
            V4L2_PIX_FMT_SBGGR8);  // "BA81": B G / G R
  EXPECT_EQ(FourccFromPixelFormat(PixelFormat::kBayerRG8), V4L2_PIX_FMT_SRGGB8);
  EXPECT_EQ(PixelFormatFromFourcc(V4L2_PIX_FMT_JPEG), PixelFormat::kMJPEG);
  EXPECT_EQ(PixelFormatFromFourcc(V4L2_PIX_FMT_GREY), PixelFormat::kMono8);
  EXPECT_EQ(PixelFormatFromFourcc(V4L2_PIX_FMT_Y16), PixelFormat::kMono16);
  EXPECT_FALSE(PixelFormatFromFourcc(V4L2_PIX_FMT_NV12).has_value());
  for (PixelFormat format : AllPixelFormats())
    EXPECT_EQ(PixelFormatFromFourcc(FourccFromPixelFormat(format)), format);
  EXPECT_EQ(FourccName(V4L2_PIX_FMT_YUYV), "YUYV");
  EXPECT_EQ(FourccName(V4L2_PIX_FMT_Y16), "Y16 ");
}

// A typical UVC webcam: YUYV up to 1280×720, MJPEG up to 1920×1080, and libv4l2's emulated RGB.
const std::vector<V4l2FrameSize> kWebcam = {
    {V4L2_PIX_FMT_MJPEG, 1920, 1080, false}, {V4L2_PIX_FMT_MJPEG, 640, 480, false},
    {V4L2_PIX_FMT_YUYV, 1280, 720, false},   {V4L2_PIX_FMT_YUYV, 640, 480, false},
    {V4L2_PIX_FMT_RGB24, 1920, 1080, true},  {V4L2_PIX_FMT_NV12, 1920, 1080, false}};

TEST(V4l2Mapping, NegotiationPrefersNativeUncompressedFormatsAtTheLargestSize) {
  std::string why;
  auto choice = ChooseV4l2Format(kWebcam, {}, &why);
  ASSERT_TRUE(choice) << why;
  EXPECT_EQ(choice->fourcc, V4L2_PIX_FMT_YUYV);  // native YUYV beats emulated RGB and MJPEG
  EXPECT_EQ(choice->width, 1280);
  EXPECT_EQ(choice->height, 720);

  choice = ChooseV4l2Format(kWebcam, {PixelFormat::kMJPEG, 0, 0}, &why);
  ASSERT_TRUE(choice) << why;
  EXPECT_EQ(choice->fourcc, V4L2_PIX_FMT_MJPEG);
  EXPECT_EQ(choice->width, 1920);

  choice = ChooseV4l2Format(kWebcam, {PixelFormat::kYUYV, 640, 480}, &why);
  ASSERT_TRUE(choice) << why;
  EXPECT_EQ(choice->width, 640);

  choice =
      ChooseV4l2Format(kWebcam, {PixelFormat::kRGB8, 0, 0}, &why);  // asked for: emulated is fine
  ASSERT_TRUE(choice) << why;
  EXPECT_TRUE(choice->emulated);

  // Only emulated formats besides an undecodable one: the emulated one is taken.
  choice = ChooseV4l2Format(
      {{V4L2_PIX_FMT_NV12, 800, 600, false}, {V4L2_PIX_FMT_BGR24, 800, 600, true}}, {}, &why);
  ASSERT_TRUE(choice) << why;
  EXPECT_EQ(choice->fourcc, V4L2_PIX_FMT_BGR24);
}

TEST(V4l2Mapping, NegotiationFailuresSayWhatTheDeviceOffers) {
  std::string why;
  EXPECT_FALSE(ChooseV4l2Format(kWebcam, {PixelFormat::kMono16, 0, 0}, &why));
  EXPECT_NE(why.find("format Mono16 not offered; the device offers MJPG 1920x1080"),
            std::string::npos)
      << why;
  EXPECT_FALSE(ChooseV4l2Format(kWebcam, {PixelFormat::kYUYV, 1920, 1080}, &why));
  EXPECT_NE(why.find("size 1920x1080 not offered in YUYV"), std::string::npos) << why;
  EXPECT_FALSE(ChooseV4l2Format({{V4L2_PIX_FMT_NV12, 640, 480, false}}, {}, &why));
  EXPECT_NE(why.find("no decodable format"), std::string::npos) << why;
}

TEST(V4l2Mapping, ControlsSnapToTheirGridAndRejectOutOfRange) {
  // uvcvideo's exposure_absolute: 3 .. 2047 in 100 µs units, step 1.
  const V4l2Control exposure{true, 3, 2047, 1, 156};
  EXPECT_EQ(V4l2ExposureValue(10000, exposure), 100);  // 10 ms
  EXPECT_EQ(V4l2ExposureValue(333, exposure), 3);      // 3.33 units → 3
  EXPECT_EQ(V4l2ExposureValue(204700, exposure), 2047);
  EXPECT_FALSE(V4l2ExposureValue(100, exposure));  // 1 unit < 3
  EXPECT_FALSE(V4l2ExposureValue(300000, exposure));
  EXPECT_DOUBLE_EQ(V4l2ExposureMicroseconds(156), 15600);
  const ControlRange range = V4l2ExposureRange(exposure);
  EXPECT_TRUE(range.available);
  EXPECT_DOUBLE_EQ(range.min, 300);
  EXPECT_DOUBLE_EQ(range.max, 204700);
  EXPECT_DOUBLE_EQ(range.step, 100);

  const V4l2Control gain{true, 16, 255, 4, 32};  // grid 16, 20, 24, ...
  EXPECT_EQ(V4l2ControlValue(16, gain), 16);
  EXPECT_EQ(V4l2ControlValue(21, gain), 20);
  EXPECT_EQ(V4l2ControlValue(23, gain), 24);
  EXPECT_EQ(V4l2ControlValue(256, gain),
            252);  // within half a step of the top: the last grid value
  EXPECT_FALSE(V4l2ControlValue(300, gain));
  EXPECT_EQ(V4l2ControlValue(14, gain), 16);  // within half a step of the bottom
  EXPECT_FALSE(V4l2ControlValue(13, gain));
  EXPECT_FALSE(V4l2ControlValue(20, V4l2Control{}));  // unavailable control
  EXPECT_FALSE(V4l2GainRange(V4l2Control{}).available);
}

// A YUYV buffer as a driver delivers it, rows padded to 16 bytes: every pixel grey Y=126,
// U=V=128 decodes to 1.164·(126−16) = 128.
TEST(V4l2Mapping, PaddedYuyvDriverBuffersConvert) {
  const int width = 6, height = 3, stride = 16;
  std::vector<uint8_t> buffer(stride * height, 0xEE);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; x += 2) {
      uint8_t* pair = &buffer[y * stride + 2 * x];
      pair[0] = 126;
      pair[1] = 128;
      pair[2] = 126;
      pair[3] = 128;
    }
  }
  RawImage raw;
  raw.data = buffer.data();
  raw.size = buffer.size();
  raw.width = width;
  raw.height = height;
  raw.stride = stride;
  raw.format = PixelFormat::kYUYV;
  const cv::Mat image = DecodeImage(raw);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(image.at<cv::Vec3b>(y, x)[c], 128, 1) << x << "," << y;
    }
  }
}

TEST(V4l2Camera, UriKeysAndMissingDevicesGiveClearErrors) {
  const V4l2CameraOptions options = V4l2CameraOptionsFromUri(
      CameraUri::Parse("v4l2:/dev/video4?format=MJPG&width=1280&height=720&fps=30&buffers=3"));
  EXPECT_EQ(options.device, "/dev/video4");
  EXPECT_EQ(options.format.format, PixelFormat::kMJPEG);
  EXPECT_EQ(options.format.width, 1280);
  EXPECT_DOUBLE_EQ(options.frame_rate, 30);
  EXPECT_EQ(options.buffers, 3);
  EXPECT_THROW(V4l2CameraOptionsFromUri(CameraUri::Parse("v4l2:/dev/video0?buffers=1")), IoError);
  EXPECT_THROW(V4l2CameraOptionsFromUri(CameraUri::Parse("v4l2:/dev/video0?format=NV12")), IoError);
  try {
    V4l2CameraOptions missing;
    missing.device = "/dev/video-procam-missing";
    V4l2Camera camera(missing);
    FAIL() << "opened a missing device";
  } catch (const IoError& error) {
    EXPECT_NE(
        std::string(error.what()).find("camera 'v4l2:/dev/video-procam-missing': cannot open"),
        std::string::npos)
        << error.what();
  }
  // Listing never throws; on a machine without video devices it is empty.
  EXPECT_NO_THROW(ListV4l2Cameras());
}

}  // namespace
}  // namespace procam
