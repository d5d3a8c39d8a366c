#pragma once
// Room registration and joint refinement (issue 7, "Geometry"): the camera's pose in the room
// and every projector's intrinsics and pose, all in the room (scene) frame, from structured-light
// correspondences on the room's surfaces and the scene model; then an independent check by
// triangulation and ICP, and planes fitted to the scan.
//
//   CalibrateRoom (joint refinement, Ceres)
//     unknowns  room_from_camera (6 dof) and, per projector, fx, fy, cx, cy (optionally k1, k2)
//               and proj_from_room (6 dof); optionally (refine_camera_intrinsics) the camera's
//               fx, fy, cx, cy too, its distortion held at the chessboard calibration's values.
//               By default the camera's lens is held FIXED (from `procam calibrate camera`).
//               A projector whose lens is held (held_projector_lenses: a board calibration's
//               lens, calibration/board_projector.h) has its pose alone free.
//     data      per projector, camera pixel ↔ projector pixel (decoded structured light)
//     camera    each camera pixel's ray is its undistorted normalised coordinate x(d), d =
//               ((u − cx)/fx, (v − cy)/fy); with free intrinsics x is computed inside the cost
//               by two Newton steps on the OpenCV4 distortion from x0 = x(d0), the exact ray at
//               the intrinsics of the previous round (re-computed between rounds), so the
//               residual and its derivatives are those of the exact unprojection
//     model     each camera ray, through the current room_from_camera, meets the model's first
//               facet (a quad's plane, or one triangle of a mesh); the point is projected into
//               the projector; residual = projected − decoded projector pixel. The facet is
//               chosen from the current pose and re-chosen between solves until no
//               correspondence changes facet.
//     robust    a Cauchy pass on everything, then least squares on the inliers (residual ≤
//               outlier_threshold), as CalibrateProjector does
//     seed      a rough room_from_camera (a guess a few cm and degrees off) → the model's planes
//               in the camera frame → CalibrateProjector per projector (DLT + Ceres); a held
//               lens replaces the seed's, and the pose alone is refined against those planes
//   The camera pose is observable when the projectors light three or more surfaces with
//   linearly independent normals (e.g. floor and two walls); with two walls, sliding along their
//   common line is not. The camera's fx, fy, cx, cy are observable in addition when the points
//   are off one plane (the rays of a wrong focal length meet the planes where no single pinhole
//   projector sees them in the decoded order); the summary gives their 1σ from the final solve's
//   covariance, which says how well a given rig pins them.
//
//   Triangulate: each correspondence's camera ray and projector ray (midpoint of their common
//   perpendicular, the gap between them reported) → a point cloud in the camera frame.
//   RegisterModelToCloud: robust point-to-plane ICP (closest model point, a shrinking gate,
//   Huber loss) moves the model onto the cloud from a guess: room_from_camera and the residual
//   statistics of the cloud against the model (RMS, median, 95th percentile, per surface).
//   FitPlanes: sequential RANSAC planes in the cloud (a scene model from the scan alone starts
//   here).
//
// Frames and conventions: camera and projector frames x right, y down, z forward, metres;
// pixel centres at integers (calibration/projector_calibration.h). `room_from_camera` maps
// camera-frame points into the room (the scene file's frame); its translation is the camera's
// centre in the room. `proj_from_room` is what a scene file's projector `extrinsics` hold
// (mrcal rt_cam_ref with ref = the room).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "calibration/projection_uncertainty.h"
#include "calibration/projector_calibration.h"
#include "calibration/structured_light.h"
#include "geometry/scene.h"

namespace procam {

class RayScene;

// A planar piece of the room model in the room frame: a quad, or one triangle of a mesh.
struct ModelFacet {
  int surface = 0;            // index into Scene::surfaces
  Vec3 normal = Vec3::UnitZ();  // unit, towards the lit side
  double offset = 0.0;        // normal · p + offset = 0, metres
  std::vector<Vec3> corners;  // counter-clockwise seen from the lit side (convex)
};

// The scene's surfaces as facets, for ray casting (Embree) and closest-point queries.
class RoomModel {
 public:
  // Throws std::invalid_argument when the scene has no surface.
  explicit RoomModel(const Scene& scene);
  ~RoomModel();
  RoomModel(const RoomModel&) = delete;
  RoomModel& operator=(const RoomModel&) = delete;

  const Scene& scene() const { return scene_; }
  const std::vector<ModelFacet>& facets() const { return facets_; }
  // The first facet the ray (room frame; direction need not be unit) meets at t > 0; −1 when
  // none. `t` (optional) gets the ray parameter.
  int Intersect(const Vec3& origin, const Vec3& direction, double* t = nullptr) const;
  // The facet nearest to `p` (room frame), the nearest point on it and its distance, metres.
  int Closest(const Vec3& p, Vec3* nearest, double* distance) const;

 private:
  Scene scene_;
  std::vector<ModelFacet> facets_;
  std::vector<std::vector<int>> facets_of_surface_;
  std::unique_ptr<RayScene> rays_;
};

// What one projector showed, as the camera decoded it.
struct ProjectorObservations {
  std::string name;                 // for reports
  int width = 0, height = 0;        // projector pixels, ≥ 1
  std::vector<Vec2> camera_pixels;  // camera pixel of each correspondence
  std::vector<Vec2> projector_pixels;  // decoded projector pixel (same order)
  // Camera pixels where only one axis decoded: a surface lit at a grazing angle crowds many
  // projector columns (or rows) into one camera pixel, and the other axis may still resolve.
  // The decoded coordinate, NaN for the other one: (column, NaN) or (NaN, row). Calibration
  // does not use them; the scan triangulates them against the projector's column or row
  // (TriangulateOneAxis) where no projector decoded both axes.
  std::vector<Vec2> one_axis_camera_pixels;
  std::vector<Vec2> one_axis_projector_pixels;  // same order
};

// The correspondences of a decoded structured-light capture: every camera pixel of `map.mask`
// with the projector pixel it decoded to, and every pixel where one axis decoded (one_axis_*)
// and at least 3 of its 8 neighbours decoded that axis within 3 projector pixels of it (one axis
// passes its tests by chance where only bounce light reaches a pixel; a chance code disagrees
// with its neighbours), for a `width` × `height` projector named `name`.
ProjectorObservations ObservationsFromMap(const StructuredLightMap& map, std::string name, int width, int height);

// A projector's lens held fixed in the room's solve: its pose alone is found. What a board
// calibration (calibration/board_projector.h) gives of a projector, read from its .cameramodel.
struct HeldProjectorLens {
  std::string lens_model;          // "LENSMODEL_PINHOLE" (4 intrinsics) or "LENSMODEL_OPENCV4" (8)
  std::vector<double> intrinsics;  // mrcal order: fx, fy, cx, cy[, k1, k2, p1, p2]
  std::string source;              // where it came from, for reports (a file name)
  int source_width = 0, source_height = 0;  // the file's imagersize (checked by its reader)
};

struct RoomCalibrationProblem {
  // The camera's lens: "LENSMODEL_PINHOLE" (4 intrinsics) or "LENSMODEL_OPENCV4" (8). Held fixed,
  // or the start of fx, fy, cx, cy with RoomCalibrationOptions::refine_camera_intrinsics.
  std::string camera_lens_model = "LENSMODEL_PINHOLE";
  std::vector<double> camera_intrinsics;
  // The lens's covariance from the chessboard (ProjectionUncertainty::IntrinsicsCovariance),
  // intrinsics × intrinsics, or empty: the prior with which SelfCalibrateRoom refines the lens
  // (SelfCalibrationOptions::refine_camera_lens), and the lens's uncertainty it folds into the
  // projectors' (SelfCalibrationProjectorSummary::uncertainty). CalibrateRoom does not use it.
  Eigen::MatrixXd camera_intrinsics_covariance;
  std::vector<ProjectorObservations> projectors;
  // Empty, or one per projector (same order): an entry with a lens_model holds that projector's
  // lens (intrinsics and distortion) fixed at its values, so the solve finds its pose alone (6
  // unknowns instead of 10 or 12); an entry with an empty lens_model leaves the lens to the solve.
  std::vector<HeldProjectorLens> held_projector_lenses;
};

struct RoomCalibrationOptions {
  // Refine the projectors' radial distortion k1, k2 (LENSMODEL_OPENCV4, p1 = p2 = 0).
  bool refine_distortion = false;
  // Refine the camera's fx, fy, cx, cy jointly with its pose and the projectors (distortion held
  // at the problem's values). Needs points off one plane; see the summary's camera_sigma.
  bool refine_camera_intrinsics = false;
  // With refine_camera_intrinsics: keep fy / fx at the problem's value (the chessboard's ratio)
  // and refine one focal length, cx and cy. Rooms pin the image's vertical scale weakly when
  // their surfaces are walls and a floor (c_shaped: fy's 1σ is 4× fx's, and the decoded
  // staircase pulls fy 0.23% off); the aspect ratio is what a chessboard determines best.
  // false: fx and fy free independently.
  bool keep_camera_aspect_ratio = true;
  double loss_scale = 1.0;         // Cauchy scale of the robust pass, projector pixels, > 0
  double outlier_threshold = 2.0;  // inlier residual norm, projector pixels, > 0
  int min_correspondences = 50;    // per projector, fewest usable ones, ≥ 12
  // Per projector, at most this many correspondences are used, thinned evenly (decoded
  // structured light gives one per camera pixel; a few thousand already average the decoding
  // noise down far below the targets), ≥ min_correspondences.
  int max_correspondences = 10000;
  int max_rounds = 6;              // facet re-association rounds, ≥ 1
  int max_iterations = 100;        // per Ceres solve, ≥ 1
  bool Check(std::string* why) const;
};

// A projector in the room frame.
struct RoomProjector {
  std::string name;
  std::string lens_model;          // "LENSMODEL_PINHOLE" or "LENSMODEL_OPENCV4"
  std::vector<double> intrinsics;  // mrcal order (a held lens's exactly as given)
  int width = 0, height = 0;
  Eigen::Isometry3d proj_from_room = Eigen::Isometry3d::Identity();
  bool lens_held = false;  // the problem's held_projector_lenses held it
};

struct RoomCalibration {
  Eigen::Isometry3d room_from_camera = Eigen::Isometry3d::Identity();
  // The camera's lens: the problem's, with fx, fy, cx, cy refined when refine_camera_intrinsics.
  std::string camera_lens_model;
  std::vector<double> camera_intrinsics;
  std::vector<RoomProjector> projectors;  // same order as the problem's
};

struct RoomProjectorSummary {
  int correspondences = 0;  // given
  int used = 0;             // after thinning to max_correspondences
  int points = 0;           // whose camera ray meets the model (final pose)
  int outliers = 0;         // residual norm > outlier_threshold after the robust pass
  double seed_rms = 0.0;    // CalibrateProjector's RMS per coordinate on the guessed planes, px
  double rms = 0.0;         // RMS per coordinate over inliers, px
  double max_norm = 0.0;    // largest inlier residual norm, px
  // What the joint solve is sure of: the worst-direction standard deviation, px, of where the
  // projector shows a point fixed in the room `uncertainty_distance_m` along each pixel's ray
  // (the median distance of its points), over a 16 × 12 grid, centre and corners. Covariance of
  // the projector's free parameters: the marginal of σ² (JᵀJ)⁻¹ over the whole final solve (the
  // camera's pose, and lens when refined, included), σ² the inliers' residual variance: decoding
  // noise only, the model's own errors come on top. Empty grid when JᵀJ is singular.
  ProjectionUncertaintyMap uncertainty;
  double uncertainty_distance_m = 0.0;
};

struct RoomCalibrationSummary {
  enum Termination {
    kConverged,     // the last Ceres solve converged (or gave a usable solution) and no
                    // correspondence changed facet in the last round
    kNotSettled,    // usable, but facets still changed after max_rounds rounds
    kSeedFailed,    // CalibrateProjector failed for a projector (message names it)
    kTooFewPoints,  // a projector has fewer than min_correspondences points (or inliers)
    kSolverFailed,  // Ceres failed or the result is not finite
  };
  Termination termination = kSolverFailed;
  std::vector<RoomProjectorSummary> projectors;
  int rounds = 0;
  double initial_cost = 0.0, final_cost = 0.0;  // of the first and last Ceres solve
  // How far the result moved from the guess: the camera's centre (mm) and orientation (deg).
  double camera_moved_mm = 0.0, camera_turned_deg = 0.0;
  // With refine_camera_intrinsics: how far fx, fy, cx, cy moved from the problem's (px), and
  // their 1σ (px) from the last solve's Gauss–Newton covariance (JᵀJ)⁻¹ · s², s² = 2·cost /
  // (residuals − parameters): decoding noise only, model errors (walls not flat) come on top.
  // Zero when the intrinsics are held fixed; camera_sigma is NaN when JᵀJ is singular beyond
  // one direction (a gauge, which the pseudo-inverse leaves out).
  double camera_intrinsics_moved[4] = {0, 0, 0, 0};
  double camera_sigma[4] = {0, 0, 0, 0};
  double time_s = 0.0;
  std::string message;
  std::string BriefReport() const;
};

// Calibrates the room: seeds every projector with CalibrateProjector on the model's planes as
// seen from `room_from_camera_guess`, then refines everything jointly. Throws
// std::invalid_argument when the options fail Check(), the camera lens is unsupported, there is
// no projector, or a projector's sizes are wrong. Returns true for kConverged and kNotSettled.
bool CalibrateRoom(const RoomCalibrationOptions& options, const RoomModel& model,
                   const RoomCalibrationProblem& problem,
                   const Eigen::Isometry3d& room_from_camera_guess, RoomCalibration* calibration,
                   RoomCalibrationSummary* summary);

// One triangulated correspondence.
struct TriangulatedPoint {
  Vec3 p_in_cam = Vec3::Zero();
  double gap = 0.0;  // distance between the camera ray and the projector ray, metres
  int projector = 0;
  Vec2 camera_pixel = Vec2::Zero();
  Vec3 on_camera_ray = Vec3::Zero();  // the camera ray's point closest to the projector's ray
  bool one_axis = false;  // from a one-axis correspondence (TriangulateOneAxis)
};

// Triangulates every correspondence of `problem` by the midpoint of the camera ray and the ray
// of projector k, whose pose in the camera frame is proj_from_room · room_from_camera of
// `calibration`. The camera lens is `calibration`'s when it holds one (CalibrateRoom fills it),
// else the problem's. Points behind either device, or with a gap above `max_gap` metres, are left
// out.
std::vector<TriangulatedPoint> Triangulate(const RoomCalibrationProblem& problem,
                                           const RoomCalibration& calibration,
                                           double max_gap = 0.05);

// The one-axis correspondences (ProjectorObservations::one_axis_*) of `problem`, each
// triangulated against its projector's column (or row): the point of the camera ray at which
// projector k, posed as in Triangulate, shows the decoded coordinate, found by a safeguarded
// Newton search along the ray between 0.1 and 100 metres. A point is left out where the ray
// runs so nearly along the column's surface that one projector pixel spans more than
// `max_depth_per_pixel` metres of depth (decoding noise would move it that far), where the
// coordinate is reached more than once along the ray, or where the other coordinate of the
// projected point falls outside the projector's image. `gap` is the depth one projector pixel
// spans there, metres; on_camera_ray = p_in_cam; one_axis is true.
std::vector<TriangulatedPoint> TriangulateOneAxis(const RoomCalibrationProblem& problem,
                                                  const RoomCalibration& calibration,
                                                  double max_depth_per_pixel = 0.06);

// One point per camera pixel, as a scan of the room wants it (SceneFromPoints takes its points'
// spacing for the camera's pixel lattice): where several projectors light a pixel, their
// triangulations' points on the camera ray (on_camera_ray) within `max_spread` metres of their
// median depth are averaged into p_in_cam, on the ray; a pixel none of whose points lies that
// close is left out. `projector` is the number of points averaged, `gap` their largest.
// One-axis points (TriangulateOneAxis) count only at pixels where no two-axis point is given, and
// are kept only where their depth lies within 10% beyond the range of the fused two-axis points
// at most 8 pixels away (a wrong one-axis code lands anywhere along the ray; a surface seen at a
// grazing angle continues its neighbours' depths).
// Triangulate's points of one projector are one per pixel already; two projectors' points of one
// pixel, side by side in the cloud, double its density where both light the room and make its
// spacing look smaller than the pixels' is.
std::vector<TriangulatedPoint> FusePerCameraPixel(const std::vector<TriangulatedPoint>& points,
                                                  double max_spread = 0.01);

// The points of a scan of the room, one per camera pixel: every correspondence triangulated
// (Triangulate; rays more than `max_gap` metres apart left out) and every one-axis
// correspondence (TriangulateOneAxis), fused (FusePerCameraPixel). `gaps` (optional) gets the
// ray gaps of the two-axis triangulations, metres.
std::vector<TriangulatedPoint> TriangulateScan(const RoomCalibrationProblem& problem,
                                               const RoomCalibration& calibration,
                                               double max_gap = 0.02,
                                               std::vector<double>* gaps = nullptr);

// At most `max_points` of one-per-pixel `points` (FusePerCameraPixel's), still a lattice of
// pixels: those whose camera pixel's column and row are multiples of the smallest s that leaves
// at most max_points in the worst case (every pixel present: s = ⌈√(size / max_points)⌉); all of
// them when they are that few already. `*lattice` (optional) gets s.
std::vector<TriangulatedPoint> KeepPixelLattice(const std::vector<TriangulatedPoint>& points,
                                                size_t max_points, int* lattice = nullptr);

// Distances of points to the model, in millimetres.
struct DistanceStats {
  int points = 0;
  double rms_mm = 0.0, median_mm = 0.0, p95_mm = 0.0, max_mm = 0.0;
};
DistanceStats ComputeDistanceStats(std::vector<double> distances_m);

struct RegistrationOptions {
  // Gate of the first iteration: model points farther than this are not matched, metres, > 0.
  double initial_gate = 0.2;
  // The gate then shrinks to max(min_gate, 3 × 1.4826 × the median distance), metres, > 0.
  double min_gate = 0.01;
  double huber_scale = 0.003;     // metres, > 0
  double inlier_distance = 0.01;  // a point within this of the model is an inlier, metres, > 0
  int max_points = 20000;         // the cloud is thinned evenly to at most this, ≥ 10
  int max_iterations = 50;        // ICP iterations, ≥ 1
  double tolerance = 1e-7;        // stop when the pose moves less (metres, radians), > 0
  bool Check(std::string* why) const;
};

struct RegistrationSummary {
  enum Termination {
    kConverged,     // the pose moved less than `tolerance` in the last iteration
    kMaxIterations, // still moving after max_iterations
    kTooFewPoints,  // fewer than 6 points matched
    kSolverFailed,  // Ceres failed
  };
  Termination termination = kSolverFailed;
  int iterations = 0;
  int points = 0;              // used (after thinning)
  double initial_rms_mm = 0.0; // RMS distance of the matched points at the guess
  double inlier_fraction = 0.0;
  DistanceStats inliers;       // over points within inlier_distance of the model
  DistanceStats all;           // over every point used
  std::vector<DistanceStats> per_surface;  // inliers, by the surface of the nearest facet
  double time_s = 0.0;
  std::string BriefReport() const;
};

// Moves the model onto `points_in_cam`: finds room_from_camera (from `guess`) minimising the
// robust point-to-plane distances of the cloud (in the room frame) to the model. Throws
// std::invalid_argument when the options fail Check(). True for kConverged and kMaxIterations.
bool RegisterModelToCloud(const RegistrationOptions& options, const RoomModel& model,
                          const std::vector<Vec3>& points_in_cam,
                          const Eigen::Isometry3d& guess, Eigen::Isometry3d* room_from_camera,
                          RegistrationSummary* summary);

// Planes found in a cloud by sequential RANSAC, each refined by least squares on its inliers.
struct FittedPlane {
  Vec3 normal = Vec3::UnitZ();  // unit, in the cloud's frame (towards the cloud's origin)
  double offset = 0.0;          // normal · p + offset = 0
  int inliers = 0;
  double rms_mm = 0.0;          // of the inliers' distances to the plane
  Vec3 centroid = Vec3::Zero();
  Vec2 extent = Vec2::Zero();   // sides of the inliers' bounding rectangle in the plane (PCA axes), m
};

struct PlaneFitOptions {
  // Inlier distance, metres, > 0: about 3 × the triangulation noise (the back wall of c_shaped,
  // 5.5 m away, triangulates with 5 mm RMS); too small splits one wall into parallel slabs.
  double distance = 0.02;
  int min_inliers = 200;   // a plane needs at least this many, ≥ 3,
  double min_fraction = 0.01;  // and at least this fraction of the cloud, [0, 1)
  int max_planes = 12;     // ≥ 1
  int iterations = 500;    // RANSAC samples per plane, ≥ 1
  unsigned seed = 1;
  bool Check(std::string* why) const;
};
std::vector<FittedPlane> FitPlanes(const PlaneFitOptions& options, const std::vector<Vec3>& points);

}  // namespace procam
