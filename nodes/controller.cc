#include "nodes/controller.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <stdexcept>

#include "base/io.h"
#include "base/timing.h"

namespace procam {
namespace {

constexpr double kPingIntervalS = 0.2;

}  // namespace

NodeAddress ParseNodeAddress(const std::string& text, int index) {
  NodeAddress address;
  const size_t equals = text.find('=');
  address.name =
      equals == std::string::npos ? "node" + std::to_string(index) : text.substr(0, equals);
  address.endpoint = equals == std::string::npos ? text : text.substr(equals + 1);
  if (address.name.empty() || address.endpoint.empty() ||
      !(address.endpoint.starts_with("tcp://") || address.endpoint.starts_with("inproc://"))) {
    throw std::invalid_argument("--nodes: '" + text + "' is not NAME=tcp://HOST:PORT");
  }
  CheckTcpPort(address.endpoint, /*bind=*/false, "--nodes " + address.name);
  return address;
}

struct Controller::Node {
  enum class State { kJoining, kSettingUp, kLive };
  NodeAddress address;
  std::unique_ptr<ControllerSocket> socket;
  State state = State::kJoining;
  bool ever_live = false;
  Clock::time_point last_heard = Clock::now(), last_ping = Clock::now() - std::chrono::hours(1);
  std::string error;  // its setup's error
  // The current frame: whether it takes part (live when the frame was sent), and its answers.
  bool in_frame = false, ready = false, presented = false;
  double ready_ms = 0.0, render_ms = 0.0;
  int64_t presented_ns = 0;
};

Controller::Controller(zmq::context_t& context, std::vector<NodeAddress> nodes, const RigKeys* keys,
                       ControllerOptions options)
    : addresses_(std::move(nodes)), options_(std::move(options)) {
  if (addresses_.empty()) throw std::invalid_argument("controller: no nodes");
  if (!(options_.frame_timeout_s > 0.0))
    throw std::invalid_argument("controller: frame timeout must be > 0");
  for (const NodeAddress& address : addresses_) {
    auto node = std::make_unique<Node>();
    node->address = address;
    node->socket = std::make_unique<ControllerSocket>(context, address.endpoint, keys);
    nodes_.push_back(std::move(node));
  }
}

Controller::~Controller() = default;

const std::vector<NodeAddress>& Controller::nodes() const { return addresses_; }

int Controller::live() const {
  return static_cast<int>(std::count_if(nodes_.begin(), nodes_.end(), [](const auto& node) {
    return node->state == Node::State::kLive;
  }));
}

void Controller::Log(const std::string& line) const {
  if (options_.log) options_.log(line);
}

void Controller::Lose(Node& node, const std::string& why) {
  if (node.state != Node::State::kLive) return;
  node.state = Node::State::kJoining;
  Log(
      fmt::format("controller: node {} ({}) lost at frame {}: {}; last heard {:.0f} ms ago; {} "
                  "other node(s) go on",
                  node.address.name, node.address.endpoint, current_frame_, why,
                  MsSince(node.last_heard), live()));
}

void Controller::Handle(Node& node, const Message& message) {
  node.last_heard = Clock::now();
  switch (message.type) {
    case MessageType::kPong:
      // A node being set up that answers without our setup has restarted since it was sent
      // (or answers a ping sent before it): it is sent again (the same id is cheap to repeat).
      if (node.state == Node::State::kSettingUp &&
          message.body.value("setup", std::string()) !=
              options_.setup.value("setup", std::string())) {
        node.state = Node::State::kJoining;
      }
      if (node.state != Node::State::kJoining) break;
      if (message.body.value("setup", std::string()) ==
              options_.setup.value("setup", std::string()) &&
          node.ever_live) {
        node.state = Node::State::kLive;
        Log(fmt::format("controller: node {} is back at frame {}", node.address.name,
                        current_frame_ + 1));
        break;
      }
      {
        Message setup;
        setup.type = MessageType::kSetup;
        setup.sequence = next_request_++;
        setup.body = options_.setup;
        if (node.socket->Send(setup)) node.state = Node::State::kSettingUp;
      }
      break;
    case MessageType::kSetupDone:
      if (node.state != Node::State::kSettingUp) break;
      if (message.body.contains("error")) {
        node.error = message.body["error"].is_string() ? message.body["error"].get<std::string>()
                                                       : "setup failed";
        node.state = Node::State::kJoining;
        Log(fmt::format("controller: node {}: {}", node.address.name, node.error));
        break;
      }
      node.error.clear();
      node.state = Node::State::kLive;
      if (node.ever_live)
        Log(fmt::format("controller: node {} rejoins at frame {}", node.address.name,
                        current_frame_ + 1));
      node.ever_live = true;
      break;
    case MessageType::kReady:
      if (message.sequence == current_frame_ && node.in_frame && node.state == Node::State::kLive) {
        node.ready = true;
        const nlohmann::json& body = message.body;
        if (body.contains("render_ms") && body["render_ms"].is_number())
          node.render_ms = body["render_ms"].get<double>();
      }
      break;
    case MessageType::kPresented:
      if (message.sequence == current_frame_ && node.ready) {
        node.presented = true;
        node.presented_ns = message.presented_ns;
      }
      break;
    case MessageType::kFailed: {
      const std::string error = message.body.contains("error") && message.body["error"].is_string()
                                    ? message.body["error"].get<std::string>()
                                    : "failed";
      // A node that serves another controller: Connect ends with its line.
      const bool busy =
          message.body.is_object() && message.body.contains("busy") && message.body["busy"] == true;
      if (busy && node.state != Node::State::kLive) {
        node.error = error;
        break;
      }
      Log(fmt::format("controller: node {} says: {}", node.address.name, error));
      break;
    }
    default:
      Log(fmt::format("controller: node {} sent an unexpected '{}'", node.address.name,
                      MessageTypeName(message.type)));
  }
}

void Controller::Pump(int timeout_ms) {
  std::vector<zmq::pollitem_t> items;
  for (const auto& node : nodes_)
    items.push_back({node->socket->socket().handle(), 0, ZMQ_POLLIN, 0});
  PollOrInterrupted(items.data(), items.size(), std::chrono::milliseconds(std::max(0, timeout_ms)));
  for (size_t k = 0; k < nodes_.size(); ++k) {
    if (!(items[k].revents & ZMQ_POLLIN)) continue;
    // Everything that is there now, bounded: a flood cannot hold the controller.
    for (int count = 0; count < 64; ++count) {
      std::string why;
      std::optional<Message> message = nodes_[k]->socket->Receive(0, &why);
      if (message) {
        Handle(*nodes_[k], *message);
      } else if (!why.empty()) {
        Log(fmt::format("controller: node {} sent a malformed message: {}", nodes_[k]->address.name,
                        why));
      } else {
        break;
      }
    }
  }
}

void Controller::Service() {
  const auto now = Clock::now();
  for (const auto& node : nodes_) {
    if (node->state == Node::State::kLive) continue;
    // A node being set up is pinged too, less often: its answer says whether it still has our
    // setup coming (it restarted otherwise).
    const double interval = node->state == Node::State::kSettingUp ? 1.0 : kPingIntervalS;
    if (SecondsSince(node->last_ping) < interval) continue;
    node->last_ping = now;
    Message ping;
    ping.type = MessageType::kPing;
    ping.sequence = next_request_++;
    node->socket->Send(ping);
  }
}

void Controller::Connect() {
  const auto start = Clock::now();
  while (SecondsSince(start) < options_.setup_timeout_s) {
    if (options_.cancelled && options_.cancelled())
      throw IoError("controller: cancelled while the nodes were set up");
    Service();
    Pump(50);
    for (const auto& node : nodes_) {
      if (!node->error.empty())
        throw IoError("node " + node->address.name + " (" + node->address.endpoint +
                      "): " + node->error);
    }
    if (live() == static_cast<int>(nodes_.size())) return;
  }
  for (const auto& node : nodes_) {
    if (node->state == Node::State::kLive) continue;
    throw IoError(
        fmt::format("node {} ({}): {} in {:.0f} s (not running, not reachable, or it refused this "
                    "controller's key: see the node's log)",
                    node->address.name, node->address.endpoint,
                    node->state == Node::State::kSettingUp ? "not set up" : "no answer",
                    options_.setup_timeout_s));
  }
}

FrameReport Controller::Show(uint64_t frame, const Eigen::MatrixX3d& emittance) {
  current_frame_ = frame;
  FrameReport report;
  report.frame = frame;
  Service();
  Pump(0);
  const std::string bytes = EncodeMessage(FrameMessage(frame, emittance));  // once, for every node
  const auto sent = Clock::now();
  // Only the nodes live now take part: one that rejoins while the frame is under way waits for
  // the next.
  std::vector<bool> was_live;
  for (const auto& node : nodes_) {
    was_live.push_back(node->state == Node::State::kLive);
    node->in_frame = node->state == Node::State::kLive;
    node->ready = node->presented = false;
    node->ready_ms = node->render_ms = 0.0;
    if (!node->in_frame) continue;
    if (!node->socket->socket().send(zmq::buffer(bytes), zmq::send_flags::dontwait))
      Lose(*node, "not connected");
  }
  auto taking_part = [](const Node& node) {
    return node.in_frame && node.state == Node::State::kLive;
  };
  auto waiting = [&](bool presented) {
    return std::any_of(nodes_.begin(), nodes_.end(), [&](const auto& node) {
      return taking_part(*node) && !(presented ? node->presented : node->ready);
    });
  };
  const auto timeout = std::chrono::duration<double>(options_.frame_timeout_s);
  while (waiting(false) && Clock::now() - sent < timeout) {
    Pump(static_cast<int>(std::ceil(1e3 * (options_.frame_timeout_s - SecondsSince(sent)))));
    for (const auto& node : nodes_) {
      if (node->ready && node->ready_ms == 0.0) node->ready_ms = MsSince(sent);
    }
  }
  for (const auto& node : nodes_) {
    if (taking_part(*node) && !node->ready)
      Lose(*node, fmt::format("no answer to frame {} in {:.0f} ms", frame,
                              1e3 * options_.frame_timeout_s));
  }
  report.ready_ms = MsSince(sent);
  Message present;
  present.type = MessageType::kPresent;
  present.sequence = frame;
  const auto present_sent = Clock::now();
  for (const auto& node : nodes_) {
    if (taking_part(*node) && !node->socket->Send(present)) Lose(*node, "not connected");
  }
  while (waiting(true) && Clock::now() - present_sent < timeout)
    Pump(
        static_cast<int>(std::ceil(1e3 * (options_.frame_timeout_s - SecondsSince(present_sent)))));
  for (const auto& node : nodes_) {
    if (taking_part(*node) && !node->presented)
      Lose(*node, fmt::format("frame {} not presented in {:.0f} ms", frame,
                              1e3 * options_.frame_timeout_s));
  }
  report.present_ms = MsSince(present_sent);
  int64_t earliest = 0, latest = 0;
  for (size_t k = 0; k < nodes_.size(); ++k) {
    const auto& node = nodes_[k];
    NodeFrame part;
    part.ready_ms = node->ready_ms;
    part.render_ms = node->render_ms;
    if (node->presented && taking_part(*node)) {
      part.state = "shown";
      part.presented_ns = node->presented_ns;
      if (report.shown == 0 || node->presented_ns < earliest) earliest = node->presented_ns;
      if (report.shown == 0 || node->presented_ns > latest) latest = node->presented_ns;
      ++report.shown;
    } else {
      part.state = was_live[k] ? "lost" : "absent";
    }
    report.nodes.push_back(part);
  }
  report.skew_ms = 1e-6 * static_cast<double>(latest - earliest);
  return report;
}

void Controller::Stop(bool exit) {
  Message stop;
  stop.type = MessageType::kStop;
  stop.sequence = current_frame_;
  if (exit) stop.body = {{"exit", true}};
  for (const auto& node : nodes_) node->socket->Send(stop);
}

}  // namespace procam
