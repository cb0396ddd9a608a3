#include "reference/solvers/mprgp.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

#include "reference/solvers/pcg.hpp"

namespace monolith {

namespace {

double inf_norm(const VectorX& v) { return v.size() ? v.lpNorm<Eigen::Infinity>() : 0.0; }

/// The box of the QP with the free/active classification of an iterate. A variable with
/// lower == upper is fixed: never free, and its gradient is never chopped (any sign is optimal).
struct BoxSet {
  const VectorX& lower;
  const VectorX& upper;

  bool at_lower(const VectorX& x, int i) const { return x[i] <= lower[i] && lower[i] < upper[i]; }
  bool at_upper(const VectorX& x, int i) const { return x[i] >= upper[i] && lower[i] < upper[i]; }
  bool free(const VectorX& x, int i) const { return lower[i] < x[i] && x[i] < upper[i]; }

  /// P_Omega(x): the projection onto the box.
  void project(VectorX& x) const { x = x.cwiseMax(lower).cwiseMin(upper); }

  /// The free set F(x) as a row mask (for the masked SSOR sweeps).
  void free_mask(const VectorX& x, std::vector<char>& mask) const {
    mask.resize(x.size());
    for (int i = 0; i < x.size(); ++i) mask[i] = free(x, i) ? 1 : 0;
  }

  /// phi(x): the free gradient, g on F(x), 0 elsewhere.
  void free_gradient(const VectorX& x, const VectorX& g, VectorX& phi) const {
    phi.resize(x.size());
    for (int i = 0; i < x.size(); ++i) phi[i] = free(x, i) ? g[i] : 0.0;
  }

  /// beta(x): the chopped gradient, min(g_i, 0) at a lower bound, max(g_i, 0) at an upper bound,
  /// 0 on free and fixed variables. g^P = phi + beta is the projected gradient.
  void chopped_gradient(const VectorX& x, const VectorX& g, VectorX& beta) const {
    beta.resize(x.size());
    for (int i = 0; i < x.size(); ++i) {
      if (at_lower(x, i))
        beta[i] = std::min(g[i], 0.0);
      else if (at_upper(x, i))
        beta[i] = std::max(g[i], 0.0);
      else
        beta[i] = 0.0;
    }
  }

  /// phi~(x) . phi(x) with the reduced free gradient phi~_i = min((x_i - l_i) / alpha_bar, g_i)
  /// for g_i > 0 and max((x_i - u_i) / alpha_bar, g_i) for g_i < 0 (i free).
  double reduced_free_product(const VectorX& x, const VectorX& phi, double alpha_bar) const {
    double s = 0.0;
    for (int i = 0; i < x.size(); ++i) {
      if (phi[i] > 0.0)
        s += std::min((x[i] - lower[i]) / alpha_bar, phi[i]) * phi[i];
      else if (phi[i] < 0.0)
        s += std::max((x[i] - upper[i]) / alpha_bar, phi[i]) * phi[i];
    }
    return s;
  }

  /// The largest alpha with l <= x - alpha d <= u (infinite when d points into no bound).
  double feasible_step(const VectorX& x, const VectorX& d) const {
    double alpha = std::numeric_limits<double>::infinity();
    for (int i = 0; i < x.size(); ++i) {
      if (d[i] > 0.0)
        alpha = std::min(alpha, (x[i] - lower[i]) / d[i]);
      else if (d[i] < 0.0)
        alpha = std::min(alpha, (x[i] - upper[i]) / d[i]);
    }
    return std::max(alpha, 0.0);
  }
};

}  // namespace

int sweep_diagonal_mismatch(const LinearOperator& a, std::vector<char>& mismatch) {
  const int n = a.size();
  mismatch.assign(n, 0);
  if (n == 0) return 0;
  const VectorX diagonal = a.diagonal(), swept = a.sweep_diagonal();
  int count = 0;
  for (int i = 0; i < n; ++i) {
    if (!(diagonal[i] > 0.0)) continue;
    // a row the sweep leaves alone (d_i <= 0) or relaxes with d_i < A_ii / 2
    if (!(swept[i] >= 0.5 * diagonal[i])) {
      mismatch[i] = 1;
      ++count;
    }
  }
  return count;
}

double estimate_operator_norm(const LinearOperator& a, int iterations) {
  const int n = a.size();
  if (n == 0) return 1.0;
  // a fixed start vector with all components non-zero and unequal
  VectorX v(n), av(n);
  for (int i = 0; i < n; ++i) v[i] = 1.0 + 0.5 * std::sin(1.0 + 0.7 * i);
  v.normalize();
  double estimate = 0.0;
  for (int k = 0; k < std::max(iterations, 1); ++k) {
    a.apply(v, av);
    estimate = av.norm();  // ||A v|| with ||v|| = 1: a lower bound of ||A||_2
    if (!(estimate > 0.0) || !std::isfinite(estimate)) break;
    v = av / estimate;
  }
  if (!(estimate > 0.0) || !std::isfinite(estimate)) return 1.0;
  return 1.05 * estimate;
}

MprgpResult mprgp_solve(const LinearOperator& a, const VectorX& b, const VectorX& lower,
                        const VectorX& upper, VectorX& x, const MprgpSettings& settings,
                        const MprgpObserver& observer) {
  const int n = a.size();
  if (b.size() != n || lower.size() != n || upper.size() != n)
    throw std::invalid_argument("mprgp_solve: size mismatch between A, b and the bounds");
  for (int i = 0; i < n; ++i)
    if (!(lower[i] <= upper[i])) throw std::invalid_argument("mprgp_solve: lower > upper (or NaN bound)");
  if (settings.preconditioner && settings.preconditioner->size() != n)
    throw std::invalid_argument("mprgp_solve: preconditioner of the wrong size");
  if (settings.face_preconditioner && settings.face_preconditioner->size() != n)
    throw std::invalid_argument("mprgp_solve: face preconditioner of the wrong size");

  // null space of A: only on unbounded variables, projected out of b, x and z (as in pcg_solve)
  const std::vector<VectorX>& null_space = a.null_space();
  for (const VectorX& v : null_space) {
    if (v.size() != n) throw std::invalid_argument("mprgp_solve: null-space vector of the wrong size");
    for (int i = 0; i < n; ++i)
      if (v[i] != 0.0 && (std::isfinite(lower[i]) || std::isfinite(upper[i])))
        throw std::invalid_argument("mprgp_solve: a null-space vector touches a bounded variable");
  }
  auto project_out = [&](VectorX& v) {
    for (const VectorX& basis : null_space) v -= basis.dot(v) * basis;
  };

  MprgpResult result;
  const BoxSet box{lower, upper};
  if (x.size() != n) x.setZero(n);
  box.project(x);
  project_out(x);
  VectorX b_range;
  if (!null_space.empty()) {
    b_range = b;
    project_out(b_range);
  }
  const VectorX& rhs = null_space.empty() ? b : b_range;

  // stopping scale and the fixed step length alpha_bar in (0, 2 / ||A||]
  const double b_norm = inf_norm(rhs);
  if (!std::isfinite(b_norm)) {
    result.breakdown = true;
    result.message = "non-finite right-hand side";
    return result;
  }
  const double scale = b_norm > 0.0 ? b_norm : 1.0;
  result.norm_estimate = settings.norm_estimate > 0.0 ? settings.norm_estimate
                                                      : estimate_operator_norm(a, settings.power_iterations);
  const double alpha_bar = settings.step_scale / result.norm_estimate;
  const double gamma2 = settings.gamma_proportioning * settings.gamma_proportioning;

  // state: gradient g = A x - b, free/chopped gradients, free mask, direction p
  VectorX g(n), phi(n), beta(n), z(n), p(n), ap(n), gp(n), x_half;
  std::vector<char> mask, new_mask;
  auto exact_gradient = [&]() {
    a.apply(x, g);
    g -= rhs;
  };
  auto classify = [&]() {
    box.free_gradient(x, g, phi);
    box.chopped_gradient(x, g, beta);
    box.free_mask(x, mask);
  };
  // rows the sweeps relax with a diagonal far below A's (docs/mprgp.md, "Rows the sweeps do not
  // see"): they leave the SSOR block and get the Jacobi step g_i / A_ii instead
  std::vector<char> jacobi_row;
  VectorX a_diagonal;
  int num_jacobi_rows = 0;
  if (settings.precondition && !settings.preconditioner && !settings.face_preconditioner) {
    a_diagonal = a.diagonal();
    num_jacobi_rows = sweep_diagonal_mismatch(a, jacobi_row);
  }
  std::vector<char> sweep_mask;
  // z = M_F^-1 g_F: SSOR on the principal submatrix A_FF of the free set (zero off F), block
  // diagonal with the Jacobi rows
  auto precondition = [&]() {
    if (!settings.precondition) {
      z = phi;
    } else if (settings.face_preconditioner) {
      // z_F = M_FF^-1 g_F, zero off F (phi is g on F)
      settings.face_preconditioner->apply_in_face(phi, mask, z);
      for (int i = 0; i < n; ++i)
        if (!mask[i]) z[i] = 0.0;
    } else if (settings.preconditioner) {
      // M block diagonal with a diagonal block on every bounded row: M^-1 phi masked to F is
      // M_FF^-1 g_F
      settings.preconditioner->apply(phi, z);
      for (int i = 0; i < n; ++i)
        if (!mask[i]) z[i] = 0.0;
    } else if (num_jacobi_rows == 0) {
      ssor_precondition(a, g, z, settings.omega, &mask);
    } else {
      sweep_mask = mask;
      for (int i = 0; i < n; ++i)
        if (jacobi_row[i]) sweep_mask[i] = 0;
      ssor_precondition(a, g, z, settings.omega, &sweep_mask);
      for (int i = 0; i < n; ++i)
        if (jacobi_row[i] && mask[i]) z[i] = a_diagonal[i] > 0.0 ? g[i] / a_diagonal[i] : 0.0;
    }
    project_out(z);
  };
  // new free set or exact gradient: reclassify, precondition, restart the CG directions at z
  auto restart = [&]() {
    classify();
    precondition();
    p = z;
  };
  auto fail = [&](const std::string& why) {
    result.breakdown = true;
    result.message = why;
  };
  // a search direction d needs d^T A d > 0 and finite; otherwise the solve stops, naming it
  auto positive_curvature = [&](double curvature, const std::string& name) {
    if (std::isfinite(curvature) && curvature > 0.0) return true;
    fail(std::isfinite(curvature) ? name + " <= 0 (operator not positive definite)"
                                  : "non-finite value in " + name);
    return false;
  };

  exact_gradient();
  restart();

  StagnationTest stagnation(settings.stagnation);
  bool verified = true;  // g is exact (not a recurrence) at the next convergence test
  for (;;) {
    // stopping rule on the projected gradient g^P = phi + beta
    gp = phi + beta;
    result.relative_residual = inf_norm(gp) / scale;
    if (!std::isfinite(result.relative_residual)) {
      fail("non-finite projected gradient");
      break;
    }
    if (result.relative_residual <= settings.tolerance) {
      if (verified) {
        result.converged = true;
        break;
      }
      // recompute g without the recurrence's drift, test again, restart the directions
      exact_gradient();
      restart();
      verified = true;
      continue;
    }
    verified = false;
    if (result.iterations >= settings.max_iterations) break;
    if (result.iterations > 0 && stagnation.stagnated(result.iterations, result.relative_residual)) {
      result.stagnated = true;
      break;
    }
    ++result.iterations;

    MprgpStep kind;
    if (beta.squaredNorm() <= gamma2 * box.reduced_free_product(x, phi, alpha_bar)) {
      // x is proportional: trial conjugate gradient step along p (supported on F)
      a.apply(p, ap);
      const double pap = p.dot(ap);
      if (!positive_curvature(pap, "p^T A p")) break;
      const double alpha_cg = g.dot(p) / pap;
      const double alpha_f = box.feasible_step(x, p);
      if (alpha_cg < alpha_f) {
        // conjugate gradient step; the free set is unchanged
        kind = MprgpStep::cg;
        ++result.cg_steps;
        x -= alpha_cg * p;
        g -= alpha_cg * ap;
        box.project(x);  // guards against rounding past a bound
        box.free_mask(x, new_mask);
        const bool same_face = new_mask == mask;
        classify();
        precondition();
        if (same_face) {
          p = z - (z.dot(ap) / pap) * p;
        } else {
          p = z;
        }
      } else {
        // expansion step: the feasible half step, then a fixed-step projected gradient step
        kind = MprgpStep::expansion;
        ++result.expansion_steps;
        x -= alpha_f * p;
        g -= alpha_f * ap;
        box.project(x);
        box.free_gradient(x, g, phi);
        bool expanded = false;
        if (settings.adaptive_expansion) {
          // opt-in: the exact minimiser alpha_opt = phi^T phi / phi^T A phi along -phi when it is
          // longer than alpha_bar, kept only if the projected point lowers f below f(x_half)
          a.apply(phi, ap);
          const double phi_a_phi = phi.dot(ap);
          const double alpha_opt = phi_a_phi > 0.0 ? phi.squaredNorm() / phi_a_phi : 0.0;
          if (alpha_opt > alpha_bar && std::isfinite(alpha_opt)) {
            const double f_half = 0.5 * x.dot(g) - 0.5 * rhs.dot(x);  // f = 1/2 x^T (g + b) - b^T x
            x_half = x;
            x -= alpha_opt * phi;
            box.project(x);
            exact_gradient();
            expanded = 0.5 * x.dot(g) - 0.5 * rhs.dot(x) < f_half;
            if (!expanded) x = x_half;
          }
        }
        if (!expanded) {
          x -= alpha_bar * phi;
          box.project(x);
          exact_gradient();
        }
        restart();
      }
    } else {
      // proportioning step along the chopped gradient (releases variables from their bounds)
      kind = MprgpStep::proportioning;
      ++result.proportioning_steps;
      a.apply(beta, ap);
      const double dad = beta.dot(ap);
      if (!positive_curvature(dad, "d^T A d")) break;
      const double alpha_cg = g.dot(beta) / dad;
      // with two-sided bounds the step may reach the opposite bound: stop there
      const double alpha_f = box.feasible_step(x, beta);
      if (alpha_cg < alpha_f) {
        x -= alpha_cg * beta;
        g -= alpha_cg * ap;
        box.project(x);
      } else {
        x -= alpha_f * beta;
        box.project(x);
        exact_gradient();
      }
      restart();
    }
    if (observer) observer(kind, x, g);
  }
  project_out(x);  // removes the drift of the recurrences along the null space
  return result;
}

// --- DiagonalBoost ------------------------------------------------------------------------------

DiagonalBoost::DiagonalBoost(const LinearOperator& a, double gamma)
    : a_(a), gamma_(gamma), diagonal_(a.diagonal()) {
  if (!(gamma >= 0.0)) throw std::invalid_argument("DiagonalBoost: gamma must be >= 0");
}

int DiagonalBoost::size() const { return a_.size(); }

void DiagonalBoost::apply(const VectorX& x, VectorX& y) const {
  a_.apply(x, y);
  y += gamma_ * diagonal_.cwiseProduct(x);
}

VectorX DiagonalBoost::diagonal() const { return (1.0 + gamma_) * diagonal_; }

VectorX DiagonalBoost::shifted_rhs(const VectorX& rhs, const VectorX& x) const {
  // rhs - gamma diag(A) x, with x the values at the start of the sweep
  return rhs - gamma_ * diagonal_.cwiseProduct(x);
}

void DiagonalBoost::forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                  const std::vector<char>* active) const {
  const VectorX shifted = shifted_rhs(rhs, x);
  a_.forward_sweep(shifted, x, omega / (1.0 + gamma_), active);
}

void DiagonalBoost::backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                   const std::vector<char>* active) const {
  const VectorX shifted = shifted_rhs(rhs, x);
  a_.backward_sweep(shifted, x, omega / (1.0 + gamma_), active);
}

// --- ColouredSparseOperator ---------------------------------------------------------------------

ColouredSparseOperator::ColouredSparseOperator(SparseMatrix a, Colouring colours,
                                               std::vector<VectorX> null_space)
    : a_(std::move(a)), colours_(std::move(colours)), null_space_(std::move(null_space)) {
  if (a_.rows() != a_.cols()) throw std::invalid_argument("ColouredSparseOperator: matrix not square");
  a_.makeCompressed();
  diagonal_ = a_.diagonal();
  if (!is_proper_colouring(matrix_adjacency(a_), colours_))
    throw std::invalid_argument(
        "ColouredSparseOperator: the colouring must cover every row once and no two coupled rows "
        "may share a colour");
}

int ColouredSparseOperator::size() const { return static_cast<int>(a_.rows()); }

void ColouredSparseOperator::apply(const VectorX& x, VectorX& y) const {
  sparse_row_product(a_, x, y);
}

VectorX ColouredSparseOperator::diagonal() const { return diagonal_; }

double ColouredSparseOperator::off_diagonal_product(int i, const VectorX& x) const {
  // stored zeros are skipped: the colouring ignores them, so their x_j may be written by another
  // thread of the same colour at this moment
  double off = 0.0;
  for (SparseMatrix::InnerIterator it(a_, i); it; ++it)
    if (it.col() != i && it.value() != 0.0) off += it.value() * x[it.col()];
  return off;
}

void ColouredSparseOperator::forward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                           const std::vector<char>* active) const {
  // colours in order; the rows of one colour read only other colours' values
  colour_sweep(colours_.colours, true, false, diagonal_, rhs, x, omega, active,
               [&](int i) { return off_diagonal_product(i, x); });
}

void ColouredSparseOperator::backward_sweep(const VectorX& rhs, VectorX& x, double omega,
                                            const std::vector<char>* active) const {
  // colours and rows in reverse order: the transpose of the forward sweep (symmetric SSOR)
  colour_sweep(colours_.colours, true, true, diagonal_, rhs, x, omega, active,
               [&](int i) { return off_diagonal_product(i, x); });
}

MprgpSettings with_norm_estimate(const LinearOperator& a, MprgpSettings settings) {
  if (!(settings.norm_estimate > 0.0))
    settings.norm_estimate = estimate_operator_norm(a, settings.power_iterations);
  return settings;
}

}  // namespace monolith
