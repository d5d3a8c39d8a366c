#pragma once
// The demo on the synthetic rig: every stage of the pipeline on a simulated room — geometry,
// compensation with the four methods, projector images, what the simulated camera photographs,
// ΔE per pixel (datasets_synthetic/evaluation.h); the rig calibrated from its own simulated
// captures (RunCalibrateAll) and its errors against the ground truth; the compensation (`method`)
// redone with the recovered rig and photographed in the true world; the closed loop
// (RunVerification); and the room scanned instead of given (calibrate all --scan), compensated
// on its scan and shown in the true room. Writes pictures, result.json and report.html into
// `out`. What `procam demo` runs on a synthetic scene.

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "base/progress.h"
#include "capture/display.h"
#include "compensation/solver.h"
#include "datasets_synthetic/evaluation.h"

namespace procam {

class OptionTable;

struct SyntheticDemoOptions {
  std::string scene = "c_shaped";  // SyntheticSceneNames(), or a scene file with projectors and a camera
  int patches = 600;               // solver patches
  LightField light = LightField::kSmooth;  // projector images: seamless, or flat per patch
  // Also calibrate without the room model (calibrate all --scan into out/rig_scan), compensate
  // on the scanned room and show the result in the true one, beside the scanned surfaces' errors.
  bool scan = true;
  // The compensation of the calibrated and scanned stages (and of the verification, which
  // solves again with it): naive, reverse, linear, perceptual or perceptual2000 (with the
  // metric measured at every iterate, RecommendedSolverOptions). The true rig's evaluation
  // compares every method whatever this is.
  CompensationMethod method = RecommendedSolverOptions().method;
  std::filesystem::path out = "out/demo";
  // The demo on a rig instead (RunDemo): a camera URI (a real camera, or a synthetic one treated
  // like a real one), `scene` then the room model (a scene file, or a synthetic scene by name).
  // Empty: the synthetic rig.
  std::string camera;
  std::vector<std::string> displays;  // each projector's monitor, in order (glfw:N|NAME)
  std::vector<std::string> names;     // the projectors' names; empty: the displays'
  // As calibrate all's (CalibrateAllOptions): chessboard photos of the camera, or a calibrated
  // camera.cameramodel instead; the camera value per unit exitance (a number, or R,G,B); the
  // camera's position and a point it looks at (x,y,z,look_x,look_y,look_z).
  std::string chessboard, camera_model, camera_scale, camera_guess;
  int frames = 4;              // frames averaged per pattern, [1, 1000]
  double settle_ms = 150.0;    // wait after each pattern, ms (unless measure_settle)
  bool measure_settle = true;  // measure the display-to-camera latency first, settle for it
  int iterations = 4;          // closed-loop photos at most, [1, 50]
  // Opens a projector's monitor by its name in `displays` (procam: a fullscreen GLFW window).
  std::function<std::shared_ptr<PatternDisplay>(const std::string& name)> open_display;
  ProgressCallback progress;  // stages, solver iterations, ΔE per method
  ProgressCallback steps;     // the stages' command lines and their reports
  // Declares --scene, --patches, --out, --method, the rig's (--camera, --display, --names,
  // --chessboard, --camera-model, --camera-scale, --camera-guess, --frames, --settle-ms,
  // --iterations), --light and --no-scan in `table` (base/option_table.h), bound to these fields.
  void Declare(OptionTable* table);
};

struct SyntheticDemoSummary {
  std::vector<MethodEvaluation> methods;  // naive, reverse, linear, perceptual (true rig)
  MethodEvaluation calibrated;            // options.method with the calibrated rig
  std::optional<MethodEvaluation> scanned;  // options.method on the scanned room (options.scan)
  std::string verification;               // the closed loop's brief report
  std::filesystem::path out;
  // Each method's ΔE and seam, the closed loop's report and what was written, as procam demo
  // prints them.
  std::string Report() const;
};

// Throws like the stages it runs (IoError naming files, std::invalid_argument for options).
SyntheticDemoSummary RunSyntheticDemo(const SyntheticDemoOptions& options);

// `procam demo`: on a rig (options.camera) calibrate all → compensate → project → verify, each
// stage a library call given to options.steps as the command a person would run (`$ procam
// ...`); on a scene file without projectors or a camera, geometry and compensation with each
// method, numbers per patch; otherwise the synthetic rig (RunSyntheticDemo). Returns what the
// command prints at the end: the results and what was written into options.out.
std::string RunDemo(const SyntheticDemoOptions& options);

}  // namespace procam
