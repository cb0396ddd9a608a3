#pragma once
/// \file face_neighbour.hpp
/// A face's same-axis neighbour some faces away along one lattice axis, as the velocity
/// extrapolations walk them (particles' extrapolate_velocity_in, the air faces' first layer in
/// sim/air_velocity.cpp): one rule for the wrap on periodic axes and the stop at the others.

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

/// The face normal to `axis` that lies `step` faces from face `self` (at `coord` in the axis's
/// face lattice of `dims` = grid.face_dims(axis) faces per axis) along lattice axis b: wrapped on
/// a periodic axis b, -1 past the lattice's end on a non-periodic one, and -1 where it would be
/// `self` again (a periodic axis shorter than |step| + 1 faces).
template <int Dim>
inline int face_along(const MacGrid<Dim>& grid, int axis, const VecI<Dim>& dims,
                      const VecI<Dim>& coord, int self, int b, int step) {
  VecI<Dim> c = coord;
  c[b] += step;
  if (grid.periodic(b)) {
    c[b] = ((c[b] % dims[b]) + dims[b]) % dims[b];
  } else if (c[b] < 0 || c[b] >= dims[b]) {
    return -1;
  }
  const int g = grid.face_index(axis, c);
  return g == self ? -1 : g;
}

}  // namespace monolith
