// Benchmark (not a test): the paper's Tables 1-3 for our scaled built-in scenes. Each scene of a
// table runs from its first frame under each of the table's schemes (rendering off, everything
// else as in the scene file, loaded like `monolith run NAME --frames K --scheme S --no-render`),
// and the per-frame statistics (reference/sim/frame_stats.hpp) are averaged:
//   Table 1: Fig. 2 liquid-bunny-into-bowl, Fig. 3 bunny-onto-floating-bowl;
//            P-C, C-P, PC-iterative, PC-unified.
//   Table 2: Fig. 4 viscous-sphere-bunny-wall, Fig. 5 bunny-on-viscous-hemisphere;
//            PC-VC-PC-unified, PVC-unified.
//   Table 3: Fig. 6 viscous-blob-into-bowl, Fig. 7 bunnies-into-floating-bowl-viscous;
//            PV-C, C-PV, PVC-iterative, PVC-unified.
// The iterative schemes run with the scene's own staggered cap (solver.staggered_iterations, 2 in
// every one of these files) and, unless high_cap is 0, a second time with a high cap (the paper
// uses 200 for Figs. 3 and 7) so that the cost of actually converging shows.
//
// Columns (per frame unless said otherwise): the phases of the paper's tables, fluid (P, PV),
// contact (C) and coupled (PC, PVC; for PC-VC-PC-unified all three unified solves) in seconds of
// the solves themselves (solver.phases); T = timing.solve, the whole pressure / viscosity /
// contact step (contact detection, weights of the bodies, assembly of eq. (24) and the solves),
// which is what the paper's T measures; s_iter = staggered iterations per step (the outer rounds
// of the iterative schemes, the friction rounds otherwise); iterations per phase per step; DOFs
// as the mean over frames of each frame's largest system; the liquid volume drift at the last
// frame and the worst over the run (relative to frame 0); the deepest contact penetration over
// dx; the frames whose solves all converged. Then the ratios iterative / unified of T and of the
// phase seconds (the goal: >= 5x; the paper reports about 8-10x for PC and 7x for PVC).
//
// Run: build/bench/bench_paper_scenes [2d|3d|all] [frames] [threads] [csv] [high_cap] [cells3d]
//                                     [tables]
//   2d|3d|all  which scenes (default 2d)
//   frames     frames per run from the start (0: 20 in 2D, 4 in 3D)
//   threads    OpenMP threads (default 1)
//   csv        output file (default bench_paper_scenes.csv), one row per run
//   high_cap   staggered cap of the second iterative run (default 200; 0: no second run)
//   cells3d    3D grid override n -> domain.cells = [n, n, n] (0: the scene's 32^3); every one
//              of these scenes has a unit cube domain, so the cells stay cubic and the bodies
//              inside at any n
//   tables     which tables, as digits (default 123; e.g. 13 for Tables 1 and 3)
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"
#include "reference/sim/frame_stats.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

using Clock = std::chrono::steady_clock;

/// One table of the paper: its figures' scenes and the schemes compared on them.
struct TableSpec {
  int number;
  std::vector<std::pair<std::string, std::string>> scenes;  ///< figure, scene stem
  std::vector<CouplingScheme> schemes;
  std::string fluid_name, coupled_name;  ///< the paper's column names for the phases
  std::string fluid_iter, coupled_iter;  ///< and for their iterations
};

const std::vector<TableSpec> kTables = {
    {1,
     {{"Fig. 2", "liquid-bunny-into-bowl"}, {"Fig. 3", "bunny-onto-floating-bowl"}},
     {CouplingScheme::p_c, CouplingScheme::c_p, CouplingScheme::pc_iterative, CouplingScheme::pc_unified},
     "P",
     "PC",
     "p_iter",
     "pc_iter"},
    {2,
     {{"Fig. 4", "viscous-sphere-bunny-wall"}, {"Fig. 5", "bunny-on-viscous-hemisphere"}},
     {CouplingScheme::pc_vc_pc_unified, CouplingScheme::pvc_unified},
     "PV",
     "PC+VC+PC / PVC",
     "p_iter",
     "pc+vc+pc / pvc_iter"},
    {3,
     {{"Fig. 6", "viscous-blob-into-bowl"}, {"Fig. 7", "bunnies-into-floating-bowl-viscous"}},
     {CouplingScheme::pv_c, CouplingScheme::c_pv, CouplingScheme::pvc_iterative, CouplingScheme::pvc_unified},
     "PV",
     "PVC",
     "p_iter",
     "pvc_iter"},
};

/// What one run of a scene under a scheme measured, summed over its frames.
struct RunResult {
  int table = 0;
  std::string figure, scene;
  CouplingScheme scheme = CouplingScheme::pvc_unified;
  int cap = 0;            ///< staggered cap (solver.staggered_iterations) of the run
  bool high_cap = false;  ///< the second run of an iterative scheme
  std::string cells;
  int frames_asked = 0, frames_done = 0;
  long steps = 0;
  double fluid_s = 0, contact_s = 0, coupled_s = 0, solve_s = 0, total_s = 0, wall_s = 0;
  long fluid_it = 0, contact_it = 0, coupled_it = 0, staggered = 0;
  double dof_p = 0, dof_s = 0, dof_c = 0, dof_f = 0;  ///< sums of the per-frame maxima
  double volume0 = 0, volume_end = 0, worst_drift = 0;
  double max_penetration_dx = 0;
  int converged_frames = 0;
  std::string failure;  ///< SimulationError message, empty if the run finished

  double per_frame(double x) const { return frames_done > 0 ? x / frames_done : 0.0; }
  double per_step(double x) const { return steps > 0 ? x / steps : 0.0; }
  double phases() const { return fluid_s + contact_s + coupled_s; }
  double drift_end() const { return volume0 > 0 ? volume_end / volume0 - 1.0 : 0.0; }
};

std::string quoted(const std::string& s) { return nlohmann::json(s).dump(); }

/// Runs `stem` under `scheme` for `frames` frames like `monolith run` (overrides in the CLI's
/// order: frames, scheme, then --set ones, rendering off last).
RunResult run_one(const TableSpec& t, const std::string& figure, const std::string& stem, int dim,
                  CouplingScheme scheme, int frames, int cap, int cells3d) {
  RunResult r;
  r.table = t.number;
  r.figure = figure;
  r.scene = stem + (dim == 2 ? "-2d" : "-3d");
  r.scheme = scheme;
  r.frames_asked = frames;
  std::vector<std::string> overrides = {"time.frames=" + std::to_string(frames),
                                        "solver.scheme=" + quoted(enum_name(scheme))};
  if (cap > 0) overrides.push_back("solver.staggered_iterations=" + std::to_string(cap));
  if (dim == 3 && cells3d > 0) {
    const std::string n = std::to_string(cells3d);
    overrides.push_back("domain.cells=[" + n + "," + n + "," + n + "]");
  }
  overrides.push_back("render.enabled=false");
  const SceneDesc scene = load_scene(r.scene, overrides);
  r.cap = scene.solver.staggered_iterations;
  r.high_cap = cap > 0;
  for (std::size_t a = 0; a < scene.domain.cells.size(); ++a)
    r.cells += (a ? "x" : "") + std::to_string(scene.domain.cells[a]);
  const double dx = scene.dx();

  const auto start = Clock::now();
  std::unique_ptr<AnySimulation> sim = make_simulation(scene);
  const FrameStats initial = sim->current_stats();
  r.volume0 = r.volume_end = initial.liquid_volume;
  for (int k = 1; k <= frames; ++k) {
    FrameStats f;
    try {
      f = sim->advance_frame();
    } catch (const SimulationError& e) {
      r.failure = "frame " + std::to_string(k) + ": " + e.what();
      break;
    }
    // sums over the frames (the stats already sum over the frame's steps)
    ++r.frames_done;
    r.steps += f.steps;
    const SolverStats& s = f.solver;
    r.fluid_s += s.fluid_seconds;
    r.contact_s += s.contact_seconds;
    r.coupled_s += s.coupled_seconds;
    r.fluid_it += s.fluid_iterations;
    r.contact_it += s.contact_iterations;
    r.coupled_it += s.coupled_iterations;
    r.staggered += s.staggered_iterations;
    r.dof_p += s.dofs_pressure;
    r.dof_s += s.dofs_stress;
    r.dof_c += s.dofs_contact;
    r.dof_f += s.dofs_friction;
    r.solve_s += f.timing[FramePhase::solve];
    r.total_s += f.timing[FramePhase::total];
    if (s.converged) ++r.converged_frames;
    r.volume_end = f.liquid_volume;
    if (r.volume0 > 0) r.worst_drift = std::max(r.worst_drift, std::abs(f.liquid_volume / r.volume0 - 1.0));
    r.max_penetration_dx = std::max(r.max_penetration_dx, f.max_penetration / dx);
    std::fprintf(stderr, "\r  %-40s %-17s cap %3d  frame %3d/%d  %.0f s   ", r.scene.c_str(), enum_name(scheme).c_str(),
                 r.cap, k, frames, std::chrono::duration<double>(Clock::now() - start).count());
  }
  r.wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  std::fprintf(stderr, "\n");
  return r;
}

std::string fmt(const char* f, double x) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, x);
  return buf;
}

/// Seconds with three significant digits (blank for a phase the scheme does not have).
std::string secs(double x) { return x > 0 ? fmt(x < 0.01 ? "%.2g" : "%.3g", x) : ""; }

std::string scheme_label(const RunResult& r) {
  return enum_name(r.scheme) + (r.high_cap ? " (cap " + std::to_string(r.cap) + ")" : "");
}

/// One markdown table of the paper's shape for table t's runs.
void print_table(const TableSpec& t, const std::vector<RunResult>& runs, int dim) {
  std::printf("\nTable %d (%dD), per frame; iterations per step; DOFs mean of the per-frame largest system\n\n",
              t.number, dim);
  const bool viscous = t.number > 1;
  std::printf("| figure | scene grid | scheme | %s (s) | C (s) | %s (s) | phases (s) | T (s) | s_iter | %s | "
              "c_iter | %s | p_dof | %sc_dof | volume drift end / worst | max pen. / dx | converged | wall (s) |\n",
              t.fluid_name.c_str(), t.coupled_name.c_str(), t.fluid_iter.c_str(), t.coupled_iter.c_str(),
              viscous ? "s_dof | " : "");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|%s---|---|---|---|---|\n", viscous ? "---|" : "");
  for (const RunResult& r : runs) {
    if (r.table != t.number) continue;
    std::printf("| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s%s | %s %% / %s %% | %s | %d/%d%s | %.0f |\n",
                r.figure.c_str(), r.cells.c_str(), scheme_label(r).c_str(), secs(r.per_frame(r.fluid_s)).c_str(),
                secs(r.per_frame(r.contact_s)).c_str(), secs(r.per_frame(r.coupled_s)).c_str(),
                secs(r.per_frame(r.phases())).c_str(), secs(r.per_frame(r.solve_s)).c_str(),
                fmt("%.2f", r.per_step(r.staggered)).c_str(), fmt("%.1f", r.per_step(r.fluid_it)).c_str(),
                fmt("%.1f", r.per_step(r.contact_it)).c_str(), fmt("%.1f", r.per_step(r.coupled_it)).c_str(),
                fmt("%.0f", r.per_frame(r.dof_p)).c_str(),
                viscous ? (fmt("%.0f", r.per_frame(r.dof_s)) + " | ").c_str() : "",
                fmt("%.1f", r.per_frame(r.dof_c)).c_str(), fmt("%+.1f", 100 * r.drift_end()).c_str(),
                fmt("%.1f", 100 * r.worst_drift).c_str(), fmt("%.2f", r.max_penetration_dx).c_str(),
                r.converged_frames, r.frames_done, r.failure.empty() ? "" : " (failed)", r.wall_s);
  }
  for (const RunResult& r : runs)
    if (r.table == t.number && !r.failure.empty())
      std::printf("\n%s %s failed at %s\n", r.scene.c_str(), scheme_label(r).c_str(), r.failure.c_str());
}

const RunResult* find(const std::vector<RunResult>& runs, const std::string& scene, CouplingScheme scheme,
                      bool high_cap) {
  for (const RunResult& r : runs)
    if (r.scene == scene && r.scheme == scheme && r.high_cap == high_cap) return &r;
  return nullptr;
}

/// The ratios the paper quotes: iterative / unified (Tables 1, 3), PVC / PC-VC-PC (Table 2), and
/// the unified scheme against the one-pass partitioned ones.
void print_ratios(const std::vector<RunResult>& runs) {
  std::printf("\nRatios of T (timing.solve) and of the phase seconds, per frame\n\n");
  std::printf("| scene | ratio | T | phases |\n|---|---|---|---|\n");
  auto row = [](const RunResult* a, const RunResult* b, const std::string& what) {
    if (!a || !b || b->solve_s <= 0 || b->phases() <= 0) return;
    std::printf("| %s | %s | %.2f | %.2f |\n", a->scene.c_str(), what.c_str(),
                a->per_frame(a->solve_s) / b->per_frame(b->solve_s), a->per_frame(a->phases()) / b->per_frame(b->phases()));
  };
  using S = CouplingScheme;
  for (const RunResult& r : runs) {
    if (r.scheme != S::pc_unified && r.scheme != S::pvc_unified) continue;
    const bool viscous = r.scheme == S::pvc_unified;
    const std::string unified = enum_name(r.scheme);
    if (r.table == 2) {
      row(&r, find(runs, r.scene, S::pc_vc_pc_unified, false),
          unified + " / " + enum_name(S::pc_vc_pc_unified));
      continue;
    }
    // the iterative and the two one-pass partitioned schemes of the same unknowns
    const S iterative = viscous ? S::pvc_iterative : S::pc_iterative;
    const S fluid_first = viscous ? S::pv_c : S::p_c, contact_first = viscous ? S::c_pv : S::c_p;
    for (bool high : {false, true}) {
      const RunResult* it = find(runs, r.scene, iterative, high);
      if (it)
        row(it, &r, enum_name(iterative) + " (cap " + std::to_string(it->cap) + ") / " + unified);
    }
    row(&r, find(runs, r.scene, fluid_first, false), unified + " / " + enum_name(fluid_first));
    row(&r, find(runs, r.scene, contact_first, false), unified + " / " + enum_name(contact_first));
  }
}

void write_csv(const std::string& path, const std::vector<RunResult>& runs) {
  std::ofstream f(path);
  f << "table,figure,scene,cells,scheme,staggered_cap,frames,frames_done,steps,fluid_s_per_frame,"
       "contact_s_per_frame,coupled_s_per_frame,phases_s_per_frame,T_solve_s_per_frame,total_s_per_frame,"
       "s_iter_per_step,fluid_iter_per_step,contact_iter_per_step,coupled_iter_per_step,p_dof,s_dof,c_dof,"
       "friction_dof,volume_drift_end,volume_drift_worst,max_penetration_dx,converged_frames,wall_s,failure\n";
  for (const RunResult& r : runs)
    f << r.table << ',' << r.figure << ',' << r.scene << ',' << r.cells << ',' << enum_name(r.scheme) << ',' << r.cap << ','
      << r.frames_asked << ',' << r.frames_done << ',' << r.steps << ',' << r.per_frame(r.fluid_s) << ','
      << r.per_frame(r.contact_s) << ',' << r.per_frame(r.coupled_s) << ',' << r.per_frame(r.phases()) << ','
      << r.per_frame(r.solve_s) << ',' << r.per_frame(r.total_s) << ',' << r.per_step(r.staggered) << ','
      << r.per_step(r.fluid_it) << ',' << r.per_step(r.contact_it) << ',' << r.per_step(r.coupled_it) << ','
      << r.per_frame(r.dof_p) << ',' << r.per_frame(r.dof_s) << ',' << r.per_frame(r.dof_c) << ','
      << r.per_frame(r.dof_f) << ',' << r.drift_end() << ',' << r.worst_drift << ',' << r.max_penetration_dx << ','
      << r.converged_frames << ',' << r.wall_s << ',' << quoted(r.failure) << '\n';
}

int positive_or(const char* text, int fallback) {
  const int v = std::atoi(text);
  return v > 0 ? v : fallback;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string which = argc > 1 ? argv[1] : "2d";
  if (which != "2d" && which != "3d" && which != "all") {
    std::fprintf(stderr, "usage: bench_paper_scenes [2d|3d|all] [frames] [threads] [csv] [high_cap] [cells3d] [tables]\n");
    return 2;
  }
  const int frames_arg = argc > 2 ? std::atoi(argv[2]) : 0;
  const int threads = argc > 3 ? positive_or(argv[3], 1) : 1;
  const std::string csv = argc > 4 ? argv[4] : "bench_paper_scenes.csv";
  const int high_cap = argc > 5 ? std::max(0, std::atoi(argv[5])) : 200;
  const int cells3d = argc > 6 ? std::max(0, std::atoi(argv[6])) : 0;
  const std::string tables = argc > 7 ? argv[7] : "123";
  omp_set_num_threads(threads);

  std::vector<int> dims;
  if (which != "3d") dims.push_back(2);
  if (which != "2d") dims.push_back(3);
  std::vector<RunResult> runs;
  try {
    for (int dim : dims) {
      const int frames = frames_arg > 0 ? frames_arg : (dim == 2 ? 20 : 4);
      std::printf("\n## %dD: %d frames per run from the start, %d thread(s), rendering off\n", dim, frames, threads);
      std::fflush(stdout);
      const std::size_t first = runs.size();
      for (const TableSpec& t : kTables) {
        if (tables.find(char('0' + t.number)) == std::string::npos) continue;
        for (const auto& [figure, stem] : t.scenes) {
          for (const CouplingScheme scheme : t.schemes) {
            runs.push_back(run_one(t, figure, stem, dim, scheme, frames, 0, cells3d));
            write_csv(csv, runs);
            const bool iterative = scheme_is_iterative(scheme);
            if (iterative && high_cap > 0 && high_cap != runs.back().cap) {
              runs.push_back(run_one(t, figure, stem, dim, scheme, frames, high_cap, cells3d));
              write_csv(csv, runs);
            }
          }
        }
        print_table(t, std::vector<RunResult>(runs.begin() + first, runs.end()), dim);
        std::fflush(stdout);
      }
      print_ratios(std::vector<RunResult>(runs.begin() + first, runs.end()));
      std::fflush(stdout);
    }
  } catch (const InputError& e) {
    std::fprintf(stderr, "input error: %s\n", e.what());
    return 2;
  }
  std::printf("\nwrote %s (%zu runs)\n", csv.c_str(), runs.size());
  return 0;
}
