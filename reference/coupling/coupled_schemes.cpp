/// \file coupled_schemes.cpp
/// The nine coupling schemes of section 6 on the partitioned eq. (24) (coupled_schemes.hpp).

#include "reference/coupling/coupled_schemes.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>

#include "reference/contact/staggered_projections.hpp"
#include "reference/core/errors.hpp"
#include "reference/core/timer.hpp"
#include "reference/coupling/coupled_preconditioner.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/coupling/solve_sequence.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/solvers/colouring.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/pcg.hpp"

namespace monolith {

namespace {

/// The unknowns of eq. (24) during a scheme: x_f = (tau, p), lambda, z.
struct Unknowns {
  VectorX x_fluid, lambda, z;
};

template <int Dim>
Unknowns zero_unknowns(const MonolithicSystem<Dim>& s) {
  return {VectorX::Zero(s.num_fluid()), VectorX::Zero(s.num_contacts()),
          VectorX::Zero(s.num_friction())};
}

void record_mprgp(const MprgpResult& m, CoupledSolveResult& r, const char* what) {
  if (m.breakdown) throw SimulationError(std::string(what) + ": MPRGP broke down: " + m.message);
  r.converged = r.converged && m.converged;
  r.max_relative_residual = std::max(r.max_relative_residual, m.relative_residual);
}

/// The preconditioner of one system's coupled solves (CoupledSchemeOptions::preconditioner):
/// systems without stress unknowns follow pressure_preconditioner; the others the choice, auto
/// by the system's stiffness and grid as the liquid-only unified solves (choose_preconditioner), booked
/// in r.
template <int Dim>
PreconditionerKind coupled_preconditioner_kind(const MonolithicSystem<Dim>& s,
                                               const CoupledSchemeOptions& o,
                                               CoupledSolveResult& r) {
  if (s.num_fluid() == 0) return PreconditionerKind::ssor;
  if (s.num_stress() == 0) return o.pressure_preconditioner;
  const VectorX& eta = s.weights().viscosity;
  const double eta_max = eta.size() > 0 ? std::max(0.0, eta.maxCoeff()) : 0.0;
  const double stiffness = o.liquid_density > 0.0
                               ? solve_stiffness(eta_max, s.dt(), o.liquid_density, s.grid().dx())
                               : 0.0;
  const PreconditionerKind kind =
      choose_preconditioner(o.preconditioner, Dim, stiffness, s.grid().cells().maxCoeff());
  (kind == PreconditionerKind::multigrid ? r.multigrid_systems : r.ssor_systems) += 1;
  r.max_stiffness = std::max(r.max_stiffness, stiffness);
  return kind;
}

/// The block preconditioner of A_ff (coupled_preconditioner.hpp), built on its first
/// application (a zero right-hand side skips the set-up).
template <int Dim>
std::unique_ptr<LazyPreconditioner> fluid_body_preconditioner(const MonolithicSystem<Dim>& s,
                                                              bool body_correction,
                                                              KeptCoupledPreconditioner<Dim>* kept = nullptr) {
  return std::make_unique<LazyPreconditioner>(
      s.num_fluid(), "coupled-block", [&s, body_correction, kept]() -> std::unique_ptr<Preconditioner> {
        // (P13) the previous round's P where it fits (coupled_preconditioner.hpp)
        if (kept && kept->fluid_body && kept->fits(s)) return std::make_unique<SharedPreconditioner>(kept->fluid_body);
        CoupledPreconditionerOptions o;
        o.body_correction = body_correction;
        auto built = std::make_shared<CoupledPreconditioner<Dim>>(s, false, VectorX(), o);
        if (kept) kept->keep(s, built, nullptr);
        return std::make_unique<SharedPreconditioner>(std::move(built));
      });
}

/// The fluid solve of the partitioned schemes: A_ff x_f = b_f - A_f3 lambda - A_f4 z by PCG
/// (FluidBodyOperator) with SSOR or, when m is set, with m; warm-started from x.x_fluid.
/// Returns the CG iterations.
template <int Dim>
long fluid_solve(const MonolithicSystem<Dim>& s, const FluidBodyOperator<Dim>& op,
                 const StaggeredSettings& settings, Unknowns& x, CoupledSolveResult& r,
                 const Preconditioner* m = nullptr) {
  if (s.num_fluid() == 0) return 0;
  PcgSettings pcg;
  pcg.tolerance = settings.mprgp.tolerance;
  pcg.max_iterations = settings.mprgp.max_iterations;
  pcg.omega = settings.mprgp.omega;
  pcg.stagnation = settings.mprgp.stagnation;
  // a right-hand side at the round-off of its terms (free flight) is zero: no solve, and both
  // back ends give x = 0 (docs/preconditioners.md section 26)
  pcg.zero_rhs = s.rhs_round_off();
  const PcgResult p = m ? pcg_solve(op, s.fluid_rhs(x.lambda, x.z), x.x_fluid, pcg, *m)
        : pcg_solve(op, s.fluid_rhs(x.lambda, x.z), x.x_fluid, pcg);
  if (p.breakdown) throw SimulationError("fluid solve: PCG broke down: " + p.message);
  r.converged = r.converged && p.converged;
  r.max_relative_residual = std::max(r.max_relative_residual, p.relative_residual);
  return p.iterations;
}

/// fluid_solve with the block preconditioner m, given multigrid_attempt_budget iterations; if
/// that does not converge (or breaks down), the solve again with SSOR, from the attempt's
/// iterate (from x's start after a breakdown), counted in r.fallbacks (docs/preconditioners.md
/// section 20). Returns the CG iterations of both attempts.
template <int Dim>
long fluid_solve_with_fallback(const MonolithicSystem<Dim>& s, const FluidBodyOperator<Dim>& op,
                               const StaggeredSettings& settings, Unknowns& x,
                               CoupledSolveResult& r, const Preconditioner& m) {
  StaggeredSettings attempt = settings;
  attempt.mprgp.max_iterations = multigrid_attempt_budget(settings.mprgp.max_iterations);
  attempt.mprgp.stagnation = attempt_stagnation_rule();
  const VectorX start = x.x_fluid;
  CoupledSolveResult trial;
  long iterations = 0;
  try {
    iterations = fluid_solve(s, op, attempt, x, trial, &m);
  } catch (const SimulationError&) {
    trial.converged = false;
    x.x_fluid = start;
  }
  if (trial.converged) {
    r.max_relative_residual = std::max(r.max_relative_residual, trial.max_relative_residual);
    return iterations;
  }
  ++r.fallbacks;
  return iterations + fluid_solve(s, op, settings, x, r);
}

/// The contact solve of the partitioned schemes for a fixed x_f: the normal QP
/// A33 lambda = b3 - A31 tau - A32 p - A34 z, lambda >= 0 (eq. (24) row 3) and, with friction,
/// the friction QP (25), in the staggered rounds of staggered_rounds (friction first, normal
/// last). Operators, colourings and ||A|| estimates are built once per system.
template <int Dim>
class ContactSolve {
 public:
  ContactSolve(const MonolithicSystem<Dim>& s, const StaggeredSettings& settings)
      : s_(s), settings_(settings), qp_(s.contacts(), settings) {}

  bool friction() const { return qp_.friction(); }

  /// Up to `rounds` friction-normal rounds (one normal solve without friction), warm-started
  /// from x.lambda, x.z (`cold`: every QP from zero, the friction bounds still from the current
  /// lambda); stops when lambda changes by <= the tolerance. Returns the rounds done.
  int solve(Unknowns& x, int rounds, bool cold, long& iterations, CoupledSolveResult& r) const {
    if (s_.num_contacts() == 0) return 0;
    // the normal QP given (tau, p, z)
    auto solve_normal = [&]() {
      if (cold) x.lambda.setZero();
      const MprgpResult m = mprgp_solve(qp_.normal(), s_.contact_rhs(x.x_fluid, x.z),
                                        qp_.normal_lower(), qp_.normal_upper(), x.lambda,
                                        qp_.normal_settings());
      record_mprgp(m, r, "contact solve");
      iterations += m.iterations;
    };
    if (!qp_.friction()) {
      solve_normal();
      return 1;
    }
    // eq. (25) given (tau, p, lambda)
    VectorX xl(s_.num_fluid() + s_.num_contacts());
    auto solve_friction = [&](const VectorX& lower, const VectorX& upper) {
      xl << x.x_fluid, x.lambda;
      if (cold) x.z.setZero();
      const MprgpResult m =
          mprgp_solve(qp_.tangential(), s_.friction_rhs(xl), lower, upper, x.z, qp_.friction_settings());
      record_mprgp(m, r, "friction solve");
      iterations += m.iterations;
    };
    return staggered_rounds<Dim>(s_.contacts().mu, rounds, 0, settings_.tolerance,
                                 [&]() { return x.lambda; }, solve_friction, solve_normal)
        .rounds;
  }

 private:
  const MonolithicSystem<Dim>& s_;
  StaggeredSettings settings_;
  ContactQpOperators<Dim> qp_;
};

/// PC-unified / PVC-unified / VC-unified on one system: the MLCP (26) by solve_pvc_unified, or
/// PCG on A_ff when there are no contacts (no box constraints, section 6); SSOR or, with `kind`
/// multigrid, the block preconditioner of coupled_preconditioner.hpp on both.
template <int Dim>
Unknowns unified_solve(const MonolithicSystem<Dim>& s, const StaggeredSettings& settings,
                       CoupledSolveResult& r, long& iterations,
                       PreconditionerKind kind = PreconditionerKind::ssor,
                       bool body_correction = true, bool fallback = false,
                       KeptCoupledPreconditioner<Dim>* kept = nullptr) {
  Unknowns x = zero_unknowns(s);
  const bool multigrid = kind == PreconditionerKind::multigrid;
  if (s.num_contacts() == 0) {
    const FluidBodyOperator<Dim> op(s);
    const std::unique_ptr<LazyPreconditioner> m =
        multigrid ? fluid_body_preconditioner(s, body_correction, kept) : nullptr;
    iterations += m && fallback ? fluid_solve_with_fallback(s, op, settings, x, r, *m)
                                : fluid_solve(s, op, settings, x, r, m.get());
    r.staggered_iterations += 1;
    return x;
  }
  // MPRGP on the Jacobi-scaled MLCP (PvcUnifiedOptions: departure, balances the contact and
  // fluid rows)
  PvcUnifiedOptions options;
  options.jacobi_scaling = true;
  options.compute_updates = false;  // finish() updates from the unknowns
  options.preconditioner = kind;
  options.body_correction = body_correction;
  PvcUnifiedResult u;
  if (multigrid && fallback) {
    // the block preconditioner in face for multigrid_attempt_budget iterations per MLCP solve,
    // then, unless that converged, the whole solve again from zero: first with the block
    // preconditioner's Jacobi contact rows instead of their exact elimination (where the
    // contacts outnumber the bodies' DOFs many times, S_c of the elimination can stall MPRGP in a
    // face that the Jacobi rows get through: docs/preconditioners.md section 47), then with the
    // paper's SSOR (section 20). A system redone counts once in r.fallbacks.
    StaggeredSettings attempt = settings;
    attempt.mprgp.max_iterations = multigrid_attempt_budget(settings.mprgp.max_iterations);
    attempt.mprgp.stagnation = attempt_stagnation_rule();
    u = solve_pvc_unified(s, attempt, options, kept);
    const auto failed = [](const PvcUnifiedResult& v) { return !v.converged || v.breakdown; };
    if (failed(u)) {
      ++r.fallbacks;
      iterations += u.mprgp_iterations;
      r.staggered_iterations += u.staggered_iterations;
      if (options.exact_contacts) {
        // a fresh preconditioner (a kept one eliminates the contacts exactly)
        options.exact_contacts = false;
        u = solve_pvc_unified(s, attempt, options);
        if (failed(u)) {
          iterations += u.mprgp_iterations;
          r.staggered_iterations += u.staggered_iterations;
        }
      }
      if (failed(u)) {
        options.preconditioner = PreconditionerKind::ssor;
        u = solve_pvc_unified(s, settings, options);
      }
    }
  } else {
    u = solve_pvc_unified(s, settings, options, kept);
  }
  if (u.breakdown) throw SimulationError("unified solve: MPRGP broke down: " + u.message);
  r.converged = r.converged && u.converged;
  r.max_relative_residual = std::max(r.max_relative_residual, u.max_relative_residual);
  r.staggered_iterations += u.staggered_iterations;
  iterations += u.mprgp_iterations;
  x.x_fluid = u.x.head(s.num_fluid());
  x.lambda = u.lambda;
  x.z = u.z;
  return x;
}

/// eq. (24) for the step's bodies with their velocities replaced by `v` (two-way bodies, in
/// ContactSystem order; empty: as given).
template <int Dim>
std::vector<RigidBody<Dim>> with_velocities(std::vector<RigidBody<Dim>> bodies,
                                            const std::vector<int>& body_dof, const VectorX& v) {
  for (std::size_t i = 0; i < bodies.size(); ++i)
    if (body_dof[i] >= 0)
      bodies[i].set_generalized_velocity(v.template segment<kBodyDofs<Dim>>(body_dof[i]));
  return bodies;
}

template <int Dim>
std::unique_ptr<MonolithicSystem<Dim>> build_system(const CoupledStepInput<Dim>& in,
                                                    std::shared_ptr<const StokesWeights> w,
                                                    StressForm form,
                                                    StokesUnknowns unknowns,
                                                    std::shared_ptr<const VectorX> u_star,
                                                    const std::vector<RigidBody<Dim>>& bodies,
                                                    Backend backend) {
  const ContactSystem<Dim> contacts(bodies, in.contacts, in.contact_params);
  auto system = std::make_unique<MonolithicSystem<Dim>>(in.grid, form, std::move(w), in.dt,
                                                        std::move(u_star), bodies, in.solids,
                                                        contacts, backend, unknowns,
                                                        in.workspace);
  system->add_divergence_source(in.divergence_source);
  return system;
}

template <int Dim>
void count_dofs(const MonolithicSystem<Dim>& s, CoupledSolveResult& r) {
  r.pressure_dofs = s.num_pressure();
  r.stress_dofs = s.num_stress();
  r.contact_dofs = s.num_contacts();
  r.friction_dofs = s.num_friction();
}

/// P-C, C-P, PV-C, C-PV and the iterative schemes on one system.
template <int Dim>
Unknowns partitioned_solve(const MonolithicSystem<Dim>& s, CouplingScheme scheme,
                           const StaggeredSettings& settings, const CoupledSchemeOptions& options,
                           CoupledSolveResult& r) {
  // the operators, timed with their solves (the unified solves' timings include theirs too)
  Stopwatch t0;
  const FluidBodyOperator<Dim> fluid(s);
  const std::unique_ptr<LazyPreconditioner> m =
      coupled_preconditioner_kind(s, options, r) == PreconditionerKind::multigrid
          ? fluid_body_preconditioner(s, options.body_correction)
          : nullptr;
  r.fluid_seconds += t0.seconds();
  t0.restart();
  const ContactSolve<Dim> contact(s, settings);
  r.contact_seconds += t0.seconds();
  Unknowns x = zero_unknowns(s);
  auto run_fluid = [&]() {
    const Stopwatch t0;
    r.fluid_iterations += m && options.preconditioner == PreconditionerChoice::automatic
                              ? fluid_solve_with_fallback(s, fluid, settings, x, r, *m)
                              : fluid_solve(s, fluid, settings, x, r, m.get());
    r.fluid_seconds += t0.seconds();
  };
  auto run_contact = [&](int rounds, bool cold = false) {
    const Stopwatch t0;
    const int done = contact.solve(x, rounds, cold, r.contact_iterations, r);
    r.contact_seconds += t0.seconds();
    return done;
  };
  const int rounds = std::max(1, settings.max_iterations);
  switch (scheme) {
    case CouplingScheme::p_c:
    case CouplingScheme::pv_c:
      // the liquid first (lambda = z = 0), then the contacts given x_f
      run_fluid();
      r.staggered_iterations = std::max(1, run_contact(rounds));
      break;
    case CouplingScheme::c_p:
    case CouplingScheme::c_pv:
      // the contacts first (x_f = 0), then the liquid given lambda, z
      r.staggered_iterations = std::max(1, run_contact(rounds));
      run_fluid();
      break;
    default: {
      // block Gauss-Seidel: fluid, contact (one friction-normal pair), fluid, contact, ...
      bool settled = false;
      for (int k = 0; k < rounds; ++k) {
        const VectorX fluid_before = x.x_fluid, lambda_before = x.lambda;
        // cold start: each solve from zero, given the other block's latest values
        if (!options.warm_start) x.x_fluid.setZero();
        run_fluid();
        ++r.staggered_iterations;
        if (s.num_contacts() == 0) {
          // nothing to alternate with: one fluid solve is the whole answer
          settled = true;
          r.last_change = 0.0;
          break;
        }
        run_contact(1, !options.warm_start);
        r.last_change = std::max(relative_change(x.x_fluid, fluid_before),
                                 relative_change(x.lambda, lambda_before));
        if (r.last_change <= settings.tolerance) {
          settled = true;
          break;
        }
      }
      // the round cap is the scheme's setting, not a solve that failed (CoupledSolveResult::
      // converged): a frame is reported unconverged only for its inner solves
      r.rounds_settled = settled;
      break;
    }
  }
  return x;
}

/// options.export_sink with the SystemExport of `s` (built from `bodies`) and its unified
/// solution: `solved` when it came from unified_solve on `s`, otherwise a fresh unified_solve.
/// Staggered rounds of the oracle's refined reference solve (export_step): enough for the
/// friction rows of the scenes measured (docs/oracle.md) to reach the solver's tolerance.
constexpr int kExportStaggeredRounds = 200;

template <int Dim>
void export_step(const CoupledSchemeOptions& options, const MonolithicSystem<Dim>& s,
                 const std::vector<RigidBody<Dim>>& bodies, const CoupledStepInput<Dim>& in,
                 const StaggeredSettings& settings, CouplingScheme scheme, const Unknowns& solved,
                 bool solved_unified) {
  if (!options.export_sink) return;
  Unknowns x = solved;
  std::string source = std::string("the step's own solve (") + enum_name(scheme) + ")";
  if (!solved_unified) {
    CoupledSolveResult scratch;
    long iterations = 0;
    x = unified_solve(s, settings, scratch, iterations);
    source = std::string("a unified solve of this system (") + enum_name(scheme) +
             " solves it partitioned, so its own step result is not a solution of eq. (24))";
  }
  source += s.num_contacts() > 0
                ? ": MPRGP on the Jacobi-scaled MLCP (26), staggered with the friction LCP (25)"
                : ": SSOR-PCG on the fluid-body block (no contacts)";
  VectorX stacked(s.num_fluid() + s.num_contacts() + s.num_friction());
  stacked << x.x_fluid, x.lambda, x.z;
  SystemExport e = export_system<Dim>(s, bodies, in.solids, in.contacts, stacked,
                                      settings.diagonal_boost);
  e.x_source = source;
  e.tolerance = settings.mprgp.tolerance;
  e.jacobi_scaled = s.num_contacts() > 0;
  const SparseMatrix& a = e.matrix("A")->value;
  e.x_check = check_solution(a, e.vector("b")->value, e.num_tau, e.num_p, e.num_lambda, e.num_z,
                             e.mu, e.x, e.x, e.jacobi_scaled, e.tolerance);
  if (!e.x_check.passed && s.num_friction() > 0) {
    // a scene's few staggered rounds (solver.staggered_iterations) leave the friction rows short
    // of the tolerance; the reference x of the oracle is the unified solve of the same system
    // with the staggered projections run to their own tolerance (the step's result unchanged)
    StaggeredSettings refined = settings;
    refined.max_iterations = std::max(settings.max_iterations, kExportStaggeredRounds);
    refined.tolerance = std::min(settings.tolerance, settings.mprgp.tolerance);
    CoupledSolveResult scratch;
    long iterations = 0;
    const Unknowns xr = unified_solve(s, refined, scratch, iterations);
    VectorX xs(stacked.size());
    xs << xr.x_fluid, xr.lambda, xr.z;
    const SolutionCheck check =
        check_solution(a, e.vector("b")->value, e.num_tau, e.num_p, e.num_lambda, e.num_z, e.mu,
                       xs, xs, e.jacobi_scaled, e.tolerance);
    if (check.passed || check.friction < e.x_check.friction) {
      e.x = xs;
      for (ExportedVector& v : e.vectors)
        if (v.name == "x") v.value = xs;
      e.x_check = check;
      e.x_source = "a unified solve of this system with up to " +
                   std::to_string(refined.max_iterations) + " staggered rounds (" + source +
                   " stopped after solver.staggered_iterations rounds, short of the tolerance" +
                   " on the friction rows)";
    }
  }
  options.export_sink(e);
}

}  // namespace

template <int Dim>
CoupledSolveResult solve_coupled_step(const CoupledStepInput<Dim>& in, CouplingScheme scheme,
                                      Backend backend, const StaggeredSettings& settings,
                                      const CoupledSchemeOptions& options) {
  CoupledSolveResult r;
  solve_coupled_step<Dim>(in, scheme, backend, settings, options, r);
  return r;
}

template <int Dim>
void solve_coupled_step(const CoupledStepInput<Dim>& in, CouplingScheme scheme, Backend backend,
                        const StaggeredSettings& settings, const CoupledSchemeOptions& options,
                        CoupledSolveResult& result) {
  const Stopwatch t_start;
  if (in.u_star.size() != in.grid.num_faces())
    throw std::invalid_argument("solve_coupled_step: u_star must have one entry per face");
  // the caller's u, pressure and stress buffers (a previous step's, when the result lives
  // across steps) are the first solve's outputs; every other field starts afresh
  VectorX spare_u, spare_pressure, spare_stress;
  spare_u.swap(result.u);
  spare_pressure.swap(result.pressure);
  spare_stress.swap(result.stress);
  result = CoupledSolveResult();
  CoupledSolveResult& r = result;
  // the inviscid solves: viscosity zeroed, so no stress unknowns. When the input viscosity is
  // already +0 everywhere (inviscid liquids, the P.. C schemes) the input's weights serve as
  // they are: a copy holds four face-, one cell- and three stress-sized vectors (1.8 GB at the
  // paper's 256x128x256 grid)
  const bool all_plus_zero =
      std::all_of(in.weights.viscosity.data(),
                  in.weights.viscosity.data() + in.weights.viscosity.size(),
                  [](double eta) { return eta == 0.0 && !std::signbit(eta); });
  // (the systems built below share their weights: they live in this function's State values,
  // which in.weights outlives, so the input's weights are lent to them without an owner)
  const std::shared_ptr<const StokesWeights> input(&in.weights, [](const StokesWeights*) {});
  // Otherwise (a viscous input: the pressure solves of PC-VC-PC-unified, or a P.. C scheme) the
  // pressure weights are copied and the stress vectors left out: weights without them are inviscid
  // (StokesWeights::inviscid) and give the system of the zeroed viscosity bit for bit (test
  // "inviscid weights without stress vectors give the system of zero stress weights bit for
  // bit"), without a copy of W_F^s, W_L^s and a zero eta (three stress-sized vectors per step,
  // 1.2 GB at the paper's 256x128x256 grid). An export keeps them: the oracle reads every weight
  // of the system it is given.
  std::shared_ptr<const StokesWeights> inviscid = input;
  if (!all_plus_zero) {
    auto zeroed = std::make_shared<StokesWeights>();
    zeroed->pressure = in.weights.pressure;
    if (options.export_sink) {
      zeroed->fluid_stress = in.weights.fluid_stress;
      zeroed->liquid_stress = in.weights.liquid_stress;
      zeroed->viscosity.setZero(in.weights.viscosity.size());
    }
    inviscid = std::move(zeroed);
  }
  // the state between the solves of the sequence: the system and unknowns of the last solve
  // and the velocities (u, v) the next solve starts from (v empty: the bodies as given; u empty
  // in the start state: in.u_star, not copied)
  struct State {
    std::shared_ptr<const MonolithicSystem<Dim>> system;
    std::vector<RigidBody<Dim>> bodies;  ///< the bodies `system` was built from
    Unknowns x;
    VectorX u, v, pressure, stress;
  };
  // builds eq. (24) from `from` and runs the scheme's solve (unified: the MLCP; otherwise the
  // partitioned solves), booking iterations and time as coupled or VC-coupled
  auto solve = [&](const State& from, std::shared_ptr<const StokesWeights> w, StressForm form,
                   StokesUnknowns unknowns, bool unified, bool viscosity_stage,
                   KeptCoupledPreconditioner<Dim>* kept = nullptr) {
    State out;
    const std::vector<RigidBody<Dim>> bodies =
        from.v.size() ? with_velocities(in.bodies, from.system->contacts().body_dof, from.v)
                      : in.bodies;
    // u* of the system: lent (the system's solve and updates below are all that read it, while
    // `from` lives), or a copy when the oracle reads the final system after the sequence
    const VectorX& u_from = from.u.size() ? from.u : in.u_star;
    std::shared_ptr<const VectorX> u_star =
        options.export_sink ? std::make_shared<const VectorX>(u_from)
                            : std::shared_ptr<const VectorX>(&u_from, [](const VectorX*) {});
    // weights without stress vectors given a viscous input (`zeroed`, below): their system has
    // no stress field (stress_full_into leaves it empty)
    const bool stress_dropped = w->inviscid() && !in.weights.inviscid();
    out.system = build_system(in, std::move(w), form, unknowns, std::move(u_star), bodies, backend);
    out.bodies = bodies;
    const MonolithicSystem<Dim>& sys = *out.system;
    if (unified) {
      const Stopwatch t0;
      const PreconditionerKind kind = coupled_preconditioner_kind(sys, options, r);
      // "auto" falls back to SSOR where the block preconditioner does not converge
      const bool fallback = kind == PreconditionerKind::multigrid &&
                            options.preconditioner == PreconditionerChoice::automatic;
      if (kept) kept->candidate = out.system;
      out.x = unified_solve(sys, settings, r,
                            viscosity_stage ? r.viscosity_coupled_iterations : r.coupled_iterations,
                            kind, options.body_correction, fallback, kept);
      if (kept) kept->candidate.reset();
      const double seconds = t0.seconds();
      r.coupled_seconds += seconds;
      if (viscosity_stage) r.viscosity_coupled_seconds += seconds;
    } else {
      out.x = partitioned_solve(sys, scheme, settings, options, r);
    }
    // the outputs into the caller's buffers while they last (the first solve's), then fresh
    out.u.swap(spare_u);
    out.pressure.swap(spare_pressure);
    out.stress.swap(spare_stress);
    sys.fluid_velocities_into(out.x.x_fluid, out.u);
    out.v = sys.body_velocities(out.x.x_fluid, out.x.lambda, out.x.z);
    sys.pressure_cells_into(out.x.x_fluid, out.pressure, in.pressure_cells);
    // The result's stress is every StressGrid component, +0 without stress unknowns, as the copy
    // with a zeroed eta gave it, written into the kept buffer; an empty one (the system's own)
    // made the callers' reads of it, such as max |tau|, read past its end (test_coupled_schemes
    // crashed in "2D no bodies", P-C with a viscous input). Empty only for an inviscid input.
    if (stress_dropped)
      out.stress.setZero(StressGrid<Dim>(in.grid).num_dofs());
    else
      sys.stress_full_into(out.x.x_fluid, out.stress);
    return out;
  };
  // (P13) the block preconditioners of the previous round of Algorithm 2 (same state, same
  // stage; another viscosity), for the next round's system (coupled_preconditioner.hpp)
  KeptCoupledPreconditioner<Dim> kept;
  const State* kept_from = nullptr;
  bool kept_stage = false;
  auto kept_for = [&](const State& from, const VectorX* eta, bool viscosity_stage) -> KeptCoupledPreconditioner<Dim>* {
    if (!eta || !options.keep_round_preconditioner) return nullptr;
    if (kept_from != &from || kept_stage != viscosity_stage) {
      kept = KeptCoupledPreconditioner<Dim>();
      kept_from = &from;
      kept_stage = viscosity_stage;
    }
    return &kept;
  };
  const bool pc_vc_pc = scheme == CouplingScheme::pc_vc_pc_unified;
  // P.. C schemes, and the P solves of PC-VC-PC-unified (as PC-unified)
  auto pressure = [&](const State& from, SolveStage stage) {
    State out = solve(from, inviscid, StressForm::reduced, StokesUnknowns::pressure_and_stress,
                      pc_vc_pc || scheme == CouplingScheme::pc_unified, false);
    if (stage != SolveStage::second_pressure) count_dofs(*out.system, r);
    return out;
  };
  // PV.. C schemes: (tau, p) with the input viscosity or eta^k of Algorithm 2
  // the input's weights with the viscosity eta (none: the input's own, lent, not copied)
  auto with_viscosity = [&](const VectorX* eta) -> std::shared_ptr<const StokesWeights> {
    if (!eta) return input;
    auto w = std::make_shared<StokesWeights>(in.weights);
    w->viscosity = *eta;
    return w;
  };
  auto unified = [&](const State& from, const VectorX* eta) {
    const auto w = with_viscosity(eta);
    State out = solve(from, w, StressForm::reduced, StokesUnknowns::pressure_and_stress,
                      scheme == CouplingScheme::pvc_unified, false, kept_for(from, eta, false));
    count_dofs(*out.system, r);
    return out;
  };
  // the VC-unified solve of PC-VC-PC: stress only (p fixed at 0), the full form
  auto viscous = [&](const State& from, const VectorX* eta) {
    const auto w = with_viscosity(eta);
    State out = solve(from, w, StressForm::full, StokesUnknowns::stress_only, true, true,
                      kept_for(from, eta, true));
    r.stress_dofs = out.system->num_stress();
    return out;
  };
  ViscosityRounds viscosity;
  viscosity.rounds = std::max(1, settings.max_iterations);
  // (P13) a round with the previous round's viscosity, bit for bit, builds the same system from
  // the same state and solves it from the same start: the same result, not solved again
  viscosity.skip_repeated = true;
  if (options.initial_viscosity && options.update_viscosity) {
    viscosity.initial = options.initial_viscosity;
    viscosity.update = options.update_viscosity;
  }
  State start;
  // Algorithm 2's eta^1 reads the start state's u; the solves themselves read in.u_star
  if (viscosity.non_newtonian()) start.u = in.u_star;
  // with bodies every scheme keeps its own sequence, viscous liquid or not
  State end = run_solve_sequence(solve_sequence(scheme, true), start, viscosity, pressure,
                                 unified, viscous);
  if (pc_vc_pc) r.coupled_iterations += r.viscosity_coupled_iterations;
  export_step(options, *end.system, end.bodies, in, settings, scheme, end.x,
              pc_vc_pc || scheme == CouplingScheme::pc_unified ||
                  scheme == CouplingScheme::pvc_unified);
  r.u.swap(end.u);
  r.pressure.swap(end.pressure);
  r.stress.swap(end.stress);
  r.body_velocity.swap(end.v);
  r.lambda.swap(end.x.lambda);
  r.z.swap(end.x.z);
  r.body_dof = end.system->contacts().body_dof;
  r.total_seconds = t_start.seconds();
}

template <int Dim>
StokesWeights coupled_stokes_weights(const MacGrid<Dim>& grid, const SolidWeights<Dim>& solids,
                                     const VectorX& liquid_phi, double rho, double eta) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const StressGrid<Dim> stress(grid);
  StokesWeights w;
  // W_F from the bodies and static solids
  w.pressure.fluid_face = solids.fluid_face;
  w.fluid_stress = solids.fluid_stress;
  // W_L from the liquid level set
  w.pressure.liquid_cell = liquid_cell_weights<Dim>(grid, lattice, liquid_phi);
  w.pressure.liquid_face = liquid_face_weights<Dim>(grid, lattice, liquid_phi, w.pressure.liquid_cell);
  w.liquid_stress = stress_liquid_weights<Dim>(stress, lattice, liquid_phi);
  // one density and one viscosity
  w.pressure.face_density = VectorX::Constant(grid.num_faces(), rho);
  w.viscosity = VectorX::Constant(stress.num_dofs(), eta);
  return w;
}

template StokesWeights coupled_stokes_weights<2>(const MacGrid<2>&, const SolidWeights<2>&,
                                                 const VectorX&, double, double);
template StokesWeights coupled_stokes_weights<3>(const MacGrid<3>&, const SolidWeights<3>&,
                                                 const VectorX&, double, double);

template CoupledSolveResult solve_coupled_step<2>(const CoupledStepInput<2>&, CouplingScheme,
                                                  Backend, const StaggeredSettings&,
                                                  const CoupledSchemeOptions&);
template CoupledSolveResult solve_coupled_step<3>(const CoupledStepInput<3>&, CouplingScheme,
                                                  Backend, const StaggeredSettings&,
                                                  const CoupledSchemeOptions&);
template void solve_coupled_step<2>(const CoupledStepInput<2>&, CouplingScheme, Backend,
                                    const StaggeredSettings&, const CoupledSchemeOptions&,
                                    CoupledSolveResult&);
template void solve_coupled_step<3>(const CoupledStepInput<3>&, CouplingScheme, Backend,
                                    const StaggeredSettings&, const CoupledSchemeOptions&,
                                    CoupledSolveResult&);

}  // namespace monolith
