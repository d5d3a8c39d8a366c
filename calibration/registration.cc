#include "calibration/registration.h"

#include "base/timing.h"
#include "calibration/pose_math.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <numeric>
#include <random>
#include <stdexcept>
#include <unordered_map>

#include <Eigen/Eigenvalues>
#include <ceres/ceres.h>
#include <ceres/rotation.h>
extern "C" {
#include <mrcal/mrcal.h>
}

#include "base/camera_model.h"
#include "base/io.h"
#include "geometry/ray_scene.h"

namespace procam {

namespace {

// A rigid transform as Ceres parameter blocks: angle-axis rotation, then translation.
struct PoseBlock {
  double rotation[3] = {0, 0, 0};
  double translation[3] = {0, 0, 0};
  explicit PoseBlock(const Eigen::Isometry3d& pose = Eigen::Isometry3d::Identity()) {
    const Vec3 r = AngleAxisOf(pose.linear());
    for (int i = 0; i < 3; ++i) {
      rotation[i] = r(i);
      translation[i] = pose.translation()(i);
    }
  }
  Eigen::Isometry3d Pose() const {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = RotationOf(Vec3(rotation[0], rotation[1], rotation[2]));
    pose.translation() = Vec3(translation[0], translation[1], translation[2]);
    return pose;
  }
  bool Finite() const {
    for (int i = 0; i < 3; ++i)
      if (!std::isfinite(rotation[i]) || !std::isfinite(translation[i])) return false;
    return true;
  }
};

double TurnDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a * b.transpose()).angle() * 180.0 / std::numbers::pi;
}

ceres::Solver::Options SolverOptions(int max_iterations) {
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  options.max_num_iterations = max_iterations;
  options.function_tolerance = 1e-12;
  options.gradient_tolerance = 1e-12;
  options.parameter_tolerance = 1e-12;
  options.num_threads = 2;
  return options;
}

// Closest point of a convex planar polygon to p.
Vec3 ClosestOnFacet(const ModelFacet& facet, const Vec3& p) {
  const Vec3 in_plane = p - (facet.normal.dot(p) + facet.offset) * facet.normal;
  const size_t n = facet.corners.size();
  bool inside = true;
  for (size_t i = 0; i < n && inside; ++i) {
    const Vec3& a = facet.corners[i];
    const Vec3& b = facet.corners[(i + 1) % n];
    if ((b - a).cross(in_plane - a).dot(facet.normal) < 0.0) inside = false;
  }
  if (inside) return in_plane;
  Vec3 best = facet.corners[0];
  double best_sq = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < n; ++i) {
    const Vec3& a = facet.corners[i];
    const Vec3& b = facet.corners[(i + 1) % n];
    const Vec3 ab = b - a;
    const double s = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
    const Vec3 q = a + s * ab;
    if ((q - p).squaredNorm() < best_sq) {
      best_sq = (q - p).squaredNorm();
      best = q;
    }
  }
  return best;
}

ModelFacet MakeFacet(int surface, const std::vector<Vec3>& corners) {
  ModelFacet facet;
  facet.surface = surface;
  facet.corners = corners;
  Vec3 normal = Vec3::Zero();  // Newell's method: robust for any planar polygon
  Vec3 centre = Vec3::Zero();
  for (size_t i = 0; i < corners.size(); ++i) {
    const Vec3& a = corners[i];
    const Vec3& b = corners[(i + 1) % corners.size()];
    normal += a.cross(b);
    centre += a;
  }
  facet.normal = normal.normalized();
  facet.offset = -facet.normal.dot(centre / static_cast<double>(corners.size()));
  return facet;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// RoomModel

RoomModel::RoomModel(const Scene& scene) : scene_(scene) {
  if (scene.surfaces.empty()) throw std::invalid_argument("RoomModel: the scene has no surface");
  facets_of_surface_.resize(scene.surfaces.size());
  for (size_t s = 0; s < scene.surfaces.size(); ++s) {
    const Surface& surface = scene.surfaces[s];
    if (surface.kind == Surface::Kind::kQuad) {
      facets_of_surface_[s].push_back(static_cast<int>(facets_.size()));
      facets_.push_back(MakeFacet(static_cast<int>(s), {surface.quad.begin(), surface.quad.end()}));
    } else {
      for (const MeshTriangle& triangle : surface.mesh_triangles) {
        facets_of_surface_[s].push_back(static_cast<int>(facets_.size()));
        facets_.push_back(MakeFacet(static_cast<int>(s), {surface.mesh_vertices[triangle.vertex[0]],
                                                          surface.mesh_vertices[triangle.vertex[1]],
                                                          surface.mesh_vertices[triangle.vertex[2]]}));
      }
    }
  }
  rays_ = std::make_unique<RayScene>(scene_);
}

RoomModel::~RoomModel() = default;

int RoomModel::Intersect(const Vec3& origin, const Vec3& direction, double* t) const {
  double t_hit = 0.0;
  int surface = -1;
  if (!rays_->Intersect(origin, direction, 0.0, std::numeric_limits<double>::infinity(), &t_hit,
                        &surface) ||
      surface < 0 || surface >= static_cast<int>(facets_of_surface_.size()))
    return -1;
  const std::vector<int>& candidates = facets_of_surface_[surface];
  int best = candidates.empty() ? -1 : candidates[0];
  if (candidates.size() > 1) {
    // Which triangle of the mesh: the one nearest to the hit point.
    const Vec3 hit = origin + t_hit * direction;
    double best_distance = std::numeric_limits<double>::infinity();
    for (const int f : candidates) {
      const double distance = (ClosestOnFacet(facets_[f], hit) - hit).squaredNorm();
      if (distance < best_distance) {
        best_distance = distance;
        best = f;
      }
    }
  }
  if (best >= 0 && t) {
    // The hit on the facet's exact plane (Embree works in single precision).
    const ModelFacet& facet = facets_[best];
    *t = -(facet.normal.dot(origin) + facet.offset) / facet.normal.dot(direction);
  }
  return best;
}

int RoomModel::Closest(const Vec3& p, Vec3* nearest, double* distance) const {
  int best = -1;
  double best_sq = std::numeric_limits<double>::infinity();
  for (size_t f = 0; f < facets_.size(); ++f) {
    const ModelFacet& facet = facets_[f];
    // The plane distance is a lower bound of the facet distance.
    const double plane = facet.normal.dot(p) + facet.offset;
    if (plane * plane >= best_sq) continue;
    const Vec3 q = ClosestOnFacet(facet, p);
    const double sq = (q - p).squaredNorm();
    if (sq < best_sq) {
      best_sq = sq;
      best = static_cast<int>(f);
      if (nearest) *nearest = q;
    }
  }
  if (distance) *distance = std::sqrt(best_sq);
  return best;
}

// ---------------------------------------------------------------------------------------------
// Joint refinement

bool RoomCalibrationOptions::Check(std::string* why) const {
  auto fail = [why](const char* message) {
    if (why) *why = message;
    return false;
  };
  if (!(loss_scale > 0.0) || !std::isfinite(loss_scale)) return fail("loss_scale must be > 0");
  if (!(outlier_threshold > 0.0) || !std::isfinite(outlier_threshold))
    return fail("outlier_threshold must be > 0");
  if (min_correspondences < 12) return fail("min_correspondences must be at least 12");
  if (max_correspondences < min_correspondences)
    return fail("max_correspondences must be at least min_correspondences");
  if (max_rounds < 1) return fail("max_rounds must be at least 1");
  if (max_iterations < 1) return fail("max_iterations must be at least 1");
  return true;
}

std::string RoomCalibrationSummary::BriefReport() const {
  static const char* const kNames[] = {"converged", "facets not settled", "seed failed",
                                       "too few points", "solver failed"};
  std::string text = std::string("Room calibration: ") + kNames[termination];
  char line[320];
  std::snprintf(line, sizeof(line),
                "; %d rounds; cost %.4g -> %.4g; camera moved %.1f mm, turned %.3f deg from the "
                "guess; %.2f s",
                rounds, initial_cost, final_cost, camera_moved_mm, camera_turned_deg, time_s);
  text += line;
  if (camera_sigma[0] != 0.0) {
    std::snprintf(line, sizeof(line),
                  "\n  camera fx, fy, cx, cy refined: moved %+.3f, %+.3f, %+.3f, %+.3f px; 1 sigma "
                  "%.3g, %.3g, %.3g, %.3g px",
                  camera_intrinsics_moved[0], camera_intrinsics_moved[1],
                  camera_intrinsics_moved[2], camera_intrinsics_moved[3], camera_sigma[0],
                  camera_sigma[1], camera_sigma[2], camera_sigma[3]);
    text += line;
  }
  for (size_t k = 0; k < projectors.size(); ++k) {
    const RoomProjectorSummary& p = projectors[k];
    std::snprintf(line, sizeof(line),
                  "\n  projector %zu: %d correspondences, %d used, %d on the model, %d outliers; "
                  "seed RMS %.3g px, RMS %.4g px per coordinate, max %.3g px",
                  k, p.correspondences, p.used, p.points, p.outliers, p.seed_rms, p.rms, p.max_norm);
    text += line;
  }
  if (!message.empty()) text += "\n  " + message;
  return text;
}

namespace {

// Camera ray (direction with z = 1, camera frame) → through room_from_camera into the room →
// meets a fixed facet plane → the point projected by the projector (proj_from_room, fx fy cx cy
// k1 k2) → minus the decoded projector pixel.
template <typename T>
void ReprojectThroughRoom(const T* ray, const T* camera_rotation, const T* camera_translation,
                          const T* intrinsics, const T* projector_rotation,
                          const T* projector_translation, const Vec3& normal, double offset,
                          const Vec2& observed, const double* tangential, T* residual) {
  T direction[3];
  ceres::AngleAxisRotatePoint(camera_rotation, ray, direction);
  const T along_normal =
      T(normal.x()) * direction[0] + T(normal.y()) * direction[1] + T(normal.z()) * direction[2];
  const T origin_height = T(normal.x()) * camera_translation[0] +
                          T(normal.y()) * camera_translation[1] +
                          T(normal.z()) * camera_translation[2] + T(offset);
  const T s = -origin_height / along_normal;
  T p_in_room[3];
  for (int i = 0; i < 3; ++i) p_in_room[i] = camera_translation[i] + s * direction[i];
  ProjectorPixelResidual(intrinsics, projector_rotation, projector_translation, p_in_room, observed,
                         residual, tangential);
}

// The camera's lens fixed: the ray is a constant.
struct RoomReprojection {
  RoomReprojection(const Vec3& ray_in_cam, const Vec3& normal, double offset, const Vec2& observed,
                   const double* tangential)
      : ray_in_cam(ray_in_cam),
        normal(normal),
        offset(offset),
        observed(observed),
        tangential{tangential[0], tangential[1]} {}
  template <typename T>
  bool operator()(const T* camera_rotation, const T* camera_translation, const T* intrinsics,
                  const T* projector_rotation, const T* projector_translation,
                  T* residual) const {
    const T ray[3] = {T(ray_in_cam.x()), T(ray_in_cam.y()), T(ray_in_cam.z())};
    ReprojectThroughRoom(ray, camera_rotation, camera_translation, intrinsics, projector_rotation,
                         projector_translation, normal, offset, observed, tangential, residual);
    return true;
  }
  Vec3 ray_in_cam;
  Vec3 normal;
  double offset;
  Vec2 observed;
  double tangential[2];  // the projector's p1, p2 (non-zero for a held OpenCV4 lens only)
};

// The camera's fx, fy, cx, cy free (distortion k1 k2 p1 p2 fixed, all zero for a pinhole): the
// ray is the undistortion x of d = ((u − cx)/fx, (v − cy)/fy), i.e. D(x) = d with D the OpenCV4
// distortion, by two Newton steps from x0 = the exact undistortion at the intrinsics the rays
// were last computed with. The first step is the linearisation x0 + (∂D/∂x)⁻¹ (d − d0), the
// second makes the value (and through the Jets the derivative) exact to far below the decoding
// noise for the steps the intrinsics take between rounds (≲ 1%).
struct RoomReprojectionFreeCamera {
  RoomReprojectionFreeCamera(const Vec2& camera_pixel, const Vec3& ray0, const double* distortion,
                             bool distorted, double aspect, const Vec3& normal, double offset,
                             const Vec2& observed, const double* tangential)
      : camera_pixel(camera_pixel),
        ray0(ray0.x(), ray0.y()),
        distorted(distorted),
        aspect(aspect),
        normal(normal),
        offset(offset),
        observed(observed),
        tangential{tangential[0], tangential[1]} {
    for (int i = 0; i < 4; ++i) this->distortion[i] = distortion[i];
  }
  template <typename T>
  bool operator()(const T* camera_rotation, const T* camera_translation,
                  const T* camera_intrinsics, const T* intrinsics, const T* projector_rotation,
                  const T* projector_translation, T* residual) const {
    const T dx = (T(camera_pixel.x()) - camera_intrinsics[2]) / camera_intrinsics[0];
    // aspect > 0: fy = aspect · fx (the block's fy is then held and ignored).
    const T fy = aspect > 0.0 ? aspect * camera_intrinsics[0] : camera_intrinsics[1];
    const T dy = (T(camera_pixel.y()) - camera_intrinsics[3]) / fy;
    T ray[3] = {dx, dy, T(1.0)};
    if (distorted) {
      T x = T(ray0.x()), y = T(ray0.y());
      UndistortOpenCv4Steps(distortion, dx, dy, 2, &x, &y);
      ray[0] = x;
      ray[1] = y;
    }
    ReprojectThroughRoom(ray, camera_rotation, camera_translation, intrinsics, projector_rotation,
                         projector_translation, normal, offset, observed, tangential, residual);
    return true;
  }
  Vec2 camera_pixel;
  Vec2 ray0;
  double distortion[4] = {0, 0, 0, 0};
  bool distorted;
  double aspect;
  Vec3 normal;
  double offset;
  Vec2 observed;
  double tangential[2];
};

struct ProjectorState {
  double intrinsics[6] = {0, 0, 0, 0, 0, 0};  // fx, fy, cx, cy, k1, k2
  double tangential[2] = {0, 0};  // p1, p2: constants, non-zero for a held OpenCV4 lens only
  bool held = false;              // the lens held (constant): the pose alone is solved
  PoseBlock proj_from_room;
};

// Per correspondence: its camera ray (at the current camera intrinsics) and the facet it meets
// under the current pose.
struct Correspondence {
  Vec2 camera_pixel;
  Vec3 ray_in_cam;
  Vec2 observed;
  int facet = -1;
  bool inlier = true;
};

Vec2 Residual(const Correspondence& c, const ModelFacet& facet, const PoseBlock& camera,
              const ProjectorState& projector) {
  Vec2 r;
  RoomReprojection(c.ray_in_cam, facet.normal, facet.offset, c.observed, projector.tangential)(
      camera.rotation, camera.translation, projector.intrinsics, projector.proj_from_room.rotation,
      projector.proj_from_room.translation, r.data());
  return r;
}

// Re-chooses each correspondence's facet from the camera pose; returns how many changed.
int Associate(const RoomModel& model, const PoseBlock& camera,
              std::vector<std::vector<Correspondence>>* correspondences) {
  const Eigen::Isometry3d room_from_camera = camera.Pose();
  int changed = 0;
  for (std::vector<Correspondence>& list : *correspondences)
    for (Correspondence& c : list) {
      double t = 0.0;
      int facet = model.Intersect(room_from_camera.translation(),
                                  room_from_camera.linear() * c.ray_in_cam, &t);
      if (facet >= 0 && !(t > 0.0)) facet = -1;
      if (facet != c.facet) ++changed;
      c.facet = facet;
    }
  return changed;
}

}  // namespace

namespace {

// CalibrateRoom's inputs. Throws std::invalid_argument.
void CheckRoomProblem(const RoomCalibrationOptions& options, const RoomCalibrationProblem& problem) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("RoomCalibrationOptions: " + why);
  Vec3 probe;
  if (!UnprojectCameraPixel(problem.camera_lens_model, problem.camera_intrinsics, Vec2::Zero(),
                            &probe))
    throw std::invalid_argument("CalibrateRoom: camera lens must be LENSMODEL_PINHOLE (4 "
                                "intrinsics) or LENSMODEL_OPENCV4 (8), got " +
                                problem.camera_lens_model);
  if (problem.projectors.empty()) throw std::invalid_argument("CalibrateRoom: no projector");
  for (const ProjectorObservations& p : problem.projectors) {
    if (p.width < 1 || p.height < 1)
      throw std::invalid_argument("CalibrateRoom: projector '" + p.name +
                                  "': size must be at least 1x1");
    if (p.camera_pixels.size() != p.projector_pixels.size())
      throw std::invalid_argument("CalibrateRoom: projector '" + p.name +
                                  "': camera and projector pixel counts differ");
  }
  if (!problem.held_projector_lenses.empty() &&
      problem.held_projector_lenses.size() != problem.projectors.size())
    throw std::invalid_argument(
        "CalibrateRoom: " + std::to_string(problem.held_projector_lenses.size()) +
        " held projector lenses for " + std::to_string(problem.projectors.size()) + " projectors");
  for (size_t k = 0; k < problem.held_projector_lenses.size(); ++k) {
    const HeldProjectorLens& lens = problem.held_projector_lenses[k];
    if (lens.lens_model.empty()) continue;
    const std::string name = "CalibrateRoom: projector '" + problem.projectors[k].name + "': ";
    if (!UnprojectCameraPixel(lens.lens_model, lens.intrinsics, Vec2::Zero(), &probe))
      throw std::invalid_argument(name +
                                  "a held lens must be LENSMODEL_PINHOLE (4 intrinsics) "
                                  "or LENSMODEL_OPENCV4 (8), got " +
                                  lens.lens_model + " with " +
                                  std::to_string(lens.intrinsics.size()));
    for (const double value : lens.intrinsics)
      if (!std::isfinite(value))
        throw std::invalid_argument(name + "the held lens has a non-finite intrinsic");
    if (!(lens.intrinsics[0] > 0.0) || !(lens.intrinsics[1] > 0.0))
      throw std::invalid_argument(name + "the held lens's focal lengths must be positive");
  }
}

// Projector k's held lens, or null when the solve finds its lens.
const HeldProjectorLens* HeldLens(const RoomCalibrationProblem& problem, size_t k) {
  if (k >= problem.held_projector_lenses.size() ||
      problem.held_projector_lenses[k].lens_model.empty())
    return nullptr;
  return &problem.held_projector_lenses[k];
}

// Every projector's correspondences, thinned evenly to options.max_correspondences, with the
// camera ray of each at the problem's lens (pixels whose ray cannot be found are left out).
std::vector<std::vector<Correspondence>> SampleCorrespondences(const RoomCalibrationOptions& options,
                                                               const RoomCalibrationProblem& problem,
                                                               RoomCalibrationSummary* summary) {
  const int projector_count = static_cast<int>(problem.projectors.size());
  std::vector<std::vector<Correspondence>> correspondences(projector_count);
  for (int k = 0; k < projector_count; ++k) {
    const ProjectorObservations& p = problem.projectors[k];
    summary->projectors[k].correspondences = static_cast<int>(p.camera_pixels.size());
    const size_t stride = std::max<size_t>(
        1, (p.camera_pixels.size() + options.max_correspondences - 1) / options.max_correspondences);
    for (size_t i = 0; i < p.camera_pixels.size(); i += stride) {
      Correspondence c;
      if (!p.camera_pixels[i].allFinite() || !p.projector_pixels[i].allFinite() ||
          !UnprojectCameraPixel(problem.camera_lens_model, problem.camera_intrinsics,
                                p.camera_pixels[i], &c.ray_in_cam))
        continue;
      c.camera_pixel = p.camera_pixels[i];
      c.observed = p.projector_pixels[i];
      correspondences[k].push_back(c);
    }
    summary->projectors[k].used = static_cast<int>(correspondences[k].size());
  }
  return correspondences;
}

// σ² (JᵀJ)⁻¹ of the solve over `blocks` (in the tangent coordinates of each, in order),
// σ² = 2·cost / (residuals − parameters); false when JᵀJ is singular beyond one gauge direction.
bool ParameterCovariance(ceres::Problem& ceres_problem, const std::vector<double*>& blocks,
                         double cost, Eigen::MatrixXd* covariance) {
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.parameter_blocks = blocks;
  evaluate.apply_loss_function = false;
  ceres::CRSMatrix jacobian;
  if (!ceres_problem.Evaluate(evaluate, nullptr, nullptr, nullptr, &jacobian)) return false;
  const int n = jacobian.num_cols;
  Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(n, n);
  for (int row = 0; row < jacobian.num_rows; ++row)
    for (int a = jacobian.rows[row]; a < jacobian.rows[row + 1]; ++a)
      for (int b = a; b < jacobian.rows[row + 1]; ++b) {
        const double product = jacobian.values[a] * jacobian.values[b];
        normal(jacobian.cols[a], jacobian.cols[b]) += product;
        if (jacobian.cols[a] != jacobian.cols[b])
          normal(jacobian.cols[b], jacobian.cols[a]) += product;
      }
  // Scaled to unit diagonal first: radians, metres and pixels differ by orders of magnitude.
  const Eigen::VectorXd scale = normal.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd scaled = scale.asDiagonal() * normal * scale.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(scaled);
  if (eigen.info() != Eigen::Success || !(eigen.eigenvalues()(n - 1) > 0.0)) return false;
  // Directions the solve does not see at all (eigenvalues at rounding level) are a gauge: left
  // out (the pseudo-inverse). Measured on l_shaped: one, a common shift of the camera and the
  // projectors.
  Eigen::VectorXd inverse_eigenvalues(n);
  int gauge = 0;
  for (int i = 0; i < n; ++i) {
    const bool seen = eigen.eigenvalues()(i) > 1e-10 * eigen.eigenvalues()(n - 1);
    inverse_eigenvalues(i) = seen ? 1.0 / eigen.eigenvalues()(i) : 0.0;
    gauge += !seen;
  }
  if (gauge > 1) return false;  // more than a gauge: a degenerate solve
  const int degrees_of_freedom = jacobian.num_rows - n;
  if (degrees_of_freedom < 1) return false;
  const double variance = 2.0 * cost / degrees_of_freedom;
  *covariance = variance * scale.asDiagonal() * eigen.eigenvectors() *
                inverse_eigenvalues.asDiagonal() * eigen.eigenvectors().transpose() *
                scale.asDiagonal();
  return true;
}

// The camera's fx, fy, cx, cy 1σ from the covariance over (camera rotation, translation,
// camera_k, ...): columns 6… are fx, fy, cx, cy, or fx, cx, cy with fy held (tied to fx).
void CameraSigma(const Eigen::MatrixXd& covariance, double camera_aspect, double* camera_sigma) {
  const int fx = 6, fy = camera_aspect > 0.0 ? -1 : 7, cx = fy < 0 ? 7 : 8, cy = cx + 1;
  camera_sigma[0] = std::sqrt(covariance(fx, fx));
  camera_sigma[1] = fy < 0 ? camera_aspect * camera_sigma[0] : std::sqrt(covariance(fy, fy));
  camera_sigma[2] = std::sqrt(covariance(cx, cx));
  camera_sigma[3] = std::sqrt(covariance(cy, cy));
}

// A point fixed in the room as projector (intrinsics, tangential p1 p2, proj_from_room) shows it.
struct ProjectRoomPoint {
  ProjectRoomPoint(const Vec3& p_in_room, const double* tangential)
      : p_in_room(p_in_room), tangential{tangential[0], tangential[1]} {}
  template <typename T>
  bool operator()(const T* intrinsics, const T* rotation, const T* translation, T* pixel) const {
    const T p[3] = {T(p_in_room.x()), T(p_in_room.y()), T(p_in_room.z())};
    ProjectorPixelResidual(intrinsics, rotation, translation, p, Vec2::Zero().eval(), pixel,
                           tangential);
    return true;
  }
  Vec3 p_in_room;
  double tangential[2];
};

// Projector k alone against the model's planes as the guess puts them in the camera: the seed of
// its intrinsics and pose. False (with `failure`) when its own calibration fails.
bool SeedProjector(const RoomCalibrationOptions& options, const RoomModel& model, const RoomCalibrationProblem& problem,
                   int k, const std::vector<Correspondence>& correspondences,
                   const Eigen::Isometry3d& room_from_camera_guess, ProjectorState* projector,
                   RoomProjectorSummary* projector_summary, std::string* failure) {
  const Eigen::Isometry3d cam_from_room_guess = room_from_camera_guess.inverse();
  ProjectorCalibrationProblem seed_problem;
  seed_problem.camera_lens_model = problem.camera_lens_model;
  seed_problem.camera_intrinsics = problem.camera_intrinsics;
  seed_problem.projector_width = problem.projectors[k].width;
  seed_problem.projector_height = problem.projectors[k].height;
  for (const ModelFacet& facet : model.facets()) {
    PlaneInCam plane;
    plane.normal = cam_from_room_guess.linear() * facet.normal;
    plane.offset = facet.offset + facet.normal.dot(room_from_camera_guess.translation());
    seed_problem.planes.push_back(plane);
  }
  const ProjectorObservations& p = problem.projectors[k];
  for (const Correspondence& c : correspondences)
    if (c.facet >= 0) seed_problem.correspondences.push_back({c.camera_pixel, c.observed, c.facet});
  ProjectorCalibrationOptions seed_options;
  seed_options.refine_distortion = options.refine_distortion;
  seed_options.loss_scale = options.loss_scale;
  seed_options.outlier_threshold = options.outlier_threshold;
  seed_options.max_iterations = options.max_iterations;
  seed_options.min_correspondences = options.min_correspondences;
  ProjectorCalibration seed;
  ProjectorCalibrationSummary seed_summary;
  if (!CalibrateProjector(seed_options, seed_problem, &seed, &seed_summary)) {
    *failure = "projector '" + p.name + "': " + seed_summary.BriefReport();
    return false;
  }
  projector_summary->seed_rms = seed_summary.rms;
  for (int i = 0; i < 4; ++i) projector->intrinsics[i] = seed.intrinsics[i];
  if (seed.intrinsics.size() >= 6) {
    projector->intrinsics[4] = seed.intrinsics[4];
    projector->intrinsics[5] = seed.intrinsics[5];
  }
  projector->proj_from_room = PoseBlock(seed.proj_from_cam * cam_from_room_guess);
  const HeldProjectorLens* held = HeldLens(problem, k);
  if (!held) return true;
  // A held lens: its values replace the seed's, and the pose alone is refined against the planes
  // as the guess places them (robustly: the guess's planes are a few cm off), so that the joint
  // solve starts from a pose that fits this lens rather than the seed's own.
  projector->held = true;
  for (int i = 0; i < 6; ++i) projector->intrinsics[i] = 0.0;
  for (int i = 0; i < 4; ++i) projector->intrinsics[i] = held->intrinsics[i];
  if (held->intrinsics.size() == 8) {
    projector->intrinsics[4] = held->intrinsics[4];
    projector->intrinsics[5] = held->intrinsics[5];
    projector->tangential[0] = held->intrinsics[6];
    projector->tangential[1] = held->intrinsics[7];
  }
  PoseBlock guess(room_from_camera_guess);
  ceres::Problem pose_problem;
  for (const Correspondence& c : correspondences) {
    if (c.facet < 0) continue;
    const ModelFacet& facet = model.facets()[c.facet];
    pose_problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<RoomReprojection, 2, 3, 3, 6, 3, 3>(new RoomReprojection(
            c.ray_in_cam, facet.normal, facet.offset, c.observed, projector->tangential)),
        new ceres::CauchyLoss(options.loss_scale), guess.rotation, guess.translation,
        projector->intrinsics, projector->proj_from_room.rotation,
        projector->proj_from_room.translation);
  }
  if (pose_problem.NumResidualBlocks() == 0) return true;
  for (double* block : {guess.rotation, guess.translation, projector->intrinsics})
    pose_problem.SetParameterBlockConstant(block);
  ceres::Solver::Summary pose_summary;
  ceres::Solve(SolverOptions(options.max_iterations), &pose_problem, &pose_summary);
  if (!pose_summary.IsSolutionUsable() || !projector->proj_from_room.Finite()) {
    *failure = "projector '" + p.name + "': the pose with the held lens: " + pose_summary.message;
    return false;
  }
  return true;
}

// Correspondences of one projector on a facet (and inliers only when asked).
int CountPoints(const std::vector<Correspondence>& correspondences, bool inliers_only) {
  int n = 0;
  for (const Correspondence& c : correspondences)
    if (c.facet >= 0 && (!inliers_only || c.inlier)) ++n;
  return n;
}

// Each projector's projection uncertainty (RoomProjectorSummary::uncertainty) from the last
// solve's covariance over (camera rotation, translation, [camera fx, fy, cx, cy], per projector
// intrinsics, rotation, translation), tangent coordinates.
void ProjectorUncertainties(const RoomCalibrationOptions& options, const RoomModel& model,
                            const RoomCalibrationProblem& problem, const PoseBlock& camera,
                            const std::vector<ProjectorState>& projectors,
                            const std::vector<std::vector<Correspondence>>& correspondences,
                            const Eigen::MatrixXd& covariance, RoomCalibrationSummary* summary) {
  const int camera_free = !options.refine_camera_intrinsics ? 0
                          : options.keep_camera_aspect_ratio ? 3
                                                             : 4;
  int offset = 6 + camera_free;
  const Eigen::Isometry3d room_from_camera = camera.Pose();
  for (size_t k = 0; k < projectors.size(); ++k) {
    const ProjectorState& p = projectors[k];
    // A held lens is not in the covariance: the pose's uncertainty alone.
    const int intrinsics_free = p.held ? 0 : options.refine_distortion ? 6 : 4;
    const int block_offset = offset;
    offset += intrinsics_free + 6;
    if (block_offset + intrinsics_free + 6 > covariance.rows()) return;
    const Eigen::MatrixXd block =
        covariance.block(block_offset, block_offset, intrinsics_free + 6, intrinsics_free + 6);
    const Eigen::Isometry3d proj_from_room = p.proj_from_room.Pose();
    const Vec3 centre = proj_from_room.inverse().translation();
    std::vector<double> distances;
    for (const Correspondence& c : correspondences[k]) {
      if (c.facet < 0 || !c.inlier) continue;
      // The point where the camera ray meets its facet's plane, as the residual places it.
      const ModelFacet& facet = model.facets()[c.facet];
      const Vec3 direction = room_from_camera.linear() * c.ray_in_cam;
      const double t = -(facet.normal.dot(room_from_camera.translation()) + facet.offset) /
                       facet.normal.dot(direction);
      if (t > 0.0)
        distances.push_back((room_from_camera.translation() + t * direction - centre).norm());
    }
    if (distances.empty()) continue;
    std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
    const double distance = distances[distances.size() / 2];
    const auto worst = [&](const Vec2& pixel) {
      const Vec3 direction = Vec3((pixel.x() - p.intrinsics[2]) / p.intrinsics[0],
                                  (pixel.y() - p.intrinsics[3]) / p.intrinsics[1], 1.0)
                                 .normalized();
      const ceres::AutoDiffCostFunction<ProjectRoomPoint, 2, 6, 3, 3> project(
          new ProjectRoomPoint(proj_from_room.inverse() * (distance * direction), p.tangential));
      const double* parameters[] = {p.intrinsics, p.proj_from_room.rotation,
                                    p.proj_from_room.translation};
      Eigen::Matrix<double, 2, 6, Eigen::RowMajor> j_intrinsics;
      Eigen::Matrix<double, 2, 3, Eigen::RowMajor> j_rotation, j_translation;
      Vec2 projected;
      double* jacobians[] = {j_intrinsics.data(), j_rotation.data(), j_translation.data()};
      if (!project.Evaluate(parameters, projected.data(), jacobians))
        return std::numeric_limits<double>::quiet_NaN();
      Eigen::MatrixXd j(2, intrinsics_free + 6);
      j.leftCols(intrinsics_free) = j_intrinsics.leftCols(intrinsics_free);
      j.middleCols(intrinsics_free, 3) = j_rotation;
      j.rightCols(3) = j_translation;
      const Eigen::Matrix2d var = j * block * j.transpose();
      return std::sqrt(std::max(0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(var).eigenvalues()[1]));
    };
    RoomProjectorSummary& out = summary->projectors[k];
    out.uncertainty_distance_m = distance;
    out.uncertainty = MapProjectionUncertainty(worst, out.rms, problem.projectors[k].width,
                                               problem.projectors[k].height);
  }
}

// The solve's results: the calibration (camera pose and lens, every projector's model) and the
// per-projector residuals. False (with `failure`) where a value is not finite.
bool CollectRoomResults(const RoomCalibrationOptions& options, const RoomModel& model,
                        const RoomCalibrationProblem& problem, const PoseBlock& camera,
                        const std::vector<double>& camera_intrinsics, const std::vector<ProjectorState>& projectors,
                        const std::vector<std::vector<Correspondence>>& correspondences, RoomCalibration* calibration,
                        RoomCalibrationSummary* summary, std::string* failure) {
  const int projector_count = static_cast<int>(projectors.size());
  *calibration = RoomCalibration();
  calibration->room_from_camera = camera.Pose();
  calibration->camera_lens_model = problem.camera_lens_model;
  calibration->camera_intrinsics = camera_intrinsics;
  for (int i = 0; i < 4; ++i)
    summary->camera_intrinsics_moved[i] = camera_intrinsics[i] - problem.camera_intrinsics[i];
  for (int k = 0; k < projector_count; ++k) {
    const ProjectorState& state = projectors[k];
    RoomProjector out;
    out.name = problem.projectors[k].name;
    out.width = problem.projectors[k].width;
    out.height = problem.projectors[k].height;
    out.intrinsics.assign(state.intrinsics, state.intrinsics + 4);
    if (const HeldProjectorLens* held = HeldLens(problem, k)) {
      out.lens_model = held->lens_model;
      out.intrinsics = held->intrinsics;  // exactly as given
      out.lens_held = true;
    } else if (options.refine_distortion) {
      out.lens_model = "LENSMODEL_OPENCV4";
      out.intrinsics.insert(out.intrinsics.end(),
                            {state.intrinsics[4], state.intrinsics[5], 0.0, 0.0});
    } else {
      out.lens_model = "LENSMODEL_PINHOLE";
    }
    out.proj_from_room = state.proj_from_room.Pose();
    for (const double value : out.intrinsics)
      if (!std::isfinite(value)) {
        *failure = "NaN";
        return false;
      }
    if (!state.proj_from_room.Finite()) {
      *failure = "non-finite pose";
      return false;
    }
    calibration->projectors.push_back(out);

    RoomProjectorSummary& s = summary->projectors[k];
    s.points = CountPoints(correspondences[k], false);
    s.outliers = s.points - CountPoints(correspondences[k], true);
    double sq = 0.0;
    int n = 0;
    for (const Correspondence& c : correspondences[k]) {
      if (c.facet < 0 || !c.inlier) continue;
      const double norm = Residual(c, model.facets()[c.facet], camera, state).norm();
      sq += norm * norm;
      ++n;
      s.max_norm = std::max(s.max_norm, norm);
    }
    s.rms = n ? std::sqrt(sq / (2.0 * n)) : 0.0;
  }
  return true;
}

}  // namespace

bool CalibrateRoom(const RoomCalibrationOptions& options, const RoomModel& model,
                   const RoomCalibrationProblem& problem,
                   const Eigen::Isometry3d& room_from_camera_guess, RoomCalibration* calibration,
                   RoomCalibrationSummary* summary) {
  const auto start = Clock::now();
  CheckRoomProblem(options, problem);
  const int projector_count = static_cast<int>(problem.projectors.size());
  *summary = RoomCalibrationSummary();
  summary->projectors.resize(projector_count);
  auto finish = [&](RoomCalibrationSummary::Termination termination, std::string message) {
    summary->termination = termination;
    if (!message.empty())
      summary->message = summary->message.empty() ? message : summary->message + "; " + message;
    summary->time_s =
        SecondsSince(start);
    return termination == RoomCalibrationSummary::kConverged ||
           termination == RoomCalibrationSummary::kNotSettled;
  };

  // The camera's lens: fx, fy, cx, cy (free with refine_camera_intrinsics) and the distortion
  // (always fixed).
  std::vector<double> camera_intrinsics = problem.camera_intrinsics;
  double camera_k[4] = {camera_intrinsics[0], camera_intrinsics[1], camera_intrinsics[2],
                        camera_intrinsics[3]};
  const bool camera_distorted = camera_intrinsics.size() == 8;
  double camera_distortion[4] = {0, 0, 0, 0};
  if (camera_distorted)
    for (int i = 0; i < 4; ++i) camera_distortion[i] = camera_intrinsics[4 + i];
  const double camera_aspect =
      options.keep_camera_aspect_ratio ? camera_intrinsics[1] / camera_intrinsics[0] : 0.0;

  // Camera rays at the problem's lens; re-computed after every solve when the lens is refined.
  std::vector<std::vector<Correspondence>> correspondences = SampleCorrespondences(options, problem, summary);
  PoseBlock camera(room_from_camera_guess);
  Associate(model, camera, &correspondences);

  // Seed: each projector alone against the model's planes as the guess puts them in the camera.
  std::vector<ProjectorState> projectors(projector_count);
  for (int k = 0; k < projector_count; ++k) {
    std::string failure;
    if (!SeedProjector(options, model, problem, k, correspondences[k], room_from_camera_guess, &projectors[k],
                       &summary->projectors[k], &failure)) {
      return finish(RoomCalibrationSummary::kSeedFailed, failure);
    }
  }

  // With the camera's lens refined: the rays at the current fx, fy, cx, cy (a ray whose
  // unprojection fails keeps its last one; the facets are re-chosen after this).
  auto update_rays = [&]() {
    if (camera_aspect > 0.0) camera_k[1] = camera_aspect * camera_k[0];
    for (int i = 0; i < 4; ++i) camera_intrinsics[i] = camera_k[i];
    for (std::vector<Correspondence>& list : correspondences)
      for (Correspondence& c : list) {
        Vec3 ray;
        if (UnprojectCameraPixel(problem.camera_lens_model, camera_intrinsics, c.camera_pixel,
                                 &ray))
          c.ray_in_cam = ray;
      }
  };
  // Joint solves: robust until the facets settle, then least squares on the inliers.
  Eigen::MatrixXd covariance;  // of the last least-squares solve (ParameterCovariance)
  bool covariance_ok = false;
  auto solve = [&](bool robust, ceres::Solver::Summary* ceres_summary) {
    ceres::Problem ceres_problem;
    std::vector<double*> blocks = {camera.rotation, camera.translation, camera_k};
    for (int k = 0; k < projector_count; ++k) {
      ProjectorState& state = projectors[k];
      for (const Correspondence& c : correspondences[k]) {
        if (c.facet < 0 || (!robust && !c.inlier)) continue;
        const ModelFacet& facet = model.facets()[c.facet];
        ceres::LossFunction* loss = robust ? new ceres::CauchyLoss(options.loss_scale) : nullptr;
        if (options.refine_camera_intrinsics)
          ceres_problem.AddResidualBlock(
              new ceres::AutoDiffCostFunction<RoomReprojectionFreeCamera, 2, 3, 3, 4, 6, 3, 3>(
                  new RoomReprojectionFreeCamera(c.camera_pixel, c.ray_in_cam, camera_distortion,
                                                 camera_distorted, camera_aspect, facet.normal,
                                                 facet.offset, c.observed, state.tangential)),
              loss, camera.rotation, camera.translation, camera_k, state.intrinsics,
              state.proj_from_room.rotation, state.proj_from_room.translation);
        else
          ceres_problem.AddResidualBlock(
              new ceres::AutoDiffCostFunction<RoomReprojection, 2, 3, 3, 6, 3, 3>(
                  new RoomReprojection(c.ray_in_cam, facet.normal, facet.offset, c.observed,
                                       state.tangential)),
              loss, camera.rotation, camera.translation, state.intrinsics,
              state.proj_from_room.rotation, state.proj_from_room.translation);
      }
      if (!ceres_problem.HasParameterBlock(state.intrinsics)) continue;
      if (state.held) {
        // Its lens is given: constant, and out of the covariance (a zero column would read as a
        // direction the solve cannot see).
        ceres_problem.SetParameterBlockConstant(state.intrinsics);
        blocks.insert(blocks.end(),
                      {state.proj_from_room.rotation, state.proj_from_room.translation});
        continue;
      }
      if (!options.refine_distortion)
        ceres_problem.SetManifold(state.intrinsics, new ceres::SubsetManifold(6, {4, 5}));
      blocks.insert(blocks.end(), {state.intrinsics, state.proj_from_room.rotation,
                                   state.proj_from_room.translation});
    }
    if (camera_aspect > 0.0 && ceres_problem.HasParameterBlock(camera_k))
      ceres_problem.SetManifold(camera_k, new ceres::SubsetManifold(4, {1}));
    ceres::Solve(SolverOptions(options.max_iterations), &ceres_problem, ceres_summary);
    if (summary->rounds == 0) summary->initial_cost = ceres_summary->initial_cost;
    summary->final_cost = ceres_summary->final_cost;
    ++summary->rounds;
    bool usable = ceres_summary->IsSolutionUsable() && camera.Finite();
    for (const double value : camera_k) usable = usable && std::isfinite(value) && value != 0.0;
    if (usable && !robust) {
      // What the solve is sure of: the covariance over the blocks it has (the camera's lens
      // only when refined), kept for the projectors' uncertainty after the last solve.
      std::vector<double*> present;
      for (double* block : blocks)
        if (ceres_problem.HasParameterBlock(block)) present.push_back(block);
      covariance_ok =
          ParameterCovariance(ceres_problem, present, ceres_summary->final_cost, &covariance);
      if (options.refine_camera_intrinsics) {
        std::fill(summary->camera_sigma, summary->camera_sigma + 4,
                  std::numeric_limits<double>::quiet_NaN());
        if (covariance_ok) CameraSigma(covariance, camera_aspect, summary->camera_sigma);
      }
    }
    if (usable && options.refine_camera_intrinsics) update_rays();
    return usable;
  };
  auto check_counts = [&](bool inliers_only) {
    for (int k = 0; k < projector_count; ++k)
      if (CountPoints(correspondences[k], inliers_only) < options.min_correspondences) return k;
    return -1;
  };

  ceres::Solver::Summary ceres_summary;
  bool settled = false;
  for (int round = 0; round < options.max_rounds && !settled; ++round) {
    const int short_of = check_counts(false);
    if (short_of >= 0)
      return finish(RoomCalibrationSummary::kTooFewPoints,
                    "projector '" + problem.projectors[short_of].name + "'");
    if (!solve(true, &ceres_summary))
      return finish(RoomCalibrationSummary::kSolverFailed, ceres_summary.message);
    settled = Associate(model, camera, &correspondences) == 0;
  }
  // Inliers of the robust fit, then least squares on them; re-associate and repeat while any
  // facet changes (a point near an edge can cross it as the camera moves).
  bool changed = true;
  for (int round = 0; round < options.max_rounds && changed; ++round) {
    for (int k = 0; k < projector_count; ++k)
      for (Correspondence& c : correspondences[k])
        c.inlier = c.facet >= 0 &&
                   Residual(c, model.facets()[c.facet], camera, projectors[k]).norm() <=
                       options.outlier_threshold;
    const int short_of = check_counts(true);
    if (short_of >= 0)
      return finish(RoomCalibrationSummary::kTooFewPoints,
                    "too few inliers for projector '" + problem.projectors[short_of].name + "'");
    if (!solve(false, &ceres_summary))
      return finish(RoomCalibrationSummary::kSolverFailed, ceres_summary.message);
    changed = Associate(model, camera, &correspondences) > 0;
  }
  settled = settled && !changed;

  std::string failure;
  if (!CollectRoomResults(options, model, problem, camera, camera_intrinsics, projectors, correspondences,
                          calibration, summary, &failure)) {
    return finish(RoomCalibrationSummary::kSolverFailed, failure);
  }
  if (covariance_ok)
    ProjectorUncertainties(options, model, problem, camera, projectors, correspondences, covariance,
                           summary);
  summary->camera_moved_mm =
      1e3 * (calibration->room_from_camera.translation() - room_from_camera_guess.translation())
                .norm();
  summary->camera_turned_deg =
      TurnDeg(calibration->room_from_camera.linear(), room_from_camera_guess.linear());
  return finish(settled ? RoomCalibrationSummary::kConverged : RoomCalibrationSummary::kNotSettled,
                ceres_summary.message);
}

// ---------------------------------------------------------------------------------------------
// Triangulation

namespace {

// The camera's lens a triangulation uses: `calibration`'s when it holds one (CalibrateRoom and
// SelfCalibrateRoom fill it), else the problem's.
struct CameraLens {
  const std::string& model;
  const std::vector<double>& intrinsics;
};
CameraLens CameraLensOf(const RoomCalibrationProblem& problem, const RoomCalibration& calibration) {
  if (calibration.camera_intrinsics.empty())
    return {problem.camera_lens_model, problem.camera_intrinsics};
  return {calibration.camera_lens_model, calibration.camera_intrinsics};
}

}  // namespace

std::vector<TriangulatedPoint> Triangulate(const RoomCalibrationProblem& problem,
                                           const RoomCalibration& calibration, double max_gap) {
  const CameraLens camera = CameraLensOf(problem, calibration);
  std::vector<TriangulatedPoint> points;
  for (size_t k = 0; k < problem.projectors.size() && k < calibration.projectors.size(); ++k) {
    const RoomProjector& projector = calibration.projectors[k];
    const Eigen::Isometry3d cam_from_proj =
        (projector.proj_from_room * calibration.room_from_camera).inverse();
    const Vec3 centre = cam_from_proj.translation();
    const ProjectorObservations& p = problem.projectors[k];
    for (size_t i = 0; i < p.camera_pixels.size(); ++i) {
      Vec3 ray_cam, ray_proj;
      if (!p.camera_pixels[i].allFinite() || !p.projector_pixels[i].allFinite() ||
          !UnprojectCameraPixel(camera.model, camera.intrinsics, p.camera_pixels[i],
                                &ray_cam) ||
          !UnprojectCameraPixel(projector.lens_model, projector.intrinsics,
                                p.projector_pixels[i], &ray_proj))
        continue;
      // Closest points of x = a·d1 and x = c + b·d2.
      const Vec3 d1 = ray_cam.normalized();
      const Vec3 d2 = (cam_from_proj.linear() * ray_proj).normalized();
      const double d12 = d1.dot(d2);
      const double denominator = 1.0 - d12 * d12;
      if (denominator < 1e-12) continue;
      const double e1 = d1.dot(centre), e2 = d2.dot(centre);
      const double a = (e1 - d12 * e2) / denominator;
      const double b = (d12 * e1 - e2) / denominator;
      if (!(a > 0.0) || !(b > 0.0)) continue;
      const Vec3 on_camera_ray = a * d1, on_projector_ray = centre + b * d2;
      TriangulatedPoint point;
      point.p_in_cam = 0.5 * (on_camera_ray + on_projector_ray);
      point.gap = (on_camera_ray - on_projector_ray).norm();
      point.projector = static_cast<int>(k);
      point.camera_pixel = p.camera_pixels[i];
      point.on_camera_ray = on_camera_ray;
      if (point.gap <= max_gap && point.p_in_cam.allFinite()) points.push_back(point);
    }
  }
  return points;
}

std::vector<TriangulatedPoint> TriangulateOneAxis(const RoomCalibrationProblem& problem,
                                                  const RoomCalibration& calibration,
                                                  double max_depth_per_pixel) {
  const CameraLens camera = CameraLensOf(problem, calibration);
  // Depths along the unit camera ray at which the search brackets the coordinate, metres: a
  // geometric ladder fine enough that a coordinate reached twice shows as two brackets.
  constexpr double kNear = 0.1, kFar = 100.0;
  constexpr int kLadder = 200;
  std::vector<double> ladder(kLadder);
  for (int i = 0; i < kLadder; ++i) ladder[i] = kNear * std::pow(kFar / kNear, i / (kLadder - 1.0));
  std::vector<TriangulatedPoint> points;
  for (size_t k = 0; k < problem.projectors.size() && k < calibration.projectors.size(); ++k) {
    const RoomProjector& projector = calibration.projectors[k];
    const LensModel lens(projector.lens_model, projector.intrinsics);
    const Eigen::Isometry3d proj_from_cam = projector.proj_from_room * calibration.room_from_camera;
    const ProjectorObservations& p = problem.projectors[k];
    for (size_t i = 0; i < p.one_axis_camera_pixels.size(); ++i) {
      const Vec2& decoded = p.one_axis_projector_pixels[i];
      const int axis = std::isfinite(decoded.x()) ? 0 : 1;
      Vec3 ray_cam;
      if (!std::isfinite(decoded[axis]) || !p.one_axis_camera_pixels[i].allFinite() ||
          !UnprojectCameraPixel(camera.model, camera.intrinsics, p.one_axis_camera_pixels[i],
                                &ray_cam))
        continue;
      const Vec3 d = ray_cam.normalized();
      const Vec3 direction = proj_from_cam.linear() * d;
      // The decoded coordinate minus the projected one at depth t (NaN behind the projector),
      // and its derivative.
      const auto residual = [&](double t, double* derivative, Vec2* pixel) {
        const Vec3 q = proj_from_cam * Vec3(t * d);
        if (!(q.z() > 0.0)) return std::numeric_limits<double>::quiet_NaN();
        ProjectionJacobian dq_dp;
        *pixel = lens.Project(q, &dq_dp);
        if (derivative) *derivative = dq_dp.row(axis).dot(direction);
        return (*pixel)[axis] - decoded[axis];
      };
      // Bracket the root on the ladder; more than one bracket: ambiguous, left out.
      int brackets = 0;
      double low = 0.0, high = 0.0;
      double previous = std::numeric_limits<double>::quiet_NaN();
      Vec2 pixel;
      for (int j = 0; j < kLadder; ++j) {
        const double value = residual(ladder[j], nullptr, &pixel);
        if (std::isfinite(previous) && std::isfinite(value) && (previous < 0.0) != (value < 0.0)) {
          ++brackets;
          low = ladder[j - 1];
          high = ladder[j];
        }
        previous = value;
      }
      if (brackets != 1) continue;
      // Newton steps kept inside the bracket (bisection where a step leaves it).
      const double sign_low = residual(low, nullptr, &pixel) < 0.0 ? -1.0 : 1.0;
      double t = 0.5 * (low + high), slope = 0.0;
      for (int iteration = 0; iteration < 60; ++iteration) {
        const double value = residual(t, &slope, &pixel);
        if (!std::isfinite(value)) break;
        if ((value < 0.0 ? -1.0 : 1.0) == sign_low) low = t; else high = t;
        double next = slope != 0.0 ? t - value / slope : 0.5 * (low + high);
        if (!(next > low && next < high)) next = 0.5 * (low + high);
        const bool settled = std::abs(next - t) < 1e-9;
        t = next;
        if (settled) break;
      }
      const double value = residual(t, &slope, &pixel);
      const double depth_per_pixel = 1.0 / std::abs(slope);
      const int other = 1 - axis;
      const double other_size = other == 0 ? p.width : p.height;
      if (!(std::abs(value) < 1e-3) || !(depth_per_pixel <= max_depth_per_pixel) ||
          !(pixel[other] >= -0.5 && pixel[other] <= other_size - 0.5))
        continue;
      TriangulatedPoint point;
      point.p_in_cam = t * d;
      point.on_camera_ray = point.p_in_cam;
      point.gap = depth_per_pixel;
      point.projector = static_cast<int>(k);
      point.camera_pixel = p.one_axis_camera_pixels[i];
      point.one_axis = true;
      points.push_back(point);
    }
  }
  return points;
}

std::vector<TriangulatedPoint> KeepPixelLattice(const std::vector<TriangulatedPoint>& points,
                                                size_t max_points, int* lattice) {
  const double ratio = static_cast<double>(points.size()) / std::max<size_t>(max_points, 1);
  const int s = points.size() <= max_points ? 1 : static_cast<int>(std::ceil(std::sqrt(ratio) - 1e-9));
  if (lattice) *lattice = s;
  if (s == 1) return points;
  std::vector<TriangulatedPoint> kept;
  for (const TriangulatedPoint& p : points)
    if (std::lround(p.camera_pixel.x()) % s == 0 && std::lround(p.camera_pixel.y()) % s == 0)
      kept.push_back(p);
  return kept;
}

// A one-axis point (FusePerCameraPixel) is kept only when its depth lies within this fraction
// beyond the range of the two-axis points at most kOneAxisWindow pixels from it.
constexpr int kOneAxisWindow = 8;
constexpr double kOneAxisDepthMargin = 0.1;

std::vector<TriangulatedPoint> FusePerCameraPixel(const std::vector<TriangulatedPoint>& points,
                                                  double max_spread) {
  // Grouped by pixel: indices sorted by pixel, row-major.
  std::vector<int> order(points.size());
  std::iota(order.begin(), order.end(), 0);
  const auto before = [&](int a, int b) {
    const Vec2& p = points[a].camera_pixel;
    const Vec2& q = points[b].camera_pixel;
    return p.y() < q.y() || (p.y() == q.y() && p.x() < q.x());
  };
  std::stable_sort(order.begin(), order.end(), before);
  std::vector<TriangulatedPoint> fused;
  std::vector<int> group;
  std::vector<double> depths;
  for (size_t begin = 0; begin < order.size();) {
    size_t end = begin + 1;
    while (end < order.size() && points[order[end]].camera_pixel == points[order[begin]].camera_pixel)
      ++end;
    // The pixel's two-axis points, or its one-axis points where it has none.
    bool two_axis = false;
    for (size_t i = begin; i < end; ++i) two_axis |= !points[order[i]].one_axis;
    group.clear();
    depths.clear();
    for (size_t i = begin; i < end; ++i) {
      if (two_axis && points[order[i]].one_axis) continue;
      group.push_back(order[i]);
      depths.push_back(points[order[i]].on_camera_ray.norm());
    }
    std::sort(depths.begin(), depths.end());
    const size_t n = depths.size();
    const double median = n % 2 == 1 ? depths[n / 2] : 0.5 * (depths[n / 2 - 1] + depths[n / 2]);
    TriangulatedPoint out;
    out.camera_pixel = points[order[begin]].camera_pixel;
    out.one_axis = !two_axis;
    for (const int i : group) {
      if (std::abs(points[i].on_camera_ray.norm() - median) > max_spread) continue;
      out.on_camera_ray += points[i].on_camera_ray;
      out.gap = std::max(out.gap, points[i].gap);
      ++out.projector;
    }
    if (out.projector > 0) {
      out.on_camera_ray /= out.projector;
      out.p_in_cam = out.on_camera_ray;
      fused.push_back(out);
    }
    begin = end;
  }
  // A one-axis point's depth within the range of the two-axis points around it.
  std::unordered_map<long long, double> two_axis_depth;
  const auto key = [](const Vec2& pixel) {
    return (static_cast<long long>(std::lround(pixel.y())) << 32) + std::lround(pixel.x());
  };
  for (const TriangulatedPoint& p : fused)
    if (!p.one_axis) two_axis_depth[key(p.camera_pixel)] = p.on_camera_ray.norm();
  std::vector<TriangulatedPoint> kept;
  kept.reserve(fused.size());
  for (const TriangulatedPoint& p : fused) {
    if (p.one_axis) {
      double low = std::numeric_limits<double>::infinity(), high = 0.0;
      for (int dy = -kOneAxisWindow; dy <= kOneAxisWindow; ++dy)
        for (int dx = -kOneAxisWindow; dx <= kOneAxisWindow; ++dx) {
          const auto found = two_axis_depth.find(key(p.camera_pixel + Vec2(dx, dy)));
          if (found == two_axis_depth.end()) continue;
          low = std::min(low, found->second);
          high = std::max(high, found->second);
        }
      const double depth = p.on_camera_ray.norm();
      if (!(depth >= (1.0 - kOneAxisDepthMargin) * low && depth <= (1.0 + kOneAxisDepthMargin) * high))
        continue;
    }
    kept.push_back(p);
  }
  return kept;
}

std::vector<TriangulatedPoint> TriangulateScan(const RoomCalibrationProblem& problem,
                                               const RoomCalibration& calibration, double max_gap,
                                               std::vector<double>* gaps) {
  std::vector<TriangulatedPoint> points = Triangulate(problem, calibration, max_gap);
  if (gaps) {
    gaps->clear();
    for (const TriangulatedPoint& p : points) gaps->push_back(p.gap);
  }
  const std::vector<TriangulatedPoint> one_axis = TriangulateOneAxis(problem, calibration);
  points.insert(points.end(), one_axis.begin(), one_axis.end());
  return FusePerCameraPixel(points);
}

// ---------------------------------------------------------------------------------------------
// Registration

DistanceStats ComputeDistanceStats(std::vector<double> distances_m) {
  DistanceStats stats;
  stats.points = static_cast<int>(distances_m.size());
  if (distances_m.empty()) return stats;
  std::sort(distances_m.begin(), distances_m.end());
  double sq = 0.0;
  for (const double d : distances_m) sq += d * d;
  const size_t n = distances_m.size();
  stats.rms_mm = 1e3 * std::sqrt(sq / n);
  stats.median_mm = 1e3 * distances_m[n / 2];
  stats.p95_mm = 1e3 * distances_m[std::min(n - 1, static_cast<size_t>(0.95 * n))];
  stats.max_mm = 1e3 * distances_m.back();
  return stats;
}

bool RegistrationOptions::Check(std::string* why) const {
  auto fail = [why](const char* message) {
    if (why) *why = message;
    return false;
  };
  for (const double value : {initial_gate, min_gate, huber_scale, inlier_distance, tolerance})
    if (!(value > 0.0) || !std::isfinite(value))
      return fail("gates, huber_scale, inlier_distance and tolerance must be > 0");
  if (max_points < 10) return fail("max_points must be at least 10");
  if (max_iterations < 1) return fail("max_iterations must be at least 1");
  return true;
}

std::string RegistrationSummary::BriefReport() const {
  static const char* const kNames[] = {"converged", "max iterations", "too few points",
                                       "solver failed"};
  char line[400];
  std::snprintf(line, sizeof(line),
                "Registration (ICP): %s after %d iterations; %d points, %.1f%% inliers; distance "
                "to the model over inliers: RMS %.2f mm, median %.2f mm, 95%% %.2f mm (at the "
                "guess: RMS %.1f mm); %.2f s",
                kNames[termination], iterations, points, 100.0 * inlier_fraction, inliers.rms_mm,
                inliers.median_mm, inliers.p95_mm, initial_rms_mm, time_s);
  return line;
}

namespace {

struct PointToPlane {
  PointToPlane(const Vec3& p_in_cam, const Vec3& normal, double offset)
      : p_in_cam(p_in_cam), normal(normal), offset(offset) {}
  template <typename T>
  bool operator()(const T* rotation, const T* translation, T* residual) const {
    const T p[3] = {T(p_in_cam.x()), T(p_in_cam.y()), T(p_in_cam.z())};
    T q[3];
    ceres::AngleAxisRotatePoint(rotation, p, q);
    residual[0] = T(offset);
    for (int i = 0; i < 3; ++i) residual[0] += T(normal(i)) * (q[i] + translation[i]);
    return true;
  }
  Vec3 p_in_cam, normal;
  double offset;
};

}  // namespace

bool RegisterModelToCloud(const RegistrationOptions& options, const RoomModel& model,
                          const std::vector<Vec3>& points_in_cam,
                          const Eigen::Isometry3d& guess, Eigen::Isometry3d* room_from_camera,
                          RegistrationSummary* summary) {
  const auto start = Clock::now();
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("RegistrationOptions: " + why);
  *summary = RegistrationSummary();
  *room_from_camera = guess;
  auto finish = [&](RegistrationSummary::Termination termination) {
    summary->termination = termination;
    summary->time_s =
        SecondsSince(start);
    return termination == RegistrationSummary::kConverged ||
           termination == RegistrationSummary::kMaxIterations;
  };
  // Thin evenly.
  std::vector<Vec3> points;
  const size_t stride =
      std::max<size_t>(1, (points_in_cam.size() + options.max_points - 1) / options.max_points);
  for (size_t i = 0; i < points_in_cam.size(); i += stride) points.push_back(points_in_cam[i]);
  summary->points = static_cast<int>(points.size());

  PoseBlock pose(guess);
  double gate = options.initial_gate;
  auto termination = RegistrationSummary::kMaxIterations;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    const Eigen::Isometry3d current = pose.Pose();
    std::vector<int> facets(points.size());
    std::vector<double> distances(points.size());
    for (size_t i = 0; i < points.size(); ++i)
      facets[i] = model.Closest(current * points[i], nullptr, &distances[i]);
    std::vector<double> matched;
    for (size_t i = 0; i < points.size(); ++i)
      if (facets[i] >= 0 && distances[i] <= gate) matched.push_back(distances[i]);
    if (matched.size() < 6) return finish(RegistrationSummary::kTooFewPoints);
    if (iteration == 0) summary->initial_rms_mm = ComputeDistanceStats(matched).rms_mm;

    ceres::Problem problem;
    for (size_t i = 0; i < points.size(); ++i) {
      if (facets[i] < 0 || distances[i] > gate) continue;
      const ModelFacet& facet = model.facets()[facets[i]];
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PointToPlane, 1, 3, 3>(
                                   new PointToPlane(points[i], facet.normal, facet.offset)),
                               new ceres::HuberLoss(options.huber_scale), pose.rotation,
                               pose.translation);
    }
    ceres::Solver::Options solver_options = SolverOptions(50);
    solver_options.linear_solver_type = ceres::DENSE_QR;
    ceres::Solver::Summary ceres_summary;
    ceres::Solve(solver_options, &problem, &ceres_summary);
    if (!ceres_summary.IsSolutionUsable() || !pose.Finite())
      return finish(RegistrationSummary::kSolverFailed);
    summary->iterations = iteration + 1;

    // The gate shrinks to a robust multiple of the typical distance.
    std::nth_element(matched.begin(), matched.begin() + matched.size() / 2, matched.end());
    const double previous_gate = gate;
    gate = std::max(options.min_gate, std::min(gate, 3.0 * 1.4826 * matched[matched.size() / 2]));
    const Eigen::Isometry3d moved = pose.Pose();
    const double step = (moved.translation() - current.translation()).norm() +
                        TurnDeg(moved.linear(), current.linear()) * std::numbers::pi / 180.0;
    if (step < options.tolerance && gate > 0.99 * previous_gate) {
      termination = RegistrationSummary::kConverged;
      break;
    }
  }
  *room_from_camera = pose.Pose();

  std::vector<double> all, inliers;
  std::vector<std::vector<double>> per_surface(model.scene().surfaces.size());
  for (const Vec3& p : points) {
    double distance = 0.0;
    const int facet = model.Closest(*room_from_camera * p, nullptr, &distance);
    if (facet < 0) continue;
    all.push_back(distance);
    if (distance <= options.inlier_distance) {
      inliers.push_back(distance);
      per_surface[model.facets()[facet].surface].push_back(distance);
    }
  }
  summary->all = ComputeDistanceStats(all);
  summary->inliers = ComputeDistanceStats(inliers);
  summary->inlier_fraction = all.empty() ? 0.0 : static_cast<double>(inliers.size()) / all.size();
  for (std::vector<double>& d : per_surface) summary->per_surface.push_back(ComputeDistanceStats(d));
  return finish(termination);
}

// ---------------------------------------------------------------------------------------------
// Planes by RANSAC

bool PlaneFitOptions::Check(std::string* why) const {
  auto fail = [why](const char* message) {
    if (why) *why = message;
    return false;
  };
  if (!(distance > 0.0) || !std::isfinite(distance)) return fail("distance must be > 0");
  if (min_inliers < 3) return fail("min_inliers must be at least 3");
  if (!(min_fraction >= 0.0 && min_fraction < 1.0)) return fail("min_fraction must be in [0, 1)");
  if (max_planes < 1) return fail("max_planes must be at least 1");
  if (iterations < 1) return fail("iterations must be at least 1");
  return true;
}

std::vector<FittedPlane> FitPlanes(const PlaneFitOptions& options, const std::vector<Vec3>& points) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("PlaneFitOptions: " + why);
  std::vector<FittedPlane> planes;
  std::vector<int> remaining(points.size());
  std::iota(remaining.begin(), remaining.end(), 0);
  std::mt19937 random(options.seed);
  const int min_inliers = std::max(
      options.min_inliers, static_cast<int>(std::ceil(options.min_fraction * points.size())));
  while (static_cast<int>(planes.size()) < options.max_planes &&
         static_cast<int>(remaining.size()) >= min_inliers) {
    std::uniform_int_distribution<size_t> pick(0, remaining.size() - 1);
    Vec3 best_normal = Vec3::UnitZ();
    double best_offset = 0.0;
    int best_count = 0;
    for (int iteration = 0; iteration < options.iterations; ++iteration) {
      const Vec3& a = points[remaining[pick(random)]];
      const Vec3& b = points[remaining[pick(random)]];
      const Vec3& c = points[remaining[pick(random)]];
      const Vec3 cross = (b - a).cross(c - a);
      if (cross.norm() < 1e-9) continue;
      const Vec3 normal = cross.normalized();
      const double offset = -normal.dot(a);
      int count = 0;
      for (const int i : remaining)
        if (std::abs(normal.dot(points[i]) + offset) <= options.distance) ++count;
      if (count > best_count) {
        best_count = count;
        best_normal = normal;
        best_offset = offset;
      }
    }
    if (best_count < min_inliers) break;
    // Least squares on the inliers (twice: the refit plane may take in a few more).
    std::vector<int> inliers;
    FittedPlane plane;
    for (int pass = 0; pass < 2; ++pass) {
      inliers.clear();
      for (const int i : remaining)
        if (std::abs(best_normal.dot(points[i]) + best_offset) <= options.distance)
          inliers.push_back(i);
      Vec3 centroid = Vec3::Zero();
      for (const int i : inliers) centroid += points[i];
      centroid /= static_cast<double>(inliers.size());
      Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
      for (const int i : inliers)
        covariance += (points[i] - centroid) * (points[i] - centroid).transpose();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(covariance);
      best_normal = eigen.eigenvectors().col(0);
      best_offset = -best_normal.dot(centroid);
      plane.centroid = centroid;
      // Extent along the two in-plane principal axes.
      const Vec3 u = eigen.eigenvectors().col(2), v = eigen.eigenvectors().col(1);
      double u_min = 1e30, u_max = -1e30, v_min = 1e30, v_max = -1e30;
      for (const int i : inliers) {
        const Vec3 d = points[i] - centroid;
        u_min = std::min(u_min, d.dot(u));
        u_max = std::max(u_max, d.dot(u));
        v_min = std::min(v_min, d.dot(v));
        v_max = std::max(v_max, d.dot(v));
      }
      plane.extent = Vec2(u_max - u_min, v_max - v_min);
    }
    if (best_offset < 0.0) {  // normal towards the cloud's origin (the camera)
      best_normal = -best_normal;
      best_offset = -best_offset;
    }
    plane.normal = best_normal;
    plane.offset = best_offset;
    plane.inliers = static_cast<int>(inliers.size());
    double sq = 0.0;
    for (const int i : inliers) sq += std::pow(best_normal.dot(points[i]) + best_offset, 2);
    plane.rms_mm = 1e3 * std::sqrt(sq / std::max<size_t>(1, inliers.size()));
    if (plane.inliers < min_inliers) break;
    planes.push_back(plane);
    std::vector<int> rest;
    std::vector<char> taken(points.size(), 0);
    for (const int i : inliers) taken[i] = 1;
    for (const int i : remaining)
      if (!taken[i]) rest.push_back(i);
    remaining.swap(rest);
  }
  return planes;
}

ProjectorObservations ObservationsFromMap(const StructuredLightMap& map, std::string name, int width, int height) {
  ProjectorObservations out;
  out.name = std::move(name);
  out.width = width;
  out.height = height;
  for (int row = 0; row < map.mask.rows; ++row) {
    for (int col = 0; col < map.mask.cols; ++col) {
      const Vec2 decoded(map.column.at<float>(row, col), map.row.at<float>(row, col));
      if (map.mask.at<uint8_t>(row, col)) {
        out.camera_pixels.push_back(Vec2(col, row));
        out.projector_pixels.push_back(decoded);
      } else if (std::isfinite(decoded.x()) != std::isfinite(decoded.y())) {
        // One axis passes its tests by chance where the projector lights a pixel only through
        // bounces (bits of random sign but enough contrast), both axes rarely: a one-axis
        // coordinate is kept only where enough of its 8 neighbours decoded that axis close by.
        constexpr int kMinAgreeing = 3;
        constexpr float kAgreePixels = 3.0f;
        const cv::Mat& axis = std::isfinite(decoded.x()) ? map.column : map.row;
        const float value = axis.at<float>(row, col);
        int agreeing = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int y = row + dy, x = col + dx;
            if ((dx || dy) && y >= 0 && y < axis.rows && x >= 0 && x < axis.cols)
              agreeing += std::abs(axis.at<float>(y, x) - value) <= kAgreePixels;  // NaN: false
          }
        if (agreeing < kMinAgreeing) continue;
        out.one_axis_camera_pixels.push_back(Vec2(col, row));
        out.one_axis_projector_pixels.push_back(decoded);
      }
    }
  }
  return out;
}

}  // namespace procam
