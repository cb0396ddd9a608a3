#pragma once
/// \file sparse_helpers.hpp
/// Small sparse test matrices shared by tests and benchmarks.

#include <cstring>
#include <vector>

#include <Eigen/SparseCore>

#include "reference/core/common.hpp"

namespace monolith::testing {

/// True when a and b have the same pattern and every value the same bits (memcmp: -0 differs
/// from +0, a NaN equals itself), for checks that a product or an assembly is bitwise another's.
inline bool same_sparse_bits(const SparseMatrix& a, const SparseMatrix& b) {
  if (a.rows() != b.rows() || a.cols() != b.cols() || a.nonZeros() != b.nonZeros()) return false;
  for (int i = 0; i <= a.rows(); ++i)
    if (a.outerIndexPtr()[i] != b.outerIndexPtr()[i]) return false;
  for (int e = 0; e < a.nonZeros(); ++e)
    if (a.innerIndexPtr()[e] != b.innerIndexPtr()[e] ||
        std::memcmp(a.valuePtr() + e, b.valuePtr() + e, sizeof(double)) != 0)
      return false;
  return true;
}

/// The 5-point matrix on m x m nodes (node (i, j) is row i + m j): -1 between grid neighbours,
/// diagonal 4 + extra[r] in row r (extra > 0: symmetric positive definite; a small constant
/// extra gives a condition number of about m^2).
inline SparseMatrix five_point_matrix(int m, const VectorX& extra) {
  std::vector<Eigen::Triplet<double>> t;
  auto id = [m](int i, int j) { return i + m * j; };
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i) {
      t.emplace_back(id(i, j), id(i, j), 4.0 + extra[id(i, j)]);
      if (i > 0) t.emplace_back(id(i, j), id(i - 1, j), -1.0);
      if (i < m - 1) t.emplace_back(id(i, j), id(i + 1, j), -1.0);
      if (j > 0) t.emplace_back(id(i, j), id(i, j - 1), -1.0);
      if (j < m - 1) t.emplace_back(id(i, j), id(i, j + 1), -1.0);
    }
  SparseMatrix a(m * m, m * m);
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

/// The 7-point matrix on m^3 nodes: -1 between grid neighbours, diagonal
/// `diagonal + ramp * (r % 7)` in row r (6.5 and 0: a shifted Laplacian, symmetric positive
/// definite; a small ramp makes rows differ so that a wrong ordering shows in the last bits).
inline SparseMatrix seven_point_matrix(int m, double diagonal = 6.5, double ramp = 0.0) {
  std::vector<Eigen::Triplet<double>> t;
  auto id = [m](int i, int j, int k) { return (k * m + j) * m + i; };
  for (int k = 0; k < m; ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const int r = id(i, j, k);
        t.emplace_back(r, r, diagonal + ramp * (r % 7));
        if (i > 0) t.emplace_back(r, id(i - 1, j, k), -1.0), t.emplace_back(id(i - 1, j, k), r, -1.0);
        if (j > 0) t.emplace_back(r, id(i, j - 1, k), -1.0), t.emplace_back(id(i, j - 1, k), r, -1.0);
        if (k > 0) t.emplace_back(r, id(i, j, k - 1), -1.0), t.emplace_back(id(i, j, k - 1), r, -1.0);
      }
  SparseMatrix a(m * m * m, m * m * m);
  a.setFromTriplets(t.begin(), t.end());
  return a;
}

}  // namespace monolith::testing
