#include "datasets_synthetic/scene_files.h"

#include <fmt/format.h>

#include <nlohmann/json.hpp>
#include <numbers>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <utility>
#include <vector>

#include "base/camera_model.h"
#include "base/image_io.h"
#include "base/io.h"
#include "base/json_fields.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/simulated_rig.h"
#include "geometry/srgb.h"

namespace procam {
namespace {

using json = nlohmann::ordered_json;

json Triple(const Vec3& v) { return {v[0], v[1], v[2]}; }

// A file name made of the surface's name (letters, digits, '_', '-').
std::string FileStem(const std::string& text) {
  std::string stem;
  for (char c : text) stem += std::isalnum(static_cast<unsigned char>(c)) || c == '-' ? c : '_';
  return stem;
}

// A linear RGB texture (CV_32FC3, row 0 = top) as a 16-bit sRGB PNG (B, G, R as PNGs store it).
std::string TexturePng(const std::filesystem::path& path, const cv::Mat& linear_rgb) {
  cv::Mat bgr(linear_rgb.size(), CV_16UC3);
  for (int row = 0; row < bgr.rows; ++row) {
    const cv::Vec3f* in = linear_rgb.ptr<cv::Vec3f>(row);
    cv::Vec3w* out = bgr.ptr<cv::Vec3w>(row);
    for (int col = 0; col < bgr.cols; ++col) {
      for (int c = 0; c < 3; ++c) {
        out[col][2 - c] = cv::saturate_cast<ushort>(65535.0 * LinearToSrgb(std::clamp<double>(in[col][c], 0.0, 1.0)));
      }
    }
  }
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", bgr, bytes)) throw IoError(path.string() + ": cannot encode PNG");
  return std::string(bytes.begin(), bytes.end());
}

json ProjectorEntry(const Projector& projector, const std::string& model) {
  const ProjectorPhotometry& photometry = projector.photometry;
  json gamma = json::array();
  for (const ResponseCurve& curve : photometry.response) gamma.push_back(curve.gamma());
  json mixing = json::array();
  for (int r = 0; r < 3; ++r) mixing.push_back(Triple(photometry.mixing.row(r).transpose()));
  return {{"name", projector.name},           {"model", model},
          {"black", Triple(photometry.black)}, {"max", Triple(photometry.max)},
          {"gamma", gamma},                   {"mixing", mixing},
          {"bits", photometry.bits}};
}

}  // namespace

std::filesystem::path WriteSyntheticSceneFile(const std::string& name, int patches,
                                              const std::filesystem::path& dir) {
  return WriteSyntheticSceneFile(MakeSyntheticScene(name, patches), name,
                                 "procam's built-in synthetic scene " + name, dir);
}

std::filesystem::path WriteSyntheticSceneFile(const SyntheticScene& synthetic,
                                              const std::string& name,
                                              const std::string& description,
                                              const std::filesystem::path& dir) {
  const int patches = synthetic.scene.target_patches;
  // Every file is made first, then checked against what `dir` holds, then written: a file
  // edited by hand is never replaced, and a refusal leaves nothing new behind.
  std::vector<std::pair<std::string, std::string>> files;  // name in `dir`, bytes
  const Scene& scene = synthetic.scene;
  json surfaces = json::array();
  for (const Surface& surface : scene.surfaces) {
    json entry = {{"name", surface.name}, {"reflectance", Triple(surface.reflectance)}};
    const std::string stem = FileStem(name + "_" + surface.name);
    if (surface.kind == Surface::Kind::kQuad) {
      entry["quad"] = json::array();
      for (const Vec3& corner : surface.quad) entry["quad"].push_back(Triple(corner));
    } else {
      files.emplace_back(stem + ".obj", ObjMeshText(surface, "written by procam scene write"));
      entry["mesh"] = stem + ".obj";
    }
    if (surface.reflectance_texture.HasTexture()) {
      const ReflectanceTexture& texture = surface.reflectance_texture;
      files.emplace_back(stem + "_reflectance.png",
                         TexturePng(dir / (stem + "_reflectance.png"), texture.texture_linear));
      entry["reflectance"] = {{"texture", stem + "_reflectance.png"}, {"scale", texture.scale}};
    }
    if (surface.desired.HasTexture()) {
      files.emplace_back(stem + ".png", TexturePng(dir / (stem + ".png"), surface.desired.texture_linear));
      entry["desired"] = {{"texture", stem + ".png"}};
    } else {
      entry["desired"] = Triple(surface.desired.srgb);
    }
    surfaces.push_back(entry);
  }
  json projectors = json::array();
  for (const DevicePlacement& placement : synthetic.projectors) {
    const Projector projector = ProjectorFromPlacement(placement);
    const std::string model = FileStem(name + "_" + projector.name) + ".cameramodel";
    files.emplace_back(model, CameraModelText(projector.geometry));
    projectors.push_back(ProjectorEntry(projector, model));
  }
  const std::string camera_model = FileStem(name + "_camera") + ".cameramodel";
  files.emplace_back(camera_model,
                     CameraModelText(CameraFromPlacement(synthetic.camera).Model(),
                                     "procam synthetic camera of " + name +
                                         "; extrinsics = mrcal rt_cam_ref with ref = world"));
  const json file = {
      {"name", name},
      {"description", description},
      {"patches", patches},
      {"white", scene.white},
      {"weld_tolerance", scene.weld_tolerance},
      {"surfaces", surfaces},
      {"projectors", projectors},
      {"cameras", json::array({{{"name", "camera"}, {"model", camera_model}, {"format", "BGR8"}}})}};
  files.emplace_back(name + ".json", file.dump(2) + "\n");  // last: the file that names the rest

  std::error_code error;
  if (std::filesystem::exists(dir, error) && !std::filesystem::is_directory(dir, error)) {
    throw IoError(dir.string() + ": --out must be a directory, and this is a file");
  }
  for (const auto& [file_name, bytes] : files) {
    const std::filesystem::path path = dir / file_name;
    const std::filesystem::file_status status = std::filesystem::symlink_status(path, error);
    if (!std::filesystem::exists(status)) continue;
    if (!std::filesystem::is_regular_file(status)) {
      throw IoError(path.string() + ": exists and is not a regular file; scene write writes nothing");
    }
    if (ReadFile(path) != bytes) {
      throw IoError(path.string() + ": exists and differs from what scene write would write " +
                    "(edited?); scene write replaces nothing: remove it or give another --out");
    }
  }
  std::filesystem::create_directories(dir, error);
  if (error) throw IoError(dir.string() + ": cannot create directory: " + error.message());
  for (const auto& [file_name, bytes] : files) WriteFileAtomically(dir / file_name, bytes);
  return dir / (name + ".json");
}

}  // namespace procam

namespace procam {

Eigen::Isometry3d SceneChessboard::CamFromBoard(size_t k) const {
  const Pose& pose = poses.at(k);
  const double deg = std::numbers::pi / 180.0;
  Eigen::Isometry3d cam_from_board = Eigen::Isometry3d::Identity();
  cam_from_board.linear() = (Eigen::AngleAxisd(pose.rotation_deg.x() * deg, Vec3::UnitX()) *
                             Eigen::AngleAxisd(pose.rotation_deg.y() * deg, Vec3::UnitY()) *
                             Eigen::AngleAxisd(pose.rotation_deg.z() * deg, Vec3::UnitZ()))
                                .toRotationMatrix();
  const Vec3 centre_in_board((board.corners_x - 1) * board.square_size / 2.0,
                             (board.corners_y - 1) * board.square_size / 2.0, 0.0);
  cam_from_board.translation() = pose.translation_m - cam_from_board.linear() * centre_in_board;
  return cam_from_board;
}

nlohmann::json SceneChessboard::Json() const {
  nlohmann::json out = {{"corners", {board.corners_x, board.corners_y}},
                        {"square_m", board.square_size},
                        {"reflectance", {dark_reflectance, light_reflectance}}};
  nlohmann::json list = nlohmann::json::array();
  for (const Pose& pose : poses)
    list.push_back({{"rotation_deg", JsonTriple(pose.rotation_deg)},
                    {"translation_m", JsonTriple(pose.translation_m)}});
  out["poses"] = list;
  return out;
}

std::optional<SceneChessboard> ReadSceneChessboard(const std::filesystem::path& scene_file) {
  const std::string file = scene_file.string();
  const nlohmann::json root = ReadJsonFile(scene_file);
  if (!root.is_object() || !root.contains("chessboard")) return std::nullopt;
  JsonFields fields(root.at("chessboard"), file, "chessboard");
  fields.RejectUnknown({"corners", "square_m", "reflectance", "poses"});
  SceneChessboard out;
  const nlohmann::json& corners = fields.At("corners");
  if (!corners.is_array() || corners.size() != 2 || !corners[0].is_number_integer() ||
      !corners[1].is_number_integer())
    throw fields.Error("corners", "must be [columns, rows], two integers (inner corners)");
  out.board.corners_x = corners[0].get<int>();
  out.board.corners_y = corners[1].get<int>();
  out.board.square_size = fields.Number("square_m");
  std::string why;
  if (!out.board.Check(&why)) throw fields.Error("", why);
  if (fields.Has("reflectance")) {
    const std::vector<double> values = fields.Numbers("reflectance", fields.At("reflectance"));
    if (values.size() != 2 || !(values[0] >= 0.0) || !(values[1] <= 1.0) ||
        !(values[0] < values[1]))
      throw fields.Error(
          "reflectance",
          "must be [dark, light], 0 <= dark < light <= 1 (the squares' reflectance)");
    out.dark_reflectance = values[0];
    out.light_reflectance = values[1];
  }
  const nlohmann::json& poses = fields.At("poses");
  if (!poses.is_array() || poses.empty())
    throw fields.Error("poses", "must be a non-empty array of {rotation_deg, translation_m}");
  for (size_t k = 0; k < poses.size(); ++k) {
    JsonFields pose(poses[k], file, "chessboard.poses[" + std::to_string(k) + "]");
    pose.RejectUnknown({"rotation_deg", "translation_m"});
    SceneChessboard::Pose entry;
    entry.rotation_deg = pose.Triple("rotation_deg", pose.At("rotation_deg"));
    entry.translation_m = pose.Triple("translation_m", pose.At("translation_m"));
    if (!(entry.translation_m.z() > 0.0))
      throw pose.Error("translation_m",
                       "the board's centre must be in front of the camera (z > 0)");
    out.poses.push_back(entry);
  }
  return out;
}

}  // namespace procam
