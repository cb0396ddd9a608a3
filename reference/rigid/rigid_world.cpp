/// \file rigid_world.cpp
/// RigidWorld<Dim>: gravity, contact detection, staggered projections, velocity and position
/// update of the rigid bodies (the body lines of Algorithm 1).

#include "reference/rigid/rigid_world.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "reference/core/errors.hpp"
#include "reference/core/timer.hpp"

namespace monolith {

namespace {

/// The longest step a scene takes: max_dt, or the frame when that is shorter.
double largest_step(const TimeSpec& t) {
  return t.fps > 0.0 ? std::min(t.max_dt, 1.0 / t.fps) : t.max_dt;
}

}  // namespace

RigidWorldSettings RigidWorldSettings::from_scene(const SceneDesc& scene) {
  RigidWorldSettings s;
  s.dx = scene.dx();
  s.baumgarte = scene.solver.baumgarte;
  // the recovery cap: the scene's, or the speed eq. (16) gives a one-cell penetration at the
  // largest step (docs/rigid-bodies.md, "A cap on the recovery speed")
  s.max_recovery_speed = scene.solver.max_recovery_speed > 0.0
                             ? scene.solver.max_recovery_speed
                             : scene.solver.baumgarte * scene.dx() / largest_step(scene.time);
  s.margin_cells = scene.solver.contact_margin;
  s.diagonal_boost = scene.solver.diagonal_boost;
  s.staggered_iterations = std::max(1, scene.solver.staggered_iterations);
  s.tolerance = scene.solver.tolerance;
  s.max_iterations = scene.solver.max_iterations;
  return s;
}

template <int Dim>
RigidWorld<Dim>::RigidWorld(const SceneDesc& scene)
    : RigidWorld(make_bodies<Dim>(scene), Walls<Dim>::from_scene(scene),
                 RigidWorldSettings::from_scene(scene)) {}

template <int Dim>
RigidWorld<Dim>::RigidWorld(std::vector<RigidBody<Dim>> bodies, const Walls<Dim>& walls,
                            const RigidWorldSettings& settings)
    : bodies_(std::move(bodies)), walls_(walls), settings_(settings) {
  // a bound on the distance of any body point from its centre of mass
  radius_.assign(bodies_.size(), 0.0);
  for (std::size_t i = 0; i < bodies_.size(); ++i) {
    const Box<Dim> box = bodies_[i].bounds();
    if (!box.min().allFinite() || !box.max().allFinite()) continue;
    double r = 0.0;
    for (int corner = 0; corner < (1 << Dim); ++corner) {
      Vec<Dim> x;
      for (int a = 0; a < Dim; ++a) x[a] = (corner >> a) & 1 ? box.max()[a] : box.min()[a];
      r = std::max(r, (x - bodies_[i].position).norm());
    }
    radius_[i] = r;
  }
}

template <int Dim>
void RigidWorld<Dim>::apply_gravity(double dt, const Vec<Dim>& gravity) {
  for (auto& b : bodies_)
    if (b.is_dynamic()) b.velocity += dt * gravity;
}

template <int Dim>
std::vector<Contact<Dim>> RigidWorld<Dim>::find_contacts(double dt, RigidStepStats& stats) const {
  const double dx = settings_.dx;
  // the margin plus what two bodies can close in a step
  const double search = settings_.margin_cells * dx + 2.0 * dt * max_point_speed() + 0.1 * dx;
  ContactReduction reduction;
  if (settings_.points_per_patch > 0)
    reduction.max_points_2d = reduction.max_points_3d = settings_.points_per_patch;
  else if (settings_.points_per_patch == 0)
    reduction.max_points_2d = reduction.max_points_3d = 1 << 20;  // every candidate
  std::vector<Contact<Dim>> found = detect_contacts<Dim>(bodies_, walls_, search, reduction);
  std::vector<Contact<Dim>> contacts;
  contacts.reserve(found.size());
  for (Contact<Dim> c : found) {
    // only contacts that touch a dynamic body carry an unknown
    const bool a_dyn = c.body_a >= 0 && bodies_[c.body_a].is_dynamic();
    const bool b_dyn = c.body_b >= 0 && bodies_[c.body_b].is_dynamic();
    if (!a_dyn && !b_dyn) continue;
    // the pair's coefficients as the scene contract combines them, a wall counting as a body
    // with domain.wall_friction and domain.wall_restitution: sqrt(mu_a mu_b), max(e_a, e_b)
    const double mu_a = c.body_a >= 0 ? bodies_[c.body_a].friction : walls_.friction;
    const double mu_b = c.body_b >= 0 ? bodies_[c.body_b].friction : walls_.friction;
    const double e_a = c.body_a >= 0 ? bodies_[c.body_a].restitution : walls_.restitution;
    const double e_b = c.body_b >= 0 ? bodies_[c.body_b].restitution : walls_.restitution;
    c.friction = std::sqrt(mu_a * mu_b);
    c.restitution = std::max(e_a, e_b);
    contacts.push_back(c);
  }
  stats.contacts = static_cast<int>(contacts.size());
  stats.max_penetration = 0.0;
  for (const auto& c : contacts) stats.max_penetration = std::max(stats.max_penetration, -c.phi);
  return contacts;
}

template <int Dim>
ContactParameters RigidWorld<Dim>::contact_parameters(double dt, const Vec<Dim>& gravity) const {
  ContactParameters params;
  params.dt = dt;
  params.dx = settings_.dx;
  params.baumgarte = settings_.baumgarte;
  params.max_recovery_speed = settings_.max_recovery_speed;
  params.margin_cells = settings_.margin_cells;
  params.restitution_threshold = 2.0 * gravity.norm() * dt;
  return params;
}

template <int Dim>
void RigidWorld<Dim>::set_velocities(const VectorX& v, const std::vector<int>& body_dof) {
  for (std::size_t i = 0; i < bodies_.size() && i < body_dof.size(); ++i)
    if (body_dof[i] >= 0)
      bodies_[i].set_generalized_velocity(v.template segment<kBodyDofs<Dim>>(body_dof[i]));
}

template <int Dim>
void RigidWorld<Dim>::integrate(double dt, double t, const char* after) {
  for (auto& b : bodies_) b.integrate(dt, t + dt);
  for (const auto& b : bodies_)
    if (!b.position.allFinite() || !b.velocity.allFinite() || !b.angular_velocity.allFinite()) {
      std::ostringstream msg;
      msg << "t = " << t + dt << " s: non-finite state of body \"" << b.name << "\" after " << after;
      throw SimulationError(msg.str());
    }
}

template <int Dim>
void RigidWorld<Dim>::remember(std::vector<Contact<Dim>> contacts, const StaggeredResult& solve) {
  contacts_ = std::move(contacts);
  solve_ = solve;
}

template <int Dim>
RigidStepStats RigidWorld<Dim>::step(double dt, double t, const Vec<Dim>& gravity) {
  RigidStepStats stats;
  const double dx = settings_.dx;
  // (3) external force on the dynamic bodies: v* = v + dt g
  apply_gravity(dt, gravity);
  // (6) contacts up to a search distance
  std::vector<Contact<Dim>> contacts = find_contacts(dt, stats);
  // (8) J_lambda, J_z, M_r, C at v*
  ContactSystem<Dim> system(bodies_, contacts, contact_parameters(dt, gravity));
  const int nc = system.num_contacts();
  stats.dofs_contact = nc;
  stats.dofs_friction = system.mu.size() && system.mu.maxCoeff() > 0.0 ? system.num_friction_rows() : 0;

  // warm start from the previous step's matching contacts
  VectorX lambda0 = VectorX::Zero(nc), z0 = VectorX::Zero(system.num_friction_rows());
  if (settings_.warm_start && solve_.lambda.size() == static_cast<long>(contacts_.size())) {
    const double reach2 = 0.25 * dx * dx;
    for (int c = 0; c < nc; ++c)
      for (std::size_t d = 0; d < contacts_.size(); ++d) {
        const Contact<Dim>& o = contacts_[d];
        if (o.body_a != contacts[c].body_a || o.body_b != contacts[c].body_b ||
            o.wall_face != contacts[c].wall_face ||
            (o.point - contacts[c].point).squaredNorm() > reach2)
          continue;
        lambda0[c] = solve_.lambda[d];
        if (solve_.z.size() == static_cast<long>((Dim - 1) * contacts_.size()))
          for (int j = 0; j < Dim - 1; ++j) z0[(Dim - 1) * c + j] = solve_.z[(Dim - 1) * d + j];
        break;
      }
  }

  // (10) staggered projections
  StaggeredSettings ss;
  ss.max_iterations = settings_.staggered_iterations;
  ss.tolerance = settings_.tolerance;
  ss.diagonal_boost = settings_.diagonal_boost;
  ss.mprgp.tolerance = settings_.tolerance;
  ss.mprgp.max_iterations = settings_.max_iterations;
  StaggeredResult solve;
  {
    ScopedTimer timer(stats.solve_seconds);
    solve = solve_staggered_projections<Dim>(system, ss, lambda0, z0);
  }
  stats.staggered_iterations = solve.staggered_iterations;
  stats.iterations = solve.mprgp_iterations;
  stats.max_relative_residual = solve.max_relative_residual;
  stats.converged = solve.converged;

  // (12) contact and friction forces on the dynamic bodies, eq. (13)
  if (nc > 0) set_velocities(system.velocity_update(solve.lambda, solve.z), system.body_dof);
  // (13) positions (kinematic bodies follow their path)
  integrate(dt, t, "the contact solve");
  contacts_ = std::move(contacts);
  system_ = std::move(system);
  solve_ = std::move(solve);
  return stats;
}

template <int Dim>
double RigidWorld<Dim>::kinetic_energy() const {
  double e = 0.0;
  for (const auto& b : bodies_) e += b.kinetic_energy();
  return e;
}

template <int Dim>
double RigidWorld<Dim>::potential_energy(const Vec<Dim>& gravity) const {
  double e = 0.0;
  for (const auto& b : bodies_)
    if (b.is_dynamic()) e -= b.mass * gravity.dot(b.position);
  return e;
}

template <int Dim>
double RigidWorld<Dim>::max_point_speed() const {
  double s = 0.0;
  for (std::size_t i = 0; i < bodies_.size(); ++i)
    if (bodies_[i].moves())
      s = std::max(s, bodies_[i].velocity.norm() + bodies_[i].angular_velocity.norm() * radius_[i]);
  return s;
}

template <int Dim>
std::vector<BodyStats> RigidWorld<Dim>::body_stats() const {
  std::vector<BodyStats> out;
  for (const auto& b : bodies_) {
    BodyStats s;
    s.name = b.name;
    s.position.assign(b.position.data(), b.position.data() + Dim);
    s.velocity.assign(b.velocity.data(), b.velocity.data() + Dim);
    s.angular_velocity.assign(b.angular_velocity.data(), b.angular_velocity.data() + kAngularDofs<Dim>);
    if constexpr (Dim == 2) {
      s.orientation = {b.orientation};
    } else {
      s.orientation = {b.orientation.w(), b.orientation.x(), b.orientation.y(), b.orientation.z()};
    }
    out.push_back(s);
  }
  return out;
}

template class RigidWorld<2>;
template class RigidWorld<3>;

}  // namespace monolith
