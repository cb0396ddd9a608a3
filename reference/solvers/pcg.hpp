#pragma once
/// \file pcg.hpp
/// Conjugate gradients with the symmetric SOR (SSOR) preconditioner of section 4.3, written once
/// against LinearOperator so it runs on the explicit and the matrix-free back end alike.

#include <string>

#include "reference/solvers/linear_operator.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

struct PcgSettings {
  double tolerance = 1e-6;  ///< stop when ||r||_inf <= tolerance ||b||_inf
  int max_iterations = 2000;
  double omega = 1.0;        ///< SSOR relaxation in (0, 2); 1 = symmetric Gauss-Seidel
  bool precondition = true;  ///< false: plain CG
};

struct PcgResult {
  int iterations = 0;
  double relative_residual = 0.0;  ///< ||b - A x||_inf / ||b||_inf at exit (0 when b = 0)
  bool converged = false;
  bool breakdown = false;  ///< a non-finite value or p^T A p <= 0 stopped the iteration
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
