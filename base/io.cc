#include "base/io.h"

#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
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

void WriteFileAtomically(const std::filesystem::path& path, const std::string& bytes) {
  std::random_device entropy;
  const std::filesystem::path temp =
      path.string() + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(entropy());
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    if (!out) throw IoError(temp.string() + ": cannot create file: " + std::strerror(errno));
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.flush();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(temp, ignored);
      throw IoError(path.string() + ": write failed (disk full?)");
    }
  }
  std::error_code error;
  std::filesystem::rename(temp, path, error);
  if (error) {
    std::filesystem::remove(temp, error);
    throw IoError(path.string() + ": cannot replace file: " + error.message());
  }
}

std::string ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path.string() + ": cannot open file");
  std::ostringstream contents;
  contents << in.rdbuf();
  return contents.str();
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
  const size_t header_length =
      static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8);
  if (bytes.size() < 10 + header_length) throw fail("truncated header");
  const std::string header = bytes.substr(10, header_length);
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
  int64_t count = 1;
  while (std::getline(shape, item, ',')) {
    if (item.find_first_not_of(' ') == std::string::npos) continue;
    array.shape.push_back(std::stoll(item));
    count *= array.shape.back();
  }
  const size_t data_offset = 10 + header_length;
  if (bytes.size() != data_offset + 8 * static_cast<size_t>(count)) throw fail("size mismatch");
  array.values.resize(static_cast<size_t>(count));
  for (int64_t k = 0; k < count; ++k) {
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
