#pragma once
/// \file stats.hpp
/// Per-frame statistics: one line of stats.jsonl (docs/interface in docs/cli.md). The simulation
/// fills a FrameStats; the runner serialises it. Fields whose physics arrives in later issues
/// (bodies, contacts, stress DOFs) keep their shape with empty or zero values.

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace monolith {

struct BodyStats {
  std::string name;
  std::vector<double> position;          ///< centre of mass
  std::vector<double> orientation;       ///< 2D: [angle]; 3D: quaternion [w, x, y, z]
  std::vector<double> velocity;
  std::vector<double> angular_velocity;  ///< 2D: [omega]; 3D: 3-vector
};

struct ProbeStats {
  std::string name;
  std::vector<double> position;
  std::vector<double> velocity;
  double pressure = 0.0;
};

struct SolverStats {
  std::string scheme;
  long iterations = 0;            ///< summed over the frame's steps
  int staggered_iterations = 0;   ///< summed over the frame's steps
  double max_relative_residual = 0.0;
  bool converged = true;          ///< all solves of the frame converged
  long dofs_pressure = 0, dofs_stress = 0, dofs_contact = 0, dofs_friction = 0;  ///< max
  /// The phases of the paper's Tables 1-3, summed over the frame's steps: separate liquid
  /// solves (P, PV or VC without contact rows), separate contact solves (C), and unified solves
  /// (PC, PVC; the VC step of PC-VC-PC-unified counts here): iterations and wall time.
  long fluid_iterations = 0, contact_iterations = 0, coupled_iterations = 0;
  double fluid_seconds = 0.0, contact_seconds = 0.0, coupled_seconds = 0.0;
  /// Non-Newtonian liquids (Algorithm 2, section 5): the residual of each viscosity round of
  /// the frame's last step (NonNewtonianViscosity::residuals, Fig. 9's convergence plot) and
  /// the largest last-round residual over the frame's steps. Empty / 0 (and left out of the
  /// JSON) for Newtonian liquids.
  std::vector<double> viscosity_residuals;
  double max_viscosity_residual = 0.0;
};

struct FrameStats {
  int frame = 0;
  double time = 0.0;
  int steps = 0;
  double dt_min = 0.0, dt_max = 0.0;
  double liquid_volume = 0.0;  ///< sum of W_L^p dx^Dim
  long particles = 0;
  std::vector<double> liquid_bounds_lower, liquid_bounds_upper;
  double kinetic_energy_liquid = 0.0, kinetic_energy_bodies = 0.0;
  std::vector<BodyStats> bodies;
  int contact_count = 0;
  double max_penetration = 0.0;
  std::vector<ProbeStats> probes;
  SolverStats solver;
  double timing_total = 0.0, timing_solve = 0.0;

  /// The stats.jsonl object with every field of the contract.
  nlohmann::json to_json() const;
};

}  // namespace monolith
