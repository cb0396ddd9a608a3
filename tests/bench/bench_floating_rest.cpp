// The floating box of slow_still_water.cpp (2D, 64^2, PC-unified, box 0.1 x 0.05 of density ratio
// 0.5 placed at Archimedes' draft in water 0.5 deep), frame by frame: its offset from Archimedes'
// height (in dx) and its vertical velocity, to tell a drift from an oscillation about the
// equilibrium and to read the oscillation's period and amplitude.
//
//   bench_floating_rest [--frames N]
//
// A measurement program, not a test: it asserts nothing. docs/particles.md ("Still water").
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "tests/support/coupled_validation.hpp"

using namespace monolith;
using namespace monolith::validation;

int main(int argc, char** argv) {
  int frames = 500;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--frames" && i + 1 < argc) {
      frames = std::atoi(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: bench_floating_rest [--frames N]\n");
      return 2;
    }
  }
  const int n = 64;
  const double dx = 1.0 / n;
  const FloatBody body = FloatBody::box(2, 0.1, 0.05, 0.5);
  nlohmann::json j = base_scene(2, {1.0, 1.0}, n, "PC-unified", 50);
  j["liquids"].push_back(pool(2, 0.5));
  j["bodies"].push_back({{"name", "floater"},
                         {"density", body.s * kRho},
                         {"shape", body.shape(body.centre_at(0.5))}});
  const std::vector<FrameStats> s = run_frames(j, frames);
  std::printf("%6s %8s %12s %12s %12s\n", "frame", "t", "offset (dx)", "v_y (m/s)", "|v| (m/s)");
  for (std::size_t f = 1; f < s.size(); ++f) {
    const double predicted = body.centre_at(s[f].liquid_volume + body.s * body.volume());
    double v2 = 0.0;
    for (double c : s[f].bodies[0].velocity) v2 += c * c;
    std::printf("%6zu %8.2f %12.5f %12.3e %12.3e\n", f, s[f].time,
                (s[f].bodies[0].position[1] - predicted) / dx, s[f].bodies[0].velocity[1],
                std::sqrt(v2));
  }
  return 0;
}
