// Camera URIs, the backend registry and the software test camera's model (test_camera.h), whose
// frames are checked against the radiance, timing and buffering it is documented to follow.
#include "capture/camera.h"

#include <gtest/gtest.h>

#include <cmath>
#include <thread>

#include "capture/display.h"
#include "capture/test_camera.h"
#include "procam/config.h"

namespace procam {
namespace {

using std::chrono::milliseconds;

std::string ErrorOf(const std::function<void()>& action) {
  try {
    action();
  } catch (const std::exception& error) {
    return error.what();
  }
  return "";
}

SceneView Flat(float radiance) {
  return [radiance](int64_t) { return cv::Mat(4, 4, CV_32FC1, cv::Scalar(radiance)); };
}

TEST(CameraUri, ParsesSchemePathAndParameters) {
  const CameraUri uri = CameraUri::Parse("v4l2:/dev/video2?format=YUYV&width=1280&fps=7.5");
  EXPECT_EQ(uri.scheme(), "v4l2");
  EXPECT_EQ(uri.path(), "/dev/video2");
  EXPECT_EQ(uri.GetString("format", ""), "YUYV");
  EXPECT_EQ(uri.GetInt("width", 0), 1280);
  EXPECT_DOUBLE_EQ(uri.GetDouble("fps", 0), 7.5);
  EXPECT_EQ(uri.GetInt("height", 480), 480);  // absent: the fallback
  EXPECT_NO_THROW(uri.CheckAllRead());
  EXPECT_EQ(CameraUri::Parse("aravis:Fake_1").path(), "Fake_1");
}

TEST(CameraUri, RejectsMalformedUrisWithTheUriInTheMessage) {
  EXPECT_NE(ErrorOf([] {
              CameraUri::Parse("/dev/video0");
            }).find("camera '/dev/video0': expected <backend>:<device>"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { CameraUri::Parse("test:x?noise"); }).find("'noise' is not key=value"),
            std::string::npos);
  const CameraUri uri = CameraUri::Parse("test:x?width=abc&hieght=3");
  EXPECT_NE(ErrorOf([&] { uri.GetInt("width", 0); }).find("width=abc is not a number"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { uri.CheckAllRead(); }).find("unknown parameter 'hieght'"),
            std::string::npos);
}

TEST(CameraRegistry, MissingBackendsFailWithOneLineNamingThem) {
  const std::string synthetic = ErrorOf([] { OpenCamera("synthetic:room.json"); });
  EXPECT_NE(synthetic.find("backend 'synthetic' is not available"), std::string::npos) << synthetic;
  const std::string unknown = ErrorOf([] { OpenCamera("gphoto:canon"); });
  EXPECT_NE(unknown.find("unknown camera backend 'gphoto'"), std::string::npos) << unknown;
  // Without RegisterDeviceBackends(), device backends are missing; the message says whether
  // this build has them.
  const std::string aravis = ErrorOf([] { OpenCamera("aravis:Fake_1"); });
  EXPECT_NE(aravis.find(PROCAM_WITH_ARAVIS ? "built but not registered"
                                           : "built without the Aravis backend"),
            std::string::npos)
      << aravis;
  const std::string v4l2 = ErrorOf([] { OpenCamera("v4l2:/dev/video0"); });
  EXPECT_NE(
      v4l2.find(PROCAM_WITH_V4L2 ? "built but not registered" : "built without the V4L2 backend"),
      std::string::npos)
      << v4l2;
  for (const std::string& message : {synthetic, unknown, aravis, v4l2})
    EXPECT_EQ(message.find('\n'), std::string::npos);
}

TEST(CameraRegistry, RegisteredBackendsOpenAndList) {
  CameraBackend backend;
  backend.scheme = "unittest";
  backend.open = [](const CameraUri& uri,
                    const OpenCameraOptions& options) -> std::unique_ptr<Camera> {
    TestCameraOptions test;
    test.name = uri.path();
    return std::make_unique<TestCamera>(test, options.scene_view);
  };
  backend.list = [](const ListCamerasOptions&) {
    CameraInfo info;
    info.uri = "unittest:one";
    return std::vector<CameraInfo>{info};
  };
  RegisterCameraBackend(backend);
  const auto schemes = RegisteredCameraBackends();
  EXPECT_NE(std::find(schemes.begin(), schemes.end(), "unittest"), schemes.end());
  EXPECT_NE(std::find(schemes.begin(), schemes.end(), "test"), schemes.end());
  EXPECT_EQ(OpenCamera("unittest:abc")->Info().serial, "abc");
  ListCamerasOptions list;
  list.gige_discovery = false;
  list.include_virtual = true;
  bool found_unittest = false, found_test = false;
  for (const CameraInfo& info : ListCameras(list)) {
    found_unittest |= info.uri == "unittest:one";
    found_test |= info.uri == "test:loopback";
  }
  EXPECT_TRUE(found_unittest);
  EXPECT_TRUE(found_test);
}

TEST(TestCamera, UriKeysConfigureItAndTyposAreErrors) {
  const auto camera = OpenCamera("test:cam7?format=Mono16&width=64&height=32&fps=200&noise=3");
  const CameraSettings settings = camera->Settings();
  EXPECT_EQ(settings.width, 64);
  EXPECT_EQ(settings.height, 32);
  EXPECT_EQ(settings.pixel_format, PixelFormat::kMono16);
  EXPECT_EQ(camera->Info().uri, "test:cam7");
  EXPECT_NE(ErrorOf([] { OpenCamera("test:x?nosie=3"); }).find("unknown parameter 'nosie'"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { OpenCamera("test:x?format=YUYV"); }).find("cannot be simulated"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { OpenCamera("test:x?format=BayerRG8&width=63"); }).find("even width"),
            std::string::npos);
}

// DN = radiance · full scale · (t / t_ref) · 10^(gain/20), rounded.
TEST(TestCamera, DigitalNumbersFollowRadianceExposureAndGain) {
  TestCameraOptions options;
  options.width = 8;
  options.height = 6;
  options.frame_rate = 500;
  options.exposure_us = 1000;
  options.reference_exposure_us = 4000;
  TestCamera camera(options, Flat(0.4f));
  EXPECT_NEAR(camera.Grab(milliseconds(500)).image.at<uint8_t>(3, 3), std::lround(0.4 * 255 * 0.25),
              0);
  // Frames finished before a change keep the old settings (as on a real camera): drop them.
  camera.SetExposure(2000);
  camera.DropBufferedFrames();
  Frame frame = camera.Grab(milliseconds(500));
  EXPECT_EQ(frame.image.at<uint8_t>(0, 0), std::lround(0.4 * 255 * 0.5));
  EXPECT_DOUBLE_EQ(frame.exposure_us, 2000);
  camera.SetGain(20 * std::log10(1.6));
  camera.DropBufferedFrames();
  frame = camera.Grab(milliseconds(500));
  EXPECT_EQ(frame.image.at<uint8_t>(5, 7), std::lround(0.4 * 255 * 0.5 * 1.6));
  camera.SetExposure(40000);  // 0.4 · 10 · 1.6 = 6.4 times full scale: clipped
  camera.DropBufferedFrames();
  EXPECT_EQ(camera.Grab(milliseconds(500)).image.at<uint8_t>(2, 2), 255);
  EXPECT_THROW(camera.SetExposure(1), IoError);
  EXPECT_THROW(camera.SetGain(30), IoError);
}

TEST(TestCamera, ColourViewsThroughABayerSensorComeBackInColour) {
  TestCameraOptions options;
  options.width = 16;
  options.height = 12;
  options.frame_rate = 500;
  options.pixel_format = PixelFormat::kBayerGB8;
  const cv::Vec3f radiance(0.2f, 0.5f, 0.9f);  // B, G, R
  TestCamera camera(options, [radiance](int64_t) {
    return cv::Mat(3, 3, CV_32FC3, cv::Scalar(radiance[0], radiance[1], radiance[2]));
  });
  const Frame frame = camera.Grab(milliseconds(500));
  ASSERT_EQ(frame.image.type(), CV_8UC3);
  for (int c = 0; c < 3; ++c)
    EXPECT_NEAR(frame.image.at<cv::Vec3b>(6, 8)[c], radiance[c] * 255, 1.0) << c;
  // A mono sensor sees Rec. 709 luma.
  options.pixel_format = PixelFormat::kMono8;
  TestCamera mono(options, [radiance](int64_t) {
    return cv::Mat(3, 3, CV_32FC3, cv::Scalar(radiance[0], radiance[1], radiance[2]));
  });
  EXPECT_NEAR(mono.Grab(milliseconds(500)).image.at<uint8_t>(6, 8),
              (0.0722 * 0.2 + 0.7152 * 0.5 + 0.2126 * 0.9) * 255, 1.0);
}

// What real photographs have besides noise (test_camera.h), each against its closed form.
// A unit step from 0 to 1 between columns 15 and 16, blurred by a Gaussian of σ pixels (sampled
// at the pixels and normalised), reads Σ_{k ≥ 16} g(x − k) at column x, g(j) ∝ exp(−j²/2σ²).
// Mono16 resolves that to 1e-5; a kernel cut at 3σ or more changes it by under 3e-3.
double BlurredStep(int x, double sigma) {
  double above = 0.0, all = 0.0;
  for (int k = x - 50; k <= x + 50; ++k) {
    const double g = std::exp(-(x - k) * (x - k) / (2.0 * sigma * sigma));
    all += g;
    if (k >= 16) above += g;
  }
  return above / all;
}

cv::Mat Step(int width, int height) {
  cv::Mat step(height, width, CV_32FC1, cv::Scalar(0.0f));
  step.colRange(16, width) = 1.0f;
  return step;
}

TEST(TestCamera, DefocusAmbientLightAndJpegFollowTheirModels) {
  TestCameraOptions options;
  options.width = 32;
  options.height = 8;
  options.pixel_format = PixelFormat::kMono16;
  PhotographSettings settings;
  settings.width = options.width;
  settings.height = options.height;
  settings.pixel_format = options.pixel_format;
  cv::RNG rng(1);
  const double full = 65535.0;

  // Camera defocus, and ambient light added before it (a constant stays constant).
  options.camera_blur_px = 2.0;
  options.ambient = 0.25;
  settings.exposure_us = options.reference_exposure_us / 2;  // so that 1.25 does not clip
  cv::Mat photo = PhotographRadiance(Step(32, 8), options, settings, rng);
  for (int x = 8; x < 24; ++x)
    EXPECT_NEAR(photo.at<uint16_t>(4, x) / full, 0.5 * (0.25 + BlurredStep(x, 2.0)), 0.003) << x;

  // Projector defocus belongs to the view: the test camera, whose view is the display's image,
  // blurs it in the view's pixels before resampling (here 2 camera pixels per view pixel).
  options.camera_blur_px = 0.0;
  options.ambient = 0.0;
  options.projector_blur_px = 1.5;
  options.width = settings.width = 64;
  options.frame_rate = 500;
  TestCamera camera(options, [](int64_t) { return Step(32, 8); });
  photo = camera.Grab(milliseconds(500)).image;
  for (int x = 8; x < 24; ++x) {
    EXPECT_NEAR(photo.at<uint16_t>(4, 2 * x) / full, BlurredStep(x, 1.5), 0.003) << x;
    EXPECT_EQ(photo.at<uint16_t>(4, 2 * x), photo.at<uint16_t>(4, 2 * x + 1)) << x;
  }

  // JPEG: a smooth ramp survives quality 95 within a few DN; random texture at quality 10 loses
  // most of its detail (8×8 blocks of few coefficients); colour stays colour.
  TestCameraOptions jpeg;
  jpeg.width = settings.width = 64;
  jpeg.height = settings.height = 64;
  jpeg.pixel_format = settings.pixel_format = PixelFormat::kBGR8;
  settings.exposure_us = jpeg.reference_exposure_us;
  cv::Mat ramp(64, 64, CV_32FC3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) ramp.at<cv::Vec3f>(y, x) = cv::Vec3f(0.2f, 0.2f + x / 128.0f, 0.7f - y / 128.0f);
  const cv::Mat exact = PhotographRadiance(ramp, jpeg, settings, rng);
  jpeg.jpeg_quality = 95;
  const cv::Mat compressed = PhotographRadiance(ramp, jpeg, settings, rng);
  ASSERT_EQ(compressed.type(), CV_8UC3);
  EXPECT_LE(cv::norm(exact, compressed, cv::NORM_INF), 6.0);
  EXPECT_LE(cv::norm(exact, compressed, cv::NORM_L1) / exact.total() / 3, 1.0);  // mean, DN
  EXPECT_GT(cv::norm(exact, compressed, cv::NORM_INF), 0.0) << "the JPEG round trip ran";
  cv::Mat texture(64, 64, CV_32FC1);
  rng.fill(texture, cv::RNG::UNIFORM, 0.0, 1.0);
  jpeg.pixel_format = settings.pixel_format = PixelFormat::kMono8;
  jpeg.jpeg_quality = 0;
  const cv::Mat sharp = PhotographRadiance(texture, jpeg, settings, rng);
  jpeg.jpeg_quality = 10;
  const cv::Mat blocky = PhotographRadiance(texture, jpeg, settings, rng);
  ASSERT_EQ(blocky.type(), CV_8UC1);
  // Uniform noise has σ = 255/√12 ≈ 74 DN; what is left of it differs from it by most of that.
  EXPECT_GT(cv::norm(sharp, blocky, cv::NORM_L2) / 64.0, 30.0);
  EXPECT_NEAR(cv::mean(blocky)[0], cv::mean(sharp)[0], 3.0);  // the DC terms survive
}

TEST(TestCamera, DefectSettingsAreCheckedByName) {
  EXPECT_NE(ErrorOf([] { OpenCamera("test:x?projector_blur=21"); }).find("projector_blur must be in [0, 20]"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { OpenCamera("test:x?camera_blur=-1"); }).find("camera_blur must be in [0, 20]"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { OpenCamera("test:x?ambient=11"); }).find("ambient must be in [0, 10]"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { OpenCamera("test:x?jpeg_quality=101"); }).find("jpeg_quality must be in [1, 100]"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { OpenCamera("test:x?jpeg_quality=90&format=BayerRG8"); })
                .find("jpeg_quality needs an 8-bit Mono8, RGB8 or BGR8 format, not BayerRG8"),
            std::string::npos);
  const auto camera = OpenCamera("test:x?jpeg_quality=90&format=RGB8&ambient=0.1&camera_blur=1&projector_blur=2");
  EXPECT_EQ(camera->Settings().pixel_format, PixelFormat::kRGB8);
}

TEST(TestCamera, NoiseHasTheConfiguredSpread) {
  TestCameraOptions options;
  options.width = 200;
  options.height = 100;
  options.frame_rate = 1000;
  options.pixel_format = PixelFormat::kMono16;
  options.noise_sigma = 40;
  TestCamera camera(options, Flat(0.5f));
  const Frame frame = camera.Grab(milliseconds(500));
  cv::Scalar mean, deviation;
  cv::meanStdDev(frame.image, mean, deviation);
  EXPECT_NEAR(mean[0], 0.5 * 65535, 2.0);
  EXPECT_NEAR(deviation[0], 40, 40 * 0.05);
}

TEST(TestCamera, FramesAreTimedByTheFrameRateAndSeeTheSceneAtTheirExposureStart) {
  TestCameraOptions options;
  options.width = 4;
  options.height = 4;
  options.frame_rate = 100;
  options.exposure_us = 2000;
  options.reference_exposure_us = 2000;
  // The view reports the time it was asked about, in milliseconds since `origin`, as radiance.
  const int64_t origin = SteadyNowNs();
  TestCamera camera(options, [origin](int64_t time_ns) {
    return cv::Mat(1, 1, CV_32FC1, cv::Scalar((time_ns - origin) * 1e-6 / 255.0));
  });
  Frame previous = camera.Grab(milliseconds(500));
  for (int i = 0; i < 5; ++i) {
    const Frame frame = camera.Grab(milliseconds(500));
    EXPECT_EQ(frame.sequence, previous.sequence + 1);
    EXPECT_EQ(frame.exposure_start_ns - previous.exposure_start_ns, 10000000);  // 1 / 100 Hz
    EXPECT_EQ(frame.arrival_ns - frame.exposure_start_ns, 2000000);
    EXPECT_LE(frame.arrival_ns, SteadyNowNs());
    EXPECT_NEAR(frame.image.at<uint8_t>(0, 0), (frame.exposure_start_ns - origin) * 1e-6,
                0.5 + 1e-9);
    previous = frame;
  }
}

// Like a V4L2 driver, full buffers keep the oldest frames: a reader that waited gets stale ones
// until it drops them.
TEST(TestCamera, FullBuffersKeepStaleFramesUntilDropped) {
  TestCameraOptions options;
  options.width = 4;
  options.height = 4;
  options.frame_rate = 200;
  options.exposure_us = 1000;
  options.reference_exposure_us = 1000;
  options.buffers = 3;
  auto display = std::make_shared<MemoryDisplay>(cv::Size(4, 4));
  TestCamera camera(options, MakeLoopbackView(display));
  display->Show(cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(40)));
  camera.Start();
  std::this_thread::sleep_for(milliseconds(60));  // ≥ 12 frames of 5 ms: 3 kept, the rest overrun
  display->Show(cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(200)));
  const int64_t shown = SteadyNowNs();
  for (int i = 0; i < 3; ++i) {
    const Frame stale = camera.Grab(milliseconds(500));
    EXPECT_LT(stale.exposure_start_ns, shown);
    EXPECT_EQ(stale.image.at<uint8_t>(0, 0), 40) << i;
  }
  EXPECT_GE(camera.frames_overrun(), 5);
  std::this_thread::sleep_for(milliseconds(30));
  EXPECT_GE(camera.DropBufferedFrames(), 1);
  const Frame fresh = camera.Grab(milliseconds(500));
  EXPECT_GE(fresh.exposure_start_ns, shown);
  EXPECT_EQ(fresh.image.at<uint8_t>(0, 0), 200);
}

TEST(TestCamera, InjectedTimeoutsAndDisconnectionsStrikeAfterTheConfiguredFrames) {
  auto timeouts =
      OpenCamera("test:flaky?fps=500&width=4&height=4&fault=timeout&fault_after=2&fault_grabs=2");
  EXPECT_NO_THROW(timeouts->Grab(milliseconds(200)));
  EXPECT_NO_THROW(timeouts->Grab(milliseconds(200)));
  const int64_t before = SteadyNowNs();
  EXPECT_THROW(timeouts->Grab(milliseconds(30)), CameraTimeout);
  EXPECT_GE(SteadyNowNs() - before, 30000000);  // it waited its timeout
  EXPECT_THROW(timeouts->Grab(milliseconds(30)), CameraTimeout);
  EXPECT_NO_THROW(timeouts->Grab(milliseconds(200)));  // recovered after 2 failing grabs

  auto vanishing = OpenCamera("test:gone?fps=500&width=4&height=4&fault=disconnect&fault_after=1");
  EXPECT_NO_THROW(vanishing->Grab(milliseconds(200)));
  const std::string message = ErrorOf([&] { vanishing->Grab(milliseconds(200)); });
  EXPECT_NE(message.find("camera 'test:gone': device disappeared"), std::string::npos) << message;
  EXPECT_THROW(vanishing->Grab(milliseconds(200)), CameraDisconnected);
  EXPECT_THROW(vanishing->Start(), CameraDisconnected);
}

}  // namespace
}  // namespace procam
