// Printed walls compensated per pixel through the product's path: a rig directory whose
// rig.json has reflectance maps (the true ones of the synthetic world, written by their one
// writer), the calibrated room built from it (the maps attached), the problem solved, the images
// rendered as `procam project` and `procam verify` render them (RenderOptions::reflectance where
// the room has maps) and photographed by the synthetic camera (noise off). Against the world's
// truth (its desired picture, its reflectance):
//   - on the tiny box's back wall printed with a poster of coloured cells, the per-pixel
//     CIEDE2000 between the photo and the desired picture, and the print's visibility (each
//     pixel's CIEDE2000 from its patch's mean in the photo), fall with the maps;
//   - the per-pixel prediction (PredictPixels) follows the print with the maps;
//   - an unprinted box is unchanged by maps (they are constant over each wall), and a rig
//     without maps renders exactly what the room rendered before maps existed.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "base/io.h"
#include "base/json_fields.h"
#include "compensation/colour.h"
#include "compensation/solver.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/simulated_rig.h"
#include "datasets_synthetic/true_reflectance.h"
#include "geometry/ray_scene.h"
#include "projection/calibrated_room.h"
#include "projection/camera_rays.h"
#include "projection/projector_images.h"
#include "projection/reflectance_map.h"
#include "tests/testing/testing.h"
#include "verification/model_fit.h"

namespace procam {
namespace {

constexpr int kPatches = 100;
constexpr int kBackWall = 1;  // tiny_box's surfaces: floor, back wall, ...

// A poster of 8 × 8 cells (125 mm on the 1 m back wall, about 19 projector pixels) in four
// colours of linear reflectance 0.45–0.85: within what the tiny box's projectors can even out
// (a contrast of 1.9 at most between cells).
ReflectanceTexture Poster() {
  const cv::Vec3f palette[4] = {cv::Vec3f(0.85f, 0.85f, 0.85f), cv::Vec3f(0.6f, 0.6f, 0.6f),
                                cv::Vec3f(0.85f, 0.6f, 0.45f), cv::Vec3f(0.5f, 0.65f, 0.85f)};
  ReflectanceTexture poster;
  constexpr int kCell = 8, kCells = 8;
  poster.texture_linear = cv::Mat(kCell * kCells, kCell * kCells, CV_32FC3);
  for (int row = 0; row < poster.texture_linear.rows; ++row) {
    for (int col = 0; col < poster.texture_linear.cols; ++col) {
      const int cell_row = row / kCell, cell_col = col / kCell;
      poster.texture_linear.at<cv::Vec3f>(row, col) =
          palette[(cell_row * 3 + cell_col * 5 + cell_row * cell_col) % 4];
    }
  }
  poster.scale = 1.0;
  return poster;
}

// The tiny box (its back wall printed with the poster when `printed`) and the simulated world
// that photographs it.
struct World {
  SyntheticScene synthetic;
  std::vector<Projector> projectors;
  std::unique_ptr<SimulatedRig> rig;
};

World MakeWorld(bool printed) {
  World world;
  world.synthetic = MakeSyntheticScene("tiny_box", kPatches);
  if (printed) {
    Surface& back_wall = world.synthetic.scene.surfaces[kBackWall];
    back_wall.reflectance_texture = Poster();
    back_wall.reflectance = back_wall.reflectance_texture.Mean();  // as LoadScene sets it
  }
  for (const DevicePlacement& placement : world.synthetic.projectors)
    world.projectors.push_back(ProjectorFromPlacement(placement));
  SimulatedRigOptions options;
  options.solver_patches = kPatches;
  world.rig = std::make_unique<SimulatedRig>(world.synthetic.scene, world.projectors,
                                             CameraFromPlacement(world.synthetic.camera), options);
  return world;
}

// A rig directory with the world's true projectors and camera and, with `maps`, every
// projector's true reflectance map in rig.json's reflectance_maps.
std::filesystem::path WriteRig(const World& world, const std::filesystem::path& rig, bool maps) {
  std::filesystem::create_directories(rig);
  nlohmann::json entries = nlohmann::json::array(), map_entries = nlohmann::json::object();
  for (const Projector& projector : world.projectors) {
    WriteCameraModel(rig / (projector.name + ".cameramodel"), projector.geometry);
    const ProjectorPhotometry& p = projector.photometry;
    const double gamma = p.response[0].gamma();
    entries.push_back({{"name", projector.name},
                       {"model", projector.name + ".cameramodel"},
                       {"black", JsonTriple(p.black)},
                       {"max", JsonTriple(p.max)},
                       {"gamma", {gamma, gamma, gamma}}});
    if (!maps) continue;
    ReflectanceMap map;
    map.reflectance = TrueReflectanceMap(world.synthetic.scene, projector.geometry);
    RigReflectanceMap entry;
    WriteReflectanceMap(rig, projector.name, map, &entry);
    map_entries[projector.name] = {{"file", entry.file},
                                   {"width", entry.width},
                                   {"height", entry.height},
                                   {"target_patches", kPatches}};
  }
  WriteCameraModel(rig / "camera.cameramodel", world.rig->camera());
  nlohmann::json json = {{"format_version", kRigFormatVersion},
                         {"projectors", entries},
                         {"camera", {{"model", "camera.cameramodel"}}}};
  if (maps) json["reflectance_maps"] = map_entries;
  WriteFileAtomically(rig / "rig.json", json.dump(2));
  return rig;
}

CalibratedRoom LoadRoom(const World& world, const std::filesystem::path& rig,
                        bool use_maps = true) {
  CalibratedRoomOptions options;
  options.rig_dir = rig;
  options.camera_rays = true;
  options.camera_lighting = true;
  options.reflectance_maps = use_maps;
  RoomSources sources;
  sources.scene = world.synthetic.scene;
  return BuildCalibratedRoom(options, ReadRoomSources(options, std::move(sources)));
}

// The room's problem solved, rendered as the product renders it (per pixel where the room has
// maps), photographed without noise; per-pixel comparisons over the back wall's camera pixels.
struct Shot {
  std::vector<ProjectorImage> images;
  RenderSummary render;
  cv::Mat radiance, predicted;  // CV_32FC3 linear R, G, B
  double mean2000 = 0.0;        // photo vs desired, per pixel
  double print2000 = 0.0;       // photo vs its patch's mean in the photo, per pixel
  double model2000 = 0.0;       // photo vs the per-pixel prediction, per pixel
  int pixels = 0;
  std::vector<bool> interior;  // camera pixels whose four neighbours see the same patch
};

Shot Photograph(const World& world, const CalibratedRoom& room) {
  SolverSummary summary;
  const CompensationSolution solution = Solve(SolverOptions(), room.problem, &summary);
  Shot shot;
  RenderOptions render;
  render.reflectance = HasReflectanceMaps(room.projection);  // as project and verify decide
  shot.images = RenderProjectorImages(room.projection, room.geometry.scene, solution.emittance,
                                      render, &shot.render);
  shot.radiance = world.rig->RenderRadiance(shot.images);
  shot.predicted =
      PredictPixels(room.camera_rays, room.projection, shot.images, room.geometry.form_factors);
  const cv::Mat desired = world.rig->RenderDesired();
  const LabConverter lab{room.problem.rgb_to_xyz, room.problem.white_xyz};
  const auto lab_at = [&](const cv::Mat& image, size_t index) {
    const cv::Vec3f& v = reinterpret_cast<const cv::Vec3f*>(image.data)[index];
    return lab.Lab(Eigen::Vector3d(v[0], v[1], v[2]));
  };
  const CameraPixelRays& rays = room.camera_rays;
  // Pixels on the back wall whose four neighbours see the same patch (away from patch borders,
  // where the camera's and the model's rays may disagree).
  std::vector<size_t> wall;
  shot.interior.assign(rays.patch.size(), false);
  for (int row = 1; row + 1 < rays.height; ++row) {
    for (int col = 1; col + 1 < rays.width; ++col) {
      const size_t index = static_cast<size_t>(row) * rays.width + col;
      const int i = rays.patch[index];
      if (i < 0 || world.rig->coverage().at<uint8_t>(row, col) == 0) continue;
      if (rays.patch[index - 1] != i || rays.patch[index + 1] != i ||
          rays.patch[index - rays.width] != i || rays.patch[index + rays.width] != i)
        continue;
      shot.interior[index] = true;
      if (room.projection.surface[i] == kBackWall) wall.push_back(index);
    }
  }
  const PatchPixelSums sums = SumPixelsPerPatch(shot.radiance, rays.patch, room.size());
  for (const size_t index : wall) {
    const Eigen::Vector3d photo = lab_at(shot.radiance, index);
    shot.mean2000 += DeltaE2000(photo, lab_at(desired, index));
    shot.model2000 += DeltaE2000(photo, lab_at(shot.predicted, index));
    shot.print2000 += DeltaE2000(photo, lab.Lab(sums.Mean(rays.patch[index]).transpose()));
  }
  shot.pixels = static_cast<int>(wall.size());
  shot.mean2000 /= shot.pixels;
  shot.model2000 /= shot.pixels;
  shot.print2000 /= shot.pixels;
  return shot;
}

TEST(ReflectanceCompensation, PrintedWallFadesWithTheMaps) {
  const World world = MakeWorld(/*printed=*/true);
  testing::TempDir dir;
  const CalibratedRoom with_maps = LoadRoom(world, WriteRig(world, dir.path() / "maps", true));
  const CalibratedRoom without = LoadRoom(world, WriteRig(world, dir.path() / "plain", false));
  ASSERT_TRUE(HasReflectanceMaps(with_maps.projection));
  ASSERT_FALSE(HasReflectanceMaps(without.projection));
  const Shot before = Photograph(world, without);
  const Shot after = Photograph(world, with_maps);
  ASSERT_GT(before.pixels, 1000);
  std::printf(
      "back wall, %d pixels: photo vs desired CIEDE2000 %.3f -> %.3f; print visible (vs patch "
      "mean) %.3f -> %.3f; model error %.3f -> %.3f; %lld of %lld pixels saturated by the map\n",
      after.pixels, before.mean2000, after.mean2000, before.print2000, after.print2000,
      before.model2000, after.model2000, after.render.reflectance_saturated_pixels,
      after.render.reflectance_pixels);
  EXPECT_GT(after.render.reflectance_pixels, 0);
  EXPECT_EQ(before.render.reflectance_pixels, 0);
  // Measured (2026-11-28): model error 3.52 -> 1.25, print 4.87 -> 3.75, photo vs desired
  // 9.87 -> 9.32, 101 of 103 348 pixels saturated. The prediction knows the print with the maps:
  // its error at least halves. The images even out only the direct light: the bounce (a large
  // part of the light in the closed box) reflects with the print, and the pixels straddling a
  // cell edge light both cells with one level (docs/projection.md), so the print's visibility
  // falls by at least 15% (23% measured), and the error against the desired picture, most of
  // which is the patches' own (the solver's bounds), by at least 3% (5.6% measured).
  EXPECT_LT(after.model2000, 0.5 * before.model2000);
  EXPECT_LT(after.print2000, 0.85 * before.print2000);
  EXPECT_LT(after.mean2000, 0.97 * before.mean2000);
  // Within the projectors' range: few pixels saturate (0.1% measured).
  EXPECT_LT(after.render.reflectance_saturated_pixels, after.render.reflectance_pixels / 100);
}

// The closed loop per pixel (FitReflectanceMaps): maps that know nothing of the print (each
// pixel its patch's reflectance) refitted from each photo against its per-pixel prediction, the
// images rendered again with them, three times.
TEST(ReflectanceCompensation, ClosedLoopLearnsThePrintPerPixel) {
  const World world = MakeWorld(/*printed=*/true);
  testing::TempDir dir;
  const Shot truth = Photograph(world, LoadRoom(world, WriteRig(world, dir.path() / "maps", true)));
  CalibratedRoom room = LoadRoom(world, WriteRig(world, dir.path() / "plain", false));
  std::vector<cv::Mat> flat;
  for (const ProjectorMap& map : room.projection.maps) {
    cv::Mat reflectance(map.height, map.width, CV_32FC3, cv::Scalar::all(0));
    for (int q = 0; q < map.width * map.height; ++q) {
      if (map.patch[q] < 0) continue;
      const Eigen::RowVector3d rho = room.projection.reflectance.row(map.patch[q]);
      reflectance.at<cv::Vec3f>(q / map.width, q % map.width) =
          cv::Vec3f(float(rho[0]), float(rho[1]), float(rho[2]));
    }
    flat.push_back(reflectance);
  }
  AttachReflectanceMaps(flat, &room.projection);
  std::vector<Shot> shots = {Photograph(world, room)};
  for (int iteration = 1; iteration <= 3; ++iteration) {
    const Shot& last = shots.back();
    const ReflectanceMapUpdate update =
        FitReflectanceMaps(ReflectanceMapFitOptions(), room.camera_rays, last.radiance,
                           last.predicted, last.interior, &room.projection);
    EXPECT_GT(update.updated_pixels, 0);
    shots.push_back(Photograph(world, room));
    std::printf(
        "iteration %d: rms log gain %.4f; back wall: photo vs desired CIEDE2000 %.3f, print "
        "visible %.3f, model error %.3f\n",
        iteration, update.rms_log_gain, shots.back().mean2000, shots.back().print2000,
        shots.back().model2000);
  }
  std::printf("start (no print known): %.3f / %.3f / %.3f; true maps: %.3f / %.3f / %.3f\n",
              shots.front().mean2000, shots.front().print2000, shots.front().model2000,
              truth.mean2000, truth.print2000, truth.model2000);
  // Measured (2026-11-28): print 4.87 -> 3.83, 3.78, 3.79 against 3.75 with the true maps;
  // model error 3.52 -> 1.01, 0.99, 1.05 (1.25 with the true maps: the refit also absorbs the
  // model's bounce error). One update reaches the true maps' evenness within 5%, and later ones
  // stay there.
  for (size_t k = 1; k < shots.size(); ++k) {
    EXPECT_LT(shots[k].print2000, 1.05 * truth.print2000) << "iteration " << k;
    EXPECT_LT(shots[k].model2000, truth.model2000 + 0.1) << "iteration " << k;
  }
}

TEST(ReflectanceCompensation, UnprintedWallsAreUnchangedAndOldRigsAsBefore) {
  const World world = MakeWorld(/*printed=*/false);
  testing::TempDir dir;
  const std::filesystem::path maps_rig = WriteRig(world, dir.path() / "maps", true);
  const CalibratedRoom with_maps = LoadRoom(world, maps_rig);
  const CalibratedRoom maps_unused = LoadRoom(world, maps_rig, /*use_maps=*/false);
  const CalibratedRoom without = LoadRoom(world, WriteRig(world, dir.path() / "plain", false));
  ASSERT_TRUE(HasReflectanceMaps(with_maps.projection));
  ASSERT_FALSE(HasReflectanceMaps(maps_unused.projection));
  const Shot plain = Photograph(world, without);
  const Shot unused = Photograph(world, maps_unused);
  const Shot mapped = Photograph(world, with_maps);
  // A rig without maps, or with maps left unused, renders what the renderer renders per patch.
  SolverSummary summary;
  const CompensationSolution solution = Solve(SolverOptions(), without.problem, &summary);
  RenderSummary render;
  const std::vector<ProjectorImage> per_patch =
      RenderProjectorImages(without.projection, solution.emittance, RenderOptions(), &render);
  ASSERT_EQ(plain.images.size(), per_patch.size());
  for (size_t k = 0; k < per_patch.size(); ++k) {
    EXPECT_EQ(cv::norm(plain.images[k].codes, per_patch[k].codes, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(unused.images[k].codes, per_patch[k].codes, cv::NORM_INF), 0.0);
  }
  std::printf(
      "unprinted back wall: photo vs desired CIEDE2000 %.4f (no maps), %.4f (maps); "
      "within-patch %.4f / %.4f\n",
      plain.mean2000, mapped.mean2000, plain.print2000, mapped.print2000);
  // Maps constant over each wall ask every pixel for the patch's level (q = 1): the photo is the
  // per-patch one up to the renderer's other path (identical to 4 decimals, measured).
  EXPECT_NEAR(mapped.mean2000, plain.mean2000, 0.01);
  EXPECT_NEAR(mapped.print2000, plain.print2000, 0.01);
}

}  // namespace
}  // namespace procam
