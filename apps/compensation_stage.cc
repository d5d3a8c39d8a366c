#include "apps/compensation_stage.h"

#include <spdlog/spdlog.h>

#include "base/io.h"

namespace procam {

CompensationRun RunCompensation(const GeometryStage& geometry, const SolverOptions& options, double alpha,
                                const ProjectionRig* rig) {
  CompensationRun run;
  const PatchHierarchy& patches = geometry.patches;
  run.fine = MakeProblem(geometry.scene, patches.fine, geometry.form_factors, alpha);
  if (geometry.compressed) {
    run.fine.compressed_form_factors = geometry.compressed;
    // The coarse level is only needed to start from: compressed too, computed for it directly.
    run.coarse = MakeProblem(geometry.scene, patches.coarse, Eigen::MatrixXd(), alpha);
    if (options.multires) {
      run.coarse.compressed_form_factors = std::make_shared<const CompressedFormFactors>(ComputeCompressedFormFactors(
          geometry.scene, patches.coarse, FormFactorOptions(), ClusterOptions(), nullptr));
    }
  } else {
    run.coarse = MakeProblem(geometry.scene, patches.coarse,
                             AggregateFormFactors(geometry.form_factors, patches.fine.Areas(),
                                                  patches.coarse_of_fine, patches.coarse.size()),
                             alpha);
  }
  if (rig != nullptr) {
    run.fine.lower = rig->lower;
    run.fine.upper = rig->upper;
    const Eigen::VectorXd area = patches.fine.Areas();
    run.coarse.lower = CoarsenBounds(rig->lower, area, patches.coarse_of_fine, patches.coarse.size());
    run.coarse.upper = CoarsenBounds(rig->upper, area, patches.coarse_of_fine, patches.coarse.size());
  }
  SolverOptions logged = options;
  if (!logged.progress) {
    logged.progress = [](int iteration, double cost, double seconds) {
      spdlog::info("  iteration {:3d}  objective {:.6e}  {:.3f} s", iteration, cost, seconds);
    };
  }
  spdlog::info("compensate: {} on {} patches ({} variables){}", MethodName(options.method), run.fine.size(),
               3 * run.fine.size(), options.multires ? ", multires" : "");
  run.solution = Solve(logged, run.fine, &run.summary, CoarseLevel{&run.coarse, &patches.coarse_of_fine});
  spdlog::info("{}", run.summary.BriefReport());
  const CompensationObjective lab(run.fine, *run.solution.radiosity_system, ColourModel::kLab);
  run.perceptual_objective = lab.Value(run.solution.emittance);
  lab.DeltaE(run.solution.radiosity, &run.delta_e76, &run.delta_e2000);
  const double total_area = run.fine.area.sum();
  run.mean_delta_e76 = run.fine.area.dot(run.delta_e76) / total_area;
  run.mean_delta_e2000 = run.fine.area.dot(run.delta_e2000) / total_area;
  run.max_delta_e76 = run.delta_e76.maxCoeff();
  run.max_delta_e2000 = run.delta_e2000.maxCoeff();
  return run;
}

namespace {

nlohmann::json FormFactorJson(const GeometryStage& geometry) {
  const int n = geometry.patches.fine.size();
  if (!geometry.compressed) {
    return {{"storage", "dense"}, {"bytes", 8.0 * n * n}, {"seconds", geometry.form_factor_summary.seconds}};
  }
  const CompressedBuildSummary& c = geometry.compressed_summary;
  return {{"storage", "compressed"}, {"bytes", c.bytes},          {"dense_bytes", 8.0 * n * n},
          {"seconds", c.seconds},     {"near_entries", c.near_entries}, {"far_blocks", c.far_blocks},
          {"far_values", c.far_values}, {"clusters", c.clusters}};
}

}  // namespace

nlohmann::json CompensationResultJson(const GeometryStage& geometry, const CompensationRun& run) {
  const SolverSummary& s = run.summary;
  nlohmann::json trace = nlohmann::json::array();
  for (const IterationRecord& record : s.trace) {
    trace.push_back({{"iteration", record.iteration}, {"objective", record.cost}, {"seconds", record.seconds},
                     {"step", record.step}, {"free_variables", record.free_variables},
                     {"cg_iterations", record.cg_iterations}});
  }
  return {{"method", MethodName(s.method)},
          {"scene", geometry.scene.path.string()},
          {"patches", run.fine.size()},
          {"target_patches", geometry.scene.target_patches},
          {"variables", 3 * run.fine.size()},
          {"alpha", run.fine.alpha},
          {"iterations", s.iterations},
          {"inner_iterations", s.inner_iterations},
          {"cg_iterations", s.cg_iterations},
          {"coarse_iterations", s.coarse_iterations},
          {"objective", run.perceptual_objective},
          {"method_objective", s.final_cost},
          {"initial_method_objective", s.initial_cost},
          {"setup_seconds", s.setup_seconds},
          {"solve_seconds", s.solve_seconds},
          {"termination", TerminationName(s.termination)},
          {"message", s.message},
          {"delta_e76", {{"mean", run.mean_delta_e76}, {"max", run.max_delta_e76}}},
          {"delta_e2000", {{"mean", run.mean_delta_e2000}, {"max", run.max_delta_e2000}}},
          {"trace", trace},
          {"form_factors", FormFactorJson(geometry)}};
}

void WriteCompensation(const GeometryStage& geometry, const CompensationRun& run,
                       const std::filesystem::path& out, bool export_problem,
                       const nlohmann::json& extra) {
  std::error_code error;
  std::filesystem::create_directories(out, error);
  if (error) throw IoError(out.string() + ": cannot create directory: " + error.message());
  if (export_problem) {
    if (run.fine.compressed()) {
      throw std::invalid_argument("--export writes the dense F.npy: not with compressed form factors");
    }
    nlohmann::json settings = {{"scene", geometry.scene.path.string()}, {"method", MethodName(run.summary.method)}};
    ExportProblem(run.fine, geometry.patches.fine, geometry.patches.coarse_of_fine, out, settings.dump());
  }
  WriteNpy(out / "E.npy", RowMatrixXd(run.solution.emittance));
  WriteNpy(out / "B.npy", RowMatrixXd(run.solution.radiosity));
  nlohmann::json result = CompensationResultJson(geometry, run);
  if (extra.is_object()) result.update(extra);
  WriteFileAtomically(out / "result.json", result.dump(2) + "\n");
}

}  // namespace procam
