// Notebook 02: the gradient G, the weighted divergence, and the variational pressure solve
// (eq. (8) without stress, which is eq. (18) without bodies; A22 and b2 of eq. (24)).
//
// Run: build/notebooks/notebook_02_gradient_and_divergence --out DIR
#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "notebooks_cpp/notebook.hpp"
#include "reference/fluid/gradient.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/oracle/cholmod_solver.hpp"
#include "reference/solvers/pcg.hpp"

using namespace monolith;

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "02 The gradient G and the weighted divergence");

  nb.md("## G on a 3 x 2 grid\n"
        "Row f of G is (p_plus - p_minus) / dx for the two cells beside face f; on a boundary face "
        "the outside cell is omitted (air pressure 0 beyond an open face; a wall face has W_F^u = 0, "
        "so its row never contributes). `gradient_matrix` in reference/fluid/gradient.hpp.");
  const MacGrid<2> small(Vec<2>::Zero(), 1.0, VecI<2>(3, 2), {false, false});
  const SparseMatrix G_small = gradient_matrix<2>(small);
  nb.matrix("G (dx = 1): rows are the 8 x-faces then the 9 y-faces, columns the 6 cells",
            Eigen::MatrixXd(G_small), 0);
  {
    // row f: +1 at the cell above the face, -1 at the cell below it, the outside cell omitted
    const Eigen::MatrixXd Gd(G_small);
    double worst = 0.0;
    for (int f = 0; f < small.num_faces(); ++f) {
      const auto [axis, coord] = small.face_coord(f);
      Eigen::RowVectorXd expected = Eigen::RowVectorXd::Zero(small.num_cells());
      if (coord[axis] > 0) expected[small.face_cell_minus(axis, coord)] = -1.0;
      if (coord[axis] < small.cells()[axis]) expected[small.face_cell_plus(axis, coord)] = 1.0;
      worst = std::max(worst, (Gd.row(f) - expected).cwiseAbs().maxCoeff());
    }
    nb.check("every row of G is (p_plus - p_minus) / dx with the outside cell omitted, max deviation", worst, 0.0);
  }

  nb.md("## -G^T is the divergence\n"
        "For any face field u and face weights W, G^T W u summed cell by cell is minus the net "
        "weighted outflow: (G^T W u)_c = -sum over faces of c of (outward sign) W_f u_f / dx. Below "
        "that sum is written out independently and compared, on a 16 x 12 grid with random data.");
  const MacGrid<2> grid(Vec<2>::Zero(), 1.0 / 16, VecI<2>(16, 12), {false, false});
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  VectorX u(grid.num_faces()), w(grid.num_faces()), p(grid.num_cells());
  for (int f = 0; f < grid.num_faces(); ++f) u[f] = uni(rng), w[f] = 0.5 + 0.5 * uni(rng);
  for (int c = 0; c < grid.num_cells(); ++c) p[c] = uni(rng);
  const SparseMatrix G = gradient_matrix<2>(grid);
  VectorX divergence = VectorX::Zero(grid.num_cells());
  for (int c = 0; c < grid.num_cells(); ++c) {
    const VecI<2> cc = grid.cell_coord(c);
    for (int a = 0; a < 2; ++a) {
      const VecI<2> lo = cc, hi = cc + unit_offset<2>(a);
      const int f_lo = grid.face_index(a, lo), f_hi = grid.face_index(a, hi);
      divergence[c] += (w[f_hi] * u[f_hi] - w[f_lo] * u[f_lo]) / grid.dx();
    }
  }
  const VectorX GtWu = G.transpose() * w.asDiagonal() * u;
  nb.check("max |G^T W u + div_W u|", (GtWu + divergence).cwiseAbs().maxCoeff(), 1e-12);
  const double lhs = (G * p).dot(w.asDiagonal() * u), rhs = -p.dot(divergence);
  nb.check("adjointness |<G p, W u> - <p, -div_W u>|", std::abs(lhs - rhs), 1e-10 * std::abs(lhs));
  nb.check("matrix-free G p equals the matrix", (apply_gradient<2>(grid, p) - G * p).cwiseAbs().maxCoeff(), 1e-12);

  nb.md("## The pressure solve as a minimisation\n"
        "Liquid below y = 0.4 in a walled tank open at the top, falling at u* = -g dt. Eq. (8) "
        "without stress: p = argmin 1/2 || u* - dt P^-1 (W_L^u)^-1 G W_L^p p ||^2 over M_f = P W^u. "
        "Its optimality condition is A p = b with A = dt W_L^p G^T W_F^u P^-1 (W_L^u)^-1 G W_L^p "
        "and b = W_L^p G^T W_F^u u* (A22 and b2 of eq. (24)).");
  const SampleLattice<2> lattice = half_lattice(grid);
  VectorX liquid_phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) liquid_phi[k] = lattice.position(lattice.coord(k))[1] - 0.4;
  const VectorX no_solid = VectorX::Constant(lattice.size(), std::numeric_limits<double>::infinity());
  const std::array<BoundaryType, 4> boundary{BoundaryType::wall, BoundaryType::wall, BoundaryType::wall,
                                             BoundaryType::open};
  PressureWeights pw;
  pw.fluid_face = fluid_face_weights<2>(grid, lattice, no_solid, boundary);
  pw.liquid_cell = liquid_cell_weights<2>(grid, lattice, liquid_phi);
  pw.liquid_face = liquid_face_weights<2>(grid, lattice, liquid_phi, pw.liquid_cell);
  pw.face_density = VectorX::Constant(grid.num_faces(), 1000.0);
  const double dt = 0.01, g = 9.81;
  VectorX u_star = VectorX::Zero(grid.num_faces());
  for (int f = grid.face_offset(1); f < grid.num_faces(); ++f) u_star[f] = pw.fluid_face[f] > 0 ? -g * dt : 0.0;
  const PressureDofs dofs = select_pressure_dofs<2>(grid, pw, dt);
  const ExplicitPressureSystem sys = assemble_explicit_pressure<2>(grid, pw, dofs, dt, u_star);
  const Eigen::MatrixXd A = Eigen::MatrixXd(sys.A);
  nb.md("The system has " + std::to_string(dofs.size()) + " pressure DOFs.");
  nb.check("symmetry ||A - A^T||_max / ||A||_max", (A - A.transpose()).cwiseAbs().maxCoeff() / A.cwiseAbs().maxCoeff(), 1e-14);
  const Eigen::VectorXd eig = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(A).eigenvalues();
  nb.check("positive definiteness: -lambda_min / lambda_max", -eig.minCoeff() / eig.maxCoeff(), -1e-8);

  PcgSettings settings;
  settings.tolerance = 1e-10;
  const SparseMatrixOperator op(sys.A);
  VectorX p_cg = VectorX::Zero(dofs.size());
  const PcgResult result = pcg_solve(op, sys.b, p_cg, settings);
  const VectorX p_chol = cholmod_solve(sys.A, sys.b);
  nb.md("SSOR-PCG took " + std::to_string(result.iterations) + " iterations.");
  nb.check("PCG against CHOLMOD, relative", (p_cg - p_chol).norm() / p_chol.norm(), 1e-8);

  // the new velocity is discretely divergence free in the weighted sense: b(u_new) = 0
  VectorX u_new = u_star;
  const VectorX pressure = scatter_pressure(dofs, p_chol, grid.num_cells());
  apply_pressure_update<2>(grid, pw, dt, pressure, u_new);
  const VectorX residual_div = sys.S * (pw.liquid_cell.asDiagonal() * (G.transpose() * (pw.fluid_face.asDiagonal() * u_new)));
  nb.check("weighted divergence W_L^p G^T W_F^u u_new after the update, max", residual_div.cwiseAbs().maxCoeff(), 1e-9);
  // hydrostatics: p = rho g depth at the cell centres below the surface row. The surface is at
  // 6.4 dx, so the face above the top liquid cell has no liquid and W_L^u is clamped there to
  // kMinLiquidFaceFraction (volume_fractions.hpp): that leaves a relative error of the order of
  // the clamp, which is the bound checked.
  double worst = 0.0;
  for (int k = 0; k < dofs.size(); ++k) {
    const int c = dofs.cell_of_dof[k];
    const double depth = 0.4 - grid.cell_center(grid.cell_coord(c))[1];
    if (depth > 1.5 * grid.dx()) worst = std::max(worst, std::abs(pressure[c] - 1000.0 * g * depth) / (1000.0 * g * depth));
  }
  nb.check("hydrostatic pressure p = rho g depth below the surface row, relative", worst, 2.0 * kMinLiquidFaceFraction);
  {
    // figure: the solved pressure per cell (viridis, 0 to its maximum), the surface at y = 0.4
    const int px = 24;
    const double p_max = pressure.maxCoeff();
    Image img(grid.cells()[0] * px, grid.cells()[1] * px, {255, 255, 255});
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x) {
        const int c = grid.cell_index(VecI<2>(x / px, (img.height - 1 - y) / px));
        if (pw.liquid_cell[c] > 0.0) img.set(x, y, colormap_viridis(pressure[c] / p_max));
        if (x % px == 0 || y % px == 0) img.set(x, y, {200, 200, 200});
      }
    nb.figure("02_pressure.ppm", img, "the solved pressure per liquid cell (viridis, 0 to " +
                                          std::to_string(static_cast<int>(p_max)) + " Pa), white: air");
  }
  // finite-difference check that the solution minimises the energy of eq. (8)
  auto energy = [&](const VectorX& q_dofs) {
    VectorX uu = u_star;
    apply_pressure_update<2>(grid, pw, dt, scatter_pressure(dofs, q_dofs, grid.num_cells()), uu);
    double e = 0.0;
    for (int f = 0; f < grid.num_faces(); ++f) e += 0.5 * pw.face_density[f] * pw.fluid_face[f] * pw.liquid_face[f] * uu[f] * uu[f];
    return e;
  };
  double worst_gradient = 0.0;
  const double h = 1e-3, scale = std::abs(energy(p_chol + VectorX::Constant(dofs.size(), h)) - energy(p_chol)) + 1e-30;
  for (int k = 0; k < dofs.size(); k += 7) {
    VectorX e = VectorX::Zero(dofs.size());
    e[k] = h;
    worst_gradient = std::max(worst_gradient, std::abs(energy(p_chol + e) - energy(p_chol - e)) / (2 * h));
  }
  nb.check("finite-difference gradient of E at the solution (relative to a unit step's change)", worst_gradient * h / scale, 1e-4);
  return nb.finish();
}
