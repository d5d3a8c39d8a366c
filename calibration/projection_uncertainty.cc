#include "calibration/projection_uncertainty.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "calibration/mrcal_chessboard.h"

extern "C" {
#include <mrcal/poseutils.h>
}
#include <suitesparse/cholmod.h>  // the cholmod_sparse that carries Jᵀ (the struct only)

namespace procam {
namespace {

// sqrt of the larger eigenvalue of a 2×2 covariance (mrcal.worst_direction_stdev).
double WorstDirection(const Eigen::Matrix2d& covariance) {
  const double a = covariance(0, 0), b = covariance(1, 0), c = covariance(1, 1);
  return std::sqrt((a + c) / 2.0 + std::sqrt((a - c) * (a - c) / 4.0 + b * b));
}

}  // namespace

bool ProjectionUncertainty::Compute(const CameraCalibration& calibration, std::string* why) {
  MrcalChessboardProblem problem;
  try {
    problem = ToMrcal(calibration);
  } catch (const std::invalid_argument& error) {
    *why = error.what();
    return false;
  }
  const int state_count = problem.StateCount();
  const int measurement_count = problem.MeasurementCount();
  const int board_measurements = problem.BoardMeasurementCount();
  const int nonzeros = problem.JacobianNonZeros();

  // J at the optimum, as Jᵀ in compressed columns (one column per measurement), in mrcal's
  // packed state b* = D⁻¹ b, the same call mrcal.optimizer_callback makes.
  std::vector<double> b_packed(state_count), x(measurement_count), values(nonzeros);
  std::vector<int> column_starts(measurement_count + 1), rows(nonzeros);
  cholmod_sparse jt{};
  jt.nrow = state_count;
  jt.ncol = measurement_count;
  jt.nzmax = nonzeros;
  jt.p = column_starts.data();
  jt.i = rows.data();
  jt.x = values.data();
  jt.stype = 0;
  jt.itype = CHOLMOD_INT;
  jt.xtype = CHOLMOD_REAL;
  jt.dtype = CHOLMOD_DOUBLE;
  jt.sorted = 1;
  jt.packed = 1;
  if (!mrcal_optimizer_callback(b_packed.data(), state_count * sizeof(double), x.data(),
                                measurement_count * sizeof(double), &jt, problem.intrinsics.data(),
                                nullptr, problem.frames.data(), nullptr, nullptr,
                                /*Ncameras_intrinsics=*/1, /*Ncameras_extrinsics=*/0,
                                problem.Frames(), 0, 0, problem.observations.data(), nullptr,
                                problem.Frames(), 0, problem.pool.data(), &problem.lens,
                                problem.imager_sizes.data(), problem.selections, &kChessboardConstants,
                                problem.spacing, problem.corners_x, problem.corners_y, false)) {
    *why = "mrcal_optimizer_callback failed on the chessboard solve";
    return false;
  }

  // JᵀJ over every measurement and J_obsᵀJ_obs over the corners' (the leading rows; an outlier's
  // rows are zero). Each row of J touches only the lens and one board: a few dozen entries.
  Eigen::MatrixXd jtj = Eigen::MatrixXd::Zero(state_count, state_count);
  Eigen::MatrixXd jtj_observations = Eigen::MatrixXd::Zero(state_count, state_count);
  for (int m = 0; m < measurement_count; ++m) {
    for (int i = column_starts[m]; i < column_starts[m + 1]; ++i) {
      for (int k = column_starts[m]; k < column_starts[m + 1]; ++k) {
        const double product = values[i] * values[k];
        jtj(rows[i], rows[k]) += product;
        if (m < board_measurements) jtj_observations(rows[i], rows[k]) += product;
      }
    }
  }
  const Eigen::LLT<Eigen::MatrixXd> factor(jtj);
  if (factor.info() != Eigen::Success) {
    *why = "the chessboard solve's JᵀJ is not positive definite (degenerate views)";
    return false;
  }
  // Var(b*)/σ² = (JᵀJ)⁻¹ J_obsᵀJ_obs (JᵀJ)⁻¹, symmetric.
  const Eigen::MatrixXd left = factor.solve(jtj_observations);
  packed_covariance_ = factor.solve(left.transpose());
  packed_covariance_ = 0.5 * (packed_covariance_ + packed_covariance_.transpose()).eval();
  if (!packed_covariance_.allFinite()) {
    *why = "the chessboard solve's parameter covariance is not finite";
    return false;
  }

  // D: mrcal's unpacking of a vector of ones.
  scale_ = Eigen::VectorXd::Ones(state_count);
  mrcal_unpack_solver_state_vector(scale_.data(), 1, 0, problem.Frames(), 0, 0, problem.selections,
                                   &problem.lens);

  // σ: numpy.std of the inlier corners' residuals (x and y together), mrcal's estimate.
  double sum = 0.0, sum_squares = 0.0;
  int count = 0;
  for (size_t k = 0; k < problem.pool.size(); ++k) {
    if (!(problem.pool[k].z > 0.0)) continue;
    for (int axis = 0; axis < 2; ++axis) {
      const double residual = x[2 * k + axis];
      sum += residual;
      sum_squares += residual * residual;
      ++count;
    }
  }
  if (count == 0) {
    *why = "every corner of the chessboard solve is an outlier";
    return false;
  }
  const double mean = sum / count;
  sigma_ = std::sqrt(std::max(0.0, sum_squares / count - mean * mean));

  lens_model_ = calibration.lens_model;
  intrinsics_ = calibration.intrinsics;
  cam_from_board_ = calibration.cam_from_board;
  state_index_intrinsics_ = problem.StateIndexIntrinsics();
  state_index_frames_ = problem.StateIndexFrames();
  return true;
}

Eigen::MatrixXd ProjectionUncertainty::IntrinsicsCovariance() const {
  const int n = static_cast<int>(intrinsics_.size());
  const Eigen::VectorXd d = scale_.segment(state_index_intrinsics_, n);
  return sigma_ * sigma_ * d.asDiagonal() *
         packed_covariance_.block(state_index_intrinsics_, state_index_intrinsics_, n, n) *
         d.asDiagonal();
}

Eigen::Matrix<double, 2, Eigen::Dynamic> ProjectionUncertainty::ProjectionGradient(
    const Vec3& p_in_cam, bool at_infinity) const {
  Eigen::Matrix<double, 2, Eigen::Dynamic> gradient =
      Eigen::Matrix<double, 2, Eigen::Dynamic>::Zero(2, state_count());
  mrcal_lensmodel_t lens;
  mrcal_lensmodel_from_name(&lens, lens_model_.c_str());  // parsed in Compute() already
  const int intrinsic_count = static_cast<int>(intrinsics_.size());
  const Vec3 p = at_infinity ? p_in_cam.normalized() : p_in_cam;
  mrcal_point2_t q;
  Eigen::Matrix<double, 2, 3, Eigen::RowMajor> dq_dp;
  Eigen::Matrix<double, 2, Eigen::Dynamic, Eigen::RowMajor> dq_dintrinsics(2, intrinsic_count);
  mrcal_project(&q, reinterpret_cast<mrcal_point3_t*>(dq_dp.data()), dq_dintrinsics.data(),
                reinterpret_cast<const mrcal_point3_t*>(p.data()), 1, &lens, intrinsics_.data());
  gradient.middleCols(state_index_intrinsics_, intrinsic_count) = dq_dintrinsics;

  // The camera frame is known only through the boards: p goes into every board's frame with the
  // optimal pose and back with the solve's, and the mean of those points is projected. Each
  // board's pose moves the mean by 1/N of its own motion.
  const double share = 1.0 / static_cast<double>(cam_from_board_.size());
  for (size_t v = 0; v < cam_from_board_.size(); ++v) {
    const std::array<double, 6> rt = RtFromPose(cam_from_board_[v]);
    const int column = state_index_frames_ + 6 * static_cast<int>(v);
    Vec3 p_in_board, p_back;
    if (at_infinity) {
      Eigen::Matrix<double, 3, 3, Eigen::RowMajor> dp_dr;
      mrcal_rotate_point_r_inverted(p_in_board.data(), nullptr, nullptr, rt.data(), p.data());
      mrcal_rotate_point_r(p_back.data(), dp_dr.data(), nullptr, rt.data(), p_in_board.data());
      gradient.middleCols<3>(column) = share * dq_dp * dp_dr;
    } else {
      Eigen::Matrix<double, 3, 6, Eigen::RowMajor> dp_drt;
      mrcal_transform_point_rt_inverted(p_in_board.data(), nullptr, nullptr, rt.data(), p.data());
      mrcal_transform_point_rt(p_back.data(), dp_drt.data(), nullptr, rt.data(), p_in_board.data());
      gradient.middleCols<6>(column) = share * dq_dp * dp_drt;
    }
  }
  return gradient;
}

Eigen::Matrix2d ProjectionUncertainty::Covariance(const Vec3& p_in_cam, bool at_infinity) const {
  // dq/db* = dq/db D.
  const Eigen::Matrix<double, 2, Eigen::Dynamic> gradient_packed =
      ProjectionGradient(p_in_cam, at_infinity) * scale_.asDiagonal();
  return sigma_ * sigma_ * gradient_packed * packed_covariance_ * gradient_packed.transpose();
}

double ProjectionUncertainty::WorstDirectionStdev(const Vec2& pixel, double distance) const {
  Vec3 direction;
  if (!LensModel(lens_model_, intrinsics_).Unproject(&pixel, 1, &direction) ||
      !direction.allFinite() || direction.norm() == 0.0) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  const bool at_infinity = !std::isfinite(distance);
  const Vec3 p_in_cam = at_infinity ? direction.normalized() : distance * direction.normalized();
  return WorstDirection(Covariance(p_in_cam, at_infinity));
}

std::string ProjectionUncertaintyMap::BriefReport() const {
  double worst = 0.0;
  for (double value : grid) worst = std::max(worst, value);
  return fmt::format(
      "projection uncertainty (1σ, worst direction, at infinity; corner noise σ {:.3f} px): "
      "centre {:.3f} px, corners {:.3f} {:.3f} {:.3f} {:.3f} px, largest on the {}x{} grid "
      "{:.3f} px",
      observed_pixel_sigma, centre, corners[0], corners[1], corners[2], corners[3], grid_width,
      grid_height, worst);
}

nlohmann::json ProjectionUncertaintyMap::Json() const {
  nlohmann::json rows = nlohmann::json::array();
  for (int j = 0; j < grid_height; ++j)
    rows.push_back(std::vector<double>(grid.begin() + j * grid_width, grid.begin() + (j + 1) * grid_width));
  return {{"observed_pixel_sigma_px", observed_pixel_sigma},
          {"centre_px", centre},
          {"corners_px", {{"top_left", corners[0]}, {"top_right", corners[1]},
                          {"bottom_left", corners[2]}, {"bottom_right", corners[3]}}},
          {"grid_size", {grid_width, grid_height}},
          {"grid_px", rows}};
}

ProjectionUncertaintyMap MapProjectionUncertainty(const ProjectionUncertainty& uncertainty,
                                                  int width, int height, int grid_width,
                                                  int grid_height) {
  return MapProjectionUncertainty(
      [&](const Vec2& pixel) { return uncertainty.WorstDirectionStdev(pixel); },
      uncertainty.observed_pixel_sigma(), width, height, grid_width, grid_height);
}

ProjectionUncertaintyMap MapProjectionUncertainty(const std::function<double(const Vec2&)>& stdev,
                                                  double observed_pixel_sigma, int width,
                                                  int height, int grid_width, int grid_height) {
  if (width < 1 || height < 1 || grid_width < 2 || grid_height < 2) {
    throw std::invalid_argument("projection uncertainty map: image at least 1×1, grid 2×2");
  }
  ProjectionUncertaintyMap map;
  map.observed_pixel_sigma = observed_pixel_sigma;
  const double right = width - 1.0, bottom = height - 1.0;
  map.centre = stdev(Vec2(right / 2.0, bottom / 2.0));
  const Vec2 corners[4] = {{0.0, 0.0}, {right, 0.0}, {0.0, bottom}, {right, bottom}};
  for (int k = 0; k < 4; ++k) map.corners[k] = stdev(corners[k]);
  map.grid_width = grid_width;
  map.grid_height = grid_height;
  for (int j = 0; j < grid_height; ++j) {
    for (int i = 0; i < grid_width; ++i) {
      map.grid.push_back(stdev(Vec2(right * i / (grid_width - 1), bottom * j / (grid_height - 1))));
    }
  }
  return map;
}

}  // namespace procam
