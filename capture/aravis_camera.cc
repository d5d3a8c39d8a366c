#include "capture/aravis_camera.h"

#include <arpa/inet.h>
#include <arv.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <mutex>

#include "base/check.h"

namespace procam {
namespace {

// The local address the kernel would send from to reach `address` (a connected UDP socket:
// connecting sends nothing). Empty when there is no route.
std::string RoutedSourceAddress(const std::string& address) {
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return "";
  sockaddr_in remote{};
  remote.sin_family = AF_INET;
  remote.sin_port = htons(3956);
  inet_pton(AF_INET, address.c_str(), &remote.sin_addr);
  std::string local_text;
  sockaddr_in local{};
  socklen_t length = sizeof(local);
  char text[INET_ADDRSTRLEN] = {};
  if (connect(fd, reinterpret_cast<const sockaddr*>(&remote), sizeof(remote)) == 0 &&
      getsockname(fd, reinterpret_cast<sockaddr*>(&local), &length) == 0 &&
      inet_ntop(AF_INET, &local.sin_addr, text, sizeof(text)) != nullptr) {
    local_text = text;
  }
  close(fd);
  return local_text;
}

// The largest receive buffer an unprivileged process may give a socket (net.core.rmem_max), in
// bytes; 0 when it cannot be read.
int64_t ReceiveBufferLimit() {
  std::ifstream file("/proc/sys/net/core/rmem_max");
  int64_t bytes = 0;
  return file >> bytes ? bytes : 0;
}

}  // namespace

std::optional<PixelFormat> PixelFormatFromPfnc(uint32_t code) {
  switch (static_cast<ArvPixelFormat>(code)) {
    case ARV_PIXEL_FORMAT_MONO_8:
      return PixelFormat::kMono8;
    case ARV_PIXEL_FORMAT_MONO_16:
      return PixelFormat::kMono16;
    case ARV_PIXEL_FORMAT_BAYER_RG_8:
      return PixelFormat::kBayerRG8;
    case ARV_PIXEL_FORMAT_BAYER_BG_8:
      return PixelFormat::kBayerBG8;
    case ARV_PIXEL_FORMAT_BAYER_GR_8:
      return PixelFormat::kBayerGR8;
    case ARV_PIXEL_FORMAT_BAYER_GB_8:
      return PixelFormat::kBayerGB8;
    case ARV_PIXEL_FORMAT_RGB_8_PACKED:
      return PixelFormat::kRGB8;
    case ARV_PIXEL_FORMAT_BGR_8_PACKED:
      return PixelFormat::kBGR8;
    case ARV_PIXEL_FORMAT_YUV_422_YUYV_PACKED:
      return PixelFormat::kYUYV;
    default:
      return std::nullopt;
  }
}

std::optional<uint32_t> PfncFromPixelFormat(PixelFormat format) {
  for (uint32_t code :
       {ARV_PIXEL_FORMAT_MONO_8, ARV_PIXEL_FORMAT_MONO_16, ARV_PIXEL_FORMAT_BAYER_RG_8,
        ARV_PIXEL_FORMAT_BAYER_BG_8, ARV_PIXEL_FORMAT_BAYER_GR_8, ARV_PIXEL_FORMAT_BAYER_GB_8,
        ARV_PIXEL_FORMAT_RGB_8_PACKED, ARV_PIXEL_FORMAT_BGR_8_PACKED,
        ARV_PIXEL_FORMAT_YUV_422_YUYV_PACKED}) {
    if (PixelFormatFromPfnc(code) == format) return code;
  }
  return std::nullopt;
}

namespace {

std::optional<PixelFormat> FromArv(ArvPixelFormat code) { return PixelFormatFromPfnc(code); }

// The GenICam PixelFormat entry of a format ("YUV422_8" is the Y U Y V order).
std::string GenicamName(PixelFormat format) {
  return format == PixelFormat::kYUYV ? std::string("YUV422_8") : PixelFormatName(format);
}

// Nanoseconds between the real-time clock (Aravis's system timestamps) and the steady clock.
int64_t RealtimeMinusSteadyNs() {
  const int64_t real = std::chrono::duration_cast<std::chrono::nanoseconds>(
                           std::chrono::system_clock::now().time_since_epoch())
                           .count();
  return real - SteadyNowNs();
}

std::string StatusName(ArvBufferStatus status) {
  switch (status) {
    case ARV_BUFFER_STATUS_SUCCESS:
      return "success";
    case ARV_BUFFER_STATUS_CLEARED:
      return "cleared";
    case ARV_BUFFER_STATUS_TIMEOUT:
      return "packet timeout";
    case ARV_BUFFER_STATUS_MISSING_PACKETS:
      return "missing packets";
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID:
      return "wrong packet id";
    case ARV_BUFFER_STATUS_SIZE_MISMATCH:
      return "size mismatch";
    case ARV_BUFFER_STATUS_FILLING:
      return "filling";
    case ARV_BUFFER_STATUS_ABORTED:
      return "aborted";
    default:
      return "unknown";
  }
}

// Aravis's interface switches are process-wide.
std::mutex& InterfaceMutex() {
  static std::mutex mutex;
  return mutex;
}

}  // namespace

bool AravisCameraOptions::Check(std::string* why) const {
  if (device_id.empty() && gige_address.empty())
    return Fail(why, "no device id (aravis:<id>; `procam cameras` lists them)");
  if (!device_id.empty() && !gige_address.empty())
    return Fail(why, "give a device id or a GigE Vision address, not both");
  if (!gige_address.empty() && !IsIpv4Address(gige_address))
    return Fail(why, "'" + gige_address + "' is not an IPv4 address (aravis:gv:<address>)");
  if (!interface_address.empty() && gige_address.empty())
    return Fail(why, "interface is for cameras opened by address (aravis:gv:<address>)");
  if (!interface_address.empty() && !IsIpv4Address(interface_address))
    return Fail(why, "interface '" + interface_address + "' is not an IPv4 address");
  if (trigger != "auto" && trigger != "software" && trigger != "free") {
    return Fail(why, "trigger must be auto, software or free, got '" + trigger + "'");
  }
  if (buffers < 2 || buffers > 64) return Fail(why, "buffers must be in [2, 64]");
  if (packet_size != 0 && (packet_size < 576 || packet_size > 65000))
    return Fail(why, "packet_size must be in [576, 65000] bytes (or 0: the camera's)");
  return true;
}

bool IsIpv4Address(const std::string& text) {
  in_addr parsed{};
  return inet_pton(AF_INET, text.c_str(), &parsed) == 1;
}

AravisCameraOptions AravisCameraOptionsFromUri(const CameraUri& uri) {
  AravisCameraOptions options;
  if (uri.path().rfind("gv:", 0) == 0) {
    options.gige_address = uri.path().substr(3);
    options.interface_address = uri.GetString("interface", "");
  } else {
    options.device_id = uri.path();
  }
  options.trigger = uri.GetString("trigger", options.trigger);
  options.buffers = uri.GetInt("buffers", options.buffers);
  options.packet_size = uri.GetInt("packet_size", options.packet_size);
  if (uri.Has("format")) {
    const std::string name = uri.GetString("format", "");
    options.format = ParsePixelFormat(name);
    if (!options.format)
      throw IoError("camera '" + uri.text() + "': unknown pixel format '" + name + "'");
  }
  uri.CheckAllRead();
  std::string why;
  if (!options.Check(&why)) throw IoError("camera '" + uri.text() + "': " + why);
  return options;
}

struct AravisCamera::Impl {
  AravisCameraOptions options;
  ArvCamera* camera = nullptr;
  ArvStream* stream = nullptr;
  gulong control_lost_handler = 0;
  std::atomic<bool> control_lost{false};
  bool gone = false;  // the last control request went unanswered: closing skips the stop
  // ExposureTime and Gain as last set or read, so a grab needs no control transaction.
  double exposure_us = 0.0;
  double gain = 0.0;
  bool software_trigger = false;
  // The device clock onto the steady clock: exposure start ≈ device timestamp + offset, offset
  // the smallest (arrival − exposure − device timestamp) seen, allowed to grow 100 ppm of the
  // time since (the two clocks drift). INT64_MAX until a frame with a device timestamp arrives.
  int64_t clock_offset_ns = std::numeric_limits<int64_t>::max();
  int64_t clock_offset_at_ns = 0;  // steady time of the frame that set it
  int64_t last_device_ns = 0;      // a device clock that goes back (a restarted camera) starts over
  PixelFormat format = PixelFormat::kMono8;
  // Set when a GigE Vision stream's frame is larger than net.core.rmem_max lets its UDP socket
  // buffer: what to raise, said with every timeout of incomplete frames.
  std::string receive_buffer_advice;

  std::string Uri() const {
    return "aravis:" + (options.gige_address.empty() ? options.device_id
                                                      : "gv:" + options.gige_address);
  }

  // Throws for a failed call; lost connections become CameraDisconnected.
  void Check(GError* error, const std::string& what) {
    if (error == nullptr) {
      gone = false;
      return;
    }
    const std::string message = "camera '" + Uri() + "': " + what + ": " + error->message;
    const bool unreachable =
        error->domain == ARV_DEVICE_ERROR &&
        (error->code == ARV_DEVICE_ERROR_NOT_CONNECTED || error->code == ARV_DEVICE_ERROR_TIMEOUT ||
         error->code == ARV_DEVICE_ERROR_TRANSFER_ERROR);
    g_error_free(error);
    if (unreachable || control_lost) {
      gone = true;
      throw CameraDisconnected(message);
    }
    throw IoError(message);
  }

  void CheckConnected() {
    if (control_lost) {
      throw CameraDisconnected("camera '" + Uri() +
                               "': lost the connection to the camera (control lost)");
    }
  }

  static void OnControlLost(ArvDevice*, gpointer self) {
    static_cast<Impl*>(self)->control_lost = true;
  }

  // A GigE Vision camera by address: the GVCP socket talks to that address only.
  ArvCamera* OpenByAddress() {
    const std::string local = options.interface_address.empty()
                                  ? RoutedSourceAddress(options.gige_address)
                                  : options.interface_address;
    if (local.empty()) throw IoError("camera '" + Uri() + "': no route to the address");
    GInetAddress* interface_address = g_inet_address_new_from_string(local.c_str());
    GInetAddress* device_address = g_inet_address_new_from_string(options.gige_address.c_str());
    GError* error = nullptr;
    ArvDevice* device = arv_gv_device_new(interface_address, device_address, &error);
    g_object_unref(interface_address);
    g_object_unref(device_address);
    if (device == nullptr && error == nullptr)
      throw IoError("camera '" + Uri() + "': no GigE Vision camera answers (from " + local + ")");
    Check(error, "cannot open (from " + local + ")");
    ArvCamera* opened = arv_camera_new_with_device(device, &error);
    g_object_unref(device);  // the camera holds its own reference
    if (opened == nullptr && error == nullptr)
      throw IoError("camera '" + Uri() + "': cannot open");
    Check(error, "cannot open");
    return opened;
  }

  void Open() {
    if (!options.gige_address.empty()) {
      camera = OpenByAddress();
    } else {
      OpenById();
    }
    FinishOpening();
  }

  void OpenById() {
    {
      std::lock_guard<std::mutex> lock(InterfaceMutex());
      if (options.device_id.rfind("Fake", 0) == 0) {  // never broadcast for the in-process camera
        arv_disable_interface("GigEVision");
        arv_enable_interface("Fake");
      }
    }
    GError* error = nullptr;
    camera = arv_camera_new(options.device_id.c_str(), &error);
    if (camera == nullptr && error == nullptr) {
      throw IoError("camera '" + Uri() + "': not found (see `procam cameras`)");
    }
    Check(error, "cannot open");
  }

  void FinishOpening() {
    GError* error = nullptr;
    control_lost_handler = g_signal_connect(arv_camera_get_device(camera), "control-lost",
                                            G_CALLBACK(&Impl::OnControlLost), this);

    if (options.format) {
      arv_camera_set_pixel_format_from_string(camera, GenicamName(*options.format).c_str(), &error);
      Check(error, "setting PixelFormat " + GenicamName(*options.format));
    }
    const ArvPixelFormat code = arv_camera_get_pixel_format(camera, &error);
    Check(error, "reading PixelFormat");
    if (const auto decoded = FromArv(code)) {
      format = *decoded;
    } else {  // e.g. Mono12Packed: fall back to Mono8, which every GenICam camera offers
      const char* name = arv_camera_get_pixel_format_as_string(camera, nullptr);
      arv_camera_set_pixel_format(camera, ARV_PIXEL_FORMAT_MONO_8, &error);
      if (error) {
        g_error_free(error);
        throw IoError("camera '" + Uri() + "': pixel format " + std::string(name ? name : "?") +
                      " is not supported and Mono8 cannot be set; choose one with ?format=");
      }
      format = PixelFormat::kMono8;
    }

    if (options.packet_size > 0) {
      if (!arv_camera_is_gv_device(camera))
        throw IoError("camera '" + Uri() + "': packet_size is for GigE Vision cameras");
      arv_camera_gv_set_packet_size_adjustment(camera, ARV_GV_PACKET_SIZE_ADJUSTMENT_NEVER);
      arv_camera_gv_set_packet_size(camera, options.packet_size, &error);
      Check(error, "setting the packet size to " + std::to_string(options.packet_size));
    }
    arv_camera_set_acquisition_mode(camera, ARV_ACQUISITION_MODE_CONTINUOUS, &error);
    Check(error, "setting continuous acquisition");
    const bool supported = arv_camera_is_software_trigger_supported(camera, &error);
    Check(error, "querying the software trigger");
    if (options.trigger == "software" && !supported) {
      throw IoError("camera '" + Uri() + "': no software trigger; use trigger=free");
    }
    ReadExposureAndGain();
    software_trigger = options.trigger != "free" && supported;
    if (software_trigger) {
      arv_camera_set_trigger(camera, "Software", &error);
      Check(error, "setting the software trigger");
    } else {
      arv_camera_clear_triggers(camera, &error);
      Check(error, "switching triggers off");
    }
  }

  void ReadExposureAndGain() {
    GError* error = nullptr;
    if (arv_camera_is_exposure_time_available(camera, nullptr)) {
      exposure_us = arv_camera_get_exposure_time(camera, &error);
      Check(error, "reading ExposureTime");
    }
    if (arv_camera_is_gain_available(camera, nullptr)) {
      gain = arv_camera_get_gain(camera, &error);
      Check(error, "reading Gain");
    }
  }

  void StartStreaming() {
    CheckConnected();
    if (stream != nullptr) return;
    GError* error = nullptr;
    stream = arv_camera_create_stream(camera, nullptr, nullptr, &error);
    if (stream == nullptr && error == nullptr)
      throw IoError("camera '" + Uri() + "': cannot create a stream");
    Check(error, "creating the stream");
    const guint payload = arv_camera_get_payload(camera, &error);
    Check(error, "reading the payload size");
    if (ARV_IS_GV_STREAM(stream)) {
      // Without CAP_NET_RAW Aravis receives through a UDP socket, whose default buffer
      // (net.core.rmem_default, about 208 KiB) holds a fraction of a megabyte frame sent in one
      // burst: the rest is dropped. AUTO sizes it to one frame; the kernel caps that silently at
      // net.core.rmem_max, so the cap is checked here and named when frames come incomplete.
      g_object_set(stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_AUTO, "socket-buffer-size",
                   0, nullptr);
      const int64_t limit = ReceiveBufferLimit();
      receive_buffer_advice.clear();
      if (limit > 0 && limit < static_cast<int64_t>(payload)) {
        receive_buffer_advice = "a frame is " + std::to_string(payload) +
                                " bytes, over the receive buffer net.core.rmem_max allows (" +
                                std::to_string(limit) +
                                " bytes): raise it, e.g. sudo sysctl -w net.core.rmem_max=" +
                                std::to_string(2 * static_cast<int64_t>(payload));
      }
    }
    for (int i = 0; i < options.buffers; ++i)
      arv_stream_push_buffer(stream, arv_buffer_new_allocate(payload));
    arv_camera_start_acquisition(camera, &error);
    Check(error, "starting acquisition");
  }

  // Never throws: used on error paths and in the destructor.
  void StopStreaming() {
    if (stream == nullptr) return;
    GError* error = nullptr;
    // An unreachable device would keep us through every retry of the command (seconds).
    if (!gone && !control_lost) arv_camera_stop_acquisition(camera, &error);
    if (error) g_error_free(error);
    g_object_unref(stream);  // stops the stream thread and frees its buffers
    stream = nullptr;
  }
};

AravisCamera::AravisCamera(const AravisCameraOptions& options) : impl_(std::make_unique<Impl>()) {
  std::string why;
  if (!options.Check(&why)) throw IoError("camera 'aravis:" + options.device_id + "': " + why);
  impl_->options = options;
  try {
    impl_->Open();
  } catch (...) {
    if (impl_->camera) {
      if (impl_->control_lost_handler)
        g_signal_handler_disconnect(arv_camera_get_device(impl_->camera),
                                    impl_->control_lost_handler);
      g_object_unref(impl_->camera);
    }
    throw;
  }
}

AravisCamera::~AravisCamera() {
  impl_->StopStreaming();
  if (impl_->control_lost_handler)
    g_signal_handler_disconnect(arv_camera_get_device(impl_->camera), impl_->control_lost_handler);
  g_object_unref(impl_->camera);
}

ArvCamera* AravisCamera::handle() const { return impl_->camera; }

CameraInfo AravisCamera::Info() const {
  CameraInfo info;
  info.uri = impl_->Uri();
  info.backend = "aravis";
  GError* error = nullptr;
  const char* vendor = arv_camera_get_vendor_name(impl_->camera, &error);
  if (error) g_clear_error(&error);
  const char* model = arv_camera_get_model_name(impl_->camera, &error);
  if (error) g_clear_error(&error);
  const char* serial = arv_camera_get_device_serial_number(impl_->camera, &error);
  if (error) g_clear_error(&error);
  info.vendor = vendor ? vendor : "";
  info.model = model ? model : "";
  info.serial = serial ? serial : "";
  info.description = info.vendor + " " + info.model + " (" + PixelFormatName(impl_->format) +
                     (impl_->software_trigger ? ", software trigger)" : ", free-running)");
  return info;
}

CameraSettings AravisCamera::Settings() const {
  impl_->CheckConnected();
  CameraSettings settings;
  GError* error = nullptr;
  int x = 0, y = 0;
  arv_camera_get_region(impl_->camera, &x, &y, &settings.width, &settings.height, &error);
  impl_->Check(error, "reading the region");
  settings.pixel_format = impl_->format;
  settings.trigger = impl_->software_trigger ? "software" : "free-running";
  settings.gain_unit = "dB";
  if (arv_camera_is_exposure_time_available(impl_->camera, nullptr)) {
    settings.exposure_us = arv_camera_get_exposure_time(impl_->camera, &error);
    impl_->Check(error, "reading ExposureTime");
    settings.exposure_range_us.available = true;
    arv_camera_get_exposure_time_bounds(impl_->camera, &settings.exposure_range_us.min,
                                        &settings.exposure_range_us.max, &error);
    impl_->Check(error, "reading ExposureTime bounds");
    if (arv_camera_is_exposure_auto_available(impl_->camera, nullptr)) {
      settings.auto_exposure =
          arv_camera_get_exposure_time_auto(impl_->camera, nullptr) != ARV_AUTO_OFF;
    }
  }
  if (arv_camera_is_gain_available(impl_->camera, nullptr)) {
    settings.gain = arv_camera_get_gain(impl_->camera, &error);
    impl_->Check(error, "reading Gain");
    settings.gain_range.available = true;
    arv_camera_get_gain_bounds(impl_->camera, &settings.gain_range.min, &settings.gain_range.max,
                               &error);
    impl_->Check(error, "reading Gain bounds");
  }
  return settings;
}

std::vector<PixelFormat> AravisCamera::SupportedPixelFormats() const {
  std::vector<PixelFormat> formats;
  guint count = 0;
  GError* error = nullptr;
  gint64* codes = arv_camera_dup_available_pixel_formats(impl_->camera, &count, &error);
  impl_->Check(error, "listing pixel formats");
  for (guint i = 0; i < count; ++i) {
    if (const auto format = FromArv(static_cast<ArvPixelFormat>(codes[i])))
      formats.push_back(*format);
  }
  g_free(codes);
  return formats;
}

void AravisCamera::SetExposure(double exposure_us) {
  impl_->CheckConnected();
  GError* error = nullptr;
  if (!arv_camera_is_exposure_time_available(impl_->camera, &error)) {
    impl_->Check(error, "querying ExposureTime");
    throw IoError("camera '" + impl_->Uri() + "': the camera has no ExposureTime feature");
  }
  double lowest = 0.0, highest = 0.0;
  arv_camera_get_exposure_time_bounds(impl_->camera, &lowest, &highest, &error);
  impl_->Check(error, "reading ExposureTime bounds");
  if (!(exposure_us >= lowest && exposure_us <= highest)) {
    throw IoError("camera '" + impl_->Uri() + "': exposure " + std::to_string(exposure_us) +
                  " us outside [" + std::to_string(lowest) + ", " + std::to_string(highest) +
                  "] us");
  }
  if (arv_camera_is_exposure_auto_available(impl_->camera, nullptr)) {
    arv_camera_set_exposure_time_auto(impl_->camera, ARV_AUTO_OFF, &error);
    impl_->Check(error, "switching ExposureAuto off");
  }
  arv_camera_set_exposure_time(impl_->camera, exposure_us, &error);
  impl_->Check(error, "setting ExposureTime");
  impl_->ReadExposureAndGain();  // as the device rounded it
}

void AravisCamera::SetGain(double gain) {
  impl_->CheckConnected();
  GError* error = nullptr;
  if (!arv_camera_is_gain_available(impl_->camera, &error)) {
    impl_->Check(error, "querying Gain");
    throw IoError("camera '" + impl_->Uri() + "': the camera has no Gain feature");
  }
  double lowest = 0.0, highest = 0.0;
  arv_camera_get_gain_bounds(impl_->camera, &lowest, &highest, &error);
  impl_->Check(error, "reading Gain bounds");
  if (!(gain >= lowest && gain <= highest)) {
    throw IoError("camera '" + impl_->Uri() + "': gain " + std::to_string(gain) + " outside [" +
                  std::to_string(lowest) + ", " + std::to_string(highest) + "]");
  }
  if (arv_camera_is_gain_auto_available(impl_->camera, nullptr)) {
    arv_camera_set_gain_auto(impl_->camera, ARV_AUTO_OFF, &error);
    impl_->Check(error, "switching GainAuto off");
  }
  arv_camera_set_gain(impl_->camera, gain, &error);
  impl_->Check(error, "setting Gain");
  impl_->ReadExposureAndGain();
}

void AravisCamera::SetPixelFormat(PixelFormat format) {
  impl_->CheckConnected();
  const bool was_streaming = impl_->stream != nullptr;
  impl_->StopStreaming();
  GError* error = nullptr;
  arv_camera_set_pixel_format_from_string(impl_->camera, GenicamName(format).c_str(), &error);
  impl_->Check(error, "setting PixelFormat " + GenicamName(format));
  impl_->format = format;
  if (was_streaming) Start();
}

void AravisCamera::Start() {
  try {
    impl_->StartStreaming();
  } catch (...) {
    impl_->StopStreaming();
    throw;
  }
}

void AravisCamera::Stop() { impl_->StopStreaming(); }

Frame AravisCamera::Grab(std::chrono::milliseconds timeout) {
  Start();
  GError* error = nullptr;
  if (impl_->software_trigger) {
    arv_camera_software_trigger(impl_->camera, &error);
    impl_->Check(error, "software trigger");
  }
  const double exposure_us = impl_->exposure_us;
  const double gain = impl_->gain;
  const int64_t deadline =
      SteadyNowNs() + std::chrono::duration_cast<std::chrono::nanoseconds>(timeout).count();
  int bad_buffers = 0;
  ArvBufferStatus last_bad = ARV_BUFFER_STATUS_SUCCESS;
  for (;;) {
    impl_->CheckConnected();
    const int64_t left_ns = deadline - SteadyNowNs();
    ArvBuffer* buffer = left_ns > 0 ? arv_stream_timeout_pop_buffer(
                                          impl_->stream, static_cast<guint64>(left_ns / 1000))
                                    : nullptr;
    if (buffer == nullptr) {
      impl_->CheckConnected();
      std::string why;
      if (bad_buffers > 0) {
        why = " (" + std::to_string(bad_buffers) +
              " frames arrived incomplete, last: " + StatusName(last_bad) +
              (impl_->receive_buffer_advice.empty() ? "" : "; " + impl_->receive_buffer_advice) +
              ")";
      }
      throw CameraTimeout("camera '" + impl_->Uri() + "': no frame within " +
                          std::to_string(timeout.count()) + " ms" + why);
    }
    const ArvBufferStatus status = arv_buffer_get_status(buffer);
    if (status != ARV_BUFFER_STATUS_SUCCESS) {
      ++bad_buffers;
      last_bad = status;
      arv_stream_push_buffer(impl_->stream, buffer);
      if (impl_->software_trigger) {  // that frame spent our trigger: ask for another
        arv_camera_software_trigger(impl_->camera, &error);
        impl_->Check(error, "software trigger");
      }
      continue;
    }
    const int64_t arrival_steady = SteadyNowNs();
    Frame frame;
    const auto format = FromArv(arv_buffer_get_image_pixel_format(buffer));
    if (!format) {
      arv_stream_push_buffer(impl_->stream, buffer);
      throw IoError("camera '" + impl_->Uri() + "': frame in an undecodable pixel format");
    }
    try {
      size_t size = 0;
      RawImage raw;
      raw.data = static_cast<const uint8_t*>(arv_buffer_get_image_data(buffer, &size));
      raw.size = size;
      raw.width = arv_buffer_get_image_width(buffer);
      raw.height = arv_buffer_get_image_height(buffer);
      raw.format = *format;
      frame.image = DecodeImage(raw);
    } catch (const IoError& decode_error) {
      arv_stream_push_buffer(impl_->stream, buffer);
      throw IoError("camera '" + impl_->Uri() + "': " + decode_error.what());
    }
    frame.source_format = *format;
    frame.sequence = arv_buffer_get_frame_id(buffer);
    frame.device_timestamp_ns = static_cast<int64_t>(arv_buffer_get_timestamp(buffer));
    const int64_t system_ns = static_cast<int64_t>(arv_buffer_get_system_timestamp(buffer));
    arv_stream_push_buffer(impl_->stream, buffer);
    // The system timestamp (real-time clock) is when the frame began to arrive; map it onto the
    // steady clock. Readout precedes arrival, so the exposure began at least `exposure` earlier.
    frame.arrival_ns = system_ns > 0 ? system_ns - RealtimeMinusSteadyNs() : arrival_steady;
    frame.exposure_us = exposure_us;
    frame.gain = gain;
    const int64_t exposure_ns = static_cast<int64_t>(std::llround(exposure_us * 1e3));
    frame.exposure_start_ns = frame.arrival_ns - exposure_ns;
    if (frame.device_timestamp_ns > 0) {
      // The device's timestamp places the exposure better than arrival, which carries the
      // transfer and the host's delays (milliseconds, varying): map it through the smallest
      // apparent delay so far.
      const int64_t sample = frame.exposure_start_ns - frame.device_timestamp_ns;
      int64_t& offset = impl_->clock_offset_ns;
      if (frame.device_timestamp_ns < impl_->last_device_ns) offset = std::numeric_limits<int64_t>::max();
      impl_->last_device_ns = frame.device_timestamp_ns;
      if (offset != std::numeric_limits<int64_t>::max())
        offset += (frame.arrival_ns - impl_->clock_offset_at_ns) / 10000;  // 100 ppm drift allowance
      if (sample <= offset) {
        offset = sample;
      }
      impl_->clock_offset_at_ns = frame.arrival_ns;
      frame.exposure_start_ns = std::min(frame.exposure_start_ns, frame.device_timestamp_ns + offset);
    }
    return frame;
  }
}

int AravisCamera::DropBufferedFrames() {
  impl_->CheckConnected();
  if (impl_->stream == nullptr) return 0;
  int dropped = 0;
  while (ArvBuffer* buffer = arv_stream_try_pop_buffer(impl_->stream)) {
    arv_stream_push_buffer(impl_->stream, buffer);
    ++dropped;
  }
  return dropped;
}

std::vector<CameraInfo> ListAravisCameras(const ListCamerasOptions& options) {
  std::lock_guard<std::mutex> lock(InterfaceMutex());
  if (options.gige_discovery) {
    arv_enable_interface("GigEVision");
  } else {
    arv_disable_interface("GigEVision");
  }
  if (options.include_virtual) {
    arv_enable_interface("Fake");
  } else {
    arv_disable_interface("Fake");
  }
  arv_update_device_list();
  std::vector<CameraInfo> cameras;
  for (unsigned int i = 0; i < arv_get_n_devices(); ++i) {
    auto text = [](const char* value) { return std::string(value ? value : ""); };
    CameraInfo info;
    info.backend = "aravis";
    info.uri = "aravis:" + text(arv_get_device_id(i));
    info.vendor = text(arv_get_device_vendor(i));
    info.model = text(arv_get_device_model(i));
    info.serial = text(arv_get_device_serial_nbr(i));
    info.description = info.vendor + " " + info.model + " (" + text(arv_get_device_protocol(i)) +
                       (arv_get_device_address(i) ? std::string(", ") + arv_get_device_address(i)
                                                  : std::string()) +
                       ")";
    cameras.push_back(info);
  }
  return cameras;
}

CameraBackend AravisCameraBackend() {
  CameraBackend backend;
  backend.scheme = "aravis";
  backend.description =
      "GenICam cameras (GigE Vision, USB3 Vision) and the Fake camera, through Aravis";
  backend.open = [](const CameraUri& uri, const OpenCameraOptions&) -> std::unique_ptr<Camera> {
    return std::make_unique<AravisCamera>(AravisCameraOptionsFromUri(uri));
  };
  backend.list = ListAravisCameras;
  return backend;
}

}  // namespace procam
