#include "reference/solvers/sparse_ldlt.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <vector>

namespace monolith {

namespace {

/// The lower part of the update product of the supernodal factor: u(r, i) = sum_{c < w} t(r, c)
/// l(i, c) for i < k and i <= r < m (t column-major m x w, l(i, c) = l[c * l_stride + i], u
/// column-major m x k; entries above the diagonal of u are not needed and not all formed). Each
/// entry is the sum over c in increasing order from zero, one product added at a time (no fused
/// multiply-add): the bits of the coefficient-based product (`lazyProduct`) this replaces, whose
/// packets sum the same way. Tiles of 2 packets of rows by 4 columns keep eight independent sums
/// in registers (the lazy product kept one, a chain of dependent additions), and the tiles above
/// the diagonal are skipped.
void lower_update(const double* t, int m, const double* l, int l_stride, int k, int w, double* u) {
  using Packet = Eigen::internal::packet_traits<double>::type;
  constexpr int P = Eigen::internal::packet_traits<double>::size;
  using Eigen::internal::padd;
  using Eigen::internal::pmul;
  using Eigen::internal::pset1;
  using Eigen::internal::ploadu;
  using Eigen::internal::pstoreu;
  for (int i0 = 0; i0 < k; i0 += 4) {
    const int nc = std::min(4, k - i0);
    int r = i0;
    if (nc == 4)
      for (; r + 2 * P <= m; r += 2 * P) {
        Packet s00 = pset1<Packet>(0.0), s01 = s00, s02 = s00, s03 = s00;
        Packet s10 = s00, s11 = s00, s12 = s00, s13 = s00;
        const double* tc = t + r;
        const double* lc = l + i0;
        for (int c = 0; c < w; ++c, tc += m, lc += l_stride) {
          const Packet t0 = ploadu<Packet>(tc), t1 = ploadu<Packet>(tc + P);
          const Packet b0 = pset1<Packet>(lc[0]), b1 = pset1<Packet>(lc[1]);
          const Packet b2 = pset1<Packet>(lc[2]), b3 = pset1<Packet>(lc[3]);
          s00 = padd(s00, pmul(t0, b0));
          s10 = padd(s10, pmul(t1, b0));
          s01 = padd(s01, pmul(t0, b1));
          s11 = padd(s11, pmul(t1, b1));
          s02 = padd(s02, pmul(t0, b2));
          s12 = padd(s12, pmul(t1, b2));
          s03 = padd(s03, pmul(t0, b3));
          s13 = padd(s13, pmul(t1, b3));
        }
        double* u0 = u + static_cast<Eigen::Index>(i0) * m + r;
        pstoreu(u0, s00);
        pstoreu(u0 + P, s10);
        pstoreu(u0 + m, s01);
        pstoreu(u0 + m + P, s11);
        pstoreu(u0 + 2 * m, s02);
        pstoreu(u0 + 2 * m + P, s12);
        pstoreu(u0 + 3 * m, s03);
        pstoreu(u0 + 3 * m + P, s13);
      }
    // the rows left over (and the last columns when k is not a multiple of 4): entry by entry
    for (; r < m; ++r)
      for (int q = 0; q < nc && i0 + q <= r; ++q) {
        double s = 0.0;
        const double* tc = t + r;
        const double* lc = l + i0 + q;
        for (int c = 0; c < w; ++c, tc += m, lc += l_stride) s += *tc * *lc;
        u[static_cast<Eigen::Index>(i0 + q) * m + r] = s;
      }
  }
}

/// The LDL^T of a dense panel (column-major, nr rows, w <= nr columns, the first w rows its
/// diagonal block): on return column c holds L's rows below the diagonal, diag[c] D's entry; false
/// on a zero pivot. Every entry (r, c2) receives the terms U(r, c) (U(c2, c) / D_c) of the columns
/// c < c2 in increasing order, each subtracted as it comes (U the unscaled columns, L = U / D_c by
/// multiplication with 1 / D_c), exactly as the right-looking loop does column by column: the
/// same bits. Wide panels are done by blocks of four columns: the terms of the columns left of a
/// block are subtracted tile by tile (two packets of rows by four columns, eight independent
/// chains held in registers; the right-looking loop streams the whole trailing panel through
/// memory once per column), then the block's own columns right-looking; the scaling by 1 / D_c
/// waits to the end (the unscaled columns are read by every later block). `factor`: scratch of
/// 4 w doubles.
bool panel_ldlt(double* x, int nr, int w, double* diag, double* factor) {
  using Index = Eigen::Index;
  using Packet = Eigen::internal::packet_traits<double>::type;
  constexpr int P = Eigen::internal::packet_traits<double>::size;
  using Eigen::internal::pmul;
  using Eigen::internal::psub;
  using Eigen::internal::pset1;
  using Eigen::internal::ploadu;
  using Eigen::internal::pstoreu;
  if (w < 8) {
    for (int c = 0; c < w; ++c) {
      double* xc = x + static_cast<Index>(c) * nr;
      const double dc = xc[c];
      diag[c] = dc;
      if (dc == 0.0) return false;
      for (int c2 = c + 1; c2 < w; ++c2) {
        const double t = xc[c2];  // L(c2, c) D_c
        double* x2 = x + static_cast<Index>(c2) * nr;
        for (int r = c2; r < nr; ++r) x2[r] -= xc[r] * (t / dc);
      }
      const double inv = 1.0 / dc;
      for (int r = c + 1; r < nr; ++r) xc[r] *= inv;
    }
    return true;
  }
  for (int j0 = 0; j0 < w; j0 += 4) {
    const int nc = std::min(4, w - j0);
    // the columns c < j0: factor[4 c + q] = U(j0 + q, c) / D_c, then each entry of the block
    // minus its terms over c in order
    for (int c = 0; c < j0; ++c)
      for (int q = 0; q < nc; ++q) factor[4 * c + q] = x[static_cast<Index>(c) * nr + j0 + q] / diag[c];
    if (j0 > 0) {
      int r = j0;
      if (nc == 4)
        for (; r + 2 * P <= nr; r += 2 * P) {
          double* y = x + static_cast<Index>(j0) * nr + r;
          Packet s00 = ploadu<Packet>(y), s10 = ploadu<Packet>(y + P);
          Packet s01 = ploadu<Packet>(y + nr), s11 = ploadu<Packet>(y + nr + P);
          Packet s02 = ploadu<Packet>(y + 2 * nr), s12 = ploadu<Packet>(y + 2 * nr + P);
          Packet s03 = ploadu<Packet>(y + 3 * nr), s13 = ploadu<Packet>(y + 3 * nr + P);
          const double* uc = x + r;
          for (int c = 0; c < j0; ++c, uc += nr) {
            const Packet u0 = ploadu<Packet>(uc), u1 = ploadu<Packet>(uc + P);
            const double* fc = factor + 4 * c;
            const Packet f0 = pset1<Packet>(fc[0]), f1 = pset1<Packet>(fc[1]);
            const Packet f2 = pset1<Packet>(fc[2]), f3 = pset1<Packet>(fc[3]);
            s00 = psub(s00, pmul(u0, f0));
            s10 = psub(s10, pmul(u1, f0));
            s01 = psub(s01, pmul(u0, f1));
            s11 = psub(s11, pmul(u1, f1));
            s02 = psub(s02, pmul(u0, f2));
            s12 = psub(s12, pmul(u1, f2));
            s03 = psub(s03, pmul(u0, f3));
            s13 = psub(s13, pmul(u1, f3));
          }
          // (rows above a column's diagonal are formed too: never read)
          pstoreu(y, s00);
          pstoreu(y + P, s10);
          pstoreu(y + nr, s01);
          pstoreu(y + nr + P, s11);
          pstoreu(y + 2 * nr, s02);
          pstoreu(y + 2 * nr + P, s12);
          pstoreu(y + 3 * nr, s03);
          pstoreu(y + 3 * nr + P, s13);
        }
      for (; r < nr; ++r)
        for (int q = 0; q < nc && j0 + q <= r; ++q) {
          double v = x[static_cast<Index>(j0 + q) * nr + r];
          for (int c = 0; c < j0; ++c) v -= x[static_cast<Index>(c) * nr + r] * factor[4 * c + q];
          x[static_cast<Index>(j0 + q) * nr + r] = v;
        }
    }
    // the block's own columns, right-looking (unscaled)
    for (int c = j0; c < j0 + nc; ++c) {
      double* xc = x + static_cast<Index>(c) * nr;
      const double dc = xc[c];
      diag[c] = dc;
      if (dc == 0.0) return false;
      for (int c2 = c + 1; c2 < j0 + nc; ++c2) {
        const double t = xc[c2];
        double* x2 = x + static_cast<Index>(c2) * nr;
        for (int r = c2; r < nr; ++r) x2[r] -= xc[r] * (t / dc);
      }
    }
  }
  for (int c = 0; c < w; ++c) {
    double* xc = x + static_cast<Index>(c) * nr;
    const double inv = 1.0 / diag[c];
    for (int r = c + 1; r < nr; ++r) xc[r] *= inv;
  }
  return true;
}

}  // namespace

void SparseLdlt::factorize_supernodal(const Eigen::SparseMatrix<double>& a) {
  eigen_assert(m_analysisIsOk && "SparseLdlt::factorize_supernodal: analyzePattern first");
  using Index = Eigen::Index;
  const int n = static_cast<int>(a.rows());
  // C = P A P^T, its upper triangle by columns (as factorize builds it), and the lower one
  Eigen::SparseMatrix<double> upper(n, n);
  if (m_P.size() == n)
    upper.selfadjointView<Eigen::Upper>() = a.selfadjointView<Eigen::Lower>().twistedBy(m_P);
  else
    upper.selfadjointView<Eigen::Upper>() = a.selfadjointView<Eigen::Lower>();
  Eigen::SparseMatrix<double> lower = upper.transpose();  // column j: rows r >= j
  lower.makeCompressed();
  // the structure of L (strictly lower, by columns, rows increasing): row k's columns are the
  // elimination-tree paths from the entries of C's column k above the diagonal
  int* lp = m_matrix.outerIndexPtr();
  int* li = m_matrix.innerIndexPtr();
  double* lx = m_matrix.valuePtr();
  std::vector<int> fill(lp, lp + n);
  {
    std::vector<int> tag(n, -1);
    for (int k = 0; k < n; ++k) {
      tag[k] = k;
      for (Eigen::SparseMatrix<double>::InnerIterator it(upper, k); it; ++it)
        for (int i = static_cast<int>(it.index()); i < k && tag[i] != k; i = m_parent[i]) {
          tag[i] = k;
          li[fill[i]++] = k;
        }
    }
  }
  for (int j = 0; j < n; ++j) m_nonZerosPerCol[j] = fill[j] - lp[j];
  // supernodes: column j + 1 joins j's when it is j's parent and j's structure is {j + 1} and
  // j + 1's structure
  std::vector<int> first{0};  // supernode s: columns first[s] .. first[s + 1] - 1
  for (int j = 0; j + 1 < n; ++j)
    if (!(m_parent[j] == j + 1 && m_nonZerosPerCol[j] == m_nonZerosPerCol[j + 1] + 1)) first.push_back(j + 1);
  if (n > 0) first.push_back(n);
  const int ns = static_cast<int>(first.size()) - 1;
  std::vector<int> super_of(n);
  std::vector<Index> panel_start(ns + 1, 0);  // dense panels, column-major, rows = its rows
  std::size_t max_rows = 0, max_width = 0;
  for (int s = 0; s < ns; ++s) {
    const int w = first[s + 1] - first[s];
    const int rows = 1 + m_nonZerosPerCol[first[s]];
    for (int j = first[s]; j < first[s + 1]; ++j) super_of[j] = s;
    panel_start[s + 1] = panel_start[s] + static_cast<Index>(rows) * w;
    max_rows = std::max<std::size_t>(max_rows, rows);
    max_width = std::max<std::size_t>(max_width, w);
  }
  std::vector<double> panel(static_cast<std::size_t>(panel_start[ns]));
  m_diag.resize(n);
  // rows of supernode s: its first column, then that column's structure
  auto rows_of = [&](int s, int r) { return r == 0 ? first[s] : li[lp[first[s]] + r - 1]; };
  std::vector<int> pos(n, -1);
  std::vector<int> next(ns, 0);  // per finished supernode: its first row not yet applied
  std::vector<std::vector<int>> pending(ns);  // supernodes whose next update goes to s
  std::vector<double> scaled(max_rows * max_width), update(max_rows * max_rows);
  std::vector<int> row_index(max_rows);
  std::vector<double> factor(max_width * 4);
  bool ok = true;
  for (int s = 0; s < ns && ok; ++s) {
    const int f = first[s], w = first[s + 1] - f, nr = 1 + m_nonZerosPerCol[f];
    double* x = panel.data() + panel_start[s];
    for (int r = 0; r < nr; ++r) {
      row_index[r] = rows_of(s, r);
      pos[row_index[r]] = r;
    }
    // C's lower entries of the panel's columns (the diagonal shifted as factorize shifts it)
    for (int c = 0; c < w; ++c)
      for (Eigen::SparseMatrix<double>::InnerIterator it(lower, f + c); it; ++it) {
        const int r = static_cast<int>(it.index());
        x[static_cast<Index>(c) * nr + pos[r]] += r == f + c ? it.value() * m_shiftScale + m_shiftOffset : it.value();
      }
    // updates from the earlier supernodes whose rows reach these columns:
    // x -= L_d[rows >= f] D_d L_d[rows in f..f+w-1]^T
    for (int d : pending[s]) {
      const int fd = first[d], wd = first[d + 1] - fd, nrd = 1 + m_nonZerosPerCol[fd];
      const double* ld = panel.data() + panel_start[d];
      const int p = next[d];
      int q = p;
      while (q < nrd && rows_of(d, q) < f + w) ++q;
      const int m = nrd - p, k = q - p;
      Eigen::Map<Eigen::MatrixXd> t(scaled.data(), m, wd);
      for (int c = 0; c < wd; ++c)
        for (int r = 0; r < m; ++r) t(r, c) = ld[static_cast<Index>(c) * nrd + p + r] * m_diag[fd + c];
      // u = t L_d[rows p..q-1]^T, its lower part: each entry's sum over the d's columns in order,
      // on the calling thread (lower_update); Eigen's blocked GEMM would split its depth by the
      // thread count (bits that depend on it) and may start threads of its own
      lower_update(scaled.data(), m, ld + p, nrd, k, wd, update.data());
      Eigen::Map<const Eigen::MatrixXd> u(update.data(), m, k);
      for (int c = 0; c < k; ++c) {
        double* col = x + static_cast<Index>(rows_of(d, p + c) - f) * nr;
        for (int r = c; r < m; ++r) col[pos[rows_of(d, p + r)]] -= u(r, c);
      }
      next[d] = q;
      if (q < nrd) pending[super_of[rows_of(d, q)]].push_back(d);
    }
    std::vector<int>().swap(pending[s]);
    // the panel's own LDL^T (panel_ldlt)
    ok = panel_ldlt(x, nr, w, m_diag.data() + f, factor.data());
    for (int r = 0; r < nr; ++r) pos[row_index[r]] = -1;
    next[s] = w;
    if (nr > w) pending[super_of[rows_of(s, w)]].push_back(s);
  }
  // into Eigen's storage: column f + c holds the panel's rows below its diagonal
  if (ok)
    for (int s = 0; s < ns; ++s) {
      const int f = first[s], w = first[s + 1] - f, nr = 1 + m_nonZerosPerCol[f];
      const double* x = panel.data() + panel_start[s];
      for (int c = 0; c < w; ++c)
        for (int r = c + 1; r < nr; ++r) lx[lp[f + c] + r - c - 1] = x[static_cast<Index>(c) * nr + r];
    }
  m_info = ok ? Eigen::Success : Eigen::NumericalIssue;
  m_factorizationIsOk = true;
}

}  // namespace monolith
