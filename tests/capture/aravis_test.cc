// The Aravis backend against Aravis's in-process Fake camera. GigE Vision discovery is switched
// off before anything else: it would broadcast on every network interface.
//
// Truth: the Fake camera fills Mono8 frames with the diagonal ramp
//   DN(x, y) = min(255, ((x + y + frame id) mod 255) · (1 + gain + log10(exposure_us / 10000)))
// and Mono16 frames whose high byte is ((x + y + frame id) mod 65535) mod 256 (measured on
// Aravis 0.8.26: a 16-bit ramp shifted up by 8 bits, low byte 255).
#include <arv.h>
#include <gtest/gtest.h>

#include <cmath>
#include <thread>

#include "capture/aravis_camera.h"
#include "capture/devices.h"
#include "capture/display.h"
#include "capture/sequencer.h"
#include "capture/session.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using std::chrono::milliseconds;

class AravisFake : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    arv_disable_interface("GigEVision");  // first: never broadcast
    arv_enable_interface("Fake");
    RegisterDeviceBackends();
  }

  static std::unique_ptr<Camera> Open(const std::string& parameters = "") {
    return OpenCamera("aravis:Fake_1" + parameters);
  }

  static AravisCamera& AsAravis(Camera& camera) { return dynamic_cast<AravisCamera&>(camera); }

  // Frames filled before a settings change may still be queued: wait two frame periods (25 Hz)
  // and drop them.
  static void LetSettingsApply(Camera& camera) {
    std::this_thread::sleep_for(milliseconds(100));
    camera.DropBufferedFrames();
  }
};

int Ramp(int x, int y, uint64_t frame_id) { return static_cast<int>((x + y + frame_id) % 255); }

// Pixels of a Mono8 frame (any depth) that differ from the scaled ramp by more than 1.
int CountRampMismatches(const cv::Mat& image, uint64_t frame_id, double scale) {
  cv::Mat values;
  image.convertTo(values, CV_32F);
  int mismatches = 0;
  for (int y = 0; y < values.rows; ++y) {
    for (int x = 0; x < values.cols; ++x) {
      const double expected = std::floor(std::min(255.0, Ramp(x, y, frame_id) * scale));
      mismatches += std::abs(values.at<float>(y, x) - expected) > 1;
    }
  }
  return mismatches;
}

TEST_F(AravisFake, ListsTheFakeCameraWithoutDiscovery) {
  ListCamerasOptions options;
  options.gige_discovery = false;
  options.include_virtual = true;
  bool found = false;
  for (const CameraInfo& info : ListAravisCameras(options)) found |= info.uri == "aravis:Fake_1";
  EXPECT_TRUE(found);
}

TEST_F(AravisFake, OpensWithSoftwareTriggerAndReportsItsFeatures) {
  const auto camera = Open("?format=Mono8&buffers=4");
  const CameraInfo info = camera->Info();
  EXPECT_EQ(info.uri, "aravis:Fake_1");
  EXPECT_EQ(info.vendor, "Aravis");
  EXPECT_EQ(info.model, "Fake");
  const CameraSettings settings = camera->Settings();
  EXPECT_EQ(settings.width, 512);
  EXPECT_EQ(settings.height, 512);
  EXPECT_EQ(settings.pixel_format, PixelFormat::kMono8);
  EXPECT_EQ(settings.trigger, "software");
  EXPECT_DOUBLE_EQ(settings.exposure_us, 10000);
  EXPECT_TRUE(settings.exposure_range_us.available);
  EXPECT_TRUE(settings.gain_range.available);
  const auto formats = camera->SupportedPixelFormats();
  for (PixelFormat format :
       {PixelFormat::kMono8, PixelFormat::kMono16, PixelFormat::kBayerRG8, PixelFormat::kRGB8}) {
    EXPECT_NE(std::find(formats.begin(), formats.end(), format), formats.end())
        << PixelFormatName(format);
  }
  EXPECT_THROW(camera->SetExposure(1), IoError);  // below the ExposureTime minimum (10 µs)
  EXPECT_THROW(camera->SetGain(100), IoError);
  EXPECT_THROW(OpenCamera("aravis:Fake_1?trigger=sometimes"), IoError);
}

TEST_F(AravisFake, Mono8FramesAreTheDiagonalRamp) {
  const auto camera = Open("?format=Mono8");
  Frame previous = camera->Grab(milliseconds(2000));
  for (int i = 0; i < 3; ++i) {
    const Frame frame = camera->Grab(milliseconds(2000));
    ASSERT_EQ(frame.image.type(), CV_8UC1);
    EXPECT_EQ(CountRampMismatches(frame.image, frame.sequence, 1.0), 0);
    EXPECT_GT(frame.sequence, previous.sequence);
    EXPECT_GT(frame.arrival_ns, previous.arrival_ns);
    EXPECT_NEAR(static_cast<double>(frame.arrival_ns), static_cast<double>(SteadyNowNs()), 2e9);
    EXPECT_EQ(frame.exposure_start_ns, frame.arrival_ns - 10000000);
    EXPECT_GT(frame.device_timestamp_ns, 0);
    previous = frame;
  }
}

TEST_F(AravisFake, GainAndExposureReachTheSensor) {
  const auto camera = Open("?format=Mono8");
  camera->Grab(milliseconds(2000));
  camera->SetGain(1.0);  // scale 1 + 1 = 2
  LetSettingsApply(*camera);
  Frame frame = camera->Grab(milliseconds(2000));
  EXPECT_DOUBLE_EQ(frame.gain, 1.0);
  EXPECT_DOUBLE_EQ(camera->Settings().gain, 1.0);
  EXPECT_EQ(CountRampMismatches(frame.image, frame.sequence, 2.0), 0);
  camera->SetGain(0.0);
  camera->SetExposure(100000);  // scale 1 + log10(10) = 2
  LetSettingsApply(*camera);
  frame = camera->Grab(milliseconds(2000));
  EXPECT_DOUBLE_EQ(frame.exposure_us, 100000);
  EXPECT_EQ(CountRampMismatches(frame.image, frame.sequence, 2.0), 0);
}

TEST_F(AravisFake, PixelFormatsDecode) {
  const auto camera = Open("?format=Mono16");
  Frame frame = camera->Grab(milliseconds(2000));
  ASSERT_EQ(frame.image.type(), CV_16UC1);
  int mismatches = 0;
  for (int y = 0; y < frame.image.rows; y += 7) {
    for (int x = 0; x < frame.image.cols; x += 5) {
      const uint64_t expected = ((x + y + frame.sequence) % 65535) % 256;
      mismatches += (frame.image.at<uint16_t>(y, x) >> 8) != expected;
    }
  }
  EXPECT_EQ(mismatches, 0);
  for (PixelFormat format : {PixelFormat::kRGB8, PixelFormat::kBayerRG8, PixelFormat::kBayerGB8}) {
    camera->SetPixelFormat(format);
    EXPECT_EQ(camera->Settings().pixel_format, format);
    frame = camera->Grab(milliseconds(2000));
    EXPECT_EQ(frame.source_format, format);
    EXPECT_EQ(frame.image.type(), CV_8UC3);
    EXPECT_EQ(frame.image.size(), cv::Size(512, 512));
  }
}

// The sequencer's average of Fake frames equals the average of the ramps of the frame ids it
// reports.
TEST_F(AravisFake, SequencerAveragesTheFramesItReports) {
  const auto camera = Open("?format=Mono8");
  MemoryDisplay display(cv::Size(8, 8));
  SequencerOptions options;
  options.settle_ms = 0;
  options.frames_per_pattern = 3;
  options.max_changed_fraction = 1.0;  // the fake camera's ramp moves every frame, by design
  PatternSequencer sequencer(options, camera.get(), &display);
  const PatternCapture capture = sequencer.Capture(cv::Mat(8, 8, CV_8UC3, cv::Scalar::all(255)));
  const ExposureCapture& exposure = capture.exposures[0];
  ASSERT_EQ(exposure.sequences.size(), 3u);
  double worst = 0;
  for (int y = 0; y < 512; y += 3) {
    for (int x = 0; x < 512; x += 3) {
      double expected = 0;
      for (uint64_t id : exposure.sequences) expected += Ramp(x, y, id) / 3.0;
      worst = std::max(worst, std::abs(exposure.mean.at<float>(y, x) - expected));
    }
  }
  EXPECT_LT(worst, 1e-3);
}

TEST_F(AravisFake, LostControlBecomesADisconnection) {
  const auto camera = Open();
  camera->Grab(milliseconds(2000));
  g_signal_emit_by_name(arv_camera_get_device(AsAravis(*camera).handle()), "control-lost");
  try {
    camera->Grab(milliseconds(2000));
    FAIL() << "no error";
  } catch (const CameraDisconnected& error) {
    EXPECT_NE(std::string(error.what()).find("camera 'aravis:Fake_1': lost the connection"),
              std::string::npos)
        << error.what();
  }
  EXPECT_THROW(camera->Start(), CameraDisconnected);
}

// A stream whose frames no longer fit the buffers (the Fake camera's Width doubled behind our
// back) yields only incomplete buffers: a timeout that says why.
TEST_F(AravisFake, ABrokenStreamTimesOutSayingWhy) {
  const auto camera = Open("?format=Mono8");
  camera->Grab(milliseconds(2000));
  GError* error = nullptr;
  arv_camera_set_integer(AsAravis(*camera).handle(), "Width", 1024, &error);
  ASSERT_EQ(error, nullptr);
  LetSettingsApply(*camera);
  try {
    camera->Grab(milliseconds(300));
    FAIL() << "no timeout";
  } catch (const CameraTimeout& timeout) {
    EXPECT_NE(std::string(timeout.what()).find("size mismatch"), std::string::npos)
        << timeout.what();
  }
}

// A display that, on its n-th pattern, makes the Fake camera lose its connection.
class SabotagingDisplay : public MemoryDisplay {
 public:
  SabotagingDisplay(cv::Size size, int fail_at, ArvCamera* victim)
      : MemoryDisplay(size), fail_at_(fail_at), victim_(victim) {}
  void Show(const cv::Mat& pattern) override {
    MemoryDisplay::Show(pattern);
    if (shown_count() == fail_at_)
      g_signal_emit_by_name(arv_camera_get_device(victim_), "control-lost");
  }

 private:
  int fail_at_;
  ArvCamera* victim_;
};

TEST_F(AravisFake, SessionInterruptedByALostCameraResumesWithANewOne) {
  testing::TempDir dir;
  GrayCodeOptions gray;
  gray.width = 4;
  gray.height = 2;
  const CaptureSequence sequence = MakeGrayCodeSequence(gray);  // 2 + 2·(2 + 1) = 8 patterns
  ASSERT_EQ(sequence.patterns.size(), 8u);
  CaptureSessionOptions options;
  options.directory = dir.path();
  options.sequencer.settle_ms = 0;
  options.sequencer.frames_per_pattern = 1;
  options.sequencer.max_retries = 1;
  options.sequencer.retry_delay_ms = 1;
  {
    const auto camera = Open("?format=Mono8");
    SabotagingDisplay display(cv::Size(4, 2), 4, AsAravis(*camera).handle());
    try {
      RunCaptureSession(options, sequence, *camera, display);
      FAIL() << "no fault";
    } catch (const CaptureFault& fault) {
      const std::string message = fault.what();
      EXPECT_NE(message.find("lost the connection"), std::string::npos) << message;
      EXPECT_NE(message.find("at pattern 4/8"), std::string::npos) << message;
      EXPECT_NE(message.find("3 captured patterns are kept"), std::string::npos) << message;
    }
  }
  const CaptureSessionData interrupted = CaptureSessionData::Load(dir.path());
  for (int i = 0; i < 8; ++i) EXPECT_EQ(interrupted.captured(i), i < 3) << i;

  const auto camera = Open("?format=Mono8");
  MemoryDisplay display(cv::Size(4, 2));
  const CaptureSummary summary = RunCaptureSession(options, sequence, *camera, display);
  EXPECT_EQ(summary.patterns_before, 3);
  EXPECT_EQ(summary.patterns_captured, 5);
  const CaptureSessionData resumed = CaptureSessionData::Load(dir.path());
  EXPECT_TRUE(resumed.complete());
  for (int i = 0; i < 8; ++i) {
    const uint64_t id =
        resumed.manifest()["patterns"][i]["captured"]["exposures"][0]["sequences"][0]
            .get<uint64_t>();
    EXPECT_EQ(CountRampMismatches(resumed.Mean(i), id, 1.0), 0) << "pattern " << i;
  }
}

}  // namespace
}  // namespace procam
