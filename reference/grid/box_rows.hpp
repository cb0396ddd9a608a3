#pragma once
/// \file box_rows.hpp
/// The points of an inclusive box of a lattice walked as rows along axis 0 (issue 20, branch
/// band20). Passes restricted to a box (docs/derivations.md, "Passes restricted to boxes") visit
/// it row by row: a row is nx consecutive points in the lattice's numbering (x fastest), so the
/// inner loop runs over contiguous memory and only the row's first point needs a coordinate. The
/// same walk served the face boxes of the simulation (FaceRows), the boxed level set's copy into
/// the whole lattice (BoxedLattice::materialise), the in-place overwrite of the level set
/// (overwrite_in_box) and the viscosity splat's copy of its box (sample_viscosity_into); this is
/// that walk once.
///
/// Row r (0 <= r < rows()) starts at the point start(r) = lo + (0, r_1, ..., r_{Dim-1}), the
/// rows numbered with axis 1 fastest (lattice_coord of r over the box's extents with axis 0
/// taken as 1), so increasing r visits the box's points in the lattice's index order. first(r)
/// is that point's index in the lattice, box_first(r) = r nx its index in the box's own
/// numbering (the box's points, x fastest).

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

template <int Dim>
struct BoxRows {
  VecI<Dim> lo = VecI<Dim>::Zero();
  VecI<Dim> dims = VecI<Dim>::Zero();      ///< the lattice's points per axis
  VecI<Dim> row_dims = VecI<Dim>::Zero();  ///< the box's extents with axis 0 taken as 1
  int nx = 0;     ///< points per row (the box's extent along axis 0)
  int count = 0;  ///< rows (0 when the box is empty)

  BoxRows() = default;
  /// The rows of the inclusive box [box_lo, box_hi] of a lattice of `lattice_dims` points per
  /// axis (the box must lie in the lattice); no rows when it is empty (box_lo > box_hi on some
  /// axis).
  BoxRows(const VecI<Dim>& lattice_dims, const VecI<Dim>& box_lo, const VecI<Dim>& box_hi)
      : lo(box_lo), dims(lattice_dims) {
    if ((box_lo.array() > box_hi.array()).any()) return;
    row_dims = box_hi - box_lo + VecI<Dim>::Ones();
    nx = row_dims[0];
    row_dims[0] = 1;
    count = row_dims.prod();
  }
  int rows() const { return count; }
  /// The coordinate of row r's first point.
  VecI<Dim> start(int r) const { return lo + lattice_coord<Dim>(r, row_dims); }
  /// Its index in the lattice.
  int first(int r) const { return lattice_index<Dim>(start(r), dims); }
  /// Its index in the box's own numbering.
  int box_first(int r) const { return r * nx; }
};

}  // namespace monolith
