#pragma once
// What the chessboard calibration is sure of: mrcal's projection uncertainty (Kogan,
// "Projection uncertainty", mrcal.secretsauce.net/uncertainty.html; mrcal 2.2's
// mrcal.projection_uncertainty, the version Debian 12 ships), computed by procam from the solve.
//
// The corners are observed with noise N(0, σ²) per coordinate; σ is estimated as mrcal does,
// the standard deviation of the inlier corner residuals at the optimum. The solve maps that noise
// onto its parameters b (intrinsics and board poses):
//   Var(b) = σ² (JᵀJ)⁻¹ J_obsᵀ J_obs (JᵀJ)⁻¹
// with J the Jacobian of all measurements (corners and regularisation) and J_obs its corner rows
// (without regularisation this is σ² (JᵀJ)⁻¹). A point p fixed in the camera frame projects
// through the noisy lens; and since the camera frame itself is only known through the boards,
// mrcal lets p ride with them: p is carried into every board's frame with the optimal poses and
// back with the noisy ones, and the mean over boards is the point that is projected (mrcal 2.2's
// "mean-frames" compensation for the moving reference). At infinity only rotations count. Then
//   Var(q) = (dq/db) Var(b) (dq/db)ᵀ
// and the number reported is the worst-direction standard deviation, the square root of the
// larger eigenvalue of Var(q): what mrcal-show-projection-uncertainty plots by default.
//
// Pixels as in base/camera_model.h (centre of the top-left pixel at (0, 0)); the camera frame x
// right, y down, z forward, metres.

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <array>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "base/camera_model.h"
#include "calibration/camera_calibration.h"

namespace procam {

// The projection uncertainty of one calibrated camera. Compute() evaluates the solve once again
// (libmrcal's mrcal_optimizer_callback at the optimum gives J) and keeps Var(b)/σ²; each query
// is then a few small matrix products. Immutable after Compute(); thread-safe queries.
class ProjectionUncertainty {
 public:
  static constexpr double kInfinity = std::numeric_limits<double>::infinity();

  // False, with the reason in `why`, when the calibration has no solve (CameraCalibration::solve
  // empty), libmrcal cannot evaluate it, or JᵀJ is not positive definite (a degenerate solve);
  // the object is then not to be queried.
  bool Compute(const CameraCalibration& calibration, std::string* why);

  // σ, pixels: the standard deviation of the inlier corner residuals at the optimum (both
  // coordinates together, mean removed; numpy.std as mrcal computes it).
  double observed_pixel_sigma() const { return sigma_; }
  int state_count() const { return static_cast<int>(scale_.size()); }

  // dq/db, 2 × state_count(), in mrcal's state order (intrinsics, then per board r, t) and full
  // units (radians, metres, the intrinsics' own): how the pixel of the point `p_in_cam` moves with
  // the solve's parameters, including the mean-frames motion of the camera frame. At infinity
  // only the direction of `p_in_cam` counts and the translations' columns are zero.
  Eigen::Matrix<double, 2, Eigen::Dynamic> ProjectionGradient(const Vec3& p_in_cam,
                                                              bool at_infinity) const;
  // Var(intrinsics), the lens's marginal covariance in mrcal's order and units (px², px ·
  // distortion, ...): σ² times the intrinsics' block of Var(b)/σ². What the chessboard says
  // of the lens on its own, e.g. as a prior where a later solve refines it.
  Eigen::MatrixXd IntrinsicsCovariance() const;
  // Var(q), px², of the pixel of `p_in_cam` (mrcal's what = 'covariance').
  Eigen::Matrix2d Covariance(const Vec3& p_in_cam, bool at_infinity) const;
  // The worst-direction standard deviation, px, at `pixel`, for a point `distance` metres along
  // its ray (kInfinity: looking out to infinity, mrcal-show-projection-uncertainty's default).
  // NaN where the lens cannot unproject the pixel.
  double WorstDirectionStdev(const Vec2& pixel, double distance = kInfinity) const;

 private:
  std::string lens_model_;
  std::vector<double> intrinsics_;
  std::vector<Eigen::Isometry3d> cam_from_board_;
  int state_index_intrinsics_ = 0, state_index_frames_ = 0;
  Eigen::VectorXd scale_;             // D: b = D b*, mrcal's packing of the state
  Eigen::MatrixXd packed_covariance_;  // Var(b*)/σ² in mrcal's packed, unitless state b*
  double sigma_ = 0.0;
};

// The uncertainty over one image as result.json reports it: the worst-direction standard
// deviation at infinity at the image centre, the four corner pixels and a coarse grid.
struct ProjectionUncertaintyMap {
  double observed_pixel_sigma = 0.0;  // σ, px
  double centre = 0.0;                // at ((width − 1)/2, (height − 1)/2), px
  // At the corner pixels (0, 0), (width − 1, 0), (0, height − 1), (width − 1, height − 1),
  // px.
  std::array<double, 4> corners{};
  // Grid of grid_width × grid_height pixels spanning the image corner to corner (x = i (width −
  // 1)/(grid_width − 1), likewise y; mrcal.sample_imager's grid), row-major, px.
  int grid_width = 0, grid_height = 0;
  std::vector<double> grid;
  std::string BriefReport() const;
  // result.json's form: observed_pixel_sigma_px, centre_px, corners_px (top_left, ...),
  // grid_size [w, h] and grid_px (rows).
  nlohmann::json Json() const;
};

// Evaluates `uncertainty` at infinity over a `width` × `height` image; grid_width and grid_height
// at least 2 (std::invalid_argument otherwise).
ProjectionUncertaintyMap MapProjectionUncertainty(const ProjectionUncertainty& uncertainty,
                                                  int width, int height, int grid_width = 16,
                                                  int grid_height = 12);

// The same map of any worst-direction standard deviation `stdev(pixel)` (a projector's, from the
// self-calibration), σ given.
ProjectionUncertaintyMap MapProjectionUncertainty(const std::function<double(const Vec2&)>& stdev,
                                                  double observed_pixel_sigma, int width,
                                                  int height, int grid_width = 16,
                                                  int grid_height = 12);

}  // namespace procam
