#include "calibration/self_calibration.h"

#include <ceres/ceres.h>
#include <ceres/normal_prior.h>
#include <ceres/rotation.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <stdexcept>
#include <unordered_map>

#include "calibration/pose_math.h"

namespace procam {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A thinned camera pixel: the 3D point z · ray of the camera frame that every projector lighting
// it sees.
struct Track {
  Vec2 camera_pixel = Vec2::Zero();
  Vec3 ray = Vec3::UnitZ();  // undistorted normalised coordinate, z = 1
  double depth = 0.0;        // z in the camera frame; 0 until seeded
};

struct Observation {
  int track = 0;
  Vec2 projector_pixel = Vec2::Zero();
};

// A projector's state through the steps: its thinned observations, its seed (in its own unit of
// length) and the parameters the bundle adjustment refines.
struct ProjectorState {
  std::vector<Observation> observations;
  std::vector<double> seed_depth;       // per observation, 0 when not a seed inlier
  double intrinsics[4] = {0, 0, 0, 0};  // fx, fy, cx, cy
  double rotation[3] = {0, 0, 0};       // proj_from_cam, angle-axis
  double translation[3] = {0, 0, 0};
  std::vector<bool> inlier;  // per observation, after the robust pass
  bool principal_point_held = false;
  // Its lens held (the problem's held_projector_lenses): `intrinsics` are the held lens's fx, fy,
  // cx, cy and constant, and the observations' projector pixels are the decoded ones undistorted
  // through the held lens (fx·x + cx, fy·y + cy of the undistorted normalised point), so that
  // the pinhole residual is exact for it.
  bool lens_held = false;
};

// Whether fy is tied to fx in projector p's residual: square_pixels, unless its lens is held
// (fx and fy then as given).
bool TiedFocal(const SelfCalibrationOptions& options, const ProjectorState& p) {
  return options.square_pixels && !p.lens_held;
}

// Projector k's held lens, or null when the self-calibration solves its lens.
const HeldProjectorLens* HeldLens(const RoomCalibrationProblem& problem, size_t k) {
  if (k >= problem.held_projector_lenses.size() ||
      problem.held_projector_lenses[k].lens_model.empty())
    return nullptr;
  return &problem.held_projector_lenses[k];
}

std::int64_t PixelKey(int col, int row) {
  return (static_cast<std::int64_t>(row) << 32) ^ static_cast<std::uint32_t>(col);
}

// A number for a message: %g, 4 significant digits.
std::string Number(double value) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.4g", value);
  return text;
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t middle = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + middle, values.end());
  return values[middle];
}

// Step 1: per projector, in every stride × stride cell of the camera image, the correspondence of
// the smallest camera pixel (row-major); the same pixel is then chosen by every projector that
// lights the whole cell, and is one track.
void Thin(const RoomCalibrationProblem& problem, int stride, std::vector<Track>* tracks,
          std::vector<ProjectorState>* projectors) {
  std::unordered_map<std::int64_t, int> track_of_pixel;
  tracks->clear();
  projectors->assign(problem.projectors.size(), ProjectorState());
  for (size_t k = 0; k < problem.projectors.size(); ++k) {
    const ProjectorObservations& given = problem.projectors[k];
    std::unordered_map<std::int64_t, int> chosen_in_cell;  // cell → index into `given`
    for (size_t i = 0; i < given.camera_pixels.size(); ++i) {
      const int col = static_cast<int>(std::lround(given.camera_pixels[i].x()));
      const int row = static_cast<int>(std::lround(given.camera_pixels[i].y()));
      const std::int64_t cell = PixelKey(col / stride, row / stride);
      auto [it, inserted] = chosen_in_cell.emplace(cell, static_cast<int>(i));
      if (inserted) continue;
      const Vec2& old = given.camera_pixels[it->second];
      if (std::make_pair(std::lround(given.camera_pixels[i].y()),
                         std::lround(given.camera_pixels[i].x())) <
          std::make_pair(std::lround(old.y()), std::lround(old.x())))
        it->second = static_cast<int>(i);
    }
    std::vector<int> kept;
    for (const auto& [cell, index] : chosen_in_cell) kept.push_back(index);
    std::sort(kept.begin(), kept.end());
    for (const int i : kept) {
      const Vec2& pixel = given.camera_pixels[i];
      const std::int64_t key = PixelKey(static_cast<int>(std::lround(pixel.x())),
                                        static_cast<int>(std::lround(pixel.y())));
      auto [it, inserted] = track_of_pixel.emplace(key, static_cast<int>(tracks->size()));
      if (inserted) {
        Track track;
        track.camera_pixel = pixel;
        UnprojectCameraPixel(problem.camera_lens_model, problem.camera_intrinsics, pixel,
                             &track.ray);
        tracks->push_back(track);
      }
      (*projectors)[k].observations.push_back({it->second, given.projector_pixels[i]});
    }
  }
}

// (σ1 − σ2) / σ2 of E(f) = K_p(f)ᵀ F: zero for the focal length of an essential matrix.
double SingularValueGap(const Eigen::Matrix3d& f_matrix, double f, double cx, double cy) {
  Eigen::Matrix3d k;
  k << f, 0, cx, 0, f, cy, 0, 0, 1;
  const Eigen::Vector3d s =
      Eigen::JacobiSVD<Eigen::Matrix3d>(k.transpose() * f_matrix).singularValues();
  return (s[0] - s[1]) / std::max(s[1], 1e-300);
}

// The focal length f for which E(f) = K_p(f)ᵀ F is closest to an essential matrix, the principal
// point (cx, cy) given: a log-spaced search over the throw-ratio range, refined by golden section.
struct FocalFit {
  double focal = 0.0;
  double gap = 0.0;           // SingularValueGap at focal
  bool at_range_end = false;  // the best sample was the first or last: no minimum inside
};
FocalFit FitFocal(const SelfCalibrationOptions& options, const Eigen::Matrix3d& f_matrix, int width,
                  double cx, double cy) {
  const double log_lo = std::log(options.min_throw_ratio * width);
  const double log_hi = std::log(options.max_throw_ratio * width);
  constexpr int kSamples = 80;
  auto gap_at = [&](double log_f) { return SingularValueGap(f_matrix, std::exp(log_f), cx, cy); };
  int best = 0;
  double best_gap = std::numeric_limits<double>::infinity();
  for (int i = 0; i < kSamples; ++i) {
    const double gap = gap_at(log_lo + (log_hi - log_lo) * i / (kSamples - 1));
    if (gap < best_gap) best_gap = gap, best = i;
  }
  double a = log_lo + (log_hi - log_lo) * std::max(best - 1, 0) / (kSamples - 1);
  double b = log_lo + (log_hi - log_lo) * std::min(best + 1, kSamples - 1) / (kSamples - 1);
  const double golden = 0.5 * (std::sqrt(5.0) - 1.0);
  for (int i = 0; i < 60; ++i) {
    const double c = b - golden * (b - a), d = a + golden * (b - a);
    if (gap_at(c) < gap_at(d))
      b = d;
    else
      a = c;
  }
  FocalFit fit;
  fit.focal = std::exp(0.5 * (a + b));
  fit.gap = gap_at(0.5 * (a + b));
  fit.at_range_end = best == 0 || best == kSamples - 1;
  return fit;
}

// Step 2 for one projector (unit translation), its principal point assumed at `principal_point`,
// or its lens the held one in state->intrinsics (state->lens_held); the termination it ends in,
// kConverged for a seed.
SelfCalibrationSummary::Termination SeedProjector(const SelfCalibrationOptions& options,
                                                  const std::vector<Track>& tracks, int width,
                                                  int height, const Vec2& principal_point,
                                                  ProjectorState* state,
                                                  SelfCalibrationProjectorSummary* summary,
                                                  std::string* why) {
  // F between camera points in normalised coordinates and projector pixels; OpenCV's Hartley
  // normalisation makes the mixed scales harmless, but RANSAC's threshold is a distance in the
  // second image only when the first is in pixels too: scale the camera's by a nominal focal.
  constexpr double kCameraScale = 1000.0;
  std::vector<cv::Point2d> camera_points, projector_points;
  for (const Observation& o : state->observations) {
    const Vec3& ray = tracks[o.track].ray;
    camera_points.emplace_back(kCameraScale * ray.x(), kCameraScale * ray.y());
    projector_points.emplace_back(o.projector_pixel.x(), o.projector_pixel.y());
  }
  std::vector<uchar> f_mask, h_mask;
  const cv::Mat f_cv = cv::findFundamentalMat(camera_points, projector_points, cv::USAC_ACCURATE,
                                              options.ransac_threshold, 0.999, 10000, f_mask);
  summary->seed_inliers = f_cv.rows == 3 ? cv::countNonZero(f_mask) : 0;
  const cv::Mat h_cv = cv::findHomography(camera_points, projector_points, cv::USAC_ACCURATE,
                                          options.ransac_threshold, h_mask, 10000, 0.999);
  summary->homography_inliers = h_cv.empty() ? 0 : cv::countNonZero(h_mask);
  if (summary->seed_inliers < options.min_correspondences) {
    *why = "only " + std::to_string(summary->seed_inliers) +
           " correspondences fit one fundamental matrix (fewer than min_correspondences " +
           std::to_string(options.min_correspondences) + ")";
    return SelfCalibrationSummary::kTooFewPoints;
  }
  if (summary->homography_inliers >=
      options.degenerate_homography_fraction * summary->seed_inliers) {
    *why = "one homography explains " + std::to_string(summary->homography_inliers) + " of the " +
           std::to_string(summary->seed_inliers) +
           " epipolar inliers: it lights one plane only (or sits at the camera's centre), so its "
           "pose and focal length do not follow from it; light two or more surfaces";
    return SelfCalibrationSummary::kDegenerate;
  }
  std::vector<cv::Point2d> camera_normalised, projector_normalised;
  cv::Mat essential_cv(3, 3, CV_64F), pose_mask;
  if (state->lens_held) {
    // The lens is known: no focal length to search. E straight from the normalised points of both
    // devices (the five-point solver under RANSAC with local optimisation), its inlier distance
    // the fundamental matrix's in the projector's (undistorted) pixels.
    const double fx = state->intrinsics[0], fy = state->intrinsics[1];
    const double cx = state->intrinsics[2], cy = state->intrinsics[3];
    summary->seed_focal = fx;
    summary->seed_principal_point = Vec2(cx, cy);
    for (const Observation& o : state->observations) {
      const Vec3& ray = tracks[o.track].ray;
      camera_normalised.emplace_back(ray.x(), ray.y());
      projector_normalised.emplace_back((o.projector_pixel.x() - cx) / fx,
                                        (o.projector_pixel.y() - cy) / fy);
    }
    cv::Mat e_mask;
    const cv::Mat e_cv = cv::findEssentialMat(camera_normalised, projector_normalised, 1.0,
                                              cv::Point2d(0, 0), cv::USAC_ACCURATE, 0.999,
                                              options.ransac_threshold / fx, 10000, e_mask);
    if (e_cv.rows < 3 || e_cv.cols != 3) {
      *why = "no essential matrix fits its correspondences through the held lens";
      return SelfCalibrationSummary::kDegenerate;
    }
    e_cv.rowRange(0, 3).convertTo(essential_cv, CV_64F);
    pose_mask = e_mask;
  } else {
    Eigen::Matrix3d f_matrix;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) f_matrix(r, c) = f_cv.at<double>(r, c);
    // Camera points back to normalised coordinates: F_norm = F · diag(s, s, 1).
    f_matrix = f_matrix * Eigen::Vector3d(kCameraScale, kCameraScale, 1.0).asDiagonal();

    // Focal length: equal singular values of E(f), the principal point at its guess; with
    // search_principal_point_y, also along the image's vertical where that makes E far closer to an
    // essential matrix (a lens shift the guess misses).
    const double cx = principal_point.x();
    double cy = principal_point.y();
    FocalFit fit = FitFocal(options, f_matrix, width, cx, cy);
    if (options.search_principal_point_y && fit.gap > 0.02) {
      auto fit_at = [&](double y) { return FitFocal(options, f_matrix, width, cx, y); };
      constexpr int kRows = 81;  // cy from −height/2 to 3·height/2
      double best_y = cy;
      FocalFit best = fit;
      for (int i = 0; i < kRows; ++i) {
        const double y = -0.5 * height + 2.0 * height * i / (kRows - 1);
        const FocalFit trial = fit_at(y);
        if (trial.gap < best.gap) best = trial, best_y = y;
      }
      double a = best_y - 2.0 * height / (kRows - 1), b = best_y + 2.0 * height / (kRows - 1);
      const double golden = 0.5 * (std::sqrt(5.0) - 1.0);
      for (int i = 0; i < 40; ++i) {
        const double c = b - golden * (b - a), d = a + golden * (b - a);
        if (fit_at(c).gap < fit_at(d).gap)
          b = d;
        else
          a = c;
      }
      const FocalFit refined = fit_at(0.5 * (a + b));
      if (refined.gap < 0.25 * fit.gap) cy = 0.5 * (a + b), fit = refined;
    }
    const double focal = fit.focal;
    summary->seed_focal = focal;
    summary->seed_principal_point = Vec2(cx, cy);
    if (fit.gap > options.max_seed_gap || fit.at_range_end) {
      *why = "no focal length with throw ratio in [" + Number(options.min_throw_ratio) + ", " +
             Number(options.max_throw_ratio) +
             "] makes its fundamental matrix an essential matrix (best f " + Number(focal) + " px)";
      return SelfCalibrationSummary::kDegenerate;
    }
    Eigen::Matrix3d k_projector;
    k_projector << focal, 0, cx, 0, focal, cy, 0, 0, 1;
    const Eigen::Matrix3d essential = k_projector.transpose() * f_matrix;

    for (const Observation& o : state->observations) {
      const Vec3& ray = tracks[o.track].ray;
      camera_normalised.emplace_back(ray.x(), ray.y());
      projector_normalised.emplace_back((o.projector_pixel.x() - cx) / focal,
                                        (o.projector_pixel.y() - cy) / focal);
    }
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) essential_cv.at<double>(r, c) = essential(r, c);
    pose_mask = cv::Mat(f_mask, true);
    state->intrinsics[0] = state->intrinsics[1] = focal;
    state->intrinsics[2] = cx;
    state->intrinsics[3] = cy;
  }
  cv::Mat rotation_cv, translation_cv;
  cv::recoverPose(essential_cv, camera_normalised, projector_normalised, rotation_cv,
                  translation_cv, 1.0, cv::Point2d(0, 0), pose_mask);
  Eigen::Matrix3d rotation;
  Vec3 translation;
  for (int r = 0; r < 3; ++r) {
    translation[r] = translation_cv.at<double>(r);
    for (int c = 0; c < 3; ++c) rotation(r, c) = rotation_cv.at<double>(r, c);
  }
  // Depth along each camera ray: the midpoint of the camera ray z·r and the projector ray
  // c + s·d (c the projector's centre, d its ray, both in the camera frame).
  const Vec3 centre = -rotation.transpose() * translation;
  state->seed_depth.assign(state->observations.size(), 0.0);
  int in_front = 0;
  for (size_t i = 0; i < state->observations.size(); ++i) {
    if (!pose_mask.at<uchar>(static_cast<int>(i))) continue;
    const Vec3& r = tracks[state->observations[i].track].ray;
    const Vec3 d =
        rotation.transpose() * Vec3(projector_normalised[i].x, projector_normalised[i].y, 1.0);
    Eigen::Matrix2d a_matrix;
    a_matrix << r.dot(r), -r.dot(d), r.dot(d), -d.dot(d);
    const Eigen::Vector2d rhs(r.dot(centre), d.dot(centre));
    const Eigen::Vector2d zs = a_matrix.colPivHouseholderQr().solve(rhs);
    if (!(zs[0] > 0.0 && zs[1] > 0.0)) continue;
    state->seed_depth[i] = zs[0];
    ++in_front;
  }
  if (in_front < options.min_correspondences) {
    *why = "only " + std::to_string(in_front) +
           " correspondences triangulate in front of both devices after decomposing E";
    return SelfCalibrationSummary::kTooFewPoints;
  }
  ceres::RotationMatrixToAngleAxis(rotation.data(), state->rotation);  // column-major
  for (int i = 0; i < 3; ++i) state->translation[i] = translation[i];
  return SelfCalibrationSummary::kConverged;
}

// Step 3: scales every projector's seed into the unit of the one with the most seed points along
// a maximum spanning tree of shared tracks, then sets the tracks' depths to the median over the
// projectors and rescales so that the median depth is 1. Returns the index of a projector not
// reached, or −1.
int TieScales(const SelfCalibrationOptions& options, std::vector<Track>* tracks,
              std::vector<ProjectorState>* projectors,
              std::vector<SelfCalibrationProjectorSummary>* summaries) {
  const int n = static_cast<int>(projectors->size());
  // Per track, the seed depth each projector gives it.
  std::vector<std::vector<std::pair<int, double>>> depths(tracks->size());
  for (int k = 0; k < n; ++k) {
    const ProjectorState& p = (*projectors)[k];
    for (size_t i = 0; i < p.observations.size(); ++i)
      if (p.seed_depth[i] > 0.0) depths[p.observations[i].track].push_back({k, p.seed_depth[i]});
  }
  std::vector<std::vector<std::vector<double>>> ratios(n, std::vector<std::vector<double>>(n));
  std::vector<int> shared(n, 0);
  for (const auto& seen : depths) {
    if (seen.size() > 1)
      for (const auto& [k, depth] : seen) ++shared[k];
    for (const auto& [k, depth_k] : seen)
      for (const auto& [l, depth_l] : seen)
        if (k != l) ratios[k][l].push_back(depth_k / depth_l);
  }
  for (int k = 0; k < n; ++k) (*summaries)[k].shared = shared[k];
  int root = 0;
  for (int k = 1; k < n; ++k)
    if ((*summaries)[k].seed_inliers > (*summaries)[root].seed_inliers) root = k;
  // Prim's algorithm on the number of shared tracks: scale[l] converts l's unit into root's.
  std::vector<double> scale(n, 0.0);
  scale[root] = 1.0;
  for (int added = 1; added < n; ++added) {
    int best_k = -1, best_l = -1;
    size_t best_count = 0;
    for (int k = 0; k < n; ++k)
      for (int l = 0; l < n; ++l)
        if (scale[k] > 0.0 && scale[l] == 0.0 && ratios[l][k].size() > best_count)
          best_count = ratios[l][k].size(), best_k = k, best_l = l;
    if (best_l < 0 || best_count < static_cast<size_t>(options.min_shared_points)) {
      for (int l = 0; l < n; ++l)
        if (scale[l] == 0.0) return l;
    }
    // depth_k · scale_k = depth_l · scale_l.
    scale[best_l] = scale[best_k] / Median(ratios[best_l][best_k]);
  }
  std::vector<double> all_depths;
  for (size_t t = 0; t < tracks->size(); ++t) {
    std::vector<double> scaled;
    for (const auto& [k, depth] : depths[t]) scaled.push_back(depth * scale[k]);
    (*tracks)[t].depth = Median(scaled);
    if (!scaled.empty()) all_depths.push_back((*tracks)[t].depth);
  }
  const double unit = Median(all_depths);
  for (Track& track : *tracks) track.depth /= unit;
  for (int k = 0; k < n; ++k)
    for (double& t : (*projectors)[k].translation) t *= scale[k] / unit;
  return -1;
}

// Step 4's residual: the point depth · (ray_x, ray_y, 1) (camera frame) seen by a projector,
// minus the decoded projector pixel. With square pixels fy is fx.
template <typename T>
void ProjectDepthPoint(const T& ray_x, const T& ray_y, const T* intrinsics, const T* rotation,
                       const T* translation, const T* depth, const Vec2& observed,
                       bool square_pixels, T* residual) {
  const T p[3] = {depth[0] * ray_x, depth[0] * ray_y, depth[0]};
  T q[3];
  ceres::AngleAxisRotatePoint(rotation, p, q);
  for (int i = 0; i < 3; ++i) q[i] += translation[i];
  const T& fy = square_pixels ? intrinsics[0] : intrinsics[1];
  residual[0] = intrinsics[0] * q[0] / q[2] + intrinsics[2] - T(observed.x());
  residual[1] = fy * q[1] / q[2] + intrinsics[3] - T(observed.y());
}

// The residual with the camera's lens held: the track's ray is a constant.
struct DepthReprojection {
  DepthReprojection(const Vec3& ray, const Vec2& observed, bool square_pixels)
      : ray_(ray), observed_(observed), square_pixels_(square_pixels) {}
  template <typename T>
  bool operator()(const T* intrinsics, const T* rotation, const T* translation, const T* depth,
                  T* residual) const {
    ProjectDepthPoint(T(ray_.x()), T(ray_.y()), intrinsics, rotation, translation, depth,
                      observed_, square_pixels_, residual);
    return true;
  }
  Vec3 ray_;
  Vec2 observed_;
  bool square_pixels_;
};

// The residual with the camera's lens free (kCameraBlock: fx, fy, cx, cy, then k1, k2, p1, p2
// of LENSMODEL_OPENCV4, zero and held for a pinhole): the ray is the camera pixel unprojected
// through the lens, by Newton steps from the ray at the lens the solve started from.
constexpr int kCameraBlock = 8;

// The free lens's ray (x, y, 1) of `camera_pixel`: Newton steps from `ray0`, the ray at the lens
// the solve started from.
template <typename T>
void RayThroughFreeLens(const T* camera, const Vec2& camera_pixel, const Vec2& ray0, T* x, T* y) {
  const T distorted_x = (T(camera_pixel.x()) - camera[2]) / camera[0];
  const T distorted_y = (T(camera_pixel.y()) - camera[3]) / camera[1];
  *x = T(ray0.x());
  *y = T(ray0.y());
  UndistortOpenCv4Steps(camera + 4, distorted_x, distorted_y, 3, x, y);
}

struct DepthReprojectionFreeLens {
  DepthReprojectionFreeLens(const Vec2& camera_pixel, const Vec3& ray0, const Vec2& observed,
                            bool square_pixels)
      : camera_pixel_(camera_pixel), ray0_(ray0.x(), ray0.y()), observed_(observed),
        square_pixels_(square_pixels) {}
  template <typename T>
  bool operator()(const T* camera, const T* intrinsics, const T* rotation, const T* translation,
                  const T* depth, T* residual) const {
    T x, y;
    RayThroughFreeLens(camera, camera_pixel_, ray0_, &x, &y);
    ProjectDepthPoint(x, y, intrinsics, rotation, translation, depth, observed_, square_pixels_,
                      residual);
    return true;
  }
  Vec2 camera_pixel_;
  Vec2 ray0_;
  Vec2 observed_;
  bool square_pixels_;
};

// The floor's constraint (SelfCalibrationOptions::floor_normal_in_camera): a floor point's
// distance to the plane of the given normal, normal · p + offset = 0, `weight` times, with the
// offset free. The point as in the reprojection residuals: depth · ray, the ray through the held
// lens or (FreeLens) the free one.
template <typename T>
T FloorDistance(const T& ray_x, const T& ray_y, const T& depth, const Vec3& normal,
                const T& offset) {
  return depth * (T(normal.x()) * ray_x + T(normal.y()) * ray_y + T(normal.z())) + offset;
}

struct FloorPlaneResidual {
  FloorPlaneResidual(const Vec3& ray, const Vec3& normal, double weight)
      : ray_(ray), normal_(normal), weight_(weight) {}
  template <typename T>
  bool operator()(const T* depth, const T* offset, T* residual) const {
    residual[0] = T(weight_) * FloorDistance(T(ray_.x()), T(ray_.y()), depth[0], normal_, offset[0]);
    return true;
  }
  Vec3 ray_, normal_;
  double weight_;
};

struct FloorPlaneResidualFreeLens {
  FloorPlaneResidualFreeLens(const Vec2& camera_pixel, const Vec3& ray0, const Vec3& normal,
                             double weight)
      : camera_pixel_(camera_pixel), ray0_(ray0.x(), ray0.y()), normal_(normal), weight_(weight) {}
  template <typename T>
  bool operator()(const T* camera, const T* depth, const T* offset, T* residual) const {
    T x, y;
    RayThroughFreeLens(camera, camera_pixel_, ray0_, &x, &y);
    residual[0] = T(weight_) * FloorDistance(x, y, depth[0], normal_, offset[0]);
    return true;
  }
  Vec2 camera_pixel_;
  Vec2 ray0_;
  Vec3 normal_;
  double weight_;
};

// The tracks on the floor and the plane they are held to.
struct FloorConstraint {
  std::vector<int> tracks;
  Vec3 normal = Vec3::UnitZ();
  double offset = 0.0;  // solve units, free in the solve
  double weight = 1.0;  // px per solve unit (10 σ_decoding / σ_floor, SelfCalibrateRoom)
};

// The camera's lens in the bundle adjustment (SelfCalibrationOptions::refine_camera_lens): its
// parameters and the chessboard's estimate as a Gaussian prior, ‖A (lens − mean)‖², A scaled
// by the decoding noise so that both terms are in the same units (A = σ_decoding L⁻¹ for the
// chessboard's covariance L Lᵀ).
struct CameraLensBlock {
  double lens[kCameraBlock] = {0, 0, 0, 0, 0, 0, 0, 0};
  double mean[kCameraBlock] = {0, 0, 0, 0, 0, 0, 0, 0};
  Eigen::MatrixXd sqrt_information;  // A without the noise factor: rows = the lens's parameters
  int parameters = 4;                // 4 (pinhole) or 8 (OpenCV4)
  double noise_px = 1.0;             // σ_decoding per coordinate
};

Vec2 Residual(const SelfCalibrationOptions& options, const ProjectorState& p, const Track& track,
              const Vec2& observed) {
  Vec2 r;
  DepthReprojection(track.ray, observed, TiedFocal(options, p))(
      p.intrinsics, p.rotation, p.translation, &track.depth, r.data());
  return r;
}

// One Ceres solve: the robust pass over every observation of a seeded track under a Cauchy loss,
// the final one over the inliers without a loss. The gauge is the depth of the track closest to
// the median depth among those seen by the most projectors.
bool Solve(const SelfCalibrationOptions& options, bool robust, std::vector<Track>* tracks,
           std::vector<ProjectorState>* projectors, ceres::Solver::Summary* ceres_summary,
           int* gauge_out = nullptr, CameraLensBlock* camera = nullptr,
           FloorConstraint* floor = nullptr) {
  ceres::Problem ceres_problem;
  std::vector<int> seen_by(tracks->size(), 0);
  for (ProjectorState& p : *projectors) {
    for (size_t i = 0; i < p.observations.size(); ++i) {
      const Observation& o = p.observations[i];
      Track& track = (*tracks)[o.track];
      if (track.depth <= 0.0 || (!robust && !p.inlier[i])) continue;
      ceres::LossFunction* loss = robust ? new ceres::CauchyLoss(options.loss_scale) : nullptr;
      if (camera) {
        ceres_problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<DepthReprojectionFreeLens, 2, kCameraBlock, 4, 3, 3, 1>(
                new DepthReprojectionFreeLens(track.camera_pixel, track.ray, o.projector_pixel,
                                              TiedFocal(options, p))),
            loss, camera->lens, p.intrinsics, p.rotation, p.translation, &track.depth);
      } else {
        ceres_problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<DepthReprojection, 2, 4, 3, 3, 1>(
                new DepthReprojection(track.ray, o.projector_pixel, TiedFocal(options, p))),
            loss, p.intrinsics, p.rotation, p.translation, &track.depth);
      }
      ++seen_by[o.track];
    }
  }
  for (size_t k = 0; k < projectors->size(); ++k) {
    ProjectorState& p = (*projectors)[k];
    if (!ceres_problem.HasParameterBlock(p.intrinsics)) continue;
    if (p.lens_held) {
      ceres_problem.SetParameterBlockConstant(p.intrinsics);
      continue;
    }
    std::vector<int> held;
    if (options.square_pixels) held.push_back(1);
    if (p.principal_point_held) held.insert(held.end(), {2, 3});
    if (!held.empty()) ceres_problem.SetManifold(p.intrinsics, new ceres::SubsetManifold(4, held));
  }
  if (floor) {
    for (const int t : floor->tracks) {
      Track& track = (*tracks)[t];
      if (!ceres_problem.HasParameterBlock(&track.depth)) continue;
      if (camera) {
        ceres_problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<FloorPlaneResidualFreeLens, 1, kCameraBlock, 1, 1>(
                new FloorPlaneResidualFreeLens(track.camera_pixel, track.ray, floor->normal,
                                               floor->weight)),
            nullptr, camera->lens, &track.depth, &floor->offset);
      } else {
        ceres_problem.AddResidualBlock(
            new ceres::AutoDiffCostFunction<FloorPlaneResidual, 1, 1, 1>(
                new FloorPlaneResidual(track.ray, floor->normal, floor->weight)),
            nullptr, &track.depth, &floor->offset);
      }
    }
  }
  if (camera && ceres_problem.HasParameterBlock(camera->lens)) {
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(camera->parameters, kCameraBlock);
    a.leftCols(camera->parameters) = camera->noise_px * camera->sqrt_information;
    const ceres::Vector mean = ceres::ConstVectorRef(camera->mean, kCameraBlock);
    ceres_problem.AddResidualBlock(new ceres::NormalPrior(a, mean), nullptr, camera->lens);
    std::vector<int> held_lens;
    for (int i = camera->parameters; i < kCameraBlock; ++i) held_lens.push_back(i);
    if (!held_lens.empty())
      ceres_problem.SetManifold(camera->lens,
                                new ceres::SubsetManifold(kCameraBlock, held_lens));
  }
  const int most = *std::max_element(seen_by.begin(), seen_by.end());
  if (most == 0) return false;  // no residual: the callers' point counts exclude it
  std::vector<double> candidate_depths;
  for (size_t t = 0; t < tracks->size(); ++t)
    if (seen_by[t] == most) candidate_depths.push_back((*tracks)[t].depth);
  const double median = Median(candidate_depths);
  int gauge = -1;
  for (size_t t = 0; t < tracks->size(); ++t)
    if (seen_by[t] == most && (gauge < 0 || std::abs((*tracks)[t].depth - median) <
                                                std::abs((*tracks)[gauge].depth - median)))
      gauge = static_cast<int>(t);
  ceres_problem.SetParameterBlockConstant(&(*tracks)[gauge].depth);
  if (gauge_out) *gauge_out = gauge;

  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_SCHUR;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = 1e-12;
  solver_options.gradient_tolerance = 1e-12;
  solver_options.parameter_tolerance = 1e-12;
  // One thread: Ceres's threads sum the Schur complement in varying order, and the last bits
  // that changes can tip the scan's outlines (measured: a wall's outline 13 or 73 corners from
  // run to run); the solve takes about a second either way.
  solver_options.num_threads = 1;
  ceres::Solve(solver_options, &ceres_problem, ceres_summary);
  for (ProjectorState& p : *projectors)
    if (TiedFocal(options, p)) p.intrinsics[1] = p.intrinsics[0];
  return ceres_summary->IsSolutionUsable();
}

// A point fixed in the camera frame in units of the projector's distance from the camera
// (`point` at the solve's `baseline`), as the projector shows it: the solve's overall scale
// cancels (header: uncertainty).
struct ProjectScaledPoint {
  ProjectScaledPoint(const Vec3& point, double baseline, bool square_pixels)
      : point_(point), baseline_(baseline), square_pixels_(square_pixels) {}
  template <typename T>
  bool operator()(const T* intrinsics, const T* rotation, const T* translation, T* pixel) const {
    using std::sqrt;
    const T length = sqrt(translation[0] * translation[0] + translation[1] * translation[1] +
                          translation[2] * translation[2]);
    const T p[3] = {T(point_.x()) * length / baseline_, T(point_.y()) * length / baseline_,
                    T(point_.z()) * length / baseline_};
    T q[3];
    ceres::AngleAxisRotatePoint(rotation, p, q);
    for (int i = 0; i < 3; ++i) q[i] += translation[i];
    const T& fy = square_pixels_ ? intrinsics[0] : intrinsics[1];
    pixel[0] = intrinsics[0] * q[0] / q[2] + intrinsics[2];
    pixel[1] = fy * q[1] / q[2] + intrinsics[3];
    return true;
  }
  Vec3 point_;
  double baseline_;
  bool square_pixels_;
};

// The parameters of a projector the final solve refines, as indices into (fx, fy, cx, cy,
// rotation, translation): a held lens's intrinsics are not among them.
std::vector<int> FreeParameters(const SelfCalibrationOptions& options, const ProjectorState& p) {
  std::vector<int> free;
  if (!p.lens_held) {
    free.push_back(0);
    if (!options.square_pixels) free.push_back(1);
    if (!p.principal_point_held) free.insert(free.end(), {2, 3});
  }
  for (int i = 4; i < 10; ++i) free.push_back(i);
  return free;
}

// The columns of a 2 × (fx, fy, cx, cy, rotation, translation) Jacobian, given by its blocks,
// for the parameters `free` (FreeParameters).
Eigen::MatrixXd FreeColumns(const Eigen::Matrix<double, 2, 4, Eigen::RowMajor>& intrinsics,
                            const Eigen::Matrix<double, 2, 3, Eigen::RowMajor>& rotation,
                            const Eigen::Matrix<double, 2, 3, Eigen::RowMajor>& translation,
                            const std::vector<int>& free) {
  Eigen::Matrix<double, 2, 10> all;
  all << intrinsics, rotation, translation;
  Eigen::MatrixXd columns(2, free.size());
  for (size_t c = 0; c < free.size(); ++c) columns.col(c) = all.col(free[c]);
  return columns;
}

// Step 4b: each projector's projection uncertainty (header: uncertainty), in the solve's
// units (uncertainty_distance_m is scaled to metres by the caller).
// With the chessboard's covariance Σc of the camera's lens (the problem's
// camera_intrinsics_covariance), the lens's own uncertainty is folded in. Held fixed, the lens
// moves the projectors by −S⁻¹B Δc (S the reduced JᵀJ of the projectors' parameters, B their
// reduced cross term with the lens), adding S⁻¹BΣcBᵀS⁻¹; refined with Σc as its prior (`refined`),
// the projectors' covariance is the marginal of the joint one, σ²(S − B(C + σ²Σc⁻¹)⁻¹Bᵀ)⁻¹,
// C the lens's reduced JᵀJ.
void ProjectorUncertainties(const SelfCalibrationOptions& options,
                            const RoomCalibrationProblem& problem,
                            const std::vector<double>& camera_intrinsics, bool refined,
                            const std::vector<Track>& tracks,
                            const std::vector<ProjectorState>& projectors, int gauge,
                            std::vector<SelfCalibrationProjectorSummary>* summaries) {
  const int n = static_cast<int>(projectors.size());
  std::vector<std::vector<int>> free(n);
  std::vector<int> offset(n + 1, 0);
  for (int k = 0; k < n; ++k) {
    free[k] = FreeParameters(options, projectors[k]);
    offset[k + 1] = offset[k] + static_cast<int>(free[k].size());
  }
  // The camera's lens as the free-lens residual takes it (kCameraBlock, zero distortion for a
  // pinhole), and its covariance where the problem has one of the right size.
  const int lens_parameters = static_cast<int>(camera_intrinsics.size());
  const Eigen::MatrixXd& lens_covariance = problem.camera_intrinsics_covariance;
  const bool with_lens = lens_covariance.rows() == lens_parameters &&
                         lens_covariance.cols() == lens_parameters && lens_parameters <= kCameraBlock &&
                         lens_covariance.allFinite();
  double lens[kCameraBlock] = {0, 0, 0, 0, 0, 0, 0, 0};
  std::copy(camera_intrinsics.begin(), camera_intrinsics.end(), lens);
  struct Entry {
    int k;
    Eigen::MatrixXd jp;  // 2 × free[k].size()
    Vec2 jd;
    Eigen::Matrix<double, 2, kCameraBlock> jc;  // the first lens_parameters columns are the lens's
  };
  std::vector<std::vector<Entry>> by_track(tracks.size());
  double squared = 0.0;
  int residuals = 0;
  for (int k = 0; k < n; ++k) {
    const ProjectorState& p = projectors[k];
    for (size_t i = 0; i < p.observations.size(); ++i) {
      const Observation& o = p.observations[i];
      const Track& track = tracks[o.track];
      if (track.depth <= 0.0 || !p.inlier[i]) continue;
      const ceres::AutoDiffCostFunction<DepthReprojectionFreeLens, 2, kCameraBlock, 4, 3, 3, 1>
          cost(new DepthReprojectionFreeLens(track.camera_pixel, track.ray, o.projector_pixel,
                                             TiedFocal(options, p)));
      const double* parameters[] = {lens, p.intrinsics, p.rotation, p.translation, &track.depth};
      Eigen::Matrix<double, 2, kCameraBlock, Eigen::RowMajor> j_lens;
      Eigen::Matrix<double, 2, 4, Eigen::RowMajor> j_intrinsics;
      Eigen::Matrix<double, 2, 3, Eigen::RowMajor> j_rotation, j_translation;
      Vec2 residual, j_depth;
      double* jacobians[] = {j_lens.data(), j_intrinsics.data(), j_rotation.data(),
                             j_translation.data(), j_depth.data()};
      if (!cost.Evaluate(parameters, residual.data(), jacobians)) continue;
      by_track[o.track].push_back(
          {k, FreeColumns(j_intrinsics, j_rotation, j_translation, free[k]), j_depth, j_lens});
      squared += residual.squaredNorm();
      residuals += 2;
    }
  }
  // JᵀJ with the depths eliminated (each depth couples only its own observations): the
  // projectors' block S, their cross term with the lens B and the lens's own C.
  Eigen::MatrixXd schur = Eigen::MatrixXd::Zero(offset[n], offset[n]);
  Eigen::MatrixXd cross = Eigen::MatrixXd::Zero(offset[n], lens_parameters);
  Eigen::MatrixXd lens_block = Eigen::MatrixXd::Zero(lens_parameters, lens_parameters);
  int depths = 0;
  for (size_t t = 0; t < tracks.size(); ++t) {
    const std::vector<Entry>& entries = by_track[t];
    if (entries.empty()) continue;
    double dd = 0.0;
    Eigen::RowVectorXd dc = Eigen::RowVectorXd::Zero(lens_parameters);  // Σ jdᵀ jc
    for (const Entry& e : entries) {
      const auto jc = e.jc.leftCols(lens_parameters);
      schur.block(offset[e.k], offset[e.k], e.jp.cols(), e.jp.cols()) += e.jp.transpose() * e.jp;
      cross.middleRows(offset[e.k], e.jp.cols()) += e.jp.transpose() * jc;
      lens_block += jc.transpose() * jc;
      dd += e.jd.squaredNorm();
      dc += e.jd.transpose() * jc;
    }
    if (static_cast<int>(t) == gauge || !(dd > 0.0)) continue;  // the gauge's depth is held
    ++depths;
    lens_block -= dc.transpose() * dc / dd;
    for (const Entry& e : entries) {
      const Eigen::VectorXd b_e = e.jp.transpose() * e.jd;
      cross.middleRows(offset[e.k], e.jp.cols()) -= b_e * dc / dd;
      for (const Entry& f : entries) {
        schur.block(offset[e.k], offset[f.k], e.jp.cols(), f.jp.cols()) -=
            b_e * (f.jp.transpose() * f.jd).transpose() / dd;
      }
    }
  }
  const int dof = residuals - offset[n] - depths;
  if (dof <= 0) return;
  const double variance = squared / dof;
  if (with_lens && refined) {
    // The lens's information in JᵀJ's units: the data's C and the prior's σ²Σc⁻¹; the lens is
    // then marginalised out of S.
    const Eigen::MatrixXd lens_information =
        lens_block + variance * lens_covariance.inverse();
    schur -= cross * lens_information.ldlt().solve(cross.transpose());
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(schur);
  if (eigen.info() != Eigen::Success || !(eigen.eigenvalues().minCoeff() > 0.0)) return;
  const Eigen::MatrixXd schur_inverse = eigen.eigenvectors() *
                                        eigen.eigenvalues().cwiseInverse().asDiagonal() *
                                        eigen.eigenvectors().transpose();
  Eigen::MatrixXd covariance = variance * schur_inverse;
  if (with_lens && !refined) {
    const Eigen::MatrixXd moved = schur_inverse * cross;  // −∂(projectors)/∂(lens)
    covariance += moved * lens_covariance * moved.transpose();
  }
  for (int k = 0; k < n; ++k) {
    const ProjectorState& p = projectors[k];
    Eigen::Matrix3d rotation;
    ceres::AngleAxisToRotationMatrix(p.rotation, rotation.data());  // column-major
    const Vec3 translation(p.translation[0], p.translation[1], p.translation[2]);
    std::vector<double> distances;
    for (size_t i = 0; i < p.observations.size(); ++i) {
      const Track& track = tracks[p.observations[i].track];
      if (track.depth > 0.0 && p.inlier[i])
        distances.push_back((rotation * (track.depth * track.ray) + translation).norm());
    }
    const double distance = Median(distances);
    if (!(distance > 0.0)) continue;
    const Eigen::MatrixXd block =
        covariance.block(offset[k], offset[k], free[k].size(), free[k].size());
    const bool tied = TiedFocal(options, p);
    const double fy = tied ? p.intrinsics[0] : p.intrinsics[1];
    // A held lens: the solve's pixels are its undistorted ones; the map is of the image's own
    // (distorted) pixels, each unprojected through the lens, and the spread is taken through the
    // distortion's Jacobian there.
    const HeldProjectorLens* held = HeldLens(problem, k);
    const auto worst = [&](const Vec2& pixel) {
      Vec3 ray(0.0, 0.0, 1.0);
      if (held) {
        if (!UnprojectCameraPixel(held->lens_model, held->intrinsics, pixel, &ray))
          return std::numeric_limits<double>::quiet_NaN();
      } else {
        ray = Vec3((pixel.x() - p.intrinsics[2]) / p.intrinsics[0],
                   (pixel.y() - p.intrinsics[3]) / fy, 1.0);
      }
      const Vec3 direction = ray.normalized();
      const Vec3 in_camera = rotation.transpose() * (distance * direction - translation);
      const ceres::AutoDiffCostFunction<ProjectScaledPoint, 2, 4, 3, 3> project(
          new ProjectScaledPoint(in_camera, translation.norm(), tied));
      const double* parameters[] = {p.intrinsics, p.rotation, p.translation};
      Eigen::Matrix<double, 2, 4, Eigen::RowMajor> j_intrinsics;
      Eigen::Matrix<double, 2, 3, Eigen::RowMajor> j_rotation, j_translation;
      Vec2 projected;
      double* jacobians[] = {j_intrinsics.data(), j_rotation.data(), j_translation.data()};
      if (!project.Evaluate(parameters, projected.data(), jacobians))
        return std::numeric_limits<double>::quiet_NaN();
      Eigen::MatrixXd j = FreeColumns(j_intrinsics, j_rotation, j_translation, free[k]);
      if (held && held->intrinsics.size() == 8) {
        // d(distorted pixel)/d(undistorted pixel) = diag(fx, fy) · D'(x, y) · diag(1/fx, 1/fy).
        double distorted_x, distorted_y;
        Eigen::Matrix<double, 2, 2, Eigen::RowMajor> d;
        DistortOpenCv4(held->intrinsics.data() + 4, ray.x(), ray.y(), &distorted_x, &distorted_y,
                       d.data());
        const Eigen::DiagonalMatrix<double, 2> focal(p.intrinsics[0], p.intrinsics[1]);
        j = (focal * d * focal.inverse()) * j;
      }
      const Eigen::Matrix2d var = j * block * j.transpose();
      return std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(var).eigenvalues()[1]);
    };
    SelfCalibrationProjectorSummary& summary = (*summaries)[k];
    summary.uncertainty_includes_camera_lens = with_lens;
    summary.uncertainty_distance_m = distance;  // solve units until the scale is known
    summary.uncertainty = MapProjectionUncertainty(worst, std::sqrt(variance),
                                                   problem.projectors[k].width,
                                                   problem.projectors[k].height);
  }
}

// Step 5: the floor among the planes fitted to `points` (camera frame); -1 when none.
int FindFloor(const SelfCalibrationOptions& options, const std::vector<FittedPlane>& planes,
              const std::vector<Vec3>& points, double distance) {
  const Vec3 image_up(0.0, -1.0, 0.0);
  const double min_cos = std::cos(options.max_floor_tilt_deg * kPi / 180.0);
  int floor = -1, floor_lit = -1;
  for (size_t i = 0; i < planes.size(); ++i) {
    const FittedPlane& plane = planes[i];
    if (plane.normal.dot(image_up) < min_cos || plane.offset <= 0.0) continue;
    int lit = 0;
    for (const Vec3& p : points) lit += plane.normal.dot(p) + plane.offset >= -distance;
    if (lit > floor_lit || (lit == floor_lit && plane.inliers > planes[floor].inliers))
      floor = static_cast<int>(i), floor_lit = lit;
  }
  return floor;
}

// The floor again by least squares on the points within 2.5 σ of it, σ its inliers' RMS, a few
// times: RANSAC's band (2 cm at 4 m) takes in the feet of walls and columns, which tilt and lift
// the plane, and the metric scale comes from its offset.
FittedPlane RefinePlane(const FittedPlane& plane, const std::vector<Vec3>& points) {
  FittedPlane refined = plane;
  double band = 2.5 * 1e-3 * plane.rms_mm;
  for (int round = 0; round < 5; ++round) {
    Vec3 centroid = Vec3::Zero();
    std::vector<const Vec3*> inliers;
    for (const Vec3& p : points)
      if (std::abs(refined.normal.dot(p) + refined.offset) <= band) inliers.push_back(&p);
    if (inliers.size() < 3) return refined;
    for (const Vec3* p : inliers) centroid += *p;
    centroid /= static_cast<double>(inliers.size());
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
    for (const Vec3* p : inliers) covariance += (*p - centroid) * (*p - centroid).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(covariance);
    Vec3 normal = eigen.eigenvectors().col(0);
    if (normal.dot(refined.normal) < 0.0) normal = -normal;
    refined.normal = normal;
    refined.offset = -normal.dot(centroid);
    refined.centroid = centroid;
    refined.inliers = static_cast<int>(inliers.size());
    refined.rms_mm = 1e3 * std::sqrt(std::max(eigen.eigenvalues()[0], 0.0) / inliers.size());
    band = 2.5 * 1e-3 * refined.rms_mm;
  }
  return refined;
}

// The room frame of step 5 in the camera frame: z the floor's unit normal `up` (camera frame),
// x the optical axis projected on the floor (the image's x axis when the camera looks straight
// down), origin the camera's foot, `height` below its centre.
Eigen::Isometry3d RoomFromCamera(const Vec3& up, double height) {
  Vec3 x_axis = Vec3::UnitZ() - Vec3::UnitZ().dot(up) * up;
  if (x_axis.norm() < 1e-6) x_axis = Vec3::UnitX() - Vec3::UnitX().dot(up) * up;
  x_axis.normalize();
  Eigen::Isometry3d room_from_camera = Eigen::Isometry3d::Identity();
  room_from_camera.linear().row(0) = x_axis.transpose();
  room_from_camera.linear().row(1) = up.cross(x_axis).transpose();
  room_from_camera.linear().row(2) = up.transpose();
  room_from_camera.translation() = Vec3(0.0, 0.0, height);
  return room_from_camera;
}

// Marks projector p's observations whose residual norm is within the threshold as inliers;
// returns how many.
int MarkInliers(const SelfCalibrationOptions& options, const std::vector<Track>& tracks,
                ProjectorState* p) {
  p->inlier.assign(p->observations.size(), false);
  int inliers = 0;
  for (size_t i = 0; i < p->observations.size(); ++i) {
    const Track& track = tracks[p->observations[i].track];
    if (track.depth <= 0.0) continue;
    const Vec2 r = Residual(options, *p, track, p->observations[i].projector_pixel);
    p->inlier[i] = r.norm() <= options.outlier_threshold;
    inliers += p->inlier[i];
  }
  return inliers;
}

// Projector p's RMS per coordinate and largest residual norm over its inliers; false when a
// residual is not finite. Counts the inlier views of each track into `inlier_views`.
bool InlierResiduals(const SelfCalibrationOptions& options, const std::vector<Track>& tracks,
                     const ProjectorState& p, SelfCalibrationProjectorSummary* summary,
                     std::vector<int>* inlier_views) {
  double sum_squared = 0.0, max_norm = 0.0;
  int count = 0;
  for (size_t i = 0; i < p.observations.size(); ++i) {
    if (!p.inlier[i]) continue;
    const Vec2 r =
        Residual(options, p, tracks[p.observations[i].track], p.observations[i].projector_pixel);
    if (!r.allFinite()) return false;
    sum_squared += r.squaredNorm();
    max_norm = std::max(max_norm, r.norm());
    ++count;
    ++(*inlier_views)[p.observations[i].track];
  }
  summary->rms = std::sqrt(sum_squared / (2.0 * std::max(count, 1)));
  summary->max_norm = max_norm;
  return true;
}

// The RMS per coordinate of every projector's inlier residuals together, px (1 when there are
// none).
double PooledInlierRms(const SelfCalibrationOptions& options, const std::vector<Track>& tracks,
                       const std::vector<ProjectorState>& projectors) {
  double squared = 0.0;
  int count = 0;
  for (const ProjectorState& p : projectors)
    for (size_t i = 0; i < p.observations.size(); ++i)
      if (p.inlier[i]) {
        squared +=
            Residual(options, p, tracks[p.observations[i].track], p.observations[i].projector_pixel)
                .squaredNorm();
        count += 2;
      }
  return count > 0 && squared > 0.0 ? std::sqrt(squared / count) : 1.0;
}

// Projector k of the result: its pinhole lens (or the held lens, exactly as given) and
// proj_from_room, the solve's translation in metres (× scale).
RoomProjector ResultProjector(const ProjectorObservations& given, const HeldProjectorLens* held,
                              const ProjectorState& p, double scale,
                              const Eigen::Isometry3d& camera_from_room) {
  RoomProjector projector;
  projector.name = given.name;
  if (held) {
    projector.lens_model = held->lens_model;
    projector.intrinsics = held->intrinsics;
    projector.lens_held = true;
  } else {
    projector.lens_model = "LENSMODEL_PINHOLE";
    projector.intrinsics.assign(p.intrinsics, p.intrinsics + 4);
  }
  projector.width = given.width;
  projector.height = given.height;
  Eigen::Matrix3d rotation;
  ceres::AngleAxisToRotationMatrix(p.rotation, rotation.data());  // column-major
  Eigen::Isometry3d proj_from_cam = Eigen::Isometry3d::Identity();
  proj_from_cam.linear() = rotation;
  proj_from_cam.translation() = scale * Vec3(p.translation[0], p.translation[1], p.translation[2]);
  projector.proj_from_room = proj_from_cam * camera_from_room;
  return projector;
}

}  // namespace

bool SelfCalibrationOptions::Check(std::string* why) const {
  if (!(camera_height > 0.0) || !std::isfinite(camera_height)) {
    *why = "camera_height must be a finite distance > 0 metres";
    return false;
  }
  if (!(min_throw_ratio > 0.0 && max_throw_ratio > min_throw_ratio) ||
      !std::isfinite(max_throw_ratio)) {
    *why = "need 0 < min_throw_ratio < max_throw_ratio";
    return false;
  }
  if (!(ransac_threshold > 0.0) || !(loss_scale > 0.0) || !(outlier_threshold > 0.0)) {
    *why = "ransac_threshold, loss_scale and outlier_threshold must be > 0";
    return false;
  }
  if (!(max_outlier_fraction >= 0.0 && max_outlier_fraction <= 1.0)) {
    *why = "max_outlier_fraction must be in [0, 1]";
    return false;
  }
  if (!(max_seed_gap > 0.0)) {
    *why = "max_seed_gap must be > 0";
    return false;
  }
  for (const Vec2& guess : principal_point_guesses)
    if (!guess.allFinite()) {
      *why = "principal_point_guesses must be finite";
      return false;
    }
  if (!(degenerate_homography_fraction > 0.0 && degenerate_homography_fraction <= 1.0)) {
    *why = "degenerate_homography_fraction must be in (0, 1]";
    return false;
  }
  if (min_correspondences < 12 || max_correspondences < min_correspondences ||
      min_shared_points < 1 || max_iterations < 1) {
    *why =
        "need min_correspondences >= 12, max_correspondences >= min_correspondences, "
        "min_shared_points >= 1, max_iterations >= 1";
    return false;
  }
  if (!(plane_distance > 0.0 && plane_distance < 0.1) ||
      !(max_floor_tilt_deg > 0.0 && max_floor_tilt_deg < 90.0)) {
    *why = "need plane_distance in (0, 0.1) and max_floor_tilt_deg in (0, 90)";
    return false;
  }
  if (!floor_normal_in_camera.allFinite() ||
      !(max_floor_normal_deg > 0.0 && max_floor_normal_deg < 90.0)) {
    *why = "need a finite floor_normal_in_camera and max_floor_normal_deg in (0, 90)";
    return false;
  }
  return true;
}

std::string SelfCalibrationSummary::BriefReport() const {
  static const char* const kNames[] = {"converged",    "too few points", "degenerate",
                                       "disconnected", "inconsistent",   "no floor",
                                       "solver failed"};
  std::string text = std::string("Room self-calibration: ") + kNames[termination];
  char line[400];
  std::snprintf(line, sizeof(line),
                "; %d points; %d iterations, cost %.4g -> %.4g; %.4g m per unit; floor %d "
                "points, RMS %.2f mm; %.2f s",
                points, ceres_iterations, initial_cost, final_cost, scale, floor_inliers,
                floor_rms_mm, time_s);
  text += line;
  if (floor_normal_held) {
    text += "\n  floor held to the given normal (" + Number(floor_to_given_normal_deg) +
            " deg from the scan's)";
  }
  if (camera_lens_refined) {
    std::string moved;
    for (double d : camera_lens_moved) moved += (moved.empty() ? "" : ", ") + Number(d);
    text += "\n  camera lens refined with the chessboard's as prior: moved (" + moved + "), " +
            Number(camera_lens_moved_sigmas) + " chessboard sigmas";
  }
  if (!message.empty()) text += "\n  " + message;
  for (size_t k = 0; k < projectors.size(); ++k) {
    const SelfCalibrationProjectorSummary& p = projectors[k];
    std::snprintf(line, sizeof(line),
                  "\n  projector %zu: %d of %d used, %s f %.1f px cy %.1f px (%d F / %d H "
                  "inliers), %d shared, %s; %d outliers, RMS %.3f px, max %.3f px",
                  k, p.used, p.correspondences, p.lens_held ? "held lens" : "seed", p.seed_focal,
                  p.seed_principal_point.y(), p.seed_inliers, p.homography_inliers, p.shared,
                  p.lens_held              ? "lens held, pose alone solved"
                  : p.principal_point_held ? "principal point held"
                                           : "principal point refined",
                  p.outliers, p.rms, p.max_norm);
    text += line;
    if (!p.uncertainty.grid.empty()) {
      const double corner = *std::max_element(p.uncertainty.corners.begin(), p.uncertainty.corners.end());
      std::snprintf(line, sizeof(line),
                    "; projection uncertainty %.3f px at the centre, %.3f px at worst corner "
                    "(%.2f m away)",
                    p.uncertainty.centre, corner, p.uncertainty_distance_m);
      text += line;
    }
  }
  return text;
}

bool SelfCalibrateRoom(const SelfCalibrationOptions& options, const RoomCalibrationProblem& problem,
                       RoomCalibration* calibration, std::vector<SelfCalibrationPoint>* points,
                       SelfCalibrationSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("SelfCalibrationOptions: " + why);
  if (problem.projectors.empty()) throw std::invalid_argument("self-calibration: no projector");
  Vec3 probe;
  if (!UnprojectCameraPixel(problem.camera_lens_model, problem.camera_intrinsics, Vec2(0, 0),
                            &probe))
    throw std::invalid_argument("self-calibration: unsupported camera lens '" +
                                problem.camera_lens_model + "' or wrong number of intrinsics");
  for (const ProjectorObservations& p : problem.projectors)
    if (p.width < 1 || p.height < 1 || p.camera_pixels.size() != p.projector_pixels.size())
      throw std::invalid_argument("self-calibration: projector '" + p.name +
                                  "' has a size < 1 or unequal pixel lists");
  if (!options.principal_point_guesses.empty() &&
      options.principal_point_guesses.size() != problem.projectors.size())
    throw std::invalid_argument("self-calibration: principal_point_guesses has " +
                                std::to_string(options.principal_point_guesses.size()) +
                                " entries for " + std::to_string(problem.projectors.size()) +
                                " projectors");
  if (!problem.held_projector_lenses.empty() &&
      problem.held_projector_lenses.size() != problem.projectors.size())
    throw std::invalid_argument(
        "self-calibration: " + std::to_string(problem.held_projector_lenses.size()) +
        " held projector lenses for " + std::to_string(problem.projectors.size()) + " projectors");
  for (size_t k = 0; k < problem.projectors.size(); ++k) {
    const HeldProjectorLens* held = HeldLens(problem, k);
    if (!held) continue;
    const std::string name = "self-calibration: projector '" + problem.projectors[k].name + "': ";
    if (!UnprojectCameraPixel(held->lens_model, held->intrinsics, Vec2::Zero(), &probe))
      throw std::invalid_argument(name +
                                  "a held lens must be LENSMODEL_PINHOLE (4 intrinsics) or "
                                  "LENSMODEL_OPENCV4 (8), got " +
                                  held->lens_model + " with " +
                                  std::to_string(held->intrinsics.size()));
    for (const double value : held->intrinsics)
      if (!std::isfinite(value))
        throw std::invalid_argument(name + "the held lens has a non-finite intrinsic");
    if (!(held->intrinsics[0] > 0.0) || !(held->intrinsics[1] > 0.0))
      throw std::invalid_argument(name + "the held lens's focal lengths must be positive");
  }

  const int n = static_cast<int>(problem.projectors.size());
  *summary = SelfCalibrationSummary();
  summary->projectors.resize(n);
  auto finish = [&](SelfCalibrationSummary::Termination termination, const std::string& message) {
    summary->termination = termination;
    summary->message = message;
    summary->time_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return termination == SelfCalibrationSummary::kConverged;
  };
  auto projector_name = [&](int k) { return "projector '" + problem.projectors[k].name + "': "; };
  for (int k = 0; k < n; ++k) {
    const int given = static_cast<int>(problem.projectors[k].camera_pixels.size());
    summary->projectors[k].correspondences = given;
    if (given < options.min_correspondences)
      return finish(SelfCalibrationSummary::kTooFewPoints,
                    projector_name(k) + std::to_string(given) +
                        " correspondences, fewer than min_correspondences " +
                        std::to_string(options.min_correspondences));
  }

  // 1. Thinning: the smallest common stride that keeps every projector within the limit.
  std::vector<Track> tracks;
  std::vector<ProjectorState> projectors;
  // A stride s keeps about 1/s² of a dense projector's pixels: start just below that.
  int most_given = 0;
  for (const ProjectorObservations& p : problem.projectors)
    most_given = std::max(most_given, static_cast<int>(p.camera_pixels.size()));
  const int first_stride = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(most_given) /
                                                                  options.max_correspondences)));
  for (int stride = first_stride;; ++stride) {
    Thin(problem, stride, &tracks, &projectors);
    bool fits = true;
    for (const ProjectorState& p : projectors)
      fits = fits && static_cast<int>(p.observations.size()) <= options.max_correspondences;
    if (fits) break;
  }
  // A held lens: its intrinsics are constant, its decoded pixels undistorted through it once.
  for (int k = 0; k < n; ++k) {
    const HeldProjectorLens* held = HeldLens(problem, k);
    if (!held) continue;
    ProjectorState& p = projectors[k];
    p.lens_held = p.principal_point_held = true;
    std::copy(held->intrinsics.begin(), held->intrinsics.begin() + 4, p.intrinsics);
    std::vector<Observation> undistorted;
    for (const Observation& o : p.observations) {
      Vec3 ray;
      if (!UnprojectCameraPixel(held->lens_model, held->intrinsics, o.projector_pixel, &ray))
        continue;
      undistorted.push_back({o.track, Vec2(p.intrinsics[0] * ray.x() + p.intrinsics[2],
                                           p.intrinsics[1] * ray.y() + p.intrinsics[3])});
    }
    p.observations = std::move(undistorted);
    summary->projectors[k].lens_held = true;
  }
  for (int k = 0; k < n; ++k) {
    summary->projectors[k].used = static_cast<int>(projectors[k].observations.size());
    if (summary->projectors[k].used < options.min_correspondences)
      return finish(SelfCalibrationSummary::kTooFewPoints,
                    projector_name(k) + "only " + std::to_string(summary->projectors[k].used) +
                        " correspondences left after thinning to the common grid");
  }

  // 2. Seeds.
  for (int k = 0; k < n; ++k) {
    const ProjectorObservations& given = problem.projectors[k];
    const Vec2 principal_point = options.principal_point_guesses.empty()
                                     ? Vec2(0.5 * (given.width - 1), 0.5 * (given.height - 1))
                                     : options.principal_point_guesses[k];
    const SelfCalibrationSummary::Termination seeded =
        SeedProjector(options, tracks, given.width, given.height, principal_point, &projectors[k],
                      &summary->projectors[k], &why);
    if (seeded != SelfCalibrationSummary::kConverged)
      return finish(seeded, projector_name(k) + why);
  }

  // 3. One unit of length for all.
  const int unreached = TieScales(options, &tracks, &projectors, &summary->projectors);
  if (unreached >= 0)
    return finish(SelfCalibrationSummary::kDisconnected,
                  projector_name(unreached) + "shares fewer than min_shared_points (" +
                      std::to_string(options.min_shared_points) +
                      ") camera pixels with the other projectors: its scale is unknown");
  for (int k = 0; k < n; ++k) {
    projectors[k].principal_point_held = projectors[k].lens_held || n == 1 ||
                                         summary->projectors[k].shared < options.min_shared_points;
    summary->projectors[k].principal_point_held = projectors[k].principal_point_held;
  }

  // 4. Bundle adjustment: a robust pass, then the inliers.
  ceres::Solver::Summary robust_summary, final_summary;
  if (!Solve(options, true, &tracks, &projectors, &robust_summary))
    return finish(SelfCalibrationSummary::kSolverFailed,
                  "the robust bundle adjustment failed: " + robust_summary.message);
  summary->initial_cost = robust_summary.final_cost;
  summary->ceres_iterations = static_cast<int>(robust_summary.iterations.size());
  for (int k = 0; k < n; ++k) {
    const int inliers = MarkInliers(options, tracks, &projectors[k]);
    const int used = static_cast<int>(projectors[k].observations.size());
    summary->projectors[k].outliers = used - inliers;
    if (used - inliers > options.max_outlier_fraction * used)
      return finish(SelfCalibrationSummary::kInconsistent,
                    projector_name(k) + std::to_string(used - inliers) + " of " +
                        std::to_string(used) +
                        " correspondences are outliers after the robust bundle adjustment: the "
                        "solve went astray (a principal point far from its guess? give "
                        "principal_point_guesses) or the decoding is bad");
    if (inliers < options.min_correspondences)
      return finish(SelfCalibrationSummary::kTooFewPoints,
                    projector_name(k) + "only " + std::to_string(inliers) +
                        " inliers after the robust bundle adjustment");
  }
  // The camera's lens joins the final solve, its chessboard estimate the prior.
  const int lens_parameters = static_cast<int>(problem.camera_intrinsics.size());
  const bool refine_lens = options.refine_camera_lens;
  if (refine_lens && problem.camera_intrinsics_covariance.size() == 0)
    throw std::invalid_argument(
        "self-calibration: refine_camera_lens needs the problem's camera_intrinsics_covariance");
  // σ_decoding: the robust pass's inlier residuals, all projectors pooled.
  const double noise_px = PooledInlierRms(options, tracks, projectors);
  CameraLensBlock lens;
  const Eigen::MatrixXd& covariance = problem.camera_intrinsics_covariance;
  if (covariance.size() != 0) {
    if (covariance.rows() != lens_parameters || covariance.cols() != lens_parameters)
      throw std::invalid_argument("self-calibration: camera_intrinsics_covariance is " +
                                  std::to_string(covariance.rows()) + "x" +
                                  std::to_string(covariance.cols()) + " for " +
                                  std::to_string(lens_parameters) + " intrinsics");
    if (!covariance.allFinite() || Eigen::LLT<Eigen::MatrixXd>(covariance).info() != Eigen::Success)
      throw std::invalid_argument(
          "self-calibration: camera_intrinsics_covariance is not positive definite");
  }
  if (refine_lens) {
    const Eigen::LLT<Eigen::MatrixXd> factor(covariance);
    // Σ = L Lᵀ, so Σ⁻¹ = AᵀA with A = L⁻¹.
    lens.sqrt_information = factor.matrixL().solve(
        Eigen::MatrixXd::Identity(lens_parameters, lens_parameters));
    lens.parameters = lens_parameters;
    for (int i = 0; i < lens_parameters; ++i)
      lens.lens[i] = lens.mean[i] = problem.camera_intrinsics[i];
    lens.noise_px = noise_px;
  }
  std::vector<double> camera_intrinsics = problem.camera_intrinsics;
  // After a solve that refined the lens: the lens, and every track's ray through it.
  const auto take_lens = [&]() {
    if (!refine_lens) return true;
    camera_intrinsics.assign(lens.lens, lens.lens + lens_parameters);
    for (Track& track : tracks)
      if (!UnprojectCameraPixel(problem.camera_lens_model, camera_intrinsics, track.camera_pixel,
                                &track.ray))
        return false;
    return true;
  };
  int gauge = -1;
  if (!Solve(options, false, &tracks, &projectors, &final_summary, &gauge,
             refine_lens ? &lens : nullptr))
    return finish(SelfCalibrationSummary::kSolverFailed,
                  "the bundle adjustment failed: " + final_summary.message);
  if (!take_lens())
    return finish(SelfCalibrationSummary::kSolverFailed,
                  "the bundle adjustment left a camera lens that cannot unproject the image");
  summary->final_cost = final_summary.final_cost;
  summary->ceres_iterations += static_cast<int>(final_summary.iterations.size());

  // 5. The floor, the metric scale and the room frame.
  std::vector<int> inlier_views;
  std::vector<Vec3> cloud;
  std::vector<int> cloud_track;
  // The inlier residuals and the cloud of the tracks some projector saw as an inlier; false when
  // a residual is not finite.
  const auto gather = [&]() {
    inlier_views.assign(tracks.size(), 0);
    for (int k = 0; k < n; ++k)
      if (!InlierResiduals(options, tracks, projectors[k], &summary->projectors[k],
                           &inlier_views))
        return k;
    cloud.clear();
    cloud_track.clear();
    for (size_t t = 0; t < tracks.size(); ++t) {
      if (inlier_views[t] == 0) continue;
      cloud.push_back(tracks[t].depth * tracks[t].ray);
      cloud_track.push_back(static_cast<int>(t));
    }
    return -1;
  };
  if (const int k = gather(); k >= 0)
    return finish(SelfCalibrationSummary::kSolverFailed,
                  projector_name(k) + "the bundle adjustment left a non-finite residual");
  ProjectorUncertainties(options, problem, camera_intrinsics, refine_lens, tracks, projectors,
                         gauge, &summary->projectors);

  std::vector<double> depths;
  for (const Vec3& p : cloud) depths.push_back(p.z());
  summary->points = static_cast<int>(cloud.size());
  PlaneFitOptions plane_options;
  plane_options.distance = options.plane_distance * Median(depths);
  plane_options.min_inliers = std::clamp(static_cast<int>(cloud.size()) / 50, 3, 200);
  const std::vector<FittedPlane> planes = FitPlanes(plane_options, cloud);
  const int floor = FindFloor(options, planes, cloud, plane_options.distance);
  if (floor < 0)
    return finish(SelfCalibrationSummary::kNoFloor,
                  "no floor: none of the " + std::to_string(planes.size()) +
                      " planes fitted to the points faces the camera's image-up within " +
                      Number(options.max_floor_tilt_deg) + " deg");
  FittedPlane floor_plane = RefinePlane(planes[floor], cloud);

  // The floor held to the given normal (the floor chessboard's) in one more solve.
  if (options.floor_normal_in_camera.norm() > 0.0) {
    const Vec3 given = options.floor_normal_in_camera.normalized();
    summary->floor_to_given_normal_deg =
        std::acos(std::clamp(given.dot(floor_plane.normal), -1.0, 1.0)) * 180.0 / kPi;
    if (summary->floor_to_given_normal_deg <= options.max_floor_normal_deg) {
      FloorConstraint constraint;
      constraint.normal = given;
      constraint.offset = floor_plane.offset;
      const double floor_sigma = 1e-3 * floor_plane.rms_mm;  // solve units
      // Ten times the weight of the floor's own scatter: in effect an equality (measured on the
      // green trapezoid, half size, lens held off the truth, true normal given: weight 1 left the
      // floor 0.031 deg off that normal and the points 10.6 mm RMS off the truth, weight 10
      // 0.0004 deg and 6.7 mm, from 0.110 deg and 22.4 mm free).
      constraint.weight = 10.0 * noise_px / std::max(floor_sigma, 1e-12);
      for (size_t i = 0; i < cloud.size(); ++i)
        if (std::abs(floor_plane.normal.dot(cloud[i]) + floor_plane.offset) <= 2.5 * floor_sigma)
          constraint.tracks.push_back(cloud_track[i]);
      ceres::Solver::Summary floor_summary;
      if (!Solve(options, false, &tracks, &projectors, &floor_summary, &gauge,
                 refine_lens ? &lens : nullptr, &constraint))
        return finish(SelfCalibrationSummary::kSolverFailed,
                      "the bundle adjustment with the floor's normal failed: " +
                          floor_summary.message);
      if (!take_lens())
        return finish(SelfCalibrationSummary::kSolverFailed,
                      "the bundle adjustment left a camera lens that cannot unproject the image");
      summary->final_cost = floor_summary.final_cost;
      summary->ceres_iterations += static_cast<int>(floor_summary.iterations.size());
      if (const int k = gather(); k >= 0)
        return finish(SelfCalibrationSummary::kSolverFailed,
                      projector_name(k) + "the bundle adjustment left a non-finite residual");
      FittedPlane held = floor_plane;
      held.normal = given;
      held.offset = constraint.offset;
      held = RefinePlane(held, cloud);
      held.rms_mm = floor_plane.rms_mm;  // the scan's own scatter (held, the points have none)
      floor_plane = held;
      summary->floor_normal_held = true;
    }
  }
  if (refine_lens) {
    Eigen::VectorXd moved(lens_parameters);
    for (int i = 0; i < lens_parameters; ++i) moved[i] = lens.lens[i] - lens.mean[i];
    summary->camera_lens_refined = true;
    summary->camera_lens_moved.assign(moved.data(), moved.data() + lens_parameters);
    summary->camera_lens_moved_sigmas = (lens.sqrt_information * moved).norm();
  }
  const double scale = options.camera_height / floor_plane.offset;
  summary->scale = scale;
  for (SelfCalibrationProjectorSummary& p : summary->projectors) p.uncertainty_distance_m *= scale;
  summary->floor_inliers = floor_plane.inliers;
  summary->floor_rms_mm = floor_plane.rms_mm * scale;

  const Eigen::Isometry3d room_from_camera =
      RoomFromCamera(floor_plane.normal, options.camera_height);
  const Eigen::Isometry3d camera_from_room = room_from_camera.inverse();

  RoomCalibration result;
  result.room_from_camera = room_from_camera;
  result.camera_lens_model = problem.camera_lens_model;
  result.camera_intrinsics = camera_intrinsics;
  for (int k = 0; k < n; ++k)
    result.projectors.push_back(ResultProjector(problem.projectors[k], HeldLens(problem, k),
                                                projectors[k], scale, camera_from_room));
  if (points) {
    points->clear();
    for (size_t i = 0; i < cloud.size(); ++i) {
      const Track& track = tracks[cloud_track[i]];
      points->push_back({room_from_camera * (scale * cloud[i]), track.camera_pixel,
                         inlier_views[cloud_track[i]]});
    }
  }
  *calibration = std::move(result);
  return finish(SelfCalibrationSummary::kConverged,
                final_summary.termination_type == ceres::NO_CONVERGENCE
                    ? "the final solve stopped at max_iterations before converging"
                    : "");
}

}  // namespace procam
