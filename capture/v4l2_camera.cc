#include "capture/v4l2_camera.h"

#include <fcntl.h>
#include <libv4l2.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <set>

#include "base/check.h"

namespace procam {
namespace {

std::string CString(const uint8_t* text, size_t size) {
  return std::string(reinterpret_cast<const char*>(text),
                     strnlen(reinterpret_cast<const char*>(text), size));
}

uint32_t CaptureCaps(const v4l2_capability& capability) {
  return (capability.capabilities & V4L2_CAP_DEVICE_CAPS) ? capability.device_caps
                                                          : capability.capabilities;
}

}  // namespace

bool V4l2CameraOptions::Check(std::string* why) const {
  if (device.empty()) return Fail(why, "no device path");
  if (format.width < 0 || format.height < 0) return Fail(why, "width and height must be >= 0");
  if (!(frame_rate >= 0 && frame_rate <= 1000)) return Fail(why, "fps must be in [0, 1000]");
  if (buffers < 2 || buffers > 32) return Fail(why, "buffers must be in [2, 32]");
  return true;
}

V4l2CameraOptions V4l2CameraOptionsFromUri(const CameraUri& uri) {
  V4l2CameraOptions options;
  if (!uri.path().empty()) options.device = uri.path();
  if (uri.Has("format")) {
    const std::string name = uri.GetString("format", "");
    options.format.format = ParsePixelFormat(name);
    if (!options.format.format)
      throw IoError("camera '" + uri.text() + "': unknown pixel format '" + name + "'");
  }
  options.format.width = uri.GetInt("width", 0);
  options.format.height = uri.GetInt("height", 0);
  options.frame_rate = uri.GetDouble("fps", 0.0);
  options.buffers = uri.GetInt("buffers", options.buffers);
  uri.CheckAllRead();
  std::string why;
  if (!options.Check(&why)) throw IoError("camera '" + uri.text() + "': " + why);
  return options;
}

struct V4l2Camera::Impl {
  struct MappedBuffer {
    void* start = MAP_FAILED;
    size_t length = 0;
  };

  V4l2CameraOptions options;
  int fd = -1;
  std::string card, driver, bus;
  std::vector<V4l2FrameSize> offered;
  PixelFormat format = PixelFormat::kMono8;
  int width = 0, height = 0;
  size_t bytes_per_line = 0;
  std::vector<MappedBuffer> buffers;
  bool streaming = false;
  V4l2Control exposure_absolute, exposure_auto, gain, autogain;

  std::string Uri() const { return "v4l2:" + options.device; }

  // ioctl through libv4l2, retrying when a signal interrupts it.
  int Ioctl(unsigned long request, void* argument) const {
    int result;
    do {
      result = v4l2_ioctl(fd, request, argument);
    } while (result == -1 && errno == EINTR);
    return result;
  }

  // Throws the error of a failed call: CameraDisconnected when the device is gone.
  [[noreturn]] void Throw(const std::string& what, int error) const {
    const std::string message = "camera '" + Uri() + "': " + what + ": " + std::strerror(error);
    if (error == ENODEV || error == ENXIO || error == EIO) throw CameraDisconnected(message);
    throw IoError(message);
  }

  V4l2Control QueryControl(uint32_t id) const {
    v4l2_queryctrl query{};
    query.id = id;
    V4l2Control control;
    if (Ioctl(VIDIOC_QUERYCTRL, &query) == 0 && !(query.flags & V4L2_CTRL_FLAG_DISABLED)) {
      control.available = true;
      control.minimum = query.minimum;
      control.maximum = query.maximum;
      control.step = std::max<int32_t>(1, query.step);
      control.default_value = query.default_value;
    }
    return control;
  }

  int32_t GetControl(uint32_t id) const {
    v4l2_control control{};
    control.id = id;
    if (Ioctl(VIDIOC_G_CTRL, &control) != 0) Throw("reading control " + std::to_string(id), errno);
    return control.value;
  }

  void SetControl(uint32_t id, int32_t value, const std::string& name) {
    v4l2_control control{};
    control.id = id;
    control.value = value;
    if (Ioctl(VIDIOC_S_CTRL, &control) != 0)
      Throw("setting " + name + " to " + std::to_string(value), errno);
  }

  void EnumerateFormats() {
    offered.clear();
    for (uint32_t index = 0;; ++index) {
      v4l2_fmtdesc description{};
      description.index = index;
      description.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      if (Ioctl(VIDIOC_ENUM_FMT, &description) != 0) break;
      const bool emulated = description.flags & V4L2_FMT_FLAG_EMULATED;
      bool any_size = false;
      for (uint32_t size_index = 0;; ++size_index) {
        v4l2_frmsizeenum size{};
        size.index = size_index;
        size.pixel_format = description.pixelformat;
        if (Ioctl(VIDIOC_ENUM_FRAMESIZES, &size) != 0) break;
        any_size = true;
        if (size.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
          offered.push_back({description.pixelformat, static_cast<int>(size.discrete.width),
                             static_cast<int>(size.discrete.height), emulated});
        } else {  // stepwise or continuous: the largest, and the requested size when it fits
          const v4l2_frmsize_stepwise& range = size.stepwise;
          offered.push_back({description.pixelformat, static_cast<int>(range.max_width),
                             static_cast<int>(range.max_height), emulated});
          const int w = options.format.width, h = options.format.height;
          if (w > 0 && h > 0 && static_cast<uint32_t>(w) >= range.min_width &&
              static_cast<uint32_t>(w) <= range.max_width &&
              static_cast<uint32_t>(h) >= range.min_height &&
              static_cast<uint32_t>(h) <= range.max_height) {
            offered.push_back({description.pixelformat, w, h, emulated});
          }
          break;
        }
      }
      if (!any_size) {  // drivers without size enumeration: the current size
        v4l2_format current{};
        current.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        if (Ioctl(VIDIOC_G_FMT, &current) == 0) {
          offered.push_back({description.pixelformat, static_cast<int>(current.fmt.pix.width),
                             static_cast<int>(current.fmt.pix.height), emulated});
        }
      }
    }
  }

  void ApplyFormat(const V4l2FrameSize& choice) {
    v4l2_format requested{};
    requested.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    requested.fmt.pix.width = static_cast<uint32_t>(choice.width);
    requested.fmt.pix.height = static_cast<uint32_t>(choice.height);
    requested.fmt.pix.pixelformat = choice.fourcc;
    requested.fmt.pix.field = V4L2_FIELD_NONE;
    if (Ioctl(VIDIOC_S_FMT, &requested) != 0)
      Throw("setting format " + FourccName(choice.fourcc), errno);
    const auto accepted = PixelFormatFromFourcc(requested.fmt.pix.pixelformat);
    if (!accepted) {
      throw IoError("camera '" + Uri() + "': driver chose format " +
                    FourccName(requested.fmt.pix.pixelformat) + ", which procam cannot decode");
    }
    format = *accepted;
    width = static_cast<int>(requested.fmt.pix.width);
    height = static_cast<int>(requested.fmt.pix.height);
    bytes_per_line = format == PixelFormat::kMJPEG ? 0 : requested.fmt.pix.bytesperline;
    if (options.frame_rate > 0) {
      v4l2_streamparm parameters{};
      parameters.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      if (Ioctl(VIDIOC_G_PARM, &parameters) != 0 ||
          !(parameters.parm.capture.capability & V4L2_CAP_TIMEPERFRAME)) {
        throw IoError("camera '" + Uri() +
                      "': the device cannot set its frame rate; leave out fps=");
      }
      parameters.parm.capture.timeperframe.numerator = 1000;
      parameters.parm.capture.timeperframe.denominator =
          static_cast<uint32_t>(std::lround(options.frame_rate * 1000));
      if (Ioctl(VIDIOC_S_PARM, &parameters) != 0) Throw("setting the frame rate", errno);
    }
  }

  // libv4l2 prints lines of its own on stderr when what it opens is not a V4L2 device (a regular
  // file, /dev/null): the kernel is asked first, so that such a path is one line of procam's.
  void CheckIsV4l2Device() const {
    struct stat info {};
    if (::stat(options.device.c_str(), &info) != 0) return;  // v4l2_open names the error
    if (!S_ISCHR(info.st_mode)) {
      throw IoError("camera '" + Uri() + "': " + options.device +
                    " is not a device (a V4L2 camera is a character device such as /dev/video0; "
                    "see `procam cameras`)");
    }
    const int probe = ::open(options.device.c_str(), O_RDWR | O_NONBLOCK);
    if (probe < 0) return;  // v4l2_open names the error (permissions, ...)
    v4l2_capability capability{};
    const bool v4l2 = ::ioctl(probe, VIDIOC_QUERYCAP, &capability) == 0;
    const int error = errno;
    ::close(probe);
    if (!v4l2) {
      throw IoError("camera '" + Uri() + "': " + options.device + " is not a V4L2 device (" +
                    std::strerror(error) + "; see `procam cameras`)");
    }
  }

  void Open() {
    CheckIsV4l2Device();
    fd = v4l2_open(options.device.c_str(), O_RDWR | O_NONBLOCK);
    if (fd < 0) {
      const int error = errno;
      std::string hint;
      if (error == EACCES) hint = " (add yourself to the 'video' group)";
      if (error == ENOENT) hint = " (see `procam cameras` for the devices present)";
      throw IoError("camera '" + Uri() + "': cannot open: " + std::strerror(error) + hint);
    }
    v4l2_capability capability{};
    if (Ioctl(VIDIOC_QUERYCAP, &capability) != 0) Throw("not a V4L2 device", errno);
    const uint32_t caps = CaptureCaps(capability);
    if (!(caps & V4L2_CAP_VIDEO_CAPTURE))
      throw IoError("camera '" + Uri() + "': not a video capture device");
    if (!(caps & V4L2_CAP_STREAMING))
      throw IoError("camera '" + Uri() + "': device does not support streaming I/O");
    card = CString(capability.card, sizeof(capability.card));
    driver = CString(capability.driver, sizeof(capability.driver));
    bus = CString(capability.bus_info, sizeof(capability.bus_info));
    EnumerateFormats();
    std::string why;
    const auto choice = ChooseV4l2Format(offered, options.format, &why);
    if (!choice) throw IoError("camera '" + Uri() + "': " + why);
    ApplyFormat(*choice);
    exposure_absolute = QueryControl(V4L2_CID_EXPOSURE_ABSOLUTE);
    exposure_auto = QueryControl(V4L2_CID_EXPOSURE_AUTO);
    gain = QueryControl(V4L2_CID_GAIN);
    autogain = QueryControl(V4L2_CID_AUTOGAIN);
  }

  void StartStreaming() {
    if (streaming) return;
    v4l2_requestbuffers request{};
    request.count = static_cast<uint32_t>(options.buffers);
    request.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    request.memory = V4L2_MEMORY_MMAP;
    if (Ioctl(VIDIOC_REQBUFS, &request) != 0) Throw("requesting buffers", errno);
    if (request.count < 2)
      throw IoError("camera '" + Uri() + "': driver granted only " + std::to_string(request.count) +
                    " buffer");
    buffers.assign(request.count, MappedBuffer());
    for (uint32_t i = 0; i < request.count; ++i) {
      v4l2_buffer buffer{};
      buffer.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      buffer.memory = V4L2_MEMORY_MMAP;
      buffer.index = i;
      if (Ioctl(VIDIOC_QUERYBUF, &buffer) != 0) Throw("querying buffer", errno);
      buffers[i].length = buffer.length;
      buffers[i].start = v4l2_mmap(nullptr, buffer.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd,
                                   buffer.m.offset);
      if (buffers[i].start == MAP_FAILED) Throw("mapping buffer", errno);
      if (Ioctl(VIDIOC_QBUF, &buffer) != 0) Throw("queueing buffer", errno);
    }
    v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (Ioctl(VIDIOC_STREAMON, &type) != 0) Throw("starting the stream", errno);
    streaming = true;
  }

  // Never throws: also used on error paths and in the destructor.
  void StopStreaming() {
    if (fd >= 0 && streaming) {
      v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      Ioctl(VIDIOC_STREAMOFF, &type);
    }
    streaming = false;
    for (MappedBuffer& buffer : buffers) {
      if (buffer.start != MAP_FAILED) v4l2_munmap(buffer.start, buffer.length);
    }
    buffers.clear();
    if (fd >= 0) {
      v4l2_requestbuffers release{};
      release.count = 0;
      release.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
      release.memory = V4L2_MEMORY_MMAP;
      Ioctl(VIDIOC_REQBUFS, &release);
    }
  }

  // Dequeues one filled buffer without waiting; false when none is ready.
  bool Dequeue(v4l2_buffer* buffer) {
    *buffer = v4l2_buffer{};
    buffer->type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buffer->memory = V4L2_MEMORY_MMAP;
    if (Ioctl(VIDIOC_DQBUF, buffer) == 0) return true;
    if (errno == EAGAIN) return false;
    Throw("dequeueing a frame", errno);
  }

  void Requeue(v4l2_buffer* buffer) {
    if (Ioctl(VIDIOC_QBUF, buffer) != 0) Throw("requeueing a frame", errno);
  }

  double ExposureUs() const {
    return exposure_absolute.available
               ? V4l2ExposureMicroseconds(GetControl(V4L2_CID_EXPOSURE_ABSOLUTE))
               : 0.0;
  }
};

V4l2Camera::V4l2Camera(const V4l2CameraOptions& options) : impl_(std::make_unique<Impl>()) {
  std::string why;
  if (!options.Check(&why)) throw IoError("camera 'v4l2:" + options.device + "': " + why);
  impl_->options = options;
  try {
    impl_->Open();
  } catch (...) {
    if (impl_->fd >= 0) v4l2_close(impl_->fd);
    impl_->fd = -1;
    throw;
  }
}

V4l2Camera::~V4l2Camera() {
  impl_->StopStreaming();
  if (impl_->fd >= 0) v4l2_close(impl_->fd);
}

CameraInfo V4l2Camera::Info() const {
  CameraInfo info;
  info.uri = impl_->Uri();
  info.backend = "v4l2";
  info.vendor = impl_->driver;
  info.model = impl_->card;
  info.serial = impl_->bus;
  info.description = impl_->card + " (" + impl_->driver + ", " + impl_->bus + "), " +
                     std::to_string(impl_->width) + "x" + std::to_string(impl_->height) + " " +
                     PixelFormatName(impl_->format);
  return info;
}

CameraSettings V4l2Camera::Settings() const {
  CameraSettings settings;
  settings.width = impl_->width;
  settings.height = impl_->height;
  settings.pixel_format = impl_->format;
  settings.exposure_us = impl_->ExposureUs();
  settings.auto_exposure = impl_->exposure_auto.available &&
                           impl_->GetControl(V4L2_CID_EXPOSURE_AUTO) != V4L2_EXPOSURE_MANUAL;
  settings.gain = impl_->gain.available ? impl_->GetControl(V4L2_CID_GAIN) : 0.0;
  settings.gain_unit = "driver";
  settings.trigger = "free-running";
  settings.exposure_range_us = V4l2ExposureRange(impl_->exposure_absolute);
  settings.gain_range = V4l2GainRange(impl_->gain);
  return settings;
}

std::vector<PixelFormat> V4l2Camera::SupportedPixelFormats() const {
  std::set<PixelFormat> formats;
  for (const V4l2FrameSize& size : impl_->offered) {
    if (const auto format = PixelFormatFromFourcc(size.fourcc)) formats.insert(*format);
  }
  return std::vector<PixelFormat>(formats.begin(), formats.end());
}

void V4l2Camera::SetExposure(double exposure_us) {
  const auto value = V4l2ExposureValue(exposure_us, impl_->exposure_absolute);
  if (!value) {
    if (!impl_->exposure_absolute.available) {
      throw IoError("camera '" + impl_->Uri() +
                    "': the device has no manual exposure control (exposure_absolute)");
    }
    const ControlRange range = V4l2ExposureRange(impl_->exposure_absolute);
    throw IoError("camera '" + impl_->Uri() + "': exposure " + std::to_string(exposure_us) +
                  " us outside [" + std::to_string(range.min) + ", " + std::to_string(range.max) +
                  "] us");
  }
  if (impl_->exposure_auto.available)
    impl_->SetControl(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL, "exposure_auto");
  impl_->SetControl(V4L2_CID_EXPOSURE_ABSOLUTE, *value, "exposure_absolute");
}

void V4l2Camera::SetGain(double gain) {
  const auto value = V4l2ControlValue(gain, impl_->gain);
  if (!value) {
    if (!impl_->gain.available)
      throw IoError("camera '" + impl_->Uri() + "': the device has no gain control");
    throw IoError("camera '" + impl_->Uri() + "': gain " + std::to_string(gain) + " outside [" +
                  std::to_string(impl_->gain.minimum) + ", " + std::to_string(impl_->gain.maximum) +
                  "]");
  }
  if (impl_->autogain.available) impl_->SetControl(V4L2_CID_AUTOGAIN, 0, "autogain");
  impl_->SetControl(V4L2_CID_GAIN, *value, "gain");
}

void V4l2Camera::SetPixelFormat(PixelFormat format) {
  const bool was_streaming = impl_->streaming;
  impl_->StopStreaming();
  V4l2FormatRequest request{format, impl_->width, impl_->height};
  std::string why;
  auto choice = ChooseV4l2Format(impl_->offered, request, &why);
  if (!choice) choice = ChooseV4l2Format(impl_->offered, V4l2FormatRequest{format, 0, 0}, &why);
  if (!choice) throw IoError("camera '" + impl_->Uri() + "': " + why);
  impl_->ApplyFormat(*choice);
  if (was_streaming) impl_->StartStreaming();
}

void V4l2Camera::Start() {
  try {
    impl_->StartStreaming();
  } catch (...) {
    impl_->StopStreaming();
    throw;
  }
}

void V4l2Camera::Stop() { impl_->StopStreaming(); }

Frame V4l2Camera::Grab(std::chrono::milliseconds timeout) {
  Start();
  const int64_t deadline =
      SteadyNowNs() + std::chrono::duration_cast<std::chrono::nanoseconds>(timeout).count();
  int bad_buffers = 0;
  for (;;) {
    v4l2_buffer buffer;
    if (!impl_->Dequeue(&buffer)) {
      const int64_t left_ms = (deadline - SteadyNowNs()) / 1000000;
      if (left_ms <= 0) {
        throw CameraTimeout(
            "camera '" + impl_->Uri() + "': no frame within " + std::to_string(timeout.count()) +
            " ms" +
            (bad_buffers ? " (" + std::to_string(bad_buffers) + " corrupted buffers)" : ""));
      }
      pollfd poll_fd{impl_->fd, POLLIN, 0};
      const int ready = poll(&poll_fd, 1, static_cast<int>(std::min<int64_t>(left_ms, 1000)));
      if (ready < 0 && errno != EINTR) impl_->Throw("waiting for a frame", errno);
      if (ready > 0 && (poll_fd.revents & (POLLERR | POLLHUP | POLLNVAL)) &&
          !(poll_fd.revents & POLLIN)) {
        throw CameraDisconnected("camera '" + impl_->Uri() +
                                 "': device stopped answering (poll error)");
      }
      continue;
    }
    const int64_t arrival = SteadyNowNs();
    if (buffer.flags & V4L2_BUF_FLAG_ERROR) {
      ++bad_buffers;
      impl_->Requeue(&buffer);
      continue;
    }
    Frame frame;
    try {
      RawImage raw;
      raw.data = static_cast<const uint8_t*>(impl_->buffers.at(buffer.index).start);
      raw.size = buffer.bytesused;
      raw.width = impl_->width;
      raw.height = impl_->height;
      raw.stride = impl_->bytes_per_line;
      raw.format = impl_->format;
      frame.image = DecodeImage(raw);
    } catch (const IoError& error) {
      impl_->Requeue(&buffer);
      if (impl_->format == PixelFormat::kMJPEG) {  // a torn JPEG happens now and then: skip it
        ++bad_buffers;
        continue;
      }
      throw IoError("camera '" + impl_->Uri() + "': " + error.what());
    }
    impl_->Requeue(&buffer);
    frame.source_format = impl_->format;
    frame.sequence = buffer.sequence;
    frame.exposure_us = impl_->ExposureUs();
    frame.gain = impl_->gain.available ? impl_->GetControl(V4L2_CID_GAIN) : 0.0;
    frame.arrival_ns = arrival;
    const int64_t exposure_ns = static_cast<int64_t>(std::llround(frame.exposure_us * 1e3));
    const int64_t stamp = static_cast<int64_t>(buffer.timestamp.tv_sec) * 1000000000 +
                          buffer.timestamp.tv_usec * 1000;
    frame.device_timestamp_ns = stamp;
    if ((buffer.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC &&
        stamp > 0) {
      // CLOCK_MONOTONIC, the steady clock's: start of exposure (SOE) or end of frame (EOF).
      const bool start_of_exposure =
          (buffer.flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_SOE;
      frame.exposure_start_ns = start_of_exposure ? stamp : stamp - exposure_ns;
    } else {
      frame.exposure_start_ns = arrival - exposure_ns;
    }
    return frame;
  }
}

int V4l2Camera::DropBufferedFrames() {
  if (!impl_->streaming) return 0;
  int dropped = 0;
  v4l2_buffer buffer;
  while (impl_->Dequeue(&buffer)) {
    impl_->Requeue(&buffer);
    ++dropped;
  }
  return dropped;
}

std::vector<CameraInfo> ListV4l2Cameras() {
  std::vector<std::string> nodes;
  std::error_code error;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", error)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("video", 0) == 0) nodes.push_back(entry.path().string());
  }
  std::sort(nodes.begin(), nodes.end(), [](const std::string& a, const std::string& b) {
    return a.size() != b.size() ? a.size() < b.size() : a < b;
  });
  std::vector<CameraInfo> cameras;
  for (const std::string& node : nodes) {
    CameraInfo info;
    info.uri = "v4l2:" + node;
    info.backend = "v4l2";
    const int fd = ::open(node.c_str(), O_RDWR | O_NONBLOCK);
    if (fd < 0) {
      info.description = std::string("cannot open: ") + std::strerror(errno);
      cameras.push_back(info);
      continue;
    }
    v4l2_capability capability{};
    if (::ioctl(fd, VIDIOC_QUERYCAP, &capability) == 0 &&
        (CaptureCaps(capability) & V4L2_CAP_VIDEO_CAPTURE)) {
      info.vendor = CString(capability.driver, sizeof(capability.driver));
      info.model = CString(capability.card, sizeof(capability.card));
      info.serial = CString(capability.bus_info, sizeof(capability.bus_info));
      std::string formats;
      for (uint32_t index = 0;; ++index) {
        v4l2_fmtdesc description{};
        description.index = index;
        description.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        if (::ioctl(fd, VIDIOC_ENUM_FMT, &description) != 0) break;
        formats += (formats.empty() ? "" : " ") + FourccName(description.pixelformat);
      }
      info.description =
          info.model + " (" + info.vendor + ", " + info.serial + "), formats: " + formats;
      cameras.push_back(info);
    }
    ::close(fd);
  }
  return cameras;
}

CameraBackend V4l2CameraBackend() {
  CameraBackend backend;
  backend.scheme = "v4l2";
  backend.description = "Video4Linux2 devices (webcams), through libv4l2";
  backend.open = [](const CameraUri& uri, const OpenCameraOptions&) -> std::unique_ptr<Camera> {
    return std::make_unique<V4l2Camera>(V4l2CameraOptionsFromUri(uri));
  };
  backend.list = [](const ListCamerasOptions&) { return ListV4l2Cameras(); };
  return backend;
}

}  // namespace procam
