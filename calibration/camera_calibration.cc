#include "calibration/camera_calibration.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <stdexcept>

#include "base/camera_model.h"
#include "base/io.h"
#include "base/option_table.h"
#include "base/parse.h"
#include "base/timing.h"
#include "calibration/mrcal_chessboard.h"
#include "calibration/pose_math.h"

namespace procam {

void ChessboardSpec::Declare(OptionTable* table, const std::string& what) {
  int* columns = &corners_x;
  int* rows = &corners_y;
  table
      ->Custom(
          "corners",
          [columns, rows] { return std::to_string(*columns) + "x" + std::to_string(*rows); },
          [columns, rows](const std::string& text, std::string* why) {
            try {
              const std::array<int, 2> sides =
                  ParseSize("corners", text, "COLUMNSxROWS of inner corners, e.g. 9x6", 2, 100);
              *columns = sides[0];
              *rows = sides[1];
              return true;
            } catch (const IoError& error) {
              *why = std::string(error.what()).substr(std::string("corners: ").size());
              return false;
            }
          },
          "COLUMNSxROWS, each in [2, 100]", what + " inner corners")
      .Number("square", &square_size, OptionTable::Interval::AboveMin(0.0, 10.0), "m",
              what + " square size");
}

bool ChessboardSpec::Check(std::string* why) const {
  // The detector's time grows with the grid: a board beyond 100 corners a side is a typing
  // error, not a board.
  if (corners_x < 2 || corners_y < 2 || corners_x > 100 || corners_y > 100) {
    *why = "chessboard: corners_x and corners_y must be in [2, 100]";
    return false;
  }
  if (!(square_size > 0.0) || !std::isfinite(square_size)) {
    *why = "chessboard: square_size must be a positive number of metres";
    return false;
  }
  return true;
}

Vec3 ChessboardSpec::Corner(int k) const {
  return Vec3((k % corners_x) * square_size, (k / corners_x) * square_size, 0.0);
}

cv::Mat ChessboardGrey(const cv::Mat& image) {
  cv::Mat grey = image;
  if (grey.channels() == 3) cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  if (grey.channels() == 4) cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  if (grey.depth() != CV_8U) {
    // Scale to the full 8-bit range; the detectors work on 8-bit images.
    double low = 0.0, high = 0.0;
    cv::minMaxLoc(grey, &low, &high);
    cv::Mat eight;
    grey.convertTo(eight, CV_8U, high > low ? 255.0 / (high - low) : 1.0,
                   high > low ? -255.0 * low / (high - low) : 0.0);
    grey = eight;
  }
  return grey;
}

namespace {

// OpenCV's classic search (adaptive thresholds times dilations, then grouping quads) costs in
// proportion to the image's area, and on a board seen at an angle it runs through many of its
// levels: 24 s on one 1280x800 photo (docs/chessboard.md). Photos wider than this are searched at
// this width first; the corners found there are carried back to the full photo, where
// cornerSubPix refines them, so their accuracy is the full photo's. 800 px keeps a 10 px square
// of a 1280 px photo above the 6 px the detector needs (OpenCV's minimum quad size is ~25 px^2).
constexpr int kChessboardSearchWidth = 800;  // pixels

bool FindChessboardCorners(const cv::Mat& grey, const cv::Size& pattern,
                           std::vector<cv::Point2f>* found) {
  const int flags = cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE;
  if (grey.cols > kChessboardSearchWidth) {
    const double scale = static_cast<double>(kChessboardSearchWidth) / grey.cols;
    cv::Mat small;
    cv::resize(grey, small, cv::Size(), scale, scale, cv::INTER_AREA);
    if (cv::findChessboardCorners(small, pattern, *found, flags)) {
      // Pixel centres: a pixel's centre x in the small image is at (x + 0.5) / scale - 0.5.
      for (cv::Point2f& point : *found) {
        point.x = static_cast<float>((point.x + 0.5) / scale - 0.5);
        point.y = static_cast<float>((point.y + 0.5) / scale - 0.5);
      }
      // As findChessboardCorners ends on its own photo: a first refinement in a 5x5 window.
      cv::cornerSubPix(
          grey, *found, cv::Size(2, 2), cv::Size(-1, -1),
          cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::MAX_ITER, 15, 0.1));
      return true;
    }
  }
  // Not found small (squares too small there), or a photo small already: the full photo.
  return cv::findChessboardCorners(grey, pattern, *found, flags);
}

}  // namespace

bool DetectChessboard(const cv::Mat& image, const ChessboardSpec& board,
                      std::vector<Vec2>* corners) {
  const cv::Mat grey = ChessboardGrey(image);
  const cv::Size pattern(board.corners_x, board.corners_y);
  std::vector<cv::Point2f> found;
  if (!FindChessboardCorners(grey, pattern, &found)) return false;
  // Half a square in pixels bounds the search window, so it never reaches the next corner.
  double spacing = 1e9;
  for (int k = 0; k + 1 < static_cast<int>(found.size()); ++k) {
    if ((k + 1) % board.corners_x == 0) continue;
    spacing = std::min(spacing, static_cast<double>(cv::norm(found[k + 1] - found[k])));
  }
  const int half = std::clamp(static_cast<int>(spacing * 0.4), 2, 11);
  cv::cornerSubPix(grey, found, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  corners->resize(found.size());
  for (size_t k = 0; k < found.size(); ++k) (*corners)[k] = Vec2(found[k].x, found[k].y);
  return true;
}

void CameraCalibrationOptions::Declare(OptionTable* table) {
  table
      ->Choice<std::string>("lens-model", &lens_model,
                            {{"LENSMODEL_OPENCV4", "LENSMODEL_OPENCV4"},
                             {"LENSMODEL_OPENCV5", "LENSMODEL_OPENCV5"},
                             {"LENSMODEL_OPENCV8", "LENSMODEL_OPENCV8"}},
                            "the lens's distortion model (mrcal)")
      .NegatedFlag("no-outlier-rejection", &reject_outliers, "keep every corner");
}

bool CameraCalibrationOptions::Check(std::string* why) const {
  if (lens_model != "LENSMODEL_OPENCV4" && lens_model != "LENSMODEL_OPENCV5" &&
      lens_model != "LENSMODEL_OPENCV8") {
    *why = "lens_model must be LENSMODEL_OPENCV4, LENSMODEL_OPENCV5 or LENSMODEL_OPENCV8, not '" +
           lens_model + "'";
    return false;
  }
  if (min_views < 3) {
    *why = "min_views must be at least 3";
    return false;
  }
  return true;
}

std::string CameraCalibrationSummary::BriefReport() const {
  static const char* kNames[] = {"converged", "too few views", "seed failed", "solver failed"};
  char line[512];
  std::snprintf(line, sizeof(line),
                "camera calibration: %s; %d views, %d corners, %d outliers; rms %.4f px per "
                "coordinate (seed %.4f), median |r| %.4f px, max |r| %.4f px; %.2f s%s%s",
                kNames[termination], views, corners, outliers, rms, seed_rms, median_norm, max_norm,
                time_s, message.empty() ? "" : "; ", message.c_str());
  return line;
}

namespace {

// OpenCV's flags for the distortion terms of an mrcal OpenCV lens model.
int SeedFlags(const std::string& lens_model) {
  if (lens_model == "LENSMODEL_OPENCV4") return cv::CALIB_FIX_K3;
  if (lens_model == "LENSMODEL_OPENCV8") return cv::CALIB_RATIONAL_MODEL;
  return 0;  // OPENCV5: k1, k2, p1, p2, k3
}

// The calibration's residuals over the inliers (pool weight ≥ 0), by projecting the board at
// mrcal's frames through the fitted lens: per view and overall. Sets the board poses. False when
// every corner is an outlier.
bool ResidualStatistics(const ChessboardSpec& board, const LensModel& lens_fitted,
                        const std::vector<mrcal_pose_t>& frames, const std::vector<mrcal_point3_t>& pool,
                        CameraCalibration* calibration, CameraCalibrationSummary* summary) {
  const int view_count = static_cast<int>(frames.size());
  const int per_board = board.CornerCount();
  calibration->cam_from_board.resize(view_count);
  std::vector<double> norms;
  double sum_squares = 0.0;
  summary->view_rms.assign(view_count, 0.0);
  for (int v = 0; v < view_count; ++v) {
    const Eigen::Isometry3d cam_from_board = PoseFromRt(&frames[v].r.x);
    calibration->cam_from_board[v] = cam_from_board;
    double view_squares = 0.0;
    int view_inliers = 0;
    for (int k = 0; k < per_board; ++k) {
      const mrcal_point3_t& observed = pool[v * per_board + k];
      if (observed.z < 0.0) {
        ++summary->outliers;
        continue;
      }
      const Vec3 corner_in_cam = cam_from_board * board.Corner(k);
      if (!(corner_in_cam.z() > 0.0)) {
        ++summary->outliers;
        continue;
      }
      const Vec2 pixel = lens_fitted.Project(corner_in_cam);
      const double squared = (pixel - Vec2(observed.x, observed.y)).squaredNorm();
      norms.push_back(std::sqrt(squared));
      sum_squares += squared;
      view_squares += squared;
      ++view_inliers;
    }
    summary->view_rms[v] = view_inliers ? std::sqrt(view_squares / (2.0 * view_inliers)) : 0.0;
  }
  if (norms.empty()) return false;
  summary->rms_norm = std::sqrt(sum_squares / norms.size());
  summary->rms = summary->rms_norm / std::sqrt(2.0);
  std::sort(norms.begin(), norms.end());
  summary->median_norm = norms[norms.size() / 2];
  summary->max_norm = norms.back();
  return true;
}

}  // namespace

bool CalibrateCamera(const CameraCalibrationOptions& options, const ChessboardSpec& board,
                     const std::vector<ChessboardView>& views, int width, int height,
                     CameraCalibration* calibration, CameraCalibrationSummary* summary) {
  const auto start = Clock::now();
  std::string why;
  if (!options.Check(&why) || !board.Check(&why)) throw std::invalid_argument(why);
  if (width < 1 || height < 1) throw std::invalid_argument("image size must be at least 1×1");
  const int per_board = board.CornerCount();
  for (const ChessboardView& view : views) {
    if (static_cast<int>(view.corners.size()) != per_board) {
      throw std::invalid_argument("view " + view.name + ": " + std::to_string(view.corners.size()) +
                                  " corners, the board has " + std::to_string(per_board));
    }
  }
  *summary = CameraCalibrationSummary();
  auto finish = [&](CameraCalibrationSummary::Termination termination, std::string message) {
    summary->termination = termination;
    summary->message = std::move(message);
    summary->time_s =
        SecondsSince(start);
    return termination == CameraCalibrationSummary::kConverged;
  };
  const int view_count = static_cast<int>(views.size());
  summary->views = view_count;
  summary->corners = view_count * per_board;
  if (view_count < options.min_views) {
    return finish(CameraCalibrationSummary::kTooFewViews,
                  std::to_string(view_count) + " views, need " + std::to_string(options.min_views));
  }

  // 1. Seed with OpenCV (Zhang's method and Levenberg–Marquardt on the same model).
  std::vector<std::vector<cv::Point3f>> object_points(view_count);
  std::vector<std::vector<cv::Point2f>> image_points(view_count);
  for (int v = 0; v < view_count; ++v) {
    for (int k = 0; k < per_board; ++k) {
      const Vec3 corner = board.Corner(k);
      object_points[v].emplace_back(corner.x(), corner.y(), 0.0f);
      image_points[v].emplace_back(views[v].corners[k].x(), views[v].corners[k].y());
    }
  }
  cv::Mat camera_matrix, distortion;
  std::vector<cv::Mat> rvecs, tvecs;
  try {
    summary->seed_rms =
        cv::calibrateCamera(object_points, image_points, cv::Size(width, height), camera_matrix,
                            distortion, rvecs, tvecs, SeedFlags(options.lens_model));
  } catch (const cv::Exception& error) {
    return finish(CameraCalibrationSummary::kSeedFailed, error.what());
  }
  if (!std::isfinite(summary->seed_rms)) {
    return finish(CameraCalibrationSummary::kSeedFailed, "OpenCV's seed error is not finite");
  }

  // 2. Refine with mrcal: one camera at the reference, the board poses are mrcal's frames.
  mrcal_lensmodel_t lens;
  if (!mrcal_lensmodel_from_name(&lens, options.lens_model.c_str())) {
    throw std::invalid_argument("unknown lens " + options.lens_model);
  }
  const int parameter_count = LensModel::ParameterCount(options.lens_model);
  std::vector<double> intrinsics(parameter_count, 0.0);
  intrinsics[0] = camera_matrix.at<double>(0, 0);
  intrinsics[1] = camera_matrix.at<double>(1, 1);
  intrinsics[2] = camera_matrix.at<double>(0, 2);
  intrinsics[3] = camera_matrix.at<double>(1, 2);
  for (int k = 4; k < parameter_count && k - 4 < static_cast<int>(distortion.total()); ++k) {
    intrinsics[k] = distortion.at<double>(k - 4);
  }
  std::vector<mrcal_pose_t> frames(view_count);
  for (int v = 0; v < view_count; ++v) {
    frames[v] = mrcal_pose_t{{{rvecs[v].at<double>(0), rvecs[v].at<double>(1),
                               rvecs[v].at<double>(2)}},
                             {{tvecs[v].at<double>(0), tvecs[v].at<double>(1),
                               tvecs[v].at<double>(2)}}};
  }
  std::vector<mrcal_observation_board_t> observations(view_count);
  // Pool of shape (views, corners_y, corners_x): x, y, weight (< 0 marks an outlier).
  std::vector<mrcal_point3_t> pool(static_cast<size_t>(view_count) * per_board);
  for (int v = 0; v < view_count; ++v) {
    observations[v].icam.intrinsics = 0;
    observations[v].icam.extrinsics = -1;  // the camera is the reference frame
    observations[v].iframe = v;
    for (int k = 0; k < per_board; ++k) {
      pool[v * per_board + k] =
          mrcal_point3_t{{views[v].corners[k].x(), views[v].corners[k].y(), 1.0}};
    }
  }
  const mrcal_problem_selections_t selections =
      ChessboardSelections(options.regularization, options.reject_outliers);
  const mrcal_problem_constants_t constants = kChessboardConstants;
  const int imager_size[2] = {width, height};
  const mrcal_stats_t stats = mrcal_optimize(
      nullptr, 0, nullptr, 0, intrinsics.data(), nullptr, frames.data(), nullptr, nullptr,
      /*Ncameras_intrinsics=*/1, /*Ncameras_extrinsics=*/0, view_count, /*Npoints=*/0,
      /*Npoints_fixed=*/0, observations.data(), nullptr, view_count, 0, pool.data(), &lens,
      imager_size, selections, &constants, board.square_size, board.corners_x, board.corners_y,
      options.verbose, false);
  if (!(stats.rms_reproj_error__pixels >= 0.0) || !std::isfinite(stats.rms_reproj_error__pixels)) {
    return finish(CameraCalibrationSummary::kSolverFailed, "mrcal_optimize failed");
  }
  for (double value : intrinsics) {
    if (!std::isfinite(value)) {
      return finish(CameraCalibrationSummary::kSolverFailed, "mrcal_optimize gave non-finite intrinsics");
    }
  }

  // 3. Residual statistics over the inliers, by projecting the board with the result.
  std::optional<LensModel> fitted;
  try {
    fitted.emplace(options.lens_model, intrinsics);
  } catch (const std::invalid_argument& error) {
    return finish(CameraCalibrationSummary::kSolverFailed, std::string("mrcal_optimize: ") + error.what());
  }
  const LensModel& lens_fitted = *fitted;
  calibration->lens_model = options.lens_model;
  calibration->intrinsics = intrinsics;
  calibration->width = width;
  calibration->height = height;
  calibration->solve.board = board;
  calibration->solve.corners.resize(pool.size());
  for (size_t k = 0; k < pool.size(); ++k) {
    calibration->solve.corners[k] = Vec3(pool[k].x, pool[k].y, pool[k].z);
  }
  calibration->solve.regularization = options.regularization;
  calibration->solve.reject_outliers = options.reject_outliers;
  if (!ResidualStatistics(board, lens_fitted, frames, pool, calibration, summary)) {
    return finish(CameraCalibrationSummary::kSolverFailed, "every corner is an outlier");
  }
  return finish(CameraCalibrationSummary::kConverged, "");
}

CameraModel CameraCalibration::Model() const {
  CameraModel model;
  model.lens_model = lens_model;
  model.intrinsics = intrinsics;
  model.width = width;
  model.height = height;
  if (!solve.corners.empty()) {
    model.optimization_inputs = MrcalOptimizationInputs(*this);
    model.icam_intrinsics = 0;
  }
  return model;  // the camera is the reference frame
}

void WriteCalibrationModel(const std::filesystem::path& path,
                           const CameraCalibration& calibration) {
  WriteCameraModelFile(path, calibration.Model(),
                       "procam camera model (procam calibrate camera; mrcal_optimize); the camera "
                       "is the reference frame");
}

}  // namespace procam
