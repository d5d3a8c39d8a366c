#pragma once
// Ground truth for calibrating a projector with a chessboard and structured light
// (calibration/board_projector.h): a camera and a projector of known lenses and relative pose, a
// printed chessboard at known poses in front of them (the only surface in view), and what the
// camera records of the board under every pattern of a sequence — rendered directly: each camera
// pixel is the mean of supersample × supersample rays met with the board plane; a ray's point is
// lit by the projector pixel it projects to (a projector pixel is a uniform square of light; the
// pattern's grey level linear in light) plus ambient light, times the board's reflectance there;
// then a Gaussian blur (the camera's defocus) and Gaussian read noise.

#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "calibration/camera_calibration.h"
#include "capture/patterns.h"
#include "projection/projector.h"

namespace procam {

// The devices: both frames as in projection/projector.h; `projector_from_camera` maps camera
// points into the projector frame (metres).
struct BoardRig {
  ProjectorGeometry camera;     // the camera's lens and image size (its pose is ignored)
  ProjectorGeometry projector;  // the projector's lens and image size (its pose is ignored)
  Eigen::Isometry3d projector_from_camera = Eigen::Isometry3d::Identity();
};

// A rig about the size of a desk setup: a 1280×800 camera (f ≈ 1600 px, OpenCV4 distortion) and a
// 1024×768 projector (f ≈ 1500 px, a small OpenCV4 distortion) 0.2 m to its right, toed in by 8°:
// at 1 m both see about 0.8 m × 0.5 m.
BoardRig DefaultBoardRig();

struct BoardRenderOptions {
  double dark_reflectance = 0.1;   // the board's dark squares, [0, 1]
  double light_reflectance = 0.85; // its light squares and a one-square margin, [0, 1]
  double projector_gain = 0.9;     // camera value of full projector white on reflectance 1, > 0
  double ambient = 0.02;           // camera value of the light not from the projector, ≥ 0
  double blur_sigma_px = 0.8;      // camera pixels, ≥ 0 (0: no blur)
  double noise_sigma = 0.004;      // read noise, camera values (full scale 1), ≥ 0
  int supersample = 3;             // rays per camera pixel side, [1, 8]
  uint32_t seed = 1;               // noise seed
  bool Check(std::string* why) const;
};

// `count` board poses (cam_from_board, up to 8) around `distance` metres in front of the camera,
// tilted by 30°–45° about different axes, centred where the projector's image centre meets the
// plane at `distance` and moved up to 0.12 m sideways and 0.06 m up or down towards the corners
// of both images (so that the board's corners reach towards the images' corners).
std::vector<Eigen::Isometry3d> BoardRigPoses(const BoardRig& rig, const ChessboardSpec& board,
                                             int count, double distance);

// The camera's images (CV_32FC1, full scale 1, values may exceed [0, 1] with noise) of the board
// at `cam_from_board` under each pattern of `sequence`, in order. Throws std::invalid_argument when
// the options fail Check() or a pattern's size is not the projector's.
std::vector<cv::Mat> RenderBoardUnderPatterns(const BoardRig& rig, const ChessboardSpec& board,
                                              const Eigen::Isometry3d& cam_from_board,
                                              const CaptureSequence& sequence,
                                              const BoardRenderOptions& options);

// A chessboard at a pose in a room of projectors, as a camera sees it (the synthetic camera's
// `board_pose`, synthetic_camera.h): the board the only surface in view (nothing else returns
// light). Built once per pose: every ray of a camera `supersample` times finer (same lens) that
// meets the board, its camera pixel, the board's reflectance there and, per projector, the
// projector pixel that lights it and the geometric gain (ProjectorGeometry::Gain: distance
// falloff, incidence, the lens's pixel density; 0 where the projector is behind the board or
// misses it). Rendering adds, per ray, reflectance × gain × the projector's output at that pixel.
class BoardInRoom {
 public:
  // `camera` and `projectors` with their poses in the world (the room); `cam_from_board` the
  // board's pose in the camera frame. Throws std::invalid_argument when the board or the
  // reflectances are invalid, or supersample is outside [1, 8].
  BoardInRoom(const ProjectorGeometry& camera, const std::vector<ProjectorGeometry>& projectors,
              const ChessboardSpec& board, const Eigen::Isometry3d& cam_from_board,
              double dark_reflectance, double light_reflectance, int supersample = 2);

  // The radiance at the camera (CV_32FC3, R, G, B, the camera's size): `outputs[k]` is projector
  // k's output per pixel (CV_32FC3, R, G, B, ProjectorPhotometry::Output's units), or empty for
  // a dark projector.
  cv::Mat RenderRadiance(const std::vector<cv::Mat>& outputs) const;

  int rays_on_board() const { return static_cast<int>(pixel_.size()); }

 private:
  int width_ = 0, height_ = 0, projector_count_ = 0;
  float per_ray_ = 1.0f;
  std::vector<int> pixel_;          // per ray on the board: its camera pixel
  std::vector<float> reflectance_;  // per ray
  std::vector<int> lit_;            // per ray × projector: the projector pixel, −1 none
  std::vector<float> gain_;         // per ray × projector
};

}  // namespace procam
