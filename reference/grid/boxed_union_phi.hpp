#pragma once
/// \file boxed_union_phi.hpp
/// The solids' union level set on the half lattice kept only in a box around the bodies (issue
/// 20: the lattice-sized union, 541 MB at the paper's 256x128x256 grid, was alive beside the
/// liquid level set at a coupled step's memory peak).
///
/// solid_weights (reference/coupling) writes the union of bounded bodies' lattice phi, where
/// each body's value farther than `far` from its bounds box is the distance to that box plus the
/// shrink zeta (a positive lower bound of the true distance; body_phi_on_lattice). Outside a box
/// around every body's bounds (grown by `far` and one lattice point) no body is evaluated, so
/// the union there is min over the bodies of that closed form: this class stores the union's
/// values in the box and evaluates the closed form outside it, with the same operations in the
/// same order as body_phi_on_lattice (per-axis offset tables; the squares summed in the order of
/// Eigen's norm() of the offset vector; then + zeta), so every value has the dense vector's bits.

#include <array>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

template <int Dim>
class BoxedUnionPhi {
 public:
  /// Keeps the union `dense` (a lattice-sized vector as solid_weights writes it for bodies with
  /// these bounds, `far` and `shrink_in_metres`) in the box around the bodies. Returns false, and
  /// keeps nothing, when the closed form does not hold everywhere outside such a box: no body,
  /// or a body with empty or unbounded bounds (its shape is evaluated at every point), a box of
  /// more than half the lattice (bodies as large as the domain), or `dense` not lattice-sized.
  bool assign(const SampleLattice<Dim>& lattice, const std::vector<Box<Dim>>& bounds, double far,
              double shrink_in_metres, const VectorX& dense);
  /// Nothing kept (the next assign reuses the buffers).
  void clear() { valid_ = false; }
  bool valid() const { return valid_; }
  /// The union's value at lattice point k (index of the lattice given to assign).
  double operator()(int k) const { return at(lattice_coord<Dim>(k, dims_)); }
  double at(const VecI<Dim>& c) const;
  /// The closed form alone (the value outside the box): min over the bodies of the distance to
  /// the bounds plus zeta.
  double far_value(const VecI<Dim>& c) const;
  /// The inclusive box of stored points.
  const VecI<Dim>& lo() const { return lo_; }
  const VecI<Dim>& hi() const { return hi_; }
  /// Stored values (the box's points, x fastest).
  Eigen::Index stored() const { return values_.size(); }

 private:
  bool valid_ = false;
  VecI<Dim> dims_ = VecI<Dim>::Zero(), lo_ = VecI<Dim>::Zero(), hi_ = -VecI<Dim>::Ones();
  VecI<Dim> box_dims_ = VecI<Dim>::Zero();
  double shrink_ = 0.0;
  /// per body and axis: the lattice coordinate's offset from the body's bounds along that axis
  std::vector<std::array<std::vector<double>, Dim>> offset_;
  VectorX values_;
};

}  // namespace monolith
