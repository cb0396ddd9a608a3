// The multigrid patch sweep (Multigrid::sweep, reference/solvers/multigrid.cpp) gives the bits of
// the plain algorithm: for each patch in order, r_i = b_i - sum_q a_iq x_q over row i's entries in
// stored order, d_i = sum_j inv_ij r_j for j from 0 with inv the symmetrised dense inverse of the
// patch block, then x_P += d (backward: the patches in reverse order). Section 42 of
// docs/preconditioners.md stores the inverses of patches of at most 6 unknowns as packed upper
// triangles and relaxes patches of 4 and 6 unknowns whose rows hold 15 entries by an unrolled
// kernel; this test covers patches of 1 to 9 unknowns, rows of 15 entries and of other lengths,
// in double and in single precision, and checks that the comparison has teeth (the same inverse
// applied with its sums in another order differs).
#include <catch2/catch.hpp>

#include <Eigen/Dense>
#include <cmath>
#include <vector>

#include "reference/solvers/multigrid.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A banded SPD matrix: row i couples to i - 7 .. i + 7 (15 entries inside, fewer at the ends),
/// values not representable in float, diagonally dominant; two levels (pairs aggregated), one
/// group of patches of sizes 1, 2, ..., 9, 4, 6, 4, 6, ... (consecutive unknowns).
std::vector<MultigridLevel> banded_levels(int n) {
  std::vector<Triplet> t;
  for (int i = 0; i < n; ++i) {
    double off_sum = 0.0;
    for (int k = -7; k <= 7; ++k) {
      const int j = i + k;
      if (k == 0 || j < 0 || j >= n) continue;
      const int lo = std::min(i, j), hi = std::max(i, j);
      const double v = -(0.3 + 0.2 * std::sin(0.37 * lo + 0.11 * hi)) / 3.0;  // symmetric
      t.emplace_back(i, j, v);
      off_sum += std::abs(v);
    }
    t.emplace_back(i, i, off_sum * 1.05 + 0.01 * (1.0 + std::cos(0.3 * i)) / 7.0);
  }
  SparseMatrix a(n, n);
  a.setFromTriplets(t.begin(), t.end());
  a.makeCompressed();
  const int nc = (n + 1) / 2;
  std::vector<Triplet> pt;
  for (int i = 0; i < n; ++i) pt.emplace_back(i, i / 2, 1.0);
  SparseMatrix p(n, nc);
  p.setFromTriplets(pt.begin(), pt.end());
  p.makeCompressed();
  std::vector<MultigridLevel> levels(2);
  levels[0].a = a;
  levels[0].prolongation = p;
  int i = 0, k = 0;
  while (i < n) {
    const int size = k < 9 ? k + 1 : (k % 2 == 0 ? 4 : 6);
    std::vector<int> members;
    for (int q = 0; q < size && i < n; ++q) members.push_back(i++);
    levels[0].patches.add(members);
    ++k;
  }
  levels[0].patches.close_group(0);
  levels[1].a = galerkin_product(a, p);
  return levels;
}

/// The plain sweep of the patches of `ps` (one group, in order; backward: reversed) with the
/// operator a; `reverse_inverse_sums` sums d_i over j from m - 1 down (the teeth).
void plain_sweep(const SparseMatrix& a, const PatchSet& ps, const VectorX& b, VectorX& x, bool backward,
                 bool reverse_inverse_sums = false) {
  const int np = ps.size();
  for (int step = 0; step < np; ++step) {
    const int k = backward ? np - 1 - step : step;
    const int m = ps.start[k + 1] - ps.start[k];
    const int* idx = ps.index.data() + ps.start[k];
    // the block and its inverse, formed as Multigrid forms them
    using Block = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, PatchSet::kMaxPatchSize, PatchSet::kMaxPatchSize>;
    Block block = Block::Zero(m, m);
    for (int i = 0; i < m; ++i)
      for (SparseMatrix::InnerIterator it(a, idx[i]); it; ++it)
        for (int j = 0; j < m; ++j)
          if (it.col() == idx[j]) block(i, j) = it.value();
    Eigen::LDLT<Block> ldlt(block);
    Block inv = ldlt.solve(Block::Identity(m, m));
    inv = 0.5 * (inv + inv.transpose()).eval();
    std::vector<double> r(m), d(m);
    for (int i = 0; i < m; ++i) {
      double s = b[idx[i]];
      for (int e = a.outerIndexPtr()[idx[i]]; e < a.outerIndexPtr()[idx[i] + 1]; ++e)
        s -= a.valuePtr()[e] * x[a.innerIndexPtr()[e]];
      r[i] = s;
    }
    for (int i = 0; i < m; ++i) {
      double s = 0.0;
      for (int q = 0; q < m; ++q) {
        const int j = reverse_inverse_sums ? m - 1 - q : q;
        s += inv(i, j) * r[j];
      }
      d[i] = s;
    }
    for (int i = 0; i < m; ++i) x[idx[i]] += d[i];
  }
}

}  // namespace

TEST_CASE("patch sweep: packed inverses and the unrolled 4- and 6-unknown patches give the plain sweep's bits",
          "[unit]") {
  const int n = 403;
  for (const bool single : {false, true}) {
    INFO("single precision " << single);
    const Multigrid mg(banded_levels(n), 1, /*renumber=*/false, single);
    const SparseMatrix a = mg.smoothed_operator(0);  // the values the sweep uses (rounded in single)
    const PatchSet& ps = mg.level(0).patches;
    // rows of 15 entries inside: the unrolled kernel is taken for most patches of 4 and 6
    int uniform = 0;
    for (int k = 0; k < ps.size(); ++k) {
      const int m = ps.start[k + 1] - ps.start[k];
      bool all = m == 4 || m == 6;
      for (int q = ps.start[k]; q < ps.start[k + 1]; ++q)
        all = all && a.outerIndexPtr()[ps.index[q] + 1] - a.outerIndexPtr()[ps.index[q]] == 15;  // (multigrid.cpp's kUniformRowLength)
      uniform += all;
    }
    CHECK(uniform > ps.size() / 2);
    const VectorX b = random_vector(n, 41);
    VectorX x = random_vector(n, 42), y = x, z = x;
    for (int s = 0; s < 3; ++s) {
      mg.sweep(0, b, x, false);
      plain_sweep(a, ps, b, y, false);
      plain_sweep(a, ps, b, z, false, true);
      CHECK(differing(x, y) == 0);
      mg.sweep(0, b, x, true);
      plain_sweep(a, ps, b, y, true);
      plain_sweep(a, ps, b, z, true, true);
      CHECK(differing(x, y) == 0);
    }
    CHECK(differing(y, z) > 0);  // teeth: the inverse's sums in another order change bits
  }
}
