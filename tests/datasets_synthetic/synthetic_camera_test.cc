// The synthetic camera ("synthetic:<scene>") photographs the simulated room through the capture
// module: the truth it is checked against is the geometry — which surface point each camera
// pixel sees, whether projector 0 reaches it unoccluded, and where that point projects into the
// projector — not the renderer.
#include "datasets_synthetic/synthetic_camera.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>

#include <nlohmann/json.hpp>

#include "base/json_fields.h"
#include "capture/patterns.h"
#include "capture/scene_cameras.h"
#include "capture/sequencer.h"
#include "datasets_synthetic/scene_files.h"
#include "geometry/ray_scene.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

// Fast frames; 1 ms exposure at the reference exposure, so radiance 1 reads 255.
const std::string kTinyBox =
    "synthetic:tiny_box?patches=100&fps=500&exposure_us=1000&reference_exposure_us=1000";

SequencerOptions FastSequencer(int frames) {
  SequencerOptions options;
  options.settle_ms = 2;
  options.frames_per_pattern = frames;
  options.grab_timeout_ms = 5000;  // a render takes a while on a small machine
  return options;
}

// What projector `k` does to the point camera pixel (row, col) sees, from the geometry alone.
struct DirectLight {
  bool lit = false;  // in front of the projector, inside its image, nothing in between
  double cos_incidence = 0.0;
  Vec2 projector_pixel = Vec2::Zero();
  Vec3 full_white = Vec3::Zero();  // reflected direct light of full white over black, R, G, B
};

class Geometry {
 public:
  explicit Geometry(const SimulatedRig& rig) : rig_(rig), surfaces_(rig.scene()) {}

  DirectLight Direct(int k, int row, int col) const {
    DirectLight direct;
    const Projector& projector = rig_.projectors()[k];
    Vec3 point, normal;
    if (!rig_.PointSeenByPixel(row, col, &point, &normal)) return direct;
    const double gain = projector.geometry.Gain(point, normal, &direct.projector_pixel);
    if (gain <= 0.0 || !projector.geometry.InImage(direct.projector_pixel)) return direct;
    if (surfaces_.Occluded(point, projector.geometry.CentreInWorld(), 1e-4)) return direct;
    direct.lit = true;
    direct.cos_incidence = (projector.geometry.CentreInWorld() - point).normalized().dot(normal);
    // The surface the camera ray meets there gives the reflectance.
    const Vec3 camera_centre = rig_.camera().CentreInWorld();
    double t = 0.0;
    int surface = -1;
    EXPECT_TRUE(surfaces_.Intersect(camera_centre, point - camera_centre, 0.0, 2.0, &t, &surface));
    const Vec3 reflectance = rig_.scene().surfaces[std::max(surface, 0)].reflectance;
    direct.full_white =
        reflectance.cwiseProduct(gain * (projector.photometry.max - projector.photometry.black));
    return direct;
  }

 private:
  const SimulatedRig& rig_;
  RayScene surfaces_;
};

TEST(SyntheticCamera, WhiteOnOneProjectorBrightensExactlyWhereItLightsTheRoom) {
  RegisterSyntheticCameraBackend();
  const std::unique_ptr<Camera> camera = OpenCamera(kTinyBox);
  const std::shared_ptr<SyntheticWorld> world = OpenSyntheticWorld(CameraUri::Parse(kTinyBox));
  ASSERT_EQ(world.get(), dynamic_cast<SyntheticCamera&>(*camera).world().get())
      << "the camera and the caller share one world";
  ASSERT_EQ(world->displays.size(), 2u);
  EXPECT_EQ(world->displays[0]->Name(), "synthetic:tiny_box/left");
  EXPECT_EQ(world->displays[0]->Resolution(), cv::Size(320, 200));
  EXPECT_EQ(camera->Info().uri, "synthetic:tiny_box");
  EXPECT_EQ(camera->Info().backend, "synthetic");
  const CameraSettings settings = camera->Settings();
  const SimulatedRig& rig = *world->rig;
  EXPECT_EQ(settings.width, rig.camera().width());
  EXPECT_EQ(settings.height, rig.camera().height());
  EXPECT_EQ(settings.pixel_format, PixelFormat::kBGR8);

  // Projector 1's display never shows anything: it stays black.
  PatternSequencer sequencer(FastSequencer(4), camera.get(), world->displays[0].get());
  const cv::Size projector = world->displays[0]->Resolution();
  const cv::Mat black =
      sequencer.Capture(cv::Mat(projector, CV_8UC3, cv::Scalar::all(0))).exposures[0].mean;
  const int renders_before = world->renders;
  const PatternCapture white_capture =
      sequencer.Capture(cv::Mat(projector, CV_8UC1, cv::Scalar(255)));  // grey patterns too
  EXPECT_EQ(world->renders - renders_before, 1) << "four frames of one pattern, one render";
  const cv::Mat brighter = white_capture.exposures[0].mean - black;  // B, G, R digital numbers

  // Lit pixels brighten by at least the direct light the geometry predicts (radiance 1 = 255
  // at the reference exposure; each frame is rounded, hence 1 DN); the bounce light adds to it
  // everywhere, lit or not, but less than the direct light adds: one threshold separates lit
  // from unlit.
  const Geometry geometry(rig);
  int lit_count = 0, below_direct = 0;
  float lit_min = 1e9f, unlit_max = 0.0f;
  double direct_sum = 0.0, bounce_sum = 0.0;
  for (int row = 0; row < brighter.rows; ++row) {
    for (int col = 0; col < brighter.cols; ++col) {
      const cv::Vec3f measured = brighter.at<cv::Vec3f>(row, col);
      const float grey = (measured[0] + measured[1] + measured[2]) / 3;
      const DirectLight direct = geometry.Direct(0, row, col);
      if (!direct.lit) {
        unlit_max = std::max(unlit_max, grey);
        continue;
      }
      ++lit_count;
      lit_min = std::min(lit_min, grey);
      const Vec3 expected = 255.0 * world->radiance_scale * direct.full_white;  // R, G, B
      for (int c = 0; c < 3; ++c) below_direct += measured[2 - c] < expected[c] - 1.0;
      direct_sum += expected.mean();
      bounce_sum += grey - expected.mean();
    }
  }
  ASSERT_GT(lit_count, static_cast<int>(brighter.total() / 4))
      << "projector 0 lights much of the view";
  std::printf(
      "white on projector 0: %d lit pixels brighten by >= %.1f DN (direct %.1f + bounce "
      "%.1f DN on average), the %d unlit ones by <= %.1f DN\n",
      lit_count, lit_min, direct_sum / lit_count, bounce_sum / lit_count,
      static_cast<int>(brighter.total()) - lit_count, unlit_max);
  EXPECT_EQ(below_direct, 0);
  EXPECT_GT(lit_min, unlit_max) << "every lit pixel is brighter than every unlit one";
}

TEST(SyntheticCamera, GrayCodeThroughTheSequencerDecodesWhereTheGeometryProjects) {
  RegisterSyntheticCameraBackend();
  const std::unique_ptr<Camera> camera = OpenCamera(kTinyBox);
  const std::shared_ptr<SyntheticWorld> world = dynamic_cast<SyntheticCamera&>(*camera).world();
  MemoryDisplay& display = *world->displays[0];
  GrayCodeOptions options;
  options.width = display.Resolution().width;  // 320 × 200: 9 + 8 bits
  options.height = display.Resolution().height;
  const CaptureSequence sequence = MakeGrayCodeSequence(options);
  PatternSequencer sequencer(FastSequencer(1), camera.get(), &display);
  const int renders_before = world->renders;
  const auto start = std::chrono::steady_clock::now();
  std::vector<cv::Mat> captured;
  for (const Pattern& pattern : sequence.patterns)
    captured.push_back(sequencer.Capture(pattern.image).exposures[0].mean);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const GrayCodeMap map = DecodeGrayCode(options, captured);

  // Agreement: the decoded column and row within 1 projector pixel of where the point the camera
  // pixel sees projects into projector 0.
  const Geometry geometry(*world->rig);
  int lit = 0, decoded = 0, agree = 0, steep = 0, steep_agree = 0;
  for (int row = 0; row < map.column.rows; ++row) {
    for (int col = 0; col < map.column.cols; ++col) {
      const DirectLight direct = geometry.Direct(0, row, col);
      if (!direct.lit) continue;
      const int u = map.column.at<int32_t>(row, col), v = map.row.at<int32_t>(row, col);
      const bool is_decoded = u >= 0 && v >= 0;
      const bool agrees = is_decoded && std::abs(u - direct.projector_pixel.x()) <= 1.0 &&
                          std::abs(v - direct.projector_pixel.y()) <= 1.0;
      ++lit;
      decoded += is_decoded;
      agree += agrees;
      if (direct.cos_incidence >= 0.2) {  // light arriving less than 78° from the normal
        ++steep;
        steep_agree += agrees;
      }
    }
  }
  ASSERT_GT(lit, 0);
  std::printf(
      "gray code on tiny_box projector 0 (%dx%d, %zu patterns, %.2f s, %d renders): of "
      "%d lit camera pixels %.2f%% decoded, %.2f%% within 1 projector pixel (%.2f%% of the "
      "decoded; %.2f%% of the %d lit at incidence < 78 deg)\n",
      options.width, options.height, sequence.patterns.size(), seconds,
      world->renders - renders_before, lit, 100.0 * decoded / lit, 100.0 * agree / lit,
      100.0 * agree / std::max(decoded, 1), 100.0 * steep_agree / std::max(steep, 1), steep);
  EXPECT_EQ(world->renders - renders_before, static_cast<int>(sequence.patterns.size()));
  // Where the decoder answers, it is right.
  EXPECT_GE(agree, 0.995 * decoded);
  // Where projector 0 lights the walls squarely enough, ≥ 95% decode right.
  EXPECT_GT(steep, lit * 3 / 4);
  EXPECT_GE(steep_agree, 0.95 * steep);
  // The rest: projector 0 grazes the left wall (cos θ ≈ 0.1) next to the box's corners, where
  // the bounce light of the wide stripes rivals the direct light and the decoder's bit-contrast
  // test (min_bit_contrast 0.1) refuses the pixel — as it would in a real box.
  EXPECT_GE(agree, 0.88 * lit);
}

TEST(SyntheticCamera, BadUrisNameTheUriAndTheKey) {
  RegisterSyntheticCameraBackend();
  struct Case {
    std::string uri, expected;
  };
  for (const Case& c :
       {Case{"synthetic:room",
             "camera 'synthetic:room': unknown synthetic scene "
             "'room' (scenes: l_shaped,"},
        Case{"synthetic:no/such/room.json", "no/such/room.json: file not found"},
        Case{"synthetic:tiny_box?pathces=100", "unknown parameter 'pathces'"},
        Case{"synthetic:tiny_box?patches=5", "patches must be in [20, 5000], got 5"},
        Case{"synthetic:tiny_box?patches=many", "patches"},
        Case{"synthetic:tiny_box?format=YUYV", "cannot be simulated"}}) {
    try {
      OpenCamera(c.uri);
      ADD_FAILURE() << c.uri << " opened";
    } catch (const IoError& error) {
      EXPECT_NE(std::string(error.what()).find(c.expected), std::string::npos)
          << c.uri << ": " << error.what();
      EXPECT_NE(std::string(error.what()).find(c.uri), std::string::npos) << error.what();
    }
  }
  EXPECT_THROW(OpenSyntheticWorld(CameraUri::Parse("test:tiny_box")), IoError);
  EXPECT_THROW(MakeSyntheticWorld("nowhere"), std::invalid_argument);
}

// A pattern that differs across each projector's image and between projectors: a diagonal
// gradient per channel.
cv::Mat GradientPattern(cv::Size size, int k) {
  cv::Mat pattern(size, CV_8UC3);
  for (int row = 0; row < size.height; ++row) {
    for (int col = 0; col < size.width; ++col) {
      pattern.at<cv::Vec3b>(row, col) =
          cv::Vec3b(255 * col / size.width, 255 * row / size.height, k == 0 ? 255 : 96);
    }
  }
  return pattern;
}

// A built-in scene written as a scene file (its surfaces, projector and camera models and
// photometry) is the same rig: the same displays and camera settings, and the same picture of
// the same patterns, to rounding. The built-in path builds it from the placements in code, the
// file path from what LoadScene, ReadProjectors and ParseSceneCameras read back.
TEST(SyntheticCamera, SceneFileRigPhotographsWhatTheBuiltInSceneDoes) {
  RegisterSyntheticCameraBackend();
  testing::TempDir dir;
  for (const std::string name : {"tiny_box", "blue_curves"}) {
    const std::filesystem::path file = WriteSyntheticSceneFile(name, 100, dir.path() / name);
    const std::string keys = "?patches=60&fps=500&exposure_us=1000&reference_exposure_us=1000";
    const std::string built_in_uri = "synthetic:" + name + keys, file_uri = "synthetic:" + file.string() + keys;
    const std::shared_ptr<SyntheticWorld> built_in = OpenSyntheticWorld(CameraUri::Parse(built_in_uri));
    const std::shared_ptr<SyntheticWorld> from_file = OpenSyntheticWorld(CameraUri::Parse(file_uri));
    ASSERT_NE(built_in.get(), from_file.get());
    EXPECT_EQ(from_file->scene, file.string());
    EXPECT_EQ(from_file->scene_source, file.string());
    // The same position; the file's look point is 3 m along the optical axis, the built-in's the
    // point the placement aims at: the two lie on one line from the camera, within rounding.
    const auto guess = [](const std::string& text) {
      std::vector<double> v;
      for (size_t at = 0; at < text.size();) {
        size_t next = text.find(',', at);
        v.push_back(std::stod(text.substr(at, next - at)));
        at = next == std::string::npos ? text.size() : next + 1;
      }
      return v;
    };
    const std::vector<double> a = guess(from_file->camera_guess), b = guess(built_in->camera_guess);
    ASSERT_EQ(a.size(), 6u);
    ASSERT_EQ(b.size(), 6u);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(a[k], b[k], 1e-9) << from_file->camera_guess;
    const Vec3 centre(a[0], a[1], a[2]);
    const Vec3 axis_a = (Vec3(a[3], a[4], a[5]) - centre).normalized(), axis_b = (Vec3(b[3], b[4], b[5]) - centre).normalized();
    EXPECT_GT(axis_a.dot(axis_b), std::cos(10.0 * M_PI / 180.0)) << from_file->camera_guess << " vs " << built_in->camera_guess;
    ASSERT_EQ(from_file->displays.size(), built_in->displays.size());
    EXPECT_EQ(from_file->displays[0]->Name(), "synthetic:" + file.string() + "/left");
    // Exact for quads; meshes read back from OBJ differ in summation order (below).
    EXPECT_NEAR(from_file->radiance_scale, built_in->radiance_scale, 1e-3 * built_in->radiance_scale) << name;

    const std::unique_ptr<Camera> camera = OpenCamera(file_uri), reference = OpenCamera(built_in_uri);
    const CameraSettings settings = camera->Settings(), expected = reference->Settings();
    EXPECT_EQ(settings.width, expected.width);
    EXPECT_EQ(settings.height, expected.height);
    EXPECT_EQ(settings.pixel_format, PixelFormat::kBGR8);
    EXPECT_EQ(settings.exposure_us, 1000.0) << "the URI's keys override the entry's";

    for (size_t k = 0; k < built_in->displays.size(); ++k) {
      const cv::Mat pattern = GradientPattern(built_in->displays[k]->Resolution(), static_cast<int>(k));
      built_in->displays[k]->Show(pattern);
      from_file->displays[k]->Show(pattern);
    }
    const int64_t now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                            std::chrono::steady_clock::now().time_since_epoch()).count();
    const cv::Mat view = MakeSyntheticView(from_file)(now), truth = MakeSyntheticView(built_in)(now);
    ASSERT_EQ(view.size(), truth.size());
    double brightest = 0.0;
    cv::minMaxLoc(truth.reshape(1), nullptr, &brightest);
    ASSERT_GT(brightest, 0.05) << name << ": the patterns light the room";
    cv::Mat difference;
    cv::absdiff(view, truth, difference);
    difference = difference.reshape(1);
    if (name == "tiny_box") {  // quads only: the same world, number for number
      EXPECT_LT(cv::norm(difference, cv::NORM_INF), 1e-6) << name;
    } else {
      // The OBJ reader numbers a mesh's welded vertices its own way, so the world mesh's
      // patches (the same ones) come in another order and sums round differently: the pictures
      // agree to 2e-5 on average (measured), with a handful of values off by more than 1e-3.
      EXPECT_LT(cv::mean(difference)[0], 1e-4) << name;
      EXPECT_LT(cv::countNonZero(difference > 1e-3), 1e-5 * difference.total()) << name;
    }
  }
}

// A scene file that cannot be a rig, or whose camera entry is wrong, is refused with one line
// naming the file and the key.
TEST(SyntheticCamera, SceneFileErrorsNameTheFileAndTheKey) {
  RegisterSyntheticCameraBackend();
  testing::TempDir dir;
  const std::filesystem::path file = WriteSyntheticSceneFile("tiny_box", 100, dir.path());
  const nlohmann::json scene = ReadJsonFile(file);
  const auto variant = [&](const std::string& name, const std::function<void(nlohmann::json&)>& change) {
    nlohmann::json copy = scene;
    change(copy);
    dir.Write(name + ".json", copy.dump(2));
    return (dir.path() / (name + ".json")).string();
  };
  struct Case {
    std::string uri, expected;
  };
  const Case cases[] = {
      {variant("no_cameras", [](nlohmann::json& s) { s.erase("cameras"); }),
       "no_cameras.json: cameras: a synthetic rig needs a camera"},
      {variant("no_projectors", [](nlohmann::json& s) { s.erase("projectors"); }),
       "no_projectors.json: projectors: a synthetic rig needs at least one projector"},
      {variant("gain", [](nlohmann::json& s) { s["cameras"][0]["gain_db"] = 30; }),
       "gain.json: cameras[0].gain_db: must be in [0, 24]"},
      {variant("exposure", [](nlohmann::json& s) { s["cameras"][0]["exposure_us"] = "long"; }),
       "exposure.json: cameras[0].exposure_us"},
      {variant("format", [](nlohmann::json& s) { s["cameras"][0]["format"] = "RGB565"; }),
       "format.json: cameras[0].format: unknown pixel format 'RGB565'"},
      {variant("unknown", [](nlohmann::json& s) { s["cameras"][0]["iso"] = 100; }),
       "unknown.json: cameras[0]"},
      {variant("model", [](nlohmann::json& s) { s["cameras"][0]["model"] = "gone.cameramodel"; }),
       "model.json: cameras[0].model: "},
      {variant("twice", [](nlohmann::json& s) { s["cameras"].push_back(s["cameras"][0]); }),
       "twice.json: cameras[1].name: 'camera' is already the name of another camera"},
      {variant("noise", [](nlohmann::json& s) { s["cameras"][0]["noise"] = -1; }),
       "noise.json: cameras[0].noise: must be in [0, full scale]"},
      {variant("projector_blur", [](nlohmann::json& s) { s["cameras"][0]["projector_blur"] = 25; }),
       "projector_blur.json: cameras[0].projector_blur: must be in [0, 20] projector pixels"},
      {variant("camera_blur", [](nlohmann::json& s) { s["cameras"][0]["camera_blur"] = -0.5; }),
       "camera_blur.json: cameras[0].camera_blur: must be in [0, 20] camera pixels"},
      {variant("ambient", [](nlohmann::json& s) { s["cameras"][0]["ambient"] = -0.1; }),
       "ambient.json: cameras[0].ambient: must be in [0, 10]"},
      {variant("jpeg", [](nlohmann::json& s) { s["cameras"][0]["jpeg_quality"] = 101; }),
       "jpeg.json: cameras[0].jpeg_quality: must be in [1, 100], or 0 for no JPEG"},
      {variant("jpeg_real", [](nlohmann::json& s) { s["cameras"][0]["jpeg_quality"] = 7.5; }),
       "jpeg_real.json: cameras[0].jpeg_quality: must be an integer"},
      {variant("jpeg_mono16", [](nlohmann::json& s) {
         s["cameras"][0].merge_patch({{"jpeg_quality", 80}, {"format", "Mono16"}});
       }),
       "jpeg_mono16.json: cameras[0].jpeg_quality: needs an 8-bit Mono8, RGB8 or BGR8 format, not Mono16"},
  };
  for (const Case& c : cases) {
    try {
      OpenCamera("synthetic:" + c.uri);
      ADD_FAILURE() << c.uri << " opened";
    } catch (const IoError& error) {
      const std::string what = error.what();
      EXPECT_NE(what.find(c.expected), std::string::npos) << what;
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
      EXPECT_EQ(what.rfind("camera 'synthetic:" + c.uri + "'", 0), 0u) << what;
    }
  }
  try {
    OpenCamera("synthetic:" + file.string() + "?camera=webcam");
    ADD_FAILURE() << "an unknown camera name opened";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("no camera named 'webcam' (cameras: camera)"), std::string::npos)
        << error.what();
  }
  // The entry's settings are the camera's defaults.
  const std::string noisy = variant("noisy", [](nlohmann::json& s) {
    s["cameras"][0].merge_patch({{"exposure_us", 2500}, {"gain_db", 6}, {"noise", 1.5}, {"format", "Mono8"},
                                 {"projector_blur", 1.5}, {"camera_blur", 0.7}, {"ambient", 0.2},
                                 {"jpeg_quality", 80}});
  });
  const std::unique_ptr<Camera> camera = OpenCamera("synthetic:" + noisy + "?patches=40");
  EXPECT_EQ(camera->Settings().exposure_us, 2500.0);
  EXPECT_EQ(camera->Settings().gain, 6.0);
  EXPECT_EQ(camera->Settings().pixel_format, PixelFormat::kMono8);
  const std::vector<SceneCamera> cameras = ParseSceneCameras(
      ReadJsonFile(noisy)["cameras"].dump(), noisy, dir.path());
  ASSERT_EQ(cameras.size(), 1u);
  EXPECT_EQ(cameras[0].settings.noise_sigma, 1.5);
  EXPECT_EQ(cameras[0].settings.projector_blur_px, 1.5);
  EXPECT_EQ(cameras[0].settings.camera_blur_px, 0.7);
  EXPECT_EQ(cameras[0].settings.ambient, 0.2);
  EXPECT_EQ(cameras[0].settings.jpeg_quality, 80);
  EXPECT_EQ(cameras[0].settings.width, 240);
  // A URI key overrides the entry's.
  const std::string uri = "synthetic:" + noisy + "?ambient=0.5&jpeg_quality=0";
  const TestCameraOptions overridden =
      TestCameraOptionsFromUri(CameraUri::Parse(uri), cameras[0].settings);
  EXPECT_EQ(overridden.ambient, 0.5);
  EXPECT_EQ(overridden.jpeg_quality, 0);
  EXPECT_EQ(overridden.camera_blur_px, 0.7);
}

// Every setting of a camera entry and a synthetic URI is declared once (TestCameraSettings) and
// documented in the camera table of docs/scene_format.md, in the declaration's words.
TEST(SyntheticCamera, EveryCameraSettingIsDocumented) {
  std::ifstream in(testing::SourceDir() / "docs" / "scene_format.md");
  const std::string scene_format((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(scene_format.empty());
  for (const TestCameraSetting& setting : TestCameraSettings()) {
    const std::string row = "| `" + std::string(setting.key) + "` | no | " + setting.meaning + " |";
    EXPECT_NE(scene_format.find(row), std::string::npos)
        << "docs/scene_format.md's camera table lacks the row\n" << row;
  }
}

TEST(SyntheticCamera, ListsOneVirtualCameraPerScene) {
  RegisterSyntheticCameraBackend();
  ListCamerasOptions options;
  options.gige_discovery = false;
  options.include_virtual = true;
  int synthetic = 0;
  for (const CameraInfo& info : ListCameras(options)) synthetic += info.backend == "synthetic";
  EXPECT_EQ(synthetic, static_cast<int>(SyntheticSceneNames().size()));
  options.include_virtual = false;
  for (const CameraInfo& info : ListCameras(options)) EXPECT_NE(info.backend, "synthetic");
}

}  // namespace
}  // namespace procam
