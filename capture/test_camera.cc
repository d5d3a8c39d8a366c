#include "capture/test_camera.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <thread>

#include "base/check.h"

namespace procam {
namespace {

constexpr double kMinExposureUs = 10.0;
constexpr double kMaxExposureUs = 1e7;
constexpr double kMaxGainDb = 24.0;
constexpr double kMaxBlurPx = 20.0;
constexpr double kMaxAmbient = 10.0;

bool Simulatable(PixelFormat format) {
  return format != PixelFormat::kYUYV && format != PixelFormat::kMJPEG;
}

// The chart a test camera without a scene view sees: a horizontal ramp 0..1, with red, green
// and blue bands in the lower third.
cv::Mat DefaultChart(int width, int height) {
  cv::Mat chart(height, width, CV_32FC3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const float ramp = width > 1 ? static_cast<float>(x) / static_cast<float>(width - 1) : 0.0f;
      cv::Vec3f value(ramp, ramp, ramp);
      if (y >= 2 * height / 3) {
        const int band = std::min(2, 3 * x / std::max(1, width));  // R, G, B from left to right
        value = cv::Vec3f(0, 0, 0);
        value[2 - band] = 0.8f;
      }
      chart.at<cv::Vec3f>(y, x) = value;
    }
  }
  return chart;
}

}  // namespace

bool TestCameraOptions::Check(std::string* why) const {
  if (width < 2 || width > 16384 || height < 2 || height > 16384) {
    return Fail(why, "width and height must be in [2, 16384], got " + std::to_string(width) + "x" +
                         std::to_string(height));
  }
  if (!Simulatable(pixel_format))
    return Fail(why, "format " + PixelFormatName(pixel_format) + " cannot be simulated");
  if (IsBayer(pixel_format) && (width % 2 || height % 2))
    return Fail(why, "Bayer formats need an even width and height");
  if (!(frame_rate > 0 && frame_rate <= 10000)) return Fail(why, "fps must be in (0, 10000]");
  if (buffers < 1 || buffers > 64) return Fail(why, "buffers must be in [1, 64]");
  if (!(exposure_us >= kMinExposureUs && exposure_us <= kMaxExposureUs))
    return Fail(why, "exposure_us must be in [10, 1e7]");
  if (!(reference_exposure_us > 0)) return Fail(why, "reference_exposure_us must be > 0");
  if (!(gain_db >= 0 && gain_db <= kMaxGainDb)) return Fail(why, "gain_db must be in [0, 24]");
  const double full_scale = FullScale(pixel_format);
  if (!(black_level >= 0 && black_level < full_scale))
    return Fail(why, "black must be in [0, full scale)");
  if (!(noise_sigma >= 0 && noise_sigma <= full_scale))
    return Fail(why, "noise must be in [0, full scale]");
  if (!(response_gamma > 0 && response_gamma <= 10))
    return Fail(why, "response_gamma must be in (0, 10]");
  if (!(display_latency_ms >= 0 && display_latency_ms <= 10000))
    return Fail(why, "latency_ms must be in [0, 10000]");
  if (!(projector_blur_px >= 0 && projector_blur_px <= kMaxBlurPx))
    return Fail(why, "projector_blur must be in [0, 20] projector pixels");
  if (!(camera_blur_px >= 0 && camera_blur_px <= kMaxBlurPx))
    return Fail(why, "camera_blur must be in [0, 20] camera pixels");
  if (!(ambient >= 0 && ambient <= kMaxAmbient))
    return Fail(why, "ambient must be in [0, 10] (radiance 1 = full scale)");
  if (jpeg_quality < 0 || jpeg_quality > 100)
    return Fail(why, "jpeg_quality must be in [1, 100], or 0 for no JPEG");
  if (jpeg_quality > 0 && pixel_format != PixelFormat::kMono8 &&
      pixel_format != PixelFormat::kRGB8 && pixel_format != PixelFormat::kBGR8) {
    return Fail(why, "jpeg_quality needs an 8-bit Mono8, RGB8 or BGR8 format, not " +
                         PixelFormatName(pixel_format));
  }
  if (fault_after_frames < 0 || fault_grabs < 0)
    return Fail(why, "fault_after and fault_grabs must be >= 0");
  return true;
}

const std::vector<TestCameraSetting>& TestCameraSettings() {
  using O = TestCameraOptions;
  static const std::vector<TestCameraSetting> settings = {
      {"exposure_us", &O::exposure_us, nullptr, "initial exposure, µs, [10, 10⁷] (default 10000)"},
      {"reference_exposure_us", &O::reference_exposure_us, nullptr,
       "the exposure at which radiance 1 reads full scale, µs, > 0 (default 10000)"},
      {"gain_db", &O::gain_db, nullptr, "initial gain, dB, [0, 24] (default 0)"},
      {"black", &O::black_level, nullptr, "black level, digital numbers, [0, full scale) (default 0)"},
      {"noise", &O::noise_sigma, nullptr, "read noise σ, digital numbers, [0, full scale] (default 0)"},
      {"response_gamma", &O::response_gamma, nullptr,
       "non-linear response: value = linear^(1/γ) between black and full scale, before "
       "rounding, (0, 10] (default 1: linear)"},
      {"fps", &O::frame_rate, nullptr, "frame rate, (0, 10000] (default 30)"},
      {"latency_ms", &O::display_latency_ms, nullptr,
       "display-to-camera latency: a frame sees the projectors as they were this long before its "
       "exposure, ms, [0, 10000] (default 0)"},
      {"projector_blur", &O::projector_blur_px, nullptr,
       "projector defocus: Gaussian σ in projector pixels of the light each projector shows, "
       "[0, 20] (default 0)"},
      {"camera_blur", &O::camera_blur_px, nullptr,
       "camera defocus: Gaussian σ in camera pixels of the photographed image, [0, 20] (default 0)"},
      {"ambient", &O::ambient, nullptr,
       "ambient light: a constant radiance added to every pixel, in units of full scale at the "
       "reference exposure (synthetic rooms: the brightest pixel under full white), [0, 10] "
       "(default 0)"},
      {"jpeg_quality", nullptr, &O::jpeg_quality,
       "JPEG compression: every frame is encoded and decoded in memory at this quality, [1, 100]; "
       "0 = off (default); Mono8, RGB8 and BGR8 only"},
  };
  return settings;
}

TestCameraOptions TestCameraOptionsFromUri(const CameraUri& uri) {
  TestCameraOptions options;
  if (!uri.path().empty()) options.name = uri.path();
  return TestCameraOptionsFromUri(uri, options);
}

TestCameraOptions TestCameraOptionsFromUri(const CameraUri& uri, TestCameraOptions defaults) {
  TestCameraOptions& options = defaults;
  const std::string format = uri.GetString("format", PixelFormatName(options.pixel_format));
  const auto parsed = ParsePixelFormat(format);
  if (!parsed) throw IoError("camera '" + uri.text() + "': unknown pixel format '" + format + "'");
  options.pixel_format = *parsed;
  options.width = uri.GetInt("width", options.width);
  options.height = uri.GetInt("height", options.height);
  options.buffers = uri.GetInt("buffers", options.buffers);
  for (const TestCameraSetting& setting : TestCameraSettings()) {
    if (setting.number) {
      options.*setting.number = uri.GetDouble(setting.key, options.*setting.number);
    } else {
      options.*setting.integer = uri.GetInt(setting.key, options.*setting.integer);
    }
  }
  options.seed = static_cast<uint32_t>(uri.GetInt("seed", static_cast<int>(options.seed)));
  const std::string fault = uri.GetString("fault", "none");
  if (fault == "none") {
    options.fault = TestCameraOptions::Fault::kNone;
  } else if (fault == "timeout") {
    options.fault = TestCameraOptions::Fault::kTimeout;
  } else if (fault == "disconnect") {
    options.fault = TestCameraOptions::Fault::kDisconnect;
  } else {
    throw IoError("camera '" + uri.text() + "': fault must be none, timeout or disconnect, got '" +
                  fault + "'");
  }
  options.fault_after_frames = uri.GetInt("fault_after", options.fault_after_frames);
  options.fault_grabs = uri.GetInt("fault_grabs", options.fault_grabs);
  uri.CheckAllRead();
  std::string why;
  if (!options.Check(&why)) throw IoError("camera '" + uri.text() + "': " + why);
  return options;
}

SceneView ProjectorBlurredView(SceneView view, double sigma_px) {
  if (!view || !(sigma_px > 0.0)) return view;
  return [view = std::move(view), sigma_px](int64_t exposure_start_ns) {
    cv::Mat radiance = view(exposure_start_ns);
    if (radiance.empty()) return radiance;
    if (radiance.depth() != CV_32F) radiance.convertTo(radiance, CV_32F);
    cv::Mat blurred;
    cv::GaussianBlur(radiance, blurred, cv::Size(0, 0), sigma_px, sigma_px, cv::BORDER_REFLECT);
    return blurred;
  };
}

TestCamera::TestCamera(const TestCameraOptions& options, SceneView view)
    : TestCamera(options, ProjectorBlurredView(std::move(view), options.projector_blur_px),
                 ViewHasProjectorBlur{}) {}

TestCamera::TestCamera(const TestCameraOptions& options, SceneView view, ViewHasProjectorBlur)
    : options_(options), view_(std::move(view)), rng_(options.seed) {
  std::string why;
  if (!options_.Check(&why)) throw std::invalid_argument("TestCameraOptions: " + why);
}

// Errors name the camera as Info() does, so a camera built on this one (the synthetic rig's)
// is named by its own URI.
std::string TestCamera::Uri() const { return Info().uri; }

CameraInfo TestCamera::Info() const {
  CameraInfo info;
  info.uri = "test:" + options_.name;
  info.backend = "test";
  info.vendor = "procam";
  info.model = "test camera";
  info.serial = options_.name;
  info.description = "software test camera, " + std::to_string(options_.width) + "x" +
                     std::to_string(options_.height) + " " + PixelFormatName(options_.pixel_format);
  return info;
}

CameraSettings TestCamera::Settings() const {
  CameraSettings settings;
  settings.width = options_.width;
  settings.height = options_.height;
  settings.pixel_format = options_.pixel_format;
  settings.exposure_us = options_.exposure_us;
  settings.gain = options_.gain_db;
  settings.gain_unit = "dB";
  settings.trigger = "free-running";
  settings.exposure_range_us = {true, kMinExposureUs, kMaxExposureUs, 1.0};
  settings.gain_range = {true, 0.0, kMaxGainDb, 0.0};
  return settings;
}

std::vector<PixelFormat> TestCamera::SupportedPixelFormats() const {
  std::vector<PixelFormat> formats;
  for (PixelFormat format : AllPixelFormats()) {
    if (Simulatable(format)) formats.push_back(format);
  }
  return formats;
}

int64_t TestCamera::ExposureNs() const {
  return static_cast<int64_t>(std::llround(options_.exposure_us * 1e3));
}

int64_t TestCamera::PeriodNs() const {
  return std::max(ExposureNs(), static_cast<int64_t>(std::llround(1e9 / options_.frame_rate)));
}

void TestCamera::RestartTimeline() {
  timeline_start_ns_ = SteadyNowNs();
  next_in_timeline_ = 0;
}

void TestCamera::Advance(int64_t now_ns) {
  if (!streaming_) return;
  const int64_t period = PeriodNs();
  const int64_t exposure = ExposureNs();
  if (now_ns < timeline_start_ns_ + exposure) return;
  const int64_t finished =
      (now_ns - timeline_start_ns_ - exposure) / period + 1;  // frames done by now
  while (next_in_timeline_ < finished && static_cast<int>(buffered_.size()) < options_.buffers) {
    buffered_.push_back({next_sequence_++, timeline_start_ns_ + next_in_timeline_ * period,
                         options_.exposure_us, options_.gain_db});
    ++next_in_timeline_;
  }
  if (next_in_timeline_ < finished) {  // buffers full: the rest is lost
    frames_overrun_ += static_cast<int>(finished - next_in_timeline_);
    next_sequence_ += static_cast<uint64_t>(finished - next_in_timeline_);
    next_in_timeline_ = finished;
  }
}

void TestCamera::SetExposure(double exposure_us) {
  if (!(exposure_us >= kMinExposureUs && exposure_us <= kMaxExposureUs)) {
    throw IoError("camera '" + Uri() + "': exposure " + std::to_string(exposure_us) +
                  " us outside [10, 1e7]");
  }
  Advance(SteadyNowNs());
  options_.exposure_us = std::round(exposure_us);
  RestartTimeline();
}

void TestCamera::SetGain(double gain_db) {
  if (!(gain_db >= 0 && gain_db <= kMaxGainDb)) {
    throw IoError("camera '" + Uri() + "': gain " + std::to_string(gain_db) +
                  " dB outside [0, 24]");
  }
  Advance(SteadyNowNs());
  options_.gain_db = gain_db;
  RestartTimeline();
}

void TestCamera::SetPixelFormat(PixelFormat format) {
  TestCameraOptions changed = options_;
  changed.pixel_format = format;
  std::string why;
  if (!changed.Check(&why)) throw IoError("camera '" + Uri() + "': " + why);
  const bool was_streaming = streaming_;
  Stop();
  options_ = changed;
  if (was_streaming) Start();
}

void TestCamera::Start() {
  if (disconnected_)
    throw CameraDisconnected("camera '" + Uri() + "': device disappeared (injected fault)");
  if (streaming_) return;
  streaming_ = true;
  RestartTimeline();
}

void TestCamera::Stop() {
  streaming_ = false;
  buffered_.clear();
}

void TestCamera::CheckFaults(std::chrono::milliseconds timeout) {
  if (disconnected_)
    throw CameraDisconnected("camera '" + Uri() + "': device disappeared (injected fault)");
  if (options_.fault == TestCameraOptions::Fault::kNone ||
      frames_delivered_ < options_.fault_after_frames)
    return;
  if (options_.fault == TestCameraOptions::Fault::kDisconnect) {
    disconnected_ = true;
    streaming_ = false;
    buffered_.clear();
    throw CameraDisconnected("camera '" + Uri() + "': device disappeared after " +
                             std::to_string(frames_delivered_) + " frames (injected fault)");
  }
  if (options_.fault_grabs == 0 || failed_grabs_ < options_.fault_grabs) {
    ++failed_grabs_;
    std::this_thread::sleep_for(timeout);
    throw CameraTimeout("camera '" + Uri() + "': no frame within " +
                        std::to_string(timeout.count()) + " ms (injected fault)");
  }
}

Frame TestCamera::Grab(std::chrono::milliseconds timeout) {
  CheckFaults(timeout);
  Start();
  const int64_t deadline =
      SteadyNowNs() + std::chrono::duration_cast<std::chrono::nanoseconds>(timeout).count();
  Advance(SteadyNowNs());
  while (buffered_.empty()) {
    const int64_t next_done = timeline_start_ns_ + next_in_timeline_ * PeriodNs() + ExposureNs();
    if (next_done > deadline) {
      std::this_thread::sleep_for(
          std::chrono::nanoseconds(std::max<int64_t>(0, deadline - SteadyNowNs())));
      throw CameraTimeout("camera '" + Uri() + "': no frame within " +
                          std::to_string(timeout.count()) + " ms");
    }
    std::this_thread::sleep_for(
        std::chrono::nanoseconds(std::max<int64_t>(0, next_done - SteadyNowNs())));
    Advance(SteadyNowNs());
  }
  const PendingFrame pending = buffered_.front();
  buffered_.pop_front();
  ++frames_delivered_;
  return Render(pending);
}

int TestCamera::DropBufferedFrames() {
  if (disconnected_)
    throw CameraDisconnected("camera '" + Uri() + "': device disappeared (injected fault)");
  Advance(SteadyNowNs());
  const int dropped = static_cast<int>(buffered_.size());
  buffered_.clear();
  return dropped;
}

cv::Mat PhotographRadiance(cv::Mat radiance, const TestCameraOptions& model,
                           const PhotographSettings& settings, cv::RNG& rng) {
  const int width = settings.width;
  const int height = settings.height;
  const PixelFormat format = settings.pixel_format;
  if (radiance.empty()) radiance = cv::Mat::zeros(height, width, CV_32FC1);
  if (radiance.depth() != CV_32F) radiance.convertTo(radiance, CV_32F);
  if (radiance.cols != width || radiance.rows != height) {
    cv::Mat resized(height, width, radiance.type());
    for (int y = 0; y < height; ++y) {
      const int source_y = static_cast<int>(static_cast<int64_t>(y) * radiance.rows / height);
      for (int x = 0; x < width; ++x) {
        const int source_x = static_cast<int>(static_cast<int64_t>(x) * radiance.cols / width);
        std::memcpy(resized.ptr(y, x), radiance.ptr(source_y, source_x), radiance.elemSize());
      }
    }
    radiance = resized;
  }
  if (model.ambient > 0.0) {  // into a new matrix: `radiance` may share the caller's pixels
    cv::Mat lit;
    cv::add(radiance, cv::Scalar::all(model.ambient), lit);
    radiance = lit;
  }
  if (model.camera_blur_px > 0.0) {
    cv::Mat blurred;
    cv::GaussianBlur(radiance, blurred, cv::Size(0, 0), model.camera_blur_px, model.camera_blur_px,
                     cv::BORDER_REFLECT);
    radiance = blurred;
  }
  const bool colour = IsColour(format);
  if (colour && radiance.channels() == 1) {
    cv::cvtColor(radiance, radiance, cv::COLOR_GRAY2BGR);
  } else if (!colour && radiance.channels() == 3) {
    cv::Mat luma;
    cv::transform(radiance, luma, cv::Matx13f(0.0722f, 0.7152f, 0.2126f));  // B, G, R weights
    radiance = luma;
  }
  const double full_scale = FullScale(format);
  const double scale = full_scale * (settings.exposure_us / model.reference_exposure_us) *
                       std::pow(10.0, settings.gain_db / 20.0);
  cv::Mat digital;
  radiance.convertTo(digital, CV_32F, scale, model.black_level);
  if (model.noise_sigma > 0) {
    cv::Mat noise(digital.size(), digital.type());
    rng.fill(noise, cv::RNG::NORMAL, 0.0, model.noise_sigma);
    digital += noise;
  }
  if (model.response_gamma != 1.0) {  // the output curve of a camera that is not linear
    const double range = full_scale - model.black_level;
    const double exponent = 1.0 / model.response_gamma;
    digital.reshape(1).forEach<float>([&](float& value, const int*) {
      const double u = std::clamp((value - model.black_level) / range, 0.0, 1.0);
      value = static_cast<float>(model.black_level + range * std::pow(u, exponent));
    });
  }
  cv::Mat image;  // convertTo rounds and saturates to [0, full scale]
  digital.convertTo(image, format == PixelFormat::kMono16 ? CV_16U : CV_8U);
  if (model.jpeg_quality > 0) {  // Check() allows it for 8-bit Mono8, RGB8 and BGR8 only
    std::vector<uchar> jpeg;
    cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, model.jpeg_quality});
    image = cv::imdecode(jpeg, image.channels() == 1 ? cv::IMREAD_GRAYSCALE : cv::IMREAD_COLOR);
  }
  return image;
}

Frame TestCamera::Render(const PendingFrame& pending) {
  const int64_t latency_ns = static_cast<int64_t>(std::llround(options_.display_latency_ms * 1e6));
  const cv::Mat radiance = view_ ? view_(pending.exposure_start_ns - latency_ns)
                                 : DefaultChart(options_.width, options_.height);
  PhotographSettings settings;
  settings.width = options_.width;
  settings.height = options_.height;
  settings.pixel_format = options_.pixel_format;
  settings.exposure_us = pending.exposure_us;
  settings.gain_db = pending.gain_db;
  const cv::Mat image = PhotographRadiance(radiance, options_, settings, rng_);

  const std::vector<uint8_t> raw = EncodeRaw(image, options_.pixel_format);
  RawImage raw_image;
  raw_image.data = raw.data();
  raw_image.size = raw.size();
  raw_image.width = options_.width;
  raw_image.height = options_.height;
  raw_image.format = options_.pixel_format;

  Frame frame;
  frame.image = DecodeImage(raw_image);
  frame.source_format = options_.pixel_format;
  frame.sequence = pending.sequence;
  frame.exposure_start_ns = pending.exposure_start_ns;
  frame.arrival_ns =
      pending.exposure_start_ns + static_cast<int64_t>(std::llround(pending.exposure_us * 1e3));
  frame.device_timestamp_ns = frame.exposure_start_ns;
  frame.exposure_us = pending.exposure_us;
  frame.gain = pending.gain_db;
  return frame;
}

CameraBackend TestCameraBackend() {
  CameraBackend backend;
  backend.scheme = "test";
  backend.description =
      "software test camera (noise, buffering and fault injection; sees the memory display)";
  backend.open = [](const CameraUri& uri,
                    const OpenCameraOptions& options) -> std::unique_ptr<Camera> {
    return std::make_unique<TestCamera>(TestCameraOptionsFromUri(uri), options.scene_view);
  };
  backend.list = [](const ListCamerasOptions& options) {
    std::vector<CameraInfo> cameras;
    if (options.include_virtual)
      cameras.push_back(TestCamera(TestCameraOptions(), SceneView()).Info());
    return cameras;
  };
  return backend;
}

}  // namespace procam
