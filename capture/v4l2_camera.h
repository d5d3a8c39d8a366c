#pragma once
// The V4L2 backend ("v4l2:" URIs): webcams and other Video4Linux2 capture devices, through
// libv4l2 (which also converts formats a device only offers compressed or in exotic layouts).
// Memory-mapped streaming with `buffers` driver buffers; exposure and gain through the standard
// controls (V4L2_CID_EXPOSURE_AUTO/EXPOSURE_ABSOLUTE in 100 µs units, V4L2_CID_AUTOGAIN/GAIN in
// driver units). The format and control arithmetic lives in v4l2_mapping.h.
//
// URI: v4l2:/dev/videoN?format=YUYV&width=1280&height=720&fps=30&buffers=4; every key optional
// (format: any PixelFormatName or V4L2 fourcc name; default the best the device offers).

#include <memory>
#include <string>
#include <vector>

#include "capture/camera.h"
#include "capture/v4l2_mapping.h"

namespace procam {

struct V4l2CameraOptions {
  std::string device = "/dev/video0";
  V4l2FormatRequest format;
  double frame_rate =
      0.0;          // frames per second requested with VIDIOC_S_PARM, [0, 1000]; 0 = driver's
  int buffers = 4;  // driver buffers, [2, 32]; fewer keep less stale data
  bool Check(std::string* why) const;
};

// Reads the URI's keys. Throws IoError naming the URI and key.
V4l2CameraOptions V4l2CameraOptionsFromUri(const CameraUri& uri);

class V4l2Camera : public Camera {
 public:
  // Opens the device and negotiates the format. Throws IoError naming the device.
  explicit V4l2Camera(const V4l2CameraOptions& options);
  ~V4l2Camera() override;
  V4l2Camera(const V4l2Camera&) = delete;
  V4l2Camera& operator=(const V4l2Camera&) = delete;

  CameraInfo Info() const override;
  CameraSettings Settings() const override;
  std::vector<PixelFormat> SupportedPixelFormats() const override;
  void SetExposure(double exposure_us) override;
  void SetGain(double gain) override;
  void SetPixelFormat(PixelFormat format) override;
  void Start() override;
  void Stop() override;
  Frame Grab(std::chrono::milliseconds timeout) override;
  int DropBufferedFrames() override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Every /dev/video* node that can capture video, as CameraInfo (unopenable ones say why).
std::vector<CameraInfo> ListV4l2Cameras();

// The "v4l2" backend for the registry.
CameraBackend V4l2CameraBackend();

}  // namespace procam
