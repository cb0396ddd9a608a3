#pragma once
/// \file monolithic_system.hpp
/// The unified pressure-viscosity-contact system of eq. (24) (section 4.2) over (tau, p, lambda,
/// z) for one step, the MLCP (26) and the friction LCP (25) as LinearOperators, and the
/// PVC-unified solve (staggered projections, MPRGP). docs/coupling.md, "The unified system (24)",
/// derives the scaling.
///
/// Scaling (section 4.1). With Jh_p, Jh_s the Jacobians of coupling.hpp (they keep the control
/// volume dx^Dim: Jh p is a force in N) and alpha = 1 / dx^Dim, the paper's J_p = alpha Jh_p,
/// J_s = alpha Jh_s, and every rigid block of eq. (24) is one product
///     A_ij(rigid) = dt alpha B_i^T M_r^-1 B_j,
///     B_1 = Jh_s W_L^s E S_tau^T,  B_2 = Jh_p W_L^p S_p^T,  B_3 = J_lambda^T,  B_4 = J_z^T,
/// (nd rows: the two-way bodies' DOFs in ContactSystem order), e.g. the paper's
/// (dt / alpha) W_L^p J_p^T M_r^-1 J_p W_L^p = dt alpha W_L^p Jh_p^T M_r^-1 Jh_p W_L^p and
/// dt W_L^p J_p^T M_r^-1 J_lambda^T = dt alpha W_L^p Jh_p^T M_r^-1 J_lambda^T: the same dt alpha as
/// ContactSystem's A33 = dt alpha J_lambda M_r^-1 J_lambda^T. lambda and z stay forces in N (2D:
/// N/m). (alpha M_r)^-1 is never formed: M_r^-1 (ContactSystem::m_r_inverse, block diagonal) is
/// applied to a body-space vector and the factor dt alpha multiplies the result (section 4.2).
/// The products B_i^T M_r^-1 B_j x are evaluated right to left (sequential multiplication,
/// section 4.4.3); the dense n x n blocks exist only in dense_matrix(), for small tests.

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "reference/contact/contact_system.hpp"
#include "reference/core/common.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/fluid/viscosity.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "reference/solvers/linear_operator.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

/// The sixteen blocks of eq. (24) for one step. Unknown blocks: 1 tau (active stress unknowns of
/// StokesDofs, StressLayout numbering), 2 p (active pressure DOFs), 3 lambda (one per contact of
/// the ContactSystem), 4 z ((Dim - 1) per contact). Holds copies of its inputs.
///
/// Two back ends (docs/coupling.md, "Back ends of the coupled step"), chosen by the last
/// constructor argument:
///   - "explicit" (the reference oracle): the fluid part F is ExplicitStokesSystem (every matrix of
///     eq. (8) by its paper name, stokes()) and B_f = [B_1 B_2] is one sparse nd x (n_tau + n_p)
///     matrix (fluid_body_jacobian());
///   - "matrixfree" (the production path): F is a MatrixFreeStokesOperator (face stencils, no
///     global matrix) and B_f is kept as its non-zero column blocks only: for every fluid unknown
///     on a body surface and every body it touches, the kBodyDofs entries of W_L J E S^T, read
///     once from BodyCouplingOperator (coupling.hpp) and applied by loops over the surface
///     (O(surface) memory and work, no global matrix). stokes() and fluid_body_jacobian() are
///     empty under this back end.
/// Both back ends agree to round-off (tests/test_backends.cpp); every function below works under
/// both. Copies share the fluid part (built once, never modified).
template <int Dim>
class MonolithicSystem {
 public:
  /// `w` must carry W_F^u / W_F^s of `solids` (solid_weights over coupling_bodies(bodies), moving
  /// bodies included); `u_star` the face velocities after advection and forces; `contacts` the
  /// ContactSystem of the same bodies (its v* is the two-way bodies' v*, its alpha must equal
  /// 1 / dx^Dim: std::invalid_argument otherwise). One-way (fixed, kinematic) bodies enter b1,
  /// b2 only (section 4.4.4). `unknowns` = stress_only drops the pressure block (p fixed at
  /// zero: the "VC" solve of PC-VC-PC-unified, section 6.2); n_p = 0 then. `backend` chooses
  /// assembled matrices or stencils for the fluid part and the rigid products.
  MonolithicSystem(const MacGrid<Dim>& grid, StressForm form, const StokesWeights& w, double dt,
                   const VectorX& u_star, const std::vector<RigidBody<Dim>>& bodies,
                   const SolidWeights<Dim>& solids, const ContactSystem<Dim>& contacts,
                   Backend backend,
                   StokesUnknowns unknowns = StokesUnknowns::pressure_and_stress);
  /// The same with weights shared instead of copied (the copy holds four face-, one cell- and
  /// three stress-sized vectors: 2 GB at the paper's 256x128x256 grid). A caller whose weights
  /// outlive the system may pass a non-owning pointer.
  MonolithicSystem(const MacGrid<Dim>& grid, StressForm form,
                   std::shared_ptr<const StokesWeights> w, double dt, const VectorX& u_star,
                   const std::vector<RigidBody<Dim>>& bodies, const SolidWeights<Dim>& solids,
                   const ContactSystem<Dim>& contacts, Backend backend,
                   StokesUnknowns unknowns = StokesUnknowns::pressure_and_stress);
  /// The same with u* shared too (a face-sized vector: 194 MiB at the paper's 256x128x256 grid).
  /// A caller whose u* outlives the system may pass a non-owning pointer. `workspace`
  /// (stokes_workspace.hpp; nullptr: none): the matrix-free operator's storage kept across steps
  /// and the liquid's band (the DOF selection and C_f in the band only); it must outlive the
  /// system. The same system either way.
  MonolithicSystem(const MacGrid<Dim>& grid, StressForm form,
                   std::shared_ptr<const StokesWeights> w, double dt,
                   std::shared_ptr<const VectorX> u_star,
                   const std::vector<RigidBody<Dim>>& bodies, const SolidWeights<Dim>& solids,
                   const ContactSystem<Dim>& contacts, Backend backend,
                   StokesUnknowns unknowns = StokesUnknowns::pressure_and_stress,
                   StokesWorkspace* workspace = nullptr);

  /// Test switch (tests only; not thread-safe): true makes every system built afterwards search
  /// the bodies' whole boxes for J_p and J_s columns (BodyCouplingOperator without Columns)
  /// instead of the unknowns' cells and stress DOFs only, which must give the same system bit
  /// for bit.
  static inline bool search_every_column = false;

  int num_stress() const { return dofs_.num_stress(); }
  int num_pressure() const { return dofs_.num_pressure(); }
  int num_fluid() const { return dofs_.size(); }
  int num_contacts() const { return contacts_.num_contacts(); }
  int num_friction() const { return contacts_.num_friction_rows(); }
  int num_body_dofs() const { return contacts_.num_body_dofs(); }
  /// Size of block i (1..4).
  int block_size(int i) const;

  /// y = A_ij x for block row i and column j (1..4) of eq. (24):
  ///   A_ij = F_ij + dt alpha B_i^T M_r^-1 B_j (file comment for B_i), F the fluid part
  ///   F_11 = 1/2 N^-1 W_F^s W_L^s + dt W_L^s M D W_F^u P^-1 (W_L^u)^-1 D^T M W_L^s,
  ///   F_12 = dt W_L^s M D W_F^u P^-1 (W_L^u)^-1 G W_L^p,
  ///   F_22 = dt W_L^p G^T W_F^u P^-1 (W_L^u)^-1 G W_L^p (stokes_system.hpp, restricted to the
  ///   active DOFs), zero in the other blocks. A_ji = A_ij^T. The rigid part is evaluated as
  ///   B_i^T (M_r^-1 (B_j x)), never formed; F through stokes_operator() under matrixfree.
  VectorX apply_block(int i, int j, const VectorX& x) const;
  /// eq. (24): A11 tau = (1/2 N^-1 W^s + dt W_L^s M D K D^T M W_L^s + (dt/alpha) W_L^s J_s^T
  /// M_r^-1 J_s W_L^s) tau, K = W_F^u P^-1 (W_L^u)^-1; n_tau x n_tau.
  VectorX a11(const VectorX& tau) const { return apply_block(1, 1, tau); }
  /// eq. (24): A12 p = (dt W_L^s M D K G W_L^p + (dt/alpha) W_L^s J_s^T M_r^-1 J_p W_L^p) p; n_tau x n_p.
  VectorX a12(const VectorX& p) const { return apply_block(1, 2, p); }
  /// eq. (24): A13 lambda = dt W_L^s J_s^T M_r^-1 J_lambda^T lambda; n_tau x nc.
  VectorX a13(const VectorX& lambda) const { return apply_block(1, 3, lambda); }
  /// eq. (24): A14 z = dt W_L^s J_s^T M_r^-1 J_z^T z; n_tau x nf.
  VectorX a14(const VectorX& z) const { return apply_block(1, 4, z); }
  /// eq. (24): A22 p = (dt W_L^p G^T K G W_L^p + (dt/alpha) W_L^p J_p^T M_r^-1 J_p W_L^p) p; n_p x n_p.
  VectorX a22(const VectorX& p) const { return apply_block(2, 2, p); }
  /// eq. (24): A23 lambda = dt W_L^p J_p^T M_r^-1 J_lambda^T lambda; n_p x nc.
  VectorX a23(const VectorX& lambda) const { return apply_block(2, 3, lambda); }
  /// eq. (24): A24 z = dt W_L^p J_p^T M_r^-1 J_z^T z; n_p x nf.
  VectorX a24(const VectorX& z) const { return apply_block(2, 4, z); }
  /// eq. (24): A33 lambda = dt alpha J_lambda M_r^-1 J_lambda^T lambda; nc x nc.
  VectorX a33(const VectorX& lambda) const { return apply_block(3, 3, lambda); }
  /// eq. (24): A34 z = dt alpha J_lambda M_r^-1 J_z^T z; nc x nf.
  VectorX a34(const VectorX& z) const { return apply_block(3, 4, z); }
  /// eq. (24): A44 z = dt alpha J_z M_r^-1 J_z^T z; nf x nf.
  VectorX a44(const VectorX& z) const { return apply_block(4, 4, z); }

  /// eq. (24): b1 = W_L^s M D W_F^u u* - W_L^s (J_{s,2}^T v*_2 + J_{s,1}^T v*_1) (paper's J_s,
  /// i.e. alpha Jh_s; both groups, section 4.4.4), n_tau.
  const VectorX& b1() const { return b1_; }
  /// eq. (24): b2 = W_L^p G^T W_F^u u* - W_L^p (J_{p,2}^T v*_2 + J_{p,1}^T v*_1), n_p.
  const VectorX& b2() const { return b2_; }
  /// b2 += W_L^p d on each pressure DOF's cell: a target divergence d (cell field, 1/s; nullptr
  /// or empty: nothing) of the new velocity (add_divergence_source, pressure_projection.hpp;
  /// CoupledStepInput::divergence_source). Called before any solve reads b2.
  void add_divergence_source(const VectorX* d) {
    monolith::add_divergence_source(dofs_.pressure.cell_of_dof, w_.pressure.liquid_cell, d, 0, b2_);
    if (d && d->size() > 0) rhs_round_off_ += kRhsRoundOffUlps * kEpsilon * d->cwiseAbs().maxCoeff();
  }
  /// The round-off level N of (b1, b2) (item 4 of docs/derivations.md, "The coupling schemes of
  /// section 6"; docs/preconditioners.md section 26): a row of b1 or b2 sums at most about
  /// 2 x 2 Dim terms W (G^T, D) W_F^u u* and W_L alpha J^T v*, each at most (2 Dim / dx) U in
  /// size, U = max(max_f |W_F^u_f u*_f|, the largest linear velocity component of a moving body),
  /// so
  ///     N = 16 eps ((2 Dim / dx) U + max |d|)     (d: add_divergence_source's target, 1/s).
  /// Where the liquid and the bodies touching it move rigidly (free flight: uniform u* plus
  /// gravity) b is zero in exact arithmetic and only the last bits of u* and of the sums remain,
  /// measured at 0.09-1.25 (2 Dim / dx) U eps; every other step of the measured scenes had
  /// ||b||_inf >= 1e9 of that. The same value on both back ends (one formula from the inputs).
  double rhs_round_off() const { return rhs_round_off_; }
  /// eq. (24): b3 = -alpha (C (J_lambda v* + g_n) - target) (ContactSystem::b3), nc.
  VectorX b3() const { return contacts_.b3(); }
  /// eq. (24): b4 = -alpha (J_z v* + g_t) (ContactSystem::b4), nf.
  VectorX b4() const { return contacts_.b4(); }

  /// The whole of eq. (24) densely, (n_tau + n_p + nc + nf) square, column by column through
  /// apply_block (both back ends): for small tests only.
  Eigen::MatrixXd dense_matrix() const;
  /// (b1, b2, b3, b4).
  VectorX rhs() const;

  /// eq. (26) right-hand side given z: (b1 - A14 z, b2 - A24 z, b3 - A34 z).
  VectorX mlcp_rhs(const VectorX& z) const;
  /// eq. (25) right-hand side given x = (tau, p, lambda): b4 - A14^T tau - A24^T p - A34^T lambda.
  VectorX friction_rhs(const VectorX& x) const;
  /// The fluid block rows of eq. (24) given the contact forces (section 6, the "P" / "PV" solve
  /// of the partitioned schemes): (b1, b2) - (A13, A23) lambda - (A14, A24) z
  /// = (b1, b2) - dt alpha B_f^T M_r^-1 (J_lambda^T lambda + J_z^T z), n_tau + n_p. Empty
  /// lambda / z count as zero.
  VectorX fluid_rhs(const VectorX& lambda, const VectorX& z) const;
  /// The normal-contact block row of eq. (24) given the fluid and friction unknowns (the "C"
  /// solve): b3 - A13^T tau - A23^T p - A34 z = b3 - dt alpha J_lambda M_r^-1 (B_f x_f +
  /// J_z^T z), nc. Empty x_fluid / z count as zero.
  VectorX contact_rhs(const VectorX& x_fluid, const VectorX& z) const;

  /// The generalised force on the two-way bodies (N and N m; 2D per metre) of the fluid part
  /// x_f = (tau, p): B_1 tau + B_2 p = Jh_s W_L^s tau_full + Jh_p W_L^p p (eq. (21)), nd.
  VectorX fluid_body_force(const VectorX& x_fluid) const;
  /// eq. (21), the transpose of fluid_body_force: B_f^T f = (B_1^T f, B_2^T f) for a body-space
  /// vector f (nd), n_tau + n_p.
  VectorX fluid_body_force_transpose(const VectorX& f) const;
  /// force = B_f x_f (eq. (21), nd; `force` must already have nd entries), without allocating:
  /// the hot-loop form of fluid_body_force that the coupled operators use.
  void fluid_body_force_into(const Eigen::Ref<const VectorX>& x_fluid, VectorX& force) const;
  /// y += scale B_f^T f (eq. (24), the left factor of the rigid blocks dt alpha B_f^T M_r^-1 B_f;
  /// y has n_tau + n_p entries). Allocation-free under matrixfree.
  void add_fluid_body_force_transpose(const VectorX& f, double scale, Eigen::Ref<VectorX> y) const;
  /// diagonal += scale diag(B_f^T M_r^-1 B_f) (eq. (24): with scale = dt alpha, the rigid part
  /// of the diagonal of A_ff), n_tau + n_p, column by column of B_f (never the n x n product).
  void add_rigid_diagonal(double scale, Eigen::Ref<VectorX> diagonal) const;
  /// sum |B_f| over its entries (the scale of the null-space test of the coupled operators).
  double fluid_body_jacobian_abs_sum() const;
  /// eq. (21): v = v* + dt M_r^-1 (J_lambda^T lambda + J_z^T z + Jh_p W_L^p p + Jh_s W_L^s tau);
  /// the alpha of (alpha M_r)^-1 and of the scaled forces cancels. nd, ContactSystem order.
  VectorX body_velocities(const VectorX& x_fluid, const VectorX& lambda, const VectorX& z) const;
  /// eq. (8) update of the face velocities: u* - dt P^-1 (W_L^u)^-1 (G W_L^p p + D^T M W_L^s tau)
  /// on faces with W_F^u W_L^u > 0 (explicit: apply_stokes_update; matrixfree: the same face
  /// force from MatrixFreeStokesOperator::face_force), num_faces.
  VectorX fluid_velocities(const VectorX& x_fluid) const;
  /// Cell pressures and all stress components of x_fluid = (tau, p).
  VectorX pressure_cells(const VectorX& x_fluid) const;
  VectorX stress_full(const VectorX& x_fluid) const;
  /// The same three into `out` (resized only when its size differs, so a buffer kept across
  /// steps is reused); the same values bit for bit. stress_full_into of a system without stress
  /// unknowns only zeroes `out`, and leaves it empty when the weights are inviscid
  /// (StokesWeights::inviscid: no stress vectors). fluid_velocities_into writes the face force
  /// into `out` first (MatrixFreeStokesOperator::face_force_into): no face-sized temporary.
  void fluid_velocities_into(const VectorX& x_fluid, VectorX& out) const;
  /// (band23) With `kept` holding `out` (+0 outside kept->cells), only those cells are zeroed
  /// before the DOFs' cells are written (the same bits as zeroing `out` whole); otherwise `out`
  /// is zeroed whole. Either way `kept` (when given) then describes `out`: +0 outside this
  /// system's DOF cells.
  void pressure_cells_into(const VectorX& x_fluid, VectorX& out,
                           ZerosOutsideCells* kept = nullptr) const;
  void stress_full_into(const VectorX& x_fluid, VectorX& out) const;

  Backend backend() const { return backend_; }
  bool matrix_free() const { return matrix_free_; }
  /// The fluid part F = A_stokes of eq. (24) (the (tau, p) blocks without bodies) as a
  /// LinearOperator: explicit, stokes().A with row-order SSOR sweeps; matrixfree, the
  /// MatrixFreeStokesOperator with red-black colour-group sweeps (section 4.3).
  const LinearOperator& stokes_operator() const { return *stokes_operator_; }
  /// The explicit matrices of eq. (8) (explicit back end; all empty under matrixfree).
  const ExplicitStokesSystem& stokes() const;
  const StokesDofs& dofs() const { return dofs_; }
  const ContactSystem<Dim>& contacts() const { return contacts_; }
  /// B_1 = Jh_s W_L^s E S_tau^T and B_2 = Jh_p W_L^p S_p^T side by side: nd x (n_tau + n_p),
  /// non-zero only in the body-surface columns (explicit back end; 0 x 0 under matrixfree, where
  /// fluid_body_force and its transpose apply the same products).
  const SparseMatrix& fluid_body_jacobian() const { return b_fluid_; }
  const SparseMatrix& j_lambda_transpose() const { return j_lambda_t_; }
  double dt() const { return dt_; }
  double alpha() const { return alpha_; }
  /// The inputs the system was built from (the export of system_export.hpp rebuilds the
  /// explicit twin of a matrix-free system from them).
  const MacGrid<Dim>& grid() const { return grid_; }
  const StressLayout<Dim>& layout() const { return layout_; }
  const StokesWeights& weights() const { return w_; }
  const VectorX& u_star() const { return u_star_; }
  StokesUnknowns unknowns() const { return unknowns_; }

 private:
  /// One non-zero column block of B_f (matrixfree): fluid unknown, first row of the body, the
  /// kBodyDofs entries (W_L, E and the DOF selection folded in).
  struct RigidColumn {
    int unknown = 0;
    int row = 0;
    BodyVec<Dim> column;
  };
  /// B_i x (body space, nd) for block j.
  VectorX body_force(int j, const VectorX& x) const;
  /// B_i^T f for block i.
  VectorX body_force_transpose(int i, const VectorX& f) const;
  /// matrixfree: b1_, b2_ -= the bodies' part of eq. (24)'s right-hand side (both groups), over
  /// the bodies' surface DOFs (no grid-sized temporaries).
  void add_body_rhs(const BodyCouplingOperator<Dim>& two, const BodyCouplingOperator<Dim>& one,
                    const VectorX& v_two, const VectorX& v_one);
  /// The matrixfree column blocks of B_f from the two-way BodyCouplingOperator.
  void build_rigid_columns(const BodyCouplingOperator<Dim>& two);

  MacGrid<Dim> grid_;
  StressGrid<Dim> stress_;
  StressLayout<Dim> layout_;
  std::shared_ptr<const StokesWeights> w_owner_;  ///< the weights (shared or a copy of them)
  const StokesWeights& w_;                         ///< *w_owner_
  double dt_ = 0.0, alpha_ = 1.0;
  std::shared_ptr<const VectorX> u_star_owner_;  ///< u* (shared or a copy of it)
  const VectorX& u_star_;                         ///< *u_star_owner_
  Backend backend_;
  StokesUnknowns unknowns_ = StokesUnknowns::pressure_and_stress;
  bool matrix_free_ = false;
  StokesDofs dofs_;
  std::shared_ptr<const ExplicitStokesSystem> stokes_;                 ///< explicit only
  std::shared_ptr<const MatrixFreeStokesOperator<Dim>> matrix_free_stokes_;  ///< matrixfree only
  std::shared_ptr<const LinearOperator> stokes_operator_;
  ContactSystem<Dim> contacts_;
  SparseMatrix b_fluid_;      ///< nd x n_fluid (explicit)
  SparseMatrix b_fluid_t_;    ///< its transpose (explicit)
  std::vector<RigidColumn> rigid_columns_;  ///< matrixfree, by unknown then row
  SparseMatrix j_lambda_t_, j_z_t_;
  VectorX b1_, b2_;
  /// rhs_round_off(): eps (times kRhsRoundOffUlps of pressure_projection.hpp) and the bound itself.
  static constexpr double kEpsilon = std::numeric_limits<double>::epsilon();  // 2^-52
  double rhs_round_off_ = 0.0;
};

/// The common base of the coupled operators of eq. (24) (MonolithicOperator over (tau, p, lambda),
/// FluidBodyOperator over (tau, p)): A = S + R with
///   S = blockdiag(F, A33 + gamma diag(A33)) the sparse part (FluidBodyOperator: S = F),
///   R = dt alpha [B_f^T M_r^-1 B_f, B_f^T M_r^-1 J_lambda^T; J_lambda M_r^-1 B_f, 0],
/// F = MonolithicSystem::stokes_operator() whatever the back end, B_f = [B_1 B_2]. apply = S x +
/// R x with R by sequential multiplication (section 4.4.3: body-space vectors only, never n x n);
/// diagonal = diag(S) + dt alpha diag(B_f^T M_r^-1 B_f) (column by column, never the n x n
/// product). SSOR sweeps (section 4.3: SOR on the remaining sparse part) run on S only, honouring
/// `active`: the fluid rows through F's own sweeps (explicit: row order; matrixfree: red-black
/// colour groups per stress component and pressure), then the contact rows (explicit: row order;
/// matrixfree: Welsh-Powell colour groups of the contact graph, ColouredSparseOperator); the
/// backward sweep runs the contact rows first, so forward then backward is symmetric. gamma is
/// the boost of section 4.4.5 on the contact rows only, so the fluid rows keep their exact
/// equations. null_space: the Stokes null vectors (enclosed liquid) that the bodies do not see
/// (B_f n = 0), extended by zeros.
///
/// apply and the sweeps work in mutable scratch vectors sized at construction (no allocation per
/// call under matrixfree): calling them concurrently on one operator object is not thread-safe
/// (each call is parallel inside). Holds a reference to the system, which must outlive it.
template <int Dim>
class CoupledOperator : public LinearOperator {
 public:
  int size() const override { return size_; }
  void apply(const VectorX& x, VectorX& y) const override;
  VectorX diagonal() const override { return diagonal_; }
  /// diag(S): the sweeps relax the sparse part only, so on rows where the rigid term R dominates
  /// this is far below diagonal().
  VectorX sweep_diagonal() const override { return sweep_diagonal_; }
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override;
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override;
  const std::vector<VectorX>& null_space() const override { return null_space_; }
  /// The operator densely (column by column through apply), for small tests.
  Eigen::MatrixXd dense_matrix() const;
  const MonolithicSystem<Dim>& system() const { return system_; }

 protected:
  /// with_contacts: the lambda rows and columns of (26) with gamma = contact_boost on A33.
  CoupledOperator(const MonolithicSystem<Dim>& system, bool with_contacts, double contact_boost);
  /// The contact block of S (A33 boosted), nullptr without contact rows.
  const LinearOperator* contact_block() const { return contact_.get(); }

 private:
  /// One SOR sweep of S: fluid rows then contact rows (forward), or the reverse.
  void sweep(const VectorX& rhs, VectorX& x, double omega, const std::vector<char>* active,
             bool backward) const;

  const MonolithicSystem<Dim>& system_;
  int size_ = 0, num_fluid_ = 0, num_contacts_ = 0;
  std::shared_ptr<const LinearOperator> contact_;
  VectorX diagonal_, sweep_diagonal_;
  std::vector<VectorX> null_space_;
  // scratch (apply, sweeps)
  mutable VectorX x_fluid_, y_fluid_, rhs_fluid_, x_contact_, y_contact_, rhs_contact_;
  mutable VectorX force_, g_, h_;
  mutable std::vector<char> active_fluid_, active_contact_;
};

/// The MLCP (26) over x = (tau, p, lambda) as a LinearOperator, size n_tau + n_p + nc: the
/// CoupledOperator with contact rows, A = S + R,
///   S = blockdiag(A_stokes, A33 (1 + gamma on its diagonal)) the sparse part,
///   R = dt alpha [B_f^T M_r^-1 B_f, B_f^T M_r^-1 J_lambda^T; J_lambda M_r^-1 B_f, 0]
/// (eqs. (24), (26)); apply, diagonal, sweeps and null space as CoupledOperator says.
template <int Dim>
class MonolithicOperator : public CoupledOperator<Dim> {
 public:
  MonolithicOperator(const MonolithicSystem<Dim>& system, double contact_boost = 0.0);
  /// The sparse part S assembled (explicit back end only: std::logic_error under matrixfree,
  /// where S exists only as operators). For small tests.
  SparseMatrix sparse_part() const;

 private:
  double contact_boost_ = 0.0;
};

/// The fluid-body block A_ff of eq. (24) over x_f = (tau, p), size n_tau + n_p:
///   A_ff = [A11 A12; A12^T A22] = A_stokes + dt alpha B_f^T M_r^-1 B_f
/// (symmetric positive semi-definite; definite unless the liquid is enclosed and the bodies do not
/// feel the enclosed group's constant pressure), i.e. the liquid two-way coupled with the
/// bodies but without contact: the "P" / "PV" / "VC" solve of the partitioned schemes of
/// section 6 (and the unified schemes when there are no contacts). The CoupledOperator without
/// contact rows: MonolithicOperator restricted to its fluid rows and columns.
template <int Dim>
class FluidBodyOperator : public CoupledOperator<Dim> {
 public:
  explicit FluidBodyOperator(const MonolithicSystem<Dim>& system);
};

/// The friction LCP (25) as a LinearOperator over z: A44 with (1 + gamma) on its diagonal
/// (section 4.4.5), nf x nf; A44 = dt alpha J_z M_r^-1 J_z^T is sparse (contact graph).
template <int Dim>
SparseMatrixOperator friction_operator(const MonolithicSystem<Dim>& system, double contact_boost);

/// A LinearOperator seen through a symmetric diagonal (Jacobi) scaling: S A S with
/// S = diag(1 / sqrt(A_ii)) (1 where A_ii <= 0), so the scaled diagonal is 1. A box-constrained
/// QP in x with bounds 0 <= lambda or free is the same QP in y = S^-1 x (positive scaling keeps
/// the bounds 0 and +-inf), with right-hand side S b. SSOR sweeps are forwarded to A on
/// (S^-1 rhs, S y) and so are exactly the sweeps of S A S: the SSOR preconditioner is invariant
/// under the scaling, and preconditioned CG steps are the same; what changes is MPRGP's
/// expansion step length 1.9 / ||S A S|| and its proportioning test, which compare gradient
/// entries across rows. null_space: S^-1 n, normalised. Holds a reference to A. apply and the
/// sweeps use mutable scratch vectors sized at construction (not thread-safe to call
/// concurrently on one object).
class JacobiScaledOperator : public LinearOperator {
 public:
  explicit JacobiScaledOperator(const LinearOperator& a);
  int size() const override { return a_.size(); }
  void apply(const VectorX& x, VectorX& y) const override;
  VectorX diagonal() const override { return diagonal_; }
  /// S^2 times A's sweep diagonal: the sweeps are A's on scaled values.
  VectorX sweep_diagonal() const override {
    return scale_.cwiseProduct(scale_).cwiseProduct(a_.sweep_diagonal());
  }
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override;
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override;
  const std::vector<VectorX>& null_space() const override { return null_space_; }
  /// The diagonal of S.
  const VectorX& scale() const { return scale_; }

 private:
  const LinearOperator& a_;
  VectorX scale_, diagonal_;
  std::vector<VectorX> null_space_;
  mutable VectorX scaled_x_, scaled_rhs_;
};

/// Options of solve_pvc_unified.
struct PvcUnifiedOptions {
  /// MPRGP on the Jacobi-scaled MLCP (JacobiScaledOperator). Departure from the paper, whose
  /// alpha scaling (section 4.1) balances the blocks only roughly: with alpha = 1/dx^Dim the
  /// contact rows' diagonal differs from the fluid rows' by orders of magnitude, so MPRGP's
  /// fixed expansion step 1.9 / ||A|| barely moves lambda and the proportioning test fires
  /// often (measured on the bowl scene of bench_schemes, 3D 24^3: 123 MPRGP iterations with 26
  /// expansion and 22 proportioning steps unscaled, 42 with 0 and 1 scaled; a fluid-only
  /// PCG solve of the same step takes 40). The solution set is the same; the stopping test
  /// ||g^P||_inf <= tolerance ||b||_inf is applied to the scaled gradient and right-hand side.
  /// Off by default, so solve_pvc_unified(system, settings) keeps its iterates bit for bit;
  /// solve_coupled_step (coupled_schemes.hpp) turns it on.
  bool jacobi_scaling = false;
  /// Fill u, body_velocity, stress and pressure of the result (eqs. (8), (21)); a caller that
  /// updates from x itself (solve_coupled_step) turns it off.
  bool compute_updates = true;
  /// The preconditioner of the MPRGP solves of (26): ssor (the paper's, section 4.3) or
  /// multigrid, the block preconditioner of coupled_preconditioner.hpp (the fluid rows by the
  /// multigrid block preconditioner of eq. (8) with the bodies' low-rank term by Woodbury, Jacobi
  /// on the contact rows), applied in face (docs/mprgp.md). Built once per call, on its first
  /// application.
  PreconditionerKind preconditioner = PreconditionerKind::ssor;
  /// multigrid: CoupledPreconditionerOptions::body_correction.
  bool body_correction = true;
  /// multigrid: the contact rows eliminated exactly in face with the contact Schur complement
  /// (CoupledPreconditioner::apply_in_face; docs/preconditioners.md section 17); false: the
  /// Jacobi contact rows of section 13.
  bool exact_contacts = true;
};

struct PvcUnifiedResult {
  VectorX stress;      ///< tau, all StressGrid components, Pa
  VectorX pressure;    ///< cell field, Pa
  VectorX lambda;      ///< nc normal forces (N; 2D N/m)
  VectorX z;           ///< nf friction forces
  VectorX x;           ///< the MLCP unknowns (tau, p, lambda) at exit
  VectorX u;           ///< updated face velocities (eq. (8))
  VectorX body_velocity;  ///< two-way bodies' (v, omega), ContactSystem order (eq. (21))
  int staggered_iterations = 0;  ///< MLCP (26) solves
  long mprgp_iterations = 0;     ///< summed over all MPRGP solves
  /// mprgp_iterations by kind (MprgpResult): CG, expansion and proportioning steps
  long cg_steps = 0, expansion_steps = 0, proportioning_steps = 0;
  bool converged = true;         ///< every MPRGP solve converged
  double last_change = 0.0;      ///< relative change of lambda in the last staggered iteration
  double max_relative_residual = 0.0;  ///< largest MPRGP relative residual at exit
  bool breakdown = false;        ///< some MPRGP solve broke down (message says which)
  std::string message;
};

/// PVC-unified (section 4.2): MPRGP on (26) with lambda >= 0 and free tau, p; when some mu > 0,
/// staggered projections: (26) with z = 0, then up to settings.max_iterations - 1 times the
/// friction LCP (25) with -mu lambda <= z <= mu lambda followed by (26) given z, stopping when
/// lambda changes by <= settings.tolerance (relative, inf-norm); always ends on (26).
/// settings.diagonal_boost is gamma on the contact rows (section 4.4.5).
template <int Dim>
struct KeptCoupledPreconditioner;

/// kept (nullptr: none): with the block preconditioner, the MLCP's CoupledPreconditioner is taken
/// from it when it fits the system and stored into it when built here (the rounds of Algorithm 2
/// within a step, (P13) of coupled_preconditioner.hpp).
template <int Dim>
PvcUnifiedResult solve_pvc_unified(const MonolithicSystem<Dim>& system,
                                   const StaggeredSettings& settings,
                                   const PvcUnifiedOptions& options = {},
                                   KeptCoupledPreconditioner<Dim>* kept = nullptr);

}  // namespace monolith
