// Notebook 09: staggered projections with friction (section 4.2, eqs. (25)-(26)): a box sliding
// on the floor of a tank of viscous liquid, the MLCP (26) over (tau, p, lambda) and the friction
// LCP (25) over z alternated by hand with MPRGP, the change of lambda and z per round, the final
// KKT conditions (Signorini, the friction pyramid, maximal dissipation), the same by
// solve_pvc_unified, a sticking box, and the convergence plot.
//
// Run: build/notebooks/notebook_09_staggered_projections --out DIR
#include <Eigen/Dense>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

#include "notebooks_cpp/coupled_step.hpp"
#include "notebooks_cpp/notebook.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/viz/plot.hpp"

using namespace monolith;
using nlohmann::json;

namespace {

constexpr double kRho = 1000.0, kEta = 1.0, kDt = 0.01, kMu = 0.5;
const double kInf = std::numeric_limits<double>::infinity();

std::string sci(double x) {
  std::ostringstream s;
  s << std::scientific << std::setprecision(3) << x;
  return s.str();
}

std::string vec_str(const VectorX& v) {
  std::ostringstream s;
  s << "(" << std::setprecision(6);
  for (int i = 0; i < v.size(); ++i) s << (i ? ", " : "") << v[i];
  s << ")";
  return s.str();
}

/// A 12 x 12 tank of liquid up to y = 0.35 m with a box (0.3 m x 0.2 m, density 2000) on the floor,
/// its bottom 0.12 dx below the floor line (0.02 dx beyond the margin), sliding to the right at `speed`; friction mu = 0.5
/// with the floor.
notebook::CoupledStep<2> floor_step(double speed) {
  const int n = 12;
  json j = {{"format", "monolith-scene/1"}, {"name", "notebook-09"}, {"dim", 2}};
  j["domain"] = {{"lower", {0, 0}}, {"upper", {1, 1}}, {"cells", {n, n}}, {"wall_friction", kMu}};
  j["bodies"] = json::array();
  j["bodies"].push_back({{"name", "box"}, {"density", 2000}, {"friction", kMu}, {"velocity", {speed, 0.0}},
                         {"shape", {{"type", "box"}, {"center", {0.45, 0.1 - 0.12 / n}}, {"half_size", {0.15, 0.1}}}}});
  const SceneDesc scene = parse_scene(j, "notebook-09", ".");
  return notebook::make_coupled_step<2>(
      scene, [](const Vec<2>& x) { return x[1] - 0.35; }, kRho, kEta, kDt, Vec<2>(0.0, -9.81 * kDt));
}

MonolithicSystem<2> make_system(const notebook::CoupledStep<2>& s) {
  return MonolithicSystem<2>(s.grid, StressForm::full, s.w, s.dt, s.u_star, s.bodies, s.solids,
                             s.contact_system, Backend::explicit_matrices);
}

/// The by-hand staggered projections: what each round did.
struct Round {
  VectorX lambda, z;
  double lambda_change = 0.0, z_change = 0.0;  ///< relative, inf-norm (round 0: none)
  int mlcp_iterations = 0, friction_iterations = 0;
};

struct HandResult {
  std::vector<Round> rounds;
  VectorX x, z;  ///< (tau, p, lambda) and z at exit
};

/// Section 4.2 by hand: (26) with z = 0, then rounds of (25) given (tau, p, lambda) with
/// -mu lambda^k <= z <= mu lambda^k, followed by (26) given z, until lambda changes by at most
/// `tolerance` (relative, inf-norm).
HandResult staggered_by_hand(const MonolithicSystem<2>& sys, const StaggeredSettings& settings) {
  const int nf = sys.num_fluid(), nc = sys.num_contacts(), nz = sys.num_friction();
  const MonolithicOperator<2> op(sys, settings.diagonal_boost);
  const SparseMatrixOperator fop = friction_operator(sys, settings.diagonal_boost);
  // (26): tau and p free, lambda >= 0
  VectorX lower = VectorX::Constant(nf + nc, -kInf), upper = VectorX::Constant(nf + nc, kInf);
  lower.tail(nc).setZero();
  const MprgpSettings mlcp_settings = with_norm_estimate(op, settings.mprgp);
  const MprgpSettings friction_settings = with_norm_estimate(fop, settings.mprgp);
  HandResult h;
  h.x = VectorX::Zero(nf + nc);
  h.z = VectorX::Zero(nz);
  Round first;
  first.mlcp_iterations = mprgp_solve(op, sys.mlcp_rhs(h.z), lower, upper, h.x, mlcp_settings).iterations;
  first.lambda = h.x.tail(nc);
  first.z = h.z;
  h.rounds.push_back(first);
  for (int k = 1; k < settings.max_iterations; ++k) {
    Round r;
    const VectorX lambda_old = h.x.tail(nc), z_old = h.z;
    // (25): bounds from the previous lambda
    VectorX zl(nz), zu(nz);
    for (int c = 0; c < nc; ++c) {
      zl[c] = -sys.contacts().mu[c] * lambda_old[c];
      zu[c] = sys.contacts().mu[c] * lambda_old[c];
    }
    r.friction_iterations = mprgp_solve(fop, sys.friction_rhs(h.x), zl, zu, h.z, friction_settings).iterations;
    // (26) given z
    r.mlcp_iterations = mprgp_solve(op, sys.mlcp_rhs(h.z), lower, upper, h.x, mlcp_settings).iterations;
    r.lambda = h.x.tail(nc);
    r.z = h.z;
    r.lambda_change = (r.lambda - lambda_old).cwiseAbs().maxCoeff() / std::max(r.lambda.cwiseAbs().maxCoeff(), 1e-300);
    r.z_change = (r.z - z_old).cwiseAbs().maxCoeff() / std::max(r.z.cwiseAbs().maxCoeff(), 1e-300);
    h.rounds.push_back(r);
    if (r.lambda_change <= settings.tolerance) break;
  }
  return h;
}

/// The KKT conditions at (x, z): (26) with its bounds (tau, p free rows zero, Signorini on
/// lambda), the pyramid |z| <= mu lambda (slack: the last change of lambda, since (25) bounds z
/// by the previous round's lambda) and the signs of maximal dissipation against the tangential
/// velocity after the step. Returns the tangential velocities.
VectorX check_kkt(notebook::Notebook& nb, const MonolithicSystem<2>& sys, const StaggeredSettings& settings,
                  const VectorX& x, const VectorX& z, double last_change, const std::string& label) {
  const int nf = sys.num_fluid(), nc = sys.num_contacts();
  const MonolithicOperator<2> op(sys, settings.diagonal_boost);
  VectorX ax;
  op.apply(x, ax);
  const VectorX rhs = sys.mlcp_rhs(z);
  const VectorX g = ax - rhs;
  const double scale = rhs.cwiseAbs().maxCoeff();
  const VectorX lambda = x.tail(nc);
  nb.check(label + "(26) fluid rows: max |g_tau,p| / max |rhs|", g.head(nf).cwiseAbs().maxCoeff() / scale, 1e-8);
  double signorini = 0.0, complementarity = 0.0;
  for (int c = 0; c < nc; ++c) {
    signorini = std::max({signorini, -lambda[c], -g[nf + c] / scale});
    complementarity = std::max(complementarity, std::abs(lambda[c] * g[nf + c]) / (scale * lambda.cwiseAbs().maxCoeff()));
  }
  nb.check(label + "Signorini: lambda >= 0 and g_lambda = alpha (normal velocity - target) >= 0, worst violation",
           signorini, 1e-8);
  nb.check(label + "Signorini: max |lambda_c g_c| / (max lambda max |rhs|)", complementarity, 1e-8);
  // (25) bounds z by mu times the previous round's lambda, which differs from the final one by at
  // most last_change max(lambda)
  double pyramid = 0.0;
  for (int c = 0; c < nc; ++c) pyramid = std::max(pyramid, std::abs(z[c]) - sys.contacts().mu[c] * lambda[c]);
  nb.check(label + "pyramid: max (|z| - mu lambda) / max lambda, at most mu times the last change",
           pyramid / lambda.maxCoeff(), sys.contacts().mu.maxCoeff() * last_change + 1e-13);
  // velocities after the step (eq. (21)) and the tangential slip J_z v + g_t
  const VectorX v = sys.body_velocities(x.head(nf), lambda, z);
  const VectorX slip = sys.contacts().tangent_velocity(v);
  double power = 0.0;
  for (int c = 0; c < nc; ++c) power = std::max(power, z[c] * slip[c]);
  nb.check(label + "maximal dissipation: friction opposes the slip, max z_c (J_z v)_c (W/m)", power, 1e-9);
  return slip;
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "09 Staggered projections with friction");

  nb.md("## The scene\n"
        "A 1 m tank of 12 x 12 cells holds liquid (rho = 1000 kg/m^3, eta = 1 Pa s) up to y = "
        "0.35 m. A box of 0.3 m x 0.2 m and density 2000 kg/m^3 lies on the floor under water, its bottom "
        "0.12 dx below the floor line (0.02 dx beyond the margin of 0.1 dx: eq. (16) asks for a "
        "small push out, beta 0.02 dx / dt = 0.033 m/s), and "
        "slides to the right at 0.3 m/s; mu = 0.5. dt = 0.01 s. detect_contacts finds its two "
        "bottom corners; in 2D each contact has one friction row, along t = n turned by +90 "
        "degrees = (-1, 0), so the box sliding to the right has slip J_z v < 0.");
  const notebook::CoupledStep<2> s = floor_step(0.3);
  const MonolithicSystem<2> sys = make_system(s);
  const int nc = sys.num_contacts();
  nb.md("Sizes: tau " + std::to_string(sys.num_stress()) + ", p " + std::to_string(sys.num_pressure()) +
        ", lambda " + std::to_string(nc) + ", z " + std::to_string(sys.num_friction()) + ".");
  nb.check_true("two floor contacts with mu = 0.5", nc == 2 && sys.contacts().mu.minCoeff() == kMu);

  nb.md("## By hand: (26), then (25) and (26) in turns\n"
        "Round 0 solves the MLCP (26) over (tau, p, lambda) with z = 0: MPRGP with tau, p free and "
        "lambda >= 0, on the operator S + R of monolithic_system.hpp (boost gamma = 1e-4 on the "
        "contact rows). Each further round solves the friction LCP (25), min 1/2 z^T A44 z - (b4 - "
        "A14^T tau - A24^T p - A34^T lambda)^T z with -mu lambda^k <= z <= mu lambda^k, then (26) "
        "again with b - A_.4 z, both warm-started. Stop when lambda changes by at most 1e-10 "
        "(relative, inf-norm). MPRGP tolerance 1e-12.");
  StaggeredSettings settings;
  settings.max_iterations = 200;
  settings.tolerance = 1e-10;
  settings.mprgp.tolerance = 1e-12;
  settings.mprgp.max_iterations = 20000;
  const HandResult h = staggered_by_hand(sys, settings);
  {
    std::ostringstream t;
    t << "| round | lambda (N/m) | z (N/m) | change of lambda | change of z | MPRGP (25) | MPRGP (26) |\n"
      << "|---|---|---|---|---|---|---|\n";
    for (std::size_t k = 0; k < h.rounds.size(); ++k) {
      if (k >= 12 && k + 4 < h.rounds.size()) {
        if (k == 12) t << "| ... | | | | | | |\n";
        continue;
      }
      const Round& r = h.rounds[k];
      t << "| " << k << " | " << vec_str(r.lambda) << " | " << vec_str(r.z) << " | "
        << (k ? sci(r.lambda_change) : "-") << " | " << (k ? sci(r.z_change) : "-") << " | "
        << r.friction_iterations << " | " << r.mlcp_iterations << " |\n";
    }
    nb.md(t.str());
  }
  const int rounds = static_cast<int>(h.rounds.size());
  const double last_change = h.rounds.back().lambda_change;
  nb.check("converged: the last change of lambda", last_change, settings.tolerance);
  // the change shrinks geometrically: fit the rate over the rounds after the first two
  double rate = 0.0;
  if (rounds > 4) rate = std::pow(h.rounds.back().lambda_change / h.rounds[2].lambda_change, 1.0 / (rounds - 3));
  nb.md("Rounds: " + std::to_string(rounds) + "; the change of lambda shrinks by about " + sci(rate) +
        " per round (linear convergence: each round passes the load between the normal and the "
        "tangential problem once).");
  nb.check_true("more than one round: friction changes lambda", rounds > 2);
  nb.check("linear convergence rate < 1", rate, 0.99);

  nb.md("## KKT conditions at the end\n"
        "(26): the tau, p rows are equations; the lambda rows satisfy Signorini, 0 <= lambda perp "
        "g >= 0, with g = alpha (relative normal velocity after the step - target) (+ the gamma "
        "boost). (25): |z| <= mu lambda, and maximal dissipation: z opposes the tangential slip, "
        "and a contact with |z| < mu lambda does not slip.");
  const VectorX slip = check_kkt(nb, sys, settings, h.x, h.z, last_change, "");
  const VectorX lambda = h.x.tail(nc);
  nb.md("lambda = " + vec_str(lambda) + ", z = " + vec_str(h.z) + ", mu lambda = " + vec_str(kMu * lambda) +
        ", slip J_z v = " + vec_str(slip) + " m/s");
  nb.check("sliding: both contacts at the pyramid's edge, max ||z| - mu lambda| / max lambda",
           (h.z.cwiseAbs() - kMu * lambda).cwiseAbs().maxCoeff() / lambda.maxCoeff(), 1e-8);
  const VectorX v_after = sys.body_velocities(h.x.head(sys.num_fluid()), lambda, h.z);
  nb.md("Body velocity after the step (vx, vy, omega) = " + vec_str(v_after) + "; v* = " +
        vec_str(s.contact_system.v_star) + ".");
  nb.check_true("friction slows the box but does not stop it: 0 < vx < 0.3", v_after[0] > 0.0 && v_after[0] < 0.3);
  {
    // eq. (21) split: the x-velocity change from friction (J_z^T z) and from the liquid (B_f x_f)
    const VectorX f_friction = Eigen::MatrixXd(sys.contacts().j_z).transpose() * h.z;
    const VectorX f_liquid = sys.fluid_body_force(h.x.head(sys.num_fluid()));
    const double m = s.bodies[0].mass;
    nb.md("Of the change of vx, " + sci(kDt * f_friction[0] / m) + " m/s is friction (dt (J_z^T z)_x / m) and " +
          sci(kDt * f_liquid[0] / m) + " m/s the liquid's pressure and viscous stress (dt (B_f x_f)_x / m): "
          "the box pushes the liquid ahead of it.");
    nb.check("eq. (21): |vx - vx* - (friction + liquid parts)| (m/s)",
             std::abs(v_after[0] - s.contact_system.v_star[0] - kDt * (f_friction[0] + f_liquid[0]) / m), 1e-12);
  }

  nb.md("## The library: solve_pvc_unified\n"
        "The same loop, with the same settings, is solve_pvc_unified (section 4.2): with its default "
        "options it gives the same numbers bit for bit. With options.jacobi_scaling (what "
        "solve_coupled_step uses) MPRGP works on the Jacobi-scaled MLCP S A S, S = diag(A)^-1/2: "
        "the same minimiser, other iterates, so it agrees to the solvers' tolerance.");
  const PvcUnifiedResult lib = solve_pvc_unified<2>(sys, settings);
  nb.md("solve_pvc_unified: " + std::to_string(lib.staggered_iterations) + " MLCP solves, " +
        std::to_string(lib.mprgp_iterations) + " MPRGP iterations in all, last change " + sci(lib.last_change));
  nb.check_true("the library converged too", lib.converged && lib.last_change <= settings.tolerance);
  nb.check_true("as many rounds as by hand", lib.staggered_iterations == rounds);
  nb.check("max |x_lib - x_hand| / max |x_hand|", (lib.x - h.x).cwiseAbs().maxCoeff() / h.x.cwiseAbs().maxCoeff(), 1e-15);
  nb.check("max |z_lib - z_hand| / max |z_hand|", (lib.z - h.z).cwiseAbs().maxCoeff() / h.z.cwiseAbs().maxCoeff(), 1e-15);
  {
    PvcUnifiedOptions scaled;
    scaled.jacobi_scaling = true;
    const PvcUnifiedResult js = solve_pvc_unified<2>(sys, settings, scaled);
    nb.md("Jacobi-scaled: " + std::to_string(js.staggered_iterations) + " MLCP solves, " +
          std::to_string(js.mprgp_iterations) + " MPRGP iterations in all (unscaled: " +
          std::to_string(lib.mprgp_iterations) + ").");
    nb.check("Jacobi-scaled: max |x - x_hand| / max |x_hand|", (js.x - h.x).cwiseAbs().maxCoeff() / h.x.cwiseAbs().maxCoeff(), 1e-9);
    nb.check("Jacobi-scaled: max |z - z_hand| / max |z_hand|", (js.z - h.z).cwiseAbs().maxCoeff() / h.z.cwiseAbs().maxCoeff(), 1e-9);
  }

  nb.md("## A box that sticks\n"
        "The same box sliding at only 0.01 m/s: one step of friction (at most mu g dt ~ 0.05 m/s) "
        "stops it, so z ends inside the pyramid and the contacts do not slip.");
  const notebook::CoupledStep<2> slow = floor_step(0.01);
  const MonolithicSystem<2> sys_slow = make_system(slow);
  const HandResult h_slow = staggered_by_hand(sys_slow, settings);
  {
    const PvcUnifiedResult r = solve_pvc_unified<2>(sys_slow, settings);
    nb.check("sticking: by hand and solve_pvc_unified agree, max |dx| / max |x|",
             (r.x - h_slow.x).cwiseAbs().maxCoeff() / h_slow.x.cwiseAbs().maxCoeff(), 1e-9);
    const VectorX slip_slow = check_kkt(nb, sys_slow, settings, r.x, r.z, r.last_change, "sticking: ");
    nb.md("rounds " + std::to_string(r.staggered_iterations) + ", lambda = " + vec_str(r.lambda) + ", z = " +
          vec_str(r.z) + ", mu lambda = " + vec_str(kMu * r.lambda) + ", slip = " + vec_str(slip_slow) + " m/s");
    nb.check_true("sticking: |z| < mu lambda on some contact", (r.z.cwiseAbs() - kMu * r.lambda).minCoeff() < 0.0);
    // where z is inside the pyramid the gradient of (25) vanishes: alpha slip + gamma diag(A44) z = 0,
    // so the boost of section 4.4.5 leaves a slip of -gamma diag(A44) z / alpha
    const VectorX a44 = Eigen::MatrixXd(sys_slow.contacts().a44()).diagonal();
    const VectorX boost_slip = -settings.diagonal_boost * a44.cwiseProduct(r.z) / sys_slow.alpha();
    nb.md("The slip left by the boost gamma: -gamma diag(A44) z / alpha = " + vec_str(boost_slip) + " m/s.");
    nb.check("sticking: max |slip - (-gamma diag(A44) z / alpha)| (m/s)", (slip_slow - boost_slip).cwiseAbs().maxCoeff(), 1e-9);
    nb.check("sticking: the slip is tiny next to the speed 0.01 m/s, max |slip| / 0.01", slip_slow.cwiseAbs().maxCoeff() / 0.01, 1e-3);
    const int n_slow = static_cast<int>(h_slow.rounds.size());
    const double rate_slow =
        n_slow > 4 ? std::pow(h_slow.rounds.back().lambda_change / h_slow.rounds[2].lambda_change, 1.0 / (n_slow - 3)) : 0.0;
    nb.md("Sticking takes " + std::to_string(n_slow) + " rounds (lambda changes by a factor " + sci(rate_slow) +
          " per round) against " + std::to_string(rounds) + " sliding (" + sci(rate) + "). With z inside "
          "the pyramid the rounds are block Gauss-Seidel between (26) and (25) on two coupled "
          "equations, whose rate is set by the coupling A34 (the friction forces' torque moves load "
          "between the two contacts); sliding, z = mu lambda^k follows lambda directly.");
    nb.check_true("sticking converges too, more slowly", rate_slow < 1.0 && n_slow > rounds);
  }

  nb.md("## Figure: change per round\n"
        "The relative change of lambda and of z in every round, sliding and sticking (log scale).");
  {
    PlotSpec spec;
    spec.title = "staggered projections: change per round";
    spec.x_label = "round";
    spec.y_label = "relative change (inf-norm)";
    spec.log_y = true;
    PlotSeries sl, sz;
    sl.label = "lambda, sliding box";
    sz.label = "z, sliding box";
    sl.marker = Marker::circle;
    sz.marker = Marker::square;
    sz.dash = 6.0;
    for (int k = 1; k < rounds; ++k) {
      if (h.rounds[k].lambda_change > 0.0) {
        sl.x.push_back(k);
        sl.y.push_back(h.rounds[k].lambda_change);
      }
      if (h.rounds[k].z_change > 0.0) {
        sz.x.push_back(k);
        sz.y.push_back(h.rounds[k].z_change);
      }
    }
    PlotSeries st;
    st.label = "lambda, sticking box";
    st.marker = Marker::cross;
    for (std::size_t k = 1; k < h_slow.rounds.size(); ++k)
      if (h_slow.rounds[k].lambda_change > 0.0) {
        st.x.push_back(static_cast<double>(k));
        st.y.push_back(h_slow.rounds[k].lambda_change);
      }
    spec.series = {sl, sz, st};
    nb.figure("09_change_per_round.ppm", plot_lines(spec), "relative change of lambda and z per round");
  }
  return nb.finish();
}
