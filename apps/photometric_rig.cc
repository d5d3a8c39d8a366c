#include "apps/photometric_rig.h"

#include "apps/command_line.h"

#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>

#include "geometry/stage.h"
#include "calibration/photometric_transfer.h"
#include "projection/camera_rays.h"
#include "compensation/unit_light.h"
#include "projection/projection_rig.h"
#include "calibration/rig_directory.h"
#include "capture/camera.h"
#include "capture/test_camera.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "base/io.h"
#include "projection/projector.h"

namespace procam {

struct PhotometricRigStage::State {
  PhotometricRigArguments args;
  std::filesystem::path rig_dir, session_dir;
  std::string rig_file;
  // Scene units only:
  std::optional<GeometryStage> stage;
  Projector projector;
  CameraPixelLighting lighting;
  UnitLightModel model;
  Eigen::Vector3d camera_scale = Eigen::Vector3d::Ones();
  double camera_black = 0.0;
  cv::Mat transfer;
  // Prepared by Prepare():
  ReflectanceEstimate reflectance;
  nlohmann::json photometric_entry, rig_projector;
};

namespace {

nlohmann::json Json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

// k from "x", "r,g,b" or a synthetic camera URI (with the session's exposure and gain).
void ParseCameraScale(const PhotometricRigArguments& args, const std::filesystem::path& session,
                      bool hdr, double full_scale, Eigen::Vector3d* scale, double* black) {
  const std::string& text = args.camera_scale;
  if (text.rfind("synthetic:", 0) == 0) {
    const CameraUri uri = CameraUri::Parse(text);
    // The world reads `patches` first; the test camera's reader rejects keys nobody read.
    const std::shared_ptr<SyntheticWorld> world = OpenSyntheticWorld(uri);
    const TestCameraOptions camera = TestCameraOptionsFromUri(uri);
    const nlohmann::json manifest = nlohmann::json::parse(ReadFile(session / "session.json"));
    const nlohmann::json settings =
        manifest.value("camera", nlohmann::json::object()).value("settings", nlohmann::json::object());
    const std::string recorded =
        manifest.value("camera", nlohmann::json::object()).value("uri", std::string());
    if (recorded != "synthetic:" + uri.path()) {
      throw IoError("--camera-scale: " + text + " is not the camera of " +
                    (session / "session.json").string() + " (" + recorded + ")");
    }
    const double gain = std::pow(10.0, settings.value("gain", 0.0) / 20.0);
    const double full = full_scale > 0.0 ? full_scale : 255.0;
    if (hdr) {  // the HDR merge: (DN − black) / (full − black) per second
      *scale = Eigen::Vector3d::Constant(world->radiance_scale * full /
                                         (full - camera.black_level) * gain /
                                         (camera.reference_exposure_us * 1e-6));
      *black = 0.0;
    } else {
      const double exposure = settings.value("exposure_us", camera.exposure_us);
      *scale = Eigen::Vector3d::Constant(world->radiance_scale * full * exposure /
                                         camera.reference_exposure_us * gain);
      *black = camera.black_level;
    }
    return;
  }
  *scale = ParsePositiveRgb("--camera-scale", text);
  *black = 0.0;
}

}  // namespace

void AddPhotometricRigOptions(CLI::App* command, PhotometricRigArguments* args) {
  command->add_option("--projector", args->projector,
                      "Merge the fit into RIG_DIR/rig.json's projector of this name");
  command->add_option("--scene", args->scene,
                      "Scene file: black and max in the scene's units and per-patch reflectance "
                      "(needs the rig's camera registration and the projector's model)");
  command->add_option("--patches", args->patches, "Patch target for --scene (default: the scene's)");
  command->add_option("--camera-scale", args->camera_scale,
                      "Camera value per unit exitance in the scene's units: a number, R,G,B, or "
                      "the synthetic camera's URI (its exposure and gain from session.json)");
  command->add_option("--camera-black", args->camera_black,
                      "Camera black level in digital numbers, subtracted before the fit "
                      "(default 0, or the synthetic URI's black)");
  command->add_option("--response", args->response, "What rig.json gets: gamma or lut")
      ->check(CLI::IsMember({"gamma", "lut"}))
      ->capture_default_str();
}

PhotometricRigStage::PhotometricRigStage(const PhotometricRigArguments& args,
                                         const std::filesystem::path& rig_dir,
                                         const std::filesystem::path& session_dir,
                                         cv::Size image_size, bool hdr, double full_scale)
    : state_(std::make_unique<State>()) {
  State& s = *state_;
  s.args = args;
  s.rig_dir = rig_dir;
  s.session_dir = session_dir;
  s.rig_file = (rig_dir / "rig.json").string();
  if (args.response != "gamma" && args.response != "lut") {
    throw IoError("--response: '" + args.response + "': gamma or lut");
  }
  if (args.scene.empty()) {
    if (!args.camera_scale.empty()) throw IoError("--camera-scale: needs --scene");
    return;
  }
  if (args.projector.empty()) {
    throw IoError("--scene: needs --projector NAME (the rig.json projector to calibrate)");
  }
  if (args.camera_scale.empty()) {
    throw IoError(
        "--camera-scale: required with --scene: the camera's value per unit exitance in the "
        "scene's units (a number or R,G,B; for the synthetic camera its URI)");
  }
  // The rig's geometry: the camera registered in the room and the projector's model.
  const nlohmann::json rig = ReadRigJson(rig_dir);
  const nlohmann::json camera = rig.value("camera", nlohmann::json::object());
  if (!camera.is_object() || !camera.contains("model") || !camera["model"].is_string()) {
    throw IoError(s.rig_file + ": camera.model: required key is missing (procam calibrate "
                               "camera), needed for --scene");
  }
  if (!rig.contains("registration")) {
    throw IoError(s.rig_file +
                  ": registration: required key is missing (the camera is not registered in the "
                  "room frame: procam calibrate projectors), needed for --scene");
  }
  const nlohmann::json* entry = nullptr;
  if (rig.contains("projectors") && rig["projectors"].is_array()) {
    for (const nlohmann::json& candidate : rig["projectors"]) {
      if (candidate.is_object() && candidate.value("name", "") == args.projector) entry = &candidate;
    }
  }
  if (entry == nullptr || !entry->contains("model") || !(*entry)["model"].is_string()) {
    throw IoError(s.rig_file + ": projectors: no entry named '" + args.projector +
                  "' with a model (procam calibrate projectors), needed for --scene");
  }
  ProjectorGeometry camera_geometry;
  try {
    camera_geometry = ReadCameraModel(rig_dir / camera["model"].get<std::string>());
    s.projector.geometry = ReadCameraModel(rig_dir / (*entry)["model"].get<std::string>());
  } catch (const IoError& error) {
    throw IoError(s.rig_file + ": " + error.what());
  }
  s.projector.name = args.projector;
  if (camera_geometry.width() != image_size.width ||
      camera_geometry.height() != image_size.height) {
    throw IoError(s.rig_file + ": camera.model: " + std::to_string(camera_geometry.width()) + "x" +
                  std::to_string(camera_geometry.height()) + ", the session's images are " +
                  std::to_string(image_size.width) + "x" + std::to_string(image_size.height));
  }
  ParseCameraScale(args, session_dir, hdr, full_scale, &s.camera_scale, &s.camera_black);
  if (args.camera_black >= 0.0) s.camera_black = args.camera_black;

  s.stage = RunGeometryStage(args.scene, GeometryArguments(args.patches));
  const PatchLevel& level = s.stage->patches.fine;
  s.lighting = LightCameraPixels(s.stage->scene, level, s.projector.geometry, camera_geometry);
  s.model = ModelUnitLight(level, s.stage->form_factors, UnitLightExitance(level, s.projector));
  s.transfer = PhotometricTransfer(s.lighting, level, s.model, s.camera_scale);
}

PhotometricRigStage::~PhotometricRigStage() = default;

bool PhotometricRigStage::scene_units() const { return state_->stage.has_value(); }

void PhotometricRigStage::Configure(PhotometricCalibrationOptions* options) const {
  const State& s = *state_;
  if (!scene_units()) return;
  options->transfer = s.transfer;
  if (s.camera_black > 0.0) {
    options->ambient = cv::Mat(s.transfer.size(), CV_32FC3, cv::Scalar::all(s.camera_black));
  }
  cv::Mat seen;
  cv::inRange(s.transfer, cv::Scalar::all(1e-30), cv::Scalar::all(1e30), seen);
  options->mask = options->mask.empty() ? seen : (options->mask & seen);
}

void PhotometricRigStage::Prepare(const PhotometricModel& model,
                                  const std::vector<FlatField>& fields, const cv::Mat& mask,
                                  nlohmann::json* photometric, nlohmann::json* result) {
  State& s = *state_;
  nlohmann::json& entry = s.photometric_entry;
  entry = {{"session", s.session_dir.string()}};
  if (scene_units()) {
    const std::string units =
        "scene units: irradiance at 1 m on the projector's axis (docs/scene_format.md max)";
    (*photometric)["units"] = units;
    (*photometric)["note"] =
        "black and max converted through the radiosity model of " + s.args.scene +
        " with the rig's geometry and camera scale k; scaled by the scene's nominal reflectance";
    (*result)["units"] = units;
    (*result)["note"] = (*photometric)["note"];
    entry["units"] = "scene";
    entry["scene"] = s.args.scene;
    entry["camera_scale"] = Json(s.camera_scale);
    entry["camera_black"] = s.camera_black;

    // White minus black: a white field when captured, else the sum of the full-drive channel
    // fields minus black; its output difference is max − black either way.
    const FlatField* black = nullptr;
    const FlatField* white = nullptr;
    std::array<const FlatField*, 3> full = {nullptr, nullptr, nullptr};
    for (const FlatField& field : fields) {
      if (field.drive.isZero()) black = &field;
      if ((field.drive.array() == 1.0).all()) white = &field;
      for (int c = 0; c < 3; ++c) {
        if (field.drive == Eigen::Vector3d::Unit(c)) full[c] = &field;
      }
    }
    cv::Mat difference;
    const auto as_float = [](const cv::Mat& image) {
      cv::Mat out;
      image.convertTo(out, CV_32FC3);
      return out;
    };
    if (white != nullptr) {
      difference = as_float(white->image) - as_float(black->image);
    } else {
      difference = cv::Mat(black->image.size(), CV_32FC3, cv::Scalar::all(0));
      for (int c = 0; c < 3; ++c) difference += as_float(full[c]->image) - as_float(black->image);
    }
    const PatchLevel& level = s.stage->patches.fine;
    s.reflectance =
        EstimatePatchReflectance(s.lighting, level, s.stage->form_factors, s.model, difference,
                                 mask, model.max - model.black, s.camera_scale,
                                 s.args.min_patch_pixels);
    std::printf("reflectance: %d of %d patches seen by the camera (≥ %d pixels)\n",
                s.reflectance.patches_seen, level.size(), s.args.min_patch_pixels);
    (*result)["reflectance"] = {{"file", "reflectance.npy"},
                                {"patches", level.size()},
                                {"patches_seen", s.reflectance.patches_seen},
                                {"target_patches", s.stage->scene.target_patches}};
    (*result)["camera_scale"] = Json(s.camera_scale);
  } else {
    entry["units"] = "camera";
  }
  (*result)["rig_projector"] = s.args.projector;

  nlohmann::json& projector = s.rig_projector;
  projector = nlohmann::json::object();
  if (s.args.response == "lut") {
    projector["lut"] = {model.table[0], model.table[1], model.table[2]};
  } else {
    projector["gamma"] = Json(model.gamma);
  }
  projector["mixing"] = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) {
    projector["mixing"].push_back({model.mixing(i, 0), model.mixing(i, 1), model.mixing(i, 2)});
  }
  if (scene_units()) {
    projector["black"] = Json(model.black);
    projector["max"] = Json(model.max);
  }
}

void PhotometricRigStage::Commit() const {
  const State& s = *state_;
  if (s.args.projector.empty()) return;
  if (scene_units()) {
    WriteNpy(s.rig_dir / "reflectance.npy", RowMatrixXd(s.reflectance.reflectance));
  }
  UpdateRigJson(s.rig_dir, [&](nlohmann::json& rig) {
    nlohmann::json& entry = RigProjectorEntry(rig, s.args.projector);
    for (const char* key : {"gamma", "lut", "black", "max"}) entry.erase(key);
    entry.update(s.rig_projector);
    if (!rig.contains("photometric") || !rig["photometric"].is_object())
      rig["photometric"] = nlohmann::json::object();
    rig["photometric"][s.args.projector] = s.photometric_entry;
    if (scene_units()) {
      rig["reflectance"] = {{"file", "reflectance.npy"},
                            {"projector", s.args.projector},
                            {"scene", s.args.scene},
                            {"target_patches", s.stage->scene.target_patches},
                            {"patches", s.stage->patches.fine.size()},
                            {"patches_seen", s.reflectance.patches_seen}};
    }
  });
}

}  // namespace procam
