// Every built-in scene run for three times its length (issue 16: "no NaN, no energy growth
// without a source"). Label `slow`: the 2D scenes take minutes, the 3D ones more than an hour on
// one core; run one dimension with `build/tests/slow_long_runs "[2d]"` (or "[3d]"), one scene
// with `build/tests/slow_long_runs "[2d]" -c dam-break-2d`.
//
// Per frame: the frame advances without an error, every solve converged, and every number the
// stats report (energies, volume, the bodies' state) is finite. For a scene without an energy
// source (no kinematic body on a prescribed path, no periodic side through which gravity does
// work on liquid that wraps around), the mechanical energy E = kinetic + gravitational potential
// of liquid and bodies (+ the credit line 15's account holds, FrameStats::line15_banked_energy)
// must not rise above its running minimum by more than 2 % of the energy
// released up to then (the sloshing bound of tests/slow/slow_still_water.cpp) plus 1e-5 M g H
// (M the mass of liquid and dynamic bodies, H the domain's height along gravity: the still-water
// bound), and must end below its start. The paper-grid variants (`-paper`) are left out: they
// are the same scenes on finer grids.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "reference/app/embedded_scenes.hpp"
#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

/// Names of the built-in scenes of one dimension, without the paper-grid variants.
std::vector<std::string> scenes_of(int dim) {
  std::vector<std::string> names;
  for (const auto& f : embedded_scenes()) {
    const std::string name(f.name);
    if (ends_with(name, "-paper")) continue;
    if (load_scene(name, {"render.enabled=false"}).dim == dim) names.push_back(name);
  }
  std::sort(names.begin(), names.end());
  return names;
}

/// Why a scene may gain mechanical energy (empty: it may not).
std::string energy_source(const SceneDesc& scene) {
  for (int i = 0; i < 2 * scene.dim; ++i)
    if (scene.domain.boundary[i] == BoundaryType::periodic) return "a periodic side";
  for (const auto& b : scene.bodies)
    if (b.motion == BodyMotion::kinematic) return "kinematic body '" + b.name + "'";
  return {};
}

bool all_finite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

/// The finite check of one frame's stats; names the first bad field.
std::string first_non_finite(const FrameStats& s) {
  const double scalars[] = {s.liquid_volume, s.kinetic_energy_liquid, s.kinetic_energy_bodies,
                            s.potential_energy_liquid, s.potential_energy_bodies, s.dt_min,
                            s.dt_max, s.max_penetration};
  for (double x : scalars)
    if (!std::isfinite(x)) return "volume, an energy, dt or the penetration";
  if (!all_finite(s.liquid_bounds_lower) || !all_finite(s.liquid_bounds_upper))
    return "the liquid's bounds";
  for (const auto& b : s.bodies)
    if (!all_finite(b.position) || !all_finite(b.orientation) || !all_finite(b.velocity) ||
        !all_finite(b.angular_velocity))
      return "body '" + b.name + "'";
  return {};
}

/// Kinetic + potential energy of liquid and bodies, with the credit line 15's account holds
/// (FrameStats::line15_banked_energy when positive: potential energy the position corrections
/// released, kept against their next rises; without it a release and its later spending read as
/// a regain). A debt (negative: rises the kinetic energy could not pay) is not forgiven: the
/// energy it stands for is in the state.
double mechanical_energy(const FrameStats& s) {
  return s.kinetic_energy_liquid + s.kinetic_energy_bodies + s.potential_energy_liquid +
         s.potential_energy_bodies + std::max(0.0, s.line15_banked_energy);
}

/// M g H of the scene at its start: liquid mass from the level set's volume and the densest
/// liquid, the dynamic bodies' masses, H the domain's extent along gravity.
template <int Dim>
double energy_scale(const SceneDesc& scene, const Simulation<Dim>& sim, const FrameStats& s0) {
  std::vector<double> g = scene.gravity.empty() ? default_gravity(scene.dim) : scene.gravity;
  double gn = 0.0;
  for (double c : g) gn += c * c;
  gn = std::sqrt(gn);
  if (gn == 0.0) return 0.0;
  double height = 0.0;
  for (int i = 0; i < scene.dim; ++i)
    height += std::abs(g[i] / gn) * (scene.domain.upper[i] - scene.domain.lower[i]);
  double rho = 0.0;
  for (const auto& l : scene.liquids) rho = std::max(rho, l.density);
  double mass = rho * s0.liquid_volume;
  if (const auto* world = sim.rigid_world())
    for (const auto& b : world->bodies())
      if (b.motion == BodyMotion::dynamic) mass += b.mass;
  return mass * gn * height;
}

template <int Dim>
void run_three_times(const std::string& name) {
  const SceneFile scene = load_scene(name, {"render.enabled=false"});
  auto base = make_simulation(scene);
  auto* sim = dynamic_cast<Simulation<Dim>*>(base.get());
  REQUIRE(sim != nullptr);
  FrameStats s = sim->current_stats();
  const std::string source = energy_source(scene);
  const double e0 = mechanical_energy(s);
  const double floor = 1e-5 * energy_scale<Dim>(scene, *sim, s);
  double lowest = e0, worst_excess = -1e300, worst_regain = 0.0, largest_regain = 0.0;
  int worst_frame = 0;
  const int frames = 3 * scene.time.frames;
  for (int f = 1; f <= frames; ++f) {
    INFO(name << " frame " << f << " of " << frames);
    REQUIRE_NOTHROW(s = sim->advance_frame());
    std::ostringstream unconverged;
    for (const auto& u : s.solver.unconverged)
      unconverged << u.solve << " at t = " << u.time << " s: " << u.iterations
                  << " iterations, relative residual " << u.relative_residual << "; ";
    INFO("unconverged: " << unconverged.str());
    REQUIRE(s.solver.converged);
    const std::string bad = first_non_finite(s);
    INFO("non-finite: " << bad);
    REQUIRE(bad.empty());
    const double e = mechanical_energy(s);
    const double regain = e - lowest;
    const double allowed = 0.02 * (e0 - lowest) + floor;
    largest_regain = std::max(largest_regain, regain);
    if (regain - allowed > worst_excess) {
      worst_excess = regain - allowed;
      worst_regain = regain;
      worst_frame = f;
    }
    lowest = std::min(lowest, e);
  }
  const double e_end = mechanical_energy(s);
  std::ostringstream report;
  report << name << ": E " << e0 << " -> " << e_end << " J (lowest " << lowest
         << "), largest regain over the running minimum " << largest_regain
         << " J; closest to the bound at frame " << worst_frame << " (regain " << worst_regain
         << " J, excess over the bound " << worst_excess << " J; floor " << floor << " J)" << (source.empty() ? "" : "; energy source: " + source);
  INFO(report.str());
  WARN(report.str());
  if (source.empty()) {
    CHECK(worst_excess <= 0.0);
    CHECK(e_end < e0);
  }
}

}  // namespace

TEST_CASE("every built-in 2D scene runs three times its length: finite, converged, no energy gain",
          "[slow][2d]") {
  for (const std::string& name : scenes_of(2))
    SECTION(name) { run_three_times<2>(name); }
}

TEST_CASE("every built-in 3D scene runs three times its length: finite, converged, no energy gain",
          "[slow][3d]") {
  for (const std::string& name : scenes_of(3))
    SECTION(name) { run_three_times<3>(name); }
}
