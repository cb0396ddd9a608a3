#include "reference/grid/boxed_union_phi.hpp"

#include <algorithm>
#include <cmath>

#include "reference/core/parallel.hpp"

namespace monolith {

template <int Dim>
bool BoxedUnionPhi<Dim>::assign(const SampleLattice<Dim>& lattice,
                                const std::vector<Box<Dim>>& bounds, double far,
                                double shrink_in_metres, const VectorX& dense) {
  valid_ = false;
  if (bounds.empty() || dense.size() != lattice.size()) return false;
  for (const Box<Dim>& box : bounds)
    if (box.isEmpty() || !box.min().allFinite() || !box.max().allFinite()) return false;
  dims_ = lattice.dims;
  shrink_ = shrink_in_metres;
  // the offset tables of body_phi_on_lattice's closed form
  offset_.resize(bounds.size());
  for (std::size_t i = 0; i < bounds.size(); ++i) box_offset_table<Dim>(lattice, bounds[i], offset_[i]);
  // the box: every body's far_point_box
  lo_ = lattice.dims;
  hi_ = -VecI<Dim>::Ones();
  for (const Box<Dim>& box : bounds) {
    VecI<Dim> lo, hi;
    // a body far from every point: the closed form everywhere
    if (!far_point_box<Dim>(lattice, box, far, 2, lo, hi)) continue;
    lo_ = lo_.cwiseMin(lo);
    hi_ = hi_.cwiseMax(hi);
  }
  const bool any = (lo_.array() <= hi_.array()).all();
  if (!any) {
    lo_ = VecI<Dim>::Zero();
    hi_ = -VecI<Dim>::Ones();
  }
  box_dims_ = any ? VecI<Dim>(hi_ - lo_ + VecI<Dim>::Ones()) : VecI<Dim>::Zero();
  const Eigen::Index n = any ? box_dims_.prod() : 0;
  // a box of more than half the lattice (a body as large as the domain: Fig. 17's basin) would
  // save little and, while it is copied, be alive beside the dense union
  if (2 * n > lattice.size()) return false;
  // the box's values, by rows along x on several threads (each row written by one thread)
  if (values_.size() != n) values_.resize(n);
  if (any) {
    VecI<Dim> row_dims = box_dims_;
    row_dims[0] = 1;
    const int rows = row_dims.prod(), nx = box_dims_[0];
#pragma omp parallel for schedule(static) num_threads(team_threads(n))
    for (int q = 0; q < rows; ++q) {
      const VecI<Dim> c = lo_ + lattice_coord<Dim>(q, row_dims);
      std::copy_n(dense.data() + lattice.index(c), nx,
                  values_.data() + static_cast<Eigen::Index>(q) * nx);
    }
  }
  valid_ = true;
  return true;
}

template <int Dim>
double BoxedUnionPhi<Dim>::far_value(const VecI<Dim>& c) const {
  double value = 0.0;
  for (std::size_t i = 0; i < offset_.size(); ++i) {
    const double v = box_offset_distance<Dim>(offset_[i], c) + shrink_;
    // the union is the first body's values, then the minimum with each further body's
    value = i == 0 ? v : std::min(value, v);
  }
  return value;
}

template <int Dim>
double BoxedUnionPhi<Dim>::at(const VecI<Dim>& c) const {
  if ((c.array() >= lo_.array()).all() && (c.array() <= hi_.array()).all())
    return values_[lattice_index<Dim>(c - lo_, box_dims_)];
  return far_value(c);
}

template class BoxedUnionPhi<2>;
template class BoxedUnionPhi<3>;


template <int Dim>
void PartsUnionPhi<Dim>::begin(const SampleLattice<Dim>& lattice, double shrink_in_metres) {
  valid_ = false;
  lattice_ = lattice;
  dims_ = lattice.dims;
  shrink_ = shrink_in_metres;
  count_ = 0;
}

template <int Dim>
void PartsUnionPhi<Dim>::add_dense(const VectorX* phi, const VecI<Dim>& neg_lo,
                                   const VecI<Dim>& neg_hi) {
  if (count_ == static_cast<int>(parts_.size())) parts_.emplace_back();
  Part& part = parts_[count_++];
  part.dense = phi;
  part.neg_lo = neg_lo;
  part.neg_hi = neg_hi;
}

template <int Dim>
void PartsUnionPhi<Dim>::add_boxed(const Box<Dim>& bounds, double far, VecI<Dim>& lo,
                                   VecI<Dim>& hi) {
  if (count_ == static_cast<int>(parts_.size())) parts_.emplace_back();
  Part& part = parts_[count_++];
  part.dense = nullptr;
  // the closed form's tables, and the points outside of which body_phi_on_lattice writes it
  box_offset_table<Dim>(lattice_, bounds, part.offset);
  const bool any = far_point_box<Dim>(lattice_, bounds, far, 2, lo, hi);
  if (!any) {
    lo = VecI<Dim>::Zero();
    hi = -VecI<Dim>::Ones();
  }
  part.lo = lo;
  part.hi = hi;
  part.box_dims = any ? VecI<Dim>(hi - lo + VecI<Dim>::Ones()) : VecI<Dim>::Zero();
  const Eigen::Index n = any ? part.box_dims.prod() : 0;
  if (part.values.size() != n) part.values.resize(n);
  part.neg_lo = VecI<Dim>::Zero();
  part.neg_hi = -VecI<Dim>::Ones();
}

template <int Dim>
void PartsUnionPhi<Dim>::set_negative_box(int part, const VecI<Dim>& neg_lo,
                                          const VecI<Dim>& neg_hi) {
  parts_[part].neg_lo = neg_lo;
  parts_[part].neg_hi = neg_hi;
}

template <int Dim>
double PartsUnionPhi<Dim>::part_at(int i, const VecI<Dim>& c) const {
  const Part& part = parts_[i];
  if (part.dense) return (*part.dense)[lattice_index<Dim>(c, dims_)];
  if ((c.array() >= part.lo.array()).all() && (c.array() <= part.hi.array()).all())
    return part.values[lattice_index<Dim>(c - part.lo, part.box_dims)];
  return box_offset_distance<Dim>(part.offset, c) + shrink_;
}

template <int Dim>
double PartsUnionPhi<Dim>::at(const VecI<Dim>& c) const {
  // the first part's value, then the minimum with each further part's (cwiseMin's order)
  double value = part_at(0, c);
  for (int i = 1; i < count_; ++i) value = std::min(value, part_at(i, c));
  return value;
}

template <int Dim>
bool PartsUnionPhi<Dim>::negative(const VecI<Dim>& c, int k) const {
  // the dense parts by index first, then the boxed parts in their boxes of negative points
  return dense_negative(k) || boxed_negative(c);
}

template <int Dim>
bool PartsUnionPhi<Dim>::negative(int k) const {
  for (int i = 0; i < count_; ++i) {
    const Part& part = parts_[i];
    if (part.dense && (*part.dense)[k] < 0.0) return true;
  }
  VecI<Dim> c;
  bool have_c = false;
  for (int i = 0; i < count_; ++i) {
    const Part& part = parts_[i];
    if (part.dense) continue;
    if (!have_c) {
      c = lattice_coord<Dim>(k, dims_);
      have_c = true;
    }
    if ((c.array() < part.neg_lo.array()).any() || (c.array() > part.neg_hi.array()).any())
      continue;
    if (part.values[lattice_index<Dim>(c - part.lo, part.box_dims)] < 0.0) return true;
  }
  return false;
}

template <int Dim>
void PartsUnionPhi<Dim>::negative_box(VecI<Dim>& lo, VecI<Dim>& hi) const {
  lo = dims_;
  hi = -VecI<Dim>::Ones();
  for (int i = 0; i < count_; ++i) {
    const Part& part = parts_[i];
    if ((part.neg_lo.array() > part.neg_hi.array()).any()) continue;
    lo = lo.cwiseMin(part.neg_lo);
    hi = hi.cwiseMax(part.neg_hi);
  }
  if ((lo.array() > hi.array()).any()) {
    lo = VecI<Dim>::Zero();
    hi = -VecI<Dim>::Ones();
  }
}

template class PartsUnionPhi<2>;
template class PartsUnionPhi<3>;

}  // namespace monolith
