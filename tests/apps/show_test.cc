// procam play steered over OSC on 127.0.0.1, as a show controller would (docs/show.md): the test
// runs `procam play` on a video it wrote, sends it pause, fade to black, fade back and play from a
// UDP socket of its own, asks for the status after each, and checks on result.json's per-frame
// records that each change shows within two frames of the frame the status reported: the
// status's frame number is the frame under way when the command arrived (both travel the same
// socket in order), so no wall-clock deadline is asserted. Every wait is a bounded loop.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <opencv2/videoio.hpp>
#include <regex>
#include <thread>

#include "base/io.h"
#include "datasets_synthetic/scene_files.h"
#include "nodes/osc.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

namespace fs = std::filesystem;

// tiny_box as a scene file and a rig directory with its camera and projectors.
std::string WriteRoom(const fs::path& dir) {
  const fs::path scene = WriteSyntheticSceneFile("tiny_box", 80, dir);
  const nlohmann::json file = nlohmann::json::parse(ReadFile(scene));
  WriteFileAtomically(dir / "rig.json",
                      nlohmann::json{{"format_version", 1},
                                     {"camera", {{"model", file.at("cameras").at(0).at("model")}}},
                                     {"projectors", file.at("projectors")}}
                          .dump());
  return scene.string();
}

// A UDP socket on 127.0.0.1 (or another loopback address) that sends OSC to play and reads its
// replies.
class OscClient {
 public:
  explicit OscClient(const std::string& host = "127.0.0.1") {
    socket_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    inet_pton(AF_INET, host.c_str(), &address.sin_addr);
    EXPECT_EQ(::bind(socket_, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0);
  }
  ~OscClient() { ::close(socket_); }

  void Send(int port, const std::vector<uint8_t>& bytes) {
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(static_cast<uint16_t>(port));
    inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
    ASSERT_EQ(::sendto(socket_, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&to),
                       sizeof(to)),
              static_cast<ssize_t>(bytes.size()));
  }
  void Send(int port, const std::string& address, const std::string& types = "",
            const std::vector<double>& numbers = {}) {
    OscMessage message;
    message.address = address;
    message.types = types;
    for (size_t k = 0; k < types.size(); ++k) message.arguments.push_back({types[k], numbers[k], ""});
    Send(port, EncodeOscMessage(message));
  }
  // /procam/status and its reply (empty if none came within 200 ms).
  std::optional<OscMessage> Status(int port) {
    Send(port, "/procam/status");
    std::vector<uint8_t> buffer(2048);
    pollfd poll_fd{socket_, POLLIN, 0};
    if (::poll(&poll_fd, 1, 200) <= 0) return std::nullopt;
    const ssize_t size = ::recv(socket_, buffer.data(), buffer.size(), 0);
    OscMessage reply;
    std::string why;
    if (size <= 0 || !DecodeOscPacket(buffer.data(), size, &reply, &why)) return std::nullopt;
    return reply;
  }

 private:
  int socket_ = -1;
};

// The port play's OSC control listens on, from its log line (play binds port 0: a free one).
int ListeningPort(const fs::path& log) {
  std::ifstream file(log);
  const std::string text((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  std::smatch match;
  static const std::regex line("osc: listening on 127\\.0\\.0\\.1:([0-9]+)");
  return std::regex_search(text, match, line) ? std::stoi(match[1]) : 0;
}

// The frame the status reports (frames shown), after waiting (bounded) for it to reach `at_least`.
int WaitForFrame(OscClient& client, int port, int at_least) {
  for (int attempt = 0; attempt < 600; ++attempt) {
    const std::optional<OscMessage> status = client.Status(port);
    if (status && status->types == "ifiiiif" && status->arguments[0].number >= at_least)
      return static_cast<int>(status->arguments[0].number);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ADD_FAILURE() << "play never reached frame " << at_least;
  return -1;
}

// The first frame whose record applied `command` (-1 if none).
int AppliedAt(const nlohmann::json& frames, const std::string& command) {
  for (size_t k = 0; k < frames.size(); ++k)
    if (frames[k].contains("osc"))
      for (const nlohmann::json& applied : frames[k].at("osc"))
        if (applied.at("command") == command) return static_cast<int>(k);
  return -1;
}

TEST(Show, PlayFollowsPauseFadeAndPlayOverOscWithinTwoFrames) {
  testing::TempDir dir;
  const std::string scene = WriteRoom(dir.path());
  const fs::path video = dir / "content.avi";
  {
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                           cv::Size(32, 24));
    ASSERT_TRUE(writer.isOpened());
    for (int k = 0; k < 400; ++k)
      writer.write(cv::Mat(24, 32, CV_8UC3, cv::Scalar(40 + k % 50, 120, 200 - k % 50)));
  }
  const fs::path log = dir / "play.log";
  std::thread play([&] {
    // timeout: a play that never hears /procam/stop ends anyway (the test fails on its result).
    testing::RunShell("timeout 120 " + std::string(std::getenv("PROCAM_BINARY")) + " play " +
                      scene + " --rig " + dir.path().string() + " --desired " + video.string() +
                      " --fps 10 --display memory,memory --osc 127.0.0.1:0 --out " +
                      (dir / "play").string() + " > " + log.string() + " 2>&1");
  });
  int port = 0;
  for (int attempt = 0; attempt < 1200 && port == 0; ++attempt) {
    port = ListeningPort(log);
    if (port == 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_GT(port, 0) << ReadFile(log);
  OscClient client, stranger("127.0.0.2");
  WaitForFrame(client, port, 3);
  // Ignored, each in one line: a level out of range, a sender not allowed (the default allows
  // 127.0.0.1 only), an address not procam's.
  client.Send(port, "/procam/fade", "f", {2.0});
  stranger.Send(port, "/procam/pause");
  client.Send(port, "/other/pause");
  client.Send(port, "/procam/pause");
  const int paused_at = WaitForFrame(client, port, 0);
  const int black_after = WaitForFrame(client, port, paused_at + 4);
  client.Send(port, "/procam/fade", "ff", {0.0, 0.0});
  const int black_at = WaitForFrame(client, port, 0);
  const int back_after = WaitForFrame(client, port, black_at + 4);
  client.Send(port, "/procam/fade", "ff", {1.0, 0.3});
  client.Send(port, "/procam/play");
  const int playing_at = WaitForFrame(client, port, 0);
  WaitForFrame(client, port, playing_at + 8);
  client.Send(port, "/procam/stop");
  play.join();
  (void)black_after;
  (void)back_after;

  const std::string output = ReadFile(log);
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir / "play" / "result.json"));
  EXPECT_TRUE(result.at("stopped").get<bool>()) << output;
  EXPECT_EQ(result.at("osc_refused"), 3) << output;
  auto lines_with = [&](const std::string& text) {
    int count = 0;
    for (size_t at = output.find(text); at != std::string::npos; at = output.find(text, at + 1))
      ++count;
    return count;
  };
  EXPECT_EQ(lines_with("osc: ignored a message from 127.0.0.1:"), 2) << output;
  EXPECT_EQ(lines_with("/procam/fade: argument 1 (level) must be in [0, 1], got 2"), 1) << output;
  EXPECT_EQ(lines_with("osc: ignored a message from 127.0.0.2:"), 1) << output;
  EXPECT_EQ(lines_with("not an allowed sender"), 1) << output;
  EXPECT_EQ(lines_with("/other/pause: not an address of procam's"), 1) << output;
  EXPECT_EQ(lines_with("stopped by /procam/stop"), 1) << output;

  const nlohmann::json& frames = result.at("frames");
  const int pause = AppliedAt(frames, "pause"), black = AppliedAt(frames, "fade 0 0"),
            back = AppliedAt(frames, "fade 1 0.3"), resume = AppliedAt(frames, "play");
  ASSERT_GE(pause, 0) << output;
  ASSERT_GT(black, pause);
  ASSERT_GE(resume, black);
  EXPECT_EQ(back, resume);  // sent one after the other: taken at the same frame or the next
  // Within two frames of the frame under way when each arrived (the status's).
  EXPECT_LE(pause, paused_at + 2);
  EXPECT_LE(black, black_at + 2);
  EXPECT_LE(resume, playing_at + 2);
  // Before the pause the source advances; paused, it holds; after play it advances again.
  const int held = frames[pause].at("source");
  for (int k = 1; k < pause; ++k)
    EXPECT_GT(frames[k].at("source"), frames[k - 1].at("source")) << "frame " << k;
  for (int k = pause; k < resume; ++k) {
    EXPECT_TRUE(frames[k].at("paused").get<bool>()) << "frame " << k;
    EXPECT_EQ(frames[k].at("source"), held) << "frame " << k;
  }
  for (int k = resume + 1; k < static_cast<int>(frames.size()); ++k) {
    EXPECT_FALSE(frames[k].at("paused").get<bool>()) << "frame " << k;
    EXPECT_GT(frames[k].at("source"), frames[k - 1].at("source")) << "frame " << k;
  }
  // Fade to black: the desired appearance scaled to 0 is solved as black (no light); fading
  // back over 0.3 s at 10 fps rises through levels in (0, 1) to the light of before.
  const double lit = frames[black - 1].at("emittance_mean");
  EXPECT_GT(lit, 0.05);
  for (int k = black; k < resume; ++k) {
    EXPECT_EQ(frames[k].at("fade"), 0.0) << "frame " << k;
    EXPECT_LT(frames[k].at("emittance_mean").get<double>(), 0.02 * lit) << "frame " << k;
  }
  double level = 0.0;
  int rising = 0;
  for (int k = resume; k < static_cast<int>(frames.size()); ++k) {
    const double fade = frames[k].at("fade");
    EXPECT_GE(fade, level) << "frame " << k;
    if (fade > 0.0 && fade < 1.0) ++rising;
    level = fade;
  }
  EXPECT_GE(rising, 1);
  EXPECT_EQ(level, 1.0);
  EXPECT_NEAR(frames.back().at("emittance_mean").get<double>(), lit, 0.1 * lit);
}

}  // namespace
}  // namespace procam
