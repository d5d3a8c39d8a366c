#pragma once
// Camera linearity (issue 7, "Photometry"): the inverse response of a camera that is not linear
// (webcams, consumer cameras: an sRGB-like output curve), from photos of a still scene at several
// exposures (Debevec & Malik, SIGGRAPH 1997, through OpenCV's CalibrateDebevec).
//
// Model: code z of a pixel = f(exposure × irradiance); the inverse response g = f⁻¹ gives the
// linear signal of a code. Debevec & Malik solve for ln g at every code from many pixels seen at
// every exposure (smoothness weight lambda), up to a scale. Here g is normalised so that a
// power law fitted over the trusted codes, g(z) ≈ (z / z_max)^γ, is 1 at full scale; the table
// is made non-decreasing and starts at 0 (the camera's black level must be 0, as for 8-bit
// cameras that deliver display-ready codes). Samples are spread over the codes of the middle
// exposure (Debevec & Malik's advice), not OpenCV's regular grid.
//
// The result feeds the HDR merge (capture/sequencer.h HdrMergeOptions::inverse_response) and is
// written as RIG_DIR/camera_response.json by `procam calibrate response`.

#include <Eigen/Core>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace procam {

struct CameraResponseOptions {
  int samples = 200;      // pixels sampled (a regular grid, OpenCV's non-random mode), ≥ 10
  double lambda = 10.0;   // smoothness weight of Debevec & Malik, > 0
  // Codes trusted for the gamma fit: normalised value in [min_code, max_code]. The ends of the
  // Debevec curve are poorly constrained: at the bottom read noise clipped at 0 lifts the mean
  // code, at the top few pixels stay unsaturated. Above max_code the table continues the fitted
  // power law from its value at max_code.
  double min_code = 0.2, max_code = 0.9;
  bool Check(std::string* why) const;
};

struct CameraResponse {
  // Per channel R, G, B: linear signal at code z = 0, 1, ..., 255 (8-bit codes), 0 at code 0,
  // ≈ 1 at code 255, non-decreasing.
  std::vector<std::vector<double>> inverse;
  Eigen::Vector3d gamma = Eigen::Vector3d::Ones();  // power-law fit per channel, R, G, B
  Eigen::Vector3d gamma_rms = Eigen::Vector3d::Zero();  // RMS of that fit in ln g
  int pixels = 0;                                   // pixels the sampling grid offered
};

// `images`: CV_8UC3 (B, G, R as capture delivers) of one still scene, one per exposure
// (microseconds, all different, > 0), at least 3. Returns false with `why` set when the input does
// not fit (sizes, types, too few exposures, options) or the fit fails.
bool CalibrateCameraResponse(const std::vector<cv::Mat>& images,
                             const std::vector<double>& exposures_us,
                             const CameraResponseOptions& options, CameraResponse* response,
                             std::string* why);

}  // namespace procam

#include <filesystem>
#include <nlohmann/json.hpp>

namespace procam {

// camera_response.json: {"format": "procam camera response", "codes": 256, "gamma": [R, G, B],
// "gamma_rms": [...], "inverse": {"r": [...], "g": [...], "b": [...]}} (plus what the caller
// adds to `extra`).
nlohmann::json CameraResponseJson(const CameraResponse& response);

// The tables of a camera_response.json in the order HdrMergeOptions::inverse_response wants for
// images with `channels` channels: B, G, R for 3, the green table for 1. Throws IoError naming
// the file and the key when it is missing or malformed.
std::vector<std::vector<double>> ReadInverseResponse(const std::filesystem::path& path,
                                                     int channels);

}  // namespace procam
