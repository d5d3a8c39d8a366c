#pragma once
// File I/O shared by every module: atomic writes and NumPy .npy arrays.
//
// Every file procam writes goes through WriteFileAtomically(): the bytes land in a
// temporary file beside the target, which is then renamed over it, so a reader (or a crash)
// never sees a half-written file and an old file stays intact until the new one is complete.

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace procam {

// Thrown at I/O boundaries (files, devices); the message names the file and what is wrong.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Writes `bytes` to `path` through a temporary file and a rename. Throws IoError.
void WriteFileAtomically(const std::filesystem::path& path, const std::string& bytes);

// Reads a whole file. Throws IoError naming the file.
std::string ReadFile(const std::filesystem::path& path);

// Row-major (C order) matrices as NumPy stores them: one patch per row.
using RowMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using RowMatrixXi64 = Eigen::Matrix<int64_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Writes a float64 array of shape (rows, cols), or (rows,) when `as_vector` is true.
void WriteNpy(const std::filesystem::path& path, const RowMatrixXd& array, bool as_vector = false);
// Writes an int64 array of shape (rows, cols), or (rows,) when `as_vector` is true.
void WriteNpy(const std::filesystem::path& path, const RowMatrixXi64& array,
              bool as_vector = false);

// A .npy array read back: shape (1 or 2 dimensions) and values converted to double.
struct NpyArray {
  std::vector<int64_t> shape;
  std::vector<double> values;  // C order
  bool is_integer = false;
};
// Reads a little-endian float64/int64 .npy file in C order. Throws IoError naming the file.
NpyArray ReadNpy(const std::filesystem::path& path);

}  // namespace procam
