#pragma once
// procam's subcommands, one group per file. Each Add*Commands registers its subcommands and
// their callbacks on the app; callbacks throw (IoError, std::invalid_argument, ...) on
// failure, and main turns that into one line on stderr and exit code 1.

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace procam {

void AddSceneCommands(CLI::App& app);         // scene info, scene export
void AddCompensationCommands(CLI::App& app);  // compensate
// project, show, bench projection (joins the bench group: call after AddBenchCommands)
void AddProjectionCommands(CLI::App& app);
void AddBenchCommands(CLI::App& app);         // bench formfactors, bench solver
void AddDemoCommand(CLI::App& app);           // demo
void AddEvaluationCommands(CLI::App& app);    // evaluate
void AddCaptureCommands(CLI::App& app);       // cameras, capture
void AddStructuredLightCommands(CLI::App& app);  // import, decode, patterns
void AddVerifyCommand(CLI::App& app);         // verify
void AddEmulateCommand(CLI::App& app);        // emulate (the room as a GigE camera)
void AddNodeCommands(CLI::App& app);          // keys, node, play (display nodes)
void AddCalibrateCommands(CLI::App& app);     // calibrate camera, photometric, ...
void AddCalibrateResponseCommand(CLI::App& calibrate);  // calibrate response (the group)
void AddCalibrateAllCommand(CLI::App& calibrate);       // calibrate all (the group)
void AddCalibrateProjectorsCommand(CLI::App& calibrate);  // calibrate projectors (the group)
void AddOptionsCommand(CLI::App& app);                    // options (the declared option tables)
// The option tables at their defaults as docs/options.md holds them (procam options --markdown).
std::string DeclaredOptionsMarkdown();

}  // namespace procam
