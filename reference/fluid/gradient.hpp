#pragma once
/// \file gradient.hpp
/// The discrete pressure gradient G of eq. (8) on the MAC grid, and its negative transpose, the
/// divergence.

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

/// eq. (8): G, num_faces x num_cells. Row f (a face normal to axis a) is
///   (G p)_f = (p_plus - p_minus) / dx,
/// with p_plus the cell on the +e_a side (MacGrid::face_cell_plus) and p_minus the cell on the
/// -e_a side (face_cell_minus), wrapped on periodic axes. On a boundary face the cell outside the
/// domain is omitted: for an `open` boundary that is the air pressure 0 outside; on a `wall` the
/// face has W_F^u = 0 so its row never contributes. Sign: G approximates +grad; the divergence
/// is -G^T (so G^T G is positive semi-definite).
template <int Dim>
SparseMatrix gradient_matrix(const MacGrid<Dim>& grid);

/// y = G p without forming G (the matrix-free form of eq. (8)); size num_faces.
template <int Dim>
VectorX apply_gradient(const MacGrid<Dim>& grid, const VectorX& p);

/// y = G^T u without forming G; size num_cells. (-G^T u is the divergence of u.)
template <int Dim>
VectorX apply_gradient_transpose(const MacGrid<Dim>& grid, const VectorX& u);

}  // namespace monolith
