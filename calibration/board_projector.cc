#include "calibration/board_projector.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <limits>
#include <cmath>
#include <cstring>
#include <numbers>
#include <optional>
#include <stdexcept>

#include <opencv2/calib3d.hpp>

#include "base/timing.h"
#include "calibration/mrcal_chessboard.h"

extern "C" {
#include <mrcal/poseutils.h>
}

namespace procam {

bool BoardProjectorOptions::Check(std::string* why) const {
  if (lens_model != "LENSMODEL_OPENCV4" && lens_model != "LENSMODEL_OPENCV5" &&
      lens_model != "LENSMODEL_OPENCV8") {
    *why = "lens_model must be LENSMODEL_OPENCV4, LENSMODEL_OPENCV5 or LENSMODEL_OPENCV8, not '" +
           lens_model + "'";
    return false;
  }
  if (homography_half_window < 3 || homography_half_window > 200) {
    *why = "homography_half_window must be in [3, 200] camera pixels";
    return false;
  }
  if (min_window_pixels < 8) {
    *why = "min_window_pixels must be at least 8";
    return false;
  }
  if (!(homography_reject_px > 0.0) || !std::isfinite(homography_reject_px)) {
    *why = "homography_reject_px must be a positive number of projector pixels";
    return false;
  }
  if (min_poses < 2) {
    *why = "min_poses must be at least 2";
    return false;
  }
  if (!(min_tilt_spread_deg >= 0.0 && min_tilt_spread_deg < 90.0)) {
    *why = "min_tilt_spread_deg must be in [0, 90) degrees";
    return false;
  }
  return true;
}

namespace {

// The homography camera → projector fitted to `camera`/`projector` by least squares (OpenCV's
// normalised DLT refined by Levenberg–Marquardt), then refitted without the pairs farther than
// `reject_px` from it until none is rejected (at most five rounds). Empty when it fails.
cv::Mat FitLocalHomography(std::vector<cv::Point2f> camera, std::vector<cv::Point2f> projector,
                           double reject_px, int min_pixels, int* kept) {
  cv::Mat homography;
  for (int round = 0; round < 5; ++round) {
    if (static_cast<int>(camera.size()) < min_pixels) return cv::Mat();
    homography = cv::findHomography(camera, projector, 0);
    if (homography.empty()) return homography;
    std::vector<cv::Point2f> mapped;
    cv::perspectiveTransform(camera, mapped, homography);
    std::vector<cv::Point2f> camera_kept, projector_kept;
    for (size_t k = 0; k < camera.size(); ++k) {
      if (cv::norm(mapped[k] - projector[k]) <= reject_px) {
        camera_kept.push_back(camera[k]);
        projector_kept.push_back(projector[k]);
      }
    }
    *kept = static_cast<int>(camera_kept.size());
    if (camera_kept.size() == camera.size()) break;
    camera.swap(camera_kept);
    projector.swap(projector_kept);
  }
  return homography;
}

// The largest angle between two poses' board normals (the poses' z axes), degrees.
double TiltSpreadDeg(const std::vector<Vec3>& normals) {
  double spread = 0.0;
  for (size_t a = 0; a < normals.size(); ++a) {
    for (size_t b = a + 1; b < normals.size(); ++b) {
      const double cosine = std::clamp(normals[a].dot(normals[b]), -1.0, 1.0);
      spread = std::max(spread, std::acos(cosine) * 180.0 / std::numbers::pi);
    }
  }
  return spread;
}

int SeedFlags(const std::string& lens_model) {
  if (lens_model == "LENSMODEL_OPENCV4") return cv::CALIB_FIX_K3;
  if (lens_model == "LENSMODEL_OPENCV8") return cv::CALIB_RATIONAL_MODEL;
  return 0;
}

// OpenCV's seed of one device: intrinsics in mrcal's order and device_from_board per view
// (views with fewer than 6 points are left out of the seed; their pose is then nullopt).
bool SeedDevice(const std::string& lens_model, const std::vector<std::vector<cv::Point3f>>& object,
                const std::vector<std::vector<cv::Point2f>>& image, int width, int height,
                std::vector<double>* intrinsics,
                std::vector<std::optional<Eigen::Isometry3d>>* device_from_board, double* rms,
                std::string* why) {
  std::vector<std::vector<cv::Point3f>> object_used;
  std::vector<std::vector<cv::Point2f>> image_used;
  std::vector<int> used;
  for (size_t v = 0; v < object.size(); ++v) {
    if (object[v].size() < 6) continue;
    object_used.push_back(object[v]);
    image_used.push_back(image[v]);
    used.push_back(static_cast<int>(v));
  }
  if (used.size() < 2) {
    *why = "fewer than 2 poses with enough corners";
    return false;
  }
  cv::Mat camera_matrix, distortion;
  std::vector<cv::Mat> rvecs, tvecs;
  try {
    *rms = cv::calibrateCamera(object_used, image_used, cv::Size(width, height), camera_matrix,
                               distortion, rvecs, tvecs, SeedFlags(lens_model));
  } catch (const cv::Exception& error) {
    *why = error.what();
    return false;
  }
  if (!std::isfinite(*rms)) {
    *why = "OpenCV's seed error is not finite";
    return false;
  }
  const int parameter_count = LensModel::ParameterCount(lens_model);
  intrinsics->assign(parameter_count, 0.0);
  (*intrinsics)[0] = camera_matrix.at<double>(0, 0);
  (*intrinsics)[1] = camera_matrix.at<double>(1, 1);
  (*intrinsics)[2] = camera_matrix.at<double>(0, 2);
  (*intrinsics)[3] = camera_matrix.at<double>(1, 2);
  for (int k = 4; k < parameter_count && k - 4 < static_cast<int>(distortion.total()); ++k) {
    (*intrinsics)[k] = distortion.at<double>(k - 4);
  }
  device_from_board->assign(object.size(), std::nullopt);
  for (size_t u = 0; u < used.size(); ++u) {
    const double rt[6] = {rvecs[u].at<double>(0), rvecs[u].at<double>(1), rvecs[u].at<double>(2),
                          tvecs[u].at<double>(0), tvecs[u].at<double>(1), tvecs[u].at<double>(2)};
    (*device_from_board)[used[u]] = PoseFromRt(rt);
  }
  return true;
}

// The calibration's solve as libmrcal's arrays: observation 2i the camera's corners of pose i,
// 2i + 1 the projector's.
MrcalChessboardProblem ToMrcalRig(const BoardProjectorCalibration& calibration) {
  MrcalChessboardProblem problem;
  if (!mrcal_lensmodel_from_name(&problem.lens, calibration.lens_model.c_str())) {
    throw std::invalid_argument("unknown mrcal lens model '" + calibration.lens_model + "'");
  }
  const int poses = static_cast<int>(calibration.cam_from_board.size());
  const int per_board = calibration.board.CornerCount();
  if (calibration.pool.size() != static_cast<size_t>(2 * poses * per_board)) {
    throw std::invalid_argument("board projector calibration: no solve to evaluate");
  }
  problem.cameras = 2;
  problem.intrinsics = calibration.camera_intrinsics;
  problem.intrinsics.insert(problem.intrinsics.end(), calibration.projector_intrinsics.begin(),
                            calibration.projector_intrinsics.end());
  problem.extrinsics.resize(1);
  const std::array<double, 6> extrinsics = RtFromPose(calibration.projector_from_camera);
  std::memcpy(&problem.extrinsics[0], extrinsics.data(), sizeof(extrinsics));
  problem.frames.resize(poses);
  problem.observations.resize(2 * poses);
  for (int v = 0; v < poses; ++v) {
    const std::array<double, 6> rt = RtFromPose(calibration.cam_from_board[v]);
    std::memcpy(&problem.frames[v], rt.data(), sizeof(rt));
    for (int device = 0; device < 2; ++device) {
      mrcal_observation_board_t& observation = problem.observations[2 * v + device];
      observation.icam.intrinsics = device;
      observation.icam.extrinsics = device - 1;  // the camera is the reference frame
      observation.iframe = v;
    }
  }
  problem.pool.resize(calibration.pool.size());
  for (size_t k = 0; k < calibration.pool.size(); ++k) {
    const Vec3& corner = calibration.pool[k];
    problem.pool[k] = mrcal_point3_t{{corner.x(), corner.y(), corner.z()}};
  }
  problem.selections = ChessboardSelections(calibration.regularization, calibration.reject_outliers);
  problem.imager_sizes = {calibration.camera_width, calibration.camera_height,
                          calibration.projector_width, calibration.projector_height};
  problem.spacing = calibration.board.square_size;
  problem.corners_x = calibration.board.corners_x;
  problem.corners_y = calibration.board.corners_y;
  return problem;
}

// sqrt of the larger eigenvalue of a 2×2 covariance (mrcal.worst_direction_stdev).
double WorstDirection(const Eigen::Matrix2d& covariance) {
  const double a = covariance(0, 0), b = covariance(1, 0), c = covariance(1, 1);
  return std::sqrt((a + c) / 2.0 + std::sqrt((a - c) * (a - c) / 4.0 + b * b));
}

}  // namespace

bool LocateBoardCorners(const BoardProjectorOptions& options, const ChessboardSpec& board,
                        const BoardPoseCapture& capture, BoardPoseCorners* corners) {
  std::string why;
  if (!options.Check(&why) || !board.Check(&why)) throw std::invalid_argument(why);
  const StructuredLightMap& map = capture.map;
  if (map.column.size() != capture.white.size() || map.row.size() != capture.white.size()) {
    throw std::invalid_argument(capture.name + ": the decoded map and the white photo differ in size");
  }
  corners->name = capture.name;
  if (!DetectChessboard(capture.white, board, &corners->camera)) return false;
  const int count = board.CornerCount();
  corners->projector.assign(count, Vec2::Zero());
  corners->projector_found.assign(count, false);
  corners->window_pixels.assign(count, 0);
  const int half = options.homography_half_window;
  for (int k = 0; k < count; ++k) {
    const Vec2& corner = corners->camera[k];
    const int x0 = std::max(0, static_cast<int>(std::floor(corner.x())) - half);
    const int x1 = std::min(map.column.cols - 1, static_cast<int>(std::ceil(corner.x())) + half);
    const int y0 = std::max(0, static_cast<int>(std::floor(corner.y())) - half);
    const int y1 = std::min(map.column.rows - 1, static_cast<int>(std::ceil(corner.y())) + half);
    std::vector<cv::Point2f> camera_pixels, projector_pixels;
    for (int y = y0; y <= y1; ++y) {
      const float* column = map.column.ptr<float>(y);
      const float* row = map.row.ptr<float>(y);
      for (int x = x0; x <= x1; ++x) {
        if (!std::isfinite(column[x]) || !std::isfinite(row[x])) continue;
        // Pixel coordinates relative to the corner keep the fit well conditioned.
        camera_pixels.emplace_back(static_cast<float>(x - corner.x()),
                                   static_cast<float>(y - corner.y()));
        projector_pixels.emplace_back(column[x], row[x]);
      }
    }
    int kept = 0;
    const cv::Mat homography =
        FitLocalHomography(camera_pixels, projector_pixels, options.homography_reject_px,
                           options.min_window_pixels, &kept);
    if (homography.empty() || kept < options.min_window_pixels) continue;
    // The corner is the origin of the fit's camera coordinates: H · (0, 0, 1).
    const double w = homography.at<double>(2, 2);
    if (!(std::abs(w) > 0.0)) continue;
    corners->projector[k] = Vec2(homography.at<double>(0, 2) / w, homography.at<double>(1, 2) / w);
    corners->projector_found[k] = corners->projector[k].allFinite();
    corners->window_pixels[k] = kept;
  }
  return true;
}

std::string BoardProjectorSummary::BriefReport() const {
  static const char* kNames[] = {"converged", "too few poses", "parallel poses", "seed failed",
                                 "solver failed"};
  return fmt::format(
      "board projector calibration: {}; {} poses (normals spread {:.1f}°), camera {} corners "
      "({} outliers) rms {:.4f} px, max |r| {:.4f} px; projector {} corners ({} outliers or "
      "unseen) rms {:.4f} px, max |r| {:.4f} px; {:.2f} s{}{}",
      kNames[termination], poses, tilt_spread_deg, camera_corners, camera_outliers, camera_rms,
      camera_max_norm, projector_corners, projector_outliers, projector_rms, projector_max_norm,
      time_s, message.empty() ? "" : "; ", message);
}

bool CalibrateBoardProjector(const BoardProjectorOptions& options, const ChessboardSpec& board,
                             const std::vector<BoardPoseCorners>& poses, int camera_width,
                             int camera_height, int projector_width, int projector_height,
                             BoardProjectorCalibration* calibration,
                             BoardProjectorSummary* summary) {
  const auto start = Clock::now();
  std::string why;
  if (!options.Check(&why) || !board.Check(&why)) throw std::invalid_argument(why);
  if (camera_width < 1 || camera_height < 1 || projector_width < 1 || projector_height < 1)
    throw std::invalid_argument("camera and projector sizes must be at least 1×1");
  const int per_board = board.CornerCount();
  for (const BoardPoseCorners& pose : poses) {
    if (static_cast<int>(pose.camera.size()) != per_board ||
        static_cast<int>(pose.projector.size()) != per_board ||
        static_cast<int>(pose.projector_found.size()) != per_board) {
      throw std::invalid_argument("pose " + pose.name + ": corner count differs from the board's " +
                                  std::to_string(per_board));
    }
  }
  *summary = BoardProjectorSummary();
  auto finish = [&](BoardProjectorSummary::Termination termination, std::string message) {
    summary->termination = termination;
    summary->message = std::move(message);
    summary->time_s = SecondsSince(start);
    return termination == BoardProjectorSummary::kConverged;
  };
  const int pose_count = static_cast<int>(poses.size());
  summary->poses = pose_count;
  if (pose_count < options.min_poses) {
    return finish(BoardProjectorSummary::kTooFewPoses,
                  fmt::format("{} board pose{}, need at least {} differently tilted ones",
                              pose_count, pose_count == 1 ? "" : "s", options.min_poses));
  }

  // 1. Are the poses tilted differently? The board's normal per pose from its camera corners
  // (solvePnP with a rough pinhole: the normal hardly depends on the focal length).
  std::vector<cv::Point3f> board_points;
  for (int k = 0; k < per_board; ++k) {
    const Vec3 corner = board.Corner(k);
    board_points.emplace_back(corner.x(), corner.y(), 0.0f);
  }
  const double rough_focal = 0.5 * (camera_width + camera_height);
  const cv::Matx33d rough_matrix(rough_focal, 0, (camera_width - 1) / 2.0, 0, rough_focal,
                                 (camera_height - 1) / 2.0, 0, 0, 1);
  std::vector<Vec3> normals;
  for (const BoardPoseCorners& pose : poses) {
    std::vector<cv::Point2f> pixels;
    for (const Vec2& corner : pose.camera) pixels.emplace_back(corner.x(), corner.y());
    cv::Mat rvec, tvec;
    if (!cv::solvePnP(board_points, pixels, rough_matrix, cv::noArray(), rvec, tvec)) continue;
    const double rt[6] = {rvec.at<double>(0), rvec.at<double>(1), rvec.at<double>(2), 0, 0, 0};
    normals.push_back(PoseFromRt(rt).linear().col(2));
  }
  summary->tilt_spread_deg = TiltSpreadDeg(normals);
  if (summary->tilt_spread_deg < options.min_tilt_spread_deg) {
    return finish(BoardProjectorSummary::kParallelPoses,
                  fmt::format("the {} board poses are all parallel (normals within {:.1f}°, need "
                              "{:.1f}°): tilt the board differently between poses",
                              pose_count, summary->tilt_spread_deg, options.min_tilt_spread_deg));
  }

  // 2. Seeds: each device alone (OpenCV: Zhang's method), the projector's pose from the camera's
  // as the mean over poses of projector_from_board · board_from_camera.
  std::vector<std::vector<cv::Point3f>> camera_object(pose_count), projector_object(pose_count);
  std::vector<std::vector<cv::Point2f>> camera_image(pose_count), projector_image(pose_count);
  for (int v = 0; v < pose_count; ++v) {
    for (int k = 0; k < per_board; ++k) {
      camera_object[v].push_back(board_points[k]);
      camera_image[v].emplace_back(poses[v].camera[k].x(), poses[v].camera[k].y());
      if (poses[v].projector_found[k]) {
        projector_object[v].push_back(board_points[k]);
        projector_image[v].emplace_back(poses[v].projector[k].x(), poses[v].projector[k].y());
      }
    }
  }
  std::vector<double> camera_intrinsics, projector_intrinsics;
  std::vector<std::optional<Eigen::Isometry3d>> cam_from_board, projector_from_board;
  double camera_seed_rms = 0.0, projector_seed_rms = 0.0;
  if (!SeedDevice(options.lens_model, camera_object, camera_image, camera_width, camera_height,
                  &camera_intrinsics, &cam_from_board, &camera_seed_rms, &why)) {
    return finish(BoardProjectorSummary::kSeedFailed, "camera: " + why);
  }
  if (!SeedDevice(options.lens_model, projector_object, projector_image, projector_width,
                  projector_height, &projector_intrinsics, &projector_from_board,
                  &projector_seed_rms, &why)) {
    return finish(BoardProjectorSummary::kSeedFailed, "projector: " + why);
  }
  Eigen::Vector4d quaternion_sum = Eigen::Vector4d::Zero();
  Vec3 translation_sum = Vec3::Zero();
  int seeds = 0;
  for (int v = 0; v < pose_count; ++v) {
    if (!cam_from_board[v] || !projector_from_board[v]) continue;
    const Eigen::Isometry3d projector_from_camera =
        *projector_from_board[v] * cam_from_board[v]->inverse();
    Eigen::Quaterniond q(projector_from_camera.linear());
    if (seeds > 0 && q.coeffs().dot(quaternion_sum) < 0.0) q.coeffs() *= -1.0;
    quaternion_sum += q.coeffs();
    translation_sum += projector_from_camera.translation();
    ++seeds;
  }
  if (seeds == 0) return finish(BoardProjectorSummary::kSeedFailed, "no pose seeds both devices");
  Eigen::Isometry3d projector_from_camera = Eigen::Isometry3d::Identity();
  projector_from_camera.linear() =
      Eigen::Quaterniond(Eigen::Vector4d(quaternion_sum.normalized())).toRotationMatrix();
  projector_from_camera.translation() = translation_sum / seeds;

  // 3. One mrcal solve of both devices.
  calibration->lens_model = options.lens_model;
  calibration->camera_intrinsics = camera_intrinsics;
  calibration->projector_intrinsics = projector_intrinsics;
  calibration->camera_width = camera_width;
  calibration->camera_height = camera_height;
  calibration->projector_width = projector_width;
  calibration->projector_height = projector_height;
  calibration->projector_from_camera = projector_from_camera;
  calibration->board = board;
  calibration->regularization = options.regularization;
  calibration->reject_outliers = options.reject_outliers;
  calibration->cam_from_board.assign(pose_count, Eigen::Isometry3d::Identity());
  for (int v = 0; v < pose_count; ++v) {
    // A pose the camera's seed left out (it cannot: every pose has all corners) stays identity.
    if (cam_from_board[v]) calibration->cam_from_board[v] = *cam_from_board[v];
  }
  calibration->pool.clear();
  for (int v = 0; v < pose_count; ++v) {
    for (int k = 0; k < per_board; ++k)
      calibration->pool.emplace_back(poses[v].camera[k].x(), poses[v].camera[k].y(), 1.0);
    for (int k = 0; k < per_board; ++k) {
      calibration->pool.push_back(poses[v].projector_found[k]
                                      ? Vec3(poses[v].projector[k].x(), poses[v].projector[k].y(), 1.0)
                                      : Vec3(0.0, 0.0, -1.0));
    }
  }
  MrcalChessboardProblem problem = ToMrcalRig(*calibration);
  const mrcal_problem_constants_t constants = kChessboardConstants;
  const mrcal_stats_t stats = mrcal_optimize(
      nullptr, 0, nullptr, 0, problem.intrinsics.data(), problem.extrinsics.data(),
      problem.frames.data(), nullptr, nullptr, problem.cameras, problem.Extrinsics(),
      problem.Frames(), 0, 0, problem.observations.data(), nullptr, problem.Observations(), 0,
      problem.pool.data(), &problem.lens, problem.imager_sizes.data(), problem.selections,
      &constants, problem.spacing, problem.corners_x, problem.corners_y, options.verbose, false);
  if (!(stats.rms_reproj_error__pixels >= 0.0) || !std::isfinite(stats.rms_reproj_error__pixels)) {
    return finish(BoardProjectorSummary::kSolverFailed, "mrcal_optimize failed");
  }
  for (double value : problem.intrinsics) {
    if (!std::isfinite(value))
      return finish(BoardProjectorSummary::kSolverFailed, "mrcal_optimize gave non-finite intrinsics");
  }
  const int parameter_count = static_cast<int>(camera_intrinsics.size());
  calibration->camera_intrinsics.assign(problem.intrinsics.begin(),
                                        problem.intrinsics.begin() + parameter_count);
  calibration->projector_intrinsics.assign(problem.intrinsics.begin() + parameter_count,
                                           problem.intrinsics.end());
  calibration->projector_from_camera = PoseFromRt(&problem.extrinsics[0].r.x);
  for (int v = 0; v < pose_count; ++v)
    calibration->cam_from_board[v] = PoseFromRt(&problem.frames[v].r.x);
  for (size_t k = 0; k < problem.pool.size(); ++k)
    calibration->pool[k] = Vec3(problem.pool[k].x, problem.pool[k].y, problem.pool[k].z);

  // 4. Residuals, by projecting the board through the fitted lenses.
  std::optional<LensModel> camera_lens, projector_lens;
  try {
    camera_lens.emplace(options.lens_model, calibration->camera_intrinsics);
    projector_lens.emplace(options.lens_model, calibration->projector_intrinsics);
  } catch (const std::invalid_argument& error) {
    return finish(BoardProjectorSummary::kSolverFailed, std::string("mrcal_optimize: ") + error.what());
  }
  double squares[2] = {0.0, 0.0};
  int inliers[2] = {0, 0};
  summary->pose_camera_rms.assign(pose_count, 0.0);
  summary->pose_projector_rms.assign(pose_count, 0.0);
  summary->camera_residuals.assign(pose_count, {});
  summary->projector_residuals.assign(pose_count, {});
  for (int v = 0; v < pose_count; ++v) {
    for (int device = 0; device < 2; ++device) {
      const Eigen::Isometry3d device_from_board =
          device == 0 ? calibration->cam_from_board[v]
                      : calibration->projector_from_camera * calibration->cam_from_board[v];
      const LensModel& lens = device == 0 ? *camera_lens : *projector_lens;
      std::vector<Vec2>& residuals =
          device == 0 ? summary->camera_residuals[v] : summary->projector_residuals[v];
      double pose_squares = 0.0;
      int pose_inliers = 0;
      for (int k = 0; k < per_board; ++k) {
        const Vec3& observed = calibration->pool[(2 * v + device) * per_board + k];
        const bool seen = device == 0 || poses[v].projector_found[k];
        const Vec2 residual =
            seen ? Vec2(Vec2(observed.x(), observed.y()) -
                        lens.Project(device_from_board * board.Corner(k)))
                 : Vec2::Constant(std::numeric_limits<double>::quiet_NaN());
        residuals.push_back(residual);
        if (!seen) {
          ++summary->projector_outliers;
          continue;
        }
        (device == 0 ? summary->camera_corners : summary->projector_corners) += 1;
        if (observed.z() < 0.0) {
          (device == 0 ? summary->camera_outliers : summary->projector_outliers) += 1;
          continue;
        }
        const double squared = residual.squaredNorm();
        double& largest = device == 0 ? summary->camera_max_norm : summary->projector_max_norm;
        largest = std::max(largest, std::sqrt(squared));
        pose_squares += squared;
        ++pose_inliers;
        squares[device] += squared;
        ++inliers[device];
      }
      (device == 0 ? summary->pose_camera_rms : summary->pose_projector_rms)[v] =
          pose_inliers ? std::sqrt(pose_squares / (2.0 * pose_inliers)) : 0.0;
    }
  }
  if (inliers[0] == 0 || inliers[1] == 0)
    return finish(BoardProjectorSummary::kSolverFailed, "every corner of a device is an outlier");
  summary->camera_rms = std::sqrt(squares[0] / (2.0 * inliers[0]));
  summary->projector_rms = std::sqrt(squares[1] / (2.0 * inliers[1]));
  return finish(BoardProjectorSummary::kConverged, "");
}

// Device 0 (the camera, at the reference) or 1 (the projector) as a .cameramodel carrying the
// joint solve's optimization inputs.
namespace {
CameraModel DeviceModel(const BoardProjectorCalibration& rig, int device) {
  CameraModel model;
  model.lens_model = rig.lens_model;
  model.intrinsics = device == 0 ? rig.camera_intrinsics : rig.projector_intrinsics;
  model.width = device == 0 ? rig.camera_width : rig.projector_width;
  model.height = device == 0 ? rig.camera_height : rig.projector_height;
  if (device == 1) model.cam_from_ref = rig.projector_from_camera;
  model.optimization_inputs = MrcalOptimizationInputs(ToMrcalRig(rig), rig.lens_model);
  model.icam_intrinsics = device;
  return model;
}
}  // namespace

CameraModel BoardProjectorCalibration::CameraModelOut() const { return DeviceModel(*this, 0); }

CameraModel BoardProjectorCalibration::ProjectorModelOut() const { return DeviceModel(*this, 1); }

bool BoardProjectorUncertainty(const BoardProjectorCalibration& calibration,
                               ProjectionUncertaintyMap* camera_map,
                               ProjectionUncertaintyMap* projector_map, std::string* why) {
  MrcalChessboardProblem problem;
  try {
    problem = ToMrcalRig(calibration);
  } catch (const std::invalid_argument& error) {
    *why = error.what();
    return false;
  }
  std::vector<double> x, values;
  std::vector<int> column_starts, rows;
  if (!problem.Evaluate(&x, &column_starts, &rows, &values)) {
    *why = "mrcal_optimizer_callback failed on the board solve";
    return false;
  }
  // Var(b*)/σ² = (JᵀJ)⁻¹ J_obsᵀJ_obs (JᵀJ)⁻¹ in mrcal's packed state (projection_uncertainty.h).
  const int state_count = problem.StateCount();
  const int board_measurements = problem.BoardMeasurementCount();
  Eigen::MatrixXd jtj = Eigen::MatrixXd::Zero(state_count, state_count);
  Eigen::MatrixXd jtj_observations = Eigen::MatrixXd::Zero(state_count, state_count);
  for (size_t m = 0; m + 1 < column_starts.size(); ++m) {
    for (int i = column_starts[m]; i < column_starts[m + 1]; ++i) {
      for (int k = column_starts[m]; k < column_starts[m + 1]; ++k) {
        const double product = values[i] * values[k];
        jtj(rows[i], rows[k]) += product;
        if (static_cast<int>(m) < board_measurements) jtj_observations(rows[i], rows[k]) += product;
      }
    }
  }
  const Eigen::LLT<Eigen::MatrixXd> factor(jtj);
  if (factor.info() != Eigen::Success) {
    *why = "the board solve's JᵀJ is not positive definite (degenerate poses)";
    return false;
  }
  Eigen::MatrixXd covariance = factor.solve(factor.solve(jtj_observations).transpose());
  covariance = 0.5 * (covariance + covariance.transpose()).eval();
  Eigen::VectorXd scale = Eigen::VectorXd::Ones(state_count);
  mrcal_unpack_solver_state_vector(scale.data(), problem.cameras, problem.Extrinsics(),
                                   problem.Frames(), 0, 0, problem.selections, &problem.lens);
  double sum = 0.0, sum_squares = 0.0;
  int count = 0;
  for (size_t k = 0; k < problem.pool.size(); ++k) {
    if (!(problem.pool[k].z > 0.0)) continue;
    for (int axis = 0; axis < 2; ++axis) {
      sum += x[2 * k + axis];
      sum_squares += x[2 * k + axis] * x[2 * k + axis];
      ++count;
    }
  }
  if (count == 0) {
    *why = "every corner is an outlier";
    return false;
  }
  const double sigma = std::sqrt(std::max(0.0, sum_squares / count - (sum / count) * (sum / count)));

  // A direction fixed in device `device`'s frame, looking out to infinity: it goes into every
  // board's frame with the optimal poses and back with the solve's, the mean is carried into the
  // device with the solve's extrinsics, and projected with the solve's lens (mrcal 2.2's
  // mean-frames). Only rotations move a point at infinity.
  const double share = 1.0 / problem.Frames();
  const int parameter_count = static_cast<int>(calibration.camera_intrinsics.size());
  auto stdev = [&](int device, const Vec2& pixel) {
    const std::vector<double>& intrinsics =
        device == 0 ? calibration.camera_intrinsics : calibration.projector_intrinsics;
    const LensModel lens(calibration.lens_model, intrinsics);
    Vec3 direction;
    if (!lens.Unproject(&pixel, 1, &direction) || !direction.allFinite() || direction.norm() == 0.0)
      return std::numeric_limits<double>::quiet_NaN();
    const Vec3 v_device = direction.normalized();
    const Eigen::Matrix3d device_from_ref =
        device == 0 ? Eigen::Matrix3d::Identity().eval()
                    : Eigen::Matrix3d(calibration.projector_from_camera.linear());
    const Vec3 v_ref = device_from_ref.transpose() * v_device;
    Eigen::Matrix<double, 2, Eigen::Dynamic> gradient =
        Eigen::Matrix<double, 2, Eigen::Dynamic>::Zero(2, state_count);
    Eigen::Matrix<double, 2, 3, Eigen::RowMajor> dq_dp;
    Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor> dq_dintrinsics(2, parameter_count);
    mrcal_point2_t q;
    mrcal_project(&q, reinterpret_cast<mrcal_point3_t*>(dq_dp.data()), dq_dintrinsics.data(),
                  reinterpret_cast<const mrcal_point3_t*>(v_device.data()), 1, &problem.lens,
                  intrinsics.data());
    gradient.middleCols(problem.StateIndexIntrinsics(device), parameter_count) = dq_dintrinsics;
    if (device == 1) {
      const std::array<double, 6> rt = RtFromPose(calibration.projector_from_camera);
      Eigen::Matrix<double, 3, 3, Eigen::RowMajor> dp_dr;
      Vec3 rotated;
      mrcal_rotate_point_r(rotated.data(), dp_dr.data(), nullptr, rt.data(), v_ref.data());
      gradient.middleCols<3>(problem.StateIndexExtrinsics(1)) = dq_dp * dp_dr;
    }
    for (int v = 0; v < problem.Frames(); ++v) {
      const std::array<double, 6> rt = RtFromPose(calibration.cam_from_board[v]);
      Vec3 v_board, back;
      Eigen::Matrix<double, 3, 3, Eigen::RowMajor> dp_dr;
      mrcal_rotate_point_r_inverted(v_board.data(), nullptr, nullptr, rt.data(), v_ref.data());
      mrcal_rotate_point_r(back.data(), dp_dr.data(), nullptr, rt.data(), v_board.data());
      gradient.middleCols<3>(problem.StateIndexFrames() + 6 * v) =
          share * dq_dp * device_from_ref * dp_dr;
    }
    const Eigen::Matrix<double, 2, Eigen::Dynamic> packed = gradient * scale.asDiagonal();
    return WorstDirection(sigma * sigma * packed * covariance * packed.transpose());
  };
  *camera_map = MapProjectionUncertainty([&](const Vec2& pixel) { return stdev(0, pixel); }, sigma,
                                         calibration.camera_width, calibration.camera_height);
  *projector_map =
      MapProjectionUncertainty([&](const Vec2& pixel) { return stdev(1, pixel); }, sigma,
                               calibration.projector_width, calibration.projector_height);
  return true;
}

}  // namespace procam
