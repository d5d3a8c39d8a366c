#include "apps/verification.h"

#include "apps/command_line.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "apps/compensation_stage.h"
#include "apps/evaluation.h"
#include "apps/geometry_stage.h"
#include "apps/rig_stage.h"
#include "calibration/camera_response.h"
#include "capture/camera.h"
#include "capture/patterns.h"
#include "capture/pixel_format.h"
#include "capture/session.h"
#include "capture/test_camera.h"
#include "compensation/colour.h"
#include "compensation/problem.h"
#include "compensation/radiosity.h"
#include "compensation/solver.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "base/io.h"
#include "geometry/ray_scene.h"
#include "projection/projection_rig.h"
#include "projection/projector_images.h"

namespace procam {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

nlohmann::json Json3(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

void CreateDirectories(const std::filesystem::path& dir) {
  std::error_code error;
  std::filesystem::create_directories(dir, error);
  if (error) throw IoError(dir.string() + ": cannot create directory: " + error.message());
}

void WritePicture(const std::filesystem::path& path, const cv::Mat& image) {
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", image, bytes)) throw IoError(path.string() + ": cannot encode PNG");
  WriteFileAtomically(path, std::string(bytes.begin(), bytes.end()));
}

// ---------------------------------------------------------------------------------------------
// Inputs

struct LoadedSolution {
  nlohmann::json result;
  std::filesystem::path scene_path;
  int patches = 0, target_patches = 0;
  Eigen::MatrixX3d emittance, radiosity;
  SolverOptions solver;
  double alpha = 0.5;
};

Eigen::MatrixX3d ReadPatchMatrix(const std::filesystem::path& path, int n) {
  if (!std::filesystem::exists(path)) throw IoError(path.string() + ": file not found");
  const NpyArray array = ReadNpy(path);
  if (array.shape.size() != 2 || array.shape[0] != n || array.shape[1] != 3) {
    throw IoError(path.string() + ": expected shape (" + std::to_string(n) +
                  ",3), as result.json's patches says");
  }
  Eigen::MatrixX3d matrix(n, 3);
  for (int i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) matrix(i, c) = array.values[3 * i + c];
  }
  if (!matrix.allFinite()) throw IoError(path.string() + ": non-finite values");
  return matrix;
}

LoadedSolution ReadSolution(const std::filesystem::path& dir, bool scene_given) {
  const std::filesystem::path path = dir / "result.json";
  const std::string file = path.string();
  if (!std::filesystem::exists(path)) {
    throw IoError(file + ": file not found (SOLUTION_DIR must be what `procam compensate SCENE "
                         "--rig RIG_DIR --out DIR` wrote)");
  }
  LoadedSolution s;
  try {
    s.result = nlohmann::json::parse(ReadFile(path));
  } catch (const nlohmann::json::exception&) {
    throw IoError(file + ": invalid JSON");
  }
  const nlohmann::json& r = s.result;
  if (!r.is_object()) throw IoError(file + ": expected a JSON object");
  if (!r.contains("patches") || !r["patches"].is_number_integer() || r["patches"].get<int>() < 1) {
    throw IoError(file + ": patches: required key is missing (a positive integer)");
  }
  s.patches = r["patches"].get<int>();
  s.target_patches = r.value("target_patches", s.patches);
  if (!scene_given) {
    if (!r.contains("scene") || !r["scene"].is_string() || r["scene"].get<std::string>().empty()) {
      throw IoError(file + ": scene: required key is missing (a string: the scene file)");
    }
    std::filesystem::path scene = r["scene"].get<std::string>();
    if (!scene.is_absolute() && !std::filesystem::exists(scene) &&
        std::filesystem::exists(dir / scene)) {
      scene = dir / scene;
    }
    s.scene_path = scene;
  }
  const std::string method = r.value("method", std::string("perceptual"));
  if (!ParseMethod(method, &s.solver.method)) {
    throw IoError(file + ": method: unknown method '" + method + "'");
  }
  s.solver.multires = r.value("coarse_iterations", 0) > 0;
  s.alpha = r.value("alpha", 0.5);
  if (!(s.alpha > 0.0 && s.alpha <= 1.0)) throw IoError(file + ": alpha: must be in (0,1]");
  s.emittance = ReadPatchMatrix(dir / "E.npy", s.patches);
  s.radiosity = ReadPatchMatrix(dir / "B.npy", s.patches);
  return s;
}

// Camera colour calibration: exitance (working RGB, scene units) = to_exitance · (camera RGB −
// black) for single exposures; HDR merges have black removed already.
struct CameraColour {
  Eigen::Matrix3d to_exitance = Eigen::Matrix3d::Identity();
  double black = 0.0;
  std::string source;
  nlohmann::json Json() const {
    nlohmann::json m = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) m.push_back(Json3(to_exitance.row(r).transpose()));
    return {{"to_exitance", m}, {"black", black}, {"source", source}};
  }
};

// What the rig or the options say (the synthetic camera's is derived per photo).
struct ColourSource {
  bool synthetic = false;
  Eigen::Matrix3d matrix = Eigen::Matrix3d::Identity();  // per unit camera value
  double black = 0.0;
  std::string source;
};

ColourSource ResolveColourSource(const VerificationOptions& options, const nlohmann::json& rig_json,
                                 const std::string& rig_file, bool synthetic) {
  ColourSource c;
  c.black = std::max(0.0, options.camera_black);
  if (!options.camera_scale.empty()) {
    const Eigen::Vector3d k = ParsePositiveRgb("--camera-scale", options.camera_scale);
    c.matrix = k.cwiseInverse().asDiagonal();
    c.source = "--camera-scale";
    return c;
  }
  const nlohmann::json camera = rig_json.value("camera", nlohmann::json::object());
  if (camera.is_object() && camera.contains("colour")) {
    const nlohmann::json& colour = camera["colour"];
    const std::string key = rig_file + ": camera.colour";
    if (colour.is_object() && colour.contains("scale") && colour["scale"].is_array() &&
        colour["scale"].size() == 3) {
      Eigen::Vector3d k;
      for (int i = 0; i < 3; ++i) {
        if (!colour["scale"][i].is_number() || !(colour["scale"][i].get<double>() > 0))
          throw IoError(key + ".scale: three positive numbers (camera value per unit exitance)");
        k[i] = colour["scale"][i].get<double>();
      }
      c.matrix = k.cwiseInverse().asDiagonal();
    } else if (colour.is_object() && colour.contains("matrix") && colour["matrix"].is_array() &&
               colour["matrix"].size() == 3) {
      for (int r = 0; r < 3; ++r) {
        const nlohmann::json& row = colour["matrix"][r];
        if (!row.is_array() || row.size() != 3)
          throw IoError(key + ".matrix: 3 rows of 3 numbers (camera RGB → exitance)");
        for (int j = 0; j < 3; ++j) {
          if (!row[j].is_number()) throw IoError(key + ".matrix: numbers only");
          c.matrix(r, j) = row[j].get<double>();
        }
      }
      if (std::abs(c.matrix.determinant()) < 1e-300) throw IoError(key + ".matrix: singular");
    } else {
      throw IoError(key + ": expected {\"scale\": [R,G,B]} or {\"matrix\": [[..],[..],[..]]}");
    }
    if (options.camera_black < 0) c.black = colour.value("black", 0.0);
    c.source = "rig.json camera.colour";
    return c;
  }
  if (synthetic) {
    c.synthetic = true;
    c.source = "synthetic camera URI";
    return c;
  }
  throw IoError(rig_file +
                ": camera.colour: required key is missing for camera '" + options.camera +
                "' (the camera's value per unit exitance: {\"scale\": [R,G,B]} or {\"matrix\": "
                "3x3}), or give --camera-scale");
}

// The synthetic camera's k: radiance_scale × full scale × exposure / reference × gain, per DN
// (one exposure) or per full scale per second (HDR), as apps/photometric_rig.cc derives it.
CameraColour SyntheticColour(const CameraUri& uri, const SyntheticWorld& world,
                             const nlohmann::json& manifest, bool hdr, double full_scale,
                             double black_override) {
  const TestCameraOptions camera = TestCameraOptionsFromUri(uri);
  const nlohmann::json settings = manifest.value("camera", nlohmann::json::object())
                                      .value("settings", nlohmann::json::object());
  const double gain = std::pow(10.0, settings.value("gain", 0.0) / 20.0);
  const double full = full_scale > 0.0 ? full_scale : 255.0;
  const double black = black_override >= 0 ? black_override : camera.black_level;
  double k = 0.0;
  CameraColour colour;
  if (hdr) {
    k = world.radiance_scale * full / (full - black) * gain /
        (camera.reference_exposure_us * 1e-6);
    colour.black = 0.0;
  } else {
    const double exposure = settings.value("exposure_us", camera.exposure_us);
    k = world.radiance_scale * full * exposure / camera.reference_exposure_us * gain;
    colour.black = black;
  }
  colour.to_exitance = Eigen::Matrix3d::Identity() / k;
  colour.source = "synthetic camera URI";
  return colour;
}

// ---------------------------------------------------------------------------------------------
// Model

// Replaces the fine reflectance and keeps the coarse level the area-weighted mean of its
// children (as ApplyRigReflectance does).
void SetReflectance(const Eigen::MatrixX3d& reflectance, PatchHierarchy* patches) {
  patches->fine.reflectance = reflectance;
  const Eigen::VectorXd area = patches->fine.Areas();
  Eigen::MatrixX3d sum = Eigen::MatrixX3d::Zero(patches->coarse.size(), 3);
  Eigen::VectorXd coarse_area = Eigen::VectorXd::Zero(patches->coarse.size());
  for (int i = 0; i < patches->fine.size(); ++i) {
    sum.row(patches->coarse_of_fine[i]) += area[i] * reflectance.row(i);
    coarse_area[patches->coarse_of_fine[i]] += area[i];
  }
  for (int j = 0; j < patches->coarse.size(); ++j) {
    if (coarse_area[j] > 0.0) patches->coarse.reflectance.row(j) = sum.row(j) / coarse_area[j];
  }
}

// The direct irradiance the shown codes deliver to each patch (the renderer's flux
// bookkeeping), as a function of a response exponent per projector and primary.
class DirectLightModel {
 public:
  DirectLightModel(const ProjectionRig& rig, const std::vector<ProjectorImage>& images)
      : rig_(rig) {
    const int n = rig.size();
    const int projectors = static_cast<int>(rig.projectors.size());
    counts_.resize(projectors);
    light_.resize(projectors);
    lit_.assign(projectors, Eigen::VectorXd::Zero(n));
    sums_.resize(projectors);
    exponent_.assign(projectors, Eigen::Vector3d::Ones());
    for (int k = 0; k < projectors; ++k) {
      const ProjectorMap& map = rig.maps[k];
      const ProjectorPhotometry& photometry = rig.projectors[k].photometry;
      const int levels = photometry.MaxCode() + 1;
      const auto* codes = reinterpret_cast<const cv::Vec3w*>(images[k].codes.data);
      for (int j = 0; j < 3; ++j) {
        counts_[k][j] = Eigen::MatrixXf::Zero(n, levels);
        light_[k][j].resize(levels);
        for (int code = 0; code < levels; ++code)
          light_[k][j][code] = photometry.response[j].Light(double(code) / (levels - 1));
      }
      for (int i = 0; i < n; ++i) {
        for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
          const cv::Vec3w& code = codes[map.pixels_by_patch[position]];
          for (int j = 0; j < 3; ++j) counts_[k][j](i, std::min<int>(code[j], levels - 1)) += 1.0f;
          lit_[k][i] += 1.0;
        }
      }
      for (int j = 0; j < 3; ++j) sums_[k][j] = Sum(k, j, 1.0);
    }
  }

  int projectors() const { return static_cast<int>(counts_.size()); }
  const Eigen::Vector3d& exponent(int k) const { return exponent_[k]; }
  void SetExponent(int k, int j, double p) {
    exponent_[k][j] = p;
    sums_[k][j] = Sum(k, j, p);
  }

  // (n,3) direct irradiance (scene units) with the current exponents; `of_projector` ≥ 0 keeps
  // only that projector's light.
  Eigen::MatrixX3d Irradiance(int of_projector = -1) const {
    const int n = rig_.size();
    Eigen::MatrixX3d irradiance = Eigen::MatrixX3d::Zero(n, 3);
    for (int k = 0; k < projectors(); ++k) {
      if (of_projector >= 0 && k != of_projector) continue;
      const ProjectorPhotometry& p = rig_.projectors[k].photometry;
      const double omega = rig_.maps[k].pixel_solid_angle;
      for (int i = 0; i < n; ++i) {
        if (lit_[k][i] == 0.0) continue;
        const double scale = rig_.coverage_scale(i, k) * omega / rig_.area[i];
        const Eigen::Vector3d relative(sums_[k][0][i], sums_[k][1][i], sums_[k][2][i]);
        const Eigen::Vector3d mixed = p.mixing * relative;
        for (int c = 0; c < 3; ++c) {
          irradiance(i, c) += scale * (lit_[k][i] * p.black[c] + (p.max[c] - p.black[c]) * mixed[c]);
        }
      }
    }
    return irradiance;
  }

 private:
  Eigen::VectorXd Sum(int k, int j, double p) const {
    Eigen::VectorXf powered(light_[k][j].size());
    for (size_t code = 0; code < light_[k][j].size(); ++code)
      powered[code] = static_cast<float>(std::pow(light_[k][j][code], p));
    return (counts_[k][j] * powered).cast<double>();
  }

  const ProjectionRig& rig_;
  std::vector<std::array<Eigen::MatrixXf, 3>> counts_;  // per patch, pixels per code
  std::vector<std::array<std::vector<double>, 3>> light_;  // response per code
  std::vector<Eigen::VectorXd> lit_;                        // lit pixels per patch
  std::vector<std::array<Eigen::VectorXd, 3>> sums_;        // Σ light^p per patch
  std::vector<Eigen::Vector3d> exponent_;
};

struct ModelUpdate {
  std::vector<Eigen::Vector3d> exponent;
  Eigen::Vector3d scale = Eigen::Vector3d::Ones();
  Eigen::MatrixX3d reflectance;
  int fit_patches = 0;
  double rms_before = 0, rms_after = 0;  // log residual of the fit
};

// Header comment, steps 1 and 2.
ModelUpdate FitModel(const VerificationOptions& options, const ProjectionRig& rig,
                     const std::vector<ProjectorImage>& images, const Eigen::MatrixXd& form_factors,
                     const Eigen::MatrixX3d& measured, const std::vector<bool>& seen,
                     const Eigen::MatrixX3d& predicted) {
  const int n = rig.size();
  DirectLightModel direct(rig, images);
  Eigen::MatrixX3d radiosity = predicted;  // measured where seen, the model's elsewhere
  for (int i = 0; i < n; ++i) {
    if (seen[i]) radiosity.row(i) = measured.row(i);
  }
  const Eigen::MatrixX3d bounce = form_factors * radiosity;
  // Patches and channels bright enough to fit on.
  std::array<std::vector<int>, 3> fit;
  Eigen::MatrixX3d target = Eigen::MatrixX3d::Zero(n, 3);  // log(B / ρ)
  const Eigen::MatrixX3d irradiance0 = direct.Irradiance();
  for (int c = 0; c < 3; ++c) {
    double brightest = 0.0;
    for (int i = 0; i < n; ++i) {
      if (seen[i]) brightest = std::max(brightest, measured(i, c));
    }
    for (int i = 0; i < n; ++i) {
      if (!seen[i] || !(measured(i, c) > 0.02 * brightest) || !(irradiance0(i, c) > 0.0) ||
          !(rig.reflectance(i, c) > 0.0))
        continue;
      fit[c].push_back(i);
      target(i, c) = std::log(measured(i, c) / rig.reflectance(i, c));
    }
  }
  auto objective = [&](Eigen::Vector3d* log_scale) {
    const Eigen::MatrixX3d irradiance = direct.Irradiance();
    double sum = 0.0;
    for (int c = 0; c < 3; ++c) {
      if (fit[c].empty()) continue;
      double mean = 0.0;
      std::vector<double> residual;
      residual.reserve(fit[c].size());
      for (const int i : fit[c]) {
        residual.push_back(target(i, c) - std::log(irradiance(i, c) + bounce(i, c)));
        mean += residual.back();
      }
      mean /= residual.size();
      if (log_scale) (*log_scale)[c] = mean;
      for (const double r : residual) sum += (r - mean) * (r - mean);
    }
    return sum;
  };

  ModelUpdate update;
  update.fit_patches = static_cast<int>(fit[0].size() + fit[1].size() + fit[2].size());
  const double count = std::max(1, update.fit_patches);
  update.rms_before = std::sqrt(objective(nullptr) / count);
  if (options.fit_response) {
    // Fit only the primaries of projectors that are the main light on enough patches.
    std::vector<bool> fittable(direct.projectors(), false);
    for (int k = 0; k < direct.projectors(); ++k) {
      const Eigen::MatrixX3d own = direct.Irradiance(k);
      int main = 0;
      for (const int i : fit[1]) main += own(i, 1) > 0.5 * irradiance0(i, 1);
      fittable[k] = main >= 3;
    }
    constexpr double kLow = -0.5, kHigh = 0.5;  // log p: p in [0.61, 1.65] per iteration
    const double golden = (std::sqrt(5.0) - 1.0) / 2.0;
    for (int sweep = 0; sweep < 3; ++sweep) {
      for (int k = 0; k < direct.projectors(); ++k) {
        if (!fittable[k]) continue;
        for (int j = 0; j < 3; ++j) {
          if (fit[j].empty()) continue;
          auto at = [&](double log_p) {
            direct.SetExponent(k, j, std::exp(log_p));
            return objective(nullptr);
          };
          double a = kLow, b = kHigh;
          double x1 = b - golden * (b - a), x2 = a + golden * (b - a);
          double f1 = at(x1), f2 = at(x2);
          for (int step = 0; step < 30; ++step) {
            if (f1 < f2) {
              b = x2, x2 = x1, f2 = f1;
              x1 = b - golden * (b - a);
              f1 = at(x1);
            } else {
              a = x1, x1 = x2, f1 = f2;
              x2 = a + golden * (b - a);
              f2 = at(x2);
            }
          }
          const double best = 0.5 * (a + b);
          // Keep the current exponent unless the fit really prefers another.
          const double current = std::log(direct.exponent(k)[j]);
          const double f_current = at(current);
          const double f_best = at(best);
          direct.SetExponent(k, j, std::exp(f_best < f_current ? best : current));
        }
      }
    }
  }
  Eigen::Vector3d log_scale = Eigen::Vector3d::Zero();
  update.rms_after = std::sqrt(objective(&log_scale) / count);
  for (int c = 0; c < 3; ++c) {
    if (!fit[c].empty()) update.scale[c] = std::clamp(std::exp(log_scale[c]), 0.5, 2.0);
  }
  for (int k = 0; k < direct.projectors(); ++k) update.exponent.push_back(direct.exponent(k));

  // Reflectance: ρ = B / (D + F B) where measured, else the common scale.
  update.reflectance = rig.reflectance;
  if (options.fit_reflectance) {
    const Eigen::MatrixX3d irradiance = direct.Irradiance();
    std::array<std::vector<bool>, 3> fitted;
    for (int c = 0; c < 3; ++c) {
      fitted[c].assign(n, false);
      for (const int i : fit[c]) fitted[c][i] = true;
    }
    for (int i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        const double old = rig.reflectance(i, c);
        if (!(old > 0.0)) continue;
        double estimate = old * update.scale[c];
        const double total = irradiance(i, c) + bounce(i, c);
        if (fitted[c][i] && total > 0.0) estimate = measured(i, c) / total;
        const double ratio = std::clamp(estimate / old, 0.5, 2.0);
        update.reflectance(i, c) =
            std::clamp(old * std::pow(ratio, options.reflectance_step), 0.01, 0.99);
      }
    }
  }
  return update;
}

// Applies the update to the rig (responses, reflectance and the bounds, which are linear in ρ)
// and the geometry (reflectance, both levels).
void ApplyUpdate(const ModelUpdate& update, ProjectionRig* rig, GeometryStage* geometry) {
  for (size_t k = 0; k < rig->projectors.size(); ++k) {
    ProjectorPhotometry& photometry = rig->projectors[k].photometry;
    for (int j = 0; j < 3; ++j) {
      const double p = update.exponent[k][j];
      if (p == 1.0) continue;
      const ResponseCurve& curve = photometry.response[j];
      if (curve.is_table()) {
        std::vector<double> table = curve.table();
        for (double& value : table) value = std::pow(value, p);
        photometry.response[j] = ResponseCurve::Table(table);
      } else {
        photometry.response[j] = ResponseCurve::Gamma(curve.gamma() * p);
      }
    }
  }
  for (int i = 0; i < rig->size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      const double old = rig->reflectance(i, c);
      if (!(old > 0.0)) continue;
      const double ratio = update.reflectance(i, c) / old;
      rig->lower(i, c) *= ratio;
      rig->upper(i, c) *= ratio;
    }
  }
  rig->reflectance = update.reflectance;
  SetReflectance(update.reflectance, &geometry->patches);
}

// ---------------------------------------------------------------------------------------------
// Per-pixel prediction


// The predicted exitance of every camera pixel (CV_32FC3, working R, G, B, scene units; 0 where
// the pixel sees nothing) for the images shown, by the model's split of the light at the point
// x of patch i the pixel sees (rig_stage.h's transfer):
//     x_p = ρ_i ⊙ (Σ_k G_k(x) · output_k(code_k) + (F B)_i),
// code_k the code of the projector pixel that lights x, output_k the projector's photometry as
// the model knows it, and B = K⁻¹(ρ ⊙ D) the radiosity of the direct irradiance D the shown
// images deliver to each patch (the renderer's flux bookkeeping), so the bounce term is the one
// of the light actually shown. `shown_radiosity` (optional) receives that B.
cv::Mat PredictPixels(const CameraPixelRays& rays, const ProjectionRig& rig,
                      const std::vector<ProjectorImage>& images,
                      const Eigen::MatrixXd& form_factors,
                      Eigen::MatrixX3d* shown_radiosity = nullptr) {
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
      light[k][code] = Eigen::Vector3d(photometry.response[0].Light(drive),
                                       photometry.response[1].Light(drive),
                                       photometry.response[2].Light(drive));
    }
  }
  cv::Mat predicted(rays.height, rays.width, CV_32FC3, cv::Scalar::all(0));
  for (int row = 0; row < rays.height; ++row) {
    for (int col = 0; col < rays.width; ++col) {
      const size_t index = static_cast<size_t>(row) * rays.width + col;
      const int i = rays.patch[index];
      if (i < 0) continue;
      Eigen::Vector3d irradiance = bounce.row(i).transpose();
      for (int k = 0; k < rays.projectors; ++k) {
        const int32_t pixel = rays.projector_pixel[index * rays.projectors + k];
        if (pixel < 0) continue;
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
      const Eigen::Vector3d exitance = rig.reflectance.row(i).transpose().cwiseProduct(irradiance);
      predicted.at<cv::Vec3f>(row, col) =
          cv::Vec3f(float(exitance[0]), float(exitance[1]), float(exitance[2]));
    }
  }
  return predicted;
}

// ---------------------------------------------------------------------------------------------
// Photos

cv::Mat PatternFromImage(const ProjectorImage& image) {
  cv::Mat codes = image.codes;
  if (image.bits != 8) codes.convertTo(codes, CV_16UC3, 255.0 / ((1 << image.bits) - 1));
  cv::Mat rgb8, bgr8;
  codes.convertTo(rgb8, CV_8UC3);
  cv::cvtColor(rgb8, bgr8, cv::COLOR_RGB2BGR);
  return bgr8;
}

// Linear working RGB (CV_32FC3, R, G, B) in scene units from the camera's linear photo (B, G, R).
cv::Mat PhotoToExitance(const cv::Mat& photo, const CameraColour& colour) {
  cv::Mat exitance(photo.rows, photo.cols, CV_32FC3);
  for (int row = 0; row < photo.rows; ++row) {
    for (int col = 0; col < photo.cols; ++col) {
      const cv::Vec3f& v = photo.at<cv::Vec3f>(row, col);
      const Eigen::Vector3d camera(v[2] - colour.black, v[1] - colour.black, v[0] - colour.black);
      const Eigen::Vector3d x = colour.to_exitance * camera;
      exitance.at<cv::Vec3f>(row, col) = cv::Vec3f(float(x[0]), float(x[1]), float(x[2]));
    }
  }
  return exitance;
}

struct Comparison {
  PhotoDeltaE measured, model;
  double predicted_mean76 = 0, predicted_mean2000 = 0;
  double model_constant_mean76 = 0;  // per pixel, photo vs its patch's B (constant per patch)
  Eigen::MatrixX3d patch_exitance;  // mean measured exitance per patch (NaN where unseen)
  std::vector<bool> seen;
  std::vector<int> pixels;
  int seen_pixels = 0, seen_patches = 0;
  cv::Mat delta_e76, delta_e2000, model_delta_e76, model_delta_e2000, predicted;  // per pixel
};

// Photo vs desired and vs predicted, per pixel (against the per-pixel prediction
// `predicted_pixels`, PredictPixels) and per patch (against the solution's radiosity B), as the
// header comment says.
Comparison Compare(const cv::Mat& exitance, const std::vector<int>& pixel_patch,
                   const std::vector<bool>& interior, const CompensationProblem& problem,
                   const Eigen::MatrixX3d& radiosity, const cv::Mat& predicted_pixels,
                   int min_pixels) {
  const int n = problem.size();
  const LabConverter lab{problem.rgb_to_xyz, problem.white_xyz};
  std::vector<Eigen::Vector3d> lab_desired(n), lab_predicted(n);
  for (int i = 0; i < n; ++i) {
    lab_desired[i] = lab.Lab(problem.desired.row(i).transpose());
    lab_predicted[i] = lab.Lab(radiosity.row(i).transpose());
  }
  Comparison result;
  const int rows = exitance.rows, cols = exitance.cols;
  result.delta_e76 = cv::Mat::zeros(rows, cols, CV_32FC1);
  result.delta_e2000 = cv::Mat::zeros(rows, cols, CV_32FC1);
  result.model_delta_e76 = cv::Mat::zeros(rows, cols, CV_32FC1);
  result.model_delta_e2000 = cv::Mat::zeros(rows, cols, CV_32FC1);
  result.predicted = predicted_pixels;
  Eigen::MatrixX3d sum_all = Eigen::MatrixX3d::Zero(n, 3), sum_interior = sum_all;
  std::vector<int> count_all(n, 0), count_interior(n, 0);
  double sum76 = 0, sum2000 = 0, model76 = 0, model2000 = 0, constant76 = 0;
  for (int row = 0; row < rows; ++row) {
    for (int col = 0; col < cols; ++col) {
      const size_t index = static_cast<size_t>(row) * cols + col;
      const int i = pixel_patch[index];
      if (i < 0) continue;
      const cv::Vec3f& v = exitance.at<cv::Vec3f>(row, col);
      const Eigen::Vector3d x(v[0], v[1], v[2]);
      const Eigen::Vector3d lab_measured = lab.Lab(x);
      const double e76 = DeltaE76(lab_measured, lab_desired[i]);
      const double e2000 = DeltaE2000(lab_measured, lab_desired[i]);
      const cv::Vec3f& p = predicted_pixels.at<cv::Vec3f>(row, col);
      const Eigen::Vector3d lab_pixel_predicted = lab.Lab(Eigen::Vector3d(p[0], p[1], p[2]));
      const double m76 = DeltaE76(lab_measured, lab_pixel_predicted);
      const double m2000 = DeltaE2000(lab_measured, lab_pixel_predicted);
      constant76 += DeltaE76(lab_measured, lab_predicted[i]);
      result.delta_e76.at<float>(row, col) = float(e76);
      result.delta_e2000.at<float>(row, col) = float(e2000);
      result.model_delta_e76.at<float>(row, col) = float(m76);
      result.model_delta_e2000.at<float>(row, col) = float(m2000);
      sum76 += e76, sum2000 += e2000, model76 += m76, model2000 += m2000;
      result.measured.max76 = std::max(result.measured.max76, e76);
      result.measured.max2000 = std::max(result.measured.max2000, e2000);
      result.model.max76 = std::max(result.model.max76, m76);
      result.model.max2000 = std::max(result.model.max2000, m2000);
      ++result.seen_pixels;
      sum_all.row(i) += x.transpose();
      ++count_all[i];
      if (interior[index]) {
        sum_interior.row(i) += x.transpose();
        ++count_interior[i];
      }
    }
  }
  const double pixels = std::max(1, result.seen_pixels);
  result.measured.mean76 = sum76 / pixels;
  result.measured.mean2000 = sum2000 / pixels;
  result.model.mean76 = model76 / pixels;
  result.model.mean2000 = model2000 / pixels;
  result.model_constant_mean76 = constant76 / pixels;

  // Per patch: the mean of its interior pixels (away from patch borders, where projector pixels
  // straddling two patches spill light), or of all its pixels when too few are interior.
  result.patch_exitance = Eigen::MatrixX3d::Constant(n, 3, std::numeric_limits<double>::quiet_NaN());
  result.seen.assign(n, false);
  result.pixels.assign(n, 0);
  double area = 0, patch76 = 0, patch2000 = 0, model_patch76 = 0, model_patch2000 = 0,
         predicted76 = 0, predicted2000 = 0;
  for (int i = 0; i < n; ++i) {
    result.pixels[i] = count_all[i];
    if (count_all[i] < min_pixels) continue;
    result.seen[i] = true;
    ++result.seen_patches;
    result.patch_exitance.row(i) = count_interior[i] >= min_pixels
                                       ? Eigen::RowVector3d(sum_interior.row(i) / count_interior[i])
                                       : Eigen::RowVector3d(sum_all.row(i) / count_all[i]);
    const Eigen::Vector3d lab_measured = lab.Lab(result.patch_exitance.row(i).transpose());
    const double a = problem.area[i];
    area += a;
    patch76 += a * DeltaE76(lab_measured, lab_desired[i]);
    patch2000 += a * DeltaE2000(lab_measured, lab_desired[i]);
    model_patch76 += a * DeltaE76(lab_measured, lab_predicted[i]);
    model_patch2000 += a * DeltaE2000(lab_measured, lab_predicted[i]);
    predicted76 += a * DeltaE76(lab_predicted[i], lab_desired[i]);
    predicted2000 += a * DeltaE2000(lab_predicted[i], lab_desired[i]);
  }
  if (area > 0) {
    result.measured.patch_mean76 = patch76 / area;
    result.measured.patch_mean2000 = patch2000 / area;
    result.model.patch_mean76 = model_patch76 / area;
    result.model.patch_mean2000 = model_patch2000 / area;
    result.predicted_mean76 = predicted76 / area;
    result.predicted_mean2000 = predicted2000 / area;
  }
  return result;
}

double SolverMeanDeltaE76(const CompensationProblem& problem, const Eigen::MatrixX3d& radiosity) {
  const LabConverter lab{problem.rgb_to_xyz, problem.white_xyz};
  double sum = 0;
  for (int i = 0; i < problem.size(); ++i) {
    sum += problem.area[i] * DeltaE76(lab.Lab(radiosity.row(i).transpose()),
                                      lab.Lab(problem.desired.row(i).transpose()));
  }
  return sum / problem.area.sum();
}

nlohmann::json DeltaEJson(const PhotoDeltaE& d) {
  return {{"pixel_mean76", d.mean76},         {"pixel_max76", d.max76},
          {"pixel_mean2000", d.mean2000},     {"pixel_max2000", d.max2000},
          {"patch_mean76", d.patch_mean76}, {"patch_mean2000", d.patch_mean2000}};
}

nlohmann::json IterationJson(const VerificationIteration& it) {
  nlohmann::json exponents = nlohmann::json::array();
  for (const Eigen::Vector3d& e : it.response_exponent) exponents.push_back(Json3(e));
  nlohmann::json json = {
      {"iteration", it.index},
      {"directory", it.directory.string()},
      {"measured_vs_desired", DeltaEJson(it.measured)},
      {"measured_vs_predicted", DeltaEJson(it.model)},
      {"measured_vs_patch_radiosity_pixel_mean76", it.model_constant_mean76},
      {"predicted_vs_desired", {{"patch_mean76", it.predicted_mean76},
                                {"patch_mean2000", it.predicted_mean2000},
                                {"solver_mean76_all_patches", it.solver_mean76}}},
      {"seen_pixels", it.seen_pixels},
      {"seen_patches", it.seen_patches},
      {"seconds", {{"capture", it.capture_seconds}, {"solve", it.solve_seconds}, {"total", it.seconds}}}};
  if (!it.response_exponent.empty()) {
    json["update"] = {{"response_exponent", exponents},
                      {"reflectance_scale", Json3(it.reflectance_scale)}};
  }
  return json;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

bool VerificationOptions::Check(std::string* why) const {
  auto fail = [why](const std::string& text) {
    if (why) *why = text;
    return false;
  };
  if (rig_dir.empty()) return fail("the rig directory is required");
  if (solution_dir.empty()) return fail("the solution directory is required");
  if (out.empty()) return fail("--out is required");
  if (camera.empty()) return fail("--camera is required");
  if (iterations < 1 || iterations > 50) return fail("--iterations must be in [1, 50]");
  if (!(min_improvement >= 0.0 && min_improvement < 1.0))
    return fail("--min-improvement must be in [0, 1)");
  if (!(reflectance_step > 0.0 && reflectance_step <= 1.0))
    return fail("--reflectance-step must be in (0, 1]");
  if (min_patch_pixels < 1) return fail("--min-patch-pixels must be ≥ 1");
  std::string sequencer_why;
  if (!sequencer.Check(&sequencer_why)) return fail(sequencer_why);
  if (!camera_response.empty() && sequencer.exposures_us.size() < 2)
    return fail("--camera-response needs bracketed exposures (--exposure-us a,b,...)");
  return true;
}

DisplayWall::DisplayWall(std::vector<std::shared_ptr<PatternDisplay>> displays,
                         std::vector<std::string> names)
    : displays_(std::move(displays)), names_(std::move(names)) {
  if (displays_.empty() || displays_.size() != names_.size())
    throw std::invalid_argument("DisplayWall: one name per display, at least one display");
}

cv::Size DisplayWall::Resolution() const {
  cv::Size size(0, 0);
  for (const auto& display : displays_) {
    size.width += display->Resolution().width;
    size.height = std::max(size.height, display->Resolution().height);
  }
  return size;
}

std::string DisplayWall::Name() const {
  std::string name;
  for (const auto& display : displays_) {
    if (!name.empty()) name += '+';
    name += display->Name();
  }
  return name;
}

cv::Mat DisplayWall::Compose(const std::vector<cv::Mat>& images) const {
  if (images.size() != displays_.size())
    throw std::invalid_argument("DisplayWall: one image per display");
  cv::Mat wall(Resolution(), CV_8UC3, cv::Scalar::all(0));
  int x = 0;
  for (size_t k = 0; k < displays_.size(); ++k) {
    const cv::Size size = displays_[k]->Resolution();
    if (images[k].size() != size || images[k].type() != CV_8UC3)
      throw std::invalid_argument("DisplayWall: image " + std::to_string(k) + " does not fit");
    images[k].copyTo(wall(cv::Rect(x, 0, size.width, size.height)));
    x += size.width;
  }
  return wall;
}

void DisplayWall::Show(const cv::Mat& pattern) {
  if (pattern.size() != Resolution())
    throw IoError("display wall " + Name() + ": pattern of the wrong size");
  cv::Mat colour = pattern;
  if (pattern.type() == CV_8UC1) cv::cvtColor(pattern, colour, cv::COLOR_GRAY2BGR);
  int x = 0;
  for (size_t k = 0; k < displays_.size(); ++k) {
    const cv::Size size = displays_[k]->Resolution();
    try {
      displays_[k]->Show(colour(cv::Rect(x, 0, size.width, size.height)).clone());
    } catch (const std::exception& error) {
      // Displays' own messages usually start with their name (capture/display.h).
      const std::string display = displays_[k]->Name(), what = error.what();
      throw IoError("projector '" + names_[k] + "'" +
                    (what.rfind(display, 0) == 0 ? "" : " (display " + display + ")") + ": " + what);
    }
    x += size.width;
  }
}

nlohmann::json VerificationSummary::Json() const {
  nlohmann::json list = nlohmann::json::array();
  for (const VerificationIteration& it : iterations) list.push_back(IterationJson(it));
  nlohmann::json json = {{"command", "verify"},
                         {"iterations", list},
                         {"best", best},
                         {"complete", complete},
                         {"termination", termination},
                         {"seconds", seconds}};
  if (!error.empty()) json["error"] = error;
  if (!iterations.empty() && best >= 0) {
    const double first = iterations.front().measured.mean76;
    const double kept = iterations[best].measured.mean76;
    json["initial_mean76"] = first;
    json["best_mean76"] = kept;
    json["improvement"] = first > 0 ? (first - kept) / first : 0.0;
  }
  return json;
}

std::string VerificationSummary::BriefReport() const {
  if (iterations.empty()) return "verify: no photo taken (" + termination + ")";
  std::string text = "verify: " + std::to_string(iterations.size()) + " photo(s), measured mean ΔE76";
  for (const VerificationIteration& it : iterations) text += fmt::format(" {:.2f}", it.measured.mean76);
  if (best >= 0) {
    text += fmt::format("; best iteration {} ({:.2f}, model error {:.2f}, predicted {:.2f}), {}",
                        best, iterations[best].measured.mean76, iterations[best].model.mean76,
                        iterations[best].predicted_mean76, termination);
  }
  return text;
}

VerificationSummary RunVerification(const VerificationOptions& options) {
  const auto start = Clock::now();
  std::string why;
  if (!options.Check(&why)) throw IoError("verify: " + why);
  RegisterSyntheticCameraBackend();

  // Inputs, all checked before anything is shown or written.
  const RigDirectory rig_dir = ReadRigDirectory(options.rig_dir);
  const std::string rig_file = (options.rig_dir / "rig.json").string();
  const nlohmann::json camera_json = rig_dir.json.value("camera", nlohmann::json::object());
  if (!camera_json.is_object() || !camera_json.contains("model") || !camera_json["model"].is_string()) {
    throw IoError(rig_file + ": camera.model: required key is missing (the camera registered in "
                             "the room, from procam calibrate projectors)");
  }
  const std::filesystem::path camera_model_path =
      options.rig_dir / camera_json["model"].get<std::string>();
  if (!std::filesystem::exists(camera_model_path)) {
    throw IoError(rig_file + ": camera.model: " + camera_model_path.string() + ": file not found");
  }
  const ProjectorGeometry camera_geometry = ReadCameraModel(camera_model_path);
  const LoadedSolution solution = ReadSolution(options.solution_dir, options.scene.has_value());

  const CameraUri uri = CameraUri::Parse(options.camera);
  std::shared_ptr<SyntheticWorld> world;
  if (uri.scheme() == "synthetic") world = OpenSyntheticWorld(uri);
  const ColourSource colour_source =
      ResolveColourSource(options, rig_dir.json, rig_file, world != nullptr);

  std::vector<std::shared_ptr<PatternDisplay>> displays = options.displays;
  if (world && displays.empty()) displays.assign(world->displays.begin(), world->displays.end());
  if (displays.size() != rig_dir.projectors.size()) {
    throw IoError(rig_file + ": projectors: the rig has " + std::to_string(rig_dir.projectors.size()) +
                  " projector(s) but " + std::to_string(displays.size()) +
                  " display(s) were given (one --display glfw:N|NAME per projector, in rig.json's order)");
  }
  std::vector<std::string> names;
  for (size_t k = 0; k < displays.size(); ++k) {
    const Projector& projector = rig_dir.projectors[k];
    names.push_back(projector.name);
    const cv::Size size(projector.geometry.width(), projector.geometry.height());
    if (displays[k]->Resolution() != size) {
      throw IoError(rig_file + ": projectors[" + std::to_string(k) + "] ('" + projector.name +
                    "') is " + std::to_string(size.width) + "x" + std::to_string(size.height) +
                    " but its display " + displays[k]->Name() + " is " +
                    std::to_string(displays[k]->Resolution().width) + "x" +
                    std::to_string(displays[k]->Resolution().height));
    }
  }
  DisplayWall wall(displays, names);

  OpenCameraOptions open_options;
  std::unique_ptr<Camera> camera = OpenCamera(options.camera, open_options);
  if (!IsColour(camera->Settings().pixel_format)) {
    throw IoError("camera '" + options.camera + "': delivers grey images; verification needs colour");
  }
  if (options.gain >= 0) camera->SetGain(options.gain);
  SequencerOptions sequencer = options.sequencer;
  if (!options.camera_response.empty()) {
    sequencer.hdr.inverse_response = ReadInverseResponse(options.camera_response, 3);
  }
  const bool hdr = sequencer.exposures_us.size() >= 2;
  // The HDR merge subtracts the camera's black level: the option's, rig.json's, or the
  // synthetic URI's.
  if (options.camera_black >= 0) {
    sequencer.hdr.black_level = options.camera_black;
  } else if (world) {
    sequencer.hdr.black_level = TestCameraOptionsFromUri(uri).black_level;
  } else {
    sequencer.hdr.black_level = colour_source.black;
  }

  // The model: geometry, the rig's reflectance and projectors (shown through 8-bit displays).
  GeometryStage geometry = options.scene
                               ? RunGeometryStage(*options.scene, solution.target_patches)
                               : RunGeometryStage(solution.scene_path, solution.target_patches);
  if (geometry.patches.fine.size() != solution.patches) {
    throw IoError((options.solution_dir / "result.json").string() + ": the solution has " +
                  std::to_string(solution.patches) + " patches but its scene subdivides into " +
                  std::to_string(geometry.patches.fine.size()) + " for target " +
                  std::to_string(solution.target_patches));
  }
  ApplyRigReflectance(rig_dir, &geometry.patches);
  std::vector<Projector> projectors = rig_dir.projectors;
  for (Projector& projector : projectors) {
    if (projector.photometry.bits != 8) {
      spdlog::warn("verify: projector '{}' is {}-bit; the displays show 8 bits, rendering at 8",
                   projector.name, projector.photometry.bits);
      projector.photometry.bits = 8;
    }
  }
  ProjectionRig rig = BuildProjectionRig(geometry.patches.fine, projectors, ProjectionRigOptions());
  if (camera_geometry.width() <= 0) throw IoError(camera_model_path.string() + ": bad size");
  spdlog::info("verify: casting the camera's {}x{} rays", camera_geometry.width(), camera_geometry.height());
  // What each camera pixel sees and which projector pixels light it (the geometry is fixed;
  // the photometry the loop refines is applied per photo, PredictPixels).
  const CameraPixelRays lighting =
      CastCameraPixels(geometry.scene, geometry.patches.fine, projectors, camera_geometry);
  // Interior pixels: their four neighbours see the same patch.
  std::vector<bool> interior(lighting.patch.size(), false);
  for (int row = 1; row + 1 < lighting.height; ++row) {
    for (int col = 1; col + 1 < lighting.width; ++col) {
      const size_t index = static_cast<size_t>(row) * lighting.width + col;
      const int i = lighting.patch[index];
      interior[index] = i >= 0 && lighting.patch[index - 1] == i && lighting.patch[index + 1] == i &&
                        lighting.patch[index - lighting.width] == i &&
                        lighting.patch[index + lighting.width] == i;
    }
  }

  CreateDirectories(options.out);
  VerificationSummary summary;
  summary.termination = "max_iterations";
  const double white = geometry.scene.white;
  auto write_summary = [&] {
    nlohmann::json json = summary.Json();
    json["rig"] = rig_dir.Describe();
    json["solution"] = options.solution_dir.string();
    json["camera"] = options.camera;
    json["colour_source"] = colour_source.source;
    json["hdr"] = hdr;
    json["exposures_us"] = sequencer.exposures_us;
    WriteFileAtomically(options.out / "result.json", json.dump(2) + "\n");
    HtmlReport report("procam verify");
    AddVerificationReport(summary, &report);
    report.Write(options.out / "report.html");
  };

  CompensationProblem problem = MakeProblem(geometry.scene, geometry.patches.fine,
                                            geometry.form_factors, solution.alpha);
  problem.lower = rig.lower;
  problem.upper = rig.upper;
  {
    cv::Mat desired = cv::Mat::zeros(lighting.height, lighting.width, CV_32FC3);
    for (int row = 0; row < lighting.height; ++row) {
      for (int col = 0; col < lighting.width; ++col) {
        const int i = lighting.patch[static_cast<size_t>(row) * lighting.width + col];
        if (i < 0) continue;
        desired.at<cv::Vec3f>(row, col) = cv::Vec3f(float(problem.desired(i, 0) / white),
                                                    float(problem.desired(i, 1) / white),
                                                    float(problem.desired(i, 2) / white));
      }
    }
    summary.desired = LinearToDisplay(desired);
    WritePicture(options.out / "desired.png", summary.desired);
  }

  Eigen::MatrixX3d emittance = solution.emittance, radiosity = solution.radiosity;
  double heat_scale = 0.0;
  double best_mean = std::numeric_limits<double>::infinity();
  for (int k = 0; k < options.iterations; ++k) {
    const auto iteration_start = Clock::now();
    VerificationIteration it;
    it.index = k;
    it.directory = options.out / "iterations" / std::to_string(k);
    CreateDirectories(it.directory);
    RenderSummary render;
    const std::vector<ProjectorImage> images =
        RenderProjectorImages(rig, geometry.scene, emittance, RenderOptions(), &render);
    std::vector<cv::Mat> patterns;
    for (size_t p = 0; p < images.size(); ++p) {
      WriteProjectorImage(it.directory / (names[p] + ".png"), images[p]);
      patterns.push_back(PatternFromImage(images[p]));
    }
    WriteNpy(it.directory / "E.npy", RowMatrixXd(emittance));
    WriteNpy(it.directory / "B.npy", RowMatrixXd(radiosity));
    WriteNpy(it.directory / "reflectance.npy", RowMatrixXd(rig.reflectance));

    // Show and photograph: the session keeps the photo the moment it is taken.
    CaptureSequence sequence;
    sequence.kind = "verify";
    const cv::Mat pattern = wall.Compose(patterns);
    sequence.parameters = {{"iteration", k}, {"projectors", names}, {"checksum", PatternChecksum(pattern)}};
    sequence.patterns.push_back({"solution", pattern, {{"kind", "verify"}, {"iteration", k}}});
    CaptureSessionOptions session_options;
    session_options.directory = it.directory / "session";
    session_options.sequencer = sequencer;
    const auto capture_start = Clock::now();
    try {
      RunCaptureSession(session_options, sequence, *camera, wall);
    } catch (const std::exception& error) {
      summary.complete = false;
      summary.termination = "fault";
      summary.error = error.what();
      summary.seconds = SecondsSince(start);
      write_summary();
      throw IoError("verify: iteration " + std::to_string(k) + ": " + error.what() + " (kept " +
                    std::to_string(k) + " complete iteration(s) and the photos taken in " +
                    options.out.string() + ", see result.json)");
    }
    it.capture_seconds = SecondsSince(capture_start);
    const CaptureSessionData session = CaptureSessionData::Load(session_options.directory);
    const cv::Mat photo = hdr ? session.Hdr(0) : session.Mean(0);
    if (photo.channels() != 3) throw IoError(session_options.directory.string() + ": the photo is not colour");
    if (photo.cols != lighting.width || photo.rows != lighting.height) {
      throw IoError("camera '" + options.camera + "' delivers " + std::to_string(photo.cols) + "x" +
                    std::to_string(photo.rows) + " photos but " + camera_model_path.string() +
                    " is " + std::to_string(lighting.width) + "x" + std::to_string(lighting.height));
    }
    CameraColour colour;
    if (colour_source.synthetic) {
      const nlohmann::json& manifest = session.manifest();
      const double full_scale =
          manifest["patterns"][0]["captured"].value("full_scale", 255.0);
      colour = SyntheticColour(uri, *world, manifest, hdr, full_scale, options.camera_black);
    } else {
      colour.to_exitance = colour_source.matrix;
      colour.black = hdr ? 0.0 : colour_source.black;
      colour.source = colour_source.source;
    }
    cv::Mat photo32;
    photo.convertTo(photo32, CV_32FC3);
    const cv::Mat exitance = PhotoToExitance(photo32, colour);
    const cv::Mat predicted =
        PredictPixels(lighting, rig, images, geometry.form_factors);
    const Comparison comparison = Compare(exitance, lighting.patch, interior, problem, radiosity,
                                          predicted, options.min_patch_pixels);
    it.measured = comparison.measured;
    it.model = comparison.model;
    it.predicted_mean76 = comparison.predicted_mean76;
    it.predicted_mean2000 = comparison.predicted_mean2000;
    it.solver_mean76 = SolverMeanDeltaE76(problem, radiosity);
    it.seen_pixels = comparison.seen_pixels;
    it.seen_patches = comparison.seen_patches;
    it.model_constant_mean76 = comparison.model_constant_mean76;
    if (k == 0) heat_scale = std::max(10.0, 10.0 * std::ceil(3.0 * it.measured.mean76 / 10.0));
    it.photo = LinearToDisplay(exitance / white);
    it.predicted = LinearToDisplay(comparison.predicted / white);
    it.delta_e76 = HeatMapWithColourBar(comparison.delta_e76, heat_scale, "dE76");
    it.model_delta_e76 = HeatMapWithColourBar(comparison.model_delta_e76, heat_scale, "dE76");
    WritePicture(it.directory / "photo.png", it.photo);
    WritePicture(it.directory / "predicted.png", it.predicted);
    WritePicture(it.directory / "delta_e76.png", it.delta_e76);
    WritePicture(it.directory / "delta_e2000.png",
                 HeatMapWithColourBar(comparison.delta_e2000, heat_scale / 2, "dE00"));
    WritePicture(it.directory / "model_delta_e76.png", it.model_delta_e76);
    WriteNpy(it.directory / "measured_B.npy", RowMatrixXd(comparison.patch_exitance));
    spdlog::info("verify: iteration {}: measured ΔE76 {:.2f} (max {:.1f}), model error {:.2f}, "
                 "predicted {:.2f}, {} patches seen",
                 k, it.measured.mean76, it.measured.max76, it.model.mean76, it.predicted_mean76,
                 it.seen_patches);
    if (it.seen_patches == 0) {
      throw IoError("camera '" + options.camera + "': " + camera_model_path.string() +
                    " sees no patch of the scene (is the camera registered in the room frame?)");
    }

    const bool improved = it.measured.mean76 < best_mean * (1.0 - options.min_improvement);
    if (it.measured.mean76 < best_mean) {
      best_mean = it.measured.mean76;
      summary.best = k;
    }
    const bool last = k + 1 == options.iterations || (k > 0 && !improved);
    if (!last) {  // update the model from this photo and solve again
      const auto solve_start = Clock::now();
      const ModelUpdate update = FitModel(options, rig, images, geometry.form_factors,
                                          comparison.patch_exitance, comparison.seen, radiosity);
      it.response_exponent = update.exponent;
      it.reflectance_scale = update.scale;
      spdlog::info("verify: model update: reflectance scale ({:.3f}, {:.3f}, {:.3f}), fit rms {:.4f} → {:.4f}",
                   update.scale[0], update.scale[1], update.scale[2], update.rms_before, update.rms_after);
      for (size_t p = 0; p < update.exponent.size(); ++p) {
        spdlog::info("verify:   projector '{}': response exponent ({:.3f}, {:.3f}, {:.3f})", names[p],
                     update.exponent[p][0], update.exponent[p][1], update.exponent[p][2]);
      }
      ApplyUpdate(update, &rig, &geometry);
      const CompensationRun run = RunCompensation(geometry, solution.solver, solution.alpha, &rig);
      emittance = run.solution.emittance;
      radiosity = run.solution.radiosity;
      problem = run.fine;
      it.solve_seconds = SecondsSince(solve_start);
    }
    it.seconds = SecondsSince(iteration_start);
    nlohmann::json json = IterationJson(it);
    json["colour"] = colour.Json();
    json["render"] = {{"patches_below_lower", render.patches_below_lower},
                      {"patches_above_upper", render.patches_above_upper},
                      {"max_relative_error", render.max_relative_error}};
    nlohmann::json model = nlohmann::json::array();
    for (size_t p = 0; p < rig.projectors.size(); ++p) {
      nlohmann::json gamma = nlohmann::json::array();
      for (int j = 0; j < 3; ++j) {
        const ResponseCurve& curve = rig.projectors[p].photometry.response[j];
        gamma.push_back(curve.is_table() ? nlohmann::json("table") : nlohmann::json(curve.gamma()));
      }
      model.push_back({{"name", names[p]}, {"gamma_after_update", gamma}});
    }
    json["projectors"] = model;
    WriteFileAtomically(it.directory / "result.json", json.dump(2) + "\n");
    summary.iterations.push_back(std::move(it));
    summary.seconds = SecondsSince(start);
    write_summary();
    if (last) {
      if (k + 1 < options.iterations) summary.termination = "converged";
      break;
    }
  }
  summary.complete = true;
  summary.seconds = SecondsSince(start);
  write_summary();
  return summary;
}

void AddVerificationReport(const VerificationSummary& summary, HtmlReport* report) {
  report->Heading("Verification with photos and the closed loop");
  report->Paragraph(
      "Each iteration shows the solution's projector images, photographs the room and compares "
      "the photo in CIE L*a*b* with the desired appearance (measured ΔE) and with what the model "
      "predicts (model error); then the model (projector response exponents, per-patch "
      "reflectance) is updated from measured minus predicted and the problem solved again. "
      "Predicted: the solver's radiosity against the desired, on the patches the camera sees.");
  std::vector<std::vector<std::string>> rows;
  std::vector<std::pair<double, double>> measured, model, predicted;
  for (const VerificationIteration& it : summary.iterations) {
    std::string update = "—";
    if (!it.response_exponent.empty()) {
      update = fmt::format("ρ scale ({:.3f}, {:.3f}, {:.3f})", it.reflectance_scale[0],
                           it.reflectance_scale[1], it.reflectance_scale[2]);
      for (const Eigen::Vector3d& e : it.response_exponent)
        update += fmt::format("; γ × ({:.3f}, {:.3f}, {:.3f})", e[0], e[1], e[2]);
    }
    rows.push_back({std::to_string(it.index) + (it.index == summary.best ? " (best)" : ""),
                    fmt::format("{:.2f} ({:.1f})", it.measured.mean76, it.measured.max76),
                    fmt::format("{:.2f}", it.measured.mean2000),
                    fmt::format("{:.2f}", it.model.mean76),
                    fmt::format("{:.2f}", it.predicted_mean76), std::to_string(it.seen_patches),
                    update, fmt::format("{:.1f}", it.seconds)});
    measured.emplace_back(it.index, std::max(1e-3, it.measured.mean76));
    model.emplace_back(it.index, std::max(1e-3, it.model.mean76));
    predicted.emplace_back(it.index, std::max(1e-3, it.predicted_mean76));
  }
  report->Table({"iteration", "measured ΔE76 mean (max)", "measured CIEDE2000 mean",
                 "model error ΔE76 mean", "predicted ΔE76 mean", "patches seen",
                 "model update after it", "seconds"},
                rows);
  if (!summary.complete) report->Paragraph("Stopped by a fault: " + summary.error);
  if (!summary.iterations.empty()) {
    report->Plot("Convergence", "iteration", "mean ΔE76",
                 {{"measured (photo vs desired)", measured},
                  {"model error (photo vs predicted)", model},
                  {"predicted (solver vs desired)", predicted}});
  }
  if (!summary.desired.empty()) report->Figures({{"desired (per patch, as the camera sees it)", summary.desired}});
  for (const VerificationIteration& it : summary.iterations) {
    report->Heading(fmt::format("Iteration {}", it.index), 3);
    report->Figures({{"photo", it.photo},
                     {"predicted", it.predicted},
                     {"ΔE76 photo vs desired", it.delta_e76},
                     {"ΔE76 photo vs predicted", it.model_delta_e76}});
  }
}

}  // namespace procam
