// Regression tests of the stability defects of the built-in scenes: particles tunnelling through
// thin solids at CFL 3, the spurious free surface inside walls (energy injected at static solids,
// pour-into-bowl-3d breaking down), and the volume and energy of full scenes.
#include <catch2/catch.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <thread>

#include "reference/app/scene_file.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

template <int Dim>
MacGrid<Dim> unit_grid(int n) {
  return MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {});
}

/// The solid field of one shape (as the simulation builds it).
template <int Dim>
SolidField<Dim> solid_of(const ShapePtr<Dim>& shape) {
  SolidField<Dim> s;
  s.distance = [shape](const Vec<Dim>& x) { return shape->distance(x); };
  s.gradient = [shape](const Vec<Dim>& x) { return shape->gradient(x); };
  return s;
}

ShapeSpec box_spec(const std::vector<double>& centre, const std::vector<double>& half) {
  ShapeSpec s;
  s.type = ShapeType::box;
  s.center = centre;
  s.half_size = half;
  return s;
}

/// Total energy (kinetic + potential) of a built-in scene after every frame, and its frames.
/// With StageSwitches::energy_ledger also `corrections`: the potential energy that position
/// correction and the density projection (line 15, moves that are not the flow's) added up to
/// each frame.
struct EnergyRun {
  std::vector<double> total, volume, corrections;
  std::vector<long> particles;
};

EnergyRun run_scene(const std::string& name, int frames, const std::vector<std::string>& sets,
                    const StageSwitches& switches = StageSwitches{}) {
  std::vector<std::string> overrides = sets;
  overrides.push_back("time.frames=" + std::to_string(frames));
  overrides.push_back("render.enabled=false");
  const SceneDesc scene = load_scene(name, overrides);
  auto sim = make_simulation(scene, switches);
  EnergyRun run;
  FrameStats s = sim->current_stats();
  double corrections = 0.0;
  for (int f = 0; f <= frames; ++f) {
    if (f > 0) {
      s = sim->advance_frame();
      const EnergyLedger l = sim->energy_ledger();
      corrections += l.position_correction + l.density_projection;
    }
    run.total.push_back(s.kinetic_energy_liquid + sim->liquid_potential_energy());
    run.volume.push_back(s.liquid_volume);
    run.particles.push_back(s.particles);
    run.corrections.push_back(corrections);
  }
  return run;
}

/// Largest gain of total energy over its lowest earlier value, relative to the initial energy
/// measured from the lowest point the liquid can reach (the floor, y = 0).
double worst_energy_gain(const std::vector<double>& total) {
  double lowest = total.front(), gain = 0.0;
  for (double e : total) {
    gain = std::max(gain, e - lowest);
    lowest = std::min(lowest, e);
  }
  return gain / total.front();
}

// --- tunnelling ------------------------------------------------------------------------------------

template <int Dim>
void check_no_tunnelling() {
  // a slab 1.5 dx thick across the domain at x = 0.5 and a uniform flow of 3 dx per step towards
  // it: one RK2 jump lands beyond the slab, outside the solid, and nothing pushes it back
  const int n = 32;
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const double dx = grid.dx(), dt = 0.01;
  std::vector<double> centre(Dim, 0.5), half(Dim, 0.6);
  half[0] = 0.75 * dx;
  const ShapePtr<Dim> slab = make_shape<Dim>(box_spec(centre, half), "slab");
  const SolidField<Dim> solids = solid_of<Dim>(slab);
  VectorX u = VectorX::Zero(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f)
    if (grid.face_coord(f).first == 0) u[f] = 3.0 * dx / dt;
  Particles<Dim> p;
  for (int k = 0; k < 20; ++k) {
    // start between 0.1 dx and 1.4 dx in front of the slab, spread across it
    Vec<Dim> x = Vec<Dim>::Constant(0.2 + 0.03 * k);
    x[0] = 0.5 - 0.75 * dx - (0.1 + 0.065 * k) * dx;
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(1.0);
    p.density.push_back(1000.0);
    p.liquid.push_back(0);
  }
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  for (int step = 0; step < 3; ++step) {
    const long removed = advect_particles(p, grid, u, dt, solids, boundary);
    REQUIRE(removed == 0);
    for (std::size_t i = 0; i < p.size(); ++i) {
      INFO("dim " << Dim << " step " << step << " particle " << i << " at x = " << p.x[i][0]);
      // on the near side of the slab and outside it
      REQUIRE(p.x[i][0] < 0.5 - 0.75 * dx);
      REQUIRE(solids.distance(p.x[i]) >= 0.0);
    }
  }
}

// --- spurious free surface in walls ----------------------------------------------------------------

/// A liquid layer resting on a solid floor whose surface lies `sliver` dx into a row of cells
/// (leaving a sliver of fluid that the particles may not reach) is hydrostatic: after one pressure step
/// every face near the floor whose solved velocity reaches the particles must be at rest.
/// Returns the largest such speed in units of g dt, with the liquid level set extended into the
/// solid or not.
template <int Dim>
double resting_layer_speed(bool extend, double sliver) {
  const int n = Dim == 2 ? 32 : 16;
  // periodic across, so the layer has no side walls (their corners have errors of their own)
  std::array<bool, Dim> periodic;
  periodic.fill(true);
  periodic[1] = false;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
  const auto lattice = half_lattice(grid);
  const double dx = grid.dx(), dt = 0.01, g = 9.81, rho = 1000.0;
  const double floor = (4.0 + sliver) * dx;
  // solid floor y < floor (a box reaching below the domain) and liquid up to y = 0.5
  std::vector<double> fc(Dim, 0.5), fh(Dim, 0.7);
  fc[1] = floor - 0.7;
  const ShapePtr<Dim> ground = make_shape<Dim>(box_spec(fc, fh), "floor");
  const SolidField<Dim> solids = solid_of<Dim>(ground);
  std::vector<double> lc(Dim, 0.5), lh(Dim, 0.5);
  lc[1] = 0.25;
  lh[1] = 0.25;
  LiquidSpec liquid;
  liquid.name = "water";
  liquid.shape = box_spec(lc, lh);
  liquid.density = rho;
  const ShapePtr<Dim> block = make_shape<Dim>(liquid.shape, "liquid");
  Particles<Dim> particles =
      seed_particles<Dim>(grid, {liquid}, {block}, solids, Dim == 2 ? 4 : 8, 7u);
  // the weights as the simulation forms them
  PressureWeights w;
  const VectorX solid_phi = solid_phi_on_lattice(grid, lattice, {ground}, 0.01 * dx);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::periodic);
  boundary[2] = BoundaryType::wall;
  boundary[3] = BoundaryType::open;
  w.fluid_face = fluid_face_weights(grid, lattice, solid_phi, boundary);
  VectorX phi = liquid_phi_on_lattice(particles, grid, lattice, boundary);
  if (extend) phi = extend_liquid_into_solids(grid, phi, solid_phi, kLiquidSolidReach * dx);
  w.liquid_cell = liquid_cell_weights(grid, lattice, phi);
  w.liquid_face = liquid_face_weights(grid, lattice, phi, w.liquid_cell);
  const VectorX raw = face_negative_fractions(grid, lattice, phi);
  // u* = particles at rest plus gravity, then the pressure step
  VectorX u, mass, density;
  particles_to_grid(particles, grid, u, mass, density);
  for (int f = 0; f < grid.num_faces(); ++f)
    if (mass[f] > 0.0 && grid.face_coord(f).first == 1) u[f] -= g * dt;
  w.face_density = density_diagonal(grid, density, rho);
  PcgSettings settings;
  settings.tolerance = 1e-8;
  settings.max_iterations = 4000;
  const PressureSolveResult solve = solve_pressure(grid, w, dt, Backend::matrix_free, settings, u);
  REQUIRE(solve.pcg.converged);
  // the faces the simulation hands to the particles (weight W_F^u W_L^u >= 0.1) in the two
  // cells above the floor
  double worst = 0.0;
  for (int f = 0; f < grid.num_faces(); ++f)
    if (w.fluid_face[f] * raw[f] >= 0.1 &&
        grid.face_center(grid.face_coord(f).first, grid.face_coord(f).second)[1] < floor + 2 * dx)
      worst = std::max(worst, std::abs(u[f]));
  return worst / (g * dt);
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("advection does not tunnel through a slab 1.5 dx thick at CFL 3",
                       "[regression][unit]", ((int Dim), Dim), 2, 3) {
  check_no_tunnelling<Dim>();
}

TEMPLATE_TEST_CASE_SIG(
    "liquid resting on a solid floor stays at rest: no free surface in the wall's fluid sliver",
    "[regression][unit]", ((int Dim), Dim), 2, 3) {
  double with = 0.0, without = 0.0;
  for (double sliver : {0.6, 0.75, 0.9, 0.97}) {
    with = std::max(with, resting_layer_speed<Dim>(true, sliver));
    without = std::max(without, resting_layer_speed<Dim>(false, sliver));
  }
  INFO("dim " << Dim << ": largest speed / (g dt) after one step, floors 0.6-0.97 dx into a "
              << "cell: extended " << with
              << ", not extended " << without);
  // the defect: without the extension the sliver is air and the layer drains into the floor
  // (measured: 3.5 g dt in 2D, 0.28 g dt in 3D, where 8 particles per cell reach more slivers)
  CHECK(without > 0.2);
  // the fix: the resting layer stays at rest to a small fraction of one step of free fall
  REQUIRE(with < 0.1);
}

TEST_CASE("extend_liquid_into_solids: only solid points near the liquid change", "[unit]") {
  const MacGrid<2> grid = unit_grid<2>(8);
  const double dx = grid.dx();
  VectorX liquid(5), solid(5);
  liquid << -0.3 * dx, 0.4 * dx, 2.0 * dx, 0.4 * dx, -2.0 * dx;
  solid << -1.0, -1.0, -1.0, 1.0, -1.0;
  const VectorX e = extend_liquid_into_solids(grid, liquid, solid, dx);
  CHECK(e[0] == -0.5 * dx);  // liquid in the solid: at least half a cell deep
  CHECK(e[1] == -0.5 * dx);  // solid point within reach of the liquid: wetted
  CHECK(e[2] == 2.0 * dx);   // solid point far from the liquid: unchanged
  CHECK(e[3] == 0.4 * dx);   // outside the solid: unchanged
  CHECK(e[4] == -2.0 * dx);  // deeper liquid kept
}

// --- full scenes -------------------------------------------------------------------------------------

TEST_CASE("default scene: volume drift and energy with the static disk", "[regression][validation]") {
  // the dam break around a static disk (2D, 96x64, 80 frames): before the fixes the disk's
  // spurious free surface injected energy (total +230 J in a frame) and the volume drifted by
  // -4.6 %; measured after: -0.5 %, total energy never above an earlier value
  const EnergyRun run = run_scene("default", 80, {});
  const double drift = run.volume.back() / run.volume.front() - 1.0;
  INFO("volume drift " << drift << ", worst energy regain " << worst_energy_gain(run.total));
  CHECK(std::abs(drift) < 0.02);
  CHECK(run.particles.back() > 0.98 * run.particles.front());
  CHECK(worst_energy_gain(run.total) < 0.005);
}

TEST_CASE("pour-into-bowl-2d: a splash in a static bowl never gains energy",
          "[regression][validation]") {
  // CFL 3, 96x96, 60 frames: the liquid leaves only through the open top (a real splash,
  // particles then carry their energy away), it never gains energy. With the whole drift and
  // line 15's energy free (the defaults before slosh11), whose first-order step loses
  // m g^2 dt^2 / 2 per step in the free fall; the defaults' check is the next test case.
  StageSwitches whole;
  whole.split_advection = false;
  whole.line15_energy = Line15Energy::free;
  const EnergyRun run = run_scene("pour-into-bowl-2d", 60, {}, whole);
  INFO("worst energy regain " << worst_energy_gain(run.total));
  CHECK(worst_energy_gain(run.total) < 0.01);
  for (std::size_t f = 0; f < run.total.size(); ++f) REQUIRE(run.total[f] <= run.total.front());
}

TEST_CASE("pour-into-bowl-2d with drift-kick-drift (the defaults): the flow's stages never gain energy",
          "[regression][validation]") {
  // With the split (StageSwitches::split_advection) free fall conserves energy exactly, so the
  // small moves of line 15 (position correction, density projection: not the flow's) show in
  // the total: without them counted, E read +0.0017 J of 341 J above its start at frame 1
  // (docs/particles.md, "Sloshing"). What the flow's stages (transfers, gravity, the solve,
  // advection) did, E minus the energy the ledger books to line 15, must never exceed the start
  // by more than the round-off of summing 341 J over the particles (measured: at most 4.4e-12 J,
  // 1.3e-14 of E(0), in the free fall, where the split is exact; the bound is 1e-12 of E(0)).
  StageSwitches split;
  split.split_advection = true;
  split.energy_ledger = true;
  const EnergyRun run = run_scene("pour-into-bowl-2d", 60, {}, split);
  double worst = -1e300, worst_total = -1e300;
  for (std::size_t f = 0; f < run.total.size(); ++f) {
    worst = std::max(worst, run.total[f] - run.corrections[f] - run.total.front());
    worst_total = std::max(worst_total, run.total[f] - run.total.front());
  }
  INFO("largest E - E(0): " << worst_total << " J; less line 15's share: " << worst
                            << " J (E(0) = " << run.total.front() << " J)");
  CHECK(worst <= 1e-12 * run.total.front());
  CHECK(worst_energy_gain(run.total) < 0.01);
}

TEST_CASE("hollow-spheres-inviscid-3d: the time step never collapses (frames 1-12)",
          "[regression][validation]") {
  // Before the fix the CFL limit read the solved velocity of every face, also of faces whose
  // weight W_F^u W_L^u is below kTrustedLiquidFaceFraction (their velocity is not physical and
  // never reaches a particle). In frame 9 one such face had 2.9e5 m/s: dt fell to 8.5e-8 s, the
  // contacts' penetration recovery (-beta phi / dt) then threw the bodies at 8.6 km/s, and dt
  // collapsed to 6e-28 s: the frame never ended. A watchdog stops a frame that takes minutes.
  const SceneDesc scene = load_scene("hollow-spheres-inviscid-3d",
                                     {"time.frames=12", "render.enabled=false"});
  auto sim = make_simulation(scene);
  volatile std::sig_atomic_t stop = 0;
  sim->set_stop_flag(&stop);
  std::atomic<bool> done{false};
  std::thread watchdog([&] {
    const auto start = std::chrono::steady_clock::now();
    while (!done && std::chrono::steady_clock::now() - start < std::chrono::minutes(5))
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    stop = 1;
  });
  const double e0 = sim->current_stats().kinetic_energy_bodies;
  double dt_min = 1.0, body_energy = 0.0;
  bool stalled = false;
  for (int f = 1; f <= 12 && !stalled; ++f) {
    const FrameStats s = sim->advance_frame();
    stalled = sim->mid_frame();
    dt_min = std::min(dt_min, s.dt_min);
    body_energy = std::max(body_energy, s.kinetic_energy_bodies);
  }
  done = true;
  watchdog.join();
  INFO("smallest step " << dt_min << " s, largest body kinetic energy " << body_energy << " J (start "
                        << e0 << " J)");
  REQUIRE_FALSE(stalled);
  // the scene's steps are 1.8-10 ms (max_dt 0.01, CFL 1, the bodies' half-cell rule); the
  // spheres fall 0.3 m at most: their kinetic energy stays below 10x its start (measured 115 J)
  CHECK(dt_min > 1e-4);
  CHECK(body_energy < 10.0 * e0);
}
