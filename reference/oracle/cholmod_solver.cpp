#include "reference/oracle/cholmod_solver.hpp"

#include <Eigen/CholmodSupport>
#include <stdexcept>

namespace monolith {

VectorX cholmod_solve(const SparseMatrix& a, const VectorX& b) {
  // CHOLMOD wants compressed column storage; only the lower triangle is read
  Eigen::SparseMatrix<double, Eigen::ColMajor, int> column_major = a;
  column_major.makeCompressed();
  Eigen::CholmodDecomposition<Eigen::SparseMatrix<double, Eigen::ColMajor, int>, Eigen::Lower>
      solver;
  solver.setMode(Eigen::CholmodAuto);
  solver.compute(column_major);
  if (solver.info() != Eigen::Success)
    throw std::runtime_error("cholmod_solve: factorisation failed (matrix not positive definite)");
  VectorX x = solver.solve(b);
  if (solver.info() != Eigen::Success) throw std::runtime_error("cholmod_solve: solve failed");
  return x;
}

}  // namespace monolith
