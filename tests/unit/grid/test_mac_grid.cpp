// MacGrid index arithmetic: faces after periodic wrapping (the rule D's stencil, the coupling's
// face lists and the solid faces share).
#include <catch2/catch.hpp>

#include <cmath>
#include <random>

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
