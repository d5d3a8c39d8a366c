#pragma once
// Each projector pixel's reflectance, measured from the flat fields of the photometric
// calibration (docs/calibration.md#reflectance-per-pixel).
//
// The per-patch estimate (photometric_transfer.h) divides, over a patch's camera pixels, the
// measured exitance by the modelled irradiance: ρ_i = Σ_p m_p / Σ_p k (G_p o + H_i). The same
// ratio per camera pixel p (channel c),
//
//     r_p,c = (m_p,c / k_c) / (G_p o_c + H_i,c),
//
// m the white-minus-black field, k the camera's value per unit exitance, G_p the projector's
// geometric gain at the point p sees, o = max − black and H_i the patch's bounce irradiance, is
// the reflectance at that point up to the model's error in H (the bounce is constant over the
// patch in the model, not in the room) and the camera's noise. Only pixels the projector lights
// directly (G_p > 0) and that the mask keeps count.
//
// The map is kept per PROJECTOR pixel because what uses it next, the per-pixel rendering of the
// projector images (projection/projector_images.h), shapes each projector pixel's level and
// indexes its factor by the same pixel as the projector's map (projection_rig.h ProjectorMap):
// no reprojection at render time, and the map's resolution is that of the light that can be
// shaped. Each projector pixel's ray is cast against the fine patches; the point it lights is
// projected into the camera and r is interpolated bilinearly between the (up to four) camera
// pixels around it that see the same surface and count. A projector pixel with none is not
// measured (the camera does not see its point, or sees it at a grazing angle through an edge).
//
// Normalisation: on every patch the camera sees (ReflectanceEstimate::pixels ≥ min_patch_pixels)
// the measured pixels are scaled per channel by one factor, chosen so that the mean of the scaled
// values clamped to [0, 0.99] equals the patch's estimated reflectance ρ_i, and its unmeasured
// pixels get ρ_i: the map's mean over the projector pixels lighting the patch (each pixel counted
// once, unweighted) is ρ_i. On patches it does not see, every pixel gets the patch's reflectance
// (the nominal one). Pixels that light no patch are 0.

#include <Eigen/Core>
#include <filesystem>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "geometry/patches.h"
#include "projection/camera_rays.h"
#include "projection/photometric_transfer.h"
#include "projection/projector.h"
#include "projection/rig_directory.h"

namespace procam {

struct ReflectanceMapOptions {
  // Camera pixels a patch needs for its pixels to be measured (as EstimatePatchReflectance's
  // min_pixels), ≥ 1.
  int min_patch_pixels = 4;
  // Least sum of bilinear weights (of the four camera pixels around a point) that must come
  // from usable pixels for the projector pixel to count as measured, in (0, 1].
  double min_weight = 0.25;
  // Shadow and cast rays start this far from surfaces (metres, > 0).
  double ray_margin = 1e-4;
  bool Check(std::string* why) const;
};

// One projector's reflectance map.
struct ReflectanceMap {
  cv::Mat reflectance;      // CV_32FC3, linear R, G, B (not OpenCV's BGR), the projector's size,
                            // row 0 = top; 0 where the pixel lights no patch
  cv::Mat measured;         // CV_8UC1, 255 where the camera measured the pixel's point
  cv::Mat patch;            // CV_32SC1, the fine patch each pixel lights, −1 for none
  int lit_pixels = 0;       // pixels that light a patch
  int measured_pixels = 0;  // of those, measured
};

// The map (header comment). `lighting` is the camera pixels' view of `projector`
// (LightCameraPixels), `estimate` the per-patch reflectance from the same `difference` (camera
// B, G, R, CV_32FC3, white minus black in camera values), `mask` (CV_8UC1, empty = all) the
// usable camera pixels, `output` = max − black (R, G, B, scene units) and `camera_scale` k
// (R, G, B). Throws std::invalid_argument for options that fail Check() or sizes that differ.
ReflectanceMap EstimateReflectanceMap(
    const PatchLevel& level, const ProjectorGeometry& projector, const ProjectorGeometry& camera,
    const CameraPixelLighting& lighting, const ReflectanceEstimate& estimate,
    const cv::Mat& difference, const cv::Mat& mask, const Eigen::Vector3d& output,
    const Eigen::Vector3d& camera_scale, const ReflectanceMapOptions& options = {});

// The file a projector's map is stored in, relative to the rig directory:
// NAME.reflectance_map.png.
std::string ReflectanceMapFile(const std::string& projector);

// The one writer of a reflectance map file: RIG_DIR/entry.file, a 16-bit RGB PNG whose codes are
// the reflectance × 65535 (linear, not sRGB), written atomically. `entry` gets the file name,
// size and pixel counts. The caller records the entry in rig.json (RigFile::reflectance_maps).
// Throws IoError naming the file.
void WriteReflectanceMap(const std::filesystem::path& rig_dir, const std::string& projector,
                         const ReflectanceMap& map, RigReflectanceMap* entry);

// The one reader: the map of rig.json's reflectance_maps.NAME as CV_32FC3 linear R, G, B of
// the entry's size. Throws IoError naming RIG_DIR/rig.json and the key when the file is missing,
// or naming the file when it is not a 16-bit 3-channel PNG of the recorded size.
cv::Mat ReadReflectanceMap(const std::filesystem::path& rig_dir, const std::string& projector,
                           const RigReflectanceMap& entry);

// The maps of every projector of `rig` (rig.json's reflectance_maps, each read by
// ReadReflectanceMap), in rig.projectors' order, for AttachReflectanceMaps; an empty vector
// unless every projector has one (the per-pixel rendering needs them all). Throws IoError like
// ReadReflectanceMap, and naming RIG_DIR/rig.json's reflectance_maps.NAME when a map's size is
// not its projector's.
std::vector<cv::Mat> ReadRigReflectanceMaps(const RigDirectory& rig);

// Pictures of a map for the calibration report (8-bit BGR): the reflectance as sRGB, and each
// pixel's reflectance relative to its patch's (green luminance ratio) on a diverging scale,
// 1 ± `relative_range` from blue through white to red; unmeasured pixels grey, pixels that light
// nothing black.
cv::Mat DrawReflectanceMap(const ReflectanceMap& map);
cv::Mat DrawRelativeReflectance(const ReflectanceMap& map,
                                const Eigen::MatrixX3d& patch_reflectance, double relative_range);

}  // namespace procam
