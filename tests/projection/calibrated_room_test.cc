// The calibrated room (projection/calibrated_room.h) on the synthetic tiny box, whose true
// geometry and photometry are written as a rig directory:
//   - the pieces against independent truth: the patch count of SubdividePatches at the target,
//     the rig's reflectance on the fine level and its area-weighted mean on the coarse one, the
//     bounds scaling with the reflectance (upper = ρ · flux / A: a rig whose reflectance is 0.9×
//     gives 0.9× the bounds), the problem within the projection rig's bounds, the camera's rays
//     against the camera's projection of the patch centroids;
//   - each inconsistency with its one line: a solution of another patch count, a count other
//     than the expected one, the rig's reflectance for another count, no registered camera,
//     options that fail Check();
//   - SumPixelsPerPatch (projection/camera_rays.h), the per-patch mean over camera pixels, on a
//     picture small enough to average by hand.
#include "projection/calibrated_room.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "base/io.h"
#include "base/json_fields.h"
#include "compensation/stage.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/simulated_rig.h"
#include "geometry/patches.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

constexpr int kPatches = 100;
constexpr double kReflectanceFactor = 0.9;

class CalibratedRoomTest : public ::testing::Test {
 protected:
  void SetUp() override {
    synthetic_ = MakeSyntheticScene("tiny_box", kPatches);
    scene_ = WriteScene();
    rig_ = WriteRig("rig", kReflectanceFactor, /*camera=*/true);
  }

  // The tiny box as a scene file without projectors (they come from the rig).
  std::string WriteScene() const {
    nlohmann::json surfaces = nlohmann::json::array();
    for (const Surface& surface : synthetic_.scene.surfaces) {
      nlohmann::json quad = nlohmann::json::array();
      for (const Vec3& corner : surface.quad) quad.push_back(JsonTriple(corner));
      surfaces.push_back({{"name", surface.name},
                          {"quad", quad},
                          {"reflectance", JsonTriple(surface.reflectance)},
                          {"desired", JsonTriple(surface.desired.srgb)}});
    }
    return dir_
        .Write("scene.json",
               nlohmann::json({{"patches", kPatches}, {"surfaces", surfaces}}).dump(2))
        .string();
  }

  // A rig directory with the world's true projectors (and camera), the fine patches' true
  // reflectance × `factor` at kPatches (none written for factor 1).
  std::filesystem::path WriteRig(const std::string& name, double factor, bool camera) const {
    const std::filesystem::path rig = dir_ / name;
    std::filesystem::create_directories(rig);
    nlohmann::json entries = nlohmann::json::array();
    for (const DevicePlacement& placement : synthetic_.projectors) {
      const Projector projector = ProjectorFromPlacement(placement);
      WriteCameraModel(rig / (projector.name + ".cameramodel"), projector.geometry);
      const ProjectorPhotometry& p = projector.photometry;
      const double gamma = p.response[0].gamma();
      entries.push_back({{"name", projector.name},
                         {"model", projector.name + ".cameramodel"},
                         {"black", JsonTriple(p.black)},
                         {"max", JsonTriple(p.max)},
                         {"gamma", {gamma, gamma, gamma}}});
    }
    nlohmann::json json = {{"format_version", kRigFormatVersion}, {"projectors", entries}};
    if (camera) {
      WriteCameraModel(rig / "camera.cameramodel", CameraFromPlacement(synthetic_.camera));
      json["camera"] = {{"model", "camera.cameramodel"}};
    }
    if (factor != 1.0) {
      WriteNpy(rig / "reflectance.npy", RowMatrixXd(factor * TruePatches().fine.reflectance));
      json["reflectance"] = {{"file", "reflectance.npy"}, {"target_patches", kPatches}};
    }
    dir_.Write(name + "/rig.json", json.dump(2));
    return rig;
  }

  PatchHierarchy TruePatches(int target = kPatches) const {
    SubdivisionOptions subdivision;
    subdivision.target_patches = target;
    return SubdividePatches(synthetic_.scene, subdivision);
  }

  CalibratedRoomOptions Options() const {
    CalibratedRoomOptions options;
    options.scene = scene_;
    options.rig_dir = rig_;
    return options;
  }

  // The message of the IoError `load` throws ("" if none).
  template <typename Load>
  static std::string ErrorOf(Load load) {
    try {
      load();
    } catch (const IoError& e) {
      return e.what();
    }
    return "";
  }

  testing::TempDir dir_;
  SyntheticScene synthetic_;
  std::string scene_;
  std::filesystem::path rig_;
};

TEST_F(CalibratedRoomTest, PiecesMatchTheRigAndTheScene) {
  const CalibratedRoom room = LoadCalibratedRoom(Options());
  const PatchHierarchy truth = TruePatches();
  ASSERT_EQ(room.size(), truth.fine.size());
  EXPECT_EQ(room.geometry.patches.coarse.size(), truth.coarse.size());
  EXPECT_EQ(room.geometry.form_factors.rows(), truth.fine.size());
  // The fine level's reflectance is the rig's; each coarse patch's the area-weighted mean of its
  // children's.
  const Eigen::MatrixX3d rig_reflectance = kReflectanceFactor * truth.fine.reflectance;
  EXPECT_LT((room.fine().reflectance - rig_reflectance).cwiseAbs().maxCoeff(), 1e-12);
  Eigen::MatrixX3d coarse = Eigen::MatrixX3d::Zero(truth.coarse.size(), 3);
  Eigen::VectorXd coarse_area = Eigen::VectorXd::Zero(truth.coarse.size());
  for (int i = 0; i < truth.fine.size(); ++i) {
    const double area = truth.fine.patches[i].area;
    coarse.row(truth.coarse_of_fine[i]) += area * rig_reflectance.row(i);
    coarse_area[truth.coarse_of_fine[i]] += area;
  }
  for (int c = 0; c < truth.coarse.size(); ++c) coarse.row(c) /= coarse_area[c];
  EXPECT_LT((room.geometry.patches.coarse.reflectance - coarse).cwiseAbs().maxCoeff(), 1e-12);
  // The rig's projectors, the projection rig over them, the problem within its bounds.
  ASSERT_EQ(room.projectors.size(), synthetic_.projectors.size());
  ASSERT_EQ(room.projection.size(), room.size());
  EXPECT_EQ(room.projection.maps.size(), synthetic_.projectors.size());
  ASSERT_EQ(room.problem.size(), room.size());
  EXPECT_EQ(room.problem.lower, room.projection.lower);
  EXPECT_EQ(room.problem.upper, room.projection.upper);
  EXPECT_EQ(room.problem.reflectance, room.fine().reflectance);
  EXPECT_EQ(room.problem.form_factors, room.geometry.form_factors);
  EXPECT_DOUBLE_EQ(room.problem.alpha, 0.5);
  EXPECT_GT(room.projection.upper.maxCoeff(), 0.0);
  EXPECT_EQ(room.camera_rays.width, 0);  // not asked for
  // The bounds are reflected light (ρ · flux / A): the rig's 0.9× reflectance gives 0.9× the
  // bounds of a rig with the scene's own.
  CalibratedRoomOptions plain = Options();
  plain.rig_dir = WriteRig("plain_rig", 1.0, false);
  plain.problem = false;
  const CalibratedRoom scene_reflectance = LoadCalibratedRoom(plain);
  EXPECT_LT((scene_reflectance.fine().reflectance - truth.fine.reflectance).cwiseAbs().maxCoeff(),
            1e-12);
  EXPECT_EQ(scene_reflectance.problem.size(), 0);
  EXPECT_LT((room.projection.upper - kReflectanceFactor * scene_reflectance.projection.upper)
                .cwiseAbs()
                .maxCoeff(),
            1e-9 * scene_reflectance.projection.upper.maxCoeff());
}

TEST_F(CalibratedRoomTest, CameraRaysSeeThePatchesTheCameraProjects) {
  CalibratedRoomOptions options = Options();
  options.camera_rays = true;
  options.form_factors = false;  // the rays need the patches only
  options.problem = false;
  const CalibratedRoom room = LoadCalibratedRoom(options);
  const ProjectorGeometry camera = CameraFromPlacement(synthetic_.camera);
  const CameraPixelRays& rays = room.camera_rays;
  ASSERT_EQ(rays.width, camera.width());
  ASSERT_EQ(rays.height, camera.height());
  EXPECT_EQ(room.camera_model_path, rig_ / "camera.cameramodel");
  EXPECT_TRUE(room.geometry.form_factors.size() == 0);
  // The pixel each patch's centroid projects to sees that patch (the box is convex and the
  // camera inside: nothing occludes; patches are many pixels wide, so the pixel's centre lies on
  // the patch unless it is seen nearly edge-on).
  int projected = 0, seen_there = 0;
  for (int i = 0; i < room.size(); ++i) {
    Vec2 pixel;
    if (!camera.Project(room.fine().patches[i].centroid, &pixel) || !camera.InImage(pixel))
      continue;
    ++projected;
    const int col = static_cast<int>(std::lround(pixel.x()));
    const int row = static_cast<int>(std::lround(pixel.y()));
    seen_there += rays.patch[static_cast<size_t>(row) * rays.width + col] == i;
  }
  EXPECT_GT(projected, room.size() / 3);
  EXPECT_GE(seen_there, 0.95 * projected) << seen_there << " of " << projected;
}

TEST_F(CalibratedRoomTest, ASolutionOfAnotherPatchCountIsRefusedInOneLine) {
  // A solution at kPatches, through the room as compensate builds it.
  CalibratedRoomOptions compensate = Options();
  compensate.problem = false;
  const CalibratedRoom room = LoadCalibratedRoom(compensate);
  CompensationOptions solve;
  solve.lower = room.projection.lower;
  solve.upper = room.projection.upper;
  const CompensationRun run = RunCompensation(room.geometry, solve);
  const std::filesystem::path solution = dir_ / "solution";
  WriteCompensation(room.geometry, run, solution, false, {{"rig", room.rig->Describe()}});

  // The solution's own count: its patches, its emittance.
  CalibratedRoomOptions options = Options();
  options.scene.clear();  // the solution's scene
  options.solution_dir = solution;
  const CalibratedRoom with_solution = LoadCalibratedRoom(options);
  ASSERT_TRUE(with_solution.solution.has_value());
  EXPECT_EQ(with_solution.size(), room.size());
  EXPECT_EQ(with_solution.solution->emittance, run.solution.emittance);

  // Another target: another count, refused with the one wording.
  const int other = TruePatches(2 * kPatches).fine.size();
  ASSERT_NE(other, room.size());
  options.scene = scene_;
  options.patches = 2 * kPatches;
  options.rig_dir = WriteRig("plain_rig", 1.0, false);  // no reflectance to refuse first
  const std::string error = ErrorOf([&] { LoadCalibratedRoom(options); });
  EXPECT_EQ(error, PatchCountMismatch(
                       scene_, other, 2 * kPatches,
                       "the solution (" + (solution / "result.json").string() + ")", room.size(),
                       "the scene changed since `procam compensate` ran (or give --patches as "
                       "compensate was given it)"));
  EXPECT_EQ(error.find('\n'), std::string::npos);
  EXPECT_NE(error.find("scene.json: subdivides into " + std::to_string(other) + " patches"),
            std::string::npos)
      << error;
}

TEST_F(CalibratedRoomTest, EachInconsistencyHasItsOneLine) {
  // Another count than a display node's controller counted.
  CalibratedRoomOptions node = Options();
  node.form_factors = false;
  node.problem = false;
  node.expected_patches = TruePatches().fine.size() + 1;
  EXPECT_EQ(ErrorOf([&] { LoadCalibratedRoom(node); }),
            PatchCountMismatch(scene_, TruePatches().fine.size(), kPatches, "the controller's room",
                               node.expected_patches, "the display PC's copy of the room differs"));
  node.expected_patches = TruePatches().fine.size();
  EXPECT_EQ(LoadCalibratedRoom(node).projection.size(), TruePatches().fine.size());

  // The rig's reflectance was estimated for another patch count.
  CalibratedRoomOptions other_count = Options();
  other_count.patches = 2 * kPatches;
  const std::string reflectance = ErrorOf([&] { LoadCalibratedRoom(other_count); });
  EXPECT_NE(reflectance.find((rig_ / "rig.json").string() + ": reflectance: estimated for"),
            std::string::npos)
      << reflectance;

  // Camera rays from a rig with no registered camera.
  CalibratedRoomOptions no_camera = Options();
  no_camera.rig_dir = WriteRig("no_camera", 1.0, false);
  no_camera.camera_rays = true;
  const std::string camera = ErrorOf([&] { ReadRoomSources(no_camera); });
  EXPECT_NE(camera.find((no_camera.rig_dir / "rig.json").string() +
                        ": camera.model: the rig has no registered camera"),
            std::string::npos)
      << camera;
  EXPECT_EQ(camera.find('\n'), std::string::npos);
}

TEST_F(CalibratedRoomTest, OptionsAreChecked) {
  const auto why = [](const CalibratedRoomOptions& options) {
    std::string text;
    return options.Check(&text) ? std::string() : text;
  };
  CalibratedRoomOptions options = Options();
  EXPECT_EQ(why(options), "");
  options.form_factors = false;  // a problem needs them
  EXPECT_NE(why(options).find("form factors"), std::string::npos);
  options = Options();
  options.storage = FormFactorStorage::kCompressed;  // the problem is dense
  EXPECT_NE(why(options), "");
  options.problem = false;
  EXPECT_EQ(why(options), "");
  options = Options();
  options.alpha = 0.0;
  EXPECT_NE(why(options).find("alpha"), std::string::npos);
  options = Options();
  options.display_bits = 9;
  EXPECT_NE(why(options).find("display_bits"), std::string::npos);
  options = Options();
  options.rig_dir.clear();
  options.camera_rays = true;  // the camera is the rig's
  EXPECT_NE(why(options).find("rig"), std::string::npos);
  options.camera_rays = false;
  options.scene.clear();  // no scene and no solution: refused when built
  EXPECT_THROW(LoadCalibratedRoom(options), std::invalid_argument);
}

// A 3×2 picture over a map of two patches and an unseen pixel, averaged by hand.
TEST(SumPixelsPerPatch, MeansOverEachPatchsPixels) {
  cv::Mat picture(2, 3, CV_32FC3);
  picture.at<cv::Vec3f>(0, 0) = {1, 2, 3};
  picture.at<cv::Vec3f>(0, 1) = {3, 4, 5};
  picture.at<cv::Vec3f>(0, 2) = {9, 9, 9};
  picture.at<cv::Vec3f>(1, 0) = {0, 0, 8};
  picture.at<cv::Vec3f>(1, 1) = {2, 2, 2};
  picture.at<cv::Vec3f>(1, 2) = {4, 6, 8};
  const std::vector<int> pixel_patch = {0, 0, -1, 2, 0, 2};  // patch 1 unseen, −1 none
  const PatchPixelSums sums = SumPixelsPerPatch(picture, pixel_patch, 3);
  EXPECT_EQ(sums.count, Eigen::Vector3i(3, 0, 2));
  EXPECT_EQ(sums.Mean(0), Eigen::RowVector3d(2, 8.0 / 3, 10.0 / 3));
  EXPECT_EQ(sums.Mean(2), Eigen::RowVector3d(2, 3, 8));
  const Eigen::MatrixX3d fallback = Eigen::MatrixX3d::Constant(3, 3, -1);
  const Eigen::MatrixX3d means = sums.Means(fallback);
  EXPECT_EQ(means.row(1), fallback.row(1));
  EXPECT_EQ(means.row(2), Eigen::RowVector3d(2, 3, 8));
  // At least 3 pixels: patch 2 falls back too.
  EXPECT_EQ(sums.Means(fallback, 3).row(2), fallback.row(2));
  // Only the masked pixels.
  const std::vector<bool> mask = {true, false, true, true, true, false};
  const PatchPixelSums masked = SumPixelsPerPatch(picture, pixel_patch, 3, &mask);
  EXPECT_EQ(masked.count, Eigen::Vector3i(2, 0, 1));
  EXPECT_EQ(masked.Mean(0), Eigen::RowVector3d(1.5, 2, 2.5));
  // A map of another size is refused.
  EXPECT_THROW(SumPixelsPerPatch(picture, {0, 0}, 3), std::invalid_argument);
}

}  // namespace
}  // namespace procam
