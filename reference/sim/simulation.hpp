#pragma once
/// \file simulation.hpp
/// The time loop of Algorithm 1. Simulation<Dim> owns the grid, particles, solids and solver
/// state; AnySimulation erases the dimension for the CLI.

#include <memory>
#include <string>

#include "reference/viz/image.hpp"
#include "reference/viz/render.hpp"
#include "reference/app/scene.hpp"
#include "reference/sim/stats.hpp"

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

/// The solves of lines 7-11 of Algorithm 1 for the liquid, without dynamic bodies.
enum class SolveSequence {
  pressure,   ///< eq. (8) without stress (solve_pressure)
  unified,    ///< eq. (8) in (tau, p) together, reduced stress (solve_stokes)
  decoupled,  ///< section 6.2: pressure, then stress only (p = 0), then pressure again
};

/// The sequence a scheme runs when no body is dynamic: P-C, C-P, PC-iterative, PC-unified ->
/// pressure (viscosity ignored); PV-C, C-PV, PVC-iterative, PVC-unified -> unified;
/// PC-VC-PC-unified -> decoupled. Without viscous liquid (`viscous` false) always pressure.
SolveSequence solve_sequence(const std::string& scheme, bool viscous);

/// Builds the simulation for scene.dim. Throws InputError for scenes that need physics this
/// build does not support yet (with the key path and what is missing).
std::unique_ptr<AnySimulation> make_simulation(const SceneDesc& scene);

}  // namespace monolith
