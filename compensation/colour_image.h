#pragma once
// Colour differences of images, per pixel, and pictures of them: the per-pixel side of
// colour.h, used wherever a rendered or photographed room is compared with what it should look
// like (evaluation, verification, the demo).
//
// Images are OpenCV matrices: linear RGB as CV_32FC3 in R, G, B order (the working space of
// colour.h); L*a*b* as CV_64FC3; ΔE as CV_32FC1; masks as CV_8UC1 (non-zero = compared).

#include <cstdint>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "compensation/colour.h"

namespace procam {

// L*a*b* of every pixel of a linear RGB image (CV_32FC3, R, G, B) with `lab`'s T and white.
cv::Mat LabImage(const cv::Mat& linear_rgb, const LabConverter& lab);

// ΔE76 and CIEDE2000 per pixel of two L*a*b* images, within a mask.
struct ImageDeltaE {
  cv::Mat delta_e76, delta_e2000;                           // CV_32FC1, 0 outside the mask
  double mean76 = 0, max76 = 0, mean2000 = 0, max2000 = 0;  // over the mask (0 if it is empty)
  int64_t pixels = 0;                                       // in the mask
};
// `mask` empty = every pixel. The sums run in row-major order in double precision.
ImageDeltaE CompareLabImages(const cv::Mat& lab_a, const cv::Mat& lab_b, const cv::Mat& mask);

// How visible the patch grid is in an image: the mean CIEDE2000 between 4-neighbouring pixels
// whose patches differ (pairs across a patch border) minus the same for pixels of one patch
// (pairs within patches), counting only pairs that should look alike: both pixels see a patch
// of the same surface, and their desired colours differ by less than `flat_delta_e` CIEDE2000
// (so edges between surfaces and edges of a texture do not count). Light that steps at patch
// borders raises the first mean and not the second; smooth light, noise and dithering raise
// both alike. 0 for an image whose colour varies smoothly (or not at all) over its surfaces;
// for an image whose colour steps by ΔE s at every patch border and is flat within patches, s.
struct SeamOptions {
  // Largest CIEDE2000 between the two pixels' desired colours for a pair to count, > 0.
  double flat_delta_e = 1.0;
  bool Check(std::string* why) const;
};
struct SeamMeasure {
  double across = 0, within = 0;  // mean CIEDE2000 of the pairs (0 when there are none)
  int64_t across_pairs = 0, within_pairs = 0;
  double seam = 0;  // across − within: the metric (0 when either kind of pair is missing)
  // {"seam", "across", "within", "across_pairs", "within_pairs"}: what reports write.
  nlohmann::json Json() const;
};
// `lab`, `lab_desired`: L*a*b* images (CV_64FC3) of what is seen and what should be; `patch`:
// the patch each pixel sees (CV_32SC1, < 0 for none, which is never counted); `patch_surface`:
// the surface of each patch (empty: all on one surface). Throws std::invalid_argument if the
// options fail Check(), the sizes differ, or a patch id is beyond patch_surface.
SeamMeasure MeasureSeams(const cv::Mat& lab, const cv::Mat& lab_desired, const cv::Mat& patch,
                         const std::vector<int>& patch_surface, const SeamOptions& options = {});

// Linear RGB (CV_32FC3, R, G, B, clamped to [0, 1]) → displayable 8-bit sRGB (CV_8UC3, B, G, R
// for OpenCV's writers).
cv::Mat LinearToDisplay(const cv::Mat& linear);
// ΔE (CV_32FC1) → colour heat map from 0 to `max_value` (inferno) with a labelled colour bar on
// the right (CV_8UC3, B, G, R).
cv::Mat HeatMapWithColourBar(const cv::Mat& delta_e, double max_value, const std::string& label);

}  // namespace procam
