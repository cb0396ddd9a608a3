#include "reference/grid/volume_fractions.hpp"
#include "reference/core/first_touch.hpp"
#include "reference/core/huge_pages.hpp"
#include "reference/core/parallel.hpp"
#include "reference/grid/box_rows.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace monolith {

namespace {

/// Reference vertices of the unit simplex (origin and the unit vectors), 3D.
Eigen::Vector3d tet_vertex(int k) {
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  if (k > 0) v[k - 1] = 1.0;
  return v;
}

double abs_det(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
               const Eigen::Vector3d& d) {
  Eigen::Matrix3d m;
  m << b - a, c - a, d - a;
  return std::abs(m.determinant());
}

/// Fraction of a triangle where phi < 0 (phi = 0 counts as outside).
double triangle_fraction(const std::array<double, 3>& phi) {
  int negatives = 0;
  for (double p : phi) negatives += p < 0.0;
  if (negatives == 0) return 0.0;
  if (negatives == 3) return 1.0;
  // the lonely vertex (the one whose sign differs) cuts off a similar corner triangle
  const bool lonely_negative = negatives == 1;
  int k = 0;
  while ((phi[k] < 0.0) != lonely_negative) ++k;
  const double a = phi[k], b = phi[(k + 1) % 3], c = phi[(k + 2) % 3];
  const double corner = a * a / ((a - b) * (a - c));
  return lonely_negative ? corner : 1.0 - corner;
}

/// Fraction of a tetrahedron where phi < 0 (phi = 0 counts as outside).
double tetrahedron_fraction(const std::array<double, 4>& phi) {
  int negatives = 0;
  for (double p : phi) negatives += p < 0.0;
  if (negatives == 0) return 0.0;
  if (negatives == 4) return 1.0;
  if (negatives == 1 || negatives == 3) {
    // one vertex of the other sign: a corner tetrahedron scaled by the three edge ratios
    const bool lonely_negative = negatives == 1;
    int k = 0;
    while ((phi[k] < 0.0) != lonely_negative) ++k;
    double corner = 1.0;
    for (int j = 0; j < 4; ++j)
      if (j != k) corner *= phi[k] / (phi[k] - phi[j]);
    return lonely_negative ? corner : 1.0 - corner;
  }
  // two negatives (i, j), two positives (k, l): the negative part is a prism with triangles
  // (V_i, P_ik, P_il) and (V_j, P_jk, P_jl), split into three tetrahedra
  std::array<int, 2> neg{}, pos{};
  int n = 0, p = 0;
  for (int v = 0; v < 4; ++v) (phi[v] < 0.0 ? neg[n++] : pos[p++]) = v;
  auto cut = [&](int a, int b) {
    const double t = phi[a] / (phi[a] - phi[b]);
    return Eigen::Vector3d(tet_vertex(a) + t * (tet_vertex(b) - tet_vertex(a)));
  };
  const Eigen::Vector3d a0 = tet_vertex(neg[0]), a1 = cut(neg[0], pos[0]), a2 = cut(neg[0], pos[1]);
  const Eigen::Vector3d b0 = tet_vertex(neg[1]), b1 = cut(neg[1], pos[0]), b2 = cut(neg[1], pos[1]);
  // reference tetrahedron volume is 1/6, each |det| is 6 times a volume
  return abs_det(a0, a1, a2, b2) + abs_det(a0, a1, b1, b2) + abs_det(a0, b0, b1, b2);
}

}  // namespace

template <>
double simplex_negative_fraction<2>(const std::array<double, 3>& phi) {
  return triangle_fraction(phi);
}

template <>
double simplex_negative_fraction<3>(const std::array<double, 4>& phi) {
  return tetrahedron_fraction(phi);
}

template <int Dim>
double lattice_cell_negative_fraction(const std::array<double, (1 << Dim)>& corner_phi) {
  // all one sign: exact without splitting
  int negatives = 0;
  for (double p : corner_phi) negatives += p < 0.0;
  if (negatives == 0) return 0.0;
  if (negatives == (1 << Dim)) return 1.0;
  // Kuhn split: one simplex per axis permutation, walking from corner 0 to the opposite corner
  std::array<int, Dim> perm;
  std::iota(perm.begin(), perm.end(), 0);
  double sum = 0.0;
  int count = 0;
  do {
    std::array<double, Dim + 1> simplex;
    int corner = 0;
    simplex[0] = corner_phi[corner];
    for (int m = 0; m < Dim; ++m) {
      corner |= 1 << perm[m];
      simplex[m + 1] = corner_phi[corner];
    }
    sum += simplex_negative_fraction<Dim>(simplex);
    ++count;
  } while (std::next_permutation(perm.begin(), perm.end()));
  return sum / count;
}

template <int Dim>
void solid_phi_on_lattice(const MacGrid<Dim>& /*grid*/, const SampleLattice<Dim>& lattice,
                          const std::vector<ShapePtr<Dim>>& solids, double shrink_in_metres,
                          VectorX& phi) {
  if (phi.size() != lattice.size()) phi.resize(lattice.size());
  if (solids.empty()) {
    // the min over no solid: +infinity (+ zeta) everywhere, without visiting the positions
    phi.setConstant(std::numeric_limits<double>::infinity() + shrink_in_metres);
    return;
  }
  // min over solids of the signed distance, then shifted inward by zeta (section 4.4.6)
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    double d = std::numeric_limits<double>::infinity();
    for (const auto& s : solids) d = std::min(d, s->distance(x));
    phi[k] = d + shrink_in_metres;
  }
}

template <int Dim>
VectorX solid_phi_on_lattice(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const std::vector<ShapePtr<Dim>>& solids, double shrink_in_metres) {
  VectorX phi;
  solid_phi_on_lattice(grid, lattice, solids, shrink_in_metres, phi);
  return phi;
}

int map_lattice_cell(int l, int cells2, bool periodic) {
  if (periodic) return ((l % cells2) + cells2) % cells2;
  if (l < 0) return -l - 1;
  if (l >= cells2) return 2 * cells2 - l - 1;
  return l;
}

template <int Dim>
double lattice_cube_negative_fraction(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                      const VecI<Dim>& lower, const VectorX& phi) {
  constexpr int kCorners = 1 << Dim;
  // per axis, the lattice coordinate of corner bit k of sub-cube bit s (after wrapping or
  // mirroring the sub-cube) times the axis stride: 2 x 2 offsets, summed into point indices
  std::array<std::array<std::array<int, 2>, 2>, Dim> offset;
  int stride = 1;
  for (int a = 0; a < Dim; ++a) {
    for (int s = 0; s < 2; ++s) {
      const int l = map_lattice_cell(lower[a] + s, 2 * grid.cells()[a], grid.periodic(a));
      offset[a][s] = {l * stride, (l + 1) * stride};
    }
    stride *= lattice.dims[a];
  }
  // the corner values of every sub-cube; all of one sign (the cube away from the surface, most
  // of the domain) gives 0 or 1 without the Kuhn split (the same value as summing the 2^Dim
  // sub-cubes' 0s or 1s)
  std::array<std::array<double, kCorners>, kCorners> corners;
  int negatives = 0;
  for (int sub = 0; sub < kCorners; ++sub)
    for (int k = 0; k < kCorners; ++k) {
      int index = 0;
      for (int a = 0; a < Dim; ++a) index += offset[a][(sub >> a) & 1][(k >> a) & 1];
      const double v = phi[index];
      corners[sub][k] = v;
      negatives += v < 0.0;
    }
  return sub_cubes_negative_fraction<Dim>(corners, negatives);
}

namespace {

/// floor(a / 2) for any sign of a.
inline int floor_half(int a) { return a >= 0 ? a / 2 : -((1 - a) / 2); }

/// Calls fn(c) for every c in [lo, hi] (inclusive) of the axes below the last, last axis fixed
/// at c[Dim - 1] (x fastest).
template <int Dim, class Fn>
inline void for_slab(VecI<Dim> c, const VecI<Dim>& lo, const VecI<Dim>& hi, Fn&& fn) {
  for (int a = 0; a + 1 < Dim; ++a) c[a] = lo[a];
  while (true) {
    fn(c);
    int a = 0;
    while (a + 1 < Dim && c[a] == hi[a]) c[a] = lo[a], ++a;
    if (a + 1 >= Dim) return;
    ++c[a];
  }
}

/// LatticeSigns' table of the mixed cells' fractions, from its classes and box: a count per
/// row, the rows' starts, then the fractions, each row on one thread (fixed rows, each value
/// independent: the same table for any thread count).
template <int Dim>
void mixed_cell_fractions(const SampleLattice<Dim>& /*lattice*/, const LatticeValues<Dim>& phi,
                          LatticeSigns<Dim>& signs) {
  using Signs = LatticeSigns<Dim>;
  constexpr int kCorners = 1 << Dim;
  signs.phi_data = phi.data;
  signs.phi_size = phi.size;
  signs.mixed_x.clear();
  signs.mixed_fraction.clear();
  if (!signs.any_negative()) {
    signs.row_start.assign(1, 0);
    return;
  }
  const VecI<Dim> lo = signs.lo, hi = signs.hi;
  VecI<Dim> row_dims = hi - lo + VecI<Dim>::Ones();
  row_dims[0] = 1;
  const int rows = row_dims.prod();
  const VecI<Dim> pstride = phi.stride;
  // the classes are stored over the written box, which holds [lo, hi]
  const VecI<Dim> cstride = signs.box_strides(), wlo = signs.written_lo;
  // corner k of a lattice cell: point offset of its bits
  std::array<int, kCorners> corner_offset;
  for (int k = 0; k < kCorners; ++k) {
    corner_offset[k] = 0;
    for (int a = 0; a < Dim; ++a) corner_offset[k] += ((k >> a) & 1) * pstride[a];
  }
  signs.row_start.assign(rows + 1, 0);
  const int nx = hi[0] - lo[0] + 1;
  // (the counts, their running sums (one thread) and the fractions in one parallel region)
#pragma omp parallel num_threads(process_threads())
  {
#pragma omp for schedule(static)
    for (int q = 0; q < rows; ++q) {
      const VecI<Dim> c = lo + lattice_coord<Dim>(q, row_dims);
      const std::uint8_t* cls = signs.cls.data() + (c - wlo).dot(cstride);
      int count = 0;
      for (int x = 0; x < nx; ++x) count += cls[x] == Signs::kMixed;
      signs.row_start[q + 1] = count;
    }
#pragma omp single
    {
      for (int q = 0; q < rows; ++q) signs.row_start[q + 1] += signs.row_start[q];
      signs.mixed_x.resize(signs.row_start[rows]);
      signs.mixed_fraction.resize(signs.row_start[rows]);
    }
#pragma omp for schedule(static)
    for (int q = 0; q < rows; ++q) {
      const VecI<Dim> c = lo + lattice_coord<Dim>(q, row_dims);
      const std::uint8_t* cls = signs.cls.data() + (c - wlo).dot(cstride);
      const int point = c.dot(pstride);
      int slot = signs.row_start[q];
      for (int x = 0; x < nx; ++x) {
        if (cls[x] != Signs::kMixed) continue;
        std::array<double, kCorners> corners;
        for (int k = 0; k < kCorners; ++k) corners[k] = phi[point + x + corner_offset[k]];
        signs.mixed_x[slot] = lo[0] + x;
        signs.mixed_fraction[slot] = lattice_cell_negative_fraction<Dim>(corners);
        ++slot;
      }
    }
  }
}

}  // namespace

template <int Dim>
std::pair<VecI<Dim>, VecI<Dim>> negative_point_box(const SampleLattice<Dim>& lattice,
                                                   const VectorX& phi) {
  return negative_point_box_in<Dim>(lattice, phi, VecI<Dim>::Zero(),
                               (lattice.dims - VecI<Dim>::Ones()).eval());
}

template <int Dim>
std::pair<VecI<Dim>, VecI<Dim>> negative_point_box_in(const SampleLattice<Dim>& lattice,
                                                      const VectorX& phi, VecI<Dim> search_lo,
                                                      VecI<Dim> search_hi) {
  return negative_point_box_in<Dim>(lattice, whole_lattice_values(lattice, phi), search_lo,
                                    search_hi);
}

template <int Dim>
std::pair<VecI<Dim>, VecI<Dim>> negative_point_box_in(const SampleLattice<Dim>& lattice,
                                                      const LatticeValues<Dim>& phi,
                                                      VecI<Dim> search_lo, VecI<Dim> search_hi) {
  VecI<Dim> lo = lattice.dims, hi = -VecI<Dim>::Ones();
  for (int a = 0; a < Dim; ++a) {
    search_lo[a] = std::max(search_lo[a], 0);
    search_hi[a] = std::min(search_hi[a], lattice.dims[a] - 1);
    if (search_lo[a] > search_hi[a]) return {lo, hi};
  }
  // the rows along x of the search box, each from search_lo[0] to search_hi[0]
  const int x0 = search_lo[0], nx = search_hi[0] - search_lo[0] + 1;
  VecI<Dim> row_dims = search_hi - search_lo + VecI<Dim>::Ones();
  row_dims[0] = 1;
  const int rows = row_dims.prod();
#pragma omp parallel num_threads(process_threads())
  {
    VecI<Dim> tlo = lattice.dims, thi = -VecI<Dim>::Ones();
#pragma omp for schedule(static)
    for (int q = 0; q < rows; ++q) {
      VecI<Dim> a = search_lo + lattice_coord<Dim>(q, row_dims);
      const double* row = phi.data + (phi.index(a) - phi.shift);
      // a count first (no branch per point), the ends only in rows that hold a negative
      int negatives = 0;
      for (int x = 0; x < nx; ++x) negatives += row[x] < 0.0;
      if (negatives == 0) continue;
      int first = 0, last = nx - 1;
      while (!(row[first] < 0.0)) ++first;
      while (!(row[last] < 0.0)) --last;
      VecI<Dim> b = a;
      a[0] = x0 + first;
      b[0] = x0 + last;
      tlo = tlo.cwiseMin(a);
      thi = thi.cwiseMax(b);
    }
    // min / max: the same box for any thread count
#pragma omp critical(monolith_negative_point_box)
    {
      lo = lo.cwiseMin(tlo);
      hi = hi.cwiseMax(thi);
    }
  }
  return {lo, hi};
}

template <int Dim>
void classify_lattice_cells(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& phi, LatticeSigns<Dim>& signs) {
  const auto [lo, hi] = negative_point_box(lattice, phi);
  classify_lattice_cells_in_box(grid, lattice, phi, lo, hi, signs);
}

template <int Dim>
void classify_lattice_cells_searching(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                      const VectorX& phi, const VecI<Dim>& search_lo,
                                      const VecI<Dim>& search_hi, LatticeSigns<Dim>& signs) {
  classify_lattice_cells_searching<Dim>(grid, lattice, whole_lattice_values(lattice, phi), search_lo,
                                        search_hi, signs);
}

template <int Dim>
void classify_lattice_cells_searching(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                      const LatticeValues<Dim>& phi, const VecI<Dim>& search_lo,
                                      const VecI<Dim>& search_hi, LatticeSigns<Dim>& signs) {
  const auto [lo, hi] = negative_point_box_in<Dim>(lattice, phi, search_lo, search_hi);
  classify_lattice_cells_in_box<Dim>(grid, lattice, phi, lo, hi, signs);
}

template <int Dim>
void classify_lattice_cells_in_box(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                   const VectorX& phi, const VecI<Dim>& point_lo,
                                   const VecI<Dim>& point_hi, LatticeSigns<Dim>& signs) {
  classify_lattice_cells_in_box<Dim>(grid, lattice, whole_lattice_values(lattice, phi), point_lo,
                                     point_hi, signs);
}

template <int Dim>
void classify_lattice_cells_in_box(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                   const LatticeValues<Dim>& phi, const VecI<Dim>& point_lo,
                                   const VecI<Dim>& point_hi, LatticeSigns<Dim>& signs) {
  using Signs = LatticeSigns<Dim>;
  constexpr int kCorners = 1 << Dim;
  constexpr int kRows = 1 << (Dim - 1);  // point rows along x that hold a row of cells' corners
  const VecI<Dim> cells = 2 * grid.cells();
  signs.cells = cells;
  const VecI<Dim> pstride = phi.stride;
  // the lattice cells with a corner in the point box: cell l spans points l and l + 1
  VecI<Dim> from, to;
  for (int a = 0; a < Dim; ++a) {
    from[a] = std::max(point_lo[a] - 1, 0);
    to[a] = std::min(point_hi[a], signs.cells[a] - 1);
  }
  signs.written_lo = from;
  signs.written_hi = to;
  VecI<Dim> lo = signs.cells, hi = -VecI<Dim>::Ones();
  if ((from.array() > to.array()).any()) {
    signs.written_lo = VecI<Dim>::Zero();
    signs.written_hi = -VecI<Dim>::Ones();
    signs.cls.clear();
    signs.lo = lo;
    signs.hi = hi;
    mixed_cell_fractions(lattice, phi, signs);
    return;
  }
  // row r of a cell row: point offset of bit b of r along axis b + 1
  std::array<int, kRows> row{};
  for (int r = 0; r < kRows; ++r)
    for (int b = 0; b + 1 < Dim; ++b)
      if ((r >> b) & 1) row[r] += pstride[b + 1];
  const int x0 = from[0], nx = to[0] - from[0] + 1;
  // the box's classes (every one written below); the vector keeps its capacity across calls
  const std::size_t box_cells = static_cast<std::size_t>((to - from + VecI<Dim>::Ones()).prod());
  if (box_cells > signs.cls.capacity()) signs.cls = std::vector<std::uint8_t>();
  signs.cls.resize(box_cells);
  const VecI<Dim> cstride = signs.box_strides();
  // cell rows of the box: every cell coordinate but x, x = from[0]
  VecI<Dim> row_dims = to - from + VecI<Dim>::Ones();
  row_dims[0] = 1;
  const int rows = row_dims.prod();
#pragma omp parallel num_threads(process_threads())
  {
    VecI<Dim> tlo = signs.cells, thi = -VecI<Dim>::Ones();
    std::vector<int> column(nx + 1);
#pragma omp for schedule(static)
    for (int q = 0; q < rows; ++q) {
      const VecI<Dim> c0 = from + lattice_coord<Dim>(q, row_dims);
      const int base = c0.dot(pstride);
      // negative corners per point column (the 2^(Dim-1) rows at one x), then per cell the sum
      // of its two columns: the count of its 2^Dim corners where phi < 0
      for (int x = 0; x <= nx; ++x) {
        int negatives = 0;
        for (int r = 0; r < kRows; ++r) negatives += phi[base + row[r] + x] < 0.0;
        column[x] = negatives;
      }
      std::uint8_t* out = signs.cls.data() + (c0 - from).dot(cstride);
      int first = -1, last = -1;
      for (int x = 0; x < nx; ++x) {
        const int negatives = column[x] + column[x + 1];
        const std::uint8_t cl = negatives == 0          ? Signs::kPositive
                                : negatives == kCorners ? Signs::kNegative
                                                        : Signs::kMixed;
        out[x] = cl;
        if (cl != Signs::kPositive) {
          if (first < 0) first = x;
          last = x;
        }
      }
      if (first >= 0) {
        VecI<Dim> a = c0, b = c0;
        a[0] = x0 + first;
        b[0] = x0 + last;
        tlo = tlo.cwiseMin(a);
        thi = thi.cwiseMax(b);
      }
    }
    // min / max: the same box for any thread count
#pragma omp critical(monolith_lattice_signs)
    {
      lo = lo.cwiseMin(tlo);
      hi = hi.cwiseMax(thi);
    }
  }
  signs.lo = lo;
  signs.hi = hi;
  mixed_cell_fractions(lattice, phi, signs);
}

namespace {

/// One call of control_volume_negative_fractions, planned (serially: what to zero, which control
/// volumes to visit, the written box updated) and then run by the threads of an enclosing
/// parallel region: zero() and then, after a barrier, fill() (each an `omp for nowait`, each
/// entry written by one thread). Several planned calls over distinct outputs (the Dim face
/// lattices) share one region.
template <int Dim>
struct ControlVolumePass {
  using Signs = LatticeSigns<Dim>;
  static constexpr int kCorners = 1 << Dim;
  const MacGrid<Dim>* grid_ = nullptr;
  LatticeValues<Dim> phi_;
  const Signs* signs_ = nullptr;
  VecI<Dim> dims, lower_offset;
  double* out = nullptr;
  long total = 0;
  // zeros: rows of [zlo, zhi] (what the last call wrote), or every entry in blocks
  VecI<Dim> zlo = VecI<Dim>::Zero(), rows_box = VecI<Dim>::Ones();
  int zero_rows = 0, zero_nx = 0;
  long zero_blocks = 0;  // of kParallelMinWork entries, when every entry is zeroed
  // fractions: the control volumes [from, to], when any
  bool fractions = false, memo = false;
  VecI<Dim> from = VecI<Dim>::Zero(), to = -VecI<Dim>::Ones();
  VecI<Dim> pstride, ostride, cstride, wlo, wext;

  long zero_work() const { return zero_blocks > 0 ? total : static_cast<long>(zero_rows) * zero_nx; }

  void zero() const {
#pragma omp for schedule(static) nowait
    for (int r = 0; r < zero_rows; ++r) {
      const VecI<Dim> c = zlo + lattice_coord<Dim>(r, rows_box);
      std::fill_n(out + lattice_index<Dim>(c, dims), zero_nx, 0.0);
    }
#pragma omp for schedule(static) nowait
    for (long b = 0; b < zero_blocks; ++b)
      std::fill(out + b * kParallelMinWork, out + std::min(total, (b + 1) * kParallelMinWork), 0.0);
  }

  void fill() const {
    const int first_slab = fractions ? from[Dim - 1] : 0, last_slab = fractions ? to[Dim - 1] : -1;
    const MacGrid<Dim>& grid = *grid_;
    const LatticeValues<Dim>& phi = phi_;
    const Signs& signs = *signs_;
#pragma omp for schedule(static) nowait
    for (int t = first_slab; t <= last_slab; ++t) {
      VecI<Dim> start = from;
      start[Dim - 1] = t;
      for_slab<Dim>(start, from, to, [&](const VecI<Dim>& c) {
        // the mapped lattice cells of the cube along every axis (wrapped or mirrored)
        std::array<std::array<int, 2>, Dim> l;
        for (int a = 0; a < Dim; ++a)
          for (int s = 0; s < 2; ++s)
            l[a][s] = map_lattice_cell(2 * c[a] + lower_offset[a] + s, signs.cells[a],
                                       grid.periodic(a));
        std::array<std::uint8_t, kCorners> sub_class;
        int negative = 0, positive = 0;
        for (int sub = 0; sub < kCorners; ++sub) {
          int index = 0;
          bool inside = true;
          for (int a = 0; a < Dim; ++a) {
            const int offset = l[a][(sub >> a) & 1] - wlo[a];
            inside = inside && offset >= 0 && offset <= wext[a];
            index += offset * cstride[a];
          }
          const std::uint8_t cl = inside ? signs.cls[index] : Signs::kPositive;
          sub_class[sub] = cl;
          negative += cl == Signs::kNegative;
          positive += cl == Signs::kPositive;
        }
        if (positive == kCorners) return;
        double& w = out[c.dot(ostride)];
        if (negative == kCorners) {
          w = 1.0;
          return;
        }
        // as lattice_cube_negative_fraction: the sub-cubes' fractions in order, over 2^Dim
        double sum = 0.0;
        for (int sub = 0; sub < kCorners; ++sub) {
          const std::uint8_t cl = sub_class[sub];
          if (cl == Signs::kPositive) {
            sum += 0.0;
          } else if (cl == Signs::kNegative) {
            sum += 1.0;
          } else if (memo) {
            VecI<Dim> cell;
            for (int a = 0; a < Dim; ++a) cell[a] = l[a][(sub >> a) & 1];
            sum += signs.mixed_fraction_of(cell);
          } else {
            std::array<double, kCorners> corners;
            for (int k = 0; k < kCorners; ++k) {
              int index = 0;
              for (int a = 0; a < Dim; ++a)
                index += (l[a][(sub >> a) & 1] + ((k >> a) & 1)) * pstride[a];
              corners[k] = phi[index];
            }
            sum += lattice_cell_negative_fraction<Dim>(corners);
          }
        }
        w = sum / kCorners;
      });
    }
  }
};

template <int Dim>
ControlVolumePass<Dim> plan_control_volume(const MacGrid<Dim>& grid,
                                           const SampleLattice<Dim>& /*lattice*/,
                                           const LatticeValues<Dim>& phi,
                                           const LatticeSigns<Dim>& signs, const VecI<Dim>& dims,
                                           const VecI<Dim>& lower_offset, double* out,
                                           WrittenBox<Dim>* written) {
  ControlVolumePass<Dim> pass;
  pass.grid_ = &grid;
  pass.phi_ = phi;
  pass.signs_ = &signs;
  pass.dims = dims;
  pass.lower_offset = lower_offset;
  pass.out = out;
  pass.total = dims.prod();
  if (written && written->valid_for(out, pass.total)) {
    // zero only what the last call wrote (the rest is 0 already)
    pass.zlo = written->lo.cwiseMax(VecI<Dim>::Zero());
    const VecI<Dim> zhi = written->hi.cwiseMin(dims - VecI<Dim>::Ones());
    if ((pass.zlo.array() <= zhi.array()).all()) {
      pass.zero_nx = zhi[0] - pass.zlo[0] + 1;
      pass.rows_box = zhi - pass.zlo + VecI<Dim>::Ones();
      pass.rows_box[0] = 1;
      pass.zero_rows = pass.rows_box.prod();
    }
  } else {
    pass.zero_blocks = (pass.total + kParallelMinWork - 1) / kParallelMinWork;
  }
  if (written) {
    // nothing visited unless set below
    written->lo = VecI<Dim>::Zero();
    written->hi = -VecI<Dim>::Ones();
    written->data = out;
    written->size = pass.total;
    written->valid = true;
  }
  // the mixed lattice cells' fractions made with the classes (when made from this level set)
  pass.memo = signs.phi_data == phi.data && signs.phi_size == phi.size;
  // control volumes c whose lattice cells 2 c + off + {0, 1} (mirrored at walls: at most one
  // lattice cell inwards) can reach the box [lo, hi]; every c on a periodic axis
  pass.fractions = signs.any_negative();
  for (int a = 0; a < Dim && pass.fractions; ++a) {
    pass.from[a] = 0;
    pass.to[a] = dims[a] - 1;
    if (grid.periodic(a)) continue;
    pass.from[a] = std::max(pass.from[a], floor_half(signs.lo[a] - lower_offset[a] - 1));
    pass.to[a] = std::min(pass.to[a], floor_half(signs.hi[a] - lower_offset[a] + 1));
    if (pass.from[a] > pass.to[a]) pass.fractions = false;
  }
  if (!pass.fractions) {
    pass.from = VecI<Dim>::Zero();
    pass.to = -VecI<Dim>::Ones();
  }
  if (pass.fractions && written) {
    written->lo = pass.from;
    written->hi = pass.to;
  }
  pass.ostride[0] = 1;
  for (int a = 1; a < Dim; ++a) {
    pass.ostride[a] = pass.ostride[a - 1] * dims[a - 1];
  }
  pass.pstride = phi.stride;
  // the classes of the written box (kPositive outside it)
  pass.cstride = signs.box_strides();
  pass.wlo = signs.written_lo;
  pass.wext = signs.written_hi - signs.written_lo;
  return pass;
}

/// The planned passes in one parallel region: every pass's zeros, a barrier, every pass's
/// fractions (the passes' outputs are disjoint).
template <int Dim>
void run_control_volume_passes(const ControlVolumePass<Dim>* passes, int count) {
  bool any_fractions = false;
  long zero_work = 0;
  for (int k = 0; k < count; ++k) {
    any_fractions = any_fractions || passes[k].fractions;
    zero_work += passes[k].zero_work();
  }
  if (!any_fractions && zero_work == 0) return;
#pragma omp parallel num_threads(any_fractions ? process_threads() : team_threads(zero_work))
  {
    for (int k = 0; k < count; ++k) passes[k].zero();
#pragma omp barrier
    for (int k = 0; k < count; ++k) passes[k].fill();
  }
}

}  // namespace

template <int Dim>
void control_volume_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                       const LatticeValues<Dim>& phi, const LatticeSigns<Dim>& signs,
                                       const VecI<Dim>& dims, const VecI<Dim>& lower_offset,
                                       double* out, WrittenBox<Dim>* written) {
  // the zeros (what the last call wrote, or every entry) and the fractions in one parallel
  // region, a barrier between (they were two regions per call, ~20 calls per frame)
  const ControlVolumePass<Dim> pass =
      plan_control_volume(grid, lattice, phi, signs, dims, lower_offset, out, written);
  run_control_volume_passes(&pass, 1);
}

template <int Dim>
void control_volume_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                       const LatticeValues<Dim>& phi, const LatticeSigns<Dim>& signs,
                                       const std::vector<VecI<Dim>>& dims,
                                       const std::vector<VecI<Dim>>& lower_offsets,
                                       const std::vector<double*>& out) {
  std::vector<ControlVolumePass<Dim>> passes;
  for (std::size_t k = 0; k < dims.size(); ++k)
    passes.push_back(plan_control_volume<Dim>(grid, lattice, phi, signs, dims[k], lower_offsets[k],
                                              out[k], nullptr));
  run_control_volume_passes(passes.data(), static_cast<int>(passes.size()));
}

template <int Dim>
void cell_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const LatticeValues<Dim>& phi, const LatticeSigns<Dim>& signs, VectorX& out,
                             WrittenBox<Dim>* written) {
  if (out.size() != grid.num_cells()) out.resize(grid.num_cells());
  // the cell control volume is the 2^Dim lattice cells starting at lattice point 2c
  control_volume_negative_fractions<Dim>(grid, lattice, phi, signs, grid.cells(),
                                         VecI<Dim>::Zero(), out.data(), written);
}

template <int Dim>
void face_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const LatticeValues<Dim>& phi, const LatticeSigns<Dim>& signs, VectorX& out,
                             std::array<WrittenBox<Dim>, Dim>* written) {
  if (out.size() != grid.num_faces()) out.resize(grid.num_faces());
  // the face control volume starts half a cell before the face along its normal
  // (the Dim face lattices' passes in one parallel region)
  std::array<ControlVolumePass<Dim>, Dim> passes;
  for (int axis = 0; axis < Dim; ++axis) {
    VecI<Dim> offset = VecI<Dim>::Zero();
    offset[axis] = -1;
    passes[axis] = plan_control_volume<Dim>(grid, lattice, phi, signs, grid.face_dims(axis), offset,
                                            out.data() + grid.face_offset(axis),
                                            written ? &(*written)[axis] : nullptr);
  }
  run_control_volume_passes(passes.data(), Dim);
}

// the whole-lattice vector forms: views of it (whole_lattice_values)
template <int Dim>
void control_volume_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                       const VectorX& phi, const LatticeSigns<Dim>& signs,
                                       const VecI<Dim>& dims, const VecI<Dim>& lower_offset,
                                       double* out, WrittenBox<Dim>* written) {
  control_volume_negative_fractions<Dim>(grid, lattice, whole_lattice_values(lattice, phi), signs,
                                         dims, lower_offset, out, written);
}

template <int Dim>
void control_volume_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                       const VectorX& phi, const LatticeSigns<Dim>& signs,
                                       const std::vector<VecI<Dim>>& dims,
                                       const std::vector<VecI<Dim>>& lower_offsets,
                                       const std::vector<double*>& out) {
  control_volume_negative_fractions<Dim>(grid, lattice, whole_lattice_values(lattice, phi), signs,
                                         dims, lower_offsets, out);
}

template <int Dim>
void cell_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const VectorX& phi, const LatticeSigns<Dim>& signs, VectorX& out,
                             WrittenBox<Dim>* written) {
  cell_negative_fractions<Dim>(grid, lattice, whole_lattice_values(lattice, phi), signs, out,
                               written);
}

template <int Dim>
void face_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const VectorX& phi, const LatticeSigns<Dim>& signs, VectorX& out,
                             std::array<WrittenBox<Dim>, Dim>* written) {
  face_negative_fractions<Dim>(grid, lattice, whole_lattice_values(lattice, phi), signs, out,
                               written);
}

template <int Dim>
VectorX cell_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                const VectorX& phi) {
  LatticeSigns<Dim> signs;
  classify_lattice_cells(grid, lattice, phi, signs);
  VectorX w;
  cell_negative_fractions(grid, lattice, phi, signs, w);
  return w;
}

template <int Dim>
VectorX face_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                const VectorX& phi) {
  LatticeSigns<Dim> signs;
  classify_lattice_cells(grid, lattice, phi, signs);
  VectorX w;
  face_negative_fractions(grid, lattice, phi, signs, w);
  return w;
}

template <int Dim>
VectorX fluid_face_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                           const VectorX& solid_phi,
                           const std::array<BoundaryType, 2 * Dim>& boundary) {
  // fluid = not solid (kept by the simulation and written whole: on huge pages, huge21; made
  // resident in one call, kern25)
  VectorX w;
  resize_resident(w, grid.num_faces());
  w = VectorX::Ones(grid.num_faces()) - face_negative_fractions(grid, lattice, solid_phi);
  // wall faces carry no fluid; open faces keep the (mirrored) non-solid fraction
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (!grid.is_boundary_face(axis, coord)) continue;
    const int side = coord[axis] == 0 ? 0 : 1;
    if (boundary[2 * axis + side] == BoundaryType::wall) w[f] = 0.0;
  }
  return w;
}

template <int Dim>
VectorX fluid_face_weights_without_solids(const MacGrid<Dim>& grid,
                                          const std::array<BoundaryType, 2 * Dim>& boundary) {
  // (kept by the simulation and written whole: on huge pages, huge21; made resident in one
  // call, kern25)
  VectorX w;
  resize_resident(w, grid.num_faces());
  w.setOnes();
  // the wall faces: the two boundary planes of each axis's own faces (none on periodic axes)
  for (int axis = 0; axis < Dim; ++axis) {
    if (grid.periodic(axis)) continue;
    const VecI<Dim> dims = grid.face_dims(axis);
    for (int side = 0; side < 2; ++side) {
      if (boundary[2 * axis + side] != BoundaryType::wall) continue;
      // the faces with coord[axis] fixed: every combination of the other axes' coordinates
      VecI<Dim> lo = VecI<Dim>::Zero(), hi = dims - VecI<Dim>::Ones();
      lo[axis] = hi[axis] = side == 0 ? 0 : dims[axis] - 1;
      VecI<Dim> c = lo;
      while (true) {
        w[grid.face_index(axis, c)] = 0.0;
        int a = 0;
        while (a < Dim && c[a] == hi[a]) c[a] = lo[a], ++a;
        if (a == Dim) break;
        ++c[a];
      }
    }
  }
  return w;
}

VectorX solid_face_weights(const VectorX& fluid_face_weights) {
  return VectorX::Ones(fluid_face_weights.size()) - fluid_face_weights;
}

template <int Dim>
VectorX liquid_cell_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& liquid_phi) {
  return cell_negative_fractions(grid, lattice, liquid_phi);
}

template <int Dim>
VectorX liquid_face_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& liquid_phi, const VectorX& liquid_cell_weights) {
  return clamp_liquid_face_weights(grid, face_negative_fractions(grid, lattice, liquid_phi),
                                   liquid_cell_weights);
}

namespace {

/// The faces of cell c raised to at least kMinLiquidFaceFraction (a face's minus cell is
/// f - e_axis, its plus cell f; the periodic seam's face once)
template <int Dim>
void raise_faces_of_cell(const MacGrid<Dim>& grid, VectorX& w, const VecI<Dim>& c) {
  for (int axis = 0; axis < Dim; ++axis) {
    VecI<Dim> f = c;
    for (int s = 0; s < 2; ++s) {
      f[axis] = c[axis] + s;
      if (grid.periodic(axis) && f[axis] == grid.cells()[axis]) f[axis] = 0;  // the seam face
      double& v = w[grid.face_index(axis, f)];
      v = std::max(v, kMinLiquidFaceFraction);
    }
  }
}

}  // namespace

template <int Dim>
void clamp_liquid_face_weights_in_place(const MacGrid<Dim>& grid, VectorX& w,
                                        const VectorX& liquid_cell_weights) {
  // clamp from below beside every cell with a liquid fraction, so (W_L^u)^-1 exists there: the
  // faces of the cells with W_L^p > 0 (a face's minus cell is f - e_axis, its plus cell f)
  for (int i = 0; i < grid.num_cells(); ++i) {
    if (!(liquid_cell_weights[i] > 0.0)) continue;
    const VecI<Dim> c = grid.cell_coord(i);
    raise_faces_of_cell(grid, w, c);
  }
}

template <int Dim>
void clamp_liquid_face_weights_in_place(const MacGrid<Dim>& grid, VectorX& w,
                                        const VectorX& liquid_cell_weights,
                                        const WrittenBox<Dim>& cells,
                                        std::array<WrittenBox<Dim>, Dim>& faces) {
  const bool boxed = cells.valid_for(liquid_cell_weights.data(), liquid_cell_weights.size());
  bool faces_kept = true;
  for (int axis = 0; axis < Dim; ++axis)
    faces_kept = faces_kept && faces[axis].valid_for(w.data() + grid.face_offset(axis),
                                                     grid.face_dims(axis).prod());
  if (!boxed || !faces_kept) {
    clamp_liquid_face_weights_in_place(grid, w, liquid_cell_weights);
    for (auto& box : faces) box.valid = false;  // (the clamp's faces are not known)
    return;
  }
  if ((cells.lo.array() > cells.hi.array()).any()) return;  // no cell with liquid
  // the same raise over the cells of the box, outside which every cell fraction is 0, made face
  // by face: a face of the box's cells (c and c + e_axis along axis; the seam face 0 of a
  // periodic axis lies in the box, which spans that axis whole) is raised when its minus or its
  // plus cell lies in the box with a liquid fraction. The raise is a maximum, which raising once
  // or twice, in any order, gives alike; each face is written by one thread (rows of the faces'
  // boxes along axis 0 on several threads; the cells' loop, serial, was 0.4 ms per step on the
  // 64^3 viscous bunny)
  std::array<BoxRows<Dim>, Dim> face_rows;
  std::array<int, Dim + 1> row_start{};
  for (int axis = 0; axis < Dim; ++axis) {
    VecI<Dim> lo = cells.lo, hi = cells.hi;
    hi[axis] = std::min(cells.hi[axis] + 1, grid.face_dims(axis)[axis] - 1);
    // (a periodic axis: every face, should the box not span the axis whole; its seam face 0 is
    // the last cell's plus face)
    if (grid.periodic(axis)) {
      lo[axis] = 0;
      hi[axis] = grid.face_dims(axis)[axis] - 1;
    }
    face_rows[axis] = BoxRows<Dim>(grid.face_dims(axis), lo, hi);
    row_start[axis + 1] = row_start[axis] + face_rows[axis].rows();
  }
  const auto in_box = [&](const VecI<Dim>& c) {
    return (c.array() >= cells.lo.array()).all() && (c.array() <= cells.hi.array()).all();
  };
  const auto liquid = [&](const VecI<Dim>& c) {
    return in_box(c) && liquid_cell_weights[grid.cell_index(c)] > 0.0;
  };
  const int total_rows = row_start[Dim];
  const long row_length = cells.hi[0] - cells.lo[0] + 2;
#pragma omp parallel for schedule(static) num_threads(team_threads(total_rows * row_length))
  for (int r = 0; r < total_rows; ++r) {
    int axis = 0;
    while (r >= row_start[axis + 1]) ++axis;
    const BoxRows<Dim>& rows = face_rows[axis];
    const int row = r - row_start[axis];
    VecI<Dim> f = rows.start(row);
    const int first = grid.face_offset(axis) + rows.first(row);  // the row's first face
    const int n_axis = grid.cells()[axis];
    for (int x = 0; x < rows.nx; ++x) {
      f[0] = rows.lo[0] + x;
      // the face's cells: f - e_axis (wrapped across a periodic seam) and f
      VecI<Dim> minus = f;
      minus[axis] -= 1;
      if (grid.periodic(axis) && minus[axis] < 0) minus[axis] += n_axis;
      if (!liquid(minus) && !liquid(f)) continue;
      double& v = w[first + x];
      v = std::max(v, kMinLiquidFaceFraction);
    }
  }
  // the faces of the box's cells: c and c + e_axis along axis (the seam face 0 of a periodic
  // axis lies in the box, which spans that axis whole)
  for (int axis = 0; axis < Dim; ++axis) {
    VecI<Dim> lo = cells.lo, hi = cells.hi;
    hi[axis] = std::min(hi[axis] + 1, grid.face_dims(axis)[axis] - 1);
    faces[axis].cover(lo, hi);
  }
}

template <int Dim>
VectorX clamp_liquid_face_weights(const MacGrid<Dim>& grid, VectorX w,
                                  const VectorX& liquid_cell_weights) {
  clamp_liquid_face_weights_in_place(grid, w, liquid_cell_weights);
  return w;
}

template <int Dim>
void extend_liquid_into_solids(const MacGrid<Dim>& grid, const VectorX& liquid_phi,
                               const VectorX& solid_phi, double reach, VectorX& phi) {
  phi = liquid_phi;  // no allocation when phi already has the size
  if (solid_phi.size() != liquid_phi.size()) return;
  const double dx = grid.dx();
  // lattice points inside a solid with liquid within reach count as liquid
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int k = 0; k < static_cast<int>(phi.size()); ++k)
    phi[k] = liquid_extended_into_solid(liquid_phi[k], solid_phi[k], reach, dx);
}

template <int Dim>
VectorX extend_liquid_into_solids(const MacGrid<Dim>& grid, const VectorX& liquid_phi,
                                  const VectorX& solid_phi, double reach) {
  VectorX phi;
  extend_liquid_into_solids(grid, liquid_phi, solid_phi, reach, phi);
  return phi;
}

template <int Dim>
void extend_liquid_into_solids_in_box(const MacGrid<Dim>& grid, const VectorX& liquid_phi,
                                      const VectorX& solid_phi, double reach,
                                      const VecI<Dim>& solid_lo, const VecI<Dim>& solid_hi,
                                      VectorX& phi) {
  phi = liquid_phi;  // no allocation when phi already has the size
  if (solid_phi.size() != liquid_phi.size()) return;
  const double dx = grid.dx();
  // outside the box no point is inside a solid: the liquid's own value
  for_each_lattice_point_in_box<Dim>(half_lattice(grid), solid_lo, solid_hi, [&](int k) {
    phi[k] = liquid_extended_into_solid(liquid_phi[k], solid_phi[k], reach, dx);
  });
}

#define MONOLITH_INSTANTIATE(D)                                                                   \
  template double lattice_cell_negative_fraction<D>(const std::array<double, (1 << D)>&);         \
  template double lattice_cube_negative_fraction<D>(const MacGrid<D>&, const SampleLattice<D>&,   \
                                                    const VecI<D>&, const VectorX&);              \
  template VectorX solid_phi_on_lattice<D>(const MacGrid<D>&, const SampleLattice<D>&,            \
                                           const std::vector<ShapePtr<D>>&, double);              \
  template void solid_phi_on_lattice<D>(const MacGrid<D>&, const SampleLattice<D>&,               \
                                        const std::vector<ShapePtr<D>>&, double, VectorX&);       \
  template VectorX cell_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,         \
                                              const VectorX&);                                    \
  template VectorX face_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,         \
                                              const VectorX&);                                    \
  template VectorX fluid_face_weights<D>(const MacGrid<D>&, const SampleLattice<D>&,              \
                                         const VectorX&, const std::array<BoundaryType, 2 * D>&); \
  template VectorX fluid_face_weights_without_solids<D>(const MacGrid<D>&,                        \
                                                        const std::array<BoundaryType, 2 * D>&);  \
  template VectorX liquid_cell_weights<D>(const MacGrid<D>&, const SampleLattice<D>&,             \
                                          const VectorX&);                                        \
  template VectorX liquid_face_weights<D>(const MacGrid<D>&, const SampleLattice<D>&,             \
                                          const VectorX&, const VectorX&);                        \
  template VectorX clamp_liquid_face_weights<D>(const MacGrid<D>&, VectorX, const VectorX&);      \
  template VectorX extend_liquid_into_solids<D>(const MacGrid<D>&, const VectorX&,                \
                                                const VectorX&, double);                          \
  template void extend_liquid_into_solids<D>(const MacGrid<D>&, const VectorX&, const VectorX&,   \
                                             double, VectorX&);                                   \
  template void extend_liquid_into_solids_in_box<D>(const MacGrid<D>&, const VectorX&,            \
                                                    const VectorX&, double, const VecI<D>&,       \
                                                    const VecI<D>&, VectorX&);                    \
  template void classify_lattice_cells<D>(const MacGrid<D>&, const SampleLattice<D>&,             \
                                          const VectorX&, LatticeSigns<D>&);                      \
  template std::pair<VecI<D>, VecI<D>> negative_point_box<D>(const SampleLattice<D>&,             \
                                                             const VectorX&);                     \
  template std::pair<VecI<D>, VecI<D>> negative_point_box_in<D>(const SampleLattice<D>&,          \
                                                                const VectorX&, VecI<D>, VecI<D>); \
  template void classify_lattice_cells_searching<D>(const MacGrid<D>&, const SampleLattice<D>&,   \
                                                    const VectorX&, const VecI<D>&,               \
                                                    const VecI<D>&, LatticeSigns<D>&);            \
  template void classify_lattice_cells_in_box<D>(const MacGrid<D>&, const SampleLattice<D>&,      \
                                                 const VectorX&, const VecI<D>&, const VecI<D>&,  \
                                                 LatticeSigns<D>&);                               \
  template void control_volume_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,  \
                                                     const VectorX&, const LatticeSigns<D>&,      \
                                                     const VecI<D>&, const VecI<D>&, double*,     \
                                                     WrittenBox<D>*);                             \
  template void control_volume_negative_fractions<D>(                                            \
      const MacGrid<D>&, const SampleLattice<D>&, const VectorX&, const LatticeSigns<D>&,           \
      const std::vector<VecI<D>>&, const std::vector<VecI<D>>&, const std::vector<double*>&);      \
  template void cell_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,            \
                                           const VectorX&, const LatticeSigns<D>&, VectorX&,      \
                                           WrittenBox<D>*);                                       \
  template void face_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,            \
                                           const VectorX&, const LatticeSigns<D>&, VectorX&,      \
                                           std::array<WrittenBox<D>, D>*);                        \
  template std::pair<VecI<D>, VecI<D>> negative_point_box_in<D>(                                \
      const SampleLattice<D>&, const LatticeValues<D>&, VecI<D>, VecI<D>);                        \
  template void classify_lattice_cells_searching<D>(const MacGrid<D>&, const SampleLattice<D>&,   \
                                                    const LatticeValues<D>&, const VecI<D>&,      \
                                                    const VecI<D>&, LatticeSigns<D>&);            \
  template void classify_lattice_cells_in_box<D>(const MacGrid<D>&, const SampleLattice<D>&,      \
                                                 const LatticeValues<D>&, const VecI<D>&,         \
                                                 const VecI<D>&, LatticeSigns<D>&);               \
  template void control_volume_negative_fractions<D>(                                            \
      const MacGrid<D>&, const SampleLattice<D>&, const LatticeValues<D>&, const LatticeSigns<D>&, \
      const VecI<D>&, const VecI<D>&, double*, WrittenBox<D>*);                                  \
  template void control_volume_negative_fractions<D>(                                            \
      const MacGrid<D>&, const SampleLattice<D>&, const LatticeValues<D>&, const LatticeSigns<D>&, \
      const std::vector<VecI<D>>&, const std::vector<VecI<D>>&, const std::vector<double*>&);      \
  template void cell_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,            \
                                           const LatticeValues<D>&, const LatticeSigns<D>&,       \
                                           VectorX&, WrittenBox<D>*);                             \
  template void face_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,            \
                                           const LatticeValues<D>&, const LatticeSigns<D>&,       \
                                           VectorX&, std::array<WrittenBox<D>, D>*);              \
  template void clamp_liquid_face_weights_in_place<D>(const MacGrid<D>&, VectorX&,                \
                                                      const VectorX&);                            \
  template void clamp_liquid_face_weights_in_place<D>(const MacGrid<D>&, VectorX&,                \
                                                      const VectorX&, const WrittenBox<D>&,       \
                                                      std::array<WrittenBox<D>, D>&);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
