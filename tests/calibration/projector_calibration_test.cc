// Projectors as inverse cameras, against the synthetic rig's ground truth: correspondences are
// made by projecting the point each camera pixel sees (SimulatedRig::PointSeenByPixel) into the
// true projector, with decoding noise and outliers added, or decoded from simulated Gray-code +
// phase captures; the walls' planes are known in the camera frame (the scene's geometry seen
// through the true camera pose). Targets of issue 7: focal length within 0.5%, projector
// position within 5 mm, orientation within 0.1°.
#include "calibration/projector_calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <random>

#include "calibration/structured_light.h"
#include "datasets_synthetic/simulated_rig.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "geometry/ray_scene.h"

namespace procam {
namespace {

std::unique_ptr<SimulatedRig> MakeRig(const std::string& name) {
  const SyntheticScene synthetic = MakeSyntheticScene(name, 60);
  std::vector<Projector> projectors;
  for (const DevicePlacement& placement : synthetic.projectors)
    projectors.push_back(ProjectorFromPlacement(placement));
  SimulatedRigOptions options;
  options.solver_patches = 60;
  options.world_factor = 1;
  return std::make_unique<SimulatedRig>(synthetic.scene, projectors,
                                        CameraFromPlacement(synthetic.camera), options);
}

// Correspondences of projector `index` seen by the rig's camera: every `step`-th camera pixel
// whose point the projector lights unoccluded, its projector pixel exact (`truth`) and the plane
// of its wall in the camera frame (planes are told apart by their normals: the walls of the
// stage scenes are axis-aligned).
struct Correspondences {
  ProjectorCalibrationProblem problem;
  std::vector<Vec2> truth;                 // exact projector pixel per correspondence
  cv::Mat lookup;                          // CV_32SC1: correspondence index per camera pixel, −1
};

Correspondences MakeCorrespondences(const SimulatedRig& rig, int index, int step) {
  const CameraGeometry& camera = rig.camera();
  const ProjectorGeometry& projector = rig.projectors()[index].geometry;
  const Eigen::Isometry3d& cam_from_world = camera.proj_from_world();
  const RayScene surfaces(rig.scene());
  Correspondences out;
  out.problem.camera_lens_model = camera.lens_model();
  out.problem.camera_intrinsics = camera.intrinsics();
  out.problem.projector_width = projector.width();
  out.problem.projector_height = projector.height();
  out.lookup = cv::Mat(camera.height(), camera.width(), CV_32SC1, cv::Scalar(-1));
  std::map<std::array<long, 3>, int> plane_of_normal;
  for (int row = 0; row < camera.height(); row += step)
    for (int col = 0; col < camera.width(); col += step) {
      Vec3 point, normal;
      Vec2 pixel;
      if (!rig.PointSeenByPixel(row, col, &point, &normal)) continue;
      if (projector.Gain(point, normal, &pixel) <= 0.0 || !projector.InImage(pixel)) continue;
      if (surfaces.Occluded(point, projector.CentreInWorld(), 1e-4)) continue;
      const std::array<long, 3> key = {std::lround(normal.x() * 1e4), std::lround(normal.y() * 1e4),
                                       std::lround(normal.z() * 1e4)};
      auto found = plane_of_normal.find(key);
      if (found == plane_of_normal.end()) {
        PlaneInCam plane;
        plane.normal = cam_from_world.linear() * normal;
        plane.offset = -plane.normal.dot(cam_from_world * point);
        out.problem.planes.push_back(plane);
        found = plane_of_normal.emplace(key, static_cast<int>(out.problem.planes.size()) - 1).first;
      }
      ProjectorCorrespondence c;
      c.camera_pixel = Vec2(col, row);
      c.projector_pixel = pixel;
      c.plane = found->second;
      out.lookup.at<int>(row, col) = static_cast<int>(out.problem.correspondences.size());
      out.problem.correspondences.push_back(c);
      out.truth.push_back(pixel);
    }
  return out;
}

struct Errors {
  double fx = 0.0, fy = 0.0;  // relative
  double cx = 0.0, cy = 0.0;  // pixels
  double position_mm = 0.0;
  double orientation_deg = 0.0;
};

Errors Compare(const ProjectorCalibration& calibration, const SimulatedRig& rig, int index) {
  const ProjectorGeometry& truth = rig.projectors()[index].geometry;
  const Eigen::Isometry3d proj_from_cam =
      truth.proj_from_world() * rig.camera().proj_from_world().inverse();
  Errors e;
  e.fx = std::abs(calibration.intrinsics[0] / truth.intrinsics()[0] - 1.0);
  e.fy = std::abs(calibration.intrinsics[1] / truth.intrinsics()[1] - 1.0);
  e.cx = std::abs(calibration.intrinsics[2] - truth.intrinsics()[2]);
  e.cy = std::abs(calibration.intrinsics[3] - truth.intrinsics()[3]);
  e.position_mm = 1e3 * (calibration.proj_from_cam.inverse().translation() -
                         proj_from_cam.inverse().translation()).norm();
  e.orientation_deg =
      Eigen::AngleAxisd(calibration.proj_from_cam.linear() * proj_from_cam.linear().transpose())
          .angle() * 180.0 / std::numbers::pi;
  return e;
}

void Print(const char* what, const ProjectorCalibrationSummary& summary, const Errors& e) {
  std::printf("%s\n  %s\n  fx %.4f%%, fy %.4f%%, cx %.3f px, cy %.3f px, position %.3f mm, "
              "orientation %.4f deg\n",
              what, summary.BriefReport().c_str(), 100.0 * e.fx, 100.0 * e.fy, e.cx, e.cy,
              e.position_mm, e.orientation_deg);
}

void ExpectIssueTargets(const Errors& e) {
  EXPECT_LT(e.fx, 0.005);
  EXPECT_LT(e.fy, 0.005);
  EXPECT_LT(e.position_mm, 5.0);
  EXPECT_LT(e.orientation_deg, 0.1);
}

// Gaussian noise on the projector coordinates and a fraction of outliers (uniform anywhere on
// the projector image).
void AddNoise(ProjectorCalibrationProblem* problem, double sigma, double outlier_fraction,
              uint32_t seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (ProjectorCorrespondence& c : problem->correspondences) {
    if (uniform(random) < outlier_fraction) {
      c.projector_pixel = Vec2(uniform(random) * problem->projector_width,
                               uniform(random) * problem->projector_height);
    } else {
      c.projector_pixel += Vec2(noise(random), noise(random));
    }
  }
}

TEST(ProjectorCalibration, UnprojectInvertsTheOpenCv4Lens) {
  const std::vector<double> intrinsics = {700, 690, 480, 320, -0.05, 0.01, 0.001, -0.0005};
  for (const Vec2& x : {Vec2(0.3, -0.2), Vec2(-0.6, 0.4), Vec2(0.0, 0.0)}) {
    const double r2 = x.squaredNorm(), radial = 1 + intrinsics[4] * r2 + intrinsics[5] * r2 * r2;
    const double p1 = intrinsics[6], p2 = intrinsics[7];
    const Vec2 d(x.x() * radial + 2 * p1 * x.x() * x.y() + p2 * (r2 + 2 * x.x() * x.x()),
                 x.y() * radial + p1 * (r2 + 2 * x.y() * x.y()) + 2 * p2 * x.x() * x.y());
    Vec3 ray;
    ASSERT_TRUE(UnprojectCameraPixel("LENSMODEL_OPENCV4", intrinsics,
                                     Vec2(700 * d.x() + 480, 690 * d.y() + 320), &ray));
    EXPECT_NEAR(ray.x(), x.x(), 1e-12);
    EXPECT_NEAR(ray.y(), x.y(), 1e-12);
  }
  Vec3 ray;
  EXPECT_FALSE(UnprojectCameraPixel("LENSMODEL_OPENCV8", intrinsics, Vec2::Zero(), &ray));
}

TEST(ProjectorCalibration, CoplanarPointsAreDegenerate) {
  ProjectorCalibrationProblem problem;
  problem.camera_intrinsics = {500, 500, 320, 240};
  problem.planes = {PlaneInCam{Vec3::UnitZ(), -2.0}};
  problem.projector_width = 640;
  problem.projector_height = 480;
  for (int i = 0; i < 100; ++i) {
    ProjectorCorrespondence c;
    c.camera_pixel = Vec2(100 + 4 * (i % 10) * 10, 100 + 3 * (i / 10) * 10);
    c.projector_pixel = c.camera_pixel + Vec2(20, 5);
    problem.correspondences.push_back(c);
  }
  ProjectorCalibration calibration;
  ProjectorCalibrationSummary summary;
  EXPECT_FALSE(CalibrateProjector({}, problem, &calibration, &summary));
  EXPECT_EQ(summary.termination, ProjectorCalibrationSummary::kDegenerate);
  problem.correspondences[0].plane = 3;
  EXPECT_THROW(CalibrateProjector({}, problem, &calibration, &summary), std::invalid_argument);
}

TEST(ProjectorCalibration, CShapedRoomWithNoiseAndOutliers) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("c_shaped");
  for (int index = 0; index < static_cast<int>(rig->projectors().size()); ++index) {
    Correspondences data = MakeCorrespondences(*rig, index, 8);
    ASSERT_GE(data.problem.planes.size(), 2u);
    // Exact correspondences: the solution is the truth (up to the single-precision ray hits
    // of PointSeenByPixel, about 1e-5 px).
    {
      ProjectorCalibration calibration;
      ProjectorCalibrationSummary summary;
      ASSERT_TRUE(CalibrateProjector({}, data.problem, &calibration, &summary))
          << summary.BriefReport();
      const Errors e = Compare(calibration, *rig, index);
      Print(("c_shaped projector " + std::to_string(index) + ", exact").c_str(), summary, e);
      EXPECT_LT(e.fx, 1e-6);
      EXPECT_LT(e.position_mm, 1e-3);
      EXPECT_LT(summary.rms, 1e-4);
    }
    // 0.3 px decoding noise, 1% outliers.
    AddNoise(&data.problem, 0.3, 0.01, 17 + index);
    ProjectorCalibration calibration;
    ProjectorCalibrationSummary summary;
    ASSERT_TRUE(CalibrateProjector({}, data.problem, &calibration, &summary))
        << summary.BriefReport();
    const Errors e = Compare(calibration, *rig, index);
    Print(("c_shaped projector " + std::to_string(index) + ", 0.3 px noise, 1% outliers").c_str(),
          summary, e);
    EXPECT_NEAR(summary.rms, 0.3, 0.03);
    EXPECT_GT(summary.outliers, 0);
    ExpectIssueTargets(e);
  }
}

// With k1, k2 free (LENSMODEL_OPENCV4) the true pinhole comes back with k ≈ 0, and the targets
// still hold: the extra freedom costs little accuracy with walls filling the projector's image.
TEST(ProjectorCalibration, RadialDistortionFreeRecoversThePinhole) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("c_shaped");
  Correspondences data = MakeCorrespondences(*rig, 0, 8);
  AddNoise(&data.problem, 0.3, 0.01, 3);
  ProjectorCalibrationOptions options;
  options.refine_distortion = true;
  ProjectorCalibration calibration;
  ProjectorCalibrationSummary summary;
  ASSERT_TRUE(CalibrateProjector(options, data.problem, &calibration, &summary))
      << summary.BriefReport();
  ASSERT_EQ(calibration.lens_model, "LENSMODEL_OPENCV4");
  ASSERT_EQ(calibration.intrinsics.size(), 8u);
  const Errors e = Compare(calibration, *rig, 0);
  Print("c_shaped projector 0, 0.3 px noise, 1% outliers, k1 k2 free", summary, e);
  std::printf("  k1 %.2e, k2 %.2e\n", calibration.intrinsics[4], calibration.intrinsics[5]);
  EXPECT_LT(std::abs(calibration.intrinsics[4]), 0.01);
  ExpectIssueTargets(e);
}

// What limits the result when the inputs are not exact: the camera's intrinsics (the issue's
// camera target is 0.2% on the focal length) and the planes (a wall 5 mm off). Printed for
// docs/calibration.md; the asserted bounds only say the errors are of the size expected.
TEST(ProjectorCalibration, SensitivityToCameraAndPlaneErrors) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("c_shaped");
  Correspondences data = MakeCorrespondences(*rig, 1, 8);
  AddNoise(&data.problem, 0.3, 0.0, 5);
  struct Case {
    const char* name;
    double focal_scale, plane_shift;
  };
  for (const Case& c : {Case{"camera focal +0.2%", 1.002, 0.0},
                        Case{"camera focal +0.05%", 1.0005, 0.0},
                        Case{"every plane 5 mm farther", 1.0, 0.005},
                        Case{"every plane 1 mm farther", 1.0, 0.001}}) {
    ProjectorCalibrationProblem problem = data.problem;
    problem.camera_intrinsics[0] *= c.focal_scale;
    problem.camera_intrinsics[1] *= c.focal_scale;
    for (PlaneInCam& plane : problem.planes) plane.offset -= c.plane_shift;
    ProjectorCalibration calibration;
    ProjectorCalibrationSummary summary;
    ASSERT_TRUE(CalibrateProjector({}, problem, &calibration, &summary)) << summary.BriefReport();
    const Errors e = Compare(calibration, *rig, 1);
    Print((std::string("c_shaped projector 1, 0.3 px noise, ") + c.name).c_str(), summary, e);
    EXPECT_LT(e.fx, 0.02);
    EXPECT_LT(e.position_mm, 50.0);
  }
}


// The whole chain: projector 0 of the tiny box shows XOR Gray + phase patterns, the rig
// photographs them (bounces, lens distortion, vignetting, noise), the decoder gives each camera
// pixel a projector coordinate, and the calibration uses the decoded coordinates.
TEST(ProjectorCalibration, TinyBoxFromDecodedStructuredLight) {
  const std::unique_ptr<SimulatedRig> rig = MakeRig("tiny_box");
  const Correspondences data = MakeCorrespondences(*rig, 0, 1);
  const ProjectorGeometry& geometry = rig->projectors()[0].geometry;
  StructuredLightOptions options;
  options.width = geometry.width();
  options.height = geometry.height();
  options.pattern_gamma = rig->projectors()[0].photometry.response[0].gamma();
  const CaptureSequence sequence = MakeStructuredLightSequence(options);
  const ProjectorGeometry& other = rig->projectors()[1].geometry;
  const ProjectorImage dark{cv::Mat(other.height(), other.width(), CV_16UC3, cv::Scalar::all(0)),
                            8};
  std::vector<cv::Mat> captured;
  uint32_t seed = 0;
  for (const Pattern& pattern : sequence.patterns)
    captured.push_back(rig->PhotographLinear({CodesFromPattern(pattern.image, rig->projectors()[0]), dark}, ++seed));
  const StructuredLightMap map = DecodeStructuredLight(options, captured);

  // Decoded pixels with a plane (where the geometry says the projector lights them).
  ProjectorCalibrationProblem problem = data.problem;
  problem.correspondences.clear();
  double decode_sq = 0.0;
  for (int row = 0; row < map.mask.rows; ++row)
    for (int col = 0; col < map.mask.cols; ++col) {
      const int k = data.lookup.at<int>(row, col);
      if (!map.mask.at<uint8_t>(row, col) || k < 0) continue;
      ProjectorCorrespondence c = data.problem.correspondences[k];
      c.projector_pixel = Vec2(map.column.at<float>(row, col), map.row.at<float>(row, col));
      decode_sq += (c.projector_pixel - data.truth[k]).squaredNorm();
      problem.correspondences.push_back(c);
    }
  ASSERT_GT(problem.correspondences.size(), 10000u);
  ProjectorCalibration calibration;
  ProjectorCalibrationSummary summary;
  ASSERT_TRUE(CalibrateProjector({}, problem, &calibration, &summary)) << summary.BriefReport();
  const Errors e = Compare(calibration, *rig, 0);
  std::printf("decoded %zu pixels, decoding error rms %.3f px per coordinate\n",
              problem.correspondences.size(),
              std::sqrt(decode_sq / (2.0 * problem.correspondences.size())));
  Print("tiny_box projector 0 from decoded Gray + phase", summary, e);
  ExpectIssueTargets(e);
}

}  // namespace
}  // namespace procam
