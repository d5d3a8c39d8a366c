#include "geometry/compressed_form_factors.h"

#include <omp.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <numbers>
#include <numeric>
#include <stdexcept>

#include "base/stop.h"
#include "base/timing.h"

namespace procam {
namespace {

// One cluster of the tree while it is built.
struct Node {
  int begin = 0, end = 0;               // range of tree positions
  std::array<int, 2> child = {-1, -1};  // both -1 for a leaf
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // area-weighted centroid
  double radius = 0.0;                  // of the sphere about `centre` holding every patch centroid
  double area = 0.0;
  bool planar = false;                  // one surface, every normal equal
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  // when planar
  Eigen::AlignedBox3d box;              // of the patch centroids, grown by the patch radii
  bool leaf() const { return child[0] < 0; }
};

class TreeBuilder {
 public:
  TreeBuilder(const std::vector<ClusterPatch>& patches, const ClusterOptions& options)
      : patches_(patches), options_(options) {}

  void Build() {
    const int n = static_cast<int>(patches_.size());
    order_.resize(n);
    std::iota(order_.begin(), order_.end(), 0);
    // Patches grouped by surface: each surface becomes a subtree of the root.
    std::stable_sort(order_.begin(), order_.end(),
                     [&](int a, int b) { return patches_[a].surface < patches_[b].surface; });
    nodes_.push_back(Node());
    std::vector<int> surfaces;
    for (int p = 0; p < n;) {
      int q = p;
      while (q < n && patches_[order_[q]].surface == patches_[order_[p]].surface) ++q;
      surfaces.push_back(Split(p, q));
      p = q;
    }
    // The root holds every surface; it is never a leaf pair, so it needs no geometry of its own
    // beyond the range. Surface subtrees hang below it as a chain of pairs.
    root_children_ = surfaces;
    Finish(0, 0, n);
  }

  const std::vector<int>& order() const { return order_; }
  const std::vector<Node>& nodes() const { return nodes_; }
  const std::vector<int>& root_children() const { return root_children_; }

 private:
  int Split(int begin, int end) {
    const int index = static_cast<int>(nodes_.size());
    nodes_.push_back(Node());
    Eigen::AlignedBox3d centroids;
    for (int p = begin; p < end; ++p) centroids.extend(patches_[order_[p]].centroid);
    if (end - begin > options_.leaf_size) {
      int axis = 0;
      centroids.sizes().maxCoeff(&axis);
      const int middle = begin + (end - begin) / 2;
      std::nth_element(order_.begin() + begin, order_.begin() + middle, order_.begin() + end, [&](int a, int b) {
        return patches_[a].centroid[axis] < patches_[b].centroid[axis];
      });
      const int left = Split(begin, middle);
      const int right = Split(middle, end);
      nodes_[index].child = {left, right};
    }
    Finish(index, begin, end);
    return index;
  }

  void Finish(int index, int begin, int end) {
    Node& node = nodes_[index];
    node.begin = begin;
    node.end = end;
    Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
    for (int p = begin; p < end; ++p) {
      const ClusterPatch& patch = patches_[order_[p]];
      node.area += patch.area;
      weighted += patch.area * patch.centroid;
      const Eigen::Vector3d reach = Eigen::Vector3d::Constant(0.75 * std::sqrt(patch.area));
      node.box.extend(patch.centroid - reach);
      node.box.extend(patch.centroid + reach);
    }
    node.centre = node.area > 0 ? Eigen::Vector3d(weighted / node.area) : node.box.center();
    const ClusterPatch& first = patches_[order_[begin]];
    node.planar = true;
    for (int p = begin; p < end; ++p) {
      const ClusterPatch& patch = patches_[order_[p]];
      // Radius of the patch itself: its corners lie within about 0.75 √A of its centroid.
      node.radius = std::max(node.radius, (patch.centroid - node.centre).norm() + 0.75 * std::sqrt(patch.area));
      if (patch.surface != first.surface || (patch.normal - first.normal).norm() > 1e-9) node.planar = false;
    }
    if (node.planar) node.normal = first.normal;
  }

  const std::vector<ClusterPatch>& patches_;
  const ClusterOptions& options_;
  std::vector<int> order_;
  std::vector<Node> nodes_;
  std::vector<int> root_children_;
};

// True when everything of `b` lies on or behind the plane of planar cluster `a`.
bool Behind(const Node& a, const Node& b, double margin) {
  if (!a.planar) return false;
  double most = -1e300;
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3d p = b.box.corner(static_cast<Eigen::AlignedBox3d::CornerType>(corner));
    most = std::max(most, a.normal.dot(p - a.centre));
  }
  return most <= margin;
}

}  // namespace

bool ClusterOptions::Check(std::string* why) const {
  if (leaf_size < 1) {
    *why = "leaf_size must be at least 1";
    return false;
  }
  if (!(admissibility > 0.0 && admissibility <= 1.0)) {
    *why = "admissibility must be in (0, 1]";
    return false;
  }
  return true;
}

CompressedFormFactors::CompressedFormFactors(Eigen::VectorXd area, std::vector<int> order, std::vector<int> begin,
                                             std::vector<int> end, SparseRows near, FarBlocks far)
    : area_(std::move(area)),
      order_(std::move(order)),
      begin_(std::move(begin)),
      end_(std::move(end)),
      near_(std::move(near)),
      far_(std::move(far)) {
  const int n = size();
  const int c = static_cast<int>(begin_.size());
  if (static_cast<int>(order_.size()) != n || static_cast<int>(end_.size()) != c || near_.rows() != n ||
      near_.cols() != n) {
    throw std::invalid_argument("compressed form factors: parts of different sizes");
  }
  std::vector<char> seen(n, 0);
  for (int p : order_) {
    if (p < 0 || p >= n || seen[p]) throw std::invalid_argument("compressed form factors: order is not a permutation");
    seen[p] = 1;
  }
  for (int k = 0; k < c; ++k) {
    if (begin_[k] < 0 || begin_[k] > end_[k] || end_[k] > n) {
      throw std::invalid_argument("compressed form factors: cluster range out of bounds");
    }
  }
  const int64_t blocks = far_.size();
  if (static_cast<int64_t>(far_.columns.size()) != blocks || static_cast<int64_t>(far_.column_offset.size()) != blocks ||
      static_cast<int64_t>(far_.row_offset.size()) != blocks || static_cast<int64_t>(far_.scale.size()) != blocks) {
    throw std::invalid_argument("compressed form factors: far block arrays of different sizes");
  }
  const int64_t values = static_cast<int64_t>(far_.values.size());
  for (int64_t b = 0; b < blocks; ++b) {
    const int i = far_.rows[b], j = far_.columns[b];
    if (i < 0 || i >= c || j < 0 || j >= c || i == j || far_.column_offset[b] < 0 || far_.row_offset[b] < 0 ||
        far_.column_offset[b] + (end_[i] - begin_[i]) > values || far_.row_offset[b] + (end_[j] - begin_[j]) > values) {
      throw std::invalid_argument("compressed form factors: far block " + std::to_string(b) + " out of bounds");
    }
  }
  near_.makeCompressed();
}

Eigen::MatrixXd CompressedFormFactors::Multiply(const Eigen::MatrixXd& x) const {
  const int n = size(), columns = static_cast<int>(x.cols());
  Eigen::MatrixXd y = near_ * x;
  if (far_.size() == 0) return y;
  // Along the tree order, where every cluster is a contiguous block of rows.
  Eigen::MatrixXd tree_x(n, columns), tree_y = Eigen::MatrixXd::Zero(n, columns);
  for (int p = 0; p < n; ++p) tree_x.row(p) = x.row(order_[p]);
  for (int64_t b = 0; b < far_.size(); ++b) {
    const int i = far_.rows[b], j = far_.columns[b];
    const int rows_i = end_[i] - begin_[i], rows_j = end_[j] - begin_[j];
    const Eigen::Map<const Eigen::VectorXd> column(far_.values.data() + far_.column_offset[b], rows_i);
    const Eigen::Map<const Eigen::VectorXd> row(far_.values.data() + far_.row_offset[b], rows_j);
    const Eigen::RowVectorXd to_i = far_.scale[b] * (row.transpose() * tree_x.middleRows(begin_[j], rows_j));
    const Eigen::RowVectorXd to_j = far_.scale[b] * (column.transpose() * tree_x.middleRows(begin_[i], rows_i));
    tree_y.middleRows(begin_[i], rows_i).noalias() += column * to_i;
    tree_y.middleRows(begin_[j], rows_j).noalias() += row * to_j;
  }
  // tree_y holds exchange areas G x: F x = G x / A.
  for (int p = 0; p < n; ++p) y.row(order_[p]) += tree_y.row(p) / area_[order_[p]];
  return y;
}

Eigen::MatrixXd CompressedFormFactors::MultiplyTransposed(const Eigen::MatrixXd& x) const {
  // Fᵀ = diag(A) F diag(A)⁻¹ by reciprocity.
  const Eigen::MatrixXd scaled = area_.cwiseInverse().asDiagonal() * x;
  return area_.asDiagonal() * Multiply(scaled);
}

Eigen::MatrixXd CompressedFormFactors::ToDense() const {
  return Multiply(Eigen::MatrixXd::Identity(size(), size()));
}

Eigen::VectorXd CompressedFormFactors::RowSums() const {
  return Multiply(Eigen::MatrixXd::Ones(size(), 1)).col(0);
}

int64_t CompressedFormFactors::bytes() const {
  const auto sparse = [](const SparseRows& m) {
    return static_cast<int64_t>(m.nonZeros()) * (sizeof(double) + sizeof(int)) +
           static_cast<int64_t>(m.outerSize() + 1) * sizeof(int);
  };
  return static_cast<int64_t>(area_.size()) * sizeof(double) +
         static_cast<int64_t>(order_.size() + begin_.size() + end_.size()) * sizeof(int) + sparse(near_) +
         far_.size() * static_cast<int64_t>(2 * sizeof(int) + 2 * sizeof(int64_t) + sizeof(double)) +
         static_cast<int64_t>(far_.values.size()) * sizeof(double);
}

namespace {

// Pivot of each cluster: the position (in `order`) of the patch nearest its area centroid.
std::vector<int> ClusterPivots(const std::vector<ClusterPatch>& patches, const std::vector<Node>& nodes,
                               const std::vector<int>& order, int thread_count) {
  const int cluster_count = static_cast<int>(nodes.size());
  std::vector<int> pivot(cluster_count, 0);
#pragma omp parallel for schedule(dynamic, 64) num_threads(thread_count)
  for (int k = 1; k < cluster_count; ++k) {
    double best = 1e300;
    for (int p = nodes[k].begin; p < nodes[k].end; ++p) {
      const double d = (patches[order[p]].centroid - nodes[k].centre).squaredNorm();
      if (d < best) {
        best = d;
        pivot[k] = p;
      }
    }
  }
  return pivot;
}

// The near part of F: every patch pair of the near cluster pairs by `exchange` (both orders, each
// divided by its row patch's area), in parallel over blocks; progress weighted by pairs.
CompressedFormFactors::SparseRows NearBlocks(const std::vector<ClusterPatch>& patches, const std::vector<Node>& nodes,
                                             const std::vector<int>& order,
                                             const std::vector<std::array<int, 2>>& near_pairs,
                                             const PairExchange& exchange, int thread_count,
                                             const std::function<void(double)>& progress) {
  int64_t total_pairs = 0;
  for (const auto& [a, b] : near_pairs) {
    const int64_t ca = nodes[a].end - nodes[a].begin, cb = nodes[b].end - nodes[b].begin;
    total_pairs += a == b ? ca * (ca - 1) / 2 : ca * cb;
  }
  std::vector<std::vector<Eigen::Triplet<double, int>>> near_triplets(thread_count);
  std::atomic<int64_t> pairs_done{0};
#pragma omp parallel num_threads(thread_count)
  {
    std::vector<Eigen::Triplet<double, int>>& mine = near_triplets[omp_get_thread_num()];
#pragma omp for schedule(dynamic, 4)
    for (int64_t block = 0; block < static_cast<int64_t>(near_pairs.size()); ++block) {
      if (StopRequested()) continue;  // a signal: the blocks left are skipped, Stopped below
      const auto [a, b] = near_pairs[block];
      int64_t local = 0;
      for (int p = nodes[a].begin; p < nodes[a].end; ++p) {
        const int q0 = a == b ? p + 1 : nodes[b].begin;
        for (int q = q0; q < nodes[b].end; ++q) {
          const int i = order[p], j = order[q];
          ++local;
          const double g = exchange(i, j);
          if (g <= 0.0) continue;
          mine.emplace_back(i, j, g / patches[i].area);
          mine.emplace_back(j, i, g / patches[j].area);
        }
      }
      const int64_t done = pairs_done += local;
      if (progress && omp_get_thread_num() == 0) progress(static_cast<double>(done) / std::max<int64_t>(1, total_pairs));
    }
  }
  if (StopRequested()) {
    throw Stopped("compressed form factors: stopped at " +
                  std::to_string(100 * pairs_done / std::max<int64_t>(1, total_pairs)) +
                  "% of the near pairs");
  }
  if (progress) progress(1.0);
  size_t near_count = 0;
  for (const auto& part : near_triplets) near_count += part.size();
  std::vector<Eigen::Triplet<double, int>> all_near;
  all_near.reserve(near_count);
  for (auto& part : near_triplets) {
    all_near.insert(all_near.end(), part.begin(), part.end());
    std::vector<Eigen::Triplet<double, int>>().swap(part);
  }
  const int n = static_cast<int>(patches.size());
  CompressedFormFactors::SparseRows near(n, n);
  near.setFromTriplets(all_near.begin(), all_near.end());
  return near;
}

}  // namespace

CompressedFormFactors BuildCompressedFormFactors(const std::vector<ClusterPatch>& patches,
                                                 const ClusterOptions& options, const PairExchange& exchange,
                                                 const Visibility& visible, int threads,
                                                 const std::function<void(double)>& progress,
                                                 CompressedBuildSummary* summary) {
  const auto start = Clock::now();
  std::string why;
  if (!options.Check(&why)) throw std::invalid_argument("cluster options: " + why);
  const int n = static_cast<int>(patches.size());
  if (n == 0) throw std::invalid_argument("compressed form factors: no patches");
  TreeBuilder tree(patches, options);
  tree.Build();
  const std::vector<Node>& nodes = tree.nodes();
  const std::vector<int>& order = tree.order();
  const int cluster_count = static_cast<int>(nodes.size());
  Eigen::AlignedBox3d all;
  for (const Node& node : nodes) all.extend(node.box);
  const double margin = std::max(1e-9, 1e-7 * all.diagonal().norm());

  const int thread_count = threads > 0 ? threads : omp_get_max_threads();
  const std::vector<int> pivot = ClusterPivots(patches, nodes, order, thread_count);
  // Centroid-to-centroid exchange area of the patches at positions p and q (0 when they do not
  // face each other); `blocked` is set when they face each other but a ray between them is cut.
  const auto point_exchange = [&](int p, int q, bool* blocked) {
    const ClusterPatch& a = patches[order[p]];
    const ClusterPatch& b = patches[order[q]];
    const Eigen::Vector3d d = b.centroid - a.centroid;
    const double r2 = d.squaredNorm();
    const double cos_a = a.normal.dot(d), cos_b = -b.normal.dot(d);
    if (cos_a <= 0 || cos_b <= 0 || r2 <= 0) return 0.0;
    if (visible && !visible(a.centroid, b.centroid)) {
      *blocked = true;
      return 0.0;
    }
    return a.area * b.area * cos_a * cos_b / (std::numbers::pi * r2 * r2);
  };

  // Block traversal of unordered cluster pairs (a, b), a == b allowed. Pairs far enough apart
  // become far blocks unless some of their rays are blocked and others not (an occluder between
  // or inside them: one row and one column cannot stand for the block), in which case they are
  // refined like pairs that are too close.
  std::vector<std::array<int, 2>> near_pairs;
  FarBlocks far;
  std::vector<std::array<int, 2>> stack, candidates;
  const std::vector<int>& top = tree.root_children();
  for (size_t a = 0; a < top.size(); ++a) {
    for (size_t b = a; b < top.size(); ++b) stack.push_back({top[a], top[b]});
  }
  const auto refine = [&](int a, int b) {
    const Node& na = nodes[a];
    const Node& nb = nodes[b];
    if (na.leaf() && nb.leaf()) {
      near_pairs.push_back({a, b});
    } else if (a == b) {
      stack.push_back({na.child[0], na.child[0]});
      stack.push_back({na.child[1], na.child[1]});
      stack.push_back({na.child[0], na.child[1]});
    } else if (nb.leaf() || (!na.leaf() && na.radius >= nb.radius)) {
      stack.push_back({na.child[0], b});
      stack.push_back({na.child[1], b});
    } else {
      stack.push_back({a, nb.child[0]});
      stack.push_back({a, nb.child[1]});
    }
  };
  std::atomic<int64_t> rays{0};
  while (!stack.empty()) {
    candidates.clear();
    while (!stack.empty()) {
      const auto [a, b] = stack.back();
      stack.pop_back();
      const Node& na = nodes[a];
      const Node& nb = nodes[b];
      if (a != b) {
        if (Behind(na, nb, margin) || Behind(nb, na, margin)) continue;
        const double distance = (na.centre - nb.centre).norm();
        if (2.0 * std::max(na.radius, nb.radius) <= options.admissibility * distance) {
          candidates.push_back({a, b});
          continue;
        }
      } else if (na.planar) {
        continue;  // a plane does not see itself
      }
      refine(a, b);
    }
    // Column, row and pivot of every candidate: kept (1), all dark (0: dropped) or refined (2).
    std::vector<std::vector<double>> column(candidates.size()), row(candidates.size());
    std::vector<double> centre(candidates.size(), 0.0);
    std::vector<char> verdict(candidates.size(), 0);
#pragma omp parallel for schedule(dynamic, 64) num_threads(thread_count)
    for (int64_t c = 0; c < static_cast<int64_t>(candidates.size()); ++c) {
      const auto [a, b] = candidates[c];
      bool blocked = false;
      bool any = false;
      const int pa = pivot[a], pb = pivot[b];
      column[c].resize(nodes[a].end - nodes[a].begin);
      row[c].resize(nodes[b].end - nodes[b].begin);
      for (int p = nodes[a].begin; p < nodes[a].end; ++p) {
        any |= (column[c][p - nodes[a].begin] = point_exchange(p, pb, &blocked)) > 0.0;
      }
      for (int q = nodes[b].begin; q < nodes[b].end; ++q) {
        any |= (row[c][q - nodes[b].begin] = point_exchange(pa, q, &blocked)) > 0.0;
      }
      centre[c] = point_exchange(pa, pb, &blocked);
      rays += static_cast<int64_t>(column[c].size() + row[c].size() + 1);
      if (!any && !blocked) {
        verdict[c] = 0;  // nothing of one faces the other
      } else if (blocked || !(centre[c] > 0.0)) {
        verdict[c] = any || blocked ? 2 : 0;  // an occluder, or a pivot pair that does not see itself
      } else {
        verdict[c] = 1;
      }
      if (verdict[c] != 1) {
        std::vector<double>().swap(column[c]);
        std::vector<double>().swap(row[c]);
      }
    }
    for (size_t c = 0; c < candidates.size(); ++c) {
      const auto [a, b] = candidates[c];
      if (verdict[c] == 2) {
        refine(a, b);
      } else if (verdict[c] == 1) {
        far.rows.push_back(a);
        far.columns.push_back(b);
        far.column_offset.push_back(static_cast<int64_t>(far.values.size()));
        far.values.insert(far.values.end(), column[c].begin(), column[c].end());
        far.row_offset.push_back(static_cast<int64_t>(far.values.size()));
        far.values.insert(far.values.end(), row[c].begin(), row[c].end());
        far.scale.push_back(1.0 / centre[c]);
      }
    }
  }

  // Near pairs, patch by patch, in parallel over blocks.
  CompressedFormFactors::SparseRows near = NearBlocks(patches, nodes, order, near_pairs, exchange, thread_count,
                                                      progress);
  std::vector<int> begin(cluster_count), end(cluster_count);
  for (int k = 0; k < cluster_count; ++k) {
    begin[k] = nodes[k].begin;
    end[k] = nodes[k].end;
  }
  Eigen::VectorXd area(n);
  for (int i = 0; i < n; ++i) area[i] = patches[i].area;
  CompressedFormFactors result(std::move(area), order, std::move(begin), std::move(end), std::move(near),
                               std::move(far));
  if (summary != nullptr) {
    summary->clusters = cluster_count;
    summary->leaves = 0;
    for (int k = 1; k < cluster_count; ++k) summary->leaves += nodes[k].leaf() ? 1 : 0;
    summary->near_entries = result.near().nonZeros();
    summary->far_blocks = result.far().size();
    summary->far_values = static_cast<int64_t>(result.far().values.size());
    summary->visibility_rays = rays;
    summary->bytes = result.bytes();
    summary->seconds = SecondsSince(start);
  }
  return result;
}

}  // namespace procam
