// The scan-accuracy measures against a known answer: the true room measured against itself
// through a frame that is off by a known rigid motion.
#include "datasets_synthetic/scan_accuracy.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "datasets_synthetic/paper_scenes.h"

namespace procam {
namespace {

// The "scanned" room is the true one in a frame off by 0.5° and 2 cm: measured through that
// frame every surface lies millimetres off; FitScannedRoom finds the motion back (identity) where
// the room pins all six degrees of freedom (l_shaped: floor and two walls), and through it every
// surface lies on the truth. blue_curves' floor and curved wall leave a turn about the wall's
// axis nearly free: there only the surfaces' distances are held.
TEST(ScanAccuracy, TheBestRigidFitUndoesAKnownFrameError) {
  for (const char* name : {"l_shaped", "blue_curves"}) {
    const Scene scene = MakeSyntheticScene(name).scene;
    const RoomModel truth(scene);
    const RoomModel scanned(scene);
    Eigen::Isometry3d off = Eigen::Isometry3d::Identity();
    off.rotate(Eigen::AngleAxisd(0.5 * M_PI / 180, Vec3(0.3, -0.5, 0.8).normalized()));
    off.pretranslate(Vec3(0.02, -0.012, 0.008));
    const Eigen::Isometry3d fitted = FitScannedRoom(truth, scanned, off);
    const double angle_deg = Eigen::AngleAxisd(fitted.linear()).angle() * 180 / M_PI;
    const double shift_mm = 1e3 * fitted.translation().norm();
    double worst_off = 0.0, worst_fitted = 0.0;
    for (int s = 0; s < static_cast<int>(scene.surfaces.size()); ++s) {
      worst_off = std::max(worst_off, MeasureScannedSurface(truth, scanned, s, off).RmsMetres());
      worst_fitted = std::max(worst_fitted, MeasureScannedSurface(truth, scanned, s, fitted).RmsMetres());
    }
    std::printf("%s: fitted motion %.4f deg, %.3f mm; surfaces up to %.2f mm RMS off through the "
                "wrong frame, %.3f mm after the fit\n",
                name, angle_deg, shift_mm, 1e3 * worst_off, 1e3 * worst_fitted);
    EXPECT_GT(worst_off, 0.005) << name;
    if (std::string(name) == "l_shaped") {
      EXPECT_LT(angle_deg, 0.01) << name;
      EXPECT_LT(shift_mm, 0.5) << name;
    }
    EXPECT_LT(worst_fitted, 0.0005) << name;
  }
}

// SeenAndLitArea against closed forms: a 4 × 3 m floor seen whole by a camera 10 m above it.
// Lit whole by a projector beside the camera: all 12 m². Lit by a projector whose principal
// point is at its image's left edge, pixel 0's outer side (it lights only x ≥ 2 m): half, 6 m², to the 1 cm cells.
// Under a 1 × 1 m table top 1 m above the floor, which the camera's and projector's rays meet
// first, the floor loses the table's shadow: 1 m² (the devices are 10 m up, so the shadow is the
// table's footprint scaled by 10/9).
TEST(ScanAccuracy, SeenAndLitAreaOfAFloor) {
  Scene scene;
  Surface floor;
  floor.name = "floor";
  floor.quad = {Vec3(0, 0, 0), Vec3(4, 0, 0), Vec3(4, 3, 0), Vec3(0, 3, 0)};
  scene.surfaces.push_back(floor);
  const Vec3 above(2.0, 1.5, 10.0), below(2.0, 1.5, 0.0), up(0.0, 1.0, 0.0);
  const auto device = [&](double cx) {
    return ProjectorGeometry::Pinhole(500, 500, cx, 400, 1000, 800,
                                      ProjFromWorldLookingAt(above, below, up));
  };
  const ProjectorGeometry camera = device(499.5), whole = device(499.5), half = device(-0.5);
  {
    const RoomModel truth(scene);
    const RayScene rays(scene);
    EXPECT_NEAR(SeenAndLitArea(truth, rays, 0, camera, {whole}), 12.0, 1e-9);
    EXPECT_NEAR(SeenAndLitArea(truth, rays, 0, camera, {half}), 6.0, 0.02);
    EXPECT_NEAR(SeenAndLitArea(truth, rays, 0, camera, {half, whole}), 12.0, 1e-9);
  }
  Surface table;
  table.name = "table";
  table.quad = {Vec3(0.5, 0.5, 1), Vec3(1.5, 0.5, 1), Vec3(1.5, 1.5, 1), Vec3(0.5, 1.5, 1)};
  scene.surfaces.push_back(table);
  const RoomModel truth(scene);
  const RayScene rays(scene);
  const double shadow = 1.0 * (10.0 / 9.0) * (10.0 / 9.0);
  EXPECT_NEAR(SeenAndLitArea(truth, rays, 0, camera, {whole}), 12.0 - shadow, 0.03);
  EXPECT_NEAR(SeenAndLitArea(truth, rays, 1, camera, {whole}), 1.0, 1e-9);
}

}  // namespace
}  // namespace procam
