#include "calibration/camera_report.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

#include <opencv2/imgproc.hpp>

#include "base/html_report.h"
#include "base/image_io.h"

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

std::filesystem::path ProjectorUncertaintyPicture(const std::filesystem::path& dir,
                                                  const std::string& name) {
  return dir / ("projector_uncertainty_" + name + ".png");
}

double UncertaintyFullScale(double largest_px) {
  const double step = std::pow(10.0, std::floor(std::log10(std::max(largest_px, 1e-6))));
  return std::ceil(largest_px / step) * step;
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
    const double full_scale = UncertaintyFullScale(largest);
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

namespace {

// What WriteProjectorsReport shows, whichever calibration gave the maps.
struct ProjectorMaps {
  std::string title, brief_report, what;  // `what` has one {} for the colour scale's top
  std::vector<const ProjectionUncertaintyMap*> maps;
  std::vector<double> distances_m;
};

std::vector<std::filesystem::path> WriteProjectorMaps(const std::filesystem::path& path,
                                                      const std::vector<std::string>& names,
                                                      const RoomCalibrationProblem& problem,
                                                      const ProjectorMaps& in) {
  if (names.size() != problem.projectors.size() || in.maps.size() != problem.projectors.size())
    throw std::invalid_argument("WriteProjectorsReport: one name and one summary per projector");
  HtmlReport report(in.title);
  std::istringstream lines(in.brief_report);
  for (std::string line; std::getline(lines, line);) report.Paragraph(line);
  report.Heading("What the calibration is sure of");
  double largest = 0.0;
  for (const ProjectionUncertaintyMap* map : in.maps)
    for (double v : map->grid) largest = std::max(largest, v);
  std::vector<std::filesystem::path> pictures(names.size());
  if (!(largest > 0.0)) {
    report.Paragraph("Not computed (the calibration's system was singular).");
    report.Write(path);
    return pictures;
  }
  const double full_scale = UncertaintyFullScale(largest);
  report.Paragraph(fmt::format(fmt::runtime(in.what), full_scale));
  std::vector<std::vector<std::string>> rows;
  std::vector<std::pair<std::string, cv::Mat>> figures;
  for (size_t k = 0; k < names.size(); ++k) {
    const ProjectionUncertaintyMap& map = *in.maps[k];
    if (map.grid.empty()) {
      rows.push_back({names[k], "—", "—", "—", "not computed"});
      continue;
    }
    const ProjectorObservations& observations = problem.projectors[k];
    // A random sample (fixed seed): every n-th of the camera-ordered list draws moiré curves.
    std::vector<Vec2> decoded = observations.projector_pixels;
    std::shuffle(decoded.begin(), decoded.end(), std::mt19937(7));
    decoded.resize(std::min<size_t>(decoded.size(), 3000));
    cv::Mat picture = DrawProjectionUncertainty(map, observations.width, observations.height, 1,
                                                full_scale, decoded);
    if (picture.cols > 640) {
      cv::Mat small;
      cv::resize(picture, small, cv::Size(640, std::max(1, picture.rows * 640 / picture.cols)), 0, 0,
                 cv::INTER_AREA);
      picture = small;
    }
    pictures[k] = ProjectorUncertaintyPicture(path.parent_path(), names[k]);
    WritePng(pictures[k], picture);
    rows.push_back({names[k], fmt::format("{:.3f}", map.centre),
                    fmt::format("{:.3f}", *std::max_element(map.corners.begin(), map.corners.end())),
                    fmt::format("{:.3f}", *std::max_element(map.grid.begin(), map.grid.end())),
                    fmt::format("{:.2f} m, σ {:.3f} px", in.distances_m[k],
                                map.observed_pixel_sigma)});
    figures.emplace_back(fmt::format("{}: projection uncertainty ({}×{} pixels)", names[k],
                                     observations.width, observations.height),
                         picture);
  }
  report.Table({"projector", "centre, px", "worst corner, px", "largest on the grid, px",
                "at, from"},
               rows);
  report.Figures(figures);
  report.Write(path);
  return pictures;
}

// Each projector's map and the distance it is taken at, from a calibration summary's
// per-projector entries (`uncertainty`, `uncertainty_distance_m`).
template <typename ProjectorSummaries>
void AddMaps(const ProjectorSummaries& projectors, ProjectorMaps* maps) {
  for (const auto& p : projectors) {
    maps->maps.push_back(&p.uncertainty);
    maps->distances_m.push_back(p.uncertainty_distance_m);
  }
}

}  // namespace

std::vector<std::filesystem::path> WriteProjectorsReport(const std::filesystem::path& path,
                                                         const std::vector<std::string>& names,
                                                         const RoomCalibrationProblem& problem,
                                                         const SelfCalibrationSummary& summary) {
  ProjectorMaps maps;
  maps.title = "procam: projectors from the scan";
  maps.brief_report = summary.BriefReport();
  const bool with_lens = !summary.projectors.empty() &&
                         summary.projectors.front().uncertainty_includes_camera_lens;
  maps.what = std::string(
      "1-σ worst-direction error of where each projector shows a point fixed relative to the "
      "camera, at the median distance of its points, ") +
      (with_lens ? "from decoding noise and the camera lens's own uncertainty (the "
                   "self-calibration's covariance, σ² (JᵀJ, the depths eliminated)⁻¹, plus how the "
                   "projectors move with the lens within the chessboard's covariance). "
                 : "from decoding noise alone (the self-calibration's covariance: σ² (JᵀJ, the "
                   "depths eliminated)⁻¹; no chessboard covariance of the camera's lens was "
                   "given). ") +
      "One colour scale for "
      "all: 0 px (dark blue) to {:g} px (yellow); white dots: the projector pixels decoded. Where "
      "it is large, few decoded points pin the projector's lens: light more of the room the "
      "camera sees with that part of the image.";
  AddMaps(summary.projectors, &maps);
  return WriteProjectorMaps(path, names, problem, maps);
}

std::vector<std::filesystem::path> WriteProjectorsReport(const std::filesystem::path& path,
                                                         const std::vector<std::string>& names,
                                                         const RoomCalibrationProblem& problem,
                                                         const RoomCalibrationSummary& summary) {
  ProjectorMaps maps;
  maps.title = "procam: projectors registered to the room model";
  maps.brief_report = summary.BriefReport();
  maps.what =
      "1-σ worst-direction error of where each projector shows a point fixed in the room, at the "
      "median distance of its points, from decoding noise alone (the joint solve's covariance "
      "σ² (JᵀJ)⁻¹, the camera's pose included; the model's own errors come on top). One colour "
      "scale for all: 0 px (dark blue) to {:g} px (yellow); white dots: the projector pixels "
      "decoded.";
  AddMaps(summary.projectors, &maps);
  return WriteProjectorMaps(path, names, problem, maps);
}

}  // namespace procam
