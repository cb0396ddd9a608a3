#include "reference/solvers/pcg.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "reference/core/parallel.hpp"

namespace monolith {

namespace {
/// v <- v - sum_k n_k (n_k . v) for an orthonormal null-space basis.
void project_out(const std::vector<VectorX>& basis, VectorX& v) {
  for (const VectorX& n : basis) v -= n.dot(v) * n;
}
double inf_norm(const VectorX& v) {
  return v.size() ? v.lpNorm<Eigen::Infinity>() : 0.0;
}

/// x += alpha p and r -= alpha ap in one pass, returning ||r||_inf (NaN when r has a non-finite
/// entry). Entrywise, each entry written by one thread, the same arithmetic as the Eigen
/// expressions (x_i + alpha p_i, r_i - alpha ap_i), and the maximum is exact in any order: the
/// same bits for any team size. Team size measured (AdaptiveTeam), serial below kParallelMinWork.
double update_solution_and_residual(double alpha, const VectorX& p, const VectorX& ap, VectorX& x,
                                    VectorX& r) {
  const int n = static_cast<int>(x.size());
  static AdaptiveTeam site;
  TeamScope team(site, n);
  double largest = 0.0;
  bool finite = true;
  double* xs = x.data();
  double* rs = r.data();
  const double* ps = p.data();
  const double* aps = ap.data();
#pragma omp parallel for schedule(static) num_threads(team.threads()) if (team.parallel()) \
    reduction(max : largest) reduction(&& : finite)
  for (int i = 0; i < n; ++i) {
    xs[i] = xs[i] + alpha * ps[i];
    const double ri = rs[i] - alpha * aps[i];
    rs[i] = ri;
    const double a = std::abs(ri);
    finite = finite && std::isfinite(ri);
    largest = a > largest ? a : largest;
  }
  return finite ? largest : std::numeric_limits<double>::quiet_NaN();
}

/// p = z + beta p, entrywise (each entry one writer: the same bits for any team size).
void update_direction(const VectorX& z, double beta, VectorX& p) {
  const int n = static_cast<int>(p.size());
  static AdaptiveTeam site;
  TeamScope team(site, n);
  double* ps = p.data();
  const double* zs = z.data();
#pragma omp parallel for schedule(static) num_threads(team.threads()) if (team.parallel())
  for (int i = 0; i < n; ++i) ps[i] = zs[i] + beta * ps[i];
}
}  // namespace

void ssor_precondition(const LinearOperator& a, const VectorX& r, VectorX& z, double omega,
                       const std::vector<char>* active) {
  z.setZero(r.size());
  a.forward_sweep(r, z, omega, active);
  a.backward_sweep(r, z, omega, active);
}

PcgResult pcg_solve(const LinearOperator& a, const VectorX& b, VectorX& x,
                    const PcgSettings& settings) {
  if (!settings.precondition) return pcg_solve(a, b, x, settings, IdentityPreconditioner(a.size()));
  return pcg_solve(a, b, x, settings, SsorPreconditioner(a, settings.omega));
}

PcgResult pcg_solve(const LinearOperator& a, const VectorX& b_in, VectorX& x,
                    const PcgSettings& settings, const Preconditioner& m) {
  PcgResult result;
  const int n = a.size();
  const auto& null_space = a.null_space();
  if (x.size() != n) x.setZero(n);

  // right-hand side restricted to the range of A
  VectorX b = b_in;
  project_out(null_space, b);
  project_out(null_space, x);
  const double b_norm = inf_norm(b);
  if (!std::isfinite(b_norm)) {
    result.breakdown = true;
    result.message = "non-finite right-hand side";
    return result;
  }
  if (b_norm <= settings.zero_rhs) {
    // b = 0, or zero to its round-off (PcgSettings::zero_rhs)
    x.setZero(n);
    result.converged = true;
    return result;
  }

  // initial residual and search direction
  VectorX r(n), z(n), p(n), ap(n);
  a.apply(x, ap);
  r = b - ap;
  project_out(null_space, r);
  auto precondition = [&](const VectorX& res, VectorX& out) {
    m.apply(res, out);
    project_out(null_space, out);
  };
  result.relative_residual = inf_norm(r) / b_norm;
  if (result.relative_residual <= settings.tolerance) {
    result.converged = true;
    return result;
  }
  precondition(r, z);
  p = z;
  double rz = r.dot(z);

  StagnationTest stagnation(settings.stagnation);
  for (int k = 0; k < settings.max_iterations; ++k) {
    // step along p
    a.apply(p, ap);
    const double pap = p.dot(ap);
    if (!std::isfinite(pap) || pap <= 0.0) {
      result.breakdown = true;
      result.message = std::isfinite(pap) ? "p^T A p <= 0 (operator not positive definite)"
                                          : "non-finite value in p^T A p";
      return result;
    }
    const double alpha = rz / pap;
    result.iterations = k + 1;
    if (null_space.empty()) {
      // x and r in one parallel pass with the residual norm
      result.relative_residual = update_solution_and_residual(alpha, p, ap, x, r) / b_norm;
    } else {
      x += alpha * p;
      r -= alpha * ap;
      project_out(null_space, r);
      result.relative_residual = inf_norm(r) / b_norm;
    }
    if (!std::isfinite(result.relative_residual)) {
      result.breakdown = true;
      result.message = "non-finite residual";
      return result;
    }
    if (result.relative_residual <= settings.tolerance) {
      result.converged = true;
      break;
    }
    if (stagnation.stagnated(k + 1, result.relative_residual)) {
      result.stagnated = true;
      break;
    }
    // new conjugate direction
    precondition(r, z);
    const double rz_new = r.dot(z);
    update_direction(z, rz_new / rz, p);
    rz = rz_new;
  }
  project_out(null_space, x);
  return result;
}

StagnationTest::StagnationTest(const StagnationRule& rule)
    : rule_(rule), best_now_(std::numeric_limits<double>::infinity()) {
  if (rule_.window > 0) best_.assign(rule_.window + 1, std::numeric_limits<double>::infinity());
}

bool StagnationTest::stagnated(int iteration, double relative_residual) {
  if (rule_.window <= 0) return false;
  best_now_ = std::min(best_now_, relative_residual);
  const int w = rule_.window + 1;
  best_[iteration % w] = best_now_;
  if (iteration < rule_.window) return false;
  // the slot of iteration - window (iteration 0 = the start: no best yet, infinity)
  const double before = iteration == rule_.window ? std::numeric_limits<double>::infinity()
                                                  : best_[(iteration - rule_.window) % w];
  return best_now_ > rule_.factor * before;
}

}  // namespace monolith
