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
