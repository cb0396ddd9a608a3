// Viscous flows with known answers, on the grid solve of eq. (8) directly (no particles):
// plane Poiseuille and Couette flow in periodic channels, the decay of a shear wave, and
// backward-Euler stability at very large time steps. 2D and 3D.
#include <catch2/catch.hpp>
#include <cmath>

#include "reference/fluid/stokes_system.hpp"
#include "reference/fluid/viscosity.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A box of `cells` cells of width dx filled with liquid below the level set `liquid_phi`
/// (everywhere if it is empty), boundaries as given, no solids, density rho, viscosity eta.
template <int Dim>
struct Channel {
  MacGrid<Dim> grid;
  StokesWeights w;

  Channel(const VecI<Dim>& cells, double dx, const std::array<BoundaryType, 2 * Dim>& boundary,
          double rho, double eta, const std::function<double(const Vec<Dim>&)>& liquid_phi = {}) {
    std::array<bool, Dim> periodic{};
    for (int a = 0; a < Dim; ++a) periodic[a] = boundary[2 * a] == BoundaryType::periodic;
    grid = MacGrid<Dim>(Vec<Dim>::Zero(), dx, cells, periodic);
    const SampleLattice<Dim> lattice = half_lattice(grid);
    const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
    VectorX phi(lattice.size());
    for (int k = 0; k < lattice.size(); ++k)
      phi[k] = liquid_phi ? liquid_phi(lattice.position(lattice.coord(k))) : -1.0;
    w = stokes_weights(grid, solid_phi, phi, boundary, rho, eta);
  }

  /// One backward-Euler step of the unsteady Stokes problem: u += dt f on the fluid faces along
  /// `axis` (f per face), then eq. (8) in (tau, p), reduced, SSOR-PCG at relative tolerance 1e-12.
  PcgResult step(VectorX& u, double dt, const VectorX& force = VectorX(),
                 StokesUnknowns unknowns = StokesUnknowns::pressure_and_stress,
                 StressForm form = StressForm::reduced) const {
    if (force.size()) u += dt * force;
    PcgSettings settings;
    settings.tolerance = 1e-12;
    settings.max_iterations = 20000;
    return solve_stokes(grid, w, dt, unknowns, form, Backend::matrix_free, settings, u).pcg;
  }

  /// Body force per face: `g` on the faces normal to axis 0 that carry fluid, zero elsewhere.
  VectorX force_along_x(double g) const {
    VectorX f = VectorX::Zero(grid.num_faces());
    for (int i = 0; i < grid.num_faces(0); ++i)
      if (w.pressure.fluid_face[i] > 0.0) f[i] = g;
    return f;
  }

  /// 1/2 sum_f P W_F^u W_L^u u_f^2: the kinetic energy norm of eq. (8) (dx^Dim dropped).
  double energy(const VectorX& u) const {
    return 0.5 * (w.pressure.face_density.array() * w.pressure.fluid_face.array() *
                  w.pressure.liquid_face.array() * u.array().square())
                     .sum();
  }
};

/// Periodic along every axis but y, walls at y = 0 and y = H: n cells across, 4 along the rest.
template <int Dim>
Channel<Dim> wall_channel(int n, double rho, double eta) {
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::periodic);
  boundary[2] = boundary[3] = BoundaryType::wall;
  VecI<Dim> cells = VecI<Dim>::Constant(4);
  cells[1] = n;
  return Channel<Dim>(cells, 1.0 / n, boundary, rho, eta);
}

/// Largest |u_f - exact(y_f)| over the x faces, relative to the largest |exact|.
template <int Dim>
double profile_error(const MacGrid<Dim>& grid, const VectorX& u,
                     const std::function<double(double)>& exact, int skip_top_rows = 0) {
  double err = 0.0, scale = 0.0;
  for (int i = 0; i < grid.num_faces(0); ++i) {
    const VecI<Dim> c = grid.face_coord(i).second;
    if (c[1] >= grid.cells()[1] - skip_top_rows) continue;
    const double y = grid.face_center(0, c)[1];
    err = std::max(err, std::abs(u[i] - exact(y)));
    scale = std::max(scale, std::abs(exact(y)));
  }
  return err / scale;
}

/// Plane Poiseuille flow driven by a body force g along x between no-slip walls at y = 0, H:
/// u(y) = g / (2 nu) y (H - y) (e.g. Batchelor 1967, section 4.2). Returns the relative max error
/// of the steady state reached by backward-Euler steps with dt = H^2 / nu (each step damps the
/// slowest mode by 1 / (1 + pi^2)).
template <int Dim>
double poiseuille_error(int n) {
  const double rho = 1.0, eta = 1.0, g = 1.0, h = 1.0;
  const Channel<Dim> ch = wall_channel<Dim>(n, rho, eta);
  VectorX u = VectorX::Zero(ch.grid.num_faces());
  const VectorX f = ch.force_along_x(g);
  for (int s = 0; s < 16; ++s) REQUIRE(ch.step(u, h * h * rho / eta, f).converged);
  // the cross-channel components stay zero
  REQUIRE(u.tail(u.size() - ch.grid.num_faces(0)).template lpNorm<Eigen::Infinity>() < 1e-10);
  return profile_error<Dim>(ch.grid, u, [&](double y) { return g * rho / (2 * eta) * y * (h - y); });
}

}  // namespace

TEST_CASE("plane Poiseuille flow converges to the parabolic profile at second order (2D and 3D)",
          "[validation][convergence]") {
  // source: the steady solution of the Navier-Stokes equations between parallel no-slip plates
  // under a uniform body force, u = g y (H - y) / (2 nu). The interior 3-point stencil is exact
  // for a parabola; the error comes from the wall, where the one-sided shear rate of the wall
  // stress DOF (stress_weights.hpp) is first-order accurate in a layer of width dx/2, which
  // shifts the whole profile by O(dx^2). Measured relative max errors, 2D and 3D alike:
  // n = 8: 1.587e-2, 16: 3.922e-3, 32: 9.775e-4 (exactly 1 / (4 n^2 - 1)), observed orders
  // 2.017 and 2.004. Asserted: order > 1.95 between successive resolutions, error at n = 32
  // below 1.0e-3.
  std::vector<double> e2, e3;
  for (int n : {8, 16, 32}) {
    e2.push_back(poiseuille_error<2>(n));
    e3.push_back(poiseuille_error<3>(n));
    WARN("Poiseuille n = " << n << ": relative max error 2D " << e2.back() << ", 3D " << e3.back());
  }
  for (std::size_t k = 1; k < e2.size(); ++k) {
    const double order2 = std::log2(e2[k - 1] / e2[k]), order3 = std::log2(e3[k - 1] / e3[k]);
    WARN("observed order 2D " << order2 << ", 3D " << order3);
    CHECK(order2 > 1.95);
    CHECK(order3 > 1.95);
  }
  CHECK(e2.back() < 1.0e-3);
  CHECK(e3.back() < 1.0e-3);
}

namespace {

/// Couette flow between the no-slip wall y = 0 and a moving lid: the lid is the top `lid` rows of
/// the channel filled with a liquid 1e12 times denser (a moving wall the viscous stress cannot
/// slow down: its velocity changes by O(1e-12) per step). From rest below a lid at speed 1, the
/// steady state is the linear profile u(y) = U y / y_lid, y_lid the height of the first lid face
/// row. Returns the relative max error below the lid after the steps.
template <int Dim>
double couette_error(int n) {
  const int lid = 2;
  const double rho = 1.0, eta = 1.0, lid_speed = 1.0;
  Channel<Dim> ch = wall_channel<Dim>(n, rho, eta);
  VectorX u = VectorX::Zero(ch.grid.num_faces());
  const double y_lid = ch.grid.face_center(0, VecI<Dim>::Unit(1) * (n - lid))[1];
  for (int f = 0; f < ch.grid.num_faces(); ++f) {
    const auto [axis, c] = ch.grid.face_coord(f);
    if (c[1] >= n - lid) {
      ch.w.pressure.face_density[f] = 1e12 * rho;
      if (axis == 0) u[f] = lid_speed;
    }
  }
  for (int s = 0; s < 16; ++s) REQUIRE(ch.step(u, rho / eta).converged);
  // the lid keeps its speed
  for (int i = 0; i < ch.grid.num_faces(0); ++i)
    if (ch.grid.face_coord(i).second[1] >= n - lid) REQUIRE(std::abs(u[i] - lid_speed) < 1e-6);
  return profile_error<Dim>(ch.grid, u, [&](double y) { return lid_speed * y / y_lid; }, lid);
}

}  // namespace

TEST_CASE("Couette flow below a moving lid is the linear profile (2D and 3D)",
          "[validation][convergence]") {
  // source: plane Couette flow, u = U y / h between a fixed and a moving plate (e.g. Batchelor
  // 1967, section 4.2). The moving plate is a heavy liquid lid (couette_error). A linear profile
  // has zero viscous force in the interior and the wall stress DOF makes it exact at y = 0
  // (stress_weights.hpp), so the discrete steady state is exact at every resolution: measured
  // relative max errors 1.6e-10 (n = 8), 2.9e-10 (16), 5.5e-10 (32), 2D and 3D alike: round-off
  // and the solver tolerance, no discretisation error, hence no order to measure. Bound: 1e-8
  // (solver tolerance 1e-12, 16 steps each damping the slowest mode by 1 / (1 + pi^2)).
  for (int n : {8, 16, 32}) {
    CAPTURE(n);
    const double e2 = couette_error<2>(n);
    const double e3 = couette_error<3>(n);
    WARN("Couette n = " << n << ": relative max error 2D " << e2 << ", 3D " << e3);
    CHECK(e2 < 1e-8);
    CHECK(e3 < 1e-8);
  }
}

namespace {

/// A shear wave u_x = sin(2 pi y / L) in a fully periodic box, L = 1 along y with n cells, 4 cells
/// along the other axes (the wave does not depend on them). Returns the amplitudes (projection
/// on sin(2 pi y)) after each of `steps` steps of dt.
template <int Dim>
std::vector<double> shear_wave_amplitudes(int n, double nu, double dt, int steps,
                                          StokesUnknowns unknowns, StressForm form) {
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::periodic);
  VecI<Dim> cells = VecI<Dim>::Constant(4);
  cells[1] = n;
  const Channel<Dim> ch(cells, 1.0 / n, boundary, 1.0, nu);
  VectorX u = VectorX::Zero(ch.grid.num_faces());
  VectorX mode = VectorX::Zero(ch.grid.num_faces());
  for (int i = 0; i < ch.grid.num_faces(0); ++i) {
    const auto c = ch.grid.face_coord(i).second;
    mode[i] = std::sin(2 * kPi * ch.grid.face_center(0, c)[1]);
  }
  u = mode;
  std::vector<double> amplitude{1.0};
  for (int s = 0; s < steps; ++s) {
    REQUIRE(ch.step(u, dt, VectorX(), unknowns, form).converged);
    amplitude.push_back(u.dot(mode) / mode.squaredNorm());
    // the wave keeps its shape: what is left after removing the mode is round-off
    REQUIRE((u - amplitude.back() * mode).template lpNorm<Eigen::Infinity>() < 1e-9);
  }
  return amplitude;
}

template <int Dim>
void check_shear_wave_decay() {
  const int n = 32, steps = 50;
  const double nu = 0.01, dt = 0.02, k = 2 * kPi, dx = 1.0 / n;
  // backward Euler with the 3-point Laplacian: the mode is multiplied by exactly
  // 1 / (1 + nu k_h^2 dt) per step, k_h = 2 sin(k dx / 2) / dx
  const double k_h = 2 * std::sin(k * dx / 2) / dx;
  const double discrete = 1.0 / (1.0 + nu * k_h * k_h * dt);
  for (const auto& [unknowns, form] :
       {std::pair{StokesUnknowns::pressure_and_stress, StressForm::reduced},
        std::pair{StokesUnknowns::stress_only, StressForm::full}}) {
    const auto a = shear_wave_amplitudes<Dim>(n, nu, dt, steps, unknowns, form);
    double worst = 0.0;
    for (int s = 1; s <= steps; ++s) worst = std::max(worst, std::abs(a[s] / a[s - 1] - discrete));
    // per-step factor: round-off and the solver tolerance (1e-12) only
    CHECK(worst < 1e-9);
    // against the analytic decay exp(-nu k^2 t): backward Euler loses (nu k^2 dt)^2 / 2 per step
    // in the exponent and the 3-point Laplacian (k dx)^2 / 12 relative in the rate, so at
    // t = steps dt the relative error is about steps (nu k^2 dt)^2 / 2 + nu k^2 t (k dx)^2 / 12
    // = 50 (0.0079)^2 / 2 + 0.395 (0.196)^2 / 12 = 1.6e-3 + 1.3e-3; measured 2.81e-3 (2D and
    // 3D, both solve forms), per-step factor error 2.6e-15 (2D) and 2.0e-13 (3D); bound 4e-3
    const double t = steps * dt;
    const double analytic = std::exp(-nu * k * k * t);
    const double rel = std::abs(a[steps] / analytic - 1.0);
    WARN(Dim << "D shear wave: per-step factor error " << worst << ", relative error against exp(-nu k^2 t) at t = "
             << t << ": " << rel);
    CHECK(rel < 4e-3);
  }
}

}  // namespace

TEST_CASE("a shear wave decays at the backward-Euler rate of exp(-nu k^2 t) (2D and 3D)",
          "[validation]") {
  // source: the start-up/decay of a sinusoidal shear flow, u = sin(k y) exp(-nu k^2 t), an exact
  // solution of the unsteady Stokes (and Navier-Stokes) equations in a periodic box.
  check_shear_wave_decay<2>();
  check_shear_wave_decay<3>();
}

namespace {

template <int Dim>
void check_large_dt_energy() {
  // a block of liquid with a free surface at y = 0.6 in a walled box, random velocity, no gravity
  const int n = Dim == 2 ? 12 : 8;
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  const Channel<Dim> ch(VecI<Dim>::Constant(n), 1.0 / n, boundary, 1000.0, 50.0,
                        [](const Vec<Dim>& x) { return x[1] - 0.6; });
  for (const auto& [unknowns, form] :
       {std::pair{StokesUnknowns::pressure_and_stress, StressForm::reduced},
        std::pair{StokesUnknowns::pressure_and_stress, StressForm::full},
        std::pair{StokesUnknowns::stress_only, StressForm::full}}) {
    // random velocity on the liquid faces, zero on walls and in the air: the air faces next to
    // the surface enter b of eq. (24) through D (stokes_system.hpp) but are not unknowns, so a
    // non-zero velocity there is a prescribed boundary velocity that can do work on the liquid
    // (measured: random air velocities raise the 3D energy by 2e-4 relative at dt = 1e4)
    VectorX u = random_vector(ch.grid.num_faces(), 11);
    for (int f = 0; f < ch.grid.num_faces(); ++f)
      if (ch.w.pressure.fluid_face[f] * ch.w.pressure.liquid_face[f] == 0.0) u[f] = 0.0;
    double previous = ch.energy(u);
    for (double dt : {1.0, 100.0, 1e4}) {
      CAPTURE(dt);
      const PcgResult r = ch.step(u, dt, VectorX(), unknowns, form);
      CHECK(!r.breakdown);
      REQUIRE(u.allFinite());
      const double e = ch.energy(u);
      // the update minimises eq. (8), whose value at (tau, p) = 0 is the energy of u*: the
      // energy can only drop (by the CG's monotone decrease even before convergence)
      CHECK(e <= previous * (1 + 1e-12));
      previous = e;
    }
  }
}

}  // namespace

TEST_CASE("backward Euler at very large time steps never gains kinetic energy (2D and 3D)",
          "[validation]") {
  check_large_dt_energy<2>();
  check_large_dt_energy<3>();
}
