#include "projection/seamless_light.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

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

class Field {
 public:
  Field(const ProjectionRig& rig, const SeamlessLightOptions& options)
      : rig_(rig), nodes_(FieldNodes(rig, options)), radius2_(rig.size()) {
    for (int j = 0; j < rig.size(); ++j)
      radius2_[j] = options.radius * options.radius * rig.area[j];
  }

  // The field at a point of patch i with node values v̂ (n,3).
  Eigen::Vector3d At(int i, const Eigen::Vector3f& point,
                     const Eigen::MatrixX3d& node_value) const {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double weight_sum = 0.0;
    const Eigen::Vector3d x = point.cast<double>();
    for (const int j : nodes_[i]) {
      const double d2 = (x - rig_.centroid.row(j).transpose()).squaredNorm();
      if (d2 >= radius2_[j]) continue;
      const double t = 1.0 - d2 / radius2_[j];
      sum += (t * t) * node_value.row(j).transpose();
      weight_sum += t * t;
    }
    // Only where a patch is so elongated that no bump reaches (outside the designed range).
    if (!(weight_sum > 0.0)) return node_value.row(i).transpose();
    return sum / weight_sum;
  }

  // Per patch, the field's mean over its pixels (weights w a, the flux bookkeeping's); with
  // `values`, also the field at every lit pixel.
  Eigen::MatrixX3d PatchMeans(const Eigen::MatrixX3d& node_value, Factors* values) const {
    const int n = rig_.size();
    Eigen::MatrixX3d means = node_value;
#pragma omp parallel for schedule(dynamic, 16)
    for (int i = 0; i < n; ++i) {
      if (nodes_[i].size() <= 1) continue;  // a field of its own: constant
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      double weight_sum = 0.0;
      for (size_t k = 0; k < rig_.maps.size(); ++k) {
        const ProjectorMap& map = rig_.maps[k];
        const double scale = rig_.coverage_scale(i, k) * map.pixel_solid_angle;
        for (int position = map.patch_begin[i]; position < map.patch_begin[i + 1]; ++position) {
          const Eigen::Vector3d value = At(i, map.point_by_patch[position], node_value);
          if (values) (*values)[k][position] = value.cast<float>();
          const double weight = scale * map.share[map.pixels_by_patch[position]];
          sum += weight * value;
          weight_sum += weight;
        }
      }
      if (weight_sum > 0.0) means.row(i) = (sum / weight_sum).transpose();
    }
    return means;
  }

  bool Flat(int i) const { return nodes_[i].size() <= 1; }

 private:
  const ProjectionRig& rig_;
  std::vector<std::vector<int>> nodes_;
  std::vector<double> radius2_;
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
    const Eigen::MatrixX3d means = field.PatchMeans(node_value, nullptr);
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
  const Eigen::MatrixX3d means = field.PatchMeans(node_value, &factors);
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
