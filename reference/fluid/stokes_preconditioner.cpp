#include "reference/fluid/stokes_preconditioner.hpp"
#include "reference/core/parallel.hpp"
#include "reference/solvers/row_sums.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>
#include <vector>

namespace monolith {

namespace {

/// The lower median of `values` (the middle one of an odd count, the lower middle of an even
/// count; `values` reordered). `values` must not be empty.
double lower_median(std::vector<double> values) {
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>((values.size() - 1) / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

constexpr int kParallelRows = 4096;

/// y = M x for a row-major sparse M, row-parallel (rows side by side, the bits of a plain loop).
void multiply(const SparseMatrix& m, const double* x, double* y) {
  const int n = static_cast<int>(m.rows());
  csr_row_sums<false>(m.outerIndexPtr(), m.innerIndexPtr(), m.valuePtr(), 0, n, nullptr, x, y, n > kParallelRows);
}

/// y = M x on the rows [begin, end) of a row-major sparse M (y sized end - begin).
void multiply_rows(const SparseMatrix& m, int begin, int end, const double* x, double* y) {
  csr_row_sums<false>(m.outerIndexPtr(), m.innerIndexPtr(), m.valuePtr(), begin, end, nullptr, x, y,
                      end - begin > kParallelRows);
}

/// `m` marked so that Eigen 3.4 moves it: its SparseMatrix has no move constructor or move
/// assignment (std::move alone copies), but its copy constructor and copy assignment swap from a
/// matrix marked as an rvalue. `m` is left empty (or with the target's old content).
SparseMatrix& moved(SparseMatrix& m) { return m.markAsRValue(); }

/// B_p^T diag(w) with B_p^T row-major (compressed): each entry times its face's weight, the bits
/// of Eigen's product with sparse_diagonal(w) (one term per entry).
SparseMatrix weighted_rows(const SparseMatrix& bpt, const VectorX& w) {
  SparseMatrix s = bpt;
  s.makeCompressed();
  const int* inner = s.innerIndexPtr();
  double* value = s.valuePtr();
  for (Eigen::Index e = 0; e < s.nonZeros(); ++e) value[e] = value[e] * w[inner[e]];
  return s;
}

/// B_p^T diag(w) B_p: the bits of Eigen's SparseMatrix(bpt * sparse_diagonal(w)) * bp
/// (sparse_row_product performs the additions of Eigen's conservative product in its order,
/// test_galerkin_product), without Eigen's sorting transposes.
SparseMatrix weighted_product(const SparseMatrix& bpt, const VectorX& w, const SparseMatrix& bp) {
  return sparse_row_product(weighted_rows(bpt, w), bp, false);
}

/// The diagonal of weighted_product(bpt, w, bp) alone, the same bits: entry k sums the terms of
/// row k of B_p^T diag(w) that reach column k of B_p, in the order of the row, the first term
/// assigned and the others added (as the product does; no entry: 0).
VectorX weighted_product_diagonal(const SparseMatrix& bpt, const VectorX& w, const SparseMatrix& bp) {
  const SparseMatrix s = weighted_rows(bpt, w);
  const int n = static_cast<int>(s.rows());
  VectorX d = VectorX::Zero(n);
  const int* outer = s.outerIndexPtr();
  const int* inner = s.innerIndexPtr();
  const double* value = s.valuePtr();
  const int* b_outer = bp.outerIndexPtr();
  const int* b_inner = bp.innerIndexPtr();
  const double* b_value = bp.valuePtr();
  for (int k = 0; k < n; ++k) {
    bool first = true;
    double sum = 0.0;
    for (int e = outer[k]; e < outer[k + 1]; ++e) {
      const int f = inner[e];
      for (int q = b_outer[f]; q < b_outer[f + 1]; ++q)
        if (b_inner[q] == k) {
          const double term = value[e] * b_value[q];
          sum = first ? term : sum + term;
          first = false;
        }
    }
    d[k] = sum;
  }
  return d;
}

}  // namespace

template <int Dim>
StokesPreconditioner<Dim>::StokesPreconditioner(const MacGrid<Dim>& grid, const LinearOperator& a,
                                                StokesFactors factors,
                                                const StokesPreconditionerOptions& options)
    : a_(a), f_(std::move(factors)), options_(options) {  // (StokesFactors moves: no copy)
  ns_ = f_.num_stress;
  np_ = f_.num_pressure;
  n_ = ns_ + np_;
  nf_ = static_cast<int>(f_.face.size());
  cycles_ = options.velocity_cycles;
  if (a.size() != n_) throw std::invalid_argument("StokesPreconditioner: operator and factors differ in size");
  // an explicit A swept in the matrix-free operator's order: its own sweeps run in index order,
  // a different SOR and so a different preconditioner (docs/preconditioners.md section 24)
  // (SparseMatrixOperator and the coupled systems' ExplicitStokesOperator both expose it)
  if (const SparseMatrix* m = a.explicit_matrix(); m && !f_.sweep_order.empty()) {
    if (static_cast<int>(f_.sweep_order.size()) != n_)
      throw std::invalid_argument("StokesPreconditioner: the sweep order does not list every unknown");
    if (!m->isCompressed() || m->rows() != n_ || m->cols() != n_)
      throw std::invalid_argument("StokesPreconditioner: the explicit matrix is not compressed n x n");
    ordered_matrix_ = m;
    ordered_diagonal_ = m->diagonal();
  }
  MacMultigridOptions mg;
  mg.smoothing = options.smoothing;
  mg.max_coarse = options.max_coarse;
  mg.renumber = options.renumber;
  // A22 = B_p^T C B_p, the pressure Poisson block; with the scaled commutator in the pressure
  // hierarchy's place only its diagonal is read (Pi, the near-empty cells)
  pressure_only_ = ns_ == 0;
  const bool scaled_commutator = np_ > 0 && options.schur_correction && !options.additive_pressure &&
                                 options.schur == SchurApproximation::commutator_scaled;
  SparseMatrix a22, bp, bpt;
  VectorX a22_diagonal;
  if (np_ > 0) {
    bp = f_.b.rightCols(np_);
    bpt = f_.b_transpose.bottomRows(np_);
    if (pressure_only_ || !scaled_commutator) {
      SparseMatrix product = weighted_product(bpt, f_.c, bp);
      a22.swap(product);
      a22_diagonal = a22.diagonal();
    } else {
      a22_diagonal = weighted_product_diagonal(bpt, f_.c, bp);
    }
  }
  if (pressure_only_) {
    if (np_ > 0) pressure_ = cell_multigrid<Dim>(grid, f_.pressure_cell, moved(a22), mg);
  } else {
    {
      SparseMatrix kinv = block_diagonal_inverse(f_.compliance);
      kinv_.swap(kinv);
    }
    // Pi^-1 = gamma (eta / W_L^p + 1 / A22_ii)
    penalty_.resize(np_);
    schur_diagonal_.resize(np_);
    for (int k = 0; k < np_; ++k) {
      const double visc = f_.pressure_viscosity[k] / f_.pressure_liquid[k];
      const double inv = options.penalty_factor * (visc + 1.0 / a22_diagonal[k]);
      penalty_[k] = 1.0 / inv;
      schur_diagonal_[k] = inv + options.schur_viscous_factor * visc;
    }
    // the near-empty cells: out of (P2) and S (Pi^-1 = 0), Jacobi instead
    penalty_divisor_ = penalty_;
    penalty_used_ = penalty_;
    if (np_ > 0 && options.empty_cell_ratio > 0.0) {
      const double bound = options.empty_cell_ratio *
                           lower_median(std::vector<double>(a22_diagonal.data(), a22_diagonal.data() + np_));
      const VectorX& extra = options.empty_cell_extra;
      if (extra.size() != 0 && extra.size() != np_)
        throw std::invalid_argument("StokesPreconditioner: one extra diagonal entry per pressure unknown expected");
      for (int k = 0; k < np_; ++k) {
        if (!(a22_diagonal[k] < bound && a22_diagonal[k] > 0.0)) continue;
        const double d = extra.size() ? extra[k] : 0.0;
        if (options.empty_cell_extra_ratio > 0.0 && !(d >= options.empty_cell_extra_ratio * a22_diagonal[k])) continue;
        empty_.push_back(k);
      }
      empty_diagonal_.resize(static_cast<int>(empty_.size()));
      for (std::size_t q = 0; q < empty_.size(); ++q) {
        const int k = empty_[q];
        empty_diagonal_[static_cast<int>(q)] = a22_diagonal[k];
        penalty_divisor_[k] = std::numeric_limits<double>::infinity();  // x / inf = 0
        penalty_used_[k] = 0.0;
      }
      empty_inverse_ = empty_diagonal_.cwiseInverse();
      if (extra.size()) set_empty_cell_diagonal(extra);
      if (!options.empty_cell_jacobi) empty_inverse_.setZero();
      // the outer sweeps relax the other unknowns only (SOR on their principal block)
      if (!empty_.empty()) {
        swept_.assign(n_, 1);
        for (int k : empty_) swept_[ns_ + k] = 0;
      }
    }
    // the viscous-to-mass ratio of each face row, r_f = C_f (B_tau K^-1 B_tau^T)_ff (each row by
    // one thread); its median sets the V-cycle count, and diag(V0) = (1 + r) / C weighs the
    // scaled commutator
    VectorX ratio(nf_);
    {
      const int* outer = f_.b.outerIndexPtr();
      const int* inner = f_.b.innerIndexPtr();
      const double* value = f_.b.valuePtr();
#pragma omp parallel for schedule(static) if (nf_ > kParallelRows) num_threads(process_threads())
      for (int i = 0; i < nf_; ++i) {
        double d = 0.0;
        for (int a = outer[i]; a < outer[i + 1]; ++a) {
          const int j = inner[a];
          if (j >= ns_) continue;
          for (SparseMatrix::InnerIterator it(kinv_, j); it; ++it)
            for (int b = outer[i]; b < outer[i + 1]; ++b)
              if (inner[b] == it.col()) d += value[a] * it.value() * value[b];
        }
        ratio[i] = f_.c[i] * d;
      }
    }
    if (nf_ > 0) viscous_ratio_ = lower_median(std::vector<double>(ratio.data(), ratio.data() + nf_));
    // (P6): one cycle more per factor 4 of the median ratio above cycle_ratio
    if (options.cycle_ratio > 0.0 && viscous_ratio_ > options.cycle_ratio) {
      const int extra = static_cast<int>(std::floor(std::log(viscous_ratio_ / options.cycle_ratio) / std::log(4.0)));
      cycles_ = std::min(std::max(options.velocity_cycles, options.max_velocity_cycles), options.velocity_cycles + extra);
    }
    // (P9): one cycle fewer where the liquid fills its box (a small free-surface share)
    if (np_ > 0) {
      int surface = 0;
      for (int k = 0; k < np_; ++k)
        if (f_.pressure_liquid[k] < 1.0) ++surface;
      free_surface_share_ = static_cast<double>(surface) / np_;
    }
    if (Dim == 3 && np_ > 0 && options.lean_share > 0.0 && free_surface_share_ < options.lean_share)
      cycles_ = std::max(1, cycles_ - 1);
    commutator_ = np_ > 0 && options.schur_correction && !options.additive_pressure &&
                  options.schur != SchurApproximation::cahouet_chabard;
    if (!commutator_ && np_ > 0 && options.schur_correction && !options.additive_pressure)
      bp_second_ = bp;  // (the second term's B_p: apply_penalised_inverse_pressure)
    if (commutator_) {
      bp_.swap(bp);  // (B_p and B_p^T as formed above)
      bpt_.swap(bpt);
      if (!empty_.empty()) {
        // B_p without the near-empty cells' columns (their rows of B_p^T)
        VectorX keep = VectorX::Ones(np_);
        for (int k : empty_) keep[k] = 0.0;
        bp_ = SparseMatrix(bp_ * sparse_diagonal(keep));
        bp_.prune(0.0);
        bp_.makeCompressed();
        bpt_ = SparseMatrix(sparse_diagonal(keep) * bpt_);
        bpt_.prune(0.0);
        bpt_.makeCompressed();
      }
      commutator_weight_.resize(nf_);
      for (int i = 0; i < nf_; ++i)
        commutator_weight_[i] = options.schur == SchurApproximation::commutator_scaled ? f_.c[i] / (1.0 + ratio[i]) : f_.c[i];
      lq_.setZero(np_);
      lh_.setZero(np_);
      lf_.setZero(nf_);
      lg_.setZero(nf_);
      lt_.setZero(ns_);
      lu_.setZero(n_);
    }
    ExtraPatches<Dim> extra;
    if (options.element_patches) extra = stress_element_patches<Dim>(f_);
    MacMultigridOptions vmg = mg;
    vmg.transverse_linear = options.transverse_linear;
    vmg.fine_cell_patches = options.fine_cell_patches;
    vmg.single_precision = options.single_precision_velocity;
    // V = C^-1 + B D^-1 B^T with D^-1 = 0 on the near-empty cells (1 / inf)
    // (K^-1 as formed above)
    SparseMatrix v = velocity_operator(f_, penalty_divisor_, &kinv_);
    velocity_ = face_multigrid<Dim>(grid, f_.face, moved(v), vmg, options.element_patches ? &extra : nullptr);
    if (np_ > 0 && (options.schur_correction || options.additive_pressure)) {
      // A22 is singular for enclosed liquid: the preconditioner inverts A22 + 1e-10 diag(A22)
      // (the scaled commutator's L = B_p^T W B_p in its place; with W = C it is A22)
      SparseMatrix shifted;
      if (commutator_ && options.schur == SchurApproximation::commutator_scaled) {
        SparseMatrix product = weighted_product(bpt_, commutator_weight_, bp_);
        shifted.swap(product);  // (Eigen 3.4's SparseMatrix has no move assignment)
      } else {
        shifted.swap(a22);  // (a22 is not used after this)
      }
      for (int k = 0; k < np_; ++k) shifted.coeffRef(k, k) *= 1.0 + 1e-10;
      if (!empty_.empty()) {
        // the near-empty cells decoupled (their rows and columns out, the median diagonal in
        // their place): S is zero on them
        std::vector<char> out(np_, 0);
        for (int k : empty_) out[k] = 1;
        shifted.prune([&](int i, int j, double) { return !out[i] && !out[j]; });
        std::vector<double> sorted;
        for (int k = 0; k < np_; ++k)
          if (!out[k]) sorted.push_back(shifted.coeff(k, k));
        const double fill = sorted.empty() ? 1.0 : lower_median(std::move(sorted));
        for (int k : empty_) shifted.coeffRef(k, k) = fill;
        shifted.makeCompressed();
      }
      pressure_ = cell_multigrid<Dim>(grid, f_.pressure_cell, moved(shifted), mg);
    }
  }
  if (!pressure_only_ && options.inner_cg > 0) velocity_finest_ = velocity_.finest_operator();
  if (!pressure_only_ && options.cut_threshold > 0.0) build_cut_block();
  if (!pressure_only_ && options.surface_sweeps > 0 && options.outer_sweeps > 0 && np_ > 0) build_surface_block();
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
SparseMatrix StokesPreconditioner<Dim>::rows_of_a(const std::vector<int>& list) const {
  // A with the system's own K (no W_F^s floor)
  const SparseMatrix& k = f_.compliance_exact.size() ? f_.compliance_exact : f_.compliance;
  // rows `list` of A = B^T C B + blkdiag(K, 0), row-major |list| x n: the bits of Eigen's
  // SparseMatrix(SparseMatrix(S B^T) * diag(C)) * B + [K rows] (S the selection, section 41):
  // the rows of B^T copied (S B^T's entries are 1 x b: the same values), each entry times its C
  // (weighted_rows: one term each), the product by sparse_row_product (Eigen's additions in its
  // order, sorted columns, cancelled entries kept), then K's rows merged as Eigen's sparse sum
  // merges them (x + y where both hold an entry, x + 0 or 0 + y where one does)
  const int m = static_cast<int>(list.size());
  SparseMatrix bt(m, f_.b_transpose.cols());
  {
    Eigen::Index total = 0;
    for (int q = 0; q < m; ++q)
      for (SparseMatrix::InnerIterator it(f_.b_transpose, list[q]); it; ++it) ++total;
    bt.resizeNonZeros(total);
    int* outer = bt.outerIndexPtr();
    int* inner = bt.innerIndexPtr();
    double* value = bt.valuePtr();
    int pos = 0;
    outer[0] = 0;
    for (int q = 0; q < m; ++q) {
      for (SparseMatrix::InnerIterator it(f_.b_transpose, list[q]); it; ++it) {
        inner[pos] = static_cast<int>(it.col());
        value[pos++] = it.value();
      }
      outer[q + 1] = pos;
    }
  }
  SparseMatrix bc = weighted_rows(bt, f_.c);
  const SparseMatrix product = sparse_row_product(bc, f_.b, false);
  // merge K's rows (sorted columns on both sides)
  Eigen::Index total = product.nonZeros();
  for (int q = 0; q < m; ++q)
    if (list[q] < ns_)
      for (SparseMatrix::InnerIterator it(k, list[q]); it; ++it) ++total;  // (an upper bound)
  std::vector<int> outer(static_cast<std::size_t>(m) + 1, 0);
  std::vector<int> inner;
  std::vector<double> value;
  inner.reserve(static_cast<std::size_t>(total));
  value.reserve(static_cast<std::size_t>(total));
  const int* p_outer = product.outerIndexPtr();
  const int* p_inner = product.innerIndexPtr();
  const double* p_value = product.valuePtr();
  for (int q = 0; q < m; ++q) {
    int e = p_outer[q];
    const int end = p_outer[q + 1];
    if (list[q] < ns_) {
      for (SparseMatrix::InnerIterator it(k, list[q]); it; ++it) {
        const int col = static_cast<int>(it.col());
        for (; e < end && p_inner[e] < col; ++e) {
          inner.push_back(p_inner[e]);
          value.push_back(p_value[e] + 0.0);
        }
        if (e < end && p_inner[e] == col) {
          inner.push_back(col);
          value.push_back(p_value[e] + it.value());
          ++e;
        } else {
          inner.push_back(col);
          value.push_back(0.0 + it.value());
        }
      }
    }
    for (; e < end; ++e) {
      inner.push_back(p_inner[e]);
      value.push_back(p_value[e] + 0.0);
    }
    outer[static_cast<std::size_t>(q) + 1] = static_cast<int>(inner.size());
  }
  SparseMatrix rows(m, n_);
  rows.resizeNonZeros(static_cast<Eigen::Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), rows.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), rows.innerIndexPtr());
  std::copy(value.begin(), value.end(), rows.valuePtr());
  return rows;
}

template <int Dim>
void StokesPreconditioner<Dim>::build_surface_block() {
  // the pressure unknowns of the cells the liquid fills only in part (W_L^p < 1), without the
  // near-empty cells, and the stress unknowns their rows of A reach (those on the faces of those
  // cells): the free surface's rows, where the residual of the settling liquid sits
  // (docs/preconditioners.md section 38)
  std::vector<char> in(n_, 0), empty(np_, 0);
  for (int k : empty_) empty[k] = 1;
  std::vector<int> list;
  for (int k = 0; k < np_; ++k)
    if (f_.pressure_liquid[k] < 1.0 && !empty[k]) list.push_back(ns_ + k);
  if (list.empty()) return;
  for (int i : list) in[i] = 1;
  {
    // (the stress unknowns the seed's rows reach: those on the faces of the partly filled cells)
    const SparseMatrix seed_rows = rows_of_a(list);
    for (int q = 0; q < seed_rows.outerSize(); ++q)
      for (SparseMatrix::InnerIterator it(seed_rows, q); it; ++it)
        if (it.value() != 0.0 && it.col() < ns_) in[it.col()] = 1;
  }
  list.clear();
  for (int i = 0; i < n_; ++i)
    if (in[i]) list.push_back(i);
  SparseMatrix rows = rows_of_a(list);
  VectorX diagonal = VectorX::Zero(static_cast<int>(list.size()));
  for (int q = 0; q < rows.outerSize(); ++q)
    for (SparseMatrix::InnerIterator it(rows, q); it; ++it)
      if (it.col() == list[q]) diagonal[q] += it.value();
  surface_ = std::move(list);
  surface_rows_.swap(rows);
  surface_diagonal_ = std::move(diagonal);
}

template <int Dim>
void StokesPreconditioner<Dim>::surface_sweeps(bool reverse, const VectorX& r, VectorX& z) const {
  // point Gauss-Seidel on A's rows of the surface set (the others fixed): SOR with omega 1 on
  // the principal block A_SS, a contraction in the A norm; forward then (in the mirrored place of
  // apply) backward, so P stays symmetric
  const int m = static_cast<int>(surface_.size());
  if (m == 0) return;
  const int* outer = surface_rows_.outerIndexPtr();
  const int* inner = surface_rows_.innerIndexPtr();
  const double* value = surface_rows_.valuePtr();
  for (int sweep = 0; sweep < options_.surface_sweeps; ++sweep)
    for (int t = 0; t < m; ++t) {
      const int q = reverse ? m - 1 - t : t;
      if (!(surface_diagonal_[q] > 0.0)) continue;
      const int i = surface_[q];
      double s = r[i];
      for (int e = outer[q]; e < outer[q + 1]; ++e) s -= value[e] * z[inner[e]];
      z[i] += s / surface_diagonal_[q];
    }
}

template <int Dim>
void StokesPreconditioner<Dim>::build_cut_block() {
  auto rows_of = [&](const std::vector<int>& list) { return rows_of_a(list); };
  std::vector<char> in(n_, 0);
  std::vector<int> list;
  auto collect = [&]() {
    list.clear();
    for (int i = 0; i < n_; ++i)
      if (in[i]) list.push_back(i);
  };
  // grow the set by the unknowns that rows `list` of A reach (pressure only, or all)
  auto grow = [&](bool pressure_only) {
    const SparseMatrix rows = rows_of(list);
    for (int q = 0; q < rows.outerSize(); ++q)
      for (SparseMatrix::InnerIterator it(rows, q); it; ++it)
        if (it.value() != 0.0 && (!pressure_only || it.col() >= ns_)) in[it.col()] = 1;
    collect();
  };
  // the seed: the stress unknowns cut by a solid
  for (int i = 0; i < ns_; ++i)
    if (i < f_.stress_fluid.size() && f_.stress_fluid[i] > 0.0 && f_.stress_fluid[i] < options_.cut_threshold) in[i] = 1;
  collect();
  if (list.empty()) return;
  if (options_.cut_pressure && np_ > 0) grow(true);
  for (int layer = 0; layer < options_.cut_layers; ++layer) {
    if (layer > 0 && options_.cut_layer_limit > 0 && static_cast<int>(list.size()) > options_.cut_layer_limit) break;
    grow(false);
  }
  if (!empty_.empty()) {
    // without the near-empty cells (their Jacobi term is the two-term step's)
    for (int k : empty_) in[ns_ + k] = 0;
    collect();
    if (list.empty()) return;
  }
  SparseMatrix rows = rows_of(list);
  // A_CC, a principal block of A. Its pressure diagonal is scaled by 1 + 1e-10 (as for the
  // pressure hierarchy): A is only semi-definite for enclosed liquid (constant pressure), and C
  // may hold all of that liquid's pressure unknowns.
  std::vector<int> local(n_, -1);
  for (std::size_t q = 0; q < list.size(); ++q) local[list[q]] = static_cast<int>(q);
  std::vector<Triplet> t;
  t.reserve(rows.nonZeros());
  for (int q = 0; q < rows.outerSize(); ++q)
    for (SparseMatrix::InnerIterator it(rows, q); it; ++it) {
      const int j = local[it.col()];
      if (j < 0) continue;
      const bool scale = j == q && list[q] >= ns_;
      t.emplace_back(q, j, scale ? it.value() * (1.0 + 1e-10) : it.value());
    }
  const int m = static_cast<int>(list.size());
  Eigen::SparseMatrix<double> acc(m, m);
  acc.setFromTriplets(t.begin(), t.end());
  // no block when its factor would hold more than cut_factor_cap times the entries of the finest
  // velocity operator (its two solves per application would then cost more than the rest of an
  // application; the symbolic analysis counts them before any numeric work); also none when the
  // factor is unusable (not positive definite to round-off)
  auto factor = std::make_unique<SparseLdlt>();
  factor->analyzePattern(acc);
  if (factor->info() != Eigen::Success ||
      static_cast<double>(factor->analysed_entries()) >
          options_.cut_factor_cap * static_cast<double>(velocity_.level(0).a.nonZeros()))
    return;
  if (options_.cut_supernodal) factor->factorize_supernodal(acc);
  else factor->factorize(acc);
  if (factor->info() != Eigen::Success || !factor->vectorD().allFinite() || factor->vectorD().minCoeff() <= 0.0)
    return;
  cut_ = std::move(list);
  cut_rows_.swap(rows);
  cut_factor_ = std::move(factor);
  cut_factor_->prepare_solve();
  cut_r_.setZero(m);
  cut_d_.setZero(m);
}

template <int Dim>
void StokesPreconditioner<Dim>::correct_cut(const VectorX& r, VectorX& z) const {
  if (cut_.empty()) return;
  const int m = static_cast<int>(cut_.size());
  const int* outer = cut_rows_.outerIndexPtr();
  const int* inner = cut_rows_.innerIndexPtr();
  const double* value = cut_rows_.valuePtr();
  for (int q = 0; q < m; ++q) {
    double s = r[cut_[q]];
    for (int k = outer[q]; k < outer[q + 1]; ++k) s -= value[k] * z[inner[k]];
    cut_r_[q] = s;
  }
  cut_factor_->solve_into(cut_r_, cut_d_);  // no allocation
  for (int q = 0; q < m; ++q) z[cut_[q]] += cut_d_[q];
}

template <int Dim>
void StokesPreconditioner<Dim>::outer_sweeps(bool reverse, const VectorX& r, VectorX& z, int count) const {
  const std::vector<char>* active = swept_.empty() ? nullptr : &swept_;
  if (!ordered_matrix_) {
    if (!active) {
      if (reverse) a_.backward_sweeps(r, z, options_.omega, count);
      else a_.forward_sweeps(r, z, options_.omega, count);
    } else {
      for (int k = 0; k < count; ++k) {
        if (reverse) a_.backward_sweep(r, z, options_.omega, active);
        else a_.forward_sweep(r, z, options_.omega, active);
      }
    }
    return;
  }
  // SparseMatrixOperator's relaxation of a row, over the rows in the matrix-free order
  const SparseMatrix& m = *ordered_matrix_;
  const int* outer = m.outerIndexPtr();
  const int* inner = m.innerIndexPtr();
  const double* value = m.valuePtr();
  const double omega = options_.omega;
  const std::vector<int>& order = f_.sweep_order;
  for (int k = 0; k < count; ++k)
    for (int q = 0; q < n_; ++q) {
      const int i = order[reverse ? n_ - 1 - q : q];
      if (ordered_diagonal_[i] == 0.0 || (active && !(*active)[i])) continue;
      double off = 0.0;
      for (int e = outer[i]; e < outer[i + 1]; ++e)
        if (inner[e] != i) off += value[e] * z[inner[e]];
      z[i] = (1.0 - omega) * z[i] + omega * (r[i] - off) / ordered_diagonal_[i];
    }
}

template <int Dim>
void StokesPreconditioner<Dim>::apply_penalised_inverse(const VectorX& g, VectorX& y) const {
  // h = D^-1 g
  multiply(kinv_, g.data(), h_.data());
  for (int k = 0; k < np_; ++k) h_[ns_ + k] = g[ns_ + k] / penalty_divisor_[k];
  // v ~ V^-1 B h
  multiply(f_.b, h_.data(), face_.data());
  if (options_.inner_cg <= 0) {
    velocity_.apply(face_, v_, cycles_);
  } else {
    // a few CG steps on V with the V-cycle as preconditioner, from zero
    const SparseMatrix& vm = velocity_finest_;  // V in the numbering of f_.face
    v_.setZero(nf_);
    iap_.resize(nf_);  // no-op after the first application
    ir_ = face_;
    velocity_.apply(ir_, iz_, 1);
    ip_ = iz_;
    double rz = ir_.dot(iz_);
    for (int k = 0; k < options_.inner_cg && rz > 0.0; ++k) {
      multiply(vm, ip_.data(), iap_.data());
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
  for (int k = 0; k < np_; ++k) y[ns_ + k] = h_[ns_ + k] - back_[ns_ + k] / penalty_divisor_[k];
}

template <int Dim>
void StokesPreconditioner<Dim>::apply_penalised_inverse_pressure(const VectorX& g, VectorX& y) const {
  // apply_penalised_inverse for a g whose stress part is +0 (the second term's w): h's stress
  // part is K^-1 (+0) = +0 (row sums from +0 of +-0 terms), so B h = B_p h_p: each row of B
  // (stress columns first) sums +-0 terms onto +0 before its pressure terms, which leaves +0;
  // the pressure terms then add in their stored order from +0, as in B_p's row. The same bits
  // with a seventh of B's entries read (section 41). B_p: bp_ (the commutator's; without the
  // near-empty cells' columns, where h_p = (Pi = 0) s / inf = +-0: terms that add nothing to a
  // sum that is never -0) or bp_second_.
  if (options_.inner_cg > 0 || (!commutator_ && bp_second_.rows() != nf_)) {
    apply_penalised_inverse(g, y);
    return;
  }
  const SparseMatrix& bp = commutator_ ? bp_ : bp_second_;
  h_.head(ns_).setZero();
  for (int k = 0; k < np_; ++k) h_[ns_ + k] = g[ns_ + k] / penalty_divisor_[k];
  multiply(bp, h_.data() + ns_, face_.data());
  velocity_.apply(face_, v_, cycles_);
  // y = h - D^-1 B^T v
  multiply(f_.b_transpose, v_.data(), back_.data());
  y.resize(n_);
  multiply(kinv_, back_.data(), y.data());
  for (int i = 0; i < ns_; ++i) y[i] = h_[i] - y[i];
  for (int k = 0; k < np_; ++k) y[ns_ + k] = h_[ns_ + k] - back_[ns_ + k] / penalty_divisor_[k];
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
    add_empty_cells(r, z);
    return;
  }
  if (np_ == 0 || !options_.schur_correction) {
    z = y1_;
    add_empty_cells(r, z);
    return;
  }
  // second term: A'^-1 E Pi S Pi E^T A'^-1 r, S = A22^-1 + diag (Pi taken as 0 on the
  // near-empty cells: A'^-1 is zero on them)
  for (int k = 0; k < np_; ++k) e_[k] = penalty_used_[k] * y1_[ns_ + k];
  apply_schur(e_, s_);
  w_.head(ns_).setZero();
  for (int k = 0; k < np_; ++k) w_[ns_ + k] = penalty_used_[k] * s_[k];
  apply_penalised_inverse_pressure(w_, y2_);
  z = y1_ + y2_;
  add_empty_cells(r, z);
}

template <int Dim>
void StokesPreconditioner<Dim>::set_empty_cell_diagonal(const VectorX& extra) {
  if (extra.size() != np_) throw std::invalid_argument("StokesPreconditioner: one extra diagonal entry per pressure unknown expected");
  for (std::size_t q = 0; q < empty_.size(); ++q) {
    const int k = empty_[q];
    if (!(extra[k] >= 0.0)) throw std::invalid_argument("StokesPreconditioner: negative extra diagonal");
    empty_inverse_[static_cast<int>(q)] =
        options_.empty_cell_jacobi ? 1.0 / (empty_diagonal_[static_cast<int>(q)] + extra[k]) : 0.0;
  }
}

template <int Dim>
void StokesPreconditioner<Dim>::add_empty_cells(const VectorX& r, VectorX& z) const {
  // the near-empty cells by Jacobi (the two-term form is zero on them)
  for (std::size_t q = 0; q < empty_.size(); ++q) {
    const int i = ns_ + empty_[q];
    z[i] = empty_inverse_[static_cast<int>(q)] * r[i];
  }
}

template <int Dim>
void StokesPreconditioner<Dim>::apply_unpenalised_velocity(const VectorX& x, VectorX& y) const {
  // t = B_tau^T x, u = [K^-1 t; 0], y = B u + x / C
  multiply_rows(f_.b_transpose, 0, ns_, x.data(), lt_.data());
  multiply_rows(kinv_, 0, ns_, lt_.data(), lu_.data());
  multiply(f_.b, lu_.data(), y.data());  // lu_'s pressure part stays 0
  for (int i = 0; i < nf_; ++i) y[i] += x[i] / f_.c[i];
}

template <int Dim>
void StokesPreconditioner<Dim>::apply_schur(const VectorX& e, VectorX& s) const {
  s.resize(np_);
  if (!commutator_) {
    // Cahouet-Chabard type: A22^-1 + Pi^-1 + factor eta / W_L^p
    pressure_.apply(e, s, 1);
    for (int k = 0; k < np_; ++k) s[k] += schur_diagonal_[k] * e[k];
    for (int k : empty_) s[k] = 0.0;
    return;
  }
  // (P7), the least-squares commutator: L^-1 B_p^T W V0 W B_p L^-1 e + Pi^-1 e, each L^-1 one cell V-cycle
  // (the same symmetric map on both sides: symmetric positive semi-definite, plus Pi^-1 > 0)
  pressure_.apply(e, lq_, 1);
  multiply(bp_, lq_.data(), lf_.data());
  for (int i = 0; i < nf_; ++i) lf_[i] *= commutator_weight_[i];
  apply_unpenalised_velocity(lf_, lg_);
  for (int i = 0; i < nf_; ++i) lg_[i] *= commutator_weight_[i];
  multiply(bpt_, lg_.data(), lh_.data());
  pressure_.apply(lh_, s, 1);
  for (int k = 0; k < np_; ++k) s[k] += e[k] / penalty_divisor_[k];
  for (int k : empty_) s[k] = 0.0;
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
  // (with near-empty cells, swept_: they stay 0 through the forward sweeps, whose rows would
  // divide by a diagonal up to 1e-16 of the median; the two-term step gives them their Jacobi
  // value)
  outer_sweeps(false, r, z, sweeps);
  surface_sweeps(false, r, z);
  correct_cut(r, z);
  a_.apply(z, az_);
  res_ = r - az_;
  apply_two_term(res_, d_);
  z += d_;
  correct_cut(r, z);
  surface_sweeps(true, r, z);
  outer_sweeps(true, r, z, sweeps);
}

template <int Dim>
std::size_t StokesPreconditioner<Dim>::memory_bytes() const {
  auto csr = [](const SparseMatrix& m) {
    return static_cast<std::size_t>(m.nonZeros()) * (sizeof(double) + sizeof(int)) +
           static_cast<std::size_t>(m.rows() + 1) * sizeof(int);
  };
  std::size_t bytes = csr(f_.b) + csr(f_.b_transpose) + csr(f_.compliance) + csr(kinv_);
  bytes += velocity_.memory_bytes() + pressure_.memory_bytes();
  bytes += csr(surface_rows_) + sizeof(int) * surface_.size() + sizeof(double) * surface_diagonal_.size();
  if (cut_factor_)
    bytes += csr(cut_rows_) + sizeof(double) * 3 * cut_.size() + sizeof(int) * cut_.size() +
             (sizeof(double) + sizeof(int)) * static_cast<std::size_t>(cut_factor_->analysed_entries());
  bytes += sizeof(double) * (f_.c.size() + penalty_.size() + schur_diagonal_.size());
  if (commutator_)
    bytes += csr(bp_) + csr(bpt_) +
             sizeof(double) * (commutator_weight_.size() + lq_.size() + lh_.size() + lf_.size() + lg_.size() + lt_.size() + lu_.size());
  bytes += sizeof(double) * (8 * static_cast<std::size_t>(n_) + 2 * nf_ + 2 * np_);
  return bytes;
}

template class StokesPreconditioner<2>;
template class StokesPreconditioner<3>;

}  // namespace monolith
