#include "projection/projection_rig.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "base/io.h"
#include "base/timing.h"
#include "projection/render_steps.h"

namespace procam {
namespace {

// C¹ ramp (smoothstep) from 0 at `inside` = 0 to 1 at `inside` = ramp; 1 for ramp 0.
double Ramp(double inside, double ramp) {
  if (!(inside > 0.0)) return 0.0;
  if (ramp <= 0.0 || inside >= ramp) return 1.0;
  const double t = inside / ramp;
  return t * t * (3.0 - 2.0 * t);
}

double Luminance(const Vec3& rgb) { return 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]; }

// One projector while the rig is built: its map, and per pixel the world point it lights
// (single precision suffices: Embree's hits are single precision) and a blending-ramp field.
struct Caster {
  const Projector* projector = nullptr;
  Vec3 centre;
  double luminance = 0.0;  // of max − black
  double ramp = 0.0;       // feather ramp, pixels
  ProjectorMap map;
  std::vector<Eigen::Vector3f> point;  // hit point per lit pixel (world)
  std::vector<float> distance;         // ray length per pixel that hits a surface (0: none), m
  cv::Mat edge_distance;               // CV_32F: pixels to the nearest start of a shadow

  const ProjectorGeometry& geometry() const { return projector->geometry; }

  // Blending ramp at a pixel coordinate: the image border and the start of its shadows behind
  // occluders both fade the projector out.
  double Feather(const Vec2& pixel) const {
    const int width = map.width, height = map.height;
    double inside = std::min(
        {pixel.x() + 0.5, width - 0.5 - pixel.x(), pixel.y() + 0.5, height - 0.5 - pixel.y()});
    if (!(inside > 0.0)) return 0.0;
    if (ramp <= 0.0) return 1.0;
    // Bilinear in the edge-distance field, so the weight varies continuously with the point.
    const double x = std::clamp(pixel.x(), 0.0, width - 1.0),
                 y = std::clamp(pixel.y(), 0.0, height - 1.0);
    const int x0 = std::min(static_cast<int>(x), width - 2 < 0 ? 0 : width - 2);
    const int y0 = std::min(static_cast<int>(y), height - 2 < 0 ? 0 : height - 2);
    const int x1 = std::min(x0 + 1, width - 1), y1 = std::min(y0 + 1, height - 1);
    const double fx = x - x0, fy = y - y0;
    const double edge = (1 - fx) * (1 - fy) * edge_distance.at<float>(y0, x0) +
                        fx * (1 - fy) * edge_distance.at<float>(y0, x1) +
                        (1 - fx) * fy * edge_distance.at<float>(y1, x0) +
                        fx * fy * edge_distance.at<float>(y1, x1);
    // The field is 0 at the first pixels beyond a silhouette; the silhouette itself (where this
    // projector's visibility ends) is about ½ pixel further, so the ramp starts from there.
    return Ramp(std::min(inside, edge - 0.5), ramp);
  }
};

// Barycentric coordinates of p's projection onto the plane of the triangle (a, b, c).
Vec3 Barycentric(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& p) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d00 = ab.dot(ab), d01 = ab.dot(ac), d11 = ac.dot(ac);
  const double d20 = ap.dot(ab), d21 = ap.dot(ac);
  const double denominator = d00 * d11 - d01 * d01;
  if (!(denominator > 0.0)) return Vec3(1.0, 0.0, 0.0);  // degenerate: the first corner
  const double beta = (d11 * d20 - d01 * d21) / denominator;
  const double gamma = (d00 * d21 - d01 * d20) / denominator;
  return Vec3(1.0 - beta - gamma, beta, gamma);
}

// Step 1: every pixel's ray, first hit, gain (and the hit's texture coordinate if asked for).
void CastRays(const PatchLevel& level, const RayScene& rays, bool texture_coordinates,
              Caster* caster) {
  const ProjectorGeometry& geometry = caster->geometry();
  const int width = geometry.width(), height = geometry.height();
  ProjectorMap& map = caster->map;
  map.width = width;
  map.height = height;
  map.pixel_solid_angle = 1.0 / geometry.AxisPixelDensity();
  const size_t pixels = static_cast<size_t>(width) * height;
  map.patch.assign(pixels, -1);
  map.gain.assign(pixels, 0.0f);
  map.weight.assign(pixels, 0.0f);
  if (texture_coordinates) map.uv.assign(pixels, Eigen::Vector2f::Zero());
  caster->point.assign(pixels, Eigen::Vector3f::Zero());
  caster->distance.assign(pixels, 0.0f);
  std::vector<Vec3> directions;
  std::vector<double> densities;
  geometry.UnprojectImage(&directions, &densities);
  const Eigen::Matrix3d world_from_proj = geometry.proj_from_world().rotation().transpose();
  const Vec3& centre = caster->centre;
  const double axis_density = geometry.AxisPixelDensity();
  const double infinity = std::numeric_limits<double>::infinity();
#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t index = static_cast<size_t>(y) * width + x;
      const Vec3 direction = world_from_proj * directions[index];
      if (!direction.allFinite()) continue;
      double distance = 0.0;
      int patch = -1;
      if (!rays.Intersect(centre, direction, 0.0, infinity, &distance, &patch)) continue;
      caster->distance[index] = static_cast<float>(distance);  // also for unlit sides: they occlude
      const double cosine = -level.patches[patch].normal.dot(direction);
      if (!(cosine > 0.0)) continue;  // the unlit side of a surface: blocks, but lights nothing
      const double gain = densities[index] / axis_density * cosine / (distance * distance);
      if (!(gain > 0.0) || !std::isfinite(gain)) continue;
      map.patch[index] = patch;
      map.gain[index] = static_cast<float>(gain);
      const Vec3 point = centre + distance * direction;
      caster->point[index] = point.cast<float>();
      if (texture_coordinates)
        map.uv[index] = PatchTextureCoordinate(level.patches[patch], point).cast<float>();
    }
  }
}

// Step 2: distance (pixels) from each pixel to the nearest pixel just beyond an occluder's
// silhouette: a lit pixel with a 4-neighbour more than 5% nearer. That is where this
// projector's shadow begins on the surface behind, and where another projector's light must
// take over smoothly. (The near side of a silhouette, surface edges with nothing behind, and
// corners where two surfaces meet are no seams, so they do not fade.)
void EdgeDistance(Caster* caster) {
  const ProjectorMap& map = caster->map;
  cv::Mat smooth(map.height, map.width, CV_8U, cv::Scalar(255));
  const auto& depth = caster->distance;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < map.height; ++y) {
    for (int x = 0; x < map.width; ++x) {
      const size_t index = static_cast<size_t>(y) * map.width + x;
      if (map.patch[index] < 0) continue;
      bool beyond_silhouette = false;
      auto compare = [&](int nx, int ny) {
        if (nx < 0 || ny < 0 || nx >= map.width || ny >= map.height) return;
        const float other = depth[static_cast<size_t>(ny) * map.width + nx];
        if (other > 0.0f && other < 0.95f * depth[index]) beyond_silhouette = true;
      };
      compare(x - 1, y);
      compare(x + 1, y);
      compare(x, y - 1);
      compare(x, y + 1);
      if (beyond_silhouette) smooth.at<uint8_t>(y, x) = 0;
    }
  }
  cv::distanceTransform(smooth, caster->edge_distance, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
}

// Step 3: blending weights, w = a_k / Σ_j a_j at each lit point.
void Blend(int k, const std::vector<Caster>& casters, const PatchLevel& level, const RayScene& rays,
           const ProjectionRigOptions& options, ProjectorMap* map) {
  const Caster& caster = casters[k];
  const int width = map->width, height = map->height;
  const int count = static_cast<int>(casters.size());
#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t index = static_cast<size_t>(y) * width + x;
      const int patch = map->patch[index];
      if (patch < 0) continue;
      const Vec3 point = caster.point[index].cast<double>();
      const Vec3& normal = level.patches[patch].normal;
      const double own = map->gain[index] * caster.luminance * caster.Feather(Vec2(x, y));
      double total = own;
      for (int j = 0; j < count; ++j) {
        if (j == k) continue;
        Vec2 q;
        const double gain_j = casters[j].geometry().Gain(point, normal, &q);
        if (!(gain_j > 0.0) || !casters[j].geometry().InImage(q)) continue;
        const double feather = casters[j].Feather(q);
        if (feather <= 0.0) continue;
        if (rays.Occluded(point, casters[j].centre, options.ray_margin)) continue;
        total += gain_j * casters[j].luminance * feather;
      }
      // Weight 1 when no one else lights the point (even where own feather is 0); a weight of
      // exactly 0 is kept positive so every lit pixel has a defined share.
      const float weight = total > 0.0 ? static_cast<float>(own / total) : 1.0f;
      map->weight[index] = std::max(weight, std::numeric_limits<float>::min());
    }
  }
}

// ProjectorMap::pixels_by_share and its companions, from pixels_by_patch and share.
void SortByShare(ProjectorMap* map) {
  map->pixels_by_share.resize(map->lit_pixels);
  map->share_by_share.resize(map->lit_pixels);
  map->bayer_by_share.resize(map->lit_pixels);
  const int n = static_cast<int>(map->patch_begin.size()) - 1;
#pragma omp parallel
  {
    std::vector<std::pair<float, int32_t>> pixels;  // (share, pixel): ties by pixel, one order
#pragma omp for schedule(dynamic, 16)
    for (int i = 0; i < n; ++i) {
      pixels.clear();
      for (int position = map->patch_begin[i]; position < map->patch_begin[i + 1]; ++position) {
        const int32_t index = map->pixels_by_patch[position];
        pixels.emplace_back(map->share[index], index);
      }
      std::sort(pixels.begin(), pixels.end());
      for (size_t j = 0; j < pixels.size(); ++j) {
        const size_t position = map->patch_begin[i] + j;
        const auto [share, index] = pixels[j];
        map->pixels_by_share[position] = index;
        map->share_by_share[position] = share;
        map->bayer_by_share[position] =
            static_cast<uint8_t>(internal::BayerCell(index % map->width, index / map->width));
      }
    }
  }
}

}  // namespace

bool ProjectionRigOptions::Check(std::string* why) const {
  if (!(feather >= 0.0 && feather <= 0.5)) {
    *why = "feather must be in [0, 0.5]";
    return false;
  }
  if (coverage_samples < 1 || coverage_samples > 16) {
    *why = "coverage_samples must be in [1, 16]";
    return false;
  }
  if (!(ray_margin > 0.0 && ray_margin < 0.1)) {
    *why = "ray_margin must be in (0, 0.1) metres";
    return false;
  }
  return true;
}

double FeatherWeight(const Vec2& pixel, int width, int height, double ramp) {
  return Ramp(std::min({pixel.x() + 0.5, width - 0.5 - pixel.x(), pixel.y() + 0.5,
                        height - 0.5 - pixel.y()}),
              ramp);
}

Vec2 PatchTextureCoordinate(const Patch& patch, const Vec3& point) {
  const auto& c = patch.corners;
  const auto& t = patch.uv;
  const Vec3 first = Barycentric(c[0], c[1], c[2], point);
  if (patch.corner_count == 4) {
    // The triangle that contains the point is the one where its least coordinate is largest
    // (≥ 0 inside; near the diagonal both agree, since the map is continuous across it).
    const Vec3 second = Barycentric(c[0], c[2], c[3], point);
    if (second.minCoeff() > first.minCoeff())
      return second[0] * t[0] + second[1] * t[2] + second[2] * t[3];
  }
  return first[0] * t[0] + first[1] * t[1] + first[2] * t[2];
}

Scene PatchScene(const PatchLevel& level) {
  Scene scene;
  scene.name = "patches";
  scene.surfaces.reserve(level.patches.size());
  for (const Patch& patch : level.patches) {
    Surface surface;
    surface.quad.fill(Vec3::Zero());
    if (patch.corner_count == 4) {
      surface.kind = Surface::Kind::kQuad;
      surface.quad = patch.corners;
    } else {
      surface.kind = Surface::Kind::kMesh;
      surface.mesh_vertices = {patch.corners[0], patch.corners[1], patch.corners[2]};
      MeshTriangle triangle;
      triangle.vertex = {0, 1, 2};
      triangle.uv.fill(Vec2::Zero());
      surface.mesh_triangles = {triangle};
    }
    scene.surfaces.push_back(std::move(surface));
  }
  return scene;
}

ProjectionRig BuildProjectionRig(const PatchLevel& level, std::vector<Projector> projectors,
                                 const ProjectionRigOptions& options,
                                 ProjectionRigSummary* summary) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("ProjectionRigOptions: " + why);
  const auto start = Clock::now();
  ProjectionRig rig;
  rig.projectors = std::move(projectors);
  const int n = level.size();
  rig.area = level.Areas();
  rig.reflectance = level.reflectance;
  rig.surface.resize(n);
  rig.centroid.resize(n, 3);
  for (int i = 0; i < n; ++i) {
    rig.surface[i] = level.patches[i].surface;
    rig.centroid.row(i) = level.patches[i].centroid.transpose();
  }
  if (level.desired_linear.rows() == n) rig.desired = level.desired_linear;
  rig.adjacency = level.adjacency;
  rig.lower = Eigen::MatrixX3d::Zero(n, 3);
  rig.upper = Eigen::MatrixX3d::Zero(n, 3);
  rig.blended_area = Eigen::VectorXd::Zero(n);
  rig.coverage_scale = Eigen::MatrixXd::Ones(n, static_cast<Eigen::Index>(rig.projectors.size()));
  std::vector<char> wholly_lit(n, 0);
  const RayScene rays(PatchScene(level));
  const int projector_count = static_cast<int>(rig.projectors.size());
  std::vector<Caster> casters(projector_count);
  for (int k = 0; k < projector_count; ++k) {
    const Projector& projector = rig.projectors[k];
    Caster& caster = casters[k];
    caster.projector = &projector;
    caster.centre = projector.geometry.CentreInWorld();
    caster.luminance = Luminance(projector.photometry.max - projector.photometry.black);
    caster.ramp =
        options.feather * std::min(projector.geometry.width(), projector.geometry.height());
    CastRays(level, rays, options.texture_coordinates, &caster);
    int lit = 0;
    std::vector<char> reached(n, 0);
    for (const int32_t patch : caster.map.patch) {
      if (patch < 0) continue;
      ++lit;
      reached[patch] = 1;
    }
    caster.map.lit_pixels = lit;
    caster.map.patches_reached = static_cast<int>(std::count(reached.begin(), reached.end(), 1));
    if (lit == 0) {
      throw IoError(
          (projector.model_path.empty() ? std::string() : projector.model_path.string() + ": ") +
          "projector '" + projector.name + "' lights no patch of the scene (check its pose)");
    }
    EdgeDistance(&caster);
  }
  for (int k = 0; k < projector_count; ++k)
    Blend(k, casters, level, rays, options, &casters[k].map);
  for (int k = 0; k < projector_count; ++k) {
    const Projector& projector = rig.projectors[k];
    rig.maps.push_back(std::move(casters[k].map));
    ProjectorMap& map = rig.maps.back();
    map.share.assign(map.patch.size(), 0.0f);
    for (size_t index = 0; index < map.patch.size(); ++index) {
      if (map.patch[index] >= 0) map.share[index] = map.weight[index] / map.gain[index];
    }
    // Counting sort of the lit pixels by patch.
    map.patch_begin.assign(n + 1, 0);
    for (const int32_t patch : map.patch) {
      if (patch >= 0) ++map.patch_begin[patch + 1];
    }
    for (int i = 0; i < n; ++i) map.patch_begin[i + 1] += map.patch_begin[i];
    map.pixels_by_patch.assign(map.lit_pixels, 0);
    std::vector<int> next(map.patch_begin.begin(), map.patch_begin.end() - 1);
    for (size_t index = 0; index < map.patch.size(); ++index) {
      if (map.patch[index] >= 0)
        map.pixels_by_patch[next[map.patch[index]]++] = static_cast<int32_t>(index);
    }
    map.point_by_patch.resize(map.lit_pixels);
    for (int position = 0; position < map.lit_pixels; ++position)
      map.point_by_patch[position] = casters[k].point[map.pixels_by_patch[position]];
    SortByShare(&map);
    // Footprints of the pixels counted per patch; a patch this projector lights wholly gets its
    // pixels' footprints rescaled to its exact area (coverage scale, header comment).
    Eigen::VectorXd solid_angle_sum = Eigen::VectorXd::Zero(n),
                    footprint = Eigen::VectorXd::Zero(n), blended = Eigen::VectorXd::Zero(n);
    for (size_t index = 0; index < map.patch.size(); ++index) {
      const int patch = map.patch[index];
      if (patch < 0) continue;
      solid_angle_sum[patch] += map.pixel_solid_angle;
      footprint[patch] += map.pixel_solid_angle / map.gain[index];
      blended[patch] +=
          double(map.weight[index] / map.gain[index]) * map.pixel_solid_angle;  // = share · Ω
    }
    const Vec3 centre = projector.geometry.CentreInWorld();
#pragma omp parallel for schedule(dynamic, 8)
    for (int i = 0; i < n; ++i) {
      if (!(footprint[i] > 0.0)) continue;
      const Patch& patch = level.patches[i];
      std::vector<PatchSample> samples;
      SamplePatch(patch, options.coverage_samples, &samples);
      for (int c = 0; c < patch.corner_count; ++c)
        samples.push_back({patch.corners[c], Vec2::Zero(), 0.0});
      bool whole = true;
      for (const PatchSample& sample : samples) {
        Vec2 q;
        // Corners sit on the patch's edges: test them a hair inside, towards the centroid.
        const Vec3 point = sample.point + 1e-6 * (patch.centroid - sample.point);
        if (!(projector.geometry.Gain(point, patch.normal, &q) > 0.0) ||
            !projector.geometry.InImage(q) || rays.Occluded(point, centre, options.ray_margin)) {
          whole = false;
          break;
        }
      }
      if (whole) {
        rig.coverage_scale(i, k) = rig.area[i] / footprint[i];
        wholly_lit[i] = 1;
      }
    }
    for (int i = 0; i < n; ++i) {
      const double scale = rig.coverage_scale(i, k);
      rig.blended_area[i] += scale * blended[i];
      const double flux_per_area = scale * solid_angle_sum[i] / rig.area[i];
      for (int c = 0; c < 3; ++c) {
        rig.lower(i, c) += rig.reflectance(i, c) * flux_per_area * projector.photometry.black[c];
        rig.upper(i, c) += rig.reflectance(i, c) * flux_per_area * projector.photometry.max[c];
      }
    }
  }
  // Partly lit patches: bounds of their lit part (header comment).
  rig.lit_fraction = Eigen::VectorXd::Zero(n);
  for (int i = 0; i < n; ++i) {
    if (!(rig.blended_area[i] > 0.0)) continue;
    const double fraction = wholly_lit[i] || !options.lit_part
                                ? 1.0
                                : std::min(1.0, rig.blended_area[i] / rig.area[i]);
    rig.lit_fraction[i] = fraction;
    rig.lower.row(i) /= fraction;
    rig.upper.row(i) /= fraction;
  }
  if (summary) {
    summary->seconds =
        SecondsSince(start);
    summary->patches_reached = static_cast<int>((rig.blended_area.array() > 0.0).count());
  }
  return rig;
}

void AttachReflectanceMaps(const std::vector<cv::Mat>& maps, ProjectionRig* rig) {
  if (maps.size() != rig->maps.size()) {
    throw std::invalid_argument(std::to_string(maps.size()) + " reflectance maps for " +
                                std::to_string(rig->maps.size()) + " projectors");
  }
  for (size_t k = 0; k < maps.size(); ++k) {
    ProjectorMap& map = rig->maps[k];
    map.reflectance.clear();
    if (maps[k].empty()) continue;
    const std::string name = "projector '" + rig->projectors[k].name + "'";
    if (maps[k].type() != CV_32FC3 || maps[k].cols != map.width || maps[k].rows != map.height) {
      throw std::invalid_argument(name + ": its reflectance map is not " +
                                  std::to_string(map.width) + "x" + std::to_string(map.height) +
                                  " linear RGB (CV_32FC3)");
    }
    map.reflectance.resize(static_cast<size_t>(map.width) * map.height);
    for (int row = 0; row < map.height; ++row) {
      const cv::Vec3f* values = maps[k].ptr<cv::Vec3f>(row);
      for (int col = 0; col < map.width; ++col) {
        const cv::Vec3f& value = values[col];
        for (int c = 0; c < 3; ++c) {
          if (!(std::isfinite(value[c]) && value[c] >= 0.0f)) {
            throw std::invalid_argument(name +
                                        ": its reflectance map has a value that is not "
                                        "finite and >= 0 at pixel (" +
                                        std::to_string(col) + ", " + std::to_string(row) + ")");
          }
        }
        map.reflectance[static_cast<size_t>(row) * map.width + col] =
            Eigen::Vector3f(value[0], value[1], value[2]);
      }
    }
  }
}

bool HasReflectanceMaps(const ProjectionRig& rig) {
  if (rig.maps.empty()) return false;
  for (const ProjectorMap& map : rig.maps) {
    if (map.reflectance.size() != map.patch.size()) return false;
  }
  return true;
}

Eigen::MatrixX3d MapReflectanceMeans(const ProjectionRig& rig) {
  if (!HasReflectanceMaps(rig))
    throw std::invalid_argument("MapReflectanceMeans: not every projector has a reflectance map");
  const int n = rig.size();
  Eigen::MatrixX3d means = Eigen::MatrixX3d::Zero(n, 3);
#pragma omp parallel for schedule(dynamic, 16)
  for (int i = 0; i < n; ++i) {
    Vec3 sum = Vec3::Zero();
    double weight_sum = 0.0;
    for (size_t k = 0; k < rig.maps.size(); ++k) {
      const ProjectorMap& map = rig.maps[k];
      const double scale = rig.coverage_scale(i, static_cast<int>(k)) * map.pixel_solid_angle;
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        const int32_t index = map.pixels_by_patch[position];
        const double weight = scale * map.share[index];
        sum += weight * map.reflectance[index].cast<double>();
        weight_sum += weight;
      }
    }
    if (weight_sum > 0.0) means.row(i) = (sum / weight_sum).transpose();
  }
  return means;
}

bool SetBoundsFromProjectors(const Scene& scene, const PatchLevel& level, Eigen::MatrixX3d* lower,
                             Eigen::MatrixX3d* upper, const ProjectionRigOptions& options) {
  std::vector<Projector> projectors = ReadProjectors(scene);
  if (projectors.empty()) return false;
  const ProjectionRig rig = BuildProjectionRig(level, std::move(projectors), options);
  *lower = rig.lower;
  *upper = rig.upper;
  return true;
}

Eigen::MatrixX3d UnitLightExitance(const PatchLevel& level, const Projector& projector) {
  Projector unit = projector;
  unit.photometry.black = Vec3::Zero();
  unit.photometry.max = Vec3::Ones();
  ProjectionRigOptions options;
  options.lit_part = false;  // the patch's mean, as a camera sees it
  return BuildProjectionRig(level, {unit}, options).upper;
}

}  // namespace procam
