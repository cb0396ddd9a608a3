#pragma once
/// \file deformation_rate.hpp
/// The discrete deformation rate operator D of eq. (8) (D u ~ (grad u + (grad u)^T) / 2), mapping
/// the face velocities of a MacGrid to the stress DOFs of a StressGrid.

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/stress_grid.hpp"

namespace monolith {

/// eq. (8): D, num_stress_dofs x num_faces (rows: StressGrid numbering, all components of the
/// symmetric tensor, diagonal first; columns: MacGrid face numbering, i.e. the velocity vector u).
/// Central differences of the face velocities, sign +: D u approximates +(grad u + grad u^T) / 2.
///  - diagonal row (a, a) at cell c:  (D u)_aa = (u_a(c + e_a) - u_a(c)) / dx, the two faces of
///    the cell normal to a (always inside the domain);
///  - off-diagonal row (a, b) at node/edge n:
///      (D u)_ab = 1/2 [ (u_a(n) - u_a(n - e_b)) / dx + (u_b(n) - u_b(n - e_a)) / dx ],
///    the four faces around n, u_a(f) the velocity of the face normal to a with coordinate f.
/// Periodic axes wrap (the face past the last one is face 0). At a non-periodic domain boundary a
/// face that would lie outside the domain counts as zero velocity: the row simply omits it, so
/// on boundary nodes/edges (StressGrid::is_boundary) (D u)_ab is a one-sided difference against
/// a no-slip exterior. Rows of interior DOFs are exact for velocity fields linear in x.
/// Adjoint: with M = diag(StressGrid::multiplicity), D^T M tau approximates -div tau on the faces
/// (D^T M is minus a divergence, like G^T of gradient.hpp), exactly zero on interior faces for a
/// constant tau.
template <int Dim>
SparseMatrix deformation_rate_matrix(const StressGrid<Dim>& stress);

/// The entries of row `row` of D (eq. (8)), as the stencil above states them: visit(face, value)
/// for each face inside the domain, in the order deformation_rate_matrix inserts them (two faces
/// for a diagonal row, four for an off-diagonal one; on a periodic axis of two cells two of them
/// can be the same face, which the matrix sums). The one spelling of D's stencil, also used where
/// D is applied without being assembled (deformation_rate_transpose_product).
template <int Dim, class Visit>
void for_each_deformation_rate_entry(const StressGrid<Dim>& stress, int row, Visit&& visit) {
  const MacGrid<Dim>& grid = stress.grid();
  const double inv_dx = 1.0 / grid.dx();
  auto add = [&](int axis, const VecI<Dim>& f, double w) {
    const int col = grid.face_index_or_outside(axis, f);
    if (col >= 0) visit(col, w);  // faces outside: zero velocity
  };
  const auto [k, c] = stress.coord(row);
  const auto [a, b] = StressGrid<Dim>::component_axes(k);
  if (a == b) {
    // diagonal: du_a/da across the cell
    add(a, c + unit_offset<Dim>(a), inv_dx);
    add(a, c, -inv_dx);
  } else {
    // off-diagonal: 1/2 (du_a/db + du_b/da) from the four faces around the node/edge
    add(a, c, 0.5 * inv_dx);
    add(a, c - unit_offset<Dim>(b), -0.5 * inv_dx);
    add(b, c, 0.5 * inv_dx);
    add(b, c - unit_offset<Dim>(a), -0.5 * inv_dx);
  }
}

/// The same D for the stress layout of grid (StressGrid(grid)).
template <int Dim>
SparseMatrix deformation_rate_matrix(const MacGrid<Dim>& grid);

}  // namespace monolith
