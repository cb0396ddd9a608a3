/// \file coupled_preconditioner.cpp
/// The block preconditioner of the coupled systems (24)/(26) (coupled_preconditioner.hpp).

#include "reference/coupling/coupled_preconditioner.hpp"

#include <algorithm>
#include <stdexcept>

#include <Eigen/Eigenvalues>

#include "reference/core/parallel.hpp"
#include "reference/fluid/velocity_operator.hpp"

namespace monolith {

namespace {

constexpr int kParallelRows = 4096;

/// y -= M c for a dense m (rows x cols), row by row: each row's sum over the columns in column
/// order, rows in parallel above kParallelRows (the same bits for any thread count).
void subtract_dense_product(const Eigen::MatrixXd& m, const VectorX& c, VectorX& y) {
  const int rows = static_cast<int>(m.rows()), cols = static_cast<int>(m.cols());
  const double* x = c.data();
  double* out = y.data();
#pragma omp parallel for schedule(static) if (rows > kParallelRows) num_threads(process_threads())
  for (int i = 0; i < rows; ++i) {
    double sum = 0.0;
    for (int k = 0; k < cols; ++k) sum += m(i, k) * x[k];
    out[i] -= sum;
  }
}

/// The factors B, C, K of the system's fluid part F (either back end).
template <int Dim>
StokesFactors coupled_stokes_factors(const MonolithicSystem<Dim>& s, double floor) {
  if (s.matrix_free())
    return stokes_factors<Dim>(s.grid(), s.layout(), s.weights(), s.dofs(), s.dt(),
                               static_cast<const MatrixFreeStokesOperator<Dim>&>(s.stokes_operator()),
                               floor);
  return stokes_factors<Dim>(s.grid(), s.layout(), s.weights(), s.dofs(), s.dt(), s.stokes(), floor);
}

}  // namespace

template <int Dim>
CoupledPreconditioner<Dim>::CoupledPreconditioner(const MonolithicSystem<Dim>& system,
                                                  bool with_contacts,
                                                  const VectorX& contact_diagonal,
                                                  const CoupledPreconditionerOptions& options)
    : s_(system) {
  nf_ = system.num_fluid();
  nc_ = with_contacts ? system.num_contacts() : 0;
  n_ = nf_ + nc_;
  if (nc_ > 0) {
    if (contact_diagonal.size() != nc_)
      throw std::invalid_argument("CoupledPreconditioner: contact diagonal of the wrong size");
    contact_inverse_.resize(nc_);
    // (a row with no diagonal, which no contact of a two-way body has, keeps the identity)
    for (int i = 0; i < nc_; ++i)
      contact_inverse_[i] = contact_diagonal[i] > 0.0 ? 1.0 / contact_diagonal[i] : 1.0;
  }
  rf_.setZero(nf_);
  zf_.setZero(nf_);
  if (nf_ == 0) return;
  const int nd = system.num_body_dofs();
  const bool correct = options.body_correction && nd > 0 && nd <= options.max_body_dofs;
  // B_f^T, column by column (a body that touches no fluid unknown has zero columns)
  Eigen::MatrixXd bft;
  std::vector<char> nonzero(nd, 0);
  bool coupled = false;
  if (correct) {
    bft.setZero(nf_, nd);
    VectorX e = VectorX::Zero(nd);
    for (int k = 0; k < nd; ++k) {
      e.setZero();
      e[k] = 1.0;
      bft.col(k) = system.fluid_body_force_transpose(e);
      nonzero[k] = bft.col(k).cwiseAbs().maxCoeff() != 0.0;
      coupled = coupled || nonzero[k];
    }
  }
  // W = dt alpha M_r^-1
  Eigen::MatrixXd w;
  if (correct) w = (system.dt() * system.alpha()) * Eigen::MatrixXd(system.contacts().m_r_inverse);
  StokesPreconditionerOptions fluid_options = options.fluid;
  if (coupled && options.empty_cell_ratio > 0.0) {
    // (P8): the near-empty cells where the body term dominates their Poisson row, with A_ff's
    // diagonal there, F + diag(B_f^T W B_f), in their Jacobi term (with F's alone, P would be up
    // to 1e16 times too large on them and Q = P - U (..)^-1 U^T would cancel in round-off:
    // docs/preconditioners.md sections 21 and 23)
    const int ns = system.num_stress();
    const Eigen::MatrixXd bw = bft.bottomRows(nf_ - ns) * w;
    fluid_options.empty_cell_ratio = options.empty_cell_ratio;
    fluid_options.empty_cell_extra = bw.cwiseProduct(bft.bottomRows(nf_ - ns)).rowwise().sum().cwiseMax(0.0);
    fluid_options.empty_cell_extra_ratio = options.empty_cell_body_ratio;
    fluid_options.empty_cell_jacobi = !options.exact_empty_cells;
  }
  fluid_ = std::make_unique<StokesPreconditioner<Dim>>(
      system.grid(), system.stokes_operator(),
      coupled_stokes_factors(system, options.fluid.min_fluid_fraction), fluid_options);
  if (!correct) return;
  // (P11) no correction on a contact-free system whose P marks no near-empty cell: the body
  // term is left to PCG (docs/preconditioners.md section 30)
  if (coupled && !with_contacts && !options.contact_free_correction && fluid_->empty_cells().empty())
    return;
  // the near-empty cells E, solved exactly with the body term: P = blkdiag(P_r, 0) and
  // Q^-1 = blkdiag(P_r^-1, F_EE) + B_f^T W B_f, inverted by block elimination of E (the file
  // comment; docs/preconditioners.md section 23)
  Eigen::MatrixXd w_body = w;  // W' = (W^-1 + B_E F_EE^-1 B_E^T)^-1 (W without E)
  if (coupled && !fluid_options.empty_cell_jacobi && !fluid_->empty_cells().empty()) {
    const int ns = system.num_stress();
    const int ne = static_cast<int>(fluid_->empty_cells().size());
    empty_.resize(ne);
    for (int q = 0; q < ne; ++q) empty_[q] = ns + fluid_->empty_cells()[q];
    // F_EE, column by column from F (either back end), its pressure diagonal scaled by 1 + 1e-10
    // (a group of near-empty cells closed all round would make it only semi-definite)
    Eigen::MatrixXd fee(ne, ne);
    VectorX e = VectorX::Zero(nf_), fe(nf_);
    for (int q = 0; q < ne; ++q) {
      e[empty_[q]] = 1.0;
      system.stokes_operator().apply(e, fe);
      e[empty_[q]] = 0.0;
      for (int p = 0; p < ne; ++p) fee(p, q) = fe[empty_[p]];
    }
    fee = 0.5 * (fee + fee.transpose()).eval();
    // B_E^T (ne x nd) and B_r^T (bft with the rows of E zero)
    empty_body_.resize(ne, nd);
    for (int q = 0; q < ne; ++q) {
      empty_body_.row(q) = bft.row(empty_[q]);
      bft.row(empty_[q]).setZero();
    }
    const double floor_ratio = options.empty_cell_floor;
    for (int q = 0; q < ne; ++q) {
      const double d = empty_body_.row(q).dot(w * empty_body_.row(q).transpose());
      fee(q, q) = std::max(fee(q, q) * (1.0 + 1e-10), floor_ratio * d);
    }
    const Eigen::LLT<Eigen::MatrixXd> fee_factor(fee);
    // H = F_EE + B_E^T W B_E and K_E = H^-1 B_E^T W (ne x nd)
    Eigen::MatrixXd h = fee + empty_body_ * w * empty_body_.transpose();
    h = 0.5 * (h + h.transpose()).eval();
    empty_factor_.compute(h);
    if (fee_factor.info() == Eigen::Success && empty_factor_.info() == Eigen::Success) {
      empty_gain_ = empty_factor_.solve(empty_body_ * w);
      // W' = S (I + Y Y^T)^-1 S, S = W^1/2, Y = S B_E L^-T (F_EE = L L^T): symmetric positive
      // semi-definite by construction (W - W B_E H^-1 B_E^T W would cancel where E locks the body)
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ws(0.5 * (w + w.transpose()));
      const Eigen::MatrixXd root = ws.eigenvectors() * ws.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal() *
                                   ws.eigenvectors().transpose();
      const Eigen::MatrixXd y = fee_factor.matrixL().solve(empty_body_ * root).transpose();  // nd x ne
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ys(Eigen::MatrixXd::Identity(nd, nd) + y * y.transpose());
      w_body = root * ys.eigenvectors() * ys.eigenvalues().cwiseInverse().asDiagonal() *
               ys.eigenvectors().transpose() * root;
      w_body = 0.5 * (w_body + w_body.transpose()).eval();
      body_transpose_ = bft;
      er_.setZero(ne);
      ex_.setZero(ne);
      et_.setZero(nd);
    } else {
      empty_.clear();  // not usable: P's zero rows stay (the Krylov method sees them as before P8)
    }
  }
  // U = P B_f^T, column by column (an application of P per non-zero column of B_f^T; with no
  // non-zero column at all there is nothing to correct: Q = P)
  u_.setZero(nf_, nd);
  VectorX pz(nf_);
  for (int k = 0; k < nd; ++k) {
    if (!nonzero[k]) continue;
    fluid_->apply(VectorX(bft.col(k)), pz);
    u_.col(k) = pz;
  }
  if (!coupled) {
    // B_f = 0: Q = P, A_f3 = 0, S_c = A33' exactly
    u_.resize(0, 0);
    setup_exact_contacts(contact_diagonal, w, w, w, options);
    return;
  }
  // B_f U (nd x nd), symmetric in exact arithmetic
  Eigen::MatrixXd bu(nd, nd);
  VectorX f(nd);
  for (int k = 0; k < nd; ++k) {
    system.fluid_body_force_into(u_.col(k), f);
    bu.col(k) = f;
  }
  bu = 0.5 * (bu + bu.transpose()).eval();
  // (W^-1 + B_f U)^-1 = W (I + B_f U W)^-1 (no inverse of M_r^-1 formed; W' in W's place with E)
  const Eigen::MatrixXd t = Eigen::MatrixXd::Identity(nd, nd) + bu * w_body;
  small_inv_ = w_body * t.partialPivLu().inverse();
  small_inv_ = 0.5 * (small_inv_ + small_inv_.transpose()).eval();
  nd_ = nd;
  force_.setZero(nd_);
  coeff_.setZero(nd_);
  bu_ = bu;
  setup_exact_contacts(contact_diagonal, w, w_body, small_inv_, options);
}

template <int Dim>
void CoupledPreconditioner<Dim>::setup_exact_contacts(const VectorX& contact_diagonal,
                                                      const Eigen::MatrixXd& w,
                                                      const Eigen::MatrixXd& w_body,
                                                      const Eigen::MatrixXd& w_effective,
                                                      const CoupledPreconditionerOptions& options) {
  if (nc_ == 0 || nc_ > options.max_exact_contacts) return;
  const Eigen::MatrixXd j(s_.contacts().j_lambda);  // nc x nd
  if (j.rows() != nc_ || j.cols() != w.rows()) return;
  jw_ = j * w;
  if (!empty_.empty()) j_ = j;
  // S_c = J W_eff J^T + gamma diag(A33), gamma diag(A33) = diag(A33') - diag(J W J^T)
  schur_ = j * w_effective * j.transpose();
  schur_ = 0.5 * (schur_ + schur_.transpose()).eval();
  for (int i = 0; i < nc_; ++i) {
    const double boost = contact_diagonal[i] - jw_.row(i).dot(j.row(i));
    schur_(i, i) += std::max(0.0, boost);
  }
  // Q A_f3 = Q B_f^T W J^T = U (I - (W^-1 + B_f U)^-1 B_f U) W J^T (zero when B_f = 0)
  if (nd_ > 0)
    back_ = (Eigen::MatrixXd::Identity(nd_, nd_) - small_inv_ * bu_) * (j * w_body).transpose();
  // usable only if positive definite (every principal submatrix then is)
  Eigen::LLT<Eigen::MatrixXd> check(schur_);
  if (check.info() != Eigen::Success) return;
  masked_.setZero(nc_, nc_);
  factored_free_.clear();
  yc_.setZero(nc_);
  rc_.setZero(nc_);
  bq_.setZero(w.rows());
  t_.setZero(w.rows());
  exact_contacts_ = true;
}

template <int Dim>
void CoupledPreconditioner<Dim>::apply(const VectorX& r, VectorX& z) const {
  z.resize(n_);
  if (nf_ > 0) {
    rf_ = r.head(nf_);
    reduce_empty_cells();
    fluid_->apply(rf_, zf_);
    if (nd_ > 0) {
      // z_f = P r - U (W^-1 + B_f U)^-1 B_f P r
      s_.fluid_body_force_into(zf_, force_);
      coeff_.noalias() = small_inv_ * force_;
      subtract_body_columns();
      if (!empty_.empty()) {
        // x_E = H^-1 r_E - K_E B_r x_r
        force_.noalias() -= bu_ * coeff_;
        solve_empty_cells();
      }
    }
    z.head(nf_) = zf_;
  }
  for (int i = 0; i < nc_; ++i) z[nf_ + i] = contact_inverse_[i] * r[nf_ + i];
}

template <int Dim>
void CoupledPreconditioner<Dim>::reduce_empty_cells() const {
  if (empty_.empty()) return;
  // r' = r_r - B_r^T W B_E H^-1 r_E = r_r - B_r^T K_E^T r_E; rf_'s rows of E zero (P ignores them)
  const int ne = static_cast<int>(empty_.size());
  for (int q = 0; q < ne; ++q) {
    er_[q] = rf_[empty_[q]];
    rf_[empty_[q]] = 0.0;
  }
  et_.noalias() = empty_gain_.transpose() * er_;
  subtract_dense_product(body_transpose_, et_, rf_);
}

template <int Dim>
void CoupledPreconditioner<Dim>::solve_empty_cells() const {
  // zf_ on E = H^-1 r_E - K_E (B_r x_r) with force_ = B_r x_r and er_ = r_E
  ex_ = empty_factor_.solve(er_);
  ex_.noalias() -= empty_gain_ * force_;
  for (std::size_t q = 0; q < empty_.size(); ++q) zf_[empty_[q]] = ex_[static_cast<int>(q)];
}

template <int Dim>
void CoupledPreconditioner<Dim>::subtract_body_columns() const {
  // zf_ -= U coeff_
  subtract_dense_product(u_, coeff_, zf_);
}

template <int Dim>
void CoupledPreconditioner<Dim>::apply_in_face(const VectorX& g, const std::vector<char>& free,
                                               VectorX& z) const {
  if (!exact_contacts_) {
    // block diagonal with Jacobi contact rows: M^-1 of the masked gradient, masked, is M_FF^-1
    apply(g, z);
    for (int i = 0; i < n_; ++i)
      if (!free[i]) z[i] = 0.0;
    return;
  }
  z.resize(n_);
  // z_f = P g_f; with (P4), c = (W^-1 + B_f U)^-1 B_f P g_f and B_f Q g_f = B_f P g_f - B_f U c
  rf_ = g.head(nf_);
  reduce_empty_cells();
  fluid_->apply(rf_, zf_);
  const int nd = nd_;
  if (nd > 0) {
    s_.fluid_body_force_into(zf_, force_);
    coeff_.noalias() = small_inv_ * force_;
    bq_.noalias() = force_ - bu_ * coeff_;
    if (!empty_.empty()) {
      // x_E of Q g_f, and B_f Q g_f = B_r x_r + B_E x_E
      force_ = bq_;
      ex_ = empty_factor_.solve(er_);
      ex_.noalias() -= empty_gain_ * force_;
      bq_.noalias() += empty_body_.transpose() * ex_;
    }
  }
  // the free contacts: y = S_FF^-1 (g_c - A_3f Q g_f)_F, A_3f Q g_f = J W B_f Q g_f
  if (nd > 0)
    rc_.noalias() = jw_ * bq_;
  else
    rc_.setZero();
  bool changed = factored_free_.size() != static_cast<std::size_t>(nc_);
  for (int i = 0; i < nc_ && !changed; ++i) changed = factored_free_[i] != free[nf_ + i];
  if (changed) {
    // S_c with the active rows and columns replaced by the identity: its factor solves S_FF on F
    factored_free_.assign(free.begin() + nf_, free.begin() + nf_ + nc_);
    for (int a = 0; a < nc_; ++a)
      for (int b = 0; b < nc_; ++b)
        masked_(a, b) = factored_free_[a] && factored_free_[b] ? schur_(a, b) : (a == b ? 1.0 : 0.0);
    schur_factor_.compute(masked_);
  }
  for (int i = 0; i < nc_; ++i) rc_[i] = free[nf_ + i] ? g[nf_ + i] - rc_[i] : 0.0;
  yc_ = schur_factor_.solve(rc_);
  for (int i = 0; i < nc_; ++i) {
    if (!free[nf_ + i]) yc_[i] = 0.0;
    z[nf_ + i] = yc_[i];
  }
  // z_f = Q (g_f - A_f3 y) = P g_f - U (c + t), t = back_ y
  if (nd > 0) {
    t_.noalias() = back_ * yc_;
    coeff_ += t_;
    subtract_body_columns();
    if (!empty_.empty()) {
      // (Q A_f3 y)_E = K_E (J^T y - B_f U t)
      et_.noalias() = j_.transpose() * yc_;
      et_.noalias() -= bu_ * t_;
      ex_.noalias() -= empty_gain_ * et_;
      for (std::size_t q = 0; q < empty_.size(); ++q) zf_[empty_[q]] = ex_[static_cast<int>(q)];
    }
  }
  z.head(nf_) = zf_;
}

template <int Dim>
void LazyCoupledFacePreconditioner<Dim>::apply_in_face(const VectorX& g,
                                                       const std::vector<char>& free,
                                                       VectorX& z) const {
  if (!built_) built_ = make_();
  if (!scale_) {
    built_->apply_in_face(g, free, z);
    return;
  }
  g_ = g.cwiseQuotient(*scale_);
  built_->apply_in_face(g_, free, z_);
  z = z_.cwiseQuotient(*scale_);
}

template <int Dim>
bool KeptCoupledPreconditioner<Dim>::fits(const MonolithicSystem<Dim>& s) const {
  if (!system) return false;
  const MonolithicSystem<Dim>& k = *system;
  return k.num_stress() == s.num_stress() && k.num_pressure() == s.num_pressure() &&
         k.num_contacts() == s.num_contacts() && k.num_body_dofs() == s.num_body_dofs() &&
         k.dofs().unknown_of_dof == s.dofs().unknown_of_dof &&
         k.dofs().pressure.cell_of_dof == s.dofs().pressure.cell_of_dof;
}

template <int Dim>
void KeptCoupledPreconditioner<Dim>::keep(const MonolithicSystem<Dim>& s,
                                          std::shared_ptr<CoupledPreconditioner<Dim>> fluid,
                                          std::shared_ptr<CoupledPreconditioner<Dim>> contacts) {
  if (!candidate || candidate.get() != &s) return;  // an owner unknown: nothing kept
  if (system != candidate) {
    fluid_body.reset();
    mlcp.reset();
    system = candidate;
  }
  if (fluid) fluid_body = std::move(fluid);
  if (contacts) mlcp = std::move(contacts);
}

ScaledPreconditioner::ScaledPreconditioner(const Preconditioner& inner, const VectorX& scale)
    : inner_(inner), scale_(scale) {
  if (scale.size() != inner.size())
    throw std::invalid_argument("ScaledPreconditioner: scale of the wrong size");
  r_.setZero(scale.size());
  z_.setZero(scale.size());
}

void ScaledPreconditioner::apply(const VectorX& r, VectorX& z) const {
  r_ = r.cwiseQuotient(scale_);
  inner_.apply(r_, z_);
  z = z_.cwiseQuotient(scale_);
}

template class CoupledPreconditioner<2>;
template class CoupledPreconditioner<3>;
template class LazyCoupledFacePreconditioner<2>;
template class LazyCoupledFacePreconditioner<3>;
template struct KeptCoupledPreconditioner<2>;
template struct KeptCoupledPreconditioner<3>;

}  // namespace monolith
