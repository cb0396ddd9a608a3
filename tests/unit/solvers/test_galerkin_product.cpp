// sparse_row_product and galerkin_product (reference/solvers/multigrid.hpp): the same matrices,
// bit for bit, as Eigen's sparse products (with prune(0, 0) for the Galerkin operator), on 1 and 2
// threads; exactly cancelling entries kept by the plain product and dropped by the Galerkin one.
// (On 1 thread the products take the single pass of sparse_row_product_serial, storage reserved
// for an upper bound; above 4096 rows with a team of 2 threads the two-pass form.)
#include <catch2/catch.hpp>
#include <omp.h>

#include <array>
#include <cmath>
#include <cstring>
#include <vector>

#include "reference/solvers/multigrid.hpp"
#include "tests/support/sparse_helpers.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A random sparse m x n matrix with about `per_row` entries per row (values from random_vector,
/// some of them integers so that products cancel exactly).
SparseMatrix random_sparse(int m, int n, int per_row, unsigned seed) {
  const VectorX r = random_vector(m * per_row * 3, seed);
  std::vector<Triplet> t;
  int q = 0;
  for (int i = 0; i < m; ++i)
    for (int k = 0; k < per_row; ++k) {
      const int j = static_cast<int>((0.5 * (r[q] + 1.0)) * n) % n;
      const double v = r[q + 1] > 0.3 ? std::round(4.0 * r[q + 2]) : r[q + 2];
      t.emplace_back(i, j, v);
      q += 3;
    }
  SparseMatrix a(m, n);
  a.setFromTriplets(t.begin(), t.end());
  a.makeCompressed();
  return a;
}


}  // namespace

TEST_CASE("sparse_row_product and galerkin_product: Eigen's products bit for bit, on 1 and 2 threads", "[unit]") {
  const int threads = omp_get_max_threads();
  // large enough for the parallel path (> 4096 rows)
  for (const auto& [n, nc, per_row] : std::vector<std::array<int, 3>>{{50, 17, 3}, {9000, 1300, 5}}) {
    SparseMatrix a0 = random_sparse(n, n, per_row, 11);
    const SparseMatrix a = SparseMatrix(a0 + SparseMatrix(a0.transpose()));  // symmetric, as an operator
    const SparseMatrix p = random_sparse(n, nc, 2, 12);
    SparseMatrix ap_eigen = a * p;
    ap_eigen.makeCompressed();
    const SparseMatrix pt = p.transpose();
    SparseMatrix c_eigen = pt * ap_eigen;
    c_eigen.prune(0.0, 0.0);
    c_eigen.makeCompressed();
    // the test must see cancellation: some entry of A P is an exact zero
    bool zero_entry = false;
    for (int e = 0; e < ap_eigen.nonZeros(); ++e) zero_entry = zero_entry || ap_eigen.valuePtr()[e] == 0.0;
    INFO("n " << n);
    CHECK(zero_entry);
    for (int t = 1; t <= 2; ++t) {
      omp_set_num_threads(t);
      const SparseMatrix ap = sparse_row_product(a, p, false);
      CHECK(testing::same_sparse_bits(ap, ap_eigen));
      const SparseMatrix ap_dropped = sparse_row_product(a, p, true);
      CHECK(ap_dropped.nonZeros() < ap.nonZeros());
      CHECK((SparseMatrix(ap_dropped - ap)).norm() == 0.0);
      CHECK(testing::same_sparse_bits(galerkin_product(a, p), c_eigen));
    }
    omp_set_num_threads(threads);
  }
  CHECK_THROWS(sparse_row_product(random_sparse(4, 5, 2, 1), random_sparse(4, 5, 2, 2), false));
}
