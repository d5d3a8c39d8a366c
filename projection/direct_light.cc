#include "projection/direct_light.h"

#include <algorithm>
#include <cmath>

namespace procam {

DirectLightModel::DirectLightModel(const ProjectionRig& rig,
                                   const std::vector<ProjectorImage>& images)
    : rig_(rig) {
  const int n = rig.size();
  const int projectors = static_cast<int>(rig.projectors.size());
  counts_.resize(projectors);
  light_.resize(projectors);
  lit_.assign(projectors, Eigen::VectorXd::Zero(n));
  sums_.resize(projectors);
  exponent_.assign(projectors, Eigen::Vector3d::Ones());
  for (int k = 0; k < projectors; ++k) {
    const ProjectorMap& map = rig.maps[k];
    const ProjectorPhotometry& photometry = rig.projectors[k].photometry;
    const int levels = photometry.MaxCode() + 1;
    const auto* codes = reinterpret_cast<const cv::Vec3w*>(images[k].codes.data);
    for (int j = 0; j < 3; ++j) {
      counts_[k][j] = Eigen::MatrixXf::Zero(n, levels);
      light_[k][j].resize(levels);
      for (int code = 0; code < levels; ++code)
        light_[k][j][code] = photometry.response[j].Light(double(code) / (levels - 1));
    }
    for (int i = 0; i < n; ++i) {
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        const cv::Vec3w& code = codes[map.pixels_by_patch[position]];
        for (int j = 0; j < 3; ++j) counts_[k][j](i, std::min<int>(code[j], levels - 1)) += 1.0f;
        lit_[k][i] += 1.0;
      }
    }
    for (int j = 0; j < 3; ++j) sums_[k][j] = Sum(k, j, 1.0);
  }
}

void DirectLightModel::SetExponent(int k, int primary, double p) {
  exponent_[k][primary] = p;
  sums_[k][primary] = Sum(k, primary, p);
}

Eigen::MatrixX3d DirectLightModel::Irradiance(int of_projector) const {
  const int n = rig_.size();
  Eigen::MatrixX3d irradiance = Eigen::MatrixX3d::Zero(n, 3);
  for (int k = 0; k < projectors(); ++k) {
    if (of_projector >= 0 && k != of_projector) continue;
    const ProjectorPhotometry& p = rig_.projectors[k].photometry;
    const double omega = rig_.maps[k].pixel_solid_angle;
    for (int i = 0; i < n; ++i) {
      if (lit_[k][i] == 0.0) continue;
      const double scale = rig_.coverage_scale(i, k) * omega / rig_.area[i];
      const Eigen::Vector3d relative(sums_[k][0][i], sums_[k][1][i], sums_[k][2][i]);
      const Eigen::Vector3d mixed = p.mixing * relative;
      for (int c = 0; c < 3; ++c) {
        irradiance(i, c) += scale * (lit_[k][i] * p.black[c] + (p.max[c] - p.black[c]) * mixed[c]);
      }
    }
  }
  return irradiance;
}

Eigen::VectorXd DirectLightModel::Sum(int k, int primary, double p) const {
  Eigen::VectorXf powered(light_[k][primary].size());
  for (size_t code = 0; code < light_[k][primary].size(); ++code)
    powered[code] = static_cast<float>(std::pow(light_[k][primary][code], p));
  return (counts_[k][primary] * powered).cast<double>();
}

}  // namespace procam
