#include "projection/projector_images.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "base/image_io.h"
#include "base/io.h"
#include "base/timing.h"
#include "geometry/ray_scene.h"
#include "projection/frame_plan.h"
#include "projection/render_steps.h"

namespace procam {
namespace {

using internal::CodeTable;
using internal::kInfinity;
using internal::LightFor;
using internal::ProjectorTables;

void QuantiseErrorDiffusion(const ProjectorMap& map, const ProjectorTables& tables,
                            const std::vector<Vec3>& light, cv::Mat* codes) {
  const int width = map.width, height = map.height;
  std::vector<Vec3> current(width + 2, Vec3::Zero()), next(width + 2, Vec3::Zero());
  for (int y = 0; y < height; ++y) {
    const bool forward = (y % 2) == 0;
    std::fill(next.begin(), next.end(), Vec3::Zero());
    auto* row = codes->ptr<cv::Vec3w>(y);
    for (int step = 0; step < width; ++step) {
      const int x = forward ? step : width - 1 - step;
      const size_t index = static_cast<size_t>(y) * width + x;
      if (map.patch[index] < 0) continue;  // stays black; error is not carried through it
      const int direction = forward ? 1 : -1;
      for (int c = 0; c < 3; ++c) {
        const double wanted = light[index][c] + current[x + 1][c];
        const int code = tables.codes[c].Quantise(std::clamp(wanted, 0.0, 1.0), 0.5);
        row[x][c] = static_cast<uint16_t>(code);
        const double error = wanted - tables.codes[c].Light(code);
        current[x + 1 + direction][c] += error * 7.0 / 16.0;
        next[x + 1 - direction][c] += error * 3.0 / 16.0;
        next[x + 1][c] += error * 5.0 / 16.0;
        next[x + 1 + direction][c] += error * 1.0 / 16.0;
      }
    }
    std::swap(current, next);
  }
}

// Detail factor d per lit pixel and channel (header comment), in the order of each map's
// pixels_by_patch; exactly 1 on patches of surfaces without a texture. Adds the pixels on
// textured surfaces to *textured_pixels.
std::vector<std::vector<Eigen::Vector3f>> DetailFactors(const ProjectionRig& rig,
                                                        const Scene& scene,
                                                        const RenderOptions& options,
                                                        long long* textured_pixels) {
  const int n = rig.size();
  const int projector_count = static_cast<int>(rig.maps.size());
  std::vector<std::vector<Eigen::Vector3f>> detail(projector_count);
  for (int k = 0; k < projector_count; ++k)
    detail[k].assign(rig.maps[k].lit_pixels, Eigen::Vector3f::Ones());
  long long textured = 0;
#pragma omp parallel for schedule(dynamic, 16) reduction(+ : textured)
  for (int i = 0; i < n; ++i) {
    const DesiredAppearance& desired = scene.surfaces[rig.surface[i]].desired;
    if (!desired.HasTexture()) continue;
    // The texture at every pixel's point, and its mean over the patch as the pixels light it
    // (weights w a, the same as the flux bookkeeping's, so that renormalising conserves flux).
    Vec3 texture_sum = Vec3::Zero();
    double weight_sum = 0.0;
    for (int k = 0; k < projector_count; ++k) {
      const ProjectorMap& map = rig.maps[k];
      const double scale = rig.coverage_scale(i, k) * map.pixel_solid_angle;
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        const int32_t index = map.pixels_by_patch[position];
        const Vec3 texture = desired.LinearAt(map.uv[index].cast<double>());
        detail[k][position] = texture.cast<float>();
        const double weight = scale * map.share[index];
        texture_sum += weight * texture;
        weight_sum += weight;
        ++textured;
      }
    }
    if (!(weight_sum > 0.0)) continue;
    const Vec3 mean = texture_sum / weight_sum;
    // Ratios, clamped; then divided by their own weighted mean (≥ detail_min > 0).
    Vec3 ratio_sum = Vec3::Zero();
    for (int k = 0; k < projector_count; ++k) {
      const ProjectorMap& map = rig.maps[k];
      const double scale = rig.coverage_scale(i, k) * map.pixel_solid_angle;
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        Eigen::Vector3f& d = detail[k][position];
        for (int c = 0; c < 3; ++c) {
          // A channel the texture leaves black over the whole patch has no detail to show.
          d[c] = mean[c] > 0.0 ? static_cast<float>(std::clamp(d[c] / mean[c], options.detail_min,
                                                               options.detail_max))
                               : 1.0f;
        }
        ratio_sum += scale * map.share[map.pixels_by_patch[position]] * d.cast<double>();
      }
    }
    const Eigen::Vector3f normaliser = (weight_sum * ratio_sum.cwiseInverse()).cast<float>();
    for (int k = 0; k < projector_count; ++k) {
      for (int position = rig.maps[k].patch_begin[i]; position < rig.maps[k].patch_begin[i + 1];
           ++position)
        detail[k][position] = detail[k][position].cwiseProduct(normaliser);
    }
  }
  *textured_pixels += textured;
  return detail;
}

// Reflectance factor q per lit pixel and channel (header comment, "Reflectance"), in the order
// of each map's pixels_by_patch, each patch's renormalised to a weighted mean of 1 (weights w a).
std::vector<std::vector<Eigen::Vector3f>> ReflectanceFactors(const ProjectionRig& rig,
                                                             const RenderOptions& options) {
  const int n = rig.size();
  const int projector_count = static_cast<int>(rig.maps.size());
  std::vector<std::vector<Eigen::Vector3f>> factors(projector_count);
  for (int k = 0; k < projector_count; ++k)
    factors[k].assign(rig.maps[k].lit_pixels, Eigen::Vector3f::Ones());
  const double low = 1.0 / options.reflectance_ratio_max, high = options.reflectance_ratio_max;
  // The patch's mean reflectance as its pixels light it (weights w a).
  const Eigen::MatrixX3d means = MapReflectanceMeans(rig);
#pragma omp parallel for schedule(dynamic, 16)
  for (int i = 0; i < n; ++i) {
    if (!(rig.blended_area[i] > 0.0)) continue;
    const Vec3 mean = means.row(i).transpose();
    double weight_sum = 0.0;
    Vec3 factor_sum = Vec3::Zero();
    for (int k = 0; k < projector_count; ++k) {
      const ProjectorMap& map = rig.maps[k];
      const double scale = rig.coverage_scale(i, k) * map.pixel_solid_angle;
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        const int32_t index = map.pixels_by_patch[position];
        Eigen::Vector3f& q = factors[k][position];
        for (int c = 0; c < 3; ++c) {
          const double rho = map.reflectance[index][c];
          // A channel measured black over the whole patch has nothing to even out.
          q[c] = mean[c] > 0.0
                     ? static_cast<float>(std::clamp(rho > 0.0 ? mean[c] / rho : high, low, high))
                     : 1.0f;
        }
        factor_sum += scale * map.share[index] * q.cast<double>();
        weight_sum += scale * map.share[index];
      }
    }
    if (!(weight_sum > 0.0)) continue;
    const Eigen::Vector3f normaliser = (weight_sum * factor_sum.cwiseInverse()).cast<float>();
    for (int k = 0; k < projector_count; ++k) {
      for (int position = rig.maps[k].patch_begin[i]; position < rig.maps[k].patch_begin[i + 1];
           ++position)
        factors[k][position] = factors[k][position].cwiseProduct(normaliser);
    }
  }
  return factors;
}

// The lit pixels at full drive on a channel whose reflectance factor q raises them (q > 1):
// where a dark point asks for more light than the projector has.
long long ReflectanceSaturatedPixels(const ProjectionRig& rig,
                                     const std::vector<std::vector<Eigen::Vector3f>>& factors,
                                     const std::vector<ProjectorImage>& images) {
  long long saturated = 0;
  for (size_t k = 0; k < rig.maps.size(); ++k) {
    const ProjectorMap& map = rig.maps[k];
    const int max_code = (1 << images[k].bits) - 1;
    const auto* codes = reinterpret_cast<const cv::Vec3w*>(images[k].codes.data);
    for (int position = 0; position < map.lit_pixels; ++position) {
      const cv::Vec3w& code = codes[map.pixels_by_patch[position]];
      const Eigen::Vector3f& q = factors[k][position];
      bool at_full = false;
      for (int c = 0; c < 3; ++c) at_full |= q[c] > 1.0f && code[c] == max_code;
      saturated += at_full;
    }
  }
  return saturated;
}

// The detail's and the seamless light's factors multiplied into *combined (the detail), then
// renormalised to a weighted mean of 1 per patch and channel (weights w a), so the flux is kept.
// A patch whose detail is 1 everywhere (untextured) keeps the seamless factors as they are: they
// are normalised already, and renormalising them again would move them by a rounding.
void CombineFactors(const ProjectionRig& rig,
                    const std::vector<std::vector<Eigen::Vector3f>>& smooth,
                    std::vector<std::vector<Eigen::Vector3f>>* combined) {
  const int n = rig.size();
  const int projector_count = static_cast<int>(rig.maps.size());
#pragma omp parallel for schedule(dynamic, 16)
  for (int i = 0; i < n; ++i) {
    Vec3 weighted = Vec3::Zero();
    double weight_sum = 0.0;
    bool textured = false;
    for (int k = 0; k < projector_count; ++k) {
      const ProjectorMap& map = rig.maps[k];
      const double scale = rig.coverage_scale(i, k) * map.pixel_solid_angle;
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        Eigen::Vector3f& factor = (*combined)[k][position];
        textured |= factor != Eigen::Vector3f::Ones();
        factor = factor.cwiseProduct(smooth[k][position]);
        const double weight = scale * map.share[map.pixels_by_patch[position]];
        weighted += weight * factor.cast<double>();
        weight_sum += weight;
      }
    }
    if (!textured) continue;
    for (int c = 0; c < 3; ++c) {
      const float normaliser =
          weighted[c] > 0.0 ? static_cast<float>(weight_sum / weighted[c]) : 1.0f;
      for (int k = 0; k < projector_count; ++k) {
        for (int position = rig.maps[k].patch_begin[i]; position < rig.maps[k].patch_begin[i + 1];
             ++position)
          (*combined)[k][position][c] *= normaliser;
      }
    }
  }
}

// The factor on τ per lit pixel (in pixels_by_patch order) and channel: the detail d, the
// reflectance's q, the seamless light's m, or their product renormalised (header comment); none
// with none of them (1). `flux` is step 1's. With the reflectance, *reflectance_factors gets q
// alone (for the count of the pixels it saturates).
std::vector<std::vector<Eigen::Vector3f>> PixelFactors(
    const ProjectionRig& rig, const Scene& scene, const Eigen::MatrixX3d& flux,
    const RenderOptions& options, long long* textured_pixels,
    std::vector<std::vector<Eigen::Vector3f>>* reflectance_factors) {
  std::vector<std::vector<Eigen::Vector3f>> detail;
  if (options.detail) detail = DetailFactors(rig, scene, options, textured_pixels);
  if (options.reflectance) {
    const std::vector<std::vector<Eigen::Vector3f>> reflectance = ReflectanceFactors(rig, options);
    *reflectance_factors = reflectance;
    if (detail.empty()) {
      detail = reflectance;
    } else {
      CombineFactors(rig, reflectance, &detail);
    }
  }
  if (options.light != LightField::kSmooth) return detail;
  const int n = rig.size();
  Eigen::MatrixX3d exitance = Eigen::MatrixX3d::Zero(n, 3);  // ρ τ, above black
  for (int i = 0; i < n; ++i) {
    if (rig.blended_area[i] > 0.0)
      exitance.row(i) = rig.reflectance.row(i).cwiseProduct(flux.row(i)) / rig.blended_area[i];
  }
  std::vector<std::vector<Eigen::Vector3f>> smooth =
      SeamlessLightFactors(rig, exitance.cwiseMax(0.0), options.seamless);
  if (detail.empty()) return smooth;
  CombineFactors(rig, smooth, &detail);
  return detail;
}

}  // namespace

const char* DitherName(DitherMethod method) {
  switch (method) {
    case DitherMethod::kNone:
      return "none";
    case DitherMethod::kOrdered:
      return "ordered";
    case DitherMethod::kErrorDiffusion:
      return "error-diffusion";
  }
  return "?";
}

bool ParseDither(const std::string& name, DitherMethod* method) {
  for (const DitherMethod m :
       {DitherMethod::kNone, DitherMethod::kOrdered, DitherMethod::kErrorDiffusion}) {
    if (name == DitherName(m)) {
      *method = m;
      return true;
    }
  }
  return false;
}

const char* LightFieldName(LightField light) {
  switch (light) {
    case LightField::kFlat:
      return "flat";
    case LightField::kSmooth:
      return "smooth";
  }
  return "?";
}

bool ParseLightField(const std::string& name, LightField* light) {
  for (const LightField l : {LightField::kFlat, LightField::kSmooth}) {
    if (name == LightFieldName(l)) {
      *light = l;
      return true;
    }
  }
  return false;
}

bool RenderOptions::Check(std::string* why) const {
  if (light == LightField::kSmooth && !seamless.Check(why)) return false;
  if (max_level_passes < 1 || max_level_passes > 1000) {
    *why = "max_level_passes must be in [1, 1000]";
    return false;
  }
  if (!(detail_min > 0.0 && detail_min <= 1.0)) {
    *why = "detail_min must be in (0, 1]";
    return false;
  }
  if (!(detail_max >= 1.0 && detail_max <= 1000.0)) {
    *why = "detail_max must be in [1, 1000]";
    return false;
  }
  if (!(reflectance_ratio_max >= 1.0 && reflectance_ratio_max <= 1000.0)) {
    *why = "reflectance_ratio_max must be in [1, 1000]";
    return false;
  }
  return true;
}

std::vector<ProjectorImage> RenderProjectorImages(const ProjectionRig& rig,
                                                  const Eigen::MatrixX3d& emittance,
                                                  const RenderOptions& options,
                                                  RenderSummary* summary) {
  if (options.detail) {
    throw std::invalid_argument(
        "RenderOptions::detail needs the scene's textures: call RenderProjectorImages with the "
        "scene");
  }
  return RenderProjectorImages(rig, Scene(), emittance, options, summary);
}

namespace {

// RenderProjectorImages's inputs: the options, E's shape and values, and for detail the rig's
// texture coordinates and the scene's surfaces. Throws std::invalid_argument.
void CheckRenderInputs(const ProjectionRig& rig, const Scene& scene,
                       const Eigen::MatrixX3d& emittance, const RenderOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("RenderOptions: " + why);
  const int n = rig.size();
  if (emittance.rows() != n) {
    throw std::invalid_argument("emittance has " + std::to_string(emittance.rows()) +
                                " rows, the rig " + std::to_string(n) + " patches");
  }
  if (!emittance.allFinite()) throw std::invalid_argument("emittance has non-finite values");
  if (options.reflectance) {
    for (size_t k = 0; k < rig.maps.size(); ++k) {
      if (rig.maps[k].reflectance.size() != rig.maps[k].patch.size()) {
        throw std::invalid_argument("RenderOptions::reflectance: projector '" +
                                    rig.projectors[k].name +
                                    "' has no reflectance map (AttachReflectanceMaps)");
      }
    }
  }
  if (options.detail) {
    for (const ProjectorMap& map : rig.maps) {
      if (map.uv.size() != map.patch.size()) {
        throw std::invalid_argument(
            "RenderOptions::detail: the rig has no texture coordinates (build it with "
            "ProjectionRigOptions::texture_coordinates)");
      }
    }
    const int surfaces = static_cast<int>(scene.surfaces.size());
    for (const int surface : rig.surface) {
      if (surface < 0 || surface >= surfaces) {
        throw std::invalid_argument("RenderOptions::detail: the rig's patches name surface " +
                                    std::to_string(surface) + ", the scene has " +
                                    std::to_string(surfaces));
      }
    }
  }
}

// The flux each patch receives from the codes of the images (per patch and channel: the pixels'
// light, mixed, times their solid angle and the patch's coverage).
Eigen::MatrixX3d FluxOfCodes(const ProjectionRig& rig, const std::vector<ProjectorTables>& tables,
                             const std::vector<ProjectorImage>& images) {
  const int n = rig.size();
  const int projector_count = static_cast<int>(rig.projectors.size());
  Eigen::MatrixX3d delivered_flux = Eigen::MatrixX3d::Zero(n, 3);
#pragma omp parallel for schedule(dynamic, 16)
  for (int i = 0; i < n; ++i) {
    Vec3 patch_flux = Vec3::Zero();
    for (int k = 0; k < projector_count; ++k) {
      const ProjectorMap& map = rig.maps[k];
      const ProjectorTables& table = tables[k];
      const auto* codes = reinterpret_cast<const cv::Vec3w*>(images[k].codes.data);
      Vec3 projector_light = Vec3::Zero();
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        const cv::Vec3w& code = codes[map.pixels_by_patch[position]];
        for (int c = 0; c < 3; ++c) projector_light[c] += table.codes[c].Light(code[c]);
      }
      const Vec3 mixed =
          table.identity_mixing ? projector_light : Vec3(table.photometry.mixing * projector_light);
      patch_flux +=
          rig.coverage_scale(i, k) * map.pixel_solid_angle * table.delta.cwiseProduct(mixed);
    }
    delivered_flux.row(i) = patch_flux.transpose();
  }
  return delivered_flux;
}

// One patch's counts in one projector, from ShadePatch.
struct PatchShadeCounts {
  long long saturated = 0, detail_saturated = 0, clipped = 0;
  double light[3] = {0.0, 0.0, 0.0};  // Σ light of the codes, when accounted
};
using PatchShadeFunction = void (*)(const ProjectorMap& map, const ProjectorTables& table,
                                    int first, int end, const Vec3& tau,
                                    const Eigen::Vector3f* pixel_factor, bool account,
                                    cv::Vec3w* codes, Vec3* light, PatchShadeCounts* counts);

// One pixel's relative light r per channel (step 3 of projector_images.h), mixed; counts its
// saturations.
template <bool kFactor>
inline void PixelLight(const ProjectorTables& table, const bool full[3], const Vec3& scale,
                       double share, const Eigen::Vector3f* factor, PatchShadeCounts* counts,
                       double r[3]) {
  bool saturated_by_factor = false, saturated_pixel = false;
  for (int c = 0; c < 3; ++c) {
    double value = 1.0;
    if (!full[c]) {
      value = share * scale[c];
      if constexpr (kFactor) {
        value *= (*factor)[c];
        saturated_by_factor |= value >= 1.0 && (*factor)[c] > 1.0f;
      }
      value = std::min(1.0, value);
    }
    saturated_pixel |= value >= 1.0;
    r[c] = value;
  }
  counts->saturated += saturated_pixel;
  counts->detail_saturated += saturated_by_factor;
  if (!table.identity_mixing) {
    Vec3 mixed;
    if (LightFor(table, Vec3(r[0], r[1], r[2]), &mixed)) ++counts->clipped;
    for (int c = 0; c < 3; ++c) r[c] = mixed[c];
  }
}

// One pixel's codes into the image, and their light into the sums when accounted.
inline void StoreCodes(const ProjectorTables& table, int32_t index, const int q[3], bool account,
                       cv::Vec3w* codes, double sums[3]) {
  codes[index] = cv::Vec3w(static_cast<uint16_t>(q[0]), static_cast<uint16_t>(q[1]),
                           static_cast<uint16_t>(q[2]));
  if (account) {
    for (int c = 0; c < 3; ++c) sums[c] += table.codes[c].Light(q[c]);
  }
}

// A patch's pixels without colour mixing (the hot loop of a frame shaded on the CPU): each
// channel's code below r is walked from the last pixel's instead of looked up, since r changes
// little from pixel to pixel. In the order by pixel (pixels_by_patch, rows of neighbours) the
// walk goes either way; in the order by share (ProjectorMap::pixels_by_share), a flat light's
// r only grows (share times a constant per channel, clipped at 1: rounding keeps the order), so
// it only goes up, its first step without a branch. Either way the same codes as Quantise's
// lookup (tested), with everything in registers.
template <DitherMethod kDither, bool kAccount, bool kFactor, bool kByShare>
void ShadeWalking(const ProjectorMap& map, const ProjectorTables& table, int first, int end,
                  const Vec3& scale, const Eigen::Vector3f* pixel_factor, cv::Vec3w* codes,
                  PatchShadeCounts* counts, double sums[3]) {
  const CodeTable &table_0 = table.codes[0], &table_1 = table.codes[1], &table_2 = table.codes[2];
  const double scale_0 = scale[0], scale_1 = scale[1], scale_2 = scale[2];
  long long saturated = 0, detail_saturated = 0;
  internal::RowThresholds row_thresholds(map.width);  // by pixel
  int32_t index = 0;
  double threshold = 0.5, r_0 = 0.0, r_1 = 0.0, r_2 = 0.0;
  // The pixel at `position`: its index, threshold and r (PixelLight's without mixing; a +inf
  // scale, full drive, gives 1), its saturations counted.
  const auto pixel = [&](int position) {
    double share;
    if constexpr (kByShare) {
      index = map.pixels_by_share[position];
      share = map.share_by_share[position];
      if (kDither == DitherMethod::kOrdered)
        threshold = internal::kBayerThresholds[map.bayer_by_share[position]];
    } else {
      index = map.pixels_by_patch[position];
      share = map.share[index];
      if (kDither == DitherMethod::kOrdered) threshold = row_thresholds.At(index);
    }
    r_0 = share * scale_0;
    r_1 = share * scale_1;
    r_2 = share * scale_2;
    if constexpr (kFactor) {
      const Eigen::Vector3f& factor = pixel_factor[position - first];
      r_0 = scale_0 == kInfinity ? 1.0 : r_0 * factor[0];
      r_1 = scale_1 == kInfinity ? 1.0 : r_1 * factor[1];
      r_2 = scale_2 == kInfinity ? 1.0 : r_2 * factor[2];
      detail_saturated += (r_0 >= 1.0 && factor[0] > 1.0f) | (r_1 >= 1.0 && factor[1] > 1.0f) |
                          (r_2 >= 1.0 && factor[2] > 1.0f);
    }
    r_0 = std::min(1.0, r_0);
    r_1 = std::min(1.0, r_1);
    r_2 = std::min(1.0, r_2);
    saturated += (r_0 >= 1.0) | (r_1 >= 1.0) | (r_2 >= 1.0);
  };
  if (first == end) return;
  pixel(first);
  int below_0 = table_0.Below(r_0), below_1 = table_1.Below(r_1), below_2 = table_2.Below(r_2);
  for (int position = first;;) {
    const int q[3] = {table_0.Round(below_0, r_0, threshold),
                      table_1.Round(below_1, r_1, threshold),
                      table_2.Round(below_2, r_2, threshold)};
    StoreCodes(table, index, q, kAccount, codes, sums);
    if (++position == end) break;
    pixel(position);
    if constexpr (kByShare) {
      below_0 = table_0.BelowFrom(below_0, r_0);
      below_1 = table_1.BelowFrom(below_1, r_1);
      below_2 = table_2.BelowFrom(below_2, r_2);
    } else {
      below_0 = table_0.BelowNear(below_0, r_0);
      below_1 = table_1.BelowNear(below_1, r_1);
      below_2 = table_2.BelowNear(below_2, r_2);
    }
  }
  counts->saturated += saturated;
  counts->detail_saturated += detail_saturated;
}

// One patch's pixels in one projector (step 3 of projector_images.h), specialised for the
// per-pixel branches that are fixed per call: whether the pixels have seamless factors and the
// dither. The hottest loop of a frame shaded on the CPU.
template <bool kFactor, DitherMethod kDither>
void ShadePatch(const ProjectorMap& map, const ProjectorTables& table, int first, int end,
                const Vec3& tau, const Eigen::Vector3f* pixel_factor, bool account,
                cv::Vec3w* codes, Vec3* light, PatchShadeCounts* counts) {
  // Light is linear in the codes' light and mixing: the patch's delivered flux is summed in
  // relative light and mixed once per patch and projector. The sums stay in registers.
  const bool full[3] = {tau[0] == kInfinity, tau[1] == kInfinity, tau[2] == kInfinity};
  const Vec3 scale = tau.cwiseProduct(table.inverse_delta);  // r = share · scale (full: 1)
  double sums[3] = {0.0, 0.0, 0.0};
  if constexpr (kDither != DitherMethod::kErrorDiffusion) {
    if (table.identity_mixing) {
      const bool by_share = !kFactor && !map.pixels_by_share.empty();
      using Loop = decltype(&ShadeWalking<kDither, false, kFactor, false>);
      const Loop loop =
          by_share ? (account ? ShadeWalking<kDither, true, kFactor, true>
                              : ShadeWalking<kDither, false, kFactor, true>)
                   : (account ? ShadeWalking<kDither, true, kFactor, false>
                              : ShadeWalking<kDither, false, kFactor, false>);
      loop(map, table, first, end, scale, pixel_factor, codes, counts, sums);
      for (int c = 0; c < 3; ++c) counts->light[c] = sums[c];
      return;
    }
  }
  internal::RowThresholds row_thresholds(map.width);
  for (int position = first; position < end; ++position) {
    const int32_t index = map.pixels_by_patch[position];
    double r[3];
    PixelLight<kFactor>(table, full, scale, map.share[index],
                        kFactor ? &pixel_factor[position - first] : nullptr, counts, r);
    if constexpr (kDither == DitherMethod::kErrorDiffusion) {
      light[index] = Vec3(r[0], r[1], r[2]);
    } else {
      const double threshold =
          kDither == DitherMethod::kOrdered ? row_thresholds.At(index) : 0.5;
      const int q[3] = {table.codes[0].Quantise(r[0], threshold),
                        table.codes[1].Quantise(r[1], threshold),
                        table.codes[2].Quantise(r[2], threshold)};
      StoreCodes(table, index, q, account, codes, sums);
    }
  }
  for (int c = 0; c < 3; ++c) counts->light[c] = sums[c];
}

PatchShadeFunction PatchShadeFor(bool factor, DitherMethod dither) {
  switch (dither) {
    case DitherMethod::kNone:
      return factor ? ShadePatch<true, DitherMethod::kNone> : ShadePatch<false, DitherMethod::kNone>;
    case DitherMethod::kOrdered:
      return factor ? ShadePatch<true, DitherMethod::kOrdered>
                    : ShadePatch<false, DitherMethod::kOrdered>;
    case DitherMethod::kErrorDiffusion:
      break;
  }
  return factor ? ShadePatch<true, DitherMethod::kErrorDiffusion>
                : ShadePatch<false, DitherMethod::kErrorDiffusion>;
}

}  // namespace

namespace internal {

FirstLevels ComputeFirstLevels(const ProjectionRig& rig, const Eigen::MatrixX3d& emittance) {
  const int n = rig.size();
  FirstLevels first;
  first.target = emittance.cwiseMax(rig.lower).cwiseMin(rig.upper);
  first.flux.resize(n, 3);
  first.level.resize(n, 3);
  for (int i = 0; i < n; ++i) {
    if ((emittance.row(i).array() < rig.lower.row(i).array() - 1e-12).any())
      ++first.patches_below_lower;
    if ((emittance.row(i).array() > rig.upper.row(i).array() + 1e-12).any())
      ++first.patches_above_upper;
    if (!(rig.blended_area[i] > 0.0)) ++first.patches_unreached;
    for (int c = 0; c < 3; ++c) {
      const double rho = rig.reflectance(i, c);
      first.level(i, c) = 0.0;
      first.flux(i, c) = 0.0;
      if (!(rig.blended_area[i] > 0.0) || !(rho > 0.0)) continue;
      const double lit_area = rig.LitArea(i);
      first.flux(i, c) = lit_area * (first.target(i, c) - rig.lower(i, c)) / rho;
      const double capacity = lit_area * (rig.upper(i, c) - rig.lower(i, c)) / rho;
      const bool at_upper =
          first.target(i, c) >= rig.upper(i, c) - kFullDriveTolerance * std::abs(rig.upper(i, c));
      first.level(i, c) = at_upper || first.flux(i, c) >= capacity * (1.0 - 1e-12)
                              ? kInfinity
                              : first.flux(i, c) / rig.blended_area[i];
    }
  }
  return first;
}

int RefineLevels(const ProjectionRig& rig, const std::vector<ProjectorTables>& tables,
                 const std::vector<std::vector<Eigen::Vector3f>>& factors,
                 const Eigen::MatrixX3d& flux, int max_level_passes,
                 const std::vector<char>* refine, Eigen::MatrixX3d* level_out) {
  Eigen::MatrixX3d& level = *level_out;
  const int n = rig.size();
  const int projector_count = static_cast<int>(rig.projectors.size());
  // Each pass sums a patch's pixels in chunks of at most kChunk per projector, the chunks' sums
  // then added in order: the same bits whichever thread sums a chunk, and the few large patches
  // a frame plan refines spread over every thread instead of one each.
  constexpr int kChunk = 2048;
  struct Chunk {
    int patch;  // index into `patches`
    int k, from, to;
  };
  std::vector<int> patches, chunk_begin;
  std::vector<Chunk> chunks;
  for (int i = 0; i < n; ++i) {
    if (refine != nullptr && !(*refine)[i]) continue;
    chunk_begin.push_back(static_cast<int>(chunks.size()));
    for (int k = 0; k < projector_count; ++k) {
      const ProjectorMap& map = rig.maps[k];
      for (int from = map.patch_begin[i]; from < map.patch_begin[i + 1]; from += kChunk)
        chunks.push_back({static_cast<int>(patches.size()), k, from, std::min(from + kChunk, map.patch_begin[i + 1])});
    }
    patches.push_back(i);
  }
  chunk_begin.push_back(static_cast<int>(chunks.size()));
  std::vector<Vec3> free_area(chunks.size()), clamped(chunks.size());
  std::vector<char> active(patches.size(), 1);
  int most_passes = n > 0 ? 1 : 0;
  for (int pass = 1; pass <= max_level_passes; ++pass) {
    if (std::find(active.begin(), active.end(), 1) == active.end()) break;
    most_passes = std::max(most_passes, pass);
#pragma omp parallel for schedule(dynamic, 8)
    for (size_t c_index = 0; c_index < chunks.size(); ++c_index) {
      const Chunk& chunk = chunks[c_index];
      if (!active[chunk.patch]) continue;
      const int i = patches[chunk.patch];
      const ProjectorMap& map = rig.maps[chunk.k];
      const ProjectorTables& table = tables[chunk.k];
      const double scale = rig.coverage_scale(i, chunk.k);
      const Eigen::Vector3f* pixel_factor = factors.empty() ? nullptr : factors[chunk.k].data();
      Vec3 chunk_free = Vec3::Zero(), chunk_clamped = Vec3::Zero();
      for (int position = chunk.from; position < chunk.to; ++position) {
        const double plain_share = map.share[map.pixels_by_patch[position]];  // w a / Ω
        for (int c = 0; c < 3; ++c) {
          if (level(i, c) == kInfinity) continue;
          const double share = pixel_factor ? plain_share * pixel_factor[position][c] : plain_share;
          if (share * level(i, c) * table.inverse_delta[c] >= 1.0) {
            chunk_clamped[c] += scale * map.pixel_solid_angle * table.delta[c];
          } else {
            chunk_free[c] += scale * share * map.pixel_solid_angle;
          }
        }
      }
      free_area[c_index] = chunk_free;
      clamped[c_index] = chunk_clamped;
    }
#pragma omp parallel for schedule(dynamic, 16)
    for (size_t p = 0; p < patches.size(); ++p) {
      if (!active[p]) continue;
      const int i = patches[p];
      Vec3 patch_free = Vec3::Zero(), patch_clamped = Vec3::Zero();
      for (int c_index = chunk_begin[p]; c_index < chunk_begin[p + 1]; ++c_index) {
        patch_free += free_area[c_index];
        patch_clamped += clamped[c_index];
      }
      bool changed = false;
      for (int c = 0; c < 3; ++c) {
        if (level(i, c) == kInfinity || patch_clamped[c] <= 0.0) continue;
        const double remaining = std::max(0.0, flux(i, c) - patch_clamped[c]);
        const double updated = patch_free[c] > 0.0 ? remaining / patch_free[c] : kInfinity;
        if (updated > level(i, c) * (1.0 + 1e-12)) {
          level(i, c) = updated;
          changed = true;
        }
      }
      active[p] = changed;
    }
  }
  return most_passes;
}

std::vector<ProjectorImage> ShadeImages(const ProjectionRig& rig,
                                        const std::vector<ProjectorTables>& tables,
                                        const Eigen::MatrixX3d& level,
                                        const std::vector<std::vector<Eigen::Vector3f>>& factors,
                                        DitherMethod dither, const Eigen::MatrixX3d& target,
                                        RenderSummary* summary,
                                        const std::vector<char>* projectors,
                                        const PatchFactorFunction& patch_factors,
                                        std::vector<ProjectorImage> reuse) {
  // Without a summary nobody reads the delivered flux: the pixels' light is not summed.
  const bool account = summary != nullptr;
  RenderSummary local;
  RenderSummary& s = account ? *summary : local;
  const int n = rig.size();
  const int projector_count = static_cast<int>(rig.projectors.size());
  std::vector<char> wanted(projector_count, 1);
  if (projectors != nullptr) wanted = *projectors;
  const bool all = std::find(wanted.begin(), wanted.end(), 0) == wanted.end();
  std::vector<ProjectorImage> images = std::move(reuse);
  images.resize(projector_count);
  const bool diffuse = dither == DitherMethod::kErrorDiffusion;
  std::vector<std::vector<Vec3>> light(projector_count);
  for (int k = 0; k < projector_count; ++k) {
    if (!wanted[k]) {
      images[k] = ProjectorImage();
      continue;
    }
    images[k].bits = rig.projectors[k].photometry.bits;
    const cv::Mat& codes = images[k].codes;
    if (codes.rows != rig.maps[k].height || codes.cols != rig.maps[k].width ||
        codes.type() != CV_16UC3 || !codes.isContinuous()) {
      images[k].codes =
          cv::Mat(rig.maps[k].height, rig.maps[k].width, CV_16UC3, cv::Scalar::all(0));
    }
    if (diffuse) light[k].assign(rig.maps[k].patch.size(), Vec3::Zero());
  }
  Eigen::MatrixX3d delivered_flux = Eigen::MatrixX3d::Zero(n, 3);
  std::vector<long long> saturated(projector_count, 0), clipped(projector_count, 0),
      detail_saturated(projector_count, 0);
#pragma omp parallel
  {
    std::vector<long long> my_saturated(projector_count, 0), my_clipped(projector_count, 0),
        my_detail_saturated(projector_count, 0);
    std::vector<Eigen::Vector3f> patch_buffer;  // patch_factors' output
#pragma omp for schedule(dynamic, 16)
    for (int i = 0; i < n; ++i) {
      const Vec3 tau = level.row(i).transpose();
      Vec3 patch_flux = Vec3::Zero();
      for (int k = 0; k < projector_count; ++k) {
        if (!wanted[k]) continue;
        const ProjectorMap& map = rig.maps[k];
        const ProjectorTables& table = tables[k];
        auto* codes = reinterpret_cast<cv::Vec3w*>(images[k].codes.data);
        const int first = map.patch_begin[i];
        // The factors of this patch's pixels, by position − first (null: all 1).
        const Eigen::Vector3f* pixel_factor = nullptr;
        if (patch_factors) {
          patch_buffer.resize(map.patch_begin[i + 1] - first);
          if (patch_factors(i, k, patch_buffer.data())) pixel_factor = patch_buffer.data();
        } else if (!factors.empty()) {
          pixel_factor = factors[k].data() + first;
        }
        PatchShadeCounts counts;
        const PatchShadeFunction shade =
            PatchShadeFor(pixel_factor != nullptr, dither);
        shade(map, table, first, map.patch_begin[i + 1], tau, pixel_factor, account, codes,
              diffuse ? light[k].data() : nullptr, &counts);
        my_clipped[k] += counts.clipped;
        my_saturated[k] += counts.saturated;
        my_detail_saturated[k] += counts.detail_saturated;
        const Vec3 projector_light(counts.light[0], counts.light[1], counts.light[2]);
        if (!diffuse) {
          const Vec3 mixed = table.identity_mixing
                                 ? projector_light
                                 : Vec3(table.photometry.mixing * projector_light);
          patch_flux +=
              rig.coverage_scale(i, k) * map.pixel_solid_angle * table.delta.cwiseProduct(mixed);
        }
      }
      delivered_flux.row(i) = patch_flux.transpose();
    }
#pragma omp critical
    for (int k = 0; k < projector_count; ++k) {
      saturated[k] += my_saturated[k];
      clipped[k] += my_clipped[k];
      detail_saturated[k] += my_detail_saturated[k];
    }
  }
  if (diffuse) {
    // Error diffusion runs in raster order per image; then the flux per patch from the codes.
#pragma omp parallel for schedule(static, 1)
    for (int k = 0; k < projector_count; ++k) {
      if (wanted[k]) QuantiseErrorDiffusion(rig.maps[k], tables[k], light[k], &images[k].codes);
    }
    if (all && account) delivered_flux = FluxOfCodes(rig, tables, images);
  }
  if (!account) return images;
  s.saturated_pixels = saturated;
  s.clipped_pixels = clipped;
  s.detail_saturated_pixels = detail_saturated;
  if (!all) {
    s.delivered.resize(0, 3);
    s.max_relative_error = 0.0;
    return images;
  }
  s.delivered = rig.lower;
  for (int i = 0; i < n; ++i) {
    const double lit_area = rig.LitArea(i);
    if (!(lit_area > 0.0)) continue;
    s.delivered.row(i) +=
        (rig.reflectance.row(i).array() * delivered_flux.row(i).array() / lit_area).matrix();
  }
  const double scale = std::max(rig.upper.maxCoeff(), std::numeric_limits<double>::min());
  s.max_relative_error = n > 0 ? (s.delivered - target).cwiseAbs().maxCoeff() / scale : 0.0;
  return images;
}

}  // namespace internal

std::vector<ProjectorImage> RenderProjectorImages(const ProjectionRig& rig, const Scene& scene,
                                                  const Eigen::MatrixX3d& emittance,
                                                  const RenderOptions& options,
                                                  RenderSummary* summary) {
  CheckRenderInputs(rig, scene, emittance, options);
  const auto start = Clock::now();
  RenderSummary local;
  RenderSummary& s = summary ? *summary : local;
  if (!options.detail && !options.reflectance) {
    // A frame plan (levels per patch, the seamless field's node values) shaded on the CPU.
    const FramePlanner planner(rig, options);
    const FramePlan plan = planner.Plan(emittance);
    std::vector<ProjectorImage> images = ShadeProjectorImages(planner, plan, &s);
    s.seconds = SecondsSince(start);
    return images;
  }
  s = RenderSummary();
  std::vector<ProjectorTables> tables;
  tables.reserve(rig.projectors.size());
  for (const Projector& projector : rig.projectors) tables.emplace_back(projector);
  // Step 1: the flux above black each patch needs, and the first guess of its level τ.
  internal::FirstLevels first = internal::ComputeFirstLevels(rig, emittance);
  s.patches_below_lower = first.patches_below_lower;
  s.patches_above_upper = first.patches_above_upper;
  s.patches_unreached = first.patches_unreached;
  std::vector<std::vector<Eigen::Vector3f>> reflectance_factors;
  const std::vector<std::vector<Eigen::Vector3f>> factors =
      PixelFactors(rig, scene, first.flux, options, &s.detail_pixels, &reflectance_factors);
  // Step 2, per patch: Newton from below on Σ_p min(w a τ, Ω Δ) = Φ.
  s.level_passes = internal::RefineLevels(rig, tables, factors, first.flux,
                                          options.max_level_passes, nullptr, &first.level);
  // Step 3: per pixel relative output → light → dithered codes; the flux they deliver.
  std::vector<ProjectorImage> images =
      internal::ShadeImages(rig, tables, first.level, factors, options.dither, first.target, &s);
  if (options.reflectance) {
    for (const ProjectorMap& map : rig.maps) s.reflectance_pixels += map.lit_pixels;
    s.reflectance_saturated_pixels = ReflectanceSaturatedPixels(rig, reflectance_factors, images);
  }
  s.seconds = SecondsSince(start);
  return images;
}

Eigen::MatrixX3d SimulateDirectLight(const PatchLevel& level,
                                     const std::vector<Projector>& projectors,
                                     const std::vector<ProjectorImage>& images,
                                     int samples_per_side, double ray_margin) {
  if (images.size() != projectors.size()) {
    throw std::invalid_argument(std::to_string(images.size()) + " images for " +
                                std::to_string(projectors.size()) + " projectors");
  }
  for (size_t k = 0; k < projectors.size(); ++k) {
    const ProjectorGeometry& geometry = projectors[k].geometry;
    const cv::Mat& codes = images[k].codes;
    if (codes.cols != geometry.width() || codes.rows != geometry.height() ||
        codes.type() != CV_16UC3) {
      throw std::invalid_argument("projector '" + projectors[k].name + "': image is " +
                                  std::to_string(codes.cols) + "x" + std::to_string(codes.rows) +
                                  ", the projector " + std::to_string(geometry.width()) + "x" +
                                  std::to_string(geometry.height()));
    }
    if (images[k].bits != projectors[k].photometry.bits) {
      throw std::invalid_argument("projector '" + projectors[k].name + "': image has " +
                                  std::to_string(images[k].bits) + " bits, the projector " +
                                  std::to_string(projectors[k].photometry.bits));
    }
  }
  const RayScene rays(PatchScene(level));
  const int n = level.size();
  Eigen::MatrixX3d exitance = Eigen::MatrixX3d::Zero(n, 3);
#pragma omp parallel for schedule(dynamic, 4)
  for (int i = 0; i < n; ++i) {
    const Patch& patch = level.patches[i];
    std::vector<PatchSample> samples;
    SamplePatch(patch, samples_per_side, &samples);
    Vec3 irradiance_integral = Vec3::Zero();
    double area = 0.0;
    for (const PatchSample& sample : samples) {
      area += sample.weight;
      for (size_t k = 0; k < projectors.size(); ++k) {
        const ProjectorGeometry& geometry = projectors[k].geometry;
        Vec2 q;
        const double gain = geometry.Gain(sample.point, patch.normal, &q);
        if (!(gain > 0.0) || !geometry.InImage(q)) continue;
        if (rays.Occluded(sample.point, geometry.CentreInWorld(), ray_margin)) continue;
        const int column =
            std::clamp(static_cast<int>(std::lround(q.x())), 0, geometry.width() - 1);
        const int row = std::clamp(static_cast<int>(std::lround(q.y())), 0, geometry.height() - 1);
        const cv::Vec3w code = images[k].codes.at<cv::Vec3w>(row, column);
        const double max_code = projectors[k].photometry.MaxCode();
        const Vec3 drive(code[0] / max_code, code[1] / max_code, code[2] / max_code);
        irradiance_integral += sample.weight * gain * projectors[k].photometry.Output(drive);
      }
    }
    exitance.row(i) =
        (level.reflectance.row(i).array() * irradiance_integral.transpose().array() / area)
            .matrix();
  }
  return exitance;
}

std::string EncodeProjectorImage(const ProjectorImage& image, int compression) {
  cv::Mat bgr;
  if (image.bits == 8) {
    image.codes.convertTo(bgr, CV_8UC3);
  } else {
    image.codes.convertTo(bgr, CV_16UC3, 65535.0 / ((1 << image.bits) - 1));
  }
  cv::cvtColor(bgr, bgr, cv::COLOR_RGB2BGR);
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", bgr, bytes, {cv::IMWRITE_PNG_COMPRESSION, compression})) {
    throw IoError("cannot encode a PNG");
  }
  return std::string(bytes.begin(), bytes.end());
}

std::vector<std::string> EncodeProjectorImages(const std::vector<ProjectorImage>& images,
                                               int compression) {
  std::vector<std::string> encoded(images.size());
  const int count = static_cast<int>(images.size());
#pragma omp parallel for schedule(static, 1)
  for (int k = 0; k < count; ++k) encoded[k] = EncodeProjectorImage(images[k], compression);
  return encoded;
}

void WriteProjectorImage(const std::filesystem::path& path, const ProjectorImage& image) {
  WriteFileAtomically(path, EncodeProjectorImage(image));
}

ProjectorImage ReadProjectorImage(const std::filesystem::path& path, int bits) {
  const std::string file = path.string();
  const cv::Mat raw = ReadImage(path, cv::IMREAD_UNCHANGED);
  if (raw.channels() != 3)
    throw IoError(file + ": must be an RGB image, has " + std::to_string(raw.channels()) +
                  " channels");
  ProjectorImage image;
  image.bits = bits;
  const int max_code = (1 << bits) - 1;
  cv::Mat rgb;
  cv::cvtColor(raw, rgb, cv::COLOR_BGR2RGB);
  if (raw.depth() == CV_8U) {
    if (bits != 8)
      throw IoError(file + ": 8-bit image for a " + std::to_string(bits) + "-bit projector");
    rgb.convertTo(image.codes, CV_16UC3);
  } else if (raw.depth() == CV_16U) {
    rgb.convertTo(image.codes, CV_16UC3, max_code / 65535.0);  // rounds to the nearest code
  } else {
    throw IoError(file + ": must be an 8- or 16-bit image");
  }
  return image;
}

cv::Mat PatternFromImage(const ProjectorImage& image) {
  cv::Mat codes = image.codes;
  if (image.bits != 8) codes.convertTo(codes, CV_16UC3, 255.0 / ((1 << image.bits) - 1));
  cv::Mat rgb8, bgr8;
  codes.convertTo(rgb8, CV_8UC3);
  cv::cvtColor(rgb8, bgr8, cv::COLOR_RGB2BGR);
  return bgr8;
}

}  // namespace procam
