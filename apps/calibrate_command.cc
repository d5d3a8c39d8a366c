// procam calibrate camera SESSION_DIR --out RIG_DIR: camera intrinsics from chessboard images
// (issue 7). Writes RIG_DIR/camera.cameramodel (mrcal) and RIG_DIR/result.json.
// procam calibrate photometric SESSION_DIR --out RIG_DIR: one projector's black, max, response
// and mixing from a photometric capture session, in camera units. Writes
// RIG_DIR/photometric.json and RIG_DIR/result.json.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "apps/commands.h"
#include "apps/photometric_rig.h"
#include "calibration/camera_calibration.h"
#include "calibration/photometric.h"
#include "calibration/rig_directory.h"
#include "capture/session.h"
#include "base/io.h"

namespace procam {
namespace {

struct CalibrateCameraArguments {
  std::string session;
  std::string out;
  std::string corners = "9x6";
  double square = 0.03;
  CameraCalibrationOptions options;
};

// The images to read: a capture session's frames/ (16-bit PNG means, float TIFF HDR), or every
// image in the folder itself, in name order.
std::vector<std::filesystem::path> ChessboardImages(const std::filesystem::path& session) {
  if (!std::filesystem::is_directory(session)) {
    throw IoError(session.string() + ": not a directory");
  }
  const std::filesystem::path folder =
      std::filesystem::is_directory(session / "frames") ? session / "frames" : session;
  std::vector<std::filesystem::path> images;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    std::string extension = entry.path().extension().string();
    std::transform(extension.begin(), extension.end(), extension.begin(), ::tolower);
    if (entry.is_regular_file() && (extension == ".png" || extension == ".jpg" ||
                                    extension == ".jpeg" || extension == ".tif" ||
                                    extension == ".tiff" || extension == ".bmp")) {
      images.push_back(entry.path());
    }
  }
  std::sort(images.begin(), images.end());
  if (images.empty()) throw IoError(folder.string() + ": no images (png, jpg, tiff, bmp)");
  return images;
}

void RunCalibrateCamera(const CalibrateCameraArguments& args) {
  ChessboardSpec board;
  char separator = 0;
  if (std::sscanf(args.corners.c_str(), "%d%c%d", &board.corners_x, &separator,
                  &board.corners_y) != 3 || separator != 'x') {
    throw std::invalid_argument("--corners: expected COLUMNSxROWS of inner corners, e.g. 9x6, got '" +
                                args.corners + "'");
  }
  board.square_size = args.square;
  std::string why;
  if (!board.Check(&why)) throw std::invalid_argument(why);
  if (!args.options.Check(&why)) throw std::invalid_argument(why);

  std::vector<ChessboardView> views;
  nlohmann::json skipped = nlohmann::json::array();
  int width = 0, height = 0;
  for (const std::filesystem::path& path : ChessboardImages(args.session)) {
    const cv::Mat image = cv::imread(path.string(), cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
    if (image.empty()) throw IoError(path.string() + ": cannot read the image");
    if (width == 0) {
      width = image.cols;
      height = image.rows;
    } else if (image.cols != width || image.rows != height) {
      throw IoError(path.string() + ": " + std::to_string(image.cols) + "x" +
                    std::to_string(image.rows) + ", the first image is " + std::to_string(width) +
                    "x" + std::to_string(height));
    }
    ChessboardView view;
    view.name = path.filename().string();
    if (DetectChessboard(image, board, &view.corners)) {
      views.push_back(std::move(view));
    } else {
      skipped.push_back(view.name);
    }
  }
  std::printf("chessboard %s found in %zu of %zu images\n", args.corners.c_str(), views.size(),
              views.size() + skipped.size());

  CameraCalibration calibration;
  CameraCalibrationSummary summary;
  const bool converged =
      CalibrateCamera(args.options, board, views, width, height, &calibration, &summary);
  std::printf("%s\n", summary.BriefReport().c_str());
  if (!converged) throw std::runtime_error("calibration failed: " + summary.BriefReport());

  const std::filesystem::path out(args.out);
  std::filesystem::create_directories(out);
  WriteCalibrationModel(out / "camera.cameramodel", calibration);
  nlohmann::json result;
  result["lens_model"] = calibration.lens_model;
  result["intrinsics"] = calibration.intrinsics;
  result["imagersize"] = {width, height};
  result["board"] = {{"corners_x", board.corners_x},
                     {"corners_y", board.corners_y},
                     {"square_size_m", board.square_size}};
  nlohmann::json view_list = nlohmann::json::array();
  for (size_t v = 0; v < views.size(); ++v) {
    view_list.push_back({{"image", views[v].name}, {"rms_px", summary.view_rms[v]}});
  }
  result["views"] = view_list;
  result["skipped_images"] = skipped;
  result["residuals"] = {{"rms_px_per_coordinate", summary.rms},
                         {"rms_norm_px", summary.rms_norm},
                         {"median_norm_px", summary.median_norm},
                         {"max_norm_px", summary.max_norm},
                         {"seed_rms_px", summary.seed_rms},
                         {"corners", summary.corners},
                         {"outliers", summary.outliers}};
  UpdateRigResult(out, {"camera"}, result);
  std::printf("wrote %s and %s (section camera)\n", (out / "camera.cameramodel").c_str(),
              (out / "result.json").c_str());
}

struct CalibratePhotometricArguments {
  std::string session;
  std::string out;
  PhotometricCalibrationOptions options;
  double clip = 0.99;  // fraction of the camera's full scale at which a pixel counts as clipped
  PhotometricRigArguments rig;  // --projector, --scene, ... (apps/photometric_rig.h)
};

nlohmann::json Json(const Eigen::Vector3d& v) { return {v[0], v[1], v[2]}; }

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

void RunCalibratePhotometric(const CalibratePhotometricArguments& args) {
  std::string why;
  if (!args.options.Check(&why)) throw std::invalid_argument(why);
  const std::filesystem::path session_dir(args.session);
  const PhotometricSession session = ReadPhotometricSession(session_dir);
  // rig.json and scene units (apps/photometric_rig.h), checked before anything is fitted.
  PhotometricRigStage rig_stage(args.rig, args.out, session_dir, session.fields[0].image.size(),
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
  std::printf("%zu flat fields, %d camera pixels used (%d clipped left out)\n",
              session.fields.size(), model.pixels, clipped);
  std::printf("%s\n", model.BriefReport().c_str());

  const std::string units =
      session.hdr ? "camera units: the HDR merge's full scale per second"
                  : "camera units: mean digital numbers at the session's exposure";
  const std::string note =
      "no camera-to-output factor (transfer) was applied: black and max are in camera units, "
      "relative to this camera, its exposure and where it looks; gamma, lut, mixing and the "
      "ratio black/max are absolute";
  nlohmann::json photometric;
  photometric["units"] = units;
  photometric["note"] = note;
  photometric["black"] = Json(model.black);
  photometric["max"] = Json(model.max);
  photometric["gamma"] = Json(model.gamma);
  photometric["gamma_rms"] = Json(model.gamma_rms);
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
  result["black_over_max"] = Json(model.black.cwiseQuotient(model.max));
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
  const std::string name = args.rig.projector.empty() ? "projector" : args.rig.projector;
  const std::filesystem::path model_file =
      out / (args.rig.projector.empty() ? "photometric.json" : name + ".photometric.json");
  WriteFileAtomically(model_file, photometric.dump(2) + "\n");
  UpdateRigResult(out, {"photometric", name}, result);
  rig_stage.Commit();
  std::printf("wrote %s and %s (section photometric.%s)\n", model_file.c_str(),
              (out / "result.json").c_str(), name.c_str());
}

}  // namespace

void AddCalibrateCommands(CLI::App& app) {
  CLI::App* calibrate = app.add_subcommand("calibrate", "Calibrate the rig from captures");
  calibrate->require_subcommand(1);
  auto args = std::make_shared<CalibrateCameraArguments>();
  CLI::App* camera = calibrate->add_subcommand(
      "camera", "Camera intrinsics from chessboard images (OpenCV detection, mrcal refinement)");
  camera->add_option("session", args->session,
                     "Capture session (its frames/) or a folder of chessboard images")
      ->required();
  camera->add_option("--out", args->out, "Rig directory: camera.cameramodel, result.json")
      ->required();
  camera->add_option("--corners", args->corners, "Inner corners, COLUMNSxROWS")
      ->capture_default_str();
  camera->add_option("--square", args->square, "Square size, metres")->capture_default_str();
  camera->add_option("--lens-model", args->options.lens_model,
                     "LENSMODEL_OPENCV4, LENSMODEL_OPENCV5 or LENSMODEL_OPENCV8")
      ->capture_default_str();
  camera->add_flag("!--no-outlier-rejection", args->options.reject_outliers,
                   "Keep every corner");
  camera->callback([args] { RunCalibrateCamera(*args); });

  auto photometric_args = std::make_shared<CalibratePhotometricArguments>();
  CLI::App* photometric = calibrate->add_subcommand(
      "photometric",
      "Projector black, max, gamma, response table and mixing from a photometric capture "
      "session (camera units)");
  photometric
      ->add_option("session", photometric_args->session,
                   "Capture session of `procam capture --sequence photometric --channels rgb`")
      ->required();
  photometric
      ->add_option("--out", photometric_args->out, "Rig directory: photometric.json, result.json")
      ->required();
  photometric
      ->add_option("--min-contrast", photometric_args->options.min_contrast,
                   "Pixels used: brightening from black by at least this fraction of the largest")
      ->capture_default_str();
  photometric
      ->add_option("--table-size", photometric_args->options.table_size,
                   "Entries of the response table (lut)")
      ->capture_default_str();
  AddPhotometricRigOptions(photometric, &photometric_args->rig);
  photometric->callback([photometric_args] { RunCalibratePhotometric(*photometric_args); });

  AddCalibrateResponseCommand(*calibrate);
  AddCalibrateAllCommand(*calibrate);
  AddCalibrateProjectorsCommand(*calibrate);
}

}  // namespace procam
