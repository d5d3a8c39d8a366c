#pragma once
// The direct light that shown projector images deliver to each patch, by the renderer's flux
// bookkeeping (projector_images.h): per patch, how many of each projector's pixels that light it
// show each code, and the light of each code through the photometry's response. The response of
// each projector and primary can be bent by an exponent (r(d) → r(d)^p), which is how the closed
// loop fits a projector's response to photos (verification/model_fit.h).

#include <Eigen/Core>
#include <array>
#include <vector>

#include "projection/projection_rig.h"
#include "projection/projector_images.h"

namespace procam {

class DirectLightModel {
 public:
  // `rig` must outlive the model; `images` are the images shown, one per rig projector.
  DirectLightModel(const ProjectionRig& rig, const std::vector<ProjectorImage>& images);

  int projectors() const { return static_cast<int>(counts_.size()); }
  // The response exponent of projector k, per primary (1 = the photometry as it is).
  const Eigen::Vector3d& exponent(int k) const { return exponent_[k]; }
  void SetExponent(int k, int primary, double p);

  // (n,3) direct irradiance (scene units) with the current exponents; `of_projector` ≥ 0 keeps
  // only that projector's light.
  Eigen::MatrixX3d Irradiance(int of_projector = -1) const;

 private:
  Eigen::VectorXd Sum(int k, int primary, double p) const;

  const ProjectionRig& rig_;
  std::vector<std::array<Eigen::MatrixXf, 3>> counts_;     // per patch, pixels per code
  std::vector<std::array<std::vector<double>, 3>> light_;  // response per code
  std::vector<Eigen::VectorXd> lit_;                       // lit pixels per patch
  std::vector<std::array<Eigen::VectorXd, 3>> sums_;       // Σ light^p per patch
  std::vector<Eigen::Vector3d> exponent_;
};

}  // namespace procam
