#include "reference/solvers/multigrid.hpp"
#include "reference/core/parallel.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <array>
#include <stdexcept>
#include <string>

#include "reference/solvers/linear_operator.hpp"
#include "reference/solvers/row_sums.hpp"

namespace monolith {

namespace {

/// Below this many rows a loop runs on one thread (a parallel region costs more than it saves).
constexpr int kParallelRows = 4096;

/// y = A x (Subtract false) or y = b - A x (Subtract true), row-parallel on large matrices
/// (blocks of consecutive rows, one writer per entry: any thread count gives the same bits).
template <bool Subtract>
void row_sums_all(const SparseMatrix& a, const VectorX* b, const VectorX& x, VectorX& y) {
  const int n = static_cast<int>(a.rows());
  y.resize(n);
  csr_row_sums<Subtract>(a.outerIndexPtr(), a.innerIndexPtr(), a.valuePtr(), 0, n, b ? b->data() : nullptr, x.data(),
                         y.data(), n > kParallelRows);
}

/// y = A x, row-parallel (one writer per entry) on large matrices.
void product(const SparseMatrix& a, const VectorX& x, VectorX& y) { row_sums_all<false>(a, nullptr, x, y); }

/// r = b - A x, row-parallel.
void residual(const SparseMatrix& a, const VectorX& b, const VectorX& x, VectorX& r) {
  row_sums_all<true>(a, &b, x, r);
}

/// d = inv r for a patch's dense row-major m x m inverse: four rows of inv at a time (then
/// pairs, then single rows), each d_i summed over j in order from 0 (the bits of the plain loop).
inline void patch_correction(const double* inv, const double* r, int m, double* d) {
  int i = 0;
  for (; i + 4 <= m; i += 4) {
    const double* a0 = inv + i * m;
    const double* a1 = a0 + m;
    const double* a2 = a1 + m;
    const double* a3 = a2 + m;
    double d0 = 0.0, d1 = 0.0, d2 = 0.0, d3 = 0.0;
    for (int j = 0; j < m; ++j) {
      d0 += a0[j] * r[j];
      d1 += a1[j] * r[j];
      d2 += a2[j] * r[j];
      d3 += a3[j] * r[j];
    }
    d[i] = d0;
    d[i + 1] = d1;
    d[i + 2] = d2;
    d[i + 3] = d3;
  }
  for (; i + 2 <= m; i += 2) {
    const double* a0 = inv + i * m;
    const double* a1 = a0 + m;
    double d0 = 0.0, d1 = 0.0;
    for (int j = 0; j < m; ++j) {
      d0 += a0[j] * r[j];
      d1 += a1[j] * r[j];
    }
    d[i] = d0;
    d[i + 1] = d1;
  }
  for (; i < m; ++i) {
    double s = 0.0;
    for (int j = 0; j < m; ++j) s += inv[i * m + j] * r[j];
    d[i] = s;
  }
}

/// Patches of at most this many unknowns (every patch of the 3D MAC levels: cells of 6 faces,
/// stress elements of 4) keep their inverse as its packed upper triangle, m (m + 1) / 2 entries
/// instead of m^2 (docs/preconditioners.md section 42): the inverse is exactly symmetric
/// (compute_patch_inverses symmetrises it), so entry (i, j) and (j, i) are one number.
constexpr int kPackedMax = 6;

/// Stored entries of the inverse of a patch of m unknowns.
inline int inverse_entries(int m) { return m <= kPackedMax ? m * (m + 1) / 2 : m * m; }

/// Position of entry (i, j) of a symmetric m x m block stored as its upper triangle row by row.
constexpr int packed_index(int i, int j, int m) {
  return i <= j ? i * m - i * (i - 1) / 2 + (j - i) : j * m - j * (j - 1) / 2 + (i - j);
}

/// d = inv r for a packed inverse of fixed size M: every d_i summed over j in order from 0, as
/// patch_correction sums it (the same products of the same numbers: the same bits); with M
/// known, every loop is unrolled and each stored entry is loaded once for both its places.
template <int M>
inline void packed_correction(const double* p, const double* r, double* d) {
  int i = 0;
  for (; i + 4 <= M; i += 4) {
    double d0 = 0.0, d1 = 0.0, d2 = 0.0, d3 = 0.0;
    for (int j = 0; j < M; ++j) {
      d0 += p[packed_index(i, j, M)] * r[j];
      d1 += p[packed_index(i + 1, j, M)] * r[j];
      d2 += p[packed_index(i + 2, j, M)] * r[j];
      d3 += p[packed_index(i + 3, j, M)] * r[j];
    }
    d[i] = d0;
    d[i + 1] = d1;
    d[i + 2] = d2;
    d[i + 3] = d3;
  }
  for (; i + 2 <= M; i += 2) {
    double d0 = 0.0, d1 = 0.0;
    for (int j = 0; j < M; ++j) {
      d0 += p[packed_index(i, j, M)] * r[j];
      d1 += p[packed_index(i + 1, j, M)] * r[j];
    }
    d[i] = d0;
    d[i + 1] = d1;
  }
  for (; i < M; ++i) {
    double s = 0.0;
    for (int j = 0; j < M; ++j) s += p[packed_index(i, j, M)] * r[j];
    d[i] = s;
  }
}

/// d = inv r for a patch of m unknowns, its inverse stored as inverse_entries(m) says.
inline void stored_correction(const double* inv, const double* r, int m, double* d) {
  switch (m) {
    case 1: packed_correction<1>(inv, r, d); return;
    case 2: packed_correction<2>(inv, r, d); return;
    case 3: packed_correction<3>(inv, r, d); return;
    case 4: packed_correction<4>(inv, r, d); return;
    case 5: packed_correction<5>(inv, r, d); return;
    case 6: packed_correction<6>(inv, r, d); return;
    default: patch_correction(inv, r, m, d);
  }
}
static_assert(kPackedMax == 6, "stored_correction has a case for every packed size");

/// The row length of a 3D MAC velocity level's interior rows (the face, its 6 neighbours along
/// and across its axis, the 8 faces of the other axes around it): most rows of the finest level,
/// relaxed by relax_uniform.
constexpr int kUniformRowLength = 15;

/// Relaxes a patch of M unknowns whose rows all hold exactly LEN entries, fully unrolled: r_i =
/// b_i - sum_q a_iq x_q over row i's entries in stored order (every row its own chain, as
/// row_sums forms it), d = inv r (packed_correction), x_P += d: the operations of the general
/// relaxation in the same order per row, hence the same bits, without its loop exits that
/// depend on the row lengths. Returns false (and changes nothing) when a row has another length.
template <int M, int LEN, typename V>
inline bool relax_uniform(const int* outer, const int* inner, const V* value, const double* b, double* x,
                          const int* idx, const double* inv) {
  int q[M];
  for (int i = 0; i < M; ++i) {
    q[i] = outer[idx[i]];
    if (outer[idx[i] + 1] - q[i] != LEN) return false;
  }
  double r[M], d[M];
  for (int i = 0; i < M; ++i) r[i] = b[idx[i]];
  for (int c = 0; c < LEN; ++c)
    for (int i = 0; i < M; ++i) r[i] = row_sum_term<true>(r[i], value[q[i] + c], x[inner[q[i] + c]]);
  packed_correction<M>(inv, r, d);
  for (int i = 0; i < M; ++i) x[idx[i]] += d[i];
  return true;
}

/// The unknowns of a level in the order the forward sweep first touches them (colours, groups,
/// patches, members), then the unknowns of no patch in increasing order: new -> old.
std::vector<int> sweep_order(const PatchSet& ps, int n) {
  std::vector<int> order;
  order.reserve(n);
  std::vector<char> seen(n, 0);
  for (const std::vector<int>& colour : ps.colours)
    for (int g : colour)
      for (int k = ps.group_start[g]; k < ps.group_start[g + 1]; ++k)
        for (int q = ps.start[k]; q < ps.start[k + 1]; ++q) {
          const int i = ps.index[q];
          if (!seen[i]) {
            seen[i] = 1;
            order.push_back(i);
          }
        }
  for (int i = 0; i < n; ++i)
    if (!seen[i]) order.push_back(i);
  return order;
}

/// The inverse of a permutation (old -> new from new -> old).
std::vector<int> inverse_permutation(const std::vector<int>& order) {
  std::vector<int> inv(order.size());
  for (std::size_t q = 0; q < order.size(); ++q) inv[order[q]] = static_cast<int>(q);
  return inv;
}

/// m with its rows taken in the order `row_order` (new -> old; empty: unchanged) and its column
/// indices mapped through `column_map` (old -> new; empty: unchanged), every row's entries kept
/// in their stored order (so every row sum is formed by the same additions in the same order as
/// before; the column indices of a row need no longer increase).
SparseMatrix permuted(const SparseMatrix& m, const std::vector<int>& row_order, const std::vector<int>& column_map) {
  const int rows = static_cast<int>(m.rows());
  const int* outer = m.outerIndexPtr();
  const int* inner = m.innerIndexPtr();
  const double* value = m.valuePtr();
  SparseMatrix r(rows, m.cols());
  r.resizeNonZeros(m.nonZeros());
  int* r_outer = r.outerIndexPtr();
  int* r_inner = r.innerIndexPtr();
  double* r_value = r.valuePtr();
  int pos = 0;
  r_outer[0] = 0;
  for (int i = 0; i < rows; ++i) {
    const int old = row_order.empty() ? i : row_order[i];
    for (int k = outer[old]; k < outer[old + 1]; ++k) {
      r_inner[pos] = column_map.empty() ? inner[k] : column_map[inner[k]];
      r_value[pos] = value[k];
      ++pos;
    }
    r_outer[i + 1] = pos;
  }
  return r;
}

/// The values of a in single precision, rounded so that the rounded matrix is at least a in the
/// order of symmetric matrices: the off-diagonal entries rounded to nearest (errors e_ij, exact in
/// double), every diagonal entry a_ii + (sum_j |e_ij| + sum_j |e_ji|) / 2 with a margin for the
/// double sums, rounded up. The difference (rounded - a) then has a symmetric part that is
/// diagonally dominant with a non-negative diagonal, hence positive semi-definite, so the rounded
/// matrix is SPD whenever a is ((P12) in docs/derivations.md).
RawArray<float> rounded_dominant(const SparseMatrix& a) {
  const int n = static_cast<int>(a.rows());
  const int* outer = a.outerIndexPtr();
  const int* inner = a.innerIndexPtr();
  const double* value = a.valuePtr();
  // every entry is written below, off the diagonal in the first pass, on it in the second (an
  // entry is either): no zero fill
  RawArray<float> r;
  r.allocate(static_cast<std::size_t>(a.nonZeros()));
  std::vector<double> error(static_cast<std::size_t>(n), 0.0);  // row sums + column sums of |e|
  for (int i = 0; i < n; ++i)
    for (int e = outer[i]; e < outer[i + 1]; ++e) {
      const int j = inner[e];
      if (j == i) continue;
      r[static_cast<std::size_t>(e)] = static_cast<float>(value[e]);
      const double err = std::abs(static_cast<double>(r[static_cast<std::size_t>(e)]) - value[e]);
      error[static_cast<std::size_t>(i)] += err;
      error[static_cast<std::size_t>(j)] += err;
    }
  for (int i = 0; i < n; ++i)
    for (int e = outer[i]; e < outer[i + 1]; ++e) {
      if (inner[e] != i) continue;
      // (relative 1e-12 covers the rounding of the sums of at most millions of terms)
      const double target = value[e] + 0.5 * error[static_cast<std::size_t>(i)] * (1.0 + 1e-12);
      float d = static_cast<float>(target);
      if (static_cast<double>(d) < target) d = std::nextafter(d, std::numeric_limits<float>::infinity());
      r[static_cast<std::size_t>(e)] = d;
    }
  return r;
}

}  // namespace

int PatchSet::add(const std::vector<int>& unknowns) {
  if (unknowns.empty() || static_cast<int>(unknowns.size()) > kMaxPatchSize)
    throw std::invalid_argument("PatchSet::add: a patch needs 1.." + std::to_string(kMaxPatchSize) +
                                " unknowns, got " + std::to_string(unknowns.size()));
  index.insert(index.end(), unknowns.begin(), unknowns.end());
  start.push_back(static_cast<int>(index.size()));
  return size() - 1;
}

void PatchSet::close_group(int colour) {
  if (size() == group_start.back()) return;
  group_start.push_back(size());
  if (static_cast<int>(colours.size()) <= colour) colours.resize(colour + 1);
  colours[colour].push_back(num_groups() - 1);
}

Multigrid::Multigrid(std::vector<MultigridLevel> levels, int smoothing, bool renumber_levels, bool single_precision)
    : levels_(std::move(levels)), smoothing_(std::max(1, smoothing)), single_precision_(single_precision) {
  if (levels_.empty()) throw std::invalid_argument("Multigrid: no levels");
  const int num = static_cast<int>(levels_.size());
  restriction_.resize(num);
  inverse_start_.resize(num);
  inverse_.resize(num);
  residual_.resize(num);
  coarse_rhs_.resize(num);
  coarse_x_.resize(num);
  work_.resize(num);
  for (int l = 0; l < num; ++l) {
    MultigridLevel& lv = levels_[l];
    lv.a.makeCompressed();
    const int n = static_cast<int>(lv.a.rows());
    if (lv.a.cols() != n) throw std::invalid_argument("Multigrid: level operator not square");
    residual_[l].setZero(n);
    work_[l].setZero(n);
    if (l + 1 == num) break;
    const int nc = static_cast<int>(levels_[l + 1].a.rows());
    if (lv.prolongation.rows() != n || lv.prolongation.cols() != nc)
      throw std::invalid_argument("Multigrid: prolongation of level " + std::to_string(l) +
                                  " has the wrong shape");
    lv.prolongation.makeCompressed();
    if (lv.restriction.rows() == nc && lv.restriction.cols() == n && lv.restriction.isCompressed() &&
        lv.restriction.nonZeros() == lv.prolongation.nonZeros()) {
      restriction_[l].swap(lv.restriction);  // the caller's P^T (galerkin_product's): one transpose less
    } else {
      restriction_[l] = lv.prolongation.transpose();
      restriction_[l].makeCompressed();
    }
    SparseMatrix().swap(lv.restriction);
    coarse_rhs_[l].setZero(nc);
    coarse_x_[l].setZero(nc);
    if (!single_precision_) compute_patch_inverses(l);
  }
  apply_residual_.setZero(levels_[0].a.rows());
  apply_correction_.setZero(levels_[0].a.rows());
  coarse_ = std::make_unique<SparseLdlt>();
  coarse_->compute(Eigen::SparseMatrix<double>(levels_.back().a));
  if (coarse_->info() != Eigen::Success)
    throw std::invalid_argument("Multigrid: the coarsest operator could not be factored");
  coarse_->prepare_solve();
  order_.assign(levels_.size(), {});
  if (renumber_levels) renumber();
  if (single_precision_) {
    // the rounded operators (after the renumbering: in the stored order of the rows) and the patch
    // inverses of the rounded blocks
    value_f_.clear();
    value_f_.resize(levels_.size());
    for (int l = 0; l + 1 < num; ++l) {
      value_f_[l] = rounded_dominant(levels_[l].a);
      compute_patch_inverses(l);
    }
  }
}

void Multigrid::compute_patch_inverses(int l) {
  // dense inverses of the patch blocks A_PP (of the rounded operator's blocks in single precision:
  // the smoother of the operator the level sweeps and residuals use)
  const MultigridLevel& lv = levels_[l];
  const int n = static_cast<int>(lv.a.rows());
  const float* rounded = single_precision_ ? value_f_[l].data() : nullptr;
  const PatchSet& ps = lv.patches;
  std::vector<int>& offset = inverse_start_[l];
  offset.assign(ps.size() + 1, 0);
  for (int k = 0; k < ps.size(); ++k) {
    const int m = ps.start[k + 1] - ps.start[k];
    offset[k + 1] = offset[k] + inverse_entries(m);
  }
  inverse_[l].allocate(static_cast<std::size_t>(offset.back()));  // (every entry written below)
  int singular = 0;  // (set by any thread that finds a block whose inverse is not finite)
#pragma omp parallel if (ps.size() > 1024) num_threads(process_threads())
  {
  // the block gathered by one pass over each member's row (`slot`: member position of a column)
  std::vector<int> slot(static_cast<std::size_t>(n), -1);
#pragma omp for schedule(static)
  for (int k = 0; k < ps.size(); ++k) {
    const int* idx = ps.index.data() + ps.start[k];
    const int m = ps.start[k + 1] - ps.start[k];
    // (storage on the stack, at most kMaxPatchSize square: no allocation per patch)
    using Block = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, PatchSet::kMaxPatchSize, PatchSet::kMaxPatchSize>;
    Block block = Block::Zero(m, m);
    for (int i = 0; i < m; ++i) slot[idx[i]] = i;
    for (int i = 0; i < m; ++i)
      for (int e = lv.a.outerIndexPtr()[idx[i]]; e < lv.a.outerIndexPtr()[idx[i] + 1]; ++e) {
        const int col = lv.a.innerIndexPtr()[e];
        if (slot[col] >= 0) block(i, slot[col]) = rounded ? static_cast<double>(rounded[e]) : lv.a.valuePtr()[e];
      }
    for (int i = 0; i < m; ++i) slot[idx[i]] = -1;
    Eigen::LDLT<Block> ldlt(block);
    Block inv = ldlt.solve(Block::Identity(m, m));
    inv = 0.5 * (inv + inv.transpose()).eval();  // exactly symmetric
    if (!inv.allFinite()) {
#pragma omp atomic write
      singular = 1;
    }
    double* out = inverse_[l].data() + offset[k];
    if (m <= kPackedMax) {
      for (int i = 0; i < m; ++i)
        for (int j = i; j < m; ++j) out[packed_index(i, j, m)] = inv(i, j);
    } else {
      for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) out[i * m + j] = inv(i, j);
    }
  }
  }
  if (singular) throw std::invalid_argument("Multigrid: singular patch block");
}

void Multigrid::renumber() {
  // Every smoothed level is renumbered in the order its forward sweep first touches its unknowns
  // (locality): the rows a group of patches gathers, stored apart before (the MAC faces of one
  // cell lie in three axis blocks of the face numbering), become neighbours in memory. Rows keep
  // their entries in their stored order and patches their members, so every sweep, residual and
  // transfer performs the same additions as before in the same order: the same bits. The
  // coarsest level (sparse LDL^T) keeps its numbering.
  const int num = static_cast<int>(levels_.size());
  order_.assign(num, {});
  std::vector<std::vector<int>> inverse(num);
  for (int l = 0; l + 1 < num; ++l) {
    const int n = static_cast<int>(levels_[l].a.rows());
    order_[l] = sweep_order(levels_[l].patches, n);
    inverse[l] = inverse_permutation(order_[l]);
  }
  for (int l = 0; l + 1 < num; ++l) {
    MultigridLevel& lv = levels_[l];
    // (swapped in: Eigen 3.4's SparseMatrix has no move assignment, `=` would copy)
    SparseMatrix a = permuted(lv.a, order_[l], inverse[l]);
    lv.a.swap(a);
    for (int& i : lv.patches.index) i = inverse[l][i];
    // prolongation: fine rows in the new order, coarse columns renumbered; restriction (the
    // transpose as Eigen stored it) the other way round
    SparseMatrix p = permuted(lv.prolongation, order_[l], inverse[l + 1]);
    lv.prolongation.swap(p);
    SparseMatrix r = permuted(restriction_[l], order_[l + 1], inverse[l]);
    restriction_[l].swap(r);
  }
  if (!order_.empty() && !order_[0].empty()) {
    apply_in_.setZero(levels_[0].a.rows());
    apply_out_.setZero(levels_[0].a.rows());
  }
}

SparseMatrix Multigrid::smoothed_operator(int l) const {
  SparseMatrix a = levels_[l].a;
  if (!value_f_.empty() && !value_f_[l].empty())
    for (Eigen::Index e = 0; e < a.nonZeros(); ++e) a.valuePtr()[e] = static_cast<double>(value_f_[l][e]);
  return a;
}

SparseMatrix Multigrid::finest_operator(bool smoothed) const {
  const bool rounded = smoothed && !value_f_.empty() && !value_f_[0].empty();
  if (order_.empty() || order_[0].empty()) return rounded ? smoothed_operator(0) : levels_[0].a;
  // back to the caller's numbering, columns sorted (a matrix like the one given)
  const SparseMatrix& a = levels_[0].a;
  std::vector<Triplet> t;
  t.reserve(a.nonZeros());
  for (int i = 0; i < a.outerSize(); ++i)
    for (int e = a.outerIndexPtr()[i]; e < a.outerIndexPtr()[i + 1]; ++e)
      t.emplace_back(order_[0][i], order_[0][a.innerIndexPtr()[e]],
                     rounded ? static_cast<double>(value_f_[0][e]) : a.valuePtr()[e]);
  SparseMatrix r(a.rows(), a.cols());
  r.setFromTriplets(t.begin(), t.end());
  r.makeCompressed();
  return r;
}

void Multigrid::sweep(int l, const VectorX& b, VectorX& x, bool backward) const {
  if (!value_f_.empty() && !value_f_[l].empty()) sweep_values(l, b, x, backward, value_f_[l].data());
  else sweep_values(l, b, x, backward, levels_[l].a.valuePtr());
}

template <typename V>
void Multigrid::sweep_values(int l, const VectorX& b, VectorX& x, bool backward, const V* value) const {
  const MultigridLevel& lv = levels_[l];
  const PatchSet& ps = lv.patches;
  const int* outer = lv.a.outerIndexPtr();
  const int* inner = lv.a.innerIndexPtr();
  const double* inverse = inverse_[l].data();
  const int* offset = inverse_start_[l].data();
  double* xs = x.data();
  const double* bs = b.data();
  auto relax = [&](int k) {
    const int* idx = ps.index.data() + ps.start[k];
    const int m = ps.start[k + 1] - ps.start[k];
    const double* inv = inverse + offset[k];
    // the common patches of a 3D MAC level (stress elements of 4 faces, cells of 6) whose rows
    // are interior rows: unrolled, the same bits
    if (m == 4 && relax_uniform<4, kUniformRowLength>(outer, inner, value, bs, xs, idx, inv)) return;
    if (m == 6 && relax_uniform<6, kUniformRowLength>(outer, inner, value, bs, xs, idx, inv)) return;
    // r_P = (b - A x)_P, then x_P += A_PP^-1 r_P (d depends on r only, so all of x_P is
    // updated after d is complete, as the row-by-row loop did)
    std::array<double, PatchSet::kMaxPatchSize> r, d;
    for (int i = 0; i < m; ++i) r[i] = bs[idx[i]];
    row_sums<true, V>(outer, inner, value, xs, idx, m, r.data());
    stored_correction(inv, r.data(), m, d.data());
    for (int i = 0; i < m; ++i) xs[idx[i]] += d[i];
  };
  const int num_colours = static_cast<int>(ps.colours.size());
  for (int step = 0; step < num_colours; ++step) {
    const std::vector<int>& list = ps.colours[backward ? num_colours - 1 - step : step];
    const int count = static_cast<int>(list.size());
    // groups of one colour are independent: any thread count gives the serial result
#pragma omp parallel for schedule(static) if (count > 1) num_threads(process_threads())
    for (int q = 0; q < count; ++q) {
      const int g = list[backward ? count - 1 - q : q];
      const int first = ps.group_start[g], last = ps.group_start[g + 1];
      if (!backward)
        for (int k = first; k < last; ++k) relax(k);
      else
        for (int k = last - 1; k >= first; --k) relax(k);
    }
  }
}

void Multigrid::level_residual(int l, const VectorX& b, const VectorX& x, VectorX& r) const {
  const SparseMatrix& a = levels_[l].a;
  if (value_f_.empty() || value_f_[l].empty()) {
    residual(a, b, x, r);
    return;
  }
  const int n = static_cast<int>(a.rows());
  r.resize(n);
  csr_row_sums<true, float>(a.outerIndexPtr(), a.innerIndexPtr(), value_f_[l].data(), 0, n, b.data(), x.data(), r.data(),
                            n > kParallelRows);
}

void Multigrid::cycle(int l, const VectorX& b, VectorX& x) const {
  const int num = static_cast<int>(levels_.size());
  if (l + 1 == num) {
    coarse_->solve_into(b, x);  // no allocation per cycle
    return;
  }
  const MultigridLevel& lv = levels_[l];
  x.setZero(lv.a.rows());
  for (int s = 0; s < smoothing_; ++s) sweep(l, b, x, false);
  level_residual(l, b, x, residual_[l]);
  product(restriction_[l], residual_[l], coarse_rhs_[l]);
  cycle(l + 1, coarse_rhs_[l], coarse_x_[l]);
  product(lv.prolongation, coarse_x_[l], work_[l]);
  x += work_[l];
  for (int s = 0; s < smoothing_; ++s) sweep(l, b, x, true);
}

void Multigrid::apply(const VectorX& b, VectorX& x, int cycles) const {
  const std::vector<int>* order = order_.empty() || order_[0].empty() ? nullptr : &order_[0];
  if (!order) {
    apply_internal(b, x, cycles);
    return;
  }
  // into the finest level's internal numbering and back (scratch: no allocation)
  const int n = static_cast<int>(order->size());
  const int* o = order->data();
  for (int i = 0; i < n; ++i) apply_in_[i] = b[o[i]];
  apply_internal(apply_in_, apply_out_, cycles);
  x.resize(n);
  for (int i = 0; i < n; ++i) x[o[i]] = apply_out_[i];
}

void Multigrid::apply_internal(const VectorX& b, VectorX& x, int cycles) const {
  cycle(0, b, x);
  if (cycles <= 1) return;
  // further cycles of x <- x + Q (b - A x), in scratch sized at construction (no allocation)
  VectorX& r = apply_residual_;
  VectorX& d = apply_correction_;
  for (int c = 1; c < cycles; ++c) {
    level_residual(0, b, x, r);
    cycle(0, r, d);
    x += d;
  }
}

std::size_t Multigrid::memory_bytes() const {
  std::size_t bytes = 0;
  if (levels_.empty()) return 0;
  auto csr = [](const SparseMatrix& m) {
    return static_cast<std::size_t>(m.nonZeros()) * (sizeof(double) + sizeof(int)) +
           static_cast<std::size_t>(m.rows() + 1) * sizeof(int);
  };
  for (std::size_t l = 0; l < levels_.size(); ++l) {
    bytes += csr(levels_[l].a) + csr(levels_[l].prolongation) + csr(restriction_[l]);
    bytes += sizeof(int) * (levels_[l].patches.index.size() + levels_[l].patches.start.size());
    bytes += sizeof(double) * inverse_[l].size() + sizeof(int) * inverse_start_[l].size();
    bytes += sizeof(double) * (residual_[l].size() + coarse_rhs_[l].size() + coarse_x_[l].size() +
                               work_[l].size());
  }
  bytes += sizeof(double) * (apply_residual_.size() + apply_correction_.size() + apply_in_.size() + apply_out_.size());
  for (const std::vector<int>& o : order_) bytes += sizeof(int) * o.size();
  for (const RawArray<float>& v : value_f_) bytes += sizeof(float) * v.size();
  // the coarse factor: at most the dense triangle of the coarsest level
  const std::size_t nc = levels_.empty() ? 0 : static_cast<std::size_t>(levels_.back().a.rows());
  bytes += sizeof(double) * std::min(nc * nc / 2, static_cast<std::size_t>(levels_.back().a.nonZeros()) * 8);
  return bytes;
}

double Multigrid::operator_complexity() const {
  if (levels_.empty() || levels_[0].a.nonZeros() == 0) return 0.0;
  double total = 0.0;
  for (const MultigridLevel& lv : levels_) total += static_cast<double>(lv.a.nonZeros());
  return total / static_cast<double>(levels_[0].a.nonZeros());
}

namespace {

/// Row i of a b (Gustavson's row: the entries of a's row i in stored order, the first term of a
/// column assigned and the others added), its columns written from inner[start] (mark[j] == i:
/// column j seen in this row, its sum in sum[j]), sorted when asked, the exact zeros dropped when
/// asked (Eigen's prune(0, 0)) and the values written beside them. Returns the end of the row's
/// kept entries. Both forms of sparse_row_product form their rows here.
inline int form_product_row(int i, int start, const SparseMatrix& a, const SparseMatrix& b, bool drop_zeros,
                            bool sort_columns, int* mark, double* sum, int* inner, double* value) {
  const int* a_outer = a.outerIndexPtr();
  const int* a_inner = a.innerIndexPtr();
  const double* a_value = a.valuePtr();
  const int* b_outer = b.outerIndexPtr();
  const int* b_inner = b.innerIndexPtr();
  const double* b_value = b.valuePtr();
  int end = start;
  for (int e = a_outer[i]; e < a_outer[i + 1]; ++e) {
    const int k = a_inner[e];
    const double x = a_value[e];
    for (int q = b_outer[k]; q < b_outer[k + 1]; ++q) {
      const int j = b_inner[q];
      if (mark[j] != i) {
        mark[j] = i;
        sum[j] = x * b_value[q];
        inner[end++] = j;
      } else {
        sum[j] += x * b_value[q];
      }
    }
  }
  if (sort_columns) std::sort(inner + start, inner + end);
  int out = start;
  for (int e = start; e < end; ++e) {
    const double v = sum[inner[e]];
    if (drop_zeros && !(std::abs(v) > 0.0)) continue;
    inner[out] = inner[e];
    value[out++] = v;
  }
  return out;
}

/// sparse_row_product on one thread in a single pass (section 41 of docs/preconditioners.md):
/// the result's storage is reserved for an upper bound of its entries (per row, the sum of the
/// lengths of the rows of b it reaches: address space only, the pages a row does not write are
/// never touched) and every row is formed, sorted and compacted at the end of the previous one.
/// The two-pass form counted every row's columns first (a third of the product's time); the
/// rows are formed by the same code, so the result is the same, bit for bit.
SparseMatrix sparse_row_product_serial(const SparseMatrix& a, const SparseMatrix& b, bool drop_zeros, bool sort_columns) {
  const int m = static_cast<int>(a.rows()), n = static_cast<int>(b.cols());
  const int* a_outer = a.outerIndexPtr();
  const int* a_inner = a.innerIndexPtr();
  const int* b_outer = b.outerIndexPtr();
  long long bound = 0;
  long long row_bound_max = 0;
  for (int i = 0; i < m; ++i) {
    long long row = 0;
    for (int e = a_outer[i]; e < a_outer[i + 1]; ++e) row += b_outer[a_inner[e] + 1] - b_outer[a_inner[e]];
    bound += std::min<long long>(row, n);
    row_bound_max = std::max(row_bound_max, row);
  }
  if (bound > std::numeric_limits<int>::max()) throw std::length_error("sparse_row_product: too many entries");
  SparseMatrix c(m, n);
  c.resizeNonZeros(static_cast<Eigen::Index>(bound));  // (capacity: written row by row below)
  int* inner = c.innerIndexPtr();
  double* value = c.valuePtr();
  int* outer = c.outerIndexPtr();
  std::vector<int> mark(static_cast<std::size_t>(n), -1);
  std::vector<double> sum(static_cast<std::size_t>(n));
  int pos = 0;
  for (int i = 0; i < m; ++i) {
    outer[i] = pos;
    pos = form_product_row(i, pos, a, b, drop_zeros, sort_columns, mark.data(), sum.data(), inner, value);
  }
  outer[m] = pos;
  c.resizeNonZeros(pos);  // shrinks the size only
  return c;
}

}  // namespace

SparseMatrix sparse_row_product(const SparseMatrix& a, const SparseMatrix& b, bool drop_zeros, bool sort_columns) {
  if (a.cols() != b.rows()) throw std::invalid_argument("sparse_row_product: sizes do not match");
  if (!a.isCompressed() || !b.isCompressed())
    throw std::invalid_argument("sparse_row_product: compressed matrices expected");
  const int m = static_cast<int>(a.rows()), n = static_cast<int>(b.cols());
  const int* a_outer = a.outerIndexPtr();
  const int* a_inner = a.innerIndexPtr();
  const int* b_outer = b.outerIndexPtr();
  const int* b_inner = b.innerIndexPtr();
  // (Gustavson's row-by-row product: row i of the result accumulates a_ik b_k: over the entries
  // of a's row i in stored order, each row by one thread, the first term of a column assigned and
  // the others added: the additions of Eigen's conservative product, in its order, without its
  // two transposes for sorting)
  const bool parallel = m > kParallelRows;
  if (!parallel || process_threads() == 1) return sparse_row_product_serial(a, b, drop_zeros, sort_columns);
  std::vector<int> outer(static_cast<std::size_t>(m) + 1, 0);
  // pass 1: the columns per row
#pragma omp parallel if (parallel) num_threads(process_threads())
  {
    std::vector<int> mark(static_cast<std::size_t>(n), -1);
#pragma omp for schedule(static)
    for (int i = 0; i < m; ++i) {
      int count = 0;
      for (int e = a_outer[i]; e < a_outer[i + 1]; ++e) {
        const int k = a_inner[e];
        for (int q = b_outer[k]; q < b_outer[k + 1]; ++q)
          if (mark[b_inner[q]] != i) {
            mark[b_inner[q]] = i;
            ++count;
          }
      }
      outer[static_cast<std::size_t>(i) + 1] = count;
    }
  }
  for (int i = 0; i < m; ++i) outer[static_cast<std::size_t>(i) + 1] += outer[i];
  // the result's own storage, written in place (no zero-filled staging arrays and no copy: fresh
  // pages are touched once, by the rows that fill them)
  SparseMatrix c(m, n);
  c.resizeNonZeros(outer[m]);
  int* inner = c.innerIndexPtr();
  double* value = c.valuePtr();
  std::vector<int> kept(drop_zeros ? static_cast<std::size_t>(m) : 0);
  // pass 2: values, columns sorted per row (and the exact zeros dropped, compacted below)
#pragma omp parallel if (parallel) num_threads(process_threads())
  {
    std::vector<int> mark(static_cast<std::size_t>(n), -1);
    std::vector<double> sum(static_cast<std::size_t>(n));
#pragma omp for schedule(static)
    for (int i = 0; i < m; ++i) {
      const int out = form_product_row(i, outer[i], a, b, drop_zeros, sort_columns, mark.data(), sum.data(), inner, value);
      if (drop_zeros) kept[i] = out - outer[i];
    }
  }
  if (drop_zeros) {
    // compact the rows (serial: a copy within the arrays, in increasing order)
    int pos = 0;
    for (int i = 0; i < m; ++i) {
      const int start = outer[i];
      if (pos != start)
        for (int e = 0; e < kept[i]; ++e) {
          inner[pos + e] = inner[start + e];
          value[pos + e] = value[start + e];
        }
      outer[i] = pos;
      pos += kept[i];
    }
    outer[m] = pos;
    c.resizeNonZeros(pos);  // shrinks the size only: the arrays stay
  }
  std::copy(outer.begin(), outer.end(), c.outerIndexPtr());
  return c;
}

SparseMatrix galerkin_product(const SparseMatrix& a, const SparseMatrix& p, SparseMatrix* transpose) {
  // P^T (A P), both products row by row; A P keeps its cancelled entries (as Eigen's product
  // did), P^T A P drops the exact zeros: the same matrix, bit for bit, as
  // prune(P^T * (A * P)) with Eigen's products (test_multigrid's check), at about half the cost
  // (a and p copied only when they are not compressed: the finest operator holds millions of entries)
  SparseMatrix pt = p.transpose();
  pt.makeCompressed();
  SparseMatrix ac, pc;
  if (!a.isCompressed()) {
    ac = a;
    ac.makeCompressed();
  }
  if (!p.isCompressed()) {
    pc = p;
    pc.makeCompressed();
  }
  // (A P's rows unsorted: P^T (A P) adds the terms of each of its entries in the order of P^T's
  // row, one term per row of A P, whatever the order within that row, and sorts its own rows)
  const SparseMatrix ap = sparse_row_product(a.isCompressed() ? a : ac, p.isCompressed() ? p : pc, false, false);
  SparseMatrix c = sparse_row_product(pt, ap, true);
  if (transpose) transpose->swap(pt);
  return c;
}

bool patches_independent(const SparseMatrix& a, const PatchSet& patches) {
  const int n = static_cast<int>(a.rows());
  std::vector<int> owner(n, -1), seen(patches.num_groups(), 0);
  auto unknowns = [&](int g, const auto& visit) {
    for (int k = patches.group_start[g]; k < patches.group_start[g + 1]; ++k)
      for (int q = patches.start[k]; q < patches.start[k + 1]; ++q) visit(patches.index[q]);
  };
  for (const std::vector<int>& colour : patches.colours) {
    bool ok = true;
    for (int g : colour) {
      if (g < 0 || g >= patches.num_groups() || seen[g]++) return false;
      unknowns(g, [&](int i) {
        if (owner[i] >= 0 && owner[i] != g) ok = false;  // shared with another group
        owner[i] = g;
      });
    }
    // no row of one group reaches an unknown of another group of the colour
    for (int g : colour)
      unknowns(g, [&](int i) {
        for (SparseMatrix::InnerIterator it(a, i); it; ++it)
          if (it.value() != 0.0 && owner[it.col()] >= 0 && owner[it.col()] != g) ok = false;
      });
    for (int g : colour) unknowns(g, [&](int i) { owner[i] = -1; });
    if (!ok) return false;
  }
  for (int g = 0; g < patches.num_groups(); ++g)
    if (seen[g] != 1) return false;
  return true;
}

}  // namespace monolith
