// G of eq. (8) and its adjoint, the divergence.
#include <catch2/catch.hpp>
#include <random>

#include "reference/fluid/gradient.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

template <int Dim>
MacGrid<Dim> make_grid(bool periodic_x) {
  VecI<Dim> cells;
  for (int a = 0; a < Dim; ++a) cells[a] = 5 + a;  // unequal sizes catch index mix-ups
  std::array<bool, Dim> periodic{};
  periodic[0] = periodic_x;
  return MacGrid<Dim>(Vec<Dim>::Constant(-0.3), 0.125, cells, periodic);
}

/// Weighted divergence written from cell coordinates alone: for every cell, the sum over axes of
/// (W u) on its upper face minus (W u) on its lower face, over dx.
template <int Dim>
VectorX weighted_divergence(const MacGrid<Dim>& grid, const VectorX& w, const VectorX& u) {
  VectorX div(grid.num_cells());
  for (int c = 0; c < grid.num_cells(); ++c) {
    const VecI<Dim> cc = grid.cell_coord(c);
    double s = 0.0;
    for (int a = 0; a < Dim; ++a) {
      VecI<Dim> up = cc;
      up[a] += 1;
      if (grid.periodic(a) && up[a] == grid.cells()[a]) up[a] = 0;
      const int lower = grid.face_index(a, cc), upper = grid.face_index(a, up);
      s += w[upper] * u[upper] - w[lower] * u[lower];
    }
    div[c] = s / grid.dx();
  }
  return div;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("G is num_faces x num_cells and matches its matrix-free forms", "[unit]",
                       ((int Dim), Dim), 2, 3) {
  for (bool periodic : {false, true}) {
    const auto grid = make_grid<Dim>(periodic);
    const SparseMatrix g = gradient_matrix(grid);
    REQUIRE(g.rows() == grid.num_faces());
    REQUIRE(g.cols() == grid.num_cells());
    const VectorX p = random_vector(grid.num_cells(), 1);
    const VectorX u = random_vector(grid.num_faces(), 2);
    CHECK((g * p - apply_gradient(grid, p)).norm() <= 1e-12 * (g * p).norm());
    const VectorX gtu = g.transpose() * u;
    CHECK((gtu - apply_gradient_transpose(grid, u)).norm() <= 1e-12 * gtu.norm());
  }
}

TEMPLATE_TEST_CASE_SIG("adjointness <G p, W u> = -<p, div_W u>", "[property]", ((int Dim), Dim), 2,
                       3) {
  for (bool periodic : {false, true}) {
    const auto grid = make_grid<Dim>(periodic);
    const SparseMatrix g = gradient_matrix(grid);
    for (unsigned seed = 0; seed < 5; ++seed) {
      const VectorX p = random_vector(grid.num_cells(), 10 + seed);
      const VectorX u = random_vector(grid.num_faces(), 20 + seed);
      const VectorX w = (random_vector(grid.num_faces(), 30 + seed).array() + 1.0) * 0.5;
      const double lhs = (g * p).dot(w.cwiseProduct(u));
      const double rhs = -p.dot(weighted_divergence(grid, w, u));
      REQUIRE(lhs == Approx(rhs).epsilon(1e-12).margin(1e-12));
    }
  }
}

TEMPLATE_TEST_CASE_SIG("G of a linear field is its exact gradient on interior faces", "[unit]",
                       ((int Dim), Dim), 2, 3) {
  for (bool periodic : {false, true}) {
    const auto grid = make_grid<Dim>(periodic);
    Vec<Dim> slope;
    for (int a = 0; a < Dim; ++a) slope[a] = 0.7 - 1.3 * a;
    VectorX p(grid.num_cells());
    for (int c = 0; c < grid.num_cells(); ++c)
      p[c] = 2.0 + slope.dot(grid.cell_center(grid.cell_coord(c)));
    const VectorX gp = apply_gradient(grid, p);
    int checked = 0;
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, coord] = grid.face_coord(f);
      // interior faces (on a periodic axis: not the seam, where the linear field jumps)
      if (grid.is_boundary_face(axis, coord) || (grid.periodic(axis) && coord[axis] == 0)) continue;
      REQUIRE(gp[f] == Approx(slope[axis]).epsilon(1e-12));
      ++checked;
    }
    CHECK(checked > grid.num_cells());
    // a constant field has zero gradient everywhere on a fully periodic axis and inside
    const VectorX gc = apply_gradient(grid, VectorX::Constant(grid.num_cells(), 3.0));
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, coord] = grid.face_coord(f);
      if (!grid.is_boundary_face(axis, coord)) REQUIRE(gc[f] == 0.0);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("open boundary faces see zero pressure outside", "[unit]", ((int Dim), Dim),
                       2, 3) {
  const auto grid = make_grid<Dim>(false);
  const VectorX p = VectorX::Constant(grid.num_cells(), 4.0);
  const VectorX gp = apply_gradient(grid, p);
  const int lower = grid.face_index(0, VecI<Dim>::Zero());
  VecI<Dim> top = VecI<Dim>::Zero();
  top[0] = grid.cells()[0];
  const int upper = grid.face_index(0, top);
  CHECK(gp[lower] == Approx(4.0 / grid.dx()));
  CHECK(gp[upper] == Approx(-4.0 / grid.dx()));
}
