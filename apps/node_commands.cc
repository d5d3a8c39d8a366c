// procam keys (the rig's CURVE keys), procam node (a display node) and procam play (light that
// follows changing content): each parses, calls its library function, prints.
#include <fmt/format.h>

#include <atomic>
#include <functional>
#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "apps/stop_signals.h"
#include "base/output_directory.h"
#include "capture/devices.h"
#include "geometry/stage.h"
#include "nodes/node.h"
#include "nodes/outputs.h"
#include "nodes/play.h"
#include "nodes/transport.h"

namespace procam {
namespace {

struct PlayArguments {
  std::string scene, rig, desired, solution, out, method = MethodName(PlaySolverOptions().method),
                                                  device = "cpu", dither = "ordered",
                                                  render = "gpu";
  std::string metric_update = MetricUpdateName(PlaySolverOptions().metric_update);
  std::vector<std::string> nodes, display = {"memory"};
  LightField light = LightField::kSmooth;
  double fps = 30.0, alpha = 0.5, frame_timeout_ms = 500.0, setup_timeout = 120.0;
  double tolerance = kPlayFunctionTolerance;
  int frames = 0, patches = 0;
};

// Throws std::invalid_argument naming `option` when a value is given twice (a projector shown
// by one node twice, a monitor given two projectors, two nodes of one name or address).
// `counts(value)` says whether the value must be unique (memory outputs may repeat).
void CheckUnique(const std::vector<std::string>& values, const std::string& option,
                 const std::function<bool(const std::string&)>& counts = nullptr) {
  for (size_t k = 0; k < values.size(); ++k) {
    if (counts && !counts(values[k])) continue;
    for (size_t j = 0; j < k; ++j) {
      if (values[j] == values[k]) {
        throw std::invalid_argument(option + ": '" + values[k] + "' is given twice (entries " +
                                    std::to_string(j + 1) + " and " + std::to_string(k + 1) + ")");
      }
    }
  }
}

// A display output that is a device (a monitor), which two projectors cannot share.
bool IsMonitor(const std::string& display) { return display.starts_with("glfw:"); }

// `options` holds what PlayOptions::Declare declared (--osc, --osc-allow); the rest is copied from
// `args`.
void RunPlayCommand(const PlayArguments& args, PlayOptions options) {
  options.scene = args.scene;
  options.rig_dir = args.rig;
  options.desired = args.desired;
  options.solution = args.solution;
  options.setup_timeout_s = args.setup_timeout;
  options.out = args.out;
  options.fps = args.fps;
  options.frames = args.frames;
  options.patches = args.patches;
  options.alpha = args.alpha;
  ParseMethod(args.method, &options.solver.method);
  ParseMetricUpdate(args.metric_update, &options.solver.metric_update);
  options.solver.function_tolerance = args.tolerance;
  ParseDevice(args.device, &options.solver.device);
  if (!ParseDither(args.dither, &options.dither))
    throw std::invalid_argument("--dither: unknown method " + args.dither);
  options.light = args.light;
  options.frame_timeout_s = 1e-3 * args.frame_timeout_ms;
  options.local_gpu = args.render == "gpu";
  std::vector<std::string> names, endpoints;
  for (size_t k = 0; k < args.nodes.size(); ++k) {
    options.nodes.push_back(ParseNodeAddress(args.nodes[k], int(k)));
    names.push_back(options.nodes.back().name);
    endpoints.push_back(options.nodes.back().endpoint);
  }
  CheckUnique(names, "--nodes");
  CheckUnique(endpoints, "--nodes");
  CheckUnique(args.display, "--display", IsMonitor);
  if (options.nodes.empty()) options.local_outputs = MakeNodeOutputs(args.display);
  options.progress = PrintProgress();
  options.stop = &StopOnSignals();
  const PlaySummary summary = RunPlay(options);
  if (summary.stopped && summary.frames.empty()) {
    std::cout << fmt::format(
        "play: stopped by a signal before the first frame; nothing written "
        "to {}\n",
        args.out);
  } else {
    std::cout << fmt::format(
        "play: {}{} frames shown, {} dropped in {:.1f} s; wrote {}/result.json\n",
        !summary.stopped       ? ""
        : options.stop->load() ? "stopped by a signal: "
                               : "stopped by /procam/stop: ",
        summary.frames.size(), summary.dropped, summary.seconds, args.out);
  }
}

}  // namespace

void AddNodeCommands(CLI::App& app) {
  auto keys_rig = std::make_shared<std::string>();
  auto keys_replace = std::make_shared<bool>(false);
  CLI::App* keys =
      app.add_subcommand("keys", "Make the rig's CURVE keys for its controller and display nodes");
  keys->add_option("--rig", *keys_rig, "Rig directory (keys go into RIG_DIR/keys/)")->required();
  keys->add_flag("--replace", *keys_replace, "Replace existing keys (nodes must get the new ones)");
  keys->callback([keys_rig, keys_replace] {
    const RigKeys made = MakeRigKeys(*keys_rig, *keys_replace);
    std::cout
        << "wrote " << *keys_rig << "/keys/: controller.key, controller.pub, node.key, node.pub\n"
        << "controller public key " << made.controller.public_key << "\nnode public key "
        << made.node.public_key
        << "\ndisplay PCs need node.key, node.pub, controller.pub; the controller controller.key, "
           "controller.pub, node.pub\n";
  });

  CLI::App* node = app.add_subcommand(
      "node", "Run a display node: show the frames a controller sends on this PC's projectors");
  const auto node_options = AddDeclaredOptions<NodeOptions>(node);
  node->callback([node_options] {
    NodeOptions& options = *node_options;
    CheckUnique(options.projectors, "--projectors");
    CheckUnique(options.display, "--display", IsMonitor);
    // inproc:// endpoints are for nodes run inside the controller's process (tests); another
    // process could never reach this one.
    if (!options.listen.starts_with("tcp://")) {
      throw std::invalid_argument("--listen: " + options.listen +
                                  ": a node listens at tcp://ADDRESS:PORT (another process cannot "
                                  "reach any other endpoint)");
    }
    CheckTcpPort(options.listen, /*bind=*/true, "--listen");
    // The room is read when the controller's setup arrives; a file that cannot be read is said
    // now, not minutes later on the controller.
    LoadSceneArgument(options.scene);
    options.log = [](const std::string& line) { std::cout << line << std::endl; };
    std::atomic<bool>& stop = StopOnSignals();
    zmq::context_t context;
    RunNode(context, options, MakeNodeOutputs(options.display), stop);
    if (stop) std::cout << "node " << options.name << ": stopped by a signal" << std::endl;
  });

  auto play_args = std::make_shared<PlayArguments>();
  CLI::App* play = app.add_subcommand(
      "play", "Light that follows changing content: solve, send and show every frame");
  play->add_option("scene", play_args->scene, "The room (scene file)")->required();
  play->add_option("--rig", play_args->rig, "Rig directory (projectors, registered camera, keys)")
      ->required();
  play->add_option(
      "--desired", play_args->desired,
      "The desired appearance as the rig's camera sees the room: a directory of "
      "images, a video, or "
      "stdin:WIDTHxHEIGHT (raw rgb24 frames on standard input, the newest shown), or camera:URI "
      "(a capture device, e.g. camera:v4l2:/dev/video2; procam cameras lists them)");
  play->add_option(
      "--solution", play_args->solution,
      "Instead of --desired: show a compensation solution's emittance (procam compensate --out) "
      "as every frame");
  play->add_option("--out", play_args->out, "Output directory (result.json with per-frame timings)")
      ->required();
  play->add_option("--nodes", play_args->nodes,
                   "Display nodes NAME=tcp://HOST:PORT,...; none: a node in this process")
      ->delimiter(',');
  play->add_option("--display", play_args->display,
                   "Without --nodes, per projector: glfw:MONITOR, record:DIR or memory")
      ->delimiter(',')
      ->capture_default_str();
  play->add_option("--fps", play_args->fps,
                   "Target frame rate (frames due while one is shown are dropped)")
      ->check(FiniteRange(0.01, 1000.0))
      ->capture_default_str();
  play->add_option("--frames", play_args->frames, "Frames to play (0: the whole source)")
      ->check(FiniteNonNegative());
  play->add_option("--patches", play_args->patches, "Target patch count (0: the room's)")
      ->check(FiniteNonNegative());
  play->add_option("--method", play_args->method,
                   "naive | reverse | linear | perceptual | perceptual2000")
      ->check(CLI::IsMember({"naive", "reverse", "linear", "perceptual", "perceptual2000"}))
      ->capture_default_str();
  play->add_option("--metric-update", play_args->metric_update,
                   "perceptual2000: CIEDE2000's metric measured again at every_iteration | rounds "
                   "(docs/solver.md)")
      ->check(CLI::IsMember({"every_iteration", "rounds"}))
      ->capture_default_str();
  play->add_option("--device", play_args->device, "cpu | cuda")
      ->check(CLI::IsMember({"cpu", "cuda"}))
      ->capture_default_str();
  AddPlayToleranceOption(play, &play_args->tolerance);
  play->add_option("--alpha", play_args->alpha, "Weight of the absolute term, (0,1]")
      ->check(FiniteRange(1e-9, 1.0));
  play->add_option("--dither", play_args->dither, "none | ordered | error-diffusion")
      ->capture_default_str();
  AddLightOption(play, &play_args->light);
  play->add_option("--render", play_args->render,
                   "Without --nodes: gpu (the node's images rendered with OpenGL) | cpu (the "
                   "reference renderer)")
      ->check(CLI::IsMember({"gpu", "cpu"}))
      ->capture_default_str();
  play->add_option(
          "--frame-timeout-ms", play_args->frame_timeout_ms,
          "A node that does not answer a frame in this time is reported lost; the others go on")
      ->check(FiniteRange(1.0, 60000.0))
      ->capture_default_str();
  play->add_option("--setup-timeout", play_args->setup_timeout,
                   "Seconds for every node to answer and build the rig before the first frame")
      ->check(FiniteRange(0.1, 3600.0))
      ->capture_default_str();
  const auto play_options = AddDeclaredOptions<PlayOptions>(play);
  play->callback([play_args, play_options] {
    CheckOutputDirectory(play_args->out, DirectoryKind::kShow);
    RegisterDeviceBackends();  // --desired camera:v4l2:..., camera:aravis:...
    RunPlayCommand(*play_args, *play_options);
  });
}

}  // namespace procam
