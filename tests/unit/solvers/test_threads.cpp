// The parallel kernels above their serial thresholds (issue 19): the matrix-free Stokes and
// pressure applies and SSOR sweeps (one parallel region per sweep, rows taken in dynamic chunks)
// and the coloured sparse sweep of MPRGP give bitwise the same result on 1, 2 and 3 threads,
// from a zero and from a non-zero start (the sweep's own scatter of x). The existing
// determinism tests run below kParallelMinWork, where everything is serial.
#include <omp.h>

#include <catch2/catch.hpp>

#include "tests/support/sparse_helpers.hpp"
#include "reference/core/parallel.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/solvers/colouring.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/pcg.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::random_vector;

namespace {

/// apply, SSOR from zero, a forward and a backward sweep from a non-zero x: per thread count.
struct Outputs {
  VectorX y, z, forward, backward;
};

Outputs run_kernels(const LinearOperator& op, const VectorX& x, const VectorX& b, int threads) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  Outputs o;
  op.apply(x, o.y);
  ssor_precondition(op, b, o.z, 1.0);
  o.forward = x;
  op.forward_sweep(b, o.forward, 1.3);
  o.backward = x;
  op.backward_sweep(b, o.backward, 0.8);
  omp_set_num_threads(saved);
  return o;
}

void check_same_on_any_thread_count(const LinearOperator& op, unsigned seed) {
  const VectorX x = random_vector(op.size(), seed), b = random_vector(op.size(), seed + 1);
  const Outputs one = run_kernels(op, x, b, 1);
  for (int threads : {2, 3}) {
    CAPTURE(threads);
    const Outputs many = run_kernels(op, x, b, threads);
    CHECK((one.y - many.y).cwiseAbs().maxCoeff() == 0.0);
    CHECK((one.z - many.z).cwiseAbs().maxCoeff() == 0.0);
    CHECK((one.forward - many.forward).cwiseAbs().maxCoeff() == 0.0);
    CHECK((one.backward - many.backward).cwiseAbs().maxCoeff() == 0.0);
  }
  // the sweeps did something (not a vacuous comparison)
  CHECK((one.forward - x).norm() > 0.0);
  CHECK(one.z.norm() > 0.0);
}

/// Liquid below a flat surface at height h in a walled box open at the top, a fixed ball.
MacGrid<3> box_grid(int n) {
  return MacGrid<3>(Vec<3>::Zero(), 1.0 / n, VecI<3>::Constant(n), {});
}

std::array<BoundaryType, 6> open_top() {
  std::array<BoundaryType, 6> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  return boundary;
}

}  // namespace

TEST_CASE("matrix-free Stokes apply and sweeps in parallel: bitwise equal on 1, 2, 3 threads",
          "[unit]") {
  const int n = 20;  // 3 * 20^3 faces + stress DOFs, far above kParallelMinWork
  const MacGrid<3> grid = box_grid(n);
  const SampleLattice<3> lattice = half_lattice(grid);
  const VectorX solid_phi = solid_phi_on_lattice<3>(grid, lattice, {}, 0.0);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<3> x = lattice.position(lattice.coord(k));
    phi[k] = x[1] - 0.7 - 0.05 * std::sin(7.0 * x[0] + 3.0 * x[2]);
  }
  const StokesWeights w = uniform_stokes_weights<3>(grid, solid_phi, phi, open_top(), 1000.0, 3.0);
  for (StressForm form : {StressForm::full, StressForm::reduced}) {
    CAPTURE(form == StressForm::full);
    const StressLayout<3> layout(StressGrid<3>(grid), form);
    const StokesDofs dofs = select_stokes_dofs(grid, layout, w, 0.01, StokesUnknowns::pressure_and_stress);
    const MatrixFreeStokesOperator<3> op(grid, layout, w, dofs, 0.01);
    REQUIRE(op.size() > kParallelMinWork);
    check_same_on_any_thread_count(op, 11);
  }
}

TEST_CASE("matrix-free pressure apply and sweeps in parallel: bitwise equal on 1, 2, 3 threads",
          "[unit]") {
  const int n = 32;  // 32^3 cells > kParallelMinWork
  const MacGrid<3> grid = box_grid(n);
  const PressureWeights w = monolith::testing::flat_surface_weights<3>(grid, open_top(), 0.63, 1000.0);
  const PressureDofs dofs = select_pressure_dofs<3>(grid, w, 0.01);
  const MatrixFreePressureOperator<3> op(grid, w, dofs, 0.01);
  REQUIRE(grid.num_cells() > kParallelMinWork);
  check_same_on_any_thread_count(op, 21);
}

TEST_CASE("coloured sparse sweep (MPRGP) in parallel: bitwise equal on 1, 2, 3 threads", "[unit]") {
  // a 7-point matrix on m^3 nodes, m^3 above the sweep's serial threshold
  const int m = 42;
  REQUIRE(m * m * m >= kParallelMinColourRows);
  const SparseMatrix a = monolith::testing::seven_point_matrix(m, 6.5, 0.001);
  Colouring colours = welsh_powell(matrix_adjacency(a));
  const ColouredSparseOperator op(a, std::move(colours));
  check_same_on_any_thread_count(op, 31);
}
