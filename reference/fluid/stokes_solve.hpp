#pragma once
/// \file stokes_solve.hpp
/// Lines 7-11 of Algorithm 1 for the unified pressure-viscosity solve of eq. (8) with a choice of
/// preconditioner (the paper's SSOR or the multigrid block preconditioner of
/// reference/fluid/stokes_preconditioner.hpp) and an optional initial guess (the previous step's
/// stress and pressure fields: a warm start).

#include <string>

#include "reference/fluid/stokes_preconditioner.hpp"
#include "reference/pcg.hpp"
#include "reference/stokes_system.hpp"

namespace monolith {

/// The preconditioners of the unified solves: "ssor" (section 4.3, the paper's) and "multigrid"
/// (docs/preconditioners.md).
enum class PreconditionerKind { ssor, multigrid };

/// The name used in scene files and reports.
const char* preconditioner_name(PreconditionerKind kind);

struct StokesSolveOptions {
  PreconditionerKind preconditioner = PreconditionerKind::multigrid;
  StokesPreconditionerOptions multigrid;  ///< the multigrid preconditioner's parameters
  /// Warm start: the initial (tau, p) read from these fields where the unknowns exist (all
  /// StressGrid components / cells; nullptr or empty: zero). The result still converges to
  /// settings.tolerance; only the starting residual changes.
  const VectorX* initial_stress = nullptr;
  const VectorX* initial_pressure = nullptr;
};

/// select DOFs, build (backend "explicit" or "matrixfree"), PCG with the chosen preconditioner
/// from the initial guess, update u (which enters as u*). Throws std::invalid_argument on an
/// unknown backend name.
template <int Dim>
StokesSolveResult solve_stokes(const MacGrid<Dim>& grid, const StokesWeights& w, double dt,
                               StokesUnknowns unknowns, StressForm form,
                               const std::string& backend, const PcgSettings& settings,
                               const StokesSolveOptions& options, VectorX& u);

/// The unknown vector x = (tau, p) of `dofs` read from a stress field (all StressGrid components;
/// the layout's unknowns take their component's value) and a cell pressure field; empty fields
/// give zeros.
template <int Dim>
VectorX gather_stokes_unknowns(const StressLayout<Dim>& layout, const StokesDofs& dofs,
                               const VectorX& stress_full, const VectorX& pressure_cells);

}  // namespace monolith
