#pragma once
// `procam play`: light that follows changing content. Each frame's desired appearance (an image
// of the room as the rig's camera would see it: one of an image sequence or a video's frames)
// becomes the per-patch desired colours, is solved warm-started from the previous frame's
// emittance (the factorised radiosity system made once), sent to the display nodes and shown
// through the frame barrier (nodes/controller.h), at a target rate: a frame whose time has
// passed while the previous one was being solved and shown is dropped, never shown late, so the
// show does not drift. Per-frame timings go to OUT/result.json; a progress line every second.
//
// Remote control (docs/show.md): with `osc` set, a show controller steers the show over OSC
// (nodes/osc.h's address space): play, pause, seek, fade to black and back, method and tolerance,
// status. Frames run on a clock of their own at the target rate; the source's position advances
// with it while playing and holds while paused (the frame shown again, solved again only when the
// fade or the solver changed). Commands take effect at the start of the next frame; each frame's
// record says what it showed (source frame, fade level, paused, the commands it applied).
//
// Desired appearance from an image: the image (sRGB, 8 or 16 bits) is resized to the rig
// camera's resolution; every camera pixel's ray is cast into the room (CastCameraPixels with the
// registered camera of RIG_DIR/camera.cameramodel); a patch's desired linear colour is the mean
// of the linearised pixels that see it. Patches the camera does not see keep the room's own
// desired colours.

#include <Eigen/Core>
#include <array>
#include <atomic>
#include <filesystem>
#include <opencv2/core/mat.hpp>
#include <string>
#include <utility>
#include <vector>
#include <zmq.hpp>

#include "base/option_table.h"
#include "base/progress.h"
#include "compensation/solver.h"
#include "nodes/controller.h"
#include "nodes/node.h"
#include "nodes/osc.h"
#include "projection/projector_images.h"

namespace procam {

// The solver's options for play: the recommended ones (RecommendedSolverOptions), each frame's
// solve stopping at kPlayFunctionTolerance (solver.h).
inline SolverOptions PlaySolverOptions() {
  SolverOptions options = RecommendedSolverOptions();
  options.function_tolerance = kPlayFunctionTolerance;
  return options;
}

struct PlayOptions {
  std::string scene;              // the room (LoadSceneArgument)
  std::filesystem::path rig_dir;  // projectors, reflectance, camera, keys
  // A directory of images (sorted by name), a video file, or a live source: stdin:WIDTHxHEIGHT
  // (raw rgb24 frames on standard input) or camera:URI (a capture device opened by
  // capture/camera.h's OpenCamera: v4l2:/dev/video2, ...); of a live source the newest frame is
  // shown (a frame that arrives before the show took the one before replaces it).
  std::filesystem::path desired;
  // Instead of `desired`: a compensation solution (procam compensate's directory) whose
  // emittance every frame shows (`frames` of them, default 1): a computed compensation shown
  // through the display nodes, the images `procam project` makes for it.
  std::filesystem::path solution;
  std::filesystem::path out;  // result.json (created)
  double fps = 30.0;          // target frame rate, > 0
  int frames = 0;  // frames to play (0: the whole source); of a live source, its frames shown
  int patches = 0;            // target patch count (0: the room's)
  double alpha = 0.5;
  // Method (default perceptual2000), device, and each frame's stopping rule (function_tolerance,
  // kPlayFunctionTolerance by default).
  SolverOptions solver = PlaySolverOptions();
  DitherMethod dither = DitherMethod::kOrdered;
  LightField light = LightField::kSmooth;
  double feather = 0.1;
  double frame_timeout_s = 0.5;    // a node silent this long in a frame is reported lost
  double setup_timeout_s = 120.0;  // every node set up before the first frame, or an error
  // Display nodes; empty: one node in this process showing every projector of the rig on
  // `local_outputs` (made on the calling thread, which runs the node: GLFW's main thread).
  std::vector<NodeAddress> nodes;
  // Without `nodes`, per projector: glfw:MONITOR, record:DIR or memory (the command makes
  // `local_outputs` from them).
  std::vector<std::string> display = {"memory"};
  NodeOutputFactory local_outputs;
  bool local_gpu = true;  // the in-process node renders on the GPU (NodeOptions::gpu)
  ProgressCallback progress;
  // Set (by a signal handler) to end the show cleanly: after the frame in hand, or during the
  // setup; the nodes are told to stop. Null: the show runs to the end of its source.
  const std::atomic<bool>* stop = nullptr;
  // OSC control: IPV4:PORT to listen at (127.0.0.1:9000: this machine only; 0.0.0.0:9000: every
  // interface); empty: none.
  std::string osc;
  // Senders the OSC control answers: IPv4 addresses or ranges A.B.C.D/N; others are refused in a
  // log line each.
  std::vector<std::string> osc_allow = {"127.0.0.1"};
  // Content per surface (nodes/playlist.h), over `desired` (or the room's own desired colours
  // without one); empty: none.
  std::filesystem::path playlist;

  // Declares every option of `procam play` in `table`, bound to these fields
  // (base/option_table.h).
  void Declare(OptionTable* table);
  // The declared options and --osc-allow's entries; false and `*why` (one line naming the
  // option) otherwise.
  bool Check(std::string* why) const;
};

// What a surface with playlist content showed in a frame.
struct PlaySurface {
  std::string surface, content;
  int frame = 0;                                   // the content's frame
  std::array<double, 3> desired_mean = {0, 0, 0};  // its patches' desired linear RGB, mean
};

struct PlayFrame {
  int source = 0;  // index in the source
  double read_ms = 0.0, desired_ms = 0.0, solve_ms = 0.0;
  int iterations = 0;
  FrameReport shown;
  double total_ms = 0.0;  // from the frame's start to its presentation
  bool paused = false;    // shown while the show was paused (OSC)
  double fade = 1.0;      // the level the desired appearance was scaled by, [0, 1]
  double emittance_mean = 0.0;  // the mean of the emittance shown, over patches and channels
  std::array<double, 3> desired_mean = {0, 0, 0};  // the desired linear RGB solved for, mean
  // The OSC commands this frame applied (OscCommand::Text) and the frame that was under way when
  // each arrived.
  std::vector<std::pair<std::string, int>> commands;
  std::vector<PlaySurface> surfaces;  // the surfaces showing playlist content
};

struct PlaySummary {
  std::vector<PlayFrame> frames;
  int dropped = 0;
  double seconds = 0.0;
  double setup_seconds = 0.0;  // geometry, form factors, camera rays, nodes set up
  bool stopped = false;        // ended by options.stop or /procam/stop before the source's end
  int osc_refused = 0;         // OSC messages ignored (not an allowed sender, malformed)
  // Live frames (--desired stdin:...): received, and replaced by a newer one before the show
  // took them (never shown).
  int received = 0, replaced = 0;
};

// Desired linear colours (n,3) from an image as the camera sees the room: `image` any size
// (resized to pixel_patch's), 8- or 16-bit sRGB, BGR (OpenCV's order); `pixel_patch` the patch
// every camera pixel sees (−1 for none), row-major `width` × `height`; patches no pixel sees get
// `fallback`'s row.
Eigen::MatrixX3d DesiredFromImage(const cv::Mat& image, const std::vector<int>& pixel_patch,
                                  int width, int height, const Eigen::MatrixX3d& fallback);

// Plays the source (header comment). Throws IoError naming the file, node or key that stops it
// before the first frame; a node failing during the show is reported and the show goes on.
// Stopped by options.stop, OUT/result.json records the frames shown (with "stopped": true), and
// a stop before the first frame writes nothing (an earlier result.json is kept).
PlaySummary RunPlay(const PlayOptions& options);

}  // namespace procam
