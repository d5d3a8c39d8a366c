#pragma once
// procam's subcommands, one group per file. Each Add*Commands registers its subcommands and
// their callbacks on the app; callbacks throw (IoError, std::invalid_argument, ...) on
// failure, and main turns that into one line on stderr and exit code 1.

#include <CLI/CLI.hpp>

namespace procam {

void AddSceneCommands(CLI::App& app);         // scene info, scene export
void AddCompensationCommands(CLI::App& app);  // compensate
void AddBenchCommands(CLI::App& app);         // bench formfactors, bench solver
void AddDemoCommand(CLI::App& app);           // demo

}  // namespace procam
