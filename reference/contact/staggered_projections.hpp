#pragma once
/// \file staggered_projections.hpp
/// The staggered projections of section 4.2 (Kaufman et al. 2008) written once: the outer loop
/// that alternates the friction QP (25) with the normal solve, the pyramid bounds of eq. (14) it
/// gives the friction QP, the relative change of lambda that stops it, and the MPRGP operators of
/// the contact-only QPs (A33, A44 coloured and boosted). Every friction loop of the library runs
/// through staggered_rounds:
///   - solve_staggered_projections (contact_system.hpp): bodies without liquid;
///   - the contact solve of the partitioned schemes (coupled_schemes.cpp), for a fixed x_f;
///   - solve_pvc_unified (monolithic_system.hpp): the normal solve there is the MLCP (26) over
///     (tau, p, lambda).
/// What differs between them is what a "normal solve" and a "friction solve" are (their
/// right-hand sides, operators and bookkeeping), so the loop takes both as callables.

#include <algorithm>
#include <memory>

#include "reference/contact/contact_system.hpp"
#include "reference/core/common.hpp"
#include "reference/solvers/colouring.hpp"
#include "reference/solvers/mprgp.hpp"

namespace monolith {

/// ||next - previous||_inf / ||next||_inf, the denominator at least 1e-300 (0 for empty vectors):
/// the change of lambda that stops the staggered rounds (and of x_f in the iterative schemes).
inline double relative_change(const VectorX& next, const VectorX& previous) {
  if (next.size() == 0) return 0.0;
  return (next - previous).lpNorm<Eigen::Infinity>() /
         std::max(next.lpNorm<Eigen::Infinity>(), 1e-300);
}

/// The symmetric pyramid of eq. (14) for the friction QP (25): for contact c and each of its
/// Dim - 1 friction rows, -mu_c max(lambda_c, 0) <= z <= mu_c max(lambda_c, 0). lower and upper
/// are resized to (Dim - 1) nc. (lambda from an MPRGP solve is never negative, where the clamp
/// changes nothing; it keeps the box non-empty for a warm start given from outside.)
template <int Dim>
void friction_bounds(const VectorX& mu, const VectorX& lambda, VectorX& lower, VectorX& upper) {
  const int nc = static_cast<int>(mu.size());
  lower.resize((Dim - 1) * nc);
  upper.resize((Dim - 1) * nc);
  for (int c = 0; c < nc; ++c)
    for (int j = 0; j < Dim - 1; ++j) {
      const double bound = mu[c] * std::max(lambda[c], 0.0);
      lower[(Dim - 1) * c + j] = -bound;
      upper[(Dim - 1) * c + j] = bound;
    }
}

/// What staggered_rounds did.
struct StaggeredRounds {
  int rounds = 0;            ///< friction-normal rounds performed
  double last_change = 0.0;  ///< relative change of lambda in the last round (0 if none)
};

/// The outer loop of the staggered projections: rounds of
///   eq. (25): the friction QP with the pyramid bounds of the current lambda (solve_friction(
///             lower, upper)), then
///   eq. (26) (or its contact-only part, eq. (16)): the normal solve given z (solve_normal()),
/// until lambda changes by <= tolerance (relative_change) or `max_normal_solves` normal solves
/// are reached, counting `normal_solves_done` solves the caller ran before the loop (PVC-unified
/// starts with (26) at z = 0 and so runs at most max_normal_solves - 1 rounds). At least one
/// round when normal_solves_done = 0. Always ends on the normal solve. `lambda()` returns the
/// current normal forces (nc), `mu` the friction coefficients per contact.
template <int Dim, class Lambda, class FrictionSolve, class NormalSolve>
StaggeredRounds staggered_rounds(const VectorX& mu, int max_normal_solves, int normal_solves_done,
                                 double tolerance, Lambda lambda, FrictionSolve solve_friction,
                                 NormalSolve solve_normal) {
  StaggeredRounds out;
  VectorX lower, upper;
  for (int k = normal_solves_done; k < std::max(1, max_normal_solves); ++k) {
    const VectorX previous = lambda();
    friction_bounds<Dim>(mu, previous, lower, upper);
    solve_friction(lower, upper);
    solve_normal();
    ++out.rounds;
    out.last_change = relative_change(lambda(), previous);
    if (out.last_change <= tolerance) break;
  }
  return out;
}

/// The MPRGP operators of the contact-only QPs of one ContactSystem, built once for all the
/// staggered rounds: A33 with SSOR sweeps over Welsh-Powell colours of the contact graph, its
/// diagonal scaled by (1 + gamma) (section 4.4.5), and, when some mu > 0 and bodies carry DOFs,
/// A44 with the colouring expanded to the (Dim - 1) rows of each contact; each with the MPRGP
/// settings carrying ||A|| (estimated once rather than in every solve).
template <int Dim>
class ContactQpOperators {
 public:
  ContactQpOperators(const ContactSystem<Dim>& system, const StaggeredSettings& settings);
  ContactQpOperators(const ContactQpOperators&) = delete;
  ContactQpOperators& operator=(const ContactQpOperators&) = delete;

  /// Some contact has mu > 0 and there are body DOFs: the friction QP is solved.
  bool friction() const { return friction_; }
  const LinearOperator& normal() const { return *a33_boosted_; }
  const LinearOperator& tangential() const { return *a44_boosted_; }
  const MprgpSettings& normal_settings() const { return normal_settings_; }
  const MprgpSettings& friction_settings() const { return friction_settings_; }
  /// lambda >= 0: the bounds of the normal QP, nc.
  const VectorX& normal_lower() const { return zero_; }
  const VectorX& normal_upper() const { return infinity_; }

 private:
  bool friction_ = false;
  std::unique_ptr<ColouredSparseOperator> a33_, a44_;
  std::unique_ptr<DiagonalBoost> a33_boosted_, a44_boosted_;
  MprgpSettings normal_settings_, friction_settings_;
  VectorX zero_, infinity_;
};

}  // namespace monolith
