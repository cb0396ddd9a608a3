#pragma once
/// \file air_velocity.hpp
/// The extension of u* into the air before a solve (Simulation::extrapolate_into_air): a first
/// layer that is exact for a velocity field linear in space, then neighbour averaging.

#include <array>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

/// Extends u from faces with valid[f] != 0 into the others, `layers` rings deep, and marks the
/// filled faces valid (1). The first ring (the invalid faces with a valid same-axis neighbour,
/// the same faces extrapolate_velocity's first ring fills) takes, per axis b along which it has
///  - both neighbours valid: their mean (u(-1) + u(+1)) / 2,
///  - else two valid faces in a row on one side: the linear continuation 2 u(1) - u(2),
/// the mean of those estimates over the axes that have one; a face with neither on any axis
/// takes the mean of its valid neighbours, as extrapolate_velocity does (the same value, summed
/// in the same order). Both estimates are exact for a linear field such as a rigid rotation
/// omega x r, which neighbour averaging is not (it biases a surface's air faces toward the
/// interior's velocity: a shear at the surface that D u* turns into a viscous drag, departures
/// item 22). Every estimate reads faces valid on entry only: no extrapolated value is
/// extrapolated again with a factor. The further rings are extrapolate_velocity's averaging.
/// Neighbours wrap on periodic axes. With boxes (box_lo / box_hi per axis an inclusive box of
/// face coordinates outside which every valid[f] is 0, as for extrapolate_velocity) only the
/// boxes grown by one face are searched. Each filled face is written by one thread from values
/// valid on entry: the same result for any team.
template <int Dim>
void extrapolate_air_velocity(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                              int layers, const std::array<VecI<Dim>, Dim>* box_lo = nullptr,
                              const std::array<VecI<Dim>, Dim>* box_hi = nullptr);

}  // namespace monolith
