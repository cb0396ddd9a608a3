#include "reference/fluid/viscosity.hpp"

#include <stdexcept>

namespace monolith {

template <int Dim>
StressLayout<Dim>::StressLayout(const StressGrid<Dim>& stress, StressForm form)
    : stress_(stress), form_(form) {
  // unknown components: all, or all but the last diagonal one
  unknown_of_component_.assign(StressGrid<Dim>::kComponents, -1);
  offset_.assign(1, 0);
  for (int k = 0; k < StressGrid<Dim>::kComponents; ++k) {
    if (form == StressForm::reduced && k == Dim - 1) continue;
    unknown_of_component_[k] = static_cast<int>(component_.size());
    component_.push_back(k);
    offset_.push_back(offset_.back() + stress.num_dofs(k));
  }
}

template <int Dim>
int StressLayout<Dim>::component_of_unknown(int i) const {
  int j = 0;
  while (i >= offset_[j + 1]) ++j;
  return j;
}

template <int Dim>
int StressLayout<Dim>::dof_of_unknown(int i) const {
  const int j = component_of_unknown(i);
  return stress_.offset(component_[j]) + (i - offset_[j]);
}

template <int Dim>
int StressLayout<Dim>::unknown_of_dof(int dof) const {
  const int k = stress_.coord(dof).first;
  const int j = unknown_of_component_[k];
  return j < 0 ? -1 : offset_[j] + (dof - stress_.offset(k));
}

template <int Dim>
SparseMatrix StressLayout<Dim>::expansion() const {
  std::vector<Triplet> t;
  t.reserve(stress_.num_dofs() + (Dim - 1) * stress_.num_dofs(0));
  for (int i = 0; i < num_unknowns(); ++i) {
    const int j = component_of_unknown(i);
    const int k = component_[j];
    const int local = i - offset_[j];
    // the unknown itself
    t.emplace_back(stress_.offset(k) + local, i, 1.0);
    // reduced: the eliminated diagonal component of the same cell is minus the others
    if (form_ == StressForm::reduced && StressGrid<Dim>::is_diagonal(k))
      t.emplace_back(stress_.offset(Dim - 1) + local, i, -1.0);
  }
  SparseMatrix e(stress_.num_dofs(), num_unknowns());
  e.setFromTriplets(t.begin(), t.end());
  return e;
}

template <int Dim>
VectorX StressLayout<Dim>::expand(const VectorX& tau) const {
  VectorX full = VectorX::Zero(stress_.num_dofs());
  for (int j = 0; j < num_components(); ++j) {
    const int k = component_[j];
    const int n = stress_.num_dofs(k);
    full.segment(stress_.offset(k), n) = tau.segment(offset_[j], n);
    if (form_ == StressForm::reduced && StressGrid<Dim>::is_diagonal(k))
      full.segment(stress_.offset(Dim - 1), n) -= tau.segment(offset_[j], n);
  }
  return full;
}

template <int Dim>
VectorX StressLayout<Dim>::expand_transpose(const VectorX& s) const {
  VectorX r(num_unknowns());
  for (int j = 0; j < num_components(); ++j) {
    const int k = component_[j];
    const int n = stress_.num_dofs(k);
    r.segment(offset_[j], n) = s.segment(stress_.offset(k), n);
    if (form_ == StressForm::reduced && StressGrid<Dim>::is_diagonal(k))
      r.segment(offset_[j], n) -= s.segment(stress_.offset(Dim - 1), n);
  }
  return r;
}

template <int Dim>
VectorX stress_multiplicity(const StressGrid<Dim>& stress) {
  VectorX m(stress.num_dofs());
  for (int k = 0; k < StressGrid<Dim>::kComponents; ++k)
    m.segment(stress.offset(k), stress.num_dofs(k))
        .setConstant(StressGrid<Dim>::multiplicity(k));
  return m;
}

template <int Dim>
SparseMatrix inverse_viscosity_matrix(const StressLayout<Dim>& layout, const VectorX& eta) {
  const StressGrid<Dim>& stress = layout.grid();
  if (eta.size() != stress.num_dofs())
    throw std::invalid_argument("inverse_viscosity_matrix: eta must have one value per stress DOF");
  // N_full^-1 = M diag(1/eta), then E^T N_full^-1 E
  VectorX n_full(stress.num_dofs());
  const VectorX m = stress_multiplicity(stress);
  for (int i = 0; i < stress.num_dofs(); ++i) n_full[i] = m[i] * reciprocal_or_zero(eta[i]);
  SparseMatrix nf(stress.num_dofs(), stress.num_dofs());
  nf.reserve(Eigen::VectorXi::Constant(stress.num_dofs(), 1));
  for (int i = 0; i < stress.num_dofs(); ++i) nf.insert(i, i) = n_full[i];
  const SparseMatrix e = layout.expansion();
  const SparseMatrix et = e.transpose();
  SparseMatrix r = et * nf * e;
  r.prune(0.0);
  return r;
}

template <int Dim>
SparseMatrix viscosity_matrix(const StressLayout<Dim>& layout, const VectorX& eta) {
  const StressGrid<Dim>& stress = layout.grid();
  const SparseMatrix n_inv = inverse_viscosity_matrix(layout, eta);
  std::vector<Triplet> t;
  // invert the blocks of N^-1: off-diagonal unknowns and full-form unknowns are 1 x 1; the
  // diagonal unknowns of one cell in the reduced form are coupled (Dim - 1 square)
  for (int j = 0; j < layout.num_components(); ++j) {
    const int k = layout.component(j);
    const bool block = layout.form() == StressForm::reduced && StressGrid<Dim>::is_diagonal(k);
    if (block && k != 0) continue;  // the whole block is handled with component 0
    for (int local = 0; local < stress.num_dofs(k); ++local) {
      if (!block) {
        const int i = layout.offset(j) + local;
        const double v = n_inv.coeff(i, i);
        if (v > 0.0) t.emplace_back(i, i, 1.0 / v);
        continue;
      }
      constexpr int B = Dim - 1;
      Eigen::Matrix<double, B, B> blk;
      std::array<int, B> idx;
      for (int r = 0; r < B; ++r) idx[r] = layout.offset(r) + local;
      for (int r = 0; r < B; ++r)
        for (int c = 0; c < B; ++c) blk(r, c) = n_inv.coeff(idx[r], idx[c]);
      // a block with eta = 0 somewhere is singular: no viscosity there, N = 0
      if (!(blk.determinant() > 0.0) || !(blk.diagonal().minCoeff() > 0.0)) continue;
      const Eigen::Matrix<double, B, B> inv = blk.inverse();
      for (int r = 0; r < B; ++r)
        for (int c = 0; c < B; ++c) t.emplace_back(idx[r], idx[c], inv(r, c));
    }
  }
  SparseMatrix n(layout.num_unknowns(), layout.num_unknowns());
  n.setFromTriplets(t.begin(), t.end());
  return n;
}

template class StressLayout<2>;
template class StressLayout<3>;
template VectorX stress_multiplicity<2>(const StressGrid<2>&);
template VectorX stress_multiplicity<3>(const StressGrid<3>&);
template SparseMatrix viscosity_matrix<2>(const StressLayout<2>&, const VectorX&);
template SparseMatrix viscosity_matrix<3>(const StressLayout<3>&, const VectorX&);
template SparseMatrix inverse_viscosity_matrix<2>(const StressLayout<2>&, const VectorX&);
template SparseMatrix inverse_viscosity_matrix<3>(const StressLayout<3>&, const VectorX&);

}  // namespace monolith
