#pragma once
// The vector types every module uses (Eigen, double precision), and rotations as angle-axis
// vectors (axis × angle in radians, as Ceres and mrcal's rt store them).

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace procam {

using Vec3 = Eigen::Vector3d;
using Vec2 = Eigen::Vector2d;

// Rotation matrix → angle-axis vector.
inline Vec3 AngleAxisOf(const Eigen::Matrix3d& rotation) {
  const Eigen::AngleAxisd angle_axis(rotation);
  return angle_axis.angle() * angle_axis.axis();
}
// Angle-axis vector → rotation matrix (the identity for the zero vector).
inline Eigen::Matrix3d RotationOf(const Vec3& angle_axis) {
  const double angle = angle_axis.norm();
  return angle > 0.0 ? Eigen::AngleAxisd(angle, angle_axis / angle).toRotationMatrix()
                     : Eigen::Matrix3d::Identity();
}

}  // namespace procam
