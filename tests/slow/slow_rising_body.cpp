// A light box released near the floor rises to its Archimedes draft in 3D (docs/derivations.md
// departures item 25): check25's case (docs/validation.md "A third independent check"), 24^3,
// eta = 1, 1 s. Before item 25 the box crept up at 0.065 m/s (its centre at 0.246 m after 1 s,
// the draft at 0.495 m); the short check of the default suite is test_rising_body.cpp.
#include <catch2/catch.hpp>

#include "tests/support/rising_body.hpp"

using namespace monolith;
using namespace monolith::rising_body;

TEST_CASE("A light box released near the floor rises to its draft within 1 s (3D, 24^3, eta = 1)",
          "[slow][validation][coupling]") {
  const int frames = 20;
  const Rise r = run_rise(rising_scene(3, 24, 1.0, frames), 3, frames);
  INFO("highest " << r.highest << " m, draft " << r.draft << " m, largest upward speed "
                  << r.top_speed << " m/s");
  CHECK(r.converged);
  CHECK(r.highest > r.draft - 0.5 / 24);
}
