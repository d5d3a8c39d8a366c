#include "base/camera_model.h"

#include <cmath>
#include <cstdio>
#include <regex>
#include <stdexcept>

#include "base/io.h"

extern "C" {
#include <mrcal/mrcal.h>
}

namespace procam {

namespace {

static_assert(sizeof(mrcal_point2_t) == sizeof(Vec2) && sizeof(mrcal_point3_t) == sizeof(Vec3),
              "Eigen fixed vectors and mrcal points must share their layout");
static_assert(sizeof(ProjectionJacobian) == 2 * sizeof(mrcal_point3_t),
              "ProjectionJacobian must have mrcal's dq_dp layout");

std::string FormatNumber(double value) {
  char text[40];
  std::snprintf(text, sizeof(text), "%.17g", value);
  return text;
}

struct CameraModelDeleter {
  void operator()(mrcal_cameramodel_t* model) const { mrcal_free_cameramodel(&model); }
};
using ParsedCameraModel = std::unique_ptr<mrcal_cameramodel_t, CameraModelDeleter>;

// libmrcal's parser reads a '#' comment up to its newline and a quoted string up to its closing
// quote even past the end of the buffer (files ending inside either crashed it, found by
// fuzz_cameramodel: fuzz/regressions/cameramodel/). True when every comment ends with a newline
// and every string closes on its own line, so that the parser never runs off the end.
bool CommentsAndStringsEnd(const std::string& text) {
  for (size_t at = 0; at < text.size(); ++at) {
    const char c = text[at];
    if (c != '#' && c != '\'' && c != '"') continue;
    const size_t end = text.find_first_of(c == '#' ? std::string("\n") : std::string(1, c) + "\n", at + 1);
    if (end == std::string::npos || (c != '#' && text[end] != c)) return false;
    at = end;
  }
  return true;
}

// libmrcal prints its own parser diagnostics on stderr before returning null; procam reports
// one line of its own instead. Null also for text libmrcal cannot parse safely.
ParsedCameraModel ParseCameraModel(const std::string& text) {
  if (!CommentsAndStringsEnd(text)) return nullptr;
  const SilencedStderr quiet;
  return ParsedCameraModel(mrcal_read_cameramodel_string(text.data(), static_cast<int>(text.size())));
}

// Numbers that make no sense are refused here, before they reach mrcal, Embree or a solver:
// a pose further than kMaxTranslation metres away or turned by more than kMaxRotation radians
// (a Rodrigues vector's length), non-finite intrinsics, focal lengths outside (0, kMaxFocal]
// pixels, principal points or distortions beyond kMaxIntrinsic, images beyond kMaxImagerSide.
constexpr double kMaxTranslation = 1e6;
constexpr double kMaxRotation = 100.0;
constexpr double kMaxFocal = 1e8;
constexpr double kMaxIntrinsic = 1e8;
constexpr unsigned kMaxImagerSide = 65536;

// Why the model's numbers are absurd, or "" when they are not.
std::string CheckModelNumbers(const mrcal_cameramodel_t& model, int intrinsics_count) {
  const double* rt = model.rt_cam_ref;
  for (int k = 0; k < 6; ++k) {
    if (!std::isfinite(rt[k])) return "extrinsics: must be finite, got " + FormatNumber(rt[k]);
  }
  if (Vec3(rt[0], rt[1], rt[2]).norm() > kMaxRotation) {
    return "extrinsics: rotation vector longer than " + FormatNumber(kMaxRotation) + " radians";
  }
  if (Vec3(rt[3], rt[4], rt[5]).norm() > kMaxTranslation) {
    return "extrinsics: translation further than " + FormatNumber(kMaxTranslation) + " metres";
  }
  for (int k = 0; k < intrinsics_count; ++k) {
    const double value = model.intrinsics[k];
    if (!std::isfinite(value) || std::abs(value) > kMaxIntrinsic) {
      return "intrinsics[" + std::to_string(k) + "]: must be finite, at most " +
             FormatNumber(kMaxIntrinsic) + " in magnitude, got " + FormatNumber(value);
    }
  }
  const bool core = mrcal_lensmodel_metadata(&model.lensmodel).has_core;
  if (core && intrinsics_count >= 2 &&
      !(model.intrinsics[0] > 0.0 && model.intrinsics[0] <= kMaxFocal &&
        model.intrinsics[1] > 0.0 && model.intrinsics[1] <= kMaxFocal)) {
    return "intrinsics: focal lengths fx, fy must be in (0, " + FormatNumber(kMaxFocal) + "]";
  }
  for (const unsigned side : model.imagersize) {
    if (side < 1 || side > kMaxImagerSide) {
      return "imagersize: each side must be in [1, " + std::to_string(kMaxImagerSide) + "]";
    }
  }
  return "";
}

// Where libmrcal could not parse a file: the key whose list holds a word that is not a number
// (nan, inf), as "KEY: not a number: WORD", or "" when there is none.
std::string NonNumberKey(const std::string& text) {
  static const std::regex word(R"([-+]?\b(nan|inf|infinity)\b)", std::regex::icase);
  std::smatch found;
  if (!std::regex_search(text, found, word)) return "";
  static const std::regex key(R"('([A-Za-z_]+)'\s*:)");
  const std::string before = text.substr(0, found.position(0));
  std::string last;
  for (auto it = std::sregex_iterator(before.begin(), before.end(), key); it != std::sregex_iterator(); ++it) {
    last = (*it)[1];
  }
  return (last.empty() ? std::string("a value") : last) + ": not a number: " + found.str(0);
}

}  // namespace

CameraModel ReadCameraModelFile(const std::filesystem::path& path) {
  const std::string file = path.string();
  // A .cameramodel is a few kilobytes (splined models: some hundred numbers).
  const std::string text = ReadFile(path, uintmax_t{16} << 20);
  const ParsedCameraModel parsed = ParseCameraModel(text);
  if (!parsed) {
    const std::string key = NonNumberKey(text);
    if (!key.empty()) throw IoError(file + ": " + key);
    throw IoError(file + ": not a valid mrcal .cameramodel (libmrcal could not parse it)");
  }
  CameraModel model;
  char name[1024];
  if (!mrcal_lensmodel_name(name, sizeof(name), &parsed->lensmodel)) {
    throw IoError(file + ": lensmodel: cannot be named");
  }
  model.lens_model = name;
  const int count = mrcal_lensmodel_num_params(&parsed->lensmodel);
  const std::string why = CheckModelNumbers(*parsed, count);
  if (!why.empty()) throw IoError(file + ": " + why);
  model.intrinsics.assign(parsed->intrinsics, parsed->intrinsics + count);
  model.width = static_cast<int>(parsed->imagersize[0]);
  model.height = static_cast<int>(parsed->imagersize[1]);
  model.cam_from_ref = PoseFromRt(parsed->rt_cam_ref);
  return model;
}

std::string CameraModelText(const CameraModel& model, const std::string& comment) {
  auto list = [](const auto& values) {
    std::string text = "[";
    for (size_t k = 0; k < values.size(); ++k) text += (k ? ", " : " ") + FormatNumber(values[k]);
    return text + " ]";
  };
  return "# " + comment + "\n{\n  'lensmodel':  '" + model.lens_model +
         "',\n  'intrinsics': " + list(model.intrinsics) + ",\n  'imagersize': [ " +
         std::to_string(model.width) + ", " + std::to_string(model.height) +
         " ],\n  'extrinsics': " + list(RtFromPose(model.cam_from_ref)) +
         (model.optimization_inputs.empty()
              ? std::string()
              : ",\n  'icam_intrinsics': " + std::to_string(model.icam_intrinsics) +
                    ",\n  'optimization_inputs': b'" + model.optimization_inputs + "'") +
         "\n}\n";
}

void WriteCameraModelFile(const std::filesystem::path& path, const CameraModel& model,
                          const std::string& comment) {
  const std::string text = CameraModelText(model, comment);
  if (!ParseCameraModel(text)) {
    throw IoError(path.string() + ": libmrcal cannot parse the model text procam made");
  }
  WriteFileAtomically(path, text);
}

std::array<double, 6> RtFromPose(const Eigen::Isometry3d& b_from_a) {
  const Vec3 r = AngleAxisOf(b_from_a.linear());
  const Vec3& t = b_from_a.translation();
  return {r.x(), r.y(), r.z(), t.x(), t.y(), t.z()};
}

Eigen::Isometry3d PoseFromRt(const double* rt) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = RotationOf(Vec3(rt[0], rt[1], rt[2]));
  pose.translation() = Vec3(rt[3], rt[4], rt[5]);
  return pose;
}

struct LensModel::Parsed {
  mrcal_lensmodel_t model;
};

LensModel::LensModel() : LensModel("LENSMODEL_PINHOLE", {1.0, 1.0, 0.0, 0.0}) {}

LensModel::LensModel(const std::string& name, std::vector<double> intrinsics)
    : name_(name), intrinsics_(std::move(intrinsics)) {
  auto parsed = std::make_shared<Parsed>();
  if (!mrcal_lensmodel_from_name(&parsed->model, name.c_str()) ||
      !mrcal_lensmodel_type_is_valid(parsed->model.type)) {
    throw std::invalid_argument("unknown mrcal lens model '" + name + "'");
  }
  if (parsed->model.type == MRCAL_LENSMODEL_CAHVORE) {
    throw std::invalid_argument("lens model " + name + " cannot be unprojected by mrcal");
  }
  if (!mrcal_lensmodel_metadata(&parsed->model).has_core) {
    throw std::invalid_argument("lens model " + name + " has no fx, fy, cx, cy core");
  }
  const int expected = mrcal_lensmodel_num_params(&parsed->model);
  if (static_cast<int>(intrinsics_.size()) != expected) {
    throw std::invalid_argument(name + " needs " + std::to_string(expected) + " intrinsics, got " +
                                std::to_string(intrinsics_.size()));
  }
  for (const double value : intrinsics_) {
    if (!std::isfinite(value)) throw std::invalid_argument("intrinsics must be finite");
  }
  if (!(intrinsics_[0] > 0.0 && intrinsics_[1] > 0.0)) {
    throw std::invalid_argument("focal lengths fx, fy must be positive");
  }
  parsed_ = std::move(parsed);
}

int LensModel::ParameterCount(const std::string& name) {
  mrcal_lensmodel_t model;
  if (!mrcal_lensmodel_from_name(&model, name.c_str()) ||
      !mrcal_lensmodel_type_is_valid(model.type)) {
    throw std::invalid_argument("unknown mrcal lens model '" + name + "'");
  }
  return mrcal_lensmodel_num_params(&model);
}

Vec2 LensModel::Project(const Vec3& p_in_cam, ProjectionJacobian* dq_dp) const {
  Vec2 pixel;
  mrcal_project(reinterpret_cast<mrcal_point2_t*>(&pixel),
                reinterpret_cast<mrcal_point3_t*>(dq_dp ? dq_dp->data() : nullptr), nullptr,
                reinterpret_cast<const mrcal_point3_t*>(&p_in_cam), 1, &parsed_->model,
                intrinsics_.data());
  return pixel;
}

bool LensModel::Unproject(const Vec2* pixels, int count, Vec3* directions_in_cam) const {
  if (count <= 0) return true;
  return mrcal_unproject(reinterpret_cast<mrcal_point3_t*>(directions_in_cam),
                         reinterpret_cast<const mrcal_point2_t*>(pixels), count, &parsed_->model,
                         intrinsics_.data());
}

}  // namespace procam
