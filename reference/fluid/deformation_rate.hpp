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

/// The same D for the stress layout of grid (StressGrid(grid)).
template <int Dim>
SparseMatrix deformation_rate_matrix(const MacGrid<Dim>& grid);

}  // namespace monolith
