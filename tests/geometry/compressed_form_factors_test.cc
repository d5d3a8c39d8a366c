#include "geometry/compressed_form_factors.h"

#include <cmath>
#include <random>
#include <utility>

#include <gtest/gtest.h>

#include "datasets_synthetic/rooms.h"
#include "geometry/form_factors.h"
#include "geometry/patches.h"

namespace procam {
namespace {

struct Room {
  Scene scene;
  PatchHierarchy patches;
  FormFactorOptions options;
};

Room MakeRoom(int target_patches) {
  Room room;
  SubdividedRoom box = MakeSubdividedBoxRoom(target_patches);
  room.scene = std::move(box.scene);
  room.patches = std::move(box.patches);
  room.options.threads = 2;
  return room;
}

Eigen::MatrixXd RandomPositive(int rows, int columns, unsigned seed) {
  std::mt19937 generator(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  Eigen::MatrixXd x(rows, columns);
  for (int i = 0; i < x.size(); ++i) x.data()[i] = uniform(generator);
  return x;
}

double RelativeError(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) { return (a - b).norm() / b.norm(); }

class CompressedFormFactorsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    room_ = new Room(MakeRoom(1500));
    dense_ = new Eigen::MatrixXd(ComputeFormFactors(room_->scene, room_->patches.fine, room_->options, &summary_));
  }
  static void TearDownTestSuite() {
    delete room_;
    delete dense_;
  }
  static Room* room_;
  static Eigen::MatrixXd* dense_;
  static FormFactorSummary summary_;
};
Room* CompressedFormFactorsTest::room_ = nullptr;
Eigen::MatrixXd* CompressedFormFactorsTest::dense_ = nullptr;
FormFactorSummary CompressedFormFactorsTest::summary_;

TEST_F(CompressedFormFactorsTest, WithoutFarBlocksItIsTheDenseQuadrature) {
  // Admissibility so small that no pair of clusters is far apart: every entry is a near pair,
  // computed by the same quadrature and rays as the dense matrix. The dense one then had its
  // rows limited to sum ≤ 1 (F_ij ← s_i F_ij s_j, s ≥ 1 − cut), which the compressed one does not.
  ClusterOptions clusters;
  clusters.admissibility = 1e-9;
  CompressedBuildSummary summary;
  const CompressedFormFactors f =
      ComputeCompressedFormFactors(room_->scene, room_->patches.fine, room_->options, clusters, &summary);
  EXPECT_EQ(summary.far_blocks, 0);
  const Eigen::MatrixXd compressed = f.ToDense();
  const double cut = summary_.max_row_correction;
  EXPECT_GT(cut, 0.0);
  EXPECT_LT(cut, 0.01);
  const Eigen::MatrixXd allowed = (2.0 * cut + 1e-12) * compressed.cwiseAbs().array() + 1e-15;
  EXPECT_TRUE(((compressed - *dense_).cwiseAbs().array() <= allowed.array()).all());
  EXPECT_LT(RelativeError(compressed, *dense_), 2.0 * cut);
}

TEST_F(CompressedFormFactorsTest, FarBlocksApproximateTheDenseProductAndKeepReciprocity) {
  const int n = room_->patches.fine.size();
  ClusterOptions clusters;  // defaults: leaf 32, admissibility 0.5, 4 representatives
  CompressedBuildSummary summary;
  const CompressedFormFactors f =
      ComputeCompressedFormFactors(room_->scene, room_->patches.fine, room_->options, clusters, &summary);
  ASSERT_EQ(f.size(), n);
  EXPECT_GT(summary.far_blocks, 0);
  EXPECT_LT(summary.near_entries + summary.far_values, static_cast<int64_t>(n) * n);  // dense: n²
  const Eigen::MatrixXd x = RandomPositive(n, 3, 7);
  const Eigen::MatrixXd exact = *dense_ * x;
  const double error = RelativeError(f.Multiply(x), exact);
  RecordProperty("product_relative_error", std::to_string(error));
  EXPECT_LT(error, 0.012);  // measured 0.0072 (leaf 16, admissibility 0.7)
  // Light leaving each patch: the row sums (1 in this closed room) within a few percent.
  const Eigen::VectorXd row_error = (f.RowSums() - dense_->rowwise().sum()).cwiseAbs();
  RecordProperty("row_sum_error_max", std::to_string(row_error.maxCoeff()));
  RecordProperty("row_sum_error_mean", std::to_string(row_error.mean()));
  EXPECT_LT(row_error.maxCoeff(), 0.08);  // measured 0.047
  EXPECT_LT(row_error.mean(), 0.008);     // measured 0.0045
  // A_i F_ij = A_j F_ji exactly, so Fᵀ X is A ∘ F (X / A).
  const Eigen::MatrixXd full = f.ToDense();
  const Eigen::MatrixXd exchange = f.area().asDiagonal() * full;
  EXPECT_LT((exchange - exchange.transpose()).cwiseAbs().maxCoeff(), 1e-15 * exchange.cwiseAbs().maxCoeff() * n);
  EXPECT_LT(RelativeError(f.MultiplyTransposed(x), full.transpose() * x), 1e-12);
}

TEST(CompressedFormFactors, StorageGrowsFarSlowerThanNSquared) {
  // Without visibility (the product's structure does not depend on it) to keep the test fast.
  std::vector<int64_t> stored;
  std::vector<int> sizes;
  for (int target : {1000, 4000}) {
    Room room = MakeRoom(target);
    room.options.visibility = false;
    CompressedBuildSummary summary;
    ComputeCompressedFormFactors(room.scene, room.patches.fine, room.options, ClusterOptions(), &summary);
    stored.push_back(summary.near_entries + summary.far_blocks);
    sizes.push_back(room.patches.fine.size());
  }
  const double n_ratio = static_cast<double>(sizes[1]) / sizes[0];
  const double stored_ratio = static_cast<double>(stored[1]) / stored[0];
  // n² would grow by n_ratio²; n log n by a little more than n_ratio.
  EXPECT_LT(stored_ratio, 0.5 * n_ratio * n_ratio) << "n " << sizes[0] << " → " << sizes[1] << ", stored "
                                                   << stored[0] << " → " << stored[1];
}

TEST(CompressedFormFactors, PartsAreChecked) {
  CompressedFormFactors::SparseRows near(2, 2);
  EXPECT_THROW(CompressedFormFactors(Eigen::VectorXd::Ones(2), {0, 0}, {0}, {2}, near, FarBlocks()),
               std::invalid_argument);
  EXPECT_THROW(CompressedFormFactors(Eigen::VectorXd::Ones(2), {0, 1}, {0}, {3}, near, FarBlocks()),
               std::invalid_argument);
  EXPECT_NO_THROW(CompressedFormFactors(Eigen::VectorXd::Ones(2), {1, 0}, {0}, {2}, near, FarBlocks()));
  FarBlocks far;  // a block whose values run past the end
  far.rows = {1};
  far.columns = {2};
  far.column_offset = {0};
  far.row_offset = {1};
  far.scale = {1.0};
  far.values = {1.0};
  EXPECT_THROW(CompressedFormFactors(Eigen::VectorXd::Ones(2), {0, 1}, {0, 0, 1}, {2, 1, 2}, near, far),
               std::invalid_argument);
  ClusterOptions options;
  options.admissibility = 1.5;
  std::string why;
  EXPECT_FALSE(options.Check(&why));
  EXPECT_NE(why.find("admissibility"), std::string::npos);
}

TEST(CompressedFormFactors, HandBuiltBlocksMultiplyAsDefined) {
  // Four patches in tree order (3, 1 | 0, 2): cluster 1 = positions [0, 2) = patches {3, 1},
  // cluster 2 = [2, 4) = patches {0, 2}, cluster 0 = everything. One near pair (3, 1) inside
  // cluster 1 and one far block between clusters 1 and 2: G_ij = column_i row_j scale.
  const Eigen::VectorXd area = (Eigen::VectorXd(4) << 1.0, 2.0, 3.0, 4.0).finished();
  const std::vector<int> order = {3, 1, 0, 2};
  CompressedFormFactors::SparseRows near(4, 4);
  near.insert(3, 1) = 0.2 / 4.0;  // exchange A_3 F_31 = A_1 F_13 = 0.2
  near.insert(1, 3) = 0.2 / 2.0;
  FarBlocks far;
  far.rows = {1};
  far.columns = {2};
  far.column_offset = {0};
  far.row_offset = {2};
  far.scale = {0.5};
  far.values = {0.3, 0.7, 0.11, 0.13};  // column over patches 3, 1; row over patches 0, 2
  const CompressedFormFactors f(area, order, {0, 0, 2}, {4, 2, 4}, near, far);
  Eigen::MatrixXd exchange = Eigen::MatrixXd::Zero(4, 4);
  exchange(3, 1) = exchange(1, 3) = 0.2;
  const int column_patch[2] = {3, 1}, row_patch[2] = {0, 2};
  for (int a = 0; a < 2; ++a) {
    for (int b = 0; b < 2; ++b) {
      exchange(column_patch[a], row_patch[b]) = exchange(row_patch[b], column_patch[a]) =
          far.values[a] * far.values[2 + b] * 0.5;
    }
  }
  const Eigen::MatrixXd expected = area.cwiseInverse().asDiagonal() * exchange;
  EXPECT_LT((f.ToDense() - expected).cwiseAbs().maxCoeff(), 1e-15);
  const Eigen::MatrixXd x = RandomPositive(4, 2, 3);
  EXPECT_LT(RelativeError(f.MultiplyTransposed(x), expected.transpose() * x), 1e-15);
}

}  // namespace
}  // namespace procam
