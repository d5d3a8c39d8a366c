// procam bench formfactors / bench solver / bench scale / bench decode (datasets_synthetic/benchmarks.h).
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "datasets_synthetic/benchmarks.h"

namespace procam {

void AddBenchCommands(CLI::App& app) {
  CLI::App* bench = app.add_subcommand("bench", "Benchmarks on generated rooms");
  bench->require_subcommand(1);
  auto args = std::make_shared<BenchmarkOptions>();
  args->progress = PrintProgress();
  CLI::App* ff = bench->add_subcommand("formfactors", "Form factors of a closed room with an occluder");
  ff->add_option("--patches", args->patches, "Target patch count")->capture_default_str();
  ff->add_option("--threads", args->threads, "Worker threads (0: all cores)")->capture_default_str();
  ff->add_option("--json", args->json, "Also write the result as JSON here");
  ff->callback([args] { RunFormFactorBenchmark(*args); });

  CLI::App* solver = bench->add_subcommand(
      "solver", "Perceptual solver (with and without multires), linear, L-BFGS-B and Ceres side by side");
  solver->add_option("--sizes", args->sizes, "Target patch counts (3 variables each)")->delimiter(',')
      ->capture_default_str();
  solver->add_option("--ceres-max-variables", args->ceres_max_variables, "Skip Ceres above this many variables")
      ->capture_default_str();
  solver->add_option("--alpha", args->alpha, "Weight of the absolute term")->check(FiniteRange(1e-9, 1.0))
      ->capture_default_str();
  solver->add_option("--json", args->json, "Also write the results as JSON here");
  solver->add_option("--device", args->device, "Rows to run: cpu, cuda (the GPU solver) or both")
      ->check(CLI::IsMember({"cpu", "cuda", "both"}))
      ->capture_default_str();
  solver->add_option("--cpu-max-variables", args->cpu_max_variables,
                     "Skip the CPU rows (own solvers and peers) above this many variables");
  solver->callback([args] { RunSolverBenchmark(*args); });

  CLI::App* scale = bench->add_subcommand(
      "scale", "Compressed form factors and the matrix-free solver: build, memory, products, K⁻¹, solve");
  scale->add_option("--sizes", args->scale_sizes, "Target patch counts (3 variables each)")->delimiter(',')
      ->capture_default_str();
  scale->add_option("--dense-max-patches", args->dense_max_patches,
                    "Also compute the dense F (time, product error) up to this many patches")
      ->capture_default_str();
  scale->add_option("--leaf-size", args->clusters.leaf_size, "Most patches per leaf cluster")
      ->check(FinitePositive())->capture_default_str();
  scale->add_option("--admissibility", args->clusters.admissibility,
                    "Far when diameters <= this x distance, in (0, 1]")
      ->check(FiniteRange(1e-6, 1.0))->capture_default_str();
  scale->add_option("--threads", args->threads, "Form-factor threads (0: all cores)")->capture_default_str();
  scale->add_option("--alpha", args->alpha, "Weight of the absolute term")->check(FiniteRange(1e-9, 1.0))
      ->capture_default_str();
  scale->add_option("--device", args->device, "Solves to run: cpu, cuda or both")
      ->check(CLI::IsMember({"cpu", "cuda", "both"}))->capture_default_str();
  scale->add_option("--cpu-max-variables", args->cpu_max_variables, "Skip the CPU solves above this many variables");
  scale->add_option("--json", args->json, "Also write the results as JSON here");
  scale->callback([args] { RunScaleBenchmark(*args); });

  auto decode_args = std::make_shared<DecodeBenchmarkOptions>();
  decode_args->progress = PrintProgress();
  CLI::App* decode = bench->add_subcommand(
      "decode", "Import and decode a structured-light capture (procam's 42 patterns, 1280x1024 photos)");
  decode->add_option("--camera-width", decode_args->camera_width, "Photo width")->capture_default_str();
  decode->add_option("--camera-height", decode_args->camera_height, "Photo height")->capture_default_str();
  decode->add_option("--repeat", decode_args->repeat, "Timed runs")->check(CLI::Range(1, 100))
      ->capture_default_str();
  decode->add_option("--out", decode_args->out, "Keep the photos and the session here");
  decode->callback([decode_args] { RunDecodeBenchmark(*decode_args); });
}

}  // namespace procam
