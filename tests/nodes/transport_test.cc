// The display nodes' transport on 127.0.0.1: only the rig's controller is answered (CURVE with a
// ZAP handler), anything else is refused and logged, malformed messages are dropped without
// stopping the node, and the keys are made and read with errors naming the file.
#include "nodes/transport.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <functional>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

// A node socket on a free loopback port, with a log the test can read.
struct TestNode {
  explicit TestNode(const RigKeys& keys)
      : socket(context, "tcp://127.0.0.1:*", &keys, [this](const std::string& line) {
          std::lock_guard<std::mutex> lock(mutex);
          log += line + "\n";
        }) {}
  std::string Log() {
    std::lock_guard<std::mutex> lock(mutex);
    return log;
  }
  zmq::context_t context;
  std::mutex mutex;
  std::string log;
  NodeSocket socket;
};

Message Ping(uint64_t sequence) {
  Message ping;
  ping.type = MessageType::kPing;
  ping.sequence = sequence;
  return ping;
}

// Sends pings (the connection may take a moment) until the node receives one, for at most 3 s.
std::optional<Envelope> PingUntilReceived(ControllerSocket& controller, TestNode& node) {
  for (int attempt = 0; attempt < 30; ++attempt) {
    controller.Send(Ping(attempt));
    if (std::optional<Envelope> envelope = node.socket.Receive(100)) return envelope;
  }
  return std::nullopt;
}

TEST(NodeTransport, TheRigsControllerIsAnswered) {
  testing::TempDir dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  TestNode node(keys);
  zmq::context_t context;
  ControllerSocket controller(context, node.socket.endpoint(), &keys);
  std::optional<Envelope> envelope = PingUntilReceived(controller, node);
  ASSERT_TRUE(envelope) << node.Log();
  EXPECT_EQ(envelope->message.type, MessageType::kPing);
  Message pong;
  pong.type = MessageType::kPong;
  pong.sequence = envelope->message.sequence;
  pong.body = {{"node", "test"}};
  ASSERT_TRUE(node.socket.Send(envelope->peer, pong));
  std::optional<Message> answer;
  for (int k = 0; k < 30 && !answer; ++k) answer = controller.Receive(100);
  ASSERT_TRUE(answer);
  EXPECT_EQ(answer->type, MessageType::kPong);
  EXPECT_EQ(answer->body["node"], "test");
  EXPECT_EQ(node.socket.refused(), 0);
}

TEST(NodeTransport, AControllerWithAnotherRigsKeyIsRefusedAndLogged) {
  testing::TempDir dir, other_dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  RigKeys impostor = MakeRigKeys(other_dir.path(), false);
  impostor.node.public_key =
      keys.node.public_key;  // it knows the node's public key, not our secret
  TestNode node(keys);
  zmq::context_t context;
  ControllerSocket controller(context, node.socket.endpoint(), &impostor);
  EXPECT_FALSE(PingUntilReceived(controller, node));
  EXPECT_GE(node.socket.refused(), 1);
  EXPECT_NE(node.Log().find("refused a controller at 127.0.0.1"), std::string::npos) << node.Log();
  EXPECT_NE(node.Log().find(impostor.controller.public_key), std::string::npos) << node.Log();
}

TEST(NodeTransport, APeerWithoutCurveIsRefused) {
  testing::TempDir dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  TestNode node(keys);
  zmq::context_t context;
  zmq::socket_t plain(context, zmq::socket_type::dealer);
  plain.set(zmq::sockopt::linger, 0);
  plain.connect(node.socket.endpoint());
  const std::string bytes = EncodeMessage(Ping(1));
  for (int attempt = 0; attempt < 10; ++attempt) {
    (void)plain.send(zmq::buffer(bytes), zmq::send_flags::dontwait);
    EXPECT_FALSE(node.socket.Receive(100));
  }
  EXPECT_GE(node.socket.refused(), 1);
  EXPECT_NE(node.Log().find("refused a peer"), std::string::npos) << node.Log();
}

TEST(NodeTransport, MalformedMessagesAreDroppedAndTheNodeGoesOn) {
  testing::TempDir dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  TestNode node(keys);
  zmq::context_t context;
  ControllerSocket controller(context, node.socket.endpoint(), &keys);
  ASSERT_TRUE(PingUntilReceived(controller, node));
  (void)controller.socket().send(zmq::str_buffer("not a procam message at all"),
                                 zmq::send_flags::none);
  (void)controller.socket().send(zmq::str_buffer("PCN1"), zmq::send_flags::sndmore);
  (void)controller.socket().send(zmq::str_buffer("two frames"), zmq::send_flags::none);
  controller.Send(Ping(99));
  std::optional<Envelope> envelope = node.socket.Receive(2000);
  ASSERT_TRUE(envelope);
  EXPECT_EQ(envelope->message.sequence, 99u);
  EXPECT_EQ(node.socket.malformed(), 2);
  EXPECT_NE(node.Log().find("dropped a malformed message: not a procam node message"),
            std::string::npos)
      << node.Log();
  EXPECT_NE(node.Log().find("2 frames"), std::string::npos) << node.Log();
}

// A message longer than any frame (kMaxMessageBytes) is cut off by libzmq before procam reads a
// byte: the connection drops, the node receives nothing, and the controller, reconnected, is
// answered again.
TEST(NodeTransport, AnOversizedMessageIsDroppedAndTheNodeGoesOn) {
  testing::TempDir dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  TestNode node(keys);
  zmq::context_t context;
  ControllerSocket controller(context, node.socket.endpoint(), &keys);
  ASSERT_TRUE(PingUntilReceived(controller, node));
  // Beyond the limit on the encrypted frame (kMaxMessageBytes + CURVE's 33 bytes).
  const std::string huge(static_cast<size_t>(kMaxMessageBytes) + 34, 'x');
  ASSERT_TRUE(controller.socket().send(zmq::buffer(huge), zmq::send_flags::none));
  EXPECT_FALSE(node.socket.Receive(1000));
  EXPECT_TRUE(PingUntilReceived(controller, node)) << node.Log();
  EXPECT_EQ(node.socket.malformed(), 0);  // never reached the parser
}

// The largest frame the protocol accepts (kMaxFramePatches patches, kMaxMessageBytes) reaches
// the node through CURVE, whose 33 bytes per message libzmq's size limit counts (it dropped the
// connection, without a line, for the last 6 patch counts before the protocol's limit); a frame
// beyond the protocol's limit is refused at the controller, by the encoder, in one line.
TEST(NodeTransport, TheLargestFrameOfTheProtocolPassesCurve) {
  testing::TempDir dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  TestNode node(keys);
  zmq::context_t context;
  ControllerSocket controller(context, node.socket.endpoint(), &keys);
  ASSERT_TRUE(PingUntilReceived(controller, node));
  Eigen::MatrixX3d emittance = Eigen::MatrixX3d::Constant(kMaxFramePatches, 3, 0.25);
  emittance(kMaxFramePatches - 1, 2) = 0.5;
  const std::string bytes = EncodeMessage(FrameMessage(7, emittance));
  ASSERT_EQ(static_cast<int64_t>(bytes.size()), kMaxMessageBytes);
  ASSERT_TRUE(controller.socket().send(zmq::buffer(bytes), zmq::send_flags::none));
  std::optional<Envelope> envelope = node.socket.Receive(10000);
  ASSERT_TRUE(envelope) << node.Log();
  EXPECT_EQ(envelope->message.type, MessageType::kFrame);
  EXPECT_EQ(envelope->message.sequence, 7u);
  ASSERT_EQ(envelope->message.emittance.size(), 3u * kMaxFramePatches);
  EXPECT_EQ(envelope->message.emittance.back(), 0.5);
  emittance.resize(0, 3);
  const Eigen::MatrixX3d beyond = Eigen::MatrixX3d::Constant(kMaxFramePatches + 1, 3, 0.25);
  try {
    EncodeMessage(FrameMessage(8, beyond));
    ADD_FAILURE() << "a frame beyond the protocol's limit was encoded";
  } catch (const std::invalid_argument& error) {
    const std::string what = error.what();
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    EXPECT_NE(what.find(std::to_string(kMaxFramePatches)), std::string::npos) << what;
  }
}

// Opens a TCP connection to the node's endpoint (tcp://127.0.0.1:PORT) and greets it as a
// ZeroMQ peer without CURVE does (ZMTP 3.0, mechanism NULL): the signature, then, once the node
// has sent its own and a moment later (a peer's round trip), the rest; closes once the node has
// hung up. Returns the connection's own port (what the node must name).
int ConnectWithoutCurve(const std::string& endpoint) {
  const int port = std::stoi(endpoint.substr(endpoint.rfind(':') + 1));
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  EXPECT_GE(fd, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  EXPECT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0);
  sockaddr_in own{};
  socklen_t size = sizeof(own);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&own), &size);
  timeval timeout{2, 0};  // every read bounded
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
  std::string greeting(64, '\0');
  greeting[0] = '\xff';
  greeting[9] = '\x7f';
  greeting[10] = 3;  // version 3.0
  greeting.replace(12, 4, "NULL");
  (void)::send(fd, greeting.data(), 10, MSG_NOSIGNAL);
  char buffer[256];
  (void)::recv(fd, buffer, 10, MSG_WAITALL);  // the node's signature
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  (void)::send(fd, greeting.data() + 10, greeting.size() - 10, MSG_NOSIGNAL);
  while (::recv(fd, buffer, sizeof(buffer), 0) > 0) {
  }
  ::close(fd);
  return ntohs(own.sin_port);
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  size_t start = 0;
  for (size_t end = text.find('\n'); end != std::string::npos; end = text.find('\n', start)) {
    lines.push_back(text.substr(start, end - start));
    start = end + 1;
  }
  return lines;
}

// The refusals the count lines of `log` count ("refused N more connections ...").
long long Counted(const std::string& log) {
  long long counted = 0;
  for (const std::string& line : Lines(log)) {
    const size_t at = line.find("node: refused ");
    if (at == std::string::npos || line.find(" more connection") == std::string::npos) continue;
    counted += std::stoll(line.substr(at + 14));
  }
  return counted;
}

// Waits (at most `seconds`) until `done` holds.
bool WaitFor(double seconds, const std::function<bool()>& done) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (!done()) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return true;
}

// A refused peer is named by its own address (IP:PORT), not the node's endpoint; a peer
// retrying (here 20 connections in a row) adds no line per try: after the first, the refusals
// are counted, in one line every kRefusalLogIntervalS.
TEST(NodeTransport, RefusalsNameThePeerAndRepeatsAreCounted) {
  testing::TempDir dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  TestNode node(keys);
  const std::string own_port = node.socket.endpoint().substr(node.socket.endpoint().rfind(':') + 1);
  const int first = ConnectWithoutCurve(node.socket.endpoint());
  ASSERT_TRUE(WaitFor(5, [&] { return node.socket.refused() >= 1; })) << node.Log();
  EXPECT_NE(node.Log().find("node: refused a peer at 127.0.0.1:" + std::to_string(first) +
                            ": its security handshake failed"),
            std::string::npos)
      << node.Log();
  EXPECT_EQ(node.Log().find(":" + own_port), std::string::npos) << node.Log();
  constexpr int kRetries = 20;
  for (int k = 0; k < kRetries; ++k) ConnectWithoutCurve(node.socket.endpoint());
  ASSERT_TRUE(WaitFor(5, [&] { return node.socket.refused() >= 1 + kRetries; })) << node.Log();
  // Every refusal after the first is counted, within an interval and a little.
  ASSERT_TRUE(WaitFor(kRefusalLogIntervalS + 3, [&] {
    return Counted(node.Log()) == node.socket.refused() - 1;
  })) << node.Log();
  EXPECT_EQ(node.socket.refused(), 1 + kRetries) << node.Log();
  const std::vector<std::string> lines = Lines(node.Log());
  EXPECT_GE(lines.size(), 2u) << node.Log();
  EXPECT_LE(lines.size(), 3u) << node.Log();  // not one a try
  for (size_t k = 1; k < lines.size(); ++k) {
    EXPECT_NE(lines[k].find(" more connection"), std::string::npos) << lines[k];
    EXPECT_NE(lines[k].find("from 127.0.0.1:"), std::string::npos) << lines[k];
  }
}

// Opens a TCP connection to the node's endpoint (tcp://127.0.0.1:PORT), waits `delay_ms`, sends
// `bytes` (none: it only connects), stops sending and waits, at most 2 s, for the node to hang
// up; closes. Returns the connection's own port (what the node must name).
int SendJunk(const std::string& endpoint, const std::string& bytes, int delay_ms = 0) {
  const int port = std::stoi(endpoint.substr(endpoint.rfind(':') + 1));
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  EXPECT_GE(fd, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  EXPECT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0);
  sockaddr_in own{};
  socklen_t size = sizeof(own);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&own), &size);
  timeval timeout{2, 0};  // every read bounded
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
  std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
  if (!bytes.empty()) (void)::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
  ::shutdown(fd, SHUT_WR);
  char buffer[256];
  while (::recv(fd, buffer, sizeof(buffer), 0) > 0) {
  }
  ::close(fd);
  return ntohs(own.sin_port);
}

// `count` bytes of a seeded generator, the first of them `first`.
std::string RandomBytes(size_t count, char first, uint32_t seed) {
  std::mt19937 generator(seed);
  std::string bytes(count, '\0');
  for (char& c : bytes) c = static_cast<char>(generator() & 0xff);
  if (count > 0) bytes[0] = first;
  return bytes;
}

// Connections that are not ZeroMQ at all (a web request, random bytes, bytes that begin as
// ZeroMQ's greeting does, a connection that sends nothing, three bytes): each is refused with a
// line naming the peer's own address and port, and the node goes on answering the rig's
// controller. (libzmq drops a connection whose first byte is not ZeroMQ's with no failure event:
// such peers went unlogged.) Each sends 100 ms after connecting, as a client that is not at once
// refused: one rejected within microseconds of connecting has closed before the node's monitor
// reads its address, and is logged as such (the flood below).
TEST(NodeTransport, JunkConnectionsAreLoggedWithThePeerAndTheNodeGoesOn) {
  testing::TempDir dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"a web request", "GET / HTTP/1.1\r\nHost: node\r\n\r\n"},
      {"4 KiB of random bytes", RandomBytes(4096, 'x', 1)},
      {"ZeroMQ's first byte, then random bytes", RandomBytes(200, '\xff', 2)},
      {"nothing", ""},
      {"three bytes", std::string("\x01\x02\x03", 3)},
  };
  for (const auto& [what, bytes] : cases) {
    TestNode node(keys);  // its first refusal is logged in full
    const int port = SendJunk(node.socket.endpoint(), bytes, /*delay_ms=*/100);
    ASSERT_TRUE(WaitFor(5, [&] { return node.socket.refused() >= 1; })) << what << "\n"
                                                                        << node.Log();
    EXPECT_NE(node.Log().find("node: refused a peer at 127.0.0.1:" + std::to_string(port) + ": "),
              std::string::npos)
        << what << "\n"
        << node.Log();
    zmq::context_t context;
    ControllerSocket controller(context, node.socket.endpoint(), &keys);
    EXPECT_TRUE(PingUntilReceived(controller, node)) << what << "\n" << node.Log();
    EXPECT_EQ(node.socket.refused(), 1) << what << "\n" << node.Log();
    EXPECT_EQ(Lines(node.Log()).size(), 1u) << what << "\n" << node.Log();
  }
}

// A flood of junk connections (here 200 in a row) adds no line per connection: after the first,
// they are counted, one line every kRefusalLogIntervalS; the node still answers its controller.
TEST(NodeTransport, AFloodOfJunkConnectionsIsCountedAndTheNodeGoesOn) {
  testing::TempDir dir;
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  TestNode node(keys);
  constexpr int kConnections = 200;
  for (int k = 0; k < kConnections; ++k) {
    SendJunk(node.socket.endpoint(), RandomBytes(64 + k, 'G', static_cast<uint32_t>(k)));
  }
  ASSERT_TRUE(WaitFor(5, [&] { return node.socket.refused() >= kConnections; })) << node.Log();
  ASSERT_TRUE(WaitFor(kRefusalLogIntervalS + 3, [&] {
    return Counted(node.Log()) == node.socket.refused() - 1;
  })) << node.Log();
  EXPECT_EQ(node.socket.refused(), kConnections) << node.Log();
  const std::vector<std::string> lines = Lines(node.Log());
  EXPECT_GE(lines.size(), 2u) << node.Log();
  EXPECT_LE(lines.size(), 3u) << node.Log();
  zmq::context_t context;
  ControllerSocket controller(context, node.socket.endpoint(), &keys);
  EXPECT_TRUE(PingUntilReceived(controller, node)) << node.Log();
  EXPECT_EQ(node.socket.refused(), kConnections) << node.Log();
}

TEST(NodeTransport, KeysAreMadeOnceAndReadWithErrorsNamingTheFile) {
  testing::TempDir dir;
  const RigKeys made = MakeRigKeys(dir.path(), false);
  EXPECT_EQ(made.controller.public_key.size(), 40u);
  EXPECT_NE(made.controller.public_key, made.node.public_key);
  struct stat info {};
  ASSERT_EQ(::stat((dir / "keys" / "node.key").c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 0777, 0600u);
  try {
    MakeRigKeys(dir.path(), false);
    ADD_FAILURE() << "replaced existing keys";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("keys/controller.key: the rig already has keys"),
              std::string::npos)
        << e.what();
  }
  const RigKeys node = ReadRigKeys(dir.path(), KeyRole::kNode);
  EXPECT_EQ(node.node.secret_key, made.node.secret_key);
  EXPECT_TRUE(node.controller.secret_key.empty());  // a display PC does not need it
  const RigKeys controller = ReadRigKeys(dir.path(), KeyRole::kController);
  EXPECT_EQ(controller.controller.secret_key, made.controller.secret_key);
  std::filesystem::remove(dir / "keys" / "controller.key");
  try {
    ReadRigKeys(dir.path(), KeyRole::kController);
    ADD_FAILURE() << "read a missing key";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("controller.key: no such key file"), std::string::npos)
        << e.what();
  }
  dir.Write("keys/node.pub", "too short\n");
  try {
    ReadRigKeys(dir.path(), KeyRole::kNode);
    ADD_FAILURE() << "read a bad key";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("node.pub: not a CURVE key"), std::string::npos)
        << e.what();
  }
  const RigKeys replaced = MakeRigKeys(dir.path(), true);
  EXPECT_NE(replaced.node.public_key, made.node.public_key);
}

}  // namespace
}  // namespace procam
