#pragma once
/// \file coupled_preconditioner.hpp
/// The block preconditioner of the coupled systems of eq. (24) with dynamic bodies: the
/// fluid-body block A_ff (the partitioned schemes' fluid solve, PCG without contacts) and the
/// MLCP (26) over (tau, p, lambda) that MPRGP solves (docs/preconditioners.md, "The coupled
/// systems"; docs/mprgp.md, "Preconditioning in face with the block preconditioner").
///
/// With F = A_stokes the fluid part of eq. (24) and W = dt alpha M_r^-1 (nd x nd, block diagonal
/// over the two-way bodies), the fluid rows of the coupled operators are
///
///   A_ff = F + B_f^T W B_f          (B_f = [B_1 B_2], nd x (n_tau + n_p), monolithic_system.hpp)
///
/// and the preconditioner is
///
///   M^-1 = blkdiag(Q, D_c^-1),   Q = (P^-1 + B_f^T W B_f)^-1 = P - U (W^-1 + B_f U)^-1 B_f P,
///   U = P B_f^T                                                      (Woodbury, nd columns)
///
/// P the block multigrid preconditioner of F (stokes_preconditioner.hpp, P ~ F^-1, SPD), D_c the
/// diagonal of the contact rows (the boosted A33 of (26)). Q is the exact inverse of the matrix
/// A_ff would be with F replaced by P^-1: the rank-nd body term costs nd applications of P at
/// set-up and nd dot products per application, instead of up to nd extra Krylov iterations
/// (measured in docs/preconditioners.md). The contact rows get a diagonal block so that MPRGP
/// can precondition in face: the fluid rows are never bounded, so the restriction of M to a
/// free set is blkdiag(Q, D_c restricted to the free contacts), which is M^-1 applied to the
/// free gradient and then masked (mprgp.hpp, MprgpSettings::preconditioner).
///
/// In face (apply_in_face, MPRGP on the MLCP (26)) the contact rows are eliminated exactly
/// instead: M = [Q^-1 A_f3; A_3f A33'] (A33' = A33 (1 + gamma on its diagonal); A with Q^-1 in
/// the fluid block's place), whose principal submatrix on a free set F (all fluid rows and the
/// free contacts) is inverted by block elimination with the contact Schur complement
///
///   S_c = A33' - A_3f Q A_f3 = J (W^-1 + B_f U)^-1 J^T + gamma diag(A33)     (J = J_lambda)
///
/// (A_f3 = B_f^T W J^T, so with (P4) the Schur complement is the bodies' Delassus operator
/// with M_r / (dt alpha) augmented by B_f P B_f^T, the fluid's response through P: nc x nc,
/// dense, from the set-up's small matrices; its free principal submatrix is factored when the
/// free set changes). SPD as M is (S_c is); the same cost per application as the Jacobi rows
/// (one P). docs/preconditioners.md section 17, docs/mprgp.md.
///
/// Near-empty cells E (pressure cells almost closed between a body and a solid, whose Poisson
/// diagonal the body term dwarfs; CoupledPreconditionerOptions::empty_cell_ratio) are left out of
/// P (P = blkdiag(P_r, 0)) and solved exactly with the body term: with H = F_EE + B_E^T W B_E
/// (F_EE's diagonal floored, empty_cell_floor) and W' = (W^-1 + B_E F_EE^-1 B_E^T)^-1,
///
///   Q^-1 = blkdiag(P_r^-1, F_EE) + B_f^T W B_f,   x_r = (P_r - U (W'^-1 + B_f U)^-1 U^T) r',
///   r' = r_r - B_r^T W B_E H^-1 r_E,   x_E = H^-1 (r_E - B_E^T W B_r x_r)
///
/// (block elimination of E; the couplings of E to the rest in F, of A22_kk's size, are left
/// out). W' takes W's place in S_c and the body columns, so S_c and apply_in_face keep their form
/// (docs/preconditioners.md section 23).
///
/// (P11): on a contact-free system (with_contacts false) whose P marks no near-empty cell the
/// correction is left out by default, Q = P (CoupledPreconditionerOptions::contact_free_correction;
/// docs/preconditioners.md section 30).
///
/// (P14): P's cut block without the layers of neighbours (coupled_fluid_options; section 32).
///
/// SPD whenever P is; apply allocates nothing and is deterministic for any thread count (P's
/// applications are, the body correction runs over rows in fixed order).

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Cholesky>

#include "reference/core/common.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/fluid/stokes_preconditioner.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

/// The fluid part's options on the coupled systems: StokesPreconditionerOptions with a cut block
/// of the cut unknowns and their pressures only (cut_layers 0, (P14)). The two layers of
/// neighbours were chosen on a liquid-only scene (the bunny on the curved container wall,
/// section 12); on the coupled 3D scenes they cost set-up and application time and saved no
/// iteration on any built-in scene, and on hollow-spheres-viscous-3d they took 23-37 MPRGP
/// iterations per system where the bare block takes 4-5 (docs/preconditioners.md section 32).
inline StokesPreconditionerOptions coupled_fluid_options() {
  StokesPreconditionerOptions o;
  o.cut_layers = 0;
  return o;
}

struct CoupledPreconditionerOptions {
  /// The Woodbury correction of the body term B_f^T W B_f (false: Q = P, the body term is left to
  /// the Krylov method).
  bool body_correction = true;
  /// The correction also on the contact-free systems (with_contacts false: PCG on A_ff, the
  /// unified solves without contacts and the partitioned schemes' fluid solves) where P marks no
  /// near-empty cell. false (since section 30 of docs/preconditioners.md): Q = P there, the body
  /// term left to PCG; its set-up cost one application of P per body DOF touching the liquid
  /// and saved about two iterations of 4-6 (bunnies-into-floating-bowl-viscous-3d). The MLCP
  /// systems (with_contacts true, where section 20's stalls were) and the systems with
  /// near-empty cells (P8, sections 21 and 23) keep it.
  bool contact_free_correction = false;
  /// Above this many body DOFs the correction is skipped (its set-up costs one application of P
  /// per body DOF).
  int max_body_dofs = 96;
  /// The fluid part's preconditioner (coupled_fluid_options: no layers around the cut block).
  StokesPreconditionerOptions fluid = coupled_fluid_options();
  /// apply_in_face eliminates the contact rows exactly (the Schur complement S_c of the file
  /// comment) when there are at most this many contacts and S_c is available (the Woodbury term
  /// on, or no body touching the liquid); otherwise, and with 0, the Jacobi rows.
  int max_exact_contacts = 256;
  /// fluid.empty_cell_ratio when a body's term touches the liquid (B_f != 0) and the body
  /// correction is on: the near-empty cells of (P8), where P's 1 / A22_kk made the Woodbury
  /// correction cancel in round-off (docs/preconditioners.md section 21). 1e-2 since section 23:
  /// the cells of a thin gap under a resting body at 1e-4..3e-3 of the median with d_k / A22_kk
  /// 0.05..0.3 stalled bunny-into-block-newtonian-2d and -shear-thinning-2d when kept in P.
  /// 0: fluid's own value.
  double empty_cell_ratio = 1e-2;
  /// fluid.empty_cell_extra_ratio in the same case: a cell below empty_cell_ratio is near-empty
  /// only where the body term's diagonal is at least this fraction of its Poisson diagonal,
  /// d_k = (B_f^T W B_f)_kk >= ratio x A22_kk (section 23: the cells below 1e-4 of the median in
  /// the 3D viscous scenes have d_k / A22_kk below 2e-5 and cost 1.1-3x the iterations when left
  /// out of P; a cell closed by the body alone has d_k = 0, rigid motion keeping its volume).
  double empty_cell_body_ratio = 1e-3;
  /// Those cells E solved exactly with the body term (Q^-1 = blkdiag(P_r^-1, F_EE) + B_f^T W B_f
  /// by block elimination of E, the file comment) instead of section 21's Jacobi term
  /// r_k / (A22_kk + d_k) (false), which counts the body term twice on E and cannot see a
  /// combination of E's pressures that the body's motion does not change (rank of B_E below |E|;
  /// A_ff holds it at A22's scale): bunny-into-block-shear-thinning-2d frame 31 stalled on it.
  bool exact_empty_cells = true;
  /// F_EE's diagonal is raised to at least this fraction of the body term's, (B_E^T W B_E)_kk:
  /// H = F_EE + B_E^T W B_E then has a condition number below about 1 / floor where the body
  /// term cannot see a mode of E (A_ff holds it at A22's scale, down to 1e-18 of the median:
  /// solved exactly, that mode's huge values cancel in round-off in B_f x; hollow-spheres-
  /// viscous-2d stalled so).
  double empty_cell_floor = 1e-8;
};

/// M^-1 of the file comment over (tau, p) (with_contacts false: the FluidBodyOperator's unknowns)
/// or (tau, p, lambda) (the MonolithicOperator's). Holds a reference to the system, which must
/// outlive it; one object must not run two applications at once.
template <int Dim>
class CoupledPreconditioner : public Preconditioner, public FacePreconditioner {
 public:
  /// contact_diagonal: the diagonal of the contact rows of the operator (size nc; ignored and may
  /// be empty when with_contacts is false); a non-positive entry gets the identity.
  CoupledPreconditioner(const MonolithicSystem<Dim>& system, bool with_contacts,
                        const VectorX& contact_diagonal,
                        const CoupledPreconditionerOptions& options = {});
  int size() const override { return n_; }
  void apply(const VectorX& r, VectorX& z) const override;
  std::string name() const override { return "coupled-block"; }
  /// z_F = M_FF^-1 g_F with the exact contact elimination (file comment), zero off F; with the
  /// Jacobi contact rows (has_exact_contacts() false) apply() masked to F, the same map.
  void apply_in_face(const VectorX& g, const std::vector<char>& free, VectorX& z) const override;
  /// Whether apply_in_face eliminates the contact rows with S_c.
  bool has_exact_contacts() const { return exact_contacts_; }
  /// S_c (nc x nc; empty without exact contacts).
  const Eigen::MatrixXd& contact_schur() const { return schur_; }

  /// The fluid part P.
  const StokesPreconditioner<Dim>& fluid() const { return *fluid_; }
  /// Whether the Woodbury body correction is applied (off when disabled, above max_body_dofs, or
  /// when no body touches a fluid unknown: B_f = 0).
  bool body_correction() const { return nd_ > 0; }

 private:
  void setup_exact_contacts(const VectorX& contact_diagonal, const Eigen::MatrixXd& w,
                            const Eigen::MatrixXd& w_body, const Eigen::MatrixXd& w_effective,
                            const CoupledPreconditionerOptions& options);

  const MonolithicSystem<Dim>& s_;
  int n_ = 0, nf_ = 0, nc_ = 0, nd_ = 0;
  std::unique_ptr<StokesPreconditioner<Dim>> fluid_;
  Eigen::MatrixXd u_;           ///< U = P B_f^T, nf x nd
  Eigen::MatrixXd small_inv_;   ///< (W^-1 + B_f U)^-1, nd x nd
  VectorX contact_inverse_;     ///< 1 / D_c
  mutable VectorX rf_, zf_, force_, coeff_;
  /// zf_ -= U coeff_ (the Woodbury body columns U times their coefficients).
  void subtract_body_columns() const;
  // the near-empty cells E solved exactly (CoupledPreconditionerOptions::exact_empty_cells)
  std::vector<int> empty_;       ///< E (fluid unknowns, increasing; empty: none)
  Eigen::MatrixXd empty_body_;   ///< B_E^T (|E| x nd)
  Eigen::MatrixXd empty_gain_;   ///< K_E = H^-1 B_E^T W, H = F_EE + B_E^T W B_E (|E| x nd)
  /// B_r^T (nf x nd, zero on E). Kept, not derived from the system's B_f^T product at each
  /// application: on the matrix-free back end in 3D that product sums each surface sample's six
  /// body columns in Eigen's vectorised dot order, not in column order as these rows do, and
  /// differs in the last bits (docs/preconditioners.md section 23, "B_r^T kept").
  Eigen::MatrixXd body_transpose_;
  Eigen::MatrixXd j_;            ///< J (nc x nd; with E and exact contacts)
  Eigen::LLT<Eigen::MatrixXd> empty_factor_;  ///< of H
  mutable VectorX er_, ex_, et_;
  /// er_ = r_E, rf_ = r' (r_r - B_r^T K_E^T r_E, zero on E).
  void reduce_empty_cells() const;
  /// zf_ on E = H^-1 er_ - K_E force_ (force_ = B_r x_r).
  void solve_empty_cells() const;
  // exact contact elimination (apply_in_face)
  bool exact_contacts_ = false;
  Eigen::MatrixXd bu_;          ///< B_f U (nd x nd)
  Eigen::MatrixXd jw_;          ///< J W (nc x nd)
  Eigen::MatrixXd back_;        ///< (I - (W^-1 + B_f U)^-1 B_f U) W J^T (nd x nc): Q A_f3 = U back_
  Eigen::MatrixXd schur_;       ///< S_c
  mutable std::vector<char> factored_free_;  ///< the contact free set S_c was last factored on
  mutable Eigen::MatrixXd masked_;           ///< S_c with the active rows/columns identity
  mutable Eigen::LLT<Eigen::MatrixXd> schur_factor_;
  mutable VectorX yc_, rc_, bq_, t_;
};

/// The coupled preconditioner in face for MPRGP on the Jacobi-scaled MLCP (S A S): built on its
/// first application by `make` (the multigrid set-up costs seconds at 64^3), applied as
/// z = S^-1 M_FF^-1 S^-1 g (a diagonal scaling keeps the free set). Holds a reference to the
/// scale.
template <int Dim>
class LazyCoupledFacePreconditioner : public FacePreconditioner {
 public:
  using Factory = std::function<std::shared_ptr<CoupledPreconditioner<Dim>>()>;
  /// scale: S (nullptr: none).
  LazyCoupledFacePreconditioner(int n, Factory make, const VectorX* scale)
      : n_(n), make_(std::move(make)), scale_(scale) {}
  int size() const override { return n_; }
  void apply_in_face(const VectorX& g, const std::vector<char>& free, VectorX& z) const override;

 private:
  int n_;
  Factory make_;
  const VectorX* scale_;
  mutable std::shared_ptr<CoupledPreconditioner<Dim>> built_;
  mutable VectorX g_, z_;
};

/// (P13) The block preconditioners of one round of Algorithm 2 (section 5), kept for the next
/// round of the same step: the rounds build their systems from the same state (the same bodies,
/// u*, weights) and differ in the viscosity only, so P built for eta^k, an SPD operator, serves
/// the system of eta^(k+1) as its preconditioner (a stale one: the iterations may grow; the set-up,
/// half or more of a block solve at 24^3, is saved). Holds the system P was built on (P reads it
/// at every application). Used with CoupledSchemeOptions::keep_round_preconditioner, off by
/// default (the stale P cost more iterations than it saved on shear-thinning's third frame).
/// docs/preconditioners.md section 32.
template <int Dim>
struct KeptCoupledPreconditioner {
  std::shared_ptr<const MonolithicSystem<Dim>> system;  ///< the system the preconditioners were built on
  std::shared_ptr<CoupledPreconditioner<Dim>> fluid_body;  ///< PCG on A_ff (with_contacts false)
  std::shared_ptr<CoupledPreconditioner<Dim>> mlcp;        ///< MPRGP on (26) (with_contacts true)
  /// The owner of the system being solved, set by the caller before the solve: kept with a
  /// preconditioner built on it.
  std::shared_ptr<const MonolithicSystem<Dim>> candidate;
  /// Whether the kept preconditioners may serve `s`: built on a system with the same unknowns
  /// (stress DOFs, pressure cells, contacts, body DOFs; the caller promises the same bodies and
  /// weights up to the viscosity).
  bool fits(const MonolithicSystem<Dim>& s) const;
  /// Stores a preconditioner built on `s` (the candidate's system), dropping one of another system.
  void keep(const MonolithicSystem<Dim>& s, std::shared_ptr<CoupledPreconditioner<Dim>> fluid,
            std::shared_ptr<CoupledPreconditioner<Dim>> contacts);
};

/// A shared preconditioner seen as one of its own (the fluid-body PCG's LazyPreconditioner owns
/// what its factory returns).
class SharedPreconditioner : public Preconditioner {
 public:
  explicit SharedPreconditioner(std::shared_ptr<const Preconditioner> inner) : inner_(std::move(inner)) {}
  int size() const override { return inner_->size(); }
  void apply(const VectorX& r, VectorX& z) const override { inner_->apply(r, z); }
  std::string name() const override { return inner_->name(); }

 private:
  std::shared_ptr<const Preconditioner> inner_;
};

/// A preconditioner of the Jacobi-scaled operator S A S (JacobiScaledOperator) from one of A:
/// z = S^-1 M^-1 (S^-1 r). Holds references to both.
class ScaledPreconditioner : public Preconditioner {
 public:
  ScaledPreconditioner(const Preconditioner& inner, const VectorX& scale);
  int size() const override { return inner_.size(); }
  void apply(const VectorX& r, VectorX& z) const override;
  std::string name() const override { return inner_.name(); }

 private:
  const Preconditioner& inner_;
  const VectorX& scale_;
  mutable VectorX r_, z_;
};

}  // namespace monolith
