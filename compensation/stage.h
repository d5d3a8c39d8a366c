#pragma once
// The compensation stage: the fine and coarse problems from the geometry stage, the solve, the
// colour differences per patch, and the solution directory (docs/solution_format.md).

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "base/progress.h"
#include "compensation/problem.h"
#include "compensation/solver.h"
#include "geometry/stage.h"

namespace procam {

class OptionTable;

struct CompensationRun {
  CompensationProblem fine, coarse;
  CompensationSolution solution;
  SolverSummary summary;
  double perceptual_objective = 0.0;       // f in L*a*b* of the solution, whatever the method
  Eigen::VectorXd delta_e76, delta_e2000;  // per fine patch
  double mean_delta_e76 = 0.0, max_delta_e76 = 0.0;  // area-weighted mean, max
  double mean_delta_e2000 = 0.0, max_delta_e2000 = 0.0;
};

struct CompensationOptions {
  // Method (perceptual2000 with the metric measured at every iterate: RecommendedSolverOptions),
  // multires, device, tolerances (solver.h).
  SolverOptions solver = RecommendedSolverOptions();
  double alpha = 0.5;    // weight of the absolute term of the objective, (0, 1]
  // The fine patches' direct-light limits (n,3), e.g. a projection rig's lower and upper
  // (projection/projection_rig.h); empty: the scene's "bounds".
  Eigen::MatrixX3d lower, upper;
  // A line per solver iteration and the solver's brief report (when solver.progress is unset).
  ProgressCallback progress;
  // Declares the options a person sets — --method, --loss, --loss-scale, --metric-update,
  // --metric-rounds, --alpha, --multires, --device — in `table`, bound to this struct's fields,
  // with their ranges and choices (base/option_table.h; the command line and docs/options.md come
  // from it).
  void Declare(OptionTable* table);
  // The declared options within their ranges, the bounds' shapes, and solver.Check().
  bool Check(std::string* why) const;
};

// The names the option tables take for the solver's enumerations (OptionTable::Choice), in the
// order they are listed: --method (naive, reverse, linear, perceptual, perceptual2000), --loss,
// --metric-update (every_iteration, rounds) and --device, for every command that declares them.
std::vector<std::pair<std::string, CompensationMethod>> MethodChoices();
std::vector<std::pair<std::string, SolverOptions::RobustLoss>> RobustLossChoices();
std::vector<std::pair<std::string, SolverOptions::MetricUpdate>> MetricUpdateChoices();
std::vector<std::pair<std::string, Device>> DeviceChoices();

// Builds the fine and coarse problems (coarse F aggregated from the fine one, coarse bounds
// area-weighted from the fine ones) and solves. Throws std::invalid_argument for bad options.
// A numerical failure is run.summary.termination, not an exception.
CompensationRun RunCompensation(const GeometryStage& geometry, const CompensationOptions& options);

// result.json content for a run (docs/solution_format.md).
nlohmann::json CompensationResultJson(const GeometryStage& geometry, const CompensationRun& run);

// The solution directory: what `procam compensate` writes and `project`, `verify` and the demo
// read. result.json (format version kSolutionFormatVersion) with the run's numbers, E.npy and
// B.npy (n,3), and with `--export` the whole problem (ExportProblem). Schema:
// docs/solution_format.md.
constexpr int kSolutionFormatVersion = 1;

// Where `procam compensate` writes its solution (WriteCompensation's `out` and `export_problem`).
struct SolutionOutputOptions {
  std::filesystem::path out;    // the solution directory (created)
  bool export_problem = false;  // also the whole problem (F.npy, ...)
  // Declares --export and --out (required) in `table`, bound to these fields.
  void Declare(OptionTable* table);
};

// Writes result.json, E.npy, B.npy (and with `export_problem` the whole problem) into `out`,
// each atomically. `extra` keys (e.g. "rig") are added to result.json.
void WriteCompensation(const GeometryStage& geometry, const CompensationRun& run,
                       const std::filesystem::path& out, bool export_problem,
                       const nlohmann::json& extra = nlohmann::json::object());

// `procam scene export`: the fine level's problem of `stage` with weight `alpha`, written as
// NumPy files and problem.json (ExportProblem) into `out`. Throws IoError naming the scene when
// the problem is invalid.
void ExportGeometryProblem(const GeometryStage& stage, double alpha,
                           const std::filesystem::path& out);

// A solution directory as read back.
struct SolutionDirectory {
  std::filesystem::path dir;
  nlohmann::json result;  // result.json as read: every key, the typed ones below included
  // The scene as compensate named it (a file, or PREFIX:NAME): a relative file path that does
  // not exist from here but does from `dir` is made relative to `dir`.
  std::string scene;
  int patches = 0;         // fine patches
  int target_patches = 0;  // the patch target that subdivides the scene into them
  CompensationMethod method = CompensationMethod::kPerceptual;
  bool multires = false;
  double alpha = 0.5;
  std::filesystem::path rig_dir;  // the rig directory compensate used (--rig); empty if none
  Eigen::MatrixX3d emittance, radiosity;  // E.npy, B.npy
};
// Reads and checks a solution directory. Throws IoError naming the file and the key (or the
// .npy and its shape): no result.json, a format version other than kSolutionFormatVersion, a
// missing or mistyped key, arrays of the wrong shape or with non-finite values.
SolutionDirectory ReadSolutionDirectory(const std::filesystem::path& dir);

}  // namespace procam
