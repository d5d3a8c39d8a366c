#include "base/camera_model.h"

#include <gtest/gtest.h>

#include <cmath>

#include "base/io.h"
#include "tests/testing/testing.h"

namespace procam {
namespace {

const std::vector<double> kOpenCv4 = {900.0, 880.0, 640.5, 400.25, -0.21, 0.07, 0.0013, -0.0009};

TEST(CameraModelFile, WriteReadIsLossless) {
  testing::TempDir dir;
  CameraModel model;
  model.lens_model = "LENSMODEL_OPENCV4";
  model.intrinsics = {900.0 + 1.0 / 3.0, 880.1, 640.5, 400.25, -0.21, 0.07, 1e-17, -0.0009};
  model.width = 1280;
  model.height = 800;
  model.cam_from_ref.linear() = RotationOf(Vec3(0.3, -1.1, 0.2));
  model.cam_from_ref.translation() = Vec3(1.0 / 7.0, -2.5, 3.0);
  WriteCameraModelFile(dir / "m.cameramodel", model, "a test model");
  const CameraModel back = ReadCameraModelFile(dir / "m.cameramodel");
  EXPECT_EQ(back.lens_model, model.lens_model);
  EXPECT_EQ(back.intrinsics, model.intrinsics);  // bit for bit: 17 significant digits
  EXPECT_EQ(back.width, 1280);
  EXPECT_EQ(back.height, 800);
  EXPECT_LT(testing::MaxAbsDifference(back.cam_from_ref.matrix(), model.cam_from_ref.matrix()),
            1e-15);
  EXPECT_EQ(ReadFile(dir / "m.cameramodel").rfind("# a test model\n", 0), 0u);
}

// mrcal's optimization inputs ride along as two more keys, which libmrcal's parser skips
// (mrcal's Python reader is checked in tests/calibration/projection_uncertainty_test.cc).
TEST(CameraModelFile, OptimizationInputsAreWrittenAndSkippedOnRead) {
  testing::TempDir dir;
  CameraModel model;
  model.lens_model = "LENSMODEL_PINHOLE";
  model.intrinsics = {500.0, 510.0, 319.5, 239.5};
  model.width = 640;
  model.height = 480;
  model.optimization_inputs = "P)h>@6aWAK00000";  // base-85 text, as mrcal writes it
  model.icam_intrinsics = 0;
  WriteCameraModelFile(dir / "m.cameramodel", model, "with inputs");
  const std::string text = ReadFile(dir / "m.cameramodel");
  EXPECT_NE(text.find("'icam_intrinsics': 0,\n  'optimization_inputs': b'P)h>@6aWAK00000'\n}"),
            std::string::npos)
      << text;
  const CameraModel back = ReadCameraModelFile(dir / "m.cameramodel");
  EXPECT_EQ(back.intrinsics, model.intrinsics);
  EXPECT_TRUE(back.optimization_inputs.empty());
}

TEST(CameraModelFile, BadFilesFailWithOneLineNamingTheFile) {
  testing::TempDir dir;
  try {
    ReadCameraModelFile(dir / "missing.cameramodel");
    FAIL() << "no error";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("missing.cameramodel: file not found"),
              std::string::npos);
  }
  const auto junk =
      dir.Write("junk.cameramodel", "{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [1, 2");
  ::testing::internal::CaptureStderr();
  try {
    ReadCameraModelFile(junk);
    ADD_FAILURE() << "no error";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find(junk.string() + ": not a valid mrcal .cameramodel"),
              std::string::npos);
  }
  // libmrcal's own parser diagnostics do not reach stderr: the IoError is the one line.
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
}

// Numbers that make no sense are refused where models are read, before they reach mrcal, Embree
// (an extrinsic of 1e308 aborts inside its BVH traversal) or a solver.
TEST(CameraModelFile, RefusesAbsurdNumbers) {
  testing::TempDir dir;
  const auto model = [](const std::string& intrinsics, const std::string& size,
                        const std::string& extrinsics) {
    return "{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [" + intrinsics +
           "], 'imagersize': [" + size + "], 'extrinsics': [" + extrinsics + "] }\n";
  };
  const std::string good_k = "100, 100, 50, 40", good_size = "100, 80",
                    good_rt = "0, 0, 0, 1, 2, 3";
  struct Case {
    std::string text, expected;
  };
  const std::vector<Case> cases = {
      {model(good_k, good_size, "0, 0, 0, 0, 0, 1e308"), "extrinsics: translation further than"},
      {model(good_k, good_size, "1e308, 0, 0, 0, 0, 0"), "extrinsics: rotation vector longer than"},
      {model("1e308, 100, 50, 40", good_size, good_rt), "intrinsics[0]: must be finite"},
      {model("-100, 100, 50, 40", good_size, good_rt),
       "intrinsics: focal lengths fx, fy must be in (0, "},
      {model(good_k, "0, 80", good_rt), "not a valid mrcal .cameramodel"},  // libmrcal's check
      {model(good_k, "100000, 80", good_rt), "imagersize: each side must be in [1, 65536]"},
      // Words that are not numbers, whether or not libmrcal parses them: the key is named.
      {model("nan, 100, 50, 40", good_size, good_rt), "intrinsics"},
      {model(good_k, good_size, "0, 0, 0, 1, -inf, 3"), "extrinsics"},
  };
  for (const Case& c : cases) {
    const auto path = dir.Write("m.cameramodel", c.text);
    try {
      ReadCameraModelFile(path);
      ADD_FAILURE() << "accepted: " << c.text;
    } catch (const IoError& error) {
      EXPECT_NE(std::string(error.what()).find(path.string() + ": " + c.expected),
                std::string::npos)
          << error.what();
    }
  }
  EXPECT_NO_THROW(
      ReadCameraModelFile(dir.Write("m.cameramodel", model(good_k, good_size, good_rt))));
}

// A file ending inside a '#' comment, or with a quoted string that never closes, made libmrcal's
// parser read past its buffer and crash (found by fuzz_cameramodel; the inputs are in
// fuzz/regressions/cameramodel/). Both are refused as unparsable.
TEST(CameraModelFile, CommentsAndStringsThatDoNotEndAreRefused) {
  const auto dir = testing::SourceDir() / "fuzz/regressions/cameramodel";
  for (const char* name : {"comment_at_end_of_file.cameramodel", "string_not_closed.cameramodel"}) {
    EXPECT_THROW(ReadCameraModelFile(dir / name), IoError) << name;
  }
}

TEST(Rt, PoseRoundTripAndMrcalConvention) {
  const double rt[6] = {0.1, -0.2, 0.3, 1.0, 2.0, -3.0};
  const Eigen::Isometry3d pose = PoseFromRt(rt);
  // Rodrigues: rotation by |r| about r/|r|.
  const Vec3 r(0.1, -0.2, 0.3);
  const Eigen::Matrix3d expected = Eigen::AngleAxisd(r.norm(), r.normalized()).toRotationMatrix();
  EXPECT_LT(testing::MaxAbsDifference(pose.linear(), expected), 1e-15);
  const std::array<double, 6> back = RtFromPose(pose);
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(back[k], rt[k], 1e-15);
}

TEST(LensModel, PinholeMatchesTheClosedForm) {
  const LensModel lens("LENSMODEL_PINHOLE", {1000.0, 900.0, 320.0, 240.0});
  const Vec3 p(0.3, -0.2, 2.0);
  ProjectionJacobian dq_dp;
  const Vec2 q = lens.Project(p, &dq_dp);
  EXPECT_NEAR(q.x(), 1000.0 * 0.3 / 2.0 + 320.0, 1e-12);
  EXPECT_NEAR(q.y(), 900.0 * -0.2 / 2.0 + 240.0, 1e-12);
  EXPECT_NEAR(dq_dp(0, 0), 1000.0 / 2.0, 1e-12);
  EXPECT_NEAR(dq_dp(0, 2), -1000.0 * 0.3 / 4.0, 1e-12);
  EXPECT_NEAR(dq_dp(1, 1), 900.0 / 2.0, 1e-12);
  Vec3 direction;
  ASSERT_TRUE(lens.Unproject(&q, 1, &direction));
  EXPECT_LT((direction.normalized() - p.normalized()).norm(), 1e-12);
}

// mrcal's OpenCV4 model and procam's DistortOpenCv4 (used inside Ceres problems) agree.
TEST(LensModel, OpenCv4AgreesWithDistortOpenCv4) {
  const LensModel lens("LENSMODEL_OPENCV4", kOpenCv4);
  for (const Vec3& p : {Vec3(0.3, -0.2, 2.0), Vec3(-0.5, 0.4, 1.0), Vec3(0.0, 0.0, 1.0)}) {
    const Vec2 q = lens.Project(p);
    double x = 0, y = 0;
    DistortOpenCv4(kOpenCv4.data() + 4, p.x() / p.z(), p.y() / p.z(), &x, &y);
    EXPECT_NEAR(q.x(), kOpenCv4[0] * x + kOpenCv4[2], 1e-9);
    EXPECT_NEAR(q.y(), kOpenCv4[1] * y + kOpenCv4[3], 1e-9);
  }
}

TEST(DistortOpenCv4, JacobianMatchesFiniteDifferences) {
  const double* k = kOpenCv4.data() + 4;
  for (const Vec2& u : {Vec2(0.3, -0.2), Vec2(-0.45, 0.35), Vec2(0.01, 0.6)}) {
    double x, y, jacobian[4];
    DistortOpenCv4(k, u.x(), u.y(), &x, &y, jacobian);
    const double h = 1e-6;
    for (int column = 0; column < 2; ++column) {
      const Vec2 step = column == 0 ? Vec2(h, 0.0) : Vec2(0.0, h);
      double xp, yp, xm, ym;
      DistortOpenCv4(k, u.x() + step.x(), u.y() + step.y(), &xp, &yp);
      DistortOpenCv4(k, u.x() - step.x(), u.y() - step.y(), &xm, &ym);
      EXPECT_NEAR(jacobian[column], (xp - xm) / (2 * h), 1e-8);
      EXPECT_NEAR(jacobian[2 + column], (yp - ym) / (2 * h), 1e-8);
    }
  }
}

TEST(LensModel, RejectsBadModels) {
  EXPECT_THROW(LensModel("LENSMODEL_NOPE", {1, 1, 0, 0}), std::invalid_argument);
  EXPECT_THROW(LensModel("LENSMODEL_OPENCV4", {1, 1, 0, 0}), std::invalid_argument);
  EXPECT_THROW(LensModel("LENSMODEL_PINHOLE", {1, std::nan(""), 0, 0}), std::invalid_argument);
  EXPECT_THROW(LensModel("LENSMODEL_PINHOLE", {-1, 1, 0, 0}), std::invalid_argument);
  EXPECT_EQ(LensModel::ParameterCount("LENSMODEL_OPENCV8"), 12);
}

}  // namespace
}  // namespace procam
