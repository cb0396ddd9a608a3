/// \file stats_json.cpp
/// Serialisation of FrameStats: one line of stats.jsonl, with the key names of docs/cli.md.

#include "reference/app/stats_json.hpp"

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

json frame_stats_json(const FrameStats& s) {
  json j;
  // time stepping
  j["frame"] = s.frame;
  j["time"] = number(s.time);
  j["steps"] = s.steps;
  j["dt_min"] = number(s.dt_min);
  j["dt_max"] = number(s.dt_max);
  // liquid
  j["liquid_volume"] = number(s.liquid_volume);
  j["particles"] = s.particles;
  j["liquid_bounds"] = {{"lower", vector(s.liquid_bounds_lower)}, {"upper", vector(s.liquid_bounds_upper)}};
  j["kinetic_energy"] = {{"liquid", number(s.kinetic_energy_liquid)}, {"bodies", number(s.kinetic_energy_bodies)}};
  j["potential_energy"] = {{"liquid", number(s.potential_energy_liquid)},
                           {"bodies", number(s.potential_energy_bodies)}};
  j["line15_banked_energy"] = number(s.line15_banked_energy);
  // bodies and contacts
  json bs = json::array();
  for (const auto& b : s.bodies)
    bs.push_back({{"name", b.name},
                  {"position", vector(b.position)},
                  {"orientation", vector(b.orientation)},
                  {"velocity", vector(b.velocity)},
                  {"angular_velocity", vector(b.angular_velocity)}});
  j["bodies"] = bs;
  j["contacts"] = {{"count", s.contact_count}, {"max_penetration", number(s.max_penetration)}};
  // probes
  json ps = json::array();
  for (const auto& p : s.probes)
    ps.push_back({{"name", p.name},
                  {"position", vector(p.position)},
                  {"velocity", vector(p.velocity)},
                  {"pressure", number(p.pressure)}});
  j["probes"] = ps;
  // solver
  j["solver"] = {{"scheme", enum_name(s.solver.scheme)},
                 {"iterations", s.solver.iterations},
                 {"max_step_iterations", s.solver.max_step_iterations},
                 {"staggered_iterations", s.solver.staggered_iterations},
                 {"max_relative_residual", number(s.solver.max_relative_residual)},
                 {"converged", s.solver.converged},
                 {"dofs",
                  {{"pressure", s.solver.dofs_pressure},
                   {"stress", s.solver.dofs_stress},
                   {"contact", s.solver.dofs_contact},
                   {"friction", s.solver.dofs_friction}}},
                 {"phases",
                  {{"fluid", {{"iterations", s.solver.fluid_iterations},
                              {"seconds", number(s.solver.fluid_seconds)}}},
                   {"contact", {{"iterations", s.solver.contact_iterations},
                                {"seconds", number(s.solver.contact_seconds)}}},
                   {"coupled", {{"iterations", s.solver.coupled_iterations},
                                {"seconds", number(s.solver.coupled_seconds)}}}}}};
  // non-Newtonian liquids only: the residuals of Algorithm 2 (section 5)
  if (!s.solver.viscosity_residuals.empty())
    j["solver"]["viscosity"] = {{"residuals", vector(s.solver.viscosity_residuals)},
                                {"max_final_residual", number(s.solver.max_viscosity_residual)}};
  // liquids with viscosity only: which preconditioner the unified / viscosity solves used
  // (solver.preconditioner "auto" picks per solve by the stiffness) and the largest stiffness
  if (s.solver.stokes_solves_multigrid + s.solver.stokes_solves_ssor > 0)
    j["solver"]["preconditioner"] = {{"multigrid", s.solver.stokes_solves_multigrid},
                                     {"ssor", s.solver.stokes_solves_ssor},
                                     {"max_stiffness", number(s.solver.max_stokes_stiffness)}};
  // the multigrid solves redone with SSOR (left out when there were none)
  if (s.solver.preconditioner_fallbacks > 0)
    j["solver"]["preconditioner"]["fallbacks"] = s.solver.preconditioner_fallbacks;
  // PC-/PVC-iterative steps whose rounds stopped at their cap before settling (left out when 0)
  if (s.solver.unsettled_steps > 0) j["solver"]["unsettled_steps"] = s.solver.unsettled_steps;
  // timing
  j["timing"] = json::object();
  for (const FramePhase phase : enum_values<FramePhase>())
    j["timing"][enum_name(phase)] = number(s.timing[phase]);
  return j;
}

}  // namespace monolith
