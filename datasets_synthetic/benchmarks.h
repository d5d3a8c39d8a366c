#pragma once
// procam's benchmarks on generated rooms (rooms.h: a closed box room with an occluder), as
// `procam bench formfactors|solver|scale|projection` runs them: the table goes to the progress callback a
// line per room size as it finishes, JSON to `json` when given. Timings are measurements for
// people to read (docs/solver.md, docs/scale.md, docs/gpu.md), never asserted.

#include <string>
#include <vector>

#include "base/option_table.h"
#include "base/progress.h"
#include "compensation/solver.h"
#include "geometry/compressed_form_factors.h"
#include "projection/projector_images.h"

namespace procam {

struct BenchmarkOptions {
  int patches = 4096;  // bench formfactors: target patch count
  int threads = 0;
  std::string json;
  std::vector<int> sizes = {100, 333, 1000, 3333};  // bench solver: room sizes, patches
  int ceres_max_variables = 1100;  // Ceres takes ~2 min at 1044 variables, hours at 3000
  double alpha = 0.5;
  std::string device = "cpu";       // cpu | cuda | both: which devices' rows to run
  int cpu_max_variables = 1 << 30;  // skip the CPU rows (and peers) above this many variables
  // bench scale
  std::vector<int> scale_sizes = {1000, 3333, 10000};
  int dense_max_patches = 5000;  // also the dense F (and its error) up to here
  ClusterOptions clusters;
  ProgressCallback progress;  // the table, a line per size as it finishes

  // Each benchmark's options (bench formfactors, bench solver, bench scale) in `table`, bound to
  // these fields (base/option_table.h).
  void DeclareFormFactors(OptionTable* table);
  void DeclareSolver(OptionTable* table);
  void DeclareScale(OptionTable* table);
};

// The form factors of one room: time, pairs, shadow rays, row sums.
void RunFormFactorBenchmark(const BenchmarkOptions& options);
// The solvers (perceptual, multires, L-BFGS-B, Ceres, linear; CPU and/or CUDA) per room size:
// time to the best objective (+1e-6 relative), total time, iterations.
void RunSolverBenchmark(const BenchmarkOptions& options);
// The matrix-free path per room size: compressed F, its products, K⁻¹ by CG and the solver on
// them, beside the dense F where it fits.
void RunScaleBenchmark(const BenchmarkOptions& options);

struct ProjectionBenchmarkOptions {
  int width = 1920, height = 1080;  // each projector's
  int patches = 1000;               // target patch count
  int repeat = 10;                  // timed runs
  DitherMethod dither = DitherMethod::kOrdered;
  bool detail = false;  // every surface striped, rendered with the texture's detail
  LightField light = LightField::kSmooth;  // seamless light, or one level per patch
  std::string json;     // also the timings as JSON here
  ProgressCallback progress;
  // Declares --width, --height, --patches, --repeat, --dither, --detail, --light and --json in
  // `table`, bound to these fields.
  void Declare(OptionTable* table);
};

// Images for two projectors of the box room from a random emittance within the bounds: the pixel
// maps once, then rendering and PNG encoding, median over the runs.
void RunProjectionBenchmark(const ProjectionBenchmarkOptions& options);

struct DecodeBenchmarkOptions {
  int camera_width = 1280, camera_height = 1024;    // the photos' size
  int projector_width = 1024, projector_height = 768;  // procam's default sequence: 42 photos
  int repeat = 3;                                    // timed runs (median reported)
  std::string out;  // where the photos and the session go (default: a temporary folder, removed)
  ProgressCallback progress;
  // Declares --camera-width, --camera-height, --repeat and --out in `table`, bound to these fields.
  void Declare(OptionTable* table);
};

// Photos of procam's structured light on a plane (8-bit PNG, ambient light, read noise), then
// timed: `procam import` of the folder (reading and checksumming every photo, the session, the
// decode and its picture), reading the session back, and decoding alone.
void RunDecodeBenchmark(const DecodeBenchmarkOptions& options);


}  // namespace procam
