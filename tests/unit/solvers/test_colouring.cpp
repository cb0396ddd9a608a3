// Welsh-Powell colouring and the coloured SOR sweeps of section 4.3: proper colourings, the
// max-degree + 1 bound, thread-count independence and equality with serial Gauss-Seidel in the
// colour order.
#include <omp.h>

#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <random>
#include <set>

#include "reference/solvers/colouring.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/pcg.hpp"

using namespace monolith;

namespace {

/// A random graph on n vertices with edge probability p (symmetric, no self loops).
std::vector<std::vector<int>> random_graph(int n, double p, std::mt19937& rng) {
  std::bernoulli_distribution edge(p);
  std::vector<std::vector<int>> adj(n);
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if (edge(rng)) {
        adj[i].push_back(j);
        adj[j].push_back(i);
      }
  return adj;
}

int max_degree(const std::vector<std::vector<int>>& adj) {
  size_t d = 0;
  for (const auto& l : adj) d = std::max(d, l.size());
  return static_cast<int>(d);
}

/// No edge inside a colour, every vertex in exactly one increasing colour list: checked here
/// independently of is_proper_colouring.
void require_proper(const std::vector<std::vector<int>>& adj, const Colouring& c) {
  const int n = static_cast<int>(adj.size());
  REQUIRE(static_cast<int>(c.colour_of.size()) == n);
  std::vector<int> count(n, 0);
  for (int k = 0; k < c.num_colours(); ++k) {
    REQUIRE(std::is_sorted(c.colours[k].begin(), c.colours[k].end()));
    for (int v : c.colours[k]) {
      REQUIRE(c.colour_of[v] == k);
      ++count[v];
    }
  }
  for (int v = 0; v < n; ++v) REQUIRE(count[v] == 1);
  for (int v = 0; v < n; ++v)
    for (int w : adj[v]) REQUIRE(c.colour_of[v] != c.colour_of[w]);
}

/// 2D five-point Laplacian on m x m nodes (plus a shift): SPD, degree <= 4.
SparseMatrix laplacian(int m) {
  std::vector<Triplet> t;
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i) {
      const int k = i + m * j;
      t.emplace_back(k, k, 4.2);
      if (i > 0) t.emplace_back(k, k - 1, -1.0);
      if (i < m - 1) t.emplace_back(k, k + 1, -1.0);
      if (j > 0) t.emplace_back(k, k - m, -1.0);
      if (j < m - 1) t.emplace_back(k, k + m, -1.0);
    }
  SparseMatrix a(m * m, m * m);
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

VectorX random_vec(int n, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  VectorX v(n);
  for (int i = 0; i < n; ++i) v[i] = u(rng);
  return v;
}

/// The permutation listing the rows colour by colour (the serial sweep order).
std::vector<int> colour_order(const Colouring& c) {
  std::vector<int> order;
  for (const auto& rows : c.colours) order.insert(order.end(), rows.begin(), rows.end());
  return order;
}

}  // namespace

TEST_CASE("Welsh-Powell gives proper colourings with at most max-degree + 1 colours", "[unit][property]") {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 40; ++trial) {
    const int n = 1 + trial * 5;
    const double p = 0.02 + 0.02 * (trial % 10);
    const auto adj = random_graph(n, p, rng);
    const Colouring c = welsh_powell(adj);
    require_proper(adj, c);
    CHECK(c.num_colours() <= max_degree(adj) + 1);
    CHECK(is_proper_colouring(adj, c));
  }
}

TEST_CASE("Welsh-Powell on graphs with known chromatic numbers", "[unit]") {
  // complete graph K_6: 6 colours
  std::vector<std::vector<int>> k6(6);
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j)
      if (i != j) k6[i].push_back(j);
  CHECK(welsh_powell(k6).num_colours() == 6);
  // even cycle: 2 colours; odd cycle: 3
  for (int n : {8, 9}) {
    std::vector<std::vector<int>> cycle(n);
    for (int i = 0; i < n; ++i) {
      cycle[i].push_back((i + 1) % n);
      cycle[i].push_back((i + n - 1) % n);
    }
    const Colouring c = welsh_powell(cycle);
    require_proper(cycle, c);
    CHECK(c.num_colours() == (n % 2 ? 3 : 2));
  }
  // no edges: one colour; no vertices: none
  CHECK(welsh_powell(std::vector<std::vector<int>>(5)).num_colours() == 1);
  CHECK(welsh_powell({}).num_colours() == 0);
  // a star: the centre (highest degree) is coloured first, the leaves share the second colour
  std::vector<std::vector<int>> star(6);
  for (int i = 1; i < 6; ++i) {
    star[0].push_back(i);
    star[i].push_back(0);
  }
  const Colouring s = welsh_powell(star);
  CHECK(s.num_colours() == 2);
  CHECK(s.colour_of[0] == 0);
  // the 5-point Laplacian graph is bipartite; Welsh-Powell needs at most 5 colours on it
  const auto lap = matrix_adjacency(laplacian(10));
  const Colouring cl = welsh_powell(lap);
  require_proper(lap, cl);
  CHECK(cl.num_colours() <= 5);
}

TEST_CASE("matrix_adjacency is the symmetrised off-diagonal pattern of the non-zeros", "[unit]") {
  std::vector<Triplet> t = {{0, 0, 1.0}, {0, 2, 3.0}, {1, 1, 2.0}, {3, 1, -1.0}, {2, 3, 0.0}};
  SparseMatrix a(4, 4);
  a.setFromTriplets(t.begin(), t.end());  // (2, 3) is stored with value 0: not an edge
  const auto adj = matrix_adjacency(a);
  REQUIRE(adj.size() == 4);
  CHECK(adj[0] == std::vector<int>{2});
  CHECK(adj[1] == std::vector<int>{3});
  CHECK(adj[2] == std::vector<int>{0});
  CHECK(adj[3] == std::vector<int>{1});
}

TEST_CASE("contact_adjacency couples contacts sharing a dynamic body only", "[unit]") {
  // bodies 0, 1, 2; -1 is the static world
  const std::vector<std::pair<int, int>> contacts = {{0, -1}, {0, 1}, {1, -1}, {2, -1}, {-1, 2}, {1, 1}};
  const auto adj = contact_adjacency(contacts, 3);
  CHECK(adj[0] == std::vector<int>{1});
  CHECK(adj[1] == (std::vector<int>{0, 2, 5}));
  CHECK(adj[2] == (std::vector<int>{1, 5}));
  CHECK(adj[3] == std::vector<int>{4});
  CHECK(adj[4] == std::vector<int>{3});
  CHECK(adj[5] == (std::vector<int>{1, 2}));
  CHECK_THROWS_AS(contact_adjacency({{0, 3}}, 3), std::invalid_argument);
}

TEST_CASE("a body-sharing contact colouring, expanded to the rows, is proper for J M^-1 J^T",
          "[unit][property]") {
  std::mt19937 rng(13);
  std::uniform_int_distribution<int> pick(-1, 19);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int dofs : {3, 6}) {
    const int block = dofs == 3 ? 1 : 2;  // friction rows per contact: Dim - 1
    const int bodies = 20, contacts = 60;
    std::vector<std::pair<int, int>> pairs;
    Eigen::MatrixXd j = Eigen::MatrixXd::Zero(contacts * block, bodies * dofs);
    for (int c = 0; c < contacts; ++c) {
      int b0 = pick(rng), b1 = pick(rng);
      if (b0 < 0) b0 = c % bodies;  // at least one dynamic body
      if (b1 == b0) b1 = -1;
      pairs.emplace_back(b0, b1);
      for (int r = 0; r < block; ++r)
        for (int k = 0; k < dofs; ++k) {
          j(c * block + r, b0 * dofs + k) = u(rng);
          if (b1 >= 0) j(c * block + r, b1 * dofs + k) = u(rng);
        }
    }
    const SparseMatrix a = Eigen::MatrixXd(j * j.transpose()).sparseView();
    const Colouring cc = welsh_powell(contact_adjacency(pairs, bodies));
    const Colouring rows = expand_colouring(cc, block);
    CHECK(rows.num_colours() == cc.num_colours() * block);
    require_proper(matrix_adjacency(a), rows);
    CHECK_NOTHROW(ColouredSparseOperator(a, rows));
  }
}

TEST_CASE("ColouredSparseOperator rejects colourings that couple two rows of one colour", "[unit]") {
  const SparseMatrix a = laplacian(4);
  Colouring one;
  one.colours = {std::vector<int>(16)};
  for (int i = 0; i < 16; ++i) one.colours[0][i] = i;
  one.colour_of.assign(16, 0);
  CHECK_THROWS_AS(ColouredSparseOperator(a, one), std::invalid_argument);
  Colouring missing = welsh_powell(matrix_adjacency(a));
  missing.colours[0].pop_back();
  CHECK_THROWS_AS(ColouredSparseOperator(a, missing), std::invalid_argument);
}

TEST_CASE("coloured sweeps: identical for 1 and 2 threads, equal to serial Gauss-Seidel in colour order",
          "[unit][property]") {
  // 120 x 120 nodes: the colours hold thousands of rows, so the OpenMP loops really split
  const int m = 120, n = m * m;
  const SparseMatrix a = laplacian(m);
  const Colouring colours = welsh_powell(matrix_adjacency(a));
  REQUIRE(colours.colours[0].size() > 1000);
  ColouredSparseOperator coloured(a, colours);

  // the serial reference: the plain operator (index-order sweeps) on the colour-permuted system
  const std::vector<int> order = colour_order(colours);
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> perm(n);
  for (int k = 0; k < n; ++k) perm.indices()[order[k]] = k;  // row order[k] goes to position k
  const SparseMatrix pa = (perm * a * perm.transpose()).eval();
  SparseMatrixOperator serial(pa);

  std::mt19937 rng(19);
  const VectorX rhs = random_vec(n, rng), x0 = random_vec(n, rng);
  std::vector<char> mask(n);
  for (int i = 0; i < n; ++i) mask[i] = (i * 7) % 5 != 0;
  std::vector<char> pmask(n);
  for (int i = 0; i < n; ++i) pmask[perm.indices()[i]] = mask[i];

  const int saved = omp_get_max_threads();
  for (const bool masked : {false, true})
    for (const double omega : {1.0, 1.5}) {
      VectorX x1 = x0, x2 = x0;
      omp_set_num_threads(1);
      coloured.forward_sweep(rhs, x1, omega, masked ? &mask : nullptr);
      coloured.backward_sweep(rhs, x1, omega, masked ? &mask : nullptr);
      omp_set_num_threads(2);
      coloured.forward_sweep(rhs, x2, omega, masked ? &mask : nullptr);
      coloured.backward_sweep(rhs, x2, omega, masked ? &mask : nullptr);
      CHECK(x1 == x2);  // bitwise: each row is written by one thread from other colours' values

      VectorX xs = perm * x0;
      const VectorX prhs = perm * rhs;
      serial.forward_sweep(prhs, xs, omega, masked ? &pmask : nullptr);
      serial.backward_sweep(prhs, xs, omega, masked ? &pmask : nullptr);
      const VectorX back = perm.transpose() * xs;
      CHECK((back - x1).lpNorm<Eigen::Infinity>() <= 1e-13 * x1.lpNorm<Eigen::Infinity>());
      // the sweep did something
      CHECK((x1 - x0).norm() > 0.1 * x0.norm());
    }
  omp_set_num_threads(saved);
}

TEST_CASE("SSOR-PCG on the coloured operator converges with a symmetric preconditioner", "[unit]") {
  // SSOR in the colour order is symmetric (forward then reversed): PCG converges as on the
  // plain operator, and z^T M w = w^T M z for the preconditioner
  const SparseMatrix a = laplacian(30);
  ColouredSparseOperator coloured(a, welsh_powell(matrix_adjacency(a)));
  std::mt19937 rng(29);
  const VectorX r1 = random_vec(a.rows(), rng), r2 = random_vec(a.rows(), rng);
  VectorX z1, z2;
  ssor_precondition(coloured, r1, z1, 1.2);
  ssor_precondition(coloured, r2, z2, 1.2);
  CHECK(std::abs(r2.dot(z1) - r1.dot(z2)) <= 1e-12 * std::abs(r1.dot(z2)));
  PcgSettings s;
  s.tolerance = 1e-10;
  VectorX x = VectorX::Zero(a.rows());
  const PcgResult r = pcg_solve(coloured, r1, x, s);
  CHECK(r.converged);
  VectorX ax;
  coloured.apply(x, ax);
  CHECK((ax - r1).lpNorm<Eigen::Infinity>() <= 1e-9);
}

TEST_CASE("stored zeros do not couple rows: accepted by the colouring check, ignored by the sweeps",
          "[unit]") {
  // a 5-point Laplacian plus explicitly stored zeros between every row and the row two to the
  // right (same red-black colour): the same colouring stays valid and the sweeps are unchanged
  const int m = 40, n = m * m;
  const SparseMatrix a = laplacian(m);
  std::vector<Triplet> t;
  for (int k = 0; k < a.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(a, k); it; ++it) t.emplace_back(it.row(), it.col(), it.value());
  for (int k = 0; k + 2 < n; ++k) {
    t.emplace_back(k, k + 2, 0.0);
    t.emplace_back(k + 2, k, 0.0);
  }
  SparseMatrix with_zeros(n, n);
  with_zeros.setFromTriplets(t.begin(), t.end());
  REQUIRE(with_zeros.nonZeros() > a.nonZeros());
  const Colouring colours = welsh_powell(matrix_adjacency(a));
  ColouredSparseOperator plain(a, colours), padded(with_zeros, colours);
  std::mt19937 rng(37);
  const VectorX rhs = random_vec(n, rng);
  VectorX x1 = random_vec(n, rng), x2 = x1;
  plain.forward_sweep(rhs, x1, 1.2);
  plain.backward_sweep(rhs, x1, 1.2);
  padded.forward_sweep(rhs, x2, 1.2);
  padded.backward_sweep(rhs, x2, 1.2);
  CHECK(x1 == x2);
}
