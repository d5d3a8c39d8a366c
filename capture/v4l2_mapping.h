#pragma once
// The device-independent half of the V4L2 backend: pixel-format codes, format negotiation and
// control mapping. Pure functions, so they are unit-tested without a /dev/video device.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "capture/camera.h"
#include "capture/pixel_format.h"

namespace procam {

// V4L2 fourcc (V4L2_PIX_FMT_*) of a format: GREY, Y16, RGGB/BA81/GRBG/GBRG, RGB3, BGR3, YUYV,
// MJPG. The inverse also accepts JPEG as MJPEG; nullopt for formats procam cannot decode.
uint32_t FourccFromPixelFormat(PixelFormat format);
std::optional<PixelFormat> PixelFormatFromFourcc(uint32_t fourcc);
// "YUYV", "MJPG", "Y16 " as four printable characters.
std::string FourccName(uint32_t fourcc);

// One frame size a device offers for one format (VIDIOC_ENUM_FMT × VIDIOC_ENUM_FRAMESIZES).
struct V4l2FrameSize {
  uint32_t fourcc = 0;
  int width = 0;
  int height = 0;
  bool emulated = false;  // converted in software by libv4l2 (V4L2_FMT_FLAG_EMULATED)
};

struct V4l2FormatRequest {
  std::optional<PixelFormat> format;  // nullopt: the best the device offers (see below)
  int width = 0;                      // pixels; 0 = the largest offered
  int height = 0;                     // pixels; 0 = the largest offered
};

// Chooses among what the device offers. Without a requested format, the first offered natively
// (then, failing that, emulated by libv4l2) of Mono16, Mono8, the Bayer formats, RGB8, BGR8,
// YUYV, MJPEG: uncompressed first, because JPEG artefacts spoil photometry, and native before
// libv4l2's conversions. Without a requested size, the largest (by area) of that format.
// With a requested size, exactly that size. nullopt, with `why` saying what is offered, when
// nothing fits.
std::optional<V4l2FrameSize> ChooseV4l2Format(const std::vector<V4l2FrameSize>& offered,
                                              const V4l2FormatRequest& request, std::string* why);

// An integer V4L2 control as VIDIOC_QUERYCTRL reports it.
struct V4l2Control {
  bool available = false;
  int32_t minimum = 0;
  int32_t maximum = 0;
  int32_t step = 1;
  int32_t default_value = 0;
};

// V4L2_CID_EXPOSURE_ABSOLUTE counts 100 µs units.
constexpr double kV4l2ExposureUnitUs = 100.0;

// The control value nearest to `value` on the control's grid minimum + k·step; nullopt when the
// control is unavailable or `value` lies outside [minimum, maximum] by more than half a step.
std::optional<int32_t> V4l2ControlValue(double value, const V4l2Control& control);
// Exposure in microseconds → V4L2_CID_EXPOSURE_ABSOLUTE value, and back.
std::optional<int32_t> V4l2ExposureValue(double exposure_us, const V4l2Control& exposure_absolute);
double V4l2ExposureMicroseconds(int32_t value);
// The control's range in the unit of CameraSettings (exposure: microseconds).
ControlRange V4l2ExposureRange(const V4l2Control& exposure_absolute);
ControlRange V4l2GainRange(const V4l2Control& gain);

}  // namespace procam
