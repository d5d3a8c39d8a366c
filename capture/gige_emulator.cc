#include "capture/gige_emulator.h"

#include <arpa/inet.h>
#include <arv.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <mutex>
#include <stdexcept>

#include "base/check.h"
#include "base/io.h"
#include "capture/aravis_camera.h"
#include "capture/camera.h"

namespace procam {
namespace {

constexpr int kGvcpPort = 3956;  // GigE Vision's control port (fixed by the standard)
// How often a waiting software trigger is looked at: the fake camera polls its trigger register
// at this rate, so a triggered exposure starts at most 1 ms after the trigger arrives.
constexpr double kTriggerPollHz = 1000.0;

bool FrameRateInRange(double frame_rate) { return frame_rate >= 0.1 && frame_rate <= 1000.0; }
bool LatencyInRange(double latency_ms) { return latency_ms >= 0.0 && latency_ms <= 10000.0; }

// Binds (and releases) the GVCP port of `address`, so that a taken port or an address no
// interface has is reported before Aravis, which only logs it, tries. Empty when it is free.
std::string ProbeGvcpPort(const std::string& address) {
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);  // a program started meanwhile must not hold the port
  if (fd < 0) return std::string("cannot create a UDP socket: ") + std::strerror(errno);
  sockaddr_in where{};
  where.sin_family = AF_INET;
  where.sin_port = htons(kGvcpPort);
  inet_pton(AF_INET, address.c_str(), &where.sin_addr);
  std::string problem;
  if (bind(fd, reinterpret_cast<const sockaddr*>(&where), sizeof(where)) != 0) {
    problem = errno == EADDRINUSE ? "UDP port 3956 is taken (another GigE Vision camera?)"
              : errno == EADDRNOTAVAIL
                  ? "no local network interface has this address"
                  : std::string("cannot bind UDP port 3956: ") + std::strerror(errno);
  }
  close(fd);
  return problem;
}

}  // namespace

GigeFrameSource PhotographScene(SceneView view, const TestCameraOptions& model) {
  auto rng = std::make_shared<cv::RNG>(model.seed);
  return [view = std::move(view), model, rng](const GigeFrameRequest& request) {
    PhotographSettings settings;
    settings.width = request.width;
    settings.height = request.height;
    settings.pixel_format = request.pixel_format;
    settings.exposure_us = request.exposure_us;
    settings.gain_db = request.gain_db;
    return PhotographRadiance(view ? view(request.scene_time_ns) : cv::Mat(), model, settings,
                              *rng);
  };
}

bool GigeEmulatorOptions::Check(std::string* why) const {
  if (!IsIpv4Address(address)) return Fail(why, "address must be an IPv4 address, got '" + address + "'");
  if (serial.empty() || serial.size() > 15)
    return Fail(why, "serial must have 1 to 15 characters, got '" + serial + "'");
  if (width < 1 || width > 2048 || height < 1 || height > 2048)
    return Fail(why, "width and height must be in [1, 2048]");
  const auto formats = GigeEmulator::SupportedPixelFormats();
  if (std::find(formats.begin(), formats.end(), pixel_format) == formats.end())
    return Fail(why, "pixel format " + PixelFormatName(pixel_format) + " is not offered");
  if (IsBayer(pixel_format) && (width % 2 || height % 2))
    return Fail(why, "Bayer formats need an even width and height");
  if (!FrameRateInRange(frame_rate)) return Fail(why, "frame_rate must be in [0.1, 1000]");
  if (!LatencyInRange(latency_ms)) return Fail(why, "latency_ms must be in [0, 10000]");
  if (!(exposure_us >= 10 && exposure_us <= 1e7))
    return Fail(why, "exposure_us must be in [10, 1e7]");
  if (!(gain_db >= 0 && gain_db <= 10 && gain_db == std::floor(gain_db)))
    return Fail(why, "gain_db must be an integer in [0, 10]");
  if (!(packet_loss >= 0 && packet_loss < 1)) return Fail(why, "packet_loss must be in [0, 1)");
  return true;
}

struct GigeEmulator::Impl {
  GigeEmulatorOptions options;
  GigeFrameSource source;
  ArvGvFakeCamera* gv_camera = nullptr;
  ArvFakeCamera* camera = nullptr;  // owned by gv_camera
  std::atomic<int64_t> latency_ns{0};
  std::atomic<int64_t> frames_served{0};
  std::atomic<int64_t> frames_failed{0};
  mutable std::mutex mutex;  // guards last_error and stopping (with `wake`)
  std::string last_error;
  bool stopping = false;
  std::condition_variable wake;

  std::string Where() const { return "GigE Vision emulator at " + options.address; }

  static void FillCallback(ArvBuffer* buffer, void* self, guint32 exposure_us, guint32 gain_raw,
                           ArvPixelFormat code) {
    static_cast<Impl*>(self)->Fill(buffer, exposure_us, gain_raw, code);
  }

  // Called by the fake camera's thread when an exposure starts (free-running period or
  // software trigger); the frame is sent when this returns.
  void Fill(ArvBuffer* buffer, guint32 exposure_us, guint32 gain_raw, ArvPixelFormat code) {
    // The fake camera stamped the buffer with the real-time clock just before calling: a
    // triggered exposure starts then. A free-running one starts on the multiple of the frame
    // period the camera's thread woke up for (it wakes a little late on a busy host; a camera's
    // sensor timing would not), which also becomes the frame's device timestamp. Map it onto the
    // steady clock.
    int64_t stamp_real_ns = static_cast<int64_t>(arv_buffer_get_timestamp(buffer));
    guint32 period_us = 0;
    if (arv_fake_camera_is_in_free_running_mode(camera) &&
        arv_fake_camera_read_register(camera, ARV_FAKE_CAMERA_REGISTER_ACQUISITION_FRAME_PERIOD_US,
                                      &period_us) &&
        period_us > 0) {
      const int64_t period_ns = int64_t{period_us} * 1000;
      stamp_real_ns -= stamp_real_ns % period_ns;
      arv_buffer_set_timestamp(buffer, static_cast<guint64>(stamp_real_ns));
    }
    const int64_t steady_now = SteadyNowNs();
    const int64_t real_now = g_get_real_time() * 1000;
    GigeFrameRequest request;
    request.frame_id = arv_buffer_get_frame_id(buffer);
    request.width = static_cast<int>(arv_buffer_get_image_width(buffer));
    request.height = static_cast<int>(arv_buffer_get_image_height(buffer));
    request.exposure_us = exposure_us;
    request.gain_db = gain_raw;
    request.exposure_start_ns = steady_now - (real_now - stamp_real_ns);
    request.exposure_end_ns = request.exposure_start_ns + int64_t{exposure_us} * 1000;
    request.scene_time_ns = request.exposure_start_ns - latency_ns.load();

    uint8_t* data = static_cast<uint8_t*>(const_cast<void*>(arv_buffer_get_data(buffer, nullptr)));
    const auto format = PixelFormatFromPfnc(code);
    const size_t payload = static_cast<size_t>(request.width) * request.height *
                           (ARV_PIXEL_FORMAT_BIT_PER_PIXEL(code) / 8);
    std::string error;
    if (!format) {
      error = "pixel format code " + std::to_string(code) + " is not supported";
    } else {
      request.pixel_format = *format;
      try {
        const cv::Mat image = source(request);
        if (image.cols != request.width || image.rows != request.height) {
          throw std::invalid_argument("the source returned " + std::to_string(image.cols) + "x" +
                                      std::to_string(image.rows) + " for a " +
                                      std::to_string(request.width) + "x" +
                                      std::to_string(request.height) + " frame");
        }
        const std::vector<uint8_t> raw = EncodeRaw(image, *format);
        if (raw.size() != payload) throw std::logic_error("encoded size differs from payload");
        std::memcpy(data, raw.data(), payload);
      } catch (const std::exception& failure) {
        error = failure.what();
      } catch (...) {
        error = "the source threw a non-standard exception";
      }
    }
    std::unique_lock<std::mutex> lock(mutex);
    if (!error.empty()) {
      std::memset(data, 0, payload);
      last_error = "frame " + std::to_string(request.frame_id) + ": " + error;
      ++frames_failed;
    }
    ++frames_served;
    // Send when the exposure ends (or at once when stopping).
    const auto end =
        std::chrono::steady_clock::time_point(std::chrono::nanoseconds(request.exposure_end_ns));
    wake.wait_until(lock, end, [this] { return stopping; });
  }
};

GigeEmulator::GigeEmulator(const GigeEmulatorOptions& options, GigeFrameSource source)
    : impl_(std::make_unique<Impl>()) {
  impl_->options = options;
  std::string why;
  if (!options.Check(&why)) throw IoError(impl_->Where() + ": " + why);
  if (!source) throw IoError(impl_->Where() + ": no frame source");
  const std::string port_problem = ProbeGvcpPort(options.address);
  if (!port_problem.empty()) throw IoError(impl_->Where() + ": " + port_problem);
  impl_->source = std::move(source);
  impl_->latency_ns = std::llround(options.latency_ms * 1e6);

  impl_->gv_camera =
      arv_gv_fake_camera_new_full(options.address.c_str(), options.serial.c_str(), nullptr);
  if (impl_->gv_camera == nullptr || !arv_gv_fake_camera_is_running(impl_->gv_camera)) {
    if (impl_->gv_camera) g_object_unref(impl_->gv_camera);
    throw IoError(impl_->Where() + ": Aravis's GigE Vision fake camera did not start");
  }
  g_object_set(impl_->gv_camera, "gvsp-lost-ratio", options.packet_loss, nullptr);
  ArvFakeCamera* camera = arv_gv_fake_camera_get_fake_camera(impl_->gv_camera);
  impl_->camera = camera;
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_WIDTH, options.width);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_HEIGHT, options.height);
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_PIXEL_FORMAT,
                                 *PfncFromPixelFormat(options.pixel_format));
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_EXPOSURE_TIME_US,
                                 static_cast<guint32>(std::llround(options.exposure_us)));
  arv_fake_camera_write_register(camera, ARV_FAKE_CAMERA_REGISTER_GAIN_RAW,
                                 static_cast<guint32>(options.gain_db));
  arv_fake_camera_set_trigger_frequency(camera, kTriggerPollHz);
  SetFrameRate(options.frame_rate);
  arv_fake_camera_set_fill_pattern(camera, &Impl::FillCallback, impl_.get());
}

GigeEmulator::~GigeEmulator() {
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->stopping = true;
  }
  impl_->wake.notify_all();
  g_object_unref(impl_->gv_camera);  // joins the camera's thread, closes its sockets
}

std::string GigeEmulator::Uri() const { return "aravis:gv:" + impl_->options.address; }

const GigeEmulatorOptions& GigeEmulator::options() const { return impl_->options; }

void GigeEmulator::SetFrameRate(double frame_rate) {
  if (!FrameRateInRange(frame_rate))
    throw std::invalid_argument(impl_->Where() + ": frame_rate must be in [0.1, 1000]");
  arv_fake_camera_write_register(impl_->camera,
                                 ARV_FAKE_CAMERA_REGISTER_ACQUISITION_FRAME_PERIOD_US,
                                 static_cast<guint32>(std::llround(1e6 / frame_rate)));
}

void GigeEmulator::SetLatencyMs(double latency_ms) {
  if (!LatencyInRange(latency_ms))
    throw std::invalid_argument(impl_->Where() + ": latency_ms must be in [0, 10000]");
  impl_->latency_ns = std::llround(latency_ms * 1e6);
}

int64_t GigeEmulator::frames_served() const { return impl_->frames_served; }
int64_t GigeEmulator::frames_failed() const { return impl_->frames_failed; }

std::string GigeEmulator::last_error() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->last_error;
}

std::vector<PixelFormat> GigeEmulator::SupportedPixelFormats() {
  return {PixelFormat::kMono8,    PixelFormat::kMono16,   PixelFormat::kRGB8,
          PixelFormat::kBayerRG8, PixelFormat::kBayerBG8, PixelFormat::kBayerGR8,
          PixelFormat::kBayerGB8};
}

}  // namespace procam
