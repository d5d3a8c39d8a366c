// A display node in this process (inproc://, its own thread) with outputs the test controls: a
// monitor that disappears mid-show is reported to the controller and the node goes on with its
// other projector; play's mapping of a desired image onto the patches is the per-patch mean.
#include "nodes/node.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <mutex>
#include <opencv2/videoio.hpp>
#include <stdexcept>
#include <thread>

#include "base/io.h"
#include "datasets_synthetic/scene_files.h"
#include "nodes/controller.h"
#include "nodes/play.h"
#include "nodes/transport.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

// Keeps what it presents; after `fail_after` presents its monitor is gone: Fault says so between
// frames, or, `in_draw`, the next Draw throws (a monitor unplugged while a frame is under way).
class VanishingOutput : public NodeOutput {
 public:
  VanishingOutput(std::string name, int fail_after, int* presented, bool in_draw = false)
      : name_(std::move(name)), fail_after_(fail_after), presented_(presented), in_draw_(in_draw) {}
  std::string Describe() const override { return "test:" + name_; }
  void Draw(const ProjectorImage&) override {
    if (in_draw_ && Gone()) throw std::runtime_error(Why());
  }
  void Present(uint64_t) override { ++*presented_; }
  std::string Fault() override { return !in_draw_ && Gone() ? Why() : ""; }

 private:
  bool Gone() const { return fail_after_ >= 0 && *presented_ >= fail_after_; }
  std::string Why() const { return "monitor TEST-" + name_ + " disappeared"; }
  std::string name_;
  int fail_after_;
  int* presented_;
  bool in_draw_;
};

// tiny_box as a scene file and a rig directory holding its projectors.
std::string WriteRig(const testing::TempDir& dir) {
  const std::filesystem::path scene = WriteSyntheticSceneFile("tiny_box", 80, dir.path());
  const nlohmann::json file = nlohmann::json::parse(ReadFile(scene));
  WriteFileAtomically(
      dir / "rig.json",
      nlohmann::json{{"format_version", 1}, {"projectors", file.at("projectors")}}.dump());
  return scene.string();
}

// Shows 5 frames on a node whose left monitor goes after 2 (found between frames, or by a draw
// that throws) and checks that it is reported once and the node goes on with the right one.
void ShowWithAVanishingMonitor(bool in_draw) {
  testing::TempDir dir;
  const std::string scene = WriteRig(dir);
  int presented_left = 0, presented_right = 0;
  NodeOptions options;
  options.name = "n";
  options.rig_dir = dir.path();
  options.scene = scene;
  options.projectors = {"left", "right"};
  options.listen = "inproc://node-test";
  zmq::context_t context;
  std::atomic<bool> stop{false};
  std::thread node([&] {
    RunNode(
        context, options,
        [&](const std::vector<Projector>&) {
          std::vector<std::unique_ptr<NodeOutput>> outputs;
          outputs.push_back(
              std::make_unique<VanishingOutput>("left", 2, &presented_left, in_draw));
          outputs.push_back(std::make_unique<VanishingOutput>("right", -1, &presented_right));
          return outputs;
        },
        stop);
  });
  std::mutex mutex;
  std::string log;
  ControllerOptions controller_options;
  controller_options.setup = {{"setup", "test"}, {"target_patches", 80}, {"patches", 64}};
  controller_options.setup_timeout_s = 30.0;
  controller_options.log = [&](const std::string& line) {
    std::lock_guard<std::mutex> lock(mutex);
    log += line + "\n";
  };
  Controller controller(context, {{"n", "inproc://node-test"}}, nullptr, controller_options);
  bool connected = true;
  try {
    controller.Connect();
  } catch (const IoError& e) {
    ADD_FAILURE() << e.what();
    connected = false;
  }
  Eigen::MatrixX3d emittance = Eigen::MatrixX3d::Constant(64, 3, 0.5);
  for (uint64_t frame = 0; connected && frame < 5; ++frame) {
    const FrameReport report = controller.Show(frame, emittance);
    EXPECT_EQ(report.shown, 1) << log;  // the node goes on
  }
  stop = true;
  node.join();
  EXPECT_EQ(presented_right, 5);
  EXPECT_EQ(presented_left, 2);  // not shown on once its monitor was gone
  EXPECT_NE(log.find("node n says: projector left: monitor TEST-left disappeared"),
            std::string::npos)
      << log;
  EXPECT_EQ(log.find("right:"), std::string::npos) << log;
  EXPECT_EQ(log.find("lost"), std::string::npos) << log;
  size_t reports = 0;
  for (size_t at = log.find("says: projector left"); at != std::string::npos;
       at = log.find("says: projector left", at + 1))
    ++reports;
  EXPECT_EQ(reports, 1u) << log;  // once
}

TEST(Node, AMonitorThatDisappearsIsReportedAndTheOtherProjectorGoesOn) {
  ShowWithAVanishingMonitor(/*in_draw=*/false);
}

// The monitor goes while a frame is drawn: the node still answers that frame (the controller
// does not lose it) and shows it on its other projector.
TEST(Node, AMonitorThatGoesDuringADrawIsReportedAndTheFrameStillShown) {
  ShowWithAVanishingMonitor(/*in_draw=*/true);
}

TEST(Node, ASetupTheRoomDoesNotGiveIsRefusedNamingTheScene) {
  testing::TempDir dir;
  const std::string scene = WriteRig(dir);
  NodeOptions options;
  options.rig_dir = dir.path();
  options.scene = scene;
  options.projectors = {"left"};
  options.listen = "inproc://node-test-2";
  zmq::context_t context;
  std::atomic<bool> stop{false};
  std::thread node([&] {
    RunNode(
        context, options,
        [](const std::vector<Projector>&) {
          std::vector<std::unique_ptr<NodeOutput>> outputs;
          outputs.push_back(std::make_unique<RecordOutput>());
          return outputs;
        },
        stop);
  });
  ControllerOptions controller_options;
  controller_options.setup = {
      {"setup", "x"}, {"target_patches", 80}, {"patches", 99}};  // not tiny_box's
  controller_options.setup_timeout_s = 30.0;
  Controller controller(context, {{"n", "inproc://node-test-2"}}, nullptr, controller_options);
  try {
    controller.Connect();
    ADD_FAILURE() << "a node set up on another room";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "tiny_box.json: subdivides into 64 patches for target 80, the controller's "
                  "room into 99"),
              std::string::npos)
        << e.what();
  }
  stop = true;
  node.join();
}

// A node serves one controller at a time. A second one holding the rig's key is refused while the
// first is served: one line at the node naming both, and the second's setup ends at once with
// one line naming both too; the first's show goes on. Once the first ends its show, another is
// served. Everything on 127.0.0.1; every wait bounded.
TEST(Node, ASecondControllerIsRefusedWhileTheFirstIsServed) {
  testing::TempDir dir;
  const std::string scene = WriteRig(dir);
  const RigKeys keys = MakeRigKeys(dir.path(), false);
  std::mutex mutex;
  std::string log;
  const auto node_log = [&] {
    std::lock_guard<std::mutex> lock(mutex);
    return log;
  };
  NodeOptions options;
  options.name = "n";
  options.rig_dir = dir.path();
  options.scene = scene;
  options.projectors = {"left", "right"};
  options.listen = "tcp://127.0.0.1:*";
  options.gpu = false;
  options.log = [&](const std::string& line) {
    std::lock_guard<std::mutex> lock(mutex);
    log += line + "\n";
  };
  zmq::context_t node_context, context;
  std::atomic<bool> stop{false};
  std::thread node([&] {
    RunNode(
        node_context, options,
        [](const std::vector<Projector>&) {
          std::vector<std::unique_ptr<NodeOutput>> outputs;
          outputs.push_back(std::make_unique<RecordOutput>());
          outputs.push_back(std::make_unique<RecordOutput>());
          return outputs;
        },
        stop);
  });
  const auto wait_for = [&](const std::string& text) {
    for (int k = 0; k < 500 && node_log().find(text) == std::string::npos; ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    return node_log().find(text) != std::string::npos;
  };
  ASSERT_TRUE(wait_for("listening at tcp://127.0.0.1:")) << node_log();
  const std::string listening = node_log().substr(node_log().find("tcp://127.0.0.1:"));
  const std::string endpoint = listening.substr(0, listening.find(','));
  const auto controller_options = [](const std::string& id) {
    ControllerOptions controller;
    controller.setup = {{"setup", id}, {"target_patches", 80}, {"patches", 64}};
    controller.setup_timeout_s = 30.0;
    return controller;
  };
  const Eigen::MatrixX3d emittance = Eigen::MatrixX3d::Constant(64, 3, 0.5);
  {
    Controller first(context, {{"n", endpoint}}, &keys, controller_options("first"));
    ASSERT_NO_THROW(first.Connect()) << node_log();
    EXPECT_EQ(first.Show(0, emittance).shown, 1) << node_log();
    const auto start = std::chrono::steady_clock::now();
    try {
      Controller second(context, {{"n", endpoint}}, &keys, controller_options("second"));
      second.Connect();
      ADD_FAILURE() << "a second controller was served\n" << node_log();
    } catch (const IoError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("serves the controller at 127.0.0.1:"), std::string::npos) << what;
      EXPECT_NE(what.find("the controller at 127.0.0.1:"),
                what.rfind("the controller at 127.0.0.1:"))
          << what;  // both named
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    }
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
              10.0);
    const std::string refused = node_log();
    size_t lines = 0;
    for (size_t at = refused.find("refused a second controller at 127.0.0.1:");
         at != std::string::npos; at = refused.find("refused a second controller", at + 1))
      ++lines;
    EXPECT_EQ(lines, 1u) << refused;
    EXPECT_NE(refused.find("it serves the controller at 127.0.0.1:"), std::string::npos) << refused;
    EXPECT_EQ(first.Show(1, emittance).shown, 1) << node_log();  // the first's show goes on
    first.Stop();
    ASSERT_TRUE(wait_for("stopped by the controller")) << node_log();
  }
  Controller third(context, {{"n", endpoint}}, &keys, controller_options("third"));
  ASSERT_NO_THROW(third.Connect()) << node_log();
  EXPECT_EQ(third.Show(0, emittance).shown, 1) << node_log();
  stop = true;
  node.join();
}

TEST(Node, AProjectorNotInTheRigIsRefusedAtStart) {
  testing::TempDir dir;
  const std::string scene = WriteRig(dir);
  NodeOptions options;
  options.rig_dir = dir.path();
  options.scene = scene;
  options.projectors = {"middle"};
  options.listen = "inproc://node-test-3";
  zmq::context_t context;
  std::atomic<bool> stop{false};
  try {
    RunNode(
        context, options,
        [](const std::vector<Projector>&) { return std::vector<std::unique_ptr<NodeOutput>>(); },
        stop);
    ADD_FAILURE() << "started";
  } catch (const IoError& e) {
    EXPECT_NE(
        std::string(e.what()).find("rig.json: no projector 'middle' (the rig has left, right)"),
        std::string::npos)
        << e.what();
  }
}

// The mean of the linearised pixels seeing each patch; unseen patches keep the fallback.
TEST(Play, DesiredFromImageIsThePerPatchMeanOfTheLinearisedPixels) {
  const int width = 4, height = 2;
  const std::vector<int> pixel_patch = {0, 0, 1, 1, 0, -1, 1, 1};
  cv::Mat image(height, width, CV_8UC3);
  const int values[8] = {0, 255, 128, 128, 255, 17, 64, 200};  // grey levels
  for (int k = 0; k < 8; ++k)
    image.at<cv::Vec3b>(k / width, k % width) = cv::Vec3b(values[k], values[k], values[k]);
  image.at<cv::Vec3b>(0, 0) = cv::Vec3b(255, 0, 0);  // blue (OpenCV's B, G, R)
  Eigen::MatrixX3d fallback(3, 3);
  fallback << 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9;
  const Eigen::MatrixX3d desired = DesiredFromImage(image, pixel_patch, width, height, fallback);
  auto linear = [](int code) {  // the sRGB transfer function, written out
    const double c = code / 255.0;
    return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
  };
  // Patch 0: pixels 0 (blue), 1, 4.
  EXPECT_NEAR(desired(0, 0), (0.0 + linear(255) + linear(255)) / 3, 1e-12);
  EXPECT_NEAR(desired(0, 2), (linear(255) + linear(255) + linear(255)) / 3, 1e-12);
  // Patch 1: pixels 2, 3, 6, 7.
  EXPECT_NEAR(desired(1, 1), (2 * linear(128) + linear(64) + linear(200)) / 4, 1e-12);
  EXPECT_EQ(desired.row(2), fallback.row(2));  // seen by no pixel
  // An image of another size is resized to the camera's first (a flat image stays flat).
  cv::Mat flat(10, 20, CV_16UC3, cv::Scalar::all(65535));
  const Eigen::MatrixX3d white = DesiredFromImage(flat, pixel_patch, width, height, fallback);
  EXPECT_NEAR(white(1, 0), 1.0, 1e-12);
}

}  // namespace
}  // namespace procam

namespace procam {
namespace {

// Keeps the mean code of each channel of every image it presents.
class MeanOutput : public NodeOutput {
 public:
  explicit MeanOutput(std::vector<cv::Scalar>* means) : means_(means) {}
  std::string Describe() const override { return "test:means"; }
  void Draw(const ProjectorImage& image) override {  // a copy, as NodeOutput::Draw asks
    drawn_.bits = image.bits;
    drawn_.codes = image.codes.clone();
  }
  void Present(uint64_t) override { means_->push_back(cv::mean(drawn_.codes)); }

 private:
  std::vector<cv::Scalar>* means_;
  ProjectorImage drawn_;
};

// procam play on a video (OpenCV's MJPG AVI) with the node in this process: every frame is shown
// (or dropped), and the light follows the content — a red frame's images are red, a blue one's
// blue, whatever the room's own desired colours.
TEST(Play, AVideosFramesAreSolvedAndShownAndTheLightFollowsThem) {
  testing::TempDir dir;
  const std::filesystem::path scene = WriteSyntheticSceneFile("tiny_box", 80, dir.path());
  const nlohmann::json file = nlohmann::json::parse(ReadFile(scene));
  WriteFileAtomically(dir / "rig.json",
                      nlohmann::json{{"format_version", 1},
                                     {"camera", {{"model", file.at("cameras").at(0).at("model")}}},
                                     {"projectors", file.at("projectors")}}
                          .dump());
  const std::filesystem::path video = dir / "content.avi";
  {
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                           cv::Size(64, 48));
    ASSERT_TRUE(writer.isOpened());
    for (int k = 0; k < 6; ++k) {
      const cv::Scalar colour =
          k % 2 == 0 ? cv::Scalar(30, 30, 220) : cv::Scalar(220, 30, 30);  // B, G, R
      writer.write(cv::Mat(48, 64, CV_8UC3, colour));
    }
  }
  std::vector<cv::Scalar> left, right;
  PlayOptions options;
  options.scene = scene.string();
  options.rig_dir = dir.path();
  options.desired = video;
  options.out = dir / "play";
  options.fps = 2.0;  // slow enough that no frame is dropped on a loaded machine
  options.local_outputs = [&](const std::vector<Projector>& projectors) {
    EXPECT_EQ(projectors.size(), 2u);
    std::vector<std::unique_ptr<NodeOutput>> outputs;
    outputs.push_back(std::make_unique<MeanOutput>(&left));
    outputs.push_back(std::make_unique<MeanOutput>(&right));
    return outputs;
  };
  const PlaySummary summary = RunPlay(options);
  ASSERT_EQ(summary.frames.size() + summary.dropped, 6u);
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir / "play" / "result.json"));
  EXPECT_EQ(result.at("frames").size(), summary.frames.size());
  ASSERT_EQ(left.size(), summary.frames.size());
  for (size_t k = 0; k < summary.frames.size(); ++k) {
    const bool red = summary.frames[k].source % 2 == 0;
    // Codes in R, G, B order (ProjectorImage): the frame's colour dominates both projectors.
    for (const cv::Scalar& mean : {left[k], right[k]}) {
      if (red) {
        EXPECT_GT(mean[0], 1.5 * mean[2]) << "frame " << k;
      } else {
        EXPECT_GT(mean[2], 1.5 * mean[0]) << "frame " << k;
      }
    }
    if (k > 0) {
      EXPECT_GT(summary.frames[k].iterations, 0);
    }
  }
}

}  // namespace
}  // namespace procam
