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

#include "geometry/compressed_form_factors.h"

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
  // F X on the device, when the backend holds F (the matrix-free one); false: the caller
  // multiplies on the CPU.
  virtual bool MultiplyF(const Eigen::MatrixX3d& x, Eigen::MatrixX3d* fx) const {
    (void)x;
    (void)fx;
    return false;
  }
};

// The matrix-free system (compressed F): K⁻¹ and K⁻ᵀ by conjugate gradients on the symmetric
// positive definite M_c = I − D_c^½ S D_c^½, S = A^½ F A^-½ (one product with F per iteration,
// no n² storage, no division by rho so black patches need no special case):
//   K b = e:   M w = D^½ A^½ F e,            b = e + A^-½ D^½ w
//   Kᵀ x = y:  M w = D^½ A^-½ y,             x = y + A F A^-½ D^½ w
// Iterations ~ √cond(M) log(1/tolerance), cond(M) ≤ (1 + max rho)/(1 − max rho).
struct IterativeRadiosityOptions {
  double tolerance = 1e-11;      // relative residual |r| ≤ tolerance |rhs| of Solve / SolveTransposed
  double fast_tolerance = 1e-5;  // of the Fast solves (CG directions, preconditioners)
  int max_iterations = 2000;     // per solve; a solve that does not converge throws std::runtime_error
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

  // Matrix-free: F compressed (shared, not copied), every solve iterative on the CPU, or by
  // `backend` when given (which then holds what it needs of F). No n² memory.
  RadiositySystem(std::shared_ptr<const CompressedFormFactors> form_factors, const Eigen::MatrixX3d& reflectance,
                  const IterativeRadiosityOptions& options = {},
                  std::shared_ptr<const RadiosityBackend> backend = nullptr);

  int size() const { return static_cast<int>(area_.size()); }
  // The compressed F of a matrix-free system, else null.
  const CompressedFormFactors* compressed() const { return compressed_.get(); }
  // CG iterations of the iterative solves so far (matrix-free systems on the CPU).
  int64_t solve_iterations() const { return solve_iterations_; }
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

  // Dense K_c⁻¹ (n×n) for one channel: for small problems, tests and peer solvers (n solves
  // when matrix-free).
  Eigen::MatrixXd InverseMatrix(int channel) const;

  // Dense F (empty when matrix-free).
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
  std::shared_ptr<const CompressedFormFactors> compressed_;  // matrix-free systems
  IterativeRadiosityOptions iterative_;
  mutable int64_t solve_iterations_ = 0;

  // F X and Fᵀ X, dense or compressed.
  Eigen::MatrixX3d ProductF(const Eigen::MatrixX3d& x) const;
  Eigen::MatrixX3d ProductFTransposed(const Eigen::MatrixX3d& x) const;
  // The matrix-free solves above (transposed: Kᵀ).
  Eigen::MatrixX3d SolveIteratively(const Eigen::MatrixX3d& y, bool transposed, double tolerance) const;
};

}  // namespace procam
