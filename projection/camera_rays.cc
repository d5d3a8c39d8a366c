#include "projection/camera_rays.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>

#include "compensation/radiosity.h"
#include "geometry/ray_scene.h"
#include "projection/direct_light.h"
#include "projection/seamless_light.h"

namespace procam {

Eigen::MatrixX3d PatchPixelSums::Means(const Eigen::MatrixX3d& fallback, int min_pixels) const {
  Eigen::MatrixX3d means = fallback;
  for (int i = 0; i < count.size(); ++i) {
    if (count[i] >= std::max(1, min_pixels)) means.row(i) = Mean(i);
  }
  return means;
}

PatchPixelSums SumPixelsPerPatch(const cv::Mat& picture, const std::vector<int>& pixel_patch,
                                 int patches, const std::vector<bool>* mask) {
  if (picture.type() != CV_32FC3 ||
      pixel_patch.size() != static_cast<size_t>(picture.rows) * picture.cols ||
      (mask != nullptr && mask->size() != pixel_patch.size())) {
    throw std::invalid_argument("SumPixelsPerPatch: need a CV_32FC3 picture of the map's size");
  }
  return SumPixelsPerPatch(pixel_patch, picture.cols, picture.rows, patches,
                           [&](int x, int y, Eigen::RowVector3d* rgb) {
                             if (mask != nullptr &&
                                 !(*mask)[static_cast<size_t>(y) * picture.cols + x])
                               return false;
                             const cv::Vec3f& v = picture.at<cv::Vec3f>(y, x);
                             *rgb = Eigen::RowVector3d(v[0], v[1], v[2]);
                             return true;
                           });
}

CameraPixelRays CastCameraPixels(const Scene& scene, const PatchLevel& level,
                                 const std::vector<Projector>& projectors,
                                 const ProjectorGeometry& camera, double ray_margin) {
  CameraPixelRays rays;
  rays.width = camera.width();
  rays.height = camera.height();
  rays.projectors = static_cast<int>(projectors.size());
  const size_t count = static_cast<size_t>(rays.width) * rays.height;
  rays.patch.assign(count, -1);
  rays.gain.assign(count * rays.projectors, 0.0f);
  rays.projector_pixel.assign(count * rays.projectors, -1);
  rays.point.assign(count, Eigen::Vector3f::Zero());
  const RayScene patches(PatchScene(level));
  const RayScene surfaces(scene);
  std::vector<Vec3> directions;
  std::vector<double> densities;
  camera.UnprojectImage(&directions, &densities);
  const Eigen::Isometry3d room_from_cam = camera.proj_from_world().inverse();
  const Vec3 origin = room_from_cam.translation();
#pragma omp parallel for schedule(dynamic, 8)
  for (int row = 0; row < rays.height; ++row) {
    for (int col = 0; col < rays.width; ++col) {
      const size_t index = static_cast<size_t>(row) * rays.width + col;
      const Vec3 direction = room_from_cam.linear() * directions[index];
      double t = 0.0;
      int hit = -1;
      if (!patches.Intersect(origin, direction, 0.0, std::numeric_limits<double>::infinity(), &t,
                             &hit)) {
        continue;
      }
      const Vec3 point = origin + t * direction;
      const Patch& patch = level.patches[hit];
      if (patch.normal.dot(origin - point) <= 0.0) continue;  // its unlit side
      rays.patch[index] = hit;
      rays.point[index] = point.cast<float>();
      for (int k = 0; k < rays.projectors; ++k) {
        const ProjectorGeometry& projector = projectors[k].geometry;
        Vec2 pixel;
        const double gain = projector.Gain(point, patch.normal, &pixel);
        if (gain <= 0.0 || !projector.InImage(pixel)) continue;
        if (surfaces.Occluded(point, projector.CentreInWorld(), ray_margin)) continue;
        // Pixel (c, r) covers [c − ½, c + ½] × [r − ½, r + ½] (projector.h).
        const int x =
            std::clamp(static_cast<int>(std::floor(pixel.x() + 0.5)), 0, projector.width() - 1);
        const int y =
            std::clamp(static_cast<int>(std::floor(pixel.y() + 0.5)), 0, projector.height() - 1);
        rays.gain[index * rays.projectors + k] = static_cast<float>(gain);
        rays.projector_pixel[index * rays.projectors + k] = y * projector.width() + x;
      }
    }
  }
  return rays;
}

CameraPixelLighting LightCameraPixels(const Scene& scene, const PatchLevel& level,
                                      const ProjectorGeometry& projector,
                                      const ProjectorGeometry& camera, double ray_margin) {
  Projector one;
  one.geometry = projector;
  const CameraPixelRays rays = CastCameraPixels(scene, level, {one}, camera, ray_margin);
  CameraPixelLighting lighting;
  lighting.width = rays.width;
  lighting.height = rays.height;
  lighting.patch = rays.patch;
  lighting.gain.assign(rays.gain.begin(), rays.gain.end());
  return lighting;
}

// The predicted exitance of every camera pixel (CV_32FC3, working R, G, B, scene units; 0 where
// the pixel sees nothing) for the images shown, by the model's split of the light at the point
// x of patch i the pixel sees (projection/photometric_transfer.h's transfer):
//     x_p = ρ_i ⊙ (Σ_k G_k(x) · output_k(code_k) + (F B)_i),
// code_k the code of the projector pixel that lights x, output_k the projector's photometry as
// the model knows it, and B = K⁻¹(ρ ⊙ D) the radiosity of the direct irradiance D the shown
// images deliver to each patch (the renderer's flux bookkeeping), so the bounce term is the one
// of the light actually shown. `shown_radiosity` (optional) receives that B.
namespace {

// Per camera pixel, the factor on its patch's bounce irradiance (PredictPixels' comment): the
// smooth field over each surface (every same-surface neighbour shares it: bounce light does not
// step where the desired appearance does) at the point the pixel sees, scaled so that its mean
// over the pixels that see each patch is 1. Empty where the rays carry no points or the rig no
// centroids or adjacency (the bounce then stays constant over each patch).
std::vector<Eigen::Vector3f> BounceFactors(const CameraPixelRays& rays, const ProjectionRig& rig,
                                           const Eigen::MatrixX3d& bounce) {
  if (rays.point.size() != rays.patch.size() || rig.centroid.rows() != rig.size() ||
      rig.adjacency.empty()) {
    return {};
  }
  SeamlessLightOptions smooth;
  smooth.tolerance = 1.0;
  const SeamlessField field(rig, smooth);
  const Eigen::MatrixX3d nodes = field.NodeValues(bounce.cwiseMax(0.0));
  const Eigen::MatrixX3d means = field.PatchMeans(nodes);
  std::vector<Eigen::Vector3f> factor(rays.patch.size(), Eigen::Vector3f::Ones());
#pragma omp parallel for schedule(dynamic, 8)
  for (int row = 0; row < rays.height; ++row) {
    for (int col = 0; col < rays.width; ++col) {
      const size_t index = static_cast<size_t>(row) * rays.width + col;
      const int i = rays.patch[index];
      if (i < 0 || field.Flat(i)) continue;
      factor[index] = field.Factor(i, rays.point[index], nodes, means);
    }
  }
  const PatchPixelSums sums = SumPixelsPerPatch(
      rays.patch, rays.width, rays.height, rig.size(), [&](int x, int y, Eigen::RowVector3d* rgb) {
        *rgb = factor[static_cast<size_t>(y) * rays.width + x].cast<double>().transpose();
        return true;
      });
  for (size_t index = 0; index < rays.patch.size(); ++index) {
    const int i = rays.patch[index];
    if (i < 0) continue;
    for (int c = 0; c < 3; ++c)
      if (sums.sum(i, c) > 0.0)
        factor[index][c] *= static_cast<float>(sums.count[i] / sums.sum(i, c));
  }
  return factor;
}

}  // namespace

cv::Mat PredictPixels(const CameraPixelRays& rays, const ProjectionRig& rig,
                      const std::vector<ProjectorImage>& images,
                      const Eigen::MatrixXd& form_factors, Eigen::MatrixX3d* shown_radiosity) {
  const Eigen::MatrixX3d direct = DirectLightModel(rig, images).Irradiance();
  const RadiositySystem system(form_factors, rig.area, rig.reflectance);
  const Eigen::MatrixX3d radiosity = system.Solve(rig.reflectance.cwiseProduct(direct));
  const Eigen::MatrixX3d bounce = form_factors * radiosity;
  if (shown_radiosity) *shown_radiosity = radiosity;
  // Output per code: the photometry's response per primary, mixed, black to max.
  std::vector<std::vector<Eigen::Vector3d>> light(images.size());
  for (size_t k = 0; k < images.size(); ++k) {
    const ProjectorPhotometry& photometry = rig.projectors[k].photometry;
    const int max_code = (1 << images[k].bits) - 1;
    light[k].resize(max_code + 1);
    for (int code = 0; code <= max_code; ++code) {
      const double drive = double(code) / max_code;
      light[k][code] =
          Eigen::Vector3d(photometry.response[0].Light(drive), photometry.response[1].Light(drive),
                          photometry.response[2].Light(drive));
    }
  }
  const std::vector<Eigen::Vector3f> bounce_factor = BounceFactors(rays, rig, bounce);
  // With every projector's reflectance map, the point's reflectance relative to its patch's.
  const bool per_pixel_reflectance = HasReflectanceMaps(rig);
  const Eigen::MatrixX3d map_means =
      per_pixel_reflectance ? MapReflectanceMeans(rig) : Eigen::MatrixX3d();
  cv::Mat predicted(rays.height, rays.width, CV_32FC3, cv::Scalar::all(0));
#pragma omp parallel for schedule(dynamic, 8)
  for (int row = 0; row < rays.height; ++row) {
    for (int col = 0; col < rays.width; ++col) {
      const size_t index = static_cast<size_t>(row) * rays.width + col;
      const int i = rays.patch[index];
      if (i < 0) continue;
      Eigen::Vector3d irradiance = bounce.row(i).transpose();
      if (!bounce_factor.empty())
        irradiance = irradiance.cwiseProduct(bounce_factor[index].cast<double>());
      Eigen::Vector3d map_reflectance = Eigen::Vector3d::Zero();
      int mapped = 0;
      for (int k = 0; k < rays.projectors; ++k) {
        const int32_t pixel = rays.projector_pixel[index * rays.projectors + k];
        if (pixel < 0) continue;
        if (per_pixel_reflectance) {
          map_reflectance += rig.maps[k].reflectance[pixel].cast<double>();
          ++mapped;
        }
        const ProjectorPhotometry& p = rig.projectors[k].photometry;
        const cv::Vec3w& code = reinterpret_cast<const cv::Vec3w*>(images[k].codes.data)[pixel];
        const int max_code = static_cast<int>(light[k].size()) - 1;
        const Eigen::Vector3d relative(light[k][std::min<int>(code[0], max_code)][0],
                                       light[k][std::min<int>(code[1], max_code)][1],
                                       light[k][std::min<int>(code[2], max_code)][2]);
        const Eigen::Vector3d output =
            p.black + (p.max - p.black).cwiseProduct(p.mixing * relative);
        irradiance += double(rays.gain[index * rays.projectors + k]) * output;
      }
      Eigen::Vector3d reflectance = rig.reflectance.row(i).transpose();
      if (mapped > 0) {
        for (int c = 0; c < 3; ++c) {
          if (map_means(i, c) > 0.0)
            reflectance[c] *= map_reflectance[c] / mapped / map_means(i, c);
        }
      }
      const Eigen::Vector3d exitance = reflectance.cwiseProduct(irradiance);
      predicted.at<cv::Vec3f>(row, col) =
          cv::Vec3f(float(exitance[0]), float(exitance[1]), float(exitance[2]));
    }
  }
  return predicted;
}

}  // namespace procam
