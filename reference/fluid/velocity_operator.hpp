#pragma once
/// \file velocity_operator.hpp
/// The factors of the Stokes system of eq. (8) and the velocity-space operator built from them
/// ((P1) and (P3) of docs/preconditioners.md),
/// the pieces of the (tau, p) preconditioner (reference/fluid/stokes_preconditioner.hpp,
/// docs/preconditioners.md).
///
/// The system of eq. (8) / the (tau, p) blocks of eq. (24) is (docs/stokes.md, section 6)
///
///   A = B^T C B + blkdiag(K, 0),   B = [D^T M W_L^s E S_tau^T, G W_L^p S_p^T],
///   C = dt W_F^u P^-1 (W_L^u)^-1 (diagonal, faces),   K = 1/2 N^-1 W^s (stress unknowns),
///
/// with C restricted to the faces where it is positive (no other face enters A). Adding a
/// positive diagonal Pi to the pressure block gives A' = A + blkdiag(0, Pi) = B^T C B + D with
/// D = blkdiag(K, Pi) invertible, and the Woodbury identity
///
///   A'^-1 = D^-1 - D^-1 B^T V^-1 B D^-1,   V = C^-1 + B D^-1 B^T
///         = C^-1 + D^T M W_L^s E K^-1 E^T W_L^s M D + G W_L^p Pi^-1 W_L^p G^T   (restricted)
///
/// turns a solve with A' into one solve with V, the implicit viscosity operator on the face
/// velocities (mass over dt plus the viscous term) with a grad-div term Pi^-1 added (an augmented
/// Lagrangian term). V is SPD and elliptic: geometric multigrid handles it
/// (reference/fluid/mac_hierarchy.hpp).

#include <utility>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/fluid/mac_hierarchy.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/fluid/viscosity.hpp"

namespace monolith {

/// B, C and K of the system above, over the unknowns (tau, p) of StokesDofs and the faces with
/// C_f > 0. Built from either back end; both give the same factors (to round-off).
struct StokesFactors {
  int num_stress = 0, num_pressure = 0;
  std::vector<int> face;      ///< the faces with C_f > 0 (increasing global face index)
  VectorX c;                  ///< C_f on those faces
  SparseMatrix b;             ///< B: faces x (n_tau + n_p), row-major
  SparseMatrix b_transpose;   ///< B^T: (n_tau + n_p) x faces, row-major
  SparseMatrix compliance;    ///< K = 1/2 N^-1 W^s: n_tau square, blocks of 1 (and 2 in 3D reduced)
  /// K without the W_F^s floor (the system's own A11 term); empty when the floor changes nothing
  /// (floor 0, or no W_F^s strictly between 0 and it): then `compliance` is exact.
  SparseMatrix compliance_exact;
  /// W_F^s of each stress unknown (in the 3D reduced form the smaller of its own and that of its
  /// cell's eliminated diagonal DOF): small on the stress DOFs cut by a solid.
  VectorX stress_fluid;
  std::vector<int> pressure_cell;  ///< the cell of each pressure unknown
  VectorX pressure_liquid;         ///< W_L^p of each pressure unknown
  VectorX pressure_viscosity;      ///< eta at the cell of each pressure unknown (0 if none)
  /// The stress elements (for smoother patches): per element the stress unknowns it groups (the
  /// two diagonal unknowns of a cell in the 3D reduced form, else one), its StressGrid component
  /// and lattice coordinate.
  std::vector<std::vector<int>> element_unknowns;
  std::vector<int> element_component;
  std::vector<VecI<3>> element_coord;
  /// The unknowns in the matrix-free operator's SOR sweep order (stokes_sweep_order): filled by
  /// the explicit back end's stokes_factors, so that the block preconditioner sweeps the explicit
  /// A in that order rather than in index order (the same preconditioner on both back ends,
  /// docs/preconditioners.md section 24). Empty: the operator's own order.
  std::vector<int> sweep_order;
  int size() const { return num_stress + num_pressure; }

  StokesFactors() = default;
  StokesFactors(const StokesFactors&) = default;
  StokesFactors& operator=(const StokesFactors&) = default;
  /// Moves that move: Eigen 3.4's SparseMatrix has no move constructor, so the implicit one
  /// copied B, B^T and K (about 130 MB and 33k fresh pages on the 64^3 tank, on every
  /// `StokesPreconditioner(grid, a, std::move(f))`; docs/preconditioners.md section 41). The
  /// members are swapped (a member added here must be added to swap_from); `other` is left
  /// empty (construction) or with the target's old content (assignment).
  StokesFactors(StokesFactors&& other) noexcept { swap_from(other); }
  StokesFactors& operator=(StokesFactors&& other) noexcept {
    if (this != &other) swap_from(other);
    return *this;
  }

 private:
  void swap_from(StokesFactors& o) noexcept {
    std::swap(num_stress, o.num_stress);
    std::swap(num_pressure, o.num_pressure);
    face.swap(o.face);
    c.swap(o.c);
    b.swap(o.b);
    b_transpose.swap(o.b_transpose);
    compliance.swap(o.compliance);
    compliance_exact.swap(o.compliance_exact);
    stress_fluid.swap(o.stress_fluid);
    pressure_cell.swap(o.pressure_cell);
    pressure_liquid.swap(o.pressure_liquid);
    pressure_viscosity.swap(o.pressure_viscosity);
    element_unknowns.swap(o.element_unknowns);
    element_component.swap(o.element_component);
    element_coord.swap(o.element_coord);
    sweep_order.swap(o.sweep_order);
  }
};

/// K = 1/2 N^-1 W^s over the active stress unknowns (eq. (24)'s A11 term; docs/stokes.md): per
/// unknown 1/2 m W_F^s W_L^s / eta of its StressGrid DOF, in the reduced form plus that of the
/// eliminated DOF of its cell, which also couples the cell's diagonal unknowns (3D). With
/// min_fluid_fraction > 0, W_F^s is read as max(W_F^s, min_fluid_fraction) (for the
/// preconditioner only: docs/preconditioners.md, "stiff stress DOFs").
template <int Dim>
SparseMatrix stress_compliance(const StressLayout<Dim>& layout, const StokesDofs& dofs,
                               const StokesWeights& w, double min_fluid_fraction = 0.0);

/// The factors from the explicit back end's named matrices (B = [D^T M W_L^s E S_tau^T,
/// G W_L^p S_p^T], C = dt W_F^u P^-1 (W_L^u)^-1), K from the weights.
template <int Dim>
StokesFactors stokes_factors(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                             const StokesWeights& w, const StokesDofs& dofs, double dt,
                             const ExplicitStokesSystem& system, double min_fluid_fraction = 0.0);

/// The factors from the matrix-free operator's stencils (its columns of B and face
/// coefficients C), K from the weights. Costs in proportion to the active unknowns.
template <int Dim>
StokesFactors stokes_factors(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                             const StokesWeights& w, const StokesDofs& dofs, double dt,
                             const MatrixFreeStokesOperator<Dim>& op, double min_fluid_fraction = 0.0);

/// V = C^-1 + B D^-1 B^T over the faces of `f`, D = blkdiag(K, diag(penalty)) (penalty = the
/// diagonal Pi added to the pressure block, one positive entry per pressure unknown), assembled
/// row by row (each row by one thread, in a fixed order: deterministic). SPD.
/// `kinv`: K^-1 as block_diagonal_inverse(f.compliance) gives it, when the caller has it already
/// (null: computed here).
SparseMatrix velocity_operator(const StokesFactors& f, const VectorX& penalty, const SparseMatrix* kinv = nullptr);

/// The inverse of a block-diagonal SPD matrix whose blocks have at most 3 unknowns (K).
SparseMatrix block_diagonal_inverse(const SparseMatrix& k);

/// The finest-level extra smoother patches of the velocity operator: one per off-diagonal stress
/// element (a diagonal one acts on the faces of its cell, which have a cell patch already), its
/// faces (numbered as f.face), positioned at the element's lattice coordinate, kind = component.
template <int Dim>
ExtraPatches<Dim> stress_element_patches(const StokesFactors& f);

}  // namespace monolith
