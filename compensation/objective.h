#pragma once
// The compensation objective (paper Eq. 5–6) as a function of the emittance E (n×3):
//   f(E) = Σ_k r_kᵀ W r_k,  W = α diag(A_i/A_avg) + (1−α) L,  r = C(B) − C(Bd),  B = K⁻¹ E,
// where k runs over the three colour components, L is the adjacency graph's Laplacian (each
// unordered pair once) and C maps linear RGB to the colour space: L*a*b* for the perceptual
// method (nonlinear), Y'PbPr-like linear luma/chroma for the linear method of Sheng 2010.
//
// Variables are stored as n×3 matrices (row = patch, column = RGB channel); a flattened vector
// is patch-major (index 3i + c).

#include <array>
#include <memory>
#include <mutex>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include "compensation/problem.h"
#include "compensation/radiosity.h"

namespace procam {

enum class ColourModel {
  kLab,    // CIE L*a*b* relative to the problem's white (perceptual)
  kLinear  // Y, Pb, Pr of linear Rec. 709 RGB, scaled to L*-like units (linear; Sheng 2010)
};

// A per-patch reweighting of the L*a*b* objective: patch i's residual becomes L_i r_i, so that
// its squared length is r_iᵀ M_i r_i with M_i = L_iᵀ L_i (e.g. CIEDE2000's metric,
// DeltaE2000Metric), in the data term and in the spatial term alike (neighbours' residuals are
// compared in their metrics: measured better than comparing them in plain L*a*b*, docs/solver.md),
// the data term α A_i/Ā is scaled by `weight`_i and the spatial term's pair k (problem.adjacency)
// by `pair_weight`_k (e.g. a robust loss's ρ′). Empty members leave the objective as published.
struct ColourMetric {
  std::vector<Eigen::Matrix3d> factor;  // L_i, n of them, or none
  Eigen::VectorXd weight;               // n positive weights, or none
  Eigen::VectorXd pair_weight;          // one positive weight per adjacent pair, or none
};

// Everything the objective knows at one point E.
struct ObjectivePoint {
  Eigen::MatrixX3d emittance;   // E (n×3)
  Eigen::MatrixX3d radiosity;   // B = K⁻¹E
  Eigen::MatrixX3d residual;    // r (n×3 colour components)
  std::vector<Eigen::Matrix3d> colour_jacobian;  // ∂C/∂B per patch
  // Optional second-order term per patch, Σ_k (2WR)_ik ∇²C_k(B_i) (3×3 in B); empty for pure
  // Gauss–Newton. Filled by AddSecondOrder.
  std::vector<Eigen::Matrix3d> second_order;
  double value = 0.0;           // f
};

class CompensationObjective {
 public:
  // Keeps a reference to `problem` and `radiosity` (both must outlive the objective). `metric`
  // (copied) reweights the L*a*b* objective; the linear model takes none.
  CompensationObjective(const CompensationProblem& problem, const RadiositySystem& radiosity,
                        ColourModel model, ColourMetric metric = {});

  int patches() const { return static_cast<int>(weight_diagonal_.size()); }
  int variables() const { return 3 * patches(); }
  ColourModel model() const { return model_; }
  const ColourMetric& metric() const { return metric_; }
  const CompensationProblem& problem() const { return problem_; }
  const RadiositySystem& radiosity() const { return radiosity_; }

  // Colour of linear RGB radiosity in this objective's space, and its Jacobian.
  Eigen::Vector3d Colour(const Eigen::Vector3d& rgb) const;
  Eigen::Matrix3d ColourJacobian(const Eigen::Vector3d& rgb) const;

  // Fills `point` at E; returns f. Non-finite input gives a non-finite value, never a crash.
  double Evaluate(const Eigen::MatrixX3d& emittance, ObjectivePoint* point) const;
  // f only.
  double Value(const Eigen::MatrixX3d& emittance) const;
  // ∂f/∂E at an evaluated point.
  Eigen::MatrixX3d Gradient(const ObjectivePoint& point) const;
  // Hessian product H v with H = K⁻ᵀ (M + S) K⁻¹: M = 2 Jᵀ (W ⊗ I₃) J the Gauss–Newton
  // matrix (J = blockdiag ∂C/∂B), S the block-diagonal second-order term when
  // point.second_order is filled (then H is the exact Hessian of f), else S = 0.
  // `fast`: K⁻¹ and K⁻ᵀ in float32 (RadiositySystem::SolveFast), for CG iterations.
  Eigen::MatrixX3d GaussNewtonProduct(const ObjectivePoint& point, const Eigen::MatrixX3d& v,
                                      bool fast = false) const;
  // Fills point.second_order (all zero for the linear model, whose f is quadratic).
  void AddSecondOrder(ObjectivePoint* point) const;

  // W as a sparse n×n matrix, and W·R for an n×3 R.
  const Eigen::SparseMatrix<double>& weights() const { return weights_; }
  // The colour-space matrix M + S in B (3n×3n, patch-major), S as in GaussNewtonProduct:
  // H = K⁻ᵀ (M + S) K⁻¹, so H⁻¹ = K (M + S)⁻¹ Kᵀ. Assembled for tests and small problems; the
  // solver assembles only the free variables' part of M (solver.cc).
  Eigen::SparseMatrix<double> ColourHessian(const ObjectivePoint& point) const;

  // M⁻¹ R for the Gauss–Newton colour matrix M = 2 Jᵀ (W ⊗ I₃) J (R: n×3 in B, patch-major
  // as everywhere). J is block diagonal with invertible 3×3 blocks J_i = ∂C/∂B_i and W does not
  // depend on the point, so M⁻¹ = ½ J⁻¹ (W⁻¹ ⊗ I₃) J⁻ᵀ: per-patch 3×3 products around one
  // sparse solve with W, factorised once in the constructor. `jacobian_inverse` holds J_i⁻¹
  // (InverseColourJacobians).
  Eigen::MatrixX3d SolveGaussNewtonColour(const std::vector<Eigen::Matrix3d>& jacobian_inverse,
                                          const Eigen::MatrixX3d& r) const;
  std::vector<Eigen::Matrix3d> InverseColourJacobians(const ObjectivePoint& point) const;

  // Patch i's residual L_i (C(rgb) − C(Bd_i)) and its Jacobian L_i ∂C/∂B (L_i = I without a
  // metric).
  Eigen::Vector3d Residual(int i, const Eigen::Vector3d& rgb) const;
  Eigen::Matrix3d PatchJacobian(int i, const Eigen::Vector3d& rgb) const;

  // Per-patch colour differences between B and the desired radiosity in L*a*b*.
  void DeltaE(const Eigen::MatrixX3d& radiosity, Eigen::VectorXd* delta_e76,
              Eigen::VectorXd* delta_e2000) const;

 private:
  const CompensationProblem& problem_;
  const RadiositySystem& radiosity_;
  ColourModel model_;
  ColourMetric metric_;
  Eigen::VectorXd weight_diagonal_;
  Eigen::SparseMatrix<double> weights_;
  // W = L Lᵀ (W is SPD: α > 0), factorised on first use: only the kInverseHessian
  // preconditioner needs it, and the factorisation costs ~0.1 s at 100k patches.
  mutable Eigen::SimplicialLLT<Eigen::SparseMatrix<double>> weights_factor_;
  mutable std::once_flag weights_factored_;
  // The desired appearance in the objective's colour space, formed on first use (the GPU solver
  // forms its own on the device: 0.4 ms of its set-up at 10 000 patches).
  const Eigen::MatrixX3d& DesiredColour() const;
  mutable Eigen::MatrixX3d desired_colour_;
  mutable std::once_flag desired_colour_formed_;
};

// Flattening helpers (patch-major: index 3i + c).
Eigen::VectorXd Flatten(const Eigen::MatrixX3d& m);
Eigen::MatrixX3d Unflatten(const Eigen::VectorXd& v);

}  // namespace procam
