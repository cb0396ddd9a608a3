#include "reference/fluid/deformation_rate.hpp"

#include <vector>

namespace monolith {

namespace {
/// Global index of the face normal to axis with coordinate f after periodic wrapping, or -1 if
/// it lies outside the domain (treated as zero velocity by the caller).
template <int Dim>
int face_index_or_outside(const MacGrid<Dim>& grid, int axis, VecI<Dim> f) {
  const VecI<Dim> dims = grid.face_dims(axis);
  for (int a = 0; a < Dim; ++a) {
    if (grid.periodic(a)) f[a] = ((f[a] % dims[a]) + dims[a]) % dims[a];
    if (f[a] < 0 || f[a] >= dims[a]) return -1;
  }
  return grid.face_index(axis, f);
}
}  // namespace

template <int Dim>
SparseMatrix deformation_rate_matrix(const StressGrid<Dim>& stress) {
  const MacGrid<Dim>& grid = stress.grid();
  const double inv_dx = 1.0 / grid.dx();
  std::vector<Triplet> triplets;
  triplets.reserve(static_cast<size_t>(stress.num_dofs()) * 4);
  auto add = [&](int row, int axis, const VecI<Dim>& f, double w) {
    const int col = face_index_or_outside(grid, axis, f);
    if (col >= 0) triplets.emplace_back(row, col, w);  // faces outside: zero velocity
  };
  for (int row = 0; row < stress.num_dofs(); ++row) {
    const auto [k, c] = stress.coord(row);
    const auto [a, b] = StressGrid<Dim>::component_axes(k);
    if (a == b) {
      // diagonal: du_a/da across the cell
      add(row, a, c + unit_offset<Dim>(a), inv_dx);
      add(row, a, c, -inv_dx);
    } else {
      // off-diagonal: 1/2 (du_a/db + du_b/da) from the four faces around the node/edge
      add(row, a, c, 0.5 * inv_dx);
      add(row, a, c - unit_offset<Dim>(b), -0.5 * inv_dx);
      add(row, b, c, 0.5 * inv_dx);
      add(row, b, c - unit_offset<Dim>(a), -0.5 * inv_dx);
    }
  }
  SparseMatrix d(stress.num_dofs(), grid.num_faces());
  d.setFromTriplets(triplets.begin(), triplets.end());
  return d;
}

template <int Dim>
SparseMatrix deformation_rate_matrix(const MacGrid<Dim>& grid) {
  return deformation_rate_matrix(StressGrid<Dim>(grid));
}

template SparseMatrix deformation_rate_matrix<2>(const StressGrid<2>&);
template SparseMatrix deformation_rate_matrix<3>(const StressGrid<3>&);
template SparseMatrix deformation_rate_matrix<2>(const MacGrid<2>&);
template SparseMatrix deformation_rate_matrix<3>(const MacGrid<3>&);

}  // namespace monolith
