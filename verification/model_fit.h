#pragma once
// The closed loop's model update: a photo of the room, lit by known projector images, says how
// the rig's photometry and the room's reflectance differ from the model's (verification/).
//
//   1. projector response: per projector and primary j, an exponent p (response r_j(d) →
//      r_j(d)^p, i.e. gamma γ → γ·p) fitted to the measured radiosity of the seen patches:
//      B_i,c = s_c ρ_i,c (D_i,c(p) + (F B)_i,c), D the direct irradiance the shown codes deliver
//      by the rig's flux bookkeeping (projection/direct_light.h), F B the bounce irradiance from
//      the measured B (the model's on unseen patches), s_c a common reflectance scale per
//      channel; least squares on log B by coordinate descent (golden section on each p);
//   2. reflectance: per seen patch ρ = B / (D(p) + F B) (the radiosity equation solved for ρ
//      with the measured B), damped (ρ ← ρ_old (ρ/ρ_old)^step), the ratio bounded to
//      [1/2, 2] and ρ to [0.01, 0.99]; unseen patches scale by s;
//   3. with per-pixel reflectance maps, a gain per projector pixel (FitReflectanceMaps below).

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "geometry/patches.h"
#include "projection/camera_rays.h"
#include "projection/projection_rig.h"
#include "projection/projector_images.h"

namespace procam {

struct ModelFitOptions {
  bool fit_response = true;       // fit the projectors' response exponents (step 1)
  bool fit_reflectance = true;    // update the per-patch reflectance (step 2)
  double reflectance_step = 1.0;  // damping of the reflectance update, (0, 1]
};

struct ModelUpdate {
  std::vector<Eigen::Vector3d> exponent;            // per projector, per primary (step 1)
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();  // common reflectance scale s per channel
  Eigen::MatrixX3d reflectance;                     // (n,3) the updated reflectance (step 2)
  int fit_patches = 0;                              // patch-channels fitted on
  double rms_before = 0, rms_after = 0;             // log residual of the fit
};

// Fits steps 1 and 2 to `measured` (n,3, the photo's exitance per patch, used where `seen`)
// with `predicted` (n,3, the model's radiosity, used where unseen) for the rig's `images`.
ModelUpdate FitModel(const ModelFitOptions& options, const ProjectionRig& rig,
                     const std::vector<ProjectorImage>& images, const Eigen::MatrixXd& form_factors,
                     const Eigen::MatrixX3d& measured, const std::vector<bool>& seen,
                     const Eigen::MatrixX3d& predicted);

// Applies the update to the rig (responses, reflectance and the bounds, which are linear in ρ)
// and to the patches' reflectance (both levels).
void ApplyModelUpdate(const ModelUpdate& update, ProjectionRig* rig, PatchHierarchy* patches);

// 3. The per-pixel reflectance (the maps attached to the rig, HasReflectanceMaps): a gain per
//    projector pixel from the photo. Per camera pixel p that `mask` keeps, on patch i, the ratio
//    t_p = measured_p / predicted_p per channel (the photo's exitance over the per-pixel
//    prediction of the same images, PredictPixels) divided by its patch's mean ratio (the patch's
//    scale is step 2's); for each projector pixel q lighting p's point, the mean of t over the
//    camera pixels within a box of ±radius projector pixels around q is its gain g_q, clamped to
//    [1/max_gain, max_gain] and damped: ρ_q ← min(0.99, ρ_q g_q^step). With the model's irradiance
//    right, one update makes the prediction the photo; the clamp and the box keep the map smooth
//    and bounded where it is not (the camera's noise, the bounce's variation within a patch).
struct ReflectanceMapFitOptions {
  double step = 1.0;      // damping of the gain, (0, 1]
  double max_gain = 1.5;  // bound on one update's gain per pixel and channel, > 1
  int radius = 2;         // half-width of the averaging box, projector pixels, [0, 50]
  bool Check(std::string* why) const;
};

struct ReflectanceMapUpdate {
  long long updated_pixels = 0;  // projector pixels whose reflectance changed (all projectors)
  double rms_log_gain = 0.0;     // root mean square of log g over them and their channels
};

// Step 3. `measured` and `predicted`: CV_32FC3 R, G, B exitance of the camera pixels (the size of
// `rays`); `mask`: one per camera pixel (rays.patch's order), the pixels to fit on. Throws
// std::invalid_argument when the rig has no maps, the sizes differ or the options fail Check().
ReflectanceMapUpdate FitReflectanceMaps(const ReflectanceMapFitOptions& options,
                                        const CameraPixelRays& rays, const cv::Mat& measured,
                                        const cv::Mat& predicted, const std::vector<bool>& mask,
                                        ProjectionRig* rig);

}  // namespace procam
