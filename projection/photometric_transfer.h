#pragma once
// Photometry in the scene's units: what a registered camera's photo of a flat field says about
// a projector's black and max and the room's per-patch reflectance.
//
// - Absolute photometry: a flat field photographed by a camera registered in the room frame is,
//   per camera pixel p (channel c) seeing a point x of fine patch i,
//
//       m_p,c = k_c · ρ_i,c · (G(x) · o_c + H_i,c) + camera black + ambient,
//
//   with o the projector's output for the field's drive (scene units: irradiance at 1 m on
//   axis), G(x) the projector's geometric gain at x (0 where it does not light x: outside its
//   image, facing away, occluded), H = F·B the bounce irradiance of the radiosity model
//   (B = K⁻¹(ρ ⊙ Ḡ) o, Ḡ_i the patch's mean gain, exactly the projection rig's upper bound at
//   max 1), and k_c the camera's value per unit exitance. So m is linear in o with the known
//   per-pixel transfer t_p,c = k_c ρ_i,c (G(x) + (F b)_i,c), b = K⁻¹(ρ ⊙ Ḡ): given to
//   CalibratePhotometry (calibration/photometric.h) it yields black and max in scene units.
// - Per-patch reflectance: with o known, each seen patch's ρ_i = Σ_p m_p / Σ_p k (G(x_p) o +
//   H_i) from the white-minus-black field (the radiosity equation B = ρ (E_irr + F B) solved for
//   ρ with the measured B), H = F B where B is measured on the patches the camera sees and
//   modelled with the scene's reflectance on the others.
// The transfer uses the scene's nominal reflectance, so the absolute scale is tied to it: a
// surface whose paint is 5% darker than the scene says makes max 5% low there, and the
// reflectances found afterwards are relative to that scale (their area-weighted mean follows
// the nominal one).

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "compensation/unit_light.h"
#include "geometry/patches.h"
#include "projection/camera_rays.h"

namespace procam {

// Per-pixel transfer (CV_32FC3, camera B, G, R: camera value per unit projector output) for
// PhotometricCalibrationOptions::transfer: k_c ρ_i,c (G_p + bounce_i,c); 0 where the pixel sees
// no patch. `camera_scale` is k (R, G, B): camera value per unit exitance.
cv::Mat PhotometricTransfer(const CameraPixelLighting& lighting, const PatchLevel& level,
                            const UnitLightModel& model, const Eigen::Vector3d& camera_scale);

struct ReflectanceEstimate {
  Eigen::MatrixX3d reflectance;  // (n,3): estimated where seen, the level's nominal elsewhere
  std::vector<int> pixels;       // camera pixels used per patch
  int patches_seen = 0;          // with at least min_pixels pixels
  // (n,3) the bounce irradiance H = F·B the estimate divided by (per unit of `output`'s field,
  // scene units), for the per-pixel reflectance map (projection/reflectance_map.h).
  Eigen::MatrixX3d bounce_irradiance;
};

// Per-patch reflectance from a white-minus-black field `difference` (camera B, G, R, camera
// values, CV_32FC3; ambient and camera black cancel in the difference) and the projector's
// output difference `output` = max − black (R, G, B, scene units). Patches with fewer than
// `min_pixels` usable pixels (`mask`, CV_8UC1, empty = all) keep the nominal reflectance.
// Estimates are clamped to [0, 0.99].
ReflectanceEstimate EstimatePatchReflectance(const CameraPixelLighting& lighting,
                                             const PatchLevel& level,
                                             const Eigen::MatrixXd& form_factors,
                                             const UnitLightModel& model, const cv::Mat& difference,
                                             const cv::Mat& mask, const Eigen::Vector3d& output,
                                             const Eigen::Vector3d& camera_scale,
                                             int min_pixels = 4);

// Each projector's black level when all of them show black at once (the only state a rig can
// photograph: a projector showing black still emits its black). The black field m (camera B, G,
// R, camera values) is then, per pixel p and working channel c,
//     m_p,c − camera_black = Σ_j black_j,c · T_j,p,c
// with T_j the per-pixel transfer of projector j (PhotometricTransfer: camera value per unit
// output, bounces included). Least squares per channel over the pixels some projector lights;
// the projectors light different parts of the room in different proportions, which is what
// separates them. Returns black_j (R, G, B, scene units), one per transfer. Throws
// std::invalid_argument when sizes differ or the system is singular (projectors whose light
// cannot be told apart).
std::vector<Eigen::Vector3d> SeparateBlackLevels(const std::vector<cv::Mat>& transfers,
                                                 const cv::Mat& black_field, double camera_black);

}  // namespace procam
