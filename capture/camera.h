#pragma once
// The camera interface every backend implements, and the registry that opens cameras by URI.
//
// A camera is opened from a URI "<backend>:<device>[?key=value&key=value...]":
//   v4l2:/dev/video0?format=YUYV&width=1280&height=720   a webcam (backend procam_capture_v4l2)
//   aravis:Fake_1?trigger=software                        a GenICam camera (procam_capture_aravis);
//                                                         Fake_1 is Aravis's in-process fake camera
//   test:loopback?format=Mono8&noise=2                    the software test camera (test_camera.h)
//   synthetic:c_shaped?patches=300                        the simulated rig's camera in a
//                                                         synthetic room (registered by
//                                                         datasets_synthetic/synthetic_camera.h)
// Backends are registered at run time (RegisterCameraBackend); RegisterDeviceBackends() in
// capture/devices.h registers every device backend this build contains. Opening a URI whose
// backend is missing throws IoError with one line naming the backend and why it is missing.
//
// Frames: pixel (x, y) is column x, row y of the readout region, (0, 0) at the top left.
// Geometric conventions (pixel centres, distortion) belong to the camera models of calibration.
//
// Time: every host-side time is nanoseconds of std::chrono::steady_clock (CLOCK_MONOTONIC),
// so frame times compare directly with the time a pattern was shown (see SteadyNowNs()).
//
// Thread safety: a Camera is used from one thread at a time.

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "capture/pixel_format.h"
#include "base/io.h"

namespace procam {

class OptionTable;

// Nanoseconds of std::chrono::steady_clock now.
int64_t SteadyNowNs();
// Sleeps until SteadyNowNs() reaches `steady_ns` (returns at once if it has).
void SleepUntil(int64_t steady_ns);
// Milliseconds as nanoseconds, rounded.
int64_t MsToNs(double ms);

// A grab waited longer than its timeout. The camera may still answer later.
class CameraTimeout : public IoError {
 public:
  using IoError::IoError;
};

// The device is gone (unplugged, lost its network link, closed by the driver). Reopening it
// is the only way back.
class CameraDisconnected : public IoError {
 public:
  using IoError::IoError;
};

// What `procam cameras` prints for one camera.
struct CameraInfo {
  std::string uri;      // opens this camera
  std::string backend;  // "v4l2", "aravis", "test", ...
  std::string vendor;
  std::string model;
  std::string serial;
  std::string description;  // one line: bus, formats, anything else worth knowing
};

// Range of a control in the unit of the corresponding setting; `available` false when the
// device has no such control.
struct ControlRange {
  bool available = false;
  double min = 0.0;
  double max = 0.0;
  double step = 0.0;  // 0 = continuous
};

// The settings a camera is running with, as the device reports them (recorded in manifests).
struct CameraSettings {
  int width = 0;   // pixels
  int height = 0;  // pixels
  PixelFormat pixel_format = PixelFormat::kMono8;
  double exposure_us = 0.0;    // microseconds; 0 when unknown (auto exposure)
  double gain = 0.0;           // in `gain_unit`
  std::string gain_unit;       // "dB" (GenICam Gain), "driver" (V4L2 raw value)
  bool auto_exposure = false;  // true when the device still controls exposure
  std::string trigger;         // "software" or "free-running"
  ControlRange exposure_range_us;
  ControlRange gain_range;
};

// One frame, decoded (see DecodeImage for the image types).
struct Frame {
  cv::Mat image;  // CV_8UC1, CV_16UC1 or CV_8UC3 (B, G, R)
  PixelFormat source_format = PixelFormat::kMono8;
  uint64_t sequence = 0;            // the device's frame counter (frame id)
  int64_t arrival_ns = 0;           // steady clock when the backend received it
  int64_t exposure_start_ns = 0;    // steady clock, best estimate of exposure start
  int64_t device_timestamp_ns = 0;  // the camera's own clock; 0 when it has none
  double exposure_us = 0.0;         // exposure in effect (as set), microseconds
  double gain = 0.0;                // gain in effect, camera units
};

// A camera. Implementations: V4l2Camera, AravisCamera, TestCamera, and SyntheticCamera of
// datasets_synthetic (a TestCamera looking at the simulated rig). Device failures throw IoError
// or its subclasses above, with a message that names the URI.
class Camera {
 public:
  virtual ~Camera() = default;

  virtual CameraInfo Info() const = 0;
  virtual CameraSettings Settings() const = 0;
  virtual std::vector<PixelFormat> SupportedPixelFormats() const = 0;

  // Sets a fixed exposure (microseconds), switching automatic exposure off; the device may
  // round to its step. Frames whose exposure began before the call may still carry the old
  // exposure: the sequencer drops them. Throws IoError when the device has no such control or
  // the value is outside ControlRange.
  virtual void SetExposure(double exposure_us) = 0;
  // Sets the gain in the unit of CameraSettings::gain_unit, switching automatic gain off.
  virtual void SetGain(double gain) = 0;
  // Changes the pixel format; the camera stops streaming while it changes.
  virtual void SetPixelFormat(PixelFormat format) = 0;

  // Starts and stops streaming. Grab() starts streaming when needed.
  virtual void Start() = 0;
  virtual void Stop() = 0;

  // The next frame, waiting at most `timeout`. Throws CameraTimeout when none came,
  // CameraDisconnected when the device is gone.
  virtual Frame Grab(std::chrono::milliseconds timeout) = 0;

  // Discards frames already captured and waiting in the driver's or library's buffers (their
  // exposure began before now); returns how many were dropped.
  virtual int DropBufferedFrames() = 0;
};

// A parsed camera URI: "<scheme>:<path>[?key=value&...]". Keys are read through the getters,
// which throw IoError naming the URI and key on a malformed value; CheckAllRead() then
// rejects keys no getter asked for (a typo in a URI is an error, not a silent default).
class CameraUri {
 public:
  // Throws IoError when `text` has no "scheme:" or a parameter is not key=value.
  static CameraUri Parse(const std::string& text);

  const std::string& text() const { return text_; }
  const std::string& scheme() const { return scheme_; }
  const std::string& path() const { return path_; }
  bool Has(const std::string& key) const { return params_.count(key) > 0; }

  std::string GetString(const std::string& key, const std::string& fallback) const;
  double GetDouble(const std::string& key, double fallback) const;
  int GetInt(const std::string& key, int fallback) const;
  void CheckAllRead() const;

 private:
  std::string text_, scheme_, path_;
  std::map<std::string, std::string> params_;
  mutable std::map<std::string, bool> read_;
};

// What a simulated camera photographs: given the steady-clock time its exposure starts, the
// linear radiance image in front of it (CV_32FC1 or CV_32FC3 B, G, R; 1.0 = the brightest a
// projector makes a white surface). Physical cameras ignore it.
using SceneView = std::function<cv::Mat(int64_t exposure_start_ns)>;

struct OpenCameraOptions {
  SceneView scene_view;  // for simulated backends ("test", "synthetic"); may be empty
};

struct ListCamerasOptions {
  // GigE Vision discovery broadcasts on every network interface: off in tests.
  bool gige_discovery = true;
  // Also list virtual cameras (Aravis Fake_1, the test camera).
  bool include_virtual = false;
  // Declares --no-gige and --virtual (procam cameras) in `table`, bound to these fields.
  void Declare(OptionTable* table);
};

// A backend: a URI scheme, how to open it and how to list its cameras.
struct CameraBackend {
  std::string scheme;       // "v4l2", "aravis", "test", ...
  std::string description;  // one line for `procam cameras`
  std::function<std::unique_ptr<Camera>(const CameraUri& uri, const OpenCameraOptions& options)>
      open;
  std::function<std::vector<CameraInfo>(const ListCamerasOptions& options)> list;  // may be empty
};

// Adds (or replaces) the backend of `backend.scheme`. The "test" backend is always registered.
void RegisterCameraBackend(CameraBackend backend);
// Schemes registered now, sorted.
std::vector<std::string> RegisteredCameraBackends();

// Opens a camera. Throws IoError: malformed URI, a backend that is not built or not
// registered (one line naming it and how to get it), or the device's own failure.
std::unique_ptr<Camera> OpenCamera(const std::string& uri, const OpenCameraOptions& options = {});

// Lists the cameras of every registered backend. Backends that fail to list add one
// CameraInfo whose description says why, rather than hiding the others.
std::vector<CameraInfo> ListCameras(const ListCamerasOptions& options = {});

}  // namespace procam
