#pragma once
/// \file frame_stats.hpp
/// Per-frame statistics as a plain struct: the simulation fills a FrameStats per frame; the
/// application writes it as one line of stats.jsonl (reference/app/stats_json.hpp, the keys of
/// docs/cli.md). Fields a scene has no use for (bodies, contacts, stress DOFs of a scene without
/// them) keep their shape with empty or zero values.

#include <algorithm>
#include <string>
#include <vector>

#include "reference/core/timer.hpp"
#include "reference/coupling/coupling_scheme.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

/// The phases of a frame's wall time (FrameStats::timing), each with its stats.jsonl name. A new
/// phase is one enumerator and its name; ScopedTimer fills it where it is measured.
enum class FramePhase {
  total,          ///< the whole frame: its steps, and in a run its picture and output files
  solve,          ///< the pressure / viscosity / contact solves (lines 6-12 of Algorithm 1)
  particles,      ///< transfers, advection, position correction, density projection, level set
  weights,        ///< volume fractions and the solve's set-up (W_F, W_L, eta, face densities)
  extrapolation,  ///< velocity extrapolation, wall and solid velocity conditions
  render,         ///< the frame's picture (run only)
  output,         ///< writing the frame's picture file (run only)
};

template <>
struct EnumNames<FramePhase> {
  static constexpr std::array<std::pair<FramePhase, const char*>, 7> values{
      {{FramePhase::total, "total"},
       {FramePhase::solve, "solve"},
       {FramePhase::particles, "particles"},
       {FramePhase::weights, "weights"},
       {FramePhase::extrapolation, "extrapolation"},
       {FramePhase::render, "render"},
       {FramePhase::output, "output"}}};
};

struct BodyStats {
  std::string name;
  std::vector<double> position;          ///< centre of mass
  std::vector<double> orientation;       ///< 2D: [angle]; 3D: quaternion [w, x, y, z]
  std::vector<double> velocity;
  std::vector<double> angular_velocity;  ///< 2D: [omega]; 3D: 3-vector
};

struct ProbeStats {
  std::string name;
  std::vector<double> position;
  std::vector<double> velocity;
  double pressure = 0.0;
};

/// A solve of a frame that stopped without reaching the tolerance (at solver.max_iterations, or
/// a staggered scheme at its rounds): which solve, its iterations and the relative residual it
/// reached. Reported on stderr by the runner, not written to stats.jsonl.
struct UnconvergedSolve {
  std::string solve;
  double time = 0.0;  ///< simulation time at the start of the step (s)
  long iterations = 0;
  double relative_residual = 0.0;
};

struct SolverStats {
  CouplingScheme scheme = CouplingScheme::pvc_unified;
  long iterations = 0;            ///< summed over the frame's steps
  /// The largest iteration count of one step of the frame (all its solves together): the
  /// per-step view of `iterations`, whose frame sum grows with the steps a CFL or body limit
  /// asks for (a frame of 23 steps of 4-7 iterations sums to 122; docs/preconditioners.md
  /// section 43).
  long max_step_iterations = 0;
  int staggered_iterations = 0;   ///< summed over the frame's steps
  double max_relative_residual = 0.0;
  bool converged = true;          ///< all solves of the frame converged
  /// The solves of the frame that did not converge, in order (empty when converged).
  std::vector<UnconvergedSolve> unconverged;
  long dofs_pressure = 0, dofs_stress = 0, dofs_contact = 0, dofs_friction = 0;  ///< max
  /// The phases of the paper's Tables 1-3, summed over the frame's steps: separate liquid
  /// solves (P, PV or VC without contact rows), separate contact solves (C), and unified solves
  /// (PC, PVC; the VC step of PC-VC-PC-unified counts here): iterations and wall time.
  long fluid_iterations = 0, contact_iterations = 0, coupled_iterations = 0;
  double fluid_seconds = 0.0, contact_seconds = 0.0, coupled_seconds = 0.0;
  /// Non-Newtonian liquids (Algorithm 2, section 5): the residual of each viscosity round of
  /// the frame's last step (NonNewtonianViscosity::residuals, Fig. 9's convergence plot) and
  /// the largest last-round residual over the frame's steps. Empty / 0 (and left out of the
  /// JSON) for Newtonian liquids.
  std::vector<double> viscosity_residuals;
  double max_viscosity_residual = 0.0;
  /// The liquid's unified / viscosity solves of the frame (solve_stokes) by the preconditioner
  /// they used (solver.preconditioner; "auto" picks per solve), and the largest stiffness
  /// eta_max dt / (rho dx^2) among them. All 0 (and left out of the JSON) without such solves.
  long stokes_solves_multigrid = 0, stokes_solves_ssor = 0;
  double max_stokes_stiffness = 0.0;
  /// Of the multigrid solves, those that did not converge within multigrid_attempt_budget and
  /// were solved again with SSOR (solver.preconditioner "auto"; docs/preconditioners.md
  /// section 20). Written to stats.jsonl only when not 0.
  long preconditioner_fallbacks = 0;
  /// PC-/PVC-iterative: the frame's steps whose fluid-contact rounds stopped at
  /// solver.staggered_iterations before (lambda, x_f) settled (CoupledSolveResult::
  /// rounds_settled). Not a failed solve (`converged` is about the inner solves), but not silent
  /// either: written to stats.jsonl as "unsettled_steps" only when not 0.
  long unsettled_steps = 0;

  /// Books one solve (or one step's solves): iterations and staggered rounds summed, the
  /// largest relative residual, convergence of all.
  void add_solve(long solve_iterations, int staggered, double relative_residual, bool solve_converged) {
    iterations += solve_iterations;
    staggered_iterations += staggered;
    max_relative_residual = std::max(max_relative_residual, relative_residual);
    converged = converged && solve_converged;
  }
  /// Books the preconditioner of one unified / viscosity solve and its stiffness.
  void add_stokes_preconditioner(PreconditionerKind kind, double stiffness) {
    (kind == PreconditionerKind::multigrid ? stokes_solves_multigrid : stokes_solves_ssor) += 1;
    max_stokes_stiffness = std::max(max_stokes_stiffness, stiffness);
  }
  /// The unknowns of a solve: each count the largest over the frame's solves.
  void add_dofs(long pressure, long stress, long contact, long friction) {
    dofs_pressure = std::max(dofs_pressure, pressure);
    dofs_stress = std::max(dofs_stress, stress);
    dofs_contact = std::max(dofs_contact, contact);
    dofs_friction = std::max(dofs_friction, friction);
  }
};

struct FrameStats {
  int frame = 0;
  double time = 0.0;
  int steps = 0;
  double dt_min = 0.0, dt_max = 0.0;
  double liquid_volume = 0.0;  ///< sum of W_L^p dx^Dim
  long particles = 0;
  std::vector<double> liquid_bounds_lower, liquid_bounds_upper;
  double kinetic_energy_liquid = 0.0, kinetic_energy_bodies = 0.0;
  /// Gravitational potential energy -sum m g . x of the particles (liquid) and of the dynamic
  /// bodies' centres of mass (bodies), zero at the origin (J; 2D: J per metre of depth).
  double potential_energy_liquid = 0.0, potential_energy_bodies = 0.0;
  /// Energy held by line 15's account (Line15Energy::balance, J; 2D: J/m): potential energy the
  /// position corrections released and kept against their next rises (positive), less what the
  /// kinetic energy could not pay yet (negative). Kinetic + potential + this is what the
  /// scheme neither creates nor destroys by line 15.
  double line15_banked_energy = 0.0;
  std::vector<BodyStats> bodies;
  int contact_count = 0;
  double max_penetration = 0.0;
  std::vector<ProbeStats> probes;
  SolverStats solver;
  /// Wall time of the frame per phase (s): the `timing` object of stats.jsonl.
  TimingTable<FramePhase> timing;
};

}  // namespace monolith
