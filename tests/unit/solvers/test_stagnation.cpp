// The stagnation rule of the multigrid attempt under "auto" (pcg.hpp StagnationRule; PCG and
// MPRGP; docs/preconditioners.md section 21): a solve whose smallest residual has not fallen by
// 1 / factor in the last `window` iterations stops, unconverged and `stagnated`, so that the SSOR
// fallback starts early; a solve that keeps converging is not touched (the same bits as with
// the rule off).
#include <catch2/catch.hpp>
#include <limits>

#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/pcg.hpp"
#include "tests/support/sparse_helpers.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// 2D five-point Laplacian on m x m nodes plus a small diagonal: SPD, condition about m^2.
SparseMatrix laplacian(int m) { return five_point_matrix(m, VectorX::Constant(m * m, 1e-3)); }

}  // namespace

TEST_CASE("the stagnation test: a residual that keeps falling never stops, a flat one stops after the window",
          "[unit][stagnation]") {
  StagnationTest off(StagnationRule{});
  for (int i = 1; i <= 1000; ++i) CHECK_FALSE(off.stagnated(i, 1.0));
  // falling by 0.9 per iteration: 0.9^10 = 0.35 < 0.5 over any window of 10
  StagnationTest falling(StagnationRule{10, 0.5});
  double r = 1.0;
  for (int i = 1; i <= 200; ++i) {
    r *= 0.9;
    CHECK_FALSE(falling.stagnated(i, r));
  }
  // falling by 0.7 for 20 iterations, then flat (with noise above the best): stops at
  // iteration 29, the first whose best (0.7^20) is not below half the best of 10 iterations
  // before (0.7^19)
  StagnationTest flat(StagnationRule{10, 0.5});
  r = 1.0;
  int stopped = -1;
  for (int i = 1; i <= 100 && stopped < 0; ++i) {
    if (i <= 20) r *= 0.7;
    const double noisy = i <= 20 ? r : r * (1.0 + 0.5 * (i % 3));
    if (flat.stagnated(i, noisy)) stopped = i;
  }
  CHECK(stopped == 29);
}

TEST_CASE("PCG and MPRGP stop on stagnation and are unchanged by the rule when they converge",
          "[unit][stagnation]") {
  const SparseMatrix a = laplacian(40);
  const VectorX b = random_vector(a.rows(), 11);
  const SparseMatrixOperator op(a);
  PcgSettings plain;
  plain.tolerance = 1e-10;
  plain.max_iterations = 5000;
  plain.precondition = false;  // plain CG: about 100 iterations here
  VectorX x_off;
  const PcgResult off = pcg_solve(op, b, x_off, plain);
  REQUIRE(off.converged);
  // the attempt's rule (no halving in 100 iterations) never fires on a converging solve
  PcgSettings with = plain;
  with.stagnation = attempt_stagnation_rule();
  VectorX x_with;
  const PcgResult on = pcg_solve(op, b, x_with, with);
  CHECK(on.converged);
  CHECK_FALSE(on.stagnated);
  CHECK(on.iterations == off.iterations);
  CHECK((x_with - x_off).cwiseAbs().maxCoeff() == 0.0);
  // a rule no solve can meet (a factor 1e6 in 5 iterations) stops it after 5, unconverged
  PcgSettings strict = plain;
  strict.stagnation = StagnationRule{5, 1e-6};
  VectorX x_strict;
  const PcgResult cut = pcg_solve(op, b, x_strict, strict);
  CHECK(cut.stagnated);
  CHECK_FALSE(cut.converged);
  CHECK(cut.iterations == 6);
  // MPRGP with every bound infinite is preconditioned CG: the same three cases
  const VectorX lower = VectorX::Constant(a.rows(), -std::numeric_limits<double>::infinity());
  const VectorX upper = VectorX::Constant(a.rows(), std::numeric_limits<double>::infinity());
  MprgpSettings m;
  m.tolerance = 1e-10;
  m.max_iterations = 5000;
  m.precondition = false;
  VectorX y_off, y_with, y_strict;
  const MprgpResult moff = mprgp_solve(op, b, lower, upper, y_off, m);
  REQUIRE(moff.converged);
  m.stagnation = attempt_stagnation_rule();
  const MprgpResult mon = mprgp_solve(op, b, lower, upper, y_with, m);
  CHECK(mon.converged);
  CHECK_FALSE(mon.stagnated);
  CHECK(mon.iterations == moff.iterations);
  CHECK((y_with - y_off).cwiseAbs().maxCoeff() == 0.0);
  m.stagnation = StagnationRule{5, 1e-6};
  const MprgpResult mcut = mprgp_solve(op, b, lower, upper, y_strict, m);
  CHECK(mcut.stagnated);
  CHECK_FALSE(mcut.converged);
  CHECK(mcut.iterations == 6);
}
