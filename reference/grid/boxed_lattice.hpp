#pragma once
/// \file boxed_lattice.hpp
/// Values on the points of a sample lattice stored over an inclusive box of it, one background
/// value everywhere else (issue 20, branch band19: the liquid level set was a lattice-sized
/// vector, 541 MB at the paper's 256x128x256 grid, filled with its background and first touched
/// by the kernel every step, for a liquid in a part of the box).
///
/// LatticeValues is the read-only view the level-set readers take (volume_fractions.hpp): the
/// value of lattice point c is data[c . stride - shift], with the strides of the stored box and
/// shift = lo . stride, so a reader that walks the points with strides reads a boxed store and
/// a whole-lattice vector (stride = the lattice's, shift 0) with the same index arithmetic. A
/// view holds only the stored box: its readers read inside it (their callers promise it; the
/// simulation checks the boxes it hands them, require_stored in sim/simulation.cpp).

#include <algorithm>
#include <cmath>

#include "reference/core/common.hpp"
#include "reference/core/parallel.hpp"
#include "reference/grid/box_rows.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

/// Read-only view of lattice values (see the file comment).
template <int Dim>
struct LatticeValues {
  const double* data = nullptr;
  long size = 0;  ///< entries stored
  VecI<Dim> stride = VecI<Dim>::Zero();
  int shift = 0;
  /// The stored entry of the point with c . stride = i.
  double operator[](int i) const { return data[i - shift]; }
  int index(const VecI<Dim>& c) const { return c.dot(stride); }
};

/// The view of a whole-lattice vector (phi[lattice.index(c)]).
template <int Dim>
LatticeValues<Dim> whole_lattice_values(const SampleLattice<Dim>& lattice, const VectorX& phi) {
  LatticeValues<Dim> v;
  v.data = phi.data();
  v.size = static_cast<long>(phi.size());
  v.stride[0] = 1;
  for (int a = 1; a < Dim; ++a) v.stride[a] = v.stride[a - 1] * lattice.dims[a - 1];
  return v;
}

/// Lattice values kept over the inclusive box [lo, hi] (x fastest in `values`), `background` at
/// every other point of a lattice of `dims` points per axis. `made` is false after release().
template <int Dim>
struct BoxedLattice {
  VecI<Dim> dims = VecI<Dim>::Zero();
  VecI<Dim> lo = VecI<Dim>::Zero(), hi = -VecI<Dim>::Ones();
  VecI<Dim> stride = VecI<Dim>::Zero();
  double background = 0.0;
  VectorX values;
  bool made = false;

  bool box_empty() const { return (lo.array() > hi.array()).any(); }
  /// Whether the box is the whole lattice (then `values` is the whole-lattice vector).
  bool whole() const {
    return (lo.array() == 0).all() && (hi.array() == dims.array() - 1).all();
  }
  /// The box [lo, hi] (clamped to the lattice; may be empty) with its entries unset.
  void set_box(const VecI<Dim>& lattice_dims, const VecI<Dim>& box_lo, const VecI<Dim>& box_hi,
               double background_value) {
    dims = lattice_dims;
    lo = box_lo.cwiseMax(VecI<Dim>::Zero());
    hi = box_hi.cwiseMin(dims - VecI<Dim>::Ones());
    if (box_empty()) {
      lo = VecI<Dim>::Zero();
      hi = -VecI<Dim>::Ones();
    }
    background = background_value;
    const VecI<Dim> ext = box_empty() ? VecI<Dim>::Zero() : (hi - lo + VecI<Dim>::Ones()).eval();
    stride[0] = 1;
    for (int a = 1; a < Dim; ++a) stride[a] = stride[a - 1] * ext[a - 1];
    const Eigen::Index n = box_empty() ? 0 : static_cast<Eigen::Index>(ext.prod());
    if (values.size() != n) values.resize(n);  // Eigen keeps the buffer when the size is kept
    made = true;
  }
  /// Whether point c lies in the box; whether the box [a, b] lies in it (an empty [a, b] does).
  bool holds(const VecI<Dim>& c) const {
    return (c.array() >= lo.array()).all() && (c.array() <= hi.array()).all();
  }
  bool holds_box(const VecI<Dim>& a, const VecI<Dim>& b) const {
    return (a.array() > b.array()).any() || (holds(a) && holds(b));
  }
  /// The entry of point c in `values` (c in the box).
  int entry(const VecI<Dim>& c) const { return (c - lo).dot(stride); }
  double at(const VecI<Dim>& c) const { return holds(c) ? values[entry(c)] : background; }
  /// The value of lattice point k (lattice_index numbering).
  double operator()(int k) const { return at(lattice_coord<Dim>(k, dims)); }
  LatticeValues<Dim> view() const {
    LatticeValues<Dim> v;
    v.data = values.data();
    v.size = static_cast<long>(values.size());
    v.stride = stride;
    v.shift = box_empty() ? 0 : lo.dot(stride);
    return v;
  }
  /// Every lattice point's value, x fastest (the render, tests); empty when not made.
  VectorX materialise() const {
    if (!made) return VectorX();
    if (whole()) return values;
    VectorX out = VectorX::Constant(dims.prod(), background);
    if (box_empty()) return out;
    // the box's rows along x copied into the lattice's
    const BoxRows<Dim> box(dims, lo, hi);
    for (int q = 0; q < box.rows(); ++q)
      std::copy_n(values.data() + box.box_first(q), box.nx, out.data() + box.first(q));
    return out;
  }
  /// The storage back to the heap.
  void release() {
    values = VectorX();
    lo = VecI<Dim>::Zero();
    hi = -VecI<Dim>::Ones();
    stride = VecI<Dim>::Zero();
    made = false;
  }
};

}  // namespace monolith
