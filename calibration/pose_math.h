#pragma once
// Small pieces the calibration's Ceres problems share (internal to calibration/): the projector
// lens model (fx, fy, cx, cy, radial k1, k2: OpenCV4 with
// p1 = p2 = 0) applied to a point given in another frame.

#include <Eigen/Geometry>
#include <ceres/rotation.h>

#include "base/camera_model.h"
#include "base/vector.h"

namespace procam {


// The point `p` (3 values in the frame the pose starts from) moved by the pose (angle-axis
// `rotation`, `translation`) into the projector frame and projected through `intrinsics`
// (fx, fy, cx, cy, k1, k2), minus the observed pixel: residual[0..1], pixels.
template <typename T>
void ProjectorPixelResidual(const T* intrinsics, const T* rotation, const T* translation,
                            const T* p, const Vec2& observed, T* residual) {
  T p_in_proj[3];
  ceres::AngleAxisRotatePoint(rotation, p, p_in_proj);
  for (int i = 0; i < 3; ++i) p_in_proj[i] += translation[i];
  const T x = p_in_proj[0] / p_in_proj[2], y = p_in_proj[1] / p_in_proj[2];
  const T distortion[4] = {intrinsics[4], intrinsics[5], T(0.0), T(0.0)};  // p1 = p2 = 0
  T distorted_x, distorted_y;
  DistortOpenCv4(distortion, x, y, &distorted_x, &distorted_y);
  residual[0] = intrinsics[0] * distorted_x + intrinsics[2] - T(observed.x());
  residual[1] = intrinsics[1] * distorted_y + intrinsics[3] - T(observed.y());
}

}  // namespace procam
