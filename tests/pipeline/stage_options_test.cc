// Each calibration stage's options declared once (base/option_table.h): the command a stage
// prints for a step (ChangedArgumentsOf) reads back, through the same declarations, to the
// options the step ran with — what `procam calibrate all` shows a user is what it ran.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "base/option_table.h"
#include "pipeline/board_stage.h"
#include "pipeline/calibrate_all_stage.h"
#include "pipeline/camera_stage.h"
#include "pipeline/capture_stage.h"
#include "pipeline/photometric_stage.h"
#include "pipeline/projectors_stage.h"
#include "pipeline/response_stage.h"

namespace procam {
namespace {

// Parses `arguments` as the command line does, option by option, into a default `Options`:
// "--NAME VALUE", "--FLAG", "--FLAG=false", and bare values for the positional option.
template <typename Options>
Options ReadBack(const std::vector<std::string>& arguments) {
  Options options;
  OptionTable table;
  options.Declare(&table);
  std::vector<std::string> positional;
  std::vector<std::pair<std::string, std::vector<std::string>>> lists;  // repeated flags
  for (size_t i = 0; i < arguments.size(); ++i) {
    const std::string& argument = arguments[i];
    if (argument.rfind("--", 0) != 0) {
      positional.push_back(argument);
      continue;
    }
    std::string name = argument.substr(2);
    const size_t equals = name.find('=');
    if (equals != std::string::npos) {
      table.Set(name.substr(0, equals), name.substr(equals + 1));
      continue;
    }
    const OptionTable::Option* option = table.Find(name);
    if (option == nullptr) ADD_FAILURE() << "no option " << argument;
    if (option == nullptr || option->kind == OptionTable::Kind::kFlag) {
      table.Set(name, "true");
      continue;
    }
    EXPECT_LT(i + 1, arguments.size()) << argument << " has no value";
    const std::string value = arguments[++i];
    if (option->repeated) {
      auto found =
          std::find_if(lists.begin(), lists.end(), [&](const auto& l) { return l.first == name; });
      if (found == lists.end()) found = lists.insert(lists.end(), {name, {}});
      found->second.push_back(value);
    } else {
      table.Set(name, value);
    }
  }
  for (const auto& [name, items] : lists) {
    std::string why;
    EXPECT_TRUE(table.Find(name)->set_items(items, &why)) << why;
  }
  for (const OptionTable::Option& option : table.options()) {
    if (!option.positional || positional.empty()) continue;
    std::string joined;
    for (size_t k = 0; k < positional.size(); ++k) joined += (k ? "," : "") + positional[k];
    table.Set(option.name, joined);
    positional.clear();
  }
  return options;
}

// Every declared value of `expected` and `actual` alike, as written.
template <typename Options>
void ExpectSameDeclared(Options expected, Options actual) {
  OptionTable a, b;
  expected.Declare(&a);
  actual.Declare(&b);
  ASSERT_EQ(a.options().size(), b.options().size());
  for (size_t k = 0; k < a.options().size(); ++k)
    EXPECT_EQ(a.options()[k].get(), b.options()[k].get()) << "--" << a.options()[k].name;
}

TEST(StageOptions, TheCameraStepReadsBack) {
  CameraStageOptions camera;
  camera.images = "rig/captures/chessboard";
  camera.out = "rig";
  camera.board.corners_x = 7;
  camera.board.square_size = 0.06;
  camera.options.reject_outliers = false;
  const std::vector<std::string> arguments = ChangedArgumentsOf(camera);
  EXPECT_EQ(arguments,
            (std::vector<std::string>{"rig/captures/chessboard", "--out", "rig", "--corners", "7x6",
                                      "--square", "0.06", "--no-outlier-rejection"}));
  ExpectSameDeclared(camera, ReadBack<CameraStageOptions>(arguments));
  std::string why;
  EXPECT_TRUE(camera.Check(&why)) << why;
  EXPECT_FALSE(CameraStageOptions().Check(&why));  // no session, no rig directory
  EXPECT_EQ(why, "session is required");
}

TEST(StageOptions, TheCapturesReadBack) {
  CaptureStageOptions capture;
  capture.camera = "synthetic:tiny_box?patches=150&fps=500";
  capture.sequence = "photometric";
  capture.out = "rig/captures/photometric_left";
  capture.display_name = "glfw:1";
  capture.projector = 1;
  capture.sequencer.frames_per_pattern = 2;
  capture.sequencer.settle_ms = 37.5;
  capture.sequencer.exposures_us = {2500, 10000};
  capture.gain = 3;
  capture.levels = {0, 128, 255};
  capture.channels = "rgb";
  const std::vector<std::string> arguments = ChangedArgumentsOf(capture);
  ExpectSameDeclared(capture, ReadBack<CaptureStageOptions>(arguments));
  std::string why;
  EXPECT_TRUE(capture.Check(&why)) << why;
  // Measured settle time: written as auto.
  capture.measure_latency = true;
  const std::vector<std::string> measured = ChangedArgumentsOf(capture);
  EXPECT_NE(std::find(measured.begin(), measured.end(), "auto"), measured.end());
  EXPECT_TRUE(ReadBack<CaptureStageOptions>(measured).measure_latency);
  // Values the stage refuses, named.
  capture.projector = -1;
  EXPECT_FALSE(capture.Check(&why));
  EXPECT_EQ(why, "--projector: must be >= 0, got -1");
}

TEST(StageOptions, TheProjectorsStepReadsBack) {
  ProjectorsStageOptions projectors;
  projectors.sessions = {"rig/captures/structured_light_left",
                         "rig/captures/structured_light_right"};
  projectors.out = "rig";
  projectors.names = {"left", "right"};
  projectors.held_lenses = {{"left", "board/left.cameramodel"},
                            {"right", "board/right,2.cameramodel"}};
  projectors.scene = "synthetic:tiny_box";
  projectors.camera_guess = "0.5,-1.4,0.8,0.5,0.5,0.5";
  projectors.options.refine_camera_intrinsics = true;
  projectors.max_correspondences = 5000;
  const std::vector<std::string> arguments = ChangedArgumentsOf(projectors);
  ExpectSameDeclared(projectors, ReadBack<ProjectorsStageOptions>(arguments));
  std::string why;
  EXPECT_TRUE(projectors.Check(&why)) << why;
  // A scan's options without a scene only.
  projectors.camera_height = 1.5;
  EXPECT_FALSE(projectors.Check(&why));
  EXPECT_NE(why.find("only without --scene"), std::string::npos) << why;
  projectors.scene.clear();
  projectors.held_lenses.clear();
  EXPECT_FALSE(projectors.Check(&why));  // and a guess with a scene only
  EXPECT_NE(why.find("--camera-guess: only with --scene"), std::string::npos) << why;
  projectors.camera_guess.clear();
  EXPECT_TRUE(projectors.Check(&why)) << why;
  ExpectSameDeclared(projectors, ReadBack<ProjectorsStageOptions>(ChangedArgumentsOf(projectors)));
}

TEST(StageOptions, ThePhotometryBoardResponseAndWholeRigReadBack) {
  PhotometricStageOptions photometric;
  photometric.session = "rig/captures/photometric_left";
  photometric.out = "rig";
  photometric.projector = "left";
  photometric.scene = "synthetic:tiny_box";
  photometric.patches = 150;
  photometric.camera_scale = "0.5,0.6,0.7";
  photometric.camera_black = 8;
  photometric.response = "lut";
  ExpectSameDeclared(photometric,
                     ReadBack<PhotometricStageOptions>(ChangedArgumentsOf(photometric)));

  BoardStageOptions board;
  board.sessions = {"a", "b", "c"};
  board.out = "rig";
  board.projector = "front";
  board.options.homography_half_window = 8;
  board.options.min_tilt_spread_deg = 2.5;
  ExpectSameDeclared(board, ReadBack<BoardStageOptions>(ChangedArgumentsOf(board)));

  ResponseStageOptions response;
  response.session = "bracket";
  response.out = "rig";
  response.pattern = 3;
  response.options.lambda = 20;
  ExpectSameDeclared(response, ReadBack<ResponseStageOptions>(ChangedArgumentsOf(response)));

  CalibrateAllOptions all;
  all.camera = "v4l2:/dev/video0";
  all.out = "rig";
  all.display_names = {"glfw:1", "glfw:2"};
  all.names = {"left", "right"};
  all.camera_scale = "1200";
  all.chessboard = "photos";
  all.measure_settle = false;
  all.settle_ms = 80;
  all.levels = {0, 64, 255};
  const std::vector<std::string> arguments = ChangedArgumentsOf(all);
  ExpectSameDeclared(all, ReadBack<CalibrateAllOptions>(arguments));
  EXPECT_NE(std::find(arguments.begin(), arguments.end(), "glfw:1,glfw:2"), arguments.end());
  std::string why;
  EXPECT_TRUE(all.Check(&why)) << why;
  all.levels = {0, 300};
  EXPECT_FALSE(all.Check(&why));
  EXPECT_EQ(why, "--levels: must be in [0, 255], got 300");
}

}  // namespace
}  // namespace procam
