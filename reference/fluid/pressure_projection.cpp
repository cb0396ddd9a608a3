#include "reference/fluid/pressure_projection.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>

#include "reference/core/parallel.hpp"
#include "reference/fluid/gradient.hpp"
#include "reference/fluid/mac_hierarchy.hpp"

namespace monolith {

namespace {

/// Below this many cells the matrix-free loops run on one thread: a parallel region costs more
/// than it saves on small grids (and much more on an oversubscribed machine).
constexpr Eigen::Index kParallelMin = kParallelMinWork;

// (W_L^u)^-1 entries are reciprocal_or_zero: 0 where W_L^u = 0 (such faces have no liquid cell
// beside them, so the matching row of G W_L^p is zero anyway).

/// Coefficient dt W_F^u P^-1 (W_L^u)^-1 / dx^2 of face f in the stencil form of A.
inline double face_coefficient(const PressureWeights& w, int f, double dt, double dx) {
  const double wf = w.fluid_face[f];
  return wf > 0.0 && w.face_density[f] > 0.0
             ? dt * wf * reciprocal_or_zero(w.liquid_face[f]) / (w.face_density[f] * dx * dx)
             : 0.0;
}

/// face_coefficient of every face.
VectorX face_coefficients(const PressureWeights& w, double dt, double dx) {
  VectorX k(w.fluid_face.size());
  for (int f = 0; f < k.size(); ++f) k[f] = face_coefficient(w, f, dt, dx);
  return k;
}

/// The 2 Dim faces of a cell with the other cell across each (-1 outside), and the sign of the
/// cell in that face's row of G.
template <int Dim>
struct CellFaces {
  std::array<int, 2 * Dim> face, other;
  std::array<double, 2 * Dim> sign;
};

template <int Dim>
CellFaces<Dim> cell_faces(const MacGrid<Dim>& grid, int cell) {
  CellFaces<Dim> cf;
  const VecI<Dim> c = grid.cell_coord(cell);
  for (int a = 0; a < Dim; ++a) {
    // lower face: the cell is its plus cell
    cf.face[2 * a] = grid.face_index(a, c);
    cf.other[2 * a] = grid.face_cell_minus(a, c);
    cf.sign[2 * a] = 1.0;
    // upper face: the cell is its minus cell
    VecI<Dim> upper = c;
    upper[a] += 1;
    const VecI<Dim> upper_face = grid.periodic(a) ? grid.wrap_cell(upper) : upper;
    cf.face[2 * a + 1] = grid.face_index(a, upper_face);
    cf.other[2 * a + 1] = grid.cell_index_or_outside(upper);
    cf.sign[2 * a + 1] = -1.0;
  }
  return cf;
}

/// The cell stencil (faces and cells across them, as MatrixFreePressureOperator::cell_stencil)
/// of the cell at x along axis 0 of a row, from the stencil of the row's first cell: along axes
/// 1.. both move with x; along axis 0 they follow x, wrapped on a periodic axis 0.
template <int Dim>
inline void shift_stencil(int x, int n0, bool periodic0, int cell,
                          const std::array<int, 2 * Dim>& face0,
                          const std::array<int, 2 * Dim>& other0, std::array<int, 2 * Dim>& face,
                          std::array<int, 2 * Dim>& other) {
  const bool last = x == n0 - 1;
  face[0] = face0[0] + x;
  other[0] = x > 0 ? cell - 1 : (periodic0 ? cell + n0 - 1 : -1);
  face[1] = last && periodic0 ? face0[0] : face0[0] + x + 1;
  other[1] = !last ? cell + 1 : (periodic0 ? cell - (n0 - 1) : -1);
  for (int j = 2; j < 2 * Dim; ++j) {
    face[j] = face0[j] + x;
    other[j] = other0[j] >= 0 ? other0[j] + x : -1;
  }
}

}  // namespace

template <int Dim>
VectorX density_diagonal(const MacGrid<Dim>& grid, const VectorX& face_density,
                         double fallback_density) {
  VectorX rho = face_density;
  density_diagonal_in_place(grid, rho, fallback_density);
  return rho;
}

template <int Dim>
void density_diagonal_in_place(const MacGrid<Dim>& grid, VectorX& rho, double fallback_density) {
  std::array<VecI<Dim>, Dim> lo, hi;
  for (int a = 0; a < Dim; ++a) {
    lo[a] = VecI<Dim>::Zero();
    hi[a] = grid.face_dims(a) - VecI<Dim>::Ones();
  }
  density_diagonal_in_place<Dim>(grid, rho, fallback_density, lo, hi);
}

namespace {

/// The sorted union of lists that are each sorted and free of repeats (a set union, pair by pair
/// in list order; the result is unique, so it does not depend on how the values were split).
std::vector<int> union_of_sorted(std::vector<std::vector<int>>& lists) {
  if (lists.empty()) return {};
  std::vector<int> merged, next;
  merged.swap(lists[0]);
  for (std::size_t k = 1; k < lists.size(); ++k) {
    next.resize(merged.size() + lists[k].size());
    next.erase(std::set_union(merged.begin(), merged.end(), lists[k].begin(), lists[k].end(),
                              next.begin()),
               next.end());
    merged.swap(next);
  }
  return merged;
}

}  // namespace

template <int Dim>
void density_diagonal_in_place(const MacGrid<Dim>& grid, VectorX& rho, double fallback_density,
                               const std::array<VecI<Dim>, Dim>& lo,
                               const std::array<VecI<Dim>, Dim>& hi,
                               const std::vector<std::pair<long, long>>* fill) {
  const int nf = grid.num_faces();
  // a face without a density whose cells have no face with one gets the fallback: that is every
  // such face except those next to the faces with a density, which are collected from those
  // (work in proportion to the liquid, not the box: issue 20). The means are taken from the
  // input values before any face is written (the faces near the liquid have none themselves),
  // so writing in place gives the values of a separate output.
  // (on several threads in blocks of rows of the boxes, which hold every face with a density:
  // the sorted, unique list and every value are the same for any team size and any boxes)
  // (the team from the boxes' faces, not their rows: the 64^3 viscous bunny's boxes have under
  // 4096 rows, on which gather_in_order stays on one thread, but ~50k faces; the order of the
  // list does not matter, it is sorted)
  std::array<int, Dim + 1> row_start{};
  std::array<VecI<Dim>, Dim> rows_box;
  long box_faces = 0;
  for (int a = 0; a < Dim; ++a) {
    rows_box[a] = hi[a] - lo[a] + VecI<Dim>::Ones();
    const bool empty = (rows_box[a].array() <= 0).any();
    const int rows = empty ? 0 : rows_box[a].prod() / rows_box[a][0];
    row_start[a + 1] = row_start[a] + rows;
    if (!empty) box_faces += rows_box[a].prod();
  }
  const auto emit = [&](int r, std::vector<int>& out) {
    int axis = 0;
    while (r >= row_start[axis + 1]) ++axis;
    VecI<Dim> one_row = rows_box[axis];
    const int nx = one_row[0];
    one_row[0] = 1;
    VecI<Dim> coord = lo[axis] + lattice_coord<Dim>(r - row_start[axis], one_row);
    const int first = grid.face_index(axis, coord);
    for (int x = 0; x < nx; ++x) {
      if (!(rho[first + x] > 0.0)) continue;
      coord[0] = lo[axis][0] + x;
      for (int cell : {grid.face_cell_minus(axis, coord), grid.face_cell_plus(axis, coord)}) {
        if (cell < 0) continue;
        for (int g : cell_faces<Dim>(grid, cell).face)
          if (!(rho[g] > 0.0)) out.push_back(g);
      }
    }
  };
  const int total_rows = row_start[Dim];
  const int parts = std::max(1, std::min(team_threads(box_faces), total_rows));
  std::vector<std::vector<int>> part(parts);
  // each part's list sorted and made unique by its own thread (a face is listed once per face
  // with a density beside it: several times), then the parts' union in part order; the sorted,
  // unique list of all faces emitted, whatever the parts (the 64^3 viscous bunny's list was
  // sorted whole on one thread below 8192 entries: 0.6-0.8 ms per frame of serial sort)
#pragma omp parallel for schedule(static, 1) num_threads(parts)
  for (int t = 0; t < parts; ++t) {
    for (int r = static_cast<int>(static_cast<long>(total_rows) * t / parts);
         r < static_cast<int>(static_cast<long>(total_rows) * (t + 1) / parts); ++r)
      emit(r, part[t]);
    std::sort(part[t].begin(), part[t].end());
    part[t].erase(std::unique(part[t].begin(), part[t].end()), part[t].end());
  }
  const std::vector<int> near = union_of_sorted(part);
  const int nn = static_cast<int>(near.size());
  std::vector<double> near_rho(near.size());
  // (the team from the reads: 2 cells of 2 Dim faces per listed face)
#pragma omp parallel for schedule(static) num_threads(team_threads(4L * Dim * nn))
  for (int n = 0; n < nn; ++n) {
    // mean of the known densities on the faces of the two cells beside the face
    const auto [axis, coord] = grid.face_coord(near[n]);
    double sum = 0.0;
    int count = 0;
    for (int cell : {grid.face_cell_minus(axis, coord), grid.face_cell_plus(axis, coord)}) {
      if (cell < 0) continue;
      const auto cf = cell_faces<Dim>(grid, cell);
      for (int g : cf.face)
        if (rho[g] > 0.0) {
          sum += rho[g];
          ++count;
        }
    }
    near_rho[n] = count > 0 ? sum / count : fallback_density;
  }
  if (fill) {
    // (kern22) the fallback on the listed ranges only: the others hold it already
    for (const auto& [begin, end] : *fill) {
      const long first = std::max(begin, 0L), last = std::min(end, static_cast<long>(nf));
#pragma omp parallel for schedule(static) num_threads(team_threads(last - first))
      for (long f = first; f < last; ++f)
        if (!(rho[f] > 0.0)) rho[f] = fallback_density;
    }
  } else {
#pragma omp parallel for schedule(static) num_threads(team_threads(nf))
    for (int f = 0; f < nf; ++f)
      if (!(rho[f] > 0.0)) rho[f] = fallback_density;
  }
  // (the listed faces are distinct: each written by one thread)
#pragma omp parallel for schedule(static) num_threads(team_threads(nn))
  for (int n = 0; n < nn; ++n) rho[near[n]] = near_rho[n];
}

template <int Dim>
PressureDofs select_pressure_dofs(const MacGrid<Dim>& grid, const PressureWeights& w, double dt,
                                  const LiquidBand* band) {
  PressureDofs dofs;
  dofs.dof_of_cell.assign(grid.num_cells(), -1);
  // active: liquid in the cell and at least one face open to fluid
  auto visit = [&](int c) {
    if (!(w.liquid_cell[c] > 0.0)) return;
    const auto cf = cell_faces<Dim>(grid, c);
    bool open = false;
    for (int f : cf.face) open = open || w.fluid_face[f] > 0.0;
    if (!open) return;
    dofs.dof_of_cell[c] = dofs.size();
    dofs.cell_of_dof.push_back(c);
  };
  if (band && band->valid) {
    // the cells of the band's box (W_L^p = 0 outside it), rows along x in increasing index
    // order: the order of the pass over every cell (issue 20)
    VecI<Dim> lo, hi;
    for (int a = 0; a < Dim; ++a) {
      lo[a] = std::max(band->cell_lo[a], 0);
      hi[a] = std::min(band->cell_hi[a], grid.cells()[a] - 1);
    }
    if ((lo.array() <= hi.array()).all()) {
      VecI<Dim> rows_box = hi - lo + VecI<Dim>::Ones();
      rows_box[0] = 1;
      for (int r = 0; r < rows_box.prod(); ++r) {
        VecI<Dim> c = lo + lattice_coord<Dim>(r, rows_box);
        const int start = grid.cell_index(c);
        for (int k = 0; k <= hi[0] - lo[0]; ++k) visit(start + k);
      }
    }
  } else {
    for (int c = 0; c < grid.num_cells(); ++c) visit(c);
  }
  // connected groups over weighted faces; a group is closed if no weighted face leaves it
  // (the faces' coefficients computed where the search reads them, the faces of the DOFs'
  // cells: no pass over every face of the grid, issue 20)
  const double dx = grid.dx();
  const int n = dofs.size();
  std::vector<int> group(n, -1);
  std::vector<int> stack;
  int groups = 0;
  for (int seed = 0; seed < n; ++seed) {
    if (group[seed] >= 0) continue;
    bool closed = true;
    std::vector<int> members;
    group[seed] = groups;
    stack.push_back(seed);
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      members.push_back(i);
      const int cell = dofs.cell_of_dof[i];
      const auto cf = cell_faces<Dim>(grid, cell);
      for (int j = 0; j < 2 * Dim; ++j) {
        if (!(face_coefficient(w, cf.face[j], dt, dx) > 0.0) || cf.other[j] == cell) continue;
        const int other = cf.other[j] >= 0 ? dofs.dof_of_cell[cf.other[j]] : -1;
        if (other < 0) {
          closed = false;  // pressure is pinned to zero across this face (air, open boundary)
          continue;
        }
        if (group[other] < 0) {
          group[other] = groups;
          stack.push_back(other);
        }
      }
    }
    if (closed) {
      // null vector: W_L^p p constant on the group
      VectorX v = VectorX::Zero(n);
      for (int i : members) v[i] = 1.0 / w.liquid_cell[dofs.cell_of_dof[i]];
      dofs.null_space.push_back(v / v.norm());
    }
    ++groups;
  }
  return dofs;
}

template <int Dim>
ExplicitPressureSystem assemble_explicit_pressure(const MacGrid<Dim>& grid,
                                                  const PressureWeights& w,
                                                  const PressureDofs& dofs, double dt,
                                                  const VectorX& u_star) {
  ExplicitPressureSystem sys;
  // the named matrices of eq. (8)
  sys.G = gradient_matrix(grid);
  sys.W_F_u = sparse_diagonal(w.fluid_face);
  sys.W_L_p = sparse_diagonal(w.liquid_cell);
  sys.W_L_u_inv = sparse_diagonal(w.liquid_face.unaryExpr(&reciprocal_or_zero));
  VectorX p_inv(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) p_inv[f] = reciprocal_or_zero(w.face_density[f]);
  sys.P_inv = sparse_diagonal(p_inv);
  // selection of the active DOFs
  std::vector<Triplet> t;
  for (int i = 0; i < dofs.size(); ++i) t.emplace_back(i, dofs.cell_of_dof[i], 1.0);
  sys.S.resize(dofs.size(), grid.num_cells());
  sys.S.setFromTriplets(t.begin(), t.end());
  // A = dt W_L^p G^T W_F^u P^-1 (W_L^u)^-1 G W_L^p, restricted by S
  const SparseMatrix Gt = sys.G.transpose();
  const SparseMatrix A_full =
      dt * (sys.W_L_p * Gt * sys.W_F_u * sys.P_inv * sys.W_L_u_inv * sys.G * sys.W_L_p);
  const SparseMatrix St = sys.S.transpose();
  sys.A = sys.S * A_full * St;
  // b = W_L^p G^T W_F^u u*, restricted by S
  sys.b = sys.S * (sys.W_L_p * (Gt * (sys.W_F_u * u_star)));
  return sys;
}

template <int Dim>
MatrixFreePressureOperator<Dim>::MatrixFreePressureOperator(const MacGrid<Dim>& grid,
                                                            const PressureWeights& w,
                                                            const PressureDofs& dofs, double dt)
    : cells_(grid.cells()),
      periodic_(grid.periodic()),
      inv_dx_(1.0 / grid.dx()),
      num_dofs_(dofs.size()),
      dof_of_cell_(dofs.dof_of_cell),
      coefficient_(face_coefficients(w, dt, grid.dx())),
      fluid_face_(w.fluid_face),
      null_space_(dofs.null_space) {
  for (int a = 0; a < Dim; ++a) {
    face_offset_[a] = grid.face_offset(a);
    face_dims_[a] = grid.face_dims(a);
  }
  liquid_.resize(num_dofs_);
  diagonal_.setZero(num_dofs_);
  // W_L^p and A_ii = W_i^2 sum_f k_f per DOF (a face onto the cell itself, on a periodic axis
  // of one cell, has a zero row in G and is left out)
  for (int i = 0; i < num_dofs_; ++i) {
    const int cell = dofs.cell_of_dof[i];
    liquid_[i] = w.liquid_cell[cell];
    std::array<int, 2 * Dim> face, other;
    cell_stencil(grid.cell_coord(cell), face, other);
    double diag = 0.0;
    for (int j = 0; j < 2 * Dim; ++j)
      if (other[j] != cell) diag += coefficient_[face[j]];
    diagonal_[i] = liquid_[i] * liquid_[i] * diag;
  }
  // red-black colours by the parity of the cell coordinates
  for (int a = 0; a < Dim; ++a)
    if (grid.periodic(a) && grid.cells()[a] % 2 == 1 && grid.cells()[a] > 1)
      colouring_valid_ = false;
  q_.setZero(grid.num_cells());
}

template <int Dim>
void MatrixFreePressureOperator<Dim>::cell_stencil(const VecI<Dim>& c,
                                                   std::array<int, 2 * Dim>& face,
                                                   std::array<int, 2 * Dim>& other) const {
  // linear indices of c along the face lattices and the cells, then +-1 along each axis
  for (int a = 0; a < Dim; ++a) {
    const VecI<Dim>& fd = face_dims_[a];
    int lower_face = 0, cell = 0;
    for (int b = Dim - 1; b >= 0; --b) {
      lower_face = lower_face * fd[b] + c[b];
      cell = cell * cells_[b] + c[b];
    }
    int stride = 1, face_stride = 1;
    for (int b = 0; b < a; ++b) {
      stride *= cells_[b];
      face_stride *= fd[b];
    }
    const int n = cells_[a];
    // lower face: the cell is its plus cell; the minus cell is c - e_a
    face[2 * a] = face_offset_[a] + lower_face;
    other[2 * a] = c[a] > 0 ? cell - stride : (periodic_[a] ? cell + (n - 1) * stride : -1);
    // upper face: the cell is its minus cell; the plus cell is c + e_a
    const bool last = c[a] == n - 1;
    face[2 * a + 1] = face_offset_[a] + lower_face +
                      (last && periodic_[a] ? -(n - 1) * face_stride : face_stride);
    other[2 * a + 1] = !last ? cell + stride : (periodic_[a] ? cell - (n - 1) * stride : -1);
  }
}

template <int Dim>
void MatrixFreePressureOperator<Dim>::scatter(const VectorX& x) const {
  // (orphaned omp for, a barrier at its end: called inside the caller's parallel region)
  const int num_cells = static_cast<int>(q_.size());
#pragma omp for schedule(static)
  for (int c = 0; c < num_cells; ++c) {
    const int i = dof_of_cell_[c];
    q_[c] = i >= 0 ? liquid_[i] * x[i] : 0.0;
  }
}

template <int Dim>
SparseMatrix MatrixFreePressureOperator<Dim>::matrix(const PressureDofs& dofs) const {
  // row i: A_ii = diagonal_[i], A_ij = -W_i k_f W_j for each face f to an active cell j != i
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(static_cast<std::size_t>(num_dofs_) * (2 * Dim + 1));
  for (int i = 0; i < num_dofs_; ++i) {
    const int cell = dofs.cell_of_dof[i];
    std::array<int, 2 * Dim> face, other;
    cell_stencil(lattice_coord<Dim>(cell, cells_), face, other);
    entries.emplace_back(i, i, diagonal_[i]);
    for (int j = 0; j < 2 * Dim; ++j) {
      if (other[j] < 0 || other[j] == cell) continue;
      const int k = dof_of_cell_[other[j]];
      if (k >= 0) entries.emplace_back(i, k, -liquid_[i] * coefficient_[face[j]] * liquid_[k]);
    }
  }
  SparseMatrix a(num_dofs_, num_dofs_);
  a.setFromTriplets(entries.begin(), entries.end());
  a.makeCompressed();
  return a;
}

template <int Dim>
void MatrixFreePressureOperator<Dim>::apply(const VectorX& x, VectorX& y) const {
  y.resize(num_dofs_);
  // one parallel region: q = W x, a barrier, then
  // (A x)_i = W_i sum_f k_f (q_i - q_j), the stencil of W G^T K G W, per grid row
  const int n0 = cells_[0];
  const int rows = static_cast<int>(q_.size()) / n0;
  // the team size measured per call (AdaptiveTeam), one thread below kParallelMinWork cells
  static AdaptiveTeam site;
  TeamScope team(site, static_cast<long>(q_.size()));
#pragma omp parallel num_threads(team.threads()) if (team.parallel())
  {
  scatter(x);
#pragma omp for schedule(dynamic, dynamic_chunk(rows)) nowait
  for (int r = 0; r < rows; ++r) {
    VecI<Dim> c = VecI<Dim>::Zero();
    int rest = r;
    for (int a = 1; a < Dim; ++a) {
      c[a] = rest % cells_[a];
      rest /= cells_[a];
    }
    // the stencil of the row's first cell, shifted along the row
    std::array<int, 2 * Dim> face0, other0, face, other;
    cell_stencil(c, face0, other0);
    for (int x0 = 0; x0 < n0; ++x0) {
      const int cell = r * n0 + x0;
      const int i = dof_of_cell_[cell];
      if (i < 0) continue;
      shift_stencil<Dim>(x0, n0, periodic_[0], cell, face0, other0, face, other);
      const double qi = q_[cell];
      double sum = 0.0;
      for (int j = 0; j < 2 * Dim; ++j)
        sum += coefficient_[face[j]] * (qi - (other[j] >= 0 ? q_[other[j]] : 0.0));
      y[i] = liquid_[i] * sum;
    }
  }
  }
}

template <int Dim>
void MatrixFreePressureOperator<Dim>::sweep(bool reverse, const VectorX& rhs, VectorX& x,
                                            double omega, const std::vector<char>* active) const {
  const int n0 = cells_[0];
  const int rows = static_cast<int>(q_.size()) / n0;
  auto relax_row = [&](int r, int parity) {
    VecI<Dim> c = VecI<Dim>::Zero();
    int rest = r, sum = 0;
    for (int a = 1; a < Dim; ++a) {
      c[a] = rest % cells_[a];
      rest /= cells_[a];
      sum += c[a];
    }
    const int first = (parity + sum) % 2;
    if (first >= n0) return;
    std::array<int, 2 * Dim> face0, other0, face, other;
    cell_stencil(c, face0, other0);
    const int last = first + 2 * ((n0 - 1 - first) / 2);
    // within an independent colour the order does not matter: ascending (memory order) then
    const bool descending = reverse && !colouring_valid_;
    for (int step = 0; step <= (last - first) / 2; ++step) {
      const int x0 = descending ? last - 2 * step : first + 2 * step;
      const int cell = r * n0 + x0;
      const int i = dof_of_cell_[cell];
      if (i < 0 || diagonal_[i] == 0.0 || (active && !(*active)[i])) continue;
      shift_stencil<Dim>(x0, n0, periodic_[0], cell, face0, other0, face, other);
      // sum_{j != i} A_ij x_j = -W_i sum_f k_f W_j x_j over the neighbours of i
      double off = 0.0;
      for (int j = 0; j < 2 * Dim; ++j)
        if (other[j] >= 0 && other[j] != cell) off -= coefficient_[face[j]] * q_[other[j]];
      off *= liquid_[i];
      x[i] = (1.0 - omega) * x[i] + omega * (rhs[i] - off) / diagonal_[i];
      q_[cell] = liquid_[i] * x[i];
    }
  };
  // one parallel region per sweep (only with a valid colouring and enough cells): q = W x of
  // the starting x (kept current as DOFs change), then the two colours, a barrier after each
  static AdaptiveTeam site;  // the team size measured per call (parallel.hpp)
  TeamScope team(site, colouring_valid_ ? static_cast<long>(q_.size()) : 0);
#pragma omp parallel num_threads(team.threads()) if (team.parallel())
  {
    scatter(x);
    for (int step = 0; step < 2; ++step) {
      const int parity = reverse ? 1 - step : step;
      if (colouring_valid_) {
        // cells of one colour only couple to the other colour: rows in parallel, each row
        // written by one thread (any split gives the same result)
#pragma omp for schedule(dynamic, dynamic_chunk(rows))
        for (int r = 0; r < rows; ++r) relax_row(r, parity);
      } else if (!reverse) {
        for (int r = 0; r < rows; ++r) relax_row(r, parity);
      } else {
        for (int r = rows - 1; r >= 0; --r) relax_row(r, parity);
      }
    }
  }
}

template <int Dim>
void MatrixFreePressureOperator<Dim>::forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                                    const std::vector<char>* active) const {
  sweep(false, rhs, x, omega, active);
}

template <int Dim>
void MatrixFreePressureOperator<Dim>::backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                                     const std::vector<char>* active) const {
  sweep(true, rhs, x, omega, active);
}

template <int Dim>
VectorX MatrixFreePressureOperator<Dim>::rhs(const VectorX& u_star) const {
  VectorX b(num_dofs_);
  // b_i = W_i sum_f s_if W_F^u_f u*_f / dx  (s = +1 on the cell's lower faces, -1 on upper, 0
  // on a face onto the cell itself)
  const int num_cells = static_cast<int>(q_.size());
#pragma omp parallel for schedule(static) num_threads(process_threads()) if (q_.size() > kParallelMin)
  for (int cell = 0; cell < num_cells; ++cell) {
    const int i = dof_of_cell_[cell];
    if (i < 0) continue;
    VecI<Dim> c = lattice_coord<Dim>(cell, cells_);
    std::array<int, 2 * Dim> face, other;
    cell_stencil(c, face, other);
    double sum = 0.0;
    for (int j = 0; j < 2 * Dim; ++j) {
      const double sign = other[j] == cell ? 0.0 : (j % 2 == 0 ? 1.0 : -1.0);
      sum += sign * fluid_face_[face[j]] * u_star[face[j]];
    }
    b[i] = liquid_[i] * sum * inv_dx_;
  }
  return b;
}

template <int Dim>
std::size_t MatrixFreePressureOperator<Dim>::memory_bytes() const {
  std::size_t bytes = sizeof(int) * dof_of_cell_.size() +
                      sizeof(double) * (liquid_.size() + coefficient_.size() +
                                        fluid_face_.size() + diagonal_.size() + q_.size());
  for (const VectorX& n : null_space_) bytes += sizeof(double) * n.size();
  return bytes;
}

template <int Dim>
double MatrixFreePressureOperator<Dim>::bytes_per_apply() const {
  // compulsory traffic, the same count as SparseMatrixOperator's: every stored array the apply
  // reads once (cell -> DOF map, k per face, W_L^p per DOF), x read once, y written once; the
  // scratch q and repeated reads that can hit the cache are not counted, so the bandwidth
  // derived from it is a lower bound
  return static_cast<double>(dof_of_cell_.size()) * sizeof(int) +
         static_cast<double>(coefficient_.size()) * sizeof(double) +
         static_cast<double>(num_dofs_) * 3 * sizeof(double);
}

template <int Dim>
void apply_pressure_update(const MacGrid<Dim>& grid, const PressureWeights& w, double dt,
                           const VectorX& pressure, VectorX& u) {
  // q = W_L^p p, then the face update with G q
  const VectorX q = w.liquid_cell.cwiseProduct(pressure);
  const VectorX gq = apply_gradient(grid, q);
#pragma omp parallel for schedule(static) num_threads(team_threads(grid.num_faces()))
  for (int f = 0; f < grid.num_faces(); ++f) {
    if (!(w.fluid_face[f] * w.liquid_face[f] > 0.0) || !(w.face_density[f] > 0.0)) continue;
    u[f] -= dt * gq[f] / (w.face_density[f] * w.liquid_face[f]);
  }
}

VectorX scatter_pressure(const PressureDofs& dofs, const VectorX& p_dofs, int num_cells) {
  VectorX p = VectorX::Zero(num_cells);
  for (int i = 0; i < dofs.size(); ++i) p[dofs.cell_of_dof[i]] = p_dofs[i];
  return p;
}

namespace {

/// MGPCG (McAdams et al. 2010): PCG on the pressure system of either back end, preconditioned by
/// one symmetric V-cycle of the cell multigrid on the assembled matrix A (the matrix-free back end
/// assembles A for the hierarchy only; its own stencils still apply A). Built lazily, so a
/// solve that stops before its first iteration pays nothing. Enclosed liquid makes A singular
/// on constants: the hierarchy inverts A + 1e-10 diag(A), and PCG projects the null space out of
/// every preconditioned residual as for SSOR.
template <int Dim>
PcgResult mgpcg_pressure(const MacGrid<Dim>& grid, const PressureWeights& w, const PressureDofs& dofs,
                         double dt, Backend backend, const PcgSettings& settings, const VectorX& u,
                         VectorX& p, const VectorX* divergence_source) {
  std::optional<ExplicitPressureSystem> sys;
  std::optional<MatrixFreePressureOperator<Dim>> mf;
  std::optional<SparseMatrixOperator> explicit_op;
  const LinearOperator* op = nullptr;
  VectorX b;
  if (backend == Backend::explicit_matrices) {
    sys = assemble_explicit_pressure(grid, w, dofs, dt, u);
    explicit_op.emplace(sys->A, dofs.null_space);
    op = &*explicit_op;
    b = sys->b;
  } else {
    mf.emplace(grid, w, dofs, dt);
    op = &*mf;
    b = mf->rhs(u);
  }
  add_divergence_source(dofs.cell_of_dof, w.liquid_cell, divergence_source, 0, b);
  const LazyPreconditioner m(dofs.size(), "multigrid", [&]() -> std::unique_ptr<Preconditioner> {
    SparseMatrix a = sys ? sys->A : mf->matrix(dofs);
    if (!dofs.null_space.empty())
      for (int k = 0; k < a.outerSize(); ++k)
        for (SparseMatrix::InnerIterator it(a, k); it; ++it)
          if (it.col() == it.row()) it.valueRef() *= 1.0 + 1e-10;
    return std::make_unique<MultigridPreconditioner>(
        cell_multigrid<Dim>(grid, dofs.cell_of_dof, std::move(a), MacMultigridOptions{}));
  });
  return pcg_solve(*op, b, p, settings, m);
}

}  // namespace

void add_divergence_source(const std::vector<int>& cell_of_dof, const VectorX& liquid_cell,
                           const VectorX* divergence_source, int offset, VectorX& b) {
  if (!divergence_source || divergence_source->size() == 0) return;
  const VectorX& d = *divergence_source;
  for (std::size_t k = 0; k < cell_of_dof.size(); ++k) {
    const int c = cell_of_dof[k];
    if (c < d.size()) b[offset + static_cast<int>(k)] += liquid_cell[c] * d[c];
  }
}

template <int Dim>
double liquid_rhs_round_off(const MacGrid<Dim>& grid, const VectorX& fluid_face,
                            const VectorX& u_star, const VectorX* divergence_source,
                            const LiquidBand* band) {
  constexpr double kEpsilon = std::numeric_limits<double>::epsilon();  // 2^-52
  const double speed = weighted_face_speed(grid, fluid_face, u_star, band);
  double source = 0.0;
  if (divergence_source && divergence_source->size() > 0) source = divergence_source->cwiseAbs().maxCoeff();
  return kRhsRoundOffUlps * kEpsilon * ((2.0 * Dim / grid.dx()) * speed + source);
}

template <int Dim>
PressureSolveResult solve_pressure(const MacGrid<Dim>& grid, const PressureWeights& w, double dt,
                                   Backend backend, const PcgSettings& settings,
                                   VectorX& u, PreconditionerKind preconditioner,
                                   const VectorX* divergence_source) {
  PressureSolveResult result;
  // line 7: active DOFs
  const PressureDofs dofs = select_pressure_dofs(grid, w, dt);
  result.dofs = dofs.size();
  VectorX p = VectorX::Zero(dofs.size());
  // a right-hand side at its own round-off (a liquid in free fall) is zero: p = 0, no iteration,
  // no preconditioner set-up (liquid_rhs_round_off; docs/preconditioners.md section 35, (P16))
  PcgSettings pcg = settings;
  pcg.zero_rhs = std::max(pcg.zero_rhs, liquid_rhs_round_off(grid, w.fluid_face, u, divergence_source));
  // lines 8-10: assemble (or set up the stencil) and solve
  if (preconditioner == PreconditionerKind::multigrid && dofs.size() > 0) {
    result.pcg = mgpcg_pressure(grid, w, dofs, dt, backend, pcg, u, p, divergence_source);
  } else {
    switch (backend) {
      case Backend::explicit_matrices: {
        const ExplicitPressureSystem sys = assemble_explicit_pressure(grid, w, dofs, dt, u);
        const SparseMatrixOperator op(sys.A, dofs.null_space);
        VectorX b = sys.b;
        add_divergence_source(dofs.cell_of_dof, w.liquid_cell, divergence_source, 0, b);
        result.pcg = pcg_solve(op, b, p, pcg);
        break;
      }
      case Backend::matrix_free: {
        const MatrixFreePressureOperator<Dim> op(grid, w, dofs, dt);
        VectorX b = op.rhs(u);
        add_divergence_source(dofs.cell_of_dof, w.liquid_cell, divergence_source, 0, b);
        result.pcg = pcg_solve(op, b, p, pcg);
        break;
      }
    }
  }
  // line 11: velocity update
  // (none for p = +0: it would subtract +0 from every face, leaving u bit for bit; a
  // right-hand side at its round-off, docs/preconditioners.md section 35)
  result.pressure = scatter_pressure(dofs, p, grid.num_cells());
  if (!all_positive_zero(p)) apply_pressure_update(grid, w, dt, result.pressure, u);
  return result;
}

#define MONOLITH_INSTANTIATE(D)                                                                  \
  template VectorX density_diagonal<D>(const MacGrid<D>&, const VectorX&, double);               \
  template void density_diagonal_in_place<D>(const MacGrid<D>&, VectorX&, double);               \
  template void density_diagonal_in_place<D>(const MacGrid<D>&, VectorX&, double,        \
                                             const std::array<VecI<D>, D>&,                \
                                             const std::array<VecI<D>, D>&,                \
                                             const std::vector<std::pair<long, long>>*);   \
  template PressureDofs select_pressure_dofs<D>(const MacGrid<D>&, const PressureWeights&,       \
                                                double, const LiquidBand*);                      \
  template ExplicitPressureSystem assemble_explicit_pressure<D>(                                 \
      const MacGrid<D>&, const PressureWeights&, const PressureDofs&, double, const VectorX&);   \
  template class MatrixFreePressureOperator<D>;                                                  \
  template void apply_pressure_update<D>(const MacGrid<D>&, const PressureWeights&, double,      \
                                         const VectorX&, VectorX&);                              \
  template PressureSolveResult solve_pressure<D>(const MacGrid<D>&, const PressureWeights&,      \
                                                 double, Backend, const PcgSettings&, \
                                                 VectorX&, PreconditionerKind, const VectorX*); \
  template double liquid_rhs_round_off<D>(const MacGrid<D>&, const VectorX&, const VectorX&,     \
                                          const VectorX*, const LiquidBand*);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
