/// \file coupled_preconditioner.cpp
/// The block preconditioner of the coupled systems (24)/(26) (coupled_preconditioner.hpp).

#include "reference/coupling/coupled_preconditioner.hpp"

#include <algorithm>
#include <stdexcept>

#include "reference/core/parallel.hpp"
#include "reference/fluid/velocity_operator.hpp"

namespace monolith {

namespace {

constexpr int kParallelRows = 4096;

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
  StokesPreconditionerOptions fluid_options = options.fluid;
  if (coupled && options.empty_cell_ratio > 0.0) fluid_options.empty_cell_ratio = options.empty_cell_ratio;
  fluid_ = std::make_unique<StokesPreconditioner<Dim>>(
      system.grid(), system.stokes_operator(),
      coupled_stokes_factors(system, options.fluid.min_fluid_fraction), fluid_options);
  if (!correct) return;
  // U = P B_f^T, column by column (an application of P per non-zero column of B_f^T; with no
  // non-zero column at all there is nothing to correct: Q = P)
  u_.setZero(nf_, nd);
  VectorX pz(nf_);
  // W = dt alpha M_r^-1
  const Eigen::MatrixXd w = (system.dt() * system.alpha()) * Eigen::MatrixXd(system.contacts().m_r_inverse);
  if (coupled && !fluid_->empty_cells().empty()) {
    // P's Jacobi term on the near-empty cells with A_ff's diagonal there, F + diag(B_f^T W B_f)
    // (with F's alone, P would be up to 1e16 times too large on them and Q = P - U (..)^-1 U^T
    // would cancel in round-off: docs/preconditioners.md section 21)
    const int ns = system.num_stress();
    const Eigen::MatrixXd bw = bft.bottomRows(nf_ - ns) * w;
    VectorX extra = bw.cwiseProduct(bft.bottomRows(nf_ - ns)).rowwise().sum().cwiseMax(0.0);
    fluid_->set_empty_cell_diagonal(extra);
  }
  for (int k = 0; k < nd; ++k) {
    if (!nonzero[k]) continue;
    fluid_->apply(VectorX(bft.col(k)), pz);
    u_.col(k) = pz;
  }
  if (!coupled) {
    // B_f = 0: Q = P, A_f3 = 0, S_c = A33' exactly
    u_.resize(0, 0);
    setup_exact_contacts(contact_diagonal, w, w, options);
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
  // (W^-1 + B_f U)^-1 = W (I + B_f U W)^-1 (no inverse of M_r^-1 formed)
  const Eigen::MatrixXd t = Eigen::MatrixXd::Identity(nd, nd) + bu * w;
  small_inv_ = w * t.partialPivLu().inverse();
  small_inv_ = 0.5 * (small_inv_ + small_inv_.transpose()).eval();
  nd_ = nd;
  force_.setZero(nd_);
  coeff_.setZero(nd_);
  bu_ = bu;
  setup_exact_contacts(contact_diagonal, w, small_inv_, options);
}

template <int Dim>
void CoupledPreconditioner<Dim>::setup_exact_contacts(const VectorX& contact_diagonal,
                                                      const Eigen::MatrixXd& w,
                                                      const Eigen::MatrixXd& w_effective,
                                                      const CoupledPreconditionerOptions& options) {
  if (nc_ == 0 || nc_ > options.max_exact_contacts) return;
  const Eigen::MatrixXd j(s_.contacts().j_lambda);  // nc x nd
  if (j.rows() != nc_ || j.cols() != w.rows()) return;
  jw_ = j * w;
  // S_c = J W_eff J^T + gamma diag(A33), gamma diag(A33) = diag(A33') - diag(J W J^T)
  schur_ = j * w_effective * j.transpose();
  schur_ = 0.5 * (schur_ + schur_.transpose()).eval();
  for (int i = 0; i < nc_; ++i) {
    const double boost = contact_diagonal[i] - jw_.row(i).dot(j.row(i));
    schur_(i, i) += std::max(0.0, boost);
  }
  // Q A_f3 = Q B_f^T W J^T = U (I - (W^-1 + B_f U)^-1 B_f U) W J^T (zero when B_f = 0)
  if (nd_ > 0)
    back_ = (Eigen::MatrixXd::Identity(nd_, nd_) - small_inv_ * bu_) * jw_.transpose();
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
    fluid_->apply(rf_, zf_);
    if (nd_ > 0) {
      // z_f = P r - U (W^-1 + B_f U)^-1 B_f P r
      s_.fluid_body_force_into(zf_, force_);
      coeff_.noalias() = small_inv_ * force_;
      subtract_body_columns();
    }
    z.head(nf_) = zf_;
  }
  for (int i = 0; i < nc_; ++i) z[nf_ + i] = contact_inverse_[i] * r[nf_ + i];
}

template <int Dim>
void CoupledPreconditioner<Dim>::subtract_body_columns() const {
  // zf_ -= U coeff_, row by row (each row's sum over the body columns in column order)
  const int nd = nd_;
  const double* c = coeff_.data();
  double* zf = zf_.data();
  const Eigen::MatrixXd& u = u_;
#pragma omp parallel for schedule(static) if (nf_ > kParallelRows) num_threads(process_threads())
  for (int i = 0; i < nf_; ++i) {
    double s = 0.0;
    for (int k = 0; k < nd; ++k) s += u(i, k) * c[k];
    zf[i] -= s;
  }
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
  fluid_->apply(rf_, zf_);
  const int nd = nd_;
  if (nd > 0) {
    s_.fluid_body_force_into(zf_, force_);
    coeff_.noalias() = small_inv_ * force_;
    bq_.noalias() = force_ - bu_ * coeff_;
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

}  // namespace monolith
