// Notebook 04: the Stokes minimisation of eq. (8), its SPD system (the tau, p blocks of eq. (24))
// and the energy it minimises.
//
// Run: build/notebooks/notebook_04_stokes_minimisation --out DIR   (writes DIR/transcript.md)
#include <Eigen/Dense>
#include <cmath>
#include <memory>

#include "notebooks_cpp/notebook.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/oracle/cholmod_solver.hpp"
#include "reference/viz/plot.hpp"

using namespace monolith;

namespace {

/// A ball solid for the level sets.
class Ball : public Shape<2> {
 public:
  Ball(const Vec<2>& c, double r) : c_(c), r_(r) {}
  double distance(const Vec<2>& x) const override { return (x - c_).norm() - r_; }
  Vec<2> gradient(const Vec<2>& x) const override { return (x - c_).normalized(); }
  Box<2> bounds() const override { return Box<2>(c_ - Vec<2>::Constant(r_), c_ + Vec<2>::Constant(r_)); }

 private:
  Vec<2> c_;
  double r_;
};

/// Weights of eq. (8): liquid below y = level (level > 1: full), a solid ball if `solid`.
StokesWeights weights(const MacGrid<2>& grid, const std::array<BoundaryType, 4>& boundary, double level,
                      bool solid, double rho, double eta) {
  const SampleLattice<2> lattice = half_lattice(grid);
  std::vector<ShapePtr<2>> solids;
  if (solid) solids.push_back(std::make_shared<Ball>(Vec<2>(0.6, 0.3), 0.15));
  const VectorX solid_phi = solid_phi_on_lattice<2>(grid, lattice, solids, 0.0);
  VectorX liquid(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) liquid[k] = lattice.position(lattice.coord(k))[1] - level;
  return uniform_stokes_weights(grid, solid_phi, liquid, boundary, rho, eta);
}

std::string str(double v) {
  std::ostringstream s;
  s << std::setprecision(6) << v;
  return s.str();
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "04 The Stokes minimisation (8) and its SPD system");

  nb.md("## Eq. (8) and its optimality system\n"
        "E_f(tau, p) = 1/2 ||u* - dt P^-1 (W_L^u)^-1 (G W_L^p p + D^T M W_L^s tau)||^2_{P W^u} + "
        "dt/4 tau^T N^-1 W^s tau, with M = diag(multiplicity) and N^-1 = M / eta (docs/stokes.md). "
        "Setting its gradient to zero and dividing by dt gives [A11 A12; A12^T A22] (tau, p) = (b1, b2):\n\n"
        "- A11 = 1/2 N^-1 W^s + dt W_L^s M D C' D^T M W_L^s,  C' = W_F^u P^-1 (W_L^u)^-1\n"
        "- A12 = dt W_L^s M D C' G W_L^p,  A22 = dt W_L^p G^T C' G W_L^p\n"
        "- b1 = W_L^s M D W_F^u u*,  b2 = W_L^p G^T W_F^u u*\n\n"
        "(reduced form: E^T on the left of the tau rows, E on the right of the tau columns).");

  nb.md("## Worked example: one shear DOF on a 2 x 2 grid\n"
        "dx = 1, rho = 1, walls all round, full of liquid; eta = 1/2 at the centre node only (every "
        "other stress DOF inviscid, so tau_xy at node (1, 1) is the single unknown), dt = 1/4, stress "
        "only. u* is a shear: u = -a on the x-face (1, 0) below the node, +a on (1, 1) above it, a = 1, "
        "v = 0. By hand: the node's row of D has +-1/2 on its four faces, M = 2, so B = D^T M W_L^s "
        "has +-1 there; A11 = 1/2 (2/eta) 1 + dt (1 + 1 + 1 + 1) = 1/eta + 4 dt = 3; "
        "b1 = (u(1,1) - u(1,0)) + (v(1,1) - v(0,1)) = 2a = 2; tau = 2/3 = 2 eta a / (1 + 4 eta dt). "
        "The update moves each of the four faces by -+dt tau = -+1/6: u = -+5/6, v(1,1) = -1/6, "
        "v(0,1) = +1/6, so D_xy(u_new) = 1/2 (10/6 - 2/6) = 2/3 and 2 eta D_xy(u_new) = 2/3 = tau.");
  {
    const MacGrid<2> grid(Vec<2>::Zero(), 1.0, VecI<2>(2, 2), {false, false});
    const StressGrid<2> stress(grid);
    std::array<BoundaryType, 4> walls;
    walls.fill(BoundaryType::wall);
    StokesWeights w = weights(grid, walls, 10.0, false, 1.0, 0.0);
    const int node = stress.index(2, VecI<2>(1, 1));
    w.viscosity[node] = 0.5;
    const double dt = 0.25;
    VectorX u_star = VectorX::Zero(grid.num_faces());
    u_star[grid.face_index(0, VecI<2>(1, 0))] = -1.0;
    u_star[grid.face_index(0, VecI<2>(1, 1))] = 1.0;
    const StressLayout<2> layout(stress, StressForm::full);
    const StokesDofs dofs = select_stokes_dofs(grid, layout, w, dt, StokesUnknowns::stress_only);
    const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, w, dofs, dt, u_star);
    nb.check_true("a single unknown", dofs.size() == 1);
    nb.check("A11 = 1/eta + 4 dt = 3", std::abs(Eigen::MatrixXd(sys.A11)(0, 0) - 3.0), 1e-15);
    nb.check("b1 = 2a = 2", std::abs(sys.b1[0] - 2.0), 1e-15);
    VectorX u = u_star;
    const auto r = solve_stokes(grid, w, dt, StokesUnknowns::stress_only, StressForm::full, Backend::explicit_matrices, PcgSettings{}, u);
    nb.check("tau = 2/3", std::abs(r.stress[node] - 2.0 / 3.0), 1e-14);
    nb.check("u(1,1) = 5/6", std::abs(u[grid.face_index(0, VecI<2>(1, 1))] - 5.0 / 6.0), 1e-14);
    nb.check("v(1,1) = -1/6", std::abs(u[grid.face_index(1, VecI<2>(1, 1))] + 1.0 / 6.0), 1e-14);
    nb.check("v(0,1) = +1/6", std::abs(u[grid.face_index(1, VecI<2>(0, 1))] - 1.0 / 6.0), 1e-14);
  }

  nb.md("## The PV system on an 8 x 8 tank\n"
        "Liquid below y = 0.55 with a solid ball in it, walls at the sides and bottom, open top; "
        "rho = 1000, eta = 5, dt = 0.01, u* random.");
  const MacGrid<2> grid(Vec<2>::Zero(), 1.0 / 8, VecI<2>(8, 8), {false, false});
  std::array<BoundaryType, 4> tank{BoundaryType::wall, BoundaryType::wall, BoundaryType::wall, BoundaryType::open};
  const StokesWeights w = weights(grid, tank, 0.55, true, 1000.0, 5.0);
  const double dt = 0.01;
  std::srand(5);
  const VectorX u_star = VectorX::Random(grid.num_faces());
  for (StressForm form : {StressForm::full, StressForm::reduced}) {
    const std::string name = form == StressForm::full ? "full" : "reduced";
    const StressLayout<2> layout(StressGrid<2>(grid), form);
    const StokesDofs dofs = select_stokes_dofs(grid, layout, w, dt, StokesUnknowns::pressure_and_stress);
    const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, w, dofs, dt, u_star);
    const Eigen::MatrixXd A(sys.A);
    nb.md(name + " form: " + std::to_string(dofs.num_stress()) + " stress and " +
          std::to_string(dofs.num_pressure()) + " pressure unknowns; A11 " +
          std::to_string(sys.A11.rows()) + " x " + std::to_string(sys.A11.cols()) + ", A12 " +
          std::to_string(sys.A12.rows()) + " x " + std::to_string(sys.A12.cols()) + ", A22 " +
          std::to_string(sys.A22.rows()) + " x " + std::to_string(sys.A22.cols()) + ".");
    nb.check(name + ": symmetry ||A - A^T||_max / ||A||_max",
             (A - A.transpose()).cwiseAbs().maxCoeff() / A.cwiseAbs().maxCoeff(), 1e-15);
    const Eigen::VectorXd eig = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(A).eigenvalues();
    nb.md(name + ": eigenvalues in [" + str(eig.minCoeff()) + ", " + str(eig.maxCoeff()) + "]");
    nb.check(name + ": positive definite, -lambda_min / lambda_max", -eig.minCoeff() / eig.maxCoeff(), -1e-12);
    PcgSettings settings;
    settings.tolerance = 1e-10;
    const MatrixFreeStokesOperator<2> op(grid, layout, w, dofs, dt);
    VectorX x = VectorX::Zero(dofs.size());
    const PcgResult pr = pcg_solve(op, op.rhs(u_star), x, settings);
    const VectorX x_chol = cholmod_solve(sys.A, sys.b);
    nb.md(name + ": SSOR-PCG (matrix-free) took " + std::to_string(pr.iterations) + " iterations to 1e-10.");
    nb.check(name + ": PCG against CHOLMOD, relative", (x - x_chol).norm() / x_chol.norm(), 1e-7);
  }

  nb.md("## The energy\n"
        "E_f (stokes_energy) is a quadratic in x = (tau, p): E_f(x) = E_f(0) + dt (1/2 x^T A x - b~^T x), "
        "where b~ is b with u* read only on faces with W_L^u > 0. The paper's b (and this code) reads "
        "W_F^u u* on every face of a stress stencil; the two differ only on dry faces touched by the "
        "stencil of a wet node at the surface, where the stress then sees the (extrapolated) air "
        "velocity, which is what makes tau = 2 eta D u_new hold there too. Below, a tank full of "
        "liquid (b~ = b): the identity, the minimum at the solution, and E_f decreasing along the "
        "(preconditioned) CG iterates, each of which minimises E_f over a growing Krylov space.");
  {
    const StokesWeights wf = weights(grid, tank, 10.0, true, 1000.0, 5.0);
    const StressLayout<2> layout(StressGrid<2>(grid), StressForm::reduced);
    const StokesDofs dofs = select_stokes_dofs(grid, layout, wf, dt, StokesUnknowns::pressure_and_stress);
    const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, wf, dofs, dt, u_star);
    auto energy = [&](const VectorX& x) { return stokes_energy(grid, layout, wf, dofs, dt, u_star, x); };
    const double e0 = energy(VectorX::Zero(dofs.size()));
    double worst = 0.0;
    for (unsigned seed = 1; seed <= 3; ++seed) {
      std::srand(seed);
      const VectorX x = VectorX::Random(dofs.size());
      const double quadratic = e0 + dt * (0.5 * x.dot(sys.A * x) - sys.b.dot(x));
      worst = std::max(worst, std::abs(energy(x) - quadratic) / std::abs(energy(x)));
    }
    nb.check("E_f(x) = E_f(0) + dt (1/2 x^T A x - b^T x), relative, random x", worst, 1e-12);
    const VectorX x_star = cholmod_solve(sys.A, sys.b);
    const double e_star = energy(x_star);
    double lowest_neighbour = 1e300;
    for (unsigned seed = 10; seed < 20; ++seed) {
      std::srand(seed);
      lowest_neighbour = std::min(lowest_neighbour, energy(x_star + 1e-3 * VectorX::Random(dofs.size())));
    }
    nb.check_true("E_f at the solution is below E_f at 10 random perturbations", e_star < lowest_neighbour);
    nb.md("E_f(0) = " + str(e0) + " (J/m^3 summed over the control volumes), E_f(x*) = " + str(e_star));
    std::vector<double> history;
    const SparseMatrixOperator op(sys.A);
    for (int k = 0; k <= 12; ++k) {
      PcgSettings s;
      s.tolerance = 0.0;
      s.max_iterations = k;
      VectorX x = VectorX::Zero(dofs.size());
      pcg_solve(op, sys.b, x, s);
      history.push_back(energy(x));
    }
    std::ostringstream s;
    s << "E_f along the PCG iterates 0..12:";
    for (double e : history) s << " " << std::setprecision(8) << e;
    nb.md(s.str());
    double rise = 0.0;
    for (size_t k = 1; k < history.size(); ++k) rise = std::max(rise, history[k] - history[k - 1]);
    nb.check("largest increase of E_f between iterates (relative to E_f(0))", rise / e0, 1e-14);
    nb.check_true("E_f(iterate 12) approaches E_f(x*)", history.back() - e_star < 1e-3 * (e0 - e_star));
    PlotSpec spec;
    spec.title = "E_f along the PCG iterates";
    spec.x_label = "PCG iteration";
    spec.y_label = "E_f";
    PlotSeries along;
    along.label = "E_f(x_k)";
    along.marker = Marker::circle;
    PlotSeries optimum;
    optimum.label = "E_f(x*) (CHOLMOD)";
    optimum.dash = 6.0;
    for (std::size_t k = 0; k < history.size(); ++k) {
      along.x.push_back(static_cast<double>(k));
      along.y.push_back(history[k]);
      optimum.x.push_back(static_cast<double>(k));
      optimum.y.push_back(e_star);
    }
    spec.series = {along, optimum};
    nb.figure("04_energy.ppm", plot_lines(spec), "E_f along the PCG iterates, and its minimum");
  }
  return nb.finish();
}
