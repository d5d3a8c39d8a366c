#pragma once
// Chessboard photos for the synthetic rig (issue 7): what a person holding a printed board in
// front of the rig's camera would capture, so that the demo and `procam calibrate all` can
// calibrate the simulated camera's intrinsics the way a real one is calibrated.

#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "calibration/camera_calibration.h"
#include "datasets_synthetic/simulated_rig.h"

namespace procam {

// Ten board poses in the camera frame (cam_from_board), tilted up to ±35° and rolled, spread
// over the image so that corners reach its edges (where distortion is largest), at a distance
// where the board spans about 45% of the image width.
std::vector<Eigen::Isometry3d> ChessboardPoses(const CameraGeometry& camera,
                                               const ChessboardSpec& board);

// An 8-bit grey photo of `board` at `cam_from_board` through the camera's lens (its extrinsics
// are ignored): every pixel is the mean of supersample × supersample rays of a camera that finer
// with the same lens, met with the board plane; dark squares 0.08, light squares and a one-square
// white margin 0.85, background 0.35, plus N(0, noise_sigma²) (fractions of full scale).
cv::Mat RenderChessboard(const CameraGeometry& camera, const ChessboardSpec& board,
                         const Eigen::Isometry3d& cam_from_board, double noise_sigma,
                         uint32_t seed, int supersample = 4);

}  // namespace procam
