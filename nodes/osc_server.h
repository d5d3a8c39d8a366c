#pragma once
// The OSC control's socket: a UDP socket bound to the address given (127.0.0.1:9000 answers only
// this machine; 0.0.0.0:9000 every interface), read by a thread of its own. Each datagram from
// an allowed sender is decoded and checked (nodes/osc.h) and handed on as a command; anything
// else is one log line naming the sender and why, and is dropped. /procam/status is answered at
// once, on this thread, to the sender's address and port.

#include <atomic>
#include <functional>
#include <string>
#include <thread>

#include "nodes/osc.h"

namespace procam {

struct OscServerOptions {
  std::string listen = "127.0.0.1:9000";  // IPV4:PORT to bind (port 1..65535, or 0: any free)
  OscAllowList allow;                     // senders answered; others refused (one line each)
  // Each accepted command but status, on the server's thread.
  std::function<void(const OscCommand&)> on_command;
  // The reply to /procam/status (address /procam/status), on the server's thread.
  std::function<OscMessage()> on_status;
  std::function<void(const std::string&)> log;  // refusals and the bound address
};

class OscServer {
 public:
  // Binds and starts the thread. Throws IoError naming the address (taken, not local, not
  // IPV4:PORT).
  explicit OscServer(OscServerOptions options);
  ~OscServer();  // stops the thread (within its 100 ms poll) and closes the socket
  OscServer(const OscServer&) = delete;
  OscServer& operator=(const OscServer&) = delete;

  int port() const { return port_; }  // the port bound (the one chosen, for port 0)
  int refused() const { return refused_.load(); }

 private:
  void Run();
  void Handle(const uint8_t* data, size_t size, uint32_t host, int port);

  OscServerOptions options_;
  int socket_ = -1;
  int port_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<int> refused_{0};
  std::thread thread_;
};

}  // namespace procam
