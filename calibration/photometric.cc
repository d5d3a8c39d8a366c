#include "calibration/photometric.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace procam {
namespace {

cv::Mat ToFloat3(const cv::Mat& image, const char* what) {
  if (image.channels() != 3)
    throw std::invalid_argument(std::string("photometric calibration: ") + what +
                                " must have 3 channels (B, G, R), got " +
                                std::to_string(image.channels()));
  cv::Mat f;
  image.convertTo(f, CV_64FC3);
  return f;
}

// Which channel a drive excites alone, 3 for black, 4 for white, −1 otherwise.
int Kind(const Eigen::Vector3d& drive) {
  if (drive.isZero()) return 3;
  if ((drive.array() == 1.0).all()) return 4;
  int lit = -1, count = 0;
  for (int c = 0; c < 3; ++c) {
    if (drive[c] != 0.0) {
      lit = c;
      ++count;
    }
  }
  return count == 1 ? lit : -1;
}

}  // namespace

bool PhotometricCalibrationOptions::Check(std::string* why) const {
  auto fail = [&](const std::string& message) {
    if (why) *why = message;
    return false;
  };
  if (!(min_contrast >= 0.0 && min_contrast < 1.0)) return fail("min_contrast must be in [0, 1)");
  if (table_size < 2 || table_size > 4096) return fail("table_size must be in [2, 4096]");
  if (!(min_response >= 0.0 && min_response < 1.0)) return fail("min_response must be in [0, 1)");
  if (!transfer.empty() && transfer.channels() != 3) return fail("transfer must have 3 channels");
  if (!mask.empty() && mask.type() != CV_8UC1) return fail("mask must be CV_8UC1");
  return true;
}

std::string PhotometricModel::BriefReport() const {
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer),
                "black (%.5g, %.5g, %.5g), max (%.5g, %.5g, %.5g), gamma (%.4f, %.4f, %.4f), "
                "gamma fit rms (%.2g, %.2g, %.2g), mixing diagonal (%.4f, %.4f, %.4f), %d pixels",
                black[0], black[1], black[2], max[0], max[1], max[2], gamma[0], gamma[1],
                gamma[2], gamma_rms[0], gamma_rms[1], gamma_rms[2], mixing(0, 0), mixing(1, 1),
                mixing(2, 2), pixels);
  return buffer;
}

PhotometricModel CalibratePhotometry(const std::vector<FlatField>& fields,
                                     const PhotometricCalibrationOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("photometric calibration: " + why);
  if (fields.empty()) throw std::invalid_argument("photometric calibration: no flat fields");
  const cv::Size size = fields[0].image.size();
  std::vector<cv::Mat> images;
  int black_index = -1, white_index = -1;
  std::array<int, 3> full = {-1, -1, -1};
  for (size_t f = 0; f < fields.size(); ++f) {
    const Eigen::Vector3d& d = fields[f].drive;
    if (!((d.array() >= 0.0).all() && (d.array() <= 1.0).all()))
      throw std::invalid_argument("photometric calibration: field " + std::to_string(f) +
                                  " has a drive outside [0,1]");
    if (fields[f].image.size() != size)
      throw std::invalid_argument("photometric calibration: field " + std::to_string(f) +
                                  " differs in size from field 0");
    cv::Mat image = ToFloat3(fields[f].image, "flat fields");
    if (!options.ambient.empty()) image -= ToFloat3(options.ambient, "ambient");
    images.push_back(image);
    const int kind = Kind(d);
    if (kind == 3) black_index = static_cast<int>(f);
    if (kind == 4) white_index = static_cast<int>(f);
    if (kind >= 0 && kind < 3 && d[kind] == 1.0) full[kind] = static_cast<int>(f);
  }
  if (black_index < 0) throw std::invalid_argument("photometric calibration: no black field");
  for (int c = 0; c < 3; ++c) {
    if (full[c] < 0)
      throw std::invalid_argument(std::string("photometric calibration: no field with channel ") +
                                  "RGB"[c] + " at full drive and the others at 0");
  }

  cv::Mat transfer = options.transfer.empty() ? cv::Mat(size, CV_64FC3, cv::Scalar::all(1.0))
                                              : ToFloat3(options.transfer, "transfer");
  if (transfer.size() != size)
    throw std::invalid_argument("photometric calibration: transfer differs in size from the fields");

  // Pixels used.
  cv::Mat mask;
  if (!options.mask.empty()) {
    if (options.mask.size() != size)
      throw std::invalid_argument("photometric calibration: mask differs in size from the fields");
    mask = options.mask != 0;
  } else {
    const cv::Mat& brightest = images[white_index >= 0 ? white_index : full[1]];
    cv::Mat increase;
    cv::transform(brightest - images[black_index], increase, cv::Matx13d(1, 1, 1));
    double largest = 0.0;
    cv::minMaxLoc(increase, nullptr, &largest);
    mask = increase > options.min_contrast * largest;
    std::vector<cv::Mat> t;
    cv::split(transfer, t);
    for (const cv::Mat& channel : t) mask &= channel > 0.0;
  }
  PhotometricModel model;
  model.pixels = cv::countNonZero(mask);
  if (model.pixels == 0) throw std::invalid_argument("photometric calibration: no usable pixels");

  // v(field), working R, G, B: ratio of sums over the mask.
  cv::Scalar t_sum = cv::Scalar::all(0.0);
  {
    cv::Mat masked;
    transfer.copyTo(masked, mask);
    t_sum = cv::sum(masked);
  }
  std::vector<Eigen::Vector3d> value(fields.size());
  for (size_t f = 0; f < fields.size(); ++f) {
    cv::Mat masked;
    images[f].copyTo(masked, mask);
    const cv::Scalar sum = cv::sum(masked);
    for (int i = 0; i < 3; ++i) value[f][i] = sum[2 - i] / t_sum[2 - i];
  }

  model.black = value[black_index];
  Eigen::Vector3d above_black_sum = Eigen::Vector3d::Zero();
  for (int c = 0; c < 3; ++c) above_black_sum += value[full[c]] - model.black;
  model.max = white_index >= 0 ? value[white_index] : Eigen::Vector3d(model.black + above_black_sum);
  for (int i = 0; i < 3; ++i) {
    for (int c = 0; c < 3; ++c)
      model.mixing(i, c) = std::max(0.0, value[full[c]][i] - model.black[i]);
    const double row = model.mixing.row(i).sum();
    if (!(row > 0.0))
      throw std::invalid_argument(std::string("photometric calibration: working channel ") +
                                  "RGB"[i] + " does not brighten with any projector channel");
    model.mixing.row(i) /= row;
  }

  // Response samples per channel: the least-squares scale onto the mixing column.
  for (int c = 0; c < 3; ++c) {
    const Eigen::Vector3d column = (model.max - model.black).cwiseProduct(model.mixing.col(c));
    std::vector<Eigen::Vector2d>& samples = model.samples[c];
    samples.push_back(Eigen::Vector2d(0.0, 0.0));
    for (size_t f = 0; f < fields.size(); ++f) {
      if (Kind(fields[f].drive) != c) continue;
      const double r = column.dot(value[f] - model.black) / column.squaredNorm();
      samples.push_back(Eigen::Vector2d(fields[f].drive[c], r));
    }
    std::sort(samples.begin(), samples.end(),
              [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a[0] < b[0]; });

    // Gamma: log-log seed, then Gauss-Newton on the light itself.
    double sxy = 0.0, sxx = 0.0;
    std::vector<Eigen::Vector2d> fit;
    for (const Eigen::Vector2d& s : samples) {
      if (s[0] <= 0.0 || s[0] >= 1.0 || s[1] < options.min_response) continue;
      fit.push_back(s);
      sxy += std::log(s[0]) * std::log(s[1]);
      sxx += std::log(s[0]) * std::log(s[0]);
    }
    double gamma = sxx > 0.0 ? sxy / sxx : 2.2;
    for (int iteration = 0; iteration < 20 && !fit.empty(); ++iteration) {
      double jtj = 0.0, jtr = 0.0;
      for (const Eigen::Vector2d& s : fit) {
        const double predicted = std::pow(s[0], gamma);
        const double jacobian = predicted * std::log(s[0]);
        jtj += jacobian * jacobian;
        jtr += jacobian * (s[1] - predicted);
      }
      if (!(jtj > 0.0)) break;
      const double step = jtr / jtj;
      gamma = std::clamp(gamma + step, 0.05, 20.0);
      if (std::abs(step) < 1e-12) break;
    }
    model.gamma[c] = gamma;
    double sq = 0.0;
    for (const Eigen::Vector2d& s : fit) sq += std::pow(s[1] - std::pow(s[0], gamma), 2);
    model.gamma_rms[c] = fit.empty() ? 0.0 : std::sqrt(sq / fit.size());

    // Table: linear interpolation of the samples, forced strictly increasing, 0 → 1.
    std::vector<double>& table = model.table[c];
    table.resize(options.table_size);
    for (int j = 0; j < options.table_size; ++j) {
      const double d = static_cast<double>(j) / (options.table_size - 1);
      size_t k = 1;
      while (k + 1 < samples.size() && samples[k][0] < d) ++k;
      const Eigen::Vector2d& a = samples[k - 1];
      const Eigen::Vector2d& b = samples[k];
      const double t = b[0] > a[0] ? std::clamp((d - a[0]) / (b[0] - a[0]), 0.0, 1.0) : 1.0;
      table[j] = a[1] + t * (b[1] - a[1]);
    }
    for (int j = 1; j < options.table_size; ++j)
      table[j] = std::max(table[j], table[j - 1] + 1e-9);
    const double first = table.front(), range = table.back() - table.front();
    for (double& r : table) r = (r - first) / range;
  }
  return model;
}

}  // namespace procam
