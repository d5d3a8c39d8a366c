#include "nodes/transport.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <mutex>

#include "base/io.h"

namespace procam {

int PollOrInterrupted(zmq::pollitem_t* items, size_t count, std::chrono::milliseconds timeout) {
  try {
    return zmq::poll(items, count, timeout);
  } catch (const zmq::error_t& error) {
    if (error.num() != EINTR) throw;
    for (size_t i = 0; i < count; ++i) items[i].revents = 0;
    return 0;
  }
}

namespace {

constexpr int kHeartbeatMs = 200;
constexpr int kHeartbeatTimeoutMs = 1000;
// A node drops a connection whose handshake is not complete within this (libzmq's default is
// 30 s): a peer that sends a few bytes and holds its connection open keeps nothing for long.
constexpr int kNodeHandshakeMs = 5000;

std::filesystem::path KeyFile(const std::filesystem::path& rig_dir, const std::string& name) {
  return rig_dir / "keys" / name;
}

// The 32 bytes of a Z85 key; throws IoError naming `where` if it is not one.
std::string DecodeKey(const std::string& z85, const std::string& where) {
  if (z85.size() != 40)
    throw IoError(where +
                  ": not a CURVE key (40 Z85 characters); make the rig's keys with `procam keys`");
  uint8_t bytes[32];
  if (zmq_z85_decode(bytes, z85.c_str()) == nullptr) {
    throw IoError(where + ": not a CURVE key (Z85); make the rig's keys with `procam keys`");
  }
  return std::string(reinterpret_cast<const char*>(bytes), 32);
}

std::string ReadKey(const std::filesystem::path& path) {
  if (!std::filesystem::exists(path)) {
    throw IoError(path.string() +
                  ": no such key file; make the rig's keys with `procam keys --rig " +
                  path.parent_path().parent_path().string() + "` and copy them (docs/nodes.md)");
  }
  std::string text = ReadFile(path, 4096);
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' '))
    text.pop_back();
  DecodeKey(text, path.string());
  return text;
}

// `curve`: the socket encrypts, and libzmq's limit applies to the encrypted frame.
void CommonOptions(zmq::socket_t& socket, bool curve) {
  socket.set(zmq::sockopt::linger, 0);
  socket.set(zmq::sockopt::maxmsgsize,
             kMaxMessageBytes + (curve ? kCurveMessageOverheadBytes : int64_t{0}));
  socket.set(zmq::sockopt::heartbeat_ivl, kHeartbeatMs);
  socket.set(zmq::sockopt::heartbeat_timeout, kHeartbeatTimeoutMs);
  socket.set(zmq::sockopt::heartbeat_ttl, kHeartbeatTimeoutMs);
}

}  // namespace

int64_t SystemNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

RigKeys MakeRigKeys(const std::filesystem::path& rig_dir, bool replace) {
  if (!std::filesystem::is_directory(rig_dir))
    throw IoError(rig_dir.string() + ": no such rig directory");
  for (const char* name : {"controller.key", "controller.pub", "node.key", "node.pub"}) {
    const std::filesystem::path path = KeyFile(rig_dir, name);
    if (!replace && std::filesystem::exists(path)) {
      throw IoError(path.string() +
                    ": the rig already has keys (nodes set up with them would refuse a "
                    "controller with new ones); give --replace to make new ones anyway");
    }
  }
  std::error_code error;
  std::filesystem::create_directories(rig_dir / "keys", error);
  if (error) throw IoError((rig_dir / "keys").string() + ": " + error.message());
  RigKeys keys;
  for (CurveKeyPair* pair : {&keys.controller, &keys.node}) {
    char public_key[41], secret_key[41];
    if (zmq_curve_keypair(public_key, secret_key) != 0) {
      throw IoError("zmq_curve_keypair: " + std::string(zmq_strerror(zmq_errno())) +
                    " (libzmq built without CURVE?)");
    }
    pair->public_key = public_key;
    pair->secret_key = secret_key;
  }
  // Secrets first, each written atomically and created readable by its owner only.
  const std::pair<std::string, std::string> files[] = {
      {"controller.key", keys.controller.secret_key},
      {"node.key", keys.node.secret_key},
      {"controller.pub", keys.controller.public_key},
      {"node.pub", keys.node.public_key}};
  for (const auto& [name, key] : files) {
    const std::filesystem::path path = KeyFile(rig_dir, name);
    WriteFileAtomically(path, key + "\n", name.ends_with(".key") ? 0600 : 0644);
  }
  return keys;
}

RigKeys ReadRigKeys(const std::filesystem::path& rig_dir, KeyRole role) {
  RigKeys keys;
  keys.controller.public_key = ReadKey(KeyFile(rig_dir, "controller.pub"));
  keys.node.public_key = ReadKey(KeyFile(rig_dir, "node.pub"));
  if (role == KeyRole::kController) {
    keys.controller.secret_key = ReadKey(KeyFile(rig_dir, "controller.key"));
  } else {
    keys.node.secret_key = ReadKey(KeyFile(rig_dir, "node.key"));
  }
  return keys;
}

namespace {

// The peer's address of a connected TCP socket, "IP:PORT" ("" if it cannot be read: closed).
std::string PeerAddress(int fd) {
  sockaddr_storage address{};
  socklen_t size = sizeof(address);
  if (::getpeername(fd, reinterpret_cast<sockaddr*>(&address), &size) != 0) return "";
  char host[INET6_ADDRSTRLEN] = {};
  if (address.ss_family == AF_INET) {
    const auto* in = reinterpret_cast<const sockaddr_in*>(&address);
    ::inet_ntop(AF_INET, &in->sin_addr, host, sizeof(host));
    return std::string(host) + ":" + std::to_string(ntohs(in->sin_port));
  }
  if (address.ss_family == AF_INET6) {
    const auto* in6 = reinterpret_cast<const sockaddr_in6*>(&address);
    ::inet_ntop(AF_INET6, &in6->sin6_addr, host, sizeof(host));
    return "[" + std::string(host) + "]:" + std::to_string(ntohs(in6->sin6_port));
  }
  return "";
}

}  // namespace

RefusalLog::RefusalLog(std::function<void(const std::string&)> log, double interval_s)
    : log_(std::move(log)), interval_s_(interval_s) {}

void RefusalLog::Refuse(const std::string& address, const std::string& line) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++total_;
  const auto now = std::chrono::steady_clock::now();
  if (!logged_ ||
      (held_ == 0 && std::chrono::duration<double>(now - last_line_).count() >= interval_s_)) {
    logged_ = true;
    last_line_ = now;
    if (log_) log_(line);
    return;
  }
  ++held_;
  last_held_ = line.starts_with("node: ") ? line.substr(6) : line;
  if (address.empty()) {
    ++unread_addresses_;
  } else if (std::find(addresses_.begin(), addresses_.end(), address) == addresses_.end()) {
    if (addresses_.size() < 3) {
      addresses_.push_back(address);
    } else {
      ++other_addresses_;
    }
  }
}

void RefusalLog::Flush() {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto now = std::chrono::steady_clock::now();
  const double seconds = std::chrono::duration<double>(now - last_line_).count();
  if (held_ == 0 || seconds < interval_s_) return;
  std::string from;
  for (size_t k = 0; k < addresses_.size(); ++k) from += (k == 0 ? "" : ", ") + addresses_[k];
  if (other_addresses_ > 0) from += " and " + std::to_string(other_addresses_) + " other addresses";
  if (unread_addresses_ > 0) {
    from += (from.empty() ? "" : "; ") + std::to_string(unread_addresses_) +
            " closed before their address could be read";
  }
  if (log_) {
    log_("node: refused " + std::to_string(held_) + " more connection" + (held_ == 1 ? "" : "s") +
         " in the last " + std::to_string(static_cast<int>(std::lround(seconds))) + " s from " +
         from + " (the last: " + last_held_ + ")");
  }
  last_line_ = now;
  held_ = 0;
  other_addresses_ = 0;
  unread_addresses_ = 0;
  addresses_.clear();
}

long long RefusalLog::total() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return total_;
}

// ZeroMQ's authentication protocol (ZAP, RFC 27) for one context: a thread that answers the
// CURVE server's requests (admit only the controller's public key) and watches the node
// socket's monitor: the connections it accepts (their peers' addresses, read when they are
// accepted) and the handshakes that fail, before ZAP is asked
// (a client without CURVE, or one that does not know the node's key) or by ZAP's refusal. libzmq's
// monitor (version 1) names only the node's own endpoint in a failure; the connection's
// descriptor comes with its acceptance and with its disconnection, which follows the failure at
// once, so the refusal is logged then, with the peer's address.
// A connection whose bytes are not ZeroMQ's greeting at all (a port scanner, a web browser, junk)
// is dropped by libzmq with no failure event: only its disconnection, before any handshake
// succeeded. The monitor's events come in the order libzmq's I/O thread made them, a handshake's
// success after its connection's acceptance, but a success names no descriptor: it settles the
// one connection still handshaking, or, when several are, all of them (a junk connection among
// them then goes unlogged rather than a controller's logged as junk).
class NodeSocket::ZapHandler {
 public:
  ZapHandler(zmq::context_t& context, const std::string& allowed_key,
             std::function<void(const std::string&)> log)
      : handler_(context, zmq::socket_type::rep),
        monitor_(context, zmq::socket_type::pair),
        allowed_(allowed_key),
        log_(log),
        refusals_(std::move(log), kRefusalLogIntervalS) {
    handler_.set(zmq::sockopt::linger, 0);
    handler_.bind("inproc://zeromq.zap.01");
  }
  ~ZapHandler() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  // Starts answering; `monitor_endpoint` is the node socket's monitor (zmq_socket_monitor).
  void Start(const std::string& monitor_endpoint) {
    monitor_.set(zmq::sockopt::linger, 0);
    monitor_.connect(monitor_endpoint);
    thread_ = std::thread([this] { Run(); });
  }
  long long refused() const { return refusals_.total(); }
  // The peer of the connection descriptor `fd` is now ("" if not known).
  std::string Address(int fd) const {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto found = accepted_.find(fd);
    return found == accepted_.end() ? "" : found->second.address;
  }
  void Refuse(const std::string& address, const std::string& line) {
    refusals_.Refuse(address, line);
  }

 private:
  void Run() {
    zmq::pollitem_t items[] = {{handler_.handle(), 0, ZMQ_POLLIN, 0},
                               {monitor_.handle(), 0, ZMQ_POLLIN, 0}};
    while (!stop_) {
      try {
        PollOrInterrupted(items, 2, std::chrono::milliseconds(50));
        if (items[0].revents & ZMQ_POLLIN) Answer();
        if (items[1].revents & ZMQ_POLLIN) Watch();
        refusals_.Flush();
      } catch (const zmq::error_t& e) {
        if (e.num() == ETERM) return;
        Log(std::string("node: authentication: ") + e.what());
      }
    }
  }
  void Answer() {
    std::vector<zmq::message_t> request;
    for (;;) {
      zmq::message_t part;
      if (!handler_.recv(part, zmq::recv_flags::none)) return;
      const bool more = part.more();
      request.push_back(std::move(part));
      if (!more || request.size() > 16) break;
    }
    // version, request id, domain, address, routing id, mechanism, credentials...
    if (request.size() < 6) return;
    const std::string mechanism = request[5].to_string();
    bool admit = false;
    std::string text = "not the rig's controller";
    if (mechanism == "CURVE" && request.size() >= 7 && request[6].size() == 32) {
      admit = request[6].to_string() == allowed_;
      if (!admit) {
        char z85[41];
        zmq_z85_encode(z85, static_cast<const uint8_t*>(request[6].data()), 32);
        failure_ = {"a controller",
                    std::string("its key ") + z85 + " is not the rig's (keys/controller.pub)",
                    request[3].to_string()};
      }
    } else {
      text = "CURVE required";
      failure_ = {"a peer", "mechanism " + mechanism + ", not CURVE", request[3].to_string()};
    }
    const std::string version = "1.0", status = admit ? "200" : "400",
                      status_text = admit ? "OK" : text;
    handler_.send(zmq::buffer(version), zmq::send_flags::sndmore);
    handler_.send(request[1], zmq::send_flags::sndmore);
    handler_.send(zmq::buffer(status), zmq::send_flags::sndmore);
    handler_.send(zmq::buffer(status_text), zmq::send_flags::sndmore);
    handler_.send(zmq::buffer(std::string(admit ? "controller" : "")), zmq::send_flags::sndmore);
    handler_.send(zmq::str_buffer(""), zmq::send_flags::none);
  }
  // Monitor events: two frames, (u16 event, u32 value) and an endpoint (the node's own).
  void Watch() {
    zmq::message_t event, endpoint;
    if (!monitor_.recv(event, zmq::recv_flags::none)) return;
    if (event.more()) (void)monitor_.recv(endpoint, zmq::recv_flags::none);
    if (event.size() < 6) return;
    uint16_t id;
    uint32_t value;
    std::memcpy(&id, event.data(), 2);
    std::memcpy(&value, static_cast<const char*>(event.data()) + 2, 4);
    const int fd = static_cast<int>(value);
    switch (id) {
      case ZMQ_EVENT_ACCEPTED: {
        std::lock_guard<std::mutex> lock(mutex_);
        accepted_[fd] = {PeerAddress(fd), false};  // "" when it closed before it could be read
        break;
      }
      case ZMQ_EVENT_HANDSHAKE_SUCCEEDED: {
        std::lock_guard<std::mutex> lock(mutex_);
        for (auto& [descriptor, connection] : accepted_) connection.handshaken = true;
        break;
      }
      case ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL:
      case ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL:
        failed_ = {"a peer", "its security handshake failed (no CURVE, or not the rig's node key)",
                   ""};
        break;
      case ZMQ_EVENT_HANDSHAKE_FAILED_AUTH:
        failed_ = failure_.who.empty() ? Failure{"a peer", "refused by ZAP", ""} : failure_;
        failure_ = {};
        break;
      case ZMQ_EVENT_DISCONNECTED: {
        std::string address;
        bool known = false, handshaken = false;
        {
          std::lock_guard<std::mutex> lock(mutex_);
          const auto found = accepted_.find(fd);
          if (found != accepted_.end()) {
            known = true;
            address = found->second.address;
            handshaken = found->second.handshaken;
            accepted_.erase(found);
          }
        }
        if (failed_.who.empty() && known && !handshaken) {
          failed_ = {"a peer",
                     "it closed or was dropped before a ZeroMQ handshake (what it sent, if "
                     "anything, was not ZeroMQ's greeting)",
                     ""};
        }
        if (!failed_.who.empty()) {
          if (address.empty()) address = failed_.ip;  // ZAP's (the port not known)
          const std::string from =
              address.empty() ? "an address (its connection closed before it could be read)"
                              : address;
          refusals_.Refuse(address,
                           "node: refused " + failed_.who + " at " + from + ": " + failed_.why);
          failed_ = {};
        }
        break;
      }
      default:
        break;
    }
  }
  void Log(const std::string& line) {
    std::lock_guard<std::mutex> lock(log_mutex_);
    if (log_) log_(line);
  }

  zmq::socket_t handler_, monitor_;
  std::string allowed_;
  std::function<void(const std::string&)> log_;
  std::mutex log_mutex_;
  RefusalLog refusals_;
  struct Failure {
    std::string who;  // "a peer", "a controller"
    std::string why;
    std::string ip;  // ZAP's record of the peer's address (no port), "" before ZAP
  };
  Failure failure_;  // ZAP's last refusal, until the failure's event
  Failure failed_;   // a handshake failed: the refusal is logged at its disconnection
  mutable std::mutex mutex_;
  struct Connection {
    std::string address;  // the peer's, "" if it could not be read
    // A handshake succeeded since it was accepted: its own, or one the monitor could not tell
    // from its own (see the class comment).
    bool handshaken = false;
  };
  std::map<int, Connection> accepted_;  // open connections by descriptor
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

void CheckTcpPort(const std::string& endpoint, bool bind, const std::string& what) {
  if (!endpoint.starts_with("tcp://")) return;
  const size_t colon = endpoint.rfind(':');
  const std::string port = colon == std::string::npos || colon < 6 ? "" : endpoint.substr(colon + 1);
  if (bind && port == "*") return;
  const bool digits = !port.empty() && port.size() <= 5 &&
                      std::all_of(port.begin(), port.end(), [](char c) { return c >= '0' && c <= '9'; });
  const long value = digits ? std::stol(port) : -1;
  if (!digits || value > 65535 || (value == 0 && !bind)) {
    throw IoError(what + ": " + endpoint + ": the port must be a number in " +
                  (bind ? "0..65535 or *" : "1..65535") +
                  (port.empty() ? std::string(" (none given)") : ", not " + port));
  }
}

NodeSocket::NodeSocket(zmq::context_t& context, const std::string& endpoint, const RigKeys* keys,
                       std::function<void(const std::string&)> log)
    : log_(std::move(log)) {
  if (keys != nullptr) {
    zap_ = std::make_unique<ZapHandler>(
        context, DecodeKey(keys->controller.public_key, "keys/controller.pub"), log_);
  }
  socket_ = zmq::socket_t(context, zmq::socket_type::router);
  CommonOptions(socket_, keys != nullptr);
  socket_.set(zmq::sockopt::router_mandatory, 1);
  if (keys != nullptr) {
    socket_.set(zmq::sockopt::handshake_ivl, kNodeHandshakeMs);
    socket_.set(zmq::sockopt::curve_server, 1);
    socket_.set(zmq::sockopt::curve_secretkey, DecodeKey(keys->node.secret_key, "keys/node.key"));
    const std::string monitor =
        "inproc://procam-node-monitor-" + std::to_string(reinterpret_cast<uintptr_t>(this));
    if (zmq_socket_monitor(
            socket_.handle(), monitor.c_str(),
            ZMQ_EVENT_ACCEPTED | ZMQ_EVENT_DISCONNECTED | ZMQ_EVENT_HANDSHAKE_SUCCEEDED |
                ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL | ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                ZMQ_EVENT_HANDSHAKE_FAILED_AUTH) != 0) {
      throw IoError("node: cannot monitor the socket: " + std::string(zmq_strerror(zmq_errno())));
    }
    zap_->Start(monitor);
  } else if (!endpoint.starts_with("inproc://")) {
    throw IoError("node " + endpoint + ": a network endpoint needs the rig's keys");
  }
  CheckTcpPort(endpoint, /*bind=*/true, "node");
  try {
    socket_.bind(endpoint);
  } catch (const zmq::error_t& e) {
    throw IoError("node: cannot listen at " + endpoint + ": " + e.what());
  }
  endpoint_ = socket_.get(zmq::sockopt::last_endpoint);
}

NodeSocket::~NodeSocket() {
  if (zap_) zmq_socket_monitor(socket_.handle(), nullptr, 0);
  socket_.close();
  zap_.reset();
}

long long NodeSocket::refused() const { return zap_ ? zap_->refused() : 0; }

void NodeSocket::Refuse(const std::string& address, const std::string& line) {
  if (zap_) {
    zap_->Refuse(address, line);
  } else if (log_) {
    log_(line);
  }
}

std::optional<Envelope> NodeSocket::Receive(int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    zmq::pollitem_t item = {socket_.handle(), 0, ZMQ_POLLIN, 0};
    PollOrInterrupted(&item, 1, std::max(left, std::chrono::milliseconds(0)));
    if (!(item.revents & ZMQ_POLLIN)) return std::nullopt;
    std::vector<zmq::message_t> parts;
    for (;;) {
      zmq::message_t part;
      if (!socket_.recv(part, zmq::recv_flags::dontwait)) break;
      const bool more = part.more();
      if (parts.size() < 3) parts.push_back(std::move(part));
      if (!more) break;
    }
    std::string why;
    Envelope envelope;
    if (parts.size() == 2) {
      envelope.peer = parts[0].to_string();
      if (zap_) {  // the connection's descriptor (ZMQ_SRCFD, deprecated but kept by libzmq 4.3)
        const int fd = zmq_msg_get(parts[1].handle(), ZMQ_SRCFD);
        if (fd >= 0) envelope.address = zap_->Address(fd);
        if (envelope.address.empty() && fd >= 0) envelope.address = PeerAddress(fd);
      }
      if (ParseMessage(parts[1].data(), parts[1].size(), &envelope.message, &why)) return envelope;
    } else {
      why = "a message of " + std::to_string(parts.size() - 1) + " frames (one expected)";
    }
    ++malformed_;
    if (log_) log_("node: dropped a malformed message: " + why);
  }
}

bool NodeSocket::Send(const std::string& peer, const Message& message) {
  const std::string bytes = EncodeMessage(message);
  try {
    if (!socket_.send(zmq::buffer(peer), zmq::send_flags::sndmore | zmq::send_flags::dontwait))
      return false;
    return socket_.send(zmq::buffer(bytes), zmq::send_flags::dontwait).has_value();
  } catch (const zmq::error_t&) {
    return false;  // EHOSTUNREACH: the peer is gone (router_mandatory)
  }
}

ControllerSocket::ControllerSocket(zmq::context_t& context, const std::string& endpoint,
                                   const RigKeys* keys)
    : socket_(context, zmq::socket_type::dealer), endpoint_(endpoint) {
  CommonOptions(socket_, keys != nullptr);
  socket_.set(zmq::sockopt::immediate, 1);
  socket_.set(zmq::sockopt::reconnect_ivl, 100);
  socket_.set(zmq::sockopt::reconnect_ivl_max, 500);
  if (keys != nullptr) {
    socket_.set(zmq::sockopt::curve_serverkey, DecodeKey(keys->node.public_key, "keys/node.pub"));
    socket_.set(zmq::sockopt::curve_publickey,
                DecodeKey(keys->controller.public_key, "keys/controller.pub"));
    socket_.set(zmq::sockopt::curve_secretkey,
                DecodeKey(keys->controller.secret_key, "keys/controller.key"));
  } else if (!endpoint.starts_with("inproc://")) {
    throw IoError("controller: node " + endpoint + " is on the network: the rig's keys are needed");
  }
  CheckTcpPort(endpoint, /*bind=*/false, "controller: node");
  try {
    socket_.connect(endpoint);
  } catch (const zmq::error_t& e) {
    throw IoError("controller: cannot connect to node " + endpoint + ": " + e.what());
  }
}

bool ControllerSocket::Send(const Message& message) {
  const std::string bytes = EncodeMessage(message);
  return socket_.send(zmq::buffer(bytes), zmq::send_flags::dontwait).has_value();
}

std::optional<Message> ControllerSocket::Receive(int timeout_ms, std::string* why) {
  zmq::pollitem_t item = {socket_.handle(), 0, ZMQ_POLLIN, 0};
  PollOrInterrupted(&item, 1, std::chrono::milliseconds(std::max(0, timeout_ms)));
  if (!(item.revents & ZMQ_POLLIN)) return std::nullopt;
  zmq::message_t part;
  if (!socket_.recv(part, zmq::recv_flags::dontwait)) return std::nullopt;
  bool extra = false;
  while (part.more()) {  // a node sends one frame per message; anything more is malformed
    extra = true;
    if (!socket_.recv(part, zmq::recv_flags::dontwait)) break;
  }
  Message message;
  std::string reason;
  if (!extra && ParseMessage(part.data(), part.size(), &message, &reason)) return message;
  if (why) *why = extra ? "a message of several frames" : reason;
  return std::nullopt;
}

}  // namespace procam
