#pragma once
// A clean stop on SIGINT (Ctrl+C) and SIGTERM (a service manager, `kill`): the long-running
// commands (node, play, capture, emulate) end the step in hand, release what they hold (sockets,
// windows, the camera's stream), keep what they made, say so in one line and exit 0.

#include <atomic>

namespace procam {

// Installs handlers for SIGINT and SIGTERM that set the returned flag (once set, it stays set);
// the command's loop reads it. Calling it again returns the same flag.
std::atomic<bool>& StopOnSignals();

}  // namespace procam
