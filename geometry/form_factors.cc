#include "geometry/form_factors.h"

#include <omp.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <numbers>
#include <string>

#include "base/stop.h"
#include "base/timing.h"
#include "geometry/ray_scene.h"

namespace procam {
namespace {

// Sutherland–Hodgman: keeps the part of the polygon with normal·(p − x) ≥ 0.
int ClipToHemisphere(const Vec3& x, const Vec3& normal, const Vec3* polygon, int count, Vec3* out) {
  int kept = 0;
  for (int k = 0; k < count; ++k) {
    const Vec3& a = polygon[k];
    const Vec3& b = polygon[(k + 1) % count];
    const double da = normal.dot(a - x), db = normal.dot(b - x);
    if (da >= 0) out[kept++] = a;
    if ((da >= 0) != (db >= 0)) out[kept++] = a + (da / (da - db)) * (b - a);
  }
  return kept;
}

}  // namespace

bool FormFactorOptions::Check(std::string* why) const {
  if (far_samples < 1 || near_samples < far_samples || near_samples > 64) {
    *why = "need 1 <= far_samples <= near_samples <= 64";
    return false;
  }
  if (!(near_scale > 0.0)) {
    *why = "near_scale must be positive";
    return false;
  }
  if (threads < 0) {
    *why = "threads must be >= 0";
    return false;
  }
  return true;
}

double PointToPolygonFormFactor(const Vec3& x, const Vec3& normal, const Vec3* polygon, int count) {
  // Seen from its back side (or edge-on) the polygon sends nothing to x.
  const Vec3 polygon_normal = (polygon[1] - polygon[0]).cross(polygon[2] - polygon[0]);
  if (polygon_normal.dot(x - polygon[0]) <= 0.0) return 0.0;
  Vec3 clipped[12];
  const int kept = ClipToHemisphere(x, normal, polygon, count, clipped);
  if (kept < 3) return 0.0;
  // Lambert's contour formula: F = (1/2π) Σ_k γ_k n·(R_k × R_k+1)/|R_k × R_k+1|.
  double sum = 0.0;
  for (int k = 0; k < kept; ++k) {
    const Vec3 a = (clipped[k] - x).normalized();
    const Vec3 b = (clipped[(k + 1) % kept] - x).normalized();
    const Vec3 cross = a.cross(b);
    const double sine = cross.norm();
    if (sine < 1e-15) continue;
    const double angle = std::atan2(sine, a.dot(b));
    sum += angle * normal.dot(cross) / sine;
  }
  return std::abs(sum) / (2.0 * std::numbers::pi);
}

namespace {

// Exchange areas A_i F_ij = A_j F_ji of patch pairs of one level: k² quadrature points on each
// side, one shadow ray per point pair, both one-sided estimates averaged. Thread-safe queries.
class PairIntegrator {
 public:
  PairIntegrator(const Scene& scene, const PatchLevel& level, const FormFactorOptions& options)
      : level_(level), options_(options) {
    if (options.visibility) rays_ = std::make_unique<RayScene>(scene);
    // Margin that keeps shadow rays off the surfaces they start and end on.
    Eigen::AlignedBox3d box;
    for (const Patch& patch : level.patches) {
      for (int k = 0; k < patch.corner_count; ++k) box.extend(patch.corners[k]);
    }
    margin_ = std::max(1e-6, 1e-5 * box.diagonal().norm());
    const int n = level.size();
    samples_.resize(n);
    radius_.resize(n);
    for (int i = 0; i < n; ++i) {
      SamplePatch(level.patches[i], options.far_samples, &samples_[i]);
      radius_[i] = std::sqrt(level.patches[i].area);
    }
  }

  // Per-thread scratch and counters.
  struct Scratch {
    std::vector<PatchSample> near_i, near_j;
    int64_t pairs = 0, rays = 0;
  };

  // A_i F_ij; 0 when one patch lies wholly behind the other's plane or every ray is blocked.
  double Exchange(int i, int j, Scratch* scratch) const {
    const Patch& pi = level_.patches[i];
    const Patch& pj = level_.patches[j];
    // Skip pairs where one patch lies wholly behind the other's plane.
    bool j_in_front = false, i_in_front = false;
    for (int k = 0; k < pj.corner_count; ++k) j_in_front |= pi.normal.dot(pj.corners[k] - pi.centroid) > margin_;
    for (int k = 0; k < pi.corner_count; ++k) i_in_front |= pj.normal.dot(pi.corners[k] - pj.centroid) > margin_;
    if (!j_in_front || !i_in_front) return 0.0;
    ++scratch->pairs;
    const double distance = (pi.centroid - pj.centroid).norm();
    const int k = std::clamp(static_cast<int>(std::ceil(options_.near_scale * (radius_[i] + radius_[j]) / distance)),
                             options_.far_samples, options_.near_samples);
    double exchange_from_i = 0.0, exchange_from_j = 0.0;
    // Estimates both exchange areas with k² samples; returns how many rays were blocked.
    auto estimate = [&](int order) {
      const std::vector<PatchSample>* si = &samples_[i];
      const std::vector<PatchSample>* sj = &samples_[j];
      if (order != options_.far_samples) {
        SamplePatch(pi, order, &scratch->near_i);
        SamplePatch(pj, order, &scratch->near_j);
        si = &scratch->near_i;
        sj = &scratch->near_j;
      }
      const int count = order * order;
      const int stride = (count % 7 == 0) ? 11 : 7;  // coprime with count: a permutation
      exchange_from_i = exchange_from_j = 0.0;
      int blocked = 0;
      for (int s = 0; s < count; ++s) {
        const PatchSample& x = (*si)[s];
        const PatchSample& y = (*sj)[(static_cast<int64_t>(s) * stride + count / 2) % count];
        if (rays_) {
          ++scratch->rays;
          if (rays_->Occluded(x.point, y.point, margin_)) {
            ++blocked;
            continue;
          }
        }
        exchange_from_i += x.weight * PointToPolygonFormFactor(x.point, pi.normal, pj.corners.data(), pj.corner_count);
        exchange_from_j += y.weight * PointToPolygonFormFactor(y.point, pj.normal, pi.corners.data(), pi.corner_count);
      }
      return std::pair<int, int>(blocked, count);
    };
    const auto [blocked, count] = estimate(k);
    // Partly shadowed pairs get the finest sampling: the shadow edge dominates their error.
    if (blocked > 0 && blocked < count && k < options_.near_samples) estimate(options_.near_samples);
    return 0.5 * (exchange_from_i + exchange_from_j);
  }

  const RayScene* rays() const { return rays_.get(); }
  double margin() const { return margin_; }

 private:
  const PatchLevel& level_;
  const FormFactorOptions& options_;
  std::unique_ptr<RayScene> rays_;
  double margin_ = 1e-6;
  std::vector<std::vector<PatchSample>> samples_;
  std::vector<double> radius_;
};

}  // namespace

Eigen::MatrixXd ComputeFormFactors(const Scene& scene, const PatchLevel& level,
                                   const FormFactorOptions& options, FormFactorSummary* summary) {
  const auto start = Clock::now();
  const int n = level.size();
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(n, n);
  const PairIntegrator integrator(scene, level, options);
  std::atomic<int64_t> pairs{0}, shadow_rays{0}, rows_done{0};
  const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
#pragma omp parallel num_threads(threads)
  {
    PairIntegrator::Scratch scratch;
#pragma omp for schedule(dynamic, 8)
    for (int i = 0; i < n; ++i) {
      if (StopRequested()) continue;  // a signal: the rows left are skipped, Stopped below
      for (int j = i + 1; j < n; ++j) {
        const double exchange = integrator.Exchange(i, j, &scratch);
        if (exchange == 0.0) continue;
        f(i, j) = exchange / level.patches[i].area;
        f(j, i) = exchange / level.patches[j].area;
      }
      const int64_t done = ++rows_done;
      if (options.progress && omp_get_thread_num() == 0 && done % std::max(1, n / 50) == 0) {
        // Rows shrink as i grows: weight progress by the pairs done so far.
        const double remaining = static_cast<double>(n - done) / n;
        options.progress(1.0 - remaining * remaining);
      }
    }
    pairs += scratch.pairs;
    shadow_rays += scratch.rays;
  }
  if (StopRequested()) {
    const double remaining = static_cast<double>(n - rows_done) / std::max(n, 1);
    // std::to_string, not fmt: procam-form-factor-bench builds this file without fmt.
    throw Stopped(
        "form factors of " + std::to_string(n) + " patches: stopped at " +
        std::to_string(static_cast<int>(std::lround(100.0 * (1.0 - remaining * remaining)))) + "%");
  }
  if (options.progress) options.progress(1.0);
  const double correction = LimitRowSums(&f);
  if (summary != nullptr) {
    summary->max_row_correction = correction;
    summary->pairs_evaluated = pairs;
    summary->shadow_rays = shadow_rays;
    SummariseFormFactors(f, level.Areas(), summary);
    summary->seconds = SecondsSince(start);
  }
  return f;
}

CompressedFormFactors ComputeCompressedFormFactors(const Scene& scene, const PatchLevel& level,
                                                   const FormFactorOptions& options,
                                                   const ClusterOptions& clusters,
                                                   CompressedBuildSummary* summary) {
  const PairIntegrator integrator(scene, level, options);
  std::vector<ClusterPatch> patches(level.size());
  for (int i = 0; i < level.size(); ++i) {
    const Patch& patch = level.patches[i];
    patches[i] = {patch.centroid, patch.normal, patch.area, patch.surface};
  }
  const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
  std::vector<PairIntegrator::Scratch> scratch(threads);
  const PairExchange exchange = [&](int i, int j) {
    return integrator.Exchange(i, j, &scratch[omp_get_thread_num()]);
  };
  Visibility visible;
  if (integrator.rays() != nullptr) {
    visible = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
      return !integrator.rays()->Occluded(a, b, integrator.margin());
    };
  }
  CompressedFormFactors f =
      BuildCompressedFormFactors(patches, clusters, exchange, visible, threads, options.progress, summary);
  if (summary != nullptr) {
    for (const auto& s : scratch) summary->visibility_rays += s.rays;
  }
  return f;
}

double LimitRowSums(Eigen::MatrixXd* f) {
  const Eigen::VectorXd rows = f->rowwise().sum();
  Eigen::VectorXd scale = Eigen::VectorXd::Ones(rows.size());
  for (int i = 0; i < rows.size(); ++i) {
    if (rows[i] > 1.0) scale[i] = 1.0 / rows[i];
  }
  if ((scale.array() == 1.0).all()) return 0.0;
  // G = diag(A) F is symmetric, and diag(s) G diag(s) = diag(A) (diag(s) F diag(s)) stays so;
  // row i then sums to at most s_i · rows_i = 1 because every s_j ≤ 1.
  *f = scale.asDiagonal() * (*f) * scale.asDiagonal();
  return 1.0 - scale.minCoeff();
}

void SummariseFormFactors(const Eigen::MatrixXd& f, const Eigen::VectorXd& area,
                          FormFactorSummary* summary) {
  const Eigen::VectorXd rows = f.rowwise().sum();
  summary->min_row_sum = rows.size() ? rows.minCoeff() : 0.0;
  summary->max_row_sum = rows.size() ? rows.maxCoeff() : 0.0;
  summary->mean_row_sum = rows.size() ? rows.mean() : 0.0;
  double worst = 0.0;
  for (int i = 0; i < f.rows(); ++i) {
    for (int j = i + 1; j < f.cols(); ++j) {
      const double a = area[i] * f(i, j), b = area[j] * f(j, i);
      const double scale = std::max(std::max(a, b), 1e-300);
      if (a != 0.0 || b != 0.0) worst = std::max(worst, std::abs(a - b) / scale);
    }
  }
  summary->max_reciprocity_error = worst;
}

Eigen::MatrixXd AggregateFormFactors(const Eigen::MatrixXd& fine_f, const Eigen::VectorXd& fine_area,
                                     const std::vector<int>& coarse_of_fine, int coarse_count) {
  const int n = static_cast<int>(fine_f.rows());
  // Exchange areas add up; divide by the coarse area at the end.
  Eigen::MatrixXd by_column = Eigen::MatrixXd::Zero(n, coarse_count);
  for (int j = 0; j < n; ++j) by_column.col(coarse_of_fine[j]) += fine_f.col(j);
  Eigen::MatrixXd coarse = Eigen::MatrixXd::Zero(coarse_count, coarse_count);
  Eigen::VectorXd coarse_area = Eigen::VectorXd::Zero(coarse_count);
  for (int i = 0; i < n; ++i) {
    coarse.row(coarse_of_fine[i]) += fine_area[i] * by_column.row(i);
    coarse_area[coarse_of_fine[i]] += fine_area[i];
  }
  return coarse_area.cwiseInverse().asDiagonal() * coarse;
}

}  // namespace procam
