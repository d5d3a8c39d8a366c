#pragma once
// The controller's side of the display nodes: sets every node up, sends each frame through the
// frame barrier (nodes/messages.h), measures how far apart the nodes present it, and keeps the
// show going when a node fails.
//
// Node states: joining (pinged every 200 ms until it answers) → setting up (kSetup sent; the
// node casts its rays) → live (takes part in every frame) → lost (missed a deadline, or its
// connection dropped) → joining again. A live node that does not answer a frame within
// `frame_timeout_s` is reported lost at once (one line naming it and how long it has been
// silent) and the frame is shown by the others; a lost node that answers a ping again is set up
// and rejoins at the next frame.

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>
#include <zmq.hpp>

#include "nodes/transport.h"

namespace procam {

struct NodeAddress {
  std::string name;      // for messages and result.json
  std::string endpoint;  // tcp://HOST:PORT, or inproc://NAME for a node in this process
};
// "name=tcp://host:port" or "tcp://host:port" (named nodeN). Throws std::invalid_argument.
NodeAddress ParseNodeAddress(const std::string& text, int index);

struct ControllerOptions {
  // kSetup's body: "setup" (an id), "target_patches", "patches", "light", "dither", "feather".
  nlohmann::json setup;
  double setup_timeout_s = 120.0;  // every node set up at Connect, or it fails naming the node
  double frame_timeout_s = 0.5;    // a live node's kReady and kPresented, each, > 0
  std::function<void(const std::string&)> log;
  // Checked while Connect waits: true ends it with an IoError (e.g. the in-process node failed).
  std::function<bool()> cancelled;
};

// One node's part in a frame.
struct NodeFrame {
  std::string state;         // "shown", "lost" (this frame), "absent" (lost before it)
  double ready_ms = 0.0;     // kFrame sent → its kReady
  double render_ms = 0.0;    // what it reported rendering took
  int64_t presented_ns = 0;  // its swap (system clock)
};

struct FrameReport {
  uint64_t frame = 0;
  double ready_ms = 0.0;         // kFrame sent → the last live node ready
  double present_ms = 0.0;       // kPresent sent → the last kPresented
  double skew_ms = 0.0;          // latest − earliest presentation among the nodes that showed it
  int shown = 0;                 // nodes that showed it
  std::vector<NodeFrame> nodes;  // in the controller's node order
};

class Controller {
 public:
  // No keys: every endpoint must be inproc://.
  Controller(zmq::context_t& context, std::vector<NodeAddress> nodes, const RigKeys* keys,
             ControllerOptions options);
  ~Controller();

  // Waits until every node has answered and built the rig. Throws IoError naming the first node
  // that did not within setup_timeout_s (unreachable, refused us, or its setup error).
  void Connect();
  // Frame `frame` (numbers increase) with per-patch emittance (n,3) through the barrier.
  FrameReport Show(uint64_t frame, const Eigen::MatrixX3d& emittance);
  // Tells every node the show is over (`exit`: in-process nodes return from RunNode).
  void Stop(bool exit = false);

  int live() const;
  const std::vector<NodeAddress>& nodes() const;

 private:
  struct Node;
  void Pump(int timeout_ms);
  void Handle(Node& node, const Message& message);
  void Service();
  void Lose(Node& node, const std::string& why);
  void Log(const std::string& line) const;

  std::vector<std::unique_ptr<Node>> nodes_;
  std::vector<NodeAddress> addresses_;
  ControllerOptions options_;
  uint64_t current_frame_ = 0;
  uint64_t next_request_ = 1;
};

}  // namespace procam
