// The volume drift of test_validation_volume.cpp (a built-in scene's liquid_volume, the level
// set's sum(W_L^p) dx^Dim, against frame 0) with the stage switches of the sloshing and rest
// benchmarks, so a change to the density projection or the step can be weighed against the dam
// breaks' 1 % bound (docs/particles.md, "Volume correction through the solve").
//
//   bench_volume_drift [--scene NAME] [--frames N] [--set KEY=VALUE]... [--split-drift]
//                      [--divergence-free-surface] [--no-surface-deficits]
//                      [--dead-band-deficits] [--volume-source GAIN] [--pay-line15 per-step|balance|local] [--carry-debt]
//
// Defaults: dam-break-2d at 64x32 for 60 frames (the test's first case); the test's 3D case is
// --scene dam-break-3d --set domain.cells=[32,16,16] --frames 30. Prints the worst |drift|, its
// frame, the lowest and highest drift. A measurement program, not a test: it asserts nothing.
// Run it with OMP_NUM_THREADS=1.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/frame_stats.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/bench_args.hpp"
#include "tests/support/stage_variants.hpp"

using namespace monolith;

int main(int argc, char** argv) {
  std::string name = "dam-break-2d";
  int frames = 60;
  std::vector<std::string> overrides;
  bool cells_set = false;
  StageSwitches switches;
  bench::BenchArgs args(argc, argv);
  while (args.next()) {
    const std::string& a = args.flag();
    if (a == "--scene") {
      name = args.value();
    } else if (a == "--frames") {
      frames = std::atoi(args.value().c_str());
    } else if (a == "--set") {
      overrides.push_back(args.value());
      cells_set = cells_set || overrides.back().rfind("domain.cells=", 0) == 0;
    } else if (a == "--split-drift") {
      switches.split_advection = true;
    } else if (a == "--divergence-free-surface") {
      switches.divergence_free_air = switches.divergence_free_surface_cells = true;
    } else if (a == "--no-surface-deficits") {
      switches.density_projection_surface_deficits = SurfaceDeficits::none;
    } else if (a == "--dead-band-deficits") {
      switches.density_projection_surface_deficits = SurfaceDeficits::beyond_dead_band;
    } else if (a == "--volume-source") {
      switches.density_projection_surface_deficits = SurfaceDeficits::to_solve;
      switches.volume_source_gain = std::atof(args.value().c_str());
    } else if (a == "--pay-line15") {
      switches.line15_energy = bench::line15_energy(args.value());
    } else if (a == "--carry-debt") {
      switches.line15_carry_debt = true;
    } else {
      std::cerr << "usage: bench_volume_drift [--scene NAME] [--frames N] [--set KEY=VALUE]... "
                   "[--split-drift] [--divergence-free-surface] [--no-surface-deficits] "
                   "[--dead-band-deficits] [--volume-source GAIN] [--pay-line15 per-step|balance|local] [--carry-debt]\n";
      return 2;
    }
  }
  if (!cells_set && name == "dam-break-2d") overrides.push_back("domain.cells=[64,32]");
  const SceneDesc scene = load_scene(name, overrides);
  const auto sim = make_simulation(scene, switches);
  const FrameStats first = sim->current_stats();
  double worst = 0.0, lo = 0.0, hi = 0.0;
  int worst_frame = 0;
  for (int f = 1; f <= frames; ++f) {
    const FrameStats s = sim->advance_frame();
    const double d = s.liquid_volume / first.liquid_volume - 1.0;
    lo = std::min(lo, d);
    hi = std::max(hi, d);
    if (std::abs(d) > worst) {
      worst = std::abs(d);
      worst_frame = f;
    }
  }
  std::printf("%s, %d frames: worst |drift| %.3f %% at frame %d (min %.3f %%, max %.3f %%)\n",
              name.c_str(), frames, 100.0 * worst, worst_frame, 100.0 * lo, 100.0 * hi);
  return 0;
}
