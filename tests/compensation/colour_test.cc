#include "compensation/colour.h"

#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "tests/testing/testing.h"

namespace procam {
namespace {

TEST(Srgb, TransferFunctionRoundTripsAndMatchesKnownValues) {
  for (double v = 0.0; v <= 1.0; v += 0.01) EXPECT_NEAR(LinearToSrgb(SrgbToLinear(v)), v, 1e-12);
  EXPECT_NEAR(SrgbToLinear(0.5), 0.214041, 1e-6);
  EXPECT_NEAR(SrgbToLinear(0.04045), 0.04045 / 12.92, 1e-12);
}

TEST(RgbToXyz, SrgbMatrixMatchesIec61966) {
  Eigen::Matrix3d published;  // IEC 61966-2-1, 4 decimals
  published << 0.4124, 0.3576, 0.1805, 0.2126, 0.7152, 0.0722, 0.0193, 0.1192, 0.9505;
  EXPECT_LT(testing::MaxAbsDifference(SrgbToXyzMatrix(), published), 1e-4);
  EXPECT_NEAR((SrgbToXyzMatrix() * Eigen::Vector3d::Ones())[1], 1.0, 1e-12);
}

TEST(Lab, WhiteIsHundredAndRoundTrips) {
  const LabConverter lab = LabConverter::ForWhite(SrgbToXyzMatrix(), 2.0);
  EXPECT_LT((lab.Lab(Eigen::Vector3d::Constant(2.0)) - Eigen::Vector3d(100, 0, 0)).norm(), 1e-10);
  EXPECT_LT(lab.Lab(Eigen::Vector3d::Zero()).norm(), 1e-10);
  for (const Eigen::Vector3d& xyz : {Eigen::Vector3d(0.3, 0.5, 0.1), Eigen::Vector3d(1e-4, 2e-3, 5e-4)}) {
    EXPECT_LT((LabToXyz(XyzToLab(xyz, lab.white_xyz), lab.white_xyz) - xyz).norm(), 1e-12);
  }
}

TEST(Lab, JacobianMatchesFiniteDifferencesOnBothSidesOfTheKnee) {
  const LabConverter lab = LabConverter::ForWhite(SrgbToXyzMatrix(), 1.0);
  // Bright colours (cube root branch), very dark ones (linear branch), and a mixture.
  const std::vector<Eigen::Vector3d> colours = {
      {0.6, 0.3, 0.2}, {0.9, 0.9, 0.9}, {1e-3, 2e-3, 5e-4}, {4e-3, 0.5, 1e-3}};
  for (const Eigen::Vector3d& rgb : colours) {
    const Eigen::Matrix3d analytic = lab.Jacobian(rgb);
    Eigen::Matrix3d numeric;
    for (int c = 0; c < 3; ++c) {
      const double step = 1e-7 * std::max(rgb[c], 1e-3);
      Eigen::Vector3d plus = rgb, minus = rgb;
      plus[c] += step;
      minus[c] -= step;
      numeric.col(c) = (lab.Lab(plus) - lab.Lab(minus)) / (2 * step);
    }
    EXPECT_LT(testing::MaxAbsDifference(analytic, numeric), 1e-5 * analytic.cwiseAbs().maxCoeff())
        << rgb.transpose();
  }
  // And on ∂Lab/∂XYZ directly, either side of t = (6/29)^3.
  const double knee = kLabDelta * kLabDelta * kLabDelta;
  for (const double t : {0.5 * knee, 2.0 * knee}) {
    const Eigen::Vector3d white(0.95, 1.0, 1.09), xyz = t * white;
    const Eigen::Matrix3d analytic = XyzToLabJacobian(xyz, white);
    for (int c = 0; c < 3; ++c) {
      const double step = 1e-6 * t;
      Eigen::Vector3d plus = xyz, minus = xyz;
      plus[c] += step;
      minus[c] -= step;
      const Eigen::Vector3d numeric = (XyzToLab(plus, white) - XyzToLab(minus, white)) / (2 * step);
      EXPECT_LT((analytic.col(c) - numeric).norm(), 1e-6 * analytic.col(c).norm() + 1e-9);
    }
  }
}

TEST(DeltaE, CIE76IsEuclidean) {
  EXPECT_DOUBLE_EQ(DeltaE76({50, 10, -10}, {53, 14, -10}), 5.0);
}

TEST(DeltaE2000, MatchesSharmaWuDalalTestPairsInBothOrders) {
  const auto path = testing::SharedDir() / "data" / "sharma2005_ciede2000.csv";
  std::ifstream in(path);
  ASSERT_TRUE(in) << "missing reference data " << path;
  std::string line;
  std::getline(in, line);  // header
  int pairs = 0;
  while (std::getline(in, line)) {
    std::stringstream fields(line);
    double v[7];
    char comma;
    for (int k = 0; k < 7; ++k) {
      fields >> v[k];
      if (k < 6) fields >> comma;
    }
    const Eigen::Vector3d lab1(v[0], v[1], v[2]), lab2(v[3], v[4], v[5]);
    EXPECT_NEAR(DeltaE2000(lab1, lab2), v[6], 1e-4) << "pair " << pairs + 1;
    EXPECT_NEAR(DeltaE2000(lab2, lab1), v[6], 1e-4) << "pair " << pairs + 1 << " reversed";
    ++pairs;
  }
  EXPECT_EQ(pairs, 34);
}

}  // namespace
}  // namespace procam
