// Notebook 05: rigid contact as a QP. J_lambda, J_z and M_r of two boxes (eqs. (9), (10), (13)),
// the normal LCP (11)/(12) and the frictional problem (15) by staggered projections, A33, A34,
// A44, b3, b4 of eq. (24), the Signorini conditions and the kinetic energy.
//
// Run: build/notebooks/notebook_05_contact_qp --out DIR
#include <Eigen/Dense>
#include <cmath>
#include <sstream>

#include "notebooks_cpp/notebook.hpp"
#include "reference/app/scene_file.hpp"
#include "reference/contact/collision.hpp"
#include "reference/contact/contact_system.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "reference/viz/plot.hpp"

using namespace monolith;
using nlohmann::json;

namespace {

/// Kinetic energy 1/2 v^T M_r v of generalized velocities.
double kinetic(const ContactSystem<2>& sys, const VectorX& v) {
  return 0.5 * v.dot(sys.m_r * v);
}

std::string num(double x) {
  std::ostringstream s;
  s << x;
  return s.str();
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "05 Rigid contact as a quadratic program");

  nb.md("## Two boxes on the floor\n"
        "Box A (0.2 x 0.1 m, 500 kg/m^3) rests on the floor; box B (0.12 x 0.08 m, 800 kg/m^3) lies "
        "on A and slides to the right at 1 m/s while falling at 1.5 m/s. Gravity has already been "
        "added (v* of eq. (10)); dt = 0.01 s, dx = 1/32 m. Contacts come from `detect_contacts` "
        "(reference/contact/collision.hpp): two points between B and A and two between A and the floor. "
        "The DOFs are [vx, vy, omega] of A then of B.");
  json j = {{"format", "monolith-scene/1"}, {"name", "two-boxes"}, {"dim", 2}};
  j["domain"] = {{"lower", {0, 0}}, {"upper", {1, 1}}, {"cells", {32, 32}}, {"wall_friction", 0.5}};
  j["bodies"] = json::array();
  j["bodies"].push_back({{"name", "A"}, {"density", 500}, {"friction", 0.5},
                         {"shape", {{"type", "box"}, {"center", {0.5, 0.05}}, {"half_size", {0.1, 0.05}}}}});
  j["bodies"].push_back({{"name", "B"}, {"density", 800}, {"friction", 0.5}, {"restitution", 0.0},
                         {"shape", {{"type", "box"}, {"center", {0.52, 0.14}}, {"half_size", {0.06, 0.04}}}}});
  const SceneDesc scene = parse_scene(j, "notebook-05", ".");
  std::vector<RigidBody<2>> bodies = make_bodies<2>(scene);
  bodies[0].velocity = Vec<2>(0.0, -9.81 * 0.01);
  bodies[1].velocity = Vec<2>(1.0, -1.5);
  std::vector<Contact<2>> contacts = detect_contacts<2>(bodies, Walls<2>::from_scene(scene), 0.01);
  ContactParameters params;
  params.dt = 0.01;
  params.dx = 1.0 / 32;
  params.baumgarte = 0.2;
  params.margin_cells = 0.1;
  params.restitution_threshold = 2 * 9.81 * params.dt;
  for (std::size_t c = 0; c < contacts.size(); ++c) {
    const auto& k = contacts[c];
    nb.md("- contact " + std::to_string(c) + ": a = " + std::to_string(k.body_a) + ", b = " +
          std::to_string(k.body_b) + " (-1 = wall), point (" + num(k.point[0]) + ", " + num(k.point[1]) +
          "), normal (" + num(k.normal[0]) + ", " + num(k.normal[1]) + "), phi " + num(k.phi) +
          ", mu " + num(k.friction));
  }
  ContactSystem<2> sys(bodies, contacts, params);
  nb.check_true("four contacts", sys.num_contacts() == 4);
  {
    // figure: the two boxes, the floor, the contact points and their normals (from b to a)
    PlotSpec spec;
    spec.title = "two boxes: contact points and normals";
    spec.x_label = "x (m)";
    spec.y_label = "y (m)";
    spec.width = 640;
    spec.height = 420;
    spec.x_min = 0.35;
    spec.x_max = 0.65;
    spec.y_min = -0.03;
    spec.y_max = 0.2;
    auto outline = [](const std::string& label, const Vec<2>& c, const Vec<2>& h, Rgb colour) {
      PlotSeries b;
      b.label = label;
      b.color = colour;
      b.x = {c[0] - h[0], c[0] + h[0], c[0] + h[0], c[0] - h[0], c[0] - h[0]};
      b.y = {c[1] - h[1], c[1] - h[1], c[1] + h[1], c[1] + h[1], c[1] - h[1]};
      return b;
    };
    PlotSeries floor;
    floor.label = "floor";
    floor.color = Rgb{90, 90, 90};
    floor.x = {0.35, 0.65};
    floor.y = {0.0, 0.0};
    PlotSeries points, normals;
    points.label = "contact points";
    points.line = false;
    points.marker = Marker::circle;
    points.color = Rgb{200, 40, 40};
    normals.label = "normals (0.03 m)";
    normals.color = Rgb{200, 40, 40};
    normals.line_width = 1.5;
    for (const auto& k : contacts) {
      points.x.push_back(k.point[0]);
      points.y.push_back(k.point[1]);
      normals.x.insert(normals.x.end(), {k.point[0], k.point[0] + 0.03 * k.normal[0], NAN});
      normals.y.insert(normals.y.end(), {k.point[1], k.point[1] + 0.03 * k.normal[1], NAN});
    }
    spec.series = {floor, outline("A", Vec<2>(0.5, 0.05), Vec<2>(0.1, 0.05), Rgb{40, 80, 180}),
                   outline("B", Vec<2>(0.52, 0.14), Vec<2>(0.06, 0.04), Rgb{40, 150, 80}), points, normals};
    nb.figure("05_contacts.ppm", plot_lines(spec), "the two boxes, the floor and the four contacts with their normals");
  }

  nb.md("## Jacobians and mass matrix\n"
        "Row c of J_lambda is [n^T, r_a x n] at body a's DOFs minus the same for body b: "
        "J_lambda v is the relative normal velocity, positive when separating. J_z has the "
        "tangent t = n turned by +90 degrees in place of n. M_r = diag(m, m, I) per body.");
  nb.matrix("J_lambda (contacts x DOFs)", Eigen::MatrixXd(sys.j_lambda), 4);
  nb.matrix("J_z (friction rows x DOFs)", Eigen::MatrixXd(sys.j_z), 4);
  nb.matrix("M_r", Eigen::MatrixXd(sys.m_r), 5);
  nb.matrix("relative normal velocity J_lambda v* (m/s)", Eigen::MatrixXd(sys.normal_velocity(sys.v_star)), 4);

  nb.md("## The blocks of eq. (24)\n"
        "A33 = dt alpha J_lambda M_r^-1 J_lambda^T, A34 = dt alpha J_lambda M_r^-1 J_z^T, A44 = dt "
        "alpha J_z M_r^-1 J_z^T with alpha = 1/dx^2 = 1024; b3 = -alpha (C J_lambda v* + "
        "beta min(phi + eps, 0)/dt) with the speculative gap term for phi + eps > 0 "
        "(docs/rigid-bodies.md), b4 = -alpha J_z v*.");
  const Eigen::MatrixXd a33 = Eigen::MatrixXd(sys.a33());
  nb.matrix("A33", a33, 2);
  nb.matrix("A34", Eigen::MatrixXd(sys.a34()), 2);
  nb.matrix("A44", Eigen::MatrixXd(sys.a44()), 2);
  nb.matrix("b3", Eigen::MatrixXd(sys.b3()), 2);
  nb.matrix("b4", Eigen::MatrixXd(sys.b4()), 2);
  {
    // the blocks are the products they are printed as (alpha = 1/dx^2 in 2D)
    const Eigen::MatrixXd jl(sys.j_lambda), jz(sys.j_z), m_inv(sys.m_r_inverse);
    const double dt_alpha = params.dt * sys.alpha;
    const double a_scale = a33.cwiseAbs().maxCoeff();
    nb.check("alpha = 1 / dx^2 = 1024", std::abs(sys.alpha - 1024.0), 0.0);
    nb.check("A33 = dt alpha J_lambda M_r^-1 J_lambda^T, max difference / max |A33|",
             (a33 - dt_alpha * jl * m_inv * jl.transpose()).cwiseAbs().maxCoeff() / a_scale, 1e-14);
    nb.check("A34 = dt alpha J_lambda M_r^-1 J_z^T, max difference / max |A33|",
             (Eigen::MatrixXd(sys.a34()) - dt_alpha * jl * m_inv * jz.transpose()).cwiseAbs().maxCoeff() / a_scale, 1e-14);
    nb.check("A44 = dt alpha J_z M_r^-1 J_z^T, max difference / max |A33|",
             (Eigen::MatrixXd(sys.a44()) - dt_alpha * jz * m_inv * jz.transpose()).cwiseAbs().maxCoeff() / a_scale, 1e-14);
    nb.check("M_r M_r^-1 = I, max deviation",
             (Eigen::MatrixXd(sys.m_r) * m_inv - Eigen::MatrixXd::Identity(m_inv.rows(), m_inv.cols())).cwiseAbs().maxCoeff(), 1e-12);
    // b4 = -alpha J_z v* (the floor is at rest: no known tangential velocity)
    const VectorX b4_expected = -sys.alpha * (jz * sys.v_star + sys.known_tangent_velocity);
    nb.check("b4 = -alpha J_z v*, max difference / max |b4|",
             (sys.b4() - b4_expected).cwiseAbs().maxCoeff() / sys.b4().cwiseAbs().maxCoeff(), 1e-14);
  }
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(a33).eigenvalues();
  nb.check("A33 positive semi-definite: -lambda_min / lambda_max", -ev.minCoeff() / ev.maxCoeff(), 1e-12);

  nb.md("## Without friction: the LCP (11), the QP (12)\n"
        "min 1/2 lambda^T A33 lambda - b3^T lambda over lambda >= 0, one MPRGP solve on A33 with "
        "its diagonal scaled by 1 + gamma (section 4.4.5).");
  ContactSystem<2> frictionless = sys;
  frictionless.mu.setZero();
  StaggeredSettings settings;
  settings.mprgp.tolerance = 1e-12;
  const StaggeredResult r0 = solve_staggered_projections<2>(frictionless, settings);
  nb.matrix("lambda (N/m)", Eigen::MatrixXd(r0.lambda), 3);
  Eigen::MatrixXd boosted = a33;
  boosted.diagonal() *= 1.0 + settings.diagonal_boost;
  const Eigen::VectorXd w0 = boosted * r0.lambda - frictionless.b3();
  nb.matrix("w = (A33 + gamma diag) lambda - b3", Eigen::MatrixXd(w0), 4);
  nb.check("Signorini: -min(lambda)", -r0.lambda.minCoeff(), 0.0);
  nb.check("Signorini: -min(w) / ||b3||", -w0.minCoeff() / frictionless.b3().norm(), 1e-9);
  nb.check("Signorini: max |lambda_i w_i| / (||lambda|| ||b3||)",
           w0.cwiseProduct(r0.lambda).cwiseAbs().maxCoeff() / (r0.lambda.norm() * frictionless.b3().norm()), 1e-9);
  const VectorX v0 = frictionless.velocity_update(r0.lambda, r0.z);
  nb.matrix("v after the step (frictionless)", Eigen::MatrixXd(v0.transpose()), 4);
  nb.check("kinetic energy after / before", kinetic(sys, v0) / kinetic(sys, sys.v_star), 1.0);

  nb.md("## With friction mu = 0.5: eq. (15) by staggered projections\n"
        "Friction QP (25) with bounds -mu lambda^k <= z <= mu lambda^k, then the normal QP with "
        "b3 - A34 z, alternated to a relative change of 1e-10, ending on the normal solve.");
  settings.max_iterations = 100;
  settings.tolerance = 1e-10;
  const StaggeredResult r = solve_staggered_projections<2>(sys, settings);
  nb.md("staggered iterations: " + std::to_string(r.staggered_iterations) + ", MPRGP iterations in all: " +
        std::to_string(r.mprgp_iterations));
  nb.matrix("lambda (N/m)", Eigen::MatrixXd(r.lambda), 3);
  nb.matrix("z (N/m)", Eigen::MatrixXd(r.z), 3);
  const Eigen::VectorXd w = boosted * r.lambda + Eigen::MatrixXd(sys.a34()) * r.z - sys.b3();
  nb.check("Signorini with friction: -min(w) / ||b3||", -w.minCoeff() / sys.b3().norm(), 1e-9);
  double pyramid = 0.0;
  for (int c = 0; c < sys.num_contacts(); ++c) pyramid = std::max(pyramid, std::abs(r.z[c]) - sys.mu[c] * r.lambda[c]);
  nb.check("pyramid: max(|z| - mu lambda) / ||lambda||", pyramid / r.lambda.norm(), 1e-8);
  const VectorX v = sys.velocity_update(r.lambda, r.z);
  nb.matrix("v after the step (with friction)", Eigen::MatrixXd(v.transpose()), 4);
  const VectorX slip = sys.tangent_velocity(v);
  nb.matrix("tangential velocity J_z v (m/s)", Eigen::MatrixXd(slip), 4);
  double power = 0.0;
  for (int i = 0; i < sys.num_friction_rows(); ++i) power = std::max(power, r.z[i] * slip[i]);
  nb.check("maximal dissipation: max z_i (J_z v)_i", power, 1e-9);
  nb.check("kinetic energy with friction / without", kinetic(sys, v) / kinetic(sys, v0), 1.0);
  nb.check("B slows down: vx of B after", v[3], 1.0 - 1e-3);
  return nb.finish();
}
