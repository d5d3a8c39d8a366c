#pragma once
// Projectors as inverse cameras (issue 7, "Geometry"): a projector's intrinsics and its pose in
// the camera frame from camera–projector correspondences (structured light) on planar surfaces
// whose planes are known in the camera frame.
//
//   1. Each correspondence's camera pixel is unprojected through the camera's (known) lens and
//      its ray is intersected with the correspondence's plane: a 3D point in the camera frame.
//   2. Seed: a normalised DLT (Hartley & Zisserman, Alg. 7.1) on the 3D point ↔ projector pixel
//      pairs, decomposed into K [R | t] by an RQ decomposition. Needs points off one plane (two
//      or more non-parallel planes, e.g. two walls of a room).
//   3. Refinement (Ceres): projector intrinsics (fx, fy, cx, cy, optionally k1, k2) and pose
//      minimise the projector reprojection error, first under a Cauchy loss, then without a loss
//      on the inliers (residual norm ≤ outlier_threshold).
// Noise is assumed to be in the decoded projector coordinates (the camera pixel is exact), so
// the projector reprojection error is the maximum-likelihood cost. The camera's lens and the
// planes are held fixed.
//
// Conventions (as in calibration/camera_calibration.h and projection/projector.h): pixels x right,
// y down, CENTRE of the top-left pixel at (0, 0); frames x right, y down, z forward, metres.
// `proj_from_cam` maps camera-frame points into the projector frame. Intrinsics in mrcal's order
// (fx, fy, cx, cy, then OpenCV's k1, k2, p1, p2). Calibrating several projectors against the same
// camera puts them all in the camera's frame.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "geometry/scene.h"

namespace procam {

// A plane in the camera frame: points p with normal · p + offset = 0 (normal of unit length).
struct PlaneInCam {
  Vec3 normal = Vec3::UnitZ();
  double offset = -1.0;  // metres
};

// One camera pixel and the projector pixel it sees (decoded structured light), on plane `plane`.
struct ProjectorCorrespondence {
  Vec2 camera_pixel = Vec2::Zero();
  Vec2 projector_pixel = Vec2::Zero();
  int plane = 0;  // index into ProjectorCalibrationProblem::planes
};

struct ProjectorCalibrationProblem {
  // The camera's lens: "LENSMODEL_PINHOLE" (fx, fy, cx, cy) or "LENSMODEL_OPENCV4" (fx, fy, cx,
  // cy, k1, k2, p1, p2), as CameraCalibration gives it.
  std::string camera_lens_model = "LENSMODEL_PINHOLE";
  std::vector<double> camera_intrinsics;
  std::vector<PlaneInCam> planes;
  int projector_width = 0, projector_height = 0;  // pixels, ≥ 1
  std::vector<ProjectorCorrespondence> correspondences;
};

struct ProjectorCalibrationOptions {
  // Refine radial distortion k1, k2 of the projector (LENSMODEL_OPENCV4 with p1 = p2 = 0);
  // false: a pinhole (LENSMODEL_PINHOLE).
  bool refine_distortion = false;
  // Scale of the Cauchy loss of the robust pass, projector pixels, > 0.
  double loss_scale = 1.0;
  // Residual norm above which a correspondence is an outlier after the robust pass, projector
  // pixels, > 0.
  double outlier_threshold = 2.0;
  int min_correspondences = 12;   // fewest usable correspondences, ≥ 6
  int max_iterations = 100;       // per Ceres solve, ≥ 1
  bool Check(std::string* why) const;
};

// The projector as an inverse camera, in the camera's frame.
struct ProjectorCalibration {
  std::string lens_model;          // "LENSMODEL_PINHOLE" or "LENSMODEL_OPENCV4"
  std::vector<double> intrinsics;  // mrcal order, pixels (distortion unitless)
  int width = 0, height = 0;
  Eigen::Isometry3d proj_from_cam = Eigen::Isometry3d::Identity();
};

struct ProjectorCalibrationSummary {
  enum Termination {
    kConverged,         // Ceres reported convergence (or a usable solution) on the inliers
    kTooFewPoints,      // fewer than min_correspondences points hit their plane in front of
                        // the camera, or fewer inliers than that after the robust pass
    kDegenerate,        // the DLT seed failed: the points are (nearly) coplanar, or its
                        // K is not a proper camera (non-positive focal lengths)
    kSolverFailed,      // Ceres failed, or the result is not finite
  };
  Termination termination = kSolverFailed;
  int correspondences = 0;  // given
  int points = 0;           // whose camera ray met its plane in front of the camera
  int outliers = 0;         // residual norm > outlier_threshold after the robust pass
  double seed_rms = 0.0;    // RMS residual norm of the DLT seed over the points, px
  double rms = 0.0;         // RMS per coordinate over inliers, px (σ for N(0, σ²) per axis)
  double max_norm = 0.0;    // largest inlier residual norm, px
  double time_s = 0.0;
  std::string message;
  std::string BriefReport() const;
};

// Unit-free ray direction (z = 1) of a camera pixel through a pinhole or OpenCV4 lens (the
// OpenCV4 distortion is inverted by Newton iteration, to 1e-12). False for an unknown model or a
// wrong number of intrinsics.
bool UnprojectCameraPixel(const std::string& lens_model, const std::vector<double>& intrinsics,
                          const Vec2& pixel, Vec3* ray_in_cam);

// Calibrates one projector. Throws std::invalid_argument when the options fail Check(), the
// camera lens model is unsupported, or a correspondence names a plane that does not exist.
// Returns true when summary->termination is kConverged.
bool CalibrateProjector(const ProjectorCalibrationOptions& options,
                        const ProjectorCalibrationProblem& problem,
                        ProjectorCalibration* calibration, ProjectorCalibrationSummary* summary);

}  // namespace procam
