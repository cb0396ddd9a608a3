#pragma once
/// \file boxed_union_phi.hpp
/// The solids' union level set on the half lattice kept only in a box around the bodies (issue
/// 20: the lattice-sized union, 541 MB at the paper's 256x128x256 grid, was alive beside the
/// liquid level set at a coupled step's memory peak).
///
/// solid_weights (reference/coupling) writes the union of bounded bodies' lattice phi, where
/// each body's value farther than `far` from its bounds box is the distance to that box plus the
/// shrink zeta (a positive lower bound of the true distance; body_phi_on_lattice). Outside a box
/// around every body's bounds (grown by `far` and two lattice points) no body is evaluated, so
/// the union there is min over the bodies of that closed form: this class stores the union's
/// values in the box and evaluates the closed form outside it, with the same operations in the
/// same order as body_phi_on_lattice (per-axis offset tables; the squares summed in the order of
/// Eigen's norm() of the offset vector; then + zeta), so every value has the dense vector's bits.

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

/// The closed form's tables (body_phi_on_lattice's far value): per axis a and lattice
/// coordinate c, component a of p - clamp(p, box) for the lattice point p = (c, ..., c).
template <int Dim>
void box_offset_table(const SampleLattice<Dim>& lattice, const Box<Dim>& box,
                      std::array<std::vector<double>, Dim>& offset) {
  for (int a = 0; a < Dim; ++a) {
    offset[a].resize(lattice.dims[a]);
    for (int c = 0; c < lattice.dims[a]; ++c) {
      const Vec<Dim> p = lattice.position(VecI<Dim>::Constant(c));
      offset[a][c] = (p - p.cwiseMax(box.min()).cwiseMin(box.max()))[a];
    }
  }
}

/// The distance of lattice point c from the box of `offset` (box_offset_table):
/// sqrt((t_0^2 + t_1^2) + t_2^2), summed in the order of Eigen's norm() of the offset vector,
/// as body_phi_on_lattice sums it.
template <int Dim>
double box_offset_distance(const std::array<std::vector<double>, Dim>& offset,
                           const VecI<Dim>& c) {
  double sum = offset[0][c[0]] * offset[0][c[0]];
  for (int a = 1; a < Dim; ++a) {
    const double square = offset[a][c[a]] * offset[a][c[a]];
    sum += square;
  }
  return std::sqrt(sum);
}

/// The inclusive box of lattice points within `far` of `bounds`, grown by `points` lattice
/// points on every side and clamped to the lattice; false when it holds no point (then lo > hi
/// on some axis). With two points (BoxedUnionPhi, PartsUnionPhi: one for the rounding of the
/// coordinates, one so that a point outside has an offset beyond far + spacing / 2 on some axis,
/// which body_phi_on_lattice tests with rounded sums) body_phi_on_lattice writes the closed form
/// everywhere outside it.
template <int Dim>
bool far_point_box(const SampleLattice<Dim>& lattice, const Box<Dim>& bounds, double far,
                   int points, VecI<Dim>& lo, VecI<Dim>& hi) {
  const double grow = static_cast<double>(points);
  bool any = true;
  for (int a = 0; a < Dim; ++a) {
    const double from = (bounds.min()[a] - far - lattice.origin[a]) / lattice.spacing;
    const double to = (bounds.max()[a] + far - lattice.origin[a]) / lattice.spacing;
    const double top = static_cast<double>(lattice.dims[a] - 1);
    lo[a] = static_cast<int>(std::clamp(std::floor(from) - grow, 0.0, top + 1.0));
    hi[a] = static_cast<int>(std::clamp(std::ceil(to) + grow, -1.0, top));
    any = any && lo[a] <= hi[a];
  }
  return any;
}

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


/// The solids' union level set on the half lattice kept per part instead of as one
/// lattice-sized vector (issue 20: Fig. 17's static basin and two moving shells). solid_weights
/// (reference/coupling) writes the union as the first body's lattice phi, then the minimum with
/// every further body's, each body's phi being its shape's distance (+ zeta) within `far` of its
/// bounds and the distance to the bounds box (+ zeta) farther out. Here a part is either
///  - dense: a lattice-sized vector of its values (a body that never moves: computed once and
///    kept by the caller, not copied), or
///  - boxed: its values in a box of lattice points (its bounds grown by `far` and two points, as
///    in BoxedUnionPhi) and the closed form of the distance to the bounds outside it,
/// and the union's value at a point is the minimum over the parts in body order, with the same
/// operations as the dense union (std::min of the running value and the next part), so the same
/// bits. The sign alone (negative()) needs no closed form: with zeta >= 0 it is >= 0.
template <int Dim>
class PartsUnionPhi {
 public:
  /// Starts a union over `lattice` with shrink zeta (no part yet; not valid until finish()).
  void begin(const SampleLattice<Dim>& lattice, double shrink_in_metres);
  /// Appends a dense part: `phi` (lattice-sized, not copied: it must outlive the reads) whose
  /// negative points lie in the inclusive box [neg_lo, neg_hi] (lo > hi: none).
  void add_dense(const VectorX* phi, const VecI<Dim>& neg_lo, const VecI<Dim>& neg_hi);
  /// Appends a boxed part for a body with these bounds (bounded, not empty) and `far`; returns
  /// the inclusive box of lattice points it stores (lo > hi on some axis: none).
  void add_boxed(const Box<Dim>& bounds, double far, VecI<Dim>& lo, VecI<Dim>& hi);
  /// The stored values of boxed part `part` (the box's points, x fastest), to be written by the
  /// caller after add_boxed; then set_negative_box.
  VectorX& boxed_values(int part) { return parts_[part].values; }
  void set_negative_box(int part, const VecI<Dim>& neg_lo, const VecI<Dim>& neg_hi);
  /// The union is complete (at least one part).
  void finish() { valid_ = count_ > 0; }
  void clear() { valid_ = false; }
  bool valid() const { return valid_; }
  int num_parts() const { return count_; }

  /// Part `i`'s value at lattice point c (stored, or the closed form outside its box).
  double part_at(int i, const VecI<Dim>& c) const;
  /// The union's value at lattice point c / index k.
  double at(const VecI<Dim>& c) const;
  double operator()(int k) const { return at(lattice_coord<Dim>(k, dims_)); }
  /// Whether the union is < 0 at lattice point k (some part is; the closed form never is).
  bool negative(int k) const;
  /// The same at lattice point c of index k (no division for the coordinate).
  bool negative(const VecI<Dim>& c, int k) const;
  /// Boxed part `i`'s stored values and box (the box's points, x fastest), for readers that
  /// index them directly inside the box and read part_at outside it.
  const VectorX& boxed_values(int i, VecI<Dim>& lo, VecI<Dim>& hi) const {
    lo = parts_[i].lo;
    hi = parts_[i].hi;
    return parts_[i].values;
  }
  /// The inclusive box of the union's negative points (lo > hi: none).
  void negative_box(VecI<Dim>& lo, VecI<Dim>& hi) const;

  /// Part `i` is dense (a lattice-sized phi kept by the caller: a fixed body).
  bool is_dense(int i) const { return parts_[i].dense != nullptr; }
  /// Part `i`'s dense phi (nullptr for a boxed part).
  const VectorX* dense_phi(int i) const { return parts_[i].dense; }
  /// The inclusive box of part `i`'s negative points (lo > hi: none).
  void part_negative_box(int i, VecI<Dim>& lo, VecI<Dim>& hi) const {
    lo = parts_[i].neg_lo;
    hi = parts_[i].neg_hi;
  }
  /// Whether some dense part is < 0 at lattice point k (the first half of negative()).
  bool dense_negative(int k) const {
    for (int i = 0; i < count_; ++i)
      if (parts_[i].dense && (*parts_[i].dense)[k] < 0.0) return true;
    return false;
  }
  /// Whether some boxed part is < 0 at lattice point c (the second half of negative()).
  bool boxed_negative(const VecI<Dim>& c) const {
    for (int i = 0; i < count_; ++i) {
      const Part& part = parts_[i];
      if (part.dense) continue;
      if ((c.array() < part.neg_lo.array()).any() || (c.array() > part.neg_hi.array()).any())
        continue;
      if (part.values[lattice_index<Dim>(c - part.lo, part.box_dims)] < 0.0) return true;
    }
    return false;
  }

 private:
  struct Part {
    const VectorX* dense = nullptr;
    VecI<Dim> lo = VecI<Dim>::Zero(), hi = -VecI<Dim>::Ones(), box_dims = VecI<Dim>::Zero();
    VectorX values;
    std::array<std::vector<double>, Dim> offset;  ///< per axis: offset from the bounds
    VecI<Dim> neg_lo = VecI<Dim>::Zero(), neg_hi = -VecI<Dim>::Ones();
  };
  bool valid_ = false;
  SampleLattice<Dim> lattice_;
  VecI<Dim> dims_ = VecI<Dim>::Zero();
  double shrink_ = 0.0;
  std::vector<Part> parts_;  ///< kept across begin() calls (their buffers reused)
  int count_ = 0;            ///< parts of the current union (parts_ may hold more buffers)
};

}  // namespace monolith
