// Sparse LDL^T factor with a solve that allocates nothing (used by the multigrid's coarsest level
// and by the Stokes preconditioner's cut block).
#pragma once

#include <Eigen/SparseCholesky>

#include "reference/core/common.hpp"

namespace monolith {

/// Eigen's SimplicialLDLT with two additions:
/// - analysed_entries(): the entries of L after analyzePattern, so that a caller can refuse a
///   factor that would be too large before any numeric work;
/// - solve_into(b, x): x = A^-1 b = P^-1 L^-T D^-1 L^-1 P b by the same operations in the same
///   order as Eigen's solve (hence the same bits) but into caller-owned storage, with no
///   allocation (Eigen's solve permutes through a temporary on every call). prepare_solve() must
///   follow compute() / factorize() once.
/// One object must not run two solves at once (it keeps one work vector).
class SparseLdlt : public Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> {
 public:
  /// Entries of L, known after analyzePattern.
  Eigen::Index analysed_entries() const { return m_matrix.nonZeros(); }

  /// The numeric factorisation of `a` (the pattern analysed by analyzePattern, as for
  /// factorize(a)) by supernodes: columns with the same structure below their diagonal block are
  /// factored together as dense panels, each earlier panel's update applied as one dense product
  /// (left-looking). The same L and D as factorize(a) up to round-off (the sums run in another
  /// order), the same storage afterwards (matrixL(), vectorD(), solve_into). On the 64^3 tank's
  /// cut block (19307 unknowns, 3.9M entries of L): docs/preconditioners.md section 27.
  /// info() is NumericalIssue when a pivot is exactly zero (as factorize's).
  void factorize_supernodal(const Eigen::SparseMatrix<double>& a);

  /// 1 / D (vectorD() returns a copy, so it is taken once here) and the work vector.
  void prepare_solve() {
    inverse_d_ = vectorD().cwiseInverse();
    work_.setZero(rows());
  }

  /// x = A^-1 b (b and x of size rows(); they may be the same vector).
  void solve_into(const VectorX& b, VectorX& x) const {
    const Eigen::Index n = rows();
    const int* perm = permutationP().indices().data();
    const bool permuted = permutationP().size() == n;
    for (Eigen::Index q = 0; q < n; ++q) work_[permuted ? perm[q] : q] = b[q];  // P b
    matrixL().solveInPlace(work_);
    for (Eigen::Index q = 0; q < n; ++q) work_[q] = inverse_d_[q] * work_[q];  // D^-1, as Eigen's solve
    matrixU().solveInPlace(work_);
    x.resize(n);
    for (Eigen::Index q = 0; q < n; ++q) x[q] = work_[permuted ? perm[q] : q];  // P^-1
  }

 private:
  VectorX inverse_d_;
  mutable VectorX work_;
};

}  // namespace monolith
