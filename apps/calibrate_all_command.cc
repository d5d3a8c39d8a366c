// procam calibrate all --camera URI --scene SCENE --out RIG_DIR: a whole rig, end to end (issue
// 7). Captures with the sequencer and calibrates, by running the same commands a user would run
// by hand, each writing its part of RIG_DIR:
//
//   1. camera intrinsics: `calibrate camera` on --chessboard DIR, or --camera-model FILE copied;
//      a synthetic camera photographs a simulated chessboard held in front of it;
//   2. per projector: `capture --sequence structured_light` and `capture --sequence photometric`
//      into RIG_DIR/captures/;
//   3. `calibrate projectors` on every structured-light session (joint refinement, registration);
//   4. per projector: `calibrate photometric --projector NAME --scene SCENE` (scene units,
//      per-patch reflectance);
//   5. the projectors' black levels separated from one another (SeparateProjectorBlacks).
#include <algorithm>
#include <cmath>
#include <optional>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <stdexcept>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "geometry/stage.h"
#include "calibration/rig_directory.h"
#include "calibration/photometric_transfer.h"
#include "projection/camera_rays.h"
#include "compensation/unit_light.h"
#include "projection/projection_rig.h"
#include "calibration/rig_directory.h"
#include "capture/camera.h"
#include "capture/session.h"
#include "datasets_synthetic/chessboard_views.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "base/io.h"

namespace procam {
namespace {

struct CalibrateAllArguments {
  std::string camera;
  std::string scene;
  std::string out;
  int patches = 0;
  std::string chessboard;    // folder or session of chessboard photos
  std::string camera_model;  // an existing camera.cameramodel instead
  std::string corners = "9x6";
  double square = 0.03;
  std::vector<std::string> displays;  // real rigs: one per projector (glfw:N|NAME)
  std::vector<std::string> names;     // projector names, one per projector
  std::string camera_guess;
  std::string camera_scale;
  int frames = 4;
  double settle_ms = 150.0;
  std::vector<double> exposures_us;
  std::string levels = "0,32,64,96,128,160,192,224,255";
};

std::string Join(const std::vector<std::string>& items, const char* separator) {
  std::string text;
  for (size_t k = 0; k < items.size(); ++k) text += (k ? separator : "") + items[k];
  return text;
}

// The synthetic camera's chessboard photos: the rig's own camera (its lens, not its pose) sees
// a board of `board` held in ten poses. Written as 8-bit PNGs into `folder`.
void RenderSyntheticChessboard(const SyntheticWorld& world, const ChessboardSpec& board,
                               const std::filesystem::path& folder) {
  std::filesystem::create_directories(folder);
  const CameraGeometry& camera = world.rig->camera();
  const std::vector<Eigen::Isometry3d> poses = ChessboardPoses(camera, board);
  for (size_t v = 0; v < poses.size(); ++v) {
    const cv::Mat image = RenderChessboard(camera, board, poses[v], 0.01, 100 + v);
    std::vector<uchar> png;
    cv::imencode(".png", image, png);
    WriteFileAtomically(folder / fmt::format("{:03d}_board.png", v),
                        std::string(png.begin(), png.end()));
  }
  std::printf("rendered %zu chessboard photos of the synthetic camera into %s\n", poses.size(),
              folder.c_str());
}

// A tape-measure guess of the synthetic camera's pose: its position rounded to 5 cm and the
// point it aims at rounded to 25 cm (what someone standing in the room would write down).
std::string SyntheticCameraGuess(const std::string& scene) {
  const DevicePlacement camera = MakeSyntheticScene(scene, 100).camera;
  const auto round = [](double value, double step) { return std::round(value / step) * step; };
  return fmt::format("{},{},{},{},{},{}", round(camera.centre.x(), 0.05),
                     round(camera.centre.y(), 0.05), round(camera.centre.z(), 0.05),
                     round(camera.target.x(), 0.25), round(camera.target.y(), 0.25),
                     round(camera.target.z(), 0.25));
}

// Every photometric session's black field shows all projectors at black, so each projector's
// fitted black is the sum of all of them there. Separates them (SeparateBlackLevels) and moves
// each max by the same amount (the fit's max − black is unbiased), in rig.json and in a
// `black_levels` section of result.json.
void SeparateProjectorBlacks(const std::filesystem::path& out, const std::vector<std::string>& names,
                             const std::filesystem::path& captures, const std::string& scene,
                             int patches) {
  std::printf("\n== black levels, jointly\n");
  const nlohmann::json rig_json = ReadRigJson(out);
  const RigDirectory rig = ReadRigDirectory(out);
  const ProjectorGeometry camera = ReadCameraModel(out / "camera.cameramodel");
  const GeometryStage stage =
      RunGeometryStage(scene, GeometryArguments(patches));
  std::vector<cv::Mat> transfers;
  cv::Mat black_field;
  int black_fields = 0;
  double camera_black = 0.0;
  for (const std::string& name : names) {
    const auto projector = std::find_if(rig.projectors.begin(), rig.projectors.end(),
                                        [&](const Projector& p) { return p.name == name; });
    if (projector == rig.projectors.end()) throw IoError((out / "rig.json").string() + ": no projector " + name);
    // Written by step 4 for every projector; .at() names what is missing otherwise.
    Eigen::Vector3d scale;
    nlohmann::json entry;
    try {
      entry = rig_json.at("photometric").at(name);
      const nlohmann::json& k = entry.at("camera_scale");
      scale = Eigen::Vector3d(k.at(0).get<double>(), k.at(1).get<double>(), k.at(2).get<double>());
    } catch (const nlohmann::json::exception&) {
      throw IoError((out / "rig.json").string() + ": photometric." + name +
                    ".camera_scale: missing (calibrate photometric --scene did not run for it)");
    }
    camera_black = entry.value("camera_black", 0.0);
    const CameraPixelLighting lighting =
        LightCameraPixels(stage.scene, stage.patches.fine, projector->geometry, camera);
    const UnitLightModel model = ModelUnitLight(stage.patches.fine, stage.form_factors, UnitLightExitance(stage.patches.fine, *projector));
    transfers.push_back(PhotometricTransfer(lighting, stage.patches.fine, model, scale));
    // The session's black fields (drive 0 on any channel): every projector dark.
    const CaptureSessionData session = CaptureSessionData::Load(captures / ("photometric_" + name));
    if (!session.Hdr(0).empty()) {
      std::printf("HDR sessions: black levels left as fitted (not separated)\n");
      return;
    }
    for (int p = 0; p < session.pattern_count(); ++p) {
      const nlohmann::json& info = session.manifest()["patterns"][p].value("info", nlohmann::json());
      if (!info.is_object() || info.value("kind", "") != "flat" || info.value("level", -1) != 0) continue;
      const cv::Mat mean = session.Mean(p, 0);
      if (black_field.empty()) black_field = cv::Mat::zeros(mean.size(), CV_32FC3);
      black_field += mean;
      ++black_fields;
    }
  }
  if (black_fields == 0) {
    std::printf("no black fields: black levels left as fitted\n");
    return;
  }
  black_field /= black_fields;
  const std::vector<Eigen::Vector3d> black = SeparateBlackLevels(transfers, black_field, camera_black);
  nlohmann::json report = nlohmann::json::object();
  UpdateRigJson(out, [&](nlohmann::json& json) {
    for (size_t j = 0; j < names.size(); ++j) {
      nlohmann::json& entry = RigProjectorEntry(json, names[j]);
      nlohmann::json fitted_black = entry["black"], fitted_max = entry["max"];
      nlohmann::json new_black = nlohmann::json::array(), new_max = nlohmann::json::array();
      for (int c = 0; c < 3; ++c) {
        const double shift = fitted_black[c].get<double>() - black[j][c];
        new_black.push_back(std::max(0.0, black[j][c]));
        new_max.push_back(fitted_max[c].get<double>() - shift);
      }
      report[names[j]] = {{"fitted_black", fitted_black}, {"black", new_black}, {"max", new_max}};
      std::printf("%s: black (%.5f, %.5f, %.5f) (fitted alone: %.5f, %.5f, %.5f)\n", names[j].c_str(),
                  new_black[0].get<double>(), new_black[1].get<double>(), new_black[2].get<double>(),
                  fitted_black[0].get<double>(), fitted_black[1].get<double>(), fitted_black[2].get<double>());
      entry["black"] = new_black;
      entry["max"] = new_max;
    }
  });
  UpdateRigResult(out, {"black_levels"},
                  {{"what", "each projector's black separated from the black fields (all projectors dark) "
                            "by least squares over the projectors' transfers; max moved by the same amount"},
                   {"black_fields", black_fields},
                   {"projectors", report}});
}

void RunCalibrateAll(const CalibrateAllArguments& args) {
  RegisterSyntheticCameraBackend();
  const CameraUri uri = CameraUri::Parse(args.camera);
  const bool synthetic = uri.scheme() == "synthetic";
  std::shared_ptr<SyntheticWorld> world;
  if (synthetic) world = OpenSyntheticWorld(uri);  // held open: every capture shares it

  // The projectors: a synthetic world's, or one per --display.
  std::vector<std::string> names = args.names;
  const size_t count = synthetic ? world->rig->projectors().size() : args.displays.size();
  if (count == 0) {
    throw std::invalid_argument("--display: a real rig needs one per projector, e.g. --display "
                                "glfw:1,glfw:2 (procam show --list)");
  }
  if (synthetic && !args.displays.empty()) {
    throw std::invalid_argument("--display: a synthetic camera looks at its own projectors");
  }
  if (names.empty()) {
    for (size_t k = 0; k < count; ++k) {
      names.push_back(synthetic ? world->rig->projectors()[k].name : fmt::format("projector{}", k));
    }
  }
  if (names.size() != count) {
    throw std::invalid_argument("--names: " + std::to_string(names.size()) + " names for " +
                                std::to_string(count) + " projectors");
  }
  std::string scene = args.scene;
  if (scene.empty()) {
    if (!synthetic) throw std::invalid_argument("--scene: required for a real rig (the room model)");
    scene = "synthetic:" + world->scene;
  }
  const int patches = args.patches > 0 ? args.patches : synthetic ? world->patches : 0;

  // Everything the later steps need is checked before anything is captured or written.
  if (args.camera_model.empty() && args.chessboard.empty() && !synthetic) {
    throw std::invalid_argument(
        "--chessboard: a real camera needs chessboard photos (--chessboard DIR) or a "
        "calibrated model (--camera-model FILE)");
  }
  if (!args.camera_model.empty() && !std::filesystem::exists(args.camera_model))
    throw IoError(args.camera_model + ": file not found (--camera-model)");
  if (args.camera_scale.empty() && !synthetic) {
    throw std::invalid_argument(
        "--camera-scale: required for a real camera (camera value per unit exitance, "
        "docs/calibration.md)");
  }
  const std::filesystem::path out(args.out);
  const std::filesystem::path captures = out / "captures";
  std::filesystem::create_directories(captures);
  std::printf("calibrating %zu projector(s) (%s) with camera %s into %s\n", count,
              Join(names, ", ").c_str(), args.camera.c_str(), out.c_str());

  // 1. Camera intrinsics.
  std::printf("\n== 1/4 camera intrinsics\n");
  if (!args.camera_model.empty()) {
    if (!std::filesystem::exists(args.camera_model))
      throw IoError(args.camera_model + ": file not found (--camera-model)");
    std::filesystem::copy_file(args.camera_model, out / "camera.cameramodel",
                               std::filesystem::copy_options::overwrite_existing);
    UpdateRigJson(out, [](nlohmann::json& rig) { rig["camera"]["model"] = "camera.cameramodel"; });
    std::printf("camera model from %s\n", args.camera_model.c_str());
  } else {
    std::string chessboard = args.chessboard;
    std::string corners = args.corners;
    double square = args.square;
    if (chessboard.empty()) {
      if (!synthetic) {
        throw std::invalid_argument(
            "--chessboard: a real camera needs chessboard photos (--chessboard DIR) or a "
            "calibrated model (--camera-model FILE)");
      }
      ChessboardSpec board;
      board.square_size = 0.06;
      RenderSyntheticChessboard(*world, board, captures / "chessboard");
      chessboard = (captures / "chessboard").string();
      corners = fmt::format("{}x{}", board.corners_x, board.corners_y);
      square = board.square_size;
    }
    RunProcamCommand({"calibrate", "camera", chessboard, "--out", args.out, "--corners", corners,
                "--square", fmt::format("{}", square)});
  }

  // 2. Captures, per projector.
  std::printf("\n== 2/4 structured light and flat fields, per projector\n");
  std::vector<std::string> sessions;
  for (size_t k = 0; k < count; ++k) {
    std::vector<std::string> common = {"--camera", args.camera, "--frames",
                                       std::to_string(args.frames), "--settle-ms",
                                       fmt::format("{}", args.settle_ms)};
    if (synthetic) {
      common.insert(common.end(), {"--projector", std::to_string(k)});
    } else {
      common.insert(common.end(), {"--display", args.displays[k]});
    }
    if (!args.exposures_us.empty()) {
      std::vector<std::string> exposures;
      for (double e : args.exposures_us) exposures.push_back(fmt::format("{}", e));
      common.insert(common.end(), {"--exposure-us", Join(exposures, ",")});
    }
    const std::string structured = (captures / ("structured_light_" + names[k])).string();
    std::vector<std::string> command = {"capture", "--sequence", "structured_light", "--out",
                                        structured};
    command.insert(command.end(), common.begin(), common.end());
    RunProcamCommand(command);
    sessions.push_back(structured);
    command = {"capture", "--sequence", "photometric", "--levels", args.levels, "--channels",
               "rgb", "--out", (captures / ("photometric_" + names[k])).string()};
    command.insert(command.end(), common.begin(), common.end());
    RunProcamCommand(command);
    // The projector goes dark again, so its last flat field does not light the next one's
    // captures (on a real rig: every projector but the one being captured must show black).
    if (synthetic) {
      const cv::Size size = world->displays[k]->Resolution();
      world->displays[k]->Show(cv::Mat(size, CV_8UC3, cv::Scalar::all(0)));
    }
  }

  // 3. Geometry: every projector and the camera's pose in the room, jointly.
  std::printf("\n== 3/4 projectors and registration\n");
  std::vector<std::string> command = {"calibrate", "projectors"};
  command.insert(command.end(), sessions.begin(), sessions.end());
  command.insert(command.end(), {"--scene", scene, "--out", args.out, "--names", Join(names, ",")});
  std::string guess = args.camera_guess;
  if (guess.empty() && synthetic) guess = SyntheticCameraGuess(world->scene);
  if (!guess.empty()) command.insert(command.end(), {"--camera-guess", guess});
  RunProcamCommand(command);

  // 4. Photometry in the scene's units and per-patch reflectance.
  std::printf("\n== 4/4 photometry, per projector\n");
  std::string camera_scale = args.camera_scale;
  if (camera_scale.empty()) {
    if (!synthetic) {
      throw std::invalid_argument(
          "--camera-scale: required for a real camera (camera value per unit exitance, "
          "docs/calibration.md)");
    }
    camera_scale = args.camera;
  }
  for (size_t k = 0; k < count; ++k) {
    command = {"calibrate", "photometric", (captures / ("photometric_" + names[k])).string(),
               "--out", args.out, "--projector", names[k], "--scene", scene,
               "--camera-scale", camera_scale};
    if (patches > 0) command.insert(command.end(), {"--patches", std::to_string(patches)});
    RunProcamCommand(command);
  }
  SeparateProjectorBlacks(out, names, captures, scene, patches);
  std::printf("\nrig calibrated: %s (rig.json, camera.cameramodel, %s, reflectance.npy); use it "
              "with `procam compensate SCENE --rig %s`\n",
              out.c_str(), Join(names, ".cameramodel, ").append(".cameramodel").c_str(),
              out.c_str());
}

}  // namespace

void RunProcamCommand(const std::vector<std::string>& arguments) {
  std::printf("\n$ procam %s\n", Join(arguments, " ").c_str());
  std::fflush(stdout);
  CLI::App app("procam");
  app.require_subcommand(1);
  AddCaptureCommands(app);
  AddCalibrateCommands(app);
  AddCompensationCommands(app);
  AddBenchCommands(app);
  AddProjectionCommands(app);
  AddVerifyCommand(app);
  std::vector<std::string> reversed(arguments.rbegin(), arguments.rend());
  try {
    app.parse(reversed);
  } catch (const CLI::ParseError& error) {
    throw std::invalid_argument(Join(arguments, " ").substr(0, 40) + "...: " + error.what());
  }
}

void AddCalibrateAllCommand(CLI::App& calibrate) {
  auto args = std::make_shared<CalibrateAllArguments>();
  CLI::App* all = calibrate.add_subcommand(
      "all",
      "Capture and calibrate a whole rig: camera, projectors, registration, photometry");
  all->add_option("--camera", args->camera,
                  "Camera URI (v4l2:..., aravis:..., synthetic:SCENE for the simulated rig)")
      ->required();
  all->add_option("--scene", args->scene,
                  "The room model (scene JSON, or synthetic:NAME; default for a synthetic camera: "
                  "its scene)");
  all->add_option("--out", args->out, "Rig directory")->required();
  all->add_option("--patches", args->patches,
                  "Patch target the per-patch reflectance is estimated for (default: the scene's; "
                  "synthetic: the camera's patches)");
  all->add_option("--chessboard", args->chessboard,
                  "Chessboard photos of the camera (a folder or a capture session)");
  all->add_option("--camera-model", args->camera_model,
                  "A calibrated camera.cameramodel instead of --chessboard");
  all->add_option("--corners", args->corners, "Chessboard inner corners, COLUMNSxROWS")
      ->capture_default_str();
  all->add_option("--square", args->square, "Chessboard square size, metres")
      ->capture_default_str();
  all->add_option("--display", args->displays,
                  "Real rigs: each projector's monitor, in order (glfw:N|NAME, comma-separated)")
      ->delimiter(',');
  all->add_option("--names", args->names, "Projector names, comma-separated")->delimiter(',');
  all->add_option("--camera-guess", args->camera_guess,
                  "Camera position and a point it looks at, x,y,z,look_x,look_y,look_z (scene "
                  "frame, metres); a synthetic camera's is guessed from its placement");
  all->add_option("--camera-scale", args->camera_scale,
                  "Camera value per unit exitance (number or R,G,B; default for a synthetic "
                  "camera: from its URI)");
  all->add_option("--frames", args->frames, "Frames averaged per pattern")->capture_default_str();
  all->add_option("--settle-ms", args->settle_ms, "Wait after each pattern, milliseconds")
      ->capture_default_str();
  all->add_option("--exposure-us", args->exposures_us,
                  "Exposure(s), microseconds; several bracket and merge to HDR")
      ->delimiter(',');
  all->add_option("--levels", args->levels, "Photometric drive levels, comma-separated")
      ->capture_default_str();
  all->callback([args] { RunCalibrateAll(*args); });
}

}  // namespace procam
