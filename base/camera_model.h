#pragma once
// The one mrcal adapter: mrcal `.cameramodel` files and mrcal lens models. Everything that
// touches libmrcal's types or its `rt_cam_ref` convention is in camera_model.cc; the rest of
// procam sees poses as Eigen isometries (`cam_from_ref`, COLMAP naming) and lenses as LensModel.
// (calibration/camera_calibration.cc also calls mrcal_optimize, the chessboard calibration
// itself, and converts its results through this header.)
//
// Pixel convention (mrcal's and OpenCV's): the CENTRE of the top-left pixel is (0, 0), x to the
// right, y down. Camera frame: x right, y down, z forward (out of the lens), metres.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "base/vector.h"

namespace procam {

// An mrcal .cameramodel as procam reads and writes it: lens, image size and pose.
struct CameraModel {
  // An mrcal lens-model name with its configuration, e.g. "LENSMODEL_PINHOLE",
  // "LENSMODEL_OPENCV8", "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=16_Ny=12_fov_x_deg=50".
  std::string lens_model;
  std::vector<double> intrinsics;  // mrcal's order: fx, fy, cx, cy, then distortion (pixels)
  int width = 0, height = 0;       // imager size, pixels
  // mrcal's extrinsics (rt_cam_ref): the camera frame from the reference frame (the room once
  // a rig is registered; the camera itself for a fresh intrinsic calibration).
  Eigen::Isometry3d cam_from_ref = Eigen::Isometry3d::Identity();
  // The solve that made this model, as mrcal's tools read it (mrcal-show-projection-uncertainty,
  // mrcal.projection_uncertainty): the `optimization_inputs` entry, mrcal.optimize()'s arguments
  // at the optimum as a NumPy .npz in base-85 text (calibration/mrcal_optimization_inputs.h), and
  // `icam_intrinsics`, this camera's index in that solve. Written when not empty; the reader leaves
  // it empty (libmrcal's C parser skips both keys).
  std::string optimization_inputs;
  int icam_intrinsics = 0;
};

// Reads a .cameramodel through libmrcal (its own diagnostics silenced). Throws IoError naming
// the file: missing, unparsable, an unnamed lens model.
CameraModel ReadCameraModelFile(const std::filesystem::path& path);
// The text WriteCameraModelFile writes: mrcal's Python-literal format, `comment` as its first line,
// every number with 17 significant digits so that write → read is lossless (mrcal 2.2's own C
// writer prints 6 decimals).
std::string CameraModelText(const CameraModel& model, const std::string& comment);
// Writes the text atomically after libmrcal has parsed it back. Throws IoError naming the file.
void WriteCameraModelFile(const std::filesystem::path& path, const CameraModel& model,
                          const std::string& comment);

// mrcal's rt (Rodrigues rotation vector, then translation) ↔ a pose.
std::array<double, 6> RtFromPose(const Eigen::Isometry3d& b_from_a);
Eigen::Isometry3d PoseFromRt(const double* rt);

// d(pixel)/d(point) of a projection: rows x, y; columns the point's x, y, z (mrcal's dq_dp).
using ProjectionJacobian = Eigen::Matrix<double, 2, 3, Eigen::RowMajor>;

// An mrcal lens model with its intrinsics, parsed once. Immutable, cheap to copy (the parsed
// model is shared), thread-safe.
class LensModel {
 public:
  // A 1×1-pixel pinhole (fx = fy = 1, cx = cy = 0): a placeholder.
  LensModel();
  // Throws std::invalid_argument (one line) for an unknown lens model, one without the
  // fx, fy, cx, cy core, one mrcal cannot unproject (CAHVORE), a wrong number of intrinsics,
  // non-finite intrinsics or non-positive focal lengths.
  LensModel(const std::string& name, std::vector<double> intrinsics);
  // The number of intrinsics of a lens model; throws std::invalid_argument for an unknown one.
  static int ParameterCount(const std::string& name);

  const std::string& name() const { return name_; }
  const std::vector<double>& intrinsics() const { return intrinsics_; }

  // The pixel of a point in the camera frame (any z: a point behind the lens still maps
  // somewhere; callers check z > 0), with its Jacobian when `dq_dp` is given (mrcal_project).
  Vec2 Project(const Vec3& p_in_cam, ProjectionJacobian* dq_dp = nullptr) const;
  // Directions (not normalised) of `count` pixels (mrcal_unproject). False where mrcal fails.
  bool Unproject(const Vec2* pixels, int count, Vec3* directions_in_cam) const;

 private:
  struct Parsed;  // mrcal_lensmodel_t
  std::string name_;
  std::vector<double> intrinsics_;
  std::shared_ptr<const Parsed> parsed_;
};

// The OpenCV distortion of LENSMODEL_OPENCV4 (k1, k2, p1, p2) applied to the normalised point
// (x, y): radial 1 + k1 r² + k2 r⁴ plus the tangential terms. `T` and the coefficients' type `K`
// may be Ceres Jets. With `jacobian` (row-major 2×2, d(distorted)/d(x, y)) also its derivative.
template <typename T, typename K>
void DistortOpenCv4(const K* k1_k2_p1_p2, const T& x, const T& y, T* distorted_x, T* distorted_y,
                    T* jacobian = nullptr) {
  const K &k1 = k1_k2_p1_p2[0], &k2 = k1_k2_p1_p2[1], &p1 = k1_k2_p1_p2[2], &p2 = k1_k2_p1_p2[3];
  const T r2 = x * x + y * y;
  const T radial = T(1.0) + k1 * r2 + k2 * r2 * r2;
  *distorted_x = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
  *distorted_y = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
  if (jacobian) {
    const T radial_dr2 = k1 + 2.0 * k2 * r2;  // ∂radial/∂r²
    jacobian[0] = radial + 2.0 * x * x * radial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x;
    jacobian[1] = 2.0 * x * y * radial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y;
    jacobian[2] = jacobian[1];
    jacobian[3] = radial + 2.0 * y * y * radial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x;
  }
}

}  // namespace procam
