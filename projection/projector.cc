#include "projection/projector.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>

#include "base/camera_model.h"
#include "base/io.h"
#include "base/json_fields.h"


namespace procam {

namespace {

// Pixels per steradian from the projection Jacobian at a unit direction v: dq/dp has rows a, b
// with a·v = b·v = 0 (q is invariant to scaling p), so the Jacobian restricted to the tangent
// plane has determinant (a × b)·v.
double DensityFromJacobian(const ProjectionJacobian& dq_dp, const Vec3& v) {
  const Vec3 a = dq_dp.row(0).transpose(), b = dq_dp.row(1).transpose();
  return std::abs(a.cross(b).dot(v));
}

}  // namespace

ProjectorGeometry::ProjectorGeometry(const std::string& lens_model, std::vector<double> intrinsics,
                                     int width, int height,
                                     const Eigen::Isometry3d& proj_from_world)
    : lens_(lens_model, std::move(intrinsics)),
      width_(width),
      height_(height),
      proj_from_world_(proj_from_world) {
  if (width < 1 || height < 1 || width > 65536 || height > 65536) {
    throw std::invalid_argument("image size must be in [1, 65536], got " + std::to_string(width) +
                                "x" + std::to_string(height));
  }
  if (!proj_from_world.matrix().allFinite()) throw std::invalid_argument("pose must be finite");
  axis_density_ = PixelDensity(Vec3::UnitZ());
  if (!(axis_density_ > 0.0) || !std::isfinite(axis_density_)) {
    throw std::invalid_argument("the lens has no finite pixel density on its optical axis");
  }
}

ProjectorGeometry::ProjectorGeometry()
    : ProjectorGeometry("LENSMODEL_PINHOLE", {1.0, 1.0, 0.0, 0.0}, 1, 1,
                        Eigen::Isometry3d::Identity()) {}

ProjectorGeometry ProjectorGeometry::Pinhole(double fx, double fy, double cx, double cy, int width,
                                             int height, const Eigen::Isometry3d& proj_from_world) {
  return ProjectorGeometry("LENSMODEL_PINHOLE", {fx, fy, cx, cy}, width, height, proj_from_world);
}

bool ProjectorGeometry::ProjectFromProj(const Vec3& p_in_proj, Vec2* pixel, double* density) const {
  if (!(p_in_proj.z() > 0.0)) return false;
  const Vec3 v = p_in_proj.normalized();
  ProjectionJacobian dq_dp;
  *pixel = lens_.Project(v, density ? &dq_dp : nullptr);
  if (density) *density = DensityFromJacobian(dq_dp, v);
  return pixel->allFinite();
}

bool ProjectorGeometry::Project(const Vec3& p_in_world, Vec2* pixel, double* density) const {
  return ProjectFromProj(proj_from_world_ * p_in_world, pixel, density);
}

bool ProjectorGeometry::InImage(const Vec2& pixel) const {
  return pixel.x() >= -0.5 && pixel.x() < width_ - 0.5 && pixel.y() >= -0.5 &&
         pixel.y() < height_ - 0.5;
}

void ProjectorGeometry::Unproject(const Vec2* pixels, int count, Vec3* directions_in_proj) const {
  if (count <= 0) return;
  if (!lens_.Unproject(pixels, count, directions_in_proj)) {
    for (int k = 0; k < count; ++k) directions_in_proj[k] = Vec3::Constant(std::nan(""));
    return;
  }
  for (int k = 0; k < count; ++k) directions_in_proj[k].normalize();
}

Vec3 ProjectorGeometry::Unproject(const Vec2& pixel) const {
  Vec3 direction;
  Unproject(&pixel, 1, &direction);
  return direction;
}

double ProjectorGeometry::PixelDensity(const Vec3& direction_in_proj) const {
  const Vec3 v = direction_in_proj.normalized();
  ProjectionJacobian dq_dp;
  lens_.Project(v, &dq_dp);
  return DensityFromJacobian(dq_dp, v);
}

void ProjectorGeometry::UnprojectImage(std::vector<Vec3>* directions_in_proj,
                                       std::vector<double>* densities) const {
  // Grid nodes every kStep pixels plus the last row/column, unprojected exactly.
  constexpr int kStep = 16;
  std::vector<int> node_x, node_y;
  for (int x = 0; x < width_ - 1; x += kStep) node_x.push_back(x);
  node_x.push_back(width_ - 1);
  for (int y = 0; y < height_ - 1; y += kStep) node_y.push_back(y);
  node_y.push_back(height_ - 1);
  const int nx = static_cast<int>(node_x.size()), ny = static_cast<int>(node_y.size());
  std::vector<Vec2> node_pixels;
  node_pixels.reserve(nx * ny);
  for (const int y : node_y) {
    for (const int x : node_x) node_pixels.emplace_back(x, y);
  }
  std::vector<Vec3> node_directions(node_pixels.size());
  Unproject(node_pixels.data(), static_cast<int>(node_pixels.size()), node_directions.data());

  directions_in_proj->assign(static_cast<size_t>(width_) * height_, Vec3::Zero());
  densities->assign(static_cast<size_t>(width_) * height_, 0.0);
#pragma omp parallel for schedule(dynamic, 8)
  for (int y = 0; y < height_; ++y) {
    const int gy = std::min(y / kStep, ny - 2 < 0 ? 0 : ny - 2);
    const double fy = ny > 1 ? double(y - node_y[gy]) / (node_y[gy + 1] - node_y[gy]) : 0.0;
    for (int x = 0; x < width_; ++x) {
      const int gx = std::min(x / kStep, nx - 2 < 0 ? 0 : nx - 2);
      const double fx = nx > 1 ? double(x - node_x[gx]) / (node_x[gx + 1] - node_x[gx]) : 0.0;
      auto node = [&](int i, int j) -> const Vec3& {
        return node_directions[std::min(j, ny - 1) * nx + std::min(i, nx - 1)];
      };
      Vec3 v = ((1 - fx) * (1 - fy)) * node(gx, gy) + (fx * (1 - fy)) * node(gx + 1, gy) +
               ((1 - fx) * fy) * node(gx, gy + 1) + (fx * fy) * node(gx + 1, gy + 1);
      v.normalize();
      const Vec2 target(x, y);
      double density = std::nan("");
      for (int iteration = 0; iteration < 6 && v.allFinite(); ++iteration) {
        ProjectionJacobian dq_dp;
        const Vec2 q = lens_.Project(v, &dq_dp);
        density = DensityFromJacobian(dq_dp, v);
        const Vec2 error = q - target;
        if (error.norm() < 1e-9) break;
        // Newton step in the tangent plane of the unit sphere at v.
        const Vec3 t1 = v.unitOrthogonal(), t2 = v.cross(t1);
        const Vec3 a = dq_dp.row(0).transpose(), b = dq_dp.row(1).transpose();
        Eigen::Matrix2d jacobian;
        jacobian << a.dot(t1), a.dot(t2), b.dot(t1), b.dot(t2);
        const Vec2 step = jacobian.partialPivLu().solve(-error);
        v = (v + step.x() * t1 + step.y() * t2).normalized();
      }
      const size_t index = static_cast<size_t>(y) * width_ + x;
      (*directions_in_proj)[index] = v;
      (*densities)[index] = density;
    }
  }
}

double ProjectorGeometry::Gain(const Vec3& p_in_world, const Vec3& normal, Vec2* pixel) const {
  const Vec3 p_in_proj = proj_from_world_ * p_in_world;
  if (!(p_in_proj.z() > 0.0)) return 0.0;
  const double distance = p_in_proj.norm();
  const double cosine = normal.dot(CentreInWorld() - p_in_world) / distance;
  if (!(cosine > 0.0)) return 0.0;
  Vec2 q;
  double density = 0.0;
  if (!ProjectFromProj(p_in_proj, &q, &density)) return 0.0;
  if (pixel) *pixel = q;
  return density / axis_density_ * cosine / (distance * distance);
}

Eigen::Isometry3d ProjFromWorldLookingAt(const Vec3& centre, const Vec3& target, const Vec3& up) {
  const Vec3 forward = target - centre;
  if (!(forward.norm() > 0.0)) throw std::invalid_argument("look-at: centre and target coincide");
  const Vec3 z = forward.normalized();
  const Vec3 down = -up + up.dot(z) * z;  // −up without its component along the axis
  if (!(down.norm() > 1e-9 * up.norm()))
    throw std::invalid_argument("look-at: axis parallel to up");
  const Vec3 y = down.normalized();
  const Vec3 x = y.cross(z);
  Eigen::Isometry3d proj_from_world = Eigen::Isometry3d::Identity();
  proj_from_world.linear().row(0) = x.transpose();
  proj_from_world.linear().row(1) = y.transpose();
  proj_from_world.linear().row(2) = z.transpose();
  proj_from_world.translation() = -(proj_from_world.linear() * centre);
  return proj_from_world;
}

CameraModel ProjectorGeometry::Model() const {
  CameraModel model;
  model.lens_model = lens_model();
  model.intrinsics = intrinsics();
  model.width = width_;
  model.height = height_;
  model.cam_from_ref = proj_from_world_;
  return model;
}

ProjectorGeometry ProjectorGeometry::FromModel(const CameraModel& model) {
  return ProjectorGeometry(model.lens_model, model.intrinsics, model.width, model.height,
                           model.cam_from_ref);
}

std::string CameraModelText(const ProjectorGeometry& geometry) {
  return CameraModelText(geometry.Model(),
                         "procam projector model; extrinsics = mrcal rt_cam_ref with ref = world");
}

ProjectorGeometry ReadCameraModel(const std::filesystem::path& path) {
  const CameraModel model = ReadCameraModelFile(path);
  try {
    return ProjectorGeometry::FromModel(model);
  } catch (const std::invalid_argument& error) {
    throw IoError(path.string() + ": " + error.what());
  }
}

void WriteCameraModel(const std::filesystem::path& path, const ProjectorGeometry& geometry) {
  WriteCameraModelFile(path, geometry.Model(),
                   "procam projector model; extrinsics = mrcal rt_cam_ref with ref = world");
}

// ---------------------------------------------------------------------------------------------
// Photometry.

ResponseCurve ResponseCurve::Gamma(double gamma) {
  if (!(gamma > 0.0) || !std::isfinite(gamma)) {
    throw std::invalid_argument("gamma must be a positive number");
  }
  ResponseCurve curve;
  curve.gamma_ = gamma;
  return curve;
}

ResponseCurve ResponseCurve::Table(const std::vector<double>& light) {
  if (light.size() < 2) throw std::invalid_argument("a response table needs at least 2 values");
  for (size_t k = 0; k < light.size(); ++k) {
    if (!std::isfinite(light[k])) throw std::invalid_argument("response values must be finite");
    if (k > 0 && !(light[k] > light[k - 1])) {
      throw std::invalid_argument("response values must increase strictly (index " +
                                  std::to_string(k) + ")");
    }
  }
  ResponseCurve curve;
  curve.table_.resize(light.size());
  const double range = light.back() - light.front();
  for (size_t k = 0; k < light.size(); ++k) curve.table_[k] = (light[k] - light.front()) / range;
  curve.table_.front() = 0.0;
  curve.table_.back() = 1.0;
  return curve;
}

double ResponseCurve::Light(double drive) const {
  drive = std::clamp(drive, 0.0, 1.0);
  if (table_.empty()) return std::pow(drive, gamma_);
  const double position = drive * (table_.size() - 1);
  const size_t k = std::min(static_cast<size_t>(position), table_.size() - 2);
  const double f = position - k;
  return (1 - f) * table_[k] + f * table_[k + 1];
}

double ResponseCurve::Drive(double light) const {
  light = std::clamp(light, 0.0, 1.0);
  if (table_.empty()) return std::pow(light, 1.0 / gamma_);
  const auto upper = std::upper_bound(table_.begin(), table_.end(), light);
  if (upper == table_.end()) return 1.0;
  const size_t k = static_cast<size_t>(upper - table_.begin()) - 1;
  const double f = (light - table_[k]) / (table_[k + 1] - table_[k]);
  return (k + f) / (table_.size() - 1);
}

std::string ProjectorPhotometry::Validate() const {
  for (int c = 0; c < 3; ++c) {
    if (!(black[c] >= 0.0) || !std::isfinite(black[c])) return "black: each value must be >= 0";
    if (!(max[c] > black[c]) || !std::isfinite(max[c]))
      return "max: each value must be greater than black";
  }
  if (!mixing.allFinite() || mixing.minCoeff() < 0.0)
    return "mixing: entries must be finite and >= 0";
  for (int r = 0; r < 3; ++r) {
    if (std::abs(mixing.row(r).sum() - 1.0) > 1e-6) {
      return "mixing: row " + std::to_string(r) + " must sum to 1 (it sums to " +
             fmt::format("{:.17g}", mixing.row(r).sum()) + ")";
    }
  }
  // Rows of non-negative entries summing to 1 have norms in [1/√3, 1], so |det| is a fair
  // measure of how close to singular the matrix is.
  if (std::abs(mixing.determinant()) < 1e-6) return "mixing: matrix is singular (or nearly)";
  if (bits != 8 && bits != 10) return "bits: must be 8 or 10";
  return "";
}

Vec3 ProjectorPhotometry::Output(const Vec3& drive) const {
  const Vec3 light(response[0].Light(drive[0]), response[1].Light(drive[1]),
                   response[2].Light(drive[2]));
  return black + (max - black).asDiagonal() * (mixing * light);
}

Vec3 ProjectorPhotometry::DriveFor(const Vec3& output, bool* clipped) const {
  const Vec3 relative = (output - black).cwiseQuotient(max - black);
  const Vec3 light = mixing.inverse() * relative;
  const Vec3 inside = light.cwiseMax(0.0).cwiseMin(1.0);
  if (clipped) *clipped = (inside - light).cwiseAbs().maxCoeff() > 1e-12;
  return Vec3(response[0].Drive(inside[0]), response[1].Drive(inside[1]),
              response[2].Drive(inside[2]));
}

// ---------------------------------------------------------------------------------------------
// The scene's "projectors" array.

namespace {

using nlohmann::json;

using Fields = JsonFields;

bool UsableAsFileName(const std::string& name) {
  if (name.empty() || name == "." || name == ".." || name == "result") return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

Projector ParseProjector(const json& object, const std::string& file, const std::string& prefix,
                         const std::filesystem::path& base, int index) {
  const Fields fields(object, file, prefix);
  fields.RejectUnknown({"name", "model", "black", "max", "gamma", "lut", "mixing", "bits"});
  Projector projector;
  projector.name = "projector" + std::to_string(index);
  if (fields.Has("name")) {
    if (!fields.At("name").is_string()) throw fields.Error("name", "must be a string");
    projector.name = fields.At("name").get<std::string>();
    if (!UsableAsFileName(projector.name)) {
      throw fields.Error(
          "name",
          "must be letters, digits, '_', '-' or '.' (it names the image file), not 'result'");
    }
  }
  if (!fields.At("model").is_string())
    throw fields.Error("model", "must be a path to an mrcal .cameramodel");
  projector.model_path = base / fields.At("model").get<std::string>();
  try {
    projector.geometry = ReadCameraModel(projector.model_path);
  } catch (const IoError& error) {
    throw fields.Error("model", error.what());
  }
  ProjectorPhotometry& photometry = projector.photometry;
  if (fields.Has("black")) photometry.black = fields.NumberOrRgb("black");
  photometry.max = fields.NumberOrRgb("max");
  for (int c = 0; c < 3; ++c) {
    if (!(photometry.black[c] >= 0.0)) throw fields.Error("black", "each value must be >= 0");
    if (!(photometry.max[c] > photometry.black[c]))
      throw fields.Error("max", "each value must be greater than black");
  }
  if (fields.Has("gamma") && fields.Has("lut"))
    throw fields.Error("lut", "give either 'gamma' or 'lut', not both");
  try {
    if (fields.Has("gamma")) {
      const Vec3 gamma = fields.NumberOrRgb("gamma");
      for (int c = 0; c < 3; ++c) {
        if (!(gamma[c] > 0.0 && gamma[c] <= 10.0))
          throw fields.Error("gamma", "each value must be in (0, 10]");
        photometry.response[c] = ResponseCurve::Gamma(gamma[c]);
      }
    } else if (fields.Has("lut")) {
      const json& lut = fields.At("lut");
      if (!lut.is_array() || lut.empty())
        throw fields.Error("lut", "must be an array of numbers or 3 arrays");
      if (lut[0].is_array()) {
        if (lut.size() != 3)
          throw fields.Error("lut", "per-channel tables must be exactly 3 arrays");
        for (int c = 0; c < 3; ++c) {
          const std::string key = "lut[" + std::to_string(c) + "]";
          photometry.response[c] = ResponseCurve::Table(fields.Numbers(key, lut[c]));
        }
      } else {
        const ResponseCurve curve = ResponseCurve::Table(fields.Numbers("lut", lut));
        photometry.response = {curve, curve, curve};
      }
    }
  } catch (const std::invalid_argument& error) {
    throw fields.Error("lut", error.what());
  }
  if (fields.Has("mixing")) {
    const json& mixing = fields.At("mixing");
    if (!mixing.is_array() || mixing.size() != 3)
      throw fields.Error("mixing", "must be a 3x3 array (3 rows)");
    for (int r = 0; r < 3; ++r) {
      const std::vector<double> row = fields.Numbers("mixing", mixing[r]);
      if (row.size() != 3)
        throw fields.Error("mixing", "row " + std::to_string(r) + " must have 3 numbers");
      for (int c = 0; c < 3; ++c) photometry.mixing(r, c) = row[c];
    }
  }
  if (fields.Has("bits")) {
    const json& bits = fields.At("bits");
    if (!bits.is_number_integer() || (bits.get<int>() != 8 && bits.get<int>() != 10)) {
      throw fields.Error("bits", "must be 8 or 10");
    }
    photometry.bits = bits.get<int>();
  }
  const std::string why = photometry.Validate();
  if (!why.empty()) {
    const std::string key = why.substr(0, why.find(':'));
    throw fields.Error(key, why.substr(why.find(':') + 2));
  }
  return projector;
}

}  // namespace

std::vector<Projector> ParseProjectors(const std::string& projectors_json,
                                       const std::string& scene_file,
                                       const std::filesystem::path& base) {
  std::vector<Projector> projectors;
  if (projectors_json.empty()) return projectors;
  json array;
  try {
    array = json::parse(projectors_json);
  } catch (const json::exception& error) {
    throw IoError(scene_file + ": projectors: invalid JSON");
  }
  if (!array.is_array()) throw IoError(scene_file + ": projectors: must be an array");
  std::set<std::string> names;
  for (size_t k = 0; k < array.size(); ++k) {
    const std::string prefix = "projectors[" + std::to_string(k) + "]";
    projectors.push_back(ParseProjector(array[k], scene_file, prefix, base, static_cast<int>(k)));
    if (!names.insert(projectors.back().name).second) {
      throw IoError(scene_file + ": " + prefix + ".name: '" + projectors.back().name +
                    "' is already the name of another projector");
    }
  }
  return projectors;
}

std::vector<Projector> ReadProjectors(const Scene& scene) {
  return ParseProjectors(scene.projectors_json, scene.path.string(), scene.path.parent_path());
}

}  // namespace procam
