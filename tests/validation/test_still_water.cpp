// Rest is rest (docs/particles.md, "Still water"): short versions of slow_still_water.cpp for
// the default suite. Still water must stay still through the whole step (particles, level set,
// weights, solve, extrapolation, transfers, position correction and density projection). Before
// the particle level set mirrored the particles across the walls, the 2D tank below reached
// 1.24 J/m of kinetic energy after 1 s (50 times the bound; 3.4 J/m at 32^2) with probes at
// 7 cm/s.
#include <catch2/catch.hpp>

#include "tests/support/still_water.hpp"

using namespace monolith;
using namespace monolith::still_water;

TEST_CASE("still water stays still for 1 s (2D, 64^2), both back ends", "[validation]") {
  // measured with the mirror images: kinetic energy at most 1.5e-3 J/m (the seeding jitter
  // settling), probes at most 2.1 mm/s in the last 0.5 s, volume drift 0.02 %
  for (const std::string backend : {"matrixfree", "explicit"}) {
    const RestResult r = run_rest(2, 64, 1.0, backend);
    INFO(backend << ": max kinetic energy " << r.max_kinetic << " J/m (bound 1e-5 M g H = "
                 << 1e-5 * mgh() << "), probe speed in the last 0.5 s " << r.max_probe_speed
                 << " m/s, volume drift " << r.max_drift);
    CHECK(r.converged);
    CHECK(r.max_kinetic < 1e-5 * mgh());
    CHECK(r.max_probe_speed < 5e-3);
    CHECK(r.max_drift < 5e-3);
  }
}

TEST_CASE("still water gains no energy in 0.5 s (3D, 16^3)", "[validation]") {
  // the energy and volume bounds of the 10 s run; the probe bound (5 mm/s) is for the settled
  // state at 32^3 (slow_still_water.cpp): at 16^3 the seeding's jitter settles with probes of
  // 6.9 mm/s in the first 0.5 s. Before the mirror images: 0.72 J at 1 s at 32^3.
  const RestResult r = run_rest(3, 16, 0.5, "matrixfree");
  INFO("max kinetic energy " << r.max_kinetic << " J (bound " << 1e-5 * mgh()
                             << "), probe speed in the last 0.25 s " << r.max_probe_speed
                             << " m/s, volume drift " << r.max_drift);
  CHECK(r.converged);
  CHECK(r.max_kinetic < 1e-5 * mgh());
  CHECK(r.max_drift < 5e-3);
}

TEST_CASE("a settled start takes the seeding's jitter out of still water (2D, 64^2, 1 s)",
          "[validation]") {
  // particles.settle_steps (Simulation::settle, docs/particles.md "A settled start"): whole steps
  // before t = 0 with the velocities zeroed after each, so the run starts from the discrete
  // equilibrium of the particles instead of the jittered seeding's. Measured (slosh10): largest
  // kinetic energy in 1 s 1.40e-3 J/m without, 1.50e-5 with 50 settling steps; probes in the
  // last 0.5 s 1.80 / 0.53 mm/s; volume drift 4e-6.
  const RestResult free = run_rest(2, 64, 1.0, "matrixfree");
  const RestResult settled = run_rest(2, 64, 1.0, "matrixfree", 50);
  INFO("largest kinetic energy " << free.max_kinetic << " J/m without, " << settled.max_kinetic
                                 << " settled; probe speed in the last 0.5 s "
                                 << free.max_probe_speed << " / " << settled.max_probe_speed
                                 << " m/s; volume drift " << settled.max_drift);
  CHECK(settled.converged);
  CHECK(settled.max_kinetic < 0.1 * free.max_kinetic);
  CHECK(settled.max_probe_speed < 0.5 * free.max_probe_speed);
  CHECK(settled.max_drift < 5e-3);
}

TEST_CASE("a settled start gives the liquid its initial velocity back", "[validation]") {
  // the settling zeroes the velocities after each of its steps; the scene's initial velocity is
  // the particles' again at t = 0, and the particles are where the settling left them
  nlohmann::json plain = tank(2, 32, 0.1, "matrixfree");
  plain["liquids"][0]["velocity"] = {0.25, 0.0};
  nlohmann::json settled = plain;
  settled["particles"]["settle_steps"] = 10;
  const auto a = make_simulation(parse_scene(plain, "plain.json", "."));
  const auto b = make_simulation(parse_scene(settled, "settled.json", "."));
  const FrameStats sa = a->current_stats(), sb = b->current_stats();
  INFO("kinetic energy " << sa.kinetic_energy_liquid << " / " << sb.kinetic_energy_liquid
                         << " J/m, potential energy " << sa.potential_energy_liquid << " / "
                         << sb.potential_energy_liquid << " J/m, particles " << sa.particles
                         << " / " << sb.particles);
  CHECK(sb.particles == sa.particles);
  CHECK(sb.kinetic_energy_liquid == Approx(sa.kinetic_energy_liquid).epsilon(1e-12));
  // the settling moved the particles (it did something) and lowered their potential energy
  CHECK(sb.potential_energy_liquid < sa.potential_energy_liquid);
}

TEST_CASE("drift-kick-drift keeps the sloshing tank's energy rise below half of symplectic Euler's (2D, 64^2, 1 s)",
          "[validation]") {
  // drift-kick-drift (StageSwitches::split_advection, for scenes without moving bodies) against
  // the whole drift after the solve (symplectic Euler): at the test's max_dt 0.02 (omega dt = 0.11
  // for the first mode) the total energy of symplectic Euler rises by up to 0.26 J/m in the first
  // second (a swing within each half period), the split's by 0.066 (docs/particles.md,
  // "Sloshing"). The energy the density projection adds (0.04-0.08 J/m per second) is in both.
  // (line 15's energy free in both, the default before slosh11, so that only the order differs)
  StageSwitches dkd;
  dkd.split_advection = true;
  dkd.line15_energy = Line15Energy::free;
  StageSwitches whole = dkd;
  whole.split_advection = false;
  const SloshResult split = run_slosh(2, 64, 1.0, "matrixfree", 0.1, dkd);
  const SloshResult euler = run_slosh(2, 64, 1.0, "matrixfree", 0.1, whole);
  INFO("largest rise of E in 1 s: split " << split.max_rise << " J/m, whole drift "
                                          << euler.max_rise << " J/m (available "
                                          << split.available << " J/m)");
  CHECK(split.converged);
  CHECK(euler.converged);
  CHECK(split.max_rise < 0.5 * euler.max_rise);
  CHECK(split.max_rise < 0.025 * split.available);
}

TEST_CASE("divergence-free surface cells take away what the density projection answered in the sloshing tank (2D, 64^2, 1 s)",
          "[validation]") {
  // The density projection added 0.04-0.09 J/m of potential energy per second to the sloshing
  // tank, pushing particle volume out through the surface: the extrapolated velocity the surface
  // band's particles move with is not divergence-free (each component copied from the liquid), so
  // where the surface rises the band converges. With the air cells and the surface cells whose
  // outer face the solve does not trust made divergence-free (StageSwitches::
  // divergence_free_air, divergence_free_surface_cells), measured: 0.083 J/m in the first second
  // without, 0.004 with (docs/particles.md, "Sloshing"). The total rise stays (the projection is
  // not what raises it; see there).
  // (measured with the defaults before slosh11: the whole drift, line 15's energy free)
  StageSwitches ledger;
  ledger.energy_ledger = true;
  ledger.split_advection = false;
  ledger.line15_energy = Line15Energy::free;
  StageSwitches divfree = ledger;
  divfree.divergence_free_air = true;
  divfree.divergence_free_surface_cells = true;
  const SloshResult plain = run_slosh(2, 64, 1.0, "matrixfree", 0.1, ledger);
  const SloshResult fixed = run_slosh(2, 64, 1.0, "matrixfree", 0.1, divfree);
  INFO("potential energy added by the density projection in 1 s: extrapolated as it is "
       << plain.projection << " J/m, divergence-free surface cells " << fixed.projection
       << " J/m");
  CHECK(plain.converged);
  CHECK(fixed.converged);
  CHECK(plain.projection > 0.04);
  CHECK(std::abs(fixed.projection) < 0.2 * plain.projection);
}

TEST_CASE("the surface band's deficits beyond a dead band keep the sloshing tank within 2 % for 2 s (2D, 64^2)",
          "[validation]") {
  // physics6 (docs/particles.md, "Sloshing"): with drift-kick-drift and divergence-free air and
  // surface cells, correcting every deficit on the liquid side of the surface band raised the
  // tank's energy by 0.104 J/m in 2 s (2.6 % of the available 4.09 J/m; 10 % in 10 s); corrected
  // only beyond a dead band of the level set's volume over the particles'
  // (SurfaceDeficits::beyond_dead_band) 0.046 J/m (1.1 %, the same over 10 s). A measurement
  // switch: with it, water at rest and the floating box move more than their bounds allow.
  StageSwitches all;
  all.split_advection = true;
  all.line15_energy = Line15Energy::free;
  all.divergence_free_air = true;
  all.divergence_free_surface_cells = true;
  StageSwitches dead_band = all;
  dead_band.density_projection_surface_deficits = SurfaceDeficits::beyond_dead_band;
  const SloshResult every = run_slosh(2, 64, 2.0, "matrixfree", 0.1, all);
  const SloshResult band = run_slosh(2, 64, 2.0, "matrixfree", 0.1, dead_band);
  INFO("largest rise of E in 2 s: every deficit " << every.max_rise << " J/m, dead band "
                                                  << band.max_rise << " J/m (available "
                                                  << band.available << " J/m)");
  CHECK(every.converged);
  CHECK(band.converged);
  CHECK(band.max_rise < 0.02 * band.available);
  CHECK(band.max_rise < 0.6 * every.max_rise);
}

TEST_CASE("line 15's potential energy paid by the kinetic energy keeps the split sloshing tank below its start for 2 s (2D, 64^2)",
          "[validation]") {
  // slosh9 (docs/particles.md, "Line 15's potential energy paid by the kinetic energy"): with
  // drift-kick-drift the tank's energy rises steadily by what the moves of line 15 (mostly the
  // density projection's corrections of the surface band) add, +0.11 J/m in 2 s (0.389 J/m,
  // 9.5 % of the available 4.09 J/m, in 10 s). With that potential energy taken from the
  // liquid's kinetic energy whenever line 15's summed change since the start would be positive
  // (Line15Energy::balance), the tank never rose above its start in 10 s (measured: it ends
  // 0.46 J/m below). Checked here: the split alone rises by more than 1 % in 2 s, the
  // ledger's line-15 columns summed from the start never exceed the round-off of summing 1228 J
  // over the particles, and the paid tank stays below a quarter of the slow test's 2 % (seeds 2 /
  // 3 over 10 s: never above / +0.015 J/m).
  StageSwitches split;
  split.split_advection = true;
  split.line15_energy = Line15Energy::free;
  split.energy_ledger = true;
  StageSwitches paid = split;
  paid.line15_energy = Line15Energy::balance;  // (the default since slosh11)
  const SloshResult plain = run_slosh(2, 64, 2.0, "matrixfree", 0.1, split);
  const auto sim = make_simulation(
      parse_scene(tank(2, 64, 2.0, "matrixfree", 0.1), "sloshing.json", "."), paid);
  const double e0 = total_energy(sim->current_stats());
  const double roundoff = 1e-12 * e0;
  double max_rise = -1e300, max_line15 = -1e300, line15 = 0.0;
  bool converged = true;
  for (int f = 1; f <= 100; ++f) {
    const FrameStats s = sim->advance_frame();
    converged = converged && s.solver.converged;
    max_rise = std::max(max_rise, total_energy(s) - e0);
    const EnergyLedger l = sim->energy_ledger();
    line15 += l.position_correction + l.density_projection;
    max_line15 = std::max(max_line15, line15);
  }
  INFO("largest rise of E in 2 s: split " << plain.max_rise << " J/m, paid " << max_rise
                                          << " J/m; line 15's summed change at most "
                                          << max_line15 << " J/m (available " << plain.available
                                          << " J/m)");
  CHECK(plain.converged);
  CHECK(converged);
  CHECK(plain.max_rise > 0.01 * plain.available);
  CHECK(max_rise < 0.005 * plain.available);
  CHECK(max_line15 <= roundoff);
}
