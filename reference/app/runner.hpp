#pragma once
/// \file runner.hpp
/// The `run` command of docs/cli.md: loads a scene, advances the simulation frame by frame and
/// writes frames/frame_NNNNN.ppm, stats.jsonl and summary.json. The simulation is made by an
/// injectable factory and drawn by an injectable renderer, so that the output logic can be
/// tested with a stand-in simulation.

#include <functional>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"
#include "reference/viz/image.hpp"
#include "reference/viz/render.hpp"

namespace monolith {

/// Options of `run` (and of `check`, which uses scene and overrides only).
struct RunOptions {
  std::string scene;                   ///< path or built-in name
  std::vector<std::string> overrides;  ///< KEY=VALUE, applied in order (the sugar flags included)
  std::string out_dir;                 ///< empty: out/<scene name>
  /// OpenMP threads: N > 0 as given; kAutoThreads: the free cores of the affinity mask
  /// (automatic_thread_count, reference/core/parallel.hpp); 0: OpenMP's default (OMP_NUM_THREADS).
  /// parse_options resolves --threads, then MONOLITH_THREADS, then OMP_NUM_THREADS, else auto.
  int threads = 0;
  static constexpr int kAutoThreads = -1;
  bool no_render = false;
  bool quiet = false;
  int checkpoint_every = 0;            ///< a checkpoint every N frames and at the end; 0: none
  /// `resume`: the run folder to continue (scene and out_dir then come from its checkpoint)
  /// and the new total frame count (-1: the scene's).
  std::string resume_dir;
  int resume_frames = -1;
  /// `resume --any-build`: continue a checkpoint written by another build of the same checkpoint
  /// format (A/B timing of late frames, a rebuilt binary); the continuation is then not bit for
  /// bit, which stderr and summary.json (`totals.earlier_build`) say.
  bool any_build = false;
};

using SimulationFactory = std::function<std::unique_ptr<AnySimulation>(const SceneDesc&)>;
/// Draws the current state of a simulation made by the factory (render_simulation for the
/// simulations of make_simulation).
using FrameRenderer = std::function<Image(const AnySimulation&, const RenderSpec&)>;

/// Runs a scene and writes its outputs. Returns 0 on success; 3 after a SimulationError, an
/// output that cannot be written or (solver.on_nonconvergence "fail") a solve that did not
/// converge (summary.json then has status "failed", the frame and the reason); 130 / 143 after
/// SIGINT / SIGTERM (stopped at a step boundary, checkpoint written, status "interrupted").
/// Throws InputError for bad input.
/// Sets the OpenMP thread count of RunOptions::threads (kAutoThreads: the free cores now; 0:
/// leaves OpenMP's default).
void apply_thread_option(int threads);

int run_scene(const RunOptions& options, std::ostream& err, const SimulationFactory& factory,
              const FrameRenderer& render = render_simulation);

/// `monolith resume DIR`: continues the run in options.resume_dir from its checkpoint
/// (reference/app/checkpoint.hpp), up to options.resume_frames frames when given. Refuses a
/// checkpoint that is missing, truncated, corrupted, from another build or of another scene
/// with InputError before any file in the folder is changed. Returns like run_scene.
int resume_run(const RunOptions& options, std::ostream& err, const SimulationFactory& factory,
               const FrameRenderer& render = render_simulation);

/// run_cli (reference/app/cli.hpp) with the simulation factory and renderer injected.
int run_cli_with(const std::vector<std::string>& args, std::ostream& out, std::ostream& err,
                 const SimulationFactory& factory, const FrameRenderer& render = render_simulation);

}  // namespace monolith
