#include "projection/photometric_transfer.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace procam {

cv::Mat PhotometricTransfer(const CameraPixelLighting& lighting, const PatchLevel& level,
                            const UnitLightModel& model, const Eigen::Vector3d& camera_scale) {
  cv::Mat transfer(lighting.height, lighting.width, CV_32FC3, cv::Scalar::all(0));
  for (int row = 0; row < lighting.height; ++row) {
    for (int col = 0; col < lighting.width; ++col) {
      const size_t index = static_cast<size_t>(row) * lighting.width + col;
      const int i = lighting.patch[index];
      if (i < 0) continue;
      cv::Vec3f& value = transfer.at<cv::Vec3f>(row, col);
      for (int c = 0; c < 3; ++c) {  // working R, G, B → camera B, G, R
        value[2 - c] = static_cast<float>(camera_scale[c] * level.reflectance(i, c) *
                                          (lighting.gain[index] + model.bounce_irradiance(i, c)));
      }
    }
  }
  return transfer;
}

ReflectanceEstimate EstimatePatchReflectance(const CameraPixelLighting& lighting,
                                             const PatchLevel& level,
                                             const Eigen::MatrixXd& form_factors,
                                             const UnitLightModel& model, const cv::Mat& difference,
                                             const cv::Mat& mask, const Eigen::Vector3d& output,
                                             const Eigen::Vector3d& camera_scale, int min_pixels) {
  const int n = level.size();
  CV_Assert(difference.type() == CV_32FC3 && difference.rows == lighting.height &&
            difference.cols == lighting.width);
  ReflectanceEstimate estimate;
  estimate.pixels.assign(n, 0);
  // Per patch: Σ measured exitance and Σ direct irradiance over its usable pixels.
  Eigen::MatrixX3d exitance_sum = Eigen::MatrixX3d::Zero(n, 3);
  Eigen::MatrixX3d direct_sum = Eigen::MatrixX3d::Zero(n, 3);
  for (int row = 0; row < lighting.height; ++row) {
    for (int col = 0; col < lighting.width; ++col) {
      const size_t index = static_cast<size_t>(row) * lighting.width + col;
      const int i = lighting.patch[index];
      if (i < 0 || (!mask.empty() && mask.at<uchar>(row, col) == 0)) continue;
      const cv::Vec3f& value = difference.at<cv::Vec3f>(row, col);
      ++estimate.pixels[i];
      for (int c = 0; c < 3; ++c) {
        exitance_sum(i, c) += value[2 - c] / camera_scale[c];
        direct_sum(i, c) += lighting.gain[index] * output[c];
      }
    }
  }
  std::vector<int> seen, unseen;
  for (int i = 0; i < n; ++i) (estimate.pixels[i] >= min_pixels ? seen : unseen).push_back(i);
  estimate.patches_seen = static_cast<int>(seen.size());

  // Radiosity B: measured where seen; elsewhere the model with the nominal reflectance, driven
  // by the measured B: (I − diag(ρ_U) F_UU) B_U = ρ_U ⊙ (Ḡ_U o + F_US B_S).
  Eigen::MatrixX3d radiosity = Eigen::MatrixX3d::Zero(n, 3);
  for (const int i : seen) {
    radiosity.row(i) = exitance_sum.row(i) / estimate.pixels[i];
  }
  if (!unseen.empty()) {
    const int u = static_cast<int>(unseen.size());
    Eigen::MatrixXd f_uu(u, u);
    for (int a = 0; a < u; ++a) {
      for (int b = 0; b < u; ++b) f_uu(a, b) = form_factors(unseen[a], unseen[b]);
    }
    for (int c = 0; c < 3; ++c) {
      Eigen::VectorXd rhs(u);
      Eigen::MatrixXd system = -f_uu;
      for (int a = 0; a < u; ++a) {
        const int i = unseen[a];
        const double rho = level.reflectance(i, c);
        double bounce = 0.0;
        for (const int j : seen) bounce += form_factors(i, j) * radiosity(j, c);
        rhs[a] = rho * (model.direct_irradiance(i, c) * output[c] + bounce);
        system.row(a) *= rho;
        system(a, a) += 1.0;
      }
      const Eigen::VectorXd b_unseen = system.partialPivLu().solve(rhs);
      for (int a = 0; a < u; ++a) radiosity(unseen[a], c) = b_unseen[a];
    }
  }
  const Eigen::MatrixX3d bounce = form_factors * radiosity;
  estimate.bounce_irradiance = bounce;

  estimate.reflectance = level.reflectance;
  for (const int i : seen) {
    for (int c = 0; c < 3; ++c) {
      const double irradiance = direct_sum(i, c) + estimate.pixels[i] * bounce(i, c);
      if (irradiance > 0.0) {
        estimate.reflectance(i, c) = std::clamp(exitance_sum(i, c) / irradiance, 0.0, 0.99);
      }
    }
  }
  return estimate;
}

std::vector<Eigen::Vector3d> SeparateBlackLevels(const std::vector<cv::Mat>& transfers,
                                                 const cv::Mat& black_field, double camera_black) {
  const size_t count = transfers.size();
  if (count == 0) throw std::invalid_argument("SeparateBlackLevels: no projectors");
  if (black_field.type() != CV_32FC3)
    throw std::invalid_argument("SeparateBlackLevels: the black field must be CV_32FC3");
  for (const cv::Mat& transfer : transfers) {
    if (transfer.type() != CV_32FC3 || transfer.size() != black_field.size())
      throw std::invalid_argument("SeparateBlackLevels: transfers and black field differ in size");
  }
  std::vector<Eigen::Vector3d> black(count, Eigen::Vector3d::Zero());
  for (int c = 0; c < 3; ++c) {
    const int camera_channel = 2 - c;
    Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(count, count);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(count);
    Eigen::VectorXd t(count);
    for (int row = 0; row < black_field.rows; ++row) {
      for (int col = 0; col < black_field.cols; ++col) {
        bool lit = false;
        for (size_t j = 0; j < count; ++j) {
          t[j] = transfers[j].at<cv::Vec3f>(row, col)[camera_channel];
          lit = lit || t[j] > 0;
        }
        if (!lit) continue;
        normal += t * t.transpose();
        rhs += t * (black_field.at<cv::Vec3f>(row, col)[camera_channel] - camera_black);
      }
    }
    const Eigen::LDLT<Eigen::MatrixXd> solve(normal);
    if (solve.info() != Eigen::Success || !(solve.vectorD().minCoeff() > 1e-12 * normal.trace())) {
      throw std::invalid_argument(
          "SeparateBlackLevels: the projectors' light cannot be told apart in the black field");
    }
    const Eigen::VectorXd x = solve.solve(rhs);
    for (size_t j = 0; j < count; ++j) black[j][c] = x[j];
  }
  return black;
}

}  // namespace procam
