#include "calibration/projector_calibration.h"

#include "base/timing.h"
#include "calibration/pose_math.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <ceres/ceres.h>
#include <ceres/rotation.h>

namespace procam {

bool ProjectorCalibrationOptions::Check(std::string* why) const {
  auto fail = [why](const char* message) {
    if (why) *why = message;
    return false;
  };
  if (!(loss_scale > 0.0) || !std::isfinite(loss_scale)) return fail("loss_scale must be > 0");
  if (!(outlier_threshold > 0.0) || !std::isfinite(outlier_threshold))
    return fail("outlier_threshold must be > 0");
  if (min_correspondences < 6) return fail("min_correspondences must be at least 6");
  if (max_iterations < 1) return fail("max_iterations must be at least 1");
  return true;
}

std::string ProjectorCalibrationSummary::BriefReport() const {
  static const char* const kNames[] = {"converged", "too few points", "degenerate",
                                       "solver failed"};
  char line[320];
  std::snprintf(line, sizeof(line),
                "Projector calibration: %s; %d correspondences, %d points, %d outliers; seed RMS "
                "%.3g px, RMS %.4g px per coordinate, max %.3g px; %.2f s%s%s",
                kNames[termination], correspondences, points, outliers, seed_rms, rms, max_norm,
                time_s, message.empty() ? "" : "; ", message.c_str());
  return line;
}

bool UnprojectCameraPixel(const std::string& lens_model, const std::vector<double>& intrinsics,
                          const Vec2& pixel, Vec3* ray_in_cam) {
  const bool pinhole = lens_model == "LENSMODEL_PINHOLE" && intrinsics.size() == 4;
  const bool opencv4 = lens_model == "LENSMODEL_OPENCV4" && intrinsics.size() == 8;
  if (!pinhole && !opencv4) return false;
  const double fx = intrinsics[0], fy = intrinsics[1], cx = intrinsics[2], cy = intrinsics[3];
  const Vec2 distorted((pixel.x() - cx) / fx, (pixel.y() - cy) / fy);
  Vec2 x = distorted;
  if (opencv4) {
    // Newton on D(x) = distorted, D the OpenCV model (well conditioned for lenses that are
    // invertible over the image).
    const double* distortion = intrinsics.data() + 4;
    for (int iteration = 0; iteration < 50; ++iteration) {
      Vec2 value;
      Eigen::Matrix<double, 2, 2, Eigen::RowMajor> jacobian;
      DistortOpenCv4(distortion, x.x(), x.y(), &value.x(), &value.y(), jacobian.data());
      const Vec2 error = value - distorted;
      if (error.norm() < 1e-14) break;
      x -= jacobian.inverse() * error;
    }
  }
  *ray_in_cam = Vec3(x.x(), x.y(), 1.0);
  return std::isfinite(x.x()) && std::isfinite(x.y());
}

namespace {

// Projector reprojection: p_in_cam (fixed) → pixel through intrinsics (fx, fy, cx, cy, k1, k2)
// and the pose (angle-axis, translation) of proj_from_cam.
struct ProjectorReprojection {
  ProjectorReprojection(const Vec3& p_in_cam, const Vec2& observed)
      : p_in_cam(p_in_cam), observed(observed) {}
  template <typename T>
  bool operator()(const T* intrinsics, const T* rotation, const T* translation,
                  T* residual) const {
    const T p[3] = {T(p_in_cam.x()), T(p_in_cam.y()), T(p_in_cam.z())};
    ProjectorPixelResidual(intrinsics, rotation, translation, p, observed, residual);
    return true;
  }
  Vec3 p_in_cam;
  Vec2 observed;
};

struct Parameters {
  double intrinsics[6] = {0, 0, 0, 0, 0, 0};  // fx, fy, cx, cy, k1, k2
  double rotation[3] = {0, 0, 0};             // angle-axis of proj_from_cam
  double translation[3] = {0, 0, 0};          // metres
};

Vec2 Project(const Parameters& parameters, const Vec3& p_in_cam) {
  Vec2 residual;
  ProjectorReprojection(p_in_cam, Vec2::Zero())(parameters.intrinsics, parameters.rotation,
                                                parameters.translation, residual.data());
  return residual;
}

// Normalised DLT (H&Z Alg. 7.1) and K [R | t] by RQ decomposition. False when degenerate.
bool SeedByDlt(const std::vector<Vec3>& points, const std::vector<Vec2>& pixels,
               Parameters* seed, std::string* why) {
  const int n = static_cast<int>(points.size());
  Vec3 mean3 = Vec3::Zero();
  Vec2 mean2 = Vec2::Zero();
  for (int i = 0; i < n; ++i) {
    mean3 += points[i];
    mean2 += pixels[i];
  }
  mean3 /= n;
  mean2 /= n;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  double spread3 = 0.0, spread2 = 0.0;
  for (int i = 0; i < n; ++i) {
    covariance += (points[i] - mean3) * (points[i] - mean3).transpose();
    spread3 += (points[i] - mean3).norm();
    spread2 += (pixels[i] - mean2).norm();
  }
  const Eigen::Vector3d eigenvalues =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance).eigenvalues();
  if (!(eigenvalues(0) > 1e-6 * eigenvalues(2))) {
    *why = "the points are (nearly) coplanar: use two or more non-parallel planes";
    return false;
  }
  const double s3 = std::sqrt(3.0) * n / spread3, s2 = std::sqrt(2.0) * n / spread2;
  Eigen::Matrix<double, 12, 12> normal = Eigen::Matrix<double, 12, 12>::Zero();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector4d X((points[i] - mean3).x() * s3, (points[i] - mean3).y() * s3,
                            (points[i] - mean3).z() * s3, 1.0);
    const Vec2 q = (pixels[i] - mean2) * s2;
    Eigen::Matrix<double, 2, 12> rows = Eigen::Matrix<double, 2, 12>::Zero();
    rows.block<1, 4>(0, 0) = X.transpose();
    rows.block<1, 4>(0, 8) = -q.x() * X.transpose();
    rows.block<1, 4>(1, 4) = X.transpose();
    rows.block<1, 4>(1, 8) = -q.y() * X.transpose();
    normal += rows.transpose() * rows;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 12, 12>> solver(normal);
  const Eigen::Matrix<double, 12, 1> h = solver.eigenvectors().col(0);
  Eigen::Matrix<double, 3, 4> p_normalised;
  p_normalised << h.segment<4>(0).transpose(), h.segment<4>(4).transpose(),
      h.segment<4>(8).transpose();
  Eigen::Matrix3d t2 = Eigen::Matrix3d::Identity();
  t2(0, 0) = t2(1, 1) = s2;
  t2.block<2, 1>(0, 2) = -s2 * mean2;
  Eigen::Matrix4d t3 = Eigen::Matrix4d::Identity();
  t3.block<3, 3>(0, 0) *= s3;
  t3.block<3, 1>(0, 3) = -s3 * mean3;
  Eigen::Matrix<double, 3, 4> p = t2.inverse() * p_normalised * t3;
  Eigen::Matrix3d m = p.block<3, 3>(0, 0);
  if (m.determinant() < 0.0) {
    p = -p;
    m = -m;
  }
  // RQ: with J the row reversal, (J M)ᵀ = Q U gives M = (J Uᵀ J)(J Qᵀ).
  Eigen::Matrix3d j = Eigen::Matrix3d::Zero();
  j(0, 2) = j(1, 1) = j(2, 0) = 1.0;
  const Eigen::HouseholderQR<Eigen::Matrix3d> qr((j * m).transpose());
  const Eigen::Matrix3d q = qr.householderQ();
  const Eigen::Matrix3d u = qr.matrixQR().triangularView<Eigen::Upper>();
  Eigen::Matrix3d k = j * u.transpose() * j;
  Eigen::Matrix3d r = j * q.transpose();
  const Eigen::Vector3d signs(k(0, 0) < 0 ? -1.0 : 1.0, k(1, 1) < 0 ? -1.0 : 1.0,
                              k(2, 2) < 0 ? -1.0 : 1.0);
  k = k * signs.asDiagonal();
  r = signs.asDiagonal() * r;
  if (r.determinant() < 0.0) {  // only when det(M) sign and K's signs disagree
    *why = "the DLT seed is not a proper camera";
    return false;
  }
  const Vec3 t = k.inverse() * p.col(3);
  k /= k(2, 2);
  if (!(k(0, 0) > 0.0 && k(1, 1) > 0.0) || !t.allFinite()) {
    *why = "the DLT seed has non-positive focal lengths";
    return false;
  }
  seed->intrinsics[0] = k(0, 0);
  seed->intrinsics[1] = k(1, 1);
  seed->intrinsics[2] = k(0, 2);
  seed->intrinsics[3] = k(1, 2);
  seed->intrinsics[4] = seed->intrinsics[5] = 0.0;  // the skew k(0, 1) is dropped
  const Vec3 rotation = AngleAxisOf(r);
  for (int i = 0; i < 3; ++i) {
    seed->rotation[i] = rotation(i);
    seed->translation[i] = t(i);
  }
  return true;
}

// One Ceres solve over the points in `use`. False when Ceres reports failure.
bool Refine(const ProjectorCalibrationOptions& options, const std::vector<Vec3>& points,
            const std::vector<Vec2>& pixels, const std::vector<int>& use, bool robust,
            Parameters* parameters, std::string* message) {
  ceres::Problem problem;
  for (const int i : use) {
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<ProjectorReprojection, 2, 6, 3, 3>(
            new ProjectorReprojection(points[i], pixels[i])),
        robust ? new ceres::CauchyLoss(options.loss_scale) : nullptr, parameters->intrinsics,
        parameters->rotation, parameters->translation);
  }
  if (!options.refine_distortion)
    problem.SetManifold(parameters->intrinsics, new ceres::SubsetManifold(6, {4, 5}));
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = 1e-12;
  solver_options.gradient_tolerance = 1e-12;
  solver_options.parameter_tolerance = 1e-12;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  *message = summary.message;
  return summary.IsSolutionUsable();
}

}  // namespace

bool CalibrateProjector(const ProjectorCalibrationOptions& options,
                        const ProjectorCalibrationProblem& problem,
                        ProjectorCalibration* calibration, ProjectorCalibrationSummary* summary) {
  const auto start = Clock::now();
  std::string why;
  if (!options.Check(&why))
    throw std::invalid_argument("ProjectorCalibrationOptions: " + why);
  Vec3 probe;
  if (!UnprojectCameraPixel(problem.camera_lens_model, problem.camera_intrinsics, Vec2::Zero(),
                            &probe))
    throw std::invalid_argument("CalibrateProjector: camera lens must be LENSMODEL_PINHOLE (4 "
                                "intrinsics) or LENSMODEL_OPENCV4 (8), got " +
                                problem.camera_lens_model);
  if (problem.projector_width < 1 || problem.projector_height < 1)
    throw std::invalid_argument("CalibrateProjector: projector size must be at least 1×1");
  *summary = ProjectorCalibrationSummary();
  auto finish = [&](ProjectorCalibrationSummary::Termination termination, std::string message) {
    summary->termination = termination;
    summary->message = std::move(message);
    summary->time_s =
        SecondsSince(start);
    return termination == ProjectorCalibrationSummary::kConverged;
  };
  summary->correspondences = static_cast<int>(problem.correspondences.size());

  // 1. Points on the planes, camera frame.
  std::vector<Vec3> points;
  std::vector<Vec2> pixels;
  for (const ProjectorCorrespondence& c : problem.correspondences) {
    if (c.plane < 0 || c.plane >= static_cast<int>(problem.planes.size()))
      throw std::invalid_argument("CalibrateProjector: a correspondence names plane " +
                                  std::to_string(c.plane) + " of " +
                                  std::to_string(problem.planes.size()));
    Vec3 ray;
    if (!c.camera_pixel.allFinite() || !c.projector_pixel.allFinite() ||
        !UnprojectCameraPixel(problem.camera_lens_model, problem.camera_intrinsics,
                              c.camera_pixel, &ray))
      continue;
    const PlaneInCam& plane = problem.planes[c.plane];
    const double along = -plane.offset / plane.normal.dot(ray);
    if (!(along > 0.0) || !std::isfinite(along)) continue;
    points.push_back(along * ray);
    pixels.push_back(c.projector_pixel);
  }
  summary->points = static_cast<int>(points.size());
  if (summary->points < options.min_correspondences)
    return finish(ProjectorCalibrationSummary::kTooFewPoints, "");

  // 2. Seed.
  Parameters parameters;
  if (!SeedByDlt(points, pixels, &parameters, &why))
    return finish(ProjectorCalibrationSummary::kDegenerate, why);
  double sq = 0.0;
  for (size_t i = 0; i < points.size(); ++i)
    sq += (Project(parameters, points[i]) - pixels[i]).squaredNorm();
  summary->seed_rms = std::sqrt(sq / points.size());

  // 3. Robust pass on everything, then plain least squares on the inliers.
  std::vector<int> use(points.size());
  for (size_t i = 0; i < use.size(); ++i) use[i] = static_cast<int>(i);
  std::string message;
  if (!Refine(options, points, pixels, use, true, &parameters, &message))
    return finish(ProjectorCalibrationSummary::kSolverFailed, message);
  use.clear();
  for (size_t i = 0; i < points.size(); ++i)
    if ((Project(parameters, points[i]) - pixels[i]).norm() <= options.outlier_threshold)
      use.push_back(static_cast<int>(i));
  summary->outliers = summary->points - static_cast<int>(use.size());
  if (static_cast<int>(use.size()) < options.min_correspondences)
    return finish(ProjectorCalibrationSummary::kTooFewPoints, "too few inliers");
  if (!Refine(options, points, pixels, use, false, &parameters, &message))
    return finish(ProjectorCalibrationSummary::kSolverFailed, message);

  sq = 0.0;
  for (const int i : use) {
    const double norm = (Project(parameters, points[i]) - pixels[i]).norm();
    sq += norm * norm;
    summary->max_norm = std::max(summary->max_norm, norm);
  }
  summary->rms = std::sqrt(sq / (2.0 * use.size()));

  const Vec3 rotation(parameters.rotation[0], parameters.rotation[1], parameters.rotation[2]);
  const Vec3 translation(parameters.translation[0], parameters.translation[1],
                         parameters.translation[2]);
  *calibration = ProjectorCalibration();
  calibration->width = problem.projector_width;
  calibration->height = problem.projector_height;
  calibration->intrinsics.assign(parameters.intrinsics, parameters.intrinsics + 4);
  if (options.refine_distortion) {
    calibration->lens_model = "LENSMODEL_OPENCV4";
    calibration->intrinsics.insert(calibration->intrinsics.end(),
                                   {parameters.intrinsics[4], parameters.intrinsics[5], 0.0, 0.0});
  } else {
    calibration->lens_model = "LENSMODEL_PINHOLE";
  }
  calibration->proj_from_cam.linear() = RotationOf(rotation);
  calibration->proj_from_cam.translation() = translation;
  for (const double value : calibration->intrinsics)
    if (!std::isfinite(value)) return finish(ProjectorCalibrationSummary::kSolverFailed, "NaN");
  if (!translation.allFinite() || !rotation.allFinite())
    return finish(ProjectorCalibrationSummary::kSolverFailed, "non-finite pose");
  return finish(ProjectorCalibrationSummary::kConverged, message);
}

}  // namespace procam
