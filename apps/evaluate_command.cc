// procam evaluate: the paper's Table 1 on the synthetic world (datasets_synthetic/evaluation.h),
// its options as EvaluationOptions declares them.
#include <iostream>
#include <memory>

#include "apps/command_line.h"
#include "apps/commands.h"
#include "datasets_synthetic/evaluation.h"

namespace procam {

void AddEvaluationCommands(CLI::App& app) {
  CLI::App* cmd = app.add_subcommand(
      "evaluate", "Table 1 of the paper on synthetic scenes: per-pixel ΔE of naive, reverse, linear, perceptual, perceptual2000");
  const auto evaluation = AddDeclaredOptions<EvaluationOptions>(cmd);
  cmd->callback([evaluation] { std::cout << RunEvaluation(*evaluation); });
}

}  // namespace procam
