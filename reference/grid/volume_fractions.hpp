#pragma once
/// \file volume_fractions.hpp
/// The volume-fraction weights of the variational discretisation (section 3.1.2) and the solid
/// level-set shrinkage of section 4.4.6.
///
/// Every level set is sampled on the half lattice of the grid (half_lattice(grid), spacing dx/2).
/// A cell control volume, and a face control volume (the cube of side dx centred on the face),
/// are each the union of 2^Dim lattice cells. The fraction of a lattice cell where phi < 0 is
/// computed exactly for the piecewise-linear interpolant on its Kuhn simplices (2 triangles in
/// 2D, 6 tetrahedra in 3D, all sharing the main diagonal), which makes the fractions second-order
/// accurate for smooth interfaces.
///
/// Outside the domain: on a periodic axis lattice points wrap; on a wall or open axis the half of
/// a boundary face's control volume that lies outside the domain mirrors the inside half.

#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/core/parallel.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/grid/boxed_lattice.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

/// Lower bound of W_L^u on faces adjacent to a cell with W_L^p > 0 (a deliberate departure from
/// the paper). The face control volume covers only the near halves of its two cells, so a face
/// beside a cell whose liquid sits entirely in the far half of that cell gets W_L^u = 0 although
/// the cell has a pressure DOF; eq. (8) needs (W_L^u)^-1 on every such face. Clamping keeps the
/// system well defined. In the limit W_L^u -> 0 the face's term of eq. (8) forces
/// (G W_L^p p)_f = 0 (that cell then acts as air beyond the ghost-fluid surface carried by its
/// other faces); a clamp c leaves a pressure error of about c dx |u*| rho / dt there. Measured on
/// the analytic projection test (tests/test_pressure.cpp): c = 0.01 stalls the pressure
/// convergence at 4e-4 (relative) on a 64^2 grid, c = 1e-4 keeps second order (1.96) with no
/// change in PCG iterations.
inline constexpr double kMinLiquidFaceFraction = 1e-4;

/// Exact fraction of a simplex (Dim + 1 vertex values of a linear function) where phi < 0.
template <int Dim>
double simplex_negative_fraction(const std::array<double, Dim + 1>& phi);
template <>
double simplex_negative_fraction<2>(const std::array<double, 3>& phi);
template <>
double simplex_negative_fraction<3>(const std::array<double, 4>& phi);

/// Fraction of a lattice cell (corner values, corner k has offset bit a of k along axis a) where
/// the Kuhn-simplex linear interpolant of phi is negative.
template <int Dim>
double lattice_cell_negative_fraction(const std::array<double, (1 << Dim)>& corner_phi);

/// The mean negative fraction of a cube's 2^Dim lattice cells (sub-cube s has corner values
/// corners[s], as lattice_cell_negative_fraction takes them), of whose corner values `negatives`
/// are below 0: 0 or 1 without the Kuhn split when every corner has one sign (the same value as
/// summing the sub-cubes' 0s or 1s). The last step of lattice_cube_negative_fraction and of the
/// coupling's reads of a per-body level set (reference/coupling/coupling.cpp).
template <int Dim>
double sub_cubes_negative_fraction(
    const std::array<std::array<double, (1 << Dim)>, (1 << Dim)>& corners, int negatives) {
  constexpr int kCorners = 1 << Dim;
  if (negatives == 0) return 0.0;
  if (negatives == kCorners * kCorners) return 1.0;
  double sum = 0.0;
  for (int sub = 0; sub < kCorners; ++sub) sum += lattice_cell_negative_fraction<Dim>(corners[sub]);
  return sum / kCorners;
}

/// The lattice cell standing for lattice cell l along one axis of `cells2` lattice cells (two per
/// grid cell): wrapped on a periodic axis, mirrored across the ends otherwise, so control volumes
/// that stick out of the domain see the mirror image (wall/open) or the other side (periodic).
int map_lattice_cell(int l, int cells2, bool periodic);

/// Fraction where phi < 0 (phi on the half lattice) of the cube of 2^Dim lattice cells with lower
/// corners lower + {0,1}^Dim, each lattice cell mapped by map_lattice_cell: the control volume
/// fraction shared by cells, faces and stress DOFs.
template <int Dim>
double lattice_cube_negative_fraction(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                      const VecI<Dim>& lower, const VectorX& phi);

/// Sign classes of the lattice cells of a level set on the half lattice (2 lattice cells per grid
/// cell along every axis, lattice cell l spanning lattice points l and l + 1): what the fraction
/// functions below need to visit only the band where the sign changes. A lattice cell whose
/// 2^Dim corners are all >= 0 (or NaN) has fraction 0, all < 0 fraction 1, and only the mixed
/// ones need the Kuhn split; a control volume of 2^Dim lattice cells all of class 0 (or all 1)
/// is 0 (1) without reading phi. Same values as lattice_cube_negative_fraction, bit for bit.
template <int Dim>
struct LatticeSigns {
  static constexpr std::uint8_t kPositive = 0, kNegative = 1, kMixed = 2;
  VecI<Dim> cells = VecI<Dim>::Zero();  ///< lattice cells per axis (2 x grid cells)
  /// Inclusive box of the lattice cells the last classification wrote (lo > hi: none); every
  /// class outside it is kPositive.
  VecI<Dim> written_lo = VecI<Dim>::Zero(), written_hi = -VecI<Dim>::Ones();
  /// The class of every lattice cell of the written box, x fastest, indexed by the offset from
  /// written_lo (box_strides): only the band the classification visited is stored (issue 20:
  /// a byte per lattice cell of the whole lattice was 64 MiB at the paper's 256x128x256 grid,
  /// first touched by the kernel, for a liquid in a small part of it). The vector is kept
  /// across calls (its capacity that of the largest box so far).
  std::vector<std::uint8_t> cls;
  /// Inclusive bounding box of the lattice cells of class != kPositive (lo > hi: none).
  VecI<Dim> lo = VecI<Dim>::Zero(), hi = -VecI<Dim>::Ones();
  bool any_negative() const { return (lo.array() <= hi.array()).all(); }
  /// Strides of cls along each axis (the written box's extents).
  VecI<Dim> box_strides() const {
    VecI<Dim> s;
    s[0] = 1;
    for (int a = 1; a < Dim; ++a) s[a] = s[a - 1] * (written_hi[a - 1] - written_lo[a - 1] + 1);
    return s;
  }
  /// The class of lattice cell l (0 <= l < cells): kPositive outside the written box.
  std::uint8_t class_of(const VecI<Dim>& l) const {
    if ((l.array() < written_lo.array()).any() || (l.array() > written_hi.array()).any())
      return kPositive;
    return cls[(l - written_lo).dot(box_strides())];
  }
  /// Every lattice cell's class, x fastest (tests: the whole lattice as one vector).
  std::vector<std::uint8_t> all_classes() const {
    std::vector<std::uint8_t> out(static_cast<std::size_t>(cells.prod()), kPositive);
    for (int l = 0; l < cells.prod(); ++l) out[l] = class_of(lattice_coord<Dim>(l, cells));
    return out;
  }
  /// The fraction of every kMixed lattice cell (lattice_cell_negative_fraction of its corners),
  /// made once with the classes: a mixed cell is shared by up to 2 + 3 Dim control volumes (a
  /// cell, Dim faces, the stress DOFs), which read it from here instead of splitting it again.
  /// Per row of lattice cells along x in the box [lo, hi] (rows numbered x-less, axis 1
  /// fastest), the mixed cells' x in ascending order and their fractions, entries
  /// [row_start[r], row_start[r + 1]). Made from the level set at `phi_data` (size phi_size);
  /// a fraction call with another level set computes them itself.
  std::vector<int> row_start, mixed_x;
  std::vector<double> mixed_fraction;
  const double* phi_data = nullptr;
  long phi_size = -1;
  /// The stored fraction of mixed lattice cell l (in the box, class kMixed).
  double mixed_fraction_of(const VecI<Dim>& l) const {
    int row = 0;
    for (int a = Dim - 1; a >= 1; --a) row = row * (hi[a] - lo[a] + 1) + (l[a] - lo[a]);
    const auto first = mixed_x.begin() + row_start[row], last = mixed_x.begin() + row_start[row + 1];
    return mixed_fraction[std::lower_bound(first, last, l[0]) - mixed_x.begin()];
  }
};

/// Inclusive box [lo, hi] of the lattice points where phi < 0 (lo > hi: none; NaN counts as not
/// negative). One read of phi, a comparison per point.
template <int Dim>
std::pair<VecI<Dim>, VecI<Dim>> negative_point_box(const SampleLattice<Dim>& lattice,
                                                   const VectorX& phi);

/// The same box when phi is nowhere < 0 outside the inclusive point box [search_lo, search_hi]
/// (clamped to the lattice): only that box is read (issue 20: the liquid's band instead of the
/// lattice). Same box as negative_point_box, provided the promise holds.
template <int Dim>
std::pair<VecI<Dim>, VecI<Dim>> negative_point_box_in(const SampleLattice<Dim>& lattice,
                                                      const VectorX& phi, VecI<Dim> search_lo,
                                                      VecI<Dim> search_hi);

/// Fills `signs` from phi on the half lattice of grid: negative_point_box, then
/// classify_lattice_cells_in_box (the class buffer is reused when it has the right size).
template <int Dim>
void classify_lattice_cells(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& phi, LatticeSigns<Dim>& signs);

/// The same classes when phi is nowhere < 0 outside the inclusive point box [search_lo,
/// search_hi]: negative_point_box_in there, then classify_lattice_cells_in_box with its box (the
/// same calls as classify_lattice_cells after the search).
template <int Dim>
void classify_lattice_cells_searching(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                      const VectorX& phi, const VecI<Dim>& search_lo,
                                      const VecI<Dim>& search_hi, LatticeSigns<Dim>& signs);

/// The same classes when the caller knows a box of lattice points [point_lo, point_hi]
/// (inclusive, clamped to the lattice) outside which phi is nowhere < 0: only the lattice cells
/// with a corner in it are classified (every other one is kPositive), and of the buffer only the
/// last call's written box and this one are touched. Same classes and box as a classification
/// of every lattice cell, provided the promise holds.
template <int Dim>
void classify_lattice_cells_in_box(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                   const VectorX& phi, const VecI<Dim>& point_lo,
                                   const VecI<Dim>& point_hi, LatticeSigns<Dim>& signs);

/// The box of control volumes [lo, hi] (inclusive; empty when some lo > hi) outside which a
/// fraction output kept across calls holds 0, for a sparse reset (issue 20): a call given a box
/// that is valid for the same storage (data, size) zeroes that box only instead of the whole
/// output, and records the box it writes. The caller keeps the output zero outside the box
/// between calls (it writes nothing there, or grows the box: clamp_liquid_face_weights_in_place).
template <int Dim>
struct WrittenBox {
  VecI<Dim> lo = VecI<Dim>::Zero(), hi = -VecI<Dim>::Ones();
  const double* data = nullptr;
  long size = 0;
  bool valid = false;
  bool valid_for(const double* out, long n) const { return valid && data == out && size == n; }
  /// Grows the box to cover [box_lo, box_hi] as well (an empty box becomes that box).
  void cover(const VecI<Dim>& box_lo, const VecI<Dim>& box_hi) {
    if ((lo.array() > hi.array()).any()) {
      lo = box_lo;
      hi = box_hi;
    } else {
      lo = lo.cwiseMin(box_lo);
      hi = hi.cwiseMax(box_hi);
    }
  }
  /// The box of storage [data, data + size) that holds 0 everywhere: valid, nothing written.
  static WrittenBox nothing_written(const double* data, long size) {
    WrittenBox box;
    box.data = data;
    box.size = size;
    box.valid = true;
    return box;
  }
};

/// The fraction where phi < 0 of the control volumes c in [0, dims) (x fastest) whose cube of
/// 2^Dim lattice cells has lower corner 2 c + lower_offset (lower_offset 0 on cell-centred axes,
/// -1 on node-aligned ones), i.e. lattice_cube_negative_fraction of each, written to
/// out[0 .. prod(dims)). Only the control volumes that reach the box of `signs` (plus one
/// lattice cell for the mirror at walls; whole periodic axes) are visited; the others are 0.
/// With `written` (see WrittenBox) only its box is zeroed first when it is valid for out, and it
/// returns with the box of the control volumes visited.
template <int Dim>
void control_volume_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                       const VectorX& phi, const LatticeSigns<Dim>& signs,
                                       const VecI<Dim>& dims, const VecI<Dim>& lower_offset,
                                       double* out, WrittenBox<Dim>* written = nullptr);

/// control_volume_negative_fractions of several control-volume lattices of one level set
/// (lattice k: dims[k], lower_offsets[k], out[k], outputs disjoint, no written boxes), in one
/// parallel region instead of one per lattice: the same values.
template <int Dim>
void control_volume_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                       const VectorX& phi, const LatticeSigns<Dim>& signs,
                                       const std::vector<VecI<Dim>>& dims,
                                       const std::vector<VecI<Dim>>& lower_offsets,
                                       const std::vector<double*>& out);

/// The forms above and below of a level set stored over a box (LatticeValues, boxed_lattice.hpp:
/// a BoxedLattice's view, or whole_lattice_values of a vector): the same arithmetic with the
/// view's strides. Every point they read must lie in the stored box: the search box of
/// negative_point_box_in; the corners of the lattice cells with a corner in the point box of
/// classify_lattice_cells_in_box (that box and one point around it); the corners of the mixed
/// cells for the fractions (which the classes' memo holds when made from the same view).
/// (The whole-lattice VectorX forms are these with whole_lattice_values.)
template <int Dim>
std::pair<VecI<Dim>, VecI<Dim>> negative_point_box_in(const SampleLattice<Dim>& lattice,
                                                      const LatticeValues<Dim>& phi,
                                                      VecI<Dim> search_lo, VecI<Dim> search_hi);
template <int Dim>
void classify_lattice_cells_searching(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                      const LatticeValues<Dim>& phi, const VecI<Dim>& search_lo,
                                      const VecI<Dim>& search_hi, LatticeSigns<Dim>& signs);
template <int Dim>
void classify_lattice_cells_in_box(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                   const LatticeValues<Dim>& phi, const VecI<Dim>& point_lo,
                                   const VecI<Dim>& point_hi, LatticeSigns<Dim>& signs);
template <int Dim>
void control_volume_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                       const LatticeValues<Dim>& phi,
                                       const LatticeSigns<Dim>& signs, const VecI<Dim>& dims,
                                       const VecI<Dim>& lower_offset, double* out,
                                       WrittenBox<Dim>* written = nullptr);
template <int Dim>
void control_volume_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                       const LatticeValues<Dim>& phi,
                                       const LatticeSigns<Dim>& signs,
                                       const std::vector<VecI<Dim>>& dims,
                                       const std::vector<VecI<Dim>>& lower_offsets,
                                       const std::vector<double*>& out);
template <int Dim>
void cell_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const LatticeValues<Dim>& phi, const LatticeSigns<Dim>& signs,
                             VectorX& out, WrittenBox<Dim>* written = nullptr);
template <int Dim>
void face_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const LatticeValues<Dim>& phi, const LatticeSigns<Dim>& signs,
                             VectorX& out, std::array<WrittenBox<Dim>, Dim>* written = nullptr);

/// Signed distance to the union of the solids, shifted inward by the shrinkage zeta of section
/// 4.4.6: returns min_k d_k(x) + shrink_in_metres at every lattice point (positive outside the
/// solids; +infinity everywhere when there is no solid).
template <int Dim>
VectorX solid_phi_on_lattice(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const std::vector<ShapePtr<Dim>>& solids, double shrink_in_metres);
/// The same into `out` (reused when it has the lattice's size).
template <int Dim>
void solid_phi_on_lattice(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                          const std::vector<ShapePtr<Dim>>& solids, double shrink_in_metres,
                          VectorX& out);

/// Fraction of every cell control volume where phi < 0 (phi on the half lattice). Size num_cells.
template <int Dim>
VectorX cell_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                const VectorX& phi);

/// Fraction of every face control volume where phi < 0. Size num_faces.
template <int Dim>
VectorX face_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                const VectorX& phi);

/// cell_negative_fractions / face_negative_fractions with phi's classes computed by the caller
/// (shared by several fraction sets of one level set) into `out` (resized when needed, so a
/// buffer kept across steps is not allocated again). With `written` (one box for the cells, one
/// per axis for the faces, in each axis's face lattice) a kept buffer is reset sparsely
/// (WrittenBox).
template <int Dim>
void cell_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const VectorX& phi, const LatticeSigns<Dim>& signs, VectorX& out,
                             WrittenBox<Dim>* written = nullptr);
template <int Dim>
void face_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                             const VectorX& phi, const LatticeSigns<Dim>& signs, VectorX& out,
                             std::array<WrittenBox<Dim>, Dim>* written = nullptr);

/// W_F^u (section 3.1.2): diagonal, num_faces x num_faces, stored as its diagonal. The fluid
/// (non-solid) fraction of each face control volume, in [0, 1]; 0 on `wall` boundary faces, the
/// non-solid fraction (1 without solids) on `open` ones. `solid_phi` is solid_phi_on_lattice.
template <int Dim>
VectorX fluid_face_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                           const VectorX& solid_phi,
                           const std::array<BoundaryType, 2 * Dim>& boundary);

/// fluid_face_weights without a solid (solid_phi +infinity everywhere: no face control volume
/// has a solid fraction): 1 on every face but the `wall` boundary faces, 0 there; the same bits
/// as fluid_face_weights of solid_phi_on_lattice over no shape, without the lattice-sized level
/// set (541 MB at the paper's 256x128x256 grid) or its pass over every face control volume.
/// Only the boundary planes are visited after the fill.
template <int Dim>
VectorX fluid_face_weights_without_solids(const MacGrid<Dim>& grid,
                                          const std::array<BoundaryType, 2 * Dim>& boundary);

/// W_S^u = 1 - W_F^u (diagonal, num_faces x num_faces, stored as its diagonal).
VectorX solid_face_weights(const VectorX& fluid_face_weights);

/// W_L^p (section 3.1.2): diagonal, num_cells x num_cells: liquid fraction of each cell.
template <int Dim>
VectorX liquid_cell_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& liquid_phi);

/// W_L^u (section 3.1.2): diagonal, num_faces x num_faces: liquid fraction of each face control
/// volume, clamped from below to kMinLiquidFaceFraction on every face with an adjacent cell of
/// W_L^p > 0 (see kMinLiquidFaceFraction for why).
template <int Dim>
VectorX liquid_face_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& liquid_phi, const VectorX& liquid_cell_weights);

/// The same W_L^u from the faces' raw liquid fractions (face_negative_fractions of the level set),
/// for a caller that keeps those too: the clamp alone, without sampling the fractions again.
template <int Dim>
VectorX clamp_liquid_face_weights(const MacGrid<Dim>& grid, VectorX raw_face_fractions,
                                  const VectorX& liquid_cell_weights);

/// clamp_liquid_face_weights in place: w holds the raw fractions on entry and W_L^u on return.
template <int Dim>
void clamp_liquid_face_weights_in_place(const MacGrid<Dim>& grid, VectorX& w,
                                        const VectorX& liquid_cell_weights);
/// The same where the cell fractions are 0 outside `cells` (valid for them: the box
/// cell_negative_fractions recorded): only the cells of that box are visited, and each face
/// box of `faces` (valid for w) grows to cover the faces of those cells (which the clamp may
/// raise), so that w stays 0 outside it.
template <int Dim>
void clamp_liquid_face_weights_in_place(const MacGrid<Dim>& grid, VectorX& w,
                                        const VectorX& liquid_cell_weights,
                                        const WrittenBox<Dim>& cells,
                                        std::array<WrittenBox<Dim>, Dim>& faces);

/// Reach of the liquid level set into static solids, in units of dx (see extend_liquid_into_solids).
inline constexpr double kLiquidSolidReach = 1.0;

/// The liquid level set extended into the static solids (a departure from the paper, which
/// leaves the extension to the implementation): at every lattice point inside a solid
/// (solid_phi < 0) with liquid closer than `reach` (liquid_phi < reach), phi <- min(phi, -dx/2);
/// elsewhere phi is unchanged. Both level sets are on the same lattice.
///
/// Why: particles stay outside the solids (kSolidMargin) and the particle level set ends a
/// fraction of a cell beyond them, so without the extension the thin fluid sliver of a
/// wall-cutting cell reads as air. Such a cell has W_L^p = 0 and, in eq. (8), pins p = 0
/// right against the liquid across a face that is mostly solid (small W_F^u): a spurious free
/// surface inside the wall, which the minimisation drains liquid into at many times the flow
/// speed (measured on pour-into-bowl-3d: faces with W_F^u = 0.02-0.07 at 10-23 m/s for an impact
/// speed of 3-4 m/s, then a solver breakdown). With the extension the liquid touching a solid
/// wets it and the wall is a wall (no flux through W_F^u = 0, only the fluid part open).
template <int Dim>
VectorX extend_liquid_into_solids(const MacGrid<Dim>& grid, const VectorX& liquid_phi,
                                  const VectorX& solid_phi, double reach);
/// The rule of extend_liquid_into_solids at one point, for callers that have the solid distance
/// pointwise instead of as a lattice (the density projection).
inline double liquid_extended_into_solid(double liquid_phi, double solid_phi, double reach,
                                         double dx) {
  return solid_phi < 0.0 && liquid_phi < reach ? std::min(liquid_phi, -0.5 * dx) : liquid_phi;
}
/// The same into `out` (reused across steps when it has the lattice's size).
template <int Dim>
void extend_liquid_into_solids(const MacGrid<Dim>& grid, const VectorX& liquid_phi,
                               const VectorX& solid_phi, double reach, VectorX& out);
/// The same when the caller knows a box of lattice points [solid_lo, solid_hi] (inclusive)
/// outside which solid_phi is nowhere < 0: out is liquid_phi there (a copy), the rule runs in
/// the box only. Same values.
template <int Dim>
void extend_liquid_into_solids_in_box(const MacGrid<Dim>& grid, const VectorX& liquid_phi,
                                      const VectorX& solid_phi, double reach,
                                      const VecI<Dim>& solid_lo, const VecI<Dim>& solid_hi,
                                      VectorX& out);

/// out[0 .. n) = value on several threads (fixed blocks): the zero or background fill of a
/// grid- or lattice-sized output, which on one thread is a serial pass over the whole vector.
inline void fill_in_parallel(double* out, long n, double value) {
  constexpr long kBlock = 1L << 15;
  const long blocks = (n + kBlock - 1) / kBlock;
#pragma omp parallel for schedule(static) num_threads(process_threads()) if (blocks > 1)
  for (long b = 0; b < blocks; ++b)
    std::fill(out + b * kBlock, out + std::min(n, (b + 1) * kBlock), value);
}

/// fn(k) for the index k of every point of the lattice box [lo, hi] (inclusive, clamped to the
/// lattice), rows along x on several threads (fn of distinct points must be independent).
template <int Dim, class Fn>
void for_each_lattice_point_in_box(const SampleLattice<Dim>& lattice, VecI<Dim> lo, VecI<Dim> hi,
                                   Fn&& fn) {
  for (int a = 0; a < Dim; ++a) {
    lo[a] = std::max(lo[a], 0);
    hi[a] = std::min(hi[a], lattice.dims[a] - 1);
    if (lo[a] > hi[a]) return;
  }
  VecI<Dim> row_dims = hi - lo + VecI<Dim>::Ones();
  row_dims[0] = 1;
  const int rows = row_dims.prod();
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int q = 0; q < rows; ++q) {
    const int start = lattice.index(lo + lattice_coord<Dim>(q, row_dims));
    for (int x = 0; x <= hi[0] - lo[0]; ++x) fn(start + x);
  }
}

}  // namespace monolith
