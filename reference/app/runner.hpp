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
  int threads = 0;                     ///< 0: OpenMP's default
  bool no_render = false;
  bool quiet = false;
};

using SimulationFactory = std::function<std::unique_ptr<AnySimulation>(const SceneDesc&)>;
/// Draws the current state of a simulation made by the factory (render_simulation for the
/// simulations of make_simulation).
using FrameRenderer = std::function<Image(const AnySimulation&, const RenderSpec&)>;

/// Runs a scene and writes its outputs. Returns 0 on success and 3 after a SimulationError
/// (summary.json then has status "failed" and the frame); throws InputError for bad input.
int run_scene(const RunOptions& options, std::ostream& err, const SimulationFactory& factory,
              const FrameRenderer& render = render_simulation);

/// run_cli (reference/app/cli.hpp) with the simulation factory and renderer injected.
int run_cli_with(const std::vector<std::string>& args, std::ostream& out, std::ostream& err,
                 const SimulationFactory& factory, const FrameRenderer& render = render_simulation);

}  // namespace monolith
