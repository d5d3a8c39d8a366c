#pragma once
// A display node (`procam node`): owns the projectors attached to one display PC — their
// monitors, and the pixel maps, blending weights and photometry of the rig — and shows the
// frames a controller sends it (nodes/messages.h for the protocol and the frame barrier).
//
// At start the node reads the rig directory (the projectors it shows must be in rig.json) and
// opens its outputs. A controller's kSetup names the patch subdivision and the render options;
// the node subdivides its copy of the room (the scene file) the same way, checks that it gives
// the controller's patch count, applies the rig's reflectance, and casts every projector's rays
// (BuildProjectionRig: the maps of all projectors, since the blending weights and the level of
// every patch depend on all of them). Each kFrame's per-patch emittance is then rendered into
// its outputs' back buffers — on the GPU (the frame's per-patch plan once, then each output's
// shader: projection/gl_renderer.h, within one code step of the CPU's) or with the CPU renderer
// `procam project` uses (the same images, byte for byte) — and shown at kPresent.
// A monitor that disappears is reported to the controller (kFailed) and the node goes on with
// the others.

#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>
#include <zmq.hpp>

#include "base/option_table.h"
#include "projection/frame_plan.h"
#include "projection/projector.h"
#include "projection/projector_images.h"

namespace procam {

// Where a node's projector image goes.
class NodeOutput {
 public:
  virtual ~NodeOutput() = default;
  virtual std::string Describe() const = 0;  // e.g. "glfw:HDMI-1" or "record:DIR/left.png"
  // Puts the image into the back buffer (nothing visible changes). The image's buffer is the
  // node's and is shaded into again next frame: an output that keeps the image copies it.
  virtual void Draw(const ProjectorImage& image) = 0;
  // Shows what Draw (or DrawPlan) put there.
  virtual void Present(uint64_t frame) = 0;
  // Outputs that render on the GPU: told the rig's planner and their projector's index once per
  // setup (true: this output renders plans itself from now on), then drawn from each frame's
  // plan. The others get CPU images through Draw.
  virtual bool PrepareGpu(const FramePlanner& /*planner*/, int /*projector*/) { return false; }
  virtual void DrawPlan(const FramePlan& /*plan*/) {}
  // "" while the output works; else one line saying why not (e.g. its monitor is gone).
  virtual std::string Fault() { return ""; }
};

// An output that keeps the last presented image (for tests) and, when `path` is given, writes it
// there as PNG (atomically) at every Present.
class RecordOutput : public NodeOutput {
 public:
  explicit RecordOutput(std::filesystem::path path = {}) : path_(std::move(path)) {}
  std::string Describe() const override;
  void Draw(const ProjectorImage& image) override {  // a copy: the node shades into its buffer
    drawn_.bits = image.bits;
    drawn_.codes = image.codes.clone();
  }
  void Present(uint64_t frame) override;
  const ProjectorImage& presented() const { return presented_; }
  uint64_t frames() const { return frames_; }

 private:
  std::filesystem::path path_;
  ProjectorImage drawn_, presented_;
  uint64_t frames_ = 0;
};

struct NodeOptions {
  std::string name = "node";
  std::filesystem::path rig_dir;
  std::string scene;                    // the room (LoadSceneArgument), as the controller's
  std::vector<std::string> projectors;  // names in rig.json this node shows, in output order
  // Per projector, the output it is shown on: glfw:MONITOR, record:DIR or memory
  // (MakeNodeOutputs, nodes/outputs.h); the caller makes RunNode's outputs from it.
  std::vector<std::string> display = {"memory"};
  std::string listen = "tcp://*:5600";  // tcp://ADDRESS:PORT, or inproc://NAME (no keys)
  double max_seconds = 0.0;             // > 0: return after this long (tests, timed shows), >= 0
  std::function<void(const std::string&)> log;  // a line per event (setup, faults, refusals)
  // Render on the GPU where the outputs can (PrepareGpu) and the render options allow (not
  // detail or error diffusion: then the CPU renderer); false: the CPU renderer everywhere.
  bool gpu = true;

  // Declares --rig, --scene, --projectors, --display, --listen, --name, --render and --seconds
  // in `table`, bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
};

// Makes the outputs, one per projector of `projectors` (the node's, in order).
using NodeOutputFactory =
    std::function<std::vector<std::unique_ptr<NodeOutput>>(const std::vector<Projector>&)>;

// Runs a node until `stop` is set (checked every 100 ms) or a controller sends kStop with
// {"exit": true}. Throws IoError naming the file, projector or endpoint when it cannot start
// (no such projector in the rig, keys missing, the port taken); once running, faults are
// reported to the controller and logged, never thrown.
void RunNode(zmq::context_t& context, const NodeOptions& options, const NodeOutputFactory& outputs,
             const std::atomic<bool>& stop);

}  // namespace procam
