#include "projection/seamless_light.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include <Eigen/Sparse>

namespace procam {

bool SeamlessLightOptions::Check(std::string* why) const {
  if (!(radius >= 0.5 && radius <= 5.0)) {
    *why = "radius must be in [0.5, 5]";
    return false;
  }
  if (rings < 1 || rings > 8) {
    *why = "rings must be in [1, 8]";
    return false;
  }
  if (iterations < 0 || iterations > 50) {
    *why = "iterations must be in [0, 50]";
    return false;
  }
  if (!(tolerance >= 0.0 && tolerance <= 1.0)) {
    *why = "tolerance must be in [0, 1]";
    return false;
  }
  return true;
}

namespace {

using Factors = std::vector<std::vector<Eigen::Vector3f>>;

// Whether patches i and j share a field: same surface, desired colours close (header comment).
bool ShareField(const ProjectionRig& rig, int i, int j, double tolerance) {
  if (rig.surface[i] != rig.surface[j]) return false;
  if (rig.desired.rows() != rig.size()) return true;
  for (int c = 0; c < 3; ++c) {
    const double a = rig.desired(i, c), b = rig.desired(j, c);
    if (std::abs(a - b) > tolerance * std::max(a, b) + 1e-12) return false;
  }
  return true;
}

// Per patch, the patches whose bumps make its field: itself first, then those reached within
// `rings` adjacency steps through patches that share its field (and are lit).
std::vector<std::vector<int>> FieldNodes(const ProjectionRig& rig,
                                         const SeamlessLightOptions& options) {
  const int n = rig.size();
  std::vector<std::vector<int>> neighbours(n);
  for (const auto& [a, b] : rig.adjacency) {
    if (a < 0 || b < 0 || a >= n || b >= n) {
      throw std::invalid_argument("SeamlessLightFactors: the rig's adjacency names patch " +
                                  std::to_string(std::max(a, b)) + " of " + std::to_string(n));
    }
    neighbours[a].push_back(b);
    neighbours[b].push_back(a);
  }
  std::vector<std::vector<int>> nodes(n);
#pragma omp parallel
  {
    std::vector<int> visited(n, -1);  // the patch whose search last reached it
#pragma omp for schedule(dynamic, 32)
    for (int i = 0; i < n; ++i) {
      std::vector<int>& list = nodes[i];
      list.push_back(i);
      visited[i] = i;
      size_t ring_begin = 0;
      for (int ring = 0; ring < options.rings; ++ring) {
        const size_t ring_end = list.size();
        for (size_t position = ring_begin; position < ring_end; ++position) {
          for (const int j : neighbours[list[position]]) {
            if (visited[j] == i) continue;
            visited[j] = i;
            if (rig.blended_area[j] > 0.0 && ShareField(rig, i, j, options.tolerance))
              list.push_back(j);
          }
        }
        ring_begin = ring_end;
      }
    }
  }
  return nodes;
}

// The field v(x) = Σ_j K̃_j(x) v̂_j (K̃ the bumps normalised to a partition of unity) is linear in
// the node values, so each patch's mean of it is a fixed row of an n×n matrix A: the corrections
// of the node values run on A alone, and the lit pixels are visited twice (forming A, and the
// factors).
class Field {
 public:
  Field(const ProjectionRig& rig, const SeamlessLightOptions& options)
      : rig_(rig), nodes_(FieldNodes(rig, options)), radius2_(rig.size()) {
    for (int j = 0; j < rig.size(); ++j)
      radius2_[j] = options.radius * options.radius * rig.area[j];
    DropNodesOutOfReach();
    FormPatchMeans();
  }

  // Per patch, the field's mean over its pixels (weights w a, the flux bookkeeping's).
  Eigen::MatrixX3d PatchMeans(const Eigen::MatrixX3d& node_value) const { return means_ * node_value; }

  // The field at every lit pixel (in pixels_by_patch order) of the patches that are not flat.
  void Values(const Eigen::MatrixX3d& node_value, Factors* values) const {
    ForEachPixel([&](int i, size_t k, int position, const std::vector<std::pair<int, double>>& bumps) {
      Eigen::Vector3d value = Eigen::Vector3d::Zero();
      for (const auto& [node, weight] : bumps) value += weight * node_value.row(nodes_[i][node]).transpose();
      (*values)[k][position] = value.cast<float>();
    });
  }

  bool Flat(int i) const { return nodes_[i].size() <= 1; }

 private:
  // Keeps, for each patch i, the nodes j whose bump can reach one of its points:
  // |c_i − c_j| < r_j + (the farthest of i's points from c_i). Exact: the others add nothing.
  void DropNodesOutOfReach() {
    const int n = rig_.size();
    std::vector<double> reach(n, 0.0);
    for (const ProjectorMap& map : rig_.maps) {
      for (int i = 0; i < n; ++i) {
        for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
          const double d = (map.point_by_patch[position].cast<double>() - rig_.centroid.row(i).transpose()).norm();
          reach[i] = std::max(reach[i], d);
        }
      }
    }
    for (int i = 0; i < n; ++i) {
      std::vector<int>& list = nodes_[i];
      list.erase(std::remove_if(list.begin() + 1, list.end(),
                                [&](int j) {
                                  const double d = (rig_.centroid.row(i) - rig_.centroid.row(j)).norm();
                                  return d >= std::sqrt(radius2_[j]) + reach[i];
                                }),
                 list.end());
    }
  }

  // Calls visit(i, k, position, bumps) for every lit pixel of every patch that is not flat, with
  // the normalised bumps (position in nodes_[i], K̃_j(x)) at its point; in parallel over patches.
  template <typename Visit>
  void ForEachPixel(Visit visit) const {
    const int n = rig_.size();
#pragma omp parallel
    {
      std::vector<std::pair<int, double>> bumps;
#pragma omp for schedule(dynamic, 16)
      for (int i = 0; i < n; ++i) {
        if (Flat(i)) continue;
        for (size_t k = 0; k < rig_.maps.size(); ++k) {
          const ProjectorMap& map = rig_.maps[k];
          for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
            Bumps(i, map.point_by_patch[position], &bumps);
            visit(i, k, position, bumps);
          }
        }
      }
    }
  }

  // The bumps at a point of patch i, normalised to sum 1, each by its node's position in
  // nodes_[i].
  void Bumps(int i, const Eigen::Vector3f& point, std::vector<std::pair<int, double>>* bumps) const {
    bumps->clear();
    double weight_sum = 0.0;
    const Eigen::Vector3d x = point.cast<double>();
    for (int node = 0; node < static_cast<int>(nodes_[i].size()); ++node) {
      const int j = nodes_[i][node];
      const double d2 = (x - rig_.centroid.row(j).transpose()).squaredNorm();
      if (d2 >= radius2_[j]) continue;
      const double t = 1.0 - d2 / radius2_[j];
      bumps->emplace_back(node, t * t);
      weight_sum += t * t;
    }
    // Only where a patch is so elongated that no bump reaches (outside the designed range): the
    // patch's own value (nodes_[i] starts with i).
    if (!(weight_sum > 0.0)) {
      bumps->assign(1, {0, 1.0});
      return;
    }
    for (auto& bump : *bumps) bump.second /= weight_sum;
  }

  // A: row i the pixel-weighted mean of the normalised bumps over patch i (e_i on flat patches).
  void FormPatchMeans() {
    const int n = rig_.size();
    std::vector<std::vector<double>> rows(n);  // Σ w K̃ per node of nodes_[i]
    for (int i = 0; i < n; ++i) rows[i].assign(nodes_[i].size(), 0.0);
    std::vector<double> row_weight(n, 0.0);
    ForEachPixel([&](int i, size_t k, int position, const std::vector<std::pair<int, double>>& bumps) {
      const ProjectorMap& map = rig_.maps[k];
      const double weight =
          rig_.coverage_scale(i, k) * map.pixel_solid_angle * map.share[map.pixels_by_patch[position]];
      for (const auto& [node, value] : bumps) rows[i][node] += weight * value;
      row_weight[i] += weight;  // patch i is visited by one thread only
    });
    std::vector<Eigen::Triplet<double>> triplets;
    for (int i = 0; i < n; ++i) {
      if (!(row_weight[i] > 0.0)) {
        triplets.emplace_back(i, i, 1.0);
        continue;
      }
      for (size_t node = 0; node < rows[i].size(); ++node) {
        if (rows[i][node] != 0.0) triplets.emplace_back(i, nodes_[i][node], rows[i][node] / row_weight[i]);
      }
    }
    means_.resize(n, n);
    means_.setFromTriplets(triplets.begin(), triplets.end());
  }

  const ProjectionRig& rig_;
  std::vector<std::vector<int>> nodes_;
  std::vector<double> radius2_;
  Eigen::SparseMatrix<double, Eigen::RowMajor> means_;  // A
};

void CheckInputs(const ProjectionRig& rig, const Eigen::MatrixX3d& exitance,
                 const SeamlessLightOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("SeamlessLightOptions: " + why);
  const int n = rig.size();
  if (exitance.rows() != n || !exitance.allFinite() || (exitance.array() < 0.0).any()) {
    throw std::invalid_argument("SeamlessLightFactors: need finite exitance >= 0 for each of " +
                                std::to_string(n) + " patches");
  }
  if (rig.centroid.rows() != n || static_cast<int>(rig.surface.size()) != n) {
    throw std::invalid_argument("SeamlessLightFactors: the rig has no patch centroids");
  }
  for (const ProjectorMap& map : rig.maps) {
    if (static_cast<int>(map.point_by_patch.size()) != map.lit_pixels) {
      throw std::invalid_argument(
          "SeamlessLightFactors: the rig has no hit points (build it with BuildProjectionRig)");
    }
  }
}

}  // namespace

Factors SeamlessLightFactors(const ProjectionRig& rig, const Eigen::MatrixX3d& exitance,
                             const SeamlessLightOptions& options) {
  CheckInputs(rig, exitance, options);
  const int n = rig.size();
  const Field field(rig, options);
  // Node values whose field has (nearly) each patch's own value as its mean over the patch.
  Eigen::MatrixX3d node_value = exitance;
  const double largest = exitance.size() > 0 ? exitance.maxCoeff() : 0.0;
  for (int iteration = 0; iteration < options.iterations; ++iteration) {
    const Eigen::MatrixX3d means = field.PatchMeans(node_value);
    for (int j = 0; j < n; ++j) {
      for (int c = 0; c < 3; ++c) {
        if (means(j, c) > 0.0 && exitance(j, c) > 0.0) {
          node_value(j, c) =
              std::min(node_value(j, c) * exitance(j, c) / means(j, c), 4.0 * largest);
        }
      }
    }
  }
  Factors factors(rig.maps.size());
  for (size_t k = 0; k < rig.maps.size(); ++k)
    factors[k].assign(rig.maps[k].lit_pixels, Eigen::Vector3f::Ones());
  field.Values(node_value, &factors);
  const Eigen::MatrixX3d means = field.PatchMeans(node_value);
  // m = v / mean(v) per patch and channel: the weighted mean of m is 1, so the flux is kept.
#pragma omp parallel for schedule(dynamic, 16)
  for (int i = 0; i < n; ++i) {
    if (field.Flat(i)) continue;
    for (size_t k = 0; k < rig.maps.size(); ++k) {
      const ProjectorMap& map = rig.maps[k];
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        Eigen::Vector3f& m = factors[k][position];
        for (int c = 0; c < 3; ++c)
          m[c] = means(i, c) > 0.0 ? static_cast<float>(m[c] / means(i, c)) : 1.0f;
      }
    }
  }
  return factors;
}

}  // namespace procam
