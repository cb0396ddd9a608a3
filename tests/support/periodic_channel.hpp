#pragma once
/// \file periodic_channel.hpp
/// A channel between two no-slip walls (y = 0 and y = H), periodic along x, full of liquid and
/// driven from rest by gravity along x: plane Poiseuille start-up flow through the whole step
/// (particles, line 15, solve). test_periodic_channel.cpp (default suite) and
/// slow_periodic_channel.cpp (label `slow`) use it. The start-up flow of a Newtonian liquid is the
/// series (Batchelor 1967, §4.3; the odd sine modes of the steady parabola decaying at
/// exp(-n^2 pi^2 nu t / H^2)); with backward Euler at step dt each mode decays by
/// 1 / (1 + nu k_n^2 dt) per step instead. Its kinetic energy rises monotonically from rest.

#include <cmath>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

namespace monolith::periodic_channel {

constexpr double kHeight = 0.5;  ///< channel width H between the walls (m)
constexpr double kRho = 1000.0;

/// The channel: [0, 1] x [0, H] (3D: a slab 4 cells deep, periodic in z too), `cells` across H,
/// gravity g e_x, `viscosity` the liquid's viscosity object, `fps` frames for `seconds`, probes
/// at the cell centres of the column x = 1/2 + dx/6.
inline nlohmann::json scene(int dim, int cells, double g, const nlohmann::json& viscosity,
                            double seconds, int fps = 20) {
  using nlohmann::json;
  const double dx = kHeight / cells;
  const int nx = 2 * cells;
  json j;
  j["format"] = "monolith-scene/1";
  j["name"] = "periodic-channel";
  j["dim"] = dim;
  std::vector<double> lower(dim, 0.0), upper{1.0, kHeight}, centre{0.5, 0.5 * kHeight},
      half{0.6, 0.5 * kHeight + 0.1}, gravity(dim, 0.0);
  std::vector<int> n{nx, cells};
  json boundary = {{"x-", "periodic"}, {"x+", "periodic"}, {"y-", "wall"}, {"y+", "wall"}};
  if (dim == 3) {
    upper.push_back(4 * dx);
    centre.push_back(2 * dx);
    half.push_back(2 * dx + 0.1);
    n.push_back(4);
    boundary["z-"] = "periodic";
    boundary["z+"] = "periodic";
  }
  gravity[0] = g;
  j["domain"] = {{"lower", lower}, {"upper", upper}, {"cells", n}, {"boundary", boundary}};
  j["gravity"] = gravity;
  j["time"] = {{"fps", fps}, {"frames", static_cast<int>(std::lround(fps * seconds))}};
  j["liquids"] = {{{"name", "liquid"},
                   {"density", kRho},
                   {"shape", {{"type", "box"}, {"center", centre}, {"half_size", half}}},
                   {"viscosity", viscosity}}};
  j["probes"] = json::array();
  for (int k = 0; k < cells; ++k) {
    std::vector<double> x{0.5 + dx / 6, (k + 0.5) * dx};
    if (dim == 3) x.push_back(2 * dx + dx / 7);
    j["probes"].push_back({{"name", "y" + std::to_string(k)}, {"position", x}});
  }
  j["render"] = {{"enabled", false}};
  return j;
}

/// Newtonian start-up velocity at height y and time t (nu = eta / rho), the series above with
/// backward Euler's per-step factor at step dt (dt = 0: the exact exponential).
inline double newtonian_startup(double y, double t, double g, double nu, double dt) {
  const double pi = 3.14159265358979323846;
  double u = g * y * (kHeight - y) / (2 * nu);
  for (int n = 1; n < 400; n += 2) {
    const double k2 = n * n * pi * pi / (kHeight * kHeight);
    const double decay = dt > 0 ? std::pow(1.0 / (1.0 + nu * k2 * dt), t / dt) : std::exp(-nu * k2 * t);
    u -= 4 * g * kHeight * kHeight / (nu * n * n * n * pi * pi * pi) *
         std::sin(n * pi * y / kHeight) * decay;
  }
  return u;
}

/// Power-law (Herschel-Bulkley with tau0 = 0) steady profile, stress k s^n: shear stress
/// G (H/2 - y) with G = rho g, so u = n/(n+1) (G/k)^(1/n) ((H/2)^(1+1/n) - |H/2 - y|^(1+1/n)).
inline double power_law_steady(double y, double g, double k, double n) {
  const double G = kRho * g, h = 0.5 * kHeight, e = 1.0 + 1.0 / n;
  return n / (n + 1) * std::pow(G / k, 1.0 / n) * (std::pow(h, e) - std::pow(std::abs(h - y), e));
}

struct ChannelRun {
  std::vector<double> time;          ///< frame times
  std::vector<double> kinetic;       ///< kinetic energy of the liquid per frame (J; 2D: J/m)
  std::vector<std::vector<double>> u;  ///< probe x velocities per frame (cell centres, y up)
  std::vector<double> y;             ///< probe heights
  double max_banked = 0.0;           ///< largest |line15_banked_energy| over the run (J)
  double particle_mass = 0.0;        ///< mass of one particle (kg; 2D: kg/m)
  bool converged = true;
};

inline ChannelRun run(const nlohmann::json& j) {
  const auto sim = make_simulation(parse_scene(j, "periodic-channel.json", "."));
  ChannelRun r;
  const int frames = j["time"]["frames"];
  FrameStats s = sim->current_stats();
  r.particle_mass = (s.particles > 0) ? kRho * s.liquid_volume / s.particles : 0.0;
  for (const auto& p : s.probes) r.y.push_back(p.position[1]);
  for (int f = 0; f <= frames; ++f) {
    if (f > 0) s = sim->advance_frame();
    r.converged = r.converged && s.solver.converged;
    r.time.push_back(s.time);
    r.kinetic.push_back(s.kinetic_energy_liquid);
    r.max_banked = std::max(r.max_banked, std::abs(s.line15_banked_energy));
    std::vector<double> u;
    for (const auto& p : s.probes) u.push_back(p.velocity[0]);
    r.u.push_back(u);
  }
  return r;
}

/// The largest relative fall of the kinetic energy from one frame to the next after frame 1.
inline double largest_kinetic_fall(const ChannelRun& r) {
  double fall = 0.0;
  for (std::size_t f = 2; f < r.kinetic.size(); ++f)
    fall = std::max(fall, (r.kinetic[f - 1] - r.kinetic[f]) / r.kinetic[f - 1]);
  return fall;
}

}  // namespace monolith::periodic_channel
