// The display nodes' transport on 127.0.0.1: only the rig's controller is answered (CURVE with a
// ZAP handler), anything else is refused and logged, malformed messages are dropped without
// stopping the node, and the keys are made and read with errors naming the file.
#include "nodes/transport.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <mutex>

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
  const std::string huge(static_cast<size_t>(kMaxMessageBytes) + 1, 'x');
  ASSERT_TRUE(controller.socket().send(zmq::buffer(huge), zmq::send_flags::none));
  EXPECT_FALSE(node.socket.Receive(1000));
  EXPECT_TRUE(PingUntilReceived(controller, node)) << node.Log();
  EXPECT_EQ(node.socket.malformed(), 0);  // never reached the parser
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
