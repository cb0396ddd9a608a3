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
/// SPD whenever P is; apply allocates nothing and is deterministic for any thread count (P's
/// applications are, the body correction runs over rows in fixed order).

#include <memory>
#include <string>

#include "reference/core/common.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/fluid/stokes_preconditioner.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

struct CoupledPreconditionerOptions {
  /// The Woodbury correction of the body term B_f^T W B_f (false: Q = P, the body term is left to
  /// the Krylov method).
  bool body_correction = true;
  /// Above this many body DOFs the correction is skipped (its set-up costs one application of P
  /// per body DOF).
  int max_body_dofs = 96;
  /// The fluid part's preconditioner.
  StokesPreconditionerOptions fluid;
};

/// M^-1 of the file comment over (tau, p) (with_contacts false: the FluidBodyOperator's unknowns)
/// or (tau, p, lambda) (the MonolithicOperator's). Holds a reference to the system, which must
/// outlive it; one object must not run two applications at once.
template <int Dim>
class CoupledPreconditioner : public Preconditioner {
 public:
  /// contact_diagonal: the diagonal of the contact rows of the operator (size nc; ignored and may
  /// be empty when with_contacts is false); a non-positive entry gets the identity.
  CoupledPreconditioner(const MonolithicSystem<Dim>& system, bool with_contacts,
                        const VectorX& contact_diagonal,
                        const CoupledPreconditionerOptions& options = {});
  int size() const override { return n_; }
  void apply(const VectorX& r, VectorX& z) const override;
  std::string name() const override { return "coupled-block"; }

  /// The fluid part P.
  const StokesPreconditioner<Dim>& fluid() const { return *fluid_; }
  /// Whether the Woodbury body correction is applied (off when disabled, above max_body_dofs, or
  /// when no body touches a fluid unknown: B_f = 0).
  bool body_correction() const { return nd_ > 0; }

 private:
  const MonolithicSystem<Dim>& s_;
  int n_ = 0, nf_ = 0, nc_ = 0, nd_ = 0;
  std::unique_ptr<StokesPreconditioner<Dim>> fluid_;
  Eigen::MatrixXd u_;           ///< U = P B_f^T, nf x nd
  Eigen::MatrixXd small_inv_;   ///< (W^-1 + B_f U)^-1, nd x nd
  VectorX contact_inverse_;     ///< 1 / D_c
  mutable VectorX rf_, zf_, force_, coeff_;
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
