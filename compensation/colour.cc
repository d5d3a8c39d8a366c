#include "compensation/colour.h"

#include <Eigen/Dense>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <vector>

namespace procam {
namespace {

double Degrees(double radians) { return radians * 180.0 / std::numbers::pi; }
double Radians(double degrees) { return degrees * std::numbers::pi / 180.0; }

Eigen::Vector3d XyzOfChromaticity(const Eigen::Vector2d& xy) {
  return Eigen::Vector3d(xy[0] / xy[1], 1.0, (1.0 - xy[0] - xy[1]) / xy[1]);
}

double LabHInverse(double f) {
  return f > kLabDelta ? f * f * f : 3.0 * kLabDelta * kLabDelta * (f - 4.0 / 29.0);
}

}  // namespace

Eigen::Matrix3d RgbToXyzMatrix(const Eigen::Vector2d& red, const Eigen::Vector2d& green,
                               const Eigen::Vector2d& blue, const Eigen::Vector2d& white) {
  Eigen::Matrix3d primaries;
  primaries << XyzOfChromaticity(red), XyzOfChromaticity(green), XyzOfChromaticity(blue);
  // Scale each primary so that the three together make the white point with Y = 1.
  const Eigen::Vector3d scale = primaries.lu().solve(XyzOfChromaticity(white));
  return primaries * scale.asDiagonal();
}

Eigen::Matrix3d SrgbToXyzMatrix() {
  return RgbToXyzMatrix({0.64, 0.33}, {0.30, 0.60}, {0.15, 0.06}, {0.3127, 0.3290});
}

Eigen::Vector3d LabToXyz(const Eigen::Vector3d& lab, const Eigen::Vector3d& white) {
  const double fy = (lab[0] + 16.0) / 116.0;
  const double fx = fy + lab[1] / 500.0;
  const double fz = fy - lab[2] / 200.0;
  return Eigen::Vector3d(white[0] * LabHInverse(fx), white[1] * LabHInverse(fy),
                         white[2] * LabHInverse(fz));
}

double DeltaE2000(const Eigen::Vector3d& lab1, const Eigen::Vector3d& lab2) {
  // Notation and steps of Sharma, Wu & Dalal (2005), Eqs. 1–20.
  const double c1 = std::hypot(lab1[1], lab1[2]);
  const double c2 = std::hypot(lab2[1], lab2[2]);
  const double c_mean = 0.5 * (c1 + c2);
  const double c_mean7 = std::pow(c_mean, 7.0);
  const double g = 0.5 * (1.0 - std::sqrt(c_mean7 / (c_mean7 + std::pow(25.0, 7.0))));
  const double a1 = (1.0 + g) * lab1[1], a2 = (1.0 + g) * lab2[1];
  const double c1p = std::hypot(a1, lab1[2]), c2p = std::hypot(a2, lab2[2]);
  auto hue = [](double b, double a) {
    if (a == 0.0 && b == 0.0) return 0.0;
    const double h = Degrees(std::atan2(b, a));
    return h < 0.0 ? h + 360.0 : h;
  };
  const double h1p = hue(lab1[2], a1), h2p = hue(lab2[2], a2);

  const double delta_l = lab2[0] - lab1[0];
  const double delta_c = c2p - c1p;
  double delta_h_angle = 0.0;
  if (c1p * c2p != 0.0) {
    delta_h_angle = h2p - h1p;
    if (delta_h_angle > 180.0) delta_h_angle -= 360.0;
    if (delta_h_angle < -180.0) delta_h_angle += 360.0;
  }
  const double delta_h = 2.0 * std::sqrt(c1p * c2p) * std::sin(Radians(delta_h_angle) / 2.0);

  const double l_mean = 0.5 * (lab1[0] + lab2[0]);
  const double cp_mean = 0.5 * (c1p + c2p);
  double h_mean = h1p + h2p;
  if (c1p * c2p != 0.0) {
    if (std::abs(h1p - h2p) <= 180.0) {
      h_mean = 0.5 * (h1p + h2p);
    } else if (h1p + h2p < 360.0) {
      h_mean = 0.5 * (h1p + h2p + 360.0);
    } else {
      h_mean = 0.5 * (h1p + h2p - 360.0);
    }
  }
  const double t = 1.0 - 0.17 * std::cos(Radians(h_mean - 30.0)) +
                   0.24 * std::cos(Radians(2.0 * h_mean)) +
                   0.32 * std::cos(Radians(3.0 * h_mean + 6.0)) -
                   0.20 * std::cos(Radians(4.0 * h_mean - 63.0));
  const double delta_theta = 30.0 * std::exp(-std::pow((h_mean - 275.0) / 25.0, 2.0));
  const double cp_mean7 = std::pow(cp_mean, 7.0);
  const double r_c = 2.0 * std::sqrt(cp_mean7 / (cp_mean7 + std::pow(25.0, 7.0)));
  const double l50 = (l_mean - 50.0) * (l_mean - 50.0);
  const double s_l = 1.0 + 0.015 * l50 / std::sqrt(20.0 + l50);
  const double s_c = 1.0 + 0.045 * cp_mean;
  const double s_h = 1.0 + 0.015 * cp_mean * t;
  const double r_t = -std::sin(Radians(2.0 * delta_theta)) * r_c;
  const double term_l = delta_l / s_l, term_c = delta_c / s_c, term_h = delta_h / s_h;
  return std::sqrt(term_l * term_l + term_c * term_c + term_h * term_h + r_t * term_c * term_h);
}

namespace {

// The fit's fixed part: the 18 unit directions (the three axes, the diagonals of each pair, both
// signs) and the least-squares solution operator of its design at step 1 (the design scales by
// step², so the solution by 1/step²). Formed once: a QR per call was most of the metric's cost.
struct MetricFit {
  std::array<Eigen::Vector3d, 18> directions;
  Eigen::Matrix<double, 6, 18> solve;
};

const MetricFit& Ciede2000MetricFit() {
  static const MetricFit fit = [] {
    MetricFit f;
    std::vector<Eigen::Vector3d> axes;
    for (int a = 0; a < 3; ++a) axes.push_back(Eigen::Vector3d::Unit(a));
    for (int a = 0; a < 3; ++a) {
      for (int b = a + 1; b < 3; ++b) {
        axes.push_back((Eigen::Vector3d::Unit(a) + Eigen::Vector3d::Unit(b)) / std::sqrt(2.0));
        axes.push_back((Eigen::Vector3d::Unit(a) - Eigen::Vector3d::Unit(b)) / std::sqrt(2.0));
      }
    }
    // Unknowns m = (M00, M11, M22, M01, M02, M12): δᵀMδ = Σ δa² Maa + 2 Σ δa δb Mab.
    Eigen::Matrix<double, 18, 6> design;
    int row = 0;
    for (const Eigen::Vector3d& axis : axes) {
      for (const double sign : {1.0, -1.0}) {
        const Eigen::Vector3d d = sign * axis;
        f.directions[row] = d;
        design.row(row) << d[0] * d[0], d[1] * d[1], d[2] * d[2], 2 * d[0] * d[1], 2 * d[0] * d[2],
            2 * d[1] * d[2];
        ++row;
      }
    }
    f.solve = design.colPivHouseholderQr().solve(Eigen::Matrix<double, 18, 18>::Identity());
    return f;
  }();
  return fit;
}

}  // namespace

Eigen::Matrix3d DeltaE2000Metric(const Eigen::Vector3d& lab, double step) {
  const MetricFit& fit = Ciede2000MetricFit();
  Eigen::Matrix<double, 18, 1> squared;
  for (int row = 0; row < 18; ++row) {
    const double distance = DeltaE2000(lab + step * fit.directions[row], lab);
    squared[row] = distance * distance;
  }
  const Eigen::Matrix<double, 6, 1> m = fit.solve * squared / (step * step);
  Eigen::Matrix3d metric;
  metric << m[0], m[3], m[4], m[3], m[1], m[5], m[4], m[5], m[2];
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(metric);
  const double largest = std::max(eigen.eigenvalues().maxCoeff(), 1e-12);
  const Eigen::Vector3d values = eigen.eigenvalues().cwiseMax(1e-3 * largest);
  return eigen.eigenvectors() * values.asDiagonal() * eigen.eigenvectors().transpose();
}

Eigen::Matrix3d DeltaE2000MetricClosedForm(const Eigen::Vector3d& lab) {
  // As δ → 0 both colours share G, C̄′ and h̄′, so ΔL′ = δL, ΔC′ = ∇C′·δ and ΔH′ = C′ ∇h′·δ (h′ in
  // radians) with a′ = (1 + G) a, and ΔE00² = uᵀQu for u = (ΔL′, ΔC′, ΔH′): M = JᵀQJ.
  const double c = std::hypot(lab[1], lab[2]);
  const double c7 = std::pow(c, 7.0);
  const double g = 0.5 * (1.0 - std::sqrt(c7 / (c7 + std::pow(25.0, 7.0))));
  const double ap = (1.0 + g) * lab[1], b = lab[2];
  const double cp = std::hypot(ap, b);
  const double l50 = (lab[0] - 50.0) * (lab[0] - 50.0);
  const double s_l = 1.0 + 0.015 * l50 / std::sqrt(20.0 + l50);
  const double s_c = 1.0 + 0.045 * cp;
  Eigen::Matrix3d metric = Eigen::Matrix3d::Zero();
  metric(0, 0) = 1.0 / (s_l * s_l);
  if (cp == 0.0) {
    // Neutral: ΔH′ = 0 and ΔC′ = ‖((1 + G) δa, δb)‖, a quadratic form of its own (G = ½ at C̄ = 0).
    metric(1, 1) = (1.0 + g) * (1.0 + g) / (s_c * s_c);
    metric(2, 2) = 1.0 / (s_c * s_c);
    return metric;
  }
  double h = Degrees(std::atan2(b, ap));
  if (h < 0.0) h += 360.0;
  const double t = 1.0 - 0.17 * std::cos(Radians(h - 30.0)) + 0.24 * std::cos(Radians(2.0 * h)) +
                   0.32 * std::cos(Radians(3.0 * h + 6.0)) -
                   0.20 * std::cos(Radians(4.0 * h - 63.0));
  const double s_h = 1.0 + 0.015 * cp * t;
  const double cp7 = std::pow(cp, 7.0);
  const double r_c = 2.0 * std::sqrt(cp7 / (cp7 + std::pow(25.0, 7.0)));
  const double delta_theta = 30.0 * std::exp(-std::pow((h - 275.0) / 25.0, 2.0));
  const double r_t = -std::sin(Radians(2.0 * delta_theta)) * r_c;
  Eigen::Matrix3d j = Eigen::Matrix3d::Zero();  // rows ΔL′, ΔC′, ΔH′; columns δL, δa, δb
  j(0, 0) = 1.0;
  j(1, 1) = (1.0 + g) * ap / cp;
  j(1, 2) = b / cp;
  j(2, 1) = -(1.0 + g) * b / cp;
  j(2, 2) = ap / cp;
  Eigen::Matrix3d q = Eigen::Matrix3d::Zero();
  q(0, 0) = 1.0 / (s_l * s_l);
  q(1, 1) = 1.0 / (s_c * s_c);
  q(2, 2) = 1.0 / (s_h * s_h);
  q(1, 2) = q(2, 1) = 0.5 * r_t / (s_c * s_h);
  metric = j.transpose() * q * j;
  // Its eigenvalues λ1 ≤ λ2 ≤ λ3 floored at 10⁻³ λ3 below. M is SPD (J is invertible, |R_T| ≤ √3
  // keeps Q's 2×2 block definite), and λ1 ≥ det/λ3² with λ3 ≤ trace: det ≥ 10⁻³ trace³ proves the
  // floor inactive without the eigendecomposition (most colours).
  const double trace = metric.trace();
  if (metric.determinant() >= 1e-3 * trace * trace * trace) return metric;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen;
  eigen.computeDirect(metric);
  const double largest = std::max(eigen.eigenvalues().maxCoeff(), 1e-12);
  if (eigen.eigenvalues().minCoeff() >= 1e-3 * largest) return metric;
  const Eigen::Vector3d values = eigen.eigenvalues().cwiseMax(1e-3 * largest);
  return eigen.eigenvectors() * values.asDiagonal() * eigen.eigenvectors().transpose();
}

}  // namespace procam
