#include "tests/testing/testing.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <thread>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <fstream>
#include <random>

namespace procam::testing {

TempDir::TempDir() {
  std::random_device entropy;
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "procam";
  path_ = std::filesystem::temp_directory_path() / ("procam-" + name + "-" + std::to_string(entropy()));
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ignored;
  std::filesystem::remove_all(path_, ignored);
}

std::filesystem::path TempDir::Write(const std::string& name, const std::string& text) const {
  const std::filesystem::path file = path_ / name;
  std::filesystem::create_directories(file.parent_path());
  std::ofstream(file) << text;
  return file;
}

CommandRun RunShell(const std::string& command) {
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen((command + " 2>&1").c_str(), "r"), pclose);
  CommandRun run;
  if (!pipe) return run;
  std::array<char, 4096> buffer;
  size_t count;
  while ((count = fread(buffer.data(), 1, buffer.size(), pipe.get())) > 0) run.output.append(buffer.data(), count);
  const int status = pclose(pipe.release());
  run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return run;
}

CommandRun RunProcam(const std::string& arguments) {
  const char* binary = std::getenv("PROCAM_BINARY");
  EXPECT_NE(binary, nullptr) << "PROCAM_BINARY is not set (run the test through CTest)";
  return RunShell(std::string(binary ? binary : "procam") + " " + arguments);
}

CommandRun RunProcamStderr(const std::string& arguments) {
  const char* binary = std::getenv("PROCAM_BINARY");
  EXPECT_NE(binary, nullptr) << "PROCAM_BINARY is not set (run the test through CTest)";
  return RunShell("{ " + std::string(binary ? binary : "procam") + " " + arguments +
                  " 2>&1 >/dev/null; }");
}

void ExpectOneErrorLine(const CommandRun& run, const std::string& expected,
                        const std::string& context) {
  EXPECT_EQ(run.exit_code, 1) << context << "\n" << run.output;
  EXPECT_EQ(std::count(run.output.begin(), run.output.end(), '\n'), 1) << context << "\n"
                                                                       << run.output;
  EXPECT_EQ(run.output.rfind("procam: error: ", 0), 0u) << context << "\n" << run.output;
  EXPECT_NE(run.output.find(expected), std::string::npos) << context << "\n" << run.output;
}

SignalledRun SignalProcamWhen(const std::string& arguments, const std::function<bool()>& ready,
                              int signal, double max_seconds, const std::filesystem::path& log) {
  const char* binary = std::getenv("PROCAM_BINARY");
  EXPECT_NE(binary, nullptr) << "PROCAM_BINARY is not set (run the test through CTest)";
  const std::string command = "exec " + std::string(binary ? binary : "procam") + " " +
                              arguments + " >'" + log.string() + "' 2>&1";
  SignalledRun run;
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  EXPECT_GT(pid, 0) << "fork failed";
  if (pid <= 0) return run;
  const auto wait_until = [&](std::chrono::steady_clock::time_point deadline,
                              const std::function<bool()>& until, int* status) {
    while (std::chrono::steady_clock::now() < deadline) {
      if (::waitpid(pid, status, WNOHANG) == pid) return true;  // ended
      if (until && until()) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  };
  const auto seconds = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(max_seconds));
  int status = 0;
  run.running = !wait_until(std::chrono::steady_clock::now() + seconds, ready, &status);
  if (run.running) {
    ::kill(pid, signal);
    if (!wait_until(std::chrono::steady_clock::now() + seconds, nullptr, &status)) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
    }
  }
  run.exited = WIFEXITED(status);
  run.exit_code = run.exited ? WEXITSTATUS(status) : -1;
  run.died_of = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  return run;
}

bool KillProcamWhen(const std::string& arguments, const std::function<bool()>& ready,
                    double max_seconds, const std::filesystem::path& log) {
  const SignalledRun run = SignalProcamWhen(arguments, ready, SIGKILL, max_seconds, log);
  return run.running && run.died_of == SIGKILL;
}

std::filesystem::path SourceDir() {
  const char* dir = std::getenv("PROCAM_SOURCE_DIR");
  return dir ? dir : ".";
}

std::filesystem::path SharedDir() {
  const char* dir = std::getenv("PROCAM_SHARED_DIR");
  return dir ? dir : SourceDir() / ".." / "shared";
}

}  // namespace procam::testing
