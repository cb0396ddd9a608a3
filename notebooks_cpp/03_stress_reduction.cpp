// Notebook 03: the deformation rate D, the viscosity matrix N and the stress reduction of
// section 4.4.2 (full vs reduced stress unknowns, the factor 2 of tau = 2 eta D u).
//
// Run: build/notebooks/notebook_03_stress_reduction --out DIR   (writes DIR/transcript.md)
#include <Eigen/Dense>
#include <cmath>

#include "notebooks_cpp/notebook.hpp"
#include "reference/fluid/deformation_rate.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/oracle/cholmod_solver.hpp"

using namespace monolith;

namespace {

/// Weights of eq. (8) for a box full of liquid (no solids), with the given boundary types.
template <int Dim>
StokesWeights full_box(const MacGrid<Dim>& grid, const std::array<BoundaryType, 2 * Dim>& boundary,
                       double rho, double eta) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX no_solid = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
  const VectorX liquid = VectorX::Constant(lattice.size(), -1.0);
  return uniform_stokes_weights(grid, no_solid, liquid, boundary, rho, eta);
}

VectorX random_field(int n, unsigned seed) {
  std::srand(seed);
  return VectorX::Random(n);
}

/// Solves eq. (8) exactly (CHOLMOD) and returns (tau_full, u_new).
template <int Dim>
std::pair<VectorX, VectorX> exact_solve(const MacGrid<Dim>& grid, const StokesWeights& w, double dt,
                                        const VectorX& u_star, StokesUnknowns unknowns, StressForm form) {
  const StressLayout<Dim> layout(StressGrid<Dim>(grid), form);
  const StokesDofs dofs = select_stokes_dofs(grid, layout, w, dt, unknowns);
  const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, w, dofs, dt, u_star);
  const VectorX x = cholmod_solve(sys.A, sys.b);
  const VectorX tau = scatter_stress(layout, dofs, x);
  VectorX u = u_star;
  apply_stokes_update(grid, layout, w, dt, scatter_stokes_pressure(dofs, x, grid.num_cells()), tau, u);
  return {tau, u};
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "03 D, N and the stress reduction");

  nb.md("## D on a 2 x 2 grid\n"
        "Stress DOFs (reference/grid/stress_grid.hpp): tau_xx and tau_yy at the 4 cell centres, tau_xy at "
        "the 9 nodes; rows of D in that order (xx, yy, xy). Columns: the 6 x-faces then the 6 "
        "y-faces. Diagonal rows are (u_a(c + e_a) - u_a(c)) / dx, off-diagonal rows "
        "1/2 (du_a/db + du_b/da) from the four faces around the node; faces outside the domain are "
        "omitted (zero velocity).");
  const MacGrid<2> g2(Vec<2>::Zero(), 1.0, VecI<2>(2, 2), {false, false});
  const StressGrid<2> s2(g2);
  const SparseMatrix D2 = deformation_rate_matrix(s2);
  nb.matrix("D (dx = 1)", Eigen::MatrixXd(D2), 1);
  nb.check_true("D is 17 x 12", D2.rows() == 17 && D2.cols() == 12);
  {
    // figure: D as a picture, one square per entry (coolwarm: -1 blue, 0 white-grey, +1 red)
    const Eigen::MatrixXd Dd(D2);
    const int px = 20;
    Image img(static_cast<int>(Dd.cols()) * px, static_cast<int>(Dd.rows()) * px, {255, 255, 255});
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        const double v = Dd(y / px, x / px);
        if (v != 0.0) img.set(x, y, colormap_coolwarm(0.5 + 0.5 * v));
        if (x % px == 0 || y % px == 0) img.set(x, y, {220, 220, 220});
      }
    nb.figure("03_D.ppm", img, "D (17 x 12): rows xx, yy at the cells, then xy at the nodes; blue -1, red +1");
  }
  {
    // a diagonal row: -1/dx and +1/dx on the two faces of its cell along its axis; D of a constant
    // velocity is zero on every DOF whose faces all lie inside the domain
    const Eigen::MatrixXd Dd(D2);
    double worst_row = 0.0;
    for (int a = 0; a < 2; ++a)
      for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
          const VecI<2> c(i, j);
          Eigen::RowVectorXd expected = Eigen::RowVectorXd::Zero(g2.num_faces());
          expected[g2.face_index(a, c)] = -1.0;
          expected[g2.face_index(a, c + unit_offset<2>(a))] = 1.0;
          worst_row = std::max(worst_row, (Dd.row(s2.index(a, c)) - expected).cwiseAbs().maxCoeff());
        }
    nb.check("rows tau_aa: (u_a(c + e_a) - u_a(c)) / dx, max deviation", worst_row, 0.0);
    const VectorX constant = VectorX::Ones(g2.num_faces());
    const int centre_node = s2.index(2, VecI<2>(1, 1));
    nb.check("D of a constant field at the interior node (1, 1) and the cells", std::abs((D2 * constant)[centre_node]) +
                 (D2 * constant).head(8).cwiseAbs().maxCoeff(), 0.0);
    nb.check("the interior node's row: four entries +-1/2", std::abs(Dd.row(centre_node).cwiseAbs().sum() - 2.0) +
                 std::abs(Dd.row(centre_node).cwiseAbs().maxCoeff() - 0.5), 1e-15);
  }

  nb.md("## The factor 2: M, N and tau = 2 eta D u\n"
        "One off-diagonal DOF stands for tau_xy and tau_yx. It counts twice in ||tau||_F^2 and twice "
        "in div tau (D^T M tau is minus the divergence of the symmetric tensor), with "
        "M = diag(1, 1, 2) per component. Discretising eq. (7) with control volumes dx^Dim gives the "
        "stress term dt/4 tau^T N^-1 W^s tau with N^-1 = M / eta (N = eta / m per DOF), and the "
        "minimum over tau satisfies 1/2 N^-1 W^s tau = W_L^s M D W_F^u u_new, i.e. "
        "tau = 2 eta D u_new where the weights are 1 (eq. (5)).");
  const double eta = 1.0;
  const StressLayout<2> full2(s2, StressForm::full), red2(s2, StressForm::reduced);
  const VectorX eta2 = VectorX::Constant(s2.num_dofs(), eta);
  nb.matrix("diagonal of N, full form (eta = 1): xx, yy, then xy", Eigen::MatrixXd(viscosity_matrix(full2, eta2)).diagonal().transpose(), 2);
  nb.matrix("E, reduced form (2D): rows xx, yy, xy DOFs; columns the xx, xy unknowns",
            Eigen::MatrixXd(red2.expansion()), 0);
  const Eigen::MatrixXd n_full = Eigen::MatrixXd(viscosity_matrix(full2, eta2));
  {
    // N = eta / m: eta on the 8 diagonal DOFs (xx, yy at 4 cells), eta / 2 on the 9 xy nodes
    Eigen::VectorXd expected(s2.num_dofs());
    expected << Eigen::VectorXd::Constant(8, eta), Eigen::VectorXd::Constant(9, eta / 2.0);
    nb.check("full N = diag(eta / m): max deviation", (n_full.diagonal() - expected).cwiseAbs().maxCoeff(), 1e-15);
  }
  const Eigen::MatrixXd n_red = Eigen::MatrixXd(viscosity_matrix(red2, eta2));
  nb.matrix("diagonal of N, reduced form: tau_xx unknowns (eta/2: H merged in), then xy",
            n_red.diagonal().transpose(), 2);
  // 2D reduced: tau_yy = -tau_xx, so tau_xx counts twice in ||tau||_F^2: N^-1 = 2 / eta, N = eta / 2
  nb.check("reduced N: eta / 2 on every unknown (tau_xx with H merged in, tau_xy with m = 2), max deviation",
           (n_red.diagonal().array() - eta / 2.0).abs().maxCoeff(), 1e-15);
  const Eigen::MatrixXd n_red_inv = Eigen::MatrixXd(inverse_viscosity_matrix(red2, eta2));
  const Eigen::MatrixXd E2 = Eigen::MatrixXd(red2.expansion());
  const Eigen::MatrixXd n_full_inv = Eigen::MatrixXd(inverse_viscosity_matrix(full2, eta2));
  nb.check("N^-1 (reduced) = E^T N^-1 (full) E", (n_red_inv - E2.transpose() * n_full_inv * E2).cwiseAbs().maxCoeff(), 1e-15);
  nb.check("N N^-1 = I (reduced)", (n_red * n_red_inv - Eigen::MatrixXd::Identity(n_red.rows(), n_red.cols())).cwiseAbs().maxCoeff(), 1e-14);

  nb.md("### 3D: the block of one cell\n"
        "With tau_zz = -(tau_xx + tau_yy) the stress energy of a cell is (tau_xx^2 + tau_yy^2 + "
        "(tau_xx + tau_yy)^2) / (2 eta), so N^-1 = [2 1; 1 2] / eta on (tau_xx, tau_yy) and "
        "N = eta/3 [2 -1; -1 2]: the paper's 1/2 H tau = N D u with H merged into N.");
  const MacGrid<3> g3(Vec<3>::Zero(), 1.0, VecI<3>(1, 1, 1), {false, false, false});
  const StressGrid<3> s3(g3);
  const StressLayout<3> red3(s3, StressForm::reduced);
  const VectorX eta3 = VectorX::Constant(s3.num_dofs(), 3.0);
  const Eigen::MatrixXd n3 = Eigen::MatrixXd(viscosity_matrix(red3, eta3)).topLeftCorner(2, 2);
  const Eigen::MatrixXd n3_inv = Eigen::MatrixXd(inverse_viscosity_matrix(red3, eta3)).topLeftCorner(2, 2);
  nb.matrix("N block of the diagonal unknowns (eta = 3)", n3, 3);
  nb.matrix("N^-1 block (eta = 3)", n3_inv, 3);
  Eigen::Matrix2d expected;
  expected << 2, -1, -1, 2;
  nb.check("N block = eta/3 [2 -1; -1 2]", (n3 - expected).cwiseAbs().maxCoeff(), 1e-14);
  Eigen::Matrix2d expected_inv;
  expected_inv << 2, 1, 1, 2;
  nb.check("N^-1 block = [2 1; 1 2] / eta", (n3_inv - expected_inv / 3.0).cwiseAbs().maxCoeff(), 1e-15);

  nb.md("## At the optimum: tau = 2 eta D u_new\n"
        "A 6 x 6 periodic box of liquid (rho = 1000, eta = 2, dt = 0.01) with a random u*, solved "
        "exactly (CHOLMOD). With all weights 1 the optimality condition of every stress unknown says "
        "tau = 2 eta D u_new.");
  const MacGrid<2> g6(Vec<2>::Zero(), 1.0 / 6, VecI<2>(6, 6), {true, true});
  const StressGrid<2> s6(g6);
  std::array<BoundaryType, 4> periodic;
  periodic.fill(BoundaryType::periodic);
  const double eta6 = 2.0, dt = 0.01;
  const StokesWeights w6 = full_box<2>(g6, periodic, 1000.0, eta6);
  const VectorX u_star = random_field(g6.num_faces(), 3);
  const SparseMatrix D6 = deformation_rate_matrix(s6);
  for (StressForm form : {StressForm::full, StressForm::reduced}) {
    const auto [tau, u] = exact_solve<2>(g6, w6, dt, u_star, StokesUnknowns::pressure_and_stress, form);
    const VectorX residual = tau - 2.0 * eta6 * (D6 * u);
    nb.check(std::string(form == StressForm::full ? "full" : "reduced") +
                 " form: max |tau - 2 eta D u_new| / max |tau|",
             residual.cwiseAbs().maxCoeff() / tau.cwiseAbs().maxCoeff(), 1e-11);
  }

  nb.md("## Full vs reduced\n"
        "The reduced form minimises eq. (8) over traceless tau only. The full optimum has trace "
        "2 eta (sum_a D_aa u_new) = 2 eta div u_new (weighted), which the pressure makes zero: the "
        "pressure-viscosity (PV) solve gives the same velocity in both forms (to round-off), also with "
        "a free surface and solids (tests/test_stokes.cpp). The stress-only VC step of PC-VC-PC has no "
        "pressure, u_new is not divergence free there, and the forms differ.");
  for (StokesUnknowns unknowns : {StokesUnknowns::pressure_and_stress, StokesUnknowns::stress_only}) {
    const auto full = exact_solve<2>(g6, w6, dt, u_star, unknowns, StressForm::full);
    const auto reduced = exact_solve<2>(g6, w6, dt, u_star, unknowns, StressForm::reduced);
    const double diff = (full.second - reduced.second).cwiseAbs().maxCoeff() / full.second.cwiseAbs().maxCoeff();
    std::ostringstream s;
    s << (unknowns == StokesUnknowns::pressure_and_stress ? "PV" : "VC") << " solve: max |u_full - u_reduced| / max |u| = " << std::scientific << diff;
    nb.md(s.str());
    if (unknowns == StokesUnknowns::pressure_and_stress)
      nb.check("PV: full and reduced velocity updates agree", diff, 1e-12);
    else
      nb.check_true("VC: the forms differ (the VC optimum has a trace)", diff > 1e-4);
  }
  // and a VC step on a divergence-free u* (what PC-VC-PC feeds it)
  nb.md("### VC after a pressure projection\n"
        "PC-VC-PC feeds the VC step a weighted-divergence-free u*. With constant eta on this uniform "
        "periodic grid the discrete viscous operator D^T M D commutes with the divergence (it is "
        "eta (Laplacian + grad div) on the MAC grid), so the VC step keeps u divergence free, the "
        "full optimum stays traceless and the forms agree. A spatially varying eta breaks the "
        "commutation: the forms then differ by the amount measured below.");
  VectorX u_div_free = u_star;
  PcgSettings tight;
  tight.tolerance = 1e-13;
  solve_pressure<2>(g6, w6.pressure, dt, Backend::explicit_matrices, tight, u_div_free);
  StokesWeights w_var = w6;
  for (int d = 0; d < s6.num_dofs(); ++d) {
    const auto [k, c] = s6.coord(d);
    const Vec<2> x = s6.position(k, c);
    w_var.viscosity[d] = eta6 * (1.0 + 0.5 * std::sin(2.0 * M_PI * x[0]));
  }
  for (bool varying : {false, true}) {
    const StokesWeights& w = varying ? w_var : w6;
    const auto vc_full = exact_solve<2>(g6, w, dt, u_div_free, StokesUnknowns::stress_only, StressForm::full);
    const auto vc_red = exact_solve<2>(g6, w, dt, u_div_free, StokesUnknowns::stress_only, StressForm::reduced);
    const double diff = (vc_full.second - vc_red.second).cwiseAbs().maxCoeff() / vc_full.second.cwiseAbs().maxCoeff();
    std::ostringstream s;
    s << "VC on divergence-free u*, " << (varying ? "eta = 2 (1 + sin(2 pi x) / 2)" : "constant eta = 2")
      << ": max |u_full - u_reduced| / max |u| = " << std::scientific << diff;
    nb.md(s.str());
    if (varying)
      nb.check_true("varying eta: the VC forms differ", diff > 1e-6);
    else
      nb.check("constant eta, periodic: the VC forms agree", diff, 1e-12);
  }
  return nb.finish();
}
