#include "nodes/play.h"

#include <fmt/format.h>
#include <poll.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <exception>
#include <limits>
#include <mutex>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <random>
#include <thread>

#include "base/image_io.h"
#include "base/io.h"
#include "base/stop.h"
#include "base/timing.h"
#include "capture/camera.h"
#include "compensation/problem.h"
#include "compensation/stage.h"
#include "geometry/patches.h"
#include "geometry/srgb.h"
#include "geometry/stage.h"
#include "nodes/osc_server.h"
#include "nodes/playlist.h"
#include "projection/calibrated_room.h"
#include "projection/camera_rays.h"
#include "projection/projection_rig.h"
#include "projection/rig_directory.h"
#include "projection/stage.h"

namespace procam {
namespace {

// The desired appearance's frames: the images of a directory in name order, or a video's frames.
class FrameSource {
 public:
  explicit FrameSource(const std::filesystem::path& path) : path_(path) {
    if (std::filesystem::is_directory(path)) {
      for (const auto& entry : std::filesystem::directory_iterator(path)) {
        std::string extension = entry.path().extension().string();
        std::transform(extension.begin(), extension.end(), extension.begin(), ::tolower);
        if (extension == ".png" || extension == ".jpg" || extension == ".jpeg" ||
            extension == ".tif" || extension == ".tiff" || extension == ".ppm" ||
            extension == ".pnm" || extension == ".bmp") {
          // A FIFO or device named like an image would block or never end: refused now.
          CheckRegularFile(entry.path(), kMaxImageBytes);
          files_.push_back(entry.path());
        }
      }
      std::sort(files_.begin(), files_.end());
      if (files_.empty())
        throw IoError(path.string() + ": no images (.png, .jpg, .tif, .ppm) in the directory");
      count_ = static_cast<int>(files_.size());
      return;
    }
    if (!std::filesystem::exists(path))
      throw IoError(path.string() + ": no such file or directory");
    // GStreamer, FFmpeg and OpenCV print lines of their own for a file they cannot read: the
    // failure is this line of procam's instead.
    bool opened = false, read = false;
    {
      SilencedStderr silenced;
      opened = video_.open(path.string(), cv::CAP_ANY) && video_.isOpened();
      read = opened && video_.read(first_) && !first_.empty();
    }
    if (!opened) {
      throw IoError(path.string() + ": not a video OpenCV can read (nor a directory of images)");
    }
    count_ = static_cast<int>(video_.get(cv::CAP_PROP_FRAME_COUNT));  // may be an estimate
    // A video without a frame would show nothing and replace the last result: refused now.
    if (!read) throw IoError(path.string() + ": the video has no frame that can be read");
    next_ = 1;
  }
  // Frames in the source (a video's may be an estimate; 0 if unknown).
  int count() const { return count_; }
  // Frame `index`: an image of the directory, or a video's frame (skipped frames decoded and
  // dropped; an index before the last one read opens the video again: a seek back). Empty past
  // the end of the source.
  cv::Mat Read(int index) {
    if (!files_.empty()) {
      if (index >= static_cast<int>(files_.size())) return cv::Mat();
      // ReadImage: the header's size checked before decoding, the decoders' lines silenced.
      return ReadImage(files_[index], cv::IMREAD_COLOR | cv::IMREAD_ANYDEPTH);
    }
    cv::Mat frame;
    if (!first_.empty()) {  // read by the constructor
      frame = first_;
      first_.release();
      if (index == 0) return frame;
    }
    if (index < next_ - 1 || (index == next_ - 1 && frame.empty())) {
      SilencedStderr silenced;
      video_.release();
      if (!video_.open(path_.string(), cv::CAP_ANY) || !video_.isOpened()) return cv::Mat();
      next_ = 0;
    }
    while (next_ <= index) {
      SilencedStderr silenced;  // a damaged frame's decoder lines: it ends the source
      if (!video_.read(frame) || frame.empty()) return cv::Mat();
      ++next_;
    }
    return frame;
  }

 private:
  std::filesystem::path path_;
  std::vector<std::filesystem::path> files_;
  cv::VideoCapture video_;
  cv::Mat first_;  // a video's first frame, read by the constructor until Read() takes it
  int count_ = 0, next_ = 0;
};

// A live source's newest frame: its producer (a thread of its own, at the source's rate) puts
// each frame it completes; the show takes the newest at each of its frames. A frame put before
// the show took the one before replaces it (counted), never queues.
class LiveFrames {
 public:
  virtual ~LiveFrames() = default;
  // The newest frame not yet taken (BGR, OpenCV's order) and its number (frames received before
  // it); empty if none arrived since the last call.
  cv::Mat Take(int* index) {
    std::lock_guard<std::mutex> lock(mutex_);
    cv::Mat frame;
    std::swap(frame, waiting_);
    *index = received_ - 1;
    return frame;
  }
  // Waits up to `seconds` for a frame to wait; false at once when the input ended without one.
  bool Wait(double seconds) {
    std::unique_lock<std::mutex> lock(mutex_);
    arrived_.wait_for(lock, std::chrono::duration<double>(seconds),
                      [this] { return !waiting_.empty() || ended_; });
    return !waiting_.empty();
  }
  // The input has ended (end of file, a device gone) and no frame waits.
  bool Ended() {
    std::lock_guard<std::mutex> lock(mutex_);
    return ended_ && waiting_.empty();
  }
  int received() {
    std::lock_guard<std::mutex> lock(mutex_);
    return received_;
  }
  int replaced() {
    std::lock_guard<std::mutex> lock(mutex_);
    return replaced_;
  }
  std::string error() {
    std::lock_guard<std::mutex> lock(mutex_);
    return error_;
  }

 protected:
  void Put(cv::Mat bgr) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!waiting_.empty()) ++replaced_;
    waiting_ = std::move(bgr);
    ++received_;
    arrived_.notify_all();
  }
  void Finish(const std::string& error) {
    std::lock_guard<std::mutex> lock(mutex_);
    ended_ = true;
    error_ = error;
    arrived_.notify_all();
  }
  std::atomic<bool> stop_{false};

 private:
  std::mutex mutex_;
  std::condition_variable arrived_;
  cv::Mat waiting_;
  int received_ = 0, replaced_ = 0;
  bool ended_ = false;
  std::string error_;
};

// Raw frames on standard input (--desired stdin:WIDTHxHEIGHT): rgb24, WIDTH × HEIGHT × 3 bytes
// each, one after another, as `ffmpeg -f rawvideo -pix_fmt rgb24 -` writes them.
class StdinFrames : public LiveFrames {
 public:
  StdinFrames(int width, int height, int fd = 0)
      : width_(width), height_(height), fd_(fd), thread_([this] { Read(); }) {}
  ~StdinFrames() override {
    stop_ = true;
    thread_.join();
  }

 private:
  void Read() {
    const size_t bytes = static_cast<size_t>(width_) * height_ * 3;
    cv::Mat rgb(height_, width_, CV_8UC3);
    size_t filled = 0;
    while (!stop_) {
      // Polled, so that the show's end is not held up by a producer that went quiet.
      pollfd poll_fd{fd_, POLLIN, 0};
      const int ready = ::poll(&poll_fd, 1, 100);
      if (ready == 0 || (ready < 0 && errno == EINTR)) continue;
      const ssize_t got = ready < 0 ? -1 : ::read(fd_, rgb.data + filled, bytes - filled);
      if (got < 0 && (errno == EINTR || errno == EAGAIN)) continue;
      if (got < 0) return Finish(std::string("standard input: ") + std::strerror(errno));
      if (got == 0) {
        return Finish(filled == 0 ? ""
                                  : fmt::format("standard input: ended {} bytes into frame {} "
                                                "({} bytes a frame)",
                                                filled, received(), bytes));
      }
      filled += static_cast<size_t>(got);
      if (filled < bytes) continue;
      filled = 0;
      cv::Mat bgr;
      cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
      Put(std::move(bgr));
    }
  }

  const int width_, height_, fd_;
  std::thread thread_;  // last: started once the members it uses are made
};

// A capture device as a live source (--desired camera:URI): capture/'s cameras by URI
// (v4l2:/dev/video2, aravis:..., test:...), each frame grabbed as it comes.
class CameraFrames : public LiveFrames {
 public:
  explicit CameraFrames(const std::string& uri)
      : uri_(uri), camera_(OpenCamera(uri)), thread_([this] { Grab(); }) {}
  ~CameraFrames() override {
    stop_ = true;
    thread_.join();
  }

 private:
  void Grab() {
    try {
      camera_->Start();
      while (!stop_) {
        Frame frame;
        try {
          frame = camera_->Grab(std::chrono::milliseconds(200));
        } catch (const CameraTimeout&) {
          continue;  // a quiet device: the last frame holds
        }
        cv::Mat bgr;
        if (frame.image.channels() == 1) {
          cv::cvtColor(frame.image, bgr, cv::COLOR_GRAY2BGR);
        } else {
          bgr = frame.image;
        }
        Put(std::move(bgr));
      }
      camera_->Stop();
      Finish("");
    } catch (const std::exception& error) {
      Finish(uri_ + ": " + error.what());
    }
  }

  std::string uri_;
  std::unique_ptr<Camera> camera_;
  std::thread thread_;  // last
};

// "stdin:WIDTHxHEIGHT" → the size; false if `desired` does not start with "stdin:". Throws
// std::invalid_argument naming --desired for a size that is not one.
bool ParseStdinSource(const std::string& desired, int* width, int* height) {
  if (!desired.starts_with("stdin:")) return false;
  const std::string size = desired.substr(6);
  const size_t x = size.find('x');
  auto number = [](const std::string& text, int* value) {
    if (text.empty() || text.size() > 5 ||
        text.find_first_not_of("0123456789") != std::string::npos)
      return false;
    *value = std::stoi(text);
    return *value >= 1 && *value <= 16384;
  };
  if (x == std::string::npos || !number(size.substr(0, x), width) ||
      !number(size.substr(x + 1), height))
    throw std::invalid_argument("--desired: " + desired +
                                ": raw frames on standard input are stdin:WIDTHxHEIGHT (rgb24, "
                                "each side in [1, 16384]), e.g. stdin:640x360");
  return true;
}

std::string RandomId() {
  std::random_device device;
  return fmt::format("{:08x}{:08x}", device(), device());
}

nlohmann::json FrameJson(const PlayFrame& frame, const std::vector<NodeAddress>& nodes) {
  nlohmann::json json = {{"frame", frame.shown.frame},
                         {"source", frame.source},
                         {"read_ms", frame.read_ms},
                         {"desired_ms", frame.desired_ms},
                         {"solve_ms", frame.solve_ms},
                         {"iterations", frame.iterations},
                         {"ready_ms", frame.shown.ready_ms},
                         {"present_ms", frame.shown.present_ms},
                         {"skew_ms", frame.shown.skew_ms},
                         {"total_ms", frame.total_ms},
                         {"nodes_shown", frame.shown.shown},
                         {"paused", frame.paused},
                         {"fade", frame.fade},
                         {"emittance_mean", frame.emittance_mean},
                         {"desired_mean", frame.desired_mean}};
  for (const auto& [command, received] : frame.commands)
    json["osc"].push_back({{"command", command}, {"received_frame", received}});
  for (const PlaySurface& surface : frame.surfaces)
    json["surfaces"][surface.surface] = {{"content", surface.content},
                                         {"frame", surface.frame},
                                         {"desired_mean", surface.desired_mean}};
  for (size_t k = 0; k < frame.shown.nodes.size(); ++k) {
    const NodeFrame& node = frame.shown.nodes[k];
    json["nodes"][nodes[k].name] = {{"state", node.state},
                                    {"ready_ms", node.ready_ms},
                                    {"render_ms", node.render_ms},
                                    {"presented_ns", node.presented_ns}};
  }
  return json;
}

// Everything the frames share: the room (the problem with the rig's bounds and reflectance, the
// camera's view of the patches), the solution shown when playing one, the nodes' setup.
struct PlayScene {
  CalibratedRoom room;
  Eigen::MatrixX3d solution;  // shown as every frame, when playing a solution
  nlohmann::json setup;
};

// kSetup's body: a fresh id, the subdivision and the render options.
nlohmann::json SetupJson(const PlayOptions& options, const PlayScene& play) {
  return {{"setup", RandomId()},
          {"target_patches", play.room.geometry.scene.target_patches},
          {"patches", play.room.size()},
          {"light", LightFieldName(options.light)},
          {"dither", DitherName(options.dither)},
          {"feather", options.feather}};
}

PlayScene PreparePlay(const PlayOptions& options, RigDirectory rig) {
  PlayScene play;
  CalibratedRoomOptions room;
  room.scene = options.scene;
  room.rig_dir = options.rig_dir;
  room.solution_dir = options.solution;
  room.patches = options.patches;
  room.alpha = options.alpha;
  room.projection.feather = options.feather;
  room.progress = options.progress;  // the form factors' progress: minutes for a large room
  // Frames are planned per patch (frame_plan.h), which carries no per-pixel reflectance.
  room.reflectance_maps = false;
  // The solution's emittance needs no camera; desired images are mapped through it.
  room.camera_rays = options.solution.empty();
  RoomSources sources;
  sources.rig = std::move(rig);  // read already (its keys, its projectors' outputs)
  sources = ReadRoomSources(room, std::move(sources));
  Report(options.progress,
         options.solution.empty()
             ? "play: subdividing the room, computing form factors, casting the camera's rays"
             : "play: subdividing the room and computing form factors");
  play.room = BuildCalibratedRoom(room, std::move(sources));
  if (play.room.solution) play.solution = play.room.solution->emittance;
  play.setup = SetupJson(options, play);
  return play;
}

void WritePlayResult(const PlayOptions& options, const PlaySummary& summary,
                     const std::vector<NodeAddress>& nodes, const PlayScene& play) {
  nlohmann::json result = {{"scene", options.scene},
                           {"rig", options.rig_dir.string()},
                           {"desired", options.desired.string()},
                           {"solution", options.solution.string()},
                           {"playlist", options.playlist.string()},
                           {"patches", play.room.problem.size()},
                           {"method", MethodName(options.solver.method)},
                           {"function_tolerance", options.solver.function_tolerance},
                           {"fps_target", options.fps},
                           {"frames_shown", summary.frames.size()},
                           {"frames_dropped", summary.dropped},
                           {"seconds", summary.seconds},
                           {"setup_seconds", summary.setup_seconds},
                           {"stopped", summary.stopped},
                           {"osc", options.osc},
                           {"osc_refused", summary.osc_refused},
                           {"frames_received", summary.received},
                           {"frames_replaced", summary.replaced}};
  std::vector<double> solve, ready, skew, total;
  for (const PlayFrame& frame : summary.frames) {
    result["frames"].push_back(FrameJson(frame, nodes));
    solve.push_back(frame.solve_ms);
    ready.push_back(frame.shown.ready_ms);
    skew.push_back(frame.shown.skew_ms);
    total.push_back(frame.total_ms);
  }
  result["median_ms"] = {{"solve", Median(solve)},
                         {"ready", Median(ready)},
                         {"skew", Median(skew)},
                         {"total", Median(total)}};
  for (const NodeAddress& node : nodes)
    result["nodes"].push_back({{"name", node.name}, {"endpoint", node.endpoint}});
  std::filesystem::create_directories(options.out);
  WriteFileAtomically(options.out / "result.json", result.dump(2) + "\n");
}

// Linear RGB (CV_32FC3, R G B) of an 8- or 16-bit sRGB BGR image: a desired texture.
cv::Mat LinearTexture(const cv::Mat& image) {
  if (image.empty() || image.channels() != 3 || (image.depth() != CV_8U && image.depth() != CV_16U))
    throw std::invalid_argument("playlist frame: need 8- or 16-bit colour");
  const bool eight_bit = image.depth() == CV_8U;
  std::vector<float> linear(eight_bit ? 256 : 65536);
  for (size_t q = 0; q < linear.size(); ++q)
    linear[q] = static_cast<float>(SrgbToLinear(q / (eight_bit ? 255.0 : 65535.0)));
  cv::Mat texture(image.rows, image.cols, CV_32FC3);
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      int b, g, r;
      if (eight_bit) {
        const cv::Vec3b& p = image.at<cv::Vec3b>(y, x);
        b = p[0], g = p[1], r = p[2];
      } else {
        const cv::Vec3w& p = image.at<cv::Vec3w>(y, x);
        b = p[0], g = p[1], r = p[2];
      }
      texture.at<cv::Vec3f>(y, x) = cv::Vec3f(linear[r], linear[g], linear[b]);
    }
  }
  return texture;
}

// The playlist's contents on the room's surfaces: which content each surface shows, from which
// position of the show, and the desired colours of its patches for the content's current frame
// (the texture's mean over each patch, as the scene's desired textures are: geometry/patches.h).
class SurfaceContents {
 public:
  SurfaceContents(const Playlist* playlist, const std::string& playlist_file, const Scene& scene,
                  const PatchLevel& fine, int texture_samples, ProgressCallback log)
      : playlist_(playlist), white_(scene.white), log_(std::move(log)) {
    for (size_t s = 0; s < scene.surfaces.size(); ++s) {
      Surface surface_state;
      surface_state.name = scene.surfaces[s].name;
      surfaces_.push_back(std::move(surface_state));
    }
    for (int i = 0; i < fine.size(); ++i) {
      Surface& surface = surfaces_[fine.patches[i].surface];
      surface.patches.push_back(i);
      surface.areas.push_back(fine.patches[i].area);
      surface.samples.emplace_back();
      SamplePatch(fine.patches[i], texture_samples, &surface.samples.back());
    }
    if (playlist_ == nullptr) return;
    for (size_t k = 0; k < playlist_->surfaces.size(); ++k) {
      const PlaylistEntry& entry = playlist_->surfaces[k];
      if (FindSurface(entry.surface) < 0)
        throw IoError(playlist_file + ": surfaces[" + std::to_string(k) +
                      "].surface: no surface '" + entry.surface + "' in the room (" + scene.name +
                      ")");
      schedule_.push_back(entry);
    }
    std::stable_sort(
        schedule_.begin(), schedule_.end(),
        [](const PlaylistEntry& a, const PlaylistEntry& b) { return a.start < b.start; });
  }

  bool empty() const { return playlist_ == nullptr; }

  // An OSC switch: `content` ("" none) on `surface` from `position`. False (logged) when there
  // is no such surface or content.
  bool Switch(const std::string& surface_name, const std::string& content, int position) {
    const int s = FindSurface(surface_name);
    if (s < 0) {
      Report(log_, "play: surface " + surface_name + ": no such surface in the room; ignored");
      return false;
    }
    const PlaylistContent* found = nullptr;
    if (!content.empty()) {
      found = playlist_ != nullptr ? playlist_->Find(content) : nullptr;
      if (found == nullptr) {
        Report(log_, "play: surface " + surface_name + ": no content '" + content +
                         "' in the playlist; ignored");
        return false;
      }
    }
    Start(&surfaces_[s], found, position);
    return true;
  }

  // Brings every surface to show position `position` (frames of the show's clock at `fps`):
  // starts the schedule's entries now due, reads each content's frame. True when a surface's
  // desired colours changed.
  bool Update(int position, double fps) {
    while (next_ < schedule_.size() && schedule_[next_].start * fps <= position + 1e-9) {
      const PlaylistEntry& entry = schedule_[next_++];
      Start(&surfaces_[FindSurface(entry.surface)], playlist_->Find(entry.content),
            static_cast<int>(std::llround(entry.start * fps)));
    }
    bool changed = false;
    for (Surface& surface : surfaces_) {
      if (surface.content == nullptr) {
        changed = changed || surface.fresh;
        surface.fresh = false;
        continue;
      }
      int frame = std::max(0, position - surface.start);
      const int count = surface.count;
      if (count > 0) frame = surface.content->loop ? frame % count : std::min(frame, count - 1);
      if (frame == surface.frame && !surface.fresh) continue;
      cv::Mat image = surface.image.empty() ? surface.source->Read(frame) : surface.image;
      if (image.empty() && surface.content->loop && frame > 0) {
        // A video's count was an estimate: its end found here; from its start again.
        surface.count = frame;
        surface.start = position;
        frame = 0;
        image = surface.source->Read(0);
      }
      surface.fresh = false;
      if (image.empty()) continue;  // past the end: the last frame holds
      surface.frame = frame;
      SetDesired(&surface, LinearTexture(image));
      changed = true;
    }
    return changed;
  }

  // Writes the surfaces' desired colours over `desired`'s rows of their patches.
  void Apply(Eigen::MatrixX3d* desired) const {
    for (const Surface& surface : surfaces_) {
      if (surface.content == nullptr || surface.desired.rows() == 0) continue;
      for (size_t k = 0; k < surface.patches.size(); ++k)
        desired->row(surface.patches[k]) = surface.desired.row(k);
    }
  }

  // What each surface with content shows.
  std::vector<PlaySurface> Record() const {
    std::vector<PlaySurface> record;
    for (const Surface& surface : surfaces_) {
      if (surface.content == nullptr) continue;
      const Eigen::RowVector3d mean = surface.desired.rows() > 0
                                          ? Eigen::RowVector3d(surface.desired.colwise().mean())
                                          : Eigen::RowVector3d::Zero();
      record.push_back(
          {surface.name, surface.content->name, surface.frame, {mean(0), mean(1), mean(2)}});
    }
    return record;
  }

 private:
  struct Surface {
    std::string name;
    std::vector<int> patches;
    std::vector<double> areas;
    std::vector<std::vector<PatchSample>> samples;
    const PlaylistContent* content = nullptr;
    std::unique_ptr<FrameSource> source;
    cv::Mat image;  // an image content's one frame
    int count = 0, start = 0, frame = -1;
    bool fresh = false;  // switched: its desired colours to be made again
    Eigen::MatrixX3d desired;
  };

  int FindSurface(const std::string& name) const {
    for (size_t s = 0; s < surfaces_.size(); ++s)
      if (surfaces_[s].name == name) return static_cast<int>(s);
    return -1;
  }

  void Start(Surface* surface, const PlaylistContent* content, int position) {
    surface->content = content;
    surface->source.reset();
    surface->image.release();
    surface->desired.resize(0, 3);
    surface->start = position;
    surface->frame = -1;
    surface->count = 0;
    surface->fresh = true;
    if (content == nullptr) return;
    try {
      if (content->kind == PlaylistContent::Kind::kImage) {
        surface->image = ReadImage(content->resolved, cv::IMREAD_COLOR | cv::IMREAD_ANYDEPTH);
        surface->count = 1;
      } else {
        surface->source = std::make_unique<FrameSource>(content->resolved);
        surface->count = surface->source->count();
      }
    } catch (const std::exception& error) {
      // Checked when the playlist was read; a file that went since is this surface's loss only.
      Report(log_, "play: surface " + surface->name + ": " + error.what());
      surface->content = nullptr;
    }
  }

  void SetDesired(Surface* surface, const cv::Mat& texture) {
    DesiredAppearance appearance;
    appearance.texture_linear = texture;
    surface->desired.resize(static_cast<int>(surface->patches.size()), 3);
    for (size_t k = 0; k < surface->patches.size(); ++k) {
      Vec3 sum = Vec3::Zero();
      for (const PatchSample& sample : surface->samples[k])
        sum += sample.weight * appearance.LinearAt(sample.uv);
      surface->desired.row(k) = white_ * (sum / surface->areas[k]).transpose();
    }
  }

  const Playlist* playlist_;
  double white_;
  ProgressCallback log_;
  std::vector<Surface> surfaces_;
  std::vector<PlaylistEntry> schedule_;
  size_t next_ = 0;
};

// What the OSC thread and the show share: commands waiting for the next frame, and the status a
// /procam/status is answered with.
class ShowControl {
 public:
  static constexpr size_t kMaxPending = 256;  // commands waiting; more are refused

  // On the OSC thread. False when the queue is full.
  bool Push(const OscCommand& command) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (pending_.size() >= kMaxPending) return false;
    pending_.emplace_back(command, status_.frame);
    return true;
  }
  // On the show's thread: the commands that arrived, each with the frame under way then.
  std::vector<std::pair<OscCommand, int>> Take() {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<std::pair<OscCommand, int>> taken;
    taken.swap(pending_);
    return taken;
  }

  struct Status {
    int frame = 0;  // frames shown (the number of the frame under way)
    double rate = 0.0;
    int dropped = 0, nodes_lost = 0, source = 0;
    bool paused = false;
    double fade = 1.0;
  };
  void Publish(const Status& status) {
    std::lock_guard<std::mutex> lock(mutex_);
    status_ = status;
  }
  OscMessage StatusMessage() {
    std::lock_guard<std::mutex> lock(mutex_);
    OscMessage message;
    message.address = "/procam/status";
    message.types = "ifiiiif";
    const double values[] = {double(status_.frame),
                             status_.rate,
                             double(status_.dropped),
                             double(status_.nodes_lost),
                             double(status_.source),
                             status_.paused ? 1.0 : 0.0,
                             status_.fade};
    for (size_t k = 0; k < message.types.size(); ++k)
      message.arguments.push_back({message.types[k], values[k], ""});
    return message;
  }

 private:
  std::mutex mutex_;
  std::vector<std::pair<OscCommand, int>> pending_;
  Status status_;
};

// The fade: a level moving linearly from `from` to `to` over `seconds` from `start`.
struct Fade {
  double from = 1.0, to = 1.0, seconds = 0.0;
  Clock::time_point start;
  double Level(Clock::time_point now) const {
    if (seconds <= 0.0) return to;
    const double t = std::chrono::duration<double>(now - start).count() / seconds;
    return t >= 1.0 ? to : from + (to - from) * std::max(0.0, t);
  }
};

// The show itself: frames through the controller until the source ends, a stop, or /procam/stop.
// Frames follow a clock of ticks at the target rate; the source's position advances with the
// ticks while playing and holds while paused.
PlaySummary PlayFrames(const PlayOptions& options, PlayScene& play, Controller& controller,
                       FrameSource* source, LiveFrames* live, const Playlist* playlist,
                       ShowControl* control, Clock::time_point start) {
  PlaySummary summary;
  const int limit = options.frames > 0 ? options.frames
                    : live != nullptr  ? INT32_MAX
                    : source == nullptr
                        ? (control != nullptr || playlist != nullptr ? INT32_MAX : 1)
                        : (source->count() > 0 ? source->count() : INT32_MAX);
  const auto period = std::chrono::duration<double>(1.0 / options.fps);
  std::shared_ptr<const RadiositySystem> radiosity;
  Eigen::MatrixX3d previous;
  CompensationProblem& problem = play.room.problem;
  const CameraPixelRays& rays = play.room.camera_rays;
  const Eigen::MatrixX3d room_desired = problem.desired;
  SolverOptions solver = options.solver;  // the method and tolerance OSC may change
  auto last_progress = Clock::now();
  Clock::time_point t0;                  // when tick 0 ended
  std::deque<Clock::time_point> recent;  // the last frames' ends, for the status's rate
  int tick = 0;
  int media_tick = 0, media_index = 0;  // the source's position: media_index at tick media_tick
  bool paused = false;
  Fade fade;
  // What the emittance in `previous` was solved for: a frame solves again when any differs.
  int solved_index = -1, image_index = -1;
  int live_taken = 0;  // a live source's frames taken
  double solved_fade = -1.0;
  bool solver_changed = false;
  // The camera-view source's desired colours (the room's own without one).
  Eigen::MatrixX3d image_desired = room_desired;
  Eigen::RowVector3d desired_mean = Eigen::RowVector3d::Zero();
  SurfaceContents contents(playlist, options.playlist.string(), play.room.geometry.scene,
                           play.room.fine(), SubdivisionOptions().texture_samples,
                           options.progress);
  while (true) {
    if (options.stop != nullptr && options.stop->load()) {
      summary.stopped = true;
      break;
    }
    // A live source's first frame: nothing is shown before it.
    if (live != nullptr && image_index < 0 && !live->Wait(0.1)) {
      if (live->Ended()) break;
      continue;
    }
    const auto frame_start = Clock::now();
    PlayFrame frame;
    bool stop_command = false;
    const int playing_index = media_index + (tick - media_tick);
    bool surfaces_changed = false;
    if (control != nullptr) {
      for (const auto& [command, received] : control->Take()) {
        using Kind = OscCommand::Kind;
        const int at = paused ? media_index : playing_index;
        switch (command.kind) {
          case Kind::kPlay:
            if (paused) paused = false, media_index = at, media_tick = tick;
            break;
          case Kind::kPause:
            if (!paused) paused = true, media_index = at, media_tick = tick;
            break;
          case Kind::kSeek:
            media_index = static_cast<int>(
                std::llround(std::min(command.seconds * options.fps, double(INT32_MAX) / 2)));
            media_tick = tick;
            break;
          case Kind::kFade:
            fade = Fade{fade.Level(frame_start), command.level, command.seconds, frame_start};
            break;
          case Kind::kMethod:
            ParseMethod(command.method, &solver.method);
            solver_changed = true;
            break;
          case Kind::kTolerance:
            solver.function_tolerance = command.tolerance;
            solver_changed = true;
            break;
          case Kind::kSurface:
            surfaces_changed =
                contents.Switch(command.surface, command.content, at) || surfaces_changed;
            break;
          case Kind::kStop:
            stop_command = true;
            break;
          case Kind::kStatus:
            break;  // answered by the OSC thread
        }
        frame.commands.emplace_back(command.Text(), received);
      }
    }
    if (stop_command) {
      summary.stopped = true;
      break;
    }
    if (live != nullptr && !paused) {
      // The newest frame that arrived, if one did; else the one shown holds.
      int number = 0;
      const cv::Mat image = live->Take(&number);
      if (!image.empty()) {
        if (live_taken >= limit) break;  // --frames: that many of the source's frames shown
        ++live_taken;
        const auto step = Clock::now();
        image_desired = DesiredFromImage(image, rays.patch, rays.width, rays.height, room_desired);
        image_index = number;
        frame.desired_ms = MsSince(step);
      } else if (live->Ended()) {
        break;  // every frame that came was shown
      }
    }
    const int position = paused ? media_index : media_index + (tick - media_tick);
    const int index = live != nullptr ? image_index : position;
    if (live == nullptr && index >= limit) break;
    frame.source = index;
    frame.paused = paused;
    frame.fade = fade.Level(frame_start);
    if (source != nullptr || live != nullptr || playlist != nullptr) {
      if (source != nullptr && index != image_index) {
        cv::Mat image = source->Read(index);
        if (image.empty()) break;  // the end of a video
        frame.read_ms = MsSince(frame_start);
        const auto step = Clock::now();
        image_desired = DesiredFromImage(image, rays.patch, rays.width, rays.height, room_desired);
        image_index = index;
        frame.desired_ms = MsSince(step);
      }
      surfaces_changed = contents.Update(position, options.fps) || surfaces_changed;
      if (index != solved_index || frame.fade != solved_fade || solver_changed ||
          surfaces_changed) {
        problem.desired = image_desired;
        contents.Apply(&problem.desired);
        problem.desired *= frame.fade;
        desired_mean = problem.desired.colwise().mean();
        const auto step = Clock::now();
        SolverSummary solver_summary;
        const CompensationSolution solution =
            Solve(solver, problem, &solver_summary, {}, WarmStart{radiosity, previous});
        radiosity = solution.radiosity_system;
        previous = solution.emittance;
        frame.solve_ms = MsSince(step);
        frame.iterations = solver_summary.iterations;
        solved_index = index;
        solved_fade = frame.fade;
        solver_changed = false;
      }
    } else {
      // A solution's light scaled: radiosity is linear in the emittance (B = K⁻¹E), so the room's
      // appearance scales by the same level in linear light.
      previous = frame.fade * play.solution;
      desired_mean = frame.fade * room_desired.colwise().mean();
    }
    frame.desired_mean = {desired_mean(0), desired_mean(1), desired_mean(2)};
    frame.surfaces = contents.Record();
    frame.emittance_mean = previous.size() > 0 ? previous.mean() : 0.0;
    frame.shown = controller.Show(static_cast<uint64_t>(summary.frames.size()), previous);
    frame.total_ms = MsSince(frame_start);
    if (summary.frames.empty()) t0 = Clock::now();
    summary.frames.push_back(frame);
    // The next tick is the one due now: ticks whose time passed are dropped, not shown late.
    const auto next_due = t0 + std::chrono::duration_cast<Clock::duration>(period * (tick + 1));
    if (Clock::now() < next_due) std::this_thread::sleep_until(next_due);
    const int due = static_cast<int>(std::chrono::duration<double>(Clock::now() - t0) / period);
    const int next = std::max(tick + 1, due);
    const int advance = next - tick;
    summary.dropped += paused || live != nullptr
                           ? advance - 1
                           : std::max(0, std::min(index + advance, limit) - (index + 1));
    tick = next;
    recent.push_back(Clock::now());
    if (recent.size() > 30) recent.pop_front();
    const double rate =
        recent.size() < 2
            ? 0.0
            : (recent.size() - 1) /
                  std::max(1e-9,
                           std::chrono::duration<double>(recent.back() - recent.front()).count());
    if (control != nullptr) {
      control->Publish({static_cast<int>(summary.frames.size()), rate, summary.dropped,
                        static_cast<int>(controller.nodes().size()) - controller.live(), index,
                        paused, frame.fade});
    }
    const bool last = !paused && live == nullptr && index + advance >= limit;
    if (SecondsSince(last_progress) >= 1.0 || last) {
      last_progress = Clock::now();
      Report(options.progress,
             fmt::format("play: frame {}/{} ({:.1f} fps), solve {:.1f} ms ({} it), ready {:.1f} "
                         "ms, skew {:.2f} ms, "
                         "dropped {}, nodes {}/{}{}",
                         std::min(index + (paused || live != nullptr ? 1 : advance), limit),
                         limit == INT32_MAX ? 0 : limit, rate, frame.solve_ms, frame.iterations,
                         frame.shown.ready_ms, frame.shown.skew_ms, summary.dropped,
                         controller.live(), controller.nodes().size(), paused ? ", paused" : ""));
    }
  }
  summary.seconds = SecondsSince(start);
  return summary;
}

}  // namespace

Eigen::MatrixX3d DesiredFromImage(const cv::Mat& image, const std::vector<int>& pixel_patch,
                                  int width, int height, const Eigen::MatrixX3d& fallback) {
  if (image.empty() || image.channels() != 3 || (image.depth() != CV_8U && image.depth() != CV_16U))
    throw std::invalid_argument("desired image: need 8- or 16-bit colour");
  if (static_cast<long long>(pixel_patch.size()) != 1LL * width * height)
    throw std::invalid_argument("desired image: the camera's pixel map does not fit its size");
  cv::Mat resized;
  if (image.cols != width || image.rows != height) {
    cv::resize(image, resized, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  } else {
    resized = image;
  }
  const double scale = image.depth() == CV_8U ? 1.0 / 255.0 : 1.0 / 65535.0;
  // sRGB decoding per code value (a table: 256 or 65536 entries).
  std::vector<double> linear(image.depth() == CV_8U ? 256 : 65536);
  for (size_t q = 0; q < linear.size(); ++q) linear[q] = SrgbToLinear(q * scale);
  const bool eight_bit = resized.depth() == CV_8U;
  const PatchPixelSums sums = SumPixelsPerPatch(
      pixel_patch, width, height, static_cast<int>(fallback.rows()),
      [&](int x, int y, Eigen::RowVector3d* rgb) {
        int b, g, r;
        if (eight_bit) {
          const cv::Vec3b& p = resized.at<cv::Vec3b>(y, x);
          b = p[0], g = p[1], r = p[2];
        } else {
          const cv::Vec3w& p = resized.at<cv::Vec3w>(y, x);
          b = p[0], g = p[1], r = p[2];
        }
        *rgb = Eigen::RowVector3d(linear[r], linear[g], linear[b]);
        return true;
      });
  return sums.Means(fallback);
}

void PlayOptions::Declare(OptionTable* table) {
  table->Text("scene", &scene, "the room (scene file)")
      .Positional()
      .Required()
      .Path("rig", &rig_dir, "rig directory (projectors, registered camera, keys)")
      .Required()
      .Path("desired", &desired,
            "the desired appearance as the rig's camera sees the room: a directory of images, a "
            "video, stdin:WIDTHxHEIGHT (raw rgb24 frames on standard input, the newest shown) or "
            "camera:URI (a capture device, e.g. camera:v4l2:/dev/video2; procam cameras lists "
            "them)")
      .Path("solution", &solution,
            "instead of --desired: show a compensation solution's emittance (procam compensate "
            "--out) as every frame")
      .Path("out", &out, "output directory (result.json with per-frame timings)")
      .Required()
      .List(
          "nodes",
          [this] {
            std::vector<std::string> items;
            for (const NodeAddress& node : nodes) items.push_back(node.name + "=" + node.endpoint);
            return items;
          },
          [this](const std::vector<std::string>& items, std::string* why) {
            std::vector<NodeAddress> parsed;
            try {
              for (size_t k = 0; k < items.size(); ++k)
                parsed.push_back(ParseNodeAddress(items[k], static_cast<int>(k)));
            } catch (const std::exception& error) {
              *why = error.what();
              return false;
            }
            nodes = std::move(parsed);
            return true;
          },
          "NAME=tcp://HOST:PORT", "display nodes; none: a node in this process")
      .Sets(&nodes)
      .Texts("display", &display,
             "without --nodes, per projector: glfw:MONITOR, record:DIR or memory")
      .Number("fps", &fps, OptionTable::Interval::AboveMin(0.0, 1000.0), "Hz",
              "target frame rate (frames due while one is shown are dropped)")
      .Integer("frames", &frames, 0, std::numeric_limits<int>::max(), "",
               "frames to play (0: the whole source; a live source: its frames shown)")
      .Integer("patches", &patches, 0, std::numeric_limits<int>::max(), "",
               "target patch count (0: the room's)")
      .Choice("method", &solver.method, MethodChoices(),
              "the objective (docs/solver.md): naive, reverse, linear, perceptual (the paper's) or "
              "perceptual2000")
      .Choice("metric-update", &solver.metric_update, MetricUpdateChoices(),
              "perceptual2000: CIEDE2000's metric measured again at every iterate or in rounds "
              "(docs/solver.md)")
      .Choice("device", &solver.device, DeviceChoices(), "where K⁻¹ is applied: cpu or cuda")
      .Number("tolerance", &solver.function_tolerance, 0.0, 0.1, "",
              "each frame's solve stops when an iteration lowers the cost by less than this "
              "fraction of it")
      .Number("alpha", &alpha, OptionTable::Interval::AboveMin(0.0, 1.0), "",
              "weight of the absolute term against the spatial term")
      .Choice("dither", &dither, DitherChoices(),
              "none (nearest code value), ordered (8×8 Bayer) or error-diffusion")
      .Choice("light", &light, LightFieldChoices(),
              "smooth: the light varies smoothly over each surface, stepping only where the "
              "desired appearance does, each patch's flux kept (seamless); flat: one uniform "
              "level per patch")
      .Choice<bool>("render", &local_gpu, {{"gpu", true}, {"cpu", false}},
                    "without --nodes: gpu (the node's images rendered with OpenGL) or cpu (the "
                    "reference renderer)")
      .Custom(
          "frame-timeout-ms", [this] { return OptionNumberText(1e3 * frame_timeout_s); },
          [this](const std::string& text, std::string* why) {
            double ms = 0.0;
            const char* end = text.data() + text.size();
            const auto [last, error] = std::from_chars(text.data(), end, ms);
            if (text.empty() || error != std::errc() || last != end ||
                !(ms >= 1.0 && ms <= 60000.0)) {
              *why = "must be a number of ms in [1, 60000], got '" + text + "'";
              return false;
            }
            frame_timeout_s = 1e-3 * ms;
            return true;
          },
          "ms in [1, 60000]",
          "a node that does not answer a frame in this time is reported lost; the others go on")
      .Sets(&frame_timeout_s)
      .Number("setup-timeout", &setup_timeout_s, 0.1, 3600.0, "s",
              "for every node to answer and build the rig before the first frame")
      .Text("osc", &osc,
            "IPV4:PORT to listen at for a show controller's OSC messages (docs/show.md): "
            "127.0.0.1:9000 this machine only, 0.0.0.0:9000 every interface; empty: no remote "
            "control")
      .Path("playlist", &playlist,
            "content per surface in its texture coordinates (JSON, docs/show.md#a-playlist), "
            "switched by /procam/surface")
      .Texts("osc-allow", &osc_allow,
             "senders the OSC control answers, IPv4 addresses or ranges A.B.C.D/N; others are "
             "refused in a log line each");
}

bool PlayOptions::Check(std::string* why) const {
  OptionTable table("play");  // reads the fields only
  const_cast<PlayOptions*>(this)->Declare(&table);
  if (!table.Check(why)) return false;
  try {
    OscAllowList::Parse(osc_allow);
  } catch (const std::invalid_argument& error) {
    *why = error.what();
    return false;
  }
  return true;
}

PlaySummary RunPlay(const PlayOptions& given) {
  const auto start = Clock::now();
  std::string why;
  if (!given.Check(&why)) throw std::invalid_argument(why);
  // The OSC thread logs too: one line at a time.
  auto log_mutex = std::make_shared<std::mutex>();
  PlayOptions options = given;
  if (given.progress) {
    options.progress = [log_mutex, progress = given.progress](const std::string& line) {
      std::lock_guard<std::mutex> lock(*log_mutex);
      progress(line);
    };
  }
  // The OSC socket before anything long: a port taken or an address not this machine's fails at
  // once.
  std::optional<ShowControl> show_control;
  std::unique_ptr<OscServer> osc;
  if (!options.osc.empty()) {
    show_control.emplace();
    OscServerOptions server;
    server.listen = options.osc;
    server.allow = OscAllowList::Parse(options.osc_allow);
    server.log = options.progress;
    server.on_command = [&show_control, progress = options.progress](const OscCommand& command) {
      if (!show_control->Push(command))
        Report(progress, "osc: ignored " + command.Text() + ": " +
                             std::to_string(ShowControl::kMaxPending) +
                             " commands wait already for the next frame");
    };
    server.on_status = [&show_control] { return show_control->StatusMessage(); };
    osc = std::make_unique<OscServer>(std::move(server));
  }
  const RigDirectory rig = ReadRigDirectory(options.rig_dir);
  std::optional<RigKeys> keys;
  std::vector<NodeAddress> nodes = options.nodes;
  const bool local = nodes.empty();
  if (local) {
    nodes.push_back({"local", "inproc://procam-play-node"});
  } else {
    keys = ReadRigKeys(options.rig_dir, KeyRole::kController);
  }
  if (options.desired.empty() == options.solution.empty() &&
      !(options.desired.empty() && !options.playlist.empty()))
    throw std::invalid_argument(
        "play: give the desired appearance (--desired, --playlist or both) or a solution "
        "(--solution), not both");
  if (!options.solution.empty() && !options.playlist.empty())
    throw std::invalid_argument("play: --playlist takes no --solution (a playlist is solved)");
  std::optional<Playlist> playlist;
  if (!options.playlist.empty()) playlist = ReadPlaylist(options.playlist);
  std::optional<FrameSource> source;
  std::unique_ptr<LiveFrames> live;
  int live_width = 0, live_height = 0;
  // Live sources read from now on: frames that come while the room is prepared replace one
  // another.
  if (ParseStdinSource(options.desired.string(), &live_width, &live_height)) {
    live = std::make_unique<StdinFrames>(live_width, live_height);
  } else if (options.desired.string().starts_with("camera:")) {
    live = std::make_unique<CameraFrames>(options.desired.string().substr(7));
  } else if (!options.desired.empty()) {
    source.emplace(options.desired);
  }
  zmq::context_t context;
  std::atomic<bool> node_stop{false}, node_failed{false};
  std::exception_ptr failure;
  PlaySummary summary;
  std::vector<NodeAddress> node_list = nodes;
  // The controller's part (on its own thread when the node runs on this one).
  const auto stopping = [&] { return options.stop != nullptr && options.stop->load(); };
  auto control = [&] {
    try {
      PlayScene play = PreparePlay(options, rig);
      ControllerOptions controller_options;
      controller_options.setup = play.setup;
      controller_options.frame_timeout_s = options.frame_timeout_s;
      controller_options.setup_timeout_s = options.setup_timeout_s;
      controller_options.log = options.progress;
      controller_options.cancelled = [&] { return node_failed.load() || stopping(); };
      Controller controller(context, nodes, keys ? &*keys : nullptr, controller_options);
      if (!stopping()) {
        Report(options.progress, fmt::format("play: setting up {} node(s)", nodes.size()));
        try {
          controller.Connect();
        } catch (const IoError&) {
          if (!stopping()) throw;  // cancelled by the stop: ended below
        }
      }
      if (stopping()) {  // before the first frame: nothing shown, nothing written
        summary.stopped = true;
        summary.seconds = SecondsSince(start);
        controller.Stop(/*exit=*/local);
      } else {
        const double setup_seconds = SecondsSince(start);
        summary = PlayFrames(options, play, controller, source ? &*source : nullptr, live.get(),
                             playlist ? &*playlist : nullptr,
                             show_control ? &*show_control : nullptr, start);
        if (live) {
          summary.received = live->received();
          summary.replaced = live->replaced();
          if (!live->error().empty()) Report(options.progress, "play: " + live->error());
        }
        summary.setup_seconds = setup_seconds;
        if (osc) summary.osc_refused = osc->refused();
        controller.Stop(/*exit=*/local);
        if (!summary.frames.empty() || !summary.stopped)
          WritePlayResult(options, summary, node_list, play);
      }
    } catch (const Stopped&) {
      // The form factors cut short by the stop (base/stop.h), before any node was set up: as a
      // stop before the first frame, nothing written.
      if (!stopping()) failure = std::current_exception();
      summary.stopped = true;
      summary.seconds = SecondsSince(start);
    } catch (...) {
      failure = std::current_exception();
    }
    node_stop = true;
  };
  if (!local) {
    control();
  } else {
    // The outputs first, on this thread (GLFW's): a --display that does not fit the rig fails
    // at once, before the form factors are computed.
    auto outputs = std::make_shared<std::vector<std::unique_ptr<NodeOutput>>>(
        options.local_outputs(rig.projectors));
    const NodeOutputFactory made = [outputs](const std::vector<Projector>&) {
      return std::move(*outputs);
    };
    std::thread controller_thread(control);
    try {
      NodeOptions node;
      node.name = "local";
      node.rig_dir = options.rig_dir;
      node.scene = options.scene;
      for (const Projector& projector : rig.projectors) node.projectors.push_back(projector.name);
      node.listen = nodes[0].endpoint;
      node.log = options.progress;
      node.gpu = options.local_gpu;
      RunNode(context, node, made, node_stop);
    } catch (...) {
      node_failed = true;
      controller_thread.join();
      throw;
    }
    controller_thread.join();
  }
  if (failure) std::rethrow_exception(failure);
  return summary;
}

}  // namespace procam
