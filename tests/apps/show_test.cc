// procam play steered over OSC on 127.0.0.1, as a show controller would (docs/show.md): the test
// runs `procam play` on a video it wrote, sends it pause, fade to black, fade back and play from a
// UDP socket of its own, asks for the status after each, and checks on result.json's per-frame
// records that each change shows within two frames of the frame the status reported: the
// status's frame number is the frame under way when the command arrived (both travel the same
// socket in order), so no wall-clock deadline is asserted. Every wait is a bounded loop.
#include <arpa/inet.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <regex>
#include <set>
#include <thread>

#include "base/io.h"
#include "datasets_synthetic/scene_files.h"
#include "nodes/osc.h"
#include "nodes/playlist.h"
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
    for (size_t k = 0; k < types.size(); ++k)
      message.arguments.push_back({types[k], numbers[k], ""});
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

// ListeningPort once play has logged it: waits (bounded, 60 s) for the line; 0 if it never came.
int WaitForListeningPort(const fs::path& log) {
  int port = 0;
  for (int attempt = 0; attempt < 1200 && port == 0; ++attempt) {
    port = ListeningPort(log);
    if (port == 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return port;
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
  const int port = WaitForListeningPort(log);
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

// Raw frames piped on standard input (--desired stdin:32x24), paced and then in a burst: every
// frame that came is shown or was replaced by a newer one before the show took it (counted), the
// last one is shown, and each shown frame's desired colour is the one the test wrote into it (even
// frames red, odd ones blue).
TEST(Show, PlayShowsTheNewestFramePipedOnStandardInput) {
  testing::TempDir dir;
  const std::string scene = WriteRoom(dir.path());
  const int width = 32, height = 24, paced = 12, burst = 5;
  auto frame_bytes = [&](int k) {
    std::string bytes(3 * width * height, char(30));  // R, G, B
    for (size_t p = k % 2 == 0 ? 0 : 2; p < bytes.size(); p += 3) bytes[p] = char(220);
    return bytes;
  };
  std::string burst_bytes;
  for (int k = 0; k < paced; ++k)
    WriteFileAtomically(dir / fmt::format("f{}.rgb", k), frame_bytes(k));
  for (int k = paced; k < paced + burst; ++k) burst_bytes += frame_bytes(k);
  WriteFileAtomically(dir / "burst.rgb", burst_bytes);
  const std::string feed = "{ for k in $(seq 0 " + std::to_string(paced - 1) + "); do cat " +
                           (dir / "f").string() + "$k.rgb; sleep 0.15; done; cat " +
                           (dir / "burst.rgb").string() + "; }";
  const testing::CommandRun run = testing::RunShell(
      feed + " | timeout 120 " + std::string(std::getenv("PROCAM_BINARY")) + " play " + scene +
      " --rig " + dir.path().string() + " --desired stdin:32x24 --fps 20 --display memory,memory" +
      " --out " + (dir / "play").string());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir / "play" / "result.json"));
  EXPECT_EQ(result.at("frames_received"), paced + burst) << run.output;
  const nlohmann::json& frames = result.at("frames");
  ASSERT_FALSE(frames.empty());
  std::set<int> shown;
  int previous = -1;
  for (const nlohmann::json& frame : frames) {
    const int source = frame.at("source");
    EXPECT_GE(source, previous);  // a frame holds until a newer one comes, never goes back
    previous = source;
    shown.insert(source);
    const std::vector<double> desired = frame.at("desired_mean");
    if (source % 2 == 0) {
      EXPECT_GT(desired[0], 2.0 * desired[2]) << "frame " << frame.at("frame");
    } else {
      EXPECT_GT(desired[2], 2.0 * desired[0]) << "frame " << frame.at("frame");
    }
  }
  EXPECT_EQ(*shown.rbegin(), paced + burst - 1);
  EXPECT_EQ(static_cast<int>(shown.size()) + result.at("frames_replaced").get<int>(),
            paced + burst);
}

// Show options that cannot work are refused at once, in one line naming the option, and nothing
// is written: a sender that is not an IPv4 address or range, an OSC address that is not
// IPV4:PORT or not this machine's, a raw-frame size that is not one, a playlist with a mistake.
TEST(Show, BadShowOptionsAreOneLineNamingTheOption) {
  testing::TempDir dir;
  const std::string scene = WriteRoom(dir.path());
  WriteFileAtomically(dir / "show.json",
                      R"({"format_version": 1, "contents": {}, "surfaces": [{"surface": "floor",
                          "content": "rain"}]})");
  const std::string play = "play " + scene + " --rig " + dir.path().string() +
                           " --display memory,memory --out " + (dir / "play").string() + " ";
  const std::string video = " --desired stdin:32x24 < /dev/null";
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr(play + "--osc 127.0.0.1:0 --osc-allow 127.0.0.1,localhost" + video),
      "--osc-allow: 'localhost' is not an IPv4 address or range", "--osc-allow localhost");
  testing::ExpectOneErrorLine(testing::RunProcamStderr(play + "--osc 127.0.0.1:99999" + video),
                              "--osc: 127.0.0.1:99999: not IPV4:PORT", "--osc port");
  testing::ExpectOneErrorLine(testing::RunProcamStderr(play + "--osc 192.0.2.1:9000" + video),
                              "--osc: 192.0.2.1:9000: cannot listen there", "--osc not local");
  testing::ExpectOneErrorLine(testing::RunProcamStderr(play + "--desired stdin:32"),
                              "--desired: stdin:32: raw frames on standard input are "
                              "stdin:WIDTHxHEIGHT",
                              "--desired stdin:32");
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr(play + "--playlist " + (dir / "show.json").string()),
      (dir / "show.json").string() + ": surfaces[0].content: no content 'rain'", "playlist");
  EXPECT_FALSE(fs::exists(dir / "play" / "result.json"));
}

// A capture device as a live source (--desired camera:URI), here capture/'s software test camera
// at 30 fps: the show takes its newest frame at each of its own, the frame numbers only go up,
// and --frames 10 ends the show after 10 of the camera's frames. A camera that goes away mid-show
// ends the show, with one line naming it.
TEST(Show, PlayFollowsALiveCamera) {
  testing::TempDir dir;
  const std::string scene = WriteRoom(dir.path());
  const std::string play = "timeout 120 " + std::string(std::getenv("PROCAM_BINARY")) + " play " +
                           scene + " --rig " + dir.path().string() + " --fps 20" +
                           " --display memory,memory --out " + (dir / "play").string();
  const testing::CommandRun run = testing::RunShell(
      play + " --frames 10 --desired 'camera:test:live?format=BGR8&width=32&height=24&fps=30'");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  nlohmann::json result = nlohmann::json::parse(ReadFile(dir / "play" / "result.json"));
  const nlohmann::json& frames = result.at("frames");
  ASSERT_FALSE(frames.empty()) << run.output;
  std::set<int> shown;
  for (size_t k = 0; k < frames.size(); ++k) {
    const int source = frames[k].at("source");
    if (k > 0) {
      EXPECT_GE(source, frames[k - 1].at("source").get<int>());
    }
    shown.insert(source);
  }
  EXPECT_EQ(shown.size(), 10u);
  EXPECT_LE(static_cast<int>(shown.size()) + result.at("frames_replaced").get<int>(),
            result.at("frames_received").get<int>());

  const testing::CommandRun gone = testing::RunShell(
      play + " --desired 'camera:test:live?format=BGR8&width=32&height=24&fps=30" +
      "&fault=disconnect&fault_after=5'");
  ASSERT_EQ(gone.exit_code, 0) << gone.output;
  EXPECT_NE(gone.output.find("play: test:live?"), std::string::npos) << gone.output;
  result = nlohmann::json::parse(ReadFile(dir / "play" / "result.json"));
  EXPECT_EQ(result.at("frames_received"), 5) << gone.output;
  EXPECT_EQ(result.at("frames").back().at("source"), 4) << gone.output;
}

// A playlist (written by its owner's writer) puts a red video on the back wall and a green image
// on the floor, in their texture coordinates; /procam/surface switches the back wall to a blue
// video over OSC. Each frame's record says what every surface showed; its patches' desired colour
// is the content's (sRGB decoded, times the scene's white), and the switch shows within two
// frames of the status frame.
TEST(Show, PlaylistContentPerSurfaceSwitchedOverOsc) {
  testing::TempDir dir;
  const std::string scene = WriteRoom(dir.path());
  const double white = nlohmann::json::parse(ReadFile(scene)).value("white", 1.0);
  auto write_video = [&](const std::string& name, const cv::Scalar& bgr) {
    cv::VideoWriter writer((dir / name).string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                           cv::Size(16, 16));
    ASSERT_TRUE(writer.isOpened());
    for (int k = 0; k < 8; ++k) writer.write(cv::Mat(16, 16, CV_8UC3, bgr));
  };
  write_video("red.avi", cv::Scalar(30, 30, 220));
  write_video("blue.avi", cv::Scalar(220, 30, 30));
  ASSERT_TRUE(
      cv::imwrite((dir / "green.png").string(), cv::Mat(8, 8, CV_8UC3, cv::Scalar(40, 200, 30))));
  Playlist playlist;
  playlist.contents = {{"red", PlaylistContent::Kind::kVideo, "red.avi", {}, true},
                       {"blue", PlaylistContent::Kind::kVideo, "blue.avi", {}, false},
                       {"green", PlaylistContent::Kind::kImage, "green.png", {}, false}};
  playlist.surfaces = {{"back wall", "red", 0.0}, {"floor", "green", 0.0}};
  WritePlaylist(dir / "show.json", playlist);

  const fs::path log = dir / "play.log";
  std::thread play([&] {
    testing::RunShell("timeout 120 " + std::string(std::getenv("PROCAM_BINARY")) + " play " +
                      scene + " --rig " + dir.path().string() + " --playlist " +
                      (dir / "show.json").string() +
                      " --fps 10 --display memory,memory --osc 127.0.0.1:0 --out " +
                      (dir / "play").string() + " > " + log.string() + " 2>&1");
  });
  const int port = WaitForListeningPort(log);
  ASSERT_GT(port, 0) << ReadFile(log);
  OscClient client;
  // Past the red video's 8 frames: it loops.
  WaitForFrame(client, port, 10);
  OscMessage message;
  message.address = "/procam/surface";
  message.types = "ss";
  message.arguments = {{'s', 0, "back wall"}, {'s', 0, "blue"}};
  client.Send(port, EncodeOscMessage(message));
  const int switched_at = WaitForFrame(client, port, 0);
  WaitForFrame(client, port, switched_at + 4);
  client.Send(port, "/procam/stop");
  play.join();

  const std::string output = ReadFile(log);
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir / "play" / "result.json"));
  const nlohmann::json& frames = result.at("frames");
  const int switched = AppliedAt(frames, "surface back wall blue");
  ASSERT_GT(switched, 0) << output;
  EXPECT_LE(switched, switched_at + 2);
  auto linear = [](int code) {  // the sRGB transfer function, written out
    const double c = code / 255.0;
    return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
  };
  int looped = 0;
  for (int k = 0; k < static_cast<int>(frames.size()); ++k) {
    const nlohmann::json& surfaces = frames[k].at("surfaces");
    // The PNG is lossless: the floor's desired colour is green's exactly.
    const std::vector<double> floor = surfaces.at("floor").at("desired_mean");
    EXPECT_NEAR(floor[0], white * linear(30), 1e-6) << "frame " << k;
    EXPECT_NEAR(floor[1], white * linear(200), 1e-6) << "frame " << k;
    EXPECT_NEAR(floor[2], white * linear(40), 1e-6) << "frame " << k;
    const nlohmann::json& wall = surfaces.at("back wall");
    const std::vector<double> mean = wall.at("desired_mean");
    // MJPG is lossy: the dominant channel within 10% of the colour written.
    if (k < switched) {
      EXPECT_EQ(wall.at("content"), "red") << "frame " << k;
      EXPECT_NEAR(mean[0], white * linear(220), 0.1 * white * linear(220)) << "frame " << k;
      EXPECT_GT(mean[0], 5 * mean[2]) << "frame " << k;
      if (wall.at("frame").get<int>() <
          frames[std::max(0, k - 1)].at("surfaces").at("back wall").at("frame").get<int>())
        ++looped;
    } else {
      EXPECT_EQ(wall.at("content"), "blue") << "frame " << k;
      EXPECT_NEAR(mean[2], white * linear(220), 0.1 * white * linear(220)) << "frame " << k;
      EXPECT_GT(mean[2], 5 * mean[0]) << "frame " << k;
    }
  }
  EXPECT_GE(looped, 1);  // the red video (8 frames, "loop": true) started again
}

}  // namespace
}  // namespace procam
