#include "tests/testing/testing.h"

#include <cstdlib>
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
  std::ofstream(file) << text;
  return file;
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
