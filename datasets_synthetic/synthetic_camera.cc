#include "datasets_synthetic/synthetic_camera.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <mutex>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <tuple>
#include <utility>

#include "base/image_io.h"
#include "base/io.h"
#include "capture/scene_cameras.h"
#include "capture/simulated_camera.h"
#include "datasets_synthetic/chessboard_views.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/scene_files.h"
#include "geometry/scene.h"
#include "geometry/stage.h"
#include "projection/projector.h"

namespace procam {
namespace {

constexpr int kDefaultPatches = 300;
constexpr int kMinPatches = 20;
constexpr int kMaxPatches = 5000;  // the world mesh is 4× finer and its dense F is n²

std::string SceneList() {
  std::string list;
  for (const std::string& name : SyntheticSceneNames()) list += (list.empty() ? "" : ", ") + name;
  return list;
}

bool IsSceneName(const std::string& name) {
  const std::vector<std::string> names = SyntheticSceneNames();
  return std::find(names.begin(), names.end(), name) != names.end();
}


// RenderRadiance (R, G, B) → the SceneView's B, G, R, scaled.
cv::Mat ViewFromRadiance(const cv::Mat& radiance_rgb, double scale) {
  cv::Mat view(radiance_rgb.size(), CV_32FC3);
  const float s = static_cast<float>(scale);
  for (int row = 0; row < view.rows; ++row) {
    const cv::Vec3f* in = radiance_rgb.ptr<cv::Vec3f>(row);
    cv::Vec3f* out = view.ptr<cv::Vec3f>(row);
    for (int col = 0; col < view.cols; ++col)
      out[col] = cv::Vec3f(s * in[col][2], s * in[col][1], s * in[col][0]);
  }
  return view;
}

bool SamePattern(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  if (a.data == b.data) return true;  // the display hands out the buffer it keeps
  return cv::norm(a, b, cv::NORM_INF) == 0.0;
}

// What a synthetic URI names: a built-in scene or a scene file (with its camera), the patch
// count and the albedo variation. Throws IoError naming the URI.
struct SyntheticUri {
  std::string scene;  // the URI's path
  std::filesystem::path file;  // a scene file, made absolute (empty for a built-in scene)
  std::string camera;  // the scene file's camera ("" = its first)
  int patches = 0;
  double albedo_variation = 0.0;
  int board_pose = -1;  // the scene file's chessboard pose photographed; −1: the room
  bool operator<(const SyntheticUri& other) const {
    return std::tie(scene, file, camera, patches, albedo_variation, board_pose) <
           std::tie(other.scene, other.file, other.camera, other.patches, other.albedo_variation,
                    other.board_pose);
  }
};

bool IsSceneFile(const std::string& path) {
  return path.size() > 5 && path.compare(path.size() - 5, 5, ".json") == 0;
}

SyntheticUri ParseSyntheticUri(const CameraUri& uri) {
  if (uri.scheme() != "synthetic")
    throw IoError("camera '" + uri.text() + "': not a synthetic: camera URI");
  SyntheticUri parsed;
  parsed.scene = uri.path();
  if (IsSceneFile(uri.path())) {
    parsed.file = std::filesystem::absolute(uri.path()).lexically_normal();
    parsed.camera = uri.GetString("camera", "");
    parsed.board_pose = uri.GetInt("board_pose", -1);
    if (parsed.board_pose < -1)
      throw IoError("camera '" + uri.text() +
                    "': board_pose must be a pose of the scene file's "
                    "chessboard, from 0");
  } else if (!IsSceneName(uri.path())) {
    throw IoError("camera '" + uri.text() + "': unknown synthetic scene '" + uri.path() +
                  "' (scenes: " + SceneList() + ", or a scene file ROOM.json)");
  }
  parsed.patches = uri.GetInt("patches", kDefaultPatches);
  if (parsed.patches < kMinPatches || parsed.patches > kMaxPatches) {
    throw IoError("camera '" + uri.text() + "': patches must be in [" +
                  std::to_string(kMinPatches) + ", " + std::to_string(kMaxPatches) + "], got " +
                  std::to_string(parsed.patches));
  }
  parsed.albedo_variation = uri.GetDouble("albedo", 0.0);
  if (!(parsed.albedo_variation >= 0.0 && parsed.albedo_variation < 0.5)) {
    throw IoError("camera '" + uri.text() + "': albedo must be in [0, 0.5), got " +
                  std::to_string(parsed.albedo_variation));
  }
  return parsed;
}

void CheckPatches(const std::string& scene, int patches) {
  if (patches < kMinPatches || patches > kMaxPatches) {
    throw std::invalid_argument("synthetic scene '" + scene + "': patches must be in [" +
                                std::to_string(kMinPatches) + ", " + std::to_string(kMaxPatches) +
                                "], got " + std::to_string(patches));
  }
}

// A tape-measure guess of a camera's pose: its position rounded to 5 cm and the point it aims
// at rounded to 25 cm (what someone standing in the room would write down).
std::string CameraGuess(const Vec3& centre, const Vec3& target) {
  const auto round = [](double value, double step) { return std::round(value / step) * step; };
  return fmt::format("{},{},{},{},{},{}", round(centre.x(), 0.05), round(centre.y(), 0.05),
                     round(centre.z(), 0.05), round(target.x(), 0.25), round(target.y(), 0.25),
                     round(target.z(), 0.25));
}

// The world of a scene, its projectors and camera: the rig, one display per projector and the
// radiance scale (one full-white render). `world` holds the names and settings already.
std::shared_ptr<SyntheticWorld> BuildWorld(std::shared_ptr<SyntheticWorld> world, const Scene& scene,
                                           std::vector<Projector> projectors, CameraGeometry camera,
                                           double albedo_variation) {
  SimulatedRigOptions options;
  options.solver_patches = world->patches;
  options.albedo_variation = albedo_variation;
  auto rig = std::make_shared<SimulatedRig>(scene, std::move(projectors), std::move(camera), options);
  std::vector<ProjectorImage> white;
  for (const Projector& projector : rig->projectors()) {
    world->displays.push_back(std::make_shared<MemoryDisplay>(
        cv::Size(projector.geometry.width(), projector.geometry.height()),
        "synthetic:" + world->scene + "/" + projector.name));
    ProjectorImage image;
    image.bits = projector.photometry.bits;
    image.codes = cv::Mat(projector.geometry.height(), projector.geometry.width(), CV_16UC3,
                          cv::Scalar::all(projector.photometry.MaxCode()));
    white.push_back(std::move(image));
  }
  double brightest = 0.0;
  cv::minMaxLoc(rig->RenderRadiance(white).reshape(1), nullptr, &brightest);
  world->radiance_scale = brightest > 0.0 ? 1.0 / brightest : 1.0;
  world->rig = std::move(rig);
  return world;
}

// What projector `projector` emits for `image` per pixel (ProjectorPhotometry::Output of the
// codes: CV_32FC3, R, G, B); empty for an image that is black everywhere and a projector without
// black level (it adds nothing).
cv::Mat ProjectorOutput(const ProjectorImage& image, const Projector& projector) {
  const ProjectorPhotometry& photometry = projector.photometry;
  if (photometry.black.isZero() && cv::countNonZero(image.codes.reshape(1)) == 0) return cv::Mat();
  const int max_code = photometry.MaxCode();
  std::array<std::vector<float>, 3> light_of_code;  // per channel, code → relative light
  for (int c = 0; c < 3; ++c) {
    light_of_code[c].resize(max_code + 1);
    for (int code = 0; code <= max_code; ++code)
      light_of_code[c][code] =
          static_cast<float>(photometry.response[c].Light(static_cast<double>(code) / max_code));
  }
  const Eigen::Matrix3d to_output_d =
      (photometry.max - photometry.black).asDiagonal() * photometry.mixing;
  const Eigen::Matrix3f to_output = to_output_d.cast<float>();
  const Eigen::Vector3f black = photometry.black.cast<float>();
  cv::Mat output(image.codes.size(), CV_32FC3);
  for (int row = 0; row < output.rows; ++row) {
    const cv::Vec3w* in = image.codes.ptr<cv::Vec3w>(row);
    cv::Vec3f* out = output.ptr<cv::Vec3f>(row);
    for (int col = 0; col < output.cols; ++col) {
      const Eigen::Vector3f light(light_of_code[0][std::min<int>(in[col][0], max_code)],
                                  light_of_code[1][std::min<int>(in[col][1], max_code)],
                                  light_of_code[2][std::min<int>(in[col][2], max_code)]);
      const Eigen::Vector3f value = black + to_output * light;
      out[col] = cv::Vec3f(value.x(), value.y(), value.z());
    }
  }
  return output;
}

// The world's board (PlaceSceneChessboard) lit by `images`: radiance R, G, B.
cv::Mat RenderBoard(const SyntheticWorld& world, const std::vector<ProjectorImage>& images) {
  std::vector<cv::Mat> outputs;
  for (size_t k = 0; k < images.size(); ++k)
    outputs.push_back(ProjectorOutput(images[k], world.rig->projectors()[k]));
  return world.board->RenderRadiance(outputs);
}

// A built-in scene's rig: its projectors and camera (with distortion) from their placements.
SyntheticRigSource RigFromPlacements(const SyntheticScene& synthetic) {
  SyntheticRigSource source;
  source.scene = synthetic.scene;
  for (const DevicePlacement& placement : synthetic.projectors)
    source.projectors.push_back(ProjectorFromPlacement(placement));
  source.camera = CameraFromPlacement(synthetic.camera);
  return source;
}

}  // namespace

ProjectorImage CodesFromPattern(const cv::Mat& pattern, const Projector& projector) {
  const int width = projector.geometry.width(), height = projector.geometry.height();
  if (pattern.cols != width || pattern.rows != height ||
      (pattern.type() != CV_8UC1 && pattern.type() != CV_8UC3)) {
    throw std::invalid_argument(
        "synthetic view: projector '" + projector.name + "' is " + std::to_string(width) + "x" +
        std::to_string(height) + ", its display shows a " + std::to_string(pattern.cols) + "x" +
        std::to_string(pattern.rows) + " pattern of type " + std::to_string(pattern.type()));
  }
  ProjectorImage image;
  image.bits = projector.photometry.bits;
  image.codes.create(height, width, CV_16UC3);
  const int max_code = projector.photometry.MaxCode();
  uint16_t table[256];  // 8-bit value → code, rounded
  for (int value = 0; value < 256; ++value)
    table[value] = static_cast<uint16_t>((value * max_code + 127) / 255);
  const bool grey = pattern.channels() == 1;
  for (int row = 0; row < height; ++row) {
    const uint8_t* in = pattern.ptr<uint8_t>(row);
    cv::Vec3w* out = image.codes.ptr<cv::Vec3w>(row);
    for (int col = 0; col < width; ++col) {
      if (grey) {
        const uint16_t code = table[in[col]];
        out[col] = cv::Vec3w(code, code, code);
      } else {
        const uint8_t* bgr = in + 3 * col;
        out[col] = cv::Vec3w(table[bgr[2]], table[bgr[1]], table[bgr[0]]);
      }
    }
  }
  return image;
}

std::shared_ptr<SyntheticWorld> MakeSyntheticWorld(const std::string& scene, int patches,
                                                   double albedo_variation) {
  if (!IsSceneName(scene)) {
    throw std::invalid_argument("unknown synthetic scene '" + scene + "' (scenes: " + SceneList() +
                                ")");
  }
  CheckPatches(scene, patches);
  const SyntheticScene synthetic = MakeSyntheticScene(scene, patches);
  SyntheticRigSource source = RigFromPlacements(synthetic);
  auto world = std::make_shared<SyntheticWorld>();
  world->scene = scene;
  world->scene_source = "synthetic:" + scene;
  world->patches = patches;
  world->camera_settings.name = scene;
  world->camera_settings.width = synthetic.camera.width;
  world->camera_settings.height = synthetic.camera.height;
  world->camera_settings.pixel_format = PixelFormat::kBGR8;
  world->camera_guess = CameraGuess(synthetic.camera.centre, synthetic.camera.target);
  return BuildWorld(world, source.scene, std::move(source.projectors), std::move(source.camera),
                    albedo_variation);
}

SyntheticRigSource LoadSceneFileRig(const std::filesystem::path& scene_file,
                                    const std::string& camera, int patches) {
  const std::string file = scene_file.string();
  CheckPatches(file, patches);
  SyntheticRigSource source;
  source.scene = LoadScene(scene_file);
  source.scene.target_patches = patches;
  source.projectors = ReadProjectors(source.scene);
  ReadSceneChessboard(scene_file);  // its errors whether or not a board pose is photographed
  if (source.projectors.empty())
    throw IoError(file + ": projectors: a synthetic rig needs at least one projector");
  const std::vector<SceneCamera> cameras =
      ParseSceneCameras(source.scene.cameras_json, file, scene_file.parent_path());
  if (cameras.empty()) throw IoError(file + ": cameras: a synthetic rig needs a camera");
  size_t index = 0;
  if (!camera.empty()) {
    std::string names;
    while (index < cameras.size() && cameras[index].name != camera) {
      names += (names.empty() ? "" : ", ") + cameras[index].name;
      ++index;
    }
    if (index == cameras.size())
      throw IoError(file + ": cameras: no camera named '" + camera + "' (cameras: " + names + ")");
  }
  source.camera_entry = cameras[index];
  try {
    source.camera = CameraGeometry::FromModel(source.camera_entry.model);
  } catch (const std::invalid_argument& error) {
    throw IoError(file + ": cameras[" + std::to_string(index) + "].model: " + error.what());
  }
  return source;
}

SyntheticRigSource LoadSyntheticRig(const std::string& scene, int patches) {
  if (IsSceneFile(scene)) return LoadSceneFileRig(scene, "", patches);
  return RigFromPlacements(MakeSyntheticScene(scene, patches));
}

std::shared_ptr<SyntheticWorld> MakeSceneFileWorld(const std::filesystem::path& scene_file,
                                                   const std::string& camera, int patches,
                                                   double albedo_variation, const std::string& uri_path) {
  SyntheticRigSource source = LoadSceneFileRig(scene_file, camera, patches);
  const std::string file = scene_file.string();
  auto world = std::make_shared<SyntheticWorld>();
  world->scene = uri_path.empty() ? file : uri_path;
  world->scene_source = file;
  world->patches = patches;
  world->camera_settings = source.camera_entry.settings;
  world->camera_settings.name = world->scene;
  const Eigen::Isometry3d world_from_camera = source.camera_entry.model.cam_from_ref.inverse();
  const Vec3 centre = world_from_camera.translation();
  world->camera_guess = CameraGuess(centre, centre + 3.0 * world_from_camera.linear().col(2));
  return BuildWorld(world, source.scene, std::move(source.projectors), std::move(source.camera),
                    albedo_variation);
}

void PlaceSceneChessboard(SyntheticWorld* world, const std::filesystem::path& scene_file,
                          int pose) {
  const std::string file = scene_file.string();
  const std::optional<SceneChessboard> chessboard = ReadSceneChessboard(scene_file);
  if (!chessboard)
    throw IoError(file +
                  ": chessboard: missing (board_pose needs the scene file's chessboard, "
                  "docs/scene_format.md)");
  if (pose < 0 || pose >= static_cast<int>(chessboard->poses.size()))
    throw IoError(file + ": chessboard.poses: no pose " + std::to_string(pose) + " (it has " +
                  std::to_string(chessboard->poses.size()) + ")");
  const SimulatedRig& rig = *world->rig;
  std::vector<ProjectorGeometry> projectors;
  for (const Projector& projector : rig.projectors()) projectors.push_back(projector.geometry);
  auto board = std::make_shared<BoardInRoom>(
      rig.camera(), projectors, chessboard->board, chessboard->CamFromBoard(pose),
      chessboard->dark_reflectance, chessboard->light_reflectance);
  if (board->rays_on_board() == 0)
    throw IoError(file + ": chessboard.poses[" + std::to_string(pose) +
                  "]: the board is not in the camera's view");
  world->board = board;
  world->board_pose = pose;
  // Radiance 1: the board's brightest pixel with every projector at full white.
  std::vector<ProjectorImage> white;
  for (const Projector& projector : rig.projectors()) {
    ProjectorImage image;
    image.bits = projector.photometry.bits;
    image.codes = cv::Mat(projector.geometry.height(), projector.geometry.width(), CV_16UC3,
                          cv::Scalar::all(projector.photometry.MaxCode()));
    white.push_back(std::move(image));
  }
  double brightest = 0.0;
  cv::minMaxLoc(RenderBoard(*world, white).reshape(1), nullptr, &brightest);
  world->radiance_scale = brightest > 0.0 ? 1.0 / brightest : 1.0;
}

ProjectorImage DefocusProjectorCodes(const ProjectorImage& codes, const Projector& projector,
                                     double sigma_px) {
  if (!(sigma_px > 0.0)) return codes;
  const ProjectorPhotometry& photometry = projector.photometry;
  const int max_code = photometry.MaxCode();
  std::array<std::vector<float>, 3> light_of_code;  // per channel, code → relative light
  for (int c = 0; c < 3; ++c) {
    light_of_code[c].resize(max_code + 1);
    for (int code = 0; code <= max_code; ++code)
      light_of_code[c][code] = static_cast<float>(photometry.response[c].Light(static_cast<double>(code) / max_code));
  }
  cv::Mat light(codes.codes.size(), CV_32FC3);
  for (int row = 0; row < light.rows; ++row) {
    const cv::Vec3w* in = codes.codes.ptr<cv::Vec3w>(row);
    cv::Vec3f* out = light.ptr<cv::Vec3f>(row);
    for (int col = 0; col < light.cols; ++col)
      for (int c = 0; c < 3; ++c) out[col][c] = light_of_code[c][std::min<int>(in[col][c], max_code)];
  }
  cv::Mat blurred;
  cv::GaussianBlur(light, blurred, cv::Size(0, 0), sigma_px, sigma_px, cv::BORDER_CONSTANT);
  ProjectorImage defocused;
  defocused.bits = codes.bits;
  defocused.codes.create(codes.codes.size(), CV_16UC3);
  for (int row = 0; row < light.rows; ++row) {
    const cv::Vec3f* in = blurred.ptr<cv::Vec3f>(row);
    cv::Vec3w* out = defocused.codes.ptr<cv::Vec3w>(row);
    for (int col = 0; col < light.cols; ++col)
      for (int c = 0; c < 3; ++c)
        out[col][c] = static_cast<uint16_t>(std::lround(max_code * photometry.response[c].Drive(in[col][c])));
  }
  return defocused;
}

SceneView MakeSyntheticView(std::shared_ptr<const SyntheticWorld> world, double projector_blur_px) {
  if (!world || !world->rig) throw std::invalid_argument("MakeSyntheticView: no world");
  if (world->displays.size() != world->rig->projectors().size()) {
    throw std::invalid_argument("MakeSyntheticView: " + std::to_string(world->displays.size()) +
                                " displays for " + std::to_string(world->rig->projectors().size()) +
                                " projectors");
  }
  struct Cache {
    std::mutex mutex;
    std::vector<cv::Mat> shown;  // the patterns of the last render (held: their buffers stay)
    cv::Mat view;                // its SceneView image
  };
  auto cache = std::make_shared<Cache>();
  return [world, cache, projector_blur_px](int64_t exposure_start_ns) -> cv::Mat {
    std::vector<cv::Mat> shown;
    for (const auto& display : world->displays)
      shown.push_back(display->ShownAt(exposure_start_ns));
    std::lock_guard<std::mutex> lock(cache->mutex);
    bool same = !cache->view.empty();
    for (size_t k = 0; same && k < shown.size(); ++k) same = SamePattern(shown[k], cache->shown[k]);
    if (!same) {
      const SimulatedRig& rig = *world->rig;
      std::vector<ProjectorImage> images;
      for (size_t k = 0; k < shown.size(); ++k)
        images.push_back(DefocusProjectorCodes(CodesFromPattern(shown[k], rig.projectors()[k]),
                                               rig.projectors()[k], projector_blur_px));
      const cv::Mat radiance =
          world->board ? RenderBoard(*world, images) : rig.RenderRadiance(images);
      cache->view = ViewFromRadiance(radiance, world->radiance_scale);
      cache->shown = std::move(shown);
      ++world->renders;
    }
    return cache->view.clone();  // the camera may scale it in place
  };
}

double CameraValuePerExitance(const SyntheticWorld& world, const TestCameraOptions& camera, double exposure_us,
                              double gain_db, double full_scale) {
  return world.radiance_scale * full_scale * exposure_us / camera.reference_exposure_us *
         std::pow(10.0, gain_db / 20.0);
}

std::shared_ptr<SyntheticWorld> OpenSyntheticWorld(const CameraUri& uri) {
  const SyntheticUri key = ParseSyntheticUri(uri);
  // Alive worlds by scene, patch count and albedo; a world goes when its last holder lets it go,
  // so a camera opened later starts with dark displays rather than an earlier run's patterns.
  static std::mutex mutex;
  static std::map<SyntheticUri, std::weak_ptr<SyntheticWorld>> worlds;
  std::lock_guard<std::mutex> lock(mutex);
  std::weak_ptr<SyntheticWorld>& slot = worlds[key];
  if (std::shared_ptr<SyntheticWorld> alive = slot.lock()) return alive;
  std::shared_ptr<SyntheticWorld> world;
  if (key.file.empty()) {
    world = MakeSyntheticWorld(key.scene, key.patches, key.albedo_variation);
  } else {
    try {  // the file as the URI names it, so that errors name it so too
      world = MakeSceneFileWorld(key.scene, key.camera, key.patches, key.albedo_variation, key.scene);
      if (key.board_pose >= 0) PlaceSceneChessboard(world.get(), key.scene, key.board_pose);
    } catch (const IoError& error) {
      throw IoError("camera '" + uri.text() + "': " + error.what());
    }
  }
  slot = world;
  return world;
}

SyntheticCamera::SyntheticCamera(const TestCameraOptions& options,
                                 std::shared_ptr<SyntheticWorld> world)
    : TestCamera(options, MakeSyntheticView(world, options.projector_blur_px), ViewHasProjectorBlur{}),
      world_(std::move(world)) {}

CameraInfo SyntheticCamera::Info() const {
  CameraInfo info = TestCamera::Info();
  const CameraSettings settings = Settings();
  info.uri = "synthetic:" + world_->scene;
  info.backend = "synthetic";
  info.model = "simulated rig camera";
  info.serial = world_->scene;
  info.description = "simulated camera of synthetic scene " + world_->scene + " (" +
                     std::to_string(world_->displays.size()) + " projectors), " +
                     std::to_string(settings.width) + "x" + std::to_string(settings.height) + " " +
                     PixelFormatName(settings.pixel_format);
  return info;
}

CameraBackend SyntheticCameraBackend() {
  CameraBackend backend;
  backend.scheme = "synthetic";
  backend.description = "the simulated rig's camera in a synthetic scene (datasets_synthetic)";
  backend.open = [](const CameraUri& uri, const OpenCameraOptions&) -> std::unique_ptr<Camera> {
    ParseSyntheticUri(uri);  // its own keys first, so CheckAllRead below knows them
    TestCameraOptionsFromUri(uri);  // rejects unknown keys before the world is built
    const std::shared_ptr<SyntheticWorld> world = OpenSyntheticWorld(uri);
    return std::make_unique<SyntheticCamera>(TestCameraOptionsFromUri(uri, world->camera_settings), world);
  };
  backend.list = [](const ListCamerasOptions& options) {
    std::vector<CameraInfo> cameras;
    if (!options.include_virtual) return cameras;
    for (const std::string& name : SyntheticSceneNames()) {
      const SyntheticScene scene = MakeSyntheticScene(name, kMinPatches);
      CameraInfo info;
      info.uri = "synthetic:" + name;
      info.backend = "synthetic";
      info.vendor = "procam";
      info.model = "simulated rig camera";
      info.serial = name;
      info.description = "simulated room, " + std::to_string(scene.projectors.size()) +
                         " projectors (" + std::to_string(scene.projectors[0].width) + "x" +
                         std::to_string(scene.projectors[0].height) + "), camera " +
                         std::to_string(scene.camera.width) + "x" +
                         std::to_string(scene.camera.height) + " BGR8";
      cameras.push_back(std::move(info));
    }
    return cameras;
  };
  return backend;
}

void RegisterSyntheticCameraBackend() {
  static std::once_flag once;
  std::call_once(once, [] { RegisterCameraBackend(SyntheticCameraBackend()); });
}

namespace {

// The synthetic camera's k: radiance_scale × full scale × exposure / reference × gain, per DN
// (one exposure) or per full scale per second (HDR), as calibrate photometric derives it.
double SyntheticValuePerExitance(const CameraUri& uri, const SyntheticWorld& world, const nlohmann::json& manifest,
                                 bool hdr, double full_scale, double black) {
  const TestCameraOptions camera = TestCameraOptionsFromUri(uri, world.camera_settings);
  const nlohmann::json settings = manifest.value("camera", nlohmann::json::object())
                                      .value("settings", nlohmann::json::object());
  const double gain = std::pow(10.0, settings.value("gain", 0.0) / 20.0);
  const double full = full_scale > 0.0 ? full_scale : 255.0;
  if (hdr) {  // the HDR merge: (DN − black) / (full − black) per second
    return world.radiance_scale * full / (full - black) * gain / (camera.reference_exposure_us * 1e-6);
  }
  return CameraValuePerExitance(world, camera, settings.value("exposure_us", camera.exposure_us),
                                settings.value("gain", 0.0), full);
}

// The synthetic camera's chessboard photos: the rig's own camera (its lens, not its pose) sees
// a board of `board` held in ten poses. Written as 8-bit PNGs into `folder`.
int RenderSyntheticChessboard(const SyntheticWorld& world, const ChessboardSpec& board,
                              const std::filesystem::path& folder) {
  std::filesystem::create_directories(folder);
  const CameraGeometry& camera = world.rig->camera();
  const std::vector<Eigen::Isometry3d> poses = ChessboardPoses(camera, board);
  for (size_t v = 0; v < poses.size(); ++v) {
    const cv::Mat image = RenderChessboard(camera, board, poses[v], 0.01, 100 + v);
    WritePng(folder / fmt::format("{:03d}_board.png", v), image);
  }
  return static_cast<int>(poses.size());
}

// A photo of a chessboard of `corners_x` × `corners_y` inner corners lying flat on the floor
// (z = 0) in front of the camera, from the camera's own pose (calibration/floor_chessboard.h: the
// scan's metric scale); returns its square size, metres. The board's rows run along the camera's
// image rows; it is centred on the floor point seen at the image's centre column and the lowest
// row (of 80%, 75%, ... 55% of the height) from which the whole board is in view, its squares
// sized (whole centimetres) so that it spans about 45% of the image's width there.
double RenderSyntheticFloorChessboard(const SyntheticWorld& world, int corners_x, int corners_y,
                                      const std::filesystem::path& file) {
  const CameraGeometry& camera = world.rig->camera();
  const Eigen::Isometry3d world_from_cam = camera.proj_from_world().inverse();
  Vec3 x_axis = world_from_cam.linear().col(0);
  x_axis.z() = 0.0;
  if (x_axis.norm() < 1e-6)
    throw IoError("synthetic:" + world.scene + ": the camera looks straight down or up");
  x_axis.normalize();
  const Vec3 z_axis = Vec3::UnitZ(), y_axis = z_axis.cross(x_axis);
  for (const double fraction : {0.88, 0.84, 0.8, 0.75, 0.7, 0.65, 0.6, 0.55}) {
    const Vec3 ray = world_from_cam.linear() *
                     camera.Unproject(Vec2(camera.width() / 2.0, fraction * camera.height()));
    if (!(ray.z() < 0.0)) continue;
    const Vec3 eye = world_from_cam.translation();
    const Vec3 centre = eye - eye.z() / ray.z() * ray;
    ChessboardSpec board;
    board.corners_x = corners_x;
    board.corners_y = corners_y;
    const double width = 0.6 * camera.width() * (centre - eye).norm() / camera.intrinsics()[0];
    board.square_size = std::max(0.01, std::round(100.0 * width / (corners_x + 1)) / 100.0);
    const double s = board.square_size;
    Eigen::Isometry3d world_from_board = Eigen::Isometry3d::Identity();
    world_from_board.linear().col(0) = x_axis;
    world_from_board.linear().col(1) = y_axis;
    world_from_board.linear().col(2) = z_axis;
    world_from_board.translation() =
        centre - (corners_x - 1) * s / 2.0 * x_axis - (corners_y - 1) * s / 2.0 * y_axis;
    bool in_view = true;
    for (const double u : {-1.0, corners_x + 0.0})
      for (const double v : {-1.0, corners_y + 0.0}) {
        Vec2 pixel;
        in_view = in_view && camera.Project(world_from_board * Vec3(u * s, v * s, 0.0), &pixel) &&
                  pixel.x() > 0.03 * camera.width() && pixel.x() < 0.97 * camera.width() &&
                  pixel.y() > 0.03 * camera.height() && pixel.y() < 0.97 * camera.height();
      }
    if (!in_view) continue;
    const Eigen::Isometry3d cam_from_board = camera.proj_from_world() * world_from_board;
    std::filesystem::create_directories(file.parent_path());
    WritePng(file, RenderChessboard(camera, board, cam_from_board, 0.01, 7));
    return s;
  }
  throw IoError("synthetic:" + world.scene +
                ": no place on the floor (z = 0) shows the whole chessboard to the camera");
}

}  // namespace

void RegisterSyntheticWorld() {
  static std::once_flag once;
  std::call_once(once, [] {
    RegisterSyntheticCameraBackend();
    SceneSource source;
    source.names = SyntheticSceneNames;
    source.make = [](const std::string& name) {
      std::string known;
      for (const std::string& scene : SyntheticSceneNames()) {
        if (scene == name) return MakeSyntheticScene(name).scene;
        known += (known.empty() ? "" : ", ") + scene;
      }
      throw IoError("synthetic:" + name + ": no such synthetic scene (" + known + ")");
    };
    RegisterSceneSource("synthetic", std::move(source));
    RegisterSimulatedCameraSource("synthetic", [](const std::string& text) {
      const CameraUri uri = CameraUri::Parse(text);
      const std::shared_ptr<SyntheticWorld> world = OpenSyntheticWorld(uri);
      SimulatedCamera camera;
      camera.description = "synthetic scene '" + world->scene + "'";
      for (const Projector& projector : world->rig->projectors()) camera.projector_names.push_back(projector.name);
      camera.displays.assign(world->displays.begin(), world->displays.end());
      camera.black_level = TestCameraOptionsFromUri(uri, world->camera_settings).black_level;
      camera.scene = world->scene_source;
      camera.patches = world->patches;
      camera.camera_guess = world->camera_guess;
      camera.render_chessboard = [world](int corners_x, int corners_y, double square,
                                         const std::filesystem::path& folder) {
        ChessboardSpec board;
        board.corners_x = corners_x;
        board.corners_y = corners_y;
        board.square_size = square;
        return RenderSyntheticChessboard(*world, board, folder);
      };
      camera.render_floor_chessboard = [world](int corners_x, int corners_y,
                                               const std::filesystem::path& file) {
        return RenderSyntheticFloorChessboard(*world, corners_x, corners_y, file);
      };
      camera.value_per_exitance = [uri, world](const nlohmann::json& manifest, bool hdr, double full_scale,
                                               double black) {
        return Eigen::Vector3d::Constant(SyntheticValuePerExitance(uri, *world, manifest, hdr, full_scale, black));
      };
      return camera;
    });
  });
}

}  // namespace procam
