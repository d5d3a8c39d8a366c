#include "compensation/cuda_radiosity.h"

#include <stdexcept>
#include <vector>

#include "compensation/cuda_dense.h"

namespace procam {
namespace {

class CudaRadiosity : public RadiosityBackend {
 public:
  CudaRadiosity(const Eigen::MatrixXd& form_factors, const Eigen::VectorXd& area,
                const Eigen::MatrixX3d& reflectance, bool float32, const cuda::DenseProductSettings& products)
      : float32_(float32) {
    std::string why;
    if (!cuda::DeviceAvailable(&why)) throw std::runtime_error("--device cuda: " + why);
    // As RadiositySystem: one K⁻¹ when every patch reflects the three channels alike.
    const bool grey = (reflectance.col(0) == reflectance.col(1)) && (reflectance.col(0) == reflectance.col(2));
    groups_ = grey ? std::vector<std::vector<int>>{{0, 1, 2}} : std::vector<std::vector<int>>{{0}, {1}, {2}};
    const Eigen::MatrixXd f = form_factors;  // contiguous column-major
    for (const std::vector<int>& channels : groups_) {
      const Eigen::VectorXd rho = reflectance.col(channels.front());
      inverses_.push_back(cuda::InverseRadiosity::Create(f.data(), area.data(), rho.data(),
                                                         static_cast<int>(area.size()), products));
    }
    form_factors_ = cuda::DeviceMatrix::Create(f.data(), static_cast<int>(area.size()));
  }

  // The solver's K·Bd start: an n² product, ~0.3 s on two CPU cores at 9800 patches.
  bool MultiplyF(const Eigen::MatrixX3d& x, Eigen::MatrixX3d* fx) const override {
    fx->resize(x.rows(), 3);
    const Eigen::MatrixX3d contiguous = x;
    form_factors_->Apply(contiguous.data(), 3, fx->data());
    return true;
  }

  Eigen::MatrixX3d Solve(const Eigen::MatrixX3d& y, bool transposed, bool fast) const override {
    Eigen::MatrixX3d x(y.rows(), 3);
    for (size_t g = 0; g < groups_.size(); ++g) {
      const std::vector<int>& channels = groups_[g];
      Eigen::MatrixXd block(y.rows(), channels.size());
      for (size_t k = 0; k < channels.size(); ++k) block.col(k) = y.col(channels[k]);
      Eigen::MatrixXd result(y.rows(), channels.size());
      inverses_[g]->Apply(block.data(), static_cast<int>(channels.size()), transposed, fast || float32_,
                          result.data());
      for (size_t k = 0; k < channels.size(); ++k) x.col(channels[k]) = result.col(k);
    }
    return x;
  }

  int factorisations() const override { return static_cast<int>(groups_.size()); }

  const std::vector<std::vector<int>>& groups() const { return groups_; }
  std::vector<const cuda::InverseRadiosity*> inverses() const {
    std::vector<const cuda::InverseRadiosity*> result;
    for (const auto& inverse : inverses_) result.push_back(inverse.get());
    return result;
  }

 private:
  bool float32_;
  std::vector<std::vector<int>> groups_;
  std::vector<std::unique_ptr<cuda::InverseRadiosity>> inverses_;
  std::unique_ptr<cuda::DeviceMatrix> form_factors_;  // F, for MultiplyF
};

}  // namespace

bool CudaDeviceAvailable(std::string* description) { return cuda::DeviceAvailable(description); }

std::shared_ptr<const RadiosityBackend> MakeCudaRadiosityBackend(const Eigen::MatrixXd& form_factors,
                                                                 const Eigen::VectorXd& area,
                                                                 const Eigen::MatrixX3d& reflectance,
                                                                 bool float32,
                                                                 const cuda::DenseProductSettings& products) {
  return std::make_shared<const CudaRadiosity>(form_factors, area, reflectance, float32, products);
}

bool CudaInverseRadiosities(const RadiosityBackend& backend, std::vector<const cuda::InverseRadiosity*>* inverses,
                            std::vector<std::vector<int>>* channels) {
  const auto* dense = dynamic_cast<const CudaRadiosity*>(&backend);
  if (dense == nullptr) return false;
  *inverses = dense->inverses();
  *channels = dense->groups();
  return true;
}

}  // namespace procam
