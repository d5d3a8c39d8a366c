// Faults through the procam binary, on the synthetic rig (the `synthetic:tiny_box` camera and
// its simulated projectors): a command killed with SIGKILL part-way and run again, output to a
// full filesystem and to a read-only one, a camera that stalls, and files cut short by a crash.
// Each ends with one line naming what failed, a non-zero exit, and nothing already written lost;
// a command run again after a kill resumes or redoes and ends as an uninterrupted run would
// (docs/faults.md, "Faults").
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <set>
#include <sstream>
#include <string>

#include "apps/stop_signals.h"
#include "base/image_io.h"
#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

namespace fs = std::filesystem;
using testing::CommandRun;

// The simulated rig's camera, fast (500 fps, 1 ms exposures) and a little noisy.
const std::string kCamera =
    "'synthetic:tiny_box?patches=150&fps=500&exposure_us=1000&reference_exposure_us=1000"
    "&black=8&noise=1";
const std::string kCapture = " --frames 2 --settle-ms 1 ";
const std::string kScene = "synthetic:tiny_box --patches 150";
constexpr double kMaxSeconds = 120;  // bound on any one wait for a command to reach a point

bool IsTemporary(const fs::path& path) {
  return path.filename().string().find(".tmp-") != std::string::npos;
}

// The regular files under `dir`, relative to it, sorted; temporary files (a killed writer's
// `NAME.tmp-PID-N`, which no reader opens) apart.
std::set<std::string> FilesUnder(const fs::path& dir, bool temporary = false) {
  std::set<std::string> files;
  if (!fs::exists(dir)) return files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file() && IsTemporary(entry.path()) == temporary) {
      files.insert(fs::relative(entry.path(), dir).string());
    }
  }
  return files;
}

size_t CountFiles(const fs::path& dir) { return FilesUnder(dir).size(); }

// Every .npy, .png and .json file under `dir` reads whole: nothing is half-written.
void ExpectEveryFileReads(const fs::path& dir) {
  for (const std::string& name : FilesUnder(dir)) {
    const fs::path path = dir / name;
    const std::string extension = path.extension().string();
    try {
      if (extension == ".npy") ReadNpy(path);
      if (extension == ".png") ReadImage(path, cv::IMREAD_UNCHANGED);
      if (extension == ".json") {
        EXPECT_FALSE(nlohmann::json::parse(ReadFile(path)).is_discarded()) << name;
      }
    } catch (const std::exception& error) {
      ADD_FAILURE() << name << ": " << error.what();
    }
  }
}

std::string Bytes(const fs::path& path) { return ReadFile(path); }

// The largest difference between two .npy arrays of one shape.
double NpyDifference(const fs::path& a, const fs::path& b) {
  const NpyArray x = ReadNpy(a), y = ReadNpy(b);
  EXPECT_EQ(x.shape, y.shape) << a << " " << b;
  if (x.values.size() != y.values.size()) return 1e300;
  double largest = 0;
  for (size_t i = 0; i < x.values.size(); ++i) {
    largest = std::max(largest, std::abs(x.values[i] - y.values[i]));
  }
  return largest;
}

// Cuts `path` to half its length, as a crash of a writer that wrote in place would.
void Truncate(const fs::path& path) { fs::resize_file(path, fs::file_size(path) / 2); }

// Runs `arguments` as a child, SIGKILLs it once `ready` holds (or after kMaxSeconds), and
// returns the same command run again to its end.
CommandRun KillThenRunAgain(const std::string& arguments, const std::function<bool()>& ready,
                            const testing::TempDir& dir) {
  const bool killed = testing::KillProcamWhen(arguments, ready, kMaxSeconds, dir / "killed.log");
  EXPECT_TRUE(killed) << arguments << " ended before it was killed\n" << Bytes(dir / "killed.log");
  return testing::RunProcam(arguments);
}

// Seconds `arguments` takes uninterrupted; expects it to succeed.
double TimedRun(const std::string& arguments) {
  const auto start = std::chrono::steady_clock::now();
  const CommandRun run = testing::RunProcam(arguments);
  EXPECT_EQ(run.exit_code, 0) << arguments << "\n" << run.output;
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::function<bool()> After(double seconds) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  return [deadline] { return std::chrono::steady_clock::now() >= deadline; };
}

// compensate on the synthetic box with `rig` into `out`; expects it to succeed.
void Compensate(const fs::path& rig, const fs::path& out) {
  ASSERT_GT(TimedRun("compensate " + kScene + " --rig " + rig.string() + " --out " + out.string()),
            0);
}

// One rig for the suite, made by `calibrate all` killed part-way (during the last projector's
// flat fields) and run again: the test of that fault checks what these runs left.
class Faults : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir;
    const std::string calibrate =
        "calibrate all --camera " + kCamera + "'" + kCapture + "--out " + Rig().string();
    const fs::path last = Rig() / "captures" / "photometric_right" / "frames";
    killed_ = testing::KillProcamWhen(
        calibrate, [last] { return CountFiles(last) >= 4; }, 4 * kMaxSeconds,
        *dir_ / "calibrate_killed.log");
    rerun_ = new CommandRun(testing::RunProcam(calibrate));
  }
  static void TearDownTestSuite() {
    delete rerun_;
    delete dir_;
  }
  static fs::path Rig() { return *dir_ / "rig"; }

  // verify of the rig and `solution` through the synthetic camera, two iterations, into dir/`out`.
  std::string VerifyCommand(const std::string& solution, const std::string& out) const {
    return "verify " + Rig().string() + " " + solution + " --camera " + kCamera + "'" + kCapture +
           "--iterations 2 --out " + (dir / out).string();
  }

  // A copy of the rig's files (not its captures) in `to`.
  static fs::path CopyRig(const fs::path& to) {
    fs::create_directories(to);
    for (const auto& entry : fs::directory_iterator(Rig())) {
      if (entry.is_regular_file()) fs::copy_file(entry.path(), to / entry.path().filename());
    }
    return to;
  }

  static testing::TempDir* dir_;
  static bool killed_;
  static CommandRun* rerun_;
  testing::TempDir dir;
};

testing::TempDir* Faults::dir_ = nullptr;
bool Faults::killed_ = false;
CommandRun* Faults::rerun_ = nullptr;

TEST_F(Faults, KillNineDuringCalibrateAllThenRunAgain) {
  EXPECT_TRUE(killed_) << Bytes(*dir_ / "calibrate_killed.log");
  ASSERT_EQ(rerun_->exit_code, 0) << rerun_->output;
  // The captures finished before the kill are kept, the one cut short resumes.
  EXPECT_NE(rerun_->output.find("(0 this run, "), std::string::npos) << rerun_->output;
  EXPECT_EQ(rerun_->output.find("(25 this run, 0 already there)"), std::string::npos)
      << rerun_->output;
  for (const char* name : {"rig.json", "camera.cameramodel", "left.cameramodel",
                           "right.cameramodel", "reflectance.npy", "result.json"}) {
    EXPECT_TRUE(fs::exists(Rig() / name)) << name;
  }
  ExpectEveryFileReads(Rig());
}

TEST_F(Faults, KillNineDuringCaptureThenRunAgain) {
  const auto command = [&](const std::string& out) {
    return "capture --camera " + kCamera + "'" + kCapture +
           "--projector 0 --sequence photometric --levels 0,128,255 --channels rgb --out " +
           (dir / out).string();
  };
  ASSERT_GT(TimedRun(command("clean")), 0);
  const CommandRun resumed = KillThenRunAgain(
      command("flat"), [&] { return CountFiles(dir / "flat" / "frames") >= 2; }, dir);
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("7/7 patterns captured"), std::string::npos) << resumed.output;
  EXPECT_EQ(resumed.output.find(" 0 already there"), std::string::npos) << resumed.output;
  EXPECT_EQ(FilesUnder(dir / "flat"), FilesUnder(dir / "clean"));
  ExpectEveryFileReads(dir / "flat");
}

// compensate is killed while rewriting a solution: the directory is then either the old
// solution, the new one, or has no result.json (removed first, written last), so `project`
// either uses a whole solution or refuses with one line; run again, it redoes the solve.
TEST_F(Faults, KillNineDuringCompensateThenRunAgain) {
  const auto command = [&](const std::string& out) {
    return "compensate " + kScene + " --rig " + Rig().string() + " --out " + (dir / out).string();
  };
  const double seconds = TimedRun(command("clean"));
  ASSERT_GT(TimedRun(command("solution")), 0);  // the earlier solution the kill interrupts
  ASSERT_TRUE(testing::KillProcamWhen(command("solution"), After(0.5 * seconds), kMaxSeconds,
                                      dir / "killed.log"));
  const CommandRun project =
      testing::RunProcamStderr("project " + (dir / "solution").string() + " --rig " +
                               Rig().string() + " --out " + (dir / "images").string());
  if (project.exit_code != 0) testing::ExpectOneErrorLine(project, "result.json", "project");
  const CommandRun again = testing::RunProcam(command("solution"));
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(FilesUnder(dir / "solution"), FilesUnder(dir / "clean"));
  ExpectEveryFileReads(dir / "solution");
  EXPECT_LT(NpyDifference(dir / "solution" / "E.npy", dir / "clean" / "E.npy"), 1e-9);
}

TEST_F(Faults, KillNineDuringProjectThenRunAgain) {
  const std::string solution = (dir / "solution").string();
  Compensate(Rig(), solution);
  const auto command = [&](const std::string& out) {
    return "project " + solution + " --rig " + Rig().string() + " --out " + (dir / out).string();
  };
  const double seconds = TimedRun(command("clean"));
  const CommandRun again = KillThenRunAgain(command("images"), After(0.5 * seconds), dir);
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(FilesUnder(dir / "images"), FilesUnder(dir / "clean"));
  ExpectEveryFileReads(dir / "images");
  for (const char* image : {"left.png", "right.png"}) {
    EXPECT_EQ(Bytes(dir / "images" / image), Bytes(dir / "clean" / image)) << image;
  }
}

// verify is killed during its second iteration; run again it resumes (the photo sessions'
// frames are kept) and ends with the files of an uninterrupted run.
TEST_F(Faults, KillNineDuringVerifyThenRunAgain) {
  const std::string solution = (dir / "solution").string();
  Compensate(Rig(), solution);
  ASSERT_GT(TimedRun(VerifyCommand(solution, "clean")), 0);
  const fs::path second = dir / "verify" / "iterations" / "1" / "session" / "frames";
  const CommandRun again = KillThenRunAgain(
      VerifyCommand(solution, "verify"), [&] { return CountFiles(second) >= 1; }, dir);
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(FilesUnder(dir / "verify"), FilesUnder(dir / "clean"));
  ExpectEveryFileReads(dir / "verify");
  const nlohmann::json result = nlohmann::json::parse(Bytes(dir / "verify" / "result.json"));
  EXPECT_TRUE(result.at("complete").get<bool>()) << result.dump(2);
}

// Runs `script` (sh) in a new user and mount namespace, where `mount` is allowed; false (and
// the reason in `why`) where this system does not allow such namespaces.
bool RunInMountNamespace(const std::string& script, std::string* why) {
  const CommandRun probe = testing::RunShell("unshare -rm true");
  if (probe.exit_code != 0) {
    *why = "unshare -rm (user and mount namespaces) is not available: " + probe.output;
    return false;
  }
  const CommandRun run = testing::RunShell("unshare -rm sh -c '" + script + "'");
  EXPECT_EQ(run.exit_code, 0) << script << "\n" << run.output;
  return true;
}

// The procam binary and its stderr only, its exit code appended to `log_dir`/exit.
std::string ProcamInScript(const std::string& arguments, const fs::path& log_dir) {
  return "{ " + std::string(std::getenv("PROCAM_BINARY")) + " " + arguments + " 2>" +
         (log_dir / "stderr").string() + " >/dev/null; echo $? >" + (log_dir / "exit").string() +
         "; }";
}

CommandRun ScriptRun(const fs::path& log_dir) {
  CommandRun run;
  run.exit_code = std::stoi(Bytes(log_dir / "exit"));
  run.output = Bytes(log_dir / "stderr");
  return run;
}

// An earlier solution in a 64 KiB tmpfs, then compensate --export (a 160 KiB F.npy) into the
// same filesystem: one line naming the file that did not fit, exit 1, the earlier solution
// untouched, no temporary file left.
TEST_F(Faults, FullFilesystemIsOneLineAndKeepsWhatWasWritten) {
  const std::string solution = (dir / "solution").string();
  Compensate(Rig(), solution);
  const fs::path mount = dir / "small", after = dir / "after";
  fs::create_directories(mount);
  const std::string script = "mount -t tmpfs -o size=64k tmpfs " + mount.string() + " && cp -r " +
                             solution + " " + (mount / "old").string() + " && " +
                             ProcamInScript("compensate " + kScene + " --rig " + Rig().string() +
                                                " --export --out " + (mount / "new").string(),
                                            dir.path()) +
                             " && cp -r " + mount.string() + " " + after.string();
  std::string why;
  if (!RunInMountNamespace(script, &why)) GTEST_SKIP() << why;
  testing::ExpectOneErrorLine(ScriptRun(dir.path()), (mount / "new").string(), "compensate");
  EXPECT_NE(ScriptRun(dir.path()).output.find("No space left on device"), std::string::npos);
  for (const std::string& name : FilesUnder(solution)) {
    EXPECT_EQ(Bytes(after / "old" / name), Bytes(fs::path(solution) / name)) << name;
  }
  EXPECT_EQ(FilesUnder(after, /*temporary=*/true).size(), 0u);
  EXPECT_FALSE(fs::exists(after / "new" / "result.json"));  // no solution to trust
}

// A solution on a read-only filesystem (as root, mode 0555 would not stop a write): compensate
// over it and project beside it are one line each naming the path, exit 1, and it is unchanged.
TEST_F(Faults, ReadOnlyDirectoryIsOneLineAndKeepsWhatWasWritten) {
  const std::string solution = (dir / "solution").string();
  Compensate(Rig(), solution);
  const fs::path mount = dir / "readonly", after = dir / "after";
  const fs::path compensate_log = dir / "compensate", project_log = dir / "project";
  for (const fs::path& d : {mount, compensate_log, project_log}) fs::create_directories(d);
  const std::string script =
      "mount -t tmpfs tmpfs " + mount.string() + " && cp -r " + solution + " " +
      (mount / "solution").string() + " && mount -o remount,ro " + mount.string() + " && " +
      ProcamInScript("compensate " + kScene + " --rig " + Rig().string() + " --out " +
                         (mount / "solution").string(),
                     compensate_log) +
      " && " +
      ProcamInScript("project " + (mount / "solution").string() + " --rig " + Rig().string() +
                         " --out " + (mount / "images").string(),
                     project_log) +
      " && cp -r " + mount.string() + " " + after.string();
  std::string why;
  if (!RunInMountNamespace(script, &why)) GTEST_SKIP() << why;
  testing::ExpectOneErrorLine(ScriptRun(compensate_log), (mount / "solution").string(),
                              "compensate");
  testing::ExpectOneErrorLine(ScriptRun(project_log), (mount / "images").string(), "project");
  EXPECT_NE(ScriptRun(project_log).output.find("Read-only file system"), std::string::npos);
  EXPECT_EQ(FilesUnder(after / "solution"), FilesUnder(solution));
  for (const std::string& name : FilesUnder(solution)) {
    EXPECT_EQ(Bytes(after / "solution" / name), Bytes(fs::path(solution) / name)) << name;
  }
}

// The same stall in calibrate all, with its own --timeout-ms: one line naming the camera, in
// bounded time, the captured frames kept for a rerun.
TEST_F(Faults, StalledCameraEndsCalibrateAllWithOneLine) {
  const fs::path rig = dir / "stalled_rig";
  const auto start = std::chrono::steady_clock::now();
  const CommandRun stalled = testing::RunProcamStderr("calibrate all --camera " + kCamera +
                                                      "&fault=timeout&fault_after=30'" + kCapture +
                                                      "--timeout-ms 50 --out " + rig.string());
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  testing::ExpectOneErrorLine(stalled, "camera 'synthetic:tiny_box'", "stalled in calibrate all");
  // --timeout-ms reached the grabs: 50 ms plus the 1 ms exposure.
  EXPECT_NE(stalled.output.find("no frame within 51 ms"), std::string::npos) << stalled.output;
  EXPECT_LT(seconds, kMaxSeconds);
  EXPECT_TRUE(fs::exists(rig / "captures" / "structured_light_left" / "session.json"));
  ExpectEveryFileReads(rig);
}

// A camera that stalls: after some frames it delivers nothing and reports nothing, so every
// grab waits its --timeout-ms (the synthetic camera's fault=timeout, for ever). verify ends with
// one line naming the camera, exit 1, the photos it took kept; run again with a camera that
// answers, it resumes and completes.
TEST_F(Faults, StalledCameraEndsVerifyWithOneLineAndItResumes) {
  const std::string solution = (dir / "solution").string();
  Compensate(Rig(), solution);
  const std::string verify =
      "verify " + Rig().string() + " " + solution + kCapture +
      "--iterations 2 --timeout-ms 50 --retries 1 --retry-delay-ms 0 --out " +
      (dir / "verify").string() + " --camera " + kCamera;
  const CommandRun stalled = testing::RunProcamStderr(verify + "&fault=timeout&fault_after=2'");
  testing::ExpectOneErrorLine(stalled, "camera 'synthetic:tiny_box'", "stalled");
  const std::set<std::string> kept = FilesUnder(dir / "verify");
  EXPECT_GT(kept.size(), 0u);
  ExpectEveryFileReads(dir / "verify");
  const CommandRun resumed = testing::RunProcam(verify + "'");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  const std::set<std::string> now = FilesUnder(dir / "verify");
  EXPECT_TRUE(std::includes(now.begin(), now.end(), kept.begin(), kept.end()));
  const nlohmann::json result = nlohmann::json::parse(Bytes(dir / "verify" / "result.json"));
  EXPECT_TRUE(result.at("complete").get<bool>());
}

// Files cut short by a crash of whatever wrote them: a solution's E.npy and a rig's
// reflectance.npy are refused by the next command in one line naming them, with nothing
// written; a session's frame PNG is captured again on resume (as a frame of junk is).
TEST_F(Faults, TruncatedFilesAreNamedOrCapturedAgain) {
  const fs::path solution = dir / "solution";
  Compensate(Rig(), solution);
  Truncate(solution / "E.npy");
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr("project " + solution.string() + " --rig " + Rig().string() +
                               " --out " + (dir / "images").string()),
      "E.npy", "project");
  EXPECT_FALSE(fs::exists(dir / "images"));

  const fs::path rig = CopyRig(dir / "rig");
  Truncate(rig / "reflectance.npy");
  testing::ExpectOneErrorLine(
      testing::RunProcamStderr("compensate " + kScene + " --rig " + rig.string() + " --out " +
                               (dir / "other").string()),
      "reflectance.npy", "compensate");
  EXPECT_FALSE(fs::exists(dir / "other"));

  const std::string capture = "capture --camera " + kCamera + "'" + kCapture +
                              "--projector 0 --sequence photometric --levels 0,255 "
                              "--channels rgb --out " +
                              (dir / "flat").string();
  ASSERT_GT(TimedRun(capture), 0);
  const nlohmann::json manifest = nlohmann::json::parse(Bytes(dir / "flat" / "session.json"));
  const fs::path frame =
      dir / "flat" / manifest["patterns"][1]["captured"]["exposures"][0]["file"].get<std::string>();
  Truncate(frame);
  const CommandRun resumed = testing::RunProcam(capture);
  EXPECT_EQ(resumed.exit_code, 0) << resumed.output;
  EXPECT_NE(resumed.output.find("(1 this run, 3 already there)"), std::string::npos)
      << resumed.output;
  ExpectEveryFileReads(dir / "flat");
}


// Every regular file under `dir` (captures apart) and its bytes: what a refused command must
// leave as it was.
std::map<std::string, std::string> Contents(const fs::path& dir) {
  std::map<std::string, std::string> contents;
  for (const std::string& name : FilesUnder(dir)) {
    if (name.rfind("captures/", 0) != 0) contents[name] = Bytes(dir / name);
  }
  return contents;
}

// --out pointed at a directory another command wrote: each command that writes a directory
// refuses one of another kind in one line naming it, before anything is written.
TEST_F(Faults, OutputDirectoryOfAnotherKindIsRefusedAndKept) {
  const fs::path solution = dir / "solution", images = dir / "images";
  Compensate(Rig(), solution);
  ASSERT_EQ(testing::RunProcam("project " + solution.string() + " --rig " + Rig().string() +
                               " --out " + images.string())
                .exit_code,
            0);
  const auto rig_before = Contents(Rig());
  const auto solution_before = Contents(solution);
  const auto images_before = Contents(images);
  const std::string rig = Rig().string(), sol = solution.string();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"project " + sol + " --rig " + rig + " --out " + sol, "is a solution directory"},
      {"project " + sol + " --rig " + rig + " --out " + rig, "is a rig directory"},
      {"compensate " + kScene + " --rig " + rig + " --out " + rig, "is a rig directory"},
      {"compensate " + kScene + " --rig " + rig + " --out " + images.string(),
       "is a projector images directory"},
      {"verify " + rig + " " + sol + " --camera " + kCamera + "'" + kCapture + "--out " + sol,
       "is a solution directory"},
      {"play " + kScene + " --rig " + rig + " --solution " + sol + " --out " + rig,
       "is a rig directory"},
      {"calibrate all --camera " + kCamera + "'" + kCapture + "--out " + sol,
       "is a solution directory"},
      {"capture --camera test:loopback --sequence photometric --out " + rig, "is a rig directory"},
  };
  for (const auto& [arguments, expected] : cases) {
    testing::ExpectOneErrorLine(testing::RunProcamStderr(arguments), expected, arguments);
  }
  EXPECT_EQ(Contents(Rig()), rig_before);
  EXPECT_EQ(Contents(solution), solution_before);
  EXPECT_EQ(Contents(images), images_before);
}

// A rewrite that fails part-way (compensate --export into a 64 KiB tmpfs holding the earlier
// solution: F.npy does not fit) leaves the earlier solution whole, result.json included: the new
// files are written beside it and swapped in only when all are written.
TEST_F(Faults, ARewriteThatFailsPartWayKeepsTheEarlierSolutionWhole) {
  const std::string solution = (dir / "solution").string();
  Compensate(Rig(), solution);
  const fs::path mount = dir / "small", after = dir / "after";
  fs::create_directories(mount);
  const std::string script = "mount -t tmpfs -o size=64k tmpfs " + mount.string() + " && cp -r " +
                             solution + " " + (mount / "old").string() + " && " +
                             ProcamInScript("compensate " + kScene + " --rig " + Rig().string() +
                                                " --export --out " + (mount / "old").string(),
                                            dir.path()) +
                             " && cp -r " + mount.string() + " " + after.string();
  std::string why;
  if (!RunInMountNamespace(script, &why)) GTEST_SKIP() << why;
  testing::ExpectOneErrorLine(ScriptRun(dir.path()), (mount / "old").string(), "compensate");
  EXPECT_NE(ScriptRun(dir.path()).output.find("No space left on device"), std::string::npos);
  EXPECT_EQ(Contents(after / "old"), Contents(solution));
  for (const auto& entry : fs::directory_iterator(after)) {  // no staging directory left
    EXPECT_EQ(entry.path().filename().string().find(".tmp-"), std::string::npos) << entry.path();
  }
}

// A solution made with a relative --rig is used with that rig from any working directory, not
// with whatever ./rig is there.
TEST_F(Faults, ASolutionFindsItsRigFromAnotherDirectory) {
  CopyRig(dir / "made" / "rig");
  fs::create_directories(dir / "elsewhere" / "rig");
  dir.Write("elsewhere/rig/rig.json", "{\"format_version\": 1}");  // another, unusable, rig
  const CommandRun made = testing::RunShell(
      "cd " + (dir / "made").string() + " && " + std::getenv("PROCAM_BINARY") + " compensate " +
      kScene + " --rig rig --out solution");
  ASSERT_EQ(made.exit_code, 0) << made.output;
  const CommandRun project = testing::RunShell(
      "cd " + (dir / "elsewhere").string() + " && " + std::getenv("PROCAM_BINARY") + " project " +
      (dir / "made" / "solution").string() + " --out images");
  ASSERT_EQ(project.exit_code, 0) << project.output;
  const nlohmann::json result =
      nlohmann::json::parse(Bytes(dir / "elsewhere" / "images" / "result.json"));
  EXPECT_EQ(fs::path(result.at("rig").at("dir").get<std::string>()), dir / "made" / "rig");
}

// play --desired: a video without frames, a FIFO named like an image, an image whose header
// states 30000x30000 pixels: one line naming it, before anything is shown, the earlier
// result.json kept.
TEST_F(Faults, DesiredFramesThatCannotBeShownAreRefusedUpFront) {
  const fs::path out = dir / "show";
  const std::string earlier = R"({"fps_target": 30, "frames_shown": 3})";
  dir.Write("show/result.json", earlier);
  const auto play = [&](const fs::path& desired) {
    return "play " + kScene + " --rig " + Rig().string() + " --desired " + desired.string() +
           " --display memory,memory --out " + out.string();
  };
  const fs::path video = dir / "empty.avi";
  {
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 30,
                           cv::Size(64, 48));
    ASSERT_TRUE(writer.isOpened());
  }  // closed with no frame
  testing::ExpectOneErrorLine(testing::RunProcamStderr(play(video)), video.string(), "empty video");
  // Junk named like a video: the decoders' own lines (GStreamer, FFmpeg) are not shown.
  std::string junk(4096, '\0');
  for (size_t k = 0; k < junk.size(); ++k) junk[k] = static_cast<char>((k * 2654435761u) >> 13);
  const fs::path junk_video = dir.Write("junk.mp4", junk);
  testing::ExpectOneErrorLine(testing::RunProcamStderr(play(junk_video)), junk_video.string(),
                              "junk video");
  fs::create_directories(dir / "fifo");
  ASSERT_EQ(::mkfifo((dir / "fifo" / "a.png").c_str(), 0600), 0);
  testing::ExpectOneErrorLine(testing::RunProcamStderr(play(dir / "fifo")), "a.png", "FIFO");
  fs::create_directories(dir / "huge");
  fs::copy_file(testing::SourceDir() / "fuzz/regressions/image/png_header_30000x30000.png",
                dir / "huge" / "a.png");
  const CommandRun huge = testing::RunProcamStderr(play(dir / "huge"));
  testing::ExpectOneErrorLine(huge, "a.png", "huge frame");
  EXPECT_NE(huge.output.find("30000x30000"), std::string::npos) << huge.output;
  EXPECT_EQ(Bytes(out / "result.json"), earlier);
}

// What can be checked of a rig's parts against each other cheaply is, in one line: two
// projectors given one model, the camera's model given for a projector, a rig.json whose
// registration puts the camera elsewhere than its model does.
TEST_F(Faults, InconsistentRigsAreRefusedInOneLine) {
  const nlohmann::json good = nlohmann::json::parse(Bytes(Rig() / "rig.json"));
  const std::vector<std::pair<std::function<void(nlohmann::json&)>, std::string>> cases = {
      {[](nlohmann::json& rig) { rig["projectors"][1]["model"] = rig["projectors"][0]["model"]; },
       "projectors[1].model: the same file as projectors[0].model"},
      {[](nlohmann::json& rig) { rig["projectors"][0]["model"] = rig["camera"]["model"]; },
       "is the camera's model"},
      {[](nlohmann::json& rig) {
         rig["registration"]["camera_centre_m"][0] =
             rig["registration"]["camera_centre_m"][0].get<double>() + 0.5;
       },
       "registration.camera_centre_m"},
      // Two projectors' models swapped: each file is its own, and not the camera's.
      {[](nlohmann::json& rig) {
         const nlohmann::json left = rig["projectors"][0]["model"];
         rig["projectors"][0]["model"] = rig["projectors"][1]["model"];
         rig["projectors"][1]["model"] = left;
       },
       "centre_m): the model of another projector"},
  };
  for (const auto& [edit, expected] : cases) {
    const fs::path rig = dir / "rig";
    fs::remove_all(rig);
    CopyRig(rig);
    nlohmann::json edited = good;
    edit(edited);
    dir.Write("rig/rig.json", edited.dump(2));
    testing::ExpectOneErrorLine(
        testing::RunProcamStderr("compensate " + kScene + " --rig " + rig.string() + " --out " +
                                 (dir / "solution").string()),
        expected, expected);
    EXPECT_FALSE(fs::exists(dir / "solution")) << expected;
  }
}

// The room the rig was registered in, changed since: a wall moved 0.5 m along its normal, or
// flipped (its corners in the other order), is refused in one line naming the surface, before
// the form factors; the room as it was is accepted.
TEST_F(Faults, ARoomChangedSinceTheCalibrationIsRefusedInOneLine) {
  const nlohmann::json rig = nlohmann::json::parse(Bytes(Rig() / "rig.json"));
  ASSERT_TRUE(rig.at("registration").contains("room")) << rig.at("registration").dump();
  ASSERT_EQ(testing::RunProcam("scene write tiny_box --out " + (dir / "room").string()).exit_code,
            0);
  const fs::path scene = dir / "room" / "tiny_box.json";
  const nlohmann::json room = nlohmann::json::parse(Bytes(scene));
  const auto compensate = [&] {
    return "compensate " + scene.string() + " --patches 150 --rig " + Rig().string() + " --out " +
           (dir / "solution").string();
  };
  const CommandRun same = testing::RunProcam(compensate());
  ASSERT_EQ(same.exit_code, 0) << same.output;
  fs::remove_all(dir / "solution");
  int wall = -1;
  for (size_t s = 0; s < room.at("surfaces").size() && wall < 0; ++s)
    if (room["surfaces"][s].contains("quad")) wall = static_cast<int>(s);
  ASSERT_GE(wall, 0);
  const std::string name = room["surfaces"][wall]["name"];
  const std::vector<std::pair<std::function<void(nlohmann::json&)>, std::string>> cases = {
      {[&](nlohmann::json& quad) {  // moved 0.5 m along its normal
         Eigen::Vector3d c[4];
         for (int k = 0; k < 4; ++k)
           for (int i = 0; i < 3; ++i) c[k][i] = quad[k][i].get<double>();
         const Eigen::Vector3d shift = 0.5 * (c[1] - c[0]).cross(c[2] - c[0]).normalized();
         for (int k = 0; k < 4; ++k)
           for (int i = 0; i < 3; ++i) quad[k][i] = c[k][i] + shift[i];
       },
       "its centre is 0.500 m from where the rig was registered"},
      {[](nlohmann::json& quad) {  // flipped
         quad = nlohmann::json::array({quad[3], quad[2], quad[1], quad[0]});
       },
       "its lit side faces 180"},
  };
  for (const auto& [edit, expected] : cases) {
    nlohmann::json changed = room;
    edit(changed["surfaces"][wall]["quad"]);
    WriteFileAtomically(scene, changed.dump(2));
    const CommandRun run = testing::RunProcamStderr(compensate());
    testing::ExpectOneErrorLine(run, expected, expected);
    EXPECT_NE(run.output.find("'" + name + "'"), std::string::npos) << run.output;
    EXPECT_NE(run.output.find("registration.room.surfaces"), std::string::npos) << run.output;
    EXPECT_FALSE(fs::exists(dir / "solution")) << expected;
  }
}

}  // namespace
}  // namespace procam

namespace procam {
namespace {

// The lines of `text` that contain `what`.
int LinesWith(const std::string& text, const std::string& what) {
  int count = 0;
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    if (text.substr(start, end - start).find(what) != std::string::npos) ++count;
    start = end + 1;
  }
  return count;
}

// capture stopped by SIGTERM or SIGINT (Ctrl+C) part-way: exit 0, one line saying so and how to
// resume, result.json complete false, the stop recorded in session.json; run again, it captures
// only what is missing and ends with the files of an uninterrupted session.
TEST_F(Faults, ASignalStopsCaptureCleanlyAndItResumes) {
  const auto command = [&](const std::string& out) {
    return "capture --camera " + kCamera + "'" + kCapture +
           "--projector 0 --sequence photometric --levels 0,128,255 --channels rgb --out " +
           (dir / out).string();
  };
  ASSERT_GT(TimedRun(command("clean")), 0);
  for (const int signal : {SIGTERM, SIGINT}) {
    const std::string out = "stopped" + std::to_string(signal);
    const fs::path log = dir / (out + ".log");
    const testing::SignalledRun run = testing::SignalProcamWhen(
        command(out), [&] { return CountFiles(dir / out / "frames") >= 2; }, signal, kMaxSeconds,
        log);
    const std::string output = Bytes(log);
    ASSERT_TRUE(run.running) << "capture ended before the signal\n" << output;
    EXPECT_TRUE(run.exited) << "died of signal " << run.died_of << "\n" << output;
    EXPECT_EQ(run.exit_code, 0) << output;
    EXPECT_EQ(LinesWith(output, "stopped by a signal"), 1) << output;
    EXPECT_EQ(LinesWith(output, "run the same command again to resume"), 1) << output;
    EXPECT_EQ(output.find("error"), std::string::npos) << output;
    const nlohmann::json result = nlohmann::json::parse(Bytes(dir / out / "result.json"));
    EXPECT_EQ(result.at("complete"), false) << result.dump();
    EXPECT_EQ(result.at("stopped"), true) << result.dump();
    const nlohmann::json session = nlohmann::json::parse(Bytes(dir / out / "session.json"));
    ASSERT_EQ(session.at("interruptions").size(), 1u) << session.dump();
    EXPECT_EQ(session.at("interruptions").at(0).at("reason"), "stopped by a signal");
    ExpectEveryFileReads(dir / out);
    const CommandRun resumed = testing::RunProcam(command(out));
    ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
    EXPECT_NE(resumed.output.find("7/7 patterns captured"), std::string::npos) << resumed.output;
    EXPECT_EQ(resumed.output.find(" 0 already there"), std::string::npos) << resumed.output;
    EXPECT_EQ(FilesUnder(dir / out), FilesUnder(dir / "clean"));
  }
}

// play stopped by SIGTERM or SIGINT mid-show: exit 0, one line, a whole result.json of the
// frames shown (stopped: true). Stopped before its first frame (waiting for a node that never
// answers), it writes nothing: the earlier result.json is kept as it was.
TEST_F(Faults, ASignalStopsPlayCleanly) {
  const fs::path solution = dir / "solution";
  Compensate(Rig(), solution);
  const auto play = [&](const fs::path& out, const std::string& extra) {
    return "play " + kScene + " --rig " + Rig().string() + " --solution " + solution.string() +
           " --frames 100000 --fps 20 --out " + out.string() + extra;
  };
  for (const int signal : {SIGTERM, SIGINT}) {
    const fs::path out = dir / ("show" + std::to_string(signal));
    const fs::path log = dir / ("show" + std::to_string(signal) + ".log");
    const testing::SignalledRun run = testing::SignalProcamWhen(
        play(out, " --display memory,memory"),
        [&] { return fs::exists(log) && Bytes(log).find("play: frame ") != std::string::npos; },
        signal, kMaxSeconds, log);
    const std::string output = Bytes(log);
    ASSERT_TRUE(run.running) << "play ended before the signal\n" << output;
    EXPECT_TRUE(run.exited) << "died of signal " << run.died_of << "\n" << output;
    EXPECT_EQ(run.exit_code, 0) << output;
    EXPECT_EQ(LinesWith(output, "stopped by a signal"), 1) << output;
    EXPECT_EQ(output.find("error"), std::string::npos) << output;
    ASSERT_TRUE(fs::exists(out / "result.json")) << output;
    const nlohmann::json result = nlohmann::json::parse(Bytes(out / "result.json"));
    EXPECT_EQ(result.at("stopped"), true);
    EXPECT_GE(result.at("frames_shown").get<int>(), 1);
    EXPECT_LT(result.at("frames_shown").get<int>(), 100000);
    EXPECT_EQ(result.at("frames").size(), result.at("frames_shown").get<size_t>());
  }
  // Before the first frame: a node at a port nobody listens at is waited for (setup timeout
  // 120 s), then the signal.
  const fs::path rig = CopyRig(dir / "keyed_rig");
  ASSERT_EQ(testing::RunProcam("keys --rig " + rig.string()).exit_code, 0);
  const fs::path out = dir / "earlier";
  const std::string earlier = R"({"fps_target": 30, "frames_shown": 3})";
  dir.Write("earlier/result.json", earlier);
  const int port = 21000 + static_cast<int>(::getpid() % 4000);
  const fs::path log = dir / "setup.log";
  const testing::SignalledRun run = testing::SignalProcamWhen(
      "play " + kScene + " --rig " + rig.string() + " --solution " + solution.string() +
          " --nodes a=tcp://127.0.0.1:" + std::to_string(port) + " --out " + out.string(),
      [&] { return fs::exists(log) && Bytes(log).find("setting up 1 node") != std::string::npos; },
      SIGTERM, kMaxSeconds, log);
  const std::string output = Bytes(log);
  ASSERT_TRUE(run.running) << output;
  EXPECT_TRUE(run.exited) << "died of signal " << run.died_of << "\n" << output;
  EXPECT_EQ(run.exit_code, 0) << output;
  EXPECT_EQ(LinesWith(output, "stopped by a signal before the first frame"), 1) << output;
  EXPECT_EQ(Bytes(out / "result.json"), earlier);
  EXPECT_EQ(FilesUnder(out), std::set<std::string>{"result.json"});
}

// calibrate all stopped by SIGTERM during its first capture: exit 0 (a clean stop; the rig is
// not made, which rig.json's absence says), one line saying where it stopped and how to resume,
// the capture's session records the stop, every file written reads whole. Run again, it resumes
// the capture (its patterns kept) and ends with a whole rig.
TEST_F(Faults, ASignalStopsCalibrateAllCleanlyAndItResumes) {
  const fs::path rig = dir / "rig";
  const std::string calibrate =
      "calibrate all --camera " + kCamera + "'" + kCapture + "--out " + rig.string();
  const fs::path session = rig / "captures" / "structured_light_left";
  const fs::path log = dir / "stopped.log";
  const testing::SignalledRun run = testing::SignalProcamWhen(
      calibrate, [&] { return CountFiles(session / "frames") >= 2; }, SIGTERM, kMaxSeconds, log);
  const std::string output = Bytes(log);
  ASSERT_TRUE(run.running) << "calibrate all ended before the signal\n" << output;
  EXPECT_TRUE(run.exited) << "died of signal " << run.died_of << "\n" << output;
  EXPECT_EQ(run.exit_code, 0) << output;
  EXPECT_EQ(LinesWith(output, "stopped by a signal"), 1) << output;
  EXPECT_EQ(LinesWith(output,
                      "procam: stopped: calibrate all: stopped by a signal in step 2/4, "
                      "the structured light of projector 'left' ("),
            1)
      << output;
  EXPECT_EQ(LinesWith(output, "run the same command again to resume"), 1) << output;
  EXPECT_EQ(output.find("procam: error"), std::string::npos) << output;
  EXPECT_FALSE(fs::exists(rig / "captures" / "photometric_left")) << "a step begun after the stop";
  EXPECT_FALSE(fs::exists(rig / "rig.json")) << "a stopped calibration reads as a rig";
  const nlohmann::json manifest = nlohmann::json::parse(Bytes(session / "session.json"));
  ASSERT_EQ(manifest.at("interruptions").size(), 1u) << manifest.dump();
  EXPECT_EQ(manifest.at("interruptions").at(0).at("reason"), "stopped by a signal");
  ExpectEveryFileReads(rig);
  const std::set<std::string> kept = FilesUnder(rig);
  const CommandRun resumed = testing::RunProcam(calibrate);
  ASSERT_EQ(resumed.exit_code, 0) << resumed.output;
  // The stopped capture resumes with the patterns it kept.
  std::string resumed_line;
  std::istringstream lines(resumed.output);
  for (std::string line; std::getline(lines, line);)
    if (line.find("into " + session.string() + ": ") != std::string::npos) resumed_line = line;
  EXPECT_NE(resumed_line.find(" already there)"), std::string::npos) << resumed.output;
  EXPECT_EQ(resumed_line.find(" 0 already there)"), std::string::npos) << resumed_line;
  const std::set<std::string> now = FilesUnder(rig);
  EXPECT_TRUE(std::includes(now.begin(), now.end(), kept.begin(), kept.end()));
  for (const char* name : {"rig.json", "camera.cameramodel", "left.cameramodel",
                           "right.cameramodel", "reflectance.npy", "result.json"}) {
    EXPECT_TRUE(fs::exists(rig / name)) << name;
  }
  ExpectEveryFileReads(rig);
}

// calibrate all over a rig whose captures are complete, stopped by SIGINT once its fits have
// begun: it ends before the next step with the same exit status and one line, and every file of
// the rig still reads whole.
TEST_F(Faults, ASignalDuringTheFitsStopsCalibrateAllBeforeTheNextStep) {
  const fs::path rig = dir / "fits";
  fs::copy(Rig(), rig, fs::copy_options::recursive);
  const fs::path log = dir / "fits.log";
  const testing::SignalledRun run = testing::SignalProcamWhen(
      "calibrate all --camera " + kCamera + "'" + kCapture + "--out " + rig.string(),
      [&] { return fs::exists(log) && Bytes(log).find("== 3/4") != std::string::npos; }, SIGINT,
      kMaxSeconds, log);
  const std::string output = Bytes(log);
  ASSERT_TRUE(run.running) << output;
  EXPECT_TRUE(run.exited) << "died of signal " << run.died_of << "\n" << output;
  EXPECT_EQ(run.exit_code, 0) << output;
  EXPECT_EQ(LinesWith(output, "procam: stopped: calibrate all: stopped by a signal"), 1) << output;
  EXPECT_EQ(output.find("== 4/4"), std::string::npos) << output;
  EXPECT_EQ(output.find("procam: error"), std::string::npos) << output;
  EXPECT_EQ(FilesUnder(rig), FilesUnder(Rig()));
  ExpectEveryFileReads(rig);
}

// verify stopped by SIGTERM during its first photo: the photo in hand is finished, the model
// update is not begun; exit 0, one line, result.json complete false with
// termination "stopped" and the one iteration. Run again, it resumes (the photo is kept) and
// ends with the files of an uninterrupted run.
TEST_F(Faults, ASignalStopsVerifyCleanlyAndItResumes) {
  const std::string solution = (dir / "solution").string();
  Compensate(Rig(), solution);
  ASSERT_GT(TimedRun(VerifyCommand(solution, "clean")), 0);
  const fs::path first = dir / "verify" / "iterations" / "0" / "session" / "frames";
  const fs::path log = dir / "verify.log";
  const testing::SignalledRun run = testing::SignalProcamWhen(
      VerifyCommand(solution, "verify"), [&] { return CountFiles(first) >= 1; }, SIGTERM,
      kMaxSeconds, log);
  const std::string output = Bytes(log);
  ASSERT_TRUE(run.running) << output;
  EXPECT_TRUE(run.exited) << "died of signal " << run.died_of << "\n" << output;
  EXPECT_EQ(run.exit_code, 0) << output;
  EXPECT_EQ(LinesWith(output, "procam: stopped: verify: stopped by a signal"), 1) << output;
  EXPECT_EQ(LinesWith(output, "run the same command again to resume"), 1) << output;
  EXPECT_EQ(output.find("procam: error"), std::string::npos) << output;
  const nlohmann::json stopped = nlohmann::json::parse(Bytes(dir / "verify" / "result.json"));
  EXPECT_FALSE(stopped.at("complete").get<bool>()) << stopped.dump(2);
  EXPECT_EQ(stopped.at("termination"), "stopped") << stopped.dump(2);
  EXPECT_EQ(stopped.at("iterations").size(), 1u) << stopped.dump(2);
  EXPECT_FALSE(fs::exists(dir / "verify" / "iterations" / "1")) << output;
  ExpectEveryFileReads(dir / "verify");
  const std::set<std::string> kept = FilesUnder(dir / "verify" / "iterations" / "0" / "session");
  const CommandRun again = testing::RunProcam(VerifyCommand(solution, "verify"));
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(FilesUnder(dir / "verify"), FilesUnder(dir / "clean"));
  EXPECT_EQ(FilesUnder(dir / "verify" / "iterations" / "0" / "session"), kept);
  ExpectEveryFileReads(dir / "verify");
  const nlohmann::json result = nlohmann::json::parse(Bytes(dir / "verify" / "result.json"));
  EXPECT_TRUE(result.at("complete").get<bool>()) << result.dump(2);
}

// capture --settle-ms auto stopped by SIGINT while it measures the display's latency (seconds:
// each of its two reference fields waits a second before it is photographed): the measurement
// is cut short (no latency line), the session records the stop before its first pattern,
// result.json says stopped, exit 0 as any stopped capture.
TEST_F(Faults, ASignalDuringTheLatencyMeasurementStopsCaptureCleanly) {
  const fs::path out = dir / "latency";
  const fs::path log = dir / "latency.log";
  const testing::SignalledRun run = testing::SignalProcamWhen(
      "capture --camera " + kCamera + "' --frames 2 --settle-ms auto --projector 0 --sequence " +
          "photometric --levels 0,255 --channels w --out " + out.string(),
      [&] {
        return fs::exists(log) &&
               Bytes(log).find("measuring the display-to-camera latency") != std::string::npos;
      },
      SIGINT, kMaxSeconds, log);
  const std::string output = Bytes(log);
  ASSERT_TRUE(run.running) << output;
  EXPECT_TRUE(run.exited) << "died of signal " << run.died_of << "\n" << output;
  EXPECT_EQ(run.exit_code, 0) << output;
  EXPECT_EQ(LinesWith(output, "stopped by a signal"), 1) << output;
  EXPECT_EQ(output.find("every change seen between"), std::string::npos) << output;
  EXPECT_EQ(output.find("procam: error"), std::string::npos) << output;
  const nlohmann::json result = nlohmann::json::parse(Bytes(out / "result.json"));
  EXPECT_EQ(result.at("stopped"), true) << result.dump();
  EXPECT_TRUE(result.at("latency").is_null()) << result.dump();
  EXPECT_EQ(result.at("patterns_captured"), 0) << result.dump();
  const nlohmann::json session = nlohmann::json::parse(Bytes(out / "session.json"));
  ASSERT_EQ(session.at("interruptions").size(), 1u) << session.dump();
  EXPECT_EQ(session.at("interruptions").at(0).at("pattern"), 0);
  ExpectEveryFileReads(out);
}

// play stopped by SIGTERM while it computes the form factors of a finer room (seconds): the
// computation is cut short (no "form factors: 100%"), play ends as stopped before its first
// frame: exit 0, one line, nothing written.
TEST_F(Faults, ASignalDuringTheFormFactorsStopsPlayCleanly) {
  // The rig without its per-patch reflectance, which is of the suite's 150 patches.
  const fs::path rig = CopyRig(dir / "rig");
  nlohmann::json file = nlohmann::json::parse(Bytes(rig / "rig.json"));
  file.erase("reflectance");
  dir.Write("rig/rig.json", file.dump(2));
  fs::create_directories(dir / "desired");
  ASSERT_TRUE(cv::imwrite((dir / "desired" / "a.png").string(),
                          cv::Mat(48, 64, CV_8UC3, cv::Scalar(40, 120, 200))));
  const fs::path out = dir / "show";
  const fs::path log = dir / "show.log";
  const testing::SignalledRun run = testing::SignalProcamWhen(
      "play synthetic:tiny_box --patches 2500 --rig " + rig.string() + " --desired " +
          (dir / "desired").string() + " --display memory,memory --out " + out.string(),
      [&] { return fs::exists(log) && Bytes(log).find("form factors: ") != std::string::npos; },
      SIGTERM, kMaxSeconds, log);
  const std::string output = Bytes(log);
  ASSERT_TRUE(run.running) << output;
  EXPECT_TRUE(run.exited) << "died of signal " << run.died_of << "\n" << output;
  EXPECT_EQ(run.exit_code, 0) << output;
  EXPECT_EQ(LinesWith(output, "stopped by a signal before the first frame"), 1) << output;
  EXPECT_EQ(output.find("form factors: 100%"), std::string::npos) << output;
  EXPECT_EQ(output.find("procam: error"), std::string::npos) << output;
  EXPECT_FALSE(fs::exists(out / "result.json")) << output;
}

// A rig registered before procam recorded what its checks read (the camera's and the
// projectors' centres and image sizes, the room): compensate says in one warning line which keys
// are missing and which command records them, and goes on; the rig registered again by that
// command (calibrate all over its captures) has them all, and no line is said. A whole rig says
// nothing.
TEST_F(Faults, ARigWithoutTheRegistrationRecordsSaysWhatIsMissingAndHowToAddIt) {
  const auto compensate = [&](const fs::path& rig) {
    return testing::RunProcam("compensate " + kScene + " --rig " + rig.string() + " --out " +
                              (dir / "solution").string());
  };
  const CommandRun whole = compensate(Rig());
  ASSERT_EQ(whole.exit_code, 0) << whole.output;
  EXPECT_EQ(whole.output.find("warning: "), std::string::npos) << whole.output;

  const fs::path rig = dir / "old_rig";
  fs::copy(Rig(), rig, fs::copy_options::recursive);
  nlohmann::json file = nlohmann::json::parse(Bytes(rig / "rig.json"));
  nlohmann::json& registration = file.at("registration");
  registration.erase("room");
  registration.erase("camera_imagersize");
  for (nlohmann::json& projector : registration.at("projectors")) projector.erase("centre_m");
  dir.Write("old_rig/rig.json", file.dump(2));
  const CommandRun old = compensate(rig);
  ASSERT_EQ(old.exit_code, 0) << old.output;
  EXPECT_EQ(LinesWith(old.output, "warning: "), 1) << old.output;
  const std::string expected = "warning: " + (rig / "rig.json").string() +
                               ": no registration.camera_imagersize, "
                               "registration.projectors[0].centre_m, "
                               "registration.projectors[1].centre_m, registration.room (";
  EXPECT_EQ(LinesWith(old.output, expected), 1) << old.output;
  EXPECT_EQ(LinesWith(old.output, "register the rig again: procam calibrate projectors " +
                                      rig.string() + "/captures/structured_light_* --scene"),
            1)
      << old.output;

  const CommandRun registered = testing::RunProcam("calibrate all --camera " + kCamera + "'" +
                                                   kCapture + "--out " + rig.string());
  ASSERT_EQ(registered.exit_code, 0) << registered.output;
  const CommandRun again = compensate(rig);
  ASSERT_EQ(again.exit_code, 0) << again.output;
  EXPECT_EQ(again.output.find("warning: "), std::string::npos) << again.output;
}

}  // namespace
}  // namespace procam
