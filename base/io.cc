#include "base/io.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <mutex>
#include <random>
#include <sstream>

namespace procam {
namespace {

std::string ShapeString(int64_t rows, int64_t cols, bool as_vector) {
  std::ostringstream shape;
  shape << '(' << rows << ',';
  if (!as_vector) shape << ' ' << cols;
  shape << ')';
  return shape.str();
}

// NumPy format 1.0: magic, version, little-endian header length, a Python dict literal padded
// with spaces and ended by '\n' so that the data starts on a 64-byte boundary.
std::string NpyHeader(const char* descr, const std::string& shape) {
  std::string dict = std::string("{'descr': '") + descr +
                     "', 'fortran_order': False, 'shape': " + shape + ", }";
  const size_t preamble = 10;
  size_t total = preamble + dict.size() + 1;
  const size_t padded = (total + 63) / 64 * 64;
  dict.append(padded - total, ' ');
  dict.push_back('\n');
  std::string header("\x93NUMPY\x01\x00", 8);
  const uint16_t length = static_cast<uint16_t>(dict.size());
  header.push_back(static_cast<char>(length & 0xff));
  header.push_back(static_cast<char>(length >> 8));
  return header + dict;
}

template <typename Scalar>
std::string NpyBytes(const char* descr, const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic,
                                                             Eigen::RowMajor>& array,
                     bool as_vector) {
  std::string bytes = NpyHeader(
      descr, as_vector ? ShapeString(array.size(), 1, true) : ShapeString(array.rows(), array.cols(), false));
  const size_t offset = bytes.size();
  bytes.resize(offset + sizeof(Scalar) * static_cast<size_t>(array.size()));
  if (array.size() > 0) std::memcpy(bytes.data() + offset, array.data(), bytes.size() - offset);
  return bytes;
}

}  // namespace

namespace {

// Removes what a writer killed between creating and renaming its temporary file left beside
// `path`: PATH.tmp-PID-N whose process is gone (no such PID here) and that is over a minute old
// (so that a writer on another machine sharing the directory is never disturbed).
void RemoveStaleTemporaries(const std::filesystem::path& path) {
  const std::string prefix = path.filename().string() + ".tmp-";
  const std::filesystem::path directory = path.has_parent_path() ? path.parent_path() : ".";
  std::error_code error;
  const auto now = std::filesystem::file_time_type::clock::now();
  for (std::filesystem::directory_iterator it(directory, error), end; !error && it != end; it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    char* digits_end = nullptr;
    const long pid = std::strtol(name.c_str() + prefix.size(), &digits_end, 10);
    if (pid <= 0 || *digits_end != '-') continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // alive, or not ours to ask
    std::error_code stat_error;
    const auto modified = std::filesystem::last_write_time(it->path(), stat_error);
    if (stat_error || now - modified < std::chrono::minutes(1)) continue;
    std::filesystem::remove(it->path(), stat_error);
  }
}

}  // namespace

void WriteFileAtomically(const std::filesystem::path& path, const std::string& bytes,
                         unsigned mode) {
  std::random_device entropy;
  const std::filesystem::path temp =
      path.string() + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(entropy());
  {
    // Created with `mode` (less the umask) from the start: a secret is never readable by others,
    // not even between its creation and a chmod.
    const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC,
                          static_cast<mode_t>(mode));
    if (fd < 0) throw IoError(path.string() + ": cannot create file: " + std::strerror(errno));
    size_t written = 0;
    int write_errno = 0;
    while (written < bytes.size()) {
      const ssize_t count = ::write(fd, bytes.data() + written, bytes.size() - written);
      if (count < 0 && errno == EINTR) continue;
      if (count <= 0) {
        write_errno = count < 0 ? errno : ENOSPC;
        break;
      }
      written += static_cast<size_t>(count);
    }
    if (::close(fd) != 0 && write_errno == 0) write_errno = errno;
    if (write_errno != 0) {
      std::error_code ignored;
      std::filesystem::remove(temp, ignored);
      throw IoError(path.string() + ": write failed: " + std::strerror(write_errno));
    }
  }
  std::error_code error;
  std::filesystem::rename(temp, path, error);
  if (error) {
    std::error_code ignored;  // the rename's error is the one to report
    std::filesystem::remove(temp, ignored);
    throw IoError(path.string() + ": cannot replace file: " + error.message());
  }
  RemoveStaleTemporaries(path);
}

void RemoveManifest(const std::filesystem::path& path) {
  std::error_code error;
  std::filesystem::remove(path, error);
  if (error) throw IoError(path.string() + ": cannot remove the old manifest: " + error.message());
}

void CheckRegularFile(const std::filesystem::path& path, uintmax_t max_bytes) {
  std::error_code error;
  const std::filesystem::file_status status = std::filesystem::status(path, error);
  // A loop of symbolic links, a directory that may not be searched: the system's reason, not
  // "not found".
  if (error && error != std::errc::no_such_file_or_directory) throw IoError(path.string() + ": " + error.message());
  if (!std::filesystem::exists(status)) {
    if (std::filesystem::is_symlink(std::filesystem::symlink_status(path, error))) {
      throw IoError(path.string() + ": a symbolic link to a file that does not exist");
    }
    throw IoError(path.string() + ": file not found");
  }
  if (!std::filesystem::is_regular_file(status)) {
    throw IoError(path.string() + ": not a regular file (a directory, device, FIFO or socket)");
  }
  const uintmax_t bytes = std::filesystem::file_size(path, error);
  if (error) throw IoError(path.string() + ": cannot read its size: " + error.message());
  if (bytes > max_bytes) {
    throw IoError(path.string() + ": too large (" + std::to_string(bytes) + " bytes, at most " +
                  std::to_string(max_bytes) + ")");
  }
}

std::string ReadFile(const std::filesystem::path& path, uintmax_t max_bytes) {
  CheckRegularFile(path, max_bytes);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string() + ": cannot open file");
  // One read into a string of the file's size: a stream's growing buffer, then its copy, moved
  // every byte of a large file several times over (42 photos of a megapixel per session).
  std::error_code error;
  const uintmax_t expected = std::filesystem::file_size(path, error);
  std::string contents(error ? 0 : static_cast<size_t>(expected), '\0');
  in.read(contents.data(), static_cast<std::streamsize>(contents.size()));
  contents.resize(static_cast<size_t>(in.gcount()));
  if (in) {  // whatever the file gained since its size was read
    std::ostringstream rest;
    rest << in.rdbuf();
    contents += rest.str();
  }
  return contents;
}

std::string ContentChecksum(std::string_view bytes) {
  uint64_t hash = 1469598103934665603ull;
  for (const char byte : bytes) {
    hash ^= static_cast<uint8_t>(byte);
    hash *= 1099511628211ull;
  }
  char text[17];
  std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(hash));
  return text;
}

namespace {
std::mutex stderr_mutex;  // SilencedStderr: one at a time
}  // namespace

SilencedStderr::SilencedStderr() {
  stderr_mutex.lock();
  std::fflush(stderr);
  const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  if (null < 0) return;
  saved_ = ::dup(STDERR_FILENO);
  if (saved_ >= 0) ::dup2(null, STDERR_FILENO);
  ::close(null);
}

SilencedStderr::~SilencedStderr() {
  std::fflush(stderr);
  if (saved_ >= 0) {
    ::dup2(saved_, STDERR_FILENO);
    ::close(saved_);
  }
  stderr_mutex.unlock();
}

void WriteNpy(const std::filesystem::path& path, const RowMatrixXd& array, bool as_vector) {
  WriteFileAtomically(path, NpyBytes("<f8", array, as_vector));
}

void WriteNpy(const std::filesystem::path& path, const RowMatrixXi64& array, bool as_vector) {
  WriteFileAtomically(path, NpyBytes("<i8", array, as_vector));
}

NpyArray ReadNpy(const std::filesystem::path& path) {
  const std::string bytes = ReadFile(path);
  auto fail = [&](const std::string& why) { return IoError(path.string() + ": " + why); };
  if (bytes.size() < 10 || bytes.compare(0, 6, "\x93NUMPY") != 0) throw fail("not a .npy file");
  // Format 1.x stores the header length in 2 bytes, 2.x and 3.x in 4; no other version exists.
  const int major = static_cast<unsigned char>(bytes[6]);
  if (major < 1 || major > 3) {
    throw fail("unknown .npy format version " + std::to_string(major) + "." +
               std::to_string(static_cast<unsigned char>(bytes[7])));
  }
  const size_t length_bytes = major == 1 ? 2 : 4;
  if (bytes.size() < 8 + length_bytes) throw fail("truncated header");
  size_t header_length = 0;
  for (size_t k = 0; k < length_bytes; ++k) {
    header_length |= static_cast<size_t>(static_cast<unsigned char>(bytes[8 + k])) << (8 * k);
  }
  const size_t header_start = 8 + length_bytes;
  if (bytes.size() < header_start + header_length) throw fail("truncated header");
  const std::string header = bytes.substr(header_start, header_length);
  NpyArray array;
  if (header.find("'<f8'") != std::string::npos) {
    array.is_integer = false;
  } else if (header.find("'<i8'") != std::string::npos) {
    array.is_integer = true;
  } else {
    throw fail("only little-endian float64 and int64 arrays are supported");
  }
  if (header.find("'fortran_order': False") == std::string::npos) throw fail("not in C order");
  const size_t open = header.find("'shape': (");
  const size_t close = header.find(')', open);
  if (open == std::string::npos || close == std::string::npos) throw fail("no shape in header");
  std::stringstream shape(header.substr(open + 10, close - open - 10));
  std::string item;
  size_t count = 1;
  const size_t max_count = bytes.size() / 8;
  while (std::getline(shape, item, ',')) {
    if (item.find_first_not_of(' ') == std::string::npos) continue;
    char* end = nullptr;
    const long long extent = std::strtoll(item.c_str(), &end, 10);
    if (end == item.c_str() ||
        item.find_first_not_of(' ', end - item.c_str()) != std::string::npos || extent < 0 ||
        (extent > 0 && count > max_count / static_cast<size_t>(extent))) {
      throw fail("shape: '" + item + "' is not a dimension that fits the file");
    }
    array.shape.push_back(extent);
    count *= static_cast<size_t>(extent);
  }
  if (array.shape.empty() || array.shape.size() > 2)
    throw fail("shape: must have 1 or 2 dimensions");
  const size_t data_offset = header_start + header_length;
  if (bytes.size() != data_offset + 8 * count) throw fail("size mismatch");
  array.values.resize(count);
  for (size_t k = 0; k < count; ++k) {
    const char* at = bytes.data() + data_offset + 8 * k;
    if (array.is_integer) {
      int64_t value;
      std::memcpy(&value, at, 8);
      array.values[k] = static_cast<double>(value);
    } else {
      std::memcpy(&array.values[k], at, 8);
    }
  }
  return array;
}

}  // namespace procam
