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
#include <optional>
#include <string>
#include <vector>

#include "base/progress.h"
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
  ProgressCallback progress;  // stages, solver iterations, ΔE per method
  ProgressCallback steps;     // the calibration's command lines and their reports
  // Declares --method in `table` (base/option_table.h), bound to this struct's field.
  void Declare(OptionTable* table);
};

struct SyntheticDemoSummary {
  std::vector<MethodEvaluation> methods;  // naive, reverse, linear, perceptual (true rig)
  MethodEvaluation calibrated;            // options.method with the calibrated rig
  std::optional<MethodEvaluation> scanned;  // options.method on the scanned room (options.scan)
  std::string verification;               // the closed loop's brief report
};

// Throws like the stages it runs (IoError naming files, std::invalid_argument for options).
SyntheticDemoSummary RunSyntheticDemo(const SyntheticDemoOptions& options);

}  // namespace procam
