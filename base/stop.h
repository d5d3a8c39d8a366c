#pragma once
// A request to stop, made by a signal (SIGINT from Ctrl+C, SIGTERM from `kill` or a service
// manager; apps/stop_signals.h installs the handlers): one flag for the whole process, as a
// signal is the process's. The commands that stop cleanly read it between their steps (a capture
// between patterns, a show between frames, calibrate all between its stages); the long
// computations inside a step (form factors, the display latency's measurement) read it too and
// end early by throwing Stopped, which the command turns into its clean stop. Nothing sets the
// flag unless a command installed the handlers, so every other caller computes to the end.

#include <atomic>
#include <stdexcept>

namespace procam {

// The process's stop request (a lock-free atomic: a signal handler may set it).
inline std::atomic<bool> g_stop_requested{false};

// True once a stop was requested.
inline bool StopRequested() { return g_stop_requested.load(std::memory_order_relaxed); }

// Thrown by a computation that saw the stop request part-way: its message says what was cut
// short ("form factors: stopped at 40%"). What the computation had made is dropped; what the
// command had written before is kept.
class Stopped : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace procam
