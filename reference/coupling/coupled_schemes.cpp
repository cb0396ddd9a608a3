/// \file coupled_schemes.cpp
/// The nine coupling schemes of section 6 on the partitioned eq. (24) (coupled_schemes.hpp).

#include "reference/coupling/coupled_schemes.hpp"

#include <algorithm>
#include <limits>
#include <memory>
#include <stdexcept>

#include "reference/core/errors.hpp"
#include "reference/core/timer.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/solvers/colouring.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/pcg.hpp"

namespace monolith {

namespace {

double inf_norm(const VectorX& v) { return v.size() ? v.lpNorm<Eigen::Infinity>() : 0.0; }

/// ||new - old||_inf / ||new||_inf (0 when both vanish).
double relative_change(const VectorX& next, const VectorX& previous) {
  if (next.size() == 0) return 0.0;
  return inf_norm(next - previous) / std::max(inf_norm(next), 1e-300);
}

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

/// The fluid solve of the partitioned schemes: A_ff x_f = b_f - A_f3 lambda - A_f4 z by SSOR-PCG
/// (FluidBodyOperator), warm-started from x.x_fluid. Returns the CG iterations.
template <int Dim>
long fluid_solve(const MonolithicSystem<Dim>& s, const FluidBodyOperator<Dim>& op,
                 const StaggeredSettings& settings, Unknowns& x, CoupledSolveResult& r) {
  if (s.num_fluid() == 0) return 0;
  PcgSettings pcg;
  pcg.tolerance = settings.mprgp.tolerance;
  pcg.max_iterations = settings.mprgp.max_iterations;
  pcg.omega = settings.mprgp.omega;
  const PcgResult p = pcg_solve(op, s.fluid_rhs(x.lambda, x.z), x.x_fluid, pcg);
  if (p.breakdown) throw SimulationError("fluid solve: SSOR-PCG broke down: " + p.message);
  r.converged = r.converged && p.converged;
  r.max_relative_residual = std::max(r.max_relative_residual, p.relative_residual);
  return p.iterations;
}

/// The contact solve of the partitioned schemes for a fixed x_f: the normal QP
/// A33 lambda = b3 - A31 tau - A32 p - A34 z, lambda >= 0 (eq. (24) row 3) and, with friction,
/// the friction QP (25), staggered as solve_staggered_projections does (friction first, normal
/// last). Operators, colourings and ||A|| estimates are built once per system.
template <int Dim>
class ContactSolve {
 public:
  ContactSolve(const MonolithicSystem<Dim>& s, const StaggeredSettings& settings)
      : s_(s), settings_(settings) {
    const int nc = s.num_contacts();
    if (nc == 0) return;
    const ContactSystem<Dim>& c = s.contacts();
    friction_ = c.mu.maxCoeff() > 0.0 && s.num_body_dofs() > 0;
    // A33 with SSOR sweeps over Welsh-Powell colours of the contact graph, boosted by gamma
    const Colouring colours = welsh_powell(contact_adjacency(c.dynamic_pairs, c.num_dynamic_bodies));
    a33_ = std::make_unique<ColouredSparseOperator>(c.a33(), colours);
    a33_boosted_ = std::make_unique<DiagonalBoost>(*a33_, settings.diagonal_boost);
    normal_settings_ = with_norm_estimate(*a33_boosted_, settings.mprgp);
    if (friction_) {
      a44_ = std::make_unique<ColouredSparseOperator>(c.a44(), expand_colouring(colours, Dim - 1));
      a44_boosted_ = std::make_unique<DiagonalBoost>(*a44_, settings.diagonal_boost);
      friction_settings_ = with_norm_estimate(*a44_boosted_, settings.mprgp);
    }
  }

  bool friction() const { return friction_; }

  /// Up to `rounds` friction-normal rounds (one normal solve without friction), warm-started
  /// from x.lambda, x.z (`cold`: every QP from zero, the friction bounds still from the current
  /// lambda); stops when lambda changes by <= the tolerance. Returns the rounds done.
  int solve(Unknowns& x, int rounds, bool cold, long& iterations, CoupledSolveResult& r) const {
    const int nc = s_.num_contacts(), nz = s_.num_friction();
    if (nc == 0) return 0;
    const double inf = std::numeric_limits<double>::infinity();
    const VectorX zero_n = VectorX::Zero(nc), inf_n = VectorX::Constant(nc, inf);
    if (!friction_) {
      if (cold) x.lambda.setZero();
      const MprgpResult m = mprgp_solve(*a33_boosted_, s_.contact_rhs(x.x_fluid, x.z), zero_n, inf_n,
                                        x.lambda, normal_settings_);
      record_mprgp(m, r, "contact solve");
      iterations += m.iterations;
      return 1;
    }
    const int nf = s_.num_fluid();
    VectorX lower(nz), upper(nz), xl(nf + nc);
    int done = 0;
    for (int k = 0; k < std::max(1, rounds); ++k) {
      // eq. (25) given (tau, p, lambda): the pyramid bounds of the current lambda
      const ContactSystem<Dim>& c = s_.contacts();
      for (int i = 0; i < nc; ++i)
        for (int j = 0; j < Dim - 1; ++j) {
          const double bound = c.mu[i] * std::max(x.lambda[i], 0.0);
          lower[(Dim - 1) * i + j] = -bound;
          upper[(Dim - 1) * i + j] = bound;
        }
      xl << x.x_fluid, x.lambda;
      if (cold) x.z.setZero();
      const MprgpResult mz = mprgp_solve(*a44_boosted_, s_.friction_rhs(xl), lower, upper, x.z,
                                         friction_settings_);
      record_mprgp(mz, r, "friction solve");
      iterations += mz.iterations;
      // the normal QP given (tau, p, z)
      const VectorX previous = x.lambda;
      if (cold) x.lambda.setZero();
      const MprgpResult mn = mprgp_solve(*a33_boosted_, s_.contact_rhs(x.x_fluid, x.z), zero_n,
                                         inf_n, x.lambda, normal_settings_);
      record_mprgp(mn, r, "contact solve");
      iterations += mn.iterations;
      ++done;
      if (relative_change(x.lambda, previous) <= settings_.tolerance) break;
    }
    return done;
  }

 private:
  const MonolithicSystem<Dim>& s_;
  StaggeredSettings settings_;
  bool friction_ = false;
  std::unique_ptr<ColouredSparseOperator> a33_, a44_;
  std::unique_ptr<DiagonalBoost> a33_boosted_, a44_boosted_;
  MprgpSettings normal_settings_, friction_settings_;
};

/// PC-unified / PVC-unified / VC-unified on one system: the MLCP (26) by solve_pvc_unified, or
/// SSOR-PCG on A_ff when there are no contacts (no box constraints, section 6).
template <int Dim>
Unknowns unified_solve(const MonolithicSystem<Dim>& s, const StaggeredSettings& settings,
                       CoupledSolveResult& r, long& iterations) {
  Unknowns x = zero_unknowns(s);
  if (s.num_contacts() == 0) {
    const FluidBodyOperator<Dim> op(s);
    iterations += fluid_solve(s, op, settings, x, r);
    r.staggered_iterations += 1;
    return x;
  }
  // MPRGP on the Jacobi-scaled MLCP (PvcUnifiedOptions: departure, balances the contact and
  // fluid rows)
  PvcUnifiedOptions options;
  options.jacobi_scaling = true;
  options.compute_updates = false;  // finish() updates from the unknowns
  const PvcUnifiedResult u = solve_pvc_unified(s, settings, options);
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
                                                    const StokesWeights& w, StressForm form,
                                                    StokesUnknowns unknowns, const VectorX& u_star,
                                                    const std::vector<RigidBody<Dim>>& bodies,
                                                    Backend backend) {
  const ContactSystem<Dim> contacts(bodies, in.contacts, in.contact_params);
  return std::make_unique<MonolithicSystem<Dim>>(in.grid, form, w, in.dt, u_star, bodies,
                                                 in.solids, contacts, backend, unknowns);
}

/// u, p, tau, v, lambda, z of the final system and unknowns.
template <int Dim>
void finish(const MonolithicSystem<Dim>& s, const Unknowns& x, CoupledSolveResult& r) {
  r.u = s.fluid_velocities(x.x_fluid);
  r.pressure = s.pressure_cells(x.x_fluid);
  r.stress = s.stress_full(x.x_fluid);
  r.body_velocity = s.body_velocities(x.x_fluid, x.lambda, x.z);
  r.lambda = x.lambda;
  r.z = x.z;
  r.body_dof = s.contacts().body_dof;
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
  r.fluid_seconds += t0.seconds();
  t0.restart();
  const ContactSolve<Dim> contact(s, settings);
  r.contact_seconds += t0.seconds();
  Unknowns x = zero_unknowns(s);
  auto run_fluid = [&]() {
    const Stopwatch t0;
    r.fluid_iterations += fluid_solve(s, fluid, settings, x, r);
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
      r.converged = r.converged && settled;
      break;
    }
  }
  return x;
}

/// options.export_sink with the SystemExport of `s` (built from `bodies`) and its unified
/// solution: `solved` when it came from unified_solve on `s`, otherwise a fresh unified_solve.
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
  options.export_sink(e);
}

}  // namespace

template <int Dim>
CoupledSolveResult solve_coupled_step(const CoupledStepInput<Dim>& in, CouplingScheme scheme,
                                      Backend backend, const StaggeredSettings& settings,
                                      const CoupledSchemeOptions& options) {
  const Stopwatch t_start;
  if (in.u_star.size() != in.grid.num_faces())
    throw std::invalid_argument("solve_coupled_step: u_star must have one entry per face");
  CoupledSolveResult r;
  // P.. C schemes: inviscid (viscosity zeroed, so no stress unknowns)
  StokesWeights inviscid = in.weights;
  inviscid.viscosity.setZero();
  // Algorithm 2 (section 5) for non-Newtonian liquids: rounds of (viscosity, viscous solve)
  const bool non_newtonian = options.initial_viscosity && options.update_viscosity;
  const int viscosity_rounds = std::max(1, settings.max_iterations);

  if (scheme == CouplingScheme::pc_vc_pc_unified) {
    // section 6.2: PC-unified -> (u1, v1), VC-unified -> (u2, v2), PC-unified -> final
    const auto s1 = build_system(in, inviscid, StressForm::reduced,
                                 StokesUnknowns::pressure_and_stress, in.u_star, in.bodies,
                                 backend);
    const Stopwatch t1;
    const Unknowns x1 = unified_solve(*s1, settings, r, r.coupled_iterations);
    const double pc1_seconds = t1.seconds();
    const VectorX u1 = s1->fluid_velocities(x1.x_fluid);
    const VectorX v1 = s1->body_velocities(x1.x_fluid, x1.lambda, x1.z);
    const VectorX p1 = s1->pressure_cells(x1.x_fluid);
    const std::vector<int>& dof = s1->contacts().body_dof;

    std::unique_ptr<MonolithicSystem<Dim>> s2;
    Unknowns x2;
    if (!non_newtonian) {
      s2 = build_system(in, in.weights, StressForm::full, StokesUnknowns::stress_only, u1,
                        with_velocities(in.bodies, dof, v1), backend);
      const Stopwatch t2;
      x2 = unified_solve(*s2, settings, r, r.viscosity_coupled_iterations);
      r.viscosity_coupled_seconds = t2.seconds();
    } else {
      // Algorithm 2 around VC-unified, every round from (u1, v1) with eta^k
      StokesWeights w = in.weights;
      VectorX eta = options.initial_viscosity(u1);
      for (int k = 0; k < viscosity_rounds; ++k) {
        w.viscosity = eta;
        s2 = build_system(in, w, StressForm::full, StokesUnknowns::stress_only, u1,
                          with_velocities(in.bodies, dof, v1), backend);
        const Stopwatch t2;
        x2 = unified_solve(*s2, settings, r, r.viscosity_coupled_iterations);
        r.viscosity_coupled_seconds += t2.seconds();
        eta = options.update_viscosity(s2->stress_full(x2.x_fluid), w.viscosity);
      }
    }
    const VectorX u2 = s2->fluid_velocities(x2.x_fluid);
    const VectorX v2 = s2->body_velocities(x2.x_fluid, x2.lambda, x2.z);
    const VectorX tau2 = s2->stress_full(x2.x_fluid);

    const auto s3 = build_system(in, inviscid, StressForm::reduced,
                                 StokesUnknowns::pressure_and_stress, u2,
                                 with_velocities(in.bodies, dof, v2), backend);
    const Stopwatch t3;
    const Unknowns x3 = unified_solve(*s3, settings, r, r.coupled_iterations);
    r.coupled_seconds = pc1_seconds + r.viscosity_coupled_seconds + t3.seconds();
    r.coupled_iterations += r.viscosity_coupled_iterations;
    finish(*s3, x3, r);
    export_step(options, *s3, with_velocities(in.bodies, dof, v2), in, settings, scheme, x3, true);
    r.pressure = p1 + r.pressure;
    r.stress = tau2;
    count_dofs(*s1, r);
    r.stress_dofs = s2->num_stress();
    r.total_seconds = t_start.seconds();
    return r;
  }

  const bool viscous = scheme_uses_viscosity(scheme);
  if (viscous && non_newtonian) {
    // Algorithm 2 around the scheme's solve: every round from u* with eta^k
    StokesWeights w = in.weights;
    VectorX eta = options.initial_viscosity(in.u_star);
    std::unique_ptr<MonolithicSystem<Dim>> s;
    Unknowns x;
    for (int k = 0; k < viscosity_rounds; ++k) {
      w.viscosity = eta;
      s = build_system(in, w, StressForm::reduced, StokesUnknowns::pressure_and_stress, in.u_star,
                       in.bodies, backend);
      if (scheme == CouplingScheme::pvc_unified) {
        const Stopwatch t0;
        x = unified_solve(*s, settings, r, r.coupled_iterations);
        r.coupled_seconds += t0.seconds();
      } else {
        x = partitioned_solve(*s, scheme, settings, options, r);
      }
      eta = options.update_viscosity(s->stress_full(x.x_fluid), w.viscosity);
    }
    count_dofs(*s, r);
    finish(*s, x, r);
    export_step(options, *s, in.bodies, in, settings, scheme, x,
                scheme == CouplingScheme::pvc_unified);
    r.total_seconds = t_start.seconds();
    return r;
  }
  const auto s = build_system(in, viscous ? in.weights : inviscid, StressForm::reduced,
                              StokesUnknowns::pressure_and_stress, in.u_star, in.bodies,
                              backend);
  count_dofs(*s, r);
  Unknowns x;
  if (scheme == CouplingScheme::pc_unified || scheme == CouplingScheme::pvc_unified) {
    const Stopwatch t0;
    x = unified_solve(*s, settings, r, r.coupled_iterations);
    r.coupled_seconds = t0.seconds();
  } else {
    x = partitioned_solve(*s, scheme, settings, options, r);
  }
  finish(*s, x, r);
  export_step(options, *s, in.bodies, in, settings, scheme, x,
              scheme == CouplingScheme::pc_unified || scheme == CouplingScheme::pvc_unified);
  r.total_seconds = t_start.seconds();
  return r;
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

}  // namespace monolith
