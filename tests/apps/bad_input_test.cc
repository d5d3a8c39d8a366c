// Bad input through the procam binary, as a user (or a fuzzer) gives it: every refusal is one
// line "procam: error: ..." on stderr naming the file, key or option, exit code 1, no crash, no
// hang, and nothing written. The readers' own tests check each case's message; these check
// that the command line keeps the promise (docs/faults.md).
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
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

}  // namespace
}  // namespace procam
