#include "fuzz/fuzz_input.h"

#include <unistd.h>

#include <cstdlib>
#include <fstream>

namespace procam {
namespace fs = std::filesystem;

namespace {

void RemoveFuzzDirectory() {
  std::error_code ignored;
  fs::remove_all(FuzzDirectory(), ignored);
}

}  // namespace

const fs::path& FuzzDirectory() {
  static const fs::path directory = [] {
    fs::path dir = fs::temp_directory_path() / ("procam-fuzz-" + std::to_string(getpid()));
    fs::create_directories(dir);
    std::atexit(RemoveFuzzDirectory);
    return dir;
  }();
  return directory;
}

fs::path WriteFuzzInput(const uint8_t* data, size_t size, const std::string& name) {
  const fs::path path = FuzzDirectory() / name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  if (!out) std::abort();  // the harness itself failed: not a finding about procam
  return path;
}

void CopyIntoFuzzDirectory(const std::string& repository_file, const std::string& name) {
  const fs::path source = fs::path(PROCAM_SOURCE_DIR) / repository_file;
  const fs::path target = FuzzDirectory() / (name.empty() ? source.filename() : fs::path(name));
  fs::copy_file(source, target, fs::copy_options::overwrite_existing);
}

}  // namespace procam
