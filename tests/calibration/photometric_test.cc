// Photometric calibration against the simulated rig's known photometry: a projector with
// different gammas per channel, a black level, per-channel maxima and colour mixing, photographed
// by the rig's linear camera (vignetting, shot and read noise).
#include "calibration/photometric.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "datasets_synthetic/rooms.h"
#include "datasets_synthetic/simulated_rig.h"

namespace procam {
namespace {

ProjectorPhotometry TruePhotometry() {
  ProjectorPhotometry photometry;
  photometry.black = Vec3(0.006, 0.008, 0.005);
  photometry.max = Vec3(1.4, 1.6, 1.2);
  photometry.response = {ResponseCurve::Gamma(2.4), ResponseCurve::Gamma(2.0),
                         ResponseCurve::Gamma(2.2)};
  photometry.mixing << 0.90, 0.08, 0.02,  //
      0.05, 0.90, 0.05,                   //
      0.02, 0.10, 0.88;
  return photometry;
}

const int kLevels[] = {0, 32, 64, 96, 128, 160, 192, 224, 255};

// Flat fields per channel and level, and white, photographed linearly (B, G, R like capture).
std::vector<FlatField> Capture(const SimulatedRig& rig) {
  const Projector& projector = rig.projectors()[0];
  std::vector<Vec3> drives = {Vec3::Zero(), Vec3::Ones()};
  for (int c = 0; c < 3; ++c)
    for (int level : kLevels)
      if (level > 0) drives.push_back(Vec3::Unit(c) * (level / 255.0));
  std::vector<FlatField> fields;
  uint32_t seed = 0;
  for (const Vec3& drive : drives) {
    const cv::Vec3w code(std::lround(drive[0] * 255), std::lround(drive[1] * 255),
                         std::lround(drive[2] * 255));
    ProjectorImage image{cv::Mat(projector.geometry.height(), projector.geometry.width(),
                                 CV_16UC3, cv::Scalar(code[0], code[1], code[2])),
                         8};
    FlatField field;
    field.drive = drive;
    std::vector<cv::Mat> rgb;
    cv::split(rig.PhotographLinear({image}, ++seed), rgb);
    cv::merge(std::vector<cv::Mat>{rgb[2], rgb[1], rgb[0]}, field.image);
    fields.push_back(field);
  }
  return fields;
}

void ExpectWithin(const char* what, double estimate, double truth, double relative) {
  EXPECT_LE(std::abs(estimate - truth), relative * std::abs(truth))
      << what << ": " << estimate << " vs " << truth;
}

void ExpectModel(const PhotometricModel& model, const ProjectorPhotometry& truth, bool absolute) {
  for (int c = 0; c < 3; ++c) {
    ExpectWithin("gamma", model.gamma[c], truth.response[c].gamma(), 0.02);
    if (absolute) {
      ExpectWithin("black", model.black[c], truth.black[c], 0.02);
      ExpectWithin("max", model.max[c], truth.max[c], 0.02);
    }
    ExpectWithin("black/max", model.black[c] / model.max[c], truth.black[c] / truth.max[c], 0.02);
    for (int j = 0; j < 3; ++j) ExpectWithin("mixing", model.mixing(c, j), truth.mixing(c, j), 0.02);
    // The table follows the true response.
    for (size_t j = 0; j < model.table[c].size(); ++j) {
      const double d = static_cast<double>(j) / (model.table[c].size() - 1);
      EXPECT_NEAR(model.table[c][j], truth.response[c].Light(d), 0.01) << "channel " << c;
    }
  }
}

void Print(const char* what, const PhotometricModel& model, const ProjectorPhotometry& truth) {
  double worst_mixing = 0.0, worst_gamma = 0.0, worst_black = 0.0, worst_max = 0.0;
  for (int c = 0; c < 3; ++c) {
    worst_gamma = std::max(worst_gamma, std::abs(model.gamma[c] / truth.response[c].gamma() - 1));
    worst_black = std::max(worst_black, std::abs(model.black[c] / truth.black[c] - 1));
    worst_max = std::max(worst_max, std::abs(model.max[c] / truth.max[c] - 1));
    for (int j = 0; j < 3; ++j)
      worst_mixing = std::max(worst_mixing, std::abs(model.mixing(c, j) / truth.mixing(c, j) - 1));
  }
  std::printf("%s: %s\n  worst relative error: gamma %.3g, black %.3g, max %.3g, mixing %.3g\n",
              what, model.BriefReport().c_str(), worst_gamma, worst_black, worst_max,
              worst_mixing);
}

TEST(Photometric, FlatFieldsOnABoardRecoverTheProjectorWithin2Percent) {
  // A 2 × 1.5 m grey board 2 m in front of the projector: no interreflections.
  Scene scene;
  scene.name = "board";
  scene.surfaces.push_back(MakeRectangle(Vec3(-1.0, 2.0, 0.0), Vec3(2.0, 0.0, 0.0),
                                         Vec3(0.0, 0.0, 1.5), 0.8, Vec3(0.5, 0.5, 0.5)));
  DevicePlacement projector_place{"projector", Vec3(0.0, 0.0, 0.75), Vec3(0.0, 2.0, 0.75),
                                  Vec3::UnitZ(), 40.0, 160, 100};
  DevicePlacement camera_place{"camera", Vec3(0.3, -0.2, 0.75), Vec3(0.0, 2.0, 0.75),
                               Vec3::UnitZ(), 50.0, 120, 90};
  Projector projector = ProjectorFromPlacement(projector_place);
  const ProjectorPhotometry truth = TruePhotometry();
  projector.photometry = truth;
  SimulatedRigOptions options;
  options.solver_patches = 20;
  options.camera.exposure = 2.5;  // white reads about 0.8
  const SimulatedRig rig(scene, {projector}, CameraFromPlacement(camera_place), options);

  // The camera's known response: exposure × vignetting; the geometry's gain and the board's
  // reflectance: camera value per unit projector output at each pixel (B, G, R).
  cv::Mat transfer(rig.camera().height(), rig.camera().width(), CV_32FC3, cv::Scalar::all(0));
  const double half_diagonal = 0.5 * std::hypot(transfer.cols, transfer.rows);
  for (int row = 0; row < transfer.rows; ++row)
    for (int col = 0; col < transfer.cols; ++col) {
      Vec3 point, normal;
      Vec2 pixel;
      if (!rig.PointSeenByPixel(row, col, &point, &normal)) continue;
      const double gain = projector.geometry.Gain(point, normal, &pixel);
      if (gain <= 0.0 || !projector.geometry.InImage(pixel)) continue;
      const double r = std::hypot(col - 0.5 * (transfer.cols - 1), row - 0.5 * (transfer.rows - 1)) /
                       half_diagonal;
      const float t = static_cast<float>(options.camera.exposure *
                                         (1.0 - options.camera.vignetting * r * r) * 0.8 * gain);
      transfer.at<cv::Vec3f>(row, col) = cv::Vec3f(t, t, t);
    }
  PhotometricCalibrationOptions calibration;
  calibration.transfer = transfer;
  const PhotometricModel model = CalibratePhotometry(Capture(rig), calibration);
  Print("board", model, truth);
  EXPECT_GT(model.pixels, 3000);  // the lit part of the board (120×90 camera)
  ExpectModel(model, truth, /*absolute=*/true);
}

TEST(Photometric, InterreflectionsInTheTinyBoxLeaveRatiosExact) {
  // The 1 m box with one projector: bounce light scales every measurement per channel, so
  // gamma, mixing and black/max come back; black and max only in camera units (no transfer).
  const SyntheticScene synthetic = MakeSyntheticScene("tiny_box", 100);
  Projector projector = ProjectorFromPlacement(synthetic.projectors[0]);
  const ProjectorPhotometry truth = TruePhotometry();
  projector.photometry = truth;
  SimulatedRigOptions options;
  options.solver_patches = 100;
  options.camera.exposure = 2.0;
  const SimulatedRig rig(synthetic.scene, {projector}, CameraFromPlacement(synthetic.camera),
                         options);
  const PhotometricModel model = CalibratePhotometry(Capture(rig));
  Print("tiny_box (camera units)", model, truth);
  ExpectModel(model, truth, /*absolute=*/false);
}

TEST(Photometric, MissingFieldsAreNamed) {
  std::vector<FlatField> fields(1);
  fields[0].image = cv::Mat(4, 4, CV_32FC3, cv::Scalar::all(0.1));
  try {
    CalibratePhotometry(fields);
    FAIL() << "no full-drive fields";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("channel R at full drive"), std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace procam
