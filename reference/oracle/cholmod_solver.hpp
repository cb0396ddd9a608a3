#pragma once
/// \file cholmod_solver.hpp
/// Exact sparse Cholesky solves with CHOLMOD (SuiteSparse), the oracle the iterative solvers are
/// checked against in the tests. Not used by the simulation itself.

#include "reference/core/common.hpp"

namespace monolith {

/// Solves A x = b for a symmetric positive definite A (row-major; a column-major copy is
/// factored with CHOLMOD's LLT, supernodal or simplicial as CHOLMOD chooses). Throws
/// std::runtime_error if the factorisation fails (A not positive definite).
VectorX cholmod_solve(const SparseMatrix& a, const VectorX& b);

}  // namespace monolith
