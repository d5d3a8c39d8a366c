#include "compensation/objective.h"

#include <cmath>
#include <stdexcept>
#include <utility>

#include "compensation/colour.h"

namespace procam {
namespace {

// Linear luma/chroma of Rec. 709 RGB (Y, Pb, Pr), scaled so that the white radiosity has Y = 100.
Eigen::Matrix3d LinearColourMatrix(double white) {
  const double kr = 0.2126, kg = 0.7152, kb = 0.0722;
  Eigen::Matrix3d m;
  m << kr, kg, kb,
       -0.5 * kr / (1 - kb), -0.5 * kg / (1 - kb), 0.5,
       0.5, -0.5 * kg / (1 - kr), -0.5 * kb / (1 - kr);
  return (100.0 / white) * m;
}

}  // namespace

Eigen::VectorXd Flatten(const Eigen::MatrixX3d& m) {
  Eigen::VectorXd v(m.size());
  for (int i = 0; i < m.rows(); ++i) v.segment<3>(3 * i) = m.row(i).transpose();
  return v;
}

Eigen::MatrixX3d Unflatten(const Eigen::VectorXd& v) {
  Eigen::MatrixX3d m(v.size() / 3, 3);
  for (int i = 0; i < m.rows(); ++i) m.row(i) = v.segment<3>(3 * i).transpose();
  return m;
}

CompensationObjective::CompensationObjective(const CompensationProblem& problem,
                                             const RadiositySystem& radiosity, ColourModel model,
                                             ColourMetric metric)
    : problem_(problem), radiosity_(radiosity), model_(model), metric_(std::move(metric)) {
  const int n = problem.size();
  if ((!metric_.factor.empty() && static_cast<int>(metric_.factor.size()) != n) ||
      (metric_.weight.size() != 0 && metric_.weight.size() != n)) {
    throw std::invalid_argument("colour metric: one factor and weight per patch");
  }
  const Eigen::Index pairs = static_cast<Eigen::Index>(problem.adjacency.size());
  if (metric_.pair_weight.size() != 0 && metric_.pair_weight.size() != pairs)
    throw std::invalid_argument("colour metric: one weight per adjacent pair");
  if (model_ == ColourModel::kLinear && !metric_.factor.empty())
    throw std::invalid_argument("colour metric: for the L*a*b* model only");
  const double mean_area = problem.area.mean();
  weight_diagonal_ = problem.alpha * problem.area / mean_area;
  if (problem.patch_weight.size() == n) weight_diagonal_ = weight_diagonal_.cwiseProduct(problem.patch_weight);
  if (metric_.weight.size() == n) weight_diagonal_ = weight_diagonal_.cwiseProduct(metric_.weight);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(2 * problem.adjacency.size() + n);
  Eigen::VectorXd diagonal = weight_diagonal_;
  for (Eigen::Index k = 0; k < pairs; ++k) {
    const auto& pair = problem.adjacency[k];
    const double w = (1.0 - problem.alpha) * (metric_.pair_weight.size() == pairs ? metric_.pair_weight[k] : 1.0);
    if (w == 0.0) continue;
    diagonal[pair[0]] += w;
    diagonal[pair[1]] += w;
    triplets.emplace_back(pair[0], pair[1], -w);
    triplets.emplace_back(pair[1], pair[0], -w);
  }
  for (int i = 0; i < n; ++i) triplets.emplace_back(i, i, diagonal[i]);
  weights_.resize(n, n);
  weights_.setFromTriplets(triplets.begin(), triplets.end());
}

const Eigen::MatrixX3d& CompensationObjective::DesiredColour() const {
  std::call_once(desired_colour_formed_, [this] {
    desired_colour_.resize(patches(), 3);
    for (int i = 0; i < patches(); ++i) {
      desired_colour_.row(i) = Colour(problem_.desired.row(i).transpose()).transpose();
    }
  });
  return desired_colour_;
}

Eigen::Vector3d CompensationObjective::Colour(const Eigen::Vector3d& rgb) const {
  if (model_ == ColourModel::kLinear) {
    return LinearColourMatrix(problem_.white_xyz[1] / problem_.rgb_to_xyz.row(1).sum()) * rgb;
  }
  return XyzToLab(problem_.rgb_to_xyz * rgb, problem_.white_xyz);
}

Eigen::Matrix3d CompensationObjective::ColourJacobian(const Eigen::Vector3d& rgb) const {
  if (model_ == ColourModel::kLinear) {
    return LinearColourMatrix(problem_.white_xyz[1] / problem_.rgb_to_xyz.row(1).sum());
  }
  return XyzToLabJacobian(problem_.rgb_to_xyz * rgb, problem_.white_xyz) * problem_.rgb_to_xyz;
}

Eigen::Vector3d CompensationObjective::Residual(int i, const Eigen::Vector3d& rgb) const {
  const Eigen::Vector3d r = Colour(rgb) - DesiredColour().row(i).transpose();
  return metric_.factor.empty() ? r : Eigen::Vector3d(metric_.factor[i] * r);
}

Eigen::Matrix3d CompensationObjective::PatchJacobian(int i, const Eigen::Vector3d& rgb) const {
  const Eigen::Matrix3d jacobian = ColourJacobian(rgb);
  return metric_.factor.empty() ? jacobian : Eigen::Matrix3d(metric_.factor[i] * jacobian);
}

double CompensationObjective::Evaluate(const Eigen::MatrixX3d& emittance, ObjectivePoint* point) const {
  const int n = patches();
  point->emittance = emittance;
  point->radiosity = radiosity_.Solve(emittance);
  point->residual.resize(n, 3);
  point->colour_jacobian.resize(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d rgb = point->radiosity.row(i).transpose();
    point->residual.row(i) = Residual(i, rgb).transpose();
    point->colour_jacobian[i] = PatchJacobian(i, rgb);
  }
  point->value = point->residual.cwiseProduct((weights_ * point->residual)).sum();
  return point->value;
}

double CompensationObjective::Value(const Eigen::MatrixX3d& emittance) const {
  const Eigen::MatrixX3d radiosity = radiosity_.Solve(emittance);
  Eigen::MatrixX3d residual(patches(), 3);
  for (int i = 0; i < patches(); ++i) residual.row(i) = Residual(i, radiosity.row(i).transpose()).transpose();
  return residual.cwiseProduct((weights_ * residual)).sum();
}

Eigen::MatrixX3d CompensationObjective::Gradient(const ObjectivePoint& point) const {
  const Eigen::MatrixX3d weighted = 2.0 * (weights_ * point.residual);
  Eigen::MatrixX3d by_radiosity(patches(), 3);
  for (int i = 0; i < patches(); ++i) {
    by_radiosity.row(i) = weighted.row(i) * point.colour_jacobian[i];
  }
  return radiosity_.SolveTransposed(by_radiosity);
}

Eigen::MatrixX3d CompensationObjective::GaussNewtonProduct(const ObjectivePoint& point,
                                                           const Eigen::MatrixX3d& v, bool fast) const {
  const Eigen::MatrixX3d u = fast ? radiosity_.SolveFast(v) : radiosity_.Solve(v);
  Eigen::MatrixX3d colour(patches(), 3);
  for (int i = 0; i < patches(); ++i) colour.row(i) = u.row(i) * point.colour_jacobian[i].transpose();
  const Eigen::MatrixX3d weighted = 2.0 * (weights_ * colour);
  Eigen::MatrixX3d back(patches(), 3);
  for (int i = 0; i < patches(); ++i) back.row(i) = weighted.row(i) * point.colour_jacobian[i];
  if (!point.second_order.empty()) {
    for (int i = 0; i < patches(); ++i) back.row(i) += u.row(i) * point.second_order[i];  // S symmetric
  }
  return fast ? radiosity_.SolveTransposedFast(back) : radiosity_.SolveTransposed(back);
}

void CompensationObjective::AddSecondOrder(ObjectivePoint* point) const {
  point->second_order.assign(patches(), Eigen::Matrix3d::Zero());
  if (model_ == ColourModel::kLinear) return;
  const Eigen::MatrixX3d weighted = 2.0 * (weights_ * point->residual);
  const Eigen::Matrix3d& t = problem_.rgb_to_xyz;
  for (int i = 0; i < patches(); ++i) {
    const Eigen::Vector3d xyz = t * point->radiosity.row(i).transpose();
    // Σ_k w_k ∇²(L_i Lab)_k = Σ_m (L_iᵀ w)_m ∇²Lab_m.
    const Eigen::Vector3d w =
        metric_.factor.empty()
            ? Eigen::Vector3d(weighted.row(i).transpose())
            : Eigen::Vector3d(metric_.factor[i].transpose() * weighted.row(i).transpose());
    const Eigen::Vector3d curvature = XyzToLabWeightedCurvature(xyz, problem_.white_xyz, w);
    point->second_order[i] = t.transpose() * curvature.asDiagonal() * t;
  }
}

Eigen::SparseMatrix<double> CompensationObjective::ColourHessian(const ObjectivePoint& point) const {
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(9 * weights_.nonZeros());
  for (int column = 0; column < weights_.outerSize(); ++column) {
    for (Eigen::SparseMatrix<double>::InnerIterator it(weights_, column); it; ++it) {
      const int i = static_cast<int>(it.row()), j = static_cast<int>(it.col());
      Eigen::Matrix3d block = 2.0 * it.value() * point.colour_jacobian[i].transpose() * point.colour_jacobian[j];
      if (i == j && !point.second_order.empty()) block += point.second_order[i];
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) triplets.emplace_back(3 * i + a, 3 * j + b, block(a, b));
      }
    }
  }
  Eigen::SparseMatrix<double> m(variables(), variables());
  m.setFromTriplets(triplets.begin(), triplets.end());
  return m;
}

std::vector<Eigen::Matrix3d> CompensationObjective::InverseColourJacobians(const ObjectivePoint& point) const {
  std::vector<Eigen::Matrix3d> inverse(patches());
  for (int i = 0; i < patches(); ++i) inverse[i] = point.colour_jacobian[i].inverse();
  return inverse;
}

Eigen::MatrixX3d CompensationObjective::SolveGaussNewtonColour(const std::vector<Eigen::Matrix3d>& jacobian_inverse,
                                                               const Eigen::MatrixX3d& r) const {
  // Row form: (J_i⁻ᵀ r_i)ᵀ = r_iᵀ J_i⁻¹.
  Eigen::MatrixX3d colour(patches(), 3);
  for (int i = 0; i < patches(); ++i) colour.row(i) = r.row(i) * jacobian_inverse[i];
  std::call_once(weights_factored_, [this] { weights_factor_.compute(weights_); });
  const Eigen::MatrixX3d weighted = 0.5 * weights_factor_.solve(colour);
  Eigen::MatrixX3d result(patches(), 3);
  for (int i = 0; i < patches(); ++i) result.row(i) = weighted.row(i) * jacobian_inverse[i].transpose();
  return result;
}

void CompensationObjective::DeltaE(const Eigen::MatrixX3d& radiosity, Eigen::VectorXd* delta_e76,
                                   Eigen::VectorXd* delta_e2000) const {
  const int n = patches();
  delta_e76->resize(n);
  delta_e2000->resize(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d lab = XyzToLab(problem_.rgb_to_xyz * radiosity.row(i).transpose(), problem_.white_xyz);
    const Eigen::Vector3d desired =
        XyzToLab(problem_.rgb_to_xyz * problem_.desired.row(i).transpose(), problem_.white_xyz);
    (*delta_e76)[i] = DeltaE76(lab, desired);
    (*delta_e2000)[i] = DeltaE2000(lab, desired);
  }
}

}  // namespace procam
