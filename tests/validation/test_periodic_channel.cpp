// A channel periodic along gravity (tests/support/periodic_channel.hpp): plane Poiseuille
// start-up through the whole step. Line 15's moves (position correction and density projection)
// carry particles across the periodic face now and then; the potential energy -m g.x then jumps
// by m g L, and line 15's energy account (Line15Energy::balance) read that jump as a rise of the
// potential energy and paid it with the liquid's kinetic energy (check23, docs/validation.md "An
// independent checker's cases"): before the fix this channel lost up to 1.2 % of its kinetic
// energy in single frames while it accelerated (t = 2.45, 3.7, 3.75, 3.9, 4.0 s).
#include <catch2/catch.hpp>

#include "tests/support/periodic_channel.hpp"

using namespace monolith;
using namespace monolith::periodic_channel;

TEST_CASE("a periodic channel driven along its axis speeds up as the start-up series says (2D)",
          "[validation]") {
  // 16 cells across H = 0.5 m, eta = 20 Pa s (nu = 0.02), g = 0.1 along x, 4 s at 20 fps (3
  // steps of 1/60 s per frame). Measured after the fix: the kinetic energy never falls, the centre
  // velocity 0.14916 m/s against the series' 0.1488 (backward Euler) at t = 4 s.
  const double g = 0.1, eta = 20.0, nu = eta / kRho;
  const ChannelRun r = run(scene(2, 16, g, {{"model", "newtonian"}, {"eta", eta}}, 4.0));
  const double fall = largest_kinetic_fall(r);
  const std::size_t centre = r.y.size() / 2;
  const double u = r.u.back()[centre];
  const double expected = newtonian_startup(r.y[centre], r.time.back(), g, nu, 1.0 / 60.0);
  INFO("largest fall of the kinetic energy between frames " << fall << "; centre velocity " << u
                                                            << " m/s against " << expected);
  CHECK(r.converged);
  CHECK(fall < 1e-3);
  CHECK(std::abs(u - expected) < 0.02 * expected);
}
