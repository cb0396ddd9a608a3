// The liquid solve's set-up kept across steps and restricted to the liquid's band (issue 20,
// docs/preconditioners.md section 39): a MatrixFreeStokesOperator built with a StokesWorkspace
// (storage borrowed and given back, C_f only in the band) and the DOF selection in the band give
// the bits of the operator and the selection made afresh over the whole grid, step after step,
// and the set-up's parallel loops give the same bits on any number of threads.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <memory>
#include <omp.h>

#include "reference/core/parallel.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/fluid/stokes_workspace.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::random_vector;
using monolith::testing::stokes_weights;
using monolith::testing::TestBall;

namespace {

bool same_bits(const VectorX& a, const VectorX& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
}

/// Weights of a liquid below a wavy surface at height `level` beside a solid ball (the case of
/// test_stokes.cpp, with the surface moved: one "step" per level), eta varying in space.
template <int Dim>
StokesWeights case_weights(const MacGrid<Dim>& grid, double level, double eta, bool periodic_x) {
  const StressGrid<Dim> stress(grid);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  if (periodic_x) boundary[0] = boundary[1] = BoundaryType::periodic;
  boundary[3] = BoundaryType::open;
  std::vector<ShapePtr<Dim>> solids{std::make_shared<TestBall<Dim>>(Vec<Dim>::Constant(0.37), 0.16)};
  const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, solids, 0.0);
  VectorX liquid_phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    liquid_phi[k] = x[1] - level - 0.08 * std::sin(2.0 * M_PI * x[0]);
  }
  StokesWeights w = stokes_weights(grid, solid_phi, liquid_phi, boundary, 1000.0, std::max(eta, 1e-300));
  w.pressure.face_density += 200.0 * random_vector(grid.num_faces(), 7);
  if (eta == 0.0) {
    w.viscosity = VectorX();  // inviscid: no stress vectors (StokesWeights::inviscid)
    w.fluid_stress = VectorX();
    w.liquid_stress = VectorX();
  } else {
    for (int d = 0; d < stress.num_dofs(); ++d) {
      const auto [k, c] = stress.coord(d);
      const Vec<Dim> x = stress.position(k, c);
      w.viscosity[d] = eta * (1.0 + 0.5 * std::sin(3.0 * x[0] + 2.0 * x[1]));
    }
  }
  return w;
}

/// The tight band of the weights: the boxes of the cells with W_L^p != 0 and of the faces of
/// each axis with W_L^u != 0 (the promise of LiquidBand, as the simulation's WrittenBox keeps).
template <int Dim>
LiquidBand tight_band(const MacGrid<Dim>& grid, const PressureWeights& w) {
  LiquidBand band;
  band.valid = true;
  auto box = [&](const VecI<Dim>& dims, const double* v, std::array<int, 3>& lo, std::array<int, 3>& hi) {
    for (int a = 0; a < Dim; ++a) {
      lo[a] = dims[a];
      hi[a] = -1;
    }
    for (int i = 0; i < dims.prod(); ++i) {
      if (v[i] == 0.0) continue;
      const VecI<Dim> c = lattice_coord<Dim>(i, dims);
      for (int a = 0; a < Dim; ++a) {
        lo[a] = std::min(lo[a], c[a]);
        hi[a] = std::max(hi[a], c[a]);
      }
    }
  };
  box(grid.cells(), w.liquid_cell.data(), band.cell_lo, band.cell_hi);
  for (int a = 0; a < Dim; ++a)
    box(grid.face_dims(a), w.liquid_face.data() + grid.face_offset(a), band.face_lo[a], band.face_hi[a]);
  return band;
}

/// Everything an operator gives: C_f, the diagonal, apply, rhs, SSOR, the velocity update.
template <int Dim>
std::vector<VectorX> outputs(const MatrixFreeStokesOperator<Dim>& op, const VectorX& u_star, double dt) {
  std::vector<VectorX> out;
  out.push_back(op.face_coefficients());
  out.push_back(op.diagonal());
  const VectorX x = random_vector(op.size(), 300);
  VectorX y;
  op.apply(x, y);
  out.push_back(y);
  out.push_back(op.rhs(u_star));
  VectorX z;
  ssor_precondition(op, x, z, 1.0);
  out.push_back(z);
  VectorX u = VectorX::Constant(u_star.size(), 3.0);
  op.updated_velocities_into(x, u_star, dt, u);
  out.push_back(u);
  op.apply(x, y);  // (after SSOR and the update: the scratch is as apply needs it)
  out.push_back(y);
  return out;
}

template <int Dim>
bool same_outputs(const std::vector<VectorX>& a, const std::vector<VectorX>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t k = 0; k < a.size(); ++k)
    if (!same_bits(a[k], b[k])) return false;
  return true;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("select_pressure_dofs in the liquid's band: the DOFs and null space of the whole grid",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  const int n = Dim == 2 ? 24 : 10;
  for (bool periodic : {false, true}) {
    std::array<bool, Dim> per{};
    per[0] = periodic;
    const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), per);
    for (double level : {0.3, 0.62}) {
      const StokesWeights w = case_weights(grid, level, 0.0, periodic);
      const LiquidBand band = tight_band(grid, w.pressure);
      // the band is smaller than the grid (the test exercises the box)
      REQUIRE(band.cell_hi[1] < n - 1);
      const PressureDofs all = select_pressure_dofs(grid, w.pressure, 0.01);
      const PressureDofs banded = select_pressure_dofs(grid, w.pressure, 0.01, &band);
      REQUIRE(all.size() > 0);
      CHECK(banded.cell_of_dof == all.cell_of_dof);
      CHECK(banded.dof_of_cell == all.dof_of_cell);
      REQUIRE(banded.null_space.size() == all.null_space.size());
      for (std::size_t k = 0; k < all.null_space.size(); ++k)
        CHECK(same_bits(banded.null_space[k], all.null_space[k]));
      // an empty band: no DOF
      LiquidBand empty = band;
      empty.cell_lo[0] = 1;
      empty.cell_hi[0] = 0;
      CHECK(select_pressure_dofs(grid, w.pressure, 0.01, &empty).size() == 0);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("matrix-free Stokes operator with a kept workspace and a band: the bits of a fresh one, step after step",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  const int n = Dim == 2 ? 20 : 8;
  const double dt = 0.01;
  for (bool periodic : {false, true}) {
    std::array<bool, Dim> per{};
    per[0] = periodic;
    const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), per);
    const VectorX u_star = random_vector(grid.num_faces(), 11);
    for (StressForm form : {StressForm::full, StressForm::reduced}) {
      const StressLayout<Dim> layout(StressGrid<Dim>(grid), form);
      StokesWorkspace ws;
      long steps = 0;
      // steps with the liquid rising, falling, viscous and inviscid: each reuses what the last
      // one left (rows written by a larger liquid must be reset for a smaller one)
      for (const auto& [level, eta] : {std::pair{0.62, 2.0}, std::pair{0.3, 2.0}, std::pair{0.7, 0.0},
                                       std::pair{0.45, 0.0}, std::pair{0.55, 5.0}}) {
        const StokesWeights w = case_weights(grid, level, eta, periodic);
        for (StokesUnknowns unknowns : {StokesUnknowns::pressure_and_stress, StokesUnknowns::stress_only}) {
          if (eta == 0.0 && unknowns == StokesUnknowns::stress_only) continue;
          ws.band = tight_band(grid, w.pressure);
          const StokesDofs fresh_dofs = select_stokes_dofs(grid, layout, w, dt, unknowns);
          const StokesDofs band_dofs = select_stokes_dofs(grid, layout, w, dt, unknowns, &ws.band);
          REQUIRE(band_dofs.unknown_of_dof == fresh_dofs.unknown_of_dof);
          REQUIRE(band_dofs.pressure.cell_of_dof == fresh_dofs.pressure.cell_of_dof);
          const MatrixFreeStokesOperator<Dim> fresh(grid, layout, w, fresh_dofs, dt);
          const std::vector<VectorX> expected = outputs(fresh, u_star, dt);
          {
            const MatrixFreeStokesOperator<Dim> kept(grid, layout, w, band_dofs, dt, &ws);
            ++steps;
            CHECK(ws.lent);
            CHECK(same_outputs<Dim>(outputs(kept, u_star, dt), expected));
            // a second operator while the first holds the storage: its own vectors, same bits
            const MatrixFreeStokesOperator<Dim> second(grid, layout, w, band_dofs, dt, &ws);
            CHECK(same_outputs<Dim>(outputs(second, u_star, dt), expected));
          }
          CHECK_FALSE(ws.lent);
          // the band without kept storage
          ws.keep = false;
          {
            const MatrixFreeStokesOperator<Dim> band_only(grid, layout, w, band_dofs, dt, &ws);
            CHECK_FALSE(ws.lent);
            CHECK(same_outputs<Dim>(outputs(band_only, u_star, dt), expected));
          }
          ws.keep = true;
        }
      }
      CHECK(ws.reused == steps);
      CHECK(ws.refused == steps);
      // the kept vectors are grid-sized and were not made anew: the face coefficients' storage
      // is the one of the first step
      CHECK(ws.face_coefficient.values.size() == grid.num_faces());
    }
  }
}

TEMPLATE_TEST_CASE_SIG("matrix-free Stokes operator set-up: the same bits on 1, 2, 3 and 5 threads above the serial threshold",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // large enough that the set-up's per-unknown and per-face loops run in parallel
  // (team_threads: kParallelMinWork = 16384 unknowns / entries)
  const int n = Dim == 2 ? 192 : 32;
  const double dt = 0.01;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), std::array<bool, Dim>{});
  const StokesWeights w = case_weights(grid, 0.62, 2.0, false);
  const StressLayout<Dim> layout(StressGrid<Dim>(grid), StressForm::reduced);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const StokesDofs dofs = select_stokes_dofs(grid, layout, w, dt, StokesUnknowns::pressure_and_stress);
  omp_set_num_threads(threads);
  REQUIRE(dofs.size() >= kParallelMinWork);
  REQUIRE(layout.num_unknowns() > 3 * 4096);  // several blocks of the selection's list
  const VectorX u_star = random_vector(grid.num_faces(), 5);
  StokesWorkspace ws;
  ws.band = tight_band(grid, w.pressure);
  // the whole team on every call ("3 threads" is 3, whatever the machine's load)
  const bool adaptive = adaptive_teams(), monitor = core_monitor();
  set_adaptive_teams(false);
  set_core_monitor(false);
  std::vector<std::vector<VectorX>> results;
  for (int t : {1, 2, 3, 5}) {
    omp_set_num_threads(t);
    // the DOF selection's parallel list: the same unknowns in the same order
    const StokesDofs again = select_stokes_dofs(grid, layout, w, dt, StokesUnknowns::pressure_and_stress,
                                                &ws.band);
    CHECK(again.unknown_of_dof == dofs.unknown_of_dof);
    CHECK(again.dof_of_unknown == dofs.dof_of_unknown);
    CHECK(again.pressure.cell_of_dof == dofs.pressure.cell_of_dof);
    const MatrixFreeStokesOperator<Dim> op(grid, layout, w, dofs, dt, &ws);
    results.push_back(outputs(op, u_star, dt));
    // and without the workspace (storage and loops of its own)
    const MatrixFreeStokesOperator<Dim> own(grid, layout, w, dofs, dt);
    results.push_back(outputs(own, u_star, dt));
  }
  omp_set_num_threads(threads);
  set_adaptive_teams(adaptive);
  set_core_monitor(monitor);
  for (std::size_t k = 1; k < results.size(); ++k) CHECK(same_outputs<Dim>(results[k], results[0]));
}
