#pragma once
// The camera stage's report page (RIG_DIR/camera_report.html): the lens, the residuals, and the
// projection uncertainty drawn over the image with the board corners that pinned it, so that a
// person sees at a glance where the calibration is sure and where more photos are needed.

#include <filesystem>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "calibration/camera_calibration.h"
#include "calibration/projection_uncertainty.h"

namespace procam {

// The map as an 8-bit BGR picture of the image, `scale` output pixels per image pixel (≥ 1):
// every pixel's uncertainty interpolated bilinearly from the map's grid (the grid's nodes sit on
// the image's corner pixels, ProjectionUncertaintyMap), coloured by OpenCV's viridis map from 0
// (dark blue) to `full_scale_px` (yellow; larger values clamp), and every point of `corners`
// (image pixels) marked by a small white dot. Throws std::invalid_argument for an empty grid, a
// size or scale below 1, or full_scale_px ≤ 0.
cv::Mat DrawProjectionUncertainty(const ProjectionUncertaintyMap& map, int width, int height,
                                  int scale, double full_scale_px,
                                  const std::vector<Vec2>& corners);

// Writes `path` (atomically): the lens, the per-view residuals, the uncertainty's numbers and its
// picture (when uncertainty_error is empty), the images whose board was not found.
void WriteCameraReport(const std::filesystem::path& path, const CameraCalibration& calibration,
                       const CameraCalibrationSummary& summary,
                       const std::vector<ChessboardView>& views,
                       const std::vector<std::string>& skipped, const ProjectionUncertaintyMap& map,
                       const std::string& uncertainty_error);

}  // namespace procam
