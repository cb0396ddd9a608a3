#pragma once
/// \file linear_operator.hpp
/// The interface every system operator implements (explicit sparse matrix or matrix-free
/// stencil), so the solvers (pcg.hpp) are written once for both back ends (section 4.3).

#include <cstddef>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/core/parallel.hpp"

namespace monolith {

/// A symmetric positive (semi-)definite operator A of size n x n.
class LinearOperator {
 public:
  virtual ~LinearOperator() = default;
  /// n.
  virtual int size() const = 0;
  /// y = A x (y is resized to n).
  virtual void apply(const VectorX& x, VectorX& y) const = 0;
  /// The diagonal of A.
  virtual VectorX diagonal() const = 0;
  /// The diagonal the SOR sweeps below divide by: diagonal() unless the sweeps relax only a part
  /// of A (CoupledOperator sweeps the sparse part S of A = S + R, section 4.3). mprgp_solve
  /// compares the two (sweep_diagonal_mismatch in mprgp.hpp).
  virtual VectorX sweep_diagonal() const { return diagonal(); }
  /// One forward SOR sweep on A x = rhs, in place on x, relaxation omega: for every row i in the
  /// operator's sweep order, x_i <- (1 - omega) x_i + omega (rhs_i - sum_{j != i} A_ij x_j) / A_ii.
  /// Rows with A_ii = 0 are left unchanged. With `active` (size n), only rows with active[i] != 0
  /// are relaxed; the others keep their value (and still enter the sums): with those values zero
  /// this is SOR on the principal submatrix A_FF of the active set F, which is what the
  /// preconditioner of MPRGP needs on the free variables (mprgp.hpp).
  virtual void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                             const std::vector<char>* active = nullptr) const = 0;
  /// The same sweep in the reverse order (so forward then backward is symmetric SOR).
  virtual void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                              const std::vector<char>* active = nullptr) const = 0;
  /// `count` forward sweeps one after the other: what `count` calls of forward_sweep do, except
  /// that an operator may carry what one sweep computed into the next instead of recomputing it
  /// from x (MatrixFreeStokesOperator keeps its face force B x: the same sweeps up to round-off).
  virtual void forward_sweeps(const VectorX& rhs, VectorX& x, double omega, int count) const {
    for (int s = 0; s < count; ++s) forward_sweep(rhs, x, omega);
  }
  /// `count` backward sweeps one after the other (as forward_sweeps).
  virtual void backward_sweeps(const VectorX& rhs, VectorX& x, double omega, int count) const {
    for (int s = 0; s < count; ++s) backward_sweep(rhs, x, omega);
  }
  /// Orthonormal basis of the null space of A (empty when A is definite). Solvers project it out
  /// of the right-hand side and of every iterate.
  virtual const std::vector<VectorX>& null_space() const { return no_null_space_; }
  /// Bytes the operator holds (matrix or stencil coefficients, maps, scratch); 0 if not reported.
  /// For the benchmark harness (memory per DOF).
  virtual std::size_t memory_bytes() const { return 0; }
  /// Bytes one apply must move at least (every array it streams through, once per pass); 0 if
  /// not reported. For the benchmark harness (achieved bandwidth of the apply).
  virtual double bytes_per_apply() const { return 0.0; }
  /// The operator as an explicit compressed row-major matrix whose row relaxation is the one of
  /// forward_sweep above (the diagonal of the matrix, rows with A_ii = 0 skipped), or nullptr
  /// (matrix-free). The block preconditioner sweeps such a matrix in the matrix-free operator's
  /// order instead of the index order of the operator's own sweeps, so that both back ends apply
  /// the same preconditioner (docs/preconditioners.md, sections 24-25).
  virtual const SparseMatrix* explicit_matrix() const { return nullptr; }

 private:
  std::vector<VectorX> no_null_space_;
};

/// Sweeps over fewer rows than this (all colour groups together) run on one thread: a sparse
/// row relaxes in a few nanoseconds, so below this the barriers between the colours cost more
/// than a second thread saves (bench_threads, docs/benchmarks.md "Threads on a busy machine").
constexpr long kParallelMinColourRows = 4 * kParallelMinWork;

/// One SOR sweep (section 4.3) over colour groups, shared by the matrix-free operators: `groups`
/// (any indexable container of std::vector<int> row lists) in order, or last group first when
/// `reverse`. Every row i with diagonal[i] != 0 (and active[i] != 0 when `active` is given) gets
///   x_i <- (1 - omega) x_i + omega (rhs_i - off_diagonal(i)) / diagonal_i,
/// where off_diagonal(i) returns sum_{j != i} A_ij x_j at the current x. With `independent` (no
/// two rows of one group couple) each group is relaxed in parallel; otherwise serially in list
/// order, and in reverse list order on a backward sweep so forward then backward stays symmetric.
template <class Groups, class OffDiagonal>
void colour_sweep(const Groups& groups, bool independent, bool reverse, const VectorX& diagonal,
                  const VectorX& rhs, VectorX& x, double omega, const std::vector<char>* active,
                  const OffDiagonal& off_diagonal) {
  auto relax = [&](int i) {
    if (diagonal[i] == 0.0 || (active && !(*active)[i])) return;
    const double off = off_diagonal(i);
    x[i] = (1.0 - omega) * x[i] + omega * (rhs[i] - off) / diagonal[i];
  };
  const int num_groups = static_cast<int>(groups.size());
  long total = 0;
  for (int g = 0; g < num_groups; ++g) total += static_cast<long>(groups[g].size());
  // independent groups: one parallel region for the whole sweep (a barrier per group, no fork
  // and join per group), only when there is enough work (kParallelMinColourRows)
  // (the team size measured per call, AdaptiveTeam of parallel.hpp; the work counted in rows
  // over kParallelMinColourRows / kParallelMinWork, so the threshold stays the measured one)
  static AdaptiveTeam site;
  TeamScope team(site, independent && total >= kParallelMinColourRows
                           ? total * kParallelMinWork / kParallelMinColourRows : 0);
#pragma omp parallel num_threads(team.threads()) if (team.parallel())
  for (int step = 0; step < num_groups; ++step) {
    const std::vector<int>& list = groups[reverse ? num_groups - 1 - step : step];
    const int count = static_cast<int>(list.size());
    if (independent) {
      // rows of one group share no coupling: independent updates in any order and any split
      // among the threads (each row has one writer), the same result either way
#pragma omp for schedule(dynamic, dynamic_chunk(count))
      for (int m = 0; m < count; ++m) relax(list[m]);
    } else if (!reverse) {
      // the colouring is broken (e.g. an odd periodic axis): serial, in list order
      for (int m = 0; m < count; ++m) relax(list[m]);
    } else {
      for (int m = count - 1; m >= 0; --m) relax(list[m]);
    }
  }
}

/// y = A x for a row-major sparse A (y resized to rows), row-parallel: every row is written by
/// one thread, so the result does not depend on the thread count.
inline void sparse_row_product(const SparseMatrix& a, const VectorX& x, VectorX& y) {
  y.resize(a.rows());
  // the team size measured per call (AdaptiveTeam); one thread below 4 kParallelMinWork non-zeros
  static AdaptiveTeam site;
  TeamScope team(site, a.nonZeros() >= 4 * kParallelMinWork ? static_cast<long>(a.nonZeros()) : 0);
#pragma omp parallel for schedule(dynamic, dynamic_chunk(a.rows())) num_threads(team.threads()) if (team.parallel())
  for (int i = 0; i < a.rows(); ++i) {
    double s = 0.0;
    for (SparseMatrix::InnerIterator it(a, i); it; ++it) s += it.value() * x[it.col()];
    y[i] = s;
  }
}

/// An explicit sparse matrix as a LinearOperator: sweeps run over the rows in index order.
class SparseMatrixOperator : public LinearOperator {
 public:
  explicit SparseMatrixOperator(SparseMatrix a, std::vector<VectorX> null_space = {})
      : a_(std::move(a)), null_space_(std::move(null_space)) {
    a_.makeCompressed();
    diagonal_ = a_.diagonal();
  }
  int size() const override { return static_cast<int>(a_.rows()); }
  void apply(const VectorX& x, VectorX& y) const override { sparse_row_product(a_, x, y); }
  VectorX diagonal() const override {
    return diagonal_;
  }
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override {
    for (int i = 0; i < a_.rows(); ++i)
      if (!active || (*active)[i]) relax_row(i, rhs, x, omega);
  }
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override {
    for (int i = static_cast<int>(a_.rows()) - 1; i >= 0; --i)
      if (!active || (*active)[i]) relax_row(i, rhs, x, omega);
  }
  const std::vector<VectorX>& null_space() const override {
    return null_space_;
  }
  const SparseMatrix& matrix() const {
    return a_;
  }
  const SparseMatrix* explicit_matrix() const override { return &a_; }
  /// CSR arrays (values, column indices, row starts), the diagonal and the null space.
  std::size_t memory_bytes() const override {
    std::size_t bytes = static_cast<std::size_t>(a_.nonZeros()) * (sizeof(double) + sizeof(int)) +
                        static_cast<std::size_t>(a_.rows() + 1) * sizeof(int) +
                        static_cast<std::size_t>(diagonal_.size()) * sizeof(double);
    for (const VectorX& v : null_space_) bytes += static_cast<std::size_t>(v.size()) * sizeof(double);
    return bytes;
  }
  /// One pass over the CSR arrays, x read once (at best) and y written once.
  double bytes_per_apply() const override {
    return static_cast<double>(a_.nonZeros()) * (sizeof(double) + sizeof(int)) +
           static_cast<double>(a_.rows() + 1) * sizeof(int) + 2.0 * sizeof(double) * a_.rows();
  }

 private:
  void relax_row(int i, const VectorX& rhs, VectorX& x, double omega) const {
    if (diagonal_[i] == 0.0) return;
    double off = 0.0;
    for (SparseMatrix::InnerIterator it(a_, i); it; ++it)
      if (it.col() != i) off += it.value() * x[it.col()];
    x[i] = (1.0 - omega) * x[i] + omega * (rhs[i] - off) / diagonal_[i];
  }
  SparseMatrix a_;
  VectorX diagonal_;
  std::vector<VectorX> null_space_;
};

}  // namespace monolith
