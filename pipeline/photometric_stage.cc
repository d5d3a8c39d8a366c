#include "pipeline/photometric_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <set>
#include <stdexcept>
#include <vector>

#include "base/html_report.h"
#include "base/io.h"
#include "base/json_fields.h"
#include "base/parse.h"
#include "capture/camera.h"
#include "capture/session.h"
#include "capture/simulated_camera.h"
#include "compensation/unit_light.h"
#include "geometry/stage.h"
#include "projection/camera_rays.h"
#include "projection/photometric_transfer.h"
#include "projection/projection_rig.h"
#include "projection/projector.h"
#include "projection/reflectance_map.h"
#include "projection/rig_directory.h"

namespace procam {
namespace {

// The rig side of the stage: rig.json's geometry for scene units, the per-pixel transfer, the
// reflectance and the rig.json update.
class PhotometricRigStage {
 public:
  // Checks the arguments and, with a scene, the rig's geometry (rig.json camera.model,
  // registration, projectors[NAME].model), and computes the per-pixel transfer. Throws IoError
  // naming RIG_DIR/rig.json and the key, or the option.
  PhotometricRigStage(const PhotometricStageOptions& args, const std::filesystem::path& rig_dir,
                      const std::filesystem::path& session_dir, cv::Size image_size, bool hdr,
                      double full_scale);
  ~PhotometricRigStage();

  bool scene_units() const;
  // Scene units: sets the transfer and the camera black (as ambient), and keeps only pixels
  // that see a patch. Camera units: nothing.
  void Configure(PhotometricCalibrationOptions* options) const;
  // After the fit: the reflectance (scene units) and the rig.json update, nothing written yet;
  // `photometric` and `result` (the command's JSON) get the units and the numbers.
  void Prepare(const PhotometricModel& model, const std::vector<FlatField>& fields,
               const cv::Mat& mask, nlohmann::json* photometric, nlohmann::json* result);
  // Writes RIG_DIR/reflectance.npy and the projector's reflectance map with its report page
  // (scene units) and rig.json, each atomically.
  void Commit() const;
  // RIG_DIR/NAME.photometric_report.html: the reflectance map and its numbers.
  void WriteReflectanceReport(const std::filesystem::path& path) const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

struct PhotometricRigStage::State {
  PhotometricStageOptions args;
  std::filesystem::path rig_dir, session_dir;
  std::string rig_file;
  // Scene units only:
  std::optional<GeometryStage> stage;
  Projector projector;
  ProjectorGeometry camera_geometry;
  CameraPixelLighting lighting;
  UnitLightModel model;
  Eigen::Vector3d camera_scale = Eigen::Vector3d::Ones();
  double camera_black = 0.0;
  cv::Mat transfer;
  // Prepared by Prepare():
  ReflectanceEstimate reflectance;
  ReflectanceMap reflectance_map;
  RigPhotometry photometric_entry;
  RigProjector rig_projector;  // its photometry (black, max, response, mixing)
};

// k from "x", "r,g,b" or a simulated camera's URI (its colour calibration for the session's
// exposure and gain: capture/simulated_camera.h).
void ParseCameraScale(const PhotometricStageOptions& args, const std::filesystem::path& session,
                      bool hdr, double full_scale, Eigen::Vector3d* scale, double* black) {
  const std::string& text = args.camera_scale;
  std::optional<SimulatedCamera> simulated;
  if (text.find(':') != std::string::npos) simulated = FindSimulatedCamera(text);
  if (simulated) {
    const CameraUri uri = CameraUri::Parse(text);
    const nlohmann::json manifest = nlohmann::json::parse(ReadFile(session / "session.json"));
    const std::string recorded =
        manifest.value("camera", nlohmann::json::object()).value("uri", std::string());
    if (recorded != uri.scheme() + ":" + uri.path()) {
      throw IoError(FlagOf(args, &args.camera_scale) + ": " + text + " is not the camera of " +
                    (session / "session.json").string() + " (" + recorded + ")");
    }
    *scale = simulated->value_per_exitance(manifest, hdr, full_scale, simulated->black_level);
    *black = hdr ? 0.0 : simulated->black_level;  // the HDR merge has removed it
    return;
  }
  *scale = ParsePositiveRgb(FlagOf(args, &args.camera_scale), text);
  *black = 0.0;
}

}  // namespace

PhotometricRigStage::PhotometricRigStage(const PhotometricStageOptions& args,
                                         const std::filesystem::path& rig_dir,
                                         const std::filesystem::path& session_dir,
                                         cv::Size image_size, bool hdr, double full_scale)
    : state_(std::make_unique<State>()) {
  State& s = *state_;
  s.args = args;
  s.rig_dir = rig_dir;
  s.session_dir = session_dir;
  s.rig_file = (rig_dir / "rig.json").string();
  if (!args.projector.empty() && !std::filesystem::is_regular_file(s.rig_file)) {
    throw IoError(s.rig_file + ": not found; " + FlagOf(args, &args.projector) + " " +
                  args.projector +
                  " merges the fit into an existing rig (procam calibrate camera, projectors)");
  }
  if (args.scene.empty()) {
    if (!args.camera_scale.empty())
      throw IoError(FlagOf(args, &args.camera_scale) + ": needs " + FlagOf(args, &args.scene));
    return;
  }
  if (args.projector.empty()) {
    throw IoError(FlagOf(args, &args.scene) + ": needs " + FlagOf(args, &args.projector) +
                  " NAME (the rig.json projector to calibrate)");
  }
  if (args.camera_scale.empty()) {
    throw IoError(FlagOf(args, &args.camera_scale) + ": required with " +
                  FlagOf(args, &args.scene) +
                  ": the camera's value per unit exitance in the scene's units (a number or "
                  "R,G,B; for the synthetic camera its URI)");
  }
  // The rig's geometry: the camera registered in the room and the projector's model.
  const RigFile rig = ReadRigFile(rig_dir);
  if (rig.camera.model.empty()) {
    throw IoError(s.rig_file +
                  ": camera.model: required key is missing (procam calibrate "
                  "camera), needed for --scene");
  }
  if (rig.registration.is_null()) {
    throw IoError(s.rig_file +
                  ": registration: required key is missing (the camera is not registered in the "
                  "room frame: procam calibrate projectors), needed for --scene");
  }
  const auto entry = std::find_if(rig.projectors.begin(), rig.projectors.end(),
                                  [&](const RigProjector& p) { return p.name == args.projector; });
  if (entry == rig.projectors.end() || entry->model.empty()) {
    throw IoError(s.rig_file + ": projectors: no entry named '" + args.projector +
                  "' with a model (procam calibrate projectors), needed for --scene");
  }
  ProjectorGeometry& camera_geometry = s.camera_geometry;
  try {
    camera_geometry = ReadCameraModel(rig_dir / rig.camera.model);
    s.projector.geometry = ReadCameraModel(rig_dir / entry->model);
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
  if (args.camera_black) s.camera_black = *args.camera_black;

  GeometryOptions geometry;
  geometry.patches = args.patches;
  geometry.progress = args.progress;
  s.stage = RunGeometryStage(args.scene, geometry);
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
  RigPhotometry& entry = s.photometric_entry;
  entry = RigPhotometry{};
  entry.session = s.session_dir.string();
  if (scene_units()) {
    const std::string units =
        "scene units: irradiance at 1 m on the projector's axis (docs/scene_format.md max)";
    (*photometric)["units"] = units;
    (*photometric)["note"] =
        "black and max converted through the radiosity model of " + s.args.scene +
        " with the rig's geometry and camera scale k; scaled by the scene's nominal reflectance";
    (*result)["units"] = units;
    (*result)["note"] = (*photometric)["note"];
    entry.units = "scene";
    entry.scene = s.args.scene;
    entry.camera_scale = s.camera_scale;
    entry.camera_black = s.camera_black;

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
    s.reflectance = EstimatePatchReflectance(s.lighting, level, s.stage->form_factors, s.model,
                                             difference, mask, model.max - model.black,
                                             s.camera_scale, s.args.min_patch_pixels);
    Report(s.args.progress,
           fmt::format("reflectance: {} of {} patches seen by the camera (≥ {} pixels)",
                       s.reflectance.patches_seen, level.size(), s.args.min_patch_pixels));
    ReflectanceMapOptions map_options;
    map_options.min_patch_pixels = s.args.min_patch_pixels;
    s.reflectance_map = EstimateReflectanceMap(
        level, s.projector.geometry, s.camera_geometry, s.lighting, s.reflectance, difference, mask,
        model.max - model.black, s.camera_scale, map_options);
    Report(s.args.progress,
           fmt::format("reflectance map: {} of the projector's {} lit pixels measured",
                       s.reflectance_map.measured_pixels, s.reflectance_map.lit_pixels));
    (*result)["reflectance_map"] = {{"file", ReflectanceMapFile(s.args.projector)},
                                    {"lit_pixels", s.reflectance_map.lit_pixels},
                                    {"measured_pixels", s.reflectance_map.measured_pixels},
                                    {"report", s.args.projector + ".photometric_report.html"}};
    (*result)["reflectance"] = {{"file", "reflectance.npy"},
                                {"patches", level.size()},
                                {"patches_seen", s.reflectance.patches_seen},
                                {"target_patches", s.stage->scene.target_patches}};
    (*result)["camera_scale"] = JsonTriple(s.camera_scale);
  } else {
    entry.units = "camera";
  }
  (*result)["rig_projector"] = s.args.projector;

  RigProjector& projector = s.rig_projector;
  projector = RigProjector{};
  if (s.args.response == "lut") {
    projector.response = {{"lut", {model.table[0], model.table[1], model.table[2]}}};
  } else {
    projector.response = {{"gamma", JsonTriple(model.gamma)}};
  }
  projector.mixing = model.mixing;
  if (scene_units()) {
    projector.black = model.black;
    projector.max = model.max;
  }
}

void PhotometricRigStage::Commit() const {
  const State& s = *state_;
  if (s.args.projector.empty()) return;
  RigReflectanceMap map_entry;
  if (scene_units()) {
    WriteNpy(s.rig_dir / "reflectance.npy", RowMatrixXd(s.reflectance.reflectance));
    WriteReflectanceMap(s.rig_dir, s.args.projector, s.reflectance_map, &map_entry);
    map_entry.target_patches = s.stage->scene.target_patches;
    WriteReflectanceReport(s.rig_dir / (s.args.projector + ".photometric_report.html"));
  }
  UpdateRigFile(s.rig_dir, [&](RigFile& rig) {
    RigProjector& entry = rig.Projector(s.args.projector);
    entry.black = s.rig_projector.black;
    entry.max = s.rig_projector.max;
    entry.response = s.rig_projector.response;
    entry.mixing = s.rig_projector.mixing;
    rig.photometric[s.args.projector] = s.photometric_entry;
    if (scene_units()) {
      RigReflectance reflectance;
      reflectance.file = "reflectance.npy";
      reflectance.projector = s.args.projector;
      reflectance.scene = s.args.scene;
      reflectance.target_patches = s.stage->scene.target_patches;
      reflectance.patches = s.stage->patches.fine.size();
      reflectance.patches_seen = s.reflectance.patches_seen;
      rig.reflectance = reflectance;
      rig.reflectance_maps[s.args.projector] = map_entry;
    }
  });
}

void PhotometricRigStage::WriteReflectanceReport(const std::filesystem::path& path) const {
  const State& s = *state_;
  const ReflectanceMap& map = s.reflectance_map;
  HtmlReport report("procam: reflectance of the room as projector " + s.args.projector +
                    " lights it");
  report.Paragraph(
      "From the white-minus-black flat field of session " + s.session_dir.string() +
      ", each camera pixel's measured exitance over the model's irradiance there, carried to "
      "the projector pixel that lights its point and scaled so that every patch's mean is its "
      "estimated reflectance (docs/calibration.md#reflectance-per-pixel).");
  report.Table(
      {"patches", "seen by the camera", "projector pixels lighting a patch", "measured"},
      {{std::to_string(s.stage->patches.fine.size()), std::to_string(s.reflectance.patches_seen),
        std::to_string(map.lit_pixels), std::to_string(map.measured_pixels)}});
  constexpr double kRelativeRange = 0.2;
  report.Figures(
      {{"reflectance per projector pixel (sRGB)", DrawReflectanceMap(map)},
       {"relative to its patch's (green): blue 0.8, white 1, red 1.2; grey: not measured",
        DrawRelativeReflectance(map, s.reflectance.reflectance, kRelativeRange)}});
  report.Write(path);
}

namespace {

// The flat fields of a photometric capture session, drives from each pattern's channel and level.
// Throws IoError naming session.json (or the frame file) when the session is of another kind,
// lacks levels or channels the fit needs, or is not fully captured.
struct PhotometricSession {
  std::vector<FlatField> fields;
  std::vector<std::string> names;
  nlohmann::json levels, channels;
  double full_scale = 0.0;  // camera full scale in the fields' units; 0 for HDR merges
  bool hdr = false;
};

PhotometricSession ReadPhotometricSession(const std::filesystem::path& directory) {
  if (!std::filesystem::is_directory(directory)) {
    throw IoError(directory.string() + ": not a directory");
  }
  const CaptureSessionData data = CaptureSessionData::Load(directory);
  const std::string manifest = (directory / "session.json").string();
  const nlohmann::json& sequence = data.manifest().value("sequence", nlohmann::json::object());
  const std::string kind = sequence.value("kind", "");
  if (kind != "photometric") {
    throw IoError(manifest + ": a '" + kind +
                  "' session; photometric calibration needs one captured with --sequence "
                  "photometric");
  }
  PhotometricSession session;
  const nlohmann::json& parameters = sequence.value("parameters", nlohmann::json::object());
  session.levels = parameters.value("levels", nlohmann::json::array());
  session.channels = parameters.value("channels", nlohmann::json(""));
  std::set<int> levels;
  for (const nlohmann::json& level : session.levels) {
    if (level.is_number_integer()) levels.insert(level.get<int>());
  }
  if (levels.count(255) == 0) {
    throw IoError(manifest + ": levels " + session.levels.dump() +
                  " lack 255 (each channel must be captured at full drive)");
  }
  const std::string channels =
      session.channels.is_string() ? session.channels.get<std::string>() : "";
  for (char c : std::string("rgb")) {
    if (channels.find(c) == std::string::npos) {
      throw IoError(manifest + ": channels '" + channels + "' lack '" + c +
                    "' (capture with --channels rgb or rgbw)");
    }
  }
  if (std::none_of(levels.begin(), levels.end(), [](int l) { return l > 0 && l < 255; })) {
    throw IoError(manifest + ": levels " + session.levels.dump() +
                  " give no response between black and full drive (capture several levels, "
                  "e.g. 0,32,64,...,255)");
  }

  for (int p = 0; p < data.pattern_count(); ++p) {
    const nlohmann::json& info = data.manifest()["patterns"][p].value("info", nlohmann::json());
    if (!info.is_object() || info.value("kind", "") != "flat") continue;
    if (!data.captured(p)) {
      throw IoError(manifest + ": pattern " + data.pattern_name(p) +
                    " is not captured (run the same capture command again to resume)");
    }
    const std::string channel = info.value("channel", "");
    const double drive = info.value("level", 0) / 255.0;
    FlatField field;
    if (channel == "w") {
      field.drive = Eigen::Vector3d::Constant(drive);
    } else if (channel == "r" || channel == "g" || channel == "b") {
      field.drive[channel == "r" ? 0 : channel == "g" ? 1 : 2] = drive;
    } else {
      throw IoError(manifest + ": pattern " + data.pattern_name(p) + " has channel '" + channel +
                    "'");
    }
    const nlohmann::json& captured = data.manifest()["patterns"][p]["captured"];
    field.image = data.Hdr(p);
    session.hdr = !field.image.empty();
    if (field.image.empty()) {
      field.image = data.Mean(p, 0);
      session.full_scale = captured.value("full_scale", 0.0);
    }
    if (field.image.channels() != 3) {
      throw IoError(manifest + ": pattern " + data.pattern_name(p) +
                    " was captured in grey; photometric calibration needs a colour camera");
    }
    session.fields.push_back(std::move(field));
    session.names.push_back(data.pattern_name(p));
  }
  return session;
}

}  // namespace

void PhotometricStageOptions::Declare(OptionTable* table) {
  table
      ->Path("session", &session,
             "a capture session of `procam capture --sequence photometric --channels rgb`")
      .Positional()
      .Required()
      .Path("out", &out, "the rig directory: photometric.json, result.json")
      .Required()
      .Number("min-contrast", &options.min_contrast, OptionTable::Interval::BelowMax(0.0, 1.0), "",
              "pixels used: brightening from black by at least this fraction of the largest")
      .Integer("table-size", &options.table_size, 2, 4096, "",
               "entries of the response table (lut)")
      .Text("projector", &projector, "merge the fit into RIG_DIR/rig.json's projector of this name")
      .Text("scene", &scene,
            "scene file: black and max in the scene's units and per-patch reflectance (needs the "
            "rig's camera registration and the projector's model)")
      .Integer("patches", &patches, 0, std::numeric_limits<int>::max(), "",
               "patch target for the scene (0: the scene's)")
      .Text("camera-scale", &camera_scale,
            "camera value per unit exitance in the scene's units: a number, R,G,B, or the "
            "synthetic camera's URI (its exposure and gain from session.json)")
      .OptionalNumber("camera-black", &camera_black, OptionTable::Interval::Closed(0.0, 1e9), "DN",
                      "camera black level, subtracted before the fit (default 0, or the synthetic "
                      "URI's black)")
      .Choice<std::string>("response", &response, {{"gamma", "gamma"}, {"lut", "lut"}},
                           "what rig.json gets: a gamma or the response table");
}

bool PhotometricStageOptions::Check(std::string* why) const {
  auto fail = [&](const std::string& message) {
    *why = message;
    return false;
  };
  if (!CheckDeclared(*this, why)) return false;
  if (!(clip > 0.0 && clip <= 1.0)) return fail("clip: must be in (0, 1]");
  if (min_patch_pixels < 1) return fail("min_patch_pixels: must be >= 1");
  return options.Check(why);
}

PhotometricModel RunPhotometricStage(const PhotometricStageOptions& args) {
  std::string why;
  if (!args.Check(&why)) throw std::invalid_argument(why);
  const std::filesystem::path session_dir(args.session);
  const PhotometricSession session = ReadPhotometricSession(session_dir);
  // rig.json and scene units, checked before anything is fitted.
  PhotometricRigStage rig_stage(args, args.out, session_dir, session.fields[0].image.size(),
                                session.hdr, session.full_scale);

  // Pixels: those that brighten enough (PhotometricCalibrationOptions::mask's default rule)
  // among those no field clips (a clipped pixel bends the response).
  PhotometricCalibrationOptions options = args.options;
  const cv::Size size = session.fields[0].image.size();
  cv::Mat unclipped(size, CV_8UC1, cv::Scalar(255));
  int black = -1, brightest = -1;
  for (size_t f = 0; f < session.fields.size(); ++f) {
    const cv::Mat& image = session.fields[f].image;
    if (image.size() != size) {
      throw IoError((session_dir / "session.json").string() + ": pattern " + session.names[f] +
                    " differs in size from " + session.names[0]);
    }
    if (session.full_scale > 0.0) {
      cv::Mat low;
      cv::inRange(image, cv::Scalar::all(-1e30), cv::Scalar::all(args.clip * session.full_scale),
                  low);
      unclipped &= low;
    }
    const Eigen::Vector3d& d = session.fields[f].drive;
    if (d.isZero()) black = static_cast<int>(f);
    if ((d.array() == 1.0).all() || (brightest < 0 && d == Eigen::Vector3d(0, 1, 0))) {
      brightest = static_cast<int>(f);
    }
  }
  const int clipped = size.area() - cv::countNonZero(unclipped);
  if (black >= 0 && brightest >= 0) {
    cv::Mat increase;
    cv::transform(session.fields[brightest].image - session.fields[black].image, increase,
                  cv::Matx13f(1, 1, 1));
    double largest = 0.0;
    cv::minMaxLoc(increase, nullptr, &largest, nullptr, nullptr, unclipped);
    options.mask = (increase > options.min_contrast * largest) & unclipped;
  }
  rig_stage.Configure(&options);
  PhotometricModel model;
  try {
    model = CalibratePhotometry(session.fields, options);
  } catch (const std::invalid_argument& error) {
    throw IoError((session_dir / "session.json").string() + ": " + error.what());
  }
  Report(args.progress, fmt::format("{} flat fields, {} camera pixels used ({} clipped left out)",
                                    session.fields.size(), model.pixels, clipped));
  Report(args.progress, model.BriefReport());

  const std::string units = session.hdr
                                ? "camera units: the HDR merge's full scale per second"
                                : "camera units: mean digital numbers at the session's exposure";
  const std::string note =
      "no camera-to-output factor (transfer) was applied: black and max are in camera units, "
      "relative to this camera, its exposure and where it looks; gamma, lut, mixing and the "
      "ratio black/max are absolute";
  nlohmann::json photometric;
  photometric["units"] = units;
  photometric["note"] = note;
  photometric["black"] = JsonTriple(model.black);
  photometric["max"] = JsonTriple(model.max);
  photometric["gamma"] = JsonTriple(model.gamma);
  photometric["gamma_rms"] = JsonTriple(model.gamma_rms);
  photometric["lut"] = {model.table[0], model.table[1], model.table[2]};
  photometric["mixing"] = nlohmann::json::array();
  for (int i = 0; i < 3; ++i) {
    photometric["mixing"].push_back({model.mixing(i, 0), model.mixing(i, 1), model.mixing(i, 2)});
  }

  nlohmann::json result;
  result["session"] = session_dir.string();
  result["units"] = units;
  result["note"] = note;
  result["levels"] = session.levels;
  result["channels"] = session.channels;
  result["fields"] = session.names;
  result["pixels_used"] = model.pixels;
  result["pixels_clipped"] = clipped;
  result["min_contrast"] = options.min_contrast;
  result["black_over_max"] = JsonTriple(model.black.cwiseQuotient(model.max));
  nlohmann::json channels = nlohmann::json::array();
  for (int c = 0; c < 3; ++c) {
    nlohmann::json samples = nlohmann::json::array();
    for (const Eigen::Vector2d& s : model.samples[c]) samples.push_back({s[0], s[1]});
    channels.push_back({{"channel", std::string(1, "rgb"[c])},
                        {"gamma", model.gamma[c]},
                        {"gamma_rms", model.gamma_rms[c]},
                        {"samples_drive_light", samples}});
  }
  result["channels_fit"] = channels;
  result["photometric"] = photometric;
  rig_stage.Prepare(model, session.fields, options.mask, &photometric, &result);
  result["photometric"] = photometric;

  const std::filesystem::path out(args.out);
  std::filesystem::create_directories(out);
  // One projector's photometry per file when it is named (a rig has several).
  const std::string name = args.projector.empty() ? "projector" : args.projector;
  const std::filesystem::path model_file =
      out / (args.projector.empty() ? "photometric.json" : name + ".photometric.json");
  WriteFileAtomically(model_file, photometric.dump(2) + "\n");
  UpdateRigResult(out, {"photometric", name}, result);
  rig_stage.Commit();
  Report(args.progress, "wrote " + model_file.string() + " and " + (out / "result.json").string() +
                            " (section photometric." + name + ")");
  return model;
}

}  // namespace procam
