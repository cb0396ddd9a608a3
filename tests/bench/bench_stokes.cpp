// Benchmark (not a test): SSOR-PCG iterations and time per Stokes solve of eq. (8) against the
// number of unknowns, 2D and 3D, and the solve-time ratio PVC-unified / PC-VC-PC-unified on a
// whole scene (the paper reports 1.56-1.77x, section 6.2). Results go to docs/benchmarks.md.
//
//   build-X/bench/bench_stokes [--quick]
//
// Every solve uses the matrix-free back end at relative tolerance 1e-6 (the scene default).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <omp.h>

#include "reference/app/scene_file.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/fluid/viscosity.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// Liquid below y = 0.6 in a unit box (walls, open top) with a solid ball in it, viscosity eta,
/// and a smooth swirling u* plus one step of gravity: one solve of each kind on n^Dim cells.
template <int Dim>
void bench_grid(int n, double eta, int repeats) {
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {});
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = lattice.position(lattice.coord(k))[1] - 0.6;
  const StokesWeights w = monolith::testing::stokes_weights(grid, solid_phi, phi, boundary, 1000.0, eta);
  const double dt = 0.01;
  VectorX u_star(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, c] = grid.face_coord(f);
    const Vec<Dim> x = grid.face_center(axis, c);
    u_star[f] = std::sin(3 * x[(axis + 1) % Dim] + axis) * std::cos(2 * x[axis]) -
                (axis == 1 ? 9.81 * dt : 0.0);
  }
  PcgSettings settings;
  settings.tolerance = 1e-6;
  settings.max_iterations = 100000;

  // PVC: eq. (8) in (tau, p), reduced
  double t_pvc = 0.0;
  int it_pvc = 0, dofs_p = 0, dofs_s = 0;
  for (int r = 0; r < repeats; ++r) {
    VectorX u = u_star;
    const auto t0 = Clock::now();
    const StokesSolveResult s = solve_stokes(grid, w, dt, StokesUnknowns::pressure_and_stress,
                                             StressForm::reduced, Backend::matrix_free, settings, u);
    t_pvc += seconds_since(t0);
    it_pvc = s.pcg.iterations;
    dofs_p = s.pressure_dofs;
    dofs_s = s.stress_dofs;
  }
  // PC-VC-PC: pressure, stress only (full), pressure
  double t_dec = 0.0;
  int it_dec[3] = {0, 0, 0};
  for (int r = 0; r < repeats; ++r) {
    VectorX u = u_star;
    const auto t0 = Clock::now();
    it_dec[0] = solve_pressure(grid, w.pressure, dt, Backend::matrix_free, settings, u).pcg.iterations;
    it_dec[1] = solve_stokes(grid, w, dt, StokesUnknowns::stress_only, StressForm::full,
                             Backend::matrix_free, settings, u)
                    .pcg.iterations;
    it_dec[2] = solve_pressure(grid, w.pressure, dt, Backend::matrix_free, settings, u).pcg.iterations;
    t_dec += seconds_since(t0);
  }
  std::printf("| %dD | %d^%d | %d | %d | %d | %d | %.4f | %d+%d+%d | %.4f | %.2f |\n", Dim, n, Dim,
              dofs_p, dofs_s, dofs_p + dofs_s, it_pvc, t_pvc / repeats, it_dec[0], it_dec[1],
              it_dec[2], t_dec / repeats, t_pvc / t_dec);
  std::fflush(stdout);
}

/// Runs a built-in scene with a scheme and returns (solve seconds, iterations) summed over frames.
std::pair<double, long> run_scene(const std::string& name, const std::string& scheme, int frames) {
  const SceneDesc scene =
      load_scene(name, {"solver.scheme=" + scheme, "time.frames=" + std::to_string(frames),
                        "render.enabled=false"});
  auto sim = make_simulation(scene);
  double seconds = 0.0;
  long iterations = 0;
  for (int f = 0; f < frames; ++f) {
    const FrameStats s = sim->advance_frame();
    seconds += s.timing[FramePhase::solve];
    iterations += s.solver.iterations;
  }
  return {seconds, iterations};
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  std::printf("threads: %d\n\n", omp_get_max_threads());
  for (double eta : {1.0, 100.0}) {
    std::printf("Per solve, eta = %g Pa s, dt = 0.01 s, liquid below y = 0.6 in a walled unit box:\n\n", eta);
    std::printf("| dim | grid | pressure DOFs | stress DOFs | unknowns | PVC iterations | PVC s/solve | "
                "PC-VC-PC iterations | PC-VC-PC s | time ratio |\n|---|---|---|---|---|---|---|---|---|---|\n");
    // the larger viscosity only on the smaller grids (its solves take many more iterations)
    const bool small = quick || eta > 1.0;
    for (int n : small ? std::vector<int>{32, 64} : std::vector<int>{32, 64, 128, 256})
      bench_grid<2>(n, eta, n <= 64 ? 3 : 1);
    for (int n : small ? std::vector<int>{12, 16} : std::vector<int>{12, 16, 24, 32})
      bench_grid<3>(n, eta, n <= 16 ? 3 : 1);
    std::printf("\n");
  }

  std::printf("Whole scenes (solve time summed over the frames):\n\n");
  std::printf("| scene | frames | PVC-unified s (iterations) | PC-VC-PC-unified s (iterations) | ratio |\n"
              "|---|---|---|---|---|\n");
  for (const auto& [name, frames] :
       {std::pair{"viscous-sphere-wall-2d", quick ? 5 : 20}, std::pair{"viscous-sphere-wall-3d", quick ? 3 : 6}}) {
    const auto pvc = run_scene(name, "PVC-unified", frames);
    const auto dec = run_scene(name, "PC-VC-PC-unified", frames);
    std::printf("| %s | %d | %.2f (%ld) | %.2f (%ld) | %.2f |\n", name, frames, pvc.first,
                pvc.second, dec.first, dec.second, pvc.first / dec.first);
    std::fflush(stdout);
  }
  return 0;
}
