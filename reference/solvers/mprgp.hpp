#pragma once
/// \file mprgp.hpp
/// MPRGP (modified proportioning with reduced gradient projections; Dostal & Schoberl 2005,
/// Dostal 2009, "Optimal Quadratic Programming Algorithms", ch. 8) for the bound-constrained
/// quadratic programs of the contact solve (section 4.3: the friction LCP (25) and the MLCP (26),
/// the latter with infinite bounds on tau and p), with the SSOR
/// preconditioner applied to the free set ("preconditioning in face"), the (1 + gamma) diagonal
/// rescaling of section 4.4.5, and a coloured sparse operator whose SOR sweeps run in parallel.
/// Written once against LinearOperator: it runs on explicit matrices and matrix-free operators.
/// The algorithm as implemented is documented step by step in docs/mprgp.md.

#include <functional>
#include <string>
#include <vector>

#include "reference/solvers/colouring.hpp"
#include "reference/solvers/linear_operator.hpp"
#include "reference/solvers/pcg.hpp"
#include "reference/solvers/preconditioner.hpp"

namespace monolith {

/// A preconditioner applied in face with the free set known: z_F = M_FF^-1 g_F (M_FF the
/// principal submatrix on the free set F of one fixed SPD matrix M), z = 0 off F. Unlike
/// MprgpSettings::preconditioner, M need not be block diagonal between bounded and unbounded
/// rows: the implementation solves with M_FF itself (e.g. CoupledPreconditioner's block
/// elimination over the free contact rows, coupled_preconditioner.hpp; docs/mprgp.md).
class FacePreconditioner {
 public:
  virtual ~FacePreconditioner() = default;
  virtual int size() const = 0;
  /// g: the gradient (read on F only); free: 1 on F; z resized to size().
  virtual void apply_in_face(const VectorX& g, const std::vector<char>& free, VectorX& z) const = 0;
};

struct MprgpSettings {
  double tolerance = 1e-6;     ///< stop when ||g^P||_inf <= tolerance * ||b||_inf (projected gradient)
  int max_iterations = 2000;   ///< limit on CG + expansion + proportioning steps
  bool precondition = true;    ///< SSOR on the free set (section 4.3); Jacobi on rows the sweeps under-weight
  double omega = 1.0;          ///< SSOR relaxation in (0, 2)
  double step_scale = 1.9;     ///< alpha_bar = step_scale / ||A||, ||A|| estimated by power iteration
  double gamma_proportioning = 1.0;  ///< Gamma of the proportioning test
  double norm_estimate = 0.0;  ///< ||A||_2 if known (> 0); 0: estimated by power iteration
  int power_iterations = 30;   ///< power iterations of the ||A|| estimate
  /// Opt-in departure: in an expansion step, first try the exact minimiser along the free
  /// gradient (phi^T phi / phi^T A phi, when longer than alpha_bar), projected, and keep it if it
  /// lowers f; otherwise the fixed step. Fewer expansion steps when many variables must reach
  /// their bounds (docs/mprgp.md); costs one or two extra operator applications per expansion.
  bool adaptive_expansion = false;
  /// With precondition: instead of SSOR on the free set, z = M^-1 phi masked to the free set F
  /// (phi the free gradient). M must be a fixed SPD map that is block diagonal with a diagonal
  /// block over every bounded variable (e.g. CoupledPreconditioner of coupled_preconditioner.hpp:
  /// a fluid block over the unbounded (tau, p) rows, Jacobi on the contact rows); then the masked
  /// application is exactly M_FF^-1 on every free set, i.e. preconditioning in face
  /// (docs/mprgp.md). Not owned; nullptr: SSOR.
  const Preconditioner* preconditioner = nullptr;
  /// With precondition: z = M_FF^-1 g_F by the face-aware map (takes precedence over
  /// `preconditioner`). Not owned; nullptr: not used.
  const FacePreconditioner* face_preconditioner = nullptr;
  /// Early exit when the projected gradient stops falling (pcg.hpp; off by default): the
  /// multigrid attempt under "auto", which the SSOR fallback follows.
  StagnationRule stagnation;
};

struct MprgpResult {
  int iterations = 0;           ///< CG + expansion + proportioning steps
  int cg_steps = 0, expansion_steps = 0, proportioning_steps = 0;
  double relative_residual = 0; ///< ||g^P||_inf / ||b||_inf at exit (||g^P||_inf if b = 0)
  bool converged = false, breakdown = false;
  bool stagnated = false;       ///< settings.stagnation stopped it (not converged)
  std::string message;          ///< what broke down, empty otherwise
  double norm_estimate = 0.0;   ///< the ||A|| used for alpha_bar
};

/// The kind of an MPRGP step, reported to an observer (the notebook prints them).
enum class MprgpStep { cg, expansion, proportioning };
/// Called after every step with its kind, the new iterate and its gradient g = A x - b.
using MprgpObserver = std::function<void(MprgpStep, const VectorX& x, const VectorX& g)>;

/// Eqs. (25) and (26) as convex QPs (section 4.3): the box-constrained LCP "A x = b where
/// lower < x < upper, A x >= b at lower, A x <= b at upper" is the optimality condition of
/// min 1/2 x^T A x - b^T x  s.t.  lower <= x <= upper (entries may be -inf / +inf: then that
/// variable is free; lower_i = upper_i fixes it; with all bounds infinite this is preconditioned
/// CG). x is the initial guess (resized to zero if its size is wrong, then projected onto the
/// box). A must be SPD (use DiagonalBoost for section 4.4.5) except for a.null_space(): as in
/// pcg_solve, that orthonormal basis is projected out of b, x and every preconditioned
/// direction (so an enclosed liquid's constant pressure mode is allowed); each basis vector must
/// be supported on unbounded variables only (l = -inf, u = +inf), so the projection keeps x
/// feasible. Throws std::invalid_argument on mismatched sizes, lower > upper, or a null-space
/// vector touching a bounded variable.
MprgpResult mprgp_solve(const LinearOperator& a, const VectorX& b, const VectorX& lower,
                        const VectorX& upper, VectorX& x, const MprgpSettings& settings,
                        const MprgpObserver& observer = nullptr);

/// The rows whose SOR sweeps relax with a diagonal d_i = a.sweep_diagonal()_i below A_ii / 2
/// (or not at all, d_i <= 0), A_ii = a.diagonal()_i: mismatch[i] = 1 for them (n entries),
/// returns their number. Rows with A_ii <= 0 are never flagged. Such rows occur when an operator
/// sweeps only a sparse part S of A = S + R (CoupledOperator: R is the rigid-body coupling of
/// eq. (24)): the SSOR of S then badly underestimates A on those rows, and mprgp_solve takes them
/// out of the SSOR block and gives them a Jacobi step (docs/mprgp.md).
int sweep_diagonal_mismatch(const LinearOperator& a, std::vector<char>& mismatch);

/// An estimate of ||A||_2 = lambda_max(A) for SPD A: power iteration from a fixed start vector,
/// ||A v|| / ||v|| after `iterations` steps, times 1.05 (the iteration approaches from below; the
/// margin keeps alpha_bar = step_scale / ||A|| under 2 / ||A||).
double estimate_operator_norm(const LinearOperator& a, int iterations = 30);

/// `settings` with norm_estimate filled in for `a` (power iteration, as mprgp_solve would do) when
/// it is not set: a caller that solves with the same operator several times (the staggered
/// projections of section 4.2) estimates ||A|| once instead of once per solve. The solves are
/// unchanged (the estimate is deterministic).
MprgpSettings with_norm_estimate(const LinearOperator& a, MprgpSettings settings);

/// Section 4.4.5 (the paper uses gamma = 1e-4 on A_33 and A_44 of eq. (24)): the operator A with
/// its diagonal scaled by (1 + gamma), i.e. A + gamma diag(A)
/// (n x n, SPD for gamma > 0 whenever A is SPSD with a positive diagonal). apply, diagonal and
/// sweeps are forwarded to A (so the preconditioner sees the boosted diagonal and A's sweep order
/// and parallelism are kept): a sweep of the boosted matrix is A's sweep with omega / (1 + gamma)
/// on the right-hand side rhs - gamma diag(A) x, exact when the sweep relaxes every row once.
/// Holds a reference to A, which must outlive it.
class DiagonalBoost : public LinearOperator {
 public:
  DiagonalBoost(const LinearOperator& a, double gamma);
  int size() const override;
  void apply(const VectorX& x, VectorX& y) const override;
  VectorX diagonal() const override;
  /// (1 + gamma) times A's sweep diagonal.
  VectorX sweep_diagonal() const override { return (1.0 + gamma_) * a_.sweep_diagonal(); }
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override;
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override;
  double gamma() const { return gamma_; }

 private:
  VectorX shifted_rhs(const VectorX& rhs, const VectorX& x) const;
  const LinearOperator& a_;
  double gamma_;
  VectorX diagonal_;  ///< diag(A) (not boosted)
};

/// An explicit sparse matrix whose SOR sweeps visit the rows colour by colour (rows of one colour
/// share no off-diagonal entry, so each colour is relaxed in parallel with OpenMP; the backward
/// sweep reverses colours and order, keeping SSOR symmetric). Deterministic for any thread count,
/// and equal to serial Gauss-Seidel/SOR in the colour order. Throws std::invalid_argument when
/// the colouring does not cover every row exactly once or two rows of a colour are coupled.
class ColouredSparseOperator : public LinearOperator {
 public:
  ColouredSparseOperator(SparseMatrix a, Colouring colours, std::vector<VectorX> null_space = {});
  int size() const override;
  void apply(const VectorX& x, VectorX& y) const override;
  VectorX diagonal() const override;
  void forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                     const std::vector<char>* active = nullptr) const override;
  void backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                      const std::vector<char>* active = nullptr) const override;
  const std::vector<VectorX>& null_space() const override { return null_space_; }
  const SparseMatrix& matrix() const { return a_; }
  const Colouring& colouring() const { return colours_; }

 private:
  /// sum_{j != i} A_ij x_j over the nonzero stored entries of row i.
  double off_diagonal_product(int i, const VectorX& x) const;
  SparseMatrix a_;
  Colouring colours_;
  VectorX diagonal_;
  std::vector<VectorX> null_space_;
};

}  // namespace monolith
