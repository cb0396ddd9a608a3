/// \file stokes_solve.cpp
/// solve_stokes (declared in stokes_system.hpp): lines 7-11 of Algorithm 1 for the unified
/// pressure-viscosity system of eq. (8) / the stress-only system, on either back end, with the
/// paper's SSOR or the block multigrid preconditioner (stokes_preconditioner.hpp) and an optional
/// initial guess (warm start).

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>

#include "reference/fluid/stokes_preconditioner.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/fluid/stokes_warm_start.hpp"
#include "reference/fluid/velocity_operator.hpp"

namespace monolith {

template <int Dim>
VectorX gather_stokes_unknowns(const StressLayout<Dim>& layout, const StokesDofs& dofs,
                               const VectorX& stress_full, const VectorX& pressure_cells) {
  VectorX x = VectorX::Zero(dofs.size());
  if (stress_full.size() == layout.grid().num_dofs())
    for (int i = 0; i < dofs.num_stress(); ++i)
      x[i] = stress_full[layout.dof_of_unknown(dofs.unknown_of_dof[i])];
  if (pressure_cells.size() > 0)
    for (int k = 0; k < dofs.num_pressure(); ++k) {
      const int cell = dofs.pressure.cell_of_dof[k];
      if (cell < pressure_cells.size()) x[dofs.num_stress() + k] = pressure_cells[cell];
    }
  return x;
}

void condition_stokes_warm_start(const LinearOperator& a, const VectorX& b, VectorX& x, int rounds) {
  if (x.size() != a.size() || b.size() != a.size() || x.isZero(0.0) || b.isZero(0.0)) return;
  const double b_norm = b.lpNorm<Eigen::Infinity>();
  VectorX ax;
  std::vector<char> worse(static_cast<std::size_t>(x.size()));
  for (int k = 0; k < rounds; ++k) {
    a.apply(x, ax);
    bool any = false;
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      worse[static_cast<std::size_t>(i)] = std::abs(b[i] - ax[i]) > b_norm;
      any = any || worse[static_cast<std::size_t>(i)];
    }
    if (!any) break;
    a.forward_sweep(b, x, 1.0, &worse);
    a.backward_sweep(b, x, 1.0, &worse);
  }
  for (const VectorX& n : a.null_space()) x -= n.dot(x) * n;
  a.apply(x, ax);
  const double curvature = x.dot(ax), slope = b.dot(x);
  if (curvature > 0.0 && slope > 0.0 && std::isfinite(curvature) && std::isfinite(slope))
    x *= slope / curvature;
  else
    x.setZero();
}

template <int Dim>
StokesSolveResult solve_stokes(const MacGrid<Dim>& grid, const StokesWeights& w, double dt,
                               StokesUnknowns unknowns, StressForm form, Backend backend,
                               const PcgSettings& settings, VectorX& u,
                               const StokesSolveOptions& options) {
  StokesSolveResult result;
  const StressLayout<Dim> layout(StressGrid<Dim>(grid), form);
  // line 7: active DOFs
  const StokesDofs dofs = select_stokes_dofs(grid, layout, w, dt, unknowns,
                                             options.workspace ? &options.workspace->band : nullptr);
  result.stress_dofs = dofs.num_stress();
  result.pressure_dofs = dofs.num_pressure();
  const VectorX empty;
  VectorX x = gather_stokes_unknowns(layout, dofs, options.initial_stress ? *options.initial_stress : empty,
                                     options.initial_pressure ? *options.initial_pressure : empty);
  // lines 8-10: assemble (or set up the stencils), precondition, solve
  std::optional<ExplicitStokesSystem> sys;
  std::unique_ptr<LinearOperator> op;
  VectorX b;
  switch (backend) {
    case Backend::explicit_matrices:
      sys = assemble_explicit_stokes(grid, layout, w, dofs, dt, u);
      op = std::make_unique<SparseMatrixOperator>(sys->A, dofs.null_space);
      b = sys->b;
      break;
    case Backend::matrix_free: {
      auto mf = std::make_unique<MatrixFreeStokesOperator<Dim>>(grid, layout, w, dofs, dt,
                                                                options.workspace);
      b = mf->rhs(u);
      op = std::move(mf);
      break;
    }
  }
  add_divergence_source(dofs.pressure.cell_of_dof, w.pressure.liquid_cell,
                        options.divergence_source, dofs.num_stress(), b);
  // a right-hand side at its own round-off (a liquid in free fall) is zero: x = 0, no
  // iteration, no preconditioner set-up (liquid_rhs_round_off; docs/preconditioners.md section 33)
  PcgSettings pcg = settings;
  pcg.zero_rhs = std::max(pcg.zero_rhs, liquid_rhs_round_off(grid, w.pressure.fluid_face, u,
                                                             options.divergence_source,
                                                             options.workspace
                                                                 ? &options.workspace->band
                                                                 : nullptr));
  // a warm start no worse than zero (docs/preconditioners.md section 46), unless b is at its
  // round-off (then x = 0 below, whatever the start)
  if ((options.initial_stress || options.initial_pressure) && b.size() > 0 &&
      b.lpNorm<Eigen::Infinity>() > pcg.zero_rhs)
    condition_stokes_warm_start(*op, b, x);
  if (options.preconditioner == PreconditionerKind::ssor || dofs.size() == 0) {
    result.pcg = pcg_solve(*op, b, x, pcg);
  } else {
    // built on the first PCG iteration only: a step whose right-hand side vanishes (a liquid at
    // rest under uniform gravity) or whose warm start already converges skips the set-up
    const StokesPreconditionerOptions mg = options.multigrid ? *options.multigrid : StokesPreconditionerOptions{};
    const LinearOperator& a = *op;
    const LazyPreconditioner m(dofs.size(), "block", [&]() -> std::unique_ptr<Preconditioner> {
      const double floor = mg.min_fluid_fraction;
      StokesFactors f = sys ? stokes_factors(grid, layout, w, dofs, dt, *sys, floor)
                            : stokes_factors(grid, layout, w, dofs, dt,
                                             static_cast<const MatrixFreeStokesOperator<Dim>&>(a), floor);
      return std::make_unique<StokesPreconditioner<Dim>>(grid, a, std::move(f), mg);
    });
    PcgSettings attempt = pcg;
    VectorX start;
    if (options.fallback_to_ssor) {
      attempt.max_iterations = multigrid_attempt_budget(pcg.max_iterations);
      attempt.stagnation = attempt_stagnation_rule();
      start = x;
    }
    result.pcg = pcg_solve(*op, b, x, attempt, m);
    if (options.fallback_to_ssor && !result.pcg.converged) {
      // the fallback (docs/preconditioners.md section 20): SSOR from the last iterate, or from
      // the start if the attempt broke down (its iterate may not be finite)
      if (result.pcg.breakdown) x = start;
      const int spent = result.pcg.iterations;
      result.pcg = pcg_solve(*op, b, x, pcg);
      result.pcg.iterations += spent;
      result.fell_back = true;
    }
  }
  // line 11: velocity update (none for x = +0: it would subtract +0 from every face, leaving u
  // bit for bit; a right-hand side at its round-off, docs/preconditioners.md section 35)
  // (x = +0 scatters to +0 fields: StressLayout::expand's -= of +0 leaves +0)
  if (all_positive_zero(x)) {
    result.stress = VectorX::Zero(layout.grid().num_dofs());
    result.pressure = VectorX::Zero(grid.num_cells());
    return result;
  }
  result.stress = scatter_stress(layout, dofs, x);
  result.pressure = scatter_stokes_pressure(dofs, x, grid.num_cells());
  apply_stokes_update(grid, layout, w, dt, result.pressure, result.stress, u);
  return result;
}

#define MONOLITH_INSTANTIATE(D)                                                                  \
  template VectorX gather_stokes_unknowns<D>(const StressLayout<D>&, const StokesDofs&,          \
                                             const VectorX&, const VectorX&);                   \
  template StokesSolveResult solve_stokes<D>(const MacGrid<D>&, const StokesWeights&, double,    \
                                             StokesUnknowns, StressForm, Backend,                \
                                             const PcgSettings&, VectorX&,                       \
                                             const StokesSolveOptions&);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
