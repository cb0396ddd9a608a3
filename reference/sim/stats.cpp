/// \file stats.cpp
/// Serialisation of FrameStats: one line of stats.jsonl, with the key names of docs/cli.md.

#include "reference/sim/stats.hpp"

#include <cmath>

namespace monolith {

namespace {

using nlohmann::json;

/// JSON has no NaN or infinity: non-finite numbers are written as null.
json number(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }

json vector(const std::vector<double>& v) {
  json a = json::array();
  for (double x : v) a.push_back(number(x));
  return a;
}

}  // namespace

json FrameStats::to_json() const {
  json j;
  // time stepping
  j["frame"] = frame;
  j["time"] = number(time);
  j["steps"] = steps;
  j["dt_min"] = number(dt_min);
  j["dt_max"] = number(dt_max);
  // liquid
  j["liquid_volume"] = number(liquid_volume);
  j["particles"] = particles;
  j["liquid_bounds"] = {{"lower", vector(liquid_bounds_lower)}, {"upper", vector(liquid_bounds_upper)}};
  j["kinetic_energy"] = {{"liquid", number(kinetic_energy_liquid)}, {"bodies", number(kinetic_energy_bodies)}};
  // bodies and contacts
  json bs = json::array();
  for (const auto& b : bodies)
    bs.push_back({{"name", b.name},
                  {"position", vector(b.position)},
                  {"orientation", vector(b.orientation)},
                  {"velocity", vector(b.velocity)},
                  {"angular_velocity", vector(b.angular_velocity)}});
  j["bodies"] = bs;
  j["contacts"] = {{"count", contact_count}, {"max_penetration", number(max_penetration)}};
  // probes
  json ps = json::array();
  for (const auto& p : probes)
    ps.push_back({{"name", p.name},
                  {"position", vector(p.position)},
                  {"velocity", vector(p.velocity)},
                  {"pressure", number(p.pressure)}});
  j["probes"] = ps;
  // solver
  j["solver"] = {{"scheme", solver.scheme},
                 {"iterations", solver.iterations},
                 {"staggered_iterations", solver.staggered_iterations},
                 {"max_relative_residual", number(solver.max_relative_residual)},
                 {"converged", solver.converged},
                 {"dofs",
                  {{"pressure", solver.dofs_pressure},
                   {"stress", solver.dofs_stress},
                   {"contact", solver.dofs_contact},
                   {"friction", solver.dofs_friction}}},
                 {"phases",
                  {{"fluid", {{"iterations", solver.fluid_iterations},
                              {"seconds", number(solver.fluid_seconds)}}},
                   {"contact", {{"iterations", solver.contact_iterations},
                                {"seconds", number(solver.contact_seconds)}}},
                   {"coupled", {{"iterations", solver.coupled_iterations},
                                {"seconds", number(solver.coupled_seconds)}}}}}};
  // non-Newtonian liquids only: the residuals of Algorithm 2 (section 5)
  if (!solver.viscosity_residuals.empty())
    j["solver"]["viscosity"] = {{"residuals", vector(solver.viscosity_residuals)},
                                {"max_final_residual", number(solver.max_viscosity_residual)}};
  // timing
  j["timing"] = {{"total", number(timing_total)}, {"solve", number(timing_solve)}};
  return j;
}

}  // namespace monolith
