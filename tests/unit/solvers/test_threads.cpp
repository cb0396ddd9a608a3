// The parallel kernels above their serial thresholds (issue 19): the matrix-free Stokes and
// pressure applies and SSOR sweeps (one parallel region per sweep, rows taken in dynamic chunks)
// and the coloured sparse sweep of MPRGP give bitwise the same result on 1, 2 and 3 threads,
// from a zero and from a non-zero start (the sweep's own scatter of x). The existing
// determinism tests run below kParallelMinWork, where everything is serial. Also the policy of
// AdaptiveTeam (parallel.hpp) on made-up timings, and a PCG solve whose team sizes are chosen
// by measurement, bitwise equal to the one-thread solve.
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

/// apply, SSOR from zero, a forward and a backward sweep from a non-zero x, and three
/// consecutive sweeps each way (forward_sweeps / backward_sweeps): per thread count.
struct Outputs {
  VectorX y, z, forward, backward, forward3, backward3;
};

Outputs run_kernels(const LinearOperator& op, const VectorX& x, const VectorX& b, int threads) {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(threads);
  // the whole team on every call (no measured choice of a smaller one), so "3 threads" is 3
  const bool adaptive = adaptive_teams(), monitor = core_monitor();
  set_adaptive_teams(false);
  set_core_monitor(false);  // nor a smaller one because the machine is busy
  Outputs o;
  op.apply(x, o.y);
  ssor_precondition(op, b, o.z, 1.0);
  o.forward = x;
  op.forward_sweep(b, o.forward, 1.3);
  o.backward = x;
  op.backward_sweep(b, o.backward, 0.8);
  o.forward3 = x;
  op.forward_sweeps(b, o.forward3, 1.3, 3);
  o.backward3 = x;
  op.backward_sweeps(b, o.backward3, 0.8, 3);
  omp_set_num_threads(saved);
  set_adaptive_teams(adaptive);
  set_core_monitor(monitor);
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
    CHECK((one.forward3 - many.forward3).cwiseAbs().maxCoeff() == 0.0);
    CHECK((one.backward3 - many.backward3).cwiseAbs().maxCoeff() == 0.0);
  }
  // the sweeps did something (not a vacuous comparison)
  CHECK((one.forward - x).norm() > 0.0);
  CHECK(one.z.norm() > 0.0);
  // consecutive sweeps are the single sweeps one after the other (an operator may carry its
  // state from one to the next, as the matrix-free Stokes operator does its face force B x:
  // equal up to round-off)
  VectorX forward = x, backward = x;
  for (int s = 0; s < 3; ++s) op.forward_sweep(b, forward, 1.3);
  for (int s = 0; s < 3; ++s) op.backward_sweep(b, backward, 0.8);
  CHECK((one.forward3 - forward).norm() <= 1e-12 * forward.norm());
  CHECK((one.backward3 - backward).norm() <= 1e-12 * backward.norm());
  CHECK((one.forward3 - one.forward).norm() > 1e-6 * forward.norm());  // the later sweeps counted
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

namespace {

/// Drives `site` for `calls` calls whose time per call is cost[team] (made-up timings, so the
/// policy is tested without a clock); returns how many calls ran with each team size.
std::vector<int> drive(AdaptiveTeam& site, const std::vector<double>& cost, int calls) {
  std::vector<int> used(cost.size(), 0);
  const long work = 4 * kParallelMinWork;
  for (int c = 0; c < calls; ++c) {
    const int team = site.choose(work);
    REQUIRE(team >= 1);
    REQUIRE(team < static_cast<int>(cost.size()));
    ++used[team];
    site.record(team, work, cost[team]);
  }
  return used;
}

/// Sets the OpenMP cap and switches the measured choice on for the scope; the process-wide
/// team (ProcessTeam) is off unless `monitor`, so the machine's load does not lower the cap of
/// a test on made-up timings.
struct TeamCap {
  explicit TeamCap(int threads, bool monitor = false)
      : saved(omp_get_max_threads()), adaptive(adaptive_teams()), monitored(core_monitor()) {
    omp_set_num_threads(threads);
    set_adaptive_teams(true);
    set_core_monitor(monitor);
  }
  ~TeamCap() {
    omp_set_num_threads(saved);
    set_adaptive_teams(adaptive);
    set_core_monitor(monitored);
  }
  int saved;
  bool adaptive, monitored;
};

}  // namespace

TEST_CASE("AdaptiveTeam: a faster smaller team wins its probe, the full team wins back", "[unit]") {
  const TeamCap cap(2);
  AdaptiveTeam site;
  // a core taken: 2 threads take twice as long as 1; the first probe (4th call) and its repeat
  // move to 1
  std::vector<int> used = drive(site, {0.0, 1.0e-3, 2.0e-3}, 8);
  CHECK(site.current() == 1);
  CHECK(used[2] <= AdaptiveTeam::kFirstProbeInterval);
  // it stays there: probes of 2 lose and become rare (at most one per kMaxProbeInterval calls
  // once the interval has doubled up to it: 4 + 8 + 16 + 32 + 64 calls for the first 5)
  used = drive(site, {0.0, 1.0e-3, 2.0e-3}, 1000);
  CHECK(site.current() == 1);
  CHECK(used[2] <= 5 + 1000 / AdaptiveTeam::kMaxProbeInterval);
  CHECK(used[2] >= 1000 / (2 * AdaptiveTeam::kMaxProbeInterval));  // it keeps probing
  // the other process ended: 2 threads twice as fast; the next probe (within the interval)
  // and its repeat move back to 2
  used = drive(site, {0.0, 1.0e-3, 0.5e-3}, AdaptiveTeam::kMaxProbeInterval + 2);
  CHECK(site.current() == 2);
  // idle: probes of 1 thread lose, rare again
  used = drive(site, {0.0, 1.0e-3, 0.5e-3}, 1000);
  CHECK(site.current() == 2);
  CHECK(used[1] <= 5 + 1000 / AdaptiveTeam::kMaxProbeInterval);
  // a core taken again: two slow calls (4x the average, the median of the last 3) make the
  // next call a probe, without waiting for the probe interval; it and its repeat win
  drive(site, {0.0, 1.0e-3, 2.0e-3}, 6);  // (the first may be a scheduled probe)
  CHECK(site.current() == 1);
  // one lucky probe does not move a site: every other call at 2 threads is fast (so every
  // probe wins and every repeat loses)
  AdaptiveTeam lucky;
  drive(lucky, {0.0, 1.0e-3, 2.0e-3}, 8);
  REQUIRE(lucky.current() == 1);
  int at_two = 0;
  for (int c = 0; c < 2000; ++c) {
    const int team = lucky.choose(4 * kParallelMinWork);
    const double seconds = team == 2 ? (at_two++ % 2 == 0 ? 0.5e-3 : 2.0e-3) : 1.0e-3;
    lucky.record(team, 4 * kParallelMinWork, seconds);
  }
  CHECK(at_two >= 10);  // it did probe
  CHECK(lucky.current() == 1);
}

TEST_CASE("AdaptiveTeam: climbs to the fastest team size between 1 and the cap", "[unit]") {
  const TeamCap cap(4);
  AdaptiveTeam site;
  // 2 threads fastest (e.g. 4 threads on a machine with 2 free cores)
  drive(site, {0.0, 1.0e-3, 0.55e-3, 0.7e-3, 0.9e-3}, 300);
  CHECK(site.current() == 2);
  // a probe only 1 % faster (timing noise) does not move the site
  AdaptiveTeam steady;
  drive(steady, {0.0, 1.0e-3, 1.0e-3, 0.99e-3, 1.0e-3}, 300);
  CHECK(steady.current() == 4);
}

TEST_CASE("AdaptiveTeam: one thread below the threshold, inside a parallel region, with a cap of 1",
          "[unit]") {
  AdaptiveTeam site;
  {
    const TeamCap cap(2);
    CHECK(site.choose(kParallelMinWork - 1) == 0);  // serial, not measured
    CHECK(site.choose(kParallelMinWork) == 2);
    int nested = -1;
#pragma omp parallel num_threads(2)
    {
#pragma omp single
      nested = site.choose(10 * kParallelMinWork);
    }
    CHECK(nested == 0);
    set_adaptive_teams(false);
    drive(site, {0.0, 1.0e-3, 2.0e-3}, 20);  // records ignored, the full team every time
    CHECK(site.choose(kParallelMinWork) == 2);
  }
  const TeamCap cap(1);
  CHECK(site.choose(10 * kParallelMinWork) == 0);
}

TEST_CASE("PCG with measured team sizes: bitwise equal to the one-thread solve", "[unit]") {
  const int n = 20;
  const MacGrid<3> grid = box_grid(n);
  const SampleLattice<3> lattice = half_lattice(grid);
  const VectorX solid_phi = solid_phi_on_lattice<3>(grid, lattice, {}, 0.0);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = lattice.position(lattice.coord(k))[1] - 0.6;
  const StokesWeights w = uniform_stokes_weights<3>(grid, solid_phi, phi, open_top(), 1000.0, 1.0);
  const StressLayout<3> layout(StressGrid<3>(grid), StressForm::reduced);
  const StokesDofs dofs = select_stokes_dofs(grid, layout, w, 0.01, StokesUnknowns::pressure_and_stress);
  const MatrixFreeStokesOperator<3> op(grid, layout, w, dofs, 0.01);
  const VectorX b = random_vector(op.size(), 41);
  PcgSettings settings;
  settings.tolerance = 1e-10;
  settings.max_iterations = 40;  // enough calls of each kernel for several probes
  auto solve = [&](int threads) {
    const TeamCap cap(threads, true);  // measured teams under the process-wide team
    VectorX x;
    const PcgResult r = pcg_solve(op, b, x, settings);
    CHECK(r.iterations > 10);
    return x;
  };
  const VectorX one = solve(1);
  CHECK(one.norm() > 0.0);
  for (int repeat = 0; repeat < 2; ++repeat) {
    const VectorX two = solve(2);
    CHECK((one - two).cwiseAbs().maxCoeff() == 0.0);
  }
}

TEST_CASE("process-wide team: the cores other processes leave free, with a hysteresis", "[unit]") {
  // 2 CPUs: nobody else -> 2; another process on a whole core -> 1; back -> 2
  CHECK(next_process_team(2, 2, 0.0) == 2);
  CHECK(next_process_team(2, 2, 1.0) == 1);
  CHECK(next_process_team(2, 1, 1.0) == 1);
  CHECK(next_process_team(2, 1, 0.0) == 2);
  // inside the band around half a core the team stays as it is (no flipping on noise)
  for (double others : {0.45, 0.5, 0.55}) {
    CAPTURE(others);
    CHECK(next_process_team(2, 2, others) == 2);
    CHECK(next_process_team(2, 1, others) == 1);
  }
  CHECK(next_process_team(2, 2, 0.65) == 1);
  CHECK(next_process_team(2, 1, 0.35) == 2);
  // never below 1 (both cores taken), never above the CPUs
  CHECK(next_process_team(2, 2, 2.0) == 1);
  CHECK(next_process_team(2, 1, 5.0) == 1);
  CHECK(next_process_team(2, 7, 0.0) == 2);
  CHECK(next_process_team(2, 0, 0.0) == 2);
  // 8 CPUs, 3 cores taken -> 5; a fourth half-taken core: down only past the band
  CHECK(next_process_team(8, 8, 3.0) == 5);
  CHECK(next_process_team(8, 5, 3.55) == 5);
  CHECK(next_process_team(8, 5, 3.65) == 4);
  CHECK(next_process_team(8, 4, 3.45) == 4);
  CHECK(next_process_team(8, 4, 3.35) == 5);
}

TEST_CASE("process-wide team: within 1..the cap, and the whole cap when switched off", "[unit]") {
  const int cpus = static_cast<int>(affinity_cpus().size());
  {
    const TeamCap cap(2, true);
    for (int i = 0; i < 3; ++i) {
      const int team = process_threads();
      CHECK(team >= 1);
      CHECK(team <= std::min(2, cpus));
      std::this_thread::sleep_for(std::chrono::milliseconds(110));  // a new window
    }
    CHECK(ProcessTeam::instance().others() >= 0.0);
    CHECK(team_threads(kParallelMinWork - 1) == 1);
    int nested = -1;
#pragma omp parallel num_threads(2)
    {
#pragma omp single
      nested = process_threads();
    }
    CHECK(nested == 1);
  }
  const TeamCap off(3, false);
  CHECK(process_threads() == 3);
  CHECK(team_threads(kParallelMinWork) == 3);
}

TEST_CASE("AdaptiveTeam: a change of the cap starts the site afresh at the new cap", "[unit]") {
  AdaptiveTeam site;
  {
    const TeamCap cap(2);
    drive(site, {0.0, 1.0e-3, 2.0e-3}, 8);
    REQUIRE(site.current() == 1);
  }
  const TeamCap cap(3);
  CHECK(site.choose(4 * kParallelMinWork) == 3);
  CHECK(site.current() == 3);
}
