#pragma once
// Small pieces the calibration's Ceres problems share (internal to calibration/): angle-axis
// rotations, and the projector lens model (fx, fy, cx, cy, radial k1, k2: OpenCV4 with
// p1 = p2 = 0) applied to a point given in another frame.

#include <Eigen/Geometry>
#include <ceres/rotation.h>

#include "geometry/scene.h"

namespace procam {

// Rotation ↔ angle-axis vector (axis × angle in radians), as Ceres and mrcal's rt store it.
inline Vec3 AngleAxisOf(const Eigen::Matrix3d& rotation) {
  const Eigen::AngleAxisd angle_axis(rotation);
  return angle_axis.angle() * angle_axis.axis();
}
inline Eigen::Matrix3d RotationOf(const Vec3& angle_axis) {
  const double angle = angle_axis.norm();
  return angle > 0.0 ? Eigen::AngleAxisd(angle, angle_axis / angle).toRotationMatrix()
                     : Eigen::Matrix3d::Identity();
}

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
  const T r2 = x * x + y * y;
  const T radial = T(1.0) + intrinsics[4] * r2 + intrinsics[5] * r2 * r2;
  residual[0] = intrinsics[0] * x * radial + intrinsics[2] - T(observed.x());
  residual[1] = intrinsics[1] * y * radial + intrinsics[3] - T(observed.y());
}

}  // namespace procam
