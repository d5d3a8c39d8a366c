#pragma once
// Colour differences of images, per pixel, and pictures of them: the per-pixel side of
// colour.h, used wherever a rendered or photographed room is compared with what it should look
// like (evaluation, verification, the demo).
//
// Images are OpenCV matrices: linear RGB as CV_32FC3 in R, G, B order (the working space of
// colour.h); L*a*b* as CV_64FC3; ΔE as CV_32FC1; masks as CV_8UC1 (non-zero = compared).

#include <cstdint>
#include <opencv2/core/mat.hpp>
#include <string>

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

// Linear RGB (CV_32FC3, R, G, B, clamped to [0, 1]) → displayable 8-bit sRGB (CV_8UC3, B, G, R
// for OpenCV's writers).
cv::Mat LinearToDisplay(const cv::Mat& linear);
// ΔE (CV_32FC1) → colour heat map from 0 to `max_value` (inferno) with a labelled colour bar on
// the right (CV_8UC3, B, G, R).
cv::Mat HeatMapWithColourBar(const cv::Mat& delta_e, double max_value, const std::string& label);

}  // namespace procam
