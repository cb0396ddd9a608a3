#include "reference/fluid/mac_hierarchy.hpp"

#include <algorithm>
#include <array>
#include <cstdint>
#include <stdexcept>

namespace monolith {

namespace {

/// Weights of a fine index i on a cell-centred axis of n fine and nc coarse cells: the coarse
/// cell i/2 with 3/4 and its neighbour on i's side with 1/4 (wrapped when periodic; at a
/// non-periodic end the whole weight on i/2). Returns the count.
int cell_centred_weights(int i, int nc, bool periodic, std::array<int, 2>& idx,
                         std::array<double, 2>& w, bool linear = true) {
  const int I = i / 2;
  if (!linear) {
    idx[0] = I;
    w[0] = 1.0;
    return 1;
  }
  int J = (i % 2 == 0) ? I - 1 : I + 1;
  if (J < 0 || J >= nc) {
    if (!periodic) {
      idx[0] = I;
      w[0] = 1.0;
      return 1;
    }
    J = (J + nc) % nc;
  }
  idx[0] = I;
  w[0] = 0.75;
  idx[1] = J;
  w[1] = 0.25;
  return 2;
}

/// Weights of a fine node-aligned index i (a face position along its normal) on nc coarse cells.
int node_weights(int i, int nc, bool periodic, std::array<int, 2>& idx, std::array<double, 2>& w) {
  if (i % 2 == 0) {
    idx[0] = i / 2;
    w[0] = 1.0;
    if (periodic) idx[0] %= nc;
    return 1;
  }
  idx[0] = i / 2;
  idx[1] = i / 2 + 1;
  if (periodic) idx[1] %= nc;
  w[0] = w[1] = 0.5;
  return 2;
}

/// The tensor product of per-axis weight lists: calls add(coarse coordinate, weight).
template <int Dim, class Add>
void tensor_product(const std::array<std::array<int, 2>, Dim>& idx,
                    const std::array<std::array<double, 2>, Dim>& w, const std::array<int, Dim>& count,
                    const Add& add) {
  int total = 1;
  for (int a = 0; a < Dim; ++a) total *= count[a];
  for (int m = 0; m < total; ++m) {
    int rest = m;
    VecI<Dim> c;
    double weight = 1.0;
    for (int a = 0; a < Dim; ++a) {
      const int k = rest % count[a];
      rest /= count[a];
      c[a] = idx[a][k];
      weight *= w[a][k];
    }
    add(c, weight);
  }
}

/// Patches are relaxed in blocks of kBlock^Dim cells; blocks are coloured by the parity of their
/// block coordinates (a third colour for the last block of a periodic axis with an odd number of
/// blocks), so blocks of one colour are at least kBlock cells apart: more than the reach of any
/// patch plus the couplings of the Galerkin operators (2 cells).
constexpr int kBlock = 4;

template <int Dim>
struct BlockLayout {
  VecI<Dim> blocks;
  std::array<bool, Dim> periodic;
  explicit BlockLayout(const MacGrid<Dim>& grid) {
    for (int a = 0; a < Dim; ++a) {
      blocks[a] = (grid.cells()[a] + kBlock - 1) / kBlock;
      periodic[a] = grid.periodic(a);
    }
  }
  /// The block of cell coordinate c (clamped into the grid).
  int block_of(VecI<Dim> c, const VecI<Dim>& cells) const {
    for (int a = 0; a < Dim; ++a) c[a] = std::min(std::max(c[a], 0), cells[a] - 1) / kBlock;
    return lattice_index<Dim>(c, blocks);
  }
  int colour_of(int block) const {
    const VecI<Dim> b = lattice_coord<Dim>(block, blocks);
    int colour = 0;
    for (int a = Dim - 1; a >= 0; --a) {
      int k = b[a] % 2;
      if (periodic[a] && blocks[a] % 2 == 1 && b[a] == blocks[a] - 1) k = 2;
      colour = colour * 3 + k;
    }
    return colour;
  }
};

/// Drops empty colour lists, keeping the order.
void compact_colours(std::vector<std::vector<int>>& colours) {
  colours.erase(std::remove_if(colours.begin(), colours.end(),
                               [](const std::vector<int>& c) { return c.empty(); }),
                colours.end());
}

/// The coarse faces (global index, weight) a fine face interpolates from.
template <int Dim, class Add>
void face_weights(const MacGrid<Dim>& fine, const MacGrid<Dim>& coarse, int f, const Add& add,
                  bool linear = true) {
  const auto [a, c] = fine.face_coord(f);
  std::array<std::array<int, 2>, Dim> idx;
  std::array<std::array<double, 2>, Dim> w;
  std::array<int, Dim> count;
  for (int b = 0; b < Dim; ++b)
    count[b] = b == a ? node_weights(c[b], coarse.cells()[b], coarse.periodic(b), idx[b], w[b])
                      : cell_centred_weights(c[b], coarse.cells()[b], coarse.periodic(b), idx[b], w[b], linear);
  const int axis = a;
  tensor_product<Dim>(idx, w, count, [&](const VecI<Dim>& cc, double weight) {
    add(coarse.face_index(axis, cc), weight);
  });
}

/// The coarse cells (global index, weight) a fine cell interpolates from.
template <int Dim, class Add>
void cell_weights(const MacGrid<Dim>& fine, const MacGrid<Dim>& coarse, int i, const Add& add) {
  const VecI<Dim> c = fine.cell_coord(i);
  std::array<std::array<int, 2>, Dim> idx;
  std::array<std::array<double, 2>, Dim> w;
  std::array<int, Dim> count;
  for (int b = 0; b < Dim; ++b)
    count[b] = cell_centred_weights(c[b], coarse.cells()[b], coarse.periodic(b), idx[b], w[b]);
  tensor_product<Dim>(idx, w, count, [&](const VecI<Dim>& cc, double weight) {
    add(coarse.cell_index(cc), weight);
  });
}

/// The prolongation restricted to the fine unknowns `fine` (rows, global indices) and the coarse
/// entries they use (columns, increasing global indices, returned). Costs in proportion to the
/// fine unknowns, not to the grid.
template <class Weights>
std::vector<int> active_prolongation(const std::vector<int>& fine, const Weights& weights, SparseMatrix& p) {
  std::vector<std::pair<int, double>> entries;
  std::vector<int> row_start{0};
  entries.reserve(fine.size() * 8);
  for (int f : fine) {
    weights(f, [&](int coarse, double w) { entries.emplace_back(coarse, w); });
    row_start.push_back(static_cast<int>(entries.size()));
  }
  // the coarse unknowns: the coarse indices reached, increasing (a mark per global index rather
  // than a sort of every entry)
  int top = -1;
  for (const auto& e : entries) top = std::max(top, e.first);
  std::vector<int> local(static_cast<std::size_t>(top + 1), -1);
  for (const auto& e : entries) local[e.first] = 0;
  std::vector<int> coarse;
  for (int g = 0; g <= top; ++g)
    if (local[g] == 0) {
      local[g] = static_cast<int>(coarse.size());
      coarse.push_back(g);
    }
  // P straight into compressed storage: each row's entries sorted by column, repeated columns
  // summed in the order given (what setFromTriplets did)
  const int rows = static_cast<int>(fine.size());
  p.resize(rows, static_cast<int>(coarse.size()));
  p.resizeNonZeros(static_cast<Eigen::Index>(entries.size()));
  int* outer = p.outerIndexPtr();
  int* inner = p.innerIndexPtr();
  double* value = p.valuePtr();
  std::vector<std::pair<int, double>> row;
  int pos = 0;
  outer[0] = 0;
  for (int r = 0; r < rows; ++r) {
    row.clear();
    for (int q = row_start[r]; q < row_start[r + 1]; ++q) row.emplace_back(local[entries[q].first], entries[q].second);
    std::stable_sort(row.begin(), row.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
    for (std::size_t q = 0; q < row.size(); ++q) {
      if (q > 0 && row[q].first == row[q - 1].first) {
        value[pos - 1] += row[q].second;
        continue;
      }
      inner[pos] = row[q].first;
      value[pos++] = row[q].second;
    }
    outer[r + 1] = pos;
  }
  p.resizeNonZeros(pos);
  return coarse;
}

/// Restricted to the fine unknowns, two coarse columns of the prolongation can be parallel (a thin
/// liquid region seen by one fine unknown), and P^T A P is then only semi-definite. Its diagonal
/// is scaled by 1 + 1e-8: definite, and the V-cycle still satisfies Q <= A^-1 (the coarse
/// correction only shrinks); a dependent combination z has P z = 0, so its large coarse values
/// never reach the fine level.
void stabilise_coarse(SparseMatrix& ac) {
  for (int i = 0; i < ac.outerSize(); ++i)
    for (SparseMatrix::InnerIterator it(ac, i); it; ++it)
      if (it.col() == i) it.valueRef() *= 1.0 + 1e-8;
}

/// Position of global index g in the increasing list `list`, -1 if absent.
int find_sorted(const std::vector<int>& list, int g) {
  const auto it = std::lower_bound(list.begin(), list.end(), g);
  return it != list.end() && *it == g ? static_cast<int>(it - list.begin()) : -1;
}

}  // namespace

template <int Dim>
MacGrid<Dim> coarsen_grid(const MacGrid<Dim>& grid) {
  VecI<Dim> cells;
  std::array<bool, Dim> periodic;
  for (int a = 0; a < Dim; ++a) {
    cells[a] = (grid.cells()[a] + 1) / 2;
    periodic[a] = grid.periodic(a);
  }
  return MacGrid<Dim>(grid.origin(), 2.0 * grid.dx(), cells, periodic);
}

template <int Dim>
bool can_coarsen(const MacGrid<Dim>& grid) {
  for (int a = 0; a < Dim; ++a) {
    if (grid.cells()[a] <= 2) return false;
    if (grid.periodic(a) && grid.cells()[a] % 2 != 0) return false;
  }
  return true;
}

template <int Dim>
SparseMatrix face_prolongation(const MacGrid<Dim>& fine, const MacGrid<Dim>& coarse) {
  std::vector<Triplet> t;
  t.reserve(static_cast<std::size_t>(fine.num_faces()) * (1u << Dim));
  for (int f = 0; f < fine.num_faces(); ++f)
    face_weights<Dim>(fine, coarse, f, [&](int g, double w) { t.emplace_back(f, g, w); });
  SparseMatrix p(fine.num_faces(), coarse.num_faces());
  p.setFromTriplets(t.begin(), t.end());
  p.makeCompressed();
  return p;
}

template <int Dim>
SparseMatrix cell_prolongation(const MacGrid<Dim>& fine, const MacGrid<Dim>& coarse) {
  std::vector<Triplet> t;
  t.reserve(static_cast<std::size_t>(fine.num_cells()) * (1u << Dim));
  for (int i = 0; i < fine.num_cells(); ++i)
    cell_weights<Dim>(fine, coarse, i, [&](int g, double w) { t.emplace_back(i, g, w); });
  SparseMatrix p(fine.num_cells(), coarse.num_cells());
  p.setFromTriplets(t.begin(), t.end());
  p.makeCompressed();
  return p;
}

namespace {

/// The smoother of a face level: per cell of `grid` next to an unknown face a patch of its
/// unknown faces (level numbering; `faces` = the unknowns' global face indices, increasing), and
/// the `extra` patches; grouped by blocks of cells (cells in lexicographic order, then the extra
/// patches of the block in the caller's order), blocks coloured by BlockLayout.
template <int Dim>
PatchSet face_level_patches(const MacGrid<Dim>& grid, const std::vector<int>& faces,
                            const ExtraPatches<Dim>* extra, bool cell_patches = true) {
  const BlockLayout<Dim> layout(grid);
  // the cells beside the unknown faces
  // within a block the patches go by the parity pattern of their cell (a multicolour order, a
  // better smoother than the lexicographic one), then by cell
  auto parity = [](const VecI<Dim>& c) {
    int p = 0;
    for (int a = Dim - 1; a >= 0; --a) p = 2 * p + (((c[a] % 2) + 2) % 2);
    return p;
  };
  struct Key {
    int block, sub, index;
    bool operator<(const Key& o) const {
      return block != o.block ? block < o.block : sub != o.sub ? sub < o.sub : index < o.index;
    }
    bool operator==(const Key& o) const { return block == o.block && sub == o.sub && index == o.index; }
  };
  // (each cell once: marked, then sorted; the same list as sorting the cells of every face)
  std::vector<char> beside(static_cast<std::size_t>(grid.num_cells()), 0);
  for (int f : faces) {
    const auto [a, c] = grid.face_coord(f);
    for (int cell : {grid.face_cell_minus(a, c), grid.face_cell_plus(a, c)})
      if (cell >= 0) beside[cell] = 1;
  }
  std::vector<Key> cells;
  for (int cell = 0; cell < grid.num_cells(); ++cell)
    if (beside[cell]) {
      const VecI<Dim> cc = grid.cell_coord(cell);
      cells.push_back({layout.block_of(cc, grid.cells()), parity(cc), cell});
    }
  std::sort(cells.begin(), cells.end());
  if (!cell_patches) cells.clear();
  std::vector<Key> extras;  // (block, kind and parity, patch number in extra)
  if (extra)
    for (std::size_t k = 0; k < extra->unknowns.size(); ++k)
      extras.push_back({layout.block_of(extra->position[k], grid.cells()),
                        extra->kind[k] * (1 << Dim) + parity(extra->position[k]), static_cast<int>(k)});
  std::sort(extras.begin(), extras.end());
  PatchSet ps;
  int block_colours = 1;
  for (int a = 0; a < Dim; ++a) block_colours *= 3;
  // first the cell patches, block by block, then (a second sweep) the extra patches
  std::vector<int> members;
  for (std::size_t ci = 0; ci < cells.size(); ++ci) {
    const VecI<Dim> c = grid.cell_coord(cells[ci].index);
    members.clear();
    for (int a = 0; a < Dim; ++a)
      for (int side = 0; side < 2; ++side) {
        VecI<Dim> f = c;
        f[a] += side;
        if (grid.periodic(a) && f[a] == grid.cells()[a]) f[a] = 0;
        const int u = find_sorted(faces, grid.face_index(a, f));
        if (u >= 0 && std::find(members.begin(), members.end(), u) == members.end()) members.push_back(u);
      }
    if (!members.empty()) {
      std::sort(members.begin(), members.end());
      ps.add(members);
    }
    if (ci + 1 == cells.size() || cells[ci + 1].block != cells[ci].block)
      ps.close_group(layout.colour_of(cells[ci].block));
  }
  for (std::size_t ei = 0; ei < extras.size(); ++ei) {
    ps.add(extra->unknowns[extras[ei].index]);
    if (ei + 1 == extras.size() || extras[ei + 1].block != extras[ei].block)
      ps.close_group(block_colours + layout.colour_of(extras[ei].block));
  }
  compact_colours(ps.colours);
  return ps;
}

/// Point patches of a cell level, grouped and coloured by blocks.
template <int Dim>
PatchSet cell_point_patches(const MacGrid<Dim>& grid, const std::vector<int>& cell_of_unknown) {
  const BlockLayout<Dim> layout(grid);
  std::vector<std::pair<int, int>> order;  // (block, unknown)
  order.reserve(cell_of_unknown.size());
  for (std::size_t u = 0; u < cell_of_unknown.size(); ++u)
    order.emplace_back(layout.block_of(grid.cell_coord(cell_of_unknown[u]), grid.cells()), static_cast<int>(u));
  std::sort(order.begin(), order.end());
  PatchSet ps;
  for (std::size_t q = 0; q < order.size(); ++q) {
    ps.add({order[q].second});
    if (q + 1 == order.size() || order[q + 1].first != order[q].first) ps.close_group(layout.colour_of(order[q].first));
  }
  compact_colours(ps.colours);
  return ps;
}

}  // namespace

template <int Dim>
Multigrid face_multigrid(const MacGrid<Dim>& grid, const std::vector<int>& face_of_unknown,
                         SparseMatrix a, const MacMultigridOptions& options,
                         const ExtraPatches<Dim>* extra) {
  if (static_cast<int>(face_of_unknown.size()) != a.rows())
    throw std::invalid_argument("face_multigrid: one face per unknown expected");
  std::vector<MultigridLevel> levels;
  levels.reserve(static_cast<std::size_t>(std::max(1, options.max_levels)));  // no reallocation (it would copy the levels)
  MacGrid<Dim> g = grid;
  std::vector<int> faces = face_of_unknown;
  levels.emplace_back();
  levels.back().a.swap(a);  // (Eigen 3.4's SparseMatrix has no move assignment: `= std::move` copies)
  while (static_cast<int>(faces.size()) > options.max_coarse &&
         static_cast<int>(levels.size()) < options.max_levels && can_coarsen(g)) {
    MultigridLevel& lv = levels.back();
    // the smoother: cell patches (and the caller's extra patches on the finest level)
    lv.patches = face_level_patches<Dim>(g, faces, levels.size() == 1 ? extra : nullptr,
                                         levels.size() > 1 || !extra || options.fine_cell_patches);
    // the next level
    const MacGrid<Dim> gc = coarsen_grid(g);
    std::vector<int> coarse = active_prolongation(
        faces, [&](int f, const auto& add) { face_weights<Dim>(g, gc, f, add, options.transverse_linear); },
        lv.prolongation);
    SparseMatrix ac = galerkin_product(lv.a, lv.prolongation, &lv.restriction);
    stabilise_coarse(ac);
    levels.emplace_back();
    levels.back().a.swap(ac);
    faces = std::move(coarse);
    g = gc;
  }
  return Multigrid(std::move(levels), options.smoothing, options.renumber, options.single_precision);
}

template <int Dim>
Multigrid cell_multigrid(const MacGrid<Dim>& grid, const std::vector<int>& cell_of_unknown,
                         SparseMatrix a, const MacMultigridOptions& options) {
  if (static_cast<int>(cell_of_unknown.size()) != a.rows())
    throw std::invalid_argument("cell_multigrid: one cell per unknown expected");
  std::vector<MultigridLevel> levels;
  levels.reserve(static_cast<std::size_t>(std::max(1, options.max_levels)));  // no reallocation (it would copy the levels)
  MacGrid<Dim> g = grid;
  std::vector<int> cells = cell_of_unknown;
  levels.emplace_back();
  levels.back().a.swap(a);  // (Eigen 3.4's SparseMatrix has no move assignment: `= std::move` copies)
  while (static_cast<int>(cells.size()) > options.max_coarse &&
         static_cast<int>(levels.size()) < options.max_levels && can_coarsen(g)) {
    MultigridLevel& lv = levels.back();
    lv.patches = cell_point_patches<Dim>(g, cells);
    const MacGrid<Dim> gc = coarsen_grid(g);
    std::vector<int> coarse = active_prolongation(
        cells, [&](int i, const auto& add) { cell_weights<Dim>(g, gc, i, add); }, lv.prolongation);
    SparseMatrix ac = galerkin_product(lv.a, lv.prolongation, &lv.restriction);
    stabilise_coarse(ac);
    levels.emplace_back();
    levels.back().a.swap(ac);
    cells = std::move(coarse);
    g = gc;
  }
  return Multigrid(std::move(levels), options.smoothing, options.renumber, options.single_precision);
}

#define MONOLITH_INSTANTIATE(D)                                                                  \
  template MacGrid<D> coarsen_grid<D>(const MacGrid<D>&);                                        \
  template bool can_coarsen<D>(const MacGrid<D>&);                                               \
  template SparseMatrix face_prolongation<D>(const MacGrid<D>&, const MacGrid<D>&);              \
  template SparseMatrix cell_prolongation<D>(const MacGrid<D>&, const MacGrid<D>&);              \
  template Multigrid face_multigrid<D>(const MacGrid<D>&, const std::vector<int>&, SparseMatrix, \
                                       const MacMultigridOptions&, const ExtraPatches<D>*);      \
  template Multigrid cell_multigrid<D>(const MacGrid<D>&, const std::vector<int>&, SparseMatrix, \
                                       const MacMultigridOptions&);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
