#pragma once
/// \file pressure_projection.hpp
/// The variational pressure solve: eq. (8) without stress (equivalently eq. (18) without bodies),
/// i.e. the A22 and b2 blocks of eq. (24), with both back ends of the operator:
///
///   A = dt W_L^p G^T W_F^u P^-1 (W_L^u)^-1 G W_L^p     (num_dofs x num_dofs, SPD or SPSD)
///   b = W_L^p G^T W_F^u u*                              (num_dofs)
///   u = u* - dt P^-1 (W_L^u)^-1 G W_L^p p               (on faces with W_F^u W_L^u > 0)
///
/// obtained by minimising E(p) = 1/2 ||u* - dt P^-1 (W_L^u)^-1 G W_L^p p||^2_{P W_F^u W_L^u}
/// over p. The pressure DOFs are the cells with W_L^p > 0 that touch at least one face with
/// W_F^u > 0; every other cell has p = 0. A is restricted to those DOFs (rows and columns).

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/core/parallel.hpp"
#include "reference/fluid/stokes_workspace.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/solvers/backend.hpp"
#include "reference/solvers/linear_operator.hpp"
#include "reference/solvers/pcg.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

/// The diagonal weight matrices and densities the pressure system is built from, each stored as
/// its diagonal (see volume_fractions.hpp).
struct PressureWeights {
  VectorX fluid_face;    ///< W_F^u, num_faces
  VectorX liquid_cell;   ///< W_L^p, num_cells
  VectorX liquid_face;   ///< W_L^u, num_faces (clamped, see kMinLiquidFaceFraction)
  VectorX face_density;  ///< diagonal of P, num_faces, positive wherever W_F^u W_L^u > 0
};

/// The diagonal of P: the faces' densities from particles_to_grid; where a face has none (zero),
/// the mean of the non-zero densities of the faces of its two cells, else `fallback_density`.
template <int Dim>
VectorX density_diagonal(const MacGrid<Dim>& grid, const VectorX& face_density,
                         double fallback_density);
/// The same in place: `rho` enters as the faces' densities and leaves as the diagonal of P (the
/// same values; no second face-sized vector).
template <int Dim>
void density_diagonal_in_place(const MacGrid<Dim>& grid, VectorX& rho, double fallback_density);
/// The same where every face with a density (rho > 0) lies in the box [lo[a], hi[a]] of axis
/// a's face lattice (inclusive; empty when some lo > hi): the faces next to them are searched
/// in the boxes only (issue 20: particles_to_grid's faces), with the same result.
/// With `fill` (sorted, disjoint face index ranges [first, second)) the fallback is written only
/// on the faces of `fill` without a density (issue 20, kern22): for a caller whose other faces
/// hold the fallback already (particles_to_grid's DensitySpans). Every face this function reads
/// (the boxes, the faces of the cells beside a face with a density and of the cells beside
/// those) must then lie in `fill` or hold its input value.
template <int Dim>
void density_diagonal_in_place(const MacGrid<Dim>& grid, VectorX& rho, double fallback_density,
                               const std::array<VecI<Dim>, Dim>& lo,
                               const std::array<VecI<Dim>, Dim>& hi,
                               const std::vector<std::pair<long, long>>* fill = nullptr);

/// Active pressure DOFs (Algorithm 1, line 7) and the null space of A.
struct PressureDofs {
  std::vector<int> cell_of_dof;  ///< cell index of each DOF, increasing
  std::vector<int> dof_of_cell;  ///< DOF of each cell, -1 for inactive cells
  /// One unit vector per connected group of DOFs that no weighted face links to air, an open
  /// boundary or an inactive cell (enclosed or periodic liquid): n_i proportional to 1 / W_L^p_i
  /// on the group (a constant q = W_L^p p), zero elsewhere. Empty when A is definite.
  std::vector<VectorX> null_space;
  int size() const { return static_cast<int>(cell_of_dof.size()); }
};

/// `band` (optional, stokes_workspace.hpp): the DOFs are searched among the cells of its cell box
/// only (a DOF needs W_L^p > 0, which the band promises to be 0 outside the box), in the same
/// increasing cell order: the same DOFs and null space.
template <int Dim>
PressureDofs select_pressure_dofs(const MacGrid<Dim>& grid, const PressureWeights& w, double dt,
                                  const LiquidBand* band = nullptr);

/// Explicit back end: every matrix of eq. (8) with its paper name, A and b formed as written.
struct ExplicitPressureSystem {
  SparseMatrix G;          ///< eq. (8) gradient, num_faces x num_cells
  SparseMatrix W_F_u;      ///< num_faces x num_faces, diagonal
  SparseMatrix W_L_p;      ///< num_cells x num_cells, diagonal
  SparseMatrix W_L_u_inv;  ///< (W_L^u)^-1, num_faces x num_faces, diagonal (0 where W_L^u = 0)
  SparseMatrix P_inv;      ///< P^-1, num_faces x num_faces, diagonal
  SparseMatrix S;          ///< selection, num_dofs x num_cells, S(k, cell_of_dof[k]) = 1
  SparseMatrix A;          ///< S (dt W_L^p G^T W_F^u P^-1 (W_L^u)^-1 G W_L^p) S^T, SPSD
  VectorX b;               ///< S W_L^p G^T W_F^u u*
};

/// eq. (8) / A22 and b2 of eq. (24), assembled explicitly.
template <int Dim>
ExplicitPressureSystem assemble_explicit_pressure(const MacGrid<Dim>& grid,
                                                  const PressureWeights& w,
                                                  const PressureDofs& dofs, double dt,
                                                  const VectorX& u_star);

/// Matrix-free back end: the same A (eq. (8), A22 of eq. (24)) applied by a stencil loop over
/// the cells (OpenMP over grid rows, one writer per output entry, deterministic):
///   (A x)_i = W_i sum_{faces f of cell i} k_f (W_i x_i - W_j x_j),  k_f = dt W_F^u / (rho W_L^u dx^2),
/// j the cell across f (W_j x_j = 0 outside the domain or on inactive cells). It stores k_f and
/// W_F^u per face, a cell -> DOF map, W_L^p and A_ii per DOF; the neighbours come from the grid
/// layout on the fly. SSOR sweeps use red-black ordering of the cells (by the parity of the sum of
/// cell coordinates), each colour in parallel (serially in grid order on an odd periodic axis).
/// Scratch is sized at construction: apply and the sweeps allocate nothing, and one operator must
/// not run two of them at once from different threads.
template <int Dim>
class MatrixFreePressureOperator : public LinearOperator {
 public:
  MatrixFreePressureOperator(const MacGrid<Dim>& grid, const PressureWeights& w,
                             const PressureDofs& dofs, double dt);
  int size() const override { return num_dofs_; }
  void apply(const VectorX& x, VectorX& y) const override;
  VectorX diagonal() const override { return diagonal_; }
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override;
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override;
  const std::vector<VectorX>& null_space() const override { return null_space_; }
  /// b = W_L^p G^T W_F^u u* restricted to the DOFs, by a stencil loop.
  VectorX rhs(const VectorX& u_star) const;
  /// The operator as an explicit matrix (row-major, the entries of its stencils: equal to
  /// ExplicitPressureSystem::A without the sparse products), for the multigrid hierarchy of
  /// MGPCG. `dofs` must be the DOFs the operator was built with.
  SparseMatrix matrix(const PressureDofs& dofs) const;

  /// Bytes the operator holds (coefficients, map, scratch), for the benchmark harness.
  std::size_t memory_bytes() const override;
  /// Bytes one apply must move at least: every stored array it reads once, x once, y once
  /// (scratch excluded), as SparseMatrixOperator counts; for the harness's bandwidth figure.
  double bytes_per_apply() const override;

 private:
  /// The 2 Dim faces of the cell at c (lower then upper per axis) and the cell across each (-1
  /// outside; the cell itself across a periodic axis of one cell).
  void cell_stencil(const VecI<Dim>& c, std::array<int, 2 * Dim>& face,
                    std::array<int, 2 * Dim>& other) const;
  /// q = W_L^p x on the cells (zero on inactive cells): an orphaned omp for (barrier at the end),
  /// called inside the parallel region of apply or sweep.
  void scatter(const VectorX& x) const;
  void sweep(bool reverse, const VectorX& rhs, VectorX& x, double omega,
             const std::vector<char>* active) const;
  VecI<Dim> cells_ = VecI<Dim>::Zero();
  std::array<bool, Dim> periodic_{};
  std::array<int, Dim> face_offset_{};
  std::array<VecI<Dim>, Dim> face_dims_{};
  double inv_dx_ = 1.0;
  int num_dofs_ = 0;
  std::vector<int> dof_of_cell_;  ///< per cell: DOF or -1
  VectorX liquid_;                ///< W_L^p per DOF
  VectorX coefficient_;           ///< k_f = dt W_F^u P^-1 (W_L^u)^-1 / dx^2 per face
  VectorX fluid_face_;            ///< W_F^u per face (for rhs)
  VectorX diagonal_;
  bool colouring_valid_ = true;  ///< false on odd periodic axes: colours then run serially
  std::vector<VectorX> null_space_;
  mutable VectorX q_;  ///< scratch: W_L^p x on the cells
};

/// u <- u - dt P^-1 (W_L^u)^-1 G W_L^p p on faces with W_F^u W_L^u > 0 (the update of eq. (4)
/// in the form of eq. (8)); `pressure` is a cell field (zero on inactive cells).
template <int Dim>
void apply_pressure_update(const MacGrid<Dim>& grid, const PressureWeights& w, double dt,
                           const VectorX& pressure, VectorX& u);

/// Cell field from DOF values (zero on inactive cells).
VectorX scatter_pressure(const PressureDofs& dofs, const VectorX& p_dofs, int num_cells);

struct PressureSolveResult {
  VectorX pressure;  ///< cell field, Pa
  PcgResult pcg;
  int dofs = 0;
};

/// Lines 7-11 of Algorithm 1 for the pressure alone: selects DOFs, builds the system with the
/// back end `backend` (assembled matrices or stencils), solves it with PCG and updates u
/// (which enters as u*). `preconditioner`: the paper's SSOR (default) or MGPCG, a V-cycle of the
/// cell multigrid of reference/fluid/mac_hierarchy.hpp on the assembled matrix (built on the
/// first iteration; docs/preconditioners.md section 8).
///
/// `divergence_source` (a cell field d, 1/s; nullptr: none) makes the solve's constraint
/// W_L^p G^T W_F^u u = -W_L^p d instead of 0, i.e. the weighted divergence of the new velocity
/// is d on the pressure DOFs: b_k += W_L^p d on each DOF's cell (add_divergence_source). Not a
/// paper equation: a project item (docs/derivations.md, "volume feedback"), the volume correction
/// of docs/particles.md "Volume correction through the solve".
///
/// A right-hand side at or below its round-off level (liquid_rhs_round_off, (P16): a liquid in
/// free fall) is zero: p = 0 with no iteration and no preconditioner set-up, and u* is kept bit
/// for bit (all_positive_zero); above the level the relative rule decides as before
/// (docs/preconditioners.md section 35).
template <int Dim>
PressureSolveResult solve_pressure(const MacGrid<Dim>& grid, const PressureWeights& w, double dt,
                                   Backend backend, const PcgSettings& settings,
                                   VectorX& u,
                                   PreconditionerKind preconditioner = PreconditionerKind::ssor,
                                   const VectorX* divergence_source = nullptr);

/// b_k += W_L^p_c d_c for each pressure DOF k of cell c (`cell_of_dof`, in DOF order; `offset`:
/// the first pressure row of b): the right-hand side of eq. (8) / b2 of eq. (24) with a target
/// divergence d (1/s) of the new velocity (solve_pressure's divergence_source). Nothing for a
/// null or empty d.
void add_divergence_source(const std::vector<int>& cell_of_dof, const VectorX& liquid_cell,
                           const VectorX* divergence_source, int offset, VectorX& b);

/// Every entry of x is +0 (the x = 0 of a right-hand side at its round-off, PcgSettings::zero_rhs).
/// The velocity updates (apply_pressure_update, apply_stokes_update) of such an x add +0 force to
/// every face and subtract dt (+0) / (rho W_L^u) = +0 from u, which leaves every u_f bit for bit
/// (also -0 and non-finite values): the solves skip them then (docs/preconditioners.md section 35).
/// A -0 entry does not count: -0 - (-0) is +0, so its update could flip the sign of a zero u_f.
inline bool all_positive_zero(const VectorX& x) {
  for (Eigen::Index i = 0; i < x.size(); ++i)
    if (x[i] != 0.0 || std::signbit(x[i])) return false;
  return true;
}

/// Multiples of eps in the round-off level N of a right-hand side (liquid_rhs_round_off below and
/// MonolithicSystem::rhs_round_off: one rule for the liquid-only and the coupled systems).
inline constexpr double kRhsRoundOffUlps = 16.0;

/// U = max_f |W_F^u_f u*_f| over the faces: the largest face velocity term of N (below). A
/// maximum over every face on several threads: std::max passes over a NaN term in any order and
/// every term is >= +0, so any split gives the serial loop's bits (issue 20: a serial read of two
/// face-sized vectors was 2.3 % of Fig. 2's samples at the paper's grid).
inline double weighted_face_speed(const VectorX& fluid_face, const VectorX& u_star) {
  double speed = 0.0;
  const long n = static_cast<long>(std::min(fluid_face.size(), u_star.size()));
#pragma omp parallel for schedule(static) reduction(max : speed) num_threads(team_threads(n))
  for (long f = 0; f < n; ++f) speed = std::max(speed, std::abs(fluid_face[f] * u_star[f]));
  return speed;
}

/// The same U where `band` promises u* = +-0 outside its speed boxes (LiquidBand::speed_valid):
/// the maximum over those boxes' faces only (issue 20, band18: a pass over every face per solve,
/// 2.2-2.6 % of Fig. 2's samples at the paper's grid). Outside the boxes every term is
/// |W_F^u (+-0)| = +0, which leaves a maximum that starts at +0 unchanged, and the maximum
/// takes its terms in any order (above): the bits of the pass over every face. Without a band
/// or its promise, and for vectors that are not the grid's, the pass over every face.
template <int Dim>
double weighted_face_speed(const MacGrid<Dim>& grid, const VectorX& fluid_face,
                           const VectorX& u_star, const LiquidBand* band) {
  if (band == nullptr || !band->speed_valid || fluid_face.size() != grid.num_faces() ||
      u_star.size() != grid.num_faces())
    return weighted_face_speed(fluid_face, u_star);
  // the boxes' rows along x (first face, length), every axis
  std::vector<std::pair<int, int>> rows;
  long work = 0;
  for (int a = 0; a < Dim; ++a) {
    const VecI<Dim> dims = grid.face_dims(a);
    VecI<Dim> lo, hi;
    for (int d = 0; d < Dim; ++d) {
      lo[d] = std::max(band->speed_lo[a][d], 0);
      hi[d] = std::min(band->speed_hi[a][d], dims[d] - 1);
    }
    if ((lo.array() > hi.array()).any()) continue;
    VecI<Dim> row_box = hi - lo + VecI<Dim>::Ones();
    const int nx = row_box[0];
    row_box[0] = 1;
    for (int r = 0; r < row_box.prod(); ++r)
      rows.emplace_back(grid.face_index(a, lo + lattice_coord<Dim>(r, row_box)), nx);
    work += static_cast<long>(row_box.prod()) * nx;
  }
  double speed = 0.0;
  const long count = static_cast<long>(rows.size());
#pragma omp parallel for schedule(static) reduction(max : speed) num_threads(team_threads(work))
  for (long r = 0; r < count; ++r)
    for (int f = rows[r].first; f < rows[r].first + rows[r].second; ++f)
      speed = std::max(speed, std::abs(fluid_face[f] * u_star[f]));
  return speed;
}

/// The round-off level N of a liquid-only right-hand side b = B^T W_F^u u* (+ W_L^p d): the
/// pressure rows W_L^p G^T W_F^u u* (eq. (8), solve_pressure) and the stress rows W_L^s M D
/// W_F^u u* (eq. (8), solve_stokes), each a sum of at most about 2 x 2 Dim terms of size at most
/// (2 Dim / dx) U with U = max_f |W_F^u_f u*_f|, so
///     N = 16 eps ((2 Dim / dx) U + max |d|)     (d: the target divergence, 1/s; nullptr: none),
/// the bound of MonolithicSystem::rhs_round_off without bodies (docs/derivations.md, "The
/// coupling schemes of section 6", item 4; docs/preconditioners.md sections 26 and 33). A liquid
/// in free fall (uniform u* plus gravity) has b = 0 in exact arithmetic; what remains is the
/// last bits of u* and of the sums (measured 0.64-1.06 (2 Dim / dx) U eps on
/// viscous-bunny-into-sphere-3d's falling steps, 2-4). Passed as PcgSettings::zero_rhs: such a b
/// gives x = 0 after no iteration. One formula from the inputs: the same on both back ends.
/// `band` (optional): U from its speed boxes (weighted_face_speed above; the same value).
template <int Dim>
double liquid_rhs_round_off(const MacGrid<Dim>& grid, const VectorX& fluid_face,
                            const VectorX& u_star, const VectorX* divergence_source,
                            const LiquidBand* band = nullptr);

}  // namespace monolith
