#pragma once
/// \file common.hpp
/// Basic types shared by the whole library. Everything numerical is templated on the spatial
/// dimension `Dim` (2 or 3) and explicitly instantiated for both in the .cpp files.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <cstdint>

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

/// Unit vector along `axis`.
template <int Dim>
inline VecI<Dim> unit_offset(int axis) {
  VecI<Dim> e = VecI<Dim>::Zero();
  e[axis] = 1;
  return e;
}

}  // namespace monolith
