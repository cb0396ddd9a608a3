#pragma once
/// \file contact_system.hpp
/// The rigid-body contact problem of section 3.2 (eqs. (9)-(16)) in the scaled form of section
/// 4.1, restricted to bodies (no liquid): the Jacobians J_lambda and J_z, the mass matrix M_r,
/// the restitution matrix C = I + R, the Baumgarte-stabilised gap, the blocks A33, A34, A44 and
/// b3, b4 of eq. (24), the velocity update of eqs. (13)/(21), and the staggered projections of
/// section 4.2 (eqs. (25)-(26) without the tau and p blocks) solved with MPRGP.
///
/// DOF layout. Only dynamic bodies carry unknowns: kBodyDofs<Dim> per body (linear velocity,
/// then angular velocity: 2D [vx, vy, omega], 3D [vx, vy, vz, wx, wy, wz]), in body order,
/// skipping fixed and kinematic bodies. Those enter through their known velocity only (the
/// one-way part of section 4.4.4: M_r^-1 = 0 for them, their velocity goes to the right-hand
/// side). Contact rows follow the order of the contact list; friction rows are (Dim - 1) per
/// contact, contact c owning rows (Dim - 1) c ... (Dim - 1) c + Dim - 2.

#include <limits>
#include <utility>
#include <vector>

#include "reference/contact/collision.hpp"
#include "reference/core/common.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "reference/solvers/mprgp.hpp"

namespace monolith {

/// Parameters of the contact QP for one time step.
struct ContactParameters {
  double dt = 0.0;
  /// Cell width dx (m): sets the margin epsilon = margin_cells dx and alpha = 1 / dx^Dim.
  double dx = 1.0;
  /// beta of eq. (16).
  double baumgarte = 0.2;
  /// The largest speed (m/s) at which eq. (16) pushes a penetration out: the recovery target
  /// -beta phi / dt becomes min(-beta phi / dt, max_recovery_speed). Departure from the paper
  /// (docs/rigid-bodies.md, "A cap on the recovery speed"): -beta phi / dt grows without bound as
  /// dt shrinks, and the speed stays with the body after the step. Infinite (no cap) by default
  /// here; the simulator sets solver.max_recovery_speed (RigidWorldSettings::from_scene).
  double max_recovery_speed = std::numeric_limits<double>::infinity();
  /// epsilon of section 3.2.4 in units of dx (solver.contact_margin).
  double margin_cells = 0.1;
  /// Restitution acts only on contacts approaching faster than this (m/s); resting contacts,
  /// whose approach speed is of the order of |g| dt (one step of gravity), do not bounce. The
  /// world passes 2 |g| dt.
  double restitution_threshold = 0.0;
};

/// The assembled contact problem of one step. Shapes: nc = number of contacts, nf = (Dim - 1) nc
/// friction rows, nd = kBodyDofs<Dim> x number of dynamic bodies.
template <int Dim>
class ContactSystem {
 public:
  ContactSystem() = default;
  /// Assembles J_lambda, J_z, M_r, C and the known-velocity terms for `contacts` between
  /// `bodies` (walls are body index -1). The velocities of the bodies are v* (gravity applied).
  ContactSystem(const std::vector<RigidBody<Dim>>& bodies, const std::vector<Contact<Dim>>& contacts,
                const ContactParameters& params);

  int num_contacts() const { return static_cast<int>(phi.size()); }
  int num_friction_rows() const { return (Dim - 1) * num_contacts(); }
  int num_body_dofs() const { return static_cast<int>(v_star.size()); }

  /// eqs. (9)/(10): J_lambda, nc x nd. Row c is the relative normal velocity of contact c,
  /// n^T (v_a + w_a x r_a) - n^T (v_b + w_b x r_b) with r = point - centre of mass and n pointing
  /// from b to a, restricted to the dynamic bodies' DOFs: positive = separating. Its transpose
  /// maps a normal force lambda_c (>= 0 pushes a away from b) to generalized forces.
  SparseMatrix j_lambda;
  /// eq. (13): J_z, nf x nd. Row (c, k) is t_k^T (relative velocity of contact c) for the
  /// orthonormal tangents t_k of contact c (t_k . n = 0); sign as J_lambda. The symmetric pyramid
  /// of eq. (14) bounds each row independently: -mu_c lambda_c <= z_(c,k) <= mu_c lambda_c.
  SparseMatrix j_z;
  /// M_r, nd x nd, block diagonal: m I (Dim x Dim) and the world inertia I_w (kAngularDofs x
  /// kAngularDofs) per dynamic body. Symmetric positive definite.
  SparseMatrix m_r;
  /// M_r^-1, nd x nd: (1/m) I and I_w^-1 per dynamic body.
  SparseMatrix m_r_inverse;
  /// v*, nd: the dynamic bodies' generalized velocities before contact (eq. (10)).
  VectorX v_star;
  /// The part of each contact's relative normal velocity that comes from fixed and kinematic
  /// bodies and walls (known velocities; section 4.4.4), nc. The relative normal velocity is
  /// J_lambda v + known_normal_velocity.
  VectorX known_normal_velocity;
  /// The same for the friction rows, nf.
  VectorX known_tangent_velocity;
  /// Diagonal of C = I + R (eq. (11)) per contact row, nc: 1 + max(e_a, e_b) on contacts
  /// approaching faster than the restitution threshold whose gap phi + epsilon closes within
  /// the step (phi + dt u* <= 0), 1 otherwise. Departure: the paper's R is
  /// per body; the scene contract combines restitution per pair, so C acts on contact rows,
  /// (I + R) J_lambda v* instead of J_lambda (I + R) v*. For one contact with a static partner
  /// both read the same.
  VectorX restitution_scale;
  /// phi + epsilon per contact (m), nc: the gap with the margin of section 3.2.4.
  VectorX phi;
  /// Friction coefficient per contact (sqrt(mu_a mu_b), walls: domain.wall_friction), nc.
  VectorX mu;
  /// Unit tangents per contact, (Dim - 1) per contact in row order.
  std::vector<Vec<Dim>> tangents;
  /// Normals per contact (from b to a).
  std::vector<Vec<Dim>> normals;
  /// Index of the first DOF of each body, -1 for bodies without DOFs (fixed, kinematic).
  std::vector<int> body_dof;
  /// alpha = 1 / dx^Dim of section 4.1 (the scale shared with the liquid blocks of eq. (24)).
  double alpha = 1.0;
  ContactParameters params;

  /// eq. (24): A33 = dt alpha J_lambda M_r^-1 J_lambda^T, nc x nc, symmetric positive
  /// semi-definite (definite when J_lambda has full row rank).
  SparseMatrix a33() const;
  /// eq. (24): A34 = dt alpha J_lambda M_r^-1 J_z^T, nc x nf.
  SparseMatrix a34() const;
  /// eq. (24): A44 = dt alpha J_z M_r^-1 J_z^T, nf x nf, symmetric positive semi-definite.
  SparseMatrix a44() const;
  /// eqs. (16)/(24): b3 = -alpha (C (J_lambda v* + g_n) - target), nc, where g_n is the known
  /// relative normal velocity and target the lowest admissible relative normal velocity after the
  /// step: with phi = phi + epsilon,
  ///   - restitution active: target = -e (J_lambda v* + g_n) - beta min(phi, 0)/dt, i.e. the
  ///     paper's b3 = -alpha (C J_lambda v* + beta min(phi, 0)/dt);
  ///   - otherwise, phi <= 0: target = -beta phi / dt (eq. (16): push out a fraction beta of the
  ///     penetration beyond the margin per step);
  ///   - otherwise, phi > 0: target = -phi / dt. Departure: the paper's contacts have phi <= 0;
  ///     ours are found up to a search distance ahead (a speculative contact), and such a contact
  ///     may close its gap within the step but not more. Without it a body would stop at the
  ///     search distance.
  /// A33 lambda - b3 = alpha (relative normal velocity after the step - target): the Signorini
  /// conditions 0 <= lambda perp A33 lambda - b3 >= 0 of eqs. (9)/(16).
  VectorX b3() const;
  /// eq. (24): b4 = -alpha (J_z v* + g_t), nf (g_t: known tangential velocity). A44 z - b4 +
  /// A34^T lambda = alpha (tangential velocity after the step).
  VectorX b4() const;
  /// eqs. (13)/(21): v = v* + dt M_r^-1 (J_lambda^T lambda + J_z^T z), nd. The alpha of eq. (21)
  /// scales the mass and the forces alike and cancels.
  VectorX velocity_update(const VectorX& lambda, const VectorX& z) const;
  /// Relative normal velocity J_lambda v + g_n per contact for generalized velocities v (nd).
  VectorX normal_velocity(const VectorX& v) const;
  /// Relative tangential velocity J_z v + g_t per friction row.
  VectorX tangent_velocity(const VectorX& v) const;
  /// The two dynamic-body indices of each contact (index among the dynamic bodies; -1 for a
  /// wall, a fixed or a kinematic body): the input of contact_adjacency for the colouring.
  std::vector<std::pair<int, int>> dynamic_pairs;
  /// Number of dynamic bodies (nd / kBodyDofs<Dim>).
  int num_dynamic_bodies = 0;
};

/// Settings of the staggered projections.
struct StaggeredSettings {
  /// Outer iterations at most (solver.staggered_iterations, at least 1).
  int max_iterations = 2;
  /// Stop when ||lambda^(k+1) - lambda^k||_inf <= tolerance max(||lambda^(k+1)||_inf, tiny).
  double tolerance = 1e-6;
  /// gamma of section 4.4.5 (solver.diagonal_boost).
  double diagonal_boost = 1e-4;
  /// Settings of each MPRGP solve.
  MprgpSettings mprgp;
};

struct StaggeredResult {
  VectorX lambda;  ///< nc normal forces (N; N/m in 2D): alpha scales the equations, not lambda
  VectorX z;       ///< nf friction forces
  int staggered_iterations = 0;  ///< normal solves performed
  long mprgp_iterations = 0;     ///< summed over every QP solve
  double max_relative_residual = 0.0;
  bool converged = true;  ///< every QP solve converged
  /// Relative change of lambda in the last outer iteration (0 with one iteration).
  double last_change = 0.0;
};

/// Staggered projections (Kaufman et al. 2008) as in section 4.2 without the liquid blocks:
/// with mu = 0 everywhere, one normal QP; otherwise, alternately
///   eq. (25): z^(k+1) = argmin 1/2 z^T A44 z - (b4 - A34^T lambda^k)^T z,
///             -mu lambda^k <= z <= mu lambda^k,
///   eq. (26): lambda^(k+1) = argmin 1/2 l^T A33 l - (b3 - A34 z^(k+1))^T l,  l >= 0,
/// (the loop of staggered_rounds, staggered_projections.hpp) until lambda changes by less than
/// the tolerance or max_iterations is reached, always ending on
/// the normal solve. Each QP is solved by MPRGP on A (1 + gamma) on the diagonal (section 4.4.5)
/// with the SSOR preconditioner, its sweeps run in parallel over Welsh-Powell colours of the
/// contact graph. `lambda0` and `z0` are a warm start (size nc and nf, or empty for zero).
template <int Dim>
StaggeredResult solve_staggered_projections(const ContactSystem<Dim>& system,
                                            const StaggeredSettings& settings,
                                            const VectorX& lambda0 = VectorX(),
                                            const VectorX& z0 = VectorX());

/// Orthonormal tangents of a unit normal: 2D the normal turned by +90 degrees; 3D two vectors
/// completing a right-handed frame (t1, t2, n).
template <int Dim>
std::vector<Vec<Dim>> contact_tangents(const Vec<Dim>& n);

}  // namespace monolith
