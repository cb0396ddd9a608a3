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
#include <string>
#include <utility>
#include <vector>

#include "reference/common.hpp"
#include "reference/linear_operator.hpp"
#include "reference/mac_grid.hpp"
#include "reference/pcg.hpp"
#include "reference/pressure_projection.hpp"
#include "reference/scene.hpp"
#include "reference/stress_grid.hpp"
#include "reference/viscosity.hpp"

namespace monolith {

/// Everything eq. (8) is built from, per DOF (diagonal matrices stored as their diagonals).
struct StokesWeights {
  PressureWeights pressure;  ///< W_F^u, W_L^p, W_L^u, P (pressure_projection.hpp)
  VectorX fluid_stress;      ///< W_F^s per StressGrid DOF (all components)
  VectorX liquid_stress;     ///< W_L^s per StressGrid DOF
  VectorX viscosity;         ///< eta per StressGrid DOF, Pa s (0 = inviscid there)
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

/// Which unknowns a solve has: both (PV: eq. (8)) or stress only (the "VC" step of PC-VC-PC:
/// eq. (8) with p fixed at zero). Pressure only is solve_pressure (pressure_projection.hpp).
enum class StokesUnknowns { pressure_and_stress, stress_only };

/// Active unknowns (Algorithm 1, line 7): stress unknowns with W^s = W_F^s W_L^s > 0 and eta > 0
/// (reduced diagonal unknowns: also on the eliminated component of the cell), and the pressure
/// DOFs of select_pressure_dofs. The unknown vector is (tau, p), tau first (eq. (24)).
struct StokesDofs {
  PressureDofs pressure;                 ///< empty for stress_only
  std::vector<int> unknown_of_dof;       ///< active stress DOF k -> StressLayout unknown
  std::vector<int> dof_of_unknown;       ///< StressLayout unknown -> active stress DOF, -1 inactive
  std::vector<VectorX> null_space;       ///< of the whole (tau, p) system, orthonormal
  int num_stress() const { return static_cast<int>(unknown_of_dof.size()); }
  int num_pressure() const { return pressure.size(); }
  int size() const { return num_stress() + num_pressure(); }
};

template <int Dim>
StokesDofs select_stokes_dofs(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                              const StokesWeights& w, double dt, StokesUnknowns unknowns);

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
/// B stored as per-unknown face stencils (and their transpose per face), never A itself. apply is
/// two gather loops (faces, then unknowns; OpenMP, deterministic). SSOR sweeps (section 4.3) run
/// over colour groups: per stress component (in StressLayout order) and then pressure, red-black
/// by the parity of the coordinate sum; unknowns of one group share no face, so each group is
/// relaxed in parallel (serially, in a fixed order, when an odd periodic axis breaks the colouring).
template <int Dim>
class MatrixFreeStokesOperator : public LinearOperator {
 public:
  MatrixFreeStokesOperator(const MacGrid<Dim>& grid, const StressLayout<Dim>& layout,
                           const StokesWeights& w, const StokesDofs& dofs, double dt);
  int size() const override { return size_; }
  void apply(const VectorX& x, VectorX& y) const override;
  VectorX diagonal() const override { return diagonal_; }
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override;
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override;
  const std::vector<VectorX>& null_space() const override { return null_space_; }
  /// b = B^T W_F^u u* (= (b1, b2) of eq. (24)) by the same stencils.
  VectorX rhs(const VectorX& u_star) const;
  /// The face coefficient C_f = dt W_F^u / (rho W_L^u) (0 where the face carries no fluid).
  const VectorX& face_coefficients() const { return face_coefficient_; }
  /// B x: the generalised force G W_L^p p + D^T M W_L^s tau_full of x = (tau, p) on every face
  /// (num_faces). The velocity update is u* - dt P^-1 (W_L^u)^-1 B x; the rigid-body terms of
  /// eq. (24) aggregate the same force (J_s = -Q W_S^u D^T M, J_p = -Q W_S^u G, section 4.4.1; reference/coupling.hpp).
  VectorX face_force(const VectorX& x) const;
  /// Column i of B: the faces unknown i acts on and the coefficients B_fi, as (face, B_fi) pairs.
  std::vector<std::pair<int, double>> stencil(int i) const;

 private:
  /// (B x)_f: row f of B times x.
  double face_product(int f, const VectorX& x) const;
  double row_product(int i, const VectorX& x) const;
  int size_ = 0;
  int num_faces_ = 0;
  VectorX face_coefficient_;
  VectorX fluid_face_;
  // B by unknown (CSR): the faces each unknown acts on and the coefficient
  std::vector<int> unknown_start_, unknown_face_;
  std::vector<double> unknown_coef_;
  // B by face (CSR): the unknowns acting on each face
  std::vector<int> face_start_, face_unknown_;
  std::vector<double> face_coef_;
  // 1/2 N^-1 W^s: own entry and (3D reduced diagonal block) the partner unknown's entry
  VectorX self_;
  std::vector<int> partner_;
  std::vector<double> partner_coef_;
  VectorX diagonal_;
  std::vector<std::vector<int>> groups_;
  bool colouring_valid_ = true;
  std::vector<VectorX> null_space_;
};

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
  PcgResult pcg;
  int pressure_dofs = 0, stress_dofs = 0;
};

/// Lines 7-11 of Algorithm 1 for the Stokes problem: select DOFs, build (backend "explicit" or
/// "matrixfree"), SSOR-PCG, update u (which enters as u*). Throws std::invalid_argument on an
/// unknown backend name.
template <int Dim>
StokesSolveResult solve_stokes(const MacGrid<Dim>& grid, const StokesWeights& w, double dt,
                               StokesUnknowns unknowns, StressForm form,
                               const std::string& backend, const PcgSettings& settings,
                               VectorX& u);

}  // namespace monolith
