// The floating box of slow_still_water.cpp (2D, 64^2, PC-unified, box 0.1 x 0.05 of density ratio
// 0.5 placed at Archimedes' draft in water 0.5 deep), frame by frame: its offset from Archimedes'
// height (in dx) and its vertical velocity, to tell a drift from an oscillation about the
// equilibrium and to read the oscillation's period and amplitude. Each variant switches one stage
// of the step off (StageSwitches, as bench_still_water does) and ends with a summary line: the
// mean, lowest and highest offset, the largest speed, and the energy ledger summed over the run.
//
//   bench_floating_rest [--frames N] [--every K] [--only NAME[,NAME...]] [--set KEY=VALUE]...
//
// --every K prints every K-th frame (0: the summary lines only). A measurement program, not a
// test: it asserts nothing. Run it with OMP_NUM_THREADS=1. docs/particles.md ("Still water").
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "reference/core/errors.hpp"
#include "tests/support/bench_args.hpp"
#include "tests/support/coupled_validation.hpp"
#include "tests/support/stage_variants.hpp"

using namespace monolith;
using namespace monolith::validation;

namespace {

using Variant = bench::StageVariant;

std::vector<Variant> variants() {
  return {
      {"simulator", [](StageSwitches&) {}},
      // the defaults before slosh11 (line 15's energy free; the box keeps the whole drift anyway)
      {"before-slosh11", [](StageSwitches& s) { s.line15_energy = Line15Energy::free; }},
      {"no-correction", [](StageSwitches& s) { s.position_correction = false; }},
      {"no-projection", [](StageSwitches& s) { s.density_projection = false; }},
      {"no-line-15", [](StageSwitches& s) { s.position_correction = s.density_projection = false; }},
      {"pic", [](StageSwitches& s) { s.apic = false; }},
      // the extrapolated velocity made divergence-free in the air and surface cells
      // (docs/particles.md, "Sloshing")
      {"divergence-free-surface",
       [](StageSwitches& s) { s.divergence_free_air = s.divergence_free_surface_cells = true; }},
      {"divergence-free-surface-no-projection",
       [](StageSwitches& s) {
         s.divergence_free_air = s.divergence_free_surface_cells = true;
         s.density_projection = false;
       }},
      // the 2D sloshing tank's passing configuration (docs/particles.md, "Sloshing", physics6):
      // divergence-free air and surface cells, the surface band's deficits beyond a dead band
      // (the box is a moving body: its scene keeps the whole drift)
      {"dead-band",
       [](StageSwitches& s) {
         s.divergence_free_air = s.divergence_free_surface_cells = true;
         s.density_projection_surface_deficits = SurfaceDeficits::beyond_dead_band;
       }},
      // the surface band's deficits handed to the next solve as a divergence source instead of
      // moving particles (docs/particles.md, "Volume correction through the solve")
      {"volume-source",
       [](StageSwitches& s) { s.density_projection_surface_deficits = SurfaceDeficits::to_solve; }},
      // line 15's potential energy paid by the liquid's kinetic energy (docs/particles.md, slosh9)
      {"paid", [](StageSwitches& s) { s.line15_energy = Line15Energy::per_step; }},
      {"balance", [](StageSwitches& s) { s.line15_energy = Line15Energy::balance; }},
      // the same amount paid by the particles near line 15's rises (docs/particles.md, slosh11)
      {"balance-local", [](StageSwitches& s) { s.line15_energy = Line15Energy::balance_local; }},
      // what the kinetic energy cannot pay stays owed
      {"balance-debt",
       [](StageSwitches& s) {
         s.line15_energy = Line15Energy::balance;
         s.line15_carry_debt = true;
       }},
      {"balance-local-debt",
       [](StageSwitches& s) {
         s.line15_energy = Line15Energy::balance_local;
         s.line15_carry_debt = true;
       }},
      {"divergence-free-surface-volume-source",
       [](StageSwitches& s) {
         s.divergence_free_air = s.divergence_free_surface_cells = true;
         s.density_projection_surface_deficits = SurfaceDeficits::to_solve;
       }},
  };
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 500, every = 1;
  std::vector<std::string> only, overrides;
  bench::BenchArgs args(argc, argv);
  while (args.next()) {
    const std::string& a = args.flag();
    if (a == "--frames") {
      frames = std::atoi(args.value().c_str());
    } else if (a == "--every") {
      every = std::atoi(args.value().c_str());
    } else if (a == "--only") {
      for (const std::string& item : args.list()) only.push_back(item);
    } else if (a == "--set") {
      overrides.push_back(args.value());
    } else {
      std::cerr << "usage: bench_floating_rest [--frames N] [--every K] [--only NAME,...] "
                   "[--set KEY=VALUE]...\n";
      return 2;
    }
  }
  const int n = 64;
  const double dx = 1.0 / n;
  const FloatBody body = FloatBody::box(2, 0.1, 0.05, 0.5);
  SceneDesc scene;
  try {
    nlohmann::json j = base_scene(2, {1.0, 1.0}, n, "PC-unified", 50);
    j["liquids"].push_back(pool(2, 0.5));
    j["bodies"].push_back({{"name", "floater"},
                           {"density", body.s * kRho},
                           {"shape", body.shape(body.centre_at(0.5))}});
    j = apply_overrides(j, "floating box", overrides);
    scene = parse_scene(j, "floating box", ".");
  } catch (const InputError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  for (const Variant& v : variants()) {
    if (!v.selected(only)) continue;
    auto sim = make_simulation(scene, v.switches());
    if (every > 0)
      std::printf("%-14s %6s %8s %12s %12s %12s %12s %12s %12s\n", v.name.c_str(), "frame", "t",
                  "offset (dx)", "v_y (m/s)", "|v| (m/s)", "x - x0 (dx)", "v_x (m/s)",
                  "E - E0 (J)");
    const FrameStats s0 = sim->current_stats();
    const double e0 = bench::mechanical_energy(s0);
    double sum = 0.0, lo = 1e9, hi = -1e9, speed = 0.0, late_speed = 0.0;
    EnergyLedger ledger;
    int count = 0;
    try {
      for (int f = 1; f <= frames; ++f) {
        const FrameStats s = sim->advance_frame();
        const EnergyLedger l = sim->energy_ledger();
        bench::accumulate(ledger, l);
        const double predicted = body.centre_at(s.liquid_volume + body.s * body.volume());
        const double offset = (s.bodies[0].position[1] - predicted) / dx;
        double v2 = 0.0;
        for (double c : s.bodies[0].velocity) v2 += c * c;
        sum += offset;
        ++count;
        lo = std::min(lo, offset);
        hi = std::max(hi, offset);
        speed = std::max(speed, std::sqrt(v2));
        if (2 * f > frames) late_speed = std::max(late_speed, std::sqrt(v2));
        if (every > 0 && f % every == 0)
          std::printf("%-14s %6d %8.2f %12.5f %12.3e %12.3e %12.5f %12.3e %12.4e\n",
                      v.name.c_str(), f, s.time, offset, s.bodies[0].velocity[1], std::sqrt(v2),
                      (s.bodies[0].position[0] - s0.bodies[0].position[0]) / dx,
                      s.bodies[0].velocity[0], bench::mechanical_energy(s) - e0);
      }
    } catch (const std::exception& e) {
      std::printf("%-14s failed: %s\n", v.name.c_str(), e.what());
      continue;
    }
    std::printf("summary %-14s offset mean %+.4f min %+.4f max %+.4f dx, speed max %.2e (second "
                "half %.2e) m/s | ledger to_grid %+.4f solve %+.4f extend %+.4f to_part %+.4f "
                "advect %+.4f correct %+.4f project %+.4f total %+.4f J\n",
                v.name.c_str(), sum / count, lo, hi, speed, late_speed, ledger.to_grid,
                ledger.forces_and_solve, ledger.velocity_extension, ledger.to_particles,
                ledger.advection, ledger.position_correction, ledger.density_projection,
                ledger.total());
    std::fflush(stdout);
  }
  return 0;
}
