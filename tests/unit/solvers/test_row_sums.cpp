// row_sums and csr_row_sums (reference/solvers/row_sums.hpp): rows summed side by side give the
// bits of the plain row-by-row loop (each row's terms in stored order from the same start), for
// residuals and products, whole ranges and sub-ranges, rows in any order and any count, on 1 and
// 2 threads. The check has teeth: the same terms summed in another order differ in some row.
#include <catch2/catch.hpp>
#include <omp.h>

#include <cstring>
#include <vector>

#include "reference/solvers/row_sums.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A CSR matrix (rows of 0 to 40 entries, unsorted columns with repeats) as plain arrays.
struct Csr {
  std::vector<int> outer{0}, inner;
  std::vector<double> value;
};

Csr random_csr(int rows, int cols, unsigned seed) {
  const VectorX r = random_vector(rows * 41 * 2 + rows, seed);
  Csr m;
  int q = 0;
  for (int i = 0; i < rows; ++i) {
    const int length = static_cast<int>(0.5 * (r[q++] + 1.0) * 40.99);
    for (int k = 0; k < length; ++k) {
      m.inner.push_back(static_cast<int>(0.5 * (r[q] + 1.0) * cols) % cols);
      m.value.push_back(r[q + 1] * 1e3);  // large and small terms: the order matters
      q += 2;
    }
    m.outer.push_back(static_cast<int>(m.inner.size()));
  }
  return m;
}

/// The plain loop: s = start, then s -/+ a x over the row's entries in stored order.
double plain(const Csr& m, int row, double start, bool subtract, const VectorX& x) {
  double s = start;
  for (int q = m.outer[row]; q < m.outer[row + 1]; ++q) {
    if (subtract) s -= m.value[q] * x[m.inner[q]];
    else s += m.value[q] * x[m.inner[q]];
  }
  return s;
}


}  // namespace

TEST_CASE("row_sums: rows side by side, the bits of the plain row loop", "[unit]") {
  const int threads = omp_get_max_threads();
  for (const int n : {37, 9001}) {  // the second one takes the parallel path
    const Csr m = random_csr(n, n, 21);
    const VectorX x = random_vector(n, 22);
    const VectorX b = random_vector(n, 23);
    // teeth: the same terms summed backwards differ in some row
    int reordered_differs = 0;
    for (int i = 0; i < n; ++i) {
      double s = 0.0;
      for (int q = m.outer[i + 1] - 1; q >= m.outer[i]; --q) s += m.value[q] * x[m.inner[q]];
      reordered_differs += !same_bits(s, plain(m, i, 0.0, false, x));
    }
    INFO("n " << n);
    CHECK(reordered_differs > 0);
    for (int t = 1; t <= 2; ++t) {
      omp_set_num_threads(t);
      // whole range and a sub-range, product and residual
      for (const auto& [begin, end] : std::vector<std::pair<int, int>>{{0, n}, {3, n - 2}}) {
        VectorX y(end - begin), r(end - begin);
        csr_row_sums<false>(m.outer.data(), m.inner.data(), m.value.data(), begin, end, nullptr, x.data(), y.data(), true);
        csr_row_sums<true>(m.outer.data(), m.inner.data(), m.value.data(), begin, end, b.data(), x.data(), r.data(), true);
        int wrong = 0;
        for (int i = begin; i < end; ++i) {
          wrong += !same_bits(y[i - begin], plain(m, i, 0.0, false, x));
          wrong += !same_bits(r[i - begin], plain(m, i, b[i], true, x));
        }
        CHECK(wrong == 0);
      }
    }
    omp_set_num_threads(threads);
    // rows in any order and any count (a patch's members: 1 to 12 rows, scattered)
    int wrong = 0;
    for (int count = 1; count <= 12; ++count) {
      std::vector<int> rows(count);
      std::vector<double> out(count);
      for (int t = 0; t < count; ++t) {
        rows[t] = (7919 * (t + 1) + 31 * count) % n;
        out[t] = b[rows[t]];
      }
      row_sums<true>(m.outer.data(), m.inner.data(), m.value.data(), x.data(), rows.data(), count, out.data());
      for (int t = 0; t < count; ++t) wrong += !same_bits(out[t], plain(m, rows[t], b[rows[t]], true, x));
    }
    CHECK(wrong == 0);
  }
}
