// Rest is rest for 10 s, sloshing without energy gain, a floating box at its draft
// (docs/particles.md, "Still water"; docs/validation.md, "Added in the second plan"). The short
// versions run in the default suite (test_still_water.cpp).
#include <catch2/catch.hpp>

#include "tests/support/coupled_validation.hpp"
#include "tests/support/still_water.hpp"

using namespace monolith;
using namespace monolith::still_water;

namespace {

void check_rest(int dim, int cells, const std::string& backend) {
  const RestResult r = run_rest(dim, cells, 10.0, backend);
  INFO(dim << "D " << cells << " cells, " << backend << ": max kinetic energy " << r.max_kinetic
           << " J (bound " << 1e-5 * mgh() << "), probe speed in the last 5 s "
           << r.max_probe_speed << " m/s, volume drift " << r.max_drift);
  CHECK(r.converged);
  CHECK(r.max_kinetic < 1e-5 * mgh());
  CHECK(r.max_probe_speed < 5e-3);
  CHECK(r.max_drift < 5e-3);
}

}  // namespace

TEST_CASE("still water stays still for 10 s (2D, 64^2), both back ends", "[validation][slow]") {
  check_rest(2, 64, "matrixfree");
  check_rest(2, 64, "explicit");
}

TEST_CASE("still water stays still for 10 s (3D, 32^3)", "[validation][slow]") {
  check_rest(3, 32, "matrixfree");
}

TEST_CASE("a sloshing tank never gains energy and ends below its start (10 s)",
          "[validation][slow]") {
  for (int dim : {2, 3}) {
    const SloshResult r = run_slosh(dim, dim == 2 ? 64 : 24, 10.0, "matrixfree", 0.1);
    INFO(dim << "D: available energy " << r.available << " J, largest rise " << r.max_rise
             << ", change at the end " << r.end_change);
    CHECK(r.converged);
    CHECK(r.max_rise <= 0.02 * r.available);
    CHECK(r.end_change < 0.0);
  }
}

TEST_CASE("a floating box placed at its Archimedes draft stays there for 10 s (2D)",
          "[validation][slow]") {
  using namespace monolith::validation;
  const int n = 64;
  const double dx = 1.0 / n;
  const FloatBody body = FloatBody::box(2, 0.1, 0.05, 0.5);
  nlohmann::json j = base_scene(2, {1.0, 1.0}, n, "PC-unified", 50);
  j["liquids"].push_back(validation::pool(2, 0.5));
  // the water is seeded around the body (none inside it), so the surface stays at 0.5
  j["bodies"].push_back({{"name", "floater"},
                         {"density", body.s * validation::kRho},
                         {"shape", body.shape(body.centre_at(0.5))}});
  // the pool and the box start at rest: settled (particles.settle_steps, docs/particles.md "A
  // settled start"), so the run starts from the discrete equilibrium and not from the jittered
  // seeding's, whose settling the inviscid APIC water kept as a sway of the box (4.6 mm/s)
  j["particles"]["settle_steps"] = 100;
  const std::vector<FrameStats> s = run_frames(j, 500);
  double worst_offset = 0.0, worst_speed = 0.0;
  bool converged = true;
  for (std::size_t f = 1; f < s.size(); ++f) {
    converged = converged && s[f].solver.converged;
    const double predicted = body.centre_at(s[f].liquid_volume + body.s * body.volume());
    worst_offset = std::max(worst_offset, std::abs(s[f].bodies[0].position[1] - predicted));
    double v2 = 0.0;
    for (double c : s[f].bodies[0].velocity) v2 += c * c;
    worst_speed = std::max(worst_speed, std::sqrt(v2));
  }
  INFO("largest offset from Archimedes' height " << worst_offset / dx << " dx, largest speed "
                                                 << worst_speed << " m/s");
  CHECK(converged);
  CHECK(worst_offset < 0.05 * dx);
  CHECK(worst_speed < 1e-3);
}
