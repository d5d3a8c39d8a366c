#include "nodes/node.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <limits>
#include <optional>

#include "base/io.h"
#include "base/timing.h"
#include "geometry/patches.h"
#include "geometry/stage.h"
#include "nodes/messages.h"
#include "nodes/transport.h"
#include "projection/calibrated_room.h"
#include "projection/projection_rig.h"
#include "projection/rig_directory.h"

namespace procam {
namespace {

// What a kSetup asks for, and the rig built for it.
struct NodeSetup {
  std::string id;
  int target_patches = 0, patches = 0;
  RenderOptions render;
  double feather = 0.1;
  ProjectionRig rig;
  std::unique_ptr<FramePlanner> planner;  // refers to rig; null for detail (no frame plans)
  std::vector<bool> gpu;                  // per output: renders plans itself
  // The CPU's images of the last frame: their buffers are shaded into again (outputs copy what
  // they keep).
  std::vector<ProjectorImage> images;
};

// Reads a kSetup's body into *setup (not the rig). Throws std::invalid_argument naming the key.
void ParseSetup(const nlohmann::json& body, NodeSetup* setup) {
  auto need = [&](const char* key) -> const nlohmann::json& {
    if (!body.contains(key)) throw std::invalid_argument(std::string("setup: no \"") + key + "\"");
    return body.at(key);
  };
  const nlohmann::json& id = need("setup");
  const nlohmann::json& target = need("target_patches");
  const nlohmann::json& patches = need("patches");
  if (!id.is_string() || id.get<std::string>().size() > 256)
    throw std::invalid_argument("setup: \"setup\" must be a string");
  if (!target.is_number_integer() || target.get<long long>() < 4 ||
      target.get<long long>() > kMaxFramePatches)
    throw std::invalid_argument("setup: \"target_patches\" must be an integer in [4, " +
                                std::to_string(kMaxFramePatches) + "]");
  if (!patches.is_number_integer() || patches.get<long long>() < 1 ||
      patches.get<long long>() > kMaxFramePatches)
    throw std::invalid_argument("setup: \"patches\" must be an integer in [1, " +
                                std::to_string(kMaxFramePatches) + "]");
  setup->id = id.get<std::string>();
  setup->target_patches = target.get<int>();
  setup->patches = patches.get<int>();
  if (body.contains("dither")) {
    if (!body["dither"].is_string() ||
        !ParseDither(body["dither"].get<std::string>(), &setup->render.dither))
      throw std::invalid_argument("setup: \"dither\" must be none, ordered or error-diffusion");
  }
  if (body.contains("light")) {
    if (!body["light"].is_string() ||
        !ParseLightField(body["light"].get<std::string>(), &setup->render.light))
      throw std::invalid_argument("setup: \"light\" must be smooth or flat");
  }
  if (body.contains("feather")) {
    if (!body["feather"].is_number() ||
        !(body["feather"].get<double>() > 0.0 && body["feather"].get<double>() <= 0.5))
      throw std::invalid_argument("setup: \"feather\" must be a number in (0, 0.5]");
    setup->feather = body["feather"].get<double>();
  }
}

class Node {
 public:
  Node(zmq::context_t& context, const NodeOptions& options, const NodeOutputFactory& make_outputs)
      : options_(options), rig_dir_(ReadRigDirectory(options.rig_dir)) {
    if (options.projectors.empty())
      throw IoError("node " + options.name + ": no projectors to show (--projectors)");
    for (const std::string& name : options.projectors) {
      int found = -1;
      for (size_t k = 0; k < rig_dir_.projectors.size(); ++k) {
        if (rig_dir_.projectors[k].name == name) found = static_cast<int>(k);
      }
      if (found < 0) {
        std::string names;
        for (const Projector& p : rig_dir_.projectors)
          names += (names.empty() ? "" : ", ") + p.name;
        throw IoError((options.rig_dir / "rig.json").string() + ": no projector '" + name +
                      "' (the rig has " + names + ")");
      }
      own_.push_back(found);
      own_projectors_.push_back(rig_dir_.projectors[found]);
    }
    outputs_ = make_outputs(own_projectors_);
    if (outputs_.size() != own_.size())
      throw IoError("node " + options.name + ": one output per projector needed");
    faulty_.assign(outputs_.size(), false);
    const bool local = options.listen.starts_with("inproc://");
    std::optional<RigKeys> keys;
    if (!local) keys = ReadRigKeys(options.rig_dir, KeyRole::kNode);
    socket_ =
        std::make_unique<NodeSocket>(context, options.listen, keys ? &*keys : nullptr, options.log);
    Log(fmt::format("node {}: listening at {}, showing {}", options.name, socket_->endpoint(),
                    Describe()));
  }

  // Returns when `stop` is set or a controller asked the node to exit.
  void Run(const std::atomic<bool>& stop) {
    const auto start = Clock::now();
    while (!stop && !exit_) {
      if (options_.max_seconds > 0.0 && SecondsSince(start) > options_.max_seconds) {
        Log(fmt::format("node {}: ran its {:.0f} s", options_.name, options_.max_seconds));
        return;
      }
      CheckOutputs();
      std::optional<Envelope> envelope = socket_->Receive(100);
      if (!envelope || !Admit(*envelope)) continue;
      peer_ = envelope->peer;
      try {
        Handle(envelope->message);
      } catch (const std::exception& e) {  // a frame it cannot render: say so, go on
        Fail(envelope->message.sequence, e.what());
      }
    }
  }

 private:
  // One controller at a time. The first one heard is served until it ends the show (kStop) or
  // its connection is gone; a message from another one meanwhile is refused: logged (at the rate
  // of the socket's refusals) naming both, and answered with a kFailed marked "busy", which ends
  // that controller's setup with one line. A node in the controller's process has one controller.
  bool Admit(const Envelope& envelope) {
    if (envelope.address.empty()) return true;  // in-process
    if (!controller_.empty() && envelope.peer != controller_ && ControllerStillThere()) {
      const std::string why = fmt::format(
          "serves the controller at {}, one controller at a time; the controller at "
          "{} is refused",
          controller_address_, envelope.address);
      socket_->Refuse(envelope.address,
                      fmt::format("node {}: refused a second controller at {}: "
                                  "it serves the controller at {}",
                                  options_.name, envelope.address, controller_address_));
      Message refusal;
      refusal.type = MessageType::kFailed;
      refusal.sequence = envelope.message.sequence;
      refusal.body = {{"node", options_.name}, {"error", why}, {"busy", true}};
      socket_->Send(envelope.peer, refusal);
      return false;
    }
    if (envelope.peer != controller_) controller_address_ = envelope.address;
    controller_ = envelope.peer;
    return true;
  }

  // Whether the controller served is still connected: ZeroMQ's router refuses a message to a
  // routing id whose connection is gone (router_mandatory), once the messages it had received
  // from it are read, so the node asks by sending it its status (a kPong, which a controller
  // takes at any time). A controller reconnecting (its heartbeats timed out while the node was
  // frozen) comes back under a new routing id: the old one is gone.
  bool ControllerStillThere() {
    Message status;
    status.type = MessageType::kPong;
    status.sequence = 0;
    status.body = Status();
    return socket_->Send(controller_, status);
  }

  std::string Describe() const {
    std::string text;
    for (size_t k = 0; k < outputs_.size(); ++k)
      text += (k ? ", " : "") + own_projectors_[k].name + " on " + outputs_[k]->Describe();
    return text;
  }

  void Handle(const Message& message) {
    switch (message.type) {
      case MessageType::kPing:
        Reply(MessageType::kPong, message.sequence, Status());
        break;
      case MessageType::kSetup:
        SetUp(message);
        break;
      case MessageType::kFrame:
        Render(message);
        break;
      case MessageType::kPresent:
        Present(message.sequence);
        break;
      case MessageType::kStop:
        rendered_.reset();
        controller_.clear();  // another controller may be served now
        Log(fmt::format("node {}: stopped by the controller", options_.name));
        exit_ = message.body.is_object() && message.body.value("exit", false);
        break;
      default:
        Fail(message.sequence, std::string("unexpected message '") + MessageTypeName(message.type) +
                                   "' from the controller");
    }
  }

  nlohmann::json Status() const {
    nlohmann::json status = {{"node", options_.name},
                             {"setup", setup_ ? setup_->id : ""},
                             {"render", setup_ && setup_->planner ? "gpu" : "cpu"}};
    for (size_t k = 0; k < outputs_.size(); ++k)
      status["projectors"].push_back(
          {{"name", own_projectors_[k].name}, {"output", outputs_[k]->Describe()}});
    return status;
  }

  void SetUp(const Message& message) {
    const auto start = Clock::now();
    auto setup = std::make_unique<NodeSetup>();
    nlohmann::json done = {{"node", options_.name}};
    try {
      ParseSetup(message.body, setup.get());
      done["setup"] = setup->id;
      if (setup_ && setup_->id == setup->id) {  // already built (a controller reconnecting)
        done["patches"] = setup_->patches;
        Reply(MessageType::kSetupDone, message.sequence, done);
        return;
      }
      Log(fmt::format("node {}: setting up {} patches (target {})", options_.name, setup->patches,
                      setup->target_patches));
      CalibratedRoomOptions room_options;
      room_options.scene = options_.scene;
      room_options.rig_dir = options_.rig_dir;
      room_options.patches = setup->target_patches;
      room_options.expected_patches = setup->patches;  // the controller's count
      room_options.form_factors = false;               // a node renders, it does not solve
      room_options.problem = false;
      room_options.projection.feather = setup->feather;
      room_options.reflectance_maps = false;  // as the controller's frames (play.cc)
      RoomSources sources;
      sources.rig = rig_dir_;
      setup->rig = BuildCalibratedRoom(room_options, std::move(sources)).projection;
      PrepareOutputs(setup.get());
      setup_ = std::move(setup);
      rendered_.reset();
      done["patches"] = setup_->patches;
      done["seconds"] = SecondsSince(start);
      Log(fmt::format("node {}: set up in {:.1f} s", options_.name, SecondsSince(start)));
    } catch (const std::exception& e) {
      done["error"] = e.what();
      Log(fmt::format("node {}: setup failed: {}", options_.name, e.what()));
    }
    Reply(MessageType::kSetupDone, message.sequence, done);
  }

  // A frame planner for the rig (the static part of every frame's rendering, made once), and the
  // GPU for the outputs where the options and outputs allow. Detail has no frame plans: then
  // every frame renders from scratch on the CPU.
  void PrepareOutputs(NodeSetup* setup) {
    setup->gpu.assign(outputs_.size(), false);
    try {
      setup->planner = std::make_unique<FramePlanner>(setup->rig, setup->render);
    } catch (const std::invalid_argument& e) {
      Log(fmt::format("node {}: rendering on the CPU without frame plans: {}", options_.name,
                      e.what()));
      return;
    }
    int on_gpu = 0;
    for (size_t k = 0; k < outputs_.size() && options_.gpu; ++k) {
      try {
        setup->gpu[k] = outputs_[k]->PrepareGpu(*setup->planner, own_[k]);
      } catch (const std::invalid_argument& e) {  // error diffusion: the CPU renders
        Log(fmt::format("node {}: rendering on the CPU: {}", options_.name, e.what()));
        setup->gpu[k] = false;
      }
      on_gpu += setup->gpu[k];
    }
    if (options_.gpu) {
      Log(fmt::format("node {}: {} of {} projector(s) rendered on the GPU", options_.name, on_gpu,
                      outputs_.size()));
    }
    // The CPU shades the others frame after frame: their seamless bumps are kept.
    std::vector<char> on_cpu(setup->rig.projectors.size(), 0);
    for (size_t k = 0; k < outputs_.size(); ++k) on_cpu[own_[k]] = !setup->gpu[k];
    if (std::find(on_cpu.begin(), on_cpu.end(), 1) != on_cpu.end())
      setup->planner->CacheBumps(&on_cpu);
  }

  void Render(const Message& message) {
    if (!setup_) return Fail(message.sequence, "frame before setup");
    const int n = setup_->rig.size();
    if (static_cast<int>(message.emittance.size()) != 3 * n) {
      return Fail(message.sequence, fmt::format("frame of {} patches, the rig has {}",
                                                message.emittance.size() / 3, n));
    }
    const auto start = Clock::now();
    const Eigen::MatrixX3d emittance = FrameEmittance(message);
    const bool cpu_outputs =
        std::find(setup_->gpu.begin(), setup_->gpu.end(), false) != setup_->gpu.end();
    const long on_gpu = std::count(setup_->gpu.begin(), setup_->gpu.end(), true);
    std::vector<ProjectorImage>& images = setup_->images;
    double plan_ms = 0.0;
    if (setup_->planner) {
      const FramePlan plan = setup_->planner->Plan(emittance);
      plan_ms = 1e3 * SecondsSince(start);
      for (size_t k = 0; k < outputs_.size(); ++k) {
        if (setup_->gpu[k]) Use(k, message.sequence, [&] { outputs_[k]->DrawPlan(plan); });
      }
      if (cpu_outputs) {
        // Only this node's projectors (those not on the GPU).
        std::vector<int> shade;
        for (size_t k = 0; k < outputs_.size(); ++k) {
          if (!setup_->gpu[k]) shade.push_back(own_[k]);
        }
        ShadeProjectorImages(*setup_->planner, plan, nullptr, shade, &images);
      }
    } else {
      RenderSummary summary;
      images = RenderProjectorImages(setup_->rig, emittance, setup_->render, &summary);
    }
    for (size_t k = 0; k < outputs_.size(); ++k) {
      if (!setup_->gpu[k]) Use(k, message.sequence, [&] { outputs_[k]->Draw(images[own_[k]]); });
    }
    rendered_ = message.sequence;
    Reply(MessageType::kReady, message.sequence,
          {{"node", options_.name},
           {"render_ms", 1e3 * SecondsSince(start)},
           {"plan_ms", plan_ms},
           {"render", !cpu_outputs ? "gpu" : on_gpu > 0 ? "gpu+cpu" : "cpu"}});
  }

  void Present(uint64_t frame) {
    if (!rendered_ || *rendered_ != frame) {
      return Fail(frame, fmt::format("present of frame {} that was not rendered", frame));
    }
    const auto start = Clock::now();
    for (size_t k = 0; k < outputs_.size(); ++k)
      Use(k, frame, [&] { outputs_[k]->Present(frame); });
    Message presented;
    presented.type = MessageType::kPresented;
    presented.sequence = frame;
    presented.presented_ns = SystemNowNs();
    presented.body = {{"node", options_.name}, {"present_ms", 1e3 * SecondsSince(start)}};
    socket_->Send(peer_, presented);
  }

  // An output that stops working is reported once and skipped from then on: found between
  // frames (Fault), or by a draw or a present that throws (a monitor unplugged in between), which
  // then leaves the node's other outputs and its answer to the controller as they are.
  void CheckOutputs() {
    for (size_t k = 0; k < outputs_.size(); ++k) {
      if (faulty_[k]) continue;
      const std::string fault = outputs_[k]->Fault();
      if (!fault.empty()) MarkFaulty(k, rendered_.value_or(0), fault);
    }
  }
  template <typename Action>
  void Use(size_t k, uint64_t sequence, Action action) {
    if (faulty_[k]) return;
    try {
      action();
    } catch (const std::exception& e) {
      MarkFaulty(k, sequence, e.what());
    }
  }
  void MarkFaulty(size_t k, uint64_t sequence, const std::string& fault) {
    faulty_[k] = true;
    Fail(sequence, fmt::format("projector {}: {}", own_projectors_[k].name, fault));
  }

  void Fail(uint64_t sequence, const std::string& why) {
    Log(fmt::format("node {}: {}", options_.name, why));
    if (!peer_.empty())
      Reply(MessageType::kFailed, sequence, {{"node", options_.name}, {"error", why}});
  }

  void Reply(MessageType type, uint64_t sequence, nlohmann::json body) {
    Message message;
    message.type = type;
    message.sequence = sequence;
    message.body = std::move(body);
    socket_->Send(peer_, message);
  }

  void Log(const std::string& line) const {
    if (options_.log) options_.log(line);
  }

  NodeOptions options_;
  RigDirectory rig_dir_;
  std::vector<int> own_;  // the rig's index of each projector this node shows
  std::vector<Projector> own_projectors_;
  std::vector<std::unique_ptr<NodeOutput>> outputs_;
  std::vector<bool> faulty_;
  std::unique_ptr<NodeSocket> socket_;
  std::unique_ptr<NodeSetup> setup_;
  std::optional<uint64_t> rendered_;  // the frame in the back buffers
  std::string peer_;                  // the controller (the last peer heard)
  // The controller served over the network (Admit): its routing id ("" while none is) and
  // address.
  std::string controller_;
  std::string controller_address_;
  bool exit_ = false;
};

}  // namespace

std::string RecordOutput::Describe() const {
  return path_.empty() ? "memory" : "record:" + path_.string();
}

void RecordOutput::Present(uint64_t) {
  presented_ = drawn_;
  ++frames_;
  if (!path_.empty() && !presented_.codes.empty()) WriteProjectorImage(path_, presented_);
}

void NodeOptions::Declare(OptionTable* table) {
  table->Path("rig", &rig_dir, "the rig directory (rig.json, the projectors' models, keys/)")
      .Required()
      .Text("scene", &scene, "the room (scene file), as the controller's")
      .Required()
      .Texts("projectors", &projectors,
             "projectors of the rig this node shows, in the displays' order")
      .Required()
      .Texts("display", &display,
             "per projector: glfw:MONITOR, record:DIR (DIR/NAME.png every frame) or memory")
      .Text("listen", &listen, "endpoint to listen at (tcp://ADDRESS:PORT)")
      .Text("name", &name, "the node's name in logs")
      .Choice<bool>("render", &gpu, {{"gpu", true}, {"cpu", false}},
                    "gpu: each output's images rendered on the GPU (OpenGL); cpu: the reference "
                    "renderer")
      .Number("seconds", &max_seconds,
              OptionTable::Interval::Closed(0.0, std::numeric_limits<double>::max()), "s",
              "run at most this long (0: until interrupted)");
}

void RunNode(zmq::context_t& context, const NodeOptions& options, const NodeOutputFactory& outputs,
             const std::atomic<bool>& stop) {
  Node node(context, options, outputs);
  node.Run(stop);
}

}  // namespace procam
