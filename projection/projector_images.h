#pragma once
// Emittance → projector images, and the reverse simulation (images → direct light on patches).
//
// Rendering (per patch i and channel c, with the rig's flux bookkeeping, projection_rig.h):
// 1. The light above black the patch must receive is Φ = f_i A_i (E_i − lower_i) / ρ_i, with E
//    clipped to [lower, upper] (the summary counts the patches that were outside) and f_i the
//    part of the patch the bounds and E describe (ProjectionRig::lit_fraction: 1 for a patch
//    some projector lights wholly; a partly lit patch's E is that of its lit part). An E within
//    kFullDriveTolerance of its upper bound (relative) is at the bound: every pixel of the patch
//    at full drive. That is a binary16 step, so the emittance a display node receives in half
//    precision (nodes/messages.h) renders as the solver's float64 does at the bounds, where a
//    solution often sits; without it a rounding down made the patch a per-pixel refinement whose
//    least-share pixels fell a code or two below full drive.
// 2. It is spread as a uniform irradiance τ above black over the patch's lit area, shared among
//    the projectors by the blending weights: pixel p (projector k, weight w, gain g) shows the
//    relative level s = w τ / (g (max_k − black_k)), which sends flux w a τ (a = Ω_k / g its
//    footprint, rescaled where the projector lights the patch wholly: projection_rig.h).
//    τ solves Σ_p min(w a τ, Ω_k (max_k − black_k)) = Φ: where a pixel saturates, the rest of
//    the patch rises to make up for it (Newton from below on this concave piecewise-linear
//    function, each step one pass over the patch's pixels: exact after finitely many, one for
//    most patches), so every E in [lower, upper] is delivered exactly before quantisation.
// 3. Colour mixing and the response are inverted per pixel: relative light r = mixing⁻¹ s,
//    clipped to [0,1]³ (colours outside the projector's gamut), then quantised to the
//    projector's bits with dithering in linear light: between the two code values whose light
//    brackets r, the upper one is chosen with probability proportional to r's position between
//    them, so the expected light of every pixel is exactly r.
// Pixels that light nothing show code 0 (the projector's black level).
// Steps 1–2 are per patch and step 3 per pixel: frame_plan.h splits them (a frame plan shaded on
// the CPU, or on a GPU by gl_renderer.h); without detail this renderer is that plan and its CPU
// shading.
//
// Detail (RenderOptions::detail, the paper's Fig. 2): E is constant per patch, but a surface's
// desired appearance may be a texture with detail finer than the patches. With detail on, the
// uniform level τ of step 2 becomes τ · d_p per pixel and channel, d_p the texture's detail at
// the point the pixel lights: T(uv_p) / T̄_i, clamped to [detail_min, detail_max], T̄_i the
// texture's mean over the patch as its pixels light it (weights w a), and the clamped ratios
// divided by their own weighted mean so they average 1 over the patch. Σ_p w a d_p τ is then
// what Σ_p w a τ was: the patch still receives Φ, and its light varies within it like the
// texture. Pixels that d pushes beyond full drive saturate and the rest of the patch makes up
// for them (step 2 with w a d in place of w a); the summary counts them. Surfaces without a
// texture get d = 1: the same images as without detail.
//
// Reflectance (RenderOptions::reflectance): a patch has one reflectance ρ_i in the model, while
// the surface under it may be printed or unevenly painted. With the measured reflectance ρ_p of
// the point each pixel lights (ProjectorMap::reflectance), τ becomes τ · q_p per pixel and
// channel with q_p = ρ̄_i / ρ_p, ρ̄_i the patch's mean of ρ_p as its pixels light it (weights
// w a), clamped to [1/reflectance_ratio_max, reflectance_ratio_max] and divided by its own
// weighted mean: the patch keeps its flux Φ, and the exitance ρ_p · τ q_p is the same at every
// pixel of the patch (where no pixel saturates), so a poster or a stain fades. Where the
// projector's range runs out (dark points asking for more than full drive) those pixels saturate
// and the rest of the patch makes up the flux (step 2). Keeping the flux while moving light from
// bright to dark points lowers the patch's mean exitance by the factor 1 / mean(ρ̄/ρ) (≤ 1, to
// second order in ρ's spread: 0.1% for ±5% paint). With detail or the seamless light, the
// factors multiply and are renormalised to mean 1.
//
// Light (RenderOptions::light): with kFlat, step 2's level is uniform over each patch, so the
// light steps at every patch border and the patch grid shows on surfaces meant to look even. With
// kSmooth (the default), τ becomes τ · m_p per pixel and channel, m the seamless light's factor
// (seamless_light.h): a smooth field over each surface fitted to the patches' levels, stepping
// only between surfaces and where the desired colour steps, with a weighted mean of 1 over every
// patch, so that each patch receives the same flux as with kFlat. With detail too, the two
// factors multiply and are renormalised to mean 1. Saturation is handled as for detail (step 2
// with w a m in place of w a).

#include <Eigen/Core>
#include <filesystem>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "geometry/patches.h"
#include "geometry/scene.h"
#include "projection/projection_rig.h"
#include "projection/seamless_light.h"

namespace procam {

enum class DitherMethod {
  kNone,            // round to the nearest code value in linear light
  kOrdered,         // 8×8 Bayer threshold matrix: parallel, pattern fixed in the image
  kErrorDiffusion,  // Floyd–Steinberg (serpentine) in linear light, per channel; sequential
};
const char* DitherName(DitherMethod method);
bool ParseDither(const std::string& name, DitherMethod* method);

// How the light within a patch is shaped (header comment).
enum class LightField {
  kFlat,    // one uniform level per patch
  kSmooth,  // seamless: a smooth field over each surface, each patch's flux kept
};
const char* LightFieldName(LightField light);
bool ParseLightField(const std::string& name, LightField* light);

struct RenderOptions {
  DitherMethod dither = DitherMethod::kOrdered;
  LightField light = LightField::kSmooth;
  SeamlessLightOptions seamless;  // the smooth field, for LightField::kSmooth
  // Evaluations of each patch's level solve (step 2) at most, in [1, 1000].
  int max_level_passes = 16;
  // Modulate each pixel's light by the desired texture's detail at the point it lights (header
  // comment). Needs the overload of RenderProjectorImages that takes the scene, and a rig built
  // with ProjectionRigOptions::texture_coordinates.
  bool detail = false;
  // Range of the detail ratio T / T̄ per channel before it is renormalised: 0 < detail_min ≤ 1 ≤
  // detail_max ≤ 1000. Bounds the contrast one patch's light may take on (dark texels still get
  // detail_min of the patch's mean level, bright ones at most detail_max).
  double detail_min = 0.2, detail_max = 5.0;
  // Divide each pixel's light by the measured reflectance of the point it lights relative to
  // its patch's (header comment, "Reflectance"). Needs every projector's map to carry
  // ProjectorMap::reflectance (AttachReflectanceMaps).
  bool reflectance = false;
  // The factor ρ̄ / ρ per channel is clamped to [1 / reflectance_ratio_max,
  // reflectance_ratio_max] before it is renormalised, in [1, 1000]: a point measured nearly
  // black is not asked for unbounded light.
  double reflectance_ratio_max = 5.0;
  bool Check(std::string* why) const;
};

// One projector's image: code values, row 0 = top, RGB order (not OpenCV's BGR). Copies share
// pixels (cv::Mat): clone `codes` before changing a copy.
struct ProjectorImage {
  cv::Mat codes;  // CV_16UC3, each in [0, 2^bits − 1]
  int bits = 8;
};

struct RenderSummary {
  double seconds = 0.0;
  int level_passes = 0;         // most evaluations of step 2 a patch needed (1: none saturated)
  int patches_below_lower = 0;  // E below the projectors' black on some channel (clipped)
  int patches_above_upper = 0;  // E above full white on some channel (clipped)
  int patches_unreached = 0;    // patches no projector lights
  std::vector<long long> saturated_pixels;  // per projector: some channel at full drive
  std::vector<long long> clipped_pixels;    // per projector: outside the gamut (mixing)
  // Per projector: pixels at full drive on a channel the detail, the reflectance or the seamless
  // light raises (factor > 1): where the texture's highlights, the darkest printed points or the
  // field's peaks are clipped (included in saturated_pixels). Zeros with none of them.
  std::vector<long long> detail_saturated_pixels;
  // Lit pixels whose patch's surface has a texture (all projectors); 0 without detail.
  long long detail_pixels = 0;
  // With RenderOptions::reflectance: the lit pixels shaped by their measured reflectance (all
  // projectors), and of those the ones at full drive on a channel their reflectance factor raises
  // (ρ̄/ρ > 1): the points too dark for the projectors' range to even out. 0 without.
  long long reflectance_pixels = 0, reflectance_saturated_pixels = 0;
  // (n,3) exitance the quantised images deliver, by the rig's flux bookkeeping.
  Eigen::MatrixX3d delivered;
  // Largest |delivered − clip(E)| relative to max(upper), over patches and channels.
  double max_relative_error = 0.0;
};

// Images for every projector of the rig that make each patch's direct-light exitance E (n,3).
// Throws std::invalid_argument if E has the wrong shape or non-finite values, or the options
// fail Check(), or ask for detail (which needs the scene: the overload below).
std::vector<ProjectorImage> RenderProjectorImages(const ProjectionRig& rig,
                                                  const Eigen::MatrixX3d& emittance,
                                                  const RenderOptions& options,
                                                  RenderSummary* summary);

// The same, with the scene whose subdivision the rig was built on: with RenderOptions::detail
// its surfaces' desired textures modulate the light within each patch. Throws
// std::invalid_argument also if detail is on and the rig has no texture coordinates, or the
// scene has fewer surfaces than the rig's patches name.
std::vector<ProjectorImage> RenderProjectorImages(const ProjectionRig& rig, const Scene& scene,
                                                  const Eigen::MatrixX3d& emittance,
                                                  const RenderOptions& options,
                                                  RenderSummary* summary);

// Direct-light exitance (n,3) the images deliver to each patch, integrated independently of the
// rig's maps: samples_per_side² Gauss points per patch (SamplePatch), each projected forward
// into every projector, checked for occlusion by a shadow ray, lit by the pixel it falls in
// (irradiance = output(drive) · Gain), then ρ × the patch average. Throws std::invalid_argument
// naming the projector if an image's size or bit depth does not match it.
Eigen::MatrixX3d SimulateDirectLight(const PatchLevel& level,
                                     const std::vector<Projector>& projectors,
                                     const std::vector<ProjectorImage>& images,
                                     int samples_per_side, double ray_margin = 1e-4);

// PNG: 8-bit for 8-bit projectors, 16-bit for 10-bit ones (codes scaled by 65535/1023, which
// ReadProjectorImage undoes exactly). Written atomically. Throws IoError.
void WriteProjectorImage(const std::filesystem::path& path, const ProjectorImage& image);
// The PNG as bytes (what WriteProjectorImage writes); `compression` 0–9.
std::string EncodeProjectorImage(const ProjectorImage& image, int compression = 1);
// Several at once, one image per thread (PNG encoding is the slow part of writing images).
std::vector<std::string> EncodeProjectorImages(const std::vector<ProjectorImage>& images,
                                               int compression = 1);
// Reads an 8- or 16-bit RGB PNG as codes of a `bits`-bit projector. Throws IoError naming the
// file if it cannot be read or its depth does not fit.
ProjectorImage ReadProjectorImage(const std::filesystem::path& path, int bits);

// An image as a display pattern: its codes at 8 bits (scaled from the image's bit depth), B, G, R
// (CV_8UC3), as capture's PatternDisplay shows patterns.
cv::Mat PatternFromImage(const ProjectorImage& image);

}  // namespace procam
