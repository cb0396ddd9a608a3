// Notebook 08: the unified pressure-viscosity-contact system (24) of section 4.2 on a 6 x 6 tank:
// the sizes and norms of its sixteen blocks, symmetry and definiteness from the dense matrix, the
// rigid blocks dt alpha B_i^T M_r^-1 B_j applied right to left without (alpha M_r)^-1, b1 = b2 = 0
// for one uniform motion (Fig. 8), the scaling alpha = 1/dx^Dim of section 4.1, the sparsity
// pattern, and one 3D identity check.
//
// Run: build/notebooks/notebook_08_unified_system --out DIR
#include <Eigen/Dense>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "notebooks_cpp/coupled_step.hpp"
#include "notebooks_cpp/notebook.hpp"
#include "reference/coupling/monolithic_system.hpp"

using namespace monolith;
using nlohmann::json;

namespace {

constexpr double kRho = 1000.0, kEta = 0.5, kDt = 0.01;

std::string num(double x, int digits = 4) {
  std::ostringstream s;
  s << std::setprecision(digits) << x;
  return s.str();
}

std::string sci(double x) {
  std::ostringstream s;
  s << std::scientific << std::setprecision(3) << x;
  return s.str();
}

/// The tank scene: a dynamic box (density 500, tilted by 0.5 rad) floating in the liquid,
/// touching the left wall with one corner. `side` is the domain's edge (m), `cells` per axis.
json tank_scene(int dim, double side, int cells) {
  json j = {{"format", "monolith-scene/1"}, {"name", "notebook-08"}, {"dim", dim}};
  std::vector<double> lower(dim, 0.0), upper(dim, side), centre(dim, 0.5 * side), half(dim, 0.15 * side);
  std::vector<int> n(dim, cells);
  half[1] = 0.1 * side;
  if (dim == 2) {
    // the left corner of the tilted box sits 0.02 m (0.12 dx) beyond the wall
    const double reach = half[0] * std::cos(0.5) + half[1] * std::sin(0.5);
    centre[0] = reach - 0.02 * side;
  } else {
    centre[1] = half[1] - 0.02 * side;  // 3D: the box sits on the floor instead
  }
  j["domain"] = {{"lower", lower}, {"upper", upper}, {"cells", n}, {"wall_friction", 0.4}};
  json shape = {{"type", "box"}, {"center", centre}, {"half_size", half}};
  if (dim == 2) shape["rotation"] = 0.5;
  std::vector<double> v(dim, 0.0);
  v[0] = -0.2;
  j["bodies"] = json::array();
  j["bodies"].push_back({{"name", "box"}, {"density", 500}, {"friction", 0.4}, {"velocity", v}, {"shape", shape}});
  return j;
}

template <int Dim>
notebook::CoupledStep<Dim> tank_step(double side, int cells) {
  const SceneDesc scene = parse_scene(tank_scene(Dim, side, cells), "notebook-08", ".");
  Vec<Dim> u0 = Vec<Dim>::Zero();
  u0[1] = -9.81 * kDt;  // liquid at rest before gravity
  const double level = 0.55 * side;
  return notebook::make_coupled_step<Dim>(
      scene, [level](const Vec<Dim>& x) { return x[1] - level; }, kRho, kEta, kDt, u0);
}

template <int Dim>
MonolithicSystem<Dim> make_system(const notebook::CoupledStep<Dim>& s) {
  return MonolithicSystem<Dim>(s.grid, StressForm::full, s.w, s.dt, s.u_star, s.bodies, s.solids,
                               s.contact_system, Backend::explicit_matrices);
}

/// The dense pieces of eq. (24): F the fluid part (the Stokes matrix in the (tau, p) corner),
/// B = [B_1 B_2 B_3 B_4] (nd x n, file comment of monolithic_system.hpp) and the rigid part
/// R = dt alpha B^T M_r^-1 B formed densely here, for comparison only.
struct DenseParts {
  Eigen::MatrixXd F, B, R, m_inv;
  std::vector<int> offsets;  ///< first row of blocks 1..4 and the total size
};

template <int Dim>
DenseParts dense_parts(const MonolithicSystem<Dim>& sys) {
  DenseParts d;
  const int nf = sys.num_fluid(), nc = sys.num_contacts(), nz = sys.num_friction();
  const int n = nf + nc + nz, nd = sys.num_body_dofs();
  d.offsets = {0, sys.num_stress(), nf, nf + nc, n};
  d.F = Eigen::MatrixXd::Zero(n, n);
  d.F.topLeftCorner(nf, nf) = Eigen::MatrixXd(sys.stokes().A);
  d.B.resize(nd, n);
  d.B.leftCols(nf) = Eigen::MatrixXd(sys.fluid_body_jacobian());
  d.B.middleCols(nf, nc) = Eigen::MatrixXd(sys.contacts().j_lambda).transpose();
  d.B.rightCols(nz) = Eigen::MatrixXd(sys.contacts().j_z).transpose();
  d.m_inv = Eigen::MatrixXd(sys.contacts().m_r_inverse);
  d.R = sys.dt() * sys.alpha() * d.B.transpose() * d.m_inv * d.B;
  return d;
}

Eigen::MatrixXd block(const Eigen::MatrixXd& a, const std::vector<int>& o, int i, int j) {
  return a.block(o[i - 1], o[j - 1], o[i] - o[i - 1], o[j] - o[j - 1]);
}

/// A 4 x 4 Markdown table of the Frobenius norms of the blocks of a.
std::string norm_table(const Eigen::MatrixXd& a, const std::vector<int>& o) {
  std::ostringstream s;
  s << "| ||A_ij||_F | j = 1 (tau) | j = 2 (p) | j = 3 (lambda) | j = 4 (z) |\n|---|---|---|---|---|\n";
  const char* names[] = {"tau", "p", "lambda", "z"};
  for (int i = 1; i <= 4; ++i) {
    s << "| i = " << i << " (" << names[i - 1] << ") |";
    for (int j = 1; j <= 4; ++j) s << " " << sci(block(a, o, i, j).norm()) << " |";
    s << "\n";
  }
  return s.str();
}

/// The sparsity pattern of A: one square of `px` pixels per entry; blue where the fluid part F
/// is non-zero, orange where only the rigid part R is (the dense blocks of section 4.4.3), white
/// where A_ij = 0; red lines at the block boundaries.
Image sparsity_figure(const DenseParts& d, int px, int* rigid_only) {
  const int n = static_cast<int>(d.F.rows());
  const double tiny = 1e-14 * (d.F + d.R).cwiseAbs().maxCoeff();
  Image img(n * px + 1, n * px + 1, {255, 255, 255});
  *rigid_only = 0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const bool fluid = std::abs(d.F(i, j)) > tiny, rigid = std::abs(d.R(i, j)) > tiny;
      if (!fluid && !rigid) continue;
      const Rgb c = fluid ? Rgb{40, 80, 170} : Rgb{240, 150, 40};
      *rigid_only += !fluid;
      for (int y = 0; y < px - 1; ++y)
        for (int x = 0; x < px - 1; ++x) img.set(j * px + x + 1, i * px + y + 1, c);
    }
  for (int b : d.offsets)
    for (int t = 0; t <= n * px; ++t) {
      img.set(std::min(b * px, n * px), t, {220, 30, 30});
      img.set(t, std::min(b * px, n * px), {220, 30, 30});
    }
  return img;
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "08 The unified system (24)");

  nb.md("## The scene\n"
        "A 1 m x 1 m tank of 6 x 6 cells (dx = 1/6 m, walls on every side) holds water "
        "(rho = 1000 kg/m^3, eta = 0.5 Pa s) up to y = 0.55 m. A box of 0.3 m x 0.2 m and density "
        "500 kg/m^3, tilted by 0.5 rad, floats at the surface and leans on the left wall with its "
        "left corner (0.02 m beyond the wall, more than the margin of 0.1 dx), moving at -0.2 m/s "
        "into it. Its sides make 0.5 rad with the wall, more than the 0.45 rad of a box's contact "
        "cone (ContactReduction::box_cone_cosine = 0.9), so detect_contacts keeps the corner alone. "
        "dt = 0.01 s; u* = dt g on every face (the liquid at rest before gravity) and v* = v + dt g. "
        "Friction mu = 0.4 with the wall.");
  const notebook::CoupledStep<2> s = tank_step<2>(1.0, 6);
  for (std::size_t c = 0; c < s.contacts.size(); ++c) {
    const Contact<2>& k = s.contacts[c];
    nb.md("- contact " + std::to_string(c) + ": body " + std::to_string(k.body_a) + " with wall face " +
          std::to_string(k.wall_face) + " at (" + num(k.point[0]) + ", " + num(k.point[1]) + "), normal (" +
          num(k.normal[0]) + ", " + num(k.normal[1]) + "), phi " + num(k.phi) + " m, mu " + num(k.friction));
  }
  nb.check_true("one contact (the corner on the left wall)", s.contacts.size() == 1);
  const MonolithicSystem<2> sys = make_system<2>(s);

  nb.md("## Block sizes\n"
        "Unknowns in the order of eq. (24): tau (active stress DOFs: W_F^s W_L^s > 0, xx and yy at "
        "cell centres, xy at nodes), p (cells with liquid), lambda (one per contact), z (Dim - 1 "
        "per contact). nd = 3 body DOFs (vx, vy, omega) carry no unknown of their own: the body "
        "velocity is eliminated through eq. (21).");
  {
    std::ostringstream t;
    t << "| block | unknowns | size |\n|---|---|---|\n"
      << "| 1 | tau (Pa) | " << sys.block_size(1) << " |\n| 2 | p (Pa) | " << sys.block_size(2)
      << " |\n| 3 | lambda (N/m) | " << sys.block_size(3) << " |\n| 4 | z (N/m) | " << sys.block_size(4)
      << " |\n\nnd = " << sys.num_body_dofs() << ", alpha = 1/dx^2 = " << num(sys.alpha());
    nb.md(t.str());
  }
  nb.check_true("every block is present", sys.num_stress() > 0 && sys.num_pressure() > 0 &&
                                              sys.num_contacts() == 1 && sys.num_friction() == 1);
  nb.check_true("nd = 3 body DOFs (vx, vy, omega of the one dynamic box)", sys.num_body_dofs() == 3);
  nb.check("alpha = 1/dx^2 = 36 (dx = 1/6 m), relative", std::abs(sys.alpha() / 36.0 - 1.0), 1e-14);

  nb.md("## The sixteen blocks\n"
        "MonolithicSystem::dense_matrix() assembles (24) column by column through apply_block(i, j, "
        "x) = F_ij x + dt alpha B_i^T (M_r^-1 (B_j x)). Frobenius norms:");
  const Eigen::MatrixXd A = sys.dense_matrix();
  const DenseParts d = dense_parts<2>(sys);
  nb.md(norm_table(A, d.offsets));
  const double scale = A.cwiseAbs().maxCoeff();
  nb.check("symmetry: max |A - A^T| / max |A|", (A - A.transpose()).cwiseAbs().maxCoeff() / scale, 1e-13);
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(0.5 * (A + A.transpose())).eigenvalues();
  nb.md("Eigenvalues of A: smallest " + sci(ev.minCoeff()) + ", largest " + sci(ev.maxCoeff()) +
        ", condition number " + sci(ev.maxCoeff() / ev.minCoeff()) + ". A is a sum of the Stokes "
        "matrix (definite on (tau, p): the liquid has a free surface) and dt alpha B^T M_r^-1 B "
        "(semi-definite, rank nd = 3); a null vector would need tau = p = 0 and J_lambda^T lambda + "
        "J_z^T z = 0, impossible for the two independent rows of one contact.");
  nb.check("definite: lambda_max / lambda_min (finite and positive means A > 0), bounded by 1e12",
           ev.minCoeff() > 0.0 ? ev.maxCoeff() / ev.minCoeff() : INFINITY, 1e12);
  for (int i = 1; i <= 4; ++i)
    for (int j = i + 1; j <= 4; ++j) {
      const double err = (block(A, d.offsets, i, j) - block(A, d.offsets, j, i).transpose()).cwiseAbs().maxCoeff();
      nb.check("A_" + std::to_string(j) + std::to_string(i) + " = A_" + std::to_string(i) + std::to_string(j) +
                   "^T (max difference / max |A|)", err / scale, 1e-13);
    }

  {
    // the MLCP (26) over (tau, p, lambda) is the leading block of (24): what notebook 09 solves
    const MonolithicOperator<2> op(sys, 0.0);
    const int n26 = op.size();
    nb.check("the MLCP operator (26) is the leading (tau, p, lambda) block of A: max difference / max |A|",
             (op.dense_matrix() - A.topLeftCorner(n26, n26)).cwiseAbs().maxCoeff() / scale, 1e-13);
  }

  nb.md("## (alpha M_r)^-1 is never formed\n"
        "Every rigid contribution is dt alpha B_i^T M_r^-1 B_j with B_1 = Jh_s W_L^s E S_tau^T, B_2 = "
        "Jh_p W_L^p S_p^T (body-surface columns only), B_3 = J_lambda^T, B_4 = J_z^T. apply_block "
        "evaluates it right to left: B_j x (nd numbers), M_r^-1 (a 3 x 3 block per body), then B_i^T "
        "and the factor dt alpha. Here the dense product is formed only to compare with it.");
  nb.matrix("M_r^-1 (2D: mass and inertia per metre of depth)", d.m_inv, 6);
  {
    const Eigen::MatrixXd scaled_inv = d.m_inv / sys.alpha();
    nb.md("(alpha M_r)^-1 would have entries down to " + sci(scaled_inv.diagonal().minCoeff()) +
          " here; at the paper's 128^3 grid in a 1 m box (dx^3 = 4.8e-7 m^3) and a 1 kg body they "
          "would be about 5e-7, next to fluid entries of order dt / (rho dx^2) ~ 1e-1: the tiny "
          "entries with which, the paper reports (section 4.2), double-precision CG almost always "
          "failed to converge.");
  }
  const Eigen::MatrixXd dense = d.F + d.R;
  nb.check("max |A (right-to-left) - (F + dt alpha B^T M_r^-1 B) (dense)| / max |A|",
           (A - dense).cwiseAbs().maxCoeff() / scale, 1e-13);
  {
    const int n = static_cast<int>(A.rows());
    const SparseMatrix bs = d.B.sparseView();
    std::ostringstream t;
    t << "Storage: B has " << bs.nonZeros() << " non-zeros and M_r^-1 " << (d.m_inv.array() != 0).count()
      << "; the dense rigid part R would have " << (d.R.array().abs() > 1e-14 * scale).count()
      << " of the " << n * n << " entries of A, the Stokes part F " << sys.stokes().A.nonZeros() << ".";
    nb.md(t.str());
  }
  {
    // a random x through apply_block against the dense blocks
    VectorX x = VectorX::LinSpaced(static_cast<int>(A.rows()), -1.0, 1.0).array().sin();
    double worst = 0.0;
    for (int i = 1; i <= 4; ++i)
      for (int j = 1; j <= 4; ++j) {
        const int oj = d.offsets[j - 1], nj = d.offsets[j] - oj;
        const VectorX y = sys.apply_block(i, j, x.segment(oj, nj));
        worst = std::max(worst, (y - block(dense, d.offsets, i, j) * x.segment(oj, nj)).cwiseAbs().maxCoeff());
      }
    nb.check("every apply_block(i, j, x) against the dense block times x, max difference / max |A|",
             worst / scale, 1e-13);
  }

  nb.md("## The scaling alpha = 1/dx^Dim (section 4.1)\n"
        "Dividing the energy (22) by the control volume dx^Dim turns the fluid part into eq. (8) as "
        "written and the body's kinetic energy into 1/2 ||v||^2 in the norm alpha M_r: every rigid "
        "block gets the factor alpha. Without it (the Stokes matrix of eq. (8) next to the contact "
        "blocks of eq. (12) in their own units) the rigid parts are alpha = 36 times smaller:");
  Eigen::MatrixXd unscaled = d.F + d.R / sys.alpha();
  nb.md(norm_table(unscaled, d.offsets));
  nb.md("That system is not the minimisation of one energy in one unit: the body would look alpha "
        "times heavier to the liquid. The unit of length shows it. The same scene built in a "
        "0.1 m tank (every length divided by 10, same cells) changes F_22 = dt W G^T K G W by 100 "
        "(1/dx^2); with alpha the rigid part of A_22, dt alpha Jh_p^T M_r^-1 Jh_p (Jh_p ~ dx, "
        "M_r ~ dx^2), changes by the same 100, so the ratio of the two is a property of the "
        "scene, not of the unit; without alpha the rigid part changes by dx^-2 dx^2 = 1 only and "
        "the ratio drops 100 times: how strongly the body and the liquid push on each other "
        "would depend on whether lengths are written in metres or decimetres.");
  {
    const notebook::CoupledStep<2> small = tank_step<2>(0.1, 6);
    const MonolithicSystem<2> sys_small = make_system<2>(small);
    const DenseParts ds = dense_parts<2>(sys_small);
    auto ratio = [](const DenseParts& p, double divide) {
      return block(p.R, p.offsets, 2, 2).norm() / divide / block(p.F, p.offsets, 2, 2).norm();
    };
    const double r1 = ratio(d, 1.0), r01 = ratio(ds, 1.0);
    const double u1 = ratio(d, sys.alpha()), u01 = ratio(ds, sys_small.alpha());
    std::ostringstream t;
    t << "| tank | dx (m) | ||R_22|| / ||F_22|| with alpha | without alpha |\n|---|---|---|---|\n"
      << "| 1 m | " << num(s.grid.dx()) << " | " << sci(r1) << " | " << sci(u1) << " |\n"
      << "| 0.1 m | " << num(small.grid.dx()) << " | " << sci(r01) << " | " << sci(u01) << " |\n";
    nb.md(t.str());
    nb.check("with alpha the ratio does not depend on the unit: |r(0.1 m) / r(1 m) - 1|", std::abs(r01 / r1 - 1.0), 1e-9);
    nb.check("without alpha it moves with dx^2: |100 u(0.1 m) / u(1 m) - 1|", std::abs(100.0 * u01 / u1 - 1.0), 1e-9);
  }

  nb.md("## Fig. 8: one uniform motion gives b1 = b2 = 0\n"
        "Open boundaries, a liquid disk of radius 0.35 m around the centre and the untilted box "
        "cutting its surface, liquid and box moving with v0 = (0.4, -0.3) m/s (plus dt g, both). "
        "W_F^u + W_S^u = 1 and G^T, D annihilate constants, so b2 = W_L^p G^T W_F^u u* - W_L^p "
        "alpha Jh_p^T v* and b1 = W_L^s M D W_F^u u* - W_L^s alpha Jh_s^T v* vanish.");
  {
    json j = {{"format", "monolith-scene/1"}, {"name", "notebook-08-fig8"}, {"dim", 2}};
    j["domain"] = {{"lower", {0, 0}}, {"upper", {1, 1}}, {"cells", {6, 6}},
                   {"boundary", {{"x-", "open"}, {"x+", "open"}, {"y-", "open"}, {"y+", "open"}}}};
    j["bodies"] = json::array();
    j["bodies"].push_back({{"name", "box"}, {"density", 700}, {"velocity", {0.4, -0.3}},
                           {"shape", {{"type", "box"}, {"center", {0.62, 0.7}}, {"half_size", {0.15, 0.12}}}}});
    const SceneDesc scene = parse_scene(j, "notebook-08-fig8", ".");
    const Vec<2> u0(0.4, -0.3 - 9.81 * kDt);
    const notebook::CoupledStep<2> f = notebook::make_coupled_step<2>(
        scene, [](const Vec<2>& x) { return (x - Vec<2>(0.5, 0.5)).norm() - 0.35; }, kRho, kEta, kDt, u0);
    const MonolithicSystem<2> moving = make_system<2>(f);
    const double b_scale = u0.norm() / f.grid.dx();
    nb.check_true("the box is two-way coupled (B_f not empty), no contacts",
                  moving.fluid_body_jacobian().nonZeros() > 0 && moving.num_contacts() == 0);
    nb.check("max |b1| / (|v0| / dx)", moving.b1().cwiseAbs().maxCoeff() / b_scale, 1e-13);
    nb.check("max |b2| / (|v0| / dx)", moving.b2().cwiseAbs().maxCoeff() / b_scale, 1e-13);
    notebook::CoupledStep<2> resting = f;
    resting.bodies[0].velocity.setZero();
    resting.contact_system = ContactSystem<2>(resting.bodies, resting.contacts, f.contact_system.params);
    const MonolithicSystem<2> still = make_system<2>(resting);
    nb.md("With the box at rest instead, max |b2| / (|v0| / dx) = " +
          sci(still.b2().cwiseAbs().maxCoeff() / b_scale) + ": the liquid runs into it.");
    nb.check("control: the box at rest gives b2 != 0, 0.1 - max |b2| / (|v0| / dx)",
             0.1 - still.b2().cwiseAbs().maxCoeff() / b_scale, 0.0);
  }

  nb.md("## Figure: the sparsity pattern of A\n"
        "Blue: entries of the Stokes part F (sparse, the (tau, p) corner). Orange: entries that only "
        "the rigid part dt alpha B^T M_r^-1 B creates; they fill whole rows and columns of the "
        "body-surface unknowns and the lambda, z blocks (section 4.4.3). Red: block boundaries "
        "tau | p | lambda | z.");
  {
    int rigid_only = 0;
    const Image img = sparsity_figure(d, std::max(3, 480 / static_cast<int>(A.rows())), &rigid_only);
    nb.figure("08_sparsity.ppm", img, "sparsity of A, fluid (blue) and rigid-only (orange) entries");
    nb.md(std::to_string(rigid_only) + " entries come from the rigid part alone.");
    nb.check_true("the rigid part adds entries the Stokes matrix does not have", rigid_only > 0);
  }

  nb.md("## 3D: the same identities on a 4 x 4 x 4 tank\n"
        "An untilted box resting on the floor (four corner contacts, eight friction rows), water "
        "up to 0.55 m.");
  {
    const notebook::CoupledStep<3> s3 = tank_step<3>(1.0, 4);
    const MonolithicSystem<3> sys3 = make_system<3>(s3);
    const Eigen::MatrixXd A3 = sys3.dense_matrix();
    const DenseParts d3 = dense_parts<3>(sys3);
    const double scale3 = A3.cwiseAbs().maxCoeff();
    nb.md("sizes: tau " + std::to_string(sys3.num_stress()) + ", p " + std::to_string(sys3.num_pressure()) +
          ", lambda " + std::to_string(sys3.num_contacts()) + ", z " + std::to_string(sys3.num_friction()) +
          ", nd " + std::to_string(sys3.num_body_dofs()));
    nb.check_true("3D: the box touches the floor and the liquid", sys3.num_contacts() > 0 &&
                                                                     sys3.fluid_body_jacobian().nonZeros() > 0);
    nb.check("3D symmetry: max |A - A^T| / max |A|", (A3 - A3.transpose()).cwiseAbs().maxCoeff() / scale3, 1e-13);
    nb.check("3D: max |A (right-to-left) - (F + dt alpha B^T M_r^-1 B)| / max |A|",
             (A3 - d3.F - d3.R).cwiseAbs().maxCoeff() / scale3, 1e-13);
    const Eigen::VectorXd ev3 = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(0.5 * (A3 + A3.transpose())).eigenvalues();
    int zero = 0;
    for (int k = 0; k < ev3.size(); ++k) zero += ev3[k] < 1e-10 * ev3.maxCoeff();
    nb.md("Eigenvalues: smallest " + sci(ev3.minCoeff()) + ", largest " + sci(ev3.maxCoeff()) + "; " +
          std::to_string(zero) + " below 1e-10 of the largest. Four contacts with two friction rows "
          "each are 12 rows on nd = 6 body DOFs: (24) is only semi-definite here (redundant "
          "contact rows; the solver's (26) and (25) get the diagonal boost 1 + gamma of section "
          "4.4.5 on their contact rows).");
    nb.check("3D semi-definite: -lambda_min / lambda_max", -ev3.minCoeff() / ev3.maxCoeff(), 1e-12);
    nb.check_true("3D: the null space has dimension (nc + nf) - nd = 6",
                  zero == sys3.num_contacts() + sys3.num_friction() - sys3.num_body_dofs());
  }
  return nb.finish();
}
