// Validation against experiment: the surge front of a collapsing water column, Martin & Moyce
// (1952), "Part IV. An experimental study of the collapse of liquid columns on a rigid horizontal
// plane", Phil. Trans. R. Soc. Lond. A 244, 312-324, Fig. 3, column of width a and height 2a
// (n^2 = 2). Dimensionless front Z = z/a against T = t sqrt(2 g / a).
//
// Known and expected: an inviscid free-slip simulation with an instantaneous release runs ahead of
// the experiment, whose gate takes a finite time to lift (the origin of the experimental time axis
// is uncertain by that much) and whose floor has friction; the lead builds up early and the front
// speed dZ/dT later agrees closely (docs/validation.md tabulates the unshifted errors, 6% to 26%).
// The test therefore checks (1) the front speed over T in [1.6, 2.95] within 10% of the
// experiment's, and (2) that after the single time shift dT in [0, 0.5] (the simulation's start
// leading the experiment's) that fits best, every data point lies within 10%.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <utility>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

/// Martin & Moyce (1952) Fig. 3, n^2 = 2: (T, Z) for the columns a = 1.125 in and a = 2.25 in,
/// restricted to Z < 3.8 (our tank is 4a long).
const std::vector<std::pair<double, double>> kMartinMoyce = {
    {0.832, 1.217}, {0.849, 1.245}, {1.212, 1.443}, {1.219, 1.474}, {1.602, 1.884},
    {1.997, 2.292}, {2.283, 2.689}, {2.547, 2.995}, {2.950, 3.728}};

struct FrontHistory {
  std::vector<double> T, Z;
  double initial_volume = 0.0, final_volume = 0.0;
  double Z_at(double t) const {
    for (size_t i = 0; i + 1 < T.size(); ++i)
      if (T[i] <= t && t <= T[i + 1]) {
        const double f = (t - T[i]) / (T[i + 1] - T[i]);
        return (1 - f) * Z[i] + f * Z[i + 1];
      }
    return NAN;
  }
};

/// Runs the built-in dam-break-2d scene at the given resolution, 100 frames per second, until
/// T = 3.3 and records the front (the largest particle x) after every frame.
FrontHistory run_dam_break(int nx, int ny) {
  const double a = 0.2, g = 9.81;
  const double T_of_t = std::sqrt(2.0 * g / a);
  SceneDesc scene = load_scene(
      "dam-break-2d", {"time.fps=100", "time.frames=34",
                       "domain.cells=[" + std::to_string(nx) + "," + std::to_string(ny) + "]"});
  auto sim = make_simulation(scene);
  FrontHistory h;
  FrameStats s = sim->current_stats();
  h.initial_volume = s.liquid_volume;
  h.T.push_back(0.0);
  h.Z.push_back(s.liquid_bounds_upper.at(0) / a);
  for (int f = 0; f < scene.time.frames; ++f) {
    s = sim->advance_frame();
    h.T.push_back(s.time * T_of_t);
    h.Z.push_back(s.liquid_bounds_upper.at(0) / a);
  }
  h.final_volume = s.liquid_volume;
  return h;
}

}  // namespace

TEST_CASE("dam break surge front follows Martin & Moyce (1952)", "[validation][dam-break]") {
  const FrontHistory h = run_dam_break(64, 32);
  // largest relative error of the simulated front at the data times shifted back by dT
  auto worst_error = [&](double dT) {
    double worst = 0.0;
    for (const auto& [T, Z] : kMartinMoyce) worst = std::max(worst, std::abs(h.Z_at(T - dT) - Z) / Z);
    return worst;
  };
  for (const auto& [T, Z] : kMartinMoyce) {
    const double z_sim = h.Z_at(T);
    REQUIRE(std::isfinite(z_sim));
    std::cout << "Martin & Moyce: T = " << T << "  Z_exp = " << Z << "  Z_sim = " << z_sim
              << "  relative error " << (z_sim - Z) / Z << "\n";
  }
  const double max_rel = worst_error(0.0);
  double best_shift = 0.0, best_error = max_rel;
  for (double dT = 0.0; dT <= 0.5 + 1e-12; dT += 0.01)
    if (worst_error(dT) < best_error) best_error = worst_error(dT), best_shift = dT;
  std::cout << "best time shift dT = " << best_shift << ": largest relative error " << best_error
            << "\n";
  // front speed over the later stage, where gate and start-up effects have died out
  const double speed_exp = (3.728 - 1.884) / (2.950 - 1.602);
  const double speed_sim = (h.Z_at(2.950) - h.Z_at(1.602)) / (2.950 - 1.602);
  std::cout << "front speed dZ/dT: experiment " << speed_exp << ", simulation " << speed_sim
            << "; largest pointwise relative error " << max_rel << "\n";
  CHECK(std::abs(speed_sim - speed_exp) / speed_exp < 0.10);
  CHECK(best_error < 0.10);
  // the front starts at Z = 1 and never moves backwards while it travels; once it is within a
  // cell of the far wall (Z = 4, after the data) it stays at the wall, within 0.05 dx. (There the
  // largest particle x is a particle of the run-up against the wall: the advection's clamp leaves
  // it 0.01 dx from the wall and line 15 moves the clamped layer off the wall by 0.001-0.004 dx,
  // more or less from frame to frame, with every wall rule: not a move of the surge. Measured
  // with item 18, docs/particles.md "The landing frame of a viscous pour, second form": 0.0142,
  // 0.0114, 0.0121 dx in frames 32-34; before it 0.0137, 0.0114, 0.0100 dx.)
  CHECK(h.Z.front() == Approx(1.0).margin(0.02));
  const double dx_over_a = 4.0 / 64;  // the tank is 4a long, 64 cells
  bool at_wall = false;
  for (size_t i = 1; i < h.Z.size(); ++i) {
    INFO("frame " << i << ": Z " << h.Z[i] << ", before " << h.Z[i - 1]);
    if (at_wall)
      CHECK(4.0 - h.Z[i] <= 0.05 * dx_over_a);
    else
      CHECK(h.Z[i] >= h.Z[i - 1] - 1e-9);
    at_wall = at_wall || 4.0 - h.Z[i] < dx_over_a;
  }
  CHECK(at_wall);  // (the run reaches the wall: the second check ran)
}
