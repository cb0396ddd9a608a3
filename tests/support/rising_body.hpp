#pragma once
/// \file rising_body.hpp
/// A light box released near the floor of a pool (test_rising_body.cpp, slow_rising_body.cpp;
/// docs/derivations.md departures item 25). The pool is 1 m wide and 0.5 m deep (the domain
/// [0, 1]^Dim, open above); the box 0.24 x 0.16 (x 0.24) of density 500 kg/m^3 (s = 1/2 of the
/// liquid's) starts at rest with its centre at y = 0.12 (2D) / 0.14 (3D), its bottom 2-3 cells
/// above the floor. Archimedes: floating, it displaces its own mass, so with the liquid's volume
/// V_L (FrameStats::liquid_volume) the surface lies at y_s = (V_L + s V_B) / A (A the pool's
/// cross-section, 1 m or 1 m^2) and the centre at y_s - s H + H / 2 (H = 0.16 its height).

#include <algorithm>
#include <cmath>

#include <catch2/catch.hpp>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

namespace monolith::rising_body {

constexpr double kRatio = 0.5;   // the box's density over the liquid's
constexpr double kHeight = 0.16;

inline nlohmann::json rising_scene(int dim, int cells, double eta, int frames) {
  using nlohmann::json;
  json j = {{"format", "monolith-scene/1"}, {"name", "rising-box"}, {"dim", dim}};
  const json lower = dim == 2 ? json{0, 0} : json{0, 0, 0};
  const json upper = dim == 2 ? json{1, 1} : json{1, 1, 1};
  const json n = dim == 2 ? json{cells, cells} : json{cells, cells, cells};
  j["domain"] = {{"lower", lower}, {"upper", upper}, {"cells", n}, {"boundary", {{"y+", "open"}}}};
  j["gravity"] = dim == 2 ? json{0, -9.81} : json{0, -9.81, 0};
  j["time"] = {{"fps", 20}, {"frames", frames}, {"max_dt", 0.01}};
  const json pool_centre = dim == 2 ? json{0.5, 0.25} : json{0.5, 0.25, 0.5};
  const json pool_half = dim == 2 ? json{0.5, 0.25} : json{0.5, 0.25, 0.5};
  j["liquids"] = json::array({{{"name", "pool"},
                               {"shape", {{"type", "box"}, {"center", pool_centre}, {"half_size", pool_half}}},
                               {"density", 1000},
                               {"viscosity", {{"model", "newtonian"}, {"eta", eta}}}}});
  const json box_centre = dim == 2 ? json{0.5, 0.12} : json{0.5, 0.14, 0.5};
  const json box_half = dim == 2 ? json{0.12, 0.08} : json{0.12, 0.08, 0.12};
  j["bodies"] = json::array({{{"name", "box"},
                              {"shape", {{"type", "box"}, {"center", box_centre}, {"half_size", box_half}}},
                              {"density", 1000 * kRatio}}});
  return j;
}

/// The box's volume (2D: area).
inline double box_volume(int dim) { return dim == 2 ? 0.24 * 0.16 : 0.24 * 0.16 * 0.24; }

struct Rise {
  double top_speed = 0.0;         ///< the box's largest upward speed (m/s)
  double highest = 0.0;           ///< its centre's largest height (m)
  double draft = 0.0;             ///< Archimedes' height of its centre at the last frame (m)
  double last = 0.0;              ///< its centre's height at the last frame (m)
  double liquid_kinetic = 0.0;    ///< the liquid's kinetic energy at the last frame (J)
  bool converged = true;
};

/// held: StageSwitches::density_held_beside_moving_bodies (departures item 25; off by default,
/// 1.5 the reach that lets the box rise)
inline Rise run_rise(const nlohmann::json& scene, int dim, int frames, double held = 1.5) {
  StageSwitches switches;
  switches.density_held_beside_moving_bodies = held;
  const auto sim = make_simulation(parse_scene(scene, "rising-box.json", "."), switches);
  Rise r;
  for (int f = 0; f < frames; ++f) {
    const FrameStats s = sim->advance_frame();
    r.converged = r.converged && s.solver.converged;
    REQUIRE(s.bodies.size() == 1);
    r.top_speed = std::max(r.top_speed, s.bodies[0].velocity[1]);
    r.highest = std::max(r.highest, s.bodies[0].position[1]);
    r.last = s.bodies[0].position[1];
    r.liquid_kinetic = s.kinetic_energy_liquid;
    const double surface = s.liquid_volume + kRatio * box_volume(dim);  // over A = 1
    r.draft = surface - kRatio * kHeight + kHeight / 2;
  }
  return r;
}


}  // namespace monolith::rising_body
