#pragma once
/// \file mac_hierarchy.hpp
/// Geometric multigrid hierarchies on the MAC grid for operators whose unknowns are a subset of
/// the faces (the velocity-space viscosity operator, reference/fluid/velocity_operator.hpp) or of
/// the cells (the pressure Poisson operator, A22 of eq. (24)): coarse grids of ceil(n/2) cells per
/// axis, the standard linear transfers of the staggered grid, Galerkin coarse operators and
/// cell-patch (Vanka) smoothers coloured so that each colour relaxes in parallel
/// (reference/solvers/multigrid.hpp). Only the unknowns the fine operator has and the coarse
/// unknowns they interpolate from exist on any level, so a liquid filling a small part of the box
/// costs in proportion to its own size.
///
/// Transfers (per axis, tensor products):
///  - faces of axis a along a (node-aligned): a fine face on a coarse face takes its value, a
///    fine face between two coarse faces their mean;
///  - faces along the other axes and cells (cell-centred): 3/4 from the coarse cell containing
///    the fine one and 1/4 from the coarse neighbour on its side; at a non-periodic domain end
///    the whole weight goes to the coarse cell (constant extrapolation);
///  - periodic axes wrap; coarsening stops before a periodic axis would become odd.
/// Restriction is the transpose.

#include <vector>

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/solvers/multigrid.hpp"

namespace monolith {

struct MacMultigridOptions {
  int smoothing = 1;       ///< patch sweeps before and after the coarse correction
  int max_coarse = 1500;   ///< stop coarsening once a level has at most this many unknowns
  int max_levels = 12;
  /// false: faces take their coarse value from the coarse cell containing them along the axes
  /// transverse to the face (piecewise constant), which keeps the Galerkin coarse stencils as
  /// compact as the fine ones; true: the linear (3/4, 1/4) rule above.
  bool transverse_linear = true;
  /// false: the finest level relaxes only the extra patches (when given), not the cells.
  bool fine_cell_patches = true;
  /// Multigrid's renumbering of the smoothed levels for locality (same results bit for bit).
  bool renumber = true;
  /// Multigrid's single-precision levels (the rounded operators Ã_l >= A_l; (P12), section 31
  /// of docs/preconditioners.md).
  bool single_precision = false;
};

/// The coarse grid of `grid`: ceil(cells / 2) cells of twice the width, same origin and periodic
/// axes.
template <int Dim>
MacGrid<Dim> coarsen_grid(const MacGrid<Dim>& grid);

/// True when `grid` can be coarsened (every axis has more than 2 cells, periodic axes even).
template <int Dim>
bool can_coarsen(const MacGrid<Dim>& grid);

/// Prolongation from all faces of `coarse` to all faces of `fine` (num_faces(fine) x
/// num_faces(coarse)).
template <int Dim>
SparseMatrix face_prolongation(const MacGrid<Dim>& fine, const MacGrid<Dim>& coarse);

/// Prolongation from all cells of `coarse` to all cells of `fine`.
template <int Dim>
SparseMatrix cell_prolongation(const MacGrid<Dim>& fine, const MacGrid<Dim>& coarse);

/// Extra patches for the finest level (e.g. the stress elements of the viscosity operator): the
/// fine unknowns of each patch, the cell coordinate it is sorted into (a patch should reach at
/// most one cell beyond it) and a kind (unused by the ordering; kept for reports). Patches are
/// relaxed in blocks of cells; patches_independent is checked by the tests.
template <int Dim>
struct ExtraPatches {
  std::vector<std::vector<int>> unknowns;
  std::vector<VecI<Dim>> position;
  std::vector<int> kind;
};

/// The hierarchy for an SPD operator `a` on the faces face_of_unknown[i] of `grid` (increasing
/// face indices). Every level's smoother relaxes the faces of each cell of that level's grid
/// together, cell by cell in blocks of 4^Dim cells (blocks coloured by parity, each colour in
/// parallel); `extra` adds patches on the finest level, relaxed after the cell patches of their
/// block.
template <int Dim>
Multigrid face_multigrid(const MacGrid<Dim>& grid, const std::vector<int>& face_of_unknown,
                         SparseMatrix a, const MacMultigridOptions& options,
                         const ExtraPatches<Dim>* extra = nullptr);

/// The hierarchy for an SPD operator `a` on the cells cell_of_unknown[i] of `grid` (increasing),
/// with point Gauss-Seidel smoothing in blocks of 4^Dim cells (coloured by parity).
template <int Dim>
Multigrid cell_multigrid(const MacGrid<Dim>& grid, const std::vector<int>& cell_of_unknown,
                         SparseMatrix a, const MacMultigridOptions& options);

}  // namespace monolith
