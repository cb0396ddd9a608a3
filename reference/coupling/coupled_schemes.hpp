#pragma once
/// \file coupled_schemes.hpp
/// The nine pressure / viscosity / contact coupling schemes of section 6 (P-C, C-P, PC-iterative,
/// PC-unified, PC-VC-PC-unified, PV-C, C-PV, PVC-iterative, PVC-unified) as options of one
/// library function, solve_coupled_step. docs/coupling.md, "The nine schemes", explains them.
/// Which solves a scheme runs (one, the unified one with Algorithm 2 around it, or PC-VC-PC's
/// three) is run_solve_sequence of solve_sequence.hpp, shared with the liquid-only simulator.
///
/// All nine build one MonolithicSystem (eq. (24)) and differ only in which blocks are solved
/// together. With x_f = (tau, p) the fluid unknowns, the partition of eq. (24) is
///
///   [A_ff  A_fc] [x_f      ]   [b_f ]      A_ff = A_stokes + dt alpha B_f^T M_r^-1 B_f,
///   [A_cf  A_cc] [lambda, z] = [b_c ],     A_cc = [A33 A34; A34^T A44],
///
/// and the two building blocks of the partitioned schemes are
///   - the fluid solve ("P", "PV", "VC"): A_ff x_f = b_f - A_f3 lambda - A_f4 z for given
///     contact forces, by SSOR-PCG (pcg.hpp) on FluidBodyOperator: the liquid is two-way coupled
///     with the bodies (the rigid terms of A_ff are kept), but blind to contacts;
///   - the contact solve ("C"): the normal QP A33 lambda = b3 - A31 tau - A32 p - A34 z,
///     lambda >= 0, and with some mu > 0 the friction QP (25), staggered as in
///     solve_staggered_projections (friction first, normal last), by MPRGP on the coloured
///     sparse A33 / A44 with the diagonal boost gamma of section 4.4.5, for given x_f.
///
/// Both back ends of MonolithicSystem run every scheme (solve_coupled_step's `backend`): the
/// operators (FluidBodyOperator, MonolithicOperator) and the solver code are the same, only the
/// fluid part and the rigid products are explicit matrices or stencils (docs/coupling.md, "Back
/// ends of the coupled step").

#include <functional>
#include <vector>

#include "reference/contact/collision.hpp"
#include "reference/contact/contact_system.hpp"
#include "reference/core/common.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/coupling_scheme.hpp"
#include "reference/coupling/system_export.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "reference/solvers/backend.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

/// One step's inputs to the pressure / viscosity / contact solves.
template <int Dim>
struct CoupledStepInput {
  MacGrid<Dim> grid;
  /// W_F^u (solid_weights(...).fluid_face), W_L^p, W_L^u, P, W_F^s (solid_weights(...).
  /// fluid_stress), W_L^s, eta per stress DOF.
  StokesWeights weights;
  double dt = 0.0;
  /// Face velocities after P2G, gravity, air extrapolation.
  VectorX u_star;
  /// Step-start pose; dynamic bodies carry v* (gravity in).
  std::vector<RigidBody<Dim>> bodies;
  /// solid_weights over coupling_bodies(bodies) + static solids.
  SolidWeights<Dim> solids;
  /// Friction / restitution already combined per pair.
  std::vector<Contact<Dim>> contacts;
  /// dt, dx, baumgarte, margin, restitution threshold (dx must be the grid's: alpha = 1/dx^Dim).
  ContactParameters contact_params;
  /// A target divergence of the new velocity (cell field, 1/s; nullptr: none), added to b2 of
  /// every system the scheme builds (MonolithicSystem::add_divergence_source): the simulation's
  /// volume correction through the solve (StageSwitches::volume_source_gain).
  const VectorX* divergence_source = nullptr;
  /// The liquid solve's storage kept across steps and the liquid's band (stokes_workspace.hpp;
  /// nullptr: none), given to every MonolithicSystem the scheme builds; owned by the caller.
  StokesWorkspace* workspace = nullptr;
  /// (band23) The caller's record of its pressure buffer (the first solve's output,
  /// CoupledSolveResult::pressure as given): +0 outside the listed cells while it holds that
  /// storage; pressure_cells_into then zeroes only those cells and updates the record to the
  /// buffer it wrote last (nullptr: every output zeroed whole, as before).
  ZerosOutsideCells* pressure_cells = nullptr;
};

/// The weights of eq. (24) (section 3.1.2, 4.4.6) for a liquid beside bodies: W_L^p, W_L^u
/// (clamped as liquid_face_weights does) and W_L^s from `liquid_phi` on half_lattice(grid)
/// (liquid where < 0), W_F^u and W_F^s from `solids` (solid_weights of the posed bodies and
/// static solids), one density rho (the diagonal of P, kg/m^3) and one viscosity eta (Pa s)
/// everywhere. For tests, benchmarks and notebooks that pose one step in closed form; the
/// simulator builds its weights from particles.
template <int Dim>
StokesWeights coupled_stokes_weights(const MacGrid<Dim>& grid, const SolidWeights<Dim>& solids,
                                     const VectorX& liquid_phi, double rho, double eta);

struct CoupledSolveResult {
  VectorX u;              ///< face velocities after the step's solves (eq. (8) update)
  VectorX pressure;       ///< cell pressures (Pa); for PC-VC-PC the sum of both pressure solves
  VectorX stress;         ///< all StressGrid components (zero when no stress unknowns)
  VectorX body_velocity;  ///< two-way (dynamic) bodies' generalised velocities, ContactSystem order
  std::vector<int> body_dof;  ///< per body (input order): first row in body_velocity, -1 if none
  VectorX lambda, z;      ///< contact forces of the last contact solve (N; 2D N/m)
  /// Outer iterations: PC/PVC-iterative the fluid-contact rounds; P-C, C-P, PV-C, C-PV the
  /// friction rounds of the contact solve; the unified schemes the staggered friction rounds
  /// of solve_pvc_unified (summed over the three solves of PC-VC-PC); 1 without friction.
  int staggered_iterations = 0;
  long fluid_iterations = 0;      ///< CG iterations of separate P / PV solves
  long contact_iterations = 0;    ///< MPRGP iterations of separate contact solves
  long coupled_iterations = 0;    ///< MPRGP/CG iterations of unified solves (PC, PVC, VC)
  /// fluid / contact / coupled: wall time of those solves (right-hand sides included);
  /// total: the whole call, assembly of eq. (24) included.
  double fluid_seconds = 0, contact_seconds = 0, coupled_seconds = 0, total_seconds = 0;
  /// PC-VC-PC-unified: the VC-unified share of coupled_iterations / coupled_seconds (Table 2's
  /// VC column); 0 for the other schemes.
  long viscosity_coupled_iterations = 0;
  double viscosity_coupled_seconds = 0;
  /// Unknowns of the system(s) solved: active pressure cells, active stress unknowns (for
  /// PC-VC-PC those of the VC solve), contacts, friction rows.
  long pressure_dofs = 0, stress_dofs = 0, contact_dofs = 0, friction_dofs = 0;
  /// Every inner solve (PCG, MPRGP) reached its tolerance within its iteration cap. The outer
  /// rounds are not part of it: like the friction rounds and Algorithm 2's rounds, the
  /// fluid-contact rounds of PC-/PVC-iterative stop at settings.max_iterations
  /// (solver.staggered_iterations) by design, the paper's fixed count of staggered iterations;
  /// whether they settled first is rounds_settled.
  bool converged = true;
  /// PC-/PVC-iterative: the rounds stopped because (lambda, x_f) changed by <= the tolerance
  /// (last_change), not at the round cap; true for the other schemes.
  bool rounds_settled = true;
  /// The systems with stress unknowns solved (one per system built), by the preconditioner of
  /// their fluid rows, and the largest stiffness eta_max dt / (rho dx^2) among them
  /// (CoupledSchemeOptions::preconditioner).
  long multigrid_systems = 0, ssor_systems = 0;
  /// Solves under "auto" whose block preconditioner did not converge within
  /// multigrid_attempt_budget and that were solved again (an MLCP first with the Jacobi contact
  /// rows, then with SSOR; the fluid solves with SSOR; docs/preconditioners.md sections 20, 47).
  long fallbacks = 0;
  double max_stiffness = 0.0;
  /// Largest relative residual of the inner solves (PCG: ||r||_inf / ||b||_inf; MPRGP: projected
  /// gradient).
  double max_relative_residual = 0.0;
  /// Iterative schemes: relative change (inf-norm) of (lambda, x_f) in the last round.
  double last_change = 0.0;
};

/// Options of solve_coupled_step beyond StaggeredSettings.
struct CoupledSchemeOptions {
  /// PC-iterative / PVC-iterative: start every fluid and contact solve from the previous
  /// round's unknowns (true), or from zero (false: each round's solves cost about as much as
  /// a one-pass scheme's, as the per-solve iteration counts of the paper's Tables 1 and 3
  /// suggest). The fixed point is the same.
  bool warm_start = true;
  /// Algorithm 2 (section 5, non-Newtonian liquids), used when both are set and the scheme has
  /// stress unknowns: initial_viscosity(u*) gives eta^1 (lines 1, 3), update_viscosity(tau, eta^k)
  /// gives eta^(k+1) from the solved stress (lines 6, 3); NonNewtonianViscosity
  /// (herschel_bulkley.hpp) provides both. The viscosity of in.weights is then ignored.
  std::function<VectorX(const VectorX& u_star)> initial_viscosity;
  std::function<VectorX(const VectorX& stress, const VectorX& viscosity)> update_viscosity;
  /// The oracle (system_export.hpp): when set, called once per call with the step's final
  /// system of eq. (24) (PC-VC-PC-unified: the last PC-unified system; non-Newtonian: the last
  /// viscosity round's) and its solution under the unified convention: the scheme's own x for
  /// PC-unified, PVC-unified and PC-VC-PC-unified, an extra unified solve of the same system for
  /// the partitioned schemes (whose own step does not solve eq. (24); their results are
  /// unchanged). Not set: nothing is built.
  std::function<void(const SystemExport&)> export_sink;
  /// The preconditioner of the coupled solves of systems with stress unknowns (the fluid solve on
  /// A_ff and MPRGP on (26); docs/preconditioners.md, "The coupled systems"): ssor (the paper's,
  /// the default here so that the library call keeps its iterates), multigrid (the block
  /// preconditioner of coupled_preconditioner.hpp), or auto (choose_preconditioner with the
  /// system's stiffness eta_max dt / (rho dx^2), rho = liquid_density, and its grid: the rule of the
  /// liquid-only unified solves). The simulator passes solver.preconditioner.
  PreconditionerChoice preconditioner = PreconditionerChoice::ssor;
  /// The same for the systems without stress unknowns (the P solves): solver.pressure_preconditioner.
  PreconditionerKind pressure_preconditioner = PreconditionerKind::ssor;
  /// The smallest liquid density (kg/m^3) of the stiffness under auto; <= 0: stiffness 0.
  double liquid_density = 0.0;
  /// multigrid: the Woodbury correction of the bodies' low-rank term
  /// (CoupledPreconditionerOptions::body_correction).
  bool body_correction = true;
  /// The rounds of Algorithm 2 within a step keep the block preconditioner of the previous round
  /// for the next one (the same bodies and weights, another viscosity; (P13) of
  /// coupled_preconditioner.hpp, docs/preconditioners.md section 32). Off by default: it saved
  /// 10-17 % of two frames of shear-thinning and Bingham bunnies, but the stale P took 149
  /// instead of 30 iterations in shear-thinning-3d's frame 3 (121 instead of 41 in 2D).
  bool keep_round_preconditioner = false;
};

/// One step's pressure / viscosity / contact solves under `scheme` (section 6), every
/// MonolithicSystem on `backend` (assembled sparse matrices, the reference oracle, or stencils
/// applied on the fly, the production path; solver.backend of a scene). Builds
/// MonolithicSystem (eq. (24)) once: PV schemes with StressForm::reduced and the input viscosity,
/// PC schemes with the viscosity zeroed (no stress unknowns). Then, with "fluid" and "contact"
/// solves as in the file comment:
///   - P-C / PV-C: fluid solve with lambda = z = 0, then the contact solve given x_f; u from x_f,
///     v = body_velocities(x_f, lambda, z). The contact solve changes the bodies after the liquid
///     was made divergence-free against their old velocity: volume loss (section 6.1.1).
///   - C-P / C-PV: contact solve with x_f = 0, then the fluid solve given lambda, z: the liquid's
///     push on the bodies overrides non-penetration.
///   - PC-iterative / PVC-iterative: block Gauss-Seidel on eq. (24), i.e. staggered projections
///     on the unified formulation: rounds of (fluid solve given lambda, z; friction QP (25) given
///     x_f, lambda when some mu > 0; normal QP given x_f, z), each warm-started from the previous
///     round (cold with options.warm_start = false), up to settings.max_iterations rounds, stopping when both lambda and x_f change by
///     <= settings.tolerance (relative, inf-norm) in a round. Every round ends on the contact
///     solve, so the returned bodies satisfy the contact conditions and the liquid's
///     incompressibility is off by the last round's change. The fixed point is the one of
///     PC-unified / PVC-unified: each block's equations hold given the others.
///   - PC-unified / PVC-unified: solve_pvc_unified (MPRGP on (26), friction staggered; on the
///     Jacobi-scaled MLCP, PvcUnifiedOptions::jacobi_scaling, a departure explained there); with no
///     contacts SSOR-PCG on FluidBodyOperator instead (section 6: SOR-CG when there are no box
///     constraints).
///   - PC-VC-PC-unified (section 6.2): PC-unified -> u1, v1; VC-unified: MonolithicSystem with
///     stress unknowns only (StressForm::full, p fixed at 0), u* = u1, body v* = v1 (the
///     ContactSystem rebuilt with v1), solved as the unified MLCP -> u2, v2; PC-unified from
///     u2, v2 -> final u, v, lambda, z. pressure = p1 + p3, stress = tau2.
/// Non-Newtonian liquids (options.initial_viscosity / update_viscosity set, section 5): the
/// viscous solve of the scheme (the whole solve of PV-C, C-PV, PVC-iterative, PVC-unified; the
/// VC-unified solve of PC-VC-PC-unified) runs settings.max_iterations times, round k with the
/// viscosity eta^k and each followed by the viscosity update, so the step ends with tau, p,
/// lambda optimal for the last viscosity. Departure: the paper interleaves one viscosity update
/// with each friction round of one staggered solve; solve_pvc_unified has no entry for a
/// warm-started friction force, so here every viscosity round runs the scheme's own friction
/// rounds (up to max_iterations^2 friction solves per step). Without friction the two agree.
/// settings: max_iterations = staggered rounds (>= 1), tolerance = their stopping tolerance and
/// the inner PCG tolerance is settings.mprgp.tolerance, with settings.mprgp.max_iterations;
/// diagonal_boost = gamma on the contact rows. Throws SimulationError (errors.hpp) on a solver
/// breakdown, std::invalid_argument on inconsistent input.
template <int Dim>
CoupledSolveResult solve_coupled_step(const CoupledStepInput<Dim>& in, CouplingScheme scheme,
                                      Backend backend, const StaggeredSettings& settings,
                                      const CoupledSchemeOptions& options = {});

/// The same into `result`, whose u, pressure and stress vectors (when of the right size) are
/// written in place of allocating new ones: a caller that keeps one CoupledSolveResult across
/// steps (and swaps those vectors with its own, as Simulation does) allocates no face-, cell- or
/// stress-sized result after its first step. Every other field of `result` is reset. The same
/// values, bit for bit, as the returning form.
template <int Dim>
void solve_coupled_step(const CoupledStepInput<Dim>& in, CouplingScheme scheme, Backend backend,
                        const StaggeredSettings& settings, const CoupledSchemeOptions& options,
                        CoupledSolveResult& result);

}  // namespace monolith
