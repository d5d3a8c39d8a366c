#pragma once
// Photometric calibration of one projector from flat fields: black level, maximum brightness,
// per-channel response (a gamma fit and a table) and colour mixing, in the model of
// projection/projector.h:
//
//   output(d) = black + diag(max − black) · mixing · r(d),   r_c(d) = d_c^gamma_c (or the table),
//
// output in working linear RGB, drive d ∈ [0,1]³ in projector RGB, mixing rows summing to 1.
//
// Measurement model. The projector shows one flat field (every pixel the same drive d); a camera
// with a known linear response photographs it. At camera pixel p and channel i
//
//   m_p,i(d) = t_p,i · output_i(d) + a_p,i,
//
// t the transfer (camera value per unit projector output: exposure × vignetting × reflectance ×
// the geometric gain, PhotometricCalibrationOptions::transfer) and a the ambient light (a capture
// with the projector switched off, subtracted when given). Interreflections keep this form: a
// uniform flat field drives every surface in proportion to output_i(d), so the bounce light only
// scales t (per channel, through the reflectances). Hence:
//   - mixing, response and gamma and the ratio black/max come from ratios of measurements and are
//     exact whatever t is (bounce light included);
//   - black and max in absolute units need t, i.e. geometry and reflectance (and t must include
//     the bounce light to be exact; calibrate on a board, or where bounces are negligible).
// Estimates per flat field: v_i(d) = Σ_p m_p,i / Σ_p t_p,i over the mask (a ratio of sums: the
// noise of dark pixels does not blow up). Then black = v(0); max = v(1,1,1) if captured, else
// black + Σ_c (v(e_c) − black); mixing_ic = (v_i(e_c) − black_i) / (max_i − black_i) with rows
// normalised to 1; r_c(L) = the least-squares scale of (v(L e_c) − black) onto the column
// diag(max − black) · mixing_·c; gamma_c by Gauss-Newton on Σ (r − L^gamma)², seeded by the
// log-log fit; the table by linear interpolation of (L, r) at evenly spaced drives.

#include <Eigen/Core>
#include <array>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace procam {

// One flat-field capture.
struct FlatField {
  Eigen::Vector3d drive = Eigen::Vector3d::Zero();  // projector R, G, B in [0,1]: code / max code
  cv::Mat image;  // camera, linear in light, 3 channels B, G, R (capture's order), any depth
};

struct PhotometricCalibrationOptions {
  // Camera value per unit projector output at each pixel, 3 channels B, G, R, float, same size
  // as the images. Empty: ones, so black and max come out in camera units.
  cv::Mat transfer;
  // Pixels to use (CV_8UC1, non-zero = use). Empty: every pixel whose transfer is positive on
  // all channels and which brightens from black to the brightest field by at least
  // `min_contrast` of the image's largest such increase.
  cv::Mat mask;
  // A capture with the projector off (ambient and other projectors), subtracted from every
  // image. Empty: none.
  cv::Mat ambient;
  double min_contrast = 0.2;   // [0, 1), see `mask`
  int table_size = 33;         // entries of the response table, [2, 4096]
  double min_response = 0.01;  // relative light under which a level is left out of the gamma
                               // fit (dominated by noise and black), [0, 1)
  bool Check(std::string* why) const;
};

struct PhotometricModel {
  Eigen::Vector3d black = Eigen::Vector3d::Zero();         // working R, G, B
  Eigen::Vector3d max = Eigen::Vector3d::Ones();           // working R, G, B
  Eigen::Matrix3d mixing = Eigen::Matrix3d::Identity();    // rows sum to 1
  Eigen::Vector3d gamma = Eigen::Vector3d::Constant(2.2);  // per projector channel
  // Relative light r_c at drives 0, 1/(m−1), ..., 1 (m = table_size), from 0 to 1, increasing:
  // ResponseCurve::Table of projection/projector.h takes it as it is.
  std::array<std::vector<double>, 3> table;
  // Measured (drive, relative light) per channel, and the RMS of r − drive^gamma over them.
  std::array<std::vector<Eigen::Vector2d>, 3> samples;
  Eigen::Vector3d gamma_rms = Eigen::Vector3d::Zero();
  int pixels = 0;  // pixels used
  std::string BriefReport() const;
};

// Fits the model. `fields` must hold a black field (drive 0) and, per channel c, a field with
// drive 1 on c and 0 elsewhere; more levels per channel (d e_c) sample the response; a white field
// (1,1,1) gives max directly. Throws std::invalid_argument naming what is missing or mismatched.
PhotometricModel CalibratePhotometry(const std::vector<FlatField>& fields,
                                     const PhotometricCalibrationOptions& options = {});

}  // namespace procam
