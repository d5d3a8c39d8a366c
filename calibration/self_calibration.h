#pragma once
// Self-calibration of the room (issue 19, first bullet): every projector's intrinsics and pose,
// the camera's pose and a room frame, from the decoded structured light alone. No room model and
// no guess of the camera's pose; only the camera's lens (from the chessboard) and one length that
// sets the metric scale.
//
//   1. Thinning. Every projector keeps the correspondences whose camera pixel lies on one common
//      grid (stride chosen so that no projector keeps more than max_correspondences): a camera
//      pixel two projectors light is then one 3D point of both.
//   2. Seed per projector, without a guess. A fundamental matrix between the undistorted camera
//      pixels and the projector pixels by RANSAC with local optimisation (OpenCV
//      findFundamentalMat, USAC_ACCURATE; plain RANSAC's best 7-point model left 17% of exact
//      correspondences out on a small rig). The projector's intrinsics are unknown: its
//      principal point is taken at its guess (principal_point_guesses, by default the image
//      centre) and its pixels square (fx = fy = f), and f is the one for which E(f) = K_p(f)ᵀ F
//      K_c has two equal singular values (Mendonça & Cipolla's criterion; a log-spaced search
//      over the throw ratios f / width in [min_throw_ratio, max_throw_ratio], refined by golden
//      section); with search_principal_point_y also over cy, where that brings E far closer to an
//      essential matrix. E is decomposed into the projector's rotation and unit translation, the
//      one of four that puts the inliers in front of both devices (cv::recoverPose). A projector
//      whose correspondences fit one homography about as well as F (it lights one plane only, or
//      sits at the camera's centre) has no epipolar geometry: kDegenerate, naming it.
//   3. Scales. Each projector's seed has its own unit of length. Two projectors that light the
//      same camera pixel triangulate the same point, whose depth along the camera ray they must
//      agree on: the median ratio of the depths ties their units, projector by projector along a
//      spanning tree of the "share camera pixels" graph (a projector sharing fewer than
//      min_shared_points with all the others: kDisconnected, naming it).
//   4. Joint bundle adjustment (Ceres). Unknowns: per projector fx, fy (one value with
//      square_pixels), cx, cy and proj_from_cam (angle-axis, translation); per thinned camera
//      pixel its depth z along the camera ray, the point z · (x, y, 1) with (x, y) the pixel's
//      undistorted normalised coordinate. The camera is fixed: the origin, its lens held.
//      Residual: the point projected into each projector that lit it minus the decoded projector
//      pixel. A Cauchy pass on everything, then least squares on the inliers (residual norm ≤
//      outlier_threshold), as CalibrateRoom does. Gauge: the depth of one point (the median-depth
//      point seen by the most projectors) is held, so the solve's unit is arbitrary until step 5.
//   5. Room frame and metric scale. Planes are fitted to the cloud (FitPlanes, RANSAC). The floor
//      is the plane whose normal (towards the camera) is within max_floor_tilt_deg of the
//      camera's image-up (−y of the camera frame) and which has the most points on its lit side
//      (a table top has the floor below it), ties by inliers. The cloud and the poses are scaled
//      so that the camera's centre lies `camera_height` metres above that floor. The room frame:
//      z the floor's normal (up), origin the camera's foot on the floor (the camera at (0, 0,
//      camera_height)), x the camera's optical axis projected on the floor, y = z × x.
//
// What fixes the projectors' intrinsics. One camera–projector pair's fundamental matrix has 7
// degrees of freedom; the relative pose takes 5, so only two of the projector's intrinsics follow
// from it (with square pixels, its principal point stays a one-parameter family). Two or more
// projectors lighting common camera pixels pin all of them: the points the first triangulates
// must be seen by the second through a zero-skew, square-pixel lens. Hence: with square_pixels
// the principal points are refined when there are two or more projectors (each shares at least
// min_shared_points camera pixels with another, or the calibration stops at kDisconnected), and
// held at their guess (principal_point_guesses, else the image centre; summary:
// principal_point_held) for a rig of one projector. A principal point far from its guess can lead
// the solve astray: kInconsistent (see principal_point_guesses for what was measured).
//
// Held lenses. A projector whose lens a chessboard calibrated (`procam calibrate board`) can keep
// it: the problem's held_projector_lenses (as for CalibrateRoom; LENSMODEL_PINHOLE or
// LENSMODEL_OPENCV4, its distortion included). Its decoded projector pixels are undistorted
// through the held lens once, after thinning (to fx·x + cx, fy·y + cy of the undistorted
// normalised point: the pinhole residual of step 4 is then exact for the lens, distortion and
// fx ≠ fy included); step 2 needs no focal-length search: E comes from the normalised points of
// both devices directly (cv::findEssentialMat, five points under USAC_ACCURATE, inlier distance
// ransac_threshold in the projector's pixels), decomposed as for the others; in step 4 its
// intrinsics are constant (10 or 9 unknowns fewer: its pose alone, 6, is solved), and its
// uncertainty is the pose's alone (the held intrinsics are no unknowns), mapped over the image's
// own pixels through the distortion. The result carries the held lens exactly as given with the
// solved pose (RoomProjector::lens_held). square_pixels and the principal-point rule below apply
// to the projectors whose lens is not held; a held lens also pins the others' principal points,
// as any second projector does.
//
// The metric scale: `camera_height` is the distance from the camera's centre to the floor plane,
// metres. It is meant to come from the chessboard: one photo of the board lying flat on the floor
// taken from the structured-light pose gives the floor plane in the camera frame by PnP (the
// board's square size in metres), and its distance to the camera's centre is camera_height (the
// board's thickness subtracted). A tape measure works as well.
//
// Frames and conventions as in calibration/registration.h: camera and projector frames x right,
// y down, z forward; pixel centres at integers; intrinsics in mrcal's order; `proj_from_room` is
// a scene file's projector `extrinsics`.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <limits>
#include <string>
#include <vector>

#include "calibration/projection_uncertainty.h"
#include "calibration/registration.h"

namespace procam {

struct SelfCalibrationOptions {
  // Distance from the camera's centre to the floor plane, metres, > 0: sets the metric scale
  // (see the header comment for how the chessboard gives it).
  double camera_height = 1.5;
  // One focal length per projector (fx = fy): DMD and LCD projectors have square pixels. false:
  // fx and fy refined independently; not recommended: with the aspect ratio free the solve is
  // ill-conditioned on some rigs (measured on the synthetic columns rig, three projectors: the
  // solve drifts to focal lengths 1.6% and principal points 60 px off, positions 5 cm off; on
  // l_shaped it still lands on the truth).
  bool square_pixels = true;
  // Projector focal length search of the seed: f / width in [min_throw_ratio, max_throw_ratio]
  // (the throw ratio of a projector with its principal point at the centre), 0 < min < max.
  double min_throw_ratio = 0.3;
  double max_throw_ratio = 4.0;
  // The seed's principal point per projector (problem order), pixels, e.g. from the projector's
  // lens-shift specification (a 100% vertical offset puts cy at the bottom row); empty: every
  // image's centre. It is also where a held principal point stays (see the header), and where
  // the seed's cy search (below) starts. A projector whose lens is held ignores its entry.
  std::vector<Vec2> principal_point_guesses;
  // The seed searches the principal point's cy too (cy in [−height/2, 3·height/2]) and takes the
  // cy that brings E(f) far closer (gap below a quarter, from above 0.02) to an essential matrix
  // than the guess does: one pair's F determines two of the projector's intrinsics, f and the
  // lens shift, unless the projector sits straight above or below the camera (then cy is not
  // seen, the gap stays small at the guess and the guess is kept). Measured on the synthetic rigs
  // (800 px tall projectors, default guesses): principal points 120–200 px below and 300–400 px
  // above the centre recovered on l_shaped and columns; without the search, columns 300 px above
  // goes astray (kInconsistent) unless the true principal points are given as guesses.
  bool search_principal_point_y = true;
  // The seed's focal length is refused (kDegenerate) when E(f) is farther than this from an
  // essential matrix, (σ1 − σ2) / σ2 > max_seed_gap, > 0. A wrong principal point guess alone
  // raises it: 0.32–0.48 measured for guesses 300–400 px off on 800 px tall projectors.
  double max_seed_gap = 0.75;
  // RANSAC inlier distance of the seed's fundamental matrix, projector pixels, > 0.
  double ransac_threshold = 1.5;
  // A projector is degenerate when one homography explains at least this fraction of the
  // correspondences that F explains, (0, 1].
  double degenerate_homography_fraction = 0.95;
  double loss_scale = 1.0;         // Cauchy scale of the robust pass, projector pixels, > 0
  double outlier_threshold = 2.0;  // inlier residual norm, projector pixels, > 0
  // A projector with more than this fraction of its correspondences outliers after the robust
  // pass ends the calibration (kInconsistent), [0, 1]. Decoded structured light leaves under 1%;
  // a solve the seed led astray leaves 7–57% (measured: columns, principal points 300–400 px off
  // the centre guess, search_principal_point_y off).
  double max_outlier_fraction = 0.2;
  int min_correspondences = 50;  // per projector, fewest usable ones, ≥ 12
  // Per projector, at most this many correspondences are used (thinned on a camera-pixel grid
  // shared by all projectors), ≥ min_correspondences.
  int max_correspondences = 4000;
  // Two projectors share scale (and pin each other's principal points) when they light at least
  // this many common thinned camera pixels, ≥ 1.
  int min_shared_points = 30;
  // The floor's unit normal in the camera frame, pointing up (towards the camera), measured
  // independently of the scan: the floor chessboard's plane (calibration/floor_chessboard.h);
  // zero: none. Where the scan's floor lies within max_floor_normal_deg of it, a last bundle
  // adjustment holds the floor's points to a plane of this normal (its offset free; each point
  // weighted by the floor's scatter). Why: the structured light pins the reconstruction's
  // projective part (where far points lie relative to near ones) only through the projectors'
  // square pixels, weakly, and a lens error leaks into it as a tilt of the floor against the
  // camera; the board's pose depends on the camera's lens alone (measured on the synthetic
  // green_trapezoid rig: the scan's floor 0.064 deg off the true one, the board's 0.015 deg).
  Vec3 floor_normal_in_camera = Vec3::Zero();
  double max_floor_normal_deg = 3.0;  // (0, 90)
  // Refine the camera's whole lens (fx, fy, cx, cy and the distortion) in the final bundle
  // adjustment, with the chessboard's estimate as a Gaussian prior of the problem's
  // camera_intrinsics_covariance (needed: std::invalid_argument without it). The structured
  // light covers the image where the chessboard pins the lens least, so the lens's shape comes
  // out closer to the truth; but a turn of the lens is a turn of the camera, which the scan
  // cannot see, and the refined lens drifts in it. Measured on the synthetic green_trapezoid rig
  // (floor held to the board's normal): the lens 0.86 px off the truth at worst after the best
  // turn with the chessboard's, 0.31 px refined; the scanned walls through the camera's pose
  // 1.6-3.9 mm held, 1.3-5.6 mm refined. Hence off by default.
  bool refine_camera_lens = false;
  int max_iterations = 100;  // per Ceres solve, ≥ 1
  // Floor search: planes fitted with inliers within plane_distance × the cloud's median depth
  // (0.005: 2 cm at 4 m), (0, 0.1); the floor's normal within max_floor_tilt_deg of the camera's
  // image-up, (0, 90).
  double plane_distance = 0.005;
  double max_floor_tilt_deg = 45.0;
  bool Check(std::string* why) const;
};

struct SelfCalibrationProjectorSummary {
  int correspondences = 0;                   // given
  int used = 0;                              // after thinning
  int seed_inliers = 0;                      // of the RANSAC fundamental matrix
  int homography_inliers = 0;                // of a RANSAC homography (degeneracy test)
  double seed_focal = 0.0;                   // f of the seed (equal singular values of E), px
  Vec2 seed_principal_point = Vec2::Zero();  // of the seed, px (see search_principal_point_y)
  int shared = 0;                     // thinned camera pixels some other projector lights too
  bool principal_point_held = false;  // held at its guess (see the header), or with a held lens
  // Its lens held (the problem's held_projector_lenses): seed_focal and seed_principal_point are
  // the held fx and (cx, cy), the pose alone was solved, and `uncertainty` is the pose's alone.
  bool lens_held = false;
  int outliers = 0;                   // residual norm > outlier_threshold after the robust pass
  double rms = 0.0;                   // RMS per coordinate over inliers, px
  double max_norm = 0.0;              // largest inlier residual norm, px
  // What the bundle adjustment is sure of (its projection uncertainty, as mrcal's for a camera):
  // the worst-direction standard deviation, px, of where the projector shows a point fixed
  // relative to the camera, `uncertainty_distance_m` along the ray of each pixel: the image
  // centre, the four corner pixels ((0, 0), (w − 1, 0), (0, h − 1), (w − 1, h − 1)) and a 16 × 12
  // grid corner to corner (ProjectionUncertaintyMap). The point is fixed in units of the
  // projector's distance from the camera, so the overall scale (the floor's, not the bundle
  // adjustment's) does not count. Covariance of the projector's free parameters: σ² (Schur
  // complement of JᵀJ on the points' depths)⁻¹, σ² the inliers' residual variance (the map's
  // observed_pixel_sigma is σ). An empty grid when not computed (a singular system).
  // With the problem's camera_intrinsics_covariance (the chessboard's), the camera lens's own
  // uncertainty is folded in (uncertainty_includes_camera_lens): held fixed, the projectors move
  // with the lens by −S⁻¹B (B the reduced cross term of their parameters with the lens's),
  // adding S⁻¹BΣcBᵀS⁻¹; refined (refine_camera_lens), the marginal of the joint covariance with
  // Σc as the lens's prior.
  double uncertainty_distance_m = 0.0;  // the median distance of its points from the projector
  ProjectionUncertaintyMap uncertainty;
  bool uncertainty_includes_camera_lens = false;
};

struct SelfCalibrationSummary {
  enum Termination {
    kConverged,     // the final (inlier) Ceres solve converged or gave a usable solution, and
                    // a floor was found
    kTooFewPoints,  // a projector has fewer than min_correspondences correspondences (after
                    // thinning), RANSAC inliers or final inliers (message names it)
    kDegenerate,    // a projector's correspondences fit one homography (no epipolar geometry),
                    // or no focal length in the throw-ratio range gives an essential matrix
    kDisconnected,  // a projector shares fewer than min_shared_points camera pixels with the
                    // others: its scale relative to theirs is unknown
    kInconsistent,  // a projector has more than max_outlier_fraction outliers after the robust
                    // pass: the solve went astray (e.g. a principal point far from its guess:
                    // give principal_point_guesses) or its decoding is bad (message names it)
    kNoFloor,       // no fitted plane faces the camera's image-up within max_floor_tilt_deg
    kSolverFailed,  // Ceres failed or the result is not finite
  };
  Termination termination = kSolverFailed;
  std::vector<SelfCalibrationProjectorSummary> projectors;
  int points = 0;            // 3D points (thinned camera pixels) in the bundle adjustment
  int ceres_iterations = 0;  // of both solves
  double initial_cost = 0.0, final_cost = 0.0;  // of the robust and the inlier solve
  double scale = 0.0;                           // metres per unit of the solve (from camera_height)
  // The camera's lens (refine_camera_lens with a chessboard covariance): whether the final solve
  // refined it, how far each intrinsic moved from the chessboard's (mrcal order, its units) and
  // how far that is in the chessboard's own uncertainty, √(Δᵀ Σ⁻¹ Δ) (a few: the scan agrees with
  // the chessboard; far more: one of them is wrong).
  // With floor_normal_in_camera: the angle between the scan's floor and the given normal before
  // the floor was held to it (NaN without one), and whether it was held (within
  // max_floor_normal_deg).
  double floor_to_given_normal_deg = std::numeric_limits<double>::quiet_NaN();
  bool floor_normal_held = false;
  bool camera_lens_refined = false;
  std::vector<double> camera_lens_moved;
  double camera_lens_moved_sigmas = 0.0;
  int floor_inliers = 0;                        // points on the floor plane
  double floor_rms_mm = 0.0;                    // their distance to it, millimetres
  double time_s = 0.0;
  std::string message;
  std::string BriefReport() const;
};

// The points of the self-calibration, in the room frame.
struct SelfCalibrationPoint {
  Vec3 p_in_room = Vec3::Zero();
  Vec2 camera_pixel = Vec2::Zero();
  int projectors = 0;  // how many projectors saw it (inlier observations)
};

// Calibrates the room from `problem` alone: `calibration` gets room_from_camera, the problem's
// camera lens, and per projector a pinhole lens (its held lens where the problem's
// held_projector_lenses holds one) and proj_from_room, as CalibrateRoom gives them;
// `points` (optional) the triangulated points in the room frame (for SceneFromPoints, with the
// camera's centre room_from_camera.translation() as viewpoint). Throws std::invalid_argument when
// the options fail Check(), the camera lens is unsupported, there is no projector, a
// projector's sizes are wrong, or held_projector_lenses is neither empty nor one per projector or
// holds an unsupported lens (non-finite, focal lengths ≤ 0). Returns true for kConverged; otherwise
// summary->message says why, naming the projector where one is to blame, and `calibration` is left
// unchanged.
bool SelfCalibrateRoom(const SelfCalibrationOptions& options, const RoomCalibrationProblem& problem,
                       RoomCalibration* calibration, std::vector<SelfCalibrationPoint>* points,
                       SelfCalibrationSummary* summary);

}  // namespace procam
