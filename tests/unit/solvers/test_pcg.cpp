// SSOR-preconditioned CG (section 4.3) on both operator back ends.
#include <omp.h>

#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <random>

#include "reference/fluid/pressure_projection.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/solvers/pcg.hpp"
#include "tests/support/sparse_helpers.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// 2D five-point Laplacian on m x m nodes plus a positive random diagonal: SPD.
SparseMatrix laplacian_plus_diagonal(int m, unsigned seed) {
  return five_point_matrix(m, (random_vector(m * m, seed).array() + 1.0) * 0.05);
}

/// Pressure operators of a liquid pool with a free surface (both back ends).
template <int Dim>
struct Pool {
  MacGrid<Dim> grid;
  PressureWeights w;
  PressureDofs dofs;
  SparseMatrix a;
  explicit Pool(int n) {
    grid = MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {});
    const auto lattice = half_lattice(grid);
    std::array<BoundaryType, 2 * Dim> boundary;
    boundary.fill(BoundaryType::wall);
    const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
    w.fluid_face = fluid_face_weights(grid, lattice, solid_phi, boundary);
    VectorX phi(lattice.size());
    for (int k = 0; k < lattice.size(); ++k) {
      const Vec<Dim> x = lattice.position(lattice.coord(k));
      phi[k] = x[1] - 0.6 - 0.1 * std::sin(6.0 * x[0]);
    }
    w.liquid_cell = liquid_cell_weights(grid, lattice, phi);
    w.liquid_face = liquid_face_weights(grid, lattice, phi, w.liquid_cell);
    w.face_density = VectorX::Constant(grid.num_faces(), 1000.0);
    dofs = select_pressure_dofs(grid, w, 0.01);
    a = assemble_explicit_pressure(grid, w, dofs, 0.01, VectorX::Zero(grid.num_faces())).A;
  }
};

}  // namespace

TEST_CASE("PCG solves an SPD system to the requested infinity-norm tolerance", "[unit]") {
  const SparseMatrix a = laplacian_plus_diagonal(30, 1);
  const VectorX b = random_vector(a.rows(), 2);
  const VectorX exact = Eigen::MatrixXd(a).llt().solve(b);
  const SparseMatrixOperator op(a);
  for (double tol : {1e-6, 1e-10}) {
    PcgSettings s;
    s.tolerance = tol;
    VectorX x;
    const PcgResult r = pcg_solve(op, b, x, s);
    REQUIRE(r.converged);
    REQUIRE_FALSE(r.breakdown);
    const double true_residual =
        (b - a * x).lpNorm<Eigen::Infinity>() / b.lpNorm<Eigen::Infinity>();
    CHECK(r.relative_residual <= tol);
    CHECK(true_residual <= 2.0 * tol);
    if (tol == 1e-10) CHECK((x - exact).norm() <= 1e-8 * exact.norm());
  }
}

TEST_CASE("SSOR preconditioning reduces the iteration count; omega is honoured", "[unit]") {
  const SparseMatrix a = laplacian_plus_diagonal(40, 3);
  const VectorX b = random_vector(a.rows(), 4);
  const SparseMatrixOperator op(a);
  PcgSettings plain;
  plain.precondition = false;
  plain.tolerance = 1e-8;
  VectorX x0;
  const PcgResult r_plain = pcg_solve(op, b, x0, plain);
  std::vector<int> iterations;
  for (double omega : {1.0, 1.5}) {
    PcgSettings s = plain;
    s.precondition = true;
    s.omega = omega;
    VectorX x;
    const PcgResult r = pcg_solve(op, b, x, s);
    REQUIRE(r.converged);
    iterations.push_back(r.iterations);
  }
  INFO("plain CG " << r_plain.iterations << ", SSOR(1.0) " << iterations[0] << ", SSOR(1.5) "
                   << iterations[1]);
  REQUIRE(r_plain.converged);
  CHECK(iterations[0] < r_plain.iterations);
  CHECK(iterations[1] != iterations[0]);
}

TEST_CASE("PCG reports breakdown, zero right-hand side and the iteration cap", "[unit]") {
  // indefinite: p^T A p <= 0 happens and is reported
  SparseMatrix indefinite(2, 2);
  indefinite.insert(0, 0) = 1.0;
  indefinite.insert(1, 1) = -1.0;
  PcgSettings s;
  s.precondition = false;
  VectorX x;
  const PcgResult bad = pcg_solve(SparseMatrixOperator(indefinite), VectorX::Ones(2), x, s);
  CHECK(bad.breakdown);
  CHECK_FALSE(bad.converged);
  CHECK_FALSE(bad.message.empty());
  // b = 0: x = 0 at once
  const SparseMatrix a = laplacian_plus_diagonal(10, 5);
  VectorX y = VectorX::Ones(a.rows());
  const PcgResult zero =
      pcg_solve(SparseMatrixOperator(a), VectorX::Zero(a.rows()), y, PcgSettings{});
  CHECK(zero.converged);
  CHECK(zero.iterations == 0);
  CHECK(y.norm() == 0.0);
  // PcgSettings::zero_rhs: a b at or below it counts as zero (x = 0, no iteration); above it
  // the solve runs as before, bit for bit
  const VectorX tiny = 1e-14 * random_vector(a.rows(), 3);
  PcgSettings floor;
  floor.zero_rhs = tiny.cwiseAbs().maxCoeff();
  y.setOnes();
  const PcgResult unsolved = pcg_solve(SparseMatrixOperator(a), tiny, y, floor);
  CHECK(unsolved.converged);
  CHECK(unsolved.iterations == 0);
  CHECK(y.norm() == 0.0);
  floor.zero_rhs = 0.99 * tiny.cwiseAbs().maxCoeff();
  VectorX y1, y2;
  const PcgResult solved = pcg_solve(SparseMatrixOperator(a), tiny, y1, floor);
  const PcgResult plain = pcg_solve(SparseMatrixOperator(a), tiny, y2, PcgSettings{});
  CHECK(solved.converged);
  CHECK(solved.iterations > 0);
  CHECK(solved.iterations == plain.iterations);
  CHECK((y1 - y2).cwiseAbs().maxCoeff() == 0.0);
  // the cap: not converged, not a breakdown
  PcgSettings capped;
  capped.max_iterations = 2;
  capped.tolerance = 1e-14;
  VectorX z;
  const PcgResult r = pcg_solve(SparseMatrixOperator(laplacian_plus_diagonal(30, 6)),
                                random_vector(900, 7), z, capped);
  CHECK(r.iterations == 2);
  CHECK_FALSE(r.converged);
  CHECK_FALSE(r.breakdown);
  CHECK(r.relative_residual > 1e-14);
}

TEMPLATE_TEST_CASE_SIG("the SSOR preconditioner is symmetric positive definite on both back ends",
                       "[property]", ((int Dim), Dim), 2, 3) {
  const Pool<Dim> pool(Dim == 2 ? 16 : 8);
  const SparseMatrixOperator explicit_op(pool.a);
  const MatrixFreePressureOperator<Dim> mf(pool.grid, pool.w, pool.dofs, 0.01);
  const int n = pool.dofs.size();
  for (double omega : {1.0, 1.4}) {
    for (const LinearOperator* op : {static_cast<const LinearOperator*>(&explicit_op),
                                     static_cast<const LinearOperator*>(&mf)}) {
      const VectorX r1 = random_vector(n, 11), r2 = random_vector(n, 12);
      VectorX z1, z2;
      ssor_precondition(*op, r1, z1, omega);
      ssor_precondition(*op, r2, z2, omega);
      REQUIRE(z1.dot(r2) == Approx(r1.dot(z2)).epsilon(1e-10));
      REQUIRE(z1.dot(r1) > 0.0);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("matrix-free apply and sweeps are deterministic under OpenMP", "[property]",
                       ((int Dim), Dim), 2, 3) {
  const Pool<Dim> pool(Dim == 2 ? 32 : 12);
  const MatrixFreePressureOperator<Dim> mf(pool.grid, pool.w, pool.dofs, 0.01);
  const VectorX x = random_vector(pool.dofs.size(), 9);
  const int threads = omp_get_max_threads();
  VectorX y1, y2, z1, z2;
  omp_set_num_threads(1);
  mf.apply(x, y1);
  ssor_precondition(mf, x, z1, 1.0);
  omp_set_num_threads(2);
  mf.apply(x, y2);
  ssor_precondition(mf, x, z2, 1.0);
  omp_set_num_threads(threads);
  CHECK((y1 - y2).norm() == 0.0);
  CHECK((z1 - z2).norm() == 0.0);
  // and the PCG solution equals the explicit one
  PcgSettings s;
  s.tolerance = 1e-11;
  VectorX p_mf, p_ex;
  const VectorX b = random_vector(pool.dofs.size(), 10);
  REQUIRE(pcg_solve(mf, b, p_mf, s).converged);
  REQUIRE(pcg_solve(SparseMatrixOperator(pool.a), b, p_ex, s).converged);
  CHECK((p_mf - p_ex).norm() <= 1e-8 * p_ex.norm());
}
