#pragma once
// A clean stop on SIGINT (Ctrl+C) and SIGTERM (a service manager, `kill`): the long-running
// commands (node, play, capture, emulate) end the step in hand, release what they hold (sockets,
// windows, the camera's stream), keep what they made, say so in one line and exit 0. calibrate
// all and verify, whose output is of use only once they finish, stop the same way: their line
// says where they stopped and how to resume, and what they wrote says it is not complete (no
// rig.json; verify's result.json `complete: false`), so a script tells a stop by that, not by
// the exit status.

#include <atomic>

namespace procam {

// Exit status of a command stopped by a signal before its work was done (calibrate all,
// verify): a clean stop, as for every other command, not an error (1) nor the shell's 128+N of
// a process killed by signal N.
constexpr int kStoppedExitCode = 0;

// Installs handlers for SIGINT and SIGTERM that set the process's stop request
// (base/stop.h: StopRequested) and returns it (once set, it stays set); the command's loop reads
// it. Calling it again returns the same flag.
std::atomic<bool>& StopOnSignals();

}  // namespace procam
