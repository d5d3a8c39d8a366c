// procam calibrate camera SESSION_DIR --out RIG_DIR: camera intrinsics from chessboard images
// (issue 7). Writes RIG_DIR/camera.cameramodel (mrcal) and RIG_DIR/result.json.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include <opencv2/imgcodecs.hpp>

#include "apps/commands.h"
#include "calibration/camera_calibration.h"
#include "geometry/io.h"

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
  WriteFileAtomically(out / "result.json", result.dump(2) + "\n");
  std::printf("wrote %s and %s\n", (out / "camera.cameramodel").c_str(),
              (out / "result.json").c_str());
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
}

}  // namespace procam
