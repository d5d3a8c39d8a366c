#include "datasets_synthetic/benchmarks.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <stdexcept>

#include "base/io.h"
#include "base/timing.h"
#include "compensation/objective.h"
#include "compensation/peers.h"
#include "compensation/problem.h"
#include "compensation/radiosity.h"
#include "compensation/solver.h"
#include "datasets_synthetic/bench_projectors.h"
#include "datasets_synthetic/rooms.h"
#include "geometry/form_factors.h"
#include "geometry/patches.h"
#include "projection/frame_plan.h"
#include "projection/projection_rig.h"
#include "projection/projector.h"
#include "projection/stage.h"

namespace procam {
namespace {

// A printf-style line (without its trailing newline) to the progress callback.
void Line(const ProgressCallback& progress, const char* format, ...)
    __attribute__((format(printf, 2, 3)));
void Line(const ProgressCallback& progress, const char* format, ...) {
  va_list arguments;
  va_start(arguments, format);
  va_list copy;
  va_copy(copy, arguments);
  const int size = std::vsnprintf(nullptr, 0, format, copy);
  va_end(copy);
  std::string text(size > 0 ? size : 0, '\0');
  if (size > 0) std::vsnprintf(text.data(), text.size() + 1, format, arguments);
  va_end(arguments);
  while (!text.empty() && text.back() == '\n') text.pop_back();
  Report(progress, text);
}

// One solver's row of the table.
struct BenchRow {
  std::string solver;
  double seconds = 0.0;             // whole solve, excluding the shared factorisation of K
  double seconds_to_target = -1.0;  // first time the objective was within the target, -1 never
  int iterations = 0;
  double objective = 0.0;
  std::string termination;
  std::vector<std::pair<double, double>> trace;  // (seconds, objective)
};

double TimeToTarget(const std::vector<std::pair<double, double>>& trace, double target) {
  for (const auto& [seconds, cost] : trace) {
    if (cost <= target) return seconds;
  }
  return -1.0;
}

BenchRow OurSolver(const std::string& name, const SolverOptions& options,
                   const CompensationProblem& problem, const CoarseLevel& coarse) {
  SolverSummary summary;
  Solve(options, problem, &summary, coarse);
  BenchRow row;
  row.solver = name;
  row.seconds = summary.solve_seconds;
  row.iterations = summary.iterations;
  row.objective = summary.final_cost;
  row.termination = TerminationName(summary.termination);
  // The trace's clock starts at the fine level; the coarse solve came first.
  for (const IterationRecord& record : summary.trace) {
    row.trace.emplace_back(summary.coarse_seconds + record.seconds, record.cost);
  }
  return row;
}

BenchRow Peer(const char* name, const PeerResult& result) {
  BenchRow row;
  row.solver = name;
  row.seconds = result.seconds;
  row.iterations = result.iterations;
  row.objective = result.cost;
  row.termination = result.termination;
  row.trace = result.trace;
  return row;
}

// Median seconds of `repeats` calls.
template <typename Call>
double MedianSeconds(int repeats, Call call) {
  std::vector<double> seconds;
  for (int k = 0; k < repeats; ++k) {
    const auto start = Clock::now();
    call();
    seconds.push_back(SecondsSince(start));
  }
  std::sort(seconds.begin(), seconds.end());
  return seconds[seconds.size() / 2];
}

// A 1024×1024 texture of crossed sinusoidal stripes (linear RGB), ~40 periods across: detail
// finer than the bench's patches, for timing RenderOptions::detail.
cv::Mat BenchTexture() {
  constexpr int kSize = 1024;
  constexpr double kTwoPi = 6.283185307179586;
  cv::Mat texture(kSize, kSize, CV_32FC3);
  for (int y = 0; y < kSize; ++y) {
    for (int x = 0; x < kSize; ++x) {
      const double u = (x + 0.5) / kSize, v = (y + 0.5) / kSize;
      texture.at<cv::Vec3f>(y, x) =
          cv::Vec3f(static_cast<float>(0.5 + 0.3 * std::sin(kTwoPi * 40 * u)),
                    static_cast<float>(0.5 + 0.3 * std::sin(kTwoPi * 40 * v)),
                    static_cast<float>(0.5 + 0.3 * std::sin(kTwoPi * 28 * (u + v))));
    }
  }
  return texture;
}

}  // namespace

namespace {

const std::vector<std::pair<std::string, std::string>> kDevices = {
    {"cpu", "cpu"}, {"cuda", "cuda"}, {"both", "both"}};
constexpr int kMostPatches = 10'000'000;

}  // namespace

void ProjectionBenchmarkOptions::Declare(OptionTable* table) {
  table->Integer("width", &width, 1, 16384, "pixels", "projector width")
      .Integer("height", &height, 1, 16384, "pixels", "projector height")
      .Integer("patches", &patches, 1, kMostPatches, "", "target patch count")
      .Integer("repeat", &repeat, 1, 1000, "", "timed runs")
      .Choice("dither", &dither, DitherChoices(), "none, ordered or error-diffusion")
      .Flag("detail", &detail, "give every surface a striped texture and render with its detail")
      .Choice("light", &light, LightFieldChoices(),
              "smooth: the light varies smoothly over each surface (seamless); flat: one uniform "
              "level per patch")
      .Text("json", &json, "also write the timings as JSON here");
}

void BenchmarkOptions::DeclareFormFactors(OptionTable* table) {
  table->Integer("patches", &patches, 1, kMostPatches, "", "target patch count")
      .Integer("threads", &threads, 0, 1024, "", "worker threads (0: all cores)")
      .Text("json", &json, "also write the result as JSON here");
}

void BenchmarkOptions::DeclareSolver(OptionTable* table) {
  table->Integers("sizes", &sizes, 1, kMostPatches, "", "target patch counts (3 variables each)")
      .Integer("ceres-max-variables", &ceres_max_variables, 0, std::numeric_limits<int>::max(), "",
               "skip Ceres above this many variables")
      .Number("alpha", &alpha, 1e-9, 1.0, "", "weight of the absolute term")
      .Text("json", &json, "also write the results as JSON here")
      .Choice<std::string>("device", &device, kDevices,
                           "rows to run: cpu, cuda (the GPU solver) or both")
      .Integer("cpu-max-variables", &cpu_max_variables, 0, std::numeric_limits<int>::max(), "",
               "skip the CPU rows (own solvers and peers) above this many variables");
}

void BenchmarkOptions::DeclareScale(OptionTable* table) {
  table
      ->Integers("sizes", &scale_sizes, 1, kMostPatches, "",
                 "target patch counts (3 variables each)")
      .Integer("dense-max-patches", &dense_max_patches, 0, kMostPatches, "",
               "also compute the dense F (time, product error) up to this many patches")
      .Integer("leaf-size", &clusters.leaf_size, 1, std::numeric_limits<int>::max(), "",
               "most patches per leaf cluster")
      .Number("admissibility", &clusters.admissibility, 1e-6, 1.0, "",
              "far when diameters <= this x distance")
      .Integer("threads", &threads, 0, 1024, "", "form-factor threads (0: all cores)")
      .Number("alpha", &alpha, 1e-9, 1.0, "", "weight of the absolute term")
      .Choice<std::string>("device", &device, kDevices, "solves to run: cpu, cuda or both")
      .Integer("cpu-max-variables", &cpu_max_variables, 0, std::numeric_limits<int>::max(), "",
               "skip the CPU solves above this many variables")
      .Text("json", &json, "also write the results as JSON here");
}

void RunFormFactorBenchmark(const BenchmarkOptions& args) {
  const SubdividedRoom room = MakeSubdividedBoxRoom(args.patches);  // closed, with an occluder
  const Scene& scene = room.scene;
  const PatchHierarchy& hierarchy = room.patches;
  FormFactorOptions options;
  options.threads = args.threads;
  FormFactorSummary summary;
  ComputeFormFactors(scene, hierarchy.fine, options, &summary);
  Line(args.progress,
       "form factors, closed room with occluder: %d patches, %lld facing pairs, %lld shadow rays\n",
       hierarchy.fine.size(), static_cast<long long>(summary.pairs_evaluated),
       static_cast<long long>(summary.shadow_rays));
  Line(args.progress,
       "  time %.3f s (threads: %s); row sums min %.5f mean %.5f max %.5f; largest row cut %.4f\n",
       summary.seconds, args.threads > 0 ? std::to_string(args.threads).c_str() : "all cores",
       summary.min_row_sum, summary.mean_row_sum, summary.max_row_sum, summary.max_row_correction);
  if (!args.json.empty()) {
    const nlohmann::json result = {
        {"benchmark", "form_factors"},        {"patches", hierarchy.fine.size()},
        {"seconds", summary.seconds},         {"threads", args.threads},
        {"pairs", summary.pairs_evaluated},   {"shadow_rays", summary.shadow_rays},
        {"min_row_sum", summary.min_row_sum}, {"max_row_sum", summary.max_row_sum}};
    WriteFileAtomically(args.json, result.dump(2) + "\n");
  }
}

void RunSolverBenchmark(const BenchmarkOptions& args) {
  const bool run_gpu = args.device != "cpu";
  std::string device_description = "none";
  if (run_gpu && !CudaAvailable(&device_description)) {
    throw std::runtime_error("bench solver --device " + args.device + ": " + device_description);
  }
  if (run_gpu) Line(args.progress, "CUDA device: %s\n", device_description.c_str());
  nlohmann::json sizes = nlohmann::json::array();
  Line(args.progress, "%s",
       fmt::format("{:>9} {:>8}  {:<22} {:>12} {:>11} {:>6}  {:<16} {}\n", "variables", "patches",
                   "solver", "to target s", "total s", "iters", "objective", "termination")
           .c_str());
  for (const int target_patches : args.sizes) {
    std::ostringstream table;
    const SubdividedRoom room = MakeSubdividedBoxRoom(target_patches);
    const Scene& scene = room.scene;
    const PatchHierarchy& patches = room.patches;
    FormFactorSummary ff;
    Eigen::MatrixXd f = ComputeFormFactors(scene, patches.fine, FormFactorOptions(), &ff);
    const Eigen::MatrixXd coarse_f = AggregateFormFactors(
        f, patches.fine.Areas(), patches.coarse_of_fine, patches.coarse.size());
    const CompensationProblem problem = MakeProblem(scene, patches.fine, std::move(f), args.alpha);
    const CompensationProblem coarse_problem =
        MakeProblem(scene, patches.coarse, coarse_f, args.alpha);
    const CoarseLevel coarse{&coarse_problem, &patches.coarse_of_fine};
    const int n = problem.size();
    Report(args.progress,
           fmt::format("bench solver: {} patches, {} variables (form factors {:.2f} s)", n, 3 * n,
                       ff.seconds));

    const bool run_cpu = args.device != "cuda" && 3 * n <= args.cpu_max_variables;
    double setup = -1.0, gpu_setup = -1.0;
    std::vector<BenchRow> rows;
    if (run_cpu) {
      const auto setup_start = Clock::now();
      const RadiositySystem radiosity(problem.form_factors, problem.area, problem.reflectance);
      setup = SecondsSince(setup_start);
      const CompensationObjective objective(problem, radiosity, ColourModel::kLab);
      const Eigen::MatrixX3d start =
          radiosity.Multiply(problem.desired).cwiseMax(problem.lower).cwiseMin(problem.upper);
      SolverOptions perceptual;
      rows.push_back(OurSolver("perceptual", perceptual, problem, coarse));
      perceptual.multires = true;
      rows.push_back(OurSolver("perceptual --multires", perceptual, problem, coarse));
      PeerOptions peer;
      peer.max_iterations = 5000;
      rows.push_back(Peer("L-BFGS-B (LBFGSpp)", SolveWithLbfgsb(objective, start, peer)));
      if (3 * n <= args.ceres_max_variables) {
        rows.push_back(Peer("Ceres LM", SolveWithCeres(objective, start, peer)));
      }
    }
    if (run_gpu) {
      // The same solver with every K⁻¹/K⁻ᵀ on the GPU; its setup (K⁻¹ formed on the device,
      // F uploaded) is listed apart, as the CPU's factorisation is.
      SolverOptions perceptual;
      perceptual.device = Device::kCuda;
      SolverSummary gpu_summary;
      Solve(perceptual, problem, &gpu_summary);  // setup timing, and warms the device up
      gpu_setup = gpu_summary.setup_seconds;
      rows.push_back(OurSolver("perceptual [cuda]", perceptual, problem, coarse));
      perceptual.multires = true;
      rows.push_back(OurSolver("perceptual --multires [cuda]", perceptual, problem, coarse));
      perceptual.device_float32 = true;
      rows.push_back(OurSolver("... [cuda float32]", perceptual, problem, coarse));
    }
    if (rows.empty()) continue;  // --device cpu above --cpu-max-variables
    // The float32 rows' own objective values are float32 evaluations: not a reference.
    double best = rows.front().objective;
    for (const BenchRow& row : rows) {
      if (row.solver.find("float32") == std::string::npos) best = std::min(best, row.objective);
    }
    const double target = best * (1.0 + 1e-6);
    for (BenchRow& row : rows) row.seconds_to_target = TimeToTarget(row.trace, target);
    for (const Device device : {Device::kCpu, Device::kCuda}) {
      if (device == Device::kCpu ? !run_cpu : !run_gpu) continue;
      SolverOptions linear_options;
      linear_options.method = CompensationMethod::kLinear;
      linear_options.device = device;
      BenchRow linear =
          OurSolver(device == Device::kCpu ? "linear (own objective)" : "linear [cuda]",
                    linear_options, problem, coarse);
      linear.seconds_to_target = -1.0;
      rows.push_back(linear);
    }

    nlohmann::json size_json = {{"patches", n},
                                {"variables", 3 * n},
                                {"factorisation_seconds", setup},
                                {"cuda_setup_seconds", gpu_setup},
                                {"form_factor_seconds", ff.seconds},
                                {"target_objective", target}};
    if (run_cpu) {
      table << fmt::format("{:>9} {:>8}  {:<22} {:>12} {:>11.4f} {:>6}  {:<16} {}\n", 3 * n, n,
                           "(factorise K once)", "", setup, "", "", "");
    }
    if (run_gpu) {
      table << fmt::format("{:>9} {:>8}  {:<22} {:>12} {:>11.4f} {:>6}  {:<16} {}\n", 3 * n, n,
                           "(invert K on cuda once)", "", gpu_setup, "", "", "");
    }
    for (const BenchRow& row : rows) {
      const std::string to_target =
          row.seconds_to_target < 0 ? "-" : fmt::format("{:.4f}", row.seconds_to_target);
      table << fmt::format("{:>9} {:>8}  {:<22} {:>12} {:>11.4f} {:>6}  {:<16.10g} {}\n", 3 * n, n,
                           row.solver, to_target, row.seconds, row.iterations, row.objective,
                           row.termination);
      size_json["solvers"].push_back({{"solver", row.solver},
                                      {"seconds", row.seconds},
                                      {"seconds_to_target", row.seconds_to_target},
                                      {"iterations", row.iterations},
                                      {"objective", row.objective},
                                      {"termination", row.termination}});
    }
    sizes.push_back(size_json);
    Line(args.progress, "%s",
         table.str().c_str());  // each size as it finishes: long runs show progress
  }
  if (!args.json.empty()) {
    const nlohmann::json result = {
        {"benchmark", "solver"},
        {"cuda_device", device_description},
        {"scene", "box room with occluder, bounds [0, 1], alpha " + std::to_string(args.alpha)},
        {"target", "best final objective among perceptual solvers, +1e-6 relative"},
        {"sizes", sizes}};
    WriteFileAtomically(args.json, result.dump(2) + "\n");
    Line(args.progress, "wrote %s\n", args.json.c_str());
  }
}

// The matrix-free path: compressed form factors, their products, K⁻¹ by conjugate
// gradients and the perceptual solver on them, per room size; beside the dense F where it fits.
void RunScaleBenchmark(const BenchmarkOptions& args) {
  const bool run_gpu = args.device != "cpu";
  std::string device_description = "none";
  if (run_gpu && !CudaAvailable(&device_description)) {
    throw std::runtime_error("bench scale --device " + args.device + ": " + device_description);
  }
  nlohmann::json sizes = nlohmann::json::array();
  Line(
      args.progress, "%s",
      fmt::format(
          "{:>9} {:>8} {:>9} {:>10} {:>10} {:>9} {:>9} {:>10} {:>9} {:>6}  {:<22} {:>9} {:>6} {}\n",
          "variables", "patches", "build s", "MB", "dense MB", "F x ms", "error", "K⁻¹ ms",
          "CG iters", "", "solver", "solve s", "iters", "objective")
          .c_str());
  for (const int target_patches : args.scale_sizes) {
    const SubdividedRoom room = MakeSubdividedBoxRoom(target_patches);
    const Scene& scene = room.scene;
    const PatchHierarchy& patches = room.patches;
    const int n = patches.fine.size();
    FormFactorOptions ff_options;
    ff_options.threads = args.threads;
    int last_percent = -10;
    ff_options.progress = [&](double fraction) {
      const int percent = static_cast<int>(100 * fraction);
      if (percent >= last_percent + 10) {
        last_percent = percent;
        Report(args.progress, fmt::format("bench scale: {} patches, near pairs {}%", n, percent));
      }
    };
    CompressedBuildSummary build;
    auto compressed = std::make_shared<const CompressedFormFactors>(
        ComputeCompressedFormFactors(scene, patches.fine, ff_options, args.clusters, &build));
    const Eigen::MatrixXd x = Eigen::MatrixXd::Random(n, 3).cwiseAbs();
    const double product = MedianSeconds(5, [&] { compressed->Multiply(x); });
    double error = -1.0, dense_seconds = -1.0;
    Eigen::MatrixXd dense;
    if (n <= args.dense_max_patches) {
      FormFactorSummary ff;
      ff_options.progress = nullptr;
      dense = ComputeFormFactors(scene, patches.fine, ff_options, &ff);
      dense_seconds = ff.seconds;
      const Eigen::MatrixXd exact = dense * x;
      error = (compressed->Multiply(x) - exact).norm() / exact.norm();
    }
    const RadiositySystem radiosity(compressed, patches.fine.reflectance);
    const double solve = MedianSeconds(3, [&] { radiosity.Solve(Eigen::MatrixX3d::Ones(n, 3)); });
    const int cg = static_cast<int>(radiosity.solve_iterations() / 3);
    CompensationProblem problem = MakeProblem(scene, patches.fine, Eigen::MatrixXd(), args.alpha);
    problem.compressed_form_factors = compressed;
    nlohmann::json size_json = {{"patches", n},
                                {"variables", 3 * n},
                                {"build_seconds", build.seconds},
                                {"bytes", build.bytes},
                                {"dense_bytes", 8.0 * n * n},
                                {"near_entries", build.near_entries},
                                {"far_blocks", build.far_blocks},
                                {"far_values", build.far_values},
                                {"product_seconds", product},
                                {"product_relative_error", error},
                                {"dense_form_factor_seconds", dense_seconds},
                                {"k_inverse_seconds", solve},
                                {"cg_iterations", cg}};
    const auto line = [&](const std::string& solver, double seconds, int iterations,
                          double objective) {
      Line(args.progress, "%s",
           fmt::format(
               "{:>9} {:>8} {:>9.2f} {:>10.1f} {:>10.1f} {:>9.2f} {:>9} {:>10.2f} {:>9} {:>6}  "
               "{:<22} {:>9.3f} {:>6} {:.10g}\n",
               3 * n, n, build.seconds, build.bytes / 1e6, 8.0 * n * n / 1e6, 1e3 * product,
               error < 0 ? std::string("-") : fmt::format("{:.2e}", error), 1e3 * solve, cg, "",
               solver, seconds, iterations, objective)
               .c_str());
      std::fflush(stdout);
      size_json["solvers"].push_back({{"solver", solver},
                                      {"seconds", seconds},
                                      {"iterations", iterations},
                                      {"objective", objective}});
    };
    std::vector<Device> devices;
    if (args.device != "cuda" && 3 * n <= args.cpu_max_variables) devices.push_back(Device::kCpu);
    if (run_gpu) devices.push_back(Device::kCuda);
    for (const Device device : devices) {
      SolverOptions options;
      options.device = device;
      SolverSummary summary;
      Solve(options, problem, &summary);
      line(device == Device::kCpu ? "perceptual (matrix-free)" : "perceptual [cuda, m-free]",
           summary.setup_seconds + summary.solve_seconds, summary.iterations, summary.final_cost);
    }
    if (dense.size() != 0 && args.device != "cuda" && 3 * n <= args.cpu_max_variables) {
      const CompensationProblem dense_problem =
          MakeProblem(scene, patches.fine, std::move(dense), args.alpha);
      SolverSummary summary;
      Solve(SolverOptions(), dense_problem, &summary);
      line("perceptual (dense F)", summary.setup_seconds + summary.solve_seconds,
           summary.iterations, summary.final_cost);
    }
    if (devices.empty()) line("(no solve)", 0.0, 0, 0.0);
    sizes.push_back(size_json);
  }
  if (!args.json.empty()) {
    const nlohmann::json result = {
        {"benchmark", "scale"},
        {"cuda_device", device_description},
        {"scene", "box room with occluder, bounds [0, 1], alpha " + std::to_string(args.alpha)},
        {"leaf_size", args.clusters.leaf_size},
        {"admissibility", args.clusters.admissibility},
        {"sizes", sizes}};
    WriteFileAtomically(args.json, result.dump(2) + "\n");
    Line(args.progress, "wrote %s\n", args.json.c_str());
  }
}

namespace {


}  // namespace


void RunProjectionBenchmark(const ProjectionBenchmarkOptions& args) {
  const DitherMethod dither = args.dither;
  BoxRoomOptions room;
  room.target_patches = args.patches;
  Scene scene = MakeBoxRoom(room);
  if (args.detail) {
    const cv::Mat texture = BenchTexture();
    for (Surface& surface : scene.surfaces) surface.desired.texture_linear = texture;
  }
  SubdivisionOptions subdivision;
  subdivision.target_patches = args.patches;
  const PatchHierarchy hierarchy = SubdividePatches(scene, subdivision);
  const std::vector<Projector> projectors = BoxRoomProjectors(2, args.width, args.height);
  ProjectionRigSummary rig_summary;
  ProjectionRigOptions rig_options;
  rig_options.texture_coordinates = args.detail;
  const ProjectionRig rig =
      BuildProjectionRig(hierarchy.fine, projectors, rig_options, &rig_summary);
  std::mt19937 random(1);
  std::uniform_real_distribution<double> unit(0.05, 0.95);
  Eigen::MatrixX3d emittance(rig.size(), 3);
  for (int i = 0; i < rig.size(); ++i) {
    for (int c = 0; c < 3; ++c)
      emittance(i, c) = rig.lower(i, c) + unit(random) * (rig.upper(i, c) - rig.lower(i, c));
  }
  RenderOptions options;
  options.dither = dither;
  options.detail = args.detail;
  options.light = args.light;
  std::vector<double> render_times, encode_times;
  RenderSummary summary;
  for (int r = 0; r < args.repeat; ++r) {
    const std::vector<ProjectorImage> images =
        RenderProjectorImages(rig, scene, emittance, options, &summary);
    render_times.push_back(summary.seconds);
    const auto start = Clock::now();
    EncodeProjectorImages(images);
    encode_times.push_back(SecondsSince(start));
  }
  std::sort(render_times.begin(), render_times.end());
  std::sort(encode_times.begin(), encode_times.end());
  const double render_median = render_times[render_times.size() / 2];
  const double encode_median = encode_times[encode_times.size() / 2];
  Report(args.progress,
         fmt::format("projection: 2 projectors {}x{} (OpenCV4 lens), closed room with occluder, {} patches",
                     args.width, args.height, rig.size()));
  Report(args.progress,
         fmt::format("  maps (once per rig: unproject, {} rays + blending shadow rays): {:.3f} s",
                     2LL * args.width * args.height, rig_summary.seconds));
  Report(args.progress,
         fmt::format("  images from a solution ({} light, {} dither{}, {} level passes): median "
                     "{:.1f} ms, min {:.1f} ms over {} runs",
                     LightFieldName(args.light), DitherName(dither), args.detail ? ", textures' detail" : "",
                     summary.level_passes, 1e3 * render_median, 1e3 * render_times.front(),
                     args.repeat));
  Report(args.progress, fmt::format("  PNG encoding of both: median {:.1f} ms", 1e3 * encode_median));
  Report(args.progress, fmt::format("  largest delivered-emittance error {:.2e} (relative)",
                                   summary.max_relative_error));
  if (!args.json.empty()) {
    const nlohmann::json result = {{"benchmark", "projection"},
                                   {"width", args.width},
                                   {"height", args.height},
                                   {"projectors", 2},
                                   {"patches", rig.size()},
                                   {"dither", DitherName(dither)},
                                   {"detail", args.detail},
                                   {"light", LightFieldName(args.light)},
                                   {"maps_seconds", rig_summary.seconds},
                                   {"render_seconds_median", render_median},
                                   {"render_seconds_min", render_times.front()},
                                   {"png_encode_seconds_median", encode_median},
                                   {"repeat", args.repeat},
                                   {"max_relative_error", summary.max_relative_error}};
    WriteFileAtomically(args.json, result.dump(2) + "\n");
  }
}

}  // namespace procam
