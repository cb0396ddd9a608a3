// Multigrid in single precision (reference/solvers/multigrid.hpp, (P12) of docs/derivations.md):
// the rounded operator of every smoothed level is at least the double one (Ã - A positive
// semi-definite, so Ã is SPD even where plain rounding to nearest makes a nearly singular A
// indefinite), the V-cycle stays symmetric positive definite (Q A's eigenvalues in (0, 1] up to
// the rounding), and it gives the same bits on 1 and 2 threads.
#include <catch2/catch.hpp>
#include <omp.h>

#include <Eigen/Dense>
#include <cmath>
#include <vector>

#include "reference/solvers/multigrid.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A 1D chain of n unknowns: a Laplacian with weights w_i (values not representable in float),
/// plus `mass` on the diagonal (the smallest eigenvalue about mass), two levels with linear
/// prolongation, point patches in red/black colours.
std::vector<MultigridLevel> chain_levels(int n, double mass, double phase = 0.0) {
  std::vector<Triplet> t;
  auto weight = [phase](int i) { return 1.0 + 0.1 * std::sin(0.7 * i + phase) + 1.0 / 3.0; };
  for (int i = 0; i + 1 < n; ++i) {
    const double w = weight(i);
    t.emplace_back(i, i, w);
    t.emplace_back(i + 1, i + 1, w);
    t.emplace_back(i, i + 1, -w);
    t.emplace_back(i + 1, i, -w);
  }
  for (int i = 0; i < n; ++i) t.emplace_back(i, i, mass);
  SparseMatrix a(n, n);
  a.setFromTriplets(t.begin(), t.end());
  a.makeCompressed();
  const int nc = n / 2;
  std::vector<Triplet> pt;
  for (int i = 0; i < n; ++i) {
    const int c = i / 2;
    if (i % 2 == 0) pt.emplace_back(i, c, 1.0);
    else {
      pt.emplace_back(i, c, 0.5);
      if (c + 1 < nc) pt.emplace_back(i, c + 1, 0.5);
    }
  }
  SparseMatrix p(n, nc);
  p.setFromTriplets(pt.begin(), pt.end());
  p.makeCompressed();
  std::vector<MultigridLevel> levels(2);
  levels[0].a = a;
  levels[0].prolongation = p;
  for (int colour = 0; colour < 2; ++colour)
    for (int i = colour; i < n; i += 2) {
      levels[0].patches.add({i});
      levels[0].patches.close_group(colour);
    }
  levels[1].a = galerkin_product(a, p);
  return levels;
}

double min_eigenvalue(const Eigen::MatrixXd& m) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (m + m.transpose()));
  return es.eigenvalues().minCoeff();
}

}  // namespace

TEST_CASE("multigrid in single precision: rounded operators >= A (SPD where rounding to nearest is not), Q SPD, thread-independent",
          "[unit]") {
  const int n = 64;
  const double mass = 1e-10;
  // several chains: on some of them rounding every entry to nearest (no diagonal guard) leaves a
  // matrix that is not positive definite (the sign of the rounding's effect on the near-null
  // constant vector is the luck of the data); the guarded rounding is SPD on every one
  int indefinite_nearest = 0;
  for (int c = 0; c < 8; ++c) {
    const Multigrid mg(chain_levels(n, mass, 0.37 * c), 1, true, true);
    REQUIRE(mg.single_precision());
    const Eigen::MatrixXd a(mg.level(0).a);
    const Eigen::MatrixXd ar(mg.smoothed_operator(0));
    INFO("chain " << c);
    // rounding did change the operator, and the rounded one is A plus a PSD matrix
    CHECK((ar - a).cwiseAbs().maxCoeff() > 0.0);
    CHECK(min_eigenvalue(ar - a) >= -1e-15 * a.cwiseAbs().maxCoeff());
    CHECK(min_eigenvalue(ar) > 0.5 * mass);
    Eigen::MatrixXd nearest = a;
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) nearest(i, j) = static_cast<double>(static_cast<float>(a(i, j)));
    if (min_eigenvalue(nearest) < 0.0) ++indefinite_nearest;
  }
  CHECK(indefinite_nearest > 0);
  const Multigrid mg(chain_levels(n, mass), 1, true, true);
  // Q: symmetric and positive definite. Its coarse operators are A's Galerkin products, not
  // those of the rounded Ã, so Q <= Ã^-1 <= A^-1 holds only up to the rounding: the eigenvalues
  // of Q A lie in (0, 1 + O(1e-7)] (section 31 of docs/preconditioners.md)
  const SparseMatrix af = mg.finest_operator();
  Eigen::MatrixXd q(n, n);
  VectorX e = VectorX::Zero(n), x;
  for (int j = 0; j < n; ++j) {
    e[j] = 1.0;
    mg.apply(e, x, 1);
    q.col(j) = x;
    e[j] = 0.0;
  }
  CHECK((q - q.transpose()).cwiseAbs().maxCoeff() < 1e-10 * q.cwiseAbs().maxCoeff());
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> ges(Eigen::MatrixXd(af), Eigen::MatrixXd(q.inverse()));
  CHECK(ges.eigenvalues().minCoeff() > 0.0);
  CHECK(ges.eigenvalues().maxCoeff() <= 1.0 + 1e-6);
  // the double hierarchy is a different map (by round-off), and threads do not change the bits
  const Multigrid md(chain_levels(n, mass), 1, true, false);
  const VectorX b = random_vector(n, 3);
  VectorX xs, xd, x1, x2;
  mg.apply(b, xs, 2);
  md.apply(b, xd, 2);
  CHECK(!(xs.array() == xd.array()).all());
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  mg.apply(b, x1, 2);
  omp_set_num_threads(2);
  mg.apply(b, x2, 2);
  omp_set_num_threads(threads);
  CHECK((x1.array() == x2.array()).all());
  CHECK((x1.array() == xs.array()).all());
}
