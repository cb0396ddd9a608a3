#pragma once
/// \file simulation.hpp
/// The time loop of Algorithm 1. Simulation<Dim> owns the grid, particles, solids and solver
/// state; AnySimulation erases the dimension for the CLI.

#include <memory>

#include "reference/image.hpp"
#include "reference/render.hpp"
#include "reference/scene.hpp"
#include "reference/stats.hpp"

namespace monolith {

/// Dimension-erased interface used by the CLI runner.
class AnySimulation {
 public:
  virtual ~AnySimulation() = default;
  /// Statistics of the current state (frame 0 before any step).
  virtual FrameStats current_stats() const = 0;
  /// Advances to the next frame time with CFL-limited substeps that land exactly on it, and
  /// returns that frame's statistics. Throws SimulationError on a non-finite state or a solver
  /// breakdown.
  virtual FrameStats advance_frame() = 0;
  /// Renders the current state.
  virtual Image render(const RenderSpec& spec) const = 0;
  /// Gravitational potential energy of the liquid particles, -sum_p m_p g . x_p (J; 2D: J per
  /// metre of depth), zero at the origin; with the kinetic energy of FrameStats it gives the
  /// total energy that a liquid in a static container must never gain.
  virtual double liquid_potential_energy() const { return 0.0; }
};

/// Builds the simulation for scene.dim. Throws InputError for scenes that need physics this
/// build does not support yet (with the key path and what is missing).
std::unique_ptr<AnySimulation> make_simulation(const SceneDesc& scene);

}  // namespace monolith
