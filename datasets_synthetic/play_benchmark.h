#pragma once
// `procam bench play`: what one frame of light that follows changing content costs, from a new
// desired appearance to every projector image ready. The box room (rooms.h) at `patches`, three
// projectors (bench_projectors.h); each frame every patch's desired colour drifts by a few
// percent, is solved warm-started from the last frame (K factorised once: frame 0, reported
// apart) and rendered as a display node renders it (frame_plan.h): the planner's static part
// once, then per frame a plan and its shading, on the CPU (ShadeProjectorImages) or on a GPU
// (GlProjectorRenderer into an offscreen EGL context: the three images drawn, then glFinish).
// Medians over `frames`, a summary to `progress`, JSON to `json` when given. Timings are
// measurements for people to read (docs/nodes.md), never asserted.
//
// Also built alone as tools/procam-play-bench, which carries few libraries, for GPU machines
// without procam's Debian packages.

#include <string>

#include "base/progress.h"
#include "compensation/solver.h"
#include "projection/projector_images.h"

namespace procam {

class OptionTable;

enum class PlayRender {
  kCpu,  // ShadeProjectorImages
  kGpu,  // GlProjectorRenderer, offscreen (needs procam built with PROCAM_WITH_GLFW)
};

struct PlayBenchmarkOptions {
  int width = 1920, height = 1080;
  int patches = 1000;  // about 3 000 variables
  int frames = 20;
  // The method, as procam play's (RecommendedSolverOptions: perceptual2000 with the metric measured
  // at every iterate; linear and perceptual for comparison).
  CompensationMethod method = RecommendedSolverOptions().method;
  Device device = Device::kCpu;
  LightField light = LightField::kSmooth;
  DitherMethod dither = DitherMethod::kOrdered;
  PlayRender render = PlayRender::kCpu;
  // Each frame's solve stops when an iteration lowers the cost by less than this fraction of it
  // (procam play's default).
  double tolerance = kPlayFunctionTolerance;
  // kGpu: the shader path, "auto", "fragment" or "compute" (GlShading of gl_renderer.h).
  std::string shader = "auto";
  std::string json;
  ProgressCallback progress;
  // Declares --width, --height, --patches, --frames, --method, --device, --dither, --render,
  // --shader, --tolerance, --light and --json in `table`, bound to these fields.
  void Declare(OptionTable* table);
};

// Throws IoError when the GPU render is asked for and no OpenGL context can be made (or procam
// was built without OpenGL), std::invalid_argument for bad options.
void RunPlayBenchmark(const PlayBenchmarkOptions& options);

}  // namespace procam
