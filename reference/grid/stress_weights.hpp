#pragma once
/// \file stress_weights.hpp
/// The stress volume-fraction weights W_F^s and W_L^s of section 3.1.2 (the W^s = W_F^s W_L^s of
/// eq. (8)), one value per stress DOF of a StressGrid (all components, StressGrid numbering).
///
/// The control volume of a stress DOF is the cube of side dx centred on it: for a diagonal
/// component the cell itself, for an off-diagonal one the cube around its node (2D) or edge
/// centre (3D). Its corners are points of the half lattice (half_lattice(grid)), so it is the
/// union of 2^Dim lattice cells and its fractions are computed exactly like the face fractions of
/// volume_fractions.hpp (Kuhn-simplex fractions of the piecewise-linear level set). A diagonal
/// DOF's control volume is its cell, so its weights equal the cell fractions (W_L^s = W_L^p).
///
/// Outside the domain: periodic axes wrap; on wall and open axes the outside half of a boundary
/// control volume mirrors the inside half (as for faces). Then the boundary type decides:
///  - wall: the region beyond a wall is solid. An off-diagonal DOF on a wall keeps only the part
///    of its control volume inside the domain: the mirrored fraction times 1/2 per wall it lies
///    on (1/4 on a 2D corner). This is exactly what an embedded solid whose surface passes
///    through the DOF gives, and it makes the no-slip wall exact for linear shear: with
///    u = s y (u = 0 on the wall, first face at dx/2), D gives (D u)_xy = s/4 at the wall node
///    (one-sided difference against the zero exterior) and the optimum of eq. (8),
///    tau = 2 eta (D W_F^u u) / W_F^s, gives eta s there as in the interior, so the viscous force
///    on the first row of faces vanishes and Couette/Poiseuille profiles are no-slip at the wall.
///    (With the mirrored weight 1 the wall stress would be halved: a slip length of dx/2.)
///  - open: an off-diagonal DOF on an open boundary gets W_F^s = 0 (no shear stress unknown):
///    D there would compare against a zero exterior velocity, i.e. a no-slip exterior, which an
///    open boundary does not have; without the DOF the boundary is free of shear traction.
/// Diagonal DOFs (cell centres) never lie on the boundary.

#include <array>

#include "reference/core/common.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"

namespace monolith {

/// Lattice index (on the half lattice) of the lower corner of the control volume of stress DOF
/// `index`: 2 c + 2 shift(k) - 1 per axis (may be -1 on a node-aligned axis at the boundary).
template <int Dim>
VecI<Dim> stress_control_volume_lower(const StressGrid<Dim>& stress, int index);

/// Fraction of every stress control volume where phi < 0 (phi on the half lattice), with the
/// outside half of boundary control volumes mirrored (wall/open axes) or wrapped (periodic).
/// Size stress.num_dofs().
template <int Dim>
VectorX stress_negative_fractions(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                                  const VectorX& phi);

/// The same with phi's lattice-cell classes computed by the caller (classify_lattice_cells), into
/// `out` (resized when needed): only the stress control volumes in the band where phi changes
/// sign are visited.
template <int Dim>
void stress_negative_fractions(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                               const VectorX& phi, const LatticeSigns<Dim>& signs, VectorX& out);
/// The same of a level set stored over a box (LatticeValues: the points read are the corners
/// of the mixed lattice cells, volume_fractions.hpp).
template <int Dim>
void stress_negative_fractions(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                               const LatticeValues<Dim>& phi, const LatticeSigns<Dim>& signs,
                               VectorX& out);

/// W_F^s (section 3.1.2): diagonal, num_stress_dofs x num_stress_dofs, stored as its diagonal:
/// the fluid (non-solid) fraction of each stress control volume, in [0, 1], with the wall and
/// open rules of the file comment. `solid_phi` is solid_phi_on_lattice (positive outside solids).
template <int Dim>
VectorX stress_fluid_weights(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                             const VectorX& solid_phi,
                             const std::array<BoundaryType, 2 * Dim>& boundary);
/// The same from solid_phi's classes, into `out`.
template <int Dim>
void stress_fluid_weights(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                          const VectorX& solid_phi, const LatticeSigns<Dim>& signs,
                          const std::array<BoundaryType, 2 * Dim>& boundary, VectorX& out);

/// W_F^s of one stress DOF (component k, coordinate c) whose control volume has the solid
/// fraction `fraction`: 1 - fraction, then the wall and open rules of stress_fluid_weights in
/// its order (axis a's layers before axis b's, side 0 before side 1). The value
/// stress_fluid_weights gives that DOF when its fraction is this one (issue 20: the DOFs near
/// the moving bodies made again per step, reference/coupling/coupling.cpp).
template <int Dim>
double stress_fluid_weight(const StressGrid<Dim>& stress,
                           const std::array<BoundaryType, 2 * Dim>& boundary, int k,
                           const VecI<Dim>& c, double fraction) {
  double w = 1.0 - fraction;
  if (StressGrid<Dim>::is_diagonal(k)) return w;
  const MacGrid<Dim>& grid = stress.grid();
  const auto [a, b] = StressGrid<Dim>::component_axes(k);
  for (int axis : {a, b}) {
    if (grid.periodic(axis)) continue;
    for (int side = 0; side < 2; ++side) {
      const int layer = side == 0 ? 0 : grid.cells()[axis];
      if (layer >= stress.dims(k)[axis] || c[axis] != layer) continue;
      if (boundary[2 * axis + side] == BoundaryType::wall)
        w *= 0.5;
      else
        w = 0.0;
    }
  }
  return w;
}

/// W_L^s (section 3.1.2): diagonal, num_stress_dofs x num_stress_dofs, stored as its diagonal:
/// the liquid fraction of each stress control volume (mirrored/wrapped outside the domain, no
/// clamping: W_L^s only multiplies, it is never inverted in eq. (8)).
template <int Dim>
VectorX stress_liquid_weights(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                              const VectorX& liquid_phi);

}  // namespace monolith
