#pragma once
// The compensation stage as the commands run it: problem from the geometry stage, solve,
// colour differences, result files.

#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "apps/geometry_stage.h"
#include "compensation/problem.h"
#include "compensation/solver.h"
#include "projection/projection_rig.h"

namespace procam {

struct CompensationRun {
  CompensationProblem fine, coarse;
  CompensationSolution solution;
  SolverSummary summary;
  double perceptual_objective = 0.0;  // f in L*a*b* of the solution, whatever the method
  Eigen::VectorXd delta_e76, delta_e2000;  // per fine patch
  double mean_delta_e76 = 0.0, max_delta_e76 = 0.0;      // area-weighted mean, max
  double mean_delta_e2000 = 0.0, max_delta_e2000 = 0.0;
};

// Builds the fine and coarse problems (coarse F aggregated from the fine one) and solves. The
// bounds come from `rig` (the projectors) when given, else from the scene's "bounds".
CompensationRun RunCompensation(const GeometryStage& geometry, const SolverOptions& options, double alpha,
                                const ProjectionRig* rig = nullptr);

// result.json content for a run.
nlohmann::json CompensationResultJson(const GeometryStage& geometry, const CompensationRun& run);

// Writes result.json, E.npy, B.npy (and with `export_problem` the whole problem) into `out`.
// `extra` keys (e.g. "rig") are added to result.json.
void WriteCompensation(const GeometryStage& geometry, const CompensationRun& run,
                       const std::filesystem::path& out, bool export_problem,
                       const nlohmann::json& extra = nlohmann::json::object());

}  // namespace procam
