#pragma once
// The display nodes' transport: ZeroMQ sockets with CURVE security, and the rig's keys.
//
// Who may talk to whom. Every node is a CURVE server: it listens (ROUTER) with the rig's node
// key pair, and a ZAP handler in the node lets a client in only if it proves it holds the secret
// of the rig's controller key (its public key equals RIG_DIR/keys/controller.pub); anything else
// is refused before a single message reaches the node, and the refusal is logged with the
// peer's address. The controller is a CURVE client of every node (one DEALER each) that knows
// the nodes' public key. CURVE also encrypts the traffic. The keys are made once by
// `procam keys` (MakeRigKeys) and kept in the rig directory:
//
//   RIG_DIR/keys/controller.key   the controller's secret key (Z85, 40 characters), mode 0600
//   RIG_DIR/keys/controller.pub   its public key
//   RIG_DIR/keys/node.key         the nodes' secret key, mode 0600
//   RIG_DIR/keys/node.pub         their public key
//
// A display PC needs node.key, node.pub and controller.pub; the controller's PC controller.key,
// controller.pub and node.pub (docs/nodes.md). An in-process node (endpoint inproc://...) needs
// no keys: nothing outside the process can reach it.
//
// Every socket has ZMQ_MAXMSGSIZE (a longer message drops the connection inside libzmq, before
// procam sees a byte): kMaxMessageBytes, the largest message of the protocol, plus CURVE's
// overhead on an encrypting socket (libzmq compares the encrypted frame), linger 0, and ZeroMQ's
// own heartbeats (a peer silent for a second is disconnected), so that no loop waits on a dead
// peer.

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include "nodes/messages.h"

namespace procam {

struct CurveKeyPair {
  std::string public_key, secret_key;  // Z85, 40 characters each; secret_key empty if not held
};

struct RigKeys {
  CurveKeyPair controller, node;
};

// Writes RIG_DIR/keys/ with fresh key pairs (zmq_curve_keypair). Refuses (IoError naming the
// file) to replace existing keys unless `replace`: nodes set up with the old ones would refuse
// the controller.
RigKeys MakeRigKeys(const std::filesystem::path& rig_dir, bool replace);

// What a controller or a node reads from RIG_DIR/keys/. Throws IoError naming the missing or
// malformed file (and `procam keys` as the remedy).
enum class KeyRole { kController, kNode };
RigKeys ReadRigKeys(const std::filesystem::path& rig_dir, KeyRole role);

// A message as it arrived at a node: who sent it (the ROUTER's routing id) and what, and the
// peer's address ("IP:PORT"; "" in-process).
struct Envelope {
  std::string peer;
  Message message;
  std::string address;
};

// What CURVE adds to each message frame, which libzmq's ZMQ_MAXMSGSIZE counts: the MESSAGE
// command's name (8 bytes), its nonce (8), the flags (1) and the authenticator (16).
constexpr int64_t kCurveMessageOverheadBytes = 33;

// Seconds between the lines that count repeated refusals (RefusalLog).
constexpr double kRefusalLogIntervalS = 5.0;

// Refusals logged at a bounded rate, so that a client retrying (or a flood of connections) cannot
// fill the log: the first refusal is logged in full; the ones within `interval_s` of the last
// line are counted, and Flush (called often) logs one line with their count, up to three of
// their addresses and the last one's reason, once `interval_s` has passed. Thread-safe.
class RefusalLog {
 public:
  RefusalLog(std::function<void(const std::string&)> log, double interval_s);
  // `line` names the refusal and `address`.
  void Refuse(const std::string& address, const std::string& line);
  void Flush();
  long long total() const;  // every refusal, logged or counted

 private:
  std::function<void(const std::string&)> log_;
  double interval_s_;
  mutable std::mutex mutex_;
  bool logged_ = false;
  std::chrono::steady_clock::time_point last_line_;
  long long total_ = 0, held_ = 0, other_addresses_ = 0, unread_addresses_ = 0;
  std::vector<std::string> addresses_;
  std::string last_held_;
};

// Throws IoError naming `what` (e.g. "--listen") and the endpoint when a tcp:// endpoint's port
// is not a number in 1..65535 (or "*", or 0, where `bind`): libzmq would take 99999 modulo 65536.
void CheckTcpPort(const std::string& endpoint, bool bind, const std::string& what);

// The node's end: a ROUTER bound to `endpoint` (tcp://ADDRESS:PORT, or inproc://NAME with no
// keys). With keys, a CURVE server whose ZAP handler admits only `keys->controller.public_key`;
// `log` gets a line per refused peer naming its address (IP:PORT), at a bounded rate
// (RefusalLog), and one per malformed message.
class NodeSocket {
 public:
  NodeSocket(zmq::context_t& context, const std::string& endpoint, const RigKeys* keys,
             std::function<void(const std::string&)> log);
  ~NodeSocket();
  NodeSocket(const NodeSocket&) = delete;
  NodeSocket& operator=(const NodeSocket&) = delete;

  // The next well-formed message, waiting at most `timeout_ms`; nullopt if none came. Malformed
  // messages are logged and dropped (counted in malformed()).
  std::optional<Envelope> Receive(int timeout_ms);
  // Sends to the peer a message came from; false if it is gone (dropped, never blocks).
  bool Send(const std::string& peer, const Message& message);

  const std::string& endpoint() const { return endpoint_; }  // as bound (the port if it was 0)
  long long malformed() const { return malformed_; }
  long long refused() const;
  // A refusal the node makes itself (e.g. a second controller), logged as the socket's are.
  void Refuse(const std::string& address, const std::string& line);

 private:
  class ZapHandler;
  std::unique_ptr<ZapHandler> zap_;
  zmq::socket_t socket_;
  std::string endpoint_;
  std::function<void(const std::string&)> log_;
  long long malformed_ = 0;
};

// The controller's end of one node: a DEALER connected to `endpoint`, as a CURVE client with the
// controller's keys when `keys` is given. Messages are never queued for a node that is not
// connected (ZMQ_IMMEDIATE): a restarted node gets no stale frames.
class ControllerSocket {
 public:
  ControllerSocket(zmq::context_t& context, const std::string& endpoint, const RigKeys* keys);
  // False if the node is not connected (nothing queued) or the message could not be sent now.
  bool Send(const Message& message);
  // The next message from the node within `timeout_ms`, or nullopt; a malformed one is returned
  // as nullopt with *why set.
  std::optional<Message> Receive(int timeout_ms, std::string* why = nullptr);
  zmq::socket_t& socket() { return socket_; }
  const std::string& endpoint() const { return endpoint_; }

 private:
  zmq::socket_t socket_;
  std::string endpoint_;
};

// zmq::poll, with an interruption by a signal (EINTR) read as "nothing arrived" (every revents
// 0), so that the caller's loop sees its stop flag (a node or a show stopped with SIGTERM stops
// cleanly) instead of an "Interrupted system call" error.
int PollOrInterrupted(zmq::pollitem_t* items, size_t count, std::chrono::milliseconds timeout);

// Steady-clock and system-clock "now" in nanoseconds.
int64_t SystemNowNs();

}  // namespace procam
