// Notebook 06: MPRGP step by step (section 4.3; Dostal & Schoberl 2005) on small box QPs: the
// kind of every step (CG, expansion, proportioning), the iterates, the free and active sets, the
// final KKT conditions, and the iterate path over the objective's contours.
//
// Run: build/notebooks/notebook_06_mprgp --out DIR
#include <Eigen/Dense>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

#include "notebooks_cpp/notebook.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/viz/plot.hpp"

using namespace monolith;

namespace {

const double inf = std::numeric_limits<double>::infinity();

std::string vec_str(const VectorX& v) {
  std::ostringstream s;
  s << "(" << std::fixed << std::setprecision(5);
  for (int i = 0; i < v.size(); ++i) s << (i ? ", " : "") << v[i];
  s << ")";
  return s.str();
}

/// "F" free, "L" at the lower bound, "U" at the upper bound, "X" fixed (lower = upper).
std::string sets_str(const VectorX& x, const VectorX& l, const VectorX& u) {
  std::string s;
  for (int i = 0; i < x.size(); ++i)
    s += l[i] == u[i] ? 'X' : x[i] <= l[i] ? 'L' : x[i] >= u[i] ? 'U' : 'F';
  return s;
}

const char* kind_str(MprgpStep k) {
  switch (k) {
    case MprgpStep::cg: return "CG";
    case MprgpStep::expansion: return "expansion";
    default: return "proportioning";
  }
}

/// Runs MPRGP, prints one table row per step, returns the path of iterates.
std::vector<VectorX> run_and_print(notebook::Notebook& nb, const Eigen::MatrixXd& a, const VectorX& b,
                                   const VectorX& l, const VectorX& u, VectorX& x, bool precondition,
                                   MprgpResult& result) {
  SparseMatrixOperator op(SparseMatrix(a.sparseView()));
  MprgpSettings s;
  s.tolerance = 1e-12;
  s.precondition = precondition;
  std::vector<VectorX> path{x.cwiseMax(l).cwiseMin(u)};
  std::ostringstream t;
  t << "| step | kind | x | g = A x - b | sets (F free, L lower, U upper) |\n|---|---|---|---|---|\n";
  t << "| 0 | start (projected) | " << vec_str(path[0]) << " | " << vec_str(a * path[0] - b) << " | "
    << sets_str(path[0], l, u) << " |\n";
  int step = 0;
  result = mprgp_solve(op, b, l, u, x, s, [&](MprgpStep k, const VectorX& xi, const VectorX& g) {
    path.push_back(xi);
    t << "| " << ++step << " | " << kind_str(k) << " | " << vec_str(xi) << " | " << vec_str(g) << " | "
      << sets_str(xi, l, u) << " |\n";
  });
  nb.md(t.str());
  std::ostringstream r;
  r << "Result: " << (result.converged ? "converged" : "not converged") << " after " << result.iterations
    << " steps (" << result.cg_steps << " CG, " << result.expansion_steps << " expansion, "
    << result.proportioning_steps << " proportioning), ||g^P||_inf / ||b||_inf = " << std::scientific
    << std::setprecision(2) << result.relative_residual << ", ||A|| estimate " << std::fixed
    << std::setprecision(4) << result.norm_estimate << ".";
  nb.md(r.str());
  return path;
}

/// Checks primal feasibility, the dual signs and complementarity at x.
void check_kkt(notebook::Notebook& nb, const Eigen::MatrixXd& a, const VectorX& b, const VectorX& l,
               const VectorX& u, const VectorX& x) {
  const VectorX g = a * x - b;
  double primal = 0, dual = 0, compl_ = 0;
  for (int i = 0; i < x.size(); ++i) {
    primal = std::max({primal, l[i] - x[i], x[i] - u[i]});
    if (l[i] == u[i]) continue;
    if (x[i] <= l[i])
      dual = std::max(dual, -g[i]);
    else if (x[i] >= u[i])
      dual = std::max(dual, g[i]);
    else
      dual = std::max(dual, std::abs(g[i]));
    if (std::isfinite(l[i])) compl_ = std::max(compl_, (x[i] - l[i]) * std::max(g[i], 0.0));
    if (std::isfinite(u[i])) compl_ = std::max(compl_, (u[i] - x[i]) * std::max(-g[i], 0.0));
  }
  nb.check("primal feasibility max(l - x, x - u, 0)", primal, 0.0);
  nb.check("dual sign (g >= 0 at lower, <= 0 at upper, = 0 free), worst violation", dual, 1e-11);
  nb.check("complementarity max (x - l) g^+ , (u - x) g^-", compl_, 1e-11);
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "06 MPRGP step by step");

  nb.md("MPRGP minimises f(x) = 1/2 x^T A x - b^T x on a box l <= x <= u. Every step is one of: "
        "a **CG** step (conjugate gradients inside the current face: free variables move, active "
        "ones stay), an **expansion** step (the CG step would leave the box: go to the boundary, "
        "then take a projected gradient step of fixed length alpha_bar = 1.9 / ||A|| on the free "
        "variables, which can add several variables to the active set at once), or a "
        "**proportioning** step (the chopped gradient of the active variables is large compared "
        "with the free gradient: step along it to release variables from their bounds). "
        "See docs/mprgp.md for the formulas.");

  // --- 2 variables with a figure --------------------------------------------------------------
  nb.md("## Two variables\n"
        "A = [[2, 0.9], [0.9, 1]], b = (3.5, -0.4), box [0, 2] x [0, 1.2]. The unconstrained "
        "minimiser A^-1 b lies outside the box (x_1 < 0). The start x0 = (0, 1.2) sits in a corner "
        "where the gradient points into the box for x_0: a proportioning step releases it.");
  Eigen::MatrixXd a(2, 2);
  a << 2.0, 0.9, 0.9, 1.0;
  const VectorX b = (VectorX(2) << 3.5, -0.4).finished();
  const VectorX l = (VectorX(2) << 0.0, 0.0).finished(), u = (VectorX(2) << 2.0, 1.2).finished();
  VectorX x = (VectorX(2) << 0.0, 1.2).finished();
  MprgpResult r2;
  const std::vector<VectorX> path = run_and_print(nb, a, b, l, u, x, false, r2);
  nb.check_true("converged", r2.converged);
  check_kkt(nb, a, b, l, u, x);
  // the exact solution: x_1 at its lower bound with g_1 = 0.9 x_0 + 0.4 > 0, x_0 = b_0 / A_00 =
  // 1.75 free (inside [0, 2])
  const VectorX exact = (VectorX(2) << 3.5 / 2.0, 0.0).finished();
  nb.check("|x - exact|_inf (exact: x_1 = 0 active, x_0 = b_0 / A_00 = 1.75 free)",
           (x - exact).lpNorm<Eigen::Infinity>(), 1e-10);

  // figure: contours of f (ellipses around the unconstrained minimiser), the box, the path
  PlotSpec spec;
  spec.title = "MPRGP iterates over the contours of f";
  spec.x_label = "x0";
  spec.y_label = "x1";
  spec.width = 640;
  spec.height = 560;
  spec.x_min = -0.5;
  spec.x_max = 3.7;
  spec.y_min = -3.7;
  spec.y_max = 3.2;  // room for the legend above the box
  const VectorX centre = a.ldlt().solve(b);
  const double f_min = -0.5 * b.dot(centre);
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(a);
  const Eigen::MatrixXd a_inv_sqrt = es.operatorInverseSqrt();
  const double f_start = 0.5 * path[0].dot(a * path[0]) - b.dot(path[0]);
  for (int k = 1; k <= 10; ++k) {
    // f = level: (x - c)^T A (x - c) = 2 (level - f_min); the outermost contour passes the start
    const double level = f_min + (f_start - f_min) * (k * k) / 100.0;
    PlotSeries c;
    c.color = Rgb{170, 170, 200};
    c.line_width = 1.0;
    for (int t = 0; t <= 200; ++t) {
      const double th = 2.0 * M_PI * t / 200.0;
      const Eigen::Vector2d p = centre + std::sqrt(2.0 * (level - f_min)) * a_inv_sqrt * Eigen::Vector2d(std::cos(th), std::sin(th));
      c.x.push_back(p[0]);
      c.y.push_back(p[1]);
    }
    if (k == 1) c.label = "contours of f";
    spec.series.push_back(c);
  }
  PlotSeries box;
  box.label = "box";
  box.color = Rgb{60, 60, 60};
  box.x = {l[0], u[0], u[0], l[0], l[0]};
  box.y = {l[1], l[1], u[1], u[1], l[1]};
  spec.series.push_back(box);
  PlotSeries iterates;
  iterates.label = "iterates";
  iterates.color = Rgb{200, 60, 40};
  iterates.marker = Marker::circle;
  for (const VectorX& p : path) {
    iterates.x.push_back(p[0]);
    iterates.y.push_back(p[1]);
  }
  spec.series.push_back(iterates);
  PlotSeries unconstrained;
  unconstrained.label = "unconstrained minimiser";
  unconstrained.line = false;
  unconstrained.marker = Marker::cross;
  unconstrained.marker_size = 6.0;
  unconstrained.x = {centre[0]};
  unconstrained.y = {centre[1]};
  spec.series.push_back(unconstrained);
  nb.figure("mprgp_path.ppm", plot_lines(spec), "MPRGP iterate path on a 2-variable box QP");

  // --- 3 variables: a friction-like box with a fixed variable --------------------------------
  nb.md("## Three variables, with and without the SSOR preconditioner\n"
        "A contact-like matrix, a two-sided box -mu lambda <= z <= mu lambda (mu lambda = 0.6, 2.5, 2) and a free "
        "start at 0. Both runs must reach the same point; the preconditioned run applies SSOR to "
        "the free rows only (A_FF), restarting CG whenever the face changes.");
  Eigen::MatrixXd a3(3, 3);
  a3 << 2.0, 0.8, -0.3, 0.8, 1.5, 0.6, -0.3, 0.6, 1.2;
  const VectorX b3 = (VectorX(3) << 1.0, -0.9, 0.1).finished();
  const VectorX u3 = (VectorX(3) << 0.6, 2.5, 2.0).finished(), l3 = -u3;
  VectorX x_plain = VectorX::Zero(3), x_pre = VectorX::Zero(3);
  MprgpResult rp, rs;
  nb.md("### Without preconditioner");
  run_and_print(nb, a3, b3, l3, u3, x_plain, false, rp);
  nb.md("### With SSOR on the free set");
  run_and_print(nb, a3, b3, l3, u3, x_pre, true, rs);
  nb.check_true("both converged", rp.converged && rs.converged);
  nb.check("|x_plain - x_ssor|_inf", (x_plain - x_pre).lpNorm<Eigen::Infinity>(), 1e-10);
  check_kkt(nb, a3, b3, l3, u3, x_pre);

  // --- all bounds infinite: CG -----------------------------------------------------------------
  nb.md("## No bounds: MPRGP is CG\n"
        "With l = -inf and u = +inf every variable is free, the chopped gradient is zero, no step "
        "can leave the box: only CG steps, at most n of them in exact arithmetic.");
  VectorX x_cg = VectorX::Zero(3);
  MprgpResult rc;
  run_and_print(nb, a3, b3, VectorX::Constant(3, -inf), VectorX::Constant(3, inf), x_cg, false, rc);
  nb.check_true("only CG steps", rc.expansion_steps == 0 && rc.proportioning_steps == 0 && rc.cg_steps <= 4);
  nb.check("|x - A^-1 b|_inf", (x_cg - a3.ldlt().solve(b3)).lpNorm<Eigen::Infinity>(), 1e-10);
  return nb.finish();
}
