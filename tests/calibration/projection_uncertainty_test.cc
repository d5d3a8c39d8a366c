// mrcal's projection uncertainty as procam computes it, against two independent truths: finite
// differences of the mean-frames projection (built here from Eigen poses and LensModel, not from
// mrcal's gradients), and python3-mrcal's own mrcal.projection_uncertainty run on the
// .cameramodel procam writes (its optimization_inputs). Truth lens: OpenCV4, 640×480.
#include "calibration/projection_uncertainty.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <random>

#include "base/camera_model.h"
#include "calibration/camera_calibration.h"
#include "tests/calibration/chessboard_fixture.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::Board;
using testing::kHeight;
using testing::kTrueIntrinsics;
using testing::kWidth;

// All twelve board poses of chessboard_fixture.h, their corners plus N(0, σ²) per coordinate.
std::vector<ChessboardView> NoisyViews(double sigma, uint32_t seed) {
  return testing::NoisyCorners(sigma, seed, 12);
}

// `outliers` corners of the views are knocked 8 px off (as a misdetection would), for mrcal's
// outlier rejection to find.
CameraCalibration Calibrate(double sigma, uint32_t seed, bool regularization = true,
                            int outliers = 0) {
  CameraCalibrationOptions options;
  options.regularization = regularization;
  std::vector<ChessboardView> views = NoisyViews(sigma, seed);
  for (int k = 0; k < outliers; ++k) views[2 * k].corners[5 + 7 * k] += Vec2(8.0, -6.0);
  CameraCalibration calibration;
  CameraCalibrationSummary summary;
  EXPECT_TRUE(CalibrateCamera(options, Board(), views, kWidth, kHeight, &calibration, &summary))
      << summary.BriefReport();
  std::printf("%s\n", summary.BriefReport().c_str());
  EXPECT_GE(summary.outliers, outliers);
  return calibration;
}

// The pixel of `p_in_cam` seen through parameters b (mrcal's state order in full units: the 8
// intrinsics, then r, t of every board) when the camera frame rides with the boards: p goes into
// each board's frame with the optimal pose, back with b's, and the mean is projected.
Vec2 MeanFramesPixel(const CameraCalibration& calibration, const Eigen::VectorXd& b,
                     const Vec3& p_in_cam, bool at_infinity) {
  const int intrinsic_count = static_cast<int>(calibration.intrinsics.size());
  const LensModel lens(calibration.lens_model,
                       std::vector<double>(b.data(), b.data() + intrinsic_count));
  Vec3 mean = Vec3::Zero();
  const int views = static_cast<int>(calibration.cam_from_board.size());
  for (int v = 0; v < views; ++v) {
    const Eigen::Isometry3d optimal = calibration.cam_from_board[v];
    const Eigen::Isometry3d moved = PoseFromRt(b.data() + intrinsic_count + 6 * v);
    mean += at_infinity ? Vec3(moved.linear() * optimal.linear().transpose() * p_in_cam)
                        : Vec3(moved * optimal.inverse() * p_in_cam);
  }
  return lens.Project(mean / views);
}

TEST(ProjectionUncertainty, GradientMatchesFiniteDifferences) {
  const CameraCalibration calibration = Calibrate(0.2, 3);
  ProjectionUncertainty uncertainty;
  std::string why;
  ASSERT_TRUE(uncertainty.Compute(calibration, &why)) << why;
  const int intrinsic_count = static_cast<int>(calibration.intrinsics.size());
  const int views = static_cast<int>(calibration.cam_from_board.size());
  ASSERT_EQ(uncertainty.state_count(), intrinsic_count + 6 * views);
  Eigen::VectorXd b(uncertainty.state_count());
  for (int k = 0; k < intrinsic_count; ++k) b[k] = calibration.intrinsics[k];
  for (int v = 0; v < views; ++v) {
    const std::array<double, 6> rt = RtFromPose(calibration.cam_from_board[v]);
    for (int k = 0; k < 6; ++k) b[intrinsic_count + 6 * v + k] = rt[k];
  }
  const Vec3 points[] = {Vec3(0.05, -0.02, 1.0), Vec3(-0.5, 0.35, 0.9), Vec3(0.3, 0.2, 2.5)};
  for (const Vec3& p : points) {
    for (bool at_infinity : {true, false}) {
      const Eigen::Matrix<double, 2, Eigen::Dynamic> analytic =
          uncertainty.ProjectionGradient(p, at_infinity);
      double largest_error = 0.0, largest = 0.0;
      for (int k = 0; k < b.size(); ++k) {
        const double step = 1e-6 * std::max(1.0, std::abs(b[k]));
        Eigen::VectorXd plus = b, minus = b;
        plus[k] += step;
        minus[k] -= step;
        const Vec2 numeric = (MeanFramesPixel(calibration, plus, p, at_infinity) -
                              MeanFramesPixel(calibration, minus, p, at_infinity)) /
                             (2.0 * step);
        largest_error = std::max(largest_error, (numeric - analytic.col(k)).cwiseAbs().maxCoeff());
        largest = std::max(largest, analytic.col(k).cwiseAbs().maxCoeff());
      }
      EXPECT_LT(largest_error, 1e-5 * largest)
          << "p " << p.transpose() << (at_infinity ? " at infinity" : "");
    }
  }
}

// No solve, no uncertainty: a status, not a crash.
TEST(ProjectionUncertainty, WithoutSolveIsAStatus) {
  CameraCalibration calibration = Calibrate(0.2, 3);
  calibration.solve.corners.clear();
  ProjectionUncertainty uncertainty;
  std::string why;
  EXPECT_FALSE(uncertainty.Compute(calibration, &why));
  EXPECT_NE(why.find("no chessboard solve"), std::string::npos) << why;
}

// The lens's covariance (the prior a scan may refine the lens with) against the spread of the
// intrinsics over 40 noise draws of the same views: each standard deviation within 40% (the
// spread of 40 draws is itself about 11% uncertain).
TEST(ProjectionUncertainty, IntrinsicsCovarianceMatchesTheSpreadOverNoise) {
  constexpr int kDraws = 40;
  constexpr double kSigma = 0.2;
  std::vector<std::vector<double>> draws;
  Eigen::MatrixXd predicted;
  for (int draw = 0; draw < kDraws; ++draw) {
    CameraCalibrationOptions options;
    CameraCalibration calibration;
    CameraCalibrationSummary summary;
    ASSERT_TRUE(CalibrateCamera(options, Board(), NoisyViews(kSigma, 100 + draw), kWidth, kHeight,
                                &calibration, &summary));
    draws.push_back(calibration.intrinsics);
    if (draw == 0) {
      ProjectionUncertainty uncertainty;
      std::string why;
      ASSERT_TRUE(uncertainty.Compute(calibration, &why)) << why;
      predicted = uncertainty.IntrinsicsCovariance();
    }
  }
  const int n = static_cast<int>(draws[0].size());
  ASSERT_EQ(predicted.rows(), n);
  ASSERT_EQ(predicted.cols(), n);
  EXPECT_LT((predicted - predicted.transpose()).norm(), 1e-12 * predicted.norm());
  for (int i = 0; i < n; ++i) {
    double mean = 0.0, squares = 0.0;
    for (const std::vector<double>& d : draws) mean += d[i] / kDraws;
    for (const std::vector<double>& d : draws) squares += (d[i] - mean) * (d[i] - mean);
    const double spread = std::sqrt(squares / (kDraws - 1));
    const double sigma = std::sqrt(predicted(i, i));
    std::printf("intrinsic %d: predicted 1 sigma %.4g, spread over %d draws %.4g\n", i, sigma,
                kDraws, spread);
    EXPECT_GT(sigma, spread / 1.4) << "intrinsic " << i;
    EXPECT_LT(sigma, spread * 1.4) << "intrinsic " << i;
  }
}

// Debian's python3-mrcal installs into Debian's interpreter (not a pyenv or venv python3).
constexpr char kPython[] = "/usr/bin/python3";
bool HaveMrcal() {
  return testing::RunShell(std::string(kPython) + " -c 'import mrcal'").exit_code == 0;
}

// The same solve in mrcal's hands: procam writes camera.cameramodel with the optimization inputs,
// python3-mrcal reads it and computes its projection uncertainty; procam's must agree.
void ExpectMatchesMrcal(const CameraCalibration& calibration) {
  const std::string python = kPython;
  ProjectionUncertainty uncertainty;
  std::string why;
  ASSERT_TRUE(uncertainty.Compute(calibration, &why)) << why;
  testing::TempDir dir;
  WriteCalibrationModel(dir / "camera.cameramodel", calibration);

  const double right = kWidth - 1.0, bottom = kHeight - 1.0, distance = 1.0;
  const std::vector<Vec2> pixels = {{right / 2, bottom / 2}, {0, 0},    {right, 0}, {0, bottom},
                                    {right, bottom},         {100, 350}};
  const char* names[] = {"centre",      "top left",     "top right",
                         "bottom left", "bottom right", "(100, 350)"};
  std::string command = fmt::format(
      "{} {} {} {}", python,
      (testing::SourceDir() / "tests/calibration/projection_uncertainty_mrcal.py").string(),
      (dir / "camera.cameramodel").string(), distance);
  for (const Vec2& q : pixels) command += fmt::format(" {},{}", q.x(), q.y());
  const testing::CommandRun run = testing::RunShell(command);
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json mrcal = nlohmann::json::parse(run.output.substr(run.output.find('{')));

  // procam's inputs are mrcal's optimum: re-solving them moves nothing.
  EXPECT_LT(mrcal["resolve_moved_intrinsics"].get<double>(), 1e-6);
  const double sigma = mrcal["sigma"].get<double>();
  std::printf("sigma: procam %.6f px, mrcal %.6f px\n", uncertainty.observed_pixel_sigma(), sigma);
  EXPECT_NEAR(uncertainty.observed_pixel_sigma(), sigma, 1e-9);
  for (size_t k = 0; k < pixels.size(); ++k) {
    const double procam_infinity = uncertainty.WorstDirectionStdev(pixels[k]);
    const double procam_distance = uncertainty.WorstDirectionStdev(pixels[k], distance);
    const double mrcal_infinity = mrcal["at_infinity"][k].get<double>();
    const double mrcal_distance = mrcal["at_distance"][k].get<double>();
    std::printf(
        "%-12s at infinity: procam %.6f px, mrcal %.6f px; at %.1f m: procam %.6f px, "
        "mrcal %.6f px\n",
        names[k], procam_infinity, mrcal_infinity, distance, procam_distance, mrcal_distance);
    // Same J, same formula: they agree to rounding (measured: 7 digits), so 0.01% is checked.
    EXPECT_NEAR(procam_infinity, mrcal_infinity, 1e-4 * mrcal_infinity) << names[k];
    EXPECT_NEAR(procam_distance, mrcal_distance, 1e-4 * mrcal_distance) << names[k];
    Vec3 direction;
    ASSERT_TRUE(LensModel(calibration.lens_model, calibration.intrinsics)
                    .Unproject(&pixels[k], 1, &direction));
    const Eigen::Matrix2d covariance = uncertainty.Covariance(direction.normalized(), true);
    for (int i = 0; i < 2; ++i) {
      for (int j = 0; j < 2; ++j) {
        EXPECT_NEAR(covariance(i, j), mrcal["covariance_at_infinity"][k][i][j].get<double>(),
                    1e-4 * covariance.trace())
            << names[k];
      }
    }
  }
}

TEST(ProjectionUncertainty, MatchesMrcal) {
  if (!HaveMrcal())
    GTEST_SKIP() << "python3-mrcal is not installed (apt-get install python3-mrcal)";
  ExpectMatchesMrcal(Calibrate(0.2, 5));
}

// Rejected corners (zero rows of J, left out of σ) and the solve without regularisation (where
// mrcal takes its shorter formula σ² (JᵀJ)⁻¹).
TEST(ProjectionUncertainty, MatchesMrcalWithOutliersAndWithoutRegularization) {
  if (!HaveMrcal())
    GTEST_SKIP() << "python3-mrcal is not installed (apt-get install python3-mrcal)";
  ExpectMatchesMrcal(Calibrate(0.2, 11, /*regularization=*/true, /*outliers=*/5));
  ExpectMatchesMrcal(Calibrate(0.2, 13, /*regularization=*/false));
}

}  // namespace
}  // namespace procam
