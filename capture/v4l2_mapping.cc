#include "capture/v4l2_mapping.h"

#include <linux/videodev2.h>

#include <algorithm>
#include <cmath>

namespace procam {

uint32_t FourccFromPixelFormat(PixelFormat format) {
  switch (format) {
    case PixelFormat::kMono8:
      return V4L2_PIX_FMT_GREY;
    case PixelFormat::kMono16:
      return V4L2_PIX_FMT_Y16;
    case PixelFormat::kBayerRG8:
      return V4L2_PIX_FMT_SRGGB8;
    case PixelFormat::kBayerBG8:
      return V4L2_PIX_FMT_SBGGR8;
    case PixelFormat::kBayerGR8:
      return V4L2_PIX_FMT_SGRBG8;
    case PixelFormat::kBayerGB8:
      return V4L2_PIX_FMT_SGBRG8;
    case PixelFormat::kRGB8:
      return V4L2_PIX_FMT_RGB24;
    case PixelFormat::kBGR8:
      return V4L2_PIX_FMT_BGR24;
    case PixelFormat::kYUYV:
      return V4L2_PIX_FMT_YUYV;
    case PixelFormat::kMJPEG:
      return V4L2_PIX_FMT_MJPEG;
  }
  return 0;
}

std::optional<PixelFormat> PixelFormatFromFourcc(uint32_t fourcc) {
  if (fourcc == V4L2_PIX_FMT_JPEG) return PixelFormat::kMJPEG;
  for (PixelFormat format : AllPixelFormats()) {
    if (FourccFromPixelFormat(format) == fourcc) return format;
  }
  return std::nullopt;
}

std::string FourccName(uint32_t fourcc) {
  std::string name;
  for (int shift = 0; shift < 32; shift += 8) {
    const char c = static_cast<char>((fourcc >> shift) & 0xff);
    name.push_back(c >= 32 && c < 127 ? c : '?');
  }
  return name;
}

std::optional<V4l2FrameSize> ChooseV4l2Format(const std::vector<V4l2FrameSize>& offered,
                                              const V4l2FormatRequest& request, std::string* why) {
  static const PixelFormat kPreference[] = {PixelFormat::kMono16,   PixelFormat::kMono8,
                                            PixelFormat::kBayerRG8, PixelFormat::kBayerBG8,
                                            PixelFormat::kBayerGR8, PixelFormat::kBayerGB8,
                                            PixelFormat::kRGB8,     PixelFormat::kBGR8,
                                            PixelFormat::kYUYV,     PixelFormat::kMJPEG};
  auto offers = [&](PixelFormat format, bool native_only) {
    return std::any_of(offered.begin(), offered.end(), [&](const V4l2FrameSize& size) {
      return PixelFormatFromFourcc(size.fourcc) == format && !(native_only && size.emulated);
    });
  };
  std::optional<PixelFormat> format = request.format;
  for (const bool native_only : {true, false}) {
    for (PixelFormat candidate : kPreference) {
      if (format) break;
      if (offers(candidate, native_only)) format = candidate;
    }
  }
  std::string offered_text;
  for (const V4l2FrameSize& size : offered) {
    offered_text += (offered_text.empty() ? "" : ", ") + FourccName(size.fourcc) + " " +
                    std::to_string(size.width) + "x" + std::to_string(size.height) +
                    (size.emulated ? " (emulated)" : "");
  }
  if (offered_text.empty()) offered_text = "nothing";
  if (!format || !offers(*format, false)) {
    if (why) {
      *why = (format ? "format " + PixelFormatName(*format) + " not offered"
                     : std::string("no decodable format")) +
             "; the device offers " + offered_text;
    }
    return std::nullopt;
  }
  // Among sizes of the chosen format, native entries win over emulated ones of the same size.
  std::optional<V4l2FrameSize> best;
  for (const V4l2FrameSize& size : offered) {
    if (PixelFormatFromFourcc(size.fourcc) != format) continue;
    if (request.width > 0 && size.width != request.width) continue;
    if (request.height > 0 && size.height != request.height) continue;
    const int64_t area = static_cast<int64_t>(size.width) * size.height;
    const int64_t best_area = best ? static_cast<int64_t>(best->width) * best->height : -1;
    if (area > best_area || (area == best_area && best->emulated && !size.emulated)) {
      best = size;
    }
  }
  if (!best && why) {
    *why = "size " + std::to_string(request.width) + "x" + std::to_string(request.height) +
           " not offered in " + PixelFormatName(*format) + "; the device offers " + offered_text;
  }
  return best;
}

std::optional<int32_t> V4l2ControlValue(double value, const V4l2Control& control) {
  if (!control.available || !std::isfinite(value)) return std::nullopt;
  const double step = std::max<int32_t>(1, control.step);
  if (value < control.minimum - step / 2 || value > control.maximum + step / 2) return std::nullopt;
  // The grid is minimum + k·step; its top may lie below `maximum` when the range is not a
  // whole number of steps.
  const double top =
      control.minimum + std::floor((control.maximum - control.minimum) / step) * step;
  const double steps = std::round((value - control.minimum) / step);
  const double snapped =
      std::clamp(control.minimum + steps * step, static_cast<double>(control.minimum), top);
  return static_cast<int32_t>(snapped);
}

std::optional<int32_t> V4l2ExposureValue(double exposure_us, const V4l2Control& exposure_absolute) {
  return V4l2ControlValue(exposure_us / kV4l2ExposureUnitUs, exposure_absolute);
}

double V4l2ExposureMicroseconds(int32_t value) { return value * kV4l2ExposureUnitUs; }

ControlRange V4l2ExposureRange(const V4l2Control& control) {
  if (!control.available) return {};
  return {true, control.minimum * kV4l2ExposureUnitUs, control.maximum * kV4l2ExposureUnitUs,
          std::max<int32_t>(1, control.step) * kV4l2ExposureUnitUs};
}

ControlRange V4l2GainRange(const V4l2Control& control) {
  if (!control.available) return {};
  return {true, static_cast<double>(control.minimum), static_cast<double>(control.maximum),
          static_cast<double>(std::max<int32_t>(1, control.step))};
}

}  // namespace procam
