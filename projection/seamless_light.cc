#include "projection/seamless_light.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
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

void CheckRig(const ProjectionRig& rig) {
  const int n = rig.size();
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

// Keeps, for each patch i, the nodes j whose bump can reach one of its points:
// |c_i − c_j| < r_j + (the farthest of i's points from c_i). Exact: the others add nothing.
void DropNodesOutOfReach(const ProjectionRig& rig, const std::vector<double>& radius2,
                         std::vector<std::vector<int>>* nodes) {
  const int n = rig.size();
  std::vector<double> reach(n, 0.0);
  for (const ProjectorMap& map : rig.maps) {
    for (int i = 0; i < n; ++i) {
      for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
        const double d =
            (map.point_by_patch[position].cast<double>() - rig.centroid.row(i).transpose()).norm();
        reach[i] = std::max(reach[i], d);
      }
    }
  }
  for (int i = 0; i < n; ++i) {
    std::vector<int>& list = (*nodes)[i];
    list.erase(std::remove_if(list.begin() + 1, list.end(),
                              [&](int j) {
                                const double d = (rig.centroid.row(i) - rig.centroid.row(j)).norm();
                                return d >= std::sqrt(radius2[j]) + reach[i];
                              }),
               list.end());
  }
}

}  // namespace

// The field v(x) = Σ_j K̃_j(x) v̂_j (K̃ the bumps normalised to a partition of unity) is linear in
// the node values, so each patch's mean of it is a fixed row of an n×n matrix A: the corrections
// of the node values run on A alone, and the lit pixels are visited twice (forming A, and the
// factors).
struct SeamlessField::Means {
  Eigen::SparseMatrix<double, Eigen::RowMajor> matrix;
};

SeamlessField::SeamlessField(const ProjectionRig& rig, const SeamlessLightOptions& options)
    : rig_(rig), options_(options), radius2_(rig.size()), means_(std::make_unique<Means>()) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("SeamlessLightOptions: " + why);
  CheckRig(rig);
  const int n = rig.size();
  for (int j = 0; j < n; ++j) radius2_[j] = options.radius * options.radius * rig.area[j];
  std::vector<std::vector<int>> nodes = FieldNodes(rig, options);
  DropNodesOutOfReach(rig, radius2_, &nodes);
  node_begin_.assign(n + 1, 0);
  for (int i = 0; i < n; ++i) {
    // Bumps name their node by its position in the list in 16 bits (FactorBumps).
    if (nodes[i].size() > std::numeric_limits<uint16_t>::max()) {
      throw std::invalid_argument("SeamlessField: patch " + std::to_string(i) + " has " +
                                  std::to_string(nodes[i].size()) +
                                  " nodes, more than 65535 (a smaller radius or fewer rings)");
    }
    node_begin_[i + 1] = node_begin_[i] + static_cast<int>(nodes[i].size());
  }
  node_list_.reserve(node_begin_[n]);
  for (const std::vector<int>& list : nodes)
    node_list_.insert(node_list_.end(), list.begin(), list.end());
  node_bump_.reserve(node_list_.size());
  for (const int j : node_list_) {
    node_bump_.emplace_back(rig.centroid(j, 0), rig.centroid(j, 1), rig.centroid(j, 2),
                            radius2_[j]);
  }
  FormPatchMeans();
}

SeamlessField::~SeamlessField() = default;

void SeamlessField::Bumps(int i, const Eigen::Vector3f& point,
                          std::vector<std::pair<int, double>>* bumps) const {
  bumps->clear();
  double weight_sum = 0.0;
  const Eigen::Vector3d x = point.cast<double>();
  const int begin = node_begin_[i], end = node_begin_[i + 1];
  for (int node = 0; node < end - begin; ++node) {
    const double t2 = BumpSquared(begin + node, x);
    if (t2 < 0.0) continue;
    bumps->emplace_back(node, t2);
    weight_sum += t2;
  }
  if (!(weight_sum > 0.0)) {
    bumps->assign(1, {0, 1.0});
    return;
  }
  for (auto& bump : *bumps) bump.second /= weight_sum;
}

template <typename Visit>
void SeamlessField::ForEachPixel(Visit visit) const {
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

// A: row i the pixel-weighted mean of the normalised bumps over patch i (e_i on flat patches).
void SeamlessField::FormPatchMeans() {
  const int n = rig_.size();
  std::vector<std::vector<double>> rows(n);  // Σ w K̃ per node of patch i's list
  for (int i = 0; i < n; ++i) rows[i].assign(node_begin_[i + 1] - node_begin_[i], 0.0);
  std::vector<double> row_weight(n, 0.0);
  node_share_reach_.assign(node_list_.size(), 0.0);
  ForEachPixel(
      [&](int i, size_t k, int position, const std::vector<std::pair<int, double>>& bumps) {
        const ProjectorMap& map = rig_.maps[k];
        const double share = map.share[map.pixels_by_patch[position]];
        const double weight = rig_.coverage_scale(i, k) * map.pixel_solid_angle * share;
        for (const auto& [node, value] : bumps) {
          rows[i][node] += weight * value;
          double& share_reach = node_share_reach_[node_begin_[i] + node];
          share_reach = std::max(share_reach, share * value);
        }
        row_weight[i] += weight;  // patch i is visited by one thread only
      });
  std::vector<Eigen::Triplet<double>> triplets;
  for (int i = 0; i < n; ++i) {
    if (!(row_weight[i] > 0.0)) {
      triplets.emplace_back(i, i, 1.0);
      continue;
    }
    for (size_t node = 0; node < rows[i].size(); ++node) {
      if (rows[i][node] != 0.0)
        triplets.emplace_back(i, node_list_[node_begin_[i] + node], rows[i][node] / row_weight[i]);
    }
  }
  means_->matrix.resize(n, n);
  means_->matrix.setFromTriplets(triplets.begin(), triplets.end());
}

Eigen::MatrixX3d SeamlessField::PatchMeans(const Eigen::MatrixX3d& node_value) const {
  return means_->matrix * node_value;
}

Eigen::MatrixX3d SeamlessField::NodeValues(const Eigen::MatrixX3d& exitance) const {
  const int n = rig_.size();
  // Node values whose field has (nearly) each patch's own value as its mean over the patch.
  Eigen::MatrixX3d node_value = exitance;
  const double largest = exitance.size() > 0 ? exitance.maxCoeff() : 0.0;
  for (int iteration = 0; iteration < options_.iterations; ++iteration) {
    const Eigen::MatrixX3d means = PatchMeans(node_value);
    for (int j = 0; j < n; ++j) {
      for (int c = 0; c < 3; ++c) {
        if (means(j, c) > 0.0 && exitance(j, c) > 0.0) {
          node_value(j, c) =
              std::min(node_value(j, c) * exitance(j, c) / means(j, c), 4.0 * largest);
        }
      }
    }
  }
  return node_value;
}

namespace {

// m = v / mean_i(v) per channel from a pixel's bumps: v = Σ K̃ v̂ in single precision, four lanes
// at a time (R, G, B and a zero), K̃ as single-precision weights, v̂ / mean_i(v) of node position
// b at list_value[4 b .. 4 b + 2] (ListValues: the division once per patch, not per pixel); 1 in
// the channels where the mean is not positive. The flux is kept: the weighted mean of m over the
// patch is 1 (within single precision). One function for the cached and the evaluated bumps: the
// same bits.
inline Eigen::Vector3f SumFactor(int count, const uint16_t* node, const float* weight,
                                 const float* list_value, const std::array<bool, 3>& unit) {
  Eigen::Array4f value = Eigen::Array4f::Zero();
  for (int b = 0; b < count; ++b)
    value += weight[b] * Eigen::Map<const Eigen::Array4f, Eigen::Aligned16>(list_value + 4 * node[b]);
  Eigen::Vector3f m;
  for (int c = 0; c < 3; ++c) m[c] = unit[c] ? 1.0f : value[c];
  return m;
}

}  // namespace

void SeamlessField::FactorBumps(int i, const Eigen::Vector3f& point, std::vector<uint16_t>* node,
                                std::vector<float>* weight) const {
  thread_local std::vector<std::pair<int, double>> bumps;
  Bumps(i, point, &bumps);
  node->resize(bumps.size());
  weight->resize(bumps.size());
  for (size_t b = 0; b < bumps.size(); ++b) {
    (*node)[b] = static_cast<uint16_t>(bumps[b].first);
    (*weight)[b] = static_cast<float>(bumps[b].second);
  }
}

std::array<bool, 3> SeamlessField::ListValues(int i, const Eigen::MatrixX3d& node_value,
                                               const Eigen::MatrixX3d& means,
                                               FactorValues* values) const {
  const int begin = node_begin_[i], end = node_begin_[i + 1];
  std::array<bool, 3> unit;
  double inverse_mean[3];
  for (int c = 0; c < 3; ++c) {
    unit[c] = !(means(i, c) > 0.0);
    inverse_mean[c] = unit[c] ? 0.0 : 1.0 / means(i, c);
  }
  values->assign(4 * static_cast<size_t>(end - begin), 0.0f);
  for (int b = 0; b < end - begin; ++b) {
    for (int c = 0; c < 3; ++c)
      (*values)[4 * b + c] =
          static_cast<float>(node_value(node_list_[begin + b], c) * inverse_mean[c]);
  }
  return unit;
}

Eigen::Vector3f SeamlessField::Factor(int i, const Eigen::Vector3f& point,
                                      const Eigen::MatrixX3d& node_value,
                                      const Eigen::MatrixX3d& means) const {
  if (Flat(i)) return Eigen::Vector3f::Ones();
  std::vector<uint16_t> node;
  std::vector<float> weight;
  FactorBumps(i, point, &node, &weight);
  FactorValues values;
  const std::array<bool, 3> unit = ListValues(i, node_value, means, &values);
  return SumFactor(static_cast<int>(node.size()), node.data(), weight.data(), values.data(), unit);
}

void SeamlessField::PatchFactors(int i, size_t k, const Eigen::MatrixX3d& node_value,
                                 const Eigen::MatrixX3d& means, Eigen::Vector3f* factors) const {
  const ProjectorMap& map = rig_.maps[k];
  const int first = map.patch_begin[i], last = map.patch_begin[i + 1];
  if (Flat(i)) {
    std::fill(factors, factors + (last - first), Eigen::Vector3f::Ones());
    return;
  }
  thread_local FactorValues list_value;
  const std::array<bool, 3> unit = ListValues(i, node_value, means, &list_value);
  if (BumpsCached(k)) {
    const PixelBumps& cache = cached_[k];
    int64_t bump = cache.patch_first[i];
    for (int position = first; position < last; ++position) {
      const int count = cache.count[position];
      factors[position - first] =
          SumFactor(count, &cache.node[bump], &cache.weight[bump], list_value.data(), unit);
      bump += count;
    }
    return;
  }
  thread_local std::vector<uint16_t> node;
  thread_local std::vector<float> weight;
  for (int position = first; position < last; ++position) {
    FactorBumps(i, map.point_by_patch[position], &node, &weight);
    factors[position - first] = SumFactor(static_cast<int>(node.size()), node.data(),
                                          weight.data(), list_value.data(), unit);
  }
}

std::vector<std::vector<Eigen::Vector3f>> SeamlessField::Factors(
    const Eigen::MatrixX3d& node_value, const Eigen::MatrixX3d& means,
    const std::vector<char>* projectors) const {
  const int n = rig_.size();
  const auto wanted = [projectors](size_t k) { return projectors == nullptr || (*projectors)[k]; };
  std::vector<std::vector<Eigen::Vector3f>> factors(rig_.maps.size());
  for (size_t k = 0; k < rig_.maps.size(); ++k) {
    if (wanted(k)) factors[k].assign(rig_.maps[k].lit_pixels, Eigen::Vector3f::Ones());
  }
#pragma omp parallel for schedule(dynamic, 16)
  for (int i = 0; i < n; ++i) {
    if (Flat(i)) continue;
    for (size_t k = 0; k < rig_.maps.size(); ++k) {
      if (wanted(k))
        PatchFactors(i, k, node_value, means, &factors[k][rig_.maps[k].patch_begin[i]]);
    }
  }
  return factors;
}

void SeamlessField::CacheBumps(const std::vector<char>* projectors) {
  const int n = rig_.size();
  cached_.resize(rig_.maps.size());
  for (size_t k = 0; k < rig_.maps.size(); ++k) {
    if ((projectors != nullptr && !(*projectors)[k]) || BumpsCached(k)) continue;
    const ProjectorMap& map = rig_.maps[k];
    PixelBumps cache;
    cache.count.assign(map.lit_pixels, 0);
    // Each patch's bumps in a list of their own (every bump evaluated once), then end to end.
    std::vector<std::vector<uint16_t>> patch_node(n);
    std::vector<std::vector<float>> patch_weight(n);
#pragma omp parallel
    {
      std::vector<uint16_t> node;
      std::vector<float> weight;
#pragma omp for schedule(dynamic, 16)
      for (int i = 0; i < n; ++i) {
        if (Flat(i)) continue;
        for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
          FactorBumps(i, map.point_by_patch[position], &node, &weight);
          cache.count[position] = static_cast<uint16_t>(node.size());
          patch_node[i].insert(patch_node[i].end(), node.begin(), node.end());
          patch_weight[i].insert(patch_weight[i].end(), weight.begin(), weight.end());
        }
      }
    }
    cache.patch_first.assign(n + 1, 0);
    for (int i = 0; i < n; ++i)
      cache.patch_first[i + 1] = cache.patch_first[i] + static_cast<int64_t>(patch_node[i].size());
    cache.node.reserve(cache.patch_first[n]);
    cache.weight.reserve(cache.patch_first[n]);
    for (int i = 0; i < n; ++i) {
      cache.node.insert(cache.node.end(), patch_node[i].begin(), patch_node[i].end());
      cache.weight.insert(cache.weight.end(), patch_weight[i].begin(), patch_weight[i].end());
      patch_node[i] = {};
      patch_weight[i] = {};
    }
    cached_[k] = std::move(cache);
  }
}

std::vector<std::vector<Eigen::Vector3f>> SeamlessLightFactors(
    const ProjectionRig& rig, const Eigen::MatrixX3d& exitance,
    const SeamlessLightOptions& options) {
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("SeamlessLightOptions: " + why);
  const int n = rig.size();
  if (exitance.rows() != n || !exitance.allFinite() || (exitance.array() < 0.0).any()) {
    throw std::invalid_argument("SeamlessLightFactors: need finite exitance >= 0 for each of " +
                                std::to_string(n) + " patches");
  }
  const SeamlessField field(rig, options);
  const Eigen::MatrixX3d node_value = field.NodeValues(exitance);
  return field.Factors(node_value, field.PatchMeans(node_value));
}

}  // namespace procam
