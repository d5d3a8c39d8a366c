#pragma once
// A virtual X server (Xvfb) for the tests of the GLFW backend: started once per test binary as a
// gtest environment; tests skip (SKIP_WITHOUT_XVFB) where it cannot be started.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

extern char** environ;

namespace procam::testing {

// Starts Xvfb (one screen of width × height) on the first free display from :87 and points
// DISPLAY at it for the whole binary.
class XvfbEnvironment : public ::testing::Environment {
 public:
  XvfbEnvironment(int width, int height) : width_(width), height_(height) {}
  void SetUp() override {
    for (int display = 87; display < 127; ++display) {
      if (std::filesystem::exists("/tmp/.X" + std::to_string(display) + "-lock")) continue;
      std::string name = ":";
      name += std::to_string(display);
      const std::string screen = std::to_string(width_) + "x" + std::to_string(height_) + "x24";
      // -noreset: the server would otherwise restart (and refuse connections for a moment)
      // each time the last client leaves.
      std::array<const char*, 9> argv = {"Xvfb", name.c_str(),   "-screen",
                                         "0",    screen.c_str(), "-nolisten",
                                         "tcp",  "-noreset",     nullptr};
      posix_spawn_file_actions_t actions;
      posix_spawn_file_actions_init(&actions);
      posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
      posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, "/dev/null", O_WRONLY, 0);
      const int failed = posix_spawnp(&pid_, "Xvfb", &actions, nullptr,
                                      const_cast<char* const*>(argv.data()), environ);
      posix_spawn_file_actions_destroy(&actions);
      if (failed != 0) {
        pid_ = 0;
        why_ = "Xvfb could not be started (apt-get install xvfb)";
        return;
      }
      const std::string socket = "/tmp/.X11-unix/X" + std::to_string(display);
      for (int wait = 0; wait < 200 && !std::filesystem::exists(socket); ++wait) {
        std::this_thread::sleep_for(std::chrono::milliseconds(25));
        int status = 0;
        if (waitpid(pid_, &status, WNOHANG) ==
            pid_) {  // exited: display taken meanwhile, try the next
          pid_ = 0;
          break;
        }
      }
      if (pid_ != 0 && std::filesystem::exists(socket)) {
        setenv("DISPLAY", name.c_str(), 1);
        why_.clear();
        return;
      }
      Stop();
    }
    why_ = "no free X display number for Xvfb";
  }
  void TearDown() override { Stop(); }
  static const std::string& why() { return why_; }

 private:
  void Stop() {
    if (pid_ == 0) return;
    kill(pid_, SIGTERM);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = 0;
  }
  int width_, height_;
  pid_t pid_ = 0;
  static inline std::string why_ = "Xvfb not started";
};

#define SKIP_WITHOUT_XVFB()                               \
  if (!::procam::testing::XvfbEnvironment::why().empty()) \
  GTEST_SKIP() << ::procam::testing::XvfbEnvironment::why()

}  // namespace procam::testing
