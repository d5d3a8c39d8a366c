#pragma once
// Verification with photos, and the closed loop.
//
// One iteration: the solution's emittance E becomes one image per projector (the projection
// module's renderer, with the rig's projectors as the model knows them); every projector shows
// its image at once; the camera photographs the room through the capture sequencer (averaged
// frames, HDR when exposures are bracketed), each photo written into a capture session as it is
// taken; camera pixels become patches by casting each pixel's ray from the registered camera
// (CastCameraPixels, projection/camera_rays.h); camera values become exitance in the scene's units
// through the camera's colour calibration (x = M · (camera RGB − black), M = diag(1/k) for a
// per-channel scale k); and the photo is compared in CIE L*a*b* (the problem's T and white)
// with the predicted appearance and with the desired appearance: ΔE76 and CIEDE2000 per pixel
// and per patch. Predicted per patch: the solution's radiosity B. Predicted per pixel: the
// light at the point x of patch i the pixel sees, split as projection/photometric_transfer.h's
// transfer splits it (PredictPixels, projection/camera_rays.h),
//     x_p = ρ_i ⊙ (Σ_k G_k(x) · output_k(code_k(x)) + (F B')_i),
// the direct light of every projector k that lights x (geometric gain G_k, the code its image
// shows at the projector pixel that lights x, its photometry as the model knows it) plus the
// patch's bounce irradiance, B' = K⁻¹(ρ ⊙ D) the radiosity of the direct light D the images
// shown deliver to each patch.
//
// The closed loop updates the model from measured minus predicted and solves again:
//   1. projector response and 2. reflectance, fitted to the photo (verification/model_fit.h);
//   3. RunCompensation with the updated model (method, alpha and multires of the solution).
// It stops when the measured mean ΔE76 (photo vs desired, per pixel) improves by less than
// `min_improvement`, or after `iterations` photos, and keeps the best iteration (the lowest
// measured mean ΔE76), never one worse than the first.
//
// Output (VerificationOptions::out):
//   iterations/K/session/     the capture session (session.json, patterns/, frames/)
//   iterations/K/NAME.png     each projector's image; E.npy, B.npy (the solution shown),
//                             reflectance.npy (the model's), measured_B.npy (per patch, NaN
//                             where unseen), photo.png, predicted.png, delta_e76.png (photo vs
//                             desired), delta_e2000.png, model_delta_e76.png (photo vs
//                             predicted), result.json
//   desired.png, result.json (every iteration, the best), report.html
// Everything is written atomically as it is produced, so a fault keeps what was done.

#include <Eigen/Core>
#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/html_report.h"
#include "base/progress.h"
#include "capture/display.h"
#include "capture/latency.h"
#include "capture/sequencer.h"
#include "capture/simulated_camera.h"
#include "compensation/colour_image.h"
#include "geometry/scene.h"
#include "projection/projector_images.h"

namespace procam {

struct VerificationOptions {
  std::filesystem::path rig_dir;       // rig.json: camera.model (registered), projectors[]
  std::filesystem::path solution_dir;  // what `procam compensate SCENE --rig RIG_DIR` wrote
  std::filesystem::path out;           // created; see the header comment
  std::string camera;                  // camera URI (synthetic:SCENE?..., aravis:..., v4l2:...)
  // Where each rig projector (rig.json's order) shows its image, e.g. GlfwDisplay on its
  // monitor. Empty for synthetic cameras, which then show the images on their world's
  // displays (SyntheticWorld::displays); given with a synthetic camera, they must show on the
  // world's displays (e.g. wrap them, as the fault tests do), since those are what it sees.
  std::vector<std::shared_ptr<PatternDisplay>> displays;
  // Or by name (`procam verify --display`: glfw:N|NAME), each opened by `open_display` before
  // the run and shown after `displays`; not for synthetic cameras.
  std::vector<std::string> display_names;
  std::function<std::shared_ptr<PatternDisplay>(const std::string& name)> open_display;
  // The scene, when the solution's result.json names no file (a generated scene, as in the
  // demo); otherwise left empty and read from the file result.json names.
  std::optional<Scene> scene;
  SequencerOptions sequencer;   // frames, exposures (several: HDR), settle, retries
  // Measure the display-to-camera latency first (capture/latency.h, every projector flashing
  // at once) and settle for it instead of sequencer.settle_ms.
  bool measure_latency = false;
  LatencyOptions latency;
  std::string camera_response;  // camera_response.json: linearise (needs bracketing)
  // Camera colour calibration, camera value per unit exitance (scene units) per channel (R, G,
  // B, each > 0), or unset: rig.json camera.colour ({"scale": [R,G,B]} or {"matrix": 3×3}),
  // else a simulated camera's own (from its URI and the session's exposure and gain). For
  // bracketed (HDR) photos the units are full scale per second.
  std::optional<Eigen::Vector3d> camera_scale;
  double camera_black = -1.0;     // camera black level, DN (< 0: the synthetic URI's, else 0)
  double gain = -1.0;             // camera gain to set (< 0: leave it)
  int iterations = 4;             // photos at most (iteration 0 is the solution as given), [1, 50]
  double min_improvement = 0.01;  // relative drop of the mean ΔE76 needed to go on, [0, 1)
  double reflectance_step = 1.0;  // damping of the reflectance update, (0, 1]
  bool fit_response = true;       // fit the projectors' response exponents
  bool fit_reflectance = true;    // update the per-patch reflectance
  int min_patch_pixels = 4;       // camera pixels a patch needs to count as seen, ≥ 1
  LightField light = LightField::kSmooth;  // how the projector images shape the light in a patch
  // Use the rig's per-pixel reflectance maps where every projector has one: each pixel's light
  // divided by its point's reflectance relative to its patch's, and the per-pixel prediction
  // with the point's reflectance (CalibratedRoomOptions::reflectance_maps); false: per patch.
  bool reflectance_maps = true;
  // With reflectance maps in use: refit them per projector pixel from each photo against its
  // per-pixel prediction (FitReflectanceMaps, verification/model_fit.h), after the per-patch
  // update.
  bool fit_reflectance_map = true;
  ProgressCallback progress;      // a line per stage and iteration (ΔE, the model update)
  // Set (by a signal handler) to stop cleanly: the photo in hand is finished (its session
  // records the stop), no further photo or solve begins. Null: run to the end.
  const std::atomic<bool>* stop = nullptr;
  // Declares the rig and the solution (positional), --camera, --out, --display, the closed
  // loop's options (--iterations, --min-improvement, --reflectance-step, --no-response-fit,
  // --no-reflectance-fit, --min-patch-pixels, --light, --no-reflectance-maps,
  // --no-reflectance-map-fit), the sequencer's (SequencerOptions::Declare) and the camera's
  // (--camera-scale, --camera-black, --camera-response, --gain, --settle-ms, --exposure-us) in
  // `table`, bound to these fields (base/option_table.h).
  void Declare(OptionTable* table);
  bool Check(std::string* why) const;
};

// Colour differences of one photo.
struct PhotoDeltaE {
  double mean76 = 0, max76 = 0, mean2000 = 0, max2000 = 0;  // per pixel over the seen pixels
  double patch_mean76 = 0, patch_mean2000 = 0;              // area-weighted over the seen patches
};

struct VerificationIteration {
  int index = 0;
  PhotoDeltaE measured;  // photo vs desired
  PhotoDeltaE model;     // photo vs predicted (the model's error): per pixel against the
                         // per-pixel prediction, per patch against the solution's B
  double model_constant_mean76 = 0;  // per pixel against its patch's B (constant over the patch)
  // How visible the patch grid is in the photo (MeasureSeams, compensation/colour_image.h).
  SeamMeasure seams;
  double predicted_mean76 = 0, predicted_mean2000 = 0;  // B vs desired, same seen patches
  double solver_mean76 = 0;  // B vs desired over every patch (compensate's number)
  int seen_pixels = 0, seen_patches = 0;
  // The model update made after this photo (empty for the last): per projector, the response
  // exponent per primary and the reflectance scale s per channel.
  std::vector<Eigen::Vector3d> response_exponent;
  Eigen::Vector3d reflectance_scale = Eigen::Vector3d::Ones();
  // The per-pixel reflectance maps refitted after this photo (FitReflectanceMaps; both 0 when
  // the rig has no maps, the refit is off, or it is the last photo): the projector pixels whose
  // reflectance changed, and the RMS over them of the gain (after / before) − 1, e.g. 0.02 = 2%.
  long long map_refitted_pixels = 0;
  double map_rms_gain = 0.0;
  double capture_seconds = 0, solve_seconds = 0, seconds = 0;
  std::filesystem::path directory;
  // Pictures for the report (8-bit BGR): photo, prediction, ΔE76 heat maps.
  cv::Mat photo, predicted, delta_e76, model_delta_e76;
};

// The format version of a verification run's result.json (docs/verification.md).
constexpr int kVerificationFormatVersion = 1;

// A verification run: DIR/result.json (docs/verification.md) and the pictures of its report.
struct VerificationSummary {
  std::vector<VerificationIteration> iterations;
  int best = -1;            // index of the iteration with the lowest measured mean ΔE76
  bool complete = false;    // false when a fault or a stop ended the loop early
  std::string termination;  // "converged", "max_iterations", "fault" or "stopped" (a signal)
  std::string error;        // the fault or the stop, when not complete
  cv::Mat desired;          // 8-bit BGR, the desired appearance as the camera sees it
  // Pictures of each projector's reflectance map (8-bit BGR, projector pixels), when the rig has
  // maps: as read from the rig, as refitted by the run's last update, and the gain between them.
  struct MapPictures {
    std::string projector;
    cv::Mat before, after, gain;
  };
  std::vector<MapPictures> reflectance_maps;
  double seconds = 0;
  // What the run used.
  nlohmann::json rig;          // RigDirectory::Describe()
  std::string solution;        // the solution directory
  std::string camera;          // the camera's URI
  std::string colour_source;   // where camera values → exitance came from
  bool hdr = false;
  std::vector<double> exposures_us;
  double settle_ms = 0.0;      // the settle time used (given, or measured)

  nlohmann::json Json() const;      // result.json
  std::string BriefReport() const;  // one line
};

// Writes DIR/result.json of a verification run atomically. The one writer of that file.
void WriteVerificationRun(const std::filesystem::path& dir, const VerificationSummary& summary);

// DIR/result.json of a verification run: every number of it (not the pictures). Throws IoError
// naming the file and the key: missing, not JSON, a format_version other than
// kVerificationFormatVersion, a required key missing or of the wrong type. The one reader.
VerificationSummary ReadVerificationRun(const std::filesystem::path& dir);

// Runs the loop. Camera URIs are opened through the camera registry: callers register the
// backends they use (RegisterDeviceBackends for real cameras; the synthetic world's, with its
// simulated-camera source below, through RegisterSyntheticWorld of datasets_synthetic). Throws
// IoError (naming the file, key, camera or projector) for bad input before anything is captured; a
// camera or projector lost mid-run writes result.json and report.html with the iterations done
// (complete = false) and then throws IoError saying so. Stopped by options.stop, it writes them
// the same way (termination "stopped") and throws Stopped (base/stop.h) saying where it stopped;
// the same call again resumes (the photos taken are kept).
VerificationSummary RunVerification(const VerificationOptions& options);

// Appends the verification's sections (table, convergence plot, per-iteration pictures) to a
// report, e.g. the demo's.
void AddVerificationReport(const VerificationSummary& summary, HtmlReport* report);

}  // namespace procam
