// The first air layer of u* before a solve (reference/sim/air_velocity.hpp): exact for a linear
// velocity field, equal to the neighbour average where it falls back to it, the same for any
// team and with or without boxes (2D and 3D). And the measurement behind docs/validation.md's
// rotating blob (hidden: [.measure]).
#include <omp.h>

#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/particles/particles.hpp"
#include "reference/sim/air_velocity.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

template <int Dim>
MacGrid<Dim> make_grid(int n, bool periodic_x = false) {
  std::array<bool, Dim> periodic{};
  periodic[0] = periodic_x;
  return MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
}

/// the centre of face f
template <int Dim>
Vec<Dim> face_centre(const MacGrid<Dim>& grid, int f) {
  const auto [axis, coord] = grid.face_coord(f);
  Vec<Dim> x = grid.origin() + (coord.template cast<double>().array() + 0.5).matrix() * grid.dx();
  x[axis] -= 0.5 * grid.dx();
  return x;
}

/// a linear field (a rigid rotation about z plus a strain and a translation), component `axis`
template <int Dim>
double linear(const Vec<Dim>& x, int axis) {
  const double X = x[0] - 0.5, Y = x[1] - 0.5, Z = Dim == 3 ? x[Dim - 1] - 0.5 : 0.0;
  if (axis == 0) return 0.3 - 3.0 * Y + 0.7 * X + 0.2 * Z;
  if (axis == 1) return -0.1 + 3.0 * X - 0.4 * Y;
  return 0.05 + 0.6 * X - 0.3 * Z;
}

/// faces whose centre lies in the ball of radius r about the box's centre: valid, u linear;
/// the others invalid with u = NaN (a read of one shows)
template <int Dim>
void ball_field(const MacGrid<Dim>& grid, double r, VectorX& u, std::vector<char>& valid) {
  const int nf = grid.num_faces();
  u = VectorX::Constant(nf, std::nan(""));
  valid.assign(nf, 0);
  for (int f = 0; f < nf; ++f) {
    const Vec<Dim> x = face_centre(grid, f);
    if ((x - Vec<Dim>::Constant(0.5)).norm() < r) {
      valid[f] = 1;
      u[f] = linear<Dim>(x, grid.face_coord(f).first);
    }
  }
}

/// the boxes of face coordinates of the valid faces, per axis
template <int Dim>
void valid_boxes(const MacGrid<Dim>& grid, const std::vector<char>& valid,
                 std::array<VecI<Dim>, Dim>& lo, std::array<VecI<Dim>, Dim>& hi) {
  for (int a = 0; a < Dim; ++a) {
    lo[a] = grid.face_dims(a);
    hi[a] = VecI<Dim>::Constant(-1);
  }
  for (int f = 0; f < grid.num_faces(); ++f)
    if (valid[f]) {
      const auto [a, c] = grid.face_coord(f);
      lo[a] = lo[a].cwiseMin(c);
      hi[a] = hi[a].cwiseMax(c);
    }
}

template <int Dim>
void check_linear_exact(int n) {
  const MacGrid<Dim> grid = make_grid<Dim>(n);
  VectorX u;
  std::vector<char> valid;
  ball_field(grid, 0.3, u, valid);
  const std::vector<char> given = valid;
  VectorX u_old = u;
  std::vector<char> valid_old = valid;
  extrapolate_velocity(grid, u_old, valid_old, 1);
  extrapolate_air_velocity(grid, u, valid, 1);
  // the same faces as the neighbour average's first ring, every one exact
  CHECK(valid == valid_old);
  double worst = 0.0, worst_old = 0.0;
  int filled = 0;
  for (int f = 0; f < grid.num_faces(); ++f) {
    if (given[f] || !valid[f]) continue;
    ++filled;
    const double exact = linear<Dim>(face_centre(grid, f), grid.face_coord(f).first);
    worst = std::max(worst, std::abs(u[f] - exact));
    worst_old = std::max(worst_old, std::abs(u_old[f] - exact));
  }
  CHECK(filled > 0);
  CHECK(worst < 1e-12);
  CHECK(worst_old > 1e-3);  // averaging is not exact there (what the new fill is for)
  // a second ring (averaging) fills further faces with finite values
  VectorX u2;
  std::vector<char> valid2;
  ball_field(grid, 0.3, u2, valid2);
  extrapolate_air_velocity(grid, u2, valid2, 2);
  int ring2 = 0;
  for (int f = 0; f < grid.num_faces(); ++f)
    if (valid2[f] && !valid[f]) {
      ++ring2;
      CHECK(std::isfinite(u2[f]));
    }
  CHECK(ring2 > 0);
}

template <int Dim>
void check_fallback(int n) {
  // isolated valid faces: no face has two valid faces in a row or valid faces on both sides,
  // so every filled face takes the neighbour average, bit for bit
  const MacGrid<Dim> grid = make_grid<Dim>(n, true);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> dist(-1.0, 1.0);
  VectorX u = VectorX::Zero(grid.num_faces());
  std::vector<char> valid(grid.num_faces(), 0);
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [a, c] = grid.face_coord(f);
    bool pick = true;
    for (int b = 0; b < Dim; ++b) pick = pick && c[b] % 5 == 0;
    if (pick) {
      valid[f] = 1;
      u[f] = dist(rng);
    }
  }
  VectorX u_old = u;
  std::vector<char> valid_old = valid;
  extrapolate_velocity(grid, u_old, valid_old, 2);
  extrapolate_air_velocity(grid, u, valid, 2);
  CHECK(valid == valid_old);
  CHECK((u.array() == u_old.array()).all());
}

template <int Dim>
void check_teams(int n) {
  // a noisy field in a ball, periodic along x: 1 and 3 threads, with and without boxes
  const MacGrid<Dim> grid = make_grid<Dim>(n, true);
  VectorX u0;
  std::vector<char> valid0;
  ball_field(grid, 0.35, u0, valid0);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> dist(-0.1, 0.1);
  for (int f = 0; f < grid.num_faces(); ++f)
    if (valid0[f]) u0[f] += dist(rng);
  std::array<VecI<Dim>, Dim> lo, hi;
  valid_boxes<Dim>(grid, valid0, lo, hi);
  const int threads = omp_get_max_threads();
  std::vector<VectorX> results;
  std::vector<std::vector<char>> flags;
  for (int team : {1, 3})
    for (bool boxed : {false, true}) {
      omp_set_num_threads(team);
      VectorX u = u0;
      std::vector<char> valid = valid0;
      if (boxed)
        extrapolate_air_velocity<Dim>(grid, u, valid, 2, &lo, &hi);
      else
        extrapolate_air_velocity(grid, u, valid, 2);
      results.push_back(u);
      flags.push_back(valid);
    }
  omp_set_num_threads(threads);
  for (std::size_t k = 1; k < results.size(); ++k) {
    CHECK(flags[k] == flags[0]);
    // NaN stays where no ring reached; compare the bits of the filled values
    bool same = true;
    for (int f = 0; f < grid.num_faces(); ++f)
      if (flags[0][f]) same = same && results[k][f] == results[0][f];
    CHECK(same);
  }
}

}  // namespace

TEST_CASE("the first air layer is exact for a linear velocity field (2D and 3D)", "[sim]") {
  check_linear_exact<2>(40);
  check_linear_exact<3>(16);
}

TEST_CASE("the first air layer equals the neighbour average where it falls back (2D and 3D)",
          "[sim]") {
  check_fallback<2>(30);
  check_fallback<3>(15);
}

TEST_CASE("the air fill is the same for 1 and 3 threads, with and without boxes (2D and 3D)",
          "[sim]") {
  check_teams<2>(160);  // above kParallelMinWork faces in the grown boxes
  check_teams<3>(32);
}

// The measurement of docs/validation.md's rotating blob: a free disk (r = 0.2, omega = 3, no
// gravity) for 0.4 s at 64^2, per eta: omega at the probes, the particles' angular momentum L
// about the centre of mass, their moment of inertia I and L / I.
TEST_CASE("rotating blob: omega, L and I over 0.4 s", "[.measure]") {
  const int n = 64;
  for (double eta : {0.0, 20.0, 200.0, 2000.0}) {
    nlohmann::json j;
    j["format"] = "monolith-scene/1";
    j["dim"] = 2;
    j["domain"] = {{"lower", {0.0, 0.0}}, {"upper", {1.0, 1.0}}, {"cells", {n, n}}};
    j["solver"] = {{"tolerance", 1e-8},
                   {"max_iterations", 20000},
                   {"backend", "matrixfree"},
                   {"scheme", "PVC-unified"}};
    j["render"] = {{"enabled", false}};
    j["gravity"] = {0.0, 0.0};
    j["time"] = {{"fps", 50}, {"frames", 20}, {"cfl", 1.0}, {"max_dt", 0.02}};
    j["liquids"] = {{{"name", "blob"},
                     {"shape", {{"type", "sphere"}, {"center", {0.5, 0.5}}, {"radius", 0.2}}},
                     {"density", 1000.0},
                     {"angular_velocity", 3.0},
                     {"viscosity", {{"eta", eta}}}}};
    j["probes"] = nlohmann::json::array();
    for (int k = 0; k < 8; ++k)
      j["probes"].push_back(
          {{"name", "p" + std::to_string(k)},
           {"position", {0.5 + 0.1 * std::cos(k * M_PI / 4), 0.5 + 0.1 * std::sin(k * M_PI / 4)}}});
    auto any = make_simulation(parse_scene(j, "test.json", "."));
    auto* sim = dynamic_cast<Simulation<2>*>(any.get());
    REQUIRE(sim != nullptr);
    const auto moments = [&](double& L, double& I) {
      const Particles<2>& p = sim->particles();
      double m = 0.0;
      Vec<2> xc = Vec<2>::Zero(), vc = Vec<2>::Zero();
      for (std::size_t k = 0; k < p.x.size(); ++k) {
        m += p.mass[k];
        xc += p.mass[k] * p.x[k];
        vc += p.mass[k] * p.v[k];
      }
      xc /= m;
      vc /= m;
      L = I = 0.0;
      for (std::size_t k = 0; k < p.x.size(); ++k) {
        const Vec<2> r = p.x[k] - xc, v = p.v[k] - vc;
        L += p.mass[k] * (r[0] * v[1] - r[1] * v[0]);
        I += p.mass[k] * r.squaredNorm();
      }
    };
    double L0, I0, L, I, omega = 0.0;
    moments(L0, I0);
    for (int f = 0; f < 20; ++f) {
      const FrameStats s = any->advance_frame();
      double sum = 0.0;
      for (const auto& p : s.probes) {
        const double dx = p.position[0] - 0.5, dy = p.position[1] - 0.5;
        sum += (dx * p.velocity[1] - dy * p.velocity[0]) / (dx * dx + dy * dy);
      }
      omega = sum / s.probes.size();
    }
    moments(L, I);
    std::printf(
        "n %d eta %6.0f: probe omega lost %6.2f %%, L lost %6.2f %%, I grew %6.2f %%, "
        "L/I lost %6.2f %%\n",
        n, eta, 100 * (1 - omega / 3.0), 100 * (1 - L / L0), 100 * (I / I0 - 1),
        100 * (1 - (L / I) / (L0 / I0)));
    std::fflush(stdout);
  }
}
