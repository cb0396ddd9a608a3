/// \file contact_system.cpp
/// Assembly of the contact problem of section 3.2 / eq. (24) and the staggered projections of
/// section 4.2 for rigid bodies without liquid.

#include "reference/contact/contact_system.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "reference/contact/staggered_projections.hpp"

namespace monolith {

namespace {

/// Adds sign * [d^T, (r x d)^T] at `dof` in row `row` of a Jacobian: the angular part, since
/// d . (w x r) = w . (r x d) (2D: the scalar r_x d_y - r_y d_x).
template <int Dim>
void add_jacobian_row(std::vector<Triplet>& t, int row, int dof, const Vec<Dim>& d,
                      const Vec<Dim>& r, double sign) {
  for (int a = 0; a < Dim; ++a) t.emplace_back(row, dof + a, sign * d[a]);
  const AngularVec<Dim> ang = moment<Dim>(r, d);
  for (int a = 0; a < kAngularDofs<Dim>; ++a) t.emplace_back(row, dof + Dim + a, sign * ang[a]);
}

}  // namespace

template <int Dim>
std::vector<Vec<Dim>> contact_tangents(const Vec<Dim>& n) {
  if constexpr (Dim == 2) {
    return {Vec<Dim>(-n[1], n[0])};
  } else {
    // the axis least aligned with n gives a well-conditioned first tangent
    int axis = 0;
    n.cwiseAbs().minCoeff(&axis);
    const Vec<Dim> t1 = n.cross(Vec<Dim>::Unit(axis)).normalized();
    const Vec<Dim> t2 = n.cross(t1);  // right-handed (t1, t2, n)
    return {t1, t2};
  }
}

template <int Dim>
ContactSystem<Dim>::ContactSystem(const std::vector<RigidBody<Dim>>& bodies,
                                  const std::vector<Contact<Dim>>& contacts,
                                  const ContactParameters& p)
    : params(p) {
  constexpr int kDofs = kBodyDofs<Dim>;
  alpha = 1.0 / std::pow(p.dx, Dim);
  const double epsilon = p.margin_cells * p.dx;
  // dof numbering: dynamic bodies in body order
  body_dof.assign(bodies.size(), -1);
  int nd = 0;
  for (std::size_t i = 0; i < bodies.size(); ++i)
    if (bodies[i].motion == BodyMotion::dynamic) {
      body_dof[i] = nd;
      nd += kDofs;
    }
  num_dynamic_bodies = nd / kDofs;
  // v* and the block-diagonal M_r, M_r^-1
  v_star = VectorX::Zero(nd);
  std::vector<Triplet> mt, mit;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    const int d = body_dof[i];
    if (d < 0) continue;
    const RigidBody<Dim>& b = bodies[i];
    v_star.template segment<kDofs>(d) = b.generalized_velocity();
    for (int a = 0; a < Dim; ++a) {
      mt.emplace_back(d + a, d + a, b.mass);
      mit.emplace_back(d + a, d + a, 1.0 / b.mass);
    }
    const AngularMat<Dim> iw = b.world_inertia();
    const AngularMat<Dim> iwi = b.world_inverse_inertia();
    for (int r = 0; r < kAngularDofs<Dim>; ++r)
      for (int c = 0; c < kAngularDofs<Dim>; ++c) {
        mt.emplace_back(d + Dim + r, d + Dim + c, iw(r, c));
        mit.emplace_back(d + Dim + r, d + Dim + c, iwi(r, c));
      }
  }
  m_r.resize(nd, nd);
  m_r.setFromTriplets(mt.begin(), mt.end());
  m_r_inverse.resize(nd, nd);
  m_r_inverse.setFromTriplets(mit.begin(), mit.end());

  // contact rows
  const int nc = static_cast<int>(contacts.size());
  constexpr int kT = Dim - 1;
  known_normal_velocity = VectorX::Zero(nc);
  known_tangent_velocity = VectorX::Zero(kT * nc);
  restitution_scale = VectorX::Ones(nc);
  phi = VectorX::Zero(nc);
  mu = VectorX::Zero(nc);
  normals.resize(nc);
  tangents.clear();
  dynamic_pairs.assign(nc, {-1, -1});
  std::vector<Triplet> jl, jz;
  for (int c = 0; c < nc; ++c) {
    const Contact<Dim>& k = contacts[c];
    const Vec<Dim> n = k.normal;
    normals[c] = n;
    const std::vector<Vec<Dim>> t = contact_tangents<Dim>(n);
    tangents.insert(tangents.end(), t.begin(), t.end());
    phi[c] = k.phi + epsilon;
    mu[c] = k.friction;
    // each side: +1 for a (n points from b to a), -1 for b
    const int sides[2] = {k.body_a, k.body_b};
    const double signs[2] = {1.0, -1.0};
    for (int s = 0; s < 2; ++s) {
      const int bi = sides[s];
      if (bi < 0) continue;  // a wall: at rest
      const RigidBody<Dim>& b = bodies[bi];
      const int d = body_dof[bi];
      if (d >= 0) {
        // dynamic: a Jacobian entry
        const Vec<Dim> r = b.nearest_image(k.point) - b.position;
        add_jacobian_row<Dim>(jl, c, d, n, r, signs[s]);
        for (int j = 0; j < kT; ++j) add_jacobian_row<Dim>(jz, kT * c + j, d, t[j], r, signs[s]);
        (s == 0 ? dynamic_pairs[c].first : dynamic_pairs[c].second) = d / kDofs;
      } else {
        // fixed or kinematic: its known velocity goes to the right-hand side (section 4.4.4)
        const Vec<Dim> u = b.point_velocity(k.point);
        known_normal_velocity[c] += signs[s] * n.dot(u);
        for (int j = 0; j < kT; ++j) known_tangent_velocity[kT * c + j] += signs[s] * t[j].dot(u);
      }
    }
  }
  j_lambda.resize(nc, nd);
  j_lambda.setFromTriplets(jl.begin(), jl.end());
  j_z.resize(kT * nc, nd);
  j_z.setFromTriplets(jz.begin(), jz.end());
  // C = I + R per contact row: restitution only on contacts approaching faster than the
  // threshold whose gap (with the margin) closes within this step
  const VectorX approach = normal_velocity(v_star);
  for (int c = 0; c < nc; ++c)
    if (approach[c] < -p.restitution_threshold && phi[c] + p.dt * approach[c] <= 0.0)
      restitution_scale[c] = 1.0 + contacts[c].restitution;
}

template <int Dim>
SparseMatrix ContactSystem<Dim>::a33() const {
  SparseMatrix a = (params.dt * alpha) * (j_lambda * m_r_inverse * SparseMatrix(j_lambda.transpose()));
  return a;
}

template <int Dim>
SparseMatrix ContactSystem<Dim>::a34() const {
  SparseMatrix a = (params.dt * alpha) * (j_lambda * m_r_inverse * SparseMatrix(j_z.transpose()));
  return a;
}

template <int Dim>
SparseMatrix ContactSystem<Dim>::a44() const {
  SparseMatrix a = (params.dt * alpha) * (j_z * m_r_inverse * SparseMatrix(j_z.transpose()));
  return a;
}

template <int Dim>
VectorX ContactSystem<Dim>::normal_velocity(const VectorX& v) const {
  VectorX u = known_normal_velocity;
  if (num_body_dofs() > 0) u += j_lambda * v;
  return u;
}

template <int Dim>
VectorX ContactSystem<Dim>::tangent_velocity(const VectorX& v) const {
  VectorX u = known_tangent_velocity;
  if (num_body_dofs() > 0) u += j_z * v;
  return u;
}

template <int Dim>
VectorX ContactSystem<Dim>::b3() const {
  const int nc = num_contacts();
  const VectorX un = normal_velocity(v_star);
  VectorX b(nc);
  for (int c = 0; c < nc; ++c) {
    // the lowest admissible relative normal velocity after the step
    // (eq. (16)'s recovery -beta phi / dt, at most max_recovery_speed: a penetration is pushed
    // out at a speed that does not grow without bound as dt shrinks)
    double target = 0.0;
    if (restitution_scale[c] > 1.0)
      target = -(restitution_scale[c] - 1.0) * un[c] +
               std::min(-params.baumgarte * std::min(phi[c], 0.0) / params.dt, params.max_recovery_speed);
    else if (phi[c] <= 0.0)
      target = std::min(-params.baumgarte * phi[c] / params.dt, params.max_recovery_speed);
    else
      target = -phi[c] / params.dt;
    // with restitution the target holds -R u*, so -alpha (u* - target) = -alpha (C u* + ...)
    b[c] = -alpha * (un[c] - target);
  }
  return b;
}

template <int Dim>
VectorX ContactSystem<Dim>::b4() const {
  return -alpha * tangent_velocity(v_star);
}

template <int Dim>
VectorX ContactSystem<Dim>::velocity_update(const VectorX& lambda, const VectorX& z) const {
  VectorX f = VectorX::Zero(num_body_dofs());
  if (lambda.size()) f += SparseMatrix(j_lambda.transpose()) * lambda;
  if (z.size()) f += SparseMatrix(j_z.transpose()) * z;
  return v_star + params.dt * (m_r_inverse * f);
}

template <int Dim>
StaggeredResult solve_staggered_projections(const ContactSystem<Dim>& system,
                                            const StaggeredSettings& settings,
                                            const VectorX& lambda0, const VectorX& z0) {
  StaggeredResult result;
  const int nc = system.num_contacts();
  const int nf = system.num_friction_rows();
  result.lambda = lambda0.size() == nc ? lambda0 : VectorX::Zero(nc);
  result.z = z0.size() == nf ? z0 : VectorX::Zero(nf);
  if (nc == 0) return result;
  const ContactQpOperators<Dim> qp(system, settings);
  if (!qp.friction()) result.z.setZero();
  const VectorX b3 = system.b3();

  auto record = [&result](const MprgpResult& r) {
    result.mprgp_iterations += r.iterations;
    result.max_relative_residual = std::max(result.max_relative_residual, r.relative_residual);
    result.converged = result.converged && r.converged;
  };
  // eq. (26) without tau and p (eq. (16) when z = 0): normal forces given the friction
  const SparseMatrix a34 = qp.friction() ? system.a34() : SparseMatrix();
  auto solve_normal = [&]() {
    const VectorX rhs = qp.friction() ? VectorX(b3 - a34 * result.z) : b3;
    record(mprgp_solve(qp.normal(), rhs, qp.normal_lower(), qp.normal_upper(), result.lambda,
                       qp.normal_settings()));
  };
  if (!qp.friction()) {
    // mu = 0: a single normal solve
    solve_normal();
    result.staggered_iterations = 1;
    return result;
  }
  // eq. (25): friction given lambda
  const SparseMatrix a34t = a34.transpose();
  const VectorX b4 = system.b4();
  auto solve_friction = [&](const VectorX& lower, const VectorX& upper) {
    record(mprgp_solve(qp.tangential(), b4 - a34t * result.lambda, lower, upper, result.z,
                       qp.friction_settings()));
  };
  const StaggeredRounds rounds = staggered_rounds<Dim>(
      system.mu, settings.max_iterations, 0, settings.tolerance,
      [&]() { return result.lambda; }, solve_friction, solve_normal);
  result.staggered_iterations = rounds.rounds;
  result.last_change = rounds.last_change;
  return result;
}

template std::vector<Vec<2>> contact_tangents<2>(const Vec<2>&);
template std::vector<Vec<3>> contact_tangents<3>(const Vec<3>&);
template class ContactSystem<2>;
template class ContactSystem<3>;
template StaggeredResult solve_staggered_projections<2>(const ContactSystem<2>&,
                                                        const StaggeredSettings&, const VectorX&,
                                                        const VectorX&);
template StaggeredResult solve_staggered_projections<3>(const ContactSystem<3>&,
                                                        const StaggeredSettings&, const VectorX&,
                                                        const VectorX&);

}  // namespace monolith
