#include "compensation/radiosity.h"

#include <algorithm>
#include <cassert>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/Cholesky>

#include "compensation/dense_kernels.h"

namespace procam {

RadiositySystem::RadiositySystem(const Eigen::MatrixXd& form_factors, const Eigen::VectorXd& area,
                                 const Eigen::MatrixX3d& reflectance)
    : form_factors_(form_factors), area_(area), reflectance_(reflectance) {
  [[maybe_unused]] const int n = size();
  assert(form_factors_.rows() == n && form_factors_.cols() == n && reflectance_.rows() == n);
  const bool grey = (reflectance_.col(0) == reflectance_.col(1)) && (reflectance_.col(0) == reflectance_.col(2));
  std::vector<std::vector<int>> groups = grey ? std::vector<std::vector<int>>{{0, 1, 2}}
                                              : std::vector<std::vector<int>>{{0}, {1}, {2}};
  const Eigen::VectorXd sqrt_area = area_.cwiseSqrt();
  for (const std::vector<int>& channels : groups) {
    Factor factor;
    factor.channels = channels;
    const Eigen::VectorXd rho = reflectance_.col(channels.front());
    factor.cholesky = rho.minCoeff() > 0.0;
    if (factor.cholesky) {
      // M = I − D^½ A^½ F A^-½ D^½, symmetric because A F is.
      const Eigen::VectorXd left = rho.cwiseSqrt().cwiseProduct(sqrt_area);
      const Eigen::VectorXd right = rho.cwiseSqrt().cwiseQuotient(sqrt_area);
      Eigen::MatrixXd m = -(left.asDiagonal() * form_factors_ * right.asDiagonal());
      // Symmetrise against rounding, then add the identity.
      m = 0.5 * (m + m.transpose()).eval();
      m.diagonal().array() += 1.0;
      const Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>, Eigen::Lower> llt(m);  // in place: L in m's lower part
      factor.scale = rho.cwiseSqrt().cwiseQuotient(sqrt_area);
      if (llt.info() != Eigen::Success) factor.cholesky = false;
      if (factor.cholesky) {
        for (int j = 1; j < n; ++j) m.col(j).head(j) = m.row(j).head(j).transpose();  // Lᵀ above
        factor.cholesky_factor = std::move(m);
        const Eigen::MatrixXf single = factor.cholesky_factor.cast<float>();
        factor.cholesky_factor_half.resize(single.size());
        ToHalf(single.data(), single.size(), factor.cholesky_factor_half.data());
      }
    }
    if (!factor.cholesky) {
      Eigen::MatrixXd k = -(rho.asDiagonal() * form_factors_);
      k.diagonal().array() += 1.0;
      factor.lu.compute(k);
    }
    factors_.push_back(std::move(factor));
  }
  form_factors_float_ = form_factors_.cast<float>();
  reflectance_float_ = reflectance_.cast<float>();
}

RadiositySystem::RadiositySystem(const Eigen::MatrixXd& form_factors, const Eigen::VectorXd& area,
                                 const Eigen::MatrixX3d& reflectance,
                                 std::shared_ptr<const RadiosityBackend> backend)
    : form_factors_(form_factors),
      form_factors_float_(form_factors.cast<float>()),
      reflectance_float_(reflectance.cast<float>()),
      area_(area),
      reflectance_(reflectance),
      backend_(std::move(backend)) {
  assert(backend_ != nullptr);
  assert(form_factors_.rows() == size() && form_factors_.cols() == size() && reflectance_.rows() == size());
}

RadiositySystem::RadiositySystem(std::shared_ptr<const CompressedFormFactors> form_factors,
                                 const Eigen::MatrixX3d& reflectance, const IterativeRadiosityOptions& options,
                                 std::shared_ptr<const RadiosityBackend> backend)
    : area_(form_factors->area()),
      reflectance_(reflectance),
      backend_(std::move(backend)),
      compressed_(std::move(form_factors)),
      iterative_(options) {
  assert(reflectance_.rows() == size());  // the Fast products are the double ones here: no float copies
}

Eigen::MatrixX3d RadiositySystem::ProductF(const Eigen::MatrixX3d& x) const {
  Eigen::MatrixX3d fx;
  if (backend_ && backend_->MultiplyF(x, &fx)) return fx;
  if (compressed_) return compressed_->Multiply(x);
  return form_factors_ * x;
}

Eigen::MatrixX3d RadiositySystem::ProductFTransposed(const Eigen::MatrixX3d& x) const {
  if (compressed_) {
    // Fᵀ X = A ∘ F (X / A): exact for the compressed F, whose exchange areas are symmetric.
    Eigen::MatrixX3d fx;
    if (backend_ && backend_->MultiplyF(area_.cwiseInverse().asDiagonal() * x, &fx)) return area_.asDiagonal() * fx;
    return compressed_->MultiplyTransposed(x);
  }
  return form_factors_.transpose() * x;
}

Eigen::MatrixX3d RadiositySystem::SolveIteratively(const Eigen::MatrixX3d& y, bool transposed,
                                                   double tolerance) const {
  const int n = size();
  const Eigen::ArrayXd sqrt_area = area_.cwiseSqrt().array();
  const Eigen::ArrayXXd sqrt_rho = reflectance_.cwiseSqrt().array();
  // M w = w − D^½ A^½ F A^-½ D^½ w, per channel (column).
  const auto apply_m = [&](const Eigen::MatrixX3d& w) {
    Eigen::MatrixX3d inner = (w.array() * sqrt_rho).colwise() / sqrt_area;
    const Eigen::MatrixX3d f_inner = ProductF(inner);
    return Eigen::MatrixX3d(w.array() - (f_inner.array().colwise() * sqrt_area) * sqrt_rho);
  };
  Eigen::MatrixX3d rhs;
  if (transposed) {
    rhs = (y.array().colwise() / sqrt_area) * sqrt_rho;
  } else {
    rhs = (ProductF(y).array().colwise() * sqrt_area) * sqrt_rho;
  }
  // Conjugate gradients, the three channels side by side (one product with F for all three).
  Eigen::MatrixX3d w = Eigen::MatrixX3d::Zero(n, 3);
  Eigen::MatrixX3d r = rhs, p = rhs;
  Eigen::Array3d rr = r.colwise().squaredNorm().transpose().array();
  const Eigen::Array3d goal = tolerance * tolerance * rhs.colwise().squaredNorm().transpose().array();
  int iteration = 0;
  for (; (rr > goal).any(); ++iteration) {
    if (iteration >= iterative_.max_iterations) {
      throw std::runtime_error("radiosity: conjugate gradients did not converge in " +
                               std::to_string(iterative_.max_iterations) + " iterations");
    }
    const Eigen::MatrixX3d mp = apply_m(p);
    for (int c = 0; c < 3; ++c) {
      if (rr[c] <= goal[c]) continue;  // this channel is done: leave it
      const double step = rr[c] / p.col(c).dot(mp.col(c));
      w.col(c) += step * p.col(c);
      r.col(c) -= step * mp.col(c);
      const double next = r.col(c).squaredNorm();
      p.col(c) = r.col(c) + (next / rr[c]) * p.col(c);
      rr[c] = next;
    }
  }
  solve_iterations_ += iteration;
  const Eigen::MatrixX3d scaled = (w.array() * sqrt_rho).colwise() / sqrt_area;  // A^-½ D^½ w
  if (transposed) return y + area_.asDiagonal() * ProductF(scaled);
  return y + scaled;
}

Eigen::MatrixX3d RadiositySystem::SolveFast(const Eigen::MatrixX3d& emittance) const {
  if (backend_) return backend_->Solve(emittance, /*transposed=*/false, /*fast=*/true);
  if (compressed_) return SolveIteratively(emittance, false, iterative_.fast_tolerance);
  Eigen::MatrixX3d radiosity(size(), 3);
  for (const Factor& factor : factors_) {
    if (!factor.cholesky) {
      for (int c : factor.channels) radiosity.col(c) = factor.lu.solve(emittance.col(c));
      continue;
    }
    Eigen::MatrixXf block(size(), factor.channels.size());
    for (size_t k = 0; k < factor.channels.size(); ++k) {
      block.col(k) = (factor.scale.cwiseInverse().cwiseProduct(emittance.col(factor.channels[k]))).cast<float>();
    }
    CholeskySolve(factor.cholesky_factor_half.data(), size(), static_cast<int>(block.cols()), block.data());
    for (size_t k = 0; k < factor.channels.size(); ++k) {
      radiosity.col(factor.channels[k]) = factor.scale.cwiseProduct(block.col(k).cast<double>());
    }
  }
  return radiosity;
}

Eigen::MatrixX3d RadiositySystem::SolveTransposedFast(const Eigen::MatrixX3d& y) const {
  if (backend_) return backend_->Solve(y, /*transposed=*/true, /*fast=*/true);
  if (compressed_) return SolveIteratively(y, true, iterative_.fast_tolerance);
  Eigen::MatrixX3d x(size(), 3);
  for (const Factor& factor : factors_) {
    if (!factor.cholesky) {
      for (int c : factor.channels) x.col(c) = factor.lu.transpose().solve(y.col(c));
      continue;
    }
    Eigen::MatrixXf block(size(), factor.channels.size());
    for (size_t k = 0; k < factor.channels.size(); ++k) {
      block.col(k) = (factor.scale.cwiseProduct(y.col(factor.channels[k]))).cast<float>();
    }
    CholeskySolve(factor.cholesky_factor_half.data(), size(), static_cast<int>(block.cols()), block.data());
    for (size_t k = 0; k < factor.channels.size(); ++k) {
      x.col(factor.channels[k]) = factor.scale.cwiseInverse().cwiseProduct(block.col(k).cast<double>());
    }
  }
  return x;
}

// form_factors_float_ is column-major, i.e. Fᵀ with contiguous rows for dense_kernels.h.
Eigen::MatrixX3d RadiositySystem::MultiplyFast(const Eigen::MatrixX3d& radiosity) const {
  if (compressed_) return Multiply(radiosity);
  const Eigen::MatrixX3f b = radiosity.cast<float>();
  Eigen::MatrixX3f fb(size(), 3);
  DenseTransposedProduct(form_factors_float_.data(), size(), b.data(), 3, fb.data());
  return radiosity - reflectance_.cwiseProduct(fb.cast<double>());
}

Eigen::MatrixX3d RadiositySystem::MultiplyTransposedFast(const Eigen::MatrixX3d& y) const {
  if (compressed_) return MultiplyTransposed(y);
  const Eigen::MatrixX3f weighted = reflectance_float_.cwiseProduct(y.cast<float>());
  Eigen::MatrixX3f ft_weighted(size(), 3);
  DenseProduct(form_factors_float_.data(), size(), weighted.data(), 3, ft_weighted.data());
  return y - ft_weighted.cast<double>();
}

Eigen::MatrixX3d RadiositySystem::Solve(const Eigen::MatrixX3d& emittance) const {
  if (backend_) return backend_->Solve(emittance, /*transposed=*/false, /*fast=*/false);
  if (compressed_) return SolveIteratively(emittance, false, iterative_.tolerance);
  Eigen::MatrixX3d radiosity(size(), 3);
  for (const Factor& factor : factors_) {
    Eigen::MatrixXd block(size(), factor.channels.size());
    for (size_t k = 0; k < factor.channels.size(); ++k) block.col(k) = emittance.col(factor.channels[k]);
    if (factor.cholesky) {
      // F = A^-½ S A^½ gives K = I − D F = A^-½ D^½ M D^-½ A^½, so K⁻¹ = diag(s) M⁻¹ diag(1/s)
      // with s = D^½ A^-½.
      block = factor.scale.cwiseInverse().asDiagonal() * block;
      CholeskySolve(factor.cholesky_factor.data(), size(), static_cast<int>(block.cols()), block.data());
      block = factor.scale.asDiagonal() * block;
    } else {
      block = factor.lu.solve(block);
    }
    for (size_t k = 0; k < factor.channels.size(); ++k) radiosity.col(factor.channels[k]) = block.col(k);
  }
  return radiosity;
}

Eigen::MatrixX3d RadiositySystem::SolveTransposed(const Eigen::MatrixX3d& y) const {
  if (backend_) return backend_->Solve(y, /*transposed=*/true, /*fast=*/false);
  if (compressed_) return SolveIteratively(y, true, iterative_.tolerance);
  Eigen::MatrixX3d x(size(), 3);
  for (const Factor& factor : factors_) {
    Eigen::MatrixXd block(size(), factor.channels.size());
    for (size_t k = 0; k < factor.channels.size(); ++k) block.col(k) = y.col(factor.channels[k]);
    if (factor.cholesky) {
      // (diag(s) M⁻¹ diag(1/s))ᵀ = diag(1/s) M⁻¹ diag(s).
      block = factor.scale.asDiagonal() * block;
      CholeskySolve(factor.cholesky_factor.data(), size(), static_cast<int>(block.cols()), block.data());
      block = factor.scale.cwiseInverse().asDiagonal() * block;
    } else {
      block = factor.lu.transpose().solve(block);
    }
    for (size_t k = 0; k < factor.channels.size(); ++k) x.col(factor.channels[k]) = block.col(k);
  }
  return x;
}

Eigen::MatrixX3d RadiositySystem::Multiply(const Eigen::MatrixX3d& radiosity) const {
  return radiosity - reflectance_.cwiseProduct(ProductF(radiosity));
}

Eigen::MatrixX3d RadiositySystem::MultiplyTransposed(const Eigen::MatrixX3d& y) const {
  return y - ProductFTransposed(reflectance_.cwiseProduct(y));
}

Eigen::MatrixXd RadiositySystem::InverseMatrix(int channel) const {
  if (backend_ || compressed_) {
    Eigen::MatrixXd inverse(size(), size());
    for (int j = 0; j < size(); ++j) {
      Eigen::MatrixX3d unit = Eigen::MatrixX3d::Zero(size(), 3);
      unit(j, channel) = 1.0;
      inverse.col(j) = Solve(unit).col(channel);
    }
    return inverse;
  }
  for (const Factor& factor : factors_) {
    if (std::find(factor.channels.begin(), factor.channels.end(), channel) == factor.channels.end()) continue;
    if (!factor.cholesky) return factor.lu.solve(Eigen::MatrixXd::Identity(size(), size()));
    Eigen::MatrixXd inverse = Eigen::MatrixXd::Zero(size(), size());
    for (int j = 0; j < size(); ++j) {
      inverse(j, j) = 1.0 / factor.scale[j];
      CholeskySolve(factor.cholesky_factor.data(), size(), 1, inverse.col(j).data());
    }
    return factor.scale.asDiagonal() * inverse;
  }
  return Eigen::MatrixXd();
}

}  // namespace procam
