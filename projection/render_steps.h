#pragma once
// The steps of RenderProjectorImages (projector_images.h) shared by the renderer, the frame plan
// (frame_plan.h) and the GPU renderer's uploads (gl_renderer.h): not a public interface.

#include <Eigen/Core>
#include <Eigen/LU>
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <vector>

#include "projection/projection_rig.h"
#include "projection/projector_images.h"

namespace procam::internal {

inline constexpr double kInfinity = std::numeric_limits<double>::infinity();
// Step 1 (projector_images.h): an E within this of its upper bound, relative, is at the bound
// (2^-10: one binary16 step, twice its rounding).
inline constexpr double kFullDriveTolerance = 0x1p-10;

// 8×8 Bayer matrix: thresholds (b + ½)/64 spread evenly over (0, 1).
inline constexpr std::array<uint8_t, 64> kBayer = {
    0,  32, 8,  40, 2,  34, 10, 42, 48, 16, 56, 24, 50, 18, 58, 26, 12, 44, 4,  36, 14, 46,
    6,  38, 60, 28, 52, 20, 62, 30, 54, 22, 3,  35, 11, 43, 1,  33, 9,  41, 51, 19, 59, 27,
    49, 17, 57, 25, 15, 47, 7,  39, 13, 45, 5,  37, 63, 31, 55, 23, 61, 29, 53, 21};

inline constexpr std::array<double, 64> kBayerThresholds = [] {
  std::array<double, 64> thresholds{};
  for (int i = 0; i < 64; ++i) thresholds[i] = (kBayer[i] + 0.5) / 64.0;
  return thresholds;
}();
// The Bayer matrix's cell at column x and row y (ProjectorMap::bayer_by_share holds it).
inline int BayerCell(int x, int y) { return (y & 7) * 8 + (x & 7); }
inline double BayerThreshold(int x, int y) { return kBayerThresholds[BayerCell(x, y)]; }

// The ordered dither's thresholds of pixels visited by ascending index within rows (a patch's
// pixels_by_patch): each pixel's row found incrementally, without a division per pixel.
class RowThresholds {
 public:
  explicit RowThresholds(int width) : width_(width) {}
  double At(int32_t index) {
    if (index >= row_end_) {
      row_ = index / width_;
      row_begin_ = row_ * width_;
      row_end_ = row_begin_ + width_;
    }
    return BayerThreshold(index - row_begin_, row_);
  }

 private:
  int width_, row_ = -1, row_begin_ = 0, row_end_ = 0;
};

// Code values ↔ relative light for one channel of one projector.
class CodeTable {
 public:
  CodeTable(const ResponseCurve& response, int max_code)
      : max_code_(max_code), light_(max_code + 2) {
    for (int q = 0; q <= max_code; ++q) light_[q] = response.Light(double(q) / max_code);
    light_[max_code + 1] = kInfinity;  // sentinel: never below any r
    first_.resize(kBins + 1);
    int q = 0;
    for (int b = 0; b <= kBins; ++b) {
      const double r = double(b) / kBins;
      while (q < max_code && light_[q + 1] <= r) ++q;
      first_[b] = static_cast<uint16_t>(q);
    }
  }
  double Light(int code) const { return light_[code]; }
  // Largest code whose light is ≤ r (r in [0,1]).
  int Below(double r) const {
    int q = first_[static_cast<int>(r * kBins)];
    while (light_[q + 1] <= r) ++q;
    return q;
  }
  // The code for light r: the upper of the bracketing pair when r's position between them
  // exceeds `threshold` (½: nearest in linear light).
  int Quantise(double r, double threshold) const { return Round(Below(r), r, threshold); }
  // Below(r) for an r at or above the light of `code` (≤ Below(r)): the walk up from it.
  int BelowFrom(int code, double r) const {
    code += light_[code + 1] <= r;  // most walks take no step or one: no branch for the first
    while (light_[code + 1] <= r) ++code;
    return code;
  }
  // Below(r) for an r near the light of `code`: the walk up or down from it (black, code 0,
  // for an r below black's light, 0).
  int BelowNear(int code, double r) const {
    while (light_[code + 1] <= r) ++code;
    while (code > 0 && light_[code] > r) --code;
    return code;
  }
  // Quantise's last step, from q = Below(r).
  int Round(int q, double r, double threshold) const {
    // (r − light_q) / (light_q+1 − light_q) > threshold, without the division. At the top code
    // the sentinel's infinite gap keeps q. No branch: under dithering the test is a coin toss.
    return q + static_cast<int>(r - light_[q] > threshold * (light_[q + 1] - light_[q]));
  }
  int max_code() const { return max_code_; }
  // The bins behind Below: bin b (0 ≤ b ≤ bins()) holds the largest code whose light is ≤
  // b / bins(), where Below starts its walk for r in [b, b + 1) / bins().
  static constexpr int bins() { return kBins; }
  int FirstOfBin(int bin) const { return first_[bin]; }

 private:
  static constexpr int kBins = 4096;  // 8 KB per channel: stays in L1
  int max_code_;
  std::vector<double> light_;
  std::vector<uint16_t> first_;
};

struct ProjectorTables {
  explicit ProjectorTables(const Projector& projector)
      : photometry(projector.photometry),
        delta(projector.photometry.max - projector.photometry.black),
        inverse_delta(delta.cwiseInverse()),
        mixing_inverse(projector.photometry.mixing.inverse()),
        identity_mixing(projector.photometry.mixing.isIdentity(0.0)),
        codes{CodeTable(photometry.response[0], photometry.MaxCode()),
              CodeTable(photometry.response[1], photometry.MaxCode()),
              CodeTable(photometry.response[2], photometry.MaxCode())} {}
  const ProjectorPhotometry& photometry;
  Vec3 delta, inverse_delta;
  Eigen::Matrix3d mixing_inverse;
  bool identity_mixing;
  std::array<CodeTable, 3> codes;
};

// Relative light r ∈ [0,1]³ for relative above-black output s; true if r had to be clipped.
inline bool LightFor(const ProjectorTables& tables, const Vec3& s, Vec3* r) {
  if (tables.identity_mixing) {
    *r = s;
    return false;
  }
  const Vec3 raw = tables.mixing_inverse * s;
  *r = raw.cwiseMax(0.0).cwiseMin(1.0);
  return (*r - raw).cwiseAbs().maxCoeff() > 1e-9;
}

// Step 1 of RenderProjectorImages: E clipped to the bounds (`target`), the flux above black each
// patch needs and its first level τ (+inf: the patch needs every pixel at full drive), and the
// summary's counts of patches outside the bounds or unreached.
struct FirstLevels {
  Eigen::MatrixX3d target, flux, level;  // (n,3)
  int patches_below_lower = 0, patches_above_upper = 0, patches_unreached = 0;
};
FirstLevels ComputeFirstLevels(const ProjectionRig& rig, const Eigen::MatrixX3d& emittance);

// Step 2, per patch: Newton from below on Σ_p min(w a f τ, Ω Δ) = Φ, f the pixel factors
// (`factors` per projector in pixels_by_patch order; empty: f = 1). Only the patches `refine`
// marks (null: all), which must have their factors. Raises `level` where pixels saturate;
// returns the most passes a patch took (1 for every patch not refined). Each pass sums a patch's
// pixels in fixed chunks spread over the threads: the same bits on any number of threads.
int RefineLevels(const ProjectionRig& rig, const std::vector<ProjectorTables>& tables,
                 const std::vector<std::vector<Eigen::Vector3f>>& factors,
                 const Eigen::MatrixX3d& flux, int max_level_passes,
                 const std::vector<char>* refine, Eigen::MatrixX3d* level);

// Step 3: per pixel relative output → light → dithered codes, and the summary's pixel counts,
// delivered exitance and error against `target` (none of it with a null summary: the pixels'
// light is then not summed). With `projectors` (one flag per projector) only
// those images are made (the others left empty, their counts 0) and the summary's delivered
// exitance and error are left empty and 0: the flux of the others is not known.
// The pixel factors come from `factors` (as RefineLevels), or, with `patch_factors`, per patch
// and projector as they are needed: patch_factors(i, k, out) writes patch i's factors of projector
// k in pixels_by_patch order (out[position − patch_begin[i]]), or returns false where they are
// all 1. That keeps no factor of every pixel: a frame's shading allocates no per-pixel array.
// The images of `reuse` keep their buffers where they have the projector's size and 16-bit
// codes (their unlit pixels must be black: images an earlier call made).
using PatchFactorFunction = std::function<bool(int i, int k, Eigen::Vector3f* out)>;
std::vector<ProjectorImage> ShadeImages(const ProjectionRig& rig,
                                        const std::vector<ProjectorTables>& tables,
                                        const Eigen::MatrixX3d& level,
                                        const std::vector<std::vector<Eigen::Vector3f>>& factors,
                                        DitherMethod dither, const Eigen::MatrixX3d& target,
                                        RenderSummary* summary,
                                        const std::vector<char>* projectors = nullptr,
                                        const PatchFactorFunction& patch_factors = {},
                                        std::vector<ProjectorImage> reuse = {});

}  // namespace procam::internal
