#include "datasets_synthetic/play_benchmark.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <vector>

#include "base/io.h"
#include "base/option_table.h"
#include "base/timing.h"
#include "compensation/problem.h"
#include "datasets_synthetic/bench_projectors.h"
#include "datasets_synthetic/rooms.h"
#include "geometry/form_factors.h"
#include "geometry/patches.h"
#include "nodes/messages.h"
#include "procam/config.h"
#include "projection/frame_plan.h"
#include "projection/projection_rig.h"
#include "projection/stage.h"
#if PROCAM_WITH_GLFW
#include "projection/gl_renderer.h"
#include "projection/offscreen_gl.h"
#endif

namespace procam {
namespace {

// The three projectors' images of a plan: shaded on the CPU, or drawn by the GPU (each image
// into the offscreen framebuffer in turn, then glFinish: every image ready).
class PlayRenderer {
 public:
  PlayRenderer(const FramePlanner& planner, PlayRender render, const std::string& shader)
      : planner_(planner), render_(render) {
    if (render != PlayRender::kGpu) return;
#if PROCAM_WITH_GLFW
    const ProjectorMap& map = planner.rig().maps.front();
    gl_ = std::make_unique<OffscreenGl>(map.width, map.height);
    const GlShading shading = shader == "fragment"  ? GlShading::kFragment
                              : shader == "compute" ? GlShading::kCompute
                              : shader == "auto"
                                  ? GlShading::kAuto
                                  : throw std::invalid_argument(
                                        "procam bench play: no shader path '" + shader +
                                        "' (auto, fragment, compute)");
    for (size_t k = 0; k < planner.rig().projectors.size(); ++k) {
      gpu_.push_back(
          std::make_unique<GlProjectorRenderer>(planner, static_cast<int>(k), shading));
    }
    description_ = gl_->description() + ", " + GlShadingName(gpu_.front()->shading()) + " shader";
#else
    throw IoError("procam bench play --render gpu: procam was built without OpenGL (PROCAM_WITH_GLFW)");
#endif
  }
  ~PlayRenderer() {
#if PROCAM_WITH_GLFW
    gpu_.clear();  // with the context still current
#endif
  }

  void Render(const FramePlan& plan) {
    if (render_ == PlayRender::kCpu) {
      ShadeProjectorImages(planner_, plan, nullptr, {}, &images_);  // as a node: buffers kept
      return;
    }
#if PROCAM_WITH_GLFW
    for (const auto& renderer : gpu_) renderer->Draw(plan);
    gpu_.front()->Finish();
#endif
  }

  // One projector's image alone: upload + draw + glFinish (wall clock), and the draw as the GPU
  // times it, ms.
  void TimeOneImage(const FramePlan& plan, double* wall_ms, double* gpu_ms) {
#if PROCAM_WITH_GLFW
    const auto start = Clock::now();
    gpu_.front()->Draw(plan);
    gpu_.front()->Finish();
    *wall_ms = MsSince(start);
    *gpu_ms = gpu_.front()->TimedDraw(plan);
#else
    (void)plan, (void)wall_ms, (void)gpu_ms;
#endif
  }

  const std::string& description() const { return description_; }

 private:
  const FramePlanner& planner_;
  std::vector<ProjectorImage> images_;  // kCpu: the last frame's, their buffers reused
  PlayRender render_;
  std::string description_ = "CPU";
#if PROCAM_WITH_GLFW
  std::unique_ptr<OffscreenGl> gl_;
  std::vector<std::unique_ptr<GlProjectorRenderer>> gpu_;
#endif
};

}  // namespace

void PlayBenchmarkOptions::Declare(OptionTable* table) {
  std::vector<std::pair<std::string, CompensationMethod>> methods;
  for (CompensationMethod m : {CompensationMethod::kLinear, CompensationMethod::kPerceptual,
                               CompensationMethod::kPerceptual2000})
    methods.emplace_back(MethodName(m), m);
  table->Integer("width", &width, 1, 16384, "pixels", "projector width")
      .Integer("height", &height, 1, 16384, "pixels", "projector height")
      .Integer("patches", &patches, 4, std::numeric_limits<int>::max(), "",
               "target patch count (3 variables each)")
      .Integer("frames", &frames, 1, 10000, "", "timed frames (after a first, cold one)")
      .Choice("method", &method, methods, "linear, perceptual or perceptual2000")
      .Choice("device", &device, DeviceChoices(), "where K⁻¹ is applied: cpu or cuda")
      .Choice("dither", &dither,
              {{DitherName(DitherMethod::kNone), DitherMethod::kNone},
               {DitherName(DitherMethod::kOrdered), DitherMethod::kOrdered}},
              "none or ordered")
      .Choice("render", &render, {{"cpu", PlayRender::kCpu}, {"gpu", PlayRender::kGpu}},
              "cpu | gpu: the images shaded on the CPU, or drawn by OpenGL into an offscreen "
              "context (EGL: a GPU, or Mesa's llvmpipe)")
      .Choice<std::string>(
          "shader", &shader, {{"auto", "auto"}, {"fragment", "fragment"}, {"compute", "compute"}},
          "with --render gpu, the shader path (auto: compute where the context has OpenGL 4.3)")
      .Number("tolerance", &tolerance, 0.0, 0.1, "",
              "each frame's solve stops when an iteration lowers the cost by less than this "
              "fraction of it")
      .Choice("light", &light, LightFieldChoices(),
              "smooth: the light varies smoothly over each surface (seamless); flat: one uniform "
              "level per patch")
      .Text("json", &json, "also write the timings as JSON here");
}

void RunPlayBenchmark(const PlayBenchmarkOptions& args) {
  if (args.frames < 1) throw std::invalid_argument("bench play: frames must be at least 1");
  BoxRoomOptions room;
  room.target_patches = args.patches;
  const Scene scene = MakeBoxRoom(room);
  SubdivisionOptions subdivision;
  subdivision.target_patches = args.patches;
  const PatchHierarchy hierarchy = SubdividePatches(scene, subdivision);
  const PatchLevel& fine = hierarchy.fine;
  auto start = Clock::now();
  Eigen::MatrixXd form_factors = ComputeFormFactors(scene, fine, FormFactorOptions(), nullptr);
  const double form_factor_seconds = SecondsSince(start);
  ProjectionRigSummary rig_summary;
  const ProjectionRig rig =
      BuildProjectionRig(fine, BoxRoomProjectors(3, args.width, args.height), ProjectionRigOptions(), &rig_summary);
  CompensationProblem problem = MakeProblem(scene, fine, std::move(form_factors), 0.5);
  problem.lower = rig.lower;
  problem.upper = rig.upper;
  const Eigen::MatrixX3d base = problem.desired;
  SolverOptions solver = RecommendedSolverOptions();  // as procam play's (PlaySolverOptions)
  solver.method = args.method;
  solver.device = args.device;
  solver.function_tolerance = args.tolerance;
  RenderOptions render;
  render.light = args.light;
  render.dither = args.dither;
  // As a display node: the planner's static part (seamless field, share bounds, code tables) is
  // made once per rig; each frame is a plan (per patch) and its shading (per pixel).
  start = Clock::now();
  FramePlanner planner(rig, render);
  if (args.render == PlayRender::kCpu) planner.CacheBumps();  // as a node shading on its CPU
  const double planner_seconds = SecondsSince(start);
  PlayRenderer renderer(planner, args.render, args.shader);
  const double nodes_per_patch =
      planner.field() ? double(planner.field()->node_list().size()) / problem.size() : 1.0;
  WarmStart warm;
  std::vector<double> solve_ms, plan_ms, shade_ms, render_ms, total_ms, one_image_ms,
      one_image_gpu_ms;
  std::vector<int> iterations;
  std::vector<double> refined;  // patches whose light may saturate: refined per pixel
  std::vector<double> frame_ms;  // encode and parse the frame message
  size_t frame_bytes = 0;
  // Frame 0 factorises K (or forms K⁻¹ on the device) and starts cold: reported apart.
  double first_ms = 0.0;
  for (int frame = 0; frame <= args.frames; ++frame) {
    // Changing content: every patch's desired colour drifts by a few percent per frame.
    for (int i = 0; i < problem.size(); ++i) {
      for (int c = 0; c < 3; ++c)
        problem.desired(i, c) = std::clamp(base(i, c) * (1.0 + 0.15 * std::sin(0.3 * frame + 0.01 * i + 2.0 * c)), 0.0, 1.0);
    }
    start = Clock::now();
    SolverSummary summary;
    const CompensationSolution solution = Solve(solver, problem, &summary, {}, warm);
    const double solved = MsSince(start);
    warm = WarmStart{solution.radiosity_system, solution.emittance};
    // What a display node gets: the emittance through the protocol's frame (half precision).
    const auto render_start = Clock::now();
    const std::string bytes = EncodeMessage(FrameMessage(frame, solution.emittance));
    Message message;
    std::string why;
    if (!ParseMessage(bytes.data(), bytes.size(), &message, &why))
      throw std::logic_error("bench play: a frame the encoder made was refused: " + why);
    frame_bytes = bytes.size();
    const Eigen::MatrixX3d carried = FrameEmittance(message);
    const double framed = MsSince(render_start);
    const FramePlan plan = planner.Plan(carried);
    const double planned = MsSince(render_start) - framed;
    refined.push_back(plan.refined_patches);
    const auto shade_start = Clock::now();
    renderer.Render(plan);
    const double shaded = MsSince(shade_start);
    const double rendered = MsSince(render_start);
    if (args.render == PlayRender::kGpu) {
      renderer.TimeOneImage(plan, &one_image_ms.emplace_back(), &one_image_gpu_ms.emplace_back());
    }
    if (frame == 0) {
      first_ms = solved + rendered;
      continue;
    }
    solve_ms.push_back(solved);
    plan_ms.push_back(planned);
    frame_ms.push_back(framed);
    shade_ms.push_back(shaded);
    render_ms.push_back(rendered);
    total_ms.push_back(solved + rendered);
    iterations.push_back(summary.iterations);
  }
  std::vector<double> iteration_values(iterations.begin(), iterations.end());
  Report(args.progress, fmt::format("play: box room, {} patches ({} variables), 3 projectors {}x{}, {} {}, {} light",
                                    problem.size(), 3 * problem.size(), args.width, args.height, MethodName(args.method),
                                    DeviceName(args.device), LightFieldName(args.light)));
  Report(args.progress, fmt::format("  once: form factors {:.2f} s, projector maps {:.2f} s, frame planner {:.2f} s, "
                                    "first frame (factorise K, cold solve, render) {:.1f} ms",
                                    form_factor_seconds, rig_summary.seconds, planner_seconds,
                                    first_ms));
  const bool gpu = args.render == PlayRender::kGpu;
  Report(args.progress, fmt::format("  render on {}; {:.1f} seamless-field nodes per patch on average",
                                    renderer.description(), nodes_per_patch));
  Report(args.progress,
         fmt::format("  per frame, median of {}: solve (warm, tolerance {:g}) {:.1f} ms ({:.0f} iterations), render 3 images "
                     "({}) {:.1f} ms (plan {:.1f} with {:.0f} patches refined per pixel, {} {:.1f}); new desired "
                     "appearance -> every image ready {:.1f} ms",
                     args.frames, args.tolerance, Median(solve_ms), Median(iteration_values), gpu ? "GPU" : "CPU",
                     Median(render_ms), Median(plan_ms), Median(refined), gpu ? "draw + glFinish" : "shade",
                     Median(shade_ms), Median(total_ms)));
  Report(args.progress, fmt::format("  a frame to the nodes: {} bytes ({:.1f} KiB, half precision), encoded and "
                                    "parsed in {:.3f} ms (in the render time)",
                                    frame_bytes, frame_bytes / 1024.0, Median(frame_ms)));
  if (gpu) {
    Report(args.progress, fmt::format("  one {}x{} image on the GPU, median: {:.2f} ms upload + draw + glFinish "
                                      "(wall clock), {:.2f} ms drawing (the GPU's timer)",
                                      args.width, args.height, Median(one_image_ms), Median(one_image_gpu_ms)));
  }
  if (!args.json.empty()) {
    const nlohmann::json result = {{"benchmark", "play"},
                                   {"patches", problem.size()},
                                   {"width", args.width},
                                   {"height", args.height},
                                   {"projectors", 3},
                                   {"method", MethodName(args.method)},
                                   {"function_tolerance", args.tolerance},
                                   {"device", DeviceName(args.device)},
                                   {"frames", args.frames},
                                   {"first_frame_ms", first_ms},
                                   {"median_solve_ms", Median(solve_ms)},
                                   {"median_render_ms", Median(render_ms)},
                                   {"median_plan_ms", Median(plan_ms)},
                                   {"frame_bytes", frame_bytes},
                                   {"median_frame_ms", Median(frame_ms)},
                                   {"median_refined_patches", Median(refined)},
                                   {"median_shade_ms", Median(shade_ms)},  // or draw + glFinish
                                   {"median_total_ms", Median(total_ms)},
                                   {"median_iterations", Median(iteration_values)},
                                   {"render", gpu ? "gpu" : "cpu"},
                                   {"renderer", renderer.description()},
                                   {"median_one_image_ms", gpu ? Median(one_image_ms) : 0.0},
                                   {"median_one_image_gpu_ms", gpu ? Median(one_image_gpu_ms) : 0.0}};
    WriteFileAtomically(args.json, result.dump(2) + "\n");
  }
}

}  // namespace procam
