#pragma once
/// \file rigid_world.hpp
/// RigidWorld<Dim>: the rigid bodies and the domain walls of a scene, stepped with frictional
/// contact: the body part of Algorithm 1 (lines 3, 6, 8, 10, 12, 13) without the liquid. One
/// step: gravity gives v*; contacts are detected up to a search distance; the contact problem
/// of eqs. (13)-(16) is solved by staggered projections (section 4.2) with MPRGP; the velocities
/// are updated (eq. (13)) and the positions integrated. docs/rigid-bodies.md, "Contact model".

#include <cstdint>
#include <limits>
#include <vector>

#include "reference/contact/collision.hpp"
#include "reference/contact/contact_system.hpp"
#include "reference/core/errors.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "reference/sim/frame_stats.hpp"
#include "reference/sim/scene_desc.hpp"

namespace monolith {

/// What the world needs from the scene's solver keys (all lengths in metres except the margin),
/// with the scene's defaults (SolverSpec).
struct RigidWorldSettings {
  double dx = 1.0;  ///< cell width: margin epsilon = margin_cells dx, alpha = 1/dx^Dim
  double baumgarte = SolverSpec{}.baumgarte;            ///< beta of eq. (16)
  /// Cap on eq. (16)'s recovery speed (m/s; ContactParameters::max_recovery_speed). Infinite
  /// unless set; from_scene: solver.max_recovery_speed, or without it beta dx / dt_max with
  /// dt_max = min(time.max_dt, 1 / time.fps), the scene's largest step.
  double max_recovery_speed = std::numeric_limits<double>::infinity();
  double margin_cells = SolverSpec{}.contact_margin;    ///< epsilon / dx (solver.contact_margin)
  double diagonal_boost = SolverSpec{}.diagonal_boost;  ///< gamma of section 4.4.5
  int staggered_iterations = SolverSpec{}.staggered_iterations;  ///< outer iterations of 4.2
  double tolerance = SolverSpec{}.tolerance;  ///< MPRGP and staggered-projection tolerance
  int max_iterations = SolverSpec{}.max_iterations;  ///< MPRGP iterations per QP
  /// Start each solve from the previous step's forces of matching contacts (same pair, wall
  /// face and a point within dx / 2). Not in the paper; it saves iterations on resting stacks.
  bool warm_start = true;
  /// Contact points kept per normal patch of a pair: < 0 the reduction of collision.hpp as it
  /// is (ContactReduction defaults: 2 in 2D, 4 in 3D), 0 every candidate within the search
  /// distance, > 0 that many.
  int points_per_patch = -1;
  static RigidWorldSettings from_scene(const SceneDesc& scene);
};

/// Statistics of one step of the world.
struct RigidStepStats {
  int contacts = 0;
  double max_penetration = 0.0;  ///< max over contacts of max(-phi, 0) (m, without the margin)
  int staggered_iterations = 0;
  long iterations = 0;           ///< MPRGP iterations, every QP of the step
  double max_relative_residual = 0.0;
  bool converged = true;
  long dofs_contact = 0, dofs_friction = 0;
  double solve_seconds = 0.0;    ///< wall time of the staggered projections
};

template <int Dim>
class RigidWorld {
 public:
  RigidWorld() = default;
  /// Bodies from make_bodies(scene) (surface samples at dx / 2), walls from the scene.
  explicit RigidWorld(const SceneDesc& scene);
  RigidWorld(std::vector<RigidBody<Dim>> bodies, const Walls<Dim>& walls,
             const RigidWorldSettings& settings);

  /// One step from time t to t + dt under gravity g (m/s^2): v* = v + dt g on dynamic bodies,
  /// contacts up to the search distance epsilon + 2 dt (largest body speed) + dx / 10, contact
  /// forces by staggered projections, v = v* + dt M_r^-1 (J_lambda^T lambda + J_z^T z),
  /// positions integrated (kinematic bodies take their path's state at t + dt).
  /// Throws SimulationError on a non-finite body state.
  RigidStepStats step(double dt, double t, const Vec<Dim>& gravity);

  // The pieces of step(), in its order, for the coupled liquid-body step of Simulation:
  /// Algorithm 1, line 3 for the bodies: v* = v + dt g on the dynamic bodies.
  void apply_gravity(double dt, const Vec<Dim>& gravity);
  /// Line 6: the contacts at the current pose up to the search distance epsilon + 2 dt (largest
  /// body point speed) + dx / 10, only those touching a dynamic body, each with its pair's
  /// friction sqrt(mu_a mu_b) and restitution max(e_a, e_b). Sets stats.contacts and
  /// stats.max_penetration.
  std::vector<Contact<Dim>> find_contacts(double dt, RigidStepStats& stats) const;
  /// The ContactParameters of a step of dt (restitution only above two steps of gravity).
  ContactParameters contact_parameters(double dt, const Vec<Dim>& gravity) const;
  /// Line 12: the dynamic bodies take the generalised velocities v (ContactSystem layout:
  /// body i's block starts at body_dof[i], -1 for bodies without DOFs).
  void set_velocities(const VectorX& v, const std::vector<int>& body_dof);
  /// Line 13: positions (kinematic bodies follow their path to t + dt). Throws SimulationError
  /// on a non-finite body state (`after` names what came before).
  void integrate(double dt, double t, const char* after);
  /// Keeps the contacts and forces of a step solved outside the world (the coupled step of
  /// Simulation) for last_contacts() / last_solve() and the next step's warm start.
  void remember(std::vector<Contact<Dim>> contacts, const StaggeredResult& solve);

  const std::vector<RigidBody<Dim>>& bodies() const { return bodies_; }
  std::vector<RigidBody<Dim>>& bodies() { return bodies_; }
  const Walls<Dim>& walls() const { return walls_; }
  const RigidWorldSettings& settings() const { return settings_; }
  /// The contacts of the last step and their forces (lambda, z of the last solve).
  const std::vector<Contact<Dim>>& last_contacts() const { return contacts_; }
  const StaggeredResult& last_solve() const { return solve_; }
  /// The contact problem assembled in the last step() (at v*); steps solved outside the world
  /// (remember) leave it as it was.
  const ContactSystem<Dim>& last_system() const { return system_; }

  /// Kinetic energy of the dynamic bodies (J; 2D per metre of depth).
  double kinetic_energy() const;
  /// Gravitational potential energy -sum m g . x of the dynamic bodies.
  double potential_energy(const Vec<Dim>& gravity) const;
  /// Largest speed of a point of a moving body: max |v| + |omega| R, R the distance from the
  /// centre of mass to the farthest corner of the body's bounds (for the CFL step).
  double max_point_speed() const;
  /// Per-body statistics (every body, scene order).
  std::vector<BodyStats> body_stats() const;

  /// The world's part of a simulation checkpoint (reference/core/state_io.hpp): every body's
  /// pose and velocity, and the last step's contacts and forces (the next step's warm start).
  /// The bodies' shapes, masses and samples come from the scene.
  template <class Archive>
  void state_fields(Archive& a) {
    std::uint64_t n = bodies_.size();
    a(n);
    if (n != bodies_.size()) throw InputError("checkpoint: body count differs from the scene's");
    for (auto& b : bodies_) {
      a(b.position);
      a(b.orientation);
      a(b.velocity);
      a(b.angular_velocity);
    }
    n = contacts_.size();
    a(n);
    if (n > (1u << 28)) throw InputError("checkpoint: implausible contact count");
    contacts_.resize(n);
    for (auto& c : contacts_) {
      a(c.body_a);
      a(c.body_b);
      a(c.wall_face);
      a(c.point);
      a(c.normal);
      a(c.phi);
      a(c.friction);
      a(c.restitution);
    }
    a(solve_.lambda);
    a(solve_.z);
  }

 private:
  std::vector<RigidBody<Dim>> bodies_;
  Walls<Dim> walls_;
  RigidWorldSettings settings_;
  std::vector<double> radius_;  ///< per body: COM to farthest bounds corner at rest
  std::vector<Contact<Dim>> contacts_;
  ContactSystem<Dim> system_;
  StaggeredResult solve_;
};

}  // namespace monolith
