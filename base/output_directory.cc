#include "base/output_directory.h"

#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <nlohmann/json.hpp>
#include <random>
#include <set>

#include "base/io.h"

namespace procam {

namespace fs = std::filesystem;

std::string DirectoryKindName(DirectoryKind kind) {
  switch (kind) {
    case DirectoryKind::kRig: return "a rig directory";
    case DirectoryKind::kCaptureSession: return "a capture session";
    case DirectoryKind::kSolution: return "a solution directory";
    case DirectoryKind::kProjectorImages: return "a projector images directory";
    case DirectoryKind::kVerificationRun: return "a verification run";
    case DirectoryKind::kShow: return "a show's result directory";
  }
  return "a directory";
}

namespace {

// What the result.json manifest of a directory says it is; empty when it says nothing known.
std::optional<DirectoryKind> KindOfResult(const fs::path& path) {
  nlohmann::json result;
  try {
    result = nlohmann::json::parse(ReadFile(path, uintmax_t{1} << 30));
  } catch (const std::exception&) {
    return std::nullopt;  // unreadable: its owner's reader reports it
  }
  if (!result.is_object()) return std::nullopt;
  if (result.value("command", "") == "verify") return DirectoryKind::kVerificationRun;
  if (result.contains("fps_target") && result.contains("frames_shown")) return DirectoryKind::kShow;
  if (result.contains("format_version") && result.contains("method") && result.contains("alpha")) {
    return DirectoryKind::kSolution;
  }
  if (result.contains("solution") && result.contains("projectors") && result.contains("dither")) {
    return DirectoryKind::kProjectorImages;
  }
  for (const char* section : {"camera", "projectors", "photometric", "response", "black_levels"}) {
    if (result.contains(section)) return DirectoryKind::kRig;  // the calibrate commands' report
  }
  return std::nullopt;
}

}  // namespace

std::optional<DirectoryKind> DirectoryKindOf(const fs::path& dir) {
  std::error_code error;
  if (!fs::is_directory(dir, error)) return std::nullopt;
  if (fs::exists(dir / "rig.json", error)) return DirectoryKind::kRig;
  if (fs::exists(dir / "session.json", error)) return DirectoryKind::kCaptureSession;
  if (fs::is_regular_file(dir / "result.json", error)) return KindOfResult(dir / "result.json");
  return std::nullopt;
}

void CheckOutputDirectory(const fs::path& dir, DirectoryKind kind, const std::string& option) {
  std::error_code error;
  if (fs::exists(dir, error) && !fs::is_directory(dir, error)) {
    throw IoError(dir.string() + ": " + option + " must be a directory, and this is a file");
  }
  const std::optional<DirectoryKind> found = DirectoryKindOf(dir);
  if (found && *found != kind) {
    throw IoError(dir.string() + ": " + option + " is " + DirectoryKindName(*found) +
                  ", not " + DirectoryKindName(kind) +
                  "; refusing to write into it (give a new directory)");
  }
}

namespace {

// Staging directories OUT.tmp-PID-N beside `out` whose writer is gone (no process PID here) and
// that are over a minute old: a writer killed before its swap.
void RemoveStaleStaging(const fs::path& out) {
  const std::string prefix = out.filename().string() + ".tmp-";
  std::error_code error;
  const auto now = fs::file_time_type::clock::now();
  for (fs::directory_iterator it(out.parent_path(), error), end; !error && it != end;
       it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (name.compare(0, prefix.size(), prefix) != 0) continue;
    char* digits_end = nullptr;
    const long pid = std::strtol(name.c_str() + prefix.size(), &digits_end, 10);
    if (pid <= 0 || *digits_end != '-') continue;
    if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;
    std::error_code stat_error;
    const auto modified = fs::last_write_time(it->path(), stat_error);
    if (stat_error || now - modified < std::chrono::minutes(1)) continue;
    fs::remove_all(it->path(), stat_error);
  }
}

std::string Reason(const std::error_code& error) { return error.message(); }

}  // namespace

ReplacedDirectory::ReplacedDirectory(const fs::path& out) : out_(out) {
  std::error_code error;
  if (fs::is_symlink(out_, error)) out_ = fs::canonical(out_, error);  // replace what it points at
  if (out_.filename().empty()) out_ = out_.parent_path();                // "DIR/"
  if (fs::exists(out_, error) && !fs::is_directory(out_, error)) {
    throw IoError(out_.string() + ": not a directory");
  }
  const fs::path parent = out_.has_parent_path() ? out_.parent_path() : fs::path(".");
  fs::create_directories(parent, error);
  if (error) throw IoError(parent.string() + ": cannot create directory: " + Reason(error));
  if (out_.parent_path().empty()) out_ = fs::path(".") / out_;
  RemoveStaleStaging(out_);
  std::random_device entropy;
  staging_ = out_.string() + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(entropy());
  if (!fs::create_directory(staging_, error) || error) {
    throw IoError(out_.string() + ": cannot create the directory to write it in beside it (" +
                  staging_.filename().string() + "): " + Reason(error));
  }
}

ReplacedDirectory::~ReplacedDirectory() {
  std::error_code ignored;
  fs::remove_all(staging_, ignored);  // after Commit() it holds the earlier files
}

void ReplacedDirectory::Commit() {
  std::error_code error;
  if (!fs::exists(out_, error)) {
    fs::rename(staging_, out_, error);
    if (error) throw IoError(out_.string() + ": cannot move the new files into place: " + Reason(error));
    committed_ = true;
    return;
  }
  // Files of `out` the new output does not replace are kept: linked (or copied) across.
  for (fs::directory_iterator it(out_, error), end; !error && it != end; it.increment(error)) {
    const fs::path name = it->path().filename();
    if (name.string().find(".tmp-") != std::string::npos) continue;  // a killed writer's
    if (fs::exists(fs::symlink_status(staging_ / name))) continue;
    std::error_code keep_error;
    if (it->is_symlink(keep_error)) {
      fs::copy_symlink(it->path(), staging_ / name, keep_error);
    } else if (it->is_directory(keep_error)) {
      fs::copy(it->path(), staging_ / name,
               fs::copy_options::recursive | fs::copy_options::create_hard_links, keep_error);
    } else {
      fs::create_hard_link(it->path(), staging_ / name, keep_error);
      if (keep_error) fs::copy_file(it->path(), staging_ / name, keep_error);
    }
    if (keep_error) {
      throw IoError(it->path().string() + ": cannot keep it beside the new files: " +
                    Reason(keep_error));
    }
  }
  if (error) throw IoError(out_.string() + ": cannot list it: " + Reason(error));
  if (::renameat2(AT_FDCWD, staging_.c_str(), AT_FDCWD, out_.c_str(), RENAME_EXCHANGE) == 0) {
    committed_ = true;
    return;  // staging_ now holds the earlier files, removed by the destructor
  }
  const int exchange_errno = errno;
  if (exchange_errno != EINVAL && exchange_errno != ENOSYS) {
    throw IoError(out_.string() + ": cannot swap the new files into place: " +
                  std::strerror(exchange_errno));
  }
  // A filesystem without RENAME_EXCHANGE: the earlier directory aside, the new one in, the
  // earlier one where staging was (removed by the destructor).
  std::random_device entropy;
  const fs::path aside =
      out_.string() + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(entropy());
  fs::rename(out_, aside, error);
  if (error) throw IoError(out_.string() + ": cannot move it aside: " + Reason(error));
  fs::rename(staging_, out_, error);
  if (error) {
    std::error_code ignored;
    fs::rename(aside, out_, ignored);
    throw IoError(out_.string() + ": cannot move the new files into place: " + Reason(error));
  }
  staging_ = aside;
  committed_ = true;
}

}  // namespace procam
