// Benchmark (not a test) of the hot kernels at 1 and 2 threads, on an idle machine and with a
// competing busy process pinned to one core, in one run (issue 19; docs/benchmarks.md, section
// "Threads on a busy machine"). Prints, per kernel, the median time at 1 and 2 threads (measured
// and fixed team) idle and busy, and the ratios t(1 thread) / t(2 threads) (above 1: the second thread helps; the goals
// ask >= 1.6 idle on the Stokes solve and the particle step, >= 0.95 busy everywhere).
//
//   build/bench/bench_threads [--n N] [--particles-n N] [--scene NAME[,NAME...]] [--frames F] [--budget S]
//                             [--only SUBSTRING[,SUBSTRING...]] [--no-busy]
//
// "2t" is the library's default with 2 threads: each parallel kernel chooses its team size (1 or
// 2) by measuring itself (AdaptiveTeam, reference/core/parallel.hpp); "2t fixed" runs every
// region with the whole team of 2 (set_adaptive_teams(false) and set_core_monitor(false),
// MONOLITH_ADAPTIVE_THREADS=0 for the scene's child process). The default also caps every
// region at the cores other processes leave free (ProcessTeam, parallel.hpp).
//
// Kernels: the 3D matrix-free Stokes operator of eq. (8)/(24) (apply, one SSOR application =
// forward + backward red-black sweep, 30 SSOR-PCG iterations = "the solve"), the 3D matrix-free
// pressure operator (apply, SSOR), an MPRGP sweep (ColouredSparseOperator's SSOR on a 3D
// 7-point matrix coloured by Welsh-Powell), the particle transfers P2G and G2P and advection on
// a 3D grid with 8 particles per liquid cell, and a whole 3D scene (`monolith run` in a child
// process, wall time, --threads 1 / 2). The busy process is a fork of this program spinning
// on the last CPU of the affinity mask (as `taskset -c 1 sh -c 'while :; do :; done'`).
#include <omp.h>
#include <sched.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "reference/core/parallel.hpp"
#include "tests/support/sparse_helpers.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"
#include "reference/solvers/colouring.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/pcg.hpp"

using namespace monolith;

namespace {

using Clock = std::chrono::steady_clock;
constexpr double kRho = 1000.0, kDt = 0.01;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// Median time of f over at least `min_runs` runs and about `budget` seconds (at most 100 runs).
double median_time(const std::function<void()>& f, double budget, std::size_t min_runs = 3) {
  std::vector<double> t;
  double total = 0.0;
  while (t.size() < min_runs || (total < budget && t.size() < 100)) {
    const auto t0 = Clock::now();
    f();
    t.push_back(seconds_since(t0));
    total += t.back();
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

double load_average() {
  double l = -1.0;
  if (FILE* f = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(f, "%lf", &l) != 1) l = -1.0;
    std::fclose(f);
  }
  return l;
}

// --- the competing busy process ----------------------------------------------------------------

/// A child spinning on one CPU (the last of the affinity mask) until stop().
class BusyCore {
 public:
  void start() {
    const int cpu = affinity_cpus().back();
    pid_ = fork();
    if (pid_ == 0) {
      cpu_set_t set;
      CPU_ZERO(&set);
      CPU_SET(cpu, &set);
      sched_setaffinity(0, sizeof(set), &set);
      volatile unsigned long spin = 0;
      for (;;) spin = spin + 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));  // let it take the core
  }
  void stop() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    pid_ = -1;
  }
  ~BusyCore() { stop(); }

 private:
  pid_t pid_ = -1;
};

// --- the kernels -------------------------------------------------------------------------------

struct Kernel {
  std::string name;
  std::function<void()> run;
};

/// The viscous scene of bench_backends: liquid below y = 0.6 in a unit box (walls, open top), a
/// fixed ball under the surface, eta = 1, the reduced stress form.
struct StokesScene {
  MacGrid<3> grid;
  StokesWeights weights;
  VectorX u_star;
};

StokesScene stokes_scene(int n) {
  StokesScene s{MacGrid<3>(Vec<3>::Zero(), 1.0 / n, VecI<3>::Constant(n), {}), {}, {}};
  const SampleLattice<3> lattice = half_lattice(s.grid);
  std::array<BoundaryType, 6> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  ShapeSpec ball;
  ball.type = ShapeType::sphere;
  ball.center = {0.5, 0.3, 0.5};
  ball.radius = 0.15;
  const VectorX solid_phi =
      solid_phi_on_lattice<3>(s.grid, lattice, {make_shape<3>(ball, "bench.ball")}, 0.0);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = lattice.position(lattice.coord(k))[1] - 0.6;
  s.weights = uniform_stokes_weights<3>(s.grid, solid_phi, phi, boundary, kRho, 1.0);
  s.u_star.resize(s.grid.num_faces());
  for (int f = 0; f < s.grid.num_faces(); ++f) {
    const auto [axis, c] = s.grid.face_coord(f);
    const Vec<3> x = s.grid.face_center(axis, c);
    s.u_star[f] = std::sin(3 * x[(axis + 1) % 3] + axis) * std::cos(2 * x[axis]) -
                  (axis == 1 ? 9.81 * kDt : 0.0);
  }
  return s;
}

/// The `timing` object of every line of a stats.jsonl summed per key ("solve", "particles", ...),
/// as "key seconds" pairs in the order of the first line; empty when the file is missing.
std::vector<std::pair<std::string, double>> phase_seconds(const std::string& path) {
  std::vector<std::pair<std::string, double>> sums;
  FILE* f = std::fopen(path.c_str(), "r");
  if (!f) return sums;
  std::string line;
  for (int ch; (ch = std::fgetc(f)) != EOF;) {
    if (ch != '\n') {
      line += static_cast<char>(ch);
      continue;
    }
    const std::size_t at = line.find("\"timing\":");
    if (at != std::string::npos && line.find('{', at) != std::string::npos) {
      std::size_t pos = line.find('{', at) + 1;
      const std::size_t end = line.find('}', pos);
      while (pos < end) {
        const std::size_t q0 = line.find('"', pos);
        if (q0 == std::string::npos || q0 > end) break;
        const std::size_t q1 = line.find('"', q0 + 1);
        const std::string key = line.substr(q0 + 1, q1 - q0 - 1);
        const double value = std::atof(line.c_str() + line.find(':', q1) + 1);
        auto it = std::find_if(sums.begin(), sums.end(), [&](const auto& e) { return e.first == key; });
        if (it == sums.end()) sums.emplace_back(key, value);
        else it->second += value;
        pos = line.find(',', q1);
        if (pos == std::string::npos) break;
        ++pos;
      }
    }
    line.clear();
  }
  std::fclose(f);
  return sums;
}

std::string self_dir() {
  char buf[4096];
  const ssize_t len = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (len <= 0) return ".";
  std::string p(buf, static_cast<std::size_t>(len));
  return p.substr(0, p.rfind('/'));
}

}  // namespace

int main(int argc, char** argv) {
  apply_default_wait_policy(argv);
  int n = 64, particles_n = 64, frames = 1;
  double budget = 1.0;
  bool busy_runs = true;
  std::string scene = "liquid-drop-newtonian-3d", only;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_threads: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--n") n = std::atoi(next().c_str());
    else if (a == "--particles-n") particles_n = std::atoi(next().c_str());
    else if (a == "--scene") scene = next();
    else if (a == "--frames") frames = std::atoi(next().c_str());
    else if (a == "--budget") budget = std::atof(next().c_str());
    else if (a == "--only") only = next();
    else if (a == "--no-busy") busy_runs = false;
    else {
      std::fprintf(stderr, "bench_threads: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  std::printf("bench_threads: load %.2f at start; GOMP_SPINCOUNT=%s OMP_WAIT_POLICY=%s; CPUs %d\n",
              load_average(), std::getenv("GOMP_SPINCOUNT") ? std::getenv("GOMP_SPINCOUNT") : "-",
              std::getenv("OMP_WAIT_POLICY") ? std::getenv("OMP_WAIT_POLICY") : "-",
              static_cast<int>(affinity_cpus().size()));
  std::fflush(stdout);

  std::vector<Kernel> kernels;
  std::map<std::string, std::vector<std::vector<std::pair<std::string, double>>>> scene_phases;
  // --only A,B,...: the kernels whose name contains one of the substrings
  auto wanted_name = [&](const std::string& name) {
    if (only.empty()) return true;
    for (std::size_t from = 0; from <= only.size();) {
      const std::size_t comma = std::min(only.find(',', from), only.size());
      if (comma > from && name.find(only.substr(from, comma - from)) != std::string::npos) return true;
      from = comma + 1;
    }
    return false;
  };
  // a group is built when one of its kernels is wanted
  auto wanted = [&](const std::string& tag) {
    for (const char* k : {"", " apply", " SSOR", " solve (30 PCG it.)", " P2G", " G2P", " advect"})
      if (wanted_name(tag + k)) return true;
    return false;
  };

  // Stokes, 3D matrix-free
  std::unique_ptr<StokesScene> ss;
  std::unique_ptr<StressLayout<3>> layout;
  std::unique_ptr<StokesDofs> sdofs;
  std::unique_ptr<MatrixFreeStokesOperator<3>> stokes;
  VectorX sb, sx, sy, sz;
  const std::string stokes_tag = "stokes " + std::to_string(n) + "^3";
  const std::string pressure_tag = "pressure " + std::to_string(n) + "^3";
  if (wanted(stokes_tag) || wanted(pressure_tag)) {
    ss = std::make_unique<StokesScene>(stokes_scene(n));
  }
  if (wanted(stokes_tag)) {
    layout = std::make_unique<StressLayout<3>>(StressGrid<3>(ss->grid), StressForm::reduced);
    sdofs = std::make_unique<StokesDofs>(select_stokes_dofs(ss->grid, *layout, ss->weights, kDt,
                                                            StokesUnknowns::pressure_and_stress));
    stokes = std::make_unique<MatrixFreeStokesOperator<3>>(ss->grid, *layout, ss->weights, *sdofs, kDt);
    sb = stokes->rhs(ss->u_star);
    sx = VectorX::Zero(sb.size());
    std::printf("%s: %d unknowns\n", stokes_tag.c_str(), static_cast<int>(sb.size()));
    kernels.push_back({stokes_tag + " apply", [&] { stokes->apply(sb, sy); }});
    kernels.push_back({stokes_tag + " SSOR", [&] { ssor_precondition(*stokes, sb, sz, 1.0); }});
    kernels.push_back({stokes_tag + " solve (30 PCG it.)", [&] {
                         PcgSettings settings;
                         settings.tolerance = 1e-12;
                         settings.max_iterations = 30;
                         VectorX x = VectorX::Zero(sb.size());
                         pcg_solve(*stokes, sb, x, settings);
                       }});
  }
  // pressure, 3D matrix-free (the same scene's weights)
  std::unique_ptr<PressureDofs> pdofs;
  std::unique_ptr<MatrixFreePressureOperator<3>> pressure;
  VectorX pb, py, pz;
  if (wanted(pressure_tag)) {
    pdofs = std::make_unique<PressureDofs>(select_pressure_dofs<3>(ss->grid, ss->weights.pressure, kDt));
    pressure = std::make_unique<MatrixFreePressureOperator<3>>(ss->grid, ss->weights.pressure, *pdofs, kDt);
    pb = pressure->rhs(ss->u_star);
    std::printf("%s: %d unknowns\n", pressure_tag.c_str(), static_cast<int>(pb.size()));
    kernels.push_back({pressure_tag + " apply", [&] { pressure->apply(pb, py); }});
    kernels.push_back({pressure_tag + " SSOR", [&] { ssor_precondition(*pressure, pb, pz, 1.0); }});
  }
  // MPRGP's coloured sweep
  std::unique_ptr<ColouredSparseOperator> coloured;
  VectorX cb, cz;
  const int cm = 40;
  const std::string mprgp_tag = "MPRGP sweep " + std::to_string(cm) + "^3";
  if (wanted(mprgp_tag)) {
    SparseMatrix a = monolith::testing::seven_point_matrix(cm);
    Colouring colours = welsh_powell(matrix_adjacency(a));
    coloured = std::make_unique<ColouredSparseOperator>(std::move(a), std::move(colours));
    cb = VectorX::Ones(coloured->size());
    kernels.push_back({mprgp_tag + " SSOR", [&] { ssor_precondition(*coloured, cb, cz, 1.0); }});
  }
  // particles: 8 per cell in the lower 60 % of a particles_n^3 grid, a swirl velocity
  const MacGrid<3> pgrid(Vec<3>::Zero(), 1.0 / particles_n, VecI<3>::Constant(particles_n), {});
  Particles<3> particles, moved;
  VectorX pu, mass, density, pu_field;
  std::array<BoundaryType, 6> walls;
  walls.fill(BoundaryType::wall);
  const SolidField<3> no_solids;
  const std::string particle_tag = "particles " + std::to_string(particles_n) + "^3";
  if (wanted(particle_tag)) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    const double h = pgrid.dx();
    const int top = static_cast<int>(0.6 * particles_n);
    for (int k = 0; k < particles_n; ++k)
      for (int j = 0; j < top; ++j)
        for (int i = 0; i < particles_n; ++i)
          for (int p = 0; p < 8; ++p) {
            particles.x.push_back(Vec<3>((i + u01(rng)) * h, (j + u01(rng)) * h, (k + u01(rng)) * h));
            particles.v.push_back(Vec<3>(u01(rng) - 0.5, u01(rng) - 0.5, u01(rng) - 0.5));
            particles.c.push_back(Mat<3>::Zero());
            particles.mass.push_back(kRho * h * h * h / 8);
            particles.density.push_back(kRho);
            particles.liquid.push_back(0);
          }
    pu_field.resize(pgrid.num_faces());
    for (int f = 0; f < pgrid.num_faces(); ++f) {
      const auto [axis, c] = pgrid.face_coord(f);
      const Vec<3> x = pgrid.face_center(axis, c);
      pu_field[f] = 0.5 * std::sin(3 * x[(axis + 1) % 3] + axis);
    }
    std::printf("%s: %zu particles\n", particle_tag.c_str(), particles.size());
    kernels.push_back({particle_tag + " P2G", [&] { particles_to_grid(particles, pgrid, pu, mass, density); }});
    kernels.push_back({particle_tag + " G2P", [&] { grid_to_particles(particles, pgrid, pu_field); }});
    kernels.push_back({particle_tag + " advect", [&] {
                         moved = particles;
                         advect_particles(moved, pgrid, pu_field, 0.01, no_solids, walls);
                       }});
  }
  // whole 3D scenes through the CLI (--scene A,B,...); the per-phase seconds of each run (the
  // `timing` of stats.jsonl summed over the frames) go to scene_phases, printed after the table
  const std::string exe = self_dir() + "/../bin/monolith";
  std::vector<std::string> scenes;
  for (std::size_t from = 0; from <= scene.size();) {
    const std::size_t comma = std::min(scene.find(',', from), scene.size());
    if (comma > from) scenes.push_back(scene.substr(from, comma - from));
    from = comma + 1;
  }
  for (const std::string& name : scenes) {
    const std::string scene_tag = "scene " + name + " (" + std::to_string(frames) + " frame" +
                                  (frames == 1 ? "" : "s") + ")";
    auto run_scene = [&, name, scene_tag]() {
      const int threads = omp_get_max_threads();
      const std::string out = "/tmp/bench_threads_scene_" + std::to_string(getpid());
      const std::string cmd = std::string(adaptive_teams() ? "" : "MONOLITH_ADAPTIVE_THREADS=0 ") +
                              exe + " run " + name + " --frames " + std::to_string(frames) +
                              " --threads " + std::to_string(threads) +
                              " --no-render --quiet --out " + out + " >/dev/null 2>&1";
      if (std::system(cmd.c_str()) != 0) std::fprintf(stderr, "bench_threads: %s failed\n", cmd.c_str());
      scene_phases[scene_tag].push_back(phase_seconds(out + "/stats.jsonl"));
      std::system(("rm -rf " + out).c_str());
    };
    if (wanted_name(scene_tag)) kernels.push_back({scene_tag, run_scene});
  }

  // measure: every kernel idle then busy; 1 thread, 2 threads with the team size measured per
  // call (AdaptiveTeam, the library's default: "at most 2"), 2 threads always (fixed team)
  std::printf("\n%-40s %9s %9s %9s %6s %6s %9s %9s %9s %6s %6s\n", "kernel", "idle 1t", "2t",
              "2t fixed", "ratio", "fixed", "busy 1t", "2t", "2t fixed", "ratio", "fixed");
  for (const Kernel& k : kernels) {
    if (!wanted_name(k.name)) continue;
    double t[2][3] = {{0, 0, 0}, {0, 0, 0}};
    int team_after[2] = {0, 0};  // the process-wide team at the end of the 2t runs
    for (int busy = 0; busy < (busy_runs ? 2 : 1); ++busy) {
      BusyCore spinner;
      if (busy) spinner.start();
      for (int config = 0; config < 3; ++config) {
        omp_set_num_threads(config == 0 ? 1 : 2);
        set_adaptive_teams(config != 2);
        set_core_monitor(config != 2);
        const bool whole = k.name.rfind("scene", 0) == 0;
        if (!whole) k.run();  // warm up (a whole scene: one run, its start-up included)
        t[busy][config] = whole ? median_time(k.run, 0.0, 1) : median_time(k.run, budget);
        if (config == 1) team_after[busy] = process_threads();
      }
      set_adaptive_teams(true);
      set_core_monitor(true);
    }
    auto ms = [](double s) { return s * 1e3; };
    std::printf("%-40s %7.2fms %7.2fms %7.2fms %6.2f %6.2f", k.name.c_str(), ms(t[0][0]),
                ms(t[0][1]), ms(t[0][2]), t[0][0] / t[0][1], t[0][0] / t[0][2]);
    if (busy_runs)
      std::printf(" %7.2fms %7.2fms %7.2fms %6.2f %6.2f  team %d/%d", ms(t[1][0]), ms(t[1][1]),
                  ms(t[1][2]), t[1][0] / t[1][1], t[1][0] / t[1][2], team_after[0], team_after[1]);
    std::printf("\n");
    std::fflush(stdout);
  }
  // where a whole scene's time goes: the phases of stats.jsonl's `timing`, per configuration
  // (idle 1t, 2t, 2t fixed, then busy 1t, 2t, 2t fixed)
  for (const auto& [tag, runs] : scene_phases) {
    std::printf("\n%s, seconds per phase (stats.jsonl timing summed over the frames):\n", tag.c_str());
    const char* configs[] = {"idle 1t", "idle 2t", "idle 2t fixed", "busy 1t", "busy 2t", "busy 2t fixed"};
    for (std::size_t r = 0; r < runs.size() && r < 6; ++r) {
      std::printf("  %-14s", configs[r]);
      for (const auto& [key, seconds] : runs[r])
        if (seconds > 0.0) std::printf(" %s %.3f", key.c_str(), seconds);
      std::printf("\n");
    }
  }
  std::printf("\nload %.2f at the end (ratio = t(1 thread) / t(2 threads, team measured), fixed = "
              "t(1 thread) / t(2 threads always); goals: idle >= 1.6 on the Stokes solve and the "
              "particle step, busy >= 0.95 everywhere)\n",
              load_average());
  return 0;
}
