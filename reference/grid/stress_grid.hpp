#pragma once
/// \file stress_grid.hpp
/// The viscous stress DOFs of section 3.1.2 (the tau of eq. (8), Larionov et al. 2017) on a
/// MacGrid: where each component of the symmetric stress tensor lives and how it is numbered.
///
/// Placement (dx the cell width, c an integer lattice coordinate):
///  - diagonal component tau_aa lives at cell centres, origin + (c + 1/2) dx, c in [0, cells);
///  - off-diagonal component tau_ab (a < b) lives where the coordinates along a and b are
///    integer (node-aligned) and the others are half-integer (cell-centred):
///      2D: tau_xy at grid nodes;
///      3D: tau_xy at centres of z-aligned edges, tau_xz at y-aligned edges, tau_yz at x-aligned
///          edges.
///    Along a node-aligned axis there are cells + 1 positions, c in [0, cells]; on a periodic axis
///    the last layer c = cells is the first one (c = 0) and is not stored, so c in [0, cells).
///
/// 2D sketch of one cell (x to the right, y up), u/v the face velocities of MacGrid:
///
///     xy ------ v ------ xy
///      |                 |
///      |                 |
///      u     xx, yy      u
///      |                 |
///      |                 |
///     xy ------ v ------ xy
///
/// Components k are numbered diagonal first, then the off-diagonal pairs in lexicographic order:
///   2D: k = 0 xx, 1 yy, 2 xy;     3D: k = 0 xx, 1 yy, 2 zz, 3 xy, 4 xz, 5 yz.
/// All stress DOFs form one vector, component blocks in that order:
///   index = offset(k) + c[0] + dims(k)[0] (c[1] + dims(k)[1] c[2])   (x fastest),
/// the same convention as the cells and faces of MacGrid. Every DOF is also a point of the half
/// lattice of the grid (mac_grid.hpp, half_lattice), at lattice index 2 c + 2 shift(k).
///
/// One off-diagonal DOF stands for both tau_ab and tau_ba: the Frobenius norm of eq. (7) counts it
/// twice, which is what multiplicity(k) (1 diagonal, 2 off-diagonal) records.

#include <array>
#include <utility>

#include "reference/core/common.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

template <int Dim>
class StressGrid {
 public:
  /// Number of independent components of a symmetric Dim x Dim tensor (3 in 2D, 6 in 3D).
  static constexpr int kComponents = Dim * (Dim + 1) / 2;

  StressGrid() = default;
  explicit StressGrid(const MacGrid<Dim>& grid);

  const MacGrid<Dim>& grid() const { return grid_; }

  // --- components ------------------------------------------------------------------------------
  static constexpr int num_components() { return kComponents; }
  /// The tensor indices (a, b), a <= b, of component k.
  static std::pair<int, int> component_axes(int k);
  /// The component k holding tau_ab (symmetric: tau_ba gives the same k).
  static int component(int a, int b);
  static bool is_diagonal(int k) { return k < Dim; }
  /// 1 for diagonal components, 2 for off-diagonal ones (tau_ab and tau_ba share one DOF).
  static double multiplicity(int k) { return is_diagonal(k) ? 1.0 : 2.0; }
  /// Offset in cells of the DOFs of component k from the lattice points origin + c dx:
  /// 0 along node-aligned axes (a and b of an off-diagonal component), 1/2 along the others.
  static Vec<Dim> shift(int k);

  // --- numbering -------------------------------------------------------------------------------
  /// Number of DOFs of component k along each axis.
  const VecI<Dim>& dims(int k) const { return dims_[k]; }
  int num_dofs(int k) const { return offset_[k + 1] - offset_[k]; }
  /// Number of all stress DOFs (the length of the tau vector).
  int num_dofs() const { return offset_[kComponents]; }
  int offset(int k) const { return offset_[k]; }
  /// Global index of DOF c of component k (c must be in range, see wrap / index_or_outside).
  int index(int k, const VecI<Dim>& c) const;
  /// (component, coordinate) of a global index.
  std::pair<int, VecI<Dim>> coord(int index) const;
  bool in_range(int k, const VecI<Dim>& c) const;
  /// Wraps c into range along periodic axes; non-periodic axes are left as they are.
  VecI<Dim> wrap(int k, VecI<Dim> c) const;
  /// Index of DOF c of component k after periodic wrapping, or -1 if outside the domain.
  int index_or_outside(int k, const VecI<Dim>& c) const;
  /// Position origin + (c + shift(k)) dx.
  Vec<Dim> position(int k, const VecI<Dim>& c) const;
  /// True for an off-diagonal DOF on the boundary of a non-periodic axis (c[a] or c[b] equal to 0
  /// or cells): its stencil in D lacks the faces outside the domain. Never true for diagonal DOFs.
  bool is_boundary(int k, const VecI<Dim>& c) const;

 private:
  MacGrid<Dim> grid_;
  std::array<VecI<Dim>, kComponents> dims_{};
  std::array<int, kComponents + 1> offset_{};
};

// --- index arithmetic, inline: the viscosity set-up and the shear rates call these per DOF

template <int Dim>
inline int StressGrid<Dim>::index(int k, const VecI<Dim>& c) const {
  return offset_[k] + lattice_index<Dim>(c, dims_[k]);
}

template <int Dim>
inline std::pair<int, VecI<Dim>> StressGrid<Dim>::coord(int index) const {
  int k = 0;
  while (index >= offset_[k + 1]) ++k;
  return {k, lattice_coord<Dim>(index - offset_[k], dims_[k])};
}

template <int Dim>
inline bool StressGrid<Dim>::in_range(int k, const VecI<Dim>& c) const {
  for (int a = 0; a < Dim; ++a)
    if (c[a] < 0 || c[a] >= dims_[k][a]) return false;
  return true;
}

template <int Dim>
inline VecI<Dim> StressGrid<Dim>::wrap(int /*k*/, VecI<Dim> c) const {
  // on a periodic axis dims == cells for every component
  for (int a = 0; a < Dim; ++a)
    if (grid_.periodic(a)) c[a] = ((c[a] % grid_.cells()[a]) + grid_.cells()[a]) % grid_.cells()[a];
  return c;
}

template <int Dim>
inline int StressGrid<Dim>::index_or_outside(int k, const VecI<Dim>& c) const {
  const VecI<Dim> w = wrap(k, c);
  return in_range(k, w) ? index(k, w) : -1;
}

}  // namespace monolith
