// The minimum-image rule of periodic domains (periodic_image_shift, reference/core/periodic_image.hpp),
// which the rigid bodies' nearest image, the coupling's lever arm and line 15's moves share:
// the shortest displacement between images on every periodic axis, the displacement itself on
// the others, and the displacement bit for bit where it is already the shortest.
#include <catch2/catch.hpp>

#include <cmath>
#include <random>

#include "reference/core/periodic_image.hpp"

using namespace monolith;

TEST_CASE("periodic_image_shift takes whole periods off to the shortest image", "[unit]") {
  const Vec<3> period(1.0, 0.0, 0.75);  // the y axis is not periodic
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  for (int trial = 0; trial < 2000; ++trial) {
    const Vec<3> d(u(rng), u(rng), u(rng));
    const Vec<3> shift = periodic_image_shift<3>(d, period);
    const Vec<3> r = d - shift;
    // shortest: at most half a period on the periodic axes
    CHECK(std::abs(r.x()) <= 0.5 * period.x() + 1e-15);
    CHECK(std::abs(r.z()) <= 0.5 * period.z() + 1e-15);
    // whole periods only
    CHECK(std::abs(shift.x() / period.x() - std::round(shift.x() / period.x())) < 1e-12);
    CHECK(std::abs(shift.z() / period.z() - std::round(shift.z() / period.z())) < 1e-12);
    // the non-periodic axis keeps its displacement, bit for bit
    CHECK(shift.y() == 0.0);
    CHECK(r.y() == d.y());
  }
  // already the shortest: the same bits (a move that did not wrap is exactly to - from)
  const Vec<2> p2(2.0, 3.0);
  const Vec<2> small(0.999, -1.499);
  CHECK((small - periodic_image_shift<2>(small, p2)) == small);
  // one wrap: a step of 0.1 across the face of a period-2 axis reads as 0.1, not -1.9
  const Vec<2> wrapped(-1.9, 2.95);
  const Vec<2> r = wrapped - periodic_image_shift<2>(wrapped, p2);
  CHECK(r.x() == Approx(0.1).margin(1e-15));
  CHECK(r.y() == Approx(-0.05).margin(1e-15));
  // no periodic axis: nothing is taken off
  CHECK(periodic_image_shift<2>(wrapped, Vec<2>::Zero()) == Vec<2>::Zero());
}
