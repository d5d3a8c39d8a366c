#include "nodes/osc_server.h"

#include <arpa/inet.h>
#include <fmt/format.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <vector>

#include "base/io.h"

namespace procam {

OscServer::OscServer(OscServerOptions options) : options_(std::move(options)) {
  const std::string& listen = options_.listen;
  const size_t colon = listen.rfind(':');
  uint32_t host = 0;
  int port = -1;
  if (colon != std::string::npos && ParseIpv4(listen.substr(0, colon), &host)) {
    const std::string digits = listen.substr(colon + 1);
    if (!digits.empty() && digits.size() <= 5 &&
        digits.find_first_not_of("0123456789") == std::string::npos)
      port = std::stoi(digits);
  }
  if (port < 0 || port > 65535)
    throw IoError("--osc: " + listen + ": not IPV4:PORT (e.g. 127.0.0.1:9000)");
  socket_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (socket_ < 0) throw IoError("--osc: " + listen + ": " + std::strerror(errno));
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(host);
  if (::bind(socket_, reinterpret_cast<const sockaddr*>(&address), sizeof(address)) != 0) {
    const std::string error = std::strerror(errno);
    ::close(socket_);
    throw IoError("--osc: " + listen + ": cannot listen there: " + error);
  }
  socklen_t length = sizeof(address);
  ::getsockname(socket_, reinterpret_cast<sockaddr*>(&address), &length);
  port_ = ntohs(address.sin_port);
  if (options_.log) options_.log(fmt::format("osc: listening on {}:{}", Ipv4Text(host), port_));
  thread_ = std::thread([this] { Run(); });
}

OscServer::~OscServer() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (socket_ >= 0) ::close(socket_);
}

void OscServer::Run() {
  // The largest UDP payload: a longer message cannot arrive in one datagram anyway.
  std::vector<uint8_t> buffer(65536);
  while (!stop_) {
    pollfd poll_fd{socket_, POLLIN, 0};
    if (::poll(&poll_fd, 1, 100) <= 0) continue;
    sockaddr_in from{};
    socklen_t length = sizeof(from);
    const ssize_t size = ::recvfrom(socket_, buffer.data(), buffer.size(), MSG_DONTWAIT,
                                    reinterpret_cast<sockaddr*>(&from), &length);
    if (size < 0) continue;  // EAGAIN, or an ICMP error of an earlier reply
    Handle(buffer.data(), static_cast<size_t>(size), ntohl(from.sin_addr.s_addr),
           ntohs(from.sin_port));
  }
}

void OscServer::Handle(const uint8_t* data, size_t size, uint32_t host, int port) {
  const std::string sender = fmt::format("{}:{}", Ipv4Text(host), port);
  auto refuse = [&](const std::string& why) {
    ++refused_;
    if (options_.log) options_.log("osc: ignored a message from " + sender + ": " + why);
  };
  if (!options_.allow.Allows(host)) {
    refuse("not an allowed sender (--osc-allow)");
    return;
  }
  OscMessage message;
  OscCommand command;
  std::string why;
  if (!DecodeOscPacket(data, size, &message, &why) || !ParseOscCommand(message, &command, &why)) {
    refuse(why);
    return;
  }
  if (command.kind != OscCommand::Kind::kStatus) {
    if (options_.on_command) options_.on_command(command);
    return;
  }
  if (!options_.on_status) return;
  const std::vector<uint8_t> reply = EncodeOscMessage(options_.on_status());
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<uint16_t>(port));
  to.sin_addr.s_addr = htonl(host);
  ::sendto(socket_, reply.data(), reply.size(), 0, reinterpret_cast<const sockaddr*>(&to),
           sizeof(to));
}

}  // namespace procam
