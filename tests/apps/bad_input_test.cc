// Bad input through the procam binary, as a user (or a fuzzer) gives it: every refusal is one
// line "procam: error: ..." on stderr naming the file, key or option, exit code 1, no crash, no
// hang, and nothing written. The readers' own tests check each case's message; these check
// that the command line keeps the promise (docs/faults.md).
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::CommandRun;

const char* kQuad =
    R"({"name": "floor", "quad": [[0,0,0],[2,0,0],[2,2,0],[0,2,0]], "reflectance": 0.5, "desired": [0.5, 0.5, 0.5]})";

std::string Scene(const std::string& surface, const std::string& projectors = "") {
  return R"({"patches": 16, "surfaces": [)" + surface + "]" +
         (projectors.empty() ? "" : R"(, "projectors": [)" + projectors + "]") + "}";
}

// A pinhole projector model 64x48 at (1, 1, 1.5) looking down, with `extrinsics` if given.
std::string Model(const std::string& extrinsics = "3.14159265, 0, 0, 1, -1, 1.5") {
  return "{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [ 60, 60, 31.5, 23.5 ], "
         "'imagersize': [ 64, 48 ], 'extrinsics': [ " +
         extrinsics + " ] }\n";
}

const char* kProjector = R"({"name": "p", "model": "p.cameramodel", "max": 1})";

// Expects a refusal: exit 1 and exactly one line on stderr, procam's, containing `expected`.
void ExpectOneErrorLine(const std::string& arguments, const std::string& expected) {
  testing::ExpectOneErrorLine(testing::RunProcamStderr(arguments), expected, arguments);
}

// CLI11's own errors (a value that does not convert, a missing option) are procam's one line.
TEST(BadInput, OptionValuesThatDoNotParseAreOneErrorLine) {
  testing::TempDir dir;
  const std::string capture = "capture --camera test:loopback --sequence photometric --out " +
                              (dir / "session").string() + " ";
  ExpectOneErrorLine(capture + "--levels abc", "--levels");
  ExpectOneErrorLine(capture + "--frames many", "--frames");
  ExpectOneErrorLine("capture --sequence photometric", "--camera");
  ExpectOneErrorLine("scene info", "scene");
  EXPECT_FALSE(std::filesystem::exists(dir / "session"));
  EXPECT_EQ(testing::RunProcam("--version").exit_code, 0);
}

// Values that parse but make no sense are refused before a camera is opened or a file written.
TEST(BadInput, CaptureOptionsOutOfRangeAreRefusedBeforeAnythingIsWritten) {
  testing::TempDir dir;
  const std::string capture =
      "capture --camera test:loopback --projector-size 32x24 --frames 1 "
      "--settle-ms 0 --out " +
      (dir / "session").string() + " --sequence ";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"graycode --projector -1", "--projector: must be >= 0"},
      {"structured_light --pattern-gamma 0", "--pattern-gamma"},
      {"structured_light --pattern-gamma nan", "--pattern-gamma"},
      {"graycode --pattern-gamma nan", "--pattern-gamma"},
      {"graycode --gain -1e308", "--gain"},
      {"graycode --gain nan", "--gain"},
      {"photometric --levels ''", "--levels"},
      {"graycode --levels 300", "--levels"},
      {"graycode --projector-gamma inf", "--projector-gamma"},
      {"graycode --projector-size 99999999999x2", "--projector-size"},
  };
  for (const auto& [arguments, expected] : cases) {
    ExpectOneErrorLine(capture + arguments, expected);
    EXPECT_FALSE(std::filesystem::exists(dir / "session")) << arguments;
  }
}

// A chessboard of 10^10 corners would keep the detector busy for ever: refused at once.
TEST(BadInput, ChessboardCornersAreBounded) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "photos");
  for (const char* corners : {"100000x100000", "9x101", "1x6", "9x6x", "x6", "-9x6", ""}) {
    ExpectOneErrorLine("calibrate camera " + (dir / "photos").string() + " --corners '" + corners +
                           "' --out " + (dir / "rig").string(),
                       "--corners");
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "rig"));
}

// A corrupt chessboard photo: libpng's own line is silenced, procam's names the file.
TEST(BadInput, CorruptPhotosAreOneErrorLine) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "photos");
  dir.Write("photos/a.png", std::string("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\0\0\x10\0\0\0\x10"
                                        "\x08\x02\0\0\0\xde\xad\xbe\xef junk",
                                        34));
  ExpectOneErrorLine("calibrate camera " + (dir / "photos").string() + " --corners 9x6 --out " +
                         (dir / "rig").string(),
                     "a.png: not a readable image");
  EXPECT_FALSE(std::filesystem::exists(dir / "rig"));
}

// scene info reads the projectors as every other command does: their names, photometry and
// models, so a scene it accepts is one compensate and project accept.
TEST(BadInput, SceneInfoChecksTheProjectors) {
  testing::TempDir dir;
  dir.Write("p.cameramodel", Model());
  dir.Write("empty.cameramodel", "");
  dir.Write("truncated.cameramodel", Model().substr(0, 60));
  const std::vector<std::pair<std::string, std::string>> cases = {
      {R"("")", "projectors[0]"},
      {R"({"name": "p", "model": "p.cameramodel", "max": 1, "mixing": [[1,0,0],[0,1,0]]})",
       "projectors[0].mixing"},
      {R"({"name": "p", "model": "p.cameramodel", "max": 1, "lut": ["a", "b"]})",
       "projectors[0].lut"},
      {R"({"name": "p", "model": "empty.cameramodel", "max": 1})", "empty.cameramodel"},
      {R"({"name": "p", "model": "truncated.cameramodel", "max": 1})", "truncated.cameramodel"},
      {R"({"name": "p", "model": "p.cameramodel", "max": -1})", "projectors[0].max"},
      {std::string(kProjector) + ", " + kProjector, "already the name of another projector"},
  };
  for (const auto& [projectors, expected] : cases) {
    const auto scene = dir.Write("scene.json", Scene(kQuad, projectors));
    ExpectOneErrorLine("scene info " + scene.string(), expected);
  }
  const CommandRun good = testing::RunProcam(
      "scene info " + dir.Write("scene.json", Scene(kQuad, kProjector)).string());
  EXPECT_EQ(good.exit_code, 0) << good.output;
  EXPECT_NE(good.output.find("projector p"), std::string::npos) << good.output;
}

// Models are checked where they are read: an extrinsic of 1e308 once aborted inside Embree;
// libmrcal's own parser line is folded into procam's one line.
TEST(BadInput, ProjectorModelsAreCheckedWhereTheyAreRead) {
  testing::TempDir dir;
  const std::vector<std::pair<std::string, std::string>> models = {
      {Model("0, 0, 0, 0, 0, 1e308"), "extrinsics"},
      {Model("3.14, 0, 0, 1, -1, nan"), "p.cameramodel"},
      {"{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [1, 1", "not a valid mrcal .cameramodel"},
      {"{ 'lensmodel': 'LENSMODEL_NOSUCH', 'intrinsics': [ 60, 60, 31.5, 23.5 ], "
       "'imagersize': [ 64, 48 ], 'extrinsics': [ 0, 0, 0, 0, 0, 0 ] }",
       "p.cameramodel"},
  };
  const auto scene = dir.Write("scene.json", Scene(kQuad, kProjector));
  for (const auto& [model, expected] : models) {
    dir.Write("p.cameramodel", model);
    ExpectOneErrorLine("compensate " + scene.string() + " --out " + (dir / "solution").string(),
                       expected);
    ExpectOneErrorLine("scene info " + scene.string(), expected);
    EXPECT_FALSE(std::filesystem::exists(dir / "solution"));
  }
}

// OBJ indices outside 32 bits once crashed scene info and compensate; a FIFO or /dev/zero as a
// mesh or texture hung them; a corrupt PNG texture let libpng print its own line.
TEST(BadInput, MeshesAndTexturesAreReadSafely) {
  testing::TempDir dir;
  dir.Write("big.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 2147483648\n");
  dir.Write("vt.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1/1 2/2 3/3\n");
  ASSERT_EQ(::mkfifo((dir / "fifo.obj").c_str(), 0600), 0);
  std::filesystem::create_symlink("/dev/zero", dir / "zero.png");
  // A PNG signature and header chunk with a wrong CRC, then junk.
  dir.Write("corrupt.png",
            std::string("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\0\0\x10\0\0\0\x10\x08\x02\0\0\0"
                        "\xde\xad\xbe\xef junk junk junk",
                        45));
  const std::string mesh = R"({"mesh": "NAME", "reflectance": 0.5, "desired": [1,1,1]})";
  const std::string texture =
      R"({"quad": [[0,0,0],[1,0,0],[1,1,0],[0,1,0]], "reflectance": 0.5, "desired": {"texture": "NAME"}})";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {mesh, "big.obj"},     {mesh, "vt.obj"},         {mesh, "fifo.obj"},
      {texture, "zero.png"}, {texture, "corrupt.png"},
  };
  for (const auto& [surface, name] : cases) {
    std::string text = surface;
    text.replace(text.find("NAME"), 4, name);
    const auto scene = dir.Write("scene.json", Scene(text));
    ExpectOneErrorLine("scene info " + scene.string(), name);
    ExpectOneErrorLine("compensate " + scene.string() + " --out " + (dir / "solution").string(),
                       name);
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "solution"));
}


// scene export and evaluate write files of no directory kind of their own: into a rig (or any of
// procam's outputs) they are refused in one line, and the rig is as it was.
TEST(BadInput, ExportAndEvaluateRefuseProcamDirectories) {
  testing::TempDir dir;
  const auto rig_json = dir.Write("rig/rig.json", R"({"format": "procam rig", "version": 1, "projectors": []})");
  const auto contents = [](const std::filesystem::path& path) {
    std::ifstream in(path);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string rig = (dir / "rig").string(), before = contents(rig_json);
  ExpectOneErrorLine("scene export synthetic:tiny_box --patches 50 --out " + rig,
                     "--out is a rig directory; scene export would write its own files into it");
  ExpectOneErrorLine("evaluate tiny_box --patches 50 --out " + rig,
                     "--out is a rig directory; evaluate would write its own files into it");
  EXPECT_EQ(contents(rig_json), before);
  EXPECT_FALSE(std::filesystem::exists(dir / "rig" / "F.npy"));
}

// scene write replaces no file that differs from what it would write (a scene edited by hand)
// and, refusing, writes nothing; run again over its own output it succeeds.
TEST(BadInput, SceneWriteKeepsFilesEditedByHand) {
  testing::TempDir dir;
  const std::string write = "scene write tiny_box --patches 50 --out ";
  ASSERT_EQ(testing::RunProcam(write + (dir / "a").string()).exit_code, 0);
  EXPECT_EQ(testing::RunProcam(write + (dir / "a").string()).exit_code, 0);  // the same files
  const std::string edited = "{\"edited\": \"by hand\"}\n";
  dir.Write("a/tiny_box.json", edited);
  ExpectOneErrorLine(write + (dir / "a").string(), "tiny_box.json: exists and differs");
  std::ifstream in(dir / "a" / "tiny_box.json");
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), edited);
  std::filesystem::create_directories(dir / "b" / "tiny_box.json");
  ExpectOneErrorLine(write + (dir / "b").string(), "tiny_box.json: exists and is not a regular file");
  size_t files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "b")) files += entry.is_regular_file();
  EXPECT_EQ(files, 0u);
}

// Two surfaces of one name are refused where the scene is read.
TEST(BadInput, SurfaceNamesAreUnique) {
  testing::TempDir dir;
  const auto scene = dir.Write("scene.json", Scene(std::string(kQuad) + ", " + kQuad));
  ExpectOneErrorLine("scene info " + scene.string(), "surfaces[1].name: 'floor' is already the name of surfaces[0]");
}

// A patch count whose dense form factors cannot fit in memory is refused at once, saying how
// much they need and what to use instead, before anything is allocated or written.
TEST(BadInput, PatchCountsBeyondMemoryAreRefusedUpFront) {
  testing::TempDir dir;
  for (const std::string& command :
       {std::string("scene info synthetic:tiny_box --patches 1000000"),
        "compensate synthetic:tiny_box --patches 1000000 --out " + (dir / "solution").string()}) {
    const CommandRun run = testing::RunProcamStderr(command);
    testing::ExpectOneErrorLine(run, "--form-factors compressed", command);
    EXPECT_NE(run.output.find("8000.0 GB"), std::string::npos) << run.output;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "solution"));
}

// A built-in scene by name has no projectors: compensate says, before solving, that it solves
// within the scene's bounds and that project will need a rig.
TEST(BadInput, CompensateWithoutProjectorsSaysItSolvesOnBounds) {
  testing::TempDir dir;
  const CommandRun run = testing::RunProcam("compensate synthetic:c_shaped --patches 60 --out " +
                                            (dir / "solution").string());
  EXPECT_EQ(run.exit_code, 0) << run.output;
  EXPECT_NE(run.output.find("lists no projectors and no --rig was given: solving within the "
                            "scene's bounds"),
            std::string::npos)
      << run.output;
}


// Option values that are not finite numbers (CLI11's range checks let NaN through) and ports out
// of range (libzmq takes them modulo 65536) are refused in one line naming the option, before
// anything starts.
TEST(BadInput, NotANumberAndPortsOutOfRangeAreRefused) {
  testing::TempDir dir;
  const std::string rig = (dir / "rig").string(), out = " --out " + (dir / "out").string();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"emulate room.json --monitors A --latency-ms nan", "--latency-ms"},
      {"emulate room.json --monitors A --fps nan", "--fps"},
      {"emulate room.json --monitors A --seconds nan", "--seconds"},
      {"emulate room.json --monitors A --fps inf", "--fps"},
      // An address that is not IPv4 is the option's fault, not the scene file's.
      {"emulate room.json --monitors A --address 999.1.1.1", "--address"},
      {"play room.json --rig " + rig + out + " --setup-timeout nan", "--setup-timeout"},
      {"play room.json --rig " + rig + out + " --frame-timeout-ms nan", "--frame-timeout-ms"},
      {"compensate room.json --alpha nan" + out, "--alpha"},
      {"node --rig " + rig + " --scene room.json --projectors a --seconds nan", "--seconds"},
      {"node --rig " + rig + " --scene room.json --projectors a --listen tcp://127.0.0.1:99999",
       "--listen: tcp://127.0.0.1:99999: the port must be a number in 0..65535"},
      {"node --rig " + rig + " --scene room.json --projectors a --listen inproc://x",
       "--listen: inproc://x: a node listens at tcp://ADDRESS:PORT"},
      // The scene is read at start, not when the controller's setup arrives.
      {"node --rig " + rig + " --scene " + (dir / "missing.json").string() + " --projectors a --seconds 2",
       "missing.json: file not found"},
      {"play room.json --rig " + rig + out + " --nodes a=tcp://127.0.0.1:70000",
       "the port must be a number in 1..65535"},
  };
  for (const auto& [arguments, expected] : cases) ExpectOneErrorLine(arguments, expected);
  EXPECT_FALSE(std::filesystem::exists(dir / "out"));
}

// One name, monitor or address given twice is refused in one line, before anything starts.
TEST(BadInput, NamesGivenTwiceAreRefused) {
  testing::TempDir dir;
  const std::string rig = (dir / "rig").string(), out = " --out " + (dir / "out").string();
  const std::string node = "node --rig " + rig + " --scene room.json ";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {node + "--projectors left,left --display memory,memory", "--projectors: 'left' is given twice"},
      {node + "--projectors left,right --display glfw:0,glfw:0", "--display: 'glfw:0' is given twice"},
      {"play room.json --rig " + rig + out + " --nodes a=tcp://127.0.0.1:5600,a=tcp://127.0.0.1:5601",
       "--nodes: 'a' is given twice"},
      {"play room.json --rig " + rig + out + " --nodes a=tcp://127.0.0.1:5600,b=tcp://127.0.0.1:5600",
       "--nodes: 'tcp://127.0.0.1:5600' is given twice"},
      {"emulate room.json --monitors A,A", "--monitors: 'A' is given twice"},
  };
  for (const auto& [arguments, expected] : cases) ExpectOneErrorLine(arguments, expected);
  EXPECT_FALSE(std::filesystem::exists(dir / "out"));
}

// procam keys creates the secret keys readable by their owner only, the public ones by all.
TEST(BadInput, SecretKeysAreCreatedForTheirOwnerOnly) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "rig");
  const mode_t umask_before = ::umask(0);  // the most permissive umask: the mode is procam's own
  const CommandRun run = testing::RunProcam("keys --rig " + (dir / "rig").string());
  ::umask(umask_before);
  ASSERT_EQ(run.exit_code, 0) << run.output;
  for (const char* name : {"controller.key", "node.key"}) {
    struct stat info {};
    ASSERT_EQ(::stat((dir / "rig" / "keys" / name).c_str(), &info), 0) << name;
    EXPECT_EQ(info.st_mode & 0777, 0600u) << name;
  }
  struct stat info {};
  ASSERT_EQ(::stat((dir / "rig" / "keys" / "node.pub").c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 0777, 0644u);
}

// What is not a V4L2 camera (/dev/null, /dev/zero, a regular file) is one line of procam's:
// libv4l2 printed three lines of its own when it opened them.
TEST(BadInput, WhatIsNotAV4l2CameraIsOneLine) {
  if (testing::RunProcam("cameras --no-gige").output.find("(no V4L2") != std::string::npos)
    GTEST_SKIP() << "a build without V4L2";
  testing::TempDir dir;
  const std::filesystem::path file = dir.Write("camera.txt", "not a camera\n");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"/dev/null", "/dev/null is not a V4L2 device"},
      {"/dev/zero", "/dev/zero is not a V4L2 device"},
      {file.string(), file.string() + " is not a device"},
  };
  for (const auto& [device, expected] : cases) {
    testing::ExpectOneErrorLine(
        testing::RunProcamStderr("capture --camera v4l2:" + device + " --sequence graycode --out " +
                                 (dir / "session").string()),
        expected, device);
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "session"));
}

}  // namespace
}  // namespace procam
