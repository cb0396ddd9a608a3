// The solids' union kept per body (SolidWeightsScratch::union_in_parts, PartsUnionPhi) against
// the dense union of solid_weights, and the body-coupling operator restricted to the system's
// columns against the full one: the same bits (issue 20, Fig. 17's basin and shells).
#include <catch2/catch.hpp>
#include <omp.h>

#include <cstring>
#include <memory>
#include <vector>

#include "reference/coupling/coupling.hpp"
#include "reference/grid/boxed_union_phi.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::all_boundaries;
using monolith::testing::TestBall;
using monolith::testing::TestBox;
using monolith::testing::unit_grid;
using monolith::testing::same_bits;
using monolith::testing::differing;

namespace {

template <int Dim>
CouplingBody<Dim> ball(const Vec<Dim>& c, double r, bool two_way = true) {
  CouplingBody<Dim> b;
  b.shape = std::make_shared<TestBall<Dim>>(c, r);
  b.center = c;
  b.two_way = two_way;
  return b;
}

template <int Dim>
CouplingBody<Dim> slab(const Vec<Dim>& c, const Vec<Dim>& half) {
  CouplingBody<Dim> b;
  b.shape = std::make_shared<TestBox<Dim>>(c, half);
  b.center = c;
  b.two_way = false;
  return b;
}

/// A large fixed body (more than half the lattice, as Fig. 17's basin) and two moving balls, one
/// reaching into it and one crossing the domain's edge, over three poses: per call the weights
/// kept per part equal those of a dense call bit for bit, the union at every lattice point too.
template <int Dim>
void check_parts(int n, double shrink_cells) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const auto boundary = all_boundaries<Dim>(BoundaryType::wall);
  const double shrink = shrink_cells * grid.dx();
  SolidWeights<Dim> kept;
  SolidWeightsScratch<Dim> scratch;
  scratch.fixed = {1, 0, 0};
  scratch.parts = false;
  scratch.stress = false;
  scratch.union_in_parts = true;
  for (int pose = 0; pose < 4; ++pose) {
    Vec<Dim> basin_half = Vec<Dim>::Constant(0.45);
    basin_half[1] = 0.3;
    Vec<Dim> basin_centre = Vec<Dim>::Constant(0.5);
    basin_centre[1] = 0.3;
    const double t = 0.07 * pose;
    const std::vector<CouplingBody<Dim>> bodies = {
        slab<Dim>(basin_centre, basin_half),
        ball<Dim>(Vec<Dim>::Constant(0.3 + (pose == 3 ? 0.0 : t)) +
                      Vec<Dim>::LinSpaced(0.011, 0.029),
                  0.13),
        ball<Dim>(Vec<Dim>::Constant(0.85 - 0.5 * t), 0.12)};
    SolidWeights<Dim> dense;
    SolidWeightsScratch<Dim> dense_scratch;
    dense_scratch.parts = false;
    dense_scratch.stress = false;
    solid_weights<Dim>(grid, bodies, {}, boundary, shrink, dense, dense_scratch);
    REQUIRE(dense.lattice_phi.size() == lattice.size());
    kept.lattice_phi = VectorX();  // left as it was: empty
    // pose 3: another W_F^u buffer (other data) instead of the kept one: every face made again
    if (pose == 3) {
      VectorX other = VectorX::Constant(grid.num_faces(), 7.0);
      kept.fluid_face.swap(other);
    }
    const bool incremental = scratch.kept && pose != 3;
    solid_weights<Dim>(grid, bodies, {}, boundary, shrink, kept, scratch);
    REQUIRE(scratch.union_parts.valid());
    CHECK(scratch.kept);
    // the calls after the first visit only the faces near the moving balls
    if (incremental) {
      CHECK(scratch.touched.size() > 0);
      CHECK(static_cast<int>(scratch.touched.size()) < grid.num_faces() / 2);
    } else {
      CHECK(scratch.touched.empty());
    }
    CHECK(kept.lattice_phi.size() == 0);
    REQUIRE(kept.body_face.size() == bodies.size());
    for (std::size_t i = 0; i < bodies.size(); ++i)
      CHECK(differing(kept.body_face[i], dense.body_face[i]) == 0);
    CHECK(differing(kept.fluid_face, dense.fluid_face) == 0);
    CHECK(kept.fluid_stress.size() == 0);
    // the union's classes' box
    CHECK(scratch.signs.lo == dense_scratch.signs.lo);
    CHECK(scratch.signs.hi == dense_scratch.signs.hi);
    CHECK(scratch.signs.any_negative());
    // every lattice point: the value's bits and its sign
    long value_differs = 0, sign_differs = 0;
    for (int k = 0; k < lattice.size(); ++k) {
      value_differs += !same_bits(scratch.union_parts(k), dense.lattice_phi[k]);
      sign_differs += scratch.union_parts.negative(k) != (dense.lattice_phi[k] < 0.0);
    }
    CHECK(value_differs == 0);
    CHECK(sign_differs == 0);
  }
  // W_F^s wanted: the union is still kept per part (test_stress_weights_parts.cpp compares
  // W_F^s with the dense union's), with two fixed bodies written densely
  scratch.stress = true;
  const std::vector<CouplingBody<Dim>> one = {ball<Dim>(Vec<Dim>::Constant(0.5), 0.2)};
  scratch.fixed = {0};
  kept.lattice_phi = VectorX();
  solid_weights<Dim>(grid, one, {}, boundary, shrink, kept, scratch);
  CHECK(scratch.union_parts.valid());
  CHECK(kept.lattice_phi.size() == 0);
  const std::vector<CouplingBody<Dim>> two = {ball<Dim>(Vec<Dim>::Constant(0.3), 0.1, false),
                                              ball<Dim>(Vec<Dim>::Constant(0.7), 0.1, false)};
  scratch.fixed = {1, 1};
  solid_weights<Dim>(grid, two, {}, boundary, shrink, kept, scratch);
  CHECK_FALSE(scratch.union_parts.valid());
  CHECK(kept.lattice_phi.size() == lattice.size());
}

/// (band23) Only moving bodies (no body that never moves): the first call, and a call given
/// another W_F^u buffer (7 everywhere), write W_F^u = 1 on every face and run the overlap rule on
/// the bodies' near faces only; the calls in between are incremental. Two balls overlap (the
/// rule scales their parts there) and one crosses the domain's edge. Per call every output
/// equals the dense call's bits; on 1 and 3 threads.
template <int Dim>
void check_moving_only(int n, int threads) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const auto boundary = all_boundaries<Dim>(BoundaryType::wall);
  const double shrink = 0.01 * grid.dx();
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  SolidWeights<Dim> kept;
  SolidWeightsScratch<Dim> scratch;
  scratch.fixed = {0, 0};
  scratch.parts = false;
  scratch.stress = false;
  scratch.union_in_parts = true;
  long scaled = 0;
  for (int pose = 0; pose < 4; ++pose) {
    INFO("pose " << pose << ", " << threads << " threads");
    const double t = 0.06 * pose;
    const std::vector<CouplingBody<Dim>> bodies = {
        ball<Dim>(Vec<Dim>::Constant(0.4 + t) + Vec<Dim>::LinSpaced(0.011, 0.029), 0.16),
        ball<Dim>(Vec<Dim>::Constant(0.55 + t), 0.14)};
    SolidWeights<Dim> dense;
    SolidWeightsScratch<Dim> dense_scratch;
    dense_scratch.parts = false;
    dense_scratch.stress = false;
    solid_weights<Dim>(grid, bodies, {}, boundary, shrink, dense, dense_scratch);
    if (pose == 2) {
      VectorX other = VectorX::Constant(grid.num_faces(), 7.0);
      kept.fluid_face.swap(other);
    }
    solid_weights<Dim>(grid, bodies, {}, boundary, shrink, kept, scratch);
    CHECK(scratch.kept);
    // every call visits the faces near the balls only (the first too: near_only)
    CHECK(scratch.touched.size() > 0);
    CHECK(static_cast<int>(scratch.touched.size()) < grid.num_faces() / 2);
    REQUIRE(kept.body_face.size() == bodies.size());
    for (std::size_t i = 0; i < bodies.size(); ++i)
      CHECK(differing(kept.body_face[i], dense.body_face[i]) == 0);
    CHECK(differing(kept.fluid_face, dense.fluid_face) == 0);
    // the overlap: faces solid exactly (the rule scaled them), and faces of W_F^u = 1 exist
    for (int f = 0; f < grid.num_faces(); ++f)
      scaled += dense.body_face[0][f] > 0.0 && dense.body_face[1][f] > 0.0 &&
                dense.fluid_face[f] == 0.0;
    CHECK((kept.fluid_face.array() == 1.0).count() > grid.num_faces() / 2);
  }
  CHECK(scaled > 0);
  omp_set_num_threads(saved);
}

/// The operator restricted to listed cells and without stress, and to listed stress DOFs: the
/// listed cells' and DOFs' columns of the full operator, bit for bit, and nothing else.
template <int Dim>
void check_restricted_operator() {
  const MacGrid<Dim> grid = unit_grid<Dim>(12);
  const std::vector<CouplingBody<Dim>> bodies = {
      ball<Dim>(Vec<Dim>::Constant(0.4) + Vec<Dim>::LinSpaced(0.01, 0.03), 0.2),
      ball<Dim>(Vec<Dim>::Constant(0.7), 0.15, false)};
  const SolidWeights<Dim> w = solid_weights<Dim>(grid, bodies, {},
                                                 all_boundaries<Dim>(BoundaryType::wall),
                                                 0.01 * grid.dx());
  for (const BodyGroup group : {BodyGroup::two_way, BodyGroup::one_way}) {
    const BodyCouplingOperator<Dim> full(grid, bodies, w, group);
    // every third cell, increasing
    std::vector<int> cells;
    for (int c = 0; c < grid.num_cells(); c += 3) cells.push_back(c);
    typename BodyCouplingOperator<Dim>::Columns wanted;
    wanted.cells = &cells;
    wanted.stress = false;
    const BodyCouplingOperator<Dim> part(grid, bodies, w, group, wanted);
    const auto all = full.pressure_columns();
    const auto some = part.pressure_columns();
    std::size_t expected = 0, matched = 0;
    std::size_t j = 0;
    for (const auto& c : all) {
      if (c.index % 3 != 0) continue;
      ++expected;
      if (j < some.size() && some[j].body == c.body && some[j].index == c.index &&
          some[j].row == c.row) {
        bool same = true;
        for (int r = 0; r < kBodyDofs<Dim>; ++r)
          same = same && same_bits(some[j].column[r], c.column[r]);
        matched += same;
      }
      ++j;
    }
    CHECK(expected > 0);
    CHECK(some.size() == expected);
    CHECK(matched == expected);
    CHECK(part.stress_columns().empty());
    CHECK_FALSE(full.stress_columns().empty());
    // J_s at every third stress DOF (listed, increasing): those columns of the full operator
    std::vector<int> dofs;
    for (int k = 0; k < full.num_stress_dofs(); k += 3) dofs.push_back(k);
    wanted.stress = true;
    wanted.stress_dofs = &dofs;
    const BodyCouplingOperator<Dim> listed(grid, bodies, w, group, wanted);
    const auto all_s = full.stress_columns();
    const auto some_s = listed.stress_columns();
    std::size_t expected_s = 0, matched_s = 0, k = 0;
    for (const auto& c : all_s) {
      if (c.index % 3 != 0) continue;
      ++expected_s;
      if (k < some_s.size() && some_s[k].body == c.body && some_s[k].index == c.index &&
          some_s[k].row == c.row) {
        bool same = true;
        for (int r = 0; r < kBodyDofs<Dim>; ++r)
          same = same && same_bits(some_s[k].column[r], c.column[r]);
        matched_s += same;
      }
      ++k;
    }
    CHECK(expected_s > 0);
    CHECK(expected_s < all_s.size());
    CHECK(some_s.size() == expected_s);
    CHECK(matched_s == expected_s);
    wanted.stress_dofs = nullptr;
    // the same with every cell listed: the full operator's surface
    std::vector<int> every(grid.num_cells());
    for (int c = 0; c < grid.num_cells(); ++c) every[c] = c;
    wanted.cells = &every;
    wanted.stress = true;
    const BodyCouplingOperator<Dim> whole(grid, bodies, w, group, wanted);
    CHECK(whole.surface_cells() == full.surface_cells());
    CHECK(whole.surface_stress() == full.surface_stress());
  }
}

}  // namespace

TEST_CASE("solid weights with the union kept per body equal the dense union's bits",
          "[unit][dense-reference]") {
  check_parts<2>(40, 0.01);
  check_parts<2>(24, 0.0);
  check_parts<3>(24, 0.01);
}

TEST_CASE("solid weights of moving bodies only: W_F^u = 1 written whole and the rule on the near "
          "faces, the dense union's bits (band23)",
          "[unit]") {
  for (int threads : {1, 3}) {
    check_moving_only<2>(40, threads);
    check_moving_only<3>(20, threads);
  }
}

TEST_CASE("the body-coupling operator restricted to listed cells keeps their columns' bits",
          "[unit]") {
  check_restricted_operator<2>();
  check_restricted_operator<3>();
}
