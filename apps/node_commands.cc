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

// `options` as PlayOptions::Declare parsed them; the local outputs, progress and stop added.
void RunPlayCommand(PlayOptions options) {
  std::vector<std::string> names, endpoints;
  for (const NodeAddress& node : options.nodes) {
    names.push_back(node.name);
    endpoints.push_back(node.endpoint);
  }
  CheckUnique(names, "--nodes");
  CheckUnique(endpoints, "--nodes");
  CheckUnique(options.display, "--display", IsMonitor);
  if (options.nodes.empty()) options.local_outputs = MakeNodeOutputs(options.display);
  options.progress = PrintProgress();
  options.stop = &StopOnSignals();
  const PlaySummary summary = RunPlay(options);
  if (summary.stopped && summary.frames.empty()) {
    std::cout << fmt::format(
        "play: stopped by a signal before the first frame; nothing written "
        "to {}\n",
        options.out.string());
  } else {
    std::cout << fmt::format(
        "play: {}{} frames shown, {} dropped in {:.1f} s; wrote {}/result.json\n",
        !summary.stopped       ? ""
        : options.stop->load() ? "stopped by a signal: "
                               : "stopped by /procam/stop: ",
        summary.frames.size(), summary.dropped, summary.seconds, options.out.string());
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

  CLI::App* play = app.add_subcommand(
      "play", "Light that follows changing content: solve, send and show every frame");
  const auto play_options = AddDeclaredOptions<PlayOptions>(play);
  play->callback([play_options] {
    CheckOutputDirectory(play_options->out, DirectoryKind::kShow);
    RegisterDeviceBackends();  // --desired camera:v4l2:..., camera:aravis:...
    RunPlayCommand(*play_options);
  });
}

}  // namespace procam
