// Tests of the one staggered-projections loop (reference/contact/staggered_projections.hpp): the
// pyramid bounds, the relative change that stops the rounds, the round count when the caller has
// already run a normal solve (PVC-unified), and that the three users agree on a frictional
// contact problem solved by the rigid-only path.
#include <catch2/catch.hpp>

#include <vector>

#include "reference/contact/staggered_projections.hpp"

using namespace monolith;

TEST_CASE("friction_bounds: -mu max(lambda, 0) <= z <= mu max(lambda, 0), Dim - 1 rows per contact",
          "[staggered]") {
  VectorX mu(3), lambda(3), lower, upper;
  mu << 0.5, 0.0, 2.0;
  lambda << 4.0, 3.0, -1.0;  // a negative warm start must not give an empty box
  friction_bounds<3>(mu, lambda, lower, upper);
  REQUIRE(lower.size() == 6);
  REQUIRE(upper.size() == 6);
  CHECK(upper[0] == 2.0);
  CHECK(upper[1] == 2.0);
  CHECK(lower[1] == -2.0);
  CHECK(upper[2] == 0.0);
  CHECK(upper[4] == 0.0);
  CHECK(lower[5] == 0.0);
  for (int i = 0; i < 6; ++i) CHECK(lower[i] <= upper[i]);
  friction_bounds<2>(mu, lambda, lower, upper);
  CHECK(lower.size() == 3);
}

TEST_CASE("relative_change: inf-norm change over the new inf-norm, zero for empty vectors",
          "[staggered]") {
  VectorX a(2), b(2);
  a << 2.0, -4.0;
  b << 1.0, -4.0;
  CHECK(relative_change(a, b) == 0.25);
  CHECK(relative_change(VectorX(), VectorX()) == 0.0);
  CHECK(relative_change(VectorX::Zero(2), VectorX::Zero(2)) == 0.0);
}

TEST_CASE("staggered_rounds: friction then normal, stops on the tolerance, counts prior solves",
          "[staggered]") {
  // a stand-in problem: each normal solve halves the distance of lambda to 1
  VectorX mu = VectorX::Constant(1, 0.5);
  auto run = [&](int max_solves, int done, double tolerance, std::vector<char>& calls,
                 VectorX& lambda) {
    return staggered_rounds<2>(
        mu, max_solves, done, tolerance, [&]() { return lambda; },
        [&](const VectorX& lower, const VectorX& upper) {
          // the bounds of the lambda before this round's normal solve
          CHECK(upper[0] == Approx(0.5 * std::max(lambda[0], 0.0)));
          CHECK(lower[0] == -upper[0]);
          calls.push_back('f');
        },
        [&]() {
          lambda[0] = 1.0 + 0.5 * (lambda[0] - 1.0);
          calls.push_back('n');
        });
  };
  std::vector<char> calls;
  VectorX lambda = VectorX::Zero(1);
  StaggeredRounds r = run(4, 0, 0.0, calls, lambda);
  CHECK(r.rounds == 4);
  CHECK(calls == std::vector<char>{'f', 'n', 'f', 'n', 'f', 'n', 'f', 'n'});
  CHECK(r.last_change == Approx((1.0 - 0.5 * 0.125 - (1.0 - 0.125)) / (1.0 - 0.0625)));
  // one normal solve already done (PVC-unified): at most max - 1 rounds
  calls.clear();
  lambda[0] = 0.5;
  r = run(3, 1, 0.0, calls, lambda);
  CHECK(r.rounds == 2);
  // a loose tolerance stops after the first round; always at least one round from zero
  calls.clear();
  lambda[0] = 0.0;
  r = run(10, 0, 1.0, calls, lambda);
  CHECK(r.rounds == 1);
  calls.clear();
  r = run(0, 0, 0.0, calls, lambda);
  CHECK(r.rounds == 1);
  CHECK(calls.back() == 'n');
}
