// The solids' union level set kept in the bodies' box (reference/grid/boxed_union_phi.hpp): every
// lattice point reads the bits of solid_weights' dense union (issue 20).
#include <catch2/catch.hpp>

#include <cstring>
#include <limits>
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

namespace {

template <int Dim>
CouplingBody<Dim> ball(const Vec<Dim>& c, double r) {
  CouplingBody<Dim> b;
  b.shape = std::make_shared<TestBall<Dim>>(c, r);
  b.center = c;
  return b;
}

template <int Dim>
CouplingBody<Dim> box(const Vec<Dim>& c, double size) {
  CouplingBody<Dim> b;
  b.shape = std::make_shared<TestBox<Dim>>(c, Vec<Dim>::LinSpaced(0.7 * size, size));
  b.center = c;
  return b;
}

/// Every lattice point of the boxed union against the dense one, bit for bit; returns the number
/// of stored values.
template <int Dim>
Eigen::Index check_bits(int n, const std::vector<CouplingBody<Dim>>& bodies, double shrink_cells) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const double shrink = shrink_cells * grid.dx();
  const SolidWeights<Dim> w =
      solid_weights<Dim>(grid, bodies, {}, all_boundaries<Dim>(BoundaryType::wall), shrink);
  std::vector<Box<Dim>> bounds;
  for (const auto& b : bodies) bounds.push_back(b.shape->bounds());
  BoxedUnionPhi<Dim> boxed;
  REQUIRE(boxed.assign(lattice, bounds, 2.0 * grid.dx(), shrink, w.lattice_phi));
  REQUIRE(boxed.valid());
  long differ = 0, outside = 0;
  for (int k = 0; k < lattice.size(); ++k) {
    const double a = boxed(k), b = w.lattice_phi[k];
    differ += std::memcmp(&a, &b, sizeof(double)) != 0;
    const VecI<Dim> c = lattice.coord(k);
    outside += (c.array() < boxed.lo().array()).any() || (c.array() > boxed.hi().array()).any();
  }
  CHECK(differ == 0);
  // the closed form is what is read outside the box, so it must be exercised
  CHECK(outside > 0);
  return boxed.stored();
}

template <int Dim>
void check_configurations() {
  const Vec<Dim> mid = Vec<Dim>::Constant(0.5) + Vec<Dim>::LinSpaced(0.013, 0.031);
  // a small ball: only its box is stored
  const Eigen::Index one = check_bits<Dim>(32, {ball<Dim>(mid, 0.12)}, 0.01);
  const MacGrid<Dim> grid = unit_grid<Dim>(32);
  CHECK(one < half_lattice(grid).size() / 4);
  // three bodies: a box reaching out of the domain, a ball overlapping it, a ball far outside
  // the domain (its bounds grown by 2 dx meet no lattice point), with and without the shrink
  const std::vector<CouplingBody<Dim>> three = {
      box<Dim>(Vec<Dim>::Constant(0.9), 0.17), ball<Dim>(Vec<Dim>::Constant(0.72), 0.11),
      ball<Dim>(Vec<Dim>::Constant(3.0), 0.2)};
  check_bits<Dim>(24, three, 0.01);
  check_bits<Dim>(24, three, 0.0);
  // only the body outside the domain: nothing stored, the closed form everywhere
  CHECK(check_bits<Dim>(16, {ball<Dim>(Vec<Dim>::Constant(3.0), 0.2)}, 0.01) == 0);
}

}  // namespace

TEST_CASE("the solids' union in the bodies' box reads the dense union's bits everywhere",
          "[unit][dense-reference]") {
  check_configurations<2>();
  check_configurations<3>();
}

TEST_CASE("the solids' union in a box refuses what it cannot hold", "[unit]") {
  const MacGrid<2> grid = unit_grid<2>(8);
  const SampleLattice<2> lattice = half_lattice(grid);
  BoxedUnionPhi<2> boxed;
  const VectorX dense = VectorX::Ones(lattice.size());
  // no body, a dense vector of another size, an unbounded body
  CHECK_FALSE(boxed.assign(lattice, {}, 0.25, 0.0, dense));
  const Box<2> unit(Vec<2>::Zero(), Vec<2>::Ones());
  CHECK_FALSE(boxed.assign(lattice, {unit}, 0.25, 0.0, VectorX::Ones(3)));
  Box<2> unbounded(Vec<2>::Zero(), Vec<2>::Ones());
  unbounded.max()[0] = std::numeric_limits<double>::infinity();
  CHECK_FALSE(boxed.assign(lattice, {unbounded}, 0.25, 0.0, dense));
  CHECK_FALSE(boxed.valid());
  // a body as large as the domain: its box would be the lattice
  CHECK_FALSE(boxed.assign(lattice, {unit}, 0.25, 0.0, dense));
  const Box<2> small(Vec<2>::Constant(0.4), Vec<2>::Constant(0.5));
  CHECK(boxed.assign(lattice, {small}, 0.0, 0.0, dense));
  CHECK(boxed.valid());
  boxed.clear();
  CHECK_FALSE(boxed.valid());
}
