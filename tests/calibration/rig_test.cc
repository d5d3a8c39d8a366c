// The rig directory as compensate and project consume it (--rig), and photometry in the
// scene's units (projection/photometric_transfer.h, `calibrate photometric --scene`), against the
// synthetic tiny box's ground truth:
//   - closed loop: a rig directory written from the scene's TRUE projectors gives the same
//     compensation and projector images as the scene's own projectors;
//   - bad rig.json: one line naming RIG_DIR/rig.json and the key, exit 1, nothing written;
//   - black and max in scene units from flat fields the simulated rig renders (bounces, textured
//     albedo), against the simulated projector's;
//   - per-patch reflectance against the simulated world's textured albedo;
//   - the command end to end on a synthetic-camera capture session.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "base/html_report.h"
#include "base/io.h"
#include "base/json_fields.h"
#include "calibration/photometric.h"
#include "compensation/unit_light.h"
#include "datasets_synthetic/paper_scenes.h"
#include "datasets_synthetic/simulated_rig.h"
#include "datasets_synthetic/synthetic_camera.h"
#include "geometry/form_factors.h"
#include "projection/camera_rays.h"
#include "projection/photometric_transfer.h"
#include "projection/projection_rig.h"
#include "projection/reflectance_map.h"
#include "projection/rig_directory.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

using testing::CommandRun;
using testing::RunProcam;

constexpr int kPatches = 150;
// Finer for the reflectance: patches small against the albedo texture's waves.
constexpr int kPhotometryPatches = 600;

nlohmann::json ReadJson(const std::filesystem::path& path) {
  std::ifstream file(path);
  return nlohmann::json::parse(file);
}


// The synthetic tiny box as a scene file (its surfaces are quads), projectors as given.
std::filesystem::path WriteTinyBoxScene(const testing::TempDir& dir, const std::string& name,
                                        const nlohmann::json& projectors) {
  const SyntheticScene synthetic = MakeSyntheticScene("tiny_box", kPatches);
  nlohmann::json surfaces = nlohmann::json::array();
  for (const Surface& surface : synthetic.scene.surfaces) {
    EXPECT_EQ(surface.kind, Surface::Kind::kQuad);
    nlohmann::json quad = nlohmann::json::array();
    for (const Vec3& corner : surface.quad) quad.push_back(JsonTriple(corner));
    surfaces.push_back({{"name", surface.name},
                        {"quad", quad},
                        {"reflectance", JsonTriple(surface.reflectance)},
                        {"desired", JsonTriple(surface.desired.srgb)}});
  }
  nlohmann::json scene = {{"patches", kPatches}, {"surfaces", surfaces}};
  if (!projectors.is_null()) scene["projectors"] = projectors;
  return dir.Write(name, scene.dump(2));
}

// The true projectors with photometry that exercises every key: black, RGB max, per-channel
// gamma, a non-identity mixing.
std::vector<Projector> TrueProjectors() {
  const SyntheticScene synthetic = MakeSyntheticScene("tiny_box", kPatches);
  std::vector<Projector> projectors;
  for (size_t k = 0; k < synthetic.projectors.size(); ++k) {
    Projector projector = ProjectorFromPlacement(synthetic.projectors[k]);
    projector.photometry.black = Vec3(0.004, 0.005, 0.003) * (k + 1);
    projector.photometry.max = Vec3(1.4, 1.6, 1.2) * (1.0 + 0.1 * k);
    projector.photometry.response = {ResponseCurve::Gamma(2.4), ResponseCurve::Gamma(2.0),
                                     ResponseCurve::Gamma(2.2)};
    projector.photometry.mixing << 0.92, 0.06, 0.02, 0.04, 0.9, 0.06, 0.01, 0.07, 0.92;
    projectors.push_back(projector);
  }
  return projectors;
}

// Projector JSON entries (scene-file format) for `projectors`, models written into `dir`.
nlohmann::json ProjectorEntries(const std::vector<Projector>& projectors,
                                const std::filesystem::path& dir) {
  nlohmann::json entries = nlohmann::json::array();
  for (const Projector& projector : projectors) {
    WriteCameraModel(dir / (projector.name + ".cameramodel"), projector.geometry);
    const ProjectorPhotometry& p = projector.photometry;
    nlohmann::json mixing = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) mixing.push_back({p.mixing(r, 0), p.mixing(r, 1), p.mixing(r, 2)});
    entries.push_back({{"name", projector.name},
                       {"model", projector.name + ".cameramodel"},
                       {"black", JsonTriple(p.black)},
                       {"max", JsonTriple(p.max)},
                       {"gamma", {p.response[0].gamma(), p.response[1].gamma(),
                                  p.response[2].gamma()}},
                       {"mixing", mixing}});
  }
  return entries;
}

Eigen::MatrixXd ReadMatrix(const std::filesystem::path& path) {
  const NpyArray array = ReadNpy(path);
  Eigen::MatrixXd matrix(array.shape[0], array.shape.size() > 1 ? array.shape[1] : 1);
  for (int i = 0; i < matrix.rows(); ++i) {
    for (int j = 0; j < matrix.cols(); ++j) matrix(i, j) = array.values[i * matrix.cols() + j];
  }
  return matrix;
}

// Closed loop: the rig's projectors (written from the truth, in another directory than the
// scene) replace the scene's; compensate and project give what the scene's projectors give.
TEST(RigDirectory, TrueProjectorsInARigGiveTheScenesResults) {
  testing::TempDir dir;
  const std::vector<Projector> projectors = TrueProjectors();
  const nlohmann::json scene_entries = ProjectorEntries(projectors, dir.path());
  const std::filesystem::path with = WriteTinyBoxScene(dir, "with.json", scene_entries);
  const std::filesystem::path without = WriteTinyBoxScene(dir, "without.json", nullptr);
  std::filesystem::create_directories(dir / "rig");
  const nlohmann::json rig = {{"format_version", kRigFormatVersion},
                              {"camera", {{"model", "camera.cameramodel"}}},
                              {"projectors", ProjectorEntries(projectors, dir / "rig")},
                              {"registration", nlohmann::json::object()}};
  dir.Write("rig/rig.json", rig.dump(2));

  for (const std::string method : {"perceptual", "naive"}) {
    const std::string common = " --method " + method + " --out ";
    const CommandRun a = RunProcam("compensate " + with.string() + common + (dir / "a").string());
    ASSERT_EQ(a.exit_code, 0) << a.output;
    const CommandRun b = RunProcam("compensate " + without.string() + " --rig " +
                                   (dir / "rig").string() + common + (dir / "b").string());
    ASSERT_EQ(b.exit_code, 0) << b.output;
    const Eigen::MatrixXd e_scene = ReadMatrix(dir / "a/E.npy");
    const Eigen::MatrixXd e_rig = ReadMatrix(dir / "b/E.npy");
    ASSERT_EQ(e_scene.rows(), e_rig.rows());
    const double difference = testing::MaxAbsDifference(e_scene, e_rig);
    std::printf("%s: %d patches, E differs by %.3g (max E %.3g)\n", method.c_str(),
                static_cast<int>(e_scene.rows()), difference, e_scene.maxCoeff());
    EXPECT_LE(difference, 1e-9);
    EXPECT_GT(e_scene.maxCoeff(), 0.0);
    const nlohmann::json result = ReadJson(dir / "b/result.json");
    EXPECT_EQ(result["rig"]["dir"], (dir / "rig").string());
    EXPECT_EQ(result["rig"]["projectors"], nlohmann::json({"left", "right"}));

    // project: the solution remembers its rig; the images and delivered light are the same.
    const CommandRun pa = RunProcam("project " + (dir / "a").string() + " --out " +
                                    (dir / "pa").string());
    ASSERT_EQ(pa.exit_code, 0) << pa.output;
    const CommandRun pb = RunProcam("project " + (dir / "b").string() + " --out " +
                                    (dir / "pb").string());
    ASSERT_EQ(pb.exit_code, 0) << pb.output;
    EXPECT_EQ(ReadJson(dir / "pb/result.json")["rig"]["dir"], (dir / "rig").string());
    EXPECT_LE(testing::MaxAbsDifference(ReadMatrix(dir / "pa/E_delivered.npy"),
                                        ReadMatrix(dir / "pb/E_delivered.npy")),
              1e-9);
    for (const Projector& projector : projectors) {
      const cv::Mat ia = cv::imread((dir / "pa" / (projector.name + ".png")).string(),
                                    cv::IMREAD_UNCHANGED);
      const cv::Mat ib = cv::imread((dir / "pb" / (projector.name + ".png")).string(),
                                    cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(ia.empty());
      EXPECT_EQ(cv::norm(ia, ib, cv::NORM_INF), 0.0) << projector.name;
    }
  }

  // The rig really is used: half the max halves the upper bounds and changes the solution.
  nlohmann::json dimmer = rig;
  for (nlohmann::json& entry : dimmer["projectors"]) {
    for (nlohmann::json& value : entry["max"]) value = 0.5 * value.get<double>();
  }
  std::filesystem::create_directories(dir / "dim");
  for (const Projector& projector : projectors) {
    std::filesystem::copy_file(dir / "rig" / (projector.name + ".cameramodel"),
                               dir / "dim" / (projector.name + ".cameramodel"));
  }
  dir.Write("dim/rig.json", dimmer.dump(2));
  const CommandRun c = RunProcam("compensate " + with.string() + " --method naive --rig " +
                                 (dir / "dim").string() + " --out " + (dir / "c").string());
  ASSERT_EQ(c.exit_code, 0) << c.output;
  EXPECT_GT(testing::MaxAbsDifference(ReadMatrix(dir / "a/E.npy"), ReadMatrix(dir / "c/E.npy")),
            1e-3);
}

// Every field of rig.json written by WriteRigFile comes back from ReadRigFile as it was.
TEST(RigFile, WritesAndReadsBackEveryField) {
  testing::TempDir dir;
  RigFile rig;
  rig.camera.model = "camera.cameramodel";
  rig.camera.response = "camera_response.json";
  rig.camera.colour = RigCameraColour{};
  rig.camera.colour->matrix = Eigen::Matrix3d::Identity() * 2.0;
  rig.camera.colour->black = 0.03;
  RigProjector left;
  left.name = "left";
  left.model = "left.cameramodel";
  left.black = Eigen::Vector3d(0.01, 0.02, 0.03);
  left.max = Eigen::Vector3d(1.0, 2.0, 3.0);
  left.response = {{"gamma", {2.2, 2.1, 2.0}}};
  left.mixing = Eigen::Matrix3d::Identity();
  left.bits = 10;
  rig.Projector("left") = left;
  rig.Projector("right").model = "right.cameramodel";
  EXPECT_EQ(&rig.Projector("left"), &rig.projectors[0]);  // found, not added again
  EXPECT_EQ(rig.projectors.size(), 2u);
  rig.registration = {{"room_from_camera", {1, 2, 3}}};
  rig.photometric["left"] = {"scene", "captures/left", "room.json", Eigen::Vector3d(4, 5, 6), 0.5};
  rig.reflectance = RigReflectance{"reflectance.npy", 600, "left", "room.json", 612, 580};
  WriteRigFile(dir.path() / "rig", rig);

  const RigFile back = ReadRigFile(dir.path() / "rig");
  EXPECT_EQ(back.camera.model, rig.camera.model);
  EXPECT_EQ(back.camera.response, rig.camera.response);
  ASSERT_TRUE(back.camera.colour && back.camera.colour->matrix && back.camera.colour->black);
  EXPECT_FALSE(back.camera.colour->scale);
  EXPECT_EQ(*back.camera.colour->matrix, *rig.camera.colour->matrix);
  EXPECT_EQ(*back.camera.colour->black, 0.03);
  ASSERT_EQ(back.projectors.size(), 2u);
  EXPECT_EQ(back.projectors[0].name, "left");
  EXPECT_EQ(back.projectors[0].model, "left.cameramodel");
  EXPECT_EQ(*back.projectors[0].black, *left.black);
  EXPECT_EQ(*back.projectors[0].max, *left.max);
  EXPECT_EQ(back.projectors[0].response, left.response);
  EXPECT_EQ(*back.projectors[0].mixing, *left.mixing);
  EXPECT_EQ(*back.projectors[0].bits, 10);
  EXPECT_EQ(back.projectors[1].name, "right");
  EXPECT_FALSE(back.projectors[1].black || back.projectors[1].max || back.projectors[1].bits);
  EXPECT_EQ(back.registration, rig.registration);
  ASSERT_EQ(back.photometric.count("left"), 1u);
  const RigPhotometry& photometry = back.photometric.at("left");
  EXPECT_EQ(photometry.units, "scene");
  EXPECT_EQ(photometry.session, "captures/left");
  EXPECT_EQ(photometry.scene, "room.json");
  EXPECT_EQ(*photometry.camera_scale, Eigen::Vector3d(4, 5, 6));
  EXPECT_EQ(photometry.camera_black, 0.5);
  ASSERT_TRUE(back.reflectance);
  EXPECT_EQ(back.reflectance->file, "reflectance.npy");
  EXPECT_EQ(back.reflectance->target_patches, 600);
  EXPECT_EQ(back.reflectance->patches, 612);
  EXPECT_EQ(back.reflectance->patches_seen, 580);
  EXPECT_EQ(ReadJson(dir.path() / "rig/rig.json")["format_version"], kRigFormatVersion);
  // A missing rig.json reads as an empty rig (the first calibrate command starts from it).
  EXPECT_TRUE(ReadRigFile(dir.path() / "nowhere").projectors.empty());
}

// An update that throws leaves rig.json as it was.
TEST(RigFile, FailedUpdateWritesNothing) {
  testing::TempDir dir;
  RigFile rig;
  rig.camera.model = "camera.cameramodel";
  WriteRigFile(dir.path(), rig);
  const std::string before = ReadFile(dir.path() / "rig.json");
  EXPECT_THROW(UpdateRigFile(dir.path(),
                             [](RigFile& file) {
                               file.camera.model = "other.cameramodel";
                               throw IoError("stop");
                             }),
               IoError);
  EXPECT_EQ(ReadFile(dir.path() / "rig.json"), before);
}

TEST(RigDirectory, BadRigJsonGetsOneLineNamingTheFileAndKey) {
  testing::TempDir dir;
  const std::filesystem::path scene = WriteTinyBoxScene(dir, "scene.json", nullptr);
  const std::vector<Projector> projectors = TrueProjectors();
  std::filesystem::create_directories(dir / "rig");
  const nlohmann::json good = {{"format_version", kRigFormatVersion},
                               {"projectors", ProjectorEntries(projectors, dir / "rig")}};
  struct Case {
    std::string name;
    nlohmann::json rig;  // null: no rig.json
    std::string expected;
  };
  nlohmann::json no_max = good, missing_model = good, camera_units = good, bad_mixing = good;
  nlohmann::json unversioned = good, future = good, bool_scale = good, unknown_key = good;
  nlohmann::json string_black = good, number_units = good, no_target = good, twice = good;
  unversioned.erase("format_version");
  bool_scale["camera"] = {{"model", "camera.cameramodel"}, {"colour", {{"scale", true}}}};
  unknown_key["projecter"] = nlohmann::json::array();
  string_black["projectors"][0]["black"] = "dark";
  number_units["photometric"] = {{"left", {{"units", 3}}}};
  no_target["reflectance"] = {{"file", "reflectance.npy"}};
  twice["projectors"][1]["name"] = twice["projectors"][0]["name"];
  future["format_version"] = kRigFormatVersion + 1;
  no_max["projectors"][1].erase("max");
  missing_model["projectors"][0]["model"] = "nowhere.cameramodel";
  camera_units["projectors"][0].erase("max");
  camera_units["projectors"][0].erase("black");
  camera_units["photometric"] = {{"left", {{"units", "camera"}}}};
  bad_mixing["projectors"][0]["mixing"][0] = {0.5, 0.2, 0.2};
  const Case cases[] = {
      {"none", nullptr, "rig.json: file not found"},
      {"empty", {{"format_version", kRigFormatVersion}}, "rig.json: projectors: required key is missing"},
      {"unversioned", unversioned, "rig.json: format_version: required key is missing"},
      {"future", future, "rig.json: format_version: 2 is not supported"},
      {"no_max", no_max, "rig.json: projectors[1].max"},
      {"missing_model", missing_model, "rig.json: projectors[0].model"},
      {"camera_units", camera_units, "rig.json: projectors[0].max: the photometry of 'left' is in camera units"},
      {"bad_mixing", bad_mixing, "rig.json: projectors[0].mixing: row 0"},
      {"bool_scale", bool_scale, "rig.json: camera.colour.scale: must be a number or an RGB"},
      {"unknown_key", unknown_key, "rig.json: projecter: unknown key"},
      {"string_black", string_black, "rig.json: projectors[0].black: must be a number or an RGB"},
      {"number_units", number_units, "rig.json: photometric.left.units: must be a string"},
      {"no_target", no_target, "rig.json: reflectance.target_patches: required key is missing"},
      {"twice", twice, "rig.json: projectors[1].name: 'left' appears twice"},
  };
  for (const Case& c : cases) {
    const std::filesystem::path rig = dir / ("rig_" + c.name);
    std::filesystem::create_directories(rig);
    for (const Projector& projector : projectors) {
      std::filesystem::copy_file(dir / "rig" / (projector.name + ".cameramodel"),
                                 rig / (projector.name + ".cameramodel"));
    }
    if (!c.rig.is_null()) dir.Write("rig_" + c.name + "/rig.json", c.rig.dump(2));
    const CommandRun run = RunProcam("compensate " + scene.string() + " --rig " + rig.string() +
                                     " --out " + (dir / "out").string());
    EXPECT_EQ(run.exit_code, 1) << c.name << ": " << run.output;
    EXPECT_EQ(std::count(run.output.begin(), run.output.end(), '\n'), 1) << run.output;
    EXPECT_NE(run.output.find((rig / c.expected).string()), std::string::npos)
        << c.name << ": " << run.output;
    EXPECT_FALSE(std::filesystem::exists(dir / "out")) << c.name;
  }
}

// A flat-field capture rendered by the simulated rig (exact camera scale 1, no noise): projector
// "left" of the tiny box alone, with the photometry of TrueProjectors(), the world's albedo
// varying ±5% (which the scene's nominal reflectance does not know).
class ScenePhotometry : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const SyntheticScene synthetic = MakeSyntheticScene("tiny_box", kPhotometryPatches);
    truth_ = new Projector(TrueProjectors()[0]);
    SimulatedRigOptions options;
    options.solver_patches = kPhotometryPatches;
    options.albedo_variation = 0.05;
    rig_ = new SimulatedRig(synthetic.scene, {*truth_}, CameraFromPlacement(synthetic.camera),
                            options);
    scene_ = new Scene(synthetic.scene);
    SubdivisionOptions subdivision;
    subdivision.target_patches = kPhotometryPatches;
    level_ = new PatchLevel(SubdividePatches(*scene_, subdivision).fine);
    form_factors_ = new Eigen::MatrixXd(ComputeFormFactors(*scene_, *level_, {}, nullptr));
  }
  static void TearDownTestSuite() {
    delete truth_;
    delete rig_;
    delete scene_;
    delete level_;
    delete form_factors_;
  }

  static FlatField Field(const Vec3& drive) {
    ProjectorImage image;
    image.bits = truth_->photometry.bits;
    const int code_max = truth_->photometry.MaxCode();
    image.codes = cv::Mat(truth_->geometry.height(), truth_->geometry.width(), CV_16UC3,
                          cv::Scalar(std::lround(drive[0] * code_max),
                                     std::lround(drive[1] * code_max),
                                     std::lround(drive[2] * code_max)));
    FlatField field;
    field.drive = drive;
    cv::cvtColor(rig_->RenderRadiance({image}), field.image, cv::COLOR_RGB2BGR);
    return field;
  }

  static Projector* truth_;
  static SimulatedRig* rig_;
  static Scene* scene_;
  static PatchLevel* level_;
  static Eigen::MatrixXd* form_factors_;
};
Projector* ScenePhotometry::truth_ = nullptr;
SimulatedRig* ScenePhotometry::rig_ = nullptr;
Scene* ScenePhotometry::scene_ = nullptr;
PatchLevel* ScenePhotometry::level_ = nullptr;
Eigen::MatrixXd* ScenePhotometry::form_factors_ = nullptr;

TEST_F(ScenePhotometry, BlackAndMaxInSceneUnitsAndPerPatchReflectance) {
  std::vector<FlatField> fields = {Field(Vec3::Zero()), Field(Vec3::Ones())};
  for (int c = 0; c < 3; ++c) {
    for (const double level : {0.25, 0.5, 0.75, 1.0}) fields.push_back(Field(level * Vec3::Unit(c)));
  }
  const CameraPixelLighting lighting =
      LightCameraPixels(*scene_, *level_, truth_->geometry, rig_->camera());
  const UnitLightModel model = ModelUnitLight(*level_, *form_factors_, UnitLightExitance(*level_, *truth_));
  PhotometricCalibrationOptions options;
  options.transfer = PhotometricTransfer(lighting, *level_, model, Eigen::Vector3d::Ones());
  const PhotometricModel fit = CalibratePhotometry(fields, options);
  const ProjectorPhotometry& p = truth_->photometry;
  for (int c = 0; c < 3; ++c) {
    const double max_error = fit.max[c] / p.max[c] - 1.0;
    const double black_error = fit.black[c] / p.black[c] - 1.0;
    std::printf("channel %c: max %.4f (true %.4f, %+.2f%%), black %.5f (true %.5f, %+.2f%%)\n",
                "RGB"[c], fit.max[c], p.max[c], 100 * max_error, fit.black[c], p.black[c],
                100 * black_error);
    EXPECT_LT(std::abs(max_error), 0.02);
    EXPECT_LT(std::abs(black_error), 0.02);
  }
  std::printf("%d camera pixels\n", fit.pixels);

  // Reflectance from white − black, against the world's albedo averaged over each patch.
  const cv::Mat difference = fields[1].image - fields[0].image;
  const ReflectanceEstimate estimate =
      EstimatePatchReflectance(lighting, *level_, *form_factors_, model, difference, cv::Mat(),
                               fit.max - fit.black, Eigen::Vector3d::Ones(), 20);
  double worst = 0.0, sum_squares = 0.0, nominal_worst = 0.0, nominal_squares = 0.0;
  int count = 0;
  for (int i = 0; i < level_->size(); ++i) {
    if (estimate.pixels[i] < 20) continue;
    const Patch& patch = level_->patches[i];
    // Truth: the albedo factor averaged over the pixels' points is what the camera saw; over
    // the patch, 8×8 points of its bilinear parametrisation (patches are parallelograms here).
    double factor = 0.0;
    for (int a = 0; a < 8; ++a) {
      for (int b = 0; b < 8; ++b) {
        const double s = (a + 0.5) / 8, t = (b + 0.5) / 8;
        const Vec2 uv = (1 - s) * (1 - t) * patch.uv[0] + s * (1 - t) * patch.uv[1] +
                        s * t * patch.uv[2] + (1 - s) * t * patch.uv[3];
        factor += rig_->AlbedoFactor(patch.surface, uv) / 64.0;
      }
    }
    for (int c = 0; c < 3; ++c) {
      const double truth = factor * scene_->surfaces[patch.surface].reflectance[c];
      const double error = estimate.reflectance(i, c) / truth - 1.0;
      worst = std::max(worst, std::abs(error));
      const double nominal_error = level_->reflectance(i, c) / truth - 1.0;
      nominal_worst = std::max(nominal_worst, std::abs(nominal_error));
      nominal_squares += nominal_error * nominal_error;
      sum_squares += error * error;
      ++count;
    }
  }
  const double rms = std::sqrt(sum_squares / count);
  const double nominal_rms = std::sqrt(nominal_squares / count);
  std::printf("reflectance: %d patch-channels seen, rms error %.2f%%, worst %.2f%% (nominal "
              "reflectance: rms %.2f%%, worst %.2f%%)\n",
              count, 100 * rms, 100 * worst, 100 * nominal_rms, 100 * nominal_worst);
  ASSERT_GT(count, 60);
  EXPECT_LT(rms, 0.02);
  EXPECT_LT(worst, 0.05);
  EXPECT_LT(rms, 0.5 * nominal_rms);  // it finds the texture the nominal reflectance lacks
}

// The command end to end: a photometric session captured with the synthetic camera (projector
// "left" of the tiny box, gamma 2.2, black 0.002, max 1.5: ProjectorFromPlacement), a rig
// directory holding the true geometry (camera registered in the room, the projector's model),
// then `calibrate photometric --scene --projector left --camera-scale URI`: rig.json gets max in
// scene units, and compensate --rig runs on it.
TEST(ScenePhotometryCommand, FillsTheRigInSceneUnits) {
  testing::TempDir dir;
  const std::string uri =
      "synthetic:tiny_box?patches=150&fps=500&exposure_us=1000&reference_exposure_us=1000"
      "&black=8&noise=1";
  const CommandRun capture = RunProcam(
      "capture --camera '" + uri +
      "' --projector 0 --sequence photometric --levels 0,64,128,192,255 --channels rgbw"
      " --frames 4 --settle-ms 1 --out " + (dir / "flat").string());
  ASSERT_EQ(capture.exit_code, 0) << capture.output;
  const std::shared_ptr<SyntheticWorld> world = MakeSyntheticWorld("tiny_box", 150);
  const Projector& truth = world->rig->projectors()[0];
  const std::filesystem::path scene = WriteTinyBoxScene(dir, "scene.json", nullptr);
  const std::filesystem::path rig = dir / "rig";
  std::filesystem::create_directories(rig);
  WriteCameraModel(rig / "camera.cameramodel", world->rig->camera());
  WriteCameraModel(rig / "left.cameramodel", truth.geometry);
  const nlohmann::json rig_json = {
      {"format_version", kRigFormatVersion},
      {"camera", {{"model", "camera.cameramodel"}}},
      {"projectors", {{{"name", "left"}, {"model", "left.cameramodel"}}}},
      {"registration", {{"note", "the true pose (test)"}}}};
  dir.Write("rig/rig.json", rig_json.dump(2));

  // Without the camera scale: one line, nothing written.
  const std::string calibrate = "calibrate photometric " + (dir / "flat").string() + " --out " +
                                rig.string() + " --projector left --scene " + scene.string();
  const CommandRun no_scale = RunProcam(calibrate);
  EXPECT_EQ(no_scale.exit_code, 1);
  EXPECT_NE(no_scale.output.find("--camera-scale: required with --scene"), std::string::npos)
      << no_scale.output;
  EXPECT_FALSE(std::filesystem::exists(rig / "photometric.json"));
  EXPECT_FALSE(std::filesystem::exists(rig / "left.photometric.json"));

  const CommandRun run = RunProcam(calibrate + " --camera-scale '" + uri + "'");
  std::printf("%s", run.output.c_str());
  ASSERT_EQ(run.exit_code, 0) << run.output;
  const nlohmann::json filled = ReadJson(rig / "rig.json");
  const nlohmann::json& entry = filled["projectors"][0];
  EXPECT_EQ(entry["model"], "left.cameramodel");  // the geometry is kept
  EXPECT_EQ(filled["photometric"]["left"]["units"], "scene");
  EXPECT_TRUE(std::filesystem::exists(rig / "left.photometric.json"));
  EXPECT_NE(ReadJson(rig / "result.json")["photometric"]["left"]["units"].get<std::string>().find(
                "scene units"), std::string::npos);
  for (int c = 0; c < 3; ++c) {
    const double max = entry["max"][c].get<double>(), black = entry["black"][c].get<double>();
    std::printf("channel %c: max %.4f (true %.4f, %+.2f%%), black %.5f (true %.5f: the other "
                "projector's black light adds to it), gamma %.4f\n",
                "RGB"[c], max, truth.photometry.max[c], 100 * (max / truth.photometry.max[c] - 1),
                black, truth.photometry.black[c], entry["gamma"][c].get<double>());
    EXPECT_LT(std::abs(max / truth.photometry.max[c] - 1.0), 0.02);
    EXPECT_NEAR(entry["gamma"][c].get<double>(), 2.2, 0.02 * 2.2);
  }
  EXPECT_TRUE(std::filesystem::exists(rig / "reflectance.npy"));
  EXPECT_EQ(filled["reflectance"]["target_patches"], kPatches);
  // The projector's reflectance map, its rig.json entry (read back through its owner) and its
  // report page.
  const RigFile rig_file = ReadRigFile(rig);
  ASSERT_EQ(rig_file.reflectance_maps.count("left"), 1u);
  const RigReflectanceMap& map_entry = rig_file.reflectance_maps.at("left");
  EXPECT_EQ(map_entry.width, truth.geometry.width());
  EXPECT_EQ(map_entry.height, truth.geometry.height());
  EXPECT_GT(map_entry.measured_pixels, map_entry.lit_pixels / 4);
  const cv::Mat map = ReadReflectanceMap(rig, "left", map_entry);
  EXPECT_EQ(map.size(), cv::Size(truth.geometry.width(), truth.geometry.height()));
  const std::string report = ReadFile(rig / "left.photometric_report.html");
  EXPECT_TRUE(CheckReportStructure(report).empty());

  // compensate consumes it (projector "left" alone; reflectance from the rig).
  const CommandRun compensate = RunProcam("compensate " + scene.string() + " --rig " +
                                          rig.string() + " --out " + (dir / "solution").string());
  ASSERT_EQ(compensate.exit_code, 0) << compensate.output;
  EXPECT_EQ(ReadJson(dir / "solution/result.json")["rig"]["reflectance"], true);
}

}  // namespace
}  // namespace procam
