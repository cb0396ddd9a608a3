// Where a long run regains energy (issue 16, tests/slow/slow_long_runs.cpp): a built-in scene run
// frame by frame with the energy ledger on (StageSwitches::energy_ledger), printing per frame the
// mechanical energy E = kinetic + potential of liquid and bodies, its regain over the running
// minimum (the slow test's quantity) against the test's bound, and the ledger's stages of that
// frame, so that the stage which injects the energy in the frames where E rises can be read off.
// Variants switch one stage off at a time (as bench_still_water does); a variant changes the run
// from its first frame, so compare the regains, not single frames.
//
//   bench_energy_regain SCENE [--frames N] [--from F] [--only NAME[,NAME...]] [--affine]
//                       [--set KEY=VALUE]...
//
// --affine adds a line per frame on the particles' APIC matrices c (print_affine).
// --frames defaults to three times the scene's length (the slow test's run); frames before --from
// are run but not printed; "volume" is the liquid volume's drift from frame 0. Each variant ends with a summary line: the largest regain, its frame,
// the bound there, and the ledger summed over the run. A measurement program: it asserts nothing.
// Run it with OMP_NUM_THREADS=1. docs/particles.md ("Energy regains over long runs").
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/rigid/rigid_world.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/bench_args.hpp"
#include "tests/support/stage_variants.hpp"

using namespace monolith;

namespace {

using Variant = bench::StageVariant;

std::vector<Variant> variants() {
  return {
      {"simulator", [](StageSwitches&) {}},
      {"no-correction", [](StageSwitches& s) { s.position_correction = false; }},
      {"no-projection", [](StageSwitches& s) { s.density_projection = false; }},
      {"no-step-projection", [](StageSwitches& s) { s.density_projection_in_steps = false; }},
      {"no-line-15", [](StageSwitches& s) { s.position_correction = s.density_projection = false; }},
      {"pic", [](StageSwitches& s) { s.apic = false; }},
      {"no-surface-deficits",
       [](StageSwitches& s) { s.density_projection_surface_deficits = SurfaceDeficits::none; }},
      {"no-extrapolation", [](StageSwitches& s) { s.extrapolate_after_solve = false; }},
      {"all-trusted", [](StageSwitches& s) { s.trusted_faces = false; }},
      // faces that carry particle mass outside the level set (W_L^u = 0) are extrapolated over
      // instead of keeping u* (their ballistic velocity)
      {"no-ballistic-faces", [](StageSwitches& s) { s.unreached_faces_keep_u_star = false; }},
      // those faces keep P2G's APIC value plus g dt (before issue 16's fix: the PIC value)
      {"ballistic-apic", [](StageSwitches& s) { s.ballistic_faces_pic = false; }},
      // every ballistic face takes the PIC value, not only those beside a wall or solid
      {"ballistic-pic-everywhere",
       [](StageSwitches& s) { s.ballistic_faces_pic_everywhere = true; }},
      {"split", [](StageSwitches& s) { s.split_advection = true; }},
      {"whole-drift", [](StageSwitches& s) { s.split_advection = false; }},
      // line 15's potential energy not paid by the kinetic energy (the default before slosh11)
      {"line15-free", [](StageSwitches& s) { s.line15_energy = Line15Energy::free; }},
      {"line15-no-debt", [](StageSwitches& s) { s.line15_carry_debt = false; }},
  };
}

/// The particles' affine part (APIC) and where it sits: the largest Frobenius norm of c (1/s), the
/// sum of 1/2 m |c|_F^2 dx^2 / 4 (an indicator of the energy the affine matrices hold, in J, not
/// counted in the particles' kinetic energy), and how many particles lie inside a moving body or
/// within 1.5 dx of one, with their share of that sum.
template <int Dim>
void print_affine(const AnySimulation& any, int frame) {
  const auto* sim = dynamic_cast<const Simulation<Dim>*>(&any);
  if (!sim) return;
  const auto& p = sim->particles();
  const double dx = sim->grid().dx();
  std::vector<ShapePtr<Dim>> bodies;
  if (const auto* world = sim->rigid_world())
    for (const auto& b : world->bodies())
      if (b.moves()) bodies.push_back(b.posed_shape());
  double largest = 0.0, sum = 0.0, near_sum = 0.0, large_sum = 0.0;
  long inside = 0, near = 0, large = 0, large_at_wall = 0;
  Vec<Dim> at = Vec<Dim>::Zero();
  Mat<Dim> c_at = Mat<Dim>::Zero();
  Vec<Dim> v_at = Vec<Dim>::Zero();
  const SceneDesc& scene = sim->scene();
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double c2 = p.c[i].squaredNorm();
    const double e = 0.5 * p.mass[i] * c2 * dx * dx / 4.0;
    if (std::sqrt(c2) > largest) {
      largest = std::sqrt(c2);
      at = p.x[i];
      c_at = p.c[i];
      v_at = p.v[i];
    }
    sum += e;
    if (std::sqrt(c2) * dx > 0.5) {  // a velocity difference of 0.5 m/s across a cell
      ++large;
      large_sum += e;
      double wall = 1e300;
      for (int a = 0; a < Dim; ++a) {
        if (scene.domain.boundary[2 * a] == BoundaryType::wall)
          wall = std::min(wall, p.x[i][a] - scene.domain.lower[a]);
        if (scene.domain.boundary[2 * a + 1] == BoundaryType::wall)
          wall = std::min(wall, scene.domain.upper[a] - p.x[i][a]);
      }
      if (wall < 1.5 * dx) ++large_at_wall;
    }
    double d = 1e300;
    for (const auto& b : bodies) d = std::min(d, b->distance(p.x[i]));
    if (d < 0.0) ++inside;
    if (d < 1.5 * dx) {
      ++near;
      near_sum += e;
    }
  }
  std::printf("affine frame %5d particles %ld |c| max %.3e 1/s, sum 1/2 m |c|^2 dx^2/4 %.4e J "
              "(within 1.5 dx of a moving body: %ld particles, %.4e J; inside one: %ld); |c| dx > "
              "0.5 m/s: %ld particles (%ld within 1.5 dx of a wall), %.4e J; largest at",
              frame, static_cast<long>(p.size()), largest, sum, near, near_sum, inside, large,
              large_at_wall, large_sum);
  for (int a = 0; a < Dim; ++a) std::printf(" %.4f", at[a]);
  std::printf(", v");
  for (int a = 0; a < Dim; ++a) std::printf(" %+.3e", v_at[a]);
  std::printf(", c (rows)");
  for (int a = 0; a < Dim; ++a)
    for (int b = 0; b < Dim; ++b) std::printf(" %+.3e", c_at(a, b));
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 0, from = 1;
  bool affine = false;
  std::string name;
  std::vector<std::string> only, overrides{"render.enabled=false"};
  bench::BenchArgs args(argc, argv);
  while (args.next()) {
    const std::string& a = args.flag();
    if (a == "--frames") {
      frames = std::atoi(args.value().c_str());
    } else if (a == "--from") {
      from = std::atoi(args.value().c_str());
    } else if (a == "--only") {
      for (const std::string& item : args.list()) only.push_back(item);
    } else if (a == "--affine") {
      affine = true;
    } else if (a == "--set") {
      overrides.push_back(args.value());
    } else if (!a.empty() && a[0] != '-' && name.empty()) {
      name = a;
    } else {
      std::cerr << "usage: bench_energy_regain SCENE [--frames N] [--from F] [--only NAME,...] "
                   "[--affine] [--set KEY=VALUE]...\n";
      return 2;
    }
  }
  if (name.empty()) {
    std::cerr << "bench_energy_regain: give a built-in scene's name\n";
    return 2;
  }
  SceneFile scene;
  try {
    scene = load_scene(name, overrides);
  } catch (const InputError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  if (frames <= 0) frames = 3 * scene.time.frames;
  for (const Variant& v : variants()) {
    if (!v.selected(only)) continue;
    auto sim = make_simulation(scene, v.switches());
    const FrameStats s0 = sim->current_stats();
    const double e0 = bench::mechanical_energy(s0);
    double lowest = e0, worst = -1e300, worst_regain = 0.0, worst_bound = 0.0;
    int worst_frame = 0;
    EnergyLedger total;
    std::printf("%-12s %5s %7s %11s %10s %9s %8s | %9s %9s %9s %9s %9s %9s %9s | %9s %9s\n",
                v.name.c_str(), "frame", "t", "E - E0", "regain", "bound", "volume", "to_grid", "solve",
                "extend", "to_part", "advect", "correct", "project", "KE liq", "KE body");
    try {
      for (int f = 1; f <= frames; ++f) {
        const FrameStats s = sim->advance_frame();
        const EnergyLedger l = sim->energy_ledger();
        bench::accumulate(total, l);
        const double e = bench::mechanical_energy(s);
        const double regain = e - lowest;
        // the slow test's bound without its floor of 1e-5 M g H
        const double bound = 0.02 * (e0 - lowest);
        if (regain - bound > worst) {
          worst = regain - bound;
          worst_regain = regain;
          worst_bound = bound;
          worst_frame = f;
        }
        lowest = std::min(lowest, e);
        if (f >= from)
          std::printf("%-12s %5d %7.3f %11.4e %10.3e %9.3e %+7.3f%% | %+9.2e %+9.2e %+9.2e %+9.2e %+9.2e "
                      "%+9.2e %+9.2e | %9.3e %9.3e\n",
                      v.name.c_str(), f, s.time, e - e0, regain, bound,
                      100.0 * (s.liquid_volume / s0.liquid_volume - 1.0), l.to_grid,
                      l.forces_and_solve, l.velocity_extension, l.to_particles, l.advection,
                      l.position_correction, l.density_projection, s.kinetic_energy_liquid,
                      s.kinetic_energy_bodies);
        if (affine && f >= from) {
          if (scene.dim == 2) print_affine<2>(*sim, f);
          else print_affine<3>(*sim, f);
        }
        std::fflush(stdout);
      }
    } catch (const std::exception& e) {
      std::printf("%-12s failed: %s\n", v.name.c_str(), e.what());
    }
    std::printf("summary %-12s worst regain %.4e at frame %d (bound %.4e, excess %+.4e) | ledger "
                "to_grid %+.4f solve %+.4f extend %+.4f to_part %+.4f advect %+.4f correct %+.4f "
                "project %+.4f total %+.4f\n",
                v.name.c_str(), worst_regain, worst_frame, worst_bound, worst, total.to_grid,
                total.forces_and_solve, total.velocity_extension, total.to_particles,
                total.advection, total.position_correction, total.density_projection,
                total.total());
    std::fflush(stdout);
  }
  return 0;
}
