#include "calibration/camera_report.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <opencv2/imgproc.hpp>

#include "base/html_report.h"

namespace procam {

cv::Mat DrawProjectionUncertainty(const ProjectionUncertaintyMap& map, int width, int height,
                                  int scale, double full_scale_px,
                                  const std::vector<Vec2>& corners) {
  if (map.grid_width < 2 || map.grid_height < 2 ||
      map.grid.size() != static_cast<size_t>(map.grid_width) * map.grid_height)
    throw std::invalid_argument("DrawProjectionUncertainty: no grid");
  if (width < 2 || height < 2 || scale < 1 || !(full_scale_px > 0.0))
    throw std::invalid_argument(
        "DrawProjectionUncertainty: need width, height ≥ 2, scale ≥ 1, full_scale_px > 0");
  cv::Mat level(height * scale, width * scale, CV_8UC1);
  for (int row = 0; row < level.rows; ++row) {
    // The output pixel's centre in image pixels, then in grid units (node i at x = i (W−1)/(n−1)).
    const double y = (row + 0.5) / scale - 0.5;
    const double gy = std::clamp(y * (map.grid_height - 1) / (height - 1.0), 0.0,
                                 map.grid_height - 1.0);
    const int j = std::min(static_cast<int>(gy), map.grid_height - 2);
    const double fy = gy - j;
    for (int col = 0; col < level.cols; ++col) {
      const double x = (col + 0.5) / scale - 0.5;
      const double gx = std::clamp(x * (map.grid_width - 1) / (width - 1.0), 0.0,
                                   map.grid_width - 1.0);
      const int i = std::min(static_cast<int>(gx), map.grid_width - 2);
      const double fx = gx - i;
      const auto at = [&](int a, int b) { return map.grid[b * map.grid_width + a]; };
      const double value = (1 - fy) * ((1 - fx) * at(i, j) + fx * at(i + 1, j)) +
                           fy * ((1 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1));
      level.at<uint8_t>(row, col) = cv::saturate_cast<uint8_t>(
          std::round(255.0 * std::clamp(value / full_scale_px, 0.0, 1.0)));
    }
  }
  cv::Mat picture;
  cv::applyColorMap(level, picture, cv::COLORMAP_VIRIDIS);
  for (const Vec2& corner : corners) {
    const cv::Point centre(static_cast<int>(std::lround((corner.x() + 0.5) * scale - 0.5)),
                           static_cast<int>(std::lround((corner.y() + 0.5) * scale - 0.5)));
    cv::circle(picture, centre, std::max(1, scale / 2), cv::Scalar(255, 255, 255), cv::FILLED);
  }
  return picture;
}

void WriteCameraReport(const std::filesystem::path& path, const CameraCalibration& calibration,
                       const CameraCalibrationSummary& summary,
                       const std::vector<ChessboardView>& views,
                       const std::vector<std::string>& skipped, const ProjectionUncertaintyMap& map,
                       const std::string& uncertainty_error) {
  HtmlReport report("procam: camera calibration");
  std::string lens = calibration.lens_model + ", " + std::to_string(calibration.width) + " × " +
                     std::to_string(calibration.height) + " pixels; intrinsics";
  for (double v : calibration.intrinsics) lens += fmt::format(" {:.6g}", v);
  report.Paragraph(lens);
  report.Paragraph(summary.BriefReport());

  report.Heading("What the calibration is sure of");
  if (uncertainty_error.empty()) {
    const double largest = *std::max_element(map.grid.begin(), map.grid.end());
    // The colour scale's top: the largest value rounded up to one significant step, so that two
    // reports of the same camera compare by eye.
    const double step = std::pow(10.0, std::floor(std::log10(std::max(largest, 1e-6))));
    const double full_scale = std::ceil(largest / step) * step;
    std::vector<Vec2> corners;
    for (const ChessboardView& view : views)
      corners.insert(corners.end(), view.corners.begin(), view.corners.end());
    const int scale = std::max(1, static_cast<int>(std::lround(640.0 / calibration.width)));
    report.Paragraph(fmt::format(
        "1-σ worst-direction projection error of a point at infinity from calibration noise "
        "alone (mrcal's projection uncertainty, corner noise σ {:.3f} px): centre {:.3f} px; "
        "corners {:.3f}, {:.3f}, {:.3f}, {:.3f} px (top left, top right, bottom left, bottom "
        "right); largest on the {}×{} grid {:.3f} px. Where it is large, photos with the board "
        "in that part of the image bring it down.",
        map.observed_pixel_sigma, map.centre, map.corners[0], map.corners[1], map.corners[2],
        map.corners[3], map.grid_width, map.grid_height, largest));
    report.Figures({{fmt::format("projection uncertainty over the image, 0 px (dark blue) to "
                                 "{:g} px (yellow); white dots: the {} board corners used",
                                 full_scale, corners.size()),
                     DrawProjectionUncertainty(map, calibration.width, calibration.height, scale,
                                               full_scale, corners)}});
  } else {
    report.Paragraph("Not computed: " + uncertainty_error);
  }

  report.Heading("Views");
  std::vector<std::vector<std::string>> rows;
  for (size_t v = 0; v < views.size(); ++v)
    rows.push_back({views[v].name, v < summary.view_rms.size()
                                       ? fmt::format("{:.4f}", summary.view_rms[v])
                                       : std::string("-")});
  for (const std::string& name : skipped) rows.push_back({name, "board not found"});
  report.Table({"image", "RMS per coordinate, px"}, rows);
  report.Write(path);
}

}  // namespace procam
