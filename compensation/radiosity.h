#pragma once
// Radiosity B_c = K_c⁻¹ E_c with K_c = I − diag(rho_c) F (paper Eq. 1), factorised once.
//
// F is shared by the channels; when every patch has the same reflectance in all three
// channels (grey rooms, the common case) one factorisation serves all three. Because
// A_i F_ij = A_j F_ji, S = A^½ F A^-½ is symmetric and M_c = I − D_c^½ S D_c^½ (D_c = diag rho_c)
// is symmetric positive definite (its eigenvalues lie in [1 − max rho, 1 + max rho]), so
// K_c⁻¹ = A^-½ D_c^½ M_c⁻¹ D_c^-½ A^½ is applied with a Cholesky factor (n³/3 flops instead of
// LU's 2n³/3). Reflectances of exactly 0 fall back to a pivoted LU of K_c.
// Dense factors are n² doubles plus n² halves per distinct channel (and F in double and
// float32): about 20k patches on a 24 GB machine; larger rooms need the matrix-free path of the
// GPU/scale issue.
//
// The substitutions and the float32 products with F run through dense_kernels.h (AVX2/FMA where
// the CPU has it): Eigen's triangular solves and products with three right-hand sides are
// SSE2-only at the project's compiler flags, 2–3× slower.

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>

namespace procam {

// Another device applying K⁻¹ and K⁻ᵀ in place of RadiositySystem's CPU factors (the CUDA
// backend of compensation/cuda_radiosity.h). Implementations own their device memory.
class RadiosityBackend {
 public:
  virtual ~RadiosityBackend() = default;
  // K⁻¹ Y (K⁻ᵀ Y when `transposed`), per channel (columns). `fast`: the reduced-precision
  // application used for CG directions and preconditioners (RadiositySystem::SolveFast).
  virtual Eigen::MatrixX3d Solve(const Eigen::MatrixX3d& y, bool transposed, bool fast) const = 0;
  // Channels sharing one K⁻¹ (as RadiositySystem::factorisations).
  virtual int factorisations() const = 0;
};

class RadiositySystem {
 public:
  // `form_factors` (n×n) and `area` (n) are copied; `reflectance` is (n,3) in [0,1).
  RadiositySystem(const Eigen::MatrixXd& form_factors, const Eigen::VectorXd& area,
                  const Eigen::MatrixX3d& reflectance);
  // The same system with every solve (Solve, SolveTransposed and their Fast forms) done by
  // `backend`, which already holds K⁻¹ for these inputs; nothing is factorised on the CPU.
  // Products with K (Multiply*) stay on the CPU.
  RadiositySystem(const Eigen::MatrixXd& form_factors, const Eigen::VectorXd& area,
                  const Eigen::MatrixX3d& reflectance, std::shared_ptr<const RadiosityBackend> backend);

  int size() const { return static_cast<int>(area_.size()); }
  // Channels sharing a factorisation (1 for grey reflectance, else 3).
  int factorisations() const {
    return backend_ ? backend_->factorisations() : static_cast<int>(factors_.size());
  }
  // The device doing the solves, or null for the CPU factors.
  const RadiosityBackend* backend() const { return backend_.get(); }

  // B = K⁻¹ E, per channel (columns).
  Eigen::MatrixX3d Solve(const Eigen::MatrixX3d& emittance) const;
  // X = K⁻ᵀ Y, per channel.
  Eigen::MatrixX3d SolveTransposed(const Eigen::MatrixX3d& y) const;
  // E = K B = B − rho ∘ (F B).
  Eigen::MatrixX3d Multiply(const Eigen::MatrixX3d& radiosity) const;
  // Kᵀ Y = Y − Fᵀ (rho ∘ Y).
  Eigen::MatrixX3d MultiplyTransposed(const Eigen::MatrixX3d& y) const;

  // The same four operations in reduced precision, for inner iterations whose accuracy does not
  // matter (conjugate-gradient directions, preconditioners); objective values and gradients use
  // the double versions. The solves use a half-precision factor with float32 arithmetic
  // (relative error ~5e-4 · cond(K), cond(K) ≤ (1 + max rho)/(1 − max rho)), about 3× faster
  // than double: memory-bound over a quarter of the bytes. The products use F in float32.
  Eigen::MatrixX3d SolveFast(const Eigen::MatrixX3d& emittance) const;
  Eigen::MatrixX3d SolveTransposedFast(const Eigen::MatrixX3d& y) const;
  Eigen::MatrixX3d MultiplyFast(const Eigen::MatrixX3d& radiosity) const;
  Eigen::MatrixX3d MultiplyTransposedFast(const Eigen::MatrixX3d& y) const;

  // Dense K_c⁻¹ (n×n) for one channel: for small problems, tests and peer solvers.
  Eigen::MatrixXd InverseMatrix(int channel) const;

  const Eigen::MatrixXd& form_factors() const { return form_factors_; }
  const Eigen::MatrixX3d& reflectance() const { return reflectance_; }

 private:
  struct Factor {
    std::vector<int> channels;
    bool cholesky = true;
    Eigen::VectorXd scale;  // D^½ A^-½ (left) — K⁻¹ = diag(scale) M⁻¹ diag(1/scale)
    // M = L Lᵀ stored as L + Lᵀ − diag(L) (dense_kernels.h's CholeskySolve layout), in double
    // and in IEEE half precision (for the fast solves).
    Eigen::MatrixXd cholesky_factor;
    std::vector<std::uint16_t> cholesky_factor_half;
    Eigen::PartialPivLU<Eigen::MatrixXd> lu;
  };
  Eigen::MatrixXd form_factors_;
  Eigen::MatrixXf form_factors_float_;
  Eigen::MatrixX3f reflectance_float_;
  Eigen::VectorXd area_;
  Eigen::MatrixX3d reflectance_;
  std::vector<Factor> factors_;
  std::shared_ptr<const RadiosityBackend> backend_;  // null: the CPU factors above
};

}  // namespace procam
