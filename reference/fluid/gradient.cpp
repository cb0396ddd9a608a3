#include "reference/fluid/gradient.hpp"
#include "reference/core/parallel.hpp"

#include <vector>

namespace monolith {

template <int Dim>
SparseMatrix gradient_matrix(const MacGrid<Dim>& grid) {
  const double inv_dx = 1.0 / grid.dx();
  std::vector<Triplet> triplets;
  triplets.reserve(2 * grid.num_faces());
  // one row per face: +1/dx on the plus cell, -1/dx on the minus cell (outside cells omitted)
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    const int plus = grid.face_cell_plus(axis, coord);
    const int minus = grid.face_cell_minus(axis, coord);
    if (plus >= 0) triplets.emplace_back(f, plus, inv_dx);
    if (minus >= 0) triplets.emplace_back(f, minus, -inv_dx);
  }
  SparseMatrix g(grid.num_faces(), grid.num_cells());
  g.setFromTriplets(triplets.begin(), triplets.end());
  return g;
}

template <int Dim>
VectorX apply_gradient(const MacGrid<Dim>& grid, const VectorX& p) {
  const double inv_dx = 1.0 / grid.dx();
  VectorX y(grid.num_faces());
  // difference across each face
#pragma omp parallel for schedule(static) num_threads(team_threads(grid.num_faces()))
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    const int plus = grid.face_cell_plus(axis, coord);
    const int minus = grid.face_cell_minus(axis, coord);
    y[f] = ((plus >= 0 ? p[plus] : 0.0) - (minus >= 0 ? p[minus] : 0.0)) * inv_dx;
  }
  return y;
}

template <int Dim>
VectorX apply_gradient_transpose(const MacGrid<Dim>& grid, const VectorX& u) {
  const double inv_dx = 1.0 / grid.dx();
  VectorX y(grid.num_cells());
  // gather per cell (race free): +u on the cell's minus-side faces (the cell is their plus
  // cell), -u on its plus-side faces
#pragma omp parallel for schedule(static) num_threads(team_threads(grid.num_cells()))
  for (int c = 0; c < grid.num_cells(); ++c) {
    const VecI<Dim> cc = grid.cell_coord(c);
    double sum = 0.0;
    for (int a = 0; a < Dim; ++a) {
      VecI<Dim> upper = cc;
      upper[a] += 1;
      if (grid.periodic(a)) upper = grid.wrap_cell(upper);
      sum += u[grid.face_index(a, cc)] - u[grid.face_index(a, upper)];
    }
    y[c] = sum * inv_dx;
  }
  return y;
}

template SparseMatrix gradient_matrix<2>(const MacGrid<2>&);
template SparseMatrix gradient_matrix<3>(const MacGrid<3>&);
template VectorX apply_gradient<2>(const MacGrid<2>&, const VectorX&);
template VectorX apply_gradient<3>(const MacGrid<3>&, const VectorX&);
template VectorX apply_gradient_transpose<2>(const MacGrid<2>&, const VectorX&);
template VectorX apply_gradient_transpose<3>(const MacGrid<3>&, const VectorX&);

}  // namespace monolith
