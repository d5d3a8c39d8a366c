#include "pipeline/projectors_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <stdexcept>

#include "base/camera_model.h"
#include "base/io.h"
#include "base/json_fields.h"
#include "base/parse.h"
#include "calibration/camera_report.h"
#include "calibration/capture_layout.h"
#include "calibration/floor_chessboard.h"
#include "calibration/structured_light.h"
#include "capture/session.h"
#include "geometry/stage.h"
#include "projection/projector.h"
#include "projection/rig_directory.h"

namespace procam {
namespace {

// The scan's own view of the solve: triangulated points registered to the model, and planes.
struct ScanCheck {
  DistanceStats gap;  // ray gaps of the triangulation
  Eigen::Isometry3d registered = Eigen::Isometry3d::Identity();
  bool registered_ok = false;
  RegistrationSummary registration;
  double icp_vs_joint_mm = 0, icp_vs_joint_deg = 0;
  std::vector<FittedPlane> planes;
};

ScanCheck CheckAgainstScan(const RoomCalibrationProblem& problem,
                           const RoomCalibration& calibration, const RoomModel& model,
                           const Eigen::Isometry3d& guess, const ProgressCallback& progress);
void WriteProjectorsOutputs(const ProjectorsStageOptions& args, const CameraModel& camera,
                            const Eigen::Isometry3d& guess, const std::string& guess_source,
                            const Scene& scene, const RoomCalibrationProblem& problem,
                            const ProjectorsStageSummary& stage, const ScanCheck& check);

// Decoded correspondences of one structured-light session.
ProjectorObservations ReadSession(const std::filesystem::path& directory, int camera_width,
                                  int camera_height, const std::filesystem::path& camera_model,
                                  std::string name, const ProgressCallback& progress) {
  const StructuredLightSession session = ReadStructuredLightSession(directory, /*both_axes=*/true);
  const std::string manifest = (directory / "session.json").string();
  const StructuredLightLayout& layout = session.layout;
  const cv::Mat& first = session.images.front();
  if (first.cols != camera_width || first.rows != camera_height)
    throw IoError(manifest + ": its photos are " + std::to_string(first.cols) + "x" +
                  std::to_string(first.rows) + ", " + camera_model.string() + " is " +
                  std::to_string(camera_width) + "x" + std::to_string(camera_height));
  DecodeSummary decoded;
  try {
    decoded = DecodeSession(session);
  } catch (const IoError& error) {
    throw IoError(manifest + ": " + error.what());
  }
  const StructuredLightMap& map = decoded.map;
  // The decode's picture and numbers beside the session, for people to look at; a session on a
  // read-only disk is still calibrated.
  try {
    WriteDecodeReport(decoded, directory / "decode");
  } catch (const IoError& error) {
    Report(progress, std::string("decode picture not written: ") + error.what());
  }
  if (name.empty()) {
    // The display's name, after its last '/' ("synthetic:tiny_box/left" → "left").
    const std::string& display = session.display_name;
    name = display.substr(
        display.find_last_of("/:") == std::string::npos ? 0 : display.find_last_of("/:") + 1);
  }
  const ProjectorObservations out = ObservationsFromMap(map, name, layout.width, layout.height);
  Report(progress,
         fmt::format("{}: {}x{} projector, {} camera pixels decoded, {} more on one axis alone "
                     "(refused on some axis: {} shadowed, {} ambiguous, {} weak phase, {} out of "
                     "range)",
                     directory.string(), layout.width, layout.height, out.camera_pixels.size(),
                     out.one_axis_camera_pixels.size(), map.shadowed, map.ambiguous, map.weak_phase,
                     map.out_of_range));
  return out;
}

// Every session's decoded correspondences, with the camera's lens.
RoomCalibrationProblem ReadProblem(const ProjectorsStageOptions& args, const CameraModel& camera,
                                   const std::filesystem::path& camera_path) {
  RoomCalibrationProblem problem;
  problem.camera_lens_model = camera.lens_model;
  problem.camera_intrinsics = camera.intrinsics;
  std::set<std::string> names;
  for (size_t k = 0; k < args.sessions.size(); ++k) {
    ProjectorObservations observations =
        ReadSession(args.sessions[k], camera.width, camera.height, camera_path,
                    args.names.empty() ? "" : args.names[k], args.progress);
    if (!args.names.empty() && !ValidProjectorName(args.names[k]))
      throw std::invalid_argument(FlagOf(args, &args.names) + ": '" + args.names[k] +
                                  "': a projector's name takes letters, digits, '_', '-' and '.'");
    if (!ValidProjectorName(observations.name)) observations.name = "projector" + std::to_string(k);
    if (!names.insert(observations.name).second)
      throw std::invalid_argument("projector name '" + observations.name + "' of " +
                                  args.sessions[k].string() + " is used twice (name them with " +
                                  FlagOf(args, &args.names) + ")");
    problem.projectors.push_back(std::move(observations));
  }

  return problem;
}

ProjectorsStageSummary ScanRoom(const ProjectorsStageOptions& args, const CameraModel& camera,
                                const RoomCalibrationProblem& problem);

// The held lenses' files (options.held_lenses), read and checked before any session is decoded:
// projector name → its lens. Throws IoError naming the file.
std::map<std::string, HeldProjectorLens> ReadHeldLenses(const ProjectorsStageOptions& args) {
  std::map<std::string, HeldProjectorLens> lenses;
  for (const auto& [name, path] : args.held_lenses) {
    if (!ValidProjectorName(name))
      throw std::invalid_argument(FlagOf(args, &args.held_lenses) + ": '" + name +
                                  "': a projector's name takes letters, digits, '_', '-' and '.'");
    const CameraModel model = ReadCameraModelFile(path);
    if (model.lens_model != "LENSMODEL_PINHOLE" && model.lens_model != "LENSMODEL_OPENCV4")
      throw IoError(path.string() + ": lensmodel " + model.lens_model +
                    ": a held projector lens must be LENSMODEL_PINHOLE or LENSMODEL_OPENCV4 "
                    "(calibrate board --lens-model LENSMODEL_OPENCV4, its default)");
    HeldProjectorLens lens;
    lens.lens_model = model.lens_model;
    lens.intrinsics = model.intrinsics;
    lens.source = path.string();
    // The size, checked against the session once it is read.
    lens.source_width = model.width;
    lens.source_height = model.height;
    lenses[name] = lens;
  }
  return lenses;
}

// Puts the held lenses into `problem` by projector name. Throws IoError naming the lens's file
// when its image size is not the session's projector's, std::invalid_argument for a name that no
// session has.
void HoldLenses(const std::map<std::string, HeldProjectorLens>& lenses,
                const ProjectorsStageOptions& args, RoomCalibrationProblem* problem) {
  const ProgressCallback& progress = args.progress;
  if (lenses.empty()) return;
  problem->held_projector_lenses.assign(problem->projectors.size(), HeldProjectorLens());
  for (const auto& [name, lens] : lenses) {
    std::string names;
    size_t k = 0;
    for (; k < problem->projectors.size() && problem->projectors[k].name != name; ++k)
      names += (names.empty() ? "" : ", ") + problem->projectors[k].name;
    if (k == problem->projectors.size())
      throw std::invalid_argument(FlagOf(args, &args.held_lenses) + " " + name + "=" + lens.source +
                                  ": no session's projector is named '" + name + "' (projectors: " +
                                  names + "; name them with " + FlagOf(args, &args.names) + ")");
    const ProjectorObservations& projector = problem->projectors[k];
    if (lens.source_width != projector.width || lens.source_height != projector.height)
      throw IoError(lens.source + ": imagersize " + std::to_string(lens.source_width) + "x" +
                    std::to_string(lens.source_height) + ", but projector '" + name + "' shows " +
                    std::to_string(projector.width) + "x" + std::to_string(projector.height) +
                    " patterns");
    problem->held_projector_lenses[k] = lens;
    Report(progress, fmt::format("projector {}: lens held from {} ({}, fx {:.2f}, fy {:.2f}, cx "
                                 "{:.2f}, cy {:.2f}); its pose alone is solved",
                                 name, lens.source, lens.lens_model, lens.intrinsics[0],
                                 lens.intrinsics[1], lens.intrinsics[2], lens.intrinsics[3]));
  }
}

// Scanning: the lens and its covariance as `calibrate camera` recorded them in RIG_DIR/result.json
// ("camera": intrinsics, intrinsics_covariance), the chessboard's even where camera.cameramodel
// already holds an earlier scan's refined lens, so that running the scan again starts from the
// same place. With --refine-camera (`required`) they are the lens's start and prior, and IoError
// names result.json without them (a camera model given with --camera-model has no chessboard
// solve); without it only the covariance is used, folded into the projectors' uncertainty, and
// its absence is reported, not an error. Returns whether they were read.
bool ChessboardLensPrior(const std::filesystem::path& rig_dir, const CameraModel& camera,
                         bool required, RoomCalibrationProblem* problem,
                         const ProgressCallback& progress) {
  const std::string file = (rig_dir / "result.json").string();
  const nlohmann::json camera_result =
      ReadRigResult(rig_dir).value("camera", nlohmann::json::object());
  const size_t n = camera.intrinsics.size();
  // Without the covariance: an error when it is required, else said and left out.
  const auto without = [&](const std::string& why, const std::string& error) {
    if (required) throw IoError(file + ": " + error);
    Report(progress, "camera lens: " + why + "; the projectors' uncertainty leaves the lens's out");
    return false;
  };
  if (!camera_result.contains("intrinsics_covariance"))
    return without("no chessboard covariance in " + file,
                   "camera.intrinsics_covariance: missing: --refine-camera while scanning needs "
                   "the chessboard's lens covariance (run `procam calibrate camera` into this rig "
                   "directory)");
  if (camera_result.value("lens_model", "") != camera.lens_model)
    return without(file + " holds another lens model's covariance",
                   "camera.lens_model: not camera.cameramodel's " + camera.lens_model);
  try {
    const auto intrinsics = camera_result.at("intrinsics").get<std::vector<double>>();
    const auto rows =
        camera_result.at("intrinsics_covariance").get<std::vector<std::vector<double>>>();
    if (intrinsics.size() != n || rows.size() != n)
      throw std::invalid_argument("not " + std::to_string(n) + " intrinsics");
    Eigen::MatrixXd covariance(n, n);
    for (size_t r = 0; r < n; ++r) {
      if (rows[r].size() != n) throw std::invalid_argument("a row of the wrong size");
      for (size_t c = 0; c < n; ++c) covariance(r, c) = rows[r][c];
    }
    problem->camera_intrinsics = intrinsics;
    problem->camera_intrinsics_covariance = covariance;
  } catch (const std::exception& error) {
    throw IoError(file + ": camera.intrinsics_covariance: " + error.what());
  }
  Report(progress, required
                       ? "camera lens: the chessboard's, refined by the scan with it as the prior"
                       : "camera lens: held; its chessboard covariance goes into the "
                         "projectors' uncertainty");
  return true;
}

}  // namespace

void DeclareHeldLenses(OptionTable* table,
                       std::map<std::string, std::filesystem::path>* held_lenses,
                       const std::string& help) {
  table
      ->List(
          "hold-lens",
          [held_lenses] {
            std::vector<std::string> items;
            for (const auto& [name, file] : *held_lenses)
              items.push_back(name + "=" + file.string());
            return items;
          },
          [held_lenses](const std::vector<std::string>& entries, std::string* why) {
            std::map<std::string, std::filesystem::path> lenses;
            for (const std::string& entry : entries) {
              const size_t equals = entry.find('=');
              if (equals == std::string::npos || equals == 0 || equals + 1 == entry.size()) {
                *why = "'" + entry + "': NAME=FILE, a projector's name and its .cameramodel";
                return false;
              }
              const std::string name = entry.substr(0, equals);
              if (!lenses.emplace(name, entry.substr(equals + 1)).second) {
                *why = "projector '" + name + "' given twice";
                return false;
              }
            }
            *held_lenses = std::move(lenses);
            return true;
          },
          "NAME=FILE, one per flag", help)
      .Repeated()
      .Sets(held_lenses);
}

void ProjectorsStageOptions::Declare(OptionTable* table) {
  table
      ->Paths("sessions", &sessions,
              "structured-light sessions of `procam capture --sequence structured_light`, one "
              "per projector")
      .Positional()
      .Required()
      .Text("scene", &scene,
            "scene JSON, or a synthetic scene name; without it the room is scanned")
      .Path("floor-chessboard", &floor_chessboard,
            "scanning: a photo of the chessboard lying flat on the floor, taken by the camera from "
            "where it stands (the scan's metric scale)")
      .OptionalNumber(
          "camera-height", &camera_height, OptionTable::Interval::AboveMin(0.0, 1e3), "m",
          "scanning: the camera's height above the floor, instead of a floor chessboard");
  board.Declare(table, "scanning: the floor chessboard's");
  table
      ->Number("board-thickness", &board_thickness, 0.0, 1.0, "m",
               "scanning: height of the board's printed face above the floor")
      .Integer("patches", &scan.target_patches, 1, std::numeric_limits<int>::max(), "",
               "scanning: patch target written into room.json")
      .Path("out", &out,
            "the rig directory holding camera.cameramodel; gets NAME.cameramodel, rig.json, "
            "result.json")
      .Required()
      .Text("camera-guess", &camera_guess,
            "camera position and a point it looks at, x,y,z,look_x,look_y,look_z (metres, scene "
            "frame; a few cm and degrees off is fine); default: camera.cameramodel's pose")
      .Text("camera-up", &camera_up, "the scene's up direction, x,y,z")
      .Texts("names", &names,
             "projector names, one per session (default: the session's display name)");
  DeclareHeldLenses(table, &held_lenses,
                    "hold projector NAME's lens (intrinsics and distortion) from FILE, a "
                    ".cameramodel (e.g. `procam calibrate board`'s NAME.cameramodel), and solve "
                    "only its pose in the room (with a scene, or scanning)");
  table
      ->Flag("refine-distortion", &options.refine_distortion,
             "refine projector k1, k2 (LENSMODEL_OPENCV4); default pinhole")
      .Flag("refine-camera", &options.refine_camera_intrinsics,
            "refine the camera's focal length (fy / fx kept), cx, cy jointly (distortion kept); "
            "scanning: the whole lens, with the chessboard's covariance as the prior")
      .Flag("refine-camera-aspect", &refine_camera_aspect,
            "with --refine-camera: fx and fy free independently (weakly pinned by walls and a "
            "floor)")
      .Integer(
          "max-correspondences", &max_correspondences, 0, std::numeric_limits<int>::max(), "",
          "per projector, decoded pixels used (thinned evenly); 0: " +
              std::to_string(RoomCalibrationOptions().max_correspondences) + " with a scene, " +
              std::to_string(SelfCalibrationOptions().max_correspondences) + " scanning the room");
}

bool ProjectorsStageOptions::Check(std::string* why) const {
  if (!CheckDeclared(*this, why)) return false;
  if (!scene.empty() && (!floor_chessboard.empty() || camera_height)) {
    *why = FlagOf(*this, &floor_chessboard) + ", " + FlagOf(*this, &camera_height) +
           ": only without " + FlagOf(*this, &scene) + " (scanning the room)";
    return false;
  }
  if (scene.empty() && !camera_guess.empty()) {
    *why = FlagOf(*this, &camera_guess) + ": only with " + FlagOf(*this, &scene) +
           " (a scan needs no guess)";
    return false;
  }
  return true;
}

ProjectorsStageSummary RunProjectorsStage(const ProjectorsStageOptions& input) {
  ProjectorsStageOptions args = input;
  {
    std::string why;
    if (!args.Check(&why)) throw std::invalid_argument(why);
  }
  if (args.max_correspondences > 0) {
    args.options.max_correspondences = args.max_correspondences;
    args.self_calibration.max_correspondences = args.max_correspondences;
  }
  if (!args.room_from_camera_guess && !args.camera_guess.empty())
    args.room_from_camera_guess = RoomFromCameraGuess(args.camera_guess, args.camera_up);
  if (args.refine_camera_aspect && !args.options.refine_camera_intrinsics)
    throw std::invalid_argument(FlagOf(args, &args.refine_camera_aspect) + ": needs " +
                                FlagOf(args, &args.options.refine_camera_intrinsics));
  args.options.keep_camera_aspect_ratio = !args.refine_camera_aspect;
  std::string why;
  if (!args.options.Check(&why)) throw std::invalid_argument(why);
  const std::filesystem::path out(args.out);
  const std::filesystem::path camera_path = out / "camera.cameramodel";
  if (!std::filesystem::exists(camera_path))
    throw IoError(camera_path.string() +
                  ": file not found (run `procam calibrate camera ... --out " + args.out.string() +
                  "` first)");
  const CameraModel camera = ReadCameraModelFile(camera_path);
  if (camera.lens_model != "LENSMODEL_PINHOLE" && camera.lens_model != "LENSMODEL_OPENCV4")
    throw IoError(camera_path.string() + ": lensmodel " + camera.lens_model +
                  ": projector calibration supports LENSMODEL_PINHOLE and LENSMODEL_OPENCV4");
  if (!args.names.empty() && args.names.size() != args.sessions.size())
    throw std::invalid_argument(FlagOf(args, &args.names) + ": " +
                                std::to_string(args.names.size()) + " names for " +
                                std::to_string(args.sessions.size()) + " sessions");

  if (args.scene.empty()) {
    // The scan fits pinhole projectors (self_calibration.h), or holds a board-calibrated lens and
    // solves that projector's pose alone; --refine-camera refines the whole camera lens with the
    // chessboard's as the prior.
    const std::string with_scene = ": only with " + FlagOf(args, &args.scene);
    if (args.options.refine_distortion)
      throw std::invalid_argument(FlagOf(args, &args.options.refine_distortion) + with_scene +
                                  " (a scan fits pinhole projectors)");
    if (args.refine_camera_aspect)
      throw std::invalid_argument(FlagOf(args, &args.refine_camera_aspect) + with_scene +
                                  " (a scan refines the whole lens)");
    RoomCalibrationProblem prior;  // checked before the sessions are decoded
    const bool refine = args.options.refine_camera_intrinsics;
    args.self_calibration.refine_camera_lens = refine;
    const bool have_prior = ChessboardLensPrior(out, camera, refine, &prior, args.progress);
    const std::map<std::string, HeldProjectorLens> held_lenses = ReadHeldLenses(args);
    RoomCalibrationProblem problem = ReadProblem(args, camera, camera_path);
    HoldLenses(held_lenses, args, &problem);
    if (refine) problem.camera_intrinsics = prior.camera_intrinsics;
    if (have_prior) problem.camera_intrinsics_covariance = prior.camera_intrinsics_covariance;
    return ScanRoom(args, camera, problem);
  }

  // The guess: --camera-guess, else the pose camera.cameramodel already holds.
  Eigen::Isometry3d guess;
  std::string guess_source;
  if (args.room_from_camera_guess) {
    guess = *args.room_from_camera_guess;
    guess_source = FlagOf(args, &args.camera_guess);
  } else if (!camera.cam_from_ref.isApprox(Eigen::Isometry3d::Identity(), 1e-12)) {
    guess = camera.cam_from_ref.inverse();
    guess_source = camera_path.string() + " extrinsics";
  } else {
    throw std::invalid_argument(
        FlagOf(args, &args.camera_guess) + ": required: " + camera_path.string() +
        " has no pose in the room yet; give the camera's position and a point it looks at, "
        "x,y,z,look_x,look_y,look_z in the scene's frame (a few cm and degrees suffice)");
  }
  const std::map<std::string, HeldProjectorLens> held_lenses = ReadHeldLenses(args);
  const Scene scene = LoadSceneArgument(args.scene);
  const RoomModel model(scene);
  const char* const intrinsics_treatment =
      !args.options.refine_camera_intrinsics ? "intrinsics held fixed"
      : args.refine_camera_aspect            ? "fx, fy, cx, cy refined, distortion held"
                                             : "focal length (aspect kept), cx, cy refined, "
                                               "distortion held";
  Report(
      args.progress,
      fmt::format("scene {}: {} surfaces, {} planar facets; camera {} {}x{} ({}); guess from {}: "
                  "camera at ({:.3f}, {:.3f}, {:.3f})",
                  args.scene, scene.surfaces.size(), model.facets().size(), camera.lens_model,
                  camera.width, camera.height, intrinsics_treatment, guess_source,
                  guess.translation().x(), guess.translation().y(), guess.translation().z()));
  RoomCalibrationProblem problem = ReadProblem(args, camera, camera_path);
  HoldLenses(held_lenses, args, &problem);

  ProjectorsStageSummary stage;
  RoomCalibration& calibration = stage.calibration;
  RoomCalibrationSummary& summary = stage.summary;
  const bool converged = CalibrateRoom(args.options, model, problem, guess, &calibration, &summary);
  Report(args.progress, summary.BriefReport());
  if (!converged)
    throw std::runtime_error("projector calibration failed: " + summary.BriefReport());

  const ScanCheck check = CheckAgainstScan(problem, calibration, model, guess, args.progress);
  WriteProjectorsOutputs(args, camera, guess, guess_source, scene, problem, stage, check);
  return stage;
}

namespace {

// Independent check: triangulate, register the model to the cloud from the same guess.
ScanCheck CheckAgainstScan(const RoomCalibrationProblem& problem,
                           const RoomCalibration& calibration, const RoomModel& model,
                           const Eigen::Isometry3d& guess, const ProgressCallback& progress) {
  ScanCheck check;
  const std::vector<TriangulatedPoint> triangulated = Triangulate(problem, calibration);
  std::vector<Vec3> cloud;
  std::vector<double> gaps;
  for (const TriangulatedPoint& p : triangulated) {
    cloud.push_back(p.p_in_cam);
    gaps.push_back(p.gap);
  }
  check.gap = ComputeDistanceStats(gaps);
  Report(progress, fmt::format("triangulated {} points: ray gap median {:.2f} mm, 95% {:.2f} mm",
                               cloud.size(), check.gap.median_mm, check.gap.p95_mm));
  check.registered = guess;
  check.registered_ok = RegisterModelToCloud(RegistrationOptions(), model, cloud, guess,
                                             &check.registered, &check.registration);
  Report(progress, check.registration.BriefReport());
  check.icp_vs_joint_mm =
      1e3 * (check.registered.translation() - calibration.room_from_camera.translation()).norm();
  check.icp_vs_joint_deg = Eigen::AngleAxisd(check.registered.linear() *
                                             calibration.room_from_camera.linear().transpose())
                               .angle() *
                           180.0 / 3.14159265358979323846;
  Report(progress, fmt::format("ICP vs joint refinement: camera {:.2f} mm, {:.4f} deg apart",
                               check.icp_vs_joint_mm, check.icp_vs_joint_deg));
  std::vector<Vec3> thinned;
  const size_t stride = std::max<size_t>(1, cloud.size() / 30000);
  for (size_t i = 0; i < cloud.size(); i += stride) thinned.push_back(cloud[i]);
  check.planes = FitPlanes(PlaneFitOptions(), thinned);
  Report(progress, fmt::format("RANSAC: {} planes in the scan", check.planes.size()));
  return check;
}

nlohmann::json PoseJson(const Eigen::Isometry3d& pose) {
  nlohmann::json matrix = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) matrix.push_back({pose(r, 0), pose(r, 1), pose(r, 2), pose(r, 3)});
  return matrix;
}

nlohmann::json StatsJson(const DistanceStats& stats) {
  return {{"points", stats.points},
          {"rms_mm", stats.rms_mm},
          {"median_mm", stats.median_mm},
          {"p95_mm", stats.p95_mm},
          {"max_mm", stats.max_mm}};
}

// A projector's projection uncertainty in result.json: the map's form, where it is, and null
// where it was not computed.
nlohmann::json UncertaintyJson(const ProjectionUncertaintyMap& map, double distance_m,
                               const char* what) {
  if (map.grid.empty()) return nullptr;
  nlohmann::json json = map.Json();
  json["what"] = what;
  json["distance_m"] = distance_m;
  return json;
}
nlohmann::json UncertaintyJson(const SelfCalibrationProjectorSummary& p) {
  nlohmann::json json = UncertaintyJson(
      p.uncertainty, p.uncertainty_distance_m,
      p.uncertainty_includes_camera_lens
          ? "1-sigma worst-direction error of where the projector shows a point fixed relative to "
            "the camera at distance_m, px (the self-calibration's covariance with the camera "
            "lens's chessboard covariance folded in)"
          : "1-sigma worst-direction error of where the projector shows a point fixed relative to "
            "the camera at distance_m, px (the self-calibration's covariance, decoding noise "
            "only)");
  if (!json.is_null()) {
    json["includes_camera_lens"] = p.uncertainty_includes_camera_lens;
    // A held lens's intrinsics are no unknowns of the solve: its pose's uncertainty alone.
    json["pose_only"] = p.lens_held;
  }
  return json;
}
nlohmann::json UncertaintyJson(const RoomProjectorSummary& p) {
  return UncertaintyJson(p.uncertainty, p.uncertainty_distance_m,
                         "1-sigma worst-direction error of where the projector shows a point fixed "
                         "in the room at distance_m, px (the joint solve's covariance, decoding "
                         "noise only)");
}

// The "registration" entry of rig.json.
nlohmann::json RegistrationJson(const ProjectorsStageOptions& args, const CameraModel& camera,
                                const Eigen::Isometry3d& guess, const std::string& guess_source,
                                const Scene& scene, const ProjectorsStageSummary& stage,
                                const ScanCheck& check) {
  const RoomCalibration& calibration = stage.calibration;
  const RoomCalibrationSummary& summary = stage.summary;
  const RegistrationSummary& registration = check.registration;
  nlohmann::json registration_json;
  registration_json["room_from_camera"] = PoseJson(calibration.room_from_camera);
  registration_json["camera_centre_m"] = JsonTriple(calibration.room_from_camera.translation());
  registration_json["camera_guess"] = {{"source", guess_source},
                                       {"room_from_camera", PoseJson(guess)},
                                       {"moved_mm", summary.camera_moved_mm},
                                       {"turned_deg", summary.camera_turned_deg}};
  if (args.options.refine_camera_intrinsics) {
    registration_json["camera_intrinsics"] = {
        {"refined",
         args.refine_camera_aspect ? "fx, fy, cx, cy" : "focal length (fy / fx kept), cx, cy"},
        {"lens_model", camera.lens_model},
        {"before", camera.intrinsics},
        {"after", calibration.camera_intrinsics},
        {"moved_px",
         std::vector<double>(summary.camera_intrinsics_moved, summary.camera_intrinsics_moved + 4)},
        {"sigma_px", std::vector<double>(summary.camera_sigma, summary.camera_sigma + 4)},
        {"sigma_what",
         "1 sigma of fx, fy, cx, cy from the joint solve's covariance (decoding "
         "noise only; the walls' flatness and the model's accuracy come on top)"}};
  } else {
    registration_json["camera_intrinsics"] = "held fixed (from camera.cameramodel)";
  }
  registration_json["termination"] = summary.termination == RoomCalibrationSummary::kConverged
                                         ? "converged"
                                         : "facets not settled";
  nlohmann::json per_projector = nlohmann::json::array();
  for (size_t k = 0; k < calibration.projectors.size(); ++k) {
    const RoomProjectorSummary& s = summary.projectors[k];
    const RoomProjector& p = calibration.projectors[k];
    per_projector.push_back(
        {{"name", p.name},
         {"centre_m", JsonTriple(p.proj_from_room.inverse().translation())},
         {"imagersize", {p.width, p.height}},
         {"lens", p.lens_held ? "held from " + args.held_lenses.at(p.name).string()
                              : std::string("solved")},
         {"correspondences", s.correspondences},
         {"used", s.used},
         {"on_model", s.points},
         {"inliers", s.points - s.outliers},
         {"outliers", s.outliers},
         {"seed_rms_px", s.seed_rms},
         {"rms_px_per_coordinate", s.rms},
         {"max_norm_px", s.max_norm},
         {"projection_uncertainty", UncertaintyJson(s)}});
  }
  registration_json["projectors"] = per_projector;
  // The room it was registered in, as ReadRigDirectory's and the calibrated room's checks read it
  // (a model file of another projector, a room file changed since).
  registration_json["camera_imagersize"] = {camera.width, camera.height};
  registration_json["room"] = RegisteredRoomJson(scene);
  nlohmann::json per_surface = nlohmann::json::array();
  for (size_t s = 0; s < registration.per_surface.size(); ++s) {
    nlohmann::json entry = StatsJson(registration.per_surface[s]);
    entry["surface"] = scene.surfaces[s].name;
    per_surface.push_back(entry);
  }
  registration_json["residual"] = {
      {"what",
       "triangulated camera-projector points vs the scene model after ICP from the "
       "guess (distance to the nearest surface)"},
      {"ok", check.registered_ok},
      {"icp_room_from_camera", PoseJson(check.registered)},
      {"icp_vs_joint_mm", check.icp_vs_joint_mm},
      {"icp_vs_joint_deg", check.icp_vs_joint_deg},
      {"points", registration.points},
      {"inlier_distance_mm", 1e3 * RegistrationOptions().inlier_distance},
      {"inlier_fraction", registration.inlier_fraction},
      {"inliers", StatsJson(registration.inliers)},
      {"all", StatsJson(registration.all)},
      {"per_surface", per_surface},
      {"ray_gap", StatsJson(check.gap)}};
  return registration_json;
}

// result.json's list of the calibrated projectors.
nlohmann::json ProjectorsJson(const RoomCalibration& calibration) {
  nlohmann::json projectors = nlohmann::json::array();
  for (const RoomProjector& p : calibration.projectors)
    projectors.push_back({{"name", p.name},
                          {"model", p.name + ".cameramodel"},
                          {"lens_model", p.lens_model},
                          {"lens_held", p.lens_held},
                          {"intrinsics", p.intrinsics},
                          {"imagersize", {p.width, p.height}},
                          {"centre_room_m", JsonTriple(p.proj_from_room.inverse().translation())}});
  return projectors;
}

// RIG_DIR/result.json's "projectors" section.
nlohmann::json ResultSection(const ProjectorsStageOptions& args,
                             const nlohmann::json& registration_json,
                             const ProjectorsStageSummary& stage, const ScanCheck& check) {
  const RoomCalibration& calibration = stage.calibration;

  nlohmann::json planes_json = nlohmann::json::array();
  for (const FittedPlane& plane : check.planes) {
    const Vec3 normal = calibration.room_from_camera.linear() * plane.normal;
    planes_json.push_back(
        {{"normal_room", JsonTriple(normal)},
         {"offset_room_m", plane.offset - normal.dot(calibration.room_from_camera.translation())},
         {"centroid_room_m", JsonTriple(calibration.room_from_camera * plane.centroid)},
         {"inliers", plane.inliers},
         {"rms_mm", plane.rms_mm},
         {"extent_m", {plane.extent.x(), plane.extent.y()}}});
  }

  nlohmann::json result_section;
  nlohmann::json sessions = nlohmann::json::array();
  for (const std::filesystem::path& session : args.sessions) sessions.push_back(session.string());
  result_section["sessions"] = sessions;
  result_section["scene"] = args.scene;
  result_section["registration"] = registration_json;
  result_section["planes_from_scan"] = {
      {"what",
       "sequential RANSAC planes of the triangulated cloud (room frame through the joint "
       "pose), normal . p + offset = 0"},
      {"distance_mm", 1e3 * PlaneFitOptions().distance},
      {"planes", planes_json}};
  result_section["projectors"] = ProjectorsJson(calibration);
  return result_section;
}

// Every projector's model, the camera's with its pose in the room (and intrinsics when refined),
// and the rig.json and result.json entries.
void WriteDeviceModels(const std::filesystem::path& out, const CameraModel& camera,
                       const RoomCalibration& calibration, bool refined_camera,
                       const std::string& room, const nlohmann::json& registration_json,
                       const nlohmann::json& result_section) {
  for (const RoomProjector& p : calibration.projectors) {
    CameraModel model_file;
    model_file.lens_model = p.lens_model;
    model_file.intrinsics = p.intrinsics;
    model_file.width = p.width;
    model_file.height = p.height;
    model_file.cam_from_ref = p.proj_from_room;
    WriteCameraModelFile(out / (p.name + ".cameramodel"), model_file,
                         std::string("procam projector model (procam calibrate projectors") +
                             (p.lens_held ? "; the lens held as given, the pose solved" : "") +
                             "); extrinsics = rt_proj_room, the room = " + room);
  }
  CameraModel camera_out = camera;
  camera_out.cam_from_ref = calibration.room_from_camera.inverse();
  if (refined_camera) {
    camera_out.intrinsics = calibration.camera_intrinsics;
    // The chessboard solve's inputs no longer give these intrinsics: mrcal's tools would evaluate
    // the uncertainty of a lens that is not the one written.
    camera_out.optimization_inputs.clear();
  }
  WriteCameraModelFile(
      out / "camera.cameramodel", camera_out,
      (refined_camera ? "procam camera model (procam calibrate camera; the lens refined "
                        "and the pose by procam calibrate projectors: --refine-camera, or "
                        "the scan); extrinsics = rt_cam_room, the room = "
                      : "procam camera model (procam calibrate camera; pose by procam "
                        "calibrate projectors); extrinsics = rt_cam_room, the room = ") +
          room);
  UpdateRigFile(out, [&](RigFile& rig) {
    rig.camera.model = "camera.cameramodel";
    // Projectors of an earlier calibration that this one does not name are dropped: their
    // models are in another registration's frame (and a later stage would stop at them).
    std::erase_if(rig.projectors, [&](const RigProjector& entry) {
      return std::none_of(calibration.projectors.begin(), calibration.projectors.end(),
                          [&](const RoomProjector& p) { return p.name == entry.name; });
    });
    for (const RoomProjector& p : calibration.projectors)
      rig.Projector(p.name).model = p.name + ".cameramodel";
    rig.registration = registration_json;
  });
  UpdateRigResult(out, {"projectors"}, result_section);
}

void WriteProjectorsOutputs(const ProjectorsStageOptions& args, const CameraModel& camera,
                            const Eigen::Isometry3d& guess, const std::string& guess_source,
                            const Scene& scene, const RoomCalibrationProblem& problem,
                            const ProjectorsStageSummary& stage, const ScanCheck& check) {
  const RoomCalibration& calibration = stage.calibration;
  const std::filesystem::path& out = args.out;
  const std::filesystem::path camera_path = out / "camera.cameramodel";
  const nlohmann::json registration_json =
      RegistrationJson(args, camera, guess, guess_source, scene, stage, check);
  const nlohmann::json result_section = ResultSection(args, registration_json, stage, check);
  // rig.json is read before anything is written, so a malformed one stops here.
  ReadRigFile(out);

  WriteDeviceModels(out, camera, calibration, args.options.refine_camera_intrinsics,
                    "the scene's frame", registration_json, result_section);
  std::vector<std::string> names;
  for (const RoomProjector& projector : calibration.projectors) names.push_back(projector.name);
  WriteProjectorsReport(out / "projectors_report.html", names, problem, stage.summary);
  Report(args.progress,
         fmt::format(
             "wrote {} projector models, camera.cameramodel (pose in the room{}), rig.json, "
             "result.json and projectors_report.html (where each projector's calibration "
             "is sure) in {}",
             calibration.projectors.size(),
             args.options.refine_camera_intrinsics ? ", refined intrinsics" : "", out.string()));
}

// The metric scale of a scan: measured from the floor chessboard, else given.
// The camera's height above the floor, from the floor chessboard (its plane's normal in the
// camera frame into *board_normal, for the check against the scan's floor) or --camera-height.
double ScanCameraHeight(const ProjectorsStageOptions& args, const CameraModel& camera,
                        nlohmann::json* scale_json, std::optional<Vec3>* board_normal) {
  if (!args.floor_chessboard.empty()) {
    const FloorChessboard floor =
        MeasureFloorChessboard(camera, args.board, args.floor_chessboard, args.board_thickness);
    Report(args.progress, floor.BriefReport());
    *board_normal = floor.floor_normal_in_cam;
    *scale_json = {{"source", "floor chessboard"},
                   {"photo", args.floor_chessboard.string()},
                   {"corners", {args.board.corners_x, args.board.corners_y}},
                   {"square_m", args.board.square_size},
                   {"board_thickness_m", args.board_thickness},
                   {"camera_height_m", floor.camera_height},
                   {"board_distance_m", floor.cam_from_board.translation().norm()},
                   {"reprojection_rms_px", floor.rms_px},
                   {"board_normal_in_camera", JsonTriple(floor.floor_normal_in_cam)}};
    return floor.camera_height;
  }
  if (args.camera_height) {
    if (!(*args.camera_height > 0.0) || !std::isfinite(*args.camera_height))
      throw std::invalid_argument(FlagOf(args, &args.camera_height) +
                                  ": must be a positive number of metres");
    *scale_json = {{"source", FlagOf(args, &args.camera_height)},
                   {"camera_height_m", *args.camera_height}};
    return *args.camera_height;
  }
  throw std::invalid_argument(
      FlagOf(args, &args.floor_chessboard) + ": required without " + FlagOf(args, &args.scene) +
      ": the scan's metric scale comes from a photo of the chessboard lying flat on the floor, "
      "taken by the camera from where it stands (or give " +
      FlagOf(args, &args.camera_height) + ", the camera's height above the floor in metres)");
}

nlohmann::json SelfCalibrationJson(const ProjectorsStageOptions& args,
                                   const ProjectorsStageSummary& stage) {
  const SelfCalibrationSummary& summary = *stage.self_calibration;
  nlohmann::json projectors = nlohmann::json::array();
  for (size_t k = 0; k < summary.projectors.size(); ++k) {
    const SelfCalibrationProjectorSummary& p = summary.projectors[k];
    const RoomProjector& projector = stage.calibration.projectors[k];
    projectors.push_back(
        {{"name", projector.name},
         {"lens", projector.lens_held ? "held from " + args.held_lenses.at(projector.name).string()
                                      : std::string("solved")},
         {"correspondences", p.correspondences},
         {"used", p.used},
         {"seed_inliers", p.seed_inliers},
         {"seed_focal_px", p.seed_focal},
         {"shared_points", p.shared},
         {"principal_point_held", p.principal_point_held},
         {"outliers", p.outliers},
         {"rms_px_per_coordinate", p.rms},
         {"max_norm_px", p.max_norm},
         {"projection_uncertainty", UncertaintyJson(p)}});
  }
  nlohmann::json lens;
  if (summary.camera_lens_refined) {
    lens = {
        {"refined", true},
        {"after", stage.calibration.camera_intrinsics},
        {"moved", summary.camera_lens_moved},
        {"moved_chessboard_sigmas", summary.camera_lens_moved_sigmas},
        {"what",
         "the camera's lens refined in the bundle adjustment with the chessboard's (result.json "
         "camera.intrinsics, camera.intrinsics_covariance) as a Gaussian prior; moved = after "
         "minus the chessboard's, mrcal order"}};
  } else {
    lens = {{"refined", false}, {"what", "held as camera.cameramodel has it"}};
  }
  return {{"points", summary.points},
          {"camera_lens", lens},
          {"ceres_iterations", summary.ceres_iterations},
          {"metres_per_unit", summary.scale},
          {"floor_inliers", summary.floor_inliers},
          {"floor_rms_mm", summary.floor_rms_mm},
          {"time_s", summary.time_s},
          {"projectors", projectors}};
}

ProjectorsStageSummary ScanRoom(const ProjectorsStageOptions& args, const CameraModel& camera,
                                const RoomCalibrationProblem& problem) {
  const std::filesystem::path& out = args.out;
  nlohmann::json scale_json;
  SelfCalibrationOptions options = args.self_calibration;
  std::optional<Vec3> board_normal;
  options.camera_height = ScanCameraHeight(args, camera, &scale_json, &board_normal);
  Report(args.progress,
         fmt::format("no room model: the room is scanned ({} projectors; camera {:.4f} m above "
                     "the floor, from {})",
                     problem.projectors.size(), options.camera_height,
                     scale_json["source"].get<std::string>()));
  if (board_normal) {
    options.floor_normal_in_camera = *board_normal;
    options.max_floor_normal_deg = args.max_board_floor_angle_deg;
  }
  ProjectorsStageSummary stage;
  SelfCalibrationSummary summary;
  if (!SelfCalibrateRoom(options, problem, &stage.calibration, nullptr, &summary))
    throw std::runtime_error("projector calibration from the scan failed: " + summary.message +
                             " (the captures are kept: run the same command again after "
                             "mending it)");
  Report(args.progress, summary.BriefReport());
  stage.self_calibration = summary;
  if (board_normal) {
    // The board must lie on the floor the scan found: its plane parallel to that floor (a board
    // on a tilted surface, or a photo from another camera pose, would set a wrong scale).
    // The angle is the scan's own floor's, before the floor was held to the board's normal.
    const double angle = summary.floor_to_given_normal_deg;
    scale_json["board_to_scanned_floor_deg"] = angle;
    scale_json["floor_held_to_the_board"] = summary.floor_normal_held;
    if (angle > args.max_board_floor_angle_deg)
      throw IoError(fmt::format(
          "{}: the board's plane is {:.1f} deg off the floor the scan found (at most {:g}): lay "
          "it flat on the floor and take the photo with the camera where it stood for the "
          "structured light (the captures are kept)",
          args.floor_chessboard.string(), angle, args.max_board_floor_angle_deg));
  }

  // The room: every correspondence triangulated (rays more than 2 cm apart left out), and where
  // no projector decoded both axes of a pixel, its one-axis correspondences against their
  // projector's column or row; one point per camera pixel (FusePerCameraPixel), in the room
  // frame. Above kMaxScanPoints, only the pixels of a coarser lattice (every s-th row and
  // column) are kept: SceneFromPoints takes the points' spacing for a lattice of pixels, which
  // every s-th point of the list would not be.
  constexpr size_t kMaxScanPoints = 1000000;
  std::vector<double> gaps;
  const std::vector<TriangulatedPoint> per_pixel =
      TriangulateScan(problem, stage.calibration, 0.02, &gaps);
  const long one_axis_pixels = std::count_if(per_pixel.begin(), per_pixel.end(),
                                             [](const TriangulatedPoint& p) { return p.one_axis; });
  int lattice = 1;
  std::vector<Vec3> thinned;
  for (const TriangulatedPoint& p : KeepPixelLattice(per_pixel, kMaxScanPoints, &lattice))
    thinned.push_back(stage.calibration.room_from_camera * p.p_in_cam);
  const DistanceStats gap = ComputeDistanceStats(gaps);
  Report(args.progress,
         fmt::format("triangulated {} correspondences (ray gap median {:.2f} mm, 95% {:.2f} mm) "
                     "into {} camera pixels, {} of them from one axis alone (a projector's "
                     "column or row); the room from {} of them{}",
                     gaps.size(), gap.median_mm, gap.p95_mm, per_pixel.size(), one_axis_pixels,
                     thinned.size(),
                     lattice > 1 ? fmt::format(" (every {}th row and column)", lattice) : ""));
  SceneFromPointsOptions scan = args.scan;
  scan.viewpoint = stage.calibration.room_from_camera.translation();
  scan.points_on_viewpoint_rays =
      true;  // each point on its camera pixel's ray (FusePerCameraPixel)
  // Curved parts are meshed at SceneFromPoints' fine spacing and then coarsened within its
  // tolerance and to at most target_patches triangles: meshing a coarser grid of points lets
  // advancing front bridge a concave wall (blue_curves' curved wall: +68% area, 0.6 m RMS).
  try {
    stage.scanned = SceneFromPoints(thinned, scan);
  } catch (const std::invalid_argument& error) {
    throw std::runtime_error(std::string("the scan: ") + error.what());
  }
  Report(args.progress, stage.scanned->Report());
  if (stage.scanned->scene.surfaces.empty())
    throw std::runtime_error("the scan: no surface found in " + std::to_string(thinned.size()) +
                             " points");
  const std::string left_out = LeftOutSurfaceError(*stage.scanned, scan);
  if (!left_out.empty()) {
    throw std::runtime_error("the scan: " + left_out +
                             " (the captures are kept: run the same command again after "
                             "mending it)");
  }

  nlohmann::json surfaces = nlohmann::json::array();
  for (size_t s = 0; s < stage.scanned->stats.size(); ++s) {
    const ScannedSurfaceStats& stats = stage.scanned->stats[s];
    surfaces.push_back({{"name", stage.scanned->scene.surfaces[s].name},
                        {"kind", stats.kind == ScannedSurfaceStats::kPlane ? "plane" : "mesh"},
                        {"points", stats.points},
                        {"rms_mm", stats.rms_mm},
                        {"area_m2", stats.area_m2},
                        {"holes", stats.holes}});
  }
  const nlohmann::json registration_json = {
      {"method",
       "scan: poses and projector intrinsics from the structured light alone, room frame z up "
       "from the floor (no room model)"},
      {"room", "room.json"},
      {"room_from_camera", PoseJson(stage.calibration.room_from_camera)},
      {"camera_centre_m", JsonTriple(stage.calibration.room_from_camera.translation())},
      {"scale", scale_json},
      {"self_calibration", SelfCalibrationJson(args, stage)},
      {"ray_gap", StatsJson(gap)}};
  nlohmann::json sessions = nlohmann::json::array();
  for (const std::filesystem::path& session : args.sessions) sessions.push_back(session.string());
  const nlohmann::json result_section = {
      {"sessions", sessions},
      {"scene", "room.json (scanned)"},
      {"registration", registration_json},
      {"scan",
       {{"points", stage.scanned->points},
        {"one_axis_pixels", one_axis_pixels},
        {"unassigned", stage.scanned->unassigned},
        {"largest_left_out_m2",
         stage.scanned->left_out.empty() ? 0.0 : stage.scanned->left_out.front().area_m2},
        {"time_s", stage.scanned->time_s},
        {"surfaces", surfaces}}},
      {"projectors", ProjectorsJson(stage.calibration)}};
  ReadRigFile(out);  // a malformed rig.json stops here, before anything is written
  stage.room = WriteScannedScene(out, *stage.scanned);
  if (summary.camera_lens_refined) {
    // camera.cameramodel gets the refined lens without the chessboard solve's inputs (they no
    // longer give its intrinsics); a copy of the chessboard's model keeps them for mrcal's tools
    // (written once: an earlier scan has already dropped them from camera.cameramodel).
    const std::string chessboard = ReadFile(out / "camera.cameramodel");
    if (chessboard.find("'optimization_inputs'") != std::string::npos)
      WriteFileAtomically(out / "camera_chessboard.cameramodel", chessboard);
  }
  WriteDeviceModels(out, camera, stage.calibration, summary.camera_lens_refined,
                    "the scanned room's frame (room.json)", registration_json, result_section);
  std::vector<std::string> names;
  for (const RoomProjector& projector : stage.calibration.projectors)
    names.push_back(projector.name);
  WriteProjectorsReport(out / "projectors_report.html", names, problem, *stage.self_calibration);
  Report(args.progress,
         fmt::format("wrote {} ({} surfaces), {} projector models, camera.cameramodel (pose in "
                     "the scanned room), rig.json, result.json and projectors_report.html (where "
                     "each projector's calibration is sure) in {}",
                     stage.room.string(), stage.scanned->scene.surfaces.size(),
                     stage.calibration.projectors.size(), out.string()));
  return stage;
}
}  // namespace

namespace {
bool ProjectorNameCharacter(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
}
}  // namespace

bool ValidProjectorName(const std::string& name) {
  return !name.empty() && std::all_of(name.begin(), name.end(), ProjectorNameCharacter);
}

std::string ProjectorNameFrom(const std::string& name) {
  std::string safe = name;
  for (char& c : safe)
    if (!ProjectorNameCharacter(c)) c = '_';
  return safe;
}

Eigen::Isometry3d RoomFromCameraGuess(const std::string& guess, const std::string& up) {
  // The options as ProjectorsStageOptions declares them (calibrate all's are the same).
  const ProjectorsStageOptions names;
  const std::string guess_flag = FlagOf(names, &names.camera_guess);
  const std::string up_flag = FlagOf(names, &names.camera_up);
  const std::vector<double> v =
      ParseNumberList(guess_flag, guess, "x,y,z,look_x,look_y,look_z in the room (metres)", 6);
  const std::vector<double> u = ParseNumberList(up_flag, up, "x,y,z (the room's up direction)", 3);
  try {
    return ProjFromWorldLookingAt(Vec3(v[0], v[1], v[2]), Vec3(v[3], v[4], v[5]),
                                  Vec3(u[0], u[1], u[2]))
        .inverse();
  } catch (const std::invalid_argument&) {
    throw IoError(guess_flag + ": the camera must look at a point away from it and not along " +
                  up_flag);
  }
}

}  // namespace procam
