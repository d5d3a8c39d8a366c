#include "datasets_synthetic/simulated_rig.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

#include "geometry/form_factors.h"
#include "projection/projection_rig.h"

namespace procam {
namespace {

}  // namespace

bool SimulatedCameraOptions::Check(std::string* why) const {
  if (!(exposure > 0.0) || !(vignetting >= 0.0 && vignetting < 1.0) || !(shot_noise >= 0.0) ||
      !(read_noise >= 0.0) || !(gamma > 0.0)) {
    *why = "need exposure > 0, vignetting in [0,1), noise >= 0, gamma > 0";
    return false;
  }
  return true;
}

bool SimulatedRigOptions::Check(std::string* why) const {
  if (world_factor < 1 || solver_patches < 1 || direct_samples < 1 || !(ray_margin > 0.0) ||
      !(albedo_variation >= 0.0 && albedo_variation < 0.5)) {
    *why = "need world_factor, solver_patches, direct_samples >= 1, ray_margin > 0, albedo_variation in [0, 0.5)";
    return false;
  }
  return camera.Check(why);
}

CameraGeometry CameraFromPlacement(const DevicePlacement& placement, bool distortion) {
  const double f = 0.5 * placement.width / std::tan(0.5 * placement.horizontal_fov_deg * std::numbers::pi / 180.0);
  const double cx = 0.5 * (placement.width - 1), cy = 0.5 * (placement.height - 1);
  const Eigen::Isometry3d cam_from_world = ProjFromWorldLookingAt(placement.centre, placement.target, placement.up);
  if (!distortion) return CameraGeometry::Pinhole(f, f, cx, cy, placement.width, placement.height, cam_from_world);
  return CameraGeometry("LENSMODEL_OPENCV4", {f, f, cx, cy, -0.05, 0.01, 0.0, 0.0}, placement.width,
                        placement.height, cam_from_world);
}

Projector ProjectorFromPlacement(const DevicePlacement& placement) {
  Projector projector;
  projector.name = placement.name;
  const double f = 0.5 * placement.width / std::tan(0.5 * placement.horizontal_fov_deg * std::numbers::pi / 180.0);
  projector.geometry = ProjectorGeometry::Pinhole(
      f, f, 0.5 * (placement.width - 1), 0.5 * (placement.height - 1), placement.width, placement.height,
      ProjFromWorldLookingAt(placement.centre, placement.target, placement.up));
  // Bright enough to light the surface it aims at to about 1.2 × white on axis; 500:1 contrast.
  const double distance = (placement.target - placement.centre).norm();
  projector.photometry.max = Vec3::Constant(1.2 * distance * distance);
  projector.photometry.black = projector.photometry.max / 500.0;
  return projector;
}

SimulatedRig::SimulatedRig(const Scene& scene, std::vector<Projector> projectors, CameraGeometry camera,
                           const SimulatedRigOptions& options)
    : scene_(scene), projectors_(std::move(projectors)), camera_(std::move(camera)), options_(options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("simulated rig: " + why);
  SubdivisionOptions subdivision;
  subdivision.target_patches = options.solver_patches * options.world_factor;
  world_ = SubdividePatches(scene_, subdivision);
  // Textured albedo: each world patch reflects with the albedo at its centre (times its
  // reflectance texture's mean over it, SubdividePatches's, on a printed surface).
  for (int i = 0; i < world_.fine.size(); ++i) {
    const Patch& patch = world_.fine.patches[i];
    const double factor = AlbedoFactor(patch.surface, PatchTextureCoordinate(patch, patch.centroid));
    world_.fine.reflectance.row(i) = (factor * world_.fine.reflectance.row(i)).cwiseMin(0.99);
  }
  const Eigen::MatrixXd f = ComputeFormFactors(scene_, world_.fine, FormFactorOptions(), nullptr);
  world_radiosity_ = std::make_unique<RadiositySystem>(f, world_.fine.Areas(), world_.fine.reflectance);
  surfaces_ = std::make_unique<RayScene>(scene_);
  const RayScene patches(PatchScene(world_.fine));
  if (options.smooth_bounce) {
    const int n = world_.fine.size();
    std::vector<std::vector<int>> neighbours(n);
    for (const auto& [a, b] : world_.fine.adjacency) {
      if (world_.fine.patches[a].surface != world_.fine.patches[b].surface) continue;
      neighbours[a].push_back(b);
      neighbours[b].push_back(a);
    }
    bounce_nodes_.resize(n);
    for (int i = 0; i < n; ++i) {
      std::vector<int>& nodes = bounce_nodes_[i];
      nodes = {i};
      for (size_t ring_begin = 0, ring = 0; ring < 2; ++ring) {
        const size_t ring_end = nodes.size();
        for (size_t k = ring_begin; k < ring_end; ++k) {
          for (const int j : neighbours[nodes[k]]) {
            if (std::find(nodes.begin(), nodes.end(), j) == nodes.end()) nodes.push_back(j);
          }
        }
        ring_begin = ring_end;
      }
    }
  }

  const int width = camera_.width(), height = camera_.height();
  std::vector<Vec3> directions;
  std::vector<double> densities;
  camera_.UnprojectImage(&directions, &densities);
  const Eigen::Isometry3d world_from_cam = camera_.proj_from_world().inverse();
  const Vec3 origin = world_from_cam.translation();
  hits_.assign(static_cast<size_t>(width) * height, PixelHit());
  coverage_ = cv::Mat(height, width, CV_8UC1, cv::Scalar(0));
#pragma omp parallel for schedule(dynamic, 8)
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const size_t index = static_cast<size_t>(row) * width + col;
      const Vec3 direction = world_from_cam.linear() * directions[index];
      double t = 0.0;
      int patch = -1;
      if (!patches.Intersect(origin, direction, 0.0, std::numeric_limits<double>::infinity(), &t, &patch)) continue;
      const Vec3 point = origin + t * direction;
      if (world_.fine.patches[patch].normal.dot(origin - point) <= 0.0) continue;  // the unlit side
      const Patch& seen = world_.fine.patches[patch];
      const Vec2 uv = PatchTextureCoordinate(seen, point);
      const Vec3 reflectance =
          (AlbedoFactor(seen.surface, uv) * scene_.surfaces[seen.surface].ReflectanceAt(uv))
              .cwiseMin(0.99);
      hits_[index] = {patch, point, reflectance};
      coverage_.at<uchar>(row, col) = 255;
    }
  }
}

double SimulatedRig::AlbedoFactor(int surface, const Vec2& uv) const {
  if (options_.albedo_variation == 0.0) return 1.0;
  // A smooth, deterministic pattern in [−1, 1]: a few incommensurate waves, different per surface.
  const double s = 0.61803398875 * (surface + 1);
  const double pattern = 0.5 * std::sin(2 * std::numbers::pi * (3.0 * uv.x() + s)) * std::cos(2 * std::numbers::pi * (4.0 * uv.y() + 0.5 * s)) +
                         0.5 * std::sin(2 * std::numbers::pi * (7.0 * uv.x() + 5.0 * uv.y()) + 3.0 * s);
  return 1.0 + options_.albedo_variation * pattern;
}

bool SimulatedRig::PointSeenByPixel(int row, int col, Vec3* point_in_world, Vec3* normal) const {
  if (row < 0 || row >= camera_.height() || col < 0 || col >= camera_.width()) return false;
  const PixelHit& hit = hits_[static_cast<size_t>(row) * camera_.width() + col];
  if (hit.world_patch < 0) return false;
  if (point_in_world) *point_in_world = hit.point;
  if (normal) *normal = world_.fine.patches[hit.world_patch].normal;
  return true;
}

Vec3 SimulatedRig::SmoothBounce(const PixelHit& hit, const Eigen::MatrixX3d& irradiance) const {
  Vec3 sum = Vec3::Zero();
  double weight_sum = 0.0;
  for (const int j : bounce_nodes_[hit.world_patch]) {
    const Patch& patch = world_.fine.patches[j];
    const double radius2 = 1.5 * 1.5 * patch.area;
    const double d2 = (hit.point - patch.centroid).squaredNorm();
    if (d2 >= radius2) continue;
    const double t = 1.0 - d2 / radius2;
    sum += (t * t) * irradiance.row(j).transpose();
    weight_sum += t * t;
  }
  const Vec3 field = weight_sum > 0.0 ? Vec3(sum / weight_sum)
                                      : Vec3(irradiance.row(hit.world_patch).transpose());
  return hit.reflectance.cwiseProduct(field);
}

cv::Mat SimulatedRig::RenderRadiance(const std::vector<ProjectorImage>& images) const {
  if (images.size() != projectors_.size()) {
    throw std::invalid_argument("simulated rig: " + std::to_string(images.size()) + " images for " +
                                std::to_string(projectors_.size()) + " projectors");
  }
  // Bounce light on the world mesh, driven by the direct light the images deliver there.
  const Eigen::MatrixX3d direct_world =
      SimulateDirectLight(world_.fine, projectors_, images, options_.direct_samples, options_.ray_margin);
  const Eigen::MatrixX3d indirect = world_radiosity_->Solve(direct_world) - direct_world;
  // Indirect irradiance per world patch (exitance / ρ), what smooth_bounce interpolates.
  const Eigen::MatrixX3d indirect_irradiance =
      indirect.cwiseQuotient(world_.fine.reflectance.cwiseMax(1e-9));

  const int width = camera_.width(), height = camera_.height();
  cv::Mat radiance(height, width, CV_32FC3, cv::Scalar(0, 0, 0));
#pragma omp parallel for schedule(dynamic, 8)
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const PixelHit& hit = hits_[static_cast<size_t>(row) * width + col];
      if (hit.world_patch < 0) continue;
      const Patch& patch = world_.fine.patches[hit.world_patch];
      Vec3 irradiance = Vec3::Zero();
      for (size_t k = 0; k < projectors_.size(); ++k) {
        const Projector& projector = projectors_[k];
        Vec2 pixel;
        const double gain = projector.geometry.Gain(hit.point, patch.normal, &pixel);
        if (gain <= 0.0 || !projector.geometry.InImage(pixel)) continue;
        if (surfaces_->Occluded(hit.point, projector.geometry.CentreInWorld(), options_.ray_margin)) continue;
        const int px = static_cast<int>(std::lround(pixel.x())), py = static_cast<int>(std::lround(pixel.y()));
        const cv::Vec3w& code = images[k].codes.at<cv::Vec3w>(py, px);
        const double scale = 1.0 / projector.photometry.MaxCode();
        irradiance += gain * projector.photometry.Output(Vec3(code[0], code[1], code[2]) * scale);
      }
      // On a printed surface the world patch's mean reflectance is not the point's: the bounce
      // light it reflects is its own reflectance times the patch's indirect irradiance.
      const bool printed = scene_.surfaces[patch.surface].reflectance_texture.HasTexture();
      const Vec3 bounce = options_.smooth_bounce ? SmoothBounce(hit, indirect_irradiance)
                          : printed              ? Vec3(hit.reflectance.cwiseProduct(
                                                       indirect_irradiance.row(hit.world_patch).transpose()))
                                                 : Vec3(indirect.row(hit.world_patch).transpose());
      const Vec3 exitance = hit.reflectance.cwiseProduct(irradiance) + bounce;
      radiance.at<cv::Vec3f>(row, col) = cv::Vec3f(exitance[0], exitance[1], exitance[2]);
    }
  }
  return radiance;
}

cv::Mat SimulatedRig::PhotographLinear(const std::vector<ProjectorImage>& images, uint32_t seed_offset) const {
  const SimulatedCameraOptions& cam = options_.camera;
  cv::Mat photo = RenderRadiance(images);
  const int width = photo.cols, height = photo.rows;
  const double half_diagonal = 0.5 * std::hypot(width, height);
  std::mt19937 random(cam.seed + seed_offset);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const double r = std::hypot(col - 0.5 * (width - 1), row - 0.5 * (height - 1)) / half_diagonal;
      const double factor = cam.exposure * (1.0 - cam.vignetting * r * r);
      cv::Vec3f& value = photo.at<cv::Vec3f>(row, col);
      for (int c = 0; c < 3; ++c) {
        const double signal = factor * value[c];
        const double sigma = std::sqrt(cam.shot_noise * cam.shot_noise * std::max(signal, 0.0) +
                                       cam.read_noise * cam.read_noise);
        value[c] = static_cast<float>(signal + sigma * normal(random));
      }
    }
  }
  return photo;
}

cv::Mat SimulatedRig::Photograph8(const std::vector<ProjectorImage>& images, uint32_t seed_offset) const {
  const cv::Mat linear = PhotographLinear(images, seed_offset);
  cv::Mat photo(linear.rows, linear.cols, CV_8UC3);
  for (int row = 0; row < linear.rows; ++row) {
    for (int col = 0; col < linear.cols; ++col) {
      const cv::Vec3f& value = linear.at<cv::Vec3f>(row, col);
      cv::Vec3b& code = photo.at<cv::Vec3b>(row, col);
      for (int c = 0; c < 3; ++c) {
        const double v = std::clamp(static_cast<double>(value[c]), 0.0, 1.0);
        code[c] = static_cast<uchar>(std::lround(255.0 * std::pow(v, 1.0 / options_.camera.gamma)));
      }
    }
  }
  return photo;
}

cv::Mat SimulatedRig::RenderDesired() const {
  const int width = camera_.width(), height = camera_.height();
  cv::Mat desired(height, width, CV_32FC3, cv::Scalar(0, 0, 0));
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      const PixelHit& hit = hits_[static_cast<size_t>(row) * width + col];
      if (hit.world_patch < 0) continue;
      const Patch& patch = world_.fine.patches[hit.world_patch];
      const Vec3 linear = scene_.white * scene_.surfaces[patch.surface].desired.LinearAt(PatchTextureCoordinate(patch, hit.point));
      desired.at<cv::Vec3f>(row, col) = cv::Vec3f(linear[0], linear[1], linear[2]);
    }
  }
  return desired;
}

}  // namespace procam
