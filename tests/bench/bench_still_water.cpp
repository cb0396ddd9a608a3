// Still water, stage by stage: a tank of water at rest (unit box, walls, open top, 0.5 m deep,
// inviscid, PVC-unified) run once with the simulator as it is and once with each stage of the
// step switched off or replaced (StageSwitches), printing the kinetic energy over time, the
// largest probe speed, the volume drift and the energy ledger of each stage (EnergyLedger)
// summed over the run. docs/particles.md ("Still water") shows its table.
//
//   bench_still_water [--dim 2|3] [--cells N] [--seconds T] [--backend NAME]
//                     [--only NAME[,NAME...]] [--set KEY=VALUE]... [--progress]
//
// --progress prints the kinetic energy, the probes and the ledger every second (on stderr).
//
// A measurement program, not a test: it asserts nothing. Run it with OMP_NUM_THREADS=1.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/bench_args.hpp"
#include "tests/support/stage_variants.hpp"
#include "tests/support/still_water.hpp"

using namespace monolith;

namespace {

using Variant = bench::StageVariant;

std::vector<Variant> variants() {
  return {
      {"simulator", "every stage as in the simulator", [](StageSwitches&) {}},
      {"no-correction", "correct_positions off", [](StageSwitches& s) { s.position_correction = false; }},
      {"no-projection", "project_particle_density off (also before frame 0)",
       [](StageSwitches& s) { s.density_projection = false; }},
      {"no-line-15", "both position corrections off",
       [](StageSwitches& s) { s.position_correction = s.density_projection = false; }},
      {"pic", "PIC instead of APIC (c = 0)", [](StageSwitches& s) { s.apic = false; }},
      {"no-air-u*", "no u* extrapolation into air before the solve",
       [](StageSwitches& s) { s.air_velocity = false; }},
      {"all-faces-trusted", "every face with W_L^u > 0 hands its solved velocity on",
       [](StageSwitches& s) { s.trusted_faces = false; }},
      {"unreached-extrapolated", "faces with mass but W_L^u = 0 extrapolated, not u*",
       [](StageSwitches& s) { s.unreached_faces_keep_u_star = false; }},
      {"no-extrapolation", "no extrapolation after the solve",
       [](StageSwitches& s) { s.extrapolate_after_solve = false; }},
      {"split-divergence-free", "drift-kick-drift, divergence-free air and surface cells",
       [](StageSwitches& s) {
         s.split_advection = s.divergence_free_air = s.divergence_free_surface_cells = true;
       }},
      {"dead-band", "the same and the surface band's deficits beyond a dead band (physics6)",
       [](StageSwitches& s) {
         s.split_advection = s.divergence_free_air = s.divergence_free_surface_cells = true;
         s.density_projection_surface_deficits = SurfaceDeficits::beyond_dead_band;
       }},
      {"volume-source", "the surface band's deficits as the next solve's divergence source",
       [](StageSwitches& s) { s.density_projection_surface_deficits = SurfaceDeficits::to_solve; }},
      {"paid", "line 15's potential energy paid by the kinetic energy, per step (slosh9)",
       [](StageSwitches& s) { s.line15_energy = Line15Energy::per_step; }},
      {"balance", "line 15's potential energy paid by the kinetic energy, balance (slosh9)",
       [](StageSwitches& s) { s.line15_energy = Line15Energy::balance; }},
      {"split-paid", "drift-kick-drift and line 15's potential energy paid per step (slosh9)",
       [](StageSwitches& s) {
         s.split_advection = true;
         s.line15_energy = Line15Energy::per_step;
       }},
      {"split-balance", "drift-kick-drift and line 15's potential energy paid, balance (slosh9)",
       [](StageSwitches& s) {
         s.split_advection = true;
         s.line15_energy = Line15Energy::balance;
       }},
      {"before-slosh11", "the defaults before slosh11: whole drift, line 15's energy free",
       [](StageSwitches& s) {
         s.split_advection = false;
         s.line15_energy = Line15Energy::free;
       }},
      {"split-balance-local",
       "drift-kick-drift and line 15's potential energy paid near its rises, balance (slosh11)",
       [](StageSwitches& s) {
         s.split_advection = true;
         s.line15_energy = Line15Energy::balance_local;
       }},
      {"split-balance-debt",
       "drift-kick-drift, line 15 paid (balance), what the kinetic energy cannot pay owed (slosh11)",
       [](StageSwitches& s) {
         s.split_advection = true;
         s.line15_energy = Line15Energy::balance;
         s.line15_carry_debt = true;
       }},
      {"split-volume-source", "split-divergence-free and the deficits as a divergence source",
       [](StageSwitches& s) {
         s.split_advection = s.divergence_free_air = s.divergence_free_surface_cells = true;
         s.density_projection_surface_deficits = SurfaceDeficits::to_solve;
       }},
  };
}

}  // namespace

int main(int argc, char** argv) {
  int dim = 2, cells = 0;
  double seconds = 10.0;
  std::string backend = "matrixfree";
  std::vector<std::string> only, overrides;
  bool progress = false;
  bench::BenchArgs args(argc, argv);
  while (args.next()) {
    const std::string& a = args.flag();
    if (a == "--dim") {
      dim = std::atoi(args.value().c_str());
    } else if (a == "--cells") {
      cells = std::atoi(args.value().c_str());
    } else if (a == "--seconds") {
      seconds = std::atof(args.value().c_str());
    } else if (a == "--backend") {
      backend = args.value();
    } else if (a == "--only") {
      for (const std::string& item : args.list()) only.push_back(item);
    } else if (a == "--progress") {
      progress = true;
    } else if (a == "--set") {
      overrides.push_back(args.value());
    } else {
      std::cerr << "unknown argument " << a
                << "\nusage: bench_still_water [--dim 2|3] [--cells N] [--seconds T] [--backend "
                   "NAME] [--only NAME,...] [--set KEY=VALUE]... [--progress]\n";
      return 2;
    }
  }
  if (dim != 2 && dim != 3) {
    std::cerr << "--dim must be 2 or 3\n";
    return 2;
  }
  if (cells <= 0) cells = dim == 2 ? 64 : 32;
  SceneDesc scene;
  try {
    nlohmann::json j = still_water::tank(dim, cells, seconds, backend);
    j = apply_overrides(j, "still water", overrides);
    scene = parse_scene(j, "still water", ".");
  } catch (const InputError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  const double mass = 1000.0 * 0.5, depth = 0.5;  // per metre of depth in 2D, per unit area in 3D
  const double mgh = mass * 9.81 * depth;
  std::printf("still water %dD, %d cells per axis, %.1f s, %s; M g H = %.1f J, 1e-5 of it %.4f J\n",
              dim, cells, seconds, backend.c_str(), mgh, 1e-5 * mgh);
  std::printf("%-24s %9s %9s %9s %9s %9s %8s | %8s %8s %8s %8s %8s %8s %8s %8s\n", "variant",
              "KE 1s", "KE 5s", "KE end", "KE max", "probe", "volume", "to_grid", "solve",
              "extend", "to_part", "advect", "correct", "project", "total");
  for (const Variant& v : variants()) {
    if (!v.selected(only)) continue;
    auto sim = make_simulation(scene, v.switches());
    FrameStats s = sim->current_stats();
    const double volume0 = s.liquid_volume;
    double ke1 = 0.0, ke5 = 0.0, ke_max = 0.0, probe = 0.0, drift = 0.0;
    EnergyLedger sum;
    const int frames = scene.time.frames;
    try {
      for (int f = 1; f <= frames; ++f) {
        s = sim->advance_frame();
        const EnergyLedger l = sim->energy_ledger();
        bench::accumulate(sum, l);
        const double ke = s.kinetic_energy_liquid;
        if (std::abs(s.time - 1.0) < 1e-9) ke1 = ke;
        if (std::abs(s.time - 5.0) < 1e-9) ke5 = ke;
        ke_max = std::max(ke_max, ke);
        if (progress && f % 50 == 0) {
          double frame_probe = 0.0;
          for (const auto& p : s.probes) {
            double v2 = 0.0;
            for (double c : p.velocity) v2 += c * c;
            frame_probe = std::max(frame_probe, std::sqrt(v2));
          }
          std::fprintf(stderr, "  %s t %.1f s: KE %.3e J, probe %.2e m/s, volume %+.3f%%, ledger project %+.4f correct %+.4f total %+.4f\n",
                       v.name.c_str(), s.time, ke, frame_probe,
                       100.0 * (s.liquid_volume / volume0 - 1.0), sum.density_projection,
                       sum.position_correction, sum.total());
        }
        drift = std::max(drift, std::abs(s.liquid_volume / volume0 - 1.0));
        // the largest probe speed over the second half of the run
        if (s.time > 0.5 * seconds + 1e-9)
          for (const auto& p : s.probes) {
            double speed2 = 0.0;
            for (double c : p.velocity) speed2 += c * c;
            probe = std::max(probe, std::sqrt(speed2));
          }
      }
    } catch (const std::exception& e) {
      std::printf("%-24s failed: %s\n", v.name.c_str(), e.what());
      continue;
    }
    std::printf("%-24s %9.2e %9.2e %9.2e %9.2e %9.2e %7.3f%% | %+8.3f %+8.3f %+8.3f %+8.3f %+8.3f "
                "%+8.3f %+8.3f %+8.3f\n",
                v.name.c_str(), ke1, ke5, s.kinetic_energy_liquid, ke_max, probe, 100.0 * drift,
                sum.to_grid, sum.forces_and_solve, sum.velocity_extension, sum.to_particles,
                sum.advection, sum.position_correction, sum.density_projection, sum.total());
    std::fflush(stdout);
  }
  std::printf("KE in J, probe = largest probe speed (m/s) in the second half, volume = largest "
              "|drift| of liquid_volume; stage columns: the energy ledger summed over the run (J)\n");
  return 0;
}
