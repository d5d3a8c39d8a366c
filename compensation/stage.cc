#include "compensation/stage.h"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

#include "base/io.h"
#include "base/option_table.h"
#include "base/output_directory.h"

namespace procam {

std::vector<std::pair<std::string, CompensationMethod>> MethodChoices() {
  std::vector<std::pair<std::string, CompensationMethod>> methods;
  for (CompensationMethod method :
       {CompensationMethod::kNaive, CompensationMethod::kReverse, CompensationMethod::kLinear,
        CompensationMethod::kPerceptual, CompensationMethod::kPerceptual2000}) {
    methods.emplace_back(MethodName(method), method);
  }
  return methods;
}

std::vector<std::pair<std::string, SolverOptions::RobustLoss>> RobustLossChoices() {
  std::vector<std::pair<std::string, SolverOptions::RobustLoss>> losses;
  for (SolverOptions::RobustLoss loss :
       {SolverOptions::RobustLoss::kSquared, SolverOptions::RobustLoss::kSoftL1,
        SolverOptions::RobustLoss::kHuber, SolverOptions::RobustLoss::kCauchy}) {
    losses.emplace_back(RobustLossName(loss), loss);
  }
  return losses;
}

std::vector<std::pair<std::string, SolverOptions::MetricUpdate>> MetricUpdateChoices() {
  std::vector<std::pair<std::string, SolverOptions::MetricUpdate>> updates;
  for (SolverOptions::MetricUpdate update :
       {SolverOptions::MetricUpdate::kEveryIteration, SolverOptions::MetricUpdate::kRounds}) {
    updates.emplace_back(MetricUpdateName(update), update);
  }
  return updates;
}

std::vector<std::pair<std::string, Device>> DeviceChoices() {
  std::vector<std::pair<std::string, Device>> devices;
  for (Device device : {Device::kCpu, Device::kCuda})
    devices.emplace_back(DeviceName(device), device);
  return devices;
}

void CompensationOptions::Declare(OptionTable* table) {
  table
      ->Choice("method", &solver.method, MethodChoices(),
               "the objective: naive, reverse, linear, perceptual (the paper's, in CIE76) or "
               "perceptual2000 (CIEDE2000 with a robust loss; docs/solver.md)")
      .Choice("loss", &solver.robust_loss, RobustLossChoices(),
              "perceptual2000: the loss on each patch's ΔE00²")
      .Number("loss-scale", &solver.robust_scale, 1e-6, 1e6, "ΔE00",
              "perceptual2000: the loss's scale")
      .Choice("metric-update", &solver.metric_update, MetricUpdateChoices(),
              "perceptual2000: when CIEDE2000's metric and the loss's weights are measured again: "
              "every_iteration (at every iterate of one Gauss-Newton run, to the reweighting's "
              "fixed point) or rounds (--metric-rounds whole solves; docs/solver.md)")
      .Integer("metric-rounds", &solver.metric_rounds, 1, 100, "",
               "perceptual2000 with --metric-update rounds: reweighting rounds (CIEDE2000's metric "
               "and the loss's weights re-evaluated at the last round's result)")
      .Number("alpha", &alpha, OptionTable::Interval::AboveMin(0.0, 1.0), "",
              "weight of the absolute term against the spatial term")
      .Flag("multires", &solver.multires, "solve the coarse patch level first and start from it")
      .Choice("device", &solver.device, DeviceChoices(),
              "where K⁻¹ is applied (cuda needs a CUDA build and a GPU; docs/gpu.md)");
}

void SolutionOutputOptions::Declare(OptionTable* table) {
  table->Flag("export", &export_problem, "also write the whole problem (F.npy, ...) into --out")
      .Path("out", &out, "output directory")
      .Required();
}

bool CompensationOptions::Check(std::string* why) const {
  // The table only reads the fields here.
  OptionTable table("compensate");
  const_cast<CompensationOptions*>(this)->Declare(&table);
  if (!table.Check(why)) return false;
  if (lower.rows() != upper.rows()) {
    *why = "lower and upper bounds must have the same number of patches";
    return false;
  }
  return solver.Check(why);
}

CompensationRun RunCompensation(const GeometryStage& geometry,
                                const CompensationOptions& compensation) {
  std::string why;
  if (!compensation.Check(&why)) throw std::invalid_argument(why);
  const SolverOptions& options = compensation.solver;
  const double alpha = compensation.alpha;
  CompensationRun run;
  const PatchHierarchy& patches = geometry.patches;
  run.fine = MakeProblem(geometry.scene, patches.fine, geometry.form_factors, alpha);
  if (geometry.compressed) {
    run.fine.compressed_form_factors = geometry.compressed;
    // The coarse level is only needed to start from: compressed too, computed for it directly.
    run.coarse = MakeProblem(geometry.scene, patches.coarse, Eigen::MatrixXd(), alpha);
    if (options.multires) {
      run.coarse.compressed_form_factors =
          std::make_shared<const CompressedFormFactors>(ComputeCompressedFormFactors(
              geometry.scene, patches.coarse, FormFactorOptions(), ClusterOptions(), nullptr));
    }
  } else {
    run.coarse = MakeProblem(geometry.scene, patches.coarse,
                             AggregateFormFactors(geometry.form_factors, patches.fine.Areas(),
                                                  patches.coarse_of_fine, patches.coarse.size()),
                             alpha);
  }
  if (compensation.lower.rows() > 0) {
    if (compensation.lower.rows() != run.fine.size()) {
      throw std::invalid_argument("bounds for " + std::to_string(compensation.lower.rows()) +
                                  " patches, the scene has " + std::to_string(run.fine.size()));
    }
    run.fine.lower = compensation.lower;
    run.fine.upper = compensation.upper;
    const Eigen::VectorXd area = patches.fine.Areas();
    run.coarse.lower =
        CoarsenPatchValues(compensation.lower, area, patches.coarse_of_fine, patches.coarse.size());
    run.coarse.upper =
        CoarsenPatchValues(compensation.upper, area, patches.coarse_of_fine, patches.coarse.size());
  }
  SolverOptions logged = options;
  const ProgressCallback& progress = compensation.progress;
  if (!logged.progress && progress) {
    logged.progress = [&progress](int iteration, double cost, double seconds) {
      progress(
          fmt::format("  iteration {:3d}  objective {:.6e}  {:.3f} s", iteration, cost, seconds));
    };
  }
  Report(progress,
         fmt::format("compensate: {} on {} patches ({} variables){}", MethodName(options.method),
                     run.fine.size(), 3 * run.fine.size(), options.multires ? ", multires" : ""));
  run.solution =
      Solve(logged, run.fine, &run.summary, CoarseLevel{&run.coarse, &patches.coarse_of_fine});
  Report(progress, run.summary.BriefReport());
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
    return {{"storage", "dense"},
            {"bytes", 8.0 * n * n},
            {"seconds", geometry.form_factor_summary.seconds}};
  }
  const CompressedBuildSummary& c = geometry.compressed_summary;
  return {{"storage", "compressed"},        {"bytes", c.bytes},
          {"dense_bytes", 8.0 * n * n},     {"seconds", c.seconds},
          {"near_entries", c.near_entries}, {"far_blocks", c.far_blocks},
          {"far_values", c.far_values},     {"clusters", c.clusters}};
}

}  // namespace

namespace {

// The scene as result.json records it: a scene file's absolute path, so that `project` run from
// another directory reads the same file; a built-in scene's name as it is.
std::string RecordedScenePath(const std::filesystem::path& path) {
  std::error_code error;
  if (path.empty() || path.is_absolute() || !std::filesystem::is_regular_file(path, error)) {
    return path.string();
  }
  return std::filesystem::absolute(path).lexically_normal().string();
}

}  // namespace

nlohmann::json CompensationResultJson(const GeometryStage& geometry, const CompensationRun& run) {
  const SolverSummary& s = run.summary;
  nlohmann::json trace = nlohmann::json::array();
  for (const IterationRecord& record : s.trace) {
    trace.push_back({{"iteration", record.iteration},
                     {"objective", record.cost},
                     {"seconds", record.seconds},
                     {"step", record.step},
                     {"free_variables", record.free_variables},
                     {"cg_iterations", record.cg_iterations}});
  }
  return {{"format_version", kSolutionFormatVersion},
          {"method", MethodName(s.method)},
          {"multires", s.coarse_iterations > 0},
          {"scene", RecordedScenePath(geometry.scene.path)},
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
  CheckOutputDirectory(out, DirectoryKind::kSolution);
  // Written beside `out`, then swapped in: the directory holds the earlier solution or this
  // one, never a mix, whatever stops the writing part-way.
  ReplacedDirectory replaced(out);
  const std::filesystem::path& dir = replaced.staging();
  try {
    if (export_problem) {
      if (run.fine.compressed()) {
        const SolutionOutputOptions names;  // the option as declared
        throw std::invalid_argument(FlagOf(names, &names.export_problem) +
                                    " writes the dense F.npy: not with compressed form factors");
      }
      nlohmann::json settings = {{"scene", geometry.scene.path.string()},
                                 {"method", MethodName(run.summary.method)}};
      ExportProblem(run.fine, geometry.patches.fine, geometry.patches.coarse_of_fine, dir,
                    settings.dump());
    }
    WriteNpy(dir / "E.npy", RowMatrixXd(run.solution.emittance));
    WriteNpy(dir / "B.npy", RowMatrixXd(run.solution.radiosity));
    nlohmann::json result = CompensationResultJson(geometry, run);
    if (extra.is_object()) result.update(extra);
    WriteFileAtomically(dir / "result.json", result.dump(2) + "\n");
  } catch (const IoError& error) {
    throw IoError(out.string() + ": left as it was; writing the new solution beside it failed: " +
                  error.what());
  }
  replaced.Commit();
}

namespace {

Eigen::MatrixX3d ReadPatchMatrix(const std::filesystem::path& path, int n) {
  if (!std::filesystem::exists(path)) throw IoError(path.string() + ": file not found");
  const NpyArray array = ReadNpy(path);
  if (array.shape.size() != 2 || array.shape[0] != n || array.shape[1] != 3) {
    std::string shape;
    for (const int64_t extent : array.shape) {
      if (!shape.empty()) shape += ",";  // (not `"," + ...`: GCC 12 warns a false -Wrestrict)
      shape += std::to_string(extent);
    }
    throw IoError(path.string() + ": shape (" + shape + "), but result.json says " +
                  std::to_string(n) + " patches: expected (" + std::to_string(n) + ",3)");
  }
  Eigen::MatrixX3d matrix(n, 3);
  for (int i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) matrix(i, c) = array.values[3 * i + c];
  }
  if (!matrix.allFinite()) throw IoError(path.string() + ": non-finite values");
  return matrix;
}

// A path as compensate recorded it: as given, or relative to the solution directory.
std::string ResolveAgainst(const std::string& written, const std::filesystem::path& dir) {
  const std::filesystem::path path(written);
  if (path.is_absolute() || std::filesystem::exists(path)) return written;
  if (std::filesystem::exists(dir / path)) return (dir / path).string();
  return written;
}

}  // namespace

SolutionDirectory ReadSolutionDirectory(const std::filesystem::path& dir) {
  const std::filesystem::path path = dir / "result.json";
  const std::string file = path.string();
  if (!std::filesystem::is_regular_file(path)) {
    throw IoError(
        file +
        ": file not found (SOLUTION_DIR must be what `procam compensate SCENE --out DIR` wrote)");
  }
  SolutionDirectory s;
  s.dir = dir;
  try {
    s.result = nlohmann::json::parse(ReadFile(path));
  } catch (const nlohmann::json::exception&) {
    throw IoError(file + ": invalid JSON");
  }
  const nlohmann::json& r = s.result;
  if (!r.is_object()) throw IoError(file + ": expected a JSON object");
  auto missing = [&file](const std::string& key, const std::string& what) {
    return IoError(file + ": " + key + ": required key is missing (" + what + ")");
  };
  if (!r.contains("format_version") || !r["format_version"].is_number_integer()) {
    throw missing("format_version",
                  "an integer; written by an older procam? run procam compensate again");
  }
  if (r["format_version"].get<int64_t>() != kSolutionFormatVersion) {
    throw IoError(file + ": format_version: " + r["format_version"].dump() +
                  " is not supported (this procam " + "reads version " +
                  std::to_string(kSolutionFormatVersion) + ")");
  }
  if (!r.contains("patches") || !r["patches"].is_number_integer() ||
      r["patches"].get<int64_t>() < 1 || r["patches"].get<int64_t>() > (1 << 26)) {
    throw missing("patches", "a positive integer");
  }
  s.patches = r["patches"].get<int>();
  s.target_patches = s.patches;
  if (r.contains("target_patches")) {
    if (!r["target_patches"].is_number_integer() || r["target_patches"].get<int64_t>() < 1 ||
        r["target_patches"].get<int64_t>() > (1 << 26)) {
      throw IoError(file + ": target_patches: a positive integer");
    }
    s.target_patches = r["target_patches"].get<int>();
  }
  if (!r.contains("scene") || !r["scene"].is_string() || r["scene"].get<std::string>().empty()) {
    throw missing("scene", "a string: the scene file");
  }
  s.scene = ResolveAgainst(r["scene"].get<std::string>(), dir);
  if (!r.contains("method") || !r["method"].is_string()) throw missing("method", "a method name");
  if (!ParseMethod(r["method"].get<std::string>(), &s.method)) {
    throw IoError(file + ": method: unknown method '" + r["method"].get<std::string>() + "'");
  }
  if (!r.contains("multires") || !r["multires"].is_boolean())
    throw missing("multires", "true or false");
  s.multires = r["multires"].get<bool>();
  if (!r.contains("alpha") || !r["alpha"].is_number()) throw missing("alpha", "a number in (0,1]");
  s.alpha = r["alpha"].get<double>();
  if (!(s.alpha > 0.0 && s.alpha <= 1.0)) throw IoError(file + ": alpha: must be in (0,1]");
  if (r.contains("rig")) {
    if (!r["rig"].is_object() || !r["rig"].contains("dir") || !r["rig"]["dir"].is_string()) {
      throw IoError(file + ": rig.dir: a string (the rig directory compensate used)");
    }
    s.rig_dir = ResolveAgainst(r["rig"]["dir"].get<std::string>(), dir);
  }
  s.emittance = ReadPatchMatrix(dir / "E.npy", s.patches);
  s.radiosity = ReadPatchMatrix(dir / "B.npy", s.patches);
  return s;
}

void ExportGeometryProblem(const GeometryStage& stage, double alpha,
                           const std::filesystem::path& out) {
  const CompensationProblem problem =
      MakeProblem(stage.scene, stage.patches.fine, stage.form_factors, alpha);
  const std::string invalid = problem.Validate();
  if (!invalid.empty()) throw IoError(stage.scene.path.string() + ": " + invalid);
  nlohmann::json settings;
  settings["scene"] = stage.scene.path.string();
  settings["scene_name"] = stage.scene.name;
  settings["white"] = stage.scene.white;
  settings["form_factor_seconds"] = stage.form_factor_summary.seconds;
  ExportProblem(problem, stage.patches.fine, stage.patches.coarse_of_fine, out, settings.dump());
}

}  // namespace procam
