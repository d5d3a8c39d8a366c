#include "compensation/colour_image.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include <cmath>
#include <stdexcept>

namespace procam {
namespace {

constexpr int kSide = 60, kPatchSide = 10, kPatchesPerRow = kSide / kPatchSide;

// A kSide × kSide image tiled by kPatchSide × kPatchSide patches, numbered row-major.
cv::Mat PatchGrid() {
  cv::Mat patch(kSide, kSide, CV_32SC1);
  for (int row = 0; row < kSide; ++row) {
    for (int col = 0; col < kSide; ++col)
      patch.at<int32_t>(row, col) = (row / kPatchSide) * kPatchesPerRow + col / kPatchSide;
  }
  return patch;
}

// L*a*b* image with L = lightness(row, col) and a fixed chroma (a, b) = (5, −3).
template <typename Lightness>
cv::Mat LabOf(Lightness lightness) {
  cv::Mat lab(kSide, kSide, CV_64FC3);
  for (int row = 0; row < kSide; ++row) {
    for (int col = 0; col < kSide; ++col)
      lab.at<cv::Vec3d>(row, col) = {lightness(row, col), 5, -3};
  }
  return lab;
}

const cv::Mat kFlatDesired = LabOf([](int, int) { return 60.0; });

// Steps of a known CIEDE2000 at every patch border, flat within patches: the metric is the step.
TEST(MeasureSeams, CheckerboardOfPatchesGivesItsStep) {
  const cv::Mat seen = LabOf([](int row, int col) {
    return ((row / kPatchSide + col / kPatchSide) % 2) == 0 ? 50.0 : 52.0;
  });
  const double step = DeltaE2000(Eigen::Vector3d(50, 5, -3), Eigen::Vector3d(52, 5, -3));
  const SeamMeasure seams = MeasureSeams(seen, kFlatDesired, PatchGrid(), {});
  EXPECT_NEAR(seams.across, step, 1e-12);
  EXPECT_EQ(seams.within, 0.0);
  EXPECT_NEAR(seams.seam, step, 1e-12);
  // 5 borders per direction, each kSide pairs long.
  EXPECT_EQ(seams.across_pairs, 2 * 5 * kSide);
  EXPECT_EQ(seams.within_pairs, 2 * kSide * (kSide - 1) - 2 * 5 * kSide);
}

// A smooth gradient steps as much across borders as within patches: no seam.
TEST(MeasureSeams, SmoothImageHasNoSeam) {
  const cv::Mat seen = LabOf([](int row, int col) { return 40.0 + 0.3 * (row + col); });
  const SeamMeasure seams = MeasureSeams(seen, kFlatDesired, PatchGrid(), {});
  EXPECT_GT(seams.within, 0.2);
  EXPECT_LT(std::abs(seams.seam), 0.01 * seams.within);  // S_L varies a little with L
}

// Steps that the desired appearance has (a texture edge) or that lie between surfaces are not
// seams: their pairs are left out.
TEST(MeasureSeams, DesiredEdgesAndSurfaceEdgesDoNotCount) {
  const auto checkerboard = [](int row, int col) {
    return ((row / kPatchSide + col / kPatchSide) % 2) == 0 ? 50.0 : 52.0;
  };
  const cv::Mat seen = LabOf(checkerboard);
  const SeamMeasure textured = MeasureSeams(seen, LabOf(checkerboard), PatchGrid(), {});
  EXPECT_EQ(textured.across_pairs, 0);
  EXPECT_EQ(textured.seam, 0.0);
  // Every patch its own surface: only pairs within patches remain.
  std::vector<int> own_surface(kPatchesPerRow * kPatchesPerRow);
  for (size_t i = 0; i < own_surface.size(); ++i) own_surface[i] = static_cast<int>(i);
  const SeamMeasure separate = MeasureSeams(seen, kFlatDesired, PatchGrid(), own_surface);
  EXPECT_EQ(separate.across_pairs, 0);
  EXPECT_GT(separate.within_pairs, 0);
  // One surface per row of patches: only the vertical borders (steps along a row) count.
  std::vector<int> row_surface(own_surface.size());
  for (size_t i = 0; i < row_surface.size(); ++i)
    row_surface[i] = static_cast<int>(i) / kPatchesPerRow;
  const SeamMeasure rows = MeasureSeams(seen, kFlatDesired, PatchGrid(), row_surface);
  EXPECT_EQ(rows.across_pairs, 5 * kSide);
  EXPECT_NEAR(rows.seam, DeltaE2000(Eigen::Vector3d(50, 5, -3), Eigen::Vector3d(52, 5, -3)), 1e-12);
}

TEST(MeasureSeams, PixelsWithoutPatchAreLeftOut) {
  cv::Mat patch = PatchGrid();
  patch.setTo(-1);
  const SeamMeasure seams = MeasureSeams(kFlatDesired, kFlatDesired, patch, {});
  EXPECT_EQ(seams.across_pairs + seams.within_pairs, 0);
  EXPECT_EQ(seams.seam, 0.0);
}

TEST(MeasureSeams, RejectsBadInput) {
  EXPECT_THROW(MeasureSeams(kFlatDesired, kFlatDesired, cv::Mat(3, 3, CV_32SC1, cv::Scalar(0)), {}),
               std::invalid_argument);
  SeamOptions options;
  options.flat_delta_e = 0.0;
  EXPECT_THROW(MeasureSeams(kFlatDesired, kFlatDesired, PatchGrid(), {}, options),
               std::invalid_argument);
  EXPECT_THROW(MeasureSeams(kFlatDesired, kFlatDesired, PatchGrid(), {0, 1}),
               std::invalid_argument);
}

// The heat map keeps the picture's colours (inferno of ΔE / max), and its bar runs from inferno(0)
// at the bottom to inferno(255) at the top with dark tick text beside it, at a size that grows
// with the picture.
TEST(HeatMapWithColourBar, PictureBarAndLabelsScaleWithTheImage) {
  int previous_bar_width = 0;
  for (const int rows : {120, 640, 1280}) {
    cv::Mat delta_e(rows, rows * 3 / 2, CV_32FC1);
    for (int row = 0; row < delta_e.rows; ++row)
      for (int col = 0; col < delta_e.cols; ++col) delta_e.at<float>(row, col) = 20.0f * col / delta_e.cols;
    const cv::Mat canvas = HeatMapWithColourBar(delta_e, 20.0, "dE00");
    ASSERT_EQ(canvas.rows, rows);
    const int bar_width = canvas.cols - delta_e.cols;
    EXPECT_GT(bar_width, previous_bar_width) << rows;
    previous_bar_width = bar_width;
    cv::Mat expected_scaled, expected;
    delta_e.convertTo(expected_scaled, CV_8UC1, 255.0 / 20.0);
    cv::applyColorMap(expected_scaled, expected, cv::COLORMAP_INFERNO);
    EXPECT_EQ(cv::norm(canvas(cv::Rect(0, 0, delta_e.cols, rows)), expected, cv::NORM_INF), 0.0) << rows;
    // The bar: the brightest and darkest inferno colours in its column, top and bottom.
    cv::Mat ends(2, 1, CV_8UC1), ends_colour;
    ends.at<uchar>(0, 0) = 255;
    ends.at<uchar>(1, 0) = 0;
    cv::applyColorMap(ends, ends_colour, cv::COLORMAP_INFERNO);
    const cv::Mat bar = canvas(cv::Rect(delta_e.cols, 0, bar_width, rows));
    int top_hits = 0, bottom_hits = 0, dark = 0;
    for (int row = 0; row < rows; ++row) {
      for (int col = 0; col < bar_width; ++col) {
        const cv::Vec3b& p = bar.at<cv::Vec3b>(row, col);
        top_hits += row < rows / 2 && p == ends_colour.at<cv::Vec3b>(0, 0);
        bottom_hits += row >= rows / 2 && p == ends_colour.at<cv::Vec3b>(1, 0);
        dark += p[0] < 60 && p[1] < 60 && p[2] < 60;
      }
    }
    EXPECT_GT(top_hits, 0) << rows;
    EXPECT_GT(bottom_hits, 0) << rows;
    // The text (five ticks and the label) covers more pixels on a larger picture.
    EXPECT_GT(dark, rows / 4) << rows;
  }
}

}  // namespace
}  // namespace procam
