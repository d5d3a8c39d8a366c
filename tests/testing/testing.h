#pragma once
// Shared test utilities: temporary directories, paths to test data, Eigen comparisons.

#include <filesystem>
#include <functional>
#include <string>

#include <Eigen/Core>
#include <gtest/gtest.h>

namespace procam::testing {

// A fresh directory under the system temp dir, removed when the object goes away.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }
  // Writes `text` to a file in the directory and returns its path.
  std::filesystem::path Write(const std::string& name, const std::string& text) const;

 private:
  std::filesystem::path path_;
};

// The repository root and the team's shared/ folder (from CTest's environment).
std::filesystem::path SourceDir();
std::filesystem::path SharedDir();

// A shell command's exit code and its stdout and stderr together.
struct CommandRun {
  int exit_code = -1;
  std::string output;
};
// Runs `command` through the shell (stderr joined to stdout).
CommandRun RunShell(const std::string& command);
// Runs the procam binary CTest names in PROCAM_BINARY with `arguments`, as a user would.
CommandRun RunProcam(const std::string& arguments);
// The same, keeping only what procam writes on stderr (its logs on stdout are dropped): for
// checking that an error is one line and nothing else.
CommandRun RunProcamStderr(const std::string& arguments);

// Expects a refusal: exit code 1 and exactly one line, procam's "procam: error: ...",
// containing `expected` (`context` is printed on failure).
void ExpectOneErrorLine(const CommandRun& run, const std::string& expected,
                        const std::string& context);

// Starts procam with `arguments` (its output to `log`), polls `ready` every 10 ms for at most
// `max_seconds`, and once it holds (or the time is up) sends SIGKILL, as a crash or a pulled
// plug would. Returns true if procam was still running when killed (false: it had ended).
bool KillProcamWhen(const std::string& arguments, const std::function<bool()>& ready,
                    double max_seconds, const std::filesystem::path& log);

// How a process sent a signal ended.
struct SignalledRun {
  bool running = false;  // procam was still running when the signal was sent
  bool exited = false;   // it then exited by itself (exit_code), rather than died of a signal
  int exit_code = -1;
  int died_of = 0;  // the signal that ended it, when !exited (SIGKILL: it did not end in time)
};

// Starts procam with `arguments` (its output to `log`), polls `ready` every 10 ms for at most
// `max_seconds`, then sends `signal` (SIGTERM, SIGINT) and waits at most `max_seconds` for it to
// end, then SIGKILLs it.
SignalledRun SignalProcamWhen(const std::string& arguments, const std::function<bool()>& ready,
                              int signal, double max_seconds, const std::filesystem::path& log);

// Max-norm distance of two matrices, for EXPECT_LT(MaxAbsDifference(a, b), tol).
template <typename A, typename B>
double MaxAbsDifference(const Eigen::MatrixBase<A>& a, const Eigen::MatrixBase<B>& b) {
  return (a - b).cwiseAbs().maxCoeff();
}

}  // namespace procam::testing
