// Camera intrinsics against a known lens: chessboard corners projected exactly (plus Gaussian
// noise) and chessboard images rendered through the lens (supersampled, with image noise),
// detected by OpenCV and refined by mrcal. Truth: an OpenCV4 lens of 640×480 pixels.
#include "calibration/camera_calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "base/html_report.h"
#include "base/io.h"
#include "calibration/camera_report.h"
#include "datasets_synthetic/chessboard_views.h"
#include "pipeline/camera_stage.h"
#include "projection/projector.h"
#include "tests/calibration/chessboard_fixture.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::Board;
using testing::kHeight;
using testing::kTrueIntrinsics;
using testing::kWidth;

// The ten board poses of chessboard_fixture.h.
std::vector<Eigen::Isometry3d> BoardPoses(const ChessboardSpec& board) {
  return testing::BoardPoses(board, 10);
}

// The ten board poses, their exact corners plus N(0, sigma²) per coordinate.
std::vector<ChessboardView> NoisyCorners(double sigma, uint32_t seed) {
  return testing::NoisyCorners(sigma, seed, 10);
}

double RelativeError(double estimate, double truth) { return std::abs(estimate / truth - 1.0); }

// Corner noise of 0.1 px per coordinate, about what detection on sharp images gives (the
// rendered test below measures 0.056 px). The focal error is statistical, ∝ σ/√views: with
// σ = 0.3 px the same ten views give 0.33% (fx) and 0.39% (fy), outside the 0.2%.
TEST(CameraCalibration, CornerNoiseGivesRmsAndFocal) {
  const double sigma = 0.1;
  CameraCalibrationOptions options;
  CameraCalibration calibration;
  CameraCalibrationSummary summary;
  ASSERT_TRUE(CalibrateCamera(options, Board(), NoisyCorners(sigma, 7), kWidth, kHeight,
                              &calibration, &summary))
      << summary.BriefReport();
  std::printf("%s\n", summary.BriefReport().c_str());
  std::printf("fx %.3f (true %.1f), fy %.3f (true %.1f), cx %.3f, cy %.3f\n",
              calibration.intrinsics[0], kTrueIntrinsics[0], calibration.intrinsics[1],
              kTrueIntrinsics[1], calibration.intrinsics[2], calibration.intrinsics[3]);
  // Issue 7: reprojection RMS within 10% of the injected corner noise; focal within 0.2%.
  EXPECT_NEAR(summary.rms, sigma, 0.1 * sigma);
  EXPECT_LT(RelativeError(calibration.intrinsics[0], kTrueIntrinsics[0]), 0.002);
  EXPECT_LT(RelativeError(calibration.intrinsics[1], kTrueIntrinsics[1]), 0.002);
  EXPECT_NEAR(calibration.intrinsics[2], kTrueIntrinsics[2], 1.0);
  EXPECT_NEAR(calibration.intrinsics[3], kTrueIntrinsics[3], 1.0);
  EXPECT_EQ(summary.views, 10);
}

TEST(CameraCalibration, RejectsCornerOutliers) {
  std::vector<ChessboardView> views = NoisyCorners(0.2, 11);
  // Five corners knocked 8 px off, as a misdetection would.
  for (int v = 0; v < 5; ++v) views[2 * v].corners[5 + 7 * v] += Vec2(8.0, -6.0);
  CameraCalibrationOptions options;
  CameraCalibration calibration;
  CameraCalibrationSummary summary;
  ASSERT_TRUE(CalibrateCamera(options, Board(), views, kWidth, kHeight, &calibration, &summary));
  std::printf("%s\n", summary.BriefReport().c_str());
  EXPECT_GE(summary.outliers, 5);
  EXPECT_LT(summary.outliers, 20);
  EXPECT_NEAR(summary.rms, 0.2, 0.02);
  EXPECT_LT(RelativeError(calibration.intrinsics[0], kTrueIntrinsics[0]), 0.002);
}

TEST(CameraCalibration, TooFewViewsIsAStatus) {
  std::vector<ChessboardView> views = NoisyCorners(0.1, 3);
  views.resize(2);
  CameraCalibration calibration;
  CameraCalibrationSummary summary;
  EXPECT_FALSE(CalibrateCamera(CameraCalibrationOptions(), Board(), views, kWidth, kHeight,
                               &calibration, &summary));
  EXPECT_EQ(summary.termination, CameraCalibrationSummary::kTooFewViews);
  CameraCalibrationOptions bad;
  bad.lens_model = "LENSMODEL_CAHVOR";
  std::string why;
  EXPECT_FALSE(bad.Check(&why));
  EXPECT_NE(why.find("lens_model"), std::string::npos);
}

// Renders the board through the true lens (datasets_synthetic/chessboard_views.h: 4×4
// supersampled rays met with the board plane).
cv::Mat RenderBoard(const ChessboardSpec& board, const Eigen::Isometry3d& cam_from_board,
                    uint32_t seed) {
  const CameraGeometry camera("LENSMODEL_OPENCV4", kTrueIntrinsics, kWidth, kHeight,
                              Eigen::Isometry3d::Identity());
  return RenderChessboard(camera, board, cam_from_board, 0.01, seed);
}

TEST(CameraCalibration, RenderedImagesDetectedAndRefined) {
  const ChessboardSpec board = Board();
  const std::vector<Eigen::Isometry3d> poses = BoardPoses(board);
  std::vector<ChessboardView> views;
  double detection_squares = 0.0;
  int detection_count = 0;
  for (size_t v = 0; v < poses.size(); ++v) {
    const cv::Mat image = RenderBoard(board, poses[v], static_cast<uint32_t>(v));
    ChessboardView view;
    view.name = "image" + std::to_string(v);
    ASSERT_TRUE(DetectChessboard(image, board, &view.corners)) << view.name;
    // Detection error against the truth; the grid may be reported from the other end.
    std::vector<Vec2> truth(board.CornerCount());
    for (int k = 0; k < board.CornerCount(); ++k) {
      truth[k] = LensModel("LENSMODEL_OPENCV4", kTrueIntrinsics).Project(poses[v] * board.Corner(k));
    }
    const bool reversed = (view.corners[0] - truth[0]).norm() > (view.corners[0] - truth.back()).norm();
    for (int k = 0; k < board.CornerCount(); ++k) {
      const Vec2& expected = truth[reversed ? board.CornerCount() - 1 - k : k];
      detection_squares += (view.corners[k] - expected).squaredNorm();
      ++detection_count;
    }
    views.push_back(view);
  }
  const double detection_rms = std::sqrt(detection_squares / (2.0 * detection_count));
  CameraCalibration calibration;
  CameraCalibrationSummary summary;
  ASSERT_TRUE(CalibrateCamera(CameraCalibrationOptions(), board, views, kWidth, kHeight,
                              &calibration, &summary));
  std::printf("detection rms vs truth %.4f px per coordinate\n%s\n", detection_rms,
              summary.BriefReport().c_str());
  std::printf("fx %.3f (true %.1f), fy %.3f (true %.1f), cx %.3f, cy %.3f, k1 %.4f, k2 %.4f\n",
              calibration.intrinsics[0], kTrueIntrinsics[0], calibration.intrinsics[1],
              kTrueIntrinsics[1], calibration.intrinsics[2], calibration.intrinsics[3],
              calibration.intrinsics[4], calibration.intrinsics[5]);
  EXPECT_LT(detection_rms, 0.1);
  // The fit explains the detections to their own noise level (within 10% + what the
  // outlier rejection removes).
  EXPECT_LT(summary.rms, 1.1 * detection_rms + 0.005);
  EXPECT_LT(RelativeError(calibration.intrinsics[0], kTrueIntrinsics[0]), 0.002);
  EXPECT_LT(RelativeError(calibration.intrinsics[1], kTrueIntrinsics[1]), 0.002);

  // The written model is mrcal's: libmrcal (through projection's reader) reads it back exactly.
  testing::TempDir dir;
  WriteCalibrationModel(dir / "camera.cameramodel", calibration);
  const ProjectorGeometry read = ReadCameraModel(dir / "camera.cameramodel");
  EXPECT_EQ(read.lens_model(), "LENSMODEL_OPENCV4");
  EXPECT_EQ(read.width(), kWidth);
  EXPECT_EQ(read.height(), kHeight);
  ASSERT_EQ(read.intrinsics().size(), calibration.intrinsics.size());
  for (size_t k = 0; k < calibration.intrinsics.size(); ++k) {
    EXPECT_EQ(read.intrinsics()[k], calibration.intrinsics[k]);
  }
}

// procam calibrate camera on a capture-session-like folder (frames/ with 16-bit PNGs, one of
// them without a board), as a user would run it.
TEST(CalibrateCommand, WritesModelAndResiduals) {
  const ChessboardSpec board = Board();
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "session/frames");
  const std::vector<Eigen::Isometry3d> poses = BoardPoses(board);
  for (size_t v = 0; v < poses.size(); ++v) {
    cv::Mat image = RenderBoard(board, poses[v], static_cast<uint32_t>(v)), wide;
    image.convertTo(wide, CV_16U, 257.0);
    char name[32];
    std::snprintf(name, sizeof(name), "%03zu_board.png", v);
    cv::imwrite((dir / "session/frames" / name).string(), wide);
  }
  cv::imwrite((dir / "session/frames/999_blank.png").string(),
              cv::Mat(kHeight, kWidth, CV_16U, cv::Scalar(20000)));
  const testing::CommandRun run = testing::RunProcam(
      "calibrate camera " + (dir / "session").string() + " --out " + (dir / "rig").string() +
      " --corners 9x6 --square 0.04");
  std::printf("%s", run.output.c_str());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const ProjectorGeometry model = ReadCameraModel(dir / "rig/camera.cameramodel");
  EXPECT_LT(RelativeError(model.intrinsics()[0], kTrueIntrinsics[0]), 0.002);
  EXPECT_LT(RelativeError(model.intrinsics()[1], kTrueIntrinsics[1]), 0.002);
  std::ifstream file(dir / "rig/result.json");
  const nlohmann::json result = nlohmann::json::parse(file)["camera"];  // its section
  EXPECT_EQ(result["views"].size(), 10u);
  EXPECT_EQ(result["skipped_images"][0], "999_blank.png");
  EXPECT_LT(result["residuals"]["rms_px_per_coordinate"].get<double>(), 0.1);
  EXPECT_EQ(result["imagersize"][0], kWidth);
  // What the calibration is sure of (the numbers themselves: projection_uncertainty_test.cc).
  const nlohmann::json& uncertainty = result["projection_uncertainty"];
  ASSERT_TRUE(uncertainty.contains("centre_px")) << uncertainty.dump();
  EXPECT_GT(uncertainty["centre_px"].get<double>(), 0.0);
  EXPECT_GT(uncertainty["corners_px"]["top_left"].get<double>(),
            uncertainty["centre_px"].get<double>());
  EXPECT_EQ(uncertainty["grid_px"].size(), 12u);
  EXPECT_EQ(uncertainty["grid_px"][0].size(), 16u);
  EXPECT_NE(run.output.find("projection uncertainty"), std::string::npos) << run.output;
  // The report page: well formed, with the map's picture and every image listed.
  const std::string page = ReadFile(dir / "rig/camera_report.html");
  EXPECT_TRUE(CheckReportStructure(page).empty()) << CheckReportStructure(page)[0];
  EXPECT_NE(page.find("projection uncertainty over the image"), std::string::npos);
  EXPECT_NE(page.find("999_blank.png"), std::string::npos);

  const testing::CommandRun missing = testing::RunProcam(
      "calibrate camera " + (dir / "nowhere").string() + " --out " + (dir / "rig2").string());
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("nowhere: not a directory"), std::string::npos) << missing.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "rig2"));
}


// The uncertainty picture: at every grid node the colour of the node's value, between nodes the
// bilinear mean, values above full scale clamped, board corners white. Checked on a grid whose
// values are i + 10 j (nodes on the image's corner pixels: x = i (W−1)/(n−1)) at scale 1 and 2.
TEST(CameraReport, DrawsTheUncertaintyMapWhereItsGridLies) {
  ProjectionUncertaintyMap map;
  map.grid_width = 4;
  map.grid_height = 3;
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 4; ++i) map.grid.push_back(i + 10.0 * j);
  const int width = 31, height = 21;  // nodes every 10 pixels
  const double full_scale = 25.5;     // 0.1 px per level: value v is level 10 v
  const auto colour = [](double level) {
    cv::Mat one(1, 1, CV_8UC1, cv::Scalar(level)), out;
    cv::applyColorMap(one, out, cv::COLORMAP_VIRIDIS);
    return out.at<cv::Vec3b>(0, 0);
  };
  for (int scale : {1, 2}) {
    const cv::Mat picture = DrawProjectionUncertainty(map, width, height, scale, full_scale, {});
    ASSERT_EQ(picture.cols, width * scale);
    ASSERT_EQ(picture.rows, height * scale);
    const auto at = [&](int x, int y) { return picture.at<cv::Vec3b>(y, x); };
    if (scale == 1) {
      EXPECT_EQ(at(0, 0), colour(0));             // node (0, 0): 0
      EXPECT_EQ(at(20, 10), colour(10 * 12.0));   // node (2, 1): 12
      EXPECT_EQ(at(15, 10), colour(10 * 11.5));   // halfway between 11 and 12
      EXPECT_EQ(at(10, 15), colour(10 * 16.0));   // halfway between 11 and 21
      EXPECT_EQ(at(30, 20), colour(230));         // node (3, 2): 23
    }
    // The output's corner pixels lie on (or, at scale 2, a quarter pixel beyond) the corner
    // nodes: 0, 3, 20, 23.
    EXPECT_EQ(picture.at<cv::Vec3b>(0, 0), colour(0));
    EXPECT_EQ(picture.at<cv::Vec3b>(0, picture.cols - 1), colour(30));
    EXPECT_EQ(picture.at<cv::Vec3b>(picture.rows - 1, 0), colour(200));
    EXPECT_EQ(picture.at<cv::Vec3b>(picture.rows - 1, picture.cols - 1), colour(230));
  }
  // Clamping: full scale 10 puts the bottom right corner (23) at the top of the map.
  const cv::Mat clamped = DrawProjectionUncertainty(map, width, height, 1, 10.0, {Vec2(5, 5)});
  EXPECT_EQ(clamped.at<cv::Vec3b>(20, 30), colour(255));
  EXPECT_EQ(clamped.at<cv::Vec3b>(5, 5), cv::Vec3b(255, 255, 255));  // a corner's dot
  EXPECT_THROW(DrawProjectionUncertainty(ProjectionUncertaintyMap(), width, height, 1, 1.0, {}),
               std::invalid_argument);
  EXPECT_THROW(DrawProjectionUncertainty(map, width, height, 0, 1.0, {}), std::invalid_argument);
}

}  // namespace
}  // namespace procam

namespace procam {
namespace {

// Real photographs: OpenCV's own chessboard set (Debian's opencv-doc, copied to
// ../shared/data/real/opencv_left) against the reference OpenCV's test asserts for it
// (modules/python/test/test_calibration.py: calibrateCamera with k1, k2, p1, p2, k3, square 1):
// camera-matrix L1 < 10, distortion L1 < 0.05, RMS reprojection error 0.196 ± 0.01 px per point.
TEST(CameraCalibration, OpenCvsRealChessboardPhotosMatchOpenCvsReference) {
  const std::filesystem::path photos = testing::SharedDir() / "data" / "real" / "opencv_left";
  if (!std::filesystem::exists(photos / "left01.jpg"))
    GTEST_SKIP() << photos << " is missing (the team's shared data)";
  CameraStageOptions options;
  options.images = photos;
  testing::TempDir rig;
  options.out = rig.path();
  options.board.corners_x = 9;
  options.board.corners_y = 6;
  options.board.square_size = 1.0;
  options.options.lens_model = "LENSMODEL_OPENCV5";
  options.options.reject_outliers = false;
  const CameraStageSummary stage = RunCameraStage(options);
  const std::vector<double>& k = stage.calibration.intrinsics;
  ASSERT_EQ(k.size(), 9u);
  const double matrix_l1 = std::abs(k[0] - 532.80992189) + std::abs(k[1] - 532.93346422) +
                           std::abs(k[2] - 342.4952186) + std::abs(k[3] - 233.8879292);
  const double reference[] = {-0.281325576, 0.0291130406, 0.00121234330, -0.000140825372,
                              0.154865844};
  double distortion_l1 = 0.0;
  for (int i = 0; i < 5; ++i) distortion_l1 += std::abs(k[4 + i] - reference[i]);
  std::printf("fx %.2f fy %.2f cx %.2f cy %.2f: camera-matrix L1 %.3f, distortion L1 %.4f, RMS %.4f "
              "px per point over %d views\n",
              k[0], k[1], k[2], k[3], matrix_l1, distortion_l1, stage.summary.rms_norm,
              stage.summary.views);
  EXPECT_EQ(stage.summary.views, 13);
  EXPECT_LT(matrix_l1, 10.0);
  EXPECT_LT(distortion_l1, 0.05);
  // mrcal's optimum may fit the corners better than OpenCV's; never worse than its tolerance.
  EXPECT_LT(stage.summary.rms_norm, 0.196334638 + 0.01);
  EXPECT_GT(stage.summary.rms_norm, 0.1);
}

}  // namespace
}  // namespace procam
