#pragma once
/// \file system_export.hpp
/// The oracle's view of one step's coupled system (eq. (24), section 4.2): every named object of
/// the paper as an explicit sparse matrix or vector, the reference solution x = (tau, p, lambda,
/// z), and what every row of x is, as plain data (SystemExport). The core builds it
/// (export_system); the application writes it as Matrix Market files and manifest.json (`monolith
/// export`, docs/oracle.md), and `monolith verify` judges a candidate x against it
/// (check_solution). No file format and no JSON here.
///
/// Convention (the manifest's "convention": "w = A x - b"): tau and p rows are free (w = 0),
/// lambda rows complementary (lambda >= 0, w >= 0, lambda w = 0), z rows boxed
/// (|z_k| <= mu lambda_k, and w_k of the sign that opposes z_k where the bound is active; w_k = 0
/// inside the box): the optimality conditions of the minimisation (22).

#include <string>
#include <vector>

#include "reference/contact/collision.hpp"
#include "reference/core/common.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/rigid/rigid_body.hpp"

namespace monolith {

template <int Dim>
class MonolithicSystem;

/// The measures of `monolith verify` for a candidate x of the system A x = b under the
/// convention above, relative to the right-hand sides as the solver measures them (section 4.2:
/// the MLCP (26) over (tau, p, lambda) given z, the friction LCP (25) given the rest). With
/// w = A x - b; on the MLCP rows S = diag(1 / sqrt(A_ii)) when jacobi_scaled (the solver's
/// MPRGP runs on the Jacobi-scaled MLCP; without contacts PCG does not: S = I), y = S^-1 x,
/// g = S w, scale = ||S (b - A_.4 z)||_inf over those rows; on the z rows (the friction MPRGP
/// runs unscaled) u_k = mu_c max(lambda_c, 0) for contact c of row k,
/// scale_z = ||b4 - A41 tau - A42 p - A43 lambda||_inf and scale_u = max_k u_k:
///   free_residual     = max over tau, p rows |g_i| / scale;
///   complementarity   = max over lambda rows |min(y_i, g_i)| / scale (zero iff lambda >= 0,
///                       w >= 0, lambda w = 0: the natural residual of the LCP);
///   bound_violation   = max over lambda rows max(-y_i, 0) / scale;
///   friction          = max over z rows |z_k - clamp(z_k - w_k, -u_k, u_k)| / scale_z (the
///                       natural residual of the box conditions: zero iff z_k is inside and
///                       w_k = 0, or at a bound with w_k opposing it);
///   cone_violation    = max over z rows max(|z_k| - u_k, 0) / scale_u (the staggered rounds
///                       stop on the relative change of lambda, so the bounds lag by that
///                       fraction of the friction forces);
///   difference        = ||x - x_ref||_inf / ||x_ref||_inf (reported, not judged: with
///                       redundant contacts or enclosed liquid the solution is not unique).
/// passed: the five conditions are <= tolerance.
struct SolutionCheck {
  double free_residual = 0.0, complementarity = 0.0, friction = 0.0;
  double bound_violation = 0.0, cone_violation = 0.0, difference = 0.0;
  bool passed = false;
};

/// A named matrix of the step: file stem, equation of the paper, meaning (with its row and
/// column spaces).
struct ExportedMatrix {
  std::string name, equation, meaning;
  SparseMatrix value;
};

struct ExportedVector {
  std::string name, equation, meaning;
  VectorX value;
};

/// One step's system of eq. (24) with its named parts and the reference solution.
struct SystemExport {
  int dim = 0;
  double dx = 0.0, dt = 0.0;
  double alpha = 0.0;           ///< 1 / dx^Dim (section 4.1)
  double diagonal_boost = 0.0;  ///< gamma of section 4.4.5, already in A33 and A44
  std::string backend;          ///< the scheme's back end ("explicit" or "matrixfree")
  std::string stress_form;      ///< "reduced" (section 4.4.2) or "full"
  int num_tau = 0, num_p = 0, num_lambda = 0, num_z = 0;
  std::vector<ExportedMatrix> matrices;
  std::vector<ExportedVector> vectors;
  /// The reference solution (tau, p, lambda, z) of eq. (24) under the convention above, and how
  /// it was obtained.
  VectorX x;
  std::string x_source;
  /// What check_solution should measure with: tolerance is the solver's stopping tolerance;
  /// jacobi_scaled: the solver measured its residual on the Jacobi-scaled system (MPRGP on the
  /// MLCP), so the checks do too; otherwise (PCG, no contacts) on the unscaled one.
  double tolerance = 0.0;
  bool jacobi_scaled = false;
  /// Matrix-free back end: the largest relative difference between the exported A (assembled by
  /// the explicit twin of the system) and the matrix-free operator, over a few random vectors
  /// (0 under the explicit back end).
  double backend_difference = 0.0;
  /// check_solution of x itself (the staggered friction rounds of the solver stop after
  /// solver.staggered_iterations, so x may miss the tolerance on the z rows).
  SolutionCheck x_check;

  // --- the rows of x -------------------------------------------------------------------------
  /// tau rows: the StressGrid component (0 xx, 1 yy, [2 zz,] then xy[, xz, yz]), its name, where
  /// it lives ("cell", "node", "edge"), its StressGrid DOF index and integer coordinate.
  std::vector<int> tau_component, tau_dof;
  std::vector<std::string> tau_name, tau_location;
  std::vector<std::vector<int>> tau_coord;
  /// p rows: cell index and coordinate.
  std::vector<int> p_cell;
  std::vector<std::vector<int>> p_coord;
  /// lambda rows (one per contact): the two bodies (scene body index; body_b = -1 for a domain
  /// wall, then wall_face = 0 x-, 1 x+, 2 y-, ...), friction coefficient, normal (from b to a),
  /// contact point.
  std::vector<int> contact_body_a, contact_body_b, contact_wall_face;
  VectorX mu;
  std::vector<std::vector<double>> contact_normal, contact_point;
  /// z rows: contact index and tangent direction (0 .. Dim - 2), the unit tangent.
  std::vector<int> z_contact, z_direction;
  std::vector<std::vector<double>> z_tangent;

  int size() const { return num_tau + num_p + num_lambda + num_z; }
  /// The named matrix / vector, nullptr if absent.
  const ExportedMatrix* matrix(const std::string& name) const;
  const ExportedVector* vector(const std::string& name) const;
};

/// Builds the SystemExport of `system` (either back end) for the reference solution `x` (tau, p,
/// lambda, z stacked; size n_tau + n_p + nc + nf). `bodies`, `solids` and `contacts` are what the
/// system was built from (bodies at the step's start pose with v*, SolidWeights of
/// coupling_bodies(bodies), the contacts in ContactSystem order). A33 and A44 carry the diagonal
/// boost (1 + gamma) the solver applies (section 4.4.5), so x solves the exported system. Under the
/// matrix-free back end the matrices come from the explicit twin of the system (the same inputs,
/// Backend::explicit_matrices), checked against the matrix-free operator on random vectors
/// (backend_difference). The fluid-body blocks B^T M_r^-1 B are formed as sparse products: their
/// non-zeros grow with the square of the bodies' surface unknowns (for small and medium scenes).
template <int Dim>
SystemExport export_system(const MonolithicSystem<Dim>& system,
                           const std::vector<RigidBody<Dim>>& bodies,
                           const SolidWeights<Dim>& solids,
                           const std::vector<Contact<Dim>>& contacts, const VectorX& x,
                           double diagonal_boost);

/// Block sizes (n_tau, n_p, nc, nf) and mu per contact describe the rows; x, x_ref and b have
/// A's size (std::invalid_argument otherwise).
SolutionCheck check_solution(const SparseMatrix& a, const VectorX& b, int num_tau, int num_p,
                             int num_lambda, int num_z, const VectorX& mu, const VectorX& x,
                             const VectorX& x_ref, bool jacobi_scaled, double tolerance);

}  // namespace monolith
