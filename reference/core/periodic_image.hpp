#pragma once
/// \file periodic_image.hpp
/// The minimum-image arithmetic of periodic domain axes, written once for every layer that
/// needs it (rigid bodies, the coupling's lever arms, line 15's particle moves).

#include <cmath>

#include "reference/core/common.hpp"

namespace monolith {

/// The minimum-image rule of periodic domains, written once: on each axis with period[a] > 0 the
/// whole number of periods to take off a displacement d, so that d - shift is the shortest
/// displacement between the periodic images (|d - shift| <= period / 2); 0 on the other axes.
/// Used by the rigid bodies' nearest image (RigidBody::set_periodic), the coupling's lever arm
/// (CouplingBody::arm) and line 15's moves (Simulation::line15_move).
template <int Dim>
inline Vec<Dim> periodic_image_shift(const Vec<Dim>& d, const Vec<Dim>& period) {
  Vec<Dim> shift = Vec<Dim>::Zero();
  for (int a = 0; a < Dim; ++a)
    if (period[a] > 0.0) shift[a] = period[a] * std::round(d[a] / period[a]);
  return shift;
}

}  // namespace monolith
