#pragma once
// The directories procam's commands write, and writing one whole.
//
// Each command that writes a directory writes one kind (a rig, a capture session, a solution,
// projector images, a verification run, a show's timings, a scene). Pointed by --out at a
// directory of another kind, it refuses before anything is written, so that a slip of the
// command line never replaces a rig's calibration record or a solution (docs/faults.md).
//
// A command whose directory is replaced as a whole (a solution, projector images) writes its
// files into a staging directory beside it and swaps the two at the end (ReplacedDirectory), so
// that the directory holds the earlier files or the new ones, never a mix.

#include <filesystem>
#include <optional>
#include <string>

namespace procam {

enum class DirectoryKind {
  kRig,              // rig.json, models, result.json with the calibrate commands' sections
  kCaptureSession,   // session.json and frames/ (procam capture)
  kSolution,         // result.json with format_version and method, E.npy, B.npy (compensate)
  kProjectorImages,  // result.json naming the solution and projectors, NAME.png (project)
  kVerificationRun,  // result.json with "command": "verify", iterations/ (verify)
  kShow,             // result.json with the frames shown (play)
};

// "a rig directory", "a solution directory", ... for messages.
std::string DirectoryKindName(DirectoryKind kind);

// What `dir` holds, told by its files (rig.json; session.json; result.json's keys). Empty when
// `dir` does not exist, is not a directory, or holds none of procam's manifests (an empty
// directory, or one whose manifest was removed by a rewrite cut short).
std::optional<DirectoryKind> DirectoryKindOf(const std::filesystem::path& dir);

// Throws IoError naming `dir` (given by `option`, e.g. "--out") when it holds another kind's
// files, or when it is a file. Nothing is written.
void CheckOutputDirectory(const std::filesystem::path& dir, DirectoryKind kind,
                          const std::string& option = "--out");

// A directory replaced whole. The constructor creates a staging directory beside `out`
// (OUT.tmp-PID-N, removing those of writers no longer running, as WriteFileAtomically does for
// files); the command writes its files into staging(); Commit() moves the files of `out` the new
// output does not replace into it (hard links) and swaps it into place in one rename
// (renameat2's RENAME_EXCHANGE; where the filesystem lacks it, two renames). Destroyed without
// Commit() — an exception part-way — the staging directory is removed and `out` is as it was.
// Throws IoError naming `out`.
class ReplacedDirectory {
 public:
  explicit ReplacedDirectory(const std::filesystem::path& out);
  ~ReplacedDirectory();
  ReplacedDirectory(const ReplacedDirectory&) = delete;
  ReplacedDirectory& operator=(const ReplacedDirectory&) = delete;

  const std::filesystem::path& staging() const { return staging_; }
  void Commit();

 private:
  std::filesystem::path out_, staging_;
  bool committed_ = false;
};

}  // namespace procam
