// MacGrid index arithmetic: faces after periodic wrapping (the rule D's stencil, the coupling's
// face lists and the solid faces share).
#include <catch2/catch.hpp>

#include <cmath>
#include <random>
#include <vector>

#include "reference/grid/box_rows.hpp"
#include "reference/grid/mac_grid.hpp"

using namespace monolith;

TEST_CASE("MacGrid::face_index_or_outside wraps periodic axes and rejects faces outside the domain",
          "[grid]") {
  // 3 x 2 x 4 cells, periodic along axis 0 only
  const MacGrid<3> grid(Vec<3>::Zero(), 0.25, VecI<3>(3, 2, 4), {true, false, false});
  for (int axis = 0; axis < 3; ++axis) {
    const VecI<3> dims = grid.face_dims(axis);
    for (int i = -4; i < dims[0] + 4; ++i)
      for (int j = -1; j <= dims[1]; ++j)
        for (int k = -1; k <= dims[2]; ++k) {
          const VecI<3> f(i, j, k);
          const int got = grid.face_index_or_outside(axis, f);
          const bool outside = j < 0 || j >= dims[1] || k < 0 || k >= dims[2];
          if (outside) {
            CHECK(got == -1);
            continue;
          }
          const int wrapped = ((i % dims[0]) + dims[0]) % dims[0];
          CHECK(got == grid.face_index(axis, VecI<3>(wrapped, j, k)));
        }
  }
  // on the periodic axis the faces normal to it number as many as the cells: face 3 is face 0
  CHECK(grid.face_dims(0)[0] == 3);
  CHECK(grid.face_index_or_outside(0, VecI<3>(3, 1, 2)) == grid.face_index(0, VecI<3>(0, 1, 2)));
  // along a non-periodic axis the last face (cells[a]) is inside, the next one is not
  CHECK(grid.face_index_or_outside(1, VecI<3>(0, 2, 0)) == grid.face_index(1, VecI<3>(0, 2, 0)));
  CHECK(grid.face_index_or_outside(1, VecI<3>(0, 3, 0)) == -1);
}

TEST_CASE("MacGrid::interpolate_velocity is the stencil's sum per component, bit for bit",
          "[grid][unit]") {
  // interpolate_velocity wraps once and divides once per axis for all components; the result must
  // be the sum over stencil() of each face lattice (the transfers' and the advection's weights),
  // also beyond the outermost samples and across a periodic seam
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> coord(-0.3, 1.3);
  for (bool periodic : {false, true}) {
    const MacGrid<3> grid(Vec<3>(0.1, -0.2, 0.05), 0.125, VecI<3>(8, 6, 7),
                          {periodic, false, periodic});
    VectorX u(grid.num_faces());
    for (int f = 0; f < grid.num_faces(); ++f) u[f] = std::sin(0.37 * f) + 0.01 * f;
    int differ = 0;
    for (int n = 0; n < 2000; ++n) {
      Vec<3> x;
      for (int a = 0; a < 3; ++a) x[a] = grid.origin()[a] + coord(rng) * grid.cells()[a] * grid.dx();
      const Vec<3> v = grid.interpolate_velocity(u, x);
      for (int a = 0; a < 3; ++a) {
        std::array<int, 8> idx;
        std::array<double, 8> w;
        grid.stencil(grid.wrap_position(x), MacGrid<3>::face_shift(a), grid.face_dims(a), idx, w);
        double expected = 0.0;
        for (int k = 0; k < 8; ++k) expected += w[k] * u[grid.face_offset(a) + idx[k]];
        differ += v[a] != expected;
        differ += grid.interpolate_face(u, a, x) != expected;
      }
    }
    CHECK(differ == 0);
  }
}

namespace {

/// BoxRows' rows against the box's points listed by a loop over the whole lattice: the same
/// points in the same (index) order, row r at box index r nx. Returns the points visited.
template <int Dim>
long check_box_rows(const VecI<Dim>& dims, const VecI<Dim>& lo, const VecI<Dim>& hi) {
  std::vector<int> expected;
  std::vector<int> expected_box;
  const bool empty = (lo.array() > hi.array()).any();
  for (int k = 0; k < dims.prod(); ++k) {
    const VecI<Dim> c = lattice_coord<Dim>(k, dims);
    if (empty || (c.array() < lo.array()).any() || (c.array() > hi.array()).any()) continue;
    expected.push_back(k);
    expected_box.push_back(lattice_index<Dim>(c - lo, (hi - lo + VecI<Dim>::Ones()).eval()));
  }
  const BoxRows<Dim> box(dims, lo, hi);
  std::vector<int> got, got_box;
  for (int r = 0; r < box.rows(); ++r) {
    CHECK(box.first(r) == lattice_index<Dim>(box.start(r), dims));
    for (int x = 0; x < box.nx; ++x) {
      got.push_back(box.first(r) + x);
      got_box.push_back(box.box_first(r) + x);
    }
  }
  CHECK(got == expected);
  CHECK(got_box == expected_box);
  return static_cast<long>(got.size());
}

}  // namespace

TEST_CASE("BoxRows visits a box's points row by row in the lattice's order (band20)", "[grid]") {
  CHECK(check_box_rows<2>(VecI<2>(7, 5), VecI<2>(2, 1), VecI<2>(5, 3)) == 12);
  CHECK(check_box_rows<2>(VecI<2>(7, 5), VecI<2>(0, 0), VecI<2>(6, 4)) == 35);
  CHECK(check_box_rows<3>(VecI<3>(6, 4, 5), VecI<3>(1, 0, 2), VecI<3>(3, 3, 4)) == 36);
  CHECK(check_box_rows<3>(VecI<3>(6, 4, 5), VecI<3>(4, 2, 4), VecI<3>(4, 2, 4)) == 1);
  // empty boxes: no rows
  CHECK(check_box_rows<3>(VecI<3>(6, 4, 5), VecI<3>(3, 2, 1), VecI<3>(2, 3, 4)) == 0);
  CHECK(BoxRows<2>(VecI<2>(7, 5), VecI<2>(0, 4), VecI<2>(6, 3)).rows() == 0);
}
