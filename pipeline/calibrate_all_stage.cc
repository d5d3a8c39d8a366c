#include "pipeline/calibrate_all_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>

#include "base/io.h"
#include "base/json_fields.h"
#include "base/stop.h"
#include "capture/session.h"
#include "capture/simulated_camera.h"
#include "compensation/unit_light.h"
#include "geometry/patches.h"
#include "geometry/stage.h"
#include "pipeline/camera_stage.h"
#include "pipeline/capture_stage.h"
#include "pipeline/photometric_stage.h"
#include "pipeline/projectors_stage.h"
#include "projection/camera_rays.h"
#include "projection/photometric_transfer.h"
#include "projection/projection_rig.h"
#include "projection/rig_directory.h"

namespace procam {
namespace {

std::string Join(const std::vector<std::string>& items, const char* separator) {
  std::string text;
  for (size_t k = 0; k < items.size(); ++k) text += (k ? separator : "") + items[k];
  return text;
}

// `argument` as a shell reads it back: in single quotes when it holds anything but letters,
// digits and _ . / : = , @ % + - (a camera URI's ? and &).
std::string ShellWord(const std::string& argument) {
  const bool plain = !argument.empty() && std::all_of(argument.begin(), argument.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) ||
           (c != '\0' && std::strchr("_./:=,@%+-", c) != nullptr);
  });
  if (plain) return argument;
  std::string quoted = "'";
  for (char c : argument) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// A step as the command a user would type for it: `command` and the step's options as they
// differ from the defaults (each stage's option table, ChangedArgumentsOf).
template <typename Options>
void ShowCommand(const ProgressCallback& progress, const std::string& command,
                 const Options& options) {
  std::string line = "\n$ procam " + command;
  for (const std::string& argument : ChangedArgumentsOf(options)) {
    line += ' ';
    line += ShellWord(argument);
  }
  Report(progress, line);
}

// Where a stop leaves the rig, and how to go on.
constexpr const char* kKeptAndResume =
    "every file written so far is kept; run the same command again to resume (complete captures "
    "are kept, the fits are redone)";

// Throws Stopped naming `where` when args.stop is set.
void ThrowIfStopped(const CalibrateAllOptions& args, const std::string& where) {
  if (args.stop != nullptr && args.stop->load())
    throw Stopped("calibrate all: stopped by a signal " + where + "; " + kKeptAndResume);
}

// A capture that ended at a stop: where, and the patterns its session keeps.
void ThrowIfCaptureStopped(const CaptureStageOptions& capture, const CaptureSummary& summary,
                           const std::string& what) {
  if (!summary.stopped) return;
  throw Stopped(fmt::format(
      "calibrate all: stopped by a signal in step 2/4, the {} ({} of {} patterns kept in {}); {}",
      what, summary.patterns_before + summary.patterns_captured, summary.patterns_total,
      capture.out.string(), kKeptAndResume));
}

// What the steps share, resolved from the options and the simulated world (if any).
struct RigPlan {
  std::optional<SimulatedCamera> simulated;
  std::vector<std::string> names;
  std::string scene;  // scanning: RIG_DIR/room.json, once step 3 has written it
  bool scan = false;
  int patches = 0;
  std::filesystem::path captures;
  std::vector<std::shared_ptr<PatternDisplay>> displays;  // one per projector
};

RigPlan Plan(const CalibrateAllOptions& args) {
  // An option as messages write it, named from its declaration (OptionTable::FlagOf).
  const auto flag = [&args](const auto& field) { return FlagOf(args, &field); };
  RigPlan plan;
  plan.simulated = FindSimulatedCamera(args.camera);
  const bool simulated = plan.simulated.has_value();
  const size_t count = simulated ? plan.simulated->displays.size() : args.display_names.size();
  if (count == 0) {
    throw std::invalid_argument(flag(args.display_names) +
                                ": a real rig needs one per projector, e.g. " +
                                flag(args.display_names) + " glfw:1,glfw:2 (procam show --list)");
  }
  if (simulated && !args.display_names.empty()) {
    throw std::invalid_argument(flag(args.display_names) +
                                ": a synthetic camera looks at its own projectors");
  }
  plan.names = args.names;
  if (plan.names.empty()) {
    for (size_t k = 0; k < count; ++k) {
      plan.names.push_back(simulated ? ProjectorNameFrom(plan.simulated->projector_names[k])
                                     : fmt::format("projector{}", k));
    }
  }
  if (plan.names.size() != count) {
    throw std::invalid_argument(flag(args.names) + ": " + std::to_string(plan.names.size()) +
                                " names for " + std::to_string(count) + " projectors");
  }
  for (const std::string& name : plan.names) {
    if (!ValidProjectorName(name))
      throw std::invalid_argument(flag(args.names) + ": '" + name +
                                  "': a projector's name takes letters, digits, '_', '-' and '.'");
  }
  plan.scene = args.scene;
  plan.scan = args.scan || (plan.scene.empty() && !simulated);
  for (const auto& [name, file] : args.held_lenses) {
    if (std::find(plan.names.begin(), plan.names.end(), name) == plan.names.end())
      throw std::invalid_argument(flag(args.held_lenses) + " " + name + "=" + file.string() +
                                  ": no projector is named '" + name +
                                  "' (projectors: " + Join(plan.names, ", ") + ")");
    if (!std::filesystem::is_regular_file(file))
      throw IoError(file.string() + ": file not found (" + flag(args.held_lenses) + " " + name +
                    ")");
  }
  if (plan.scan) {
    if (!plan.scene.empty())
      throw std::invalid_argument(flag(args.scan) + ": not with " + flag(args.scene) +
                                  " (scan the room, or register a model)");
    if (!args.camera_guess.empty())
      throw std::invalid_argument(flag(args.camera_guess) + ": only with " + flag(args.scene) +
                                  " (a scan needs no guess)");
    if (args.floor_chessboard.empty() && !(args.camera_height > 0.0) && !simulated)
      throw std::invalid_argument(
          flag(args.floor_chessboard) +
          ": required to scan the room: a photo of the chessboard lying flat on the floor, taken "
          "by the camera from where it stands (or " +
          flag(args.camera_height) + ", metres)");
    if (!args.floor_chessboard.empty() && !std::filesystem::is_regular_file(args.floor_chessboard))
      throw IoError(args.floor_chessboard.string() + ": file not found (" +
                    flag(args.floor_chessboard) + ")");
    plan.scene = (args.out / "room.json").string();
  } else if (plan.scene.empty()) {
    plan.scene = plan.simulated->scene;
  }
  plan.patches = args.patches > 0 ? args.patches : simulated ? plan.simulated->patches : 0;
  if (args.camera_model.empty() && args.chessboard.empty() && !simulated) {
    throw std::invalid_argument(flag(args.chessboard) +
                                ": a real camera needs chessboard photos (" +
                                flag(args.chessboard) + " DIR) or a calibrated model (" +
                                flag(args.camera_model) + " FILE)");
  }
  if (!args.camera_model.empty() && !std::filesystem::exists(args.camera_model))
    throw IoError(args.camera_model.string() + ": file not found (" + flag(args.camera_model) +
                  ")");
  if (args.camera_scale.empty() && !simulated) {
    throw std::invalid_argument(flag(args.camera_scale) +
                                ": required for a real camera (camera value per unit exitance, "
                                "docs/calibration.md)");
  }
  plan.captures = args.out / "captures";
  if (!simulated) {  // checked: now the monitors are opened
    if (!args.open_display) throw std::invalid_argument("open_display: required for a real rig");
    for (const std::string& name : args.display_names)
      plan.displays.push_back(args.open_display(name));
  } else {
    plan.displays = plan.simulated->displays;
  }
  return plan;
}

// 1. Camera intrinsics.
void CalibrateCameraStep(const CalibrateAllOptions& args, const RigPlan& plan) {
  Report(args.progress, "\n== 1/4 camera intrinsics");
  if (!args.camera_model.empty()) {
    std::filesystem::copy_file(args.camera_model, args.out / "camera.cameramodel",
                               std::filesystem::copy_options::overwrite_existing);
    UpdateRigFile(args.out, [](RigFile& rig) { rig.camera.model = "camera.cameramodel"; });
    Report(args.progress, "camera model from " + args.camera_model.string());
    return;
  }
  CameraStageOptions camera;
  camera.images = args.chessboard;
  camera.out = args.out;
  camera.board = args.board;
  camera.progress = args.progress;
  if (camera.images.empty()) {  // a simulated camera photographs a simulated board
    camera.board.square_size = 0.06;
    camera.images = plan.captures / "chessboard";
    const int photos = plan.simulated->render_chessboard(
        camera.board.corners_x, camera.board.corners_y, camera.board.square_size, camera.images);
    Report(args.progress,
           fmt::format("rendered {} chessboard photos of the synthetic camera into {}", photos,
                       camera.images.string()));
  }
  ShowCommand(args.progress, "calibrate camera", camera);
  RunCameraStage(camera);
}

// 2. Captures, per projector: structured light, then flat fields.
std::vector<std::filesystem::path> CaptureStep(const CalibrateAllOptions& args,
                                               const RigPlan& plan) {
  Report(args.progress, "\n== 2/4 structured light and flat fields, per projector");
  std::vector<std::filesystem::path> sessions;
  for (size_t k = 0; k < plan.names.size(); ++k) {
    CaptureStageOptions capture;
    capture.camera = args.camera;
    capture.sequencer.frames_per_pattern = args.frames;
    capture.sequencer.settle_ms = args.settle_ms;
    capture.measure_latency = args.measure_settle;
    capture.sequencer.grab_timeout_ms = args.grab_timeout_ms;
    capture.latency.grab_timeout_ms = args.grab_timeout_ms;
    capture.sequencer.exposures_us = args.exposures_us;
    capture.progress = args.progress;
    if (plan.simulated) {
      capture.projector = static_cast<int>(k);
    } else {
      capture.display = plan.displays[k];
      capture.display_name = args.display_names[k];
    }
    capture.sequence = "structured_light";
    capture.out = plan.captures / ("structured_light_" + plan.names[k]);
    capture.stop = args.stop;
    ThrowIfStopped(args, "before the structured light of projector '" + plan.names[k] + "'");
    ShowCommand(args.progress, "capture", capture);
    const CaptureSummary structured = RunCaptureStage(capture);
    ThrowIfCaptureStopped(capture, structured,
                          "structured light of projector '" + plan.names[k] + "'");
    Report(args.progress, CaptureLine(capture, structured));
    sessions.push_back(capture.out);

    // The flat fields settle as the structured light did (measured once per projector).
    capture.measure_latency = false;
    capture.sequencer.settle_ms = structured.settle_ms;
    capture.sequence = "photometric";
    capture.levels = args.levels;
    capture.channels = "rgb";
    capture.out = plan.captures / ("photometric_" + plan.names[k]);
    ThrowIfStopped(args, "before the flat fields of projector '" + plan.names[k] + "'");
    ShowCommand(args.progress, "capture", capture);
    const CaptureSummary flat = RunCaptureStage(capture);
    ThrowIfCaptureStopped(capture, flat, "flat fields of projector '" + plan.names[k] + "'");
    Report(args.progress, CaptureLine(capture, flat));
    // The projector goes dark again, so its last flat field does not light the next one's
    // captures (on a real rig: every projector but the one being captured must show black).
    const std::shared_ptr<PatternDisplay>& display = plan.displays[k];
    display->Show(cv::Mat(display->Resolution(), CV_8UC3, cv::Scalar::all(0)));
  }
  return sessions;
}

// 3. Geometry: every projector and the camera's pose in the room, jointly.
void ProjectorsStep(const CalibrateAllOptions& args, const RigPlan& plan,
                    const std::vector<std::filesystem::path>& sessions) {
  Report(args.progress, "\n== 3/4 projectors and registration");
  ProjectorsStageOptions projectors;
  projectors.sessions = sessions;
  projectors.out = args.out;
  projectors.names = plan.names;
  projectors.held_lenses = args.held_lenses;
  projectors.progress = args.progress;
  if (plan.scan) {
    projectors.board = args.board;
    projectors.board_thickness = args.board_thickness;
    if (plan.patches > 0) projectors.scan.target_patches = plan.patches;
    projectors.floor_chessboard = args.floor_chessboard;
    if (args.camera_height > 0.0 && args.floor_chessboard.empty()) {
      projectors.camera_height = args.camera_height;
    } else if (projectors.floor_chessboard.empty()) {  // a simulated camera photographs its floor
      projectors.floor_chessboard = plan.captures / "floor_chessboard.png";
      projectors.board.square_size = plan.simulated->render_floor_chessboard(
          projectors.board.corners_x, projectors.board.corners_y, projectors.floor_chessboard);
      Report(args.progress, "rendered the synthetic camera's photo of a chessboard on the floor: " +
                                projectors.floor_chessboard.string());
    }
    ShowCommand(args.progress, "calibrate projectors", projectors);
    RunProjectorsStage(projectors);
    return;
  }
  projectors.scene = plan.scene;
  projectors.camera_guess = args.camera_guess;
  if (projectors.camera_guess.empty() && plan.simulated)
    projectors.camera_guess = plan.simulated->camera_guess;
  ShowCommand(args.progress, "calibrate projectors", projectors);
  RunProjectorsStage(projectors);
}

// 4. Photometry in the scene's units and per-patch reflectance.
void PhotometryStep(const CalibrateAllOptions& args, const RigPlan& plan) {
  Report(args.progress, "\n== 4/4 photometry, per projector");
  const std::string camera_scale = args.camera_scale.empty() ? args.camera : args.camera_scale;
  for (const std::string& name : plan.names) {
    PhotometricStageOptions photometric;
    photometric.session = plan.captures / ("photometric_" + name);
    photometric.out = args.out;
    photometric.projector = name;
    photometric.scene = plan.scene;
    photometric.camera_scale = camera_scale;
    photometric.patches = plan.patches;
    photometric.progress = args.progress;
    ShowCommand(args.progress, "calibrate photometric", photometric);
    RunPhotometricStage(photometric);
  }
}

// A scanned room's surfaces take the photometry's reflectance: per surface, the area-weighted
// mean over the patches the camera saw (reflectance.npy keeps a patch's nominal value, exactly,
// where too few pixels saw it), written into the room file; the unseen patches in
// reflectance.npy take their surface's mean instead of the nominal. A surface no pixel saw keeps
// the nominal.
void ReflectanceIntoScannedRoom(const std::filesystem::path& out, const std::string& room_path,
                                int patches, const ProgressCallback& progress) {
  const RigDirectory rig = ReadRigDirectory(out);
  if (rig.reflectance.rows() == 0) return;
  Scene scene = LoadScene(room_path);
  if (patches > 0) scene.target_patches = patches;
  SubdivisionOptions subdivision;
  subdivision.target_patches = scene.target_patches;
  const PatchHierarchy hierarchy = SubdividePatches(scene, subdivision);
  const PatchLevel& fine = hierarchy.fine;
  if (fine.size() != rig.reflectance.rows())
    throw IoError(fmt::format("{}: {} rows, but {} subdivides into {} patches",
                              (out / "reflectance.npy").string(), rig.reflectance.rows(), room_path,
                              fine.size()));
  const Eigen::VectorXd area = fine.Areas();
  const size_t surfaces = scene.surfaces.size();
  std::vector<Vec3> sum(surfaces, Vec3::Zero());
  std::vector<double> weight(surfaces, 0.0);
  std::vector<bool> seen(fine.size(), false);
  for (int i = 0; i < fine.size(); ++i) {
    const int s = fine.patches[i].surface;
    const Vec3 rho = rig.reflectance.row(i).transpose();
    if (rho == scene.surfaces[s].reflectance) continue;  // the nominal: not seen
    seen[i] = true;
    sum[s] += area[i] * rho;
    weight[s] += area[i];
  }
  nlohmann::json room = nlohmann::json::parse(ReadFile(room_path));
  std::vector<Vec3> mean(surfaces);  // nominal where not seen
  std::string line = "reflectance per scanned surface (mean over the patches the camera saw):";
  for (size_t s = 0; s < surfaces; ++s) {
    mean[s] = weight[s] > 0.0 ? Vec3(sum[s] / weight[s]) : scene.surfaces[s].reflectance;
    if (!(weight[s] > 0.0)) {
      line += fmt::format(" {} not seen (nominal kept);", scene.surfaces[s].name);
      continue;
    }
    for (nlohmann::json& entry : room["surfaces"])
      if (entry["name"] == scene.surfaces[s].name) entry["reflectance"] = JsonTriple(mean[s]);
    line += fmt::format(" {} ({:.3f}, {:.3f}, {:.3f});", scene.surfaces[s].name, mean[s].x(),
                        mean[s].y(), mean[s].z());
  }
  line.back() = '.';
  RowMatrixXd per_patch = rig.reflectance;
  for (int i = 0; i < fine.size(); ++i)
    if (!seen[i]) per_patch.row(i) = mean[fine.patches[i].surface].transpose();
  WriteNpy(out / "reflectance.npy", per_patch);
  WriteFileAtomically(room_path, room.dump(2) + "\n");
  Report(progress, line);
}

// Every photometric session's black field shows all projectors at black, so each projector's
// fitted black is the sum of all of them there. Separates them (SeparateBlackLevels) and moves
// each max by the same amount (the fit's max − black is unbiased), in rig.json and in a
// `black_levels` section of result.json.
void SeparateProjectorBlacks(const std::filesystem::path& out,
                             const std::vector<std::string>& names,
                             const std::filesystem::path& captures, const std::string& scene,
                             int patches, const ProgressCallback& progress) {
  Report(progress, "\n== black levels, jointly");
  const RigDirectory rig = ReadRigDirectory(out);
  const ProjectorGeometry camera = ReadCameraModel(out / "camera.cameramodel");
  GeometryOptions geometry;
  geometry.patches = patches;
  geometry.progress = progress;
  const GeometryStage stage = RunGeometryStage(scene, geometry);
  std::vector<cv::Mat> transfers;
  cv::Mat black_field;
  int black_fields = 0;
  double camera_black = 0.0;
  for (const std::string& name : names) {
    const auto projector = std::find_if(rig.projectors.begin(), rig.projectors.end(),
                                        [&](const Projector& p) { return p.name == name; });
    if (projector == rig.projectors.end())
      throw IoError((out / "rig.json").string() + ": no projector " + name);
    // Written by step 4 for every projector.
    const auto photometry = rig.file.photometric.find(name);
    if (photometry == rig.file.photometric.end() || !photometry->second.camera_scale) {
      throw IoError((out / "rig.json").string() + ": photometric." + name +
                    ".camera_scale: missing (calibrate photometric --scene did not run for it)");
    }
    const Eigen::Vector3d scale = *photometry->second.camera_scale;
    camera_black = photometry->second.camera_black;
    const CameraPixelLighting lighting =
        LightCameraPixels(stage.scene, stage.patches.fine, projector->geometry, camera);
    const UnitLightModel model = ModelUnitLight(stage.patches.fine, stage.form_factors,
                                                UnitLightExitance(stage.patches.fine, *projector));
    transfers.push_back(PhotometricTransfer(lighting, stage.patches.fine, model, scale));
    // The session's black fields (drive 0 on any channel): every projector dark.
    const CaptureSessionData session = CaptureSessionData::Load(captures / ("photometric_" + name));
    if (!session.Hdr(0).empty()) {
      Report(progress, "HDR sessions: black levels left as fitted (not separated)");
      return;
    }
    for (int p = 0; p < session.pattern_count(); ++p) {
      const nlohmann::json& info =
          session.manifest()["patterns"][p].value("info", nlohmann::json());
      if (!info.is_object() || info.value("kind", "") != "flat" || info.value("level", -1) != 0)
        continue;
      const cv::Mat mean = session.Mean(p, 0);
      if (black_field.empty()) black_field = cv::Mat::zeros(mean.size(), CV_32FC3);
      black_field += mean;
      ++black_fields;
    }
  }
  if (black_fields == 0) {
    Report(progress, "no black fields: black levels left as fitted");
    return;
  }
  black_field /= black_fields;
  const std::vector<Eigen::Vector3d> black =
      SeparateBlackLevels(transfers, black_field, camera_black);
  nlohmann::json report = nlohmann::json::object();
  UpdateRigFile(out, [&](RigFile& file) {
    for (size_t j = 0; j < names.size(); ++j) {
      RigProjector& entry = file.Projector(names[j]);
      if (!entry.black || !entry.max) {
        throw IoError((out / "rig.json").string() + ": projectors: '" + names[j] +
                      "' has no black and max (calibrate photometric --scene did not run for it)");
      }
      const Eigen::Vector3d fitted_black = *entry.black, fitted_max = *entry.max;
      const Eigen::Vector3d new_black = black[j].cwiseMax(0.0);
      const Eigen::Vector3d new_max = fitted_max - (fitted_black - black[j]);
      report[names[j]] = {{"fitted_black", JsonTriple(fitted_black)},
                          {"black", JsonTriple(new_black)},
                          {"max", JsonTriple(new_max)}};
      Report(
          progress,
          fmt::format("{}: black ({:.5f}, {:.5f}, {:.5f}) (fitted alone: {:.5f}, {:.5f}, {:.5f})",
                      names[j], new_black[0], new_black[1], new_black[2], fitted_black[0],
                      fitted_black[1], fitted_black[2]));
      entry.black = new_black;
      entry.max = new_max;
    }
  });
  UpdateRigResult(
      out, {"black_levels"},
      {{"what",
        "each projector's black separated from the black fields (all projectors dark) "
        "by least squares over the projectors' transfers; max moved by the same amount"},
       {"black_fields", black_fields},
       {"projectors", report}});
}

}  // namespace

void CalibrateAllOptions::Declare(OptionTable* table) {
  table
      ->Text("camera", &camera,
             "camera URI (v4l2:..., aravis:..., synthetic:SCENE for the simulated rig)")
      .Required()
      .Text("scene", &scene,
            "the room model (scene JSON, or synthetic:NAME); without it a real camera scans the "
            "room into RIG_DIR/room.json; a synthetic camera uses its own scene unless --scan")
      .Flag("scan", &scan,
            "scan the room (no room model, no camera guess): poses and projector lenses from the "
            "structured light, the room written as RIG_DIR/room.json")
      .Path("floor-chessboard", &floor_chessboard,
            "scanning: a photo of the chessboard lying flat on the floor, taken by the camera "
            "from where it stands: the scan's metric scale (a synthetic camera takes its own)")
      .Number("camera-height", &camera_height, 0.0, 1e3, "m",
              "scanning: the camera's height above the floor, instead of a floor chessboard (0: "
              "none)")
      .Number("board-thickness", &board_thickness, 0.0, 1.0, "m",
              "scanning: height of the floor chessboard's printed face above the floor")
      .Path("out", &out, "the rig directory")
      .Required()
      .Integer("patches", &patches, 0, std::numeric_limits<int>::max(), "",
               "patch target the per-patch reflectance is estimated for (0: the scene's; "
               "synthetic: the camera's patches)")
      .Path("chessboard", &chessboard,
            "chessboard photos of the camera (a folder or a capture session)")
      .Path("camera-model", &camera_model, "a calibrated camera.cameramodel instead of photos");
  board.Declare(table);
  table
      ->Texts("display", &display_names,
              "real rigs: each projector's monitor, in order (glfw:N|NAME)")
      .Texts("names", &names, "projector names");
  DeclareHeldLenses(table, &held_lenses,
                    "hold projector NAME's lens from FILE (a .cameramodel, e.g. `procam calibrate "
                    "board`'s) and solve only its pose in the room (with a room model, or "
                    "scanning)");
  table
      ->Text("camera-guess", &camera_guess,
             "camera position and a point it looks at, x,y,z,look_x,look_y,look_z (scene frame, "
             "metres); a synthetic camera's is guessed from its placement")
      .Text("camera-scale", &camera_scale,
            "camera value per unit exitance (number or R,G,B; default for a synthetic camera: "
            "from its URI)")
      .Integer("frames", &frames, 1, 1000, "", "frames averaged per pattern");
  DeclareSettleOption(table, &settle_ms, &measure_settle);
  table
      ->Number("timeout-ms", &grab_timeout_ms, 1.0, 600000.0, "ms",
               "grab timeout per frame (a camera that delivers nothing for this long is retried, "
               "then the capture stops with one line; run the same command again to resume)")
      .Numbers("exposure-us", &exposures_us, OptionTable::Interval::AboveMin(0.0, 1e8), "µs",
               "exposure(s); several bracket and merge to HDR")
      .Integers("levels", &levels, 0, 255, "", "photometric drive levels");
}

bool CalibrateAllOptions::Check(std::string* why) const {
  return CheckDeclared(*this, why) && board.Check(why);
}

void RunCalibrateAll(const CalibrateAllOptions& args) {
  std::string why;
  if (!args.Check(&why)) throw std::invalid_argument(why);
  const RigPlan plan = Plan(args);
  std::filesystem::create_directories(plan.captures);
  Report(args.progress,
         fmt::format("calibrating {} projector(s) ({}) with camera {} into {}", plan.names.size(),
                     Join(plan.names, ", "), args.camera, args.out.string()));
  // Each step runs whole or is abandoned at a stop: a computation inside it cut short (Stopped)
  // is said with the step's name; a stop between steps begins no further one.
  const auto step = [&](const std::string& name, const std::function<void()>& run) {
    ThrowIfStopped(args, "before " + name);
    try {
      run();
    } catch (const Stopped& stopped) {
      const std::string what = stopped.what();
      if (what.starts_with("calibrate all: ")) throw;
      throw Stopped("calibrate all: stopped by a signal in " + name + " (" + what + "); " +
                    kKeptAndResume);
    }
  };
  step("step 1/4, the camera intrinsics", [&] { CalibrateCameraStep(args, plan); });
  std::vector<std::filesystem::path> sessions;
  step("step 2/4, the captures", [&] { sessions = CaptureStep(args, plan); });
  step("step 3/4, the projectors and the registration",
       [&] { ProjectorsStep(args, plan, sessions); });
  step("step 4/4, the photometry", [&] { PhotometryStep(args, plan); });
  step("the black levels", [&] {
    SeparateProjectorBlacks(args.out, plan.names, plan.captures, plan.scene, plan.patches,
                            args.progress);
  });
  if (plan.scan) {
    step("the scanned room's reflectance",
         [&] { ReflectanceIntoScannedRoom(args.out, plan.scene, plan.patches, args.progress); });
  }
  Report(args.progress,
         fmt::format(
             "\nrig calibrated: {} (rig.json, camera.cameramodel, {}, reflectance.npy{}); use "
             "it with `procam compensate {} --rig {}`",
             args.out.string(), Join(plan.names, ".cameramodel, ").append(".cameramodel"),
             plan.scan ? ", room.json: the scanned room; give its surfaces their desired colours "
                         "by name (docs/scan.md)"
                       : "",
             plan.scan ? plan.scene : std::string("SCENE"), args.out.string()));
}

}  // namespace procam
