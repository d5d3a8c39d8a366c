#pragma once
// What each projector pixel lights, and what the projectors together can deliver to each patch.
//
// Maps: every pixel's ray (projector.h conventions) is cast through Embree against the fine
// patches themselves (each patch one geometry, so the first hit IS the patch: no inverse
// bilinear map or barycentric lookup needed, and patches tile their surfaces exactly, so the
// first hit is also the first surface hit: occlusion comes for free). A pixel whose ray misses
// everything, or first meets a surface from its unlit side, lights nothing and stays black.
//
// Light bookkeeping is by flux: a pixel of projector k at drive d sends the flux
// output_k(d) · Ω_k (Ω_k = 1 / AxisPixelDensity(), steradians · 1 m², so that output is the
// on-axis irradiance at 1 m) onto the patch its ray hits. Its footprint there has area
// a = Ω_k / g with g the geometric gain (cos θ / d² times the lens's off-axis pixel density
// ratio, projector.h), so spread over the footprint that flux is the irradiance output · g:
// incidence cosine and inverse-square falloff are in the gain, and summing flux over pixels
// integrates irradiance over the patch. A patch's direct-light exitance is
// E_i = ρ_i · (flux received) / A_i; the bounds below are what the images of
// projector_images.h deliver with all lit pixels at drive 0, or at full white.
//
// Counting the pixels whose CENTRE falls on a patch misjudges its lit area by up to a row of
// pixels along each edge (several % for patches 20–50 pixels across), although the light on
// the surface is continuous across patch edges. So wherever a projector lights a patch wholly
// (coverage_samples² Gauss points and the corners all in its image, facing it, unoccluded), its
// pixels' footprints there are rescaled to sum to the patch's exact area (`coverage_scale`):
// the bounds become the quadrature of g · output over the patch to second order, and uniform
// light over neighbouring patches is delivered uniformly. Patches cut by an image border or a
// shadow edge keep the pixel count (error about ½ pixel row along the cut).
//
// Partly lit patches: a patch that no projector lights wholly (cut by an image border or a shadow
// edge) receives light on part of its area only. Its bounds, and the emittance E the renderer
// delivers to it, are by default those of its LIT PART (`ProjectionRigOptions::lit_part`): the
// patch's flux bounds divided by its lit fraction f = blended_area / A (≤ 1), so that E is the
// exitance the lit part shows and the renderer spreads the flux f A (E − lower) / ρ over it. That
// part then looks like its wholly lit neighbours at the same E. The alternative (lit_part off)
// keeps E the patch's mean: the whole flux A (E − lower) / ρ crowds into the lit part, which
// then shows 1/f times the light of its neighbours — a bright tile beside a dark remainder,
// every patch along a shadow or the edge of the projectors' reach standing out as a seam. The
// light transport's model still counts E over the whole patch, so it overestimates the bounce
// from partly lit patches by 1/f (they are few: those along shadows and image borders).
//
// Blending: where projectors overlap, each pixel's share of the light above black is its
// weight w = a_k / Σ_j a_j at the surface point, a_j = g_j · luminance(max_j − black_j) ·
// feather_j, summed over the projectors j that reach the point unoccluded. feather_j ramps
// smoothly (C¹) from 0 to 1 over `feather` of the image size, measured in projector j's image
// from its border and from the far side of occluders' silhouettes (where j's shadow begins on
// the surface behind): overlaps cross-fade without seams, also where one projector's shadow
// falls inside another's light.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "geometry/patches.h"
#include "geometry/ray_scene.h"
#include "geometry/scene.h"
#include "projection/projector.h"

namespace procam {

struct ProjectionRigOptions {
  // Width of the blending ramp at each image border, as a fraction of min(width, height), in
  // [0, 0.5]; 0 gives hard edges (each overlapping projector then shares by gain only).
  double feather = 0.1;
  // Gauss points per side used to decide whether a projector lights a patch wholly, [1, 16].
  int coverage_samples = 4;
  // Shadow rays start and end this far from surfaces (metres, > 0): larger than Embree's
  // single-precision error at room scale (~1e-6 m), smaller than any gap that matters.
  double ray_margin = 1e-4;
  // Also record the texture coordinate of every lit pixel's hit (ProjectorMap::uv), which the
  // detail modulation of projector_images.h needs; off by default (8 bytes per pixel).
  bool texture_coordinates = false;
  // Bounds of partly lit patches for their lit part (header comment); off: for the patch's mean.
  bool lit_part = true;
  bool Check(std::string* why) const;
};

// One projector's per-pixel map, row-major (index = row · width + column).
struct ProjectorMap {
  int width = 0, height = 0;
  std::vector<int32_t> patch;  // fine patch the pixel lights, −1 for none
  std::vector<float> gain;     // g at the hit (1/m²); 0 where patch is −1
  std::vector<float> weight;   // blending weight in (0, 1]; 0 where patch is −1
  std::vector<float> share;    // weight / gain (m²): the pixel's output per unit irradiance level
  // Texture coordinate (Patch::uv interpolated, PatchTextureCoordinate) of the point the pixel
  // lights; (0, 0) where patch is −1. Empty unless ProjectionRigOptions::texture_coordinates.
  std::vector<Eigen::Vector2f> uv;
  // Measured reflectance (linear R, G, B) of the point each pixel lights, row-major, from the
  // rig's reflectance map (projection/reflectance_map.h) through AttachReflectanceMaps; empty
  // unless attached. What RenderOptions::reflectance divides each pixel's light by.
  std::vector<Eigen::Vector3f> reflectance;
  double pixel_solid_angle = 0.0;  // Ω_k = 1 / axis pixel density (sr; flux per unit output, m²)
  // The lit pixels grouped by patch: those of patch i are pixels_by_patch[patch_begin[i] ..
  // patch_begin[i + 1]), ascending.
  std::vector<int> patch_begin;          // (n + 1)
  std::vector<int32_t> pixels_by_patch;  // (lit_pixels)
  // (lit_pixels) The world point (metres) each lit pixel's ray hits, in pixels_by_patch's order:
  // where the seamless light of projector_images.h evaluates its smooth field.
  std::vector<Eigen::Vector3f> point_by_patch;
  // The lit pixels of each patch once more (the same ranges patch_begin[i] .. patch_begin[i+1]),
  // by ascending share within the patch, with each one's share and 8×8 Bayer cell
  // ((y mod 8)·8 + x mod 8): the order in which a flat light's codes only grow, so that the CPU
  // shading walks each channel's code up from the last pixel's instead of looking it up. Empty
  // in a map built by hand (the shading then goes by pixels_by_patch).
  std::vector<int32_t> pixels_by_share;
  std::vector<float> share_by_share;
  std::vector<uint8_t> bayer_by_share;
  int lit_pixels = 0;       // pixels with a patch
  int patches_reached = 0;  // distinct patches lit
};

// Everything the renderer needs, for one patch level and a set of projectors.
struct ProjectionRig {
  std::vector<Projector> projectors;
  std::vector<ProjectorMap> maps;  // one per projector
  Eigen::VectorXd area;            // (n) A_i, m²
  Eigen::MatrixX3d reflectance;    // (n,3) ρ
  std::vector<int> surface;        // (n) the scene surface each patch belongs to (Patch::surface)
  Eigen::MatrixX3d centroid;       // (n,3) Patch::centroid, metres
  Eigen::MatrixX3d desired;        // (n,3) PatchLevel::desired_linear (empty if the level has none)
  std::vector<std::array<int, 2>> adjacency;  // PatchLevel::adjacency
  // (n,3) direct-light exitance bounds: ρ · flux / (f A), f = lit_fraction (1 without lit_part).
  Eigen::MatrixX3d lower, upper;
  // (n) Σ over the pixels lighting the patch of w · a · coverage_scale (m²): the patch's lit
  // area as the blending weights share it; 0 for a patch no projector reaches.
  Eigen::VectorXd blended_area;
  // (n, projectors) factor on the footprints of projector k's pixels on patch i: the patch's
  // area over their counted footprint where k lights it wholly, else 1.
  Eigen::MatrixXd coverage_scale;
  // (n) the part of the patch's area the bounds and E describe (header comment): 1 where some
  // projector lights the patch wholly, or without ProjectionRigOptions::lit_part; else
  // min(1, blended_area / A); 0 for a patch no projector reaches.
  Eigen::VectorXd lit_fraction;

  int size() const { return static_cast<int>(area.size()); }
  // The area (m²) patch i's bounds and E describe: lit_fraction · A.
  double LitArea(int i) const { return lit_fraction[i] * area[i]; }
};

struct ProjectionRigSummary {
  double seconds = 0.0;
  int patches_reached = 0;  // by at least one projector
};

// Builds the maps and bounds. Throws IoError naming the projector (and its .cameramodel) if one
// lights no patch, and std::invalid_argument if the options fail Check().
ProjectionRig BuildProjectionRig(const PatchLevel& level, std::vector<Projector> projectors,
                                 const ProjectionRigOptions& options,
                                 ProjectionRigSummary* summary = nullptr);

// Attaches one reflectance map per projector (CV_32FC3, linear R, G, B, the projector's size;
// ProjectorMap::reflectance); an empty map leaves that projector's unattached. Throws
// std::invalid_argument naming the projector when the count or a size differs, or a value is
// not finite and ≥ 0.
void AttachReflectanceMaps(const std::vector<cv::Mat>& maps, ProjectionRig* rig);

// Whether every projector of the rig (at least one) carries a reflectance map: what the renderer
// (RenderOptions::reflectance) and the per-pixel prediction (PredictPixels, camera_rays.h) need
// to shape and predict each pixel's light by its point's reflectance.
bool HasReflectanceMaps(const ProjectionRig& rig);

// (n,3) each patch's mean of the attached maps' reflectance ρ_p over the pixels that light it,
// weighted as the flux bookkeeping weights them (w a: coverage_scale · Ω · share); 0 for a patch
// no pixel lights. A pixel's reflectance relative to its patch's is ρ_p / ρ̄_i: the renderer
// divides its light by it, the prediction multiplies the model's ρ_i by it. Needs
// HasReflectanceMaps (std::invalid_argument otherwise).
Eigen::MatrixX3d MapReflectanceMeans(const ProjectionRig& rig);

// Direct-light exitance bounds of every patch of `level` from the scene's projectors, for
// CompensationProblem::lower/upper. Returns false (outputs untouched) if the scene lists no
// projectors. Throws like ReadProjectors and BuildProjectionRig.
bool SetBoundsFromProjectors(const Scene& scene, const PatchLevel& level, Eigen::MatrixX3d* lower,
                             Eigen::MatrixX3d* upper, const ProjectionRigOptions& options = {});

// The direct exitance ρ ⊙ Ḡ per patch (n,3) of one projector at unit output (black 0, max 1):
// the upper bound a rig of that projector alone gives, as the patch's mean (lit_part off), which
// is what a camera sees of it (compensation/unit_light.h).
Eigen::MatrixX3d UnitLightExitance(const PatchLevel& level, const Projector& projector);

// Texture coordinate of a point on (or within single precision of) a patch: the corners' uv
// interpolated barycentrically in the corner triangle that contains the point, a quad being the
// triangles (0, 1, 2) and (0, 2, 3). Exact for triangles and parallelogram quads (the affine
// map); for other quads the piecewise-linear map differs from SamplePatch's bilinear one by
// second order in the patch size.
Vec2 PatchTextureCoordinate(const Patch& patch, const Vec3& point);

// A ray scene whose surface k is patch k of `level` (quads as two triangles), so that
// RayScene::Intersect reports the patch it hits.
Scene PatchScene(const PatchLevel& level);

// Smooth blending ramp of a pixel coordinate for an image border: 0 on the border, 1 at `ramp`
// pixels inside (smoothstep); 1 everywhere inside when ramp is 0; 0 outside the image.
double FeatherWeight(const Vec2& pixel, int width, int height, double ramp);

}  // namespace procam
