// Self-calibration of the room (no model, no camera-pose guess) against the synthetic rigs'
// ground truth. Correspondences come from the geometry, as registration_test's exact ones do:
// every `step`-th camera pixel whose surface point a projector lights unoccluded, with the
// projector pixel of that point plus Gaussian decoding noise (0.3 px per coordinate). The scale
// input (the camera's height above the floor) is given its true value.
#include "calibration/self_calibration.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <random>
#include <tuple>

#include "calibration/structured_light.h"
#include "datasets_synthetic/scan_accuracy.h"
#include "datasets_synthetic/simulated_rig.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "geometry/ray_scene.h"
#include "geometry/scene_from_points.h"

namespace procam {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDecodingNoisePx = 0.3;

// The synthetic scene `name`'s rig; `camera_scale` < 1 shrinks the camera's image (same field of
// view). `shift_cy` (optional) moves projector k's principal point down by shift_cy[k] pixels
// (a lens shift), its pose kept; `distortion_0` (optional: k1, k2, p1, p2) gives projector 0 a
// LENSMODEL_OPENCV4 lens with that distortion.
std::unique_ptr<SimulatedRig> MakeRig(const std::string& name, double camera_scale = 1.0,
                                      const std::vector<double>& shift_cy = {},
                                      const std::vector<double>& distortion_0 = {}) {
  SyntheticScene synthetic = MakeSyntheticScene(name, 60);
  synthetic.camera.width = static_cast<int>(std::lround(synthetic.camera.width * camera_scale));
  synthetic.camera.height = static_cast<int>(std::lround(synthetic.camera.height * camera_scale));
  std::vector<Projector> projectors;
  for (size_t k = 0; k < synthetic.projectors.size(); ++k) {
    Projector projector = ProjectorFromPlacement(synthetic.projectors[k]);
    if (k < shift_cy.size()) {
      const ProjectorGeometry& g = projector.geometry;
      const std::vector<double>& in = g.intrinsics();
      projector.geometry = ProjectorGeometry::Pinhole(in[0], in[1], in[2], in[3] + shift_cy[k],
                                                      g.width(), g.height(), g.proj_from_world());
    }
    if (k == 0 && !distortion_0.empty()) {
      const ProjectorGeometry& g = projector.geometry;
      std::vector<double> lens(g.intrinsics().begin(), g.intrinsics().begin() + 4);
      lens.insert(lens.end(), distortion_0.begin(), distortion_0.end());
      projector.geometry =
          ProjectorGeometry("LENSMODEL_OPENCV4", lens, g.width(), g.height(), g.proj_from_world());
    }
    projectors.push_back(projector);
  }
  SimulatedRigOptions options;
  options.solver_patches = 60;
  options.world_factor = 1;
  return std::make_unique<SimulatedRig>(synthetic.scene, projectors,
                                        CameraFromPlacement(synthetic.camera), options);
}

// Projector k's correspondences: every `step`-th camera pixel whose point it lights unoccluded,
// the projector pixel of that point plus N(0, noise²) per coordinate. `keep` (optional) selects
// by the point in the room.
ProjectorObservations NoisyObservations(const SimulatedRig& rig, int k, int step, double noise,
                                        const std::function<bool(const Vec3&)>& keep = nullptr,
                                        unsigned seed = 0) {
  const ProjectorGeometry& projector = rig.projectors()[k].geometry;
  const RayScene surfaces(rig.scene());
  std::mt19937 random(1000 + k + 7919 * seed);
  std::normal_distribution<double> decoding(0.0, noise);
  ProjectorObservations out;
  out.name = rig.projectors()[k].name;
  out.width = projector.width();
  out.height = projector.height();
  for (int row = 0; row < rig.camera().height(); row += step)
    for (int col = 0; col < rig.camera().width(); col += step) {
      Vec3 point, normal;
      Vec2 pixel;
      if (!rig.PointSeenByPixel(row, col, &point, &normal)) continue;
      if (projector.Gain(point, normal, &pixel) <= 0.0 || !projector.InImage(pixel)) continue;
      if (surfaces.Occluded(point, projector.CentreInWorld(), 1e-4)) continue;
      if (keep && !keep(point)) continue;
      out.camera_pixels.push_back(Vec2(col, row));
      out.projector_pixels.push_back(pixel + Vec2(decoding(random), decoding(random)));
    }
  return out;
}

RoomCalibrationProblem MakeProblem(const SimulatedRig& rig, int step) {
  RoomCalibrationProblem problem;
  problem.camera_lens_model = rig.camera().lens_model();
  problem.camera_intrinsics = rig.camera().intrinsics();
  for (int k = 0; k < static_cast<int>(rig.projectors().size()); ++k)
    problem.projectors.push_back(NoisyObservations(rig, k, step, kDecodingNoisePx));
  return problem;
}

// Decoded correspondences of projector k, as registration_test makes them: the rig photographs
// XOR Gray + phase patterns on it (the other projectors black; bounces, camera distortion and
// noise), DecodeStructuredLight decodes them.
ProjectorObservations DecodedObservations(const SimulatedRig& rig, int k) {
  const ProjectorGeometry& geometry = rig.projectors()[k].geometry;
  StructuredLightOptions options;
  options.width = geometry.width();
  options.height = geometry.height();
  options.pattern_gamma = rig.projectors()[k].photometry.response[0].gamma();
  const CaptureSequence sequence = MakeStructuredLightSequence(options);
  std::vector<ProjectorImage> images;
  for (const Projector& p : rig.projectors())
    images.push_back(
        {cv::Mat(p.geometry.height(), p.geometry.width(), CV_16UC3, cv::Scalar::all(0)), 8});
  std::vector<cv::Mat> captured;
  uint32_t seed = 100 * k;
  for (const Pattern& pattern : sequence.patterns) {
    images[k] = CodesFromPattern(pattern.image, rig.projectors()[k]);
    captured.push_back(rig.PhotographLinear(images, ++seed));
  }
  const StructuredLightMap map = DecodeStructuredLight(options, captured);
  return ObservationsFromMap(map, rig.projectors()[k].name, geometry.width(), geometry.height());
}

// MakeProblem's problem with every projector's correspondences decoded (DecodedObservations).
RoomCalibrationProblem MakeDecodedProblem(const SimulatedRig& rig) {
  RoomCalibrationProblem problem;
  problem.camera_lens_model = rig.camera().lens_model();
  problem.camera_intrinsics = rig.camera().intrinsics();
  for (int k = 0; k < static_cast<int>(rig.projectors().size()); ++k)
    problem.projectors.push_back(DecodedObservations(rig, k));
  return problem;
}

double TurnDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a * b.transpose()).angle() * 180.0 / kPi;
}

double CameraHeight(const SimulatedRig& rig) {
  return rig.camera().proj_from_world().inverse().translation().z();  // the floor is z = 0
}

struct ProjectorErrors {
  double fx = 0, fy = 0;       // relative
  double cx = 0, cy = 0;       // px
  double position_mm = 0;      // the projector's centre in the camera frame
  double orientation_deg = 0;  // its orientation relative to the camera
};

// Errors of projector k relative to the camera (the room frames of the truth and the estimate
// differ by a turn about the vertical and a shift, so the poses are compared in the camera frame).
ProjectorErrors Compare(const RoomCalibration& calibration, const SimulatedRig& rig, int k) {
  const RoomProjector& estimate = calibration.projectors[k];
  const ProjectorGeometry& truth = rig.projectors()[k].geometry;
  const Eigen::Isometry3d world_from_cam = rig.camera().proj_from_world().inverse();
  const Eigen::Isometry3d true_proj_from_cam = truth.proj_from_world() * world_from_cam;
  const Eigen::Isometry3d proj_from_cam = estimate.proj_from_room * calibration.room_from_camera;
  ProjectorErrors e;
  e.fx = std::abs(estimate.intrinsics[0] / truth.intrinsics()[0] - 1.0);
  e.fy = std::abs(estimate.intrinsics[1] / truth.intrinsics()[1] - 1.0);
  e.cx = std::abs(estimate.intrinsics[2] - truth.intrinsics()[2]);
  e.cy = std::abs(estimate.intrinsics[3] - truth.intrinsics()[3]);
  e.position_mm =
      1e3 *
      (proj_from_cam.inverse().translation() - true_proj_from_cam.inverse().translation()).norm();
  e.orientation_deg = TurnDeg(proj_from_cam.linear(), true_proj_from_cam.linear());
  return e;
}

// Where projector k of `calibration` shows the point `in_camera_true` (camera frame, metres, of
// the true rig) taken in units of the projector's distance from the camera: the point scaled by
// the calibration's baseline over the true one (SelfCalibrationProjectorSummary's definition).
Vec2 ShowScaledPoint(const RoomCalibration& calibration, int k, const Vec3& in_camera_true,
                     double true_baseline) {
  const RoomProjector& p = calibration.projectors[k];
  const Eigen::Isometry3d proj_from_cam = p.proj_from_room * calibration.room_from_camera;
  const Vec3 q = proj_from_cam *
                 Vec3(in_camera_true * (proj_from_cam.translation().norm() / true_baseline));
  return Vec2(p.intrinsics[0] * q.x() / q.z() + p.intrinsics[2],
              p.intrinsics[1] * q.y() / q.z() + p.intrinsics[3]);
}

// Angle between the estimated room's up (+z) and the true one, both in the camera frame.
double FloorNormalErrorDeg(const RoomCalibration& calibration, const SimulatedRig& rig) {
  const Vec3 up_estimate = calibration.room_from_camera.linear().transpose() * Vec3::UnitZ();
  const Vec3 up_truth = rig.camera().proj_from_world().linear() * Vec3::UnitZ();
  return std::acos(std::clamp(up_estimate.dot(up_truth), -1.0, 1.0)) * 180.0 / kPi;
}

// RMS distance (mm) of the points, taken into the camera frame, to the surface points their
// camera pixels see.
double PointRmsMm(const std::vector<SelfCalibrationPoint>& points,
                  const RoomCalibration& calibration, const SimulatedRig& rig) {
  const Eigen::Isometry3d camera_from_room = calibration.room_from_camera.inverse();
  double sum = 0.0;
  int count = 0;
  for (const SelfCalibrationPoint& point : points) {
    Vec3 truth;
    if (!rig.PointSeenByPixel(static_cast<int>(point.camera_pixel.y()),
                              static_cast<int>(point.camera_pixel.x()), &truth))
      continue;
    sum +=
        (camera_from_room * point.p_in_room - rig.camera().proj_from_world() * truth).squaredNorm();
    ++count;
  }
  return 1e3 * std::sqrt(sum / std::max(count, 1));
}

struct Bounds {
  double focal = 0.01;           // relative
  double principal_point = 5.0;  // px
  double position_mm = 5.0;
  double orientation_deg = 0.1;
  double floor_deg = 0.5;
  // RMS distance of the points to the true surface points of their camera pixels: triangulation
  // noise (σ_depth ≈ σ_px · pixel footprint · depth / baseline), not a scene-fit accuracy.
  // Up to 5.5 mm measured on the 3–4 m rigs over six noise seeds (3.6 mm with the default one).
  double point_rms_mm = 8.0;
  // The decoding noise the reprojection RMS is checked against, px; 0: not checked.
  double decoding_noise_px = kDecodingNoisePx;
};

// Calibrates `problem` of `rig` with `options` (camera_height set to the truth) and checks the
// result against the truth; the summary (optional) is returned.
void CalibrateAndCheck(const std::string& name, const SimulatedRig& rig,
                       const RoomCalibrationProblem& problem, const Bounds& bounds,
                       SelfCalibrationSummary* summary_out = nullptr,
                       SelfCalibrationOptions options = SelfCalibrationOptions()) {
  options.camera_height = CameraHeight(rig);
  RoomCalibration calibration;
  std::vector<SelfCalibrationPoint> points;
  SelfCalibrationSummary summary;
  ASSERT_TRUE(SelfCalibrateRoom(options, problem, &calibration, &points, &summary))
      << summary.BriefReport();
  if (summary_out) *summary_out = summary;
  std::printf("%s: %s\n", name.c_str(), summary.BriefReport().c_str());
  const double floor_deg = FloorNormalErrorDeg(calibration, rig);
  const double point_rms_mm = PointRmsMm(points, calibration, rig);
  std::printf("  floor normal %.4f deg; points RMS %.2f mm to the true surfaces\n", floor_deg,
              point_rms_mm);
  EXPECT_LT(floor_deg, bounds.floor_deg);
  EXPECT_LT(point_rms_mm, bounds.point_rms_mm);
  EXPECT_NEAR(calibration.room_from_camera.translation().z(), options.camera_height, 1e-9);
  for (int k = 0; k < static_cast<int>(calibration.projectors.size()); ++k) {
    const ProjectorErrors e = Compare(calibration, rig, k);
    std::printf(
        "  projector %d: fx %.4f%%, fy %.4f%%, cx %.3f px, cy %.3f px, position %.3f mm, "
        "orientation %.4f deg\n",
        k, 100 * e.fx, 100 * e.fy, e.cx, e.cy, e.position_mm, e.orientation_deg);
    EXPECT_LT(e.fx, bounds.focal) << "projector " << k;
    EXPECT_LT(e.fy, bounds.focal) << "projector " << k;
    EXPECT_LT(e.cx, bounds.principal_point) << "projector " << k;
    EXPECT_LT(e.cy, bounds.principal_point) << "projector " << k;
    EXPECT_LT(e.position_mm, bounds.position_mm) << "projector " << k;
    EXPECT_LT(e.orientation_deg, bounds.orientation_deg) << "projector " << k;
    // The reprojection RMS per coordinate is below the decoding noise: each point's depth
    // absorbs one of its 2 (one projector) or 4 (two) residuals, σ·√(1/2) to σ·√(3/4).
    if (bounds.decoding_noise_px > 0.0) {
      EXPECT_LT(summary.projectors[k].rms, 1.1 * bounds.decoding_noise_px) << "projector " << k;
      EXPECT_GT(summary.projectors[k].rms, 0.65 * bounds.decoding_noise_px) << "projector " << k;
    }
  }
}

// ---------------------------------------------------------------------------------------------

// The tiny box (1 m, 320 × 200 projectors, 240 × 160 camera): every second camera pixel. Its
// pixels are millimetres wide and the projectors 0.4 m from the camera: a point's depth is
// ~10 mm uncertain.
TEST(SelfCalibrateRoom, TinyBox) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("tiny_box");
  Bounds bounds;
  bounds.point_rms_mm = 20.0;  // 11.5 mm measured; up to 14.5 mm over five other noise seeds
  CalibrateAndCheck("tiny_box", *rig, MakeProblem(*rig, 2), bounds);
}

// The tiny box from simulated captures decoded by DecodeStructuredLight (decoding errors at
// edges, bounces): the outliers the robust pass removes, the RMS is the decoder's.
TEST(SelfCalibrateRoom, TinyBoxDecoded) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("tiny_box");
  const RoomCalibrationProblem problem = MakeDecodedProblem(*rig);
  Bounds bounds;
  bounds.point_rms_mm = 25.0;  // measured 17.5 mm: exact-data noise plus decoding errors at edges
  bounds.decoding_noise_px = 0.0;  // unknown: not checked
  CalibrateAndCheck("tiny_box decoded", *rig, problem, bounds);
}

// The L-shaped stage (3 m, two 1280 × 800 projectors 4–5 m from the back wall; camera 960 × 640
// at half size).
TEST(SelfCalibrateRoom, LShaped) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("l_shaped", 0.5);
  CalibrateAndCheck("l_shaped", *rig, MakeProblem(*rig, 2), Bounds());
}

// The same from simulated captures decoded by DecodeStructuredLight.
TEST(SelfCalibrateRoom, LShapedDecoded) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("l_shaped", 0.5);
  const RoomCalibrationProblem problem = MakeDecodedProblem(*rig);
  Bounds bounds;
  bounds.decoding_noise_px = 0.0;  // unknown: not checked
  CalibrateAndCheck("l_shaped decoded", *rig, problem, bounds);
}

// Columns: three projectors, occlusions by the two columns.
TEST(SelfCalibrateRoom, Columns) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("columns", 0.5);
  CalibrateAndCheck("columns", *rig, MakeProblem(*rig, 2), Bounds());
}

// Lens-shifted projectors (principal points 120 and 200 px below the centre, as a ceiling
// projector's offset puts it): the seed assumes the centre, the shared points pin the truth.
TEST(SelfCalibrateRoom, LensShiftedProjectors) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("l_shaped", 0.5, {120.0, 200.0});
  CalibrateAndCheck("l_shaped, lens shift", *rig, MakeProblem(*rig, 2), Bounds());
}

// Principal points 400 px above the centre of 800 px tall projectors (l_shaped).
TEST(SelfCalibrateRoom, LargeLensShiftFromTheCentreSeed) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("l_shaped", 0.5, {-400.0, -400.0});
  CalibrateAndCheck("l_shaped, lens shift -400 px", *rig, MakeProblem(*rig, 2), Bounds());
}

// Columns, principal points 300 px above the centre: the seed's search along cy finds the side
// projectors' (the centre one, straight above the camera, keeps its guess) and the solve lands
// on the truth. Without that search the centre guess leads the solve astray: refused
// (kInconsistent, naming a projector) rather than returned; the true principal points as guesses
// (a lens-shift specification) recover the truth again.
TEST(SelfCalibrateRoom, FarLensShift) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("columns", 0.5, {-300.0, -300.0, -300.0});
  const RoomCalibrationProblem problem = MakeProblem(*rig, 2);
  CalibrateAndCheck("columns, lens shift -300 px", *rig, problem, Bounds());

  SelfCalibrationOptions options;
  options.camera_height = CameraHeight(*rig);
  options.search_principal_point_y = false;
  RoomCalibration calibration;
  SelfCalibrationSummary summary;
  EXPECT_FALSE(SelfCalibrateRoom(options, problem, &calibration, nullptr, &summary));
  EXPECT_EQ(summary.termination, SelfCalibrationSummary::kInconsistent) << summary.BriefReport();
  EXPECT_NE(summary.message.find("projector '"), std::string::npos) << summary.message;
  std::printf("%s\n", summary.message.c_str());

  for (const Projector& projector : rig->projectors())
    options.principal_point_guesses.push_back(
        Vec2(projector.geometry.intrinsics()[2], projector.geometry.intrinsics()[3]));
  CalibrateAndCheck("columns, lens shift -300 px, no search, guessed", *rig, problem, Bounds(),
                    nullptr, options);
}

// The camera's lens as a chessboard leaves it on the green trapezoid's rig (the demo's, at half
// size): fx, cy and k2 off by about their chessboard uncertainty, which is given as the prior's
// covariance (independent parameters here).
struct ChessboardLens {
  std::vector<double> intrinsics;
  Eigen::MatrixXd covariance;
};
ChessboardLens OffByItsUncertainty(const CameraGeometry& camera) {
  ChessboardLens lens;
  const std::vector<double> sigma = {0.15, 0.15, 0.2, 0.15, 7e-4, 1.8e-3, 1e-4, 1e-4};
  const std::vector<double> off = {0.15, -0.05, -0.1, 0.2, 1e-3, -4e-3, 1.5e-4, -5e-5};
  lens.intrinsics = camera.intrinsics();
  lens.covariance = Eigen::MatrixXd::Zero(8, 8);
  for (int i = 0; i < 8; ++i) {
    lens.intrinsics[i] += off[i];
    lens.covariance(i, i) = sigma[i] * sigma[i];
  }
  return lens;
}

// How far `estimate` projects from the camera's true lens, px, once the best rotation between
// their rays is taken out (a turn of the whole lens is a turn of the camera, which the scan
// cannot see): the largest over a grid of pixels, the angle times the true focal length.
double LensErrorAfterRotationPx(const CameraGeometry& camera, const std::vector<double>& estimate) {
  std::vector<Vec3> truth_rays, estimate_rays;
  for (int j = 0; j < 12; ++j)
    for (int i = 0; i < 16; ++i) {
      const Vec2 pixel(i * (camera.width() - 1) / 15.0, j * (camera.height() - 1) / 11.0);
      Vec3 t, e;
      EXPECT_TRUE(UnprojectCameraPixel(camera.lens_model(), camera.intrinsics(), pixel, &t));
      EXPECT_TRUE(UnprojectCameraPixel(camera.lens_model(), estimate, pixel, &e));
      truth_rays.push_back(t.normalized());
      estimate_rays.push_back(e.normalized());
    }
  Eigen::Matrix3Xd from(3, truth_rays.size()), to(3, truth_rays.size());
  for (size_t i = 0; i < truth_rays.size(); ++i) {
    from.col(i) = truth_rays[i];
    to.col(i) = estimate_rays[i];
  }
  const Eigen::Matrix3d turn = Eigen::umeyama(from, to, false).topLeftCorner<3, 3>();
  double worst = 0.0;
  for (size_t i = 0; i < truth_rays.size(); ++i)
    worst = std::max(worst, std::acos(std::clamp((turn * from.col(i)).dot(to.col(i)), -1.0, 1.0)));
  return worst * camera.intrinsics()[0];
}

// With the chessboard's covariance the bundle adjustment refines the whole lens: the structured
// light covers the image where the chessboard pins it least. The refined lens is closer to the
// truth than the chessboard's, and moved by about the chessboard's own uncertainty.
TEST(SelfCalibrateRoom, TheChessboardLensIsRefinedWithItsUncertaintyAsPrior) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("green_trapezoid", 0.5);
  RoomCalibrationProblem problem = MakeProblem(*rig, 2);
  const ChessboardLens chessboard = OffByItsUncertainty(rig->camera());
  problem.camera_intrinsics = chessboard.intrinsics;
  SelfCalibrationOptions options;
  options.camera_height = CameraHeight(*rig);
  RoomCalibration held, refined;
  SelfCalibrationSummary held_summary, summary;
  ASSERT_TRUE(SelfCalibrateRoom(options, problem, &held, nullptr, &held_summary));
  EXPECT_FALSE(held_summary.camera_lens_refined);
  EXPECT_EQ(held.camera_intrinsics, chessboard.intrinsics);
  options.refine_camera_lens = true;
  EXPECT_THROW(SelfCalibrateRoom(options, problem, &refined, nullptr, &summary),
               std::invalid_argument);  // no covariance
  problem.camera_intrinsics_covariance = chessboard.covariance;
  ASSERT_TRUE(SelfCalibrateRoom(options, problem, &refined, nullptr, &summary))
      << summary.BriefReport();
  std::printf("%s\n", summary.BriefReport().c_str());
  const double before = LensErrorAfterRotationPx(rig->camera(), chessboard.intrinsics);
  const double after = LensErrorAfterRotationPx(rig->camera(), refined.camera_intrinsics);
  std::printf("camera lens off the truth after the best turn: chessboard %.3f px, refined %.3f px\n",
              before, after);
  EXPECT_TRUE(summary.camera_lens_refined);
  EXPECT_LT(after, 0.5 * before);
  EXPECT_GT(summary.camera_lens_moved_sigmas, 0.5);
  EXPECT_LT(summary.camera_lens_moved_sigmas, 10.0);
  ASSERT_EQ(summary.camera_lens_moved.size(), 8u);
  for (int i = 0; i < 8; ++i)
    EXPECT_DOUBLE_EQ(summary.camera_lens_moved[i],
                     refined.camera_intrinsics[i] - chessboard.intrinsics[i]);

  // A covariance of the wrong size is refused.
  problem.camera_intrinsics_covariance = Eigen::MatrixXd::Identity(4, 4);
  EXPECT_THROW(SelfCalibrateRoom(options, problem, &refined, nullptr, &summary),
               std::invalid_argument);
}

// The floor held to a normal measured apart from the scan (the floor chessboard's): with the
// chessboard's lens held, the scan's floor is tilted against the camera; held to the true normal
// it is not, and the points lie nearer their true places. A normal farther from the scan's floor
// than max_floor_normal_deg is not used.
TEST(SelfCalibrateRoom, TheFloorIsHeldToAGivenNormal) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("green_trapezoid", 0.5);
  RoomCalibrationProblem problem = MakeProblem(*rig, 2);
  problem.camera_intrinsics = OffByItsUncertainty(rig->camera()).intrinsics;
  SelfCalibrationOptions options;
  options.camera_height = CameraHeight(*rig);
  const Vec3 true_up = rig->camera().proj_from_world().linear() * Vec3::UnitZ();
  RoomCalibration free_floor, held_floor, far_normal;
  std::vector<SelfCalibrationPoint> free_points, held_points;
  SelfCalibrationSummary summary;
  ASSERT_TRUE(SelfCalibrateRoom(options, problem, &free_floor, &free_points, &summary));
  EXPECT_FALSE(summary.floor_normal_held);
  EXPECT_TRUE(std::isnan(summary.floor_to_given_normal_deg));
  options.floor_normal_in_camera = true_up;
  ASSERT_TRUE(SelfCalibrateRoom(options, problem, &held_floor, &held_points, &summary))
      << summary.BriefReport();
  std::printf("%s\n", summary.BriefReport().c_str());
  const double free_deg = FloorNormalErrorDeg(free_floor, *rig);
  const double held_deg = FloorNormalErrorDeg(held_floor, *rig);
  const double free_mm = PointRmsMm(free_points, free_floor, *rig);
  const double held_mm = PointRmsMm(held_points, held_floor, *rig);
  std::printf("floor normal off the truth: %.4f deg free, %.4f deg held; points %.2f / %.2f mm\n",
              free_deg, held_deg, free_mm, held_mm);
  EXPECT_TRUE(summary.floor_normal_held);
  EXPECT_NEAR(summary.floor_to_given_normal_deg, free_deg, 1e-6);
  EXPECT_LT(held_deg, 0.01 * free_deg);
  EXPECT_LT(held_mm, 0.5 * free_mm);

  // 5° off: refused, the scan's own floor kept.
  options.floor_normal_in_camera =
      Eigen::AngleAxisd(5.0 * kPi / 180.0, Vec3::UnitX()) * true_up;
  ASSERT_TRUE(SelfCalibrateRoom(options, problem, &far_normal, nullptr, &summary));
  EXPECT_FALSE(summary.floor_normal_held);
  EXPECT_NEAR(summary.floor_to_given_normal_deg, 5.0, 0.2);  // 5° ± the scan's own 0.11°
  EXPECT_NEAR(FloorNormalErrorDeg(far_normal, *rig), free_deg, 1e-9);
}

// The room from its own scan on two of the six scenes, everything after the decoding as
// `calibrate projectors` runs it without a model: the self-calibration with the chessboard's lens
// off by about its uncertainty (OffByItsUncertainty) and the floor held to a board normal 0.03°
// off the truth (what the floor chessboard measured through such a lens on the demo's
// green_trapezoid: 0.034°), every correspondence triangulated, SceneFromPoints. Camera at half
// size (480 × 320), all its pixels, decoding noise 0.3 px. Measured against the truth through the
// camera's pose (the frame the rig uses, not a fit): every true surface the scan can see found,
// each planar surface within the 5 mm RMS, its area against the area the camera sees and a
// projector lights (SeenAndLitArea), nothing spurious above 1% of the room's area.
// The points: one per camera pixel (FusePerCameraPixel), as the scan makes them.
// Measured (2026-11-28): green_trapezoid 3.6–4.6 mm, areas −0.21 to +0.22%; l_shaped 2.3–3.4 mm,
// −0.14 to +0.01%; interior_partitions 1.5–3.0 mm, −0.51 to +0.12% (floors seen at 65–70°
// included; before the points were one per pixel, its floor came out in two pieces, −3.3%).
// `decoded`: the correspondences decoded from simulated captures (DecodedObservations: the rig
// photographs the structured light, bounces, camera noise and distortion included) instead.
// `area_bounds`: true surfaces held to another area bound than the aim's 1%, percent (a known
// limit, named where it is used).
void ExpectScanMeetsAims(const std::string& name, bool decoded = false,
                         const std::map<std::string, double>& area_bounds = {}) {
  constexpr double kRmsMm = 5.0, kAreaPercent = 1.0;  // the aims for planar surfaces
  const std::unique_ptr<SimulatedRig> rig = MakeRig(name, 0.5);
  RoomCalibrationProblem problem = decoded ? MakeDecodedProblem(*rig) : MakeProblem(*rig, 1);
  problem.camera_intrinsics = OffByItsUncertainty(rig->camera()).intrinsics;
  SelfCalibrationOptions options;
  options.camera_height = CameraHeight(*rig);
  const Vec3 true_up = rig->camera().proj_from_world().linear() * Vec3::UnitZ();
  options.floor_normal_in_camera = Eigen::AngleAxisd(0.03 * kPi / 180.0, Vec3::UnitX()) * true_up;
  RoomCalibration calibration;
  SelfCalibrationSummary summary;
  ASSERT_TRUE(SelfCalibrateRoom(options, problem, &calibration, nullptr, &summary))
      << summary.BriefReport();
  ASSERT_TRUE(summary.floor_normal_held);
  // The scan's points, as calibrate projectors takes them.
  std::vector<Vec3> points_in_room;
  for (const TriangulatedPoint& point : TriangulateScan(problem, calibration))
    points_in_room.push_back(calibration.room_from_camera * point.p_in_cam);
  SceneFromPointsOptions scene_options;
  scene_options.viewpoint = calibration.room_from_camera.translation();
  scene_options.points_on_viewpoint_rays = true;  // each point on its camera pixel's ray
  const ScannedScene scanned = SceneFromPoints(points_in_room, scene_options);
  std::printf("%s: %zu points\n%s\n", name.c_str(), points_in_room.size(),
              scanned.Report().c_str());

  const Scene& truth_scene = rig->scene();
  const RoomModel truth(truth_scene), scanned_model(scanned.scene);
  const RayScene rays(truth_scene);
  std::vector<ProjectorGeometry> projectors;
  for (const Projector& p : rig->projectors()) projectors.push_back(p.geometry);
  const Eigen::Isometry3d world_from_room =
      rig->camera().proj_from_world().inverse() * calibration.room_from_camera.inverse();
  double total_area = 0.0;
  for (const ScannedSurfaceStats& stats : scanned.stats) total_area += stats.area_m2;
  std::vector<double> scanned_on(truth_scene.surfaces.size(), 0.0);
  for (int s = 0; s < static_cast<int>(scanned.scene.surfaces.size()); ++s) {
    const ScannedSurfaceAccuracy accuracy =
        MeasureScannedSurface(truth, scanned_model, s, world_from_room);
    const int t = accuracy.TrueSurface();
    std::printf("  %s on %s: %.2f mm RMS through the camera's pose, %.3f m²\n",
                scanned.scene.surfaces[s].name.c_str(), truth_scene.surfaces[t].name.c_str(),
                1e3 * accuracy.RmsMetres(), accuracy.area_m2);
    if (accuracy.area_m2 < 0.01 * total_area) continue;  // below the spurious-surface bound
    EXPECT_LT(1e3 * accuracy.RmsMetres(), kRmsMm) << scanned.scene.surfaces[s].name;
    scanned_on[t] += accuracy.area_m2;
  }
  for (size_t t = 0; t < truth_scene.surfaces.size(); ++t) {
    const double seen = SeenAndLitArea(truth, rays, static_cast<int>(t), rig->camera(), projectors);
    if (seen < 0.05) continue;  // hardly seen: not expected
    // The incidence of the camera's ray at the surface's first facet, for the record.
    const ModelFacet& facet = *std::find_if(
        truth.facets().begin(), truth.facets().end(),
        [&](const ModelFacet& f) { return f.surface == static_cast<int>(t); });
    Vec3 centroid = Vec3::Zero();
    for (const Vec3& c : facet.corners) centroid += c / facet.corners.size();
    const Vec3 ray = (centroid - rig->camera().CentreInWorld()).normalized();
    const double incidence_deg = std::acos(std::abs(ray.dot(facet.normal))) * 180.0 / kPi;
    const double error = 100.0 * (scanned_on[t] / seen - 1.0);
    std::printf("  true %s: scanned %.3f m² of %.3f m² seen and lit (%+.2f%%), incidence %.0f deg\n",
                truth_scene.surfaces[t].name.c_str(), scanned_on[t], seen, error, incidence_deg);
    EXPECT_GT(scanned_on[t], 0.0) << truth_scene.surfaces[t].name << " not found";
    const auto bound = area_bounds.find(truth_scene.surfaces[t].name);
    EXPECT_LT(std::abs(error), bound == area_bounds.end() ? kAreaPercent : bound->second)
        << truth_scene.surfaces[t].name;
  }
}

TEST(SelfCalibrateRoom, ScannedGreenTrapezoidMeetsTheAccuracyAims) {
  ExpectScanMeetsAims("green_trapezoid");
}

TEST(SelfCalibrateRoom, ScannedLShapedMeetsTheAccuracyAims) {
  ExpectScanMeetsAims("l_shaped");
}

TEST(SelfCalibrateRoom, ScannedInteriorPartitionsMeetsTheAccuracyAims) {
  ExpectScanMeetsAims("interior_partitions");
}

// From decoded captures. The left wall, seen at 67° and lit at a grazing angle by the right
// projector, has a strip near the back corner where that projector crowds many of its rows into
// each camera pixel: only its columns decode there. Without the one-axis points the wall came out
// 3.9% small (measured); with them, −0.5%.
TEST(SelfCalibrateRoom, ScannedLShapedFromDecodedCaptures) {
  ExpectScanMeetsAims("l_shaped", /*decoded=*/true);
}

// Four projectors from decoded captures: every surface within 5 mm (1.6–3.4 mm, measured), the
// walls and the partitions within 1%. Near the back corners the side walls are lit only at a
// grazing angle, where neither of that projector's axes decodes in a pocket of camera pixels
// about ten wide, and seen at a grazing angle, so that each of those pixels spans several
// centimetres of wall. The one-axis points fill part of it; the outline, run on to the corner
// where the side wall, the back wall and the floor meet (notch filling, SceneFromPoints), the rest:
// −0.24% and −0.16% (−2.9% and −2.1% without notch filling, −4.9% and −2.3% without the one-axis
// points either). The floor comes out 1.00% small (its free edge near the camera, where the
// projectors' light ends, sits a little inside; −1.11% before free edges leaned with their
// points): held to 1.5%, a known limit (docs/scan.md).
TEST(SelfCalibrateRoom, ScannedInteriorPartitionsFromDecodedCaptures) {
  ExpectScanMeetsAims("interior_partitions", /*decoded=*/true, {{"floor", 1.5}});
}

// One projector: its principal point is not observable (header) and is held at the centre,
// which is the truth here; the rest is checked as usual.
TEST(SelfCalibrateRoom, OneProjectorHoldsItsPrincipalPoint) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("l_shaped", 0.5);
  RoomCalibrationProblem problem = MakeProblem(*rig, 2);
  problem.projectors.resize(1);
  SelfCalibrationSummary summary;
  CalibrateAndCheck("l_shaped, one projector", *rig, problem, Bounds(), &summary);
  EXPECT_TRUE(summary.projectors[0].principal_point_held);
}

// A projector whose lens a chessboard calibrated joins the scan with it held (the problem's
// held_projector_lenses): l_shaped's projector 0 gets an OpenCV4 lens whose radial and tangential
// distortion the scan's pinhole cannot fit. Held at the truth, its lens comes back bit for bit
// with its pose solved, within the bounds of the other tests and no farther from the truth than
// the same scan solving every lens; the other projector's lens is still solved.
TEST(SelfCalibrateRoom, AHeldProjectorLensLeavesThePoseAloneToSolve) {
  const std::unique_ptr<SimulatedRig> rig =
      MakeRig("l_shaped", 0.5, {}, {-0.03, 0.015, 0.0008, -0.0006});
  const RoomCalibrationProblem problem = MakeProblem(*rig, 2);
  const ProjectorGeometry& truth = rig->projectors()[0].geometry;
  SelfCalibrationOptions options;
  options.camera_height = CameraHeight(*rig);
  const auto solve = [&](const char* label, const std::vector<HeldProjectorLens>& held) {
    RoomCalibrationProblem with = problem;
    with.held_projector_lenses = held;
    RoomCalibration calibration;
    std::vector<SelfCalibrationPoint> points;
    SelfCalibrationSummary summary;
    EXPECT_TRUE(SelfCalibrateRoom(options, with, &calibration, &points, &summary))
        << label << ": " << summary.BriefReport();
    std::printf("%s: %s\n  floor normal %.4f deg; points RMS %.2f mm\n", label,
                summary.BriefReport().c_str(), FloorNormalErrorDeg(calibration, *rig),
                PointRmsMm(points, calibration, *rig));
    std::vector<ProjectorErrors> errors;
    for (int k = 0; k < static_cast<int>(calibration.projectors.size()); ++k) {
      errors.push_back(Compare(calibration, *rig, k));
      const ProjectorErrors& e = errors.back();
      std::printf(
          "  projector %d: fx %.4f%%, cx %.3f px, cy %.3f px, position %.3f mm, "
          "orientation %.4f deg\n",
          k, 100 * e.fx, e.cx, e.cy, e.position_mm, e.orientation_deg);
    }
    return std::make_tuple(calibration, summary, errors);
  };
  const auto [solved, free_summary, free_errors] = solve("every lens solved", {});
  std::vector<HeldProjectorLens> held(problem.projectors.size());
  held[0] = {truth.lens_model(), truth.intrinsics(), "the truth"};
  const auto [exact, summary, errors] = solve("projector 0's lens held at the truth", held);
  ASSERT_EQ(errors.size(), 2u);
  ASSERT_EQ(free_errors.size(), 2u);

  // The lens returned is the one given, bit for bit, and marked held; the other is solved.
  EXPECT_EQ(exact.projectors[0].lens_model, "LENSMODEL_OPENCV4");
  EXPECT_EQ(exact.projectors[0].intrinsics, truth.intrinsics());
  EXPECT_TRUE(exact.projectors[0].lens_held);
  EXPECT_TRUE(summary.projectors[0].lens_held);
  EXPECT_FALSE(exact.projectors[1].lens_held);
  EXPECT_FALSE(summary.projectors[1].lens_held);
  EXPECT_EQ(exact.projectors[1].lens_model, "LENSMODEL_PINHOLE");
  EXPECT_FALSE(summary.projectors[1].principal_point_held);  // pinned by the shared points
  // The held projector's residuals are the decoding noise's: the lens is modelled exactly.
  EXPECT_LT(summary.projectors[0].rms, 1.1 * kDecodingNoisePx);
  EXPECT_GT(summary.projectors[0].rms, 0.65 * kDecodingNoisePx);
  Bounds bounds;
  for (int k = 0; k < 2; ++k) {
    EXPECT_LT(errors[k].position_mm, bounds.position_mm) << "projector " << k;
    EXPECT_LT(errors[k].orientation_deg, bounds.orientation_deg) << "projector " << k;
  }
  EXPECT_LT(errors[1].fx, bounds.focal);
  EXPECT_LT(errors[1].cx, bounds.principal_point);
  EXPECT_LT(errors[1].cy, bounds.principal_point);
  // No farther from the truth than the scan that solves a pinhole for the distorted lens.
  EXPECT_LE(errors[0].position_mm, free_errors[0].position_mm);
  EXPECT_LE(errors[0].orientation_deg, free_errors[0].orientation_deg);
  // The uncertainty is the pose's alone, over the image's pixels.
  ASSERT_FALSE(summary.projectors[0].uncertainty.grid.empty());
  EXPECT_LT(summary.projectors[0].uncertainty.centre,
            free_summary.projectors[0].uncertainty.centre);

  // Held with a board calibration's errors (docs/chessboard.md: fx +0.02%, fy −0.015%, cx +0.5 px,
  // cy −0.7 px): written as given, the pose still within the bounds and closer than the pinhole's.
  std::vector<double> board_lens = truth.intrinsics();
  board_lens[0] *= 1.0002;
  board_lens[1] *= 0.99985;
  board_lens[2] += 0.5;
  board_lens[3] -= 0.7;
  held[0] = {truth.lens_model(), board_lens, "a board calibration's errors"};
  const auto [board, board_summary, board_errors] = solve("held with a board's errors", held);
  ASSERT_EQ(board_errors.size(), 2u);
  EXPECT_EQ(board.projectors[0].intrinsics, board_lens);
  EXPECT_LT(board_errors[0].position_mm, bounds.position_mm);
  EXPECT_LT(board_errors[0].orientation_deg, bounds.orientation_deg);
  EXPECT_LT(board_errors[0].position_mm, free_errors[0].position_mm);
  EXPECT_LT(board_errors[0].orientation_deg, free_errors[0].orientation_deg);
}

// A held lens's list and lens are checked: one per projector, a supported model, finite values.
TEST(SelfCalibrateRoom, HeldLensesAreChecked) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("tiny_box");
  RoomCalibrationProblem problem = MakeProblem(*rig, 8);
  const ProjectorGeometry& truth = rig->projectors()[0].geometry;
  RoomCalibration calibration;
  SelfCalibrationSummary summary;
  const auto throws = [&](const std::vector<HeldProjectorLens>& held) {
    RoomCalibrationProblem with = problem;
    with.held_projector_lenses = held;
    EXPECT_THROW(SelfCalibrateRoom(SelfCalibrationOptions(), with, &calibration, nullptr, &summary),
                 std::invalid_argument);
  };
  std::vector<HeldProjectorLens> held(problem.projectors.size() + 1);  // one too many
  throws(held);
  held.pop_back();
  held[0] = {"LENSMODEL_OPENCV8", truth.intrinsics(), "an unsupported model"};
  throws(held);
  held[0] = {"LENSMODEL_PINHOLE", {0.0, 500.0, 160.0, 100.0}, "a zero focal length"};
  throws(held);
  held[0] = {"LENSMODEL_PINHOLE", {500.0, 500.0, std::nan(""), 100.0}, "not finite"};
  throws(held);
}

// The chain to a scene: the self-calibration's result triangulates every correspondence
// (Triangulate, as for CalibrateRoom's result), SceneFromPoints builds the room from the points in
// the room frame. The l_shaped room's three surfaces come back, the floor at height 0.
TEST(SelfCalibrateRoom, ResultFeedsTriangulateAndSceneFromPoints) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("l_shaped", 0.5);
  const RoomCalibrationProblem problem = MakeProblem(*rig, 1);
  SelfCalibrationOptions options;
  options.camera_height = CameraHeight(*rig);
  RoomCalibration calibration;
  SelfCalibrationSummary summary;
  ASSERT_TRUE(SelfCalibrateRoom(options, problem, &calibration, nullptr, &summary))
      << summary.BriefReport();
  std::vector<Vec3> points_in_room;
  for (const TriangulatedPoint& point : Triangulate(problem, calibration))
    points_in_room.push_back(calibration.room_from_camera * point.p_in_cam);
  SceneFromPointsOptions scene_options;
  scene_options.viewpoint = calibration.room_from_camera.translation();
  const ScannedScene scanned = SceneFromPoints(points_in_room, scene_options);
  std::printf("%zu points\n%s\n", points_in_room.size(), scanned.Report().c_str());
  // The three true surfaces; anything else below the spurious-surface bound (1% of the
  // scanned area: with other noise seeds the scene stage may add a small plane at a corner).
  double total_area = 0.0;
  for (const ScannedSurfaceStats& stats : scanned.stats) total_area += stats.area_m2;
  int large = 0;
  for (const ScannedSurfaceStats& stats : scanned.stats) large += stats.area_m2 > 0.01 * total_area;
  EXPECT_EQ(large, 3);
  bool found_floor = false;
  double floor_height_mm = 0.0;
  for (size_t i = 0; i < scanned.scene.surfaces.size(); ++i) {
    const Surface& surface = scanned.scene.surfaces[i];
    if (surface.name != "floor") continue;
    found_floor = true;
    const bool quad = surface.kind == Surface::Kind::kQuad;
    for (const Vec3& corner :
         quad ? std::vector<Vec3>(surface.quad.begin(), surface.quad.end()) : surface.mesh_vertices)
      floor_height_mm = std::max(floor_height_mm, 1e3 * std::abs(corner.z()));
  }
  std::printf("  floor: largest |z| of its corners %.2f mm\n", floor_height_mm);
  EXPECT_LT(floor_height_mm, 3.0);
  EXPECT_TRUE(found_floor);
}

// ---------------------------------------------------------------------------------------------

// The projection uncertainty against the spread it predicts: the tiny box calibrated from 40
// sets of correspondences, each with its own decoding noise (every 4th camera pixel, 0.3 px).
// For the image centre and the four corners of each projector, the covariance of where the 40
// calibrations show the point (at the predicted distance along the pixel's true ray) gives an
// empirical worst-direction σ; the first run's prediction must agree with it within the
// sampling error of 40 trials (about ±11% at 1σ for a standard deviation, ±33% at 3σ): a factor
// of 1.35 either way. Measured: within 5% at all ten pixels (0.32–0.38 px).
// The predicted projection uncertainty against the spread of where 40 calibrations of tiny_box,
// each from its own decoding noise, show a point fixed relative to the camera. With `lens_sigma`
// (per intrinsic, independent) each calibration also gets its own camera lens, drawn about the
// true one from that covariance, which the problem then carries: the prediction must fold the
// lens's uncertainty in, held (`refine` false) or refined with the covariance as its prior.
// Returns the mean ratio of the prediction to the one of decoding noise alone (the first
// calibration's problem without the covariance, the lens held).
double CheckProjectionUncertaintyAgainstSpread(const std::vector<double>& lens_sigma,
                                               bool refine = false) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("tiny_box");
  SelfCalibrationOptions options;
  options.camera_height = CameraHeight(*rig);
  constexpr int kTrials = 40;
  const int n = static_cast<int>(rig->projectors().size());
  Eigen::MatrixXd lens_covariance;
  if (!lens_sigma.empty()) lens_covariance = Eigen::VectorXd::Map(lens_sigma.data(), lens_sigma.size())
                                                 .cwiseAbs2()
                                                 .asDiagonal();
  std::mt19937 random(11);
  std::normal_distribution<double> gauss;
  std::vector<RoomCalibration> calibrations(kTrials);
  SelfCalibrationSummary first, noise_only;
  for (int trial = 0; trial < kTrials; ++trial) {
    RoomCalibrationProblem problem;
    problem.camera_lens_model = rig->camera().lens_model();
    problem.camera_intrinsics = rig->camera().intrinsics();
    for (size_t i = 0; i < lens_sigma.size(); ++i)
      problem.camera_intrinsics[i] += lens_sigma[i] * gauss(random);
    for (int k = 0; k < n; ++k)
      problem.projectors.push_back(
          NoisyObservations(*rig, k, 4, kDecodingNoisePx, nullptr, static_cast<unsigned>(trial)));
    if (trial == 0) {
      RoomCalibration calibration;
      options.refine_camera_lens = false;
      EXPECT_TRUE(SelfCalibrateRoom(options, problem, &calibration, nullptr, &noise_only));
    }
    problem.camera_intrinsics_covariance = lens_covariance;
    options.refine_camera_lens = refine;
    SelfCalibrationSummary summary;
    EXPECT_TRUE(SelfCalibrateRoom(options, problem, &calibrations[trial], nullptr, &summary))
        << summary.BriefReport();
    EXPECT_EQ(summary.camera_lens_refined, refine);
    if (trial == 0) first = summary;
  }
  const Eigen::Isometry3d world_from_cam = rig->camera().proj_from_world().inverse();
  double ratio_sum = 0.0;
  int ratios = 0;
  for (int k = 0; k < n; ++k) {
    const SelfCalibrationProjectorSummary& predicted = first.projectors[k];
    EXPECT_EQ(predicted.uncertainty_includes_camera_lens, !lens_sigma.empty());
    EXPECT_FALSE(noise_only.projectors[k].uncertainty_includes_camera_lens);
    EXPECT_GT(predicted.uncertainty_distance_m, 0.3) << "projector " << k;
    const ProjectorGeometry& truth = rig->projectors()[k].geometry;
    const Eigen::Isometry3d true_proj_from_cam = truth.proj_from_world() * world_from_cam;
    const double right = truth.width() - 1.0, bottom = truth.height() - 1.0;
    const Vec2 pixels[5] = {Vec2(0.5 * right, 0.5 * bottom), Vec2(0, 0), Vec2(right, 0),
                            Vec2(0, bottom), Vec2(right, bottom)};
    const auto at = [](const ProjectionUncertaintyMap& map, int c) {
      return c == 0 ? map.centre : map.corners[c - 1];
    };
    // The map: a 16 × 12 grid from corner to corner, σ the decoding noise put in.
    const ProjectionUncertaintyMap& map = predicted.uncertainty;
    EXPECT_EQ(map.grid_width, 16);
    EXPECT_EQ(map.grid_height, 12);
    if (map.grid.size() != 16u * 12u) {
      ADD_FAILURE() << "projector " << k << ": no uncertainty map";
      continue;
    }
    EXPECT_DOUBLE_EQ(map.grid.front(), map.corners[0]);
    EXPECT_DOUBLE_EQ(map.grid[15], map.corners[1]);
    EXPECT_DOUBLE_EQ(map.grid[11 * 16], map.corners[2]);
    EXPECT_DOUBLE_EQ(map.grid.back(), map.corners[3]);
    EXPECT_NEAR(map.observed_pixel_sigma, kDecodingNoisePx, 0.1 * kDecodingNoisePx);
    for (int c = 0; c < 5; ++c) {
      const std::vector<double>& in = truth.intrinsics();
      const Vec3 direction =
          Vec3((pixels[c].x() - in[2]) / in[0], (pixels[c].y() - in[3]) / in[1], 1.0).normalized();
      const Vec3 in_camera =
          true_proj_from_cam.inverse() * Vec3(predicted.uncertainty_distance_m * direction);
      std::vector<Vec2> shown;
      Vec2 mean = Vec2::Zero();
      for (const RoomCalibration& calibration : calibrations) {
        shown.push_back(ShowScaledPoint(calibration, k, in_camera,
                                        true_proj_from_cam.translation().norm()));
        mean += shown.back() / kTrials;
      }
      Eigen::Matrix2d spread = Eigen::Matrix2d::Zero();
      for (const Vec2& q : shown) spread += (q - mean) * (q - mean).transpose() / (kTrials - 1);
      const double empirical =
          std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(spread).eigenvalues()[1]);
      const double prediction = at(map, c), alone = at(noise_only.projectors[k].uncertainty, c);
      std::printf("projector %d pixel (%.0f, %.0f) at %.2f m: predicted %.3f px (decoding noise "
                  "alone %.3f), over %d calibrations %.3f px\n",
                  k, pixels[c].x(), pixels[c].y(), predicted.uncertainty_distance_m, prediction,
                  alone, kTrials, empirical);
      EXPECT_GT(prediction, empirical / 1.35) << "projector " << k << " pixel " << c;
      EXPECT_LT(prediction, empirical * 1.35) << "projector " << k << " pixel " << c;
      ratio_sum += prediction / alone;
      ++ratios;
    }
  }
  return ratios > 0 ? ratio_sum / ratios : 0.0;
}

TEST(SelfCalibrateRoom, ProjectionUncertaintyMatchesTheSpreadOverNoise) {
  EXPECT_DOUBLE_EQ(CheckProjectionUncertaintyAgainstSpread({}), 1.0);
}

// The camera's lens uncertain by about what the decoding noise leaves of the projectors (on this
// 240 × 160 camera): the projectors move with it, and the prediction, which folds it in, grows
// to match the spread. Both parts count: leaving out either misses the 1.35 bound.
TEST(SelfCalibrateRoom, ProjectionUncertaintyFoldsInTheCameraLens) {
  const std::vector<double> sigma = {0.04, 0.04, 0.05, 0.04, 2e-4, 5e-4, 3e-5, 3e-5};
  EXPECT_GT(CheckProjectionUncertaintyAgainstSpread(sigma), 1.2);
}

// The same lens refined by the scan with that covariance as its prior: the prediction is the
// marginal of the joint covariance, and still less sure than from decoding noise alone. (On
// this rig the structured light adds little to so tight a prior: the spread and the prediction
// come out within 1% of the held lens's.)
TEST(SelfCalibrateRoom, ProjectionUncertaintyOfARefinedLens) {
  const std::vector<double> sigma = {0.04, 0.04, 0.05, 0.04, 2e-4, 5e-4, 3e-5, 3e-5};
  EXPECT_GT(CheckProjectionUncertaintyAgainstSpread(sigma, /*refine=*/true), 1.2);
}

TEST(SelfCalibrateRoom, TooFewCorrespondencesNameTheProjector) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("tiny_box");
  RoomCalibrationProblem problem = MakeProblem(*rig, 4);
  problem.projectors[1].camera_pixels.resize(20);
  problem.projectors[1].projector_pixels.resize(20);
  RoomCalibration calibration;
  calibration.camera_lens_model = "untouched";
  SelfCalibrationSummary summary;
  EXPECT_FALSE(
      SelfCalibrateRoom(SelfCalibrationOptions(), problem, &calibration, nullptr, &summary));
  EXPECT_EQ(summary.termination, SelfCalibrationSummary::kTooFewPoints);
  EXPECT_NE(summary.message.find("projector 'right'"), std::string::npos) << summary.message;
  EXPECT_EQ(calibration.camera_lens_model, "untouched");
  std::printf("%s\n", summary.message.c_str());
}

// A projector that lights the back wall only: its correspondences are one homography.
TEST(SelfCalibrateRoom, OnePlaneIsDegenerate) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("tiny_box");
  RoomCalibrationProblem problem = MakeProblem(*rig, 2);
  problem.projectors[0] = NoisyObservations(*rig, 0, 2, kDecodingNoisePx,
                                            [](const Vec3& p) { return p.y() > 1.0 - 1e-6; });
  SelfCalibrationSummary summary;
  RoomCalibration calibration;
  EXPECT_FALSE(
      SelfCalibrateRoom(SelfCalibrationOptions(), problem, &calibration, nullptr, &summary));
  EXPECT_EQ(summary.termination, SelfCalibrationSummary::kDegenerate) << summary.BriefReport();
  EXPECT_NE(summary.message.find("projector 'left'"), std::string::npos) << summary.message;
  std::printf("%s\n", summary.message.c_str());
}

// Two projectors that light disjoint halves of the camera image share no point: no common scale.
TEST(SelfCalibrateRoom, ProjectorsSharingNoPointAreRefused) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("l_shaped", 0.5);
  RoomCalibrationProblem problem = MakeProblem(*rig, 2);
  for (int k = 0; k < 2; ++k) {
    ProjectorObservations& p = problem.projectors[k];
    ProjectorObservations half = p;
    half.camera_pixels.clear();
    half.projector_pixels.clear();
    for (size_t i = 0; i < p.camera_pixels.size(); ++i)
      if ((p.camera_pixels[i].x() < 240) == (k == 0)) {
        half.camera_pixels.push_back(p.camera_pixels[i]);
        half.projector_pixels.push_back(p.projector_pixels[i]);
      }
    p = half;
  }
  RoomCalibration calibration;
  SelfCalibrationSummary summary;
  EXPECT_FALSE(
      SelfCalibrateRoom(SelfCalibrationOptions(), problem, &calibration, nullptr, &summary));
  EXPECT_EQ(summary.termination, SelfCalibrationSummary::kDisconnected) << summary.BriefReport();
  EXPECT_NE(summary.message.find("projector '"), std::string::npos) << summary.message;
  std::printf("%s\n", summary.message.c_str());
}

// Only the walls lit (no floor point): the calibration is found, but no room frame.
TEST(SelfCalibrateRoom, NoFloorIsRefused) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("l_shaped", 0.5);
  RoomCalibrationProblem problem = MakeProblem(*rig, 2);
  for (int k = 0; k < 2; ++k)
    problem.projectors[k] =
        NoisyObservations(*rig, k, 2, kDecodingNoisePx, [](const Vec3& p) { return p.z() > 0.05; });
  RoomCalibration calibration;
  SelfCalibrationSummary summary;
  EXPECT_FALSE(
      SelfCalibrateRoom(SelfCalibrationOptions(), problem, &calibration, nullptr, &summary));
  EXPECT_EQ(summary.termination, SelfCalibrationSummary::kNoFloor) << summary.BriefReport();
  std::printf("%s\n", summary.message.c_str());
}

TEST(SelfCalibrateRoom, OptionsAndInputsAreChecked) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("tiny_box");
  const RoomCalibrationProblem problem = MakeProblem(*rig, 8);
  RoomCalibration calibration;
  SelfCalibrationSummary summary;
  SelfCalibrationOptions options;
  options.camera_height = 0.0;
  EXPECT_THROW(SelfCalibrateRoom(options, problem, &calibration, nullptr, &summary),
               std::invalid_argument);
  RoomCalibrationProblem no_projector = problem;
  no_projector.projectors.clear();
  EXPECT_THROW(
      SelfCalibrateRoom(SelfCalibrationOptions(), no_projector, &calibration, nullptr, &summary),
      std::invalid_argument);
  RoomCalibrationProblem unequal = problem;
  unequal.projectors[0].projector_pixels.pop_back();
  EXPECT_THROW(
      SelfCalibrateRoom(SelfCalibrationOptions(), unequal, &calibration, nullptr, &summary),
      std::invalid_argument);
  // The floor's given normal must be finite, its angle bound in (0, 90).
  SelfCalibrationOptions floor_options;
  std::string why;
  floor_options.floor_normal_in_camera = Vec3(std::nan(""), -1.0, 0.0);
  EXPECT_FALSE(floor_options.Check(&why));
  EXPECT_NE(why.find("floor_normal_in_camera"), std::string::npos) << why;
  floor_options = SelfCalibrationOptions();
  floor_options.max_floor_normal_deg = 0.0;
  EXPECT_FALSE(floor_options.Check(&why));
  EXPECT_THROW(SelfCalibrateRoom(floor_options, problem, &calibration, nullptr, &summary),
               std::invalid_argument);
}

}  // namespace
}  // namespace procam
