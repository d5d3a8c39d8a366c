#pragma once
// What every libFuzzer target of fuzz/ shares: the input written where the reader under test
// expects a file, and refusals told apart from bugs.
//
// Most of procam's readers take paths, so a target writes libFuzzer's bytes to a file in a
// directory of its own process (/tmp/procam-fuzz-PID, removed at exit) and calls the real reader.
// A refusal is an exception derived from std::exception (IoError, nlohmann's, OpenCV's): the
// documented behaviour for bad input. A crash, abort, hang, leak or sanitizer report is a bug.

#include <cstddef>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <string>

namespace procam {

// This process's scratch directory, created on first use and removed at exit.
const std::filesystem::path& FuzzDirectory();

// Writes the fuzz input to FuzzDirectory()/name (replacing it) and returns its path.
std::filesystem::path WriteFuzzInput(const uint8_t* data, size_t size, const std::string& name);

// Copies a file of the repository (relative to its root, e.g. "data/scenes/column.obj") into
// FuzzDirectory() as `name` (its own name when empty), for inputs that name other files.
void CopyIntoFuzzDirectory(const std::string& repository_file, const std::string& name = "");

// Runs `read`, taking a std::exception as the refusal it documents; anything else propagates.
template <typename Read>
void ReadOrRefuse(Read&& read) {
  try {
    read();
  } catch (const std::exception&) {
  }
}

}  // namespace procam
