#pragma once
// The scan judged as a person would judge it (docs/scan.md#rooms-made-at-random): a synthetic
// rig's room scanned without its model (exact correspondences plus decoding noise, the
// self-calibration, every correspondence triangulated, SceneFromPoints), the scanned surfaces
// matched to the true ones by what they cover, and the aims measured:
//
//   found     every physical surface the camera sees and a projector lights (at least
//             `min_seen_m2`) has scanned area on it (at least `found_share` of what is seen);
//   RMS       the scanned facets lying on a planar physical surface within 5 mm RMS of the true
//             room (corners and centroids, through the camera's pose), on a curved one within
//             1 cm;
//   area      the scanned area lying on each physical surface within 1% of what of it is seen
//             and lit (SeenAndLitArea);
//   spurious  no scanned surface whose facets lie off the true room (centroid more than
//             `off_m` from every true surface) with more than 1% of the room's seen-and-lit area.
//
// A physical surface is the set of a scene's coplanar surfaces that touch (a wall split round an
// opening, the treads of a stair's sides, an alcove's floor and the room's): one surface to a
// person and to the scan. A scanned facet lies on the physical surface nearest its centroid, so
// one scanned surface may cover several true ones and one true surface be covered by several
// scanned ones.

#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/option_table.h"
#include "datasets_synthetic/synthetic_camera.h"

namespace procam {

struct ScanJudgeOptions {
  double camera_scale = 0.5;       // the camera's image scaled (same field of view), (0, 1]
  int pixel_step = 1;              // every n-th camera pixel and row, ≥ 1
  double decoding_noise_px = 0.3;  // Gaussian, per projector pixel coordinate, ≥ 0
  uint64_t noise_seed = 1;         // the decoding noise's
  // The camera's lens as a chessboard leaves it: fx, fy, cx, cy, k1, k2, p1, p2 off by about
  // their chessboard uncertainty (the offsets SelfCalibrateRoom's scan tests use), and the
  // floor held to a board normal 0.03° off; false: the true lens and floor normal.
  bool chessboard_lens = true;
  double min_seen_m2 = 0.05;       // physical surfaces seen and lit less than this are not expected, m², ≥ 0
  // A physical surface is found when the scanned area lying on it is at least this share of its
  // seen-and-lit area, (0, 1].
  double found_share = 0.5;
  double off_m = 0.02;             // a scanned facet's centroid farther than this from the truth is off, metres, > 0
  double cell_m = 0.01;            // SeenAndLitArea's cells, metres, > 0
  // Also compensate (perceptual) on the true model with the true rig and on the scanned room
  // with the self-calibrated projectors, show both by the true projectors in the true room and
  // compare the photographs' mean CIEDE2000 (EvaluateSyntheticScene's camera, full size). Each
  // scanned surface takes the reflectance of the true physical surface it covers most, as a
  // photometric calibration would measure it.
  bool compensate = false;
  int patches = 300;  // solver patches of both, [20, 5000]
  // The aims.
  double planar_rms_mm = 5.0;
  double curved_rms_mm = 10.0;
  double area_percent = 1.0;
  double spurious_percent = 1.0;
  double delta_e2000 = 0.5;  // on the scan minus on the model
  double seam = 0.5;         // on the scan
  // Declares --camera-scale, --noise-seed, --compensate and --patches in `table`, bound to these
  // fields (base/option_table.h).
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

struct PhysicalSurfaceJudgement {
  std::string name;              // its true surfaces' names, joined by " + "
  std::vector<int> surfaces;     // indices into the true scene's surfaces
  bool curved = false;           // a mesh whose facets are not all parallel
  double seen_and_lit_m2 = 0.0;  // what a scan can rebuild
  bool expected = false;         // seen_and_lit_m2 ≥ min_seen_m2
  double scanned_m2 = 0.0;       // of the scanned facets lying on it
  double rms_mm = 0.0;           // of their corners and centroids to the true room (0: none)
  double area_error_percent = 0.0;  // scanned / seen and lit − 1 (0 when nothing is seen)
};

struct ScannedSurfaceJudgement {
  std::string name;
  double area_m2 = 0.0;
  double off_m2 = 0.0;  // of its facets lying off the true room
  double rms_mm = 0.0;  // all its facets' corners and centroids to the true room
};

struct ScanJudgement {
  std::string room;
  std::vector<PhysicalSurfaceJudgement> physical;
  std::vector<ScannedSurfaceJudgement> scanned;
  double room_seen_and_lit_m2 = 0.0;  // the room's area a scan can rebuild
  int scan_points = 0;
  std::string scan_report;            // SceneFromPoints' report
  std::string calibration_report;     // the self-calibration's brief report
  bool calibrated = false;            // false: the self-calibration failed (message in calibration_report)
  // The measures, over the expected physical surfaces.
  int expected = 0, found = 0;
  double worst_planar_rms_mm = 0.0;
  double worst_curved_rms_mm = 0.0;   // 0 when the room has no curved surface seen
  double worst_area_error_percent = 0.0;  // signed, the largest in magnitude
  double largest_spurious_percent = 0.0;  // of the room's seen-and-lit area
  // With options.compensate: mean CIEDE2000 of the photographed compensation on the true model
  // and on the scan, and the seam metric on the scan (MeasureSeams); −1 when not computed.
  double model_delta_e2000 = -1.0, scan_delta_e2000 = -1.0, scan_seam = -1.0;
  double seconds = 0.0;
  bool CompensationMet(const ScanJudgeOptions& options) const;
  // Each aim (`options`) met.
  bool AllFound() const { return expected == found; }
  bool PlanarRmsMet(const ScanJudgeOptions& options) const;
  bool CurvedRmsMet(const ScanJudgeOptions& options) const;
  bool AreaMet(const ScanJudgeOptions& options) const;
  bool SpuriousMet(const ScanJudgeOptions& options) const;
  std::string Report() const;  // one line per physical and scanned surface, then the measures
  nlohmann::json Json() const;
};

// The physical surfaces of `scene`: its surfaces grouped where coplanar (normals within 1°,
// planes within 5 mm) and touching (a corner of one within 1 cm of the other's outline). Each
// group lists surface indices, ascending; groups ordered by their first surface.
std::vector<std::vector<int>> PhysicalSurfaces(const Scene& scene);

// Scans the room of `scene_file` (a scene file with projectors and a camera, its first camera) as above and judges the result. A failing self-calibration is a result
// (calibrated = false, nothing found), not an exception. Throws std::invalid_argument for
// options that fail Check().
ScanJudgement ScanAndJudge(const std::filesystem::path& scene_file, const ScanJudgeOptions& options);

}  // namespace procam
