// Benchmark of the contact solve (not a test): a pile of N boxes and balls dropped into a walled
// container, run until they rest on one another, then the last step's contact problem solved
// again by staggered projections with MPRGP: iterations and time per solve against the number
// of contacts, and the speed-up of the coloured SSOR sweeps on 2 threads (omp_set_num_threads
// 1 vs 2, in the same run).
//
// Run: build/bench/bench_contact [max_bodies (default 500)] [repeats (default 5)]
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>

#include "reference/app/scene_file.hpp"
#include "reference/rigid/rigid_world.hpp"

using namespace monolith;
using nlohmann::json;

namespace {

/// N bodies on a jittered lattice in the upper part of the unit box, boxes and balls alternating.
SceneDesc pile_scene(int dim, int n) {
  const int per_axis = static_cast<int>(std::ceil(std::pow(n, 1.0 / dim)));
  const double pitch = 0.9 / per_axis;
  const double half = 0.33 * pitch;
  std::mt19937 rng(n);
  std::uniform_real_distribution<double> jitter(-0.05 * pitch, 0.05 * pitch);
  json bodies = json::array();
  for (int i = 0; i < n; ++i) {
    json c = json::array();
    int k = i;
    for (int a = 0; a < dim; ++a) {
      const int ia = k % per_axis;
      k /= per_axis;
      // the layers stack upwards along y (axis 1); x and z fill the floor
      c.push_back(0.05 + pitch * (ia + 0.5) + jitter(rng));
    }
    json shape;
    if (i % 2 == 0) {
      json hs = json::array();
      for (int a = 0; a < dim; ++a) hs.push_back(half * (a == 1 ? 0.7 : 1.0));
      shape = {{"type", "box"}, {"center", c}, {"half_size", hs}, {"rotation", dim == 2 ? json(0.3 * jitter(rng) / pitch) : json{0.0, 0.0, 3.0 * jitter(rng)}}};
    } else {
      shape = {{"type", "sphere"}, {"center", c}, {"radius", half}};
    }
    bodies.push_back({{"name", "b" + std::to_string(i)}, {"density", 500}, {"friction", 0.3}, {"shape", shape}});
  }
  const int cells = dim == 2 ? 64 : 32;
  json j = {{"format", "monolith-scene/1"}, {"name", "pile"}, {"dim", dim}};
  j["domain"] = {{"lower", dim == 2 ? json{0, 0} : json{0, 0, 0}},
                 {"upper", dim == 2 ? json{1, 1} : json{1, 1, 1}},
                 {"cells", dim == 2 ? json{cells, cells} : json{cells, cells, cells}},
                 {"wall_friction", 0.3}};
  j["solver"] = {{"staggered_iterations", 2}, {"tolerance", 1e-6}, {"max_iterations", 2000}};
  j["bodies"] = bodies;
  return parse_scene(j, "pile", ".");
}

double seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

template <int Dim>
void run(int n, int repeats) {
  RigidWorld<Dim> world(pile_scene(Dim, n));
  Vec<Dim> g = Vec<Dim>::Zero();
  g[1] = -9.81;
  // drop until they touch: 0.5 s at dt = 2.5 ms
  const double dt = 0.0025;
  const auto t_sim = std::chrono::steady_clock::now();
  omp_set_num_threads(2);
  for (int k = 0; k < 200; ++k) world.step(dt, k * dt, g);
  const double sim_seconds = seconds(t_sim);
  const ContactSystem<Dim>& sys = world.last_system();
  StaggeredSettings s;
  s.max_iterations = world.settings().staggered_iterations;
  s.tolerance = world.settings().tolerance;
  s.diagonal_boost = world.settings().diagonal_boost;
  s.mprgp.tolerance = world.settings().tolerance;
  s.mprgp.max_iterations = world.settings().max_iterations;
  double time[2] = {0, 0};
  long iterations = 0;
  bool converged = true;
  for (int threads = 1; threads <= 2; ++threads) {
    omp_set_num_threads(threads);
    const auto t0 = std::chrono::steady_clock::now();
    for (int r = 0; r < repeats; ++r) {
      const StaggeredResult res = solve_staggered_projections<Dim>(sys, s);
      iterations = res.mprgp_iterations;
      converged = converged && res.converged;
    }
    time[threads - 1] = seconds(t0) / repeats;
  }
  std::printf("| %dD | %d | %d | %d | %ld | %s | %.2f | %.2f | %.2f | %.1f |\n", Dim, n,
              sys.num_contacts(), sys.num_friction_rows(), iterations, converged ? "yes" : "no",
              1e3 * time[0], 1e3 * time[1], time[0] / time[1], sim_seconds);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  const int max_bodies = argc > 1 ? std::atoi(argv[1]) : 500;
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 5;
  std::printf("| dim | bodies | contacts | friction rows | MPRGP iterations per step solve | converged | "
              "ms per solve, 1 thread | ms, 2 threads | speed-up | s to simulate the drop (2 threads) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
  for (int n : {10, 50, 200, 500}) {
    if (n > max_bodies) break;
    run<2>(n, repeats);
  }
  for (int n : {10, 50, 200, 500}) {
    if (n > max_bodies) break;
    run<3>(n, repeats);
  }
  return 0;
}
