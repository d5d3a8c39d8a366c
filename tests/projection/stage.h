#pragma once
// A small generated stage for the projection tests: a back wall and a floor, optionally a
// plate floating in front of the wall, lit by two pinhole projectors whose images overlap on
// the wall. Everything the tests check is stated here.

#include <string>
#include <vector>

#include "datasets_synthetic/rooms.h"
#include "geometry/patches.h"
#include "projection/projector.h"

namespace procam::testing {

struct StageOptions {
  bool plate = true;  // a 0.8 × 0.7 m plate 1 m in front of the wall, facing the projectors
  int target_patches = 300;
  int width = 320, height = 240;  // projector images
  int bits = 8;
  double black = 0.02, max = 12.0;  // photometry of both projectors (grey)
};

struct Stage {
  Scene scene;
  PatchHierarchy patches;
  std::vector<Projector> projectors;
  // Surface indices.
  static constexpr int kWall = 0, kFloor = 1, kPlate = 2;
};

inline Projector MakeStageProjector(const std::string& name, const Vec3& centre, const Vec3& target,
                                    const StageOptions& options) {
  Projector projector;
  projector.name = name;
  const double focal = 1.1 * options.width;  // about 49° across
  projector.geometry = ProjectorGeometry::Pinhole(
      focal, focal, 0.5 * (options.width - 1), 0.5 * (options.height - 1), options.width,
      options.height, ProjFromWorldLookingAt(centre, target, Vec3::UnitZ()));
  projector.photometry.black = Vec3::Constant(options.black);
  projector.photometry.max = Vec3::Constant(options.max);
  projector.photometry.bits = options.bits;
  return projector;
}

inline Stage MakeStage(const StageOptions& options) {
  Stage stage;
  stage.scene.name = "stage";
  stage.scene.target_patches = options.target_patches;
  // Wall at y = 3 and plate at y = 2 facing −y, floor at z = 0 facing +z (normal = u × v).
  stage.scene.surfaces.push_back(
      MakeRectangle(Vec3(0, 3, 0), Vec3(4, 0, 0), Vec3(0, 0, 2.5), 0.8, Vec3(0.5, 0.5, 0.5)));
  stage.scene.surfaces.push_back(
      MakeRectangle(Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(0, 3, 0), 0.6, Vec3(0.5, 0.5, 0.5)));
  if (options.plate) {
    stage.scene.surfaces.push_back(MakeRectangle(Vec3(1.6, 2.0, 0.9), Vec3(0.8, 0, 0),
                                                 Vec3(0, 0, 0.7), 0.7, Vec3(0.5, 0.5, 0.5)));
  }
  stage.scene.surfaces[0].name = "wall";
  stage.scene.surfaces[1].name = "floor";
  if (options.plate) stage.scene.surfaces[2].name = "plate";
  SubdivisionOptions subdivision;
  subdivision.target_patches = options.target_patches;
  stage.patches = SubdividePatches(stage.scene, subdivision);
  stage.projectors.push_back(
      MakeStageProjector("left", Vec3(1.4, -1.5, 1.4), Vec3(2.2, 3.0, 1.1), options));
  stage.projectors.push_back(
      MakeStageProjector("right", Vec3(2.6, -1.5, 1.5), Vec3(1.9, 3.0, 1.2), options));
  return stage;
}

}  // namespace procam::testing
