// Benchmark (not a test) of the particle splats' CPU time on one and on two threads, in one
// process: the particle level set with solids (liquid_phi_on_lattice) and the density projection
// (project_particle_density) and the position correction (correct_positions), each on a copy of
// the particles per call, on a 64^3 unit box with walls, a
// sphere in it and liquid resting on it and on the floor (about the 64^3 viscous bunny's
// particle count once it has landed). Teams alternate 1, 2, 1, 2, ... call by call, so another
// process's load falls on both alike; printed per kernel: the process CPU time per call at each
// team (median over the rounds), the ratio CPU(2) / CPU(1) (1.0: the second thread adds no work)
// and the wall times (median; a loaded machine makes them meaningless). docs/benchmarks.md,
// "The landed frames outside the solve on two threads" (two23).
//
//   build/bench/bench_splat_threads [--rounds R] [--only-team T]
//
// --only-team T runs every call at team T (for a profile of one team size; no ratio printed).
#include <omp.h>
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "reference/core/parallel.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"

using namespace monolith;

namespace {

double process_cpu() {
  timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}
double wall_clock() {
  timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  int rounds = 15, only = 0;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--rounds") && i + 1 < argc) rounds = std::atoi(argv[++i]);
    if (!std::strcmp(argv[i], "--only-team") && i + 1 < argc) only = std::atoi(argv[++i]);
  }
  set_adaptive_teams(false);
  set_core_monitor(false);
  constexpr int Dim = 3;
  const int cells = 64;
  const double dx = 1.0 / cells;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), dx, VecI<Dim>::Constant(cells), std::array<bool, Dim>{});
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  ShapeSpec ball;
  ball.type = ShapeType::sphere;
  ball.center = {0.5, 0.3, 0.5};
  ball.radius = 0.2;
  std::vector<ShapePtr<Dim>> solid_shapes{make_shape<Dim>(ball, "sphere")};
  const ShapePtr<Dim> shape = solid_shapes.front();
  SolidField<Dim> solids;
  solids.distance = [shape](const Vec<Dim>& x) { return shape->distance(x); };
  solids.gradient = [shape](const Vec<Dim>& x) { return shape->gradient(x); };
  const VectorX solid_phi = solid_phi_on_lattice(grid, lattice, solid_shapes, 0.0);
  const VectorX fluid = fluid_face_weights(grid, lattice, solid_phi, boundary);
  // liquid: a layer on the floor and a cap over the sphere (the seeding leaves the solid out)
  ShapeSpec floor_layer, cap;
  floor_layer.type = cap.type = ShapeType::box;
  floor_layer.center = {0.5, 0.03, 0.5};
  floor_layer.half_size = {0.5, 0.03, 0.5};
  cap.center = {0.5, 0.48, 0.5};
  cap.half_size = {0.16, 0.06, 0.16};
  LiquidSpec a, b;
  a.name = "floor";
  b.name = "cap";
  a.density = b.density = 1000.0;
  a.shape = floor_layer;
  b.shape = cap;
  const Particles<Dim> start = seed_particles<Dim>(
      grid, {a, b}, {make_shape<Dim>(floor_layer, "floor"), make_shape<Dim>(cap, "cap")}, solids,
      8, 1u);
  std::printf("64^3, %zu particles, %d rounds\n", start.size(), rounds);

  struct Kernel {
    const char* name;
    std::function<void()> run;
  };
  Particles<Dim> work = start;
  const std::vector<Kernel> kernels = {
      {"liquid_phi_on_lattice (with solids)",
       [&] {
         const VectorX phi = liquid_phi_on_lattice(start, grid, lattice, boundary, solids);
         if (!(phi.size() > 0)) std::abort();
       }},
      {"project_particle_density (one iteration)",
       [&] {
         project_particle_density(work, grid, lattice, fluid, solids, boundary);
       }},
      {"correct_positions", [&] { correct_positions(work, grid, 0.01, solids, boundary); }},
  };
  for (const Kernel& k : kernels) {
    std::vector<double> cpu[2], wall[2];
    for (int r = 0; r < rounds; ++r)
      for (int t = 1; t <= 2; ++t) {
        if (only > 0 && t != 1) continue;
        omp_set_num_threads(only > 0 ? only : t);
        work = start;
        const double c0 = process_cpu(), w0 = wall_clock();
        k.run();
        cpu[t - 1].push_back(process_cpu() - c0);
        wall[t - 1].push_back(wall_clock() - w0);
      }
    if (only > 0) {
      std::printf("%-42s team %d: CPU %7.2f ms  wall %7.2f ms\n", k.name, only, 1e3 * median(cpu[0]),
                  1e3 * median(wall[0]));
      continue;
    }
    std::vector<double> ratio;
    for (int r = 0; r < rounds; ++r) ratio.push_back(cpu[1][r] / cpu[0][r]);
    std::sort(ratio.begin(), ratio.end());
    std::printf("%-42s CPU 1t %7.2f ms  2t %7.2f ms  ratio 2t/1t %.3f (p25 %.3f, p75 %.3f)  wall 1t %7.2f  2t %7.2f ms\n",
                k.name, 1e3 * median(cpu[0]), 1e3 * median(cpu[1]), median(ratio),
                ratio[ratio.size() / 4], ratio[3 * ratio.size() / 4], 1e3 * median(wall[0]),
                1e3 * median(wall[1]));
  }
  return 0;
}
