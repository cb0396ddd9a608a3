// SparseLdlt::solve_into: the same bits as Eigen's SimplicialLDLT::solve, into caller storage.
#include <catch2/catch.hpp>

#include <vector>

#include "reference/solvers/sparse_ldlt.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A 2D 5-point Laplacian on an n x n grid plus a random positive diagonal shift (SPD), so that
/// the fill-reducing ordering is not the identity.
Eigen::SparseMatrix<double> shifted_laplacian(int n, unsigned seed) {
  const VectorX shift = random_vector(n * n, seed).cwiseAbs();
  std::vector<Eigen::Triplet<double>> t;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int k = i + n * j;
      t.emplace_back(k, k, 4.0 + shift[k]);
      if (i > 0) t.emplace_back(k, k - 1, -1.0);
      if (i + 1 < n) t.emplace_back(k, k + 1, -1.0);
      if (j > 0) t.emplace_back(k, k - n, -1.0);
      if (j + 1 < n) t.emplace_back(k, k + n, -1.0);
    }
  Eigen::SparseMatrix<double> a(n * n, n * n);
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

}  // namespace

TEST_CASE("SparseLdlt::solve_into gives Eigen's solve bit for bit, also in place", "[unit]") {
  for (int n : {1, 3, 17}) {
    const Eigen::SparseMatrix<double> a = shifted_laplacian(n, 11 + n);
    SparseLdlt f;
    f.analyzePattern(a);
    REQUIRE(f.info() == Eigen::Success);
    // the size of L (unit lower, diagonal not stored) is known before the numeric work, stays
    // that after it, and holds at least A's strictly lower entries
    const Eigen::Index analysed = f.analysed_entries();
    CHECK(analysed >= (a.nonZeros() - a.rows()) / 2);
    f.factorize(a);
    REQUIRE(f.info() == Eigen::Success);
    CHECK(f.analysed_entries() == analysed);
    f.prepare_solve();
    if (n == 17) {  // the ordering permutes, so the permutation steps are exercised
      bool identity = true;
      for (int q = 0; q < n * n; ++q) identity = identity && f.permutationP().indices()[q] == q;
      CHECK_FALSE(identity);
    }
    for (unsigned seed : {1u, 2u}) {
      const VectorX b = random_vector(n * n, seed);
      const VectorX eigen = f.solve(b);
      VectorX x(n * n);
      f.solve_into(b, x);
      CHECK((x - eigen).cwiseAbs().maxCoeff() == 0.0);
      VectorX y = b;
      f.solve_into(y, y);  // aliasing b and x
      CHECK((y - eigen).cwiseAbs().maxCoeff() == 0.0);
      CHECK((a * x - b).norm() < 1e-12 * b.norm());
    }
  }
}

namespace {

/// A 3D 7-point Laplacian on n^3 with a random positive shift and a few random couplings of
/// unknowns far apart (SPD by diagonal dominance): wide supernodes and a non-trivial tree.
Eigen::SparseMatrix<double> shifted_laplacian_3d(int n, unsigned seed) {
  const int size = n * n * n;
  const VectorX shift = random_vector(size, seed).cwiseAbs();
  const VectorX extra = random_vector(size, seed + 1);
  std::vector<Eigen::Triplet<double>> t;
  std::vector<double> diagonal(size, 0.0);
  auto couple = [&](int p, int q, double v) {
    t.emplace_back(p, q, v);
    t.emplace_back(q, p, v);
    diagonal[p] += std::abs(v);
    diagonal[q] += std::abs(v);
  };
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int p = i + n * (j + n * k);
        if (i + 1 < n) couple(p, p + 1, -1.0);
        if (j + 1 < n) couple(p, p + n, -1.0);
        if (k + 1 < n) couple(p, p + n * n, -1.0);
        if (p % 7 == 3) couple(p, (p * 13 + 5) % size == p ? (p + 1) % size : (p * 13 + 5) % size, 0.5 * extra[p]);
      }
  for (int p = 0; p < size; ++p) t.emplace_back(p, p, diagonal[p] + 0.1 + shift[p]);
  Eigen::SparseMatrix<double> a(size, size);
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

}  // namespace

TEST_CASE("SparseLdlt::factorize_supernodal: the simplicial factor to round-off, the same storage", "[unit]") {
  for (int n : {1, 2, 5, 9}) {
    const Eigen::SparseMatrix<double> a = n == 9 ? shifted_laplacian(30, 7) : shifted_laplacian_3d(n, 3 + n);
    SparseLdlt simplicial, supernodal;
    simplicial.analyzePattern(a);
    supernodal.analyzePattern(a);
    simplicial.factorize(a);
    supernodal.factorize_supernodal(a);
    REQUIRE(simplicial.info() == Eigen::Success);
    REQUIRE(supernodal.info() == Eigen::Success);
    // the same pattern of L, the same values and pivots to round-off
    const Eigen::SparseMatrix<double>& ls = simplicial.matrixL().nestedExpression();
    const Eigen::SparseMatrix<double>& lt = supernodal.matrixL().nestedExpression();
    REQUIRE(ls.nonZeros() == lt.nonZeros());
    for (Eigen::Index q = 0; q < ls.nonZeros(); ++q) {
      REQUIRE(ls.innerIndexPtr()[q] == lt.innerIndexPtr()[q]);
      CHECK(std::abs(ls.valuePtr()[q] - lt.valuePtr()[q]) <= 1e-12 * (1.0 + std::abs(ls.valuePtr()[q])));
    }
    const VectorX ds = simplicial.vectorD(), dt = supernodal.vectorD();
    CHECK((ds - dt).cwiseAbs().maxCoeff() <= 1e-12 * ds.cwiseAbs().maxCoeff());
    // and it solves: A x = b to round-off
    supernodal.prepare_solve();
    const VectorX b = random_vector(a.rows(), 5);
    VectorX x(a.rows());
    supernodal.solve_into(b, x);
    CHECK((a * x - b).cwiseAbs().maxCoeff() <= 1e-11 * b.cwiseAbs().maxCoeff());
  }
  // a zero pivot is reported as the simplicial factorisation reports it
  Eigen::SparseMatrix<double> singular = shifted_laplacian_3d(3, 2);
  singular.coeffRef(0, 0) = 0.0;
  for (Eigen::SparseMatrix<double>::InnerIterator it(singular, 0); it; ++it) it.valueRef() = 0.0;
  for (int j = 0; j < singular.outerSize(); ++j)
    for (Eigen::SparseMatrix<double>::InnerIterator it(singular, j); it; ++it)
      if (it.row() == 0) it.valueRef() = 0.0;
  SparseLdlt f;
  f.analyzePattern(singular);
  f.factorize_supernodal(singular);
  CHECK(f.info() == Eigen::NumericalIssue);
}

TEST_CASE("factorize_supernodal on a dense matrix: the right-looking LDL^T bit for bit (one panel, blocks of four columns)", "[unit]") {
  // A dense pattern is one supernode, so the factor is panel_ldlt's blocked LDL^T; its entries must
  // be those of the plain right-looking loop (every entry's terms in the same order), bit for bit.
  for (int n : {7, 8, 13, 42}) {
    Eigen::MatrixXd m = Eigen::MatrixXd::Zero(n, n);
    const VectorX v = random_vector(n * n, 11 + n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j <= i; ++j) m(i, j) = m(j, i) = v[i * n + j] / 3.0;
    for (int i = 0; i < n; ++i) m(i, i) = n + 1.0 + std::abs(v[i]);
    const Eigen::SparseMatrix<double> a = m.sparseView();
    SparseLdlt f;
    f.analyzePattern(a);
    f.factorize_supernodal(a);
    REQUIRE(f.info() == Eigen::Success);
    // the reference: C = P A P^T, right-looking column by column, L = U (1 / D)
    Eigen::MatrixXd c = f.permutationP() * m * f.permutationP().transpose();
    Eigen::VectorXd d(n);
    for (int k = 0; k < n; ++k) {
      const double dk = c(k, k);
      d[k] = dk;
      for (int k2 = k + 1; k2 < n; ++k2) {
        const double t = c(k2, k);
        for (int r = k2; r < n; ++r) c(r, k2) -= c(r, k) * (t / dk);
      }
      const double inv = 1.0 / dk;
      for (int r = k + 1; r < n; ++r) c(r, k) *= inv;
    }
    const Eigen::SparseMatrix<double>& l = f.matrixL().nestedExpression();
    REQUIRE(l.nonZeros() == static_cast<Eigen::Index>(n) * (n - 1) / 2);
    int differ = 0;
    for (int k = 0; k < n; ++k)
      for (Eigen::SparseMatrix<double>::InnerIterator it(l, k); it; ++it)
        if (it.value() != c(it.row(), k)) ++differ;
    CHECK(differ == 0);
    const VectorX dt = f.vectorD();
    CHECK((dt - d).cwiseAbs().maxCoeff() == 0.0);
  }
}
