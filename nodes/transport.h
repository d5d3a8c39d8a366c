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
// procam sees a byte), linger 0, and ZeroMQ's own heartbeats (a peer silent for a second is
// disconnected), so that no loop waits on a dead peer.

#include <filesystem>
#include <functional>
#include <memory>
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

// A message as it arrived at a node: who sent it (the ROUTER's routing id) and what.
struct Envelope {
  std::string peer;
  Message message;
};

// Throws IoError naming `what` (e.g. "--listen") and the endpoint when a tcp:// endpoint's port
// is not a number in 1..65535 (or "*", or 0, where `bind`): libzmq would take 99999 modulo 65536.
void CheckTcpPort(const std::string& endpoint, bool bind, const std::string& what);

// The node's end: a ROUTER bound to `endpoint` (tcp://ADDRESS:PORT, or inproc://NAME with no
// keys). With keys, a CURVE server whose ZAP handler admits only `keys->controller.public_key`;
// `log` gets one line per refused peer and per malformed message.
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

// Steady-clock and system-clock "now" in nanoseconds.
int64_t SystemNowNs();

}  // namespace procam
