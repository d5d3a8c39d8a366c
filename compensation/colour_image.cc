#include "compensation/colour_image.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "geometry/srgb.h"

namespace procam {

cv::Mat LabImage(const cv::Mat& linear_rgb, const LabConverter& lab) {
  CV_Assert(linear_rgb.type() == CV_32FC3);
  cv::Mat result(linear_rgb.rows, linear_rgb.cols, CV_64FC3);
  for (int row = 0; row < linear_rgb.rows; ++row) {
    for (int col = 0; col < linear_rgb.cols; ++col) {
      const cv::Vec3f& v = linear_rgb.at<cv::Vec3f>(row, col);
      const Eigen::Vector3d value = lab.Lab(Eigen::Vector3d(v[0], v[1], v[2]));
      result.at<cv::Vec3d>(row, col) = cv::Vec3d(value[0], value[1], value[2]);
    }
  }
  return result;
}

ImageDeltaE CompareLabImages(const cv::Mat& lab_a, const cv::Mat& lab_b, const cv::Mat& mask) {
  CV_Assert(lab_a.type() == CV_64FC3 && lab_b.type() == CV_64FC3 && lab_a.size() == lab_b.size());
  CV_Assert(mask.empty() || (mask.type() == CV_8UC1 && mask.size() == lab_a.size()));
  ImageDeltaE result;
  result.delta_e76 = cv::Mat::zeros(lab_a.rows, lab_a.cols, CV_32FC1);
  result.delta_e2000 = cv::Mat::zeros(lab_a.rows, lab_a.cols, CV_32FC1);
  double sum76 = 0, sum2000 = 0;
  for (int row = 0; row < lab_a.rows; ++row) {
    for (int col = 0; col < lab_a.cols; ++col) {
      if (!mask.empty() && mask.at<uchar>(row, col) == 0) continue;
      const cv::Vec3d& a = lab_a.at<cv::Vec3d>(row, col);
      const cv::Vec3d& b = lab_b.at<cv::Vec3d>(row, col);
      const Eigen::Vector3d lab1(a[0], a[1], a[2]), lab2(b[0], b[1], b[2]);
      const double e76 = DeltaE76(lab1, lab2), e2000 = DeltaE2000(lab1, lab2);
      result.delta_e76.at<float>(row, col) = static_cast<float>(e76);
      result.delta_e2000.at<float>(row, col) = static_cast<float>(e2000);
      sum76 += e76;
      sum2000 += e2000;
      result.max76 = std::max(result.max76, e76);
      result.max2000 = std::max(result.max2000, e2000);
      ++result.pixels;
    }
  }
  if (result.pixels > 0) {
    result.mean76 = sum76 / result.pixels;
    result.mean2000 = sum2000 / result.pixels;
  }
  return result;
}

bool SeamOptions::Check(std::string* why) const {
  if (!(flat_delta_e > 0.0)) {
    *why = "flat_delta_e must be > 0";
    return false;
  }
  return true;
}

nlohmann::json SeamMeasure::Json() const {
  return {{"seam", seam},
          {"across", across},
          {"within", within},
          {"across_pairs", across_pairs},
          {"within_pairs", within_pairs}};
}

SeamMeasure MeasureSeams(const cv::Mat& lab, const cv::Mat& lab_desired, const cv::Mat& patch,
                         const std::vector<int>& patch_surface, const SeamOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("SeamOptions: " + why);
  if (lab.type() != CV_64FC3 || lab_desired.type() != CV_64FC3 || patch.type() != CV_32SC1 ||
      lab.size() != lab_desired.size() || lab.size() != patch.size()) {
    throw std::invalid_argument(
        "MeasureSeams: need L*a*b* images (CV_64FC3) and patch ids (CV_32SC1) of one size");
  }
  const int surfaces_known = static_cast<int>(patch_surface.size());
  const auto surface_of = [&](int id) {
    if (surfaces_known == 0) return 0;
    if (id >= surfaces_known) {
      throw std::invalid_argument("MeasureSeams: patch " + std::to_string(id) + " of " +
                                  std::to_string(surfaces_known) + " with a known surface");
    }
    return patch_surface[id];
  };
  double across_sum = 0, within_sum = 0;
  SeamMeasure result;
  const auto add_pair = [&](int row_a, int col_a, int row_b, int col_b) {
    const int id_a = patch.at<int32_t>(row_a, col_a), id_b = patch.at<int32_t>(row_b, col_b);
    if (id_a < 0 || id_b < 0 || surface_of(id_a) != surface_of(id_b)) return;
    const cv::Vec3d& da = lab_desired.at<cv::Vec3d>(row_a, col_a);
    const cv::Vec3d& db = lab_desired.at<cv::Vec3d>(row_b, col_b);
    if (!(DeltaE2000(Eigen::Vector3d(da[0], da[1], da[2]), Eigen::Vector3d(db[0], db[1], db[2])) <
          options.flat_delta_e)) {
      return;
    }
    const cv::Vec3d& a = lab.at<cv::Vec3d>(row_a, col_a);
    const cv::Vec3d& b = lab.at<cv::Vec3d>(row_b, col_b);
    const double difference =
        DeltaE2000(Eigen::Vector3d(a[0], a[1], a[2]), Eigen::Vector3d(b[0], b[1], b[2]));
    if (id_a != id_b) {
      across_sum += difference;
      ++result.across_pairs;
    } else {
      within_sum += difference;
      ++result.within_pairs;
    }
  };
  for (int row = 0; row < lab.rows; ++row) {
    for (int col = 0; col < lab.cols; ++col) {
      if (col + 1 < lab.cols) add_pair(row, col, row, col + 1);
      if (row + 1 < lab.rows) add_pair(row, col, row + 1, col);
    }
  }
  if (result.across_pairs > 0) result.across = across_sum / result.across_pairs;
  if (result.within_pairs > 0) result.within = within_sum / result.within_pairs;
  if (result.across_pairs > 0 && result.within_pairs > 0)
    result.seam = result.across - result.within;
  return result;
}

cv::Mat LinearToDisplay(const cv::Mat& linear) {
  cv::Mat display(linear.rows, linear.cols, CV_8UC3);
  for (int row = 0; row < linear.rows; ++row) {
    for (int col = 0; col < linear.cols; ++col) {
      const cv::Vec3f& v = linear.at<cv::Vec3f>(row, col);
      cv::Vec3b& out = display.at<cv::Vec3b>(row, col);
      for (int c = 0; c < 3; ++c) {
        out[2 - c] = static_cast<uchar>(
            std::lround(255.0 * LinearToSrgb(std::clamp(double(v[c]), 0.0, 1.0))));
      }
    }
  }
  return display;
}

cv::Mat HeatMapWithColourBar(const cv::Mat& delta_e, double max_value, const std::string& label) {
  cv::Mat scaled;
  delta_e.convertTo(scaled, CV_8UC1, 255.0 / max_value);
  cv::Mat heat;
  cv::applyColorMap(scaled, heat, cv::COLORMAP_INFERNO);
  // Text sized to the picture, so it stays readable where a report shows the picture at half
  // its width: about 1/40 of the height, never below 0.5 (≈ 11 px).
  const int face = cv::FONT_HERSHEY_SIMPLEX;
  const double font = std::max(0.5, heat.rows / 640.0 * 0.7);
  const int thickness = font >= 0.9 ? 2 : 1;
  std::vector<std::string> ticks;
  int widest = cv::getTextSize(label, face, font, thickness, nullptr).width;
  for (int tick = 0; tick <= 4; ++tick) {
    ticks.push_back(fmt::format("{:.3g}", max_value * tick / 4));
    widest = std::max(widest, cv::getTextSize(ticks.back(), face, font, thickness, nullptr).width);
  }
  int baseline = 0;
  const int text_height = cv::getTextSize("0", face, font, thickness, &baseline).height;
  const int margin = text_height, bar_thickness = 2 * text_height;
  const int bar_width = std::max(margin + bar_thickness + margin / 2 + widest + margin, widest + 2 * margin);
  cv::Mat canvas(heat.rows, heat.cols + bar_width, CV_8UC3, cv::Scalar(255, 255, 255));
  heat.copyTo(canvas(cv::Rect(0, 0, heat.cols, heat.rows)));
  const int top = 3 * text_height, bottom = heat.rows - text_height;
  if (bottom - top < 2) return canvas;  // too small a picture for a bar
  cv::Mat ramp(bottom - top, 1, CV_8UC1);
  for (int k = 0; k < ramp.rows; ++k)
    ramp.at<uchar>(k, 0) = static_cast<uchar>(255 - 255 * k / std::max(1, ramp.rows - 1));
  cv::Mat ramp_colour;
  cv::applyColorMap(ramp, ramp_colour, cv::COLORMAP_INFERNO);
  cv::resize(ramp_colour, ramp_colour, cv::Size(bar_thickness, ramp.rows), 0, 0, cv::INTER_NEAREST);
  const int bar_left = heat.cols + margin;
  ramp_colour.copyTo(canvas(cv::Rect(bar_left, top, bar_thickness, ramp.rows)));
  for (int tick = 0; tick <= 4; ++tick) {
    const int y = bottom - (bottom - top) * tick / 4;
    cv::line(canvas, cv::Point(bar_left + bar_thickness, y), cv::Point(bar_left + bar_thickness + margin / 3, y),
             cv::Scalar(0, 0, 0), thickness);
    cv::putText(canvas, ticks[tick], cv::Point(bar_left + bar_thickness + margin / 2, y + text_height / 2), face,
                font, cv::Scalar(0, 0, 0), thickness, cv::LINE_AA);
  }
  cv::putText(canvas, label, cv::Point(heat.cols + margin / 2, 2 * text_height - baseline / 2), face, font,
              cv::Scalar(0, 0, 0), thickness, cv::LINE_AA);
  return canvas;
}

}  // namespace procam
