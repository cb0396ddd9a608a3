// A user of the installed Monolith core (find_package(Monolith), target Monolith::core): builds
// the pressure system of eq. (8) (the A22, b2 blocks of eq. (24)) for a tiny 2D tank with the
// library, solves it with its own Jacobi-preconditioned CG, and checks the answer against the
// library's own solve (solve_pressure, SSOR-PCG on the matrix-free back end). Exit 0 if they
// agree, 1 if not.

#include <cmath>
#include <cstdio>

#include "reference/fluid/pressure_projection.hpp"
#include "reference/grid/mac_grid.hpp"

namespace {

using monolith::SparseMatrix;
using monolith::VectorX;

/// Conjugate gradients with the Jacobi preconditioner diag(A)^-1, written here and not taken
/// from the library: stops when ||r||_inf <= tolerance ||b||_inf.
VectorX jacobi_pcg(const SparseMatrix& a, const VectorX& b, double tolerance, int& iterations) {
  const VectorX inv_diag = a.diagonal().cwiseInverse();
  VectorX x = VectorX::Zero(b.size());
  VectorX r = b;
  VectorX z = inv_diag.cwiseProduct(r);
  VectorX d = z;
  double rz = r.dot(z);
  const double stop = tolerance * b.lpNorm<Eigen::Infinity>();
  for (iterations = 0; iterations < 10 * b.size() && r.lpNorm<Eigen::Infinity>() > stop; ++iterations) {
    const VectorX ad = a * d;
    const double step = rz / d.dot(ad);
    x += step * d;
    r -= step * ad;
    z = inv_diag.cwiseProduct(r);
    const double rz_next = r.dot(z);
    d = z + (rz_next / rz) * d;
    rz = rz_next;
  }
  return x;
}

}  // namespace

int main() {
  using namespace monolith;
  // a 12 x 12 tank of 1 m, water up to 5 cells, solid walls on every side
  const int n = 12;
  const MacGrid<2> grid(Vec<2>::Zero(), 1.0 / n, VecI<2>(n, n), {false, false});
  const double dt = 0.01;
  PressureWeights w;
  w.fluid_face = VectorX::Ones(grid.num_faces());
  w.liquid_face = VectorX::Ones(grid.num_faces());
  w.face_density = VectorX::Constant(grid.num_faces(), 1000.0);
  w.liquid_cell = VectorX::Zero(grid.num_cells());
  for (int k = 0; k < grid.num_cells(); ++k) {
    const VecI<2> c = grid.cell_coord(k);
    // the top liquid row is half full (a free surface inside a cell)
    w.liquid_cell[k] = c[1] < 5 ? 1.0 : (c[1] == 5 ? 0.5 : 0.0);
  }
  // u*: one step of gravity and a swirl, zero on the walls
  VectorX u_star = VectorX::Zero(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (grid.is_boundary_face(axis, coord)) {
      w.fluid_face[f] = 0.0;
      continue;
    }
    const Vec<2> x = grid.face_center(axis, coord);
    u_star[f] = axis == 1 ? -9.81 * dt + 0.3 * std::sin(3.0 * x[0]) : 0.2 * std::cos(2.0 * x[1]);
  }

  // the library builds the system ...
  const PressureDofs dofs = select_pressure_dofs<2>(grid, w, dt);
  const ExplicitPressureSystem system = assemble_explicit_pressure<2>(grid, w, dofs, dt, u_star);
  // ... this program solves it
  int iterations = 0;
  const VectorX p_mine = jacobi_pcg(system.A, system.b, 1e-12, iterations);
  const VectorX cells_mine = scatter_pressure(dofs, p_mine, grid.num_cells());

  // the library's own solve of the same step
  PcgSettings settings;
  settings.tolerance = 1e-12;
  VectorX u = u_star;
  const PressureSolveResult lib = solve_pressure<2>(grid, w, dt, Backend::matrix_free, settings, u);

  const double scale = lib.pressure.lpNorm<Eigen::Infinity>();
  const double difference = (cells_mine - lib.pressure).lpNorm<Eigen::Infinity>() / scale;
  const double residual = (system.A * p_mine - system.b).lpNorm<Eigen::Infinity>() /
                          system.b.lpNorm<Eigen::Infinity>();
  const bool ok = dofs.size() > 0 && scale > 0.0 && lib.pcg.converged && residual <= 1e-10 &&
                  difference <= 1e-8;
  std::printf("consumer: %d pressure DOFs, Jacobi-PCG %d iterations (relative residual %.2e), "
              "library SSOR-PCG %d iterations; max |p| %.6g Pa, relative difference %.2e: %s\n",
              dofs.size(), iterations, residual, lib.pcg.iterations, scale, difference,
              ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
