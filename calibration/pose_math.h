#pragma once
// Small pieces the calibration's Ceres problems share (internal to calibration/): the projector
// lens model (fx, fy, cx, cy, radial k1, k2: OpenCV4 with
// p1 = p2 = 0, or given p1, p2 for a held lens) applied to a point given in another frame, and the
// camera's OpenCV4 distortion undone by Newton steps (differentiable, for a camera lens the solve
// refines).

#include <Eigen/Geometry>
#include <ceres/rotation.h>

#include "base/camera_model.h"
#include "base/vector.h"

namespace procam {

// The point `p` (3 values in the frame the pose starts from) moved by the pose (angle-axis
// `rotation`, `translation`) into the projector frame and projected through `intrinsics`
// (fx, fy, cx, cy, k1, k2) and the tangential distortion p1, p2 (`tangential`, constants: zero
// unless a projector's whole OpenCV4 lens is held from a file), minus the observed pixel:
// residual[0..1], pixels.
template <typename T>
void ProjectorPixelResidual(const T* intrinsics, const T* rotation, const T* translation,
                            const T* p, const Vec2& observed, T* residual,
                            const double* tangential = nullptr) {
  T p_in_proj[3];
  ceres::AngleAxisRotatePoint(rotation, p, p_in_proj);
  for (int i = 0; i < 3; ++i) p_in_proj[i] += translation[i];
  const T x = p_in_proj[0] / p_in_proj[2], y = p_in_proj[1] / p_in_proj[2];
  const T distortion[4] = {intrinsics[4], intrinsics[5], T(tangential ? tangential[0] : 0.0),
                           T(tangential ? tangential[1] : 0.0)};
  T distorted_x, distorted_y;
  DistortOpenCv4(distortion, x, y, &distorted_x, &distorted_y);
  residual[0] = intrinsics[0] * distorted_x + intrinsics[2] - T(observed.x());
  residual[1] = intrinsics[1] * distorted_y + intrinsics[3] - T(observed.y());
}

// `steps` Newton steps towards the normalised point (x, y) that DistortOpenCv4 takes to
// (distorted_x, distorted_y), from the start in *x, *y (a nearby solution: the step converges
// quadratically). Differentiable in every argument when `T` and `K` are Ceres Jets.
template <typename T, typename K>
void UndistortOpenCv4Steps(const K* k1_k2_p1_p2, const T& distorted_x, const T& distorted_y,
                           int steps, T* x, T* y) {
  for (int step = 0; step < steps; ++step) {
    T value_x, value_y, j[4];
    DistortOpenCv4(k1_k2_p1_p2, *x, *y, &value_x, &value_y, j);
    const T ex = value_x - distorted_x, ey = value_y - distorted_y;
    const T determinant = j[0] * j[3] - j[1] * j[2];
    *x -= (j[3] * ex - j[1] * ey) / determinant;
    *y -= (j[0] * ey - j[2] * ex) / determinant;
  }
}

}  // namespace procam
