#pragma once
// A GigE Vision camera served on a local network address, whose pictures procam supplies: the
// camera half of hardware-in-the-loop tests without hardware. It is Aravis's own GigE Vision
// fake camera (ArvGvFakeCamera: GVCP control on UDP port 3956 of the address, GVSP streaming,
// Aravis's fake-camera GenICam description), with its picture generator replaced by a
// GigeFrameSource. A client — procam's "aravis:" backend, arv-tool-0.8, any GigE Vision
// viewer — drives it through the GenICam features ExposureTime, Gain, PixelFormat,
// TriggerMode/TriggerSource/TriggerSoftware, Width and Height, and receives what the source
// returns for each frame.
//
// The frame model (what tests use as truth):
//   - Free-running (TriggerMode Off), exposures start at the multiples of the frame period
//     1/frame_rate on the real-time clock (a frame whose turn the emulator's thread misses on
//     a busy host starts on a later multiple); with TriggerSource Software, an exposure starts
//     at most 1 ms after the trigger command arrives.
//   - At exposure start the source is called with the frame's settings and
//     scene_time_ns = exposure_start_ns − latency (the display-to-camera latency: the frame
//     shows the scene as it was `latency` before its exposure began). The frame is sent when
//     the exposure ends, exposure_start + ExposureTime (later if the source took longer).
//   - The GVSP leader's timestamp (Aravis: arv_buffer_get_timestamp, procam:
//     Frame::device_timestamp_ns) is the exposure start in nanoseconds of the real-time clock
//     (the device's tick frequency is 1 GHz).
//   - The GVSP block id (procam: Frame::sequence) counts frames from 65401 and wraps after 65535
//     to 1 (Aravis starts near the wrap on purpose, so that clients meet it early).
//
// What the GenICam description of Aravis 0.8 offers (and so what this camera offers): pixel
// formats Mono8, Mono16, RGB8, BayerRG8, BayerBG8, BayerGR8, BayerGB8 (no BGR8 or YUV); Width
// and Height up to 2048; ExposureTime in whole microseconds, [10, 1e7]; Gain is the integer
// GainRaw in [0, 10], which this emulator reports to the source as decibels.
//
// Only one camera can listen on an address (port 3956 is fixed); use one address per camera
// (e.g. 127.0.0.2 in a private network namespace). The emulator itself never sends a
// broadcast; it answers discovery requests that reach it.
//
// Thread safety: the source is called on the emulator's own thread (one call at a time); the
// setters and counters may be called from any thread.

#include <cstdint>
#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "capture/camera.h"
#include "capture/pixel_format.h"
#include "capture/test_camera.h"

namespace procam {

// What the source is asked to render: one frame as the client configured it.
struct GigeFrameRequest {
  uint64_t frame_id = 0;  // the GVSP block id of the frame, 1..65535 (wraps)
  int width = 0;          // pixels (the client's Width)
  int height = 0;         // pixels (the client's Height)
  PixelFormat pixel_format = PixelFormat::kMono8;
  double exposure_us = 0.0;       // ExposureTime, microseconds
  double gain_db = 0.0;           // Gain, decibels
  int64_t exposure_start_ns = 0;  // steady clock (SteadyNowNs of camera.h)
  int64_t exposure_end_ns = 0;    // steady clock: exposure_start_ns + exposure; sent then
  int64_t scene_time_ns = 0;      // steady clock: exposure_start_ns − latency; render the scene
                                  // as it was at this instant
};

// Returns the frame's image in the decoded layout of its pixel format (DecodeImage of
// pixel_format.h): CV_8UC1 for Mono8, CV_16UC1 for Mono16, CV_8UC3 B, G, R for RGB8 and the
// Bayer formats (mosaiced by the emulator), width × height. A source that throws or returns
// another size or type gets its frame sent black and counted in frames_failed().
using GigeFrameSource = std::function<cv::Mat(const GigeFrameRequest& request)>;

// A source that photographs a scene with the test camera's model (PhotographRadiance of
// test_camera.h): the view's radiance at each frame's scene_time_ns, with the frame's size,
// format, exposure and gain, and `model`'s reference exposure, black level, read noise (seeded
// by model.seed) and response curve. An empty view sees black. This is how a synthetic room
// (datasets_synthetic/synthetic_camera.h: MakeSyntheticView) becomes a GigE Vision camera.
GigeFrameSource PhotographScene(SceneView view, const TestCameraOptions& model = {});

struct GigeEmulatorOptions {
  // IPv4 address of the local interface to serve on, e.g. "127.0.0.1"; clients open
  // "aravis:gv:<address>".
  std::string address = "127.0.0.1";
  // Serial number the camera reports (DeviceSerialNumber), 1 to 15 characters.
  std::string serial = "PROCAM0";
  // The camera's Width and Height until a client changes them, pixels, [1, 2048].
  int width = 640;
  int height = 480;
  // PixelFormat until a client changes it: one of SupportedPixelFormats().
  PixelFormat pixel_format = PixelFormat::kMono8;
  // Free-running frame rate, frames per second, [0.1, 1000] (the frame period is rounded to
  // whole microseconds). A client may change it through AcquisitionFrameRate.
  double frame_rate = 25.0;
  // Display-to-camera latency, milliseconds, [0, 10000]: see the file comment.
  double latency_ms = 0.0;
  // ExposureTime until a client changes it, microseconds, [10, 1e7] (whole microseconds).
  double exposure_us = 10000.0;
  // Gain until a client changes it, dB, an integer in [0, 10].
  double gain_db = 0.0;
  // Fraction of stream (GVSP) packets the emulator drops at random, [0, 1): a lossy network.
  // A frame missing a packet reaches the client incomplete (the emulator does not resend).
  double packet_loss = 0.0;

  bool Check(std::string* why) const;
};

class GigeEmulator {
 public:
  // Starts serving at once. Throws IoError, one line naming the address: options.Check()
  // fails, no local interface has the address, or its GigE Vision port (UDP 3956) is taken.
  GigeEmulator(const GigeEmulatorOptions& options, GigeFrameSource source);
  // Stops serving: an exposure in progress is cut short, the emulator's thread is joined and
  // its sockets closed. A connected client's next request goes unanswered (procam's Aravis
  // backend: CameraDisconnected, after Aravis's retries, about 2.5 s).
  ~GigeEmulator();
  GigeEmulator(const GigeEmulator&) = delete;
  GigeEmulator& operator=(const GigeEmulator&) = delete;

  // The URI that opens this camera in procam, "aravis:gv:<address>".
  std::string Uri() const;
  // The options it was started with (the setters below do not change them).
  const GigeEmulatorOptions& options() const;

  // Changes the free-running frame rate (as a client writing AcquisitionFrameRate would) and
  // the latency; same ranges as the options. Throw std::invalid_argument outside them.
  void SetFrameRate(double frame_rate);
  void SetLatencyMs(double latency_ms);

  // Frames sent so far, those of them sent black because the source failed, and the source's
  // last failure (empty when none).
  int64_t frames_served() const;
  int64_t frames_failed() const;
  std::string last_error() const;

  // The pixel formats the camera's GenICam description offers and the emulator can fill.
  static std::vector<PixelFormat> SupportedPixelFormats();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace procam
