/// \file coupled_preconditioner.cpp
/// The block preconditioner of the coupled systems (24)/(26) (coupled_preconditioner.hpp).

#include "reference/coupling/coupled_preconditioner.hpp"

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
  fluid_ = std::make_unique<StokesPreconditioner<Dim>>(
      system.grid(), system.stokes_operator(),
      coupled_stokes_factors(system, options.fluid.min_fluid_fraction), options.fluid);
  const int nd = system.num_body_dofs();
  if (!options.body_correction || nd == 0 || nd > options.max_body_dofs) return;
  // U = P B_f^T, column by column (an application of P per non-zero column of B_f^T; a body
  // that touches no fluid unknown has zero columns, and with no non-zero column at all there is
  // nothing to correct: Q = P)
  u_.setZero(nf_, nd);
  VectorX e = VectorX::Zero(nd), column(nf_), pz(nf_);
  bool coupled = false;
  for (int k = 0; k < nd; ++k) {
    e.setZero();
    e[k] = 1.0;
    column = system.fluid_body_force_transpose(e);
    if (column.cwiseAbs().maxCoeff() == 0.0) continue;
    coupled = true;
    fluid_->apply(column, pz);
    u_.col(k) = pz;
  }
  if (!coupled) {
    u_.resize(0, 0);
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
  // (W^-1 + B_f U)^-1 = W (I + B_f U W)^-1 with W = dt alpha M_r^-1 (no inverse of M_r^-1 formed)
  const Eigen::MatrixXd w = (system.dt() * system.alpha()) * Eigen::MatrixXd(system.contacts().m_r_inverse);
  const Eigen::MatrixXd t = Eigen::MatrixXd::Identity(nd, nd) + bu * w;
  small_inv_ = w * t.partialPivLu().inverse();
  small_inv_ = 0.5 * (small_inv_ + small_inv_.transpose()).eval();
  nd_ = nd;
  force_.setZero(nd_);
  coeff_.setZero(nd_);
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
    z.head(nf_) = zf_;
  }
  for (int i = 0; i < nc_; ++i) z[nf_ + i] = contact_inverse_[i] * r[nf_ + i];
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

}  // namespace monolith
