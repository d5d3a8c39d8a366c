// procam project and procam bench projection, run as a user would: a solution directory made
// here (result.json + E.npy for a stage with two projectors), the images and result.json it
// writes, and one clear error for each kind of bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "base/io.h"
#include "compensation/stage.h"
#include "projection/projection_rig.h"
#include "tests/projection/stage.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::CommandRun;

CommandRun Procam(const std::string& arguments) { return testing::RunProcam(arguments); }

// The stage of tests/projection/stage.h as files: two .cameramodel files and a scene.
class ProjectCommand : public ::testing::Test {
 protected:
  void SetUp() override {
    const testing::Stage stage = testing::MakeStage({});
    WriteCameraModel(dir_ / "left.cameramodel", stage.projectors[0].geometry);
    WriteCameraModel(dir_ / "right.cameramodel", stage.projectors[1].geometry);
    WriteScene(R"([
      {"name": "left", "model": "left.cameramodel", "black": 0.02, "max": 12},
      {"name": "right", "model": "right.cameramodel", "black": 0.02, "max": 12, "bits": 10}])");
    const Scene scene = LoadScene(scene_path_);
    SubdivisionOptions subdivision;
    subdivision.target_patches = scene.target_patches;
    level_ = SubdividePatches(scene, subdivision).fine;
    Eigen::MatrixX3d lower, upper;
    ASSERT_TRUE(SetBoundsFromProjectors(scene, level_, &lower, &upper));
    emittance_ = lower + 0.5 * (upper - lower);
    WriteSolution(level_.size(), emittance_);
  }

  void WriteScene(const std::string& projectors) {
    scene_path_ = dir_.Write("stage.json", R"({
      "patches": 300,
      "projectors": )" + projectors + R"(,
      "surfaces": [
        {"name": "wall", "quad": [[0,3,0],[4,3,0],[4,3,2.5],[0,3,2.5]], "reflectance": 0.8, "desired": [0.5,0.5,0.5]},
        {"name": "floor", "quad": [[0,0,0],[4,0,0],[4,3,0],[0,3,0]], "reflectance": 0.6, "desired": [0.5,0.5,0.5]},
        {"name": "plate", "quad": [[1.6,2,0.9],[2.4,2,0.9],[2.4,2,1.6],[1.6,2,1.6]], "reflectance": 0.7, "desired": [0.5,0.5,0.5]}
      ]})");
  }

  void WriteSolution(int patches, const Eigen::MatrixX3d& emittance) {
    std::filesystem::create_directories(dir_ / "solution");
    // A solution directory as compensate writes it (docs/solution_format.md); B is not used by
    // project, E is.
    const nlohmann::json result = {{"format_version", kSolutionFormatVersion},
                                   {"method", "naive"},
                                   {"multires", false},
                                   {"alpha", 0.5},
                                   {"scene", scene_path_.string()},
                                   {"patches", patches}};
    WriteFileAtomically(dir_ / "solution" / "result.json", result.dump(2));
    WriteNpy(dir_ / "solution" / "E.npy", RowMatrixXd(emittance));
    WriteNpy(dir_ / "solution" / "B.npy", RowMatrixXd(emittance));
  }

  std::string Project() {
    return (dir_ / "solution").string() + " --out " + (dir_ / "images").string();
  }

  testing::TempDir dir_;
  std::filesystem::path scene_path_;
  PatchLevel level_;
  Eigen::MatrixX3d emittance_;
};

TEST_F(ProjectCommand, WritesOneImagePerProjectorAndResultJson) {
  const CommandRun run = Procam("project " + Project());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const cv::Mat left = cv::imread((dir_ / "images" / "left.png").string(), cv::IMREAD_UNCHANGED);
  const cv::Mat right = cv::imread((dir_ / "images" / "right.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(left.empty());
  ASSERT_FALSE(right.empty());
  EXPECT_EQ(left.size(), cv::Size(320, 240));
  EXPECT_EQ(left.type(), CV_8UC3);
  EXPECT_EQ(right.type(), CV_16UC3);  // 10-bit projector
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir_ / "images" / "result.json"));
  EXPECT_EQ(result["patches"], level_.size());
  ASSERT_EQ(result["projectors"].size(), 2u);
  EXPECT_EQ(result["projectors"][1]["image"], "right.png");
  EXPECT_EQ(result["patches_above_upper"], 0);
  EXPECT_LT(result["max_relative_error"].get<double>(), 1e-3);
  // The delivered emittance it predicts is the solution's, to quantisation.
  const NpyArray delivered = ReadNpy(dir_ / "images" / "E_delivered.npy");
  ASSERT_EQ(delivered.values.size(), size_t(3 * level_.size()));
  for (int i = 0; i < level_.size(); ++i) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(delivered.values[3 * i + c], emittance_(i, c), 1e-3);
  }
}

TEST_F(ProjectCommand, DetailModulatesTexturedSurfacesOnly) {
  // The same stage with a striped texture on the wall (sRGB PNG, 8 periods across).
  cv::Mat stripes(64, 256, CV_8UC3);
  for (int x = 0; x < stripes.cols; ++x) {
    const double value = 0.5 + 0.35 * std::sin(6.283185307179586 * 8.0 * (x + 0.5) / stripes.cols);
    stripes.col(x).setTo(cv::Scalar::all(std::lround(255.0 * value)));
  }
  ASSERT_TRUE(cv::imwrite((dir_ / "stripes.png").string(), stripes));
  scene_path_ = dir_.Write("textured.json", R"({
      "patches": 300,
      "projectors": [
        {"name": "left", "model": "left.cameramodel", "black": 0.02, "max": 12},
        {"name": "right", "model": "right.cameramodel", "black": 0.02, "max": 12, "bits": 10}],
      "surfaces": [
        {"name": "wall", "quad": [[0,3,0],[4,3,0],[4,3,2.5],[0,3,2.5]], "reflectance": 0.8, "desired": {"texture": "stripes.png"}},
        {"name": "floor", "quad": [[0,0,0],[4,0,0],[4,3,0],[0,3,0]], "reflectance": 0.6, "desired": [0.5,0.5,0.5]},
        {"name": "plate", "quad": [[1.6,2,0.9],[2.4,2,0.9],[2.4,2,1.6],[1.6,2,1.6]], "reflectance": 0.7, "desired": [0.5,0.5,0.5]}
      ]})");
  WriteSolution(level_.size(), emittance_);
  const CommandRun plain = Procam("project " + Project());
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  const cv::Mat plain_left =
      cv::imread((dir_ / "images" / "left.png").string(), cv::IMREAD_UNCHANGED);
  const CommandRun detail = Procam("project " + Project() + " --detail");
  ASSERT_EQ(detail.exit_code, 0) << detail.output;
  EXPECT_NE(detail.output.find("detail: "), std::string::npos) << detail.output;
  const cv::Mat detail_left =
      cv::imread((dir_ / "images" / "left.png").string(), cv::IMREAD_UNCHANGED);
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir_ / "images" / "result.json"));
  EXPECT_EQ(result["detail"], true);
  EXPECT_GT(result["detail_pixels"].get<int64_t>(), 20000);
  EXPECT_LT(result["max_relative_error"].get<double>(), 1e-3);
  // Patch totals as without detail.
  const NpyArray delivered = ReadNpy(dir_ / "images" / "E_delivered.npy");
  for (int i = 0; i < level_.size(); ++i) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(delivered.values[3 * i + c], emittance_(i, c), 1e-3);
  }
  // The wall's pixels change, the floor's and the plate's do not.
  const ProjectionRig rig = BuildProjectionRig(level_, testing::MakeStage({}).projectors, {});
  int wall_changed = 0, others_changed = 0;
  for (int y = 0; y < plain_left.rows; ++y) {
    for (int x = 0; x < plain_left.cols; ++x) {
      const int patch = rig.maps[0].patch[size_t(y) * plain_left.cols + x];
      if (patch < 0 || plain_left.at<cv::Vec3b>(y, x) == detail_left.at<cv::Vec3b>(y, x)) continue;
      ++(level_.patches[patch].surface == 0 ? wall_changed : others_changed);
    }
  }
  EXPECT_GT(wall_changed, 10000);
  EXPECT_EQ(others_changed, 0);
}

TEST_F(ProjectCommand, BadInputGivesOneClearError) {
  auto error_of = [&](const std::string& arguments) {
    const CommandRun run = Procam(arguments);
    EXPECT_EQ(run.exit_code, 1) << run.output;
    size_t errors = 0;
    for (size_t at = run.output.find("procam: error: "); at != std::string::npos;
         at = run.output.find("procam: error: ", at + 1)) {
      ++errors;
    }
    EXPECT_EQ(errors, 1u) << run.output;
    return run.output;
  };
  EXPECT_NE(error_of("project " + dir_.path().string() + " --out " + (dir_ / "x").string())
                .find("result.json: file not found"),
            std::string::npos);
  // E.npy of another size than result.json says.
  WriteNpy(dir_ / "solution" / "E.npy", RowMatrixXd(emittance_.topRows(10)));
  EXPECT_NE(error_of("project " + Project()).find("E.npy: shape (10,3), but result.json says"),
            std::string::npos);
  // A solution of another patch count than the scene subdivides into (the scene changed).
  Eigen::MatrixX3d more(level_.size() + 4, 3);
  more.setConstant(0.1);
  WriteSolution(level_.size() + 4, more);
  EXPECT_NE(
      error_of("project " + Project()).find("the scene changed since `procam compensate` ran"),
      std::string::npos);
  WriteSolution(level_.size(), emittance_);
  // A projector that looks away from the room.
  WriteCameraModel(
      dir_ / "away.cameramodel",
      ProjectorGeometry::Pinhole(
          300, 300, 160, 120, 320, 240,
          ProjFromWorldLookingAt(Vec3(2, -1.5, 1.5), Vec3(2, -5, 1.5), Vec3::UnitZ())));
  WriteScene(R"([{"name": "left", "model": "left.cameramodel", "max": 12},
                 {"name": "away", "model": "away.cameramodel", "max": 12}])");
  EXPECT_NE(error_of("project " + Project()).find("projector 'away' lights no patch"),
            std::string::npos);
  // A projector key that is wrong.
  WriteScene(R"([{"name": "left", "model": "left.cameramodel", "max": 12, "bits": 9}])");
  EXPECT_NE(
      error_of("project " + Project()).find("stage.json: projectors[0].bits: must be 8 or 10"),
      std::string::npos);
  // No projectors at all.
  WriteScene("[]");
  EXPECT_NE(error_of("project " + Project()).find("the scene lists no projectors"),
            std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(dir_ / "images" / "result.json"));
}

TEST(BenchProjection, RunsOnSmallImages) {
  testing::TempDir dir;
  const CommandRun run =
      Procam("bench projection --width 160 --height 96 --patches 100 --repeat 2 --json " +
             (dir / "bench.json").string());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json result = nlohmann::json::parse(ReadFile(dir / "bench.json"));
  EXPECT_EQ(result["benchmark"], "projection");
  EXPECT_GT(result["render_seconds_median"].get<double>(), 0.0);
  EXPECT_LT(result["max_relative_error"].get<double>(), 1e-3);
}

}  // namespace
}  // namespace procam
