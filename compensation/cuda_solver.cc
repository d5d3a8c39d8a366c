#include "compensation/cuda_solver.h"

#include <memory>
#include <stdexcept>
#include <utility>
#include <vector>

#include "compensation/cuda_compressed.h"
#include "compensation/cuda_compressed_device.h"
#include "compensation/cuda_dense.h"
#include "compensation/cuda_radiosity.h"
#include "compensation/cuda_solver_device.h"

namespace procam {
namespace {

// The dense backend's K⁻¹ (one per group of channels sharing a reflectance) on device vectors:
// one product per group, on the loop's stream.
class DenseDeviceRadiosity : public cuda::DeviceRadiosity {
 public:
  DenseDeviceRadiosity(std::vector<const cuda::InverseRadiosity*> inverses, std::vector<std::vector<int>> channels,
                       int patches)
      : inverses_(std::move(inverses)), channels_(std::move(channels)), patches_(patches) {}

  cudaStream_t stream() const override { return nullptr; }
  void Solve(const double* y, bool transposed, double* x, cudaStream_t stream) const override {
    Apply(y, transposed, x, stream);
  }
  bool single() const override { return true; }
  void SolveFast(const float* y, bool transposed, float* x, cudaStream_t stream) const override {
    Apply(y, transposed, x, stream);
  }
  void SolveFast(const double* y, bool transposed, double* x, cudaStream_t stream) const override {
    Apply(y, transposed, x, stream);
  }
  bool iterative() const override { return false; }
  // As Apply forms them: a group of all three channels in one product, else one per channel.
  int DenseProducts(cuda::DenseProduct (&products)[3]) const override {
    int count = 0;
    for (size_t g = 0; g < inverses_.size(); ++g) {
      cuda::DenseInverseView view;
      if (!inverses_[g]->View(&view)) return 0;
      if (channels_[g] == std::vector<int>{0, 1, 2}) {
        products[count++] = {view, 0, 3};
        continue;
      }
      for (const int c : channels_[g]) products[count++] = {view, c, 1};
    }
    return count;
  }

 private:
  // Columns are contiguous (n×3 column-major): a grey room's three channels are one product.
  template <typename T>
  void Apply(const T* y, bool transposed, T* x, cudaStream_t stream) const {
    for (size_t g = 0; g < inverses_.size(); ++g) {
      const std::vector<int>& channels = channels_[g];
      if (channels == std::vector<int>{0, 1, 2}) {
        inverses_[g]->ApplyOnDevice(y, 3, transposed, x, stream);
        continue;
      }
      for (const int c : channels) {
        const size_t offset = static_cast<size_t>(c) * patches_;
        inverses_[g]->ApplyOnDevice(y + offset, 1, transposed, x + offset, stream);
      }
    }
  }

  std::vector<const cuda::InverseRadiosity*> inverses_;
  std::vector<std::vector<int>> channels_;
  int patches_;
};

// The matrix-free backend's CG solves (float64 throughout, the fast ones at its fast tolerance),
// on the backend's own stream.
class CompressedDeviceRadiosity : public cuda::DeviceRadiosity {
 public:
  explicit CompressedDeviceRadiosity(const CudaCompressedRadiosity& backend) : backend_(backend) {}

  cudaStream_t stream() const override { return backend_.device().stream(); }
  void Solve(const double* y, bool transposed, double* x, cudaStream_t) const override {
    backend_.SolveOnDevice(y, transposed, /*fast=*/false, x);
  }
  bool single() const override { return false; }
  void SolveFast(const float*, bool, float*, cudaStream_t) const override {
    throw std::logic_error("resident GPU solve: the matrix-free solves take float64 vectors");
  }
  void SolveFast(const double* y, bool transposed, double* x, cudaStream_t) const override {
    backend_.SolveOnDevice(y, transposed, /*fast=*/true, x);
  }
  bool iterative() const override { return true; }

 private:
  const CudaCompressedRadiosity& backend_;
};

std::unique_ptr<cuda::DeviceRadiosity> DeviceRadiosityOf(const RadiositySystem& radiosity) {
  const RadiosityBackend* backend = radiosity.backend();
  if (backend == nullptr) {
    throw std::invalid_argument("resident GPU solve: the radiosity system has no CUDA backend");
  }
  std::vector<const cuda::InverseRadiosity*> inverses;
  std::vector<std::vector<int>> channels;
  if (CudaInverseRadiosities(*backend, &inverses, &channels)) {
    return std::make_unique<DenseDeviceRadiosity>(std::move(inverses), std::move(channels), radiosity.size());
  }
  if (const auto* compressed = dynamic_cast<const CudaCompressedRadiosity*>(backend)) {
    return std::make_unique<CompressedDeviceRadiosity>(*compressed);
  }
  throw std::invalid_argument("resident GPU solve: the radiosity system's backend is not a CUDA one");
}

}  // namespace

Eigen::MatrixX3d MinimiseBoundedOnGpu(const SolverOptions& options, const CompensationObjective& objective,
                                      const Eigen::MatrixX3d& initial, SolverSummary* summary,
                                      Eigen::MatrixX3d* radiosity_out) {
  const std::unique_ptr<cuda::DeviceRadiosity> radiosity = DeviceRadiosityOf(objective.radiosity());
  const CompensationProblem& problem = objective.problem();
  const int n = objective.patches();

  // W exactly as the objective holds it (symmetric, column-major: column i lists row i).
  const Eigen::SparseMatrix<double>& w = objective.weights();
  Eigen::VectorXd diagonal = Eigen::VectorXd::Zero(n);
  std::vector<int> offsets(n + 1, 0), neighbours;
  std::vector<double> neighbour_weights;
  neighbours.reserve(w.nonZeros());
  neighbour_weights.reserve(w.nonZeros());
  for (int i = 0; i < n; ++i) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(w, i); it; ++it) {
      if (it.row() == i) {
        diagonal[i] += it.value();
      } else {
        neighbours.push_back(static_cast<int>(it.row()));
        neighbour_weights.push_back(it.value());
      }
    }
    offsets[i + 1] = static_cast<int>(neighbours.size());
  }
  const Eigen::MatrixX3d start = initial.cwiseMax(problem.lower).cwiseMin(problem.upper);

  cuda::ResidentProblem resident_problem;
  resident_problem.patches = n;
  resident_problem.weight_diagonal = diagonal.data();
  resident_problem.neighbour_offsets = offsets.data();
  resident_problem.neighbours = neighbours.data();
  resident_problem.neighbour_weights = neighbour_weights.data();
  resident_problem.lower = problem.lower.data();
  resident_problem.upper = problem.upper.data();
  resident_problem.desired = problem.desired.data();
  resident_problem.initial = start.data();
  resident_problem.lab = objective.model() == ColourModel::kLab;
  // A colour metric's factors L_i, laid out as the device keeps its Jacobians.
  const std::vector<Eigen::Matrix3d>& factors = objective.metric().factor;
  std::vector<double> metric_factor(factors.empty() ? 0 : 9 * static_cast<size_t>(n));
  for (int i = 0; i < static_cast<int>(factors.size()); ++i) {
    for (int k = 0; k < 9; ++k) metric_factor[static_cast<size_t>(k) * n + i] = factors[i](k / 3, k % 3);
  }
  if (!metric_factor.empty()) resident_problem.metric_factor = metric_factor.data();
  const Eigen::Matrix3d linear = objective.ColourJacobian(Eigen::Vector3d::Zero());  // constant for kLinear
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      resident_problem.rgb_to_xyz[3 * a + b] = problem.rgb_to_xyz(a, b);
      resident_problem.linear_colour[3 * a + b] = linear(a, b);
    }
    resident_problem.white_xyz[a] = problem.white_xyz[a];
  }

  cuda::ResidentOptions resident_options;
  static_cast<AlgorithmSettings&>(resident_options) = options;
  resident_options.fused = options.device_fused;
  resident_options.neumann =
      options.device_preconditioner == SolverOptions::DevicePreconditioner::kBlockJacobiNeumann;
  resident_options.graphs = options.device_graphs;
  resident_options.fused_blocks = options.device_fused_blocks;
  resident_options.profile = options.device_profile;
  resident_options.progress = options.progress;

  cuda::ResidentSummary resident;
  Eigen::MatrixX3d emittance(n, 3);
  if (radiosity_out != nullptr) radiosity_out->resize(n, 3);
  cuda::MinimiseResident(resident_options, resident_problem, *radiosity, emittance.data(),
                         radiosity_out != nullptr ? radiosity_out->data() : nullptr, &resident);

  AddDriverRecords(resident.records, summary);
  summary->trace.insert(summary->trace.end(), resident.trace.begin(), resident.trace.end());
  summary->device_fused = resident.fused;
  summary->device_fused_blocks = resident.fused_blocks;
  summary->device_loop = true;
  summary->device_preconditioner = options.device_preconditioner;
  summary->device_cg_matrix = options.device_cg_matrix;
  return emittance;
}

}  // namespace procam
