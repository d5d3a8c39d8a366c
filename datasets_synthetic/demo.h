#pragma once
// The demo on the synthetic rig: every stage of the pipeline on a simulated room — geometry,
// compensation with the four methods, projector images, what the simulated camera photographs,
// ΔE per pixel (datasets_synthetic/evaluation.h); the rig calibrated from its own simulated
// captures (RunCalibrateAll) and its errors against the ground truth; the perceptual compensation
// redone with the recovered rig and photographed in the true world; the closed loop
// (RunVerification); and the room scanned instead of given (calibrate all --scan), compensated
// on its scan and shown in the true room. Writes pictures, result.json and report.html into
// `out`. What `procam demo` runs on a synthetic scene.

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "base/progress.h"
#include "datasets_synthetic/evaluation.h"

namespace procam {

struct SyntheticDemoOptions {
  std::string scene = "c_shaped";  // SyntheticSceneNames(), or a scene file with projectors and a camera
  int patches = 600;               // solver patches
  LightField light = LightField::kSmooth;  // projector images: seamless, or flat per patch
  // Also calibrate without the room model (calibrate all --scan into out/rig_scan), compensate
  // on the scanned room and show the result in the true one, beside the scanned surfaces' errors.
  bool scan = true;
  std::filesystem::path out = "out/demo";
  ProgressCallback progress;  // stages, solver iterations, ΔE per method
  ProgressCallback steps;     // the calibration's command lines and their reports
};

struct SyntheticDemoSummary {
  std::vector<MethodEvaluation> methods;  // naive, reverse, linear, perceptual (true rig)
  MethodEvaluation calibrated;            // perceptual with the calibrated rig
  std::optional<MethodEvaluation> scanned;  // perceptual on the scanned room (options.scan)
  std::string verification;               // the closed loop's brief report
};

// Throws like the stages it runs (IoError naming files, std::invalid_argument for options).
SyntheticDemoSummary RunSyntheticDemo(const SyntheticDemoOptions& options);

}  // namespace procam
