#pragma once
/// \file viscosity.hpp
/// The stress unknowns of eq. (8) and the viscosity matrix N, in the full form (every component
/// of the symmetric tensor an unknown) and the reduced form of section 4.4.2 (the trace
/// eliminated, H merged into N). docs/stokes.md derives every factor.
///
/// Factors. Discretising eq. (7) with one control volume dx^Dim per stress DOF and the symmetric
/// tensor stored once per pair (StressGrid), ||tau||_F^2 = sum_k m_k tau_k^2 with the
/// multiplicity m_k (1 diagonal, 2 off-diagonal, StressGrid::multiplicity). Writing
/// M = diag(m_k) (num_stress_dofs square) the stress term of eq. (8) is
///     dt/2 ||tau||^2_{N^-1 W^s} / 2 = dt/4 tau^T N^-1 W^s tau,   N^-1 = M diag(1/eta),
/// i.e. N = diag(eta_k / m_k) in the full form, and the optimum is tau = 2 eta D u (eq. (5)).
///
/// Reduced form (section 4.4.2). The optimum of eq. (8) with pressure is traceless wherever the
/// cell has a pressure DOF (sum_a (D u)_aa is the weighted divergence there). The unknowns are
/// all components except the last diagonal one (2D: xx, xy; 3D: xx, yy, xy, xz, yz) and
///     tau_full = E tau,   (E tau)_{last diagonal} = -(sum of the other diagonal unknowns),
/// so the reduced problem is eq. (8) restricted to range(E): N^-1 <- E^T N^-1 E. Per cell the
/// diagonal unknowns form a block (all diagonal DOFs of a cell share eta and W^s):
///     2D: N^-1 = 2/eta                  (N = eta/2; optimum tau_xx = eta (D_xx - D_yy))
///     3D: N^-1 = [2 1; 1 2] / eta       (N = eta/3 [2 -1; -1 2]; optimum
///         tau_xx + tau_yy/2 = eta (D_xx - D_zz), tau_xx/2 + tau_yy = eta (D_yy - D_zz))
/// which is the paper's 1/2 H tau = N D u with H merged into N (N <- H^-1 N). Off-diagonal
/// unknowns keep N = eta/2.

#include <vector>

#include "reference/core/common.hpp"
#include "reference/grid/stress_grid.hpp"

namespace monolith {

/// Full: every component of StressGrid is an unknown. Reduced (section 4.4.2): the trace is
/// eliminated (2D unknowns tau_xx, tau_xy; 3D tau_xx, tau_yy, tau_xy, tau_xz, tau_yz) and H is
/// merged into N.
enum class StressForm { full, reduced };

/// The unknown layout of a form: which StressGrid components are unknowns and the numbering of
/// the unknown vector (component blocks in StressGrid component order, skipping the eliminated
/// one, each with StressGrid's per-component numbering).
template <int Dim>
class StressLayout {
 public:
  StressLayout() = default;
  StressLayout(const StressGrid<Dim>& stress, StressForm form);

  int num_unknowns() const { return offset_.back(); }
  StressForm form() const { return form_; }
  const StressGrid<Dim>& grid() const { return stress_; }

  /// Number of unknown components (3 / 6 full, 2 / 5 reduced).
  int num_components() const { return static_cast<int>(component_.size()); }
  /// StressGrid component of unknown component j.
  int component(int j) const { return component_[j]; }
  /// First unknown of unknown component j.
  int offset(int j) const { return offset_[j]; }
  /// The eliminated StressGrid component (Dim - 1, the last diagonal one) or -1 (full form).
  int eliminated_component() const { return form_ == StressForm::reduced ? Dim - 1 : -1; }
  /// Unknown component j and StressGrid DOF index of unknown i.
  int component_of_unknown(int i) const;
  int dof_of_unknown(int i) const;
  /// Unknown of StressGrid DOF `dof`, -1 for DOFs of the eliminated component.
  int unknown_of_dof(int dof) const;

  /// E: num_stress_dofs (all components) x num_unknowns, tau_full = E tau_unknown. Identity in
  /// the full form; in the reduced form the eliminated diagonal component is minus the sum of the
  /// other diagonal unknowns of the same cell.
  SparseMatrix expansion() const;
  /// tau_full = E tau (without forming E).
  VectorX expand(const VectorX& tau) const;
  /// E^T s for a stress-DOF vector s.
  VectorX expand_transpose(const VectorX& s) const;

 private:
  StressGrid<Dim> stress_;
  StressForm form_ = StressForm::full;
  std::vector<int> component_;
  std::vector<int> offset_{0};
  std::vector<int> unknown_of_component_;  ///< per StressGrid component: unknown component or -1
};

/// M = diag(StressGrid::multiplicity): num_stress_dofs x num_stress_dofs, stored as its diagonal
/// (1 on diagonal components, 2 on off-diagonal ones).
template <int Dim>
VectorX stress_multiplicity(const StressGrid<Dim>& stress);

/// eq. (8) / section 4.4.2: N, num_unknowns x num_unknowns, SPD where eta > 0; diagonal
/// (eta_k / m_k) in the full form, block diagonal (per cell, over the diagonal unknowns) in the
/// reduced form with H merged in (N <- H^-1 N), see the file comment. `eta` is the dynamic
/// viscosity per StressGrid DOF (Pa s, all components). Unknowns with eta = 0 get a zero row and
/// column (they are never active).
template <int Dim>
SparseMatrix viscosity_matrix(const StressLayout<Dim>& layout, const VectorX& eta);

/// N^-1 in the same layout: E^T M diag(1/eta) E (1/eta read as 0 where eta = 0), the matrix the
/// 1/2 N^-1 W^s term of A11 (eq. (24)) needs.
template <int Dim>
SparseMatrix inverse_viscosity_matrix(const StressLayout<Dim>& layout, const VectorX& eta);

}  // namespace monolith
