// procam bench formfactors / bench solver / bench scale / bench decode
// (datasets_synthetic/benchmarks.h), each benchmark's options as BenchmarkOptions and
// DecodeBenchmarkOptions declare them.
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "datasets_synthetic/benchmarks.h"

namespace procam {

void AddBenchCommands(CLI::App& app) {
  CLI::App* bench = app.add_subcommand("bench", "Benchmarks on generated rooms");
  bench->require_subcommand(1);
  CLI::App* ff = bench->add_subcommand("formfactors", "Form factors of a closed room with an occluder");
  const auto ff_options = AddDeclaredOptions(ff, &BenchmarkOptions::DeclareFormFactors);
  ff->callback([ff_options] {
    ff_options->progress = PrintProgress();
    RunFormFactorBenchmark(*ff_options);
  });

  CLI::App* solver = bench->add_subcommand(
      "solver", "Perceptual solver (with and without multires), linear, L-BFGS-B and Ceres side by side");
  const auto solver_options = AddDeclaredOptions(solver, &BenchmarkOptions::DeclareSolver);
  solver->callback([solver_options] {
    solver_options->progress = PrintProgress();
    RunSolverBenchmark(*solver_options);
  });

  CLI::App* scale = bench->add_subcommand(
      "scale", "Compressed form factors and the matrix-free solver: build, memory, products, K⁻¹, solve");
  const auto scale_options = AddDeclaredOptions(scale, &BenchmarkOptions::DeclareScale);
  scale->callback([scale_options] {
    scale_options->progress = PrintProgress();
    RunScaleBenchmark(*scale_options);
  });

  CLI::App* decode = bench->add_subcommand(
      "decode", "Import and decode a structured-light capture (procam's 42 patterns, 1280x1024 photos)");
  const auto decode_options = AddDeclaredOptions<DecodeBenchmarkOptions>(decode);
  decode->callback([decode_options] {
    decode_options->progress = PrintProgress();
    RunDecodeBenchmark(*decode_options);
  });
}

}  // namespace procam
