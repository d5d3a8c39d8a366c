#include "verification/model_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "projection/direct_light.h"

namespace procam {

ModelUpdate FitModel(const ModelFitOptions& options, const ProjectionRig& rig,
                     const std::vector<ProjectorImage>& images, const Eigen::MatrixXd& form_factors,
                     const Eigen::MatrixX3d& measured, const std::vector<bool>& seen,
                     const Eigen::MatrixX3d& predicted) {
  const int n = rig.size();
  DirectLightModel direct(rig, images);
  Eigen::MatrixX3d radiosity = predicted;  // measured where seen, the model's elsewhere
  for (int i = 0; i < n; ++i) {
    if (seen[i]) radiosity.row(i) = measured.row(i);
  }
  const Eigen::MatrixX3d bounce = form_factors * radiosity;
  // Patches and channels bright enough to fit on.
  std::array<std::vector<int>, 3> fit;
  Eigen::MatrixX3d target = Eigen::MatrixX3d::Zero(n, 3);  // log(B / ρ)
  const Eigen::MatrixX3d irradiance0 = direct.Irradiance();
  for (int c = 0; c < 3; ++c) {
    double brightest = 0.0;
    for (int i = 0; i < n; ++i) {
      if (seen[i]) brightest = std::max(brightest, measured(i, c));
    }
    for (int i = 0; i < n; ++i) {
      if (!seen[i] || !(measured(i, c) > 0.02 * brightest) || !(irradiance0(i, c) > 0.0) ||
          !(rig.reflectance(i, c) > 0.0))
        continue;
      fit[c].push_back(i);
      target(i, c) = std::log(measured(i, c) / rig.reflectance(i, c));
    }
  }
  auto objective = [&](Eigen::Vector3d* log_scale) {
    const Eigen::MatrixX3d irradiance = direct.Irradiance();
    double sum = 0.0;
    for (int c = 0; c < 3; ++c) {
      if (fit[c].empty()) continue;
      double mean = 0.0;
      std::vector<double> residual;
      residual.reserve(fit[c].size());
      for (const int i : fit[c]) {
        residual.push_back(target(i, c) - std::log(irradiance(i, c) + bounce(i, c)));
        mean += residual.back();
      }
      mean /= residual.size();
      if (log_scale) (*log_scale)[c] = mean;
      for (const double r : residual) sum += (r - mean) * (r - mean);
    }
    return sum;
  };

  ModelUpdate update;
  update.fit_patches = static_cast<int>(fit[0].size() + fit[1].size() + fit[2].size());
  const double count = std::max(1, update.fit_patches);
  update.rms_before = std::sqrt(objective(nullptr) / count);
  if (options.fit_response) {
    // Fit only the primaries of projectors that are the main light on enough patches.
    std::vector<bool> fittable(direct.projectors(), false);
    for (int k = 0; k < direct.projectors(); ++k) {
      const Eigen::MatrixX3d own = direct.Irradiance(k);
      int main = 0;
      for (const int i : fit[1]) main += own(i, 1) > 0.5 * irradiance0(i, 1);
      fittable[k] = main >= 3;
    }
    constexpr double kLow = -0.5, kHigh = 0.5;  // log p: p in [0.61, 1.65] per iteration
    const double golden = (std::sqrt(5.0) - 1.0) / 2.0;
    for (int sweep = 0; sweep < 3; ++sweep) {
      for (int k = 0; k < direct.projectors(); ++k) {
        if (!fittable[k]) continue;
        for (int j = 0; j < 3; ++j) {
          if (fit[j].empty()) continue;
          auto at = [&](double log_p) {
            direct.SetExponent(k, j, std::exp(log_p));
            return objective(nullptr);
          };
          double a = kLow, b = kHigh;
          double x1 = b - golden * (b - a), x2 = a + golden * (b - a);
          double f1 = at(x1), f2 = at(x2);
          for (int step = 0; step < 30; ++step) {
            if (f1 < f2) {
              b = x2, x2 = x1, f2 = f1;
              x1 = b - golden * (b - a);
              f1 = at(x1);
            } else {
              a = x1, x1 = x2, f1 = f2;
              x2 = a + golden * (b - a);
              f2 = at(x2);
            }
          }
          const double best = 0.5 * (a + b);
          // Keep the current exponent unless the fit really prefers another.
          const double current = std::log(direct.exponent(k)[j]);
          const double f_current = at(current);
          const double f_best = at(best);
          direct.SetExponent(k, j, std::exp(f_best < f_current ? best : current));
        }
      }
    }
  }
  Eigen::Vector3d log_scale = Eigen::Vector3d::Zero();
  update.rms_after = std::sqrt(objective(&log_scale) / count);
  for (int c = 0; c < 3; ++c) {
    if (!fit[c].empty()) update.scale[c] = std::clamp(std::exp(log_scale[c]), 0.5, 2.0);
  }
  for (int k = 0; k < direct.projectors(); ++k) update.exponent.push_back(direct.exponent(k));

  // Reflectance: ρ = B / (D + F B) where measured, else the common scale.
  update.reflectance = rig.reflectance;
  if (options.fit_reflectance) {
    const Eigen::MatrixX3d irradiance = direct.Irradiance();
    std::array<std::vector<bool>, 3> fitted;
    for (int c = 0; c < 3; ++c) {
      fitted[c].assign(n, false);
      for (const int i : fit[c]) fitted[c][i] = true;
    }
    for (int i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        const double old = rig.reflectance(i, c);
        if (!(old > 0.0)) continue;
        double estimate = old * update.scale[c];
        const double total = irradiance(i, c) + bounce(i, c);
        if (fitted[c][i] && total > 0.0) estimate = measured(i, c) / total;
        const double ratio = std::clamp(estimate / old, 0.5, 2.0);
        update.reflectance(i, c) =
            std::clamp(old * std::pow(ratio, options.reflectance_step), 0.01, 0.99);
      }
    }
  }
  return update;
}

void ApplyModelUpdate(const ModelUpdate& update, ProjectionRig* rig, PatchHierarchy* patches) {
  for (size_t k = 0; k < rig->projectors.size(); ++k) {
    ProjectorPhotometry& photometry = rig->projectors[k].photometry;
    for (int j = 0; j < 3; ++j) {
      const double p = update.exponent[k][j];
      if (p == 1.0) continue;
      const ResponseCurve& curve = photometry.response[j];
      if (curve.is_table()) {
        std::vector<double> table = curve.table();
        for (double& value : table) value = std::pow(value, p);
        photometry.response[j] = ResponseCurve::Table(table);
      } else {
        photometry.response[j] = ResponseCurve::Gamma(curve.gamma() * p);
      }
    }
  }
  for (int i = 0; i < rig->size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      const double old = rig->reflectance(i, c);
      if (!(old > 0.0)) continue;
      const double ratio = update.reflectance(i, c) / old;
      rig->lower(i, c) *= ratio;
      rig->upper(i, c) *= ratio;
    }
  }
  rig->reflectance = update.reflectance;
  patches->fine.reflectance = update.reflectance;
  patches->coarse.reflectance = CoarsenPatchValues(update.reflectance, patches->fine.Areas(),
                                                   patches->coarse_of_fine, patches->coarse.size());
}

bool ReflectanceMapFitOptions::Check(std::string* why) const {
  if (!(step > 0.0 && step <= 1.0)) {
    *why = "step must be in (0, 1]";
    return false;
  }
  if (!(max_gain > 1.0 && std::isfinite(max_gain))) {
    *why = "max_gain must be > 1";
    return false;
  }
  if (radius < 0 || radius > 50) {
    *why = "radius must be in [0, 50]";
    return false;
  }
  return true;
}

ReflectanceMapUpdate FitReflectanceMaps(const ReflectanceMapFitOptions& options,
                                        const CameraPixelRays& rays, const cv::Mat& measured,
                                        const cv::Mat& predicted, const std::vector<bool>& mask,
                                        ProjectionRig* rig) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("ReflectanceMapFitOptions: " + why);
  if (!HasReflectanceMaps(*rig))
    throw std::invalid_argument("FitReflectanceMaps: the rig has no reflectance maps");
  const size_t count = static_cast<size_t>(rays.width) * rays.height;
  const auto fits = [&](const cv::Mat& image) {
    return image.type() == CV_32FC3 && image.cols == rays.width && image.rows == rays.height &&
           image.isContinuous();
  };
  if (!fits(measured) || !fits(predicted) || mask.size() != count ||
      rays.projectors != static_cast<int>(rig->maps.size())) {
    throw std::invalid_argument(
        "FitReflectanceMaps: photo, prediction, mask and rays must be of the camera's size and "
        "the rays cast with the rig's projectors");
  }
  const auto* photo = reinterpret_cast<const cv::Vec3f*>(measured.data);
  const auto* model = reinterpret_cast<const cv::Vec3f*>(predicted.data);
  // The ratio per camera pixel (0 where not used), and each patch's mean ratio.
  const int n = rig->size();
  std::vector<Eigen::Vector3d> ratio(count, Eigen::Vector3d::Zero());
  std::vector<char> used(count, 0);
  Eigen::MatrixX3d patch_sum = Eigen::MatrixX3d::Zero(n, 3);
  Eigen::VectorXd patch_count = Eigen::VectorXd::Zero(n);
  for (size_t p = 0; p < count; ++p) {
    const int i = rays.patch[p];
    if (!mask[p] || i < 0 || i >= n) continue;
    bool ok = true;
    for (int c = 0; c < 3; ++c) {
      ok &= model[p][c] > 0.0f && photo[p][c] > 0.0f;
      if (ok) ratio[p][c] = double(photo[p][c]) / model[p][c];
    }
    if (!ok) continue;
    used[p] = 1;
    patch_sum.row(i) += ratio[p].transpose();
    patch_count[i] += 1.0;
  }
  ReflectanceMapUpdate update;
  double log_squares = 0.0;
  for (int k = 0; k < rays.projectors; ++k) {
    ProjectorMap& map = rig->maps[k];
    cv::Mat sums(map.height, map.width, CV_32FC3, cv::Scalar::all(0));
    cv::Mat counts(map.height, map.width, CV_32FC1, cv::Scalar::all(0));
    for (size_t p = 0; p < count; ++p) {
      if (!used[p]) continue;
      const int32_t q = rays.projector_pixel[p * rays.projectors + k];
      if (q < 0) continue;
      const int i = rays.patch[p];
      const Eigen::Vector3d relative =
          ratio[p].cwiseQuotient(patch_sum.row(i).transpose() / patch_count[i]);
      cv::Vec3f& sum = sums.at<cv::Vec3f>(q / map.width, q % map.width);
      for (int c = 0; c < 3; ++c) sum[c] += static_cast<float>(relative[c]);
      counts.at<float>(q / map.width, q % map.width) += 1.0f;
    }
    if (options.radius > 0) {
      const cv::Size box(2 * options.radius + 1, 2 * options.radius + 1);
      cv::boxFilter(sums, sums, -1, box, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
      cv::boxFilter(counts, counts, -1, box, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
    }
    const double low = 1.0 / options.max_gain;
    for (int row = 0; row < map.height; ++row) {
      for (int col = 0; col < map.width; ++col) {
        const size_t q = static_cast<size_t>(row) * map.width + col;
        const float samples = counts.at<float>(row, col);
        if (map.patch[q] < 0 || !(samples > 0.5f)) continue;
        const cv::Vec3f& sum = sums.at<cv::Vec3f>(row, col);
        for (int c = 0; c < 3; ++c) {
          const double gain =
              std::pow(std::clamp(double(sum[c]) / samples, low, options.max_gain), options.step);
          map.reflectance[q][c] = static_cast<float>(std::min(0.99, map.reflectance[q][c] * gain));
          log_squares += std::log(gain) * std::log(gain);
        }
        ++update.updated_pixels;
      }
    }
  }
  if (update.updated_pixels > 0)
    update.rms_log_gain = std::sqrt(log_squares / (3.0 * update.updated_pixels));
  return update;
}

}  // namespace procam
