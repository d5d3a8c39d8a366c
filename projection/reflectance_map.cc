#include "projection/reflectance_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>
#include <vector>

#include "base/image_io.h"
#include "base/io.h"
#include "geometry/ray_scene.h"
#include "geometry/srgb.h"
#include "projection/projection_rig.h"

namespace procam {

bool ReflectanceMapOptions::Check(std::string* why) const {
  if (min_patch_pixels < 1) {
    *why = "min_patch_pixels: must be >= 1";
    return false;
  }
  if (!(min_weight > 0.0 && min_weight <= 1.0)) {
    *why = "min_weight: must be in (0, 1]";
    return false;
  }
  if (!(ray_margin > 0.0)) {
    *why = "ray_margin: must be > 0";
    return false;
  }
  return true;
}

ReflectanceMap EstimateReflectanceMap(
    const PatchLevel& level, const ProjectorGeometry& projector, const ProjectorGeometry& camera,
    const CameraPixelLighting& lighting, const ReflectanceEstimate& estimate,
    const cv::Mat& difference, const cv::Mat& mask, const Eigen::Vector3d& output,
    const Eigen::Vector3d& camera_scale, const ReflectanceMapOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("reflectance map: " + why);
  const int n = level.size();
  const int cw = lighting.width, ch = lighting.height;
  if (difference.type() != CV_32FC3 || difference.cols != cw || difference.rows != ch ||
      (!mask.empty() && mask.size() != difference.size()) ||
      lighting.patch.size() != static_cast<size_t>(cw) * ch || estimate.reflectance.rows() != n ||
      estimate.bounce_irradiance.rows() != n || estimate.pixels.size() != static_cast<size_t>(n) ||
      camera.width() != cw || camera.height() != ch) {
    throw std::invalid_argument(
        "reflectance map: the camera's image, lighting and estimate differ in size");
  }
  const auto seen = [&](int i) { return estimate.pixels[i] >= options.min_patch_pixels; };

  // Per camera pixel: measured exitance over modelled irradiance (header comment).
  std::vector<Vec3> ratio(static_cast<size_t>(cw) * ch, Vec3::Zero());
  std::vector<uint8_t> usable(ratio.size(), 0);
  for (int row = 0; row < ch; ++row) {
    for (int col = 0; col < cw; ++col) {
      const size_t index = static_cast<size_t>(row) * cw + col;
      const int i = lighting.patch[index];
      if (i < 0 || !seen(i) || !(lighting.gain[index] > 0.0)) continue;
      if (!mask.empty() && mask.at<uchar>(row, col) == 0) continue;
      const cv::Vec3f& value = difference.at<cv::Vec3f>(row, col);
      bool ok = true;
      for (int c = 0; c < 3; ++c) {
        const double irradiance =
            lighting.gain[index] * output[c] + estimate.bounce_irradiance(i, c);
        if (!(irradiance > 0.0)) ok = false;
        ratio[index][c] = value[2 - c] / camera_scale[c] / irradiance;
      }
      usable[index] = ok ? 1 : 0;
    }
  }

  // Per projector pixel: the point its ray lights, seen through the camera.
  const int pw = projector.width(), ph = projector.height();
  ReflectanceMap map;
  map.reflectance = cv::Mat(ph, pw, CV_32FC3, cv::Scalar::all(0));
  map.measured = cv::Mat(ph, pw, CV_8UC1, cv::Scalar(0));
  map.patch = cv::Mat(ph, pw, CV_32SC1, cv::Scalar(-1));
  std::vector<Vec3> raw(static_cast<size_t>(pw) * ph, Vec3::Zero());
  const RayScene patches(PatchScene(level));
  std::vector<Vec3> directions;
  std::vector<double> densities;
  projector.UnprojectImage(&directions, &densities);
  const Eigen::Isometry3d world_from_proj = projector.proj_from_world().inverse();
  const Vec3 origin = world_from_proj.translation();
  for (int row = 0; row < ph; ++row) {
    for (int col = 0; col < pw; ++col) {
      const size_t index = static_cast<size_t>(row) * pw + col;
      const Vec3 direction = world_from_proj.linear() * directions[index];
      double t = 0.0;
      int i = -1;
      if (!patches.Intersect(origin, direction, 0.0, std::numeric_limits<double>::infinity(), &t,
                             &i))
        continue;
      const Vec3 point = origin + t * direction;
      if (level.patches[i].normal.dot(origin - point) <= 0.0) continue;  // its unlit side
      map.patch.at<int32_t>(row, col) = i;
      if (!seen(i)) continue;
      Vec2 pixel;
      if (!camera.Project(point, &pixel) || !camera.InImage(pixel)) continue;
      const int x0 = static_cast<int>(std::floor(pixel.x())),
                y0 = static_cast<int>(std::floor(pixel.y()));
      const double fx = pixel.x() - x0, fy = pixel.y() - y0;
      Vec3 sum = Vec3::Zero();
      double weight_sum = 0.0;
      for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) {
          const int x = x0 + dx, y = y0 + dy;
          if (x < 0 || x >= cw || y < 0 || y >= ch) continue;
          const size_t camera_index = static_cast<size_t>(y) * cw + x;
          if (!usable[camera_index]) continue;
          // A camera pixel on another surface sees an occluder or the far side of an edge.
          if (level.patches[lighting.patch[camera_index]].surface != level.patches[i].surface)
            continue;
          const double weight = (dx ? fx : 1.0 - fx) * (dy ? fy : 1.0 - fy);
          sum += weight * ratio[camera_index];
          weight_sum += weight;
        }
      }
      if (weight_sum < options.min_weight) continue;
      raw[index] = sum / weight_sum;
      map.measured.at<uchar>(row, col) = 255;
    }
  }

  // Normalisation: per seen patch and channel, one scale s on its measured pixels such that the
  // mean of clamp(s · r, 0, 0.99) is the estimate's ρ_i (bisection: the sum is non-decreasing
  // in s), so that the clamp does not move the patch's mean.
  std::vector<std::vector<size_t>> measured_of(n);
  for (int row = 0; row < ph; ++row) {
    for (int col = 0; col < pw; ++col) {
      if (map.measured.at<uchar>(row, col)) {
        measured_of[map.patch.at<int32_t>(row, col)].push_back(static_cast<size_t>(row) * pw + col);
      }
    }
  }
  constexpr double kMaxReflectance = 0.99;
  Eigen::MatrixX3d scale = Eigen::MatrixX3d::Zero(n, 3);
  for (int i = 0; i < n; ++i) {
    const std::vector<size_t>& pixels = measured_of[i];
    if (pixels.empty()) continue;
    for (int c = 0; c < 3; ++c) {
      const auto clamped_sum = [&](double s) {
        double sum = 0.0;
        for (const size_t index : pixels)
          sum += std::clamp(s * raw[index][c], 0.0, kMaxReflectance);
        return sum;
      };
      const double target = estimate.reflectance(i, c) * pixels.size();
      double raw_sum = 0.0;
      for (const size_t index : pixels) raw_sum += std::max(0.0, raw[index][c]);
      if (!(raw_sum > 0.0)) continue;
      double low = 0.0, high = target / raw_sum;
      for (int k = 0; k < 60 && clamped_sum(high) < target; ++k) high *= 2.0;
      for (int k = 0; k < 60; ++k) {
        const double middle = 0.5 * (low + high);
        (clamped_sum(middle) < target ? low : high) = middle;
      }
      scale(i, c) = 0.5 * (low + high);
    }
  }
  for (int row = 0; row < ph; ++row) {
    for (int col = 0; col < pw; ++col) {
      const int i = map.patch.at<int32_t>(row, col);
      if (i < 0) continue;
      ++map.lit_pixels;
      const bool measured = map.measured.at<uchar>(row, col) != 0;
      cv::Vec3f& value = map.reflectance.at<cv::Vec3f>(row, col);
      for (int c = 0; c < 3; ++c) {
        const double v = measured && scale(i, c) > 0.0
                             ? scale(i, c) * raw[static_cast<size_t>(row) * pw + col][c]
                             : estimate.reflectance(i, c);
        value[c] = static_cast<float>(std::clamp(v, 0.0, kMaxReflectance));
      }
      if (measured) ++map.measured_pixels;
    }
  }
  return map;
}

std::string ReflectanceMapFile(const std::string& projector) {
  return projector + ".reflectance_map.png";
}

void WriteReflectanceMap(const std::filesystem::path& rig_dir, const std::string& projector,
                         const ReflectanceMap& map, RigReflectanceMap* entry) {
  const std::filesystem::path path = rig_dir / ReflectanceMapFile(projector);
  cv::Mat bgr(map.reflectance.size(), CV_16UC3);
  for (int row = 0; row < bgr.rows; ++row) {
    const cv::Vec3f* in = map.reflectance.ptr<cv::Vec3f>(row);
    cv::Vec3w* out = bgr.ptr<cv::Vec3w>(row);
    for (int col = 0; col < bgr.cols; ++col) {
      for (int c = 0; c < 3; ++c) {
        out[col][2 - c] = cv::saturate_cast<ushort>(
            std::lround(65535.0 * std::clamp<double>(in[col][c], 0.0, 1.0)));
      }
    }
  }
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", bgr, bytes)) throw IoError(path.string() + ": cannot encode PNG");
  std::filesystem::create_directories(rig_dir);
  WriteFileAtomically(path, std::string(bytes.begin(), bytes.end()));
  entry->file = ReflectanceMapFile(projector);
  entry->width = map.reflectance.cols;
  entry->height = map.reflectance.rows;
  entry->lit_pixels = map.lit_pixels;
  entry->measured_pixels = map.measured_pixels;
}

cv::Mat ReadReflectanceMap(const std::filesystem::path& rig_dir, const std::string& projector,
                           const RigReflectanceMap& entry) {
  const std::filesystem::path path = rig_dir / entry.file;
  if (!std::filesystem::exists(path)) {
    throw IoError((rig_dir / "rig.json").string() + ": reflectance_maps." + projector +
                  ".file: " + path.string() + ": file not found");
  }
  const cv::Mat image = ReadImage(path, cv::IMREAD_UNCHANGED);
  if (image.depth() != CV_16U || image.channels() != 3) {
    throw IoError(path.string() + ": a reflectance map must be a 16-bit RGB PNG");
  }
  if (image.cols != entry.width || image.rows != entry.height) {
    throw IoError(path.string() + ": " + std::to_string(image.cols) + "x" +
                  std::to_string(image.rows) + ", rig.json's reflectance_maps." + projector +
                  " says " + std::to_string(entry.width) + "x" + std::to_string(entry.height));
  }
  cv::Mat rgb(image.size(), CV_32FC3);
  for (int row = 0; row < image.rows; ++row) {
    const cv::Vec3w* in = image.ptr<cv::Vec3w>(row);
    cv::Vec3f* out = rgb.ptr<cv::Vec3f>(row);
    for (int col = 0; col < image.cols; ++col) {
      for (int c = 0; c < 3; ++c) out[col][c] = static_cast<float>(in[col][2 - c] / 65535.0);
    }
  }
  return rgb;
}

std::vector<cv::Mat> ReadRigReflectanceMaps(const RigDirectory& rig) {
  std::vector<cv::Mat> maps;
  for (const Projector& projector : rig.projectors) {
    const auto entry = rig.file.reflectance_maps.find(projector.name);
    if (entry == rig.file.reflectance_maps.end()) return {};
  }
  for (const Projector& projector : rig.projectors) {
    const RigReflectanceMap& entry = rig.file.reflectance_maps.at(projector.name);
    if (entry.width != projector.geometry.width() || entry.height != projector.geometry.height()) {
      throw IoError((rig.dir / "rig.json").string() + ": reflectance_maps." + projector.name +
                    ": " + std::to_string(entry.width) + "x" + std::to_string(entry.height) +
                    " but the projector's model is " + std::to_string(projector.geometry.width()) +
                    "x" + std::to_string(projector.geometry.height()));
    }
    maps.push_back(ReadReflectanceMap(rig.dir, projector.name, entry));
  }
  return maps;
}

cv::Mat DrawReflectanceMap(const ReflectanceMap& map) {
  cv::Mat picture(map.reflectance.size(), CV_8UC3, cv::Scalar::all(0));
  for (int row = 0; row < picture.rows; ++row) {
    for (int col = 0; col < picture.cols; ++col) {
      const cv::Vec3f& value = map.reflectance.at<cv::Vec3f>(row, col);
      cv::Vec3b& out = picture.at<cv::Vec3b>(row, col);
      for (int c = 0; c < 3; ++c) {
        out[2 - c] = cv::saturate_cast<uchar>(
            std::lround(255.0 * LinearToSrgb(std::clamp<double>(value[c], 0.0, 1.0))));
      }
    }
  }
  return picture;
}

cv::Mat DrawRelativeReflectance(const ReflectanceMap& map,
                                const Eigen::MatrixX3d& patch_reflectance, double relative_range) {
  cv::Mat picture(map.reflectance.size(), CV_8UC3, cv::Scalar::all(0));
  for (int row = 0; row < picture.rows; ++row) {
    for (int col = 0; col < picture.cols; ++col) {
      const int i = map.patch.at<int32_t>(row, col);
      if (i < 0 || i >= patch_reflectance.rows()) continue;
      cv::Vec3b& out = picture.at<cv::Vec3b>(row, col);
      if (!map.measured.at<uchar>(row, col) || !(patch_reflectance(i, 1) > 0.0)) {
        out = cv::Vec3b(128, 128, 128);
        continue;
      }
      const double ratio = map.reflectance.at<cv::Vec3f>(row, col)[1] / patch_reflectance(i, 1);
      const double t = std::clamp((ratio - 1.0) / relative_range, -1.0, 1.0);
      // White at 1, towards blue (B, G, R = 255, 0, 0) below and red above.
      const uchar fade = cv::saturate_cast<uchar>(std::lround(255.0 * (1.0 - std::abs(t))));
      out = t < 0 ? cv::Vec3b(255, fade, fade) : cv::Vec3b(fade, fade, 255);
    }
  }
  return picture;
}

}  // namespace procam
