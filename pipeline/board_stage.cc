#include "pipeline/board_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <future>
#include <limits>
#include <nlohmann/json.hpp>
#include <numbers>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "base/html_report.h"
#include "base/io.h"
#include "calibration/camera_report.h"
#include "calibration/capture_layout.h"
#include "capture/session.h"
#include "pipeline/projectors_stage.h"
#include "projection/rig_directory.h"

namespace procam {

void BoardStageOptions::Declare(OptionTable* table) {
  table
      ->Paths("sessions", &sessions,
              "structured-light sessions of `procam capture --sequence structured_light`, one per "
              "board pose")
      .Positional()
      .Required()
      .Path("out", &out, "the rig directory: camera.cameramodel, NAME.cameramodel, result.json")
      .Required()
      .Text("name", &projector, "the projector's name");
  board.Declare(table);
  table
      ->Choice<std::string>("lens-model", &options.lens_model,
                            {{"LENSMODEL_OPENCV4", "LENSMODEL_OPENCV4"},
                             {"LENSMODEL_OPENCV5", "LENSMODEL_OPENCV5"},
                             {"LENSMODEL_OPENCV8", "LENSMODEL_OPENCV8"}},
                            "both lenses' distortion model (mrcal)")
      .Integer("window", &options.homography_half_window, 3, 200, "camera pixels",
               "half side of the window around a corner for its local homography")
      .Integer("min-window-pixels", &options.min_window_pixels, 8, std::numeric_limits<int>::max(),
               "", "fewest decoded pixels in a corner's window")
      .Number("homography-reject", &options.homography_reject_px,
              OptionTable::Interval::AboveMin(0.0, 1e6), "projector pixels",
              "decoded pixels farther than this from a corner's homography are dropped")
      .Integer("min-poses", &options.min_poses, 2, std::numeric_limits<int>::max(), "",
               "fewest board poses")
      .Number("min-tilt-spread", &options.min_tilt_spread_deg,
              OptionTable::Interval::BelowMax(0.0, 90.0), "degrees",
              "least angle between two poses' board normals")
      .NegatedFlag("no-outlier-rejection", &options.reject_outliers, "keep every corner");
}

bool BoardStageOptions::Check(std::string* why) const {
  if (sessions.empty()) {
    *why = "board: no capture sessions (one per board pose)";
    return false;
  }
  if (out.empty()) {
    *why = "board: no rig directory (--out)";
    return false;
  }
  if (!ValidProjectorName(projector)) {
    *why = "board: projector name '" + projector + "' takes letters, digits, '_', '-' and '.'";
    return false;
  }
  return CheckDeclared(*this, why) && board.Check(why) && options.Check(why) && decode.Check(why);
}

namespace {

// One session: the white photo and the decoded structured light; the projector's size.
BoardPoseCapture ReadBoardSession(const std::filesystem::path& directory,
                                  const StructuredLightDecodeOptions& decode, int* projector_width,
                                  int* projector_height) {
  // Procam's own sessions and imported ones (calibration/capture_layout.h) alike.
  const StructuredLightSession session = ReadStructuredLightSession(directory, /*both_axes=*/true);
  const std::string manifest = (directory / "session.json").string();
  const StructuredLightLayout& layout = session.layout;
  *projector_width = layout.width;
  *projector_height = layout.height;
  BoardPoseCapture capture;
  capture.name = directory.filename().empty() ? directory.parent_path().filename().string()
                                              : directory.filename().string();
  try {
    capture.map = DecodeStructuredLight(layout, session.images, decode);
  } catch (const std::invalid_argument& error) {
    throw IoError(manifest + ": " + error.what());
  }
  capture.white = session.images[layout.white];
  return capture;
}

nlohmann::json Residuals(const std::vector<Vec2>& residuals) {
  nlohmann::json out = nlohmann::json::array();
  for (const Vec2& r : residuals) {
    if (r.allFinite()) {
      out.push_back({r.x(), r.y()});
    } else {
      out.push_back(nullptr);
    }
  }
  return out;
}

void WriteBoardReport(const std::filesystem::path& path, const std::string& name,
                      const BoardStageSummary& stage) {
  const BoardProjectorCalibration& calibration = stage.calibration;
  const BoardProjectorSummary& summary = stage.summary;
  HtmlReport report("procam: camera and projector " + name + " from a chessboard");
  report.Paragraph(summary.BriefReport());
  report.Heading("Lenses");
  const auto lens_row = [](const std::string& device, const std::vector<double>& intrinsics) {
    std::vector<std::string> row = {device};
    for (int k = 0; k < 4; ++k) row.push_back(fmt::format("{:.3f}", intrinsics[k]));
    std::string distortion;
    for (size_t k = 4; k < intrinsics.size(); ++k)
      distortion += fmt::format("{}{:.5f}", k > 4 ? " " : "", intrinsics[k]);
    row.push_back(distortion);
    return row;
  };
  report.Table({"device", "fx", "fy", "cx", "cy", "distortion"},
               {lens_row("camera", calibration.camera_intrinsics),
                lens_row(name, calibration.projector_intrinsics)});
  const Eigen::Isometry3d camera_from_projector = calibration.projector_from_camera.inverse();
  report.Paragraph(fmt::format(
      "The projector's centre in the camera frame: ({:.4f}, {:.4f}, {:.4f}) m; its axis turned "
      "{:.3f}° from the camera's.",
      camera_from_projector.translation().x(), camera_from_projector.translation().y(),
      camera_from_projector.translation().z(),
      Eigen::AngleAxisd(camera_from_projector.linear()).angle() * 180.0 / std::numbers::pi));
  report.Heading("What the calibration is sure of");
  if (stage.uncertainty_error.empty()) {
    double largest = 0.0;
    for (double v : stage.camera_uncertainty.grid) largest = std::max(largest, v);
    for (double v : stage.projector_uncertainty.grid) largest = std::max(largest, v);
    const double full_scale = UncertaintyFullScale(largest);
    report.Paragraph(fmt::format(
        "1-σ worst-direction projection error at infinity, mrcal's definition (the point rides "
        "with the boards' mean), from corner noise σ {:.3f} px. One colour scale for both: 0 px "
        "(dark blue) to {:g} px (yellow); white dots: the corners observed. Where it is large, "
        "hold the board so that it covers that part of the image.",
        stage.camera_uncertainty.observed_pixel_sigma, full_scale));
    std::vector<Vec2> camera_corners, projector_corners;
    for (const BoardPoseCorners& pose : stage.corners) {
      camera_corners.insert(camera_corners.end(), pose.camera.begin(), pose.camera.end());
      for (size_t k = 0; k < pose.projector.size(); ++k)
        if (pose.projector_found[k]) projector_corners.push_back(pose.projector[k]);
    }
    auto shrink = [](cv::Mat picture) {
      if (picture.cols <= 640) return picture;
      cv::Mat small;
      cv::resize(picture, small, cv::Size(640, std::max(1, picture.rows * 640 / picture.cols)), 0,
                 0, cv::INTER_AREA);
      return small;
    };
    report.Figures({{fmt::format("camera ({}×{}): centre {:.3f} px", calibration.camera_width,
                                 calibration.camera_height, stage.camera_uncertainty.centre),
                     shrink(DrawProjectionUncertainty(
                         stage.camera_uncertainty, calibration.camera_width,
                         calibration.camera_height, 1, full_scale, camera_corners))},
                    {fmt::format("{} ({}×{}): centre {:.3f} px", name, calibration.projector_width,
                                 calibration.projector_height, stage.projector_uncertainty.centre),
                     shrink(DrawProjectionUncertainty(
                         stage.projector_uncertainty, calibration.projector_width,
                         calibration.projector_height, 1, full_scale, projector_corners))}});
  } else {
    report.Paragraph("Not computed: " + stage.uncertainty_error);
  }
  report.Heading("Poses");
  std::vector<std::vector<std::string>> rows;
  for (size_t v = 0; v < stage.corners.size(); ++v) {
    int seen = 0;
    for (bool found : stage.corners[v].projector_found) seen += found;
    rows.push_back({stage.corners[v].name, fmt::format("{:.4f}", summary.pose_camera_rms[v]),
                    fmt::format("{:.4f}", summary.pose_projector_rms[v]),
                    fmt::format("{} of {}", seen, stage.corners[v].projector_found.size())});
  }
  for (const std::string& skipped : stage.skipped)
    rows.push_back({skipped, "board not found", "-", "-"});
  report.Table({"pose", "camera RMS per coordinate, px", "projector RMS per coordinate, px",
                "corners the projector saw"},
               rows);
  report.Write(path);
}

}  // namespace

BoardStageSummary RunBoardStage(const BoardStageOptions& args) {
  std::string why;
  if (!args.Check(&why)) throw std::invalid_argument(why);
  BoardStageSummary stage;
  int camera_width = 0, camera_height = 0, projector_width = 0, projector_height = 0;
  // The next session is read and decoded while the chessboard is searched in this one: OpenCV's
  // search runs on one core, reading and decoding on all, so on two cores the two overlap.
  struct Read {
    BoardPoseCapture capture;
    int width = 0, height = 0;
  };
  const auto read = [&](size_t k) {
    return std::async(std::launch::async, [&args, k] {
      Read read;
      read.capture = ReadBoardSession(args.sessions[k], args.decode, &read.width, &read.height);
      return read;
    });
  };
  std::future<Read> next;
  if (!args.sessions.empty()) next = read(0);
  for (size_t k = 0; k < args.sessions.size(); ++k) {
    const std::filesystem::path& session = args.sessions[k];
    Read current = next.get();
    if (k + 1 < args.sessions.size()) next = read(k + 1);
    const BoardPoseCapture& capture = current.capture;
    const int width = current.width, height = current.height;
    if (projector_width == 0) {
      projector_width = width;
      projector_height = height;
      camera_width = capture.white.cols;
      camera_height = capture.white.rows;
    } else if (width != projector_width || height != projector_height ||
               capture.white.cols != camera_width || capture.white.rows != camera_height) {
      throw IoError(session.string() + ": projector " + std::to_string(width) + "x" +
                    std::to_string(height) + ", camera " + std::to_string(capture.white.cols) +
                    "x" + std::to_string(capture.white.rows) + "; the first session's are " +
                    std::to_string(projector_width) + "x" + std::to_string(projector_height) +
                    " and " + std::to_string(camera_width) + "x" + std::to_string(camera_height));
    }
    BoardPoseCorners corners;
    if (!LocateBoardCorners(args.options, args.board, capture, &corners)) {
      stage.skipped.push_back(capture.name);
      Report(args.progress, session.string() + ": chessboard not found in the white photo");
      continue;
    }
    const int seen = static_cast<int>(
        std::count(corners.projector_found.begin(), corners.projector_found.end(), true));
    Report(args.progress, fmt::format("{}: {} corners, {} located in the projector",
                                      session.string(), corners.camera.size(), seen));
    stage.corners.push_back(std::move(corners));
  }
  const bool converged = CalibrateBoardProjector(
      args.options, args.board, stage.corners, camera_width, camera_height, projector_width,
      projector_height, &stage.calibration, &stage.summary);
  Report(args.progress, stage.summary.BriefReport());
  if (!converged) throw std::runtime_error("board calibration: " + stage.summary.message);
  if (BoardProjectorUncertainty(stage.calibration, &stage.camera_uncertainty,
                                &stage.projector_uncertainty, &stage.uncertainty_error)) {
    Report(args.progress, "camera " + stage.camera_uncertainty.BriefReport());
    Report(args.progress, args.projector + " " + stage.projector_uncertainty.BriefReport());
  } else {
    Report(args.progress, "projection uncertainty: not computed: " + stage.uncertainty_error);
  }

  const std::filesystem::path out(args.out);
  std::filesystem::create_directories(out);
  const BoardProjectorCalibration& calibration = stage.calibration;
  WriteCameraModelFile(out / "camera.cameramodel", calibration.CameraModelOut(),
                       "procam camera model (procam calibrate board; mrcal_optimize with the "
                       "projector " +
                           args.projector + "); the camera is the reference frame");
  const std::filesystem::path projector_path = out / (args.projector + ".cameramodel");
  WriteCameraModelFile(projector_path, calibration.ProjectorModelOut(),
                       "procam projector model (procam calibrate board; mrcal_optimize, camera 1 "
                       "of 2); extrinsics: the projector from the camera");
  const BoardProjectorSummary& summary = stage.summary;
  nlohmann::json result;
  result["lens_model"] = calibration.lens_model;
  result["camera"] = {{"intrinsics", calibration.camera_intrinsics},
                      {"imagersize", {calibration.camera_width, calibration.camera_height}}};
  result["projector"] = {
      {"intrinsics", calibration.projector_intrinsics},
      {"imagersize", {calibration.projector_width, calibration.projector_height}},
      {"model", projector_path.filename().string()}};
  const std::array<double, 6> rt = RtFromPose(calibration.projector_from_camera);
  result["rt_projector_camera"] = rt;
  result["board"] = {{"corners_x", args.board.corners_x},
                     {"corners_y", args.board.corners_y},
                     {"square_size_m", args.board.square_size}};
  result["residuals"] = {{"camera_rms_px_per_coordinate", summary.camera_rms},
                         {"projector_rms_px_per_coordinate", summary.projector_rms},
                         {"camera_max_norm_px", summary.camera_max_norm},
                         {"projector_max_norm_px", summary.projector_max_norm},
                         {"camera_corners", summary.camera_corners},
                         {"projector_corners", summary.projector_corners},
                         {"camera_outliers", summary.camera_outliers},
                         {"projector_outliers", summary.projector_outliers},
                         {"tilt_spread_deg", summary.tilt_spread_deg}};
  nlohmann::json poses = nlohmann::json::array();
  for (size_t v = 0; v < stage.corners.size(); ++v) {
    poses.push_back({{"session", stage.corners[v].name},
                     {"camera_rms_px", summary.pose_camera_rms[v]},
                     {"projector_rms_px", summary.pose_projector_rms[v]},
                     {"rt_camera_board", RtFromPose(calibration.cam_from_board[v])},
                     {"camera_residuals_px", Residuals(summary.camera_residuals[v])},
                     {"projector_residuals_px", Residuals(summary.projector_residuals[v])}});
  }
  result["poses"] = poses;
  result["skipped_sessions"] = stage.skipped;
  if (stage.uncertainty_error.empty()) {
    result["camera_uncertainty"] = stage.camera_uncertainty.Json();
    result["projector_uncertainty"] = stage.projector_uncertainty.Json();
  } else {
    result["uncertainty_error"] = stage.uncertainty_error;
  }
  UpdateRigResult(out, {"board", args.projector}, result);
  const std::filesystem::path report = out / ("board_report_" + args.projector + ".html");
  WriteBoardReport(report, args.projector, stage);
  Report(args.progress, "wrote " + (out / "camera.cameramodel").string() + ", " +
                            projector_path.string() + ", " + (out / "result.json").string() +
                            " (section board." + args.projector + ") and " + report.string());
  return stage;
}

}  // namespace procam
