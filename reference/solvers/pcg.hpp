#pragma once
/// \file pcg.hpp
/// Conjugate gradients with the symmetric SOR (SSOR) preconditioner of section 4.3, written once
/// against LinearOperator so it runs on the explicit and the matrix-free back end alike.

#include <string>
#include <vector>

#include "reference/solvers/linear_operator.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

/// Early exit of a solve that no longer makes progress: after an iteration i >= window, the
/// solve stagnates when the smallest relative residual of its first i iterations is above
/// factor times the smallest of its first i - window (the residual has not fallen by 1 / factor
/// in the last `window` iterations). For the multigrid attempt under "auto", which the SSOR
/// fallback follows (docs/preconditioners.md sections 20-21); window 0: off.
struct StagnationRule {
  int window = 0;
  double factor = 0.5;
};

/// The attempt's rule: no halving of the residual in 100 iterations. The block preconditioner's
/// solves that converge take at most about 350 iterations and lose a factor 2 in far fewer
/// (section 21 measures both); a stalled solve sits at 1e-2..1e-5 for thousands.
inline StagnationRule attempt_stagnation_rule() { return StagnationRule{100, 0.5}; }

/// The running test of a StagnationRule (allocates window + 1 doubles once).
class StagnationTest {
 public:
  explicit StagnationTest(const StagnationRule& rule);
  /// Record iteration `iteration` (1, 2, ...) with its relative residual; true if stagnated.
  bool stagnated(int iteration, double relative_residual);

 private:
  StagnationRule rule_;
  std::vector<double> best_;  ///< best-so-far per iteration, a ring of window + 1
  double best_now_;
};

struct PcgSettings {
  double tolerance = 1e-6;  ///< stop when ||r||_inf <= tolerance ||b||_inf
  int max_iterations = 2000;
  double omega = 1.0;        ///< SSOR relaxation in (0, 2); 1 = symmetric Gauss-Seidel
  bool precondition = true;  ///< false: plain CG
  StagnationRule stagnation;  ///< early exit (unconverged, `stagnated`); off by default
  /// A right-hand side with ||b||_inf at or below this is zero to working precision: x = 0,
  /// converged after no iteration (relative_residual 0), as for b = 0. For a caller that knows
  /// the round-off level of its b (MonolithicSystem::rhs_round_off, liquid_rhs_round_off);
  /// 0 (default): only an exact zero.
  double zero_rhs = 0.0;
};

struct PcgResult {
  int iterations = 0;
  double relative_residual = 0.0;  ///< ||b - A x||_inf / ||b||_inf at exit (0 when b = 0)
  bool converged = false;
  bool breakdown = false;  ///< a non-finite value or p^T A p <= 0 stopped the iteration
  bool stagnated = false;  ///< settings.stagnation stopped it (not converged)
  std::string message;     ///< what broke down, empty otherwise
};

/// z = M^-1 r for the SSOR preconditioner: one forward then one backward SOR sweep from z = 0,
/// i.e. z = (2 - omega)/omega (D/omega + U)^-1 D (D/omega + L)^-1 r (symmetric positive definite
/// for 0 < omega < 2 when A is). With `active`, the same on the principal submatrix of the active
/// rows (z is zero on the others; r is read on the active rows only).
void ssor_precondition(const LinearOperator& a, const VectorX& r, VectorX& z, double omega,
                       const std::vector<char>* active = nullptr);

/// Solves A x = b by preconditioned CG from the initial guess in x (resized and zeroed if its
/// size is wrong). The null space of A (a.null_space()) is projected out of b and the iterates,
/// so singular but consistent systems (enclosed liquid) converge to the minimum-norm solution.
PcgResult pcg_solve(const LinearOperator& a, const VectorX& b, VectorX& x,
                    const PcgSettings& settings);

/// The same with the preconditioner `m` (settings.omega and settings.precondition are not read).
PcgResult pcg_solve(const LinearOperator& a, const VectorX& b, VectorX& x,
                    const PcgSettings& settings, const Preconditioner& m);

}  // namespace monolith
