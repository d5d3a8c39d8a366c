#pragma once
// RenderProjectorImages (projector_images.h) split into a per-frame, per-PATCH plan and a
// per-PIXEL shading, so that the shading can run where the pixels are: on a display node's GPU
// (gl_renderer.h), or on the CPU (ShadeProjectorImages, the reference).
//
// The plan of a frame, for emittance E (n,3):
// - the level τ (n,3) of every patch (steps 1 and 2 of projector_images.h; +inf: every pixel of
//   the patch at full drive on that channel);
// - for LightField::kSmooth, what the seamless factor of a pixel needs besides the pixel's own
//   hit point x_p (ProjectorMap::point_by_patch) and the field's static part (SeamlessField:
//   node lists, centroids c_j and radii r_j): the node values v̂ (n,3) and the patch means
//   mean_i = (A v̂)_i (n,3), so that m_p = v(x_p) / mean_i with
//   v(x) = Σ_j K_j(x) v̂_j / Σ_j K_j(x), K_j(x) = (1 − |x − c_j|²/r_j²)² inside r_j
//   (seamless_light.h).
// A pixel's relative output is then min(1, share_p · τ_i · m_p / Δ) per channel (1 where τ is
// +inf), and the rest of step 3 (mixing inverse, clip, dithered quantisation) is per pixel too.
//
// Step 2 (saturation) needs per-pixel factors only on patches where some pixel may reach full
// drive. Per patch and channel the planner bounds max_p share_p · τ_i · m_p / Δ_k from above,
// without visiting the pixels: m_p = v(x_p) / mean_i, and at every pixel
// share_p v(x_p) / Δ_k = Σ_j u_j v̂_j with u_j = share_p K̃_j(x_p) / Δ_k (K̃_j the normalised
// bumps, summing to 1), each u_j at most a static cap (the largest share · K̃_j over the patch's
// pixels, SeamlessField::node_share_reach, times max_k 1/Δ_k) and Σ_j u_j at most the largest
// share / Δ_k over the patch (static too). So it is at most the largest Σ_j u_j v̂_j under those
// constraints: that total filled from the largest v̂_j down, each node up to its cap (a
// fractional knapsack, O(nodes log nodes) per patch; for flat light or a flat patch simply the
// largest share / Δ). Only patches whose bound reaches 1 (less a margin for rounding) get the
// exact per-pixel refinement, their pixels' factors computed as RenderProjectorImages computes
// them.
// Everywhere else no pixel saturates, so step 2 would leave τ as it is: the plan's levels are
// exactly RenderProjectorImages's, and the rest of a plan costs O(n) plus the sparse products
// with A (SeamlessLightOptions::iterations of them).
//
// Detail (RenderOptions::detail) needs per-pixel texture ratios and their per-patch
// renormalisation: plans do not carry it (FramePlanner refuses it; RenderProjectorImages renders
// detail without a plan). Error diffusion is sequential per image: ShadeProjectorImages does it,
// the GPU renderer refuses it.

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "projection/projection_rig.h"
#include "projection/projector_images.h"
#include "projection/seamless_light.h"

namespace procam {

namespace internal {
struct ProjectorTables;
}  // namespace internal

// One frame's per-patch plan (header comment).
struct FramePlan {
  LightField light = LightField::kSmooth;
  Eigen::MatrixX3d level;  // (n,3) τ: irradiance level above black per unit share; +inf: full drive
  Eigen::MatrixX3d node_value;  // (n,3) v̂, kSmooth only (else empty)
  Eigen::MatrixX3d mean;        // (n,3) mean_i(v) = (A v̂)_i, kSmooth only (else empty)
  Eigen::MatrixX3d target;      // (n,3) E clipped to [lower, upper]
  int level_passes = 0;         // most evaluations of step 2 a patch needed (1: none saturated)
  int refined_patches = 0;      // patches whose bound reached full drive (refined per pixel)
  std::vector<char> refined;    // (n) which ones
  // kSmooth: the refined patches' pixel factors, per projector in pixels_by_patch order (the
  // other positions hold whatever an earlier plan left), which the shading takes instead of
  // computing them again; null when no patch was refined. The planner reuses the arrays for a
  // later plan once no plan holds them: fresh arrays of every lit pixel cost a frame their page
  // faults (10 ms of a 2-core VM's 15 ms plan).
  std::shared_ptr<const std::vector<std::vector<Eigen::Vector3f>>> refined_factors;
  int patches_below_lower = 0, patches_above_upper = 0, patches_unreached = 0;
  double seconds = 0.0;
};

// The static part of planning for one rig and one set of options: the seamless field
// (SeamlessField: visits every lit pixel once), per patch the largest share / Δ over its pixels,
// the projectors' code tables. Keeps references to the rig; rebuild it when the rig or its
// desired colours change.
class FramePlanner {
 public:
  // Throws std::invalid_argument if the options fail Check() or ask for detail, and like
  // SeamlessField for kSmooth on a rig without centroids or hit points.
  FramePlanner(const ProjectionRig& rig, const RenderOptions& options);
  ~FramePlanner();
  FramePlanner(const FramePlanner&) = delete;
  FramePlanner& operator=(const FramePlanner&) = delete;

  // The plan for emittance E (n,3). Throws std::invalid_argument if E has the wrong shape or
  // non-finite values.
  FramePlan Plan(const Eigen::MatrixX3d& emittance) const;

  const ProjectionRig& rig() const { return rig_; }
  const RenderOptions& options() const { return options_; }
  // The seamless field for kSmooth; null for kFlat.
  const SeamlessField* field() const { return field_.get(); }
  // For shading on the CPU frame after frame (ShadeProjectorImages): keeps the seamless field's
  // bumps at every lit pixel of the projectors flagged (null: all; SeamlessField::CacheBumps), so
  // that each frame sums them instead of evaluating them. The same images, faster; no effect
  // with kFlat.
  void CacheBumps(const std::vector<char>* projectors = nullptr) {
    if (field_) field_->CacheBumps(projectors);
  }
  const std::vector<internal::ProjectorTables>& tables() const { return *tables_; }

 private:
  const ProjectionRig& rig_;
  RenderOptions options_;
  std::unique_ptr<SeamlessField> field_;
  std::unique_ptr<std::vector<internal::ProjectorTables>> tables_;
  Eigen::MatrixX3d share_bound_;  // (n,3) max over the patch's pixels of share / Δ_k
  Vec3 largest_inverse_delta_;    // max_k 1 / Δ_k
  // The factor arrays of the last plan that refined a patch (FramePlan::refined_factors), reused
  // when no plan holds them any more.
  struct FactorBuffer;
  std::unique_ptr<FactorBuffer> factor_buffer_;
};

// FramePlanner(rig, options).Plan(E): for one frame (the planner's static part is rebuilt).
FramePlan PlanFrame(const ProjectionRig& rig, const Eigen::MatrixX3d& emittance,
                    const RenderOptions& options);

// The CPU shading of a plan (step 3 of projector_images.h, every pixel's seamless factor from
// the plan): the images RenderProjectorImages gives for the planner's options, bit for bit, and
// its summary (the plan's counts; `seconds` the shading's). With `projectors` (indices into the
// rig's, as a display node owns them) only those images are shaded, the others left empty
// (codes.empty()), and the summary's delivered exitance is left empty: the rest of the rig's
// light is not known. A null summary: the pixels' light is not summed at all (a display node's
// frames; about a tenth of the shading). Throws std::invalid_argument if the plan does not fit
// the planner's rig or light, or a projector index is out of range.
std::vector<ProjectorImage> ShadeProjectorImages(const FramePlanner& planner, const FramePlan& plan,
                                                 RenderSummary* summary,
                                                 const std::vector<int>& projectors = {});
// The same into `images`, whose buffers are reused where they are of the right size: images an
// earlier call of this function made for the same planner (their unlit pixels, never written,
// are black). A display node's frame after frame then allocates and clears no image: in this
// 2-core VM a fresh 1080p image cost its page faults on every frame. Whoever keeps an image
// across frames must copy it.
void ShadeProjectorImages(const FramePlanner& planner, const FramePlan& plan,
                          RenderSummary* summary, const std::vector<int>& projectors,
                          std::vector<ProjectorImage>* images);

}  // namespace procam
