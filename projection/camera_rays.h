#pragma once
// Camera pixels cast into the room: which fine patch each pixel of a registered camera sees, and
// how each projector lights the point it sees (geometric gain, the projector pixel whose area
// holds the point's projection, occlusion by the scene's surfaces). The camera is a
// ProjectorGeometry whose proj_from_world is cam_from_room (the same lens model and pixel
// convention as a projector, projector.h).

#include <cstdint>
#include <vector>

#include "geometry/patches.h"
#include "geometry/scene.h"
#include "projection/projection_rig.h"
#include "projection/projector.h"
#include "projection/projector_images.h"

namespace procam {

// What a camera pixel sees and how one projector lights it.
struct CameraPixelLighting {
  int width = 0, height = 0;
  std::vector<int> patch;    // fine patch seen (row-major), −1 for none (or its unlit side)
  std::vector<double> gain;  // the projector's geometric gain G at the point (1/m²), 0 if unlit
};

// What every camera pixel sees and how each projector lights it, keeping the projector pixel
// that lights the point: the cast of LightCameraPixels for every projector at once.
struct CameraPixelRays {
  int width = 0, height = 0, projectors = 0;
  std::vector<int> patch;  // fine patch seen (row-major), −1 for none (or its unlit side)
  // Per (camera pixel, projector), index pixel · projectors + k: the geometric gain G_k at the
  // point (1/m²; 0 where k does not light it: outside its image, facing away, occluded) and
  // the projector pixel whose area holds the point's projection (row · width + column; −1
  // where unlit).
  std::vector<float> gain;
  std::vector<int32_t> projector_pixel;
  // The room point (metres) each camera pixel sees, row-major; zero where patch is −1. Where the
  // per-pixel prediction evaluates the bounce light's smooth field (PredictPixels).
  std::vector<Eigen::Vector3f> point;
};
CameraPixelRays CastCameraPixels(const Scene& scene, const PatchLevel& level,
                                 const std::vector<Projector>& projectors,
                                 const ProjectorGeometry& camera, double ray_margin = 1e-4);

// Per patch: the sum and the number of a picture's values over the camera pixels that see it
// (CameraPixelRays::patch) — the per-patch mean over camera pixels, made here once for play's
// desired images, the demo's desired picture and verification's photos.
struct PatchPixelSums {
  Eigen::MatrixX3d sum;  // (n,3) the values' sum, channels as the picture stores them
  Eigen::VectorXi count;  // (n) pixels summed
  // Patch i's mean (count[i] > 0).
  Eigen::RowVector3d Mean(int i) const { return sum.row(i) / count[i]; }
  // Each patch's mean where it has at least `min_pixels` (≥ 1) pixels, `fallback`'s row
  // elsewhere (n rows).
  Eigen::MatrixX3d Means(const Eigen::MatrixX3d& fallback, int min_pixels = 1) const;
};

// Sums `value(x, y, &rgb)` (false: pixel (x, y) left out) over the pixels of a width × height
// row-major pixel → patch map whose patch is in [0, patches) (−1: none).
template <typename PixelValue>
PatchPixelSums SumPixelsPerPatch(const std::vector<int>& pixel_patch, int width, int height,
                                 int patches, PixelValue&& value) {
  PatchPixelSums sums;
  sums.sum = Eigen::MatrixX3d::Zero(patches, 3);
  sums.count = Eigen::VectorXi::Zero(patches);
  Eigen::RowVector3d rgb;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const int patch = pixel_patch[static_cast<size_t>(y) * width + x];
      if (patch < 0 || patch >= patches || !value(x, y, &rgb)) continue;
      sums.sum.row(patch) += rgb;
      ++sums.count[patch];
    }
  }
  return sums;
}

// The same for a CV_32FC3 picture of the map's size (pixel_patch: picture.rows × picture.cols),
// only the pixels `mask` marks when given (one per pixel, row-major).
PatchPixelSums SumPixelsPerPatch(const cv::Mat& picture, const std::vector<int>& pixel_patch,
                                 int patches, const std::vector<bool>* mask = nullptr);

// Casts every camera pixel's ray (camera = a ProjectorGeometry whose proj_from_world is
// cam_from_room) against the fine patches, and lights the hit from the projector: in its image,
// facing it and unoccluded (shadow ray against the scene's surfaces, `ray_margin` metres).
CameraPixelLighting LightCameraPixels(const Scene& scene, const PatchLevel& level,
                                      const ProjectorGeometry& projector,
                                      const ProjectorGeometry& camera, double ray_margin = 1e-4);

// The predicted exitance of every camera pixel (CV_32FC3, working R, G, B, scene units; 0 where
// the pixel sees nothing) for the images shown, by the model's split of the light at the point
// x of patch i the pixel sees (projection/photometric_transfer.h's transfer):
//     x_p = ρ_i ⊙ (Σ_k G_k(x) · output_k(code_k) + (F B)_i),
// code_k the code of the projector pixel that lights x, output_k the projector's photometry as
// the model knows it, and B = K⁻¹(ρ ⊙ D) the radiosity of the direct irradiance D the shown
// images deliver to each patch (the renderer's flux bookkeeping), so the bounce term is the one
// of the light actually shown. The bounce irradiance (F B)_i is not constant over the patch: it
// follows a smooth field over the surface (seamless_light.h's partition of unity of bumps at the
// patch centroids, over every neighbour on the same surface), evaluated at the point the pixel
// sees and scaled so that its mean over the pixels that see the patch is (F B)_i: the light
// bounced off the walls around varies smoothly across them. Constant where the field is flat or
// the rays carry no points. `shown_radiosity`
// (optional) receives that B. With every
// projector's reflectance map attached (HasReflectanceMaps), ρ_i becomes the point's own
// reflectance relative to its patch's, ρ_i ⊙ ρ_x / ρ̄_i (ρ_x the mean of the maps' values at the
// projector pixels that light x, ρ̄_i their patch mean, MapReflectanceMeans): the model's
// per-patch ρ_i (which the closed loop refits) keeps its scale, the map adds the variation within
// the patch. Points no projector lights keep ρ_i.
cv::Mat PredictPixels(const CameraPixelRays& rays, const ProjectionRig& rig,
                      const std::vector<ProjectorImage>& images,
                      const Eigen::MatrixXd& form_factors,
                      Eigen::MatrixX3d* shown_radiosity = nullptr);

}  // namespace procam
