#include "reference/fluid/stokes_preconditioner.hpp"
#include "reference/core/parallel.hpp"

#include <stdexcept>

namespace monolith {

namespace {

constexpr int kParallelRows = 4096;

/// y = M x for a row-major sparse M, row-parallel.
void multiply(const SparseMatrix& m, const double* x, double* y) {
  const int n = static_cast<int>(m.rows());
  const int* outer = m.outerIndexPtr();
  const int* inner = m.innerIndexPtr();
  const double* value = m.valuePtr();
#pragma omp parallel for schedule(static) if (n > kParallelRows) num_threads(process_threads())
  for (int i = 0; i < n; ++i) {
    double s = 0.0;
    for (int k = outer[i]; k < outer[i + 1]; ++k) s += value[k] * x[inner[k]];
    y[i] = s;
  }
}

}  // namespace

template <int Dim>
StokesPreconditioner<Dim>::StokesPreconditioner(const MacGrid<Dim>& grid, const LinearOperator& a,
                                                StokesFactors factors,
                                                const StokesPreconditionerOptions& options)
    : a_(a), f_(std::move(factors)), options_(options) {
  ns_ = f_.num_stress;
  np_ = f_.num_pressure;
  n_ = ns_ + np_;
  nf_ = static_cast<int>(f_.face.size());
  if (a.size() != n_) throw std::invalid_argument("StokesPreconditioner: operator and factors differ in size");
  MacMultigridOptions mg;
  mg.smoothing = options.smoothing;
  mg.max_coarse = options.max_coarse;
  // A22 = B_p^T C B_p, the pressure Poisson block
  SparseMatrix a22;
  if (np_ > 0) {
    const SparseMatrix bp = f_.b.rightCols(np_);
    const SparseMatrix bpt = f_.b_transpose.bottomRows(np_);
    a22 = SparseMatrix(bpt * sparse_diagonal(f_.c)) * bp;
    a22.makeCompressed();
  }
  pressure_only_ = ns_ == 0;
  if (pressure_only_) {
    if (np_ > 0) pressure_ = cell_multigrid<Dim>(grid, f_.pressure_cell, a22, mg);
  } else {
    kinv_ = block_diagonal_inverse(f_.compliance);
    // Pi^-1 = gamma (eta / W_L^p + 1 / A22_ii)
    penalty_.resize(np_);
    schur_diagonal_.resize(np_);
    for (int k = 0; k < np_; ++k) {
      const double visc = f_.pressure_viscosity[k] / f_.pressure_liquid[k];
      const double inv = options.penalty_factor * (visc + 1.0 / a22.coeff(k, k));
      penalty_[k] = 1.0 / inv;
      schur_diagonal_[k] = inv + options.schur_viscous_factor * visc;
    }
    SparseMatrix v = velocity_operator(f_, penalty_);
    ExtraPatches<Dim> extra;
    if (options.element_patches) extra = stress_element_patches<Dim>(f_);
    MacMultigridOptions vmg = mg;
    vmg.transverse_linear = options.transverse_linear;
    vmg.fine_cell_patches = options.fine_cell_patches;
    velocity_ = face_multigrid<Dim>(grid, f_.face, std::move(v), vmg, options.element_patches ? &extra : nullptr);
    if (np_ > 0 && (options.schur_correction || options.additive_pressure)) {
      // A22 is singular for enclosed liquid: the preconditioner inverts A22 + 1e-10 diag(A22)
      SparseMatrix shifted = a22;
      for (int k = 0; k < np_; ++k) shifted.coeffRef(k, k) *= 1.0 + 1e-10;
      pressure_ = cell_multigrid<Dim>(grid, f_.pressure_cell, std::move(shifted), mg);
    }
  }
  h_.setZero(n_);
  back_.setZero(n_);
  y1_.setZero(n_);
  y2_.setZero(n_);
  w_.setZero(n_);
  res_.setZero(n_);
  d_.setZero(n_);
  az_.setZero(n_);
  face_.setZero(nf_);
  v_.setZero(nf_);
  e_.setZero(np_);
  s_.setZero(np_);
}

template <int Dim>
void StokesPreconditioner<Dim>::apply_penalised_inverse(const VectorX& g, VectorX& y) const {
  // h = D^-1 g
  multiply(kinv_, g.data(), h_.data());
  for (int k = 0; k < np_; ++k) h_[ns_ + k] = g[ns_ + k] / penalty_[k];
  // v ~ V^-1 B h
  multiply(f_.b, h_.data(), face_.data());
  if (options_.inner_cg <= 0) {
    velocity_.apply(face_, v_, options_.velocity_cycles);
  } else {
    // a few CG steps on V with the V-cycle as preconditioner, from zero
    const SparseMatrix& vm = velocity_.level(0).a;
    v_.setZero(nf_);
    ir_ = face_;
    velocity_.apply(ir_, iz_, 1);
    ip_ = iz_;
    double rz = ir_.dot(iz_);
    for (int k = 0; k < options_.inner_cg && rz > 0.0; ++k) {
      multiply(vm, ip_.data(), (iap_.resize(nf_), iap_.data()));
      const double alpha = rz / ip_.dot(iap_);
      v_ += alpha * ip_;
      if (k + 1 == options_.inner_cg) break;
      ir_ -= alpha * iap_;
      velocity_.apply(ir_, iz_, 1);
      const double rz_new = ir_.dot(iz_);
      ip_ = iz_ + (rz_new / rz) * ip_;
      rz = rz_new;
    }
  }
  // y = h - D^-1 B^T v
  multiply(f_.b_transpose, v_.data(), back_.data());
  y.resize(n_);
  multiply(kinv_, back_.data(), y.data());
  for (int i = 0; i < ns_; ++i) y[i] = h_[i] - y[i];
  for (int k = 0; k < np_; ++k) y[ns_ + k] = h_[ns_ + k] - back_[ns_ + k] / penalty_[k];
}

template <int Dim>
void StokesPreconditioner<Dim>::apply_two_term(const VectorX& r, VectorX& z) const {
  if (pressure_only_) {
    pressure_.apply(r, z, 1);  // MGPCG: one cell V-cycle (velocity_cycles concerns V)
    return;
  }
  apply_penalised_inverse(r, y1_);
  if (np_ > 0 && options_.additive_pressure) {
    for (int k = 0; k < np_; ++k) e_[k] = r[ns_ + k];
    pressure_.apply(e_, s_, 1);
    z = y1_;
    z.tail(np_) += s_;
    return;
  }
  if (np_ == 0 || !options_.schur_correction) {
    z = y1_;
    return;
  }
  // second term: A'^-1 E Pi S Pi E^T A'^-1 r, S = A22^-1 + diag
  for (int k = 0; k < np_; ++k) e_[k] = penalty_[k] * y1_[ns_ + k];
  pressure_.apply(e_, s_, 1);
  for (int k = 0; k < np_; ++k) s_[k] += schur_diagonal_[k] * e_[k];
  w_.head(ns_).setZero();
  for (int k = 0; k < np_; ++k) w_[ns_ + k] = penalty_[k] * s_[k];
  apply_penalised_inverse(w_, y2_);
  z = y1_ + y2_;
}

template <int Dim>
void StokesPreconditioner<Dim>::apply(const VectorX& r, VectorX& z) const {
  const int sweeps = options_.outer_sweeps;
  if (sweeps <= 0) {
    apply_two_term(r, z);
    return;
  }
  // symmetric two-level composition: SOR sweeps of A, the two-term inverse on the residual,
  // the adjoint sweeps
  z.setZero(n_);
  for (int s = 0; s < sweeps; ++s) a_.forward_sweep(r, z, options_.omega);
  a_.apply(z, az_);
  res_ = r - az_;
  apply_two_term(res_, d_);
  z += d_;
  for (int s = 0; s < sweeps; ++s) a_.backward_sweep(r, z, options_.omega);
}

template <int Dim>
std::size_t StokesPreconditioner<Dim>::memory_bytes() const {
  auto csr = [](const SparseMatrix& m) {
    return static_cast<std::size_t>(m.nonZeros()) * (sizeof(double) + sizeof(int)) +
           static_cast<std::size_t>(m.rows() + 1) * sizeof(int);
  };
  std::size_t bytes = csr(f_.b) + csr(f_.b_transpose) + csr(f_.compliance) + csr(kinv_);
  bytes += velocity_.memory_bytes() + pressure_.memory_bytes();
  bytes += sizeof(double) * (f_.c.size() + penalty_.size() + schur_diagonal_.size());
  bytes += sizeof(double) * (8 * static_cast<std::size_t>(n_) + 2 * nf_ + 2 * np_);
  return bytes;
}

template class StokesPreconditioner<2>;
template class StokesPreconditioner<3>;

}  // namespace monolith
