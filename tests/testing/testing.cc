#include "tests/testing/testing.h"

#include <sys/wait.h>

#include <array>
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

std::filesystem::path SourceDir() {
  const char* dir = std::getenv("PROCAM_SOURCE_DIR");
  return dir ? dir : ".";
}

std::filesystem::path SharedDir() {
  const char* dir = std::getenv("PROCAM_SHARED_DIR");
  return dir ? dir : SourceDir() / ".." / "shared";
}

}  // namespace procam::testing
