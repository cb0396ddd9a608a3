#pragma once
/// \file common.hpp
/// Basic types shared by the whole library. Everything numerical is templated on the spatial
/// dimension `Dim` (2 or 3) and explicitly instantiated for both in the .cpp files.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <cstdint>
#include <vector>

namespace monolith {

using Real = double;

template <int Dim>
using Vec = Eigen::Matrix<double, Dim, 1>;
template <int Dim>
using VecI = Eigen::Matrix<int, Dim, 1>;
template <int Dim>
using Mat = Eigen::Matrix<double, Dim, Dim>;
template <int Dim>
using Box = Eigen::AlignedBox<double, Dim>;

/// A dense vector over grid DOFs (cells, faces, later stress DOFs), indexed by the DOF numbering
/// of MacGrid.
using VectorX = Eigen::VectorXd;

/// The sparse matrix type of the explicit (reference) back end. Row-major so that y = A x
/// parallelises over rows; convert to column-major for CHOLMOD.
using SparseMatrix = Eigen::SparseMatrix<double, Eigen::RowMajor, int>;
using Triplet = Eigen::Triplet<double, int>;

/// 1 / v for v > 0, else 0: the entries of the diagonal inverses (W_L^u)^-1, P^-1 and N^-1 of
/// eq. (8), which are zero where the weight, density or viscosity is (those rows carry nothing).
inline double reciprocal_or_zero(double v) { return v > 0.0 ? 1.0 / v : 0.0; }

/// The n x n diagonal sparse matrix diag(d) (n = d.size()), for the named diagonal factors of
/// the explicit systems.
inline SparseMatrix sparse_diagonal(const VectorX& d) {
  SparseMatrix m(d.size(), d.size());
  std::vector<Triplet> t;
  t.reserve(d.size());
  for (int i = 0; i < d.size(); ++i) t.emplace_back(i, i, d[i]);
  m.setFromTriplets(t.begin(), t.end());
  return m;
}

/// Unit vector along `axis`.
template <int Dim>
inline VecI<Dim> unit_offset(int axis) {
  VecI<Dim> e = VecI<Dim>::Zero();
  e[axis] = 1;
  return e;
}

}  // namespace monolith
