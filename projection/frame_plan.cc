#include "projection/frame_plan.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "base/timing.h"
#include "projection/render_steps.h"

namespace procam {

using internal::kInfinity;
using internal::ProjectorTables;

FramePlanner::FramePlanner(const ProjectionRig& rig, const RenderOptions& options)
    : rig_(rig), options_(options), tables_(std::make_unique<std::vector<ProjectorTables>>()) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("RenderOptions: " + why);
  if (options.detail) {
    throw std::invalid_argument(
        "RenderOptions::detail: frame plans carry no per-pixel texture detail (render it with "
        "RenderProjectorImages and the scene)");
  }
  if (options.light == LightField::kSmooth)
    field_ = std::make_unique<SeamlessField>(rig, options.seamless);
  tables_->reserve(rig.projectors.size());
  for (const Projector& projector : rig.projectors) tables_->emplace_back(projector);
  const int n = rig.size();
  share_bound_ = Eigen::MatrixX3d::Zero(n, 3);
  for (size_t k = 0; k < rig.maps.size(); ++k) {
    const ProjectorMap& map = rig.maps[k];
    const Vec3& inverse_delta = (*tables_)[k].inverse_delta;
    for (int i = 0; i < n; ++i) {
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        const double share = map.share[map.pixels_by_patch[position]];
        for (int c = 0; c < 3; ++c)
          share_bound_(i, c) = std::max(share_bound_(i, c), share * inverse_delta[c]);
      }
    }
  }
}

FramePlanner::~FramePlanner() = default;

FramePlan FramePlanner::Plan(const Eigen::MatrixX3d& emittance) const {
  const int n = rig_.size();
  if (emittance.rows() != n) {
    throw std::invalid_argument("emittance has " + std::to_string(emittance.rows()) +
                                " rows, the rig " + std::to_string(n) + " patches");
  }
  if (!emittance.allFinite()) throw std::invalid_argument("emittance has non-finite values");
  const auto start = Clock::now();
  FramePlan plan;
  plan.light = options_.light;
  internal::FirstLevels first = internal::ComputeFirstLevels(rig_, emittance);
  plan.patches_below_lower = first.patches_below_lower;
  plan.patches_above_upper = first.patches_above_upper;
  plan.patches_unreached = first.patches_unreached;
  plan.target = std::move(first.target);
  plan.level = std::move(first.level);

  if (field_) {
    // The field is fitted to the patches' exitance above black, ρ τ (as RenderProjectorImages).
    Eigen::MatrixX3d exitance = Eigen::MatrixX3d::Zero(n, 3);
    for (int i = 0; i < n; ++i) {
      if (rig_.blended_area[i] > 0.0)
        exitance.row(i) = rig_.reflectance.row(i).cwiseProduct(first.flux.row(i)) /
                          rig_.blended_area[i];
    }
    plan.node_value = field_->NodeValues(exitance.cwiseMax(0.0));
    plan.mean = field_->PatchMeans(plan.node_value);
  }

  // Patches where some pixel may reach full drive (header comment): the bound, less a margin
  // far above the rounding of the factors (single precision) and of the products.
  constexpr double kMargin = 1e-5;
  std::vector<char> refine(n, 0);
  for (int i = 0; i < n; ++i) {
    Vec3 factor_bound = Vec3::Ones();
    if (field_ && !field_->Flat(i)) {
      // v ≤ min(max_j v̂_j, v̂_i + Σ_j reach_ij (v̂_j − v̂_i)⁺) over the patch (seamless_light.h).
      const Vec3 own = plan.node_value.row(i).transpose();
      Vec3 largest = Vec3::Zero(), rise = Vec3::Zero();
      const std::vector<int>& begin = field_->node_begin();
      for (int node = begin[i]; node < begin[i + 1]; ++node) {
        const Vec3 value = plan.node_value.row(field_->node_list()[node]).transpose();
        largest = largest.cwiseMax(value);
        rise += field_->node_reach()[node] * (value - own).cwiseMax(0.0);
      }
      const Vec3 highest = largest.cwiseMin(own + rise);
      for (int c = 0; c < 3; ++c) {
        if (plan.mean(i, c) > 0.0) factor_bound[c] = highest[c] / plan.mean(i, c);
      }
    }
    for (int c = 0; c < 3; ++c) {
      const double tau = plan.level(i, c);
      if (tau == kInfinity) continue;
      refine[i] |= share_bound_(i, c) * tau * factor_bound[c] >= 1.0 - kMargin;
    }
    plan.refined_patches += refine[i];
  }

  // The refined patches' pixel factors, computed as RenderProjectorImages computes them.
  std::vector<std::vector<Eigen::Vector3f>> factors;
  if (field_ && plan.refined_patches > 0) {
    factors.resize(rig_.maps.size());
    for (size_t k = 0; k < rig_.maps.size(); ++k) factors[k].resize(rig_.maps[k].lit_pixels);
#pragma omp parallel for schedule(dynamic, 16)
    for (int i = 0; i < n; ++i) {
      if (!refine[i]) continue;
      for (size_t k = 0; k < rig_.maps.size(); ++k) {
        const ProjectorMap& map = rig_.maps[k];
        for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
          factors[k][position] =
              field_->Factor(i, map.point_by_patch[position], plan.node_value, plan.mean);
        }
      }
    }
  }
  plan.level_passes = internal::RefineLevels(rig_, *tables_, factors, first.flux,
                                             options_.max_level_passes, &refine, &plan.level);
  plan.seconds = SecondsSince(start);
  return plan;
}

FramePlan PlanFrame(const ProjectionRig& rig, const Eigen::MatrixX3d& emittance,
                    const RenderOptions& options) {
  return FramePlanner(rig, options).Plan(emittance);
}

std::vector<ProjectorImage> ShadeProjectorImages(const FramePlanner& planner, const FramePlan& plan,
                                                 RenderSummary* summary) {
  const ProjectionRig& rig = planner.rig();
  const int n = rig.size();
  const bool smooth = planner.field() != nullptr;
  if (plan.level.rows() != n || plan.target.rows() != n || plan.light != planner.options().light ||
      (smooth && (plan.node_value.rows() != n || plan.mean.rows() != n))) {
    throw std::invalid_argument("ShadeProjectorImages: the plan is not one of this planner's (" +
                                std::to_string(plan.level.rows()) + " patches, light " +
                                LightFieldName(plan.light) + "; the planner's rig " +
                                std::to_string(n) + ", light " +
                                LightFieldName(planner.options().light) + ")");
  }
  const auto start = Clock::now();
  RenderSummary local;
  RenderSummary& s = summary ? *summary : local;
  s = RenderSummary();
  s.level_passes = plan.level_passes;
  s.patches_below_lower = plan.patches_below_lower;
  s.patches_above_upper = plan.patches_above_upper;
  s.patches_unreached = plan.patches_unreached;
  std::vector<std::vector<Eigen::Vector3f>> factors;
  if (smooth) factors = planner.field()->Factors(plan.node_value, plan.mean);
  std::vector<ProjectorImage> images = internal::ShadeImages(
      rig, planner.tables(), plan.level, factors, planner.options().dither, plan.target, &s);
  s.seconds = SecondsSince(start);
  return images;
}

}  // namespace procam
