#include "base/io.h"

#include <gtest/gtest.h>

#include "tests/testing/testing.h"

namespace procam {
namespace {

TEST(Npy, FloatRoundTripKeepsShapeAndValues) {
  testing::TempDir dir;
  RowMatrixXd array(3, 2);
  array << 1.5, -2.0, 3.25, 1e-300, -0.0, 7.0;
  WriteNpy(dir / "a.npy", array);
  const NpyArray back = ReadNpy(dir / "a.npy");
  EXPECT_EQ(back.shape, (std::vector<int64_t>{3, 2}));
  EXPECT_FALSE(back.is_integer);
  for (int k = 0; k < 6; ++k) EXPECT_EQ(back.values[k], array.data()[k]);
  // NumPy's format: data starts on a 64-byte boundary after a '\n'-terminated header.
  const std::string bytes = ReadFile(dir / "a.npy");
  EXPECT_EQ(bytes.size() % 64, 48u % 64);  // 6 doubles after a 64-byte-aligned header
  EXPECT_EQ(bytes.substr(0, 6), std::string("\x93NUMPY"));
}

TEST(Npy, IntegerVectorRoundTrip) {
  testing::TempDir dir;
  RowMatrixXi64 array(4, 1);
  array << 0, 5, -3, 1234567890123;
  WriteNpy(dir / "i.npy", array, /*as_vector=*/true);
  const NpyArray back = ReadNpy(dir / "i.npy");
  EXPECT_EQ(back.shape, (std::vector<int64_t>{4}));
  EXPECT_TRUE(back.is_integer);
  EXPECT_EQ(back.values[3], 1234567890123.0);
  EXPECT_NE(ReadFile(dir / "i.npy").find("'shape': (4,)"), std::string::npos);
}

TEST(AtomicWrite, FailureLeavesTheOldFileAndNoTemporaries) {
  testing::TempDir dir;
  WriteFileAtomically(dir / "keep.txt", "old");
  EXPECT_THROW(WriteFileAtomically(dir / "missing" / "x.txt", "new"), IoError);
  // Replacing a directory with a file fails; the directory and its content stay.
  std::filesystem::create_directory(dir / "sub");
  WriteFileAtomically(dir / "sub" / "inner.txt", "inner");
  EXPECT_THROW(WriteFileAtomically(dir / "sub", "clobber"), IoError);
  EXPECT_EQ(ReadFile(dir / "sub" / "inner.txt"), "inner");
  EXPECT_EQ(ReadFile(dir / "keep.txt"), "old");
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    (void)entry;
    ++files;
  }
  EXPECT_EQ(files, 2);  // keep.txt and sub: no temporaries left behind
}

TEST(Npy, RejectsGarbage) {
  testing::TempDir dir;
  const auto path = dir.Write("bad.npy", "not numpy at all");
  EXPECT_THROW(ReadNpy(path), IoError);
  EXPECT_THROW(ReadNpy(dir / "absent.npy"), IoError);
}

}  // namespace
}  // namespace procam
