#pragma once
/// \file stokes_warm_start.hpp
/// The warm start of the unified solve (StokesSolveOptions::initial_stress / initial_pressure,
/// stokes_system.hpp) made no worse than zero: solve_stokes conditions the gathered start with
/// condition_stokes_warm_start below before PCG. The solve still stops at
/// ||r||_inf <= tolerance ||b||_inf, the cold start's measure. Measured in
/// docs/preconditioners.md sections 33, 37, 45 and 46: no fewer iterations on the issue-15 bunny,
/// 1-14 % fewer on small viscous scenes; off in the simulator (SolverSpec::stokes_warm_start).

#include "reference/core/common.hpp"
#include "reference/solvers/linear_operator.hpp"

namespace monolith {

/// The previous step's (tau, p) gathered onto this step's DOFs has rows whose residual is many
/// times ||b|| wherever the weights moved (a tau and p that cancelled on the previous weights no
/// longer do; docs/preconditioners.md section 46). In place on x, for A x = b:
///   1. up to `rounds` times: the rows with |b - A x|_i > ||b||_inf (where the start is worse
///      than zero in PCG's measure) get one forward and one backward Gauss-Seidel sweep
///      (a.forward_sweep / backward_sweep on those rows only, the others held);
///   2. x <- alpha x with alpha = b.x / x.A x (x with a's null space projected out), the
///      multiple of x of least energy 1/2 x.A x - b.x; alpha <= 0 or x.A x <= 0 give x = 0.
/// So the start's energy is at most zero's (-1/2 (b.x)^2 / x.A x <= 0). A start whose residual
/// is nowhere above ||b||_inf skips step 1 (a start from the solution itself stays one). x = 0
/// or b = 0: unchanged. Costs `rounds` + 1 applications of A and up to 2 `rounds` sweeps; the
/// same bits for any thread count (A's applications and sweeps are).
void condition_stokes_warm_start(const LinearOperator& a, const VectorX& b, VectorX& x, int rounds = 3);

}  // namespace monolith
