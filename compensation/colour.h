#pragma once
// Colour spaces of the objective (paper Eq. 2–3): linear RGB → XYZ by a 3×3 T, XYZ → CIE
// L*a*b* relative to a reference white, with the analytic Jacobian; colour differences ΔE76
// and CIEDE2000. Functions on one colour are header-only so that CPU and GPU code share them.

#include <cmath>

#include <Eigen/Core>

#include "compensation/host_device.h"
#include "geometry/srgb.h"

namespace procam {

// RGB → XYZ matrix of a display with the given chromaticities (x, y) of its red, green and
// blue primaries and white point; white (1,1,1) maps to Y = 1.
Eigen::Matrix3d RgbToXyzMatrix(const Eigen::Vector2d& red, const Eigen::Vector2d& green,
                               const Eigen::Vector2d& blue, const Eigen::Vector2d& white);
// sRGB / Rec. 709 primaries with the D65 white point (the default projector primaries).
Eigen::Matrix3d SrgbToXyzMatrix();

constexpr double kLabDelta = 6.0 / 29.0;

// h(t) of paper Eq. 3: t^(1/3) above (6/29)^3, linear below.
PROCAM_HOST_DEVICE inline double LabH(double t) {
  return t > kLabDelta * kLabDelta * kLabDelta ? std::cbrt(t)
                                                : t / (3.0 * kLabDelta * kLabDelta) + 4.0 / 29.0;
}
PROCAM_HOST_DEVICE inline double LabHDerivative(double t) {
  if (t > kLabDelta * kLabDelta * kLabDelta) {
    const double root = std::cbrt(t);
    return 1.0 / (3.0 * root * root);
  }
  return 1.0 / (3.0 * kLabDelta * kLabDelta);
}

PROCAM_HOST_DEVICE inline double LabHSecondDerivative(double t) {
  if (t > kLabDelta * kLabDelta * kLabDelta) {
    const double root = std::cbrt(t);
    return -2.0 / (9.0 * root * root * root * root * root);
  }
  return 0.0;
}

// Σ_k w_k ∇²Lab_k(XYZ): the curvature of w·Lab, which is diagonal in XYZ (each of h(X/Xn),
// h(Y/Yn), h(Z/Zn) depends on one coordinate). `w` weighs (L*, a*, b*).
PROCAM_HOST_DEVICE inline Eigen::Vector3d XyzToLabWeightedCurvature(const Eigen::Vector3d& xyz,
                                                                    const Eigen::Vector3d& white,
                                                                    const Eigen::Vector3d& w) {
  const double hx = LabHSecondDerivative(xyz[0] / white[0]) / (white[0] * white[0]);
  const double hy = LabHSecondDerivative(xyz[1] / white[1]) / (white[1] * white[1]);
  const double hz = LabHSecondDerivative(xyz[2] / white[2]) / (white[2] * white[2]);
  return Eigen::Vector3d(500.0 * w[1] * hx, (116.0 * w[0] - 500.0 * w[1] + 200.0 * w[2]) * hy,
                         -200.0 * w[2] * hz);
}

// XYZ → L*a*b* relative to the reference white (Xn, Yn, Zn).
PROCAM_HOST_DEVICE inline Eigen::Vector3d XyzToLab(const Eigen::Vector3d& xyz,
                                                   const Eigen::Vector3d& white) {
  const double fx = LabH(xyz[0] / white[0]);
  const double fy = LabH(xyz[1] / white[1]);
  const double fz = LabH(xyz[2] / white[2]);
  return Eigen::Vector3d(116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz));
}

// ∂Lab/∂XYZ (paper Eq. 8's ∂v/∂u for one patch).
PROCAM_HOST_DEVICE inline Eigen::Matrix3d XyzToLabJacobian(const Eigen::Vector3d& xyz,
                                                           const Eigen::Vector3d& white) {
  const double dx = LabHDerivative(xyz[0] / white[0]) / white[0];
  const double dy = LabHDerivative(xyz[1] / white[1]) / white[1];
  const double dz = LabHDerivative(xyz[2] / white[2]) / white[2];
  Eigen::Matrix3d jacobian;
  jacobian << 0.0, 116.0 * dy, 0.0,
              500.0 * dx, -500.0 * dy, 0.0,
              0.0, 200.0 * dy, -200.0 * dz;
  return jacobian;
}

// Inverse of XyzToLab.
Eigen::Vector3d LabToXyz(const Eigen::Vector3d& lab, const Eigen::Vector3d& white);

// CIE 1976 colour difference: Euclidean distance in L*a*b*.
inline double DeltaE76(const Eigen::Vector3d& lab1, const Eigen::Vector3d& lab2) {
  return (lab1 - lab2).norm();
}

// CIEDE2000 colour difference with kL = kC = kH = 1 (Sharma, Wu & Dalal 2005).
double DeltaE2000(const Eigen::Vector3d& lab1, const Eigen::Vector3d& lab2);

// CIEDE2000's metric at `lab`: the symmetric positive definite M with
// ΔE00(lab + δ, lab)² ≈ δᵀ M δ for small δ, fitted by least squares to ΔE00² along 18 directions
// of length `step` (the three axes and the six diagonals of each pair, both signs); eigenvalues
// below 1e-3 × the largest are raised to it (ΔE00's rotation term can make the fit indefinite
// for saturated blues).
Eigen::Matrix3d DeltaE2000Metric(const Eigen::Vector3d& lab, double step = 0.05);
// The same metric in closed form: the limit of the fit as the step goes to 0, M = JᵀQJ with J the
// derivative of (ΔL′, ΔC′, ΔH′) of Sharma et al.'s Eqs. 1–20 at δ = 0 and Q the quadratic form of
// Eq. 20 (1/S_L², 1/S_C², 1/S_H², the rotation term R_T/(2 S_C S_H)), all at `lab`; at zero chroma
// (no hue) diag(1/S_L², (1 + G)²/S_C², 1/S_C²). Eigenvalues clamped as the fit's. One ΔE00's worth
// of arithmetic instead of eighteen.
Eigen::Matrix3d DeltaE2000MetricClosedForm(const Eigen::Vector3d& lab);

// Linear RGB → L*a*b*, given T and the XYZ of the reference white.
struct LabConverter {
  Eigen::Matrix3d rgb_to_xyz;
  Eigen::Vector3d white_xyz;

  // Reference white = T·(w, w, w).
  static LabConverter ForWhite(const Eigen::Matrix3d& rgb_to_xyz, double white_radiosity) {
    return {rgb_to_xyz, rgb_to_xyz * Eigen::Vector3d::Constant(white_radiosity)};
  }
  Eigen::Vector3d Lab(const Eigen::Vector3d& linear_rgb) const {
    return XyzToLab(rgb_to_xyz * linear_rgb, white_xyz);
  }
  // ∂Lab/∂RGB.
  Eigen::Matrix3d Jacobian(const Eigen::Vector3d& linear_rgb) const {
    return XyzToLabJacobian(rgb_to_xyz * linear_rgb, white_xyz) * rgb_to_xyz;
  }
};

}  // namespace procam
