#pragma once
/// \file scene_desc.hpp
/// The plain description of a scene that the simulation takes (Simulation<Dim>, make_simulation):
/// domain, time stepping, solver settings, particles, liquids, bodies and probes, as structs and
/// enums without any file format. The scene file format "monolith-scene/1" (docs/scene-format.md)
/// is read into it by the application (reference/app/scene_file.hpp); C++ users may fill it
/// directly. Every option has its one default here, in the member initialisers. A SceneDesc is
/// dimension-agnostic: vectors are std::vector<double> of `dim` entries, converted to Vec<Dim>
/// by the simulation.

#include <array>
#include <string>
#include <vector>

#include "reference/coupling/coupling_scheme.hpp"
#include "reference/fluid/liquid_spec.hpp"
#include "reference/geometry/shape_spec.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/rigid/body_spec.hpp"
#include "reference/solvers/backend.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

/// `solver.on_nonconvergence`: what a run does with a frame in which a solve stopped at
/// solver.max_iterations (or a staggered scheme at its rounds) without reaching the tolerance.
/// Either way the frame's solver.converged is false and stderr names the solve.
enum class NonconvergencePolicy {
  warn,  ///< report it and go on (the default)
  fail,  ///< report it and end the run as a simulation failure (exit 3) after the frame's outputs
};

template <>
struct EnumNames<NonconvergencePolicy> {
  static constexpr std::array<std::pair<NonconvergencePolicy, const char*>, 2> values{
      {{NonconvergencePolicy::warn, "warn"}, {NonconvergencePolicy::fail, "fail"}}};
};

struct ProbeSpec {
  std::string name;
  std::vector<double> position;
};

struct DomainSpec {
  std::vector<double> lower, upper;
  std::vector<int> cells;
  /// Per face in the order x-, x+, y-, y+, z-, z+ (the first 2*dim are used).
  std::array<BoundaryType, 6> boundary{BoundaryType::wall, BoundaryType::wall, BoundaryType::wall,
                                       BoundaryType::wall, BoundaryType::wall, BoundaryType::wall};
  double wall_friction = 0.0;
  double wall_restitution = 0.0;
};

struct TimeSpec {
  double fps = 50.0;
  int frames = 100;
  double cfl = 3.0;
  double max_dt = 0.02;
};

struct SolverSpec {
  CouplingScheme scheme = CouplingScheme::pvc_unified;
  double tolerance = 1e-6;
  int max_iterations = 2000;
  int staggered_iterations = 2;
  Backend backend = Backend::matrix_free;
  /// The preconditioner of the liquid's unified solves without bodies (eq. (8) in (tau, p), the
  /// stress-only viscosity solve of PC-VC-PC): "auto" (default: per solve, SSOR where its
  /// estimated iteration count from the stiffness eta_max dt / (rho dx^2) and the grid is within
  /// 60, else multigrid; choose_preconditioner),
  /// "multigrid", or the paper's "ssor" (docs/preconditioners.md). The coupled systems (24)/(26)
  /// with bodies and stress unknowns follow the same choice (the block preconditioner of
  /// coupled_preconditioner.hpp, docs/preconditioners.md "The coupled systems"); the
  /// pressure-only solves, coupled or not, follow pressure_preconditioner.
  PreconditionerChoice preconditioner = PreconditionerChoice::automatic;
  /// `solver.pressure_preconditioner`: the preconditioner of the liquid's pressure-only solves
  /// beside static solids (eq. (8) without stress: PC-unified, the P solves of PC-VC-PC):
  /// "ssor" (default, the paper's) or "multigrid" (MGPCG, a cell V-cycle; docs/preconditioners.md).
  PreconditionerKind pressure_preconditioner = PreconditionerKind::ssor;
  /// Start each unified / viscosity solve from the previous step's stress and pressure (with the
  /// multigrid preconditioner only; SSOR keeps the paper's zero start). Not a scene key.
  bool stokes_warm_start = false;
  double baumgarte = 0.2;
  /// `solver.max_recovery_speed` (m/s): the cap on eq. (16)'s recovery speed -beta phi / dt
  /// (ContactParameters::max_recovery_speed); 0 (the key absent) = the default rule
  /// beta dx / min(time.max_dt, 1 / time.fps), the speed eq. (16) gives a penetration of one
  /// cell at the scene's largest step (RigidWorldSettings::from_scene).
  double max_recovery_speed = 0.0;
  double contact_margin = 0.1;  ///< epsilon of section 3.2.4, in units of dx
  double shrink = 0.01;         ///< zeta of section 4.4.6, in units of dx
  double diagonal_boost = 1e-4; ///< gamma of section 4.4.5
  NonconvergencePolicy on_nonconvergence = NonconvergencePolicy::warn;
  /// Algorithm 2's line 1 in the simulator (section 5): true (default) starts each step's
  /// viscosity rounds from the previous step's shear rate where it has one, false from the rate
  /// of u* as printed (docs/non-newtonian.md). Not a scene key: set from C++ (tests, benches).
  bool viscosity_warm_start = true;
};

/// Particle seeding and maintenance.
struct ParticleSpec {
  int per_cell = 0;                  ///< 0 = the default of the dimension (count_per_cell)
  unsigned seed = 1;                 ///< jitter seed: runs are reproducible
  bool position_correction = true;   ///< keep particles evenly spread (volume steady)
  /// Steps of the whole simulation step run on the seeded liquid before t = 0, every velocity
  /// (the liquid's, the dynamic bodies') zeroed before each, so that a scene meant to start at
  /// rest starts from the discrete equilibrium of its particles and floating bodies instead of
  /// the jittered seeding's; the initial velocities are given back at t = 0 (Simulation::settle;
  /// docs/particles.md, "A settled start"). 0: none.
  int settle_steps = 0;
  /// Particles seeded per liquid cell: per_cell, or by default 4 in 2D and 8 in 3D.
  int count_per_cell(int dim) const { return per_cell > 0 ? per_cell : (dim == 2 ? 4 : 8); }
};

struct SceneDesc {
  std::string name;
  int dim = 2;
  DomainSpec domain;
  std::vector<double> gravity;  ///< dim numbers (m/s^2); empty = default_gravity(dim)
  TimeSpec time;
  SolverSpec solver;
  ParticleSpec particles;
  std::vector<LiquidSpec> liquids;
  std::vector<BodySpec> bodies;
  std::vector<ProbeSpec> probes;

  /// Cell width (cells are cubic: validated).
  double dx() const { return (domain.upper[0] - domain.lower[0]) / domain.cells[0]; }
};

/// The default gravity of a scene of `dim` dimensions: 9.81 m/s^2 along -y.
std::vector<double> default_gravity(int dim);

}  // namespace monolith
