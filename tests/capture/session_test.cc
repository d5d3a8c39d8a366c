// Capture sessions: what a complete session holds, and that a session interrupted by a camera
// fault keeps every captured pattern, records why it stopped, and resumes where it stopped.
#include "capture/session.h"

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "capture/display.h"
#include "capture/test_camera.h"
#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

namespace fs = std::filesystem;

TestCameraOptions SessionCamera(TestCameraOptions::Fault fault = TestCameraOptions::Fault::kNone,
                                int fault_after = 0) {
  TestCameraOptions options;
  options.name = "session";
  options.width = 24;
  options.height = 16;
  options.frame_rate = 500;
  options.exposure_us = 1000;
  options.reference_exposure_us = 1000;
  options.fault = fault;
  options.fault_after_frames = fault_after;
  return options;
}

CaptureSessionOptions Options(const fs::path& directory) {
  CaptureSessionOptions options;
  options.directory = directory;
  options.sequencer.settle_ms = 2;
  options.sequencer.frames_per_pattern = 2;
  options.sequencer.grab_timeout_ms = 50;
  options.sequencer.retry_delay_ms = 1;
  options.sequencer.max_retries = 2;
  return options;
}

CaptureSequence Photometric() {
  PhotometricOptions options;
  options.width = 12;
  options.height = 8;
  options.levels = {0, 60, 120, 250};
  options.channels = "rw";
  return MakePhotometricSequence(options);  // black + 2 channels × 3 levels = 7 patterns
}

// What a pattern's flat field must read in a Mono8 test camera: the Rec. 709 luma of its colour.
double ExpectedLuma(const cv::Mat& pattern) {
  const cv::Vec3b bgr = pattern.at<cv::Vec3b>(0, 0);
  return 0.0722 * bgr[0] + 0.7152 * bgr[1] + 0.2126 * bgr[2];
}

std::string Bytes(const fs::path& path) { return ReadFile(path); }

// The file of `pattern`'s first exposure in the session in `dir`.
fs::path FrameFile(const fs::path& dir, int pattern) {
  const CaptureSessionData data = CaptureSessionData::Load(dir);
  return dir / data.manifest()["patterns"][pattern]["captured"]["exposures"][0]["file"]
                   .get<std::string>();
}

// Resumes the complete photometric session in `dir` after `pattern`'s frame was damaged: that
// pattern alone is captured again, and reads as the camera sees it.
void ExpectResumeRecapturesOnly(const fs::path& dir, const CaptureSequence& sequence,
                                TestCamera& camera, MemoryDisplay& display, int pattern) {
  const CaptureSummary summary = RunCaptureSession(Options(dir), sequence, camera, display);
  EXPECT_EQ(summary.patterns_before, 6);
  EXPECT_EQ(summary.patterns_captured, 1);
  double low = 0;
  cv::minMaxLoc(CaptureSessionData::Load(dir).Mean(pattern), &low);
  EXPECT_NEAR(low, ExpectedLuma(sequence.patterns[pattern].image), 0.501);
}

// A session.json pattern without a "captured" key aborted captured() on an assertion of
// nlohmann::json (found by fuzz_session; the input is fuzz/regressions/session/).
TEST(CaptureSessionData, PatternWithoutCapturedKeyIsNotCaptured) {
  const auto dir = testing::SourceDir() / "fuzz/regressions/session/pattern_without_captured";
  const CaptureSessionData session = CaptureSessionData::Load(dir);
  int captured = 0;
  for (int pattern = 0; pattern < session.pattern_count(); ++pattern) captured += session.captured(pattern);
  EXPECT_FALSE(session.captured(0));
  EXPECT_EQ(captured, session.pattern_count() - 1);
}

TEST(CaptureSession, CompleteSessionHoldsPatternsFramesAndManifest) {
  testing::TempDir dir;
  const CaptureSequence sequence = Photometric();
  auto display = std::make_shared<MemoryDisplay>(cv::Size(12, 8));
  TestCamera camera(SessionCamera(), MakeLoopbackView(display));
  const CaptureSummary summary = RunCaptureSession(Options(dir.path()), sequence, camera, *display);
  EXPECT_EQ(summary.patterns_total, 7);
  EXPECT_EQ(summary.patterns_captured, 7);
  EXPECT_EQ(summary.patterns_before, 0);
  EXPECT_NE(summary.BriefReport().find("7/7 patterns captured"), std::string::npos);

  const CaptureSessionData data = CaptureSessionData::Load(dir.path());
  EXPECT_TRUE(data.complete());
  ASSERT_EQ(data.pattern_count(), 7);
  const nlohmann::json& manifest = data.manifest();
  EXPECT_EQ(manifest["sequence"]["kind"], "photometric");
  EXPECT_EQ(manifest["camera"]["device"], "test:session");
  EXPECT_EQ(manifest["camera"]["settings"]["pixel_format"], "Mono8");
  EXPECT_EQ(manifest["capture"]["frames_per_pattern"], 2);
  EXPECT_EQ(manifest["display"]["width"], 12);
  EXPECT_EQ(manifest["runs"].size(), 1u);
  EXPECT_TRUE(manifest["interruptions"].empty());
  for (int i = 0; i < 7; ++i) {
    EXPECT_EQ(data.pattern_name(i), sequence.patterns[i].name);
    const nlohmann::json& entry = manifest["patterns"][i];
    const cv::Mat shown =
        cv::imread((dir.path() / entry["file"].get<std::string>()).string(), cv::IMREAD_COLOR);
    EXPECT_EQ(cv::norm(shown, sequence.patterns[i].image, cv::NORM_INF), 0.0)
        << "pattern file " << i;
    EXPECT_EQ(entry["captured"]["exposures"][0]["frames"], 2);
    EXPECT_EQ(entry["captured"]["exposures"][0]["sequences"].size(), 2u);
    const cv::Mat mean = data.Mean(i);
    ASSERT_EQ(mean.type(), CV_32FC1);
    EXPECT_EQ(mean.size(), cv::Size(24, 16));
    double low = 0, high = 0;
    cv::minMaxLoc(mean, &low, &high);
    EXPECT_NEAR(low, ExpectedLuma(sequence.patterns[i].image), 0.5 + 1e-3)
        << sequence.patterns[i].name;
    EXPECT_NEAR(high, ExpectedLuma(sequence.patterns[i].image), 0.5 + 1e-3)
        << sequence.patterns[i].name;
    EXPECT_TRUE(data.Hdr(i).empty());
  }
  // No temporary files are left behind.
  for (const auto& entry : fs::recursive_directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().string().find(".tmp-"), std::string::npos) << entry.path();
  }
}

TEST(CaptureSession, InterruptedSessionKeepsWhatWasCapturedAndResumes) {
  testing::TempDir dir;
  const CaptureSequence sequence = Photometric();
  auto display = std::make_shared<MemoryDisplay>(cv::Size(12, 8));
  // The camera disappears after 7 frames: 2 frames per pattern (plus possibly one stale frame
  // each) means 2 or 3 patterns complete.
  TestCamera dying(SessionCamera(TestCameraOptions::Fault::kDisconnect, 7),
                   MakeLoopbackView(display));
  std::string message;
  try {
    RunCaptureSession(Options(dir.path()), sequence, dying, *display);
    FAIL() << "no fault";
  } catch (const CaptureFault& fault) {
    message = fault.what();
  }
  EXPECT_NE(message.find("camera 'test:session': device disappeared"), std::string::npos)
      << message;
  EXPECT_NE(message.find("gave up after 2 retries"), std::string::npos) << message;
  EXPECT_NE(message.find("run the same command again to resume"), std::string::npos) << message;

  CaptureSessionData interrupted = CaptureSessionData::Load(dir.path());
  EXPECT_FALSE(interrupted.complete());
  int kept = 0;
  while (kept < interrupted.pattern_count() && interrupted.captured(kept)) ++kept;
  EXPECT_GE(kept, 2);
  EXPECT_LT(kept, 7);
  for (int i = kept; i < interrupted.pattern_count(); ++i)
    EXPECT_FALSE(interrupted.captured(i)) << i;
  ASSERT_EQ(interrupted.manifest()["interruptions"].size(), 1u);
  EXPECT_EQ(interrupted.manifest()["interruptions"][0]["pattern"], kept);
  EXPECT_NE(message.find(std::to_string(kept) + " captured patterns are kept"), std::string::npos)
      << message;
  std::vector<std::string> kept_files;
  for (int i = 0; i < kept; ++i) {
    const fs::path file =
        dir.path() / interrupted.manifest()["patterns"][i]["captured"]["exposures"][0]["file"]
                         .get<std::string>();
    kept_files.push_back(Bytes(file));
  }

  // Resuming with a healthy camera captures only the rest and leaves the kept frames untouched.
  TestCamera healthy(SessionCamera(), MakeLoopbackView(display));
  const CaptureSummary summary =
      RunCaptureSession(Options(dir.path()), sequence, healthy, *display);
  EXPECT_EQ(summary.patterns_before, kept);
  EXPECT_EQ(summary.patterns_captured, 7 - kept);
  EXPECT_LE(healthy.frames_delivered(), 3 * (7 - kept));
  const CaptureSessionData resumed = CaptureSessionData::Load(dir.path());
  EXPECT_TRUE(resumed.complete());
  EXPECT_EQ(resumed.manifest()["runs"].size(), 2u);
  EXPECT_EQ(resumed.manifest()["runs"][1]["patterns_before"], kept);
  for (int i = 0; i < kept; ++i) {
    const fs::path file =
        dir.path() /
        resumed.manifest()["patterns"][i]["captured"]["exposures"][0]["file"].get<std::string>();
    EXPECT_EQ(Bytes(file), kept_files[i]) << "pattern " << i << " was recaptured";
  }
  for (int i = 0; i < 7; ++i) {
    double low = 0, high = 0;
    cv::minMaxLoc(resumed.Mean(i), &low, &high);
    EXPECT_NEAR(low, ExpectedLuma(sequence.patterns[i].image), 0.501) << i;
    EXPECT_NEAR(high, ExpectedLuma(sequence.patterns[i].image), 0.501) << i;
  }
}

TEST(CaptureSession, APatternWhoseFilesAreMissingIsCapturedAgain) {
  testing::TempDir dir;
  const CaptureSequence sequence = Photometric();
  auto display = std::make_shared<MemoryDisplay>(cv::Size(12, 8));
  TestCamera camera(SessionCamera(), MakeLoopbackView(display));
  RunCaptureSession(Options(dir.path()), sequence, camera, *display);
  fs::remove(FrameFile(dir.path(), 3));
  ExpectResumeRecapturesOnly(dir.path(), sequence, camera, *display, 3);
}

// A frame altered or truncated after it was captured (a disk fault, a copy gone wrong) still
// decodes as an image, or does not: either way its checksum no longer matches. Every reader
// refuses it with one line naming the file, and resuming captures it again.
TEST(CaptureSession, AFrameChangedAfterCaptureIsRefusedAndCapturedAgain) {
  for (const bool truncate : {false, true}) {
    testing::TempDir dir;
    const CaptureSequence sequence = Photometric();
    auto display = std::make_shared<MemoryDisplay>(cv::Size(12, 8));
    TestCamera camera(SessionCamera(), MakeLoopbackView(display));
    RunCaptureSession(Options(dir.path()), sequence, camera, *display);
    const fs::path frame = FrameFile(dir.path(), 4);
    if (truncate) {
      const std::string bytes = Bytes(frame);
      WriteFileAtomically(frame, bytes.substr(0, bytes.size() - 5));
    } else {
      // The same size and depth, one pixel changed: a valid 16-bit PNG.
      cv::Mat image = cv::imread(frame.string(), cv::IMREAD_UNCHANGED);
      ASSERT_EQ(image.depth(), CV_16U);
      image.at<uint16_t>(2, 2) ^= 0x100;
      ASSERT_TRUE(cv::imwrite(frame.string(), image));
    }
    try {
      CaptureSessionData::Load(dir.path()).Mean(4);
      ADD_FAILURE() << "a changed frame was read (truncated: " << truncate << ")";
    } catch (const IoError& error) {
      EXPECT_NE(std::string(error.what()).find(frame.filename().string()), std::string::npos)
          << error.what();
    }
    ExpectResumeRecapturesOnly(dir.path(), sequence, camera, *display, 4);
  }
}

TEST(CaptureSession, ResumingWithOtherSettingsIsRefused) {
  testing::TempDir dir;
  auto display = std::make_shared<MemoryDisplay>(cv::Size(12, 8));
  TestCamera camera(SessionCamera(), MakeLoopbackView(display));
  RunCaptureSession(Options(dir.path()), Photometric(), camera, *display);
  const std::string before = Bytes(dir.path() / "session.json");

  auto refused = [&](const CaptureSequence& sequence, const CaptureSessionOptions& options,
                     Camera& with, const std::string& expected) {
    try {
      RunCaptureSession(options, sequence, with, *display);
      ADD_FAILURE() << "accepted, expected: " << expected;
    } catch (const IoError& error) {
      EXPECT_NE(std::string(error.what()).find(expected), std::string::npos) << error.what();
      EXPECT_NE(std::string(error.what()).find("session.json: cannot resume"), std::string::npos)
          << error.what();
    }
  };
  GrayCodeOptions gray;
  gray.width = 12;
  gray.height = 8;
  refused(MakeGrayCodeSequence(gray), Options(dir.path()), camera,
          "holds a 'photometric' sequence");
  CaptureSessionOptions more_frames = Options(dir.path());
  more_frames.sequencer.frames_per_pattern = 5;
  refused(Photometric(), more_frames, camera, "capture settings differ");
  TestCameraOptions other = SessionCamera();
  other.name = "other";
  TestCamera other_camera(other, MakeLoopbackView(display));
  refused(Photometric(), Options(dir.path()), other_camera, "captured with camera 'test:session'");
  TestCameraOptions colour = SessionCamera();
  colour.pixel_format = PixelFormat::kRGB8;
  TestCamera colour_camera(colour, MakeLoopbackView(display));
  refused(Photometric(), Options(dir.path()), colour_camera, "camera format differs");
  EXPECT_EQ(Bytes(dir.path() / "session.json"), before)
      << "a refused resume must not touch the session";

  WriteFileAtomically(dir.path() / "session.json", "{ not json");
  EXPECT_THROW(RunCaptureSession(Options(dir.path()), Photometric(), camera, *display), IoError);
  EXPECT_THROW(CaptureSessionData::Load(dir.path()), IoError);
}

TEST(CaptureSession, BracketedSessionsStoreTheHdrMerge) {
  testing::TempDir dir;
  auto display = std::make_shared<MemoryDisplay>(cv::Size(12, 8));
  TestCamera camera(SessionCamera(), MakeLoopbackView(display));
  CaptureSessionOptions options = Options(dir.path());
  options.sequencer.exposures_us = {500, 2000};
  PhotometricOptions photometric;
  photometric.width = 12;
  photometric.height = 8;
  photometric.levels = {255};
  photometric.channels = "w";
  RunCaptureSession(options, MakePhotometricSequence(photometric), camera, *display);
  const CaptureSessionData data = CaptureSessionData::Load(dir.path());
  ASSERT_EQ(data.pattern_count(), 2);
  // White: radiance 1 fills full scale at 1 ms, so 500 µs reads half scale and 2 ms clips.
  double low = 0, high = 0;
  cv::minMaxLoc(data.Mean(1, 0), &low, &high);
  EXPECT_NEAR(low, 127.5, 0.51);
  cv::minMaxLoc(data.Mean(1, 1), &low, &high);
  EXPECT_EQ(low, 255.0);
  const cv::Mat hdr = data.Hdr(1);
  ASSERT_EQ(hdr.type(), CV_32FC1);
  cv::minMaxLoc(hdr, &low, &high);
  // Full scale per second = 1 / 1 ms, up to the rounding of 127.5 to a whole digital number.
  EXPECT_NEAR(low, 1000.0, 5.0);
  EXPECT_NEAR(high, 1000.0, 5.0);
  EXPECT_EQ(data.manifest()["patterns"][1]["captured"]["exposures"].size(), 2u);
}

}  // namespace
}  // namespace procam
