#pragma once
// The software test camera ("test:" URIs): photographs whatever a SceneView returns (normally
// what an in-memory display last showed, see display.h), with exact frame timing, buffering
// like a V4L2 driver, Gaussian read noise and injectable faults. It lets the sequencer and
// capture sessions be tested without hardware; the physically-based simulated camera
// (datasets_synthetic/synthetic_camera.h, "synthetic:" URIs) is built on it
// implements the same Camera interface.
//
// Its model, which tests use as ground truth:
//   - Frame k's exposure starts at t0 + k·T, T = max(1/frame_rate, exposure); it arrives when
//     the exposure ends. t0 restarts whenever exposure, gain or format change.
//   - At most `buffers` finished frames wait to be grabbed; while they are full, newer frames
//     are dropped (as V4L2 drivers do), so a slow reader sees stale frames first.
//   - The frame sees the scene at (exposure start − display_latency): camera pixel (x, y)
//     takes the view's pixel (⌊x·W_view/W⌋, ⌊y·H_view/H⌋) (nearest neighbour).
//   - Digital number = black_level + radiance · full_scale · (exposure / reference_exposure)
//     · 10^(gain_dB/20) + N(0, noise_sigma²), rounded and clipped to [0, full_scale].
//     With response_gamma γ ≠ 1 (a camera that is not linear, e.g. a webcam's sRGB-like
//     output): DN = black + (full − black) · clip((DN_linear − black)/(full − black), 0, 1)^(1/γ)
//     before rounding.
//     Colour views seen by a mono camera use Rec. 709 luma (0.2126 R + 0.7152 G + 0.0722 B).
//   - Bayer formats mosaic the colour image and go through the same demosaicing as devices.
//   - What real photographs have besides noise, each off by default (TestCameraOptions):
//     projector defocus: the view is blurred by a Gaussian of σ = projector_blur_px in the
//       view's own pixels — for the test camera the view is the display's image, so these are
//       projector pixels; a synthetic camera (datasets_synthetic/synthetic_camera.h) blurs each
//       projector's light before it lights the room instead;
//     ambient light: radiance + ambient (a constant, in units of radiance 1 = full scale at the
//       reference exposure), after resampling, on every pixel and channel;
//     camera defocus: the resampled radiance blurred by a Gaussian of σ = camera_blur_px camera
//       pixels (borders reflected), before exposure, noise and the response;
//     JPEG: with jpeg_quality q > 0 the quantised 8-bit image is JPEG-encoded at quality q in
//       memory (OpenCV's libjpeg: 4:2:0 chroma for colour) and decoded again.
//   Order: view → projector blur → resample → ambient → camera blur → luma → exposure, gain,
//   black, noise → response → rounding → JPEG.
//
// URI: test:<name>?key=value&..., keys (defaults in TestCameraOptions): format, width, height,
// buffers, seed, fault (none|timeout|disconnect), fault_after (frames delivered first),
// fault_grabs (failing grabs for fault=timeout; 0 = for ever), and every key of
// TestCameraSettings() (fps, exposure_us, reference_exposure_us, gain_db, black, noise,
// response_gamma, latency_ms, projector_blur, camera_blur, ambient, jpeg_quality), which a scene
// file's camera entry may set too (capture/scene_cameras.h).

#include <cstdint>
#include <deque>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "capture/camera.h"

namespace procam {

struct TestCameraOptions {
  enum class Fault {
    kNone,
    kTimeout,     // grabs wait their full timeout and throw CameraTimeout
    kDisconnect,  // every call throws CameraDisconnected from then on
  };

  std::string name = "loopback";  // the URI's device part; names the camera in manifests
  int width = 640;                // pixels, [2, 16384]; even for Bayer formats
  int height = 480;               // pixels, [2, 16384]; even for Bayer formats
  PixelFormat pixel_format = PixelFormat::kMono8;  // any but YUYV and MJPEG
  double frame_rate = 30.0;                        // frames per second, (0, 10000]
  int buffers = 4;                                 // finished frames held for Grab(), [1, 64]
  double exposure_us = 10000.0;                    // initial exposure, microseconds, [10, 1e7]
  double reference_exposure_us = 10000.0;  // radiance 1 fills full scale at this exposure, > 0
  double gain_db = 0.0;                    // initial gain, dB, [0, 24]
  double black_level = 0.0;                // digital numbers added to every pixel, [0, full scale)
  double noise_sigma = 0.0;                // read noise, digital numbers, [0, full scale]
  double response_gamma = 1.0;             // output response exponent (1 = linear), (0, 10]
  double display_latency_ms = 0.0;         // the scene lags by this much, milliseconds, [0, 10000]
  // Defects of real photographs (file comment), all off by default:
  double projector_blur_px = 0.0;  // projector defocus, Gaussian σ in projector pixels, [0, 20]
  double camera_blur_px = 0.0;     // camera defocus, Gaussian σ in camera pixels, [0, 20]
  double ambient = 0.0;            // ambient radiance added, units of full scale (radiance 1), [0, 10]
  // JPEG round trip at this quality, [1, 100], 0 = off; 8-bit formats only (Mono8, RGB8, BGR8).
  int jpeg_quality = 0;
  uint32_t seed = 1;                       // noise generator seed
  Fault fault = Fault::kNone;
  int fault_after_frames = 0;  // frames delivered before the fault strikes, >= 0
  int fault_grabs = 0;         // failing grabs for kTimeout; 0 = for ever, >= 0

  bool Check(std::string* why) const;
};

// A camera setting that a URI key and a scene file's camera entry both set, declared once: the
// key (also the first word of TestCameraOptions::Check()'s message about it), the field (a
// number or an integer) and what it means, with units and range, as the docs' tables say it.
struct TestCameraSetting {
  const char* key;
  double TestCameraOptions::*number = nullptr;  // exactly one of number and integer is set
  int TestCameraOptions::*integer = nullptr;
  const char* meaning;
};
// The settings above in the order the docs list them.
const std::vector<TestCameraSetting>& TestCameraSettings();

// Reads the URI's keys (see the file comment). Throws IoError naming the URI and key.
TestCameraOptions TestCameraOptionsFromUri(const CameraUri& uri);
// The same, starting from `defaults` instead of TestCameraOptions' (a synthetic rig's camera
// settings, which the URI's keys override).
TestCameraOptions TestCameraOptionsFromUri(const CameraUri& uri, TestCameraOptions defaults);

// The settings a picture is taken with (a camera's current ones).
struct PhotographSettings {
  int width = 640;   // pixels
  int height = 480;  // pixels
  PixelFormat pixel_format = PixelFormat::kMono8;  // any but YUYV and MJPEG
  double exposure_us = 10000.0;                    // microseconds
  double gain_db = 0.0;                            // decibels
};

// The test camera's picture of a radiance image (the model above, without its timing):
// resampled to width × height (nearest neighbour), ambient light, camera blur, Rec. 709 luma
// for mono formats, scaled to digital numbers by exposure and gain, black level, read noise
// drawn from `rng`, the response curve, rounded and clipped, the JPEG round trip. Takes the
// model's reference_exposure_us, black_level, noise_sigma, response_gamma, ambient,
// camera_blur_px and jpeg_quality (its size, format, exposure and gain are `settings`'; the
// projector blur belongs to the view, see ProjectorBlurredView). Returns the decoded
// layout of the format: CV_8UC1 (Mono8), CV_16UC1 (Mono16) or CV_8UC3 B, G, R (colour and Bayer
// formats, before any mosaic). An empty `radiance` is black.
cv::Mat PhotographRadiance(cv::Mat radiance, const TestCameraOptions& model,
                           const PhotographSettings& settings, cv::RNG& rng);

// `view` blurred by a Gaussian of σ = sigma_px in its own pixels (borders reflected): the test
// camera's projector defocus, its view being the display's image. `view` itself when sigma_px is
// 0 or the view is empty.
SceneView ProjectorBlurredView(SceneView view, double sigma_px);

class TestCamera : public Camera {
 public:
  // `view` may be empty: the camera then sees a fixed chart (a horizontal ramp from 0 to 1,
  // with a red, green and blue band in its lower third). The camera sees
  // ProjectorBlurredView(view, options.projector_blur_px). Throws std::invalid_argument when
  // options.Check() fails.
  TestCamera(const TestCameraOptions& options, SceneView view);

  CameraInfo Info() const override;
  CameraSettings Settings() const override;
  std::vector<PixelFormat> SupportedPixelFormats() const override;
  void SetExposure(double exposure_us) override;
  void SetGain(double gain_db) override;
  void SetPixelFormat(PixelFormat format) override;
  void Start() override;
  void Stop() override;
  Frame Grab(std::chrono::milliseconds timeout) override;
  int DropBufferedFrames() override;

  // Counters for tests: frames handed out by Grab, and frames lost because buffers were full.
  int frames_delivered() const { return frames_delivered_; }
  int frames_overrun() const { return frames_overrun_; }

 protected:
  // For cameras whose view already carries the projector blur (a synthetic room blurs each
  // projector's light before it lights the room): `view` is used as it is.
  struct ViewHasProjectorBlur {};
  TestCamera(const TestCameraOptions& options, SceneView view, ViewHasProjectorBlur);

 private:
  struct PendingFrame {
    uint64_t sequence;
    int64_t exposure_start_ns;
    double exposure_us;
    double gain_db;
  };
  int64_t PeriodNs() const;
  int64_t ExposureNs() const;
  // Moves every frame finished by `now_ns` into the buffers (or drops it when they are full).
  void Advance(int64_t now_ns);
  void RestartTimeline();
  void CheckFaults(std::chrono::milliseconds timeout);
  Frame Render(const PendingFrame& pending);
  std::string Uri() const;

  TestCameraOptions options_;
  SceneView view_;
  cv::RNG rng_;
  bool streaming_ = false;
  bool disconnected_ = false;
  int64_t timeline_start_ns_ = 0;  // exposure start of frame 0 of the current timeline
  int64_t next_in_timeline_ = 0;   // index (in the timeline) of the next frame to finish
  uint64_t next_sequence_ = 0;     // device frame counter
  std::deque<PendingFrame> buffered_;
  int frames_delivered_ = 0;
  int frames_overrun_ = 0;
  int failed_grabs_ = 0;
};

// The "test" backend for the registry (registered by default). Lists one camera,
// test:loopback, when ListCamerasOptions::include_virtual is set.
CameraBackend TestCameraBackend();

}  // namespace procam
