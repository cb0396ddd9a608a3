#include "reference/monolithic_system.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "reference/mprgp.hpp"

namespace monolith {

template <int Dim>
MonolithicSystem<Dim>::MonolithicSystem(const MacGrid<Dim>& grid, StressForm form,
                                        const StokesWeights& w, double dt, const VectorX& u_star,
                                        const std::vector<RigidBody<Dim>>& bodies,
                                        const SolidWeights<Dim>& solids,
                                        const ContactSystem<Dim>& contacts,
                                        StokesUnknowns unknowns)
    : grid_(grid), stress_(grid), layout_(stress_, form), w_(w), dt_(dt), u_star_(u_star),
      contacts_(contacts) {
  // alpha = 1 / dx^Dim, shared with the contact blocks (section 4.1)
  alpha_ = 1.0 / std::pow(grid.dx(), Dim);
  if (std::abs(contacts.alpha - alpha_) > 1e-12 * alpha_)
    throw std::invalid_argument("MonolithicSystem: ContactSystem alpha differs from 1/dx^Dim");
  // the liquid blocks: eq. (8) restricted to the active DOFs
  dofs_ = select_stokes_dofs<Dim>(grid, layout_, w, dt, unknowns);
  stokes_ = assemble_explicit_stokes<Dim>(grid, layout_, w, dofs_, dt, u_star);
  const int nd = contacts.num_body_dofs();

  // B_1 = Jh_s W_L^s E S_tau^T, B_2 = Jh_p W_L^p S_p^T over the two-way bodies
  const std::vector<CouplingBody<Dim>> view = coupling_bodies(bodies);
  const BodyCouplingOperator<Dim> two(grid, view, solids, BodyGroup::two_way);
  const BodyCouplingOperator<Dim> one(grid, view, solids, BodyGroup::one_way);
  if (two.num_rows() != nd)
    throw std::invalid_argument("MonolithicSystem: bodies and ContactSystem disagree");
  const SparseMatrix b_tau = SparseMatrix(two.stress_jacobian() * stokes_.W_L_s) * stokes_.E *
                             SparseMatrix(stokes_.S_tau.transpose());
  const SparseMatrix b_p =
      SparseMatrix(two.pressure_jacobian() * stokes_.W_L_p) * SparseMatrix(stokes_.S_p.transpose());
  std::vector<Triplet> t;
  for (int k = 0; k < b_tau.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(b_tau, k); it; ++it)
      t.emplace_back(it.row(), it.col(), it.value());
  for (int k = 0; k < b_p.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(b_p, k); it; ++it)
      t.emplace_back(it.row(), num_stress() + it.col(), it.value());
  b_fluid_.resize(nd, num_fluid());
  b_fluid_.setFromTriplets(t.begin(), t.end());
  b_fluid_t_ = b_fluid_.transpose();
  j_lambda_t_ = contacts.j_lambda.transpose();
  j_z_t_ = contacts.j_z.transpose();

  // b1, b2: the liquid part, then alpha W_L J^T v* of both groups (subtracted; section 4.4.4)
  VectorX body_stress = VectorX::Zero(stress_.num_dofs());
  VectorX body_cells = VectorX::Zero(grid.num_cells());
  subtract_body_stress_rhs<Dim>(two, grid, w.liquid_stress, contacts.v_star, body_stress);
  subtract_body_pressure_rhs<Dim>(two, grid, w.pressure.liquid_cell, contacts.v_star, body_cells);
  const VectorX v_one = group_velocities(bodies, BodyGroup::one_way);
  if (one.num_rows() > 0) {
    subtract_body_stress_rhs<Dim>(one, grid, w.liquid_stress, v_one, body_stress);
    subtract_body_pressure_rhs<Dim>(one, grid, w.pressure.liquid_cell, v_one, body_cells);
  }
  b1_ = stokes_.b1 + stokes_.S_tau * (stokes_.E.transpose() * body_stress);
  b2_ = stokes_.b2 + stokes_.S_p * body_cells;
}

template <int Dim>
int MonolithicSystem<Dim>::block_size(int i) const {
  switch (i) {
    case 1: return num_stress();
    case 2: return num_pressure();
    case 3: return num_contacts();
    case 4: return num_friction();
    default: throw std::invalid_argument("MonolithicSystem: block index outside 1..4");
  }
}

template <int Dim>
VectorX MonolithicSystem<Dim>::body_force(int j, const VectorX& x) const {
  // B_j x in body space (nd)
  switch (j) {
    case 1: return b_fluid_.leftCols(num_stress()) * x;
    case 2: return b_fluid_.rightCols(num_pressure()) * x;
    case 3: return j_lambda_t_ * x;
    case 4: return j_z_t_ * x;
    default: throw std::invalid_argument("MonolithicSystem: block index outside 1..4");
  }
}

template <int Dim>
VectorX MonolithicSystem<Dim>::body_force_transpose(int i, const VectorX& f) const {
  switch (i) {
    case 1: return b_fluid_t_.topRows(num_stress()) * f;
    case 2: return b_fluid_t_.bottomRows(num_pressure()) * f;
    case 3: return contacts_.j_lambda * f;
    case 4: return contacts_.j_z * f;
    default: throw std::invalid_argument("MonolithicSystem: block index outside 1..4");
  }
}

template <int Dim>
VectorX MonolithicSystem<Dim>::apply_block(int i, int j, const VectorX& x) const {
  if (x.size() != block_size(j)) throw std::invalid_argument("MonolithicSystem: block size");
  // rigid part by sequential multiplication: dt alpha B_i^T (M_r^-1 (B_j x))
  VectorX y = VectorX::Zero(block_size(i));
  if (num_body_dofs() > 0) {
    const VectorX f = contacts_.m_r_inverse * body_force(j, x);
    y = (dt_ * alpha_) * body_force_transpose(i, f);
  }
  // fluid part (stokes_system.hpp): the (tau, p) blocks of A
  if (i <= 2 && j <= 2) {
    const int ns = num_stress();
    const int row0 = i == 1 ? 0 : ns, col0 = j == 1 ? 0 : ns;
    VectorX xf = VectorX::Zero(num_fluid());
    xf.segment(col0, x.size()) = x;
    const VectorX yf = stokes_.A * xf;
    y += yf.segment(row0, y.size());
  }
  return y;
}

template <int Dim>
Eigen::MatrixXd MonolithicSystem<Dim>::dense_matrix() const {
  int offset[5] = {0, 0, 0, 0, 0};
  for (int i = 1; i <= 4; ++i) offset[i] = offset[i - 1] + block_size(i);
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(offset[4], offset[4]);
  for (int j = 1; j <= 4; ++j)
    for (int c = 0; c < block_size(j); ++c) {
      VectorX e = VectorX::Zero(block_size(j));
      e[c] = 1.0;
      for (int i = 1; i <= 4; ++i)
        if (block_size(i) > 0) a.block(offset[i - 1], offset[j - 1] + c, block_size(i), 1) = apply_block(i, j, e);
    }
  return a;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::rhs() const {
  VectorX b(num_fluid() + num_contacts() + num_friction());
  b << b1_, b2_, b3(), b4();
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::mlcp_rhs(const VectorX& z) const {
  VectorX b(num_fluid() + num_contacts());
  b << b1_, b2_, b3();
  if (num_friction() > 0 && num_body_dofs() > 0) {
    // (A14 z, A24 z, A34 z) = dt alpha (B_1, B_2, J_lambda)^T M_r^-1 J_z^T z
    const VectorX f = contacts_.m_r_inverse * (j_z_t_ * z);
    b.head(num_fluid()) -= (dt_ * alpha_) * (b_fluid_t_ * f);
    b.tail(num_contacts()) -= (dt_ * alpha_) * (contacts_.j_lambda * f);
  }
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::friction_rhs(const VectorX& x) const {
  VectorX b = b4();
  if (num_friction() == 0 || num_body_dofs() == 0) return b;
  // b4 - dt alpha J_z M_r^-1 (B_f x_f + J_lambda^T lambda)
  const VectorX force = b_fluid_ * x.head(num_fluid()) + j_lambda_t_ * x.segment(num_fluid(), num_contacts());
  b -= (dt_ * alpha_) * (contacts_.j_z * (contacts_.m_r_inverse * force));
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::fluid_rhs(const VectorX& lambda, const VectorX& z) const {
  VectorX b(num_fluid());
  b << b1_, b2_;
  if (num_body_dofs() == 0 || num_fluid() == 0) return b;
  // dt alpha B_f^T M_r^-1 (J_lambda^T lambda + J_z^T z), in body space first
  VectorX force = VectorX::Zero(num_body_dofs());
  if (lambda.size() == num_contacts() && num_contacts() > 0) force += j_lambda_t_ * lambda;
  if (z.size() == num_friction() && num_friction() > 0) force += j_z_t_ * z;
  b -= (dt_ * alpha_) * (b_fluid_t_ * (contacts_.m_r_inverse * force));
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::contact_rhs(const VectorX& x_fluid, const VectorX& z) const {
  VectorX b = b3();
  if (num_body_dofs() == 0 || num_contacts() == 0) return b;
  // b3 - dt alpha J_lambda M_r^-1 (B_f x_f + J_z^T z)
  VectorX force = VectorX::Zero(num_body_dofs());
  if (x_fluid.size() == num_fluid() && num_fluid() > 0) force += b_fluid_ * x_fluid;
  if (z.size() == num_friction() && num_friction() > 0) force += j_z_t_ * z;
  b -= (dt_ * alpha_) * (contacts_.j_lambda * (contacts_.m_r_inverse * force));
  return b;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::fluid_body_force(const VectorX& x_fluid) const {
  return b_fluid_ * x_fluid;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::body_velocities(const VectorX& x_fluid, const VectorX& lambda,
                                               const VectorX& z) const {
  // eq. (21): the contact impulses (ContactSystem) plus the liquid's force
  const VectorX lam = lambda.size() == num_contacts() ? lambda : VectorX(VectorX::Zero(num_contacts()));
  const VectorX zz = z.size() == num_friction() ? z : VectorX(VectorX::Zero(num_friction()));
  VectorX v = contacts_.velocity_update(lam, zz);
  if (num_body_dofs() > 0) v += dt_ * (contacts_.m_r_inverse * fluid_body_force(x_fluid));
  return v;
}

template <int Dim>
VectorX MonolithicSystem<Dim>::pressure_cells(const VectorX& x_fluid) const {
  return scatter_stokes_pressure(dofs_, x_fluid, grid_.num_cells());
}

template <int Dim>
VectorX MonolithicSystem<Dim>::stress_full(const VectorX& x_fluid) const {
  return scatter_stress<Dim>(layout_, dofs_, x_fluid);
}

template <int Dim>
VectorX MonolithicSystem<Dim>::fluid_velocities(const VectorX& x_fluid) const {
  VectorX u = u_star_;
  apply_stokes_update<Dim>(grid_, layout_, w_, dt_, pressure_cells(x_fluid), stress_full(x_fluid), u);
  return u;
}

// ---------------------------------------------------------------------------------------------

namespace {

/// S = blockdiag(A_stokes, A33 + gamma diag(A33)).
template <int Dim>
SparseMatrix assemble_sparse_part(const MonolithicSystem<Dim>& s, double gamma) {
  const int nf = s.num_fluid(), nc = s.num_contacts();
  const SparseMatrix& a = s.stokes().A;
  SparseMatrix a33 = nc > 0 ? s.contacts().a33() : SparseMatrix(0, 0);
  a33.makeCompressed();
  // both blocks are row-major: copy them row by row in column order (no triplet sort)
  Eigen::VectorXi row_sizes(nf + nc);
  for (int i = 0; i < nf; ++i) row_sizes[i] = static_cast<int>(a.innerVector(i).nonZeros());
  for (int i = 0; i < nc; ++i) row_sizes[nf + i] = static_cast<int>(a33.innerVector(i).nonZeros());
  SparseMatrix m(nf + nc, nf + nc);
  m.reserve(row_sizes);
  for (int i = 0; i < nf; ++i)
    for (SparseMatrix::InnerIterator it(a, i); it; ++it) m.insert(i, it.col()) = it.value();
  for (int i = 0; i < nc; ++i)
    for (SparseMatrix::InnerIterator it(a33, i); it; ++it)
      m.insert(nf + i, nf + it.col()) = it.col() == i ? (1.0 + gamma) * it.value() : it.value();
  m.makeCompressed();
  return m;
}

/// Adds dt alpha diag(B_f^T M_r^-1 B_f) to the first n_tau + n_p entries of `diagonal`, column
/// by column of B_f (never the n x n product): the rigid part of the diagonal of A_ff (eq. (24))
/// that MonolithicOperator and FluidBodyOperator share.
template <int Dim>
void add_rigid_diagonal(const MonolithicSystem<Dim>& system, VectorX& diagonal) {
  if (system.num_body_dofs() == 0) return;
  const SparseMatrix& bf = system.fluid_body_jacobian();
  const SparseMatrix mb = system.contacts().m_r_inverse * bf;
  const SparseMatrix prod = bf.cwiseProduct(mb);
  const double scale = system.dt() * system.alpha();
  for (int k = 0; k < prod.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(prod, k); it; ++it) diagonal[it.col()] += scale * it.value();
}

/// true when the bodies do not feel the Stokes null vector n: no body DOFs, or
/// max |B_f n| <= 1e-12 max(1, sum |B_f|).
template <int Dim>
bool bodies_blind_to(const MonolithicSystem<Dim>& system, const VectorX& n) {
  if (system.num_body_dofs() == 0) return true;
  const double scale = std::max(1.0, system.fluid_body_jacobian().cwiseAbs().sum());
  return system.fluid_body_force(n).cwiseAbs().maxCoeff() <= 1e-12 * scale;
}

}  // namespace

template <int Dim>
MonolithicOperator<Dim>::MonolithicOperator(const MonolithicSystem<Dim>& system, double contact_boost)
    : system_(system),
      size_(system.num_fluid() + system.num_contacts()),
      num_fluid_(system.num_fluid()),
      sparse_(assemble_sparse_part(system, contact_boost)) {
  // diagonal: diag(S) + dt alpha diag(B_f^T M_r^-1 B_f), column by column of B_f
  diagonal_ = sparse_.diagonal();
  add_rigid_diagonal(system, diagonal_);
  // the Stokes null vectors the bodies do not feel
  for (const VectorX& n : system.dofs().null_space) {
    if (!bodies_blind_to(system, n)) continue;
    VectorX v = VectorX::Zero(size_);
    v.head(num_fluid_) = n;
    null_space_.push_back(v);
  }
}

template <int Dim>
void MonolithicOperator<Dim>::apply(const VectorX& x, VectorX& y) const {
  sparse_.apply(x, y);
  if (system_.num_body_dofs() == 0) return;
  const ContactSystem<Dim>& c = system_.contacts();
  const int nc = system_.num_contacts();
  const double scale = system_.dt() * system_.alpha();
  // g = M_r^-1 B_f x_f, h = M_r^-1 J_lambda^T lambda (body space, never n x n)
  const VectorX g = c.m_r_inverse * system_.fluid_body_force(x.head(num_fluid_));
  if (nc > 0) {
    const VectorX h = c.m_r_inverse * (c.j_lambda.transpose() * x.tail(nc));
    y.head(num_fluid_) += scale * (system_.fluid_body_jacobian().transpose() * (g + h));
    y.tail(nc) += scale * (c.j_lambda * g);
  } else {
    y.head(num_fluid_) += scale * (system_.fluid_body_jacobian().transpose() * g);
  }
}

template <int Dim>
Eigen::MatrixXd MonolithicOperator<Dim>::dense_matrix() const {
  Eigen::MatrixXd a(size_, size_);
  VectorX e = VectorX::Zero(size_), y;
  for (int j = 0; j < size_; ++j) {
    e[j] = 1.0;
    apply(e, y);
    a.col(j) = y;
    e[j] = 0.0;
  }
  return a;
}

template <int Dim>
FluidBodyOperator<Dim>::FluidBodyOperator(const MonolithicSystem<Dim>& system)
    : system_(system), size_(system.num_fluid()), sparse_(system.stokes().A) {
  // diagonal: diag(A_stokes) + dt alpha diag(B_f^T M_r^-1 B_f), column by column of B_f
  diagonal_ = sparse_.diagonal();
  add_rigid_diagonal(system, diagonal_);
  // the Stokes null vectors the bodies do not feel
  for (const VectorX& n : system.dofs().null_space)
    if (bodies_blind_to(system, n)) null_space_.push_back(n);
}

template <int Dim>
void FluidBodyOperator<Dim>::apply(const VectorX& x, VectorX& y) const {
  sparse_.apply(x, y);
  if (system_.num_body_dofs() == 0) return;
  // dt alpha B_f^T (M_r^-1 (B_f x)), right to left
  const VectorX g = system_.contacts().m_r_inverse * system_.fluid_body_force(x);
  y += (system_.dt() * system_.alpha()) * (system_.fluid_body_jacobian().transpose() * g);
}

template <int Dim>
SparseMatrixOperator friction_operator(const MonolithicSystem<Dim>& system, double contact_boost) {
  SparseMatrix a44 = system.contacts().a44();
  for (int k = 0; k < a44.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(a44, k); it; ++it)
      if (it.row() == it.col()) it.valueRef() *= 1.0 + contact_boost;
  return SparseMatrixOperator(a44);
}

JacobiScaledOperator::JacobiScaledOperator(const LinearOperator& a) : a_(a) {
  const VectorX d = a.diagonal();
  scale_.resize(d.size());
  diagonal_.resize(d.size());
  for (int i = 0; i < d.size(); ++i) {
    scale_[i] = d[i] > 0.0 ? 1.0 / std::sqrt(d[i]) : 1.0;
    diagonal_[i] = d[i] > 0.0 ? 1.0 : d[i];
  }
  for (const VectorX& n : a.null_space()) {
    const VectorX m = n.cwiseQuotient(scale_);
    null_space_.push_back(m / m.norm());
  }
}

void JacobiScaledOperator::apply(const VectorX& x, VectorX& y) const {
  a_.apply(scale_.cwiseProduct(x), y);
  y.array() *= scale_.array();
}

void JacobiScaledOperator::forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                         const std::vector<char>* active) const {
  // a sweep of S A S on (rhs, x) is a sweep of A on (S^-1 rhs, S x)
  VectorX xs = scale_.cwiseProduct(x);
  a_.forward_sweep(rhs.cwiseQuotient(scale_), xs, omega, active);
  x = xs.cwiseQuotient(scale_);
}

void JacobiScaledOperator::backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                          const std::vector<char>* active) const {
  VectorX xs = scale_.cwiseProduct(x);
  a_.backward_sweep(rhs.cwiseQuotient(scale_), xs, omega, active);
  x = xs.cwiseQuotient(scale_);
}

template <int Dim>
PvcUnifiedResult solve_pvc_unified(const MonolithicSystem<Dim>& system,
                                   const StaggeredSettings& settings,
                                   const PvcUnifiedOptions& options) {
  const double inf = std::numeric_limits<double>::infinity();
  const int nf = system.num_fluid(), nc = system.num_contacts(), nz = system.num_friction();
  const double gamma = settings.diagonal_boost;
  const MonolithicOperator<Dim> unscaled(system, gamma);
  // MPRGP runs on S A S (options.jacobi_scaling) or on A (S = I)
  const JacobiScaledOperator scaled(unscaled);
  const LinearOperator& op = options.jacobi_scaling ? static_cast<const LinearOperator&>(scaled)
                                                    : static_cast<const LinearOperator&>(unscaled);
  const VectorX s = options.jacobi_scaling ? scaled.scale() : VectorX(VectorX::Ones(nf + nc));
  // bounds of (26): tau, p free, lambda >= 0
  VectorX lower = VectorX::Constant(nf + nc, -inf), upper = VectorX::Constant(nf + nc, inf);
  lower.tail(nc).setZero();
  PvcUnifiedResult r;
  r.x = VectorX::Zero(nf + nc);
  r.z = VectorX::Zero(nz);
  // ||A|| once per operator for all the staggered solves (each would estimate it again)
  const MprgpSettings mlcp_settings = with_norm_estimate(op, settings.mprgp);
  auto solve_mlcp = [&]() {
    // in y = S^-1 x with right-hand side S b (the bounds 0 and +-inf are unchanged)
    VectorX y = r.x.cwiseQuotient(s);
    const MprgpResult m =
        mprgp_solve(op, s.cwiseProduct(system.mlcp_rhs(r.z)), lower, upper, y, mlcp_settings);
    r.x = s.cwiseProduct(y);
    r.mprgp_iterations += m.iterations;
    r.converged = r.converged && m.converged;
    r.max_relative_residual = std::max(r.max_relative_residual, m.relative_residual);
    if (m.breakdown && !r.breakdown) {
      r.breakdown = true;
      r.message = m.message;
    }
    ++r.staggered_iterations;
  };
  solve_mlcp();
  const bool friction = nc > 0 && system.contacts().mu.maxCoeff() > 0.0;
  if (friction) {
    const SparseMatrixOperator fop = friction_operator(system, gamma);
    const MprgpSettings friction_settings = with_norm_estimate(fop, settings.mprgp);
    for (int k = 1; k < std::max(1, settings.max_iterations); ++k) {
      // eq. (25): z given (tau, p, lambda), -mu lambda <= z <= mu lambda
      const VectorX lambda_old = r.x.tail(nc);
      VectorX zl(nz), zu(nz);
      for (int c = 0; c < nc; ++c)
        for (int j = 0; j < Dim - 1; ++j) {
          const double bound = system.contacts().mu[c] * lambda_old[c];
          zl[(Dim - 1) * c + j] = -bound;
          zu[(Dim - 1) * c + j] = bound;
        }
      const MprgpResult m = mprgp_solve(fop, system.friction_rhs(r.x), zl, zu, r.z, friction_settings);
      r.mprgp_iterations += m.iterations;
      r.converged = r.converged && m.converged;
      r.max_relative_residual = std::max(r.max_relative_residual, m.relative_residual);
      if (m.breakdown && !r.breakdown) {
        r.breakdown = true;
        r.message = m.message;
      }
      // eq. (26) given z
      solve_mlcp();
      const VectorX lambda_new = r.x.tail(nc);
      const double norm = std::max(lambda_new.cwiseAbs().maxCoeff(), 1e-300);
      r.last_change = (lambda_new - lambda_old).cwiseAbs().maxCoeff() / norm;
      if (r.last_change <= settings.tolerance) break;
    }
  }
  // eq. (8) and eq. (21) updates
  const VectorX xf = r.x.head(nf);
  r.lambda = r.x.tail(nc);
  if (!options.compute_updates) return r;
  r.stress = system.stress_full(xf);
  r.pressure = system.pressure_cells(xf);
  r.u = system.fluid_velocities(xf);
  r.body_velocity = system.body_velocities(xf, r.lambda, r.z);
  return r;
}

template class MonolithicSystem<2>;
template class MonolithicSystem<3>;
template class MonolithicOperator<2>;
template class MonolithicOperator<3>;
template class FluidBodyOperator<2>;
template class FluidBodyOperator<3>;
template SparseMatrixOperator friction_operator<2>(const MonolithicSystem<2>&, double);
template SparseMatrixOperator friction_operator<3>(const MonolithicSystem<3>&, double);
template PvcUnifiedResult solve_pvc_unified<2>(const MonolithicSystem<2>&, const StaggeredSettings&,
                                               const PvcUnifiedOptions&);
template PvcUnifiedResult solve_pvc_unified<3>(const MonolithicSystem<3>&, const StaggeredSettings&,
                                               const PvcUnifiedOptions&);

}  // namespace monolith
