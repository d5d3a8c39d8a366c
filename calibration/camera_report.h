#pragma once
// The calibration's report pages: the camera stage's (RIG_DIR/camera_report.html: the lens, the
// residuals, and the projection uncertainty drawn over the image with the board corners that
// pinned it), so that a person sees at a glance where the calibration is sure and where more
// photos are needed; and a scan's (RIG_DIR/projectors_report.html: each projector's projection
// uncertainty from the self-calibration, drawn the same way over the projector's image).

#include <filesystem>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "calibration/camera_calibration.h"
#include "calibration/projection_uncertainty.h"
#include "calibration/registration.h"
#include "calibration/self_calibration.h"

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

// Where WriteProjectorsReport draws projector `name`'s map: DIR/projector_uncertainty_NAME.png.
std::filesystem::path ProjectorUncertaintyPicture(const std::filesystem::path& dir,
                                                  const std::string& name);

// The top of a map's colour scale: the largest value rounded up to one significant step, so
// that two reports of the same device compare by eye.
double UncertaintyFullScale(double largest_px);

// Writes `path` (atomically) and, beside it, projector_uncertainty_NAME.png for each projector
// with a map: the calibration's numbers, each projector's map (one colour scale for all) with the
// projector pixels of its decoded correspondences (at most 3000 drawn). `names` one per
// projector of `problem`. Returns the pictures' paths, in projector order ("" where none). For
// a scan (the self-calibration's maps: a point fixed relative to the camera) and for a rig
// registered to a room model (the joint solve's: a point fixed in the room).
std::vector<std::filesystem::path> WriteProjectorsReport(const std::filesystem::path& path,
                                                         const std::vector<std::string>& names,
                                                         const RoomCalibrationProblem& problem,
                                                         const SelfCalibrationSummary& summary);
std::vector<std::filesystem::path> WriteProjectorsReport(const std::filesystem::path& path,
                                                         const std::vector<std::string>& names,
                                                         const RoomCalibrationProblem& problem,
                                                         const RoomCalibrationSummary& summary);

}  // namespace procam
