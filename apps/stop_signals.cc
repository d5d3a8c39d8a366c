#include "apps/stop_signals.h"

#include <csignal>

#include "base/stop.h"

namespace procam {
namespace {

// Only a lock-free atomic store: what a signal handler may do.
void OnStopSignal(int) { g_stop_requested.store(true); }

}  // namespace

std::atomic<bool>& StopOnSignals() {
  static_assert(std::atomic<bool>::is_always_lock_free);
  std::signal(SIGINT, OnStopSignal);
  std::signal(SIGTERM, OnStopSignal);
  return g_stop_requested;
}

}  // namespace procam
