// The sloshing tank of slow_still_water.cpp (tests/support/still_water.hpp: unit tank, walls, open
// top, inviscid, PVC-unified, water 0.5 m deep whose surface starts tilted by `slope`), printing
// kinetic, potential and total energy of the liquid every `every` frames, relative to the start
// and to the available energy E(0) - E(rest). The bound: E never rises by more than 2 %
// of the available energy and ends below its start.
//
//   bench_sloshing [--dim 2|3] [--cells N] [--seconds T] [--slope S] [--every K] [--backend NAME]
//                  [--no-projection] [--no-correction] [--max-dt DT] [--split-drift]
//                  [--divergence-free-air] [--divergence-free-surface] [--no-step-projection]
//                  [--no-surface-deficits] [--dead-band-deficits] [--seed N]
//                  [--volume-source GAIN] [--pic] [--no-air-velocity] [--all-faces-trusted]
//                  [--unreached-extrapolated] [--cfl-layers] [--pay-line15 free|per-step|balance|local] [--carry-debt]
//                  [--drop-debt] [--whole-drift] [--pay-reach CELLS] [--set KEY=VALUE]...
//
// --set: a scene override as `monolith run --set` (e.g. domain.boundary.z-=periodic
// domain.boundary.z+=periodic: a 3D tank without its side walls across the sloshing).
//
// --dead-band-deficits: the surface band's deficits corrected only beyond a dead band of the level
// set's volume over the particles' (SurfaceDeficits::beyond_dead_band, a measurement switch).
// --volume-source GAIN: the surface band's deficits not moved but handed to the next solve as a
// divergence source d = GAIN e / dt (SurfaceDeficits::to_solve, StageSwitches::volume_source_gain).
// --pay-line15 free|per-step|balance|local: what pays the potential energy line 15's moves add
// (StageSwitches::line15_energy, Line15Energy; the default `balance` with the debt carried, as
// the simulator since slosh11). --whole-drift: symplectic Euler (the default before slosh11).
//
// Each line also shows the energy ledger (EnergyLedger, as bench_still_water) summed since the
// line before: which stage of the step changed the energy.
//
// A measurement program, not a test: it asserts nothing. Run it with OMP_NUM_THREADS=1.
// docs/particles.md ("Sloshing").
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "tests/support/bench_args.hpp"
#include "tests/support/still_water.hpp"

using namespace monolith;
using namespace monolith::still_water;

int main(int argc, char** argv) {
  int dim = 2, cells = 0, every = 25;
  double seconds = 10.0, slope = 0.1;
  std::string backend = "matrixfree";
  bool no_projection = false, no_correction = false, split_drift = false, divfree_air = false;
  bool divfree_surface = false, no_step_projection = false, no_surface_deficits = false;
  bool dead_band = false;
  double volume_source = -1.0;
  bool pic = false, no_air_velocity = false, all_faces_trusted = false;
  bool unreached_extrapolated = false, cfl_layers = false;
  // the simulator's defaults unless a flag says otherwise
  Line15Energy pay_line15 = StageSwitches{}.line15_energy;
  bool carry_debt = StageSwitches{}.line15_carry_debt;
  bool whole_drift = false;
  int pay_reach = 1;
  std::vector<std::string> overrides;
  double max_dt = 0.02;
  int seed = 0;
  bench::BenchArgs args(argc, argv);
  while (args.next()) {
    const std::string& a = args.flag();
    if (a == "--dim") dim = std::atoi(args.value().c_str());
    else if (a == "--cells") cells = std::atoi(args.value().c_str());
    else if (a == "--seconds") seconds = std::atof(args.value().c_str());
    else if (a == "--slope") slope = std::atof(args.value().c_str());
    else if (a == "--every") every = std::max(1, std::atoi(args.value().c_str()));
    else if (a == "--backend") backend = args.value();
    else if (a == "--no-projection") no_projection = true;
    else if (a == "--max-dt") max_dt = std::atof(args.value().c_str());
    else if (a == "--no-correction") no_correction = true;
    else if (a == "--split-drift") split_drift = true;
    else if (a == "--divergence-free-air") divfree_air = true;
    else if (a == "--divergence-free-surface") divfree_air = divfree_surface = true;
    else if (a == "--no-step-projection") no_step_projection = true;
    else if (a == "--no-surface-deficits") no_surface_deficits = true;
    else if (a == "--dead-band-deficits") dead_band = true;
    else if (a == "--set") overrides.push_back(args.value());
    else if (a == "--pic") pic = true;
    else if (a == "--no-air-velocity") no_air_velocity = true;
    else if (a == "--all-faces-trusted") all_faces_trusted = true;
    else if (a == "--unreached-extrapolated") unreached_extrapolated = true;
    else if (a == "--cfl-layers") cfl_layers = true;
    else if (a == "--volume-source") volume_source = std::atof(args.value().c_str());
    else if (a == "--pay-line15")
      pay_line15 = bench::line15_energy(args.value());
    else if (a == "--carry-debt") carry_debt = true;
    else if (a == "--drop-debt") carry_debt = false;
    else if (a == "--whole-drift") whole_drift = true;
    else if (a == "--pay-reach") pay_reach = std::atoi(args.value().c_str());
    else if (a == "--seed") seed = std::atoi(args.value().c_str());
    else {
      std::cerr << "usage: bench_sloshing [--dim 2|3] [--cells N] [--seconds T] [--slope S] "
                   "[--every K] [--backend NAME]\n";
      return 2;
    }
  }
  if (dim != 2 && dim != 3) {
    std::cerr << "--dim must be 2 or 3\n";
    return 2;
  }
  if (cells <= 0) cells = dim == 2 ? 64 : 24;
  StageSwitches switches;
  switches.energy_ledger = true;
  if (no_projection) switches.density_projection = false;
  if (no_correction) switches.position_correction = false;
  if (split_drift) switches.split_advection = true;
  if (whole_drift) switches.split_advection = false;
  if (divfree_air) switches.divergence_free_air = true;
  if (divfree_surface) switches.divergence_free_surface_cells = true;
  if (no_step_projection) switches.density_projection_in_steps = false;
  if (no_surface_deficits) switches.density_projection_surface_deficits = SurfaceDeficits::none;
  if (dead_band)
    switches.density_projection_surface_deficits = SurfaceDeficits::beyond_dead_band;
  if (pic) switches.apic = false;
  if (no_air_velocity) switches.air_velocity = false;
  if (all_faces_trusted) switches.trusted_faces = false;
  if (unreached_extrapolated) switches.unreached_faces_keep_u_star = false;
  if (cfl_layers) switches.extrapolate_cfl_layers = true;
  switches.line15_energy = pay_line15;
  switches.line15_carry_debt = carry_debt;
  switches.line15_pay_reach = pay_reach;
  if (volume_source >= 0.0) {
    switches.density_projection_surface_deficits = SurfaceDeficits::to_solve;
    switches.volume_source_gain = volume_source;
  }
  nlohmann::json scene = tank(dim, cells, seconds, backend, slope);
  scene["time"]["max_dt"] = max_dt;
  if (seed > 0) scene["particles"]["seed"] = seed;
  scene = apply_overrides(scene, "sloshing.json", overrides);
  const auto sim = make_simulation(parse_scene(scene, "sloshing.json", "."), switches);
  const FrameStats s0 = sim->current_stats();
  const double e0 = total_energy(s0);
  const double seeded = e0 - 0.5 * kRho * kG * s0.liquid_volume * s0.liquid_volume;
  const double available = kRho * kG * slope * slope / 24.0;
  // the available energy of the continuum: a surface tilted by slope over a unit width holds
  // rho g slope^2 / 24 more potential energy than a flat one (per unit depth in 3D)
  std::printf("sloshing %dD, %d cells, slope %.3f, max_dt %.4f, %s: E0 %.4f J, available %.4f J "
              "(the continuum's rho g slope^2 / 24; E0 - rho g V0^2 / 2 from the seeded volume: "
              "%.4f J)\n",
              dim, cells, slope, max_dt, backend.c_str(), e0, available, seeded);
  std::printf("%8s %12s %12s %12s %14s %10s | ledger since the last line: %8s %8s %8s %8s %8s %8s %8s\n",
              "t", "KE (J)", "PE - PE0", "E - E0", "(E-E0)/avail", "volume", "to_grid", "solve",
              "extend", "to_part", "advect", "correct", "project");
  EnergyLedger sum;
  const int frames = static_cast<int>(std::lround(50 * seconds));
  double max_rise = 0.0, e = e0;
  for (int f = 1; f <= frames; ++f) {
    const FrameStats s = sim->advance_frame();
    e = total_energy(s);
    const EnergyLedger l = sim->energy_ledger();
    still_water::accumulate(sum, l);
    max_rise = std::max(max_rise, e - e0);
    if (f % every == 0) {
      std::printf("%8.2f %12.5f %12.5f %12.5f %14.5f %+9.3f%% | %+8.4f %+8.4f %+8.4f %+8.4f %+8.4f %+8.4f %+8.4f\n",
                  s.time, s.kinetic_energy_liquid,
                  s.potential_energy_liquid - s0.potential_energy_liquid, e - e0,
                  (e - e0) / available, 100.0 * (s.liquid_volume / s0.liquid_volume - 1.0),
                  sum.to_grid, sum.forces_and_solve, sum.velocity_extension, sum.to_particles,
                  sum.advection, sum.position_correction, sum.density_projection);
      sum = EnergyLedger{};
    }
    std::fflush(stdout);
  }
  std::printf("largest rise %.5f J = %.4f of the available energy; end %.5f J = %.4f\n", max_rise,
              max_rise / available, e - e0, (e - e0) / available);
  return 0;
}
