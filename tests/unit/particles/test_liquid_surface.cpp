// Tests of the Zhu & Bridson (2005) liquid surface reconstructed from particles
// (liquid_phi_on_lattice): sign, position of the zero level set, enclosed volume, determinism.
#include <omp.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <random>

#include "reference/particles/particles.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

template <int Dim>
LiquidSpec water_spec(const Vec<Dim>& centre) {
  LiquidSpec spec;
  spec.name = "water";
  spec.density = 1000.0;
  spec.shape.type = ShapeType::sphere;
  spec.shape.center.assign(centre.data(), centre.data() + Dim);
  return spec;
}

template <int Dim>
int default_per_cell() {
  return Dim == 2 ? 4 : 8;
}

/// Volume of {phi < 0}: each lattice cell is subsampled m^Dim times with multilinear phi.
template <int Dim>
double negative_volume(const SampleLattice<Dim>& lattice, const VectorX& phi, int m) {
  const VecI<Dim> cells = (lattice.dims.array() - 1).matrix();
  const int ncell = cells.prod();
  const int nsub = static_cast<int>(std::pow(m, Dim));
  const double sub_volume = std::pow(lattice.spacing / m, Dim);
  double volume = 0.0;
  for (int k = 0; k < ncell; ++k) {
    VecI<Dim> c;
    int rest = k;
    for (int a = 0; a < Dim; ++a) {
      c[a] = rest % cells[a];
      rest /= cells[a];
    }
    for (int s = 0; s < nsub; ++s) {
      Vec<Dim> x = lattice.position(c);
      int r = s;
      for (int a = 0; a < Dim; ++a) {
        x[a] += (r % m + 0.5) / m * lattice.spacing;
        r /= m;
      }
      if (lattice.interpolate(phi, x) < 0.0) volume += sub_volume;
    }
  }
  return volume;
}

/// Zero crossing of phi along the ray centre + t dir, t in [0, t_max] (bisection after a scan).
template <int Dim>
double zero_crossing(const SampleLattice<Dim>& lattice, const VectorX& phi, const Vec<Dim>& centre,
                     const Vec<Dim>& dir, double t_max) {
  const int steps = 400;
  double t0 = 0.0;
  for (int i = 1; i <= steps; ++i) {
    const double t1 = t_max * i / steps;
    if (lattice.interpolate(phi, centre + t1 * dir) >= 0.0) {
      double a = t0, b = t1;
      for (int it = 0; it < 60; ++it) {
        const double mid = 0.5 * (a + b);
        (lattice.interpolate(phi, centre + mid * dir) < 0.0 ? a : b) = mid;
      }
      return 0.5 * (a + b);
    }
    t0 = t1;
  }
  return t_max;
}

template <int Dim>
void check_ball_surface(int n) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const double dx = grid.dx();
  const Vec<Dim> centre = Vec<Dim>::Constant(0.5);
  const double radius = 0.3;
  auto ball = std::make_shared<TestBall<Dim>>(centre, radius);
  const Particles<Dim> particles = seed_particles<Dim>(
      grid, {water_spec<Dim>(centre)}, {ball}, SolidField<Dim>{}, default_per_cell<Dim>(), 7u);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX phi =
      liquid_phi_on_lattice(particles, grid, lattice, all_boundaries<Dim>(BoundaryType::wall));

  // sign: inside points negative, outside points positive
  for (int k = 0; k < lattice.size(); ++k) {
    const double d = ball->distance(lattice.position(lattice.coord(k)));
    if (d < -0.75 * dx) REQUIRE(phi[k] < 0.0);
    if (d > 0.75 * dx) REQUIRE(phi[k] > 0.0);
  }

  // zero crossing along many directions within 0.3 dx of the true radius
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  double worst = 0.0;
  for (int i = 0; i < 200; ++i) {
    Vec<Dim> dir;
    for (int a = 0; a < Dim; ++a) dir[a] = normal(rng);
    dir.normalize();
    const double t = zero_crossing(lattice, phi, centre, dir, 0.49);
    worst = std::max(worst, std::abs(t - radius));
  }
  INFO("dim " << Dim << " worst zero-crossing error / dx = " << worst / dx);
  CHECK(worst < 0.3 * dx);

  // enclosed volume within 3% of the ball's
  const double exact = Dim == 2 ? M_PI * radius * radius : 4.0 / 3.0 * M_PI * std::pow(radius, 3);
  const double volume = negative_volume(lattice, phi, Dim == 2 ? 8 : 3);
  INFO("dim " << Dim << " volume / exact = " << volume / exact);
  CHECK(std::abs(volume / exact - 1.0) < 0.03);
}

template <int Dim>
void check_block_boundary(int n) {
  // a block aligned with cell faces: the zero level set must lie on its faces
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const double dx = grid.dx();
  const Vec<Dim> centre = Vec<Dim>::Constant(0.5);
  const Vec<Dim> half = Vec<Dim>::Constant(0.25);
  auto block = std::make_shared<TestBox<Dim>>(centre, half);
  const Particles<Dim> particles = seed_particles<Dim>(
      grid, {water_spec<Dim>(centre)}, {block}, SolidField<Dim>{}, default_per_cell<Dim>(), 11u);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX phi =
      liquid_phi_on_lattice(particles, grid, lattice, all_boundaries<Dim>(BoundaryType::wall));
  double mean_error = 0.0, worst = 0.0;
  int count = 0;
  // rays from the centre through each face, at several offsets across the face
  for (int a = 0; a < Dim; ++a)
    for (int side = -1; side <= 1; side += 2)
      for (int i = -3; i <= 3; ++i) {
        Vec<Dim> start = centre;
        start[(a + 1) % Dim] += i * 0.03;
        Vec<Dim> dir = Vec<Dim>::Zero();
        dir[a] = side;
        const double t = zero_crossing(lattice, phi, start, dir, 0.45);
        mean_error += t - 0.25;
        worst = std::max(worst, std::abs(t - 0.25));
        ++count;
      }
  mean_error /= count;
  INFO("dim " << Dim << " block: mean offset / dx = " << mean_error / dx
              << ", worst / dx = " << worst / dx);
  CHECK(std::abs(mean_error) < 0.1 * dx);
  CHECK(worst < 0.25 * dx);

  // volume of the block
  const double exact = std::pow(0.5, Dim);
  const double volume = negative_volume(lattice, phi, Dim == 2 ? 8 : 3);
  INFO("dim " << Dim << " block volume / exact = " << volume / exact);
  CHECK(std::abs(volume / exact - 1.0) < 0.03);
}

}  // namespace

TEST_CASE("zhu-bridson surface of a seeded ball: sign, zero crossing, volume",
          "[unit][validation]") {
  check_ball_surface<2>(32);
  check_ball_surface<3>(24);
}

TEST_CASE("zhu-bridson surface of a uniform block lies on the block boundary",
          "[unit][validation]") {
  check_block_boundary<2>(32);
  check_block_boundary<3>(24);
}

namespace {

template <int Dim>
void check_surface_determinism_and_periodicity() {
  // a slab of liquid straddling the periodic x boundary: x in [0.8, 1.2] mod 1
  std::array<bool, Dim> periodic{};
  periodic[0] = true;
  const int n = Dim == 2 ? 32 : 16;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
  const double dx = grid.dx();
  Particles<Dim> particles;
  const int sub = 2 * n;
  for (int k = 0; k < static_cast<int>(std::pow(sub, Dim)); ++k) {
    Vec<Dim> x;
    int r = k;
    for (int a = 0; a < Dim; ++a) {
      x[a] = (r % sub + 0.5) / sub;
      r /= sub;
    }
    const double xs = std::fmod(x[0] + 0.5, 1.0);  // distance from 0.5 across the wrap
    if (std::abs(xs - 0.5) > 0.2 || x[1] > 0.5) continue;
    particles.x.push_back(x);
    particles.v.push_back(Vec<Dim>::Zero());
    particles.c.push_back(Mat<Dim>::Zero());
    particles.mass.push_back(1000.0 * grid.cell_volume() / std::pow(2, Dim));
    particles.density.push_back(1000.0);
    particles.liquid.push_back(0);
  }
  const SampleLattice<Dim> lattice = half_lattice(grid);
  // periodic along x, walls elsewhere: the slab rests on the wall y = 0 (mirror images there)
  std::array<BoundaryType, 2 * Dim> boundary = all_boundaries<Dim>(BoundaryType::wall);
  boundary[0] = boundary[1] = BoundaryType::periodic;
  omp_set_num_threads(1);
  const VectorX phi1 = liquid_phi_on_lattice(particles, grid, lattice, boundary);
  omp_set_num_threads(2);
  const VectorX phi2 = liquid_phi_on_lattice(particles, grid, lattice, boundary);
  // bitwise identical for any thread count
  REQUIRE((phi1.array() == phi2.array()).all());

  // mirror symmetry about x = 0 (the wrap): phi(x) = phi(1 - x)
  double asym = 0.0;
  for (int k = 0; k < lattice.size(); ++k) {
    VecI<Dim> i = lattice.coord(k);
    i[0] = lattice.dims[0] - 1 - i[0];
    asym = std::max(asym, std::abs(phi1[k] - phi1[lattice.index(i)]));
  }
  CHECK(asym < 1e-12);
  // the interfaces at x = 0.2 and x = 0.8, inside across the wrap, outside in the middle
  Vec<Dim> probe = Vec<Dim>::Constant(0.25);
  probe[0] = 0.0;
  CHECK(lattice.interpolate(phi1, probe) < 0.0);
  probe[0] = 0.5;
  CHECK(lattice.interpolate(phi1, probe) > 0.0);
  probe[0] = 1.0;
  CHECK(lattice.interpolate(phi1, probe) < 0.0);
  Vec<Dim> start = probe;
  start[0] = 0.0;
  Vec<Dim> dir = Vec<Dim>::Zero();
  dir[0] = 1.0;
  CHECK(std::abs(zero_crossing(lattice, phi1, start, dir, 0.45) - 0.2) < 0.3 * dx);
}

/// Still water in a walled box (the lower half of the unit box): the cells under the surface,
/// those along the walls included, must be full, else the pressure solve sees a lighter column
/// along every wall and drives a flow in liquid at rest.
template <int Dim>
void check_liquid_wets_walls(int n) {
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  Vec<Dim> centre = Vec<Dim>::Constant(0.5), half = Vec<Dim>::Constant(0.5);
  centre[1] = half[1] = 0.25;
  auto block = std::make_shared<TestBox<Dim>>(centre, half);
  const Particles<Dim> particles = seed_particles<Dim>(
      grid, {water_spec<Dim>(centre)}, {block}, SolidField<Dim>{}, default_per_cell<Dim>(), 5u);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary = all_boundaries<Dim>(BoundaryType::wall);
  boundary[3] = BoundaryType::open;  // open top
  const VectorX fraction =
      liquid_cell_weights(grid, lattice, liquid_phi_on_lattice(particles, grid, lattice, boundary));
  // the same particles without walls (every side open): no images
  const VectorX unmirrored = liquid_cell_weights(
      grid, lattice,
      liquid_phi_on_lattice(particles, grid, lattice, all_boundaries<Dim>(BoundaryType::open)));
  double lowest = 1.0, lowest_unmirrored = 1.0;
  double surface_min = 1.0, surface_max = 0.0;
  for (int c = 0; c < grid.num_cells(); ++c) {
    const VecI<Dim> ci = grid.cell_coord(c);
    if (ci[1] < n / 2 - 1) {  // below the surface row
      lowest = std::min(lowest, fraction[c]);
      lowest_unmirrored = std::min(lowest_unmirrored, unmirrored[c]);
    } else if (ci[1] == n / 2) {  // the cell row just above the surface at y = 0.5
      surface_min = std::min(surface_min, fraction[c]);
      surface_max = std::max(surface_max, fraction[c]);
    }
  }
  const double surface_spread = surface_max - surface_min;
  INFO("dim " << Dim << ": lowest fraction under the surface " << lowest << " (without images "
              << lowest_unmirrored << "), cell row above the surface " << surface_min << " .. "
              << surface_max);
  CHECK(lowest == 1.0);
  // what the images fix: without them the wall cells read as partly air (measured 0.79 in 2D,
  // 0.76 in 3D; with them the cell row above the surface holds at most 0.07 / 0.08 of liquid)
  CHECK(lowest_unmirrored < 0.95);
  // the surface stays within a fifth of a cell of y = 0.5 everywhere, at the walls too
  CHECK(surface_max < 0.2);
  CHECK(surface_spread < 0.2);
}

}  // namespace

TEST_CASE("liquid at rest in a walled box fills the cells along the walls", "[unit]") {
  check_liquid_wets_walls<2>(32);
  check_liquid_wets_walls<3>(12);
}

TEST_CASE("zhu-bridson surface is deterministic across thread counts and wraps periodic axes",
          "[unit][property]") {
  check_surface_determinism_and_periodicity<2>();
  check_surface_determinism_and_periodicity<3>();
}

TEST_CASE("zhu-bridson surface without particles is positive everywhere", "[unit]") {
  const MacGrid<2> grid = unit_grid<2>(8);
  const VectorX phi = liquid_phi_on_lattice(Particles<2>{}, grid, half_lattice(grid),
                                            all_boundaries<2>(BoundaryType::wall));
  REQUIRE(phi.size() == half_lattice(grid).size());
  CHECK(phi.minCoeff() > 0.0);
}

TEST_CASE("zhu-bridson surface on a 64^3 grid (timing)", "[.][perf]") {
  const MacGrid<3> grid = unit_grid<3>(64);
  const Vec<3> centre = Vec<3>::Constant(0.5);
  auto ball = std::make_shared<TestBall<3>>(centre, 0.4);
  const Particles<3> particles =
      seed_particles<3>(grid, {water_spec<3>(centre)}, {ball}, SolidField<3>{}, 8, 1u);
  const double t0 = omp_get_wtime();
  const VectorX phi = liquid_phi_on_lattice(particles, grid, half_lattice(grid),
                                            all_boundaries<3>(BoundaryType::wall));
  const double t1 = omp_get_wtime();
  WARN("64^3 grid, " << particles.size() << " particles: seeding done, surface " << (t1 - t0)
                     << " s with " << omp_get_max_threads() << " threads");
  REQUIRE(phi.size() == 129 * 129 * 129);
}

namespace {

/// The splat's sums live in tiles of 8^Dim lattice points made where particles reach: a blob
/// moved by 3 lattice points (not a multiple of the tile) gives the same level set moved by 3
/// points, so no tile a particle reaches is missing wherever the tile borders fall.
template <int Dim>
void check_surface_follows_a_shift_across_tiles() {
  const int n = Dim == 2 ? 40 : 24;
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const Vec<Dim> centre = Vec<Dim>::Constant(0.43);
  auto ball = std::make_shared<TestBall<Dim>>(centre, 0.21);
  const Particles<Dim> particles = seed_particles<Dim>(grid, {water_spec<Dim>(centre)}, {ball},
                                                       SolidField<Dim>{}, default_per_cell<Dim>(), 3u);
  REQUIRE(particles.size() > 100);
  const auto open = all_boundaries<Dim>(BoundaryType::open);
  const VectorX phi = liquid_phi_on_lattice(particles, grid, lattice, open);
  Particles<Dim> moved = particles;
  const int shift = 3;
  for (auto& x : moved.x) x += Vec<Dim>::Constant(shift * lattice.spacing);
  // the overload into a buffer of the wrong size gives the same values as the returning one
  VectorX phi_moved = VectorX::Constant(7, -1.0);
  liquid_phi_on_lattice(moved, grid, lattice, open, SolidField<Dim>{}, phi_moved);
  REQUIRE(phi_moved.size() == lattice.size());
  REQUIRE(phi_moved == liquid_phi_on_lattice(moved, grid, lattice, open));
  const double far = phi.maxCoeff();
  int inside = 0, compared = 0;
  for (int k = 0; k < lattice.size(); ++k) {
    const VecI<Dim> c = lattice.coord(k);
    const VecI<Dim> d = (c.array() + shift).matrix();
    if ((d.array() >= lattice.dims.array()).any()) continue;
    const double a = phi[k], b = phi_moved[lattice.index(d)];
    if (a == far) {
      REQUIRE(b == far);
    } else {
      REQUIRE(std::abs(a - b) < 1e-12);
    }
    inside += a < 0.0 ? 1 : 0;
    ++compared;
  }
  CHECK(inside > 0);
  CHECK(compared > lattice.size() / 2);
}

}  // namespace

TEST_CASE("zhu-bridson surface moves with its particles across the band's tile borders",
          "[unit][property]") {
  check_surface_follows_a_shift_across_tiles<2>();
  check_surface_follows_a_shift_across_tiles<3>();
}
