#include "reference/solvers/sparse_ldlt.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <vector>

namespace monolith {

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
      Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>> lrows(ld + p, k, wd, Eigen::OuterStride<>(nrd));
      Eigen::Map<Eigen::MatrixXd> u(update.data(), m, k);
      // coefficient-based (lazyProduct): each entry's sum over the d's columns in order, on the
      // calling thread; Eigen's blocked GEMM would split its depth by the thread count (bits that
      // depend on it) and may start threads of its own
      u.noalias() = t.lazyProduct(lrows.transpose());
      for (int c = 0; c < k; ++c) {
        double* col = x + static_cast<Index>(rows_of(d, p + c) - f) * nr;
        for (int r = c; r < m; ++r) col[pos[rows_of(d, p + r)]] -= u(r, c);
      }
      next[d] = q;
      if (q < nrd) pending[super_of[rows_of(d, q)]].push_back(d);
    }
    std::vector<int>().swap(pending[s]);
    // the panel's own LDL^T (columns left to right, right-looking within the panel)
    for (int c = 0; c < w; ++c) {
      double* xc = x + static_cast<Index>(c) * nr;
      const double dc = xc[c];
      m_diag[f + c] = dc;
      if (dc == 0.0) {
        ok = false;
        break;
      }
      for (int c2 = c + 1; c2 < w; ++c2) {
        const double t = xc[c2];  // L(c2, c) D_c
        double* x2 = x + static_cast<Index>(c2) * nr;
        for (int r = c2; r < nr; ++r) x2[r] -= xc[r] * (t / dc);
      }
      const double inv = 1.0 / dc;
      for (int r = c + 1; r < nr; ++r) xc[r] *= inv;
    }
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
