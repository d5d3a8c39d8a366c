#include "base/io.h"

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "base/output_directory.h"
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

// A failed create names the file asked for, not its temporary name.
// What a writer killed before its rename left (NAME.tmp-PID-N) goes with the next write of NAME
// once its process is gone and it is over a minute old; a live writer's and a fresh one stay.
TEST(AtomicWrite, NextWriteRemovesTemporariesOfDeadWriters) {
  testing::TempDir dir;
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);  // `child` names no process now
  const std::filesystem::path target = dir.path() / "result.json";
  const std::string dead = "result.json.tmp-" + std::to_string(child) + "-7";
  const std::string fresh = "result.json.tmp-" + std::to_string(child) + "-8";
  const std::string live = "result.json.tmp-" + std::to_string(::getpid()) + "-9";
  const std::string other = "report.html.tmp-" + std::to_string(child) + "-7";
  for (const std::string& name : {dead, fresh, live, other}) dir.Write(name, "half a file");
  const auto old = std::filesystem::file_time_type::clock::now() - std::chrono::minutes(5);
  for (const std::string& name : {dead, live, other}) std::filesystem::last_write_time(dir.path() / name, old);
  WriteFileAtomically(target, "{}");
  EXPECT_EQ(ReadFile(target), "{}");
  EXPECT_FALSE(std::filesystem::exists(dir.path() / dead));
  EXPECT_TRUE(std::filesystem::exists(dir.path() / fresh)) << "under a minute old";
  EXPECT_TRUE(std::filesystem::exists(dir.path() / live)) << "its writer is alive";
  EXPECT_TRUE(std::filesystem::exists(dir.path() / other)) << "another file's";
}

TEST(AtomicWrite, ErrorsNameTheTarget) {
  testing::TempDir dir;
  try {
    WriteFileAtomically(dir / "missing" / "x.txt", "new");
    ADD_FAILURE() << "no error";
  } catch (const IoError& error) {
    EXPECT_EQ(std::string(error.what()).rfind((dir / "missing" / "x.txt").string() + ": ", 0), 0u)
        << error.what();
    EXPECT_EQ(std::string(error.what()).find(".tmp-"), std::string::npos) << error.what();
  }
}

// A rename that fails (the target a directory that is not empty) is reported with its own
// error, not the cleanup's ("cannot replace file: Success").
TEST(AtomicWrite, AFailedRenameNamesItsOwnError) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "B.npy" / "inner");
  try {
    WriteFileAtomically(dir / "B.npy", "new");
    ADD_FAILURE() << "no error";
  } catch (const IoError& error) {
    const std::string what = error.what();
    EXPECT_NE(what.find("B.npy: cannot replace file: "), std::string::npos) << what;
    EXPECT_EQ(what.find("Success"), std::string::npos) << what;
    EXPECT_TRUE(what.find("directory") != std::string::npos) << what;  // EISDIR or ENOTEMPTY
  }
  size_t entries = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) entries += !entry.path().empty();
  EXPECT_EQ(entries, 1u);  // no temporary left
}

// ReplacedDirectory: the directory holds the earlier files or the new ones, never a mix; files
// the new output does not write are kept; nothing is left beside it.
TEST(ReplacedDirectory, SwapsWholeOrLeavesTheEarlierFiles) {
  testing::TempDir dir;
  const std::filesystem::path out = dir / "solution";
  std::filesystem::create_directories(out);
  WriteFileAtomically(out / "E.npy", "old E");
  WriteFileAtomically(out / "result.json", "old result");
  WriteFileAtomically(out / "notes.txt", "the user's");
  try {
    ReplacedDirectory replaced(out);
    WriteFileAtomically(replaced.staging() / "E.npy", "new E");
    throw IoError("B.npy: write failed");  // stopped part-way
  } catch (const IoError&) {
  }
  EXPECT_EQ(ReadFile(out / "E.npy"), "old E");
  EXPECT_EQ(ReadFile(out / "result.json"), "old result");
  {
    ReplacedDirectory replaced(out);
    WriteFileAtomically(replaced.staging() / "E.npy", "new E");
    WriteFileAtomically(replaced.staging() / "result.json", "new result");
    replaced.Commit();
  }
  EXPECT_EQ(ReadFile(out / "E.npy"), "new E");
  EXPECT_EQ(ReadFile(out / "result.json"), "new result");
  EXPECT_EQ(ReadFile(out / "notes.txt"), "the user's");
  {
    ReplacedDirectory replaced(dir / "fresh");
    WriteFileAtomically(replaced.staging() / "E.npy", "first");
    replaced.Commit();
  }
  EXPECT_EQ(ReadFile(dir / "fresh" / "E.npy"), "first");
  std::vector<std::string> beside;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    beside.push_back(entry.path().filename().string());
  }
  std::sort(beside.begin(), beside.end());
  EXPECT_EQ(beside, (std::vector<std::string>{"fresh", "solution"}));
}

// Each kind is told by its manifest; --out of another kind is refused naming both.
TEST(OutputDirectory, AnotherKindIsRefused) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "rig");
  WriteFileAtomically(dir / "rig" / "rig.json", "{}");
  std::filesystem::create_directories(dir / "solution");
  WriteFileAtomically(dir / "solution" / "result.json",
                      R"({"format_version": 1, "method": "perceptual", "alpha": 0.5})");
  EXPECT_EQ(DirectoryKindOf(dir / "rig"), DirectoryKind::kRig);
  EXPECT_EQ(DirectoryKindOf(dir / "solution"), DirectoryKind::kSolution);
  EXPECT_EQ(DirectoryKindOf(dir / "none"), std::nullopt);
  CheckOutputDirectory(dir / "solution", DirectoryKind::kSolution);
  CheckOutputDirectory(dir / "none", DirectoryKind::kSolution);
  try {
    CheckOutputDirectory(dir / "rig", DirectoryKind::kSolution);
    ADD_FAILURE() << "no error";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("rig: --out is a rig directory, not a solution directory"),
              std::string::npos)
        << error.what();
  }
}

// The manifest goes first: missing is fine, what cannot be removed is an error naming it.
TEST(RemoveManifest, RemovesOrNamesWhatItCannotRemove) {
  testing::TempDir dir;
  WriteFileAtomically(dir / "result.json", "{}");
  RemoveManifest(dir / "result.json");
  EXPECT_FALSE(std::filesystem::exists(dir / "result.json"));
  RemoveManifest(dir / "result.json");
  std::filesystem::create_directories(dir / "busy.json" / "inner");  // not removable
  try {
    RemoveManifest(dir / "busy.json");
    ADD_FAILURE() << "no error";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("busy.json: cannot remove"), std::string::npos)
        << error.what();
  }
}

TEST(Npy, RejectsGarbage) {
  testing::TempDir dir;
  const auto path = dir.Write("bad.npy", "not numpy at all");
  EXPECT_THROW(ReadNpy(path), IoError);
  EXPECT_THROW(ReadNpy(dir / "absent.npy"), IoError);
}

// The header length is 2 bytes in format 1.x and 4 in 2.x and 3.x; any other version is refused
// by name rather than read as if it were 1.0.
TEST(Npy, ReadsFormatTwoAndRefusesUnknownVersions) {
  testing::TempDir dir;
  RowMatrixXd values(1, 2);
  values << 1.5, -2.0;
  WriteNpy(dir / "a.npy", values);
  const std::string v1 = ReadFile(dir / "a.npy");
  std::string v2 = v1.substr(0, 6) + std::string("\x02\x00", 2) + v1.substr(8, 2) +
                   std::string(2, '\0') + v1.substr(10);
  EXPECT_EQ(ReadNpy(dir.Write("v2.npy", v2)).values, std::vector<double>({1.5, -2.0}));
  for (const char version : {'\x00', '\x04', '\x7f'}) {
    std::string unknown = v1;
    unknown[6] = version;
    try {
      ReadNpy(dir.Write("v.npy", unknown));
      ADD_FAILURE() << "accepted version " << int(version);
    } catch (const IoError& error) {
      EXPECT_NE(std::string(error.what()).find("v.npy: unknown .npy format version"),
                std::string::npos)
          << error.what();
    }
  }
  std::string huge_shape = v1;
  huge_shape.replace(huge_shape.find("(1, 2)"), 6, "(9999999999999, 9)");
  EXPECT_THROW(ReadNpy(dir.Write("h.npy", huge_shape)), IoError);
}

// Files that are not regular files (a FIFO would block, /dev/zero never ends) and files over the
// reader's limit are refused before anything is read.
TEST(ReadFile, RefusesWhatIsNotARegularFileOrTooLarge) {
  testing::TempDir dir;
  ASSERT_EQ(::mkfifo((dir / "fifo").c_str(), 0600), 0);
  std::filesystem::create_symlink("/dev/zero", dir / "zero");
  for (const char* name : {"fifo", "zero"}) {
    try {
      ReadFile(dir / name);
      ADD_FAILURE() << name;
    } catch (const IoError& error) {
      EXPECT_NE(std::string(error.what()).find(name + std::string(": not a regular file")),
                std::string::npos)
          << error.what();
    }
  }
  std::filesystem::create_directories(dir / "directory");
  EXPECT_THROW(ReadFile(dir / "directory"), IoError);
  const auto small = dir.Write("small.txt", "0123456789");
  EXPECT_EQ(ReadFile(small, 10), "0123456789");
  EXPECT_THROW(ReadFile(small, 9), IoError);
}

TEST(ReadFile, NamesALoopOfLinksAndADanglingLinkForWhatTheyAre) {
  testing::TempDir dir;
  std::filesystem::create_symlink(dir / "b", dir / "a");
  std::filesystem::create_symlink(dir / "a", dir / "b");
  std::filesystem::create_symlink(dir / "gone", dir / "dangling");
  const auto message = [](const std::filesystem::path& path) {
    try {
      ReadFile(path);
    } catch (const IoError& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  // The system's own wording of ELOOP, not "file not found".
  EXPECT_EQ(message(dir / "a"), (dir / "a").string() + ": " + std::make_error_code(std::errc::too_many_symbolic_link_levels).message());
  EXPECT_EQ(message(dir / "dangling"), (dir / "dangling").string() + ": a symbolic link to a file that does not exist");
  EXPECT_EQ(message(dir / "absent"), (dir / "absent").string() + ": file not found");
}

}  // namespace
}  // namespace procam
