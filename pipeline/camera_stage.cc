#include "pipeline/camera_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "base/image_io.h"
#include "base/io.h"
#include "calibration/camera_report.h"
#include "projection/rig_directory.h"

namespace procam {
namespace {

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
    if (entry.is_regular_file() &&
        (extension == ".png" || extension == ".jpg" || extension == ".jpeg" ||
         extension == ".tif" || extension == ".tiff" || extension == ".bmp")) {
      images.push_back(entry.path());
    }
  }
  std::sort(images.begin(), images.end());
  if (images.empty()) throw IoError(folder.string() + ": no images (png, jpg, tiff, bmp)");
  return images;
}

}  // namespace

void CameraStageOptions::Declare(OptionTable* table) {
  table
      ->Path("session", &images, "a capture session (its frames/) or a folder of chessboard photos")
      .Positional()
      .Required()
      .Path("out", &out, "the rig directory: camera.cameramodel, result.json")
      .Required();
  board.Declare(table);
  options.Declare(table);
}

bool CameraStageOptions::Check(std::string* why) const {
  return CheckDeclared(*this, why) && board.Check(why) && options.Check(why);
}

CameraStageSummary RunCameraStage(const CameraStageOptions& args) {
  const ChessboardSpec& board = args.board;
  std::string why;
  if (!args.Check(&why)) throw std::invalid_argument(why);

  std::vector<ChessboardView> views;
  std::vector<std::string> skipped;
  int width = 0, height = 0;
  for (const std::filesystem::path& path : ChessboardImages(args.images)) {
    const cv::Mat image = ReadImage(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
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
  Report(args.progress, fmt::format("chessboard {}x{} found in {} of {} images", board.corners_x,
                                    board.corners_y, views.size(), views.size() + skipped.size()));

  CameraStageSummary stage;
  CameraCalibration& calibration = stage.calibration;
  CameraCalibrationSummary& summary = stage.summary;
  const bool converged =
      CalibrateCamera(args.options, board, views, width, height, &calibration, &summary);
  Report(args.progress, summary.BriefReport());
  if (!converged) throw std::runtime_error("calibration failed: " + summary.BriefReport());

  // What the calibration is sure of (projection_uncertainty.h): a failure here is reported, not
  // fatal, since the lens itself converged.
  ProjectionUncertainty uncertainty;
  if (uncertainty.Compute(calibration, &stage.uncertainty_error)) {
    stage.uncertainty = MapProjectionUncertainty(uncertainty, width, height);
    stage.intrinsics_covariance = uncertainty.IntrinsicsCovariance();
    Report(args.progress, stage.uncertainty.BriefReport());
  } else {
    Report(args.progress, "projection uncertainty: not computed: " + stage.uncertainty_error);
  }

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
  result["residuals"] = {{"rms_px_per_coordinate", summary.rms},  {"rms_norm_px", summary.rms_norm},
                         {"median_norm_px", summary.median_norm}, {"max_norm_px", summary.max_norm},
                         {"seed_rms_px", summary.seed_rms},       {"corners", summary.corners},
                         {"outliers", summary.outliers}};
  if (stage.uncertainty_error.empty()) {
    result["projection_uncertainty"] = stage.uncertainty.Json();
    result["projection_uncertainty"]["what"] =
        "1-sigma worst-direction projection error at infinity, px (mrcal 2.2's "
        "projection_uncertainty, mean-frames)";
    nlohmann::json rows = nlohmann::json::array();
    for (int r = 0; r < stage.intrinsics_covariance.rows(); ++r) {
      std::vector<double> row(stage.intrinsics_covariance.cols());
      for (int c = 0; c < stage.intrinsics_covariance.cols(); ++c)
        row[c] = stage.intrinsics_covariance(r, c);
      rows.push_back(row);
    }
    result["intrinsics_covariance"] = rows;
  } else {
    result["projection_uncertainty"] = {{"error", stage.uncertainty_error}};
  }
  UpdateRigResult(out, {"camera"}, result);
  WriteCameraReport(out / "camera_report.html", calibration, summary, views, skipped,
                    stage.uncertainty, stage.uncertainty_error);
  Report(args.progress, "wrote " + (out / "camera.cameramodel").string() + ", " +
                            (out / "result.json").string() + " (section camera) and " +
                            (out / "camera_report.html").string() +
                            " (the uncertainty map over the image)");
  return stage;
}

}  // namespace procam
