// Tests of particle seeding, advection (RK2, solids, walls, periodic and open faces) and
// position correction.
#include <omp.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <random>

#include "reference/core/parallel.hpp"
#include "reference/fluid/viscosity_field.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"
#include "reference/particles/slab_bounds.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A solid ball as a SolidField (distance < 0 inside the solid).
template <int Dim>
SolidField<Dim> solid_ball(const Vec<Dim>& c, double r) {
  SolidField<Dim> s;
  s.distance = [c, r](const Vec<Dim>& x) { return (x - c).norm() - r; };
  s.gradient = [c](const Vec<Dim>& x) { return Vec<Dim>((x - c).normalized()); };
  return s;
}

template <int Dim>
LiquidSpec liquid_spec(const Vec<Dim>& centre, double density = 1000.0) {
  LiquidSpec spec;
  spec.name = "water";
  spec.density = density;
  spec.shape.type = ShapeType::sphere;
  spec.shape.center.assign(centre.data(), centre.data() + Dim);
  return spec;
}

template <int Dim>
std::array<BoundaryType, 2 * Dim> walls() {
  std::array<BoundaryType, 2 * Dim> b;
  b.fill(BoundaryType::wall);
  return b;
}

template <int Dim>
double ball_volume(double r) {
  return Dim == 2 ? M_PI * r * r : 4.0 / 3.0 * M_PI * r * r * r;
}

/// Face field of the velocity function f sampled at the face centres.
template <int Dim, class F>
VectorX sample_faces(const MacGrid<Dim>& grid, F f) {
  VectorX u(grid.num_faces());
  for (int i = 0; i < grid.num_faces(); ++i) {
    const auto [axis, coord] = grid.face_coord(i);
    u[i] = f(grid.face_center(axis, coord))[axis];
  }
  return u;
}

/// Variance of the number of particles per grid cell over the cells of `region`.
template <int Dim>
double count_variance(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                      const Box<Dim>& region) {
  std::vector<int> count(grid.num_cells(), 0);
  for (const auto& x : particles.x) ++count[grid.cell_index(grid.cell_containing(x))];
  double sum = 0.0, sum2 = 0.0;
  int n = 0;
  for (int c = 0; c < grid.num_cells(); ++c) {
    if (!region.contains(grid.cell_center(grid.cell_coord(c)))) continue;
    sum += count[c];
    sum2 += double(count[c]) * count[c];
    ++n;
  }
  const double mean = sum / n;
  return sum2 / n - mean * mean;
}

/// Particles on the perfect sub-lattice (sub per axis per cell) inside shape.
template <int Dim>
Particles<Dim> lattice_particles(const MacGrid<Dim>& grid, const Shape<Dim>& shape, int sub) {
  Particles<Dim> p;
  const int n = grid.cells()[0] * sub;
  const int total = static_cast<int>(std::pow(n, Dim));
  for (int k = 0; k < total; ++k) {
    Vec<Dim> x;
    int r = k;
    for (int a = 0; a < Dim; ++a) {
      x[a] = grid.origin()[a] + (r % n + 0.5) * grid.dx() / sub;
      r /= n;
    }
    if (shape.distance(x) >= 0.0) continue;
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(1000.0 * grid.cell_volume() / std::pow(sub, Dim));
    p.density.push_back(1000.0);
    p.liquid.push_back(0);
  }
  return p;
}

}  // namespace

// --- seeding -------------------------------------------------------------------------------------

namespace {

template <int Dim>
void check_seeding() {
  const int n = Dim == 2 ? 40 : 24;
  const int per_cell = Dim == 2 ? 4 : 8;
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const double dx = grid.dx();
  const Vec<Dim> centre = Vec<Dim>::Constant(0.5);
  const double radius = 0.3;
  auto ball = std::make_shared<TestBall<Dim>>(centre, radius);
  LiquidSpec spec = liquid_spec<Dim>(centre, 900.0);

  // count close to per_cell * volume / dx^Dim
  const Particles<Dim> p =
      seed_particles<Dim>(grid, {spec}, {ball}, SolidField<Dim>{}, per_cell, 1u);
  const double expected = per_cell * ball_volume<Dim>(radius) / grid.cell_volume();
  INFO("dim " << Dim << ": seeded " << p.size() << ", expected " << expected);
  CHECK(std::abs(p.size() / expected - 1.0) < 0.02);
  // every particle inside the shape, with the right mass, density and liquid index
  for (std::size_t i = 0; i < p.size(); ++i) {
    REQUIRE(ball->distance(p.x[i]) < 0.0);
    REQUIRE(p.mass[i] == Approx(900.0 * grid.cell_volume() / per_cell).epsilon(1e-14));
    REQUIRE(p.density[i] == 900.0);
    REQUIRE(p.liquid[i] == 0);
  }
  // stratified: exactly per_cell particles in every cell well inside the shape
  std::vector<int> count(grid.num_cells(), 0);
  for (const auto& x : p.x) ++count[grid.cell_index(grid.cell_containing(x))];
  for (int c = 0; c < grid.num_cells(); ++c)
    if (ball->distance(grid.cell_center(grid.cell_coord(c))) < -dx) REQUIRE(count[c] == per_cell);

  // deterministic for a seed, different for another
  const Particles<Dim> same =
      seed_particles<Dim>(grid, {spec}, {ball}, SolidField<Dim>{}, per_cell, 1u);
  const Particles<Dim> other =
      seed_particles<Dim>(grid, {spec}, {ball}, SolidField<Dim>{}, per_cell, 2u);
  REQUIRE(same.size() == p.size());
  bool identical = true;
  for (std::size_t i = 0; i < p.size(); ++i) identical = identical && same.x[i] == p.x[i];
  CHECK(identical);
  bool differs = other.size() != p.size();
  for (std::size_t i = 0; i < std::min(p.size(), other.size()); ++i)
    differs = differs || other.x[i] != p.x[i];
  CHECK(differs);

  // a solid ball overlapping the liquid: nothing inside it or within 0.05 dx of it
  const SolidField<Dim> solid = solid_ball<Dim>(Vec<Dim>::Constant(0.35), 0.15);
  const Particles<Dim> q = seed_particles<Dim>(grid, {spec}, {ball}, solid, per_cell, 1u);
  CHECK(q.size() < p.size());
  for (const auto& x : q.x) REQUIRE(solid.distance(x) > 0.05 * dx);
}

}  // namespace

TEST_CASE("seeding: count, stratification, determinism, solids", "[unit]") {
  check_seeding<2>();
  check_seeding<3>();
}

TEST_CASE("seeding: the same particles on any team, over several chunks of candidates (setup19)",
          "[unit]") {
  // seed_particles draws its candidates serially and tests them on the team in chunks of 65536:
  // two overlapping liquids (the second's candidates inside the first are claimed by it) and a
  // solid, about 200k candidates per liquid at 48^3 with 8 per cell, so three or four chunks
  const MacGrid<3> grid = unit_grid<3>(48);
  const Vec<3> a(0.45, 0.5, 0.5), b(0.6, 0.45, 0.5);
  auto first = std::make_shared<TestBall<3>>(a, 0.3);
  auto second = std::make_shared<TestBall<3>>(b, 0.25);
  const SolidField<3> solid = solid_ball<3>(Vec<3>(0.5, 0.2, 0.5), 0.12);
  const std::vector<LiquidSpec> specs = {liquid_spec<3>(a, 900.0), liquid_spec<3>(b, 1100.0)};
  const bool monitor = core_monitor();
  set_core_monitor(false);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const Particles<3> one = seed_particles<3>(grid, specs, {first, second}, solid, 8, 5u);
  REQUIRE(one.size() > 100000);
  long from_second = 0;
  for (int l : one.liquid) from_second += l == 1;
  CHECK(from_second > 0);
  for (int threads : {2, 3}) {
    CAPTURE(threads);
    omp_set_num_threads(threads);
    const Particles<3> many = seed_particles<3>(grid, specs, {first, second}, solid, 8, 5u);
    REQUIRE(many.size() == one.size());
    long differ = 0;
    for (std::size_t i = 0; i < one.size(); ++i)
      differ += !(many.x[i] == one.x[i]) || !(many.v[i] == one.v[i]) ||
                many.liquid[i] != one.liquid[i] || many.mass[i] != one.mass[i];
    CHECK(differ == 0);
  }
  omp_set_num_threads(saved);
  set_core_monitor(monitor);
}

TEST_CASE("seeding: velocity, rotation and APIC matrix of a liquid", "[unit]") {
  const MacGrid<2> grid2 = unit_grid<2>(20);
  LiquidSpec spec2 = liquid_spec<2>(Vec<2>(0.5, 0.4));
  spec2.velocity = {0.3, -0.2};
  spec2.angular_velocity = {1.5};
  auto disk = std::make_shared<TestBall<2>>(Vec<2>(0.5, 0.4), 0.2);
  const Particles<2> p2 = seed_particles<2>(grid2, {spec2}, {disk}, SolidField<2>{}, 4, 3u);
  REQUIRE(p2.size() > 0);
  for (std::size_t i = 0; i < p2.size(); ++i) {
    const Vec<2> r = p2.x[i] - Vec<2>(0.5, 0.4);
    REQUIRE((p2.v[i] - Vec<2>(0.3 - 1.5 * r[1], -0.2 + 1.5 * r[0])).norm() < 1e-14);
    REQUIRE(p2.c[i](0, 1) == -1.5);
    REQUIRE(p2.c[i](1, 0) == 1.5);
    REQUIRE(p2.c[i](0, 0) == 0.0);
  }

  const MacGrid<3> grid3 = unit_grid<3>(12);
  LiquidSpec spec3 = liquid_spec<3>(Vec<3>(0.5, 0.5, 0.5));
  spec3.velocity = {0.0, 1.0, 0.0};
  spec3.angular_velocity = {0.2, -0.4, 0.9};
  auto ball = std::make_shared<TestBall<3>>(Vec<3>(0.5, 0.5, 0.5), 0.3);
  const Particles<3> p3 = seed_particles<3>(grid3, {spec3}, {ball}, SolidField<3>{}, 8, 3u);
  const Vec<3> omega(0.2, -0.4, 0.9);
  REQUIRE(p3.size() > 0);
  for (std::size_t i = 0; i < p3.size(); ++i) {
    const Vec<3> r = p3.x[i] - Vec<3>(0.5, 0.5, 0.5);
    REQUIRE((p3.v[i] - Vec<3>(0.0, 1.0, 0.0) - omega.cross(r)).norm() < 1e-14);
    // c r = omega x r for any r
    REQUIRE((p3.c[i] * r - omega.cross(r)).norm() < 1e-14);
  }
}

TEST_CASE("seeding: overlapping liquids, non-square per_cell, shapes without a centre", "[unit]") {
  const MacGrid<2> grid = unit_grid<2>(32);
  auto a = std::make_shared<TestBall<2>>(Vec<2>(0.4, 0.5), 0.2);
  auto b = std::make_shared<TestBall<2>>(Vec<2>(0.6, 0.5), 0.2);
  LiquidSpec la = liquid_spec<2>(Vec<2>(0.4, 0.5), 1000.0),
             lb = liquid_spec<2>(Vec<2>(0.6, 0.5), 800.0);
  // a shape without `center`: the rotation is about the centre of its bounds
  lb.shape.type = ShapeType::polygon;
  lb.shape.center.clear();
  lb.angular_velocity = {2.0};
  const Particles<2> p = seed_particles<2>(grid, {la, lb}, {a, b}, SolidField<2>{}, 5, 9u);
  // the union is seeded once: overlapping points belong to the first liquid
  const double d = 0.1;  // half the centre distance
  const double lens = 2.0 * (0.04 * std::acos(d / 0.2) - d * std::sqrt(0.04 - d * d));
  const double union_area = 2.0 * M_PI * 0.04 - lens;
  const double expected = 5 * union_area / grid.cell_volume();
  INFO("seeded " << p.size() << ", expected " << expected);
  CHECK(std::abs(p.size() / expected - 1.0) < 0.02);
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.liquid[i] == 1) {
      REQUIRE(a->distance(p.x[i]) >= 0.0);
      REQUIRE(p.density[i] == 800.0);
      const Vec<2> r = p.x[i] - Vec<2>(0.6, 0.5);
      REQUIRE((p.v[i] - Vec<2>(-2.0 * r[1], 2.0 * r[0])).norm() < 1e-12);
    }
  }
  // a shape crossing the domain boundary is seeded only inside the domain
  auto edge = std::make_shared<TestBox<2>>(Vec<2>(0.0, 0.5), Vec<2>(0.25, 0.25));
  const Particles<2> q = seed_particles<2>(grid, {la}, {edge}, SolidField<2>{}, 4, 1u);
  CHECK(q.size() == static_cast<std::size_t>(4 * 8 * 16));
  for (const auto& x : q.x) REQUIRE(grid.domain_box().contains(x));
}

// --- advection -----------------------------------------------------------------------------------

namespace {

template <int Dim>
double rotation_error(int steps) {
  // rigid rotation about the domain centre in the x-y plane (linear: interpolation is exact)
  const MacGrid<Dim> grid = unit_grid<Dim>(16);
  const Vec<Dim> centre = Vec<Dim>::Constant(0.5);
  auto field = [&](const Vec<Dim>& x) {
    Vec<Dim> v = Vec<Dim>::Zero();
    v[0] = -(x[1] - centre[1]);
    v[1] = x[0] - centre[0];
    return v;
  };
  const VectorX u = sample_faces<Dim>(grid, field);
  Particles<Dim> p;
  Vec<Dim> x0 = centre;
  x0[0] += 0.25;
  p.x = {x0};
  p.v = {Vec<Dim>::Zero()};
  p.c = {Mat<Dim>::Zero()};
  p.mass = {1.0};
  p.density = {1.0};
  p.liquid = {0};
  const double T = 0.5 * M_PI;
  for (int s = 0; s < steps; ++s)
    advect_particles(p, grid, u, T / steps, SolidField<Dim>{}, walls<Dim>());
  Vec<Dim> exact = centre;
  exact[1] += 0.25;
  return (p.x[0] - exact).norm();
}

template <int Dim>
void check_rk2_order() {
  std::vector<double> errors;
  // from 16 steps on, a step moves the particle less than the advection substep (dx / 2), so each
  // step is one RK2 step (with 8 it would be split into two, the same as 16)
  for (int steps : {16, 32, 64, 128}) errors.push_back(rotation_error<Dim>(steps));
  for (std::size_t k = 1; k < errors.size(); ++k) {
    const double order = std::log2(errors[k - 1] / errors[k]);
    INFO("dim " << Dim << ": error " << errors[k - 1] << " -> " << errors[k] << ", order "
                << order);
    CHECK(order > 1.8);
  }
}

}  // namespace

TEST_CASE("advection: RK2 converges at second order in a rigid rotation", "[unit][convergence]") {
  check_rk2_order<2>();
  check_rk2_order<3>();
}

namespace {

template <int Dim>
void check_solid_in_flow() {
  // a uniform flow towards a solid ball: no particle ever ends inside it
  const MacGrid<Dim> grid = unit_grid<Dim>(Dim == 2 ? 32 : 16);
  const double dx = grid.dx();
  const SolidField<Dim> solid = solid_ball<Dim>(Vec<Dim>::Constant(0.5), 0.15);
  Vec<Dim> flow = Vec<Dim>::Zero();
  flow[0] = 1.0;
  const VectorX u = sample_faces<Dim>(grid, [&](const Vec<Dim>&) { return flow; });
  auto block = std::make_shared<TestBox<Dim>>(
      [] {
        Vec<Dim> c = Vec<Dim>::Constant(0.5);
        c[0] = 0.2;
        return c;
      }(),
      Vec<Dim>::Constant(0.12));
  Particles<Dim> p = seed_particles<Dim>(grid, {liquid_spec<Dim>(Vec<Dim>::Constant(0.5))}, {block},
                                         SolidField<Dim>{}, Dim == 2 ? 4 : 8, 5u);
  const std::size_t n0 = p.size();
  REQUIRE(n0 > 0);
  for (int step = 0; step < 24; ++step) {
    advect_particles(p, grid, u, 1.4 * dx, solid, walls<Dim>());
    for (const auto& x : p.x) {
      REQUIRE(solid.distance(x) >= 0.0);
      REQUIRE(grid.domain_box().contains(x));
    }
  }
  // walls: nothing removed, and the particles that reached x+ sit just inside it
  CHECK(p.size() == n0);
  double max_x = 0.0;
  for (const auto& x : p.x) max_x = std::max(max_x, x[0]);
  CHECK(max_x == Approx(1.0 - 0.01 * dx).epsilon(1e-12));
}

template <int Dim>
void check_periodic_and_open() {
  const MacGrid<Dim> grid = unit_grid<Dim>(10, true);
  const double dx = grid.dx();
  Vec<Dim> flow = Vec<Dim>::Zero();
  flow[0] = 1.0;
  flow[1] = 0.5;
  const VectorX u = sample_faces<Dim>(grid, [&](const Vec<Dim>&) { return flow; });
  // periodic x: a particle crossing x = 1 reappears at the low end
  std::array<BoundaryType, 2 * Dim> boundary = walls<Dim>();
  boundary[0] = boundary[1] = BoundaryType::periodic;
  boundary[3] = BoundaryType::open;  // y+
  Particles<Dim> p;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> uni(0.02, 0.98);
  const int count = 500;
  for (int i = 0; i < count; ++i) {
    Vec<Dim> x;
    for (int a = 0; a < Dim; ++a) x[a] = uni(rng);
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(1.0);
    p.density.push_back(1.0);
    p.liquid.push_back(0);
  }
  const double dt = 0.3;
  // expected: those with y + 0.5 dt > 1 leave through the open y+ face
  long expected_removed = 0;
  std::vector<Vec<Dim>> expected_x;
  for (const auto& x : p.x) {
    Vec<Dim> y = x + dt * flow;
    if (y[1] > 1.0) {
      ++expected_removed;
      continue;
    }
    y[0] = std::fmod(y[0], 1.0);
    expected_x.push_back(y);
  }
  const long removed = advect_particles(p, grid, u, dt, SolidField<Dim>{}, boundary);
  CHECK(removed == expected_removed);
  REQUIRE(p.size() == expected_x.size());
  CHECK(expected_removed > 0);
  double err = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) err = std::max(err, (p.x[i] - expected_x[i]).norm());
  CHECK(err < 1e-12);
  for (const auto& x : p.x) REQUIRE((x[0] >= 0.0 && x[0] < 1.0));
  // open y- face: flow downwards removes what crosses y = 0; the wall stays closed otherwise
  boundary[2] = BoundaryType::open;
  const VectorX down = -u;
  const std::size_t before = p.size();
  long gone = 0;
  for (int s = 0; s < 10; ++s)
    gone += advect_particles(p, grid, down, 0.25, SolidField<Dim>{}, boundary);
  CHECK(gone == static_cast<long>(before));
  CHECK(p.size() == 0);
  (void)dx;
}

}  // namespace

TEST_CASE("advection: solids, walls, periodic wrap and open faces", "[unit]") {
  check_solid_in_flow<2>();
  check_solid_in_flow<3>();
  check_periodic_and_open<2>();
  check_periodic_and_open<3>();
}

// --- position correction -------------------------------------------------------------------------

namespace {

template <int Dim>
void check_uniform_lattice_stays() {
  const MacGrid<Dim> grid = unit_grid<Dim>(Dim == 2 ? 24 : 12);
  const double dx = grid.dx();
  auto block = std::make_shared<TestBox<Dim>>(Vec<Dim>::Constant(0.5), Vec<Dim>::Constant(0.25));
  Particles<Dim> p = lattice_particles<Dim>(grid, *block, 2);
  // the lattice touching a wall too
  auto floor = std::make_shared<TestBox<Dim>>(Vec<Dim>::Constant(0.0), Vec<Dim>::Constant(0.2));
  const Particles<Dim> q = lattice_particles<Dim>(grid, *floor, 2);
  for (std::size_t i = 0; i < q.size(); ++i) {
    p.x.push_back(q.x[i]);
    p.v.push_back(q.v[i]);
    p.c.push_back(q.c[i]);
    p.mass.push_back(q.mass[i]);
    p.density.push_back(q.density[i]);
    p.liquid.push_back(q.liquid[i]);
  }
  const std::vector<Vec<Dim>> x0 = p.x;
  for (int step = 0; step < 5; ++step)
    correct_positions(p, grid, 0.01, SolidField<Dim>{}, walls<Dim>());
  double moved = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) moved = std::max(moved, (p.x[i] - x0[i]).norm());
  INFO("dim " << Dim << ": max displacement / dx " << moved / dx);
  CHECK(moved < 1e-3 * dx);
}

template <int Dim>
void check_cluster_spreads() {
  // uniformly random positions (Poisson clustering) at the seeding density, next to a solid
  const int n = Dim == 2 ? 32 : 16;
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const double dx = grid.dx();
  const int per_cell = Dim == 2 ? 4 : 8;
  const SolidField<Dim> solid = solid_ball<Dim>(Vec<Dim>::Constant(0.5), 0.1);
  Particles<Dim> p;
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> uni(0.25, 0.75);
  const int count = static_cast<int>(per_cell * std::pow(0.5 * n, Dim));
  while (static_cast<int>(p.size()) < count) {
    Vec<Dim> x;
    for (int a = 0; a < Dim; ++a) x[a] = uni(rng);
    if (solid.distance(x) < 0.05 * dx) continue;
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(1000.0 * grid.cell_volume() / per_cell);
    p.density.push_back(1000.0);
    p.liquid.push_back(0);
  }
  // a compressed corner cluster: extra particles packed into one cell
  const Vec<Dim> cluster_centre = grid.cell_center(grid.cell_containing(Vec<Dim>::Constant(0.3)));
  for (int i = 0; i < 4 * per_cell; ++i) {
    // uni - 0.5 is in [-0.25, 0.25]: the cluster fills the middle half of the cell
    Vec<Dim> x = cluster_centre;
    for (int a = 0; a < Dim; ++a) x[a] += dx * (uni(rng) - 0.5);
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(1000.0 * grid.cell_volume() / per_cell);
    p.density.push_back(1000.0);
    p.liquid.push_back(0);
  }
  const Box<Dim> inner(Vec<Dim>::Constant(0.25 + dx), Vec<Dim>::Constant(0.75 - dx));
  const double var0 = count_variance(p, grid, inner);
  // smallest pair distance away from the solid (a particle projected onto the solid's 0.05 dx
  // margin may be held against a neighbour there)
  auto min_distance = [&]() {
    double m = 1e30;
    for (std::size_t i = 0; i < p.size(); ++i) {
      if (solid.distance(p.x[i]) < 0.1 * dx) continue;
      for (std::size_t j = i + 1; j < p.size(); ++j)
        if (solid.distance(p.x[j]) >= 0.1 * dx) m = std::min(m, (p.x[i] - p.x[j]).norm());
    }
    return m;
  };
  const double min0 = min_distance();
  // particles in the cell of the compressed cluster
  const int cluster_cell = grid.cell_index(grid.cell_containing(Vec<Dim>::Constant(0.3)));
  auto cluster_count = [&]() {
    int k = 0;
    for (const auto& x : p.x) k += grid.cell_index(grid.cell_containing(x)) == cluster_cell;
    return k;
  };
  const int cluster0 = cluster_count();
  int cluster5 = 0;
  for (int step = 0; step < 20; ++step) {
    correct_positions(p, grid, 0.02, solid, walls<Dim>());
    for (const auto& x : p.x) REQUIRE(solid.distance(x) >= 0.0);
    if (step == 4) cluster5 = cluster_count();
  }
  // the compressed cell sheds at least half of its excess of 4 per_cell within 5 steps
  INFO("dim " << Dim << ": cluster cell " << cluster0 << " -> " << cluster5 << " particles");
  CHECK(cluster0 >= 4 * per_cell);
  CHECK(cluster5 < 3 * per_cell);
  const double var1 = count_variance(p, grid, inner);
  const double min1 = min_distance();
  INFO("dim " << Dim << ": per-cell count variance " << var0 << " -> " << var1
              << ", min distance / spacing " << min0 / (0.5 * dx) << " -> " << min1 / (0.5 * dx));
  // 0.6: the 5 % compression slack of the correction (chosen so a 2D dam break neither loses nor
  // gains volume, docs/particles.md) leaves mild fluctuations alone
  CHECK(var1 < 0.6 * var0);
  // close pairs are pushed towards the minimum distance of half a rest spacing (0.25 dx here)
  CHECK(min1 > 0.8 * 0.5 * 0.5 * dx);
  for (const auto& x : p.x) REQUIRE(grid.domain_box().contains(x));
}

template <int Dim>
void check_correction_keeps_volume() {
  // a jittered seeded ball at rest: corrections keep the reconstructed volume steady
  const MacGrid<Dim> grid = unit_grid<Dim>(Dim == 2 ? 32 : 12);
  auto ball = std::make_shared<TestBall<Dim>>(Vec<Dim>::Constant(0.5), 0.3);
  Particles<Dim> p = seed_particles<Dim>(grid, {liquid_spec<Dim>(Vec<Dim>::Constant(0.5))}, {ball},
                                         SolidField<Dim>{}, Dim == 2 ? 4 : 8, 4u);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  auto volume = [&]() {
    const VectorX phi = liquid_phi_on_lattice(p, grid, lattice, walls<Dim>());
    double v = 0.0;
    for (int k = 0; k < phi.size(); ++k) v += phi[k] < 0.0 ? 1.0 : 0.0;
    return v * std::pow(lattice.spacing, Dim);
  };
  auto mean_radius = [&]() {
    double m = 0.0;
    for (const auto& x : p.x) m += (x - Vec<Dim>::Constant(0.5)).norm();
    return m / p.size();
  };
  const double r0 = mean_radius();
  const double v0 = volume();
  auto run = [&](int steps) {
    for (int step = 0; step < steps; ++step)
      correct_positions(p, grid, 0.02, SolidField<Dim>{}, walls<Dim>());
  };
  run(30);
  const double v50 = volume();
  run(30);
  const double v1 = volume();
  INFO("dim " << Dim << ": lattice volume " << v0 << " -> " << v50 << " -> " << v1
              << ", mean radius " << r0 << " -> " << mean_radius());
  // a one-off settling of the seeding jitter, then steady
  CHECK(std::abs(v1 / v50 - 1.0) < 0.002);
  CHECK(std::abs(v1 / v0 - 1.0) < 0.02);
}

/// The position correction's hash holds only the occupied cells (a radix sort by cell, runs
/// found through tiles): a ball of liquid, squeezed so that it is corrected, moves bit for bit
/// the same in a 16^Dim grid and as a sub-box of a 2048^2 / 512^3 grid of the same cell size
/// (its cells then far from index 0, 134 M cells in 3D, for which a table by cell would take
/// half a gigabyte and a pass over all of them per call). The particle positions are the same numbers in both grids; only the cell
/// indices differ.
template <int Dim>
void check_correction_in_a_large_grid() {
  const int n = 16;
  const double dx = 1.0 / n;
  const MacGrid<Dim> small = unit_grid<Dim>(n);
  const int large_cells = Dim == 2 ? 2048 : 512;
  VecI<Dim> offset;
  for (int a = 0; a < Dim; ++a) offset[a] = large_cells / 2 + 37 * a;
  const MacGrid<Dim> large(Vec<Dim>(-offset.template cast<double>() * dx), dx,
                           VecI<Dim>::Constant(large_cells), std::array<bool, Dim>{});
  const Vec<Dim> centre = Vec<Dim>::Constant(0.5);
  auto ball = std::make_shared<TestBall<Dim>>(centre, 0.25);
  Particles<Dim> a = seed_particles<Dim>(small, {liquid_spec<Dim>(centre)}, {ball},
                                         SolidField<Dim>{}, Dim == 2 ? 4 : 8, 9u);
  for (auto& x : a.x) x = centre + 0.85 * (x - centre);
  Particles<Dim> b = a;
  const Particles<Dim> start = a;
  for (int step = 0; step < 3; ++step) {
    correct_positions(a, small, 0.02, SolidField<Dim>{}, walls<Dim>());
    correct_positions(b, large, 0.02, SolidField<Dim>{}, walls<Dim>());
  }
  bool moved = false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    INFO("dim " << Dim << ", particle " << i);
    REQUIRE(a.x[i] == b.x[i]);
    moved = moved || a.x[i] != start.x[i];
  }
  CHECK(moved);
}

}  // namespace

TEST_CASE("position correction: the same moves inside a grid of 134 M cells",
          "[unit][property]") {
  check_correction_in_a_large_grid<2>();
  check_correction_in_a_large_grid<3>();
}

TEST_CASE("position correction: a uniform lattice stays put", "[unit][property]") {
  check_uniform_lattice_stays<2>();
  check_uniform_lattice_stays<3>();
}

TEST_CASE("position correction: clustered particles spread, never into solids or walls", "[unit]") {
  check_cluster_spreads<2>();
  check_cluster_spreads<3>();
}

TEST_CASE("position correction keeps the reconstructed volume steady", "[unit][validation]") {
  check_correction_keeps_volume<2>();
  check_correction_keeps_volume<3>();
}

TEST_CASE("position correction on 500k particles (timing)", "[.][perf]") {
  const MacGrid<3> grid = unit_grid<3>(64);
  auto ball = std::make_shared<TestBall<3>>(Vec<3>::Constant(0.5), 0.3);
  Particles<3> p = seed_particles<3>(grid, {liquid_spec<3>(Vec<3>::Constant(0.5))}, {ball},
                                     SolidField<3>{}, 8, 4u);
  const double t0 = omp_get_wtime();
  correct_positions(p, grid, 0.01, SolidField<3>{}, walls<3>());
  const double t1 = omp_get_wtime();
  correct_positions(p, grid, 0.01, SolidField<3>{}, walls<3>());
  const double t2 = omp_get_wtime();
  VectorX u, m, rho;
  particles_to_grid(p, grid, u, m, rho);
  const double t3 = omp_get_wtime();
  grid_to_particles(p, grid, u);
  const double t4 = omp_get_wtime();
  advect_particles(p, grid, u, 0.01, SolidField<3>{}, walls<3>());
  const double t5 = omp_get_wtime();
  WARN(p.size() << " particles, " << omp_get_max_threads() << " threads: correction " << (t1 - t0)
                << " s then " << (t2 - t1) << " s, p2g " << (t3 - t2) << " s, g2p " << (t4 - t3)
                << " s, advection " << (t5 - t4) << " s");
  REQUIRE(p.size() > 0);
}

// --- small helpers -------------------------------------------------------------------------------

TEST_CASE("remove_flagged and max_particle_speed", "[unit]") {
  Particles<3> p;
  for (int i = 0; i < 5; ++i) {
    p.x.push_back(Vec<3>::Constant(i));
    p.v.push_back(Vec<3>(i, 0.0, 0.0));
    p.c.push_back(Mat<3>::Identity() * i);
    p.mass.push_back(i);
    p.density.push_back(10.0 * i);
    p.liquid.push_back(i);
  }
  CHECK(max_particle_speed(p) == 4.0);
  p.remove_flagged({0, 1, 0, 1, 0});
  REQUIRE(p.size() == 3);
  CHECK(p.liquid == std::vector<int>{0, 2, 4});
  CHECK(p.mass == std::vector<double>{0.0, 2.0, 4.0});
  CHECK(p.c[1](0, 0) == 2.0);
  CHECK(p.v.size() == 3);
  CHECK(max_particle_speed(Particles<2>{}) == 0.0);
}

TEST_CASE("position correction separates coincident particles", "[unit]") {
  const MacGrid<2> grid = unit_grid<2>(8);
  const double dx = grid.dx();
  Particles<2> p;
  for (int i = 0; i < 2; ++i) {
    p.x.push_back(Vec<2>(0.5, 0.5));
    p.v.push_back(Vec<2>::Zero());
    p.c.push_back(Mat<2>::Zero());
    p.mass.push_back(1000.0 * grid.cell_volume() / 4);
    p.density.push_back(1000.0);
    p.liquid.push_back(0);
  }
  for (int step = 0; step < 10; ++step)
    correct_positions(p, grid, 0.02, SolidField<2>{}, walls<2>());
  // both move apart along x, symmetrically, to about the minimum distance (0.5 s = dx / 4)
  CHECK(p.x[0][0] > 0.5);
  CHECK(p.x[1][0] < 0.5);
  CHECK(std::abs((p.x[0] + p.x[1])[0] - 1.0) < 1e-12);
  CHECK((p.x[0] - p.x[1]).norm() > 0.2 * dx);
}

// --- grid density projection ---------------------------------------------------------------------

namespace {

/// W_F^u without solids: 1 on every face, 0 on the (wall) boundary faces.
template <int Dim>
VectorX open_fluid_faces(const MacGrid<Dim>& grid) {
  VectorX w = VectorX::Ones(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (grid.is_boundary_face(axis, coord)) w[f] = 0.0;
  }
  return w;
}

/// Volume of the particle level set: sum of the cells' liquid fractions times dx^Dim (the
/// simulation's liquid_volume statistic, with the same Kuhn-simplex fractions).
template <int Dim>
double level_set_volume(const Particles<Dim>& p, const MacGrid<Dim>& grid) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX phi = liquid_phi_on_lattice(p, grid, lattice, walls<Dim>());
  double frac = 0.0;
  // each cell's 2^Dim lattice cells, fraction from the corner values
  const VecI<Dim> dims = 2 * grid.cells();
  int count = 1;
  for (int a = 0; a < Dim; ++a) count *= dims[a];
  for (int k = 0; k < count; ++k) {
    VecI<Dim> lower;
    int rest = k;
    for (int a = 0; a < Dim; ++a) {
      lower[a] = rest % dims[a];
      rest /= dims[a];
    }
    std::array<double, (1 << Dim)> corner;
    for (int b = 0; b < (1 << Dim); ++b) {
      VecI<Dim> i = lower;
      for (int a = 0; a < Dim; ++a) i[a] += (b >> a) & 1;
      corner[b] = phi[lattice.index(i)];
    }
    frac += lattice_cell_negative_fraction<Dim>(corner);
  }
  return frac * std::pow(lattice.spacing, Dim);
}

template <int Dim>
double particle_volume(const Particles<Dim>& p) {
  double v = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) v += p.mass[i] / p.density[i];
  return v;
}

/// A block seeded against the lower walls, [0, 0.5]^Dim of the unit box.
template <int Dim>
Particles<Dim> seeded_corner_block(const MacGrid<Dim>& grid) {
  auto block = std::make_shared<TestBox<Dim>>(Vec<Dim>::Constant(0.25), Vec<Dim>::Constant(0.25));
  return seed_particles<Dim>(grid, {liquid_spec<Dim>(Vec<Dim>::Constant(0.25))}, {block},
                             SolidField<Dim>{}, Dim == 2 ? 4 : 8, 11u);
}

template <int Dim>
void check_projection_even_block() {
  const MacGrid<Dim> grid = unit_grid<Dim>(Dim == 2 ? 32 : 12);
  const double dx = grid.dx();
  Particles<Dim> p = seeded_corner_block<Dim>(grid);
  const VectorX fluid = open_fluid_faces(grid);
  const double vp = particle_volume(p);
  const double v0 = level_set_volume(p, grid);
  const DensityProjectionStats first = project_particle_density(p, grid, half_lattice(grid), fluid,
                                                                SolidField<Dim>{}, walls<Dim>(), 2);
  const DensityProjectionStats again =
      project_particle_density(p, grid, half_lattice(grid), fluid, SolidField<Dim>{}, walls<Dim>());
  const double v1 = level_set_volume(p, grid);
  INFO("dim " << Dim << ": particle volume " << vp << ", level set " << v0 << " -> " << v1
              << ", error " << first.error_before << " -> " << again.error_before << ", moves "
              << first.max_move / dx << " then " << again.max_move / dx << " dx");
  // an evenly seeded block is nearly consistent already: moves below the seeding jitter (+-1/8 dx
  // with the defaults), shrinking from call to call with the error
  CHECK(first.max_move < 0.125 * dx);
  CHECK(again.max_move < 0.5 * first.max_move);
  CHECK(again.error_before < 0.75 * first.error_before);
  // with the particles mirrored across the two walls the block's level set encloses the particle
  // volume from the start (measured -0.03 % in 2D, +0.14 % in 3D; without the images -0.33 % and
  // -1.25 %), and the projection keeps it there up to the level set's sub-cell response to the
  // moves (+0.11 %, +0.37 %)
  CHECK(std::abs(v0 / vp - 1.0) < 0.0025);
  CHECK(std::abs(v1 / vp - 1.0) < 0.005);
  for (const auto& x : p.x) REQUIRE(grid.domain_box().contains(x));
}

template <int Dim>
void check_projection_restores_compressed_block() {
  const MacGrid<Dim> grid = unit_grid<Dim>(Dim == 2 ? 32 : 12);
  Particles<Dim> p = seeded_corner_block<Dim>(grid);
  const double vp = particle_volume(p);
  // squeeze the block towards the corner by 0.9 per axis: its level set loses ~1 - 0.9^Dim
  for (auto& x : p.x) x *= 0.9;
  // a solid ball just above the block, which the spreading liquid must not enter
  const SolidField<Dim> solid = solid_ball<Dim>(Vec<Dim>::Constant(0.62), 0.12);
  const VectorX fluid = open_fluid_faces(grid);
  const double v0 = level_set_volume(p, grid);
  std::vector<double> error;
  for (int call = 0; call < 10; ++call) {
    error.push_back(
        project_particle_density(p, grid, half_lattice(grid), fluid, solid, walls<Dim>())
            .error_before);
    for (const auto& x : p.x) {
      REQUIRE(solid.distance(x) >= 0.0);
      REQUIRE(grid.domain_box().contains(x));
    }
  }
  const double v1 = level_set_volume(p, grid);
  INFO("dim " << Dim << ": level set / particle volume " << v0 / vp << " -> " << v1 / vp
              << ", error " << error.front() << " -> " << error.back());
  CHECK(v0 / vp < 1.0 - 0.8 * (1.0 - std::pow(0.9, Dim)));
  CHECK(std::abs(v1 / vp - 1.0) < 0.01);
  CHECK(error.back() < 0.2 * error.front());
}

template <int Dim>
void check_projection_holds_beside_moving_bodies() {
  // (departures item 25) the cells closer than held_reach dx to `held_near` keep their error:
  // the compressed block of the test above with a ball inside its corner as the held body
  const MacGrid<Dim> grid = unit_grid<Dim>(Dim == 2 ? 32 : 12);
  Particles<Dim> squeezed = seeded_corner_block<Dim>(grid);
  for (auto& x : squeezed.x) x *= 0.9;
  const VectorX fluid = open_fluid_faces(grid);
  const SolidField<Dim> none;
  const SolidField<Dim> ball = solid_ball<Dim>(Vec<Dim>::Constant(0.2), 0.05);
  // every cell held (a reach beyond the domain): nothing moves, no error counted
  Particles<Dim> all = squeezed;
  const DensityProjectionStats held_all = project_particle_density(
      all, grid, half_lattice(grid), fluid, none, walls<Dim>(), 1, SurfaceDeficits::all, nullptr,
      &ball, 100.0);
  CHECK(held_all.error_before == 0.0);
  CHECK(held_all.max_move == 0.0);
  for (std::size_t i = 0; i < all.size(); ++i) REQUIRE(all.x[i] == squeezed.x[i]);
  // no field or reach 0: the projection as without them, bit for bit
  Particles<Dim> plain = squeezed, zero = squeezed, near = squeezed;
  const DensityProjectionStats s_plain =
      project_particle_density(plain, grid, half_lattice(grid), fluid, none, walls<Dim>());
  project_particle_density(zero, grid, half_lattice(grid), fluid, none, walls<Dim>(), 1,
                           SurfaceDeficits::all, nullptr, &ball, 0.0);
  for (std::size_t i = 0; i < plain.size(); ++i) REQUIRE(zero.x[i] == plain.x[i]);
  // one cell around the ball: less error corrected, but the rest of the block still is
  const DensityProjectionStats s_near = project_particle_density(
      near, grid, half_lattice(grid), fluid, none, walls<Dim>(), 1, SurfaceDeficits::all, nullptr,
      &ball, 1.0);
  INFO("dim " << Dim << ": error " << s_plain.error_before << " whole, " << s_near.error_before
              << " with the cells beside the ball held");
  CHECK(s_near.error_before < s_plain.error_before);
  CHECK(s_near.error_before > 0.2 * s_plain.error_before);
  CHECK(s_near.max_move > 0.0);
}

template <int Dim>
void check_projection_deterministic(bool with_solid) {
  const MacGrid<Dim> grid = unit_grid<Dim>(Dim == 2 ? 32 : 12);
  Particles<Dim> a = seeded_corner_block<Dim>(grid);
  for (auto& x : a.x) x *= 0.95;
  const Particles<Dim> start = a;
  const VectorX fluid = open_fluid_faces(grid);
  // with a solid ball just above the block, the level set's splat adds the particles' images
  // across it (the splat's parts along axis 0 each fill their own points' solid distances)
  const SolidField<Dim> solid =
      with_solid ? solid_ball<Dim>(Vec<Dim>::Constant(0.62), 0.12) : SolidField<Dim>{};
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  project_particle_density(a, grid, half_lattice(grid), fluid, solid, walls<Dim>(), 2);
  // the splat's slabs of cell layers (cut at equal particle counts) and the level set's parts
  // along axis 0: one per thread, so 2, 3 and 5 threads cut the grid
  // differently, and every cell must still sum in particle order
  for (int t : {2, 3, 5}) {
    Particles<Dim> b = start;
    omp_set_num_threads(t);
    project_particle_density(b, grid, half_lattice(grid), fluid, solid, walls<Dim>(),
                             2);
    omp_set_num_threads(threads);
    bool moved = false;
    for (std::size_t i = 0; i < a.size(); ++i) {
      INFO(t << " threads, particle " << i);
      REQUIRE(a.x[i] == b.x[i]);
      moved = moved || a.x[i] != start.x[i];
    }
    CHECK(moved);
  }
}

/// (issue 20, p2g21) The displacement's storage kept across calls (project_particle_density's
/// move_scratch) with a block that moves along the last axis and then shrinks, a call on another
/// grid in between and a call without particles: the same positions, bit for bit, as calls that
/// each make their own storage (on 1 thread against 3), and after every call the kept storage
/// holds +0 on every face outside the spans it lists.
/// (two24) With `cells` = 256 in 2D the spans hold more than kParallelMinWork faces, so the
/// team zeroes them in blocks of the rows' region (more than one block per thread at 3 threads).
/// Returns the most faces the kept spans listed before a call on `grid`.
template <int Dim>
long check_projection_kept_scratch(int cells = Dim == 2 ? 40 : 16) {
  const MacGrid<Dim> grid = unit_grid<Dim>(cells);
  const MacGrid<Dim> other = unit_grid<Dim>(Dim == 2 ? 24 : 10);
  const VectorX fluid = open_fluid_faces(grid), fluid_other = open_fluid_faces(other);
  Particles<Dim> a = seeded_corner_block<Dim>(grid);
  for (auto& x : a.x) x *= 0.8;
  Particles<Dim> b = a;
  KeptZeros scratch;
  const int threads = omp_get_max_threads();
  const auto zeros_outside_dirty = [&](long n) {
    REQUIRE(scratch.values.size() == n);
    std::vector<char> listed(n, 0);
    for (const auto& [from, to] : scratch.dirty) {
      REQUIRE(0 <= from);
      REQUIRE(from < to);
      REQUIRE(to <= n);
      for (long f = from; f < to; ++f) listed[f] = 1;
    }
    long nonzero = 0;
    for (long f = 0; f < n; ++f) {
      if (listed[f]) {
        nonzero += scratch.values[f] != 0.0;
        continue;
      }
      REQUIRE(scratch.values[f] == 0.0);
      REQUIRE(!std::signbit(scratch.values[f]));
    }
    return nonzero;
  };
  long written = 0, stale_most = 0;
  for (int call = 0; call < 7; ++call) {
    if (call >= 1 && call <= 3) {
      // the block moves up by a few cells per call (its written faces move with it)
      Vec<Dim> up = Vec<Dim>::Zero();
      up[Dim - 1] = 0.12;
      for (auto& x : a.x) x += up;
      for (auto& x : b.x) x += up;
    } else if (call == 4 || call == 5) {
      // the block shrinks: the particles beyond the first axis' middle of it leave
      const auto keep = [](Particles<Dim>& p) {
        std::vector<char> leave(p.size(), 0);
        for (std::size_t i = 0; i < p.size(); ++i) leave[i] = p.x[i][0] >= 0.22;
        p.remove_flagged(leave);
      };
      keep(a);
      keep(b);
    }
    if (call == 5) {
      // another grid (the storage made anew), then no particles (the storage left as it was)
      Particles<Dim> c = seeded_corner_block<Dim>(other);
      project_particle_density(c, other, half_lattice(other), fluid_other, SolidField<Dim>{},
                               walls<Dim>(), 1, SurfaceDeficits::all, &scratch);
      zeros_outside_dirty(other.num_faces());
      Particles<Dim> none;
      project_particle_density(none, other, half_lattice(other), fluid_other, SolidField<Dim>{},
                               walls<Dim>(), 1, SurfaceDeficits::all, &scratch);
      zeros_outside_dirty(other.num_faces());
    }
    if (scratch.values.size() == grid.num_faces()) {
      long stale = 0;
      for (const auto& [from, to] : scratch.dirty) stale += to - from;
      stale_most = std::max(stale_most, stale);
    }
    omp_set_num_threads(3);
    project_particle_density(a, grid, half_lattice(grid), fluid, SolidField<Dim>{}, walls<Dim>(),
                             call == 0 ? 2 : 1, SurfaceDeficits::all, &scratch);
    omp_set_num_threads(1);
    project_particle_density(b, grid, half_lattice(grid), fluid, SolidField<Dim>{}, walls<Dim>(),
                             call == 0 ? 2 : 1);
    omp_set_num_threads(threads);
    INFO("dim " << Dim << ", call " << call << ", " << a.size() << " particles");
    REQUIRE(a.size() == b.size());
    for (std::size_t i = 0; i < a.size(); ++i) REQUIRE(a.x[i] == b.x[i]);
    written += zeros_outside_dirty(grid.num_faces());
    // one span per component at most, each within its component's faces
    REQUIRE(scratch.dirty.size() <= static_cast<std::size_t>(Dim));
  }
  // the projection moved something (the spans held displacements)
  CHECK(written > 0);
  return stale_most;
}

/// Spread (standard deviation over the columns along y) of the liquid height sum_y W_L^p dx, in
/// cells: how rough the particle level set's surface is.
template <int Dim>
double column_height_spread(const Particles<Dim>& p, const MacGrid<Dim>& grid,
                            const std::array<BoundaryType, 2 * Dim>& boundary) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX w =
      liquid_cell_weights(grid, lattice, liquid_phi_on_lattice(p, grid, lattice, boundary));
  const int columns = grid.num_cells() / grid.cells()[1];
  std::vector<double> h(columns, 0.0);
  for (int c = 0; c < grid.num_cells(); ++c) {
    const VecI<Dim> ci = grid.cell_coord(c);
    int column = 0;
    for (int a = Dim - 1; a >= 0; --a)
      if (a != 1) column = column * grid.cells()[a] + ci[a];
    h[column] += w[c];
  }
  double mean = 0.0, mean2 = 0.0;
  for (double v : h) {
    mean += v / columns;
    mean2 += v * v / columns;
  }
  return std::sqrt(std::max(0.0, mean2 - mean * mean));
}

/// Water at rest in an open tank (walls, open top, half full), projected call after call with
/// no flow in between: the projection must settle, not keep reshaping the surface.
template <int Dim>
void check_projection_keeps_water_at_rest() {
  const int n = Dim == 2 ? 32 : 16;
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const double dx = grid.dx();
  std::array<BoundaryType, 2 * Dim> boundary = walls<Dim>();
  boundary[3] = BoundaryType::open;  // y+
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX fluid =
      fluid_face_weights(grid, lattice, VectorX::Constant(lattice.size(), 1.0), boundary);
  Vec<Dim> centre = Vec<Dim>::Constant(0.5), half = Vec<Dim>::Constant(0.5);
  centre[1] = half[1] = 0.25;
  auto water = std::make_shared<TestBox<Dim>>(centre, half);
  Particles<Dim> p =
      seed_particles<Dim>(grid, {liquid_spec<Dim>(centre)}, {water}, SolidField<Dim>{},
                          Dim == 2 ? 4 : 8, 1u);
  // the first calls even out the seeding jitter
  project_particle_density(p, grid, lattice, fluid, SolidField<Dim>{}, boundary, 4);
  const double settled = column_height_spread(p, grid, boundary);
  const int calls = Dim == 2 ? 100 : 60;
  DensityProjectionStats last;
  for (int k = 0; k < calls; ++k)
    last = project_particle_density(p, grid, lattice, fluid, SolidField<Dim>{}, boundary);
  const double spread = column_height_spread(p, grid, boundary);
  INFO("dim " << Dim << ": spread of the column heights " << settled << " -> " << spread
              << " dx, last move " << last.max_move / dx << " dx");
  // measured: 2D 0.0415 -> 0.0423 dx, last move 2.1e-4 dx; 3D 0.0250 -> 0.0244, 2.5e-4 dx.
  // Before the air side was made one-sided the projection pulled particles into the bumps of the
  // level set: 0.0415 -> 0.096 (2D), 0.027 -> 0.040 (3D), the surface rising and the moves
  // staying at 2.6e-3 / 2.4e-3 dx per call
  CHECK(spread < 1.1 * settled);
  CHECK(last.max_move < 1e-3 * dx);
}

/// The density projection's grid work (splat, liquid fractions, solid distances, unknowns) runs
/// in tiles of 8^Dim cells made around the particles. A squeezed ball of liquid beside a solid
/// ball, projected where it is and moved by 3 cells (not a multiple of the tile; on a grid
/// periodic along x, moved across the seam, half of it wrapped to the other end), must move every
/// particle the same way: a cell the band missed would change the moves near it.
template <int Dim>
void check_projection_follows_a_shift_across_tiles(bool periodic) {
  const int n = Dim == 2 ? 40 : 24;
  const MacGrid<Dim> grid = unit_grid<Dim>(n, periodic);
  const double dx = grid.dx();
  std::array<BoundaryType, 2 * Dim> boundary = walls<Dim>();
  if (periodic) boundary[0] = boundary[1] = BoundaryType::periodic;
  VectorX fluid = VectorX::Ones(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (grid.is_boundary_face(axis, coord)) fluid[f] = 0.0;
  }
  const Vec<Dim> centre = Vec<Dim>::Constant(0.4);
  auto ball = std::make_shared<TestBall<Dim>>(centre, 0.2);
  Particles<Dim> a = seed_particles<Dim>(grid, {liquid_spec<Dim>(centre)}, {ball},
                                         SolidField<Dim>{}, Dim == 2 ? 4 : 8, 5u);
  REQUIRE(a.size() > 100);
  for (auto& x : a.x) x = centre + 0.92 * (x - centre);
  // a solid ball within a cell of the liquid's top (no shift below takes it across x = 0)
  Vec<Dim> solid_centre = centre;
  solid_centre[0] = 0.55;
  solid_centre[1] = 0.68;
  // the shift: 3 cells along every axis, or along x by -(0.2 + 3 dx) (the liquid across x = 0)
  Vec<Dim> shift = Vec<Dim>::Constant(3 * dx);
  if (periodic) shift[0] = -(0.2 + 3 * dx);
  Particles<Dim> b = a;
  for (auto& x : b.x) x = grid.wrap_position(Vec<Dim>(x + shift));
  const SolidField<Dim> solid_a = solid_ball<Dim>(solid_centre, 0.08);
  const SolidField<Dim> solid_b = solid_ball<Dim>(Vec<Dim>(solid_centre + shift), 0.08);
  const Particles<Dim> start_a = a, start_b = b;
  const DensityProjectionStats sa =
      project_particle_density(a, grid, half_lattice(grid), fluid, solid_a, boundary);
  const DensityProjectionStats sb =
      project_particle_density(b, grid, half_lattice(grid), fluid, solid_b, boundary);
  INFO("dim " << Dim << (periodic ? ", periodic x" : "") << ": unknowns " << sa.cells << " / "
              << sb.cells << ", largest move " << sa.max_move / dx << " dx");
  CHECK(sa.cells == sb.cells);
  CHECK(sa.iterations == sb.iterations);
  CHECK(sa.max_move > 0.01 * dx);
  CHECK(std::abs(sa.error_before - sb.error_before) < 1e-9 * sa.error_before);
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    Vec<Dim> da = a.x[i] - start_a.x[i], db = b.x[i] - start_b.x[i];
    for (int ax = 0; ax < Dim; ++ax) {
      // a particle wrapped by the move differs by the period
      if (periodic && ax == 0) {
        da[ax] -= std::round(da[ax]);
        db[ax] -= std::round(db[ax]);
      }
    }
    worst = std::max(worst, (da - db).norm());
  }
  INFO("largest difference of the moves " << worst / dx << " dx");
  CHECK(worst < 1e-9 * dx);
}

/// SurfaceDeficits::to_solve (the volume correction through the solve, docs/particles.md): the
/// projection moves the particles as `none` does, bit for bit, and lists the surface band's
/// deficits that `all` would have corrected (e < 0, cells increasing) for the next solve.
template <int Dim>
void check_projection_lists_surface_deficits() {
  const int n = Dim == 2 ? 32 : 16;
  const MacGrid<Dim> grid = unit_grid<Dim>(n, false);
  const std::array<BoundaryType, 2 * Dim> boundary = walls<Dim>();
  VectorX fluid = VectorX::Ones(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (grid.is_boundary_face(axis, coord)) fluid[f] = 0.0;
  }
  const Vec<Dim> centre = Vec<Dim>::Constant(0.5);
  auto ball = std::make_shared<TestBall<Dim>>(centre, 0.25);
  Particles<Dim> start = seed_particles<Dim>(grid, {liquid_spec<Dim>(centre)}, {ball},
                                             SolidField<Dim>{}, Dim == 2 ? 4 : 8, 3u);
  REQUIRE(start.size() > 100);
  // stretched: sparser than the level set says near the surface, so the band holds deficits
  for (auto& x : start.x) x = centre + 1.06 * (x - centre);
  Particles<Dim> none = start, listed = start, all = start;
  const DensityProjectionStats s_none = project_particle_density(
      none, grid, half_lattice(grid), fluid, SolidField<Dim>{}, boundary, 1, SurfaceDeficits::none);
  const DensityProjectionStats s_listed =
      project_particle_density(listed, grid, half_lattice(grid), fluid, SolidField<Dim>{},
                               boundary, 1, SurfaceDeficits::to_solve);
  project_particle_density(all, grid, half_lattice(grid), fluid, SolidField<Dim>{}, boundary, 1,
                           SurfaceDeficits::all);
  INFO("dim " << Dim << ": " << s_listed.surface_deficits.size() << " deficits listed");
  CHECK(s_none.surface_deficits.empty());
  REQUIRE(!s_listed.surface_deficits.empty());
  double worst = 0.0, differs = 0.0;
  for (std::size_t i = 0; i < start.size(); ++i) {
    worst = std::max(worst, (listed.x[i] - none.x[i]).norm());
    differs = std::max(differs, (all.x[i] - none.x[i]).norm());
  }
  CHECK(worst == 0.0);
  CHECK(differs > 1e-3 * grid.dx());  // `all` corrects the listed deficits by moves
  for (std::size_t k = 0; k < s_listed.surface_deficits.size(); ++k) {
    CHECK(s_listed.surface_deficits[k].second < 0.0);
    if (k > 0) CHECK(s_listed.surface_deficits[k].first > s_listed.surface_deficits[k - 1].first);
  }
}

}  // namespace

TEST_CASE("density projection: an evenly seeded block settles onto its particle volume",
          "[unit][property]") {
  check_projection_even_block<2>();
  check_projection_even_block<3>();
}

TEST_CASE("density projection: a compressed block regains its volume, never into solids",
          "[unit]") {
  check_projection_restores_compressed_block<2>();
  check_projection_restores_compressed_block<3>();
}

TEST_CASE("density projection: the cells beside a held (moving) body keep their error",
          "[unit]") {
  check_projection_holds_beside_moving_bodies<2>();
  check_projection_holds_beside_moving_bodies<3>();
}

TEST_CASE("density projection: water at rest in an open tank stays at rest", "[unit]") {
  check_projection_keeps_water_at_rest<2>();
  check_projection_keeps_water_at_rest<3>();
}

TEST_CASE("density projection: kept displacement storage over a moving, shrinking block equals "
          "fresh storage (p2g21)",
          "[unit]") {
  check_projection_kept_scratch<2>();
  check_projection_kept_scratch<3>();
  // (two24) spans the team zeroes in several blocks (the team exactly 3 threads: the core
  // monitor would take fewer on a busy machine)
  const bool monitor = core_monitor();
  set_core_monitor(false);
  CHECK(check_projection_kept_scratch<2>(256) > 2 * kParallelMinWork);
  set_core_monitor(monitor);
}

TEST_CASE("density projection: identical with 1, 2, 3 and 5 threads", "[unit]") {
  check_projection_deterministic<2>(false);
  check_projection_deterministic<3>(false);
  check_projection_deterministic<2>(true);
  check_projection_deterministic<3>(true);
}

namespace {

/// A ball of two liquids (x < 0.5: liquid 0), ~10 particles per cell at random positions with
/// unequal masses: in 3D on 24^3 cells about 2e4 particles, more than kParallelMinWork, so the
/// splats below leave their serial fall-backs.
template <int Dim>
Particles<Dim> two_liquid_ball(const MacGrid<Dim>& grid, int per_cell) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Particles<Dim> p;
  const double r = 0.35;
  const int want = static_cast<int>(per_cell * (Dim == 2 ? 3.14159 * r * r : 4.18879 * r * r * r) /
                                    grid.cell_volume());
  while (static_cast<int>(p.size()) < want) {
    Vec<Dim> x;
    for (int a = 0; a < Dim; ++a) x[a] = 0.15 + 0.7 * u(rng);
    if ((x - Vec<Dim>::Constant(0.5)).norm() > r) continue;
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back((0.8 + 0.4 * u(rng)) * 1000.0 * grid.cell_volume() / per_cell);
    p.density.push_back(1000.0);
    p.liquid.push_back(x[0] < 0.5 ? 0 : 1);
  }
  return p;
}

template <int Dim>
void check_splats_deterministic_above_serial_fallback() {
  const MacGrid<Dim> grid = unit_grid<Dim>(Dim == 2 ? 160 : 24);
  const Particles<Dim> start = two_liquid_ball<Dim>(grid, Dim == 2 ? 4 : 10);
  INFO("dim " << Dim << ", " << start.size() << " particles");
  REQUIRE(static_cast<long>(start.size()) > kParallelMinWork);
  const StressGrid<Dim> stress(grid);
  const std::vector<double> eta = {2.0, 8.0};
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX fluid = open_fluid_faces(grid);
  const SolidField<Dim> solid = solid_ball<Dim>(Vec<Dim>::Constant(0.88), 0.1);
  // the team exactly t threads (the core monitor would take fewer on a busy machine, and the
  // parallel paths would not run)
  const bool monitor = core_monitor();
  set_core_monitor(false);
  const int threads = omp_get_max_threads();
  struct Result {
    VectorX cells, dofs, dofs_kept, phi;
    Particles<Dim> moved, moved_by_solid, corrected, corrected_kept;
    long cells_projected = 0;
    VectorX faces, faces_again, extrapolated;
    std::vector<char> valid;
  };
  // correct_positions' buffers, kept from one run to the next (filled by other team sizes)
  PositionCorrectionBuffers kept;
  // stress_viscosity_into's vector, kept from one run to the next at its size, every entry NaN
  // before each call (an entry it did not write would stay NaN)
  VectorX kept_eta;
  const auto run = [&](int t) {
    omp_set_num_threads(t);
    Result r;
    r.cells = cell_viscosity(grid, start, eta);
    r.dofs = stress_viscosity(stress, start, eta);
    if (kept_eta.size() > 0) kept_eta.setConstant(std::numeric_limits<double>::quiet_NaN());
    stress_viscosity_into(stress, start, eta, kept_eta);
    r.dofs_kept = kept_eta;
    r.phi = liquid_phi_on_lattice(start, grid, lattice, walls<Dim>());
    r.moved = start;
    r.cells_projected =
        project_particle_density(r.moved, grid, lattice, fluid, SolidField<Dim>{}, walls<Dim>(), 1)
            .cells;
    r.moved_by_solid = start;
    project_particle_density(r.moved_by_solid, grid, lattice, fluid, solid, walls<Dim>(), 1);
    // position correction (the ball holds more than the rest density: compressed particles)
    r.corrected = start;
    correct_positions(r.corrected, grid, 0.01, solid, walls<Dim>());
    r.corrected_kept = start;
    correct_positions(r.corrected_kept, grid, 0.01, solid, walls<Dim>(), &kept);
    // the faces' liquid fractions: all faces zeroed first, then (a second level set, the same
    // written boxes) only what the first call wrote
    LatticeSigns<Dim> signs;
    classify_lattice_cells(grid, lattice, r.phi, signs);
    std::array<WrittenBox<Dim>, Dim> written;
    face_negative_fractions<Dim>(grid, lattice, r.phi, signs, r.faces, &written);
    const VectorX phi_moved = liquid_phi_on_lattice(r.moved, grid, lattice, walls<Dim>());
    LatticeSigns<Dim> signs_moved;
    classify_lattice_cells(grid, lattice, phi_moved, signs_moved);
    r.faces_again = r.faces;
    face_negative_fractions<Dim>(grid, lattice, phi_moved, signs_moved, r.faces_again, &written);
    // the velocity extrapolated from the faces inside the ball, three layers out
    r.extrapolated = VectorX::Zero(grid.num_faces());
    r.valid.assign(grid.num_faces(), 0);
    for (int f = 0; f < grid.num_faces(); ++f) {
      if (!(r.faces[f] > 0.5)) continue;
      r.valid[f] = 1;
      r.extrapolated[f] = std::sin(0.37 * f) + 0.1 * (f % 7);
    }
    extrapolate_velocity(grid, r.extrapolated, r.valid, 3);
    omp_set_num_threads(threads);
    return r;
  };
  const Result one = run(1);
  // the kept buffers change nothing (their first use here, and after every team size below)
  {
    long kept_differ = 0;
    for (std::size_t i = 0; i < start.size(); ++i)
      kept_differ += one.corrected_kept.x[i] != one.corrected.x[i];
    CHECK(kept_differ == 0);
    CHECK(one.dofs_kept.size() == stress.num_dofs());
    CHECK(differing(one.dofs_kept, one.dofs) == 0);
  }
  // the projection's row assembly leaves its serial fall-back too (its team is sized by the
  // rows' 2 Dim + 1 entry slots: 10308 rows in 2D, 4118 in 3D)
  CHECK(one.cells_projected * (2 * Dim + 1) > kParallelMinWork);
  // the cells' splat is the diagonal stress components' (stress_viscosity makes it once)
  for (int k = 0; k < Dim; ++k) {
    INFO("diagonal component " << k);
    CHECK(differing(VectorX(one.dofs.segment(stress.offset(k), stress.num_dofs(k))), one.cells) == 0);
  }
  // two liquids: the field is not constant (a constant would hide a wrong order of the sums)
  CHECK(one.cells.maxCoeff() > one.cells.minCoeff());
  for (int t : {2, 3, 5}) {
    INFO(t << " threads");
    const Result other = run(t);
    CHECK(differing(other.cells, one.cells) == 0);
    CHECK(differing(other.dofs, one.dofs) == 0);
    CHECK(differing(other.dofs_kept, one.dofs) == 0);
    CHECK(differing(other.phi, one.phi) == 0);
    // particles whose positions differ between two sets
    const auto positions_differ = [&](const auto& a, const auto& b) {
      long n = 0;
      for (std::size_t i = 0; i < start.size(); ++i) n += a.x[i] != b.x[i];
      return n;
    };
    CHECK(positions_differ(one.moved, start) > 0);
    CHECK(positions_differ(other.moved, one.moved) == 0);
    CHECK(positions_differ(other.moved_by_solid, one.moved_by_solid) == 0);
    CHECK(positions_differ(one.corrected, start) > 0);
    CHECK(positions_differ(other.corrected, one.corrected) == 0);
    CHECK(positions_differ(other.corrected_kept, one.corrected) == 0);
    CHECK(differing(other.faces, one.faces) == 0);
    CHECK(differing(other.faces_again, one.faces_again) == 0);
    CHECK(differing(other.extrapolated, one.extrapolated) == 0);
    CHECK(other.valid == one.valid);
  }
  // the passes above their serial fall-backs: the face lattices and the particles
  CHECK(grid.num_faces() > kParallelMinWork);
  CHECK(differing(one.faces_again, one.faces) > 0);
  CHECK(std::count(one.valid.begin(), one.valid.end(), 1) >
        std::count_if(one.faces.data(), one.faces.data() + one.faces.size(),
                      [](double w) { return w > 0.5; }));
  set_core_monitor(monitor);
}

}  // namespace

TEST_CASE("viscosity, level set and density projection splats, position correction, the faces'"
          " liquid fractions and the velocity extrapolation of ~2e4 particles: identical with "
          "1, 2, 3 and 5 threads (position correction also with buffers kept across calls); the "
          "cells' viscosity is the diagonal stress components'",
          "[unit]") {
  check_splats_deterministic_above_serial_fallback<2>();
  check_splats_deterministic_above_serial_fallback<3>();
}

TEST_CASE("density projection: the same moves after a shift across the band's tiles",
          "[unit][property]") {
  check_projection_follows_a_shift_across_tiles<2>(false);
  check_projection_follows_a_shift_across_tiles<3>(false);
  check_projection_follows_a_shift_across_tiles<2>(true);
  // (3D across the periodic seam the two give 889 and 888 unknowns and moves 0.014 dx apart,
  // with the band and with the former pass over the whole grid alike: the shifted positions
  // differ by rounding, and the unknowns, cut off sharply at rho~ > 0 or T > 0, by one cell)
}

TEMPLATE_TEST_CASE_SIG("stress_viscosity of all zeros is +0 and of the only liquid's indicator is "
                       "1 at every DOF, bit for bit (the simulation takes both as constants)",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  const MacGrid<Dim> grid = monolith::testing::unit_grid<Dim>(Dim == 2 ? 16 : 8);
  const StressGrid<Dim> stress(grid);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.2, 0.6);
  Particles<Dim> p;
  for (int i = 0; i < 300; ++i) {
    Vec<Dim> x;
    for (int a = 0; a < Dim; ++a) x[a] = u(rng);
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(0.1 + 0.37 * u(rng));  // unequal masses: the ratios are not trivially 1
    p.density.push_back(1000.0);
    p.liquid.push_back(0);
  }
  const VectorX ones = stress_viscosity(stress, p, {1.0});
  const VectorX zeros = stress_viscosity(stress, p, {0.0});
  int differ = 0;
  for (int i = 0; i < stress.num_dofs(); ++i) {
    differ += ones[i] != 1.0;
    differ += zeros[i] != 0.0 || std::signbit(zeros[i]);
  }
  CHECK(differ == 0);
  CHECK(liquid_stress_fractions(stress, p, 1).front() == ones);
}

TEST_CASE("density projection: to_solve lists the surface band's deficits and moves as none does",
          "[unit]") {
  check_projection_lists_surface_deficits<2>();
  check_projection_lists_surface_deficits<3>();
}
TEST_CASE("balanced_slab_bounds: bounds that cover the output layers in order and give the "
          "least largest visit count (against every split, 2 and 3 slabs)",
          "[unit]") {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> draw(0, 40);
  for (int trial = 0; trial < 200; ++trial) {
    const int layers = 1 + trial % 17;
    std::vector<long> count(layers);
    for (long& c : count) c = trial % 5 == 0 && draw(rng) < 20 ? 0 : draw(rng);
    const int reach_lo = -(trial % 3), reach_hi = (trial / 3) % 3;
    const int outputs = layers + (trial % 2);
    // the particles a slab [a, b) visits: layers within reach of its outputs
    const auto visited = [&](int a, int b) {
      long v = 0;
      if (a >= b) return v;
      for (int l = 0; l < layers; ++l)
        if (l + reach_hi >= a && l + reach_lo <= b - 1) v += count[l];
      return v;
    };
    for (int slabs : {2, 3}) {
      INFO("trial " << trial << ", slabs " << slabs);
      const std::vector<int> first = balanced_slab_bounds(count, outputs, slabs, reach_lo, reach_hi);
      REQUIRE(static_cast<int>(first.size()) == slabs + 1);
      CHECK(first.front() == 0);
      CHECK(first.back() == outputs);
      long largest = 0;
      for (int s = 0; s < slabs; ++s) {
        CHECK(first[s] <= first[s + 1]);
        largest = std::max(largest, visited(first[s], first[s + 1]));
      }
      long best = std::numeric_limits<long>::max();
      for (int b1 = 0; b1 <= outputs; ++b1)
        for (int b2 = b1; b2 <= (slabs == 3 ? outputs : b1); ++b2) {
          const long m = slabs == 2 ? std::max(visited(0, b1), visited(b1, outputs))
                                    : std::max({visited(0, b1), visited(b1, b2), visited(b2, outputs)});
          best = std::min(best, m);
        }
      CHECK(largest == best);
    }
  }
}
