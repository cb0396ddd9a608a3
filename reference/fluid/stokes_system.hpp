#pragma once
/// \file stokes_system.hpp
/// The unified pressure-viscosity (Stokes) solve of sections 3.1.1-3.1.2: eq. (8) minimised over
/// the stress tau and the pressure p together, giving the SPD system of eq. (24) without bodies
///
///   [A11   A12] [tau]   [b1]
///   [A12^T A22] [ p ] = [b2],   with (docs/stokes.md derives every factor)
///
///   A11 = 1/2 N^-1 W^s + dt W_L^s M D W_F^u P^-1 (W_L^u)^-1 D^T M W_L^s     (reduced: E^T .. E)
///   A12 = dt W_L^s M D W_F^u P^-1 (W_L^u)^-1 G W_L^p                         (reduced: E^T ..)
///   A22 = dt W_L^p G^T W_F^u P^-1 (W_L^u)^-1 G W_L^p
///   b1  = W_L^s M D W_F^u u*,   b2 = W_L^p G^T W_F^u u*
///   u   = u* - dt P^-1 (W_L^u)^-1 (G W_L^p p + D^T M W_L^s tau_full)   (faces with W_F^u W_L^u > 0)
///
/// M = diag(StressGrid::multiplicity) (1 diagonal, 2 off-diagonal components) is the one factor
/// the paper leaves implicit: the off-diagonal DOF tau_xy stands for tau_xy and tau_yx, so it
/// enters ||tau||_F^2 twice (N^-1 = M / eta, viscosity.hpp) and the divergence of the symmetric
/// tensor twice (D^T M). With it the optimum is tau = 2 eta D u (eq. (5)) and the update adds
/// dt/rho div tau (eq. (4)). W^s = W_F^s W_L^s (stress_weights.hpp), E the expansion of
/// StressLayout (identity in the full form).

#include <array>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/fluid/stokes_workspace.hpp"
#include "reference/fluid/viscosity.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/solvers/backend.hpp"
#include "reference/solvers/linear_operator.hpp"
#include "reference/solvers/pcg.hpp"

namespace monolith {

/// Everything eq. (8) is built from, per DOF (diagonal matrices stored as their diagonals).
/// Inviscid weights may leave the three stress vectors empty: an empty `viscosity` is eta = 0 on
/// every StressGrid DOF (no stress unknowns), and `fluid_stress` and `liquid_stress` are then
/// read by nothing, so they may be empty too. Every function of this header accepts that (the
/// explicit back end and stokes_energy read zeros there), and so do MonolithicSystem and the
/// coupled schemes: at the paper's 256x128x256 grid the three are 1.2 GB of zeros.
struct StokesWeights {
  PressureWeights pressure;  ///< W_F^u, W_L^p, W_L^u, P (pressure_projection.hpp)
  VectorX fluid_stress;      ///< W_F^s per StressGrid DOF (all components; may be empty if inviscid)
  VectorX liquid_stress;     ///< W_L^s per StressGrid DOF (may be empty if inviscid)
  VectorX viscosity;         ///< eta per StressGrid DOF, Pa s (0 = inviscid there; empty: 0 everywhere)
  /// No stress unknowns whatever the other weights: eta is 0 everywhere (given as empty).
  bool inviscid() const { return viscosity.size() == 0; }
};

/// The weights of eq. (8) (section 3.1.2) from level sets on half_lattice(grid): solid where
/// solid_phi < 0, liquid where liquid_phi < 0, domain sides as `boundary` says, one density rho
/// (the diagonal of P) and one viscosity eta everywhere. W_L^u is clamped as liquid_face_weights
/// does. For teaching cases, tests and benchmarks; the simulator builds its own from particles.
template <int Dim>
StokesWeights uniform_stokes_weights(const MacGrid<Dim>& grid, const VectorX& solid_phi,
                                     const VectorX& liquid_phi,
                                     const std::array<BoundaryType, 2 * Dim>& boundary,
                                     double rho, double eta);

/// W_L^u raised to kMinLiquidFaceFraction on every face of D's stencil (eq. (8)) of a stress DOF
/// that can be active: W_F^s W_L^s > 0 and eta > 0 (select_stokes_dofs' test, per StressGrid
/// DOF). A stress DOF at the free surface reads dry faces above it (W_L^u = 0 and no cell with
/// W_L^p > 0 beside them, so clamp_liquid_face_weights leaves them at 0). With (W_L^u)^-1 taken
/// as 0 there, eq. (8) loses the face's kinetic term while b1 = W_L^s M D W_F^u u* still reads
/// its u*: the face becomes a prescribed velocity, a lid dragging the surface at the air's
/// extrapolated speed. With the clamp the face is an unknown of almost no mass, whose velocity
/// follows the stress: its net stress force D^T M W_L^s tau is driven to ~0 (of the order of the
/// clamp), eq. (8)'s zero traction at the free surface (docs/derivations.md, departures item 23).
/// Empty `viscosity` (inviscid weights) or stress weights: nothing is raised.
/// `signs` (optional): the classes W_L^s was made from; only the stress DOFs whose control
/// volumes reach its box of non-positive lattice cells are visited (W_L^s is 0 elsewhere).
/// `faces` (optional; each box valid for its axis of liquid_face, WrittenBox): grown to cover
/// every face that may be raised, so that liquid_face stays 0 outside them.
/// Deterministic for any thread count (a raise to one constant, in any order).
template <int Dim>
void clamp_stressed_face_weights(const StressGrid<Dim>& stress, const VectorX& fluid_stress,
                                 const VectorX& liquid_stress, const VectorX& viscosity,
                                 VectorX& liquid_face, const LatticeSigns<Dim>* signs = nullptr,
                                 std::array<WrittenBox<Dim>, Dim>* faces = nullptr);

/// Which unknowns a solve has: both (PV: eq. (8)) or stress only (the "VC" step of PC-VC-PC:
/// eq. (8) with p fixed at zero). Pressure only is solve_pressure (pressure_projection.hpp).
enum class StokesUnknowns { pressure_and_stress, stress_only };

/// Active unknowns (Algorithm 1, line 7): stress unknowns with W^s = W_F^s W_L^s > 0 and eta > 0
/// (reduced diagonal unknowns: also on the eliminated component of the cell), and the pressure
/// DOFs of select_pressure_dofs. The unknown vector is (tau, p), tau first (eq. (24)).
struct StokesDofs {
  PressureDofs pressure;                 ///< empty for stress_only
  std::vector<int> unknown_of_dof;       ///< active stress DOF k -> StressLayout unknown
  /// StressLayout unknown -> active stress DOF, -1 inactive; empty when there is no active
  /// stress DOF (num_stress() == 0: an int per layout unknown of -1 only, 170 MB at 256x128x256)
  std::vector<int> dof_of_unknown;
  std::vector<VectorX> null_space;       ///< of the whole (tau, p) system, orthonormal
  int num_stress() const { return static_cast<int>(unknown_of_dof.size()); }
  int num_pressure() const { return pressure.size(); }
  int size() const { return num_stress() + num_pressure(); }
};

/// `band` (optional; stokes_workspace.hpp): the pressure DOFs are searched in its cell box only
/// (select_pressure_dofs), with the same result when the band's promise holds.
template <int Dim>
StokesDofs select_stokes_dofs(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                              const StokesWeights& w, double dt, StokesUnknowns unknowns,
                              const LiquidBand* band = nullptr);

/// Explicit back end: every matrix of eq. (8)/(24) by its paper name; unknown vector (tau, p),
/// tau first (the order of eq. (24)). A = [A11 A12; A12^T A22] restricted to the active DOFs.
struct ExplicitStokesSystem {
  SparseMatrix G;          ///< eq. (8) gradient, num_faces x num_cells
  SparseMatrix D;          ///< eq. (8) deformation rate, num_stress_dofs x num_faces
  SparseMatrix M;          ///< multiplicity, num_stress_dofs square, diagonal (1 or 2)
  SparseMatrix N_inv;      ///< N^-1 in the layout, num_unknowns square (viscosity.hpp)
  SparseMatrix W_F_u;      ///< num_faces square, diagonal
  SparseMatrix W_L_u_inv;  ///< (W_L^u)^-1, num_faces square, diagonal (0 where W_L^u = 0)
  SparseMatrix P_inv;      ///< P^-1, num_faces square, diagonal
  SparseMatrix W_L_p;      ///< num_cells square, diagonal
  SparseMatrix W_F_s;      ///< num_stress_dofs square, diagonal
  SparseMatrix W_L_s;      ///< num_stress_dofs square, diagonal
  SparseMatrix E;          ///< expansion, num_stress_dofs x num_unknowns
  SparseMatrix S_tau;      ///< selection, num_stress_active x num_unknowns
  SparseMatrix S_p;        ///< selection, num_pressure_active x num_cells
  SparseMatrix A11;        ///< S_tau E^T (1/2 N_full^-1 W^s + dt W_L^s M D K D^T M W_L^s) E S_tau^T
  SparseMatrix A12;        ///< S_tau E^T dt W_L^s M D K G W_L^p S_p^T (empty for stress_only)
  SparseMatrix A22;        ///< S_p dt W_L^p G^T K G W_L^p S_p^T (empty for stress_only)
  SparseMatrix A;          ///< [A11 A12; A12^T A22], SPD (SPSD with enclosed liquid)
  VectorX b1, b2, b;       ///< b1 = S_tau E^T W_L^s M D W_F^u u*, b2 = S_p W_L^p G^T W_F^u u*
};

/// eq. (8) / the tau, p blocks of eq. (24), assembled explicitly (K = W_F^u P^-1 (W_L^u)^-1).
template <int Dim>
ExplicitStokesSystem assemble_explicit_stokes(const MacGrid<Dim>& grid,
                                              const StressLayout<Dim>& layout,
                                              const StokesWeights& w, const StokesDofs& dofs,
                                              double dt, const VectorX& u_star);

/// Matrix-free back end of the same A (eq. (24) without bodies), in the factored form
///   A = B^T C B + blockdiag(1/2 N^-1 W^s, 0),   B = [D^T M W_L^s E S_tau^T, G W_L^p S_p^T],
///   C = dt W_F^u P^-1 (W_L^u)^-1  (num_faces square, diagonal),
/// applied by stencils over the grid: neither A nor B is stored. The operator holds one C_f per
/// face, a grid -> unknown map (one int per StressGrid DOF and per cell), per unknown its weight
/// factor (M W_L^s or W_L^p), its 1/2 N^-1 W^s entry and A_ii, and (reduced form) per cell the
/// eliminated component's weight and N^-1 coupling. The +-1/dx of D (eq. (8), coupling.hpp's
/// deformation_rate_row) and G and the neighbour positions come from the grid layout on the fly.
/// apply = scatter x to the grid (s = M W_L^s E tau, q = W_L^p p), per face v = C (G q + D^T s),
/// then D v and G^T v per grid DOF, gathered into y; each loop runs OpenMP over grid rows or DOFs
/// with one writer per output entry, so results do not depend on the thread count. SSOR sweeps
/// (section 4.3) run over colour groups: per stress component (in StressLayout order) and then
/// pressure, red-black by the parity of the coordinate sum; they keep the face force B x up to
/// date as unknowns change, and unknowns of one group share no face, so each group is relaxed in
/// parallel (serially, in grid order, when an odd periodic axis breaks the colouring). Scratch
/// vectors are sized at construction: apply and the sweeps allocate nothing, and one operator
/// must not run two of them at once from different threads. The operator keeps a reference to
/// the weights it is built with (W_F^u, read by rhs): they must outlive it.
/// With a StokesWorkspace (stokes_workspace.hpp; issue 20, docs/preconditioners.md section 39)
/// the operator borrows its face-, cell- and stress-sized vectors from the workspace and gives
/// them back when destroyed (the workspace must outlive it), and with the workspace's band it
/// computes C_f on the band's face rows only (0 elsewhere): no grid-sized allocation or fill
/// after the first step, the same bits. The rows the loops visit come from the unknowns'
/// locations (a row is visited iff it holds an unknown), not from a scan of the grid.
/// Test switch (issue 20): MatrixFreeStokesOperator::rhs writes W_F^u u* on every face row and
/// updated_velocities_into computes B x on every face, as before the rows were restricted
/// (tests/unit/fluid/test_stokes.cpp compares both bit for bit). Off by default. An operator
/// made while it is on also visits whole rows instead of their spans (box26).
bool& stokes_operator_every_face_row();

template <int Dim>
class MatrixFreeStokesOperator : public LinearOperator {
 public:
  MatrixFreeStokesOperator(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                           const StokesWeights& w, const StokesDofs& dofs, double dt,
                           StokesWorkspace* workspace = nullptr);
  /// Gives the borrowed storage back to the workspace (if any), with the entries it wrote.
  ~MatrixFreeStokesOperator() override;
  MatrixFreeStokesOperator(const MatrixFreeStokesOperator&) = delete;
  MatrixFreeStokesOperator& operator=(const MatrixFreeStokesOperator&) = delete;
  int size() const override { return size_; }
  void apply(const VectorX& x, VectorX& y) const override;
  VectorX diagonal() const override { return diagonal_; }
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override;
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override;
  /// Consecutive sweeps: the second and later ones start from the face force B x the previous
  /// sweep kept up to date (one scatter and face pass less per sweep; the force differs from
  /// one recomputed from x by round-off, so the results differ from `count` single sweeps in
  /// the last bits).
  void forward_sweeps(const VectorX& rhs, VectorX& x, double omega, int count) const override;
  void backward_sweeps(const VectorX& rhs, VectorX& x, double omega, int count) const override;
  const std::vector<VectorX>& null_space() const override { return null_space_; }
  /// b = B^T W_F^u u* (= (b1, b2) of eq. (24)) by the same stencils. Reads W_F^u from the
  /// weights given to the constructor, which must still exist (every caller keeps them for the
  /// operator's life: MonolithicSystem shares them, solve_stokes holds them).
  VectorX rhs(const VectorX& u_star) const;
  /// The face coefficient C_f = dt W_F^u / (rho W_L^u) (0 where the face carries no fluid).
  const VectorX& face_coefficients() const { return face_coefficient_; }
  /// B x: the generalised force G W_L^p p + D^T M W_L^s tau_full of x = (tau, p) on every face
  /// (num_faces). The velocity update is u* - dt P^-1 (W_L^u)^-1 B x; the rigid-body terms of
  /// eq. (24) aggregate the same force (J_s = -Q W_S^u D^T M, J_p = -Q W_S^u G, section 4.4.1; reference/coupling/coupling.hpp).
  VectorX face_force(const VectorX& x) const;
  /// The same into force[0 .. num_faces) (the caller's storage; no grid-sized temporary).
  void face_force_into(const VectorX& x, double* force) const;
  /// u = u* - dt P^-1 (W_L^u)^-1 B x on the faces with W_F^u W_L^u > 0 and a density, u*
  /// elsewhere (MonolithicSystem::fluid_velocities_into; the weights given to the constructor):
  /// B x is computed only on the face rows holding such a face, and the other rows are copies
  /// of u*'s (issue 20: no stencil pass over every face). The bits of face_force_into followed
  /// by that update on every face.
  void updated_velocities_into(const VectorX& x, const VectorX& u_star, double dt,
                               VectorX& u) const;
  /// Column i of B: the faces unknown i acts on and the coefficients B_fi, as (face, B_fi) pairs.
  std::vector<std::pair<int, double>> stencil(int i) const;

  /// Bytes the operator holds (stored coefficients, maps and scratch), for the benchmark harness.
  std::size_t memory_bytes() const override;
  /// Bytes one apply must move at least: every stored array it reads once, x once, y once
  /// (scratch excluded), as SparseMatrixOperator counts; for the harness's bandwidth figure.
  double bytes_per_apply() const override;

 private:

  /// A lattice-numbered block of one of the operator's vectors: the faces of one axis, one
  /// StressGrid component or the cells (offset into its vector and size along each axis).
  struct Field {
    int offset = 0;
    VecI<Dim> dims = VecI<Dim>::Zero();
  };
  /// One stencil term: coef times the input field at c + delta e_axis.
  struct Term {
    int field = 0, axis = 0, delta = 0;
    double coef = 0.0;
  };
  static constexpr int kComponents = StressGrid<Dim>::kComponents;
  /// fields: 0..Dim-1 faces of axis a, Dim + k stress component k, Dim + kComponents cells.
  static constexpr int kCellField = Dim + kComponents;
  static constexpr int kFields = kCellField + 1;

  /// s = M W_L^s E tau on the StressGrid, q = W_L^p p on the cells (zero where inactive).
  void scatter(const VectorX& x, double* s, double* q) const;
  /// force = B x from the scattered s, q (times C_f when `scale_by_c`), on the face rows with
  /// fluid (all rows when `all_rows`).
  void faces_from_grid(const double* s, const double* q, double* force, bool scale_by_c,
                       bool all_rows) const;
  /// s = D v on every StressGrid DOF and q = G^T v on every cell.
  void grid_from_faces(const double* v, double* s, double* q) const;
  /// y = B^T-gathered values of s, q per unknown (plus 1/2 N^-1 W^s x when x is given).
  void gather(const double* s, const double* q, const VectorX* x, VectorX& y) const;
  /// Index of the entry of field `field` at c + delta e_axis after periodic wrapping, -1 outside.
  int index_or_outside(int field, VecI<Dim> c, int axis, int delta) const;
  /// The faces of the column of B of the grid DOF at c of field `field` (a stress component or
  /// the cells), with the D / G coefficient (weights not applied). Returns the count.
  int column_faces(int field, const VecI<Dim>& c, std::array<int, 2 * Dim>& face,
                   std::array<double, 2 * Dim>& coef) const;
  /// The two colour groups (red then black; black then red when `reverse`) of one field in an
  /// SSOR sweep, keeping the face force B x in the face scratch current.
  void sweep_block(int field, bool reverse, const VectorX& rhs, VectorX& x, double omega,
                   const std::vector<char>* active) const;
  /// One sweep; `force_current`: the face scratch holds B x of this x already (left there by
  /// the previous sweep with nothing in between), so it is not recomputed.
  void sweep(bool reverse, const VectorX& rhs, VectorX& x, double omega,
             const std::vector<char>* active, bool force_current = false) const;
  /// force = 0 on the faces of the active face rows (the rows a sweep can read or write).
  void zero_active_face_rows(double* force) const;

  std::array<bool, Dim> periodic_{};
  std::array<Field, kFields> fields_{};
  std::array<std::vector<Term>, kFields> terms_;  ///< per output field: the stencil of B or B^T
  /// per field, the rows (along axis 0) the loops visit: face rows with some C_f != 0, stress
  /// and cell rows with some unknown (the eliminated component: rows of cells with a diagonal
  /// unknown). The other rows of the scratch vectors stay zero, so a liquid filling a small part
  /// of the grid costs in proportion to its rows, not to the grid.
  std::array<std::vector<int>, kFields> active_rows_;
  /// per field, parallel to active_rows_: the span [first, last + 1) along axis 0 of the
  /// row's entries that can be non-zero (face rows: C_f != 0; stress and cell rows: an unknown;
  /// the eliminated component: a cell with a diagonal unknown). The passes visit the spans only
  /// (box26): outside them every pass wrote a zero (scatter, the sweeps, C_f's zero times a sum)
  /// or a value no pass reads (grid_from_faces away from unknowns), so a row as long as the box
  /// costs what its liquid holds. All of axis 0 on a periodic axis 0.
  std::array<std::vector<std::pair<int, int>>, kFields> active_spans_;
  /// per face axis, the rows with a face the velocity update changes (W_F^u W_L^u > 0 and a
  /// density): updated_velocities_into computes B x there only
  std::array<std::vector<int>, Dim> updated_rows_;
  /// per face axis, parallel to updated_rows_: the span [first, last + 1) of the row's updated
  /// faces (all of the row on a periodic axis 0; box26)
  std::array<std::vector<std::pair<int, int>>, Dim> updated_spans_;
  /// per face axis, the rows grid_from_faces reads (the stencils' input rows of the stress and
  /// cell rows it visits): rhs writes W_F^u u* there only
  std::array<std::vector<int>, Dim> read_face_rows_;
  /// Entries the loops visit: the sum over fields of active rows times the row length (the work
  /// an apply or sweep does, for the serial threshold and the adaptive team of parallel.hpp).
  long active_work_ = 0;
  std::vector<int> layout_field_;                 ///< per layout component: its field
  int eliminated_ = -1;                           ///< eliminated StressGrid component, -1 full
  int size_ = 0;
  int num_stress_ = 0;
  int num_faces_ = 0;
  int num_stress_dofs_ = 0;
  int num_cells_ = 0;
  bool has_pressure_ = false;
  VectorX face_coefficient_;
  /// W_F^u of the weights given to the constructor, read by rhs (not copied: a face-sized
  /// vector, 200 MB at 256x128x256)
  const VectorX* fluid_face_ = nullptr;
  /// the pressure weights given to the constructor (W_F^u, W_L^u, P), read by
  /// updated_velocities_into (not copied)
  const PressureWeights* pressure_weights_ = nullptr;
  std::vector<int> unknown_of_dof_;   ///< per StressGrid DOF: unknown or -1
  /// per cell: pressure unknown + 1, or 0 (band23: the kernel's zeros mean "none", so a fresh
  /// map's pages beyond the liquid's rows are never written)
  Eigen::VectorXi unknown_of_cell_;
  std::vector<int> location_;         ///< per unknown: StressGrid DOF or cell
  VectorX weight_;                    ///< per unknown: M W_L^s (stress) or W_L^p (pressure)
  VectorX self_;                      ///< per unknown: its 1/2 N^-1 W^s entry
  VectorX eliminated_weight_;         ///< reduced form, per cell: -W_L^s of the eliminated DOF
  VectorX eliminated_coupling_;       ///< 3D reduced, per cell: 1/2 N^-1 W^s of the eliminated DOF
  VectorX diagonal_;
  bool colouring_valid_ = true;
  std::vector<VectorX> null_space_;
  /// the workspace whose storage the operator holds (nullptr: its own storage), and the spans of
  /// face_coefficient_ it wrote (given back with it)
  StokesWorkspace* workspace_ = nullptr;
  std::vector<std::pair<long, long>> coefficient_spans_;
  // scratch, sized at construction
  mutable VectorX stress_scratch_, cell_scratch_, face_scratch_;
};

/// The unknowns of `dofs` in the order MatrixFreeStokesOperator's forward SOR sweep relaxes
/// them: per stress component in StressLayout order, then the pressure; within each, the entries
/// whose lattice coordinates sum to an even number (red) before the odd ones (black), each colour
/// in grid order. Its backward sweep is this list reversed (within a colour the rows share no
/// face, so their order there does not matter). The block preconditioner sweeps an explicit A in
/// this order, so that both back ends apply the same preconditioner (docs/preconditioners.md,
/// section 24).
template <int Dim>
std::vector<int> stokes_sweep_order(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                                    const StokesDofs& dofs);

/// D^T M W_L^s tau_full on every face (the stress part of the force of apply_stokes_update), by
/// the stencil of D, without assembling it: bit for bit Eigen's product with
/// deformation_rate_matrix(stress).
template <int Dim>
VectorX deformation_rate_transpose_product(const StressGrid<Dim>& stress, const VectorX& liquid_stress,
                                           const VectorX& tau_full);

/// u <- u* - dt P^-1 (W_L^u)^-1 (G W_L^p p + D^T M W_L^s tau_full) on faces with
/// W_F^u W_L^u > 0 (eq. (4) in the form of eq. (8)); M = diag(multiplicity) because one
/// off-diagonal DOF is both tau_ab and tau_ba in div tau. `pressure_cells` is a cell field (zero
/// where inactive, may be empty = no pressure), `tau_full` all StressGrid components.
template <int Dim>
void apply_stokes_update(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                         const StokesWeights& w, double dt, const VectorX& pressure_cells,
                         const VectorX& tau_full, VectorX& u);

/// The stress part of a solution vector x = (tau, p) as all StressGrid components (E S_tau^T).
template <int Dim>
VectorX scatter_stress(const StressLayout<Dim>& layout, const StokesDofs& dofs, const VectorX& x);

/// The pressure part of x = (tau, p) as a cell field (zero on inactive cells).
VectorX scatter_stokes_pressure(const StokesDofs& dofs, const VectorX& x, int num_cells);

/// E_f of eq. (8) at (tau, p) = x with the common factor dx^Dim of the control volumes dropped:
/// 1/2 ||u(x)||^2_{P W_F^u W_L^u} + dt/4 tau^T N^-1 W^s tau, u(x) the update of u*. A quadratic:
/// E_f(x) = E_f(0) + dt (1/2 x^T A x - b~^T x), b~ the b of eq. (24) with u* read only on faces with
/// W_L^u > 0; b~ = b unless a dry face lies in the stencil of a wet stress DOF (docs/stokes.md).
template <int Dim>
double stokes_energy(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                     const StokesWeights& w, const StokesDofs& dofs, double dt,
                     const VectorX& u_star, const VectorX& x);

struct StokesSolveResult {
  VectorX pressure;  ///< cell field, Pa
  VectorX stress;    ///< tau, all components, StressGrid numbering, Pa
  PcgResult pcg;  ///< with a fallback: the SSOR solve's result, iterations of both attempts summed
  int pressure_dofs = 0, stress_dofs = 0;
  /// The multigrid attempt stopped unconverged at multigrid_attempt_budget and the solve was
  /// done again with SSOR (StokesSolveOptions::fallback_to_ssor).
  bool fell_back = false;
};

struct StokesPreconditionerOptions;  // reference/fluid/stokes_preconditioner.hpp

/// How solve_stokes preconditions and starts its PCG (the defaults: the paper's SSOR from zero).
struct StokesSolveOptions {
  /// `solver.preconditioner`: the paper's SSOR (section 4.3) or the block multigrid
  /// preconditioner of reference/fluid/stokes_preconditioner.hpp (docs/preconditioners.md).
  PreconditionerKind preconditioner = PreconditionerKind::ssor;
  /// The multigrid preconditioner's parameters (nullptr: StokesPreconditionerOptions{}).
  const StokesPreconditionerOptions* multigrid = nullptr;
  /// Storage kept across steps and the liquid's band (stokes_workspace.hpp; nullptr: the
  /// operator's own vectors, passes over the whole grid). The same results either way.
  StokesWorkspace* workspace = nullptr;
  /// Warm start: the initial (tau, p) read from these fields where the unknowns exist (a full
  /// StressGrid stress field, a cell pressure field; nullptr or a field of another size: zero).
  /// The solve still stops at settings.tolerance; only the starting residual changes.
  const VectorX* initial_stress = nullptr;
  const VectorX* initial_pressure = nullptr;
  /// With the multigrid preconditioner: give it multigrid_attempt_budget(max_iterations)
  /// iterations and, if it has not converged by then, solve again with the paper's SSOR from
  /// its last iterate (solver.preconditioner "auto"; an explicit "multigrid" keeps its result).
  bool fallback_to_ssor = false;
  /// A target divergence d of the new velocity (cell field, 1/s; nullptr: none): b2_k +=
  /// W_L^p d on each pressure DOF's cell (add_divergence_source, pressure_projection.hpp).
  const VectorX* divergence_source = nullptr;
};

/// Lines 7-11 of Algorithm 1 for the Stokes problem: select DOFs, build (assembled matrices or
/// stencils, by `backend`), PCG with the preconditioner of `options` (SSOR by default) from the
/// initial guess of `options` (zero by default), update u (which enters as u*). Defined in
/// stokes_solve.cpp.
template <int Dim>
StokesSolveResult solve_stokes(const MacGrid<Dim>& grid, const StokesWeights& w, double dt,
                               StokesUnknowns unknowns, StressForm form,
                               Backend backend, const PcgSettings& settings,
                               VectorX& u, const StokesSolveOptions& options = {});

/// The unknown vector x = (tau, p) of `dofs` read from a full stress field (StressGrid
/// numbering; a layout unknown takes its DOF's value) and a cell pressure field; a field of
/// another size gives zeros (the inverse of scatter_stress / scatter_stokes_pressure on the
/// active unknowns).
template <int Dim>
VectorX gather_stokes_unknowns(const StressLayout<Dim>& layout, const StokesDofs& dofs,
                               const VectorX& stress_full, const VectorX& pressure_cells);

}  // namespace monolith
