#include "nodes/play.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <exception>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <random>
#include <thread>

#include "base/image_io.h"
#include "base/io.h"
#include "base/stop.h"
#include "base/timing.h"
#include "calibration/calibrated_room.h"
#include "calibration/rig_directory.h"
#include "compensation/problem.h"
#include "compensation/stage.h"
#include "geometry/srgb.h"
#include "geometry/stage.h"
#include "projection/camera_rays.h"
#include "projection/projection_rig.h"

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
  // Frame `index` (≥ every earlier call's): skipped frames of a video are decoded and dropped.
  // Empty at the end of the source.
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

std::string RandomId() {
  std::random_device device;
  return fmt::format("{:08x}{:08x}", device(), device());
}

nlohmann::json FrameJson(const PlayFrame& frame, const std::vector<NodeAddress>& nodes) {
  nlohmann::json json = {{"frame", frame.shown.frame},       {"source", frame.source},
                         {"read_ms", frame.read_ms},         {"desired_ms", frame.desired_ms},
                         {"solve_ms", frame.solve_ms},       {"iterations", frame.iterations},
                         {"ready_ms", frame.shown.ready_ms}, {"present_ms", frame.shown.present_ms},
                         {"skew_ms", frame.shown.skew_ms},   {"total_ms", frame.total_ms},
                         {"nodes_shown", frame.shown.shown}};
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
                           {"patches", play.room.problem.size()},
                           {"method", MethodName(options.solver.method)},
                           {"function_tolerance", options.solver.function_tolerance},
                           {"fps_target", options.fps},
                           {"frames_shown", summary.frames.size()},
                           {"frames_dropped", summary.dropped},
                           {"seconds", summary.seconds},
                           {"setup_seconds", summary.setup_seconds},
                           {"stopped", summary.stopped}};
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

// The show itself: frames through the controller until the source ends.
PlaySummary PlayFrames(const PlayOptions& options, PlayScene& play, Controller& controller,
                       FrameSource* source, Clock::time_point start) {
  PlaySummary summary;
  const int limit = options.frames > 0  ? options.frames
                    : source == nullptr ? 1
                                        : (source->count() > 0 ? source->count() : INT32_MAX);
  const auto period = std::chrono::duration<double>(1.0 / options.fps);
  std::shared_ptr<const RadiositySystem> radiosity;
  Eigen::MatrixX3d previous;
  CompensationProblem& problem = play.room.problem;
  const CameraPixelRays& rays = play.room.camera_rays;
  const Eigen::MatrixX3d room_desired = problem.desired;
  auto last_progress = Clock::now();
  Clock::time_point t0;
  int index = 0;
  while (index < limit) {
    if (options.stop != nullptr && options.stop->load()) {
      summary.stopped = true;
      break;
    }
    const auto frame_start = Clock::now();
    PlayFrame frame;
    frame.source = index;
    if (source != nullptr) {
      cv::Mat image = source->Read(index);
      if (image.empty()) break;  // the end of a video
      frame.read_ms = MsSince(frame_start);
      auto step = Clock::now();
      problem.desired = DesiredFromImage(image, rays.patch, rays.width, rays.height, room_desired);
      frame.desired_ms = MsSince(step);
      step = Clock::now();
      SolverSummary solver_summary;
      const CompensationSolution solution =
          Solve(options.solver, problem, &solver_summary, {}, WarmStart{radiosity, previous});
      radiosity = solution.radiosity_system;
      previous = solution.emittance;
      frame.solve_ms = MsSince(step);
      frame.iterations = solver_summary.iterations;
    } else {
      previous = play.solution;
    }
    frame.shown = controller.Show(static_cast<uint64_t>(summary.frames.size()), previous);
    frame.total_ms = MsSince(frame_start);
    if (summary.frames.empty())
      t0 = Clock::now() - std::chrono::duration_cast<Clock::duration>(period * index);
    summary.frames.push_back(frame);
    // The next frame is the one due now: frames whose time passed are dropped, not shown late.
    const auto next_due = t0 + std::chrono::duration_cast<Clock::duration>(period * (index + 1));
    if (Clock::now() < next_due) std::this_thread::sleep_until(next_due);
    const int due = static_cast<int>(std::chrono::duration<double>(Clock::now() - t0) / period);
    const int next = std::max(index + 1, due);
    summary.dropped += std::min(next, limit) - (index + 1);
    index = next;
    if (SecondsSince(last_progress) >= 1.0 || index >= limit) {
      last_progress = Clock::now();
      Report(options.progress,
             fmt::format("play: frame {}/{} ({:.1f} fps), solve {:.1f} ms ({} it), ready {:.1f} "
                         "ms, skew {:.2f} ms, "
                         "dropped {}, nodes {}/{}",
                         std::min(index, limit), limit == INT32_MAX ? 0 : limit,
                         summary.frames.size() / std::max(1e-9, SecondsSince(t0)), frame.solve_ms,
                         frame.iterations, frame.shown.ready_ms, frame.shown.skew_ms,
                         summary.dropped, controller.live(), controller.nodes().size()));
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

PlaySummary RunPlay(const PlayOptions& options) {
  const auto start = Clock::now();
  if (!(options.fps > 0.0 && options.fps <= 1000.0))
    throw std::invalid_argument("--fps must be in (0, 1000]");
  const RigDirectory rig = ReadRigDirectory(options.rig_dir);
  std::optional<RigKeys> keys;
  std::vector<NodeAddress> nodes = options.nodes;
  const bool local = nodes.empty();
  if (local) {
    nodes.push_back({"local", "inproc://procam-play-node"});
  } else {
    keys = ReadRigKeys(options.rig_dir, KeyRole::kController);
  }
  if (options.desired.empty() == options.solution.empty())
    throw std::invalid_argument(
        "play: give the desired appearance (--desired) or a solution (--solution), not both");
  std::optional<FrameSource> source;
  if (!options.desired.empty()) source.emplace(options.desired);
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
        summary = PlayFrames(options, play, controller, source ? &*source : nullptr, start);
        summary.setup_seconds = setup_seconds;
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
