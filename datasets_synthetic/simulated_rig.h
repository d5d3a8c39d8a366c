#pragma once
// The synthetic world: what a camera would photograph in a room lit by projectors, rendered so
// that the solver's own model is NOT the world.
//
//   direct light   per camera pixel, exactly: the surface point x the pixel sees (Embree) is
//                  projected into every projector; if x is inside the image and nothing occludes
//                  it, the pixel it falls in lights it with output(drive) · Gain(x) (projector.h:
//                  response, colour mixing, black level, distance and incidence falloff), times
//                  the reflectance at x (the surface's reflectance texture at x's UV
//                  coordinate on a printed surface, Surface::ReflectanceAt, times AlbedoFactor);
//   indirect light a radiosity solution on a "world" mesh `world_factor` times finer than the
//                  solver's, driven by the direct light the images deliver to each world patch;
//                  the bounce light B − E of the world patch x lies on is added (on a
//                  printed surface: x's reflectance times the patch's indirect irradiance);
//   camera         a lens model with distortion (the projector geometry class, used as a camera:
//                  `proj_from_world` is then cam_from_world), exposure, vignetting
//                  (1 − v·r², r = distance from the image centre / half diagonal), shot noise
//                  (Gaussian, variance = shot_noise² · signal) and read noise, a power-law response
//                  and 8-bit quantisation for photos.
// Units: pixel values are exitance in the scene's radiosity units (so the desired appearance
// Bd is directly comparable), times exposure.

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "compensation/radiosity.h"
#include "datasets_synthetic/paper_scenes.h"
#include "geometry/patches.h"
#include "geometry/ray_scene.h"
#include "geometry/scene.h"
#include "projection/projector.h"
#include "projection/projector_images.h"

namespace procam {

using CameraGeometry = ProjectorGeometry;  // same lens and pose model; proj_from_world = cam_from_world

struct SimulatedCameraOptions {
  double exposure = 1.0;     // sensor value per unit exitance, > 0 (1: white radiosity w = 1 saturates)
  double vignetting = 0.15;  // relative fall-off at the image corner, in [0, 1)
  double shot_noise = 0.01;  // standard deviation at signal 1 (sensor units), ≥ 0
  double read_noise = 0.002; // standard deviation (sensor units), ≥ 0
  double gamma = 2.2;        // photo response: code = 255 · value^(1/gamma), > 0
  uint32_t seed = 1;         // noise seed (photos are reproducible)
  bool Check(std::string* why) const;
};

struct SimulatedRigOptions {
  int world_factor = 4;            // world mesh patches per solver patch, ≥ 1
  int solver_patches = 400;        // the solver's patch count the world is finer than
  int direct_samples = 3;          // Gauss points per side when integrating direct light on world patches
  double ray_margin = 1e-4;        // metres
  // Textured albedo: the world's reflectance varies over each surface as a smooth pattern of
  // this relative amplitude (like uneven paint), which the solver's uniform reflectance does
  // not know, in [0, 0.5). 0: uniform.
  double albedo_variation = 0.0;
  // Bounce light continuous over each surface: at a pixel, the world patches' indirect
  // irradiance interpolated between their centroids (bumps of radius 1.5 patch sides over the
  // patches within 2 adjacency steps on the same surface) times the reflectance at the point.
  // false: constant over each world patch, whose borders then show as steps (the default, with
  // which the documented tables were measured).
  bool smooth_bounce = false;
  SimulatedCameraOptions camera;
  bool Check(std::string* why) const;
};

// A camera's lens (with distortion) from a placement: OpenCV4-model lens (k1 = −0.05,
// k2 = 0.01) of the placement's field of view and size; pinhole when `distortion` is false.
CameraGeometry CameraFromPlacement(const DevicePlacement& placement, bool distortion = true);
// A projector from a placement: pinhole lens, black 0.002, max 1.5 (working RGB at 1 m on
// axis), gamma 2.2, identity mixing, 8 bits.
Projector ProjectorFromPlacement(const DevicePlacement& placement);

class SimulatedRig {
 public:
  // Builds the world mesh, its form factors and ray scenes. Throws std::invalid_argument if the
  // options fail Check().
  SimulatedRig(const Scene& scene, std::vector<Projector> projectors, CameraGeometry camera,
               const SimulatedRigOptions& options);

  const Scene& scene() const { return scene_; }
  const std::vector<Projector>& projectors() const { return projectors_; }
  const CameraGeometry& camera() const { return camera_; }
  const PatchLevel& world() const { return world_.fine; }

  // Linear exitance image (CV_32FC3, RGB order, row 0 = top) the camera sees when the
  // projectors show `images`, before the camera's exposure, vignetting and noise. Pixels that
  // see nothing are 0.
  cv::Mat RenderRadiance(const std::vector<ProjectorImage>& images) const;
  // What the camera records: RenderRadiance × exposure × vignetting + noise (CV_32FC3).
  cv::Mat PhotographLinear(const std::vector<ProjectorImage>& images, uint32_t seed_offset = 0) const;
  // The linear photo through the response curve, quantised to 8 bits (CV_8UC3, RGB).
  cv::Mat Photograph8(const std::vector<ProjectorImage>& images, uint32_t seed_offset = 0) const;
  // The desired appearance as the camera would see it: desired sRGB (texture at the hit) →
  // linear × white (CV_32FC3, RGB); 0 where the pixel sees nothing.
  cv::Mat RenderDesired() const;
  // The world's albedo relative to the surface's nominal reflectance at a texture coordinate
  // (1 + albedo_variation · pattern(uv), pattern in [−1, 1]); on a printed surface it multiplies
  // the reflectance texture's value there (the world reflects min(0.99, factor · ρ(uv))).
  // The world's reflectance at a pixel's point: ReflectanceSeenByPixel.
  double AlbedoFactor(int surface, const Vec2& uv) const;
  // The world's reflectance (R, G, B) at the point camera pixel (row, col) sees: the truth a
  // measured reflectance map is judged against. Zero where the pixel sees nothing.
  Vec3 ReflectanceSeenByPixel(int row, int col) const {
    return hits_[static_cast<size_t>(row) * camera_.width() + col].reflectance;
  }
  // Mask (CV_8UC1, 255) of pixels that see a surface.
  const cv::Mat& coverage() const { return coverage_; }
  // The surface point (world, metres) camera pixel (row, col) sees and the unit normal of its
  // lit side; false when the pixel sees nothing (coverage() is 0 there) or is outside the image.
  bool PointSeenByPixel(int row, int col, Vec3* point_in_world, Vec3* normal = nullptr) const;

 private:
  struct PixelHit {
    int world_patch = -1;
    Vec3 point = Vec3::Zero();
    Vec3 reflectance = Vec3::Zero();  // the world's, at this point (textured albedo)
  };
  Scene scene_;
  std::vector<Projector> projectors_;
  CameraGeometry camera_;
  SimulatedRigOptions options_;
  PatchHierarchy world_;
  std::unique_ptr<RadiositySystem> world_radiosity_;
  std::unique_ptr<RayScene> surfaces_;   // the scene's surfaces, for shadow rays
  std::vector<PixelHit> hits_;           // row-major, one per camera pixel
  std::vector<std::vector<int>> bounce_nodes_;  // per world patch, for smooth_bounce
  // The indirect exitance (n,3) spread over the surface at a pixel's hit (smooth_bounce).
  Vec3 SmoothBounce(const PixelHit& hit, const Eigen::MatrixX3d& irradiance) const;
  cv::Mat coverage_;
};

}  // namespace procam
