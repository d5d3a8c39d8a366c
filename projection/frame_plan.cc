#include "projection/frame_plan.h"

#include <algorithm>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>

#include "base/timing.h"
#include "projection/render_steps.h"

namespace procam {

using internal::kInfinity;
using internal::ProjectorTables;

namespace {

// An upper bound of share_p · v(x_p) / Δ over patch i's pixels p (channel c, node values v̂):
// at every pixel it is Σ_j u_j v̂_j with u_j = share_p K̃_j(x_p) / Δ_k, 0 ≤ u_j ≤ cap_j =
// node_share_reach_ij · max_k(1/Δ_k) and Σ_j u_j = share_p / Δ_k ≤ `total` (the largest share / Δ
// over the patch), so it is at most the largest Σ_j u_j v̂_j under those constraints: `total`
// filled from the largest v̂_j down, each node up to its cap (a fractional knapsack). `nodes` is
// scratch.
double FieldBound(const SeamlessField& field, int i, const Eigen::MatrixX3d& node_value, int c,
                  double inverse_delta, double total,
                  std::vector<std::pair<double, double>>* nodes) {
  nodes->clear();
  double largest = 0.0;
  for (int node = field.node_begin()[i]; node < field.node_begin()[i + 1]; ++node) {
    const double value = node_value(field.node_list()[node], c);
    nodes->emplace_back(value, inverse_delta * field.node_share_reach()[node]);
    largest = std::max(largest, value);
  }
  std::sort(nodes->begin(), nodes->end(), std::greater<>());
  double bound = 0.0, filled = 0.0;
  for (const auto& [value, cap] : *nodes) {
    const double taken = std::min(cap, total - filled);
    bound += taken * value;
    filled += taken;
    if (filled >= total) break;
  }
  // Caps summing to less than the total (only by rounding): the rest at the largest value.
  return bound + std::max(0.0, total - filled) * largest;
}

}  // namespace

FramePlanner::FramePlanner(const ProjectionRig& rig, const RenderOptions& options)
    : rig_(rig), options_(options), tables_(std::make_unique<std::vector<ProjectorTables>>()),
      factor_buffer_(std::make_unique<FactorBuffer>()) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("RenderOptions: " + why);
  if (options.detail) {
    throw std::invalid_argument(
        "RenderOptions::detail: frame plans carry no per-pixel texture detail (render it with "
        "RenderProjectorImages and the scene)");
  }
  if (options.reflectance) {
    throw std::invalid_argument(
        "RenderOptions::reflectance: frame plans carry no per-pixel reflectance (render it with "
        "RenderProjectorImages)");
  }
  if (options.light == LightField::kSmooth)
    field_ = std::make_unique<SeamlessField>(rig, options.seamless);
  tables_->reserve(rig.projectors.size());
  for (const Projector& projector : rig.projectors) tables_->emplace_back(projector);
  const int n = rig.size();
  share_bound_ = Eigen::MatrixX3d::Zero(n, 3);
  largest_inverse_delta_ = Vec3::Zero();
  for (const ProjectorTables& table : *tables_)
    largest_inverse_delta_ = largest_inverse_delta_.cwiseMax(table.inverse_delta);
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

struct FramePlanner::FactorBuffer {
  std::mutex mutex;
  std::shared_ptr<std::vector<std::vector<Eigen::Vector3f>>> factors;
};

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
        exitance.row(i) =
            rig_.reflectance.row(i).cwiseProduct(first.flux.row(i)) / rig_.blended_area[i];
    }
    plan.node_value = field_->NodeValues(exitance.cwiseMax(0.0));
    plan.mean = field_->PatchMeans(plan.node_value);
  }

  // Patches where some pixel may reach full drive (header comment): the bound, less a margin
  // far above the rounding of the factors (single precision) and of the products.
  constexpr double kMargin = 1e-5;
  std::vector<char> refine(n, 0);
  std::vector<std::pair<double, double>> nodes;  // FieldBound's
  for (int i = 0; i < n; ++i) {
    // max_p share_p · m_p / Δ per channel: the share alone where m = 1.
    Vec3 share_factor_bound = share_bound_.row(i).transpose();
    if (field_ && !field_->Flat(i)) {
      for (int c = 0; c < 3; ++c) {
        if (plan.mean(i, c) > 0.0) {
          share_factor_bound[c] =
              FieldBound(*field_, i, plan.node_value, c, largest_inverse_delta_[c],
                         share_bound_(i, c), &nodes) /
              plan.mean(i, c);
        }
      }
    }
    for (int c = 0; c < 3; ++c) {
      const double tau = plan.level(i, c);
      if (tau == kInfinity) continue;
      refine[i] |= share_factor_bound[c] * tau >= 1.0 - kMargin;
    }
    plan.refined_patches += refine[i];
  }

  // The refined patches' pixel factors, computed as RenderProjectorImages computes them, into
  // the last plan's arrays where no plan holds them any more.
  std::shared_ptr<std::vector<std::vector<Eigen::Vector3f>>> buffer;
  if (field_ && plan.refined_patches > 0) {
    {
      std::lock_guard<std::mutex> lock(factor_buffer_->mutex);
      if (factor_buffer_->factors && factor_buffer_->factors.use_count() == 1) {
        buffer = factor_buffer_->factors;
      } else {
        buffer = std::make_shared<std::vector<std::vector<Eigen::Vector3f>>>();
        factor_buffer_->factors = buffer;
      }
    }
    std::vector<std::vector<Eigen::Vector3f>>& factors = *buffer;
    factors.resize(rig_.maps.size());
    for (size_t k = 0; k < rig_.maps.size(); ++k) factors[k].resize(rig_.maps[k].lit_pixels);
    // One patch at a time: the refined patches are few and clustered (a bright region), so
    // chunks of neighbours would leave most threads idle.
#pragma omp parallel for schedule(dynamic, 1)
    for (int i = 0; i < n; ++i) {
      if (!refine[i]) continue;
      for (size_t k = 0; k < rig_.maps.size(); ++k) {
        field_->PatchFactors(i, k, plan.node_value, plan.mean,
                             &factors[k][rig_.maps[k].patch_begin[i]]);
      }
    }
  }
  static const std::vector<std::vector<Eigen::Vector3f>> kNoFactors;
  plan.level_passes = internal::RefineLevels(rig_, *tables_, buffer ? *buffer : kNoFactors,
                                             first.flux, options_.max_level_passes, &refine,
                                             &plan.level);
  plan.refined_factors = std::move(buffer);
  plan.refined = std::move(refine);
  plan.seconds = SecondsSince(start);
  return plan;
}

FramePlan PlanFrame(const ProjectionRig& rig, const Eigen::MatrixX3d& emittance,
                    const RenderOptions& options) {
  return FramePlanner(rig, options).Plan(emittance);
}

std::vector<ProjectorImage> ShadeProjectorImages(const FramePlanner& planner, const FramePlan& plan,
                                                 RenderSummary* summary,
                                                 const std::vector<int>& projectors) {
  std::vector<ProjectorImage> images;
  ShadeProjectorImages(planner, plan, summary, projectors, &images);
  return images;
}

void ShadeProjectorImages(const FramePlanner& planner, const FramePlan& plan,
                          RenderSummary* summary, const std::vector<int>& projectors,
                          std::vector<ProjectorImage>* images) {
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
  std::vector<char> wanted;
  if (!projectors.empty()) {
    wanted.assign(rig.projectors.size(), 0);
    for (const int k : projectors) {
      if (k < 0 || k >= static_cast<int>(rig.projectors.size())) {
        throw std::invalid_argument("ShadeProjectorImages: no projector " + std::to_string(k) +
                                    " in a rig of " + std::to_string(rig.projectors.size()));
      }
      wanted[k] = 1;
    }
  }
  const std::vector<char>* subset = projectors.empty() ? nullptr : &wanted;
  const auto start = Clock::now();
  RenderSummary local;
  RenderSummary& s = summary ? *summary : local;
  s = RenderSummary();
  s.level_passes = plan.level_passes;
  s.patches_below_lower = plan.patches_below_lower;
  s.patches_above_upper = plan.patches_above_upper;
  s.patches_unreached = plan.patches_unreached;
  // The seamless factors patch by patch as the shading reaches them: no per-pixel array.
  internal::PatchFactorFunction patch_factors;
  if (smooth) {
    const SeamlessField& field = *planner.field();
    // A refined patch's factors are the plan's (the same bits): copied, not computed again.
    patch_factors = [&field, &plan, &rig](int i, int k, Eigen::Vector3f* out) {
      if (field.Flat(i)) return false;
      if (plan.refined_factors && plan.refined[i]) {
        const std::vector<Eigen::Vector3f>& factors = (*plan.refined_factors)[k];
        const int begin = rig.maps[k].patch_begin[i], end = rig.maps[k].patch_begin[i + 1];
        std::copy(factors.begin() + begin, factors.begin() + end, out);
        return true;
      }
      field.PatchFactors(i, k, plan.node_value, plan.mean, out);
      return true;
    };
  }
  *images = internal::ShadeImages(rig, planner.tables(), plan.level, {}, planner.options().dither,
                                  plan.target, summary ? &s : nullptr, subset, patch_factors,
                                  std::move(*images));
  s.seconds = SecondsSince(start);
}

}  // namespace procam
