#include "apps/rig_stage.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <stdexcept>

#include "calibration/rig_directory.h"
#include "compensation/radiosity.h"
#include "base/io.h"
#include "geometry/ray_scene.h"
#include "projection/projection_rig.h"

namespace procam {

nlohmann::json RigDirectory::Describe() const {
  nlohmann::json names = nlohmann::json::array();
  for (const Projector& projector : projectors) names.push_back(projector.name);
  nlohmann::json description = {{"dir", dir.string()}, {"projectors", names}};
  description["reflectance"] = reflectance.rows() > 0;
  return description;
}

RigDirectory ReadRigDirectory(const std::filesystem::path& rig_dir) {
  const std::filesystem::path path = rig_dir / "rig.json";
  const std::string file = path.string();
  if (!std::filesystem::is_directory(rig_dir)) {
    throw IoError(rig_dir.string() + ": not a directory (--rig takes a rig directory)");
  }
  if (!std::filesystem::exists(path)) {
    throw IoError(file + ": file not found (the rig directory's rig.json, written by procam "
                         "calibrate)");
  }
  RigDirectory rig;
  rig.dir = rig_dir;
  rig.json = ReadRigJson(rig_dir);
  if (!rig.json.contains("projectors") || !rig.json["projectors"].is_array() ||
      rig.json["projectors"].empty()) {
    throw IoError(file + ": projectors: required key is missing (a non-empty array, run procam "
                         "calibrate projectors and calibrate photometric)");
  }
  // Photometry still in camera units cannot light a scene: say so before the parser's plainer
  // "max: required key is missing".
  const nlohmann::json& photometric = rig.json.value("photometric", nlohmann::json::object());
  const nlohmann::json& entries = rig.json["projectors"];
  for (size_t k = 0; k < entries.size(); ++k) {
    if (!entries[k].is_object() || !entries[k].contains("name") || !entries[k]["name"].is_string())
      continue;
    const std::string name = entries[k]["name"].get<std::string>();
    if (!photometric.is_object() || !photometric.contains(name)) continue;
    const nlohmann::json& info = photometric[name];
    if (info.is_object() && info.value("units", "") == "camera" && !entries[k].contains("max")) {
      throw IoError(file + ": projectors[" + std::to_string(k) + "].max: the photometry of '" +
                    name +
                    "' is in camera units (photometric." + name +
                    ".units); compensate needs scene units: run procam calibrate photometric "
                    "with --scene once the projector's geometry and the camera's registration "
                    "are in the rig");
    }
  }
  rig.projectors = ParseProjectors(entries.dump(), file, rig_dir);

  if (rig.json.contains("reflectance")) {
    const nlohmann::json& info = rig.json["reflectance"];
    if (!info.is_object() || !info.contains("file") || !info["file"].is_string()) {
      throw IoError(file + ": reflectance.file: required key is missing (a .npy file)");
    }
    if (!info.contains("target_patches") || !info["target_patches"].is_number_integer()) {
      throw IoError(file + ": reflectance.target_patches: required key is missing (an integer)");
    }
    const std::filesystem::path npy = rig_dir / info["file"].get<std::string>();
    if (!std::filesystem::exists(npy)) {
      throw IoError(file + ": reflectance.file: " + npy.string() + ": file not found");
    }
    const NpyArray array = ReadNpy(npy);
    if (array.shape.size() != 2 || array.shape[1] != 3 || array.shape[0] < 1) {
      throw IoError(npy.string() + ": expected shape (n,3)");
    }
    rig.reflectance.resize(array.shape[0], 3);
    for (int64_t i = 0; i < array.shape[0]; ++i) {
      for (int c = 0; c < 3; ++c) {
        const double value = array.values[3 * i + c];
        if (!(value >= 0.0 && value < 1.0)) {
          throw IoError(npy.string() + ": row " + std::to_string(i) +
                        ": reflectance must be in [0,1)");
        }
        rig.reflectance(i, c) = value;
      }
    }
    rig.reflectance_target_patches = info["target_patches"].get<int>();
  }
  return rig;
}

void ApplyRigReflectance(const RigDirectory& rig, PatchHierarchy* patches) {
  if (rig.reflectance.rows() == 0) return;
  const int n = patches->fine.size();
  if (rig.reflectance.rows() != n) {
    throw IoError((rig.dir / "rig.json").string() + ": reflectance: estimated for " +
                  std::to_string(rig.reflectance.rows()) + " patches (target " +
                  std::to_string(rig.reflectance_target_patches) + "), this run has " +
                  std::to_string(n) + ": give --patches " +
                  std::to_string(rig.reflectance_target_patches));
  }
  patches->fine.reflectance = rig.reflectance;
  const Eigen::VectorXd area = patches->fine.Areas();
  Eigen::MatrixX3d sum = Eigen::MatrixX3d::Zero(patches->coarse.size(), 3);
  Eigen::VectorXd coarse_area = Eigen::VectorXd::Zero(patches->coarse.size());
  for (int i = 0; i < n; ++i) {
    const int parent = patches->coarse_of_fine[i];
    sum.row(parent) += area[i] * rig.reflectance.row(i);
    coarse_area[parent] += area[i];
  }
  for (int j = 0; j < patches->coarse.size(); ++j) {
    if (coarse_area[j] > 0.0) patches->coarse.reflectance.row(j) = sum.row(j) / coarse_area[j];
  }
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
      for (int k = 0; k < rays.projectors; ++k) {
        const ProjectorGeometry& projector = projectors[k].geometry;
        Vec2 pixel;
        const double gain = projector.Gain(point, patch.normal, &pixel);
        if (gain <= 0.0 || !projector.InImage(pixel)) continue;
        if (surfaces.Occluded(point, projector.CentreInWorld(), ray_margin)) continue;
        // Pixel (c, r) covers [c − ½, c + ½] × [r − ½, r + ½] (projector.h).
        const int x = std::clamp(static_cast<int>(std::floor(pixel.x() + 0.5)), 0, projector.width() - 1);
        const int y = std::clamp(static_cast<int>(std::floor(pixel.y() + 0.5)), 0, projector.height() - 1);
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

UnitLightModel ModelUnitLight(const PatchLevel& level, const Eigen::MatrixXd& form_factors,
                              const Projector& projector) {
  Projector unit = projector;
  unit.photometry.black = Vec3::Zero();
  unit.photometry.max = Vec3::Ones();
  const ProjectionRig rig = BuildProjectionRig(level, {unit}, ProjectionRigOptions());
  const Eigen::MatrixX3d exitance = rig.upper;  // ρ ⊙ Ḡ
  UnitLightModel model;
  model.direct_irradiance = Eigen::MatrixX3d::Zero(level.size(), 3);
  for (int i = 0; i < level.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      if (level.reflectance(i, c) > 0.0)
        model.direct_irradiance(i, c) = exitance(i, c) / level.reflectance(i, c);
    }
  }
  const RadiositySystem system(form_factors, level.Areas(), level.reflectance);
  const Eigen::MatrixX3d radiosity = system.Solve(exitance);
  model.bounce_irradiance = form_factors * radiosity;
  return model;
}

cv::Mat PhotometricTransfer(const CameraPixelLighting& lighting, const PatchLevel& level,
                            const UnitLightModel& model, const Eigen::Vector3d& camera_scale) {
  cv::Mat transfer(lighting.height, lighting.width, CV_32FC3, cv::Scalar::all(0));
  for (int row = 0; row < lighting.height; ++row) {
    for (int col = 0; col < lighting.width; ++col) {
      const size_t index = static_cast<size_t>(row) * lighting.width + col;
      const int i = lighting.patch[index];
      if (i < 0) continue;
      cv::Vec3f& value = transfer.at<cv::Vec3f>(row, col);
      for (int c = 0; c < 3; ++c) {  // working R, G, B → camera B, G, R
        value[2 - c] = static_cast<float>(camera_scale[c] * level.reflectance(i, c) *
                                          (lighting.gain[index] + model.bounce_irradiance(i, c)));
      }
    }
  }
  return transfer;
}

ReflectanceEstimate EstimatePatchReflectance(const CameraPixelLighting& lighting,
                                             const PatchLevel& level,
                                             const Eigen::MatrixXd& form_factors,
                                             const UnitLightModel& model, const cv::Mat& difference,
                                             const cv::Mat& mask, const Eigen::Vector3d& output,
                                             const Eigen::Vector3d& camera_scale,
                                             int min_pixels) {
  const int n = level.size();
  CV_Assert(difference.type() == CV_32FC3 && difference.rows == lighting.height &&
            difference.cols == lighting.width);
  ReflectanceEstimate estimate;
  estimate.pixels.assign(n, 0);
  // Per patch: Σ measured exitance and Σ direct irradiance over its usable pixels.
  Eigen::MatrixX3d exitance_sum = Eigen::MatrixX3d::Zero(n, 3);
  Eigen::MatrixX3d direct_sum = Eigen::MatrixX3d::Zero(n, 3);
  for (int row = 0; row < lighting.height; ++row) {
    for (int col = 0; col < lighting.width; ++col) {
      const size_t index = static_cast<size_t>(row) * lighting.width + col;
      const int i = lighting.patch[index];
      if (i < 0 || (!mask.empty() && mask.at<uchar>(row, col) == 0)) continue;
      const cv::Vec3f& value = difference.at<cv::Vec3f>(row, col);
      ++estimate.pixels[i];
      for (int c = 0; c < 3; ++c) {
        exitance_sum(i, c) += value[2 - c] / camera_scale[c];
        direct_sum(i, c) += lighting.gain[index] * output[c];
      }
    }
  }
  std::vector<int> seen, unseen;
  for (int i = 0; i < n; ++i) (estimate.pixels[i] >= min_pixels ? seen : unseen).push_back(i);
  estimate.patches_seen = static_cast<int>(seen.size());

  // Radiosity B: measured where seen; elsewhere the model with the nominal reflectance, driven
  // by the measured B: (I − diag(ρ_U) F_UU) B_U = ρ_U ⊙ (Ḡ_U o + F_US B_S).
  Eigen::MatrixX3d radiosity = Eigen::MatrixX3d::Zero(n, 3);
  for (const int i : seen) {
    radiosity.row(i) = exitance_sum.row(i) / estimate.pixels[i];
  }
  if (!unseen.empty()) {
    const int u = static_cast<int>(unseen.size());
    Eigen::MatrixXd f_uu(u, u);
    for (int a = 0; a < u; ++a) {
      for (int b = 0; b < u; ++b) f_uu(a, b) = form_factors(unseen[a], unseen[b]);
    }
    for (int c = 0; c < 3; ++c) {
      Eigen::VectorXd rhs(u);
      Eigen::MatrixXd system = -f_uu;
      for (int a = 0; a < u; ++a) {
        const int i = unseen[a];
        const double rho = level.reflectance(i, c);
        double bounce = 0.0;
        for (const int j : seen) bounce += form_factors(i, j) * radiosity(j, c);
        rhs[a] = rho * (model.direct_irradiance(i, c) * output[c] + bounce);
        system.row(a) *= rho;
        system(a, a) += 1.0;
      }
      const Eigen::VectorXd b_unseen = system.partialPivLu().solve(rhs);
      for (int a = 0; a < u; ++a) radiosity(unseen[a], c) = b_unseen[a];
    }
  }
  const Eigen::MatrixX3d bounce = form_factors * radiosity;

  estimate.reflectance = level.reflectance;
  for (const int i : seen) {
    for (int c = 0; c < 3; ++c) {
      const double irradiance = direct_sum(i, c) + estimate.pixels[i] * bounce(i, c);
      if (irradiance > 0.0) {
        estimate.reflectance(i, c) = std::clamp(exitance_sum(i, c) / irradiance, 0.0, 0.99);
      }
    }
  }
  return estimate;
}

}  // namespace procam

namespace procam {

std::vector<Eigen::Vector3d> SeparateBlackLevels(const std::vector<cv::Mat>& transfers,
                                                 const cv::Mat& black_field, double camera_black) {
  const size_t count = transfers.size();
  if (count == 0) throw std::invalid_argument("SeparateBlackLevels: no projectors");
  if (black_field.type() != CV_32FC3)
    throw std::invalid_argument("SeparateBlackLevels: the black field must be CV_32FC3");
  for (const cv::Mat& transfer : transfers) {
    if (transfer.type() != CV_32FC3 || transfer.size() != black_field.size())
      throw std::invalid_argument("SeparateBlackLevels: transfers and black field differ in size");
  }
  std::vector<Eigen::Vector3d> black(count, Eigen::Vector3d::Zero());
  for (int c = 0; c < 3; ++c) {
    const int camera_channel = 2 - c;
    Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(count, count);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(count);
    Eigen::VectorXd t(count);
    for (int row = 0; row < black_field.rows; ++row) {
      for (int col = 0; col < black_field.cols; ++col) {
        bool lit = false;
        for (size_t j = 0; j < count; ++j) {
          t[j] = transfers[j].at<cv::Vec3f>(row, col)[camera_channel];
          lit = lit || t[j] > 0;
        }
        if (!lit) continue;
        normal += t * t.transpose();
        rhs += t * (black_field.at<cv::Vec3f>(row, col)[camera_channel] - camera_black);
      }
    }
    const Eigen::LDLT<Eigen::MatrixXd> solve(normal);
    if (solve.info() != Eigen::Success || !(solve.vectorD().minCoeff() > 1e-12 * normal.trace())) {
      throw std::invalid_argument(
          "SeparateBlackLevels: the projectors' light cannot be told apart in the black field");
    }
    const Eigen::VectorXd x = solve.solve(rhs);
    for (size_t j = 0; j < count; ++j) black[j][c] = x[j];
  }
  return black;
}

}  // namespace procam
