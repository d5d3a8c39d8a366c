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
#include <string_view>
#include <vector>

#include <Eigen/Core>

namespace procam {

// Thrown at I/O boundaries (files, devices); the message names the file and what is wrong.
class IoError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Writes `bytes` to `path` through a temporary file and a rename. Throws IoError naming
// `path` (a full disk, a read-only directory); the temporary file is removed on failure. A
// process killed mid-write leaves only its temporary file, `NAME.tmp-PID-N`, which no reader
// opens and which the next write of `path` removes (once no process PID exists here and the
// file is over a minute old). The file is created with permissions `mode` less the umask (0600
// for a secret: never readable by others, at no moment).
void WriteFileAtomically(const std::filesystem::path& path, const std::string& bytes,
                         unsigned mode = 0666);

// Removes the manifest of a multi-file output (a solution's or an images directory's
// result.json) before its files are replaced: the manifest is written last, so a directory
// whose rewrite stopped part-way (killed, disk full) has none and no later command trusts a mix
// of old and new files. Missing is fine; throws IoError naming `path` when it cannot be removed.
void RemoveManifest(const std::filesystem::path& path);

// The largest file ReadFile reads unless told otherwise: 16 GiB (a dense F of 45k patches).
constexpr uintmax_t kMaxFileBytes = uintmax_t{16} << 30;

// Checks that `path` names a regular file (after symbolic links) of at most `max_bytes`, so a
// FIFO, a device such as /dev/zero or a directory is refused before anything blocks on it or
// reads without end. Throws IoError naming the file: not found, not a regular file, too large.
void CheckRegularFile(const std::filesystem::path& path, uintmax_t max_bytes = kMaxFileBytes);

// Reads a whole regular file of at most `max_bytes` (CheckRegularFile). Throws IoError naming
// the file.
std::string ReadFile(const std::filesystem::path& path, uintmax_t max_bytes = kMaxFileBytes);

// FNV-1a (64 bits) of `bytes` as 16 hex digits: identifies a file's contents in manifests, so a
// file changed or truncated after it was written is noticed (a fault check, not a security one).
std::string ContentChecksum(std::string_view bytes);

// While one exists, what libraries print on the process's stderr (file descriptor 2: libmrcal's
// parser, libpng's and OpenCV's decoders) goes nowhere, so that procam reports a failure in its
// own one line. One at a time (the descriptor is process-wide); keep the scope to one call.
class SilencedStderr {
 public:
  SilencedStderr();
  ~SilencedStderr();
  SilencedStderr(const SilencedStderr&) = delete;
  SilencedStderr& operator=(const SilencedStderr&) = delete;

 private:
  int saved_ = -1;
};

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
