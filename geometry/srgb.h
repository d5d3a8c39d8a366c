#pragma once
// The sRGB transfer function (IEC 61966-2-1), per channel. Desired appearances are written
// gamma-encoded; everything procam computes with is linear.

#include <cmath>

namespace procam {

// Gamma-encoded sRGB value in [0,1] → linear value in [0,1].
inline double SrgbToLinear(double encoded) {
  return encoded <= 0.04045 ? encoded / 12.92 : std::pow((encoded + 0.055) / 1.055, 2.4);
}

// Linear value in [0,1] → gamma-encoded sRGB value in [0,1].
inline double LinearToSrgb(double linear) {
  return linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
}

}  // namespace procam
