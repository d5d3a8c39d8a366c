#pragma once
// Form factors in O(n log n) memory: near pairs exact, far cluster pairs as rank-1 blocks
// (issue 9: rooms of 100k patches, where the dense F would take 80 GB).
//
// The patches are ordered along a cluster tree (each surface a subtree, split in two along the
// longest side of its centroids' box until a leaf holds at most `leaf_size` patches), so every
// cluster N is a contiguous range [begin_N, end_N) of that order. A pair of clusters (I, J)
// far enough apart — both diameters ≤ `admissibility` × the distance between their centres — is
// one far block, stored as a rank-1 cross approximation of its exchange areas G_ij = A_i F_ij:
// G_IJ ≈ c rᵀ / G_i*j*, with c = G_{I,j*} one column and r = G_{i*,J} one row through pivot
// patches i* ∈ I, j* ∈ J (those nearest the clusters' area centroids), each entry the
// centroid-to-centroid kernel A_i A_j cosθ_i cosθ_j / (π r²) times one visibility ray. |I| + |J|
// numbers per block instead of |I|·|J|; the kernel is smooth across a far block, so one row and
// one column carry its variation with position and orientation (error second order in
// diameter/distance). A block whose rays are blocked only in part is refined instead (an
// occluder makes it rough). Pairs of leaves that are not far apart are near blocks, stored
// patch by patch (the exact quadrature of form_factors.h). G is symmetric in both parts, so
// A_i F_ij = A_j F_ji holds exactly and Fᵀ X = A ∘ F (X / A).
//
// Product F X (X n×c): the near part is a sparse product; each far block adds
// c_I (rᵀ x_J) / (A_I G_i*j*) to rows I and r_J (cᵀ x_I) / (A_J G_i*j*) to rows J, over
// contiguous positions of the tree order. O(n + near entries + Σ(|I| + |J|)) per column.
//
// This file needs only Eigen (the GPU tests build it without Embree); the builder that reads a
// scene is ComputeCompressedFormFactors in form_factors.h.

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace procam {

struct ClusterOptions {
  // Most patches per leaf cluster, ≥ 1.
  int leaf_size = 16;
  // Clusters I, J are far when max(diameter_I, diameter_J) ≤ admissibility × |c_I − c_J|; in
  // (0, 1]. Smaller: more near pairs, more accurate far blocks.
  double admissibility = 0.7;

  bool Check(std::string* why) const;
};

// What the builder needs of each patch.
struct ClusterPatch {
  Eigen::Vector3d centroid;
  Eigen::Vector3d normal;  // unit, lit side
  double area = 0.0;
  int surface = 0;         // patches of different surfaces never share a cluster
};

// The far blocks, each unordered cluster pair once: G_ij = column_i · row_j · scale for i in
// cluster `rows`, j in cluster `columns` (and G_ji the same), `column` stored at
// values[column_offset + (position of i − begin of rows)], `row` likewise.
struct FarBlocks {
  std::vector<int> rows, columns;                   // clusters I, J
  std::vector<int64_t> column_offset, row_offset;   // into values: |I| and |J| numbers
  std::vector<double> scale;                        // 1 / G_i*j*
  std::vector<double> values;

  int64_t size() const { return static_cast<int64_t>(rows.size()); }
};

class CompressedFormFactors {
 public:
  using SparseRows = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;

  CompressedFormFactors() = default;
  // From parts (tests, other builders): `order` is the permutation (tree position → patch),
  // `begin`/`end` each cluster's range of positions, `near` (n×n, patch indices, F itself) and
  // `far`. Throws std::invalid_argument when they disagree.
  CompressedFormFactors(Eigen::VectorXd area, std::vector<int> order, std::vector<int> begin,
                        std::vector<int> end, SparseRows near, FarBlocks far);

  int size() const { return static_cast<int>(area_.size()); }
  int clusters() const { return static_cast<int>(begin_.size()); }
  const Eigen::VectorXd& area() const { return area_; }

  // Y = F X and Y = Fᵀ X (X n×c, any c ≥ 1).
  Eigen::MatrixXd Multiply(const Eigen::MatrixXd& x) const;
  Eigen::MatrixXd MultiplyTransposed(const Eigen::MatrixXd& x) const;
  // F as a dense matrix (n² doubles: tests and small rooms only).
  Eigen::MatrixXd ToDense() const;
  // F 1.
  Eigen::VectorXd RowSums() const;
  // Bytes held by the structure.
  int64_t bytes() const;

  const std::vector<int>& order() const { return order_; }
  const std::vector<int>& begin() const { return begin_; }
  const std::vector<int>& end() const { return end_; }
  const SparseRows& near() const { return near_; }
  const FarBlocks& far() const { return far_; }

 private:
  Eigen::VectorXd area_;
  std::vector<int> order_;
  std::vector<int> begin_, end_;
  SparseRows near_;
  FarBlocks far_;
};

struct CompressedBuildSummary {
  int clusters = 0, leaves = 0;
  int64_t near_entries = 0;  // stored patch pairs (both orders)
  int64_t far_blocks = 0;    // unordered cluster pairs
  int64_t far_values = 0;    // Σ (|I| + |J|) over them
  int64_t visibility_rays = 0;
  double seconds = 0.0;
  int64_t bytes = 0;
};

// Exchange area A_i F_ij (= A_j F_ji) of patches i ≠ j, 0 when they do not see each other.
// Called from several threads at once.
using PairExchange = std::function<double(int i, int j)>;
// Whether the points a and b see each other. Called from several threads at once.
using Visibility = std::function<bool(const Eigen::Vector3d& a, const Eigen::Vector3d& b)>;

// Builds the tree and both parts. `progress` (optional) gets the fraction of near pairs done.
// `threads` 0: all cores.
CompressedFormFactors BuildCompressedFormFactors(const std::vector<ClusterPatch>& patches,
                                                 const ClusterOptions& options, const PairExchange& exchange,
                                                 const Visibility& visible, int threads,
                                                 const std::function<void(double)>& progress,
                                                 CompressedBuildSummary* summary);

}  // namespace procam
